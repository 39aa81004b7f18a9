"""Shared fixtures: the real challenge sample (skipped when absent)."""

from __future__ import annotations

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
