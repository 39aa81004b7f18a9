"""Benchmark: both estimation methods on the same logs, in one run, on one core.

Prints one table: predictions/s end to end (MCAP in, result channels out, with and without the
Rerun recording) and the challenge scores (MSE both ways, RMSE, accuracy) against the truth.

    python benchmarks/bench_annotate.py                   # simulates the `full` preset in a temp dir
    python benchmarks/bench_annotate.py --data DATASET    # an existing dataset with test_truth.csv
    python benchmarks/bench_annotate.py --preset small    # quicker
    python benchmarks/bench_annotate.py --all-points      # also cl-det over every valid point

Everything runs in this process, one log after another (one core); the numba kernels are
compiled by a warm-up run on the first log before anything is timed. The bias correction of
``track+bias`` is fitted with ``cldet calibrate`` on the dataset's train split.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import shutil
import tempfile
import time
from pathlib import Path

from machine import cpu_model  # benchmarks/machine.py (the script's folder is on the path)

from cldet.calibrate import calibrate_logs
from cldet.config import load_config
from cldet.evaluate import evaluate_results
from cldet.export import export_results
from cldet.pipeline import annotate_log
from cldet.results import read_truth
from cldet.simulate import simulate_dataset
from converters.mcap_convert import convert_dataset


def main() -> None:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", type=Path, help="dataset root with test/ and test_truth.csv")
    parser.add_argument(
        "--preset", default="full", choices=["small", "full"], help="simulated preset"
    )
    parser.add_argument("--seed", type=int, default=2024, help="simulation seed")
    parser.add_argument("--split", default="test", help="split to annotate and score")
    parser.add_argument("--keep", type=Path, help="keep the work folder here instead of a temp dir")
    parser.add_argument(
        "--all-points",
        action="store_true",
        help="also time cl-det without environment removal (DBSCAN over every valid point, "
        "the cost regime of the report's 14.9 predictions/s; slow)",
    )
    args = parser.parse_args()

    work = args.keep or Path(tempfile.mkdtemp(prefix="cldet-bench-"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        data = args.data
        if data is None:
            data = work / "data"
            if not data.exists():
                t0 = time.perf_counter()
                simulate_dataset(data, preset=args.preset, seed=args.seed)
                print(
                    f"simulated preset {args.preset!r} (seed {args.seed}) in {time.perf_counter() - t0:.1f} s"
                )
        report = convert_dataset(
            data, work / "logs", splits=[args.split, "train"], workers=1, overwrite=True
        )
        logs = sorted(p for p in report.converted if p.parent.name == args.split)
        train = sorted(p for p in report.converted if p.parent.name == "train")
        print(f"converted {len(logs)} {args.split} and {len(train)} train sequences")
        truth = read_truth(data / f"{args.split}_truth.csv")
        query = data / f"{args.split}_timestamps.csv"

        annotate_log(logs[0], output=work / "warmup.mcap", write_rrd=True)  # numba compile
        cldet_config = load_config(overrides={"method": "cl-det"})
        annotate_log(logs[0], config=cldet_config, output=work / "warmup.mcap")

        # the bias correction is fitted on the train split (annotated with zero bias), never by hand
        for log in train:
            annotate_log(log, write_rrd=False)
        calibration = calibrate_logs(train)
        print(f"calibrated on train: {calibration.describe()}")
        bias = {"bias": calibration.bias.model_dump()}

        variants = [
            ("track", "track+bias", True, bias),
            ("track", "track+bias", False, bias),
            ("track", "track", False, {}),
            ("cl-det", "cl-det", True, {}),
            ("cl-det", "cl-det", False, {}),
        ]
        if args.all_points:
            every = {"baseline": {"environment": "none"}}
            variants += [
                ("cl-det", "cl-det-all", True, every),
                ("cl-det", "cl-det-all", False, every),
            ]
        rows = []
        speed: dict[tuple[str, bool], float] = {}
        for method, label, rrd, extra in variants:
            config = load_config(overrides={"method": method, **extra})
            out_dir = work / f"{label}-{'rrd' if rrd else 'nrrd'}"
            out_dir.mkdir(exist_ok=True)
            outputs = [out_dir / log.name for log in logs]
            frames = 0
            t0 = time.perf_counter()
            for log, out in zip(logs, outputs, strict=True):
                frames += annotate_log(log, config=config, output=out, write_rrd=rrd).frames
            seconds = time.perf_counter() - t0
            speed[(label, rrd)] = frames / seconds
            results = out_dir / "mmaud_results.csv"
            export_results(outputs, results, query if query.exists() else None, overwrite=True)
            ev = evaluate_results(results, truth)
            rows.append((label, "yes" if rrd else "no", frames, seconds, frames / seconds, ev))

        print()
        print(
            f"cldet annotate benchmark, {dt.date.today()}, {cpu_model()}, {os.cpu_count()} cores (1 used)"
        )
        print(f"data: {data} ({args.split} split, {len(logs)} sequences)")
        header = (
            f"{'method':<10} {'rrd':<4} {'frames':>6} {'seconds':>8} {'pred/s':>7} "
            f"{'MSE/coord m^2':>13} {'MSD 3D m^2':>11} {'RMSE m':>8} {'p95 m':>7} {'max m':>7} {'acc':>5}"
        )
        print(header)
        print("-" * len(header))
        for method, rrd_text, frames, seconds, rate, ev in rows:
            acc = "-" if ev.accuracy is None else f"{ev.accuracy:.2f}"
            print(
                f"{method:<10} {rrd_text:<4} {frames:>6} {seconds:>8.2f} {rate:>7.0f} "
                f"{ev.mse_per_coordinate_m2:>13.4f} {ev.mean_squared_distance_m2:>11.4f} {ev.rmse_m:>8.3f} "
                f"{ev.p95_error_m:>7.3f} {ev.max_error_m:>7.3f} {acc:>5}"
            )
        track_mse = rows[0][5].mse_per_coordinate_m2
        base_mse = rows[3][5].mse_per_coordinate_m2
        print()
        print(
            "speed track+bias / cl-det: "
            f"{speed[('track+bias', True)] / speed[('cl-det', True)]:.1f}x with .rrd, "
            f"{speed[('track+bias', False)] / speed[('cl-det', False)]:.1f}x without"
        )
        print(f"MSE per coordinate cl-det / track+bias: {base_mse / track_mse:.0f}x")
        if args.all_points:
            print(
                "speed track+bias / cl-det-all (DBSCAN over every valid point): "
                f"{speed[('track+bias', True)] / speed[('cl-det-all', True)]:.1f}x with .rrd, "
                f"{speed[('track+bias', False)] / speed[('cl-det-all', False)]:.1f}x without"
            )
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
