"""Robustness benchmark: the estimator on hundreds of randomised worlds, and the review's probes.

Each seed draws one world (``cldet.simulate.draw_world``): a scenario kind (fast_pass,
foliage_hover, structure_hover, high_hover, mixed, close), a site (car park, open field, forest
edge, urban canyon, rooftop), the sensor's tilt (0-20 deg) and mount height (0.5-5 m), a sloped
uneven ground, the drone type and the distractors (birds, people, vehicles, rain, wind). The
sequence is simulated in memory (``simulate_world_frames``, points and truth in the tilted
sensor frame; the estimator is NOT told the pose), every method estimates the track, and the
estimate is interpolated linearly to the truth stamps (clamped at the ends).

Seed ranges (see ``cldet.simulate.world``):
    development  10000-19999   look at these, debug on these, tune on these
    evaluation   90000-90299   held out: the default here; run it only to report a result

Methods: ``track-causal`` (the causal per-frame estimate of ``track``, ``est.causal``; "n/a"
when the estimator does not give one; scored from its first estimate on, after the background's
warm-up, with the share of truth rows that leaves printed as its coverage), ``track`` (the refined track) and ``cl-det`` (the
report's baseline). A sequence fails when its RMS 3D error at the truth stamps exceeds 1 m.
Printed per method, overall, per scenario kind, per site and by visibility (the drone
returning a point in under 10 % of frames, or not): sequences, failures with a 95 %
Wilson interval, MSE per coordinate (sum of squared errors / 3N over all truth rows), mean
squared 3D distance (sum / N), median and worst RMS, and "seen": the median fraction of frames
with at least one point on the drone (fast passes and high hovers are sparse by design). Then,
per method, where its summed squared error lies, over all sequences and over the failing ones:
before the estimate's first DETECTED row, in the gaps between detections, on rows whose nearest
estimate is DETECTED (a detection of the chosen track, the drone or not), after the last, or in
sequences with no detection at all (``error_parts``; the rows' ``parts`` in ``--json``).

    python benchmarks/bench_robustness.py --seeds 10000-10119            # development
    python benchmarks/bench_robustness.py                                 # evaluation, 300 worlds
    python benchmarks/bench_robustness.py --seeds 10000-10059 --kinds fast_pass,high_hover \\
        --methods track --json /tmp/rows.json
    python benchmarks/bench_robustness.py --probes --probe-seeds 10000-10002
    python benchmarks/bench_robustness.py --model model.zip              # adds track-model

``--probes`` runs the review's probes on the project's ORIGINAL simulator (``simulate_sequence``
and its six ``SCENARIOS``): 18 sequences per probe (3 seeds x 6 scenarios) for a static 0.3 m
object overhanging the sensor at 67 deg elevation, the sensor tilted 8 deg, tilted 15 deg, the
mount 3 m higher, and sequences of 1.5 s (plus the unperturbed baseline), and prints the
failures out of 18 per method; and, for a probe with sequences whose drone returned points in
under 10 % of frames (a pass below the lowest beam, with the mount 3 m higher), how many, and
the failures among the others. Probe seeds follow the same ranges (default: evaluation).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core per worker process

import argparse  # noqa: E402
import functools  # noqa: E402
import json  # noqa: E402
import multiprocessing  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Iterable, Sequence  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402
from simdata import parse_seeds  # noqa: E402 (benchmarks/simdata.py, beside this script)

METHODS: tuple[str, ...] = ("track-causal", "track", "track-model", "cl-det")
FAIL_RMS_M = 1.0
DEVELOPMENT = "10000-19999"
EVALUATION = "90000-90299"
EVALUATION_PROBES = "90000-90002"
PROBES: dict[str, dict[str, float]] = {
    "baseline": {},
    "overhang-67deg": {"overhang_elevation_deg": 67.0},
    "tilt-8deg": {"tilt_deg": 8.0},
    "tilt-15deg": {"tilt_deg": 15.0},
    "mount+3m": {"mount_offset_m": 3.0},
    "short-1.5s": {},
}
PROBE_DURATION_S = {"short-1.5s": 1.5}


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion k/n."""
    if n == 0:
        return 0.0, 1.0
    p = k / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return max(0.0, centre - half), min(1.0, centre + half)


def at_stamps(estimates: Sequence[Any], stamps_ns: NDArray[np.int64]) -> NDArray[np.float64] | None:
    """Estimates (``stamp_ns``, ``position``; in time order) interpolated linearly to
    ``stamps_ns`` (clamped)."""
    if not estimates:
        return None
    t = np.array([e.stamp_ns for e in estimates], dtype=np.int64)
    pos = np.array([e.position for e in estimates], dtype=np.float64).reshape(-1, 3)
    t0 = int(stamps_ns[0])
    tt = (t - t0).astype(np.float64)
    q = (stamps_ns - t0).astype(np.float64)
    return np.column_stack([np.interp(q, tt, pos[:, k]) for k in range(3)])


PARTS = ("before", "gaps", "detected", "after", "undetected")
PART_NAMES = {
    "before": "before the first detection",
    "gaps": "in gaps",
    "detected": "on detected frames",
    "after": "after the last detection",
    "undetected": "in sequences never detected",
}


def score(
    estimates: Sequence[Any] | None, stamps_ns: NDArray[np.int64], truth: NDArray[np.float64]
) -> dict[str, Any]:
    """A row's scores: ``rms`` (3D error), ``sse`` (sum of squared 3D errors), ``n`` (rows) and
    ``parts`` (``error_parts``); no estimates at all count as the origin."""
    est = sorted(estimates or (), key=lambda e: e.stamp_ns)  # a tie goes to the earlier
    pos = at_stamps(est, stamps_ns)
    if pos is None:
        pos = np.zeros_like(truth)
    sq = np.sum((pos - truth) ** 2, axis=1)
    return {
        "rms": float(np.sqrt(np.mean(sq))),
        "sse": float(np.sum(sq)),
        "n": int(len(sq)),
        "parts": error_parts(est, stamps_ns, sq),
    }


def error_parts(
    estimates: Sequence[Any] | None, stamps_ns: NDArray[np.int64], sq: NDArray[np.float64]
) -> dict[str, float]:
    """The squared 3D errors ``sq`` at ``stamps_ns`` summed by where each truth row lies
    (``PARTS``): before the first DETECTED estimate, after the last, on a row whose nearest
    estimate (``estimates`` in time order) is DETECTED, in the gaps between; all "undetected"
    when no estimate is DETECTED."""
    parts = dict.fromkeys(PARTS, 0.0)
    est = estimates or ()
    t = np.array([e.stamp_ns for e in est], dtype=np.int64)
    detected = np.array([e.source.name == "DETECTED" for e in est], dtype=bool)
    if not detected.any():
        parts["undetected"] = float(sq.sum())
        return parts
    first, last = t[detected][[0, -1]]
    nearest = np.argmin(np.abs(stamps_ns[:, None] - t[None, :]), axis=1)
    where = np.where(
        stamps_ns < first,
        "before",
        np.where(stamps_ns > last, "after", np.where(detected[nearest], "detected", "gaps")),
    )
    for part in ("before", "gaps", "detected", "after"):
        parts[part] = float(sq[where == part].sum())
    return parts


@dataclass(frozen=True)
class Job:
    """One sequence to simulate and estimate."""

    seed: int
    duration_s: float
    methods: tuple[str, ...]
    config: str | None
    probe: str | None = None  # probes mode: the probe's name
    scenario: str | None = None  # probes mode: the original simulator's scenario
    model: str | None = None  # track-model: the model file (`cldet train`)


@functools.cache
def _model(path: str) -> Any:
    from cldet.modelfile import load_model

    return load_model(path)


def _estimate(
    frames: Callable[[], Iterable[Any]],
    method: str,
    config_path: str | None,
    model_path: str | None = None,
) -> tuple[Any, float, str | None]:
    """Run the estimator; (SequenceEstimate or None, seconds, error text or None)."""
    from cldet.config import load_config
    from cldet.core.methods import estimate_sequence

    config = load_config(Path(config_path) if config_path else None, overrides={"method": method})
    model = _model(model_path) if model_path else None
    started = time.perf_counter()
    try:
        _, est = estimate_sequence(frames, config, model)
    except Exception as err:  # a crash is a failed sequence, reported as such
        return None, time.perf_counter() - started, f"{type(err).__name__}: {err}"
    return est, time.perf_counter() - started, None


def _method_rows(
    job: Job,
    frames: Callable[[], Iterable[Any]],
    stamps_ns: NDArray[np.int64],
    truth: NDArray[np.float64],
    common: dict[str, Any],
) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    if "track" in job.methods or "track-causal" in job.methods:
        est, seconds, error = _estimate(frames, "track", job.config)
        results: dict[str, Sequence[Any] | None] = {
            "track": None if est is None else est.estimates,
            "track-causal": None if est is None else getattr(est, "causal", None),
        }
        for method in ("track-causal", "track"):
            if method not in job.methods:
                continue
            chosen = results[method]
            if method == "track-causal" and est is not None and not chosen:
                rows.append({**common, "method": method, "rms": None, "error": "n/a"})
                continue
            coverage = 1.0
            if method == "track-causal" and chosen:
                # the causal estimator has nothing during its warm-up (it says FALLBACK): score
                # the rows from its first estimate on, and report the share of rows scored
                live = [e for e in chosen if e.source.name != "FALLBACK"]
                keep = stamps_ns >= (live[0].stamp_ns if live else np.iinfo(np.int64).max)
                coverage = float(np.mean(keep))
                if live and keep.any():
                    chosen, stamps_m, truth_m = live, stamps_ns[keep], truth[keep]
                else:
                    stamps_m, truth_m = stamps_ns, truth
            else:
                stamps_m, truth_m = stamps_ns, truth
            rows.append(
                {**common, "method": method, **score(chosen, stamps_m, truth_m),
                 "coverage": coverage, "seconds": seconds, "error": error}
            )  # fmt: skip
    if "track-model" in job.methods:
        est, seconds, error = _estimate(frames, "track", job.config, job.model)
        chosen = None if est is None else est.estimates
        rows.append(
            {**common, "method": "track-model", **score(chosen, stamps_ns, truth),
             "seconds": seconds, "error": error}
        )  # fmt: skip
    if "cl-det" in job.methods:
        est, seconds, error = _estimate(frames, "cl-det", job.config)
        chosen = None if est is None else est.estimates
        rows.append(
            {**common, "method": "cl-det", **score(chosen, stamps_ns, truth),
             "seconds": seconds, "error": error}
        )  # fmt: skip
    return rows


def run_world(job: Job) -> list[dict[str, Any]]:
    """Simulate one randomised world and score every method on it."""
    from cldet.simulate import draw_world, simulate_world_frames

    world = draw_world(job.seed)
    started = time.perf_counter()
    frames, truth = simulate_world_frames(world, job.duration_s)
    sim_s = time.perf_counter() - started
    common = {
        "seed": job.seed,
        "kind": world.kind,
        "site": world.site,
        "tilt": round(world.tilt_deg, 2),
        "height": round(world.mount_height_m, 2),
        "slope": round(world.slope_deg, 2),
        "drone": world.class_id,
        "max_speed": round(float(truth.speeds_mps.max()), 2),
        "seen": seen_fraction(truth),
        "sim_seconds": round(sim_s, 2),
    }
    return _method_rows(job, lambda: iter(frames), truth.gt_stamps_ns, truth.gt_positions, common)


def seen_fraction(truth: Any) -> float:
    """The share of the Mid-360's frames in which the drone returned a point to either LiDAR
    (the Avia's per-file counts interpolated to the Mid-360's stamps)."""
    avia = np.interp(truth.lidar_stamps_ns, truth.avia_stamps_ns, truth.avia_drone_points)
    return round(float(np.mean((truth.mid360_drone_points > 0) | (avia > 0))), 3)


def run_probe(job: Job) -> list[dict[str, Any]]:
    """Simulate one sequence of the original simulator with a probe and score every method."""
    from cldet.core.frames import pair_frames
    from cldet.simulate import SCENARIOS, simulate_sequence
    from converters.mmaud import find_sequences, iter_clouds

    assert job.probe is not None and job.scenario is not None
    root = Path(tempfile.mkdtemp(prefix="cldet-probe-"))
    try:
        started = time.perf_counter()
        truth = simulate_sequence(
            root / "val" / "seq0001",
            seed=(job.seed, SCENARIOS.index(job.scenario)),
            duration_s=job.duration_s,
            scenario=job.scenario,
            images=False,
            **PROBES[job.probe],  # type: ignore[arg-type]
        )
        (seq,) = find_sequences(root, splits=["val"])
        frames = list(pair_frames(iter_clouds(seq, "lidar_360"), iter_clouds(seq, "livox_avia")))
        common = {
            "seed": job.seed,
            "probe": job.probe,
            "scenario": job.scenario,
            "seen": seen_fraction(truth),
            "sim_seconds": round(time.perf_counter() - started, 2),
        }
        return _method_rows(
            job, lambda: iter(frames), truth.gt_stamps_ns, truth.gt_positions, common
        )
    finally:
        shutil.rmtree(root, ignore_errors=True)


def _run(job: Job) -> list[dict[str, Any]]:
    return run_probe(job) if job.probe else run_world(job)


def _fmt(v: float | None, width: int = 8) -> str:
    if v is None or not np.isfinite(v):
        return f"{'n/a':>{width}s}"
    if abs(v) >= 1000:
        return f"{v:{width}.0f}"
    return f"{v:{width}.3f}" if abs(v) < 100 else f"{v:{width}.1f}"


def table(
    rows: list[dict[str, Any]], method: str, key: str | None, order: Sequence[str]
) -> list[str]:
    """Lines of one method's table, grouped by ``key`` (None: all sequences)."""
    mine = [r for r in rows if r["method"] == method]
    groups: list[tuple[str, list[dict[str, Any]]]] = []
    if key is not None:
        for name in order:
            g = [r for r in mine if r[key] == name]
            if g:
                groups.append((name, g))
    groups.append(("all", mine))
    lines = []
    for name, g in groups:
        scored = [r for r in g if r["rms"] is not None]
        if not scored:
            lines.append(f"  {name:16s} {len(g):4d}   n/a")
            continue
        rms = np.array([r["rms"] for r in scored])
        fails = int((rms > FAIL_RMS_M).sum())
        lo, hi = wilson(fails, len(rms))
        sse = sum(r["sse"] for r in scored)
        n = sum(r["n"] for r in scored)
        crashed = sum(1 for r in scored if r.get("error"))
        seen = [r["seen"] for r in scored if "seen" in r]
        lines.append(
            f"  {name:16s} {len(rms):4d} {fails:5d} {100 * fails / len(rms):6.1f}% "
            f"[{100 * lo:5.1f}, {100 * hi:5.1f}]% {_fmt(sse / (3 * n), 9)} {_fmt(sse / n, 9)} "
            f"{_fmt(float(np.median(rms)))} {_fmt(float(rms.max()))}"
            + (f" {100 * float(np.median(seen)):6.0f}%" if seen else "")
            + (f"  ({crashed} crashed)" if crashed else "")
        )
    return lines


HEADER = (
    f"  {'group':16s} {'n':>4s} {'fails':>5s} {'rate':>7s} {'95% Wilson':>16s} "
    f"{'MSE/coord':>9s} {'MSE 3D':>9s} {'med RMS':>8s} {'max RMS':>8s} {'seen':>7s}"
)


SEEN_FEW = 0.1
VISIBILITY = ("seen rarely", "seen")


def _visibility(row: dict[str, Any]) -> str:
    """The visibility group of a world: its drone seen (a point in a frame) rarely or not."""
    return VISIBILITY[0] if row.get("seen", 1.0) < SEEN_FEW else VISIBILITY[1]


def where_errors_lie(rows: list[dict[str, Any]]) -> str:
    """The shares of the rows' summed squared error in each of ``PARTS`` (``error_parts``),
    over all rows and over the failing ones ("no failures" where none fails); "" when no row
    carries its parts; rows without (from an older ``--json``, resumed) are counted out."""
    scored = [r for r in rows if r["rms"] is not None]
    with_parts = [r for r in scored if r.get("parts")]
    if not with_parts:
        return ""
    failing = [r for r in with_parts if r["rms"] > FAIL_RMS_M]
    shares = []
    for group in (with_parts, failing):
        total = {p: sum(r["parts"][p] for r in group) for p in PARTS}
        whole = sum(total.values())
        shares.append({p: 100 * total[p] / whole if whole > 0 else 0.0 for p in PARTS})
    line = ", ".join(
        f"{PART_NAMES[p]} {shares[0][p]:.0f} %" + (f" / {shares[1][p]:.0f} %" if failing else "")
        for p in PARTS
    )
    if not failing:
        line += " (no failures)"
    if len(with_parts) < len(scored):
        line += f" (over the {len(with_parts)} of {len(scored)} sequences whose rows carry it)"
    return line


def report(rows: list[dict[str, Any]], methods: Sequence[str], duration_s: float) -> None:
    """Print the overall, per-kind, per-site and visibility tables of every method."""
    from cldet.simulate import KINDS, SITES

    n_seq = len({r["seed"] for r in rows})
    visible = [{**r, "visibility": _visibility(r)} for r in rows]
    print(f"\n{n_seq} randomised sequences of {duration_s} s; fail = RMS 3D error > {FAIL_RMS_M} m")
    print("MSE/coord = sum of squared errors / 3N over all truth rows (m^2); MSE 3D = / N (m^2)")
    print("seen = median fraction of frames with at least one point on the drone (either LiDAR)")
    for method in methods:
        mine = [r for r in rows if r["method"] == method]
        if mine and all(r["rms"] is None for r in mine):
            print(f"\n{method}: n/a (the estimator gives no causal estimates)")
            continue
        print(f"\n{method}, by scenario kind\n{HEADER}")
        print("\n".join(table(rows, method, "kind", KINDS)))
        cover = [r["coverage"] for r in mine if r.get("coverage") is not None]
        if cover and min(cover) < 1.0:
            print(f"{method}: scored from its first estimate on; median coverage "
                  f"{np.median(cover):.3f} of the truth rows (min {min(cover):.3f})")  # fmt: skip
        print(f"{method}, by site\n{HEADER}")
        print("\n".join(table(rows, method, "site", SITES)[:-1]))
        print(
            f"{method}, by visibility (the drone's points in under {SEEN_FEW:.0%} of frames: a"
            f" fast pass mostly out of reach or hidden, where most of the track is a guess)\n{HEADER}"
        )
        print("\n".join(table(visible, method, "visibility", VISIBILITY)[:-1]))  # fmt: skip
        split = where_errors_lie(mine)
        if split:
            print(f"{method}, where the squared error lies (all sequences / failing ones): {split}")
    times: dict[str, list[float]] = {}
    for r in rows:
        if r.get("seconds") is not None:
            times.setdefault("track" if r["method"] == "track-causal" else r["method"], []).append(
                r["seconds"]
            )
    sims = {r["seed"]: r["sim_seconds"] for r in rows}
    print(
        "\nseconds per sequence (median): simulate "
        f"{np.median(list(sims.values())):.2f}"
        + "".join(f", {m} {np.median(v):.2f}" for m, v in times.items())
    )


def report_probes(rows: list[dict[str, Any]], methods: Sequence[str]) -> None:
    """Failures out of the probe's sequences, per probe and method."""
    print(f"\nprobes on the original simulator: failures (RMS > {FAIL_RMS_M} m) / sequences")
    print(f"  {'probe':16s}" + "".join(f" {m:>22s}" for m in methods))
    probes = [p for p in PROBES if any(r["probe"] == p for r in rows)]
    for probe in probes:
        cells = []
        for method in methods:
            mine = [r for r in rows if r["probe"] == probe and r["method"] == method]
            scored = [r["rms"] for r in mine if r["rms"] is not None]
            if not mine:
                cells.append(f"{'':>22s}")
            elif not scored:
                cells.append(f"{'n/a':>22s}")
            else:
                v = np.array(scored)
                cells.append(
                    f"{int((v > FAIL_RMS_M).sum()):>3d}/{len(v):<3d} med {np.median(v):6.3f} m"
                )
        print(f"  {probe:16s}" + "".join(f" {c:>22s}" for c in cells))
    # a probe can put the drone out of the sensors' view (3 m higher, a pass below the
    # Mid-360's lowest beam): say how many, and the failures among the others
    for probe in probes:
        mine = [r for r in rows if r["probe"] == probe and r["rms"] is not None]
        rare = {_key(r) for r in mine if _visibility(r) == VISIBILITY[0]}
        if not rare:
            continue
        others = [r for r in mine if _key(r) not in rare]
        rest = []
        for method in methods:
            v = [r["rms"] for r in others if r["method"] == method]
            rest.append(f"{method} {sum(x > FAIL_RMS_M for x in v)}/{len(v)}")
        print(
            f"  {probe}: {len(rare)} sequence(s) with the drone's points in under {SEEN_FEW:.0%}"
            f" of frames; failures among the others: {', '.join(rest)}"
        )


def _key(row: dict[str, Any]) -> tuple[Any, ...]:
    """Which sequence a row belongs to."""
    return (row["seed"], row.get("probe"), row.get("scenario"))


def _key_of(job: Job) -> tuple[Any, ...]:
    return (job.seed, job.probe, job.scenario)


def _write_json(path: Path, rows: list[dict[str, Any]]) -> None:
    """Write the rows to ``path`` through a temporary file (an interrupted run keeps them)."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(rows, indent=1))
    tmp.replace(path)


def _import_worker_code() -> None:
    """Import what the workers run before they fork: a worker replaced after
    ``maxtasksperchild`` sequences then runs the code this run started with, not whatever is on
    disk by then (an edit during a long run would otherwise mix two versions in one table)."""
    import cldet.core.frames  # noqa: F401
    import cldet.core.methods  # noqa: F401
    import converters.mmaud  # noqa: F401


def main(argv: list[str] | None = None) -> None:
    """Parse the options, run the sequences on the workers, print the tables."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--seeds",
        type=parse_seeds,
        default=None,
        help=f"world seeds (default {EVALUATION}, evaluation; development: {DEVELOPMENT})",
    )
    parser.add_argument("--duration", type=float, default=8.0, help="seconds per sequence")
    parser.add_argument("--workers", type=int, default=2, help="worker processes")
    parser.add_argument("--methods", default=",".join(METHODS), help="comma-separated subset")
    parser.add_argument("--kinds", help="comma-separated scenario kinds to keep")
    parser.add_argument("--sites", help="comma-separated sites to keep")
    parser.add_argument("--config", type=Path, help="estimator configuration (YAML)")
    parser.add_argument(
        "--model", type=Path, help="a model from `cldet train`: adds the method track-model"
    )
    parser.add_argument(
        "--json", type=Path, help="write the per-sequence rows here (updated after each sequence)"
    )
    parser.add_argument(
        "--resume", action="store_true", help="keep the rows already in --json, run the rest"
    )
    parser.add_argument(
        "--probes",
        nargs="?",
        const=",".join(PROBES),
        default=None,
        metavar="NAMES",
        help="the probes on the original simulator: all, or the comma-separated NAMES among"
        f" {', '.join(PROBES)}",
    )
    parser.add_argument(
        "--probe-seeds",
        type=parse_seeds,
        default=None,
        help=f"3 seeds x 6 scenarios per probe (default {EVALUATION_PROBES})",
    )
    parser.add_argument(
        "--probe-duration", type=float, default=5.5, help="seconds per probe sequence"
    )
    parser.add_argument("--quiet", action="store_true", help="no per-sequence lines")
    args = parser.parse_args(argv)

    from cldet.simulate import KINDS, SCENARIOS, SITES, draw_world

    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        parser.error(f"unknown method(s) {', '.join(unknown)}: expected {', '.join(METHODS)}")
    config = str(args.config) if args.config else None
    model = str(args.model) if args.model else None
    if model is None:
        methods = tuple(m for m in methods if m != "track-model")
    elif "track-model" not in methods:
        methods = (*methods, "track-model")
    jobs: list[Job] = []
    if args.probes:
        seeds = args.probe_seeds or parse_seeds(EVALUATION_PROBES)
        names = args.probes.split(",")
        unknown = [n for n in names if n not in PROBES]
        if unknown:
            parser.error(f"unknown probe(s) {', '.join(unknown)}: expected {', '.join(PROBES)}")
        for probe in names:
            duration = PROBE_DURATION_S.get(probe, args.probe_duration)
            for scenario in SCENARIOS:
                for seed in seeds:
                    jobs.append(Job(seed, duration, methods, config, probe, scenario, model))
    else:
        seeds = args.seeds or parse_seeds(EVALUATION)
        kinds = set(args.kinds.split(",")) if args.kinds else set(KINDS)
        sites = set(args.sites.split(",")) if args.sites else set(SITES)
        bad = (kinds - set(KINDS)) | (sites - set(SITES))
        if bad:
            parser.error(f"unknown kind/site {', '.join(sorted(bad))}")
        for seed in seeds:
            world = draw_world(seed)
            if world.kind in kinds and world.site in sites:
                jobs.append(Job(seed, args.duration, methods, config, model=model))
    rows: list[dict[str, Any]] = []
    if args.resume:
        if not args.json:
            parser.error("--resume needs --json")
        if args.json.exists():
            rows = [
                r
                for r in json.loads(args.json.read_text())
                if _key(r) in {_key_of(j) for j in jobs}
            ]
            done = {_key(r) for r in rows}
            jobs = [j for j in jobs if _key_of(j) not in done]
            print(f"resuming: {len(done)} sequences already in {args.json}", file=sys.stderr)
    if not jobs and not rows:
        parser.error("no sequences to run")
    started = time.perf_counter()
    pool = None
    if args.workers > 1:
        _import_worker_code()
        pool = multiprocessing.get_context("fork").Pool(args.workers, maxtasksperchild=50)
        results: Iterable[list[dict[str, Any]]] = pool.imap_unordered(_run, jobs)
    else:
        results = map(_run, jobs)
    try:
        for i, job_rows in enumerate(results):
            rows.extend(job_rows)
            if args.json:
                _write_json(args.json, rows)
            if not args.quiet and job_rows:
                r0 = job_rows[0]
                what = (
                    f"{r0['probe']} {r0['scenario']}"
                    if args.probes
                    else f"{r0['kind']} {r0['site']}"
                )
                cells = ", ".join(f"{r['method']} {_fmt(r['rms'], 0).strip()}" for r in job_rows)
                print(
                    f"[{i + 1}/{len(jobs)}] seed {r0['seed']} {what}: {cells}"
                    f" (sim {r0['sim_seconds']:.1f} s)",
                    file=sys.stderr,
                    flush=True,
                )
    finally:
        if pool is not None:
            pool.close()
            pool.join()
    elapsed = time.perf_counter() - started
    rows.sort(key=lambda r: (r.get("probe") or "", r.get("scenario") or "", r["seed"], r["method"]))
    if args.probes:
        report_probes(rows, methods)
    else:
        report(rows, methods, args.duration)
    print(f"\n{len(jobs)} sequences in {elapsed:.0f} s on {args.workers} worker(s)")
    if args.json:
        _write_json(args.json, rows)


if __name__ == "__main__":
    main()
