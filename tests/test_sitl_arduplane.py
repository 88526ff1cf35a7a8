"""Real ArduPlane 4.7-dev SITL (the bundle's stock "plane") flown by the rig: configs/
bridge_arduplane.yaml as shipped, the circle placed where the aircraft is (tests/sitl_flights.py
says when these run and skip).

Real time (SIM_SPEEDUP 1). Measured with the rig on 2 busy cores (load average 8-10, three
SITLs at once): a 150 s stationary flight at 1x and 2x gave 0.170 and 0.176 m steady RMS (the
same flight), but at 2x the moving and serial flights and at 3x / 5x the stationary one fell
behind in the firmware's time (the bridge's wall-clock latency is multiplied by the speed-up)
and diverged after 60-90 s of good tracking. CI's load is of that kind: these fly at 1x.
"""

from __future__ import annotations

import math

import pytest
from sitl_flights import assert_hold, assert_tracked, marks, rig

pytestmark = marks("arduplane")
SPEEDUP: list[str] = []  # real time: see the module docstring


@pytest.mark.parametrize(
    "moving, rms_max",
    [pytest.param(False, 0.5, id="stationary"), pytest.param(True, 0.6, id="moving")],
)
def test_arduplane_engages_tracks_and_hands_back(tmp_path, moving, rms_max):
    """120 s of tracking (steady window 60-120 s, 1.4 laps of the 150 m circle at 22 m/s).

    Bounds: issue 22's acceptance for real ArduPlane, steady RMS <= 0.5 m stationary / 0.6 m
    moving; |mean radial| <= 0.3 m (the acceptance says 0.2 m for 300 s flights). The rig
    measured 0.17-0.18 m RMS stationary, 0.20 m moving, a -0.15 / -0.16 m radial bias (1x and
    2x, 120-150 s): the RMS bounds are ~3x the measured (a 60 s window's RMS varies between
    flights by tens of percent, not by 3x) and 0.3 m is twice the measured bias; both fail on a
    real regression (an unstable capture, a lost stream, a bias of the old +0.53 m kind), and
    neither is a copy of one flight's figure.
    """
    # the shipped config's target drifts 3 m/s east and flies as written; --still holds it
    args = ["arduplane", "--duration", "120", *SPEEDUP, *([] if moving else ["--still"])]
    rc, s, log = rig(tmp_path / "rig", *args)
    assert_tracked(rc, s, log, rms_max, 0.3)
    # stock ArduPlane streams 1 Hz on this link: the bridge raised ATTITUDE to what the loop
    # needs (the measured rate is in wall time: the firmware's 40 Hz x the speed-up)
    assert s["figures"]["attitude_hz"] >= 20.0, log
    if moving:
        assert s["mission"]["target"].startswith("moving 3 m/s"), log


def test_arduplane_over_a_serial_line(tmp_path):
    """README "CLI over serial": `mpf-mavlink run --connect /dev/pts/N:115200` on a
    pseudo-terminal relayed to ArduPlane's SERIAL1 (lab/rigs/pty_relay.py), 120 s. The link
    must not cost tracking: the same bounds as over TCP."""
    args = ["arduplane", "--duration", "120", "--serial", "--still", *SPEEDUP]
    rc, s, log = rig(tmp_path / "rig", *args)
    assert s["serial"]["device"].startswith("/dev/pts/"), log
    assert s["serial"]["bytes_to_autopilot"] > 0 and s["serial"]["bytes_to_bridge"] > 0, log
    assert_tracked(rc, s, log, 0.5, 0.3)
    assert s["figures"]["attitude_hz"] >= 20.0, log


def test_arduplane_sigkill_falls_back_to_a_hold(tmp_path):
    """SIGKILL of the bridge 60 s into tracking: ArduPlane flies the GUIDED loiter about the
    path's centre the bridge set before engaging; judged by issue 22's hold (assert_hold)."""
    args = ["arduplane", "--duration", "300", "--kill-after", "60", "--still", *SPEEDUP]
    rc, s, log = rig(tmp_path / "rig", *args)
    assert s["figures"]["fallback"].startswith("ArduPlane GUIDED loiter"), log
    assert s["bridge_sent"].get("SET_ATTITUDE_TARGET", 0) > 0, log  # counted from its tlog
    assert_hold(rc, s, log)


def test_arduplane_native_loiter_is_flown_and_judged_like_mpf(tmp_path):
    """The firmware's own guidance on the same mission (`--guidance native`: GUIDED +
    MAV_CMD_DO_REPOSITION with the circle's radius, re-sent at 1 Hz), 90 s, still target, so
    that the head-to-head of docs/results/native.md cannot rot.

    Bounds: the flight engaged GUIDED and every DO_REPOSITION was accepted; e (the same
    function as MPF's) is computed and finite. Stock ArduPlane's loiter sits outside a 150 m
    circle at this airspeed (NAVL1_LIM_BANK 0 widens the radius; no integrator for this
    airframe's weak turn per bank): +16.2 m mean radial in a 90 s flight, +16.9 m in a 300 s one
    at 23.5 m/s true (issue 42). 5..30 m holds that spread with room for the airspeed (the
    offset grows with it) and fails on a regression that matters: a radius ignored (ArduPlane's
    80 m WP_LOITER_RAD: -70 m) or the aircraft off the moving centre. The true airspeed flown
    within 1 m/s of the config's 22 m/s: the indicated-to-true conversion the rig measured.
    And the native figure above MPF's bound of the same mission (0.5 m RMS): the comparison's
    point, checked on every run."""
    args = ["arduplane", "--guidance", "native", "--duration", "90", "--still", *SPEEDUP]
    rc, s, log = rig(tmp_path / "rig", *args)
    f, n = s.get("figures", {}), s.get("native", {})
    assert rc == 0 and s["verdict"] == "FLOWN", log
    assert f["engaged"] is True and n["modes"][-1] == "GUIDED", log
    assert all(r == 0 for r in n["acks"]["192"] if isinstance(r, int)), log
    assert math.isfinite(f["e_rms_m"]) and f["e_steady_samples"] > 100, log
    assert 5.0 <= f["e_mean_radial_m"] <= 30.0, log
    assert f["e_rms_m"] > 0.5, log
    assert abs(n["speed"]["true_airspeed_flown_m_s"] - 22.0) <= 1.0, log
    assert (tmp_path / "rig" / "native_track.csv").is_file()
