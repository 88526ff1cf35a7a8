"""Paths fixed in the target frame, re-parameterised by arc length, with a transported frame."""

from mpf_mavlink.core.paths.base import PathSample, TabulatedPath
from mpf_mavlink.core.paths.shapes import circle, helix, lemniscate, line, spline

Path = TabulatedPath

__all__ = ["Path", "PathSample", "TabulatedPath", "circle", "helix", "lemniscate", "line", "spline"]
