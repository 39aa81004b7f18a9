"""Tests of the robustness benchmark's helpers: seed ranges, the Wilson interval, scoring."""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from cldet.types import Estimate, Source

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_robustness.py"


@pytest.fixture(scope="module")
def monkeypatch_module() -> Iterator[pytest.MonkeyPatch]:
    with pytest.MonkeyPatch.context() as patch:
        yield patch


@pytest.fixture(scope="module")
def bench(monkeypatch_module: pytest.MonkeyPatch) -> ModuleType:
    monkeypatch_module.syspath_prepend(str(BENCH.parent))  # as when run: its folder on the path
    spec = importlib.util.spec_from_file_location("bench_robustness", BENCH)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_seed_ranges(bench: ModuleType) -> None:
    assert bench.parse_seeds("10000-10002,10007") == [10000, 10001, 10002, 10007]
    assert len(bench.parse_seeds(bench.EVALUATION)) == 300
    assert bench.parse_seeds(bench.EVALUATION)[0] == 90000


def test_wilson_interval(bench: ModuleType) -> None:
    lo, hi = bench.wilson(0, 300)
    assert lo == 0.0 and hi == pytest.approx(0.0126, abs=5e-4)
    lo, hi = bench.wilson(6, 300)
    assert lo < 0.02 < hi and hi == pytest.approx(0.043, abs=1e-3)


def test_score_interpolates_and_clamps(bench: ModuleType) -> None:
    est = [
        Estimate(1_000, np.array([0.0, 0.0, 0.0]), Source.DETECTED, 1, 0.1),
        Estimate(3_000, np.array([2.0, 0.0, 0.0]), Source.DETECTED, 1, 0.1),
    ]
    stamps = np.array([0, 2_000, 4_000], dtype=np.int64)
    truth = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 1.0]])
    rms, sse, n = bench.score(est, stamps, truth)
    assert (sse, n) == (pytest.approx(1.0), 3)
    assert rms == pytest.approx(np.sqrt(1.0 / 3.0))
    rms, sse, _ = bench.score(None, stamps, truth)  # no estimate: the origin
    assert sse == pytest.approx(1.0 + 4.0 + 1.0)
