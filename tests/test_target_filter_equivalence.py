"""The scalar target filter (mpf_mavlink.core.target_filter) against the numpy filter it replaced
(tests/_target_filter_reference.py, main 5d64e11), report by report.

The two are the same algebra in a different order (sequential scalar updates on the two blocks
of a block-diagonal covariance, against a 7 x 7 solve and Joseph form), so they agree to
rounding, not to the bit. What is compared, after every report:

- what became of it (fused, gated, reinit, duplicate, too_late, ...), and the counts: identical;
- whether the estimate at the control time is stale: identical;
- the posterior mean and covariance, within a tolerance derived from the rounding:
  one fix rounds each term at a few ulp of the largest quantity it handles (the mean:
  ``|x_j| + sigma_j``; the covariance: ``sigma_j sigma_k`` times the conditioning ``kappa`` of
  the update, the largest ``(P_ii + r_i) / r_i`` of a measured component: the posterior
  variance is a difference that many times smaller than its terms). These errors are
  independent from fix to fix and the filter forgets them slowly (the demo's quiet tuning
  averages hundreds of fixes), so they add like a random walk: ``C sqrt(n) eps`` after n
  fixes. C = 16 ulp per fix: the transition and the update each round ~10 terms per entry.
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import Any

import _target_filter_reference as ref
import numpy as np
import pytest

from mpf_mavlink.core import target_filter as new
from mpf_mavlink.core.target import ConstantTurn, PaperProfile

EPS = float(np.finfo(float).eps)
C_ULP = 16.0
BOAT = ConstantTurn(speed=3.0, turn_rate=0.01)  # the demo's boat
DEMO_TUNING = dict(
    accel_noise_m_s2=0.001, turn_accel_noise_rad_s2=1e-6, vertical_accel_noise_m_s2=0.001
)


def _pair(d: dict[str, Any]) -> tuple[new.Report, ref.Report]:
    arrays = {k: (np.asarray(v, float) if isinstance(v, list) else v) for k, v in d.items()}
    return new.Report(**d), ref.Report(**arrays)


def _kappa(b: ref.TargetEstimator, r: ref.Report, rv: list[tuple[int, float]]) -> float:
    """(P_ii + r_i) / r_i of the report's components at the reference's prior (1 if none)."""
    post = b.latest()
    if post is None or r.t < post.t:
        return 1.0
    _, P = ref.predict(b.p, post.x, post.P, r.t - post.t)
    return max([(P[i, i] + v) / v for i, v in rv], default=1.0)


def _variances(p: new.TargetFilterParams, r: new.Report) -> list[tuple[int, float]]:
    out: list[tuple[int, float]] = []
    if r.position is not None:
        pv = (
            r.pos_var
            if r.pos_var is not None
            else [p.position_noise_m**2] * 2 + [p.vertical_noise_m**2]
        )
        out += [(i, float(v)) for i, v in enumerate(pv)]
    if r.velocity is not None:
        out += [(i, p.velocity_noise_m_s**2) for i in (3, 4, 5)]
    if r.turn_rate is not None:
        out.append((6, p.turn_rate_noise_rad_s**2))
    return out


def _compare(stream: list[tuple[float, dict[str, Any]]], **tuning: float) -> dict[str, int]:
    p = new.TargetFilterParams(**tuning)  # type: ignore[arg-type]
    a, b = new.TargetEstimator(p), ref.TargetEstimator(ref.TargetFilterParams(**tuning))
    xmax = np.zeros(7)
    kappa = 1.0
    n = 0
    for rx, d in stream:
        ra, rb = _pair(d)
        kappa = max(kappa, _kappa(b, rb, _variances(p, ra)))
        with np.errstate(all="ignore"):  # the reference overflows on the absurd reports
            ob = b.add(rb, rx)
        oa = a.add(ra, rx)
        assert oa == ob, (rx, d, oa, ob)
        n += oa == "fused"
        pa, pb = a.latest(), b.latest()
        assert (pa is None) == (pb is None)
        if pa is not None and pb is not None:
            assert pa.t == pb.t and pa.t_fix == pb.t_fix and pa.nrej == pb.nrej
            xb, Pb = np.asarray(pb.x), pb.P
            xmax = np.maximum(xmax, np.abs(xb))
            sd = np.sqrt(np.diag(Pb))
            walk = C_ULP * math.sqrt(max(n, 1)) * EPS
            np.testing.assert_array_less(np.abs(np.asarray(pa.x) - xb), walk * (xmax + sd))
            np.testing.assert_array_less(
                np.abs(pa.P - Pb), walk * kappa * np.outer(sd, sd) + 1e-300
            )
        sa, sb = a.state(rx), b.state(rx)
        assert isinstance(sa, str) == isinstance(sb, str), (rx, sa, sb)
        if not isinstance(sa, str) and not isinstance(sb, str):
            walk = C_ULP * math.sqrt(max(n, 1)) * EPS
            scale = float(np.max(np.abs(sb.position))) + float(np.sqrt(np.trace(Pb[:3, :3])))
            assert np.max(np.abs(sa.position - sb.position)) <= walk * scale
    assert a.counts == b.counts
    return a.counts


def test_demo_feed_agrees_with_the_numpy_filter():
    """The demo's boat as the SIL sends it: FOLLOW_TARGET at 10 Hz with position, velocity
    and attitude (turn rate and yaw), 1 cm of noise, 600 s, the demo's quiet tuning: 6000
    fixes, every one fused by both."""
    rng = np.random.default_rng(1)
    stream = []
    for k in range(6000):
        t = 0.1 * k
        ts = BOAT.state(t)
        yaw = math.atan2(ts.R_T_I[1, 0], ts.R_T_I[0, 0])
        stream.append((t + 0.013, dict(
            t=t + 100.0, position=(ts.position + rng.normal(0, 0.01, 3)).tolist(),
            velocity=(ts.velocity + rng.normal(0, 0.01, 3)).tolist(), turn_rate=0.01, yaw=yaw,
            attitude=True,
        )))  # fmt: skip
    counts = _compare(stream, **DEMO_TUNING)
    assert counts["fused"] == 6000


def radio_feed() -> list[tuple[float, dict[str, Any]]]:
    """The paper's manoeuvring target through a radio, as (receive time s, report fields) in
    receive order: 5 Hz fixes (2 m, 0.3 m/s noise), 10 % lost, 5 % of them 0.4 s late, and
    ATTITUDE-only turn-rate reports between them."""
    rng = np.random.default_rng(2)
    m = PaperProfile()
    stream: list[tuple[float, dict[str, Any]]] = []
    for k in range(1500):
        t = 0.2 * k
        ts = m.state(t)
        w = float((ts.R_T_I @ ts.omega_T)[2])
        stream.append((t + 0.15, dict(t=t + 0.1 - 50.0, turn_rate=w + rng.normal(0, 0.01),
                                      yaw=0.3, attitude=True)))  # fmt: skip
        if rng.random() < 0.1:
            continue
        late = 0.4 if rng.random() < 0.05 else 0.0
        stream.append((t + 0.05 + late, dict(
            t=t - 50.0, position=(ts.position + rng.normal(0, 2, 3)).tolist(),
            velocity=(ts.velocity + rng.normal(0, 0.3, 3)).tolist(),
        )))  # fmt: skip
    stream.sort(key=lambda e: e[0])
    return stream


def test_radio_feed_with_late_reports_and_attitudes_agrees_with_the_numpy_filter():
    """The paper's manoeuvring target through a radio: 5 Hz fixes (2 m, 0.3 m/s noise), 10 %
    lost, 5 % of them 0.4 s late (re-ordered: the filter re-runs from the posterior before),
    ATTITUDE-only turn-rate reports between them, the default tuning."""
    counts = _compare(radio_feed(), latency_s=0.05)
    assert counts["out_of_order"] > 20 and counts["fused"] > 2500


def test_malformed_and_implausible_reports_are_rejected_as_before():
    """Non-finite and absurd components, a report without velocity, one without position,
    reported accuracies, a target that jumps 300 m for 3 fixes (gated twice, then
    re-initialised on the third; back on its track: gated twice, re-initialised again): the
    same outcome for each as the numpy filter, the same estimate after."""
    rng = np.random.default_rng(3)
    bad: dict[int, dict[str, Any]] = {
        50: dict(position=[math.nan, 0.0, 0.0]), 60: dict(position=[math.inf, 0.0, 0.0]),
        70: dict(velocity=[0.0, math.nan, 0.0]), 80: dict(turn_rate=math.nan),
        90: dict(position=[1e300, 0.0, 0.0]), 110: dict(pos_var=[1e30, 1.0, 1.0]),
        120: dict(velocity=None), 130: dict(position=None, velocity=[1.0, 1.0, 0.0]),
        140: dict(turn_rate=-math.inf), 150: dict(pos_var=[0.25, 0.25, 2.25]),
        160: dict(velocity=[1e200, 0.0, 0.0]), 170: dict(turn_rate=5.0),
    }  # fmt: skip
    stream = []
    for k in range(300):
        t = float(k)
        ts = BOAT.state(t)
        d: dict[str, Any] = dict(
            t=t, position=(ts.position + rng.normal(0, 2, 3)).tolist(),
            velocity=(ts.velocity + rng.normal(0, 0.3, 3)).tolist(),
        )  # fmt: skip
        d.update(bad.get(k, {}))
        if 200 <= k < 203:
            d["position"] = (np.asarray(d["position"]) + [0.0, 300.0, 0.0]).tolist()
        stream.append((t + 0.3, d))
    counts = _compare(stream, latency_s=0.3)
    assert counts["gated"] >= 8 + 4 and counts["reinit"] == 2


def _exact_update(P: np.ndarray, rows: list[int], rv: list[float]) -> np.ndarray:
    """P - P H' (H P H' + R)^-1 H P in exact rational arithmetic (the floats of P and R taken
    as exact), rounded to floats once at the end."""
    Pf = [[Fraction(float(v)) for v in row] for row in P]
    n = len(rows)
    A = [[Pf[i][j] + (Fraction(rv[a]) if i == j else 0) for j in rows] for a, i in enumerate(rows)]
    Y = [list(Pf[i]) for i in rows]  # solve S Y = H P by Gauss-Jordan
    for c in range(n):
        for r in range(n):
            if r != c:
                f = A[r][c] / A[c][c]
                A[r] = [u - f * v for u, v in zip(A[r], A[c], strict=True)]
                Y[r] = [u - f * v for u, v in zip(Y[r], Y[c], strict=True)]
    Y = [[u / A[c][c] for u in Y[c]] for c in range(n)]
    return np.array(
        [[float(Pf[i][j] - sum(Pf[i][rows[k]] * Y[k][j] for k in range(n))) for j in range(7)]
         for i in range(7)]
    )  # fmt: skip


def test_a_very_precise_fix_is_fused_to_the_last_bits():
    """A FOLLOW_TARGET that claims 1e-15 m of position error (eph^2 = 1e-30 m^2) against a
    prior of metres: the posterior position variance is 1e30 times smaller than the prior, the
    worst conditioning a fix can bring. The scalar update computes the measured rows as
    ``P[i, :] r / s`` (no difference of nearly equal terms): within a few ulp of sigma_j sigma_k
    of the exact update. (The numpy Joseph form was off by ~1 % of them there.)"""
    p = new.TargetFilterParams(latency_s=0.3)
    kf = new.TargetEstimator(p)
    rng = np.random.default_rng(4)
    for k in range(100):
        ts = BOAT.state(float(k))
        kf.add(new.Report(float(k), ts.position + rng.normal(0, 2, 3),
                          ts.velocity + rng.normal(0, 0.3, 3)), k + 0.3)  # fmt: skip
    prior = kf.latest()
    assert prior is not None
    ts = BOAT.state(100.0)
    r = new.Report(100.0, ts.position, ts.velocity, pos_var=[1e-30] * 3)
    _, Ph, Pv = new._predict(prior.x, prior.Ph, prior.Pv, 100.0 - prior.t, kf.q)
    rv = [1e-30] * 3 + [p.velocity_noise_m_s**2] * 3
    exact = _exact_update(new.full_covariance(Ph, Pv), [0, 1, 2, 3, 4, 5], rv)
    assert kf.add(r, 100.3) == "fused"
    post = kf.latest()
    assert post is not None
    sd = np.sqrt(np.diag(exact))
    np.testing.assert_array_less(np.abs(post.P - exact), 8 * EPS * np.outer(sd, sd) + 1e-300)


@pytest.mark.parametrize("pos_var", [[math.inf, 1.0, 1.0], [math.nan, 1.0, 1.0]])
def test_a_report_with_a_non_finite_variance_is_gated(pos_var):
    """A non-finite variance (only a report built in Python can carry one: the decoder drops a
    FOLLOW_TARGET whose position_cov is not finite) has no innovation to gate on: gated, and
    the estimate stays finite. (The numpy filter fused it into a nan covariance.)"""
    kf = new.TargetEstimator(new.TargetFilterParams())
    ts = BOAT.state(0.0)
    kf.add(new.Report(0.0, ts.position, ts.velocity), 0.0)
    ts = BOAT.state(1.0)
    assert kf.add(new.Report(1.0, ts.position, ts.velocity, pos_var=pos_var), 1.0) == "gated"
    post = kf.latest()
    assert post is not None
    assert np.all(np.isfinite(post.P)) and np.all(np.isfinite(post.x))
