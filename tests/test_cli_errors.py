"""The command line under bad outputs and bad logs: one ``ERROR:`` line, exit 1, no traceback."""

from __future__ import annotations

import io
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner, Result

from cldet.cli import app
from cldet.errors import OutputError
from cldet.io import LogWriter
from cldet.io import topics as tp
from cldet.io.files import check_output
from cldet.stamps import format_stamp

T0 = 1_706_255_621_600_227_000


def write_clouds(path: Path, n: int = 4, corrupt: int | None = None) -> int:
    """A small log of ``n`` Mid-360 clouds; message ``corrupt`` is not protobuf. Its stamp."""
    rng = np.random.default_rng(1)
    source = io.BytesIO()
    with LogWriter(source) as writer:
        for i in range(n):
            points = rng.normal(0, 10, (40, 3)).astype(np.float32)
            writer.write_cloud(tp.LIDAR_360, T0 + i * 100_000_000, points, tp.FRAME_MID360)
    source.seek(0)
    raw = list(make_reader(source).iter_messages())
    with open(path, "wb") as f, LogWriter(f) as writer:
        for i, (schema, channel, message) in enumerate(raw):
            data = b"\x0a\x02\x08\xff" if i == corrupt else message.data
            writer.write_raw(schema, channel, message.log_time, message.publish_time, data)
    return raw[corrupt if corrupt is not None else 0][2].log_time


@pytest.fixture
def cli() -> Callable[..., Result]:
    runner = CliRunner()
    return lambda *args: runner.invoke(app, [str(a) for a in args])


def assert_one_error(result: Result, *needles: str) -> str:
    """Exit code 1, no traceback, an ``ERROR:`` line holding every needle."""
    assert result.exit_code == 1, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("ERROR:")]
    assert errors, result.output
    for needle in needles:
        assert any(needle in line for line in errors), (needle, result.output)
    return errors[0]


@pytest.fixture
def log(tmp_path: Path) -> Path:
    path = tmp_path / "logs" / "seq0001.mcap"
    path.parent.mkdir()
    write_clouds(path)
    return path


# --- outputs checked before any work ----------------------------------------------------------
def test_annotate_into_a_missing_folder(
    cli: Callable[..., Result], log: Path, tmp_path: Path
) -> None:
    before = log.read_bytes()
    out = tmp_path / "absent" / "out.mcap"
    result = cli("annotate", log, "-o", out, "--no-rrd")
    assert_one_error(result, f"cannot write the annotated log {out}", "does not exist")
    assert log.read_bytes() == before


def test_annotate_onto_a_directory(cli: Callable[..., Result], log: Path, tmp_path: Path) -> None:
    out = tmp_path / "a-folder.mcap"
    out.mkdir()
    result = cli("annotate", log, "-o", out, "--no-rrd")
    assert_one_error(result, f"{out}: it is a directory")


def test_rrd_into_a_missing_folder(cli: Callable[..., Result], log: Path, tmp_path: Path) -> None:
    rrd = tmp_path / "absent" / "review.rrd"
    result = cli("annotate", log, "--rrd", rrd)
    assert_one_error(result, f"cannot write the recording {rrd}", "does not exist")
    assert not list(log.parent.glob(".*tmp*"))


def test_annotate_into_a_read_only_folder(
    cli: Callable[..., Result], log: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from cldet.io import files

    monkeypatch.setattr(files, "_writable", lambda folder: False)  # root ignores chmod
    result = cli("annotate", log, "--no-rrd")
    assert_one_error(result, f"the folder {log.parent} is not writable")


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into a read-only folder")
def test_annotate_into_a_read_only_folder_for_real(cli: Callable[..., Result], log: Path) -> None:
    log.parent.chmod(0o555)
    try:
        result = cli("annotate", log, "--no-rrd")
    finally:
        log.parent.chmod(0o755)
    assert_one_error(result, "is not writable")


def test_check_output_follows_a_symbolic_link(tmp_path: Path) -> None:
    target = tmp_path / "real.mcap"
    target.write_bytes(b"x")
    link = tmp_path / "link.mcap"
    link.symlink_to(target)
    assert check_output(link) == target
    with pytest.raises(OutputError, match=r"cannot write the output .*: it is a directory"):
        check_output(tmp_path)


def test_an_os_error_at_the_boundary_is_one_line(
    cli: Callable[..., Result], log: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from cldet import pipeline

    def full(*args: object, **kwargs: object) -> None:
        raise OSError(28, "No space left on device", str(log))

    monkeypatch.setattr(pipeline, "open_log", full)
    result = cli("annotate", log, "--no-rrd")
    assert_one_error(result, f"ERROR: {log}: No space left on device")


# --- bad logs ----------------------------------------------------------------------------------
def test_annotate_a_corrupt_cloud_names_log_topic_and_stamp(
    cli: Callable[..., Result], tmp_path: Path
) -> None:
    path = tmp_path / "bad.mcap"
    stamp = write_clouds(path, corrupt=0)
    before = path.read_bytes()
    result = cli("annotate", path, "--no-rrd")
    assert_one_error(result, f"{path}: corrupt message on /lidar_360 stamped {format_stamp(stamp)}")
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.mcap"]


def test_annotate_a_lidar_channel_without_messages(
    cli: Callable[..., Result], tmp_path: Path
) -> None:
    from mcap.writer import Writer

    source = tmp_path / "one.mcap"
    write_clouds(source, n=1)
    with open(source, "rb") as f:
        ((schema, channel, _),) = list(make_reader(f).iter_messages())
    path = tmp_path / "empty-lidar.mcap"
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start()
        schema_id = writer.register_schema(schema.name, schema.encoding, schema.data)
        writer.register_channel(channel.topic, channel.message_encoding, schema_id)
        writer.finish()
    result = cli("annotate", path, "--no-rrd")
    assert_one_error(
        result,
        f"{path}: no message on its /lidar_360 channel, nothing to annotate; "
        "topics in the log: /lidar_360 (0)",
    )


# --- read-only logs, links, two runs at once -----------------------------------------------------
@pytest.fixture
def fake_annotate(monkeypatch: pytest.MonkeyPatch) -> list[Path]:
    """annotate_log replaced by a plain rewrite of the log (the file handling under test only)."""
    from cldet import pipeline
    from cldet.io.rewrite import rewrite_log

    calls: list[Path] = []

    def rewrite(log: Path, *, output: Path | None = None, **kwargs: object) -> object:
        calls.append(Path(log))
        rewrite_log(Path(log), Path(output) if output is not None else Path(log), [])

        class Report:
            def describe(self) -> str:
                return f"rewrote {log}"

        return Report()

    monkeypatch.setattr(pipeline, "annotate_log", rewrite)
    return calls


def test_a_read_only_log_is_refused_unless_forced(
    cli: Callable[..., Result], log: Path, fake_annotate: list[Path]
) -> None:
    log.chmod(0o444)
    before = log.read_bytes()
    result = cli("annotate", log, "--no-rrd")
    assert_one_error(result, f"{log} is read-only (mode 0444): pass --force to rewrite it")
    assert log.read_bytes() == before and fake_annotate == []
    result = cli("annotate", log, "--no-rrd", "--force")
    assert result.exit_code == 0, result.output
    assert fake_annotate == [log] and (log.stat().st_mode & 0o777) == 0o444


def test_a_symbolic_link_is_annotated_at_its_target(
    cli: Callable[..., Result], log: Path, tmp_path: Path, fake_annotate: list[Path]
) -> None:
    link = tmp_path / "link.mcap"
    link.symlink_to(log)
    inode = log.stat().st_ino
    result = cli("annotate", link, "--no-rrd")
    assert result.exit_code == 0, result.output
    assert link.is_symlink() and link.resolve() == log
    assert log.stat().st_ino != inode  # the target was replaced, through the link


def test_a_log_being_annotated_is_refused(
    cli: Callable[..., Result], log: Path, fake_annotate: list[Path]
) -> None:
    from cldet.io.files import lock_file

    with lock_file(log, "log"):  # as another `cldet annotate` holds it
        result = cli("annotate", log, "--no-rrd")
    assert_one_error(
        result, f"the log {log} is being rewritten by another process (another `cldet annotate`?)"
    )
    assert fake_annotate == []
