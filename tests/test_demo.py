"""``cldet demo``: the README's main command runs to the end and prints both methods' scores."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from cldet.cli import app


@pytest.mark.slow
def test_demo_runs_end_to_end_and_prints_both_scores(tmp_path: Path) -> None:
    root = tmp_path / "demo"
    result = CliRunner().invoke(app, ["demo", str(root), "--workers", "1"])
    assert result.exit_code == 0, result.output
    assert "MSE per coordinate" in result.output
    header = next(line for line in result.output.splitlines() if line.startswith("metric"))
    assert header.split()[1:] == ["track", "cl-det"]
    mse = next(line for line in result.output.splitlines() if line.startswith("MSE per coordinate"))
    track_mse, cldet_mse = (float(v) for v in mse.split()[-2:])
    assert track_mse < cldet_mse
    for method in ("track", "cl-det"):
        assert (root / method / "mmaud_results.csv").is_file()
    assert "rerun " in result.output and list((root / "track").glob("*.rrd"))
    # a second run reuses the dataset and still works
    again = CliRunner().invoke(app, ["demo", str(root), "--workers", "1"])
    assert again.exit_code == 0, again.output
