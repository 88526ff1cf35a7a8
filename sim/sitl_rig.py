"""Real-firmware rig: fly ``mpf-mavlink run`` against the user's own ArduPlane SITL binary.

``scripts/sitl-arduplane --binary PATH/arduplane --ardupilot PATH/ardupilot`` (or
``python -m sim.sitl_rig``) does what a user does by hand, and nothing more to the autopilot:

1. starts the SITL binary (``--model plane --defaults Tools/autotest/models/plane.parm -I0``,
   stock parameters) in a scratch directory of the run directory, TCP 5760 (SERIAL0, the rig's
   ground-station link) and 5762 (SERIAL1, the bridge's link); both are loopback connections
   (ArduPilot's SITL binds its TCP ports on every address: run it on a machine you trust);
2. takes off as a pilot would: TKOFF_ALT (the only parameter set, the takeoff's own) to the
   path altitude, mode TAKEOFF, arm (retried until the EKF and GPS let it), climb, then LOITER;
3. writes the mission: ``--config`` (default configs/bridge_arduplane.yaml) at the plane's cruise
   airspeed (AIRSPEED_CRUISE, 22 m/s stock), its circle placed so that the aircraft is on it,
   tangent to its flight, where the loiter will have taken it when the bridge engages (the
   checks then pass from where the rig leaves it); stationary or moving (``--moving``) target;
4. hands over to ``mpf-mavlink run`` on SERIAL1 (no rate is set on that link beforehand: the
   bridge negotiates them), waits for it to fly ``--duration`` seconds and hand back;
5. optionally (``--kill-after S``) SIGKILLs the bridge mid-track instead and watches what
   ArduPlane does for ``--watch-s`` seconds (mode, bank, distance from the fallback loiter);
6. flies the same mission and start state in our SIL (``--sil``) and prints one table.

Nothing of ArduPilot is copied here: the binary and the checkout are the user's.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GCS_PORT, BRIDGE_PORT = 5760, 5762
MODES = {"LOITER": 12, "TAKEOFF": 13, "GUIDED": 15, "CRUISE": 7}


class Gcs:
    """The rig's ground-station link (SERIAL0): modes, arming, parameters, what it sees."""

    def __init__(self, url: str, timeout_s: float = 60.0) -> None:
        t_end = time.monotonic() + timeout_s
        last: Exception | None = None
        while time.monotonic() < t_end:
            try:
                self.c = mavutil.mavlink_connection(url, source_system=255, source_component=190)
                break
            except OSError as e:  # SITL not listening yet
                last = e
                time.sleep(0.5)
        else:
            raise RuntimeError(f"no SITL on {url}: {last}")
        hb = self.c.wait_heartbeat(timeout=timeout_s)
        if hb is None:
            raise RuntimeError(f"no HEARTBEAT on {url} within {timeout_s:g} s")
        self.sys, self.comp = hb.get_srcSystem(), hb.get_srcComponent()
        self.last: dict[str, Any] = {}
        for sid, hz in ((6, 5), (10, 10), (11, 5), (2, 1), (3, 2)):  # position, attitude, hud...
            self.c.mav.request_data_stream_send(self.sys, self.comp, sid, hz, 1)

    def pump(self, secs: float) -> None:
        t_end = time.monotonic() + secs
        while True:
            left = t_end - time.monotonic()
            if left <= 0:
                return
            m = self.c.recv_match(blocking=True, timeout=min(left, 0.1))
            if m is not None and m.get_srcSystem() == self.sys:
                if m.get_type() == "HEARTBEAT" and m.get_srcComponent() != self.comp:
                    continue  # the bridge's own HEARTBEAT (component 191), routed by ArduPilot
                self.last[m.get_type()] = m
                if m.get_type() == "STATUSTEXT":
                    print(f"  [sitl] {m.text}", flush=True)

    def mode(self) -> int | None:
        hb = self.last.get("HEARTBEAT")
        return None if hb is None else int(hb.custom_mode)

    def armed(self) -> bool:
        hb = self.last.get("HEARTBEAT")
        return bool(hb and hb.base_mode & 128)

    def set_mode(self, name: str) -> None:
        self.c.mav.command_long_send(self.sys, self.comp, 176, 0, 1, MODES[name], 0, 0, 0, 0, 0)

    def set_param(self, name: str, value: float) -> None:
        self.c.mav.param_set_send(self.sys, self.comp, name.encode(), float(value), 9)

    def get_param(self, name: str, timeout_s: float = 5.0) -> float | None:
        self.c.mav.param_request_read_send(self.sys, self.comp, name.encode(), -1)
        t_end = time.monotonic() + timeout_s
        while time.monotonic() < t_end:
            m = self.c.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.2)
            if m is not None and m.param_id.rstrip("\x00") == name:
                return float(m.param_value)
        return None

    def arm(self) -> None:
        self.c.mav.command_long_send(self.sys, self.comp, 400, 0, 1, 0, 0, 0, 0, 0, 0)


def start_sitl(binary: Path, ardupilot: Path, work: Path, speedup: float) -> subprocess.Popen:
    work.mkdir(parents=True, exist_ok=True)
    parm = ardupilot / "Tools" / "autotest" / "models" / "plane.parm"
    if not parm.is_file():
        raise SystemExit(f"sitl-arduplane: {parm}: no such file (--ardupilot is the checkout)")
    cmd = [str(binary), "--model", "plane", "--defaults", str(parm), "-I0", "--speedup", f"{speedup:g}"]  # fmt: skip
    log = open(work / "sitl.log", "w")  # noqa: SIM115 - lives as long as the process
    return subprocess.Popen(
        cmd, cwd=work, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
    )


def take_off(g: Gcs, alt_m: float, timeout_s: float = 240.0) -> None:
    """TAKEOFF to alt_m (TKOFF_ALT), then LOITER; arming is retried until pre-arm checks pass."""
    g.set_param("TKOFF_ALT", alt_m)
    g.pump(1.0)
    g.set_mode("TAKEOFF")
    t_end = time.monotonic() + timeout_s
    last_arm = -math.inf
    while not g.armed():
        if time.monotonic() > t_end:
            raise RuntimeError("SITL did not arm (pre-arm checks) in time")
        if time.monotonic() - last_arm > 3.0:
            if g.mode() != MODES["TAKEOFF"]:
                g.set_mode("TAKEOFF")
            g.arm()
            last_arm = time.monotonic()
        g.pump(0.5)
    print(f"armed; climbing to {alt_m:g} m", flush=True)
    while True:
        if time.monotonic() > t_end:
            raise RuntimeError("takeoff did not reach the altitude in time")
        g.pump(0.5)
        gp = g.last.get("GLOBAL_POSITION_INT")
        if gp is not None and gp.relative_alt / 1000.0 >= alt_m - 3.0:
            break
    g.set_mode("LOITER")
    g.pump(15.0)  # settle into the loiter at that altitude
    print(f"loitering at {g.last['GLOBAL_POSITION_INT'].relative_alt / 1000.0:.1f} m", flush=True)


def place_mission(g: Gcs, radius: float, lead_s: float) -> tuple[list[float], float, list[float]]:
    """(circle centre NED, heading at engage, predicted start NED): the aircraft on a clockwise
    circle of ``radius``, tangent to its flight, where the current turn takes it in lead_s."""
    lp = g.last["LOCAL_POSITION_NED"]
    att = g.last["ATTITUDE"]
    vx, vy = lp.vx, lp.vy
    v = math.hypot(vx, vy)
    chi = math.atan2(vy, vx)
    # turn rate from the attitude: heading rate of a coordinated turn
    w = 9.80665 * math.tan(att.roll) / max(v, 1.0)
    x, y = lp.x, lp.y
    if abs(w) > 1e-3:
        r = v / w
        cx, cy = x - r * math.sin(chi), y + r * math.cos(chi)
        chi2 = chi + w * lead_s
        x, y = cx + r * math.sin(chi2), cy - r * math.cos(chi2)
    else:
        chi2 = chi
        x, y = x + vx * lead_s, y + vy * lead_s
    # clockwise seen from above: the centre is to the right of the flight direction
    centre = [x - radius * math.sin(chi2), y + radius * math.cos(chi2), lp.z]
    return centre, chi2, [x, y, lp.z]


def mission_overrides(centre: list[float], cruise: float, moving: bool) -> list[str]:
    sets = [
        f"target.position_ned_m=[{centre[0]:.2f},{centre[1]:.2f},{centre[2]:.2f}]",
        f"vehicle.airspeed_m_s={cruise:g}",
        f"vehicle.airspeed_min_m_s={cruise - 4:g}",
        f"vehicle.airspeed_max_m_s={cruise + 4:g}",
        # at 22 m/s the gain condition needs K_R > v_max^2 / (v_min c1 (1 - 2 c2)^2) = 0.50
        "guidance.K_R=1.0",
        "mavlink.plots=false",
    ]
    if not moving:
        sets += ["target.type=stationary"]
    return sets


def read_metrics(d: Path) -> dict[str, Any]:
    p = d / "metrics.json"
    return json.loads(p.read_text()) if p.is_file() else {}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--binary", required=True, help="the arduplane SITL binary you built")
    ap.add_argument("--ardupilot", required=True, help="its ArduPilot checkout (plane.parm)")
    ap.add_argument("--config", default=str(ROOT / "configs" / "bridge_arduplane.yaml"))
    ap.add_argument("--out", default="runs/sitl-arduplane")
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--alt", type=float, default=100.0, help="takeoff / path altitude (m)")
    ap.add_argument("--radius", type=float, default=150.0)
    ap.add_argument("--moving", action="store_true", help="the config's moving target")
    ap.add_argument("--lead", type=float, default=6.0, help="s from placing to engaging")
    ap.add_argument("--speedup", type=float, default=1.0)
    ap.add_argument("--kill-after", type=float, default=None, help="SIGKILL the bridge after S s")
    ap.add_argument("--watch-s", type=float, default=40.0)
    ap.add_argument("--sil", action="store_true", help="fly the same mission in our SIL too")
    a = ap.parse_args(argv)
    binary, ardupilot = Path(a.binary), Path(a.ardupilot)
    if not (binary.is_file() and os.access(binary, os.X_OK)):
        print(f"sitl-arduplane: {binary}: not an executable file", file=sys.stderr)
        return 2
    out = Path(a.out)
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    proc = start_sitl(binary, ardupilot, out / "sitl", a.speedup)
    bridge: subprocess.Popen | None = None
    rows: list[tuple[str, str]] = []
    rc = 1
    try:
        g = Gcs(f"tcp:127.0.0.1:{GCS_PORT}")
        take_off(g, a.alt)
        cruise = g.get_param("AIRSPEED_CRUISE") or 22.0
        centre, heading, start = place_mission(g, a.radius, a.lead)
        sets = mission_overrides(centre, cruise, a.moving)
        sets += [f"path.radius_m={a.radius:g}"]
        (out / "mission_overrides.txt").write_text("\n".join(sets) + "\n")
        cmd = [sys.executable, "-m", "mpf_mavlink.cli", "run", a.config, "--connect",
               f"tcp:127.0.0.1:{BRIDGE_PORT}", "--out", str(out / "bridge"),
               "--duration", f"{a.duration:g}", *[x for s in sets for x in ("--set", s)]]  # fmt: skip
        print("hand-over: " + " ".join(cmd[2:]), flush=True)
        blog = open(out / "bridge.log", "w")  # noqa: SIM115
        bridge = subprocess.Popen(cmd, stdout=blog, stderr=subprocess.STDOUT, text=True)
        t0 = time.monotonic()
        kill_info: dict[str, Any] = {}
        while bridge.poll() is None:
            g.pump(0.5)
            if a.kill_after is not None and g.mode() == MODES["GUIDED"] and not kill_info:
                if time.monotonic() - t0 > a.kill_after:
                    os.kill(bridge.pid, signal.SIGKILL)
                    bridge.wait()
                    kill_info = watch_after_kill(g, a.watch_s, out)
                    break
        code = bridge.wait()
        m = read_metrics(out / "bridge")
        if not m:  # a SIGKILLed bridge writes no metrics.json: what its log said before dying
            for line in (out / "bridge.log").read_text().splitlines():
                if line.startswith("fallback if the bridge dies: "):
                    m["fallback"] = line.split(": ", 1)[1]
                if line.startswith("GUIDED confirmed"):
                    m["state_reached"] = "TRACKING"
        rows = table_rows(m, code, a, cruise, kill_info)
        if a.sil and not kill_info:
            rows += sil_rows(a, sets, m, out)
        # 6: ran to its end, shorter than its steady window (NOT JUDGED): the table says so
        rc = 0 if (code in (0, 6) or kill_info) else code
    finally:
        if bridge is not None and bridge.poll() is None:
            bridge.terminate()
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
    print_table(rows, out)
    return rc


def watch_after_kill(g: Gcs, secs: float, out: Path) -> dict[str, Any]:
    """After the bridge's SIGKILL: ArduPlane's mode, peak bank and throttle, and how far it ends
    from the fallback loiter the bridge set (its guided target)."""
    t0 = time.monotonic()
    peak_bank, modes, trace = 0.0, set(), []
    while time.monotonic() - t0 < secs:
        g.pump(0.2)
        att, hud = g.last.get("ATTITUDE"), g.last.get("VFR_HUD")
        if att is not None:
            peak_bank = max(peak_bank, abs(math.degrees(att.roll)))
        if g.mode() is not None:
            modes.add(g.mode())
        lp = g.last.get("LOCAL_POSITION_NED")
        if att is not None and lp is not None:
            trace.append(
                (
                    time.monotonic() - t0,
                    math.degrees(att.roll),
                    hud.throttle if hud else -1,
                    lp.x,
                    lp.y,
                    lp.z,
                )
            )
    (out / "after_kill.csv").write_text(
        "t,roll_deg,throttle_pct,x,y,z\n"
        + "\n".join(",".join(f"{v:.3f}" for v in r) for r in trace)
    )
    info: dict[str, Any] = {"peak_bank_deg": peak_bank, "modes": sorted(modes), "trace": trace}
    ov = (out / "mission_overrides.txt").read_text().splitlines()[0]
    cx, cy, _ = (float(v) for v in ov.split("=", 1)[1].strip("[]").split(","))
    tail = [r for r in trace if r[0] >= secs - 15.0]
    if tail:  # the last 15 s: where ArduPlane's own navigation has taken it
        info["radius_m"] = sum(math.hypot(r[3] - cx, r[4] - cy) for r in tail) / len(tail)
        info["alt_m"] = sum(-r[5] for r in tail) / len(tail)
        info["bank_deg"] = sum(abs(r[1]) for r in tail) / len(tail)
    return info


def _f(v: Any, fmt: str = ".3g") -> str:
    return "n/a" if v is None else (f"{v:{fmt}}" if isinstance(v, (int, float)) else str(v))


def table_rows(
    m: dict[str, Any], code: int, a: Any, cruise: float, kill: dict[str, Any]
) -> list[tuple[str, str]]:
    c = m.get("counters", {})
    rows = [
        ("target", "moving (3 m/s)" if a.moving else "stationary"),
        ("cruise airspeed (AIRSPEED_CRUISE)", f"{cruise:g} m/s"),
        ("bridge exit", f"{m.get('exit_reason', '?')} (code {code})"),
        ("engaged / tracked", f"{m.get('state_reached', '?')} / {_f(m.get('tracked_s'), '.1f')} s"),
        ("hand-back confirmed", str(m.get("handback_confirmed"))),
        ("stream rates", "; ".join(f"{k} {v['requested_hz']:g}->{v['measured_hz']:.1f}" for k, v in m.get("streams", {}).get("messages", {}).items())),
        ("fallback", m.get("fallback", "")),
        ("first within / stays within", f"{_f(m.get('first_within_s'), '.1f')} / {_f(m.get('convergence_time_s'), '.1f')} s"),
        ("steady RMS |pt|", f"{_f(m.get('steady_rms_m'))} m"),
        ("steady max |pt|", f"{_f(m.get('steady_max_m'))} m"),
        ("steady mean vertical (up +)", f"{_f(m.get('steady_mean_vertical_m'))} m"),
        ("steady mean radial (out +)", f"{_f(m.get('steady_mean_radial_m'))} m"),
        ("thrust at ceiling", _f(m.get("thrust_saturated_fraction"))),
        ("learned trim / turn gain", f"{_f((m.get('adapter_learned') or {}).get('trim_pitch_rad'))} rad / {_f((m.get('adapter_learned') or {}).get('turn_gain'))}"),
        ("setpoints sent", str(c.get("setpoints_sent"))),
    ]  # fmt: skip
    if kill:
        rows += [
            ("after SIGKILL: modes seen", ", ".join(str(x) for x in kill["modes"])),
            ("after SIGKILL: peak |bank|", f"{kill['peak_bank_deg']:.1f} deg over {a.watch_s:g} s"),
            ("after SIGKILL: last 15 s", f"{_f(kill.get('radius_m'), '.1f')} m from the path centre, {_f(kill.get('alt_m'), '.1f')} m up, |bank| {_f(kill.get('bank_deg'), '.1f')} deg"),
        ]  # fmt: skip
    return rows


def sil_rows(a: Any, sets: list[str], m: dict[str, Any], out: Path) -> list[tuple[str, str]]:
    """Our SIL on the same mission and start state (the real aircraft's state at engagement)."""
    ts = out / "bridge" / "timeseries.csv"
    if not ts.is_file():
        return [("our SIL", "not flown (no real run)")]
    import numpy as np

    d = np.genfromtxt(ts, delimiter=",", names=True, max_rows=2)
    p0 = [float(d["p_n"][0]), float(d["p_e"][0]), float(d["p_d"][0])]
    cruise = next(float(s.split("=")[1]) for s in sets if s.startswith("vehicle.airspeed_m_s"))
    sil_sets = [*sets, "sil.link=udp", "sil.flavour=ardupilot", "sil.initial_mode=cruise",
                f"sil.initial_position_ned_m=[{p0[0]:.2f},{p0[1]:.2f},{p0[2]:.2f}]",
                f"aircraft.trim_airspeed_m_s={cruise:g}"]  # fmt: skip
    heading = _heading_at_start(out)
    if heading is not None:
        sil_sets.append(f"sil.initial_heading_rad={heading:.4f}")
    cmd = [sys.executable, "-m", "mpf_mavlink.cli", "sim", a.config, "--out", str(out / "sil"),
           "--set", f"sim.duration_s={a.duration:g}", *[x for s in sil_sets for x in ("--set", s)]]  # fmt: skip
    with open(out / "sil.log", "w") as f:
        subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, check=False)
    sm = read_metrics(out / "sil")
    real, ours = m.get("steady_rms_m"), sm.get("steady_rms_m")
    ratio = real / ours if (real is not None and ours) else None
    return [
        ("our SIL: steady RMS |pt|", f"{_f(ours)} m"),
        ("our SIL: mean vertical / radial", f"{_f(sm.get('steady_mean_vertical_m'))} / {_f(sm.get('steady_mean_radial_m'))} m"),
        ("real / our SIL RMS", _f(ratio)),
    ]  # fmt: skip


def _heading_at_start(out: Path) -> float | None:
    import numpy as np

    ts = out / "bridge" / "timeseries.csv"
    d = np.genfromtxt(ts, delimiter=",", names=True, max_rows=30)
    if len(d) < 2:
        return None
    return float(math.atan2(d["p_e"][-1] - d["p_e"][0], d["p_n"][-1] - d["p_n"][0]))


def print_table(rows: list[tuple[str, str]], out: Path) -> None:
    w = max((len(k) for k, _ in rows), default=10)
    print("")
    print(f"{'ArduPlane SITL rig':<{w}}  result")
    print("-" * (w + 40))
    for k, v in rows:
        print(f"{k:<{w}}  {v}")
    print(
        f"{'run directory':<{w}}  {out}  (sitl/, bridge/, bridge.log{', sil/' if (out / 'sil').exists() else ''})"
    )


if __name__ == "__main__":
    raise SystemExit(main())
