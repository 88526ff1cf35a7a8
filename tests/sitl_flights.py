"""Shared by tests/test_sitl_*.py: run the real-firmware rig (lab/rigs) and judge its summary.

The SITL tests run whenever the bundles are there (``MPF_SITL_DIR``, or ``shared/sitl`` beside
the checkout: README "Flying PX4 SITL") and skip, saying why, on a bare clone. Each autopilot's
flights share one xdist group (``--dist loadgroup`` in scripts/test), so that they never fly at
once in one pytest run, while the rest of the suite runs beside them; PX4 also holds
/tmp/mpf-px4.lock (its ports are fixed), ArduPlane takes a free instance and locks it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from lab.rigs.bundles import why_missing

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT_S = 1800  # a flight is minutes; this includes waiting for another user's PX4 lock


def marks(autopilot: str) -> list[Any]:
    why = why_missing(autopilot)
    return [
        pytest.mark.sitl,
        pytest.mark.xdist_group(f"sitl-{autopilot}"),
        pytest.mark.skipif(why is not None, reason=f"{autopilot} SITL: {why}"),
    ]


def rig(out: Path, *args: str) -> tuple[int, dict[str, Any], str]:
    """Run the rig (scripts/sitl); (exit code, its summary.json, the tail of its output)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run(
        [sys.executable, "-m", "lab.rigs", *args, "--out", str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=TIMEOUT_S,
    )  # fmt: skip
    p = out / "summary.json"
    s = json.loads(p.read_text()) if p.is_file() else {}
    return r.returncode, s, r.stdout[-5000:] + r.stderr[-2000:]


def assert_tracked(
    rc: int, s: dict[str, Any], log: str, rms_max: float, radial_max: float | None
) -> None:
    """Engaged by itself (the rig only starts the bridge), tracked within the bounds, handed
    back, and the bridge's own verdict passed."""
    f = s.get("figures", {})
    assert f.get("engaged") is True, log
    assert f["handback_confirmed"] is True, log
    assert f["steady_rms_m"] <= rms_max, log
    assert f["cross_track_rms_m"] <= rms_max, log
    if radial_max is not None:
        assert abs(f["steady_mean_radial_m"]) <= radial_max, log
    assert rc == 0 and s["verdict"] == "PASS", log


def assert_hold(rc: int, s: dict[str, Any], log: str) -> None:
    """Issue 22's hold after the bridge's SIGKILL, from the autopilot's own telemetry: within
    2x the path radius of its centre for the next 60 s, |bank| <= 35 deg, altitude within 10 m."""
    h = s.get("hold", {})
    assert s.get("figures", {}).get("engaged") is True, log
    assert h.get("watched_s", 0.0) >= 59.0, log
    assert h["max_dist_from_centre_m"] <= 2.0 * s["mission"]["radius_m"], log
    assert h["max_bank_deg"] <= 35.0, log
    assert h["max_alt_error_m"] <= 10.0, log
    assert rc == 0 and s["verdict"] == "PASS", log
