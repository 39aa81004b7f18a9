"""The default drone-vs-clutter track scorer: learned once, on simulated development worlds.

Which candidate track is the drone rests on many weak cues at once (height above the local
ground, size, cross-section, how steady its returns are, how it moves, how long it lasts,
which sensors saw it). The hand-set factors of :mod:`cldet.core.selection` each encode one
cue; weighing them against each other by hand traded one failure for another. The prior is
``cldet train``'s scorer (gradient-boosted trees over :data:`cldet.core.features.FEATURE_NAMES`,
physical quantities only) fitted on the candidate tracks of hundreds of randomised worlds of
``cldet simulate --randomize`` from the development seeds (other sites, tilts, mounts, ground,
flights and distractors in every world), never on the evaluation seeds. It re-weighs the
hand-set factors by ``floor + (1 - floor) p`` (``tracking.prior_scorer``; ``floor`` is
stored with it). ``cldet annotate --model`` adds the scorer learned from the user's own
labelled logs: the two factors multiply (``cldet.core.selection.TrackWeigher``);
``tracking.prior_scorer: false`` leaves the hand-set factors alone, or to the model's scorer.

The file ``prior_scorer.json`` is plain JSON (:class:`cldet.core.trees.TreeEnsemble`), written
by ``benchmarks/train_prior.py``, which says how to make it again.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from importlib import resources
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from cldet.core.features import FEATURE_NAMES
from cldet.core.trees import TreeEnsemble

__all__ = ["PRIOR_FILE", "PRIOR_FORMAT", "PriorScorer", "load_prior", "prior_json"]

PRIOR_FILE: Final = "prior_scorer.json"
PRIOR_FORMAT: Final = 1


@dataclass(frozen=True)
class PriorScorer:
    """The packaged scorer: the trees, the floor of its re-weighing, what it was trained on."""

    trees: TreeEnsemble
    floor: float
    info: dict[str, Any]
    # the features it was trained on, in its trees' column order: a subset of FEATURE_NAMES
    feature_names: tuple[str, ...] = FEATURE_NAMES

    def drone_probability(self, features: NDArray[np.float64]) -> NDArray[np.float64]:
        """(T,) the probability that each track (features (T, len(FEATURE_NAMES))) is the
        drone."""
        if len(features) == 0:
            return np.zeros(0)
        return self.trees.predict_proba(features[:, self._columns])[:, 1]

    @functools.cached_property
    def _columns(self) -> list[int]:
        """Where its features stand in this code's feature vector."""
        return [FEATURE_NAMES.index(n) for n in self.feature_names]


def prior_json(
    trees: TreeEnsemble,
    floor: float,
    info: dict[str, Any],
    feature_names: tuple[str, ...] = FEATURE_NAMES,
) -> dict[str, Any]:
    """The file's contents for ``json.dump`` (``feature_names``: the trees' columns)."""
    return {
        "kind": "cldet-prior-scorer",
        "format": PRIOR_FORMAT,
        "feature_names": list(feature_names),
        "floor": float(floor),
        "info": info,
        "trees": trees.to_json(),
    }


def parse_prior(data: Any) -> PriorScorer:
    """The scorer of a :func:`prior_json` document; ValueError when it is not one of this
    code's (another format, a feature this code does not compute, corrupt trees).

    A prior trained before features were added to :data:`FEATURE_NAMES` still reads: it names
    the features it was trained on and scores those columns."""
    if not isinstance(data, dict) or data.get("kind") != "cldet-prior-scorer":
        raise ValueError("not a cldet prior scorer")
    if data.get("format") != PRIOR_FORMAT:
        raise ValueError(f"format {data.get('format')!r}, this code reads {PRIOR_FORMAT}")
    names = data.get("feature_names", ())
    if not isinstance(names, list) or not names:
        raise ValueError("no feature list")
    unknown = sorted(set(map(str, names)) - set(FEATURE_NAMES))
    if unknown:
        raise ValueError(
            f"features this code does not compute ({', '.join(unknown)}):"
            " run benchmarks/train_prior.py"
        )
    trees = TreeEnsemble.from_json(data["trees"])
    if trees.n_features != len(names) or list(trees.classes_) != [0, 1]:
        raise ValueError("not a binary drone-vs-clutter scorer over its feature list")
    floor = float(data["floor"])
    if not 0.0 <= floor <= 1.0:
        raise ValueError(f"floor {floor} outside [0, 1]")
    return PriorScorer(trees, floor, dict(data.get("info", {})), tuple(map(str, names)))


@functools.cache
def load_prior() -> PriorScorer:
    """The packaged prior scorer (read once per process)."""
    text = resources.files("cldet.core").joinpath(PRIOR_FILE).read_text(encoding="utf-8")
    return parse_prior(json.loads(text))
