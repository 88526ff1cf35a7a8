"""Identify an autopilot profile from the real firmware.

``python -m lab.calibration.identify arduplane --out DIR``.

Flies short manoeuvres on the SITL firmware through pymavlink (its ground-station link) and fits
the parameters :mod:`sim.autopilot.profile` needs (scipy least squares), then writes
``DIR/profile.yaml`` (copy it to ``configs/autopilots/``), ``DIR/samples.csv`` and ``DIR/fit.json``.

ArduPlane (GUIDED, SET_ATTITUDE_TARGET with the quaternion's yaw 0 as the bridge sends it,
throttle left to TECS): bank steps and doublets (+-10 .. +-35 deg) and pitch steps for the attitude
loop's dead time, lag, gain and bias; steady turns at 10, 20, 30, 40 deg for the turn per bank
(the heading rate from the ground track against ``g tan(bank) / V``, as the bridge's adapter
learns it); SIMSTATE (the simulator's truth) against the reported attitude and position for
the estimator's noise and wander.

PX4 (OFFBOARD, attitude quaternion + thrust): the same bank steps and turns.

Nothing of the firmware's source is used: the binaries are driven and their answers fitted.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from lab.rigs.gcs import recv_from  # noqa: E402
from mpf_mavlink.constants import GRAVITY_M_S2 as G  # noqa: E402
from mpf_mavlink.quaternion import quat_of_euler  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


# (duration s, roll deg, pitch offset deg) segments flown in order
ARDUPLANE_SCHEDULE: list[tuple[float, float, float]] = [
    (6.0, 0.0, 0.0),
    (8.0, 20.0, 0.0),
    (8.0, -20.0, 0.0),
    (6.0, 0.0, 0.0),  # doublet
    (5.0, 10.0, 0.0),
    (5.0, -10.0, 0.0),
    (5.0, 0.0, 0.0),
    (6.0, 0.0, 4.0),
    (6.0, 0.0, -3.0),
    (6.0, 0.0, 0.0),  # pitch steps
    (14.0, 10.0, 0.0),
    (6.0, 0.0, 0.0),  # steady turns
    (14.0, 20.0, 0.0),
    (6.0, 0.0, 0.0),
    (14.0, 30.0, 0.0),
    (6.0, 0.0, 0.0),
    (14.0, -35.0, 0.0),
    (6.0, 0.0, 0.0),
]


class Recorder:
    """What the link brings, stamped with the receive time (monotonic s)."""

    def __init__(self, c: Any, sysid: int) -> None:
        self.c, self.sysid = c, sysid
        self.rows: dict[str, list[tuple]] = {"att": [], "pos": [], "hud": [], "sim": [], "cmd": []}
        self.last: dict[str, Any] = {}

    def pump(self, secs: float) -> None:
        for m in recv_from(self.c, self.sysid, secs, 0.02):
            t, mt = time.monotonic(), m.get_type()
            self.last[mt] = m
            if mt == "ATTITUDE":
                self.rows["att"].append(
                    (
                        t,
                        m.time_boot_ms / 1e3,
                        m.roll,
                        m.pitch,
                        m.yaw,
                        m.rollspeed,
                        m.pitchspeed,
                        m.yawspeed,
                    )
                )
            elif mt == "LOCAL_POSITION_NED":
                self.rows["pos"].append((t, m.time_boot_ms / 1e3, m.x, m.y, m.z, m.vx, m.vy, m.vz))
            elif mt == "VFR_HUD":
                self.rows["hud"].append((t, m.airspeed, m.groundspeed, m.throttle, m.alt))
            elif mt == "SIMSTATE":
                self.rows["sim"].append((t, m.roll, m.pitch, m.yaw, m.lat * 1e-7, m.lng * 1e-7))
            elif mt == "STATUSTEXT":
                print(f"  [sitl] {m.text}", flush=True)


def fly_schedule(
    rec: Recorder,
    send: Any,
    schedule: list[tuple[float, float, float]],
    pitch0: float,
    rate_hz: float = 25.0,
) -> None:
    for dur, roll_deg, dpitch_deg in schedule:
        t_end = time.monotonic() + dur
        roll, pitch = math.radians(roll_deg), pitch0 + math.radians(dpitch_deg)
        while time.monotonic() < t_end:
            send(roll, pitch)
            rec.rows["cmd"].append((time.monotonic(), roll, pitch))
            rec.pump(1.0 / rate_hz)


# --------------------------------------------------------------------------- fits
def _lag_response(t: np.ndarray, u: np.ndarray, delay: float, tau: float) -> np.ndarray:
    """First-order lag of u(t - delay) on the (non-uniform) sample times t (zero-order hold)."""
    ud = np.interp(t - delay, t, u, left=u[0])
    y = np.empty_like(ud)
    y[0] = ud[0]
    for i in range(1, len(t)):
        a = 1.0 - math.exp(-(t[i] - t[i - 1]) / max(tau, 1e-3))
        y[i] = y[i - 1] + a * (ud[i] - y[i - 1])
    return y


def fit_axis(t: np.ndarray, cmd: np.ndarray, meas: np.ndarray) -> dict[str, float]:
    """Dead time, lag, gain, bias of meas against cmd (least squares over the whole record)."""
    from scipy.optimize import least_squares

    def res(x: np.ndarray) -> np.ndarray:
        return x[2] * _lag_response(t, cmd, x[0], x[1]) + x[3] - meas

    best = None
    for d0 in (0.02, 0.1, 0.2):
        for tau0 in (0.2, 0.5, 1.0):
            r = least_squares(
                res, [d0, tau0, 1.0, 0.0], bounds=([0.0, 0.01, 0.5, -0.2], [1.0, 5.0, 1.5, 0.2])
            )
            if best is None or r.cost < best.cost:
                best = r
    assert best is not None
    rms = float(np.sqrt(np.mean(best.fun**2)))
    d, tau, k, b = (float(v) for v in best.x)
    return {"delay_s": d, "tau_s": tau, "gain": k, "bias_rad": b, "rms_rad": rms}


def fit_turn(
    att: np.ndarray, pos: np.ndarray, hud: np.ndarray, segs: list[tuple[float, float]]
) -> dict[str, Any]:
    """Heading rate (ground course rate, still air) per g tan(bank) / V over the steady turns."""
    rows = []
    for t0, t1 in segs:
        pm = (pos[:, 0] >= t0) & (pos[:, 0] <= t1)
        am = (att[:, 0] >= t0) & (att[:, 0] <= t1)
        hm = (hud[:, 0] >= t0) & (hud[:, 0] <= t1)
        if pm.sum() < 10 or am.sum() < 10 or hm.sum() < 3:
            continue
        tp = pos[pm, 1]
        chi = np.unwrap(np.arctan2(pos[pm, 6], pos[pm, 5]))
        chid = float(np.polyfit(tp, chi, 1)[0])
        phi = float(np.mean(att[am, 2]))
        v_air = float(np.mean(hud[hm, 1]))
        v_gnd = float(np.mean(np.hypot(pos[pm, 5], pos[pm, 6])))
        model = G * math.tan(phi) / v_air
        rows.append(
            {
                "bank_deg": math.degrees(phi),
                "chi_dot": chid,
                "airspeed": v_air,
                "groundspeed": v_gnd,
                "gain_airspeed": chid / model,
                "gain_groundspeed": chid / (G * math.tan(phi) / v_gnd),
            }
        )
    # the adapter's V is |ground velocity - wind| (TAS; VFR_HUD reports EAS): in still air the
    # ground speed
    x = np.array([G * math.tan(math.radians(r["bank_deg"])) / r["groundspeed"] for r in rows])
    y = np.array([r["chi_dot"] for r in rows])
    k = float(x @ y / (x @ x)) if len(rows) else float("nan")
    return {"turn_gain": k, "turns": rows}


def estimator_stats(
    att: np.ndarray, sim: np.ndarray, pos: np.ndarray, origin: tuple[float, float]
) -> dict[str, float]:
    """Reported minus simulator truth: attitude (rad) and horizontal position (m)."""
    out: dict[str, float] = {}
    if len(sim) < 20:
        return out
    dr = np.interp(att[:, 0], sim[:, 0], sim[:, 1]) - att[:, 2]
    out["roll_err_mean_rad"] = float(np.mean(dr))
    out["roll_err_std_rad"] = float(np.std(dr))
    lat0, lon0 = origin
    n = (sim[:, 4] - lat0) * math.radians(1.0) * 6378137.0
    e = (sim[:, 5] - lon0) * math.radians(1.0) * 6378137.0 * math.cos(math.radians(lat0))
    tn, te = np.interp(pos[:, 0], sim[:, 0], n), np.interp(pos[:, 0], sim[:, 0], e)
    dn, de = pos[:, 2] - tn, pos[:, 3] - te
    # the origins differ by a constant (EKF origin vs the first truth sample): remove the mean
    out["pos_err_std_n_m"] = float(np.std(dn - np.mean(dn)))
    out["pos_err_std_e_m"] = float(np.std(de - np.mean(de)))
    return out


# --------------------------------------------------------------------------- ArduPlane
def identify_arduplane(out: Path, bundle: Path, instance: int, alt: float) -> dict[str, Any]:
    from lab.rigs.arduplane import take_off
    from lab.rigs.gcs import Gcs
    from mpf_mavlink.mavlink.modes import Flavour

    port = 5760 + 10 * instance
    work = out / "sitl"
    work.mkdir(parents=True, exist_ok=True)
    parm = bundle / "Tools" / "autotest" / "models" / "plane.parm"
    cmd = [
        str(bundle / "bin" / "arduplane"),
        "--model",
        "plane",
        "--defaults",
        str(parm),
        f"-I{instance}",
    ]
    log = open(work / "sitl.log", "w")  # noqa: SIM115 - lives as long as the process
    proc = subprocess.Popen(
        cmd, cwd=work, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
    )
    try:
        g = Gcs(f"tcp:127.0.0.1:{port}", Flavour.ARDUPILOT)
        take_off(g, alt)
        c = g.c
        for sid, hz in ((10, 40), (6, 10), (11, 10), (12, 10)):  # attitude, position, hud, extra3
            c.mav.request_data_stream_send(g.sys, g.comp, sid, hz, 1)
        rec = Recorder(c, g.sys)
        rec.pump(2.0)
        gp = g.last["GLOBAL_POSITION_INT"]
        pitch0 = float(np.mean([r[3] for r in rec.rows["att"][-20:]])) if rec.rows["att"] else 0.03
        g.set_mode("GUIDED")
        rec.pump(1.0)

        def send(roll: float, pitch: float) -> None:
            # type_mask 7: body rates ignored; 64: throttle ignored (TECS keeps the speed)
            c.mav.set_attitude_target_send(
                int(time.monotonic() * 1e3) & 0xFFFFFFFF,
                g.sys,
                g.comp,
                7 | 64,
                list(quat_of_euler(roll, pitch, 0.0)),
                0,
                0,
                0,
                0.0,
            )

        t_start = time.monotonic()
        fly_schedule(rec, send, ARDUPLANE_SCHEDULE, pitch0)
        g.set_mode("LOITER")
        rec.pump(1.0)
        origin = (gp.lat * 1e-7, gp.lon * 1e-7)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, 15)
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, 9)
    return analyse(rec, t_start, ARDUPLANE_SCHEDULE, pitch0, origin, out)


def identify_px4(out: Path, bundle: Path, alt: float) -> dict[str, Any]:
    """Bank steps and steady turns in OFFBOARD attitude (quaternion + thrust) on real PX4 SIH,
    started and taken off by the rig (:mod:`lab.rigs.px4`, under its /tmp/mpf-px4.lock)."""
    from types import SimpleNamespace

    from lab.rigs.gcs import Gcs
    from lab.rigs.px4 import Firmware
    from mpf_mavlink.mavlink.modes import Flavour

    fw = Firmware(SimpleNamespace(speedup=1.0))
    fw.start(bundle, out / "firmware")
    try:
        g = Gcs(fw.gcs_url, Flavour.PX4)
        fw.take_off(g, alt)
        c = g.c
        for msg_id, hz in ((30, 50), (32, 20), (74, 10)):  # ATTITUDE, LOCAL_POSITION, VFR_HUD
            g.command(511, msg_id, 1e6 / hz)  # MAV_CMD_SET_MESSAGE_INTERVAL
        rec = Recorder(c, g.sys)
        rec.pump(2.0)
        pitch0 = float(np.mean([r[3] for r in rec.rows["att"][-20:]]))
        hud = rec.last.get("VFR_HUD")
        thr = (hud.throttle / 100.0) if hud is not None else 0.8

        def send(roll: float, pitch: float) -> None:
            c.mav.set_attitude_target_send(
                int(time.monotonic() * 1e3) & 0xFFFFFFFF,
                g.sys,
                1,
                7,
                list(quat_of_euler(roll, pitch, 0.0)),
                0,
                0,
                0,
                thr,
            )

        t0 = time.monotonic()
        while time.monotonic() - t0 < 1.5:  # stream before asking for OFFBOARD
            send(0.0, pitch0)
            rec.pump(0.04)
        g.set_mode("OFFBOARD")
        t_start = time.monotonic()
        fly_schedule(rec, send, ARDUPLANE_SCHEDULE, pitch0)
        g.set_mode("AUTO.LOITER")
        rec.pump(1.0)
        gp = g.last["GLOBAL_POSITION_INT"]
        origin = (gp.lat * 1e-7, gp.lon * 1e-7)
    finally:
        fw.stop()
    return analyse(rec, t_start, ARDUPLANE_SCHEDULE, pitch0, origin, out)


def analyse(
    rec: Recorder,
    t_start: float,
    schedule: list[tuple[float, float, float]],
    pitch0: float,
    origin: tuple[float, float],
    out: Path,
) -> dict[str, Any]:
    att = np.array(rec.rows["att"], float)
    pos = np.array(rec.rows["pos"], float)
    hud = np.array(rec.rows["hud"], float)
    sim = np.array(rec.rows["sim"], float).reshape(-1, 6)
    cmd = np.array(rec.rows["cmd"], float)
    np.savez(out / "samples.npz", att=att, pos=pos, hud=hud, sim=sim, cmd=cmd)
    m = att[:, 0] >= t_start
    a = att[m]
    # the command in force at each ATTITUDE sample (zero-order hold of what was sent)
    idx = np.clip(np.searchsorted(cmd[:, 0], a[:, 0], side="right") - 1, 0, len(cmd) - 1)
    roll_cmd, pitch_cmd = cmd[idx, 1], cmd[idx, 2]
    ta = a[:, 0] - a[0, 0]
    # the transients (first 40 % of the schedule: doublets and pitch steps) carry the dynamics
    t_dyn = sum(s[0] for s in schedule[:10])
    md = ta <= t_dyn
    roll = fit_axis(ta[md], roll_cmd[md], a[md, 2])
    pitch = fit_axis(ta[md], pitch_cmd[md], a[md, 3])
    # the steady turns: their last 8 s (the roll-in and the lag over)
    segs, t = [], t_start
    for dur, roll_deg, _ in schedule:
        if dur >= 12.0 and roll_deg != 0.0:
            segs.append((t + dur - 8.0, t + dur))
        t += dur
    turn = fit_turn(att, pos, hud, segs)
    # steady bank per commanded bank over the turns (the turn's own roll bias)
    steady = []
    turns = [s for s in schedule if s[0] >= 12.0 and s[1] != 0.0]
    for (t0, t1), (_, roll_deg, _) in zip(segs, turns, strict=True):
        mm = (att[:, 0] >= t0) & (att[:, 0] <= t1)
        steady.append((roll_deg, math.degrees(float(np.mean(att[mm, 2])))))
    est = estimator_stats(att, sim, pos, origin)
    res = {
        "roll": roll,
        "pitch": pitch,
        "turn": turn,
        "steady_bank_deg": steady,
        "estimator": est,
        "pitch0_rad": pitch0,
    }
    (out / "fit.json").write_text(json.dumps(res, indent=1))
    return res


def circle_wind_error(tlog: Path, after_s: float = 90.0) -> dict[str, float]:
    """From a bridge tlog of a steady circle: the reported wind (WIND) in the ground velocity's
    frame (along, to the right; m/s), the turn rate (rad/s), its mean in NED and the bank."""
    m = mavutil.mavlink_connection(str(tlog))
    w, p, a = [], [], []
    while True:
        x = m.recv_match(type=["WIND", "LOCAL_POSITION_NED", "ATTITUDE"])
        if x is None:
            break
        ts = x._timestamp
        if x.get_type() == "WIND":
            w.append((ts, x.direction, x.speed))
        elif x.get_type() == "ATTITUDE":
            a.append((ts, x.roll))
        else:
            p.append((ts, x.vx, x.vy, x.time_boot_ms / 1e3))
    W, P, A = np.array(w, float), np.array(p, float), np.array(a, float)
    W = W[W[:, 0] > W[0, 0] + after_s]
    P = P[P[:, 0] > P[0, 0] + after_s]
    # WIND.direction: where it blows FROM (deg); the air moves toward the opposite
    wn = -W[:, 2] * np.cos(np.radians(W[:, 1]))
    we = -W[:, 2] * np.sin(np.radians(W[:, 1]))
    vx, vy = np.interp(W[:, 0], P[:, 0], P[:, 1]), np.interp(W[:, 0], P[:, 0], P[:, 2])
    v = np.hypot(vx, vy)
    chi = np.unwrap(np.arctan2(P[:, 2], P[:, 1]))
    return {
        "along": float(np.mean((wn * vx + we * vy) / v)),
        "right": float(np.mean((-wn * vy + we * vx) / v)),
        "omega": float(np.polyfit(P[:, 3], chi, 1)[0]),
        "north": float(np.mean(wn)),
        "east": float(np.mean(we)),
        "bank": float(np.mean(A[A[:, 0] > A[0, 0] + after_s, 1])),
    }


def position_lead(tlog: Path, after_s: float = 60.0) -> dict[str, float]:
    """How far ahead of the reported velocity the position the bridge uses is (s), from a bridge
    tlog of a steady circle. The bridge extrapolates LOCAL_POSITION_NED by its velocity to the
    ATTITUDE stamp; ArduPlane stamps ATTITUDE 20 or 40 ms after the position it follows (its
    50 Hz loop's send slots), so the position is carried ahead of the velocity by that gap less
    any lead the velocity already has over the position (its direction against the position's
    derivative, divided by the turn rate)."""
    m = mavutil.mavlink_connection(str(tlog))
    last, gaps, pos = None, [], []
    while True:
        x = m.recv_match(type=["LOCAL_POSITION_NED", "ATTITUDE"])
        if x is None:
            break
        if x.get_type() == "LOCAL_POSITION_NED":
            last = x.time_boot_ms
            pos.append((x.time_boot_ms / 1e3, x.x, x.y, x.vx, x.vy))
        elif last is not None:
            gaps.append((x.time_boot_ms / 1e3, (x.time_boot_ms - last) / 1e3))
    g, p = np.array(gaps, float), np.array(pos, float)
    _, i = np.unique(p[:, 0], return_index=True)
    p = p[i]
    g, p = g[g[:, 0] > g[0, 0] + after_s], p[p[:, 0] > p[0, 0] + after_s]
    t = p[:, 0]
    dx, dy = np.gradient(p[:, 1], t), np.gradient(p[:, 2], t)
    ang = np.unwrap(np.arctan2(p[:, 4], p[:, 3])) - np.unwrap(np.arctan2(dy, dx))
    ang = (ang + np.pi) % (2.0 * np.pi) - np.pi
    omega = float(np.polyfit(t, np.unwrap(np.arctan2(p[:, 4], p[:, 3])), 1)[0])
    vel_lead = float(np.mean(ang)) / omega if abs(omega) > 1e-3 else 0.0
    gap = float(np.mean(g[:, 1]))
    return {"stamp_gap_s": gap, "velocity_lead_s": vel_lead, "position_lead_s": gap - vel_lead}


WIND_NOISE_M_S = 0.01  # 1-sigma of a circle's mean reported wind (its WIND std over the orbit)


def fit_wind_estimator(circles: list[dict[str, float]]) -> dict[str, float]:
    """An apparent wind (along, side) fixed to the ground velocity, through a first-order lag of
    time constant tau in NED: turning at omega, it is seen in the velocity frame as
    ``(along + i side) / (1 + i omega tau)``. Least squares over still-air circles at different
    turn rates. Where omega tau >> 1 a large apparent wind lagged by minutes fits as well as a
    small one lagged by seconds; the shortest tau that fits within the measurement noise is
    taken (an estimator that follows the wind within a take-off)."""
    om = np.array([c["omega"] for c in circles])
    y = np.array([complex(c["along"], c["right"]) for c in circles])
    best: dict[str, float] | None = None
    rows = []
    for tau in np.arange(0.5, 120.0, 0.5):
        h = 1.0 / (1.0 + 1j * om * tau)
        c = complex(np.vdot(h, y) / np.vdot(h, h))  # linear least squares for the complex input
        rms = float(np.sqrt(np.mean(np.abs(h * c - y) ** 2)))
        rows.append((float(tau), c, rms))
    rmin = min(r[2] for r in rows)
    for tau, c, rms in rows:
        if rms <= rmin + WIND_NOISE_M_S / 2:
            best = {"along_m_s": c.real, "side_m_s": c.imag, "tau_s": tau, "rms_m_s": rms}
            break
    assert best is not None
    return best


ULOG_SKIP_S = 20.0  # s of OFFBOARD left out of the EKF fit: the capture's transient


def _gm_fit(x: np.ndarray, dt: float) -> tuple[float, float]:
    """(sigma, tau_s) of a first-order Gauss-Markov process fitted to a series sampled every
    dt: sigma its standard deviation, tau the lag where the fitted exp(-lag / tau) matches its
    autocorrelation over the first 30 s (least squares, scipy)."""
    from scipy.optimize import curve_fit

    x = x - x.mean()
    v = float(np.mean(x * x))
    n = min(len(x) // 3, int(round(30.0 / dt)))
    r = np.array([np.mean(x[: len(x) - k] * x[k:]) / v for k in range(1, n)])
    lag = np.arange(1, n) * dt
    (tau,), _ = curve_fit(
        lambda k, tau: np.exp(-k / tau), lag, r, p0=(5.0,), bounds=((0.05,), (500.0,))
    )
    return math.sqrt(v), float(tau)


def ekf_errors(ulog: Path, dt: float = 0.1) -> dict[str, Any]:
    """PX4's estimate against SIH's ground truth in one ULog (``vehicle_attitude`` vs
    ``vehicle_attitude_groundtruth``, ``vehicle_local_position`` vs its ground truth,
    ``vehicle_angular_velocity`` vs its ground truth, EKF2's ``wind``), over the OFFBOARD flight
    from ULOG_SKIP_S: a Gauss-Markov (sigma, tau) per channel, the gyro's white noise, and the
    turn per bank (ground truth heading rate against g tan(bank) / V)."""
    try:
        from pyulog import ULog
    except ImportError:
        raise SystemExit("identify: --ulog needs pyulog (pip install pyulog)") from None
    from scipy.spatial.transform import Rotation

    u = ULog(str(ulog))

    def topic(name: str) -> dict[str, np.ndarray]:
        for d in u.data_list:
            if d.name == name:
                return d.data
        raise SystemExit(f"identify: {ulog}: no {name} topic")

    vs = topic("vehicle_status")
    off = vs["timestamp"][vs["nav_state"] == 14] / 1e6  # NAVIGATION_STATE_OFFBOARD
    if len(off) == 0:
        raise SystemExit(f"identify: {ulog}: never in OFFBOARD")
    tt = np.arange(off[0] + ULOG_SKIP_S, off[-1], dt)
    if len(tt) < 600:
        raise SystemExit(f"identify: {ulog}: under {ULOG_SKIP_S + 60 * dt * 10:g} s of OFFBOARD")

    def euler(d: dict[str, np.ndarray]) -> np.ndarray:
        q = np.c_[d["q[1]"], d["q[2]"], d["q[3]"], d["q[0]"]]
        e = Rotation.from_quat(q).as_euler("ZYX")[:, ::-1]
        e[:, 2] = np.unwrap(e[:, 2])
        return e

    def at(d: dict[str, np.ndarray], x: np.ndarray) -> np.ndarray:
        return np.interp(tt, d["timestamp"] / 1e6, x)

    a, ag = topic("vehicle_attitude"), topic("vehicle_attitude_groundtruth")
    ea, eg = euler(a), euler(ag)
    lp, lg = topic("vehicle_local_position"), topic("vehicle_local_position_groundtruth")
    av, avg = topic("vehicle_angular_velocity"), topic("vehicle_angular_velocity_groundtruth")
    w = topic("wind")
    res: dict[str, Any] = {"ulog": str(ulog), "window_s": float(tt[-1] - tt[0])}
    for i, k in enumerate(("roll", "pitch", "yaw")):
        res[k] = _gm_fit(at(a, ea[:, i]) - at(ag, eg[:, i]), dt)
    for k in ("x", "y", "z", "vx", "vy", "vz"):
        res[k] = _gm_fit(at(lp, lp[k]) - at(lg, lg[k]), dt)
    res["wind_n"] = _gm_fit(at(w, w["windspeed_north"]), dt)
    res["wind_e"] = _gm_fit(at(w, w["windspeed_east"]), dt)
    mg = (avg["timestamp"] / 1e6 >= tt[0]) & (avg["timestamp"] / 1e6 <= tt[-1])
    ta = avg["timestamp"][mg] / 1e6
    res["gyro_noise_rad_s"] = [
        float(np.std(np.interp(ta, av["timestamp"] / 1e6, av[f"xyz[{i}]"]) - avg[f"xyz[{i}]"][mg]))
        for i in range(3)
    ]
    # the turn per bank of SIH's airplane: ground-truth course rate against g tan(roll) / V
    vn, ve = at(lg, lg["vx"]), at(lg, lg["vy"])
    chi_dot = np.gradient(np.unwrap(np.arctan2(ve, vn)), tt)
    roll = at(ag, eg[:, 0])
    x = G * np.tan(roll) / np.maximum(np.hypot(vn, ve), 1.0)
    res["turn_gain"] = float(x @ chi_dot / (x @ x))
    return res


def write_px4_profile(fits: list[dict[str, Any]], base: Path, out: Path, command: str) -> Path:
    """The PX4 profile: ``base`` (its thrust and anything not identified here) with the EKF2
    error model of the ULogs (sigma: root mean square over the logs; tau: their mean), the gyro
    noise and the turn per bank; the empirical roll-rate wander is dropped (the EKF2 errors are
    what it stood for)."""
    import yaml

    def comb(k: str) -> tuple[float, float]:
        sig = math.sqrt(float(np.mean([f[k][0] ** 2 for f in fits])))
        return round(sig, 4), round(float(np.mean([f[k][1] for f in fits])), 1)

    prof = yaml.safe_load(base.read_text())
    prof["source"] = f"identified by `{command}` ({time.strftime('%Y-%m-%d')})"
    prof.pop("attitude", None)
    (sx, tx), (sy, ty), (sz, tz) = comb("x"), comb("y"), comb("z")
    (svx, tvx), (svy, tvy), (svz, tvz) = comb("vx"), comb("vy"), comb("vz")
    att = [comb(k) for k in ("roll", "pitch", "yaw")]
    (swn, twn), (swe, twe) = comb("wind_n"), comb("wind_e")
    est = prof.setdefault("estimator", {})
    for k in ("position_noise_m", "vertical_noise_m", "velocity_noise_m_s"):
        est.pop(k, None)  # the white noise of the telemetry is in the Gauss-Markov errors now
    est.update(
        {
            "rate_noise_rad_s": [
                round(float(np.sqrt(np.mean([f["gyro_noise_rad_s"][i] ** 2 for f in fits]))), 4)
                for i in range(3)
            ],
            "horizontal_wander_m": round(math.hypot(sx, sy) / math.sqrt(2.0), 4),
            "wander_tau_s": round((tx + ty) / 2.0, 1),
            "vertical_wander_m": sz,
            "vertical_wander_tau_s": tz,
            "velocity_wander_m_s": [round(math.hypot(svx, svy) / math.sqrt(2.0), 4), svz],
            "velocity_wander_tau_s": [round((tvx + tvy) / 2.0, 1), tvz],
            "attitude_wander_rad": [a[0] for a in att],
            "attitude_wander_tau_s": [a[1] for a in att],
            "wind_wander_m_s": round(math.hypot(swn, swe) / math.sqrt(2.0), 4),
            "wind_wander_tau_s": round((twn + twe) / 2.0, 1),
        }
    )
    prof.setdefault("turn", {})["turn_gain"] = round(
        float(np.mean([f["turn_gain"] for f in fits])), 3
    )
    path = out / "profile.yaml"
    path.write_text(yaml.safe_dump(prof, sort_keys=False))
    return path


def write_profile(
    res: dict[str, Any], autopilot: str, firmware: str, out: Path, command: str
) -> Path:
    import yaml

    r, p = dict(res["roll"]), res["pitch"]
    est = res.get("estimator", {})
    steady = res.get("steady_bank_deg")
    if steady and len(steady) >= 2:
        # the steady bank per commanded one over the held turns: what sets the turn the bridge
        # gets in a circle (the doublets' fit above carries the transients' lag, not this)
        sb = np.radians(np.array(steady, float))
        gain, bias = np.linalg.lstsq(np.c_[sb[:, 0], np.ones(len(sb))], sb[:, 1], rcond=None)[0]
        r["gain"], r["bias_rad"] = float(gain), float(bias)
    prof: dict[str, Any] = {
        "autopilot": autopilot,
        "firmware": firmware,
        "source": f"identified by `{command}` ({time.strftime('%Y-%m-%d')})",
        "attitude": {
            "roll_delay_s": round(r["delay_s"], 3),
            "roll_tau_s": round(r["tau_s"], 3),
            "roll_gain": round(r["gain"], 3),
            "roll_bias_rad": round(r["bias_rad"], 4),
            "pitch_delay_s": round(p["delay_s"], 3),
            "pitch_tau_s": round(p["tau_s"], 3),
            "pitch_gain": round(p["gain"], 3),
            "pitch_bias_rad": round(p["bias_rad"], 4),
        },
        "turn": {"turn_gain": round(res["turn"]["turn_gain"], 3)},
        "estimator": {
            "attitude_noise_rad": round(est.get("roll_err_std_rad", 0.0), 4),
        },
        "fit": {"roll_rms_rad": round(r["rms_rad"], 4), "pitch_rms_rad": round(p["rms_rad"], 4)},
    }
    wf = res.get("wind_estimator")
    if wf:
        prof["estimator"].update(
            {
                "wind_apparent_along_m_s": round(wf["along_m_s"], 3),
                "wind_apparent_side_m_s": round(wf["side_m_s"], 3),
                "wind_tau_s": round(wf["tau_s"], 2),
            }
        )
        prof["fit"]["wind_rms_m_s"] = round(wf["rms_m_s"], 4)
    if res.get("position_lead"):
        lead = float(np.mean([x["position_lead_s"] for x in res["position_lead"]]))
        prof["estimator"]["position_lead_s"] = round(lead, 4)
    if res.get("wind_scale"):
        prof["estimator"]["wind_scale"] = round(res["wind_scale"], 3)
    path = out / "profile.yaml"
    path.write_text(yaml.safe_dump(prof, sort_keys=False))
    return path


GUIDED_ARDUPLANE = 15  # ArduPlane's GUIDED mode number (MODE.Mode of its dataflash log)
TURN_WINDOWS_S = (5.0, 10.0, 20.0, 60.0)


def turn_per_bank_windows(
    t: np.ndarray,
    roll: np.ndarray,
    psi_dot: np.ndarray,
    airspeed: np.ndarray,
    windows: tuple[float, ...] = TURN_WINDOWS_S,
) -> dict[str, Any]:
    """The turn per bank ``V psi_dot = k g tan(roll)`` fitted by least squares over the whole
    series and over consecutive windows of each length: the fit, and per window length the mean
    and the standard deviation of the windows' fits (how much a stretch of that length scatters:
    what a memory of that length would carry into a turn emulation)."""
    ok = np.abs(roll) > 0.05
    tr = np.tan(roll)

    def fit(m: np.ndarray) -> float:
        return float(np.sum(airspeed[m] * psi_dot[m] * tr[m]) / np.sum(G * tr[m] ** 2))

    res: dict[str, Any] = {"turn_gain": fit(ok), "windows": {}}
    for w in windows:
        ks = [
            fit(ok & (t >= a) & (t < a + w))
            for a in np.arange(t[0], t[-1] - w + 1e-9, w)
            if np.count_nonzero(ok & (t >= a) & (t < a + w)) > 10
        ]
        if len(ks) >= 2:
            k = np.array(ks)
            res["windows"][f"{w:g}"] = {
                "n": len(ks),
                "mean": float(k.mean()),
                "sd": float(k.std(ddof=1)),
                "sd_rel": float(k.std(ddof=1) / k.mean()),
            }
    return res


def dataflash_turn(path: Path, after_s: float = 60.0) -> dict[str, Any]:
    """What ArduPlane SITL reports in a flight (its dataflash log, GUIDED from ``after_s`` after
    the last switch to GUIDED to the next mode change): ATT (the EKF's attitude, what it sends
    as ATTITUDE) against SIM (the simulator's true attitude) in degrees, and the turn per bank
    of the true heading rate (SIM's yaw) and airspeed (SIM2.As) against the reported roll and
    the true one (:func:`turn_per_bank_windows`)."""
    from pymavlink import DFReader

    f = DFReader.DFReader_binary(str(path))
    rows: dict[str, list[tuple[float, ...]]] = {"ATT": [], "SIM": [], "SIM2": []}
    modes: list[tuple[float, int]] = []
    while True:
        m = f.recv_match(type=["ATT", "SIM", "SIM2", "MODE"])
        if m is None:
            break
        k, tu = m.get_type(), m.TimeUS * 1e-6
        if k == "MODE":
            modes.append((tu, int(m.Mode)))
        elif k == "ATT":
            rows[k].append((tu, m.Roll, m.Pitch, m.Yaw))
        elif k == "SIM":
            rows[k].append((tu, m.Roll, m.Pitch, m.Yaw))
        else:
            rows[k].append((tu, m.As))
    starts = [i for i, (_, mo) in enumerate(modes) if mo == GUIDED_ARDUPLANE]
    if not starts or not rows["ATT"] or not rows["SIM"] or not rows["SIM2"]:
        raise SystemExit(f"identify: {path}: no GUIDED stretch with ATT, SIM and SIM2")
    i = starts[-1]
    t0 = modes[i][0] + after_s
    t1 = modes[i + 1][0] if i + 1 < len(modes) else math.inf
    att, sim, s2 = (np.array(rows[k]) for k in ("ATT", "SIM", "SIM2"))
    ta = att[:, 0]
    w = (ta >= t0) & (ta < t1)
    if np.count_nonzero(w) < 100:
        raise SystemExit(f"identify: {path}: under 100 ATT samples in the GUIDED stretch")
    ta = ta[w]
    roll_rep, pitch_rep, yaw_rep = (np.radians(att[w, j]) for j in (1, 2, 3))
    roll_true = np.interp(ta, sim[:, 0], np.radians(sim[:, 1]))
    pitch_true = np.interp(ta, sim[:, 0], np.radians(sim[:, 2]))
    yaw_u = np.unwrap(np.radians(sim[:, 3]))
    yaw_true = np.interp(ta, sim[:, 0], yaw_u)
    psi_dot = np.interp(ta, sim[:, 0], np.gradient(yaw_u, sim[:, 0]))
    v = np.interp(ta, s2[:, 0], s2[:, 1])
    dyaw = (yaw_rep - yaw_true + math.pi) % (2.0 * math.pi) - math.pi

    def stat(x: np.ndarray) -> dict[str, float]:
        return {"mean_deg": float(np.degrees(x.mean())), "sd_deg": float(np.degrees(x.std()))}

    return {
        "log": str(path),
        "window_s": [float(ta[0]), float(ta[-1])],
        "roll_true": stat(roll_true),
        "reported_minus_true": {
            "roll": stat(roll_rep - roll_true),
            "pitch": stat(pitch_rep - pitch_true),
            "yaw": stat(dyaw),
        },
        "turn_per_reported_bank": turn_per_bank_windows(ta, roll_rep, psi_dot, v),
        "turn_per_true_bank": turn_per_bank_windows(ta, roll_true, psi_dot, v),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("autopilot", choices=("arduplane", "px4"))
    ap.add_argument("--out", required=True)
    ap.add_argument("--bundle", default=None, help="the unpacked SITL bundle")
    ap.add_argument("--instance", type=int, default=4, help="ArduPlane -I (TCP 5760 + 10 I)")
    ap.add_argument("--alt", type=float, default=100.0)
    ap.add_argument(
        "--circles",
        nargs="*",
        default=[],
        help="bridge tlogs of still-air circles on this firmware (the wind estimator)",
    )
    ap.add_argument(
        "--wind-flight",
        nargs=2,
        metavar=("TLOG", "SPEED"),
        default=None,
        help="a bridge tlog in a steady wind of SPEED m/s (the reported wind's scale)",
    )
    ap.add_argument("--reuse", action="store_true", help="re-fit DIR's last flight, fly nothing")
    ap.add_argument(
        "--ulog",
        nargs="+",
        default=None,
        help="PX4: fit the EKF2 error model to these ULogs of OFFBOARD flights "
        "(SIH ground truth), fly nothing",
    )
    ap.add_argument(
        "--base",
        default=str(ROOT / "configs" / "autopilots" / "px4-1.16-sih.yaml"),
        help="PX4 with --ulog: the profile whose other sections are kept",
    )
    ap.add_argument(
        "--dataflash",
        nargs="+",
        default=None,
        help="ArduPlane: what the firmware reports in these dataflash logs of bridge flights "
        "(ATT against SIM, the turn per bank over windows; dataflash.json), fly nothing",
    )
    a = ap.parse_args(argv)
    out = Path(a.out).resolve()
    cmd = "python -m lab.calibration.identify " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    if a.dataflash:
        if a.autopilot != "arduplane":
            print("identify: --dataflash is for arduplane", file=sys.stderr)
            return 2
        missing = [d for d in a.dataflash if not Path(d).is_file()]
        if missing:
            print(f"identify: {missing[0]}: no such file", file=sys.stderr)
            return 2
        out.mkdir(parents=True, exist_ok=True)
        rep = [dataflash_turn(Path(d)) for d in a.dataflash]
        (out / "dataflash.json").write_text(json.dumps(rep, indent=1))
        print(json.dumps(rep, indent=1))
        return 0
    if a.ulog:
        if a.autopilot != "px4":
            print("identify: --ulog is for px4", file=sys.stderr)
            return 2
        missing = [u for u in [*a.ulog, a.base] if not Path(u).is_file()]
        if missing:
            print(f"identify: {missing[0]}: no such file", file=sys.stderr)
            return 2
        out.mkdir(parents=True, exist_ok=True)
        fits = [ekf_errors(Path(u)) for u in a.ulog]
        (out / "fit.json").write_text(json.dumps(fits, indent=1))
        path = write_px4_profile(fits, Path(a.base), out, cmd)
        print(json.dumps(fits, indent=1))
        print(f"profile: {path}")
        return 0
    res = _identify(a, out)
    if a.circles:
        circles = [circle_wind_error(Path(t)) for t in a.circles]
        res["circles"] = circles
        res["wind_estimator"] = fit_wind_estimator(circles)
        leads = [position_lead(Path(t)) for t in a.circles]
        res["position_lead"] = leads
    if a.wind_flight:
        c = circle_wind_error(Path(a.wind_flight[0]))
        res["wind_scale"] = math.hypot(c["north"], c["east"]) / float(a.wind_flight[1])
    (out / "fit.json").write_text(json.dumps(res, indent=1))
    fw = FIRMWARE[a.autopilot]
    path = write_profile(res, a.autopilot, fw, out, cmd)
    print(json.dumps({k: v for k, v in res.items() if k != "turn"}, indent=1))
    print(json.dumps(res["turn"], indent=1))
    print(f"profile: {path}")
    return 0


FIRMWARE = {
    "px4": "PX4 v1.16.0 SITL, SIH airplane (airframe 10041), stock parameters",
    "arduplane": "ArduPlane 4.7.0-dev SITL, plane model, stock parameters",
}


def _identify(a: Any, out: Path) -> dict[str, Any]:
    if a.reuse:
        res = json.loads((out / "fit.json").read_text())
        turns = res["turn"]["turns"]
        x = np.array([G * math.tan(math.radians(r["bank_deg"])) / r["groundspeed"] for r in turns])
        y = np.array([r["chi_dot"] for r in turns])
        res["turn"]["turn_gain"] = float(x @ y / (x @ x))
        return res
    from lab.calibration.calibrate import find_bundle
    from lab.rigs.bundles import RigError, check_bundle, unpack

    spec = a.bundle or find_bundle(a.autopilot)
    if spec is None:
        raise SystemExit(
            f"identify: no {a.autopilot} bundle (--bundle, MPF_SITL_DIR or ../shared/sitl)"
        )
    try:
        bundle = unpack(a.autopilot, check_bundle(a.autopilot, str(spec)))
    except RigError as e:
        raise SystemExit(f"identify: {e}") from None
    if a.autopilot == "px4":
        out.mkdir(parents=True, exist_ok=True)
        return identify_px4(out, bundle, a.alt)
    out.mkdir(parents=True, exist_ok=True)
    return identify_arduplane(out, bundle, a.instance, a.alt)


if __name__ == "__main__":
    raise SystemExit(main())
