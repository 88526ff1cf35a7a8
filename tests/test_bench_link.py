"""The link-path benchmark (``scripts/bench --only bridge_link_us``) measures what it says: every
ATTITUDE of its telemetry answered by one setpoint, every message received and counted."""

from __future__ import annotations

import math

from bench.bridge import _demo_frames, bridge_link_us
from mpf_mavlink.mavlink import dialect as d


def test_the_link_bench_answers_every_attitude_and_takes_every_message() -> None:
    frames, rounds = 50, 1
    r = bridge_link_us(frames=frames, rounds=rounds)
    per_round = sum(
        len(d.MAVLink(None).parse_buffer(bytearray(pair + slow)) or [])
        for pair, slow, _ in _demo_frames(frames, 0)
    )
    assert per_round > 3 * frames  # the pair every frame, the slower streams besides
    n = rounds + 1  # the first round warms up
    # the clock gate settles on the vehicle's first few samples (mavlink/boot_clock.py)
    assert n * frames - 5 <= r["setpoints"] <= n * frames
    assert r["rx_packets"] == n * per_round
    assert math.isfinite(r["us_per_frame"]) and r["us_per_frame"] > 0.0
