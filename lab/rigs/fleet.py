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
the held ones). Figures: DIR/fleet_tracks.png, DIR/fleet_spacing.png (sim/fleet_figures.py).
"""

from __future__ import annotations

import argparse
import contextlib
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
from lab.rigs.bundles import RigError, die_with_parent, unpack
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
            s_now.append(float(np.interp(t, tu, tr["s_m"])) if ok else 0.0)
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


def _target_position(cfg: Any, centre: list[float], t: float) -> np.ndarray:
    import dataclasses

    from mpf_mavlink.config.scenario import build_target

    tc = dataclasses.replace(cfg.target, position_ned_m=tuple(centre))
    st = build_target(tc).state(t)
    return np.asarray(st.position, float)


def fly_fleet(a: argparse.Namespace, v: dict[str, Any]) -> int:
    """The whole fleet flight; DIR/fleet.json and the table; 0 only when every verdict passed."""
    from lab.rigs.common import _bridge_command, _flight_header, figures_of, place_mission

    n, out, cfg, mod = a.fleet, v["out"], v["cfg"], v["mod"]
    if a.kill_after is not None and not 0 <= a.kill_member < n:
        raise RigError(f"--kill-member {a.kill_member}: expected 0..{n - 1}")
    summary: dict[str, Any] = {"flight": f"arduplane-fleet{n}", "autopilot": "arduplane"}
    fws: list[Any] = []
    gcs: list[Gcs] = []
    bridges: list[subprocess.Popen[str] | None] = [None] * n
    relays: list[Any] = []
    rc = 1
    try:
        for _ in range(n):
            ak = argparse.Namespace(**{**vars(a), "instance": None})
            fws.append(mod.Firmware(ak))  # each takes a free instance's lock
        bundle_dir = unpack(a.autopilot, v["bundle"])
        summary.update(_flight_header(a, v, bundle_dir))
        summary["instances"] = [fw.instance for fw in fws]
        print(f"{summary['bundle']}: starting {n} instances {summary['instances']}", flush=True)
        for k, fw in enumerate(fws):
            fw.start(bundle_dir, out / f"firmware{k}")
        gcs = [Gcs(fw.gcs_url, mod.FLAVOUR) for fw in fws]
        for g, fw in zip(gcs, fws, strict=True):
            fw.configure(g)
            for name, value in a.params:
                g.set_param(name, value)
        errs: list[str] = []

        def up(k: int) -> None:
            try:
                time.sleep(k * a.takeoff_gap)  # spread along the climb-out and loiter
                fws[k].take_off(gcs[k], a.alt)
            except Exception as e:  # noqa: BLE001 - reported below
                errs.append(f"aircraft {k}: {e}")

        ths = [threading.Thread(target=up, args=(k,), daemon=True) for k in range(n)]
        for th in ths:
            th.start()
        while any(th.is_alive() for th in ths):
            time.sleep(0.5)
        if errs:
            raise RigError("; ".join(errs))
        radius = float(cfg.path.radius_m) if cfg.path.type == "circle" else 0.0
        for g in gcs:
            g.pump(0.2, echo=False)
        centre, _ = place_mission(gcs[0], radius, a.lead * a.speedup)
        epoch = time.time() + a.lead
        listen = _free_udp_ports(n)
        send_to = list(listen)
        if a.fleet_loss or a.fleet_jitter:
            from lab.soak.relay import Impairment, UdpRelay

            imp = Impairment(loss=a.fleet_loss, jitter_s=a.fleet_jitter)
            for k in range(n):  # every member's reports to k pass k's relay
                r = UdpRelay(0, listen[k], down=imp, seed=k, keep_log=False).start()
                relays.append(r)
                send_to[k] = r.vehicle_port
        summary["mission"] = {
            "centre_ned_m": centre,
            "radius_m": radius,
            "target": v["target_label"],
            "epoch_unix_s": epoch,
            "link": {"loss": a.fleet_loss, "jitter_s": a.fleet_jitter},
        }
        engaged: list[float | None] = [None] * n  # wall time of GUIDED
        started: list[float] = []
        kill_info: dict[str, Any] = {}
        trace: list[tuple[float, float, float, float, float]] = []
        modes_after: list[str] = []
        t_kill: float | None = None
        for k in range(n):
            sets = [
                *a.overrides,
                f"target.position_ned_m=[{centre[0]:.2f},{centre[1]:.2f},{centre[2]:.2f}]",
                *v["tsets"],
                "mavlink.plots=false",
                *fleet_sets(n, k, listen, send_to, epoch),
            ]
            va = {**v, "out": out}
            dur = a.duration + (n - 1 - k) * a.fleet_gap  # every bridge ends about together
            ak = argparse.Namespace(**{**vars(a), "duration": dur})
            cmd = _bridge_command(ak, va, fws[k].bridge_url, sets)
            cmd[cmd.index("--out") + 1] = str(out / f"bridge{k}")
            (out / f"bridge{k}.cmd").write_text(" ".join(cmd) + "\n")
            with open(out / f"bridge{k}.log", "w") as blog:
                bridges[k] = subprocess.Popen(
                    cmd, stdout=blog, stderr=subprocess.STDOUT, text=True,
                    preexec_fn=die_with_parent,
                )  # fmt: skip
            started.append(time.time())
            print(f"bridge {k} started on {fws[k].bridge_url}", flush=True)
            t_next = started[-1] + a.fleet_gap
            while time.time() < t_next and k < n - 1:
                for j, g in enumerate(gcs):
                    g.pump(0.05, echo=False)
                    if engaged[j] is None and g.mode() == mod.TRACK_MODE and bridges[j] is not None:
                        engaged[j] = time.time()
                        print(f"aircraft {j} in {mod.TRACK_MODE}", flush=True)
        t_all = max(e for e in engaged if e is not None) if all(engaged) else time.time()
        while any(b is not None and b.poll() is None for b in bridges):
            for j, g in enumerate(gcs):
                g.pump(0.05, echo=False)
                if engaged[j] is None and g.mode() == mod.TRACK_MODE:
                    engaged[j] = time.time()
                    print(f"aircraft {j} in {mod.TRACK_MODE}", flush=True)
            if all(engaged):
                t_all = max(e for e in engaged if e is not None)
            km = a.kill_member
            if a.kill_after is not None and t_kill is None and all(engaged):
                if time.time() - t_all >= a.kill_after:
                    b = bridges[km]
                    assert b is not None
                    os.kill(b.pid, signal.SIGKILL)
                    b.wait()
                    t_kill = time.time()
                    kill_info = {
                        "member": km,
                        "killed_after_s": t_kill - t_all,
                        "killed_after_engaged_s": t_kill - (engaged[km] or t_kill),
                    }
                    print(
                        f"bridge {km} SIGKILLed {t_kill - t_all:.1f} s after the last engagement",
                        flush=True,
                    )
            if t_kill is not None and time.time() - t_kill <= a.watch_s:
                g = gcs[a.kill_member]
                if not modes_after or modes_after[-1] != g.mode():
                    modes_after.append(g.mode())
                att, lp = g.last.get("ATTITUDE"), g.last.get("LOCAL_POSITION_NED")
                if (
                    att is not None
                    and lp is not None
                    and (not trace or trace[-1][0] != time.time() - t_kill)
                ):
                    trace.append((time.time() - t_kill, att.roll, lp.x, lp.y, lp.z))
        codes = [b.wait() if b is not None else None for b in bridges]
        if t_kill is not None:
            km = a.kill_member
            te = engaged[km] or t_kill
            hc = _target_position(cfg, centre, te - epoch)
            h = hold_figures(trace, (float(hc[0]), float(hc[1])), -centre[2], radius)
            h["modes"] = modes_after
            if modes_after and any(m != mod.TRACK_MODE and m != mod.HOLD_MODE for m in modes_after):
                h["hold_verdict"] = f"FAIL: modes {modes_after}"
            kill_info["hold"] = h
        # -- figures ----------------------------------------------------------------------
        aircraft = []
        for k in range(n):
            kk = kill_info if (t_kill is not None and k == a.kill_member) else {}
            if kk:
                kk = {**kk, "hold_verdict": kk["hold"]["hold_verdict"]}
            f = figures_of(out / f"bridge{k}", out / f"bridge{k}.log", codes[k] or 0, kk, cfg, mod)
            f["instance"] = fws[k].instance
            f["engaged_unix_s"] = engaged[k]
            aircraft.append(f)
        summary["aircraft"] = aircraft
        fleet_cfg = {"n": n, "converge_m": a.converge_m}
        from mpf_mavlink.config.scenario import build_path

        L = float(build_path(cfg.path).length)
        slots = [j / n for j in range(n)]
        tracks = [read_fleet_csv(out / f"bridge{k}" / "fleet.csv") for k in range(n)]
        if all(tr is None for tr in tracks):
            raise RigError("no fleet.csv from any bridge")
        respace = "fleet.on_peer_lost=hold" not in a.overrides
        ser = spacing_series(tracks, slots, L, respace)
        t_end = t_kill if t_kill is not None else math.inf
        fl = spacing_figures(ser, t_all, t_end, a.converge_m, n)
        fleet_cfg.update(fl)
        if t_kill is not None:
            fleet_cfg["after_kill"] = spacing_figures(ser, t_kill, math.inf, a.converge_m, n - 1)
        fleet_cfg["length_m"] = L
        fleet_cfg["engage_spread_s"] = (
            (t_all - min(e for e in engaged if e)) if any(engaged) else None
        )
        summary["fleet"] = fleet_cfg
        np.savez(
            out / "spacing.npz",
            t_unix_s=ser["t_unix_s"],
            worst_m=ser["worst_m"],
            n_alive=ser["n_alive"],
        )
        try:
            from sim.fleet_figures import draw

            draw(out, n, ser, t_all, t_kill)
        except Exception as e:  # noqa: BLE001 - figures never fail a flight
            summary["figures_error"] = f"{type(e).__name__}: {e}"
        summary["verdict"] = verdict(summary, a)
        rc = 0 if summary["verdict"] == "PASS" else 1
    finally:
        for b in bridges:
            if b is not None and b.poll() is None:
                b.terminate()
                with contextlib.suppress(subprocess.TimeoutExpired):
                    b.wait(20)
        for r in relays:
            r.stop()
        for g in gcs:
            with contextlib.suppress(Exception):
                g.close()
        for fw in fws:
            fw.stop()
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
    print(f"fleet flight: {s.get('flight')}  {s.get('mission', {}).get('target', '')}  link "
          f"{s.get('mission', {}).get('link')}")  # fmt: skip
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
    from mpf_mavlink.config.scenario import build_path
    from mpf_mavlink.config.schema import load_config

    s = read_json(out / "fleet.json")
    n = len(s["aircraft"])
    cfg = load_config(Path(s.get("config", "configs/bridge_arduplane.yaml")))
    L = float(build_path(cfg.path).length)
    tracks = [read_fleet_csv(out / f"bridge{k}" / "fleet.csv") for k in range(n)]
    engaged = [f.get("engaged_unix_s") for f in s["aircraft"]]
    t_all = max(e for e in engaged if e)
    ser = spacing_series(tracks, [j / n for j in range(n)], L, True)
    kill = next((f["hold"] for f in s["aircraft"] if "hold" in f), None)
    t_kill = t_all + kill["killed_after_s"] if kill else None
    fl = spacing_figures(ser, t_all, t_kill if t_kill else math.inf, converge_m, n)
    if t_kill is not None:
        fl["after_kill"] = spacing_figures(ser, t_kill, math.inf, converge_m, n - 1)
    return fl


if __name__ == "__main__":
    print(json.dumps(reanalyse(Path(sys.argv[1])), indent=2))
