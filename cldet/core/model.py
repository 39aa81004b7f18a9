"""A model learned by ``cldet train``: timing, bias, a drone-vs-clutter track scorer, a type classifier.

The file is a zip archive holding ``model.json`` (format version, the feature names, the class
ids, the fitted scan-time offset and bias, what it was trained on) and ``estimators.skops``
(the scikit-learn estimators in ``skops``' format). Loading never unpickles: ``skops`` rebuilds
only the types listed in :data:`_TRUSTED` and the scikit-learn types it trusts by default, and
refuses anything else. A file of another format version, one whose feature list differs from
this code's (:data:`cldet.core.features.FEATURE_NAMES`), or a corrupt one is refused with
:class:`ModelError`.
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from cldet.config import BiasConfig, CldetConfig
from cldet.core.features import FEATURE_NAMES, TYPE_COLUMNS, TYPE_FEATURES
from cldet.errors import CldetError

__all__ = ["MODEL_FORMAT", "LearnedModel", "ModelError", "load_model", "one_thread"]

MODEL_FORMAT: Final = 1
"""Version of the file layout; a model of another version is refused."""

_META = "model.json"
_ESTIMATORS = "estimators.skops"
_TRUSTED: Final = ["sklearn.ensemble._hist_gradient_boosting.predictor.TreePredictor"]


def one_thread() -> Any:
    """A context limiting OpenMP to one thread: scikit-learn's trees otherwise spin up a thread
    per core for a few hundred rows, and parallel workers oversubscribe the machine."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="openmp")


class ModelError(CldetError):
    """A model file that cannot be used (missing, corrupt, another version, other features)."""


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
    feature_names: tuple[str, ...] = FEATURE_NAMES

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

    def to_bytes(self) -> bytes:
        """The model file's contents (see the module docstring)."""
        import skops.io as sio

        meta = {
            "format": MODEL_FORMAT,
            "kind": "cldet-model",
            "feature_names": list(self.feature_names),
            "type_feature_names": list(TYPE_FEATURES),
            "class_ids": [int(c) for c in self.class_ids],
            "scan_offset_s": float(self.scan_offset_s),
            "bias": {"along_ray_m": float(self.bias_along_ray_m), "z_m": float(self.bias_z_m)},
            "has_scorer": self.scorer is not None,
            "has_typer": self.typer is not None,
            "info": self.info,
        }
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr(_META, json.dumps(meta, indent=1))
            z.writestr(_ESTIMATORS, sio.dumps({"scorer": self.scorer, "typer": self.typer}))
        return buf.getvalue()


def load_model(path: Path | str) -> LearnedModel:
    """Read and check a model file written by ``cldet train``.

    Raises:
        ModelError: missing, not a cldet model, corrupt, another format version, or a feature
            list that is not this code's.
    """
    p = Path(path)
    if not p.is_file():
        raise ModelError(f"{p}: no such model file (write one with `cldet train`)")
    try:
        with zipfile.ZipFile(p) as z:
            meta = json.loads(z.read(_META))
            blob = z.read(_ESTIMATORS)
    except (zipfile.BadZipFile, KeyError, OSError, ValueError, EOFError) as exc:
        raise ModelError(f"{p}: not a cldet model file, or a corrupt one ({exc})") from None
    if not isinstance(meta, dict) or meta.get("kind") != "cldet-model":
        raise ModelError(f"{p}: not a cldet model file (no cldet-model metadata)")
    if meta.get("format") != MODEL_FORMAT:
        raise ModelError(
            f"{p}: model format {meta.get('format')!r}, this cldet reads format {MODEL_FORMAT}:"
            " train the model again with this version"
        )
    names = tuple(meta.get("feature_names", ()))
    if names != FEATURE_NAMES or tuple(meta.get("type_feature_names", ())) != TYPE_FEATURES:
        missing = sorted(set(FEATURE_NAMES) - set(names))
        extra = sorted(set(names) - set(FEATURE_NAMES))
        raise ModelError(
            f"{p}: the model's features do not match this code's (missing {missing or 'none'},"
            f" unknown {extra or 'none'}, or another order): train the model again"
        )
    import skops.io as sio

    try:
        est = sio.loads(blob, trusted=_TRUSTED)
        scorer, typer = est["scorer"], est["typer"]
        bias = meta["bias"]
        model = LearnedModel(
            scan_offset_s=float(meta["scan_offset_s"]),
            bias_along_ray_m=float(bias["along_ray_m"]),
            bias_z_m=float(bias["z_m"]),
            scorer=scorer,
            typer=typer,
            class_ids=[int(c) for c in meta["class_ids"]],
            info=dict(meta.get("info", {})),
        )
    except Exception as exc:  # skops raises many kinds on a damaged or untrusted payload
        raise ModelError(f"{p}: the model's estimators cannot be read safely ({exc})") from None
    for est_, what, n in (
        (scorer, "scorer", len(FEATURE_NAMES)),
        (typer, "typer", len(TYPE_FEATURES)),
    ):
        if est_ is not None and getattr(est_, "n_features_in_", n) != n:
            raise ModelError(f"{p}: the {what} expects another number of features")
    if typer is not None and len(model.class_ids) < 2:
        raise ModelError(f"{p}: a type classifier with fewer than two class ids")
    return model
