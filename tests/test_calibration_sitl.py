"""The calibration check on real firmware: the SIL with the shipped profile predicts the real
SITL's steady tracking (issue 24's band: real / SIL steady RMS in [0.67, 1.5], mean radial and
vertical within 0.3 m).

Needs the SITL bundles at <repo>/../shared/sitl (or MPF_SITL_DIR); skipped, saying why, on a bare
clone. PX4: about 5 minutes of real time (boot and take-off ~60 s, 180 s of tracking, steady from
60 s: one and a half orbits of the 150 m circle at 12 m/s, several correlation times of EKF2's
errors), then three SIL draws (the real flight is one draw of SIH's noise; the SIL's RMS over
three seeds is its expectation, ~30 s each).
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from sim.calibrate import BAND, MEAN_TOL_M, find_bundle, sitl_dir

ROOT = Path(__file__).resolve().parents[1]

pytestmark = [
    pytest.mark.sitl,
    # one real ArduPlane flight at a time in a pytest run, like tests/test_sitl_arduplane.py
    pytest.mark.xdist_group("sitl-arduplane"),
    pytest.mark.skipif(
        sitl_dir() is None,
        reason="no SITL bundles: <repo>/../shared/sitl is absent and MPF_SITL_DIR is not set",
    ),
]


def _row(out, autopilot: str, profile: str, seeds: int, timeout: float) -> tuple[dict, str]:
    r = subprocess.run(
        [sys.executable, "-m", "sim.calibrate", "sil", autopilot, "--out", str(out),
         "--profile", str(ROOT / "configs" / "autopilots" / profile), "--seeds", str(seeds)],
        cwd=ROOT, capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip
    (row,) = json.loads((out / f"calibration_{Path(profile).stem}.json").read_text())
    return row, r.stdout[-3000:] + r.stderr[-2000:]


def _assert_band(row: dict, log: str) -> None:
    assert row["ratio"] is not None and BAND[0] <= row["ratio"] <= BAND[1], log
    assert abs(row["sil_radial_m"] - row["real_radial_m"]) <= MEAN_TOL_M, log
    assert abs(row["sil_vertical_m"] - row["real_vertical_m"]) <= MEAN_TOL_M, log


@pytest.mark.xdist_group("sitl-px4")
def test_px4_profile_predicts_the_real_firmware(tmp_path):
    bundle = find_bundle("px4")
    if bundle is None:
        pytest.skip(f"no PX4 bundle in {sitl_dir()}")
    out = tmp_path / "cal"
    r = subprocess.run(
        [sys.executable, "-m", "sim.calibrate", "real", "px4", "--out", str(out),
         "--only", "stationary", "--duration", "180", "--bundle", str(bundle)],
        cwd=ROOT, capture_output=True, text=True, timeout=1800,  # the PX4 lock may be held
    )  # fmt: skip
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    row, log = _row(out, "px4", "px4-1.16-sih.yaml", 3, 900)
    _assert_band(row, log)


def _free_instance() -> int:
    """An ArduPilot SITL instance whose TCP ports (5760 + 10 I, + 2) are free here."""
    for i in range(5, 40):
        ok = True
        for port in (5760 + 10 * i, 5762 + 10 * i):
            with socket.socket() as s:
                try:
                    s.bind(("127.0.0.1", port))
                except OSError:
                    ok = False
        if ok:
            return i
    pytest.skip("no free ArduPilot SITL instance")


@pytest.mark.skip(
    reason="issue 24 open: the ArduPlane profile was fitted with the bridge config before the "
    "merge (K_R 1.0, wind compensation on since); with the shipped one the stationary row flew "
    "real 0.170 m vs SIL 0.078 m (2.17x), outside [0.67, 1.5]: refit, then re-enable"
)
def test_arduplane_profile_predicts_the_real_firmware(tmp_path):
    bundle = find_bundle("arduplane")
    if bundle is None:
        pytest.skip(f"no ArduPlane bundle in {sitl_dir()}")
    out = tmp_path / "cal"
    r = subprocess.run(
        [sys.executable, "-m", "sim.calibrate", "real", "arduplane", "--out", str(out),
         "--only", "stationary", "--duration", "150", "--instance", str(_free_instance()),
         "--bundle", str(bundle)],
        cwd=ROOT, capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    row, log = _row(out, "arduplane", "arduplane-4.7.yaml", 1, 600)
    _assert_band(row, log)
