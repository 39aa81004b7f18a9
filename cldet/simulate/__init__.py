"""Synthetic MMAUD-like datasets in exactly the challenge layout, with ground truth.

``simulate_dataset`` writes ``train/``, ``val/``, ``test/`` and the CSVs; ``simulate_sequence``
writes one sequence folder for one scenario (tests use it with fresh seeds).

Randomised worlds (domain randomisation for robustness benchmarks): ``draw_world(seed)`` draws a
:class:`World` (scenario kind, site, sensor tilt and height, sloped ground, distractors);
``simulate_world_frames`` returns its paired LiDAR frames and truth in memory,
``write_world_sequence`` writes it as a sequence folder, and ``simulate_dataset(...,
randomize=True)`` (``cldet simulate --randomize``) a whole dataset of them.
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
from cldet.simulate.randomized import WorldTruth, simulate_world_frames, write_world_sequence
from cldet.simulate.world import (
    DEVELOPMENT_SEEDS,
    EVALUATION_SEEDS,
    KINDS,
    SITES,
    World,
    draw_world,
)

__all__ = [
    "DEVELOPMENT_SEEDS",
    "DRONE_TYPES",
    "EVALUATION_SEEDS",
    "KINDS",
    "PRESETS",
    "PRISM_OFFSET_M",
    "SCENARIOS",
    "SITES",
    "DroneType",
    "SequenceTruth",
    "SimulationSummary",
    "World",
    "WorldTruth",
    "draw_world",
    "simulate_dataset",
    "simulate_sequence",
    "simulate_world_frames",
    "write_world_sequence",
]
