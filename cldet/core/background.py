"""Static background, learned online: a per-direction static range over a sliding window.

The sensors do not move, so whatever is seen at the same place most of the recent time is the
environment. A moving object (drone, person, bird) can only appear *in front of* it along a
ray. The model is a static range image, learned causally (only the past is used):

1. Directions from the sensor origin are cut into cells of ``cell_deg`` (2 deg) in azimuth and
   elevation (in the sensor's own frame: a tilted mount changes nothing here). A 2 deg cell is
   ~7 cm wide at 2 m and ~0.7 m at 20 m: it gets about one return per scan from a surface.
   An azimuth column narrows as cos(elevation): where it is narrower than
   ``polar_cell_width`` (a quarter) of a cell, a row's columns are grouped into cells about
   that wide (``azimuth_groups``; above ~76 deg). The Avia, looking up, puts ~4.6 times the
   Mid-360's returns on a steradian, so such a cell is hit as often as a full one at the
   horizon. Without that, a surface right above a sensor looking up (the Avia's boresight)
   falls into slivers hit now and then, is never learned, and its returns scatter as
   foreground: a "track" straight overhead. Wider cells would also hold a drone present from
   the start in its own learned trail for longer.
2. Time is cut into bins of ``bin_s`` (0.2 s = 2 scans). For every cell the model keeps the
   nearest range seen in the current bin; a finished bin enters a ring of the last
   ``window_bins`` (30: 6 s). The first bin is the warm-up: nothing is foreground before it
   ends. A cell of a surface is hit about once a scan, so most cells are hit in every bin; one
   that is missed in some bins still reaches the fraction below.
3. At the end of each bin the cell's *static range* is recomputed: the nearest range reached in
   at least ``static_fraction`` (0.25) of the window's bins (the k-th smallest per-bin minimum;
   a two-scan minimum scatters at grazing incidence, and a low fraction keeps that background).
   A wall, the ground or a tree gives that range in every bin; foliage swaying in and out of a
   direction fills it part of the time and stays background; a drone passing through does not.
   The static range is also the nearest range that *recurs*: reached, within the margin of
   step 6, in at least ``recurrent_bins`` (3) of the window's bins. A thin or far structure
   (a pole, a wire, a branch 30 m out) is hit only now and then, but always at its own range;
   rain and passing things do not come back to one range in one direction.
   A range that is gone is dropped: where the last ``seen_through_bins`` (2) bins returned
   nothing at or before it (farther returns, or none in a cell hit in nearly every bin, a solid
   surface) and it does not recur, the k-th smallest is no surface. A drone receding along its
   line of sight, there since the window began, is always behind its own earlier ranges, and
   would otherwise be learned as its own background; a wall recurs, swaying foliage comes back.
   A drone that stops and hovers would become background after a few seconds: the estimator
   withholds the points of confirmed small moving tracks from ``update`` (``protect_tracks``),
   so what was seen arriving is never learned as environment.
4. A static object never floats: lamp posts, cars and trees stand on something. A small blob of
   static cells (3D extent at most ``floating_max_size_m``, less one cell's width: an object
   straddling the border of two cells is seen in both) whose neighbouring directions are
   all empty or far from it in range (by max(1 m, 10 % of its range)), and at most half of
   them nearer (occluding), is a drone hovering there since the warm-up, not environment: its
   cells are cleared. A blob that stands in front of everything around it (no neighbour is
   nearer) needs only a separate surface behind it (not range-continuous with it: free space
   lies between, as between a drone and the wall 1-2 m behind it); the wider clearance is for
   surfaces seen at a grazing angle, which step away from the sensor on one side and towards
   it on the other (the ground far out: nearer cells below, farther above). Blobs are the 8-connected cells whose static ranges differ by at most
   max(0.5 m, 5 %). One exception to the clearance: right below the blob, up to three cells of a
   separate surface (not range-continuous with it) may be nearer than the clearance: a drone
   hovering a metre above a post top is seen with the top in the next cell down. A lamp head
   is attached to its pole (range-continuous), so it stays part of the pole's blob. A blob
   beside a cell outside the field of view (never hit, below the lowest elevation the sensors
   see: ``field_bottom_deg``) does not float: no free space is known there, and the ground or
   a hedge seen on the field's lowest row is the visible end of something larger; unless
   (``floating_arrivals``) its cells there arrived (``onsets``: the sensors had seen through
   the spot before), stayed (``recurrent_bins``), and their lower edges lie above the ground
   by more than 0.5 m plus a cell's height at that range. A hedge or the ground was there
   before, or is the ground, while a slow drone flying along the field's bottom (a mount
   high above the ground, a tilted sensor) learns its own trail, which recurs. An arrival
   is known while the window (6 s) holds the bins before it: one that stops there for longer
   is learned, unless the estimator protects its track.
5. Dilation: the static range is replaced by the minimum over the cell and its 8 neighbours
   (azimuth wraps), ``dilate_cells`` times: beam divergence at edges stays background.
6. A point is background when its range is not shorter than the static range by more than
   ``max(margin_m, margin_fraction * range, slack)`` (0.3 m, 3 %: range noise ~2 cm, foliage
   depth). ``slack`` is half the smaller range step from the cell to the cells above and below
   it: a surface seen at grazing incidence (the ground far out) spans about that much range
   within one cell. It is CORE background against the undilated static range, MARGIN when
   background only through dilation, FOREGROUND otherwise.

Points from both LiDARs are counted together (both are in the Mid-360 frame). At the end of each
bin the last frame's returns on static surfaces also refit the ground (``cldet.core.ground``):
a plane and a height map, never one number, so that tilted mounts, slopes and rooftops work.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from cldet.config import BackgroundConfig
from cldet.core.ground import GroundModel, GroundPlane
from cldet.core.stats import box_minimum

__all__ = ["CORE", "FOREGROUND", "MARGIN", "BackgroundModel", "StaticView", "direction_cells"]

_POLAR_WIDTH = float(BackgroundConfig.model_fields["polar_cell_width"].default)
FOREGROUND = np.uint8(0)  # in front of the static environment
MARGIN = np.uint8(1)  # background only through dilation
CORE = np.uint8(2)  # at or behind the static range of its own cell

# two ranges in one cell belong to the same surface when within max(1 m, 10 %): the clearance
# the floating-blob rule uses, far above range noise and foliage depth
_SAME_SURFACE_M = 1.0
Directions = tuple[NDArray[np.int64], NDArray[np.float32]]  # points' direction cells, ranges
NO_ONSET = np.iinfo(np.int64).min  # a static surface there as long as the window remembers
_ONSET_SEEN_THROUGH = 2  # bins with a farther return that show a spot was empty before
_ONSET_CONFIDENCE = 0.95  # ... or bins without any return, at the surface's own hit rate
_SAME_SURFACE_FRACTION = 0.1
_SOLID_FRACTION = 0.8  # a cell hit in this share of the window's bins holds a solid surface
# a floating blob may rest on a separate surface right below it this many cells wide (a pole or
# post top: a drone hovering just above it)
_MAX_SUPPORT_CELLS = 3
_GROUND_BAND_M = 0.5  # a static surface this close to the local ground is the ground
_GROUND_EVERY_BINS = 5  # the ground is refitted every this many bins (it does not move)


def direction_cells(
    points: NDArray[np.floating], cell_deg: float, polar_width: float = _POLAR_WIDTH
) -> tuple[NDArray[np.int64], NDArray[np.float32], int, int]:
    """Direction cell of each point (N,3) and its range.

    Returns:
        (flat cell index (N,), range (N,) metres, number of elevation rows, number of azimuth
        columns); flat index = elevation_row * n_az + azimuth_column.
    """
    n_az = int(round(360.0 / cell_deg))
    n_el = int(np.ceil(180.0 / cell_deg))
    p = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
    groups = azimuth_groups(float(cell_deg), float(polar_width))
    cells, rng = _cells_kernel(p, float(cell_deg), n_az, n_el, groups)
    return cells, rng, n_el, n_az


@functools.cache
def azimuth_groups(cell_deg: float, polar_width: float) -> NDArray[np.int64]:
    """(n_el,) per elevation row, how many azimuth columns make one cell.

    An azimuth column spans ``cell_deg * cos(elevation)`` of arc: near the zenith (the Avia's
    boresight) a column is a sliver hit only now and then, so a static surface overhead is never
    learned and its returns scatter as foreground. Where a column at the row's centre is
    narrower than ``polar_width`` (a fraction of ``cell_deg``), the fewest columns that reach
    that width make one cell, never wider than ``cell_deg`` at the row's edge nearest the
    horizon (a divisor of the column count, so groups tile the row); a group's first column
    holds the cell. ``polar_width`` 0: every row keeps its columns.
    """
    n_az = int(round(360.0 / cell_deg))
    n_el = int(np.ceil(180.0 / cell_deg))
    lo = np.arange(n_el) * cell_deg - 90.0
    centre = np.cos(np.radians(lo + 0.5 * cell_deg))
    nearest = np.minimum(np.abs(lo), np.abs(lo + cell_deg))  # the row's edge nearest the horizon
    nearest = np.where(lo * (lo + cell_deg) < 0, 0.0, nearest)  # a row spanning the horizon
    widest = np.floor(1.0 / np.maximum(np.cos(np.radians(nearest)), 1e-9) + 1e-9)
    divisors = np.array([d for d in range(1, n_az + 1) if n_az % d == 0])
    out = np.ones(n_el, dtype=np.int64)
    for e in range(n_el):
        fits = divisors[divisors <= widest[e]]
        wide = fits[fits * centre[e] >= polar_width]
        out[e] = wide.min() if len(wide) else fits.max()
    out.setflags(write=False)
    return out


@numba.njit(cache=True)
def pool_groups(image: NDArray[np.float32], groups: NDArray[np.int64]) -> NDArray[np.float32]:
    """(n_el, n_az) image (no NaN) with each row's groups of columns (``azimuth_groups``: each
    a divisor of n_az) set to their minimum: one cell's value on every column of it, so
    neighbour operations see whole cells."""
    out = image.copy()
    n_el, n_az = image.shape
    for e in range(n_el):
        g = groups[e]
        if g <= 1:
            continue
        if n_az % g:
            raise ValueError("a group of columns must divide the row")
        for a0 in range(0, n_az, g):
            m = image[e, a0]
            for a in range(a0 + 1, a0 + g):
                m = min(m, image[e, a])
            for a in range(a0, a0 + g):
                out[e, a] = m
    return out


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
    points: NDArray[np.float32], cell_deg: float, n_az: int, n_el: int, groups: NDArray[np.int64]
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
        g = groups[ie]
        cells[i] = ie * n_az + (ia // g) * g
    return cells, rng


@numba.njit(cache=True)
def _continuous(r: float, rn: float) -> bool:
    """Two neighbouring static ranges belong to one surface (the blob continuity step)."""
    return abs(rn - r) <= max(0.5, 0.05 * min(r, rn))


@numba.njit(cache=True)
def _clearance(r: float) -> float:
    """Ranges this far apart, or more, are separate surfaces beyond doubt: max(1 m, 10 %)."""
    return max(_SAME_SURFACE_M, _SAME_SURFACE_FRACTION * r)


@numba.njit(cache=True, inline="always")
def _margin(r: float, margin_m: float, margin_fraction: float) -> float:
    """How much nearer than a surface a return at range ``r`` must be to lie in front of it
    (step 6, without the grazing slack); also what "the same range" means for recurrence."""
    return max(margin_m, margin_fraction * r)


def _ground_band(r: NDArray[np.floating], cell_deg: float) -> NDArray[np.floating]:
    """How close to the local ground a static surface at range ``r`` lies when it is the
    ground: ``_GROUND_BAND_M`` plus the cell's height at that range (a fit of the ground seen
    at a grazing angle is that uncertain)."""
    return _GROUND_BAND_M + r * np.tan(np.radians(cell_deg))


def _margins(
    r: NDArray[np.floating], margin_m: float, margin_fraction: float
) -> NDArray[np.floating]:
    """:func:`_margin` of each range of ``r`` (the numpy form, for the questions asked outside
    the kernels)."""
    return np.maximum(margin_m, margin_fraction * r)


@numba.njit(cache=True)
def _nearest_kernel(
    cells: NDArray[np.int64], rng: NDArray[np.float32], nearest: NDArray[np.float32]
) -> None:
    """Per cell: the nearest range seen so far in the bin."""
    for i in range(cells.shape[0]):
        c = cells[i]
        if rng[i] < nearest[c]:
            nearest[c] = rng[i]


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
        limit = rng[i] + max(_margin(rng[i], margin_m, margin_fraction), slack[c])
        if limit >= static[c]:
            out[i] = 2
        elif limit >= dilated[c]:
            out[i] = 1
    return out


@numba.njit(cache=True)
def _recurrent_kernel(
    window: NDArray[np.float32], m: int, margin_m: float, margin_fraction: float
) -> NDArray[np.float32]:
    """Per row of per-bin minima (C, B): the nearest range reached, within the margin, in at
    least ``m`` bins (the farthest of those ``m``), inf when none recurs."""
    n, b = window.shape
    out = np.full(n, np.inf, dtype=np.float32)
    v = np.empty(b, dtype=np.float32)
    for c in range(n):
        k = 0
        for j in range(b):  # insertion sort of the finite minima
            x = window[c, j]
            if not np.isfinite(x):
                continue
            i = k
            while i > 0 and v[i - 1] > x:
                v[i] = v[i - 1]
                i -= 1
            v[i] = x
            k += 1
        for i in range(k - m + 1):
            if v[i + m - 1] - v[i] <= _margin(v[i], margin_m, margin_fraction):
                out[c] = v[i + m - 1]
                break
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
    static: NDArray[np.float32],
    cell_deg: float,
    max_size: float,
    unknown: NDArray[np.bool_],
    arrived: NDArray[np.bool_],
) -> NDArray[np.bool_]:
    """Cells of small static blobs floating in free space (see the module docstring, step 4).

    ``unknown`` (n_el, n_az) marks cells outside the field of view: no free space is known
    there, so a blob beside one may be the visible end of something larger, unless the blob's
    cell beside it is marked in ``arrived`` (its surface came where the sensors had seen
    through, clear of the ground: nothing larger stood there).
    """
    n_el, n_az = static.shape
    comp = np.full((n_el, n_az), -1, dtype=np.int64)
    out = np.zeros((n_el, n_az), dtype=np.bool_)
    support = np.full((n_el, n_az), -1, dtype=np.int64)  # marks support cells per component
    stack = np.empty((n_el * n_az, 2), dtype=np.int64)
    members = np.empty((n_el * n_az, 2), dtype=np.int64)
    deg = np.pi / 180.0
    cell_rad = cell_deg * deg
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
            # judge the component; does it stand in front of everything around it (a range
            # minimum on every side)? A surface seen at a grazing angle has nearer cells below
            standing_out = True
            for k in range(m):
                e, a = members[k, 0], members[k, 1]
                for de in (-1, 0, 1):
                    ee = e + de
                    if ee < 0 or ee >= n_el:
                        continue
                    for da in (-1, 0, 1):
                        aa = (a + da) % n_az
                        if comp[ee, aa] != n_comp and static[ee, aa] < static[e, a]:
                            standing_out = False
            ok = True
            n_border = 0
            n_nearer = 0
            n_support = 0
            lo = np.full(3, np.inf)
            hi = np.full(3, -np.inf)
            r_far = 0.0
            for k in range(m):
                e, a = members[k, 0], members[k, 1]
                r = static[e, a]
                el = ((e + 0.5) * cell_deg - 90.0) * deg
                az = ((a + 0.5) * cell_deg - 180.0) * deg
                p0 = r * np.cos(el) * np.cos(az)
                p1 = r * np.cos(el) * np.sin(az)
                p2 = r * np.sin(el)
                lo[0], hi[0] = min(lo[0], p0), max(hi[0], p0)
                lo[1], hi[1] = min(lo[1], p1), max(hi[1], p1)
                lo[2], hi[2] = min(lo[2], p2), max(hi[2], p2)
                # cell centres one cell apart may hold an object straddling their border: the
                # object is at least the centres' extent less one cell width at that range
                r_far = max(r_far, r)
                span = max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) - r_far * cell_rad
                if span > max_size:
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
                        if unknown[ee, aa]:
                            if arrived[e, a]:
                                continue  # it came there: not the end of something standing
                            ok = False
                            break
                        rn = static[ee, aa]
                        if not np.isfinite(rn):
                            continue
                        if standing_out and rn > r and not _continuous(r, rn):
                            continue  # a separate surface behind it: free space in between
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


@dataclass(frozen=True)
class StaticView:
    """The static range image at one instant, for questions asked after the pass (the
    refinement's): would a drone at a point have been seen in front of everything static, or
    could the static scene there hide it (a drone that stopped beside a wall and was learned,
    or that went behind it)?"""

    around: NDArray[np.float32]  # (n_el * n_az,) the nearest static range in a cell and its 8
    cell_deg: float
    margin_m: float
    margin_fraction: float
    bottom_deg: float  # the lowest elevation the sensors see (their own frame)
    # (n_el * n_az,) the undilated static range and, per cell, when its static surface was
    # first seen there after the space in front had been seen empty (ns; NO_ONSET: always
    # there as far as the window remembers); None where not computed (``view(onset=True)``)
    static: NDArray[np.float32] | None = None
    onset_ns: NDArray[np.int64] | None = None
    polar_width: float = _POLAR_WIDTH  # see ``azimuth_groups``

    def open(self, points: NDArray[np.floating]) -> NDArray[np.bool_]:
        """(N,) the points lie in the sensors' field of view and in front of every static
        surface of their direction and the 8 around by the background's margin: a drone there
        returns foreground (with the default dilation of one cell)."""
        p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        cells, rng, _, _ = direction_cells(p, self.cell_deg, self.polar_width)
        horiz = np.hypot(p[:, 0], p[:, 1])
        in_field = np.degrees(np.arctan2(p[:, 2], horiz)) >= self.bottom_deg + self.cell_deg
        margin = _margins(rng, self.margin_m, self.margin_fraction)
        return in_field & (rng + margin < self.around[cells])

    def screened(self, points: NDArray[np.floating]) -> NDArray[np.bool_]:
        """(N,) a static surface lies at or in front of each point, in its direction or one cell
        around, no farther behind it than two surfaces can be told apart (max(1 m, 10 %)):
        something static there hides it, or it is itself learned as static."""
        p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        cells, rng, _, _ = direction_cells(p, self.cell_deg, self.polar_width)
        reach = np.maximum(_SAME_SURFACE_M, _SAME_SURFACE_FRACTION * rng)
        return self.around[cells] <= rng + reach

    def appeared(self, points: NDArray[np.floating], since_ns: int) -> NDArray[np.bool_]:
        """(N,) the static surface of each point's direction lies at the point (within the
        background's margin) and was first seen there at ``since_ns`` or later, where before
        the sensors had seen through that spot: something came to rest there (a drone that
        stopped and was learned as background). False where the onset was not computed."""
        p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        if self.static is None or self.onset_ns is None:
            return np.zeros(len(p), dtype=bool)
        cells, rng, _, _ = direction_cells(p, self.cell_deg, self.polar_width)
        margin = _margins(rng, self.margin_m, self.margin_fraction)
        here = np.abs(self.static[cells] - rng) <= margin
        return here & (self.onset_ns[cells] >= since_ns)


class BackgroundModel:
    """Online static range image: per frame, ``advance`` to its stamp, ``classify``, ``update``.

    Frames come in stamp order (integer ns). ``classify`` only uses finished bins, so a frame is
    always judged by the past; until the first bin ends (``warm``) nothing is foreground.
    """

    def __init__(
        self,
        cfg: BackgroundConfig,
        field_bottom_deg: float = -90.0,
        ground_plane: GroundPlane | None = None,
    ) -> None:
        """``field_bottom_deg``: the lowest elevation any sensor sees (in the sensor's frame);
        never-hit cells below it are outside the field of view, not free space.
        ``ground_plane``: the ground plane when known (never fitted then)."""
        self.cfg = cfg
        self._field_bottom_deg = field_bottom_deg
        self._n_az = int(round(360.0 / cfg.cell_deg))
        self._n_el = int(np.ceil(180.0 / cfg.cell_deg))
        n_cells = self._n_el * self._n_az
        # per cell, its nearest range in each of the last bins (cell-major: the order statistic
        # runs along contiguous memory)
        self._ring = np.full((n_cells, cfg.window_bins), np.inf, dtype=np.float32)
        self._ring_end_ns = np.zeros(cfg.window_bins, dtype=np.int64)  # each slot's bin end
        self._seen = np.zeros(n_cells, dtype=bool)  # cells ever hit in a finished bin
        self._current = np.full(n_cells, np.inf, dtype=np.float32)
        self._bin_ns = max(1, int(round(cfg.bin_s * 1e9)))
        self._bin_end_ns: int | None = None
        self.n_bins = 0  # finished bins so far
        self._static = np.full(n_cells, np.inf, dtype=np.float32)  # undilated static range
        self._dilated = self._static
        self._around = self._static  # the nearest static range in each cell and its 8
        self._slack = np.zeros(n_cells, dtype=np.float32)  # extra margin (grazing surfaces)
        self.floating_cells = 0  # cells released as floating blobs at the last refresh
        self.ground = GroundModel(field_bottom_deg=field_bottom_deg, plane=ground_plane)
        self.n_frames = 0
        self._last_points = np.zeros((0, 3), dtype=np.float32)  # the last frame counted

    @property
    def warm(self) -> bool:
        """The warm-up bin has ended: ``classify`` can call anything foreground."""
        return self.n_bins > 0

    def view(self, onset: bool = False) -> StaticView:
        """The static range image as it stands (arrays shared, never changed in place: a refresh
        replaces them); with ``onset``, also when each cell's static surface appeared
        (:meth:`onsets`: the window's bins are read, so only for a final view)."""
        cfg = self.cfg
        return StaticView(
            self._around,
            float(cfg.cell_deg),
            float(cfg.margin_m),
            float(cfg.margin_fraction),
            self._field_bottom_deg,
            self._static if onset else None,
            self.onsets() if onset else None,
            float(cfg.polar_cell_width),
        )

    def onsets(self) -> NDArray[np.int64]:
        """(n_el * n_az,) per cell, the start of the first bin of the window in which its static
        surface was seen, where before it the sensors saw through that spot: a farther return
        in at least ``_ONSET_SEEN_THROUGH`` bins, or none in so many bins that a surface there,
        hit at its rate since, would have been hit (``1 - _ONSET_CONFIDENCE`` chance); else
        ``NO_ONSET`` (there as long as the window remembers, or never static)."""
        out = np.full(len(self._static), NO_ONSET, dtype=np.int64)
        cells = np.flatnonzero(np.isfinite(self._static) & self._seen)  # a group's own column
        out[cells] = self._onsets_at(cells, self._static[cells])[0]
        return out

    def _onsets_at(
        self, cells: NDArray[np.int64], static: NDArray[np.float32]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """:meth:`onsets` of the ``cells`` (indices of cells ever hit) whose static ranges are
        ``static`` (finite), and in how many bins from then on the surface was hit."""
        cfg = self.cfg
        b = min(self.n_bins, cfg.window_bins)
        out = np.full(len(cells), NO_ONSET, dtype=np.int64)
        if b < 2 or not len(cells):
            return out, np.zeros(len(cells), dtype=np.int64)
        order = (np.arange(b) + (self.n_bins - b)) % cfg.window_bins  # oldest bin first
        ring = self._ring[cells][:, order]  # (C, b)
        static = static[:, None]
        margin = _margins(static, cfg.margin_m, cfg.margin_fraction)
        near = np.abs(ring - static) <= margin
        far = np.isfinite(ring) & (ring > static + margin)
        first = np.argmax(near, axis=1)  # the static surface is hit in some bin (k-th smallest)
        before = np.arange(b)[None, :] < first[:, None]
        n_far = np.sum(far & before, axis=1)
        n_none = np.sum(~np.isfinite(ring) & before, axis=1)
        hits = np.sum(near & ~before, axis=1)
        rate = hits / (b - first)
        with np.errstate(divide="ignore"):
            missed = n_none * np.log1p(-np.minimum(rate, 0.999))  # log P(no hit in those bins)
        new = (first > 0) & (
            (n_far >= _ONSET_SEEN_THROUGH) | (missed <= np.log(1.0 - _ONSET_CONFIDENCE))
        )
        out[new] = self._ring_end_ns[order][first[new]] - self._bin_ns
        return out, hits

    def _arrived(
        self, static: NDArray[np.float32], unknown: NDArray[np.bool_]
    ) -> NDArray[np.bool_]:
        """(n_el, n_az) the static cells beside the unknown (``_unknown``) whose surface arrived
        there (``onsets``: the sensors had seen through that spot before), stayed (hit in
        ``recurrent_bins`` bins since: not rain learned while the window holds a few bins), and
        whose lower edge, at the static range, lies above the ground by more than
        ``_GROUND_BAND_M`` plus the cell's height there (a fit of the ground seen at a grazing
        angle is that uncertain; the ground is the lower of the plane and the height map, so
        what a drone learned there adds to the map does not count). Such a blob is not the
        visible end of something standing on the ground, as a hedge or the ground far out seen
        on the field's lowest row is (they were there before, or are the ground): a slow drone
        flying along the bottom of the field of view, learned from its own trail, is cleared by
        the floating rule (step 4)."""
        out = np.zeros(unknown.size, dtype=np.bool_)
        if not self.cfg.floating_arrivals or not unknown.any() or not self.ground.fitted:
            return out.reshape(unknown.shape)
        beside = box_minimum(np.where(unknown, 0.0, 1.0).astype(np.float32), 3, True) == 0.0
        flat = static.ravel()
        cells = np.flatnonzero(beside.ravel() & ~unknown.ravel() & np.isfinite(flat) & self._seen)
        if not len(cells):
            return out.reshape(unknown.shape)
        r = flat[cells].astype(np.float64)
        e, a = np.divmod(cells, self._n_az)
        el = np.radians(e * self.cfg.cell_deg - 90.0)  # the cell's lower edge
        az = np.radians((a + 0.5) * self.cfg.cell_deg - 180.0)
        low = np.column_stack(
            [r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)]
        )
        band = _ground_band(r, self.cfg.cell_deg)
        with np.errstate(invalid="ignore"):
            lifted = -self.ground.depth_below(low) > band
        cells, r = cells[lifted], r[lifted]
        onset, hits = self._onsets_at(cells, r.astype(np.float32))
        came = (onset != NO_ONSET) & (hits >= max(self.cfg.recurrent_bins, 1))
        out[cells[came]] = True
        return out.reshape(unknown.shape)

    def advance(self, stamp_ns: int) -> None:
        """Move the clock to ``stamp_ns``: a bin that ended before it is finished first."""
        if self._bin_end_ns is None:
            self._bin_end_ns = stamp_ns + self._bin_ns
            return
        if stamp_ns < self._bin_end_ns:
            return
        self._ring[:, self.n_bins % self.cfg.window_bins] = self._current
        self._ring_end_ns[self.n_bins % self.cfg.window_bins] = self._bin_end_ns
        self._seen |= np.isfinite(self._current)
        self.n_bins += 1
        self._current = np.full_like(self._current, np.inf)
        # after a gap the next bin starts at this frame
        late = (stamp_ns - self._bin_end_ns) // self._bin_ns
        self._bin_end_ns += (late + 1) * self._bin_ns
        self._refresh()

    def update(
        self,
        stamp_ns: int,
        points: NDArray[np.floating],
        directions: Directions | None = None,
    ) -> None:
        """Count one frame's points ((N,3) metres, Mid-360 frame) into the current bin;
        ``directions``: their cells and ranges (``directions``) when already known."""
        self.advance(stamp_ns)
        self.n_frames += 1
        if len(points) == 0:
            return
        self._last_points = np.asarray(points)
        cells, rng = directions if directions is not None else self.directions(points)
        _nearest_kernel(cells, rng, self._current)

    def _refresh(self) -> None:
        """Recompute the static range, the floating blobs, the slack, the dilation, the ground."""
        cfg = self.cfg
        b = min(self.n_bins, cfg.window_bins)
        k = max(1, int(np.floor(cfg.static_fraction * b + 0.5)))
        seen = np.flatnonzero(self._seen)  # the rest (outside every field of view) stays inf
        kth = np.full(len(self._seen), np.inf, dtype=np.float32)
        window = self._ring[seen, :b]
        kth[seen] = np.partition(window, k - 1, axis=1)[:, k - 1] if b > 1 else window[:, 0]
        recurrent = np.full(len(seen), np.inf, dtype=np.float32)
        if 0 < cfg.recurrent_bins <= b:
            recurrent = _recurrent_kernel(
                window, cfg.recurrent_bins, float(cfg.margin_m), float(cfg.margin_fraction)
            )
        n_through = cfg.seen_through_bins
        if 0 < n_through < b:
            # gone: the last bins returned nothing at or before the k-th range (by the
            # classification's own margin, a grazing surface's slack included), and that range
            # does not recur (a cell holding two surfaces keeps its nearer one)
            near = kth[seen]
            margin = _margins(near, cfg.margin_m, cfg.margin_fraction)
            margin = np.maximum(margin, self._slack[seen])
            # the window's columns are the ring's first b slots, so the last bins are among them
            last = window[:, (self.n_bins - 1 - np.arange(n_through)) % cfg.window_bins]
            with np.errstate(invalid="ignore"):
                idx = np.flatnonzero(np.all(last > (near + margin)[:, None], axis=1))
            # ... seen through (farther returns), or empty where a solid surface was hit in
            # nearly every bin (the sparse far ground misses whole bins and stays); only the
            # few candidate cells' windows are read
            rows = window[idx]
            solid = np.mean(np.isfinite(rows), axis=1) >= _SOLID_FRACTION
            through = np.all(np.isfinite(last[idx]), axis=1) | solid
            with np.errstate(invalid="ignore"):
                recurs = np.abs(rows - near[idx, None]) <= margin[idx, None]
            through &= np.sum(recurs, axis=1) < max(cfg.recurrent_bins, 1)
            kth[seen[idx[through]]] = np.inf
        kth[seen] = np.minimum(kth[seen], recurrent)
        groups = azimuth_groups(float(cfg.cell_deg), float(cfg.polar_cell_width))
        static = pool_groups(kth.reshape(self._n_el, self._n_az), groups)
        self.floating_cells = 0
        if cfg.floating_max_size_m > 0:
            unknown = self._unknown()
            floating = _floating_blobs(
                static,
                float(cfg.cell_deg),
                float(cfg.floating_max_size_m),
                unknown,
                self._arrived(static, unknown),
            )
            self.floating_cells = int(floating.sum())
            if self.floating_cells:
                static = np.where(floating, np.float32(np.inf), static)
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
        if cfg.dilate_cells > 0:
            size = 2 * cfg.dilate_cells + 1
            dilated = box_minimum(static, size, wrap_columns=True)
            dilated = pool_groups(dilated, groups)
        self._static = np.ascontiguousarray(static, dtype=np.float32).ravel()
        self._dilated = np.ascontiguousarray(dilated, dtype=np.float32).ravel()
        if cfg.dilate_cells != 1:
            dilated = pool_groups(box_minimum(static, 3, wrap_columns=True), groups)
        self._around = np.ascontiguousarray(dilated, dtype=np.float32).ravel()
        # the ground from the last frame's returns on static surfaces (real points: a cell's
        # centre at its nearest range sits above a ground seen at a grazing angle)
        last = self._last_points
        if len(last) and (self.n_bins % _GROUND_EVERY_BINS == 1 or not self.ground.fitted):
            self.ground.fit(last[self.classify(last) == CORE])

    def _unknown(self) -> NDArray[np.bool_]:
        """(n_el, n_az) cells never hit whose centre lies below the field of view."""
        centre_deg = (np.arange(self._n_el) + 0.5) * self.cfg.cell_deg - 90.0
        below = (centre_deg < self._field_bottom_deg)[:, None]
        return below & ~self._seen.reshape(self._n_el, self._n_az)

    def classify(
        self, points: NDArray[np.floating], directions: Directions | None = None
    ) -> NDArray[np.uint8]:
        """Label each point (N,3) FOREGROUND (0), MARGIN (1) or CORE (2) background;
        ``directions``: their cells and ranges (``directions``) when already known.

        During the warm-up every point is CORE background.
        """
        if len(points) == 0:
            return np.zeros(0, dtype=np.uint8)
        if not self.warm:
            return np.full(len(points), CORE, dtype=np.uint8)
        cells, rng = directions if directions is not None else self.directions(points)
        return self._labels(cells, rng)

    def vacated(
        self, points: NDArray[np.floating], n_bins: int, directions: Directions | None = None
    ) -> NDArray[np.bool_]:
        """(N,) nothing returned at or in front of each point's range (by the margin) in its
        direction cell in each of the last ``n_bins`` finished bins: whatever was there then
        has gone (farther returns, or none); ``directions``: the points' cells and ranges
        (``directions``) when already known."""
        p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        b = min(n_bins, self.n_bins, self.cfg.window_bins)
        if len(p) == 0 or b <= 0:
            return np.zeros(len(p), dtype=bool)
        cells, rng = directions if directions is not None else self.directions(p)
        slots = (self.n_bins - 1 - np.arange(b)) % self.cfg.window_bins
        recent = self._ring[cells[:, None], slots[None, :]].min(axis=1)
        return recent > rng + _margins(rng, self.cfg.margin_m, self.cfg.margin_fraction)

    def directions(self, points: NDArray[np.floating]) -> Directions:
        """``direction_cells`` of points (N,3) on this model's grid: cell indices and ranges
        (for ``classify`` and ``update`` of the same points, or a subset: index both arrays)."""
        cells, rng, _, _ = direction_cells(points, self.cfg.cell_deg, self.cfg.polar_cell_width)
        return cells, rng

    def _labels(self, cells: NDArray[np.int64], rng: NDArray[np.float32]) -> NDArray[np.uint8]:
        """FOREGROUND / MARGIN / CORE of returns at these cells and ranges."""
        return _classify_kernel(
            cells,
            rng,
            self._static,
            self._dilated,
            self._slack,
            self.cfg.margin_m,
            self.cfg.margin_fraction,
        )

    def hidden_below(self, points: NDArray[np.floating]) -> NDArray[np.bool_]:
        """For each point (N,3): would a point one cell lower, at the same range, be background?

        ... and that background is the ground: its static surface there lies within 0.5 m plus
        the cell's own height uncertainty (range times a cell's angle) of the local ground.
        Then whatever continues below it is not seen: a walking person's legs in front of the
        ground seen at a grazing angle fall within the ground's margin, leaving the upper body
        as foreground. "Lower" is one cell down in the sensor's own elevation; "ground" comes
        from the fitted ground model, so a tilted sensor or a slope does not fool it.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(p) == 0 or not self.warm or not self.ground.fitted:
            return np.zeros(len(p), dtype=bool)
        h = np.hypot(p[:, 0], p[:, 1])
        r = np.hypot(h, p[:, 2])
        el = np.arctan2(p[:, 2], h) - np.radians(self.cfg.cell_deg)
        scale = np.where(h > 0, r * np.cos(el) / np.maximum(h, 1e-9), 0.0)
        probe = np.stack([p[:, 0] * scale, p[:, 1] * scale, r * np.sin(el)], axis=1)
        cells, rng = self.directions(probe.astype(np.float32))
        hidden = self._labels(cells, rng) != FOREGROUND
        # ... by the ground: a drone hovering over a car or a pole top has them right below
        behind = self._dilated[cells].astype(np.float64)  # the nearest static surface around
        surface = (
            probe
            / np.maximum(r, 1e-9)[:, None]
            * np.where(np.isfinite(behind), behind, 0.0)[:, None]
        )
        band = _ground_band(behind, self.cfg.cell_deg)
        with np.errstate(invalid="ignore"):
            on_ground = self.ground.height_above(surface) < band
        return hidden & np.isfinite(behind) & on_ground

    def is_background(self, points: NDArray[np.floating]) -> NDArray[np.bool_]:
        """True for points that are (dilated) background."""
        return self.classify(points) != FOREGROUND
