"""The capture guards (mpf_mavlink/core/guidance/capture.py), the rig's path placement and
--start-offset (lab/rigs/placement.py), and a capture from far in our SIL (docs/bridge.md
"Capture from far")."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lab.rigs.placement import parse_offset, place_path
from mpf_mavlink.config.scenario import build_capture, build_path, build_target
from mpf_mavlink.config.schema import load_config
from mpf_mavlink.constants import GRAVITY_M_S2
from mpf_mavlink.core.guidance import capture as cap
from mpf_mavlink.core.guidance.law import Gains, MpfCommand, VehicleState, mpf_law
from mpf_mavlink.core.paths import circle, helix, lemniscate, line, spline

ROOT = Path(__file__).resolve().parents[1]
P = cap.CaptureParams()


def _frame(chi: float, gamma: float, mu: float) -> np.ndarray:
    """R_W^I (columns w1, w2, w3 in NED) of heading chi, flight path gamma, wind-axis bank mu."""
    cc, sc, cg, sg, cm, sm = (math.cos(chi), math.sin(chi), math.cos(gamma), math.sin(gamma),
                              math.cos(mu), math.sin(mu))  # fmt: skip
    Rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    Ry = np.array([[cg, 0, sg], [0, 1, 0], [-sg, 0, cg]])  # a climb: w1 down component -sin g
    Rx = np.array([[1, 0, 0], [0, cm, -sm], [0, sm, cm]])
    return Rz @ Ry @ Rx


def test_the_weight_is_zero_inside_one_beyond_and_continuous():
    d, b = 150.0, 30.0
    assert cap.capture_weight(0.0, d, b) == cap.capture_weight(150.0, d, b) == 0.0
    assert cap.capture_weight(180.0, d, b) == cap.capture_weight(1e4, d, b) == 1.0
    xs = np.linspace(140.0, 190.0, 5001)
    ws = np.array([cap.capture_weight(x, d, b) for x in xs])
    assert np.all(np.diff(ws) >= 0.0)
    # smoothstep's slope is at most 1.5 / blend: the largest jump over a 1 cm step
    assert np.max(np.diff(ws)) <= 1.5 / b * (xs[1] - xs[0]) + 1e-12


def _random_case(rng: np.random.Generator):
    chi, gamma = rng.uniform(-math.pi, math.pi), rng.uniform(-0.3, 0.3)
    R = _frame(chi, gamma, rng.uniform(-0.5, 0.5))
    v = rng.uniform(10.0, 30.0)
    pos = np.array([rng.uniform(-500, 500), rng.uniform(-500, 500), rng.uniform(-200, -20)])
    veh = VehicleState(0.0, pos, R, v)
    t = tuple(rng.uniform(-1, 1, 3))
    f1 = tuple(np.array(t) / np.linalg.norm(t))
    wd = tuple(rng.uniform(-1, 1, 3))
    wd1 = tuple(np.array(wd) / np.linalg.norm(wd))
    w2, w3 = rng.uniform(-2, 2, 2)
    sdot = rng.uniform(-100, 100)
    om = tuple(w2 * R[:, 1] + w3 * R[:, 2])
    cmd = MpfCommand(0.0, float(w2), float(w3), float(sdot), om)
    pt_norm = rng.uniform(181.0, 1000.0)  # beyond distance + blend: the guards act fully
    pt_along = rng.uniform(-pt_norm, pt_norm)
    return veh, cmd, f1, wd1, pt_norm, pt_along, rng.uniform(-150, -20)


def test_the_bounds_hold_on_random_inputs_beyond_the_capture_distance():
    rng = np.random.default_rng(40)
    K_p = 1.0
    for _ in range(2000):
        veh, cmd, f1, wd1, pt_norm, pt_along, floor_d = _random_case(rng)
        diag = _diag(pt_norm, pt_along, f1, wd1)
        ceil_d = floor_d - rng.uniform(0.0, 60.0)
        out, beta, _ = cap.guard_limited(cmd, diag, veh, floor_d, K_p, P, ceil_d)
        assert beta == 1.0
        R, v = np.asarray(veh.R_W_I), veh.airspeed
        # (a) sdot within +-v_w of the on-path rate
        sdot_0 = cap.on_path_rate(cmd.sdot, K_p, pt_along, v, float(R[:, 0] @ f1),
                                  float(np.dot(wd1, f1)))  # fmt: skip
        assert sdot_0 - v - 1e-9 <= out.sdot <= sdot_0 + v + 1e-9
        # (b) the bank set-point of the turn within the limit less the margin
        cg = max(R[2, 2], 0.1)
        bank_sp = math.atan(v * abs(out.w3) / (GRAVITY_M_S2 * P.turn_gain * cg))
        assert bank_sp <= P.bank_limit_rad - P.bank_margin_rad + 1e-9
        # (c) the flight path the adapter asks for (gamma + gamma_dot tau) inside the band;
        # above the floor's bound: at or below the floor, no sink
        gamma = math.asin(-R[2, 0])
        gdot = (out.w2 * R[2, 2] - out.w3 * R[2, 1]) / math.cos(gamma)
        g_cmd = gamma + gdot * P.tau_s
        assert g_cmd <= P.pitch_max_rad - P.pitch_margin_rad + 1e-6
        if veh.position[2] <= ceil_d:  # at or above the ceiling: no climb
            assert g_cmd <= 1e-6 or g_cmd <= P.pitch_min_rad + P.pitch_margin_rad + 1e-6
        if veh.position[2] >= floor_d:
            assert g_cmd >= -1e-6
        else:
            assert g_cmd >= P.pitch_min_rad + P.pitch_margin_rad - 1e-6
        # the command's omega is R_W^I [0, w2, w3]
        assert np.allclose(out.omega_w1_I, out.w2 * R[:, 1] + out.w3 * R[:, 2], atol=1e-12)


def _diag(pt_norm, pt_along, f1, wd1):
    """A diagnostics record with the fields the guard reads (the rest zero)."""
    from mpf_mavlink.core.guidance.law import MpfDiagnostics

    z3 = (0.0, 0.0, 0.0)
    return MpfDiagnostics(0.0, 0.0, z3, pt_norm, (pt_along, 0.0, 0.0), z3, 0.0, (0.0, 0.0),
                          0.0, 0.0, z3, wd1, f1, z3, (0.0, 0.0), (0.0, 0.0), 1.0, "law",
                          0.0, 0.0)  # fmt: skip


def test_inside_the_capture_distance_the_law_is_untouched():
    cfg = load_config(ROOT / "configs" / "bridge_arduplane_spline.yaml")
    guard = build_capture(cfg)
    assert guard is not None
    path, st = build_path(cfg.path), build_target(cfg.target).state(0.0)
    gains = Gains(cfg.guidance.K_p, cfg.guidance.K_R, cfg.guidance.alpha_m)
    rng = np.random.default_rng(3)
    n_in = 0
    for _ in range(300):
        s = rng.uniform(0.0, path.length)
        p_d = np.asarray(path.eval_flat(s)[:3])
        pos = st.position + st.R_T_I @ p_d + rng.uniform(-100.0, 100.0, 3)
        veh = VehicleState(0.0, pos, _frame(rng.uniform(-3, 3), 0.1, 0.2), 22.0)
        cmd, diag = mpf_law(s, veh, st, path, gains)
        assert diag is not None
        out, d2 = guard.apply(cmd, diag, veh, st, gains.K_p)
        if diag.pt_norm <= cfg.guidance.capture_distance_m:
            n_in += 1
            assert out is cmd and d2 is diag  # the very objects: bit for bit
        else:
            assert d2.mode.endswith("+capture")
    assert n_in > 200


def test_the_config_switches_the_guards_and_a_baseline_has_none():
    cfg = load_config(ROOT / "configs" / "bridge_px4.yaml")
    g = build_capture(cfg)
    assert g is not None
    assert g.params.distance_m == 150.0 and g.params.bank_limit_rad == cfg.vehicle.max_bank_rad
    off = load_config(ROOT / "configs" / "bridge_px4.yaml", ["guidance.capture_guards=false"])
    assert build_capture(off) is None
    assert build_capture(dataclasses.replace(cfg, guidance=dataclasses.replace(
        cfg.guidance, law="pursuit"))) is None  # fmt: skip


def test_the_floor_is_the_moving_paths_lowest_point_less_the_margin():
    cfg = load_config(ROOT / "configs" / "bridge_arduplane_spline.yaml")
    g = build_capture(cfg)
    assert g is not None
    st = build_target(cfg.target).state(10.0)
    # the spline's lowest waypoint is 12 m below the target (100 m up): 88 m, floor 83 m
    fd = cap.floor_down(st, g.nodes, g.params)
    assert fd == pytest.approx(-(100.0 - 12.0 - 5.0), abs=0.5)
    # never below metrics.altitude_floor_m above home
    low = dataclasses.replace(g.params, altitude_floor_m=95.0)
    assert cap.floor_down(st, g.nodes, low) == -95.0


PATHS = {
    "circle": circle((0.0, 0.0, 0.0), 150.0, True),
    "spline": build_path(load_config(ROOT / "configs" / "bridge_arduplane_spline.yaml").path),
    "figure-eight": lemniscate(200.0, (0.0, 0.0, 0.0)),
    "helix": helix((0.0, 0.0, 0.0), 120.0, 20.0, 3.0, True),
    "line": line((0.0, 0.0, 0.0), (800.0, 200.0, -20.0)),
    "spline-open": spline([[0, 0, 0], [200, 100, -10], [400, -50, 0], [600, 0, 10]], False),
}


def _dist(nodes_ned: np.ndarray, p: np.ndarray) -> float:
    return float(np.min(np.linalg.norm(nodes_ned - p, axis=1)))


@pytest.mark.parametrize("shape", sorted(PATHS))
@pytest.mark.parametrize("chi", [0.3, 2.0, -2.5])
def test_every_shape_is_placed_near_the_aircraft_or_at_its_offset(shape, chi):
    path = PATHS[shape]
    nodes = path.positions()
    yaw = 0.8
    R = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0],
                  [0, 0, 1]])  # fmt: skip
    a = np.array([120.0, -40.0, -100.0])
    h = np.array([math.cos(chi), math.sin(chi), 0.0])
    # a node spacing bounds how far the aircraft is from the tabulated path
    tol = path.ds + 1e-6
    tgt, _ = place_path(nodes, R, tuple(a), chi)
    ned = np.asarray(tgt) + nodes @ R.T
    assert _dist(ned, a) <= tol
    k = int(np.argmin(np.linalg.norm(ned - a, axis=1)))
    tang = np.gradient(ned, axis=0)[k]
    # tangent to the flight: the best-aligned tangent of the shape (a line has one direction)
    best = max(
        float(np.dot(t[:2], h[:2]) / np.linalg.norm(t[:2])) for t in np.gradient(ned, axis=0)
    )
    assert float(np.dot(tang[:2], h[:2]) / np.linalg.norm(tang[:2])) >= best - 0.02
    for off in ((0.0, 0.0, 30.0), (0.0, 0.0, -30.0)):
        tgt, _ = place_path(nodes, R, tuple(a), chi, off)
        ned = np.asarray(tgt) + nodes @ R.T
        # a path point D above (D > 0) or below the aircraft
        assert _dist(ned, a - np.array(off)) <= tol
    tgt, _ = place_path(nodes, R, tuple(a), chi, (300.0, 0.0, 0.0))
    ned = np.asarray(tgt) + nodes @ R.T
    # at least 300 m from every point of the path (the support point that way), and at it
    assert 300.0 - 1e-6 <= _dist(ned, a) <= 300.0 + 1e-6
    # flying away: every point of the path is behind the aircraft
    assert np.max((ned[:, :2] - a[:2]) @ h[:2]) <= -300.0 + 1e-6


@pytest.mark.parametrize(
    "text, ok",
    [
        ("300,0,0", (300.0, 0.0, 0.0)),
        ("0,0,-30", (0.0, 0.0, -30.0)),
        ("1e2,5,-3.5", (100.0, 5.0, -3.5)),
    ],
)
def test_start_offset_parses(text, ok):
    assert parse_offset(text) == ok


@pytest.mark.parametrize("text", ["300,0", "a,b,c", "1,2,3,4", "nan,0,0", ""])
def test_a_bad_start_offset_is_one_line_and_exit_2(tmp_path, text):
    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, "-m", "lab.rigs", "arduplane", "--start-offset", text, "--out", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert r.returncode == 2 and "--start-offset" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not out.exists()


def test_the_start_offset_names_another_flight():
    from lab.rigs import common

    base = ["arduplane", "--out", "x", "--config", "configs/bridge_arduplane_spline.yaml"]
    a = common.parser().parse_args(base)
    b = common.parser().parse_args([*base, "--start-offset", "300,0,0"])
    assert common.flight_name(a) != common.flight_name(b)


def test_the_capture_bound_is_distance_over_closing_speed_plus_a_turn_and_settling():
    from lab.rigs.capture import SETTLE_S, capture_bound_s

    cfg = load_config(ROOT / "configs" / "bridge_arduplane.yaml")
    # 22 m/s against 3 m/s; bank 35 - 5 deg with the 0.745 turn gain: R = 113.7 m
    r = 22.0**2 / (GRAVITY_M_S2 * 0.745 * math.tan(0.61 - 0.0873))
    assert capture_bound_s(cfg, 300.0) == pytest.approx(300.0 / 19.0 + 2 * math.pi * r / 22.0
                                                         + SETTLE_S)  # fmt: skip


@pytest.mark.slow
def test_a_capture_from_300_m_away_in_our_sil_keeps_the_floor_and_the_bank(tmp_path):
    """Our SIL (JSBSim X8 behind MAVLink, the real bridge), the ArduPlane spline, the aircraft
    300 m beyond the path's southern point flying south: the floor (the path's lowest point
    - 10 m) and the bank limit + 2 deg hold, and it captures within the stated bound; with the
    guards off the same start dives below that floor (measured: 70 m against 78 m)."""
    from lab.rigs.capture import row_figures

    cfg_path = ROOT / "configs" / "bridge_arduplane_spline.yaml"
    cfg = load_config(cfg_path)
    figs = {}
    for guards in ("true", "false"):
        out = tmp_path / guards
        r = subprocess.run(
            [sys.executable, "-m", "mpf_mavlink.cli", "sim", str(cfg_path), "--out", str(out),
             "--set", "sil.link=udp", "--set", "sim.duration_s=100",
             "--set", "kinematic.initial_position_ned_m=[-520,0,-100]",
             "--set", "kinematic.initial_attitude_rpy_rad=[0,0,3.14159]",
             "--set", f"guidance.capture_guards={guards}"],
            cwd=ROOT, capture_output=True, text=True, timeout=600,
        )  # fmt: skip
        assert (out / "bridge" / "metrics.json").is_file(), r.stdout[-2000:] + r.stderr[-2000:]
        figs[guards] = row_figures(out, cfg)
    on, off = figs["true"], figs["false"]
    assert on["start_m"] > 300.0
    assert on["lowest_alt_m"] >= on["floor_alt_m"], on
    assert on["bank_over_s"] <= 1.0 and on["verdict"] == "PASS", on
    assert off["lowest_alt_m"] < off["floor_alt_m"], off  # what the guards fix
    json.dumps(figs)


def test_the_capture_matrix_is_recorded_with_every_row_and_its_command():
    """docs/results/capture.md (scripts/capture-figures --record): the 12 rows of the matrix
    (both autopilots x circle, spline x away, below, above), each PASS, its guards-off rows,
    and the command that wrote it."""
    text = (ROOT / "docs" / "results" / "capture.md").read_text()
    assert "Command: `scripts/capture-figures" in text
    rows = [r for r in text.splitlines() if r.startswith(("| arduplane |", "| px4 |"))]
    on = [r for r in rows if r.split("|")[4].strip() == "on"]
    keys = {tuple(c.strip().split(" ")[0] for c in r.split("|")[1:4]) for r in on}
    assert len(on) == 12 and len(keys) == 12, on
    assert all(r.rstrip(" |").endswith("PASS") for r in on), on
    assert any(r.split("|")[4].strip() == "off" for r in rows)


def test_the_guards_name_exactly_the_bounds_that_changed_the_command():
    """guard_limited names (a) "sdot" iff the law's sdot was outside sdot_0 +- v_w, (b) "turn"
    iff |w3| was beyond the bank's turn-rate limit, and changes nothing it does not name; the
    envelope monitor shows these names to the user."""
    rng = np.random.default_rng(41)
    K_p, seen = 1.0, set()
    for _ in range(2000):
        veh, cmd, f1, wd1, pt_norm, pt_along, floor_d = _random_case(rng)
        diag = _diag(pt_norm, pt_along, f1, wd1)
        out, beta, limited = cap.guard_limited(cmd, diag, veh, floor_d, K_p, P)
        R, v = np.asarray(veh.R_W_I), veh.airspeed
        sdot_0 = cap.on_path_rate(cmd.sdot, K_p, pt_along, v, float(R[:, 0] @ f1),
                                  float(np.dot(wd1, f1)))  # fmt: skip
        assert ("sdot" in limited) == (abs(cmd.sdot - sdot_0) > v)
        assert ("turn" in limited) == (abs(cmd.w3) > cap.turn_rate_limit(v, R[2, 2], P))
        if "sdot" not in limited:
            assert out.sdot == cmd.sdot
        if "turn" not in limited:
            assert out.w3 == cmd.w3
        if not limited:
            assert (out.w2, out.w3, out.sdot) == (cmd.w2, cmd.w3, cmd.sdot)
        seen.update(limited)
    assert seen == {"sdot", "turn", "path"}  # the random cases reach every guard
