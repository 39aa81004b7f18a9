"""Track-before-detect for sparse fast movers (cldet.core.lines): each rule on a scene that needs it."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from cldet.config import load_config
from cldet.core.lines import find_lines
from cldet.core.methods import estimate_sequence
from cldet.core.tracking import ClusterTable, TrackRecord
from cldet.types import LidarFrame, Source
from tests.core.scene import Sphere, scan

PERIOD_S = 0.1
N_FRAMES = 80


def _tables(points_per_frame: list[NDArray[np.float64]]) -> list[ClusterTable]:
    """One single-point Mid-360 cluster per point."""
    tables = []
    for pts in points_per_frame:
        k = len(pts)
        ones, zeros = np.ones(k, dtype=np.int64), np.zeros(k, dtype=np.int64)
        tables.append(
            ClusterTable(
                np.asarray(pts, dtype=np.float64).reshape(k, 3), np.zeros(k), ones, ones, zeros
            )
        )
    return tables


def _lines(points_per_frame: list[NDArray[np.float64]], **overrides: object) -> list[TrackRecord]:
    cfg = load_config(overrides={"tracking": overrides}).tracking
    times = np.arange(len(points_per_frame), dtype=np.float64) * PERIOD_S
    return find_lines(_tables(points_per_frame), times, cfg, first_id=0)


def _pass(t: NDArray[np.float64]) -> NDArray[np.float64]:
    """A straight pass at 15 m/s, 25 m out at its closest, 10 m up."""
    return np.array([25.0, -60.0, 10.0]) + np.outer(t, [0.0, 15.0, 0.0])


def _far_speckle(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    """Lone far returns (rain, dust) in random directions of the Mid-360's band, 20-80 m."""
    az = rng.uniform(-np.pi, np.pi, n)
    el = np.radians(rng.uniform(-7.0, 52.0, n))
    r = rng.uniform(20.0, 80.0, n)
    return (
        np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]) * r[:, None]
    )


def _sparse_pass_frames(
    seed: int,
    seen: float = 0.2,
    until: int = N_FRAMES,
    walker_from: int | None = None,
    n_rays: int = 3000,
) -> tuple[list[LidarFrame], NDArray[np.float64]]:
    """The scan of the test scene with lone far speckle every scan and, in about ``seen`` of
    the scans before ``until``, one Mid-360 return from the pass (a far small drone); and the
    pass at the stamps. From scan ``walker_from`` on, a person walks 1 m/s 6 m away, its
    lowest return 1.3 m above the ground (a detection there weighs about a third of one from
    the air)."""
    rng = np.random.default_rng(seed)
    stamps = np.arange(N_FRAMES, dtype=np.float64) * PERIOD_S
    frames = []
    empty = np.zeros((0, 3), np.float32)
    for k, t in enumerate(stamps):
        walker: list[Sphere] = []
        if walker_from is not None and k >= walker_from:
            walker = [((6.0, -4.0 + 1.0 * t, 0.15), 0.35)]
        cloud = [scan(rng, walker, n_rays=n_rays), _far_speckle(rng, 4).astype(np.float32)]
        if k < until and rng.random() < seen:
            # taken somewhere inside the 100 ms scan that starts at the stamp
            cloud.append(
                _pass(np.array([t + rng.uniform(0.0, 0.1)], dtype=np.float64)).astype(np.float32)
            )
        frames.append(LidarFrame(int(round(t * 1e9)), np.concatenate(cloud), empty))
    return frames, _pass(stamps)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_sparse_fast_pass_is_followed_only_with_the_line_search(seed: int) -> None:
    # the Kalman tracker never links two sightings (the drone moves 3-9 m between them), the
    # line search does
    frames, truth = _sparse_pass_frames(seed)

    def rms(line_search: bool) -> float:
        # the straight transit's hold off: it can carry a short Kalman track along the pass and
        # hide what the line search alone brings
        cfg = load_config(
            overrides={
                "tracking": {"line_search": line_search},
                "smoothing": {"straight_rms_m": 0.0},
            }
        )
        _, result = estimate_sequence(frames, cfg)
        est = np.array([e.position for e in result.estimates])
        return float(np.sqrt(np.mean(np.sum((est - truth) ** 2, axis=1))))

    assert rms(True) < 0.6
    assert rms(False) > 1.5


def test_a_line_collects_only_the_movers_sightings() -> None:
    rng = np.random.default_rng(7)
    times = np.arange(N_FRAMES, dtype=np.float64) * PERIOD_S
    seen = rng.random(N_FRAMES) < 0.3
    frames = [
        np.concatenate(
            [_far_speckle(rng, 4), _pass(times[k : k + 1]) if seen[k] else np.zeros((0, 3))]
        )
        for k in range(N_FRAMES)
    ]
    lines = _lines(frames)
    assert len(lines) == 1
    line = lines[0]
    assert np.all(seen[line.frames])
    assert len(line.frames) >= 0.8 * seen.sum()
    np.testing.assert_allclose(line.positions, _pass(times[line.frames]), atol=1e-9)
    assert line.speed[0] == pytest.approx(15.0, abs=0.1)


def test_a_fast_pass_seen_in_bursts_of_consecutive_scans_is_a_line() -> None:
    # 22 m/s, seen in three bursts of consecutive scans (5 sightings in all): the scan's smear
    # widens the line's tolerance, but consecutive sightings 2.2 m apart are distinct places
    # of the pass, not one place seen twice (a place is the centroid's noise, line_tol_m)
    times = np.arange(N_FRAMES, dtype=np.float64) * PERIOD_S
    path = np.array([25.0, -60.0, 10.0]) + np.outer(times, [0.0, 22.0, 0.0])
    seen = {10, 11, 18, 19, 27}
    frames = [path[k : k + 1] if k in seen else np.zeros((0, 3)) for k in range(N_FRAMES)]
    lines = _lines(frames)
    assert len(lines) == 1
    assert set(lines[0].frames.tolist()) == seen


def test_lone_returns_along_one_beam_make_no_line() -> None:
    # noise along three fixed beams at random ranges: a line running along a beam meets it by
    # chance; the line must sweep line_min_sweep_deg as seen from the sensor
    rng = np.random.default_rng(3)
    beams = _far_speckle(rng, 3)
    beams /= np.linalg.norm(beams, axis=1)[:, None]
    frames = [beams * rng.uniform(20.0, 60.0, (3, 1)) for _ in range(N_FRAMES)]
    assert _lines(frames, line_min_sweep_deg=0.0)  # the rule is needed here
    assert _lines(frames) == []


def test_crowded_returns_make_no_line() -> None:
    # 25 lone returns a scan in an 8 x 8 x 4 m box 15 m away (rain or spray near the sensor):
    # any line through them meets some by chance; a line's clusters must be isolated
    rng = np.random.default_rng(4)
    frames = [
        np.array([15.0, -4.0, 0.0]) + rng.uniform(0.0, 1.0, (25, 3)) * [8.0, 8.0, 4.0]
        for _ in range(N_FRAMES)
    ]
    assert _lines(frames, line_isolation_m=0.01)  # the rule is needed here
    assert _lines(frames) == []


def test_static_things_and_slow_movers_make_no_line() -> None:
    # two static things 4 m apart: a line hopping between them would meet each for several
    # scans, but at one place; a walker at 1 m/s is the Kalman tracker's, not a line
    times = np.arange(N_FRAMES, dtype=np.float64) * PERIOD_S
    static = np.array([[20.0, 0.0, 5.0], [20.0, 4.0, 5.0]])
    assert _lines([static for _ in times]) == []
    walker = np.array([10.0, 0.0, 0.0]) + np.outer(times, [0.0, 1.0, 0.0])
    assert _lines([walker[k : k + 1] for k in range(N_FRAMES)]) == []
    assert _lines([walker[k : k + 1] for k in range(N_FRAMES)], line_min_speed=0.5)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_causal_estimate_follows_a_sparse_fast_pass_with_the_line_search(seed: int) -> None:
    # the same pass, estimated frame by frame: without a track to follow, the causal line
    # search over the last 3 s finds it once its sightings there are evidence enough, and the
    # estimate goes on along the line; without the search it reports the pass later (where two
    # sightings happened to fall within the tracker's gate) or never
    frames, truth = _sparse_pass_frames(seed)

    def reported(every_s: float) -> NDArray[np.float64]:
        cfg = load_config(overrides={"tracking": {"causal_line_every_s": every_s}})
        _, result = estimate_sequence(frames, cfg)
        return np.array(
            [
                float(np.linalg.norm(e.position - truth[k]))
                for k, e in enumerate(result.causal)
                if e.source != Source.FALLBACK
            ]
        )

    found = reported(0.5)
    assert len(found) >= 10
    assert float(np.sqrt(np.mean(found**2))) < 1.0
    assert len(reported(0.0)) < len(found)  # the search is needed here


@pytest.mark.parametrize("seed", [0, 1, 5])
def test_a_line_followed_causally_keeps_its_evidence_against_weak_newcomers(seed: int) -> None:
    # the causal estimate follows the pass along the line search's line for 6 s; once the pass
    # is out of reach, a walker's own evidence reaches causal_confirm after about a second,
    # but not the line's: the estimate carries on along the line (held, then slowing), as it
    # would after a lost track (causal_keep_lost); without that the walker takes over, tens of
    # metres off. On seeds 0-7 the largest error with the rule is under 1 m; before the line
    # kept its evidence, seeds 0 and 5 failed (the others were held by a lost Kalman track)
    frames, truth = _sparse_pass_frames(seed, seen=0.6, until=60, walker_from=60, n_rays=8000)

    def errors(keep_lost: bool) -> NDArray[np.float64]:
        cfg = load_config(overrides={"tracking": {"causal_keep_lost": keep_lost}})
        _, result = estimate_sequence(frames, cfg)
        return np.array(
            [float(np.linalg.norm(e.position - truth[k])) for k, e in enumerate(result.causal)]
        )

    kept = errors(True)
    assert np.all(kept[60:] < 5.0)
    assert np.median(errors(False)[74:]) > 20.0  # the rule is needed here
