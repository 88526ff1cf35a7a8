"""The ``fleet`` section: N bridges coordinating on one moving path (docs/fleet.md).

Off unless ``enabled``. This aircraft is ``member`` k of ``slots_deg`` (one slot per member, in
degrees of one lap of the closed path: 120 apart for three); it hears and tells its peers over
``links`` (MAVLink URLs; every link is read, ``udpin`` links are only read, the others are also
written: a direct UDP mesh is one ``udpin`` to listen on and one ``udpout`` per peer, a ground
station or router is one ``udpout``/``tcp`` both ways).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from mpf_mavlink.config.fields import _doc, _ge, _nonneg, _pos, _rng
from mpf_mavlink.errors import ConfigError


@dataclass(frozen=True)
class FleetConfig:
    """Coordination of this bridge with its peers on the same path (docs/fleet.md)."""

    enabled: bool = field(default=False, metadata=_doc("coordinate with the peers on `links`"))
    member: int = field(default=0, metadata=_ge(0, "this aircraft's index in `slots_deg`"))
    slots_deg: list[float] = field(
        default_factory=list,
        metadata=_doc("each member's slot, degrees of one lap of the closed path (distinct)"),
    )
    links: list[str] = field(
        default_factory=list,
        metadata=_doc("MAVLink URLs of the coordination link (udpin: read only; others: both)"),
    )
    spacing: Literal["path", "time"] = field(
        default="path",
        metadata=_doc(
            "path: a common along-path speed, slots as distance; time: every aircraft at "
            "u_ref of airspeed, slots as lap time (where the path speed would leave the window)"
        ),
    )
    k_c: float = field(
        default=0.2, metadata=_pos("consensus gain (1/s) on the along-path spacing error")
    )
    du_max_m_s: float = field(
        default=2.5, metadata=_pos("largest along-path speed correction (m/s)")
    )
    u_ref_m_s: float | None = field(
        default=None,
        metadata=_doc(
            "common reference speed (m/s): along the path (spacing: path) or of airspeed "
            "(spacing: time); null: vehicle.airspeed_m_s"
        ),
    )
    airspeed_margin_m_s: float = field(
        default=0.5,
        metadata=_nonneg("the set-point stays this far inside the vehicle's airspeed window"),
    )
    filter_tau_s: float = field(
        default=0.5, metadata=_nonneg("low-pass time constant (s) of the speed correction")
    )
    speed_gain: float = field(
        default=0.0,
        metadata=_nonneg(
            "airspeed set-point per m/s of along-path speed error (0: feed-forward alone)"
        ),
    )
    lead_s: float = field(
        default=1.0,
        metadata=_ge(
            -5.0, "the airspeed feed-forward looks this far (s) ahead along the path (< 0: behind)"
        ),
    )
    ff_gain: float = field(
        default=1.0,
        metadata=_nonneg(
            "gain on the feed-forward's swing about the along-path speed (the speed loop's "
            "attenuation made up)"
        ),
    )
    lap_wind_tau_s: float = field(
        default=100.0,
        metadata=_nonneg(
            "spacing: time: the lap clock's wind is the estimate low-passed over this (s; 0: "
            "as estimated); two of the demo's laps"
        ),
    )
    share_wind: bool = field(
        default=True,
        metadata=_doc(
            "spacing: time: tell the peers this member's averaged wind (DEBUG_VECT MPW, 1 Hz) "
            "and compute the lap clock in the mean of the members' (one clock for the fleet)"
        ),
    )
    ground_speed_gain: float = field(
        default=0.0,
        metadata=_nonneg(
            "spacing: time: the share k_v (<= 1) of the measured along-path speed error taken "
            "off the airspeed set-point (0: off; spacing: path has speed_gain)"
        ),
    )
    ground_speed_tau_s: float = field(
        default=1.0,
        metadata=_pos("low-pass time constant (s) of that along-path speed error"),
    )
    rate_hz: float = field(default=5.0, metadata=_rng(0.2, 50.0, "reports sent per second"))
    max_latency_s: float = field(
        default=0.5, metadata=_nonneg("the worst link latency the convergence check allows (s)")
    )
    peer_timeout_s: float = field(
        default=3.0, metadata=_pos("a peer silent this long (s) is dropped")
    )
    on_peer_lost: Literal["respace", "hold"] = field(
        default="respace",
        metadata=_doc("respace: survivors spread evenly; hold: every slot is kept"),
    )
    sysid: int | None = field(
        default=None,
        metadata=_doc("system id on the coordination link; null: 100 + member"),
    )
    target_epoch_unix_s: float | None = field(
        default=None,
        metadata=_doc(
            "a scripted target's time 0 as Unix time (s), the same for every member; null: "
            "each bridge's own engagement"
        ),
    )

    def validate(self, src: str) -> None:
        if not self.enabled:
            return
        n = len(self.slots_deg)
        if n < 2:
            raise ConfigError(f"{src}: fleet.slots_deg: a fleet needs at least 2 slots, got {n}")
        if self.member >= n:
            raise ConfigError(f"{src}: fleet.member: {self.member} but only {n} slots")
        seen: dict[float, int] = {}
        for k, d in enumerate(self.slots_deg):
            key = round((d % 360.0) * 1e6) / 1e6
            if key in seen:
                raise ConfigError(
                    f"{src}: fleet.slots_deg[{k}]: {d:g} deg is member {seen[key]}'s slot too"
                )
            seen[key] = k
        if not self.links:
            raise ConfigError(f"{src}: fleet.links: at least one MAVLink URL is needed")
        if self.sysid is not None and not 1 <= self.sysid <= 255:
            raise ConfigError(f"{src}: fleet.sysid: must be 1..255, got {self.sysid}")

    @property
    def slots(self) -> list[float]:
        """The slots as fractions of one lap, [0, 1)."""
        return [(d % 360.0) / 360.0 for d in self.slots_deg]

    @property
    def link_sysid(self) -> int:
        return self.sysid if self.sysid is not None else 100 + self.member


def validate_fleet(cfg: Any, src: str) -> None:
    """Checks across sections: a fleet flies a closed path (slots are fractions of its lap)."""
    f = cfg.section("fleet")
    f.validate(src)
    if f.enabled and not _closed(cfg.path):
        raise ConfigError(
            f"{src}: fleet.enabled: slots need a closed path (path.type {cfg.path.type})"
        )


def _closed(p: Any) -> bool:
    if p.type in ("circle", "lemniscate"):
        return True
    return p.type == "spline" and bool(getattr(p, "closed", False))
