"""Sensor models: Livox Mid-360 and Avia scans, the buffered radar, and tiny camera PNGs.

Scans fire a fresh set of random directions every frame (a non-repetitive pattern), each ray at its
own instant within the 100 ms scan, against the static scene and the movers. A ray returns a point
with a probability set by the surface and a fade beyond ~70 m; on the drone, whose airframe has a
known reflectivity, the fade starts instead at the sensor's published detection range for that
reflectivity (``DetectionRange``). The range gets ~2 cm of noise and every coordinate is rounded
to millimetres and stored as a float32 value (as the real files).
Rays without a return are zero rows: (0, 0, 0) for the Mid-360, (-0.0, -0.0, +0.0) for the Avia.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from cldet.simulate.flight import Mover
from cldet.simulate.raycast import hit_moving_box, hit_moving_cylinder, hit_moving_sphere
from cldet.simulate.scene import (
    BIRD,
    DRONE,
    GROUND,
    HIT_PROBABILITY,
    PENETRATION_M,
    PERSON,
    Scene,
)

F64 = NDArray[np.float64]

MID360_ROW_CYCLE: tuple[int, ...] = (20064, 19968, 19968)  # rows per frame, cycling
AVIA_ROWS = 24000
PACKET_ROWS = 96
SCAN_PERIOD_S = 0.1  # each scan spans [stamp, stamp + 100 ms)
MID360_ELEVATION_DEG = (-7.0, 52.0)
AVIA_MIN_ELEVATION_DEG = 52.0
RANGE_NOISE_M = 0.02
FADE_START_M = 70.0  # = the Mid-360's detection range at 80 % reflectivity (see MID360_RANGE)
AVIA_DENSITY_SCALE = 0.85  # Avia per-ray return probability relative to the Mid-360 (~4.7x denser)
_GRAZE_FULL = np.sin(np.radians(3.0))  # below this incidence the ground fades out
_GRASS_M = 0.03  # mean depth of ground returns below the surface (grass), metres
_SECTORS = 17  # azimuth sectors the Mid-360 sweeps up and down within one scan


@dataclass(frozen=True)
class ScanResult:
    """One simulated LiDAR frame."""

    points: F64  # (rows, 3) float64 with zero rows where no return; metres
    drone_points: int  # how many valid rows are on the drone
    drone_sum: F64  # (3,) sum of the drone's points (metres), for centroids
    distractor_points: int  # how many valid rows are on people and birds
    drone_rows: NDArray[np.intp] = field(  # (K,) row indices of the drone's points
        default_factory=lambda: np.zeros(0, dtype=np.intp)
    )


def mid360_directions(rng: np.random.Generator, rows: int) -> F64:
    """(rows, 3) unit directions for one Mid-360 scan, ordered so that packets are local patches.

    Elevations are uniform in -7..52 deg and azimuths uniform (new draws every frame); rows sweep
    azimuth sectors up and down, so a 96-row packet covers one small patch and patches of sky come
    out as all-zero packets, as in the real files.
    """
    lo, hi = MID360_ELEVATION_DEG
    el = rng.uniform(lo, hi, rows)
    az = rng.uniform(0.0, 2.0 * np.pi, rows)
    rot = (az + rng.uniform(0.0, 2.0 * np.pi)) % (2.0 * np.pi)
    sector = np.floor(rot / (2.0 * np.pi) * _SECTORS).astype(np.int64)
    up_down = np.where(sector % 2 == 0, el - lo, hi - el) / (hi - lo + 1.0)  # in [0, 1)
    order = np.argsort(sector + up_down)
    el_r = np.radians(el[order])
    az_r = az[order]
    return np.column_stack([np.cos(el_r) * np.cos(az_r), np.cos(el_r) * np.sin(az_r), np.sin(el_r)])


def avia_directions(rng: np.random.Generator, rows: int = AVIA_ROWS) -> F64:
    """(rows, 3) unit directions uniform in the Avia's upward cone (elevation >= 52 deg)."""
    cos_max = np.cos(np.radians(90.0 - AVIA_MIN_ELEVATION_DEG - 0.05))
    cz = rng.uniform(cos_max, 1.0, rows)
    az = rng.uniform(0.0, 2.0 * np.pi, rows)
    sz = np.sqrt(1.0 - cz * cz)
    return np.column_stack([sz * np.cos(az), sz * np.sin(az), cz])


@dataclass(frozen=True)
class DetectionRange:
    """A LiDAR's published detection range at reference reflectivities, and the law fitted to it.

    Datasheets give the range (in 100 klx sunlight) to which a flat target of a given diffuse
    reflectivity is still detected. The Livox figures follow a power law ``R = R0 * rho^k``
    (least squares in log-log): the Mid-360's 40 m @ 10 % and 70 m @ 80 % give k = 0.27, the
    Avia's 190 m @ 10 %, 230 m @ 20 % and 320 m @ 80 % give k = 0.25 (within 1.5 % of all three):
    flatter than the k = 1/2 of an ideal flat target (received power ~ rho / r^2), as the
    datasheets' own figures are (sunlight noise and the air's losses grow with range).
    """

    reflectivity: tuple[float, ...]  # reference reflectivities, 0-1
    range_m: tuple[float, ...]  # published detection range at each, metres

    def exponent(self) -> tuple[float, float]:
        """(k, log R0) of the fitted law ``log R = log R0 + k log rho``."""
        k, log_r0 = np.polyfit(np.log(self.reflectivity), np.log(self.range_m), 1)
        return float(k), float(log_r0)

    def range_at(self, reflectivity: F64) -> F64:
        """Detection range (m) at each reflectivity (0-1) by the fitted law."""
        k, log_r0 = self.exponent()
        return np.asarray(np.exp(log_r0 + k * np.log(reflectivity)), dtype=np.float64)


# Livox datasheets, detection range @ 100 klx (Mid-360 user manual; Avia specifications).
MID360_RANGE = DetectionRange((0.10, 0.80), (40.0, 70.0))
AVIA_RANGE = DetectionRange((0.10, 0.20, 0.80), (190.0, 230.0, 320.0))


def _fade(r: F64) -> F64:
    """Return probability factor for range: 1 up to 70 m, then a Gaussian roll-off, none beyond 95 m."""
    f = np.exp(-(((r - FADE_START_M) / 12.0) ** 2))
    return np.where(r <= FADE_START_M, 1.0, np.where(r < 95.0, f, 0.0))


def reflectivity_fade(r: F64, reflectivity: F64, sensor: DetectionRange) -> F64:
    """Return probability factor for a target of known reflectivity (0-1) at range ``r`` (m).

    The simulator's range fade (``_fade``, which starts at the Mid-360's 70 m @ 80 %) stretched
    to the sensor's detection range at that reflectivity: 1 up to it, a Gaussian roll-off over
    the next 12/70 of it, none beyond 95/70 of it. A white airframe on the Mid-360 keeps the
    old fade; a dark one (10 %) fades from 40 m, gone at 54 m; on the Avia both reach 190 m+.
    """
    return _fade(r * (FADE_START_M / sensor.range_at(reflectivity)))


def _cast_movers(
    dirs: F64,
    ray_t: F64,
    movers: list[Mover],
    dist: F64,
    kind: NDArray[np.intp],
    reflectivity: F64,
) -> None:
    """Update ``dist``/``kind``/``reflectivity`` in place with the movers' surfaces (each ray at
    its own instant); ``reflectivity`` is NaN where the surface has none of its own."""
    t_mid = float(ray_t[len(ray_t) // 2]) if len(ray_t) else 0.0
    t_lo = float(ray_t.min()) if len(ray_t) else 0.0
    t_hi = float(ray_t.max()) if len(ray_t) else 0.0
    for mover in movers:
        a, b = mover.active_s
        if t_hi < a or t_lo > b:
            continue
        ends = mover.track.at(np.array([t_lo, t_mid, t_hi]))
        centre = ends[1]
        r_c = float(np.linalg.norm(centre))
        reach = mover.bounding_radius() + float(np.linalg.norm(ends[2] - ends[0])) + 0.5
        if mover.shape == "cylinder":
            centre = centre + np.array([0.0, 0.0, mover.dims[1] / 2])
            r_c = float(np.linalg.norm(centre))
        if r_c <= reach:
            cand = np.arange(len(dirs))
        else:
            cos_cut = np.cos(np.arcsin(min(reach / r_c, 1.0)))
            cand = np.flatnonzero(dirs @ (centre / r_c) >= cos_cut)
        cand = cand[(ray_t[cand] >= a) & (ray_t[cand] <= b)]
        if len(cand) == 0:
            continue
        d = dirs[cand]
        pos = mover.track.at(ray_t[cand])
        if mover.shape == "box":
            t = hit_moving_box(d, pos, np.asarray(mover.dims), mover.track.yaw_at(ray_t[cand]))
        elif mover.shape == "cylinder":
            t = hit_moving_cylinder(d, pos, mover.dims[0], mover.dims[1])
        else:
            t = hit_moving_sphere(d, pos, mover.dims[0])
        better = t < dist[cand]
        dist[cand[better]] = t[better]
        kind[cand[better]] = mover.kind
        reflectivity[cand[better]] = np.nan if mover.reflectivity is None else mover.reflectivity


def _to_points(dirs: F64, r: F64) -> NDArray[np.float32]:
    """Points along ``dirs`` at ranges ``r``, rounded to mm and stored as float32 values."""
    p = dirs * r[:, None]
    return np.round(p * 1000.0).astype(np.float32) / np.float32(1000.0)


def scan(
    dirs: F64,
    stamp_s: float,
    scene: Scene,
    movers: list[Mover],
    rng: np.random.Generator,
    density_scale: float = 1.0,
    rotation: F64 | None = None,
    sensor: DetectionRange = MID360_RANGE,
) -> tuple[F64, NDArray[np.bool_], NDArray[np.intp]]:
    """Ray-cast one frame: each ray fired at ``stamp_s + i/rows * 100 ms``.

    Args:
        dirs: (rows, 3) unit directions in firing order, in the sensor's frame.
        stamp_s: scan start, seconds since the sequence start.
        scene: the static world.
        movers: drone, people, birds.
        rng: random source (detection, range noise).
        density_scale: multiplies every return probability (sensor sensitivity).
        rotation: (3, 3) sensor-to-scene rotation (a tilted mount): rays are cast along
            ``rotation @ d`` in the scene, points are returned in the sensor's frame. None: level.
        sensor: the LiDAR's detection range, for movers with a reflectivity (the drone).

    Returns:
        (rows, 3) float64 points in the sensor's frame (rows without a return hold zeros),
        (rows,) valid mask,
        (rows,) surface kind of each row (-1 where no surface was hit).
    """
    rows = dirs.shape[0]
    ray_t = stamp_s + SCAN_PERIOD_S * np.arange(rows) / rows
    cast_dirs = dirs if rotation is None else dirs @ rotation.T  # scene frame
    dist, kind = scene.cast(cast_dirs, stamp_s + SCAN_PERIOD_S / 2, rng)
    refl = np.full(rows, np.nan)
    _cast_movers(cast_dirs, ray_t, movers, dist, kind, refl)
    hit = np.isfinite(dist)
    prob = np.zeros(rows)
    prob[hit] = HIT_PROBABILITY[kind[hit]] * _fade(dist[hit]) * density_scale
    known = np.isfinite(refl)  # on a mover of known reflectivity: the sensor's own range for it
    fade = reflectivity_fade(dist[known], refl[known], sensor)
    prob[known] = HIT_PROBABILITY[kind[known]] * fade * density_scale
    # the ground returns less at grazing incidence and from inside the grass
    ground = kind == GROUND
    sin_graze = np.maximum(-scene.ground_up_component(cast_dirs), 1e-3)
    prob[ground] *= np.minimum(1.0, sin_graze[ground] / _GRAZE_FULL) ** 1.5
    valid = rng.random(rows) < prob
    r = np.where(valid, dist, 0.0)
    pen = PENETRATION_M[np.maximum(kind, 0)]
    pen = np.where(ground, _GRASS_M / sin_graze, pen)
    depth = np.minimum(rng.exponential(1.0, rows) * pen, 2.0)  # at most 2 m behind the surface
    r = r + valid * (rng.normal(0.0, RANGE_NOISE_M, rows) + depth)
    r = np.where(valid, np.maximum(r, 0.05), 0.0)
    points = _to_points(dirs, r).astype(np.float64)
    valid &= np.any(points != 0.0, axis=1)
    points[~valid] = 0.0
    return points, valid, kind


def mid360_frame(
    rng: np.random.Generator,
    rows: int,
    stamp_s: float,
    scene: Scene,
    movers: list[Mover],
    rotation: F64 | None = None,
) -> ScanResult:
    """One Mid-360 frame: ``rows`` rows, plus 0-4 lone speckle points and 1-2 self-returns.

    ``rotation`` (3, 3) turns the sensor's frame into the scene's (a tilted mount, see ``scan``).
    """
    dirs = mid360_directions(rng, rows)
    points, valid, kind = scan(dirs, stamp_s, scene, movers, rng, rotation=rotation)
    on_drone = valid & (kind == DRONE)
    drone = int(np.count_nonzero(on_drone))
    drone_sum = points[on_drone].sum(axis=0)
    others = int(np.count_nonzero(valid & ((kind == PERSON) | (kind == BIRD))))
    empty = np.flatnonzero(~valid)
    n_speckle = int(rng.integers(0, 5))
    n_self = int(rng.integers(1, 3))
    if len(empty) >= n_speckle + n_self:
        pick = rng.choice(empty, n_speckle + n_self, replace=False)
        ranges = np.concatenate([rng.uniform(1.0, 60.0, n_speckle), rng.uniform(0.03, 0.1, n_self)])
        points[pick] = _to_points(dirs[pick], ranges).astype(np.float64)
    return ScanResult(points, drone, drone_sum, others, np.flatnonzero(on_drone))


def avia_frame(
    rng: np.random.Generator,
    stamp_s: float,
    scene: Scene,
    movers: list[Mover],
    clutter: bool,
    rotation: F64 | None = None,
) -> ScanResult:
    """One Avia frame: 24000 rows looking up; ``clutter`` adds 1-10 sporadic (mostly far) returns.

    ``rotation`` (3, 3) turns the sensor's frame into the scene's: the Avia is rigidly mounted
    with the Mid-360, so its cone tilts with it.
    """
    dirs = avia_directions(rng)
    points, valid, kind = scan(
        dirs, stamp_s, scene, movers, rng, AVIA_DENSITY_SCALE, rotation=rotation, sensor=AVIA_RANGE
    )
    on_drone = valid & (kind == DRONE)
    drone = int(np.count_nonzero(on_drone))
    drone_sum = points[on_drone].sum(axis=0)
    others = int(np.count_nonzero(valid & ((kind == PERSON) | (kind == BIRD))))
    if clutter:
        n = min(int(rng.geometric(0.35)), 10)
        empty = np.flatnonzero(~valid)
        pick = rng.choice(empty, n, replace=False)
        far = rng.random(n) < 0.75
        ranges = np.where(far, rng.uniform(100.0, 430.0, n), rng.uniform(5.0, 60.0, n))
        points[pick] = _to_points(dirs[pick], ranges).astype(np.float64)
        valid[pick] = True
    out = points
    out[~valid] = np.array([-0.0, -0.0, 0.0])
    return ScanResult(out, drone, drone_sum, others, np.flatnonzero(on_drone))


def avia_clutter_states(rng: np.random.Generator, n: int) -> NDArray[np.bool_]:
    """(n,) which Avia frames carry sporadic returns: a two-state chain, ~45% quiet, in runs."""
    out = np.empty(n, dtype=bool)
    state = bool(rng.random() < 0.55)
    for i in range(n):
        out[i] = state
        stay = 0.8 if state else 0.75
        if rng.random() >= stay:
            state = not state
    return out


def radar_frames(rng: np.random.Generator, n: int) -> list[F64]:
    """``n`` radar frames in the radar's own frame (z = boresight), metres.

    Mostly empty 1-D (0,) arrays (about 40%) in runs, the rest buffered repeats: each new content
    frame is followed by a copy of itself. Content: 2-5 static points ~4.3 m ahead, sometimes a
    far ghost and a few near points.
    """
    static = np.column_stack(
        [rng.uniform(-0.6, 0.6, 5), rng.uniform(-0.3, 0.3, 5), rng.uniform(4.2, 4.5, 5)]
    )
    ghost = np.array([rng.uniform(-150, 150), rng.uniform(-100, 100), rng.uniform(200, 400)])
    frames: list[F64] = []
    on = bool(rng.random() < 0.6)
    while len(frames) < n:
        run = int(rng.integers(6, 30)) if on else int(rng.integers(6, 20))
        if not on:
            frames.extend(np.zeros(0) for _ in range(run))
        else:
            k = int(rng.integers(2, 6))
            content = static[:k] + rng.normal(0, 0.01, (k, 3))
            if rng.random() < 0.5:
                content = np.vstack([content[:1], ghost, content[1:]])
            for j in range(run):
                if j % 2 == 0 and rng.random() < 0.5:
                    extra = int(rng.integers(0, 4))
                    near = np.column_stack(
                        [
                            rng.uniform(-1.6, 1.6, extra),
                            rng.uniform(-0.3, 0.3, extra),
                            rng.uniform(1.5, 3.0, extra),
                        ]
                    )
                    content = np.vstack([static[:k] + rng.normal(0, 0.01, (k, 3)), near])
                frames.append(content.copy())
        on = not on
    return frames[:n]


def encode_png(rgb: NDArray[np.uint8]) -> bytes:
    """Encode an (H, W, 3) uint8 image as a PNG (8-bit RGB, no filtering), deterministically."""
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].tobytes() for y in range(h))

    def chunk(tag: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data))
            + tag
            + data
            + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)
        )

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(raw, 6))
        + chunk(b"IEND", b"")
    )


def camera_image(rng: np.random.Generator, t_s: float, width: int = 64, height: int = 24) -> bytes:
    """A tiny stand-in for the two side-by-side fisheye images: sky over ground with sensor noise."""
    y = np.linspace(0.0, 1.0, height)[:, None, None]
    sky = np.array([135, 180, 230], dtype=np.float64)
    ground = np.array([90, 85, 70], dtype=np.float64)
    img = np.where(y < 0.55, sky, ground) * np.ones((1, width, 1))
    img += rng.normal(0.0, 4.0, img.shape) + 10.0 * np.sin(t_s)
    img[:, width // 2 - 1 : width // 2 + 1] = 0.0  # the seam between the two fisheyes
    return encode_png(np.clip(img, 0, 255).astype(np.uint8))
