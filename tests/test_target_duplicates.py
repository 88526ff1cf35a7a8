"""LiveTarget drops the GLOBAL_POSITION_INT twin of a FOLLOW_TARGET fix before converting its
position (TargetEstimator.known_position): the estimator must end up exactly where taking every
report through report() and add() leaves it, whichever of the twins comes first, with late,
reordered, repeated and lost reports."""

from __future__ import annotations

import random
from typing import Any

import numpy as np
from test_live_target import ORIGIN, _frames

from mpf_mavlink.bridge.estimator import Estimator, EstimatorParams
from mpf_mavlink.bridge.target_sources import LiveTarget
from mpf_mavlink.core.target_filter import TargetFilterParams


class _EveryReport(LiveTarget):
    """The reference: every sample through report() and add()."""

    def update(self, sample: Any, t_mission: float | None) -> None:
        if t_mission is None:
            return
        r = self.report(sample)
        if r is None:
            return
        self.samples += 1
        self.last_outcome = self.kf.add(r, t_mission)


def test_dropping_twins_early_changes_nothing() -> None:
    rng = random.Random(3)
    p = TargetFilterParams()
    fast = LiveTarget(Estimator(EstimatorParams(origin=ORIGIN)), p)
    ref = _EveryReport(Estimator(EstimatorParams(origin=ORIGIN)), p)
    feed = []
    for k in range(300):
        t = 0.1 * k
        ft, gpi = _frames(t)
        pair = [ft, gpi] if rng.random() < 0.7 else [gpi, ft]
        for s in pair:
            if rng.random() < 0.05:
                continue  # lost
            delay = 0.05 + (0.4 if rng.random() < 0.05 else 0.0)  # some arrive late
            feed.append((t + delay + 1e-4 * rng.random(), s))
            if rng.random() < 0.03:
                feed.append((t + delay + 0.01, s))  # repeated
    feed.sort(key=lambda e: e[0])
    feed.append((feed[-1][0] + 11.0, _frames(25.0)[1]))  # 16 s in transit: too_late
    outcomes = set()
    for rx, s in feed:
        fast.update(s, rx)
        ref.update(s, rx)
        assert fast.last_outcome == ref.last_outcome
        outcomes.add(fast.last_outcome)
        a, b = fast.state(rx), ref.state(rx)
        if isinstance(a, str):
            assert a == b
            continue
        assert not isinstance(b, str)
        for x, y in zip(
            (a.position, a.velocity, a.acceleration, a.R_T_I, a.omega_T),
            (b.position, b.velocity, b.acceleration, b.R_T_I, b.omega_T),
            strict=True,
        ):
            assert np.array_equal(x, y)  # bit for bit
    assert fast.kf.counts == ref.kf.counts and fast.samples == ref.samples
    assert {"fused", "duplicate", "too_late"} <= outcomes
    assert fast.kf.counts["duplicate"] > 100
