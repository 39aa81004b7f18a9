"""Train the default drone-vs-clutter scorer (``cldet/core/prior_scorer.json``) on simulated
randomised worlds of the development seeds.

Each seed draws one world (``cldet.simulate.draw_world``: site, tilt, mount, ground, flight,
distractors), simulated in memory for ``--duration`` seconds; the estimator's per-frame pass
makes its candidate tracks, which are matched to the world's truth exactly as ``cldet train``
matches a labelled log's (``cldet.train.label_candidates``: the drone's, median within 1 m;
clutter, beyond 3 m); the scorer is ``cldet train``'s (``cldet.train.fit_track_scorer``). Per
world the labelled features are kept under ``--cache`` (so a second run, or one stopped and
started again, only fits). Never run it on the evaluation seeds (90000-90299): the robustness
benchmark reports on those.

    python3 benchmarks/train_prior.py                       # seeds 10200-10599, 2 workers
    python3 benchmarks/train_prior.py --seeds 10200-10999 --workers 16 --out /tmp/prior.json

The per-frame pass must be the one the scorer will be used with: after a change to it
(background, clustering, tracking), train again.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core per worker process

import argparse  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import multiprocessing  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from simdata import parse_seeds  # noqa: E402 (benchmarks/simdata.py, beside this script)

DEFAULT_SEEDS = "10200-10599"
PRIOR_FLOOR = 0.1  # p = 0 still keeps a tenth of the hand-set factors (see cldet.core.prior)


def _collect(job: tuple[int, float, Path]) -> tuple[int, float]:
    """Simulate one world, run the per-frame pass, store its labelled track features."""
    seed, duration, cache = job
    out = cache / f"{seed}.npz"
    if out.exists():
        return seed, 0.0
    from cldet.config import load_config
    from cldet.core.estimator import TrackEstimator
    from cldet.simulate import simulate_world_frames
    from cldet.train import label_candidates

    started = time.perf_counter()
    frames, truth = simulate_world_frames(seed, duration)
    config = load_config(None)
    estimator = TrackEstimator(config)
    for frame in frames:
        estimator.register_frame(frame)
    sample = label_candidates(
        Path(f"world{seed}"),
        estimator.candidates(),
        truth.gt_stamps_ns,
        truth.gt_positions,
        None,
        config,
    )
    partial = cache / f".{seed}.partial.npz"
    np.savez(partial, features=sample.features, hits=sample.hits, labels=sample.labels)
    partial.rename(out)
    return seed, time.perf_counter() - started


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", default=DEFAULT_SEEDS, help="development world seeds")
    parser.add_argument("--duration", type=float, default=8.0, help="seconds per world")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument(
        "--cache", type=Path, default=Path(".cldet-prior-cache"), help="per-world features"
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path(__file__).resolve().parents[1] / "cldet" / "core" / "prior_scorer.json",
    )
    args = parser.parse_args(argv)
    from cldet.simulate.world import EVALUATION_SEEDS

    seeds = parse_seeds(args.seeds)
    held_out = sorted(set(seeds) & set(EVALUATION_SEEDS))
    if held_out:
        parser.error(
            f"seeds {held_out[0]}..{held_out[-1]} are evaluation seeds: never train on them"
        )
    cache = args.cache / f"{args.duration:g}s"
    cache.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    jobs = [(s, args.duration, cache) for s in seeds]
    # the workers' code imported before they fork: a worker replaced after maxtasksperchild
    # worlds runs the code this run started with, not whatever is on disk by then
    import cldet.core.estimator  # noqa: F401
    import cldet.train  # noqa: F401

    with multiprocessing.get_context("fork").Pool(args.workers, maxtasksperchild=50) as pool:
        for k, (seed, seconds) in enumerate(pool.imap_unordered(_collect, jobs), 1):
            print(f"[{k}/{len(jobs)}] world {seed}: {seconds:.1f} s", file=sys.stderr)
    collect_s = time.perf_counter() - started

    from cldet.core.prior import PRIOR_FORMAT, parse_prior, prior_json
    from cldet.core.trees import TreeEnsemble
    from cldet.train import _TREE_PARAMS, fit_track_scorer

    parts = [np.load(cache / f"{s}.npz") for s in seeds]
    x = np.concatenate([p["features"].reshape(-1, parts[0]["features"].shape[-1]) for p in parts])
    y = np.concatenate([p["labels"] for p in parts]).astype(np.int64)
    h = np.concatenate([p["hits"] for p in parts])
    fit_started = time.perf_counter()
    trees = TreeEnsemble.from_sklearn(fit_track_scorer(x, y, h))
    fit_s = time.perf_counter() - fit_started
    kept = y >= 0
    p = trees.predict_proba(x[kept])[:, 1]
    accuracy = float(np.mean((p > 0.5) == (y[kept] == 1)))
    info = {
        "seeds": args.seeds,
        "worlds": len(seeds),
        "duration_s": args.duration,
        "tracks": {"drone": int((y == 1).sum()), "clutter": int((y == 0).sum())},
        "tree_params": _TREE_PARAMS,
        "trained": datetime.date.today().isoformat(),
        "format": PRIOR_FORMAT,
    }
    doc = prior_json(trees, PRIOR_FLOOR, info)
    parse_prior(json.loads(json.dumps(doc)))  # what load_prior will read
    tmp = args.out.with_name(args.out.name + ".partial")
    tmp.write_text(json.dumps(doc, separators=(",", ":")) + "\n", encoding="utf-8")
    tmp.replace(args.out)
    print(
        f"{len(seeds)} worlds ({collect_s:.0f} s), {info['tracks']['drone']} drone and"
        f" {info['tracks']['clutter']} clutter tracks; fitted in {fit_s:.1f} s; training"
        f" accuracy {accuracy:.3f} (per track, unweighted); wrote {args.out}"
        f" ({args.out.stat().st_size / 1e3:.0f} kB)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
