"""A cheap kinematic fixed-wing plant with JSBSimPlant's interface (for the MAVLink SIL vehicle).

Same ``step(aileron, elevator, rudder, throttle)`` / ``state() -> PlantState`` / ``dt`` / ``t`` /
``origin`` / ``set_wind`` interface as :class:`sim.plant.jsbsim_plant.JSBSimPlant`, so
:class:`sim.vehicle.vehicle.SimVehicle` and :class:`sim.autopilot.inner_loop.FixedWingAutopilot`
drive it unchanged.

Model (SI, NED, FRD; alpha = beta = 0, so the body x axis is along the air-relative velocity):

* constant true airspeed ``V`` (throttle and rudder are recorded, not used);
* body roll and pitch rates follow the surfaces with first-order lags:
  ``p' = (K_a * aileron - p) / tau_p``, ``q' = (-K_e * elevator - q) / tau_q``
  (positive elevator = nose down, as in JSBSim). ``K_a = 2.0 rad/s`` and ``K_e = 1/0.55 rad/s``
  per unit command make the autopilot's feed-forwards (0.5 roll, 0.55 pitch) track the rate
  setpoints; ``tau_p = 0.15 s`` is close to the X8's roll-mode time constant (~0.19 s);
* bank-to-turn: ``psi' = g tan(phi) / V`` (always coordinated); ``phi' = p``;
* pitch rate -> flight-path rate: ``q = cos(phi) gamma' + sin(phi) cos(gamma) psi'`` solved for
  ``gamma'`` (the same relation the autopilot's turn coordination uses, so a coordinated turn
  holds altitude); ``theta = gamma``; ``r = cos(phi) cos(gamma) psi' - sin(phi) gamma'``;
* position: ``p' = V [cos g cos psi, cos g sin psi, -sin g] + wind``.

Geodetic output uses the exact WGS-84 inverse of :class:`sim.plant.jsbsim_plant.LocalNED`
(:func:`ned_to_geodetic_fast`, a few microseconds, no pymap3d).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mpf_mavlink.constants import GRAVITY_M_S2, WGS84_A_M
from sim.plant.jsbsim_plant import WGS84_E2, LocalNED, PlantState


def ned_to_geodetic_fast(
    origin: LocalNED, n: float, e: float, d: float
) -> tuple[float, float, float]:
    """Local NED (m) about ``origin`` -> WGS-84 (lat deg, lon deg, alt m); exact (iterated)."""
    rn, re, rd = origin._rn, origin._re, origin._rd
    x = origin._o[0] + rn[0] * n + re[0] * e + rd[0] * d
    y = origin._o[1] + rn[1] * n + re[1] * e + rd[1] * d
    z = origin._o[2] + rn[2] * n + re[2] * e + rd[2] * d
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1.0 - WGS84_E2))
    h = 0.0
    for _ in range(5):  # converges to < 1e-9 rad near the surface
        s = math.sin(lat)
        N = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * s * s)
        c = math.cos(lat)
        h = p / c - N if abs(c) > 1e-12 else abs(z) - N * (1.0 - WGS84_E2)
        lat = math.atan2(z, p * (1.0 - WGS84_E2 * N / (N + h)))
    return math.degrees(lat), math.degrees(lon), h


class KinematicMavPlant:
    """Constant-airspeed bank-to-turn plant (see module docstring); its constructor mirrors
    JSBSimPlant's."""

    def __init__(
        self,
        dt: float = 1.0 / 120.0,
        lat0_deg: float = 47.397742,
        lon0_deg: float = 8.545594,
        alt0_m: float = 488.0,
        position_ned: Any = (0.0, 0.0, -100.0),
        heading: float = 0.0,
        airspeed: float = 16.0,
        throttle: float = 0.3,
        roll_gain: float = 2.0,
        roll_tau: float = 0.15,
        pitch_gain: float = 1.0 / 0.55,
        pitch_tau: float = 0.1,
        **_ignored: Any,
    ) -> None:
        self.dt = float(dt)
        self.origin = LocalNED(lat0_deg, lon0_deg, alt0_m)
        self.V = float(airspeed)
        self.roll_gain, self.roll_tau = roll_gain, roll_tau
        self.pitch_gain, self.pitch_tau = pitch_gain, pitch_tau
        self._pos = [float(v) for v in position_ned]
        self._phi, self._gam, self._psi = 0.0, 0.0, float(heading)
        self._p = self._q = self._r = 0.0
        self._wind = (0.0, 0.0, 0.0)
        self._thr = float(throttle)
        self._k = 0
        self._acc = (0.0, 0.0, 0.0)

    @property
    def t(self) -> float:
        return self._k * self.dt

    # environment (steady wind only)
    def set_wind(self, wind_ned_m_s: Any) -> None:
        w = [float(v) for v in wind_ned_m_s]
        self._wind = (w[0], w[1], w[2])

    has_random_wind = False
    random_wind = None

    def set_random_wind(self, turbulence_m_s: float, seed: int = 0) -> None:
        if turbulence_m_s > 0.0:
            raise ValueError("the kinematic plant has no random wind (use jsbsim)")

    def set_turbulence(self, kind: str = "none", seed: int = 0) -> None:
        if kind != "none":
            raise NotImplementedError("the kinematic plant has steady wind only")

    def trigger_gust(self, *a: Any, **kw: Any) -> None:
        raise NotImplementedError("the kinematic plant has steady wind only")

    def _v_air(self) -> tuple[float, float, float]:
        cg, sg = math.cos(self._gam), math.sin(self._gam)
        return (self.V * cg * math.cos(self._psi), self.V * cg * math.sin(self._psi), -self.V * sg)

    def step(self, aileron: float, elevator: float, rudder: float, throttle: float) -> None:
        dt = self.dt
        a = max(-1.0, min(1.0, aileron))
        e = max(-1.0, min(1.0, elevator))
        self._thr = max(0.0, min(1.0, throttle))
        v0 = self._v_air()
        self._p += dt / self.roll_tau * (self.roll_gain * a - self._p)
        self._q += dt / self.pitch_tau * (-self.pitch_gain * e - self._q)
        phi = self._phi + self._p * dt
        phi = max(-1.4, min(1.4, phi))  # +-80 deg: keeps tan() finite
        psid = GRAVITY_M_S2 * math.tan(phi) / self.V
        cf = max(math.cos(phi), 0.2)
        gamd = (self._q - math.sin(phi) * math.cos(self._gam) * psid) / cf
        gam = max(-1.0, min(1.0, self._gam + gamd * dt))
        self._r = math.cos(phi) * math.cos(gam) * psid - math.sin(phi) * gamd
        self._phi, self._gam = phi, gam
        self._psi = (self._psi + psid * dt + math.pi) % (2.0 * math.pi) - math.pi
        v1 = self._v_air()
        w = self._wind
        for i in range(3):
            self._pos[i] += (0.5 * (v0[i] + v1[i]) + w[i]) * dt
        self._acc = ((v1[0] - v0[0]) / dt, (v1[1] - v0[1]) / dt, (v1[2] - v0[2]) / dt)
        self._k += 1

    def run(self, n: int, aileron: float, elevator: float, rudder: float, throttle: float) -> None:
        for _ in range(n):
            self.step(aileron, elevator, rudder, throttle)

    def step_rates(
        self, aileron: float, elevator: float, rudder: float, throttle: float
    ) -> tuple[float, float, float, float]:
        self.step(aileron, elevator, rudder, throttle)
        return (self._p, self._q, self._r, self.V)

    def rates_airspeed(self) -> tuple[float, float, float, float]:
        """(p, q, r) rad/s and the airspeed (m/s), as in :meth:`state`."""
        return (self._p, self._q, self._r, self.V)

    def attitude_rates(self) -> tuple[float, float, float, float, float, float]:
        """(roll, pitch, yaw) rad and (p, q, r) rad/s, as in :meth:`state`."""
        return (self._phi, self._gam, self._psi, self._p, self._q, self._r)

    def state(self) -> PlantState:
        phi, th, psi = self._phi, self._gam, self._psi
        cf, sf = math.cos(phi), math.sin(phi)
        ct, st = math.cos(th), math.sin(th)
        cp, sp = math.cos(psi), math.sin(psi)
        R = np.array(
            [
                [ct * cp, sf * st * cp - cf * sp, cf * st * cp + sf * sp],
                [ct * sp, sf * st * sp + cf * cp, cf * st * sp - sf * cp],
                [-st, sf * ct, cf * ct],
            ]
        )
        n, e, d = self._pos
        lat, lon, alt = ned_to_geodetic_fast(self.origin, n, e, d)
        va = self._v_air()
        w = np.array(self._wind)
        f_ned = np.array(self._acc) - np.array([0.0, 0.0, GRAVITY_M_S2])
        return PlantState(
            t=self.t,
            position_ned=np.array(self._pos),
            velocity_ned=np.array(va) + w,
            R_B_N=R,
            euler=(phi, th, psi),
            pqr=np.array((self._p, self._q, self._r)),
            airspeed=self.V,
            alpha=0.0,
            beta=0.0,
            wind_ned=w,
            lat_deg=lat,
            lon_deg=lon,
            alt_m=alt,
            specific_force_body=R.T @ f_ned,
            throttle=self._thr,
        )
