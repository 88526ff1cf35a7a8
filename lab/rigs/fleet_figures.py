"""Figures of a fleet flight (rig or SIL): the tracks in the target's frame, one colour per
aircraft, and the spacing error against time (docs/fleet.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")


def draw(
    out: Path,
    n: int,
    ser: dict[str, Any],
    t_all: float,
    t_kill: float | None,
    dirs: list[Path] | None = None,
) -> None:
    """DIR/fleet_tracks.png (each bridge's timeseries.csv rel_x/rel_y, m, target frame: north
    up, east right) and DIR/fleet_spacing.png (the worst neighbour error, m, against the
    seconds since the last engagement). ``dirs``: the bridges' run directories (DIR/bridgeK)."""
    dirs = dirs if dirs is not None else [out / f"bridge{k}" for k in range(n)]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 6))
    for k in range(n):
        ts = dirs[k] / "timeseries.csv"
        if not ts.is_file():
            continue
        d = np.genfromtxt(ts, delimiter=",", names=True)
        if d.size < 2:
            continue
        ax.plot(d["rel_y"], d["rel_x"], lw=0.6, color=COLOURS[k % len(COLOURS)], label=f"{k}")
    pt = dirs[0] / "path_T.csv"
    if pt.is_file():
        P = np.genfromtxt(pt, delimiter=",", skip_header=1).reshape(-1, 3)
        ax.plot(P[:, 1], P[:, 0], "k--", lw=0.8, label="path")
    ax.set_aspect("equal")
    ax.set_xlabel("east in the target frame (m)")
    ax.set_ylabel("north in the target frame (m)")
    ax.legend(title="aircraft", fontsize=8)
    ax.set_title("fleet: tracks in the target's frame")
    fig.tight_layout()
    fig.savefig(out / "fleet_tracks.png", dpi=120)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(8, 3.5))
    t = ser["t_unix_s"] - t_all
    ax.plot(t, ser["worst_m"], lw=0.8, label="worst neighbour spacing error")
    ax.set_yscale("symlog", linthresh=5.0)
    if t_kill is not None:
        ax.axvline(t_kill - t_all, color="r", lw=0.8, label="bridge killed")
    ax.axhline(5.0, color="k", lw=0.5, ls=":")
    ax.set_xlabel("s since the last aircraft engaged")
    ax.set_ylabel("m along the path")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "fleet_spacing.png", dpi=120)
    plt.close(fig)
