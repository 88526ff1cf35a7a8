"""The paper's target profile (Section V) and the kinematic plant's state handling, as made fast.

PaperProfile integrates its grid in fixed chunks of RK4 steps written as (p + R b, R Phi) and
steps from the nearest node; ClosedLoop.step keeps the flat state of its last result. These
tests hold what must not change with that: the profile is a pure function of t, it solves its
ODE, and the plant never integrates from a stale copy of a state.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mpf_mavlink.config.schema import load_config
from mpf_mavlink.core.target import PaperProfile
from sim.plant.kinematic import KinematicState
from sim.runner import kinematic_loop


def _fields(st):
    return [st.position, st.velocity, st.acceleration, st.R_T_I, st.omega_T, st.omega_dot_T]


def test_the_paper_target_is_a_pure_function_of_t():
    # The same instant gives the same bits whatever was asked before (grid built in the same
    # chunks whichever query extends it), on a node, near one and between two.
    ts = (37.0, 37.00000000000003, 123.456789, 5.005)
    fresh = [PaperProfile().state(t) for t in ts]
    walked = PaperProfile()
    for t in np.arange(0.0, 130.0, 0.02):
        walked.state(float(t))
    for t, a in zip(ts, fresh, strict=True):
        b = walked.state(t)
        for x, y in zip(_fields(a), _fields(b), strict=True):
            assert np.array_equal(x, y), t


def test_the_paper_target_solves_its_ode():
    # Reference: the same ODE (pdot = v R e1, Rdot = R hat(w)) by DOP853 at rtol 1e-12. Our RK4
    # at 0.01 s errs by ~h^4 of the ODE's time scale (>= 10 s): ~1e-12 relative; rounding over
    # 6000 steps of |p| <= 300 m adds ~6000 * 300 * 2.2e-16 = 4e-10 m. 1e-7 m and 1e-9 on R
    # leave a wide margin while any wrong term (a sign, the b vector's stage weights, a
    # missing node) moves them by >= 1e-4.
    prof = PaperProfile()
    p0 = prof.state(0.0)

    def f(t, y):
        R = y[3:].reshape(3, 3)
        v, _ = PaperProfile.speed(t)
        w, _ = PaperProfile.omega(t)
        W = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
        return np.concatenate([R[:, 0] * v, (R @ W).ravel()])

    ts = [0.013, 1.0, 17.5049, 33.3333, 60.0]
    sol = solve_ivp(
        f, (0.0, 60.0), np.concatenate([p0.position, p0.R_T_I.ravel()]), method="DOP853",
        rtol=1e-12, atol=1e-12, t_eval=ts,
    )  # fmt: skip
    for i, t in enumerate(ts):
        st = prof.state(t)
        assert np.max(np.abs(st.position - sol.y[:3, i])) < 1e-7, t
        assert np.max(np.abs(st.R_T_I - sol.y[3:, i].reshape(3, 3))) < 1e-9, t
        v, _ = PaperProfile.speed(t)
        assert np.allclose(st.velocity, st.R_T_I[:, 0] * v, rtol=0, atol=1e-12)


def test_the_paper_target_is_continuous_across_node_boundaries():
    # Either side of the midpoint between two nodes the state comes from a different node
    # (RK4 forward from one, backward from the other): both are the ODE's solution, so they
    # agree to the integration's error, not to the step's size (|pdot| dt ~ 0.05 m).
    prof = PaperProfile()
    for k in (10, 1234, 4999):
        mid = (k + 0.5) * PaperProfile.DT
        a, b = prof.state(mid - 1e-9), prof.state(mid + 1e-9)
        assert np.max(np.abs(a.position - b.position)) < 1e-7
        assert np.max(np.abs(a.R_T_I - b.R_T_I)) < 1e-9


def _copy(x):
    return KinematicState(x.t, x.p.copy(), x.R.copy(), x.w.copy(), x.s)


def test_the_plant_never_steps_from_a_stale_state():
    # The step from the state it returned last uses its kept flat copy; from any other state
    # it converts the arrays. Both must give the same bits, also after a field was replaced.
    cfg = load_config("configs/paper_lemniscate.yaml")
    loop, x = kinematic_loop(cfg)
    for _ in range(5):
        x = loop.step(x, 0.02)
    x.s = x.s + 1.0
    b = loop.step(x, 0.02)
    assert b.s == loop.step(_copy(x), 0.02).s
    b.p = b.p + np.array([1.0, 0.0, 0.0])
    c = loop.step(b, 0.02)
    c_ref = loop.step(_copy(b), 0.02)
    assert np.array_equal(c.p, c_ref.p) and np.array_equal(c.R, c_ref.R) and c.s == c_ref.s
    # An edit in place, which it could not see, is refused.
    with pytest.raises(ValueError):
        c.p[0] += 1.0
