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
   (0.85) of the bins (the k-th smallest per-bin minimum, k = floor(0.85 B), at least 1: 5 of
   6 bins, 17 of 20; rounding down forgives one sparsely sampled bin in a short sequence).
   A wall, the ground or a tree gives that range in every bin; a drone hovering in one place for half the
   sequence does not (it is there in ~half the bins), so it stays in front of the static range.
4. A static object never floats: lamp posts, cars and trees stand on something. A small blob
   of static cells (3D extent at most ``floating_max_size_m``, nearer than
   ``floating_max_range_m``, or at any range above ``floating_any_range_above_deg`` of elevation:
   high in the Avia cone the sky holds no small static things, and a drone hovering at 40 m stays
   in one 2 deg cell all along) whose neighbouring directions are all empty or far from it in
   range (by max(1 m, 10 % of its range)), and at most half of them nearer (occluding), is a
   drone hovering through (nearly) the whole sequence, not environment: its cells are cleared.
   Blobs are the 8-connected cells whose static ranges differ by at most max(0.5 m, 5 %).
   One exception to the clearance: right below the blob, up to three cells of a separate
   surface (not range-continuous with it) may be nearer than the clearance: a drone hovering
   a metre above a post or pole top is seen with the top in the next cell down, only a few
   tenths of a metre apart in range. A lamp head is attached to its pole (range-continuous),
   so it stays part of the pole's blob.
   A drone hovering on (or just above) a pole top through the whole sequence is range-continuous
   with the pole, so it is not floating; neither is a lamp head. Both look like a small *cap*
   (at most ``floating_max_size_m``, nearer than ``floating_max_range_m``) on top of a column at
   least two cells narrower, with free space (empty, or behind it) all around the cap: such caps
   are cleared too. Nothing static tells the two apart, so both become candidates for the
   tracker, where a static candidate weighs 0.3 of a moving one: a lamp head cannot outscore a
   drone that is seen moving, and a drone hovering all along is no longer erased.
   The environment is there from the start; a drone that flies in and then hovers (for the
   ``min_bin_fraction`` of the sequence) is not. For every cell and bin the model also keeps
   when the surface at the bin's nearest range was first hit (a hit nearer by more than
   max(1 m, 10 %) is a new surface in front and restarts it); a cell's *onset* is that time in
   the first bin whose nearest range is its static range (no onset when something passed in
   front first). A blob of at least ``arrival_min_cells`` static cells (8-connected, near as
   above), every one first reached ``arrival_after_s`` (0.8 s: eight scans) or more after the
   start, at most ``floating_max_size_m`` across, arrived and stayed: it is cleared, with its
   rim of neighbouring cells at the same range (reached a little earlier as the drone slowed
   into place) when the whole stays that small. A cell of a surface is hit about once a scan,
   so three cells all missed for eight scans do not happen by chance (single late cells do, on
   the real data as well: hence the minimum). A parked car or a person who walks in and stays
   is larger; a part of one that is released is a weak static candidate like a cap.
5. Dilation: the static range is replaced by the minimum over the cell and its 8 neighbours
   (azimuth wraps), ``dilate_cells`` times. Foliage swaying by a few cm into the next cell,
   and beam divergence at edges, then stay background.
6. A point is background when its range is not shorter than the static range by more than
   ``max(margin_m, margin_fraction * range, slack)`` (0.3 m, 3 %: range noise ~2 cm, foliage
   depth). ``slack`` is half the smaller range step from the cell to the cells above and below
   it: a surface seen at grazing incidence (the ground far out, the bottom row of the field of
   view) spans about that much range within one cell, so its nearest return varies that much
   from bin to bin.
   It is CORE background against the undilated static range, MARGIN when background only
   through dilation (a drone right next to static structure falls there), FOREGROUND otherwise.

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

__all__ = ["CORE", "FOREGROUND", "MARGIN", "BackgroundModel", "direction_cells"]

FOREGROUND = np.uint8(0)  # in front of the static environment
MARGIN = np.uint8(1)  # background only through dilation
CORE = np.uint8(2)  # at or behind the static range of its own cell

_Z_LO, _Z_HI, _Z_STEP = -30.0, 30.0, 0.05  # ground-height histogram, metres
# two ranges in one cell belong to the same surface when within max(1 m, 10 %): the clearance
# the floating-blob rule uses, far above range noise and foliage depth
_SAME_SURFACE_M = 1.0
# a floating blob may rest on a separate surface right below it this many cells wide (a pole or
# post top: a drone hovering just above it)
_MAX_SUPPORT_CELLS = 3
_GROUND_BAND_M = 0.5  # a static surface this close to the ground height is the ground
_SAME_SURFACE_FRACTION = 0.1


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


@numba.njit(cache=True, inline="always")
def _atan2(y: float, x: float) -> float:
    """atan2 by a minimax polynomial (max error ~2e-4 rad, 0.01 deg): 2 deg cells need no more."""
    ax, ay = abs(x), abs(y)
    mx, mn = max(ax, ay), min(ax, ay)
    if mx == 0.0:
        return 0.0
    a = mn / mx
    s = a * a
    r = ((-0.0464964749 * s + 0.15931422) * s - 0.327622764) * s * a + a
    if ay > ax:
        r = 1.5707963267948966 - r
    if x < 0.0:
        r = 3.141592653589793 - r
    if y < 0.0:
        r = -r
    return r


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
        ia = int((_atan2(y, x) + np.pi) * scale) % n_az
        ie = int((_atan2(z, h) + np.pi / 2) * scale)
        ie = min(max(ie, 0), n_el - 1)
        cells[i] = ie * n_az + ia
    return cells, rng


@numba.njit(cache=True)
def _continuous(r: float, rn: float) -> bool:
    """Two neighbouring static ranges belong to one surface (the blob continuity step)."""
    return abs(rn - r) <= max(0.5, 0.05 * min(r, rn))


@numba.njit(cache=True)
def _clearance(r: float) -> float:
    """Ranges this far apart, or more, are separate surfaces beyond doubt: max(1 m, 10 %)."""
    return max(_SAME_SURFACE_M, _SAME_SURFACE_FRACTION * r)


@numba.njit(cache=True)
def _observe_kernel(
    cells: NDArray[np.int64],
    rng: NDArray[np.float32],
    nearest: NDArray[np.float32],
    onset: NDArray[np.int32],
    t_ms: int,
) -> None:
    """Per cell: the bin's nearest range, and when a surface at about that range was first hit.

    A hit nearer than the bin's nearest so far by more than max(1 m, 10 %) is a new surface in
    front (its time becomes the onset); a hit about as near only refines the range.
    """
    for i in range(cells.shape[0]):
        c = cells[i]
        r = rng[i]
        cur = nearest[c]
        if r >= cur:
            continue
        if not np.isfinite(cur) or r < cur - _clearance(cur):
            onset[c] = t_ms
        nearest[c] = r


@numba.njit(cache=True)
def _classify_kernel(
    cells: NDArray[np.int64],
    rng: NDArray[np.float32],
    static: NDArray[np.float32],
    dilated: NDArray[np.float32],
    slack: NDArray[np.float32],
    margin_m: float,
    margin_fraction: float,
) -> NDArray[np.uint8]:
    n = cells.shape[0]
    out = np.zeros(n, dtype=np.uint8)
    for i in range(n):
        c = cells[i]
        limit = rng[i] + max(margin_m, margin_fraction * rng[i], slack[c])
        if limit >= static[c]:
            out[i] = 2
        elif limit >= dilated[c]:
            out[i] = 1
    return out


@numba.njit(cache=True)
def _run_width(static: NDArray[np.float32], e: int, a: int) -> int:
    """Cells in row ``e`` range-continuous with cell ``a`` in a run (counted up to 9)."""
    n_az = static.shape[1]
    width = 1
    for step in (-1, 1):
        prev = static[e, a]
        aa = a
        for _ in range(4):
            aa = (aa + step) % n_az
            r = static[e, aa]
            if not np.isfinite(r) or not _continuous(prev, r):
                break
            width += 1
            prev = r
    return width


@numba.njit(cache=True)
def _floating_blobs(
    static: NDArray[np.float32], cell_deg: float, max_range: float, max_size: float, cone_el: float
) -> NDArray[np.bool_]:
    """Cells of small static blobs floating in free space (see the module docstring, step 4)."""
    n_el, n_az = static.shape
    comp = np.full((n_el, n_az), -1, dtype=np.int64)
    out = np.zeros((n_el, n_az), dtype=np.bool_)
    support = np.full((n_el, n_az), -1, dtype=np.int64)  # marks support cells per component
    stack = np.empty((n_el * n_az, 2), dtype=np.int64)
    members = np.empty((n_el * n_az, 2), dtype=np.int64)
    deg = np.pi / 180.0
    n_comp = 0
    for e0 in range(n_el):
        for a0 in range(n_az):
            if comp[e0, a0] >= 0 or not np.isfinite(static[e0, a0]):
                continue
            # flood fill over range-continuous 8-neighbours (azimuth wraps)
            comp[e0, a0] = n_comp
            top = 0
            stack[0, 0], stack[0, 1] = e0, a0
            top = 1
            m = 0
            while top > 0:
                top -= 1
                e, a = stack[top, 0], stack[top, 1]
                members[m, 0], members[m, 1] = e, a
                m += 1
                r = static[e, a]
                for de in (-1, 0, 1):
                    ee = e + de
                    if ee < 0 or ee >= n_el:
                        continue
                    for da in (-1, 0, 1):
                        aa = (a + da) % n_az
                        rn = static[ee, aa]
                        if comp[ee, aa] >= 0 or not np.isfinite(rn):
                            continue
                        if _continuous(r, rn):
                            comp[ee, aa] = n_comp
                            stack[top, 0], stack[top, 1] = ee, aa
                            top += 1
            # judge the component
            ok = True
            n_border = 0
            n_nearer = 0
            n_support = 0
            lo = np.full(3, np.inf)
            hi = np.full(3, -np.inf)
            for k in range(m):
                e, a = members[k, 0], members[k, 1]
                r = static[e, a]
                el = ((e + 0.5) * cell_deg - 90.0) * deg
                if r > max_range and el < cone_el:
                    ok = False
                    break
                az = ((a + 0.5) * cell_deg - 180.0) * deg
                p0 = r * np.cos(el) * np.cos(az)
                p1 = r * np.cos(el) * np.sin(az)
                p2 = r * np.sin(el)
                lo[0], hi[0] = min(lo[0], p0), max(hi[0], p0)
                lo[1], hi[1] = min(lo[1], p1), max(hi[1], p1)
                lo[2], hi[2] = min(lo[2], p2), max(hi[2], p2)
                if max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) > max_size:
                    ok = False
                    break
                # every other neighbour: empty, or far in front or behind (free space around it)
                clearance = _clearance(r)
                for de in (-1, 0, 1):
                    ee = e + de
                    if ee < 0 or ee >= n_el:
                        continue
                    for da in (-1, 0, 1):
                        aa = (a + da) % n_az
                        if comp[ee, aa] == n_comp:
                            continue
                        n_border += 1
                        rn = static[ee, aa]
                        if not np.isfinite(rn):
                            continue
                        if abs(rn - r) < clearance:
                            if de == -1 and not _continuous(r, rn):
                                # right below, a separate surface: what it hovers over,
                                # if it is a pole or post top (a narrow run in its row)
                                if support[ee, aa] != n_comp:
                                    support[ee, aa] = n_comp
                                    n_support += 1
                                    if _run_width(static, ee, aa) > _MAX_SUPPORT_CELLS:
                                        ok = False
                            else:
                                ok = False
                        elif rn < r:
                            n_nearer += 1
                if not ok:
                    break
            if ok and 2 * n_nearer <= n_border and n_support <= _MAX_SUPPORT_CELLS:
                for k in range(m):
                    out[members[k, 0], members[k, 1]] = True
            n_comp += 1
    return out


def _cells_extent(
    static: NDArray[np.float32], e_idx: NDArray[np.int64], a_idx: NDArray[np.int64], cell_deg: float
) -> float:
    """Largest 3D extent (metres) of the cells' centre directions at their static ranges."""
    r = static[e_idx, a_idx].astype(np.float64)
    el = np.radians((e_idx + 0.5) * cell_deg - 90.0)
    az = np.radians((a_idx + 0.5) * cell_deg - 180.0)
    xyz = np.stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)])
    return float(np.max(xyz.max(axis=1) - xyz.min(axis=1)))


def caps_on_columns(
    static: NDArray[np.float32], cell_deg: float, max_range: float, max_size: float
) -> NDArray[np.bool_]:
    """Cells of small caps standing on a narrower column, free all around (module docstring, 4).

    Candidate tops are runs of range-continuous static cells in one elevation row (at most six
    cells, nearer than ``max_range``) with nothing range-continuous right above them. From each,
    the cap grows down row by row (cells under it, one cell to either side) until a row at least
    two cells narrower than the widest so far: that row must be continued by the row under it
    (within max(1 m, 10 %): a pole thinner than a cell is sampled unevenly), the column the cap
    stands on. The cap must be small (3D extent at most ``max_size``) and
    every neighbouring direction outside the cap and the column's top must be empty or behind it.
    A lamp head qualifies as well as a drone hovering on a pole top: releasing both makes them
    weak (static) candidates for the tracker rather than erasing the drone.
    """
    n_el, n_az = static.shape
    near = np.isfinite(static) & (static <= max_range)
    out = np.zeros((n_el, n_az), dtype=bool)

    def linked(e: int, a: int, ee: int, aa: int) -> bool:
        return (
            0 <= ee < n_el
            and bool(near[ee, aa])
            and _continuous(float(static[e, a]), float(static[ee, aa]))
        )

    def below(run: list[int], e: int) -> list[int]:
        """Cells of row e - 1 linked to the run in row e (same azimuth or one either side)."""
        found = {
            (a + da) % n_az
            for a in run
            for da in (-1, 0, 1)
            if linked(e, a, e - 1, (a + da) % n_az)
        }
        return sorted(found)

    def supported(run: list[int], e: int) -> bool:
        """Row e - 1 continues the narrow row e under it (a pole sampled unevenly: 1 m / 10 %)."""
        return any(
            e >= 1
            and near[e - 1, (a + da) % n_az]
            and abs(float(static[e - 1, (a + da) % n_az]) - float(static[e, a]))
            < _clearance(float(static[e, a]))
            for a in run
            for da in (-1, 0, 1)
        )

    for e in range(n_el - 1, 0, -1):
        row = np.flatnonzero(near[e])
        if len(row) == 0:
            continue
        # runs of azimuth-adjacent, range-continuous cells in this row
        runs: list[list[int]] = []
        for a in row.tolist():
            if runs and a == runs[-1][-1] + 1 and linked(e, runs[-1][-1], e, a):
                runs[-1].append(a)
            else:
                runs.append([a])
        for top in runs:
            if len(top) > 6 or any(
                linked(e, a, e + 1, (a + da) % n_az) for a in top for da in (-1, 0, 1)
            ):
                continue
            cap = [(e, a) for a in top]
            run, widest, row_e, column = top, len(top), e, None
            for _ in range(6):
                nxt = below(run, row_e)
                if not nxt:
                    break
                if len(nxt) <= widest - 2:
                    if supported(nxt, row_e - 1):
                        column = [(row_e - 1, a) for a in nxt]
                    break
                cap += [(row_e - 1, a) for a in nxt]
                run, widest, row_e = nxt, max(widest, len(nxt)), row_e - 1
            if column is None:
                continue
            cap_e = np.array([c[0] for c in cap], dtype=np.int64)
            cap_a = np.array([c[1] for c in cap], dtype=np.int64)
            if _cells_extent(static, cap_e, cap_a, cell_deg) > max_size:
                continue
            r_cap = static[cap_e, cap_a].astype(np.float64)
            allowed = set(cap) | set(column)
            free = all(
                not (np.isfinite(rn := float(static[ee, aa])) and rn <= r + max(0.5, 0.05 * r))
                for (ce, ca), r in zip(cap, r_cap, strict=True)
                for de in (-1, 0, 1)
                for da in (-1, 0, 1)
                if 0 <= (ee := ce + de) < n_el and (ee, aa := (ca + da) % n_az) not in allowed
            )
            if free:
                for c in cap:
                    out[c] = True
    return out


class BackgroundModel:
    """Static range image over a whole sequence: ``observe`` every frame, then ``classify``."""

    def __init__(self, cfg: BackgroundConfig) -> None:
        self.cfg = cfg
        self._n_az = int(round(360.0 / cfg.cell_deg))
        self._n_el = int(np.ceil(180.0 / cfg.cell_deg))
        self._bins: list[NDArray[np.float32]] = []  # per bin: (n_el*n_az,) nearest range
        self._onsets: list[NDArray[np.int32]] = []  # per bin: ms when that surface was first hit
        self._frames_per_bin: list[int] = []
        self._bin_ns = int(round(cfg.bin_s * 1e9))
        self._t0: int | None = None
        self._bin = -1
        self._zhist = np.zeros(int(round((_Z_HI - _Z_LO) / _Z_STEP)), dtype=np.int64)
        self._static: NDArray[np.float32] | None = None  # undilated static range per cell
        self._slack = np.zeros(0, dtype=np.float32)  # extra margin per cell (grazing surfaces)
        self._dilated: NDArray[np.float32] | None = None
        self._ground_z: float | None = None
        self._arrival_cells = 0
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
            self._onsets.append(np.full(self._n_el * self._n_az, -1, dtype=np.int32))
            self._frames_per_bin.append(0)
            self._bin = int(b)
        self._frames_per_bin[-1] += 1
        self.n_frames += 1
        if len(points) == 0:
            return
        cells, rng, _, _ = direction_cells(points, self.cfg.cell_deg)
        t_ms = (stamp_ns - self._t0) // 1_000_000
        _observe_kernel(cells, rng, self._bins[-1], self._onsets[-1], int(t_ms))
        horiz = points[:, 0] ** 2 + points[:, 1] ** 2 < 30.0**2
        zi = np.floor((points[horiz, 2] - _Z_LO) / _Z_STEP).astype(np.int64)
        zi = zi[(zi >= 0) & (zi < len(self._zhist))]
        self._zhist += np.bincount(zi, minlength=len(self._zhist))

    def _freeze(self) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        if self._static is not None and self._dilated is not None:
            return self._static, self._dilated
        bins, onsets = self._bins, self._onsets
        if len(bins) >= 2 and self._frames_per_bin[-1] < 0.5 * max(self._frames_per_bin[:-1]):
            last, last_onset = bins.pop(), onsets.pop()
            with np.errstate(invalid="ignore"):
                newer = last < bins[-1] - np.maximum(
                    _SAME_SURFACE_M, _SAME_SURFACE_FRACTION * bins[-1]
                )
            newer |= ~np.isfinite(bins[-1]) & np.isfinite(last)
            onsets[-1] = np.where(newer, last_onset, onsets[-1])
            np.minimum(bins[-1], last, out=bins[-1])
        self._arrival_cells = 0
        if bins:
            raw = np.stack(bins)
            stack = np.sort(raw, axis=0)
            k = max(1, int(np.floor(self.cfg.min_bin_fraction * len(bins) + 1e-9)))
            static = stack[k - 1].reshape(self._n_el, self._n_az)
            if self.cfg.floating_max_size_m > 0 and self.cfg.arrival_after_s > 0:
                arrived = self._arrivals(static, raw, np.stack(onsets))
                self._arrival_cells = int(arrived.sum())
                static = np.where(arrived, np.float32(np.inf), static)
        else:
            static = np.full((self._n_el, self._n_az), np.inf, dtype=np.float32)
        self._floating_cells = 0
        self._cap_cells = 0
        if self.cfg.floating_max_size_m > 0:
            floating = _floating_blobs(
                static,
                float(self.cfg.cell_deg),
                float(self.cfg.floating_max_range_m),
                float(self.cfg.floating_max_size_m),
                float(np.radians(self.cfg.floating_any_range_above_deg)),
            )
            self._floating_cells = int(floating.sum())
            static = np.where(floating, np.float32(np.inf), static)
        if self.cfg.floating_max_size_m > 0 and self.cfg.release_caps:
            caps = caps_on_columns(
                static,
                float(self.cfg.cell_deg),
                float(self.cfg.floating_max_range_m),
                float(self.cfg.floating_max_size_m),
            )
            self._cap_cells = int(caps.sum())
            static = np.where(caps, np.float32(np.inf), static)
        # grazing surfaces (the ground far out) span a range interval within one cell of about
        # the range step to the next elevation row: half of the smaller vertical step
        up = np.full_like(static, np.inf)
        down = np.full_like(static, np.inf)
        with np.errstate(invalid="ignore"):
            up[:-1] = np.abs(static[1:] - static[:-1])
            down[1:] = np.abs(static[1:] - static[:-1])
        step = np.fmin(up, down)  # NaN (inf - inf) counts as missing
        self._slack = np.where(np.isfinite(step), 0.5 * step, 0.0).astype(np.float32).ravel()
        dilated = static
        if self.cfg.dilate_cells > 0:
            size = 2 * self.cfg.dilate_cells + 1
            dilated = ndimage.minimum_filter(static, size=size, mode=("nearest", "wrap"))
        self._static = static.ravel().astype(np.float32)
        self._dilated = dilated.ravel().astype(np.float32)
        self._n_bins = len(bins)
        self._bins, self._onsets = [], []  # no longer needed
        return self._static, self._dilated

    def _arrivals(
        self, static: NDArray[np.float32], raw: NDArray[np.float32], onsets: NDArray[np.int32]
    ) -> NDArray[np.bool_]:
        """Small blobs of static cells first reached late in the sequence (docstring, step 4)."""
        cfg = self.cfg
        flat = static.ravel()
        with np.errstate(invalid="ignore"):
            tol = np.maximum(_SAME_SURFACE_M, _SAME_SURFACE_FRACTION * flat)
            same = np.abs(raw - flat) <= tol  # (B, cells) the bin's nearest is the static surface
            front = raw < flat - tol  # something passed in front: that bin cannot tell
        decisive = same | front
        first = np.argmax(decisive, axis=0)
        cols = np.arange(flat.size)
        known = decisive[first, cols] & same[first, cols]
        onset_ms = np.where(known, onsets[first, cols], -1)
        n_el, n_az = static.shape
        el = ((np.arange(n_el) + 0.5) * cfg.cell_deg - 90.0)[:, None] * np.ones((1, n_az))
        near = (static <= cfg.floating_max_range_m) | (el >= cfg.floating_any_range_above_deg)
        late = (onset_ms.reshape(n_el, n_az) >= 1000.0 * cfg.arrival_after_s) & near
        late &= np.isfinite(static)
        labels, n = ndimage.label(late, structure=np.ones((3, 3), dtype=bool))
        out = np.zeros_like(late)
        if n == 0:
            return out
        finite = np.isfinite(static)
        for i in range(1, n + 1):
            seed = labels == i
            seed_e, seed_a = np.nonzero(seed)
            if len(seed_e) < cfg.arrival_min_cells:
                continue
            if _cells_extent(static, seed_e, seed_a, cfg.cell_deg) > cfg.floating_max_size_m:
                continue
            out |= seed
            # its rim: neighbouring cells on the same surface, reached a little earlier as the
            # drone slowed into place; left static, dilation would hide the blob's edges again
            r_seed = static[seed]
            lo, hi = float(r_seed.min()), float(r_seed.max())
            tol = max(0.5, 0.05 * hi)
            with np.errstate(invalid="ignore"):
                rim = ndimage.binary_dilation(seed, structure=np.ones((3, 3), dtype=bool))
                rim &= ~seed & finite & (static >= lo - tol) & (static <= hi + tol)
            if rim.any():
                grown_e, grown_a = np.nonzero(seed | rim)
                if _cells_extent(static, grown_e, grown_a, cfg.cell_deg) <= cfg.floating_max_size_m:
                    out |= rim
        return out

    # ---------------------------------------------------------------- queries
    @property
    def n_bins(self) -> int:
        """Number of time bins counted (valid after the first ``classify``)."""
        self._freeze()
        return self._n_bins

    @property
    def floating_cells(self) -> int:
        """Direction cells cleared as small floating blobs (valid after the first ``classify``)."""
        self._freeze()
        return self._floating_cells

    @property
    def arrival_cells(self) -> int:
        """Direction cells released as small blobs that arrived late (valid after ``classify``)."""
        self._freeze()
        return self._arrival_cells

    @property
    def cap_cells(self) -> int:
        """Direction cells released as small caps on a column (valid after the first ``classify``)."""
        self._freeze()
        return self._cap_cells

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
            cells, rng, static, dilated, self._slack, self.cfg.margin_m, self.cfg.margin_fraction
        )

    def hidden_below(self, points: NDArray[np.floating]) -> NDArray[np.bool_]:
        """For each point (N,3): would a point one cell lower, at the same range, be background?

        ... and that background is the ground: its static surface there lies within 0.5 m plus
        the cell's own height uncertainty (range times a cell's angle) of the ground height.
        Then whatever continues below it is not seen: a walking person's legs in front of the
        ground seen at a grazing angle fall within the ground's margin, leaving the upper body
        as foreground.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0, dtype=bool)
        h = np.hypot(p[:, 0], p[:, 1])
        r = np.hypot(h, p[:, 2])
        el = np.arctan2(p[:, 2], h) - np.radians(self.cfg.cell_deg)
        scale = np.where(h > 0, r * np.cos(el) / np.maximum(h, 1e-9), 0.0)
        probe = np.stack([p[:, 0] * scale, p[:, 1] * scale, r * np.sin(el)], axis=1)
        static, dilated = self._freeze()
        cells, rng, _, _ = direction_cells(probe.astype(np.float32), self.cfg.cell_deg)
        hidden = (
            _classify_kernel(
                cells,
                rng,
                static,
                dilated,
                self._slack,
                self.cfg.margin_m,
                self.cfg.margin_fraction,
            )
            != FOREGROUND
        )
        # ... by the ground: a drone hovering over a car or a pole top has them right below
        behind = dilated[cells].astype(np.float64)  # the nearest static surface around
        band = _GROUND_BAND_M + behind * np.tan(np.radians(self.cfg.cell_deg))
        with np.errstate(invalid="ignore"):
            on_ground = behind * np.sin(el) < self.ground_z() + band
        return hidden & np.isfinite(behind) & on_ground

    def is_background(self, points: NDArray[np.floating]) -> NDArray[np.bool_]:
        """True for points that are (dilated) background."""
        return self.classify(points) != FOREGROUND
