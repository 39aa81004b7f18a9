"""converters.mmaud: the streaming reader of the challenge layout, on real and synthetic folders."""

from __future__ import annotations

import warnings
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from cldet.errors import DatasetError
from cldet.types import ClassSample, Cloud, ImageFrame, PositionSample
from converters.mmaud import (
    CLOUD_MODALITIES,
    MODALITIES,
    PNG_SIGNATURE,
    SPLITS,
    SequenceRef,
    count_frames,
    find_sequences,
    iter_classes,
    iter_clouds,
    iter_ground_truth,
    iter_images,
    iter_positions,
    iter_sequence,
    list_stamped_files,
    load_cloud,
)

# --------------------------------------------------------------------------- helpers

FAKE_PNG = PNG_SIGNATURE + b"\x00\x00\x00\rIHDR fake image body"


def save(path: Path, array: NDArray[np.generic]) -> Path:
    """Write one .npy file (creating its folder) and return its path."""
    path.parent.mkdir(parents=True, exist_ok=True)
    np.save(path, array)
    return path


def raw_valid_rows(array: NDArray[np.float64]) -> NDArray[np.float32]:
    """The reference answer for load_cloud, computed the obvious (slow) way."""
    if array.ndim == 1:
        return np.empty((0, 3), dtype=np.float32)
    return array[np.any(array != 0, axis=1)].astype(np.float32)


def quiet_find(root: Path, **kwargs: object) -> list[SequenceRef]:
    """find_sequences, failing the test on any warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return find_sequences(root, **kwargs)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- synthetic layout

T0 = 1_706_255_621  # seconds


def ns(seconds: int, micros: int) -> int:
    return seconds * 1_000_000_000 + micros * 1_000


@pytest.fixture()
def layout(tmp_path: Path) -> Path:
    """A tiny dataset: train/seq1 (every modality), train/seq0002, val/seq0001, test/seq0003."""
    root = tmp_path / "data"
    seq = root / "train" / "seq1"
    cloud = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0], [4.0, 5.0, 6.0]])
    save(seq / "lidar_360" / f"{T0}.100000.npy", cloud)
    save(seq / "lidar_360" / f"{T0}.200000.npy", cloud * 2)
    save(seq / "livox_avia" / f"{T0}.114000.npy", np.array([[-0.0, -0.0, 0.0], [0.5, 0.5, 9.0]]))
    save(seq / "ground_truth" / f"{T0}.065000.npy", np.array([0.1, 0.2, 0.3]))
    save(seq / "ground_truth" / f"{T0}.1.npy", np.array([1.1, 1.2, 1.3]))  # ties lidar .100000
    save(seq / "class" / f"{T0}.065000.npy", np.array([2], dtype=np.int64))
    save(seq / "class" / f"{T0}.100000.npy", np.array([2, 0, 0], dtype=np.int32))
    (seq / "Image").mkdir()
    (seq / "Image" / f"{T0}.133333.png").write_bytes(FAKE_PNG)
    save(root / "train" / "seq0002" / "lidar_360" / f"{T0 + 50}.000000.npy", cloud)
    save(root / "val" / "seq0001" / "lidar_360" / f"{T0 + 99}.000001.npy", cloud)
    save(root / "val" / "seq0001" / "radar_enhance_pcl" / f"{T0 + 99}.010000.npy", np.zeros((0,)))
    save(root / "test" / "seq0003" / "livox_avia" / f"{T0 + 200}.0.npy", cloud)
    (root / "test" / "test_timestamps.csv").write_text("Sequence,Timestamp\n")  # a file: ignored
    return root


@pytest.fixture()
def train_seq(layout: Path) -> SequenceRef:
    return quiet_find(layout, splits=["train"], sequences=["seq0001"])[0]


def test_find_sequences_sorted_by_split_then_name(layout: Path) -> None:
    found = quiet_find(layout)
    assert [(s.split, s.name) for s in found] == [
        ("train", "seq0001"),
        ("train", "seq0002"),
        ("val", "seq0001"),
        ("test", "seq0003"),
    ]
    first = found[0]
    assert first.path == layout / "train" / "seq1"  # the folder as found on disk
    assert first.modalities == ("lidar_360", "livox_avia", "ground_truth", "class", "Image")
    assert found[2].modalities == ("lidar_360", "radar_enhance_pcl")
    assert found[3].modalities == ("livox_avia",)


def test_seqN_and_seqNNNN_are_the_same_name(tmp_path: Path) -> None:
    save(tmp_path / "val" / "seq7" / "lidar_360" / "1.000000.npy", np.ones((1, 3)))
    save(tmp_path / "val" / "seq12" / "lidar_360" / "1.000000.npy", np.ones((1, 3)))
    found = quiet_find(tmp_path)
    assert [s.name for s in found] == ["seq0007", "seq0012"]  # numeric order
    assert [s.name for s in quiet_find(tmp_path, sequences=["seq0007"])] == ["seq0007"]
    assert [s.name for s in quiet_find(tmp_path, sequences=["seq12"])] == ["seq0012"]


def test_splits_filter(layout: Path) -> None:
    assert [(s.split, s.name) for s in quiet_find(layout, splits=["val"])] == [("val", "seq0001")]
    assert [s.split for s in quiet_find(layout, splits=["test", "train"])] == [
        "train",
        "train",
        "test",
    ]
    # A lone string is one split, not a sequence of characters.
    assert [s.split for s in quiet_find(layout, splits="test")] == ["test"]


def test_sequences_filter(layout: Path) -> None:
    found = quiet_find(layout, sequences=["seq1"])
    assert [(s.split, s.name) for s in found] == [("train", "seq0001"), ("val", "seq0001")]
    found = quiet_find(layout, splits=["train"], sequences=["seq0002", "seq0001"])
    assert [s.name for s in found] == ["seq0001", "seq0002"]


def test_unknown_top_level_folder_warns(layout: Path) -> None:
    (layout / "reference").mkdir()
    (layout / "extras").mkdir()
    (layout / ".cache").mkdir()  # hidden: ignored silently
    (layout / "README.md").write_text("not a folder")  # files: ignored silently
    with pytest.warns(UserWarning, match=r"not a split \(train, val, test\): extras, reference$"):
        found = find_sequences(layout)
    assert len(found) == 4


def test_non_sequence_folder_in_split_warns(layout: Path) -> None:
    (layout / "val" / "notes").mkdir()
    with pytest.warns(UserWarning, match="not sequences.*: notes"):
        found = find_sequences(layout, splits=["val"])
    assert [s.name for s in found] == ["seq0001"]


def test_iter_ground_truth(train_seq: SequenceRef) -> None:
    samples = list(iter_ground_truth(train_seq))
    assert all(isinstance(s, PositionSample) for s in samples)
    assert [s.stamp_ns for s in samples] == [ns(T0, 65_000), ns(T0, 100_000)]
    np.testing.assert_array_equal(samples[1].position, [1.1, 1.2, 1.3])
    assert samples[0].position.dtype == np.float64
    assert samples[0].position.shape == (3,)


def test_iter_classes(train_seq: SequenceRef) -> None:
    samples = list(iter_classes(train_seq))
    assert samples == [ClassSample(ns(T0, 65_000), 2), ClassSample(ns(T0, 100_000), 2)]
    assert all(type(s.class_id) is int for s in samples)


def test_iter_images(train_seq: SequenceRef) -> None:
    frames = list(iter_images(train_seq))
    assert frames == [ImageFrame(ns(T0, 133_333), FAKE_PNG)]


def test_iter_clouds(train_seq: SequenceRef) -> None:
    clouds = iter_clouds(train_seq, "lidar_360")
    assert isinstance(clouds, Iterator)  # streamed, not a list
    first, second = clouds
    assert first.stamp_ns == ns(T0, 100_000)
    np.testing.assert_array_equal(first.points, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(second.points, [[2, 4, 6], [8, 10, 12]])
    # each kept row dated by its row in the scan's array: row i of 3 at i / 3 of 100 ms
    np.testing.assert_allclose(first.times, [0.0, 2 / 3 * 0.1], rtol=1e-6)
    (avia,) = iter_clouds(train_seq, "livox_avia")
    np.testing.assert_array_equal(avia.points, [[0.5, 0.5, 9.0]])
    np.testing.assert_allclose(avia.times, [0.05], rtol=1e-6)  # row 1 of 2


def test_iter_sequence_merges_in_time_order(train_seq: SequenceRef) -> None:
    items = [(m, item.stamp_ns) for m, item in iter_sequence(train_seq)]
    assert items == [
        ("ground_truth", ns(T0, 65_000)),
        ("class", ns(T0, 65_000)),  # tie: MODALITIES order
        ("lidar_360", ns(T0, 100_000)),  # tie with ground truth .1 and class .100000
        ("ground_truth", ns(T0, 100_000)),
        ("class", ns(T0, 100_000)),
        ("livox_avia", ns(T0, 114_000)),
        ("Image", ns(T0, 133_333)),
        ("lidar_360", ns(T0, 200_000)),
    ]
    kinds = {m: type(item) for m, item in iter_sequence(train_seq)}
    assert kinds == {
        "lidar_360": Cloud,
        "livox_avia": Cloud,
        "ground_truth": PositionSample,
        "class": ClassSample,
        "Image": ImageFrame,
    }


def test_iter_sequence_selected_modalities(train_seq: SequenceRef) -> None:
    items = [
        (m, item.stamp_ns) for m, item in iter_sequence(train_seq, ["livox_avia", "ground_truth"])
    ]
    assert items == [
        ("ground_truth", ns(T0, 65_000)),
        ("ground_truth", ns(T0, 100_000)),
        ("livox_avia", ns(T0, 114_000)),
    ]


def test_count_frames(train_seq: SequenceRef) -> None:
    assert count_frames(train_seq) == {
        "lidar_360": 2,
        "livox_avia": 1,
        "ground_truth": 2,
        "class": 2,
        "Image": 1,
    }


def test_absent_or_unknown_modality(layout: Path) -> None:
    val = quiet_find(layout, splits=["val"])[0]
    with pytest.raises(
        DatasetError,
        match="has no ground_truth folder; modalities present: lidar_360, radar_enhance_pcl",
    ):
        iter_ground_truth(val)
    with pytest.raises(DatasetError, match="has no Image folder"):
        iter_sequence(val, ["lidar_360", "Image"])
    with pytest.raises(DatasetError, match="has no livox_avia folder"):
        iter_clouds(val, "livox_avia")
    with pytest.raises(DatasetError, match="'ground_truth' is not a point-cloud modality"):
        iter_clouds(val, "ground_truth")
    with pytest.raises(DatasetError, match="unknown modality 'lidar'"):
        iter_sequence(val, ["lidar"])


def test_list_stamped_files_sorts_by_stamp_and_ignores_hidden(tmp_path: Path) -> None:
    for name in ["100.5.npy", "99.5.npy", "99.400000.npy"]:
        (tmp_path / name).write_bytes(b"never loaded")  # names only: contents are not read
    (tmp_path / ".DS_Store").write_bytes(b"junk")
    listed = list_stamped_files(tmp_path)
    assert listed == [
        (ns(99, 400_000), tmp_path / "99.400000.npy"),
        (ns(99, 500_000), tmp_path / "99.5.npy"),
        (ns(100, 500_000), tmp_path / "100.5.npy"),
    ]


# --------------------------------------------------------------------------- load_cloud


def test_load_cloud_drops_both_forms_of_zero_rows(tmp_path: Path) -> None:
    array = np.array(
        [
            [0.0, 0.0, 0.0],
            [-0.0, -0.0, 0.0],  # the Avia's zero row
            [-0.0, -0.0, -0.0],
            [0.0, 0.0, 1.5],  # one non-zero coordinate: a valid point
            [-2.25, 0.0, -0.0],
            [1.0, 2.0, 3.0],
        ]
    )
    points = load_cloud(save(tmp_path / "1.000000.npy", array))
    assert points.dtype == np.float32
    assert points.flags.c_contiguous
    np.testing.assert_array_equal(points, [[0, 0, 1.5], [-2.25, 0, 0], [1, 2, 3]])


@pytest.mark.parametrize("dtype", [np.float32, np.float64, ">f8", np.int16, np.uint8])
def test_load_cloud_accepts_real_dtypes(tmp_path: Path, dtype: str) -> None:
    array = np.array([[0, 0, 0], [1, 2, 3]]).astype(dtype)
    points = load_cloud(save(tmp_path / "1.000000.npy", array))
    assert points.dtype == np.float32
    np.testing.assert_array_equal(points, [[1, 2, 3]])


def test_load_cloud_fortran_order_gives_c_contiguous(tmp_path: Path) -> None:
    array = np.asfortranarray(np.arange(30, dtype=np.float64).reshape(10, 3))
    array[4] = 0.0
    points = load_cloud(save(tmp_path / "1.000000.npy", array))
    assert points.flags.c_contiguous
    np.testing.assert_array_equal(points, np.delete(array, 4, axis=0))


@pytest.mark.parametrize("array", [np.zeros((0,)), np.zeros((0, 3)), np.zeros((5, 3))])
def test_load_cloud_empty_frames(tmp_path: Path, array: NDArray[np.float64]) -> None:
    points = load_cloud(save(tmp_path / "1.000000.npy", array))
    assert points.shape == (0, 3)
    assert points.dtype == np.float32


def test_iteration_is_lazy(tmp_path: Path) -> None:
    """A corrupt second file fails only when the iterator reaches it: frames are loaded one at a time."""
    seq_dir = tmp_path / "val" / "seq0001"
    save(seq_dir / "lidar_360" / "1.000000.npy", np.ones((2, 3)))
    (seq_dir / "lidar_360" / "2.000000.npy").write_bytes(b"garbage")
    (seq,) = quiet_find(tmp_path)
    clouds = iter_clouds(seq, "lidar_360")
    assert next(clouds).points.shape == (2, 3)
    with pytest.raises(DatasetError, match="2.000000.npy: truncated or corrupt"):
        next(clouds)


# --------------------------------------------------------------------------- bad inputs


def test_truncated_npy(tmp_path: Path) -> None:
    path = save(tmp_path / "1.000000.npy", np.ones((100, 3)))
    data = path.read_bytes()
    path.write_bytes(data[:-17])
    with pytest.raises(
        DatasetError, match=r"cannot read .*1\.000000\.npy: truncated or corrupt \.npy file"
    ):
        load_cloud(path)
    path.write_bytes(data[:40])  # cut inside the header
    with pytest.raises(DatasetError, match="truncated or corrupt .npy file"):
        load_cloud(path)


@pytest.mark.parametrize(
    "garbage", [b"", b"hello, not numpy", b"PK\x03\x04not a zip", b"\x93NUMPY\x01\x00garbage"]
)
def test_garbage_bytes(tmp_path: Path, garbage: bytes) -> None:
    path = tmp_path / "1.000000.npy"
    path.write_bytes(garbage)
    with pytest.raises(DatasetError, match=r"1\.000000\.npy: truncated or corrupt \.npy file"):
        load_cloud(path)


def test_npz_archive_named_npy(tmp_path: Path) -> None:
    path = tmp_path / "1.000000.npy"
    with path.open("wb") as stream:
        np.savez(stream, a=np.ones((2, 3)))
    with pytest.raises(DatasetError, match="expected a .npy array, found an .npz archive"):
        load_cloud(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match=r"cannot read .*9\.000000\.npy"):
        load_cloud(tmp_path / "9.000000.npy")


@pytest.mark.parametrize(
    ("shape", "shown"),
    [
        ((2, 3, 1), r"\(2, 3, 1\)"),
        ((3,), r"\(3,\)"),
        ((), r"\(\)"),
        ((20064, 4), r"\(20064, 4\)"),
        ((5, 2), r"\(5, 2\)"),
        ((0, 4), r"\(0, 4\)"),  # empty, but not an (N, 3) array either
        ((0, 3, 1), r"\(0, 3, 1\)"),
    ],
)
def test_wrong_shape(tmp_path: Path, shape: tuple[int, ...], shown: str) -> None:
    path = save(tmp_path / "1.000000.npy", np.ones(shape))
    with pytest.raises(
        DatasetError, match=rf"1\.000000\.npy: expected an \(N, 3\) float array, got shape {shown}$"
    ):
        load_cloud(path)


@pytest.mark.parametrize(
    ("row", "message"),
    [
        ([np.nan, 1.0, 2.0], "found 1 NaN and 0 infinite values"),
        ([np.nan, 0.0, 0.0], "found 1 NaN and 0 infinite values"),
        ([1.0, np.inf, 2.0], "found 0 NaN and 1 infinite values"),
        ([1.0, 2.0, -np.inf], "found 0 NaN and 1 infinite values"),
        ([1e300, 2.0, 3.0], "found values beyond the float32 range"),
    ],
)
def test_non_finite(tmp_path: Path, row: list[float], message: str) -> None:
    path = save(tmp_path / "1.000000.npy", np.array([[0.0, 0.0, 0.0], row, [1.0, 1.0, 1.0]]))
    with pytest.raises(
        DatasetError, match=rf"1\.000000\.npy: expected finite coordinates, {message}"
    ):
        load_cloud(path)


@pytest.mark.parametrize(
    "array",
    [
        np.array([["a", "b", "c"]]),
        np.ones((2, 3), dtype=bool),
        np.ones((2, 3), dtype=np.complex128),
    ],
)
def test_non_numeric_dtype(tmp_path: Path, array: NDArray[np.generic]) -> None:
    path = save(tmp_path / "1.000000.npy", array)
    with pytest.raises(
        DatasetError,
        match=rf"expected an \(N, 3\) float array, got non-numeric dtype {array.dtype}",
    ):
        load_cloud(path)


def test_duplicate_stamps(tmp_path: Path) -> None:
    save(tmp_path / "1706255621.71419.npy", np.ones(3))
    save(tmp_path / "1706255621.714190.npy", np.ones(3))
    with pytest.raises(
        DatasetError, match="duplicate stamps in .*name the same instant"
    ) as excinfo:
        list_stamped_files(tmp_path)
    assert "1706255621.71419.npy" in str(excinfo.value)
    assert "1706255621.714190.npy" in str(excinfo.value)
    assert "1706255621714190000 ns" in str(excinfo.value)


@pytest.mark.parametrize(
    "name",
    [
        "frame_0001.npy",
        "1706255621.npy",
        "1706255621.6002271.npy",
        "1706255621..npy",
        "1706255621.600227npy",
    ],
)
def test_name_not_a_timestamp(tmp_path: Path, name: str) -> None:
    save(tmp_path / "1706255621.600227.npy", np.ones(3))
    (tmp_path / name).write_bytes(b"")
    with pytest.raises(
        DatasetError, match="is not a timestamp|expected a <stamp>.npy file"
    ) as excinfo:
        list_stamped_files(tmp_path)
    assert str(tmp_path / name) in str(excinfo.value)  # the message names the file


def test_wrong_suffix(tmp_path: Path) -> None:
    (tmp_path / "1706255621.600227.png").write_bytes(FAKE_PNG)
    with pytest.raises(
        DatasetError,
        match=r"unexpected file .*1706255621\.600227\.png: expected a <stamp>\.npy file",
    ):
        list_stamped_files(tmp_path)
    assert list_stamped_files(tmp_path, suffix=".png")[0][0] == ns(1_706_255_621, 600_227)


def test_missing_modality_folder(tmp_path: Path) -> None:
    with pytest.raises(
        DatasetError, match=r"folder .*nowhere not found: expected a folder of <stamp>\.npy files"
    ):
        list_stamped_files(tmp_path / "nowhere")


def test_missing_root(tmp_path: Path) -> None:
    with pytest.raises(
        DatasetError,
        match=r"dataset root .*absent does not exist: expected a folder holding train/",
    ):
        find_sequences(tmp_path / "absent")
    (tmp_path / "file").write_text("x")
    with pytest.raises(DatasetError, match=r"dataset root .*file is not a folder"):
        find_sequences(tmp_path / "file")


def test_root_without_splits(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="no split folder in dataset root"):
        find_sequences(tmp_path)


def test_missing_split(layout: Path) -> None:
    save(layout.parent / "only_val" / "val" / "seq1" / "lidar_360" / "1.0.npy", np.ones((1, 3)))
    with pytest.raises(
        DatasetError, match=r"split folder .*only_val/train not found; splits present in .*: val$"
    ):
        find_sequences(layout.parent / "only_val", splits=["train"])
    with pytest.raises(
        DatasetError, match="unknown split 'training': expected one of train, val, test"
    ):
        find_sequences(layout, splits=["training"])


def test_unknown_sequence(layout: Path) -> None:
    with pytest.raises(
        DatasetError,
        match=r"sequence seq0099 not found in .*\(split val\); sequences present: seq0001$",
    ):
        find_sequences(layout, splits=["val"], sequences=["seq99"])
    with pytest.raises(DatasetError, match="'sequence_1' is not a sequence name"):
        find_sequences(layout, sequences=["sequence_1"])


def test_no_sequence_found(tmp_path: Path) -> None:
    (tmp_path / "test").mkdir()
    (tmp_path / "test" / "test_timestamps.csv").write_text("")
    with pytest.raises(
        DatasetError, match=r"no sequence found in .*\(split test\): expected folders named seqNNNN"
    ):
        find_sequences(tmp_path)


def test_empty_sequence_without_modality_folder(tmp_path: Path) -> None:
    (tmp_path / "val" / "seq0001" / "calib").mkdir(parents=True)
    with (
        pytest.warns(UserWarning, match=r"not modalities .*: calib$"),
        pytest.raises(
            DatasetError,
            match=r"empty sequence .*seq0001: no modality folder, expected at least one of lidar_360",
        ),
    ):
        find_sequences(tmp_path)


def test_empty_sequence_with_empty_modality_folders(tmp_path: Path) -> None:
    (tmp_path / "val" / "seq0001" / "lidar_360").mkdir(parents=True)
    (tmp_path / "val" / "seq0001" / "livox_avia").mkdir()
    (tmp_path / "val" / "seq0001" / "livox_avia" / ".keep").write_text("")  # hidden: still empty
    with pytest.raises(
        DatasetError,
        match=r"empty sequence .*seq0001: its modality folders \(lidar_360, livox_avia\) are all empty",
    ):
        find_sequences(tmp_path)


def test_two_folders_for_one_sequence(tmp_path: Path) -> None:
    save(tmp_path / "val" / "seq1" / "lidar_360" / "1.0.npy", np.ones((1, 3)))
    save(tmp_path / "val" / "seq0001" / "lidar_360" / "1.0.npy", np.ones((1, 3)))
    with pytest.raises(
        DatasetError, match="two folders in .*val name sequence seq0001: seq0001 and seq1"
    ):
        find_sequences(tmp_path)


@pytest.mark.parametrize(
    ("array", "shown"),
    [
        (np.array([2.0]), "got shape \\(1,\\) dtype float64"),
        (np.array([[2]]), "got shape \\(1, 1\\) dtype int64"),
        (np.array([], dtype=np.int64), "got shape \\(0,\\) dtype int64"),
        (np.array([True]), "got shape \\(1,\\) dtype bool"),
        (np.array([7]), "got class id 7"),
        (np.array([-1]), "got class id -1"),
    ],
)
def test_bad_class_file(tmp_path: Path, array: NDArray[np.generic], shown: str) -> None:
    save(tmp_path / "train" / "seq0001" / "class" / "1.000000.npy", array)
    (seq,) = quiet_find(tmp_path)
    with pytest.raises(
        DatasetError,
        match=rf"1\.000000\.npy: expected a 1-D integer array whose element \[0\] is the class id 0\.\.3, {shown}$",
    ):
        list(iter_classes(seq))


def test_bad_png_signature(tmp_path: Path) -> None:
    image_dir = tmp_path / "train" / "seq0001" / "Image"
    image_dir.mkdir(parents=True)
    (image_dir / "1.000000.png").write_bytes(b"\xff\xd8\xff\xe0 a JPEG in disguise")
    (seq,) = quiet_find(tmp_path)
    with pytest.raises(DatasetError, match=r"1\.000000\.png: not a PNG file, bad signature"):
        list(iter_images(seq))


@pytest.mark.parametrize(
    ("array", "shown"),
    [
        (np.ones((1, 3)), r"\(1, 3\)"),
        (np.ones(4), r"\(4,\)"),
        (np.array([1.0, np.nan, 2.0]), "finite"),
    ],
)
def test_bad_position_file(tmp_path: Path, array: NDArray[np.float64], shown: str) -> None:
    save(tmp_path / "1.000000.npy", array)
    with pytest.raises(DatasetError, match=rf"1\.000000\.npy: expected .*{shown}"):
        list(iter_positions(tmp_path))


# --------------------------------------------------------------------------- the real sample

# Computed once by reading the sample's file names (integer ns).
REAL_COUNTS = {"lidar_360": 88, "livox_avia": 88, "radar_enhance_pcl": 132}
REAL_FIRST_LAST = {
    "lidar_360": (1_706_255_621_600_227_000, 1_706_255_630_300_250_000),
    "livox_avia": (1_706_255_621_614_239_000, 1_706_255_630_314_129_000),
    "radar_enhance_pcl": (1_706_255_621_610_851_000, 1_706_255_630_344_084_000),
}
REAL_VALID_POINTS = {"lidar_360": 367_441, "livox_avia": 1_250, "radar_enhance_pcl": 937}


@pytest.fixture(scope="module")
def real_seq(real_sample: Path) -> SequenceRef:
    with pytest.warns(UserWarning, match="not a split .*: reference"):
        found = find_sequences(real_sample, splits=["val"])
    assert len(found) == 1
    return found[0]


def test_real_sequence_found(real_seq: SequenceRef, real_sample: Path) -> None:
    assert real_seq.split == "val"
    assert real_seq.name == "seq0001"
    assert real_seq.path == real_sample / "val" / "seq0001"
    assert real_seq.modalities == CLOUD_MODALITIES


def test_real_counts_and_stamps(real_seq: SequenceRef) -> None:
    assert count_frames(real_seq) == REAL_COUNTS
    for modality, (first, last) in REAL_FIRST_LAST.items():
        listed = list_stamped_files(real_seq.path / modality)
        assert len(listed) == REAL_COUNTS[modality]
        assert (listed[0][0], listed[-1][0]) == (first, last)
        stamps = [stamp for stamp, _ in listed]
        assert stamps == sorted(stamps)


@pytest.mark.parametrize("modality", CLOUD_MODALITIES)
def test_real_clouds_match_raw_files(real_seq: SequenceRef, modality: str) -> None:
    files = list_stamped_files(real_seq.path / modality)
    n_valid = 0
    n_all_zero = 0
    raw_shapes: Counter[tuple[int, ...]] = Counter()
    for (stamp_ns, path), cloud in zip(files, iter_clouds(real_seq, modality), strict=True):
        raw = np.load(path)
        assert raw.dtype == np.float64
        raw_shapes[raw.shape] += 1
        assert cloud.stamp_ns == stamp_ns
        points = cloud.points
        assert points.dtype == np.float32
        assert points.ndim == 2
        assert points.shape[1] == 3
        assert points.flags.c_contiguous
        assert not np.any(np.all(points == 0, axis=1))  # no zero row left
        expected = raw_valid_rows(raw)
        assert points.shape == expected.shape
        np.testing.assert_array_equal(points, expected)
        n_valid += len(points)
        n_all_zero += len(points) == 0
    assert n_valid == REAL_VALID_POINTS[modality]
    if modality == "lidar_360":
        assert set(raw_shapes) == {(20064, 3), (19968, 3)}
        assert n_all_zero == 0
    elif modality == "livox_avia":
        assert set(raw_shapes) == {(24000, 3)}
        assert n_all_zero == 39
    else:
        assert raw_shapes[(0,)] == 54  # the radar's empty frames, read as (0, 3)
        assert n_all_zero == 54
        assert all(len(s) == 2 and 2 <= s[0] <= 20 for s in raw_shapes if s != (0,))


def test_real_avia_negative_zero_rows_removed(real_seq: SequenceRef) -> None:
    path = list_stamped_files(real_seq.path / "livox_avia")[0][1]
    raw = np.load(path)
    zero_rows = np.all(raw == 0, axis=1)
    signs = np.signbit(raw[zero_rows])
    assert np.any(np.all(signs == [True, True, False], axis=1))  # (-0.0, -0.0, +0.0) present
    assert len(load_cloud(path)) == int(np.count_nonzero(~zero_rows))


def test_real_iter_sequence(real_seq: SequenceRef) -> None:
    counts: Counter[str] = Counter()
    previous = -1
    for modality, item in iter_sequence(real_seq):
        assert isinstance(item, Cloud)
        assert item.stamp_ns >= previous
        previous = item.stamp_ns
        counts[modality] += 1
    assert counts == REAL_COUNTS
    assert sum(counts.values()) == 88 + 88 + 132


def test_real_reference_positions(real_sample: Path) -> None:
    samples = list(iter_positions(real_sample / "reference" / "seq0001"))
    assert len(samples) == 76
    stamps = [s.stamp_ns for s in samples]
    assert stamps == sorted(stamps)
    assert stamps[0] == 1_706_255_621_614_238_000
    assert stamps[-1] == 1_706_255_630_300_250_000  # file 1706255630.30025.npy
    assert 1_706_255_621_714_190_000 in stamps  # file 1706255621.71419.npy
    for sample in samples:
        assert sample.position.dtype == np.float64
        assert sample.position.shape == (3,)
        assert np.all(np.isfinite(sample.position))


def test_splits_constant() -> None:
    assert SPLITS == ("train", "val", "test")
    assert MODALITIES == CLOUD_MODALITIES + ("ground_truth", "class", "Image")
