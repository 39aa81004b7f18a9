"""Tests of the static background model on small ray-cast scenes."""

from __future__ import annotations

import numpy as np
import pytest

from cldet.config import BackgroundConfig
from cldet.core.background import CORE, FOREGROUND, BackgroundModel, _floating_blobs
from tests.core.scene import GROUND_Z, Sphere, points_near, scan

NS = 100_000_000  # 10 Hz


POST = ((5.8, -4.2, GROUND_Z), (6.2, -3.8, 1.0))  # a post standing on the ground


def _learn(frames: list[list[Sphere]], seed: int = 0, **cfg: float) -> BackgroundModel:
    rng = np.random.default_rng(seed)
    model = BackgroundModel(BackgroundConfig(**cfg))
    for k, spheres in enumerate(frames):
        model.observe(k * NS, scan(rng, spheres, boxes=[POST]))
    return model


def test_static_scene_is_background_and_a_newcomer_is_not() -> None:
    model = _learn([[]] * 60)
    rng = np.random.default_rng(99)
    newcomer: Sphere = ((5.0, 2.0, 2.0), 0.3)
    pts = scan(rng, [newcomer], n_rays=16000, boxes=[POST])
    labels = model.classify(pts)
    on_new = points_near(pts, newcomer[0], 0.35)
    assert on_new.sum() >= 5
    assert np.all(labels[on_new] == FOREGROUND)
    assert np.mean(labels[~on_new] != FOREGROUND) > 0.995
    assert model.n_bins == 6
    assert model.ground_z() == pytest.approx(GROUND_Z, abs=0.1)


def test_object_hovering_for_half_the_sequence_is_not_background() -> None:
    hover: Sphere = ((6.0, -3.0, 2.0), 0.3)
    frames = [[hover]] * 30 + [[]] * 30
    model = _learn(frames)
    pts = scan(np.random.default_rng(5), [hover], n_rays=16000, boxes=[POST])
    on = points_near(pts, hover[0], 0.35)
    assert on.sum() >= 5
    assert np.all(model.classify(pts)[on] == FOREGROUND)


def test_object_present_in_every_bin_is_background() -> None:
    # a sphere resting on the wall (not floating) is environment even though small
    box: Sphere = ((11.8, 0.0, 4.2), 0.25)
    model = _learn([[box]] * 60)
    pts = scan(np.random.default_rng(5), [box], n_rays=16000, boxes=[POST])
    on = points_near(pts, box[0], 0.3)
    assert on.sum() >= 2
    assert np.all(model.classify(pts)[on] != FOREGROUND)


def test_small_blob_floating_in_free_space_all_along_is_not_background() -> None:
    # a drone hovering through the whole sequence, nothing static around it
    drone: Sphere = ((5.0, 3.0, 2.5), 0.25)
    model = _learn([[drone]] * 60)
    assert model.floating_cells > 0
    pts = scan(np.random.default_rng(5), [drone], n_rays=16000, boxes=[POST])
    on = points_near(pts, drone[0], 0.3)
    assert on.sum() >= 3
    assert np.all(model.classify(pts)[on] == FOREGROUND)
    # with the rule switched off it is learned as background
    off = _learn([[drone]] * 60, floating_max_size_m=0.0)
    assert np.all(off.classify(pts)[on] != FOREGROUND)


def _fly_in_then_hover(spot: Sphere, n_fly: int, n_hover: int) -> list[list[Sphere]]:
    """A drone flying from 5 m away to ``spot`` in ``n_fly`` frames, then hovering there."""
    start = np.asarray(spot[0]) + np.array([-4.0, -3.0, 0.5])
    path = [start + (np.asarray(spot[0]) - start) * k / n_fly for k in range(n_fly)]
    return [[(tuple(p), spot[1])] for p in path] + [[spot]] * n_hover


def test_drone_that_flew_in_and_hovers_beside_a_post_is_not_background() -> None:
    # 0.2 m beside the post: not floating in free space, and static for 83 % of the
    # sequence; but the post was there from the start and the drone arrived after 1 s
    spot: Sphere = ((6.0, -3.3, 0.8), 0.3)
    frames = _fly_in_then_hover(spot, n_fly=10, n_hover=50)
    model = _learn(frames)
    assert model.arrival_cells >= 3
    pts = scan(np.random.default_rng(5), [spot], n_rays=16000, boxes=[POST])
    on = points_near(pts, spot[0], 0.35)
    assert on.sum() >= 5
    # most of it is foreground again (points within 0.3 m of the post's range stay MARGIN)
    assert np.mean(model.classify(pts)[on] == FOREGROUND) > 0.5
    off = _learn(frames, arrival_after_s=0.0)  # the rule switched off: erased
    assert off.arrival_cells == 0
    assert np.mean(off.classify(pts)[on] == FOREGROUND) < 0.1


def test_the_same_object_there_from_the_start_stays_background() -> None:
    spot: Sphere = ((6.0, -3.3, 0.8), 0.3)
    model = _learn([[spot]] * 60)
    assert model.arrival_cells == 0
    pts = scan(np.random.default_rng(5), [spot], n_rays=16000, boxes=[POST])
    on = points_near(pts, spot[0], 0.35)
    assert on.sum() >= 5
    assert np.all(model.classify(pts)[on] != FOREGROUND)


@pytest.mark.parametrize("seed", [61, 62, 63])
def test_a_static_scene_has_no_late_arrivals(seed: int) -> None:
    assert _learn([[]] * 60, seed=seed).arrival_cells == 0


def test_swaying_foliage_of_a_few_cm_is_background() -> None:
    rng = np.random.default_rng(3)
    base = rng.uniform([7.0, 3.0, 1.0], [8.5, 5.0, 3.0], (40, 3))  # a bush of 40 leaves
    stem: Sphere = ((7.7, 4.0, -1.0), 0.6)  # attached to the ground

    def bush(k: int) -> list[Sphere]:
        sway = 0.04 * np.sin(0.7 * k + np.arange(len(base)))[:, None] * np.array([1.0, 0.6, 0.2])
        return [stem] + [((*(c + s),), 0.12) for c, s in zip(base, sway, strict=True)]

    model = _learn([bush(k) for k in range(60)])
    pts = scan(np.random.default_rng(11), bush(77), n_rays=16000, boxes=[POST])
    in_bush = np.all((pts > [6.8, 2.8, 0.8]) & (pts < [8.7, 5.2, 3.2]), axis=1)
    assert in_bush.sum() >= 30
    assert np.mean(model.classify(pts)[in_bush] != FOREGROUND) > 0.97


def test_classify_empty_and_frozen_after_first_classify() -> None:
    model = _learn([[]] * 12)
    assert model.classify(np.zeros((0, 3), dtype=np.float32)).shape == (0,)
    with pytest.raises(RuntimeError, match="frozen"):
        model.observe(99 * NS, np.zeros((1, 3), dtype=np.float32))


def test_core_against_the_wall() -> None:
    model = _learn([[]] * 20)
    pts = scan(np.random.default_rng(1))
    wall = pts[:, 0] > 11.9
    assert wall.sum() > 20
    assert np.mean(model.classify(pts)[wall] == CORE) > 0.9


# a thin pole (lamp post) 4.5 m away; its top is at 1.2 m
POLE = ((4.4, 1.4, GROUND_Z), (4.55, 1.55, 1.2))
POLE_TOP = np.array([4.475, 1.475, 1.2])


def _drone_on_pole(k: int, drift_m: float) -> list[Sphere]:
    """A 0.7 m quadcopter (body + 4 rotors) hovering just above the pole top, drifting and yawing."""
    t = 0.1 * k
    centre = POLE_TOP + [0.0, 0.0, 0.14]
    centre = centre + drift_m * np.array(
        [np.sin(0.9 * t), np.sin(0.7 * t + 1.0), 0.5 * np.sin(1.1 * t + 2.0)]
    )
    yaw = 0.25 * t
    spheres: list[Sphere] = [((*centre,), 0.12)]
    for j in range(4):
        a = yaw + j * np.pi / 2 + np.pi / 4
        spheres.append(((*(centre + 0.25 * np.array([np.cos(a), np.sin(a), 0.0])),), 0.1))
    return spheres


def _learn_with(
    frames: list[list[Sphere]],
    boxes: list[tuple[tuple[float, ...], tuple[float, ...]]],
    seed: int,
    **cfg: float,
) -> BackgroundModel:
    rng = np.random.default_rng(seed)
    model = BackgroundModel(BackgroundConfig(**cfg))
    for k, spheres in enumerate(frames):
        model.observe(k * NS, scan(rng, spheres, boxes=boxes))
    return model


@pytest.mark.xfail(
    strict=True,
    reason="known limitation: this hover 0.14 m above a 0.15 m pole at 4.5 m is still erased "
    "(the cap rule releases the simulator's pole-top hovers, not this close, thin case)",
)
@pytest.mark.parametrize("seed", [23, 24])
def test_drone_hovering_on_a_pole_top_all_along_is_not_background(seed: int) -> None:
    frames = [_drone_on_pole(k, 0.12) for k in range(60)]
    model = _learn_with(frames, [POLE], seed)
    rng = np.random.default_rng(seed + 100)
    pts = scan(rng, _drone_on_pole(31, 0.12), n_rays=16000, boxes=[POLE])
    on = points_near(pts, POLE_TOP + [0.0, 0.0, 0.14], 0.5) & (pts[:, 2] > POLE_TOP[2] + 0.02)
    assert on.sum() >= 5
    assert np.mean(model.classify(pts)[on] == FOREGROUND) > 0.8
    # the pole itself stays background
    pole = np.all((pts > [4.3, 1.3, GROUND_Z + 0.3]) & (pts < [4.65, 1.65, 1.0]), axis=1)
    assert pole.sum() >= 5
    assert np.all(model.classify(pts)[pole] != FOREGROUND)


def _range_image(cells: dict[tuple[int, int], float]) -> np.ndarray:
    image = np.full((90, 180), np.inf, dtype=np.float32)
    for (e, a), r in cells.items():
        image[e, a] = r
    return image


def _floats(image: np.ndarray) -> np.ndarray:
    return _floating_blobs(image, 2.0, 30.0, 1.2, np.radians(50.0))


def test_a_blob_over_a_separate_pole_top_right_below_floats() -> None:
    # a drone 8.7 m away hovering a metre above a pole top: the pole top shows in the next cell
    # down at 8.1 m (0.6 m nearer, within the 1 m clearance, but a separate surface)
    drone = {(66, 100): 8.7, (66, 101): 8.6, (65, 100): 8.9}
    pole = {(64, 100): 8.1, (63, 100): 7.9, (62, 100): 7.8, (61, 100): 7.7}
    out = _floats(_range_image(drone | pole))
    assert all(out[c] for c in drone)
    assert not any(out[c] for c in pole)


def test_a_blob_continuous_with_the_pole_or_beside_a_surface_does_not_float() -> None:
    drone = {(66, 100): 8.7, (66, 101): 8.6, (65, 100): 8.9}
    # a lamp head: range-continuous with its pole, one blob that is not small
    pole = {(64, 100): 8.6, (63, 100): 8.5, (62, 100): 8.4, (61, 100): 8.3, (60, 100): 8.2}
    pole |= {(e, 100): 8.2 - 0.1 * (60 - e) for e in range(50, 60)}
    assert not _floats(_range_image(drone | pole)).any()
    # a separate surface beside it (not below): no free space around it
    wall = {(e, a): 8.0 for e in range(55, 75) for a in range(102, 110)}
    out = _floats(_range_image(drone | wall))
    assert not any(out[c] for c in drone)
    # a separate surface below but wide (a roof, a car): not a pole or post top
    roof = {(64, a): 8.1 for a in range(97, 105)} | {(63, a): 8.0 for a in range(97, 105)}
    out = _floats(_range_image(drone | roof))
    assert not any(out[c] for c in drone)


@pytest.mark.parametrize("seed", [31, 32])
def test_lamp_head_on_a_pole_is_a_released_cap_and_the_pole_stays_background(seed: int) -> None:
    # by design: nothing static tells a lamp head from a drone hovering on the pole all along, so
    # the cap is released and left to the tracker (where a static candidate weighs 0.3)
    head = ((4.2, 1.3, 1.2), (4.8, 1.65, 1.45))  # a 0.6 m lamp head, wider than the pole
    model = _learn_with([[]] * 60, [POLE, head], seed)
    pts = scan(np.random.default_rng(seed + 100), n_rays=16000, boxes=[POLE, head])
    on = np.all((pts > [4.1, 1.2, 1.2]) & (pts < [4.9, 1.75, 1.55]), axis=1)
    assert on.sum() >= 10
    model.classify(pts[:1])
    assert model.cap_cells > 0  # found as a cap: its points are no longer certain background
    pole = np.all((pts > [4.3, 1.3, GROUND_Z + 0.3]) & (pts < [4.65, 1.65, 0.9]), axis=1)
    assert pole.sum() >= 5
    assert np.all(model.classify(pts)[pole] != FOREGROUND)
    # and with the rule off it is background, as before
    off = _learn_with([[]] * 60, [POLE, head], seed, release_caps=False)
    assert np.all(off.classify(pts)[on] != FOREGROUND)
    assert off.cap_cells == 0


def test_swaying_small_crown_on_a_thin_trunk_is_released_only_as_a_cap() -> None:
    # a crown under 1.2 m on a thin trunk is a cap like a lamp head: released to the tracker
    # (a static candidate there); with the cap rule off, the swaying crown is background
    rng = np.random.default_rng(41)
    trunk = ((5.9, -2.1, GROUND_Z), (6.05, -1.95, 0.8))
    leaves = rng.uniform([5.6, -2.4, 0.8], [6.3, -1.6, 1.6], (30, 3))  # a 0.8 m crown

    def crown(k: int) -> list[Sphere]:
        sway = 0.04 * np.sin(0.7 * k + np.arange(len(leaves)))[:, None] * np.array([1.0, 0.6, 0.2])
        return [((*(c + s),), 0.1) for c, s in zip(leaves, sway, strict=True)]

    model = _learn_with([crown(k) for k in range(60)], [trunk], 42)
    pts = scan(np.random.default_rng(43), crown(77), n_rays=16000, boxes=[trunk])
    in_crown = np.all((pts > [5.4, -2.6, 0.7]) & (pts < [6.5, -1.4, 1.8]), axis=1)
    assert in_crown.sum() >= 20
    off = _learn_with([crown(k) for k in range(60)], [trunk], 42, release_caps=False)
    assert np.mean(off.classify(pts)[in_crown] != FOREGROUND) > 0.95
    trunk_pts = np.all((pts > [5.8, -2.2, GROUND_Z + 0.3]) & (pts < [6.15, -1.85, 0.6]), axis=1)
    assert trunk_pts.sum() >= 5
    assert np.all(model.classify(pts)[trunk_pts] != FOREGROUND)


def _cone_scan(rng: np.random.Generator, spheres: list[Sphere]) -> np.ndarray:
    """A Mid-360 scan plus an Avia-like scan of the cone above 52 degrees (dense, narrow)."""
    return np.concatenate(
        [
            scan(rng, spheres),
            scan(rng, spheres, n_rays=60000, wall=False, el_range_deg=(52.0, 90.0)),
        ]
    )


@pytest.mark.parametrize("seed", [51, 52])
def test_drone_hovering_high_in_the_avia_cone_all_along_is_not_background(seed: int) -> None:
    centre = np.array([14.0, 9.0, 40.0])  # 43 m away, 68 degrees up: one 2-degree cell wide
    rng = np.random.default_rng(seed)

    def drone(k: int) -> list[Sphere]:
        return [((*(centre + 0.1 * np.array([np.sin(0.3 * k), np.cos(0.2 * k), 0.0])),), 0.4)]

    frames = [drone(k) for k in range(60)]
    model = BackgroundModel(BackgroundConfig())
    for k, spheres in enumerate(frames):
        model.observe(k * NS, _cone_scan(rng, spheres))
    pts = _cone_scan(np.random.default_rng(seed + 100), drone(30))
    on = points_near(pts, centre, 0.8)
    assert on.sum() >= 3
    assert np.mean(model.classify(pts)[on] == FOREGROUND) > 0.8
    # the same blob below the cone, 43 m away, is too far to judge: it stays background
    low = BackgroundModel(BackgroundConfig(floating_any_range_above_deg=90.0))
    rng = np.random.default_rng(seed)
    for k, spheres in enumerate(frames):
        low.observe(k * NS, _cone_scan(rng, spheres))
    assert np.all(low.classify(pts)[on] != FOREGROUND)


def test_hidden_below_is_true_where_the_ground_margin_would_swallow_what_continues() -> None:
    model = _learn([[]] * 60)
    h = 15.0

    def at(el_deg: float, range_m: float, az_deg: float = 180.0) -> list[float]:
        el, az = np.radians(el_deg), np.radians(az_deg)
        return [
            range_m * np.cos(el) * np.cos(az),
            range_m * np.cos(el) * np.sin(az),
            range_m * np.sin(el),
        ]

    # at 15 m everything below the sensor's height (1.5 m up) lies within the margin of the
    # ground seen at a grazing angle behind it: a person there shows only head and shoulders
    points = np.array(
        [
            at(0.5, h),  # a shoulder 1.6 m up: one cell lower is swallowed by the ground
            at(10.0, h),  # a drone 15 m out, 4 m up: below it only far ground or sky
            at(10.0, 10.0, az_deg=0.0),  # a drone 2 m in front of the wall
            [6.0, -4.0, 1.3],  # a drone hovering over the post: what lies below is not ground
        ],
        dtype=np.float32,
    )
    assert np.all(model.classify(points) == FOREGROUND)  # all four are seen
    assert model.hidden_below(points).tolist() == [True, False, False, False]
