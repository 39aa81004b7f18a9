"""Colours (RGBA, 0-255) shared by the log's result channels and the Rerun view, so a drone
looks the same in Foxglove and in Rerun."""

from __future__ import annotations

from typing import Final

from cldet.types import Source

__all__ = ["CHOSEN_RGBA", "SOURCE_RGBA", "TRACK_RGBA"]

RGBA = tuple[int, int, int, int]

SOURCE_RGBA: Final[dict[Source, RGBA]] = {
    Source.DETECTED: (40, 220, 60, 255),  # green: measured this frame
    Source.PREDICTED: (255, 170, 0, 255),  # orange: the track's prediction, nothing measured
    Source.SMOOTHED: (80, 200, 255, 255),  # light blue: filled by the offline smoother
    Source.FALLBACK: (255, 40, 40, 255),  # red: no track, a fallback guess
}
TRACK_RGBA: Final[RGBA] = (255, 60, 200, 255)  # magenta: the refined track
CHOSEN_RGBA: Final[RGBA] = (40, 220, 60, 255)  # green: the cluster chosen as the drone
