"""mpf-mavlink: 3D moving-path-following guidance bridge for fixed-wing autopilots."""

from mpf_mavlink import _compiled

__version__ = "0.1.0"

# The compiled hot paths when built and current (mpf_mavlink._compiled); pure Python otherwise.
_compiled.install()
