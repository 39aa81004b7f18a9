"""Vectorised ray casting from the sensor origin against boxes, cylinders, spheres and the ground.

Every ray starts at the origin of the Mid-360 frame (both LiDARs are treated as co-located);
directions are unit vectors, (N, 3). Functions return the hit distance along each ray in metres,
``inf`` where the ray misses. Static primitives are batched (rays x primitives); moving ones take
one centre per ray, because each ray is fired at its own instant within the scan.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

_TINY = 1e-12


def _safe_inverse(d: F64) -> F64:
    """1/d with zeros replaced by a huge value of the right sign (slab tests)."""
    d = np.where(np.abs(d) < _TINY, np.where(d < 0, -_TINY, _TINY), d)
    return 1.0 / d


def hit_boxes(dirs: F64, lower: F64, upper: F64) -> tuple[F64, NDArray[np.intp]]:
    """Nearest hit of rays from the origin with axis-aligned boxes.

    Args:
        dirs: (N, 3) unit directions.
        lower: (M, 3) box minima, metres.
        upper: (M, 3) box maxima, metres.

    Returns:
        (N,) distance to the nearest box (inf on a miss) and (N,) index of that box (-1 on a miss).
    """
    n = dirs.shape[0]
    if lower.shape[0] == 0 or n == 0:
        return np.full(n, np.inf), np.full(n, -1, dtype=np.intp)
    inv = _safe_inverse(dirs)[:, None, :]  # (N, 1, 3)
    t1 = lower[None, :, :] * inv  # (N, M, 3)
    t2 = upper[None, :, :] * inv
    t_near = np.minimum(t1, t2).max(axis=2)  # (N, M)
    t_far = np.maximum(t1, t2).min(axis=2)
    ok = (t_near <= t_far) & (t_near > 0.0)
    t = np.where(ok, t_near, np.inf)
    idx = np.argmin(t, axis=1)
    best = t[np.arange(n), idx]
    return best, np.where(np.isfinite(best), idx, -1)


def hit_vertical_cylinders(dirs: F64, cyl: F64) -> tuple[F64, NDArray[np.intp]]:
    """Nearest hit of rays from the origin with vertical cylinders (side surface only).

    Args:
        dirs: (N, 3) unit directions.
        cyl: (M, 5) rows ``cx, cy, radius, z_bottom, z_top`` in metres.

    Returns:
        (N,) nearest distance (inf on a miss) and (N,) cylinder index (-1 on a miss).
    """
    n = dirs.shape[0]
    if cyl.shape[0] == 0 or n == 0:
        return np.full(n, np.inf), np.full(n, -1, dtype=np.intp)
    dx = dirs[:, 0:1]
    dy = dirs[:, 1:2]
    a = dx * dx + dy * dy  # (N, 1)
    b = dx * cyl[None, :, 0] + dy * cyl[None, :, 1]  # (N, M)
    c = cyl[None, :, 0] ** 2 + cyl[None, :, 1] ** 2 - cyl[None, :, 2] ** 2
    disc = b * b - a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (b - np.sqrt(np.maximum(disc, 0.0))) / np.maximum(a, _TINY)
    z = t * dirs[:, 2:3]
    ok = (disc > 0) & (t > 0) & (z >= cyl[None, :, 3]) & (z <= cyl[None, :, 4]) & (a > 1e-9)
    t = np.where(ok, t, np.inf)
    idx = np.argmin(t, axis=1)
    best = t[np.arange(n), idx]
    return best, np.where(np.isfinite(best), idx, -1)


def hit_spheres(dirs: F64, centres: F64, radii: F64) -> tuple[F64, NDArray[np.intp]]:
    """Nearest hit of rays from the origin with spheres.

    Args:
        dirs: (N, 3) unit directions.
        centres: (M, 3) sphere centres, metres.
        radii: (M,) radii, metres.

    Returns:
        (N,) nearest distance (inf on a miss) and (N,) sphere index (-1 on a miss).
    """
    n = dirs.shape[0]
    if centres.shape[0] == 0 or n == 0:
        return np.full(n, np.inf), np.full(n, -1, dtype=np.intp)
    b = dirs @ centres.T  # (N, M)
    c = (centres**2).sum(axis=1) - radii**2  # (M,)
    disc = b * b - c[None, :]
    t = b - np.sqrt(np.maximum(disc, 0.0))
    t = np.where((disc > 0) & (t > 0), t, np.inf)
    idx = np.argmin(t, axis=1)
    best = t[np.arange(n), idx]
    return best, np.where(np.isfinite(best), idx, -1)


def hit_moving_box(dirs: F64, centres: F64, half: F64, yaw: F64) -> F64:
    """Hit distance of each ray with its own placement of one box rotated about z.

    Args:
        dirs: (N, 3) unit directions.
        centres: (N, 3) box centre at each ray's instant, metres.
        half: (3,) half extents along the box's own x, y, z, metres.
        yaw: (N,) box heading at each ray's instant, radians.

    Returns:
        (N,) distance (inf on a miss).
    """
    if dirs.shape[0] == 0:
        return np.zeros(0)
    c, s = np.cos(yaw), np.sin(yaw)
    # rotate into the box frame by -yaw; the ray origin is the sensor at (0, 0, 0)
    ox, oy, oz = -centres[:, 0], -centres[:, 1], -centres[:, 2]
    o = np.stack([c * ox + s * oy, -s * ox + c * oy, oz], axis=1)
    d = np.stack(
        [c * dirs[:, 0] + s * dirs[:, 1], -s * dirs[:, 0] + c * dirs[:, 1], dirs[:, 2]], axis=1
    )
    inv = _safe_inverse(d)
    t1 = (-half[None, :] - o) * inv
    t2 = (half[None, :] - o) * inv
    t_near = np.minimum(t1, t2).max(axis=1)
    t_far = np.maximum(t1, t2).min(axis=1)
    ok = (t_near <= t_far) & (t_near > 0.0)
    return np.where(ok, t_near, np.inf)


def hit_moving_cylinder(dirs: F64, bottoms: F64, radius: float, height: float) -> F64:
    """Hit distance of each ray with its own placement of one vertical cylinder (side surface).

    Args:
        dirs: (N, 3) unit directions.
        bottoms: (N, 3) centre of the cylinder's base at each ray's instant, metres.
        radius: metres.
        height: metres.

    Returns:
        (N,) distance (inf on a miss).
    """
    if dirs.shape[0] == 0:
        return np.zeros(0)
    cyl = np.column_stack(
        [
            bottoms[:, 0],
            bottoms[:, 1],
            np.full(len(dirs), radius),
            bottoms[:, 2],
            bottoms[:, 2] + height,
        ]
    )
    dx, dy = dirs[:, 0], dirs[:, 1]
    a = dx * dx + dy * dy
    b = dx * cyl[:, 0] + dy * cyl[:, 1]
    c = cyl[:, 0] ** 2 + cyl[:, 1] ** 2 - radius**2
    disc = b * b - a * c
    t = (b - np.sqrt(np.maximum(disc, 0.0))) / np.maximum(a, _TINY)
    z = t * dirs[:, 2]
    ok = (disc > 0) & (t > 0) & (z >= cyl[:, 3]) & (z <= cyl[:, 4]) & (a > 1e-9)
    return np.where(ok, t, np.inf)


def hit_moving_sphere(dirs: F64, centres: F64, radius: float) -> F64:
    """Hit distance of each ray with its own placement of one sphere.

    Args:
        dirs: (N, 3) unit directions.
        centres: (N, 3) sphere centre at each ray's instant, metres.
        radius: metres.

    Returns:
        (N,) distance (inf on a miss).
    """
    if dirs.shape[0] == 0:
        return np.zeros(0)
    b = (dirs * centres).sum(axis=1)
    c = (centres**2).sum(axis=1) - radius**2
    disc = b * b - c
    t = b - np.sqrt(np.maximum(disc, 0.0))
    return np.where((disc > 0) & (t > 0), t, np.inf)
