"""Trim and mission scale of a stock JSBSim airframe, derived from the FDM itself.

JSBSim's own trim (``simulation/do_simple_trim`` = 1: longitudinal + lateral, FGTrim) finds the
throttle and the body pitch of steady level flight at a given airspeed and altitude; no number is
tuned per aircraft. From it:

- :func:`fdm_trim`: throttle and pitch (rad) of level flight at one airspeed;
- :func:`cruise_envelope`: the trim over a range of airspeeds, the lowest trimmable one (a
  stall / power bound from the aero and engine tables) and the minimum-power speed;
- :func:`mission_radius_m`: the smallest circle radius flyable at airspeed v within a bank limit
  less a margin, ``R = v^2 / (g tan(bank_max - margin))`` (coordinated turn, still air).

Constant-speed propellers (the pa28's): JSBSim's trim freezes the propeller governor's inputs
(JSBSim issue #1440) and fails whenever the propeller lever (``fcs/advance-cmd-norm``) is
forward, so these trims leave the lever at 0, where the governor holds the minimum RPM and the
engine gives about two thirds of its power: their throttle is an upper bound for the SIL plant,
which flies with the lever forward, and the vehicle's trim flight finds the real one.

Units SI (m, m/s, rad); altitude above mean sea level.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mpf_mavlink.constants import FT_TO_M, GRAVITY_M_S2


@dataclass(frozen=True)
class FdmTrim:
    """Steady level flight found by JSBSim's trim at ``airspeed_m_s`` (ok False: no trim)."""

    airspeed_m_s: float
    ok: bool
    throttle: float = float("nan")
    pitch_rad: float = float("nan")
    alpha_rad: float = float("nan")


def trimmed_fdm(
    model: str,
    root_dir: str | os.PathLike[str] | None,
    airspeed_m_s: float,
    altitude_m: float,
    dt: float | None = None,
) -> Any:
    """A ``jsbsim.FGFDMExec`` in JSBSim's full trim of level flight at true airspeed
    ``airspeed_m_s``, ``altitude_m`` MSL, or None when JSBSim finds none with a throttle in
    [0, 1]. root_dir None: the aircraft shipped in the jsbsim package. Engines are started
    (``propulsion/set-running`` -1, mixture rich where the model has one) before the trim; the
    model's output files and console chatter are suppressed. dt (s): the FDM step (None: the
    model's). Raises RuntimeError when the model does not load."""
    import jsbsim

    from .jsbsim_plant import _QuietStderr

    root = str(root_dir) if root_dir is not None else str(Path(jsbsim.get_default_root_dir()))
    fdm = jsbsim.FGFDMExec(root)
    fdm.set_debug_level(0)
    with _QuietStderr():
        ok = fdm.load_model(model)
        if ok:
            fdm.disable_output()
    if not ok:
        raise RuntimeError(f"JSBSim could not load model {model!r} from {root}")
    if dt is not None:
        fdm.set_dt(dt)
    fdm["ic/h-sl-ft"] = altitude_m / FT_TO_M
    fdm["ic/vt-fps"] = airspeed_m_s / FT_TO_M
    fdm["ic/gamma-deg"] = 0.0
    with _QuietStderr():
        fdm.run_ic()
    fdm["propulsion/set-running"] = -1
    if fdm.get_property_manager().hasNode("fcs/mixture-cmd-norm"):
        fdm["fcs/mixture-cmd-norm"] = 1.0
    try:
        with _QuietStderr():
            fdm["simulation/do_simple_trim"] = 1
    except Exception:  # jsbsim.TrimFailureError: no steady level flight at this speed
        return None
    if not 0.0 <= float(fdm["fcs/throttle-cmd-norm"]) <= 1.0:
        return None
    return fdm


def fdm_trim(
    model: str,
    root_dir: str | os.PathLike[str] | None,
    airspeed_m_s: float,
    altitude_m: float = 800.0,
) -> FdmTrim:
    """JSBSim's full trim of level flight at true airspeed ``airspeed_m_s``, ``altitude_m`` MSL
    (:func:`trimmed_fdm`): throttle, body pitch and angle of attack; ok False when none."""
    fdm = trimmed_fdm(model, root_dir, airspeed_m_s, altitude_m)
    if fdm is None:
        return FdmTrim(airspeed_m_s, False)
    thr = float(fdm["fcs/throttle-cmd-norm"])
    return FdmTrim(
        airspeed_m_s,
        True,
        throttle=thr,
        pitch_rad=float(fdm["attitude/theta-rad"]),
        alpha_rad=float(fdm["aero/alpha-rad"]),
    )


@dataclass(frozen=True)
class CruiseEnvelope:
    """Trims over a speed range: lowest trimmable speed and the minimum-throttle speed (m/s)."""

    trims: tuple[FdmTrim, ...]

    @property
    def ok(self) -> tuple[FdmTrim, ...]:
        return tuple(t for t in self.trims if t.ok)

    @property
    def min_speed_m_s(self) -> float:
        ok = self.ok
        return min(t.airspeed_m_s for t in ok) if ok else float("nan")

    @property
    def max_speed_m_s(self) -> float:
        ok = self.ok
        return max(t.airspeed_m_s for t in ok) if ok else float("nan")

    @property
    def min_power(self) -> FdmTrim | None:
        ok = self.ok
        return min(ok, key=lambda t: t.throttle) if ok else None


def cruise_envelope(
    model: str,
    root_dir: str | os.PathLike[str] | None,
    speeds_m_s: tuple[float, ...] = (25.0, 30.0, 35.0, 40.0, 45.0, 50.0, 55.0, 60.0),
    altitude_m: float = 800.0,
) -> CruiseEnvelope:
    """:func:`fdm_trim` at each speed."""
    return CruiseEnvelope(tuple(fdm_trim(model, root_dir, v, altitude_m) for v in speeds_m_s))


def mission_radius_m(airspeed_m_s: float, bank_max_rad: float, margin_rad: float) -> float:
    """Smallest circle radius (m) flown at ``airspeed_m_s`` with bank <= bank_max - margin."""
    usable = bank_max_rad - margin_rad
    if not 0.0 < usable < math.pi / 2:
        raise ValueError(f"bank limit {bank_max_rad} less margin {margin_rad} leaves no turn")
    return airspeed_m_s**2 / (GRAVITY_M_S2 * math.tan(usable))


if __name__ == "__main__":  # python -m sim.plant.airframe_trim c172p c172x c182 pa28
    import argparse

    ap = argparse.ArgumentParser(
        prog="python -m sim.plant.airframe_trim",
        description="JSBSim's own level-flight trim of stock jsbsim-package aircraft over "
        "25-60 m/s: the trimmable speed range, the minimum-power speed, and throttle / body "
        "pitch at each speed (what aircraft.trim_airspeed_m_s may be).",
    )
    ap.add_argument("models", nargs="*", default=["c172p", "c172x", "c182", "pa28"])
    ap.add_argument("--altitude-m", type=float, default=800.0, help="MSL (default 800)")
    args = ap.parse_args()
    for m in args.models:
        try:
            env = cruise_envelope(m, None, altitude_m=args.altitude_m)
        except RuntimeError as e:
            ap.exit(2, f"python -m sim.plant.airframe_trim: error: {e}\n")
        mp = env.min_power
        row = " ".join(
            f"{t.airspeed_m_s:g}:{t.throttle:.3f}/{math.degrees(t.pitch_rad):.1f}deg"
            if t.ok
            else f"{t.airspeed_m_s:g}:-"
            for t in env.trims
        )
        print(f"{m}: trimmable {env.min_speed_m_s:g}..{env.max_speed_m_s:g} m/s, min power at "
              f"{mp.airspeed_m_s if mp else float('nan'):g} m/s; {row}")  # fmt: skip
