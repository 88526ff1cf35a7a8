"""A real ground station against ``mpf-mavlink vehicle --serve``: MAVProxy, driven through its
command line (stdin), as a user would. Opt-in: MAVProxy is not a dependency of this project (its
wheel pulls opencv, vtk and shapely). ``MPF_MAVPROXY`` names its ``mavproxy.py`` (any venv,
e.g. ``python -m venv /tmp/mp && /tmp/mp/bin/pip install MAVProxy==1.8.75``, as README.md
says), else one on PATH is used; without either the test skips, saying so.

What is checked (issue 27's acceptance): ``param fetch`` completes with every parameter within
5 s (MAVProxy's own retry period is 10 s: an unanswered list shows as a timeout), ``param set``
is read back by ``param show``, ``wp list`` answers, no "fence breach", and the height MAVProxy
announces is the aircraft's (~100 m), never the target's (system 2, ~5 m).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from tests.test_sim_vehicle import free_port

ROOT = Path(__file__).resolve().parents[1]
MAVPROXY = os.environ.get("MPF_MAVPROXY") or shutil.which("mavproxy.py")

pytestmark = pytest.mark.skipif(
    not MAVPROXY or not Path(MAVPROXY).exists(),
    reason="MAVProxy not installed (set MPF_MAVPROXY=/path/to/mavproxy.py to run this test)",
)


class Console:
    """MAVProxy as a subprocess: commands on stdin, its output lines with arrival times."""

    def __init__(self, master: str, cwd: Path) -> None:
        py = Path(MAVPROXY).with_name("python")  # its own venv's interpreter
        exe = [str(py), MAVPROXY] if py.exists() else [MAVPROXY]
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.p = subprocess.Popen(
            [*exe, f"--master={master}", "--nowait", f"--logfile={cwd / 'mav.tlog'}"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            cwd=cwd, env=env,
        )  # fmt: skip
        self.lines: list[tuple[float, str]] = []
        self.t0 = time.monotonic()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.p.stdout is not None
        for line in self.p.stdout:
            self.lines.append((time.monotonic() - self.t0, line.rstrip()))

    def send(self, cmd: str) -> float:
        assert self.p.stdin is not None
        t = time.monotonic() - self.t0
        self.p.stdin.write(cmd + "\n")
        self.p.stdin.flush()
        return t

    def wait_for(
        self, pattern: str, after: float = 0.0, timeout: float = 10.0
    ) -> tuple[float, str] | None:
        rx = re.compile(pattern)
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for t, line in list(self.lines):
                if t >= after and rx.search(line):
                    return t, line
            time.sleep(0.05)
        return None

    def close(self) -> None:
        self.p.terminate()
        try:
            self.p.wait(5)
        except subprocess.TimeoutExpired:
            self.p.kill()

    def transcript(self) -> str:
        return "\n".join(f"[{t:6.2f}] {s}" for t, s in self.lines if "Unloading" not in s)


def _table_size(sets: list[str]) -> int:
    """How many parameters ``mpf-mavlink vehicle`` serves for the config and ``sets``: the length
    of sim/vehicle/gcs_services.py's table of a vehicle built as the command builds it (the table
    depends on the flavour and the plant), so the count follows the table as it grows."""
    from mpf_mavlink.config.schema import load_config
    from sim.sil import build_vehicle

    v = build_vehicle(
        load_config(ROOT / "configs/default.yaml", sets), f"udpin:127.0.0.1:{free_port()}"
    )
    try:
        return len(v.gcs.params)
    finally:
        v.close()


@pytest.mark.parametrize("flavour", ["px4", "ardupilot"])
def test_mavproxy_param_fetch_set_wp_list_against_the_sil_vehicle(flavour, tmp_path):
    port = free_port()
    sets = [f"sil.flavour={flavour}", f"mavlink.flavour={flavour}"]
    if flavour == "ardupilot":
        sets.append("mavlink.hold_mode=LOITER")
    vcmd = [sys.executable, "-m", "mpf_mavlink.cli", "vehicle", str(ROOT / "configs/default.yaml"),
            "--serve", f"udpin:127.0.0.1:{port}", "--duration", "60"]  # fmt: skip
    for s in sets:
        vcmd += ["--set", s]
    veh = subprocess.Popen(
        vcmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    con = None
    try:
        assert veh.stdout is not None
        first = veh.stdout.readline()  # printed once the vehicle is trimmed and serving
        assert "simulated" in first, first
        con = Console(f"udpout:127.0.0.1:{port}", tmp_path)
        assert con.wait_for(r"online system 1", timeout=20.0), con.transcript()
        time.sleep(1.0)
        t = con.send("param fetch")
        got = con.wait_for(r"Received (\d+) parameters", after=t, timeout=10.0)
        assert got is not None, con.transcript()
        # every parameter of the table the served vehicle answers from
        assert int(re.search(r"(\d+)", got[1])[1]) == _table_size(sets)  # type: ignore[index]
        assert got[0] - t < 5.0, con.transcript()
        name = "NAV_LOITER_RAD" if flavour == "px4" else "WP_LOITER_RAD"
        con.send(f"param set {name} 120")
        time.sleep(1.0)
        t = con.send(f"param show {name}")
        shown = con.wait_for(rf"{name}\s+(\S+)", after=t, timeout=5.0)
        assert shown is not None and float(shown[1].split()[-1]) == 120.0, con.transcript()
        t = con.send("wp list")
        wp = con.wait_for(r"Requesting (\d+) waypoints", after=t, timeout=5.0)
        assert wp is not None, con.transcript()
        # PX4: no mission; ArduPlane: its home is item 0 (as its SITL answers)
        count = re.search(r"Requesting (\d+) waypoints", wp[1])
        assert count is not None and count[1] == ("0" if flavour == "px4" else "1")
        time.sleep(1.0)
        text = con.transcript()
        assert "fence breach" not in text, text
        heights = [int(h) for h in re.findall(r"height (\d+)", text)]
        assert heights and all(h > 50 for h in heights), text  # the aircraft flies at ~100 m
        print(text)  # the transcript, for the report (pytest -s)
    finally:
        if con is not None:
            con.close()
        veh.terminate()
        veh.wait(10)
