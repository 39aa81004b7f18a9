"""The order statistics of short arrays (cldet.core.stats) are numpy's, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from cldet.core.stats import (
    box_minimum,
    column_medians,
    median,
    median_of_sorted,
    percentile,
    percentile_of_sorted,
)


def _same(a: float, b: float) -> bool:
    return a == b or (np.isnan(a) and np.isnan(b))


def _arrays(seed: int) -> list[np.ndarray]:
    """Short arrays of every kind the track summaries see: any length, scale and ties, some
    with NaN or infinite values."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(400):
        n = int(rng.integers(1, 40))
        x = rng.normal(0.0, 1.0, n) * 10 ** rng.uniform(-3, 3)
        if rng.random() < 0.3:
            x = np.round(x, 1)  # ties
        if rng.random() < 0.3:
            x[rng.random(n) < 0.3] = np.nan
        if rng.random() < 0.1:
            x[rng.random(n) < 0.3] = rng.choice([np.inf, -np.inf])
        out.append(x)
    return out


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")  # inf - inf, on both sides
def test_median_and_percentiles_equal_numpys_exactly(seed: int) -> None:
    for x in _arrays(seed):
        finite = x[np.isfinite(x)]
        assert _same(median(x), float(np.median(x)))
        # the compiled forms, on the sorted finite values (as the track summary calls them)
        s = np.sort(finite)
        assert _same(median_of_sorted(s), float(np.median(finite)) if len(s) else np.nan)
        for q in (10, 25, 50, 90):
            assert _same(percentile(x, q), float(np.percentile(x, q)))
            expected = float(np.percentile(finite, q)) if len(s) else np.nan
            assert _same(percentile_of_sorted(s, q), expected)


def test_nan_and_none() -> None:
    x = np.array([np.nan, 3.0, np.inf, 1.0, 2.0])
    assert np.isnan(median(x)) and np.isnan(percentile(x, 90))
    s = np.sort(x[np.isfinite(x)])
    assert median_of_sorted(s) == 2.0 and percentile_of_sorted(s, 90) == pytest.approx(2.8)
    assert np.isnan(median_of_sorted(np.zeros(0))) and np.isnan(percentile_of_sorted(s[:0], 50))


def test_column_medians_equal_numpys_exactly() -> None:
    rng = np.random.default_rng(2)
    for n in (1, 2, 3, 4, 7, 10, 51):
        a = rng.normal(0.0, 30.0, (n, 3))
        np.testing.assert_array_equal(column_medians(a), np.median(a, axis=0))
        a[0, 1] = np.nan
        np.testing.assert_array_equal(column_medians(a), np.median(a, axis=0))


@pytest.mark.parametrize("size", [1, 3, 5])
@pytest.mark.parametrize("wrap", [True, False])
def test_box_minimum_is_scipys_minimum_filter(size: int, wrap: bool) -> None:
    from scipy.ndimage import minimum_filter

    a = np.random.default_rng(size).uniform(0.0, 50.0, (12, 30)).astype(np.float32)
    a[a > 40.0] = np.inf  # cells with no static range
    cols = "wrap" if wrap else "nearest"
    np.testing.assert_array_equal(
        box_minimum(a, size, wrap), minimum_filter(a, size, mode=("nearest", cols))
    )
