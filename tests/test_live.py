"""``annotate --live``: the Foxglove WebSocket server on 127.0.0.1 streams the run's channels.

The client here is a minimal WebSocket client over a plain socket (no extra dependency): it
reads the server's channel advertisements, subscribes to the causal estimate and counts the
messages that arrive while the run goes on.
"""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from cldet.cli import app
from cldet.io import topics
from cldet.io.schemas import Estimate
from cldet.live import LiveOutput
from cldet.pipeline import annotate_log

pytest.importorskip("foxglove", reason="foxglove-sdk is not installed (pip install -e '.[dev]')")

_SUBPROTOCOLS = "foxglove.sdk.v1, foxglove.websocket.v1"


class _Client:
    """A WebSocket client of Foxglove's protocol: advertisements, one subscription."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                f"Sec-WebSocket-Protocol: {_SUBPROTOCOLS}\r\n\r\n"
            ).encode()
        )
        head = b""
        while b"\r\n\r\n" not in head:
            head += self.sock.recv(1)
        assert head.startswith(b"HTTP/1.1 101"), head
        self.channels: dict[int, dict[str, Any]] = {}
        self.messages: dict[int, list[bytes]] = {}
        self.subscribe_to: str | None = None
        self._subscriptions: dict[int, int] = {}
        self.done = threading.Event()
        self.ops: list[str] = []
        self.resubscribed = 0
        self._subscribed_at = 0.0
        self.frames: list[tuple[int, int]] = []  # (opcode, payload length) of every frame

    def _read(self, n: int) -> bytes:
        out = b""
        while len(out) < n:
            part = self.sock.recv(n - len(out))
            if not part:
                raise ConnectionError("closed")
            out += part
        return out

    def _frame(self) -> tuple[int, bytes]:
        """The next frame; TimeoutError when none starts within a quarter second."""
        self.sock.settimeout(0.25)
        first = self.sock.recv(1)  # the wait between frames, nothing consumed on a timeout
        if not first:
            raise ConnectionError("closed")
        self.sock.settimeout(10)  # the rest of a frame that has begun
        b0, b1 = first[0], self._read(1)[0]
        length = b1 & 0x7F
        if length == 126:
            (length,) = struct.unpack(">H", self._read(2))
        elif length == 127:
            (length,) = struct.unpack(">Q", self._read(8))
        return b0 & 0x0F, self._read(length)

    def send_text(self, text: str) -> None:
        data = text.encode()
        mask = os.urandom(4)
        header = bytes([0x81])
        if len(data) < 126:
            header += bytes([0x80 | len(data)])
        else:
            header += bytes([0x80 | 126]) + struct.pack(">H", len(data))
        self.sock.sendall(header + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def _subscribe(self, channel_id: int) -> None:
        sub = len(self._subscriptions) + 1
        self._subscriptions[sub] = channel_id
        self._subscribed_at = time.monotonic()
        self.send_text(
            json.dumps({"op": "subscribe", "subscriptions": [{"id": sub, "channelId": channel_id}]})
        )

    def _resubscribe(self) -> None:
        """A subscription sent right after the channel's advertisement is sometimes not
        served (seen with foxglove-sdk 0.30.3 about one run in five): after a second without
        data, subscribe again (as a client reconnecting would)."""
        if not self._subscriptions or self.messages:
            return
        if time.monotonic() - self._subscribed_at < 1.0:
            return
        last = max(self._subscriptions)
        self.send_text(json.dumps({"op": "unsubscribe", "subscriptionIds": [last]}))
        self.resubscribed += 1
        self._subscribe(self._subscriptions[last])

    def run(self) -> None:
        try:
            while not self.done.is_set():
                try:
                    opcode, payload = self._frame()
                except TimeoutError:
                    self._resubscribe()
                    continue
                except (ConnectionError, OSError) as err:
                    self.ops.append(f"closed: {err!r}")
                    return
                self.frames.append((opcode, len(payload)))
                if opcode == 1:
                    msg = json.loads(payload)
                    self.ops.append(msg.get("op", "?") + ":" + str(msg)[:300])
                    if msg.get("op") == "advertise":
                        for channel in msg["channels"]:
                            self.channels[channel["id"]] = channel
                            if channel["topic"] == self.subscribe_to:
                                self._subscribe(channel["id"])
                elif opcode == 2 and payload[:1] == b"\x01":  # messageData
                    sub, _ = struct.unpack_from("<IQ", payload, 1)
                    self.messages.setdefault(self._subscriptions[sub], []).append(payload[13:])
                elif opcode == 8:
                    return
        finally:
            self.sock.close()

    def topics(self) -> set[str]:
        return {c["topic"] for c in self.channels.values()}


def _run_with_client(live: LiveOutput, job: Callable[[], None]) -> _Client:
    port = live.foxglove_port
    assert port is not None
    client = _Client(port)
    client.subscribe_to = topics.CAUSAL
    thread = threading.Thread(target=client.run, daemon=True)
    thread.start()
    try:
        job()
        time.sleep(0.5)  # the last messages on their way
    finally:
        client.done.set()
        live.close()
        thread.join(timeout=10)
    return client


def test_a_live_run_streams_its_channels_to_a_local_foxglove_client(
    tmp_path: Path, make_log: Callable[..., Path]
) -> None:
    log = make_log(tmp_path, seed=7101, duration_s=3.0)
    latencies: list[float] = []
    live = LiveOutput(foxglove_port=0, realtime=True, on_frame=lambda _, s: latencies.append(s))
    assert live.foxglove_port and live.foxglove_port > 0
    out = tmp_path / "out.mcap"
    started = time.perf_counter()
    reports: list[Any] = []
    client = _run_with_client(
        live, lambda: reports.append(annotate_log(log, output=out, write_rrd=False, live=live))
    )
    elapsed = time.perf_counter() - started
    (report,) = reports
    assert {
        topics.TF,
        topics.LIDAR_360,
        topics.LIVOX_AVIA,
        topics.FOREGROUND,
        topics.CENTROIDS,
        topics.CLUSTERS,
        topics.CAUSAL,
        topics.DRONE,
        topics.TRACK,
    } <= client.topics(), client.topics()
    schemas = {c["topic"]: c["schemaName"] for c in client.channels.values()}
    assert schemas[topics.CAUSAL] == topics.SCHEMA_ESTIMATE
    assert schemas[topics.LIDAR_360] == topics.SCHEMA_POINT_CLOUD
    (causal_id,) = [i for i, c in client.channels.items() if c["topic"] == topics.CAUSAL]
    received = client.messages.get(causal_id, [])
    assert len(received) >= report.frames // 2, (
        len(received),
        report.frames,
        [o[:40] for o in client.ops],
        sorted(client.topics()),
        client._subscriptions,
        len(client.frames),
    )
    first = Estimate.FromString(received[-1])
    assert first.source != 0 and first.timestamp.seconds > 0
    assert len(latencies) == report.frames
    assert elapsed >= 0.9 * (report.frames - 1) * 0.1  # paced at the Mid-360's 10 Hz
    assert out.is_file()  # the annotated log is still written


def _outward_address() -> str | None:
    """This machine's address on its default route (a UDP connect sends nothing)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("192.0.2.1", 9))
        except OSError:
            return None
        address = str(probe.getsockname()[0])
    return None if address.startswith("127.") else address


@pytest.mark.parametrize("host", ["127.0.0.1", "0.0.0.0"])
def test_the_foxglove_server_binds_to_this_machine_only_by_default(host: str) -> None:
    address = _outward_address()
    if address is None:
        pytest.skip("this machine has no address besides the loopback")
    live = LiveOutput(foxglove_port=0, foxglove_host=host)
    try:
        port = live.foxglove_port
        assert port is not None
        with socket.create_connection(("127.0.0.1", port), timeout=5):
            pass
        if host == "127.0.0.1":  # the default: another interface of this machine is refused
            with pytest.raises(OSError):
                socket.create_connection((address, port), timeout=2).close()
        else:  # the control: bound to every interface, it is reachable there
            socket.create_connection((address, port), timeout=2).close()
    finally:
        live.close()


def test_cli_live_prints_the_per_frame_latency(
    tmp_path: Path, make_log: Callable[..., Path]
) -> None:
    log = make_log(tmp_path, seed=7102, duration_s=1.5)
    result = CliRunner().invoke(
        app, ["annotate", str(log), "--live", "--foxglove", "0", "--no-rrd", "--no-rerun"]
    )
    assert result.exit_code == 0, result.output
    assert "latency" in result.output and "ms" in result.output
    assert "ws://127.0.0.1:" in result.output


def test_cli_live_port_in_use_is_a_clear_error(
    tmp_path: Path, make_log: Callable[..., Path]
) -> None:
    log = make_log(tmp_path, seed=7103, duration_s=1.0)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = CliRunner().invoke(
            app, ["annotate", str(log), "--live", "--foxglove", str(port), "--no-rrd", "--no-rerun"]
        )
    assert result.exit_code == 1
    assert f"cannot serve Foxglove on 127.0.0.1:{port}" in result.output
    assert "Traceback" not in result.output


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # what `rerun --save` writes
def test_a_live_run_streams_to_a_local_rerun_grpc_server_and_still_writes_the_rrd(
    tmp_path: Path, make_log: Callable[..., Path]
) -> None:
    import shutil
    import subprocess

    import rerun as rr

    rerun = shutil.which("rerun")
    if rerun is None:
        pytest.skip("the rerun CLI is not on PATH (pip install rerun-sdk)")
    log = make_log(tmp_path, seed=7104, duration_s=2.0)
    port = _free_port()
    received = tmp_path / "received.rrd"
    server = subprocess.Popen(  # a gRPC server on 127.0.0.1 that saves what it receives
        [rerun, "--bind", "127.0.0.1", "--port", str(port), "--save", str(received)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "the Rerun gRPC server did not start"
                time.sleep(0.2)
        live = LiveOutput(rerun=f"rerun+http://127.0.0.1:{port}/proxy")
        report = annotate_log(log, output=tmp_path / "out.mcap", live=live)
        live.close()
        time.sleep(1.0)
    finally:
        server.terminate()
        server.wait(timeout=30)
    assert report.rrd is not None and report.rrd.is_file()
    paths = set()
    for chunk in rr.chunk.RrdReader(received).stream():
        paths.add(str(chunk.entity_path))
    assert {
        "/world/lidar/mid360",
        "/world/foreground",
        "/world/clusters",
        "/world/drone/estimate",
        "/world/drone/trajectory",
    } <= paths, paths


def test_foxglove_without_a_port_gets_the_default_one() -> None:
    from cldet.commands.annotate import expand_optional_port

    assert expand_optional_port(["annotate", "a.mcap", "--live", "--foxglove"]) == [
        "annotate",
        "a.mcap",
        "--live",
        "--foxglove",
        "8765",
    ]
    assert expand_optional_port(["--foxglove", "a.mcap"]) == ["--foxglove", "8765", "a.mcap"]
    assert expand_optional_port(["--foxglove", "9000", "a.mcap"]) == [
        "--foxglove",
        "9000",
        "a.mcap",
    ]


def test_live_options_without_live_are_a_clear_error(tmp_path: Path) -> None:
    result = CliRunner().invoke(app, ["annotate", str(tmp_path / "x.mcap"), "--realtime"])
    assert result.exit_code == 1
    assert "go with --live" in result.output and "Traceback" not in result.output
