"""Moving things: the drone's flight per scenario, a walking person and a crossing bird.

A flight is a list of waypoints (position, hold time, speed limit) followed by a smooth
velocity-tracking controller (bounded acceleration), sampled every 10 ms; hovers add a few
centimetres of wobble. Positions are in the Mid-360 frame (metres), times in seconds since
the start of the sequence (the writer converts to integer nanoseconds at the edge).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from cldet.simulate.scene import BIRD, DRONE, PERSON, Scene

F64 = NDArray[np.float64]

SCENARIOS: tuple[str, ...] = ("mixed", "close_pass", "hover", "avia_only", "person", "bird")

_DT_S = 0.01  # trajectory sampling step, seconds
_MARGIN_S = 1.0  # trajectories extend this far before and after the sequence
_MIN_RANGE_M = 2.0  # the drone never comes nearer the sensor than this


@dataclass(frozen=True)
class DroneType:
    """A drone class: name, body box size (length, width, height in metres) and the airframe's
    diffuse reflectivity at the LiDARs' 905 nm (0-1), which sets how far each LiDAR still
    detects it (``cldet.simulate.sensors.DetectionRange``)."""

    class_id: int
    name: str
    size_m: tuple[float, float, float]
    reflectivity: float


# Class ids follow the challenge site's listing order (Mavic 3, M30, M300, Phantom 4).
# Reflectivities are ASSUMPTIONS from each airframe's colour and finish: no 905 nm measurement of
# these airframes is published. Dark grey or black plastic is given 0.10, the dark reference of
# the Livox datasheets (black plastic can be lower, ~0.05); white paint 0.80, their bright
# reference. Gloss (the Phantom 4) also reflects part of the light away specularly: not modelled.
DRONE_TYPES: tuple[DroneType, ...] = (
    DroneType(0, "Mavic 3", (0.35, 0.29, 0.11), 0.10),  # dark grey plastic shell
    DroneType(1, "M30", (0.47, 0.58, 0.22), 0.10),  # dark grey / black body and arms
    DroneType(2, "M300", (0.81, 0.67, 0.43), 0.10),  # M300 RTK: dark grey body and arms
    # the common Phantom 4 (Pro, Advanced, RTK) is white gloss plastic; an "Obsidian" edition is
    # matte dark grey: which one MMAUD flew is not documented (white assumed)
    DroneType(3, "Phantom 4", (0.30, 0.30, 0.19), 0.80),
)


@dataclass(frozen=True)
class Track:
    """A sampled path: positions and headings on a regular time grid."""

    times_s: F64  # (T,) seconds since the sequence start, step _DT_S
    positions: (
        F64  # (T, 3) metres; the reference point (drone body centre, person feet, bird centre)
    )
    yaw: F64  # (T,) heading, radians

    def at(self, t_s: F64) -> F64:
        """(N, 3) positions at times ``t_s`` (N,), linearly interpolated (clamped at the ends)."""
        t = np.asarray(t_s, dtype=np.float64)
        return np.column_stack([np.interp(t, self.times_s, self.positions[:, k]) for k in range(3)])

    def yaw_at(self, t_s: F64) -> F64:
        """(N,) headings at times ``t_s`` (radians)."""
        return np.interp(np.asarray(t_s, dtype=np.float64), self.times_s, self.yaw)


@dataclass(frozen=True)
class Mover:
    """Something that moves through the scene and reflects LiDAR rays."""

    name: str  # "drone", "person", "bird"
    kind: int  # surface kind (scene.DRONE, PERSON, BIRD)
    shape: str  # "box" (half extents), "cylinder" (radius, height), "sphere" (radius)
    dims: tuple[float, ...]
    track: Track
    active_s: tuple[float, float] = field(default=(-np.inf, np.inf))  # visible only in this window
    # diffuse reflectivity at 905 nm (0-1): its returns follow the LiDAR's published detection
    # range at that reflectivity; None: the surface kind's fixed probability and range fade
    reflectivity: float | None = None

    def bounding_radius(self) -> float:
        """Radius (m) of a sphere around the reference point that contains the shape."""
        if self.shape == "box":
            return float(np.linalg.norm(self.dims))
        if self.shape == "cylinder":
            return float(np.hypot(self.dims[0], self.dims[1]))
        return float(self.dims[0])


@dataclass(frozen=True)
class _Waypoint:
    position: F64  # (3,) metres
    hold_s: float  # hover time on arrival
    speed: float  # speed limit on the way there, m/s


def _time_grid(duration_s: float) -> F64:
    """Sample times (seconds) from -1 s to duration + 1 s every 10 ms."""
    n = int(np.ceil((duration_s + 2 * _MARGIN_S) / _DT_S)) + 1
    return np.asarray(np.arange(n) * _DT_S - _MARGIN_S, dtype=np.float64)


def fly_waypoints(
    start: F64,
    waypoints: list[_Waypoint],
    n: int,
    a_max: float,
    tau_s: float,
    start_speed: float,
) -> F64:
    """(n, 3) positions every 10 ms flying the waypoints from ``start``.

    The velocity follows the command (towards the next waypoint at its speed, slowing to stop on
    it, holding ``hold_s`` there) with response time ``tau_s`` and acceleration at most
    ``a_max`` (m/s^2); it starts at ``start_speed`` times the first waypoint's speed.
    """
    pos = np.empty((n, 3))
    p = start.astype(np.float64).copy()
    first = waypoints[0]
    heading = first.position - p
    dist0 = float(np.linalg.norm(heading))
    v = heading / dist0 * first.speed * start_speed if dist0 > 1e-6 else np.zeros(3)
    k = 0
    held = 0.0
    for i in range(n):
        pos[i] = p
        if k < len(waypoints):
            w = waypoints[k]
            to = w.position - p
            dist = float(np.linalg.norm(to))
            if dist < 0.25:
                held += _DT_S
                v_cmd = np.zeros(3)
                if held >= w.hold_s:
                    k += 1
                    held = 0.0
            else:
                v_cmd = to / dist * min(w.speed, 0.8 * np.sqrt(2 * a_max * dist))
        else:
            v_cmd = np.zeros(3)
        acc = (v_cmd - v) / tau_s
        norm = float(np.linalg.norm(acc))
        if norm > a_max:
            acc *= a_max / norm
        v = v + acc * _DT_S
        p = p + v * _DT_S
    return pos


def _follow(
    rng: np.random.Generator,
    start: F64,
    waypoints: list[_Waypoint],
    duration_s: float,
    floor: Scene,
) -> Track:
    """Fly the waypoints with bounded acceleration; sample every 10 ms from -1 s to duration+1 s."""
    times = _time_grid(duration_s)
    a_max = float(rng.uniform(1.5, 3.0))
    pos = fly_waypoints(start, waypoints, len(times), a_max, tau_s=0.6, start_speed=0.8)
    # hover wobble: a few cm, slow
    amp = rng.uniform(0.01, 0.04, 3)
    freq = rng.uniform(0.2, 0.8, 3)
    phase = rng.uniform(0, 2 * np.pi, 3)
    pos = pos + amp * np.sin(2 * np.pi * freq * times[:, None] + phase)
    # keep at least 2 m from the sensor (a path between far points may cut close to it)
    r = np.linalg.norm(pos, axis=1)
    pos = pos * np.maximum(1.0, _MIN_RANGE_M / np.maximum(r, 1e-6))[:, None]
    # stay at least 0.6 m above the ground
    ground = floor.ground_height(pos[:, 0], pos[:, 1])
    pos[:, 2] = np.maximum(pos[:, 2], ground + 0.6)
    yaw0 = rng.uniform(-np.pi, np.pi)
    yaw_rate = rng.normal(0.0, 0.15)
    return Track(times, pos, np.asarray(yaw0 + yaw_rate * times, dtype=np.float64))


def _spherical(r: float, az: float, el_deg: float) -> F64:
    el = np.radians(el_deg)
    return np.array([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)])


def _in_cone(rng: np.random.Generator, z_lo: float, z_hi: float) -> F64:
    """A point well inside the Avia cone (elevation >= ~62 deg)."""
    z = float(rng.uniform(z_lo, z_hi))
    rh = float(rng.uniform(0.0, 0.5 * z))
    az = float(rng.uniform(-np.pi, np.pi))
    return np.array([rh * np.cos(az), rh * np.sin(az), z])


def _in_field(
    rng: np.random.Generator, r_lo: float, r_hi: float, el_lo: float, el_hi: float
) -> F64:
    """A point in the Mid-360's field of view (elevation in degrees)."""
    return _spherical(
        float(rng.uniform(r_lo, r_hi)),
        float(rng.uniform(-np.pi, np.pi)),
        float(rng.uniform(el_lo, el_hi)),
    )


def _lift(scene: Scene, p: F64, clearance: float = 1.0) -> F64:
    """Raise ``p`` to at least ``clearance`` metres above whatever static thing is below it."""
    top = scene.top_height(float(p[0]), float(p[1]))
    return np.array([p[0], p[1], max(p[2], top + clearance)])


def _visible(scene: Scene, p: F64) -> bool:
    """Whether the static scene leaves a clear line of sight from the sensor to ``p`` (+-0.2 m)."""
    offsets = np.array([[0, 0, 0], [0.2, 0, 0], [-0.2, 0, 0], [0, 0.2, 0], [0, 0, 0.2]])
    targets = p[None, :] + offsets
    r = np.linalg.norm(targets, axis=1)
    # vegetation flutter is irrelevant here: a fixed generator keeps the caller's stream untouched
    dist, _ = scene.cast(targets / r[:, None], 0.0, np.random.default_rng(0))
    return bool(np.count_nonzero(dist > r - 0.3) >= 4)


def plan_drone(
    rng: np.random.Generator, scenario: str, duration_s: float, scene: Scene
) -> tuple[Track, F64 | None]:
    """Plan the drone's body-centre track for a scenario.

    Returns:
        The track and, for "hover", the (3,) top of the static object hovered over (else None).
    """
    d = duration_s
    wps: list[_Waypoint] = []
    anchor: F64 | None = None
    if scenario == "close_pass":
        speed = float(rng.uniform(1.5, 5.0))
        az = float(rng.uniform(-np.pi, np.pi))
        miss = float(rng.uniform(2.0, 4.0))
        side = np.array([np.cos(az), np.sin(az), 0.0])
        along = np.array([-np.sin(az), np.cos(az), 0.0])
        lead = max(speed * 0.45 * d, 3.0)
        z = float(rng.uniform(-0.3, 2.5))
        start = _lift(scene, side * miss - along * lead + np.array([0, 0, z + rng.uniform(0, 2)]))
        mid = _lift(scene, side * miss + np.array([0, 0, z]))
        end = _lift(scene, side * miss + along * (lead + speed * d) + np.array([0, 0, z + 1.0]))
        wps = [_Waypoint(mid, 0.0, speed), _Waypoint(end, 0.0, speed)]
    elif scenario == "hover":
        anchors = scene.anchors()
        lift = float(rng.uniform(0.8, 1.2))
        near = [
            a
            for a in anchors
            if np.hypot(a[0], a[1]) < 15.0 and _visible(scene, a + np.array([0.0, 0.0, lift]))
        ]
        if near:
            anchor = near[int(rng.integers(len(near)))]
        else:
            anchor = _lift(scene, _in_field(rng, 6, 12, 0, 0), 0.0)
        target = anchor + np.array([0.0, 0.0, lift])
        az = float(rng.uniform(-np.pi, np.pi))
        start = _lift(scene, target + rng.uniform(2, 4) * np.array([np.cos(az), np.sin(az), 0.1]))
        leave = _lift(
            scene, target + np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(2, 6)])
        )
        wps = [_Waypoint(target, 0.7 * d, float(rng.uniform(1.0, 2.5))), _Waypoint(leave, 0.0, 2.0)]
    elif scenario == "avia_only":
        start = _in_cone(rng, 12, 50)
        t = 0.0
        last = start
        while t < d + 2:
            nxt = last + rng.normal(0.0, 3.0, 3)
            if not 10.0 < nxt[2] < 60.0 or np.hypot(nxt[0], nxt[1]) > 0.5 * nxt[2]:
                nxt = _in_cone(rng, 12, 60)
            speed = float(rng.uniform(0.3, 2.5))
            hold = float(rng.uniform(0.5, 4.0))
            wps.append(_Waypoint(nxt, hold, speed))
            t += float(np.linalg.norm(nxt - last)) / speed + hold
            last = nxt
    elif scenario == "person":
        start = _lift(scene, _in_field(rng, 5, 12, 0, 15), 1.5)
        for _ in range(20):  # start where the Mid-360 can see the drone
            if _visible(scene, start):
                break
            start = _lift(scene, _in_field(rng, 5, 12, 0, 15), 1.5)
        t = 0.0
        last = start
        while t < d + 2:
            nxt = _lift(scene, last + np.array([*rng.uniform(-5, 5, 2), rng.uniform(-1, 1.5)]), 1.5)
            if np.hypot(nxt[0], nxt[1]) < 3.0:
                continue
            speed = float(rng.uniform(0.5, 3.0))
            hold = float(rng.uniform(0.0, 2.0))
            wps.append(_Waypoint(nxt, hold, speed))
            t += float(np.linalg.norm(nxt - last)) / speed + hold
            last = nxt
    else:  # "mixed" and "bird": varied flight through the Mid-360 field, the cone, far away
        if rng.random() < 0.4:  # the real drones spend most of their time high, in the Avia cone
            start = _in_cone(rng, 8, 45)
        else:
            start = _lift(scene, _in_field(rng, 5, 40, 0, 40), 1.0)
        t = 0.0
        last = start
        while t < d + 2:
            mode = rng.choice(
                ["field", "cone", "far", "near", "hover"], p=[0.25, 0.4, 0.1, 0.1, 0.15]
            )
            speed = float(rng.uniform(1.0, 8.0))
            hold = float(rng.uniform(0.0, 2.0))
            if mode == "field":
                nxt = _lift(scene, _in_field(rng, 5, 50, 0, 40))
            elif mode == "cone":
                nxt = _in_cone(rng, 8, 45)
            elif mode == "far":
                nxt = _lift(scene, _in_field(rng, 50, 95, 5, 40))
            elif mode == "near":
                nxt = _lift(scene, _in_field(rng, 2.5, 6, 0, 35))
                speed = min(speed, 3.0)
            else:
                nxt = last + rng.normal(0.0, 0.5, 3)
                hold = float(rng.uniform(2.0, 5.0))
                speed = 1.0
            wps.append(_Waypoint(nxt, hold, speed))
            t += float(np.linalg.norm(nxt - last)) / speed + hold
            last = nxt
    if not wps:
        wps = [_Waypoint(start, d, 1.0)]
    return _follow(rng, start, wps, duration_s, scene), anchor


def drone_mover(track: Track, drone: DroneType) -> Mover:
    """The drone as a box (its class's body size and reflectivity) following ``track``."""
    half = tuple(0.5 * s for s in drone.size_m)
    return Mover("drone", DRONE, "box", half, track, reflectivity=drone.reflectivity)


def plan_person(
    rng: np.random.Generator, duration_s: float, scene: Scene, near: F64 | None = None
) -> Mover:
    """A person (1.6-1.8 m cylinder) walking at 1-1.5 m/s on the ground, near ``near`` if given."""
    if near is not None:
        off = rng.uniform(3, 8) * np.array([np.cos(a := rng.uniform(-np.pi, np.pi)), np.sin(a)])
        xy0 = near[:2] + off
    else:
        r, a = rng.uniform(3, 20), rng.uniform(-np.pi, np.pi)
        xy0 = np.array([r * np.cos(a), r * np.sin(a)])
    times = _time_grid(duration_s)
    n = len(times)
    heading = rng.uniform(-np.pi, np.pi) + np.cumsum(rng.normal(0, 0.02, n))
    speed = rng.uniform(1.0, 1.5)
    step = np.column_stack([np.cos(heading), np.sin(heading)]) * speed * _DT_S
    xy = xy0 + np.cumsum(step, axis=0) - step[0]
    z = scene.ground_height(xy[:, 0], xy[:, 1])
    track = Track(times, np.column_stack([xy, z]), heading)
    return Mover(
        "person",
        PERSON,
        "cylinder",
        (float(rng.uniform(0.18, 0.25)), float(rng.uniform(1.6, 1.8))),
        track,
    )


def plan_bird(rng: np.random.Generator, duration_s: float, scene: Scene) -> Mover:
    """A bird (sphere ~0.1 m) crossing at 8-15 m/s, visible for a few seconds."""
    t_c = float(rng.uniform(0.2, 0.8) * duration_s)
    speed = float(rng.uniform(8, 15))
    a = float(rng.uniform(-np.pi, np.pi))
    closest_h = float(rng.uniform(4, 25))
    height = float(rng.uniform(1.5, 20.0))
    p_c = np.array([closest_h * np.cos(a), closest_h * np.sin(a), scene.ground_base_m + height])
    direction = np.array([-np.sin(a), np.cos(a), rng.normal(0, 0.05)])
    direction /= np.linalg.norm(direction)
    times = _time_grid(duration_s)
    n = len(times)
    pos = p_c + np.outer(times - t_c, direction * speed)
    pos[:, 2] += 0.1 * np.sin(2 * np.pi * 3.0 * times)  # wing beat bob
    half_window = float(rng.uniform(1.0, 2.5))
    track = Track(times, pos, np.full(n, np.arctan2(direction[1], direction[0])))
    return Mover(
        "bird",
        BIRD,
        "sphere",
        (float(rng.uniform(0.08, 0.14)),),
        track,
        (t_c - half_window, t_c + half_window),
    )
