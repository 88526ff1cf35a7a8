"""The law gives the numbers of the law it replaced (tests/_law_reference.py), to a derived bound.

The reference differentiated R_D along the flow by central differences (step h = 1e-4 s); the
law now takes omega_DI analytically, term by term of the paper's (10). Everything that does not
pass through the derivative (sdot, Psi, e, the frames, the errors) is the same mathematics at
the same state, so it may differ only by rounding; the rates differ by the reference's own
error. Both bounds are derived here, per state:

- Rounding. Two conditionings turn eps = 2.2e-16 into a difference in the O(1) frames:
  pt = q - p_d cancels (~eps |q|, turned into a direction over the look-ahead alpha:
  ~eps |q| / alpha), and the tabulated tangent comes from node positions of size |p_d| over a
  cell of length ds (~eps |p_d| / ds; the path's cubic is now evaluated in power form). So the
  frames may differ by ~n eps (1 + |q| / alpha + |p_d| / ds), n ~ 10 operations deep: we allow
  64 eps times that scale (relative to max(1, |value|)). The reference's difference quotient
  divides its frames' rounding by 2 h: rho = 64 eps scale / (2 h) on its rates.
- Truncation. A central difference errs by T h^2 (T ~ the third derivative of R_D / 6). With
  the reference at h and at h / 2, |r(h) - r(h/2)| = (3/4) T h^2 up to rho(h) + rho(h/2) =
  3 rho, so T h^2 <= (4/3) (|r(h) - r(h/2)| + 3 rho); a factor 2 on the measured part covers
  the neglected h^4 terms.
- Nodes. The tabulated path is C1 (cubic Hermite cells): its curvature, hence the rate of {F}
  and omega_DI, jumps at the nodes (by ~ds^2 kappa''). When the reference's interval
  s +- h sdot contains a node, its quotient blends the two one-sided rates; the analytic rate is
  the one of the cell s lies in. We add the jump, measured by the new law at the node +- 1e-9 m.

So |omega - r(h)| <= (8/3) |r(h) - r(h/2)| + 5 rho + jump on every rate (rad/s; the rate
limits and the psi turn are 1-Lipschitz in the feedforward). This holds within Assumption 1.
Outside it (path_speed_margin < 0) both laws hold wd11 at a floor and {W_d} is no longer a
rotation: the reference differenced that non-orthonormal frame, the analytic rate takes its
heading and climb; they differ (measured: by up to |omega_DI|) and neither is the paper's law,
so there we only ask for finite commands (the last test). A change of the mathematics moves
the numbers far more: K_R * (1 + 1e-4) moves the command by many times the bound (checked).
"""

from __future__ import annotations

import math
import zlib

import numpy as np
import pytest

from mpf_mavlink.core import so3
from mpf_mavlink.core.guidance import Extensions, Gains, VehicleState, mpf_law
from mpf_mavlink.core.paths import circle, helix, lemniscate
from mpf_mavlink.core.target import ConstantTurn, PaperProfile
from tests._law_reference import FD_STEP_S, reference_mpf_law

EPS = np.finfo(float).eps

RATE_FIELDS = ("omega_DI", "feedforward", "w_cmd_law")
FLOAT_FIELDS = ("pt", "pt_norm", "pt_F", "p_f", "psi", "e", "y_w", "z_w", "d1", "wd1", "f1")
FLOAT_FIELDS += ("path_speed_margin", "k1", "k2")


def _flat(x: object) -> list[float]:
    return [float(v) for v in (x if isinstance(x, tuple) else (x,))]


def _scenarios():
    """(name, path, target motion, gains, extensions, airspeed, wind) covering the law's
    branches: the paper's rotating target, the SIL demo (wind, psi turn, per-axis limit),
    magnitude limit, an open helix past both ends, a tight look-ahead."""
    default_ext = Extensions(rate_limit=0.6, psi_turn=True, wind_compensation=True)
    return [
        ("paper", lemniscate(50.0), PaperProfile(), Gains(), Extensions(), 15.0, 0.0),
        (
            "sil_demo",
            lemniscate(150.0, center=(0.0, 0.0, -100.0)),
            ConstantTurn((0.0, 0.0, 0.0), 3.0, 0.0, 0.01),
            Gains(2.0, 3.0, 5.0),
            default_ext,
            16.0,
            4.0,
        ),
        (
            "magnitude_limit_climbing_target",
            helix((0, 0, 0), 80.0, 20.0, 3, False),
            ConstantTurn((0, 0, 0), 4.0, 0.3, 0.05, 0.5),
            Gains(1.0, 0.5, 40.0),
            Extensions(
                rate_limit=0.5, rate_limit_mode="magnitude", psi_turn=True, wind_compensation=True
            ),
            18.0,
            3.0,
        ),
        (
            "psi_turn_own_rate_circle",
            circle((0, 0, 0), 200.0),
            PaperProfile(),
            Gains(4.0, 2.0, 2.0),
            Extensions(psi_turn=True, psi_turn_rate=0.3, rate_limit=1.0),
            20.0,
            0.0,
        ),
    ]


def _states(path, motion, n, rng, wind):
    """States around the path: the virtual point anywhere (open paths: also past the ends),
    the vehicle within +-60 m of it, any heading (Psi up to 1), any wind up to ``wind``."""
    for _ in range(n):
        t = float(rng.uniform(0.0, 200.0))
        tgt = motion.state(t)
        L = path.length
        s = float(rng.uniform(-0.1 * L, 1.1 * L) if not path.closed else rng.uniform(-L, 2 * L))
        p_d = path.sample(s).position
        q = p_d + rng.normal(0.0, 1.0, 3) * rng.choice([0.01, 1.0, 20.0, 60.0])
        p = tgt.position + tgt.R_T_I @ q
        R = so3.rot_z(rng.uniform(-math.pi, math.pi)) @ so3.rot_y(rng.uniform(-0.5, 0.5))
        R = R @ so3.rot_x(rng.uniform(-0.8, 0.8))
        eta = rng.normal(0.0, 1.0, 3) * wind / math.sqrt(3.0)
        yield s, t, p, R, eta, tgt, float(np.linalg.norm(q)), float(np.linalg.norm(p_d))


def _node_jump(s, veh, tgt, path, gains, ext, delta):
    """|omega_DI(node+) - omega_DI(node-)| (rad/s) at a node of the tabulated path within
    s +- delta (m), 0 if there is none."""
    s_mod = s % path.length if path.closed else s
    x = s_mod / path.ds
    for node in (math.floor(x), math.ceil(x)):
        if abs(node - x) * path.ds <= delta:
            at = s + (node - x) * path.ds
            lo = mpf_law(at - 1e-9, veh, tgt, path, gains, ext)[1]
            hi = mpf_law(at + 1e-9, veh, tgt, path, gains, ext)[1]
            assert lo is not None and hi is not None
            return float(np.linalg.norm(np.subtract(hi.omega_DI, lo.omega_DI)))
    return 0.0


def _rate_bound(s, veh, tgt, path, gains, ext, ref_diag, scale, sdot):
    """The bound of the module docstring on |rate - reference rate| (rad/s)."""
    half = reference_mpf_law(s, veh, tgt, path, gains, ext, fd_step=FD_STEP_S / 2)[1]
    assert half is not None
    measured = float(np.linalg.norm(np.subtract(ref_diag.omega_DI, half.omega_DI)))
    rho = 64 * EPS * scale / (2 * FD_STEP_S)
    jump = _node_jump(s, veh, tgt, path, gains, ext, FD_STEP_S * abs(sdot))
    return (8.0 / 3.0) * measured + 5.0 * rho + jump


@pytest.mark.parametrize("scenario", _scenarios(), ids=lambda sc: sc[0])
def test_law_matches_the_reference(scenario):
    name, path, motion, gains, ext, v_w, wind = scenario
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    modes = set()
    worst_rate = worst_other = 0.0
    for s, t, p, R, eta, tgt, qn, pdn in _states(path, motion, 400, rng, wind):
        veh = VehicleState(t, p, R, v_w, eta)
        c, d = mpf_law(s, veh, tgt, path, gains, ext)
        cr, dr = reference_mpf_law(s, veh, tgt, path, gains, ext)
        assert d is not None and dr is not None
        scale = 1.0 + qn / gains.alpha + pdn / path.ds
        rate_tol = _rate_bound(s, veh, tgt, path, gains, ext, dr, scale, cr.sdot)
        other_tol = 64 * EPS * scale
        assert d.mode == dr.mode
        modes.add(d.mode)
        rates = [c.w2 - cr.w2, c.w3 - cr.w3]
        rates += list(np.subtract(c.omega_w1_I, cr.omega_w1_I))
        for f in RATE_FIELDS:
            rates += list(np.subtract(_flat(getattr(d, f)), _flat(getattr(dr, f))))
        # [sdot] is a sum of terms that can cancel: relative to the size of its terms.
        v_t, w_t = np.linalg.norm(tgt.velocity), np.linalg.norm(tgt.omega_T)
        sdot_terms = gains.K_p * dr.pt_norm + v_w + np.linalg.norm(eta) + v_t + w_t * pdn
        others = [(c.sdot - cr.sdot) / max(1.0, float(sdot_terms)), c.t - cr.t]
        for f in FLOAT_FIELDS:
            ref = np.array(_flat(getattr(dr, f)))
            others += list((np.array(_flat(getattr(d, f))) - ref) / np.maximum(1.0, abs(ref)))
        worst_rate = max(worst_rate, float(np.max(np.abs(rates))) / rate_tol)
        worst_other = max(worst_other, float(np.max(np.abs(others))) / other_tol)
    print(
        f"{name}: worst rate diff {worst_rate:.3g} of tol, other {worst_other:.3g} of tol; {modes}"
    )
    assert worst_rate <= 1.0
    assert worst_other <= 1.0
    # The states exercised the branches this scenario is for.
    if ext.psi_turn:
        assert any(m.startswith("psi_turn") for m in modes)
    if ext.rate_limit is not None:
        assert any(m.endswith("+sat") for m in modes)


def test_the_bound_sees_a_change_of_the_law():
    # The bound is tight enough to matter: K_R * (1 + 1e-4) is far outside it.
    name, path, motion, gains, ext, v_w, wind = _scenarios()[0]
    rng = np.random.default_rng(1)
    changed = Gains(gains.K_p, gains.K_R * (1 + 1e-4), gains.alpha)
    ratios = []
    for s, t, p, R, eta, tgt, qn, pdn in _states(path, motion, 50, rng, wind):
        veh = VehicleState(t, p, R, v_w, eta)
        c = mpf_law(s, veh, tgt, path, changed, ext)[0]
        cr, dr = reference_mpf_law(s, veh, tgt, path, gains, ext)
        assert dr is not None
        scale = 1.0 + qn / gains.alpha + pdn / path.ds
        tol = _rate_bound(s, veh, tgt, path, gains, ext, dr, scale, cr.sdot)
        ratios.append(max(abs(c.w2 - cr.w2), abs(c.w3 - cr.w3)) / tol)
    assert float(np.median(ratios)) > 10.0, np.median(ratios)


def test_outside_assumption_1_the_command_stays_finite():
    # A target at 20 m/s on a 100 m circle turning at 0.05 rad/s outruns a 15 m/s vehicle.
    path = circle((0.0, 0.0, 0.0), 100.0)
    motion = ConstantTurn((0.0, 0.0, 0.0), 20.0, 0.0, 0.05)
    rng = np.random.default_rng(5)
    outside = 0
    for _ in range(100):
        tgt = motion.state(float(rng.uniform(0.0, 50.0)))
        s = float(rng.uniform(0.0, path.length))
        q = path.sample(s).position + rng.normal(0.0, 5.0, 3)
        heading = so3.rot_z(float(rng.uniform(-math.pi, math.pi)))
        veh = VehicleState(tgt.t, tgt.position + tgt.R_T_I @ q, heading, 15.0)
        c, d = mpf_law(s, veh, tgt, path, Gains(), Extensions(rate_limit=1.0))
        assert d is not None
        outside += d.path_speed_margin < 0
        assert all(math.isfinite(v) for v in (c.w2, c.w3, c.sdot, *c.omega_w1_I, *d.omega_DI))
        assert max(abs(c.w2), abs(c.w3)) <= 1.0
    assert outside > 50
