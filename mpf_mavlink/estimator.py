"""Telemetry samples -> the law's VehicleState (pure of I/O: fed decoded samples, no clock).

Streams and their times
-----------------------
- attitude: ATTITUDE or ATTITUDE_QUATERNION (time_boot_ms). Its time is the control time.
- position: LOCAL_POSITION_NED (time_boot_ms), or GLOBAL_POSITION_INT converted to local NED
  about a geodetic origin (configured, else HOME_POSITION, whose local offset is added so both
  sources share the autopilot's local frame). LOCAL is preferred while fresh.
  The position is extrapolated by its velocity to the attitude time.
- airspeed: VFR_HUD (no timestamp: staleness from receive times).
- wind: WIND (ArduPilot) / WIND_COV (PX4), receive-time staleness. Without one, a simple
  estimator: a first-order low-pass (time constant ``wind_tau_s``) of
  ``ground velocity - airspeed * body x-axis`` (assumes zero sideslip and angle of attack,
  good to a few tenths of m/s for a trimmed fixed-wing).

Staleness: a stream is stale when it lags the attitude sample by more than its limit (boot
time for timestamped streams, receive time otherwise). A stale attitude/position/airspeed
makes :meth:`Estimator.estimate` return None with the reason.

Wind frame: w1 along the air-relative velocity (ground velocity - wind); when that is tiny
(< ``min_air_speed``), along the body x-axis. v_w = VFR_HUD airspeed, else |air velocity|.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .frames import geodetic_to_ned, wind_frame_from_velocity
from .guidance.law import VehicleState


def wind_frame(vx: float, vy: float, vz: float) -> NDArray[np.float64]:
    """Scalar twin of :func:`frames.wind_frame_from_velocity` (roll_ref = 0), ~10x faster:
    w1 = v/|v|, w2 = down x w1 normalised (horizontal, to the right), w3 = w1 x w2."""
    n = math.sqrt(vx * vx + vy * vy + vz * vz)
    if n < 1e-6:
        return wind_frame_from_velocity((vx, vy, vz))  # raises the documented ValueError
    a, b, c = vx / n, vy / n, vz / n
    h = math.sqrt(a * a + b * b)
    if h < 1e-9:
        e, f, g = 0.0, 1.0, 0.0
    else:
        e, f, g = -b / h, a / h, 0.0
    return np.array([[a, e, b * g - c * f], [b, f, c * e - a * g], [c, g, a * f - b * e]])


@dataclass(frozen=True)
class EstimatorParams:
    attitude_stale_s: float = 0.5
    position_stale_s: float = 0.5
    airspeed_stale_s: float = 0.5
    wind_stale_s: float = 2.0
    wind_tau_s: float = 5.0
    min_air_speed: float = 1.0  # m/s: below this w1 falls back to the body x-axis
    origin: tuple[float, float, float] | None = None  # lat deg, lon deg, alt m (AMSL)


@dataclass(frozen=True, eq=False)
class Estimate:
    """A VehicleState plus what the adapter and the logs need.

    vehicle.t is the attitude sample's autopilot time (s since boot) minus ``t0``."""

    vehicle: VehicleState
    t_boot_s: float
    R_B_N: NDArray[np.float64]
    rates_frd: NDArray[np.float64]
    ground_velocity: NDArray[np.float64]
    position_source: str  # "local" | "global"
    airspeed_source: str  # "vfr_hud" | "air_velocity"
    wind_source: str  # "WIND" | "WIND_COV" | "estimated"


class Estimator:
    """Keeps the latest sample of each stream; :meth:`estimate` fuses them at the attitude time."""

    def __init__(self, params: EstimatorParams = EstimatorParams()) -> None:
        self.p = params
        self.att = None  # AttitudeSample
        self.att_rx: float | None = None
        self.local = None  # LocalPositionSample
        self.glob = None  # GlobalPositionSample
        self.home = None  # HomeSample
        self.vfr = None
        self.vfr_rx: float | None = None
        self.wind = None
        self.wind_rx: float | None = None
        self._wind_lp: NDArray[np.float64] | None = None
        self._wind_lp_t: float | None = None
        self.t0 = 0.0  # time origin subtracted from t_boot (mission time)

    # -- feeding ------------------------------------------------------------------------------
    def update(self, sample: object, t_rx: float | None) -> bool:
        """Store a decoded sample (t_rx: receive time, s, any monotonic-ish clock of the link).
        Returns True when it was an attitude sample (a control instant)."""
        name = type(sample).__name__
        if name == "AttitudeSample":
            self.att, self.att_rx = sample, t_rx
            return True
        if name == "LocalPositionSample":
            self.local = sample
        elif name == "GlobalPositionSample":
            self.glob = sample
        elif name == "HomeSample":
            self.home = sample
        elif name == "VfrHudSample":
            self.vfr, self.vfr_rx = sample, t_rx
        elif name == "WindSample":
            self.wind, self.wind_rx = sample, t_rx
        return False

    def geodetic_origin(self) -> tuple[float, float, float, NDArray[np.float64]] | None:
        """(lat, lon, alt, local offset of that point) of the local frame, or None if unknown."""
        if self.p.origin is not None:
            return (*self.p.origin, np.zeros(3))
        if self.home is not None:
            h = self.home
            return (h.lat_deg, h.lon_deg, h.alt_amsl_m, np.asarray(h.pos_ned, float))
        return None

    def to_local(self, lat: float, lon: float, alt: float) -> NDArray[np.float64] | None:
        o = self.geodetic_origin()
        if o is None:
            return None
        return geodetic_to_ned(lat, lon, alt, o[0], o[1], o[2]) + o[3]

    # -- fusing -------------------------------------------------------------------------------
    def _position(self, t: float) -> tuple[NDArray[np.float64], NDArray[np.float64], str] | str:
        p = self.p
        loc = self.local
        if loc is not None and abs(t - loc.t_boot_s) <= p.position_stale_s:
            dt = t - loc.t_boot_s
            return np.asarray(loc.pos_ned) + dt * np.asarray(loc.vel_ned), np.asarray(loc.vel_ned, float), "local"
        g = self.glob
        if g is not None and abs(t - g.t_boot_s) <= p.position_stale_s:
            q = self.to_local(g.lat_deg, g.lon_deg, g.alt_amsl_m)
            if q is None:
                return "GLOBAL_POSITION_INT without an origin (no HOME_POSITION, no mavlink.origin_*)"
            dt = t - g.t_boot_s
            return q + dt * np.asarray(g.vel_ned), np.asarray(g.vel_ned, float), "global"
        if loc is None and g is None:
            return "no position yet (LOCAL_POSITION_NED or GLOBAL_POSITION_INT)"
        last = max(x.t_boot_s for x in (loc, g) if x is not None)
        return f"position stale ({t - last:.2f} s behind the attitude)"

    def estimate(self) -> tuple[Estimate | None, str]:
        """The state at the latest attitude sample, or (None, reason)."""
        a = self.att
        if a is None:
            return None, "no attitude yet"
        t = a.t_boot_s
        pos = self._position(t)
        if isinstance(pos, str):
            return None, pos
        p_ned, vg, psrc = pos
        R = np.asarray(a.R_B_N, float)
        x_b = R[:, 0]
        p = self.p
        airspeed: float | None = None
        if self.vfr is not None and (
            self.vfr_rx is None or self.att_rx is None or abs(self.att_rx - self.vfr_rx) <= p.airspeed_stale_s
        ):
            airspeed = float(self.vfr.airspeed_m_s)
        elif self.vfr is not None:
            return None, f"airspeed stale ({self.att_rx - self.vfr_rx:.2f} s behind the attitude)"  # type: ignore[operator]
        # wind: the autopilot's when fresh, else our low-pass of vg - v_air x_b
        if self._wind_lp is None or self._wind_lp_t is None or t < self._wind_lp_t:
            self._wind_lp, self._wind_lp_t = np.zeros(3), t
        if airspeed is not None:
            inst = vg - airspeed * x_b
            inst[2] = 0.0  # vertical wind is not observable this way (angle of attack)
            k = min(1.0, max(0.0, t - self._wind_lp_t) / p.wind_tau_s)
            self._wind_lp = self._wind_lp + k * (inst - self._wind_lp)
        self._wind_lp_t = t
        w = self.wind
        if w is not None and (self.wind_rx is None or self.att_rx is None or abs(self.att_rx - self.wind_rx) <= p.wind_stale_s):
            wind, wsrc = np.asarray(w.wind_ned, float), w.source
        else:
            wind, wsrc = self._wind_lp.copy(), "estimated"
        v_air = (float(vg[0] - wind[0]), float(vg[1] - wind[1]), float(vg[2] - wind[2]))
        n_air = math.sqrt(v_air[0] ** 2 + v_air[1] ** 2 + v_air[2] ** 2)
        if n_air < p.min_air_speed:
            R_W_I = wind_frame(float(x_b[0]), float(x_b[1]), float(x_b[2]))
        else:
            R_W_I = wind_frame(*v_air)
        if airspeed is not None and airspeed > 0.0:
            v_w, asrc = airspeed, "vfr_hud"
        else:
            v_w, asrc = max(n_air, 0.0), "air_velocity"
        if not v_w > 0.0:
            return None, "airspeed is zero"
        vs = VehicleState(t - self.t0, p_ned, R_W_I, v_w, wind)
        return Estimate(vs, t, R, np.asarray(a.rates_frd, float), vg, psrc, asrc, wsrc), ""
