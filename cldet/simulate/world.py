"""The parameters of one randomised world, drawn from a seed (domain randomisation).

A :class:`World` fixes everything that makes one benchmark sequence physically different from
another: the scenario kind (what the drone does), the site, the sensor's mount (tilt, heading,
height above the ground below it), the ground's slope and roughness, the drone type, and the
distractors (birds, people, vehicles, rain, wind in the foliage). ``draw_world(seed)`` draws one;
``dataclasses.replace`` builds canonical cases from it (e.g. no distractors, a given tilt).

Frames: the *level* frame has its origin at the sensor and z against gravity; the scene, the
flights and the distractors live there. The *sensor* frame is the Mid-360's own (tilted) frame,
in which both LiDARs' points and the ground truth are written: ``p_level = R @ p_sensor`` with
``R = World.rotation()``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from cldet.simulate.flight import DRONE_TYPES

F64 = NDArray[np.float64]

KINDS: tuple[str, ...] = (
    "fast_pass",
    "foliage_hover",
    "structure_hover",
    "high_hover",
    "mixed",
    "close",
)
"""Scenario kinds: what the drone does (see ``cldet.simulate.actors.plan_world_drone``)."""

SITES: tuple[str, ...] = ("car_park", "open_field", "forest_edge", "urban_canyon", "rooftop")
"""Sites: the static structure around the sensor (see ``cldet.simulate.terrain.build_site``)."""

DEVELOPMENT_SEEDS = range(10_000, 20_000)
"""World seeds for development: look at these, tune on these."""
EVALUATION_SEEDS = range(90_000, 90_300)
"""World seeds held out for the robustness benchmark: never look at them while developing."""

MAX_TILT_DEG = 20.0
MOUNT_HEIGHT_M = (0.5, 5.0)
MAX_SLOPE_DEG = 10.0


@dataclass(frozen=True)
class World:
    """One randomised world: every parameter a benchmark result can be grouped by.

    Angles in degrees, lengths in metres, rates per Mid-360 frame. ``seed`` also seeds the
    details drawn later (the site's objects, the flights, the sensor noise).
    """

    seed: int
    kind: str  # one of KINDS
    site: str  # one of SITES
    tilt_deg: float  # angle between the sensor's z axis and the vertical, 0..20
    tilt_azimuth_deg: float  # level-frame azimuth toward which the sensor's z axis leans
    yaw_deg: float  # the sensor's heading in the site (its x axis), level frame
    mount_height_m: float  # sensor above the surface right below it (ground or roof), 0.5..5
    slope_deg: float  # the ground plane's slope, 0..10
    slope_azimuth_deg: float  # level-frame azimuth of the uphill direction
    roughness_m: float  # amplitude of the ground's undulations
    class_id: int  # drone type, index into DRONE_TYPES
    n_birds: int
    n_people: int
    n_vehicles: int
    rain_per_frame: float  # mean spurious rain returns per Mid-360 frame (0: dry)
    wind_m: float  # sway amplitude of foliage (canopies, branches, bushes)
    overhead: bool  # a small static object (sign, lamp, branch) overhangs the sensor
    merged_frame: bool  # lose one Mid-360 frame and merge it into the next (40032 rows)

    def rotation(self) -> F64:
        """(3, 3) sensor-to-level rotation: ``p_level = R @ p_sensor`` (heading, then tilt)."""
        return sensor_rotation(self.tilt_deg, self.tilt_azimuth_deg, self.yaw_deg)

    def describe(self) -> str:
        """One line for humans."""
        return (
            f"seed {self.seed}: {self.kind} at a {self.site.replace('_', ' ')}, "
            f"{DRONE_TYPES[self.class_id].name}, tilt {self.tilt_deg:.1f} deg, "
            f"mount {self.mount_height_m:.1f} m, slope {self.slope_deg:.1f} deg, "
            f"birds {self.n_birds}, people {self.n_people}, vehicles {self.n_vehicles}, "
            f"rain {self.rain_per_frame:.0f}/frame"
        )


def sensor_rotation(tilt_deg: float, tilt_azimuth_deg: float, yaw_deg: float = 0.0) -> F64:
    """(3, 3) rotation taking sensor-frame vectors to the level frame.

    The sensor is first turned by ``yaw_deg`` about the vertical, then tilted by ``tilt_deg``
    about the horizontal axis perpendicular to ``tilt_azimuth_deg``, so that its z axis ends up
    at ``(sin T cos A, sin T sin A, cos T)`` in the level frame.
    """
    t = np.radians(tilt_deg)
    a = np.radians(tilt_azimuth_deg)
    k = np.array([-np.sin(a), np.cos(a), 0.0])  # tilt axis (horizontal, unit)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    tilt = np.eye(3) + np.sin(t) * kx + (1.0 - np.cos(t)) * (kx @ kx)  # Rodrigues
    y = np.radians(yaw_deg)
    yaw = np.array([[np.cos(y), -np.sin(y), 0.0], [np.sin(y), np.cos(y), 0.0], [0.0, 0.0, 1.0]])
    return np.asarray(tilt @ yaw, dtype=np.float64)


def _count(rng: np.random.Generator, p: tuple[float, ...]) -> int:
    """A count 0..len(p)-1 with probabilities ``p``."""
    return int(rng.choice(len(p), p=np.asarray(p) / sum(p)))


def draw_world(seed: int) -> World:
    """Draw the world of ``seed``: kind, site, sensor pose, ground, drone type, distractors.

    The same seed always gives the same world; every field is drawn independently of the kind
    (distractors included), so that results can be grouped by any of them.
    """
    rng = np.random.default_rng([int(seed), 0])
    kind = KINDS[int(rng.integers(len(KINDS)))]
    site = SITES[int(rng.integers(len(SITES)))]
    tilt = float(rng.uniform(0.0, MAX_TILT_DEG))
    tilt_az = float(rng.uniform(-180.0, 180.0))
    yaw = float(rng.uniform(-180.0, 180.0))
    height = float(rng.uniform(*MOUNT_HEIGHT_M))
    slope = 0.0 if site == "rooftop" else float(rng.uniform(0.0, MAX_SLOPE_DEG))
    slope_az = float(rng.uniform(-180.0, 180.0))
    roughness = float(rng.uniform(0.02, 0.25))
    class_id = int(rng.integers(len(DRONE_TYPES)))
    n_birds = _count(rng, (0.4, 0.3, 0.2, 0.1))
    n_people = _count(rng, (0.5, 0.3, 0.15, 0.05))
    n_vehicles = _count(rng, (0.6, 0.3, 0.1))
    rain = 0.0 if rng.random() < 0.5 else float(rng.uniform(5.0, 150.0))
    wind = float(rng.uniform(0.02, 0.3))
    overhead = bool(rng.random() < 0.35)
    merged = bool(rng.random() < 0.3)
    return World(
        seed=int(seed),
        kind=kind,
        site=site,
        tilt_deg=tilt,
        tilt_azimuth_deg=tilt_az,
        yaw_deg=yaw,
        mount_height_m=height,
        slope_deg=slope,
        slope_azimuth_deg=slope_az,
        roughness_m=roughness,
        class_id=class_id,
        n_birds=n_birds,
        n_people=n_people,
        n_vehicles=n_vehicles,
        rain_per_frame=rain,
        wind_m=wind,
        overhead=overhead,
        merged_frame=merged,
    )
