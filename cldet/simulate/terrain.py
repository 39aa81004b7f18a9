"""Sites of the randomised worlds: sloped, uneven ground and the static things standing on it.

Coordinates are in the level frame (origin at the sensor, z against gravity, metres). The ground
is a tilted plane plus a few long undulations, with the surface right below the sensor (the
ground, or a roof deck on the rooftop site) at ``-mount_height_m``. Sites are plain
:class:`~cldet.simulate.scene.Scene` primitives (axis-aligned boxes, vertical cylinders, swaying
spheres), so the existing ray caster and sensor models apply unchanged; unlike the car park of
``build_scene`` they may stand close to the sensor and reach any elevation, also overhead.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from cldet.simulate.scene import (
    BUILDING,
    BUSH,
    CANOPY,
    CAR,
    POLE,
    TRUNK,
    Scene,
    build_scene,
)
from cldet.simulate.world import World

F64 = NDArray[np.float64]

VEGETATION = (CANOPY, BUSH)


@dataclass(frozen=True)
class TerrainScene(Scene):
    """A :class:`Scene` on a sloped ground, optionally with a roof deck under the sensor."""

    slope: F64  # (2,) dz/dx, dz/dy of the ground plane (level frame), metres per metre
    deck: F64  # (5,) xmin, xmax, ymin, ymax, z_top (m) of the roof under the sensor; (0,) if none

    def ground_height(self, x: F64, y: F64) -> F64:
        """Ground height z (metres) at x, y (metres): the plane plus the undulations."""
        return super().ground_height(x, y) + self.slope[0] * x + self.slope[1] * y

    def ground_up_component(self, dirs: F64) -> F64:
        """(N,) component of ``dirs`` (N, 3) along the ground plane's upward normal."""
        n = np.array([-self.slope[0], -self.slope[1], 1.0])
        return np.asarray(dirs @ (n / np.linalg.norm(n)), dtype=np.float64)

    def walk_height(self, x: F64, y: F64) -> F64:
        """Height (m) of the surface people and vehicles stand on: the roof deck, else the ground."""
        h = self.ground_height(x, y)
        if self.deck.size:
            x0, x1, y0, y1, top = self.deck
            inside = (x0 <= x) & (x <= x1) & (y0 <= y) & (y <= y1)
            h = np.where(inside, top, h)
        return np.asarray(h, dtype=np.float64)

    def max_elevation_rad(self) -> float:
        """Bound on the elevation of any static surface, the uphill ground included (radians)."""
        grade = float(np.hypot(self.slope[0], self.slope[1]))
        amp = float(np.abs(self.ground_waves[:, 2]).sum()) if len(self.ground_waves) else 0.0
        ground = float(np.arctan(grade) + np.arctan(2.0 * amp / 2.0) + 0.02)
        return float(min(max(super().max_elevation_rad(), ground), np.pi / 2))

    def _hit_ground(self, dirs: F64) -> F64:
        """Distance along each ray to the sloped, uneven ground (inf where it is not hit)."""
        n = dirs.shape[0]
        out = np.full(n, np.inf)
        sx, sy = float(self.slope[0]), float(self.slope[1])
        den_all = dirs[:, 2] - sx * dirs[:, 0] - sy * dirs[:, 1]  # closing rate on the plane
        down = den_all < -0.005
        d = dirs[down]
        den = den_all[down]
        base = self.ground_base_m
        t = base / den  # the plane alone
        for _ in range(8):  # fixed-point iteration on the undulations
            x, y = t * d[:, 0], t * d[:, 1]
            t = (Scene.ground_height(self, x, y)) / den
        resid = np.abs(t * d[:, 2] - self.ground_height(t * d[:, 0], t * d[:, 1]))
        ok = (resid < 0.02) & (t > 0) & (t < 200.0)
        out[np.flatnonzero(down)[ok]] = t[ok]
        return out


class _Site:
    """Collects primitives for one site; heights are placed on the ground function."""

    def __init__(self, ground: Callable[[float, float], float], rng: np.random.Generator) -> None:
        self.ground = ground
        self.rng = rng
        self.lows: list[list[float]] = []
        self.highs: list[list[float]] = []
        self.box_kinds: list[int] = []
        self.cyls: list[list[float]] = []
        self.cyl_kinds: list[int] = []
        self.centres: list[list[float]] = []
        self.radii: list[float] = []
        self.sphere_kinds: list[int] = []
        self.sways: list[list[float]] = []

    def footing(self, x0: float, x1: float, y0: float, y1: float) -> float:
        """Lowest ground height under a footprint (its corners and centre), minus 0.3 m."""
        xs = (x0, x1, x0, x1, 0.5 * (x0 + x1))
        ys = (y0, y0, y1, y1, 0.5 * (y0 + y1))
        return min(self.ground(x, y) for x, y in zip(xs, ys, strict=True)) - 0.3

    def box(
        self, lo: tuple[float, float, float], hi: tuple[float, float, float], kind: int
    ) -> None:
        """An axis-aligned box from its corners (metres). Boxes holding the sensor are skipped."""
        if all(lo[k] < 0.0 < hi[k] for k in range(3)):
            return
        self.lows.append(list(lo))
        self.highs.append(list(hi))
        self.box_kinds.append(kind)

    def block(self, cx: float, cy: float, sx: float, sy: float, height: float, kind: int) -> None:
        """A box standing on the ground: centre x, y, sizes, height above the ground (metres)."""
        x0, x1, y0, y1 = cx - sx / 2, cx + sx / 2, cy - sy / 2, cy + sy / 2
        z0 = self.footing(x0, x1, y0, y1)
        top = self.ground(cx, cy) + height
        self.box((x0, y0, z0), (x1, y1, top), kind)

    def cylinder(
        self, cx: float, cy: float, radius: float, z0: float, z1: float, kind: int
    ) -> None:
        """A vertical cylinder (metres)."""
        if np.hypot(cx, cy) <= radius + 0.1:
            return
        self.cyls.append([cx, cy, radius, z0, z1])
        self.cyl_kinds.append(kind)

    def sphere(
        self, centre: tuple[float, float, float], radius: float, kind: int, sway: float
    ) -> None:
        """A sphere (foliage sways by up to ``sway`` metres; other kinds pass 0)."""
        if float(np.linalg.norm(centre)) <= radius + sway + 0.4:
            return
        rng = self.rng
        self.centres.append(list(centre))
        self.radii.append(radius)
        self.sphere_kinds.append(kind)
        self.sways.append(
            [
                sway * float(rng.uniform(0.3, 1.0)),
                sway * float(rng.uniform(0.3, 1.0)),
                float(rng.uniform(0.2, 1.2)),
                float(rng.uniform(0, 2 * np.pi)),
                float(rng.uniform(0, 2 * np.pi)),
            ]
        )

    def pole(self, cx: float, cy: float, height: float, radius: float = 0.1) -> None:
        """A lamp post or mast standing on the ground."""
        z0 = self.ground(cx, cy) - 0.1
        self.cylinder(cx, cy, radius, z0, z0 + 0.1 + height, POLE)

    def tree(self, cx: float, cy: float, wind: float, z_foot: float | None = None) -> None:
        """A trunk and one to three canopy spheres around its top."""
        rng = self.rng
        z0 = self.ground(cx, cy) - 0.1 if z_foot is None else z_foot
        trunk = float(rng.uniform(2.0, 8.0))
        radius = float(rng.uniform(1.2, 3.5))
        self.cylinder(cx, cy, float(rng.uniform(0.1, 0.35)), z0, z0 + trunk, TRUNK)
        for j in range(int(rng.integers(1, 4))):
            off = rng.normal(0.0, 0.5 * radius, 3) if j else np.zeros(3)
            c = (cx + off[0], cy + off[1], z0 + trunk + 0.6 * radius + 0.5 * abs(off[2]))
            self.sphere(c, radius * (1.0 if j == 0 else float(rng.uniform(0.5, 0.9))), CANOPY, wind)

    def bush(self, cx: float, cy: float, wind: float, z_foot: float | None = None) -> None:
        """A bush resting on the ground (or on ``z_foot``)."""
        radius = float(self.rng.uniform(0.4, 1.3))
        z0 = self.ground(cx, cy) if z_foot is None else z_foot
        self.sphere((cx, cy, z0 + 0.5 * radius), radius, BUSH, 0.5 * wind)

    def scene(self, bare: TerrainScene) -> TerrainScene:
        """The finished site on ``bare``'s ground."""
        return TerrainScene(
            ground_base_m=bare.ground_base_m,
            ground_waves=bare.ground_waves,
            box_lower=np.array(self.lows, dtype=np.float64).reshape(-1, 3),
            box_upper=np.array(self.highs, dtype=np.float64).reshape(-1, 3),
            box_kind=np.array(self.box_kinds, dtype=np.intp),
            cylinders=np.array(self.cyls, dtype=np.float64).reshape(-1, 5),
            cylinder_kind=np.array(self.cyl_kinds, dtype=np.intp),
            sphere_centres=np.array(self.centres, dtype=np.float64).reshape(-1, 3),
            sphere_radii=np.array(self.radii, dtype=np.float64),
            sphere_kind=np.array(self.sphere_kinds, dtype=np.intp),
            sway=np.array(self.sways, dtype=np.float64).reshape(-1, 5),
            slope=bare.slope,
            deck=bare.deck,
        )


def _polar(rng: np.random.Generator, r_lo: float, r_hi: float) -> tuple[float, float]:
    r = float(rng.uniform(r_lo, r_hi))
    a = float(rng.uniform(-np.pi, np.pi))
    return r * np.cos(a), r * np.sin(a)


def bare_ground(world: World, rng: np.random.Generator, floor_drop_m: float = 0.0) -> TerrainScene:
    """The ground alone: slope and undulations, ``floor_drop_m`` below the surface under the sensor.

    The surface right below the sensor is at ``-world.mount_height_m``; the ground itself lies
    ``floor_drop_m`` lower (a building's height on the rooftop site).
    """
    n_waves = 3
    waves = np.column_stack(
        [
            rng.uniform(-1, 1, n_waves) * 2 * np.pi / rng.uniform(6, 40, n_waves),
            rng.uniform(-1, 1, n_waves) * 2 * np.pi / rng.uniform(6, 40, n_waves),
            world.roughness_m * rng.uniform(0.15, 0.5, n_waves),
            rng.uniform(0, 2 * np.pi, n_waves),
        ]
    )
    grade = np.tan(np.radians(world.slope_deg))
    az = np.radians(world.slope_azimuth_deg)
    slope = np.array([grade * np.cos(az), grade * np.sin(az)])
    at_origin = float(np.sum(waves[:, 2] * np.sin(waves[:, 3])))  # undulation at x = y = 0
    base = -world.mount_height_m - floor_drop_m - at_origin
    empty = np.zeros((0, 3))
    return TerrainScene(
        base,
        waves,
        empty,
        empty,
        np.zeros(0, dtype=np.intp),
        np.zeros((0, 5)),
        np.zeros(0, dtype=np.intp),
        empty,
        np.zeros(0),
        np.zeros(0, dtype=np.intp),
        np.zeros((0, 5)),
        slope=slope,
        deck=np.zeros(0),
    )


def _ground_fn(scene: TerrainScene) -> Callable[[float, float], float]:
    def ground(x: float, y: float) -> float:
        return float(scene.ground_height(np.asarray(x), np.asarray(y)))

    return ground


def _car_park(world: World, rng: np.random.Generator, site: _Site, bare: TerrainScene) -> None:
    """Today's car park (``build_scene``), re-seated on this world's ground."""
    old = build_scene(rng)

    def lift(x: float, y: float) -> float:
        # each object keeps its height above the old ground and follows the new one
        return site.ground(x, y) - float(old.ground_height(np.asarray(x), np.asarray(y)))

    for lo, hi, kind in zip(old.box_lower, old.box_upper, old.box_kind, strict=True):
        cx, cy = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])
        dz = lift(cx, cy)
        z0 = min(lo[2] + dz, site.footing(lo[0], hi[0], lo[1], hi[1]))
        site.box((lo[0], lo[1], z0), (hi[0], hi[1], hi[2] + dz), int(kind))
    for c, kind in zip(old.cylinders, old.cylinder_kind, strict=True):
        dz = lift(c[0], c[1])
        site.cylinder(c[0], c[1], c[2], c[3] + dz, c[4] + dz, int(kind))
    for c, r, kind in zip(old.sphere_centres, old.sphere_radii, old.sphere_kind, strict=True):
        dz = lift(c[0], c[1])
        site.sphere((c[0], c[1], c[2] + dz), float(r), int(kind), world.wind_m)


def _open_field(world: World, rng: np.random.Generator, site: _Site, bare: TerrainScene) -> None:
    """Mostly open ground: bushes, a few lone trees, fences and utility poles far apart."""
    for _ in range(int(rng.integers(3, 12))):
        site.bush(*_polar(rng, 5, 50), world.wind_m)
    for _ in range(int(rng.integers(1, 5))):
        site.tree(*_polar(rng, 12, 60), world.wind_m)
    for _ in range(int(rng.integers(0, 3))):
        cx, cy = _polar(rng, 8, 40)
        length = float(rng.uniform(10, 40))
        sx, sy = (length, 0.1) if rng.random() < 0.5 else (0.1, length)
        site.block(cx, cy, sx, sy, float(rng.uniform(1.0, 1.5)), BUILDING)
    for _ in range(int(rng.integers(0, 3))):
        site.pole(*_polar(rng, 8, 40), float(rng.uniform(6, 10)), float(rng.uniform(0.1, 0.15)))


def _forest_edge(world: World, rng: np.random.Generator, site: _Site, bare: TerrainScene) -> None:
    """A tree line a few metres away, branches overhanging the sensor, undergrowth at the edge."""
    theta = float(rng.uniform(-np.pi, np.pi))
    toward = np.array([np.cos(theta), np.sin(theta)])
    lateral = np.array([-np.sin(theta), np.cos(theta)])
    edge = float(rng.uniform(3.0, 10.0))
    for _ in range(int(rng.integers(25, 45))):
        p = toward * (edge + float(rng.uniform(0, 40))) + lateral * float(rng.uniform(-50, 50))
        site.tree(float(p[0]), float(p[1]), world.wind_m)
    for _ in range(int(rng.integers(5, 15))):
        p = toward * (edge + float(rng.uniform(-1, 2))) + lateral * float(rng.uniform(-25, 25))
        site.bush(float(p[0]), float(p[1]), world.wind_m)
    for _ in range(int(rng.integers(1, 4))):  # branches reaching over the sensor
        p = toward * float(rng.uniform(0.0, edge))
        radius = float(rng.uniform(0.6, 2.0))
        z = float(rng.uniform(3.0, 7.0)) + radius
        site.sphere((float(p[0]), float(p[1]), z), radius, CANOPY, world.wind_m)
    for _ in range(int(rng.integers(0, 5))):  # the open side
        p = -toward * float(rng.uniform(5, 40)) + lateral * float(rng.uniform(-30, 30))
        site.bush(float(p[0]), float(p[1]), world.wind_m)


def _urban_canyon(world: World, rng: np.random.Generator, site: _Site, bare: TerrainScene) -> None:
    """A street between tall facades a few metres away on two sides, with posts, cars, trees."""
    along_x = bool(rng.random() < 0.5)
    left, right = float(rng.uniform(2.0, 8.0)), float(rng.uniform(2.0, 8.0))

    def xy(u: float, v: float) -> tuple[float, float]:
        """Street coordinates (u along, v across) to level x, y."""
        return (u, v) if along_x else (v, u)

    def sizes(su: float, sv: float) -> tuple[float, float]:
        return (su, sv) if along_x else (sv, su)

    for side, face in ((1.0, left), (-1.0, right)):
        u = -float(rng.uniform(100, 140))
        while u < 130:
            length = float(rng.uniform(10, 50))
            depth = float(rng.uniform(10, 20))
            height = float(rng.uniform(8, 40))
            cu, cv = u + length / 2, side * (face + depth / 2)
            site.block(*xy(cu, cv), *sizes(length, depth), height, BUILDING)
            if rng.random() < 0.3:  # balconies on the facade
                for _ in range(int(rng.integers(1, 4))):
                    bu = u + float(rng.uniform(1, length - 3))
                    bz = site.ground(*xy(bu, side * face)) + float(rng.uniform(3, min(height, 20)))
                    v0, v1 = sorted((side * face, side * (face - 1.2)))
                    x0, y0 = xy(bu, v0)
                    x1, y1 = xy(bu + 2.5, v1)
                    site.box(
                        (min(x0, x1), min(y0, y1), bz),
                        (max(x0, x1), max(y0, y1), bz + 1.0),
                        BUILDING,
                    )
            u += length + (float(rng.uniform(4, 12)) if rng.random() < 0.3 else 0.0)
        # lamp posts along the curb, lamp heads reaching over the street
        u = -60.0 + float(rng.uniform(0, 25))
        while u < 60:
            cu, cv = u, side * (face - 0.6)
            h = float(rng.uniform(5, 8))
            site.pole(*xy(cu, cv), h, 0.08)
            top = site.ground(*xy(cu, cv)) + h
            v0, v1 = sorted((cv, cv - side * 1.2))
            x0, y0 = xy(cu - 0.2, v0)
            x1, y1 = xy(cu + 0.2, v1)
            site.box((min(x0, x1), min(y0, y1), top - 0.3), (max(x0, x1), max(y0, y1), top), POLE)
            u += float(rng.uniform(18, 30))
        for _ in range(int(rng.integers(0, 5))):  # parked cars at the curb
            cu, cv = float(rng.uniform(-50, 50)), side * (face - 1.1)
            if abs(cu) < 3.0:
                continue
            site.block(*xy(cu, cv), *sizes(4.6, 1.85), 1.5, CAR)
        if rng.random() < 0.5:  # street trees
            for _ in range(int(rng.integers(1, 4))):
                cu = float(rng.uniform(-40, 40))
                site.tree(*xy(cu, side * max(face - 1.5, 0.8)), world.wind_m)


def _rooftop(world: World, rng: np.random.Generator, site: _Site, bare: TerrainScene) -> None:
    """A flat roof under the sensor with railings, antennas and plant; the street far below."""
    deck = bare.deck
    x0, x1, y0, y1, top = (float(v) for v in deck)
    site.box((x0, y0, site.footing(x0, x1, y0, y1)), (x1, y1, top), BUILDING)
    edges = [((x0, y0), (x1, y0)), ((x1, y0), (x1, y1)), ((x1, y1), (x0, y1)), ((x0, y1), (x0, y0))]
    if rng.random() < 0.5:  # a solid parapet
        h = float(rng.uniform(0.3, 1.0))
        for (ax, ay), (bx, by) in edges:
            lo = (min(ax, bx) - 0.1, min(ay, by) - 0.1, top)
            hi = (max(ax, bx) + 0.1, max(ay, by) + 0.1, top + h)
            site.box(lo, hi, BUILDING)
    else:  # railings: a top rail and posts
        h = float(rng.uniform(1.0, 1.15))
        perimeter = 2 * ((x1 - x0) + (y1 - y0))
        step = max(2.0, perimeter / 30.0)
        for (ax, ay), (bx, by) in edges:
            lo = (min(ax, bx) - 0.03, min(ay, by) - 0.03, top + h - 0.05)
            hi = (max(ax, bx) + 0.03, max(ay, by) + 0.03, top + h)
            site.box(lo, hi, BUILDING)
            length = float(np.hypot(bx - ax, by - ay))
            for s in np.arange(0.0, length, step):
                f = s / length
                site.cylinder(ax + f * (bx - ax), ay + f * (by - ay), 0.03, top, top + h, POLE)
    for _ in range(int(rng.integers(1, 6))):  # antennas and masts, some with a dish
        for _ in range(20):
            ax, ay = _polar(rng, 1.5, 15.0)
            if x0 + 0.5 < ax < x1 - 0.5 and y0 + 0.5 < ay < y1 - 0.5:
                break
        else:
            continue
        h = float(rng.uniform(1.5, 8.0))
        site.cylinder(ax, ay, float(rng.uniform(0.02, 0.08)), top, top + h, POLE)
        if rng.random() < 0.4:
            site.sphere((ax, ay, top + float(rng.uniform(0.5, 0.9)) * h), 0.4, BUILDING, 0.0)
    for _ in range(int(rng.integers(1, 5))):  # air-conditioning plant
        cx, cy = _polar(rng, 2.5, 14.0)
        sx, sy = float(rng.uniform(1, 3)), float(rng.uniform(1, 3))
        if x0 < cx - sx / 2 and cx + sx / 2 < x1 and y0 < cy - sy / 2 and cy + sy / 2 < y1:
            site.box(
                (cx - sx / 2, cy - sy / 2, top),
                (cx + sx / 2, cy + sy / 2, top + float(rng.uniform(1, 2.5))),
                BUILDING,
            )
    for _ in range(int(rng.integers(5, 12))):  # the neighbours, on the ground below
        cx, cy = _polar(rng, 25, 120)
        if x0 - 5 < cx < x1 + 5 and y0 - 5 < cy < y1 + 5:
            continue
        g = site.ground(cx, cy)
        height = float(rng.uniform(0.3, 1.6)) * (top - g) + float(rng.uniform(0, 10))
        site.block(cx, cy, float(rng.uniform(8, 30)), float(rng.uniform(8, 30)), height, BUILDING)
    for _ in range(int(rng.integers(0, 6))):  # street trees below
        cx, cy = _polar(rng, 10, 60)
        if not (x0 - 2 < cx < x1 + 2 and y0 - 2 < cy < y1 + 2):
            site.tree(cx, cy, world.wind_m)
    for _ in range(int(rng.integers(0, 3))):  # potted shrubs on the roof
        cx, cy = _polar(rng, 2.5, 10)
        if x0 + 1 < cx < x1 - 1 and y0 + 1 < cy < y1 - 1:
            site.bush(cx, cy, world.wind_m, z_foot=top)


_BUILDERS = {
    "car_park": _car_park,
    "open_field": _open_field,
    "forest_edge": _forest_edge,
    "urban_canyon": _urban_canyon,
    "rooftop": _rooftop,
}


def _add_overhead(world: World, rng: np.random.Generator, site: _Site) -> None:
    """A small static thing overhanging the sensor at high elevation (55-85 deg)."""
    el = np.radians(float(rng.uniform(55.0, 85.0)))
    az = float(rng.uniform(-np.pi, np.pi))
    r = float(rng.uniform(2.5, 7.0))
    c = r * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    if world.site == "forest_edge":
        site.sphere(
            (float(c[0]), float(c[1]), float(c[2])),
            float(rng.uniform(0.2, 0.5)),
            CANOPY,
            world.wind_m,
        )
    else:  # a sign or a lamp head, 0.2-0.4 m
        half = 0.5 * float(rng.uniform(0.2, 0.4))
        lo, hi = c - half, c + half
        site.box((lo[0], lo[1], lo[2]), (hi[0], hi[1], hi[2]), BUILDING)


def _ensure_anchor(world: World, rng: np.random.Generator, site: _Site) -> None:
    """Foliage or a structure 5-15 m away for the hover kinds, when the site has none near."""
    if world.kind == "foliage_hover":
        near = [
            c
            for c, r, k in zip(site.centres, site.radii, site.sphere_kinds, strict=True)
            if k in VEGETATION and 4.0 < np.hypot(c[0], c[1]) - r < 18.0
        ]
        if len(near) < 2:
            for _ in range(2):
                cx, cy = _polar(rng, 6, 15)
                if rng.random() < 0.5:
                    site.tree(cx, cy, world.wind_m)
                else:
                    site.bush(cx, cy, world.wind_m)
    elif world.kind == "structure_hover":
        near = [c for c in site.cyls if 4.0 < np.hypot(c[0], c[1]) < 20.0]
        if len(near) < 1:
            cx, cy = _polar(rng, 6, 15)
            site.pole(cx, cy, float(rng.uniform(4, 8)))


def build_site(world: World, rng: np.random.Generator) -> TerrainScene:
    """Build the static site of ``world`` in the level frame (objects drawn from ``rng``).

    Every site gets the world's ground (slope, undulations, the surface under the sensor at
    ``-mount_height_m``), its own structure, an overhanging object when ``world.overhead``, and
    for the hover kinds at least one piece of foliage or one structure in reach.
    """
    if world.site not in _BUILDERS:
        raise ValueError(f"unknown site {world.site!r}: expected one of {', '.join(_BUILDERS)}")
    drop = float(rng.uniform(8.0, 40.0)) if world.site == "rooftop" else 0.0
    bare = bare_ground(world, rng, drop)
    if world.site == "rooftop":
        extent = rng.uniform(3.0, 20.0, 4)
        deck = np.array(
            [-extent[0], extent[1], -extent[2], extent[3], -world.mount_height_m], dtype=np.float64
        )
        bare = replace(bare, deck=deck)
    site = _Site(_ground_fn(bare), rng)
    _BUILDERS[world.site](world, rng, site, bare)
    if world.overhead:
        _add_overhead(world, rng, site)
    _ensure_anchor(world, rng, site)
    return site.scene(bare)
