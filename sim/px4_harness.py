"""A small PX4 SITL harness for the calibration check (:mod:`sim.calibrate`): one flight of the
real PX4 v1.16 SIH airplane with stock parameters, the bridge flying a mission placed where the
aircraft is. What a user does by hand:

1. holds ``/tmp/mpf-px4.lock`` (PX4 SITL has fixed UDP ports: one instance per machine) and starts
   ``px4-sih-airplane WORKDIR`` from the unpacked bundle;
2. on the ground-station link (``udpout:127.0.0.1:18570``) sends MAV_CMD_NAV_TAKEOFF with param7
   = home AMSL + the path altitude, arms, and waits for AUTO.LOITER at that altitude;
3. places the circle tangent to the aircraft's flight (:func:`sim.rigs.common.place_mission`) and
   hands over to ``mpf-mavlink run configs/bridge_px4.yaml --connect udpin:0.0.0.0:14540``;
4. stops PX4 (SIGTERM, then SIGKILL) and releases the lock.
"""

from __future__ import annotations

import fcntl
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
LOCK = "/tmp/mpf-px4.lock"
PX4_LOITER = (4 << 16) | (3 << 24)  # AUTO.LOITER custom_mode


class Px4Gcs:
    """The ground-station link: what PX4 streams to it, arming, commands."""

    def __init__(self, url: str = "udpout:127.0.0.1:18570", timeout_s: float = 60.0) -> None:
        self.c = mavutil.mavlink_connection(url, source_system=255, source_component=190)
        self.last: dict[str, Any] = {}
        t_end = time.monotonic() + timeout_s
        while time.monotonic() < t_end:
            self.c.mav.heartbeat_send(6, 8, 0, 0, 0)  # GCS heartbeat: PX4 answers the peer
            hb = self.c.recv_match(type="HEARTBEAT", blocking=True, timeout=1.0)
            if hb is not None and hb.get_srcComponent() == 1:
                self.sys, self.comp = hb.get_srcSystem(), 1
                self.last["HEARTBEAT"] = hb
                return
        raise RuntimeError(f"no PX4 HEARTBEAT on {url} within {timeout_s:g} s")

    def pump(self, secs: float) -> None:
        t_end, next_hb = time.monotonic() + secs, 0.0
        while True:
            now = time.monotonic()
            if now >= t_end:
                return
            if now >= next_hb:
                self.c.mav.heartbeat_send(6, 8, 0, 0, 0)
                next_hb = now + 1.0
            m = self.c.recv_match(blocking=True, timeout=min(t_end - now, 0.1))
            if m is None or m.get_srcSystem() != self.sys:
                continue
            if m.get_type() == "HEARTBEAT" and m.get_srcComponent() != 1:
                continue
            self.last[m.get_type()] = m
            if m.get_type() == "STATUSTEXT":
                print(f"  [px4] {m.text}", flush=True)

    def command(self, cmd: int, *p: float) -> None:
        ps = [*p, *[0.0] * (7 - len(p))]
        self.c.mav.command_long_send(self.sys, self.comp, cmd, 0, *ps)

    def mode(self) -> int | None:
        hb = self.last.get("HEARTBEAT")
        return None if hb is None else int(hb.custom_mode)

    def armed(self) -> bool:
        hb = self.last.get("HEARTBEAT")
        return bool(hb and hb.base_mode & 128)


def start_px4(bundle: Path, work: Path) -> subprocess.Popen:
    work.mkdir(parents=True, exist_ok=True)
    log = open(work / "px4.log", "w")  # noqa: SIM115 - lives as long as the process
    return subprocess.Popen(
        [str(bundle / "px4-sih-airplane"), str(work / "px4")], cwd=work, stdout=log,
        stderr=subprocess.STDOUT, start_new_session=True,
    )  # fmt: skip


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(5)


def take_off(g: Px4Gcs, alt_m: float, timeout_s: float = 150.0) -> None:
    """NAV_TAKEOFF to home + alt_m, arm, wait for AUTO.LOITER near that altitude."""
    t_end = time.monotonic() + timeout_s
    while "HOME_POSITION" not in g.last and "GLOBAL_POSITION_INT" not in g.last:
        g.command(512, 242)  # MAV_CMD_REQUEST_MESSAGE HOME_POSITION
        g.pump(1.0)
        if time.monotonic() > t_end:
            raise RuntimeError("PX4 sent no position")
    g.pump(2.0)
    home = g.last.get("HOME_POSITION")
    home_amsl = home.altitude / 1e3 if home is not None else g.last["GLOBAL_POSITION_INT"].alt / 1e3
    nan = float("nan")
    last = -math.inf
    while not g.armed():
        if time.monotonic() > t_end:
            raise RuntimeError("PX4 did not arm in time")
        if time.monotonic() - last > 3.0:
            g.command(22, 0, 0, 0, nan, nan, nan, home_amsl + alt_m)  # MAV_CMD_NAV_TAKEOFF
            g.pump(0.5)
            g.command(400, 1)  # arm
            last = time.monotonic()
        g.pump(0.5)
    print(f"armed; taking off to {alt_m:g} m above home ({home_amsl:.1f} m AMSL)", flush=True)
    while True:
        if time.monotonic() > t_end:
            raise RuntimeError("PX4 take-off did not reach AUTO.LOITER at altitude in time")
        g.pump(0.5)
        gp = g.last.get("GLOBAL_POSITION_INT")
        if g.mode() == PX4_LOITER and gp is not None and gp.relative_alt / 1e3 > alt_m - 5.0:
            break
    g.pump(10.0)  # settle into the loiter
    print(f"loitering at {g.last['GLOBAL_POSITION_INT'].relative_alt / 1e3:.1f} m", flush=True)


def fly_px4(m: Any, out: Path, bundle: Path, duration: float) -> int:
    """One real PX4 flight of mission ``m`` (:class:`sim.calibrate.Mission`) into ``out``."""
    from sim.rigs.common import place_mission

    if not (bundle / "px4-sih-airplane").is_file():
        print(f"calibrate: {bundle}/px4-sih-airplane: no such file", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=False)
    (out.parent / f"{m.name}.mission.json").write_text(json.dumps(m.__dict__))
    with open(LOCK, "w") as lk:
        print("waiting for the PX4 lock...", flush=True)
        fcntl.flock(lk, fcntl.LOCK_EX)
        proc = start_px4(bundle, out / "sitl")
        bridge: subprocess.Popen | None = None
        try:
            time.sleep(3.0)
            g = Px4Gcs()
            take_off(g, m.alt_m)
            centre, _ = place_mission(g, m.radius_m, 6.0)  # type: ignore[arg-type]
            sets = [
                f"target.position_ned_m=[{centre[0]:.2f},{centre[1]:.2f},{centre[2]:.2f}]",
                f"path.radius_m={m.radius_m:g}", "mavlink.plots=false",
            ]  # fmt: skip
            if m.moving:
                sets += ["target.type=constant_turn", "target.speed_m_s=3.0",
                         "target.heading_rad=1.5708"]  # fmt: skip
            (out / "mission_overrides.txt").write_text("\n".join(sets) + "\n")
            cmd = [sys.executable, "-m", "mpf_mavlink.cli", "run",
                   str(ROOT / "configs" / "bridge_px4.yaml"), "--connect", "udpin:0.0.0.0:14540",
                   "--out", str(out / "bridge"), "--duration", f"{duration:g}",
                   *[x for s in sets for x in ("--set", s)]]  # fmt: skip
            print("hand-over: " + " ".join(cmd[2:]), flush=True)
            with open(out / "bridge.log", "w") as blog:
                bridge = subprocess.Popen(cmd, stdout=blog, stderr=subprocess.STDOUT, cwd=ROOT)
                while bridge.poll() is None:
                    g.pump(0.5)
                code = bridge.wait()
            g.pump(2.0)
            return code
        finally:
            if bridge is not None and bridge.poll() is None:
                bridge.terminate()
                bridge.wait(10)
            stop(proc)
            fcntl.flock(lk, fcntl.LOCK_UN)


def identify_px4(out: Path, bundle: Path, alt: float) -> dict[str, Any]:
    """Bank steps and steady turns in OFFBOARD attitude (quaternion + thrust) on real PX4."""
    import numpy as np

    from sim.identify import ARDUPLANE_SCHEDULE, Recorder, _quat, analyse, fly_schedule

    with open(LOCK, "w") as lk:
        fcntl.flock(lk, fcntl.LOCK_EX)
        proc = start_px4(bundle, out / "sitl")
        try:
            time.sleep(3.0)
            g = Px4Gcs()
            take_off(g, alt)
            c = g.c
            for msg_id, hz in ((30, 50), (32, 20), (74, 10)):  # ATTITUDE, LOCAL_POSITION, VFR_HUD
                g.command(511, msg_id, 1e6 / hz)
            rec = Recorder(c, g.sys)
            rec.pump(2.0)
            pitch0 = float(np.mean([r[3] for r in rec.rows["att"][-20:]]))
            hud = g.last.get("VFR_HUD")
            thr = (hud.throttle / 100.0) if hud is not None else 0.8

            def send(roll: float, pitch: float) -> None:
                c.mav.set_attitude_target_send(int(time.monotonic() * 1e3) & 0xFFFFFFFF, g.sys,
                                               1, 7, _quat(roll, pitch, 0.0), 0, 0, 0, thr)  # fmt: skip

            t0 = time.monotonic()
            while time.monotonic() - t0 < 1.5:  # stream before asking for OFFBOARD
                send(0.0, pitch0)
                rec.pump(0.04)
            g.command(176, 1, 6)  # OFFBOARD
            t_start = time.monotonic()
            fly_schedule(rec, send, ARDUPLANE_SCHEDULE, pitch0)
            g.command(176, 1, 4, 3)  # AUTO.LOITER
            rec.pump(1.0)
            gp = g.last["GLOBAL_POSITION_INT"]
            origin = (gp.lat * 1e-7, gp.lon * 1e-7)
        finally:
            stop(proc)
            fcntl.flock(lk, fcntl.LOCK_UN)
    return analyse(rec, t_start, ARDUPLANE_SCHEDULE, pitch0, origin, out)
