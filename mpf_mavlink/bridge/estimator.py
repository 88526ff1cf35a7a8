"""Telemetry samples -> the law's VehicleState (pure of I/O: fed decoded samples, no clock).

Streams and their times
-----------------------
- attitude: ATTITUDE or ATTITUDE_QUATERNION (time_boot_ms). Its time is the control time.
  One source per flight: ATTITUDE once one has been seen (the bridge asks for its rate),
  ATTITUDE_QUATERNION only while none has; :meth:`Estimator.lock_attitude_source` (at the
  mission origin) fixes the choice. PX4 streams both on some links, sampled on its own schedules:
  taken together their stamps interleave and the control rate became 50 or 100 Hz depending
  on how PX4 booted.
- position: LOCAL_POSITION_NED (time_boot_ms), or GLOBAL_POSITION_INT converted to local NED
  about a geodetic origin (configured, else HOME_POSITION, whose local offset is added so both
  sources share the autopilot's local frame). LOCAL is preferred while fresh.
  The position is extrapolated by its velocity to the attitude time.
- airspeed: VFR_HUD (no timestamp: staleness from receive times).
- wind: WIND (ArduPilot) / WIND_COV (PX4), receive-time staleness. Without one, a simple
  estimator: a first-order low-pass (time constant ``wind_tau_s``, started at the first
  measurement) of ``ground velocity - airspeed * body x-axis`` (assumes zero sideslip and angle
  of attack, good to a few tenths of m/s for a trimmed fixed-wing).

Staleness: a stream is stale when it lags the attitude sample by more than its limit (boot
time for timestamped streams, receive time otherwise); the attitude is stale when the other
streams have gone on for more than ``attitude_stale_s`` after it (receive times; position boot
times when no receive times are given). A stale attitude/position/airspeed makes
:meth:`Estimator.estimate` return None with a reason that starts with the stream's name.

Samples that are non-finite or implausible (a NaN, a speed beyond 200 m/s, a matrix that is not
a rotation, ...) are ignored by :meth:`Estimator.update`: the decoders already drop them, this
guards samples built elsewhere (replay tools, tests). An estimate is never non-finite.

Wind frame: w1 along the air-relative velocity (ground velocity - wind); when that is tiny
(< ``min_air_speed``), along the body x-axis. v_w = VFR_HUD airspeed, else |air velocity|.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple, cast

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.core.frames import wind_frame_from_velocity
from mpf_mavlink.core.guidance.law import VehicleState, vehicle_state_of_floats
from mpf_mavlink.core.so3 import exp as so3_exp

if TYPE_CHECKING:  # the decoded samples' types (mavlink.codec), for the checker only
    from mpf_mavlink.mavlink.codec import AttitudeSample, LocalPositionSample


def eas_to_tas(alt_amsl_m: float) -> float:
    """TAS / EAS = sqrt(rho0 / rho) in the ISA troposphere at ``alt_amsl_m`` (m), clamped to
    [-500, 11000] m. Autopilots report VFR_HUD.airspeed as equivalent (ArduPilot: EAS; PX4:
    calibrated/indicated, the same at UAV speeds); the law's v_w is the speed along w1, a true
    airspeed: at 600 m AMSL they differ by 3 %."""
    h = min(max(alt_amsl_m, -500.0), 11000.0) if math.isfinite(alt_amsl_m) else 0.0
    return float((1.0 - 2.25577e-5 * h) ** -2.127940)


def wind_frame_rows(vx: float, vy: float, vz: float) -> tuple[tuple[float, float, float], ...]:
    """The rows of :func:`wind_frame` as tuples (no numpy: the estimator's hot path)."""
    n = math.sqrt(vx * vx + vy * vy + vz * vz)
    if n < 1e-6:
        wind_frame_from_velocity((vx, vy, vz))  # raises the documented ValueError
    a, b, c = vx / n, vy / n, vz / n
    h = math.sqrt(a * a + b * b)
    if h < 1e-9:
        e, f, g = 0.0, 1.0, 0.0
    else:
        e, f, g = -b / h, a / h, 0.0
    return ((a, e, b * g - c * f), (b, f, c * e - a * g), (c, g, a * f - b * e))


def wind_frame(vx: float, vy: float, vz: float) -> NDArray[np.float64]:
    """Scalar twin of :func:`frames.wind_frame_from_velocity` (roll_ref = 0), ~10x faster:
    w1 = v/|v|, w2 = down x w1 normalised (horizontal, to the right), w3 = w1 x w2."""
    return np.array(wind_frame_rows(vx, vy, vz))


class LocalFrame:
    """WGS-84 geodetic -> local NED (m) about a fixed origin plus an offset (the origin's own
    local position): :func:`mpf_mavlink.core.frames.geodetic_to_ned` (pymap3d's geodetic2ned:
    both points to ECEF, their difference rotated into ENU) in scalars with the origin's terms
    computed once. The same operations in the same order on pymap3d's ellipsoid, and the same
    sin, cos and hypot, so the same floats (tests/test_estimator.py), at a tenth of the cost:
    every target fix is converted."""

    def __init__(self, lat0: float, lon0: float, alt0: float, offset: tuple[float, ...]) -> None:
        from pymap3d import Ellipsoid

        ell = Ellipsoid.from_name("wgs84")
        self.a, self.b = float(ell.semimajor_axis), float(ell.semiminor_axis)
        self.a2, self.ba2 = self.a**2, (self.b / self.a) ** 2
        self.x0, self.y0, self.z0 = self.ecef(lat0, lon0, alt0)
        la, lo = math.radians(lat0), math.radians(lon0)
        self.sla, self.cla, self.slo, self.clo = (
            math.sin(la),
            math.cos(la),
            math.sin(lo),
            math.cos(lo),
        )
        self.dn, self.de, self.dd = offset

    def ecef(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """pymap3d's geodetic2ecef (deg, deg, m -> m)."""
        la, lo = math.radians(lat), math.radians(lon)
        cla, sla = math.cos(la), math.sin(la)
        N = self.a2 / float(np.hypot(self.a * cla, self.b * sla))  # numpy's hypot, as pymap3d
        return (
            (N + alt) * cla * math.cos(lo),
            (N + alt) * cla * math.sin(lo),
            (N * self.ba2 + alt) * sla,
        )

    def ned(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """Local NED (m) of a geodetic point (deg, deg, m AMSL)."""
        x, y, z = self.ecef(lat, lon, alt)
        u, v, w = x - self.x0, y - self.y0, z - self.z0
        t = self.clo * u + self.slo * v
        east = -self.slo * u + self.clo * v
        up = self.cla * t + self.sla * w
        north = -self.sla * t + self.cla * w
        return north + self.dn, east + self.de, -up + self.dd


# Plausibility bounds of a sample (the decoders' bounds, kept here so this module stays pure)
_MAX_SPEED_M_S = 200.0
_MAX_RATE_RAD_S = 50.0
_MAX_LOCAL_POS_M = 1.0e6
_MIN_ALT_M, _MAX_ALT_M = -1000.0, 50000.0
_ROTATION_TOL = 1e-6


def _arr_list(a: object, shape: tuple[int, ...]) -> list[Any] | None:
    """``a`` as a (nested) list of floats if it has that shape, else None."""
    if type(a) is np.ndarray and a.dtype.char == "d":  # the decoders' arrays: no conversion
        return a.tolist() if a.shape == shape else None
    try:
        v = np.asarray(a, dtype=float)
    except (TypeError, ValueError):
        return None
    return v.tolist() if v.shape == shape else None


def _vec3_ok(a: object, bound: float) -> bool:
    """A finite 3-vector, every |element| <= bound (NaN fails the comparison)."""
    v = _arr_list(a, (3,))
    if v is None:
        return False
    x, y, z = v
    return bool(-bound <= x <= bound and -bound <= y <= bound and -bound <= z <= bound)


def _num_ok(x: object, lo: float, hi: float) -> bool:
    try:
        f = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False
    return math.isfinite(f) and lo <= f <= hi


def _geodetic_ok(s: object) -> bool:
    return (
        _num_ok(getattr(s, "lat_deg", None), -90.0, 90.0)
        and _num_ok(getattr(s, "lon_deg", None), -180.0, 180.0)
        and _num_ok(getattr(s, "alt_amsl_m", None), _MIN_ALT_M, _MAX_ALT_M)
    )


def _time_ok(s: object) -> bool:
    t = getattr(s, "t_boot_s", None)
    if type(t) is float:
        return math.isfinite(t)
    return _num_ok(t, -math.inf, math.inf)


def _rotation_ok(a: object) -> bool:
    """A 3x3 rotation: finite, orthonormal columns (to _ROTATION_TOL), determinant +1."""
    rows = _arr_list(a, (3, 3))
    if rows is None:
        return False
    (x0, y0, z0), (x1, y1, z1), (x2, y2, z2) = rows  # x, y, z: the columns
    b = 1.0 + _ROTATION_TOL  # a NaN fails the comparisons
    if not (
        -b <= x0 <= b and -b <= y0 <= b and -b <= z0 <= b
        and -b <= x1 <= b and -b <= y1 <= b and -b <= z1 <= b
        and -b <= x2 <= b and -b <= y2 <= b and -b <= z2 <= b
    ):  # fmt: skip
        return False
    tol = _ROTATION_TOL
    if not (
        abs(x0 * x0 + x1 * x1 + x2 * x2 - 1.0) <= tol
        and abs(y0 * y0 + y1 * y1 + y2 * y2 - 1.0) <= tol
        and abs(z0 * z0 + z1 * z1 + z2 * z2 - 1.0) <= tol
        and abs(x0 * y0 + x1 * y1 + x2 * y2) <= tol
        and abs(x0 * z0 + x1 * z1 + x2 * z2) <= tol
        and abs(y0 * z0 + y1 * z1 + y2 * z2) <= tol
    ):
        return False
    det = x0 * (y1 * z2 - y2 * z1) - x1 * (y0 * z2 - y2 * z0) + x2 * (y0 * z1 - y1 * z0)
    return bool(det > 0.0)


def _plausible(name: str, s: object) -> bool:
    """Whether a decoded sample can be taken into the state (finite and within bounds)."""
    g = getattr
    if name == "AttitudeSample":
        return (
            _time_ok(s)
            and _vec3_ok(g(s, "rates_frd", None), _MAX_RATE_RAD_S)
            and _rotation_ok(g(s, "R_B_N", None))
        )
    if name == "LocalPositionSample":
        return (
            _time_ok(s)
            and _vec3_ok(g(s, "pos_ned", None), _MAX_LOCAL_POS_M)
            and _vec3_ok(g(s, "vel_ned", None), _MAX_SPEED_M_S)
        )
    if name == "GlobalPositionSample":
        vel_ok = _vec3_ok(g(s, "vel_ned", None), _MAX_SPEED_M_S)
        return _time_ok(s) and _geodetic_ok(s) and vel_ok
    if name == "HomeSample":
        return _geodetic_ok(s) and _vec3_ok(g(s, "pos_ned", None), _MAX_LOCAL_POS_M)
    if name == "VfrHudSample":
        return _num_ok(g(s, "airspeed_m_s", None), 0.0, _MAX_SPEED_M_S)
    if name == "WindSample":
        return _vec3_ok(g(s, "wind_ned", None), _MAX_SPEED_M_S)
    return True


@dataclass(frozen=True)
class EstimatorParams:
    attitude_stale_s: float = 0.5
    position_stale_s: float = 0.5
    airspeed_stale_s: float = 0.5
    wind_stale_s: float = 2.0
    wind_tau_s: float = 5.0
    min_air_speed: float = 1.0  # m/s: below this w1 falls back to the body x-axis
    origin: tuple[float, float, float] | None = None  # lat deg, lon deg, alt m (AMSL)
    airspeed_is_eas: bool = True  # VFR_HUD.airspeed is EAS: scaled to TAS (eas_to_tas)
    airspeed_from_wind: bool = True  # v_w = |v_ground - wind| while the autopilot's wind is fresh


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
    airspeed_source: str  # "vfr_hud" | "air_velocity" | "ground_minus_wind"
    wind_source: str  # "WIND" | "WIND_COV" | "estimated"


_new = object.__new__


class _Fused(NamedTuple):
    """What :meth:`Estimator.estimate` and the wind low-pass both derive from the samples."""

    t: float
    px: float
    py: float
    pz: float
    vg: NDArray[np.float64]
    psrc: str
    R: NDArray[np.float64]
    R_rows: list[list[float]]
    airspeed: float | None


class LocalOrigin:
    """The geodetic point of the local NED frame: ``fixed`` (lat deg, lon deg, alt m AMSL,
    ``mavlink.origin_*``) when configured, else the vehicle's HOME_POSITION (``home``)."""

    def __init__(self, fixed: tuple[float, float, float] | None) -> None:
        self.fixed = fixed
        self.home: Any = None  # HomeSample
        self._frame: tuple[object, LocalFrame] | None = None  # (what it was built from, it)

    def geodetic(self) -> tuple[float, float, float, NDArray[np.float64]] | None:
        """(lat, lon, alt, local offset of that point) of the local frame, or None if unknown."""
        if self.fixed is not None:
            return (*self.fixed, np.zeros(3))
        if self.home is not None:
            h = self.home
            return (h.lat_deg, h.lon_deg, h.alt_amsl_m, np.asarray(h.pos_ned, float))
        return None

    def known(self) -> bool:
        """Whether :meth:`geodetic` is known."""
        return self.fixed is not None or self.home is not None

    def ned(self, lat: float, lon: float, alt: float) -> NDArray[np.float64] | None:
        """A geodetic point (deg, deg, m AMSL) in the local NED frame (m), None without an
        origin."""
        q = self.ned_xyz(lat, lon, alt)
        return None if q is None else np.array(q)

    def ned_xyz(self, lat: float, lon: float, alt: float) -> tuple[float, float, float] | None:
        """:meth:`ned` as a tuple (the hot path: every target fix)."""
        key: object = self.fixed if self.fixed is not None else self.home
        if key is None:
            return None
        f = self._frame
        if f is None or f[0] is not key:
            o = self.geodetic()
            assert o is not None
            f = self._frame = (key, LocalFrame(o[0], o[1], o[2], tuple(o[3].tolist())))
        return f[1].ned(lat, lon, alt)


class WindLowPass:
    """Our wind (m/s NED) when the autopilot reports none: a low-pass (``tau_s``) of
    v_ground - v_air x_b, started at the first measurement (not at zero: a calm start would bias
    w1 by the drift angle for several tau) and restarted when the autopilot's clock goes back (a
    reboot). Vertical wind is not observable this way (angle of attack): 0."""

    def __init__(self, tau_s: float) -> None:
        self.tau_s = float(tau_s)
        self.value: tuple[float, float, float] | None = None
        self.t: float | None = None  # autopilot time (s since boot) of the latest input

    def restart_if_back(self, t: float) -> None:
        if self.t is not None and t < self.t:
            self.value = self.t = None

    def add(self, t: float, x: float, y: float) -> None:
        """The horizontal wind measured at autopilot time t (s)."""
        lp = self.value
        if lp is None or self.t is None:
            self.value = (x, y, 0.0)
        else:
            k = 1.0 - math.exp(-max(0.0, t - self.t) / self.tau_s)
            lx, ly, lz = lp
            self.value = (lx + k * (x - lx), ly + k * (y - ly), lz + k * (0.0 - lz))
        self.t = t


class Estimator:
    """Keeps the latest sample of each stream; :meth:`estimate` fuses them at the attitude time."""

    def __init__(self, params: EstimatorParams = EstimatorParams()) -> None:
        self.p = params
        self.att: AttitudeSample | None = None
        self.att_rx: float | None = None
        self.att_source: str | None = None  # fixed by lock_attitude_source()
        self.att_seen: set[str] = set()  # the attitude sources heard so far
        self.att_ignored = 0  # attitude samples of the source not chosen
        self.local: LocalPositionSample | None = None
        self.local_rx: float | None = None
        self.glob: Any = None  # GlobalPositionSample
        self.glob_rx: float | None = None
        self.origin = LocalOrigin(params.origin)
        self.vfr: Any = None  # VfrHudSample
        self.vfr_rx: float | None = None
        self.wind: Any = None  # WindSample
        self.wind_rx: float | None = None
        self.wind_lp = WindLowPass(params.wind_tau_s)
        self._gen = 0  # samples stored so far
        self._fused: tuple[int, bool, _Fused | tuple[None, str]] | None = (
            None  # (_gen, at, _fuse())
        )
        self.t0 = 0.0  # time origin subtracted from t_boot (mission time)

    # -- feeding ------------------------------------------------------------------------------
    def update(self, sample: object, t_rx: float | None) -> bool:
        """Store a decoded sample (t_rx: receive time, s, any monotonic-ish clock of the link).
        Returns True when it was an attitude sample (a control instant). A non-finite or
        implausible sample, or a non-finite ``t_rx``, is ignored (returns False)."""
        name = type(sample).__name__
        if t_rx is not None and not (
            math.isfinite(t_rx) if type(t_rx) is float else _num_ok(t_rx, -math.inf, math.inf)
        ):
            return False
        if not _plausible(name, sample):
            return False
        if name == "AttitudeSample":
            src = getattr(sample, "source", "ATTITUDE")
            self.att_seen.add(src)
            want = self.att_source or (
                "ATTITUDE" if "ATTITUDE" in self.att_seen else "ATTITUDE_QUATERNION"
            )
            if src != want:
                self.att_ignored += 1
                return False
        self._gen += 1  # a new sample: the fused inputs cached for estimate() are out of date
        if name == "AttitudeSample":
            att = cast("AttitudeSample", sample)  # (its class name said so)
            self.att, self.att_rx = att, t_rx
            # the wind low-pass advances at each control instant, here, with the telemetry
            # received so far: advanced by whoever asked for an estimate first, its input
            # would depend on thread timing and a replay of the tlog could not reproduce it
            self._advance_wind(att)
            return True
        if name == "LocalPositionSample":
            self.local, self.local_rx = cast("LocalPositionSample", sample), t_rx
        elif name == "GlobalPositionSample":
            self.glob, self.glob_rx = sample, t_rx
        elif name == "HomeSample":
            self.origin.home = sample
        elif name == "VfrHudSample":
            self.vfr, self.vfr_rx = sample, t_rx
        elif name == "WindSample":
            self.wind, self.wind_rx = sample, t_rx
        return False

    def lock_attitude_source(self) -> str | None:
        """Fix the attitude source for the rest of the flight (the one in use now); returns it
        (None before any attitude sample)."""
        if self.att_source is None and self.att is not None:
            self.att_source = getattr(self.att, "source", "ATTITUDE")
        return self.att_source

    # -- fusing -------------------------------------------------------------------------------
    def _position(
        self, t: float
    ) -> tuple[tuple[float, float, float], NDArray[np.float64], str] | str:
        """((x, y, z) NED at time t, ground velocity array, source) or the reason why not."""
        p = self.p
        loc = self.local
        if loc is not None and abs(t - loc.t_boot_s) <= p.position_stale_s:
            dt = t - loc.t_boot_s
            vel = np.asarray(loc.vel_ned, float)
            (x, y, z), (vx, vy, vz) = np.asarray(loc.pos_ned).tolist(), vel.tolist()
            return (x + dt * vx, y + dt * vy, z + dt * vz), vel, "local"
        g = self.glob
        if g is not None and abs(t - g.t_boot_s) <= p.position_stale_s:
            q = self.origin.ned_xyz(g.lat_deg, g.lon_deg, g.alt_amsl_m)
            if q is None:
                return (
                    "GLOBAL_POSITION_INT without an origin (no HOME_POSITION, no mavlink.origin_*)"
                )
            dt = t - g.t_boot_s
            vel = np.asarray(g.vel_ned, float)
            (x, y, z), (vx, vy, vz) = q, np.asarray(g.vel_ned).tolist()
            return (x + dt * vx, y + dt * vy, z + dt * vz), vel, "global"
        if loc is None and g is None:
            return "no position yet (LOCAL_POSITION_NED or GLOBAL_POSITION_INT)"
        last = max(x.t_boot_s for x in (loc, g) if x is not None)
        return f"position stale ({t - last:.2f} s behind the attitude)"

    def _attitude_lag(self, a: AttitudeSample) -> float:
        """How far (s) the other telemetry has gone on since the attitude sample, 0 if not at all:
        by receive time (one clock for every stream; a sample that stopped coming cannot hold
        the attitude hostage), or by the position's boot time when there are no receive times."""
        lag = 0.0
        if self.att_rx is not None:
            # not the wind: it is optional, and a single odd wind sample must not stall control
            for rx in (self.local_rx, self.glob_rx, self.vfr_rx):
                if rx is not None:
                    lag = max(lag, rx - self.att_rx)
        else:
            for x in (self.local, self.glob):
                if x is not None:
                    lag = max(lag, x.t_boot_s - a.t_boot_s)
        return lag

    def _fuse(self, at_position: bool = False) -> _Fused | tuple[None, str]:
        """The inputs of an estimate at the latest attitude sample: its time, position, ground
        velocity, attitude and airspeed (what the wind low-pass needs too), or (None, reason).
        ``at_position``: at the latest LOCAL_POSITION_NED instead when it is newer, the attitude
        carried there by its own body rates (:meth:`estimate`)."""
        a = self.att
        if a is None:
            return None, "no attitude yet"
        lag = self._attitude_lag(a)
        if lag > self.p.attitude_stale_s:
            return None, f"attitude stale ({lag:.2f} s behind the other telemetry)"
        t = a.t_boot_s
        R = np.asarray(a.R_B_N, float)
        loc = self.local
        if at_position and loc is not None and loc.t_boot_s > t:
            # R_dot = R hat(w_body): at constant body rates the exact rotation over dt is
            # R exp(hat(w dt)); the sample's rates are the best knowledge of the hold between
            dt = float(loc.t_boot_s) - t
            p, q, r = np.asarray(a.rates_frd, float).tolist()
            R = R @ so3_exp((p * dt, q * dt, r * dt))
            t = float(loc.t_boot_s)
        pos = self._position(t)
        if isinstance(pos, str):
            return None, pos
        (px, py, pz), vg, psrc = pos
        p = self.p
        airspeed: float | None = None
        if self.vfr is not None and (
            self.vfr_rx is None
            or self.att_rx is None
            or abs(self.att_rx - self.vfr_rx) <= p.airspeed_stale_s
        ):
            airspeed = float(self.vfr.airspeed_m_s)
            if p.airspeed_is_eas:
                airspeed *= eas_to_tas(float(self.vfr.alt_amsl_m))
        elif self.vfr is not None:
            lag = self.att_rx - self.vfr_rx  # type: ignore[operator]
            return None, f"airspeed stale ({lag:.2f} s behind the attitude)"
        return tuple.__new__(_Fused, (t, px, py, pz, vg, psrc, R, R.tolist(), airspeed))

    def _fused_now(self, at_position: bool = False) -> _Fused | tuple[None, str]:
        """:meth:`_fuse` of the samples stored now, computed once per new sample."""
        c = self._fused
        if c is not None and c[0] == self._gen and c[1] == at_position:
            return c[2]
        f = self._fuse(at_position)
        self._fused = (self._gen, at_position, f)
        return f

    def _advance_wind(self, att: AttitudeSample) -> None:
        """Advance the wind low-pass to the attitude sample just stored (once per sample)."""
        t = att.t_boot_s
        self.wind_lp.restart_if_back(t)
        f = self._fused_now()
        if not isinstance(f, _Fused) or f.airspeed is None:
            return
        R_rows = f.R_rows
        gx, gy, _ = f.vg.tolist()
        self.wind_lp.add(t, gx - f.airspeed * R_rows[0][0], gy - f.airspeed * R_rows[1][0])

    def estimate(self, at_position: bool = False) -> tuple[Estimate | None, str]:
        """The state at the latest attitude sample, or (None, reason). Pure: the wind low-pass
        it reads advanced when the attitude sample was stored (:meth:`update`).

        ``at_position``: the state at the latest LOCAL_POSITION_NED when it is newer than the
        attitude (a multi-rate loop's intersample instant): position and ground velocity of that
        sample, the attitude propagated to its time by the attitude sample's body rates, the
        rates themselves unchanged; otherwise the same as without."""
        f = self._fused_now(at_position)
        if not isinstance(f, _Fused):
            return f
        t, px, py, pz, vg, psrc, R, R_rows, airspeed = f
        # Scalar arithmetic throughout (a numpy call on a 3-vector costs more than the
        # arithmetic): the same operations, in the same order, as the array form.
        gx, gy, gz = vg.tolist()
        xb0, xb1, xb2 = R_rows[0][0], R_rows[1][0], R_rows[2][0]  # body x-axis (NED)
        p = self.p
        a = self.att
        assert a is not None  # a fused estimate has an attitude sample
        w = self.wind
        if w is not None and (
            self.wind_rx is None
            or self.att_rx is None
            or abs(self.att_rx - self.wind_rx) <= p.wind_stale_s
        ):
            wsrc = w.source
            ex, ey, ez = np.asarray(w.wind_ned, float).tolist()
        else:
            lp = self.wind_lp.value
            ex, ey, ez = (0.0, 0.0, 0.0) if lp is None else lp
            wsrc = "estimated"
        v_air = (gx - ex, gy - ey, gz - ez)
        n_air = math.sqrt(v_air[0] ** 2 + v_air[1] ** 2 + v_air[2] ** 2)
        if n_air < p.min_air_speed:
            W = wind_frame_rows(xb0, xb1, xb2)
        else:
            W = wind_frame_rows(*v_air)
        if p.airspeed_from_wind and wsrc != "estimated" and n_air >= p.min_air_speed:
            # the autopilot's own wind: v_air = v_ground - wind is what the law's kinematics
            # p_dot = v_w w1 + eta assume, whatever its EAS-to-TAS factor (ArduPlane SITL:
            # ground speed 22.7 m/s in 0.2 m/s of wind against EAS 21.3 m/s, ISA TAS 22.0)
            v_w, asrc = n_air, "ground_minus_wind"
        elif airspeed is not None and airspeed > 0.0:
            v_w, asrc = airspeed, "vfr_hud"
        else:
            v_w, asrc = max(n_air, 0.0), "air_velocity"
        if not v_w > 0.0:
            return None, "airspeed is zero"
        rates = np.asarray(a.rates_frd, float)
        # belt and braces (update() already filters): one sum is NaN/inf if any element is
        (r0, r1, r2), (w0, w1, w2) = R_rows, W
        check = (
            px + py + pz + sum(w0) + sum(w1) + sum(w2) + ex + ey + ez + gx + gy + gz
            + sum(r0) + sum(r1) + sum(r2) + sum(rates.tolist())
        )  # fmt: skip
        if not math.isfinite(check + t - self.t0 + v_w):
            return None, "non-finite estimate (rejected)"
        # the state as floats (the law and the prediction read them; numpy is slow to wake up
        # in a loop that sleeps between frames), its arrays built if read
        vs = vehicle_state_of_floats(t - self.t0, w0 + w1 + w2 + (px, py, pz, ex, ey, ez), v_w)
        # Estimate(...) without the frozen dataclass's __init__ (an object.__setattr__ a field)
        e = _new(Estimate)
        d = e.__dict__
        d["vehicle"], d["t_boot_s"], d["R_B_N"], d["rates_frd"] = vs, t, R, rates
        d["ground_velocity"], d["position_source"], d["airspeed_source"] = vg, psrc, asrc
        d["wind_source"] = wsrc
        return e, ""
