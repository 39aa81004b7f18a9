"""``demo``: the whole job on a small generated dataset, both methods scored side by side.

simulate -> convert -> annotate the train split and fit the bias correction on it (calibrate)
-> annotate the test split with ``track`` (calibrated) and with ``cl-det`` -> export the challenge
CSV for each -> evaluate each against the simulator's truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from cldet.calibrate import Calibration, calibrate_logs
from cldet.config import load_config
from cldet.errors import CldetError
from cldet.evaluate import Evaluation, evaluate_results
from cldet.export import export_results
from cldet.pipeline import annotate_logs
from cldet.progress import NullProgress, Progress
from cldet.results import read_truth
from cldet.simulate import simulate_dataset
from converters.mcap_convert import convert_dataset

METHODS = ("track", "cl-det")


@dataclass(frozen=True)
class MethodRun:
    """One method's run over the demo logs."""

    method: str
    results_csv: Path
    evaluation: Evaluation
    frames: int
    seconds: float  # summed over the logs' own wall times (per-core figure)
    rrd: tuple[Path, ...]

    @property
    def predictions_per_s(self) -> float:
        """Estimates per second of one core's time, end to end (MCAP in, channels and .rrd out)."""
        return self.frames / self.seconds if self.seconds > 0 else float("inf")


@dataclass(frozen=True)
class DemoReport:
    """Everything the demo produced."""

    root: Path
    data: Path
    runs: tuple[MethodRun, ...]
    calibration: Calibration  # the bias of `track`, fitted on the train split


def run_demo(
    root: Path,
    *,
    preset: str = "small",
    seed: int = 0,
    workers: int = 1,
    progress: Progress | None = None,
) -> DemoReport:
    """Run the whole pipeline under ``root`` (created; an earlier demo's dataset is reused).

    Layout: ``root/data`` (the simulated dataset), ``root/logs/test`` (converted), and per method
    ``root/<method>/`` with the annotated logs, their ``.rrd`` recordings (``track`` only) and
    ``mmaud_results.csv``.
    """
    progress = progress or NullProgress()
    root = Path(root)
    data = root / "data"
    if not (data / "test_timestamps.csv").is_file():
        if data.exists():
            raise CldetError(
                f"{data} exists but holds no test_timestamps.csv: remove it or choose another folder"
            )
        simulate_dataset(data, preset=preset, seed=seed, progress=progress)
    converted = convert_dataset(
        data,
        root / "logs",
        splits=["train", "test"],
        workers=workers,
        overwrite=True,
        progress=progress,
    )
    if not converted.ok:
        raise CldetError("conversion failed:\n" + converted.describe())
    logs = sorted(p for p in converted.converted if p.parent.name == "test")
    train = sorted(p for p in converted.converted if p.parent.name == "train")
    # the bias correction of `track` is fitted on the train split, as on the real data
    _, failures = annotate_logs(train, write_rrd=False, workers=workers, progress=progress)
    if failures:
        raise CldetError("annotate (train) failed: " + "; ".join(m for _, m in failures))
    calibration = calibrate_logs(train)
    truth = read_truth(data / "test_truth.csv")
    runs = []
    for method in METHODS:
        out_dir = root / method
        out_dir.mkdir(parents=True, exist_ok=True)
        outputs = [out_dir / log.name for log in logs]
        overrides: dict[str, object] = {"method": method}
        if method == "track":
            overrides["bias"] = calibration.bias.model_dump()
        reports, failures = annotate_logs(
            logs,
            config=load_config(overrides=overrides),
            outputs=outputs,
            write_rrd=method == "track",
            workers=workers,
            progress=progress,
        )
        if failures:
            raise CldetError(
                f"annotate ({method}) failed: "
                + "; ".join(f"{log}: {msg}" for log, msg in failures)
            )
        results_csv = out_dir / "mmaud_results.csv"
        export_results(outputs, results_csv, data / "test_timestamps.csv", overwrite=True)
        runs.append(
            MethodRun(
                method=method,
                results_csv=results_csv,
                evaluation=evaluate_results(results_csv, truth),
                frames=sum(r.frames for r in reports),
                seconds=sum(r.seconds for r in reports),
                rrd=tuple(r.rrd for r in reports if r.rrd is not None),
            )
        )
    return DemoReport(root=root, data=data, runs=tuple(runs), calibration=calibration)


def comparison_rows(report: DemoReport) -> list[tuple[str, ...]]:
    """The score table: one row per metric, one column per method."""

    def fmt(value: float | None, digits: int = 4) -> str:
        return "-" if value is None else f"{value:.{digits}f}"

    rows: list[tuple[str, ...]] = [("metric", *(run.method for run in report.runs))]
    metrics: list[tuple[str, list[str]]] = [
        (
            "MSE per coordinate (m^2, sum sq err / 3N)",
            [fmt(r.evaluation.mse_per_coordinate_m2) for r in report.runs],
        ),
        (
            "mean squared 3D distance (m^2)",
            [fmt(r.evaluation.mean_squared_distance_m2) for r in report.runs],
        ),
        ("RMSE 3D (m)", [fmt(r.evaluation.rmse_m) for r in report.runs]),
        ("median 3D error (m)", [fmt(r.evaluation.median_error_m) for r in report.runs]),
        ("95th pct 3D error (m)", [fmt(r.evaluation.p95_error_m) for r in report.runs]),
        ("accuracy (constant class)", [fmt(r.evaluation.accuracy, 3) for r in report.runs]),
        ("rows scored", [str(r.evaluation.n_matched) for r in report.runs]),
        (
            "predictions/s per core (with start-up)",
            [f"{r.predictions_per_s:.0f}" for r in report.runs],
        ),
    ]
    rows.extend((name, *values) for name, values in metrics)
    return rows
