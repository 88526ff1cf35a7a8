"""The soak campaign's flight scenarios (:mod:`lab.soak`): baseline, fuzzed link, loss and
jitter, corruption, blackouts, target loss, a pilot taking over, autopilot reboots, a SIGKILLed
bridge."""

from __future__ import annotations

import math
import signal
import threading
import time
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as M

from lab.soak.checks import Limits, _r, bridge_silence, max_gap, setpoint_violations
from lab.soak.relay import DOWN, UP, Blackout, Impairment
from lab.soak.rig import (
    TARGET_SYSID,
    VEHICLE_COMPID,
    VEHICLE_SYSID,
    BridgeOutcome,
    Event,
    Mission,
    MissionSpec,
    Opts,
    Row,
    Tap,
)
from mpf_mavlink.mavlink.modes import is_offboard
from mpf_mavlink.runs.verdict import EXIT_NOT_JUDGED

# a soak mission's bridge ran to its end: verdict PASS, or NOT JUDGED when shorter than its
# steady window (the verdict is not what a soak row judges)
FLOWN = (0, EXIT_NOT_JUDGED)


def _mission_common(row: Row, m: Mission, out: BridgeOutcome, lim: Limits | None = None) -> None:
    """Figures every mission row reports, and the invariants every mission must keep."""
    tap = m.tap
    row.figures.update(
        bridge_exit=out.rc,
        exit_reason=out.exit_reason,
        tracked_s=_r(out.metrics.get("tracked_s"), 2),
        setpoints_at_vehicle=len(tap.setpoints),
        vehicle_modes=[f"{t:.1f}:{n}" for t, n in tap.mode_changes()],
    )
    t_on, t_off = _tracking_window(tap)
    # the vehicle's own ATTITUDE stream as it left the vehicle: a gap here is the SIL vehicle
    # (or the machine) stalling, not the link or the bridge
    row.figures["vehicle_attitude_gap_max_s"] = _r(
        max_gap([t for t, _ in tap.attitude_ms], t_on, t_off)
    )
    row.figures["relay_loop_overrun_max_s"] = _r(m.relay.max_loop_gap_s)  # the harness itself late
    row.check(
        "Traceback" not in out.stderr, f"bridge traceback: {out.stderr.strip().splitlines()[-1:]}"
    )
    if lim is not None:
        bad = setpoint_violations(tap, m.spec.flavour, lim)
        row.figures["setpoints_out_of_limits"] = len(bad)
        row.check(not bad, f"{len(bad)} setpoints out of limits, first: {bad[:3]}")


def scenario_baseline(o: Opts) -> Row:
    row = Row("baseline")
    dur = 25.0 if o.quick else 60.0
    spec = MissionSpec.make(o, dur)
    with Mission(spec, o.workdir / "baseline") as m:
        row.check(m.wait_engaged(30.0), "never engaged")
        out = m.finish(dur + 30.0)
    _mission_common(row, m, out, Limits.for_config("px4"))
    mt = out.metrics
    row.figures.update(
        steady_rms_m=_r(mt.get("steady_rms_m")),
        steady_max_m=_r(mt.get("steady_max_m")),
        convergence_time_s=_r(mt.get("convergence_time_s"), 1),
    )
    row.check(
        out.rc in FLOWN and mt.get("handback_confirmed") is True,
        f"exit {out.rc}: {out.exit_reason}",
    )
    return row


def _tracking_ok(row: Row, o: Opts, mt: dict[str, Any]) -> None:
    """The law still tracks: the final |pt| is small, and over a full-length mission the
    steady window (its second half) too. A quick mission is mostly the capture of the error
    that the loiter before engagement left (tens of metres), so only its end is judged."""
    row.figures["final_pt_m"] = _r(mt.get("final_pt_m"))
    row.check(
        (mt.get("final_pt_m") or math.inf) < 10.0,
        f"tracking degraded: final |pt| {mt.get('final_pt_m')}",
    )
    if not o.quick:
        row.check(
            (mt.get("steady_max_m") or math.inf) < 15.0,
            f"tracking degraded: steady max {mt.get('steady_max_m')}",
        )


def _tracking_window(tap: Tap) -> tuple[float | None, float | None]:
    """(first, last) relay time the vehicle reported its offboard mode."""
    t_on = tap.first_offboard_t()
    offs = [e.t for e in tap.heartbeats if is_offboard(tap.flavour, e.msg)]
    return t_on, (offs[-1] if offs else None)


def scenario_fuzz(o: Opts, n_frames: int | None = None, dur: float | None = None) -> Row:
    """>= 100,000 random and mutated frames into the bridge's link during a mission."""
    from lab.soak.mavfuzz import FrameFuzzer

    row = Row("fuzz")
    n_frames = n_frames or (12_000 if o.quick else 100_000)
    dur = dur or (14.0 if o.quick else 60.0)
    spec = MissionSpec.make(o, dur)
    stop = threading.Event()
    with Mission(spec, o.workdir / "fuzz") as m:
        fz = FrameFuzzer(o.seed, (VEHICLE_SYSID, VEHICLE_COMPID), now_ms=m.tap.vehicle_ms)
        sent = {"frames": 0, "datagrams": 0}

        def inject() -> None:
            # from the bridge's start (its HEARTBEAT wait, checks and pre-stream are part of the
            # mission) to 2 s before the end of TRACKING, which begins ~4 s after the start
            rate, t0 = n_frames / (dur + 2.0), time.monotonic()
            while sent["frames"] < n_frames and not stop.is_set():
                due = int((time.monotonic() - t0) * rate) - sent["frames"]
                if due <= 0:
                    time.sleep(0.004)
                    continue
                while due > 0 and sent["frames"] < n_frames:
                    k, data = fz.datagram()
                    m.relay.inject(DOWN, data)
                    sent["frames"] += k
                    sent["datagrams"] += 1
                    due -= k

        th = threading.Thread(target=inject, daemon=True)
        th.start()
        row.check(m.wait_engaged(30.0), "never engaged")
        out = m.finish(dur + 40.0)
        stop.set()
        th.join(5.0)
    _mission_common(row, m, out, Limits.for_config("px4"))
    tap, c, mt = m.tap, out.counters, out.metrics
    t_on, t_off = _tracking_window(tap)
    gap = max_gap([e.t for e in tap.setpoints], t_on, t_off)
    row.figures.update(
        frames_injected=sent["frames"],
        datagrams_injected=sent["datagrams"],
        frame_classes=fz.counts,
        bridge_bad_data=c.get("bad_data"),
        bridge_rejected_sysid=c.get("rejected_sysid"),
        bridge_unknown_msgid=c.get("unknown_msgid"),
        bridge_rx_packets=c.get("rx_packets"),
        bridge_rejected_time=c.get("rejected_time"),
        bridge_rejected_stale=c.get("rejected_stale"),
        bridge_rejected_identity=c.get("rejected_identity"),
        max_setpoint_gap_s=_r(gap),
        steady_rms_m=_r(mt.get("steady_rms_m")),
        steady_max_m=_r(mt.get("steady_max_m")),
    )
    row.check(sent["frames"] >= n_frames, f"only {sent['frames']} frames injected")
    row.check(
        out.rc in FLOWN and "mission duration" in out.exit_reason,
        f"mission did not go on: exit {out.rc}: {out.exit_reason}",
    )
    row.check(mt.get("handback_confirmed") is True, "hand-back not confirmed")
    # the bridge answers telemetry, so a pause the vehicle or the machine caused (both streams
    # stop) is not the fuzz's doing: the check is on the pause the bridge alone made
    silent = bridge_silence(
        [e.t for e in tap.setpoints], [t for t, _ in tap.attitude_ms], t_on, t_off
    )
    row.figures["bridge_silence_max_s"] = _r(silent)
    row.check(
        gap <= 0.25 or silent <= 0.1,
        f"setpoints paused {gap:.2f} s during tracking ({silent:.2f} s while telemetry flowed)",
    )
    row.check(not tap.failsafes(), "the vehicle's offboard failsafe fired")
    _tracking_ok(row, o, mt)
    return row


def _track(m: Mission, seconds: float) -> None:
    """Let the mission track for ``seconds`` (the tap keeps up meanwhile)."""
    m.wait_until(lambda: False, seconds)


def _last_before(events: list[Event], t: float) -> float | None:
    ts = [e.t for e in events if e.t <= t]
    return ts[-1] if ts else None


def _after(events: list[Event], t: float) -> list[Event]:
    return [e for e in events if e.t > t]


def _completed(row: Row, out: BridgeOutcome) -> None:
    row.check(
        out.rc in FLOWN and "mission duration" in out.exit_reason,
        f"mission did not complete: exit {out.rc}: {out.exit_reason}",
    )
    row.check(out.metrics.get("handback_confirmed") is True, "hand-back not confirmed")


def scenario_loss_jitter(o: Opts) -> Row:
    """20 % datagram loss and 0..50 ms jitter (which reorders), both directions."""
    row = Row("loss20_jitter50")
    dur = 25.0 if o.quick else 60.0
    imp = Impairment(loss=0.2, jitter_s=0.05)
    with Mission(MissionSpec.make(o, dur, down=imp, up=imp), o.workdir / "loss") as m:
        row.check(m.wait_engaged(40.0), "never engaged")
        out = m.finish(dur + 40.0)
    _mission_common(row, m, out, Limits.for_config("px4"))
    rc, mt, c = m.relay.counters(), out.metrics, out.counters
    t_on, t_off = _tracking_window(m.tap)
    row.figures.update(
        relay_down=_pick(rc["down"]),
        relay_up=_pick(rc["up"]),
        bridge_rejected_stale=c.get("rejected_stale"),
        steady_rms_m=_r(mt.get("steady_rms_m")),
        steady_max_m=_r(mt.get("steady_max_m")),
        convergence_time_s=_r(mt.get("convergence_time_s"), 1),
        max_setpoint_gap_at_vehicle_s=_r(max_gap([e.t for e in m.tap.setpoints], t_on, t_off)),
    )
    _completed(row, out)
    row.check(not m.tap.failsafes(), "the vehicle's offboard failsafe fired")
    _tracking_ok(row, o, mt)
    return row


def scenario_corrupt_dup_reorder(o: Opts) -> Row:
    """5 % of the datagrams with a damaged byte, 5 % duplicated, 5 % held back 30 ms (reordered),
    both directions: a noisy radio. Damaged frames must be dropped by CRC on both sides,
    duplicates and reordered samples must not be acted on twice or backwards."""
    row = Row("corrupt5_dup5_reorder5")
    dur = 20.0 if o.quick else 40.0
    imp = Impairment(corrupt=0.05, corrupt_bytes=1, duplicate=0.05, reorder=0.05, reorder_s=0.03)
    with Mission(MissionSpec.make(o, dur, down=imp, up=imp), o.workdir / "noisy") as m:
        row.check(m.wait_engaged(40.0), "never engaged")
        out = m.finish(dur + 40.0)
    _mission_common(row, m, out, Limits.for_config("px4"))
    rc, c, mt = m.relay.counters(), out.counters, out.metrics
    row.figures.update(
        relay_down=_pick(rc["down"]),
        relay_up=_pick(rc["up"]),
        bridge_bad_data=c.get("bad_data"),
        bridge_rejected_stale=c.get("rejected_stale"),
        vehicle_dropped=m.vehicle.report.get("dropped"),
        steady_rms_m=_r(mt.get("steady_rms_m")),
        steady_max_m=_r(mt.get("steady_max_m")),
    )
    _completed(row, out)
    row.check(not m.tap.failsafes(), "the vehicle's offboard failsafe fired")
    row.check(
        (c.get("bad_data") or 0) > 0 and (c.get("rejected_stale") or 0) > 0,
        "the damage and the duplicates never reached the bridge",
    )
    _tracking_ok(row, o, mt)
    return row


def _pick(d: dict[str, int]) -> dict[str, int]:
    keys = (
        "received",
        "delivered",
        "dropped_loss",
        "dropped_blackout",
        "duplicated",
        "reordered",
        "corrupted",
        "injected",
        "filtered_frames",
    )
    return {k: d[k] for k in keys if d.get(k)}


def _blackout(o: Opts, name: str, direction: str | None, reengage: bool = False) -> Row:
    """A 2 s blackout during TRACKING: ``direction`` None cuts the whole link, DOWN the
    telemetry only (commands still reach the vehicle). ``reengage``: the bridge is configured
    to fly again once telemetry is back (``mavlink.reengage_max=1``), else it ends."""
    row = Row(name)
    dur = (30.0 if o.quick else 40.0) if reengage else (20.0 if o.quick else 30.0)
    lim = Limits.for_config("px4")
    b: Blackout | None = None
    sets = ("mavlink.reengage_max=1",) if reengage else ()
    with Mission(MissionSpec.make(o, dur, sets=sets), o.workdir / name) as m:
        if row.check(m.wait_engaged(30.0), "never engaged"):
            _track(m, 4.0)
            b = m.relay.blackout(2.0, direction)
        out = m.finish(dur + 40.0)
    _mission_common(row, m, out, lim)
    if b is None:
        return row
    reengaged = _blackout_handover(row, m.tap, out, b, direction, reengage)
    if reengage:
        _blackout_reengaged(row, m, out, b, reengaged)
    else:
        _blackout_ended(row, m.tap, out, b, reengaged)
    return row


def _blackout_handover(
    row: Row,
    tap: Tap,
    out: BridgeOutcome,
    b: Blackout,
    direction: str | None,
    reengage: bool,
) -> list[Event]:
    """The bridge stops commanding within 0.5 s of the blackout's start, the vehicle leaves
    offboard within its 1 s loss timeout and hands back to AUTO.LOITER; returns the bridge's
    OFFBOARD requests after the blackout's start."""
    t0 = b.start_s
    last_sent = _last_before(tap.bridge_setpoints, b.end_s)  # the bridge's last command
    last_deliv = _last_before(tap.setpoints, b.end_s)  # the vehicle's last command
    t_out = tap.left_offboard_after(t0)
    fs = [e.t for e in tap.failsafes() if e.t >= t0]
    reengaged = [e for e in tap.mode_requests() if e.t > t0 and int(e.msg.param2) == 6]
    stop_s = None if last_sent is None else last_sent - t0
    mt = out.metrics
    # the vehicle's loss timeout (1 s) runs on its clock: measured there, a host that left the
    # vehicle's process waiting does not stretch it (the wall-clock figures are kept too)
    vs = tap.vehicle_s
    fs_v = vs(fs[0]) - vs(last_deliv) if fs and last_deliv else None
    out_v = vs(t_out) - vs(last_deliv) if t_out and last_deliv else None
    row.figures.update(
        blackout_s=2.0,
        direction="both" if direction is None else "telemetry (vehicle -> bridge)",
        commands_stop_after_s=_r(stop_s),
        vehicle_failsafe_after_last_command_s=_r(fs_v),
        vehicle_left_offboard_after_last_command_s=_r(out_v),
        wall_failsafe_after_last_command_s=_r(fs[0] - last_deliv if fs and last_deliv else None),
        wall_left_offboard_after_last_command_s=_r(
            t_out - last_deliv if t_out and last_deliv else None
        ),
        vehicle_mode_after=tap.mode(),
        handback_confirmed=mt.get("handback_confirmed"),
        configured="re-engage (mavlink.reengage_max=1)"
        if reengage
        else "end (mavlink.reengage_max=0)",
        bridge_after_blackout=(
            f"re-engaged {reengaged[0].t - b.end_s:.2f} s after the blackout"
            if reengaged
            else "ended (hand-back requested)"
        ),
        setpoints_after_blackout=len(_after(tap.bridge_setpoints, b.end_s)),
    )
    row.check(
        stop_s is not None and stop_s <= 0.5 + 0.03,
        f"commands went on {stop_s} s into the blackout",
    )
    row.check(
        out_v is not None and out_v <= 1.0 + 0.25,
        "the vehicle did not leave offboard within its 1 s loss timeout",
    )
    if direction is None:  # nothing reaches the vehicle: its own failsafe must act, on time
        row.check(
            fs_v is not None and 0.9 <= fs_v <= 1.0 + 0.25,
            "the vehicle's own offboard-loss failsafe did not take over on time",
        )
    row.check(tap.mode() == "AUTO.LOITER", f"vehicle ended in {tap.mode()}")
    row.check(
        mt.get("handback_confirmed") is True,
        "hand-back to AUTO.LOITER not confirmed after the blackout",
    )
    return reengaged


def _blackout_ended(
    row: Row, tap: Tap, out: BridgeOutcome, b: Blackout, reengaged: list[Event]
) -> None:
    """Configured to end: exit 4 (telemetry lost) and no command after the blackout."""
    row.check(
        out.rc == 4 and "telemetry lost" in out.exit_reason, f"exit {out.rc}: {out.exit_reason}"
    )
    row.check(
        not reengaged and not _after(tap.bridge_setpoints, b.end_s),
        "the bridge commanded again after the blackout",
    )


def _blackout_reengaged(
    row: Row, m: Mission, out: BridgeOutcome, b: Blackout, reengaged: list[Event]
) -> None:
    """Configured to re-engage: one OFFBOARD request within 10 s of the blackout's end, then
    the mission flies on to its original end and tracks again."""
    mt = out.metrics
    n_re = (mt.get("counters") or {}).get("reengagements")
    ts = _timeseries(m.out_dir)
    last5 = None
    if ts is not None and ts.size:
        pt = ts["pt_norm"][ts["t"] >= ts["t"][-1] - 5.0]
        last5 = math.sqrt(float((pt**2).mean()))
    row.figures.update(
        reengagements=n_re, rms_last_5s_m=_r(last5), final_pt_m=_r(mt.get("final_pt_m"))
    )
    row.check(
        out.rc in FLOWN and "mission duration" in out.exit_reason,
        f"exit {out.rc}: {out.exit_reason}",
    )
    row.check(
        n_re == 1 and len(reengaged) == 1, f"{len(reengaged)} OFFBOARD requests after the blackout"
    )
    row.check(
        bool(reengaged) and reengaged[0].t - b.end_s <= 10.0,
        "not re-engaged within 10 s of the blackout's end",
    )
    # the vehicle loitered meanwhile: the re-capture starts tens of metres off, like the first
    row.check(
        (mt.get("final_pt_m") or math.inf) < 10.0,
        f"not tracking after the re-engagement (final |pt| {mt.get('final_pt_m')})",
    )


def scenario_blackout_link(o: Opts) -> Row:
    return _blackout(o, "blackout_link_2s", None)


def scenario_blackout_link_reengage(o: Opts) -> Row:
    return _blackout(o, "blackout_link_2s_reengage", None, reengage=True)


def scenario_blackout_telemetry(o: Opts) -> Row:
    return _blackout(o, "blackout_telemetry_2s", DOWN)


def scenario_target_loss(o: Opts) -> Row:
    """A live target (FOLLOW_TARGET from system 2) whose feed stops for good mid-mission."""
    row = Row("target_feed_loss")
    dur = 20.0 if o.quick else 30.0
    # the bridge's target estimator refuses the target once its predicted uncertainty (at
    # least what a target accelerating at a can do unseen, a tau^2 / 2) passes the bound
    bound_m, accel = 4.0, 0.3
    spec = MissionSpec.make(
        o,
        dur,
        target="stationary",
        sets=(
            "target.type=mavlink",
            f"mavlink.target_sysid={TARGET_SYSID}",
            f"target_estimator.max_position_sigma_m={bound_m}",
            f"target_estimator.manoeuvre_accel_m_s2={accel}",
        ),
    )
    b: Blackout | None = None
    with Mission(spec, o.workdir / "target") as m:
        if row.check(m.wait_engaged(30.0), "never engaged"):
            _track(m, 4.0)
            b = m.relay.blackout(1e6, DOWN, sysid=TARGET_SYSID)
        out = m.finish(dur + 40.0)
    _mission_common(row, m, out, Limits.for_config("px4"))
    if b is None:
        return row
    tap = m.tap
    last_sent = _last_before(tap.bridge_setpoints, b.start_s + 10.0)
    stop_s = None if last_sent is None else last_sent - b.start_s
    row.figures.update(
        target_samples_before=len([e for e in tap.target_msgs if e.t < b.start_s]),
        commands_stop_after_target_loss_s=_r(stop_s),
        target_bound_m=bound_m,
        target_unseen_accel_m_s2=accel,
        telemetry_timeout_s=0.5,
        frames_cut=m.relay.counters()["down"]["filtered_frames"],
        vehicle_mode_after=tap.mode(),
        handback_confirmed=out.metrics.get("handback_confirmed"),
    )
    # stale once sigma_0 + a tau^2 / 2 > bound: no later than sqrt(2 bound / a) (5.2 s) whatever
    # the filter's own sigma_0, and not before sqrt(2 (bound - 2 m) / a) (3.7 s) while its
    # 1-sigma of a fixed target seen at 10 Hz stays below 2 m; then no good law step for
    # telemetry_timeout_s (0.5 s) before the bridge stops
    lo, hi = math.sqrt(2.0 * (bound_m - 2.0) / accel), math.sqrt(2.0 * bound_m / accel)
    row.check(
        stop_s is not None and lo <= stop_s <= hi + 0.5 + 0.15,
        f"commands stopped {stop_s} s after the feed (expected {lo:.2f}..{hi + 0.65:.2f} s)",
    )
    row.check(out.rc == 4 and "target" in out.exit_reason, f"exit {out.rc}: {out.exit_reason}")
    row.check(
        out.metrics.get("handback_confirmed") is True and tap.mode() == "AUTO.LOITER",
        f"not handed back: {tap.mode()}",
    )
    return row


def _gcs_set_mode(flavour: str, mode: str) -> bytes:
    """A ground station's (255/190) DO_SET_MODE to the vehicle, as raw bytes."""
    from mpf_mavlink.mavlink.modes import arduplane_mode_from_name, px4_mode_from_name

    gcs = M.MAVLink(None, srcSystem=255, srcComponent=190)
    if flavour == "px4":
        main, sub = px4_mode_from_name(mode)
        p2, p3 = float(main), float(sub)
    else:
        p2, p3 = float(arduplane_mode_from_name(mode)), 0.0
    return gcs.command_long_encode(
        VEHICLE_SYSID, VEHICLE_COMPID, M.MAV_CMD_DO_SET_MODE, 0, 1.0, p2, p3, 0, 0, 0, 0
    ).pack(gcs)


def scenario_pilot(o: Opts) -> Row:
    """ArduPlane: a ground station switches the vehicle to FBWA mid-mission."""
    row = Row("pilot_mode_change")
    dur = 20.0 if o.quick else 30.0
    t_cmd: float | None = None
    with Mission(MissionSpec.make(o, dur, flavour="ardupilot"), o.workdir / "pilot") as m:
        if row.check(m.wait_engaged(30.0), "never engaged"):
            _track(m, 4.0)
            t_cmd = m.relay.now()
            m.relay.inject(UP, _gcs_set_mode("ardupilot", "FBWA"))
        out = m.finish(dur + 40.0)
        time.sleep(1.5)  # the vehicle must stay in the pilot's mode: watch a little longer
        m.tap.update()
    _mission_common(row, m, out, Limits.for_config("ardupilot"))
    if t_cmd is None:
        return row
    tap = m.tap
    t_fbwa = tap.first_mode_after(t_cmd, lambda n: n == "FBWA")
    # set-points in flight when the heartbeat came are fine: 50 ms, plus any stall of the relay
    # around the report (it forwards a backlog of telemetry the bridge still answers, and stamps
    # the answers late)
    t_rep = t_fbwa or t_cmd
    stall = max((g for t, g in m.relay.loop_gaps if abs(t - t_rep) <= 1.0), default=0.0)
    late = _after(tap.bridge_setpoints, t_rep + 0.05 + stall)
    row.figures.update(
        pilot_mode="FBWA",
        vehicle_reported_after_s=_r(t_fbwa - t_cmd if t_fbwa else None),
        bridge_setpoints_after_report=len(late),
        relay_stall_near_report_s=_r(stall),
        bridge_mode_requests_after=len(_after(tap.mode_requests(), t_cmd)),
        vehicle_mode_after=tap.mode(),
    )
    row.check(t_fbwa is not None, "the vehicle never reported FBWA")
    row.check(not late, f"{len(late)} setpoints after the vehicle reported the pilot's mode")
    row.check(not _after(tap.mode_requests(), t_cmd), "the bridge fought the pilot (mode request)")
    row.check(
        out.rc == 4 and "someone else" in out.exit_reason, f"exit {out.rc}: {out.exit_reason}"
    )
    row.check(tap.mode() == "FBWA", f"vehicle ended in {tap.mode()}, not the pilot's FBWA")
    return row


def _reboot(o: Opts, name: str, fast: bool) -> Row:
    """The vehicle reboots mid-mission: ``fast`` in-process (a new boot clock after ~0.2 s of
    silence, less than the bridge's telemetry timeout), else its process is killed and started
    again (a power cycle, ~1 s)."""
    row = Row(name)
    dur = 20.0 if o.quick else 30.0
    t_r: float | None = None
    with Mission(
        MissionSpec.make(o, dur, vehicle_extra=("--spare",) if fast else ()), o.workdir / name
    ) as m:
        if row.check(m.wait_engaged(30.0), "never engaged"):
            _track(m, 4.0)
            old_ms = m.tap.vehicle_ms()
            t_r = m.relay.now()
            if fast:
                assert m.vehicle.proc is not None
                m.vehicle.proc.send_signal(signal.SIGUSR1)
            else:
                m.vehicle.kill()
                m.vehicle.start()
        out = m.finish(dur + 40.0)
        time.sleep(1.5)
        m.tap.update()
    _mission_common(row, m, out)
    if t_r is None:
        return row
    tap = m.tap
    back = [(t, ms) for t, ms in tap.attitude_ms if t > t_r and old_ms is not None and ms < old_ms]
    t_back = back[0][0] if back else None
    last_sent = _last_before(tap.bridge_setpoints, t_r + 10.0)
    to_new = _after(tap.setpoints, t_back) if t_back is not None else []
    row.figures.update(
        vehicle_silent_s=_r(t_back - t_r if t_back else None),
        boot_ms_before=old_ms,
        boot_ms_after=back[0][1] if back else None,
        commands_stop_after_s=_r(last_sent - t_r if last_sent else None),
        setpoints_to_new_boot=len(to_new),
        new_boot_offboard=any(
            is_offboard(tap.flavour, e.msg) for e in tap.heartbeats if t_back and e.t > t_back
        ),
        bridge_clock_resets=out.counters.get("clock_resets"),
        bridge_rejected_time=out.counters.get("rejected_time"),
        vehicle_mode_after=tap.mode(),
    )
    row.check(t_back is not None, "the vehicle never came back")
    row.check(
        last_sent is not None and last_sent - t_r <= 0.5 + 0.03,
        f"commands went on {row.figures['commands_stop_after_s']} s after the reboot",
    )
    # nothing computed for the new boot: the only setpoints it may see are re-sends of the last
    # command, still in flight or within the telemetry timeout of the old boot's last sample
    bad = [e for e in to_new if old_ms is not None and not int(e.msg.time_boot_ms) <= old_ms + 600]
    row.check(not bad, f"{len(bad)} setpoints computed on the new boot clock")
    row.check(not row.figures["new_boot_offboard"], "the rebooted vehicle was put back in OFFBOARD")
    row.check(out.rc == 4, f"exit {out.rc}: {out.exit_reason}")
    row.check(
        "someone else" not in out.exit_reason, f"a reboot blamed on a pilot: {out.exit_reason}"
    )
    return row


def scenario_reboot(o: Opts) -> Row:
    return _reboot(o, "vehicle_reboot", fast=False)


def scenario_reboot_fast(o: Opts) -> Row:
    return _reboot(o, "vehicle_reboot_fast", fast=True)


def scenario_sigkill(o: Opts) -> Row:
    """``mpf-mavlink run`` killed with SIGKILL mid-mission: PX4's offboard-loss failsafe
    (COM_OF_LOSS_T = 1 s) must take over, and the tlog must be readable up to the kill."""
    from mpf_mavlink.mavlink import read_tlog

    row = Row("bridge_sigkill")
    t_kill: float | None = None
    t_kill_wall: float | None = None
    with Mission(MissionSpec.make(o, 60.0), o.workdir / "sigkill") as m:
        if row.check(m.wait_engaged(30.0), "never engaged"):
            _track(m, 4.0)
            assert m.bridge.proc is not None
            t_kill, t_kill_wall = m.relay.now(), time.time()
            m.bridge.proc.kill()
        out = m.finish(10.0)
        _track(m, 3.0)  # the vehicle's failsafe
    tap = m.tap
    row.figures["bridge_exit"] = out.rc
    if t_kill is None:
        return row
    last_deliv = _last_before(tap.setpoints, t_kill + 0.2)
    assert t_kill is not None and t_kill_wall is not None  # the row fails above when unkilled
    fs = [e.t for e in tap.failsafes() if e.t >= t_kill]
    sp_ms = [int(e.msg.time_boot_ms) for e in tap.setpoints]
    tl = m.out_dir / "mavlink.tlog"
    r = read_tlog(tl) if tl.is_file() else None
    logged_ms = {
        int(msg.time_boot_ms)
        for _, msg in (r.messages if r else [])
        if msg.get_type() == "SET_ATTITUDE_TARGET"
    }
    missing = [ms for ms in sp_ms if ms not in logged_ms]
    # on the vehicle's clock, where its loss timeout runs (see _blackout)
    fs_v = tap.vehicle_s(fs[0]) - tap.vehicle_s(last_deliv) if fs and last_deliv else None
    row.figures.update(
        killed_after_tracking_s=4.0,
        failsafe_after_last_command_s=_r(fs_v),
        wall_failsafe_after_last_command_s=_r(fs[0] - last_deliv if fs and last_deliv else None),
        com_of_loss_t_s=1.0,
        vehicle_mode_after=tap.mode(),
        tlog_records=r.records if r else None,
        tlog_last_record_before_kill_s=_r(t_kill_wall - r.t_last_s if r and r.t_last_s else None),
        tlog_skipped_bytes=r.skipped_bytes if r else None,
        setpoints_received_not_in_tlog=len(missing),
    )
    row.check(out.rc == -signal.SIGKILL, f"bridge exit {out.rc}")
    row.check(
        fs_v is not None and 0.9 <= fs_v <= 1.0 + 0.25,
        f"failsafe {row.figures['failsafe_after_last_command_s']} s after the last command "
        "(loss timeout 1 s)",
    )
    row.check(tap.mode() == "AUTO.LOITER", f"vehicle ended in {tap.mode()}")
    row.check(
        r is not None and r.records > 100 and r.skipped_regions == 0, "tlog unreadable or corrupt"
    )
    row.check(
        r is not None and r.t_last_s is not None and t_kill_wall - r.t_last_s < 0.2,
        "the tlog stops before the kill",
    )
    row.check(not missing, f"{len(missing)} setpoints the vehicle received are not in the tlog")
    return row


def _timeseries(d: Path) -> Any:
    import numpy as np

    f = d / "timeseries.csv"
    if not f.is_file():
        return None
    return np.genfromtxt(f, delimiter=",", names=True)
