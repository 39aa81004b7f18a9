"""Track scoring helpers (cldet.core.selection)."""

from __future__ import annotations

import numpy as np
import pytest

from cldet.core.selection import _p90


@pytest.mark.parametrize("n", [1, 2, 3, 7, 10, 101, 1000])
def test_p90_equals_numpys_percentile(n: int) -> None:
    x = np.random.default_rng(n).normal(size=n)
    assert _p90(x) == pytest.approx(float(np.percentile(x, 90)), abs=1e-12)
