"""Moving things of a randomised world: the drone's flight per scenario kind, and distractors.

Everything here is in the level frame (origin at the sensor, z against gravity, metres; times in
seconds since the sequence start). Places "in the Mid-360's band" or "in the Avia cone" are
drawn in the (tilted) sensor frame and turned into the level frame with ``R = World.rotation()``,
so that the flights are where the tilted sensors look.

Kinds (``World.kind``):
- ``fast_pass``: a straight pass at 8-23 m/s whose closest approach is 10-40 m out;
- ``foliage_hover``: a hover 1-3 m from a swaying tree canopy or bush, 4-20 m away;
- ``structure_hover``: a hover above a pole or antenna top, or beside or above a wall or roof edge;
- ``high_hover``: a hover 30-80 m up inside the Avia cone (often under one point per frame);
- ``mixed``: varied flight (field, cone, far, near, hovers) at 1-15 m/s;
- ``close``: a slow flight 2-10 m from the sensor.

Distractors, drawn independently of the kind: birds (small, erratic, short-lived, 5-20 m/s),
people walking, vehicles driving.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from cldet.simulate.flight import (
    DRONE_TYPES,
    Mover,
    Track,
    _time_grid,
    _visible,
    _Waypoint,
    drone_mover,
    fly_waypoints,
)
from cldet.simulate.scene import BIRD, BUILDING, CAR, PERSON, POLE, Scene
from cldet.simulate.terrain import VEGETATION, TerrainScene
from cldet.simulate.world import World

F64 = NDArray[np.float64]

_DT_S = 0.01  # trajectory sampling step, seconds (as flight.py)
_MIN_RANGE_M = 2.0  # the drone never comes nearer the sensor than this
_CLEARANCE_M = 0.6  # the drone stays this far above the surface below it
FIELD_ELEVATION_DEG = (-5.0, 48.0)  # where drones are placed for the Mid-360 (sensor frame)
CONE_ELEVATION_DEG = (60.0, 88.0)  # where drones are placed for the Avia (sensor frame)


def _sensor_dir(rot: F64, az: float, el_deg: float) -> F64:
    """Level-frame unit vector of the sensor-frame direction (azimuth rad, elevation deg)."""
    el = np.radians(el_deg)
    d = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return np.asarray(rot @ d, dtype=np.float64)


def _in_field(rng: np.random.Generator, rot: F64, r_lo: float, r_hi: float) -> F64:
    """A level-frame point in the Mid-360's band of the tilted sensor."""
    d = _sensor_dir(
        rot, float(rng.uniform(-np.pi, np.pi)), float(rng.uniform(*FIELD_ELEVATION_DEG))
    )
    return float(rng.uniform(r_lo, r_hi)) * d


def _in_cone(rng: np.random.Generator, rot: F64, z_lo: float, z_hi: float) -> F64:
    """A level-frame point inside the tilted Avia cone, ``z_lo..z_hi`` metres above the sensor."""
    for _ in range(100):
        d = _sensor_dir(
            rot, float(rng.uniform(-np.pi, np.pi)), float(rng.uniform(*CONE_ELEVATION_DEG))
        )
        if d[2] > 0.3:
            return float(rng.uniform(z_lo, z_hi)) / float(d[2]) * d
    return np.array([0.0, 0.0, float(rng.uniform(z_lo, z_hi))])


def _surface(scene: Scene, x: F64, y: F64) -> F64:
    """Height (m) of the surface people stand on (the roof deck, else the ground)."""
    if isinstance(scene, TerrainScene):
        return scene.walk_height(x, y)
    return scene.ground_height(x, y)


def _lift(scene: Scene, p: F64, clearance: float = 1.0) -> F64:
    """Raise ``p`` to at least ``clearance`` metres above whatever static thing is below it."""
    top = scene.top_height(float(p[0]), float(p[1]))
    return np.array([p[0], p[1], max(float(p[2]), top + clearance)])


def _free(
    rng: np.random.Generator,
    scene: Scene,
    draw: Callable[[], F64],
    clearance: float = 1.0,
    tries: int = 30,
) -> F64:
    """A point from ``draw()`` that lies in free air (not over or inside a static thing).

    After ``tries`` misses, the last draw lifted above whatever is below it.
    """
    p = draw()
    for _ in range(tries):
        if p[2] >= scene.top_height(float(p[0]), float(p[1])) + clearance:
            return p
        p = draw()
    return _lift(scene, p, clearance)


def fly(
    rng: np.random.Generator,
    start: F64,
    waypoints: list[_Waypoint],
    duration_s: float,
    scene: Scene,
    a_max: float,
) -> Track:
    """Fly the waypoints with acceleration bounded by ``a_max`` (m/s^2), hover wobble added.

    Sampled every 10 ms from -1 s to duration + 1 s; at least 2 m from the sensor and 0.6 m
    above the surface below.
    """
    times = _time_grid(duration_s)
    pos = fly_waypoints(start, waypoints, len(times), a_max, tau_s=0.5, start_speed=0.9)
    return _finish(rng, times, pos, scene)


def _finish(
    rng: np.random.Generator, times: F64, pos: F64, scene: Scene, yaw: F64 | None = None
) -> Track:
    """Add hover wobble, keep the path off the sensor and the surface, and give it headings."""
    amp = rng.uniform(0.01, 0.04, 3)
    freq = rng.uniform(0.2, 0.8, 3)
    phase = rng.uniform(0, 2 * np.pi, 3)
    pos = pos + amp * np.sin(2 * np.pi * freq * times[:, None] + phase)
    r = np.linalg.norm(pos, axis=1)
    pos = pos * np.maximum(1.0, _MIN_RANGE_M / np.maximum(r, 1e-6))[:, None]
    floor = _surface(scene, pos[:, 0], pos[:, 1])
    pos[:, 2] = np.maximum(pos[:, 2], floor + _CLEARANCE_M)
    if yaw is None:
        yaw = float(rng.uniform(-np.pi, np.pi)) + float(rng.normal(0.0, 0.15)) * times
    return Track(times, pos, np.asarray(yaw, dtype=np.float64))


def _miss_distance(a: F64, b: F64) -> float:
    """Closest distance (m) of the segment from ``a`` to ``b`` to the sensor at the origin."""
    ab = b - a
    f = float(np.clip(-(a @ ab) / max(float(ab @ ab), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(a + f * ab))


def _plan_fast_pass(rng: np.random.Generator, world: World, scene: Scene, d: float) -> Track:
    """A straight pass at 8-23 m/s, closest approach 10-40 m out, mostly in the Mid-360's band."""
    rot = world.rotation()
    speed = float(rng.uniform(8.0, 23.0))
    t_c = float(rng.uniform(0.3, 0.7)) * d
    best: tuple[F64, F64] | None = None
    for attempt in range(40):
        p_c = _in_field(rng, rot, 10.0, 40.0)
        if p_c[2] < float(_surface(scene, p_c[:1], p_c[1:2])[0]) + 2.0:
            continue
        los = np.array([p_c[0], p_c[1], 0.0])
        los /= max(float(np.linalg.norm(los)), 1e-6)
        ang = float(rng.uniform(-np.pi / 3.5, np.pi / 3.5))
        perp = np.array([-los[1], los[0], 0.0])
        u = np.cos(ang) * perp + np.sin(ang) * los
        u[2] = float(rng.normal(0.0, 0.08))
        u /= np.linalg.norm(u)
        if rng.random() < 0.5:
            u = -u
        best = (p_c, u)
        probes = [p_c + speed * dt * u for dt in (-1.0, 0.0, 1.0)]
        if sum(observable(scene, rot, q) for q in probes) >= 2 or attempt == 39:
            break
    if best is None:
        p_c = np.array([20.0, 0.0, 5.0])
        u = np.array([0.0, 1.0, 0.0])
    else:
        p_c, u = best
    times = _time_grid(d)
    pos = p_c + np.outer(times - t_c, u * speed)
    floor = _surface(scene, pos[:, 0], pos[:, 1])
    pos[:, 2] = np.maximum(pos[:, 2], floor + 2.0)  # terrain following
    yaw = np.full(len(times), float(np.arctan2(u[1], u[0])))
    return _finish(rng, times, pos, scene, yaw)


def _hover_waypoints(
    rng: np.random.Generator, scene: Scene, target: F64, d: float
) -> tuple[F64, list[_Waypoint]]:
    """Start and waypoints of a hover at ``target``: already there, or flying in early."""
    if rng.random() < 0.5:
        start = target.copy()
    else:
        az = float(rng.uniform(-np.pi, np.pi))
        off = float(rng.uniform(5.0, 12.0)) * np.array([np.cos(az), np.sin(az), 0.0])
        start = _lift(scene, target + off + np.array([0.0, 0.0, float(rng.uniform(0, 3))]), 1.0)
    wps = [_Waypoint(target, d + 2.0, float(rng.uniform(2.0, 5.0)))]
    if rng.random() < 0.3:  # leave near the end
        wps = [_Waypoint(target, float(rng.uniform(0.6, 0.8)) * d, wps[0].speed)]
        leave = _lift(scene, target + rng.uniform(-6, 6, 3) + np.array([0.0, 0.0, 3.0]), 1.0)
        wps.append(_Waypoint(leave, 0.0, float(rng.uniform(2.0, 6.0))))
    return start, wps


def observable(scene: Scene, rot: F64, p: F64, max_range_m: float = 85.0) -> bool:
    """Whether a LiDAR could see ``p`` (level frame): in range, in the sensors' fields of view
    (sensor-frame elevation above the Mid-360's lower edge) and not hidden by the static scene.
    """
    r = float(np.linalg.norm(p))
    if not 0.5 < r <= max_range_m:
        return False
    el = float(np.degrees(np.arcsin(float((rot.T @ p)[2]) / r)))
    return el >= FIELD_ELEVATION_DEG[0] - 1.0 and _visible(scene, p)


def _ok_target(scene: Scene, rot: F64, p: F64) -> bool:
    """In reach, above the surface and observable by the sensor."""
    r = float(np.linalg.norm(p))
    floor = float(_surface(scene, p[:1], p[1:2])[0])
    return 3.0 < r < 40.0 and p[2] > floor + 0.8 and observable(scene, rot, p)


def _observable_point(
    rng: np.random.Generator,
    scene: Scene,
    rot: F64,
    draw: Callable[[], F64],
    spread_m: float = 0.0,
    tries: int = 40,
) -> F64:
    """A draw of ``draw()`` that the sensor can observe, also ``spread_m`` away horizontally.

    After ``tries`` misses, the last draw.
    """
    offsets = np.array([[0.0, 0.0, 0.0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]])
    offsets[1:] *= spread_m
    p = draw()
    for _ in range(tries):
        if all(observable(scene, rot, p + o) for o in (offsets if spread_m else offsets[:1])):
            return p
        p = draw()
    return p


def _plan_foliage_hover(rng: np.random.Generator, world: World, scene: Scene, d: float) -> Track:
    """A hover 1-3 m from the surface of a swaying canopy or bush (beside or in front of it)."""
    rot = world.rotation()
    half = 0.5 * max(DRONE_TYPES[world.class_id].size_m)
    idx = [
        i
        for i in range(len(scene.sphere_kind))
        if scene.sphere_kind[i] in VEGETATION
        and 4.0 < np.hypot(*scene.sphere_centres[i, :2]) - scene.sphere_radii[i] < 20.0
    ]
    target: F64 | None = None
    for _ in range(60 if idx else 0):
        i = idx[int(rng.integers(len(idx)))]
        c, r = scene.sphere_centres[i], float(scene.sphere_radii[i])
        back = -np.array([c[0], c[1], 0.0]) / max(float(np.hypot(c[0], c[1])), 1e-6)
        ang = float(rng.uniform(-np.radians(110), np.radians(110)))
        u = np.array(
            [
                np.cos(ang) * back[0] - np.sin(ang) * back[1],
                np.sin(ang) * back[0] + np.cos(ang) * back[1],
                0.0,
            ]
        )
        gap = float(rng.uniform(1.0, 3.0))
        p = c + (r + gap + half) * u + np.array([0.0, 0.0, float(rng.uniform(-0.5, 0.5)) * r])
        if _ok_target(scene, rot, p):
            target = p
            break
    if target is None:  # nothing suitable: a hover in the open
        target = _observable_point(
            rng, scene, rot, lambda: _free(rng, scene, lambda: _in_field(rng, rot, 6.0, 15.0))
        )
    start, wps = _hover_waypoints(rng, scene, target, d)
    return fly(rng, start, wps, d, scene, float(rng.uniform(2.0, 5.0)))


def _structure_targets(rng: np.random.Generator, scene: Scene) -> list[F64]:
    """Hover spots at structures: above pole and mast tops, above or beside walls and roofs."""
    out: list[F64] = []
    for c, kind in zip(scene.cylinders, scene.cylinder_kind, strict=True):
        if kind != POLE or c[4] - c[3] < 1.5:
            continue
        top = np.array([c[0], c[1], c[4]])
        if rng.random() < 0.6:
            out.append(top + np.array([0.0, 0.0, float(rng.uniform(0.5, 2.0))]))
        else:
            a = float(rng.uniform(-np.pi, np.pi))
            side = float(rng.uniform(1.0, 2.0)) * np.array([np.cos(a), np.sin(a), 0.0])
            out.append(top + side - np.array([0.0, 0.0, float(rng.uniform(0.0, 2.0))]))
    for lo, hi, kind in zip(scene.box_lower, scene.box_upper, scene.box_kind, strict=True):
        if kind not in (BUILDING, CAR) or (lo[0] <= 0 <= hi[0] and lo[1] <= 0 <= hi[1]):
            continue
        near = np.clip(np.zeros(2), lo[:2], hi[:2])  # footprint point nearest the sensor
        outward = -near / max(float(np.linalg.norm(near)), 1e-6)
        if rng.random() < 0.5:  # above the roof edge
            p = np.array([*near, hi[2] + float(rng.uniform(0.8, 3.0))])
        else:  # beside the wall, facing the sensor
            z = float(rng.uniform(lo[2] + 1.5, max(hi[2] - 0.3, lo[2] + 1.6)))
            p = np.array([*(near + outward * float(rng.uniform(1.0, 2.5))), z])
        out.append(p)
    return out


def _plan_structure_hover(rng: np.random.Generator, world: World, scene: Scene, d: float) -> Track:
    """A hover above a pole or antenna top, or beside or above a wall or roof edge."""
    rot = world.rotation()
    spots = _structure_targets(rng, scene)
    target: F64 | None = None
    for _ in range(60 if spots else 0):
        p = spots[int(rng.integers(len(spots)))]
        if _ok_target(scene, rot, p) and np.linalg.norm(p) < 30.0:
            target = p
            break
    if target is None:
        target = _observable_point(
            rng, scene, rot, lambda: _free(rng, scene, lambda: _in_field(rng, rot, 6.0, 15.0))
        )
    start, wps = _hover_waypoints(rng, scene, target, d)
    return fly(rng, start, wps, d, scene, float(rng.uniform(2.0, 5.0)))


def _plan_high_hover(rng: np.random.Generator, world: World, scene: Scene, d: float) -> Track:
    """A hover 30-80 m up inside the Avia cone, drifting a metre or two."""
    rot = world.rotation()
    start = _observable_point(rng, scene, rot, lambda: _in_cone(rng, rot, 30.0, 80.0), 2.5)
    wps: list[_Waypoint] = []
    t = 0.0
    while t < d + 2:
        nxt = start + np.array([*rng.uniform(-2.0, 2.0, 2), float(rng.uniform(-1.0, 1.0))])
        speed = float(rng.uniform(0.2, 1.5))
        hold = float(rng.uniform(1.0, 4.0))
        wps.append(_Waypoint(nxt, hold, speed))
        t += 3.0 / speed + hold
    return fly(rng, start, wps, d, scene, float(rng.uniform(1.0, 3.0)))


def _plan_mixed(rng: np.random.Generator, world: World, scene: Scene, d: float) -> Track:
    """Varied flight: the Mid-360's band, the Avia cone, far away, near, hovers; 1-15 m/s."""
    rot = world.rotation()
    if rng.random() < 0.4:
        start = _observable_point(rng, scene, rot, lambda: _in_cone(rng, rot, 8.0, 60.0))
    else:
        start = _observable_point(
            rng, scene, rot, lambda: _free(rng, scene, lambda: _in_field(rng, rot, 5.0, 40.0))
        )
    wps: list[_Waypoint] = []
    t = 0.0
    last = start
    while t < d + 2:
        mode = rng.choice(["field", "cone", "far", "near", "hover"], p=[0.3, 0.3, 0.1, 0.1, 0.2])
        speed = float(rng.uniform(1.0, 15.0))
        hold = float(rng.uniform(0.0, 2.0))
        if mode == "field":
            nxt = _free(rng, scene, lambda: _in_field(rng, rot, 5.0, 50.0))
        elif mode == "cone":
            nxt = _in_cone(rng, rot, 8.0, 60.0)
        elif mode == "far":
            nxt = _free(rng, scene, lambda: _in_field(rng, rot, 50.0, 90.0))
        elif mode == "near":
            for _ in range(20):  # a leg that does not cut past the sensor
                nxt = _free(rng, scene, lambda: _in_field(rng, rot, 3.0, 8.0))
                if _miss_distance(last, nxt) > 2.5:
                    break
            speed = min(speed, 4.0)
        else:
            nxt = last + rng.normal(0.0, 0.5, 3)
            hold = float(rng.uniform(2.0, 5.0))
            speed = 1.0
        wps.append(_Waypoint(nxt, hold, speed))
        t += float(np.linalg.norm(nxt - last)) / speed + hold
        last = nxt
    return fly(rng, start, wps, d, scene, float(rng.uniform(2.0, 6.0)))


def _plan_close(rng: np.random.Generator, world: World, scene: Scene, d: float) -> Track:
    """A slow flight 2-10 m from the sensor (in the band and in the lower cone), 0.5-6 m/s."""
    rot = world.rotation()
    start = _observable_point(
        rng, scene, rot, lambda: _free(rng, scene, lambda: _in_field(rng, rot, 3.0, 9.0), 0.8)
    )
    wps: list[_Waypoint] = []
    t = 0.0
    last = start
    while t < d + 2:
        for _ in range(20):  # a leg that does not cut past the sensor
            if rng.random() < 0.2:
                nxt = _in_cone(rng, rot, 2.0, 7.0)
            else:
                nxt = _free(rng, scene, lambda: _in_field(rng, rot, 2.5, 10.0), 0.8)
            if _miss_distance(last, nxt) > 2.5:
                break
        speed = float(rng.uniform(0.5, 6.0))
        hold = float(rng.uniform(0.0, 3.0))
        wps.append(_Waypoint(nxt, hold, speed))
        t += float(np.linalg.norm(nxt - last)) / speed + hold
        last = nxt
    return fly(rng, start, wps, d, scene, float(rng.uniform(2.0, 5.0)))


_PLANNERS = {
    "fast_pass": _plan_fast_pass,
    "foliage_hover": _plan_foliage_hover,
    "structure_hover": _plan_structure_hover,
    "high_hover": _plan_high_hover,
    "mixed": _plan_mixed,
    "close": _plan_close,
}


def plan_world_drone(
    rng: np.random.Generator, world: World, scene: Scene, duration_s: float
) -> Mover:
    """The drone of ``world`` (a box of its type's size) flying its kind's path (level frame)."""
    if world.kind not in _PLANNERS:
        raise ValueError(f"unknown kind {world.kind!r}: expected one of {', '.join(_PLANNERS)}")
    track = _PLANNERS[world.kind](rng, world, scene, duration_s)
    return drone_mover(track, DRONE_TYPES[world.class_id])


def plan_world_bird(
    rng: np.random.Generator, world: World, scene: Scene, duration_s: float
) -> Mover:
    """A bird: a 5-15 cm sphere at 5-20 m/s on an erratic path, seen for 0.5-3 s."""
    rot = world.rotation()
    times = _time_grid(duration_s)
    n = len(times)
    if rng.random() < 0.2:
        p0 = _in_cone(rng, rot, 8.0, 40.0)
    else:
        p0 = _free(rng, scene, lambda: _in_field(rng, rot, 5.0, 40.0))
    speed = float(rng.uniform(5.0, 20.0))
    heading = float(rng.uniform(-np.pi, np.pi)) + np.cumsum(
        rng.normal(0.0, 1.5 * np.sqrt(_DT_S), n)
    )
    vz = np.clip(np.cumsum(rng.normal(0.0, 1.0 * np.sqrt(_DT_S), n)), -3.0, 3.0)
    s = speed * (1.0 + 0.2 * np.sin(2 * np.pi * float(rng.uniform(0.2, 1.0)) * times))
    s = np.clip(s, 5.0, 20.0)  # horizontal speed, m/s
    vel = np.column_stack([s * np.cos(heading), s * np.sin(heading), vz])
    t_mid = float(rng.uniform(0.0, duration_s))
    i_mid = int(np.argmin(np.abs(times - t_mid)))
    pos = np.cumsum(vel * _DT_S, axis=0)
    pos = pos - pos[i_mid] + p0
    pos[:, 2] += float(rng.uniform(0.03, 0.1)) * np.sin(
        2 * np.pi * float(rng.uniform(3, 8)) * times
    )
    floor = _surface(scene, pos[:, 0], pos[:, 1])
    pos[:, 2] = np.maximum(pos[:, 2], floor + 0.5)
    life = float(rng.uniform(0.5, 3.0))
    track = Track(times, pos, np.asarray(heading, dtype=np.float64))
    return Mover(
        "bird",
        BIRD,
        "sphere",
        (float(rng.uniform(0.05, 0.15)),),
        track,
        (t_mid - life / 2, t_mid + life / 2),
    )


def plan_world_person(
    rng: np.random.Generator, world: World, scene: Scene, duration_s: float
) -> Mover:
    """A person (cylinder 1.55-1.9 m) walking at 0.8-1.6 m/s on the surface (roof deck or ground)."""
    times = _time_grid(duration_s)
    n = len(times)
    deck = scene.deck if isinstance(scene, TerrainScene) else np.zeros(0)
    if deck.size and rng.random() < 0.5:
        xy0 = np.array(
            [rng.uniform(deck[0] + 0.5, deck[1] - 0.5), rng.uniform(deck[2] + 0.5, deck[3] - 0.5)]
        )
    else:
        r, a = float(rng.uniform(3.0, 30.0)), float(rng.uniform(-np.pi, np.pi))
        xy0 = np.array([r * np.cos(a), r * np.sin(a)])
    heading = float(rng.uniform(-np.pi, np.pi)) + np.cumsum(rng.normal(0, 0.02, n))
    speed = float(rng.uniform(0.8, 1.6))
    step = np.column_stack([np.cos(heading), np.sin(heading)]) * speed * _DT_S
    xy = xy0 + np.cumsum(step, axis=0) - step[0]
    if deck.size and deck[0] <= xy0[0] <= deck[1] and deck[2] <= xy0[1] <= deck[3]:
        xy[:, 0] = np.clip(xy[:, 0], deck[0] + 0.3, deck[1] - 0.3)  # stays on the roof
        xy[:, 1] = np.clip(xy[:, 1], deck[2] + 0.3, deck[3] - 0.3)
    z = _surface(scene, xy[:, 0], xy[:, 1])
    track = Track(times, np.column_stack([xy, z]), np.asarray(heading, dtype=np.float64))
    dims = (float(rng.uniform(0.18, 0.25)), float(rng.uniform(1.55, 1.9)))
    return Mover("person", PERSON, "cylinder", dims, track)


def plan_world_vehicle(
    rng: np.random.Generator, world: World, scene: Scene, duration_s: float
) -> Mover:
    """A car or van driving straight at 3-15 m/s along a road 6-40 m from the sensor."""
    times = _time_grid(duration_s)
    a = float(rng.uniform(-np.pi, np.pi))
    offset = float(rng.uniform(6.0, 40.0))
    closest = offset * np.array([np.cos(a), np.sin(a)])
    u = np.array([-np.sin(a), np.cos(a)]) * (1.0 if rng.random() < 0.5 else -1.0)
    speed = float(rng.uniform(3.0, 15.0))
    t_c = float(rng.uniform(-0.5, 1.5)) * duration_s
    xy = closest + np.outer(times - t_c, u * speed)
    half = (
        float(rng.uniform(2.1, 2.5)),
        float(rng.uniform(0.85, 0.95)),
        float(rng.uniform(0.7, 0.9)),
    )
    z = scene.ground_height(xy[:, 0], xy[:, 1]) + half[2]
    yaw = np.full(len(times), float(np.arctan2(u[1], u[0])))
    return Mover("vehicle", CAR, "box", half, Track(times, np.column_stack([xy, z]), yaw))


def plan_world_movers(
    rng: np.random.Generator, world: World, scene: Scene, duration_s: float
) -> list[Mover]:
    """The drone first, then the world's birds, people and vehicles."""
    movers = [plan_world_drone(rng, world, scene, duration_s)]
    movers += [plan_world_bird(rng, world, scene, duration_s) for _ in range(world.n_birds)]
    movers += [plan_world_person(rng, world, scene, duration_s) for _ in range(world.n_people)]
    movers += [plan_world_vehicle(rng, world, scene, duration_s) for _ in range(world.n_vehicles)]
    return movers
