"""The model file of ``cldet train``: written and read safely, versioned.

The file is a zip archive holding ``model.json`` (format version, the feature names, the class
ids, the fitted scan-time offset and bias, what it was trained on) and ``estimators.skops``
(the scikit-learn estimators in ``skops``' format). Loading never unpickles: ``skops`` rebuilds
only the scikit-learn types it trusts and those listed in :data:`_TRUSTED`, and refuses
anything else. A file of another format version, one whose feature lists differ from this
code's (:data:`cldet.core.features.FEATURE_NAMES`, ``TYPE_FEATURES``), or a corrupt one is
refused with :class:`ModelError`.
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Final

from cldet.core.features import FEATURE_NAMES, TYPE_FEATURES
from cldet.core.model import MODEL_FORMAT, LearnedModel
from cldet.errors import CldetError
from cldet.io.files import atomic_output

__all__ = ["ModelError", "load_model", "model_bytes", "write_model"]

_META = "model.json"
_ESTIMATORS = "estimators.skops"
_TRUSTED: Final = ["sklearn.ensemble._hist_gradient_boosting.predictor.TreePredictor"]


class ModelError(CldetError):
    """A model file that cannot be used (missing, corrupt, another version, other features)."""


def model_bytes(model: LearnedModel) -> bytes:
    """The model file's contents (see the module docstring)."""
    import skops.io as sio

    meta = {
        "format": MODEL_FORMAT,
        "kind": "cldet-model",
        "feature_names": list(FEATURE_NAMES),
        "type_feature_names": list(TYPE_FEATURES),
        "class_ids": [int(c) for c in model.class_ids],
        "scan_offset_s": float(model.scan_offset_s),
        "bias": {"along_ray_m": float(model.bias_along_ray_m), "z_m": float(model.bias_z_m)},
        "has_scorer": model.scorer is not None,
        "has_typer": model.typer is not None,
        "info": model.info,
    }
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr(_META, json.dumps(meta, indent=1))
        z.writestr(_ESTIMATORS, sio.dumps({"scorer": model.scorer, "typer": model.typer}))
    return buf.getvalue()


def write_model(model: LearnedModel, path: Path | str, *, overwrite: bool = False) -> None:
    """Write the model file atomically (a temporary file renamed into place)."""
    data = model_bytes(model)
    with atomic_output(path, overwrite=overwrite) as f:
        f.write(data)


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
