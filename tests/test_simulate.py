"""Tests of the synthetic dataset generator: layout, determinism, gaps, scenarios, CLI."""

from __future__ import annotations

import csv
import hashlib
import re
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from cldet.cli import app  # importing cldet.cli registers every command
from cldet.errors import ConfigError, OutputExistsError
from cldet.simulate import (
    PRESETS,
    PRISM_OFFSET_M,
    SCENARIOS,
    SequenceTruth,
    simulate_dataset,
    simulate_sequence,
)
from cldet.stamps import parse_stamp

NAME_RE = re.compile(r"^\d{10}\.\d{6}\.(npy|png)$")
SENSORS = ("lidar_360", "livox_avia", "radar_enhance_pcl", "Image")
LABELS = ("ground_truth", "class")


def _stamps(folder: Path) -> list[int]:
    return sorted(parse_stamp(p.name.rsplit(".", 1)[0]) for p in folder.iterdir())


def _tree_digest(root: Path) -> str:
    digest = hashlib.sha256()
    for path in sorted(p for p in root.rglob("*") if p.is_file()):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny dataset (one short sequence per split), seed 3."""
    out = tmp_path_factory.mktemp("sim") / "data"
    simulate_dataset(out, preset="tiny", seed=3)
    return out


@pytest.fixture(scope="module")
def sequences(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, SequenceTruth]]:
    """One 4 s sequence per scenario, each with its own seed."""
    root = tmp_path_factory.mktemp("scenarios")
    out = {}
    for i, scenario in enumerate(SCENARIOS):
        seq = root / scenario
        out[scenario] = (
            seq,
            simulate_sequence(seq, seed=100 + i, duration_s=4.0, scenario=scenario),
        )
    return out


def test_layout_folders_and_names(tiny: Path) -> None:
    assert sorted(p.name for p in tiny.iterdir()) == [
        "test",
        "test_timestamps.csv",
        "test_truth.csv",
        "train",
        "val",
        "val_truth.csv",
    ]
    for split in ("train", "val", "test"):
        seqs = sorted(p.name for p in (tiny / split).iterdir())
        assert seqs == ["seq0001"]
        seq = tiny / split / "seq0001"
        expected = set(SENSORS) | (set(LABELS) if split == "train" else set())
        assert {p.name for p in seq.iterdir()} == expected
        for folder in seq.iterdir():
            names = [p.name for p in folder.iterdir()]
            assert names, folder
            bad = [n for n in names if not NAME_RE.match(n)]
            assert not bad, f"{folder}: {bad[:3]}"
            assert all(n.endswith(".png") == (folder.name == "Image") for n in names)


def test_mid360_frames(tiny: Path) -> None:
    sizes = []
    for path in sorted((tiny / "train" / "seq0001" / "lidar_360").iterdir()):
        a = np.load(path)
        assert a.dtype == np.float64 and a.ndim == 2 and a.shape[1] == 3
        sizes.append(a.shape[0])
        valid = np.any(a != 0, axis=1)
        assert 0.1 < valid.mean() < 0.35  # ~21% valid rows
        # zeros come in whole 96-row packets often (sky patches)
        per_packet = valid[: len(valid) // 96 * 96].reshape(-1, 96).sum(axis=1)
        assert (per_packet == 0).sum() > 10
        # mm quantisation, stored as float32 values
        v = a[valid]
        assert np.array_equal(v, v.astype(np.float32).astype(np.float64))
        assert np.abs(v * 1000 - np.round(v * 1000)).max() < 0.01
    assert set(sizes) <= {20064, 19968, 40032}
    singles = [s for s in sizes if s != 40032]
    # the 20064, 19968, 19968 cycle (a merged frame replaces a 20064 + 19968 pair)
    assert singles.count(20064) in (len(singles) // 3, len(singles) // 3 + 1)


def test_avia_frames_zero_rows_are_negative_zero(tiny: Path) -> None:
    files = sorted((tiny / "val" / "seq0001" / "livox_avia").iterdir())
    for path in files:
        a = np.load(path)
        assert a.shape == (24000, 3) and a.dtype == np.float64
        zero = ~np.any(a != 0, axis=1)
        assert zero.sum() > 23000
        z = a[zero]
        assert np.signbit(z[:, 0]).all() and np.signbit(z[:, 1]).all()
        assert not np.signbit(z[:, 2]).any()
        v = a[~zero]
        if len(v):
            el = np.degrees(np.arcsin(v[:, 2] / np.linalg.norm(v, axis=1)))
            assert el.min() >= 51.9


def test_radar_frames(tiny: Path) -> None:
    shapes = [np.load(p).shape for p in tiny.glob("*/seq*/radar_enhance_pcl/*.npy")]
    assert all(s == (0,) or (len(s) == 2 and s[1] == 3 and s[0] > 0) for s in shapes)
    assert (0,) in shapes
    assert any(len(s) == 2 for s in shapes)


def test_labels_class_and_ground_truth(tiny: Path) -> None:
    seq = tiny / "train" / "seq0001"
    gt_names = sorted(p.name for p in (seq / "ground_truth").iterdir())
    assert gt_names == sorted(p.name for p in (seq / "class").iterdir())
    assert len(gt_names) == 60  # 20 Hz x 3 s
    classes = set()
    for name in gt_names:
        gt = np.load(seq / "ground_truth" / name)
        assert gt.shape == (3,) and gt.dtype == np.float64
        c = np.load(seq / "class" / name)
        assert c.ndim == 1 and np.issubdtype(c.dtype, np.integer)
        classes.add(int(c[0]))
    assert len(classes) == 1 and classes <= {0, 1, 2, 3}


def test_ground_truth_starts_before_first_lidar_frame(tiny: Path) -> None:
    seq = tiny / "train" / "seq0001"
    first_gt = _stamps(seq / "ground_truth")[0]
    first_lidar = _stamps(seq / "lidar_360")[0]
    assert 30_000_000 <= first_lidar - first_gt <= 40_000_000


def test_images_are_valid_pngs(tiny: Path) -> None:
    path = next(iter((tiny / "val" / "seq0001" / "Image").iterdir()))
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    length, tag = struct.unpack(">I4s", data[8:16])
    width, height, depth, color = struct.unpack(">IIBB", data[16:26])
    assert (tag, depth, color) == (b"IHDR", 8, 2)
    idat_len = struct.unpack(">I", data[33:37])[0]
    raw = zlib.decompress(data[41 : 41 + idat_len])
    assert len(raw) == height * (1 + 3 * width)


def test_csvs_match_test_ground_truth(tiny: Path) -> None:
    with (tiny / "test_timestamps.csv").open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["Sequence", "Timestamp", "Position", "Classification"]
    assert len(rows) - 1 == PRESETS["tiny"]["test"][0] * 40  # 20 Hz x 2 s
    assert all(r[0] == "seq0001" and r[2] == "" and r[3] == "" for r in rows[1:])
    assert all(re.fullmatch(r"\d{10}\.\d{6}", r[1]) for r in rows[1:])
    with (tiny / "test_truth.csv").open() as fh:
        truth = list(csv.reader(fh))
    assert truth[0] == ["Sequence", "Timestamp", "x", "y", "z", "class"]
    assert [r[:2] for r in truth[1:]] == [r[:2] for r in rows[1:]]
    # query stamps are the test GT stamps: 35 ms before the first LiDAR frame, 20 Hz
    first_lidar = _stamps(tiny / "test" / "seq0001" / "lidar_360")[0]
    assert 30_000_000 <= first_lidar - parse_stamp(rows[1][1]) <= 40_000_000
    with (tiny / "val_truth.csv").open() as fh:
        val = list(csv.reader(fh))
    assert val[0] == truth[0] and len(val) - 1 == 40


def test_clocks(tiny: Path) -> None:
    seq = tiny / "val" / "seq0001"
    mid = np.array(_stamps(seq / "lidar_360"))
    avia = np.array(_stamps(seq / "livox_avia"))
    radar = np.array(_stamps(seq / "radar_enhance_pcl"))
    image = np.array(_stamps(seq / "Image"))
    for stamps in (mid, avia, radar, image):
        assert (stamps % 1000 == 0).all()  # whole microseconds
    assert np.abs(np.diff(mid)[np.diff(mid) < 150_000_000] - 100_000_000).max() <= 200_000
    offset = avia[np.searchsorted(avia, mid)] - mid
    assert ((offset >= 12_500_000) & (offset <= 14_500_000)).all()  # 14 ms, sometimes 13 ms
    assert abs(np.median(np.diff(radar)) - 66_666_667) < 1_000_000
    assert abs(np.median(np.diff(image)) - 33_333_333) < 1_000_000
    assert 1706255000 <= mid[0] // 10**9 < 1706255000 + 600
    test_mid = _stamps(tiny / "test" / "seq0001" / "lidar_360")
    assert 1713163000 <= test_mid[0] // 10**9 < 1713163000 + 600


def test_merged_frame_exists(tiny: Path) -> None:
    sizes = [np.load(p).shape[0] for p in (tiny / "train" / "seq0001" / "lidar_360").iterdir()]
    assert sizes.count(40032) == 1
    assert len(sizes) == 29  # 30 scans, one lost and merged into the next


def test_same_seed_same_bytes_different_seed_differs(tmp_path: Path, tiny: Path) -> None:
    again = tmp_path / "again"
    simulate_dataset(again, preset="tiny", seed=3)
    assert _tree_digest(again) == _tree_digest(tiny)
    other = tmp_path / "other"
    simulate_dataset(other, preset="tiny", seed=4)
    assert _tree_digest(other) != _tree_digest(tiny)


def test_existing_output_needs_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "data"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    with pytest.raises(OutputExistsError, match="data"):
        simulate_dataset(out, preset="tiny", seed=0)
    assert (out / "keep.txt").exists()
    summary = simulate_dataset(out, preset="tiny", seed=0, overwrite=True)
    assert not (out / "keep.txt").exists()
    assert (out / "train" / "seq0001").is_dir()
    assert summary.sequences == (("train", 1), ("val", 1), ("test", 1))
    assert "3 sequences" in summary.describe()
    assert [p.name for p in tmp_path.iterdir()] == ["data"]  # no partial folder left


def test_bad_arguments_raise_config_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="preset"):
        simulate_dataset(tmp_path / "x", preset="huge")
    with pytest.raises(ConfigError, match="scenario"):
        simulate_sequence(tmp_path / "s", seed=0, duration_s=2, scenario="loop")
    with pytest.raises(ConfigError, match="duration"):
        simulate_sequence(tmp_path / "s", seed=0, duration_s=0.2)
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "f").write_text("x")
    with pytest.raises(OutputExistsError, match="full"):
        simulate_sequence(tmp_path / "full", seed=0, duration_s=2)


def test_progress_reports_one_unit_per_sequence(tmp_path: Path) -> None:
    class Recorder:
        def __init__(self) -> None:
            self.total = 0
            self.done = 0

        def start(self, total: int, description: str) -> None:
            self.total = total

        def advance(self, n: int = 1) -> None:
            self.done += n

    rec = Recorder()
    simulate_dataset(tmp_path / "d", preset="tiny", seed=1, progress=rec)
    assert rec.total == rec.done == 3


def test_cli_simulate(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(PRESETS, "small", PRESETS["tiny"])  # same code path, fewer seconds
    out = tmp_path / "cli"
    runner = CliRunner()
    result = runner.invoke(app, ["simulate", str(out), "--preset", "small", "--seed", "2"])
    assert result.exit_code == 0, result.output
    assert "3 sequences" in result.output
    assert (out / "test_timestamps.csv").is_file()
    result = runner.invoke(app, ["simulate", str(out)])
    assert result.exit_code == 1
    assert "ERROR" in result.output and str(out) in result.output


# --- simulate_sequence and the scenarios ---------------------------------------------------


def test_sequence_truth_matches_files(sequences: dict[str, tuple[Path, SequenceTruth]]) -> None:
    for seq, truth in sequences.values():
        assert list(truth.lidar_stamps_ns) == _stamps(seq / "lidar_360")
        assert list(truth.gt_stamps_ns) == _stamps(seq / "ground_truth")
        assert list(truth.avia_stamps_ns) == _stamps(seq / "livox_avia")
        assert truth.drone_positions.shape == (len(truth.lidar_stamps_ns), 3)
        assert truth.mid360_drone_points.shape == truth.lidar_stamps_ns.shape
        gt = np.array([np.load(p) for p in sorted((seq / "ground_truth").iterdir())])
        np.testing.assert_allclose(gt, truth.gt_positions)
        # GT = body centre + prism offset + 5 mm noise: compare at the LiDAR stamps
        interp = np.column_stack(
            [np.interp(truth.lidar_stamps_ns, truth.gt_stamps_ns, gt[:, k]) for k in range(3)]
        )
        err = interp - PRISM_OFFSET_M - truth.drone_positions
        assert np.median(np.linalg.norm(err, axis=1)) < 0.1


def test_scenario_close_pass_is_seen_close_by_mid360(
    sequences: dict[str, tuple[Path, SequenceTruth]],
) -> None:
    truth = sequences["close_pass"][1]
    ranges = np.linalg.norm(truth.drone_positions, axis=1)
    assert ranges.min() < 6.0
    assert truth.mid360_drone_points.max() >= 10


def test_scenario_avia_only_is_seen_only_by_avia(
    sequences: dict[str, tuple[Path, SequenceTruth]],
) -> None:
    truth = sequences["avia_only"][1]
    p = truth.drone_positions
    el = np.degrees(np.arcsin(p[:, 2] / np.linalg.norm(p, axis=1)))
    assert el.min() > 52.0
    assert truth.mid360_drone_points.sum() == 0
    assert (truth.avia_drone_points > 0).mean() > 0.3


def test_scenario_hover_stays_put(sequences: dict[str, tuple[Path, SequenceTruth]]) -> None:
    truth = sequences["hover"][1]
    p = truth.drone_positions
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1) / 0.1
    assert np.median(steps) < 0.5  # m/s: hovering most of the time
    assert truth.hover_anchor is not None
    above = p - truth.hover_anchor
    hovering = steps < 0.3
    assert hovering.mean() > 0.5
    # ~1 m above the static object's top (plus the drone's half height and wobble)
    h = above[1:][hovering]
    assert np.all(np.hypot(h[:, 0], h[:, 1]) < 0.5)
    assert 0.6 < np.median(h[:, 2]) < 1.5
    assert np.linalg.norm(p, axis=1).max() < 25
    assert (truth.mid360_drone_points > 0).mean() > 0.5


def test_scenario_distractors(sequences: dict[str, tuple[Path, SequenceTruth]]) -> None:
    assert "person" in sequences["person"][1].distractors
    assert "bird" in sequences["bird"][1].distractors


def test_flights_are_smooth_and_plausible(sequences: dict[str, tuple[Path, SequenceTruth]]) -> None:
    for scenario, (_, truth) in sequences.items():
        p = truth.drone_positions
        dt = np.diff(truth.lidar_stamps_ns) / 1e9
        speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / dt
        assert speed.max() < 9.0, scenario
        r = np.linalg.norm(p, axis=1)
        assert r.min() > 1.5 and r.max() < 110, scenario


def test_seed_varies_scene_and_flight(tmp_path: Path) -> None:
    a = simulate_sequence(tmp_path / "a", seed=11, duration_s=2, scenario="mixed", images=False)
    b = simulate_sequence(tmp_path / "b", seed=12, duration_s=2, scenario="mixed", images=False)
    assert np.linalg.norm(a.drone_positions[0] - b.drone_positions[0]) > 0.5
    fa = np.load(sorted((tmp_path / "a" / "lidar_360").iterdir())[0])
    fb = np.load(sorted((tmp_path / "b" / "lidar_360").iterdir())[0])
    za = np.percentile(fa[np.any(fa != 0, axis=1)][:, 2], 5)
    zb = np.percentile(fb[np.any(fb != 0, axis=1)][:, 2], 5)
    ra = np.median(np.linalg.norm(fa[np.any(fa != 0, axis=1)], axis=1))
    rb = np.median(np.linalg.norm(fb[np.any(fb != 0, axis=1)], axis=1))
    assert abs(za - zb) > 0.01 or abs(ra - rb) > 0.5
    assert not (tmp_path / "a" / "Image").exists()


def test_simulate_sequence_is_reproducible(tmp_path: Path) -> None:
    a = simulate_sequence(tmp_path / "a", seed=[5, 1], duration_s=1.5, scenario="bird")
    b = simulate_sequence(tmp_path / "b", seed=[5, 1], duration_s=1.5, scenario="bird")
    assert _tree_digest(tmp_path / "a") == _tree_digest(tmp_path / "b")
    np.testing.assert_array_equal(a.gt_positions, b.gt_positions)


def _projected_area(size: tuple[float, float, float], direction: np.ndarray, yaw: float) -> float:
    """Projected area (m^2) of a box of ``size`` (L, W, H) rotated by ``yaw``, seen along ``direction``."""
    c, s = np.cos(yaw), np.sin(yaw)
    ax = np.array([c, s, 0.0])
    ay = np.array([-s, c, 0.0])
    az = np.array([0.0, 0.0, 1.0])
    length, width, height = size
    return float(
        abs(direction @ ax) * width * height
        + abs(direction @ ay) * length * height
        + abs(direction @ az) * length * width
    )


def test_drone_point_count_follows_area_over_range_squared(
    sequences: dict[str, tuple[Path, SequenceTruth]],
) -> None:
    """Mid-360 points on the drone ~ 3000 * A / r^2 (within a factor 2 in the median, r < 10 m).

    A is bounded using the box's largest and smallest projected area over yaw.
    """
    from cldet.simulate import DRONE_TYPES

    ratios = []
    for _, truth in sequences.values():
        size = DRONE_TYPES[truth.class_id].size_m
        for p, n in zip(truth.drone_positions, truth.mid360_drone_points, strict=True):
            r = float(np.linalg.norm(p))
            if r > 10.0:
                continue
            d = p / r
            areas = [_projected_area(size, d, y) for y in np.linspace(0, np.pi, 7)]
            expected = 3000 * float(np.mean(areas)) / r**2
            if expected > 3:
                ratios.append(n / expected)
    assert len(ratios) > 20
    assert 0.5 < np.median(ratios) < 2.0


def test_drone_points_sit_on_the_near_face(
    sequences: dict[str, tuple[Path, SequenceTruth]],
) -> None:
    """A LiDAR sees the sensor-facing side: point centroids are nearer than the body centre."""
    truth = sequences["close_pass"][1]
    seen = truth.mid360_drone_points >= 5
    assert seen.sum() > 5
    r_points = np.linalg.norm(truth.mid360_drone_centroids[seen], axis=1)
    r_body = np.linalg.norm(truth.drone_positions[seen], axis=1)
    bias = r_body - r_points
    assert 0.02 < np.median(bias) < 0.5


def test_avia_is_about_4_7_times_denser(sequences: dict[str, tuple[Path, SequenceTruth]]) -> None:
    """Avia points on the drone ~ 4.7 * 3000 * A / r^2 (aggregate within a factor 2) in the cone."""
    from cldet.simulate import DRONE_TYPES

    _, truth = sequences["avia_only"]
    size = DRONE_TYPES[truth.class_id].size_m
    stamps = truth.lidar_stamps_ns
    expected = 0.0
    for p in truth.drone_positions:
        r = float(np.linalg.norm(p))
        areas = [_projected_area(size, p / r, y) for y in np.linspace(0, np.pi, 7)]
        expected += 4.7 * 3000 * float(np.mean(areas)) / r**2
    seen = truth.avia_drone_points[np.searchsorted(truth.avia_stamps_ns, stamps)].sum()
    assert expected > 5
    assert 0.5 < seen / expected < 2.0


# --- return rates: the airframe's reflectivity and the LiDAR's detection range ---------------


def _empty_scene() -> object:
    from cldet.simulate.scene import Scene

    no3, no5 = np.zeros((0, 3)), np.zeros((0, 5))
    none = np.zeros(0, dtype=np.intp)
    return Scene(-50.0, np.zeros((0, 4)), no3, no3, none, no5, none, no3, np.zeros(0), none, no5)


def _drone_return_rate(
    size: tuple[float, float, float], reflectivity: float, r: float, sensor: object
) -> float:
    """Share of rays aimed at a hovering box (elevation 60 deg, range ``r``) that return a point."""
    from cldet.simulate.flight import Mover, Track
    from cldet.simulate.scene import DRONE
    from cldet.simulate.sensors import scan

    rng = np.random.default_rng(7)
    el = np.radians(60.0)
    centre = r * np.array([np.cos(el), 0.0, np.sin(el)])
    times = np.array([-1.0, 1.0])
    track = Track(times, np.vstack([centre, centre]), np.zeros(2))
    half = tuple(0.5 * s for s in size)
    drone = Mover("drone", DRONE, "box", half, track, reflectivity=reflectivity)
    # rays through points spread over the box's bottom face (seen from below)
    aims = centre + rng.uniform(-0.4, 0.4, (4000, 3)) * np.array(size)
    dirs = aims / np.linalg.norm(aims, axis=1, keepdims=True)
    _, valid, kind = scan(dirs, 0.0, _empty_scene(), [drone], rng, sensor=sensor)  # type: ignore[arg-type]
    on = kind == DRONE
    assert on.mean() > 0.9  # the rays do hit the box
    return float(np.mean(valid[on]))


def test_detection_range_law_reproduces_the_datasheets() -> None:
    """The fitted power law passes through the published ranges and grows with reflectivity."""
    from cldet.simulate.sensors import AVIA_RANGE, MID360_RANGE

    for sensor in (MID360_RANGE, AVIA_RANGE):
        fitted = sensor.range_at(np.array(sensor.reflectivity))
        np.testing.assert_allclose(fitted, sensor.range_m, rtol=0.02)
        k, _ = sensor.exponent()
        assert 0.0 < k < 0.5  # brighter goes further, less than the extended-target square root
    assert MID360_RANGE.range_at(np.array([0.8]))[0] == pytest.approx(70.0)  # the scene's fade


def test_a_brighter_airframe_returns_more_points_and_none_beyond_its_range() -> None:
    """Same size and range: a white airframe outlasts a dark one; beyond the range, no point."""
    from cldet.simulate.sensors import AVIA_RANGE, MID360_RANGE

    size = (0.35, 0.29, 0.11)
    dark, white = 0.10, 0.80
    # well within both ranges the returns do not depend on the reflectivity
    near_dark = _drone_return_rate(size, dark, 20.0, MID360_RANGE)
    near_white = _drone_return_rate(size, white, 20.0, MID360_RANGE)
    assert near_dark == pytest.approx(near_white, abs=0.05)
    # beyond the dark airframe's 40 m (Mid-360 @ 10 %), within the white one's 70 m
    for r in (45.0, 50.0):
        assert _drone_return_rate(size, white, r, MID360_RANGE) > 1.5 * _drone_return_rate(
            size, dark, r, MID360_RANGE
        )
    assert _drone_return_rate(size, dark, 60.0, MID360_RANGE) == 0.0
    assert _drone_return_rate(size, white, 100.0, MID360_RANGE) == 0.0
    # the Avia reaches 190 m even at 10 %: a dark airframe at 100 m still returns
    assert _drone_return_rate(size, dark, 100.0, AVIA_RANGE) > 0.5


def test_drone_types_have_physical_reflectivities() -> None:
    from cldet.simulate import DRONE_TYPES

    assert all(0.0 < d.reflectivity <= 1.0 for d in DRONE_TYPES)


# --- ray casting invariants ------------------------------------------------------------------

_coord = st.floats(-20, 20, allow_nan=False)
_size = st.floats(0.1, 5, allow_nan=False)


def _unit_rays(seed: int, n: int = 400) -> np.ndarray:
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000), _coord, _coord, _coord, _size, _size, _size)
def test_box_hits_lie_on_the_surface_and_nothing_is_nearer(
    seed: int, x: float, y: float, z: float, sx: float, sy: float, sz: float
) -> None:
    from cldet.simulate.raycast import hit_boxes, hit_moving_box

    lo = np.array([[x, y, z]])
    hi = lo + np.array([[sx, sy, sz]])
    gap = np.maximum(np.maximum(lo[0], -hi[0]), 0.0)
    assume(np.linalg.norm(gap) > 0.05)  # the sensor is clearly outside the box
    dirs = _unit_rays(seed)
    t, idx = hit_boxes(dirs, lo, hi)
    hit = np.isfinite(t)
    assert (idx[hit] == 0).all() and (idx[~hit] == -1).all()
    p = dirs[hit] * t[hit, None]
    inside = np.all((p >= lo - 1e-6) & (p <= hi + 1e-6), axis=1)
    assert inside.all()
    on_face = np.any(np.isclose(p, lo, atol=1e-6) | np.isclose(p, hi, atol=1e-6), axis=1)
    assert on_face.all()
    # a point slightly nearer along the ray is outside the box
    q = dirs[hit] * (t[hit, None] - 1e-3)
    assert not np.all((q > lo + 1e-9) & (q < hi - 1e-9), axis=1).any()
    # the moving-box version with yaw 0 agrees
    centre = np.repeat(0.5 * (lo + hi), len(dirs), axis=0)
    t2 = hit_moving_box(dirs, centre, 0.5 * (hi - lo)[0], np.zeros(len(dirs)))
    np.testing.assert_allclose(t2, t, rtol=1e-9)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000), _coord, _coord, _coord, _size)
def test_sphere_and_cylinder_hits_lie_on_the_surface(
    seed: int, x: float, y: float, z: float, radius: float
) -> None:
    from cldet.simulate.raycast import hit_moving_sphere, hit_spheres, hit_vertical_cylinders

    dirs = _unit_rays(seed)
    centre = np.array([[x, y, z]])
    assume(abs(np.linalg.norm(centre) - radius) > 0.05 and abs(np.hypot(x, y) - radius) > 0.05)
    t, _ = hit_spheres(dirs, centre, np.array([radius]))
    hit = np.isfinite(t)
    if np.linalg.norm(centre) > radius:
        p = dirs[hit] * t[hit, None]
        np.testing.assert_allclose(np.linalg.norm(p - centre, axis=1), radius, atol=1e-6)
    t2 = hit_moving_sphere(dirs, np.repeat(centre, len(dirs), axis=0), radius)
    np.testing.assert_allclose(t2, t)
    cyl = np.array([[x, y, radius, z, z + 3.0]])
    t, _ = hit_vertical_cylinders(dirs, cyl)
    hit = np.isfinite(t)
    p = dirs[hit] * t[hit, None]
    if np.hypot(x, y) > radius:
        np.testing.assert_allclose(np.hypot(p[:, 0] - x, p[:, 1] - y), radius, atol=1e-6)
        assert ((p[:, 2] >= z - 1e-9) & (p[:, 2] <= z + 3.0 + 1e-9)).all()
