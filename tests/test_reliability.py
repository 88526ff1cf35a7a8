"""Reliability and security (issue 6): the link's defences, the fuzzer, bad input, and the
campaign's scenarios (lab/soak/campaign.py) as tests.

Fast: the vehicle-clock gate and identity pinning of the link, the fuzzer, configuration
cross-checks, one-line CLI errors, and three campaign scenarios in a short form (bad input,
refused output directories, a fuzzed mission). Slow: every scenario of ``scripts/soak --quick``.
"""

from __future__ import annotations

import math
import socket
import time
from pathlib import Path

import pytest

from lab.soak import campaign as soak
from lab.soak.mavfuzz import CLASSES, FrameFuzzer
from mpf_mavlink.config import bridge as bridge_config  # noqa: F401  (registers the sections)
from mpf_mavlink.config.schema import load_config
from mpf_mavlink.errors import ConfigError
from mpf_mavlink.mavlink import decode, dialect, mavutil
from mpf_mavlink.mavlink.link import BootClockGate, open_link, wait_heartbeat

ROOT = Path(__file__).resolve().parents[1]
PX4_CFG = ROOT / "configs" / "bridge_px4.yaml"


# ----------------------------------------------------------------------------- the clock gate
def stream(
    gate: BootClockGate,
    t_boot0: float,
    rx0: float,
    n: int,
    dt_boot: float = 0.02,
    dt_rx: float = 0.02,
    mtype: str = "ATTITUDE",
):
    return [gate.check(mtype, t_boot0 + k * dt_boot, rx0 + k * dt_rx) for k in range(n)]


SETTLE = ["settling"] * 4  # the first clock is adopted at its 5th sample


def test_gate_establishes_the_genuine_clock_whatever_comes_first():
    # A fuzzer's frames come before the vehicle's first sample: a forged first time must not
    # become the clock (the genuine stream would then be refused for seconds), nor may repeated
    # constants (0, 2^32-1) or random times form one; the genuine 50 Hz pair does within 50 ms.
    import random

    rnd = random.Random(3)
    g = BootClockGate()
    forged = [0.0, 2**32 * 1e-3 - 1e-3, 2**31 * 1e-3, 0.0, 0.0, 0.0, 0.0, 0.0, 3600.0 + 20.0]
    forged += [rnd.uniform(0, 4e6) for _ in range(40)]
    assert {g.check("ATTITUDE", tb, 100.0 + 0.001 * i) for i, tb in enumerate(forged)} == {
        "settling"
    }
    res = []
    for k in range(50):  # genuine: boot 20 s, LOCAL_POSITION_NED and ATTITUDE, junk between
        res.append(g.check("LOCAL_POSITION_NED", 20.0 + 0.02 * k, 100.1 + 0.02 * k))
        res.append(g.check("ATTITUDE", 20.0 + 0.02 * k, 100.1 + 0.02 * k + 1e-4))
        forged_ok = g.check("ATTITUDE", rnd.choice(forged), 100.1 + 0.02 * k + 2e-4)
        assert forged_ok != None  # noqa: E711
    assert res[:4] == SETTLE and res[4:] == [None] * 96
    assert g.resets == 0


def test_gate_accepts_a_healthy_stream_and_rejects_absurd_times():
    g = BootClockGate()
    # 1 s of 50 Hz: all taken once 5 samples have established the clock
    assert stream(g, 100.0, 5000.0, 50) == SETTLE + [None] * 46
    # then, at rx 5001.0 (boot ~101.0): an hour ahead, 2^31 ms, and a time in the past
    assert g.check("ATTITUDE", 101.0 + 3600.0, 5001.0) == "time"
    assert g.check("ATTITUDE", 2**31 * 1e-3, 5001.0) == "time"
    assert g.check("ATTITUDE", 50.0, 5001.0) == "time"  # 51 s behind: beyond back_tol_s (2 s)
    assert g.check("ATTITUDE", 100.5, 5001.0) == "stale"  # consistent but older than the last
    assert g.check("ATTITUDE", 100.98, 5001.0) == "stale"  # a duplicate of the last sample
    assert g.check("ATTITUDE", 101.0, 5001.0) is None  # the stream goes on, unharmed
    assert g.resets == 0


def test_gate_tolerates_jitter_and_clocks_at_other_rates():
    import random

    rnd = random.Random(1)
    g = BootClockGate()
    # 0..50 ms of latency jitter on every sample: offsets vary by 50 ms, all within tolerance
    res = [
        g.check("ATTITUDE", 10.0 + 0.02 * k, 100.0 + 0.02 * k + rnd.uniform(0, 0.05))
        for k in range(500)
    ]
    assert res.count("time") == 0  # reordered ones are "stale", never "time"
    # a lockstep simulation at 0.4x and at 5x real time: 20 ms of sim per 50 ms / 4 ms of wall
    for dt_rx in (0.05, 0.004):
        g = BootClockGate()
        assert stream(g, 12.0, 0.0, 2000, dt_boot=0.02, dt_rx=dt_rx) == SETTLE + [None] * 1996


def test_gate_takes_a_backlog_with_a_hole_after_a_pause():
    """The bridge reads nothing for 0.6 s (its checks) while junk overflows the socket buffer:
    then it reads the queued samples in a burst, and the kernel has dropped 0.46 s of them. The
    first sample after the hole is 0.46 s newer than the one read 1 ms before it, yet no
    sample is ahead of the vehicle's real clock: all are taken."""
    g = BootClockGate()
    assert stream(g, 13.0, 100.0, 10) == SETTLE + [None] * 6  # up to boot 13.18 at rx 100.18
    burst = [13.20 + 0.02 * k for k in range(3)] + [13.70 + 0.02 * k for k in range(10)]  # the hole
    res = [g.check("ATTITUDE", tb, 100.80 + 0.001 * i) for i, tb in enumerate(burst)]
    assert res == [None] * len(burst)
    # and a forged sample 0.5 s ahead of the least-delayed one is still refused right after
    assert g.check("ATTITUDE", 13.90 + 0.5, 100.82) == "time"


def test_gate_adopts_a_rebooted_clock_only_after_it_proves_itself():
    g = BootClockGate()
    stream(g, 300.0, 1000.0, 50)  # the old boot, up to boot 301 at rx 1001
    assert not g.restarting(1001.0)
    # the vehicle reboots: boot time 12 s at rx 1001.1, 50 Hz, with absurd junk interleaved
    res, restarting = [], []
    for k in range(60):
        res.append(g.check("ATTITUDE", 12.0 + 0.02 * k, 1001.1 + 0.02 * k))
        restarting.append(g.restarting(1001.1 + 0.02 * k))
        assert g.check("ATTITUDE", 9e6, 1001.1 + 0.02 * k + 0.001) in ("time", None)
    first = res.index(None)
    # from its 2nd sample until adopted, the new clock is reported as a restart (the bridge
    # then tells a reboot from a pilot's mode change); junk ahead of the clock never is
    assert restarting[0] is False and all(restarting[1:first]) and not any(restarting[first:])
    # adopted after >= reset_confirm_s (0.5 s) and >= 5 samples, not before; then all taken
    assert 0.5 <= first * 0.02 <= 0.6 and all(r is None for r in res[first:])
    assert g.resets == 1 and g.check("ATTITUDE", 9e6, 1003.0) == "time"


def test_gate_never_adopts_scattered_junk():
    import random

    rnd = random.Random(2)
    g = BootClockGate()
    stream(g, 50.0, 0.0, 10)
    # 5 s with no real samples, 50 junk samples per second at random times
    res = [g.check("ATTITUDE", rnd.uniform(0, 4e6), 0.2 + k * 0.02) for k in range(250)]
    assert set(res) == {"time"} and g.resets == 0
    assert not g.restarting(5.2)


# ----------------------------------------------------------------------------- the link
def free_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def peer(port: int, sysid: int = 1, compid: int = 1):
    return mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}",
        source_system=sysid,
        source_component=compid,
        dialect="ardupilotmega",
    )


def test_link_pins_the_autopilot_and_gates_its_clock():
    port = free_port()
    with open_link(f"udpin:127.0.0.1:{port}", vehicle_sysid=1) as link:
        ap, camera = peer(port), peer(port, 1, 100)
        try:
            ap.mav.heartbeat_send(1, 12, 129, 6 << 16, 4)  # PX4, OFFBOARD
            hb = wait_heartbeat(link, 2.0)
            assert (hb.get_srcComponent(), link.vehicle_compid, link.vehicle_autopilot) == (
                1,
                1,
                12,
            )
            t0 = 30_000
            for k in range(10):
                ap.mav.attitude_send(t0 + 20 * k, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0)
            ap.mav.attitude_send(2**31, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0)  # absurd time, valid CRC
            ap.mav.attitude_send(
                t0 + 100, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0
            )  # older than the last: stale
            ap.mav.heartbeat_send(1, 3, 129, 12, 4)  # same ids, "ArduPilot" in MANUAL: an impostor
            camera.mav.heartbeat_send(30, 12, 129, 1 << 16, 4)  # another component claiming PX4
            camera.mav.attitude_send(t0 + 300, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # and its own attitude
            ap.mav.attitude_send(t0 + 400, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0)
            got, end = [], time.monotonic() + 1.0
            while time.monotonic() < end and len(got) < 11:
                m = link.recv(0.1)
                if m is not None:
                    got.append(m)
        finally:
            ap.close()
            camera.close()
        c = link.counters
    times = [m.time_boot_ms for m in got if m.get_type() == "ATTITUDE"]
    # the first 4 establish the clock (counted as settling), then the stream is taken
    assert times == [t0 + 20 * k for k in range(4, 10)] + [t0 + 400]
    assert not [m for m in got if m.get_type() == "HEARTBEAT"]
    assert (c.rejected_time, c.rejected_stale, c.rejected_identity) == (1, 1, 1)
    assert c.clock_settling == 4
    assert c.rejected_by_source[(1, 100)] == 2  # the camera's heartbeat and attitude


def test_a_truncated_frame_does_not_eat_the_next_datagram():
    """pymavlink alone completes a frame cut short at the end of a UDP datagram with the next
    datagram's bytes and then discards them all on the CRC error."""
    port = free_port()
    with open_link(f"udpin:127.0.0.1:{port}", vehicle_sysid=1) as link:
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        mav = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
        hb = mav.heartbeat_encode(1, 12, 129, 3 << 16, 4).pack(mav)
        # VFR_HUD: no time_boot_ms, so no boot clock to establish first
        vfr = mav.vfr_hud_encode(16.0, 16.5, 90, 40, 100.0, 0.0).pack(mav)
        try:
            # a good frame, then the first 12 bytes of one that claims 20 bytes of payload
            tx.sendto(vfr + vfr[:12], ("127.0.0.1", port))
            tx.sendto(hb, ("127.0.0.1", port))  # the next datagram: must not be swallowed
            got = [link.recv(1.0), link.recv(1.0)]
        finally:
            tx.close()
        assert [m.get_type() for m in got if m is not None] == ["VFR_HUD", "HEARTBEAT"]
        assert link.counters.bad_data == 1


# ----------------------------------------------------------------------------- the fuzzer
def test_fuzzer_is_reproducible_and_makes_every_class():
    a, b = FrameFuzzer(7, now_ms=lambda: 40_000), FrameFuzzer(7, now_ms=lambda: 40_000)
    fa = [a.datagram() for _ in range(3000)]
    assert fa == [b.datagram() for _ in range(3000)]
    assert fa != [FrameFuzzer(8, now_ms=lambda: 40_000).datagram() for _ in range(3000)]
    assert all(a.counts[c] > 200 for c in CLASSES)
    kinds = set(a.by_kind)
    for k in (
        "mut_len_goodcrc",
        "mut_truncated",
        "own_attitude_time_absurd",
        "own_attitude_nonfinite",
        "own_heartbeat_not_the_autopilot",
    ):
        assert k in kinds


def test_fuzzer_valid_frames_have_valid_crcs_and_own_frames_the_vehicle_ids():
    f = FrameFuzzer(3, now_ms=lambda: 40_000)
    parser = dialect.MAVLink(None)
    parser.robust_parsing = True
    n_v1 = n_v2 = 0
    for _ in range(300):
        for v1 in (False, True):
            msgs = parser.parse_buffer(f.valid(v1)) or []
            assert len(msgs) == 1 and msgs[0].get_type() != "BAD_DATA"
            assert msgs[0].get_srcSystem() not in (1, 191)  # "foreign" really is foreign
            n_v1 += v1
            n_v2 += not v1
    own = [parser.parse_buffer(f.own_absurd()) or [] for _ in range(500)]
    own = [m for ms in own for m in ms]
    assert len(own) == 500 and all(
        m.get_type() != "BAD_DATA" and m.get_srcSystem() == 1 for m in own
    )
    # contents: the codec refuses every non-finite/out-of-range one; what it lets through is a
    # plausible value at an absurd TIME (the link's clock gate) or a HEARTBEAT/ACK (identity)
    passed = [m for m in own if decode(m) is not None]
    for m in passed:
        t = m.get_type()
        assert t in ("HEARTBEAT", "COMMAND_ACK") or (
            t in ("ATTITUDE", "LOCAL_POSITION_NED") and abs(m.time_boot_ms - 40_000) > 2_000
        ), m


# ----------------------------------------------------------------------------- configuration
@pytest.mark.parametrize(
    ("cfg", "sets", "culprit"),
    [
        (PX4_CFG, ["mavlink.hold_mode=BOGUS"], "mavlink.hold_mode"),
        (PX4_CFG, ["mavlink.hold_mode=OFFBOARD"], "mavlink.hold_mode"),  # the offboard mode itself
        (
            ROOT / "configs" / "bridge_arduplane.yaml",
            ["mavlink.hold_mode=AUTO.LOITER"],
            "mavlink.hold_mode",
        ),
        (PX4_CFG, ["adapter.thrust_min=0.9", "adapter.thrust_max=0.2"], "adapter.thrust_min"),
        (PX4_CFG, ["adapter.thrust_max=0.4"], "adapter.trim_thrust"),
        (PX4_CFG, ["target.type=mavlink"], "mavlink.target_sysid"),
        (PX4_CFG, ["target.type=mavlink", "mavlink.target_sysid=1"], "mavlink.target_sysid"),
        (PX4_CFG, ["mavlink.source_component=1"], "mavlink.source_component"),
    ],
)
def test_contradictions_are_config_errors(cfg, sets, culprit):
    with pytest.raises(ConfigError) as ei:
        load_config(cfg, sets)
    msg = str(ei.value)
    assert culprit in msg and str(cfg) in msg and "\n" not in msg


def test_hold_modes_that_are_fine():
    for sets in (
        ["mavlink.hold_mode=LOITER"],
        ["mavlink.flavour=auto", "mavlink.hold_mode=LOITER"],
        ["mavlink.flavour=auto", "mavlink.hold_mode=RTL"],
        ["mavlink.hold_mode=AUTO.RTL"],
    ):
        load_config(PX4_CFG, sets)  # LOITER and RTL exist in both autopilots' tables


def test_cli_errors_are_one_line(capsys):
    from mpf_mavlink.cli.main import main

    for argv, culprit in (
        (["run", str(PX4_CFG)], "--connect"),
        (["run", str(PX4_CFG), "--connect", "udpin:1.2.3.4:5", "--duration", "-1"], "--duration"),
        (["bogus"], "bogus"),
        (["check", str(PX4_CFG), "--nope"], "--nope"),
    ):
        with pytest.raises(SystemExit) as ei:
            main(argv)
        err = capsys.readouterr().err.strip().splitlines()
        assert ei.value.code == 2 and len(err) == 1 and culprit in err[0], err


# ----------------------------------------------------------------------------- the campaign, short
@pytest.fixture(scope="module")
def probe():
    p = soak.StallProbe()
    yield p
    p.close()


def _row(name: str, tmp_path: Path, probe, **kw) -> soak.Row:
    """A campaign row, re-run once only if it failed while the shared machine stalled (the
    probe's figure is in the row), exactly as scripts/soak does."""
    row = soak.run_row(name, soak.Opts(quick=True, workdir=tmp_path), probe, **kw)
    d = row.as_dict()
    print(d)
    assert d["pass"], d["failures"]
    return row


FAST_BAD_INPUTS = (
    "config_not_yaml",
    "unknown_key",
    "non_finite",
    "set_unknown_key",
    "url_port_out_of_range",
    "connect_missing",
    "signing_key_wrong_length",
    "hold_mode_unknown",
    "thrust_limits_crossed",
    "target_sysid_is_vehicle",
)


@pytest.mark.slow  # > 8 s of real-time flight: full suite (CI), not the quick loop
def test_soak_bad_input_subset(tmp_path, probe):
    row = _row("bad_config_and_cli", tmp_path, probe, only=FAST_BAD_INPUTS)
    assert (
        row.figures["classes"] == len(FAST_BAD_INPUTS)
        and row.figures["control_good_config_datagrams_to_vehicle"] > 0
    )


def test_soak_output_dir_refused_before_connecting(tmp_path, probe):
    row = _row("output_dir_unwritable_or_full", tmp_path, probe, in_flight=False)
    assert all(r["sent_to_vehicle"] == 0 for r in row.figures["refused"].values())


@pytest.mark.slow  # > 8 s of real-time flight: full suite (CI), not the quick loop
def test_soak_fuzzed_mission_short(tmp_path, probe):
    row = _row("fuzz", tmp_path, probe, n_frames=8000, dur=8.0)
    # a datagram may carry several frames, so the last one can overshoot the count a little
    assert 8000 <= row.figures["frames_injected"] < 8020
    assert row.figures["setpoints_out_of_limits"] == 0


# ----------------------------------------------------------------------------- the campaign, whole
# Real-time missions judged on timing (setpoint gaps, failsafe delays): under pytest-xdist
# (scripts/test) at most two of them fly at once, on two workers of their own (--dist loadgroup),
# so that the other tests cannot crowd a 2-core machine into a late failsafe.
_SOAK = [n for n in soak.SCENARIOS if n != "baseline"]


@pytest.mark.slow
@pytest.mark.parametrize(
    "name",
    [pytest.param(n, marks=pytest.mark.xdist_group(f"soak{i % 2}")) for i, n in enumerate(_SOAK)],
)
def test_soak_scenario(name, tmp_path, probe):
    _row(name, tmp_path, probe)


def test_tap_measures_the_vehicles_timeouts_on_its_clock():
    # the soak vehicle is paced to the wall clock, but a loaded host can leave its process
    # waiting: 0.6 s of wall time with no simulated time (its ATTITUDEs at 50 Hz stop and go
    # on from the next frame). Its 1 s loss timeout runs on its own clock, which the tap reads
    # from the ATTITUDEs it relayed: 1.0 s there, 1.6 s on the wall clock.
    from lab.soak.rig import Tap

    tap = Tap(None, "px4")  # type: ignore[arg-type]  # no relay: the records are given
    wall = [0.02 * k for k in range(26)] + [0.6 + 0.02 * k for k in range(26, 80)]
    tap.attitude_ms = [(t, 100_000 + 20 * k) for k, t in enumerate(wall)]
    last_command, failsafe = 0.2, 1.8  # wall s; vehicle 100.2 s and 101.2 s
    assert failsafe - last_command == pytest.approx(1.6)
    assert tap.vehicle_s(failsafe) - tap.vehicle_s(last_command) == pytest.approx(1.0)
    assert tap.vehicle_s(0.01) == pytest.approx(100.01)  # between two frames: interpolated


def test_limits_come_from_the_config():
    lim = soak.Limits.for_config("px4")
    assert (lim.max_roll_rate, lim.thrust_min, lim.max_bank) == (1.2217, 0.0, 0.61)
    assert math.isclose(lim.max_yaw_rate, 0.8727)
