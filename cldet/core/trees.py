"""Gradient-boosted trees as plain arrays: evaluated by one compiled walk, stored as JSON.

``cldet train`` fits scikit-learn's ``HistGradientBoostingClassifier``; what it learned is a
sum of small regression trees. :class:`TreeEnsemble` holds those trees as flat arrays (one row
per node), so a model is read without unpickling anything and predicted without importing
scikit-learn (about a second or two of start-up per process, measured here), and its JSON form
is plain data that any tool can read.

Prediction follows scikit-learn's: at a node, a missing value (NaN) goes to the side the
training chose, any other value goes left when it is at most the threshold; the raw score is
the baseline plus the leaves' values of every tree; a binary model's probability of class 1 is
the logistic of it, a multiclass model's probabilities the softmax over one tree per class and
iteration.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["TreeEnsemble"]

F64 = NDArray[np.float64]
# a tree's node arrays, in the JSON's column order, with their types
_DTYPES: dict[str, Any] = {
    "feature": np.int64,
    "threshold": np.float64,
    "missing_left": bool,
    "left": np.int64,
    "right": np.int64,
    "leaf": bool,
    "value": np.float64,
}
_COLUMNS = tuple(_DTYPES)


@dataclass(frozen=True)
class TreeEnsemble:
    """A fitted tree ensemble: ``predict_proba`` and ``classes_`` as scikit-learn's."""

    classes_: NDArray[np.int64]  # (C,) the class labels, in probability column order
    baseline: F64  # (K,) raw score before any tree; K = 1 (binary) or C
    n_features: int
    # per tree, in fitting order (iteration-major, K trees per iteration): its node arrays
    trees: tuple[dict[str, NDArray[Any]], ...]

    @classmethod
    def from_sklearn(cls, clf: Any) -> TreeEnsemble:
        """The trees of a fitted ``HistGradientBoostingClassifier`` (numeric features)."""
        if getattr(clf, "is_categorical_", None) is not None:
            raise ValueError("categorical features are not supported")
        trees = []
        for iteration in clf._predictors:
            for tree in iteration:
                nodes = tree.nodes
                names = ("feature_idx", "num_threshold", "missing_go_to_left", "left", "right")
                trees.append(_tree([nodes[n] for n in (*names, "is_leaf", "value")]))
        return cls(
            classes_=np.asarray(clf.classes_, dtype=np.int64),
            baseline=np.asarray(clf._baseline_prediction, dtype=np.float64).ravel(),
            n_features=int(clf.n_features_in_),
            trees=tuple(trees),
        )

    @property
    def per_iteration(self) -> int:
        """Trees per boosting iteration: 1 for two classes, one per class otherwise."""
        return len(self.baseline)

    @functools.cached_property
    def _flat(self) -> tuple[NDArray[Any], ...]:
        """Every tree's nodes in one set of arrays (children as indices into them), each
        tree's root and the score column it adds to: one compiled walk evaluates them all."""
        sizes = [len(t["leaf"]) for t in self.trees]
        offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        cat = {c: np.concatenate([t[c] for t in self.trees]) for c in _COLUMNS}
        shift = np.repeat(offsets, sizes)
        return (
            offsets,
            np.arange(len(self.trees), dtype=np.int64) % self.per_iteration,
            cat["feature"],
            cat["threshold"],
            cat["missing_left"],
            cat["left"] + shift,
            cat["right"] + shift,
            cat["leaf"],
            cat["value"],
        )

    def raw_scores(self, x: NDArray[np.floating]) -> F64:
        """(N, K) the raw scores of the rows of ``x`` (N, n_features)."""
        rows = np.ascontiguousarray(np.reshape(x, (-1, self.n_features)), dtype=np.float64)
        out = np.tile(self.baseline, (len(rows), 1))
        roots, column, feature, threshold, missing_left, left, right, leaf, value = self._flat
        _walk(rows, roots, column, feature, threshold, missing_left, left, right, leaf, value, out)
        return out

    def predict_proba(self, x: NDArray[np.floating]) -> F64:
        """(N, C) class probabilities of the rows of ``x``."""
        raw = self.raw_scores(x)
        if self.per_iteration == 1:
            p1 = 1.0 / (1.0 + np.exp(-raw[:, 0]))
            return np.column_stack([1.0 - p1, p1])
        z = np.exp(raw - raw.max(axis=1, keepdims=True))
        return np.asarray(z / z.sum(axis=1, keepdims=True), dtype=np.float64)

    def to_json(self) -> dict[str, Any]:
        """Plain data (lists and numbers) for ``json.dumps``."""
        return {
            "classes": self.classes_.tolist(),
            "baseline": self.baseline.tolist(),
            "n_features": self.n_features,
            "columns": list(_COLUMNS),
            "trees": [[t[c].tolist() for c in _COLUMNS] for t in self.trees],
        }

    @classmethod
    def from_json(cls, data: Any) -> TreeEnsemble:
        """The ensemble of :meth:`to_json`'s data; ValueError when it is not that (a corrupt
        or foreign file): every index is checked, so a bad file cannot make ``predict_proba``
        loop or read out of bounds."""
        try:
            if list(data["columns"]) != list(_COLUMNS):
                raise ValueError(f"columns {data['columns']!r}, expected {list(_COLUMNS)}")
            classes = np.asarray(data["classes"], dtype=np.int64)
            baseline = np.asarray(data["baseline"], dtype=np.float64).ravel()
            n_features = int(data["n_features"])
            trees = []
            for raw in data["trees"]:
                t = _tree([raw[k] for k in range(len(_COLUMNS))])
                _check_tree(t, n_features)
                trees.append(t)
        except (KeyError, IndexError, TypeError) as exc:
            raise ValueError(f"not a tree ensemble ({type(exc).__name__}: {exc})") from None
        if len(classes) < 2 or len(baseline) not in (1, len(classes)):
            raise ValueError(f"{len(classes)} classes with {len(baseline)} baseline score(s)")
        if n_features < 1 or not trees or len(trees) % len(baseline):
            raise ValueError(f"{len(trees)} trees for {len(baseline)} per iteration")
        return cls(classes, baseline, n_features, tuple(trees))


def _tree(columns: list[Any]) -> dict[str, NDArray[Any]]:
    """One tree's node arrays from its columns in ``_COLUMNS`` order, typed."""
    return {c: np.asarray(v, dtype=_DTYPES[c]) for c, v in zip(_COLUMNS, columns, strict=True)}


@numba.njit(cache=True)
def _walk(
    x: F64,
    roots: NDArray[np.int64],
    column: NDArray[np.int64],
    feature: NDArray[np.int64],
    threshold: F64,
    missing_left: NDArray[np.bool_],
    left: NDArray[np.int64],
    right: NDArray[np.int64],
    leaf: NDArray[np.bool_],
    value: F64,
    out: F64,
) -> None:  # pragma: no cover - compiled
    """Add each tree's leaf value for each row of ``x`` to its column of ``out``, in tree
    order (scikit-learn's sum). Children always come after their node (``_check_tree``), so
    every walk ends."""
    for r in range(x.shape[0]):
        for t in range(roots.shape[0]):
            node = roots[t]
            while not leaf[node]:
                v = x[r, feature[node]]
                go_left = missing_left[node] if np.isnan(v) else v <= threshold[node]
                node = left[node] if go_left else right[node]
            out[r, column[t]] += value[node]


def _check_tree(t: dict[str, NDArray[Any]], n_features: int) -> None:
    """ValueError unless ``t`` is a binary tree rooted at node 0 whose children come later."""
    n = len(t["leaf"])
    if n == 0 or any(len(v) != n for v in t.values()):
        raise ValueError("a tree's node arrays are empty or of different lengths")
    inner = np.flatnonzero(~t["leaf"])
    idx = np.arange(n)
    for side in ("left", "right"):
        child = t[side][inner]
        if np.any(child <= idx[inner]) or np.any(child >= n):
            raise ValueError(f"a tree's {side} child index is out of order or out of range")
    if np.any((t["feature"][inner] < 0) | (t["feature"][inner] >= n_features)):
        raise ValueError("a tree splits on a feature it does not have")
