"""Run the pre-flight checks for a configuration (Assumption 1, gain condition, feasibility)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from mpf_mavlink.config.fields import Vec3
from mpf_mavlink.config.scenario import build_extensions, build_gains, build_path, build_target
from mpf_mavlink.config.schema import Config, bank_limit_rad
from mpf_mavlink.constants import GRAVITY_M_S2
from mpf_mavlink.core.adapter import reserve_airspeed
from mpf_mavlink.core.frames import euler_to_matrix
from mpf_mavlink.core.guidance.checks import (
    CheckResult,
    assumption1,
    autopilot_profile_limits,
    climb_feasibility,
    demanded_directions,
    feasibility,
    gain_condition,
    vertical_gusts,
)
from mpf_mavlink.core.guidance.law import VehicleState, mpf_law

if TYPE_CHECKING:
    from mpf_mavlink.config.autopilot_profile import ResolvedProfile
    from mpf_mavlink.core.paths import TabulatedPath


@dataclass(frozen=True)
class SimulatedPlant:
    """What the checks judge of a simulated plant (the SIL vehicle) instead of the kinematic
    one: its steady wind (NED, m/s), the largest of its gust events (m/s), its Dryden
    turbulence level, the height above sea level of its home (m), its start position (NED, m;
    None: ``kinematic.initial_position_ned_m``) and the autopilot profile it flies (None: the
    plain emulation, no ``autopilot_profile`` check)."""

    wind_ned_m_s: Vec3
    gust_m_s: float
    turbulence: Literal["none", "light", "moderate", "severe"]
    home_alt_m: float
    initial_position_ned_m: Vec3 | None
    profile: ResolvedProfile | None


def simulated_plant(cfg: Config) -> SimulatedPlant | None:
    """The SIL vehicle of ``cfg`` as the checks see it (None when ``sil.link`` is none: the
    kinematic plant). The one place the checks read the ``sil`` section."""
    sil = cfg.sil
    if sil.link == "none":
        return None
    return SimulatedPlant(
        sil.wind_ned_m_s,
        max((g.magnitude_m_s for g in sil.gusts), default=0.0),
        sil.turbulence,
        sil.home_alt_m,
        sil.initial_position_ned_m,
        sil.profile(cfg.source),
    )


#: ``plant`` argument meaning "the config's own" (:func:`simulated_plant` of it)
FROM_CONFIG: Literal["config"] = "config"
PlantArg = SimulatedPlant | None | Literal["config"]


def _plant(cfg: Config, plant: PlantArg) -> SimulatedPlant | None:
    return simulated_plant(cfg) if isinstance(plant, str) else plant


def initial_errors(cfg: Config, path: Any = None, target: Any = None) -> tuple[float, float, float]:
    """(|pt(0)| m, Psi(0), s(0) m) for the kinematic initial state of the config (``path`` and
    ``target``: the config's, when the caller has already built them)."""
    path = build_path(cfg.path) if path is None else path
    target = build_target(cfg.target) if target is None else target
    k = cfg.kinematic
    p0 = np.asarray(k.initial_position_ned_m, float)
    st = target.state(0.0)
    s0 = cfg.guidance.initial_s_m
    if s0 is None:
        s0 = path.closest(st.R_T_I.T @ (p0 - st.position))
    veh = VehicleState(
        0.0, p0, euler_to_matrix(*k.initial_attitude_rpy_rad), cfg.vehicle.airspeed_m_s
    )
    _, d = mpf_law(s0, veh, st, path, build_gains(cfg), build_extensions(cfg))
    assert d is not None
    return d.pt_norm, d.psi, s0


def auto_c1(cfg: Config, pt0: float, c2: float) -> float:
    """Smallest c1 >= |pt(0)| (on a 5 % geometric grid) for which the gain condition holds.

    The theorem holds for any c1 that satisfies it; a larger c1 weakens K but relaxes the
    bound, so we report the first certificate found (or |pt(0)| when none exists).
    """
    g = build_gains(cfg)
    c1 = max(pt0, 1e-3)
    for _ in range(200):
        r = gain_condition(g, cfg.vehicle.v_min, cfg.vehicle.v_max, c1, c2)
        if r.ok:
            return c1
        c1 *= 1.05
    return max(pt0, 1e-3)


# Extra air-mass speed (m/s) the checks allow for Dryden turbulence: about 2 sigma of the
# MIL-F-8785C low-altitude horizontal intensity at 100 m for W20 = 15 / 30 / 45 kt.
TURBULENCE_ALLOWANCE_M_S = {"none": 0.0, "light": 2.0, "moderate": 4.0, "severe": 6.0}


def scenario_wind(
    cfg: Config, plant: PlantArg = FROM_CONFIG
) -> tuple[tuple[float, float, float], float]:
    """(steady wind NED m/s, gust allowance m/s) of the plant the scenario flies: the simulated
    plant's atmosphere when there is one, else the kinematic plant's."""
    sim = _plant(cfg, plant)
    if sim is not None:
        return sim.wind_ned_m_s, sim.gust_m_s + TURBULENCE_ALLOWANCE_M_S[sim.turbulence]
    wind = cfg.kinematic.wind
    gust = max((float(np.linalg.norm(g.velocity_ned_m_s)) for g in wind.gusts), default=0.0)
    return wind.steady_ned_m_s, gust


#: The stated margin on a measured wind without the autopilot's variance (WIND, or WIND_COV with
#: var_horiz unknown): the larger of 1 m/s and 20 % of its speed. An EKF's steady-wind estimate
#: is good to about 1 m/s in light wind and lags a freshening one (ArduPlane SITL in an 8 m/s
#: wind reported 7.7 m/s); the margin is what the warning ``wind_margin`` checks with.
WIND_MARGIN_M_S = 1.0
WIND_MARGIN_FRACTION = 0.2


@dataclass(frozen=True)
class MeasuredInputs:
    """What the autopilot reports right before engaging, for :func:`run_checks`.

    wind_ned_m_s: the estimator's wind (NED, m/s, the air mass's velocity); wind_source: "WIND"
    (ArduPilot), "WIND_COV" (PX4) or "estimated" (our own low-pass of ground velocity minus
    airspeed); wind_var_m2_s2: WIND_COV.var_horiz when the autopilot sends one; airspeed_m_s:
    VFR_HUD's airspeed as true airspeed (None: none yet); target: the live target's estimated
    motion as a constant-turn target from mission time 0 (None: a scripted target)."""

    wind_ned_m_s: tuple[float, float, float]
    wind_source: str
    wind_var_m2_s2: float | None = None
    airspeed_m_s: float | None = None
    target: Any = None  # TargetConfig

    def wind_margin_m_s(self) -> tuple[float, str]:
        """(margin m/s, how it was chosen): 2 sigma of the autopilot's variance when given, else
        :data:`WIND_MARGIN_M_S` or :data:`WIND_MARGIN_FRACTION` of the speed, the larger."""
        if self.wind_var_m2_s2 is not None and self.wind_var_m2_s2 > 0.0:
            return 2.0 * math.sqrt(self.wind_var_m2_s2), "2 sigma of WIND_COV.var_horiz"
        speed = math.hypot(self.wind_ned_m_s[0], self.wind_ned_m_s[1])
        return max(WIND_MARGIN_M_S, WIND_MARGIN_FRACTION * speed), (
            f"max({WIND_MARGIN_M_S:g} m/s, {100 * WIND_MARGIN_FRACTION:g} %)"
        )


def wind_words(wind_ned: Any, source: str) -> str:
    """The wind as the checks name it: ``7.7 m/s from 270 deg (WIND)`` (horizontal speed, the
    direction it blows FROM, degrees clockwise from north, and where the figure came from)."""
    n, e = float(wind_ned[0]), float(wind_ned[1])
    speed = math.hypot(n, e)
    if speed < 0.05:
        return f"{speed:.1f} m/s ({source})"
    frm = math.degrees(math.atan2(-e, -n)) % 360.0
    return f"{speed:.1f} m/s from {frm:.0f} deg ({source})"


def _with_wind(r: CheckResult, words: str, bank_margin_rad: float) -> CheckResult:
    """The feasibility result led by what a reader needs first: the bank needed, the wind it
    was judged with and the limit it is held to (the limit less the checks' margin)."""
    f = r.figures
    peak, lim = f.get("peak_bank_rad"), f.get("bank_limit_rad")
    if not isinstance(peak, float) or not isinstance(lim, float):
        return r  # pragma: no cover - feasibility always gives both
    allowed = max(lim - bank_margin_rad, 0.0)
    lead = (
        f"peak bank {math.degrees(peak):.1f} deg needed with the {words}, limit "
        f"{math.degrees(allowed):.1f} deg; "
    )
    return dataclasses.replace(r, summary=lead + r.summary)


def gust_feasibility(
    feasible_at: Callable[[float], CheckResult], v_w: float, gust: float
) -> CheckResult:
    """Feasibility at the airspeed a gust gives the aircraft, v_w + ``gust`` (m/s; the allowance
    of :func:`scenario_wind`): a warning, not a failure. A gust that holds the airspeed up with
    the throttle at idle (Dryden's longitudinal scale at 100 m is ~260 m, ~16 s at 16 m/s) makes
    the tightest turn of the path need the bank it needs at that speed; beyond the limit less
    the margin, expect the turn command to saturate there (the demo in moderate turbulence: 44.6
    deg at 20 m/s, bursts of 5-8 m and an airspeed verdict failure). Only a warning, because the
    2-sigma allowance is a rule of thumb: the strong-wind comparison (6.5 m/s, light turbulence)
    warns too (43.8 deg at 18 m/s) and tracks to 0.2 m."""
    v = v_w + gust
    r = feasible_at(v)
    what = f"at the gust airspeed {v:.1f} m/s ({v_w:g} + {gust:g} gust allowance): {r.summary}"
    if r.ok:
        return CheckResult("gust_feasibility", "pass", what, r.figures)
    return CheckResult(
        "gust_feasibility", "warn",
        what + "; expect the turn to saturate where gusts hold the airspeed up", r.figures,
    )  # fmt: skip


def start_altitude(
    cfg: Config, path: Any = None, target: Any = None, plant: PlantArg = FROM_CONFIG
) -> CheckResult:
    """The start position against the path's altitude at t = 0: more than
    ``checks.max_start_below_m`` below its lowest point is a failure (e.g. an aircraft on the
    ground under a path 100 m up: take off first)."""
    path = build_path(cfg.path) if path is None else path
    target = build_target(cfg.target) if target is None else target
    p0 = np.asarray(cfg.kinematic.initial_position_ned_m, float)
    sim = _plant(cfg, plant)
    if sim is not None and sim.initial_position_ned_m is not None:
        p0 = np.asarray(sim.initial_position_ned_m, float)
    st = target.state(0.0)
    pts = st.position + (st.R_T_I @ np.asarray(path.positions(), float).T).T
    lowest_down = float(np.max(pts[:, 2]))  # NED: the lowest point has the largest "down"
    below = float(p0[2]) - lowest_down
    lim = cfg.checks.max_start_below_m
    fig: dict[str, float | bool | None] = {"start_below_path_m": below, "limit_m": lim}
    if below > lim:
        return CheckResult(
            "start_altitude", "fail",
            f"the vehicle starts {below:.0f} m below the path's lowest point (start altitude "
            f"{-p0[2] + 0.0:.0f} m, path from {-lowest_down + 0.0:.0f} m; limit "
            f"checks.max_start_below_m = {lim:g}): take off and climb to the path first, or "
            "give a start state in the air (kinematic/sil.initial_position_ned_m)", fig,
        )  # fmt: skip
    return CheckResult(
        "start_altitude",
        "pass",
        f"start {max(below, 0.0):.1f} m below the path's lowest point (limit {lim:g} m)",
        fig,
    )


def climb_check(
    cfg: Config,
    path: Any,
    target: Any,
    horizon: float,
    s0: float,
    steady: Any,
    demanded: tuple[Any, Any, Any] | None = None,
    plant: PlantArg = FROM_CONFIG,
) -> CheckResult:
    """:func:`climb_feasibility` of the config: the vehicle's climb/sink capability (given where
    the aircraft starts, scaled by the air density at the highest point the path reaches over
    the horizon: :func:`density_ratio`), the verdict's airspeed window as the energy reserve,
    and in the SIL the vertical gusts of its turbulence (2 sigma_w over L_w / V at the altitude
    above sea level the path reaches, as JSBSim keys them: home_alt_m + height). Heights above
    sea level start from sil.home_alt_m (SIL), mavlink.origin_alt_m or 0. ``demanded``: what
    :func:`demanded_directions` gives for them with positions, when the caller has it."""
    v, m = cfg.vehicle, cfg.metrics
    if demanded is None:
        demanded = demanded_directions(
            path, target, v.airspeed_m_s, horizon, s0, steady, with_positions=True
        )
    ts, W1, P = demanded
    gusts = None
    sil = _plant(cfg, plant)
    home_alt = sil.home_alt_m if sil is not None else cfg.mavlink.origin_alt_m
    home = float(home_alt) if home_alt is not None else 0.0
    if sil is not None and sil.turbulence != "none":
        gusts = vertical_gusts(sil.turbulence, home - P[:, 2], v.airspeed_m_s)
    # the capability is the aircraft's where it starts; the top of the path over the horizon is
    # where the thinner air leaves the least of it (a descent keeps the start's, conservatively)
    p0 = cfg.kinematic.initial_position_ned_m
    if sil is not None and sil.initial_position_ned_m is not None:
        p0 = sil.initial_position_ned_m
    h0, top = home - float(p0[2]), home - float(np.min(P[:, 2]))
    k = min(1.0, density_ratio(top, h0))
    climb, sink = v.max_climb_rate_m_s, v.max_sink_rate_m_s
    turb = None
    if sil is not None and sil.turbulence != "none":
        r_up, r_dn = energy_reserves(cfg, ts, P)
        turb = (sil.turbulence, home - P[:, 2], r_up, r_dn)
    r = climb_feasibility(
        ts, W1, v.airspeed_m_s, v.v_min * (1.0 - m.airspeed_tolerance),
        v.v_max * (1.0 + m.airspeed_tolerance), None if climb is None else round(climb * k, 2),
        None if sink is None else round(sink * k, 2), gusts=gusts, turbulence=turb,
    )  # fmt: skip
    figs = {**r.figures, "density_ratio": k, "top_asl_m": top}
    why = ""
    if k < 1.0 and climb is not None:
        why = (
            f"; capability scaled by the air density at the path's top, {top:.0f} m above sea "
            f"level: {k:.3f} of the start's ({climb:g} / {sink:g} m/s there)"
        )
    return dataclasses.replace(r, summary=r.summary + why, figures=figs)


def energy_reserves(cfg: Config, ts: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(climb, sink) energy reserves (m of height) per sample, as the adapter flies them: from
    the airspeed set-point (raised by its energy reserve for the path's climb, low-passed as
    the adapter does: core/adapter.reserve_airspeed) down to vehicle.airspeed_min_m_s, where
    its airspeed priority gives the path up, and up to vehicle.airspeed_max_m_s."""
    v = cfg.vehicle
    a = cfg.adapter
    v0, lo, hi = v.airspeed_m_s, v.v_min, v.v_max
    vs = np.full(len(ts), v0)
    if a.reserve_gust_m_s > 0.0 and v.max_climb_rate_m_s is not None:
        dts = np.diff(ts, prepend=ts[0])
        climb = np.gradient(-P[:, 2], ts) if len(ts) > 1 else np.zeros(len(ts))
        cf = float(climb[0])
        for i in range(len(ts)):
            cf += min(1.0, dts[i] / a.reserve_tau_s) * (float(climb[i]) - cf)
            vs[i] = reserve_airspeed(
                v0, hi, cf, v.max_climb_rate_m_s, a.reserve_gust_m_s, a.reserve_gust_s
            )
    g = GRAVITY_M_S2
    return np.maximum(vs * vs - lo * lo, 0.0) / (2 * g), np.maximum(hi * hi - vs * vs, 0.0) / (
        2 * g
    )


def density_ratio(h_m: float, h_ref_m: float) -> float:
    """ISA troposphere density at h_m over that at h_ref_m (heights above sea level, m,
    clamped to [-500, 11000]).

    Why the climb and sink capability scale with it: at a fixed true airspeed a propeller's
    thrust at a given rpm and the aircraft's drag are both proportional to the air density, so
    the steady climb at full thrust and the sink at idle, (T - D) V / W, are too (to first
    order; induced drag, which grows as 1 / rho, takes a little more of the climb)."""

    def rho(h: float) -> float:
        h = min(max(h, -500.0), 11000.0) if math.isfinite(h) else 0.0
        return math.pow(1.0 - 2.25577e-5 * h, 4.255876)  # a float (the base is > 0)

    return rho(h_m) / rho(h_ref_m)


def airspeed_hold(cfg: Config) -> CheckResult:
    """An airspeed the aircraft cannot hold: the thrust it needs in level flight
    (adapter.trim_thrust) at the ceiling (adapter.thrust_max), or no climb left
    (vehicle.max_climb_rate_m_s 0)."""
    a = cfg.adapter
    v = cfg.vehicle
    fig: dict[str, float | bool | None] = {"trim_thrust": a.trim_thrust, "thrust_max": a.thrust_max}
    if a.trim_thrust >= a.thrust_max or (
        v.max_climb_rate_m_s is not None and v.max_climb_rate_m_s <= 0.0
    ):
        return CheckResult(
            "airspeed_hold", "fail",
            f"vehicle.airspeed_m_s {v.airspeed_m_s:g} m/s needs the thrust at its ceiling in level "
            f"flight (adapter.trim_thrust {a.trim_thrust:g} of thrust_max {a.thrust_max:g}): "
            "nothing is left to climb, turn or hold it; fly a slower airspeed", fig,
        )  # fmt: skip
    return CheckResult(
        "airspeed_hold",
        "pass",
        f"level flight at {v.airspeed_m_s:g} m/s needs thrust {a.trim_thrust:g} of "
        f"{a.thrust_max:g}",
        fig,
    )


def run_checks(
    cfg: Config,
    scripted_target: bool = True,
    measured: MeasuredInputs | None = None,
    plant: PlantArg = FROM_CONFIG,
    path: TabulatedPath | None = None,
) -> list[CheckResult]:
    """All checks for a config (``path``: its path, already built). With a live target only
    the gain condition can be checked, unless ``measured`` gives its estimated motion.
    ``measured`` (the live bridge, right before engaging): the wind the autopilot reports
    replaces the scenario's steady wind (the turbulence allowance stays the config's), the live
    target's estimated motion replaces ``target`` and the measured airspeed adds a feasibility
    at that airspeed (a warning); ``wind_margin`` warns when the wind's margin would not be
    flyable. The start state is the caller's (``kinematic.initial_*``). ``plant``: the
    simulated plant the scenario flies (None: the kinematic one; by default the config's)."""
    results: list[CheckResult] = []
    sim = _plant(cfg, plant)
    ch = cfg.checks
    horizon = ch.horizon_s if ch.horizon_s is not None else cfg.sim.duration_s
    path = build_path(cfg.path) if path is None else path
    steady, gust = scenario_wind(cfg, sim)
    if measured is not None:
        steady = measured.wind_ned_m_s
        words = "measured wind " + wind_words(steady, measured.wind_source)
        if measured.target is not None:
            cfg = dataclasses.replace(cfg, target=measured.target)
            scripted_target = True
    else:
        words = "wind " + wind_words(steady, scenario_wind_source(sim))
    if scripted_target and cfg.target.type != "mavlink":
        target = build_target(cfg.target)
        results.append(
            assumption1(
                path, target, cfg.vehicle.v_min, horizon, steady, gust, ch.assumption1_margin_m_s
            )
        )
        results.append(start_altitude(cfg, path, target, sim))
        pt0, psi0, s0 = initial_errors(cfg, path, target)
        c2 = ch.c2
        c1 = ch.c1_m if ch.c1_m is not None else auto_c1(cfg, pt0, c2)
        results.append(
            gain_condition(
                build_gains(cfg), cfg.vehicle.v_min, cfg.vehicle.v_max, c1, c2, pt0, psi0
            )
        )

        # the directions flying the path demands at the cruise airspeed: both the turn and the
        # climb checks read them (an integration over the horizon, computed once)
        v0 = cfg.vehicle.airspeed_m_s
        at_v0 = demanded_directions(path, target, v0, horizon, s0, steady, with_positions=True)

        def feasible_at(v: float) -> CheckResult:
            # the bank the aircraft may fly (ours or the autopilot's own limit, the smaller) at
            # the turn per bank it really flies (vehicle.turn_gain)
            return feasibility(
                path, target, v, horizon, bank_limit_rad(cfg),
                cfg.vehicle.max_turn_rate_rad_s, s0, steady, bank_margin_rad=ch.bank_margin_rad,
                turn_gain=cfg.vehicle.turn_gain, demanded=at_v0[:2] if v == v0 else None,
            )  # fmt: skip

        results.append(_with_wind(feasible_at(v0), words, ch.bank_margin_rad))
        results.append(climb_check(cfg, path, target, horizon, s0, steady, at_v0, sim))
        if gust > 0.0:
            results.append(gust_feasibility(feasible_at, cfg.vehicle.airspeed_m_s, gust))
        if measured is not None:
            results.extend(_measured_checks(cfg, measured, path, target, horizon, s0))
        else:
            prof = profile_check(cfg, path, target, horizon, s0, steady, at_v0, sim)
            if prof is not None:
                results.append(prof)
        results.append(airspeed_hold(cfg))
        if cfg.section("fleet").enabled:  # fleet: convergence, speed window, bank at speed
            results.extend(_fleet_checks(cfg, path, target, steady, horizon, feasible_at))
    else:
        c1 = ch.c1_m if ch.c1_m is not None else 50.0
        results.append(
            gain_condition(build_gains(cfg), cfg.vehicle.v_min, cfg.vehicle.v_max, c1, ch.c2)
        )
    return results


def _fleet_checks(
    cfg: Config, path: Any, target: Any, steady: Any, horizon: float, feasible_at: Any
) -> list[CheckResult]:
    """:func:`~mpf_mavlink.core.guidance.coordination.fleet_checks` and the bank feasibility
    at the fastest airspeed the coordination may ask (``fleet_feasibility``)."""
    from mpf_mavlink.core.guidance.coordination import fleet_checks

    out, v_hi = fleet_checks(
        cfg.section("fleet"), cfg.vehicle, path, target,
        (float(steady[0]), float(steady[1]), float(steady[2])),
        horizon, cfg.adapter.speed_tau_s,
    )  # fmt: skip
    r = feasible_at(v_hi)
    # a warning at most: that airspeed is asked only where the path runs with the target's
    # motion, and the check applies it all round the path (an upper bound on the bank)
    out.append(dataclasses.replace(
        r, name="fleet_feasibility", status="warn" if r.status == "fail" else r.status,
        summary=f"at {v_hi:.1f} m/s all round the path (the fastest the fleet asks, an upper "
        "bound): " + r.summary))  # fmt: skip
    return out


def profile_check(
    cfg: Config,
    path: Any,
    target: Any,
    horizon: float,
    s0: float,
    steady: Any,
    at_v0: Any,
    plant: SimulatedPlant | None,
) -> CheckResult | None:
    """``autopilot_profile``: what the simulated plant's autopilot profile can fly (None: no
    simulated plant or no profile). A check of the simulated autopilot, not of a live one: the
    live bridge's pre-flight (``measured``) never runs it."""
    res = None if plant is None else plant.profile
    if res is None:
        return None
    k = res.profile.turn.turn_gain
    ch = cfg.checks
    turned = feasibility(
        path, target, cfg.vehicle.airspeed_m_s, horizon, bank_limit_rad(cfg),
        cfg.vehicle.max_turn_rate_rad_s, s0, steady, bank_margin_rad=ch.bank_margin_rad,
        turn_gain=k, demanded=at_v0[:2],
    )  # fmt: skip
    return autopilot_profile_limits(
        res.label, cfg.vehicle.airspeed_m_s, res.profile.thrust.full_thrust_airspeed_m_s, turned, k
    )


def _measured_checks(
    cfg: Config, measured: MeasuredInputs, path: Any, target: Any, horizon: float, s0: float
) -> list[CheckResult]:
    """The warnings only a measured state gives: feasibility with the wind's margin
    (``wind_margin``) and at the airspeed the aircraft flies now when that is higher than the
    law's (``measured_airspeed``: more airspeed needs more bank for the same turn)."""
    ch, v = cfg.checks, cfg.vehicle
    out: list[CheckResult] = []

    def warn(name: str, speed: float, wind: Any, what: str, then: str, fig: dict[str, Any]) -> None:
        r = feasibility(
            path, target, speed, horizon, bank_limit_rad(cfg), v.max_turn_rate_rad_s, s0, wind,
            bank_margin_rad=ch.bank_margin_rad, turn_gain=v.turn_gain,
        )  # fmt: skip
        out.append(CheckResult(name, "pass" if r.ok else "warn",
                               f"{what}: {r.summary}" + ("" if r.ok else f"; expect {then}"),
                               {**r.figures, **fig}))  # fmt: skip

    w = measured.wind_ned_m_s
    margin, how = measured.wind_margin_m_s()
    speed = math.hypot(w[0], w[1])
    # the margin along the measured wind's direction (from the north when there is none)
    ux, uy = (w[0] / speed, w[1] / speed) if speed > 1e-6 else (-1.0, 0.0)
    wm = (w[0] + margin * ux, w[1] + margin * uy, w[2])
    warn("wind_margin", v.airspeed_m_s, wm,
         f"with the measured wind plus its margin {margin:.1f} m/s ({how}), "
         f"{wind_words(wm, measured.wind_source)}", "the turn to saturate if the wind is that",
         {"wind_margin_m_s": margin})  # fmt: skip
    va = measured.airspeed_m_s
    if va is not None and math.isfinite(va) and va > v.airspeed_m_s + 0.5:
        warn("measured_airspeed", va, w,
             f"at the measured airspeed {va:.1f} m/s (VFR_HUD; the law flies "
             f"{v.airspeed_m_s:g})", "the turn to saturate until it slows",
             {"measured_airspeed_m_s": va})  # fmt: skip
    return out


def scenario_wind_source(plant: SimulatedPlant | None) -> str:
    """Which key :func:`scenario_wind`'s steady wind came from (for the checks' wording)."""
    if plant is not None:
        return "sil.wind_ned_m_s"
    return "kinematic.wind.steady_ned_m_s"


def format_checks(results: list[CheckResult]) -> str:
    lines = []
    for r in results:
        mark = {"pass": "PASS", "warn": "WARN", "fail": "FAIL"}[r.status]
        lines.append(f"[{mark}] {r.name}: {r.summary}")
    return "\n".join(lines)
