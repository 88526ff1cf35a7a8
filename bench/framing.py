"""What MAVLink framing costs the SIL vehicle (issue 17): ``scripts/bench --only
mavlink_framing_us``.

Per message, microseconds (median of 20,000): framing an ATTITUDE (the SIL vehicle's most
frequent message) with pymavlink (``attitude_encode(...).pack``) and decoding a
SET_ATTITUDE_TARGET (the bridge's setpoint, every frame) with pymavlink's parser, and the CPU
they take per simulated second at the demo's stock PX4 rates (~200 messages/s out, 50
setpoints/s in). Measured 2026-11-25 on this project's install: 5.3 us, 11.9 us, 1.7 ms per
simulated second, against 2.7 us, 2.1 us, 0.6 ms for the hand-written framer (sim/mavfast.py)
the vehicle used before: a 1 ms per simulated second gain, immaterial next to the JSBSim
step, so the framer was removed and pymavlink frames everything.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np


def _median_us(fn: Any, n: int = 20_000) -> float:
    t = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        fn()
        t[i] = time.perf_counter() - t0
    return float(np.median(t) * 1e6)


def mavlink_framing_us() -> dict[str, Any]:
    from mpf_mavlink.mavlink import dialect as M

    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    att = (123456, 0.1, -0.05, 1.2, 0.01, 0.02, -0.03)
    py_pack = _median_us(lambda: mav.attitude_encode(*att).pack(mav))
    sat = M.MAVLink(None, srcSystem=1, srcComponent=191)
    buf = sat.set_attitude_target_encode(
        123456, 1, 1, 128, [1.0, 0.0, 0.0, 0.0], 0.1, 0.2, 0.3, 0.5
    ).pack(sat)
    parser = M.MAVLink(None)
    py_parse = _median_us(lambda: parser.parse_buffer(buf))
    out_per_s, in_per_s = 200.0, 50.0
    py_share = (out_per_s * py_pack + in_per_s * py_parse) * 1e-6
    return {
        "pymavlink_pack_attitude_us": py_pack,
        "pymavlink_parse_set_attitude_target_us": py_parse,
        # CPU seconds per simulated second spent framing at the demo's rates: the most the SIL
        # could run faster than real time if framing were all it did is 1 / this
        "pymavlink_cpu_s_per_sim_s": py_share,
    }
