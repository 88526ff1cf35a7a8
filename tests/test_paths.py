"""Paths: arc length, parallel-transport frames, continuity over a lap, closest point."""

import math

import numpy as np
import pytest

from mpf_mavlink.core.paths import TabulatedPath, circle, helix, lemniscate, line, spline


def _tennis(u):
    a = 0.6
    return np.column_stack(
        [
            50 * np.cos(u) * np.cos(a * np.sin(2 * u)),
            50 * np.sin(u) * np.cos(a * np.sin(2 * u)),
            50 * np.sin(a * np.sin(2 * u)) + 20 * np.cos(u),
        ]
    )


PATHS = {
    "lemniscate": lambda: lemniscate(50.0),
    "circle": lambda: circle((0, 0, -10), 30.0),
    "helix": lambda: helix((0, 0, 0), 30.0, 20.0, 2.0),
    "line": lambda: line((0, 0, 0), (30, 40, -5)),
    "spline_open": lambda: spline(
        [[0, 0, 0], [40, 10, -5], [80, -20, 5], [120, 0, 0]], closed=False
    ),
    "spline_closed": lambda: spline(
        [[0, 0, 0], [60, 0, -30], [60, 60, 0], [0, 60, 30]], closed=True
    ),
    # A closed space curve whose transported frame comes back rotated (holonomy ~0.12 rad).
    "space_closed": lambda: TabulatedPath(_tennis, 0.0, 2 * math.pi, closed=True, name="space"),
}


@pytest.fixture(scope="module", params=list(PATHS))
def path(request):
    return PATHS[request.param]()


def test_unit_speed(path):
    # s is arc length: |dp/ds| = 1 (to the tabulation accuracy, 1e-4).
    ss = np.linspace(0, path.length, 3001)
    P = np.array([path.sample(s).position for s in ss])
    sp = np.linalg.norm(np.diff(P, axis=0), axis=1) / np.diff(ss)
    assert np.max(np.abs(sp - 1.0)) < 1e-4


def test_frame_orthonormal_and_tangent(path):
    h = 1e-4
    for s in np.linspace(0.01, path.length - 0.01, 97):
        F = path.sample(s).R_F_T
        assert np.allclose(F.T @ F, np.eye(3), atol=1e-12)
        assert abs(np.linalg.det(F) - 1) < 1e-12
        # f1 is the unit tangent dp/ds.
        dp = (path.sample(s + h).position - path.sample(s - h).position) / (2 * h)
        assert np.allclose(F[:, 0], dp, atol=2e-4)


def test_twist_free(path):
    # Parallel transport: df2/ds has no f3 component other than the spread holonomy tau
    # (zero on open paths), and df1/ds = k1 f2 + k2 f3.
    h = 1e-3
    for s in np.linspace(0.5, path.length - 0.5, 53):
        a, b, m = path.sample(s - h), path.sample(s + h), path.sample(s)
        df2 = (b.R_F_T[:, 1] - a.R_F_T[:, 1]) / (2 * h)
        df1 = (b.R_F_T[:, 0] - a.R_F_T[:, 0]) / (2 * h)
        assert abs(df2 @ m.R_F_T[:, 2] - m.tau) < 2e-3
        assert abs(df1 @ m.R_F_T[:, 1] - m.k1) < 2e-3
        assert abs(df1 @ m.R_F_T[:, 2] - m.k2) < 2e-3


def test_closed_paths_continuous_over_the_lap(path):
    if not path.closed:
        pytest.skip("open path")
    L = path.length
    for eps in (1e-9, 1e-6):
        a, b = path.sample(L - eps), path.sample(L + eps)
        # No jump of the frame at the seam (s unwrapped across laps).
        assert np.allclose(a.R_F_T, b.R_F_T, atol=1e-5)
        assert np.allclose(a.position, b.position, atol=1e-5)
    c, d = path.sample(0.3), path.sample(0.3 + 3 * L)
    assert np.allclose(c.R_F_T, d.R_F_T, atol=1e-12)


def test_holonomy_is_spread_as_twist():
    p = PATHS["space_closed"]()
    # The curve's transported frame turns by ~0.12 rad per lap; it must appear as a constant
    # twist, not as a jump.
    assert abs(p.tau * p.length) > 0.05
    assert np.allclose(p.sample(0.0).R_F_T, p.sample(p.length - 1e-9).R_F_T, atol=1e-6)


def test_circle_curvature_and_horizontal_frame():
    c = circle((0, 0, 0), 25.0, clockwise=True)
    smp = c.sample(10.0)
    # Clockwise seen from above in NED is a right turn: k1 = +1/R, f3 = down, k2 = 0.
    assert abs(smp.k1 - 1 / 25.0) < 1e-5 and abs(smp.k2) < 1e-6
    assert np.allclose(smp.R_F_T[:, 2], [0, 0, 1], atol=1e-9)
    assert abs(c.length - 2 * math.pi * 25.0) < 1e-4


def test_lemniscate_matches_paper_shape():
    p = lemniscate(50.0)
    # s = 0 is the paper's u = 0: the tip [0, 50, 0]; total length of this lemniscate of
    # Bernoulli (half-width 50) is 50 * 2 * 2.62206 = 262.206 m.
    assert np.allclose(p.sample(0.0).position, [0, 50, 0], atol=1e-9)
    assert abs(p.length - 262.2058) < 1e-3


def test_closest_point_global():
    p = lemniscate(50.0)
    for s_true in (3.0, 77.7, 150.0, 250.0):
        smp = p.sample(s_true)
        q = smp.position + 2.0 * smp.R_F_T[:, 1]  # 2 m to the side of the path
        assert abs(p.closest(q) - s_true) < 1e-3


def test_open_path_extends_straight():
    p = line((0, 0, 0), (10, 0, 0))
    assert np.allclose(p.sample(15.0).position, [15, 0, 0])
    assert np.allclose(p.sample(-5.0).position, [-5, 0, 0])
