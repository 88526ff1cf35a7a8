"""The bridge's per-sample computation, shared by the live bridge and tlog replay.

:class:`Controller` holds everything between a decoded telemetry sample and the setpoint sent
for it: the estimator, the target (scripted or live), the virtual point s, the law, the
adapter with its airspeed-hold integrator and the safe-setpoint rule. It does no I/O and reads
no clock: time comes from the samples (autopilot boot time) and from the receive times the
caller passes in, which the bridge takes from its tlog records (microseconds), so a replay of
that tlog hands it the very same numbers. Driving it with the same samples in the same order
therefore gives the same setpoints, bit for bit.

The call sequence, identical in :mod:`mpf_mavlink.bridge.live` and :mod:`mpf_mavlink.runs.replay`:

1. ``feed_vehicle(sample, rx)`` / ``feed_target(sample, rx)`` for every decoded message of the
   vehicle (after its first autopilot HEARTBEAT) or of the live target.
2. ``ready()`` after each such message until the origin is set: the bridge's wait for a
   complete state. (It calls :meth:`Estimator.estimate`, whose wind low-pass advances with
   each new attitude time, so the calls must be the same in both.)
3. ``set_origin()`` (CHECKS: mission time 0 = the attitude time then) and ``init_s()`` (INIT:
   the virtual point at the closest point of the moving path).
4. ``step()`` for every control instant once setpoints stream (an ATTITUDE sample, and with
   ``mavlink.position_instants`` a LOCAL_POSITION_NED between two of them: ``feed_vehicle``
   returns True for both): s += sdot_prev dt, the law, the adapter; a duplicate or
   out-of-order sample (dt <= 0) is skipped.

What the bridge decides from the wall clock (t0, s0, the moment streaming starts) it writes to
the tlog as STATUSTEXT (:func:`origin_texts`, :data:`STREAM_TEXT`) for replay to pick up.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from mpf_mavlink.bridge.estimator import Estimate, Estimator, EstimatorParams
from mpf_mavlink.bridge.instants import ControlInstants
from mpf_mavlink.bridge.loop_delay import LoopDelay
from mpf_mavlink.bridge.target_sources import ExtrapolatedTarget, LiveTarget, ScriptedTarget
from mpf_mavlink.config.bridge import MavlinkConfig
from mpf_mavlink.config.scenario import (
    build_capture,
    build_extensions,
    build_gains,
    build_path,
    build_target,
)
from mpf_mavlink.config.schema import Config
from mpf_mavlink.config.target import TargetEstimatorConfig
from mpf_mavlink.core.adapter import AdapterParams, AdapterState, Setpoint, adapt, safe_setpoint
from mpf_mavlink.core.guidance.capture import CaptureGuard
from mpf_mavlink.core.guidance.dispatch import guidance_law
from mpf_mavlink.core.guidance.law import (
    Extensions,
    Gains,
    MpfCommand,
    MpfDiagnostics,
    MpfErrors,
    VehicleState,
    mpf_errors,
)
from mpf_mavlink.core.guidance.predict import look_ahead, predict_rows, prediction_horizon
from mpf_mavlink.core.paths import TabulatedPath
from mpf_mavlink.core.target import TargetMotion, TargetState
from mpf_mavlink.errors import MpfError
from mpf_mavlink.runs.rundir import row_from

# ----------------------------------------------------------------------------- tlog markers
#: STATUSTEXT texts (MAVLink 2, <= 50 characters, severity INFO) the bridge sends, from its own
#: system/component ids, so that a tlog carries the decisions the telemetry cannot tell:
#: ``MPF t0=<float>`` and ``MPF s0=<float>`` right after INIT (no message is processed between
#: CHECKS and them), then ``MPF stream`` when setpoints start to stream (after the backlog that
#: piled up during the checks has been taken into the state). Floats are ``repr``: exact.
#: ``MPF halt`` when control steps stop without ending the run (telemetry or target lost with
#: re-engagement configured); a re-engagement then records ``MPF s0=`` and ``MPF stream`` again.
T0_PREFIX = "MPF t0="
S0_PREFIX = "MPF s0="
STREAM_TEXT = "MPF stream"
HALT_TEXT = "MPF halt"


def origin_texts(t0: float, s0: float) -> list[str]:
    """The two STATUSTEXT texts that record the mission-time origin t0 (s, autopilot boot time)
    and the initial arc length s0 (m). Each is at most 31 characters."""
    return [f"{T0_PREFIX}{float(t0)!r}", f"{S0_PREFIX}{float(s0)!r}"]


def parse_marker(text: str) -> tuple[str, float | None] | None:
    """('t0', value), ('s0', value), ('stream', None), ('halt', None), or None for any other
    text."""
    text = text.rstrip("\x00").strip()
    for key, prefix in (("t0", T0_PREFIX), ("s0", S0_PREFIX)):
        if text.startswith(prefix):
            try:
                v = float(text[len(prefix) :])
            except ValueError:
                return None
            return (key, v) if math.isfinite(v) else None
    if text == STREAM_TEXT:
        return ("stream", None)
    if text == HALT_TEXT:
        return ("halt", None)
    return None


#: The index of ``mode`` in :class:`MpfDiagnostics`
_MODE = MpfDiagnostics._fields.index("mode")


class _Once:
    """A value, or the function ``make()`` that makes it the first time it is asked for
    (then kept)."""

    __slots__ = ("_make", "_value")

    def __init__(self, value_or_make: Any) -> None:
        self._make: Callable[[], Any] | None = None
        self._value: Any = None
        if callable(value_or_make):
            self._make = value_or_make
        else:
            self._value = value_or_make

    @property
    def made(self) -> bool:
        return self._make is None

    def __call__(self) -> Any:
        if self._make is not None:
            self._value, self._make = self._make(), None
        return self._value


class Step:
    """One control step: what the law saw and the setpoint it produced.

    t: mission time (s); t_boot_s: the ATTITUDE sample's autopilot time (s);
    time_boot_ms: what the setpoint carries; dt: time since the previous step (s, 0 first);
    w1_prev: w1 (NED) of the previous step, for the achieved-rate column of the logs.
    ``target``, ``diag``: the target and the law's diagnostics at the sample's own instant.
    With delay compensation the command comes from the predicted state, and what the logs
    need of the sample's instant (the target's state there, a second evaluation of the pure
    law) is made only when a record or the display asks for it, after the setpoint went out:
    given as functions. ``errors``: the function that gives the rows' part of ``diag``
    (:func:`~mpf_mavlink.core.guidance.law.mpf_errors`, half the law's cost) when the full
    record has not been asked for; None: ``diag``.
    """

    __slots__ = (
        "t", "t_boot_s", "time_boot_ms", "dt", "estimate", "cmd", "setpoint",
        "w1", "w1_prev", "_target", "_diag", "_errors_of",
    )  # fmt: skip

    def __init__(
        self,
        t: float,
        t_boot_s: float,
        time_boot_ms: int,
        dt: float,
        estimate: Estimate,
        target: TargetState | Callable[[], TargetState],
        cmd: MpfCommand,
        diag: MpfDiagnostics | Callable[[], MpfDiagnostics],
        setpoint: Setpoint,
        w1: tuple[float, float, float],
        w1_prev: tuple[float, float, float] | None,
        errors: Callable[[], MpfErrors] | None = None,
    ) -> None:
        self.t, self.t_boot_s, self.time_boot_ms, self.dt = t, t_boot_s, time_boot_ms, dt
        self.estimate, self.cmd, self.setpoint = estimate, cmd, setpoint
        self.w1, self.w1_prev = w1, w1_prev
        self._target = target if isinstance(target, _Once) else _Once(target)
        self._diag = _Once(diag)
        self._errors_of = errors

    @property
    def target(self) -> TargetState:
        return cast(TargetState, self._target())

    @property
    def diag(self) -> MpfDiagnostics:
        return cast(MpfDiagnostics, self._diag())

    def row(self) -> list[float]:
        """The run directory's timeseries row (:data:`mpf_mavlink.runs.rundir.COLUMNS`)."""
        vs = self.estimate.vehicle
        w_act = (0.0, 0.0)
        wp = self.w1_prev
        if wp is not None and self.dt > 0.0:
            # logging only: the law never sees this difference of telemetry
            vf = vs.floats
            if vf is not None:
                _, r01, r02, _, r11, r12, _, r21, r22 = vf[0:9]
            else:
                (_, r01, r02), (_, r11, r12), (_, r21, r22) = vs.R_W_I.tolist()
            w = self.w1
            d0, d1, d2 = (
                (w[0] - wp[0]) / self.dt,
                (w[1] - wp[1]) / self.dt,
                (w[2] - wp[2]) / self.dt,
            )
            w_act = (-(d0 * r02 + d1 * r12 + d2 * r22), d0 * r01 + d1 * r11 + d2 * r21)
        tg = self.target
        f = tg.floats
        tp: Any
        tR: Any
        if f is not None:  # its own floats: a live target's arrays need not be built for this
            tp, tR = f[9:12], (f[0:3], f[3:6], f[6:9])
        else:
            tp, tR = tg.position, tg.R_T_I
        c = self.cmd
        # the full record when it was made (or asked for) anyway, else the rows' part of it
        ef = self._errors_of
        d: MpfDiagnostics | MpfErrors = self.diag if ef is None or self._diag.made else ef()
        vf = vs.floats
        p, wind = (vf[9:12], vf[12:15]) if vf is not None else (vs.position, vs.wind)
        return row_from(d, p, (c.w2, c.w3), w_act, c.sdot, tp, tR, wind)

    def setpoint_row(self) -> list[float]:
        """The row of setpoints.csv (:data:`SETPOINT_COLUMNS`)."""
        sp = self.setpoint
        return [
            self.t,
            *sp.body_rates_frd,
            *sp.q_wxyz,
            sp.thrust,
            sp.bank_rad,
            sp.pitch_rad,
            sp.load_factor,
            1.0 if sp.safe else 0.0,
        ]


SETPOINT_COLUMNS = "t,p,q,r,qw,qx,qy,qz,thrust,bank,pitch,load_factor,safe"


def write_setpoints(out: Path, rows: list[tuple[float, ...]]) -> None:
    """setpoints.csv in the run directory ``out``: one :meth:`Step.setpoint_row` a line."""
    np.savetxt(
        out / "setpoints.csv",
        np.array(rows, float).reshape(-1, 13),
        delimiter=",",
        header=SETPOINT_COLUMNS,
        comments="",
        fmt="%.9g",
    )


def adapter_params(cfg: Config) -> AdapterParams:
    """The adapter's limits and gains from the ``vehicle`` and ``adapter`` sections."""
    a = cfg.section("adapter")
    v = cfg.vehicle
    fields = {f.name: getattr(a, f.name) for f in dataclasses.fields(a)}
    fields["thrust_per_gamma"] = a.k_thrust(v)
    if v.max_climb_rate_m_s is not None:  # the energy reserve's capability (core/adapter.py)
        fields["max_climb_m_s"] = v.max_climb_rate_m_s
    return AdapterParams(
        max_bank_rad=v.max_bank_rad, airspeed_sp_m_s=v.airspeed_m_s, airspeed_min_m_s=v.v_min,
        airspeed_max_m_s=v.v_max, **fields,
    )  # fmt: skip


def estimator_params(m: MavlinkConfig) -> EstimatorParams:
    """The estimator's staleness limits and origin from the ``mavlink`` section."""
    origin = None
    if m.origin_lat_deg is not None and m.origin_lon_deg is not None and m.origin_alt_m is not None:
        origin = (m.origin_lat_deg, m.origin_lon_deg, m.origin_alt_m)
    return EstimatorParams(
        m.attitude_stale_s, m.position_stale_s, m.airspeed_stale_s, m.wind_stale_s,
        m.wind_filter_tau_s, origin=origin, airspeed_is_eas=m.airspeed_is_eas,
        airspeed_from_wind=m.airspeed_from_wind,
    )  # fmt: skip


def target_as_constant_turn(st: TargetState, make: Any) -> Any:
    """A live target's estimated state (at mission time 0) as the scripted target the checks
    can judge (``make``: :class:`~mpf_mavlink.config.schema.TargetConfig`): ``constant_turn``
    at its position, ground speed, course, climb rate and yaw rate (about down). Below 0.5 m/s
    the course is noise: the heading is the target frame's yaw."""
    p = [float(x) for x in st.position]
    vn, ve, vd = (float(x) for x in st.velocity)
    R = np.asarray(st.R_T_I, float)
    yaw_rate = float((R @ np.asarray(st.omega_T, float))[2])
    speed = math.hypot(vn, ve)
    heading = math.atan2(ve, vn) if speed >= 0.5 else math.atan2(R[1, 0], R[0, 0])
    return make(
        type="constant_turn", position_ned_m=(p[0], p[1], p[2]),
        speed_m_s=speed if speed >= 0.5 else 0.0, heading_rad=heading,
        turn_rate_rad_s=yaw_rate, climb_rate_m_s=-vd,
    )  # fmt: skip


@dataclass(frozen=True)
class ControlSetup:
    """What one run's controller flies, built once from the configuration (:meth:`of`)."""

    law: str  # guidance.law: MPF or a baseline (core/guidance/baselines.py)
    path: TabulatedPath  # in the target frame {T}
    gains: Gains
    ext: Extensions
    capture: CaptureGuard | None  # the capture guards (core/guidance/capture.py)
    #: the scripted target motion; None: the live target of MAVLink (``target``)
    target_motion: TargetMotion | None
    target_estimator: TargetEstimatorConfig  # how a live target is estimated
    target_timeout_s: float  # an extrapolated live target's staleness limit (s)
    estimator: EstimatorParams
    adapter: AdapterParams
    initial_s_m: float | None  # None: the closest point of the moving path
    flavour: str  # the autopilot (mavlink.flavour: px4 streams body rates)
    known_delay_s: float
    delay_compensation: bool
    position_instants: bool

    @classmethod
    def of(cls, cfg: Config, m: MavlinkConfig | None = None) -> ControlSetup:
        """The setup of ``cfg``; ``m``: its (possibly command-line adjusted) ``mavlink``."""
        m = cfg.mavlink if m is None else m
        live = cfg.target.type == "mavlink"
        if live and m.target_sysid is None:
            raise MpfError(f"{cfg.source}: target.type mavlink needs mavlink.target_sysid")
        path = build_path(cfg.path)
        return cls(
            law=cfg.guidance.law, path=path, gains=build_gains(cfg),
            ext=build_extensions(cfg), capture=build_capture(cfg, path),
            target_motion=None if live else build_target(cfg.target),
            target_estimator=cfg.target_estimator, target_timeout_s=m.target_timeout_s,
            estimator=estimator_params(m), adapter=adapter_params(cfg),
            initial_s_m=cfg.guidance.initial_s_m, flavour=m.flavour,
            known_delay_s=m.known_delay_s, delay_compensation=m.delay_compensation,
            position_instants=m.position_instants,
        )  # fmt: skip


class Controller:
    """Estimator + target + s + law + adapter for one run (see the module docstring)."""

    def __init__(self, setup: ControlSetup) -> None:
        self.setup = su = setup
        self.ad_params = su.adapter
        self.est = Estimator(su.estimator)
        self.live = su.target_motion is None
        self.target: Any = (
            ScriptedTarget(su.target_motion)
            if su.target_motion is not None
            else LiveTarget(self.est, su.target_estimator.params())
            if su.target_estimator.mode == "filter"
            else ExtrapolatedTarget(self.est, su.target_timeout_s)
        )
        self.path = su.path
        self.gains = su.gains
        self.ext = su.ext
        self.cfg_law = su.law
        self.capture = su.capture
        self.s = 0.0
        self.t0: float | None = None  # mission-time origin (autopilot boot time, s)
        self.t_prev: float | None = None
        self.sdot_prev = 0.0
        self.w1_prev: tuple[float, float, float] | None = None
        self.ad_state = AdapterState()
        self.why_not = ""
        self.law_evals = 0
        # fleet (bridge/fleet.py): (t, s, sdot, vehicle, target) -> the airspeed set-point (m/s)
        self.airspeed_hook: Callable[[float, float, float, Any, Any], float] | None = None
        # delay compensation: the step period (s, filtered), the loop delay (loop_delay.py)
        self.period_s = 0.0
        self.rates_pipeline = su.flavour == "px4"
        self.delay = LoopDelay(su.known_delay_s, self.rates_pipeline)
        self.tau_s = 0.0  # the prediction horizon of the latest step
        self.alpha_m = self.gains.alpha  # the look-ahead of the latest step (guidance/predict.py)
        if not self.rates_pipeline:  # body rates not sent: no pitch-rate bias to take off them
            self.ad_params = dataclasses.replace(self.ad_params, rate_bias_tau_s=0.0)
        # multi-rate loop: which samples are control instants (instants.py)
        self.instants = ControlInstants(self.est, self.rates_pipeline and su.position_instants)

    # -- feeding ----------------------------------------------------------------------------
    def feed_vehicle(self, sample: Any, rx: float | None) -> bool:
        """A decoded sample of the vehicle; True when it is a control instant: an ATTITUDE, or
        with ``mavlink.position_instants`` a LOCAL_POSITION_NED between two of them
        (:class:`~mpf_mavlink.bridge.instants.ControlInstants`)."""
        name = type(sample).__name__
        if name == "AttitudeTargetSample":
            self.delay.echo(sample, self.est.t0)
            return False
        if name == "TimesyncSample":
            self.delay.timesync_answer(sample, rx)
            return False
        est = self.est
        prev_att, prev_loc = est.att, est.local
        attitude = est.update(sample, rx)
        return self.instants.after_update(sample, attitude, prev_att, prev_loc)

    def feed_target(self, sample: Any, rx: float | None) -> None:
        """A decoded sample of the live target (ignored with a scripted target)."""
        if self.live:
            self.target.update(sample, mission_time_at(self.est, rx))

    # -- initialisation -----------------------------------------------------------------------
    def ready(self) -> bool:
        """A complete state (and a live target) exists; else ``why_not`` says what is missing."""
        est, why = self.est.estimate()
        if est is None:
            self.why_not = why
            return False
        if self.live:
            st = self.target.state(est.vehicle.t)
            if isinstance(st, str):
                self.why_not = st
                return False
        return True

    def set_origin(self, t0: float | None = None) -> float:
        """Mission time 0 (the checks' and the scripted target's origin): the latest attitude
        time, or ``t0`` (s, autopilot boot time) as recorded by a bridge."""
        est, why = self.est.estimate()
        if t0 is None:
            if est is None:
                raise MpfError(f"no state to start from: {why}")
            t0 = est.t_boot_s
        self.t0 = float(t0)
        self.est.t0 = self.t0
        self.est.lock_attitude_source()  # one attitude source, one control rate, per flight
        self.target.restamp(self.t0)
        return self.t0

    def init_s(self, s0: float | None = None) -> float:
        """The virtual point: ``s0`` (m) if given, else ``guidance.initial_s_m``, else the
        closest point of the moving path to the vehicle now. The step state (previous instant,
        sdot, the adapter's integrator) starts afresh, as on a re-engagement it must: s is not
        integrated across the time the law was not flying the vehicle."""
        if s0 is None:
            s0 = self.setup.initial_s_m
        if s0 is None:
            est, why = self.est.estimate()
            if est is None:
                raise MpfError(f"no state to start from: {why}")
            vs = est.vehicle
            tgt = self.target.state(vs.t)
            if isinstance(tgt, str):
                raise MpfError(f"no target to start from: {tgt}")
            s0 = self.path.closest(tgt.R_T_I.T @ (vs.position - tgt.position))
        self.s = float(s0)
        self.t_prev = None
        self.instants.t_prev_boot = None
        self.sdot_prev = 0.0
        self.w1_prev = None
        # the airframe's learned trim and turn stay; thrust starts from the autopilot's own
        self.ad_state = self.ad_state.for_reengage(thrust_flown(self.est))
        return self.s

    # -- control ------------------------------------------------------------------------------
    def step(self) -> Step | None:
        """One control step at the latest control instant (ATTITUDE, or a position instant:
        :meth:`feed_vehicle`); None (``why_not`` set) when the state or the target is not
        usable, or when the sample is not newer than the previous step.

        What only the logs need (the target at the sample's instant when the command comes
        from a prediction, the law's diagnostics there) is left in the :class:`Step` as
        functions, made when a record or the display asks: after the setpoint went out."""
        est, why = self.est.estimate(self.instants.at_position)
        if est is None:
            self.why_not = why
            return None
        vs = est.vehicle
        t = vs.t
        tgt = self.target.state_later(t)  # whether the target is there now; its state later
        if isinstance(tgt, str):
            self.why_not = tgt
            return None
        dt = 0.0
        if self.t_prev is not None:
            dt = t - self.t_prev
            if dt <= 0.0:  # duplicate or out-of-order sample: already acted on that instant
                self.why_not = (
                    f"no new ATTITUDE instant (t {t:.3f} s, last step at {self.t_prev:.3f} s)"
                )
                return None
            self._advance(dt)
        if callable(tgt):
            tgt = _Once(tgt)
        # The law acts on the state when its setpoint acts (guidance/predict.py)
        vf = vs.floats  # R_W^I by rows, ... (VehicleState.floats: the estimator's states)
        w1 = (vf[0], vf[3], vf[6]) if vf is not None else tuple(vs.R_W_I[:, 0].tolist())
        # w1: measured, for the logs' achieved rate
        # the measured attitude by rows and rates: the prediction and the adapter use scalars
        R_m, rates_m = est.R_B_N.tolist(), est.rates_frd.tolist()
        vl, R_B_N, w1l, s_law, tgt_law, tau = self._predicted(est, tgt, w1, R_m, rates_m)
        delay_comp = self.setup.delay_compensation
        hold = self.period_s if delay_comp else 0.0  # for the adapter's roll loop
        self.tau_s = tau
        gains = self.gains
        if delay_comp:
            a = look_ahead(gains.alpha, gains.K_R, vs.airspeed, self.delay.delay_s, self.period_s)
            if a > gains.alpha:
                gains = Gains(gains.K_p, gains.K_R, a)
        self.alpha_m = gains.alpha
        law = self.cfg_law
        cmd, diag_law = guidance_law(law, s_law, vl, tgt_law, self.path, gains, self.ext, True)
        assert diag_law is not None
        if self.capture is not None:  # far from the path: bounded sdot, bank, flight path
            cmd, diag_law = self.capture.apply(cmd, diag_law, vl, tgt_law, gains.K_p)
        self.law_evals += 1
        hook = self.airspeed_hook
        v_sp = None if hook is None else hook(t, self.s, self.sdot_prev, vl, tgt_law)
        sp, self.ad_state = adapt(
            cmd.omega_w1_I, vl.airspeed, R_B_N, w1l, dt, self.ad_params, self.ad_state,
            meas=(R_m, rates_m), hold_s=hold, path_down_m=diag_law.p_f[2], airspeed_sp=v_sp,
        )  # fmt: skip
        if not math.isfinite(cmd.sdot):
            sp = safe_setpoint(self.ad_params)
        if self.rates_pipeline:
            self.delay.sent_rates(t, sp.body_rates_frd, est.t_boot_s)
        self.t_prev = t
        self.instants.stepped(est.t_boot_s)
        self.sdot_prev = cmd.sdot if math.isfinite(cmd.sdot) else 0.0
        w1_prev, self.w1_prev = self.w1_prev, w1
        tb_ms = int(round(est.t_boot_s * 1000.0))
        self.why_not = ""  # a step was made: nothing is missing now
        if not tau > 0.0:
            return Step(t, est.t_boot_s, tb_ms, dt, est, tgt_law, cmd, diag_law, sp, w1, w1_prev)
        # The logs describe the sample's own instant (errors, frames, the relative position:
        # replay and the SIL truth align on them); the command and its saturation flag are
        # the predicted evaluation's, which is what was sent.
        diag, errors = diagnostics_at_sample(
            self.cfg_law, self.path, self.ext, self.s, vs, tgt, gains, diag_law.mode
        )
        return Step(t, est.t_boot_s, tb_ms, dt, est, tgt, cmd, diag, sp, w1, w1_prev, errors)

    def _advance(self, dt: float) -> None:
        """s over the dt (s) since the previous step, and the step period (how long a setpoint
        is held: the ATTITUDE period, or shorter with position instants), filtered over ~10
        steps (gaps excluded)."""
        self.s += self.sdot_prev * dt
        if dt < 1.0:
            T = self.period_s
            self.period_s = dt if T == 0.0 else T + 0.1 * (dt - T)

    def _predicted(
        self,
        est: Estimate,
        tgt: TargetState | Callable[[], TargetState],
        w1: tuple[float, float, float],
        R_m: Any,
        rates_m: Any,
    ) -> tuple[VehicleState, Any, tuple[float, float, float], float, TargetState, float]:
        """(vehicle state, R_B_N by rows, w1 (NED), s, target, horizon tau s) the law acts
        on: predicted tau ahead with delay compensation (the rates in flight, the target there,
        s moved on by sdot), else those of the sample (``w1``, ``R_m``, ``rates_m``: the
        sample's, its body rates rad/s; ``tgt`` the target there, or the function that gives
        it)."""
        vs = est.vehicle
        tau = prediction_horizon(self.delay.delay_s) if self.setup.delay_compensation else 0.0
        if not tau > 0.0:
            return vs, R_m, w1, self.s, tgt() if callable(tgt) else tgt, tau
        t = vs.t
        segs = self.delay.segments(t, tau, rates_m, self.ad_state.q_bias)
        vl, R_B_N, w1l = predict_rows(vs, R_m, segs)
        tp = self.target.state(t + tau)
        if isinstance(tp, str):  # placed now but not then: the sample's
            tp = tgt() if callable(tgt) else tgt
        s_law = self.s + self.sdot_prev * tau
        return vl, R_B_N, w1l, s_law, tp, tau

    def roll(self) -> float:
        """Roll (rad) of the latest ATTITUDE, 0 without one (for the wings-level setpoint)."""
        a = self.est.att
        if a is None:
            return 0.0
        R = a.R_B_N
        return math.atan2(R[2][1], R[2][2])


def mission_time_at(est: Estimator, rx: float | None) -> float | None:
    """The vehicle's mission time (s) at receive time rx (s): the autopilot time of the
    most recently received time-stamped sample (ATTITUDE or LOCAL_POSITION_NED) plus the
    receive time since. The most recent one: with ATTITUDE at 10 Hz and the position at
    50 Hz, the ATTITUDE is up to 80 ms old, and under a lockstep clock the receive times do
    not advance with the vehicle's (a target sample was stamped that much too early: 0.15 m
    at the demo boat's 3 m/s)."""
    if est.att is None or rx is None or est.att_rx is None:
        return None
    tb, trx = est.att.t_boot_s, est.att_rx
    loc, lrx = est.local, est.local_rx
    if loc is not None and lrx is not None and lrx > trx and loc.t_boot_s > tb:
        tb, trx = loc.t_boot_s, lrx
    return tb + (rx - trx) - est.t0


def thrust_flown(est: Estimator) -> float | None:
    """The thrust (0..1) the autopilot reports now (VFR_HUD.throttle), None when unknown:
    at engagement the energy control starts from it, so that its first set-point is no step
    (PX4 SIH flies ~0.8 in AUTO.LOITER where a configured trim of 0.5 lost ~5 m in 8 s)."""
    vfr = getattr(est, "vfr", None)
    thr = getattr(vfr, "throttle_frac", None)
    if thr is None or not math.isfinite(thr) or not 0.0 <= thr <= 1.0:
        return None
    return float(thr)


def measured_inputs(ctl: Controller) -> Any:
    """What the autopilot reports now for the pre-engage checks
    (:class:`~mpf_mavlink.bridge.preflight.MeasuredInputs`): the estimator's wind with its
    source (and WIND_COV's variance), VFR_HUD's airspeed as true airspeed, and the live
    target's estimated motion at mission time 0 as a constant-turn target. None without a
    state. Call after :meth:`Controller.set_origin`."""
    from mpf_mavlink.bridge.estimator import eas_to_tas
    from mpf_mavlink.bridge.preflight import MeasuredInputs
    from mpf_mavlink.config.schema import TargetConfig

    est, _ = ctl.est.estimate()
    if est is None:
        return None
    wn, we, wd = (float(x) for x in est.vehicle.wind)
    var = None
    w = ctl.est.wind
    if est.wind_source == "WIND_COV" and w is not None:
        var = getattr(w, "var_horiz_m2_s2", None)
    airspeed = None
    vfr = ctl.est.vfr
    if vfr is not None and math.isfinite(float(vfr.airspeed_m_s)):
        airspeed = float(vfr.airspeed_m_s)
        if ctl.est.p.airspeed_is_eas:
            airspeed *= eas_to_tas(float(vfr.alt_amsl_m))
    target = None
    if ctl.live:
        st = ctl.target.state(0.0)
        if not isinstance(st, str):
            target = target_as_constant_turn(st, TargetConfig)
    return MeasuredInputs((wn, we, wd), est.wind_source, var, airspeed, target)


def diagnostics_at_sample(
    law: str,
    path: Any,
    ext: Any,
    s: float,
    vs: VehicleState,
    tgt: TargetState | Callable[[], TargetState],
    gains: Any,
    mode: str,
) -> tuple[Callable[[], MpfDiagnostics], Callable[[], MpfErrors] | None]:
    """The diagnostics of the law at the sample's own instant, and their rows' part
    (:func:`mpf_errors`; None for a baseline law), each when asked for; ``mode`` the
    flown evaluation's."""

    def diag() -> MpfDiagnostics:
        _, dm = guidance_law(law, s, vs, tgt() if callable(tgt) else tgt, path, gains, ext)
        assert dm is not None
        # dm._replace(mode=mode) without its keyword machinery (~1 us a recorded row)
        fields = list(dm)
        fields[_MODE] = mode
        return tuple.__new__(MpfDiagnostics, fields)

    if law != "mpf":
        return diag, None

    def errors() -> MpfErrors:
        return mpf_errors(s, vs, tgt() if callable(tgt) else tgt, path, gains, ext, mode)

    return diag, errors
