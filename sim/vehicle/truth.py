"""The plant's truth, one row per frame, as arrays on demand (:meth:`TruthRecorder.truth`)."""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from sim.plant.jsbsim_plant import vector_floats

_COLS = 17


class TruthRecorder:
    """Rows of (t, time_boot_s, position, velocity, euler, airspeed, wind, throttle, mode).
    The target's state is a pure function of its time: computed in :meth:`truth`, off the
    lockstep frame's critical path."""

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled
        self._rows: list[tuple[float, ...]] = []
        self._tgt_rows: list[tuple[float, ...]] = []  # target position, velocity of the rows
        self._lock = threading.Lock()  # the target's rows: truth() may run beside the vehicle

    def record(self, t: float, boot_s: float, st: Any, custom_mode: int) -> None:
        """One row (every frame: a plant snapshot's floats read from its ``__dict__``, and no
        lock: a list's append is atomic, and :meth:`truth` reads a copy of the list)."""
        if not self.enabled:
            return
        d = getattr(st, "__dict__", {})
        p, v, w = d.get("_p"), d.get("_v"), d.get("_wind")
        if p is None or v is None or w is None:  # not a plant snapshot: its arrays
            p, v, w = (vector_floats(st, n) for n in ("position_ned", "velocity_ned", "wind_ned"))
        self._rows.append((t, boot_s, *p, *v, *st.euler, st.airspeed, *w, st.throttle,
                           custom_mode))  # fmt: skip

    def forget_target(self) -> None:
        """The target's epoch changed: its rows are recomputed on the new clock."""
        with self._lock:
            self._tgt_rows.clear()

    def truth(self, target: Any, epoch_boot_s: float) -> dict[str, np.ndarray]:
        """Plant truth at frame rate: t (s since ready), time_boot_s, position_ned (N,3),
        velocity_ned (N,3), euler (N,3: roll, pitch, yaw rad), airspeed (N), wind_ned (N,3),
        throttle (N), mode (N, custom_mode), target_t (N: the target's clock, s) and
        target_position / target_velocity (N,3) of ``target`` (motion.state(t)) if any."""
        with self._lock:
            A = np.array(self._rows[:], dtype=float).reshape(-1, _COLS)
            tgt = self._tgt_rows
            if target is not None:
                for tb in A[len(tgt) :, 1]:
                    ts = target.state(float(tb) - epoch_boot_s)
                    tgt.append((*ts.position, *ts.velocity))
            T = np.array(tgt, dtype=float).reshape(-1, 6)
        return {
            "t": A[:, 0],
            "time_boot_s": A[:, 1],
            "position_ned": A[:, 2:5],
            "velocity_ned": A[:, 5:8],
            "euler": A[:, 8:11],
            "airspeed": A[:, 11],
            "wind_ned": A[:, 12:15],
            "throttle": A[:, 15],
            "mode": A[:, 16].astype(np.int64),
            "target_position": T[:, 0:3],
            "target_velocity": T[:, 3:6],
            "target_t": A[:, 1] - epoch_boot_s,
        }
