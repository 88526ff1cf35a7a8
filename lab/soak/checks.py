"""The soak campaign's checks (:mod:`lab.soak`) on what the relay's tap saw: every setpoint
within the adapter's limits for the config (:class:`Limits`), gaps in a stream, the bridge's
silences; ``_r`` rounds figures for the result rows."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from lab.soak.rig import CONFIGS, VEHICLE_COMPID, VEHICLE_SYSID, Tap
from mpf_mavlink.mavlink.wire_limits import TYPE_MASK_ARDUPLANE_ATTITUDE


@dataclass
class Limits:
    """The adapter's output limits for a config (what every SET_ATTITUDE_TARGET must respect)."""

    max_roll_rate: float
    max_pitch_rate: float
    max_yaw_rate: float
    thrust_min: float
    thrust_max: float
    max_bank: float
    min_pitch: float
    max_pitch: float

    @classmethod
    def for_config(cls, flavour: str, sets: tuple[str, ...] = ()) -> Limits:
        # the import registers the bridge's config sections
        from mpf_mavlink.config import bridge as bridge_config  # noqa: F401
        from mpf_mavlink.config.schema import load_config

        cfg = load_config(CONFIGS[flavour], list(sets))
        a = cfg.section("adapter")
        return cls(
            a.max_roll_rate_rad_s,
            a.max_pitch_rate_rad_s,
            a.max_yaw_rate_rad_s,
            a.thrust_min,
            a.thrust_max,
            cfg.vehicle.max_bank_rad,
            a.min_pitch_rad,
            a.max_pitch_rad,
        )


def setpoint_violations(tap: Tap, flavour: str, lim: Limits, tol: float = 1e-5) -> list[str]:
    """Every SET_ATTITUDE_TARGET the vehicle received, against the adapter's limits, the
    flavour's type_mask and the vehicle's own clock (a setpoint's time_boot_ms must be within
    5 s of the vehicle's latest ATTITUDE time seen before it)."""
    bad: list[str] = []
    att = tap.attitude_ms
    j = 0
    last_ms: int | None = None
    for e in tap.setpoints:
        m = e.msg
        while j < len(att) and att[j][0] <= e.t:
            last_ms = att[j][1]
            j += 1
        vals = [m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate, m.thrust, *m.q]
        why = None
        if not all(math.isfinite(v) for v in vals):
            why = "non-finite field"
        elif (m.target_system, m.target_component) != (VEHICLE_SYSID, VEHICLE_COMPID):
            why = f"target {m.target_system}/{m.target_component}"
        elif not lim.thrust_min - tol <= m.thrust <= lim.thrust_max + tol:
            why = f"thrust {m.thrust}"
        elif last_ms is not None and abs(int(m.time_boot_ms) - last_ms) > 5000:
            why = f"time_boot_ms {m.time_boot_ms} vs vehicle {last_ms}"
        elif flavour == "px4":
            if m.type_mask != 128 or list(m.q) != [1.0, 0.0, 0.0, 0.0]:
                why = f"type_mask {m.type_mask} q {list(m.q)}"
            elif (
                abs(m.body_roll_rate) > lim.max_roll_rate + tol
                or abs(m.body_pitch_rate) > lim.max_pitch_rate + tol
                or abs(m.body_yaw_rate) > lim.max_yaw_rate + tol
            ):
                why = f"rates {m.body_roll_rate:.3f} {m.body_pitch_rate:.3f} {m.body_yaw_rate:.3f}"
        else:
            w, x, y, z = m.q
            n = math.sqrt(w * w + x * x + y * y + z * z)
            roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
            pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
            yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
            if m.type_mask != TYPE_MASK_ARDUPLANE_ATTITUDE or abs(n - 1.0) > 1e-5:
                why = f"type_mask {m.type_mask} |q| {n}"
            elif (
                abs(roll) > lim.max_bank + tol
                or not lim.min_pitch - tol <= pitch <= lim.max_pitch + tol
                or abs(yaw) > 1e-5
            ):
                why = f"roll {roll:.3f} pitch {pitch:.3f} yaw {yaw:.3g}"
        if why is not None:
            bad.append(f"t={e.t:.2f}: {why}")
    return bad


def max_gap(times: list[float], t_from: float | None = None, t_to: float | None = None) -> float:
    ts = [t for t in times if (t_from is None or t >= t_from) and (t_to is None or t <= t_to)]
    return max((b - a for a, b in zip(ts, ts[1:], strict=False)), default=math.inf)


def bridge_silence(
    setpoints: list[float], telemetry: list[float], t_from: float | None, t_to: float | None
) -> float:
    """Longest pause in setpoints (s) not explained by a pause in the telemetry they answer:
    for each gap between setpoints, the gap less the longest telemetry gap inside it. A stalled
    vehicle, relay or machine pauses both streams; a bridge that choked on input pauses only
    its own."""
    sp = [t for t in setpoints if (t_from is None or t >= t_from) and (t_to is None or t <= t_to)]
    tel = sorted(telemetry)
    worst = 0.0
    for a, b in zip(sp, sp[1:], strict=False):
        if b - a <= 0.05:
            continue
        inside = [a] + [t for t in tel if a < t < b] + [b]
        tel_gap = max(y - x for x, y in zip(inside, inside[1:], strict=False))
        worst = max(worst, (b - a) - tel_gap)
    return worst


def _r(x: Any, nd: int = 3) -> Any:
    return None if x is None else (round(float(x), nd) if isinstance(x, (int, float)) else x)
