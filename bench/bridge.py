"""Benchmarks of the bridge side: latency (a telemetry datagram in -> the SET_ATTITUDE_TARGET
datagram out), the CPU of its link path per frame (:func:`bridge_link_us`) and the wall time of
a replay of the real tlog.

A minimal PX4-like peer (this process) talks to the real bridge (run_bridge in a forked
process, so that the two never wait for each other's GIL) over UDP loopback. Each control cycle it
sends LOCAL_POSITION_NED (+ VFR_HUD), then
ATTITUDE, takes time.perf_counter() right after the ATTITUDE datagram leaves, and waits for
the setpoint carrying that ATTITUDE's time_boot_ms (time taken as the datagram is read,
before parsing). The figure therefore includes both kernel
hops, pymavlink parsing and packing, the tlog writes, the estimator, the law and the adapter.
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing
import socket
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from mpf_mavlink.config import bridge as bridge_config  # noqa: F401
from mpf_mavlink.config.schema import config_from_dict
from mpf_mavlink.mavlink.url import free_udp_port

_CFG = {
    "name": "bench",
    "path": {"type": "circle", "radius_m": 150.0},
    "target": {"type": "stationary", "position_ned_m": [0.0, 0.0, -100.0]},
    "guidance": {
        "K_p": 1.0,
        "K_R": 0.5,
        "alpha_m": 40.0,
        "rate_limit_rad_s": 0.5,
        "psi_turn": True,
    },
    "vehicle": {"airspeed_m_s": 15.0, "max_bank_rad": 0.61},
    "checks": {"c2": 0.25, "c1_m": 300.0},
    "mavlink": {
        "flavour": "px4",
        "plots": False,
        "heartbeat_timeout_s": 5.0,
        "tlog_fsync_every_s": None,
        "mode_retries": 1,
        "mode_timeout_s": 0.5,
        "set_fallback": False,  # the scripted peer answers no parameters
    },
}


class _ScriptedPx4:
    """A scripted PX4 for :func:`bridge_latency_ms`: sends its state to the bridge over UDP,
    answers mode changes, and recognises the set-point that answers a given ATTITUDE."""

    def __init__(self, port: int) -> None:
        from mpf_mavlink.mavlink import dialect as mavlink
        from mpf_mavlink.mavlink.modes import px4_custom_mode

        self.d, self._px4_custom_mode = mavlink, px4_custom_mode
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        dest = ("127.0.0.1", port)
        sock = self.sock

        class _W:
            def write(self, b: bytes) -> None:
                sock.sendto(bytes(b), dest)

        self.mav = mavlink.MAVLink(_W(), srcSystem=1, srcComponent=1)
        self.parser = mavlink.MAVLink(None)
        self.mode = px4_custom_mode(3, 0)

    def heartbeat(self) -> None:
        d = self.d
        self.mav.heartbeat_send(d.MAV_TYPE_FIXED_WING, d.MAV_AUTOPILOT_PX4, 129, self.mode, 4)

    def handle(self, data: bytes, want_ms: int | None) -> bool:
        """Answer what the bridge sent; True when it holds the set-point for ``want_ms``."""
        got = False
        for m in self.parser.parse_buffer(data) or []:
            t = m.get_type()
            if t == "SET_ATTITUDE_TARGET" and m.time_boot_ms == want_ms:
                got = True
            elif t == "COMMAND_LONG" and m.command == 176:
                self.mav.command_ack_send(176, 0)
                self.mode = self._px4_custom_mode(int(m.param2), int(m.param3))
                self.heartbeat()
        return got

    def send_state(self, tb: int, x: float, k: int) -> None:
        """Level flight at 15 m/s north, 100 m up, at boot time tb (ms); VFR_HUD every 5th."""
        self.mav.local_position_ned_send(tb, x, 0.0, -100.0, 15.0, 0.0, 0.0)
        if k % 5 == 0:
            self.mav.vfr_hud_send(15.0, 15.0, 0, 50, 100.0, 0.0)
        self.mav.attitude_send(tb, 0.0, 0.02, 0.0, 0.0, 0.0, 0.0)

    def await_setpoint(self, tb: int, t_sent: float, deadline: float) -> float | None:
        """The latency (ms) of the set-point that answers the ATTITUDE of boot time tb sent at
        t_sent (perf_counter), reading until the cycle's deadline (monotonic); None: none came."""
        lat = None
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            self.sock.settimeout(remaining)
            try:
                data = self.sock.recv(65536)
            except (TimeoutError, OSError):
                break
            t_rx = time.perf_counter()
            if self.handle(data, tb) and lat is None:
                lat = (t_rx - t_sent) * 1e3
        return lat


def bridge_latency_ms(n_samples: int = 300, rate_hz: float = 50.0) -> dict[str, float]:
    """p50 / p99 (ms) of ATTITUDE-sent -> setpoint-received over ``n_samples`` control cycles
    (after the first 20, which warm up caches). Also returns the sample count and max."""
    from mpf_mavlink.bridge.base import BridgeOptions
    from mpf_mavlink.bridge.live import run_bridge

    port = free_udp_port()
    peer = _ScriptedPx4(port)
    cfg = config_from_dict(dict(_CFG))
    duration = (n_samples + 20) / rate_hz + 1.0
    tmp = tempfile.mkdtemp(prefix="mpf-bench-")

    def fly() -> None:
        opts = BridgeOptions(url=f"udpin:127.0.0.1:{port}", out_dir=Path(tmp), duration_s=duration)
        own = _time_own_share()
        run_bridge(cfg, opts, log=lambda _s: None)
        Path(tmp, "own_us.txt").write_text(" ".join(f"{x:.1f}" for x in own))

    th = multiprocessing.get_context("fork").Process(target=fly, daemon=True)
    th.start()
    lat: list[float] = []
    t0 = time.monotonic()
    x, k = -200.0, 0
    try:
        next_hb = 0.0
        while th.is_alive() and time.monotonic() - t0 < duration + 10.0:
            now = time.monotonic()
            if now >= next_hb:
                peer.heartbeat()
                next_hb = now + 0.5
            tb = int((now - t0) * 1000) + 1000
            x += 15.0 / rate_hz
            peer.send_state(tb, x, k)
            t_sent = time.perf_counter()
            k += 1
            got = peer.await_setpoint(tb, t_sent, now + 1.0 / rate_hz)
            if got is not None:
                lat.append(got)
            if len(lat) >= n_samples + 20:
                break
    finally:
        th.terminate()  # SIGTERM: the bridge hands back and exits
        th.join(10.0)
        peer.sock.close()
    a = np.array(lat[20:] if len(lat) > 40 else lat)
    if a.size == 0:
        return {"p50": math.nan, "p99": math.nan, "n": 0, "max": math.nan}
    own = np.zeros(0)
    with contextlib.suppress(OSError, ValueError):
        own = np.array([float(x) for x in Path(tmp, "own_us.txt").read_text().split()])
    own = own[20:] if len(own) > 40 else own
    return {
        "p50": float(np.percentile(a, 50)),
        "p99": float(np.percentile(a, 99)),
        "n": int(a.size),
        "max": float(a.max()),
        # the bridge's own share (us): its ATTITUDE datagram's wake-up to the setpoint's sendto
        "bridge_p50_us": float(np.percentile(own, 50)) if own.size else math.nan,
        "bridge_p99_us": float(np.percentile(own, 99)) if own.size else math.nan,
    }


def _time_own_share() -> list[float]:
    """In the bridge's process: from now on, the time (us) from each datagram's wake-up (its
    link's poll returning) to the sendto of the next SET_ATTITUDE_TARGET, one a setpoint, in
    the list returned: the part of the latency the bridge's own code takes (the rest is the
    two kernel hops and the scheduler's wake-ups). The link's methods are wrapped for that
    (~1 us added to the figures)."""
    from mpf_mavlink.mavlink import link as link_mod

    out: list[float] = []
    wake = [0.0]
    clock = time.perf_counter

    class _Poll:
        def __init__(self, poll: Any) -> None:
            self._poll = poll

        def poll(self, timeout_ms: float) -> Any:
            r = self._poll.poll(timeout_ms)
            if r:
                wake[0] = clock()
            return r

    reader_init = link_mod.DatagramReader.__init__
    from mpf_mavlink.mavlink import link_send

    write = link_send.LinkSender._write

    def init(self: Any, *a: Any) -> None:
        reader_init(self, *a)
        self._poll = _Poll(self._poll)

    def timed_write(self: Any, buf: bytes) -> None:
        if wake[0] and len(buf) > 9 and buf[7] | buf[8] << 8 | buf[9] << 16 == _SET_ATT_ID:
            out.append((clock() - wake[0]) * 1e6)
            wake[0] = 0.0
        write(self, buf)

    link_mod.DatagramReader.__init__ = init  # type: ignore[method-assign, assignment]
    link_send.LinkSender._write = timed_write  # type: ignore[method-assign]
    return out


_SET_ATT_ID = 82  # SET_ATTITUDE_TARGET


def _demo_frames(n: int, t0_ms: int) -> list[tuple[bytes, bytes, int]]:
    """``n`` 20 ms frames of the demo's telemetry as the SIL vehicle sends it: per frame a
    datagram of LOCAL_POSITION_NED + ATTITUDE; every 5th frame also one of GLOBAL_POSITION_INT,
    VFR_HUD, ATTITUDE_TARGET and the target's FOLLOW_TARGET + GLOBAL_POSITION_INT (system 2);
    SYS_STATUS at 5 Hz, HEARTBEAT and WIND_COV at 2 Hz. (pair, slow or b"", time_boot_ms)."""
    from mpf_mavlink.mavlink import dialect as mavlink

    out: list[bytes] = []

    class _W:
        def write(self, b: bytes) -> None:
            out.append(bytes(b))

    veh = mavlink.MAVLink(_W(), srcSystem=1, srcComponent=1)
    tgt = mavlink.MAVLink(_W(), srcSystem=2, srcComponent=1)
    frames = []
    for k in range(n):
        tb = t0_ms + 20 * k
        out.clear()
        veh.local_position_ned_send(tb, 1.0 + 0.3 * k, 2.0, -100.0, 15.0, 0.1, 0.0)
        veh.attitude_send(tb, 0.1, 0.02, 1.0, 0.01, 0.02, 0.03)
        pair = b"".join(out)
        out.clear()
        if k % 5 == 0:
            veh.global_position_int_send(tb, 411850000, -87600000, 100000, 100000, 1500, 10, 0,
                                         9000)  # fmt: skip
            veh.vfr_hud_send(16.0, 15.0, 90, 50, 100.0, 0.1)
            veh.attitude_target_send(tb, 128, [1, 0, 0, 0], 0.1, 0.2, 0.3, 0.5)
            tgt.follow_target_send(tb, 7, 411850000, -87600000, 0.0, [3.0, 0.1, 0.0], [0, 0, 0],
                                   [1, 0, 0, 0], [0, 0, 0], [0, 0, 0], 0)  # fmt: skip
            tgt.global_position_int_send(tb, 411850000, -87600000, 0, 0, 300, 10, 0, 9000)
        if k % 10 == 0:
            veh.sys_status_send(0, 0, 0, 500, 12000, -1, 80, 0, 0, 0, 0, 0, 0)
        if k % 25 == 0:
            veh.heartbeat_send(1, 12, 129, 6 << 16, 4)
            veh.wind_cov_send(tb * 1000, 0.0, 4.0, 0.0, 0, 0, 0, 0, 0, 0)
        frames.append((pair, b"".join(out), tb))
    return frames


def bridge_link_us(frames: int = 800, rounds: int = 15) -> dict[str, float | int]:
    """CPU time (us) per 20 ms frame of the bridge's link path alone: the demo's telemetry
    (:func:`_demo_frames`, 3.2 messages a frame) received on a UDP loopback link with a tlog,
    decoded and dispatched (VehicleLink), and one SET_ATTITUDE_TARGET sent per ATTITUDE; no
    estimator, no law. The sender's own cost (measured alone) is subtracted; best of
    ``rounds`` (a CPU-time figure: less sensitive to a busy machine than the SIL's)."""
    from types import SimpleNamespace

    from mpf_mavlink.bridge.link_io import LinkHandlers, VehicleLink
    from mpf_mavlink.mavlink import Flavour, encode_set_attitude_target_rates, open_link

    port = free_udp_port()
    with tempfile.TemporaryDirectory(prefix="mpf-bench-link-") as d:
        link = open_link(f"udpin:127.0.0.1:{port}", tlog_path=Path(d) / "t.tlog",
                         vehicle_time=True, allowed_sysids=[2])  # fmt: skip
        vl = VehicleLink(SimpleNamespace(vehicle_sysid=1, target_sysid=2, lockstep=True), True)
        vl.link, vl.flavour = link, Flavour.PX4
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        tx.bind(("127.0.0.1", 0))
        tx.setblocking(False)
        att = [0]

        def on_vehicle(sample: object, rx: float | None) -> None:
            if type(sample).__name__ == "AttitudeSample":
                att[0] += 1
                vl.send(encode_set_attitude_target_rates(link.mav, tb_now[0], 1, 1, 0.1, 0.2,
                                                         0.3, 0.5))  # fmt: skip

        tb_now = [0]
        vl.subscribe(LinkHandlers(vehicle=on_vehicle))
        dest, sink = ("127.0.0.1", port), ("127.0.0.1", free_udp_port())
        best = best_send = math.inf
        t_ms = 100_000
        try:
            for r in range(rounds + 1):
                batch = _demo_frames(frames, t_ms)
                t_ms += 20 * frames
                t0 = time.process_time()
                for pair, slow, _ in batch:  # the sender alone, to a port nobody reads
                    if slow:
                        tx.sendto(slow, sink)
                    tx.sendto(pair, sink)
                best_send = min(best_send, time.process_time() - t0)
                t0 = time.process_time()
                for i, (pair, slow, tb) in enumerate(batch):
                    tb_now[0] = tb
                    for data in (slow, pair) if slow else (pair,):
                        tx.sendto(data, dest)
                        while (msg := link.recv(0.0)) is not None:
                            vl.dispatch(msg)
                    if i % 64 == 63:  # the setpoints that came back
                        with contextlib.suppress(BlockingIOError):
                            while True:
                                tx.recv(65536)
                if r:  # the first round warms up (the link's clock gate settles)
                    best = min(best, time.process_time() - t0)
        finally:
            tx.close()
            link.close()
    return {
        "us_per_frame": (best - best_send) / frames * 1e6,
        "sender_us_per_frame": best_send / frames * 1e6,
        "setpoints": att[0],
        "rx_packets": link.counters.rx_packets,
    }


SHARED_TLOG = (
    Path(__file__).resolve().parents[1] / "tests" / "data" / "arduplane-quadplane-sitl-vtol.tlog"
)


def replay_s(runs: int = 3) -> dict[str, float | int | str]:
    """Wall time (s) of ``mpf-mavlink replay`` on the real ArduPlane SITL tlog (208 s of flight,
    23,894 records) with configs/replay_arduplane_sitl.yaml: ``s`` with the run directory and
    its plots (what a user waits for), ``no_plots_s`` without the PNGs. Best of ``runs``
    (the machine is shared: the best run is the one least disturbed)."""
    from mpf_mavlink.bridge.replay import replay
    from mpf_mavlink.config.schema import load_config

    if not SHARED_TLOG.is_file():
        return {"s": math.nan, "no_plots_s": math.nan, "note": f"{SHARED_TLOG} not found"}
    cfg = load_config(
        Path(__file__).resolve().parents[1] / "configs" / "replay_arduplane_sitl.yaml"
    )
    full, bare = [], []
    steps = 0
    for _ in range(runs):
        with tempfile.TemporaryDirectory(prefix="mpf-bench-replay-") as d:
            t0 = time.perf_counter()
            replay(SHARED_TLOG, cfg, out_dir=Path(d) / "run", plots=True)
            full.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            steps = replay(SHARED_TLOG, cfg, out_dir=Path(d) / "bare", plots=False).steps
            bare.append(time.perf_counter() - t0)
    return {"s": min(full), "no_plots_s": min(bare), "steps": steps}


def estimator_us(runs: int = 20) -> dict[str, float | int | str]:
    """CPU time (us) per ATTITUDE of the estimator as the control loop uses it: every vehicle
    sample of the real ArduPlane SITL tlog fed to :meth:`Estimator.update` in file order and one
    :meth:`Estimator.estimate` after each ATTITUDE (the control step's). Best of ``runs``."""
    from mpf_mavlink.bridge.controller import estimator_params
    from mpf_mavlink.bridge.estimator import Estimator
    from mpf_mavlink.config.schema import load_config
    from mpf_mavlink.mavlink import decode, iter_tlog

    if not SHARED_TLOG.is_file():
        return {"per_attitude_us": math.nan, "note": f"{SHARED_TLOG} not found"}
    cfg = load_config(
        Path(__file__).resolve().parents[1] / "configs" / "replay_arduplane_sitl.yaml"
    )
    m = cfg.section("mavlink")
    samples = []
    for t, msg in iter_tlog(str(SHARED_TLOG)):
        if msg.get_srcSystem() != m.vehicle_sysid:
            continue
        msg._timestamp = t  # what the bridge's dispatch does before decoding
        s = decode(msg)
        if s is not None:
            samples.append((s, t))
    best = math.inf
    n_att = 0
    for _ in range(runs):
        est = Estimator(estimator_params(m))
        n_att = 0
        t0 = time.process_time()
        for s, t in samples:
            if est.update(s, t):
                est.estimate()
                n_att += 1
        best = min(best, time.process_time() - t0)
    return {"per_attitude_us": best / max(1, n_att) * 1e6, "attitudes": n_att}


if __name__ == "__main__":  # pragma: no cover
    print(bridge_latency_ms())
