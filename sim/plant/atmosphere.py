"""The air a :class:`sim.plant.jsbsim_plant.JSBSimPlant` flies in: steady wind, Milspec Dryden
turbulence, ArduPilot SITL's random wind (``SIM_WIND_TURB``) and one-minus-cosine gusts, set on
the JSBSim model's atmosphere properties."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from mpf_mavlink.constants import FT_TO_M
from sim.plant.sitl_turbulence import SitlTurbulence

# Milspec Dryden settings (spec): windspeed at 20 ft AGL (ft/s), severity index.
TURBULENCE_LEVELS: dict[str, tuple[float, int]] = {
    "none": (0.0, 0),
    "light": (25.0, 3),
    "moderate": (50.0, 4),
    "severe": (75.0, 6),
}


# JSBSim's turbulence generator is a minimal-standard linear congruential engine (modulus
# 2^31 - 1): a seed is taken modulo 2^31 - 1 and 0 is replaced by 1, so seeds 0 and 1 drew the same
# turbulence (measured). Accepted seeds are below this limit, and 0 is sent as the one value left.
TURBULENCE_SEED_LIMIT = 2**31 - 2


def jsbsim_turbulence_seed(seed: int) -> int:
    """The ``atmosphere/randomseed`` for a seed in [0, TURBULENCE_SEED_LIMIT): itself, except 0
    (which JSBSim's engine would turn into 1) -> 2^31 - 2, a distinct stream no other seed has."""
    s = int(seed)
    if not 0 <= s < TURBULENCE_SEED_LIMIT:
        raise ValueError(f"turbulence seed must be in [0, {TURBULENCE_SEED_LIMIT}), got {seed}")
    return s if s > 0 else TURBULENCE_SEED_LIMIT


class JSBSimAtmosphere:
    """Sets a JSBSim model's atmosphere through ``node`` (property name -> its node); ``run``
    is one physics step (``fdm_run``), with the random wind added to the steady one when on."""

    def __init__(self, node: Callable[[str], Any], fdm_run: Callable[[], bool], dt: float):
        self._node = node
        self._fdm_run = fdm_run
        self.dt = float(dt)
        self.run: Callable[[], bool] = fdm_run
        self._steady_wind = (0.0, 0.0, 0.0)  # m/s NED, what set_wind last set
        self.random_wind: SitlTurbulence | None = None

    def _set(self, name: str, value: float) -> None:
        self._node(name).set_double_value(float(value))

    def set_wind(self, wind_ned_m_s: Any) -> None:
        """Steady air-mass velocity (m/s, NED, the direction the air moves TOWARD)."""
        wn, we, wd = (float(v) for v in wind_ned_m_s)
        self._steady_wind = (wn, we, wd)  # the random wind (if any) is added to it every step
        self._set("atmosphere/wind-north-fps", wn / FT_TO_M)
        self._set("atmosphere/wind-east-fps", we / FT_TO_M)
        self._set("atmosphere/wind-down-fps", wd / FT_TO_M)

    def set_turbulence(self, kind: str = "none", seed: int = 0) -> None:
        """Milspec Dryden turbulence (JSBSim turb-type 3): none, light, moderate or severe.

        Windspeed at 20 ft AGL / severity: light 25 fps / 3, moderate 50 fps / 4, severe 75 fps / 6.
        ``seed`` (0 <= seed < :data:`TURBULENCE_SEED_LIMIT`) picks the turbulence noise: every
        seed its own draw (:func:`jsbsim_turbulence_seed`).

        JSBSim evaluates the MIL-F-8785C scales at the altitude above SEA LEVEL (FGWinds::Run
        passes AltitudeASL), not above ground: with a home 488 m AMSL the X8 at 100 m AGL is at
        1932 ft, in the blend towards the high-altitude model (L_u = L_w ~ 520 m, sigma ~ 2 m/s in
        every axis for "light"), not the low-altitude one the levels are named after (at 100 m
        AGL: L_w = 100 m, sigma_w = 0.76 m/s). Its gusts are therefore long and strong: the mean
        of one 300 s flight can sit ~1 m/s (one sigma of sigma sqrt(2 L / (V T))) off the steady
        wind.
        """
        if kind not in TURBULENCE_LEVELS:
            raise ValueError(f"turbulence kind must be one of {sorted(TURBULENCE_LEVELS)}")
        w20, sev = TURBULENCE_LEVELS[kind]
        self._set("atmosphere/randomseed", jsbsim_turbulence_seed(seed))
        if kind == "none":
            self._set("atmosphere/turb-type", 0)
            self._set("atmosphere/turbulence/milspec/windspeed_at_20ft_AGL-fps", 0.0)
            self._set("atmosphere/turbulence/milspec/severity", 0)
            return
        self._set("atmosphere/turb-type", 3)
        self._set("atmosphere/turbulence/milspec/windspeed_at_20ft_AGL-fps", w20)
        self._set("atmosphere/turbulence/milspec/severity", sev)

    def set_random_wind(self, turbulence_m_s: float, seed: int = 0) -> None:
        """ArduPilot SITL's ``SIM_WIND_TURB`` (m/s; 0: off): a random air-mass velocity added to
        the steady wind before every physics step, as the firmware's simulator does
        (:mod:`sim.plant.sitl_turbulence`: its process at its 1200 Hz, averaged over our step).
        ``seed``: every seed its own draw, the same seed the same flight."""
        if turbulence_m_s <= 0.0:
            self.random_wind = None
            self.run = self._fdm_run
            self.set_wind(self._steady_wind)
            return
        rw = self.random_wind = SitlTurbulence(turbulence_m_s, self.dt, seed)
        nxt, run = rw.next, self._fdm_run
        n_n = self._node("atmosphere/wind-north-fps")
        n_e = self._node("atmosphere/wind-east-fps")
        n_d = self._node("atmosphere/wind-down-fps")
        k = 1.0 / FT_TO_M

        def run_with_random_wind() -> bool:
            wn, we, wd = nxt()
            sn, se, sd = self._steady_wind
            n_n.set_double_value((sn + wn) * k)
            n_e.set_double_value((se + we) * k)
            n_d.set_double_value((sd + wd) * k)
            return bool(run())

        self.run = run_with_random_wind

    def trigger_gust(
        self,
        direction_ned: Any = (0.0, 1.0, 0.0),
        magnitude_m_s: float = 5.0,
        rise_s: float = 1.0,
        hold_s: float = 2.0,
        decay_s: float = 1.0,
    ) -> None:
        """One-minus-cosine gust (JSBSim ``atmosphere/cosine-gust``), air-mass velocity in NED.

        The air moves along ``direction_ned`` (normalized here) with a (1 - cos) ramp up over
        ``rise_s``, ``magnitude_m_s`` held for ``hold_s`` and a cosine decay over ``decay_s``.
        """
        d = [float(v) for v in direction_ned]
        nrm = math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
        if nrm < 1e-9:
            raise ValueError("gust direction must be non-zero")
        p = "atmosphere/cosine-gust/"
        self._set(p + "startup-duration-sec", rise_s)
        self._set(p + "steady-duration-sec", hold_s)
        self._set(p + "end-duration-sec", decay_s)
        self._set(p + "magnitude-ft_sec", magnitude_m_s / FT_TO_M)
        self._set(p + "frame", 3)  # gfLocal: NED
        self._set(p + "X-velocity-ft_sec", d[0] / nrm)
        self._set(p + "Y-velocity-ft_sec", d[1] / nrm)
        self._set(p + "Z-velocity-ft_sec", d[2] / nrm)
        self._set(p + "start", 1)
