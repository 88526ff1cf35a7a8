"""The real-firmware rig's own logic, without firmware (lab/rigs): arguments refused before
anything is created, nothing deleted, --out relative to the caller, the figures it computes
(cross-track for any shape, the hold after a kill) and the serial relay."""

from __future__ import annotations

import math
import os
import select
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from lab.rigs import common
from lab.rigs.bundles import RigError
from lab.rigs.figures import cross_track, hold_figures
from lab.rigs.pty_relay import PtyRelay

ROOT = Path(__file__).resolve().parents[1]


def run_rig(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "lab.rigs", *args], cwd=cwd, env=env, capture_output=True,
        text=True, timeout=60,
    )  # fmt: skip


@pytest.mark.parametrize(
    "args, culprit",
    [
        (["px4", "--wind", "6,90"], "PX4 v1.16 SIH has no wind model"),
        (["arduplane", "--wind", "6"], "SPEED,DIR_DEG"),
        (["arduplane", "--wind", "6,400"], "direction 0..360"),
        (["arduplane", "--duration", "-3"], "--duration"),
        (["arduplane", "--duration", "nan"], "--duration"),
        (["arduplane", "--bundle", "/nonexistent/bundle"], "--bundle /nonexistent/bundle"),
        (["arduplane", "--config", "/nonexistent.yaml"], "--config /nonexistent.yaml"),
        (["arduplane", "--set", "guidance.bogus=1"], "bogus"),
        (["px4", "--serial"], "ArduPlane options"),
        (["arduplane", "--binary", str(ROOT / "pyproject.toml")], "not an executable"),
    ],
)
def test_bad_arguments_are_one_line_and_create_nothing(tmp_path, args, culprit):
    out = tmp_path / "out"
    r = run_rig(*args, "--out", str(out), cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert culprit in r.stderr and len(r.stderr.strip().splitlines()) <= 3, r.stderr
    assert not out.exists()


def test_an_existing_out_directory_is_refused_and_kept(tmp_path):
    out = tmp_path / "precious"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    r = run_rig("arduplane", "--out", str(out), cwd=tmp_path)
    assert r.returncode == 2 and "not an empty directory" in r.stderr
    assert (out / "keep.txt").read_text() == "mine"


def test_relative_out_is_the_callers(tmp_path, monkeypatch):
    bundle = tmp_path / "b"
    (bundle / "bin").mkdir(parents=True)
    (bundle / "bin" / "arduplane").write_text("")
    monkeypatch.chdir(tmp_path)
    a = common.parser().parse_args(["arduplane", "--bundle", str(bundle), "--out", "rel/run"])
    v = common.validate(a)
    assert v["out"] == tmp_path / "rel" / "run"
    assert not (tmp_path / "rel").exists()  # validation creates nothing


def test_moving_labels_say_what_flies():
    from mpf_mavlink.config.schema import load_config

    ap = load_config(ROOT / "configs" / "bridge_arduplane.yaml")
    px = load_config(ROOT / "configs" / "bridge_px4.yaml")
    # the config's target as written (tests/test_sitl_native.py has the rest of the rules)
    assert common.target_sets(ap, False) == (
        [],
        f"moving {ap.target.speed_m_s:g} m/s heading 90 deg",
    )
    assert common.target_sets(ap, False, still=True)[0] == ["target.type=stationary"]
    sets, label = common.target_sets(px, True)  # PX4's config is still: the rig moves it
    assert "target.type=constant_turn" in sets and label.startswith("moving 3 m/s heading 90 deg")
    with pytest.raises(RigError):
        common.validate(common.parser().parse_args(["px4", "--wind", "1,2", "--out", "x"]))


def test_moving_px4_flight_sends_the_moving_target(tmp_path):
    # validate() loads the config with the target overrides already applied; the flight must
    # send those overrides, not recompute them on the moved config (which then looks moving and
    # gets none: PX4 --moving flew the still target of bridge_px4.yaml)
    bundle = tmp_path / "b"
    bundle.mkdir()
    (bundle / "px4-sih-airplane").write_text("")
    a = common.parser().parse_args(["px4", "--bundle", str(bundle), "--moving",
                                    "--out", str(tmp_path / "run")])  # fmt: skip
    v = common.validate(a)
    assert "target.type=constant_turn" in v["tsets"]
    assert v["target_label"].startswith("moving 3 m/s heading 90 deg (--moving")
    assert v["cfg"].target.type == "constant_turn"


def _circle_run(d: Path, offset: float, cw: bool = True) -> None:
    """A 100 m circle in the target frame and a vehicle ``offset`` m outside it."""
    th = np.linspace(0.0, 2 * math.pi, 721)
    sgn = 1.0 if cw else -1.0
    P = np.column_stack([100 * np.cos(th), sgn * 100 * np.sin(th), np.zeros_like(th)])
    np.savetxt(d / "path_T.csv", P, delimiter=",", header="x,y,z", comments="")
    t = np.linspace(0.0, 100.0, 500)
    ang = np.linspace(0.3, 5.0, 500)
    r = 100.0 + offset
    cols = {"t": t, "rel_x": r * np.cos(ang), "rel_y": sgn * r * np.sin(ang)}
    names = ",".join(cols)
    np.savetxt(d / "timeseries.csv", np.column_stack(list(cols.values())), delimiter=",",
               header=names, comments="")  # fmt: skip


@pytest.mark.parametrize("cw, sign", [(True, 1.0), (False, -1.0)])
def test_cross_track_is_the_distance_to_the_path_left_positive(tmp_path, cw, sign):
    _circle_run(tmp_path, 2.0, cw)
    f = cross_track(tmp_path, 60.0)
    # 2 m outside: left of travel on a clockwise circle (NED, seen from above), right on a
    # counter-clockwise one; the polyline's chords (0.5 deg) are within 1 mm of the arc
    assert f["cross_track_mean_m"] == pytest.approx(sign * 2.0, abs=0.01)
    assert f["cross_track_rms_m"] == pytest.approx(2.0, abs=0.01)


def test_cross_track_on_a_figure_eight_has_no_radial_meaning(tmp_path):
    s = np.linspace(0, 2 * math.pi, 2001)
    P = np.column_stack([300 * np.sin(s), 150 * np.sin(2 * s), np.zeros_like(s)])
    np.savetxt(tmp_path / "path_T.csv", P, delimiter=",", header="x,y,z", comments="")
    k = np.arange(200, 1800, 7)
    tang = np.gradient(P[:, :2], axis=0)[k]
    nrm = np.column_stack([-tang[:, 1], tang[:, 0]]) / np.hypot(*tang.T)[:, None]
    q = P[k, :2] - 1.5 * nrm  # 1.5 m to the left of travel in NED (-90 deg from the tangent)
    t = np.linspace(60.0, 160.0, len(k))
    np.savetxt(tmp_path / "timeseries.csv", np.column_stack([t, q]), delimiter=",",
               header="t,rel_x,rel_y", comments="")  # fmt: skip
    f = cross_track(tmp_path, 60.0)
    assert f["cross_track_rms_m"] == pytest.approx(1.5, abs=0.05)
    assert f["cross_track_mean_m"] == pytest.approx(1.5, abs=0.05)


def test_hold_figures_judge_the_issue_bounds():
    loiter = [(t, 0.4, 160 * math.cos(t / 7), 160 * math.sin(t / 7), -100.0) for t in range(61)]
    h = hold_figures(loiter, (0.0, 0.0), 100.0, 150.0)
    assert h["hold_verdict"] == "PASS" and h["max_bank_deg"] == pytest.approx(22.9, abs=0.1)
    away = [(t, 0.0, 20.0 * t, 0.0, -100.0) for t in range(61)]  # straight on: no hold
    assert hold_figures(away, (0.0, 0.0), 100.0, 150.0)["hold_verdict"].startswith("FAIL: 1200 m")
    steep = [(t, 0.7, 100.0, 0.0, -115.0) for t in range(61)]
    v = hold_figures(steep, (0.0, 0.0), 100.0, 150.0)["hold_verdict"]
    assert "|bank| 40.1 deg" in v and "altitude off by 15.0 m" in v
    # judged against the limit passed in (the autopilot's own roll limit), 35 deg without one
    level = [(t, 0.7, 100.0, 0.0, -100.0) for t in range(61)]
    assert hold_figures(level, (0.0, 0.0), 100.0, 150.0, 45.0)["hold_verdict"] == "PASS"
    assert (
        "(> 35, the hold's limit)" in hold_figures(level, (0.0, 0.0), 100.0, 150.0)["hold_verdict"]
    )


def test_pty_relay_carries_bytes_both_ways_untouched():
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    port = srv.getsockname()[1]
    got: list[bytes] = []

    def autopilot() -> None:
        c, _ = srv.accept()
        c.sendall(bytes(range(256)))  # every byte value: raw mode must pass \r, \n, ^C, ^D
        got.append(c.recv(4096))
        c.close()

    th = threading.Thread(target=autopilot)
    th.start()
    relay = PtyRelay(port)
    try:
        # The relay made the line raw; no tcsetattr here: tty.setraw's default TCSAFLUSH would
        # discard whatever the relay had already delivered (a race that hung this test).
        fd = os.open(relay.device, os.O_RDWR | os.O_NOCTTY)
        buf = b""
        t_end = time.monotonic() + 10.0
        while len(buf) < 256 and time.monotonic() < t_end:
            if select.select([fd], [], [], 0.5)[0]:
                buf += os.read(fd, 4096)
        assert buf == bytes(range(256))
        os.write(fd, b"\x03\x04\r\n\xfd\xfe")
        th.join(5)
        assert got == [b"\x03\x04\r\n\xfd\xfe"]
        os.close(fd)
    finally:
        relay.close()
        srv.close()


def test_sil_leg_flies_the_real_flights_wind_and_turbulence(tmp_path, monkeypatch):
    # `--sil` beside a wind flight must fly that wind (SIM_WIND_DIR is where it comes from, the
    # SIL's wind vector where the air goes) and SIM_WIND_TURB's model, not still air
    exe = tmp_path / "arduplane"
    exe.write_text("#!/bin/sh\n")
    exe.chmod(0o755)
    # a checkout of its own (its plane.parm only): no SITL bundle needed, a bare clone runs it
    parm = tmp_path / "ardupilot" / "Tools" / "autotest" / "models" / "plane.parm"
    parm.parent.mkdir(parents=True)
    parm.write_text("")
    out = tmp_path / "run"
    a = common.parser().parse_args(["arduplane", "--binary", str(exe), "--bundle",
                                    str(tmp_path / "ardupilot"), "--wind", "6,90",
                                    "--turbulence", "2", "--out", str(out)])  # fmt: skip
    v = common.validate(a)
    (out / "bridge").mkdir(parents=True)
    n = np.linspace(0.0, 10.0, 5)
    np.savetxt(out / "bridge" / "timeseries.csv", np.column_stack([n, n, -100.0 + 0 * n]),
               delimiter=",", header="p_n,p_e,p_d", comments="")  # fmt: skip
    seen: list[list[str]] = []
    monkeypatch.setattr(common.subprocess, "run", lambda cmd, **kw: seen.append(cmd) or
                        subprocess.CompletedProcess(cmd, 0))  # fmt: skip
    common.sil_leg(a, v, [], {"figures": {}}, out)
    sets = [seen[0][i + 1] for i, x in enumerate(seen[0]) if x == "--set"]
    wind = next(s for s in sets if s.startswith("sil.wind_ned_m_s="))
    w = [float(x) for x in wind.split("=")[1].strip("[]").split(",")]
    assert w == pytest.approx([0.0, -6.0, 0.0], abs=1e-3)  # from the east: the air moves west
    assert "sil.wind_turbulence_m_s=2" in sets


@pytest.mark.parametrize("with_filter", [True, False])
def test_a_bundle_member_outside_the_cache_is_refused_with_or_without_tarfiles_filter(
    tmp_path, monkeypatch, with_filter
):
    """Unpacking a bundle never writes outside the cache: tarfile's "tar" filter where the
    interpreter has it, our own check where it has not (Python before 3.11.4); a sound
    archive unpacks the same either way."""
    import io
    import tarfile

    from lab.rigs import bundles

    if with_filter and not hasattr(tarfile, "tar_filter"):
        pytest.skip("this interpreter's tarfile has no filters (Python before 3.11.4)")
    if not with_filter:
        monkeypatch.delattr(tarfile, "tar_filter", raising=False)

    def archive(name: str, members: dict[str, bytes], link: tuple[str, str] | None = None):
        p = tmp_path / name
        with tarfile.open(p, "w:gz") as tf:
            for n, data in members.items():
                info = tarfile.TarInfo(n)
                info.size = len(data)
                tf.addfile(info, io.BytesIO(data))
            if link is not None:
                info = tarfile.TarInfo(link[0])
                info.type, info.linkname = tarfile.SYMTYPE, link[1]
                tf.addfile(info)
        return p

    good = archive("good.tar.gz", {"b/RUN.txt": b"run", "b/bin/px4": b"\x7fELF"})
    out = tmp_path / "good"
    out.mkdir()
    with tarfile.open(good) as tf:
        bundles._extract(tf, out, good)
    assert (out / "b" / "bin" / "px4").read_bytes() == b"\x7fELF"
    outside = tmp_path / "evil"  # where "../../evil" from tmp_path/<case>/ would land
    absolute = tmp_path / "abs-evil"
    for name, members, link in (
        ("up.tar.gz", {"b/../../evil": b"x"}, None),
        ("abs.tar.gz", {str(absolute): b"x"}, None),
        ("sym.tar.gz", {"b/RUN.txt": b"run"}, ("b/escape", "../../..")),
    ):
        bad = archive(name, members, link)
        dest = tmp_path / name.split(".")[0] / "x"
        dest.mkdir(parents=True)
        refused: BaseException | None = None
        try:
            with tarfile.open(bad) as tf:
                bundles._extract(tf, dest, bad)
        except (RigError, tarfile.TarError) as e:
            refused = e
        # ours refuses all three, naming the member; the "tar" filter refuses the name that
        # leaves, takes the absolute one as relative to the destination and lets a symbolic
        # link point anywhere (its "data" filter would not: the bundles need none of that)
        if not with_filter:
            assert isinstance(refused, RigError) and "member" in str(refused), name
            assert not any(dest.rglob("*")), name
        elif name == "up.tar.gz":
            assert isinstance(refused, tarfile.TarError), name
    assert not outside.exists() and not absolute.exists()
