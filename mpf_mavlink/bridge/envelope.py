"""The envelope monitor: what the law demands against what the aircraft can give, every control
step, as EVENTS (issue 40).

Pure logic: :meth:`EnvelopeMonitor.update` takes one step's demand (:class:`Demand`, built from
the bridge's :class:`~mpf_mavlink.bridge.controller.Step` by :func:`demand_of`) and returns what
to do: the STATUSTEXTs to send (one when an episode starts) and whether the policy hands back.
No clock, no I/O: times are the step's mission time (s).

Kinds (each compared every step; an episode is a stretch where its condition holds):

- ``bank``: the bank the law's turn needs, atan(tan(bank of a = v omega x w1) / turn_gain) with
  the adapter's learned turn gain, beyond the autopilot's bank limit (the smaller of
  ``vehicle.max_bank_rad`` and ``vehicle.autopilot_bank_limit_rad``): the autopilot flies less.
- ``pitch``: the pitch set-point the law's flight-path demand needs (gamma + tau_pitch
  gamma_dot + trim) outside ``adapter.min_pitch_rad`` .. ``max_pitch_rad``.
- ``climb`` / ``sink``: the climb rate that flight-path demand means, v sin(gamma + tau_pitch
  gamma_dot), low-passed over :data:`CLIMB_TAU_S` (a steady capability against a sustained
  demand), beyond ``vehicle.max_climb_rate_m_s`` / ``max_sink_rate_m_s`` (when known).
- ``airspeed``: the airspeed outside the verdict's window, [v_min (1 - tol), v_max (1 + tol)]
  (``metrics.airspeed_tolerance``).
- ``thrust``: the thrust sent at ``adapter.thrust_max`` (within 0.005, as the verdict counts it).
- ``wind``: the measured horizontal wind above what the pre-engage checks accepted plus their
  margin (preflight.MeasuredInputs.wind_margin_m_s) and the config's gust allowance (the
  checks' turbulence allowance: a reported wind that follows the gusts is no new wind). A
  warning: the hold policy does not act on it, nor on ``thrust`` (:data:`POLICY_KINDS`).
- ``capture``: the capture guards (core/guidance/capture.py) changed the law's command, far
  from the path: its progression, its turn or its flight path was bounded. A warning: the
  guards are how a far capture stays inside the envelope, and the user sees that they acted
  (value: the distance |pt|, m; limit: ``guidance.capture_distance_m``).

An episode starts the first step its condition holds and ends once it has been clear for
``envelope.clear_s`` (a condition that flickers at 50 Hz is one episode, one STATUSTEXT); its
duration is start to the last step it held. The policy (``envelope.policy``): ``hold`` hands
back to the hold mode once one episode has lasted ``envelope.exceeded_for_s``, from
``envelope.armed_after_s`` after engagement on (default ``metrics.steady_after_s``: the capture
turns at the bank limit by design, the law's psi_turn; a saturation that outlasts the capture is
the mission not being flown); ``warn`` only tells.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from mpf_mavlink.core.adapter import bank_and_load_factor, heading_and_path_angle_rates

#: the kinds in the order they are named
KINDS = ("bank", "pitch", "climb", "sink", "airspeed", "thrust", "wind", "capture")
#: the kinds the hold policy acts on: what the aircraft does not fly (bank, pitch, climb, sink)
#: and the airspeed leaving its window. A wind beyond the checked one is a warning (the checks'
#: premise is gone; what it does to the flight shows as the bank it needs), and so is thrust at
#: its ceiling, which is how the energy control climbs (the capture's climb holds it there for
#: seconds); its consequence, an airspeed that cannot be held, is the airspeed kind.
POLICY_KINDS = ("bank", "pitch", "climb", "sink", "airspeed")
#: time constant (s) of the low-pass on the demanded climb rate that ``climb`` / ``sink`` compare:
#: the capability is a STEADY climb (full thrust) or sink (idle), and a short excess is paid
#: from the airspeed reserve, (v^2 - v_min^2) / 2g of height (the X8 at 16 m/s down to 13.6:
#: 3.6 m, a 1 m/s excess for 3.6 s; the climb check's energy budget, docs/checks.md)
CLIMB_TAU_S = 5.0
#: thrust within this of its ceiling is at the ceiling (runs/verdict.THRUST_CEILING_EPS)
THRUST_EPS = 0.005
#: a command within this of its limit (rad, rad/s) was clipped there: the adapter clips to the
#: limit itself, so anything closer is the clip's own value
CLIP_EPS = 1e-9


@dataclass(frozen=True)
class EnvelopeLimits:
    """What the aircraft can give (SI units, radians); None: not known, not compared."""

    bank_rad: float  # the autopilot's bank limit
    pitch_min_rad: float
    pitch_max_rad: float
    airspeed_min_m_s: float
    airspeed_max_m_s: float
    thrust_max: float
    climb_max_m_s: float | None = None
    sink_max_m_s: float | None = None
    wind_max_m_s: float | None = None  # the checked wind plus its margin (horizontal)
    adapter_bank_rad: float = math.inf  # the adapter's own clip (vehicle.max_bank_rad)
    rate_max_rad_s: tuple[float, float, float] = (math.inf, math.inf, math.inf)  # p, q, r
    capture_m: float = math.inf  # |pt| beyond which the capture guards act (m)


@dataclass(frozen=True)
class Demand:
    """One control step: what the law demands and what was sent. t: mission time (s); bank_rad,
    pitch_rad, climb_m_s: demanded (before any clip; pitch is the set-point before the
    adapter's pitch clip); airspeed_m_s, wind_m_s: measured; thrust: sent; clipped: some command
    of this step was cut at a limit (bank, pitch, body rates, the law's rate limit); capture:
    the capture guards that changed the law's command ("sdot", "turn", "path"), at |pt| = pt_m
    (m)."""

    t: float
    bank_rad: float
    pitch_rad: float
    climb_m_s: float
    airspeed_m_s: float
    thrust: float
    wind_m_s: float
    clipped: bool = False
    capture: tuple[str, ...] = ()
    pt_m: float = 0.0


@dataclass
class Episode:
    """One stretch of a kind beyond its limit: start and end (mission time s, the last step
    it held), the peak value (its unit: rad for bank/pitch, m/s, thrust fraction) and the
    limit it was compared with."""

    kind: str
    start: float
    end: float
    peak: float
    limit: float

    @property
    def duration(self) -> float:
        return self.end - self.start

    def as_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind, "start_s": self.start, "end_s": self.end,
            "duration_s": self.duration, "peak": self.peak, "limit": self.limit,
        }  # fmt: skip


@dataclass
class Actions:
    """What one :meth:`EnvelopeMonitor.update` asks of the bridge: texts to send (STATUSTEXT,
    severity WARNING) and a hand-back (its reason), or nothing."""

    texts: list[str] = field(default_factory=list)
    hand_back: str | None = None


def _fmt(kind: str, value: float) -> str:
    if kind == "capture":
        return f"{value:.0f}m"
    if kind in ("bank", "pitch"):
        return f"{math.degrees(value):.1f}deg"
    if kind == "thrust":
        return f"{value:.2f}"
    return f"{value:.2f}m/s"


class EnvelopeMonitor:
    """Episodes per kind, the STATUSTEXT once per episode and the policy (module docstring).

    ``t_engage``: mission time (s) of the engagement, which the policy's arming counts from."""

    def __init__(
        self,
        limits: EnvelopeLimits,
        policy: str = "hold",
        exceeded_for_s: float = 5.0,
        armed_after_s: float = 0.0,
        clear_s: float = 1.0,
    ) -> None:
        self.lim = limits
        self.policy, self.exceeded_for_s = policy, exceeded_for_s
        self.armed_after_s, self.clear_s = armed_after_s, clear_s
        self.t_engage: float | None = None
        self.open: dict[str, Episode] = {}
        self.closed: list[Episode] = []
        self.steps = 0
        self.clipped_steps = 0
        self.handed_back: str | None = None
        self._climb_f: float | None = None  # m/s, the low-passed climb demand
        self._t_prev: float | None = None

    # -- the comparisons -------------------------------------------------------------------------
    def beyond(self, d: Demand) -> dict[str, tuple[float, float]]:
        """The kinds beyond their limits at this step: kind -> (value, limit)."""
        lim, out = self.lim, {}
        if abs(d.bank_rad) > lim.bank_rad + CLIP_EPS:
            out["bank"] = (abs(d.bank_rad), lim.bank_rad)
        if d.pitch_rad > lim.pitch_max_rad + CLIP_EPS:
            out["pitch"] = (d.pitch_rad, lim.pitch_max_rad)
        elif d.pitch_rad < lim.pitch_min_rad - CLIP_EPS:
            out["pitch"] = (d.pitch_rad, lim.pitch_min_rad)
        climb = d.climb_m_s if self._climb_f is None else self._climb_f
        if lim.climb_max_m_s is not None and climb > lim.climb_max_m_s:
            out["climb"] = (climb, lim.climb_max_m_s)
        if lim.sink_max_m_s is not None and -climb > lim.sink_max_m_s:
            out["sink"] = (-climb, lim.sink_max_m_s)
        if d.airspeed_m_s > lim.airspeed_max_m_s:
            out["airspeed"] = (d.airspeed_m_s, lim.airspeed_max_m_s)
        elif d.airspeed_m_s < lim.airspeed_min_m_s:
            out["airspeed"] = (d.airspeed_m_s, lim.airspeed_min_m_s)
        if d.thrust >= lim.thrust_max - THRUST_EPS:
            out["thrust"] = (d.thrust, lim.thrust_max)
        if lim.wind_max_m_s is not None and d.wind_m_s > lim.wind_max_m_s:
            out["wind"] = (d.wind_m_s, lim.wind_max_m_s)
        if d.capture:
            out["capture"] = (d.pt_m, lim.capture_m)
        return out

    # -- one step ------------------------------------------------------------------------------
    def update(self, d: Demand) -> Actions:
        """Compare one step; close, extend and open episodes; apply the policy."""
        if self.t_engage is None:
            self.t_engage = d.t
        self.steps += 1
        if self._climb_f is None or self._t_prev is None or not math.isfinite(self._climb_f):
            self._climb_f = d.climb_m_s
        else:
            k = 1.0 - math.exp(-max(0.0, d.t - self._t_prev) / CLIMB_TAU_S)
            self._climb_f += k * (d.climb_m_s - self._climb_f)
        self._t_prev = d.t
        now = self.beyond(d)
        # a clip the monitor's kinds do not show (the law's own rate limit, body rates) counts
        # in the saturated fraction too: the command that went out is not the law's
        if d.clipped or "bank" in now or "pitch" in now:
            self.clipped_steps += 1
        acts = Actions()
        for kind in list(self.open):
            if kind not in now and d.t - self.open[kind].end >= self.clear_s:
                self.closed.append(self.open.pop(kind))
        for kind in KINDS:
            if kind not in now:
                continue
            value, limit = now[kind]
            cur = self.open.get(kind)
            if cur is None:
                new = self.open[kind] = Episode(kind, d.t, d.t, value, limit)
                acts.texts.append(self.text(new, d.capture))
            else:
                cur.end = d.t
                if abs(value) > abs(cur.peak):
                    cur.peak = value
        armed = d.t - self.t_engage >= self.armed_after_s
        if self.policy == "hold" and armed and self.handed_back is None:
            for kind in POLICY_KINDS:
                ep = self.open.get(kind)
                if ep is not None and kind in now and ep.duration >= self.exceeded_for_s:
                    self.handed_back = (
                        f"envelope exceeded: {kind} beyond its limit for {ep.duration:.1f} s "
                        f"(peak {_fmt(kind, ep.peak)}, limit {_fmt(kind, ep.limit)}; "
                        f"envelope.exceeded_for_s = {self.exceeded_for_s:g}): handed back"
                    )
                    acts.hand_back = self.handed_back
                    acts.texts.append(f"MPF envelope: {kind} {ep.duration:.0f}s, hold")
                    break
        return acts

    @staticmethod
    def text(ep: Episode, guards: tuple[str, ...] = ()) -> str:
        """The STATUSTEXT of an episode's start (<= 50 characters, MAVLink's text field);
        guards: for a capture episode, the guards that acted."""
        if ep.kind == "capture":
            return f"MPF capture: {','.join(guards)} bounded at {_fmt('capture', ep.peak)}"[:50]
        s = f"MPF envelope: {ep.kind} {_fmt(ep.kind, ep.peak)} > {_fmt(ep.kind, ep.limit)}"
        return s[:50]

    # -- the record ----------------------------------------------------------------------------
    def episodes(self) -> list[Episode]:
        """Every episode, closed and still open, by start time."""
        return sorted([*self.closed, *self.open.values()], key=lambda e: e.start)

    def summary(self, steady_after_s: float, t_end: float | None) -> dict[str, Any]:
        """metrics.json's ``envelope`` section: the episodes, per kind their count, total and
        longest time and the fraction of the steady window (t - t_engage >= steady_after_s) they
        cover, the fraction of steps whose command was clipped, and the policy's hand-back."""
        eps = self.episodes()
        t0 = self.t_engage if self.t_engage is not None else 0.0
        steady0 = t0 + steady_after_s
        steady_s = max(0.0, (t_end if t_end is not None else steady0) - steady0)
        kinds: dict[str, Any] = {}
        for k in KINDS:
            mine = [e for e in eps if e.kind == k]
            if not mine:
                continue
            in_steady = sum(
                max(0.0, min(e.end, t_end if t_end is not None else e.end) - max(e.start, steady0))
                for e in mine
            )
            kinds[k] = {
                "episodes": len(mine),
                "total_s": sum(e.duration for e in mine),
                "longest_s": max(e.duration for e in mine),
                "peak": max((e.peak for e in mine), key=abs),
                "limit": mine[0].limit,
                "steady_fraction": in_steady / steady_s if steady_s > 0 else None,
            }
        return {
            "policy": self.policy,
            "exceeded_for_s": self.exceeded_for_s,
            "armed_after_s": self.armed_after_s,
            "clear_s": self.clear_s,
            "episodes": [e.as_dict() for e in eps],
            "kinds": kinds,
            "clipped_fraction": self.clipped_steps / self.steps if self.steps else 0.0,
            "handed_back": self.handed_back,
        }


#: a kind named in the verdict covers at least this fraction of the steady window (0.5 %: a
#: second of a 200 s window); episodes of the capture alone are in metrics.json only
VERDICT_MIN_FRACTION = 0.005


def verdict_words(summary: dict[str, Any]) -> str:
    """The envelope as the verdict names it: ``bank at its limit 30 % of the steady window (4
    episodes, longest 9.2 s)``, one clause per kind that covers at least
    :data:`VERDICT_MIN_FRACTION` of the steady window (each kind without one), then the
    policy's hand-back; "" when there is nothing to name."""
    parts = []
    for kind, k in (summary.get("kinds") or {}).items():
        frac = k.get("steady_fraction")
        if frac is not None and frac < VERDICT_MIN_FRACTION:
            continue
        where = (
            f"{100 * frac:.0f} % of the steady window"
            if frac is not None
            else f"{k['total_s']:.1f} s (no steady window)"
        )
        n = k["episodes"]
        parts.append(
            f"{kind} at its limit {where} ({n} episode{'s' if n != 1 else ''}, longest "
            f"{k['longest_s']:.1f} s)"
        )
    if summary.get("handed_back"):
        parts.append("the hold policy handed back")
    return "; ".join(parts)


# ----------------------------------------------------------------------------- from a step
def demand_of(
    t: float,
    omega_w1_I: Any,
    w1: Any,
    airspeed: float,
    wind_ned: Any,
    setpoint: Any,
    turn_gain: float,
    trim_pitch_rad: float,
    tau_pitch_s: float,
    law_rate_limited: bool,
    lim: EnvelopeLimits,
) -> Demand:
    """A step's :class:`Demand` from the law's command (omega_w1_I, rad/s, NED), w1 (NED unit),
    the airspeed (m/s) and wind (NED m/s) measured, the setpoint sent, the adapter's learned turn
    gain and pitch trim (rad) and its pitch lead tau_pitch_s (s): the bank and pitch the adapter
    computes before its clips (core/adapter.py adapt)."""
    ox, oy, oz = (float(x) for x in omega_w1_I)
    w = (float(w1[0]), float(w1[1]), float(w1[2]))
    v = float(airspeed)
    accel = (v * (oy * w[2] - oz * w[1]), v * (oz * w[0] - ox * w[2]), v * (ox * w[1] - oy * w[0]))
    bank, _ = bank_and_load_factor(w, accel)
    if turn_gain != 1.0 and turn_gain > 0.0:
        bank = math.atan(math.tan(max(-1.4, min(1.4, bank))) / turn_gain)
    gamma = math.asin(max(-1.0, min(1.0, -w[2])))
    _, gamd = heading_and_path_angle_rates(w, (ox, oy, oz))
    gam_dem = gamma + gamd * tau_pitch_s
    pitch = gam_dem + trim_pitch_rad
    climb = v * math.sin(max(-math.pi / 2, min(math.pi / 2, gam_dem)))
    p, q, r = setpoint.body_rates_frd
    rp, rq, rr = lim.rate_max_rad_s
    clipped = (
        law_rate_limited
        or abs(setpoint.bank_rad) >= lim.adapter_bank_rad - CLIP_EPS
        or setpoint.pitch_rad >= lim.pitch_max_rad - CLIP_EPS
        or setpoint.pitch_rad <= lim.pitch_min_rad + CLIP_EPS
        or abs(p) >= rp - CLIP_EPS
        or abs(q) >= rq - CLIP_EPS
        or abs(r) >= rr - CLIP_EPS
    )
    wind = math.hypot(float(wind_ned[0]), float(wind_ned[1]))
    return Demand(t, bank, pitch, climb, v, float(setpoint.thrust), wind, clipped)


def demand_of_step(st: Any, ctl: Any, lim: EnvelopeLimits) -> Demand:
    """:func:`demand_of` for a bridge :class:`~mpf_mavlink.bridge.controller.Step` and its
    :class:`~mpf_mavlink.bridge.controller.Controller` (the adapter's learned turn gain and
    pitch trim after the step): what the live bridge and tlog replay both compare."""
    p, a = ctl.ad_params, ctl.ad_state
    trim = a.trim_hat if (p.adaptive and a.trim_hat is not None) else p.trim_pitch_rad
    vs = st.estimate.vehicle
    wind = vs.floats[12:15] if vs.floats is not None else vs.wind
    d = demand_of(
        st.t, st.cmd.omega_w1_I, st.w1, vs.airspeed, wind, st.setpoint,
        a.turn_gain if p.adaptive else 1.0, trim, p.tau_pitch_s, False, lim,
    )  # fmt: skip
    guard = getattr(ctl, "capture", None)
    act = guard.last if guard is not None else None
    if act is None or not act.limited:
        return d
    return dataclasses.replace(d, capture=act.limited, pt_m=act.pt_m)


def wind_limit_m_s(cfg: Any, measured: dict[str, Any], plant: Any = None) -> float | None:
    """The horizontal wind (m/s) the monitor holds a flight to: the one the pre-engage checks
    measured, plus its margin and the gust allowance of the plant (preflight.scenario_wind:
    ``plant``, the simulated vehicle behind the link, or the config's kinematic gusts); None
    without a measurement."""
    from mpf_mavlink.bridge.preflight import scenario_wind

    if not measured:
        return None
    w = measured["wind_ned_m_s"]
    _, gust = scenario_wind(cfg, plant)
    return math.hypot(w[0], w[1]) + float(measured["wind_margin_m_s"]) + gust


def envelope_monitor(cfg: Any, ad: Any) -> EnvelopeMonitor:
    """The monitor of a configuration (``envelope`` section; the limits of ``vehicle``,
    ``metrics`` and the adapter's parameters ``ad``, core/adapter.AdapterParams). The wind's
    limit is set once the pre-engage checks have measured it."""
    from mpf_mavlink.config.schema import bank_limit_rad

    v, m, e = cfg.vehicle, cfg.metrics, cfg.envelope
    tol = m.airspeed_tolerance
    lim = EnvelopeLimits(
        bank_rad=bank_limit_rad(cfg), pitch_min_rad=ad.min_pitch_rad,
        pitch_max_rad=ad.max_pitch_rad, airspeed_min_m_s=v.v_min * (1.0 - tol),
        airspeed_max_m_s=v.v_max * (1.0 + tol), thrust_max=ad.thrust_max,
        climb_max_m_s=v.max_climb_rate_m_s, sink_max_m_s=v.max_sink_rate_m_s,
        adapter_bank_rad=ad.max_bank_rad,
        rate_max_rad_s=(ad.max_roll_rate_rad_s, ad.max_pitch_rate_rad_s, ad.max_yaw_rate_rad_s),
        capture_m=cfg.guidance.capture_distance_m,
    )  # fmt: skip
    armed = e.armed_after_s if e.armed_after_s is not None else m.steady_after_s
    return EnvelopeMonitor(lim, e.policy, e.exceeded_for_s, armed, e.clear_s)
