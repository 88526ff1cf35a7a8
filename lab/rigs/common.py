"""The real-firmware rig, the same for both autopilots: ``scripts/sitl px4|arduplane --out DIR``.

It does what a user does by hand, and nothing more to the autopilot:

1. checks every argument (bundle, config, numbers, the run directory) before touching anything;
2. unpacks the bundle (``../shared/sitl``, or ``--bundle``) into the git-ignored ``.cache/sitl``
   and starts the firmware with stock parameters in a scratch directory of the run directory;
3. takes off as a ground station does (the autopilot module: ``lab/rigs/px4.py``,
   ``lab/rigs/arduplane.py``) and lets the autopilot loiter;
4. places the mission where the aircraft is: ``--config``'s path (default the autopilot's
   ``configs/bridge_*.yaml``, as shipped) about a centre chosen so that the aircraft is on the
   path, tangent to its flight, where its own loiter will have taken it when the bridge engages;
   the target stationary, or moving with ``--moving``;
5. hands over to ``mpf-mavlink run`` (over a pseudo-terminal with ``--serial``: ArduPlane only),
   waits for it to fly ``--duration`` s and hand back; or SIGKILLs it ``--kill-after`` s into
   tracking and watches ``--watch-s`` s of what the autopilot does on its own (the hold);
6. with ``--sil`` flies the same mission from the same start state in our SIL;
7. writes ``DIR/summary.json`` and prints the same as a table; exits 0 only when the flight
   passed (the bridge's verdict, engagement, hand-back; after a kill: the hold).

``--record`` also writes ``docs/results/sitl-<flight>.json`` and regenerates
``docs/results/sitl.md`` (the README's results table) from all of them.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as _dt
import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any, NoReturn

from lab.rigs import arduplane, fleet, native, px4
from lab.rigs.bundles import ROOT, RigError, bundle_version, check_bundle, die_with_parent, unpack
from lab.rigs.figures import (
    HOLD_BANK_DEG,
    cross_track,
    fmt,
    hold_figures,
    read_json,
    run_record_figures,
    tlog_counts,
    tlog_stream_hz,
)
from lab.rigs.gcs import Gcs
from mpf_mavlink.config.schema import load_config
from mpf_mavlink.errors import MpfError

AUTOPILOTS: dict[str, ModuleType] = {"px4": px4, "arduplane": arduplane}
RESULTS = ROOT / "docs" / "results"
MOVING_DEFAULT = ("constant_turn", 3.0, math.pi / 2)  # 3 m/s east, when the config's is still


def _number(kind: str, lo: float, lo_open: bool = False) -> Any:
    def conv(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not math.isfinite(v) or v < lo or (lo_open and v == lo):
            raise argparse.ArgumentTypeError(f"must be a {kind}, got {text}")
        return v

    return conv


def _wind(text: str) -> tuple[float, float]:
    parts = text.split(",")
    try:
        spd, deg = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected SPEED,DIR_DEG (m/s, deg)") from None
    if not (math.isfinite(spd) and math.isfinite(deg) and spd >= 0.0 and 0.0 <= deg <= 360.0):
        raise argparse.ArgumentTypeError(f"{text!r}: speed >= 0 m/s, direction 0..360 deg")
    return spd, deg


def _offset(text: str) -> tuple[float, float, float]:
    from lab.rigs.placement import parse_offset

    try:
        return parse_offset(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _param(text: str) -> tuple[str, float]:
    name, eq, val = text.partition("=")
    name = name.strip()
    if not eq or not name or not name.replace("_", "").isalnum() or name.upper() != name:
        raise argparse.ArgumentTypeError(f"--param {text!r}: expected NAME=VALUE (e.g. X_Y=1.5)")
    try:
        v = float(val)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--param {text!r}: {val!r} is not a number") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"--param {text!r}: not finite")
    return name, v


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line naming the culprit, not the usage
        self.exit(2, f"sitl: {message} (scripts/sitl --help)\n")


def _add_number(
    ap: argparse.ArgumentParser, flag: str, kind: str, help: str, default: float | None = None
) -> None:
    """A number option bounded below by 0 as ``kind`` says (e.g. "time > 0 s", "speed >= 0
    m/s"), which also names it in the error."""
    lo_open = ">=" not in kind
    ap.add_argument(flag, type=_number(kind, 0.0, lo_open), default=default, help=help)


def _add_flight_options(ap: argparse.ArgumentParser) -> None:
    """What is flown: autopilot, bundle, config, duration, target, weather, a bridge kill."""
    ap.add_argument("autopilot", choices=sorted(AUTOPILOTS))
    ap.add_argument("--out", required=True, help="run directory (new or empty)")
    ap.add_argument(
        "--bundle",
        "--ardupilot",
        dest="bundle",
        help=(
            "unpacked bundle or its .tar.xz (default: ../shared/sitl); with --binary: your "
            "ArduPilot checkout"
        ),
    )
    ap.add_argument("--config", help="bridge config (default configs/bridge_<autopilot>.yaml)")
    _add_number(
        ap, "--duration", "time > 0 s", "seconds of tracking (autopilot time; default 300)", 300.0
    )
    tgt = ap.add_mutually_exclusive_group()
    tgt.add_argument(
        "--moving",
        action="store_true",
        help="a still config target replaced by one moving 3 m/s east (a moving or climbing "
        "target flies as written, with or without this)",
    )
    tgt.add_argument(
        "--still",
        action="store_true",
        help="the config's target held still at its start (default: the target as written)",
    )
    ap.add_argument(
        "--guidance",
        choices=("mpf", "native"),
        default="mpf",
        help="mpf: hand over to mpf-mavlink run (default); native: the firmware's own circle "
        "re-centred on the target at --rate Hz (ArduPlane GUIDED + DO_REPOSITION, PX4 Hold + "
        "DO_ORBIT), as a ground station's follow does",
    )
    _add_number(
        ap,
        "--rate",
        "rate > 0 Hz",
        "--guidance native: centre re-sent at this rate (default 1)",
        1.0,
    )
    ap.add_argument(
        "--param",
        dest="params",
        action="append",
        default=[],
        type=_param,
        metavar="NAME=VALUE",
        help="a firmware parameter set before take-off (repeatable; default: stock)",
    )
    ap.add_argument("--wind", type=_wind, help="SPEED,DIR_DEG (ArduPlane SIM_WIND_SPD/DIR)")
    _add_number(ap, "--turbulence", "speed >= 0 m/s", "ArduPlane SIM_WIND_TURB (m/s)")
    _add_number(
        ap,
        "--kill-after",
        "time > 0 s",
        "SIGKILL the bridge S s into tracking and watch the autopilot's hold",
    )
    _add_number(ap, "--watch-s", "time > 0 s", "seconds watched after the kill (default 60)", 60.0)


def _add_rig_options(ap: argparse.ArgumentParser) -> None:
    """How it is flown: SIL twin, speed-up, serial link, instance, altitude, lead, record."""
    ap.add_argument("--sil", action="store_true", help="fly the same mission in our SIL too")
    ap.add_argument("--force", action="store_true", help="the bridge engages despite failed checks")
    _add_number(
        ap,
        "--speedup",
        "factor > 0",
        "ArduPlane SIM_SPEEDUP / PX4_SIM_SPEED_FACTOR (default 1: real time)",
        1.0,
    )
    ap.add_argument(
        "--serial",
        action="store_true",
        help="ArduPlane: the bridge on a pseudo-terminal relayed to SERIAL1",
    )
    ap.add_argument("--instance", type=int, help="ArduPlane -I N (default: the first free one)")
    ap.add_argument("--binary", help="ArduPlane: your own arduplane SITL binary instead")
    _add_number(ap, "--alt", "height > 0 m", "take-off / path altitude above home (m)", 100.0)
    _add_number(
        ap, "--lead", "time >= 0 s", "wall seconds from placing the mission to engaging", 6.0
    )
    ap.add_argument(
        "--start-offset",
        type=_offset,
        metavar="X,Y,D",
        help="the aircraft's start from the placed path (m: X along its track, Y to its "
        "right, D down; 300,0,0: 300 m out, flying away); default: on the path",
    )
    ap.add_argument(
        "--record",
        action="store_true",
        help="write docs/results/sitl-<flight>.json and regenerate docs/results/sitl.md",
    )
    ap.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a config override passed to the bridge (repeatable)",
    )


def parser() -> argparse.ArgumentParser:
    ap = _Parser(
        prog="scripts/sitl",
        description="Fly mpf-mavlink against real PX4 / ArduPlane SITL firmware "
        "(README 'Flying PX4 SITL', 'Flying ArduPilot SITL'). "
        "`scripts/sitl compare px4|arduplane --out DIR [options]` flies MPF and the firmware's "
        "own guidance (--guidance native) one after the other with the same options and writes "
        "DIR/compare.md, compare.png (docs/sitl.md 'Head-to-head on the firmware').",
    )
    _add_flight_options(ap)
    _add_rig_options(ap)
    fleet.add_options(ap)  # --fleet N (lab/rigs/fleet.py)
    return ap


def validate(a: argparse.Namespace) -> dict[str, Any]:
    """Everything that can be refused before the rig creates or starts anything."""
    mod = AUTOPILOTS[a.autopilot]
    if not mod.HAS_WIND and (a.wind is not None or a.turbulence is not None):
        raise RigError("--wind/--turbulence: PX4 v1.16 SIH has no wind model")
    if a.autopilot != "arduplane" and (a.serial or a.binary or a.instance is not None):
        raise RigError("--serial, --binary and --instance are ArduPlane options")
    if a.instance is not None and not 0 <= a.instance <= 200:
        raise RigError(f"--instance {a.instance}: expected 0..200")
    if a.kill_after is not None and (a.sil or a.serial):
        raise RigError("--kill-after flies alone (no --sil, no --serial)")
    if a.guidance == "native" and (a.kill_after is not None or a.sil or a.serial):
        raise RigError("--guidance native: no bridge to kill, no SIL twin, no serial link")
    if a.binary is not None:
        b = Path(a.binary).expanduser()
        if not (b.is_file() and os.access(b, os.X_OK) and b.stat().st_mode & 0o111):
            raise RigError(f"--binary {a.binary}: not an executable file")
        a.binary = b.resolve()
    cfg_path = Path(a.config).expanduser() if a.config else mod.DEFAULT_CONFIG
    if not cfg_path.is_file():
        raise RigError(f"--config {a.config}: no such file")
    try:  # the overrides the flight will use, with a placeholder centre
        cfg = load_config(cfg_path, [*a.overrides, "target.position_ned_m=[0,0,-100]"])
    except MpfError as e:
        raise RigError(f"--config {cfg_path}: {e}") from None
    tsets, label = target_sets(cfg, a.moving, a.still)
    try:  # and with the target the rig will give it
        cfg = load_config(cfg_path, [*a.overrides, "target.position_ned_m=[0,0,-100]", *tsets])
    except MpfError as e:
        raise RigError(f"--config {cfg_path}: {e}") from None
    if a.guidance == "native" and (cfg.path.type != "circle" or cfg.target.type == "mavlink"):
        raise RigError(
            f"--config {cfg_path}: --guidance native flies the firmware's circle about a "
            f"scripted target (path.type circle, not {cfg.path.type}; target not mavlink)"
        )
    flav = cfg.extra["mavlink"].flavour
    if flav not in (mod.FLAVOUR.value, "auto"):
        raise RigError(f"--config {cfg_path}: mavlink.flavour is {flav}, not {mod.FLAVOUR.value}")
    out = Path(a.out).expanduser()
    out = out if out.is_absolute() else Path.cwd() / out
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise RigError(f"--out {a.out}: exists and is not an empty directory (nothing removed)")
    if not os.access(out.parent if not out.exists() else out, os.W_OK) and out.parent.exists():
        raise RigError(f"--out {a.out}: not writable")
    if a.binary is not None and a.bundle is not None and Path(a.bundle).is_dir():
        bundle = Path(a.bundle).expanduser().resolve()  # your checkout: only its plane.parm
        if not (bundle / "Tools" / "autotest" / "models" / "plane.parm").is_file():
            raise RigError(f"--bundle {a.bundle}: no Tools/autotest/models/plane.parm")
    else:
        bundle = check_bundle(a.autopilot, a.bundle)
    # the target's overrides are kept from the config as given: the cfg above already has them,
    # and target_sets on it saw a moving target and gave none (PX4 --moving flew stationary)
    return {
        "mod": mod,
        "bundle": bundle,
        "config": cfg_path.resolve(),
        "cfg": cfg,
        "out": out,
        "tsets": tsets,
        "target_label": label,
    }


def place_mission(g: Gcs, radius: float, lead_s: float) -> tuple[list[float], list[float]]:
    """(circle centre NED, predicted aircraft position NED): the aircraft on a clockwise circle
    of ``radius``, tangent to its flight, where its current turn takes it in ``lead_s``."""
    (x, y, z), chi2 = predict_start(g, lead_s)
    # clockwise seen from above: the centre is to the right of the flight direction
    return [x - radius * math.sin(chi2), y + radius * math.cos(chi2), z], [x, y, z]


def place_any(
    g: Gcs, cfg: Any, lead_s: float, offset: tuple[float, float, float] | None
) -> tuple[list[float], list[float]]:
    """(target position NED, predicted aircraft position NED) for any path shape: the shipped
    circle as :func:`place_mission` places it; any other shape, or any ``--start-offset``, by
    :func:`lab.rigs.placement.place_path` (the aircraft on the path tangent to its flight, or
    at the offset from it)."""
    if cfg.path.type == "circle" and not offset and tuple(cfg.path.center_m) == (0.0, 0.0, 0.0):
        return place_mission(g, float(cfg.path.radius_m), lead_s)
    from lab.rigs.placement import place_path
    from mpf_mavlink.config.scenario import build_path, build_target

    (x, y, z), chi2 = predict_start(g, lead_s)
    nodes = build_path(cfg.path).positions()
    R = build_target(cfg.target).state(0.0).R_T_I
    target, _ = place_path(nodes, R, (x, y, z), chi2, offset or (0.0, 0.0, 0.0))
    return target, [x, y, z]


def predict_start(g: Gcs, lead_s: float) -> tuple[tuple[float, float, float], float]:
    """(aircraft position NED, track rad): where its current turn takes it in ``lead_s``."""
    lp, att = g.last["LOCAL_POSITION_NED"], g.last["ATTITUDE"]
    vx, vy = lp.vx, lp.vy
    v = math.hypot(vx, vy)
    chi = math.atan2(vy, vx)
    w = 9.80665 * math.tan(att.roll) / max(v, 1.0)  # heading rate of a coordinated turn
    x, y = lp.x, lp.y
    if abs(w) > 1e-3:
        r = v / w
        cx, cy = x - r * math.sin(chi), y + r * math.cos(chi)
        chi2 = chi + w * lead_s
        x, y = cx + r * math.sin(chi2), cy - r * math.cos(chi2)
    else:
        chi2 = chi
        x, y = x + vx * lead_s, y + vy * lead_s
    return (x, y, lp.z), chi2


def _target_label(t: Any) -> str:
    """What the config's target does, in words."""
    if t.type == "mavlink":
        return "live MAVLink target"
    if t.type == "paper":
        return "the paper's target profile"
    if t.type == "stationary" or _is_still(t):
        return "stationary"
    parts = []
    if t.speed_m_s:
        parts.append(
            f"moving {t.speed_m_s:g} m/s heading {math.degrees(t.heading_rad) % 360:.0f} deg"
        )
    if t.turn_rate_rad_s:
        parts.append(f"turning {t.turn_rate_rad_s:g} rad/s")
    if t.climb_rate_m_s:
        parts.append(f"climbing {t.climb_rate_m_s:g} m/s")
    return ", ".join(parts)


def _is_still(t: Any) -> bool:
    return t.type == "stationary" or (
        t.type == "constant_turn"
        and t.speed_m_s == 0.0
        and t.turn_rate_rad_s == 0.0
        and t.climb_rate_m_s == 0.0
    )


def target_sets(cfg: Any, moving: bool, still: bool = False) -> tuple[list[str], str]:
    """The target overrides and the label of what really flies: the config's target as written;
    ``still`` holds it at its start; ``moving`` replaces only a still one (3 m/s east)."""
    t = cfg.target
    if still:
        was = "" if _is_still(t) else f" (--still: the config's is {_target_label(t)})"
        return ["target.type=stationary"], "stationary" + was
    if moving and _is_still(t):
        typ, spd, hdg = MOVING_DEFAULT
        sets = [f"target.type={typ}", f"target.speed_m_s={spd:g}", f"target.heading_rad={hdg:.6f}",
                "target.turn_rate_rad_s=0", "target.climb_rate_m_s=0"]  # fmt: skip
        label = f"moving {spd:g} m/s heading {math.degrees(hdg) % 360:.0f} deg"
        return sets, label + " (--moving: the config's is still)"
    return [], _target_label(t)


#: the inputs that make two flights different flights (their names then differ)
_DISTINGUISHING = ("autopilot", "config", "overrides", "guidance", "rate", "params", "duration",
                   "moving", "still", "wind", "turbulence", "kill_after", "watch_s", "serial",
                   "speedup", "alt", "lead", "binary", "start_offset")  # fmt: skip


def flight_name(a: argparse.Namespace, v: dict[str, Any] | None = None) -> str:
    """A flight's name: autopilot, config stem, guidance, target, wind, kill, serial, and a
    short hash of every input that makes it another flight (so --record never overwrites a
    different flight's record)."""
    import hashlib

    cfg_path = v["config"] if v else Path(a.config or AUTOPILOTS[a.autopilot].DEFAULT_CONFIG)
    label = v["target_label"] if v else ("moving" if a.moving else "stationary")
    parts = [a.autopilot, Path(cfg_path).stem.removeprefix("bridge_")]
    if parts[1] == a.autopilot:
        parts.pop()  # the shipped config of that autopilot
    if getattr(a, "guidance", "mpf") == "native":
        parts.append(f"native{a.rate:g}hz")
    parts.append("stationary" if label.startswith("stationary") else "moving")
    if a.wind is not None:
        parts.append(f"wind{a.wind[0]:g}")
    if a.turbulence:
        parts.append(f"turb{a.turbulence:g}")
    if a.kill_after is not None:
        parts.append(f"kill{a.kill_after:g}")
    if a.serial:
        parts.append("serial")
    key = {k: getattr(a, k, None) for k in _DISTINGUISHING}
    cp = Path(cfg_path).resolve()
    # the config by where it is in the checkout (the same name in every clone) and by content
    key["config"] = str(cp.relative_to(ROOT)) if cp.is_relative_to(ROOT) else str(cp)
    key["config_sha"] = hashlib.sha256(cp.read_bytes()).hexdigest() if cp.is_file() else None
    digest = hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()
    return "-".join(parts) + "-" + digest[:6]


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["compare"]:  # MPF and the firmware's own guidance, one after the other
        from lab.rigs import worlds

        return worlds.main(argv[1:])
    if any(x == "--certificate" or x.startswith("--certificate=") for x in argv):
        from lab.rigs import validate as drawn  # flights drawn from a certificate's conditions

        return drawn.main(argv)
    a = parser().parse_args(argv)
    try:
        v = validate(a)
    except RigError as e:
        print(f"sitl: {e}", file=sys.stderr)
        return 2
    if a.fleet:  # N aircraft on one path (lab/rigs/fleet.py)
        return fleet.main(a, v)
    mod, out = v["mod"], v["out"]
    try:
        fw = mod.Firmware(a)  # ArduPlane: takes a free instance's lock (or refuses)
    except RigError as e:
        print(f"sitl: {e}", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)

    def _term(signum: int, frame: Any) -> None:  # SIGTERM: clean up as Ctrl-C does
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, _term)
    summary: dict[str, Any] = {
        "flight": flight_name(a, v),
        "autopilot": a.autopilot,
        "guidance": a.guidance,
    }
    rc = 1
    try:
        rc = fly(a, v, fw, summary)
    except (RuntimeError, OSError, RigError, MpfError) as e:
        summary["verdict"] = f"FAIL: rig: {e}"
        print(f"sitl: {e}", file=sys.stderr)
    finally:
        fw.stop()
        if a.autopilot == "px4" and "figures" in summary:  # the ULog is complete once PX4 stops
            # (it reads the native flight's clock origin from summary.json: written first)
            (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
            summary["estimator_floor"] = _estimator_floor(out)
        (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    print_table(summary, out)
    if a.record and "figures" in summary:
        record(summary)
    return rc


def _estimator_floor(out: Path) -> dict[str, Any]:
    """PX4: EKF2's error against SIH's truth over the steady window (:mod:`lab.rigs.ulog`)."""
    from lab.rigs import ulog

    try:
        return ulog.estimator_floor(out)
    except (OSError, ValueError, KeyError, IndexError) as e:
        return {"error": f"no estimator figures: {e}"}


def _flight_header(a: argparse.Namespace, v: dict[str, Any], bundle_dir: Path) -> dict[str, Any]:
    """The summary's description of the flight: firmware, config, speed-up, commit, weather."""
    return dict(
        bundle=bundle_version(bundle_dir),
        config=str(v["config"].relative_to(ROOT))
        if v["config"].is_relative_to(ROOT)
        else str(v["config"]),
        speedup=a.speedup,
        commit=_git_commit(),
        date=_dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        wind=list(a.wind) if a.wind else None,
        turbulence=a.turbulence,
        command=" ".join(["scripts/sitl", *sys.argv[1:]]) if sys.argv else "",
    )


def _bridge_command(
    a: argparse.Namespace, v: dict[str, Any], url: str, sets: list[str]
) -> list[str]:
    return [
        sys.executable,
        "-m",
        "mpf_mavlink.cli",
        "run",
        str(v["config"]),
        "--connect",
        url,
        "--out",
        str(v["out"] / "bridge"),
        "--duration",
        f"{a.duration:g}",
        *[x for s in sets for x in ("--set", s)],
        *(["--force"] if getattr(a, "force", False) else []),
    ]


def connect(fw: Any, mod: ModuleType, params: list[tuple[str, float]]) -> tuple[Gcs, Any]:
    """A ground station on started firmware, configured, with the user's ``--param`` tuning
    before take-off (stock without); returns it and what the configuring set."""
    g = Gcs(fw.gcs_url, mod.FLAVOUR)
    configured = fw.configure(g)
    for name, value in params:
        g.set_param(name, value)
    return g, configured


def mission_sets(a: argparse.Namespace, v: dict[str, Any], centre: list[float]) -> list[str]:
    """The bridge's ``--set`` overrides of the placed mission: the user's, the target at
    ``centre`` (m, local NED), the target's own, no plots."""
    ned = f"[{centre[0]:.2f},{centre[1]:.2f},{centre[2]:.2f}]"
    return [*a.overrides, f"target.position_ned_m={ned}", *v["tsets"], "mavlink.plots=false"]


def start_bridge(cmd: list[str], log: Path) -> subprocess.Popen[str]:
    """``mpf-mavlink run`` as the rig's child (dying with it), its output into ``log``."""
    with open(log, "w") as blog:
        return subprocess.Popen(
            cmd, stdout=blog, stderr=subprocess.STDOUT, text=True, preexec_fn=die_with_parent
        )


def stop_bridge(bridge: subprocess.Popen[str] | None) -> None:
    """Terminate a bridge still running and give it 20 s to hand back."""
    if bridge is not None and bridge.poll() is None:
        bridge.terminate()
        with contextlib.suppress(subprocess.TimeoutExpired):
            bridge.wait(20)


def _until_bridge_exits(
    a: argparse.Namespace,
    g: Gcs,
    mod: Any,
    bridge: subprocess.Popen[str],
    mission: tuple[list[float], float],
    out: Path,
) -> dict[str, Any]:
    """Pumps the GCS until the bridge exits (or is SIGKILLed ``--kill-after`` s into tracking,
    then watches the autopilot's hold about ``mission`` (centre, radius)); returns the kill's
    figures, empty without a kill."""
    centre, radius = mission
    t_engaged: float | None = None
    while bridge.poll() is None:
        g.pump(0.2)
        if g.mode() == mod.TRACK_MODE and t_engaged is None:
            t_engaged = g.t_boot_s
            print(f"{mod.TRACK_MODE} at t_boot {t_engaged:.1f} s", flush=True)
        if (
            a.kill_after is not None
            and t_engaged is not None
            and g.t_boot_s - t_engaged >= a.kill_after
        ):
            os.kill(bridge.pid, signal.SIGKILL)
            bridge.wait()
            tracked = g.t_boot_s - t_engaged
            print(f"bridge SIGKILLed {tracked:.1f} s into tracking", flush=True)
            kill = watch_hold(g, mod, a.watch_s, centre, -centre[2], radius, out)
            kill["killed_after_s"] = tracked
            return kill
    return {}


def fly(a: argparse.Namespace, v: dict[str, Any], fw: Any, summary: dict[str, Any]) -> int:
    mod, out, cfg = v["mod"], v["out"], v["cfg"]
    bundle_dir = unpack(a.autopilot, v["bundle"])
    summary.update(_flight_header(a, v, bundle_dir))
    print(f"{summary['bundle']}: starting ({bundle_dir})", flush=True)
    fw.start(bundle_dir, out / "firmware")
    g, summary["autopilot_params"] = connect(fw, mod, a.params)
    summary["firmware_params"] = dict(a.params)
    fw.take_off(g, a.alt)
    cruise = fw.cruise_airspeed(g)
    radius = float(cfg.path.radius_m) if cfg.path.type == "circle" else 0.0
    g.pump(0.3)
    centre, start = place_any(g, cfg, a.lead * a.speedup, a.start_offset)
    sets = mission_sets(a, v, centre)
    summary["mission"] = {
        "path": cfg.path.type,
        "radius_m": radius or None,
        "centre_ned_m": centre,
        "target": v["target_label"],
        "airspeed_m_s": cfg.vehicle.airspeed_m_s,
        "autopilot_cruise_airspeed_m_s": cruise,
        "start_offset_m": list(a.start_offset) if a.start_offset else None,
        "start_ned_m": start,
        "overrides": sets,
    }
    if a.guidance == "native":
        try:
            summary.update(native.fly_native(a, v, g, centre, sets, out))
        finally:
            g.close()
        return 0 if summary["verdict"] == "FLOWN" else 1
    relay = None
    url = fw.bridge_url
    if a.serial:
        from lab.rigs.pty_relay import PtyRelay

        relay = PtyRelay(fw.bridge_port)
        url = f"{relay.device}:115200"
        summary["serial"] = {"device": relay.device, "relayed_to": fw.bridge_url}
    cmd = _bridge_command(a, v, url, sets)
    print("hand-over: mpf-mavlink " + " ".join(cmd[3:]), flush=True)
    bridge = start_bridge(cmd, out / "bridge.log")
    kill: dict[str, Any] = {}
    try:
        kill = _until_bridge_exits(a, g, mod, bridge, (centre, radius), out)
        code = bridge.wait()
    finally:
        stop_bridge(bridge)
        if relay is not None:
            summary["serial"].update(
                bytes_to_autopilot=relay.bytes_up,
                bytes_to_bridge=relay.bytes_down,
                bytes_dropped=relay.dropped,
            )
            relay.close()
    g.close()
    summary.update(figures_of(out / "bridge", out / "bridge.log", code, kill, cfg, mod))
    if a.sil and not kill:
        summary["sil"] = sil_leg(a, v, sets, summary, out)
    return 0 if summary["verdict"] == "PASS" else 1


def hold_bank_limit_deg(g: Gcs, mod: ModuleType) -> float:
    """The autopilot's own roll limit (deg, its parameter), which its hold flies within;
    HOLD_BANK_DEG when the parameter cannot be read, said on the terminal."""
    v = g.get_param(mod.ROLL_LIMIT_PARAM)
    if v is None or not math.isfinite(v) or v <= 0.0:
        print(
            f"  {mod.ROLL_LIMIT_PARAM} not read: hold judged with |bank| <= {HOLD_BANK_DEG:g} deg"
        )
        return HOLD_BANK_DEG
    return float(v)


def watch_hold(
    g: Gcs,
    mod: ModuleType,
    secs: float,
    centre: list[float],
    alt_m: float,
    radius: float,
    out: Path,
) -> dict[str, Any]:
    """What the autopilot does on its own for ``secs`` (its clock) after the bridge died; its
    roll limit is read after the watch, so the parameter exchange costs none of it."""
    t0 = g.t_boot_s
    modes: list[str] = []
    trace: list[tuple[float, float, float, float, float]] = []
    while g.t_boot_s - t0 < secs:
        g.pump(0.1)
        g.note_hold(modes, trace, g.t_boot_s - t0)
    with open(out / "after_kill.csv", "w") as f:
        f.write("t_s,roll_rad,north_m,east_m,down_m\n")
        f.writelines(",".join(f"{x:.4f}" for x in r) + "\n" for r in trace)
    h = hold_figures(trace, (centre[0], centre[1]), alt_m, radius, hold_bank_limit_deg(g, mod))
    h["modes"] = modes
    return h


def figures_of(
    run: Path, log: Path, code: int, kill: dict[str, Any], cfg: Any, mod: ModuleType
) -> dict[str, Any]:
    """The summary's figures and verdict, from the bridge's run directory (or, after a kill,
    its log and tlog: a SIGKILLed bridge writes no metrics.json)."""
    m = read_json(run / "metrics.json")
    text = log.read_text(errors="replace") if log.is_file() else ""
    engaged = m.get("state_reached") == "TRACKING" or " confirmed: tracking" in text
    fallback = m.get("fallback") or next(
        (
            ln.split(": ", 1)[1]
            for ln in text.splitlines()
            if ln.startswith("fallback if the bridge dies: ")
        ),
        None,
    )
    f: dict[str, Any] = {
        "engaged": engaged,
        "fallback": fallback,
        "first_within_s": m.get("first_within_s"),
        "stays_within_s": m.get("convergence_time_s"),
        "steady_rms_m": m.get("steady_rms_m"),
        "steady_max_m": m.get("steady_max_m"),
        "steady_mean_vertical_m": m.get("steady_mean_vertical_m"),
        "thrust_at_ceiling": m.get("thrust_saturated_fraction"),
        "tracked_s": m.get("tracked_s"),
        "handback_confirmed": m.get("handback_confirmed"),
        "turn_gain": (m.get("adapter_learned") or {}).get("turn_gain"),
        "loop_delay_s": (m.get("delay_compensation") or {}).get("loop_delay_s"),
        "loop_delay_source": (m.get("delay_compensation") or {}).get("loop_delay_source"),
        # as flown: ATTITUDE received over the tracking span (the bridge's start-up sample of its
        # rate was taken before the rates it asked for had all arrived)
        "attitude_hz": tlog_stream_hz(run / "mavlink.tlog"),
        "attitude_hz_at_start": (
            ((m.get("streams") or {}).get("messages") or {}).get("ATTITUDE") or {}
        ).get("measured_hz"),
    }
    if cfg.path.type == "circle":
        f["steady_mean_radial_m"] = m.get("steady_mean_radial_m")
    f.update(cross_track(run, cfg.metrics.steady_after_s))
    f.update(run_record_figures(run, cfg))  # e: the same function as --guidance native's
    out: dict[str, Any] = {"figures": f}
    if kill:
        counts = tlog_counts(run / "mavlink.tlog")
        out["bridge_exit"] = f"SIGKILLed by the rig {kill['killed_after_s']:.1f} s into tracking"
        out["bridge_sent"] = counts.get("sent", {})
        f["tracked_s"] = kill["killed_after_s"]  # the autopilot's seconds, engaged to killed
        f["handback_confirmed"] = None  # nothing to hand back: the autopilot's fallback flies
        out["hold"] = kill
        why = [] if engaged else ["never engaged"]
        if kill["hold_verdict"] != "PASS":
            why.append("hold " + kill["hold_verdict"])
        out["verdict"] = "PASS" if not why else "FAIL: " + "; ".join(why)
        return out
    out["bridge_exit"] = f"{m.get('exit_reason', 'no metrics.json')} (code {code})"
    out["bridge_verdict"] = m.get("verdict")
    why = []
    if not engaged:
        why.append("never engaged")
    if m.get("handback_confirmed") is not True:
        why.append("hand-back not confirmed")
    bv = str(m.get("verdict") or "")
    if bv.startswith("verdict: NOT JUDGED") and not why:
        # exit 6: ran to its end, shorter than its steady window: neither a pass nor a failure
        out["verdict"] = bv.removeprefix("verdict: ")
        return out
    if bv != "verdict: PASS":
        why.append(bv or "the bridge judged nothing")
    if code != 0:
        why.append(f"bridge exit code {code}")
    out["verdict"] = "PASS" if not why else "FAIL: " + "; ".join(dict.fromkeys(why))
    return out


def sil_leg(
    a: argparse.Namespace, v: dict[str, Any], sets: list[str], summary: dict[str, Any], out: Path
) -> dict[str, Any]:
    """Our SIL on the same mission and start state (the real aircraft's at engagement, the
    first row of its run record): the start state goes into ``kinematic.initial_*`` too, so the
    checks judge the state the SIL flies (a warning there is about that state: the aircraft
    engaged off the circle when the bridge took longer than ``--lead`` to engage)."""
    import numpy as np

    ts = out / "bridge" / "timeseries.csv"
    if not ts.is_file():
        return {"error": "not flown (no real run record)"}
    d = np.genfromtxt(ts, delimiter=",", names=True, max_rows=30)
    if d.size < 2:
        return {"error": "not flown (real run too short)"}
    p0 = [float(d["p_n"][0]), float(d["p_e"][0]), float(d["p_d"][0])]
    hdg = math.atan2(d["p_e"][-1] - d["p_e"][0], d["p_n"][-1] - d["p_n"][0])
    sil_sets = [
        *sets,
        "sil.link=udp",
        f"sil.flavour={v['mod'].FLAVOUR.value}",
        "sil.initial_mode=cruise",
        f"kinematic.initial_position_ned_m=[{p0[0]:.2f},{p0[1]:.2f},{p0[2]:.2f}]",
        f"kinematic.initial_attitude_rpy_rad=[0,0,{hdg:.4f}]",
        f"aircraft.trim_airspeed_m_s={v['cfg'].vehicle.airspeed_m_s:g}",
    ]
    from mpf_mavlink.config.autopilot_profile import calibrated_sets

    # the calibrated SIL: the flavour's identified profile unless the config names one
    prof_sets, prof_label = calibrated_sets(v["cfg"])
    sil_sets += prof_sets
    if a.wind is not None:
        sil_sets.append(arduplane.sil_wind_set(*a.wind))
    if a.turbulence:
        sil_sets.append(f"sil.wind_turbulence_m_s={a.turbulence:g}")  # SIM_WIND_TURB's model
    cmd = [
        sys.executable,
        "-m",
        "mpf_mavlink.cli",
        "sim",
        str(v["config"]),
        "--out",
        str(out / "sil"),
        "--set",
        f"sim.duration_s={a.duration:g}",
        *[x for s in sil_sets for x in ("--set", s)],
    ]
    with open(out / "sil.log", "w") as f:
        r = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, check=False)
    sm = read_json(out / "sil" / "metrics.json")
    real, ours = summary["figures"].get("steady_rms_m"), sm.get("steady_rms_m")
    log = (out / "sil.log").read_text(errors="replace").splitlines()
    warn = [ln for ln in log if "[WARN]" in ln]
    refused = sil_refusal(r.returncode, log)
    return {
        **({"error": refused} if refused else {}),
        "exit_code": r.returncode,
        "steady_rms_m": ours,
        "steady_mean_vertical_m": sm.get("steady_mean_vertical_m"),
        "steady_mean_radial_m": sm.get("steady_mean_radial_m"),
        "real_over_sil": (real / ours) if (real is not None and ours) else None,
        "autopilot_profile": prof_label,
        "warnings": warn,
    }


def sil_refusal(code: int, log: list[str]) -> str | None:
    """Why ``mpf-mavlink sim`` did not fly (its log's lines): the refusal line of exit 3 (a
    failed check), or the last line of another non-flown exit; None when it flew."""
    from mpf_mavlink.runs.compare import FLOWN_EXIT_CODES

    if code in FLOWN_EXIT_CODES:
        return None
    lines = [ln.strip() for ln in log if ln.strip()]
    line = next((ln for ln in reversed(lines) if "refused to fly" in ln), None)
    if line is None:
        line = lines[-1] if lines else "no output"
    what = "refused by check" if code == 3 else "not flown"
    return f"{what} (exit {code}): {line.split('refused to fly: ', 1)[-1]}"


def _rows_setting(s: dict[str, Any]) -> list[tuple[str, str]]:
    """What was flown: flight, firmware, mission, wind, speed-up, serial link."""
    ms = s.get("mission", {})
    r = [("flight", s.get("flight", "?")), ("firmware", s.get("bundle", "?"))]
    r.append(("guidance", _guidance_words(s)))
    if s.get("firmware_params"):
        r.append(
            (
                "firmware parameters",
                ", ".join(f"{k}={v:g}" for k, v in s["firmware_params"].items()),
            )
        )
    if ms:
        r += [
            ("mission", f"{ms['path']} r {fmt(ms['radius_m'])} m, {ms['target']}"),
            (
                "airspeed: config / autopilot cruise",
                f"{fmt(ms['airspeed_m_s'])} / {fmt(ms['autopilot_cruise_airspeed_m_s'])} m/s",
            ),
        ]
    if s.get("wind") or s.get("turbulence"):
        w = s.get("wind") or [0, 0]
        r.append(
            (
                "wind",
                f"{w[0]:g} m/s from {w[1]:g} deg, turbulence {fmt(s.get('turbulence') or 0)} m/s",
            )
        )
    if s.get("speedup", 1.0) != 1.0:
        r.append(("speed-up", f"{s['speedup']:g}x"))
    if "serial" in s:
        r.append(("serial", f"{s['serial']['device']} <-> {s['serial']['relayed_to']}"))
    return r


def _guidance_words(s: dict[str, Any]) -> str:
    if s.get("guidance") != "native":
        return "MPF (mpf-mavlink run)"
    n = s.get("native") or {}
    return f"the firmware's own: {n.get('command', '?')} at {fmt(n.get('rate_hz'), 'g')} Hz"


def _rows_e(f: dict[str, Any]) -> list[tuple[str, str]]:
    """The head-to-head's figures: e, the 3D distance from the moving path (the same function
    for both guidances, :func:`lab.rigs.figures.moving_path_figures`)."""
    r = [
        (
            "steady e RMS / max (to moving path)",
            f"{fmt(f.get('e_rms_m'))} / {fmt(f.get('e_max_m'))} m",
        ),
        (
            "steady e mean vertical (up +)",
            f"{fmt(f.get('e_mean_vertical_m'))} m",
        ),
    ]
    if "e_mean_radial_m" in f:
        r.append(("steady e mean radial (out +)", f"{fmt(f.get('e_mean_radial_m'))} m"))
    return r


def _rows_native(s: dict[str, Any], f: dict[str, Any]) -> list[tuple[str, str]]:
    """The firmware's own guidance: what the rig set and sent, and the same figures as MPF's."""
    n = s.get("native") or {}
    sp = n.get("speed") or {}
    return [
        ("engaged (mode + accepted)", "yes" if f.get("engaged") else "NO"),
        ("modes", " -> ".join(n.get("modes", []))),
        ("centre commands sent / acks", f"{n.get('centre_commands_sent')} / {n.get('acks')}"),
        ("speed set", str(sp.get("set"))),
        (
            "true airspeed: wanted / flown (steady)",
            f"{fmt(sp.get('true_airspeed_wanted_m_s'))} / "
            f"{fmt(sp.get('true_airspeed_flown_m_s'))} m/s "
            f"(true/indicated {fmt(sp.get('true_over_indicated_measured'), '.4f')})",
        ),
        ("tracked", f"{fmt(f.get('tracked_s'), '.1f')} s"),
        (
            "e first within / stays within",
            f"{fmt(f.get('e_first_within_s'), '.1f')} / {fmt(f.get('e_stays_within_s'), '.1f')} s",
        ),
        *_rows_e(f),
        (
            "steady cross-track RMS / max",
            f"{fmt(f.get('cross_track_rms_m'))} / {fmt(f.get('cross_track_max_m'))} m",
        ),
        ("steady mean cross-track (left +)", f"{fmt(f.get('cross_track_mean_m'))} m"),
    ]


def _rows_after_kill(
    s: dict[str, Any], f: dict[str, Any], h: dict[str, Any]
) -> list[tuple[str, str]]:
    """A SIGKILLed bridge leaves no run record: what the tlog and the autopilot say."""
    return [
        ("tracked before the kill", f"{fmt(f.get('tracked_s'), '.1f')} s"),
        ("fallback (bridge's word)", fmt(f.get("fallback"))),
        (
            "setpoints sent (its tlog)",
            str(s.get("bridge_sent", {}).get("SET_ATTITUDE_TARGET", 0)),
        ),
        ("after SIGKILL: modes", " -> ".join(h.get("modes", []))),
        (
            "after SIGKILL: max from centre",
            f"{fmt(h.get('max_dist_from_centre_m'), '.1f')} m "
            f"(last 15 s mean {fmt(h.get('last15_mean_dist_m'), '.1f')} m) "
            f"over {fmt(h.get('watched_s'), '.0f')} s",
        ),
        (
            "after SIGKILL: max |bank| / |alt error|",
            f"{fmt(h.get('max_bank_deg'), '.1f')} deg / {fmt(h.get('max_alt_error_m'), '.1f')} m",
        ),
        ("after SIGKILL: hold", h.get("hold_verdict", "?")),
    ]


def _rows_tracking(f: dict[str, Any]) -> list[tuple[str, str]]:
    """How the bridge engaged, tracked and handed back (its run record's figures)."""
    r = [
        ("hand-back confirmed", fmt(f.get("handback_confirmed"))),
        ("tracked", f"{fmt(f.get('tracked_s'), '.1f')} s"),
        (
            "first within / stays within",
            f"{fmt(f.get('first_within_s'), '.1f')} / {fmt(f.get('stays_within_s'), '.1f')} s",
        ),
        ("steady RMS / max |pt|", f"{fmt(f.get('steady_rms_m'))} / {fmt(f.get('steady_max_m'))} m"),
        (
            "steady cross-track RMS / max",
            f"{fmt(f.get('cross_track_rms_m'))} / {fmt(f.get('cross_track_max_m'))} m",
        ),
        ("steady mean cross-track (left +)", f"{fmt(f.get('cross_track_mean_m'))} m"),
        ("steady mean vertical (up +)", f"{fmt(f.get('steady_mean_vertical_m'))} m"),
    ]
    if "steady_mean_radial_m" in f:
        r.append(("steady mean radial (out +)", f"{fmt(f.get('steady_mean_radial_m'))} m"))
    r += _rows_e(f)
    r += [
        (
            "thrust at ceiling",
            f"{fmt(f.get('thrust_at_ceiling'), '.1%')}"
            if f.get("thrust_at_ceiling") is not None
            else "n/a",
        ),
        ("loop delay", f"{fmt(f.get('loop_delay_s'))} s ({f.get('loop_delay_source') or 'n/a'})"),
        (
            "ATTITUDE rate / turn gain",
            f"{fmt(f.get('attitude_hz'), '.1f')} Hz / {fmt(f.get('turn_gain'))}",
        ),
        ("fallback (bridge's word)", fmt(f.get("fallback"))),
    ]
    return r


def _rows_sil(sil: dict[str, Any]) -> list[tuple[str, str]]:
    """The same mission in our SIL, beside the real firmware's figures."""
    return [
        (
            "our SIL: steady RMS |pt|",
            f"{fmt(sil.get('steady_rms_m'))} m" if "error" not in sil else sil["error"],
        ),
        (
            "our SIL: mean vertical / radial",
            f"{fmt(sil.get('steady_mean_vertical_m'))} / {fmt(sil.get('steady_mean_radial_m'))} m",
        ),
        ("real / our SIL RMS", fmt(sil.get("real_over_sil"))),
        ("our SIL: autopilot profile", str(sil.get("autopilot_profile", "none"))),
        (
            "our SIL: check warnings",
            "; ".join(w.split("]", 1)[1].split(":")[0].strip() for w in sil.get("warnings", []))
            or "none",
        ),
    ]


def rows(s: dict[str, Any]) -> list[tuple[str, str]]:
    f = s.get("figures", {})
    r = _rows_setting(s)
    if not f:
        return r + [("verdict", s.get("verdict", "?"))]
    if s.get("guidance") == "native":
        return r + _rows_native(s, f) + [("verdict", s.get("verdict", "?"))]
    h = s.get("hold")
    r += [
        ("bridge exit", s.get("bridge_exit", "?")),
        ("engaged by itself", "yes" if f.get("engaged") else "NO"),
    ]
    if h:
        return r + _rows_after_kill(s, f, h) + [("verdict", s.get("verdict", "?"))]
    r += _rows_tracking(f)
    sil = s.get("sil")
    if sil:
        r += _rows_sil(sil)
    if s.get("bridge_verdict"):
        r.append(("bridge", s["bridge_verdict"]))
    r.append(("verdict", s.get("verdict", "?")))
    return r


def print_table(s: dict[str, Any], out: Path) -> None:
    rr = rows(s)
    w = max(len(k) for k, _ in rr)
    print(f"\n{'SITL rig: ' + s.get('autopilot', '?'):<{w}}  result")
    print("-" * (w + 50))
    for k, val in rr:
        print(f"{k:<{w}}  {val}")
    what = (
        "summary.json, native_track.csv, firmware/"
        if s.get("guidance") == "native"
        else "summary.json, bridge/, bridge.log, firmware/"
    )
    print(f"{'run directory':<{w}}  {out}  ({what})")


def record(s: dict[str, Any]) -> None:
    """Write this flight's summary into docs/results and regenerate the results table."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    keep = {
        k: s.get(k)
        for k in (
            "flight",
            "autopilot",
            "bundle",
            "config",
            "speedup",
            "commit",
            "date",
            "wind",
            "turbulence",
            "mission",
            "figures",
            "hold",
            "sil",
            "verdict",
            "bridge_verdict",
            "command",
            "guidance",
            "native",
            "firmware_params",
        )
    }
    (RESULTS / f"sitl-{s['flight']}.json").write_text(
        json.dumps(keep, indent=2, default=str) + "\n"
    )
    write_results_table()


def write_results_table() -> Path:
    lines = [
        "# Real-firmware flights (written by `scripts/sitl ... --record`; do not edit by hand)",
        "",
        "Steady figures from t >= 60 s of tracking. Cross-track: horizontal distance to the path,",
        "+ left of travel (outward on a clockwise circle). Hold: after SIGKILL of the bridge.",
        "",
        "| flight | firmware | config | tracked (s) | steady RMS / max pt (m) "
        "| cross-track RMS / mean (m) | mean vertical / radial (m) | thrust at ceiling "
        "| our SIL RMS (m), real/SIL | hold after kill | verdict | commit, date |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for p in sorted(RESULTS.glob("sitl-*.json")):
        s = read_json(p)
        f, h = s.get("figures") or {}, s.get("hold") or {}
        hold = (
            (
                f"{fmt(h.get('max_dist_from_centre_m'), '.0f')} m, "
                f"{fmt(h.get('max_bank_deg'), '.0f')} deg, "
                f"{fmt(h.get('max_alt_error_m'), '.1f')} m: {h.get('hold_verdict')}"
            )
            if h
            else ""
        )
        thr = f.get("thrust_at_ceiling")
        sil = s.get("sil") or {}
        sil_txt = f"{fmt(sil.get('steady_rms_m'))}, {fmt(sil.get('real_over_sil'))}x" if sil else ""
        if sil.get("error"):
            sil_txt = str(sil["error"]).replace("|", "/")
        lines.append(
            f"| {s.get('flight')} | {s.get('bundle', '')} | {s.get('config')} "
            f"| {fmt(f.get('tracked_s'), '.0f')} "
            f"| {fmt(f.get('steady_rms_m'))} / {fmt(f.get('steady_max_m'))} "
            f"| {fmt(f.get('cross_track_rms_m'))} / {fmt(f.get('cross_track_mean_m'))} "
            f"| {fmt(f.get('steady_mean_vertical_m'))} / {fmt(f.get('steady_mean_radial_m'))} "
            f"| {'n/a' if thr is None else f'{thr:.1%}'} | {sil_txt} | {hold} | {s.get('verdict')} "
            f"| {s.get('commit', '')}, {str(s.get('date', ''))[:10]} |"
        )
    md = RESULTS / "sitl.md"
    md.write_text("\n".join(lines) + "\n")
    return md


def _git_commit() -> str:
    try:
        r = subprocess.run(
            ["git", "-C", str(ROOT), "describe", "--always", "--dirty"],
            capture_output=True,
            text=True,
            timeout=10,
            check=False,
        )
    except OSError:
        return "?"
    return r.stdout.strip() or "?"
