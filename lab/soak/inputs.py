"""The soak campaign's security and bad-input scenarios (:mod:`lab.soak`): spoofed and signed
links, malformed configuration and command lines, unwritable output directories."""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as M

from lab.soak.checks import Limits, _r, bridge_silence, max_gap
from lab.soak.missions import FLOWN, _completed, _mission_common, _timeseries, _tracking_window
from lab.soak.relay import DOWN
from lab.soak.rig import (
    CONFIGS,
    ROOT,
    TARGET_SYSID,
    VEHICLE_COMPID,
    VEHICLE_SYSID,
    BridgeOutcome,
    Mission,
    MissionSpec,
    Opts,
    Row,
    mpf_mavlink_cmd,
)
from mpf_mavlink.mavlink.url import free_udp_port


def _signed_mav(key: bytes, sysid: int, compid: int, link_id: int = 3) -> Any:
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.link_id = key, True, link_id
    mav.signing.timestamp = int((time.time() - 1420070400) * 100_000)
    return mav


class _Spoofer:
    """The attacker of :func:`scenario_spoof`: injects toward the bridge through the relay and
    counts what it injected, by kind, in ``n``."""

    def __init__(self, m: Mission, key: bytes, n: dict[str, int]) -> None:
        from mpf_mavlink.core.frames import ned_to_geodetic

        self.m, self.n = m, n
        self.lat, self.lon, self.alt = ned_to_geodetic(
            (2000.0, 2000.0, -100.0), 47.397742, 8.545594, 488.0
        )
        self.ins99, self.ins77 = _signed_mav(key, 99, 1), _signed_mav(key, 77, 1)
        self.plain1, self.plain2 = (
            M.MAVLink(None, srcSystem=1, srcComponent=1),
            M.MAVLink(None, srcSystem=TARGET_SYSID, srcComponent=1),
        )
        self.wrong = _signed_mav(os.urandom(32), 1, 1, link_id=0)
        self.mark = 0

    def run(self, dur: float, stop: threading.Event) -> None:
        t_end = time.monotonic() + dur - 3.0  # stop before the bridge closes: every frame counted
        while time.monotonic() < t_end and not stop.is_set():
            ms = self.m.tap.vehicle_ms() or 0
            ft = self._insiders(ms)
            self._unsigned(ms, ft)
            self._wrong_key(ms)
            self._replay()
            time.sleep(0.05)

    def _inject(self, kind: str, data: bytes, count: int = 1) -> None:
        self.m.relay.inject(DOWN, data)
        self.n[kind] += count

    def _insiders(self, ms: int) -> Any:
        """Telemetry from system 99 and a far target from system 77, signed with the right key;
        returns the target message for the unsigned round."""
        for msg in (
            M.MAVLink_attitude_message(ms, 1.0, 0.5, 2.0, 0, 0, 0),
            M.MAVLink_local_position_ned_message(ms, 5000.0, 5000.0, -900.0, 0.0, 30.0, 0.0),
            M.MAVLink_heartbeat_message(1, 12, 1, 1 << 16, 4, 3),
        ):
            self._inject("foreign_ids_signed", msg.pack(self.ins99))
        ft = M.MAVLink_follow_target_message(
            ms,
            15,
            int(self.lat * 1e7),
            int(self.lon * 1e7),
            self.alt,
            [0.0] * 3,
            [0.0] * 3,
            [1.0, 0, 0, 0],
            [0.0] * 3,
            [0.0] * 3,
            0,
        )
        self._inject("foreign_ids_signed", ft.pack(self.ins77))
        return ft

    def _unsigned(self, ms: int, ft: Any) -> None:
        for mav, msg in (
            (self.plain1, M.MAVLink_attitude_message(ms + 5, 1.0, 0.5, 2.0, 0, 0, 0)),
            (self.plain1, M.MAVLink_heartbeat_message(1, 12, 1, 1 << 16, 4, 3)),
            (self.plain2, ft),
        ):
            self._inject("unsigned", msg.pack(mav))

    def _wrong_key(self, ms: int) -> None:
        msg = M.MAVLink_attitude_message(ms + 5, 1.0, 0.5, 2.0, 0, 0, 0)
        self._inject("wrong_key", msg.pack(self.wrong))

    def _replay(self) -> None:
        """One of the vehicle's own signed datagrams, about 1 s old, verbatim."""
        from lab.soak.relay import split_frames

        relay = self.m.relay
        old = [
            d
            for d in relay.datagrams(DOWN, self.mark)
            if d.fate == "delivered" and d.t < relay.now() - 1.0
        ]
        if old:
            self.mark += len(relay.datagrams(start=self.mark)) // 2
            frames = split_frames(old[-1].data) or []
            if frames and all(f[0] == 0xFD and f[2] & 0x01 for f in frames):
                self._inject("replayed", old[-1].data, len(frames))


def scenario_spoof(o: Opts) -> Row:
    """Signing on, live target from system 2. Injected toward the bridge: (a) telemetry and a
    target from other system ids, signed with the RIGHT key (an insider); (b) unsigned
    telemetry and targets from the vehicle's and the target's own ids; (c) replays of the
    vehicle's own signed datagrams 1 s later; (d) the vehicle's ids signed with a WRONG key.
    Each must be rejected and counted exactly once; the mission must not notice."""
    row = Row("spoofing_signing")
    dur = 20.0 if o.quick else 40.0
    key = os.urandom(32)
    kdir = o.workdir / "spoof"
    kdir.mkdir(parents=True, exist_ok=True)
    (kdir / "key.hex").write_text(key.hex() + "\n")
    spec = MissionSpec.make(
        o,
        dur,
        target="stationary",
        signing_key=key,
        sets=(
            "target.type=mavlink",
            f"mavlink.target_sysid={TARGET_SYSID}",
            f"mavlink.signing_key_file={kdir / 'key.hex'}",
        ),
    )
    n = {"foreign_ids_signed": 0, "unsigned": 0, "replayed": 0, "wrong_key": 0}
    stop = threading.Event()
    with Mission(spec, kdir) as m:
        # the attacker is built in its thread, so its signing timestamps start at the attack
        th = threading.Thread(target=lambda: _Spoofer(m, key, n).run(dur, stop), daemon=True)
        if row.check(m.wait_engaged(30.0), "never engaged"):
            th.start()
        out = m.finish(dur + 40.0)
        stop.set()
        if th.is_alive():
            th.join(5.0)
    _judge_spoof(row, m, out, n)
    return row


def _judge_spoof(row: Row, m: Mission, out: BridgeOutcome, n: dict[str, int]) -> None:
    """Every injected frame rejected and counted once by kind; the spoofed target never used."""
    _mission_common(row, m, out, Limits.for_config("px4"))
    c = out.counters
    got = {
        "foreign_ids_signed": c.get("rejected_sysid"),
        "unsigned": c.get("rejected_unsigned"),
        "replayed": c.get("rejected_replay"),
        "wrong_key": c.get("rejected_bad_signature"),
    }
    row.figures.update(
        injected=n,
        rejected_by_bridge=got,
        rejected_by_source=c.get("rejected_by_source"),
        steady_max_m=_r(out.metrics.get("steady_max_m")),
    )
    for k in n:
        row.check(n[k] > 0 and got[k] == n[k], f"{k}: injected {n[k]}, rejected {got[k]}")
    _completed(row, out)
    ts = _timeseries(m.out_dir)
    if ts is not None:
        far = float(max(abs(ts["tgt_n"]).max(), abs(ts["tgt_e"]).max()))
        row.figures["max_target_offset_seen_m"] = _r(far)
        row.check(far < 50.0, f"a spoofed target reached the law ({far:.0f} m)")


class HeartbeatBeacon:
    """A PX4 autopilot as far as a starting bridge can tell: HEARTBEATs every 50 ms to
    127.0.0.1:``port`` (where ``mpf-mavlink run --connect udpin:127.0.0.1:port`` listens) and a
    count of every datagram that comes back. A bridge that got as far as opening its link
    answers at once (its companion HEARTBEAT), so ``received == 0`` proves nothing was sent."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        mav = M.MAVLink(None, srcSystem=VEHICLE_SYSID, srcComponent=VEHICLE_COMPID)
        self.hb = mav.heartbeat_encode(
            M.MAV_TYPE_FIXED_WING, M.MAV_AUTOPILOT_PX4, 129, 4 << 16 | 3 << 24, 4
        ).pack(mav)
        self.received = 0
        self._stop = threading.Event()
        self._th = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            with contextlib.suppress(OSError):  # nobody listening: ICMP port unreachable
                self.sock.sendto(self.hb, ("127.0.0.1", self.port))
            with contextlib.suppress(OSError):
                self.sock.recvfrom(65536)
                self.received += 1

    def __enter__(self) -> HeartbeatBeacon:
        self._th.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._th.join(1.0)
        self.sock.close()


@dataclass(frozen=True)
class BadInput:
    name: str
    argv: tuple[str, ...]  # after "mpf-mavlink"; "{PORT}" and "{W}" are filled in
    culprit: str  # the error line must name this
    config: str | None = None  # YAML text for {W}/<name>.yaml (None: the stock PX4 config)


# A valid command line: each bad input breaks one piece of it.
_RUN = (
    "run",
    "{CFG}",
    "--connect",
    "udpin:127.0.0.1:{PORT}",
    "--out",
    "{W}/out",
    "--heartbeat-timeout",
    "2",
    "-q",
    "--no-plots",
)

# (name, culprit, edits of the stock PX4 config: "section__key" -> value, None deletes the key)
_CONFIG_EDITS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("unknown_section", "autopilot", {"autopilot__gain": 1.0}),
    ("unknown_key", "guidance.K_x", {"guidance__K_x": 1.0}),
    ("wrong_type", "vehicle.airspeed_m_s", {"vehicle__airspeed_m_s": "fast"}),
    ("non_finite", "guidance.K_p", {"guidance__K_p": float("nan")}),
    ("out_of_range", "vehicle.max_bank_rad", {"vehicle__max_bank_rad": 2.0}),
    ("missing_required_key", "path.radius_m", {"path__radius_m": None}),
    ("key_unused_by_path", "path.size_m", {"path__size_m": 100.0}),
    ("airspeed_outside_limits", "vehicle.airspeed_m_s", {"vehicle__airspeed_min_m_s": 16.0}),
)

# (name, culprit, "--set" assignments appended to the valid command line)
_SETS_OF_VALUES: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("set_without_equals", "guidance.K_p", ("guidance.K_p",)),
    ("set_unknown_key", "mavlink.sysid", ("mavlink.sysid=3",)),
    ("set_bad_yaml", "guidance.K_p", ("guidance.K_p=[1,",)),
    ("set_non_finite", "guidance.K_R", ("guidance.K_R=.inf",)),
)

# (name, culprit, the --connect URL)
_URLS: tuple[tuple[str, str, str], ...] = (
    ("url_unknown_scheme", "foo", "foo:127.0.0.1:{PORT}"),
    ("url_port_out_of_range", "99999", "udpin:127.0.0.1:99999"),
    ("url_bad_host", "no such host!", "udpin:no such host!:14540"),
    ("url_serial_missing", "/dev/ttyNOPE0", "/dev/ttyNOPE0:57600"),
)

# (name, culprit, options appended to the valid command line)
_OPTIONS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("flavour_unknown", "--flavour", ("--flavour", "inav")),
    ("duration_negative", "--duration", ("--duration", "-5")),
)

# (name, culprit, "--set" assignments appended to the valid command line)
_SETS_OF_SETTINGS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("signing_key_missing", "no.key", ("mavlink.signing_key_file={W}/no.key",)),
    ("signing_key_wrong_length", "short.key", ("mavlink.signing_key_file={W}/short.key",)),
    ("live_target_without_sysid", "target_sysid", ("target.type=mavlink",)),
    ("sysid_out_of_range", "mavlink.vehicle_sysid", ("mavlink.vehicle_sysid=300",)),
    (
        "setpoint_rate_too_low",
        "mavlink.min_setpoint_rate_hz",
        ("mavlink.min_setpoint_rate_hz=1",),
    ),
    ("origin_out_of_range", "mavlink.origin_lat_deg", ("mavlink.origin_lat_deg=95",)),
    ("mission_duration_zero", "mavlink.mission_duration_s", ("mavlink.mission_duration_s=0",)),
    ("hold_mode_unknown", "mavlink.hold_mode", ("mavlink.hold_mode=BOGUS",)),
)

# (name, culprit, "--set" assignments) that follow the other autopilot's case
_SETS_OF_PAIRS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    (
        "thrust_limits_crossed",
        "adapter.thrust_min",
        ("adapter.thrust_min=0.9", "adapter.thrust_max=0.2"),
    ),
    (
        "target_sysid_is_vehicle",
        "mavlink.target_sysid",
        ("target.type=mavlink", "mavlink.target_sysid=1"),
    ),
    ("source_ids_are_autopilot", "mavlink.source_component", ("mavlink.source_component=1",)),
)


def _config_variant(base: dict[str, Any], edits: dict[str, Any]) -> str:
    """The YAML text of ``base`` with ``edits`` ("section__key" -> value; None deletes) applied."""
    import copy

    import yaml

    d = copy.deepcopy(base)
    for dotted, v in edits.items():
        sec, _, key = dotted.partition("__")
        if v is None:
            d[sec].pop(key, None)
        else:
            d.setdefault(sec, {})[key] = v
    return yaml.safe_dump(d)


def _with_sets(rows: tuple[tuple[str, str, tuple[str, ...]], ...]) -> list[BadInput]:
    out = []
    for name, culprit, assignments in rows:
        argv = list(_RUN)
        for a in assignments:
            argv += ["--set", a]
        out.append(BadInput(name, tuple(argv), culprit))
    return out


def _bad_inputs() -> list[BadInput]:
    import yaml

    base = yaml.safe_load(CONFIGS["px4"].read_text())
    run = _RUN
    ard = str(CONFIGS["ardupilot"])
    return [
        BadInput("config_missing", ("run", "{W}/nope.yaml", *run[2:]), "nope.yaml"),
        BadInput("config_not_yaml", run, "not valid YAML", "path: [unclosed\n"),
        BadInput("config_top_level_list", run, "top level", "- a\n- b\n"),
        *(BadInput(n, run, c, _config_variant(base, e)) for n, c, e in _CONFIG_EDITS),
        *_with_sets(_SETS_OF_VALUES),
        *(BadInput(n, ("run", "{CFG}", "--connect", url, *run[4:]), c) for n, c, url in _URLS),
        BadInput("connect_missing", ("run", "{CFG}", *run[4:]), "--connect"),
        *(BadInput(n, (*run, *extra), c) for n, c, extra in _OPTIONS),
        BadInput(
            "heartbeat_timeout_zero", (*run[:6], "--heartbeat-timeout", "0"), "--heartbeat-timeout"
        ),
        BadInput("unknown_option", (*run, "--bogus"), "--bogus"),
        *_with_sets(_SETS_OF_SETTINGS),
        BadInput(
            "hold_mode_of_other_autopilot",
            ("run", ard, *run[2:], "--set", "mavlink.hold_mode=AUTO.LOITER"),
            "mavlink.hold_mode",
        ),
        *_with_sets(_SETS_OF_PAIRS),
        BadInput(
            "out_is_a_file",
            ("run", "{CFG}", "--connect", "udpin:127.0.0.1:{PORT}", "--out", "{W}/short.key", "-q"),
            "short.key",
        ),
    ]


def _run_bad(case: BadInput, w: Path) -> dict[str, Any]:
    port = free_udp_port()
    cfg = str(CONFIGS["px4"])
    if case.config is not None:
        cfg = str(w / f"{case.name}.yaml")
        Path(cfg).write_text(case.config)
    argv = [
        a.replace("{PORT}", str(port)).replace("{W}", str(w)).replace("{CFG}", cfg)
        for a in case.argv
    ]
    t0 = time.monotonic()
    with HeartbeatBeacon(port) as beacon:
        p = subprocess.run(
            [*mpf_mavlink_cmd(), *argv], cwd=ROOT, capture_output=True, text=True, timeout=30
        )
        time.sleep(0.1)  # anything still in flight
    err = p.stderr.strip().splitlines()
    return {
        "case": case.name,
        "rc": p.returncode,
        "lines": len(err),
        "stderr": err[-1] if err else "",
        "names_culprit": bool(err) and case.culprit in err[-1],
        "sent_to_vehicle": beacon.received,
        "traceback": "Traceback" in p.stderr + p.stdout,
        "s": round(time.monotonic() - t0, 2),
    }


def scenario_bad_input(o: Opts, only: tuple[str, ...] = ()) -> Row:
    """Each bad configuration or command line: one line on stderr naming the culprit, a
    non-zero exit, and not one datagram to a vehicle that is there and talking."""
    from concurrent.futures import ThreadPoolExecutor

    row = Row("bad_config_and_cli")
    w = o.workdir / "badcfg"
    w.mkdir(parents=True, exist_ok=True)
    (w / "short.key").write_bytes(b"0123456789")
    cases = [c for c in _bad_inputs() if not only or c.name in only]
    with ThreadPoolExecutor(3) as ex:
        results = list(ex.map(lambda c: _run_bad(c, w), cases))
        # the control: a good config against the same beacon must be heard (the proof can fail)
        good = (
            "run",
            "{CFG}",
            "--connect",
            "udpin:127.0.0.1:{PORT}",
            "--out",
            "{W}/control",
            "--heartbeat-timeout",
            "1",
            "-q",
            "--no-plots",
        )
        control = _run_bad(BadInput("control_good_config", good, ""), w)
    bad = [
        r
        for r in results
        if not (
            r["rc"] not in (0, None)
            and r["lines"] == 1
            and r["names_culprit"]
            and r["sent_to_vehicle"] == 0
            and not r["traceback"]
        )
    ]
    row.figures.update(
        classes=len(cases),
        passed=len(cases) - len(bad),
        control_good_config_datagrams_to_vehicle=control["sent_to_vehicle"],
        cases={r["case"]: f"exit {r['rc']}: {r['stderr'][:140]}" for r in results},
    )
    row.check(len(cases) >= (len(only) if only else 20), "fewer than 20 classes")
    row.check(
        control["sent_to_vehicle"] > 0,
        "the control run sent nothing: the 'nothing sent' proof is void",
    )
    for r in bad:
        row.check(
            False,
            f"{r['case']}: exit {r['rc']}, {r['lines']} lines, names culprit {r['names_culprit']}, "
            f"{r['sent_to_vehicle']} datagrams sent: {r['stderr'][:160]}",
        )
    return row


def _userns_available() -> bool:
    """Whether ``unshare --user --map-root-user --mount`` works here (a private mount namespace
    without privileges: then a real tmpfs can be mounted full or read-only for the bridge)."""
    if shutil.which("unshare") is None:
        return False
    try:
        return (
            subprocess.run(
                ["unshare", "--user", "--map-root-user", "--mount", "true"],
                capture_output=True,
                timeout=10,
            ).returncode
            == 0
        )
    except (OSError, subprocess.SubprocessError):
        return False


def _fs_prefix(mount_dir: Path, mode: str, size_kib: int = 64) -> tuple[tuple[str, ...], str]:
    """A command prefix that runs the bridge with ``mount_dir`` on a filesystem that is
    ``mode``: "readonly", "full" or "small" (``size_kib``, fills up during the flight).
    Returns (prefix, method)."""
    if _userns_available():
        opts = f"size={size_kib}k" + (",ro" if mode == "readonly" else "")
        fill = (
            'dd if=/dev/zero of="$0/fill" bs=1k count=100000 2>/dev/null; '
            if mode == "full"
            else ""
        )
        script = (
            f'mount -t tmpfs -o {opts} tmpfs "$0" || exit 97; {fill}"$@"; rc=$?; '
            'echo "[soak] $(df -k "$0" | tail -1)"; exit $rc'
        )
        return (
            "unshare",
            "--user",
            "--map-root-user",
            "--mount",
            "sh",
            "-c",
            script,
            str(mount_dir),
        ), f"tmpfs {mode} in a private mount namespace"
    # no user namespaces: a per-process file size limit (EFBIG instead of ENOSPC / EROFS)
    limit = {"readonly": 0, "full": 1024, "small": size_kib * 1024}[mode]
    return (
        "prlimit",
        f"--fsize={limit}:{limit}",
    ), f"RLIMIT_FSIZE={limit} bytes (no user namespaces)"


def scenario_output_dir(o: Opts, in_flight: bool = True) -> Row:
    """The run directory is unwritable or the disk is full: refused before anything is sent;
    a disk that fills up DURING the flight must not end it."""
    row = Row("output_dir_unwritable_or_full")
    w = o.workdir / "outdir"
    refusals = {}
    for mode, errno_text in (
        ("readonly", ("Read-only", "File too large")),
        ("full", ("No space left", "File too large")),
    ):
        refusals[mode] = _refused_before_connecting(row, w / mode, mode, errno_text)
    row.figures["refused"] = refusals
    if in_flight:
        _disk_fills_in_flight(row, o, w)
    return row


def _refused_before_connecting(
    row: Row, mnt: Path, mode: str, errno_text: tuple[str, ...]
) -> dict[str, Any]:
    """A bridge started on an unwritable run directory (``mode`` of :func:`_fs_prefix`) exits 2
    with one line naming it, before sending anything to the vehicle."""
    mnt.mkdir(parents=True, exist_ok=True)
    prefix, method = _fs_prefix(mnt, mode)
    port = free_udp_port()
    with HeartbeatBeacon(port) as beacon:
        p = subprocess.run(
            [
                *prefix,
                *mpf_mavlink_cmd(),
                "run",
                str(CONFIGS["px4"]),
                "--connect",
                f"udpin:127.0.0.1:{port}",
                "--out",
                str(mnt / "run"),
                "-q",
                "--no-plots",
            ],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=60,
        )
        time.sleep(0.1)
    err = p.stderr.strip().splitlines()
    refusal = {
        "method": method,
        "rc": p.returncode,
        "stderr": err[-1] if err else "",
        "sent_to_vehicle": beacon.received,
    }
    row.check(
        p.returncode == 2
        and len(err) == 1
        and str(mnt / "run") in err[0]
        and any(t in err[0] for t in errno_text)
        and beacon.received == 0,
        f"{mode}: not refused cleanly before connecting: {refusal}",
    )
    return refusal


def _disk_fills_in_flight(row: Row, o: Opts, w: Path) -> None:
    """The disk fills up mid-flight (96 KiB hold the first ~10 s of tlog): the flight goes on,
    setpoints do not pause, and the summary says records were lost."""
    dur = 20.0 if o.quick else 30.0
    mnt = w / "small"
    mnt.mkdir(parents=True, exist_ok=True)
    prefix, method = _fs_prefix(mnt, "small", 96)
    spec = MissionSpec.make(o, dur, bridge_prefix=prefix, out_dir=mnt / "run")
    with Mission(spec, w / "mission") as m:
        row.check(m.wait_engaged(30.0), "never engaged")
        out = m.finish(dur + 40.0)
    _mission_common(row, m, out, Limits.for_config("px4"))
    tap = m.tap
    t_on, t_off = _tracking_window(tap)
    summary = out.stdout
    row.figures["disk_fills_in_flight"] = {
        "method": method,
        "rc": out.rc,
        "df_at_exit": next((ln for ln in summary.splitlines() if ln.startswith("[soak]")), None),
        "max_setpoint_gap_s": _r(max_gap([e.t for e in tap.setpoints], t_on, t_off)),
        "summary_says": [
            ln.strip()
            for ln in summary.splitlines()
            if "exit" in ln or "RECORDS" in ln or "hand-back" in ln
        ],
    }
    row.check(
        out.rc in FLOWN and "mission duration" in summary,
        f"the full disk ended the flight: exit {out.rc}",
    )
    row.check("hand-back         confirmed" in summary, "hand-back not confirmed")
    row.check("RECORDS LOST" in summary, "the summary does not say that records were lost")
    row.check(not tap.failsafes(), "the vehicle's offboard failsafe fired")
    # a pause of both streams is the vehicle's or the machine's (a loaded host stalls them
    # together); the disk's doing is a pause of the bridge alone while telemetry flowed
    gap = max_gap([e.t for e in tap.setpoints], t_on, t_off)
    silent = bridge_silence(
        [e.t for e in tap.setpoints], [t for t, _ in tap.attitude_ms], t_on, t_off
    )
    row.figures["disk_fills_in_flight"]["bridge_silence_max_s"] = _r(silent)
    row.check(
        gap <= 0.25 or silent <= 0.25,
        f"setpoints paused {gap:.2f} s while the disk filled ({silent:.2f} s while telemetry "
        "flowed)",
    )
