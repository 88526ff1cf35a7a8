"""The law gives the numbers of the spec's equations transcribed in numpy (tests/_law_reference.py)
to rounding.

The reference builds the same frames as 3x3 matrices and takes omega_DI as the complex-step
derivative of R_D^I along the flow, the package term by term of the paper's (10): the same
mathematics at the same state, in another order of operations. Each result is a few dozen
operations deep on O(1) frames, so reassociation alone moves it by ~n eps with n ~ 10-100;
two conditionings scale that:

- pt = q - p_d cancels: its rounding, ~eps |q|, becomes a direction over the look-ahead
  alpha, ~eps |q| / alpha in d1 and everything after it; the frames, errors and rates are
  compared relative to max(1, |value|) at 512 eps (1 + |q| / alpha). 512 = 2^9: the measured
  worst over the 1600 states below is 108 eps (1 + |q| / alpha) (printed; the paper's
  scenario, alpha = 1 m), so the bound holds a factor ~5 over what reassociation gives and
  stays ~1e6 below what a changed gain moves (K_R * (1 + 1e-4): checked by the second test).
- [sdot] is a sum of terms that can cancel: relative to the size of its terms.

Outside Assumption 1 (path_speed_margin < 0) both hold wd11 at a floor and {W_d} is no longer a
rotation, so the complex-step rate of the reference's non-orthonormal matrix and the package's
heading-and-climb rate differ and neither is the paper's law: there we only ask for finite
commands (the last test).
"""

from __future__ import annotations

import dataclasses
import math
import zlib

import numpy as np
import pytest

from mpf_mavlink.core import so3
from mpf_mavlink.core.guidance import Extensions, Gains, VehicleState, mpf_law
from mpf_mavlink.core.guidance.law import mpf_errors, vehicle_state_of_floats
from mpf_mavlink.core.guidance.law_unrolled import mpf_law_unrolled
from mpf_mavlink.core.paths import circle, helix, lemniscate
from mpf_mavlink.core.target import ConstantTurn, PaperProfile
from tests._law_reference import reference_mpf_law

EPS = np.finfo(float).eps
ULPS = 512  # module docstring

FIELDS = ("pt", "pt_norm", "pt_F", "p_f", "psi", "e", "y_w", "z_w", "d1", "wd1", "f1")
FIELDS += ("omega_DI", "feedforward", "w_cmd_law", "path_speed_margin", "k1", "k2")


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


def worst_difference(c, d, cr, dr, scale, sdot_terms):
    """max |law - reference| over the command and the record, in units of EPS scale (relative
    to max(1, |reference|); sdot relative to the size of its terms)."""
    diffs = [(c.sdot - cr.sdot) / max(1.0, sdot_terms), c.t - cr.t]
    for a, b in [(c.w2, cr.w2), (c.w3, cr.w3)] + list(
        zip(c.omega_w1_I, cr.omega_w1_I, strict=True)
    ):
        diffs.append((a - b) / max(1.0, abs(b)))
    for f in FIELDS:
        ref = np.array(_flat(getattr(dr, f)))
        diffs += list((np.array(_flat(getattr(d, f))) - ref) / np.maximum(1.0, abs(ref)))
    return float(np.max(np.abs(diffs))) / (EPS * scale)


def _compare(s, veh, tgt, path, gains, ext, qn):
    c, d = mpf_law(s, veh, tgt, path, gains, ext)
    cr, dr = reference_mpf_law(s, veh, tgt, path, gains, ext)
    assert d is not None and d.mode == dr.mode
    v_t, w_t = np.linalg.norm(tgt.velocity), np.linalg.norm(tgt.omega_T)
    p_d = np.linalg.norm(path.sample(s).position)
    terms = gains.K_p * dr.pt_norm + veh.airspeed + np.linalg.norm(veh.wind) + v_t + w_t * p_d
    return d, worst_difference(c, d, cr, dr, 1.0 + qn / gains.alpha, float(terms))


@pytest.mark.parametrize("scenario", _scenarios(), ids=lambda sc: sc[0])
def test_law_matches_the_reference(scenario):
    name, path, motion, gains, ext, v_w, wind = scenario
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    modes, worst, inside = set(), 0.0, 0
    for s, t, p, R, eta, tgt, qn, _ in _states(path, motion, 400, rng, wind):
        d, w = _compare(s, VehicleState(t, p, R, v_w, eta), tgt, path, gains, ext, qn)
        if d.path_speed_margin > 0.0:  # Assumption 1 (module docstring)
            worst, inside = max(worst, w), inside + 1
            modes.add(d.mode)
    print(f"{name}: worst {worst:.3g} eps (1 + |q|/alpha) over {inside} states; {modes}")
    assert worst <= ULPS and inside >= 300
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
    for s, t, p, R, eta, tgt, qn, _ in _states(path, motion, 50, rng, wind):
        veh = VehicleState(t, p, R, v_w, eta)
        c = mpf_law(s, veh, tgt, path, changed, ext)[0]
        cr = reference_mpf_law(s, veh, tgt, path, gains, ext)[0]
        tol = ULPS * EPS * (1.0 + qn / gains.alpha)
        ratios.append(max(abs(c.w2 - cr.w2), abs(c.w3 - cr.w3)) / max(1.0, abs(cr.w2)) / tol)
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


@pytest.mark.parametrize("scenario", _scenarios(), ids=lambda sc: sc[0])
def test_the_unrolled_law_is_the_plain_law_bit_for_bit(scenario):
    # law_unrolled.py performs the same IEEE operations in the same order as law.py (its module
    # docstring): equal, not close, on every field, with the target's and the vehicle's floats
    # or their arrays, with and without the record, and for mpf_errors' record.
    name, path, motion, gains, ext, v_w, wind = scenario
    rng = np.random.default_rng(zlib.crc32(name.encode()) + 1)
    for s, t, p, R, eta, tgt, _, _ in _states(path, motion, 100, rng, wind):
        floats = tuple(float(v) for v in (*R[0], *R[1], *R[2], *p, *eta))
        for veh in (VehicleState(t, p, R, v_w, eta), vehicle_state_of_floats(t, floats, v_w)):
            for tg in (tgt, dataclasses.replace(tgt)):
                for keep in (True, False):
                    got = mpf_law_unrolled(s, veh, tg, path, gains, ext, keep)
                    assert got == mpf_law(s, veh, tg, path, gains, ext, keep)
                errors = mpf_law_unrolled(s, veh, tg, path, gains, ext, True, "law+sat")[1]
                assert errors == mpf_errors(s, veh, tg, path, gains, ext, "law+sat")
