"""``cldet train``: learn from labelled logs what the hand-set estimator can only assume.

From logs with ``/ground_truth`` (and ``/class`` where present) one pass per log runs the
estimator's per-frame verb with the configuration given and keeps its candidate tracks
(:class:`cldet.core.estimator.Candidates`); each track is matched to the truth:

- a track whose detections lie (median) within :data:`DRONE_M` of the truth at their times is
  the drone's, one whose median distance exceeds :data:`CLUTTER_M` is clutter, those between are
  left out (a track that jumped from the drone to something else);
- the **scan-time offset**: the time inside the scan at which the drone's points were taken,
  the offset (0-100 ms after the stamp) at which the truth best matches the drone tracks'
  centroids (a moving drone's centroid lies along its path by speed x offset; a hovering one
  says nothing, and the fit says so by an unchanged error);
- the **centroid bias** (along the ray and in z, as ``cldet calibrate``) from the same pairs;
- the **drone-vs-clutter scorer**: gradient-boosted trees over the tracks' physical features
  (:data:`cldet.core.features.FEATURE_NAMES`), each track weighted by its detections and the two
  classes balanced; the refinement re-weighs the hand-set track factors by its probability
  (``cldet.core.selection.LEARNED_FLOOR``), on top of the packaged prior's re-weighing;
- the **drone-type classifier** (when the logs carry ``/class`` with two classes or more): the
  shape and return features (:data:`cldet.core.features.TYPE_FEATURES`) of the drone tracks'
  prefixes,
  each labelled with its sequence's class, voted over the chosen chain's tracks at annotation
  time.

A leave-one-sequence-out cross-validation (every log held out once, models fitted on the others)
reports the type accuracy per row and the confusion matrix, and the refined position error with
the learned scorer against the default's, on the same candidates. It also decides whether the
scorer is kept: only where the held-out logs were refined clearly better with it than with the
learned timing and bias alone (:func:`scorer_earns_its_place`); a scorer fitted on a few logs can
learn their accidents, and without it the packaged prior (on by default) still re-weighs the
tracks.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from contextlib import closing
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from cldet.config import BiasConfig, CldetConfig
from cldet.core.bias import fit_bias_sequences
from cldet.core.estimator import Candidates, TrackEstimator, refine_candidates
from cldet.core.features import FEATURE_NAMES, TYPE_COLUMNS, track_detections, track_features
from cldet.core.model import LearnedModel, one_thread
from cldet.core.trajectory import evaluate_trajectory
from cldet.errors import CldetError, OutputExistsError
from cldet.evaluate import confusion_text
from cldet.executors import iter_outcomes, runs_here
from cldet.io import topics
from cldet.io.files import check_output, file_size
from cldet.io.mcap_read import open_log
from cldet.io.sources import iter_log_positions, select_topics
from cldet.modelfile import write_model
from cldet.pipeline import read_frames
from cldet.progress import NullProgress, Progress
from cldet.stamps import NS_PER_S
from cldet.types import Estimate, PositionSample, Source

__all__ = [
    "CLUTTER_M",
    "DRONE_M",
    "SequenceSample",
    "TrainError",
    "TrainReport",
    "collect_sequence",
    "cross_validate",
    "fit_model",
    "fit_track_scorer",
    "label_candidates",
    "train_logs",
]

DRONE_M: Final = 1.0
CLUTTER_M: Final = 3.0
MIN_DRONE_DETECTIONS: Final = 20  # fewer over all logs: too few to learn from
_PREFIX_STEP = 5  # the type classifier learns from a drone track's first 5, 10, 15, ... detections
_OFFSETS_S = np.arange(0.0, 0.1001, 0.0025)  # candidate scan-time offsets
_MAX_PAIR_M = 1.0  # detection/truth pairs farther apart are another object
_TREE_PARAMS: Final[dict[str, Any]] = {
    "max_iter": 150,
    "learning_rate": 0.1,
    "max_leaf_nodes": 15,
    "min_samples_leaf": 10,
    "l2_regularization": 1.0,
    "early_stopping": False,
    "random_state": 0,
}


_TYPE_TREE_PARAMS: Final[dict[str, Any]] = {
    **_TREE_PARAMS,
    "max_iter": 60,
    "max_leaf_nodes": 7,
    "min_samples_leaf": 50,
    "l2_regularization": 5.0,
}  # a handful of sequences per class: small, regularised trees


def _no_features() -> NDArray[np.float64]:
    return np.zeros((0, len(FEATURE_NAMES)))


class TrainError(CldetError):
    """The training logs cannot give a model (no truth, too few detections, ...)."""


@dataclass
class SequenceSample:
    """One training log reduced to what learning needs."""

    log: Path
    cand: Candidates
    truth_ns: NDArray[np.int64]  # (G,)
    truth_xyz: NDArray[np.float64]  # (G,3)
    class_id: int | None  # the sequence's drone type (None: no /class)
    # (T,F) per candidate track of two detections or more
    features: NDArray[np.float64] = field(default_factory=lambda: _no_features())
    hits: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))  # (T,) detections
    # (T,) 1 the drone, 0 clutter, -1 left out
    labels: NDArray[np.int8] = field(default_factory=lambda: np.zeros(0, dtype=np.int8))
    # (P,) stamps of the drone tracks' cluster detections, (P,3) their centroids
    pair_ns: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    pair_xyz: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    # (Q,F) the drone tracks' prefixes (what typing sees)
    type_features: NDArray[np.float64] = field(default_factory=lambda: _no_features())

    def truth_at(self, stamps_ns: NDArray[np.int64]) -> NDArray[np.float64]:
        """(Q,3) the truth at these stamps (linear inside its span, NaN outside)."""
        out = evaluate_trajectory(self.truth_ns, self.truth_xyz, stamps_ns)
        outside = (stamps_ns < self.truth_ns[0]) | (stamps_ns > self.truth_ns[-1])
        out[outside] = np.nan
        return out


def _read_truth(log: Path, topic: str | None) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    samples = list(iter_log_positions(log, topic)) if topic else []
    if len(samples) < 2:
        raise TrainError(
            f"{log}: no ground truth ({topics.GROUND_TRUTH} with two samples or more):"
            " training needs labelled logs (the challenge's train split, or your own flights"
            " with a truth topic)"
        )
    ns = np.array([s.stamp_ns for s in samples], dtype=np.int64)
    order = np.argsort(ns, kind="stable")
    return ns[order], np.array([samples[i].position for i in order], dtype=np.float64)


def _read_class(log: Path) -> int | None:
    with open_log(log) as reader:
        if not reader.list_topics().get(topics.CLASS):
            return None
        ids = {c.class_id for c in reader.iter_classes(topics.CLASS)}
    if len(ids) != 1:
        raise TrainError(f"{log}: {topics.CLASS} changes within the sequence ({sorted(ids)})")
    return ids.pop()


def collect_sequence(
    log: Path,
    config: CldetConfig,
    *,
    truth_topic: str | None = None,
    progress: Progress | None = None,
) -> SequenceSample:
    """Run the per-frame pass over ``log`` and label its candidate tracks against the truth.

    Raises:
        TrainError: the log has no ground truth, or its class changes within it.
        LogError, CorruptMessageError: the log cannot be read.
    """
    progress = progress or NullProgress()
    with open_log(log) as reader:
        sensors = select_topics(reader, None, None, truth_topic)
        n_frames = reader.list_topics().get(sensors.lidar, 0)
    truth_ns, truth_xyz = _read_truth(log, sensors.truth)
    class_id = _read_class(log)
    estimator = TrackEstimator(config)
    progress.start(n_frames, f"{log.name}: tracking")
    for frame in read_frames(log, sensors, config.frames):
        estimator.register_frame(frame)
        progress.advance()
    return label_candidates(log, estimator.candidates(), truth_ns, truth_xyz, class_id, config)


def label_candidates(
    log: Path,
    cand: Candidates,
    truth_ns: NDArray[np.int64],
    truth_xyz: NDArray[np.float64],
    class_id: int | None,
    config: CldetConfig,
) -> SequenceSample:
    """One sequence's candidate tracks (from the per-frame pass with ``config``), matched to
    its truth (``truth_ns`` (G,) sorted, ``truth_xyz`` (G,3)): features, labels, the drone
    tracks' detections and prefixes (see the module docstring). ``log`` names the sequence."""
    offset_ns = int(round(config.frames.scan_offset_s * NS_PER_S))
    sample = SequenceSample(log, cand, truth_ns, truth_xyz, class_id)
    feats, hits, labels, pair_ns, pair_xyz, prefixes = [], [], [], [], [], []
    tc = config.tracking
    for rec in cand.records:
        if len(rec.frames) < 2:
            continue
        det = track_detections(rec, cand.tables, tc)
        times = cand.times_s[rec.frames]
        feats.append(track_features(rec, det, times))
        hits.append(float(len(rec.frames)))
        stamps = cand.stamps_ns[rec.frames]
        d = np.linalg.norm(rec.positions - sample.truth_at(stamps + offset_ns), axis=1)
        d = d[np.isfinite(d)]
        label = -1
        if len(d) >= 2:
            med = float(np.median(d))
            label = 1 if med <= DRONE_M else 0 if med > CLUTTER_M else -1
        labels.append(label)
        if label == 1:
            keep = ~rec.raw
            pair_ns.append(stamps[keep])
            pair_xyz.append(rec.positions[keep])
            # annotate types a chain from its growing evidence: learn from the same prefixes
            for upto in (*range(_PREFIX_STEP, len(rec.frames), _PREFIX_STEP), len(rec.frames)):
                prefixes.append(track_features(rec, det, times, upto))
    if feats:
        sample.features = np.array(feats)
        sample.hits = np.array(hits)
        sample.labels = np.array(labels, dtype=np.int8)
    if prefixes:
        sample.type_features = np.array(prefixes)
    if pair_ns:
        sample.pair_ns = np.concatenate(pair_ns)
        sample.pair_xyz = np.concatenate(pair_xyz)
    return sample


# ---------------------------------------------------------------------------- fitting


def fit_scan_offset(samples: Sequence[SequenceSample]) -> tuple[float, float, float]:
    """The scan-time offset (s) at which the drone tracks' centroids best match the truth, and
    the RMS distance (m) of those pairs at 0 and at the fitted offset (pairs within 1 m)."""
    errors = []
    for off in _OFFSETS_S:
        sq = []
        for s in samples:
            if len(s.pair_ns) == 0:
                continue
            t = s.truth_at(s.pair_ns + int(round(off * NS_PER_S)))
            d2 = np.sum((s.pair_xyz - t) ** 2, axis=1)
            sq.append(np.minimum(d2[np.isfinite(d2)], _MAX_PAIR_M**2))
        allsq = np.concatenate(sq) if sq else np.zeros(0)
        errors.append(float(np.mean(allsq)) if len(allsq) else float("nan"))
    err = np.array(errors)
    if not np.isfinite(err).any():
        raise TrainError("no drone detections matched to the truth: cannot fit the scan offset")
    k = int(np.nanargmin(err))
    return float(_OFFSETS_S[k]), float(np.sqrt(err[0])), float(np.sqrt(err[k]))


def fit_centroid_bias(samples: Sequence[SequenceSample], offset_s: float) -> BiasConfig:
    """The centroid bias (``cldet.core.bias``) from the drone tracks' centroids and the truth at
    their points' time."""
    off = int(round(offset_s * NS_PER_S))
    sequences = []
    for s in samples:
        dets = [
            Estimate(int(t) + off, p, Source.DETECTED, 1, 0.0)
            for t, p in zip(s.pair_ns, s.pair_xyz, strict=True)
        ]
        truth = [PositionSample(int(t), p) for t, p in zip(s.truth_ns, s.truth_xyz, strict=True)]
        sequences.append((dets, truth))
    return fit_bias_sequences(sequences)


def _balanced_weights(labels: NDArray[np.int64], hits: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each example weighted by its detections, every class carrying the same total weight."""
    w = hits.astype(np.float64).copy()
    for c in np.unique(labels):
        m = labels == c
        w[m] *= len(labels) / (len(np.unique(labels)) * w[m].sum())
    return w


def _measured(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """``x`` with every column that is never measured (all NaN: e.g. the two LiDARs' ratio in
    logs without an Avia) set to 0: the trees cannot bin an empty column, and a constant one
    is simply never split on (at prediction a NaN there follows the trees' default branch)."""
    empty = np.isnan(x).all(axis=0)
    if not empty.any():
        return x
    x = x.copy()
    x[:, empty] = 0.0
    return x


def fit_scorer(samples: Sequence[SequenceSample]) -> Any:
    """Gradient-boosted drone-vs-clutter trees over the labelled tracks of ``samples``."""
    return fit_track_scorer(
        np.concatenate([s.features for s in samples]),
        np.concatenate([s.labels for s in samples]).astype(np.int64),
        np.concatenate([s.hits for s in samples]),
    )


def fit_track_scorer(x: NDArray[np.float64], y: NDArray[np.int64], h: NDArray[np.float64]) -> Any:
    """Gradient-boosted drone-vs-clutter trees over tracks' features ``x`` (T, F), labels
    ``y`` (T,: 1 drone, 0 clutter, -1 left out) and detections ``h`` (T,)."""
    from sklearn.ensemble import HistGradientBoostingClassifier

    keep = y >= 0
    x, y, h = x[keep], y[keep], h[keep]
    if len(np.unique(y)) < 2:
        raise TrainError("the candidate tracks are all drone or all clutter: nothing to tell apart")
    with one_thread():
        return HistGradientBoostingClassifier(**_TREE_PARAMS).fit(
            _measured(x), y, sample_weight=_balanced_weights(y, h)
        )


def fit_typer(samples: Sequence[SequenceSample], class_ids: list[int]) -> Any:
    """Gradient-boosted drone-type trees over the drone tracks' prefixes of ``samples`` (labels
    are indices into ``class_ids``; every class carries the same total weight)."""
    from sklearn.ensemble import HistGradientBoostingClassifier

    xs, ys = [], []
    for s in samples:
        if s.class_id is None or len(s.type_features) == 0:
            continue
        xs.append(s.type_features)
        ys.append(np.full(len(s.type_features), class_ids.index(s.class_id)))
    y = np.concatenate(ys) if ys else np.zeros(0, dtype=np.int64)
    if len(np.unique(y)) < 2:
        raise TrainError("the drone tracks cover fewer than two classes: cannot learn the type")
    with one_thread():
        return HistGradientBoostingClassifier(**_TYPE_TREE_PARAMS).fit(
            _measured(np.concatenate(xs)[:, TYPE_COLUMNS]),
            y,
            sample_weight=_balanced_weights(y, np.ones(len(y))),
        )


def fit_model(
    samples: Sequence[SequenceSample],
    *,
    with_timing: bool = True,
    info: dict[str, Any] | None = None,
) -> LearnedModel:
    """Every part of the model from ``samples`` (see the module docstring).

    Raises:
        TrainError: too few drone detections, a single class of tracks.
    """
    n_pairs = sum(len(s.pair_ns) for s in samples)
    if n_pairs < MIN_DRONE_DETECTIONS:
        raise TrainError(
            f"only {n_pairs} drone detections matched to the truth in {len(samples)} log(s)"
            f" (at least {MIN_DRONE_DETECTIONS} needed): " + ", ".join(str(s.log) for s in samples)
        )
    offset, rms0, rms1 = fit_scan_offset(samples) if with_timing else (0.0, 0.0, 0.0)
    bias = fit_centroid_bias(samples, offset) if with_timing else BiasConfig()
    class_ids = sorted({s.class_id for s in samples if s.class_id is not None})
    typer = fit_typer(samples, class_ids) if len(class_ids) >= 2 else None
    meta = dict(info or {})
    meta.update({"offset_rms_m": [rms0, rms1], "logs": len(samples), "drone_detections": n_pairs})
    return LearnedModel(
        scan_offset_s=offset,
        bias_along_ray_m=bias.along_ray_m,
        bias_z_m=bias.z_m,
        scorer=fit_scorer(samples),
        typer=typer,
        class_ids=class_ids if typer is not None else [],
        info=meta,
    )


# -------------------------------------------------------------------- cross-validation


@dataclass(frozen=True)
class FoldResult:
    """One held-out log of the cross-validation."""

    log: Path
    true_class: int | None
    predicted_class: int | None
    rows: int  # truth rows scored
    mse_default: float  # per coordinate, m^2
    mse_learned: float
    fails_default: bool  # RMS over 1 m
    fails_learned: bool
    mse_unscored: float  # the learned timing and bias without the learned scorer
    fails_unscored: bool
    predicted_unscored: int | None  # the type voted over the chain chosen without the scorer


def _fails(mse: float) -> bool:
    """Whether a sequence with this MSE per coordinate is off by more than 1 m (3D RMS)."""
    return bool(np.sqrt(3 * mse) > 1.0)


@dataclass(frozen=True)
class FoldTotals:
    """The held-out logs' position error summed over the folds: MSE per coordinate (rows
    weighted) and sequences off by more than 1 m, for the default, the learned model and the
    learned model without its scorer."""

    mse_default: float
    mse_learned: float
    mse_unscored: float
    fails_default: int
    fails_learned: int
    fails_unscored: int

    @staticmethod
    def of(folds: Sequence[FoldResult]) -> FoldTotals:
        """The totals of ``folds`` (at least one)."""
        rows = np.array([f.rows for f in folds], dtype=np.float64)

        def mse(values: list[float]) -> float:
            return float(np.average(values, weights=rows))

        return FoldTotals(
            mse([f.mse_default for f in folds]),
            mse([f.mse_learned for f in folds]),
            mse([f.mse_unscored for f in folds]),
            sum(f.fails_default for f in folds),
            sum(f.fails_learned for f in folds),
            sum(f.fails_unscored for f in folds),
        )


def _mse(sample: SequenceSample, estimates: Sequence[Estimate]) -> float:
    stamps = np.array([e.stamp_ns for e in estimates], dtype=np.int64)
    pos = np.array([e.position for e in estimates], dtype=np.float64)
    at = evaluate_trajectory(stamps, pos, sample.truth_ns)
    return float(np.mean((at - sample.truth_xyz) ** 2))


def cross_validate(
    samples: Sequence[SequenceSample], config: CldetConfig, progress: Progress | None = None
) -> list[FoldResult]:
    """Leave one sequence out: fit on the others, refine and type the held-out one.

    The three refinements (default; learned; learned without its scorer) use the held-out log's
    candidates with the scan offset of the pass that made them; the learned ones apply the
    learned centroid bias, the default one the configuration's.
    """
    progress = progress or NullProgress()
    progress.start(len(samples), "cross-validation")
    out = []
    for i, held in enumerate(samples):
        rest = [s for j, s in enumerate(samples) if j != i]
        model = fit_model(rest)
        learned_cfg = config.model_copy(
            update={"bias": BiasConfig(along_ray_m=model.bias_along_ray_m, z_m=model.bias_z_m)}
        )
        default = refine_candidates(held.cand, config)
        learned = refine_candidates(held.cand, learned_cfg, model)
        unscored = refine_candidates(held.cand, learned_cfg, replace(model, scorer=None))
        predicted = learned.classes[-1].class_id if learned.classes else None
        predicted_u = unscored.classes[-1].class_id if unscored.classes else None
        mse_d, mse_l = _mse(held, default.estimates), _mse(held, learned.estimates)
        mse_u = _mse(held, unscored.estimates)
        out.append(
            FoldResult(
                held.log,
                held.class_id,
                predicted,
                len(held.truth_ns),
                mse_d,
                mse_l,
                _fails(mse_d),
                _fails(mse_l),
                mse_u,
                _fails(mse_u),
                predicted_u,
            )
        )
        progress.advance()
    return out


SCORER_MIN_GAIN: Final = 0.05
"""The least fraction of the held-out position MSE the learned scorer must remove, where it
leaves as many held-out logs off by over 1 m, to be kept (see :func:`scorer_earns_its_place`)."""


def scorer_earns_its_place(folds: Sequence[FoldResult]) -> bool:
    """Whether the learned drone-vs-clutter scorer clearly improved the held-out logs'
    refinement over the learned timing and bias alone: fewer sequences off by over 1 m, or as
    many and a position MSE (rows weighted) at least :data:`SCORER_MIN_GAIN` lower. A scorer
    fitted on a few logs can learn their accidents, and a tie on a few dozen held-out logs is
    no evidence that it helps; without it the packaged prior still weighs the tracks (where
    ``tracking.prior_scorer`` is on, the default). No cross-validation (``folds`` empty): kept
    as trained. A fold whose MSE is not finite counts against it."""
    if not folds:
        return True
    t = FoldTotals.of(folds)
    if t.fails_learned != t.fails_unscored:
        return t.fails_learned < t.fails_unscored
    return t.mse_learned <= (1.0 - SCORER_MIN_GAIN) * t.mse_unscored


# ---------------------------------------------------------------------------- command


@dataclass(frozen=True)
class TrainReport:
    """What ``train_logs`` did."""

    model: LearnedModel
    folds: list[FoldResult]
    seconds: float

    def describe(self) -> str:
        """The cross-validation report for the terminal."""
        m = self.model
        lines = [
            f"scan-time offset {m.scan_offset_s * 1000:.1f} ms after the stamp (drone centroid vs"
            f" truth RMS {m.info['offset_rms_m'][0]:.3f} m at 0 ms -> {m.info['offset_rms_m'][1]:.3f} m);"
            f" centroid bias along the ray {m.bias_along_ray_m:+.3f} m, in z {m.bias_z_m:+.3f} m",
        ]
        if self.folds:
            n = len(self.folds)
            t = FoldTotals.of(self.folds)
            lines.append(
                f"leave-one-sequence-out over {n} logs: position MSE per coordinate default"
                f" {t.mse_default:.4f} m^2 -> learned {t.mse_learned:.4f} m^2 (without the"
                f" learned scorer {t.mse_unscored:.4f}); sequences off by more than 1 m (RMS):"
                f" default {t.fails_default}, learned {t.fails_learned} (without the scorer"
                f" {t.fails_unscored})"
            )
            dropped = m.info.get("scorer") == "dropped"
            if dropped:
                lines.append(
                    "the learned drone-vs-clutter scorer did not clearly improve the held-out"
                    " logs: not kept (the model keeps the timing, the bias and the type"
                    " classifier)"
                )
            typed = [f for f in self.folds if f.true_class is not None]
            true = [int(f.true_class) for f in typed if f.true_class is not None]
            # no chain, no type: counted wrong (and left out of the matrix)
            # the type of the chain the written model picks: with or without its scorer
            voted = [f.predicted_unscored if dropped else f.predicted_class for f in typed]
            pred = [-1 if v is None else v for v in voted]
            if typed and m.class_ids:
                w = np.array([f.rows for f in typed], dtype=np.float64)
                ok = np.array([t == p for t, p in zip(true, pred, strict=True)], dtype=np.float64)
                lines.append(
                    f"drone type: per-row accuracy {float(np.average(ok, weights=w)):.3f}"
                    f" ({int(ok.sum())}/{len(typed)} sequences)"
                )
                lines.append(
                    confusion_text(
                        true,
                        pred,
                        m.class_ids,
                        weights=[f.rows for f in typed],
                    )
                )
        lines.append(f"trained in {self.seconds:.1f} s")
        return "\n".join(lines)


def _collect_job(job: tuple[Path, CldetConfig], progress: Progress) -> SequenceSample:
    """:func:`collect_sequence` on one log (runs in a worker process or a Ray task)."""
    log, config = job
    return collect_sequence(log, config)


def _collect_all(
    logs: list[Path],
    config: CldetConfig,
    make: Callable[[], Progress],
    workers: int | None,
    executor: str,
    ray_address: str | None,
) -> list[SequenceSample]:
    """Every log's sample, in the order given; in this process (per-frame progress) or in
    parallel (per-log progress). An error of one log is raised, as in one process."""
    if runs_here(len(logs), workers, executor):
        return [collect_sequence(log, config, progress=make()) for log in logs]
    progress = make()
    progress.start(len(logs), "training passes")
    samples: dict[int, SequenceSample] = {}
    outcomes = iter_outcomes(
        _collect_job,
        [(log, config) for log in logs],
        workers=workers,
        executor=executor,
        ray_address=ray_address,
        costs=[file_size(log) for log in logs],  # the longest logs first
    )
    with closing(outcomes):
        for outcome in outcomes:
            if outcome.result is None:
                outcome.raise_error()
            samples[outcome.index] = outcome.result
            progress.advance()
    return [samples[i] for i in range(len(logs))]


def train_logs(
    logs: Sequence[Path],
    out: Path,
    *,
    config: CldetConfig | None = None,
    cross_validation: bool = True,
    overwrite: bool = False,
    progress_factory: Callable[[], Progress] | None = None,
    warn: Callable[[str], None] = lambda _: None,
    workers: int | None = 1,
    executor: str = "local",
    ray_address: str | None = None,
) -> TrainReport:
    """Learn a model from labelled ``logs`` and write it to ``out`` (atomically).

    The logs' passes (most of the work) run in ``workers`` processes (None: one per CPU), or as
    Ray tasks with ``executor="ray"`` (None: as many at once as the cluster has CPUs; see
    :mod:`cldet.executors`); the model is the same either way.

    Raises:
        TrainError: no logs, no truth, too few detections, one class of tracks only.
        OutputError: ``out`` exists (without ``overwrite``) or cannot be written.
    """
    started = time.perf_counter()
    config = config or CldetConfig()
    if config.method != "track":
        raise TrainError(f"training learns for the `track` method, not {config.method!r}")
    if any(v != 0.0 for v in (config.bias.along_ray_m, config.bias.z_m)):
        config = config.model_copy(update={"bias": BiasConfig()})
        warn("the configuration's bias is ignored: training fits it from the truth")
    if not logs:
        raise TrainError("no training logs given")
    check_output(out, "model")  # fail before the work, not after
    if Path(out).exists() and not overwrite:
        raise OutputExistsError(f"{out} already exists: pass overwrite (--overwrite) to replace it")
    make = progress_factory or NullProgress
    samples = _collect_all(
        [Path(log) for log in logs], config, make, workers, executor, ray_address
    )
    for s in samples:
        if not (s.labels == 1).any():
            warn(
                f"{s.log}: no candidate track follows the truth (the drone is not learned from it)"
            )
    classes = {s.class_id for s in samples if s.class_id is not None}
    unlabelled = [s.log for s in samples if s.class_id is None]
    if classes and unlabelled:
        warn(f"{len(unlabelled)} log(s) without {topics.CLASS}: {', '.join(map(str, unlabelled))}")
    if len(classes) == 1:
        warn(f"every labelled log is class {classes.pop()}: no drone-type classifier is learned")
    info = {
        "trained_on": [Path(s.log).name for s in samples],
        "scan_offset_of_pass_s": config.frames.scan_offset_s,
    }
    model = fit_model(samples, info=info)
    folds = (
        cross_validate(samples, config, make()) if cross_validation and len(samples) >= 3 else []
    )
    if cross_validation and len(samples) < 3:
        warn("cross-validation needs three logs or more: skipped")
    if model.scorer is not None and not scorer_earns_its_place(folds):
        model = replace(model, scorer=None, info={**model.info, "scorer": "dropped"})
    write_model(model, out, overwrite=overwrite)
    return TrainReport(model, folds, time.perf_counter() - started)
