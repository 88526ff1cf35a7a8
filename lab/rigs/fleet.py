"""A fleet on the real firmware: ``scripts/sitl arduplane --fleet N --out DIR`` (docs/fleet.md).

N ArduPlane SITL instances (each its own free ``-I``, lock and ports), taken off together
(their loiters put them where they are), the config's circle placed about the first one's
loiter, then N ``mpf-mavlink run`` bridges started one after another ``--fleet-gap`` s apart
(each with ``fleet.member`` k, the slots 360/N apart, a direct UDP mesh on loopback and the
same target epoch). ``--fleet-loss`` / ``--fleet-jitter`` put the soak relay
(:mod:`lab.soak.relay`) in front of every bridge's coordination port; ``--kill-after S``
SIGKILLs bridge ``--kill-member`` S s after the last engagement and watches that aircraft's
autopilot (mode and hold) while the others fly on.

Figures (DIR/fleet.json, printed as a table): per aircraft the bridge's figures (steady RMS /
max of |pt|, cross-track), for the fleet the spacing error (the along-path distance between
neighbours against their slots, from each bridge's fleet.csv on the common clock), the time to
converge (every pair within ``--converge-m`` for good, counted from the last engagement), the
RMS and max after it; after a kill the same for the survivors against the re-spaced slots (or
the held ones). Figures: DIR/fleet_tracks.png, DIR/fleet_spacing.png (lab/rigs/fleet_figures.py).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from lab.rigs import arduplane
from lab.rigs.bundles import RigError, unpack
from lab.rigs.figures import fmt, hold_figures, read_json
from lab.rigs.gcs import Gcs


def _free_udp_ports(n: int) -> list[int]:
    socks, out = [], []
    for _ in range(n):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        socks.append(s)
        out.append(s.getsockname()[1])
    for s in socks:
        s.close()
    return out


def fleet_sets(n: int, k: int, listen: list[int], send_to: list[int], epoch: float) -> list[str]:
    """The ``--set`` overrides of member k of n: slots 360/n apart, its own listening port, a
    ``udpout`` to every other member's (relayed) port, the common target epoch."""
    links = [f"udpin:127.0.0.1:{listen[k]}"] + [
        f"udpout:127.0.0.1:{send_to[j]}" for j in range(n) if j != k
    ]
    slots = ",".join(f"{360.0 * j / n:.6f}" for j in range(n))
    return [
        "fleet.enabled=true",
        f"fleet.member={k}",
        f"fleet.slots_deg=[{slots}]",
        "fleet.links=[" + ",".join(f'"{u}"' for u in links) + "]",
        f"fleet.target_epoch_unix_s={epoch:.3f}",
        # three SITLs and three bridges on two shared cores: a 0.5 s stall of the machine
        # (measured: two bridges lost ATTITUDE for 0.68 s at once) is not a lost vehicle
        "mavlink.telemetry_timeout_s=1.5",
    ]


def read_fleet_csv(p: Path) -> dict[str, np.ndarray] | None:
    if not p.is_file():
        return None
    try:
        d = np.genfromtxt(p, delimiter=",", names=True)
    except ValueError:
        return None
    if d.size < 2:
        return None
    return {k: np.atleast_1d(d[k]) for k in d.dtype.names or ()}


def _respaced(slots: list[float], alive: list[bool]) -> list[float | None]:
    from mpf_mavlink.core.guidance.coordination import respaced_slots

    return respaced_slots(slots, alive)


def spacing_series(
    tracks: list[dict[str, np.ndarray] | None],
    slots: list[float],
    length_m: float,
    respace: bool,
    hz: float = 2.0,
) -> dict[str, np.ndarray]:
    """On a common Unix-time grid: the worst neighbour spacing error (m) and every pair's, of
    the members that report then (a member is there while its fleet.csv has rows within 1 s)."""
    spans = [(tr["t_unix_s"][0], tr["t_unix_s"][-1]) for tr in tracks if tr is not None]
    t0 = min(a for a, _ in spans)
    t1 = max(b for _, b in spans)
    grid = np.arange(t0, t1, 1.0 / hz)
    worst = np.full(len(grid), np.nan)
    n_alive = np.zeros(len(grid), int)
    pairs: list[list[float]] = []
    for gi, t in enumerate(grid):
        alive = []
        s_now = []
        for tr in tracks:
            if tr is None:
                alive.append(False)
                s_now.append(0.0)
                continue
            tu = tr["t_unix_s"]
            j = int(np.searchsorted(tu, t))
            ok = 0 < j < len(tu) and tu[j] - tu[j - 1] < 1.0
            alive.append(bool(ok))
            # shat: s itself, or the lap-time coordinate of spacing in time (fleet.csv shat_m)
            col = tr["shat_m"] if "shat_m" in tr else tr["s_m"]
            s_now.append(float(np.interp(t, tu, col)) if ok else 0.0)
        n = sum(alive)
        n_alive[gi] = n
        if n < 2:
            pairs.append([])
            continue
        sl = (
            _respaced(slots, alive)
            if respace
            else [s if a else None for s, a in zip(slots, alive, strict=True)]
        )
        members = sorted((float(sl[k] or 0.0), k) for k in range(len(tracks)) if alive[k])
        errs = []
        for a in range(len(members)):
            if n == 2 and a == 1:
                break  # two on a lap: one gap (the other is its complement)
            (sa, ka), (sb, kb) = members[a], members[(a + 1) % len(members)]
            xa = s_now[ka] - sa * length_m
            xb = s_now[kb] - sb * length_m
            errs.append((xb - xa + 0.5 * length_m) % length_m - 0.5 * length_m)
        pairs.append(errs)
        worst[gi] = max(abs(e) for e in errs)
    return {"t_unix_s": grid, "worst_m": worst, "n_alive": n_alive, "pairs": pairs}  # type: ignore[dict-item]


def spacing_figures(
    ser: dict[str, Any], t_from: float, t_to: float, converge_m: float, n_want: int
) -> dict[str, Any]:
    """Time to converge (s after t_from: every pair within converge_m from then to t_to, with
    n_want members there), and the RMS / max of every pair's error after it."""
    t, worst, na = ser["t_unix_s"], ser["worst_m"], ser["n_alive"]
    m = (t >= t_from) & (t <= t_to) & (na == n_want)
    if not m.any():
        return {"converged": False, "why": f"never {n_want} members together"}
    idx = np.flatnonzero(m)
    bad = [i for i in idx if not worst[i] <= converge_m]
    first = idx[0] if not bad else (bad[-1] + 1)
    if first > idx[-1]:
        return {
            "converged": False,
            "worst_at_end_m": float(worst[idx[-1]]),
            "window_s": float(t[idx[-1]] - t_from),
        }
    after = [e for i in idx if i >= first for e in ser["pairs"][i]]
    a = np.abs(np.array(after))
    return {
        "converged": True,
        "converge_s": float(t[first] - t_from),
        "spacing_rms_m": float(np.sqrt(np.mean(a**2))),
        "spacing_max_m": float(a.max()),
        "judged_s": float(t[idx[-1]] - t[first]),
        "start_spread_worst_m": float(worst[idx[0]]),
    }


def fleet_spacing(
    out: Path, n: int, path: Any, respace: bool, t_all: float, t_kill: float | None,
    converge_m: float,
) -> tuple[dict[str, Any], dict[str, Any], float]:  # fmt: skip
    """The spacing series of DIR's bridges' fleet.csv, its figures from ``t_all`` (Unix s, the
    last engagement) to the kill and the survivors' after it, and the path's length (m)."""
    from mpf_mavlink.config.scenario import build_path

    L = float(build_path(path).length)
    tracks = [read_fleet_csv(out / f"bridge{k}" / "fleet.csv") for k in range(n)]
    if all(tr is None for tr in tracks):
        raise RigError("no fleet.csv from any bridge")
    ser = spacing_series(tracks, [j / n for j in range(n)], L, respace)
    fl = spacing_figures(ser, t_all, t_kill if t_kill is not None else math.inf, converge_m, n)
    if t_kill is not None:
        fl["after_kill"] = spacing_figures(ser, t_kill, math.inf, converge_m, n - 1)
    return ser, fl, L


@dataclasses.dataclass
class _Fleet:
    """The fleet's live parts (firmware, ground stations, bridges, relays) and what the rig saw
    of them: each engagement (wall time, s), the last one's, the kill and the hold after it."""

    n: int
    centre: list[float] = dataclasses.field(default_factory=list)  # the placed circle's (m, NED)
    radius: float = 0.0
    epoch: float = 0.0  # the common target epoch (Unix s)
    ports: tuple[list[int], list[int]] = ([], [])  # each member's own, the one sent to
    fws: list[Any] = dataclasses.field(default_factory=list)
    gcs: list[Gcs] = dataclasses.field(default_factory=list)
    bridges: list[subprocess.Popen[str] | None] = dataclasses.field(default_factory=list)
    relays: list[Any] = dataclasses.field(default_factory=list)
    engaged: list[float | None] = dataclasses.field(default_factory=list)
    t_all: float = 0.0
    t_kill: float | None = None
    kill_info: dict[str, Any] = dataclasses.field(default_factory=dict)
    trace: list[tuple[float, float, float, float, float]] = dataclasses.field(default_factory=list)
    modes_after: list[str] = dataclasses.field(default_factory=list)

    def __post_init__(self) -> None:
        self.bridges, self.engaged = [None] * self.n, [None] * self.n

    def pump(self, track_mode: str) -> None:
        """Pump every ground station 0.05 s, noting each started aircraft's first ``track_mode``."""
        for j, g in enumerate(self.gcs):
            g.pump(0.05, echo=False)
            if self.engaged[j] is None and g.mode() == track_mode and self.bridges[j] is not None:
                self.engaged[j] = time.time()
                print(f"aircraft {j} in {track_mode}", flush=True)

    def kill(self, km: int) -> None:
        """SIGKILL bridge ``km`` and note when, after the last engagement and its own."""
        b = self.bridges[km]
        assert b is not None
        os.kill(b.pid, signal.SIGKILL)
        b.wait()
        self.t_kill = t_kill = time.time()
        self.kill_info = {
            "member": km,
            "killed_after_s": t_kill - self.t_all,
            "killed_after_engaged_s": t_kill - (self.engaged[km] or t_kill),
        }
        print(f"bridge {km} SIGKILLed {t_kill - self.t_all:.1f} s after the last engagement",
              flush=True)  # fmt: skip


def _start_fleet(a: argparse.Namespace, v: dict[str, Any], f: _Fleet, s: dict[str, Any]) -> None:
    """Start the n instances (each takes a free instance's lock), configure and take them off
    ``--takeoff-gap`` s apart, along the climb-out and loiter."""
    from lab.rigs.common import _flight_header, connect

    mod = v["mod"]
    for _ in range(f.n):
        f.fws.append(mod.Firmware(argparse.Namespace(**{**vars(a), "instance": None})))
    bundle_dir = unpack(a.autopilot, v["bundle"])
    s.update(_flight_header(a, v, bundle_dir))
    s["instances"] = [fw.instance for fw in f.fws]
    print(f"{s['bundle']}: starting {f.n} instances {s['instances']}", flush=True)
    for k, fw in enumerate(f.fws):
        fw.start(bundle_dir, v["out"] / f"firmware{k}")
    f.gcs.extend(connect(fw, mod, a.params)[0] for fw in f.fws)
    errs: list[str] = []

    def up(k: int) -> None:
        try:
            time.sleep(k * a.takeoff_gap)
            f.fws[k].take_off(f.gcs[k], a.alt)
        except Exception as e:  # noqa: BLE001 - reported below
            errs.append(f"aircraft {k}: {e}")

    ths = [threading.Thread(target=up, args=(k,), daemon=True) for k in range(f.n)]
    for th in ths:
        th.start()
    while any(th.is_alive() for th in ths):
        time.sleep(0.5)
    if errs:
        raise RigError("; ".join(errs))


def _place_fleet(a: argparse.Namespace, v: dict[str, Any], f: _Fleet, s: dict[str, Any]) -> None:
    """The circle about the first aircraft's loiter, the common target epoch and the coordination
    ports (the one sent to: a relay's under ``--fleet-loss`` / ``--fleet-jitter``)."""
    from lab.rigs.common import place_mission

    cfg = v["cfg"]
    f.radius = radius = float(cfg.path.radius_m) if cfg.path.type == "circle" else 0.0
    for g in f.gcs:
        g.pump(0.2, echo=False)
    f.centre, _ = place_mission(f.gcs[0], radius, a.lead * a.speedup)
    f.epoch = time.time() + a.lead
    listen = _free_udp_ports(f.n)
    send_to = list(listen)
    if a.fleet_loss or a.fleet_jitter:
        from lab.soak.relay import Impairment, UdpRelay

        imp = Impairment(loss=a.fleet_loss, jitter_s=a.fleet_jitter)
        for k in range(f.n):  # every member's reports to k pass k's relay
            r = UdpRelay(0, listen[k], down=imp, seed=k, keep_log=False).start()
            f.relays.append(r)
            send_to[k] = r.vehicle_port
    f.ports = (listen, send_to)
    s["mission"] = {
        "centre_ned_m": f.centre, "radius_m": radius, "target": v["target_label"],
        "epoch_unix_s": f.epoch, "link": {"loss": a.fleet_loss, "jitter_s": a.fleet_jitter},
    }  # fmt: skip


def _start_bridges(a: argparse.Namespace, v: dict[str, Any], f: _Fleet) -> None:
    """Start the n bridges ``--fleet-gap`` s apart (each to end about when the last does),
    noting engagements in between."""
    from lab.rigs.common import _bridge_command, mission_sets, start_bridge

    n, out = f.n, v["out"]
    for k in range(n):
        sets = [*mission_sets(a, v, f.centre), *fleet_sets(n, k, *f.ports, f.epoch)]
        dur = a.duration + (n - 1 - k) * a.fleet_gap  # every bridge ends about together
        ak = argparse.Namespace(**{**vars(a), "duration": dur})
        cmd = _bridge_command(ak, v, f.fws[k].bridge_url, sets)
        cmd[cmd.index("--out") + 1] = str(out / f"bridge{k}")
        (out / f"bridge{k}.cmd").write_text(" ".join(cmd) + "\n")
        f.bridges[k] = start_bridge(cmd, out / f"bridge{k}.log")
        t_next = time.time() + a.fleet_gap
        print(f"bridge {k} started on {f.fws[k].bridge_url}", flush=True)
        while time.time() < t_next and k < n - 1:
            f.pump(v["mod"].TRACK_MODE)
    e = f.engaged
    f.t_all = max(t for t in e if t is not None) if all(e) else time.time()


def _fly_until_done(a: argparse.Namespace, track_mode: str, f: _Fleet) -> None:
    """Pump until every bridge has exited; SIGKILL ``--kill-member`` ``--kill-after`` s after
    the last engagement and watch its autopilot for ``--watch-s`` s."""
    while any(b is not None and b.poll() is None for b in f.bridges):
        f.pump(track_mode)
        if all(f.engaged):
            f.t_all = max(t for t in f.engaged if t is not None)
        if a.kill_after is not None and f.t_kill is None and all(f.engaged):
            if time.time() - f.t_all >= a.kill_after:
                f.kill(a.kill_member)
        if f.t_kill is not None and time.time() - f.t_kill <= a.watch_s:
            f.gcs[a.kill_member].note_hold(f.modes_after, f.trace, time.time() - f.t_kill)


def _kill_hold(a: argparse.Namespace, v: dict[str, Any], f: _Fleet) -> None:
    """The killed aircraft's hold about the path's centre where the target was at the kill (the
    bridge re-places its fallback loiter with the target: ``mavlink.fallback_follow_s``), into
    ``kill_info``; FAIL when its autopilot left the track and hold modes."""
    from lab.rigs.common import hold_bank_limit_deg
    from mpf_mavlink.config.scenario import build_target

    mod, cfg = v["mod"], v["cfg"]
    assert f.t_kill is not None
    tc = dataclasses.replace(cfg.target, position_ned_m=tuple(f.centre))
    st = build_target(tc).state(f.t_kill - f.epoch)
    hc = np.asarray(st.position, float)
    lim = hold_bank_limit_deg(f.gcs[a.kill_member], mod)
    h = hold_figures(f.trace, (float(hc[0]), float(hc[1])), -f.centre[2], f.radius, lim)
    ma = h["modes"] = f.modes_after
    if ma and any(m != mod.TRACK_MODE and m != mod.HOLD_MODE for m in ma):
        h["hold_verdict"] = f"FAIL: modes {ma}"
    f.kill_info["hold"] = h


def _fleet_figures(
    a: argparse.Namespace, v: dict[str, Any], f: _Fleet, codes: list[int | None], s: dict[str, Any]
) -> None:
    """Per aircraft its bridge's figures, for the fleet the spacing's; DIR/spacing.npz and the
    figures (a failure to draw is noted, never fatal)."""
    from lab.rigs.common import figures_of

    n, out, cfg = f.n, v["out"], v["cfg"]
    s["aircraft"] = []
    for k in range(n):
        kk = f.kill_info if (f.t_kill is not None and k == a.kill_member) else {}
        if kk:
            kk = {**kk, "hold_verdict": kk["hold"]["hold_verdict"]}
        fk = figures_of(
            out / f"bridge{k}", out / f"bridge{k}.log", codes[k] or 0, kk, cfg, v["mod"]
        )
        fk["instance"] = f.fws[k].instance
        fk["engaged_unix_s"] = f.engaged[k]
        s["aircraft"].append(fk)
    respace = "fleet.on_peer_lost=hold" not in a.overrides
    ser, sp, L = fleet_spacing(out, n, cfg.path, respace, f.t_all, f.t_kill, a.converge_m)
    e = f.engaged
    spread = (f.t_all - min(t for t in e if t)) if any(e) else None
    s["fleet"] = {
        "n": n,
        "converge_m": a.converge_m,
        **sp,
        "length_m": L,
        "engage_spread_s": spread,
    }
    np.savez(
        out / "spacing.npz",
        t_unix_s=ser["t_unix_s"],
        worst_m=ser["worst_m"],
        n_alive=ser["n_alive"],
    )
    try:
        from lab.rigs.fleet_figures import draw

        draw(out, n, ser, f.t_all, f.t_kill)
    except Exception as e:  # noqa: BLE001 - figures never fail a flight
        s["figures_error"] = f"{type(e).__name__}: {e}"


def _tear_down(f: _Fleet) -> None:
    """Stop what still runs: bridges (given their hand-back), relays, ground stations, firmware."""
    from lab.rigs.common import stop_bridge

    for b in f.bridges:
        stop_bridge(b)
    for r in f.relays:
        r.stop()
    for g in f.gcs:
        with contextlib.suppress(Exception):
            g.close()
    for fw in f.fws:
        fw.stop()


def fly_fleet(a: argparse.Namespace, v: dict[str, Any]) -> int:
    """The whole fleet flight; DIR/fleet.json and the table; 0 only when every verdict passed."""
    n, out = a.fleet, v["out"]
    if a.kill_after is not None and not 0 <= a.kill_member < n:
        raise RigError(f"--kill-member {a.kill_member}: expected 0..{n - 1}")
    summary: dict[str, Any] = {"flight": f"arduplane-fleet{n}", "autopilot": "arduplane"}
    f = _Fleet(n)
    rc = 1
    try:
        _start_fleet(a, v, f, summary)
        _place_fleet(a, v, f, summary)
        _start_bridges(a, v, f)
        _fly_until_done(a, v["mod"].TRACK_MODE, f)
        codes = [b.wait() if b is not None else None for b in f.bridges]
        if f.t_kill is not None:
            _kill_hold(a, v, f)
        _fleet_figures(a, v, f, codes, summary)
        summary["verdict"] = verdict(summary, a)
        rc = 0 if summary["verdict"] == "PASS" else 1
    finally:
        _tear_down(f)
        if f.relays and "mission" in summary:
            summary["mission"]["link"]["relays"] = [r.counters() for r in f.relays]
        (out / "fleet.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    print_fleet_table(summary)
    return rc


def verdict(s: dict[str, Any], a: argparse.Namespace) -> str:
    why = []
    for k, f in enumerate(s["aircraft"]):
        if f.get("verdict") != "PASS":
            why.append(f"aircraft {k}: {f.get('verdict')}")
        rms = (f.get("figures") or {}).get("steady_rms_m")
        killed = a.kill_after is not None and k == a.kill_member
        if not killed and (rms is None or rms > a.rms_bar):
            why.append(f"aircraft {k}: steady RMS {fmt(rms)} m > {a.rms_bar:g}")
    fl = s["fleet"]
    if not fl.get("converged"):
        why.append("spacing never converged")
    elif fl["spacing_rms_m"] > a.spacing_bar:
        why.append(f"spacing RMS {fl['spacing_rms_m']:.2f} m > {a.spacing_bar:g}")
    ak = fl.get("after_kill")
    if ak is not None and not ak.get("converged"):
        why.append("survivors never re-spaced")
    return "PASS" if not why else "FAIL: " + "; ".join(why)


def print_fleet_table(s: dict[str, Any]) -> None:
    print("\n" + "=" * 78)
    link = dict(s.get("mission", {}).get("link") or {})
    relays = link.pop("relays", None)
    print(f"fleet flight: {s.get('flight')}  {s.get('mission', {}).get('target', '')}  link "
          f"{link}")  # fmt: skip
    if relays:  # what the relays did, measured: not what was asked of them
        tot = {k: sum(d.get(k, 0) for r in relays for d in r.values())
               for k in ("received", "dropped_loss", "delayed", "reordered")}  # fmt: skip
        frac = tot["dropped_loss"] / tot["received"] if tot["received"] else float("nan")
        print(
            f"coordination relays: {tot['received']} reports in, {tot['dropped_loss']} dropped "
            f"({100 * frac:.1f} %), {tot['delayed']} delayed, {tot['reordered']} reordered"
        )
    print(f"{'aircraft':>8} {'-I':>3} {'steady RMS m':>12} {'max m':>7} {'xtrack RMS':>10} "
          f"{'thr@ceil':>8}  verdict")  # fmt: skip
    for k, f in enumerate(s.get("aircraft", [])):
        g = f.get("figures") or {}
        print(f"{k:>8} {f.get('instance', ''):>3} {fmt(g.get('steady_rms_m')):>12} "
              f"{fmt(g.get('steady_max_m')):>7} {fmt(g.get('cross_track_rms_m')):>10} "
              f"{fmt(g.get('thrust_at_ceiling')):>8}  {f.get('verdict')}")  # fmt: skip
        if "hold" in f:
            h = f["hold"]
            hh = h.get("hold", {})
            print(f"{'':>8} killed {fmt(h.get('killed_after_s'))} s after the last engagement; "
                  f"modes {hh.get('modes')}; hold {hh.get('hold_verdict')}")  # fmt: skip
    fl = s.get("fleet", {})
    print(f"fleet: engaged over {fmt(fl.get('engage_spread_s'))} s; start spread (worst pair) "
          f"{fmt(fl.get('start_spread_worst_m'))} m; converged (all pairs within "
          f"{fmt(fl.get('converge_m'))} m) {fmt(fl.get('converge_s'))} s after the last "
          f"engagement")  # fmt: skip
    print(f"fleet: spacing error after convergence RMS {fmt(fl.get('spacing_rms_m'))} m, max "
          f"{fmt(fl.get('spacing_max_m'))} m over {fmt(fl.get('judged_s'))} s")  # fmt: skip
    ak = fl.get("after_kill")
    if ak:
        print(f"after the kill: re-spaced in {fmt(ak.get('converge_s'))} s; spacing RMS "
              f"{fmt(ak.get('spacing_rms_m'))} m, max {fmt(ak.get('spacing_max_m'))} m over "
              f"{fmt(ak.get('judged_s'))} s")  # fmt: skip
    print(f"verdict: {s.get('verdict')}")
    print("=" * 78, flush=True)


def add_options(ap: argparse.ArgumentParser) -> None:
    """The fleet's options of ``scripts/sitl`` (the rest are the single flight's)."""
    g = ap.add_argument_group("fleet (ArduPlane): docs/fleet.md")
    g.add_argument("--fleet", type=int, default=0, metavar="N", help="fly N aircraft (>= 2)")
    g.add_argument("--fleet-gap", type=float, default=20.0, help="s between bridge starts")
    g.add_argument("--takeoff-gap", type=float, default=8.0, help="s between take-offs")
    g.add_argument("--fleet-loss", type=float, default=0.0, help="coordination loss (0..1)")
    g.add_argument("--fleet-jitter", type=float, default=0.0, help="coordination jitter (s)")
    g.add_argument("--kill-member", type=int, default=1, help="which bridge --kill-after kills")
    g.add_argument("--converge-m", type=float, default=10.0, help="spacing converged within (m)")
    g.add_argument("--rms-bar", type=float, default=0.5, help="steady RMS bar per aircraft (m)")
    g.add_argument("--spacing-bar", type=float, default=5.0, help="spacing RMS bar (m)")


def check_options(a: argparse.Namespace) -> None:
    if a.fleet < 2:
        raise RigError(f"--fleet {a.fleet}: expected at least 2")
    if a.autopilot != "arduplane":
        raise RigError("--fleet: ArduPlane only (PX4 SITL runs one instance per machine)")
    if a.sil or a.serial or a.guidance != "mpf" or a.instance is not None:
        raise RigError("--fleet flies MPF bridges alone (no --sil, --serial, --instance, native)")
    if not 0.0 <= a.fleet_loss < 1.0:
        raise RigError(f"--fleet-loss {a.fleet_loss}: expected in [0, 1)")
    if a.fleet_jitter < 0.0 or a.fleet_gap <= 0.0 or a.takeoff_gap < 0.0:
        raise RigError("--fleet-jitter, --fleet-gap, --takeoff-gap: expected >= 0 (gap > 0)")


def main(a: argparse.Namespace, v: dict[str, Any]) -> int:
    try:
        check_options(a)
    except RigError as e:
        print(f"sitl: {e}", file=sys.stderr)
        return 2
    v["out"].mkdir(parents=True, exist_ok=True)

    def _term(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, _term)
    try:
        return fly_fleet(a, v)
    except (RuntimeError, OSError, RigError) as e:
        print(f"sitl: {e}", file=sys.stderr)
        return 1


__all__ = ["add_options", "main", "spacing_series", "spacing_figures", "arduplane"]


def reanalyse(out: Path, converge_m: float = 10.0) -> dict[str, Any]:
    """The fleet figures of a finished rig directory again, from its fleet.json (engagement and
    kill times) and the bridges' fleet.csv: ``python -m lab.rigs.fleet DIR``."""
    from mpf_mavlink.config.schema import load_config

    s = read_json(out / "fleet.json")
    cfg = load_config(Path(s.get("config", "configs/bridge_arduplane.yaml")))
    t_all = max(e for f in s["aircraft"] if (e := f.get("engaged_unix_s")))
    kill = next((f["hold"] for f in s["aircraft"] if "hold" in f), None)
    t_kill = t_all + kill["killed_after_s"] if kill else None
    return fleet_spacing(out, len(s["aircraft"]), cfg.path, True, t_all, t_kill, converge_m)[1]


if __name__ == "__main__":
    print(json.dumps(reanalyse(Path(sys.argv[1])), indent=2))
