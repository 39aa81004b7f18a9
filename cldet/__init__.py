"""cldet: drone detection from LiDAR for the MMAUD anti-UAV challenge."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("cldet")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
