"""The ground under the sensor: a fitted plane plus a coarse height map, from static returns.

Height reasoning ("a person stands on the ground, a drone flies") must hold with a tilted
sensor, on a slope, on a rooftop. So nothing assumes a level sensor or one ground height:

1. **Plane.** RANSAC over static points (a frame's returns that are core background): the plane with the most inliers (within ``_INLIER_M``) among those that
   pass below the sensor (at least ``_MIN_CLEARANCE_M`` under the origin) and whose normal is
   within ``max_tilt_deg`` of the sensor's +z axis (a sensor tilted up to 20 deg on ground
   sloped up to 10 deg). Its normal, pointing away from the ground towards the sensor, is "up".
   On a rooftop the roof is the plane; on a hillside, the slope. Where the sensor's own ground
   lies below its view (a roof under a sensor on it) the fit can only find what it sees (the
   street far below): a known mount (``plane``, ``from_pose``; ``sensor.ground_from_pose``)
   is then taken as the plane and never fitted.
2. **Height map.** Every static point's height above that plane goes into a horizontal grid of
   ``_CELL_M`` (2 m) cells in the plane's own coordinates; a cell keeps its lowest height. The
   local ground under a query point is the lowest cell within one cell of it (walls and roofs
   whose foot is hidden do not raise it; the street below a roof edge lowers it), and the plane
   itself (height 0) where no static return was seen.
3. **Only where the ground could be seen.** A cell counts in the map only where the plane
   under it is inside the field of view (its elevation in the sensor's own frame is at or above
   ``field_bottom_deg``). Below the field's lower edge a static thing's lowest return is just
   where the view ends, not what it stands on: from a mast 5 m up the Mid-360 (lowest
   elevation -7 deg) first sees the ground 40 m out, and nearer than that a hedge, a car or a
   drone hovering at the edge of the view would otherwise become its own ground. There the
   plane is the ground.

``height_above(points)`` is then the height of each point above the local ground, metres.
Before the first fit (the background's warm-up) heights are NaN: unknown, never guessed.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from cldet.core.stats import box_minimum

__all__ = ["GroundModel", "GroundPlane"]

_INLIER_M = 0.15  # a point this close to a candidate plane supports it
_MIN_CLEARANCE_M = 0.2  # the ground passes at least this far below the sensor
_CELL_M = 2.0  # height-map cell, metres
_HALF_EXTENT_M = 120.0  # the height map covers this far from the sensor, each way
_ITERATIONS = 64
_MAX_POINTS = 4000  # RANSAC subsample


GroundPlane = tuple[NDArray[np.float64], float]
"""A ground plane: the unit "up" in the sensor's frame (3,), and the sensor's height above it."""


class GroundModel:
    """Ground plane and height map, refitted from static points; ``height_above`` queries it."""

    def __init__(
        self,
        max_tilt_deg: float = 35.0,
        seed: int = 0,
        field_bottom_deg: float = -90.0,
        plane: GroundPlane | None = None,
    ) -> None:
        """``field_bottom_deg``: the lowest elevation the sensors see, in their own frame.
        ``plane``: the ground plane when it is known (the unit "up" in the sensor's frame and
        the sensor's height above the plane, from the mount: ``from_pose``); it is then never
        fitted, and ``fit`` only builds the height map."""
        self.max_tilt_deg = max_tilt_deg
        self.field_bottom_deg = field_bottom_deg
        self._rng = np.random.default_rng(seed)
        self.normal: NDArray[np.float64] | None = None  # (3,) unit "up", sensor frame
        self.offset = 0.0  # height of the sensor origin above the plane, metres
        n = int(round(2 * _HALF_EXTENT_M / _CELL_M))
        self._n = n
        self._map = np.full((n, n), np.inf)
        self._axes = np.eye(3)[:2]  # (2,3) in-plane axes for the map
        self._known = plane is not None
        if plane is not None:
            self._place(np.asarray(plane[0], dtype=np.float64), float(plane[1]))

    @staticmethod
    def from_pose(height_m: float, roll_deg: float, pitch_deg: float) -> GroundPlane:
        """The ground plane of a sensor ``height_m`` above level ground, tilted by ``roll_deg``
        about its x axis, then ``pitch_deg`` about its y axis (``cldet.io.transforms``'s
        ``world_from_mid360``): the world's "up" in the sensor's frame, and the height."""
        tilt = Rotation.from_euler("xy", [roll_deg, pitch_deg], degrees=True).as_matrix()
        return tilt[2].copy(), float(height_m)

    @property
    def fitted(self) -> bool:
        """A plane has been found."""
        return self.normal is not None

    def fit(self, points: NDArray[np.floating]) -> bool:
        """Refit plane and height map from static points (N,3), metres, sensor frame.

        Returns whether a plane was found; the previous fit is kept otherwise. A known plane
        (``plane``) is kept: only the height map is built, and this returns True.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        p = p[np.all(np.isfinite(p), axis=1)]
        if not self._known:
            if len(p) < 3:
                return False
            plane = self._search(p)
            if plane is None:
                return False
            self._place(*plane)
        self._build_map(p)
        return True

    def _search(self, p: NDArray[np.float64]) -> GroundPlane | None:
        """The plane with the most inliers among the static points ``p`` (see the module
        docstring), or None."""
        sample = p if len(p) <= _MAX_POINTS else p[self._rng.choice(len(p), _MAX_POINTS, False)]
        cos_max = np.cos(np.radians(self.max_tilt_deg))
        # candidate planes from random triples, evaluated together
        idx = self._rng.integers(0, len(sample), (_ITERATIONS, 3))
        a, b, c = sample[idx[:, 0]], sample[idx[:, 1]], sample[idx[:, 2]]
        n = np.cross(b - a, c - a)
        norm = np.linalg.norm(n, axis=1)
        ok = norm > 1e-9
        n[ok] /= norm[ok, None]
        n *= np.where(n[:, 2] < 0, -1.0, 1.0)[:, None]  # point up, towards the sensor side
        d = -np.einsum("ij,ij->i", n, a)  # plane: n.x + d = 0; sensor height above it = d
        ok &= (n[:, 2] >= cos_max) & (d >= _MIN_CLEARANCE_M)
        if not ok.any():
            return None
        n, d = n[ok], d[ok]
        dist = np.abs(sample @ n.T + d)  # (S, C)
        support = np.sum(dist < _INLIER_M, axis=0)
        best = int(np.argmax(support))
        if support[best] < 3:
            return None
        # refine by least squares on the inliers
        inl = sample[dist[:, best] < _INLIER_M]
        centre = inl.mean(axis=0)
        _, _, vt = np.linalg.svd(inl - centre, full_matrices=False)
        normal = vt[-1] * (1.0 if vt[-1][2] >= 0 else -1.0)
        offset = -float(normal @ centre)
        if normal[2] < cos_max or offset < _MIN_CLEARANCE_M:
            normal, offset = n[best], float(d[best])
        return normal, offset

    def _place(self, normal: NDArray[np.float64], offset: float) -> None:
        """Take ``normal``, ``offset`` as the plane, with in-plane axes for the height map."""
        self.normal = normal
        self.offset = offset
        ax = np.cross(normal, [0.0, 1.0, 0.0])
        if np.linalg.norm(ax) < 1e-6:
            ax = np.cross(normal, [1.0, 0.0, 0.0])
        ax /= np.linalg.norm(ax)
        self._axes = np.stack([ax, np.cross(normal, ax)])

    def _build_map(self, p: NDArray[np.float64]) -> None:
        """The height map from the static points ``p`` over the current plane."""
        assert self.normal is not None
        height = p @ self.normal + self.offset
        i, j, inside = self._cells(p)
        grid = np.full(self._n * self._n, np.inf)
        np.minimum.at(grid, i[inside] * self._n + j[inside], height[inside])
        grid[~self._ground_in_view()] = np.inf
        # the local ground of a cell: the lowest height within one cell of it
        self._map = box_minimum(grid.reshape(self._n, self._n), 3, wrap_columns=False)

    def _cells(
        self, p: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]]:
        uv = p @ self._axes.T
        ij = np.floor((uv + _HALF_EXTENT_M) / _CELL_M).astype(np.int64)
        inside = np.all((ij >= 0) & (ij < self._n), axis=1)
        return ij[:, 0], ij[:, 1], inside

    def _ground_in_view(self) -> NDArray[np.bool_]:
        """(n * n,) whether the plane under each map cell's centre is inside the field of view."""
        assert self.normal is not None
        centres = (np.arange(self._n) + 0.5) * _CELL_M - _HALF_EXTENT_M
        # the plane's point under (u, v): the in-plane axes, and the foot of the sensor origin
        foot = np.asarray(-self.offset * self.normal, dtype=np.float64)
        sin_bottom = float(np.sin(np.radians(self.field_bottom_deg)))
        axes = np.ascontiguousarray(self._axes, dtype=np.float64)
        return _in_view_kernel(centres, foot, axes, sin_bottom)

    def plane_height(self, points: NDArray[np.floating]) -> NDArray[np.float64]:
        """Height of each point (N,3) above the ground plane, metres (NaN before a fit)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if self.normal is None:
            return np.full(len(p), np.nan)
        return p @ self.normal + self.offset

    def height_above(self, points: NDArray[np.floating]) -> NDArray[np.float64]:
        """Height of each point (N,3) above the local ground, metres (NaN before a fit)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        h = self.plane_height(p)
        if self.normal is None or len(p) == 0:
            return h
        local = self._local(p)
        # a point below everything static around it stands on what it is (height 0 at least)
        return h - np.minimum(local, h)

    def depth_below(self, points: NDArray[np.floating]) -> NDArray[np.float64]:
        """How far each point (N,3) lies below the ground, metres (negative: above it; NaN
        before a fit). The ground here is the lower of the plane and the local height map (the
        street below a roof edge lowers it; a slope rising above the plane, or a wall whose foot
        is hidden, does not raise it): a point counts as below only where it is below both."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        h = self.plane_height(p)
        if self.normal is None or len(p) == 0:
            return -h
        return np.minimum(self._local(p), 0.0) - h

    def _local(self, p: NDArray[np.float64]) -> NDArray[np.float64]:
        """(N,) the local ground's height above the plane under each point (the height map's
        lowest static height within one cell; 0, the plane, where nothing static was seen)."""
        i, j, inside = self._cells(p)
        local = np.zeros(len(p))
        local[inside] = self._map[i[inside], j[inside]]
        local[~np.isfinite(local)] = 0.0  # nothing static seen there: the plane
        return local


@numba.njit(cache=True)
def _in_view_kernel(
    centres: NDArray[np.floating],
    foot: NDArray[np.float64],
    axes: NDArray[np.float64],
    sin_bottom: float,
) -> NDArray[np.bool_]:
    """``GroundModel._ground_in_view``: for each map cell (u, v) = (centres[i], centres[j]), in
    row-major order, whether the plane's point foot + u axes[0] + v axes[1] lies at or above the
    elevation whose sine is ``sin_bottom`` (summed in numpy's order, so the same floats)."""
    n = len(centres)
    out = np.empty(n * n, dtype=np.bool_)
    for i in range(n):
        u = centres[i]
        for j in range(n):
            v = centres[j]
            x = foot[0] + u * axes[0, 0] + v * axes[1, 0]
            y = foot[1] + u * axes[0, 1] + v * axes[1, 1]
            z = foot[2] + u * axes[0, 2] + v * axes[1, 2]
            out[i * n + j] = z >= sin_bottom * np.sqrt(x * x + y * y + z * z)
    return out
