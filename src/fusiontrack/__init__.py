"""fusiontrack: multi-sensor people and vehicle tracking (laser, camera, RGB-D, phone IMU)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("fusiontrack")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
