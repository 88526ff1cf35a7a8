"""The rig's firmware-guidance flights and head-to-head figures without firmware (lab/rigs/
native.py, figures.moving_path_figures, worlds.py), and issue 40 item 4's rig pieces: the
config's target as written, unique flight names, ATTITUDE rate from the tlog, a refused SIL
leg's reason. The flights themselves: tests/test_sitl_arduplane.py, test_sitl_px4.py."""

from __future__ import annotations

import math
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mavlink2  # noqa: E402

from lab.rigs import common, native, worlds  # noqa: E402
from lab.rigs.bundles import RigError  # noqa: E402
from lab.rigs.figures import moving_path_figures, tlog_stream_hz  # noqa: E402
from mpf_mavlink.config.scenario import build_path  # noqa: E402
from mpf_mavlink.config.schema import load_config  # noqa: E402
from mpf_mavlink.core.target import ConstantTurn  # noqa: E402
from mpf_mavlink.mavlink.tlog import TlogWriter  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


# -- the commands the rig sends --------------------------------------------------------------


def test_arduplane_reposition_puts_the_radius_in_param3_and_clockwise_is_param4_zero():
    c = native.centre_command("arduplane", 47.1234567, 8.7654321, 584.5, 150.0, clockwise=True)
    assert c.command == 192 and c.frame == 0  # MAV_CMD_DO_REPOSITION, MAV_FRAME_GLOBAL (AMSL)
    assert c.params[1] == 1.0  # MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
    assert c.params[2] == 150.0 and c.params[3] == 0.0
    assert (c.x, c.y, c.z) == (471234567, 87654321, 584.5)
    ccw = native.centre_command("arduplane", 47.0, 8.0, 500.0, 150.0, clockwise=False)
    assert ccw.params[3] != 0.0  # ArduPlane: any non-zero param4 loiters counter-clockwise


def test_px4_orbit_signs_the_radius_with_the_direction():
    c = native.centre_command("px4", -33.5, 151.25, 488.0, 150.0, clockwise=True)
    assert c.command == 34 and c.frame == 0  # MAV_CMD_DO_ORBIT, z AMSL
    assert c.params[0] == 150.0 and all(math.isnan(p) for p in c.params[1:])
    assert (c.x, c.y) == (-335000000, 1512500000)
    assert native.centre_command("px4", 0, 0, 0, 150.0, clockwise=False).params[0] == -150.0


def test_change_speed_is_an_airspeed_with_throttle_unchanged():
    assert native.change_speed_params(21.5) == (0.0, 21.5, -1.0, 0.0)


def test_the_commands_pack_as_command_int():
    # what send_command_int hands pymavlink must be a valid COMMAND_INT (ints for x/y)
    c = native.centre_command("arduplane", 47.3977, 8.5456, 584.0, 150.0, clockwise=True)
    mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    m = mav.command_int_encode(1, 1, c.frame, c.command, 0, 0, *c.params, c.x, c.y, c.z)
    back = mav.decode(bytearray(m.pack(mav)))
    assert back.command == 192 and back.x == c.x and back.y == c.y and back.param3 == 150.0


def _pair(lat, lon, alt, x, y, z, t_ms=1000, dt_ms=0, v=(0.0, 0.0, 0.0)):
    gp = SimpleNamespace(time_boot_ms=t_ms, lat=round(lat * 1e7), lon=round(lon * 1e7),
                         alt=round(alt * 1000))  # fmt: skip
    lp = SimpleNamespace(time_boot_ms=t_ms - dt_ms, x=x, y=y, z=z, vx=v[0], vy=v[1], vz=v[2])
    return gp, lp


def test_origin_from_a_pair_maps_local_points_back_to_where_they_were():
    R = native.EARTH_RADIUS_M["arduplane"]
    o0 = native.Origin(-35.363261, 149.165230, 584.0, R)
    lat, lon, alt = o0.to_global(120.0, -80.0, -100.0)
    # the aircraft at (120, -80, -100) m, its local position 40 ms older while flying 20 m/s
    # north: moved to the global sample's time by its velocity, the origin comes back
    o = native.Origin.from_pairs(
        [_pair(lat, lon, alt, 120.0 - 0.8, -80.0, -100.0, dt_ms=40, v=(20.0, 0.0, 0.0))], R
    )
    assert abs(o.lat_deg - o0.lat_deg) * R * math.pi / 180 < 0.02  # 1e-7 deg ~ 1 cm
    assert abs(o.alt_amsl_m - 584.0) < 1e-3
    # and 150 m east of the origin is 150 m east on the sphere (flat-earth, to 1 mm)
    la, lo, _ = o0.to_global(0.0, 150.0, 0.0)
    east = math.radians(lo - o0.lon_deg) * R * math.cos(math.radians(la))
    assert abs(east - 150.0) < 1e-3


def test_wind_from_the_east_blows_west():
    n, e = native.wind_to_ned(SimpleNamespace(direction=90.0, speed=6.0))
    assert abs(n) < 1e-9 and e == pytest.approx(-6.0)


# -- the figures: one function for both guidances ------------------------------------------


def _circle_nodes(r=150.0, n=721):
    th = np.linspace(0.0, 2 * math.pi, n)
    return np.column_stack([r * np.cos(th), r * np.sin(th), np.zeros_like(th)])


def test_e_on_a_synthetic_moving_track_is_the_known_offset():
    # a target drifting 3 m/s east carries a 150 m circle; the aircraft flies a 160 m circle
    # 2 m above it about the moving centre: e = hypot(10, 2), radial +10, vertical +2, for
    # every sample, whatever the target's motion (it is removed in the target's frame)
    tgt = ConstantTurn((0.0, 0.0, -100.0), 3.0, math.pi / 2)
    t = np.arange(0.0, 200.0, 0.1)
    rel = []
    for tk in t:
        st = tgt.state(float(tk))
        ang = 22.0 / 160.0 * tk
        p = st.position + st.R_T_I @ np.array([160 * math.cos(ang), 160 * math.sin(ang), -2.0])
        rel.append(st.R_T_I.T @ (p - st.position))
    f = moving_path_figures(t, np.array(rel), _circle_nodes(), True, 60.0, 5.0, circle=True)
    # the polyline's chords lie inside the circle by at most r (1 - cos(dth/2)) = 0.011 m
    assert f["e_rms_m"] == pytest.approx(math.hypot(10.0, 2.0), abs=0.02)
    assert f["e_max_m"] == pytest.approx(math.hypot(10.0, 2.0), abs=0.02)
    assert f["e_mean_radial_m"] == pytest.approx(10.0, abs=0.02)
    assert f["e_mean_vertical_m"] == pytest.approx(2.0, abs=1e-9)
    # north to east is clockwise seen from above (NED): outside is left of travel, +
    assert f["cross_track_mean_m"] == pytest.approx(10.0, abs=0.02)
    assert f["e_first_within_s"] is None and f["e_steady_samples"] == int(np.sum(t >= 60.0))


def test_e_of_a_run_record_is_the_same_function(tmp_path):
    from lab.rigs.figures import run_record_figures

    cfg = load_config(ROOT / "configs" / "bridge_px4.yaml")
    nodes = build_path(cfg.path).positions()
    t = np.arange(0.0, 120.0, 0.05)
    ang = 12.0 / 151.0 * t
    rel = np.column_stack([151.0 * np.cos(ang), 151.0 * np.sin(ang), np.full_like(t, 0.5)])
    np.savetxt(tmp_path / "timeseries.csv", np.column_stack([t, rel]), delimiter=",",
               header="t,rel_x,rel_y,rel_z", comments="")  # fmt: skip
    np.savetxt(tmp_path / "path_T.csv", nodes, delimiter=",", header="x,y,z", comments="")
    f = run_record_figures(tmp_path, cfg)
    direct = moving_path_figures(t, rel, nodes, True, 60.0, 5.0, circle=True)
    assert f["e_rms_m"] == pytest.approx(direct["e_rms_m"], rel=1e-6)
    assert f["e_rms_m"] == pytest.approx(math.hypot(1.0, 0.5), abs=0.02)
    assert f["e_mean_vertical_m"] == pytest.approx(-0.5, abs=1e-6)  # 0.5 m below (NED z +)


# -- issue 40 item 4: the rig flies exactly the config --------------------------------------


def _cfg(*sets: str):
    return load_config(ROOT / "configs" / "bridge_arduplane.yaml", list(sets))


def test_the_configs_target_flies_as_written_and_moving_replaces_only_a_still_one():
    ap = _cfg()  # the shipped ArduPlane config's target drifts 3 m/s east
    assert common.target_sets(ap, False) == ([], "moving 3 m/s heading 90 deg")
    assert common.target_sets(ap, True) == ([], "moving 3 m/s heading 90 deg")
    sets, label = common.target_sets(ap, False, still=True)
    assert sets == ["target.type=stationary"] and label.startswith("stationary (--still")
    climb = _cfg("target.speed_m_s=0", "target.climb_rate_m_s=1.5")
    for moving in (False, True):  # a target that only climbs is not "3 m/s east"
        assert common.target_sets(climb, moving) == ([], "climbing 1.5 m/s")
    still = _cfg("target.type=stationary")
    assert common.target_sets(still, False) == ([], "stationary")
    sets, label = common.target_sets(still, True)
    assert "target.type=constant_turn" in sets and "target.climb_rate_m_s=0" in sets
    assert label == "moving 3 m/s heading 90 deg (--moving: the config's is still)"


def test_a_moving_config_is_validated_with_its_own_target(tmp_path):
    bundle = tmp_path / "b"
    (bundle / "bin").mkdir(parents=True)
    (bundle / "Tools" / "autotest" / "models").mkdir(parents=True)
    (bundle / "bin" / "arduplane").write_text("")
    (bundle / "Tools" / "autotest" / "models" / "plane.parm").write_text("")
    a = common.parser().parse_args(["arduplane", "--bundle", str(bundle), "--out",
                                    str(tmp_path / "run")])  # fmt: skip
    v = common.validate(a)
    assert v["tsets"] == [] and v["cfg"].target.type == "constant_turn"


def _ns(*argv: str):
    return common.parser().parse_args([*argv, "--out", "x"])


def test_different_flights_get_different_names_and_the_same_flight_the_same():
    base = _ns("arduplane")
    names = {
        common.flight_name(_ns(*args))
        for args in (
            ["arduplane"],
            ["arduplane", "--set", "guidance.K_R=2"],
            ["arduplane", "--guidance", "native"],
            ["arduplane", "--guidance", "native", "--rate", "5"],
            ["arduplane", "--duration", "200"],
            ["arduplane", "--param", "NAVL1_LIM_BANK=45"],
            ["arduplane", "--config", str(ROOT / "configs" / "bridge_px4.yaml")],
        )
    }
    assert len(names) == 7
    assert common.flight_name(base) == common.flight_name(_ns("arduplane"))
    n = common.flight_name(
        _ns("arduplane", "--guidance", "native", "--rate", "5", "--wind", "6,90")
    )
    assert n.startswith("arduplane-native5hz-") and "-wind6-" in n  # still readable


def test_params_and_native_options_are_checked_before_anything_starts():
    with pytest.raises(SystemExit):
        _ns("arduplane", "--param", "nocase=1")
    with pytest.raises(SystemExit):
        _ns("arduplane", "--param", "X=abc")
    assert _ns("arduplane", "--param", "NAVL1_LIM_BANK=45").params == [("NAVL1_LIM_BANK", 45.0)]
    with pytest.raises(RigError, match="no SIL twin"):
        common.validate(_ns("arduplane", "--guidance", "native", "--sil"))
    with pytest.raises(RigError, match="path.type circle"):
        common.validate(_ns("arduplane", "--guidance", "native", "--config",
                            str(ROOT / "configs" / "spline3d_turning_target.yaml")))  # fmt: skip


def _packet(mav, msg) -> bytes:
    return bytes(msg.pack(mav))


def test_attitude_rate_as_flown_comes_from_the_tlog(tmp_path):
    # 40 Hz ATTITUDE from the autopilot (component 1) while the bridge (191) sends setpoints
    # from t = 10 s to 30 s; 23 Hz before it tracks (the start-up sample the table used to show)
    ap = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    br = mavlink2.MAVLink(None, srcSystem=1, srcComponent=191)
    p = tmp_path / "mavlink.tlog"
    t0 = 1.7e9
    with TlogWriter(p) as w:
        for k in range(230):  # 10 s at 23 Hz
            w.write(_packet(ap, ap.attitude_encode(k, 0, 0, 0, 0, 0, 0)), t0 + k / 23.0)
        for k in range(801):  # 20 s at 40 Hz, a setpoint after each
            tk = t0 + 10.0 + k / 40.0
            w.write(_packet(ap, ap.attitude_encode(k, 0, 0, 0, 0, 0, 0)), tk)
            sp = br.set_attitude_target_encode(k, 1, 1, 0, [1, 0, 0, 0], 0, 0, 0, 0.5)
            w.write(_packet(br, sp), tk + 0.001)
    assert tlog_stream_hz(p) == pytest.approx(40.0, rel=0.01)
    assert tlog_stream_hz(tmp_path / "none.tlog") is None


def test_a_sil_leg_refused_by_check_says_why():
    log = [
        "[WARN] c2: Psi(0) 0.31 > c2 0.25",
        "mpf-mavlink: configs/bridge_arduplane.yaml: refused to fly: check failed: feasibility "
        "(peak bank 39.4 deg > 35 deg allowed) (--force flies it anyway)",
    ]
    why = common.sil_refusal(3, log)
    assert why is not None and why.startswith("refused by check (exit 3): check failed: feasib")
    assert common.sil_refusal(0, log) is None and common.sil_refusal(5, log) is None
    assert common.sil_refusal(1, ["Traceback", "RuntimeError: boom"]) == (
        "not flown (exit 1): RuntimeError: boom"
    )
    rows = dict(common._rows_sil({"error": why, "warnings": log[:1]}))
    assert rows["our SIL: steady RMS |pt|"] == why


# -- compare across the two worlds ----------------------------------------------------------


def test_compare_passes_the_options_to_both_flights_with_their_own_guidance_and_directory():
    argv = ["px4", "--moving", "--out", "D", "--duration", "200", "--record", "--rate", "5"]
    a = worlds.sub_argv(argv, "native", Path("D/native"))
    assert a == ["px4", "--moving", "--duration", "200", "--rate", "5", "--guidance", "native",
                 "--out", "D/native"]  # fmt: skip
    assert "--out=D" not in worlds.sub_argv(["px4", "--out=D"], "mpf", Path("D/mpf"))


def test_compare_refuses_what_cannot_fly_in_both_worlds(tmp_path):
    with pytest.raises(RigError, match="no --sil"):
        worlds.validate(["arduplane", "--sil", "--out", str(tmp_path / "o")])
    with pytest.raises(RigError, match="no --guidance"):
        worlds.validate(["arduplane", "--guidance", "native", "--out", str(tmp_path / "o")])


def test_compare_table_has_a_row_per_guidance():
    row = {"words": "MPF (mpf-mavlink run)", "target": "stationary", "e_rms_m": 0.2,
           "e_max_m": 0.36, "e_mean_radial_m": -0.18, "e_mean_vertical_m": 0.01,
           "tracked_s": 300.0, "verdict": "PASS", "guidance": "mpf", "bundle": "X"}  # fmt: skip
    res = {"autopilot": "arduplane", "command": "scripts/sitl compare arduplane", "commit": "c",
           "date": "2026-12-02", "wind": [6.0, 90.0],
           "rows": [row, {**row, "guidance": "native", "words": "DO_REPOSITION"}]}  # fmt: skip
    md = worlds.markdown(res)
    assert "| arduplane | MPF (mpf-mavlink run) | stationary, wind 6 m/s from 90 deg | 0.2 |" in md
    assert "| -0.18 |" in md and md.count("| arduplane |") == 2


# -- PX4's ULog: EKF2 against SIH's truth ---------------------------------------------------


def _ulog_msg(typ: str, body: bytes) -> bytes:
    import struct

    return struct.pack("<HB", len(body), ord(typ)) + body


def test_the_ulog_reader_decodes_nested_arrays_and_restores_unlogged_trailing_padding(tmp_path):
    import struct

    from lab.rigs.ulog import read_topics

    fmt = "uint64_t timestamp;float[4] q;uint8_t n;uint8_t[7] _padding0;"
    data = b"ULog\x01\x12\x35" + b"\x01" + struct.pack("<Q", 0)
    data += _ulog_msg("F", b"att:" + fmt.encode())
    data += _ulog_msg("F", b"other:uint64_t timestamp;double x;")
    data += _ulog_msg("A", struct.pack("<BH", 0, 3) + b"att")
    data += _ulog_msg("A", struct.pack("<BH", 0, 4) + b"other")
    for k in range(5):  # the trailing 7 bytes of padding are not in the file
        payload = struct.pack("<Q4fB", 1000 * k, 1.0, 0.1 * k, 0.0, 0.0, k)
        data += _ulog_msg("D", struct.pack("<H", 3) + payload)
        data += _ulog_msg("D", struct.pack("<H", 4) + struct.pack("<Qd", 7, 2.5))
    p = tmp_path / "x.ulg"
    p.write_bytes(data)
    u = read_topics(p, {"att"})
    assert set(u) == {"att"} and len(u["att"]) == 5
    assert u["att"]["timestamp"].tolist() == [0, 1000, 2000, 3000, 4000]
    assert u["att"]["q"][3].tolist() == pytest.approx([1.0, 0.3, 0.0, 0.0])
    assert u["att"]["n"].tolist() == [0, 1, 2, 3, 4]


def test_euler_angles_of_a_known_quaternion():
    from lab.rigs.ulog import _euler

    r, pch, y = 0.3, -0.2, 2.0  # ZYX: q = qz(y) qy(p) qx(r)
    cr, sr, cp, sp, cy, sy = (math.cos(r / 2), math.sin(r / 2), math.cos(pch / 2),
                              math.sin(pch / 2), math.cos(y / 2), math.sin(y / 2))  # fmt: skip
    q = np.array([[cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                   cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy]])  # fmt: skip
    assert _euler(q)[0].tolist() == pytest.approx([r, pch, y])


def test_a_flight_name_is_the_same_in_every_clone_and_changes_with_the_configs_content(tmp_path):
    import shutil

    a = _ns("px4", "--config", str(ROOT / "configs" / "bridge_px4.yaml"))
    assert common.flight_name(a) == common.flight_name(_ns("px4"))  # the default is that file
    c = tmp_path / "bridge_px4.yaml"
    shutil.copy(ROOT / "configs" / "bridge_px4.yaml", c)
    n1 = common.flight_name(_ns("px4", "--config", str(c)))
    c.write_text(c.read_text().replace("K_R: 1.0", "K_R: 2.0"))
    assert common.flight_name(_ns("px4", "--config", str(c))) != n1


def test_the_results_table_has_every_recorded_compare_and_the_px4_floor(tmp_path, monkeypatch):
    import json

    monkeypatch.setattr(worlds, "RESULTS", tmp_path)
    row = {"guidance": "mpf", "words": "MPF (mpf-mavlink run)", "target": "stationary",
           "e_rms_m": 1.1, "e_max_m": 2.8, "e_mean_radial_m": -0.06, "e_mean_vertical_m": -0.2,
           "tracked_s": 300.0, "verdict": "PASS"}  # fmt: skip
    floor = {"estimate_error_rms_horizontal_m": 0.28, "estimate_error_rms_vertical_m": 0.33,
             "attitude_error_mean_rpy_deg": [-0.2, 0, 0],
             "attitude_error_rms_about_mean_rpy_deg": [1.0, 0, 0],
             "radial_vs_roll_error_corr": 0.93, "radial_lag_behind_roll_error_s": 4.5,
             "e_rms_from_estimate_m": 1.1, "e_rms_from_truth_m": 1.4}  # fmt: skip
    nat = {**row, "guidance": "native", "words": "MAV_CMD_DO_ORBIT (Hold)", "verdict": "FLOWN",
           "firmware_params": {"NPFG_PERIOD": 8.0}, "estimator_floor": floor}  # fmt: skip
    for name, ap in (("px4-a", "px4"), ("arduplane-b", "arduplane")):
        res = {"name": name, "autopilot": ap, "command": f"scripts/sitl compare {ap} --out X",
               "commit": "c", "date": "2026-12-02", "rows": [row, nat]}  # fmt: skip
        (tmp_path / f"native-{name}.json").write_text(json.dumps(res))
    md = worlds.write_results_table().read_text()
    assert md.count("| px4 |") == 3 and md.count("| arduplane |") == 3  # 2 rows + a floor row
    assert "MAV_CMD_DO_ORBIT (Hold), NPFG_PERIOD=8 |" in md
    assert "| 0.93, 4.5 | 1.1 / 1.4 |" in md
    assert "`scripts/sitl compare px4 --out X`" in md
