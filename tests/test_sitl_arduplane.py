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
    args = ["arduplane", "--duration", "120", *SPEEDUP, *(["--moving"] if moving else [])]
    rc, s, log = rig(tmp_path / "rig", *args)
    assert_tracked(rc, s, log, rms_max, 0.3)
    # stock ArduPlane streams 1 Hz on this link: the bridge raised ATTITUDE to what the loop
    # needs (the measured rate is in wall time: the firmware's 40 Hz x the speed-up)
    assert s["figures"]["attitude_hz"] >= 20.0, log
    if moving:
        assert s["mission"]["target"].startswith("moving 3 m/s"), log


def test_arduplane_over_a_serial_line(tmp_path):
    """README "CLI over serial": `mpf-mavlink run --connect /dev/pts/N:115200` on a
    pseudo-terminal relayed to ArduPlane's SERIAL1 (sim/rigs/pty_relay.py), 120 s. The link
    must not cost tracking: the same bounds as over TCP."""
    rc, s, log = rig(tmp_path / "rig", "arduplane", "--duration", "120", "--serial", *SPEEDUP)
    assert s["serial"]["device"].startswith("/dev/pts/"), log
    assert s["serial"]["bytes_to_autopilot"] > 0 and s["serial"]["bytes_to_bridge"] > 0, log
    assert_tracked(rc, s, log, 0.5, 0.3)
    assert s["figures"]["attitude_hz"] >= 20.0, log


def test_arduplane_sigkill_falls_back_to_a_hold(tmp_path):
    """SIGKILL of the bridge 60 s into tracking: ArduPlane flies the GUIDED loiter about the
    path's centre the bridge set before engaging; judged by issue 22's hold (assert_hold)."""
    args = ["arduplane", "--duration", "300", "--kill-after", "60", *SPEEDUP]
    rc, s, log = rig(tmp_path / "rig", *args)
    assert s["figures"]["fallback"].startswith("ArduPlane GUIDED loiter"), log
    assert s["bridge_sent"].get("SET_ATTITUDE_TARGET", 0) > 0, log  # counted from its tlog
    assert_hold(rc, s, log)
