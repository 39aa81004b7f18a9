"""Shared fixtures: the real challenge sample (skipped when absent), simulated MCAP logs."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
SAMPLE_ROOT = REPO_ROOT.parent / "shared" / "mmaud-sample"


@pytest.fixture(scope="session")
def real_sample() -> Path:
    """The real MMAUD sample root (``val/seq0001`` and ``reference/seq0001``)."""
    if not (SAMPLE_ROOT / "val" / "seq0001").is_dir():
        pytest.skip(
            f"real MMAUD sample not found at {SAMPLE_ROOT} (expected ../shared/mmaud-sample)"
        )
    return SAMPLE_ROOT


def simulated_log(
    root: Path,
    seed: int,
    scenario: str = "mixed",
    duration_s: float = 4.0,
    class_id: int | None = None,
) -> Path:
    """Simulate one training sequence (with ground truth and class) under ``root`` and convert
    it to a log; ``class_id`` forces the drone type (default: drawn from the seed)."""
    from cldet.io.mcap_write import LogWriter
    from cldet.simulate import simulate_sequence
    from converters.mcap_convert import convert_sequence
    from converters.mmaud import find_sequences

    tag = f"{seed}-{scenario}" + ("" if class_id is None else f"-class{class_id}")
    data = root / f"data-{tag}"
    simulate_sequence(
        data / "train" / "seq0001",
        seed=seed,
        duration_s=duration_s,
        scenario=scenario,
        images=False,
        class_id=class_id,
    )
    (seq,) = find_sequences(data)
    log = root / f"seq{tag}.mcap"
    with open(log, "wb") as f, LogWriter(f) as writer:
        convert_sequence(seq, writer)
    return log


@pytest.fixture(scope="session")
def make_log() -> Callable[..., Path]:
    """``make_log(root, seed, scenario="mixed", duration_s=4.0, class_id=None)``: a simulated,
    converted log."""
    return simulated_log
