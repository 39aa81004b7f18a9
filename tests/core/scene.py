"""A tiny ray-cast scene for the core tests: ground, a wall, spheres; Mid-360-like scans."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

GROUND_Z = -1.5
WALL = (np.array([12.0, -6.0, GROUND_Z]), np.array([13.0, 6.0, 4.0]))  # box lower, upper corner

Sphere = tuple[Sequence[float], float]  # centre (3,), radius


def _hit_box(
    d: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64]
) -> NDArray[np.float64]:
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1, t2 = lo * inv, hi * inv
    tmin = np.nanmax(np.minimum(t1, t2), axis=1)
    tmax = np.nanmin(np.maximum(t1, t2), axis=1)
    return np.where((tmax >= tmin) & (tmin > 0), tmin, np.inf)


def _hit_sphere(d: NDArray[np.float64], c: NDArray[np.float64], r: float) -> NDArray[np.float64]:
    b = d @ c
    disc = b * b - (c @ c - r * r)
    t = b - np.sqrt(np.maximum(disc, 0.0))
    return np.where((disc >= 0) & (t > 0), t, np.inf)


def scan(
    rng: np.random.Generator,
    spheres: Sequence[Sphere] = (),
    n_rays: int = 4000,
    wall: bool = True,
    el_range_deg: tuple[float, float] = (-7.0, 52.0),
    boxes: Sequence[tuple[Sequence[float], Sequence[float]]] = (),
    even: bool = False,
) -> NDArray[np.float32]:
    """One scan: random directions in the elevation band, nearest hit, 2 cm range noise.

    ``boxes`` are extra axis-aligned boxes (lower corner, upper corner). Directions are uniform
    in elevation (dense at the zenith) or, ``even``, uniform over the sphere as a Livox pattern
    covers its field of view.
    """
    az = rng.uniform(-np.pi, np.pi, n_rays)
    lo, hi = np.radians(el_range_deg)
    if even:
        el = np.arcsin(rng.uniform(np.sin(lo), np.sin(hi), n_rays))
    else:
        el = rng.uniform(lo, hi, n_rays)
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
    with np.errstate(divide="ignore"):
        t = np.where(d[:, 2] < 0, GROUND_Z / d[:, 2], np.inf)
    if wall:
        t = np.minimum(t, _hit_box(d, *WALL))
    for lo, hi in boxes:
        t = np.minimum(
            t, _hit_box(d, np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64))
        )
    for centre, radius in spheres:
        t = np.minimum(t, _hit_sphere(d, np.asarray(centre, dtype=np.float64), radius))
    hit = np.isfinite(t) & (t < 100.0)
    t = t[hit] + rng.normal(0.0, 0.02, int(hit.sum()))
    return (d[hit] * t[:, None]).astype(np.float32)


def points_near(
    points: NDArray[np.floating], centre: Sequence[float], radius: float
) -> NDArray[np.bool_]:
    """Mask of the points within ``radius`` of ``centre``."""
    return np.linalg.norm(points - np.asarray(centre), axis=1) <= radius
