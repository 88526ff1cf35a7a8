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
