"""The estimation methods by name: the factory that picks one from the configuration.

``track`` is :class:`cldet.core.estimator.TrackEstimator` (ours), ``cl-det`` is
:class:`cldet.core.cldet_baseline.ClDetEstimator` (the report's baseline); both follow the
:class:`cldet.core.estimator.Estimator` interface. This module imports both, so neither imports
the other back.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

from cldet.config import CldetConfig
from cldet.core.estimator import Estimator, FrameDetections, SequenceEstimate, TrackEstimator
from cldet.core.model import LearnedModel
from cldet.types import LidarFrame

__all__ = ["estimate_sequence", "make_estimator"]


def make_estimator(config: CldetConfig, model: LearnedModel | None = None) -> Estimator:
    """The estimator the configuration's ``method`` names (``model``: ``track`` only)."""
    if config.method == "track":
        return TrackEstimator(config, model)
    if config.method == "cl-det":
        from cldet.core.cldet_baseline import ClDetEstimator  # scikit-learn: cl-det only

        return ClDetEstimator(config)
    raise ValueError(f"unknown method {config.method!r}")  # unreachable: validated by config


def estimate_sequence(
    frames: Callable[[], Iterable[LidarFrame]] | Iterable[LidarFrame],
    config: CldetConfig,
    model: LearnedModel | None = None,
) -> tuple[list[FrameDetections], SequenceEstimate]:
    """Register every frame of a sequence (one pass, in stamp order), then refine.

    ``frames`` is an iterable of frames, or a callable returning one (called once). With a
    ``model`` (``cldet train``) its offset and bias replace the configuration's.
    """
    if model is not None:
        config = model.configure(config)
    estimator = make_estimator(config, model)
    source = frames() if callable(frames) else frames
    detections = [estimator.register_frame(frame) for frame in source]
    return detections, estimator.refine()
