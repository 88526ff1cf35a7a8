"""JSBSim fixed-wing plant for the software-in-the-loop vehicle.

:class:`JSBSimPlant` wraps ``jsbsim.FGFDMExec``: normalized surface/throttle commands in, a frozen
:class:`PlantState` out (NED inertial, FRD body, SI units, radians; ``R_B_N`` maps body -> NED, as
in :mod:`mpf_mavlink.core.frames`). The default model is the Skywalker X8 shipped in
``sim/jsbsim_root`` (see ``aircraft/x8/x8.xml`` for every number and its source); any JSBSim
aircraft works when its root directory and name are given (e.g. ``c172x`` under
``jsbsim.get_default_root_dir()``).

Performance: all properties touched per step or per :meth:`JSBSimPlant.state` call are cached
property nodes; :meth:`step` does four ``set_double_value`` calls and one ``run()``. Geodetic ->
NED uses the exact WGS-84 ECEF-difference rotation (the same algebra as pymap3d.geodetic2ned,
coded with :mod:`math` so one conversion costs a few microseconds; agreement with pymap3d is
at the micrometre level, see the tests).
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

os.environ.setdefault("JSBSIM_DEBUG", "0")
import jsbsim  # noqa: E402

from mpf_mavlink.constants import FT_TO_M, WGS84_A_M, WGS84_F  # noqa: E402
from sim.plant.atmosphere import JSBSimAtmosphere  # noqa: E402

if TYPE_CHECKING:
    from sim.plant.sitl_turbulence import SitlTurbulence

KTS_PER_MS = 1.0 / 0.514444
DEFAULT_ROOT = Path(__file__).resolve().parents[1] / "jsbsim_root"
# Command channel -> (JSBSim property, sign). The FlightGear/JSBSim convention: aileron > 0 rolls
# right, elevator > 0 is trailing edge down (nose down), rudder > 0 yaws right, throttle 0..1.
DEFAULT_CONTROLS: dict[str, tuple[str, float]] = {
    "aileron": ("fcs/aileron-cmd-norm", 1.0),
    "elevator": ("fcs/elevator-cmd-norm", 1.0),
    "rudder": ("fcs/rudder-cmd-norm", 1.0),
    "throttle": ("fcs/throttle-cmd-norm", 1.0),
}

# WGS-84
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared
_ONE_MINUS_E2 = 1.0 - WGS84_E2

_EULER = ("phi", "theta", "psi")
# the properties JSBSimPlant.state reads, in the order it unpacks them
_STATE_PROPERTIES = (
    "position/lat-geod-deg", "position/long-gc-deg", "position/h-sl-ft",
    *(f"attitude/{a}-rad" for a in _EULER), "simulation/sim-time-sec",
    *(f"velocities/v-{a}-fps" for a in ("north", "east", "down")),
    *(f"velocities/{a}-rad_sec" for a in "pqr"), "velocities/vt-fps", "aero/alpha-rad",
    "aero/beta-rad", *(f"atmosphere/total-wind-{a}-fps" for a in ("north", "east", "down")),
    *(f"accelerations/a-pilot-{a}-ft_sec2" for a in "xyz"), "fcs/throttle-pos-norm",
)  # fmt: skip


def _geodetic_to_ecef(lat_rad: float, lon_rad: float, h: float) -> tuple[float, float, float]:
    s, c = math.sin(lat_rad), math.cos(lat_rad)
    n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * s * s)
    return (
        (n + h) * c * math.cos(lon_rad),
        (n + h) * c * math.sin(lon_rad),
        (n * (1.0 - WGS84_E2) + h) * s,
    )


class LocalNED:
    """Exact WGS-84 geodetic -> local NED about a fixed origin (ECEF difference, rotated)."""

    def __init__(self, lat0_deg: float, lon0_deg: float, alt0_m: float):
        self.lat0_deg, self.lon0_deg, self.alt0_m = lat0_deg, lon0_deg, alt0_m
        la, lo = math.radians(lat0_deg), math.radians(lon0_deg)
        self._o = _geodetic_to_ecef(la, lo, alt0_m)
        sl, cl, so, co = math.sin(la), math.cos(la), math.sin(lo), math.cos(lo)
        self._rn = (-sl * co, -sl * so, cl)
        self._re = (-so, co, 0.0)
        self._rd = (-cl * co, -cl * so, -sl)

    def ned(self, lat_deg: float, lon_deg: float, alt_m: float) -> tuple[float, float, float]:
        """(north, east, down) m of a geodetic point (once per lockstep frame: the ECEF of
        :func:`_geodetic_to_ecef` written out, the same operations)."""
        la, lo = math.radians(lat_deg), math.radians(lon_deg)
        s = math.sin(la)
        n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * s * s)
        nhc = (n + alt_m) * math.cos(la)
        o = self._o
        dx = nhc * math.cos(lo) - o[0]
        dy = nhc * math.sin(lo) - o[1]
        dz = (n * _ONE_MINUS_E2 + alt_m) * s - o[2]
        rn, re, rd = self._rn, self._re, self._rd
        return (
            rn[0] * dx + rn[1] * dy + rn[2] * dz,
            re[0] * dx + re[1] * dy,
            rd[0] * dx + rd[1] * dy + rd[2] * dz,
        )


@dataclass(frozen=True)
class PlantState:
    """Truth state of the simulated aircraft (SI, rad; NED inertial, FRD body)."""

    t: float  # s, simulation time
    position_ned: np.ndarray  # m, about the plant origin
    velocity_ned: np.ndarray  # m/s, ground (inertial) velocity
    R_B_N: np.ndarray  # 3x3, body FRD -> NED
    euler: tuple[float, float, float]  # (roll, pitch, yaw) rad, ZYX
    pqr: np.ndarray  # rad/s, body angular rate w.r.t. inertial
    airspeed: float  # m/s, true airspeed
    alpha: float  # rad
    beta: float  # rad
    wind_ned: np.ndarray  # m/s, total air-mass velocity (steady + turbulence + gusts)
    lat_deg: float
    lon_deg: float
    alt_m: float  # m AMSL (JSBSim position/h-sl-ft; sea level = WGS-84 ellipsoid)
    specific_force_body: np.ndarray  # m/s^2, accelerometer at the CG/eye point (FRD)
    throttle: float  # 0..1, throttle position

    @property
    def velocity_air_ned(self) -> np.ndarray:
        """Air-relative velocity in NED (m/s) = ground velocity - wind."""
        v: np.ndarray = self.velocity_ned - self.wind_ned
        return v

    @property
    def altitude_rel(self) -> float:
        """Height above the origin (m) = -position_ned[2]."""
        return -float(self.position_ned[2])


class _QuietStderr:
    """Catch what JSBSim prints while a model loads and initialises (the jsbsim module routes
    its C++ std::cout / std::cerr to Python's sys.stdout / sys.stderr).

    Models may carry <output> directives (the jsbsim package's c172x writes a CSV) and every
    run_ic after the first reports that it cannot re-open that file: those lines are dropped;
    anything else goes on to stderr (and stays in ``text`` for error messages)."""

    _DROP = ("unable to open the file", "Output to this file is disabled")

    def __enter__(self) -> _QuietStderr:
        import contextlib
        import io

        self._buf = io.StringIO()
        self._stack = contextlib.ExitStack()
        self._stack.enter_context(contextlib.redirect_stdout(self._buf))
        self._stack.enter_context(contextlib.redirect_stderr(self._buf))
        self.text = ""
        return self

    def __exit__(self, *exc: object) -> None:
        import sys

        self._stack.close()
        raw = self._buf.getvalue()
        keep = [
            ln for ln in raw.splitlines() if ln.strip() and not any(d in ln for d in self._DROP)
        ]
        self.text = "\n".join(keep)
        if keep and exc[0] is None:
            sys.stderr.write(self.text + "\n")


def rotation_body_to_ned(phi: float, theta: float, psi: float) -> np.ndarray:
    """R_B_N (3x3, body FRD -> NED) of ZYX Euler angles (rad)."""
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    return np.array(
        (
            ct * cp,
            sf * st * cp - cf * sp,
            cf * st * cp + sf * sp,
            ct * sp,
            sf * st * sp + cf * cp,
            cf * st * sp - sf * cp,
            -st,
            sf * ct,
            cf * ct,
        )
    ).reshape(3, 3)


# the snapshot's 3-vectors: field -> the tuple of floats that stands in for it until it is read
VECTOR_FLOATS = {
    "position_ned": "_p",
    "velocity_ned": "_v",
    "pqr": "_w",
    "wind_ned": "_wind",
    "specific_force_body": "_f_body",
}


class _Lazy:
    """A snapshot's field made from its floats when first read, then an ordinary attribute of
    the instance (a descriptor without ``__set__`` yields to the instance's ``__dict__``)."""

    __slots__ = ("name", "make")

    def __init__(self, make: Any) -> None:
        self.make = make
        self.name = ""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, obj: Any, objtype: Any = None) -> Any:
        if obj is None:
            return self
        d = obj.__dict__
        try:
            value = self.make(d)
        except KeyError:  # a snapshot without the floats of this field
            raise AttributeError(self.name) from None
        d[self.name] = value
        return value


def _vector(key: str) -> _Lazy:
    return _Lazy(lambda d: np.array(d[key]))


class _Snapshot(PlantState):
    """A :class:`PlantState` built without the frozen dataclass's per-field
    ``object.__setattr__`` (a third of a snapshot's cost, once per lockstep frame), whose
    rotation matrix and arrays are made when first read: the vehicle's frame reads the floats
    (:func:`vector_floats`), tests, estimators and the autopilot's hold the arrays. (Descriptors
    rather than ``__getattr__``: a class with ``__getattr__`` makes every attribute read of its
    instances a slow generic lookup, and the frame reads a snapshot's fields some twenty times.)"""

    R_B_N = _Lazy(lambda d: rotation_body_to_ned(*d["_euler"]))
    position_ned = _vector(VECTOR_FLOATS["position_ned"])
    velocity_ned = _vector(VECTOR_FLOATS["velocity_ned"])
    pqr = _vector(VECTOR_FLOATS["pqr"])
    wind_ned = _vector(VECTOR_FLOATS["wind_ned"])
    specific_force_body = _vector(VECTOR_FLOATS["specific_force_body"])


def vector_floats(st: Any, name: str) -> Any:
    """State ``st``'s 3-vector field ``name`` as three Python floats (a tuple or list): a plant
    snapshot's own floats without making its array, any other state's array converted."""
    v = st.__dict__.get(VECTOR_FLOATS[name])
    if v is not None:
        return v
    v = getattr(st, name)
    return v.tolist() if type(v) is np.ndarray else [float(x) for x in v]


def _load(root_dir: Path, model: str, dt: float) -> tuple[Any, str]:
    """A quiet FGFDMExec with ``model`` loaded from ``root_dir`` and its output directory (a
    private temporary one, never the aircraft's: often the installed package's)."""
    fdm = jsbsim.FGFDMExec(str(root_dir))
    fdm.set_debug_level(0)
    outdir = tempfile.mkdtemp(prefix="mpf-jsbsim-")
    fdm.set_output_path(outdir)
    quiet = _QuietStderr()
    with quiet:
        ok = fdm.load_model(model)
        if ok:
            fdm.disable_output()  # a plant writes no files
    if not ok:
        shutil.rmtree(outdir, ignore_errors=True)
        raise RuntimeError(f"JSBSim could not load model {model!r} from {root_dir}: {quiet.text}")
    fdm.set_dt(dt)
    return fdm, outdir


def _initial_conditions(
    origin: LocalNED,
    position_ned: tuple[float, float, float] | np.ndarray,
    ground_alt_m: float,
    heading: float,
    airspeed: float,
) -> dict[str, float]:
    """JSBSim's initial-condition properties: at ``position_ned`` (m about ``origin``), wings
    level on ``heading`` (rad) at ``airspeed`` (m/s), the terrain at ``ground_alt_m`` (AMSL)."""
    from mpf_mavlink.core.frames import ned_to_geodetic  # pymap3d, once at start-up only

    lat, lon, alt = ned_to_geodetic(position_ned, origin.lat0_deg, origin.lon0_deg, origin.alt0_m)
    return {
        "ic/lat-geod-deg": lat,
        "ic/long-gc-deg": lon,
        "ic/terrain-elevation-ft": ground_alt_m / FT_TO_M,
        "ic/h-sl-ft": alt / FT_TO_M,
        "ic/psi-true-deg": math.degrees(heading),
        "ic/vt-fps": airspeed / FT_TO_M,
        "ic/alpha-deg": 0.0,
        "ic/beta-deg": 0.0,
        "ic/phi-deg": 0.0,
        "ic/theta-deg": 0.0,
    }


class JSBSimPlant:
    """A JSBSim aircraft driven by normalized commands; see module docstring."""

    has_random_wind = True

    def __init__(
        self,
        root_dir: str | os.PathLike[str] | None = None,
        model: str = "x8",
        dt: float = 1.0 / 120.0,
        lat0_deg: float = 47.397742,
        lon0_deg: float = 8.545594,
        alt0_m: float = 488.0,
        position_ned: tuple[float, float, float] | np.ndarray = (0.0, 0.0, -100.0),
        heading: float = 0.0,
        airspeed: float = 16.0,
        ground_alt_m: float | None = None,
        extra: dict[str, float] | None = None,
        throttle: float = 0.3,
        controls: dict[str, tuple[str, float]] | None = None,
    ):
        self.root_dir = Path(root_dir) if root_dir is not None else DEFAULT_ROOT
        self.model = model
        self.dt = float(dt)
        self.origin = LocalNED(lat0_deg, lon0_deg, alt0_m)
        self.ground_alt_m = alt0_m if ground_alt_m is None else float(ground_alt_m)

        # output files a model asks for go to a private directory removed after start-up
        fdm, self._outdir = _load(self.root_dir, model, self.dt)
        self.fdm = fdm
        pm = fdm.get_property_manager()
        self._pm = pm
        self._nodes: dict[str, Any] = {}
        ic = _initial_conditions(self.origin, position_ned, self.ground_alt_m, heading, airspeed)
        for k, v in {**ic, **(extra or {})}.items():
            self._set(k, v)
        with _QuietStderr():  # run_ic opens the model's output files
            ok = fdm.run_ic()
        if not ok:
            raise RuntimeError("JSBSim run_ic() failed")
        thr_prop, thr_sign = dict(DEFAULT_CONTROLS, **(controls or {}))["throttle"]
        _spin_up(self, thr_prop, thr_sign, throttle)
        self._bind_controls(model, controls or {})
        self._bind_state()
        self.atmosphere = JSBSimAtmosphere(self._node, fdm.run, self.dt)

    def _bind_state(self) -> None:
        """The state nodes and their bound getters (what state() and the rate loops read)."""
        n = self._node
        self._n_t = n("simulation/sim-time-sec")
        self._n_phi, self._n_theta, self._n_psi = (n(f"attitude/{a}-rad") for a in _EULER)
        self._n_p, self._n_q, self._n_r = (n(f"velocities/{a}-rad_sec") for a in "pqr")
        self._n_vt = n("velocities/vt-fps")
        # what state() reads, in its order: the nodes' bound getters
        self._state_getters = tuple(n(name).get_double_value for name in _STATE_PROPERTIES)
        # the rate loops' inputs, read after every step: the nodes' bound getters
        self._get_pqr_vt = tuple(
            x.get_double_value for x in (self._n_p, self._n_q, self._n_r, self._n_vt)
        )

    def _bind_controls(self, model: str, controls: dict[str, tuple[str, float]]) -> None:
        """Command nodes and signs: the autopilot's convention (aileron > 0 rolls right,
        elevator > 0 nose down, rudder > 0 yaws right, throttle 0..1) times the aircraft's."""
        n, pm = self._node, self._pm
        ctl = dict(DEFAULT_CONTROLS)
        ctl.update(controls)
        unknown = set(ctl) - set(DEFAULT_CONTROLS)
        if unknown:
            raise KeyError(
                f"unknown control channel(s) {sorted(unknown)}: use {sorted(DEFAULT_CONTROLS)}"
            )
        for name, (prop, _) in ctl.items():
            if not pm.hasNode(prop):
                raise KeyError(f"JSBSim model {model!r} has no property {prop!r} ({name} command)")
        self.controls = ctl
        self._n_ail, self._s_ail = n(ctl["aileron"][0]), float(ctl["aileron"][1])
        self._n_ele, self._s_ele = n(ctl["elevator"][0]), float(ctl["elevator"][1])
        self._n_rud, self._s_rud = n(ctl["rudder"][0]), float(ctl["rudder"][1])
        self._n_thr, self._s_thr = n(ctl["throttle"][0]), float(ctl["throttle"][1])
        self._set_cmd = tuple(
            x.set_double_value for x in (self._n_ail, self._n_ele, self._n_rud, self._n_thr)
        )
        self._unit_signs = (self._s_ail, self._s_ele, self._s_rud, self._s_thr) == (1.0,) * 4

    # ------------------------------------------------------------------ helpers
    def _node(self, name: str) -> Any:
        node = self._nodes.get(name)
        if node is None:
            node = self._pm.get_node(name, True)
            if node is None:
                raise KeyError(f"JSBSim property {name!r} not found")
            self._nodes[name] = node
        return node

    def _set(self, name: str, value: float) -> None:
        self._node(name).set_double_value(float(value))

    def get(self, name: str) -> float:
        """Any JSBSim property (cached node)."""
        return float(self._node(name).get_double_value())

    def set(self, name: str, value: float) -> None:
        """Set any JSBSim property (cached node)."""
        self._set(name, value)

    # ------------------------------------------------------------------ environment
    def set_wind(self, wind_ned_m_s: Any) -> None:
        """:meth:`JSBSimAtmosphere.set_wind`."""
        self.atmosphere.set_wind(wind_ned_m_s)

    def set_turbulence(self, kind: str = "none", seed: int = 0) -> None:
        """:meth:`JSBSimAtmosphere.set_turbulence`."""
        self.atmosphere.set_turbulence(kind, seed)

    def set_random_wind(self, turbulence_m_s: float, seed: int = 0) -> None:
        """:meth:`JSBSimAtmosphere.set_random_wind`."""
        self.atmosphere.set_random_wind(turbulence_m_s, seed)

    def trigger_gust(self, *args: Any, **kw: Any) -> None:
        """:meth:`JSBSimAtmosphere.trigger_gust`."""
        self.atmosphere.trigger_gust(*args, **kw)

    @property
    def random_wind(self) -> SitlTurbulence | None:
        return self.atmosphere.random_wind

    # ------------------------------------------------------------------ stepping
    def step(self, aileron: float, elevator: float, rudder: float, throttle: float) -> None:
        """Apply normalized commands (surfaces -1..1, throttle 0..1) and advance one ``dt``."""
        self._n_ail.set_double_value(aileron * self._s_ail)
        self._n_ele.set_double_value(elevator * self._s_ele)
        self._n_rud.set_double_value(rudder * self._s_rud)
        self._n_thr.set_double_value(throttle * self._s_thr)
        self.atmosphere.run()

    def step_rates(
        self, aileron: float, elevator: float, rudder: float, throttle: float
    ) -> tuple[float, float, float, float]:
        """:meth:`step`, then :meth:`rates_airspeed`: what the vehicle does every physics step,
        in one call with the nodes' bound accessors (a lockstep frame is short enough that the
        calls around the two JSBSim steps cost as much as the steps)."""
        set_a, set_e, set_r, set_t = self._set_cmd
        if self._unit_signs:  # (x * 1.0 is x)
            set_a(aileron)
            set_e(elevator)
            set_r(rudder)
            set_t(throttle)
        else:
            set_a(aileron * self._s_ail)
            set_e(elevator * self._s_ele)
            set_r(rudder * self._s_rud)
            set_t(throttle * self._s_thr)
        self.atmosphere.run()
        get_p, get_q, get_r, get_vt = self._get_pqr_vt
        return get_p(), get_q(), get_r(), get_vt() * FT_TO_M

    def run(self, n: int, aileron: float, elevator: float, rudder: float, throttle: float) -> None:
        """Hold the commands for ``n`` steps."""
        self._n_ail.set_double_value(aileron * self._s_ail)
        self._n_ele.set_double_value(elevator * self._s_ele)
        self._n_rud.set_double_value(rudder * self._s_rud)
        self._n_thr.set_double_value(throttle * self._s_thr)
        r = self.atmosphere.run
        for _ in range(n):
            r()

    def rates_airspeed(self) -> tuple[float, float, float, float]:
        """(p, q, r) rad/s (FRD body rates) and the true airspeed (m/s): all a rate loop needs,
        for a few property reads instead of a whole :meth:`state`."""
        return (
            self._n_p.get_double_value(),
            self._n_q.get_double_value(),
            self._n_r.get_double_value(),
            self._n_vt.get_double_value() * FT_TO_M,
        )

    def attitude_rates(self) -> tuple[float, float, float, float, float, float]:
        """(roll, pitch, yaw) rad as in :meth:`state` and (p, q, r) rad/s: what ATTITUDE carries."""
        psi = self._n_psi.get_double_value()
        return (
            self._n_phi.get_double_value(),
            self._n_theta.get_double_value(),
            psi if psi <= math.pi else psi - 2.0 * math.pi,
            self._n_p.get_double_value(),
            self._n_q.get_double_value(),
            self._n_r.get_double_value(),
        )

    @property
    def t(self) -> float:
        return float(self._n_t.get_double_value())

    def state(self) -> PlantState:
        """Snapshot of the truth state (SI units, NED/FRD, rad). (Once per lockstep frame: the
        nodes' bound getters, a third cheaper than looking the method up on each node.)"""
        (g_lat, g_lon, g_alt, g_phi, g_th, g_psi, g_t, g_vn, g_ve, g_vd, g_p, g_q, g_r, g_vt,
         g_alpha, g_beta, g_wn, g_we, g_wd, g_ax, g_ay, g_az,
         g_thr) = self._state_getters  # fmt: skip
        lat, lon, alt, phi, th, psi = g_lat(), g_lon(), g_alt() * FT_TO_M, g_phi(), g_th(), g_psi()
        st = object.__new__(_Snapshot)
        st.__dict__.update(
            t=g_t(),
            _p=self.origin.ned(lat, lon, alt),
            _v=(g_vn() * FT_TO_M, g_ve() * FT_TO_M, g_vd() * FT_TO_M),
            _euler=(phi, th, psi),
            euler=(phi, th, psi if psi <= math.pi else psi - 2.0 * math.pi),
            _w=(g_p(), g_q(), g_r()),
            airspeed=g_vt() * FT_TO_M,
            alpha=g_alpha(),
            beta=g_beta(),
            _wind=(g_wn() * FT_TO_M, g_we() * FT_TO_M, g_wd() * FT_TO_M),
            lat_deg=lat,
            lon_deg=lon,
            alt_m=alt,
            _f_body=(g_ax() * FT_TO_M, g_ay() * FT_TO_M, g_az() * FT_TO_M),
            throttle=g_thr(),
        )
        return st


def _spin_up(plant: JSBSimPlant, thr_prop: str, thr_sign: float, throttle: float) -> None:
    """Start the engines and spin the propeller up. FGPropeller divides the shaft power by
    max(omega, 1 rad/s), so throttling up a propeller at 0 RPM gives a huge one-step RPM and
    torque spike that wrecks a 3 kg aircraft (and JSBSim's own steady-state spin-up does not
    run here). So: one step at 1 % throttle (-> ~1500 RPM for the X8), 0.5 s at the initial
    throttle (propeller at its equilibrium RPM), then run_ic() again, which restores the
    initial position/attitude/velocity but keeps the propeller RPM; the clock is reset to 0."""
    fdm, pm, set_ = plant.fdm, plant._pm, plant.set
    if pm.hasNode("fcs/mixture-cmd-norm"):
        set_("fcs/mixture-cmd-norm", 1.0)  # piston models (c172x) need fuel mixture
    if pm.hasNode("fcs/advance-cmd-norm"):
        # propeller lever full forward (maximum RPM), as flown in the pattern: a constant-speed
        # propeller (pa28) left at 0 governs to its minimum RPM and the engine gives ~2/3 of
        # its power (118 of 174 hp at full throttle, 45 m/s); fixed-pitch propellers ignore it
        set_("fcs/advance-cmd-norm", 1.0)
    set_("propulsion/set-running", -1)
    set_(thr_prop, 0.01 * thr_sign)
    fdm.run()
    set_(thr_prop, throttle * thr_sign)
    for _ in range(int(round(0.5 / plant.dt))):
        fdm.run()
    with _QuietStderr():  # every run_ic re-opens the model's output files
        ok = fdm.run_ic()
    shutil.rmtree(plant._outdir, ignore_errors=True)
    if not ok:
        raise RuntimeError("JSBSim run_ic() failed")
    fdm.set_sim_time(0.0)


def benchmark(seconds: float = 600.0, state_hz: float = 50.0) -> float:
    """FDM steps per wall-clock second (returned) over ``seconds`` of simulated flight for the X8,
    with state() at ``state_hz``."""
    import time

    plant = JSBSimPlant()
    n = int(round(seconds / plant.dt))
    period, next_state = 1.0 / state_hz, 0.0
    step, dt = plant.step, plant.dt
    t0 = time.perf_counter()
    for i in range(n):
        step(0.0, 0.0, 0.0, 0.3)
        if i * dt >= next_state:
            next_state += period
            plant.state()
    return n / (time.perf_counter() - t0)


if __name__ == "__main__":
    print(f"{benchmark():.0f} FDM steps/s (X8, dt 1/120 s, state() at 50 Hz)")
