"""Static background: per-direction occupancy learned over the whole sequence, in time bins.

The sensors do not move, so whatever is seen at the same place through (nearly) the whole
sequence is the environment. A moving object (drone, person, bird) can only appear *in front
of* that environment along a ray. The model is a static range image (pass 1, streaming):

1. Directions from the Mid-360 origin are cut into cells of ``cell_deg`` (2 deg) in azimuth
   and elevation. A 2 deg cell is ~7 cm wide at 2 m and ~0.7 m at 20 m: it gets ~1 return
   per scan from a surface (the Mid-360's ~4.5k points spread over ~21,000 deg^2), so it is
   reliably hit within a 1 s bin even far away, where a fixed 0.5 m voxel would be hit once
   in ten scans.
2. Time is cut into bins of ``bin_s`` (1 s = 10 scans). For every cell and bin the model keeps
   the nearest range seen in that bin (inf when none).
3. The cell's *static range* is the nearest range reached in at least ``min_bin_fraction``
   (0.85) of the bins (the k-th smallest per-bin minimum, k = ceil(0.85 B)). A wall, the
   ground or a tree gives that range in every bin; a drone hovering in one place for half the
   sequence does not (it is there in ~half the bins), so it stays in front of the static range.
4. Dilation: the static range is replaced by the minimum over the cell and its 8 neighbours
   (azimuth wraps), ``dilate_cells`` times. Foliage swaying by a few cm into the next cell,
   and beam divergence at edges, then stay background.
5. A point is background when its range is not shorter than the static range by more than
   ``max(margin_m, margin_fraction * range)`` (0.3 m, 3 %: range noise ~2 cm, foliage depth).
   It is CORE background against the undilated static range, MARGIN when background only
   through dilation (a drone right next to static structure falls there; the estimator keeps
   those points for the tracker's raw-point gate), FOREGROUND otherwise.

Points from both LiDARs are counted together (both are in the Mid-360 frame; the Avia covers
the cone above 52 deg elevation). A trailing bin shorter than half a bin is merged into the
previous one. The model also learns the ground height (2nd percentile of return heights within
30 m horizontally) for the tracker's height-above-ground evidence.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from cldet.config import BackgroundConfig

__all__ = ["CORE", "FOREGROUND", "MARGIN", "BackgroundModel", "RecentRegions", "direction_cells"]

FOREGROUND = np.uint8(0)  # in front of the static environment
MARGIN = np.uint8(1)  # background only through dilation
CORE = np.uint8(2)  # at or behind the static range of its own cell

_Z_LO, _Z_HI, _Z_STEP = -30.0, 30.0, 0.05  # ground-height histogram, metres


def direction_cells(
    points: NDArray[np.floating], cell_deg: float
) -> tuple[NDArray[np.int64], NDArray[np.float32], int, int]:
    """Direction cell of each point (N,3) and its range.

    Returns:
        (flat cell index (N,), range (N,) metres, number of elevation rows, number of azimuth
        columns); flat index = elevation_row * n_az + azimuth_column.
    """
    n_az = int(round(360.0 / cell_deg))
    n_el = int(np.ceil(180.0 / cell_deg))
    p = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
    cells, rng = _cells_kernel(p, float(cell_deg), n_az, n_el)
    return cells, rng, n_el, n_az


@numba.njit(cache=True)
def _cells_kernel(
    points: NDArray[np.float32], cell_deg: float, n_az: int, n_el: int
) -> tuple[NDArray[np.int64], NDArray[np.float32]]:
    n = points.shape[0]
    cells = np.empty(n, dtype=np.int64)
    rng = np.empty(n, dtype=np.float32)
    scale = 180.0 / np.pi / cell_deg
    for i in range(n):
        x, y, z = float(points[i, 0]), float(points[i, 1]), float(points[i, 2])
        h = np.sqrt(x * x + y * y)
        rng[i] = np.sqrt(h * h + z * z)
        ia = int((np.arctan2(y, x) + np.pi) * scale) % n_az
        ie = int((np.arctan2(z, h) + np.pi / 2) * scale)
        ie = min(max(ie, 0), n_el - 1)
        cells[i] = ie * n_az + ia
    return cells, rng


@numba.njit(cache=True)
def _observe_kernel(
    cells: NDArray[np.int64], rng: NDArray[np.float32], nearest: NDArray[np.float32]
) -> None:
    for i in range(cells.shape[0]):
        if rng[i] < nearest[cells[i]]:
            nearest[cells[i]] = rng[i]


@numba.njit(cache=True)
def _classify_kernel(
    cells: NDArray[np.int64],
    rng: NDArray[np.float32],
    static: NDArray[np.float32],
    dilated: NDArray[np.float32],
    margin_m: float,
    margin_fraction: float,
) -> NDArray[np.uint8]:
    n = cells.shape[0]
    out = np.zeros(n, dtype=np.uint8)
    for i in range(n):
        limit = rng[i] + max(margin_m, margin_fraction * rng[i])
        c = cells[i]
        if limit >= static[c]:
            out[i] = 2
        elif limit >= dilated[c]:
            out[i] = 1
    return out


class BackgroundModel:
    """Static range image over a whole sequence: ``observe`` every frame, then ``classify``."""

    def __init__(self, cfg: BackgroundConfig) -> None:
        self.cfg = cfg
        self._n_az = int(round(360.0 / cfg.cell_deg))
        self._n_el = int(np.ceil(180.0 / cfg.cell_deg))
        self._bins: list[NDArray[np.float32]] = []  # per bin: (n_el*n_az,) nearest range
        self._frames_per_bin: list[int] = []
        self._bin_ns = int(round(cfg.bin_s * 1e9))
        self._t0: int | None = None
        self._bin = -1
        self._zhist = np.zeros(int(round((_Z_HI - _Z_LO) / _Z_STEP)), dtype=np.int64)
        self._static: NDArray[np.float32] | None = None  # undilated static range per cell
        self._dilated: NDArray[np.float32] | None = None
        self._ground_z: float | None = None
        self.n_frames = 0

    # ---------------------------------------------------------------- pass 1
    def observe(self, stamp_ns: int, points: NDArray[np.floating]) -> None:
        """Count one frame's points (both LiDARs, (N,3) metres, Mid-360 frame); frames in order."""
        if self._static is not None:
            raise RuntimeError("BackgroundModel.observe() after classify(): the model is frozen")
        if self._t0 is None:
            self._t0 = stamp_ns
        b = (stamp_ns - self._t0) // self._bin_ns
        if b != self._bin:
            self._bins.append(np.full(self._n_el * self._n_az, np.inf, dtype=np.float32))
            self._frames_per_bin.append(0)
            self._bin = int(b)
        self._frames_per_bin[-1] += 1
        self.n_frames += 1
        if len(points) == 0:
            return
        cells, rng, _, _ = direction_cells(points, self.cfg.cell_deg)
        _observe_kernel(cells, rng, self._bins[-1])
        horiz = points[:, 0] ** 2 + points[:, 1] ** 2 < 30.0**2
        zi = np.floor((points[horiz, 2] - _Z_LO) / _Z_STEP).astype(np.int64)
        zi = zi[(zi >= 0) & (zi < len(self._zhist))]
        self._zhist += np.bincount(zi, minlength=len(self._zhist))

    def _freeze(self) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        if self._static is not None and self._dilated is not None:
            return self._static, self._dilated
        bins = self._bins
        if len(bins) >= 2 and self._frames_per_bin[-1] < 0.5 * max(self._frames_per_bin[:-1]):
            last = bins.pop()
            np.minimum(bins[-1], last, out=bins[-1])
        if bins:
            stack = np.sort(np.stack(bins), axis=0)
            k = max(1, int(np.ceil(self.cfg.min_bin_fraction * len(bins) - 1e-9)))
            static = stack[k - 1].reshape(self._n_el, self._n_az)
        else:
            static = np.full((self._n_el, self._n_az), np.inf, dtype=np.float32)
        dilated = static
        if self.cfg.dilate_cells > 0:
            size = 2 * self.cfg.dilate_cells + 1
            dilated = ndimage.minimum_filter(static, size=size, mode=("nearest", "wrap"))
        self._static = static.ravel().astype(np.float32)
        self._dilated = dilated.ravel().astype(np.float32)
        self._n_bins = len(bins)
        self._bins = []  # no longer needed
        return self._static, self._dilated

    # ---------------------------------------------------------------- queries
    @property
    def n_bins(self) -> int:
        """Number of time bins counted (valid after the first ``classify``)."""
        self._freeze()
        return self._n_bins

    def ground_z(self) -> float:
        """Ground height in metres: the 2nd percentile of return heights within 30 m horizontally."""
        if self._ground_z is None:
            total = self._zhist.sum()
            if total == 0:
                self._ground_z = -1.0
            else:
                cum = np.cumsum(self._zhist)
                i = int(np.searchsorted(cum, 0.02 * total))
                self._ground_z = float(_Z_LO + (i + 0.5) * _Z_STEP)
        return self._ground_z

    def classify(self, points: NDArray[np.floating]) -> NDArray[np.uint8]:
        """Label each point (N,3) FOREGROUND (0), MARGIN (1) or CORE (2) background.

        The first call freezes the model (pass 1 is over).
        """
        static, dilated = self._freeze()
        if len(points) == 0:
            return np.zeros(0, dtype=np.uint8)
        cells, rng, _, _ = direction_cells(points, self.cfg.cell_deg)
        return _classify_kernel(
            cells, rng, static, dilated, self.cfg.margin_m, self.cfg.margin_fraction
        )

    def is_background(self, points: NDArray[np.floating]) -> NDArray[np.bool_]:
        """True for points that are (dilated) background."""
        return self.classify(points) != FOREGROUND


class RecentRegions:
    """Which places held a cluster in the last few frames (a coarse dense grid of frame indices).

    Used to keep the raw (background) points near recent clusters, so that a drone that stops
    right at static structure can still be found by the tracker's raw-point gate.
    """

    def __init__(self, extent_m: float, cell_m: float, memory_ns: int) -> None:
        n = max(1, int(np.ceil(2 * extent_m / cell_m)))
        self._lower = np.full(3, -extent_m)
        self._cell = cell_m
        self._shape = np.array([n, n, n])
        self._last = np.full((n, n, n), np.iinfo(np.int64).min // 2, dtype=np.int64)  # stamp, ns
        self._memory = int(memory_ns)

    def mark(self, centres: NDArray[np.floating], stamp_ns: int) -> None:
        """Mark the cells around ``centres`` (K,3) (their cell and its 26 neighbours)."""
        if len(centres) == 0:
            return
        ijk = np.floor((np.asarray(centres) - self._lower) / self._cell).astype(np.int64)
        ok = np.all((ijk >= -1) & (ijk <= self._shape), axis=1)
        for i, j, k in ijk[ok].tolist():
            self._last[max(i - 1, 0) : i + 2, max(j - 1, 0) : j + 2, max(k - 1, 0) : k + 2] = (
                stamp_ns
            )

    def contains(self, points: NDArray[np.floating], stamp_ns: int) -> NDArray[np.bool_]:
        """True for points (N,3) in a cell marked at most ``memory_ns`` before ``stamp_ns``."""
        return _contains_kernel(
            np.ascontiguousarray(points, dtype=np.float32),
            self._lower.astype(np.float64),
            float(self._cell),
            self._last,
            stamp_ns - self._memory,
        )


@numba.njit(cache=True)
def _contains_kernel(
    points: NDArray[np.float32],
    lower: NDArray[np.float64],
    cell: float,
    last: NDArray[np.int64],
    since: int,
) -> NDArray[np.bool_]:
    n = points.shape[0]
    out = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        a = int(np.floor((points[i, 0] - lower[0]) / cell))
        b = int(np.floor((points[i, 1] - lower[1]) / cell))
        c = int(np.floor((points[i, 2] - lower[2]) / cell))
        if 0 <= a < last.shape[0] and 0 <= b < last.shape[1] and 0 <= c < last.shape[2]:
            out[i] = last[a, b, c] >= since
    return out
