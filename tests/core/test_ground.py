"""Tests of the ground model: tilted sensors, slopes and rooftops, from static points."""

from __future__ import annotations

import numpy as np
import pytest

from cldet.core.ground import GroundModel


def _rotation(tilt_deg: float, axis_deg: float) -> np.ndarray:
    """Rotation by ``tilt_deg`` about a horizontal axis at azimuth ``axis_deg``."""
    a = np.radians(axis_deg)
    k = np.array([np.cos(a), np.sin(a), 0.0])
    t = np.radians(tilt_deg)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(t) * kx + (1 - np.cos(t)) * kx @ kx


def _ground(rng: np.random.Generator, height_m: float, n: int = 3000) -> np.ndarray:
    """Points on level ground ``height_m`` below a level sensor, out to 30 m, plus a wall."""
    r = np.sqrt(rng.uniform(1.0, 900.0, n))
    az = rng.uniform(-np.pi, np.pi, n)
    ground = np.stack([r * np.cos(az), r * np.sin(az), np.full(n, -height_m)], axis=1)
    wall = np.stack(
        [np.full(400, 8.0), rng.uniform(-5, 5, 400), rng.uniform(-height_m, 4.0, 400)], axis=1
    )
    return np.concatenate([ground, wall]) + rng.normal(0, 0.02, (n + 400, 3))


@pytest.mark.parametrize(("tilt", "height"), [(0.0, 1.5), (8.0, 1.0), (15.0, 3.0), (20.0, 5.0)])
def test_the_plane_is_found_under_a_tilted_sensor(tilt: float, height: float) -> None:
    rng = np.random.default_rng(int(tilt))
    rot = _rotation(tilt, 30.0)
    pts = _ground(rng, height) @ rot.T  # what the tilted sensor sees, in its own frame
    model = GroundModel()
    assert not model.fitted
    assert np.isnan(model.height_above(np.zeros((1, 3)))).all()
    assert model.fit(pts)
    assert model.normal is not None
    up_in_sensor = rot @ np.array([0.0, 0.0, 1.0])
    assert np.degrees(np.arccos(model.normal @ up_in_sensor)) < 1.0
    assert model.offset == pytest.approx(height, abs=0.05)
    # a point 2 m above the ground at 10 m, and a person's foot on it
    probe = np.array([[10.0, 0.0, 2.0 - height], [5.0, 5.0, -height]]) @ rot.T
    np.testing.assert_allclose(model.height_above(probe), [2.0, 0.0], atol=0.1)


def test_the_street_below_a_roof_edge_is_the_local_ground() -> None:
    # a sensor 1 m above a roof that ends 6 m away; the street lies 10 m lower beyond it
    rng = np.random.default_rng(3)
    roof = np.stack([rng.uniform(-6, 6, 3000), rng.uniform(-6, 6, 3000), np.full(3000, -1.0)], 1)
    street = np.stack([rng.uniform(10, 30, 600), rng.uniform(-20, 20, 600), np.full(600, -11.0)], 1)
    model = GroundModel()
    assert model.fit(np.concatenate([roof, street]))
    assert model.offset == pytest.approx(1.0, abs=0.05)  # the roof is the plane
    # a drone 3 m above the street 20 m out is 13 m above the local ground, not 3 m below 0
    h = model.height_above(np.array([[20.0, 0.0, -8.0], [2.0, 2.0, 0.5]]))
    np.testing.assert_allclose(h, [3.0, 1.5], atol=0.1)


def test_below_the_ground_is_below_both_the_plane_and_the_local_ground() -> None:
    # the roof scene above: under the roof is below the ground; beyond its edge, above the
    # street but 5 m below the roof's plane, is not; under the street is
    rng = np.random.default_rng(3)
    roof = np.stack([rng.uniform(-6, 6, 3000), rng.uniform(-6, 6, 3000), np.full(3000, -1.0)], 1)
    street = np.stack([rng.uniform(10, 30, 600), rng.uniform(-20, 20, 600), np.full(600, -11.0)], 1)
    model = GroundModel()
    assert np.isnan(model.depth_below(np.zeros((1, 3)))).all()  # no fit: unknown
    assert model.fit(np.concatenate([roof, street]))
    probe = np.array([[2.0, 2.0, -4.0], [20.0, 0.0, -6.0], [20.0, 0.0, -13.0], [2.0, 2.0, 1.0]])
    np.testing.assert_allclose(model.depth_below(probe), [3.0, -5.0, 2.0, -2.0], atol=0.1)


def test_no_plane_from_points_above_the_sensor_only() -> None:
    rng = np.random.default_rng(4)
    model = GroundModel()
    assert not model.fit(rng.uniform([-5, -5, 1], [5, 5, 3], (500, 3)))
    assert not model.fit(np.zeros((2, 3)))
    assert not model.fitted


def test_where_the_ground_is_below_the_field_of_view_the_plane_is_the_ground() -> None:
    # a sensor on a mast 5 m up sees the ground (lowest elevation -7.3 deg) from ~39 m out; a
    # hedge 15 m away shows only its part above the field's edge, ~3.1 m above the ground
    rng = np.random.default_rng(5)
    r = np.sqrt(rng.uniform(40.0**2, 80.0**2, 4000))
    az = rng.uniform(-np.pi, np.pi, 4000)
    ground = np.stack([r * np.cos(az), r * np.sin(az), np.full(4000, -5.0)], axis=1)
    edge = np.tan(np.radians(-7.3)) * 15.0
    hedge = np.stack(
        [np.full(300, 15.0), rng.uniform(-3, 3, 300), rng.uniform(edge, edge + 0.5, 300)], axis=1
    )
    above_hedge = np.array([[15.0, 0.0, -1.0]])  # 4 m above the ground
    blind = GroundModel(field_bottom_deg=-7.3)
    assert blind.fit(np.concatenate([ground, hedge]))
    assert blind.height_above(above_hedge)[0] == pytest.approx(4.0, abs=0.1)
    # told nothing of the field of view, the hedge's lowest return passes for the ground
    naive = GroundModel()
    assert naive.fit(np.concatenate([ground, hedge]))
    assert naive.height_above(above_hedge)[0] < 1.0
    # where the ground is in view the map still holds: a sunken lot 2 m down, 60-70 m out
    lot = np.stack([rng.uniform(60, 70, 400), rng.uniform(-5, 5, 400), np.full(400, -7.0)], 1)
    assert blind.fit(np.concatenate([ground, lot]))
    assert blind.height_above(np.array([[65.0, 0.0, -6.0]]))[0] == pytest.approx(1.0, abs=0.1)


def test_a_known_mount_gives_the_plane_the_fit_finds() -> None:
    # level ground seen by a sensor 3 m up, rolled 10 deg and pitched -5 deg: the plane from the
    # mount (as the log's transform tree places the sensor) is the one fitted to the returns
    from cldet.config import SensorConfig
    from cldet.io.transforms import world_from_mid360

    rng = np.random.default_rng(10)
    sensor = SensorConfig(height_m=3.0, roll_deg=10.0, pitch_deg=-5.0)
    world = np.column_stack([rng.uniform(-30, 30, (3000, 2)), np.zeros(3000)])
    pose = world_from_mid360(sensor)
    seen = (world - pose[:3, 3]) @ pose[:3, :3]  # into the sensor's frame
    fitted = GroundModel()
    assert fitted.fit(seen)
    assert fitted.normal is not None
    known = GroundModel(plane=GroundModel.from_pose(3.0, 10.0, -5.0))
    assert known.fitted  # before any return is seen
    assert known.normal is not None
    assert np.degrees(np.arccos(np.clip(known.normal @ fitted.normal, -1, 1))) < 0.5
    assert known.offset == pytest.approx(fitted.offset, abs=0.05)
    np.testing.assert_allclose(known.plane_height(seen), 0.0, atol=1e-9)


def test_on_a_roof_below_the_view_a_known_mount_keeps_the_roof_as_the_ground() -> None:
    # a sensor 2.4 m above a roof 30 m wide, which lies below its view (the Mid-360 sees the
    # roof only beyond ~19 m); the street 12 m lower is seen from 20 m out, beyond the edge
    rng = np.random.default_rng(11)
    r = rng.uniform(20.0, 80.0, 3000)
    az = rng.uniform(-np.pi, np.pi, 3000)
    street = np.column_stack([r * np.cos(az), r * np.sin(az), np.full(3000, -14.4)])
    head = np.array([[8.0, 0.0, -0.6]])  # a person on the roof: head 1.8 m above it
    fitted = GroundModel(field_bottom_deg=-7.3)
    assert fitted.fit(street)
    assert fitted.offset == pytest.approx(14.4, abs=0.1)  # the street is all it sees
    assert fitted.height_above(head)[0] == pytest.approx(13.8, abs=0.1)  # "flying"
    known = GroundModel(field_bottom_deg=-7.3, plane=GroundModel.from_pose(2.4, 0.0, 0.0))
    assert known.fit(street)
    assert known.offset == 2.4
    assert known.height_above(head)[0] == pytest.approx(1.8, abs=0.05)
    # and beyond the edge the street seen there is the local ground
    assert known.height_above(np.array([[40.0, 0.0, -10.0]]))[0] == pytest.approx(4.4, abs=0.1)
