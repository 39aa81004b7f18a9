"""Randomised worlds as sequences: in memory for benchmarks, or written in the challenge layout.

A :class:`~cldet.simulate.world.World` (drawn from a seed by ``draw_world``) is turned into a
site (``terrain.build_site``), a drone and distractors (``actors.plan_world_movers``) in the level
frame, and scanned by the existing sensor models through the sensor's tilt: rays are fired in the
sensor frame (the Mid-360's -7..52 deg band and the Avia's cone are the sensor's own), cast along
``R @ d`` in the level frame, and the points come back in the sensor frame. The ground truth
(body centre + prism offset (0, 0, 0.15) m in the level frame + 5 mm noise) is written in the
sensor frame too, at its own 20 Hz stamps, as real data would be; a frame's points are collected
over the 100 ms after its stamp.

Rain adds lone short-range (0.3-6 m) and far (15-150 m) returns to both LiDARs.

``simulate_world_frames(seed)`` returns the paired frames exactly as
``pair_frames(iter_clouds(...))`` gives them after ``write_world_sequence`` (same seed, same
values), without touching the disk. Everything is a pure function of the world.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from cldet.core.frames import pair_frames
from cldet.errors import CldetError, ConfigError, OutputExistsError
from cldet.simulate.actors import plan_world_movers
from cldet.simulate.dataset import (
    GT_LEAD_NS,
    GT_NOISE_M,
    GT_PERIOD_NS,
    IMAGE_PERIOD_NS,
    MID360_PERIOD_NS,
    PRISM_OFFSET_M,
    RADAR_PERIOD_NS,
    TRAIN_EPOCH_S,
    _save_npy,
    _us_grid,
)
from cldet.simulate.flight import Mover
from cldet.simulate.sensors import (
    MID360_ROW_CYCLE,
    _to_points,
    avia_clutter_states,
    avia_directions,
    avia_frame,
    camera_image,
    mid360_directions,
    mid360_frame,
    radar_frames,
)
from cldet.simulate.terrain import TerrainScene, build_site
from cldet.simulate.world import World, draw_world
from cldet.stamps import format_stamp, row_times
from cldet.types import Cloud, LidarFrame

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

RAIN_SHORT_M = (0.3, 6.0)
RAIN_FAR_M = (15.0, 150.0)
_STREAMS = ("site", "movers", "clocks", "mid360", "avia", "truth", "radar", "images")


@dataclass(frozen=True)
class WorldTruth:
    """What really happened in one randomised sequence. Positions in the SENSOR frame (metres),
    times in integer ns.

    A LiDAR frame stamped ``s`` fires its rays over ``[s, s + 100 ms)``.
    """

    world: World
    class_id: int  # 0..3, index into DRONE_TYPES
    rotation: F64  # (3, 3) sensor-to-level rotation: p_level = rotation @ p_sensor
    prism_offset: (
        F64  # (3,) the prism offset (0, 0, 0.15) m of the level frame, in the sensor frame
    )
    gt_stamps_ns: I64  # (K,) 20 Hz, the first one ~35 ms before the first LiDAR frame
    gt_positions: F64  # (K, 3) body centre + prism offset + 5 mm noise (what is scored)
    body_positions: F64  # (K, 3) the drone's body centre at the GT stamps, no noise
    speeds_mps: F64  # (K,) the drone's speed at the GT stamps
    lidar_stamps_ns: I64  # (N,) stamps of the Mid-360 files (a merged frame counts once)
    lidar_body_positions: F64  # (N, 3) body centre at the Mid-360 stamps
    mid360_drone_points: I64  # (N,) Mid-360 points on the drone per file
    mid360_drone_xyz: tuple[F64, ...]  # N arrays (k, 3): those points (sensor frame, metres)
    avia_stamps_ns: I64  # (M,) stamps of the Avia files
    avia_drone_points: I64  # (M,) Avia points on the drone per file
    distractors: tuple[str, ...]  # movers other than the drone ("bird", "person", "vehicle")
    merged_stamp_ns: int | None  # stamp of the 40032-row Mid-360 file, None when none


class _WorldRun:
    """Everything drawn for one world before scanning: site, movers, clocks, rotation."""

    def __init__(self, world: World, duration_s: float, epoch_s: int) -> None:
        if not duration_s >= 1.0:
            raise ConfigError(f"duration_s must be at least 1 s, got {duration_s}")
        self.world = world
        children = np.random.SeedSequence([int(world.seed), 1]).spawn(len(_STREAMS))
        self.rngs = {
            name: np.random.default_rng(child)
            for name, child in zip(_STREAMS, children, strict=True)
        }
        self.rotation = world.rotation()
        self.scene: TerrainScene = build_site(world, self.rngs["site"])
        self.movers: list[Mover] = plan_world_movers(
            self.rngs["movers"], world, self.scene, duration_s
        )
        rng = self.rngs["clocks"]
        self.t0_ns = int(epoch_s) * 1_000_000_000 + int(rng.integers(0, 60_000_000)) * 1000
        n_lidar = max(int(round(duration_s * 10)), 3)
        self.mid_ns = _us_grid(self.t0_ns, MID360_PERIOD_NS, n_lidar, 100.0, rng)
        lag_us = 14_000 - 1000 * (rng.random(n_lidar) < 0.34) + rng.normal(0.0, 70.0, n_lidar)
        self.avia_ns = self.mid_ns + np.round(lag_us).astype(np.int64) * 1000
        n_gt = int(round(duration_s * 20))
        self.gt_ns = _us_grid(self.t0_ns - GT_LEAD_NS, GT_PERIOD_NS, n_gt, 500.0, rng)
        self.gt_ns[0] = min(int(self.gt_ns[0]), int(self.mid_ns[0]) - 30_000_000)
        radar_start = self.t0_ns + int(rng.integers(0, RADAR_PERIOD_NS // 1000)) * 1000
        self.radar_ns = _us_grid(
            radar_start, RADAR_PERIOD_NS, int(round(duration_s * 15)), 300.0, rng
        )
        image_start = self.t0_ns + int(rng.integers(0, IMAGE_PERIOD_NS // 1000)) * 1000
        self.image_ns = _us_grid(
            image_start, IMAGE_PERIOD_NS, int(round(duration_s * 30)), 500.0, rng
        )
        phase = int(rng.integers(len(MID360_ROW_CYCLE)))
        self.rows = [MID360_ROW_CYCLE[(k + phase) % 3] for k in range(n_lidar)]
        self.lost = -1
        if world.merged_frame:
            choices = [k for k in range(1, n_lidar - 1) if self.rows[k] == MID360_ROW_CYCLE[0]]
            if choices:
                self.lost = int(choices[int(rng.integers(len(choices)))])
        self.clutter = avia_clutter_states(rng, n_lidar)
        # filled while scanning
        self.written_mid: list[int] = []
        self.mid_counts: list[int] = []
        self.mid_xyz: list[F64] = []
        self.avia_counts: list[int] = []

    def rel_s(self, stamp_ns: int | np.int64) -> float:
        return (int(stamp_ns) - self.t0_ns) / 1e9

    def _rain(
        self, rng: np.random.Generator, points: F64, short_rate: float, far_rate: float, avia: bool
    ) -> None:
        """Put lone rain returns into empty rows of ``points`` (in place, sensor frame)."""
        if short_rate <= 0.0:
            return
        n_short, n_far = int(rng.poisson(short_rate)), int(rng.poisson(far_rate))
        empty = np.flatnonzero(~np.any(points != 0.0, axis=1))
        n = min(n_short + n_far, len(empty))
        if n == 0:
            return
        pick = rng.choice(empty, n, replace=False)
        dirs = avia_directions(rng, n) if avia else mid360_directions(rng, n)
        ranges = np.concatenate(
            [rng.uniform(*RAIN_SHORT_M, n_short), rng.uniform(*RAIN_FAR_M, n_far)]
        )[:n]
        points[pick] = _to_points(dirs, ranges).astype(np.float64)

    def iter_mid360(self) -> Iterator[tuple[int, F64]]:
        """(stamp_ns, (rows, 3) float64 with zero rows) per Mid-360 file, in stamp order."""
        rng = self.rngs["mid360"]
        rain = self.world.rain_per_frame
        pending: tuple[F64, int, F64] | None = None
        for k, stamp in enumerate(self.mid_ns):
            frame = mid360_frame(
                rng, self.rows[k], self.rel_s(stamp), self.scene, self.movers, self.rotation
            )
            points = frame.points
            self._rain(rng, points, rain, 0.15 * rain, avia=False)
            xyz = points[frame.drone_rows]
            count = frame.drone_points
            if k == self.lost:
                pending = (points, count, xyz)
                continue
            if pending is not None:
                points = np.concatenate([pending[0], points])
                count += pending[1]
                xyz = np.concatenate([pending[2], xyz])
                pending = None
            self.written_mid.append(int(stamp))
            self.mid_counts.append(count)
            self.mid_xyz.append(xyz)
            yield int(stamp), points

    def iter_avia(self) -> Iterator[tuple[int, F64]]:
        """(stamp_ns, (24000, 3) float64, zero rows (-0, -0, +0)) per Avia file."""
        rng = self.rngs["avia"]
        rain = self.world.rain_per_frame
        for k, stamp in enumerate(self.avia_ns):
            frame = avia_frame(
                rng,
                self.rel_s(stamp),
                self.scene,
                self.movers,
                bool(self.clutter[k]),
                self.rotation,
            )
            points = frame.points
            self._rain(rng, points, 0.3 * rain, 0.1 * rain, avia=True)
            empty = ~np.any(points != 0.0, axis=1)
            points[empty] = np.array([-0.0, -0.0, 0.0])
            self.avia_counts.append(frame.drone_points)
            yield int(stamp), points

    def truth(self) -> WorldTruth:
        """The truth; call after both scans were iterated to the end."""
        rot = self.rotation
        track = self.movers[0].track
        gt_t = (self.gt_ns - self.t0_ns) / 1e9
        body = track.at(gt_t)
        noise = self.rngs["truth"].normal(0.0, GT_NOISE_M, body.shape)
        gt = (body + PRISM_OFFSET_M + noise) @ rot  # row form of rot.T @ p
        vel = np.gradient(track.positions, track.times_s, axis=0)
        speed = np.interp(gt_t, track.times_s, np.linalg.norm(vel, axis=1))
        lidar_ns = np.array(self.written_mid, dtype=np.int64)
        return WorldTruth(
            world=self.world,
            class_id=self.world.class_id,
            rotation=rot,
            prism_offset=PRISM_OFFSET_M @ rot,
            gt_stamps_ns=self.gt_ns.astype(np.int64),
            gt_positions=gt,
            body_positions=body @ rot,
            speeds_mps=speed,
            lidar_stamps_ns=lidar_ns,
            lidar_body_positions=track.at((lidar_ns - self.t0_ns) / 1e9) @ rot,
            mid360_drone_points=np.array(self.mid_counts, dtype=np.int64),
            mid360_drone_xyz=tuple(self.mid_xyz),
            avia_stamps_ns=self.avia_ns.astype(np.int64),
            avia_drone_points=np.array(self.avia_counts, dtype=np.int64),
            distractors=tuple(m.name for m in self.movers[1:]),
            merged_stamp_ns=int(self.mid_ns[self.lost + 1]) if self.lost >= 0 else None,
        )


def _world(world: int | World) -> World:
    return world if isinstance(world, World) else draw_world(int(world))


def as_cloud(stamp_ns: int, array: F64) -> Cloud:
    """The cloud a reader gets from one file's array: its non-zero rows as float32 (metres),
    dated by their rows (``row_times``)."""
    rows = np.flatnonzero(np.any(array != 0, axis=1))
    points = array.take(rows, axis=0).astype(np.float32, copy=False)
    times = row_times(rows, len(array))
    return Cloud(stamp_ns=int(stamp_ns), points=np.ascontiguousarray(points), times=times)


def simulate_world_frames(
    world: int | World, duration_s: float = 8.0, *, epoch_s: int = TRAIN_EPOCH_S
) -> tuple[list[LidarFrame], WorldTruth]:
    """Simulate a randomised world in memory: the paired LiDAR frames and the truth.

    The frames equal ``pair_frames(iter_clouds(seq, "lidar_360"), iter_clouds(seq,
    "livox_avia"))`` for the folder ``write_world_sequence`` writes for the same world.

    Args:
        world: a world seed (``draw_world(seed)``) or a World.
        duration_s: seconds (at least 1).
        epoch_s: Unix seconds near which the sequence starts.

    Returns:
        The frames (Mid-360 stamps, integer ns; points in the sensor frame, float32 metres) and
        the truth (sensor frame).
    """
    run = _WorldRun(_world(world), duration_s, epoch_s)
    mid = [as_cloud(s, a) for s, a in run.iter_mid360()]
    avia = [as_cloud(s, a) for s, a in run.iter_avia()]
    return list(pair_frames(mid, avia)), run.truth()


def write_world_sequence(
    seq_dir: Path,
    world: int | World,
    duration_s: float = 8.0,
    *,
    labels: bool = True,
    epoch_s: int = TRAIN_EPOCH_S,
    images: bool = True,
) -> WorldTruth:
    """Simulate a randomised world and write it as a challenge sequence folder.

    Args:
        seq_dir: the folder to create; must not exist or be empty.
        world: a world seed or a World.
        duration_s: seconds (at least 1).
        labels: write ``ground_truth/`` and ``class/`` (the train split).
        epoch_s: Unix seconds near which the sequence starts.
        images: write ``Image/`` (tiny PNGs at 30 Hz).

    Returns:
        The truth (sensor frame).

    Raises:
        ConfigError: bad duration.
        OutputExistsError: ``seq_dir`` exists and is not empty.
        CldetError: the folder cannot be written.
    """
    if seq_dir.exists() and (not seq_dir.is_dir() or any(seq_dir.iterdir())):
        raise OutputExistsError(f"{seq_dir} already exists and is not an empty folder")
    run = _WorldRun(_world(world), duration_s, epoch_s)
    try:
        folders = ["lidar_360", "livox_avia", "radar_enhance_pcl"]
        folders += ["Image"] if images else []
        folders += ["ground_truth", "class"] if labels else []
        for name in folders:
            (seq_dir / name).mkdir(parents=True, exist_ok=True)
        for stamp, points in run.iter_mid360():
            _save_npy(seq_dir / "lidar_360" / f"{format_stamp(stamp)}.npy", points)
        for stamp, points in run.iter_avia():
            _save_npy(seq_dir / "livox_avia" / f"{format_stamp(stamp)}.npy", points)
        radar = radar_frames(run.rngs["radar"], len(run.radar_ns))
        for stamp, frame in zip(run.radar_ns, radar, strict=True):
            _save_npy(seq_dir / "radar_enhance_pcl" / f"{format_stamp(int(stamp))}.npy", frame)
        if images:
            for stamp in run.image_ns:
                png = camera_image(run.rngs["images"], run.rel_s(stamp))
                (seq_dir / "Image" / f"{format_stamp(int(stamp))}.png").write_bytes(png)
        truth = run.truth()
        if labels:
            cls = np.array([truth.class_id], dtype=np.int64)
            for stamp, pos in zip(truth.gt_stamps_ns, truth.gt_positions, strict=True):
                name = f"{format_stamp(int(stamp))}.npy"
                _save_npy(seq_dir / "ground_truth" / name, pos.astype(np.float64))
                _save_npy(seq_dir / "class" / name, cls)
    except OSError as err:
        raise CldetError(f"cannot write the simulated sequence {seq_dir}: {err}") from err
    return truth
