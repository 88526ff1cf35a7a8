"""The calibrated SIL's own error, as its calibration measured it: the 95 % bound carries it.

A bound from the SIL alone ignores how far the SIL is from the firmware it stands for. Each
shipped profile was checked against the real firmware on its calibration missions
(docs/calibration-<flavour>.md: real / SIL steady RMS per mission); the certificate multiplies
the SIL's one-sided bound by the worst of those ratios, floored at 1 (a SIL that was pessimistic
on every calibration mission keeps its own bound: the calibration gives no licence to shrink it).
Only the RMS is calibrated, so the max |pt| bound takes the same factor (an assumption, stated).
"""

from __future__ import annotations

from typing import Any

# real / SIL steady RMS of each calibration mission, as tabulated in docs/calibration-px4.md and
# docs/calibration-arduplane.md (tests/test_certify.py checks these against those tables)
CALIBRATION_RATIOS: dict[str, dict[str, float]] = {
    "px4-1.16-sih": {"stationary": 0.98, "moving": 1.07, "r120_h130": 0.89, "r200": 1.33},
    "arduplane-4.7": {"stationary": 0.73, "moving": 0.72, "r120_h130": 0.84, "wind6": 0.65},
}


def model_error(profile_label: str) -> dict[str, Any] | None:
    """The model-error factor (dimensionless, >= 1) of the profile named in ``profile_label``
    (the certificate's profile words, e.g. ``auto: px4-1.16-sih (autopilot part)``), or None
    for a profile without a recorded calibration (the plain emulation, a user's file)."""
    for name, ratios in CALIBRATION_RATIOS.items():
        if name in profile_label:
            worst = max(ratios, key=lambda k: ratios[k])
            return {
                "profile": name,
                "factor": max(1.0, ratios[worst]),
                "worst_mission": worst,
                "worst_ratio": ratios[worst],
                "ratios": dict(ratios),
                "source": f"docs/calibration-{name.split('-')[0]}.md",
            }
    return None
