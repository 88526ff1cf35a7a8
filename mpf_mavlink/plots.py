"""The paper's figures for any run directory: 3D and planar views, the target-relative path,
|pt|, Psi, sdot, w2 and w3 (commanded and achieved)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_run(d: str | Path) -> list[Path]:
    """Draw every figure of the run directory d as PNG files; return their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .rundir import read_run

    d = Path(d)
    cols, path_T, metrics = read_run(d)
    t = cols["t"]
    out: list[Path] = []
    if len(t) == 0:
        return out

    def save(fig, name: str) -> None:  # noqa: ANN001
        p = d / name
        fig.tight_layout()
        fig.savefig(p, dpi=110)
        plt.close(fig)
        out.append(p)

    # 1. 3D view (north, east, up) of vehicle, target and desired point.
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    ax.plot(cols["p_e"], cols["p_n"], -cols["p_d"], lw=1.0, label="vehicle")
    ax.plot(cols["tgt_e"], cols["tgt_n"], -cols["tgt_d"], "k--", lw=1.0, label="target")
    ax.plot(cols["pf_e"], cols["pf_n"], -cols["pf_d"], lw=0.6, alpha=0.6, label="desired point p_f")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_zlabel("up [m]")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title("Moving path following (3D)")
    save(fig, "trajectory_3d.png")

    # 2. Planar views.
    fig, axs = plt.subplots(1, 3, figsize=(14, 4.5))
    for ax, (a, b, la, lb, sa, sb) in zip(
        axs,
        [("p_e", "p_n", "east", "north", 1, 1), ("p_n", "p_d", "north", "up", 1, -1), ("p_e", "p_d", "east", "up", 1, -1)],
        strict=True,
    ):
        ta, tb = "tgt_" + a[2:], "tgt_" + b[2:]
        ax.plot(sa * cols[a], sb * cols[b], lw=1.0, label="vehicle")
        ax.plot(sa * cols[ta], sb * cols[tb], "k--", lw=1.0, label="target")
        ax.set_xlabel(f"{la} [m]")
        ax.set_ylabel(f"{lb} [m]")
        ax.grid(alpha=0.3)
    axs[0].set_aspect("equal", adjustable="datalim")
    axs[0].legend(fontsize=8)
    save(fig, "planar.png")

    # 3. Target-relative path: where the vehicle flew in {T}, against the path.
    fig, ax = plt.subplots(figsize=(6, 6))
    if path_T is not None and len(path_T):
        ax.plot(path_T[:, 1], path_T[:, 0], "r-", lw=2, alpha=0.5, label="path p_d (in {T})")
    ax.plot(cols["rel_y"], cols["rel_x"], lw=0.8, label="vehicle relative to target")
    ax.plot(cols["rel_y"][:1], cols["rel_x"][:1], "go", label="start")
    ax.set_xlabel("y_T (right) [m]")
    ax.set_ylabel("x_T (forward) [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save(fig, "target_relative.png")

    # 4. Errors: |pt| (log scale like the paper's zoom) and Psi.
    fig, axs = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    axs[0].semilogy(t, np.maximum(cols["pt_norm"], 1e-6))
    axs[0].set_ylabel("|p~| [m]")
    axs[0].grid(alpha=0.3, which="both")
    rms = metrics.get("steady_rms_m")
    if rms is not None:
        conv = metrics.get("convergence_time_s")
        conv_txt = "never" if conv is None else f"{conv:.3g} s"
        axs[0].set_title(f"steady RMS {rms:.3g} m, convergence {conv_txt}")
    axs[1].plot(t, cols["psi"])
    axs[1].set_ylabel("Psi(R~)")
    axs[1].set_xlabel("t [s]")
    axs[1].grid(alpha=0.3)
    save(fig, "errors.png")

    # 5. sdot, 6. w2 and w3.
    fig, axs = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    axs[0].plot(t, cols["sdot"])
    axs[0].set_ylabel("sdot [m/s]")
    for ax, k in zip(axs[1:], ("w2", "w3"), strict=True):
        ax.plot(t, cols[f"{k}_cmd"], lw=0.8, label=f"{k} commanded")
        ax.plot(t, cols[k], lw=0.8, alpha=0.8, label=f"{k} achieved")
        ax.set_ylabel(f"{k} [rad/s]")
        ax.legend(fontsize=8)
    for ax in axs:
        ax.grid(alpha=0.3)
    axs[-1].set_xlabel("t [s]")
    save(fig, "sdot_rates.png")
    return out
