"""Software-in-the-loop: the SIL vehicle and the bridge as separate MAVLink peers (sim/sil.py),
``mpf-mavlink vehicle --serve``, the ``sil`` / ``aircraft`` configuration sections, another
JSBSim airframe, gusts and seeded turbulence.

Every threshold has its reason next to it. Missions fly the default demo (configs/default.yaml:
X8 at 16 m/s, lemniscate a = 150 m about a boat at 3 m/s, 4 m/s wind, light turbulence).
"""

from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("JSBSIM_DEBUG", "0")
os.environ.setdefault("MAVLINK20", "1")
pytest.importorskip("jsbsim")

from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as M  # noqa: E402

from mpf_mavlink.cli.main import main  # noqa: E402
from mpf_mavlink.config.schema import load_config  # noqa: E402

# a lifecycle flight of seconds has no steady window: it ends NOT JUDGED (exit 6), not PASS
from mpf_mavlink.runs.verdict import EXIT_NOT_JUDGED as NOT_JUDGED  # noqa: E402
from sim.plant.jsbsim_plant import JSBSimPlant  # noqa: E402
from sim.sil import build_vehicle, run_sil  # noqa: E402
from sim.vehicle.vehicle import SimVehicle  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEMO = str(ROOT / "configs" / "default.yaml")
C172 = str(ROOT / "configs" / "sil_c172x.yaml")


def free_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


# --------------------------------------------------------------------------- configuration
BAD_SIL = [
    ("aircraft.model=nope", "aircraft.model", "no JSBSim aircraft"),
    ("aircraft.root_dir=/does/not/exist", "aircraft.root_dir", "not a directory"),
    ("aircraft.controls.elevator.sign=0.5", "aircraft.controls.elevator.sign", "1 or -1"),
    (
        "aircraft.controls.rudder.property=''",
        "aircraft.controls.rudder.property",
        "must name a JSBSim property",
    ),
    ("aircraft.bogus=1", "aircraft.bogus", "unknown key"),
    ("aircraft.trim_airspeed_m_s=-16", "aircraft.trim_airspeed_m_s", "> 0"),
    ("aircraft.airspeed_min_m_s=20", "aircraft.airspeed_min_m_s", "below trim_airspeed_m_s"),
    ("aircraft.rate_loop.roll_p=-0.1", "aircraft.rate_loop.roll_p", ">= 0"),
    ("aircraft.attitude_loop.bank_max_rad=2", "aircraft.attitude_loop.bank_max_rad", "(0, 1.5)"),
    ("sil.plant=xplane", "sil.plant", "one of"),
    ("sil.turbulence=strong", "sil.turbulence", "one of"),
    ("sil.wind_turbulence_m_s=-1", "sil.wind_turbulence_m_s", ">= 0"),
    (
        "sil.plant=kinematic;sil.turbulence=none;sil.wind_turbulence_m_s=2",
        "sil.wind_turbulence_m_s",
        "steady wind only",
    ),
    ("sil.telemetry.attitude_hz=-1", "sil.telemetry.attitude_hz", ">= 0"),
    ("sil.gusts=[{start_s: 1, direction_ned: [0, 0, 0]}]", "sil.gusts[0].direction_ned", "zero"),
    ("target.type=mavlink;mavlink.target_sysid=2", "target.type", "publishes the scripted target"),
    ("mavlink.flavour=ardupilot;mavlink.hold_mode=LOITER", "mavlink.flavour", "sil.flavour"),
]


@pytest.mark.parametrize("override,key,words", BAD_SIL)
def test_sil_and_aircraft_errors_are_one_line_naming_key_and_file(override, key, words, capsys):
    sets = [a for o in override.split(";") for a in ("--set", o)]
    rc = main(["check", DEMO, *sets])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1
    assert DEMO in err and key in err and words in err


def test_kinematic_plant_refuses_turbulence(capsys):
    rc = main(["check", DEMO, "--set", "sil.plant=kinematic"])  # the demo has light turbulence
    err = capsys.readouterr().err
    assert rc == 2 and "sil.turbulence" in err and "steady wind only" in err


@pytest.mark.slow  # among the longest of the quick loop (CPU or real time): full suite (CI) only
def test_check_sees_the_sil_atmosphere(capsys):
    # The default demo passes check; its Assumption 1 margin counts the SIL wind (4 m/s) and a
    # 2 m/s allowance for light turbulence: |v_t t1 + v_d - eta| reaches ~10.5 m/s vs 14 m/s.
    assert main(["check", DEMO]) == 0
    out = capsys.readouterr().out
    # assumption 1, start altitude, gain condition, feasibility, feasibility at the gust
    # airspeed 16 + 2 m/s (light turbulence's allowance): 39.1 deg of the 40 allowed, airspeed
    # hold; climb warns: light turbulence's 2 sigma_w updraft at 100 m (0.2 x 25 ft/s = 1.52
    # m/s) just exceeds the X8's idle sink (1.5 m/s), 0.2 m of the 8.8 m reserve
    assert out.count("[PASS]") == 6 and "[PASS] gust_feasibility: at the gust airspeed 18.0" in out
    assert "[WARN] climb:" in out and "sink up to 1.52 m/s" in out
    # moderate turbulence's allowance (4 m/s): 44.6 deg at 20 m/s, beyond 45 - 5: a warning;
    # its updrafts (2 sigma_w = 0.2 x 50 ft/s = 3.0 m/s for L_w / V = 100 m / 16 m/s) hold
    # (3.0 - 1.5) 6.25 = 9.5-9.7 m of height beyond idle sink, more than the 8.8 m that the
    # airspeed absorbs up to the verdict's 18 x 1.15 = 20.7 m/s: refused on energy (exit 3)
    assert main(["check", DEMO, "--set", "sil.turbulence=moderate"]) == 3
    out = capsys.readouterr().out
    assert "[WARN] gust_feasibility: at the gust airspeed 20.0" in out
    assert "[FAIL] climb: the path descends faster than the aircraft can at idle" in out
    calm = load_config(DEMO, ["sil.wind_ned_m_s=[0,0,0]", "sil.turbulence=none"])
    from mpf_mavlink.bridge.preflight import run_checks

    windy = {r.name: r for r in run_checks(load_config(DEMO))}
    still = {r.name: r for r in run_checks(calm)}
    assert (
        windy["assumption_1"].figures["margin_m_s"]
        < still["assumption_1"].figures["margin_m_s"] - 5.0
    )


# --------------------------------------------------------------------------- plants
def test_control_mapping_signs_reach_the_jsbsim_properties():
    p = JSBSimPlant(controls={"elevator": ("fcs/elevator-cmd-norm", -1.0)})
    p.step(0.2, 0.3, 0.0, 0.25)
    assert p.get("fcs/aileron-cmd-norm") == pytest.approx(0.2)
    assert p.get("fcs/elevator-cmd-norm") == pytest.approx(-0.3)  # mapped with sign -1
    assert p.get("fcs/throttle-cmd-norm") == pytest.approx(0.25)
    with pytest.raises(KeyError, match="no property"):
        JSBSimPlant(controls={"rudder": ("fcs/no-such-thing", 1.0)})


def test_c172x_from_the_jsbsim_package_loads_and_flies_trimmed(capfd):
    cfg = load_config(C172)
    v = build_vehicle(cfg, f"udpin:127.0.0.1:{free_port()}", clock="lockstep")
    try:
        # nothing of JSBSim's chatter (the c172x's CSV output directive) reaches the console
        assert "JSBout" not in capfd.readouterr().out
        tr = v.trim
        assert abs(tr.airspeed - 45.0) < 1.0  # trimmed at aircraft.trim_airspeed_m_s
        assert abs(tr.altitude - 300.0) < 2.0  # 300 m up (kinematic.initial_position_ned_m)
        assert 0.4 < tr.throttle < 0.95  # a piston Cessna cruises at well under full power
        assert abs(tr.pitch) < math.radians(6)  # nose near level at cruise
        assert v.plant.get("inertia/mass-slugs") * 14.5939 > 700.0  # it really is the Cessna (~1 t)
        for _ in range(1000):  # 20 s of Hold: the loiter circle at cruise speed and altitude
            v.step_once()
        t = v.truth()
        assert np.all(np.abs(t["airspeed"] - 45.0) < 4.0)
        assert np.all(np.abs(t["position_ned"][:, 2] + 300.0) < 8.0)
        assert np.max(np.abs(t["euler"][-250:, 0])) > math.radians(15)  # it banks into the circle
    finally:
        v.close()


def test_gust_and_seeded_turbulence():
    kw = dict(plant="jsbsim", trim_seconds=2.0, physics_rate_hz=100.0)
    v = SimVehicle.build(
        "px4",
        f"udpin:127.0.0.1:{free_port()}",
        **kw,
        gusts=[
            {
                "start_s": 0.5,
                "direction_ned": (0.0, 1.0, 0.0),
                "magnitude_m_s": 5.0,
                "rise_s": 1.0,
                "hold_s": 1.0,
                "decay_s": 1.0,
            }
        ],
    )
    for _ in range(250):
        v.step_once()
    tr = v.truth()
    v.close()
    t, we = tr["t"], tr["wind_ned"][:, 1]
    assert np.all(np.abs(we[t < 0.49]) < 1e-9)  # calm before
    held = we[(t > 1.6) & (t < 2.4)]  # rise 0.5..1.5 s, held 1.5..2.5 s
    assert held.size and np.allclose(held, 5.0, atol=1e-6)
    assert np.all(np.abs(we[t > 3.6]) < 1e-6)  # gone after the 1 s decay
    i = np.argmin(np.abs(t - 1.0))  # half-way up the (1 - cos) ramp: 5 (1 - cos(pi/2)) / 2
    assert we[i] == pytest.approx(2.5, abs=0.3)

    def turb(seed: int) -> np.ndarray:
        v = SimVehicle.build(
            "px4", f"udpin:127.0.0.1:{free_port()}", **kw, turbulence="light", seed=seed
        )
        for _ in range(100):
            v.step_once()
        w = v.truth()["wind_ned"]
        v.close()
        return w

    a, b, c = turb(5), turb(5), turb(6)
    assert np.array_equal(a, b)  # same seed, same air
    assert not np.allclose(a, c)  # another seed, other air
    assert 0.05 < np.std(a[:, 2]) < 3.0  # it does move the air (light: sigma_w ~ 0.8 m/s)


# --------------------------------------------------------------------------- vehicle --serve
def test_vehicle_help_explains():
    out = subprocess.run(
        [sys.executable, "-m", "mpf_mavlink.cli", "vehicle", "--help"],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    ).stdout
    for words in (
        "--serve",
        "udpout:127.0.0.1:14550",
        "udpin:",
        "tcpin:",
        "Ctrl-C",
        "system 2",
        "OFFBOARD",
    ):
        assert words in out


def test_vehicle_serve_bad_url_is_one_line(capsys):
    assert main(["vehicle", DEMO, "--serve", "udpin:127.0.0.1:notaport"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "notaport" in err
    assert main(["vehicle", DEMO, "--serve", "tcp:127.0.0.1:5760"]) == 2
    assert "udpin:, udpout: or tcpin:" in capsys.readouterr().err


def test_vehicle_serve_answers_a_pymavlink_client():
    port = free_port()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "mpf_mavlink.cli",
            "vehicle",
            DEMO,
            "--serve",
            f"udpin:127.0.0.1:{port}",
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # as in a terminal's foreground: a runner started in the background (`cmd &`) passes
        # SIGINT down ignored, and Python then never turns it into KeyboardInterrupt
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    c = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=255, source_component=190, dialect="ardupilotmega"
    )
    try:
        got: dict[tuple[str, int], list] = {}
        requested = False
        t_end = time.monotonic() + 30.0  # JSBSim load and the trim flight come first
        while time.monotonic() < t_end:
            c.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            m = c.recv_match(blocking=True, timeout=0.2)
            while m is not None:
                got.setdefault((m.get_type(), m.get_srcSystem()), []).append((time.monotonic(), m))
                m = c.recv_match(blocking=False)
            if ("HEARTBEAT", 1) in got and not requested:
                c.mav.command_long_send(
                    1,
                    1,
                    M.MAV_CMD_REQUEST_MESSAGE,
                    0,
                    M.MAVLINK_MSG_ID_HOME_POSITION,
                    0,
                    0,
                    0,
                    0,
                    0,
                    0,
                )
                requested = True
            if ("HOME_POSITION", 1) in got and len(got.get(("ATTITUDE", 1), [])) > 60:
                break
        hb = got[("HEARTBEAT", 1)][-1][1]
        assert hb.type == M.MAV_TYPE_FIXED_WING and hb.autopilot == M.MAV_AUTOPILOT_PX4
        assert mavutil.mode_string_v10(hb) == "LOITER"  # PX4 AUTO.LOITER: the hold mode
        ack = [m for _, m in got[("COMMAND_ACK", 1)] if m.command == M.MAV_CMD_REQUEST_MESSAGE]
        assert ack and ack[-1].result == M.MAV_RESULT_ACCEPTED
        home = got[("HOME_POSITION", 1)][-1][1]
        assert (home.latitude, home.longitude, home.altitude) == (
            411850000,
            -87600000,
            0,
        )  # sil.home_*
        assert got[("HEARTBEAT", 2)][-1][1].type == M.MAV_TYPE_SURFACE_BOAT  # the target: a boat
        assert ("FOLLOW_TARGET", 2) in got
        # real time: the autopilot's clock advances like the wall clock (+-25 %: loaded CI)
        att = got[("ATTITUDE", 1)]
        (w0, a0), (w1, a1) = att[0], att[-1]
        assert w1 - w0 > 1.0
        assert 0.75 < (a1.time_boot_ms - a0.time_boot_ms) / 1000.0 / (w1 - w0) < 1.25
        proc.send_signal(signal.SIGINT)  # Ctrl-C: a clean exit
        out, err = proc.communicate(timeout=10)
        assert proc.returncode == 0, err
        assert "Ctrl-C to stop" in out and "stopped after" in out
        assert "Traceback" not in err
    finally:
        c.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()


# --------------------------------------------------------------------------- missions
@pytest.mark.slow
def test_full_sil_mission_converges(tmp_path, capsys):
    # The demo, 150 s of tracking. Bars: steady RMS |pt| <= 3 m in 5 m/s wind with light
    # turbulence (issue 4); measured ~0.8 m here, so 2 m still flags a real regression.
    out = tmp_path / "run"
    rc = main(
        [
            "sim",
            DEMO,
            "--set",
            "sim.duration_s=150",
            "--set",
            "metrics.steady_after_s=90",
            "--out",
            str(out),
            "-q",
        ]
    )
    text = capsys.readouterr().out
    assert rc == 0
    import json

    m = json.loads((out / "metrics.json").read_text())
    assert m["bridge_exit_code"] == 0 and m["handback_confirmed"] is True
    assert m["steady_rms_m"] < 2.0
    assert (
        m["convergence_time_s"] is not None and m["convergence_time_s"] < 90.0
    )  # |pt| < 3 m from then on
    assert (
        m["alignment_residual_m"] < 1e-3
    )  # the bridge's log matches the truth (float32 positions)
    # what the bridge believed agrees with the truth within estimation error (live target,
    # telemetry)
    assert abs(m["bridge_steady_rms_m"] - m["steady_rms_m"]) < 0.3
    assert (
        m["vehicle_answered_frames"] > 0.95 * 150 / 0.02
    )  # lockstep: (nearly) every frame answered
    # the loop delay the bridge measured from PX4's ATTITUDE_TARGET echo is the SIL's command
    # latency (sil.command_latency_s 0.02 s), to the 1 ms of the time_boot_ms stamps it is a
    # difference of; the ATTITUDE period is the 50 Hz stream's, to the same 1 ms
    dc = json.loads((out / "bridge" / "metrics.json").read_text())["delay_compensation"]
    assert dc["loop_delay_source"] == "echo" and dc["echoes_in_median"] == 9
    assert dc["loop_delay_s"] == pytest.approx(0.02, abs=1e-3)
    assert dc["horizon_s"] == pytest.approx(dc["loop_delay_s"], abs=1e-12)
    assert dc["attitude_period_s"] == pytest.approx(0.02, abs=1e-3)
    # ATTITUDE and LOCAL_POSITION_NED both at 50 Hz on one clock: no position falls between two
    # ATTITUDE samples, so the multi-rate loop makes no step of its own (the ATTITUDE-only loop)
    assert dc["position_instants"] and dc["position_steps"] == 0
    assert dc["step_period_s"] == pytest.approx(0.02, abs=1e-3)
    tlog = out / "bridge" / "mavlink.tlog"
    assert f"tlog:          {tlog}" in text and f"run directory: {out}" in text
    assert "steady RMS |pt|" in text
    assert "trajectory_3d" in text.split("plots:")[1].splitlines()[0]  # the figures drawn
    for f in ("timeseries.csv", "truth.csv", "metrics.json", "errors.png", "trajectory_3d.png"):
        assert (out / f).is_file(), f
    counts: dict[str, int] = {}
    log = mavutil.mavlink_connection(str(tlog))
    while (msg := log.recv_match()) is not None:
        counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
    assert counts["SET_ATTITUDE_TARGET"] > 150 / 0.02  # one setpoint per ATTITUDE (50 Hz) and more
    assert counts["FOLLOW_TARGET"] > 0  # the live target came over MAVLink
    ts = np.genfromtxt(out / "timeseries.csv", delimiter=",", names=True)
    assert ts["t"][0] == pytest.approx(0.0, abs=0.05) and ts["t"][-1] == pytest.approx(
        150.0, abs=0.1
    )
    # the bridge's own configuration is kept, and with it the replay recomputes every command
    # the bridge sent, bit for bit (the live target, the delay measured from the echoes)
    from mpf_mavlink.bridge.replay import replay

    rp = replay(tlog, load_config(str(out / "bridge" / "config.yaml")))
    assert rp.check.identical and rp.check.max_diff == 0.0
    assert rp.check.compared > 150 / 0.02


CIRCLE = """
name: clocks
path: {type: circle, radius_m: 100.0, center_m: [0.0, 100.0, -100.0], clockwise: true}
target: {type: stationary}
guidance: {K_p: 2.0, K_R: 3.0, alpha_m: 5.0, rate_limit_rad_s: 0.6, psi_turn: true,
           wind_compensation: true}
vehicle: {airspeed_m_s: 16.0, airspeed_min_m_s: 14.0, airspeed_max_m_s: 18.0,
          max_bank_rad: 0.785398}
kinematic: {initial_position_ned_m: [0.0, 0.0, -100.0], initial_attitude_rpy_rad: [0.0, 0.0, 0.0]}
metrics: {steady_after_s: 30.0}
checks: {c1_m: 300.0, c2: 0.25}
sil: {link: udp, physics_rate_hz: 100.0, wind_ned_m_s: [0.0, 4.0, 0.0], turbulence: light, seed: 7,
      initial_mode: cruise, home_alt_m: 0.0}
aircraft: {trim_airspeed_m_s: 16.0, trim_throttle: 0.22}
mavlink: {flavour: px4, mode_timeout_s: 2.5}
adapter: {tau_roll_s: 0.15, trim_thrust: 0.22}
"""


@pytest.mark.slow
def test_lockstep_applies_setpoints_after_the_command_latency_at_10_hz(tmp_path):
    # Every stream at 10 Hz over the vehicle's 20 ms frames: the lockstep vehicle must still
    # await, at the end of each frame, the answer that acts in the next one. It did not in the
    # four frames between two ATTITUDEs, and applied each setpoint whenever the bridge's
    # process got to it: PX4's echo then measured 0.100 s for a 0.02 s command latency. The
    # echo's time minus the ATTITUDE's is a difference of two ms stamps: 0.02 s to 1 ms.
    import json

    out = tmp_path / "run"
    sets = [
        "sim.duration_s=30",
        "metrics.steady_after_s=20",
        "sil.telemetry.attitude_hz=10",
        "sil.telemetry.local_position_hz=10",
        "mavlink.attitude_rate_hz=10",
        "mavlink.attitude_min_hz=8",
        "mavlink.position_rate_hz=10",
    ]
    rc = main(
        ["sim", DEMO, "--out", str(out), "-q", "--no-plots"]
        + [a for s in sets for a in ("--set", s)]
    )
    assert rc in (0, 5, 6)  # 30 s: not judged (the delay is the point)
    dc = json.loads((out / "bridge" / "metrics.json").read_text())["delay_compensation"]
    assert dc["attitude_period_s"] == pytest.approx(0.1, abs=1e-3)
    assert dc["loop_delay_source"] == "echo"
    assert dc["loop_delay_s"] == pytest.approx(0.02, abs=1e-3)


@pytest.mark.slow
def test_lockstep_and_realtime_track_alike(tmp_path):
    # The X8 starts on a 100 m circle (wind 4 m/s, light turbulence), flying straight along its
    # tangent in cruise until the bridge takes over: 2-3 s of start-up, a few metres of capture,
    # whatever the clock. Until OFFBOARD both clocks pace at real time; afterwards the closed
    # loops are the same code and differ only where a real-time setpoint misses its 20 ms frame
    # (applied one frame late). The atmosphere is a function of simulated time (seeded
    # turbulence: the same gusts in both runs). What differs is the state at engagement (the
    # bridge's wall-clock start-up, and the real-time-paced hand-over in which setpoints land
    # wherever the wall clock puts them). The capture is rate-limited (0.6 rad/s) and lightly
    # damped, so a 2 cm difference at engagement changes its course: measured quiet, it ends at
    # ~10 s; under 3 CPU hogs (as on the CI host) the same lockstep config bounced back to 3.7 m
    # at 10 s and was still at 0.5-0.8 m RMS over 20-25 s, converging by ~28 s to the same
    # steady state (0.15-0.30 m RMS per 5 s window from 30 s, within 0.03 m of the quiet run).
    # The energy control's 2 s filters slow the capture: one lockstep run captured in 34 s, the
    # realtime one in 9 s. So the runs last 90 s and are compared from t = 50 s. Tolerances: 0.15 m
    # on the RMS and 0.2 m RMS between the |pt| series on the vehicle's clock; a setpoint delayed by
    # one frame throughout, or dropped ones, would double the error.
    f = tmp_path / "circle.yaml"
    f.write_text(CIRCLE)
    res = {}
    for clock in ("lockstep", "realtime"):
        cfg = load_config(f, ["metrics.steady_after_s=50"])
        r = run_sil(
            cfg,
            tmp_path / clock,
            progress=False,
            plots=False,
            clock=clock,
            duration_s=90.0,
            log=lambda s: None,
        )
        assert r.exit_code == 0, r.exit_reason
        res[clock] = r
    a, b = (res[c].metrics["steady_rms_m"] for c in ("lockstep", "realtime"))
    # the series compared on the vehicle's clock, where both runs meet the same gusts
    ra, rb = res["lockstep"], res["realtime"]
    t0 = max(ra.t_vehicle[ra.cols["t"] >= 50.0][0], rb.t_vehicle[rb.cols["t"] >= 50.0][0])
    tt = np.arange(t0, min(ra.t_vehicle[-1], rb.t_vehicle[-1]), 0.1)
    diff = np.interp(tt, ra.t_vehicle, ra.cols["pt_norm"]) - np.interp(
        tt, rb.t_vehicle, rb.cols["pt_norm"]
    )
    rms_diff = float(np.sqrt(np.mean(diff**2)))
    print(
        f"steady RMS |pt|: lockstep {a:.3f} m, realtime {b:.3f} m; "
        f"series differ by {rms_diff:.3f} m RMS"
    )
    for c in ("lockstep", "realtime"):
        m = res[c].metrics
        print(
            f"{c}: convergence {m['convergence_time_s']} s, steady max {m['steady_max_m']:.3f} m, "
            f"lockstep timeouts {m.get('vehicle_lockstep_timeouts')}"
        )
    assert a < 1.0 and b < 1.0  # both in steady tracking
    assert abs(a - b) < 0.15
    assert rms_diff < 0.2
    assert 0.8 < res["realtime"].metrics["real_time_factor_tracking"] < 1.2  # really real time
    assert (
        res["lockstep"].metrics["real_time_factor_tracking"] > 2.0
    )  # and lockstep faster than that
    assert res["lockstep"].metrics["vehicle_answered_frames"] > 0.9 * 90 / 0.02  # in lockstep


def test_scripted_target_runs_on_the_bridge_clock(tmp_path):
    # sil.target_live=false: the bridge flies its own copy of the scripted boat, counted from
    # its mission origin; the simulated boat must be at the same place at the same instant.
    # Counted from the vehicle's readiness instead, it ran ~1 s (the bridge's start-up and
    # checks) ahead: ~3 m at the boat's 3 m/s, an error the bridge could not see. Kinematic
    # plant and 20 s: only the clocks are tested. Both evaluate the same ConstantTurn at times
    # stamped in ms: 3 m/s x 0.5 ms = 1.5 mm, plus float32 positions in the logs.
    cfg = load_config(
        DEMO,
        [
            "sil.target_live=false",
            "sil.plant=kinematic",
            "sil.turbulence=none",
            "sim.duration_s=20",
        ],
    )
    r = run_sil(cfg, tmp_path / "run", progress=False, plots=False, log=lambda s: None)
    assert r.exit_code == NOT_JUDGED, (r.exit_reason, r.metrics.get("verdict"))
    from mpf_mavlink.runs.rundir import read_run

    bc, _, _ = read_run(r.bridge_dir)
    t = r.cols["t"] + bc["t"][0]  # truth rows on the bridge's mission clock
    for c in ("tgt_n", "tgt_e"):
        b = np.interp(t, bc["t"], bc[c])
        assert np.max(np.abs(b - r.cols[c])) < 0.01, c


def test_the_summary_names_only_the_plots_drawn(tmp_path):
    # --no-plots (what campaigns fly) draws none, and the summary must not point at figures
    # that are not there
    from mpf_mavlink.cli.sim import _plots_line

    assert _plots_line(tmp_path) == "plots:         none (--no-plots)"
    for name in ("errors", "limits"):
        (tmp_path / f"{name}.png").write_bytes(b"")
    assert _plots_line(tmp_path) == f"plots:         {tmp_path}/*.png  (errors, limits)"


def test_a_lean_sil_run_writes_one_row_in_five_and_judges_on_every_frame(tmp_path):
    # mavlink.recording=lean (what campaigns fly): the tables in the run directory keep one row
    # in five and the last (the final state); the figures come from the table of every frame
    cfg = load_config(
        DEMO,
        [
            "sil.plant=kinematic",
            "sil.turbulence=none",
            "sim.duration_s=20",
            "mavlink.recording=lean",
        ],
    )
    r = run_sil(cfg, tmp_path / "run", progress=False, plots=False, log=lambda s: None)
    import json

    from mpf_mavlink.runs.rundir import read_run

    n = len(r.cols["t"])
    assert n >= 0.9 * 20.0 / 0.02  # a table of the 50 Hz frames
    keep = list(range(0, n, 5)) + ([n - 1] if (n - 1) % 5 else [])
    written, _, _ = read_run(tmp_path / "run")
    for c in ("t", "pt_norm", "rel_x"):  # written with 9 significant digits
        np.testing.assert_array_equal(written[c], [float(f"{x:.9g}") for x in r.cols[c][keep]])
    truth_rows = len((tmp_path / "run" / "truth.csv").read_text().splitlines()) - 1
    m = len(r.truth["t"])
    assert truth_rows == len(range(0, m, 5)) + (1 if (m - 1) % 5 else 0)
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["sim_time_s"] == float(r.cols["t"][-1])
    assert metrics["first_within_s"] is not None
    assert metrics["first_within_s"] == r.metrics["first_within_s"]
