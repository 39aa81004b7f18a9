"""The static transform tree of cldet's logs: one z-up ``world`` root over every sensor frame.

Every log ``cldet convert`` writes holds one ``foxglove.FrameTransforms`` message on ``/tf`` at
its first stamp; ``cldet annotate`` adds one to a log that has none. The tree (parent -> child,
each transform taking child coordinates into the parent's)::

    world                 level, z up, origin on the ground right below the Mid-360
    └── mid360            the Mid-360 (both LiDARs, the ground truth, every cldet result):
        │                 height and tilt from the configuration's ``sensor`` section
        ├── radar         APPROXIMATE: the radar's extrinsic is not published
        └── fisheye       APPROXIMATE: the camera's extrinsic is not published

The radar and the fisheye camera are placed at the Mid-360's origin looking along its +x axis,
in the optical convention their data use (z = boresight, x right, y down). That is a guess that
keeps their frames connected (so both viewers draw everything without settings); their points
are not fused with the LiDARs anywhere, and no result depends on it.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Final

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from cldet.config import SensorConfig
from cldet.io import topics
from cldet.io.ros import FrameTransform

__all__ = [
    "OPTICAL_IN_MID360",
    "log_tree",
    "sensor_tree",
    "tree_problem",
    "world_from_mid360",
]

# The optical axes (x right, y down, z boresight) of a sensor looking along the Mid-360's +x,
# as columns in the Mid-360's frame: x_o = -y, y_o = -z, z_o = +x.
OPTICAL_IN_MID360: Final = np.array(
    [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]], dtype=np.float64
)


def _matrix(rotation: NDArray[np.float64], translation: Sequence[float]) -> NDArray[np.float64]:
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = translation
    return out


def world_from_mid360(sensor: SensorConfig) -> NDArray[np.float64]:
    """(4, 4) transform taking Mid-360 points into ``world`` (the sensor's height and tilt)."""
    tilt = Rotation.from_euler("xy", [sensor.roll_deg, sensor.pitch_deg], degrees=True)
    return _matrix(tilt.as_matrix(), (0.0, 0.0, sensor.height_m))


def sensor_tree(sensor: SensorConfig | None = None) -> list[FrameTransform]:
    """The transforms of a cldet log: world -> mid360 -> {radar, fisheye} (see the module doc)."""
    sensor = sensor or SensorConfig()
    optical = _matrix(OPTICAL_IN_MID360, (0.0, 0.0, 0.0))
    return [
        FrameTransform(topics.FRAME_WORLD, topics.FRAME_MID360, world_from_mid360(sensor)),
        FrameTransform(topics.FRAME_MID360, topics.FRAME_RADAR, optical),
        FrameTransform(topics.FRAME_MID360, topics.FRAME_CAMERA, optical.copy()),
    ]


def log_tree(lidar_frame: str, sensor: SensorConfig | None = None) -> list[FrameTransform]:
    """The tree annotate adds to a log without one: cldet's own, or world -> the LiDAR's frame.

    A ROS recording's other frames are connected (or not) by its own ``/tf_static``.
    """
    if lidar_frame == topics.FRAME_MID360:
        return sensor_tree(sensor)
    return [
        FrameTransform(topics.FRAME_WORLD, lidar_frame, world_from_mid360(sensor or SensorConfig()))
    ]


def tree_problem(transforms: Iterable[FrameTransform], frames: Iterable[str]) -> str | None:
    """What keeps ``transforms`` from being one tree holding every frame id in ``frames``.

    Returns None for one rooted tree (every child has exactly one parent, no cycle, one root)
    that contains every frame of ``frames``; otherwise a sentence naming the problem.
    """
    parent: dict[str, str] = {}
    for t in transforms:
        if t.child == t.parent:
            return f"frame {t.child!r} is its own parent"
        if parent.get(t.child, t.parent) != t.parent:
            return f"frame {t.child!r} has two parents, {parent[t.child]!r} and {t.parent!r}"
        parent[t.child] = t.parent
    nodes = set(parent) | set(parent.values()) | set(frames)
    roots: set[str] = set()
    for node in sorted(nodes):
        seen = {node}
        while node in parent:
            node = parent[node]
            if node in seen:
                return f"the transforms form a cycle through {node!r}"
            seen.add(node)
        roots.add(node)
    if len(roots) != 1:
        return (
            "the frames form "
            + f"{len(roots)} unconnected trees, rooted at "
            + ", ".join(repr(r) for r in sorted(roots))
        )
    return None
