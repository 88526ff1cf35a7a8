"""The soak campaign's rig (:mod:`lab.soak`): the vehicle and bridge processes, the relay's tap
of all traffic, a mission (vehicle + relay + bridge), the checks on what the tap saw, result
rows."""

from __future__ import annotations

import argparse
import contextlib
import gc
import json
import math
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as M

from lab.soak.relay import DOWN, Blackout, Impairment, UdpRelay
from mpf_mavlink.mavlink.modes import is_offboard, mode_name
from mpf_mavlink.mavlink.url import free_udp_port

if TYPE_CHECKING:
    from mpf_mavlink.core.target import ConstantTurn, Stationary
    from sim.vehicle.vehicle import SimVehicle

ROOT = Path(__file__).resolve().parents[2]  # the repository (lab/soak/rig.py)
CONFIGS = {
    "px4": ROOT / "configs" / "bridge_px4.yaml",
    "ardupilot": ROOT / "configs" / "bridge_arduplane.yaml",
}
VEHICLE_SYSID, VEHICLE_COMPID, TARGET_SYSID = 1, 1, 2
# Where the SIL vehicle starts: 60 m outside the 150 m circle of configs/bridge_*.yaml, on its
# west side, flying north (the circle's clockwise direction there): a short capture, then steady.
START_NED = (0.0, -210.0, -100.0)
START_HEADING = 0.0
# Quick missions start on the circle itself (its west point, flying north): steady at once.
# ... and held there in the orbit the path is (the operator's loiter about the path centre before
# the mission): the vehicle is on the path however long the bridge takes to engage
START_ON_PATH = ("--position", "0", "-150", "-100", "--orbit", "0", "0", "150")


def mpf_mavlink_cmd() -> list[str]:
    """The installed ``mpf-mavlink`` console script next to this interpreter (what a user
    runs), else the module."""
    exe = Path(sys.executable).parent / "mpf-mavlink"
    return [str(exe)] if exe.is_file() else [sys.executable, "-m", "mpf_mavlink.cli"]


# ----------------------------------------------------------------------------- the vehicle process
def _vehicle_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m lab.soak vehicle")
    ap.add_argument("--flavour", choices=("px4", "ardupilot"), default="px4")
    ap.add_argument("--url", required=True)
    ap.add_argument("--plant", choices=("jsbsim", "kinematic"), default="jsbsim")
    ap.add_argument("--clock", choices=("lockstep", "realtime"), default="realtime")
    ap.add_argument("--position", type=float, nargs=3, default=START_NED)
    ap.add_argument("--heading", type=float, default=START_HEADING)
    ap.add_argument(
        "--orbit",
        type=float,
        nargs=3,
        default=None,
        metavar=("N", "E", "RADIUS"),
        help="boot in a hold orbit about (N, E) m at RADIUS m (default: about the start)",
    )
    ap.add_argument("--airspeed", type=float, default=15.0)
    ap.add_argument("--target", choices=("none", "stationary", "drift"), default="none")
    ap.add_argument("--com-of-loss-t", type=float, default=1.0)
    ap.add_argument("--guided-timeout", type=float, default=3.0)
    ap.add_argument("--signing-key-hex", default=None)
    ap.add_argument("--report", default=None)
    ap.add_argument(
        "--spare",
        action="store_true",
        help="build the rebooted vehicle in advance (SIGUSR1 swaps at once)",
    )
    return ap


def _vehicle_target(kind: str) -> Stationary | ConstantTurn | None:
    """The target system the vehicle simulates (``--target``), 100 m up over the origin."""
    from mpf_mavlink.core.target import ConstantTurn, Stationary

    if kind == "stationary":
        return Stationary((0.0, 0.0, -100.0))
    if kind == "drift":
        return ConstantTurn((0.0, 0.0, -100.0), speed=3.0, heading=math.pi / 2)
    return None


def _make_vehicle(a: argparse.Namespace, target: Stationary | ConstantTurn | None) -> SimVehicle:
    from sim.vehicle.vehicle import SimVehicle

    v = SimVehicle.build(
        a.flavour,
        a.url,
        plant=a.plant,
        clock=a.clock,
        position_ned=tuple(a.position),
        heading=a.heading,
        airspeed=a.airspeed,
        target=target,
        target_system=TARGET_SYSID,
        com_of_loss_t=a.com_of_loss_t,
        guided_timeout=a.guided_timeout,
        record_truth=False,
        initial_orbit=tuple(a.orbit) if a.orbit else None,
    )
    if a.signing_key_hex:
        key = bytes.fromhex(a.signing_key_hex)
        # the vehicle signs what it (and its target system) sends and rejects unsigned input
        v.link.conn.setup_signing(key, sign_outgoing=True, allow_unsigned_callback=None)
        ticks = int((time.time() - 1420070400) * 100_000)
        for mav in (
            v.link.mav,
            v.link.tmav,
        ):  # the encoders that write into the vehicle's send queue
            mav.signing.secret_key, mav.signing.sign_outgoing = key, True
            mav.signing.link_id, mav.signing.timestamp = 0, ticks
    return v


def _vehicle_report(v: SimVehicle) -> dict[str, Any]:
    return {
        "t": v.t,
        "time_boot_s": v.time_boot_s,
        "mode": v.mode_name,
        "mode_changes": v.modes.changes,
        "statustexts": v.link.statustexts,
        "dropped": v.autopilot.setpoints.dropped,
        "setpoints_received": v.lockstep.answers,
        "rx_count": v.link.rx_count,
        "real_time_factor": v.real_time_factor,
    }


def vehicle_main(argv: list[str]) -> int:
    """``python -m lab.soak vehicle``: a SimVehicle until SIGTERM, then a JSON report."""
    a = _vehicle_parser().parse_args(argv)
    target = _vehicle_target(a.target)

    def make() -> SimVehicle:
        return _make_vehicle(a, target)

    v = make()
    spare = make() if a.spare else None  # built now: a SIGUSR1 reboot is then only a swap
    reboot = threading.Event()

    def on_usr1(*_: Any) -> None:  # an in-process reboot: new boot clock, boot mode, new socket
        reboot.set()
        v.stop(0.0)

    signal.signal(signal.SIGTERM, lambda *_: v.stop(0.0))
    signal.signal(signal.SIGUSR1, on_usr1)
    print(f"vehicle ready: {a.flavour} {v.mode_name} on {a.url}", flush=True)
    try:
        while True:
            v.run(math.inf)
            if not reboot.is_set():
                break
            reboot.clear()
            v.close()
            v, spare = (spare, None) if spare is not None else (make(), None)
            print(f"vehicle rebooted: {v.mode_name}, time_boot {v.time_boot_s:.2f} s", flush=True)
    except KeyboardInterrupt:
        pass
    finally:
        report = _vehicle_report(v)
        if a.report:
            Path(a.report).write_text(json.dumps(report, default=float))
        v.close()
    return 0


class VehicleProc:
    """The SIL vehicle in its own process (so it can be killed and restarted like a real one)."""

    def __init__(
        self,
        flavour: str,
        url: str,
        workdir: Path,
        *,
        target: str = "none",
        signing_key: bytes | None = None,
        extra: tuple[str, ...] = (),
    ) -> None:
        self.flavour, self.url, self.workdir = flavour, url, workdir
        self.target, self.signing_key, self.extra = target, signing_key, extra
        self.proc: subprocess.Popen[str] | None = None
        self.boots = 0
        self.report: dict[str, Any] = {}

    def start(self) -> VehicleProc:
        self.boots += 1
        self.report_path = self.workdir / f"vehicle-{self.boots}.json"
        cmd = [
            sys.executable,
            "-m",
            "lab.soak",
            "vehicle",
            "--flavour",
            self.flavour,
            "--url",
            self.url,
            "--target",
            self.target,
            "--report",
            str(self.report_path),
            *self.extra,
        ]
        if self.signing_key is not None:
            cmd += ["--signing-key-hex", self.signing_key.hex()]
        self.log = open(self.workdir / f"vehicle-{self.boots}.log", "w")  # noqa: SIM115
        self.proc = subprocess.Popen(
            cmd, cwd=ROOT, stdout=self.log, stderr=subprocess.STDOUT, text=True
        )
        return self

    def kill(self) -> None:
        """Power cut: SIGKILL, no report."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(5)
        self.log.close()

    def stop(self) -> dict[str, Any]:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self.log.close()
        with contextlib.suppress(OSError, ValueError):
            self.report = json.loads(self.report_path.read_text())
        return self.report


@dataclass
class BridgeOutcome:
    rc: int | None
    stdout: str
    stderr: str
    metrics: dict[str, Any]
    out_dir: Path

    @property
    def exit_reason(self) -> str:
        return str(self.metrics.get("exit_reason", ""))

    @property
    def counters(self) -> dict[str, Any]:
        return dict(self.metrics.get("counters", {}))


class BridgeProc:
    """``mpf-mavlink run`` as a real subprocess."""

    def __init__(
        self,
        config: Path,
        url: str,
        out_dir: Path,
        duration_s: float,
        sets: tuple[str, ...] = (),
        extra: tuple[str, ...] = (),
        prefix: tuple[str, ...] = (),
    ) -> None:
        self.out_dir = out_dir
        self.cmd = [
            *prefix,
            *mpf_mavlink_cmd(),
            "run",
            str(config),
            "--connect",
            url,
            "--out",
            str(out_dir),
            "--duration",
            f"{duration_s:g}",
            "--no-plots",
            "-q",
            *extra,
        ]
        for s in ("mavlink.heartbeat_timeout_s=15", *sets):
            self.cmd += ["--set", s]
        self.proc: subprocess.Popen[str] | None = None

    def start(self) -> BridgeProc:
        self.proc = subprocess.Popen(
            self.cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        return self

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def wait(self, timeout: float) -> BridgeOutcome:
        assert self.proc is not None
        try:
            out, err = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            out, err = self.proc.communicate()
            err += f"\n[soak] bridge killed after {timeout:g} s"
        metrics: dict[str, Any] = {}
        with contextlib.suppress(OSError, ValueError):
            metrics = json.loads((self.out_dir / "metrics.json").read_text())
        return BridgeOutcome(self.proc.returncode, out, err, metrics, self.out_dir)

    def kill(self) -> None:
        if self.alive():
            assert self.proc is not None
            self.proc.kill()
            self.proc.communicate()


# ----------------------------------------------------------------------------- the tap
@dataclass
class Event:
    t: float  # relay time (s)
    msg: Any


class Tap:
    """Parses what the relay saw. DOWN: what the vehicle (and its target system) SENT, whatever
    the relay then did with it; UP: what the vehicle RECEIVED from the bridge (after loss and
    corruption). Injected datagrams are kept apart (``injected_up``)."""

    def __init__(self, relay: UdpRelay, flavour: str) -> None:
        self.relay, self.flavour = relay, flavour
        self._i = 0
        self._parser = M.MAVLink(None)
        self._parser.robust_parsing = True
        self.heartbeats: list[Event] = []  # the autopilot's (1/1)
        self.statustexts: list[Event] = []
        self.attitude_ms: list[
            tuple[float, int]
        ] = []  # (relay t, time_boot_ms) of the vehicle's ATTITUDE
        self.target_msgs: list[Event] = []  # from the target system
        self.setpoints: list[Event] = []  # SET_ATTITUDE_TARGET delivered to the vehicle
        self.commands: list[Event] = []  # COMMAND_LONG delivered to the vehicle
        self.bridge_setpoints: list[Event] = []  # SET_ATTITUDE_TARGET the bridge sent (any fate)
        self.bridge_commands: list[Event] = []  # COMMAND_LONG the bridge sent (any fate)
        self.up_other: list[Event] = []
        self.injected_up: list[Event] = []
        self.bad_up = 0  # delivered-upward frames that fail to parse (corruption by the relay)

    def _parse(self, data: bytes) -> list[Any]:
        p = self._parser
        p.buf, p.buf_index, p.expected_length = bytearray(), 0, M.HEADER_LEN_V1 + 2
        try:
            return [m for m in (p.parse_buffer(data) or []) if m.get_type() != "BAD_DATA"]
        except Exception:  # noqa: BLE001 - a corrupted datagram
            return []

    def update(self) -> Tap:
        for d in self.relay.datagrams(start=self._i):
            self._i += 1
            if d.direction == DOWN:
                if d.fate == "injected":
                    continue
                for m in self._parse(d.data):
                    src, t = (m.get_srcSystem(), m.get_srcComponent()), m.get_type()
                    if src == (VEHICLE_SYSID, VEHICLE_COMPID):
                        if t == "HEARTBEAT":
                            self.heartbeats.append(Event(d.t, m))
                        elif t == "STATUSTEXT":
                            self.statustexts.append(Event(d.t, m))
                        elif t == "ATTITUDE":
                            self.attitude_ms.append((d.t, int(m.time_boot_ms)))
                    elif src[0] == TARGET_SYSID:
                        self.target_msgs.append(Event(d.t, m))
            else:
                msgs = self._parse(d.data)
                if d.fate == "injected":
                    self.injected_up += [Event(d.t, m) for m in msgs]
                    continue
                for m in msgs:  # what the bridge emitted, whatever the relay did with it
                    if m.get_type() == "SET_ATTITUDE_TARGET":
                        self.bridge_setpoints.append(Event(d.t, m))
                    elif m.get_type() == "COMMAND_LONG":
                        self.bridge_commands.append(Event(d.t, m))
                if d.fate != "delivered":
                    continue
                if d.corrupted:
                    msgs = self._parse(d.sent or b"")
                    if not msgs:
                        self.bad_up += 1
                for m in msgs:  # what the vehicle received
                    ev = Event(d.t, m)
                    if m.get_type() == "SET_ATTITUDE_TARGET":
                        self.setpoints.append(ev)
                    elif m.get_type() == "COMMAND_LONG":
                        self.commands.append(ev)
                    else:
                        self.up_other.append(ev)
        return self

    # -- views -----------------------------------------------------------------------------
    def mode(self) -> str | None:
        return mode_name(self.flavour, self.heartbeats[-1].msg) if self.heartbeats else None

    def offboard_now(self) -> bool:
        return bool(self.heartbeats) and is_offboard(self.flavour, self.heartbeats[-1].msg)

    def first_offboard_t(self) -> float | None:
        for e in self.heartbeats:
            if is_offboard(self.flavour, e.msg):
                return e.t
        return None

    def mode_changes(self) -> list[tuple[float, str]]:
        out: list[tuple[float, str]] = []
        for e in self.heartbeats:
            name = mode_name(self.flavour, e.msg)
            if not out or out[-1][1] != name:
                out.append((e.t, name))
        return out

    def vehicle_ms(self) -> int | None:
        return self.attitude_ms[-1][1] if self.attitude_ms else None

    def vehicle_s(self, t: float) -> float:
        """The vehicle's boot clock (s) at relay time ``t``, interpolated between the ATTITUDEs
        it sent (to a 20 ms frame). The vehicle's own timeouts run on this clock: a loaded
        host that leaves its process waiting stretches wall time, not this."""
        ts = [a for a, _ in self.attitude_ms]
        ms = [b * 1e-3 for _, b in self.attitude_ms]
        return float(np.interp(t, ts, ms))

    def mode_requests(self) -> list[Event]:
        """DO_SET_MODE the bridge sent (whether or not the relay delivered it)."""
        return [e for e in self.bridge_commands if e.msg.command == M.MAV_CMD_DO_SET_MODE]

    def failsafes(self) -> list[Event]:
        return [e for e in self.statustexts if "Failsafe" in str(e.msg.text)]

    def left_offboard_after(self, t: float) -> float | None:
        """When the vehicle left its offboard mode after ``t``: its STATUSTEXT ("Mode X" or
        "Failsafe: ...") is sent at the change, the HEARTBEAT only up to 1 s later."""
        off = "OFFBOARD" if self.flavour == "px4" else "GUIDED"
        for e in self.statustexts:
            text = str(e.msg.text)
            if e.t >= t and ("Failsafe" in text or (text.startswith("Mode ") and text[5:] != off)):
                return e.t
        return None

    def first_mode_after(self, t: float, pred: Callable[[str], bool]) -> float | None:
        for e in self.heartbeats:
            if e.t >= t and pred(mode_name(self.flavour, e.msg)):
                return e.t
        return None


# ----------------------------------------------------------------------------- a mission
@dataclass
class MissionSpec:
    flavour: str = "px4"
    duration_s: float = 30.0  # TRACKING seconds (bridge --duration)
    sets: tuple[str, ...] = ()  # bridge --set overrides
    down: Impairment = Impairment()
    up: Impairment = Impairment()
    blackouts: tuple[Blackout, ...] = ()
    seed: int = 0
    target: str = "none"  # the vehicle's target system: none | stationary | drift
    signing_key: bytes | None = None
    vehicle_extra: tuple[str, ...] = ()
    bridge_prefix: tuple[str, ...] = ()  # e.g. a mount namespace around the bridge
    out_dir: Path | None = None  # None: <workdir>/run

    @classmethod
    def make(cls, o: Opts, duration_s: float, **kw: Any) -> MissionSpec:
        """A mission of ``duration_s`` (TRACKING) whose steady window is its second half;
        quick missions start on the path."""
        # A soak row judges tracking with its own figure (the final |pt|, the silence, the
        # setpoints); the flight verdict's |pt| bound (issue 13) is for missions long enough to
        # capture, and an 8-40 s mission cut by blackouts, fuzz or a re-engagement is not: its
        # |pt| bound is lifted here, every other clause of the verdict still applies.
        sets = (
            f"metrics.steady_after_s={duration_s / 2:g}",
            "metrics.fail_pt_m=1000.0",
            *kw.pop("sets", ()),
        )
        extra = (*(START_ON_PATH if o.quick else ()), *kw.pop("vehicle_extra", ()))
        return cls(duration_s=duration_s, seed=o.seed, sets=sets, vehicle_extra=extra, **kw)


class Mission:
    """Relay + vehicle process + bridge process on loopback; use as a context manager."""

    def __init__(self, spec: MissionSpec, workdir: Path) -> None:
        self.spec, self.workdir = spec, workdir
        workdir.mkdir(parents=True, exist_ok=True)
        self.bridge_port = free_udp_port()
        self.relay = UdpRelay(
            free_udp_port(),
            self.bridge_port,
            down=spec.down,
            up=spec.up,
            blackouts=spec.blackouts,
            seed=spec.seed,
        )
        self.tap = Tap(self.relay, spec.flavour)
        self.vehicle = VehicleProc(
            spec.flavour,
            f"udpout:127.0.0.1:{self.relay.vehicle_port}",
            workdir,
            target=spec.target,
            signing_key=spec.signing_key,
            extra=spec.vehicle_extra,
        )
        self.out_dir = spec.out_dir or workdir / "run"
        self.bridge = BridgeProc(
            CONFIGS[spec.flavour],
            f"udpin:127.0.0.1:{self.bridge_port}",
            self.out_dir,
            spec.duration_s,
            spec.sets,
            prefix=spec.bridge_prefix,
        )
        self.outcome: BridgeOutcome | None = None

    def __enter__(self) -> Mission:
        # no cyclic garbage collection while the relay runs: a full pass over the relay's log
        # (10^5 datagrams in the fuzz) holds the GIL for a few hundred ms and stalls the relay
        # thread, which would be blamed on the bridge (nothing here forms reference cycles)
        gc.collect()
        gc.disable()
        self.relay.start()
        self.vehicle.start()
        self.bridge.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.bridge.kill()
        self.vehicle.stop()
        self.relay.stop()
        self.tap.update()
        gc.enable()

    def wait_until(self, cond: Callable[[], bool], timeout_s: float, step_s: float = 0.02) -> bool:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.tap.update()
            if cond():
                return True
            if not self.bridge.alive() and self.outcome is None:
                self.tap.update()
                return cond()
            time.sleep(step_s)
        return False

    def wait_engaged(self, timeout_s: float = 30.0) -> bool:
        return self.wait_until(self.tap.offboard_now, timeout_s)

    def finish(self, timeout_s: float) -> BridgeOutcome:
        self.outcome = self.bridge.wait(timeout_s)
        time.sleep(0.3)  # the last hand-back heartbeats
        self.tap.update()
        return self.outcome


# ----------------------------------------------------------------------------- rows
@dataclass
class Row:
    scenario: str
    figures: dict[str, Any] = field(default_factory=dict)
    failures: list[str] = field(default_factory=list)
    wall_s: float = 0.0

    def check(self, ok: bool, what: str) -> bool:
        if not ok:
            self.failures.append(what)
        return ok

    def as_dict(self) -> dict[str, Any]:
        return {
            "scenario": self.scenario,
            "pass": not self.failures,
            "wall_s": round(self.wall_s, 1),
            **self.figures,
            "failures": self.failures,
        }


# ----------------------------------------------------------------------------- scenarios
@dataclass(frozen=True)
class Opts:
    quick: bool = False
    seed: int = 1
    workdir: Path = Path(tempfile.gettempdir())
