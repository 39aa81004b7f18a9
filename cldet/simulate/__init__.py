"""Synthetic MMAUD-like datasets in exactly the challenge layout, with ground truth.

``simulate_dataset`` writes ``train/``, ``val/``, ``test/`` and the CSVs; ``simulate_sequence``
writes one sequence folder for one scenario (tests use it with fresh seeds).
"""

from cldet.simulate.dataset import (
    PRESETS,
    PRISM_OFFSET_M,
    SequenceTruth,
    SimulationSummary,
    simulate_dataset,
    simulate_sequence,
)
from cldet.simulate.flight import DRONE_TYPES, SCENARIOS, DroneType

__all__ = [
    "DRONE_TYPES",
    "PRESETS",
    "PRISM_OFFSET_M",
    "SCENARIOS",
    "DroneType",
    "SequenceTruth",
    "SimulationSummary",
    "simulate_dataset",
    "simulate_sequence",
]
