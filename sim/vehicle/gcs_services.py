"""What a ground station asks of the simulated vehicle besides flying it: the parameter protocol,
the mission protocol, AUTOPILOT_VERSION and MAVLink FTP, answered per flavour as PX4 v1.16 and
ArduPlane 4.7 do. One object composed into the vehicle (``SimVehicle.gcs``), reached through a
narrow interface: it reads the vehicle's state, sets its tunables through :class:`Param`
setters, and sends through the vehicle's MAVLink encoder (the outgoing delay queue).

Parameters (names and MAV_PARAM_TYPE of the real firmware; checked against ArduPlane 4.7-dev
SITL's own PARAM_REQUEST_LIST, PX4 from its parameter reference):

* PX4: COM_OF_LOSS_T, COM_OBL_RC_ACT, NAV_LOITER_RAD, FW_AIRSPD_TRIM / _MIN / _MAX, MAV_SYS_ID,
  and the RC-loss trio the bridge reads to describe its fallback (COM_RCL_EXCEPT, NAV_RCL_ACT,
  COM_RC_IN_MODE: PX4 v1.16 SITL's values, served and settable, nothing flies by them since the
  SIL has no RC). Integers are sent byte-wise (the int32's bytes in param_value), as PX4 does.
* ArduPlane: GUIDED_TIMEOUT (ArduPlane's forced-attitude timeout; 4.7-dev hard-codes the 3 s),
  WP_LOITER_RAD, AIRSPEED_CRUISE / _MIN / _MAX, MAV1_EXT_STAT / _POSITION / _EXTRA1..3 (the
  stream rates of the link, Hz), SIM_WIND_SPD / SIM_WIND_DIR (the plant's steady wind, m/s and
  the direction it blows FROM, deg), SYSID_THISMAV. Integers are C-cast to float, as ArduPilot.

A PARAM_SET of a known name takes effect at once for the rest of the run (the loss timeouts,
the loiter radius of the next hold entry and of the current one, the cruise airspeed clamped to
min..max, stream rates, the wind) and is echoed with PARAM_VALUE; a value the vehicle cannot fly
(not finite, out of the parameter's range) is not taken and the unchanged value is echoed, which
a ground station reads as a refused set. Unknown names get no answer, as from both autopilots.

Missions (mission_type 0): a plain mission (waypoints, loiters, take-off, land, RTL, speed
changes, DO_JUMP) is stored and served back; anything else is refused with MISSION_ACK
MAV_MISSION_UNSUPPORTED (or UNSUPPORTED_FRAME / INVALID_SEQUENCE). ArduPlane counts its home as
item 0 (a MISSION_REQUEST_LIST of a vehicle without a mission answers 1); PX4 answers 0. The
simulated autopilot does not fly the mission: AUTO loiters (see :mod:`sim.vehicle.vehicle`).
Fence and rally lists are empty and uploads of them are refused (UNSUPPORTED).

MAVLink FTP: every request is answered with a NAK (FileNotFound for an open, UnknownCommand
otherwise), so MAVProxy and QGroundControl fall back to PARAM_REQUEST_LIST at once; the
AUTOPILOT_VERSION capabilities do not advertise FTP either.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as M

# FTP (https://mavlink.io/en/services/ftp.html): header offsets and codes
_FTP_OPEN_RO, _FTP_OPEN_RW, _FTP_CREATE = 4, 11, 6
_FTP_NAK = 129
_FTP_ERR_UNKNOWN_COMMAND, _FTP_ERR_FILE_NOT_FOUND = 7, 10

# plain mission commands the SIL stores (a real autopilot flies them; the SIL loiters in AUTO)
_MISSION_COMMANDS = frozenset(
    (
        M.MAV_CMD_NAV_WAYPOINT,
        M.MAV_CMD_NAV_LOITER_UNLIM,
        M.MAV_CMD_NAV_LOITER_TURNS,
        M.MAV_CMD_NAV_LOITER_TIME,
        M.MAV_CMD_NAV_RETURN_TO_LAUNCH,
        M.MAV_CMD_NAV_LAND,
        M.MAV_CMD_NAV_TAKEOFF,
        M.MAV_CMD_NAV_LOITER_TO_ALT,
        M.MAV_CMD_DO_CHANGE_SPEED,
        M.MAV_CMD_DO_JUMP,
    )
)
_GLOBAL_FRAMES = frozenset(
    (
        M.MAV_FRAME_GLOBAL,
        M.MAV_FRAME_GLOBAL_RELATIVE_ALT,
        M.MAV_FRAME_GLOBAL_INT,
        M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        M.MAV_FRAME_GLOBAL_TERRAIN_ALT,
        M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
    )
)
_TO_FLOAT_FRAME = {
    M.MAV_FRAME_GLOBAL_INT: M.MAV_FRAME_GLOBAL,
    M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: M.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: M.MAV_FRAME_GLOBAL_TERRAIN_ALT,
}
_INT_TYPES = frozenset(
    (
        M.MAV_PARAM_TYPE_UINT8,
        M.MAV_PARAM_TYPE_INT8,
        M.MAV_PARAM_TYPE_UINT16,
        M.MAV_PARAM_TYPE_INT16,
        M.MAV_PARAM_TYPE_UINT32,
        M.MAV_PARAM_TYPE_INT32,
    )
)


@dataclass
class Param:
    """One parameter: its firmware name and MAV_PARAM_TYPE, the range of values the vehicle
    can fly with, and how it reads / sets the vehicle (``set`` None: read-only)."""

    name: str
    ptype: int
    get: Callable[[], float]
    set: Callable[[float], None] | None
    lo: float = -math.inf
    hi: float = math.inf


def _wind_from(v: Any) -> tuple[float, float]:
    """(speed m/s, direction it blows FROM, deg) of the plant's horizontal steady wind."""
    wn, we = float(v.steady_wind[0]), float(v.steady_wind[1])
    return math.hypot(wn, we), math.degrees(math.atan2(-we, -wn)) % 360.0


def _set_wind(v: Any, speed: float | None = None, from_deg: float | None = None) -> None:
    s, d = _wind_from(v)
    s = s if speed is None else speed
    d = d if from_deg is None else from_deg
    wd = float(v.steady_wind[2])
    w = (-s * math.cos(math.radians(d)), -s * math.sin(math.radians(d)), wd)
    v.steady_wind = w
    v.plant.set_wind(w)


def _random_wind(v: Any) -> float:
    """SIM_WIND_TURB (m/s) of the plant's random wind (0: off)."""
    rw = v.plant.random_wind
    return 0.0 if rw is None else float(rw.turbulence_m_s)


def _set_random_wind(v: Any, x: float) -> None:
    """SIM_WIND_TURB set in flight: the random wind restarts, seeded with the vehicle's seed."""
    v.plant.set_random_wind(float(x), int(v.config.seed))


def _set_loiter_radius(v: Any, r: float) -> None:
    v.tun.loiter_radius = float(r)
    v.modes.hold_radius = float(r)  # the hold being flown takes it too (both autopilots do)


def _set_airspeed(v: Any, which: str, x: float) -> None:
    tun = v.tun
    setattr(tun, which, float(x))
    tun.cruise_airspeed = min(max(tun.airspeed_trim, tun.airspeed_min), tun.airspeed_max)


def _rate_param(v: Any, name: str, streams: tuple[str, ...]) -> Param:
    def get() -> float:
        return float(getattr(v.telemetry.rates, streams[0]))

    def put(hz: float) -> None:
        for s in streams:
            v.telemetry.set_rate(s, float(hz))

    return Param(name, M.MAV_PARAM_TYPE_INT16, get, put, 0.0, 50.0)


def vehicle_params(v: Any) -> list[Param]:
    """The parameter table of vehicle ``v`` for its flavour (order = PARAM_VALUE index)."""
    tun = v.tun
    R32, I16, I32 = M.MAV_PARAM_TYPE_REAL32, M.MAV_PARAM_TYPE_INT16, M.MAV_PARAM_TYPE_INT32
    speed = (
        (lambda x: _set_airspeed(v, "airspeed_trim", x)),
        (lambda x: _set_airspeed(v, "airspeed_min", x)),
        (lambda x: _set_airspeed(v, "airspeed_max", x)),
    )
    if v.px4:
        return [
            Param("COM_OBL_RC_ACT", I32, lambda: tun.obl_rc_act,
                  lambda x: setattr(v.tun, "obl_rc_act", int(x)), 0, 7),
            Param("COM_OF_LOSS_T", R32, lambda: tun.com_of_loss_t,
                  lambda x: setattr(v.tun, "com_of_loss_t", float(x)), 0.0, 60.0),
            Param("COM_RCL_EXCEPT", I32, lambda: tun.rcl_except,
                  lambda x: setattr(v.tun, "rcl_except", int(x)), 0, 7),
            Param("COM_RC_IN_MODE", I32, lambda: tun.rc_in_mode,
                  lambda x: setattr(v.tun, "rc_in_mode", int(x)), 0, 4),
            Param("FW_AIRSPD_MAX", R32, lambda: tun.airspeed_max, speed[2], 0.5, 40.0),
            Param("FW_AIRSPD_MIN", R32, lambda: tun.airspeed_min, speed[1], 0.5, 40.0),
            Param("FW_AIRSPD_TRIM", R32, lambda: tun.airspeed_trim, speed[0], 0.5, 40.0),
            Param("MAV_SYS_ID", I32, lambda: float(v.sysid), None),
            Param("NAV_LOITER_RAD", R32, lambda: tun.loiter_radius,
                  lambda x: _set_loiter_radius(v, x), 25.0, 1000.0),
            Param("NAV_RCL_ACT", I32, lambda: tun.nav_rcl_act,
                  lambda x: setattr(v.tun, "nav_rcl_act", int(x)), 1, 6),
        ]  # fmt: skip
    wind = [
        Param("SIM_WIND_DIR", R32, lambda: _wind_from(v)[1],
              lambda x: _set_wind(v, from_deg=x), -360.0, 360.0),
        Param("SIM_WIND_SPD", R32, lambda: _wind_from(v)[0],
              lambda x: _set_wind(v, speed=x), 0.0, 50.0),
    ]  # fmt: skip
    if v.plant.has_random_wind:  # the firmware's random wind (jsbsim plant only)
        wind.append(Param("SIM_WIND_TURB", R32, lambda: _random_wind(v),
                          lambda x: _set_random_wind(v, x), 0.0, 50.0))  # fmt: skip
    return [
        Param("AIRSPEED_CRUISE", R32, lambda: tun.airspeed_trim, speed[0], 5.0, 100.0),
        Param("AIRSPEED_MAX", I16, lambda: tun.airspeed_max, speed[2], 5.0, 100.0),
        Param("AIRSPEED_MIN", I16, lambda: tun.airspeed_min, speed[1], 5.0, 100.0),
        Param("GUIDED_TIMEOUT", R32, lambda: tun.guided_timeout,
              lambda x: setattr(v.tun, "guided_timeout", float(x)), 0.1, 5.0),
        _rate_param(v, "MAV1_EXT_STAT", ("sys_status", "gps_raw")),
        _rate_param(v, "MAV1_EXTRA1", ("attitude",)),
        _rate_param(v, "MAV1_EXTRA2", ("vfr_hud",)),
        _rate_param(v, "MAV1_EXTRA3", ("wind", "system_time")),
        _rate_param(v, "MAV1_POSITION", ("global_position", "local_position")),
        *wind,
        Param("SYSID_THISMAV", I16, lambda: float(v.sysid), None),
        Param("WP_LOITER_RAD", I16, lambda: tun.loiter_radius,
              lambda x: _set_loiter_radius(v, x), 1.0, 32767.0),
    ]  # fmt: skip


def _text(field: Any) -> str:
    if isinstance(field, (bytes, bytearray)):
        field = field.decode("ascii", "replace")
    return str(field).split("\x00", 1)[0]


class GcsServices:
    """Parameter, mission, version and FTP answers of one simulated vehicle (module docstring).

    ``v`` is the vehicle (:class:`sim.vehicle.vehicle.SimVehicle`): read for its flavour, ids,
    home, state and tunables, and its ``_mav`` encoder sends the answers."""

    HANDLES = frozenset(
        ("PARAM_REQUEST_READ", "PARAM_REQUEST_LIST", "PARAM_SET", "MISSION_REQUEST_LIST",
         "MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT", "MISSION_REQUEST",
         "MISSION_REQUEST_INT", "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT", "MISSION_ACK",
         "FILE_TRANSFER_PROTOCOL")
    )  # fmt: skip

    def __init__(self, vehicle: Any) -> None:
        self.v = vehicle
        self.params = vehicle_params(vehicle)
        self._by_name = {p.name: i for i, p in enumerate(self.params)}
        self.missions = MissionService(vehicle)
        self.counts: dict[str, int] = {}  # messages answered, by type (diagnostics and tests)

    # ------------------------------------------------------------------ dispatch
    def handle(self, msg: Any) -> None:
        """Answer one message of :attr:`HANDLES` addressed to the vehicle (or broadcast)."""
        mt = msg.get_type()
        if getattr(msg, "target_system", 0) not in (0, self.v.sysid):
            return
        self.counts[mt] = self.counts.get(mt, 0) + 1
        owner = self.missions if mt.startswith("MISSION_") else self
        getattr(owner, "_on_" + mt.lower())(msg)

    # ------------------------------------------------------------------ parameters
    def value_of(self, name: str) -> float:
        """The current value of parameter ``name`` (KeyError for an unknown one)."""
        return float(self.params[self._by_name[name]].get())

    def _wire_value(self, p: Param) -> float:
        x = float(p.get())
        if p.ptype in _INT_TYPES:
            n = int(round(x))
            if self.v.px4:  # PX4 puts the integer's bytes into the float (byte-wise encoding)
                return float(struct.unpack("<f", struct.pack("<i", n))[0])
            return float(n)
        return x

    def _send_param(self, i: int, index: int | None = None) -> None:
        p = self.params[i]
        mav = self.v.link.mav
        mav.send(mav.param_value_encode(p.name.encode("ascii"), self._wire_value(p), p.ptype,
                                        len(self.params),
                                        i if index is None else index))  # fmt: skip

    def _on_param_request_list(self, msg: Any) -> None:
        for i in range(len(self.params)):
            self._send_param(i)

    def _on_param_request_read(self, msg: Any) -> None:
        """By index when param_index >= 0, else by name (the MAVLink rule)."""
        index = int(msg.param_index)
        if index >= 0:
            i: int | None = index if index < len(self.params) else None
        else:
            i = self._by_name.get(_text(msg.param_id))
        if i is None:
            return  # both autopilots stay silent about a parameter they do not have
        # ArduPilot answers a read by name with index 65535 (-1); PX4 with the index
        self._send_param(i, 65535 if index < 0 and not self.v.px4 else None)

    def _decode_set(self, p: Param, msg: Any) -> float:
        x = float(msg.param_value)
        if p.ptype in _INT_TYPES and self.v.px4 and msg.param_type in _INT_TYPES:
            x = float(struct.unpack("<i", struct.pack("<f", x))[0])  # byte-wise, as PX4 sends
        return x

    def _on_param_set(self, msg: Any) -> None:
        i = self._by_name.get(_text(msg.param_id))
        if i is None:
            return  # unknown: no answer, as both autopilots
        p = self.params[i]
        x = self._decode_set(p, msg)
        if p.ptype in _INT_TYPES and math.isfinite(x):
            x = float(round(x))
        if p.set is not None and math.isfinite(x) and p.lo <= x <= p.hi:
            p.set(x)
        # the value now in force (unchanged when refused); ArduPilot echoes with index 65535
        self._send_param(i, None if self.v.px4 else 65535)

    # ------------------------------------------------------------------ version, FTP
    def capabilities(self) -> int:
        """MAV_PROTOCOL_CAPABILITY bits of what this vehicle answers (no FTP: it NAKs)."""
        c = (M.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
             | M.MAV_PROTOCOL_CAPABILITY_MISSION_INT | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
             | M.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
             | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2)  # fmt: skip
        if self.v.px4:
            return int(c | M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE)
        return int(c | M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST)

    def send_autopilot_version(self) -> None:
        """AUTOPILOT_VERSION: the firmware the flavour stands for (PX4 v1.16.0 official,
        ArduPlane 4.7.0-dev), custom version "mpf-sil" so nobody mistakes it for the real one."""
        if self.v.px4:
            sw = (1 << 24) | (16 << 16) | (0 << 8) | M.FIRMWARE_VERSION_TYPE_OFFICIAL
        else:
            sw = (4 << 24) | (7 << 16) | (0 << 8) | M.FIRMWARE_VERSION_TYPE_DEV
        custom = list(b"mpf-sil\x00")
        mav = self.v.link.mav
        mav.send(mav.autopilot_version_encode(self.capabilities(), sw, 0, 0, 0, custom, [0] * 8,
                                              [0] * 8, 0, 0, 0))  # fmt: skip

    def _on_file_transfer_protocol(self, msg: Any) -> None:
        p = bytes(bytearray(msg.payload))
        if len(p) < 12:
            return
        seq = (int.from_bytes(p[0:2], "little") + 1) & 0xFFFF
        op = p[3]
        err = (_FTP_ERR_FILE_NOT_FOUND if op in (_FTP_OPEN_RO, _FTP_OPEN_RW, _FTP_CREATE)
               else _FTP_ERR_UNKNOWN_COMMAND)  # fmt: skip
        hdr = seq.to_bytes(2, "little") + bytes((p[2], _FTP_NAK, 1, op, 0, 0)) + bytes(4)
        payload = list(hdr + bytes((err,))) + [0] * (251 - 13)
        mav = self.v.link.mav
        mav.send(
            mav.file_transfer_protocol_encode(
                0, msg.get_srcSystem(), msg.get_srcComponent(), payload
            )
        )


__all__ = ["GcsServices", "Param", "vehicle_params"]


class MissionService:
    """The mission protocol (mission_type 0) of one vehicle: upload, download, clear, set
    current (module docstring). Fence and rally lists are empty and refused."""

    def __init__(self, vehicle: Any) -> None:
        self.v = vehicle
        self.mission: list[Any] = []  # MISSION_ITEM_INT messages as uploaded (seq order)
        self._upload: dict[str, Any] | None = None  # {"count", "items", "src"}

    def _ack(self, msg: Any, result: int, mission_type: int = 0) -> None:
        mav = self.v.link.mav
        mav.send(mav.mission_ack_encode(msg.get_srcSystem(), msg.get_srcComponent(), result,
                                        mission_type))  # fmt: skip

    def _home_item(self) -> Any:
        lat, lon, alt = self.v.home_lla
        return M.MAVLink_mission_item_int_message(
            0,
            0,
            0,
            M.MAV_FRAME_GLOBAL,  # as ArduPilot sends its home
            M.MAV_CMD_NAV_WAYPOINT,
            0,
            1,
            0.0,
            0.0,
            0.0,
            0.0,
            int(round(lat * 1e7)),
            int(round(lon * 1e7)),
            float(alt),
            0,
        )

    def items(self) -> list[Any]:
        """The mission list a ground station downloads (ArduPlane: home first)."""
        if self.v.px4 or self.mission:
            return list(self.mission)
        return [self._home_item()]

    def _on_mission_request_list(self, msg: Any) -> None:
        mt = int(getattr(msg, "mission_type", 0))
        n = len(self.items()) if mt == M.MAV_MISSION_TYPE_MISSION else 0
        mav = self.v.link.mav
        mav.send(mav.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(), n, mt))

    def _send_item(self, msg: Any, as_int: bool) -> None:
        mt = int(getattr(msg, "mission_type", 0))
        items = self.items() if mt == M.MAV_MISSION_TYPE_MISSION else []
        seq = int(msg.seq)
        if not 0 <= seq < len(items):
            self._ack(msg, M.MAV_MISSION_INVALID_SEQUENCE, mt)
            return
        it, mav = items[seq], self.v.link.mav
        dst = (msg.get_srcSystem(), msg.get_srcComponent())
        common = (seq, it.frame, it.command, int(seq == 0 and self.v.px4), it.autocontinue,
                  it.param1, it.param2, it.param3, it.param4)  # fmt: skip
        if as_int:
            mav.send(mav.mission_item_int_encode(*dst, *common, it.x, it.y, it.z, mt))
        else:
            frame = _TO_FLOAT_FRAME.get(it.frame, it.frame)
            mav.send(mav.mission_item_encode(*dst, seq, frame, *common[2:], it.x * 1e-7,
                                             it.y * 1e-7, it.z, mt))  # fmt: skip

    def _on_mission_request_int(self, msg: Any) -> None:
        self._send_item(msg, True)

    def _on_mission_request(self, msg: Any) -> None:
        self._send_item(msg, False)

    def _request(self, seq: int) -> None:
        up, mav = self._upload, self.v.link.mav
        assert up is not None
        mav.send(mav.mission_request_int_encode(*up["src"], seq, 0))

    def _on_mission_count(self, msg: Any) -> None:
        mt = int(getattr(msg, "mission_type", 0))
        if mt != M.MAV_MISSION_TYPE_MISSION:
            self._ack(msg, M.MAV_MISSION_UNSUPPORTED, mt)
            return
        n = int(msg.count)
        if n == 0:
            self.mission, self._upload = [], None
            self._ack(msg, M.MAV_MISSION_ACCEPTED)
            return
        if n > 500:
            self._ack(msg, M.MAV_MISSION_NO_SPACE)
            return
        self._upload = {
            "count": n,
            "items": [],
            "src": (msg.get_srcSystem(), msg.get_srcComponent()),
        }
        self._request(0)

    def _on_mission_item_int(self, msg: Any) -> None:
        self._take_item(msg)

    def _on_mission_item(self, msg: Any) -> None:
        """A float MISSION_ITEM: stored as MISSION_ITEM_INT (degrees * 1e7 in a global frame)."""
        f = msg.frame
        glob = f in _GLOBAL_FRAMES
        to_int = {M.MAV_FRAME_GLOBAL: M.MAV_FRAME_GLOBAL_INT,
                  M.MAV_FRAME_GLOBAL_RELATIVE_ALT: M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                  M.MAV_FRAME_GLOBAL_TERRAIN_ALT: M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT}  # fmt: skip
        if not (math.isfinite(msg.x) and math.isfinite(msg.y)):
            self._finish_upload(msg, M.MAV_MISSION_INVALID_PARAM5_X)
            return
        it = M.MAVLink_mission_item_int_message(
            msg.target_system, msg.target_component, msg.seq, to_int.get(f, f), msg.command,
            msg.current, msg.autocontinue, msg.param1, msg.param2, msg.param3, msg.param4,
            int(round(msg.x * 1e7)) if glob else int(msg.x),
            int(round(msg.y * 1e7)) if glob else int(msg.y),
            msg.z, getattr(msg, "mission_type", 0),
        )  # fmt: skip
        it._header = msg._header
        self._take_item(it, msg)

    def _finish_upload(self, msg: Any, result: int) -> None:
        self._upload = None
        self._ack(msg, result)

    def _take_item(self, it: Any, raw: Any = None) -> None:
        raw = it if raw is None else raw
        up = self._upload
        if up is None or int(getattr(it, "mission_type", 0)) != M.MAV_MISSION_TYPE_MISSION:
            return  # not uploading (a late duplicate): ignored, as both autopilots
        seq = int(it.seq)
        if seq != len(up["items"]):
            self._request(len(up["items"]))  # out of order: ask again for the one awaited
            return
        home_item = seq == 0 and not self.v.px4  # ArduPilot's item 0 is home: any frame
        if it.command not in _MISSION_COMMANDS and not home_item:
            self._finish_upload(raw, M.MAV_MISSION_UNSUPPORTED)
            return
        if (not home_item and it.command not in (M.MAV_CMD_DO_CHANGE_SPEED, M.MAV_CMD_DO_JUMP)
                and it.frame not in _GLOBAL_FRAMES):  # fmt: skip
            self._finish_upload(raw, M.MAV_MISSION_UNSUPPORTED_FRAME)
            return
        if not all(math.isfinite(x) for x in (it.param1, it.param2, it.param3, it.z)):
            self._finish_upload(raw, M.MAV_MISSION_INVALID)
            return
        up["items"].append(it)
        if len(up["items"]) < up["count"]:
            self._request(len(up["items"]))
            return
        self.mission = up["items"]
        self._finish_upload(raw, M.MAV_MISSION_ACCEPTED)

    def _on_mission_clear_all(self, msg: Any) -> None:
        mt = int(getattr(msg, "mission_type", 0))
        if mt in (M.MAV_MISSION_TYPE_MISSION, M.MAV_MISSION_TYPE_ALL):
            self.mission, self._upload = [], None
        self._ack(msg, M.MAV_MISSION_ACCEPTED, mt)

    def _on_mission_set_current(self, msg: Any) -> None:
        n = len(self.items())
        mav = self.v.link.mav
        if 0 <= msg.seq < n:
            mav.send(mav.mission_current_encode(int(msg.seq), n))
        else:
            self._ack(msg, M.MAV_MISSION_INVALID_SEQUENCE)

    def _on_mission_ack(self, msg: Any) -> None:
        """The end of a download: nothing to answer."""
