"""What ``cldet train`` learned, as the estimator uses it: timing, bias, a drone-vs-clutter
track scorer and a drone-type classifier (scikit-learn estimators held as objects; reading and
writing the model file is :mod:`cldet.modelfile`'s job).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from cldet.config import BiasConfig, CldetConfig
from cldet.core.features import TYPE_COLUMNS

__all__ = ["MODEL_FORMAT", "LearnedModel", "one_thread"]

MODEL_FORMAT: Final = 1
"""Version of what a model holds (features, classifiers); a model file of another is refused."""


def one_thread() -> Any:
    """A context limiting OpenMP to one thread: scikit-learn's trees otherwise spin up a thread
    per core for a few hundred rows, and parallel workers oversubscribe the machine."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="openmp")


@dataclass
class LearnedModel:
    """What ``cldet train`` learned. ``scorer`` / ``typer`` are scikit-learn classifiers with
    ``predict_proba`` (None: not learned, the defaults apply)."""

    scan_offset_s: float
    bias_along_ray_m: float
    bias_z_m: float
    scorer: Any = None  # binary: 1 = the drone
    typer: Any = None  # classes: indices into class_ids
    class_ids: list[int] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)  # trained on what, cross-validation

    def configure(self, config: CldetConfig) -> CldetConfig:
        """``config`` with the model's scan-time offset and centroid bias."""
        frames = config.frames.model_copy(update={"scan_offset_s": self.scan_offset_s})
        bias = BiasConfig(along_ray_m=self.bias_along_ray_m, z_m=self.bias_z_m)
        return config.model_copy(update={"frames": frames, "bias": bias})

    def describe_source(self) -> dict[str, Any]:
        """What the model is, for the annotated log's metadata."""
        return {
            "format": MODEL_FORMAT,
            "class_ids": self.class_ids,
            "scan_offset_s": self.scan_offset_s,
            "bias": [self.bias_along_ray_m, self.bias_z_m],
            "trained_on": len(self.info.get("trained_on", [])),
        }

    def drone_probability(self, features: NDArray[np.float64]) -> NDArray[np.float64]:
        """(T,) probability that each track (features (T, F)) is the drone."""
        if self.scorer is None or len(features) == 0:
            return np.ones(len(features))
        with one_thread():
            return np.asarray(self.scorer.predict_proba(features)[:, 1], dtype=np.float64)

    def type_probabilities(
        self, features: NDArray[np.float64], weights: NDArray[np.float64], groups: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        """(G, C) class probabilities of ``G = groups.max() + 1`` groups of tracks (a sequence's
        chain at several instants): the probabilities of the tracks (features (T, F)) of each
        group voted with ``weights`` (T,) (their detections). Uniform for an empty group."""
        c = len(self.class_ids)
        n_groups = int(groups.max()) + 1 if len(groups) else 0
        out = np.full((n_groups, c), 1.0 / max(c, 1))
        if self.typer is None or len(features) == 0:
            return out
        with one_thread():
            proba = np.asarray(
                self.typer.predict_proba(features[:, TYPE_COLUMNS]), dtype=np.float64
            )
        full = np.zeros((len(features), c))
        full[:, np.asarray(self.typer.classes_, dtype=np.int64)] = proba
        vote = np.zeros((n_groups, c))
        np.add.at(vote, groups, full * np.asarray(weights, dtype=np.float64)[:, None])
        total = vote.sum(axis=1)
        ok = total > 0
        out[ok] = vote[ok] / total[ok, None]
        return out
