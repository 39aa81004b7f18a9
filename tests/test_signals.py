"""SIGTERM and SIGKILL in the middle of ``cldet convert`` (a subprocess): nothing half-done stays.

After the signal and a re-run: the inputs are byte-identical, no temporary file is left, every
log is complete, and no process of the killed run is left after 5 s.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cldet.io import list_topics

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
# Imported by every Python process of the run (parent, forkserver, workers): slows np.load down
# so that the signal lands mid-run.
SLOW_LOAD = """
import numpy as _np
import time as _time
_load = _np.load
def _slow_load(*args, **kwargs):
    _time.sleep(0.02)
    return _load(*args, **kwargs)
_np.load = _slow_load
"""


def build(root: Path, n_seq: int = 4, n_frames: int = 60) -> None:
    rng = np.random.default_rng(0)
    for s in range(1, n_seq + 1):
        folder = root / "val" / f"seq{s:04d}" / "lidar_360"
        folder.mkdir(parents=True)
        for i in range(n_frames):
            np.save(folder / f"{1_706_255_621 + i // 10}.{(i % 10) * 100_000:06d}.npy",
                    rng.normal(0, 20, (2000, 3)))  # fmt: skip


def digest(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def processes_tagged(tag: str) -> list[int]:
    """Live processes whose environment carries ``CLDET_SIGNAL_TEST=tag`` (the run's, all)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            environ = (entry / "environ").read_bytes().split(b"\0")
            state = (entry / "stat").read_bytes().rsplit(b")", 1)[1].split()[0]
        except (OSError, IndexError):
            continue
        if f"CLDET_SIGNAL_TEST={tag}".encode() in environ and state != b"Z":
            found.append(int(entry.name))
    return found


def processes_left(tag: str, within_s: float = 5.0) -> list[int]:
    """The run's processes still alive after ``within_s`` seconds (polled: [] as soon as none)."""
    deadline = time.monotonic() + within_s
    while (alive := processes_tagged(tag)) and time.monotonic() < deadline:
        time.sleep(0.05)
    return alive


def hooked_env(tmp_path: Path, payload: str, tag: str) -> dict[str, str]:
    """The environment of a run whose Python first executes ``payload`` (a sitecustomize.py in
    a folder first on PYTHONPATH), its processes tagged ``tag`` for :func:`processes_left`."""
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(payload)
    return {**os.environ, "PYTHONPATH": f"{hook}:{REPO}", "CLDET_SIGNAL_TEST": tag}


def temporaries(out: Path) -> list[str]:
    return sorted(p.name for p in out.rglob(".*") if ".tmp-" in p.name or ".clean-" in p.name)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_signal_mid_convert_leaves_nothing_behind(tmp_path: Path, sig: signal.Signals) -> None:
    data, out = tmp_path / "data", tmp_path / "logs"
    build(data)
    before = digest(data)
    tag = f"{os.getpid()}{sig.value}"
    env = hooked_env(tmp_path, SLOW_LOAD, tag)
    command = [
        sys.executable,
        "-m",
        "cldet",
        "convert",
        str(data),
        "-o",
        str(out),
        "--workers",
        "2",
    ]
    run = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while not temporaries(out) and time.monotonic() < deadline:  # wait until writing
        time.sleep(0.05)
    assert temporaries(out), "the run never started writing"
    time.sleep(0.3)
    run.send_signal(sig)
    run.wait(timeout=30)  # not communicate(): a surviving child would hold the pipes open
    assert run.stderr is not None
    err = run.stderr.read() if sig == signal.SIGTERM else b""
    if sig == signal.SIGTERM:
        assert run.returncode == 143, err
        assert b"terminated (SIGTERM)" in err and b"Traceback" not in err
        assert temporaries(out) == []  # removed by the run itself
    else:
        assert run.returncode == -signal.SIGKILL
    assert processes_left(tag) == [], "processes of the signalled run are still alive"
    partial = [p.name for p in out.rglob("*.mcap")]
    for log in out.rglob("*.mcap"):  # whatever is under a final name is complete
        assert list_topics(log)["/lidar_360"] == 60, partial

    again = subprocess.run(
        [*command, "--overwrite"], env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert again.returncode == 0, again.stderr
    assert temporaries(out) == []  # stale ones of the killed run removed too
    assert sorted(p.name for p in (out / "val").iterdir()) == [
        f"seq{s:04d}.mcap" for s in range(1, 5)
    ]
    assert digest(data) == before


SLOW_FRAMES = """
import numpy as _np
import time as _time
_frombuffer = _np.frombuffer
def _slow_frombuffer(*args, **kwargs):
    _time.sleep(0.1)
    return _frombuffer(*args, **kwargs)
_np.frombuffer = _slow_frombuffer
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_signal_mid_annotate_leaves_the_log_intact(tmp_path: Path, sig: signal.Signals) -> None:
    from cldet.io import LogWriter
    from cldet.io import topics as tp

    log = tmp_path / "seq0001.mcap"
    rng = np.random.default_rng(2)
    with open(log, "wb") as f, LogWriter(f) as writer:
        for i in range(20):
            points = rng.normal(0, 20, (50, 3)).astype(np.float32)  # few: the line search is quick
            writer.write_cloud(tp.LIDAR_360, 10**18 + i * 10**8, points, tp.FRAME_MID360)
        writer.write_metadata(tp.METADATA_SOURCE, {"sequence": "seq0001", "split": "val"})
    before = log.read_bytes()
    tag = f"{os.getpid()}a{sig.value}"
    env = hooked_env(tmp_path, SLOW_FRAMES, tag)
    command = [sys.executable, "-m", "cldet", "annotate", str(log)]  # with the .rrd
    run = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while not temporaries(tmp_path) and time.monotonic() < deadline:  # the .rrd's, at first
        time.sleep(0.05)
    assert temporaries(tmp_path), "the run never started writing"
    time.sleep(1.0)
    run.send_signal(sig)
    run.wait(timeout=30)
    assert run.stderr is not None
    if sig == signal.SIGTERM:
        err = run.stderr.read()
        assert run.returncode == 143, err
        assert b"terminated (SIGTERM)" in err and b"Traceback" not in err
        assert temporaries(tmp_path) == []
    else:
        assert run.returncode == -signal.SIGKILL
    assert log.read_bytes() == before  # the input, byte for byte
    assert not (tmp_path / "seq0001.rrd").exists()
    assert processes_left(tag) == []

    again = subprocess.run(
        command, env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert again.returncode == 0, again.stderr
    assert temporaries(tmp_path) == []  # the killed run's stale ones removed too
    assert list_topics(log)["/cldet/estimate"] == 20 and (tmp_path / "seq0001.rrd").exists()


def test_a_sigterm_whose_exception_was_lost_still_stops_the_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """SIGTERM's exception can be swallowed by a C callback (numba's cache loader prints
    "Exception ignored" and goes on); the handler's flag still stops the run at the next frame
    and keeps any result from being renamed into place."""
    from cldet import signals
    from cldet.io import LogWriter
    from cldet.io import topics as tp
    from cldet.io.files import atomic_output
    from cldet.pipeline import annotate_log

    log = tmp_path / "seq0001.mcap"
    rng = np.random.default_rng(2)
    with open(log, "wb") as f, LogWriter(f) as writer:
        for i in range(5):
            points = rng.normal(0, 20, (50, 3)).astype(np.float32)
            writer.write_cloud(tp.LIDAR_360, 10**18 + i * 10**8, points, tp.FRAME_MID360)
    before = log.read_bytes()
    monkeypatch.setattr(signals, "_sigterm_received", True)  # the handler ran, its raise was lost
    with pytest.raises(signals.Terminated):
        annotate_log(log, output=tmp_path / "out.mcap", write_rrd=False)
    with pytest.raises(signals.Terminated), atomic_output(tmp_path / "other.bin") as stream:
        stream.write(b"complete, but the run was terminated")
    assert log.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seq0001.mcap"]  # no output, no temporary
