"""Configuration of the estimator: pydantic sections in one root model, defaults in code, optional YAML.

Every section forbids unknown keys (a misspelt key is an error, not a silently ignored value) and
is frozen. ``load_config`` reads a YAML file and/or a nested dict of overrides; ``config_to_dict``
gives the effective configuration as plain JSON-able data, stored with every output.
Lengths are metres (``*_m``), durations seconds (``*_s``), speeds m/s.
"""

from __future__ import annotations

import difflib
from pathlib import Path
from typing import Any, Final, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from cldet.errors import ConfigError

__all__ = [
    "BackgroundConfig",
    "BiasConfig",
    "CldetConfig",
    "ClusteringConfig",
    "FramesConfig",
    "SensorConfig",
    "SmoothingConfig",
    "TrackingConfig",
    "config_to_dict",
    "load_config",
]

_STRICT = ConfigDict(extra="forbid", frozen=True)


TRAINING_MEAN_POSITION_M: Final[tuple[float, float, float]] = (0.734, -9.739, 33.353)
"""The mean drone position of the challenge's training split (metres, Mid-360 frame): the
position of last resort when there is no estimate at all."""


class FramesConfig(BaseModel):
    """Point filtering and when, inside a scan, a frame's points were taken."""

    model_config = _STRICT

    min_range_m: float = Field(default=0.3, ge=0, description="drop self-returns nearer than this")
    max_range_m: float = Field(default=150.0, gt=0, description="drop returns farther than this")
    scan_offset_s: float = Field(
        default=0.05,
        ge=0,
        le=1,
        description="a frame's points are dated at its stamp plus this (the middle of the"
        " Mid-360's 100 ms scan): a fast drone's estimate no longer leads the truth",
    )
    point_times: Literal["off", "fit", "track"] = Field(
        default="fit",
        description="where a cloud records each point's firing time (the MMAUD arrays' row"
        " order, a 'time' field), a cluster is seen at its points' mean time: a drone at 20 m/s"
        " moves 2 m in a scan, and a return dated at the scan's middle is off by up to 1 m along"
        " its path. 'fit': the fits over a track's detections use it (the line search, the"
        " refinement's smoother and straight runs, the causal estimate's coasts along a straight"
        " run or a line, and the tracker's output state that the causal estimate reports),"
        " while the tracker's association and filter take each cluster at the frame's time;"
        " 'track': the tracker too (H = [1, lag]), which broke close drones on development worlds (a close drone's centroid jitters by"
        " decimetres between detections the lags put 0.04 s apart, which a young track takes"
        " as speed); 'off' (or times not recorded): every point at scan_offset_s. true and"
        " false, the switch's former values, mean 'track' and 'off'",
    )

    @field_validator("point_times", mode="before")
    @classmethod
    def _point_times_from_bool(cls, value: object) -> object:
        """The switch was a bool: true dated clusters in the tracker and the smoother."""
        if isinstance(value, bool):
            return "track" if value else "off"
        return value

    avia_xyz_m: tuple[float, float, float] = Field(
        default=(0.0, 0.0, 0.0),
        description="the Avia's origin in the LiDAR's frame, used when a log's /tf_static does"
        " not connect their frames (the challenge's Avia clouds are already in the Mid-360's"
        " frame: zero)",
    )
    avia_rpy_deg: tuple[float, float, float] = Field(
        default=(0.0, 0.0, 0.0),
        description="the Avia's roll, pitch, yaw in the LiDAR's frame (degrees, about the fixed"
        " x, y, z axes), with avia_xyz_m",
    )


class SensorConfig(BaseModel):
    """Where the Mid-360 stands: the z-up ``world`` frame of a log's transform tree.

    ``world`` is level (z up) with its origin on the ground right below the sensor and its x axis
    under the sensor's heading; estimates stay in the Mid-360's frame, this only places them.
    With ``ground_from_pose`` the estimator also takes its ground plane from these figures
    instead of fitting it to the data.
    """

    model_config = _STRICT

    height_m: float = Field(
        default=1.0,
        ge=0,
        le=100,
        description="the Mid-360's height above the ground (the challenge's ground is about 1 m"
        " below it)",
    )
    roll_deg: float = Field(
        default=0.0, ge=-90, le=90, description="the sensor's tilt about its x axis (degrees)"
    )
    pitch_deg: float = Field(
        default=0.0, ge=-90, le=90, description="the sensor's tilt about its y axis (degrees)"
    )
    ground_from_pose: bool = Field(
        default=False,
        description="the ground plane is the one height_m, roll_deg and pitch_deg describe, not"
        " fitted to the static returns: for a mount whose own ground the sensor does not see"
        " (a roof below the view of a sensor on it, where the fit finds the street far below);"
        " false: fitted (the robustness benchmark's setting: the pose is not told)",
    )


class BackgroundConfig(BaseModel):
    """Online static range image over a sliding window of time bins (see ``cldet.core.background``)."""

    model_config = _STRICT

    cell_deg: float = Field(
        default=2.0, gt=0, le=30, description="direction cell, azimuth and elevation"
    )
    bin_s: float = Field(
        default=0.2,
        gt=0,
        description="time bin: a cell's nearest range per bin; the first bin is the warm-up",
    )
    window_bins: int = Field(
        default=30, ge=1, le=600, description="the static range is learned over this many bins"
    )
    static_fraction: float = Field(
        default=0.25,
        gt=0,
        le=1,
        description="static = reached in at least this fraction of the window's bins (swaying"
        " foliage that fills a direction part of the time stays background)",
    )
    seen_through_bins: int = Field(
        default=2,
        ge=0,
        le=600,
        description="... unless that range is gone: nothing returned at or before it in each of"
        " the last this many bins (farther returns or none) and it does not recur (see"
        " recurrent_bins). A drone receding along its line of sight always lies behind its own"
        " earlier ranges, which the fraction above would keep as static; a wall recurs, swaying"
        " foliage comes back to its range (0: off)",
    )
    recurrent_bins: int = Field(
        default=3,
        ge=0,
        le=600,
        description="static is also the nearest range that recurs (within the margin) in at"
        " least this many of the window's bins: a thin or far structure hit only now and then"
        " (a pole, a wire, a branch 30 m out) returns the same range each time, rain and passing"
        " things do not (0: off)",
    )
    replay_s: float = Field(
        default=3.0,
        ge=0,
        description="the first this many seconds are judged again, once, against the background"
        " learned by then, for the refinement: while the window holds a few bins, one bin's"
        " return is static, and a drone there from the start is learned where it just was"
        " (receding, or in empty sky that nothing shows see-through) for seconds. What is"
        " foreground then is added as clusters and tracks, nothing taken away; the causal"
        " estimates stay. Costs those seconds' points in memory (0: off)",
    )
    polar_cell_width: float = Field(
        default=0.25,
        ge=0,
        le=1,
        description="near the zenith, azimuth columns narrow as cos(elevation): where one is"
        " narrower than this fraction of cell_deg, columns are grouped into cells at least this"
        " wide (and at most cell_deg). The Avia, looking up, puts about 4.6 times the"
        " Mid-360's returns on a steradian, so a quarter-width cell there is hit as often as a"
        " full one at the horizon; slivers are hit now and then and a surface overhead is never"
        " learned (0: off)",
    )
    dilate_cells: int = Field(
        default=1, ge=0, le=3, description="grow the static range by this many cells"
    )
    margin_m: float = Field(
        default=0.3, ge=0, description="foreground = nearer than static by more than"
    )
    margin_fraction: float = Field(
        default=0.03, ge=0, lt=1, description="... or this fraction of range"
    )
    floating_max_size_m: float = Field(
        default=1.2,
        ge=0,
        description="static blobs this small floating in free space are not background (0: off)",
    )
    floating_arrivals: bool = Field(
        default=True,
        description="... also a blob beside the bottom of the field of view, where its surface"
        " arrived (the sensors had seen through that spot before), stayed and lies clear of the"
        " ground:"
        " a slow drone flying along the field's bottom (a high mount, a tilted sensor), learned"
        " from its own trail; a hedge or the ground far out seen on the lowest row was there"
        " before, or is the ground (false: such a blob never floats, as it may be the visible"
        " end of something larger)",
    )
    reclaim_m: float = Field(
        default=0.6,
        ge=0,
        description="dilation-margin points this close to where a protected mover was just seen"
        " are foreground",
    )
    protect_tracks: bool = Field(
        default=True,
        description="points of confirmed small moving tracks are not learned as background (a"
        " drone that flew in and hovers stays foreground)",
    )
    protect_min_moved_m: float = Field(
        default=1.2,
        ge=0,
        description="... once the running mean of the track's detections lies this far from"
        " its first value:"
        " beyond the largest drone, so that a sparse far structure lit in different places"
        " each scan (its centroid scatters, its mean stays) is learned, not protected for ever",
    )
    protect_dense_points: int = Field(
        default=3,
        ge=0,
        description="... and, short of that, a track's cluster detections need a median of at"
        " least this many points to be protected as a hover within a drone's size or, too young"
        " for a running mean, as a compact object that jumped: single returns cannot tell a"
        " small body from a larger thing lit in different places each scan (0: every hover"
        " within a drone's size protected, no young jumps)",
    )
    protect_hold: bool = Field(
        default=True,
        description="a track once protected stays protected while it lives: a hovering drone"
        " that merges in some frames with foreground beside it (a cluster wider than a drone)"
        " is not learned in those frames",
    )


class ClusteringConfig(BaseModel):
    """Exact DBSCAN over the foreground points of one frame."""

    model_config = _STRICT

    eps_m: float = Field(default=1.0, gt=0, description="neighbourhood radius")
    min_samples: int = Field(
        default=1, ge=1, description="core point: at least this many within eps"
    )
    max_points: int = Field(
        default=20000, ge=1, description="foreground points beyond this (nearest first) are dropped"
    )
    max_clusters: int = Field(
        default=300,
        ge=1,
        description="a frame's clusters beyond this (smallest first) become noise: a frame flooded"
        " with speckle (rain, a broken sensor) cannot flood the tracker",
    )


class TrackingConfig(BaseModel):
    """Candidate tracks (constant-velocity Kalman), their whole-sequence score and the chain."""

    model_config = _STRICT

    accel_psd: float = Field(
        default=4.0,
        gt=0,
        description="white-acceleration PSD q of the candidate tracks' Kalman filter, m^2/s^3:"
        " it sizes the gate, so a manoeuvring drone stays inside it (the offline smoother has"
        " its own, smoothing.accel_psd)",
    )
    meas_sigma_m: float = Field(default=0.12, gt=0, description="centroid noise, 1 sigma")
    raw_meas_sigma_m: float = Field(default=0.25, gt=0, description="noise of a raw-gate detection")
    init_speed_sigma: float = Field(
        default=5.0, gt=0, description="speed uncertainty at track start, m/s"
    )
    gate_chi2: float = Field(default=16.0, gt=0, description="Mahalanobis gate (3 dof)")
    max_gate_m: float = Field(default=3.0, gt=0, description="hard Euclidean gate")
    gate_speed: float = Field(
        default=0.0,
        ge=0,
        description="the hard gate grows by this speed (m/s) times the time a track was unseen"
        " beyond one scan",
    )
    max_miss_s: float = Field(
        default=1.5, gt=0, description="a candidate track ends after this unseen"
    )
    static_factor: float = Field(
        default=0.6,
        gt=0,
        le=1,
        description="score factor of a track that goes nowhere (static clutter, or a drone"
        " hovering all along: a real mover wins)",
    )
    fixed_spread_m: float = Field(
        default=0.025,
        ge=0,
        description="a track whose half-second mean position stays (90 %) this close to its"
        " median for a second or more is rigidly fixed structure: a hovering drone wanders"
        " more (0: off)",
    )
    fixed_sampling_factor: float = Field(
        default=1.0,
        ge=0,
        description="... or within this many times the jitter that sampling alone gives a rigid"
        " object's centroid (its largest edge / sqrt(12 points), median over the track): a sign"
        " or a balcony 0.7 m across, sampled by 20 points a scan, jitters by 4 cm where a"
        " hovering drone wanders by decimetres (0: fixed_spread_m alone)",
    )
    prior_scorer: bool = Field(
        default=True,
        description="the refinement re-weighs the hand-set track factors by the drone"
        " probability of the scorer learned on the simulator's randomised development worlds"
        " (cldet/core/prior.py; a --model's own scorer re-weighs them as well); false: the"
        " hand-set factors alone, or with a --model's scorer only",
    )
    fixed_factor: float = Field(
        default=0.01,
        gt=0,
        le=1,
        description="score factor of a rigidly fixed track (no multirotor holds its mean"
        " position to centimetres: structure beyond doubt, so far below the static factor)",
    )
    static_spread_m: float = Field(
        default=0.5,
        ge=0,
        description="a track whose detections (90 %) lie this close to their median is static",
    )
    max_speed: float = Field(
        default=30.0,
        gt=0,
        description="tracks faster than this (90th percentile) are not a drone (DJI drones"
        " cruise at 15-23 m/s)",
    )
    mid360_points_per_sr: float = Field(
        default=3000.0,
        gt=0,
        description="Mid-360 points per steradian of surface per scan (a drone of area A at"
        " range r returns about this * A / r^2 points)",
    )
    avia_points_per_sr: float = Field(
        default=14000.0, gt=0, description="the same for the Avia (about 4.7x denser)"
    )
    min_cross_section_m2: float = Field(
        default=0.02,
        gt=0,
        description="detections whose points / density * r^2 is below this weigh less, down to"
        " 0.1 (a lone return near the sensor: rain, dust, a leaf)",
    )
    max_size_m: float = Field(
        default=1.2, gt=0, description="clusters larger than this are not a drone"
    )
    crowd_radius_m: float = Field(
        default=3.0,
        ge=0,
        description="a detection with k other clusters of its frame within this radius, each"
        " with a point count within a factor of two of its own, weighs 1 / (1 + k): among rain, speckle or flickering"
        " foliage any track finds a return to continue on by chance, so such a detection is"
        " weak evidence of one object; none of them imitates a dense cluster (0: off)",
    )
    min_height_m: float = Field(
        default=2.0, description="clusters reaching lower than this above ground: unlikely"
    )
    fov_bottom_deg: float = Field(
        default=-7.3, ge=-90, le=0, description="bottom elevation of the Mid-360's field of view"
    )
    fov_cut_m: float = Field(
        default=0.3,
        ge=0,
        description="clusters this close to the field's bottom may reach the ground (0: off)",
    )
    ground_mover_max_m: float = Field(
        default=2.5,
        gt=0,
        description="the tallest thing that moves on the ground (people, cars, vans), metres: a"
        " cluster cut by the field's bottom this high above the local ground or higher cannot be"
        " one reaching down to the ground (from a mast the field's edge passes metres up)",
    )
    link_max_gap_s: float = Field(
        default=8.0, gt=0, description="longest unseen gap bridged between tracks"
    )
    link_speed: float = Field(
        default=10.0,
        gt=0,
        description="max mean speed across a bridged gap, m/s: from where the earlier track was"
        " at its last detection before the gap, or from where its motion then carries it",
    )
    link_velocity_s: float = Field(
        default=0.5,
        ge=0,
        description="a track's motion at a detection, which a link across a gap carries on: the"
        " constant-velocity fit of its detections over this long up to it (0: links reach from"
        " where it was only, so a pass faster than link_speed is never linked)",
    )
    extend_gap_s: float = Field(
        default=0.5,
        ge=0,
        description="refinement: the chosen chain is carried on, before its first detection and"
        " after its last, by any track that touches it (its nearest detection at most this"
        " long before or after, within link_speed's reach), however weak: the chain's evidence"
        " says which object is the drone, and a track continuous with it is where that object"
        " was meanwhile (a hover judged static at the start, say), which beats extrapolating"
        " (0: off)",
    )
    extend_min_evidence: float = Field(
        default=0.5,
        ge=0,
        description="... a track carrying it on must bring at least this much evidence (summed"
        " detection weights of the part taken; one full-weight detection is 1): a drone"
        " hovering for a second, judged static, brings ~0.5, while two or three near-weightless"
        " returns that clutter makes by chance next to anything bring ~0.1",
    )
    link_tail_ratio: float = Field(
        default=0.25,
        ge=0,
        le=1,
        description="a link may leave a track before the next one starts, dropping its tail, when"
        " the tail's returns per detection average at most this fraction of the kept part's (a"
        " track that lost the drone and coasted on single returns; 0: links leave at the next"
        " track's start only)",
    )
    carve_gate_m: float = Field(
        default=0.6,
        ge=0,
        description="a confirmed drone-sized track that has flown (background.protect_min_moved_m)"
        " whose prediction falls in a cluster larger than max_size_m carves out the foreground"
        " points within this radius of the blob there, when they stand isolated (at most half as"
        " many points in the shell out to twice the radius, what lies below counted) and the wide"
        " cluster reaches beyond that shell: the 1 m linkage chains rain near the sensor into one"
        " wide blob, and a drone close by joins it, its detection then the blob's centroid"
        " metres away (0: off)",
    )
    split_rigid: bool = Field(
        default=True,
        description="a candidate track whose first or last detections are rigidly fixed (as"
        " fixed_spread_m judges a whole track, over 2 s or more) where another track shows a"
        " fixed object at the same place is cut there, and the fixed part scored as a track of"
        " its own: a track that followed the drone past a sign or a"
        " lamp head and kept the sign is the drone's only up to the sign (false: tracks are"
        " judged only whole)",
    )
    chain_head_ratio: float = Field(
        default=0.25,
        ge=0,
        le=1,
        description="the chosen chain begins at its first track's first detection whose"
        " cross-section reaches this fraction of the track's median: a track begun on lone"
        " returns (rain, speckle) that its gate then led onto the drone has its head dropped (0:"
        " off)",
    )
    raw_gate_m: float = Field(
        default=0.0,
        ge=0,
        description="raw-point search radius around a confirmed mover's prediction (0: off; the"
        " background's protect_tracks keeps a hovering drone in the foreground instead)",
    )
    raw_min_cluster_hits: int = Field(
        default=2, ge=1, description="cluster detections before a track may use raw points"
    )
    raw_min_spread_m: float = Field(
        default=0.3, ge=0, description="... spread over at least this (the track has moved)"
    )
    raw_weight: float = Field(
        default=0.5, ge=0, le=1, description="score weight of a raw-gate detection"
    )
    causal_confirm: float = Field(
        default=3.0,
        ge=0,
        description="causal: a track is reported as the drone once its running evidence (summed"
        " detection weights after its first) reaches this; before any track has, the estimate"
        " is FALLBACK (0: the first track with a second detection)",
    )
    causal_keep_lost: bool = Field(
        default=True,
        description="causal: when the followed track is lost, its chain's evidence keeps"
        " competing for link_max_gap_s, as the refinement weighs whole chains: a track that"
        " could continue the chain (reachable from the lost track's last detection before its"
        " first at link_speed plus the lost track's speed there) competes with the chain's"
        " evidence added to its own, any other only once its own exceeds the chain's. A drone"
        " that stopped and was learned, or went behind something, stays a better hypothesis"
        " than weak clutter that turns up meanwhile; so does a line from when the causal line"
        " search (causal_line_every_s) follows it (false: any track reaching"
        " causal_confirm)",
    )
    causal_judge_s: float = Field(
        default=1.0,
        ge=0,
        description="causal: a track is chosen only once it has lived this long, and is judged"
        " static or rigidly fixed from then on (a still object and a drone just arrived look"
        " alike for their first second; 0: chosen at once, judged only after 1 s and 2 s)",
    )
    causal_robust_still: bool = Field(
        default=True,
        description="causal: a track is judged rigidly fixed also from its detections after"
        " its first causal_judge_s alone (90 % of their running means near the median, as the"
        " refinement judges), not only from the box around all its running means, which one"
        " stray early detection (the track begun on clutter beside a sign) widens for good;"
        " false: the box",
    )
    line_search: bool = Field(
        default=True,
        description="track-before-detect for sparse fast movers: constant-velocity lines through"
        " the whole sequence's clusters become candidate tracks (cldet.core.lines)",
    )
    line_tol_m: float = Field(
        default=0.7, gt=0, description="a cluster this close to a line's position is on it"
    )
    line_min_hits: int = Field(
        default=5,
        ge=3,
        description="distinct places on a line (2 line_tol_m apart along it: the centroid's"
        " noise, not the scan's smear) with a cluster before it is a candidate",
    )
    line_seed_s: float = Field(
        default=1.0, gt=0, description="a line starts from two clusters at most this far apart"
    )
    line_window_s: float = Field(
        default=3.0, gt=0, description="longest unseen stretch a line bridges while it grows"
    )
    line_isolation_m: float = Field(
        default=3.0,
        gt=0,
        description="a line's clusters have no other cluster of their frame this close",
    )
    line_min_sweep_deg: float = Field(
        default=10.0,
        ge=0,
        description="a line's clusters span at least this angle seen from the sensor (a line"
        " along the line of sight matches noise along one beam)",
    )
    line_min_speed: float = Field(
        default=3.0,
        ge=0,
        description="lines slower than this are left to the Kalman tracker (m/s)",
    )
    causal_line_every_s: float = Field(
        default=0.5,
        ge=0,
        description="causal: while no track is followed, the line search runs this often over"
        " the last causal_line_window_s; a line scoring causal_confirm or more is followed"
        " along its fit, carried on as a straight transit (a sparse fast pass the Kalman"
        " tracker cannot hold; 0: off)",
    )
    causal_line_window_s: float = Field(
        default=3.0, gt=0, description="causal: the line search looks this far back"
    )
    fallback_position: tuple[float, float, float] = Field(
        default=TRAINING_MEAN_POSITION_M, description="used only when no track exists at all"
    )


class SmoothingConfig(BaseModel):
    """Offline forward-backward (Rauch-Tung-Striebel) smoother over the chosen track."""

    model_config = _STRICT

    accel_psd: float = Field(
        default=2.0,
        gt=0,
        description="white-acceleration PSD q of the offline smoother, m^2/s^3: how closely the"
        " final trajectory follows the chosen detections (the tracker's gate has its own,"
        " tracking.accel_psd)",
    )
    extrapolation_tau_s: float = Field(
        default=1.5,
        gt=0,
        description="beyond the detections the velocity decays with this time constant (after"
        " holding as long as the straight run that ends, or starts, the track)",
    )
    max_decel_mps2: float = Field(
        default=6.0,
        ge=0,
        description="beyond the detections the velocity decays no faster than a multirotor"
        " brakes, about g tan(tilt limit), 6 m/s^2 for 31 deg: the decay's time constant grows"
        " to speed / this where that is longer than extrapolation_tau_s (0: off)",
    )
    straight_rms_m: float = Field(
        default=0.4,
        ge=0,
        description="a run of detections is straight when a constant velocity fits it to this"
        " RMS residual, metres, plus the smear of a scan at the run's speed (0: never). Inertia:"
        " beyond a straight run the extrapolation keeps the run's velocity for straight_hold_factor"
        " times as long as the run lasted, then decays",
    )
    straight_min_points: int = Field(
        default=3,
        ge=3,
        description="a straight run needs this many detections at least (3: the fewest that test"
        " a line). Its duration is not gated: a transit seen for only half a second still keeps"
        " its velocity for straight_hold_factor times that, where a decay from the first moment"
        " would stop a 15 m/s pass within metres",
    )
    straight_min_speed_mps: float = Field(
        default=3.0,
        ge=0,
        description="a straight run slower than this is a hover's drift or a manoeuvre, not a"
        " transit: its velocity is not held",
    )
    straight_hold_factor: float = Field(
        default=2.0,
        ge=0,
        description="a straight run's velocity is held beyond the detections this many times as"
        " long as the run was seen, then decays: a drone seen in transit for T seconds keeps"
        " going after it fades out of reach (the refinement's negative evidence stops it where"
        " it would have been seen; the causal estimate has none, so the hold stays bounded)",
    )
    straight_max_hold_s: float = Field(
        default=10.0,
        ge=0,
        description="the longest a straight run's velocity is held beyond the detections, s",
    )
    unseen_check_s: float = Field(
        default=1.0,
        ge=0,
        description="negative evidence: a track's motion is carried on beyond its detections only"
        " if, over this long, the drone could have gone undetected that way (out of the field,"
        " behind static structure, or too sparse to be sure of); otherwise, where the static"
        " scene at that end could hide a drone (it stopped and was learned, or it came out of a"
        " hover), the position is held instead (0: off)",
    )
    unseen_confidence: float = Field(
        default=0.95,
        gt=0,
        lt=1,
        description="... 'could not have gone undetected': the chance of at least one detection"
        " along the carried-on path, from the track's own detection rate near that end",
    )
    causal_straight_coast: bool = Field(
        default=True,
        description="causal: a frame the followed track misses is estimated along the line of"
        " the straight run that ends its detections (as when the track is lost, and as the"
        " refinement extrapolates), not from the tracker's filtered state: a sparse fast"
        " pass's last few smeared detections pull the filter's velocity off by metres a"
        " second; false: the filter's prediction until the track is lost",
    )
    came_to_rest: bool = Field(
        default=True,
        description="a track whose end position became static while it was followed (the"
        " sensors saw through that spot before) came to rest there and was learned as"
        " background: its position is held there, not carried on (with unseen_check_s > 0)",
    )
    terrain_clearance_m: float = Field(
        default=2.0,
        ge=0,
        description="beyond the detections a track's carried-on path does not pass through the"
        " ground: it keeps at least the height above the ground (the plane and height map, the"
        " lower of the two) that it had at that end, up to this much, rising with the ground"
        " where the motion would run into it (a pass over a slope or a hill climbs with the"
        " terrain, as it must to fly on). Only as good as the ground: a plane fitted to a roof"
        " beside the sensor instead of the street lifts the path wrongly (0: off)",
    )
    ground_stop_m: float = Field(
        default=0.0,
        ge=0,
        description="beyond the detections a track's carried-on motion stops where it would"
        " pass more than this below the ground (the plane and height map, the lower of the"
        " two): a drone flies above the ground, so a path that runs into it did not carry on"
        " (it came up from a take-off or a hover there, or went down to land); the position"
        " holds where the path met it. 0: off, the default: it is only as good as the ground,"
        " and the fitted plane is often wrong where little ground is seen (an urban canyon, a"
        " forest edge); with a known mount (sensor.ground_from_pose) the plane is right, but"
        " that was not measured (try 1 m)",
    )


class BiasConfig(BaseModel):
    """Correction of cluster centroids (LiDAR sees the near face; GT prism sits above the body)."""

    model_config = _STRICT

    along_ray_m: float = Field(
        default=0.0, description="push centroids away from the sensor by this"
    )
    z_m: float = Field(default=0.0, description="add this to z")


class BaselineConfig(BaseModel):
    """The ``cl-det`` comparison method (see ``cldet.core.cldet_baseline``)."""

    model_config = _STRICT

    environment: Literal["learned", "none"] = Field(
        default="learned",
        description="environment removal: 'learned' static background (as issue 4 asks), or"
        " 'none': DBSCAN over every valid Mid-360 point, the cost regime of the report's 14.9/s",
    )


class CldetConfig(BaseModel):
    """The whole estimator configuration."""

    model_config = _STRICT

    method: Literal["track", "cl-det"] = "track"
    frames: FramesConfig = Field(default_factory=FramesConfig)
    sensor: SensorConfig = Field(default_factory=SensorConfig)
    background: BackgroundConfig = Field(default_factory=BackgroundConfig)
    clustering: ClusteringConfig = Field(default_factory=ClusteringConfig)
    tracking: TrackingConfig = Field(default_factory=TrackingConfig)
    smoothing: SmoothingConfig = Field(default_factory=SmoothingConfig)
    bias: BiasConfig = Field(default_factory=BiasConfig)
    baseline: BaselineConfig = Field(default_factory=BaselineConfig)


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """Deep-merge ``over`` into a copy of ``base``."""
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


_LIBRARY_PREFIXES = ("Value error,", "Assertion failed,")  # pydantic's, not ours


def _known_keys(loc: tuple[Any, ...]) -> list[str]:
    """The keys allowed beside the last element of ``loc`` (the fields of its section)."""
    model: Any = CldetConfig
    for part in loc[:-1]:
        field = getattr(model, "model_fields", {}).get(part)
        if field is None:
            return []
        model = field.annotation
    return list(getattr(model, "model_fields", {}))


def _describe(err: ValidationError) -> str:
    """One line per problem: the dotted key, the bad value and what was expected.

    An unknown key gets the closest known key of its section as a suggestion (a misspelling);
    pydantic's own prefixes ("Value error, ") are dropped and an empty reason is never shown.
    """
    lines = []
    for item in err.errors():
        loc = tuple(item["loc"])
        key = ".".join(str(p) for p in loc) or "<root>"
        if item["type"] == "extra_forbidden":
            known = _known_keys(loc)
            close = difflib.get_close_matches(str(loc[-1]), known, n=1, cutoff=0.6)
            if close:
                hint = f" (did you mean {'.'.join([*map(str, loc[:-1]), close[0]])!r}?)"
            else:
                hint = f"; known keys here: {', '.join(known)}" if known else ""
            lines.append(f"unknown key {key!r}{hint}")
            continue
        reason = str(item.get("msg", ""))
        for prefix in _LIBRARY_PREFIXES:
            reason = reason.removeprefix(prefix)
        reason = reason.strip() or str(item.get("type", "")).replace("_", " ") or "invalid value"
        lines.append(f"{key} = {item.get('input')!r}: {reason}")
    return "; ".join(lines)


def load_config(path: Path | None = None, overrides: dict[str, Any] | None = None) -> CldetConfig:
    """Build the configuration: defaults, then the YAML file, then ``overrides`` (nested dict).

    Args:
        path: optional YAML file holding a (partial) nested mapping of the sections.
        overrides: optional nested mapping applied last, e.g. ``{"method": "cl-det"}``.

    Returns:
        The validated, frozen configuration.

    Raises:
        ConfigError: the file is missing or not YAML, or a key/value is invalid (the message
            names the file and the key).
    """
    data: dict[str, Any] = {}
    where = "overrides"
    if path is not None:
        where = str(path)
        try:
            text = Path(path).read_text(encoding="utf-8")
        except OSError as err:
            raise ConfigError(f"cannot read config file {path}: {err}") from err
        try:
            loaded = yaml.safe_load(text)
        except yaml.YAMLError as err:
            raise ConfigError(f"config file {path} is not valid YAML: {err}") from err
        if loaded is None:
            loaded = {}
        if not isinstance(loaded, dict):
            raise ConfigError(
                f"config file {path} must hold a mapping of sections, got {type(loaded).__name__}"
            )
        data = loaded
    if overrides:
        data = _merge(data, overrides)
        if path is not None:
            where = f"{path} (with overrides)"
    try:
        return CldetConfig.model_validate(data)
    except ValidationError as err:
        raise ConfigError(f"invalid configuration in {where}: {_describe(err)}") from err


def config_to_dict(cfg: CldetConfig) -> dict[str, Any]:
    """The effective configuration as JSON-able nested dicts (tuples become lists)."""
    return cfg.model_dump(mode="json")
