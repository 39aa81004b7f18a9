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
    scores = bench.score(est, stamps, truth)
    assert (scores["sse"], scores["n"]) == (pytest.approx(1.0), 3)
    assert scores["rms"] == pytest.approx(np.sqrt(1.0 / 3.0))
    assert bench.score(est[::-1], stamps, truth)["sse"] == pytest.approx(1.0)  # any order
    scores = bench.score(None, stamps, truth)  # no estimate: the origin
    assert scores["sse"] == pytest.approx(1.0 + 4.0 + 1.0)


def test_the_squared_error_is_split_by_where_each_row_lies(bench: ModuleType) -> None:
    # estimates at 1..5 us: predicted, detected, smoothed (a gap), detected, predicted; one
    # truth row before them all (clamped to the first), one at each, one after them all
    sources = [Source.PREDICTED, Source.DETECTED, Source.SMOOTHED, Source.DETECTED]
    sources.append(Source.PREDICTED)
    est = [
        Estimate(1_000 * (k + 1), np.array([float(k), 0.0, 0.0]), src, 1, 0.1)
        for k, src in enumerate(sources)
    ]
    stamps = np.array([0, 1_000, 2_000, 3_000, 4_000, 5_000, 6_000], dtype=np.int64)
    truth = np.zeros((7, 3))
    truth[:, 0] = [0.0, 1.0, 1.0, 3.0, 3.0, 6.0, 6.0]  # errors 0, 1, 0, 1, 0, 2, 2
    scores = bench.score(est, stamps, truth)
    parts = scores["parts"]
    assert parts == {
        "before": pytest.approx(0.0 + 1.0),  # rows at 0 and 1 us: before the first detection
        "detected": pytest.approx(0.0 + 0.0),  # 2 and 4 us
        "gaps": pytest.approx(1.0),  # 3 us
        "after": pytest.approx(4.0 + 4.0),  # 5 and 6 us
        "undetected": 0.0,
    }
    assert sum(parts.values()) == pytest.approx(scores["sse"])
    never = [Estimate(e.stamp_ns, e.position, Source.PREDICTED, 0, 1.0) for e in est]
    assert bench.score(never, stamps, truth)["parts"]["undetected"] == pytest.approx(10.0)
    rows = [
        {"rms": 0.5, "parts": {**dict.fromkeys(bench.PARTS, 0.0), "detected": 1.0}},
        {"rms": 2.0, "parts": {**dict.fromkeys(bench.PARTS, 0.0), "after": 3.0}},
    ]
    line = bench.where_errors_lie(rows)
    assert (
        "on detected frames 25 % / 0 %" in line and "after the last detection 75 % / 100 %" in line
    )
    assert "no failures" in bench.where_errors_lie(rows[:1])
    resumed = bench.where_errors_lie([*rows, {"rms": 3.0}])  # a row from an older --json
    assert "over the 2 of 3 sequences" in resumed
    # one estimate (at 2 us, the origin): the rows before it, on it, and after it
    one = [Estimate(2_000, np.zeros(3), Source.DETECTED, 1, 0.1)]
    split = bench.score(one, stamps, truth)["parts"]
    assert split["before"] == pytest.approx(0.0 + 1.0) and split["detected"] == pytest.approx(1.0)
    assert split["after"] == pytest.approx(9.0 + 9.0 + 36.0 + 36.0)
    assert bench.score(est[::-1], stamps, truth)["parts"] == parts  # the order does not matter


def test_the_probe_report_counts_failures_apart_where_the_drone_was_rarely_seen(
    bench: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    # three sequences of one probe: one whose drone gave points in 5 % of frames (out of view),
    # failing; one seen and failing; one seen and passing
    def row(seed: int, method: str, rms: float, seen: float) -> dict[str, object]:
        return {"seed": seed, "probe": "mount+3m", "scenario": "hover", "method": method,
                "rms": rms, "seen": seen}  # fmt: skip

    rows = []
    for method in ("track", "track-causal"):
        rows += [row(1, method, 30.0, 0.05), row(2, method, 2.0, 0.8), row(3, method, 0.2, 1.0)]
    bench.report_probes(rows, ["track", "track-causal"])
    out = capsys.readouterr().out
    assert "2/3" in out  # the table counts every sequence
    assert "mount+3m: 1 sequence(s) with the drone's points in under 10% of frames" in out
    assert "failures among the others: track 1/2, track-causal 1/2" in out
    bench.report_probes([r for r in rows if r["seed"] != 1], ["track"])
    assert "under 10%" not in capsys.readouterr().out  # nothing to set apart: no line
