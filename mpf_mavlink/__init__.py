"""mpf-mavlink: 3D moving-path-following guidance bridge for fixed-wing autopilots."""

__version__ = "0.1.0"
