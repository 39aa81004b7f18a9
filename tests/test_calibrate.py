"""``calibrate``: the bias fitted from annotated training logs, and its refusals."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from cldet.calibrate import calibrate_logs
from cldet.cli import app
from cldet.config import load_config
from cldet.errors import CldetError
from cldet.pipeline import annotate_log


@pytest.fixture(scope="module")
def train_logs(
    tmp_path_factory: pytest.TempPathFactory, make_log: Callable[..., Path]
) -> list[Path]:
    root = tmp_path_factory.mktemp("calibrate")
    logs = [
        make_log(root, seed, scenario)
        for seed, scenario in ((8101, "close_pass"), (8102, "person"))
    ]
    for log in logs:
        annotate_log(log, write_rrd=False)
    return logs


def test_the_fit_points_away_from_the_sensor_and_up_and_reduces_the_error(
    train_logs: list[Path],
) -> None:
    calibration = calibrate_logs(train_logs)
    # the simulator puts the prism ~0.15 m above the body and the LiDAR sees the near face
    assert 0.0 < calibration.bias.along_ray_m < 0.5
    assert 0.05 < calibration.bias.z_m < 0.3
    assert calibration.rms_after_m < calibration.rms_before_m
    assert calibration.detections > 20


def test_cli_writes_a_config_that_annotate_accepts(train_logs: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "bias.yaml"
    result = CliRunner().invoke(app, ["calibrate", *map(str, train_logs), "-o", str(out)])
    assert result.exit_code == 0, result.output
    bias = yaml.safe_load(out.read_text())["bias"]
    assert load_config(out).bias.z_m == pytest.approx(bias["z_m"])
    again = CliRunner().invoke(app, ["calibrate", *map(str, train_logs), "-o", str(out)])
    assert again.exit_code == 1 and "exists" in again.output


def test_refuses_logs_annotated_with_a_bias_or_not_annotated(
    train_logs: list[Path], tmp_path: Path, make_log: Callable[..., Path]
) -> None:
    biased = tmp_path / "biased.mcap"
    annotate_log(
        train_logs[0],
        config=load_config(overrides={"bias": {"z_m": 0.1}}),
        output=biased,
        write_rrd=False,
    )
    with pytest.raises(CldetError, match="annotated with a bias correction"):
        calibrate_logs([biased])
    raw = make_log(tmp_path, 8103, duration_s=2.0)
    with pytest.raises(CldetError, match="has not been annotated"):
        calibrate_logs([raw])
    with pytest.raises(CldetError, match="at least one"):
        calibrate_logs([])
