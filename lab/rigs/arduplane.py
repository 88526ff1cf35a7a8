"""ArduPlane SITL (the bundle's ``bin/arduplane``, built-in "plane" model, stock plane.parm).

Instance ``-I N`` listens on TCP 5760+10N (SERIAL0: the rig's ground-station link) and 5762+10N
(SERIAL1: the bridge's link). Take-off as a pilot does it: TKOFF_ALT (the only parameter set for
flying; wind parameters when asked) to the path altitude, mode TAKEOFF, arm (retried until the
EKF and GPS let it), climb, then LOITER. Wind: SIM_WIND_SPD / SIM_WIND_DIR / SIM_WIND_TURB.
"""

from __future__ import annotations

import fcntl
import math
import socket
import subprocess
import time
from pathlib import Path
from typing import IO, Any

from lab.rigs.bundles import ROOT, RigError, die_with_parent, stop_process_group
from lab.rigs.gcs import Gcs
from mpf_mavlink.mavlink.modes import Flavour


def sil_wind_set(speed_m_s: float, from_deg: float) -> str:
    """The SIL's ``sil.wind_ned_m_s`` override for ArduPlane's SIM_WIND_SPD / SIM_WIND_DIR:
    SIM_WIND_DIR is where the wind comes FROM, the SIL's vector where the air moves TO (m/s)."""
    to = math.radians(from_deg + 180.0)
    return f"sil.wind_ned_m_s=[{speed_m_s * math.cos(to):.3f},{speed_m_s * math.sin(to):.3f},0.0]"


NAME = "arduplane"
FLAVOUR = Flavour.ARDUPILOT
DEFAULT_CONFIG = ROOT / "configs" / "bridge_arduplane.yaml"
TRACK_MODE, HOLD_MODE = "GUIDED", "LOITER"
# the roll limit (deg) the autopilot flies its own hold within: what its hold is judged against
ROLL_LIMIT_PARAM = "ROLL_LIMIT_DEG"
HAS_WIND = True


def ports(instance: int) -> tuple[int, int]:
    """(ground-station, bridge) TCP ports of instance N."""
    return 5760 + 10 * instance, 5762 + 10 * instance


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("0.0.0.0", port))  # ArduPilot binds every address
        except OSError:
            return False
    return True


def instance_free(n: int) -> bool:
    return all(_port_free(5760 + 10 * n + k) for k in range(4))


class InstanceLock:
    """An flock on /tmp/mpf-arduplane-I<N>.lock for as long as the rig runs instance N, so that
    two rigs (two tests, two users) that probe the same free ports cannot both take them."""

    def __init__(self, instance: int | None) -> None:
        self.f: IO[str] | None = None
        candidates = [instance] if instance is not None else list(range(1, 40))
        for n in candidates:
            f = open(f"/tmp/mpf-arduplane-I{n}.lock", "w")  # noqa: SIM115 - held while flying
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                f.close()
                continue
            if instance_free(n):
                self.f, self.instance = f, n
                return
            fcntl.flock(f, fcntl.LOCK_UN)
            f.close()
        which = f"-I {instance}" if instance is not None else "any of -I 1..39"
        raise RigError(f"ArduPlane SITL {which}: TCP ports in use (another SITL runs there)")

    def release(self) -> None:
        if self.f is not None:
            fcntl.flock(self.f, fcntl.LOCK_UN)
            self.f.close()
            self.f = None


class Firmware:
    """One ArduPlane SITL process and how the rig talks to it."""

    def __init__(self, a: Any) -> None:
        self.a = a
        self.lock = InstanceLock(a.instance)
        self.instance = self.lock.instance
        self.gcs_port, self.bridge_port = ports(self.instance)
        self.gcs_url = f"tcp:127.0.0.1:{self.gcs_port}"
        self.bridge_url = f"tcp:127.0.0.1:{self.bridge_port}"
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self, bundle: Path, work: Path) -> None:
        parm = bundle / "Tools" / "autotest" / "models" / "plane.parm"
        binary = self.a.binary or (bundle / "bin" / "arduplane")
        work.mkdir(parents=True, exist_ok=True)
        cmd = [str(binary), "--model", "plane", "--defaults", str(parm), f"-I{self.instance}",
               "--speedup", f"{self.a.speedup:g}"]  # fmt: skip
        log = open(work / "sitl.log", "w")  # noqa: SIM115 - lives as long as the process
        self.proc = subprocess.Popen(
            cmd,
            cwd=work,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            preexec_fn=die_with_parent,
        )

    def configure(self, g: Gcs) -> dict[str, float]:
        """Wind (SIM_WIND_*) when asked; returns what was set."""
        sets: dict[str, float] = {}
        if self.a.wind is not None:
            sets["SIM_WIND_SPD"], sets["SIM_WIND_DIR"] = self.a.wind
        if self.a.turbulence is not None:
            sets["SIM_WIND_TURB"] = self.a.turbulence
        for k, v in sets.items():
            g.set_param(k, v)
        return sets

    def take_off(self, g: Gcs, alt_m: float, timeout_s: float = 300.0) -> None:
        take_off(g, alt_m, timeout_s)

    def cruise_airspeed(self, g: Gcs) -> float | None:
        return g.get_param("AIRSPEED_CRUISE")

    def stop(self) -> None:
        stop_process_group(self.proc, 5)
        self.lock.release()


def take_off(g: Gcs, alt_m: float, timeout_s: float = 300.0) -> None:
    """TAKEOFF to alt_m (TKOFF_ALT), then LOITER; arming is retried until pre-arm passes
    (the rig's and the identification flights' take-off, :mod:`lab.calibration.identify`)."""
    g.set_param("TKOFF_ALT", alt_m)
    g.set_mode("TAKEOFF")
    t_end = time.monotonic() + timeout_s

    def attempt() -> None:
        if g.mode() != "TAKEOFF":
            g.set_mode("TAKEOFF")
        g.arm()

    g.arm_retrying(t_end, attempt, "SITL did not arm (pre-arm checks) in time")
    print(f"armed; climbing to {alt_m:g} m", flush=True)
    g.climb_until(
        t_end,
        lambda gp: gp.relative_alt / 1000.0 >= alt_m - 3.0,
        lambda: "the take-off did not reach the altitude in time",
    )
    g.set_mode("LOITER")
    g.settle(15.0)  # settle into the loiter at that altitude
