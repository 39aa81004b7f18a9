"""Tree ensembles as plain arrays (cldet.core.trees) and the packaged prior scorer."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cldet.core.features import FEATURE_NAMES
from cldet.core.prior import load_prior, parse_prior, prior_json
from cldet.core.trees import TreeEnsemble


def _data(rng: np.random.Generator, n: int, classes: int) -> tuple[np.ndarray, np.ndarray]:
    x = rng.normal(size=(n, 5))
    x[rng.random(x.shape) < 0.15] = np.nan  # missing values take the side training chose
    signal = np.nan_to_num(x[:, 0]) + np.nan_to_num(x[:, 1]) ** 2
    y = np.digitize(signal, np.quantile(signal, np.linspace(0, 1, classes + 1)[1:-1]))
    return x, y + 3  # labels need not start at 0


@pytest.mark.parametrize("classes", [2, 3])
def test_predictions_equal_scikit_learns_after_a_json_round_trip(classes: int) -> None:
    from sklearn.ensemble import HistGradientBoostingClassifier

    rng = np.random.default_rng(0)
    x, y = _data(rng, 600, classes)
    clf = HistGradientBoostingClassifier(max_iter=40, max_leaf_nodes=7, random_state=0)
    clf.fit(x, y)
    trees = TreeEnsemble.from_json(json.loads(json.dumps(TreeEnsemble.from_sklearn(clf).to_json())))
    x_new, _ = _data(rng, 300, classes)
    np.testing.assert_allclose(trees.predict_proba(x_new), clf.predict_proba(x_new), atol=1e-12)
    np.testing.assert_array_equal(trees.classes_, clf.classes_)


def _tiny() -> dict:
    from sklearn.ensemble import HistGradientBoostingClassifier

    x, y = _data(np.random.default_rng(1), 200, 2)
    clf = HistGradientBoostingClassifier(max_iter=3, random_state=0).fit(x, y)
    return TreeEnsemble.from_sklearn(clf).to_json()


@pytest.mark.parametrize(
    "corrupt",
    [
        lambda d: d.pop("trees"),
        lambda d: d.update(columns=["feature"]),
        lambda d: d["trees"][0][3].__setitem__(0, 0),  # a child pointing back at its parent
        lambda d: d["trees"][0][3].__setitem__(0, 10**6),  # ... or out of the tree
        lambda d: d["trees"][0][0].__setitem__(0, 99),  # a split on a feature it lacks
        lambda d: d.update(baseline=[0.0, 0.0, 0.0]),
    ],
)
def test_a_corrupt_ensemble_is_refused_not_evaluated(corrupt: object) -> None:
    data = _tiny()
    corrupt(data)  # type: ignore[operator]
    with pytest.raises(ValueError):
        TreeEnsemble.from_json(data)


def test_the_packaged_prior_reads_this_codes_features_and_gives_probabilities() -> None:
    prior = load_prior()
    assert prior.trees.n_features == len(prior.feature_names)
    assert set(prior.feature_names) <= set(FEATURE_NAMES)
    assert 0.0 <= prior.floor < 1.0
    assert prior.info["worlds"] >= 100  # trained on many randomised development worlds
    p = prior.drone_probability(np.full((3, len(FEATURE_NAMES)), np.nan))
    assert p.shape == (3,) and np.all((p >= 0) & (p <= 1))
    assert len(prior.drone_probability(np.zeros((0, len(FEATURE_NAMES))))) == 0


def test_a_prior_of_other_features_or_format_is_refused() -> None:
    prior = load_prior()
    doc = prior_json(prior.trees, 0.1, {}, prior.feature_names)
    parse_prior(json.loads(json.dumps(doc)))
    for change in (
        {"feature_names": list(prior.feature_names[:-1])},  # fewer names than the trees' columns
        {"feature_names": [*prior.feature_names[:-1], "colour_of_the_sky"]},  # not computed here
        {"feature_names": []},
        {"format": 99},
        {"kind": "x"},
    ):
        with pytest.raises(ValueError):
            parse_prior({**doc, **change})


def test_a_prior_trained_on_fewer_features_scores_its_own_columns() -> None:
    """Features added to the code later do not invalidate a prior: it scores the columns it
    names, wherever they now stand in the feature vector."""
    prior = load_prior()
    rng = np.random.default_rng(0)
    own = rng.normal(0.0, 1.0, (50, len(prior.feature_names)))
    full = np.full((50, len(FEATURE_NAMES)), 1e6)  # the columns it does not read: nonsense
    full[:, [FEATURE_NAMES.index(n) for n in prior.feature_names]] = own
    expected = prior.trees.predict_proba(own)[:, 1]
    np.testing.assert_allclose(prior.drone_probability(full), expected)
    assert len(set(np.round(expected, 6))) > 1  # the check can fail: the scores vary
