"""What the bridge shows an operator's ground station while it flies: a few NAMED_VALUE_FLOAT
values of the guidance at a low rate, and a STATUSTEXT on every life-cycle state and on the
reason it stops. Autopilots forward both to their other links (ArduPilot routes messages without
a target to every link; PX4 with forwarding on), so MAVProxy / QGroundControl on the vehicle's
telemetry radio see them; the SIL vehicle does the same (sim/vehicle/endpoint.py).

Values (names <= 10 characters, as NAMED_VALUE_FLOAT allows; ``time_boot_ms`` = the vehicle's
time of the ATTITUDE the step answered):

- ``MPF_pt``    |pt|, the distance to the path's moving point (m)
- ``MPF_psi``   Psi, the attitude error function in [0, 1]
- ``MPF_sdot``  the virtual point's progression rate (m/s)
- ``MPF_state`` the bridge's life-cycle state (:class:`~mpf_mavlink.bridge.base.State` value)

Off the control path: a control step sends its setpoint first, then (at most every
1 / ``operator_display_hz`` s of vehicle time) these four packets. ``mavlink.operator_display:
false`` sends nothing. The texts start ``MPF:`` (never one of the replay markers ``MPF t0=`` ...).
"""

from __future__ import annotations

import itertools
from typing import Any

from mpf_mavlink.mavlink import dialect

#: STATUSTEXT payload (MAVLink 2): 50 characters per chunk; longer texts go in chunks with an id
_CHUNK = 50
_MAX_CHUNKS = 4


class OperatorDisplay:
    """Rate-limited guidance values and state texts for a ground station (module docstring).

    Holds no link: the bridge passes its :class:`~mpf_mavlink.mavlink.link.Link` in."""

    def __init__(self, enabled: bool = True, rate_hz: float = 2.0) -> None:
        self.enabled = bool(enabled) and rate_hz > 0.0
        self.period_s = 1.0 / rate_hz if rate_hz > 0.0 else float("inf")
        self._next_t: float | None = None  # vehicle time (s) of the next values
        self._ids = itertools.count(1)
        self.values_sent = 0
        self.texts_sent = 0
        self.stop_said = False

    def values(self, link: Any, step: Any, state: int) -> None:
        """After a control step's setpoint: the four values, when 1 / rate_hz s of vehicle time
        have passed since the last ones."""
        if not self.enabled or link is None:
            return
        t = float(step.t_boot_s)
        if self._next_t is not None and t < self._next_t:
            return
        self._next_t = t + self.period_s
        mav, ms, d = link.mav, int(step.time_boot_ms), step.diag
        values = (
            (b"MPF_pt", d.pt_norm),
            (b"MPF_psi", d.psi),
            (b"MPF_sdot", step.cmd.sdot),
            (b"MPF_state", float(state)),
        )
        # in one datagram: the peer wakes up once for the four
        link.send_many([mav.named_value_float_encode(ms, n, float(v)) for n, v in values])
        self.values_sent += 1

    def text(self, link: Any, text: str, severity: int = dialect.MAV_SEVERITY_INFO) -> None:
        """One STATUSTEXT ``MPF: <text>`` (chunked beyond 50 characters, at most 200)."""
        if not self.enabled or link is None:
            return
        raw = ("MPF: " + text).encode("ascii", "replace")[: _CHUNK * _MAX_CHUNKS]
        chunks = [raw[i : i + _CHUNK] for i in range(0, len(raw), _CHUNK)] or [b""]
        # a text in one chunk has id 0; a chunked one shares an id (receivers join them)
        tid = 0 if len(chunks) == 1 else next(self._ids) & 0xFFFF
        for seq, chunk in enumerate(chunks):
            link.send(link.mav.statustext_encode(severity, chunk, tid, seq))
        self.texts_sent += 1

    def stopped(self, link: Any, reason: str, ok: bool) -> None:
        """The reason the bridge stops (once): NOTICE for a completed mission, else WARNING."""
        if self.stop_said or not reason:
            return
        self.stop_said = True
        sev = dialect.MAV_SEVERITY_NOTICE if ok else dialect.MAV_SEVERITY_WARNING
        try:
            self.text(link, f"stop: {reason}", sev)
        except Exception:  # noqa: BLE001 - a closed link must not hide the real exit
            pass
