"""The live bridge's three fleet hooks (attach, open, finish), which load :mod:`.fleet` only
when ``fleet.enabled`` is on, so that a single aircraft's run does not import it."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mpf_mavlink.bridge.fleet import FleetMember


def attach(bridge: Any) -> FleetMember | None:
    """:func:`.fleet.attach` (None, without importing it, when ``fleet.enabled`` is off)."""
    if not bridge.cfg.section("fleet").enabled:
        return None
    from mpf_mavlink.bridge import fleet

    return fleet.attach(bridge)


def open_(member: FleetMember | None, m: Any) -> None:
    """:func:`.fleet.open_`: open the links (``m`` the mavlink section) of a fleet member."""
    if member is None:
        return
    from mpf_mavlink.bridge import fleet

    fleet.open_(member, m)


def finish(member: FleetMember | None, out: Path) -> None:
    """:func:`.fleet.finish`: close the links and write the fleet's files in ``out``."""
    if member is None:
        return
    from mpf_mavlink.bridge import fleet

    fleet.finish(member, out)
