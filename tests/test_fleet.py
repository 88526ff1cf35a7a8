"""The fleet: the coordination law (pure), the ``fleet`` section, the DEBUG_VECT exchange."""

from __future__ import annotations

import math
import socket
import time
from collections import deque
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from mpf_mavlink.bridge.fleet import FleetMember, _Peer, report_name
from mpf_mavlink.config.scenario import build_path
from mpf_mavlink.config.schema import load_config
from mpf_mavlink.core.guidance import coordination as co
from mpf_mavlink.errors import ConfigError, MpfError

ROOT = Path(__file__).resolve().parents[1]
AP = ROOT / "configs" / "bridge_arduplane.yaml"
L150 = 2.0 * math.pi * 150.0  # the shipped circle's lap (m)


# -- the law -------------------------------------------------------------------------------
def _fly(k_c: float, delay_s: float, tau_v: float, t_end: float, compensate: bool = True):
    """Three aircraft on one lap: xi' = v, v' = (u_ref + du - v) / tau_v, each hearing the
    others' reports ``delay_s`` old (propagated with their sdot when ``compensate``)."""
    dt, u_ref, L = 0.05, 22.0, L150
    s = np.array([0.0, 40.0, -60.0])  # 40 m and 60 m out of the 0/120/240 slots
    slots = [0.0, 1 / 3, 2 / 3]
    s = s + np.array(slots) * L
    v = np.full(3, u_ref)
    hist: deque[tuple[float, np.ndarray, np.ndarray]] = deque()
    lag = round(delay_s / dt)
    errs = []
    for k in range(round(t_end / dt)):
        t = k * dt
        hist.append((t, s.copy(), v.copy()))
        t_r, s_r, v_r = hist[0] if len(hist) > lag else hist[0]
        if len(hist) > lag:
            hist.popleft()
        for i in range(3):
            peers = [
                co.PeerReport(slots[j], s_r[j], v_r[j] if compensate else 0.0, t_r)
                for j in range(3)
                if j != i
            ]
            e, _ = co.coordination_error_m(s[i], slots[i], peers, t, L)
            du = co.speed_correction(e, k_c, 3.0)
            v[i] += (u_ref + du - v[i]) * dt / tau_v
        s = s + v * dt
        xi = [co.xi_m(s[i], slots[i], L) for i in range(3)]
        errs.append(max(abs(co.wrap_m(xi[i] - xi[0], L)) for i in range(3)))
    return np.array(errs)


def test_converges_inside_the_condition() -> None:
    # k_c 0.05, N 3 (lambda 1.5), 0.5 s old reports at 5 Hz, tau_V 2 s: margin > 0, and the
    # linear decay rate k_c lambda = 0.075 /s takes 60 m to ~0.7 m in 60 s beyond a ~20 s lag
    assert co.convergence_margin(0.05, 3, 5.0, 0.5, 2.0) > 0.0
    err = _fly(0.05, 0.5, 2.0, 160.0)
    assert err[0] == pytest.approx(60.0, abs=1.5)  # the worst start offset, against aircraft 0
    assert err[-1] < 0.5


def test_diverges_outside_the_condition_and_compensation_saves_it() -> None:
    # k_c 1 on 2 s old reports: k_c lambda tau = 1 * 1.5 * 2.1 = 3.2 > pi/2 (the delayed
    # consensus' bound): uncompensated, a sustained oscillation (bounded by du_max), never a
    # formation; propagated with the peers' sdot the same reports converge
    assert co.convergence_margin(1.0, 3, 10.0, 2.0, 0.1) < 0.0
    err = _fly(1.0, 2.0, 0.1, 120.0, compensate=False)
    assert err[-400:].max() > 5.0
    assert _fly(1.0, 2.0, 0.1, 120.0, compensate=True)[-1] < 0.1


def test_delay_compensation() -> None:
    # a 2 s old report of a peer at 22 m/s is 44 m behind where the peer is: compensated, the
    # error is the slot error alone (0); uncompensated it is the 44 m of travel
    rep = co.PeerReport(1 / 3, L150 / 3 - 44.0, 22.0, 98.0)
    e, n = co.coordination_error_m(0.0, 0.0, [rep], 100.0, L150)
    assert n == 1 and e == pytest.approx(0.0, abs=1e-9)
    rep0 = co.PeerReport(1 / 3, L150 / 3 - 44.0, 0.0, 98.0)
    e0, _ = co.coordination_error_m(0.0, 0.0, [rep0], 100.0, L150)
    assert e0 == pytest.approx(44.0)


def test_correction_is_bounded_and_smooth() -> None:
    for e in (-1e6, -500.0, -1.0, 0.0, 1.0, 500.0, 1e6):
        du = co.speed_correction(e, 0.05, 2.5)
        assert abs(du) <= 2.5
    # slope -k_c at the origin: 1 m of error asks for 0.05 m/s (tanh(0.02) = 0.019997)
    assert co.speed_correction(1.0, 0.05, 2.5) == pytest.approx(-0.05, rel=2e-4)
    assert co.wrap_m(L150 - 1.0, L150) == pytest.approx(-1.0)


def test_airspeed_feed_forward() -> None:
    # 22 m/s along a north tangent with the path point moving 3 m/s east: |(22, 3, 0)|
    assert co.airspeed_for(22.0, (1, 0, 0), (0, 3, 0), (0, 0, 0)) == pytest.approx(
        math.hypot(22.0, 3.0)
    )
    # tangent east, target east: 22 + 3; a 5 m/s wind blowing east takes 5 off
    assert co.airspeed_for(22.0, (0, 1, 0), (0, 3, 0), (0, 5, 0)) == pytest.approx(20.0)
    f = co.feasibility([(0, 1, 0), (0, -1, 0)], [(0, 3, 0)] * 2, (0, 0, 0), 22.0, 1.0)
    assert (f.lo, f.hi, f.lo_full, f.hi_full) == pytest.approx((19.0, 25.0, 18.0, 26.0))


def test_respace() -> None:
    assert co.respaced_slots([0.0, 1 / 3, 2 / 3], [True, False, True]) == [0.0, None, 0.5]
    assert co.respaced_slots([0.0, 1 / 3, 2 / 3], [False, True, True]) == pytest.approx(
        [None, 1 / 3, 1 / 3 + 0.5]
    )


# -- the section ---------------------------------------------------------------------------
def _cfg(*sets: str):
    return load_config(AP, ["fleet.enabled=true", *sets])


def test_config_errors() -> None:
    links = 'fleet.links=["udpin:127.0.0.1:14600"]'
    with pytest.raises(ConfigError, match=r"fleet.slots_deg\[2\]: 480 deg is member 1's slot"):
        _cfg("fleet.slots_deg=[0,120,480]", links)
    with pytest.raises(ConfigError, match="fleet.member: 3 but only 3 slots"):
        _cfg("fleet.slots_deg=[0,120,240]", "fleet.member=3", links)
    with pytest.raises(ConfigError, match="fleet.links"):
        _cfg("fleet.slots_deg=[0,180]")
    with pytest.raises(ConfigError, match="fleet.on_peer_lost"):
        _cfg("fleet.slots_deg=[0,180]", links, "fleet.on_peer_lost=land")
    with pytest.raises(ConfigError, match="fleet.slots_deg: a fleet needs at least 2"):
        _cfg("fleet.slots_deg=[0]", links)


# -- the exchange --------------------------------------------------------------------------
def _ports(n: int) -> list[int]:
    out, socks = [], []
    for _ in range(n):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        out.append(s.getsockname()[1])
        socks.append(s)
    for s in socks:
        s.close()
    return out


class _Clock:
    def __init__(self) -> None:
        self.t = time.time()

    def __call__(self) -> float:
        return self.t


def _pair(
    extra_b: tuple[str, ...] = (),
    signing: tuple[bytes | None, bytes | None] = (None, None),
    extra: tuple[str, ...] = (),
):
    pa, pb = _ports(2)
    clock = _Clock()
    members = []
    for k, (mine, theirs) in enumerate(((pa, pb), (pb, pa))):
        sets = [
            "fleet.slots_deg=[0,180]", f"fleet.member={k}",
            f'fleet.links=["udpin:127.0.0.1:{mine}","udpout:127.0.0.1:{theirs}"]',
        ]  # fmt: skip
        if k == 1:
            sets += list(extra_b)
        cfg = _cfg(*sets, *extra)
        key = signing[k]
        m = FleetMember(cfg, build_path(cfg.path), lambda _t: None, clock,
                        (key, k) if key is not None else None)  # fmt: skip
        m.open()
        members.append(m)
    return members[0], members[1], clock


def _vs_tgt():
    vs = SimpleNamespace(wind=np.zeros(3), airspeed=22.0, R_W_I=np.eye(3))
    tgt = SimpleNamespace(R_T_I=np.eye(3), omega_T=np.zeros(3), velocity=np.array([0.0, 3.0, 0]))
    return vs, tgt


def _settle(*ms: FleetMember) -> None:
    time.sleep(0.05)
    for m in ms:
        m.poll()


def test_exchange_encode_decode_and_the_law() -> None:
    a, b, clock = _pair()
    vs, tgt = _vs_tgt()
    try:
        # b 10 m ahead of its slot (half a lap from a): a must speed up, b slow down
        a.step(0.0, 0.0, 22.0, vs, tgt)
        b.step(0.0, L150 / 2 + 10.0, 22.0, vs, tgt)
        _settle(a, b)
        assert a.n.accepted == 1 and b.n.accepted == 1
        rep = b.peers[a.f.link_sysid].report
        assert rep is not None and (rep.s_m, rep.sdot_m_s, rep.slot) == (0.0, 22.0, 0.0)
        clock.t += 0.5  # both at 22 m/s for 0.5 s: the propagated peer is 11 m on
        a.lp.y = b.lp.y = None
        a.step(0.5, 11.0, 22.0, vs, tgt)
        b.step(0.5, L150 / 2 + 21.0, 22.0, vs, tgt)
        # a's error -10 m (behind): du = 2.5 tanh(0.2 * 10 / 2.5) = +1.6600 m/s; b's -1.6600
        assert a.last["e_m"] == pytest.approx(-10.0, abs=1e-3)
        assert a.last["du_m_s"] == pytest.approx(2.5 * math.tanh(0.8), abs=1e-4)
        assert b.last["du_m_s"] == pytest.approx(-2.5 * math.tanh(0.8), abs=1e-4)
        assert report_name(a.pid) == "MPF" + a.pid and len(a.name) == 10
    finally:
        a.close()
        b.close()


def test_out_of_order_and_timeout() -> None:
    a, b, clock = _pair()
    vs, tgt = _vs_tgt()
    try:
        t0 = clock.t
        a.send(100.0, 22.0, t0)
        a.send(50.0, 22.0, t0 - 1.0)  # older than the one before it: discarded
        a.send(100.0, 22.0, t0)  # a duplicate: discarded
        _settle(b)
        assert b.n.accepted == 1 and b.n.stale_or_reordered == 2
        clock.t = t0 + 3.5  # silent beyond peer_timeout_s 3
        b.step(3.5, 0.0, 22.0, vs, tgt)
        assert b.last["n_peers"] == 0.0 and b.n.peers_lost == 1
    finally:
        a.close()
        b.close()


def test_path_mismatch_and_same_slot_refused() -> None:
    a, b, _ = _pair(("path.radius_m=160",))
    try:
        a.send(0.0, 22.0, time.time())
        _settle(b)
        assert b.n.other_path == 1 and b.n.accepted == 0
    finally:
        a.close()
        b.close()
    a, b, _ = _pair(("fleet.slots_deg=[180,0]", "fleet.member=1"))  # b claims a's slot 0
    try:
        b.send(0.0, 22.0, time.time())
        _settle(a)
        assert a.n.same_slot == 1 and a.n.accepted == 0
    finally:
        a.close()
        b.close()


def test_signed_exchange(tmp_path: Path) -> None:
    key = bytes(range(32))
    a, b, _ = _pair(signing=(key, key))
    try:
        a.send(0.0, 22.0, time.time())
        _settle(b)
        assert b.n.accepted == 1
    finally:
        a.close()
        b.close()
    a, b, _ = _pair(signing=(None, key))  # a unsigned, b signing: a's reports are dropped
    try:
        a.send(0.0, 22.0, time.time())
        _settle(b)
        assert b.n.accepted == 0
    finally:
        a.close()
        b.close()


def test_bad_link_url_is_one_line() -> None:
    cfg = _cfg("fleet.slots_deg=[0,180]", 'fleet.links=["bogus:1"]')
    m = FleetMember(cfg, build_path(cfg.path), lambda _t: None)
    with pytest.raises(MpfError, match="bogus"):
        m.open()


def test_rig_spacing_figures() -> None:
    """The rig's judge (lab/rigs/fleet.py) on synthetic tracks: three members at 22 m/s, the
    third 30 m behind its slot until t = 50 s, then on it: converged at 50 s (the first grid
    instant after the last one beyond 10 m), RMS and max 0 after; after member 1 stops (t 80 s)
    the two survivors are judged against 180 deg (respace): member 2 is 120 deg from member 0
    where 180 is wanted, L/6 = 157 m."""
    from lab.rigs.fleet import spacing_figures, spacing_series

    t = np.arange(0.0, 120.0, 0.1)
    L = L150
    s0 = 22.0 * t
    s1 = 22.0 * t + L / 3
    s2 = 22.0 * t + 2 * L / 3 - np.where(t < 50.0, 30.0, 0.0)
    tracks = [{"t_unix_s": t, "s_m": s} for s in (s0, s1, s2)]
    tracks[1] = {"t_unix_s": t[t < 80.0], "s_m": s1[t < 80.0]}
    ser = spacing_series(tracks, [0.0, 1 / 3, 2 / 3], L, True)  # type: ignore[arg-type]
    f = spacing_figures(ser, 0.0, 79.0, 10.0, 3)
    assert f["converged"] and f["converge_s"] == pytest.approx(50.0, abs=0.5)
    assert f["spacing_rms_m"] == pytest.approx(0.0, abs=1e-6)
    assert f["start_spread_worst_m"] == pytest.approx(30.0, abs=1e-6)
    after = spacing_figures(ser, 81.0, 200.0, 10.0, 2)
    assert not after["converged"] and after["worst_at_end_m"] == pytest.approx(L / 6, abs=0.5)


def test_fleet_csv_is_written_as_the_flight_goes(tmp_path: Path) -> None:
    """A SIGKILLed bridge never reaches write(): its rows must be on disk already."""
    a, b, clock = _pair()
    vs, tgt = _vs_tgt()
    try:
        a.record.path = tmp_path / "fleet.csv"
        a.step(0.0, 0.0, 22.0, vs, tgt)  # the first row is flushed at once
        lines = (tmp_path / "fleet.csv").read_text().splitlines()
        assert lines[0].startswith("t_unix_s,") and len(lines) == 2
        a.write(tmp_path)
        assert len((tmp_path / "fleet.csv").read_text().splitlines()) == 2
    finally:
        a.close()
        b.close()


# -- spacing in time -----------------------------------------------------------------------
def _nu_circle(theta: float, v_air: float, vx: float) -> float:
    """The along-path speed on a counter-clockwise circle at angle theta (f1 = (-sin, cos)) of
    an aircraft at v_air over a point moving at vx north, written out: the positive root of
    nu^2 - 2 nu vx sin(theta) + vx^2 - v_air^2 = 0."""
    b = -vx * math.sin(theta)
    return -b + math.sqrt(b * b - vx * vx + v_air * v_air)


def test_along_path_speed_is_the_root_of_the_airspeed() -> None:
    # the point moving forward along the path at 3 m/s: 16 m/s of air is 13 along the path
    assert co.along_path_speed(16.0, (1.0, 0.0, 0.0), (3.0, 0.0, 0.0), (0.0, 0.0, 0.0)) == 13.0
    # a 4 m/s headwind on a still point: the aircraft makes 12 m/s along the path
    assert co.along_path_speed(16.0, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), (-4.0, 0.0, 0.0)) == 12.0
    # the point outruns the airspeed across the path: no speed holds the aircraft on it
    assert math.isnan(co.along_path_speed(5.0, (1.0, 0.0, 0.0), (0.0, 6.0, 0.0), (0, 0, 0)))
    # and it is what airspeed_for inverts
    f1, vp, w = (0.6, 0.8, 0.0), (1.0, -2.0, 0.5), (3.0, 1.0, 0.0)
    nu = co.along_path_speed(17.0, f1, vp, w)
    assert co.airspeed_for(nu, f1, vp, w) == pytest.approx(17.0, rel=1e-12)


def test_lap_clock_against_quadrature() -> None:
    """On a circle of 150 m about a point moving at 3 m/s, at 16 m/s of air: the lap time and
    tau(s) of the lap clock against scipy's quadrature of 1/nu written out. The trapezoid on a
    smooth periodic integrand is exact to rounding for the lap; shat in between is a linear
    interpolation of tau, off by at most h^2/8 max|shat''| (h the grid's step)."""
    from scipy.integrate import quad

    cfg = _cfg("fleet.slots_deg=[0,180]", 'fleet.links=["udpin:127.0.0.1:14600"]')
    path = build_path(cfg.path)
    R, L = float(cfg.path.radius_m), float(path.length)
    lap = co.LapClock(path, 256)
    # the path's own tangent decides the sense: theta(s) = theta0 + sign s / R
    p0, f0 = (np.asarray(x, float) for x in path.eval(0.0)[:2])
    theta0 = math.atan2(p0[1], p0[0])
    sign = 1.0 if np.dot(f0, (-math.sin(theta0), math.cos(theta0), 0.0)) > 0 else -1.0
    vx, V = 3.0, 16.0
    assert lap.update(np.eye(3), (vx, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), V)

    def inv_nu(s: float) -> float:
        th = theta0 + sign * s / R
        return 1.0 / _nu_circle(th, V, vx) if sign > 0 else 1.0 / _nu_circle(-th, V, -vx)

    T = quad(inv_nu, 0.0, L, limit=200, epsabs=1e-12)[0]
    assert lap.lap_s == pytest.approx(T, rel=1e-9)
    # shat's nodes are a cumulative trapezoid of f = 1/nu (error <= h^2/12 |f'(s) - f'(0)|) and
    # linearly interpolated between (<= h^2/8 max|f'|), both times L/T
    ss = np.linspace(0.0, L, 4001)
    f = np.array([inv_nu(float(x)) for x in ss])
    df = float(np.max(np.abs(np.gradient(f, ss))))
    h = L / 256
    bound = (L / T) * df * h * h * (2.0 / 12.0 + 1.0 / 8.0)
    for s in (37.0, 250.0, 471.2, 900.0, L + 100.0):
        tau = quad(inv_nu, 0.0, s, limit=200, epsabs=1e-12)[0]
        assert lap.shat(s) == pytest.approx(L * tau / T, abs=bound)
    # the equal-time coordinate: half a lap of shat is half the lap's time, not half the path
    s_half = float(np.interp(0.5 * L, lap.shat_grid, lap.s))
    assert quad(inv_nu, 0.0, s_half)[0] == pytest.approx(0.5 * T, abs=h * float(f.max()))
    assert abs(s_half - 0.5 * L) > 10.0  # at 3 m/s of 16 the two halves differ by tens of m


def test_time_spacing_law_on_shat() -> None:
    # two members half a lap apart in shat: no correction; 5 s of lap time late: speed up by
    # k_c shat-error (m) through tanh, in airspeed (the lap clock's own figures)
    clock = _Clock()
    cfg_a = _cfg("fleet.slots_deg=[0,180]", 'fleet.links=["udpin:127.0.0.1:14600"]',
                 "fleet.spacing=time")  # fmt: skip
    m = FleetMember(cfg_a, build_path(cfg_a.path), lambda _t: None, clock)
    vs, tgt = _vs_tgt()
    lap = m.lap
    assert lap is not None
    m.step(0.0, 0.0, 20.0, vs, tgt)  # fills the table for this target and wind
    s_peer = float(np.interp(0.5 * lap.L, lap.shat_grid, lap.s))  # half a lap of time on
    m.peers[7] = fl_peer = _Peer(7, 180.0)
    fl_peer.report = co.PeerReport(0.5, s_peer, 0.0, clock.t)
    fl_peer.last_rx = clock.t
    m.lp.y = None
    m.step(0.0, 0.0, 20.0, vs, tgt)
    assert m.last["e_m"] == pytest.approx(0.0, abs=1e-6)
    assert m.last["airspeed_sp_m_s"] == pytest.approx(m.params.u_ref_m_s)
    m.lp.y = None
    s_late = float(np.interp(-5.0 * lap.L / lap.lap_s % lap.L, lap.shat_grid, lap.s))
    m.step(0.0, s_late - lap.L, 20.0, vs, tgt)
    e = -5.0 * lap.L / lap.lap_s
    assert m.last["e_m"] == pytest.approx(e, abs=1e-6)
    du = -m.f.du_max_m_s * math.tanh(m.f.k_c * e / m.f.du_max_m_s)
    assert m.last["airspeed_sp_m_s"] == pytest.approx(min(m.params.u_ref_m_s + du, m.window[1]))


def test_time_spacing_checks_on_the_demo() -> None:
    """configs/fleet_demo.yaml: a common along-path speed fails fleet_speed (10-25 m/s of air
    asked), spacing in time passes; its convergence condition carries the lap clock's gain
    factor g, so without the along-path speed loop k_c = 0.2 (the path spacing's default) fails
    where 0.1 passes; with it (the demo's k_v 1) the margin is the phase criterion's, and 0.3
    fails."""
    from mpf_mavlink.cli.main import main

    demo = str(Path(__file__).resolve().parents[1] / "configs" / "fleet_demo.yaml")
    assert main(["check", demo]) == 0
    assert main(["check", demo, "--set", "fleet.spacing=path"]) == 3
    off = ["--set", "fleet.ground_speed_gain=0"]
    assert main(["check", demo, *off]) == 0
    assert main(["check", demo, *off, "--set", "fleet.k_c=0.2"]) == 3
    assert main(["check", demo, "--set", "fleet.k_c=0.3"]) == 3
    assert main(["check", demo, "--set", "fleet.ground_speed_gain=1.5"]) == 3  # small gain


def test_sil_fleet_refuses_bad_arguments_in_one_line(tmp_path: Path, capsys) -> None:
    from lab.rigs.sil_fleet import main

    with pytest.raises(SystemExit) as e:
        main(["--out", str(tmp_path / "x"), "--seeds", "1,a"])
    assert e.value.code == 2 and "--seeds '1,a'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["--out", str(tmp_path / "x"), "--n", "1"])
    assert e.value.code == 2 and not (tmp_path / "x").exists()  # nothing left behind


def test_time_spacing_judge_from_the_records() -> None:
    # three members at one constant speed, a third of a lap apart in time, one of them 2 s
    # late: the pairs around it are -/+ 2 s x L/T off, the third pair on its slot
    from lab.rigs.sil_fleet import time_spacing_series

    L, v, T = 900.0, 15.0, 60.0
    t = np.arange(0.0, 200.0, 0.05)
    late = (0.0, 2.0, 0.0)
    tracks = [{"t_unix_s": t, "s_m": v * (t - late[k]) + k * L / 3.0} for k in range(3)]
    ser = time_spacing_series(tracks, [0.0, 1 / 3, 2 / 3], L)
    ok = ser["n_alive"] == 3
    assert ok.sum() > 100  # judged once every member has flown a lap
    i = int(np.flatnonzero(ok)[-1])
    errs = sorted(ser["pairs"][i])
    assert errs == pytest.approx([-2.0 * L / T, 0.0, 2.0 * L / T], abs=1e-6)


# -- the along-path speed loop (spacing in time, fleet.ground_speed_gain) ----------------------
def test_along_path_slope_is_the_derivative() -> None:
    # d nu / dV against a central difference of along_path_speed: its error is h^2/6 |nu'''|,
    # below 1e-7 at h = 1e-3 m/s for these speeds (nu''' ~ |d|^2 / V^4 < 1e-2); calm air over
    # a still point: 1 exactly; crabbing into a 4 m/s crosswind: 1 / cos(crab) = V / nu
    f1, vp, w = (0.6, 0.8, 0.0), (1.0, -2.0, 0.5), (3.0, 1.0, 0.0)
    V, h = 16.0, 1e-3
    nu = co.along_path_speed(V, f1, vp, w)
    fd = (co.along_path_speed(V + h, f1, vp, w) - co.along_path_speed(V - h, f1, vp, w)) / (2 * h)
    assert co.along_path_slope(nu, V, f1, vp, w) == pytest.approx(fd, abs=1e-7)
    assert co.along_path_slope(16.0, 16.0, (1.0, 0, 0), (0, 0, 0), (0, 0, 0)) == 1.0
    nu_x = co.along_path_speed(16.0, (1.0, 0, 0), (0, 0, 0), (0.0, 4.0, 0))
    assert nu_x == pytest.approx(math.sqrt(16.0**2 - 16.0))
    slope = co.along_path_slope(nu_x, 16.0, (1.0, 0, 0), (0, 0, 0), (0.0, 4.0, 0))
    assert slope == pytest.approx(16.0 / nu_x, rel=1e-12)


def test_ground_speed_loop_gain_and_filter() -> None:
    # a constant along-path speed error err: du_v -> -k_v err / slope with the filter's time
    # constant (1 - e^-1 of it after tau, exact for the discrete exp filter); a non-finite
    # sample holds the last output
    loop = co.GroundSpeedLoop(0.8, 2.0)
    err, slope, dt = 1.5, 1.2, 0.02
    out = [loop(err, slope, dt) for _ in range(round(2.0 / dt) + 1)]
    final = -0.8 * err / slope
    assert out[0] == pytest.approx(final)  # the filter starts at its first sample
    loop = co.GroundSpeedLoop(0.8, 2.0)
    loop(0.0, slope, dt)
    out = [loop(err, slope, dt) for _ in range(round(2.0 / dt))]
    assert out[-1] == pytest.approx(final * (1.0 - math.exp(-1.0)), rel=1e-9)
    assert loop(math.nan, slope, dt) == out[-1]
    assert loop(err, math.nan, dt) == out[-1]
    # beyond the window's span of along-path speed (a capture's sdot): nothing, filter reset
    assert loop(30.0, slope, dt, span_m_s=3.6) == 0.0 and loop.lp.y is None
    assert loop(err, slope, dt, span_m_s=3.6) == pytest.approx(final)


def test_inner_loop_response() -> None:
    """H = G (1 + k F) / (1 + k F G): DC gain 1; k 0 is the speed lag G itself; its group delay
    at 0 Hz is tau_V / (1 + k) (the filter's lag cancels between the zero and the poles), read
    from the phase at omega 1e-4 (the next term of the phase is O(omega^3 tau^3): < 1e-9 here)."""
    w = np.array([1e-4, 0.1, 1.0])
    G = 1.0 / (4.0j * w + 1.0)
    assert np.allclose(co.inner_loop_response(w, 0.0, 1.0, 4.0), G, rtol=1e-12)
    for k in (0.5, 1.0):
        H = co.inner_loop_response(np.array([0.0, 1e-4]), k, 1.0, 4.0)
        assert H[0] == pytest.approx(1.0)
        assert -np.angle(H[1]) / 1e-4 == pytest.approx(4.0 / (1.0 + k), rel=1e-6)


def test_consensus_phase_margin_is_the_closed_form_with_no_inner_loop() -> None:
    # H = 1: the mode K e^{-s tau} / s crosses |L| = 1 at omega = K, where its margin is
    # pi/2 - K tau; the grid's step (ratio r = 10^(6/20000)) can put the last point at most
    # K (r - 1) short of it, hence a tolerance tau K (r - 1)
    r = 10.0 ** (6.0 / 20000.0)
    for K, tau in ((0.27, 1.2), (0.5, 3.0), (0.1, 5.2)):
        pm = co.consensus_phase_margin(K, tau)
        assert pm == pytest.approx(0.5 * math.pi - K * tau, abs=tau * K * (r - 1.0) + 1e-12)


def _fly_inner(
    K_c: float,
    k_v: float,
    t_end: float,
    d: tuple[float, float, float],
    tau_v: float = 4.0,
    tau_f: float = 1.0,
    delay_s: float = 1.2,
    dt: float = 0.01,
):
    """Three aircraft, all-to-all: xi_i' = v_i + d_i, v_i' = (c_i - v_i) / tau_v (the speed
    lag), c_i = -K_c e_i(t - delay) - k_v y_i, y_i' = (v_i + d_i - (-K_c e_i) - y_i) / tau_f (the
    filtered along-path speed error against what the consensus asked): the linear model
    GroundSpeedLoop and the consensus make (gain factor g and slope 1)."""
    n = round(t_end / dt)
    lag = round(delay_s / dt)
    xi = np.array([30.0, -10.0, -20.0])
    v = np.zeros(3)
    y = np.zeros(3)
    dd = np.array(d)
    hist = [xi.copy()] * (lag + 1)
    out = np.zeros((n, 3))
    for k in range(n):
        old = hist[-lag - 1]
        e = np.array([np.mean([old[i] - old[j] for j in range(3) if j != i]) for i in range(3)])
        c_e = -K_c * e
        c = c_e - k_v * y
        y += (v + dd - c_e - y) * dt / tau_f
        v += (c - v) * dt / tau_v
        xi = xi + (v + dd) * dt
        hist.append(xi.copy())
        hist = hist[-lag - 1 :]
        out[k] = [np.mean([xi[i] - xi[j] for j in range(3) if j != i]) for i in range(3)]
    return out


def test_inner_loop_divides_a_steady_disturbance_and_keeps_convergence() -> None:
    """A steady along-path speed disturbance d on one aircraft (a gust it rides, the energy
    control's airspeed offset): the consensus alone holds e_1 = d (2/3) / (K_c lambda) with
    lambda = 3/2; the inner loop divides it by 1 + k_v (its DC rejection; the derivation in
    GroundSpeedLoop). Euler at 10 ms on dynamics of >= 1 s: 1 % of the figure."""
    K_c = 0.1 * 1.81  # the demo's k_c times its largest gain factor
    d = (0.6, 0.0, 0.0)
    e_off = _fly_inner(K_c, 0.0, 400.0, d)[-1]
    e_on = _fly_inner(K_c, 1.0, 400.0, d)[-1]
    # steady: every xi' equal, v_i = -K_c e_i, sum e_i = 0: -K_c e_1 + d = K_c e_1 / 2
    want = d[0] / (K_c * 1.5)
    assert e_off[0] == pytest.approx(want, rel=0.01)
    assert e_on[0] == pytest.approx(want / 2.0, rel=0.01)


def test_phase_criterion_boundary_in_the_time_domain() -> None:
    """The check's criterion at k_v 1 through the speed lag and 1.2 s of delay: where its margin
    is positive (the demo's K, 0.9 of the boundary) the consensus converges, at 1.1 of it the
    error grows (one gain crossover here, so the criterion is also necessary). Read from the
    envelope of the last 50 s against the 50 s before 100 s earlier; 10 % either side of the
    boundary is the criterion's grid (1 %) and the 10 ms Euler step's phase (~ omega dt / 2 at
    the 0.5 rad/s crossover, 0.25 %) with room."""
    H = lambda w: co.inner_loop_response(w, 1.0, 1.0, 4.0)  # noqa: E731
    Ks = np.linspace(0.3, 1.5, 121)
    pms = np.array([co.consensus_phase_margin(K * 1.5, 1.2, H) for K in Ks])
    K_star = float(Ks[np.argmax(pms < 0.0)])  # K_c (before lambda 1.5) at the boundary
    assert co.consensus_phase_margin(0.1 * 1.81 * 1.5, 1.2, H) > 0.0
    for frac, grows in ((0.1 * 1.81 / K_star, False), (0.9, False), (1.1, True)):
        e = _fly_inner(frac * K_star, 1.0, 300.0, (0.0, 0.0, 0.0))
        before = np.max(np.abs(e[15000:20000]))
        late = np.max(np.abs(e[25000:30000]))
        assert bool(late > before) is grows, (frac, before, late)


def test_member_takes_the_along_path_speed_error_off_the_set_point() -> None:
    # e 0 (the peer half a lap on in lap time), the aircraft 1.2 m/s faster along the path than
    # u_ref gives where it is: after 20 filter time constants (e^-20 left) the set-point is
    # u_ref - k_v 1.2 / slope
    clock = _Clock()
    cfg = _cfg("fleet.slots_deg=[0,180]", 'fleet.links=["udpin:127.0.0.1:14600"]',
               "fleet.spacing=time", "fleet.ground_speed_gain=0.7", "fleet.ground_speed_tau_s=0.5",
               "fleet.du_max_m_s=3")  # fmt: skip
    m = FleetMember(cfg, build_path(cfg.path), lambda _t: None, clock)
    vs, tgt = _vs_tgt()
    lap = m.lap
    assert lap is not None and m.gs is not None
    m.step(0.0, 0.0, 20.0, vs, tgt)
    s_peer = float(np.interp(0.5 * lap.L, lap.shat_grid, lap.s))
    m.peers[7] = p = _Peer(7, 180.0)
    from mpf_mavlink.bridge.fleet import _wind, path_motion

    f1, vp = path_motion(m.path, 0.0, tgt)
    u = m.params.u_ref_m_s
    nu = co.along_path_speed(u, f1, vp, _wind(vs))
    for _ in range(200):
        clock.t += 0.05
        p.report = co.PeerReport(0.5, s_peer, 0.0, clock.t)
        p.last_rx = clock.t
        m.step(0.0, 0.0, nu + 1.2, vs, tgt)
    assert m.last["e_m"] == pytest.approx(0.0, abs=1e-6)
    slope = co.along_path_slope(nu, u, f1, vp, _wind(vs))
    assert m.last["du_v_m_s"] == pytest.approx(-0.7 * 1.2 / slope, rel=1e-6)
    assert m.last["airspeed_sp_m_s"] == pytest.approx(u - 0.7 * 1.2 / slope, rel=1e-6)


def test_member_counts_a_correction_its_bound_clips() -> None:
    # the same along-path speed error as above (du_v ~ -0.84 m/s) against du_max 0.3: the
    # set-point is u_ref - 0.3 and every step that clipped is counted, none silently
    clock = _Clock()
    cfg = _cfg("fleet.slots_deg=[0,180]", 'fleet.links=["udpin:127.0.0.1:14600"]',
               "fleet.spacing=time", "fleet.ground_speed_gain=0.7", "fleet.ground_speed_tau_s=0.5",
               "fleet.du_max_m_s=0.3")  # fmt: skip
    m = FleetMember(cfg, build_path(cfg.path), lambda _t: None, clock)
    vs, tgt = _vs_tgt()
    lap = m.lap
    assert lap is not None
    m.step(0.0, 0.0, 20.0, vs, tgt)
    s_peer = float(np.interp(0.5 * lap.L, lap.shat_grid, lap.s))
    m.peers[7] = p = _Peer(7, 180.0)
    from mpf_mavlink.bridge.fleet import _wind, path_motion

    f1, vp = path_motion(m.path, 0.0, tgt)
    u = m.params.u_ref_m_s
    nu = co.along_path_speed(u, f1, vp, _wind(vs))
    for _ in range(200):
        clock.t += 0.05
        p.report = co.PeerReport(0.5, s_peer, 0.0, clock.t)
        p.last_rx = clock.t
        m.step(0.0, 0.0, nu + 1.2, vs, tgt)
    assert m.last["airspeed_sp_m_s"] == pytest.approx(u - 0.3, rel=1e-9)
    # past the filter's first time constant (0.5 s = 10 steps) |du_v| > 0.3 at every step
    assert m.n.extra.get("correction_clipped", 0) >= 190


def test_lap_wind_averages_gusts_not_the_wind() -> None:
    """LapWind: the running mean of the first estimates (exact, to rounding) while that weighs
    the newest more than the low-pass (n + 1 < 1 / (1 - e^(-dt/tau)), ~500 at 0.2 s and
    100 s), then the low-pass: a gust of period P attenuated to 1 / sqrt(1 + (2 pi tau / P)^2)
    (the continuous filter; the 0.2 s step changes it by O(dt / P) = 1 %: tolerance 2 %)."""
    lw = co.LapWind(100.0)
    xs = [0.3, -1.2, 2.0, 0.5, 0.1]
    out = (0.0, 0.0, 0.0)
    for x in xs:
        out = lw((x, 4.0, 0.0), 0.2)
    assert out[0] == pytest.approx(sum(xs) / len(xs), abs=1e-12)
    assert out[1] == pytest.approx(4.0)
    assert lw((math.nan, 0.0, 0.0), 0.2) == out  # a non-finite estimate: the last average
    P, tau, dt = 20.0, 100.0, 0.2
    lw = co.LapWind(tau)
    ys = [lw((math.sin(2 * math.pi * k * dt / P), 0.0, 0.0), dt)[0] for k in range(20000)]
    amp = max(abs(y) for y in ys[-1000:])
    assert amp == pytest.approx(1.0 / math.sqrt(1.0 + (2 * math.pi * tau / P) ** 2), rel=0.02)


def test_member_lap_clock_uses_the_averaged_wind() -> None:
    # a 2 m/s gust in the estimate for one report period after 50 calm ones: the lap clock
    # moves by the average's share of it (1/51), not by the gust
    clock = _Clock()
    cfg = _cfg("fleet.slots_deg=[0,180]", 'fleet.links=["udpin:127.0.0.1:14600"]',
               "fleet.spacing=time")  # fmt: skip
    m = FleetMember(cfg, build_path(cfg.path), lambda _t: None, clock)
    vs, tgt = _vs_tgt()
    lap = m.lap
    assert lap is not None
    for _ in range(50):
        m.step(0.0, 0.0, 20.0, vs, tgt)
        clock.t += 0.2
    T0 = lap.lap_s
    gust = SimpleNamespace(wind=np.array([2.0, 0.0, 0.0]), airspeed=22.0, R_W_I=np.eye(3))
    m.step(0.0, 0.0, 20.0, gust, tgt)
    want = co.LapClock(m.path)  # the 51st estimate, in the running mean (no peer's wind heard)
    w = (2.0 / 51.0, 0.0, 0.0)
    assert want.update(tgt.R_T_I, tgt.velocity, tgt.omega_T, w, m.params.u_ref_m_s)
    assert lap.lap_s == pytest.approx(want.lap_s, rel=1e-9)
    assert abs(lap.lap_s - T0) < 0.01 * T0


def test_members_share_their_averaged_wind_for_one_lap_clock() -> None:
    # a's estimate (1, 0, 0), b's (-1, 2, 0) m/s: once each has heard the other (DEBUG_VECT
    # "MPW" + path id, x y z the average), both lap clocks are in the mean (0, 1, 0), exactly
    a, b, clock = _pair(extra=("fleet.spacing=time",))
    tgt = _vs_tgt()[1]
    va = SimpleNamespace(wind=np.array([1.0, 0.0, 0.0]), airspeed=22.0, R_W_I=np.eye(3))
    vb = SimpleNamespace(wind=np.array([-1.0, 2.0, 0.0]), airspeed=22.0, R_W_I=np.eye(3))
    try:
        a.step(0.0, 0.0, 22.0, va, tgt)
        b.step(0.0, L150 / 2, 22.0, vb, tgt)
        assert a.wind.lap == (1.0, 0.0, 0.0)  # nobody heard yet: its own
        _settle(a, b)
        clock.t += 0.25
        a.step(0.25, 5.0, 22.0, va, tgt)
        b.step(0.25, L150 / 2 + 5.0, 22.0, vb, tgt)
        for m in (a, b):
            assert m.n.extra["wind_rx"] == 1
            assert m.wind.lap == pytest.approx((0.0, 1.0, 0.0), abs=1e-12)
        want = co.LapClock(a.path)
        assert want.update(tgt.R_T_I, tgt.velocity, tgt.omega_T, (0.0, 1.0, 0.0), 22.0)
        assert a.lap is not None and b.lap is not None
        assert a.lap.lap_s == pytest.approx(want.lap_s, rel=1e-12) == b.lap.lap_s
    finally:
        a.close()
        b.close()
