"""What PX4 (v1.14 and later: the failsafe framework of commander/failsafe/failsafe.cpp) does
when the bridge's setpoints stop, from its parameters; pure (no I/O).

- After ``COM_OF_LOSS_T`` s without setpoints, OFFBOARD falls back to the mode of
  ``COM_OBL_RC_ACT`` whether or not an RC is present (``COM_OBL_ACT``, the no-RC variant of
  older releases, is gone): 0 Position, 1 Altitude, 2 Stabilized, 3 Return, 4 Land, 5 Hold,
  6 Terminate, 7 Disarm. A fallback mode that cannot run (Position without a position
  estimate, per ``COM_POSCTL_NAVL``) falls further, last to Return.
- Position and Altitude modes on a fixed-wing hold the heading and the altitude while the
  sticks are centred: without RC (or with the sticks left alone) the aircraft flies straight
  on, away from the path, until the fuel or the geofence ends it. Only Hold (AUTO.LOITER)
  loiters.
- Hold on a fixed-wing loiters |``NAV_LOITER_RAD``| (its sign: the direction) about the
  navigator's reposition point when one was set (MAV_CMD_DO_REPOSITION while armed, consumed
  when Hold starts: Navigator::run, Loiter::on_activation), else about where the aircraft is
  when Hold starts.
- In Hold an RC loss triggers ``NAV_RCL_ACT`` (1 Hold, 2 Return, 3 Land, 5 Terminate,
  6 Disarm), unless bit 1 of ``COM_RCL_EXCEPT`` exempts Hold, no RC was present at arming,
  or ``COM_RC_IN_MODE`` is 4 (no RC input at all).
"""

from __future__ import annotations

from typing import Any

#: Parameters read before engaging (the first two are required to say anything at all).
PX4_FALLBACK_PARAMS = (
    "COM_OF_LOSS_T",
    "COM_OBL_RC_ACT",
    "COM_RCL_EXCEPT",
    "NAV_RCL_ACT",
    "COM_RC_IN_MODE",
    "NAV_LOITER_RAD",
)
PX4_OBL_HOLD = 5  # COM_OBL_RC_ACT: Hold

PX4_OBL_ACTIONS = {
    0: "Position mode: a fixed-wing with centred (or no) sticks flies straight on at its "
    "heading and altitude, NOT a hold",
    1: "Altitude mode: a fixed-wing with centred (or no) sticks flies straight on, NOT a hold",
    2: "Stabilized mode: wings level, no position or altitude hold, NOT a hold",
    3: "Return: flies to home and loiters there, not at the path",
    4: "Land",
    5: "Hold (AUTO.LOITER)",
    6: "Terminate (flight termination)",
    7: "Disarm",
}
PX4_RCL_ACTIONS = {0: "none", 1: "Hold", 2: "Return", 3: "Land", 5: "Terminate", 6: "Disarm"}


def obl_action(act: float | None) -> str:
    if act is None:
        return "unknown (COM_OBL_RC_ACT not answered)"
    return PX4_OBL_ACTIONS.get(int(act), f"COM_OBL_RC_ACT {int(act)} (unknown to this bridge)")


def rc_loss_clause(p: dict[str, float]) -> str:
    """What an RC loss during the Hold does, from the parameters read (those missing are
    said to be unknown)."""
    rcl, exc, mode = p.get("NAV_RCL_ACT"), p.get("COM_RCL_EXCEPT"), p.get("COM_RC_IN_MODE")
    if mode is not None and int(mode) == 4:
        return "no RC input (COM_RC_IN_MODE = 4): no RC-loss action"
    if exc is not None and int(exc) & 2:
        return "an RC loss is ignored in Hold (COM_RCL_EXCEPT bit 1)"
    what = "unknown" if rcl is None else PX4_RCL_ACTIONS.get(int(rcl), f"action {int(rcl)}")
    rcl_s = "?" if rcl is None else f"{int(rcl)}"
    return (
        f"an RC lost during the Hold -> {what} (NAV_RCL_ACT = {rcl_s}); none if no RC was "
        "present at arming"
    )


def describe(
    p: dict[str, float],
    set_from: float | None = None,
    centre: str | None = None,
) -> str:
    """One line: what PX4 will do when our setpoints stop. ``set_from``: the COM_OBL_RC_ACT the
    bridge replaced (None: untouched); ``centre``: where the Hold loiters when the bridge set
    a reposition point (else about the position where the loss happens)."""
    t, act = p.get("COM_OF_LOSS_T"), p.get("COM_OBL_RC_ACT")
    t_s = "?" if t is None else f"{t:g}"
    head = f"PX4: {t_s} s (COM_OF_LOSS_T) without setpoints -> "
    if act is None:
        return head + obl_action(None)
    changed = "" if set_from is None else f", set by the bridge (was {int(set_from)})"
    head += f"{obl_action(act)} (COM_OBL_RC_ACT = {int(act)}{changed}; with or without RC)"
    if int(act) != PX4_OBL_HOLD:
        return head
    r = p.get("NAV_LOITER_RAD")
    rad = (
        "NAV_LOITER_RAD"
        if r is None
        else f"{abs(r):g} m {'CCW' if r < 0 else 'CW'} (NAV_LOITER_RAD)"
    )
    where = centre or "the position where the loss happens (no reposition point set)"
    return f"{head}: loiter {rad} about {where}; {rc_loss_clause(p)}"


def detail(p: dict[str, float], set_from: float | None, centre: Any) -> dict[str, Any]:
    """The structured record for metrics.json."""
    act = p.get("COM_OBL_RC_ACT")
    return {
        "params": {k: p[k] for k in PX4_FALLBACK_PARAMS if k in p},
        "is_hold": act is not None and int(act) == PX4_OBL_HOLD,
        "com_obl_rc_act_set_from": set_from,
        "loiter_centre": centre,
    }
