"""The coordination link of a fleet (``fleet`` section; docs/fleet.md): N bridges on one path.

Each bridge tells its peers where its virtual point is, at ``fleet.rate_hz``, in one standard
MAVLink message, DEBUG_VECT (#250):

- ``name``: ``"MPF"`` + the path id (:func:`path_id`, 7 hex digits of
  the path, the target and its epoch): a peer whose id differs flies another path and is refused;
- ``time_usec``: Unix time (us) at which s held (the hosts' clocks are the common time base:
  NTP or GPS on real aircraft; one clock in the SITL rig);
- ``x``: s modulo the path's length (m), ``y``: sdot (m/s), ``z``: the member's configured slot
  (degrees of one lap).

The sender is the message's system id (``fleet.sysid``, default 100 + member). Signed (MAVLink 2)
when ``mavlink.signing_key_file`` is set, with the bridge's key; unsigned or badly signed reports
are then dropped by the link and counted. A report older than the newest one of that peer
(late, reordered or duplicated) is discarded; a peer silent for ``peer_timeout_s`` is dropped,
and with ``on_peer_lost: respace`` the living members spread evenly again. A peer announcing
this aircraft's own slot, or a slot not in ``slots_deg``, is refused.

:class:`FleetMember` is what :mod:`mpf_mavlink.bridge.live` calls at every control step: it
reads the link (never blocks), sends when due and returns the airspeed set-point
(:mod:`mpf_mavlink.core.guidance.coordination`). A broken link never stops the flight: the
aircraft then flies its reference speed alone and the failure is counted.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mpf_mavlink.config.fleet import FleetConfig
from mpf_mavlink.config.schema import config_to_dict
from mpf_mavlink.core.guidance import coordination as co
from mpf_mavlink.errors import MpfError

MSG_PREFIX = "MPF"
MAV_COMP_ID_ONBOARD_COMPUTER = 191


def report_name(pid: str) -> str:
    """The DEBUG_VECT name of a path id: "MPF" + 7 hex digits (the field holds 10 chars)."""
    return (MSG_PREFIX + pid)[:10]


WIND_PREFIX = "MPW"


def wind_name(pid: str) -> str:
    """The DEBUG_VECT name of a member's lap-clock wind on that path: "MPW" + 7 hex digits."""
    return (WIND_PREFIX + pid)[:10]


def path_id(cfg: Any) -> str:
    """Seven hex digits naming the moving path (path, target and the target's epoch): the
    coordination messages carry it, and a peer whose id differs flies another path."""
    d = config_to_dict(cfg)
    key = {"path": d["path"], "target": d["target"], "epoch": d["fleet"]["target_epoch_unix_s"]}
    text = json.dumps(key, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:7]


@dataclass
class _Peer:
    sysid: int
    slot_deg: float
    report: co.PeerReport | None = None
    last_rx: float = -math.inf  # our clock (s) at its newest report
    lost: bool = False


@dataclass
class FleetCounts:
    rx: int = 0
    accepted: int = 0
    stale_or_reordered: int = 0
    other_path: int = 0
    same_slot: int = 0
    unknown_slot: int = 0
    bad_value: int = 0
    sent: int = 0
    send_errors: int = 0
    read_errors: int = 0
    peers_lost: int = 0
    extra: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, int]:
        d = {k: v for k, v in self.__dict__.items() if k != "extra"}
        d.update(self.extra)
        return d


def path_motion(path: Any, s: float, tgt: Any) -> tuple[co.Vec3, co.Vec3]:
    """(f1, v_point) in NED at s (m): the path's unit tangent and its point's inertial velocity
    (m/s) with the target's motion ``tgt`` (a TargetState)."""
    pt = path.eval(s)
    R = tgt.R_T_I
    p_d, f1T = pt[0], pt[1]
    f1v = R @ f1T
    w = tgt.omega_T
    wxp = (w[1] * p_d[2] - w[2] * p_d[1], w[2] * p_d[0] - w[0] * p_d[2],
           w[0] * p_d[1] - w[1] * p_d[0])  # fmt: skip
    rot = R @ wxp
    f1 = (float(f1v[0]), float(f1v[1]), float(f1v[2]))
    vp = (float(tgt.velocity[0] + rot[0]), float(tgt.velocity[1] + rot[1]),
          float(tgt.velocity[2] + rot[2]))  # fmt: skip
    return f1, vp


def path_airspeed(f: FleetConfig, path: Any, u: float, s: float, vs: Any, tgt: Any) -> float:
    """Spacing on the path: the airspeed (m/s) that moves the aircraft at s (m) along the path
    at u (m/s), |u f1 + v_point - wind| at the path point ``f.lead_s`` ahead, before the
    airspeed window (``vs`` the VehicleState, ``tgt`` the TargetState)."""
    f1, vp = path_motion(path, s + u * f.lead_s, tgt)
    R = tgt.R_T_I
    wind = _wind(vs)
    a = co.airspeed_for(u, f1, vp, wind)
    a = u + f.ff_gain * (a - u)  # the lap's swing, scaled
    k_u = f.speed_gain
    if k_u > 0.0:
        # the along-path speed flown now against the one asked: the energy control alone
        # follows a set-point that swings every lap with ~30 % less amplitude (measured)
        here = path.eval(s)
        f1n = R @ here[1]
        v_a = float(vs.airspeed)
        w1 = vs.R_W_I[:, 0]
        u_now = sum(float((v_a * w1[k] + wind[k] - vp[k]) * f1n[k]) for k in range(3))
        a += k_u * (u - u_now)
    return a


def _wind(vs: Any) -> tuple[float, float, float]:
    """The wind (m/s NED) of a VehicleState (calm when it has none)."""
    w = getattr(vs, "wind", (0.0, 0.0, 0.0))
    return (float(w[0]), float(w[1]), float(w[2]))


class FleetRecord:
    """fleet.csv, one row a control step (:attr:`HEADER`): streamed to ``path`` as the flight
    goes (flushed each second: a SIGKILLed bridge's record is there too, for the rig to judge
    the fleet before the kill), or written at the end without one. Never ends a flight."""

    HEADER = ("t_unix_s", "t_s", "s_m", "sdot_m_s", "e_m", "du_m_s", "airspeed_sp_m_s",
              "n_peers", "slot_deg", "shat_m", "du_v_m_s")  # fmt: skip

    def __init__(self) -> None:
        self.path: Path | None = None
        self.rows: list[tuple[float, ...]] = []
        self._fh: Any = None
        self._flushed = -math.inf

    def add(self, row: tuple[float, ...], now: float) -> None:
        """One step's row at ``now`` (Unix s)."""
        self.rows.append(row)
        if self.path is None:
            return
        try:
            if self._fh is None:
                self._fh = open(self.path, "w", newline="")  # noqa: SIM115 - whole flight
                self._fh.write(",".join(self.HEADER) + "\n")
            self._fh.write(",".join(repr(float(x)) for x in row) + "\n")
            if now - self._flushed >= 1.0:
                self._flushed = now
                self._fh.flush()
        except OSError:
            self.path = None

    def close(self, out: Path, log: Callable[[str], None]) -> None:
        """The streamed file closed, or every row written to ``out``/fleet.csv."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None
            return
        try:
            with open(out / "fleet.csv", "w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(self.HEADER)
                w.writerows(self.rows)
        except OSError as e:
            log(f"fleet: could not write fleet.csv: {e}")


class FleetWind:
    """The lap clock's wind (spacing in time): this member's estimate averaged over
    ``fleet.lap_wind_tau_s`` (co.LapWind: a gust moves the aircraft, it does not re-map the
    lap), told to the peers at 1 Hz (DEBUG_VECT "MPW" + path id: x, y, z the wind m/s NED) and,
    with ``fleet.share_wind``, meaned with theirs so that every member computes one clock."""

    def __init__(self, f: FleetConfig, pid: str, n: FleetCounts) -> None:
        self.f, self.n = f, n
        self.avg = co.LapWind(f.lap_wind_tau_s)
        self.name = wind_name(pid)
        self.own: co.Vec3 | None = None  # this member's average
        self.lap: co.Vec3 = (0.0, 0.0, 0.0)  # the fleet's: the mean of the members' averages
        self.peers: dict[int, tuple[co.Vec3, float]] = {}  # sysid: (wind, our clock)
        self.t_sent = -math.inf

    def take(self, sysid: int, name: str, msg: Any, now: float) -> bool:
        """A peer's averaged wind; True when accepted."""
        if name != self.name:
            return False  # another path's (its reports are refused and counted)
        w = (float(msg.x), float(msg.y), float(msg.z))
        if not all(math.isfinite(v) and abs(v) < 100.0 for v in w):
            self.n.bad_value += 1
            return False
        self.peers[sysid] = (w, now)
        self.n.extra["wind_rx"] = self.n.extra.get("wind_rx", 0) + 1
        return True

    def update(
        self, estimate: co.Vec3, dt: float, alive: list[_Peer], now: float,
        send: Callable[[Any], None],
    ) -> co.Vec3:  # fmt: skip
        """The lap clock's wind now (m/s NED) from this member's ``estimate`` ``dt`` s after
        the last; the living peers' averages (heard within peer_timeout_s) meaned in."""
        own = self.own = self.avg(estimate, dt)
        if not self.f.share_wind:
            self.lap = own
            return own
        if now - self.t_sent >= 1.0:
            self.t_sent = now
            send(debug_vect(self.name, now, own))
        ws = [own]
        for p in alive:
            got = self.peers.get(p.sysid)
            if got is not None and now - got[1] <= self.f.peer_timeout_s:
                ws.append(got[0])
        k = float(len(ws))
        self.lap = (sum(w[0] for w in ws) / k, sum(w[1] for w in ws) / k, sum(w[2] for w in ws) / k)
        return self.lap


def debug_vect(name: str, now: float, xyz: co.Vec3) -> Any:
    """The DEBUG_VECT ``name`` stamped ``now`` (Unix s) carrying ``xyz``."""
    from mpf_mavlink.mavlink import dialect

    x, y, z = (float(v) for v in xyz)
    return dialect.MAVLink_debug_vect_message(name.encode(), int(now * 1e6), x, y, z)


class FleetMember:
    """This aircraft on the coordination link. ``now``: the common clock (Unix s)."""

    def __init__(
        self,
        cfg: Any,
        path: Any,
        log: Callable[[str], None] = print,
        now: Callable[[], float] = time.time,
        signing: tuple[bytes, int] | None = None,
    ) -> None:
        self.cfg = cfg
        self.f: FleetConfig = cfg.section("fleet")
        self.path = path
        self.L = float(path.length)
        self.log, self.now = log, now
        self.pid = path_id(cfg)
        self.name = report_name(self.pid)
        self.slot_deg = float(self.f.slots_deg[self.f.member])
        self.slot = self.f.slots[self.f.member]
        u_ref = co.reference_speed(self.f, cfg.vehicle)
        self.params = co.CoordParams(self.L, self.f.k_c, self.f.du_max_m_s, u_ref)
        # spacing in time: the lap clock of this path (shat of s, docs/fleet.md), its table
        # recomputed at the report rate (the target turns and the wind changes slowly)
        self.lap = co.LapClock(path) if self.f.spacing == "time" else None
        self.t_lap = -math.inf
        # ... in the wind averaged over fleet.lap_wind_tau_s (co.LapWind: a gust moves the
        # aircraft, it does not re-map the lap)
        self.n = FleetCounts()
        self.wind = FleetWind(self.f, self.pid, self.n)
        self.window = co.airspeed_window(self.f, cfg.vehicle)
        self.signing = signing
        self.links: list[tuple[Any, bool]] = []  # (Link, written)
        self.peers: dict[int, _Peer] = {}
        self.lp = co.LowPass(self.f.filter_tau_s)
        # spacing in time: the inner loop on the measured along-path speed (k_v 0: none)
        self.gs = (
            co.GroundSpeedLoop(self.f.ground_speed_gain, self.f.ground_speed_tau_s)
            if self.lap is not None and self.f.ground_speed_gain > 0.0 else None
        )  # fmt: skip
        self.t_sent = -math.inf
        self.t_prev: float | None = None
        self.record = FleetRecord()
        self.last: dict[str, float] = {}
        self._warned: set[str] = set()

    # -- link -------------------------------------------------------------------------------
    def open(self) -> None:
        """Open every ``fleet.links`` URL (MpfError, one line, for a bad one)."""
        from mpf_mavlink.mavlink import enable_signing, open_link

        for url in self.f.links:
            link = open_link(
                url, source_system=self.f.link_sysid,
                source_component=MAV_COMP_ID_ONBOARD_COMPUTER, vehicle_sysid=None,
            )  # fmt: skip
            if self.signing is not None:
                enable_signing(link, self.signing[0], self.signing[1])
            self.links.append((link, not url.startswith("udpin:")))
        self.log(
            f"fleet: member {self.f.member} (slot {self.slot_deg:g} deg, sysid "
            f"{self.f.link_sysid}) on {', '.join(self.f.links)}; reports {self.name}"
        )

    def close(self) -> None:
        for link, _ in self.links:
            try:
                link.close()
            except Exception:  # noqa: BLE001 - closing must never end the flight's records
                self.n.read_errors += 1
        self.links = []

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            self.log(f"fleet: {text}")

    def poll(self) -> None:
        """Take in every report waiting on the links (never blocks)."""
        for link, _ in self.links:
            try:
                msgs = link.recv_all(0.0)
            except Exception:  # noqa: BLE001 - a broken link must not end the flight
                self.n.read_errors += 1
                continue
            for msg in msgs:
                if msg.get_type() == "DEBUG_VECT":
                    self.take(msg.get_srcSystem(), msg)

    def take(self, sysid: int, msg: Any) -> bool:
        """One DEBUG_VECT from system ``sysid``; True when accepted."""
        name = msg.name
        name = name.decode(errors="replace") if isinstance(name, bytes) else str(name)
        name = name.rstrip("\x00")
        if name.startswith(WIND_PREFIX):
            return self.wind.take(sysid, name, msg, self.now())
        if not name.startswith(MSG_PREFIX):
            return False  # someone else's debug vector
        self.n.rx += 1
        if name != self.name:
            self.n.other_path += 1
            self._warn_once(f"path{sysid}", f"system {sysid} flies another path ({name}): refused")
            return False
        s, sdot, slot_deg = float(msg.x), float(msg.y), float(msg.z)
        t = float(msg.time_usec) * 1e-6
        if not (math.isfinite(s) and math.isfinite(sdot) and math.isfinite(slot_deg)):
            self.n.bad_value += 1
            return False
        if abs(((slot_deg - self.slot_deg + 180.0) % 360.0) - 180.0) < 1e-3:
            self.n.same_slot += 1
            self._warn_once(f"slot{sysid}", f"system {sysid} claims my slot {slot_deg:g}: refused")
            return False
        if not any(abs(((slot_deg - d + 180.0) % 360.0) - 180.0) < 1e-3 for d in self.f.slots_deg):
            self.n.unknown_slot += 1
            self._warn_once(f"unk{sysid}", f"system {sysid} slot {slot_deg:g} not in slots_deg")
            return False
        now = self.now()
        p = self.peers.get(sysid)
        if p is None or p.slot_deg != slot_deg:
            p = self.peers[sysid] = _Peer(sysid, slot_deg)
            self.log(f"fleet: peer system {sysid} (slot {slot_deg:g} deg) heard")
        if p.report is not None and t <= p.report.t_s:
            self.n.stale_or_reordered += 1
            return False
        if now - t > self.f.peer_timeout_s:  # too old to say where the peer is now
            self.n.stale_or_reordered += 1
            return False
        p.report = co.PeerReport(slot_deg / 360.0 % 1.0, s, sdot, t)
        p.last_rx = now
        if p.lost:
            p.lost = False
            self.log(f"fleet: peer system {sysid} back")
        self.n.accepted += 1
        return True

    def send(self, s: float, sdot: float, now: float) -> None:
        self.broadcast(debug_vect(self.name, now, (float(s % self.L), float(sdot), self.slot_deg)))

    def broadcast(self, msg: Any) -> None:
        """``msg`` on every link this member writes to (a failure is counted, never raised)."""
        for link, written in self.links:
            if not written:
                continue
            try:
                link.send(msg)
                self.n.sent += 1
            except (OSError, MpfError):
                self.n.send_errors += 1

    # -- the coordination -------------------------------------------------------------------
    def alive(self, now: float) -> list[_Peer]:
        out = []
        for p in self.peers.values():
            if p.report is None:
                continue
            if now - p.last_rx > self.f.peer_timeout_s:
                if not p.lost:
                    p.lost = True
                    self.n.peers_lost += 1
                    self.log(
                        f"fleet: peer system {p.sysid} (slot {p.slot_deg:g}) silent for "
                        f"{self.f.peer_timeout_s:g} s: dropped ({self.f.on_peer_lost})"
                    )
                continue
            out.append(p)
        return out

    def slots_now(self, alive: list[_Peer]) -> tuple[float, dict[int, float]]:
        """(my slot, each living peer's slot) as fractions: configured, or respaced."""
        if self.f.on_peer_lost == "hold":
            return self.slot, {p.sysid: p.slot_deg / 360.0 % 1.0 for p in alive}
        slots = [self.slot] + [p.slot_deg / 360.0 % 1.0 for p in alive]
        new = co.respaced_slots(slots, [True] * len(slots))
        mine = new[0]
        assert mine is not None
        return mine, {p.sysid: float(new[k + 1] or 0.0) for k, p in enumerate(alive)}

    def step(self, t_mission: float, s: float, sdot: float, vs: Any, tgt: Any) -> float:
        """One control step: read, send when due, and the airspeed set-point (m/s) that
        carries this aircraft along the path at u_ref + du (``vs`` the VehicleState, ``tgt``
        the TargetState the law flew)."""
        now = self.now()
        self.poll()
        if now - self.t_sent >= 1.0 / self.f.rate_hz:
            self.t_sent = now
            self.send(s, sdot, now)
        alive = self.alive(now)
        mine, theirs = self.slots_now(alive)
        reps = [
            co.PeerReport(theirs[p.sysid], p.report.s_m, p.report.sdot_m_s, p.report.t_s)
            for p in alive
            if p.report is not None
        ]
        lap = self.lap
        if lap is not None:  # spacing in time: the consensus on shat (peers propagated first)
            if now - self.t_lap >= 1.0 / self.f.rate_hz:
                dt_lap = now - self.t_lap if math.isfinite(self.t_lap) else 0.0
                self.t_lap = now
                u = self.params.u_ref_m_s
                w_lap = self.wind.update(_wind(vs), dt_lap, alive, now, self.broadcast)
                if not lap.update(tgt.R_T_I, tgt.velocity, tgt.omega_T, w_lap, u):
                    self.n.extra["lap_unsolved"] = self.n.extra.get("lap_unsolved", 0) + 1
            reps = [co.PeerReport(r.slot, lap.shat(r.s_m + r.sdot_m_s * max(0.0, now - r.t_s)),
                                  0.0, now) for r in reps]  # fmt: skip
            shat = lap.shat(s)
        else:
            shat = s
        e, n = co.coordination_error_m(shat, mine, reps, now, self.L)
        du_raw = co.speed_correction(e, self.params.k_c, self.params.du_max_m_s)
        dt = 0.0 if self.t_prev is None else now - self.t_prev
        self.t_prev = now
        du = self.lp(du_raw, dt)
        du_v = 0.0
        if lap is not None:  # the energy control holds u_ref + du of airspeed
            u_c = self.params.u_ref_m_s + du
            if self.gs is not None and n:  # ... less k_v of the along-path speed error
                # against the lap clock's own speed (its wind: the error is what moves shat
                # off its rate, not the estimate's gusts)
                f1, vp = path_motion(self.path, s, tgt)
                wind = self.wind.lap
                nu_c = co.along_path_speed(u_c, f1, vp, wind)
                slope = co.along_path_slope(nu_c, u_c, f1, vp, wind)
                span = (self.window[1] - self.window[0]) * slope  # the window's worth
                du_v = self.gs(sdot - nu_c, slope, dt, span)
            dmax = self.params.du_max_m_s  # du + du_v within the correction's bound: counted
            if abs(du + du_v) > dmax:
                self.n.extra["correction_clipped"] = self.n.extra.get("correction_clipped", 0) + 1
            want = self.params.u_ref_m_s + min(max(du + du_v, -dmax), dmax)
        else:
            want = path_airspeed(self.f, self.path, max(0.0, self.params.u_ref_m_s + du), s, vs,
                                 tgt)  # fmt: skip
        asp = min(max(want, self.window[0]), self.window[1])
        if asp != want:  # the window takes part of what the coordination asks: counted
            self.n.extra["airspeed_clipped"] = self.n.extra.get("airspeed_clipped", 0) + 1
        self.last = {"e_m": e, "du_m_s": du, "airspeed_sp_m_s": asp, "n_peers": float(n),
                     "du_v_m_s": du_v}  # fmt: skip
        row = (now, t_mission, s, sdot, e, du, asp, float(n), mine * 360.0, shat, du_v)
        self.record.add(row, now)
        return asp

    def write(self, out: Path) -> dict[str, Any]:
        """fleet.csv (one row a step) and the summary that goes into metrics.json."""
        return write_member(self, out)


def write_member(m: FleetMember, out: Path) -> dict[str, Any]:
    """A member's fleet.csv (one row a step) and the summary that goes into metrics.json."""
    m.record.close(out, m.log)
    es = [r[4] for r in m.record.rows if r[7] > 0]
    summary: dict[str, Any] = {
        "member": m.f.member,
        "slot_deg": m.slot_deg,
        "path_id": m.pid,
        "length_m": m.L,
        "k_c": m.f.k_c,
        "u_ref_m_s": m.params.u_ref_m_s,
        "on_peer_lost": m.f.on_peer_lost,
        "spacing": m.f.spacing,
        "lap_s": m.lap.lap_s if m.lap is not None else None,
        "peers": {str(p.sysid): p.slot_deg for p in m.peers.values()},
        "counts": m.n.as_dict(),
        "final_error_m": es[-1] if es else None,
    }
    try:
        (out / "fleet.json").write_text(json.dumps(summary, indent=2) + "\n")
    except OSError:
        pass
    return summary


class EpochTarget:
    """A scripted target whose time 0 is ``epoch`` (Unix s), the same for every member: at
    :meth:`restamp` (the mission-time origin) the offset of mission time to target time is
    taken from the common clock, so that members engaging one after another see one target."""

    live = False

    def __init__(self, inner: Any, epoch_unix_s: float, now: Callable[[], float] = time.time):
        self.inner, self.epoch, self.now = inner, float(epoch_unix_s), now
        self.offset_s = 0.0

    def update(self, sample: Any, t_mission: float | None) -> None:
        return None

    def restamp(self, t0: float) -> None:
        self.offset_s = self.now() - self.epoch

    def state(self, t: float) -> Any:
        import dataclasses

        st = self.inner.state(t + self.offset_s)
        return st if isinstance(st, str) else dataclasses.replace(st, t=t)

    def state_later(self, t: float) -> Any:
        return self.state(t)


def attach(bridge: Any) -> FleetMember | None:
    """The fleet of a :class:`~mpf_mavlink.bridge.live.Bridge` (None when ``fleet.enabled`` is
    off): the target's epoch, the airspeed hook on its controller; links opened by :func:`open_`."""
    cfg = bridge.cfg
    f = cfg.section("fleet")
    if not f.enabled:
        return None
    ctl = bridge.ctl
    if f.target_epoch_unix_s is not None and not ctl.live:
        ctl.target = EpochTarget(ctl.target, f.target_epoch_unix_s)
    member = FleetMember(cfg, ctl.path, bridge.log)
    member.record.path = Path(bridge.opts.out_dir) / "fleet.csv"
    failed: list[bool] = []

    def hook(t: float, s: float, sdot: float, vs: Any, tgt: Any) -> float | None:
        if failed:
            return None
        try:
            return member.step(t, s, sdot, vs, tgt)
        except Exception as e:  # noqa: BLE001 - the coordination never ends a flight
            failed.append(True)
            bridge.log(f"fleet: coordination off after an error: {type(e).__name__}: {e}")
            return None

    ctl.airspeed_hook = hook
    return member


def open_(member: FleetMember | None, m: Any) -> None:
    """Open the links, signed with the bridge's key when signing is on."""
    if member is None:
        return
    if m.signing_key_file:
        from mpf_mavlink.mavlink import load_signing_key

        member.signing = (load_signing_key(m.signing_key_file), m.signing_link_id)
    member.open()


def finish(member: FleetMember | None, out: Path) -> None:
    """Close the links, write fleet.csv / fleet.json and the ``fleet`` entry of metrics.json."""
    if member is None:
        return
    member.close()
    summary = member.write(out)
    mp = out / "metrics.json"
    try:
        metrics = json.loads(mp.read_text())
        metrics["fleet"] = summary
        mp.write_text(json.dumps(metrics, indent=2, default=str) + "\n")
    except (OSError, ValueError):
        pass
