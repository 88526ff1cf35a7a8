"""Benchmarks of the bridge side: latency (a telemetry datagram in -> the SET_ATTITUDE_TARGET
datagram out) and the wall time of a replay of the real tlog.

A minimal PX4-like peer (this process) talks to the real bridge (run_bridge in a forked
process, so that the two never wait for each other's GIL) over UDP loopback. Each control cycle it
sends LOCAL_POSITION_NED (+ VFR_HUD), then
ATTITUDE, takes time.perf_counter() right after the ATTITUDE datagram leaves, and waits for
the setpoint carrying that ATTITUDE's time_boot_ms (time taken as the datagram is read,
before parsing). The figure therefore includes both kernel
hops, pymavlink parsing and packing, the tlog writes, the estimator, the law and the adapter.
"""

from __future__ import annotations

import math
import multiprocessing
import socket
import tempfile
import time
from pathlib import Path

import numpy as np

from mpf_mavlink.config import bridge as bridge_config  # noqa: F401
from mpf_mavlink.config.schema import config_from_dict

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


def bridge_latency_ms(n_samples: int = 300, rate_hz: float = 50.0) -> dict[str, float]:
    """p50 / p99 (ms) of ATTITUDE-sent -> setpoint-received over ``n_samples`` control cycles
    (after the first 20, which warm up caches). Also returns the sample count and max."""
    from mpf_mavlink.bridge.live import BridgeOptions, run_bridge
    from mpf_mavlink.mavlink import dialect as mavlink
    from mpf_mavlink.mavlink.modes import px4_custom_mode

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    dest = ("127.0.0.1", port)

    class _W:
        def write(self, b: bytes) -> None:
            sock.sendto(bytes(b), dest)

    mav = mavlink.MAVLink(_W(), srcSystem=1, srcComponent=1)
    parser = mavlink.MAVLink(None)
    mode = [px4_custom_mode(3, 0)]
    cfg = config_from_dict(dict(_CFG))
    duration = (n_samples + 20) / rate_hz + 1.0
    tmp = tempfile.mkdtemp(prefix="mpf-bench-")

    def fly() -> None:
        opts = BridgeOptions(url=f"udpin:127.0.0.1:{port}", out_dir=Path(tmp), duration_s=duration)
        run_bridge(cfg, opts, log=lambda _s: None)

    th = multiprocessing.get_context("fork").Process(target=fly, daemon=True)
    th.start()
    lat: list[float] = []
    t0 = time.monotonic()
    x, k = -200.0, 0
    try:

        def heartbeat() -> None:
            mav.heartbeat_send(
                mavlink.MAV_TYPE_FIXED_WING, mavlink.MAV_AUTOPILOT_PX4, 129, mode[0], 4
            )

        def handle(data: bytes, want_ms: int | None) -> bool:
            got = False
            for m in parser.parse_buffer(data) or []:
                t = m.get_type()
                if t == "SET_ATTITUDE_TARGET" and m.time_boot_ms == want_ms:
                    got = True
                elif t == "COMMAND_LONG" and m.command == 176:
                    mav.command_ack_send(176, 0)
                    mode[0] = px4_custom_mode(int(m.param2), int(m.param3))
                    heartbeat()
            return got

        next_hb = 0.0
        while th.is_alive() and time.monotonic() - t0 < duration + 10.0:
            now = time.monotonic()
            if now >= next_hb:
                heartbeat()
                next_hb = now + 0.5
            tb = int((now - t0) * 1000) + 1000
            x += 15.0 / rate_hz
            mav.local_position_ned_send(tb, x, 0.0, -100.0, 15.0, 0.0, 0.0)
            if k % 5 == 0:
                mav.vfr_hud_send(15.0, 15.0, 0, 50, 100.0, 0.0)
            mav.attitude_send(tb, 0.0, 0.02, 0.0, 0.0, 0.0, 0.0)
            t_sent = time.perf_counter()
            k += 1
            deadline = now + 1.0 / rate_hz
            got = False
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                sock.settimeout(remaining)
                try:
                    data = sock.recv(65536)
                except (TimeoutError, OSError):
                    break
                t_rx = time.perf_counter()
                if handle(data, tb) and not got:
                    got = True
                    lat.append((t_rx - t_sent) * 1e3)
            if len(lat) >= n_samples + 20:
                break
    finally:
        th.terminate()  # SIGTERM: the bridge hands back and exits
        th.join(10.0)
        sock.close()
    a = np.array(lat[20:] if len(lat) > 40 else lat)
    if a.size == 0:
        return {"p50": math.nan, "p99": math.nan, "n": 0, "max": math.nan}
    return {
        "p50": float(np.percentile(a, 50)),
        "p99": float(np.percentile(a, 99)),
        "n": int(a.size),
        "max": float(a.max()),
    }


SHARED_TLOG = (
    Path(__file__).resolve().parents[2] / "tests" / "data" / "arduplane-quadplane-sitl-vtol.tlog"
)


def replay_s(runs: int = 3) -> dict[str, float | int | str]:
    """Wall time (s) of ``mpf-mavlink replay`` on the real ArduPlane SITL tlog (208 s of flight,
    23,894 records) with configs/replay_arduplane_sitl.yaml: ``s`` with the run directory and
    its plots (what a user waits for), ``no_plots_s`` without the PNGs. Best of ``runs``
    (the machine is shared: the best run is the one least disturbed)."""
    from mpf_mavlink.config.schema import load_config
    from mpf_mavlink.runs.replay import replay

    if not SHARED_TLOG.is_file():
        return {"s": math.nan, "no_plots_s": math.nan, "note": f"{SHARED_TLOG} not found"}
    cfg = load_config(
        Path(__file__).resolve().parents[2] / "configs" / "replay_arduplane_sitl.yaml"
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
        Path(__file__).resolve().parents[2] / "configs" / "replay_arduplane_sitl.yaml"
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
