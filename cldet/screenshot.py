"""Screenshots of a recording or a log in the real Rerun viewer, headless (Xvfb), for review.

What works on a machine without a GPU: Debian's ``xvfb`` started with ``-extension Composite``
(without it the window stays black) and ``mesa-vulkan-drivers`` (the viewer renders with Vulkan
on llvmpipe; its GL renderer fails). ``python3 -m cldet.screenshot FILE OUT.png`` saves one PNG
of ``FILE`` (an ``.rrd`` or an ``.mcap``) as the viewer first shows it.

:func:`scene_fill` measures a screenshot: the fraction of pixels in a region that differ from
the background, which tells an empty 3D view from one that draws something.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from cldet.errors import CldetError

__all__ = ["missing_tools", "scene_fill", "screenshot"]

WINDOW_SIZE = (1600, 1000)  # logical points; the PNG is twice that on this viewer


_VULKAN_DRIVERS = ("/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d")


def missing_tools() -> list[str]:
    """What a screenshot needs and this machine lacks: ``xvfb-run``, ``Xvfb``, ``rerun`` on PATH
    and a Vulkan driver (an ICD file, e.g. Mesa's llvmpipe from ``mesa-vulkan-drivers``)."""
    missing = [tool for tool in ("xvfb-run", "Xvfb", "rerun") if shutil.which(tool) is None]
    if not any(
        Path(folder).is_dir() and any(Path(folder).glob("*.json")) for folder in _VULKAN_DRIVERS
    ):
        missing.append("a Vulkan driver")
    return missing


def screenshot(
    source: Path,
    png: Path,
    *,
    size: tuple[int, int] = WINDOW_SIZE,
    timeout_s: float = 300.0,
) -> Path:
    """Open ``source`` in the Rerun viewer under Xvfb and save what it shows to ``png``.

    Raises:
        CldetError: a tool is missing, the viewer fails or times out, or no PNG was written.
    """
    missing = missing_tools()
    if missing:
        raise CldetError(
            f"cannot take a screenshot: {', '.join(missing)} not found "
            "(apt-get install xvfb mesa-vulkan-drivers; pip install rerun-sdk)"
        )
    if not Path(source).is_file():
        raise CldetError(f"{source}: no such file")
    png = Path(png)
    png.unlink(missing_ok=True)
    width, height = size
    env = dict(os.environ, WGPU_BACKEND="vulkan")
    runtime = tempfile.mkdtemp(prefix="cldet-xdg-")
    env.setdefault("XDG_RUNTIME_DIR", runtime)
    os.chmod(runtime, 0o700)
    command = [
        "xvfb-run",
        "-a",
        "-s",
        f"-screen 0 {width}x{height}x24 -extension Composite",
        "rerun",
        str(source),
        "--screenshot-to",
        str(png),
        "--window-size",
        f"{width}x{height}",
    ]
    try:
        done = subprocess.run(
            command, capture_output=True, text=True, timeout=timeout_s, env=env, check=False
        )
    except subprocess.TimeoutExpired as err:
        raise CldetError(f"the Rerun viewer took over {timeout_s:.0f} s on {source}") from err
    finally:
        shutil.rmtree(runtime, ignore_errors=True)
    if done.returncode != 0 or not png.is_file():
        tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
        raise CldetError(
            f"the Rerun viewer wrote no screenshot of {source} (exit {done.returncode}): "
            + " | ".join(tail)
        )
    return png


def _read_png(png: Path) -> NDArray[np.uint8]:
    from PIL import Image

    with Image.open(png) as image:
        return np.asarray(image.convert("RGB"), dtype=np.uint8)


def scene_fill(
    png: Path,
    region: tuple[float, float, float, float] = (0.15, 0.1, 0.8, 0.75),
    *,
    tolerance: int = 60,
) -> float:
    """Fraction of the pixels in ``region`` of a screenshot that stand out from its background.

    Args:
        png: a screenshot.
        region: (left, top, right, bottom) as fractions of the width and height; the default
            is the middle of the window, inside the 3D view of either layout.
        tolerance: a pixel is background when each channel is within this of the region's
            most common colour (the view's background; the grid lines are faint and count as
            background at the default).
    """
    pixels = _read_png(png)
    h, w = pixels.shape[:2]
    left, top, right, bottom = region
    area = pixels[int(top * h) : int(bottom * h), int(left * w) : int(right * w)].reshape(-1, 3)
    if not len(area):
        return 0.0
    colours, counts = np.unique(area, axis=0, return_counts=True)
    background = colours[np.argmax(counts)].astype(np.int16)
    differs = np.abs(area.astype(np.int16) - background).max(axis=1) > tolerance
    return float(differs.mean())


def main(argv: list[str] | None = None) -> int:
    """``python3 -m cldet.screenshot FILE OUT.png [--size WxH]``: one screenshot."""
    parser = argparse.ArgumentParser(prog="python3 -m cldet.screenshot", description=__doc__)
    parser.add_argument("source", type=Path, help="an .rrd recording or an .mcap log")
    parser.add_argument("png", type=Path, help="where the PNG goes")
    parser.add_argument("--size", default="1600x1000", help="window size in points, WxH")
    args = parser.parse_args(argv)
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        print(f"ERROR: --size {args.size!r} is not WIDTHxHEIGHT", file=sys.stderr)
        return 1
    try:
        out = screenshot(args.source, args.png, size=(width, height))
    except CldetError as err:
        print(f"ERROR: {err}", file=sys.stderr)
        return 1
    print(f"{out}: {scene_fill(out):.1%} of the view's middle drawn")
    return 0


if __name__ == "__main__":
    sys.exit(main())
