"""``calibrate``: fit the centroid bias correction from annotated training logs and their truth.

A LiDAR sees only the near face of the drone and the ground truth is a prism above the body, so
detected centroids sit nearer the sensor and lower than the truth. The correction (two numbers:
along the ray, and in z; see :mod:`cldet.core.bias`) is fitted by least squares on the training
split, never tuned by hand, and written as a YAML configuration for ``cldet annotate --config``.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from cldet.config import BiasConfig
from cldet.core.bias import apply_bias, detection_pairs, fit_bias_sequences
from cldet.core.trajectory import rms
from cldet.errors import CldetError
from cldet.io import topics
from cldet.io.mcap_read import open_log
from cldet.results import write_atomic
from cldet.types import Estimate, PositionSample


@dataclass(frozen=True)
class Calibration:
    """The fitted bias and how much it helps on the data it was fitted on."""

    bias: BiasConfig
    logs: int
    detections: int  # detected estimates with truth around them
    rms_before_m: float  # detected estimates vs interpolated truth, before the correction
    rms_after_m: float

    def describe(self) -> str:
        """One line for the terminal."""
        return (
            f"bias along the ray {self.bias.along_ray_m:+.3f} m, in z {self.bias.z_m:+.3f} m "
            f"(from {self.detections} detections in {self.logs} logs; RMS of detections vs truth "
            f"{self.rms_before_m:.3f} m -> {self.rms_after_m:.3f} m)"
        )


def _read(log: Path) -> tuple[list[Estimate], list[PositionSample]]:
    with open_log(log) as reader:
        meta = reader.metadata().get(topics.METADATA_CONFIG)
        if meta is None:
            raise CldetError(
                f"{log} has not been annotated (no {topics.METADATA_CONFIG} metadata): run `cldet annotate` first"
            )
        bias = json.loads(meta.get("config", "{}")).get("bias", {})
        if any(float(v) != 0.0 for v in bias.values()):
            raise CldetError(
                f"{log} was annotated with a bias correction {bias}: annotate with zero bias to calibrate"
            )
        found = reader.list_topics()
        if not found.get(topics.GROUND_TRUTH):
            raise CldetError(
                f"{log} has no {topics.GROUND_TRUTH} messages: calibrate on training logs"
            )
        estimates = [e for e, _ in reader.iter_estimates()]
        truth = list(reader.iter_positions(topics.GROUND_TRUTH))
    return estimates, truth


def _rms(
    pairs: Sequence[tuple[list[Estimate], list[PositionSample]]], bias: BiasConfig
) -> tuple[float, int]:
    """RMS distance (metres) of the corrected detections to the truth, and their number."""
    errors = [np.zeros(0)]
    for estimates, truth in pairs:
        if len(truth) < 2:
            continue
        detected, true = detection_pairs(estimates, truth)
        errors.append(np.linalg.norm(apply_bias(detected, bias) - true, axis=1))
    all_errors = np.concatenate(errors)
    return rms(all_errors), len(all_errors)


def calibrate_logs(logs: Sequence[Path]) -> Calibration:
    """Fit the bias from annotated training logs (``/cldet/estimate`` and ``/ground_truth``).

    Raises:
        CldetError: a log is not annotated, was annotated with a bias already, has no ground
            truth, or there are too few detections to fit.
    """
    if not logs:
        raise CldetError("calibrate needs at least one annotated training log")
    pairs = [_read(Path(log)) for log in logs]
    bias = fit_bias_sequences(pairs)
    before, n = _rms(pairs, BiasConfig())
    after, _ = _rms(pairs, bias)
    return Calibration(
        bias=bias, logs=len(logs), detections=n, rms_before_m=before, rms_after_m=after
    )


def write_bias_config(calibration: Calibration, path: Path, *, overwrite: bool = False) -> None:
    """Write ``bias:`` as a YAML configuration for ``cldet annotate --config``, atomically."""
    text = (
        "# fitted by `cldet calibrate` on "
        f"{calibration.logs} training logs ({calibration.detections} detections)\n"
        + yaml.safe_dump(
            {
                "bias": {
                    "along_ray_m": round(calibration.bias.along_ray_m, 4),
                    "z_m": round(calibration.bias.z_m, 4),
                }
            },
            sort_keys=False,
        )
    )

    def write(tmp: Path) -> None:
        tmp.write_text(text)

    write_atomic(path, write, overwrite=overwrite)
