"""``guidance.law`` dispatch: the MPF law, or one of the NPFG/L1/pursuit baselines (its own
module so that an MPF flight does not load :mod:`.baselines`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from mpf_mavlink.core.guidance.law import (
    Extensions,
    Gains,
    MpfCommand,
    MpfDiagnostics,
    VehicleState,
    mpf_law,
)

if TYPE_CHECKING:
    from mpf_mavlink.core.guidance.baselines import BaselineParams
    from mpf_mavlink.core.paths import TabulatedPath
    from mpf_mavlink.core.target import TargetState


def guidance_law(
    law: str,
    s: float,
    vehicle: VehicleState,
    target: TargetState,
    path: TabulatedPath,
    gains: Gains,
    ext: Extensions,
    diagnostics: bool = True,
    params: BaselineParams | None = None,
) -> tuple[MpfCommand, MpfDiagnostics | None]:
    """MPF or one of the baselines (``law``, guidance.law's name), one command type; ``s`` the
    path parameter (m), the states NED; ``params`` None: the baselines' defaults."""
    if law == "mpf":
        return mpf_law(s, vehicle, target, path, gains, ext, diagnostics)
    # the baselines only load when guidance.law names one
    from mpf_mavlink.core.guidance.baselines import baseline_law

    if params is None:
        return baseline_law(law, s, vehicle, target, path)
    return baseline_law(law, s, vehicle, target, path, params)
