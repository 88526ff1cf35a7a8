"""Progress of a SIL run (:func:`sim.sil.run_sil`): a bar over the tracking seconds with the
bridge's events above it, and the peers' CPU time over the tracking phase."""

from __future__ import annotations

import math
import os
import re
import sys
import time
from pathlib import Path
from typing import Any

# the bridge's life-cycle lines ("[TRACKING]"), as opposed to its check results ("[PASS] ...")
_STATE_MARK = re.compile(r"^\[[A-Z_]+\]$")


def _cpu_s(pid: int) -> float | None:
    """CPU seconds (user + system) a process has used so far (Linux /proc), else None."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


class _Progress:
    """Progress for long runs: a bar over the tracking seconds, the bridge's events above it.
    Also samples the peers' CPU time over the tracking phase (a load-independent cost figure)."""

    def __init__(
        self,
        duration: float,
        enabled: bool,
        log: Any,
        pids: tuple[int, int] = (0, 0),
        spin_s: Any = None,
    ):
        self.duration, self.enabled, self.log = duration, enabled, log
        self.pids = pids
        # the vehicle's CPU time spent spinning in its lockstep wait so far (s), sampled with cpu
        self.spin_s = spin_s if spin_s is not None else (lambda: 0.0)
        self.spin0 = self.spin1 = 0.0
        self.cpu0: list[float | None] = [None, None]
        self.cpu1: list[float | None] = [None, None]
        self.t_end: float | None = None
        self.next_line = 0.1
        self.t_track: float | None = None
        self.bar: Any = None
        self.wall_track = 0.0

    def note(self, text: str) -> None:
        if self.enabled:
            self._write(text)

    def _write(self, text: str) -> None:
        if self.bar is not None:
            self.bar.write(text, file=sys.stderr)
        else:
            self.log(text)

    def event(self, text: str, t: float) -> None:
        if text.startswith("[TRACKING]"):
            self.t_track, self.wall_track = t, time.perf_counter()
            self.cpu0 = [_cpu_s(p) for p in self.pids]
            self.spin0 = float(self.spin_s())
            self.next_line = 0.1
            if self.enabled and sys.stderr.isatty():
                from tqdm import tqdm

                self.bar = tqdm(
                    total=round(self.duration),
                    desc="tracking",
                    unit="s",
                    file=sys.stderr,
                    mininterval=0.5,
                    bar_format="{desc} {n}/{total} s sim |{bar:24}| {elapsed} wall{postfix}",
                )
        elif text.startswith("[HANDBACK]") or text.startswith("[DONE]"):
            if self.t_end is None and self.t_track is not None:
                self.cpu1 = [_cpu_s(p) for p in self.pids]
                self.spin1 = float(self.spin_s())
                self.t_end = t
            self.update(t)
        if self.enabled and not _STATE_MARK.match(text):  # states are shown by the bar
            self._write(f"bridge: {text}")

    def update(self, t: float) -> None:
        if self.t_track is None or not self.enabled:
            return
        if self.bar is None:  # not a terminal (a log, CI): a plain line every 10 %
            done = (t - self.t_track) / self.duration
            if done + 1e-9 >= self.next_line and self.t_end is None:
                wall = time.perf_counter() - self.wall_track
                rtf = (t - self.t_track) / max(wall, 1e-9)
                self.log(
                    f"tracking {t - self.t_track:6.0f} / {self.duration:g} s simulated, "
                    f"{rtf:.0f}x real time"
                )
                self.next_line = math.floor(done * 10 + 1e-9) / 10 + 0.1
            return
        n = min(round(self.duration), max(0, int(t - self.t_track)))
        if n > self.bar.n:
            wall = time.perf_counter() - self.wall_track
            self.bar.set_postfix_str(
                f"{(t - self.t_track) / max(wall, 1e-9):.0f}x real time", refresh=False
            )
            self.bar.update(n - self.bar.n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
