"""Physical constants and unit conversions shared by the bridge, the checks and the SIL.

One definition each, so a reader never wonders whether two modules disagree. SI units.
"""

from __future__ import annotations

from typing import Final

GRAVITY_M_S2: Final = 9.80665
"""Standard gravity (m/s^2), the value ISA, JSBSim and both autopilots use."""

FT_TO_M: Final = 0.3048
"""International foot in metres (JSBSim's properties are in feet)."""

WGS84_A_M: Final = 6378137.0
"""WGS-84 semi-major axis (m)."""

WGS84_F: Final = 1.0 / 298.257223563
"""WGS-84 flattening."""

RHO0_KG_M3: Final = 1.225
"""ISA sea-level air density (kg/m^3), the reference of equivalent airspeed."""
