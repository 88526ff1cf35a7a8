"""Random and mutated MAVLink frames for fuzzing a MAVLink receiver (seeded, reproducible).

Classes of frames (``FrameFuzzer.frame()`` returns (class name, bytes)):

- ``random_bytes``: 1..96 random bytes, sometimes starting with a MAVLink magic byte;
- ``valid_v2`` / ``valid_v1``: a well-formed frame (valid CRC) of a random message of the
  ardupilotmega dialect from a random foreign system id, with random field values drawn from
  pools that include NaN, +-inf, +-1e38, integer extremes and random text;
- ``mutated``: a valid frame with bit flips, truncated, with trailing garbage, with the length
  byte changed (CRC left wrong, or recomputed so that the frame is "valid" with a wrong
  length), with the signed flag set but no signature, or with the magic of the other version;
- ``own_absurd``: valid-CRC frames from the vehicle's own (sysid, compid) whose contents are
  physically absurd: non-finite or out-of-range attitude, position, velocity, airspeed, wind and
  home, non-unit quaternions, and plausible attitude / position samples with absurd timestamps
  (0, 2^32-1, hours ahead or behind the vehicle's clock when ``now_ms`` is given). Also
  HEARTBEATs from the vehicle's id that cannot be its autopilot (other components, other
  autopilot types, MAV_AUTOPILOT_INVALID) and COMMAND_ACKs with random results.

What is NOT generated from the vehicle's own ids: well-formed, physically plausible telemetry
or a plausible mode report. Those are indistinguishable from the real autopilot at the MAVLink
level (only signing can tell them apart) and the bridge is right to act on them.
"""

from __future__ import annotations

import math
import random
import struct
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as M
from pymavlink.generator.mavcrc import x25crc

_INT_RANGES = {
    "int8_t": (-(2**7), 2**7 - 1),
    "uint8_t": (0, 2**8 - 1),
    "int16_t": (-(2**15), 2**15 - 1),
    "uint16_t": (0, 2**16 - 1),
    "int32_t": (-(2**31), 2**31 - 1),
    "uint32_t": (0, 2**32 - 1),
    "int64_t": (-(2**63), 2**63 - 1),
    "uint64_t": (0, 2**64 - 1),
    "uint8_t_mavlink_version": (0, 255),
}
FLOAT_POOL = (math.nan, math.inf, -math.inf, 1e38, -1e38, 3.4e38, -0.0, 0.0, 1e-45, 1e9, -1e9)
CLASSES = ("random_bytes", "valid_v2", "valid_v1", "mutated", "own_absurd")
DEFAULT_WEIGHTS = (0.25, 0.25, 0.10, 0.20, 0.20)

_MSG_CLASSES = sorted(M.mavlink_map.values(), key=lambda c: c.id)
_V1_CLASSES = [c for c in _MSG_CLASSES if c.id < 256]


class _Sink:
    def write(self, b: bytes) -> None:  # pragma: no cover - we pack, never send
        pass


# every system id but the vehicle's (1) and the companion's (191), the broadcast 0 excluded
FOREIGN_SYSIDS = tuple(i for i in range(2, 256) if i != 191)


class FrameFuzzer:
    """Seeded MAVLink frame generator. ``vehicle`` = (sysid, compid) of the autopilot;
    ``now_ms()`` optionally returns the vehicle's current time_boot_ms (for absurd-but-close
    timestamps)."""

    def __init__(
        self,
        seed: int = 0,
        vehicle: tuple[int, int] = (1, 1),
        now_ms: Callable[[], int | None] | None = None,
        weights: tuple[float, ...] = DEFAULT_WEIGHTS,
        foreign_sysids: tuple[int, ...] = FOREIGN_SYSIDS,
    ) -> None:
        if len(weights) != len(CLASSES):
            raise ValueError(f"weights must have {len(CLASSES)} entries")
        self.rng = random.Random(seed)
        self.vehicle = vehicle
        self.now_ms = now_ms or (lambda: None)
        self.weights = weights
        self.foreign = foreign_sysids
        self.counts: dict[str, int] = dict.fromkeys(CLASSES, 0)
        self.by_kind: dict[str, int] = {}
        self._mavs: dict[tuple[int, int], M.MAVLink] = {}

    def _mav(self, sysid: int, compid: int) -> M.MAVLink:
        key = (sysid, compid)
        m = self._mavs.get(key)
        if m is None:
            m = self._mavs[key] = M.MAVLink(_Sink(), srcSystem=sysid, srcComponent=compid)
        m.seq = self.rng.randrange(256)
        return m

    def _note(self, kind: str) -> None:
        self.by_kind[kind] = self.by_kind.get(kind, 0) + 1

    # -- values ----------------------------------------------------------------------------
    def _float(self) -> float:
        r = self.rng.random()
        if r < 0.35:
            return self.rng.choice(FLOAT_POOL)
        if r < 0.7:
            return self.rng.gauss(0.0, 10.0 ** self.rng.randrange(-3, 8))
        return struct.unpack("<f", self.rng.randbytes(4))[0]  # any bit pattern, NaNs included

    def _int(self, tp: str) -> int:
        lo, hi = _INT_RANGES.get(tp, (0, 255))
        return self.rng.choice((lo, hi, 0, self.rng.randint(lo, hi), self.rng.randint(lo, hi)))

    def _value(self, tp: str, n: int) -> object:
        if tp == "char":
            return bytes(self.rng.randrange(256) for _ in range(max(n, 1)))
        one = self._float if tp in ("float", "double") else (lambda: self._int(tp))
        return [one() for _ in range(n)] if n else one()

    def random_message(self) -> M.MAVLink_message:
        cls = self.rng.choice(_MSG_CLASSES)
        args = [self._value(tp, n) for tp, n in zip(cls.fieldtypes, cls.array_lengths, strict=True)]
        return cls(*args)

    # -- classes ---------------------------------------------------------------------------
    def random_bytes(self) -> bytes:
        b = bytearray(self.rng.randbytes(self.rng.randint(1, 96)))
        if self.rng.random() < 0.5:
            b[0] = self.rng.choice((0xFD, 0xFE))
        return bytes(b)

    def valid(self, v1: bool = False) -> bytes:
        for _ in range(20):
            cls = self.rng.choice(_V1_CLASSES if v1 else _MSG_CLASSES)
            args = [
                self._value(tp, n) for tp, n in zip(cls.fieldtypes, cls.array_lengths, strict=True)
            ]
            mav = self._mav(self.rng.choice(self.foreign), self.rng.randrange(256))
            try:
                return cls(*args).pack(mav, force_mavlink1=v1)
            except (struct.error, TypeError, ValueError, OverflowError):
                continue  # a value pymavlink cannot pack (e.g. a double into a float): draw again
        return self.random_bytes()

    def mutated(self) -> bytes:
        frame = bytearray(self.valid(v1=self.rng.random() < 0.3))
        op = self.rng.randrange(7)
        if op == 0:  # bit flips anywhere
            for _ in range(self.rng.randint(1, 4)):
                frame[self.rng.randrange(len(frame))] ^= 1 << self.rng.randrange(8)
            self._note("mut_bitflip")
        elif op == 1:  # truncated
            frame = frame[: self.rng.randrange(1, len(frame))]
            self._note("mut_truncated")
        elif op == 2:  # trailing garbage
            frame += self.rng.randbytes(self.rng.randint(1, 40))
            self._note("mut_trailing")
        elif op == 3:  # wrong length byte, CRC not updated
            frame[1] = self.rng.randrange(256)
            self._note("mut_len_badcrc")
        elif op == 4:  # wrong length, CRC recomputed: a "valid" frame of the wrong length
            frame = bytearray(self._relength(bytes(frame)))
            self._note("mut_len_goodcrc")
        elif op == 5:  # MAVLink 2 with the "signed" flag but no signature (or v1: flag byte junk)
            if frame[0] == 0xFD:
                frame[2] |= 0x01
            else:
                frame[2] = self.rng.randrange(256)
            self._note("mut_signed_flag")
        else:  # the other version's magic on this header
            frame[0] = 0xFE if frame[0] == 0xFD else 0xFD
            self._note("mut_magic")
        return bytes(frame)

    def _relength(self, frame: bytes) -> bytes:
        """Same message, payload cut or zero-padded to a random length, with a valid CRC."""
        v2 = frame[0] == 0xFD
        hl = 10 if v2 else 6
        plen = frame[1]
        msgid = (frame[7] | frame[8] << 8 | frame[9] << 16) if v2 else frame[5]
        cls = M.mavlink_map.get(msgid)
        payload = frame[hl : hl + plen]
        new_len = self.rng.randrange(0, 256)
        payload = (payload + bytes(256))[:new_len]
        hdr = bytearray(frame[:hl])
        hdr[1] = new_len
        crc = x25crc(bytes(hdr[1:]) + payload)
        if cls is not None:
            crc.accumulate(struct.pack("B", cls.crc_extra))
        return bytes(hdr) + payload + struct.pack("<H", crc.crc)

    # -- frames from the vehicle's own ids with absurd contents ------------------------------
    def own_absurd(self) -> bytes:
        s, c = self.vehicle
        mav = self._mav(s, c)
        now = self.now_ms()
        t_ok = now if now is not None else self.rng.randrange(2**32)
        kind, build = _OwnAbsurd.KINDS[self.rng.randrange(len(_OwnAbsurd.KINDS))]
        self._note(kind)
        own = _OwnAbsurd(self, t_ok, mav)
        msg = build(own)
        try:
            return msg.pack(own.mav)
        except (struct.error, OverflowError):  # pragma: no cover - pools are packable
            return self.random_bytes()

    # -- the mix ---------------------------------------------------------------------------
    def frame(self) -> tuple[str, bytes]:
        cls = self.rng.choices(CLASSES, self.weights)[0]
        if cls == "random_bytes":
            data = self.random_bytes()
        elif cls == "valid_v2":
            data = self.valid(False)
        elif cls == "valid_v1":
            data = self.valid(True)
        elif cls == "mutated":
            data = self.mutated()
        else:
            data = self.own_absurd()
        self.counts[cls] += 1
        return cls, data

    def datagram(self, max_frames: int = 4) -> tuple[int, bytes]:
        """One datagram of 1..max_frames frames (several frames in one datagram happen on
        real links and exercise the receiver's stream parser). Returns (frame count, bytes)."""
        n = 1 if self.rng.random() < 0.7 else self.rng.randint(2, max_frames)
        return n, b"".join(self.frame()[1] for _ in range(n))


class _OwnAbsurd:
    """The kinds of ``own_absurd`` frame, one builder each: a message from the vehicle's own
    ids (``mav``, which a builder may swap for another component's) whose contents are absurd.
    Every value is drawn from the fuzzer's generator, so a seed reproduces the frames."""

    def __init__(self, fz: FrameFuzzer, t_ok: int, mav: M.MAVLink) -> None:
        self.fz, self.r, self.t_ok, self.mav = fz, fz.rng, t_ok, mav

    def _a(self) -> float:
        return self.r.choice((math.nan, math.inf, -math.inf, 1e30, -1e30, 3.4e38, 1e9, -1e9, 7e6))

    def _time_ms(self) -> int:
        now = self.fz.now_ms()
        choices = [0, 1, 2**32 - 1, 2**31, self.r.randrange(2**32)]
        if now is not None:
            choices += [
                (now + 3_600_000) % 2**32,
                max(0, now - 3_600_000),
                (now + 86_400_000) % 2**32,
                (now + self.r.randrange(60_000, 10**9)) % 2**32,
            ]
        return self.r.choice(choices)

    def attitude_nonfinite(self) -> M.MAVLink_message:
        a = self._a
        return M.MAVLink_attitude_message(self.t_ok, a(), a(), a(), a(), a(), a())

    def attitude_rates(self) -> M.MAVLink_message:
        rate = self.r.choice((60.0, -1e4, 1e20))
        return M.MAVLink_attitude_message(self.t_ok, 0.1, 0.05, 1.0, rate, 0.0, 0.0)

    def _plausible(self, *half_widths: float) -> list[float]:
        """Uniform draws in +-each half-width: a plausible sample to carry an absurd time."""
        return [self.r.uniform(-h, h) for h in half_widths]

    def attitude_time(self) -> M.MAVLink_message:
        t = self._time_ms()  # drawn first: the seed's order
        return M.MAVLink_attitude_message(t, *self._plausible(0.5, 0.2, 3, 0.3, 0.3, 0.3))

    def attitude_quaternion(self) -> M.MAVLink_message:
        q = self.r.choice(
            (
                [0.0, 0.0, 0.0, 0.0],
                [2.0, 0.0, 0.0, 0.0],
                [self._a(), 0.0, 0.0, 0.0],
                [0.5, 0.5, 0.5, 0.2],
            )
        )
        return M.MAVLink_attitude_quaternion_message(self.t_ok, *q, 0.0, 0.0, 0.0, [0.0] * 4)

    def local_position(self) -> M.MAVLink_message:
        a = self._a
        return M.MAVLink_local_position_ned_message(self.t_ok, a(), a(), a(), a(), a(), a())

    def local_position_time(self) -> M.MAVLink_message:
        t = self._time_ms()
        n, e, vn, ve = self._plausible(500, 500, 15, 15)
        return M.MAVLink_local_position_ned_message(t, n, e, -100.0, vn, ve, 0.0)

    def global_position(self) -> M.MAVLink_message:
        r = self.r
        lat = r.choice((910_000_000, -910_000_000, 0, 2**31 - 1))
        lon = r.choice((1_810_000_000, 0, -(2**31)))
        alt = r.choice((-(2**31), 2**31 - 1, 60_000_000))
        vel = r.choice((32767, -32768))
        return M.MAVLink_global_position_int_message(
            self.t_ok, lat, lon, alt, alt, vel, vel, vel, r.choice((36001, 65534))
        )

    def vfr_hud(self) -> M.MAVLink_message:
        r, a = self.r, self._a
        return M.MAVLink_vfr_hud_message(
            r.choice((math.nan, -5.0, 1e6, math.inf)),
            a(),
            r.randrange(-32768, 32768),
            r.choice((65535, 1000)),
            a(),
            a(),
        )

    def wind(self) -> M.MAVLink_message:
        r, a = self.r, self._a
        if r.random() < 0.5:
            return M.MAVLink_wind_cov_message(
                r.randrange(2**63), a(), a(), a(), 0.0, 0.0, 0.0, 0.0, 0.0
            )
        return M.MAVLink_wind_message(a(), a(), a())

    def home(self) -> M.MAVLink_message:
        r, a = self.r, self._a
        return M.MAVLink_home_position_message(
            r.choice((950_000_000, 0)),
            r.choice((1_900_000_000, 0)),
            r.choice((2**31 - 1, -(2**31))),
            a(),
            a(),
            a(),
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            0.0,
            0.0,
            0,
        )

    def heartbeat_not_the_autopilot(self) -> M.MAVLink_message:
        r = self.r
        choice = r.randrange(3)
        if choice == 0:  # another component of the vehicle claiming to be an autopilot
            s, c = self.fz.vehicle
            self.mav = self.fz._mav(s, r.choice([x for x in range(1, 256) if x not in (c, 191)]))
            ap = r.choice((M.MAV_AUTOPILOT_PX4, M.MAV_AUTOPILOT_ARDUPILOTMEGA))
        elif choice == 1:  # the autopilot's ids, but an autopilot field it never sends
            ap = r.choice((M.MAV_AUTOPILOT_GENERIC, 4, 8, 18, 200))
        else:  # a GCS / companion on the vehicle's system id
            ap = M.MAV_AUTOPILOT_INVALID
        return M.MAVLink_heartbeat_message(
            r.randrange(256), ap, r.randrange(256), r.randrange(2**32), r.randrange(256), 3
        )

    def command_ack(self) -> M.MAVLink_message:
        r = self.r
        return M.MAVLink_command_ack_message(
            r.randrange(65536), r.randrange(256), r.randrange(256), r.randrange(2**31), 1, 191
        )

    # the draw picks one of these by index: their order is part of what a seed reproduces
    KINDS: tuple[tuple[str, Callable[[_OwnAbsurd], M.MAVLink_message]], ...] = (
        ("own_attitude_nonfinite", attitude_nonfinite),
        ("own_attitude_rates_absurd", attitude_rates),
        ("own_attitude_time_absurd", attitude_time),
        ("own_attitude_quaternion_absurd", attitude_quaternion),
        ("own_local_position_absurd", local_position),
        ("own_local_position_time_absurd", local_position_time),
        ("own_global_position_absurd", global_position),
        ("own_vfr_hud_absurd", vfr_hud),
        ("own_wind_absurd", wind),
        ("own_home_absurd", home),
        ("own_heartbeat_not_the_autopilot", heartbeat_not_the_autopilot),
        ("own_command_ack_random", command_ack),
    )


__all__ = ["CLASSES", "FrameFuzzer"]
