"""Track scoring helpers (cldet.core.selection)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from cldet.config import load_config
from cldet.core.estimator import _weigher
from cldet.core.features import FEATURE_NAMES
from cldet.core.prior import load_prior
from cldet.core.selection import LEARNED_FLOOR, TrackWeigher, _p90


@pytest.mark.parametrize("n", [1, 2, 3, 7, 10, 101, 1000])
def test_p90_equals_numpys_percentile(n: int) -> None:
    x = np.random.default_rng(n).normal(size=n)
    assert _p90(x) == pytest.approx(float(np.percentile(x, 90)), abs=1e-12)


def test_learned_weighings_multiply_each_within_its_floor() -> None:
    def half(f: Any) -> Any:
        return np.full(len(f), 0.5)

    def sure(f: Any) -> Any:
        return np.ones(len(f))

    weigher = TrackWeigher(((half, 0.2), (sure, 0.5)))
    assert weigher.floor == pytest.approx(0.1)
    np.testing.assert_allclose(weigher(np.zeros((3, 4))), [0.6, 0.6, 0.6])


def test_a_models_scorer_weighs_with_the_prior_unless_the_prior_is_off() -> None:
    # a model that calls every track clutter: it weighs each by its floor alone
    model: Any = SimpleNamespace(scorer=object(), drone_probability=lambda f: np.zeros(len(f)))
    features = np.random.default_rng(0).uniform(0.0, 5.0, (4, len(FEATURE_NAMES)))
    prior = load_prior()
    with_prior = _weigher(model, load_config().tracking)
    off = load_config(overrides={"tracking": {"prior_scorer": False}}).tracking
    alone = _weigher(model, off)
    assert with_prior is not None and alone is not None
    np.testing.assert_allclose(alone(features), LEARNED_FLOOR)
    expected = LEARNED_FLOOR * (prior.floor + (1 - prior.floor) * prior.drone_probability(features))
    np.testing.assert_allclose(with_prior(features), expected)
    assert with_prior.floor == pytest.approx(LEARNED_FLOOR * prior.floor)
    assert _weigher(None, off) is None
