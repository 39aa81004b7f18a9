"""``cldet train``: what it learns from labelled logs, the model file's safety, and its use by
``annotate --model``, ``export`` and ``evaluate``."""

from __future__ import annotations

import json
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cldet.cli import app
from cldet.config import CldetConfig
from cldet.core.features import FEATURE_NAMES, TYPE_FEATURES
from cldet.core.model import LearnedModel
from cldet.errors import OutputExistsError
from cldet.io import topics
from cldet.io.mcap_read import open_log
from cldet.modelfile import ModelError, load_model, model_bytes, write_model
from cldet.train import (
    FoldResult,
    SequenceSample,
    TrainError,
    collect_sequence,
    fit_scan_offset,
    fit_typer,
    scorer_earns_its_place,
    train_logs,
)

runner = CliRunner()

# two airframes far apart in size (Mavic 3 and M300), close passes: the types are separable
CLASSES = (0, 2, 0, 2)


@pytest.fixture(scope="module")
def train_logs_(
    tmp_path_factory: pytest.TempPathFactory, make_log: Callable[..., Path]
) -> list[Path]:
    root = tmp_path_factory.mktemp("train")
    return [
        make_log(root, 700 + i, "close_pass", duration_s=4.0, class_id=c)
        for i, c in enumerate(CLASSES)
    ]


@pytest.fixture(scope="module")
def trained(train_logs_: list[Path], tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    out = tmp_path_factory.mktemp("model") / "model.zip"
    warnings: list[str] = []
    report = train_logs(train_logs_, out, warn=warnings.append)
    return out, report.describe()


def test_train_writes_a_model_that_loads_with_what_it_learned(trained: tuple[Path, str]) -> None:
    path, text = trained
    model = load_model(path)
    assert 0.0 <= model.scan_offset_s <= 0.1
    assert abs(model.bias_along_ray_m) < 0.5 and abs(model.bias_z_m) < 0.5
    assert model.typer is not None
    # the drone-vs-clutter scorer is kept only where the cross-validation showed a clear gain
    assert (model.scorer is None) == ("scorer did not clearly improve" in text)
    assert model.class_ids == [0, 2]
    # the cross-validation report: every log held out once, the type's confusion matrix
    assert "leave-one-sequence-out over 4 logs" in text
    assert "without the learned scorer" in text
    assert "per-row accuracy" in text and "true \\ predicted" in text


def _fold(rows: int, with_scorer_m: float, without_m: float) -> FoldResult:
    """A held-out log whose refinement missed by an RMS of ``with_scorer_m`` with the learned
    scorer and ``without_m`` with the learned timing and bias alone."""
    mse_l, mse_u = with_scorer_m**2 / 3, without_m**2 / 3
    return FoldResult(
        Path("a.mcap"),
        None,
        None,
        rows,
        mse_u,
        mse_l,
        without_m > 1,
        with_scorer_m > 1,
        mse_u,
        without_m > 1,
        None,
    )


def test_the_scorer_is_kept_only_where_the_held_out_logs_were_clearly_better_with_it() -> None:
    mended = [_fold(100, 0.2, 0.2), _fold(100, 0.3, 9.0)]  # it mended one log
    assert scorer_earns_its_place(mended)
    broke_one = [_fold(100, 0.2, 0.2), _fold(100, 16.5, 0.3)]  # it broke one
    assert not scorer_earns_its_place(broke_one)
    # as many failures: kept only where it brought them clearly nearer (rows weigh the error)
    assert scorer_earns_its_place([_fold(100, 0.2, 0.2), _fold(300, 8.0, 12.0)])
    assert not scorer_earns_its_place([_fold(100, 0.2, 0.2), _fold(300, 20.0, 12.0)])
    assert not scorer_earns_its_place([_fold(100, 0.2, 0.2), _fold(300, 12.0, 12.05)])  # a tie
    assert scorer_earns_its_place([])  # no cross-validation: no evidence, kept as trained


def test_collect_labels_the_drone_track_against_the_truth(train_logs_: list[Path]) -> None:
    sample = collect_sequence(train_logs_[0], CldetConfig())
    assert sample.class_id == CLASSES[0]
    assert (sample.labels == 1).any() and (sample.labels == 0).any()
    assert sample.features.shape[1] == len(FEATURE_NAMES)
    # the drone's detections lie within a metre of the truth (their label says so)
    truth = sample.truth_at(sample.pair_ns + 50_000_000)
    d = np.linalg.norm(sample.pair_xyz - truth, axis=1)
    assert np.median(d[np.isfinite(d)]) < 1.0


def test_annotate_with_model_writes_class_and_export_uses_it(
    trained: tuple[Path, str], train_logs_: list[Path], tmp_path: Path
) -> None:
    path, _ = trained
    out = tmp_path / "annotated.mcap"
    result = runner.invoke(
        app, ["annotate", str(train_logs_[1]), "-o", str(out), "--no-rrd", "--model", str(path)]
    )
    assert result.exit_code == 0, result.output
    with open_log(out) as log:
        classes = list(log.iter_class_estimates(topics.CLASS_ESTIMATE))
        meta = log.metadata()[topics.METADATA_CONFIG]
    assert classes, "no /cldet/class message"
    for c in classes:
        assert c.class_ids == (0, 2)
        assert abs(sum(c.probabilities) - 1.0) < 1e-9
        assert c.class_id == c.class_ids[int(np.argmax(c.probabilities))]
    assert json.loads(meta["model"])["class_ids"] == [0, 2]
    final = classes[-1].class_id
    csv = tmp_path / "results.csv"
    result = runner.invoke(app, ["export", str(out), "-o", str(csv)])
    assert result.exit_code == 0, result.output
    rows = csv.read_text().splitlines()[1:]
    assert rows and all(r.rsplit(",", 1)[1] == str(final) for r in rows)
    result = runner.invoke(app, ["evaluate", str(csv), "--logs", str(out)])
    assert result.exit_code == 0, result.output
    assert "drone type confusion" in result.output


def test_without_model_no_class_channel_and_the_constant_class(
    train_logs_: list[Path], tmp_path: Path
) -> None:
    out = tmp_path / "annotated.mcap"
    assert (
        runner.invoke(app, ["annotate", str(train_logs_[0]), "-o", str(out), "--no-rrd"]).exit_code
        == 0
    )
    with open_log(out) as log:
        assert topics.CLASS_ESTIMATE not in log.list_topics()
    csv = tmp_path / "results.csv"
    assert runner.invoke(app, ["export", str(out), "-o", str(csv)]).exit_code == 0
    assert all(r.endswith(",0") for r in csv.read_text().splitlines()[1:])


def test_scan_offset_is_fitted_from_a_moving_drone() -> None:
    # a drone at 10 m/s whose detections show where it was 30 ms after each stamp
    truth_ns = np.arange(0, 4_000_000_000, 50_000_000, dtype=np.int64)
    truth_xyz = np.column_stack(
        [10.0 * truth_ns / 1e9, np.full(len(truth_ns), 8.0), np.full(len(truth_ns), 5.0)]
    )
    stamps = np.arange(100_000_000, 3_800_000_000, 100_000_000, dtype=np.int64)
    det = np.column_stack(
        [10.0 * (stamps + 30_000_000) / 1e9, np.full(len(stamps), 8.0), np.full(len(stamps), 5.0)]
    )
    sample = _sample(truth_ns, truth_xyz, stamps, det)
    offset, rms0, rms1 = fit_scan_offset([sample])
    assert offset == pytest.approx(0.03, abs=0.0026)
    assert rms0 == pytest.approx(0.3, abs=0.01) and rms1 < 0.03


def _sample(
    truth_ns: np.ndarray, truth_xyz: np.ndarray, pair_ns: np.ndarray, pair_xyz: np.ndarray
) -> SequenceSample:
    from cldet.core.estimator import Candidates

    empty = Candidates([], [], np.zeros(0), np.zeros(0, dtype=np.int64))
    return SequenceSample(
        Path("synthetic.mcap"), empty, truth_ns, truth_xyz, None, pair_ns=pair_ns, pair_xyz=pair_xyz
    )


def test_type_classifier_votes_over_tracks_and_maps_class_ids() -> None:
    rng = np.random.default_rng(0)
    cross = FEATURE_NAMES.index("log_cross_med")
    samples = []
    for cls, level in ((7, -1.0), (3, -0.2)):  # ids are whatever the logs use
        for _ in range(3):
            s = _sample(
                np.zeros(2, np.int64), np.zeros((2, 3)), np.zeros(0, np.int64), np.zeros((0, 3))
            )
            s.class_id = cls
            s.type_features = rng.normal(0.0, 0.05, (40, len(FEATURE_NAMES)))
            s.type_features[:, cross] += level
            # a Mid-360 alone (no Avia): the two LiDARs' ratio is never measured
            s.type_features[:, FEATURE_NAMES.index("log_mid_avia_med")] = np.nan
            samples.append(s)
    model = LearnedModel(0.05, 0.0, 0.0, typer=fit_typer(samples, [3, 7]), class_ids=[3, 7])
    small = np.zeros((2, len(FEATURE_NAMES)))
    small[:, cross] = -1.0
    big = np.zeros((1, len(FEATURE_NAMES)))
    big[:, cross] = -0.2
    # group 0: two small-looking tracks; group 1: one of each, the big one with more detections
    feats = np.vstack([small, small[:1], big])
    p = model.type_probabilities(feats, np.array([10.0, 5.0, 2.0, 30.0]), np.array([0, 0, 1, 1]))
    assert p.shape == (2, 2) and np.allclose(p.sum(axis=1), 1.0)
    assert model.class_ids[int(np.argmax(p[0]))] == 7
    assert model.class_ids[int(np.argmax(p[1]))] == 3


# ------------------------------------------------------------------ the model file is safe


def _tiny_model() -> LearnedModel:
    return LearnedModel(0.04, 0.1, 0.12, info={"trained_on": ["a.mcap"]})


def test_model_file_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "m.zip"
    write_model(_tiny_model(), path)
    back = load_model(path)
    assert (back.scan_offset_s, back.bias_along_ray_m, back.bias_z_m) == (0.04, 0.1, 0.12)
    assert back.scorer is None and back.typer is None
    with pytest.raises(OutputExistsError, match="exists"):
        write_model(_tiny_model(), path)


def _rewrite(path: Path, meta_update: dict | None = None, blob: bytes | None = None) -> None:
    with zipfile.ZipFile(path) as z:
        meta = json.loads(z.read("model.json"))
        old_blob = z.read("estimators.skops")
    meta.update(meta_update or {})
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("model.json", json.dumps(meta))
        z.writestr("estimators.skops", old_blob if blob is None else blob)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"format": 999}, "model format 999"),
        ({"feature_names": ["height_med_m"]}, "features do not match"),
        ({"type_feature_names": list(TYPE_FEATURES[:-1])}, "features do not match"),
        ({"kind": "something-else"}, "not a cldet model"),
    ],
)
def test_model_of_another_version_or_features_is_refused(
    tmp_path: Path, change: dict, message: str
) -> None:
    path = tmp_path / "m.zip"
    path.write_bytes(model_bytes(_tiny_model()))
    _rewrite(path, change)
    with pytest.raises(ModelError, match=message) as info:
        load_model(path)
    assert str(path) in str(info.value)


def test_corrupt_or_untrusted_model_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "m.zip"
    path.write_bytes(model_bytes(_tiny_model())[:100])
    with pytest.raises(ModelError, match="corrupt"):
        load_model(path)
    # estimators that are not what skops trusts (here: a pickled object) are never rebuilt
    import skops.io as sio

    path.write_bytes(model_bytes(_tiny_model()))
    _rewrite(path, blob=sio.dumps({"scorer": Path("x"), "typer": None}))
    with pytest.raises(ModelError, match="cannot be read safely"):
        load_model(path)
    with pytest.raises(ModelError, match="no such model file"):
        load_model(tmp_path / "missing.zip")


def test_cli_bad_model_is_one_line_error(train_logs_: list[Path], tmp_path: Path) -> None:
    bad = tmp_path / "bad.zip"
    bad.write_bytes(b"not a zip")
    result = runner.invoke(
        app, ["annotate", str(train_logs_[0]), "-o", str(tmp_path / "o.mcap"), "--model", str(bad)]
    )
    assert result.exit_code == 1
    assert result.output.startswith("ERROR: ") and str(bad) in result.output
    assert "Traceback" not in result.output


# ------------------------------------------------------------------ bad training input


def test_training_logs_without_truth_are_named(
    make_log: Callable[..., Path], tmp_path: Path
) -> None:
    from cldet.io.mcap_write import LogWriter

    log = tmp_path / "no_truth.mcap"
    with open(log, "wb") as f, LogWriter(f) as w:
        w.write_cloud(
            topics.LIDAR_360, 1_000_000_000, np.zeros((3, 3), np.float32), topics.FRAME_MID360
        )
    with pytest.raises(TrainError, match="no ground truth") as info:
        train_logs([log], tmp_path / "m.zip")
    assert str(log) in str(info.value)
    result = runner.invoke(app, ["train", str(log), "-o", str(tmp_path / "m.zip")])
    assert result.exit_code == 1 and result.output.startswith("ERROR: ")
    assert not (tmp_path / "m.zip").exists()


def test_one_class_warns_and_learns_no_type(train_logs_: list[Path], tmp_path: Path) -> None:
    warnings: list[str] = []
    report = train_logs(
        [train_logs_[0], train_logs_[2]],
        tmp_path / "m.zip",
        cross_validation=False,
        warn=warnings.append,
    )
    assert report.model.typer is None and report.model.class_ids == []
    assert any("every labelled log is class 0" in w for w in warnings)


def test_existing_output_refused_before_any_work(train_logs_: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "m.zip"
    out.write_bytes(b"keep me")
    with pytest.raises(OutputExistsError, match="already exists"):
        train_logs(train_logs_, out)
    assert out.read_bytes() == b"keep me"


def test_training_in_parallel_learns_the_same_model(
    train_logs_: list[Path], trained: tuple[Path, str], tmp_path: Path
) -> None:
    """The logs' passes in two worker processes: the same samples, so the same model (without
    a cross-validation the scorer is kept as trained, and read back from the file)."""
    out = tmp_path / "parallel.zip"
    report = train_logs(train_logs_, out, workers=2, cross_validation=False)
    alone = train_logs(train_logs_, tmp_path / "alone.zip", cross_validation=False).model
    together = load_model(out)
    assert report.model.scan_offset_s == alone.scan_offset_s == together.scan_offset_s
    assert (together.bias_along_ray_m, together.bias_z_m) == (
        alone.bias_along_ray_m,
        alone.bias_z_m,
    )
    assert together.class_ids == alone.class_ids
    assert together.scorer is not None and alone.scorer is not None
    rng = np.random.default_rng(1)
    feats = rng.normal(0.0, 1.0, (20, len(FEATURE_NAMES)))
    np.testing.assert_array_equal(together.drone_probability(feats), alone.drone_probability(feats))
    groups = np.arange(20) % 2
    np.testing.assert_array_equal(
        together.type_probabilities(feats, np.ones(20), groups),
        alone.type_probabilities(feats, np.ones(20), groups),
    )
    # the cross-validated model of the same logs: the same type classifier, whatever it decided
    # for the scorer
    np.testing.assert_array_equal(
        load_model(trained[0]).type_probabilities(feats, np.ones(20), groups),
        alone.type_probabilities(feats, np.ones(20), groups),
    )
