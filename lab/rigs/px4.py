"""PX4 v1.16 SITL with SIH (the bundle's ``px4-sih-airplane``, airframe 10041, stock parameters).

PX4 SITL uses fixed UDP ports (one instance per machine): the rig holds ``/tmp/mpf-px4.lock``
(flock) for as long as its PX4 runs and waits for it otherwise. Ground-station link:
``udpout:127.0.0.1:18570``; the bridge listens on ``udpin:0.0.0.0:14540`` (PX4's onboard link
sends there from 14580). Take-off as the bundle's README does it: MAV_CMD_NAV_TAKEOFF with
param7 = home AMSL + the path altitude, arm; PX4 climbs out and loiters (AUTO.LOITER).
v1.16 SIH has no wind model: ``--wind`` is refused. ``--speedup`` sets PX4_SIM_SPEED_FACTOR,
which SIH honours (its loop runs that much faster in wall time).
"""

from __future__ import annotations

import fcntl
import math
import os
import subprocess
import time
from pathlib import Path
from typing import IO, Any

from lab.rigs.bundles import ROOT, die_with_parent, stop_process_group
from lab.rigs.gcs import Gcs
from mpf_mavlink.mavlink.modes import Flavour

NAME = "px4"
FLAVOUR = Flavour.PX4
DEFAULT_CONFIG = ROOT / "configs" / "bridge_px4.yaml"
TRACK_MODE, HOLD_MODE = "OFFBOARD", "AUTO.LOITER"
# the roll limit (deg) the autopilot flies its own hold within: what its hold is judged against
ROLL_LIMIT_PARAM = "FW_R_LIM"
HAS_WIND = False
LOCK = "/tmp/mpf-px4.lock"
MAV_CMD_NAV_TAKEOFF = 22


class Firmware:
    """One PX4 SIH process (under the machine-wide PX4 lock) and how the rig talks to it."""

    gcs_url = "udpout:127.0.0.1:18570"
    bridge_url = "udpin:0.0.0.0:14540"

    def __init__(self, a: Any) -> None:
        self.a = a
        self.proc: subprocess.Popen[bytes] | None = None
        self.lock: IO[str] | None = None

    def start(self, bundle: Path, work: Path) -> None:
        self.lock = open(LOCK, "w")  # noqa: SIM115 - held while PX4 runs
        try:
            fcntl.flock(self.lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            print(f"waiting for {LOCK} (another PX4 SITL runs on this machine)", flush=True)
            fcntl.flock(self.lock, fcntl.LOCK_EX)
        work.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ)
        if self.a.speedup != 1.0:
            env["PX4_SIM_SPEED_FACTOR"] = f"{self.a.speedup:g}"
        log = open(work / "px4.log", "w")  # noqa: SIM115 - lives as long as the process
        self.proc = subprocess.Popen(
            [str(bundle / "px4-sih-airplane"), str(work / "px4-work")],
            cwd=work, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env,
            start_new_session=True, preexec_fn=die_with_parent,
        )  # fmt: skip

    def configure(self, g: Gcs) -> dict[str, float]:
        return {}

    def take_off(self, g: Gcs, alt_m: float, timeout_s: float = 240.0) -> None:
        """NAV_TAKEOFF to home AMSL + alt_m and arm (retried until pre-flight checks pass),
        then wait for AUTO.LOITER at that altitude."""
        t_end = time.monotonic() + timeout_s
        while "GLOBAL_POSITION_INT" not in g.last:
            if time.monotonic() > t_end:
                raise RuntimeError("PX4 sent no GLOBAL_POSITION_INT")
            g.pump(0.5)

        def attempt() -> None:
            gp = g.last["GLOBAL_POSITION_INT"]
            home_amsl = (gp.alt - gp.relative_alt) / 1000.0
            g.command(MAV_CMD_NAV_TAKEOFF, -1, 0, 0, math.nan, math.nan, math.nan,
                      home_amsl + alt_m)  # fmt: skip
            g.pump(0.3)
            g.arm()

        g.arm_retrying(t_end, attempt, "PX4 did not arm (pre-flight checks) in time")
        print(f"armed; climbing to {alt_m:g} m", flush=True)
        g.climb_until(
            t_end,
            lambda gp: g.mode() == "AUTO.LOITER" and gp.relative_alt / 1000.0 >= alt_m - 5.0,
            lambda: f"the take-off did not reach AUTO.LOITER ({g.mode()})",
        )
        g.settle(10.0)  # settle into the loiter

    def cruise_airspeed(self, g: Gcs) -> float | None:
        return g.get_param("FW_AIRSPD_TRIM")

    def stop(self) -> None:
        stop_process_group(self.proc, 10)
        if self.lock is not None:
            fcntl.flock(self.lock, fcntl.LOCK_UN)
            self.lock.close()
            self.lock = None
