"""Write simulated sequences and whole datasets in exactly the challenge's folder layout.

One sequence folder holds ``lidar_360/``, ``livox_avia/``, ``radar_enhance_pcl/`` (``<stamp>.npy``),
``Image/`` (``<stamp>.png``) and, with labels, ``ground_truth/`` and ``class/``. A dataset holds
``train/``, ``val/``, ``test/`` plus ``test_timestamps.csv`` (the query rows), ``test_truth.csv``
and ``val_truth.csv``. Everything is a pure function of the seed: the same seed gives the same bytes.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from cldet.errors import CldetError, ConfigError, OutputExistsError
from cldet.progress import NullProgress, Progress
from cldet.simulate.flight import (
    DRONE_TYPES,
    SCENARIOS,
    Mover,
    drone_mover,
    plan_bird,
    plan_drone,
    plan_person,
)
from cldet.simulate.scene import BUILDING, Scene, build_scene
from cldet.simulate.sensors import (
    MID360_ROW_CYCLE,
    avia_clutter_states,
    avia_frame,
    camera_image,
    mid360_frame,
    radar_frames,
)
from cldet.simulate.world import World, draw_world, sensor_rotation
from cldet.stamps import format_stamp

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

PRISM_OFFSET_M = np.array([0.0, 0.0, 0.15])  # ground truth = body centre + this + 5 mm noise
GT_NOISE_M = 0.005
MID360_PERIOD_NS = 100_000_000
RADAR_PERIOD_NS = 1_000_000_000 // 15
IMAGE_PERIOD_NS = 1_000_000_000 // 30
GT_PERIOD_NS = 50_000_000
GT_LEAD_NS = 35_000_000  # ground truth starts this long before the first LiDAR frame
TRAIN_EPOCH_S = 1706255000
TEST_EPOCH_S = 1713163000
SPLITS: tuple[str, ...] = ("train", "val", "test")

# preset -> split -> (number of sequences, seconds each)
PRESETS: dict[str, dict[str, tuple[int, float]]] = {
    "tiny": {"train": (1, 3.0), "val": (1, 2.0), "test": (1, 2.0)},  # for tests
    "small": {"train": (2, 8.0), "val": (1, 5.0), "test": (2, 5.0)},
    "full": {"train": (6, 20.0), "val": (4, 5.0), "test": (12, 5.0)},
}


@dataclass(frozen=True)
class SequenceTruth:
    """What really happened in one simulated sequence (times in integer ns, positions in metres).

    A LiDAR frame stamped ``s`` fires its rays over ``[s, s + 100 ms)``; ``drone_positions`` are
    the drone's body centre at the stamp itself.
    """

    scenario: str
    class_id: int  # 0..3, index into DRONE_TYPES
    gt_stamps_ns: (
        I64  # (K,) ground-truth stamps (20 Hz, first one 35 ms before the first LiDAR frame)
    )
    gt_positions: F64  # (K, 3) body centre + prism offset (0, 0, 0.15) + 5 mm noise
    lidar_stamps_ns: I64  # (N,) stamps of the Mid-360 files written (a merged frame counts once)
    drone_positions: F64  # (N, 3) body centre at the Mid-360 stamps
    mid360_drone_points: I64  # (N,) Mid-360 points on the drone per file
    mid360_drone_centroids: F64  # (N, 3) mean of those points (NaN when none): the near-face bias
    mid360_distractor_points: I64  # (N,) Mid-360 points on people and birds per file
    avia_stamps_ns: I64  # (M,) stamps of the Avia files
    avia_drone_points: I64  # (M,) Avia points on the drone per file
    distractors: tuple[str, ...]  # movers other than the drone ("person", "bird")
    merged_stamp_ns: int | None  # stamp of the 40032-row Mid-360 file, None when no frame was lost
    hover_anchor: F64 | None  # (3,) top of the car / lamp post hovered over ("hover"), else None


@dataclass(frozen=True)
class SimulationSummary:
    """What ``simulate_dataset`` wrote."""

    out: Path
    sequences: tuple[tuple[str, int], ...]  # (split, number of sequences)
    lidar_frames: int  # Mid-360 files over all splits
    seconds: float  # wall-clock time taken

    def describe(self) -> str:
        """One line for humans: where, how many sequences per split, frames, time."""
        per_split = ", ".join(f"{split} {n}" for split, n in self.sequences)
        total = sum(n for _, n in self.sequences)
        return (
            f"wrote {total} sequences ({per_split}), {self.lidar_frames} Mid-360 frames "
            f"to {self.out} in {self.seconds:.1f} s"
        )


def _save_npy(path: Path, array: NDArray[np.generic]) -> None:
    with path.open("wb") as fh:
        np.save(fh, array, allow_pickle=False)


def _us_grid(
    start_ns: int, period_ns: int, n: int, jitter_us: float, rng: np.random.Generator
) -> I64:
    """``n`` stamps ``start + k * period`` plus uniform jitter, rounded to whole microseconds."""
    base = start_ns + period_ns * np.arange(n, dtype=np.int64)
    jitter = np.round(rng.uniform(-jitter_us, jitter_us, n)).astype(np.int64) * 1000
    stamps = (base // 1000) * 1000 + jitter
    return stamps.astype(np.int64)


def simulate_sequence(
    seq_dir: Path,
    *,
    seed: int | Sequence[int],
    duration_s: float,
    scenario: str = "mixed",
    labels: bool = True,
    epoch_s: int = TRAIN_EPOCH_S,
    images: bool = True,
    class_id: int | None = None,
    merged_frame: bool | None = None,
    tilt_deg: float = 0.0,
    mount_offset_m: float = 0.0,
    overhang_elevation_deg: float | None = None,
) -> SequenceTruth:
    """Simulate one sequence and write it as a challenge sequence folder.

    The seed draws the site (ground, buildings, vegetation), the drone's class and flight, the
    distractors and all sensor noise; the same seed writes the same bytes.

    Args:
        seq_dir: the folder to create (e.g. ``.../train/seq0001``); must not exist or be empty.
        seed: an int or a sequence of ints for ``numpy.random.default_rng``.
        duration_s: length in seconds (at least 1).
        scenario: one of ``SCENARIOS``: "mixed" (varied flight), "close_pass" (passes 2-4 m from the
            sensor), "hover" (long hover ~1 m above a parked car or lamp post), "avia_only" (high,
            inside the Avia cone only), "person" (a person walking near the drone), "bird" (a bird
            crossing). Other distractors may appear in any scenario.
        labels: write ``ground_truth/`` and ``class/`` (the train split); truth is returned anyway.
        epoch_s: Unix seconds near which the sequence starts (0-60 s later).
        images: write ``Image/`` (tiny 64x24 PNGs at 30 Hz).
        class_id: force the drone class 0..3 (default: drawn from the seed).
        merged_frame: lose one Mid-360 frame and merge it into the next (40032 rows); default:
            drawn from the seed (30%).
        tilt_deg: probe: tilt the sensor (both LiDARs, rigidly) by this angle about a horizontal
            axis drawn from the seed; points and truth are written in the tilted sensor frame.
        mount_offset_m: probe: mount the sensor this much higher above the same world.
        overhang_elevation_deg: probe: add a static 0.3 m box 3-6 m from the sensor at this
            elevation (azimuth drawn from the seed), e.g. 67 (a sign overhanging the sensor).
            The probes draw from their own stream: with the defaults nothing changes, byte for
            byte, and a probe leaves the rest of the sequence's draws as they were.

    Returns:
        The sequence's truth.

    Raises:
        ConfigError: unknown scenario, bad duration or class.
        OutputExistsError: ``seq_dir`` exists and is not empty.
        CldetError: the folder cannot be written.
    """
    if scenario not in SCENARIOS:
        raise ConfigError(f"unknown scenario {scenario!r}: expected one of {', '.join(SCENARIOS)}")
    if not duration_s >= 1.0:
        raise ConfigError(f"duration_s must be at least 1 s, got {duration_s}")
    if class_id is not None and not 0 <= class_id < len(DRONE_TYPES):
        raise ConfigError(f"class_id must be 0..{len(DRONE_TYPES) - 1}, got {class_id}")
    if seq_dir.exists() and (not seq_dir.is_dir() or any(seq_dir.iterdir())):
        raise OutputExistsError(f"{seq_dir} already exists and is not an empty folder")
    try:
        return _simulate_sequence(
            seq_dir,
            np.random.default_rng(seed),
            duration_s,
            scenario,
            labels,
            epoch_s,
            images,
            class_id,
            merged_frame,
            _Probe(tilt_deg, mount_offset_m, overhang_elevation_deg, seed),
        )
    except OSError as err:
        raise CldetError(f"cannot write the simulated sequence {seq_dir}: {err}") from err


def _to_sensor(p: F64, rotation: F64 | None) -> F64:
    """Level-frame points (..., 3) in the tilted sensor frame (unchanged without a rotation)."""
    return p if rotation is None else np.asarray(p @ rotation, dtype=np.float64)


@dataclass(frozen=True)
class _Probe:
    """Optional perturbations of one sequence (the review's probes); defaults change nothing."""

    tilt_deg: float
    mount_offset_m: float
    overhang_elevation_deg: float | None
    seed: int | Sequence[int]

    def active(self) -> bool:
        return bool(self.tilt_deg or self.mount_offset_m or self.overhang_elevation_deg is not None)

    def apply(
        self, scene: Scene, movers: list[Mover], anchor: F64 | None
    ) -> tuple[Scene, list[Mover], F64 | None, F64 | None]:
        """The perturbed scene, movers and anchor (level frame), and the sensor's rotation."""
        # a stream of its own, so that a probe leaves every other draw of the sequence as it was
        rng = np.random.default_rng([*np.atleast_1d(np.asarray(self.seed, dtype=np.int64)), 7919])
        tilt_azimuth = float(rng.uniform(-180.0, 180.0))
        overhang_az = float(rng.uniform(-np.pi, np.pi))
        overhang_r = float(rng.uniform(3.0, 6.0))
        if self.mount_offset_m:
            dz = np.array([0.0, 0.0, self.mount_offset_m])
            scene = replace(
                scene,
                ground_base_m=scene.ground_base_m - self.mount_offset_m,
                box_lower=scene.box_lower - dz,
                box_upper=scene.box_upper - dz,
                cylinders=scene.cylinders - np.array([0.0, 0.0, 0.0, dz[2], dz[2]]),
                sphere_centres=scene.sphere_centres - dz,
            )
            movers = [
                replace(m, track=replace(m.track, positions=m.track.positions - dz)) for m in movers
            ]
            anchor = None if anchor is None else anchor - dz
        if self.overhang_elevation_deg is not None:
            el = np.radians(self.overhang_elevation_deg)
            c = overhang_r * np.array(
                [np.cos(el) * np.cos(overhang_az), np.cos(el) * np.sin(overhang_az), np.sin(el)]
            )
            scene = replace(
                scene,
                box_lower=np.vstack([scene.box_lower, c - 0.15]),
                box_upper=np.vstack([scene.box_upper, c + 0.15]),
                box_kind=np.append(scene.box_kind, BUILDING).astype(np.intp),
            )
        rotation = sensor_rotation(self.tilt_deg, tilt_azimuth) if self.tilt_deg else None
        return scene, movers, anchor, rotation


def _simulate_sequence(
    seq_dir: Path,
    rng: np.random.Generator,
    duration_s: float,
    scenario: str,
    labels: bool,
    epoch_s: int,
    images: bool,
    class_id: int | None,
    merged_frame: bool | None,
    probe: _Probe | None = None,
) -> SequenceTruth:
    # --- what happens: site, drone, distractors -------------------------------------------
    t0_ns = int(epoch_s) * 1_000_000_000 + int(rng.integers(0, 60_000_000)) * 1000
    cls = int(rng.integers(len(DRONE_TYPES))) if class_id is None else int(class_id)
    scene = build_scene(rng)
    track, anchor = plan_drone(rng, scenario, duration_s, scene)
    movers: list[Mover] = [drone_mover(track, DRONE_TYPES[cls])]
    start_xyz = track.at(np.array([0.0]))[0]
    n_people = int(rng.integers(1, 3)) if scenario == "person" else int(rng.random() < 0.35)
    for i in range(n_people):
        near = start_xyz if scenario == "person" and i == 0 else None
        movers.append(plan_person(rng, duration_s, scene, near))
    n_birds = int(rng.integers(1, 3)) if scenario == "bird" else int(rng.random() < 0.3)
    for _ in range(n_birds):
        movers.append(plan_bird(rng, duration_s, scene))
    merged = bool(rng.random() < 0.3) if merged_frame is None else merged_frame
    rotation: F64 | None = None
    if probe is not None and probe.active():
        scene, movers, anchor, rotation = probe.apply(scene, movers, anchor)
        track = movers[0].track

    # --- clocks ---------------------------------------------------------------------------
    n_lidar = max(int(round(duration_s * 10)), 3)
    mid_ns = _us_grid(t0_ns, MID360_PERIOD_NS, n_lidar, 100.0, rng)
    # the Avia lags by 14 ms, or 13 ms in about a third of the frames (as in the real sample)
    avia_lag_us = 14_000 - 1000 * (rng.random(n_lidar) < 0.34) + rng.normal(0.0, 70.0, n_lidar)
    avia_ns = mid_ns + np.round(avia_lag_us).astype(np.int64) * 1000
    radar_start = t0_ns + int(rng.integers(0, RADAR_PERIOD_NS // 1000)) * 1000
    n_radar = int(round(duration_s * 15))
    radar_ns = _us_grid(radar_start, RADAR_PERIOD_NS, n_radar, 300.0, rng)
    image_start = t0_ns + int(rng.integers(0, IMAGE_PERIOD_NS // 1000)) * 1000
    n_image = int(round(duration_s * 30))
    image_ns = _us_grid(image_start, IMAGE_PERIOD_NS, n_image, 500.0, rng)
    n_gt = int(round(duration_s * 20))
    gt_ns = _us_grid(t0_ns - GT_LEAD_NS, GT_PERIOD_NS, n_gt, 500.0, rng)
    gt_ns[0] = min(int(gt_ns[0]), int(mid_ns[0]) - 30_000_000)
    row_phase = int(rng.integers(len(MID360_ROW_CYCLE)))
    rows = [MID360_ROW_CYCLE[(k + row_phase) % 3] for k in range(n_lidar)]
    lost = -1
    if merged:
        # lose a 20064-row frame in the middle; its rows go into the next file (40032 rows)
        choices = [k for k in range(1, n_lidar - 1) if rows[k] == MID360_ROW_CYCLE[0]]
        if choices:
            lost = int(choices[int(rng.integers(len(choices)))])

    def rel_s(stamp_ns: int | np.int64) -> float:
        return (int(stamp_ns) - t0_ns) / 1e9

    # --- write ----------------------------------------------------------------------------
    folders = ["lidar_360", "livox_avia", "radar_enhance_pcl"]
    if images:
        folders.append("Image")
    if labels:
        folders += ["ground_truth", "class"]
    for name in folders:
        (seq_dir / name).mkdir(parents=True, exist_ok=True)

    written_mid: list[int] = []
    mid_points: list[int] = []
    pending: NDArray[np.float64] | None = None
    pending_points = 0
    pending_sum = np.zeros(3)
    mid_sums: list[F64] = []
    mid_others: list[int] = []
    pending_others = 0
    for k in range(n_lidar):
        frame = mid360_frame(rng, rows[k], rel_s(mid_ns[k]), scene, movers, rotation)
        if k == lost:
            pending, pending_points, pending_sum = frame.points, frame.drone_points, frame.drone_sum
            pending_others = frame.distractor_points
            continue
        points = frame.points
        n_drone = frame.drone_points
        drone_sum = frame.drone_sum
        others = frame.distractor_points
        if pending is not None:
            points = np.concatenate([pending, points])
            n_drone += pending_points
            drone_sum = drone_sum + pending_sum
            others += pending_others
            pending = None
        _save_npy(seq_dir / "lidar_360" / f"{format_stamp(int(mid_ns[k]))}.npy", points)
        written_mid.append(int(mid_ns[k]))
        mid_points.append(n_drone)
        mid_sums.append(drone_sum)
        mid_others.append(others)

    clutter = avia_clutter_states(rng, n_lidar)
    avia_points: list[int] = []
    for k in range(n_lidar):
        frame = avia_frame(rng, rel_s(avia_ns[k]), scene, movers, bool(clutter[k]), rotation)
        _save_npy(seq_dir / "livox_avia" / f"{format_stamp(int(avia_ns[k]))}.npy", frame.points)
        avia_points.append(frame.drone_points)

    for stamp, radar in zip(radar_ns, radar_frames(rng, n_radar), strict=True):
        _save_npy(seq_dir / "radar_enhance_pcl" / f"{format_stamp(int(stamp))}.npy", radar)

    if images:
        for stamp in image_ns:
            png = camera_image(rng, rel_s(stamp))
            (seq_dir / "Image" / f"{format_stamp(int(stamp))}.png").write_bytes(png)

    gt_t = (gt_ns - t0_ns) / 1e9
    gt_pos = track.at(gt_t) + PRISM_OFFSET_M + rng.normal(0.0, GT_NOISE_M, (n_gt, 3))
    if rotation is not None:  # into the tilted sensor frame (row form of rotation.T @ p)
        gt_pos = gt_pos @ rotation
    if labels:
        cls_array = np.array([cls], dtype=np.int64)
        for stamp, pos in zip(gt_ns, gt_pos, strict=True):
            name = f"{format_stamp(int(stamp))}.npy"
            _save_npy(seq_dir / "ground_truth" / name, pos.astype(np.float64))
            _save_npy(seq_dir / "class" / name, cls_array)

    lidar_ns = np.array(written_mid, dtype=np.int64)
    counts = np.array(mid_points, dtype=np.int64)
    with np.errstate(invalid="ignore", divide="ignore"):
        centroids = np.array(mid_sums).reshape(-1, 3) / counts[:, None]
    centroids[counts == 0] = np.nan
    return SequenceTruth(
        scenario=scenario,
        class_id=cls,
        gt_stamps_ns=gt_ns.astype(np.int64),
        gt_positions=gt_pos,
        lidar_stamps_ns=lidar_ns,
        drone_positions=_to_sensor(track.at((lidar_ns - t0_ns) / 1e9), rotation),
        mid360_drone_points=counts,
        mid360_drone_centroids=centroids,
        mid360_distractor_points=np.array(mid_others, dtype=np.int64),
        avia_stamps_ns=avia_ns.astype(np.int64),
        avia_drone_points=np.array(avia_points, dtype=np.int64),
        distractors=tuple(m.name for m in movers[1:]),
        merged_stamp_ns=int(mid_ns[lost + 1]) if lost >= 0 else None,
        hover_anchor=None if anchor is None else _to_sensor(anchor, rotation),
    )


class _Truth(Protocol):
    """What the dataset writer needs of a sequence's truth (SequenceTruth, WorldTruth)."""

    @property
    def class_id(self) -> int: ...
    @property
    def gt_stamps_ns(self) -> I64: ...
    @property
    def gt_positions(self) -> F64: ...
    @property
    def lidar_stamps_ns(self) -> I64: ...


def _truth_rows(seq_name: str, truth: _Truth) -> list[str]:
    return [
        f"{seq_name},{format_stamp(int(s))},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f},{truth.class_id}"
        for s, p in zip(truth.gt_stamps_ns, truth.gt_positions, strict=True)
    ]


def simulate_dataset(
    out: Path,
    *,
    preset: str = "small",
    seed: int = 0,
    overwrite: bool = False,
    progress: Progress | None = None,
    randomize: bool = False,
) -> SimulationSummary:
    """Generate a synthetic dataset in the challenge layout, with the truth as CSVs.

    The dataset is built in ``OUT.partial-<pid>`` next to ``out`` and renamed into place at the
    end, so a crash never leaves a half-written ``out``. Sequence ``i`` of split ``j`` uses the
    generator seeded with ``[seed, j, i]``, and scenarios cycle through ``SCENARIOS``.

    With ``randomize``, every sequence is a randomised world instead (``draw_world``: site,
    sensor tilt and height, sloped ground, scenario kind, distractors; points and truth in the
    tilted sensor frame): the k-th sequence written (train, then val, then test) is world
    ``seed + k``, and ``worlds.csv`` lists each sequence's world.

    Args:
        out: the folder to create.
        preset: "tiny" (1 sequence of 2-3 s per split, for tests), "small" (train 2 x 8 s, val 1 x 5 s, test 2 x 5 s) or "full" (train 6 x 20 s,
            val 4 x 5 s, test 12 x 5 s).
        seed: the dataset seed; the same seed gives the same bytes.
        overwrite: replace ``out`` if it exists.
        progress: receives one unit per sequence.
        randomize: randomised worlds (see above) instead of the car-park scenarios.

    Returns:
        A summary of what was written.

    Raises:
        ConfigError: unknown preset or negative seed.
        OutputExistsError: ``out`` exists and ``overwrite`` is false.
        CldetError: the dataset cannot be written.
    """
    from cldet.simulate.randomized import write_world_sequence  # it imports this module

    if preset not in PRESETS:
        raise ConfigError(f"unknown preset {preset!r}: expected one of {', '.join(PRESETS)}")
    if seed < 0:
        raise ConfigError(f"seed must be non-negative, got {seed}")
    out = Path(out)
    if out.exists() and not overwrite:
        raise OutputExistsError(f"{out} already exists (use overwrite to replace it)")
    bar: Progress = progress if progress is not None else NullProgress()
    plan = PRESETS[preset]
    started = time.perf_counter()
    partial = out.parent / f"{out.name}.partial-{os.getpid()}"
    try:
        if partial.exists():
            shutil.rmtree(partial)
        partial.mkdir(parents=True)
        bar.start(sum(n for n, _ in plan.values()), f"simulating {preset} dataset")
        frames = 0
        world_rows: list[str] = []
        for j, split in enumerate(SPLITS):
            n_seq, duration = plan[split]
            epoch = TEST_EPOCH_S if split == "test" else TRAIN_EPOCH_S
            truth_rows: list[str] = []
            query_rows: list[str] = []
            for i in range(n_seq):
                name = f"seq{i + 1:04d}"
                truth: _Truth
                if randomize:
                    world = draw_world(seed + len(world_rows))
                    truth = write_world_sequence(
                        partial / split / name,
                        world,
                        duration,
                        labels=split == "train",
                        epoch_s=epoch + 120 * i,
                    )
                    world_rows.append(
                        f"{split},{name}," + ",".join(str(v) for v in dataclasses.astuple(world))
                    )
                else:
                    truth = simulate_sequence(
                        partial / split / name,
                        seed=(seed, j, i),
                        duration_s=duration,
                        scenario=SCENARIOS[(i + 2 * j) % len(SCENARIOS)],
                        labels=split == "train",
                        epoch_s=epoch + 120 * i,
                        merged_frame=True if i == 0 else None,
                    )
                frames += len(truth.lidar_stamps_ns)
                truth_rows += _truth_rows(name, truth)
                query_rows += [f"{name},{format_stamp(int(s))},," for s in truth.gt_stamps_ns]
                bar.advance(1)
            header = "Sequence,Timestamp,x,y,z,class\n"
            if split == "test":
                (partial / "test_timestamps.csv").write_text(
                    "Sequence,Timestamp,Position,Classification\n"
                    + "".join(r + "\n" for r in query_rows)
                )
                (partial / "test_truth.csv").write_text(
                    header + "".join(r + "\n" for r in truth_rows)
                )
            elif split == "val":
                (partial / "val_truth.csv").write_text(
                    header + "".join(r + "\n" for r in truth_rows)
                )
        if randomize:
            names = ",".join(f.name for f in dataclasses.fields(World))
            (partial / "worlds.csv").write_text(
                f"split,sequence,{names}\n" + "".join(r + "\n" for r in world_rows)
            )
        if out.exists():
            if out.is_dir():
                shutil.rmtree(out)
            else:
                out.unlink()
        partial.rename(out)
    except OSError as err:
        shutil.rmtree(partial, ignore_errors=True)
        raise CldetError(f"cannot write the simulated dataset {out}: {err}") from err
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    return SimulationSummary(
        out=out,
        sequences=tuple((split, plan[split][0]) for split in SPLITS),
        lidar_frames=frames,
        seconds=time.perf_counter() - started,
    )
