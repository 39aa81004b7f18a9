"""Centroid bias: a LiDAR sees only the near face of the drone, and the ground truth is a prism.

A cluster centroid sits a few cm to ~0.2 m nearer the sensor than the body centre, and the
surveying prism mounted on the drone sits ~0.15 m above it. The correction is two numbers:
a shift ``along_ray_m`` away from the sensor (the Mid-360 origin) along the ray to the point,
and a shift ``z_m`` up. Both default to 0; ``fit_bias`` fits them by least squares from
estimates made with zero bias and the training ground truth.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import NDArray

from cldet.config import BiasConfig
from cldet.core.trajectory import evaluate_trajectory
from cldet.errors import CldetError
from cldet.types import Estimate, PositionSample, Source

__all__ = ["apply_bias", "detection_pairs", "fit_bias", "fit_bias_sequences"]

_RIDGE = 1e-3  # relative ridge weight of the least-squares fit
_OUTLIER_M = 1.0  # pairs farther apart than this after the fit are refitted without


def _unit_rays(positions: NDArray[np.floating]) -> NDArray[np.float64]:
    p = np.asarray(positions, dtype=np.float64)
    norm = np.linalg.norm(p, axis=-1, keepdims=True)
    return np.divide(p, norm, out=np.zeros_like(p), where=norm > 1e-9)


def apply_bias(positions: NDArray[np.floating], bias: BiasConfig) -> NDArray[np.float64]:
    """Corrected positions (N,3): p + along_ray_m * p/|p| + (0, 0, z_m)."""
    p = np.asarray(positions, dtype=np.float64)
    if bias.along_ray_m == 0.0 and bias.z_m == 0.0:
        return p.copy()
    out = p + bias.along_ray_m * _unit_rays(p)
    out[..., 2] += bias.z_m
    return out


def detection_pairs(
    detections: Sequence[Estimate],
    truth: Sequence[PositionSample],
    max_truth_gap_ns: int | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The detected positions of one sequence and the truth at their stamps, (N,3) each.

    Only estimates with ``source == DETECTED`` inside the truth's span count; the truth is
    interpolated linearly (:func:`cldet.core.trajectory.evaluate_trajectory`). With
    ``max_truth_gap_ns``, a detection between two truth samples further apart than that is
    skipped (one at a truth sample's stamp never is).
    """
    det = [e for e in detections if e.source == Source.DETECTED]
    if not truth or not det:
        return np.zeros((0, 3)), np.zeros((0, 3))
    t_ns = np.sort(np.array([s.stamp_ns for s in truth], dtype=np.int64))
    stamps = np.array([e.stamp_ns for e in det], dtype=np.int64)
    keep = (stamps >= t_ns[0]) & (stamps <= t_ns[-1])
    if max_truth_gap_ns is not None:
        k = np.searchsorted(t_ns, stamps)
        exact = (k < len(t_ns)) & (t_ns[np.minimum(k, len(t_ns) - 1)] == stamps)
        gap = t_ns[np.clip(k, 1, len(t_ns) - 1)] - t_ns[np.clip(k - 1, 0, len(t_ns) - 1)]
        keep &= exact | (gap <= max_truth_gap_ns)
    positions = np.array([e.position for e in det], dtype=np.float64).reshape(-1, 3)[keep]
    if not keep.any():
        return positions, np.zeros((0, 3))
    true = evaluate_trajectory(
        [s.stamp_ns for s in truth], [s.position for s in truth], stamps[keep]
    )
    return positions, true


def fit_bias(
    detections: Sequence[Estimate],
    truth: Sequence[PositionSample],
    max_truth_gap_ns: int = 200_000_000,
) -> BiasConfig:
    """Least-squares ``along_ray_m`` and ``z_m`` from one sequence's detections and ground truth.

    For a training set of several sequences use ``fit_bias_sequences``: stamps of different
    sequences may overlap, so their truths must not be mixed. See ``fit_bias_sequences``.

    Raises:
        CldetError: no truth, or fewer than two usable detection/truth pairs.
    """
    if not truth:
        raise CldetError("fit_bias: no ground truth given")
    return fit_bias_sequences([(detections, truth)], max_truth_gap_ns)


def fit_bias_sequences(
    sequences: Iterable[tuple[Sequence[Estimate], Sequence[PositionSample]]],
    max_truth_gap_ns: int = 200_000_000,
) -> BiasConfig:
    """Least-squares ``along_ray_m`` and ``z_m`` over several sequences' (detections, truth).

    Only estimates with ``source == DETECTED`` are used; each sequence's truth is linearly
    interpolated at its detection stamps, and a detection is skipped when the two bracketing
    truth samples are more than ``max_truth_gap_ns`` apart or it lies outside the truth's span.
    The detections should come from a run with zero bias. Pairs more than 1 m apart are dropped
    (a detection of something else: the bias is a few tenths of a metre); the fit is least
    squares with a small ridge (the ray and z coincide for a drone straight overhead), refitted
    up to twice without pairs it leaves more than 1 m apart.

    Raises:
        CldetError: fewer than two usable detection/truth pairs.
    """
    used_p: list[NDArray[np.float64]] = [np.zeros((0, 3))]
    used_t: list[NDArray[np.float64]] = [np.zeros((0, 3))]
    for detections, truth in sequences:
        p_seq, t_seq = detection_pairs(detections, truth, max_truth_gap_ns)
        used_p.append(p_seq)
        used_t.append(t_seq)
    n_pairs = sum(len(p) for p in used_p)
    if n_pairs < 2:
        raise CldetError(
            f"fit_bias: only {n_pairs} detected estimate(s) overlap the ground truth, need >= 2"
        )
    p = np.concatenate(used_p)
    residual = np.concatenate(used_t) - p  # (N,3)
    u = _unit_rays(p)
    design = np.zeros((3 * len(p), 2))
    design[:, 0] = u.ravel()
    design[2::3, 1] = 1.0
    # a detection more than 1 m from the truth is of something else (the bias is a few tenths)
    keep = np.linalg.norm(residual, axis=1) <= _OUTLIER_M
    if keep.sum() < 2:
        raise CldetError(
            f"fit_bias: only {int(keep.sum())} of {len(p)} detections lie within {_OUTLIER_M} m "
            "of the ground truth, need >= 2"
        )
    coef = np.zeros(2)
    for _ in range(3):  # refit without pairs the fit leaves more than 1 m apart
        rows = np.repeat(keep, 3)
        a, b = design[rows], residual.ravel()[rows]
        # a little ridge: when the drone is straight above the sensor the ray and z coincide
        # and the split between the two is arbitrary; take the smallest one
        coef = np.linalg.solve(a.T @ a + _RIDGE * len(a) * np.eye(2), a.T @ b)
        err = np.linalg.norm(residual - (u * coef[0] + np.array([0.0, 0.0, coef[1]])), axis=1)
        new_keep = err <= _OUTLIER_M
        if new_keep.sum() < 2 or np.array_equal(new_keep, keep):
            break
        keep = new_keep
    return BiasConfig(along_ray_m=float(coef[0]), z_m=float(coef[1]))
