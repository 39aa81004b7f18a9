"""Benchmark reading point clouds from a ROS 2 log (PointCloud2, CDR) next to a cldet log
(foxglove.PointCloud, protobuf) holding the same clouds, in one run.

Writes N clouds of M points (float32, Mid-360-like ranges) twice: with cldet's ``LogWriter``
(x, y, z) and with ``mcap-ros2-support``'s writer as ``sensor_msgs/msg/PointCloud2`` (x, y, z,
and optionally an ``intensity`` field, as a Livox driver publishes), both zstd. Then reads every
cloud to an (N, 3) float32 array through ``cldet.io.sources.iter_log_clouds`` (what annotate
uses) and prints clouds/s, points/s and the ratio. Target: PointCloud2 within 1.5x of
foxglove.PointCloud. Also a Livox ``CustomMsg`` log (fewer clouds: slow to write), read by
cldet's byte reader and by rosbags' deserializer (the reason for the byte reader).

    python benchmarks/bench_ros_read.py [--clouds 300] [--points 20000] [--repeat 3]

Needs the dev extras (``mcap-ros2-support``).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the tests' ROS writers

from cldet.io import ros, topics  # noqa: E402
from cldet.io.mcap_read import open_log  # noqa: E402
from cldet.io.mcap_write import LogWriter  # noqa: E402
from cldet.io.sources import iter_log_clouds  # noqa: E402
from tests.ros_writers import (  # noqa: E402
    CUSTOM_MSG2,
    POINT_CLOUD2,
    Ros2Log,
    custom_msg_dict,
    point_cloud2,
)

T0 = 1_706_255_621_600_227_000


def _clouds(n: int, m: int) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    out = []
    for _ in range(n):
        direction = rng.normal(size=(m, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        out.append((direction * rng.uniform(1, 60, (m, 1))).astype(np.float32))
    return out


def _time(read: Callable[[], int], repeat: int) -> tuple[float, int]:
    best, count = float("inf"), 0
    for _ in range(repeat):
        started = time.perf_counter()
        count = read()
        best = min(best, time.perf_counter() - started)
    return best, count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clouds", type=int, default=300)
    parser.add_argument("--points", type=int, default=20000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--livox-clouds", type=int, default=30, help="(slow to write)")
    args = parser.parse_args()
    clouds = _clouds(args.clouds, args.points)
    with tempfile.TemporaryDirectory() as tmp:
        logs: dict[str, tuple[Path, str]] = {}
        fox = Path(tmp) / "foxglove.mcap"
        with open(fox, "wb") as f, LogWriter(f) as writer:
            for i, points in enumerate(clouds):
                writer.write_cloud(topics.LIDAR_360, T0 + i * 100_000_000, points, "mid360")
        logs["foxglove.PointCloud x,y,z"] = (fox, topics.LIDAR_360)
        for name, extra in (("x,y,z", ()), ("x,y,z,intensity", (("intensity", "f4"),))):
            path = Path(tmp) / f"pc2-{len(extra)}.mcap"
            with Ros2Log(path) as log:
                for i, points in enumerate(clouds):
                    stamp = T0 + i * 100_000_000
                    message = point_cloud2(stamp, "livox_frame", points, extra=extra)
                    log.write(
                        "/livox/lidar", "sensor_msgs/msg/PointCloud2", POINT_CLOUD2, message, stamp
                    )
            logs[f"PointCloud2 {name}"] = (path, "/livox/lidar")

        livox = Path(tmp) / "livox.mcap"
        with Ros2Log(livox) as log:
            for i, points in enumerate(clouds[: args.livox_clouds]):
                stamp = T0 + i * 100_000_000
                message = custom_msg_dict(stamp, "livox_frame", points)
                log.write(
                    "/livox/lidar", "livox_ros_driver2/msg/CustomMsg", CUSTOM_MSG2, message, stamp
                )

        def reader(path: Path, topic: str) -> Callable[[], int]:
            return lambda: sum(len(c.points) for c in iter_log_clouds(path, topic))

        def library(path: Path, topic: str) -> Callable[[], int]:
            """rosbags' deserializer, then the points picked from its objects."""

            def read() -> int:
                with open_log(path) as log:
                    n = 0
                    for schema, channel, message in log.iter_messages([topic]):
                        assert schema is not None
                        decode = ros.message_decoder(
                            schema.name, schema.encoding, schema.data, channel.message_encoding
                        )
                        n += len(ros.ros_cloud(decode(message.data), schema.name).points)
                    return n

            return read

        runs = [
            (name, path, reader(path, topic), args.clouds) for name, (path, topic) in logs.items()
        ]
        runs += [
            ("Livox CustomMsg", livox, reader(livox, "/livox/lidar"), args.livox_clouds),
            (
                "Livox CustomMsg via rosbags",
                livox,
                library(livox, "/livox/lidar"),
                args.livox_clouds,
            ),
        ]
        print(f"clouds of {args.points} points, best of {args.repeat}")
        base = None
        for name, path, read, n_clouds in runs:
            seconds, n = _time(read, args.repeat)
            per_cloud = seconds / n_clouds
            base = base or per_cloud
            size = path.stat().st_size / 1e6
            print(
                f"{name:28s} {n_clouds:4d} clouds {size:6.1f} MB {1 / per_cloud:7.0f} clouds/s "
                f"{n / seconds / 1e6:6.1f} M points/s  {per_cloud / base:6.2f}x the foxglove time"
            )


if __name__ == "__main__":
    main()
