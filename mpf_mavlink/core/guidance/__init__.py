"""The MPF guidance law and its pre-flight checks (pure: no I/O, no clock)."""

from mpf_mavlink.core.guidance.law import (
    Extensions,
    Gains,
    MpfCommand,
    MpfDiagnostics,
    VehicleState,
    mpf_law,
)

__all__ = ["Extensions", "Gains", "MpfCommand", "MpfDiagnostics", "VehicleState", "mpf_law"]
