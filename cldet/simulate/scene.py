"""The static world around the sensor: uneven ground, buildings, walls, cars, poles and vegetation.

All coordinates are in the Mid-360 frame (origin at the sensor, z up, metres); the ground lies
about 1.1 m below the sensor. Vegetation (tree canopies, bushes) sways a few centimetres from
frame to frame; everything else is still. Objects are kept below ~48 deg elevation so that the
Avia, which looks straight up (elevation >= 52 deg), sees sky, as in the real data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from cldet.simulate.raycast import hit_boxes, hit_spheres, hit_vertical_cylinders

F64 = NDArray[np.float64]

# Surface kinds: index into HIT_PROBABILITY / PENETRATION_M.
GROUND, BUILDING, CAR, POLE, TRUNK, CANOPY, BUSH, DRONE, PERSON, BIRD = range(10)
# Probability that a ray hitting this kind of surface returns a point (before range fading).
# The drone's 0.9 makes the Mid-360 put ~3000 * A / r^2 points on it (A = projected box area, m^2)
# within the detection range for its airframe's reflectivity (sensors.DetectionRange).
HIT_PROBABILITY = np.array([0.85, 0.95, 0.85, 0.9, 0.9, 0.5, 0.55, 0.9, 0.8, 0.6])
# Mean extra depth (m) of a return below the surface: porous vegetation returns from inside.
PENETRATION_M = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.25, 0.12, 0.0, 0.0, 0.0])

_MAX_ELEVATION_RAD = np.radians(48.0)  # static objects stay below this (the Avia sees sky)


@dataclass(frozen=True)
class Scene:
    """Static structure of one sequence's site."""

    ground_base_m: float  # mean ground height (z), metres
    ground_waves: F64  # (W, 4) rows kx, ky (rad/m), amplitude (m), phase (rad)
    box_lower: F64  # (B, 3) buildings, walls and cars: minima, metres
    box_upper: F64  # (B, 3) maxima, metres
    box_kind: NDArray[np.intp]  # (B,) BUILDING or CAR
    cylinders: F64  # (C, 5) poles and trunks: cx, cy, radius, z_bottom, z_top
    cylinder_kind: NDArray[np.intp]  # (C,) POLE or TRUNK
    sphere_centres: F64  # (S, 3) canopies and bushes at rest, metres
    sphere_radii: F64  # (S,) metres
    sphere_kind: NDArray[np.intp]  # (S,) CANOPY or BUSH
    sway: F64  # (S, 5) amplitude_x, amplitude_y (m), frequency (Hz), phase_x, phase_y (rad)

    def ground_height(self, x: F64, y: F64) -> F64:
        """Ground height z (metres) at the given x, y (metres, any matching shapes)."""
        w = self.ground_waves
        h = np.full(np.broadcast(x, y).shape, self.ground_base_m)
        for kx, ky, amp, phase in w:
            h = h + amp * np.sin(kx * x + ky * y + phase)
        return h

    def ground_up_component(self, dirs: F64) -> F64:
        """(N,) component of unit directions ``dirs`` (N, 3) along the ground's upward normal."""
        return dirs[:, 2]

    def top_height(self, x: float, y: float, margin_m: float = 0.5) -> float:
        """Highest static surface (ground, roof, pole, canopy) within ``margin_m`` of x, y (metres)."""
        top = float(self.ground_height(np.asarray(x), np.asarray(y)))
        lo, hi = self.box_lower, self.box_upper
        over = (
            (lo[:, 0] - margin_m <= x)
            & (x <= hi[:, 0] + margin_m)
            & (lo[:, 1] - margin_m <= y)
            & (y <= hi[:, 1] + margin_m)
        )
        if over.any():
            top = max(top, float(hi[over, 2].max()))
        c = self.cylinders
        near = np.hypot(c[:, 0] - x, c[:, 1] - y) <= c[:, 2] + margin_m
        if near.any():
            top = max(top, float(c[near, 4].max()))
        sc, sr = self.sphere_centres, self.sphere_radii
        near = np.hypot(sc[:, 0] - x, sc[:, 1] - y) <= sr + margin_m
        if near.any():
            top = max(top, float((sc[near, 2] + sr[near]).max()))
        return top

    def anchors(self) -> F64:
        """(K, 3) tops of cars and lamp posts (metres): things a drone may hover just above."""
        cars = self.box_kind == CAR
        car_tops = np.column_stack(
            [
                0.5 * (self.box_lower[cars, 0] + self.box_upper[cars, 0]),
                0.5 * (self.box_lower[cars, 1] + self.box_upper[cars, 1]),
                self.box_upper[cars, 2],
            ]
        )
        poles = self.cylinder_kind == POLE
        pole_tops = self.cylinders[poles][:, [0, 1, 4]]
        return np.concatenate([car_tops, pole_tops]).reshape(-1, 3)

    def max_elevation_rad(self) -> float:
        """Highest elevation (radians) any static surface reaches as seen from the sensor (bound)."""
        best = 0.0
        if len(self.box_kind):
            xs = np.stack([self.box_lower[:, 0], self.box_upper[:, 0]], axis=1)
            ys = np.stack([self.box_lower[:, 1], self.box_upper[:, 1]], axis=1)
            # nearest horizontal distance of each box footprint to the origin
            nx = np.where((xs[:, 0] <= 0) & (xs[:, 1] >= 0), 0.0, np.abs(xs).min(axis=1))
            ny = np.where((ys[:, 0] <= 0) & (ys[:, 1] >= 0), 0.0, np.abs(ys).min(axis=1))
            near = np.maximum(np.hypot(nx, ny), 1e-6)
            best = max(best, float(np.arctan2(self.box_upper[:, 2], near).max()))
        if len(self.cylinder_kind):
            c = self.cylinders
            near = np.maximum(np.hypot(c[:, 0], c[:, 1]) - c[:, 2], 1e-6)
            best = max(best, float(np.arctan2(c[:, 4], near).max()))
        if len(self.sphere_kind):
            d = np.linalg.norm(self.sphere_centres, axis=1)
            r = self.sphere_radii + np.hypot(self.sway[:, 0], self.sway[:, 1]) + 0.05
            el = np.arcsin(self.sphere_centres[:, 2] / d) + np.arcsin(np.minimum(r / d, 1.0))
            best = max(best, float(el.max()))
        return min(best, np.pi / 2)

    def sphere_centres_at(self, t_s: float, rng: np.random.Generator) -> F64:
        """(S, 3) vegetation centres at time ``t_s`` (seconds), swaying plus 1 cm of flutter."""
        sw = self.sway
        phase = 2.0 * np.pi * sw[:, 2] * t_s
        offset = np.column_stack(
            [
                sw[:, 0] * np.sin(phase + sw[:, 3]),
                sw[:, 1] * np.sin(phase + sw[:, 4]),
                np.zeros(len(sw)),
            ]
        )
        flutter = rng.normal(0.0, 0.01, size=offset.shape)
        return self.sphere_centres + offset + flutter

    def cast(self, dirs: F64, t_s: float, rng: np.random.Generator) -> tuple[F64, NDArray[np.intp]]:
        """Cast rays from the origin into the static scene at time ``t_s``.

        Each primitive is tested only against the rays inside the cone that bounds it (rays
        sorted by azimuth once per call), which keeps a 20k-ray scan at a few milliseconds.

        Args:
            dirs: (N, 3) unit directions.
            t_s: seconds since the start of the sequence (vegetation sway).
            rng: random source for the vegetation flutter.

        Returns:
            (N,) distance to the nearest surface (inf on a miss) and (N,) its kind (-1 on a miss).
        """
        n_all = dirs.shape[0]
        dist_all = np.full(n_all, np.inf)
        kind_all = np.full(n_all, -1, dtype=np.intp)
        # rays above every static object (the Avia's, mostly) cannot hit anything static
        low = np.flatnonzero(dirs[:, 2] < np.sin(self.max_elevation_rad() + 0.01))
        dirs = dirs[low]
        n = dirs.shape[0]
        dist = self._hit_ground(dirs)
        kind = np.where(np.isfinite(dist), GROUND, -1).astype(np.intp)
        if n == 0:
            return dist_all, kind_all
        az = np.arctan2(dirs[:, 1], dirs[:, 0])
        el = np.arcsin(np.clip(dirs[:, 2], -1.0, 1.0))
        order = np.argsort(az, kind="stable")
        az_sorted = az[order]

        def update(cand: NDArray[np.intp], t: F64, k: int) -> None:
            better = t < dist[cand]
            dist[cand[better]] = t[better]
            kind[cand[better]] = k

        for i in range(len(self.box_kind)):
            lo, hi = self.box_lower[i], self.box_upper[i]
            centre = 0.5 * (lo + hi)
            cand = _rays_near(az_sorted, order, el, centre, 0.5 * float(np.linalg.norm(hi - lo)))
            if len(cand):
                t, _ = hit_boxes(dirs[cand], lo[None, :], hi[None, :])
                update(cand, t, int(self.box_kind[i]))
        for i in range(len(self.cylinder_kind)):
            cx, cy, radius, z0, z1 = self.cylinders[i]
            centre = np.array([cx, cy, 0.5 * (z0 + z1)])
            cand = _rays_near(
                az_sorted, order, el, centre, float(np.hypot(radius, 0.5 * (z1 - z0)))
            )
            if len(cand):
                t, _ = hit_vertical_cylinders(dirs[cand], self.cylinders[i : i + 1])
                update(cand, t, int(self.cylinder_kind[i]))
        centres = self.sphere_centres_at(t_s, rng)
        for i in range(len(self.sphere_kind)):
            radius = float(self.sphere_radii[i])
            cand = _rays_near(az_sorted, order, el, centres[i], radius)
            if len(cand):
                t, _ = hit_spheres(dirs[cand], centres[i : i + 1], self.sphere_radii[i : i + 1])
                update(cand, t, int(self.sphere_kind[i]))
        dist_all[low] = dist
        kind_all[low] = kind
        return dist_all, kind_all

    def _hit_ground(self, dirs: F64) -> F64:
        """Distance to the uneven ground along each ray (inf when it points up or grazes away)."""
        n = dirs.shape[0]
        out = np.full(n, np.inf)
        down = dirs[:, 2] < -0.005
        d = dirs[down]
        t = self.ground_base_m / d[:, 2]
        for _ in range(6):  # fixed-point iteration on t * dz = h(t dx, t dy)
            t = self.ground_height(t * d[:, 0], t * d[:, 1]) / d[:, 2]
        resid = np.abs(t * d[:, 2] - self.ground_height(t * d[:, 0], t * d[:, 1]))
        ok = (resid < 0.02) & (t > 0) & (t < 200.0)
        out[np.flatnonzero(down)[ok]] = t[ok]
        return out


def _rays_near(
    az_sorted: F64, order: NDArray[np.intp], el: F64, centre: F64, radius: float
) -> NDArray[np.intp]:
    """Indices of the rays inside the cone from the origin that bounds a sphere (centre, radius)."""
    d = float(np.linalg.norm(centre))
    if d <= radius + 0.05:
        return order.copy()
    alpha = float(np.arcsin(radius / d)) + 0.005
    el_c = float(np.arcsin(centre[2] / d))
    az_c = float(np.arctan2(centre[1], centre[0]))
    if abs(el_c) + alpha >= np.pi / 2 - 1e-3:
        cand = order
    else:
        half = float(np.arcsin(min(1.0, np.sin(alpha) / np.cos(el_c)))) + 0.005
        lo, hi = az_c - half, az_c + half
        parts = [(max(lo, -np.pi), min(hi, np.pi))]
        if lo < -np.pi:
            parts.append((lo + 2 * np.pi, np.pi))
        if hi > np.pi:
            parts.append((-np.pi, hi - 2 * np.pi))
        cand = np.concatenate(
            [
                order[
                    np.searchsorted(az_sorted, a, "left") : np.searchsorted(az_sorted, b, "right")
                ]
                for a, b in parts
            ]
        )
    return cand[np.abs(el[cand] - el_c) <= alpha]


def _polar(rng: np.random.Generator, r_min: float, r_max: float) -> tuple[float, float]:
    r = float(rng.uniform(r_min, r_max))
    a = float(rng.uniform(-np.pi, np.pi))
    return r * np.cos(a), r * np.sin(a)


def _max_top(horizontal_m: float) -> float:
    """Highest z an object at this horizontal distance may reach (keeps it out of the Avia cone)."""
    return horizontal_m * float(np.tan(_MAX_ELEVATION_RAD))


def build_scene(rng: np.random.Generator) -> Scene:
    """Draw a random site: ground, 3-7 buildings, walls, 2-4 cars, lamp posts, trees and bushes.

    At least one car and one lamp post stand 5-14 m from the sensor (anchors for hovers).
    """
    base = float(rng.uniform(-1.4, -1.0))
    n_waves = 3
    waves = np.column_stack(
        [
            rng.uniform(-1, 1, n_waves) * 2 * np.pi / rng.uniform(8, 40, n_waves),
            rng.uniform(-1, 1, n_waves) * 2 * np.pi / rng.uniform(8, 40, n_waves),
            rng.uniform(0.02, 0.1, n_waves),
            rng.uniform(0, 2 * np.pi, n_waves),
        ]
    )
    tmp = Scene(
        base,
        waves,
        np.zeros((0, 3)),
        np.zeros((0, 3)),
        np.zeros(0, dtype=np.intp),
        np.zeros((0, 5)),
        np.zeros(0, dtype=np.intp),
        np.zeros((0, 3)),
        np.zeros(0),
        np.zeros(0, dtype=np.intp),
        np.zeros((0, 5)),
    )

    def ground(x: float, y: float) -> float:
        return float(tmp.ground_height(np.asarray(x), np.asarray(y)))

    lows: list[list[float]] = []
    highs: list[list[float]] = []
    kinds: list[int] = []

    def add_box(
        cx: float,
        cy: float,
        sx: float,
        sy: float,
        height: float,
        kind: int,
        max_el_deg: float = 48.0,
    ) -> None:
        nx = max(abs(cx) - sx / 2, 0.0)
        ny = max(abs(cy) - sy / 2, 0.0)
        near = float(np.hypot(nx, ny))
        if near < 4.0:
            return
        z0 = ground(cx, cy) - 0.3
        top = min(z0 + 0.3 + height, _max_top(near), near * float(np.tan(np.radians(max_el_deg))))
        if top <= z0 + 0.5:
            return
        lows.append([cx - sx / 2, cy - sy / 2, z0])
        highs.append([cx + sx / 2, cy + sy / 2, top])
        kinds.append(kind)

    for _ in range(int(rng.integers(5, 13))):  # buildings
        cx, cy = _polar(rng, 18, 70)
        add_box(
            cx,
            cy,
            rng.uniform(5, 20),
            rng.uniform(5, 20),
            rng.uniform(3, 15),
            BUILDING,
            float(rng.uniform(8, 25)),
        )
    for _ in range(int(rng.integers(2, 7))):  # walls, fences and hedges
        cx, cy = _polar(rng, 10, 45)
        long_side = rng.uniform(8, 30)
        if rng.random() < 0.5:
            add_box(cx, cy, long_side, 0.25, rng.uniform(1.5, 3), BUILDING)
        else:
            add_box(cx, cy, 0.25, long_side, rng.uniform(1.5, 3), BUILDING)
    for i in range(int(rng.integers(2, 5))):  # parked cars, the first one near
        cx, cy = _polar(rng, 6, 12) if i == 0 else _polar(rng, 6, 25)
        along_x = rng.random() < 0.5
        add_box(cx, cy, 4.6 if along_x else 1.85, 1.85 if along_x else 4.6, 1.5, CAR)

    cyls: list[list[float]] = []
    ckinds: list[int] = []
    for i in range(int(rng.integers(2, 7))):  # lamp posts, the first one near
        cx, cy = _polar(rng, 6, 12) if i == 0 else _polar(rng, 5, 35)
        h = float(min(rng.uniform(4, 7), _max_top(np.hypot(cx, cy)) - ground(cx, cy)))
        z0 = ground(cx, cy) - 0.1
        cyls.append([cx, cy, rng.uniform(0.07, 0.12), z0, z0 + h])
        ckinds.append(POLE)
    centres: list[list[float]] = []
    radii: list[float] = []
    skinds: list[int] = []
    for _ in range(int(rng.integers(3, 11))):  # trees: trunk + canopy
        cx, cy = _polar(rng, 10, 50)
        z0 = ground(cx, cy) - 0.1
        radius = float(rng.uniform(1.5, 4.0))
        trunk = float(rng.uniform(1.5, 6.0))
        top_allowed = _max_top(max(np.hypot(cx, cy) - radius, 1.0))
        centre_z = min(z0 + trunk + 0.7 * radius, top_allowed - radius)
        if centre_z < z0 + 0.5:
            continue
        cyls.append([cx, cy, rng.uniform(0.12, 0.3), z0, centre_z])
        ckinds.append(TRUNK)
        centres.append([cx, cy, centre_z])
        radii.append(radius)
        skinds.append(CANOPY)
    for _ in range(int(rng.integers(4, 14))):  # bushes
        cx, cy = _polar(rng, 8, 45)
        radius = float(rng.uniform(0.5, 1.2))
        centres.append([cx, cy, ground(cx, cy) + 0.5 * radius])
        radii.append(radius)
        skinds.append(BUSH)
    n_s = len(radii)
    sway = np.column_stack(
        [
            rng.uniform(0.01, 0.06, n_s),
            rng.uniform(0.01, 0.06, n_s),
            rng.uniform(0.2, 0.9, n_s),
            rng.uniform(0, 2 * np.pi, n_s),
            rng.uniform(0, 2 * np.pi, n_s),
        ]
    )
    return Scene(
        ground_base_m=base,
        ground_waves=waves,
        box_lower=np.array(lows, dtype=np.float64).reshape(-1, 3),
        box_upper=np.array(highs, dtype=np.float64).reshape(-1, 3),
        box_kind=np.array(kinds, dtype=np.intp),
        cylinders=np.array(cyls, dtype=np.float64).reshape(-1, 5),
        cylinder_kind=np.array(ckinds, dtype=np.intp),
        sphere_centres=np.array(centres, dtype=np.float64).reshape(-1, 3),
        sphere_radii=np.array(radii, dtype=np.float64),
        sphere_kind=np.array(skinds, dtype=np.intp),
        sway=sway.reshape(-1, 5),
    )
