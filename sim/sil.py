"""Software-in-the-loop runs: the simulated vehicle and the bridge as two MAVLink peers.

:func:`run_sil` is what ``mpf-mavlink sim CONFIG`` does when ``sil.link: udp``: the vehicle
(:class:`sim.vehicle.vehicle.SimVehicle`: the JSBSim aircraft or the kinematic plant, the simulated
autopilot, PX4 or ArduPlane rules) and the bridge (:func:`mpf_mavlink.bridge.live.run_bridge`, the
same code that flies a real autopilot) run in two processes - two interpreters, so neither
waits for the other's GIL - and talk MAVLink over UDP loopback (the vehicle sends to the
bridge's ``udpin`` port, as PX4 SITL does to an offboard API). This process watches, shows the
progress, and then measures the tracking on the plant's TRUTH.

Truth metrics: the MPF error is ``pt = p - p_f(s)`` with the virtual point ``s`` the bridge
actually flew (its ``timeseries.csv``), the TRUE vehicle position and the TRUE target, i.e. the
paper's error, including what the bridge's estimates (telemetry, live target) get wrong. The
closest point of the moving path would hide the along-track part of the error that the law's
``sdot`` is there to remove, so it is reported only as ``steady_rms_cross_track_m``. The bridge's
mission clock (autopilot boot time minus its start) is matched to the vehicle's by the
positions the bridge logged, which are the vehicle's LOCAL_POSITION_NED of the same instant.

Run directory: ``timeseries.csv`` / ``metrics.json`` / plots from the truth (``t`` = seconds
since the bridge took control), ``truth.csv`` (the plant at telemetry rate) and ``bridge/``: the
bridge's own run directory with ``mavlink.tlog`` (both directions), what the law saw, the
setpoints.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import multiprocessing
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mpf_mavlink.bridge.envelope import verdict_words
from mpf_mavlink.bridge.recording import LEAN_ROW_EVERY, is_lean
from mpf_mavlink.config.scenario import build_path, build_target
from mpf_mavlink.config.schema import Config
from mpf_mavlink.core.paths import TabulatedPath
from mpf_mavlink.errors import ConfigError
from mpf_mavlink.mavlink.url import free_udp_port
from mpf_mavlink.runs.rundir import (
    RunTable,
    compute_metrics,
    prepare_out_dir,
    read_run,
)
from mpf_mavlink.runs.verdict import Verdict, assess
from mpf_mavlink.runs.write import write_limits, write_run
from sim.sil_progress import _Progress
from sim.sil_truth import truth_table
from sim.vehicle.config import VehicleConfig

# custom modes in which the bridge commands the vehicle (PX4 OFFBOARD, ArduPlane GUIDED)
_ENGAGED_MODES = ("OFFBOARD", "GUIDED")
# MPF_SIL_PROFILE=DIR: each peer process writes cProfile statistics to DIR/{vehicle,bridge}.prof
_PROFILE_ENV = "MPF_SIL_PROFILE"


def _profiled(name: str, fn: Any, *args: Any) -> None:
    d = os.environ.get(_PROFILE_ENV)
    if not d:
        fn(*args)
        return
    import cProfile

    pr = cProfile.Profile()
    pr.enable()
    try:
        fn(*args)
    finally:
        pr.disable()
        Path(d).mkdir(parents=True, exist_ok=True)
        pr.dump_stats(str(Path(d) / f"{name}.prof"))


def _vehicle_main(*args: Any) -> None:
    _profiled("vehicle", _vehicle_run, *args)


def _bridge_main(*args: Any) -> None:
    _profiled("bridge", _bridge_run, *args)


# --------------------------------------------------------------------------- the vehicle
def _start_altitude_m(cfg: Config) -> float:
    """Altitude (m MSL) where the vehicle starts: home altitude less the initial down position."""
    sil, k = cfg.section("sil"), cfg.kinematic
    pos = (
        sil.initial_position_ned_m
        if sil.initial_position_ned_m is not None
        else k.initial_position_ned_m
    )
    return float(sil.home_alt_m - pos[2])


@functools.lru_cache(maxsize=8)
def _identify(model: str, root: str | None, v: float, alt: float, controls: tuple[Any, ...]) -> Any:
    from sim.plant.airframe_ident import identify

    return identify(model, root, v, alt, dict(controls))


def identified(cfg: Config) -> Any:
    """The identification of the config's aircraft (sim.plant.airframe_ident.AirframeModel) when
    ``aircraft.gains_from_fdm`` asks for it (JSBSim plant), else None. Errors are ValueErrors
    naming the config key."""
    ac = cfg.section("aircraft")
    if not (ac.gains_from_fdm and cfg.section("sil").plant == "jsbsim"):
        return None
    root = ac.resolved_root(cfg.source)
    controls = tuple(sorted(ac.controls.mapping().items()))
    return _identify(
        ac.model,
        None if root is None else str(root),
        ac.trim_airspeed_m_s,
        _start_altitude_m(cfg),
        controls,
    )


def trim_of(cfg: Config) -> tuple[float, float | None]:
    """(throttle, hold pitch trim rad or None) of the config's aircraft at its trim airspeed.

    ``aircraft.trim_from_fdm``: JSBSim's own trim of level flight decides both (an aircraft it
    cannot trim at that speed is a one-line error naming the key); otherwise the config's.
    """
    ac = cfg.section("aircraft")
    ident = identified(cfg)
    if ident is not None:
        return ident.trim["throttle"], ident.pitch_rad
    if not (ac.trim_from_fdm and cfg.section("sil").plant == "jsbsim"):
        return ac.trim_throttle, ac.attitude_loop.pitch_trim_rad
    from sim.plant.airframe_trim import fdm_trim

    root = ac.resolved_root(cfg.source)
    tr = fdm_trim(ac.model, root, ac.trim_airspeed_m_s, _start_altitude_m(cfg))
    if not tr.ok:
        raise ValueError(
            f"aircraft.trim_airspeed_m_s: JSBSim finds no level-flight trim of {ac.model} at "
            f"{ac.trim_airspeed_m_s:g} m/s (python -m sim.plant.airframe_trim {ac.model} lists its "
            "range)"
        )
    return tr.throttle, tr.pitch_rad


def build_autopilot(cfg: Config) -> Any:
    """The simulated autopilot for the config's aircraft (rate loops, attitude loop, hold)."""
    from sim.autopilot.inner_loop import AttitudeGains, FixedWingAutopilot, HoldGains, RateLoopGains

    ac, sil = cfg.section("aircraft"), cfg.section("sil")
    base = RateLoopGains()
    ident = identified(cfg)
    if ident is not None:
        from sim.plant.airframe_ident import derive_gains, trims

        al0 = ac.attitude_loop
        derived = derive_gains(
            ident,
            roll_tc_s=al0.roll_tc_s or AttitudeGains().roll_tc,
            pitch_tc_s=al0.pitch_tc_s or AttitudeGains().pitch_tc,
        )
        base = dataclasses.replace(base, **derived, **trims(ident))
    over = {k: v for k, v in dataclasses.asdict(ac.rate_loop).items() if v is not None}
    v_trim = ac.trim_airspeed_m_s
    trim_throttle, pitch_trim = trim_of(cfg)
    # The rate loops' airspeed scaling is s = V_trim / V, limited below by V_min: defaults keep
    # the X8's margins (10 / 16 / 22 m/s) in proportion for another trim airspeed.
    gains = dataclasses.replace(
        base,
        **over,
        trim_throttle=trim_throttle,
        airspeed_trim=v_trim,
        airspeed_min=ac.airspeed_min_m_s or v_trim * base.airspeed_min / base.airspeed_trim,
        airspeed_max=ac.airspeed_max_m_s or v_trim * base.airspeed_max / base.airspeed_trim,
    )
    al = ac.attitude_loop
    att = AttitudeGains()
    att_over = {
        "roll_tc": al.roll_tc_s,
        "pitch_tc": al.pitch_tc_s,
        "roll_rate_max": al.roll_rate_max_rad_s,
        "pitch_rate_max": al.pitch_rate_max_rad_s,
        "yaw_rate_max": al.yaw_rate_max_rad_s,
        "bank_max": al.bank_max_rad,
    }
    att = dataclasses.replace(
        att, airspeed_min=gains.airspeed_min, **{k: v for k, v in att_over.items() if v is not None}
    )
    hold = HoldGains(loiter_radius=sil.loiter_radius_m)
    if pitch_trim is not None:
        hold = dataclasses.replace(hold, pitch_trim=pitch_trim)
    if al.bank_max_rad is not None:
        hold = dataclasses.replace(hold, bank_max=al.bank_max_rad)
    return FixedWingAutopilot(gains, att, hold)


_SAME_NAMES = (
    "flavour", "plant", "target_system", "target_rate_hz", "target_type", "physics_rate_hz",
    "telemetry_latency_s", "command_latency_s", "wind_estimate_tau_s", "answer_timeout_s",
    "lockstep_spin_s", "realtime_speed", "initial_mode", "turbulence", "wind_turbulence_m_s",
    "seed",
)  # fmt: skip


def vehicle_config(cfg: Config, url: str, clock: str | None = None, **over: Any) -> VehicleConfig:
    """The :class:`sim.vehicle.config.VehicleConfig` of a config's SIL vehicle (``over`` wins)."""
    sil, ac, k = cfg.section("sil"), cfg.section("aircraft"), cfg.kinematic
    pos = (
        sil.initial_position_ned_m
        if sil.initial_position_ned_m is not None
        else k.initial_position_ned_m
    )
    heading = (
        sil.initial_heading_rad
        if sil.initial_heading_rad is not None
        else k.initial_attitude_rpy_rad[2]
    )
    tel = sil.telemetry
    rates = {f.name[: -len("_hz")]: getattr(tel, f.name) for f in dataclasses.fields(tel)}
    plant_options: dict[str, Any] = {}
    if sil.plant == "jsbsim":
        root = ac.resolved_root(cfg.source)
        plant_options = {
            "model": ac.model,
            "controls": ac.controls.mapping(),
            "throttle": trim_of(cfg)[0],
        }
        if root is not None:
            plant_options["root_dir"] = str(root)
    # the fields the two sections name alike; the rest are renamed or derived below
    opts: dict[str, Any] = {n: getattr(sil, n) for n in _SAME_NAMES}
    opts.update(
        url=url,
        clock=clock or sil.clock,
        position_ned=tuple(pos),
        heading=float(heading),
        airspeed=ac.trim_airspeed_m_s,
        lat0_deg=sil.home_lat_deg,
        lon0_deg=sil.home_lon_deg,
        alt0_m=sil.home_alt_m,
        target=build_target(cfg.target),
        rates=rates,
        frame_period=sil.frame_period_s,
        com_of_loss_t=sil.offboard_loss_timeout_s,
        guided_timeout=sil.guided_timeout_s,
        loiter_radius=sil.loiter_radius_m,
        trim_seconds=sil.trim_s,
        wind_ned=tuple(sil.wind_ned_m_s),
        gusts=[dataclasses.asdict(g) for g in sil.gusts],
        plant_options=plant_options,
        autopilot=build_autopilot(cfg),
        # lockstep: the bridge answers every frame in every phase (mavlink.lockstep), so the
        # hand-over runs on vehicle time too; a realtime clock ignores this
        lockstep_from_connect=True,
        # the bridge's own scripted target counts from its mission origin: so must the world's
        target_epoch="ready" if sil.target_live else "bridge",
        target_feed=None if sil.target_feed is None else dataclasses.asdict(sil.target_feed),
    )
    opts.update(_fleet_epoch(cfg, clock or sil.clock))
    opts.update(over)
    return VehicleConfig(**opts)


def _fleet_epoch(cfg: Config, clock: str) -> dict[str, Any]:
    """A fleet's common target epoch for the world's target (a realtime SIL fleet: every
    member's bridge counts its scripted target from ``fleet.target_epoch_unix_s``)."""
    f = cfg.section("fleet")
    if not (f.enabled and f.target_epoch_unix_s is not None and not cfg.section("sil").target_live):
        return {}
    if clock != "realtime":
        raise ConfigError(
            f"{cfg.source}: fleet.target_epoch_unix_s: a SIL fleet needs sil.clock: realtime"
        )
    return {"target_epoch": "unix", "target_epoch_unix_s": float(f.target_epoch_unix_s)}


def build_vehicle(cfg: Config, url: str, clock: str | None = None, **over: Any) -> Any:
    """The config's simulated vehicle on ``url`` (trimmed, in the hold mode, ready to serve)."""
    from sim.vehicle.vehicle import SimVehicle, use_profile

    vc = vehicle_config(cfg, url, clock, **over)
    v = SimVehicle(vc)
    sil = cfg.section("sil")
    res = sil.profile(cfg.source)
    if res is not None:
        prof = res.profile
        full = None
        if prof.thrust.full_thrust_airspeed_m_s is not None and sil.plant == "jsbsim":
            full = full_thrust_throttle(cfg, vc, prof.thrust.full_thrust_airspeed_m_s)
        use_profile(v, prof, seed=sil.seed, full_thrust_throttle=full)
    return v


def full_thrust_throttle(cfg: Config, vc: VehicleConfig, airspeed: float) -> float:
    """The plant's level-flight throttle at ``airspeed`` (m/s), found by flying it (a trim flight
    of a second plant at the start altitude): what the profile's full offboard thrust maps to."""
    from sim.autopilot.inner_loop import fly_to_trim
    from sim.plant.jsbsim_plant import JSBSimPlant
    from sim.vehicle.vehicle import plant_kwargs

    alt = -float(vc.position_ned[2])
    plant = JSBSimPlant(**plant_kwargs(vc, (0.0, 0.0, -alt), 0.0, airspeed))
    res = fly_to_trim(plant, build_autopilot(cfg), airspeed, alt, seconds=20.0, apply=False)
    return float(res.throttle)


def bridge_config(cfg: Config, **mavlink: Any) -> Config:
    """The bridge's view of a SIL config: flavour from ``sil``, the live target when asked;
    ``mavlink`` overrides entries of its mavlink section."""
    sil = cfg.section("sil")
    m = dataclasses.replace(cfg.section("mavlink"), flavour=sil.flavour, **mavlink)
    target = cfg.target
    if sil.target_live:
        target = dataclasses.replace(cfg.target, type="mavlink")
        m = dataclasses.replace(m, target_sysid=sil.target_system)
    extra = dict(cfg.extra, mavlink=m)
    return dataclasses.replace(cfg, target=target, extra=extra)


# --------------------------------------------------------------------------- processes
def _vehicle_run(
    cfg: Config,
    url: str,
    clock: str | None,
    conn: Any,
    stop: Any,
    status: Any,
    parent: int,
    over: dict[str, Any],
) -> None:
    """Child process: build the vehicle, run it until ``stop`` (or the parent is gone), then send
    its truth. Ctrl-C is ignored here: the bridge must be able to hand back to a live vehicle."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        v = build_vehicle(cfg, url, clock, **over)
    except Exception as e:  # noqa: BLE001 - reported to the parent as one line
        conn.send(("error", f"{type(e).__name__}: {e}"))
        return
    conn.send(
        (
            "ready",
            {
                "trim": dataclasses.asdict(v.trim) if v.trim is not None else None,
                "mode": v.mode_name,
            },
        )
    )

    def watch() -> None:
        spin = getattr(v.clock, "spin_cpu_s", None) is not None
        while not stop.wait(0.05):
            status[0] = v.t
            if spin:
                status[1] = v.clock.spin_cpu_s
            if os.getppid() != parent:  # orphaned (parent killed): do not run forever
                break
        v._stop.set()

    threading.Thread(target=watch, daemon=True).start()
    try:
        v.run(math.inf)
    finally:
        info = {
            "mode_log": v.modes.log,
            "statustexts": v.link.statustexts,
            "dropped": v.autopilot.setpoints.dropped,
            "answers": v.lockstep.answers,
            "frames": v.clock.frames if hasattr(v.clock, "frames") else None,
            "answered_frames": getattr(v.clock, "answered_frames", None),
            "lockstep_timeouts": getattr(v.clock, "timeouts", None),
            "lockstep_overlapped": v.lockstep.overlapped,
            "sim_time_s": v.t,
            "wall_time_s": v.wall_time_running,
            "flavour": v.flavour,
        }
        conn.send(("truth", v.truth(), info))
        v.close()


def _bridge_run(
    cfg: Config, url: str, out: str, duration: float, q: Any, force: bool = False
) -> None:
    """Child process: fly the bridge; results and log lines go to ``q``."""
    from mpf_mavlink.bridge.base import BridgeOptions
    from mpf_mavlink.bridge.live import run_bridge
    from mpf_mavlink.bridge.preflight import simulated_plant
    from mpf_mavlink.errors import MpfError

    def on_int(signum: int, frame: Any) -> None:
        # the first Ctrl-C hands back; more (the parent forwards one) must not abort that
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, on_int)
    try:
        res = run_bridge(
            cfg,
            BridgeOptions(
                url=url,
                out_dir=Path(out),
                duration_s=duration,
                force=force,
                plant=simulated_plant(cfg),
            ),  # fmt: skip
            log=lambda s: q.put(("log", s)),
        )
        q.put(("result", res))
    except MpfError as e:
        q.put(("error", str(e)))
    except KeyboardInterrupt:
        q.put(("error", "interrupted before the bridge was flying"))
    except Exception as e:  # noqa: BLE001 - the parent reports it
        q.put(("error", f"{type(e).__name__}: {e}"))


@dataclass
class SilResult:
    """A SIL run: the truth table and metrics, where things are, what the bridge said."""

    cols: dict[str, np.ndarray]
    metrics: dict[str, Any]
    path_T: np.ndarray
    out_dir: Path
    bridge_dir: Path
    tlog: Path
    exit_code: int
    exit_reason: str
    truth: dict[str, np.ndarray] = field(default_factory=dict)
    bridge: Any = None
    t_vehicle: np.ndarray = field(
        default_factory=lambda: np.zeros(0)
    )  # vehicle time of each row (s)


def _context() -> Any:
    # fork: the children start at once without re-importing numpy/scipy/pymavlink (nothing here
    # holds threads or JSBSim before the fork); spawn where fork is unsafe (macOS, Windows).
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context(
        "fork" if sys.platform.startswith("linux") and "fork" in methods else "spawn"
    )


def run_sil(
    cfg: Config,
    out: str | Path,
    *,
    progress: bool = True,
    plots: bool = True,
    clock: str | None = None,
    duration_s: float | None = None,
    log: Any = print,
    force: bool = False,
    vehicle: dict[str, Any] | None = None,
) -> SilResult:
    """Fly the config's mission with the SIL vehicle and the bridge over UDP loopback.

    ``duration_s`` (default ``sim.duration_s``): seconds of tracking, after the bridge has taken
    control; ``clock`` overrides ``sil.clock``; ``vehicle``: :class:`VehicleConfig` fields that
    win over the config's (e.g. ``{"lockstep_overlap": False}``). Raises MpfError when a peer
    fails to start and KeyboardInterrupt after a Ctrl-C (once the bridge has handed back and the
    records are written).
    """
    from mpf_mavlink.errors import MpfError

    out = prepare_out_dir(out)
    bridge_dir = out / "bridge"
    sil = cfg.section("sil")
    duration = float(duration_s if duration_s is not None else cfg.sim.duration_s)
    port = sil.port or free_udp_port()
    # in lockstep the bridge's timeouts count the vehicle's time: a simulation slowed down by
    # a loaded host is not a lost link (mavlink.lockstep)
    bcfg = bridge_config(cfg, plots=plots, lockstep=(clock or sil.clock) == "lockstep")
    wall0 = time.perf_counter()
    pb, pv, rx, stop, status, q = _start_peers(
        cfg, bcfg, port, bridge_dir, duration, clock, force, vehicle or {}
    )
    bar = _Progress(duration, progress, log, (pv.pid, pb.pid), lambda: status[1])
    bres: Any = None
    berr: str | None = None
    interrupted = False
    truth_msg: Any = None
    try:
        try:
            _await_vehicle(rx, bar, f"{sil.plant}, {sil.flavour}, {clock or sil.clock} clock")
            # what the figures after the flight need (~0.3 s), loaded now while the hand-over
            # paces at real time and this process only waits
            import scipy.spatial  # noqa: F401

            bres, berr = _await_bridge(q, pb, bar, status)
        except KeyboardInterrupt:
            interrupted = True
            bar.note("interrupted: the bridge hands back, then the records are written")
            bres, berr = _hand_back(q, pb)
        stop.set()
        if rx.poll(60.0):
            truth_msg = rx.recv()
    finally:
        stop.set()
        bar.close()
        for p in (pb, pv):
            p.join(10.0)
            if p.is_alive():
                p.terminate()
                p.join(5.0)
    wall = time.perf_counter() - wall0
    _write_bridge_config(bridge_dir, bcfg)
    if bres is None:
        if interrupted:
            raise KeyboardInterrupt
        raise MpfError(f"SIL run failed: {berr or 'no result from the bridge'}")
    if truth_msg is None or truth_msg[0] != "truth":
        raise MpfError("SIL run failed: the vehicle sent no truth")
    truth, vinfo = truth_msg[1], truth_msg[2]
    res = _measure(cfg, truth, vinfo, bres, bridge_dir, wall)
    res.metrics.update(_cpu_per_frame(bar, sil.frame_period_s))
    res.metrics["clock"] = clock or sil.clock
    res.out_dir = out
    _write(out, res, truth, plots, LEAN_ROW_EVERY if is_lean(cfg.section("mavlink")) else 1)
    if interrupted:
        raise KeyboardInterrupt
    return res


def _await_vehicle(rx: Any, bar: _Progress, what: str) -> None:
    """Wait (up to 120 s) for the SIL vehicle's "ready" on ``rx`` and note it (``what``: its
    plant, flavour and clock); MpfError when it does not come."""
    from mpf_mavlink.errors import MpfError

    ready = rx.poll(120.0) and rx.recv()
    if not ready or ready[0] != "ready":
        raise MpfError(
            f"the SIL vehicle did not start: {ready[1] if ready else 'no answer in 120 s'}"
        )
    bar.note(f"vehicle ready ({what}) in {ready[1]['mode']}")


def _start_peers(
    cfg: Config,
    bcfg: Config,
    port: int,
    bridge_dir: Path,
    duration: float,
    clock: str | None,
    force: bool,
    over: dict[str, Any],
) -> tuple[Any, ...]:
    """The bridge (listening on ``port``) and the vehicle, each a process of its own: (bridge,
    vehicle, the vehicle's pipe, the stop event, the vehicle's sim time, the bridge's queue)."""
    ctx = _context()
    rx, tx = ctx.Pipe(duplex=False)
    stop = ctx.Event()
    status = ctx.RawArray("d", 2)  # the vehicle's sim time (s), its CPU time spent spinning (s)
    q = ctx.Queue()
    pb = ctx.Process(
        target=_bridge_main,
        name="mpf-bridge",
        daemon=True,
        args=(bcfg, f"udpin:127.0.0.1:{port}", str(bridge_dir), duration, q, force),
    )
    pv = ctx.Process(
        target=_vehicle_main,
        name="mpf-sil-vehicle",
        daemon=True,
        args=(cfg, f"udpout:127.0.0.1:{port}", clock, tx, stop, status, os.getpid(), over),
    )
    pb.start()
    pv.start()
    tx.close()
    return pb, pv, rx, stop, status, q


def _await_bridge(q: Any, pb: Any, bar: Any, status: Any) -> tuple[Any, str | None]:
    """The bridge's result or error, relaying its log lines to the progress bar meanwhile."""
    while True:
        try:
            kind, payload = q.get(timeout=0.25)
        except Exception:  # noqa: BLE001 - queue.Empty
            if not pb.is_alive() and q.empty():
                return None, f"the bridge process exited (code {pb.exitcode})"
            bar.update(status[0])
            continue
        if kind == "log":
            bar.event(payload, status[0])
        elif kind == "result":
            return payload, None
        else:
            return None, payload


def _hand_back(q: Any, pb: Any) -> tuple[Any, str | None]:
    """After a Ctrl-C: the bridge hands back (20 s at most), its result or error."""
    if pb.is_alive():
        os.kill(pb.pid, signal.SIGINT)  # in case the Ctrl-C came only to this process
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline:
        try:
            kind, payload = q.get(timeout=0.5)
        except Exception:  # noqa: BLE001
            if not pb.is_alive():
                break
            continue
        if kind == "result":
            return payload, None
        if kind == "error":
            return None, payload
    return None, None


def _cpu_per_frame(bar: Any, frame_period_s: float) -> dict[str, float]:
    """CPU time (us) of each peer per frame while tracking, when the progress bar took it."""
    if None in bar.cpu0 + bar.cpu1 or bar.t_end is None or bar.t_track is None:
        return {}
    frames = max(1.0, (bar.t_end - bar.t_track) / frame_period_s)
    out = {
        f"cpu_us_per_frame_{who}": (bar.cpu1[i] - bar.cpu0[i]) / frames * 1e6
        for i, who in enumerate(("vehicle", "bridge"))
    }
    # the vehicle's lockstep spin (sil.lockstep_spin_s) is waiting: its work is the rest
    spin = (bar.spin1 - bar.spin0) / frames * 1e6
    out["cpu_us_per_frame_vehicle_spin"] = spin
    out["cpu_us_per_frame_vehicle_work"] = out["cpu_us_per_frame_vehicle"] - spin
    return out


def _measure(
    cfg: Config,
    truth: dict[str, np.ndarray],
    vinfo: dict[str, Any],
    bres: Any,
    bridge_dir: Path,
    wall: float,
) -> SilResult:
    from mpf_mavlink.errors import MpfError

    try:
        bc, _, _ = read_run(bridge_dir)
    except MpfError:
        bc = {"t": np.zeros(0)}
    path = build_path(cfg.path)
    vd: Verdict | None = None
    if len(bc["t"]) < 2:
        cols = RunTable().arrays()
        metrics: dict[str, Any] = compute_metrics(
            cols, cfg.metrics.steady_after_s, cfg.metrics.converge_threshold_m
        )
        info: dict[str, Any] = {}
    else:
        cols, metrics, info, vd = _judge_truth(cfg, truth, bc, bres.metrics, path)
    # real-time factor while the bridge was in control (the lockstep figure) and overall
    ml = vinfo["mode_log"]
    rtf_track = _tracking_rtf(ml, float(vinfo["sim_time_s"]))
    sim_total = float(vinfo["sim_time_s"])
    metrics.update(
        sim_time_s=float(cols["t"][-1]) if len(cols["t"]) else 0.0,
        wall_time_s=wall,
        vehicle_sim_time_s=sim_total,
        real_time_factor_tracking=rtf_track,
        real_time_factor_overall=sim_total / wall if wall > 0 else None,
        plant=cfg.section("sil").plant,
        flavour=cfg.section("sil").flavour,
        autopilot_profile=_profile_label(cfg),
        bridge_exit_code=bres.exit_code,
        bridge_exit_reason=bres.exit_reason,
        bridge_state_reached=bres.state_reached,
        handback_confirmed=bres.handback_confirmed,
        vehicle_answered_frames=vinfo.get("answered_frames"),
        vehicle_frames=vinfo.get("frames"),
        vehicle_lockstep_timeouts=vinfo.get("lockstep_timeouts"),
        vehicle_lockstep_overlapped=vinfo.get("lockstep_overlapped"),
        statustexts=[t for _, t in vinfo["statustexts"]],
        vehicle_modes=[[round(t, 3), name] for t, _, name in ml],
    )
    # The truth's verdict decides a run that otherwise ended normally (the bridge's own, on its
    # estimates, is in bridge/metrics.json); any other exit of the bridge stands.
    code = vd.exit_code(bres.exit_code) if vd is not None else bres.exit_code
    metrics["exit_code"] = code
    return SilResult(cols, metrics, path.positions(), Path("."), bridge_dir,
                     bridge_dir / "mavlink.tlog", code, bres.exit_reason, truth, bres,
                     info.get("t_vehicle", np.zeros(0)))  # fmt: skip


def _judge_truth(
    cfg: Config,
    truth: dict[str, np.ndarray],
    bc: dict[str, np.ndarray],
    bm: dict[str, Any],
    path: TabulatedPath,
) -> tuple[dict[str, np.ndarray], dict[str, Any], dict[str, Any], Verdict]:
    """The plant's truth against the bridge's rows ``bc`` (its metrics ``bm``): the truth's
    table, metrics, alignment info and verdict while the bridge was flying it."""
    cols, info = truth_table(cfg, truth, bc, path)
    metrics = compute_metrics(cols, cfg.metrics.steady_after_s, cfg.metrics.converge_threshold_m)
    m = cols["t"] >= cfg.metrics.steady_after_s
    ct = info["cross_track_m"]
    metrics["steady_rms_cross_track_m"] = float(np.sqrt(np.mean(ct[m] ** 2))) if m.any() else None
    metrics["alignment_residual_m"] = info["alignment_residual_m"]
    metrics["bridge_steady_rms_m"] = bm.get("steady_rms_m")
    metrics["bridge_thrust_saturated_fraction"] = bm.get("thrust_saturated_fraction")
    metrics["bridge_adapter_learned"] = bm.get("adapter_learned")
    sel = info["rows"]
    eul = truth["euler"][sel]
    vd = assess(cfg, cols["t"], cols["pt_norm"], -truth["position_ned"][sel, 2],
                truth["airspeed"][sel], eul[:, 0], eul[:, 1], truth["throttle"][sel],
                source="truth")  # fmt: skip
    # what the bridge's envelope monitor saw the law demand beyond the aircraft's limits
    env = bm.get("envelope")
    metrics["bridge_envelope"] = env
    words = verdict_words(env) if isinstance(env, dict) else ""
    if words:
        vd.notes.append(f"envelope: {words}")
    vd.record(metrics)
    metrics["bridge_verdict"] = bm.get("verdict")
    return cols, metrics, info, vd


def _profile_label(cfg: Config) -> str:
    """Which autopilot profile the SIL flew (metrics.json says it beside the flavour)."""
    res = cfg.section("sil").profile(cfg.source)
    return "none (the plain emulation)" if res is None else res.label


def _tracking_rtf(mode_log: list[Any], sim_end_s: float) -> float | None:
    """Sim seconds per wall second while the bridge was in control (the lockstep figure), from
    the vehicle's mode log of (t, wall s, name)."""
    for i, (t_in, w_in, name) in enumerate(mode_log):
        if name in _ENGAGED_MODES:
            nxt = mode_log[i + 1] if i + 1 < len(mode_log) else None
            t_out, w_out = (nxt[0], nxt[1]) if nxt is not None else (sim_end_s, None)
            if w_out is not None and w_out > w_in:
                return float((t_out - t_in) / (w_out - w_in))
            return None
    return None


def _write_bridge_config(bridge_dir: Path, bcfg: Config) -> None:
    """``bridge/config.yaml``: the configuration the bridge flew with (the SIL's live target is
    ``target.type: mavlink``; no ``sil``/``aircraft`` sections), so that ``mpf-mavlink replay
    --config bridge/config.yaml bridge/mavlink.tlog`` recomputes the commands it sent."""
    import yaml

    from mpf_mavlink.config.schema import config_to_dict

    if not bridge_dir.is_dir():  # the bridge never got to create its run directory
        return
    head = (
        "# The bridge's configuration in this SIL flight (written by mpf-mavlink sim): replay\n"
        "# with  mpf-mavlink replay --config bridge/config.yaml bridge/mavlink.tlog\n"
    )
    body = yaml.safe_dump(config_to_dict(bcfg, omit=("sil", "aircraft")), sort_keys=False)
    (bridge_dir / "config.yaml").write_text(head + body)


def _lean_rows(n: int, every: int) -> np.ndarray:
    """Indices of the rows kept of ``n``: one in ``every`` and the last (the final state)."""
    keep = np.arange(0, n, every)
    return keep if n == 0 or keep[-1] == n - 1 else np.append(keep, n - 1)


def _write(
    out: Path, res: SilResult, truth: dict[str, np.ndarray], plots: bool, every: int = 1
) -> None:
    """The run directory's tables (``every``: one row in that many, the lean recording's; the
    figures in metrics.json are the whole run's either way)."""
    if every > 1:
        truth = {k: v[_lean_rows(len(v), every)] for k, v in truth.items()}
        sel = _lean_rows(len(res.cols["t"]), every)
        res = dataclasses.replace(
            res, cols={k: v[sel] for k, v in res.cols.items()}, t_vehicle=res.t_vehicle[sel]
        )
    tv = res.t_vehicle
    if len(tv) and len(res.cols["t"]) and "euler" in truth:
        # the truth the verdict judged, from the start (t < 0: before engagement) for the plots
        t0 = float(tv[0] - res.cols["t"][0])
        write_limits(
            out,
            np.column_stack(
                [
                    truth["t"] - t0,
                    truth["euler"][:, 0],
                    truth["euler"][:, 1],
                    truth["airspeed"],
                    -truth["position_ned"][:, 2],
                    truth["throttle"],
                ]
            ),
        )
    write_run(out, res.cols, res.metrics, res.path_T, plots=plots and len(res.cols["t"]) >= 2)
    cols = [
        truth["t"],
        truth["time_boot_s"],
        *truth["position_ned"].T,
        *truth["velocity_ned"].T,
        *truth["euler"].T,
        truth["airspeed"],
        *truth["wind_ned"].T,
        truth["throttle"],
        truth["mode"],
    ]
    hdr = (
        "t,time_boot_s,p_n,p_e,p_d,v_n,v_e,v_d,roll,pitch,yaw,airspeed,wind_n,wind_e,wind_d,"
        "throttle,custom_mode"
    )
    np.savetxt(
        out / "truth.csv", np.column_stack(cols), delimiter=",", header=hdr, comments="", fmt="%.9g"
    )
