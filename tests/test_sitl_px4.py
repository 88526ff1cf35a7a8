"""Real PX4 v1.16.0 SITL (SIH fixed-wing, airframe 10041, stock parameters) flown by the rig:
configs/bridge_px4.yaml as it stands, the circle placed where PX4's own loiter has the aircraft
(tests/sitl_flights.py says when these run and skip; the rig holds /tmp/mpf-px4.lock).

Real time. PX4_SIM_SPEED_FACTOR works with SIH (PX4's boot clock ran 1.97x wall time at 2,
`scripts/sitl px4 --speedup 2`), but a speed-up multiplies the bridge's wall-clock latency in
the firmware's time: at 2x on 2 busy cores the bridge never engaged PX4 ("telemetry lost:
no usable state for 0.50 s"), and ArduPlane diverged at 2x-5x (tests/test_sitl_arduplane.py).
CI flies PX4 at 1x.
"""

from __future__ import annotations

import math

import pytest
from sitl_flights import assert_hold, assert_tracked, marks, rig

pytestmark = marks("px4")
SPEEDUP: list[str] = []  # real time: see the module docstring


@pytest.mark.parametrize(
    "moving", [pytest.param(False, id="stationary"), pytest.param(True, id="moving")]
)
def test_px4_engages_tracks_and_hands_back(tmp_path, moving):
    """120 s of tracking (steady window 60-120 s).

    Bound: steady RMS <= 4.0 m. Measured: issue 22's 300 s flights 1.71 m RMS / 4.29 m max
    stationary and 1.91 / 3.79 m moving, a radial wander of +-2-5 m with 25-70 s periods; the
    rig's 120 s flight 2.1 m / 3.5 m max (1x). A 60 s window
    holds one or two swings of that wander, so its RMS can reach the swing's amplitude (~4 m)
    without anything broken; beyond it the loop is. No radial bound: a 60 s window of a 25-70 s
    wander has a mean that swings with its phase (the 0.3 m of issue 22 is for 300 s)."""
    args = ["px4", "--duration", "120", *SPEEDUP, *(["--moving"] if moving else [])]
    rc, s, log = rig(tmp_path / "rig", *args)
    assert_tracked(rc, s, log, 4.0, None)
    if moving:
        assert s["mission"]["target"].startswith("moving 3 m/s"), log


def test_px4_sigkill_falls_back_to_a_hold(tmp_path):
    """SIGKILL of the bridge 60 s into tracking: PX4 must hold about the path's centre,
    judged by issue 22's hold (assert_hold). Stock PX4 without RC switches to Position mode,
    which on a fixed-wing flies straight on; the bridge makes COM_OBL_RC_ACT Hold before it
    engages, and PX4 then circles its loss point at NAV_LOITER_RAD (80 m), within 2x the
    path radius of the centre."""
    rc, s, log = rig(tmp_path / "rig", "px4", "--duration", "300", "--kill-after", "60", *SPEEDUP)
    assert_hold(rc, s, log)


def test_px4_native_orbit_is_flown_and_judged_like_mpf(tmp_path):
    """The firmware's own guidance on the same mission (`--guidance native`: MAV_CMD_DO_ORBIT
    in Hold, re-sent at 1 Hz, DO_CHANGE_SPEED to the config's 12 m/s), 90 s, still target, so
    that the head-to-head of docs/results/native.md cannot rot.

    Bounds: Hold kept and every DO_ORBIT accepted; e (the same function as MPF's) finite and
    within MPF's own bound on this mission (4.0 m RMS, test above: both laws sit on SIH's
    estimator wander; a 90 s flight measured 1.41 m RMS, issue 42's 300 s one 0.89 m); a mean
    radial within 5 m (measured -0.08 and +0.17 m: PX4's orbit honours the radius, 80 m
    NAV_LOITER_RAD would be -70 m); the true airspeed flown within 1 m/s of 12 m/s (11.5 m/s
    measured: DO_CHANGE_SPEED taken in Hold)."""
    args = ["px4", "--guidance", "native", "--duration", "90", *SPEEDUP]
    rc, s, log = rig(tmp_path / "rig", *args)
    f, n = s.get("figures", {}), s.get("native", {})
    assert rc == 0 and s["verdict"] == "FLOWN", log
    assert f["engaged"] is True and n["modes"][-1] == "AUTO.LOITER", log
    assert all(r == 0 for r in n["acks"]["34"] if isinstance(r, int)), log
    assert math.isfinite(f["e_rms_m"]) and f["e_rms_m"] <= 4.0, log
    assert abs(f["e_mean_radial_m"]) <= 5.0, log
    assert abs(n["speed"]["true_airspeed_flown_m_s"] - 12.0) <= 1.0, log
