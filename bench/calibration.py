"""Bench group ``calibration`` (``python -m bench --only calibration``): how far our
SIL, with the shipped autopilot profiles, is from the real firmware on the calibration matrix.

The real side is stored in the repository (lab/calibration/flights/<autopilot>.json: each real
flight's mission, the rig's overrides, its start state and the bridge's metrics, written by
``python -m lab.calibration.calibrate store``); only the SIL legs fly here, from each real
flight's start state, so the group runs on a bare clone (no firmware bundle). Per row: the real
and SIL steady RMS (the bridge's view on both sides), their ratio real / SIL, the mean radial and
vertical of both, and whether the row is within issue 24's band (ratio in [0.67, 1.5], means
within 0.3 m). PX4 rows average ``PX4_SEEDS`` SIL draws (EKF2's errors make one flight a draw);
ArduPlane's profile has only 1 mrad of attitude noise, so one draw.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any

PROFILES = {
    "arduplane": "configs/autopilots/arduplane-4.7.yaml",
    "px4": "configs/autopilots/px4-1.16-sih.yaml",
}
PX4_SEEDS = 3
ARDUPLANE_SEEDS = 1


def _line(autopilot: str, r: dict[str, Any]) -> str:
    def g(v: Any, f: str) -> str:
        return "n/a" if v is None else format(v, f)

    return (
        f"[calibration] {autopilot:<9} {r['mission']:<10} real {g(r['real_rms_m'], '.3f')} m  "
        f"SIL {g(r['sil_rms_m'], '.3f')} m  ratio {g(r['ratio'], '.2f')}  "
        f"radial {g(r['real_radial_m'], '+.2f')} / {g(r['sil_radial_m'], '+.2f')} m  "
        f"vertical {g(r['real_vertical_m'], '+.2f')} / {g(r['sil_vertical_m'], '+.2f')} m  "
        f"{'within' if r['within'] else 'OUT'}"
    )


def calibration(
    autopilots: tuple[str, ...] = ("arduplane", "px4"), log: Any = None
) -> dict[str, Any]:
    """Fly the SIL legs of the stored calibration matrix with the shipped profiles; per
    autopilot and mission the real and SIL figures, and the count of rows within the band."""
    from lab.calibration.calibrate import ROOT, sil_rows

    say = log or (lambda s: print(s, file=sys.stderr, flush=True))
    out: dict[str, Any] = {}
    within = total = 0
    for ap in autopilots:
        seeds = PX4_SEEDS if ap == "px4" else ARDUPLANE_SEEDS
        with tempfile.TemporaryDirectory(prefix=f"mpf-bench-cal-{ap}-") as d:
            rows = sil_rows(
                ap, ROOT / PROFILES[ap], Path(d), seeds, log=lambda r, ap=ap: say(_line(ap, r))
            )
        out[ap] = {
            r["mission"]: {
                k: r[k]
                for k in (
                    "real_rms_m",
                    "sil_rms_m",
                    "ratio",
                    "real_radial_m",
                    "sil_radial_m",
                    "real_vertical_m",
                    "sil_vertical_m",
                    "within",
                    "sil_seeds_rms_m",
                )
            }
            for r in rows
        }
        within += sum(bool(r["within"]) for r in rows)
        total += len(rows)
    out["rows_within_band"] = f"{within} of {total}"
    return out
