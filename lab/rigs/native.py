"""The firmware's own guidance on the rig's mission: ``scripts/sitl ... --guidance native``.

What a ground station's "follow" does without this bridge: it re-centres the autopilot's own
loiter on the moving target at ``--rate`` Hz and lets the firmware's guidance fly the circle.

- ArduPlane: GUIDED, MAV_CMD_DO_REPOSITION (COMMAND_INT, MAV_FRAME_GLOBAL: altitude AMSL) with
  param3 = the circle's radius (used when > 0) and param4 = 0 (clockwise; non-zero is
  counter-clockwise). ArduPlane holds AIRSPEED_CRUISE as an indicated (equivalent) airspeed: the
  rig measures the ratio of true to indicated airspeed in the loiter before engaging (ground
  velocity less ArduPlane's WIND, over VFR_HUD.airspeed) and sets AIRSPEED_CRUISE so that the
  true airspeed is the config's ``vehicle.airspeed_m_s``.
- PX4: MAV_CMD_DO_ORBIT in Hold (AUTO.LOITER; v1.16 takes centre, radius and direction there:
  param1 = radius, > 0 clockwise; z AMSL), and MAV_CMD_DO_CHANGE_SPEED while loitering, with the
  config's airspeed as it is (PX4 flies that true airspeed; the ratio is recorded).

The centre is the moving path's centre (the target's position plus the path's ``center_m`` in
the target's frame) at the autopilot's time, the target's motion exactly the bridge's: the
config's target at the placed centre, its clock started when the rig engages. The track is
recorded from LOCAL_POSITION_NED (the frame the mission was placed in) and judged by
:func:`lab.rigs.figures.moving_path_figures`, the same function that judges MPF's run record.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lab.rigs.figures import moving_path_figures
from lab.rigs.gcs import Gcs
from mpf_mavlink.config.scenario import build_path, build_target
from mpf_mavlink.config.schema import load_config

MAV_CMD_DO_ORBIT = 34
MAV_CMD_DO_CHANGE_SPEED = 178
MAV_CMD_DO_REPOSITION = 192
MAV_FRAME_GLOBAL = 0  # COMMAND_INT: x, y in degE7, z in m AMSL
SPEED_TYPE_AIRSPEED = 0
#: the sphere each autopilot's flat-earth conversion uses (m): ArduPilot's
#: LOCATION_SCALING_FACTOR, PX4's map projection (CONSTANTS_RADIUS_OF_EARTH)
EARTH_RADIUS_M = {"arduplane": 6378100.0, "px4": 6371000.0}
#: a ratio of true to indicated airspeed outside this band is not a measurement (no airspeed
#: in VFR_HUD, a turn's transient): the rig then commands the config's airspeed as it is
EAS2TAS_BAND = (0.9, 1.3)
#: the mode the firmware's own circle flies in
NATIVE_MODE = {"arduplane": "GUIDED", "px4": "AUTO.LOITER"}


@dataclass(frozen=True)
class CommandInt:
    """One COMMAND_INT: ``params`` are param1..param4, ``x``/``y`` degE7, ``z`` m AMSL."""

    command: int
    frame: int
    params: tuple[float, float, float, float]
    x: int
    y: int
    z: float


def centre_command(
    autopilot: str, lat_deg: float, lon_deg: float, alt_amsl_m: float, radius_m: float,
    clockwise: bool,
) -> CommandInt:  # fmt: skip
    """The firmware's own circle about (lat, lon, alt AMSL) of ``radius_m`` (m)."""
    x, y = round(lat_deg * 1e7), round(lon_deg * 1e7)
    if autopilot == "arduplane":
        # param1 speed (ArduPlane ignores it), param2 1 = MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
        direction = 0.0 if clockwise else 1.0
        return CommandInt(
            MAV_CMD_DO_REPOSITION, MAV_FRAME_GLOBAL, (-1.0, 1.0, radius_m, direction), x, y,
            alt_amsl_m,
        )  # fmt: skip
    signed = radius_m if clockwise else -radius_m
    return CommandInt(
        MAV_CMD_DO_ORBIT, MAV_FRAME_GLOBAL, (signed, math.nan, math.nan, math.nan), x, y,
        alt_amsl_m,
    )  # fmt: skip


def change_speed_params(airspeed_m_s: float) -> tuple[float, float, float, float]:
    """MAV_CMD_DO_CHANGE_SPEED's param1..4: an airspeed (m/s), throttle unchanged (-1)."""
    return (float(SPEED_TYPE_AIRSPEED), float(airspeed_m_s), -1.0, 0.0)


@dataclass(frozen=True)
class Origin:
    """Where the autopilot's LOCAL_POSITION_NED is zero: latitude, longitude (deg), altitude
    (m AMSL), and the sphere (m) its flat-earth conversion uses."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    radius_m: float

    def to_global(self, n: float, e: float, d: float) -> tuple[float, float, float]:
        """(lat deg, lon deg, alt m AMSL) of the local NED point (m)."""
        lat = self.lat_deg + math.degrees(n / self.radius_m)
        lon = self.lon_deg + math.degrees(e / (self.radius_m * math.cos(math.radians(lat))))
        return lat, lon, self.alt_amsl_m - d

    @staticmethod
    def from_pairs(pairs: list[tuple[Any, Any]], radius_m: float) -> Origin:
        """The origin from (GLOBAL_POSITION_INT, LOCAL_POSITION_NED) pairs of one instant
        (each local position moved to its global sample's time with its velocity): the mean
        over the pairs, so that a few ms of timing between the two streams averages out."""
        lats, lons, alts = [], [], []
        for gp, lp in pairs:
            dt = (gp.time_boot_ms - lp.time_boot_ms) / 1000.0
            x, y, z = lp.x + lp.vx * dt, lp.y + lp.vy * dt, lp.z + lp.vz * dt
            lat = gp.lat / 1e7 - math.degrees(x / radius_m)
            lats.append(lat)
            lons.append(gp.lon / 1e7 - math.degrees(y / (radius_m * math.cos(math.radians(lat)))))
            alts.append(gp.alt / 1000.0 + z)
        return Origin(float(np.mean(lats)), float(np.mean(lons)), float(np.mean(alts)), radius_m)


def wind_to_ned(w: Any) -> tuple[float, float]:
    """ArduPilot's WIND (direction the wind comes FROM, deg; speed m/s) as the air's
    horizontal velocity (m/s, N, E)."""
    d = math.radians(w.direction)
    return -w.speed * math.cos(d), -w.speed * math.sin(d)


def _sample_origin_and_ratio(g: Gcs, autopilot: str, secs: float) -> tuple[Origin, float | None]:
    """Pump ``secs`` of the autopilot's time collecting position pairs and true/indicated
    airspeed samples (ground velocity less WIND when the autopilot sends one)."""
    pairs: list[tuple[Any, Any]] = []
    tas, ias = [], []
    t0, last_gp = g.t_boot_s, -1
    while g.t_boot_s - t0 < secs or len(pairs) < 5:
        g.pump(0.05, echo=False)
        gp, lp = g.last.get("GLOBAL_POSITION_INT"), g.last.get("LOCAL_POSITION_NED")
        if gp is None or lp is None or gp.time_boot_ms == last_gp:
            continue
        last_gp = gp.time_boot_ms
        if abs(gp.time_boot_ms - lp.time_boot_ms) <= 100:
            pairs.append((gp, lp))
        hud, wind = g.last.get("VFR_HUD"), g.last.get("WIND")
        if hud is not None and hud.airspeed > 1.0:
            wn, we = wind_to_ned(wind) if wind is not None else (0.0, 0.0)
            tas.append(math.sqrt((lp.vx - wn) ** 2 + (lp.vy - we) ** 2 + lp.vz**2))
            ias.append(hud.airspeed)
        if g.t_boot_s - t0 > 10 * secs:
            raise RuntimeError("no matching GLOBAL_POSITION_INT / LOCAL_POSITION_NED samples")
    ratio = float(np.mean(tas) / np.mean(ias)) if ias else None
    if ratio is not None and not EAS2TAS_BAND[0] <= ratio <= EAS2TAS_BAND[1]:
        ratio = None
    return Origin.from_pairs(pairs, EARTH_RADIUS_M[autopilot]), ratio


def send_command_int(g: Gcs, c: CommandInt) -> None:
    g.c.mav.command_int_send(g.sys, g.comp, c.frame, c.command, 0, 0, *c.params, c.x, c.y, c.z)


class _Acks:
    """The COMMAND_ACKs of the commands the rig sent (first result, refusals)."""

    def __init__(self) -> None:
        self.seen: dict[int, list[int]] = {}
        self._last: Any = None

    def poll(self, g: Gcs) -> None:
        m = g.last.get("COMMAND_ACK")
        if m is not None and m is not self._last:
            self._last = m
            self.seen.setdefault(int(m.command), []).append(int(m.result))


@dataclass(frozen=True)
class _MovingCircle:
    """The firmware's circle about the moving path's centre: the target, the centre in the
    target's frame (m), the autopilot's local origin, the radius (m) and the direction."""

    autopilot: str
    target: Any
    c_T: np.ndarray
    origin: Origin
    radius: float
    clockwise: bool

    def centre_at(self, t: float) -> tuple[np.ndarray, Any]:
        """The centre (m, local NED) at the target's time t (s), and the target's state."""
        st = self.target.state(t)
        return st.position + st.R_T_I @ self.c_T, st

    def send(self, g: Gcs, t: float) -> None:
        """Re-centre the firmware's circle on where the centre is at t (s)."""
        lat, lon, alt = self.origin.to_global(*self.centre_at(t)[0])
        c = centre_command(self.autopilot, lat, lon, alt, self.radius, self.clockwise)
        send_command_int(g, c)


def _command_speed(a: argparse.Namespace, g: Gcs, cfg: Any, ratio: float | None) -> dict[str, Any]:
    """Command the config's true airspeed (m/s) as each autopilot takes it; returns what was
    wanted, measured and set."""
    want = float(cfg.vehicle.airspeed_m_s)
    # ArduPlane's AIRSPEED_CRUISE is indicated; PX4's DO_CHANGE_SPEED flew the true airspeed
    # it was given (11.57 m/s commanded, 11.54 m/s true in SIH's still air)
    indicated = want / ratio if (ratio is not None and a.autopilot == "arduplane") else want
    speed: dict[str, Any] = {
        "true_airspeed_wanted_m_s": want,
        "true_over_indicated_measured": ratio,
        "indicated_commanded_m_s": indicated,
    }
    if a.autopilot == "arduplane":
        g.set_param("AIRSPEED_CRUISE", indicated)
        speed["set"] = f"AIRSPEED_CRUISE={indicated:.3f}"
    else:
        g.command(MAV_CMD_DO_CHANGE_SPEED, *change_speed_params(indicated))
        speed["set"] = f"MAV_CMD_DO_CHANGE_SPEED airspeed {indicated:.3f} m/s"
    return speed


def _track(
    a: argparse.Namespace, g: Gcs, circle: _MovingCircle, lp0: Any
) -> tuple[np.ndarray, list[str], int, _Acks]:
    """Re-centre at ``--rate`` Hz for ``--duration`` s of the target's time (0 at ``lp0``);
    returns the track's rows, the modes seen, the commands sent and their acks."""
    t0 = lp0.time_boot_ms / 1000.0
    period = 1.0 / a.rate
    next_send = period
    rows: list[tuple[float, ...]] = []
    modes: list[str] = []
    last_ms = lp0.time_boot_ms
    sends, acks = 1, _Acks()
    while True:
        g.pump(0.05, echo=True)
        acks.poll(g)
        if not modes or modes[-1] != g.mode():
            modes.append(g.mode())
        lp = g.last.get("LOCAL_POSITION_NED")
        if lp is None or lp.time_boot_ms == last_ms:
            continue
        last_ms = lp.time_boot_ms
        t = lp.time_boot_ms / 1000.0 - t0
        if t >= next_send:
            circle.send(g, t)
            sends += 1
            next_send += period * max(1.0, math.floor((t - next_send) / period) + 1.0)
        _, st = circle.centre_at(t)
        p = np.array([lp.x, lp.y, lp.z])
        tp = st.position
        rel = st.R_T_I.T @ (p - tp)
        w = g.last.get("WIND")
        wn, we = wind_to_ned(w) if w is not None else (math.nan, math.nan)
        rows.append((t, lp.x, lp.y, lp.z, lp.vx, lp.vy, lp.vz, *tp, *rel, wn, we))
        if t >= a.duration:
            break
    return np.array(rows, float), modes, sends, acks


def _track_figures(cols: np.ndarray, path: Any, cfg: Any, out: Path) -> tuple[dict[str, Any], Any]:
    """Write DIR/native_track.csv and DIR/native_path_T.csv; the track's figures and the mean
    true airspeed (m/s) flown over the steady window (None without one)."""
    names = "t,p_n,p_e,p_d,v_n,v_e,v_d,tgt_n,tgt_e,tgt_d,rel_x,rel_y,rel_z,wind_n,wind_e"
    np.savetxt(out / "native_track.csv", cols, delimiter=",", header=names, comments="",
               fmt="%.4f")  # fmt: skip
    nodes = path.positions()
    np.savetxt(out / "native_path_T.csv", nodes, delimiter=",", header="x,y,z", comments="",
               fmt="%.6f")  # fmt: skip
    t_col = cols[:, 0]
    fig = moving_path_figures(
        t_col, cols[:, 10:13], nodes, path.closed, cfg.metrics.steady_after_s,
        cfg.metrics.converge_threshold_m, circle=True,
    )  # fmt: skip
    m = t_col >= cfg.metrics.steady_after_s
    wind_ok = np.isfinite(cols[:, 13])
    wn_, we_ = np.where(wind_ok, cols[:, 13], 0.0), np.where(wind_ok, cols[:, 14], 0.0)
    tas = np.sqrt((cols[:, 4] - wn_) ** 2 + (cols[:, 5] - we_) ** 2 + cols[:, 6] ** 2)
    return fig, float(np.mean(tas[m])) if m.any() else None


def _why_not_flown(cmd: int, results: list[int], modes: list[str], mode: str, fig: Any) -> str:
    """The verdict: FLOWN, or FAIL with every reason (no or refused acks of ``cmd``, the mode
    left, no steady window)."""
    why = []
    if not results:
        why.append(f"no COMMAND_ACK for command {cmd}")
    elif any(r != 0 for r in results):
        why.append(f"command {cmd} refused {sum(r != 0 for r in results)} of {len(results)} times")
    if not modes or modes[-1] != mode:
        why.append(f"not in {mode} at the end (modes {' -> '.join(modes)})")
    if fig.get("e_rms_m") is None or not math.isfinite(fig["e_rms_m"]):
        why.append("no steady window")
    return "FLOWN" if not why else "FAIL: " + "; ".join(why)


def fly_native(
    a: argparse.Namespace,
    v: dict[str, Any],
    g: Gcs,
    centre: list[float],
    sets: list[str],
    out: Path,
) -> dict[str, Any]:
    """Fly the firmware's own guidance for ``--duration`` s about the moving centre; returns the
    summary's native part (what was set and sent, the figures, the verdict)."""
    cfg = load_config(v["config"], sets)  # the config with the placed target, as the bridge has
    path, target = build_path(cfg.path), build_target(cfg.target)
    if cfg.path.type != "circle" or cfg.path.radius_m is None:
        raise RuntimeError(
            "--guidance native flies the firmware's circle: path.type must be circle"
        )
    t_placed = g.t_boot_s  # place_mission predicted the start --lead s from now
    origin, ratio = _sample_origin_and_ratio(g, a.autopilot, min(4.0, a.lead * a.speedup))
    circle = _MovingCircle(
        a.autopilot, target, np.asarray(cfg.path.center_m, float), origin,
        float(cfg.path.radius_m), bool(cfg.path.clockwise),
    )  # fmt: skip
    speed = _command_speed(a, g, cfg, ratio)
    # engage where place_mission put the start: --lead s after placing, as the bridge is given
    g.wait_boot(max(0.0, a.lead * a.speedup - (g.t_boot_s - t_placed)))
    mode = NATIVE_MODE[a.autopilot]
    if g.mode() != mode:
        g.set_mode(mode)
    lp0 = g.last["LOCAL_POSITION_NED"]  # the target's clock: t = 0 when the rig engages
    circle.send(g, 0.0)
    print(f"native: {mode}, centre re-sent at {a.rate:g} Hz, {speed['set']}", flush=True)
    if a.autopilot == "px4":  # PX4 takes the speed while it loiters: once more, now in orbit
        g.pump(0.3, echo=False)
        g.command(MAV_CMD_DO_CHANGE_SPEED, *change_speed_params(speed["indicated_commanded_m_s"]))
    cols, modes, sends, acks = _track(a, g, circle, lp0)
    fig, speed["true_airspeed_flown_m_s"] = _track_figures(cols, path, cfg, out)
    cmd = MAV_CMD_DO_REPOSITION if a.autopilot == "arduplane" else MAV_CMD_DO_ORBIT
    results = acks.seen.get(cmd, [])
    fig["engaged"] = bool(results) and results[0] == 0 and mode in modes
    fig["tracked_s"] = float(cols[-1, 0]) if len(cols) else 0.0
    return {
        "guidance": "native",
        "native": {
            "command": "MAV_CMD_DO_REPOSITION (GUIDED)"
            if a.autopilot == "arduplane"
            else "MAV_CMD_DO_ORBIT (Hold)",
            "rate_hz": a.rate,
            "centre_commands_sent": sends,
            "acks": {
                str(k): vv[:3] + ([f"... {len(vv)} in all"] if len(vv) > 3 else [])
                for k, vv in acks.seen.items()
            },  # fmt: skip
            "speed": speed,
            "origin": [origin.lat_deg, origin.lon_deg, origin.alt_amsl_m],
            "t0_boot_s": lp0.time_boot_ms / 1000.0,
            "modes": modes,
        },
        "figures": fig,
        "verdict": _why_not_flown(cmd, results, modes, mode, fig),
    }
