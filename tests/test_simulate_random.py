"""Tests of the randomised worlds: the world draw, the tilted sensor, sites, flights, frames, CLI.

Invariants are checked on small canonical worlds built with ``dataclasses.replace`` (no
distractors, a chosen tilt, slope and kind), not on the luck of a few seeds.
"""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cldet.cli import app
from cldet.core.frames import pair_frames
from cldet.simulate import PRESETS, simulate_sequence
from cldet.simulate.actors import observable, plan_world_movers
from cldet.simulate.flight import DRONE_TYPES
from cldet.simulate.randomized import simulate_world_frames, write_world_sequence
from cldet.simulate.terrain import VEGETATION, TerrainScene, build_site
from cldet.simulate.world import (
    KINDS,
    MAX_TILT_DEG,
    MOUNT_HEIGHT_M,
    SITES,
    World,
    draw_world,
    sensor_rotation,
)
from converters.mmaud import find_sequences, iter_clouds, load_cloud

F64 = np.ndarray


def canonical(**changes: object) -> World:
    """A quiet world: open field, level ground, no distractors, no rain; ``changes`` on top."""
    base = replace(
        draw_world(10_000),
        kind="close",
        site="open_field",
        tilt_deg=0.0,
        tilt_azimuth_deg=30.0,
        yaw_deg=0.0,
        mount_height_m=1.5,
        slope_deg=0.0,
        roughness_m=0.02,
        n_birds=0,
        n_people=0,
        n_vehicles=0,
        rain_per_frame=0.0,
        overhead=False,
        merged_frame=False,
    )
    return replace(base, **changes)  # type: ignore[arg-type]


def ground_plane(points: F64, within_deg: float = 30.0) -> tuple[F64, float]:
    """Dominant plane of ``points`` within ``within_deg`` of horizontal (RANSAC, least squares).

    Returns the unit normal (z >= 0) and the plane's distance below the origin (metres).
    """
    rng = np.random.default_rng(0)
    best = np.zeros(len(points), dtype=bool)
    for _ in range(300):
        a, b, c = points[rng.choice(len(points), 3, replace=False)]
        n = np.cross(b - a, c - a)
        if np.linalg.norm(n) < 1e-6:
            continue
        n /= np.linalg.norm(n)
        if abs(n[2]) < np.cos(np.radians(within_deg)):
            continue
        inliers = np.abs((points - a) @ n) < 0.08
        if inliers.sum() > best.sum():
            best = inliers
    p = points[best]
    centre = p.mean(axis=0)
    normal = np.linalg.eigh(np.cov((p - centre).T))[1][:, 0]  # smallest eigenvalue
    normal = normal if normal[2] >= 0 else -normal
    return normal, float(-centre @ normal)


def elevation_deg(p: F64) -> F64:
    return np.degrees(np.arcsin(p[:, 2] / np.linalg.norm(p, axis=1)))


# --- the world draw ---------------------------------------------------------------------------


def test_draw_world_is_a_pure_function_of_the_seed() -> None:
    assert draw_world(12_345) == draw_world(12_345)
    assert draw_world(12_345) != draw_world(12_346)


def test_draw_world_ranges_and_coverage() -> None:
    worlds = [draw_world(s) for s in range(10_000, 10_300)]
    assert {w.kind for w in worlds} == set(KINDS)
    assert {w.site for w in worlds} == set(SITES)
    for w in worlds:
        assert 0.0 <= w.tilt_deg <= MAX_TILT_DEG
        assert MOUNT_HEIGHT_M[0] <= w.mount_height_m <= MOUNT_HEIGHT_M[1]
        assert 0.0 <= w.slope_deg <= 10.0
        assert 0 <= w.class_id < len(DRONE_TYPES)
    tilts = np.array([w.tilt_deg for w in worlds])
    assert tilts.max() > 18.0 and tilts.min() < 2.0
    assert any(w.rain_per_frame > 0 for w in worlds) and any(w.n_birds for w in worlds)


@pytest.mark.parametrize(
    "tilt, azimuth, yaw", [(0.0, 0.0, 40.0), (12.0, 70.0, -20.0), (20.0, -150.0, 0)]
)
def test_sensor_rotation_tilts_the_z_axis(tilt: float, azimuth: float, yaw: float) -> None:
    r = sensor_rotation(tilt, azimuth, yaw)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    t, a = np.radians(tilt), np.radians(azimuth)
    expected = [np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.cos(t)]
    np.testing.assert_allclose(r @ [0.0, 0.0, 1.0], expected, atol=1e-12)


# --- sites -------------------------------------------------------------------------------------


@pytest.mark.parametrize("site", SITES)
def test_sites_leave_the_sensor_free_and_put_the_surface_below_it(site: str) -> None:
    for seed in (10_001, 10_002):
        world = replace(draw_world(seed), site=site, overhead=True)
        scene = build_site(world, np.random.default_rng(seed))
        assert isinstance(scene, TerrainScene)
        below = float(scene.walk_height(np.zeros(1), np.zeros(1))[0])
        assert below == pytest.approx(-world.mount_height_m, abs=1e-9)
        inside = (scene.box_lower <= 0.0).all(axis=1) & (scene.box_upper >= 0.0).all(axis=1)
        assert not inside.any()
        d = np.linalg.norm(scene.sphere_centres, axis=1)
        assert (d > scene.sphere_radii).all()
        # a ray straight down meets the surface right below the sensor
        dist, _ = scene.cast(np.array([[0.0, 0.0, -1.0]]), 0.0, np.random.default_rng(0))
        assert dist[0] == pytest.approx(world.mount_height_m, abs=0.05)


def test_overhead_objects_reach_high_elevation() -> None:
    world = replace(canonical(), site="car_park", overhead=True)
    scene = build_site(world, np.random.default_rng(3))
    tops = np.concatenate(
        [0.5 * (scene.box_lower + scene.box_upper), scene.sphere_centres]
    ).reshape(-1, 3)
    assert (elevation_deg(tops) > 54.0).any()


# --- the tilted sensor ---------------------------------------------------------------------


@pytest.mark.parametrize(
    "tilt, slope",
    [(0.0, 0.0), (9.0, 0.0), (17.0, 0.0), (0.0, 8.0), (12.0, 6.0)],
)
def test_ground_plane_normal_in_the_sensor_frame(tilt: float, slope: float) -> None:
    world = canonical(
        tilt_deg=tilt, tilt_azimuth_deg=50.0, slope_deg=slope, slope_azimuth_deg=-100.0
    )
    frames, truth = simulate_world_frames(world, 1.0)
    pts = np.concatenate([f.mid360 for f in frames]).astype(np.float64)
    pts = pts[np.linalg.norm(pts, axis=1) < 40.0]
    normal, offset = ground_plane(pts)
    # the level frame's ground normal, seen from the tilted sensor
    g = np.tan(np.radians(slope)) * np.array(
        [np.cos(np.radians(-100.0)), np.sin(np.radians(-100.0))]
    )
    n_level = np.array([-g[0], -g[1], 1.0]) / np.linalg.norm([-g[0], -g[1], 1.0])
    expected = n_level @ world.rotation()  # row form of R.T @ n
    angle = np.degrees(np.arccos(np.clip(normal @ expected, -1, 1)))
    assert angle < 0.7, (normal, expected)
    tilt_from_vertical = np.degrees(np.arccos(normal[2]))
    if slope == 0.0:
        assert tilt_from_vertical == pytest.approx(tilt, abs=0.7)
        assert offset == pytest.approx(world.mount_height_m, abs=0.1)
    np.testing.assert_allclose(truth.rotation, world.rotation())


def test_fields_of_view_are_the_sensors_own() -> None:
    world = canonical(tilt_deg=15.0, site="forest_edge", kind="high_hover")
    frames, _ = simulate_world_frames(world, 1.0)
    mid = np.concatenate([f.mid360 for f in frames]).astype(np.float64)
    avia = np.concatenate([f.avia for f in frames]).astype(np.float64)
    mid = mid[np.linalg.norm(mid, axis=1) > 0.2]  # not the self-returns (mm rounding)
    avia = avia[np.linalg.norm(avia, axis=1) > 0.2]
    el = elevation_deg(mid)
    assert el.min() >= -7.05 and el.max() <= 52.05
    assert elevation_deg(avia).min() >= 51.9
    # the tilt shows: in the level frame some Mid-360 points are far below -7 deg
    assert elevation_deg(mid @ world.rotation().T).min() < -15.0


def test_drone_points_agree_with_the_truth_minus_the_prism() -> None:
    world = canonical(tilt_deg=15.0, tilt_azimuth_deg=-60.0, yaw_deg=35.0, class_id=2)
    _, truth = simulate_world_frames(world, 2.0)
    rot = world.rotation()
    np.testing.assert_allclose(truth.prism_offset, rot.T @ [0.0, 0.0, 0.15], atol=1e-12)
    # ground truth = body centre + prism (level frame) + 5 mm noise, all in the sensor frame
    gt = np.column_stack(
        [
            np.interp(truth.lidar_stamps_ns, truth.gt_stamps_ns, truth.gt_positions[:, k])
            for k in range(3)
        ]
    )
    err = gt - truth.prism_offset - truth.lidar_body_positions
    assert np.median(np.linalg.norm(err, axis=1)) < 0.03
    half_diag = 0.5 * float(np.linalg.norm(DRONE_TYPES[2].size_m))
    v_max = float(truth.speeds_mps.max())
    assert truth.mid360_drone_points.sum() > 20
    for centre, xyz in zip(truth.lidar_body_positions, truth.mid360_drone_xyz, strict=True):
        if len(xyz):
            d = np.linalg.norm(xyz - centre, axis=1)
            assert d.max() < half_diag + 0.08 + 0.1 * v_max  # points are taken over 100 ms


def test_return_rate_on_the_drone_follows_area_over_range_squared() -> None:
    world = canonical(kind="close", class_id=2)
    _, truth = simulate_world_frames(world, 2.0)
    r = np.linalg.norm(truth.lidar_body_positions, axis=1)
    seen = truth.mid360_drone_points
    size = DRONE_TYPES[2].size_m
    area = max(size[0], size[1]) * size[2]  # side-on projected area, order of magnitude
    expected = 3000.0 * area / r**2
    in_band = elevation_deg(truth.lidar_body_positions) < 45.0
    if in_band.sum() >= 5:
        ratio = seen[in_band].sum() / expected[in_band].sum()
        assert 0.2 < ratio < 5.0


# --- flights and distractors -------------------------------------------------------------------


def _drone_path(world: World, duration_s: float = 8.0) -> tuple[TerrainScene, F64, F64]:
    """Site, level-frame drone positions and speeds over [0, duration] (10 ms steps)."""
    scene = build_site(world, np.random.default_rng(world.seed))
    movers = plan_world_movers(np.random.default_rng(world.seed + 1), world, scene, duration_s)
    track = movers[0].track
    keep = (track.times_s >= 0) & (track.times_s <= duration_s)
    vel = np.gradient(track.positions, track.times_s, axis=0)
    return scene, track.positions[keep], np.linalg.norm(vel[keep], axis=1)


@pytest.mark.parametrize("seed", [10_010, 10_011, 10_012])
def test_fast_pass_is_fast_and_passes_10_to_40_m_out(seed: int) -> None:
    _, p, v = _drone_path(replace(draw_world(seed), kind="fast_pass"))
    assert 7.5 <= np.median(v) <= 23.5
    assert v.max() < 25.0
    assert 9.0 <= np.linalg.norm(p, axis=1).min() <= 45.0


@pytest.mark.parametrize("seed", [10_020, 10_021, 10_022])
def test_high_hover_stays_high_inside_the_tilted_avia_cone(seed: int) -> None:
    world = replace(draw_world(seed), kind="high_hover")
    _, p, v = _drone_path(world)
    assert p[:, 2].min() >= 28.0 and p[:, 2].max() <= 83.0
    assert elevation_deg(p @ world.rotation()).min() > 55.0
    assert v.max() < 3.0


@pytest.mark.parametrize("seed", [10_030, 10_031, 10_032])
def test_close_flights_stay_within_10_m(seed: int) -> None:
    _, p, v = _drone_path(replace(draw_world(seed), kind="close"))
    r = np.linalg.norm(p, axis=1)
    assert r.min() >= 1.99 and r.max() <= 11.0
    assert v.max() <= 6.5


@pytest.mark.parametrize("seed", [10_040, 10_041, 10_042])
def test_foliage_hover_hovers_1_to_3_m_from_swaying_foliage(seed: int) -> None:
    world = replace(draw_world(seed), kind="foliage_hover")
    scene, p, v = _drone_path(world)
    hovering = v < 0.5
    assert hovering.mean() > 0.4
    veg = np.isin(scene.sphere_kind, VEGETATION)
    gap = (
        np.linalg.norm(p[hovering][:, None, :] - scene.sphere_centres[veg][None], axis=2)
        - scene.sphere_radii[veg][None]
    ).min(axis=1)
    half = 0.5 * max(DRONE_TYPES[world.class_id].size_m)
    assert np.median(gap) == pytest.approx(2.0 + half, abs=1.3)
    assert (scene.sway[veg, :2] > 0).all()


@pytest.mark.parametrize("seed", [10_050, 10_051])
def test_structure_hover_hovers_near_a_structure(seed: int) -> None:
    world = replace(draw_world(seed), kind="structure_hover")
    scene, p, v = _drone_path(world)
    assert (v < 0.5).mean() > 0.4
    hover = p[v < 0.5]
    near_pole = np.hypot(
        hover[:, None, 0] - scene.cylinders[None, :, 0],
        hover[:, None, 1] - scene.cylinders[None, :, 1],
    ).min(axis=1)
    lo, hi = scene.box_lower, scene.box_upper
    out = np.maximum(np.maximum(lo[None] - hover[:, None], hover[:, None] - hi[None]), 0.0)
    near_box = np.linalg.norm(out, axis=2).min(axis=1)
    assert np.median(np.minimum(near_pole, near_box)) < 3.5


@pytest.mark.parametrize("kind", KINDS)
def test_the_drone_is_observable_most_of_the_time(kind: str) -> None:
    # in range, inside the tilted sensors' fields of view, not hidden by the static site
    for seed in (10_100, 10_101):
        world = replace(draw_world(seed), kind=kind)
        scene = build_site(world, np.random.default_rng(seed))
        movers = plan_world_movers(np.random.default_rng(seed + 1), world, scene, 8.0)
        points = movers[0].track.at(np.arange(0.0, 8.0, 0.4))
        seen = np.mean([observable(scene, world.rotation(), p) for p in points])
        assert seen >= (0.25 if kind == "fast_pass" else 0.6), (seed, world.site)


def test_speeds_of_every_kind_stay_below_23_m_s_and_birds_overlap() -> None:
    for i, kind in enumerate(KINDS):
        world = replace(draw_world(10_060 + i), kind=kind, n_birds=3)
        scene = build_site(world, np.random.default_rng(1))
        movers = plan_world_movers(np.random.default_rng(2), world, scene, 6.0)
        for m in movers:
            t = m.track
            vel = np.gradient(t.positions, t.times_s, axis=0)
            active = (t.times_s >= max(m.active_s[0], 0.0)) & (t.times_s <= min(m.active_s[1], 6.0))
            if m.name == "drone":
                assert np.linalg.norm(vel, axis=1).max() < 25.0, kind
            elif m.name == "bird" and active.any():
                h = np.hypot(vel[active, 0], vel[active, 1])
                assert 4.0 < np.median(h) < 20.5
                assert m.active_s[1] - m.active_s[0] <= 3.0
                assert m.dims[0] <= 0.15


# --- frames --------------------------------------------------------------------------------


def test_same_seed_same_frames_different_seed_differs() -> None:
    a, ta = simulate_world_frames(10_070, 1.2)
    b, tb = simulate_world_frames(10_070, 1.2)
    c, _ = simulate_world_frames(10_071, 1.2)
    assert [f.stamp_ns for f in a] == [f.stamp_ns for f in b]
    for fa, fb in zip(a, b, strict=True):
        np.testing.assert_array_equal(fa.mid360, fb.mid360)
        np.testing.assert_array_equal(fa.avia, fb.avia)
    np.testing.assert_array_equal(ta.gt_positions, tb.gt_positions)
    assert [f.stamp_ns for f in a] != [f.stamp_ns for f in c]


def test_in_memory_frames_equal_the_written_folder(tmp_path: Path) -> None:
    world = replace(draw_world(10_080), merged_frame=True, rain_per_frame=40.0, n_birds=1)
    frames, truth = simulate_world_frames(world, 1.5)
    seq = tmp_path / "val" / "seq0001"
    written = write_world_sequence(seq, world, 1.5, images=False, labels=True)
    np.testing.assert_array_equal(written.gt_positions, truth.gt_positions)
    (ref,) = find_sequences(tmp_path, splits=["val"])
    disk = list(pair_frames(iter_clouds(ref, "lidar_360"), iter_clouds(ref, "livox_avia")))
    assert len(disk) == len(frames) == len(truth.lidar_stamps_ns)
    for a, b in zip(frames, disk, strict=True):
        assert (a.stamp_ns, a.avia_stamp_ns) == (b.stamp_ns, b.avia_stamp_ns)
        assert a.mid360.dtype == b.mid360.dtype == np.float32
        np.testing.assert_array_equal(a.mid360, b.mid360)
        np.testing.assert_array_equal(a.avia, b.avia)
    assert truth.merged_stamp_ns is not None
    merged = load_cloud(
        seq
        / "lidar_360"
        / f"{truth.merged_stamp_ns // 10**9}.{truth.merged_stamp_ns % 10**9 // 1000:06d}.npy"
    )
    assert merged.shape[0] > 0
    raw = np.load(
        seq
        / "lidar_360"
        / f"{truth.merged_stamp_ns // 10**9}.{truth.merged_stamp_ns % 10**9 // 1000:06d}.npy"
    )
    assert raw.shape == (40032, 3)
    gt = sorted((seq / "ground_truth").iterdir())
    np.testing.assert_allclose(np.load(gt[0]), truth.gt_positions[0])


def test_rain_adds_lone_short_range_returns() -> None:
    dry = canonical(kind="high_hover")
    wet = replace(dry, rain_per_frame=120.0)
    near = []
    for world in (dry, wet):
        frames, _ = simulate_world_frames(world, 1.0)
        mid = np.concatenate([f.mid360 for f in frames]).astype(np.float64)
        r = np.linalg.norm(mid, axis=1)
        near.append(int(((r > 0.25) & (r < 6.0)).sum()))
    assert near[1] > near[0] + 500


# --- the CLI and the original simulator's probes ---------------------------------------------


def test_cli_simulate_randomize_writes_a_readable_dataset(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(PRESETS, "small", PRESETS["tiny"])
    out = tmp_path / "rand"
    result = CliRunner().invoke(app, ["simulate", str(out), "--randomize", "--seed", "10090"])
    assert result.exit_code == 0, result.output
    with (out / "worlds.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["seed"]) for r in rows] == [10_090, 10_091, 10_092]
    assert [r["split"] for r in rows] == ["train", "val", "test"]
    assert all(r["kind"] in KINDS and r["site"] in SITES for r in rows)
    seqs = find_sequences(out)
    assert len(seqs) == 3
    for seq in seqs:
        clouds = list(iter_clouds(seq, "lidar_360"))
        assert len(clouds) >= 20 and all(c.points.shape[1] == 3 for c in clouds)
    assert (out / "train" / "seq0001" / "ground_truth").is_dir()
    assert (out / "test_timestamps.csv").is_file()


def _original_ground(seq: Path) -> tuple[F64, float]:
    (ref,) = find_sequences(seq.parent.parent, splits=[seq.parent.name])
    pts = np.concatenate([c.points for c in iter_clouds(ref, "lidar_360")]).astype(np.float64)
    return ground_plane(pts[np.linalg.norm(pts, axis=1) < 60.0])


def test_original_simulator_probe_tilt(tmp_path: Path) -> None:
    base = tmp_path / "a" / "val" / "seq0001"
    level = simulate_sequence(base, seed=41, duration_s=1.0, scenario="mixed", images=False)
    probed = tmp_path / "b" / "val" / "seq0001"
    tilted = simulate_sequence(
        probed, seed=41, duration_s=1.0, scenario="mixed", images=False, tilt_deg=10.0
    )
    n0, d0 = _original_ground(base)
    n1, d1 = _original_ground(probed)
    assert np.degrees(np.arccos(n0[2])) < 1.0
    assert np.degrees(np.arccos(n1[2])) == pytest.approx(10.0, abs=1.0)
    assert d1 == pytest.approx(d0, abs=0.3)
    # the same world, seen from the tilted sensor: truth rotated, not moved
    np.testing.assert_allclose(
        np.linalg.norm(tilted.gt_positions, axis=1), np.linalg.norm(level.gt_positions, axis=1)
    )
    assert not np.allclose(tilted.gt_positions, level.gt_positions)


def test_original_simulator_probe_mount(tmp_path: Path) -> None:
    base = tmp_path / "a" / "val" / "seq0001"
    low = simulate_sequence(base, seed=43, duration_s=1.0, scenario="hover", images=False)
    probed = tmp_path / "b" / "val" / "seq0001"
    high = simulate_sequence(
        probed, seed=43, duration_s=1.0, scenario="hover", images=False, mount_offset_m=3.0
    )
    np.testing.assert_allclose(high.gt_positions, low.gt_positions - [0.0, 0.0, 3.0])
    assert low.hover_anchor is not None and high.hover_anchor is not None
    np.testing.assert_allclose(high.hover_anchor, low.hover_anchor - [0.0, 0.0, 3.0])
    lowest = []
    for root in (base, probed):
        (ref,) = find_sequences(root.parent.parent, splits=["val"])
        pts = np.concatenate([c.points for c in iter_clouds(ref, "lidar_360")])
        lowest.append(float(np.percentile(pts[:, 2], 1.0)))  # the ground (it undulates a little)
    assert lowest[0] - lowest[1] == pytest.approx(3.0, abs=0.4)


def test_original_simulator_probe_overhang(tmp_path: Path) -> None:
    seq = tmp_path / "val" / "seq0001"
    simulate_sequence(
        seq, seed=42, duration_s=1.0, scenario="hover", images=False, overhang_elevation_deg=67.0
    )
    (ref,) = find_sequences(tmp_path, splits=["val"])
    avia = np.concatenate([c.points for c in iter_clouds(ref, "livox_avia")]).astype(np.float64)
    r = np.linalg.norm(avia, axis=1)
    el = elevation_deg(avia)
    near = (r > 2.5) & (r < 6.5) & (np.abs(el - 67.0) < 4.0)
    assert near.sum() >= 10
