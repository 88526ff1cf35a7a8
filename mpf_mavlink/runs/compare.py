"""The head-to-head figures of ``mpf-mavlink compare``: one row per guidance law, the same
measure for every law, a markdown table and the overlay plots.

Every law is judged by the same two distances, both from the recorded run table:
- ``|pt|``: the law's own error (MPF: to its virtual point; a baseline: to the closest point);
- cross-track: the distance of the vehicle from the moving path (the polyline of the path's
  nodes in the target frame), identical for every law. The comparison's ratios use it.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mpf_mavlink.constants import GRAVITY_M_S2
from mpf_mavlink.runs.rundir import convergence_time_s


def distance_to_polyline(
    nodes: NDArray[np.float64], q: NDArray[np.float64], closed: bool
) -> NDArray[np.float64]:
    """Distance (m) of each point of q (n, 3) from the polyline through nodes (m, 3), exact.

    Fast on long tables (a SIL truth of 30,000 rows against a path of thousands of nodes): the
    segments that meet at a point's k nearest nodes (k-d tree) settle it when its k-th nearest
    node is farther than the distance found plus half the longest segment (a closer segment
    would have an end point within that distance, so among those nodes); the points left
    unsettled (far from a densely sampled path, e.g. before convergence) are asked again with
    eight times as many nodes, up to all of them (every segment)."""
    from scipy.spatial import cKDTree

    nodes, q = np.asarray(nodes, float), np.asarray(q, float).reshape(-1, 3)
    A, B = nodes[:-1], nodes[1:]
    if closed:
        A, B = np.vstack([A, nodes[-1:]]), np.vstack([B, nodes[:1]])
    best = np.full(len(q), np.inf)
    if len(q) == 0 or len(A) == 0:
        return best if len(A) else np.linalg.norm(q - nodes[0], axis=1)
    d = B - A
    L2 = np.maximum(np.sum(d * d, axis=1), 1e-12)
    half = 0.5 * math.sqrt(float(np.max(L2)))
    tree, n = cKDTree(nodes), len(nodes)
    kth = np.empty(len(q))  # the k-th nearest node's distance of the latest ask
    todo, k = np.arange(len(q)), min(8, n)
    while True:
        # chunks keep the (points, 2 k segments, 3) arrays to a few MB
        step = max(1, 65536 // k)
        for i in range(0, len(todo), step):
            r = todo[i : i + step]
            qq = q[r]
            dist, idx = tree.query(qq, k=k)
            dist, idx = np.reshape(dist, (len(r), k)), np.reshape(idx, (len(r), k))
            seg = np.concatenate([idx - 1, idx], axis=1)  # the segments ending/starting there
            seg = seg % len(A) if closed else np.clip(seg, 0, len(A) - 1)
            Aq, dq = A[seg], d[seg]
            u = np.clip(np.sum((qq[:, None, :] - Aq) * dq, axis=2) / L2[seg], 0.0, 1.0)
            gap = np.linalg.norm(qq[:, None, :] - (Aq + u[:, :, None] * dq), axis=2)
            best[r] = np.min(gap, axis=1)
            kth[r] = dist[:, -1]
        if k >= n:
            break
        todo = todo[kth[todo] <= best[todo] + half]
        if not len(todo):
            break
        k = min(8 * k, n)
    return np.asarray(best, dtype=np.float64)


#: exit codes of a flight that ran to its end, whatever its verdict (0 PASS, 5 FAIL, 6 NOT JUDGED)
FLOWN_EXIT_CODES = (0, 5, 6)


@dataclass
class LawRow:
    law: str
    figures: dict[str, Any]


def law_figures(
    cols: dict[str, NDArray[np.float64]],
    path_nodes: NDArray[np.float64],
    closed: bool,
    airspeed: float,
    steady_after_s: float,
    threshold_m: float,
    roll: NDArray[np.float64] | None = None,
) -> dict[str, Any]:
    """The table's figures of one run (units in the keys)."""
    t = cols["t"]
    rel = np.column_stack([cols["rel_x"], cols["rel_y"], cols["rel_z"]])
    ct = distance_to_polyline(path_nodes, rel, closed)
    m = t >= steady_after_s
    conv = convergence_time_s(t, ct, threshold_m)
    pt = cols["pt_norm"]
    rate = np.hypot(cols["w2_cmd"], cols["w3_cmd"])
    # the bank a coordinated turn at the achieved rate needs (the kinematic plant has no roll)
    bank = np.degrees(np.arctan(airspeed * np.abs(cols["w3"]) / GRAVITY_M_S2))
    out: dict[str, Any] = {
        "convergence_s": conv,
        "steady_rms_pt_m": float(np.sqrt(np.mean(pt[m] ** 2))) if m.any() else None,
        "steady_max_pt_m": float(np.max(pt[m])) if m.any() else None,
        "steady_rms_xt_m": float(np.sqrt(np.mean(ct[m] ** 2))) if m.any() else None,
        "steady_max_xt_m": float(np.max(ct[m])) if m.any() else None,
        "max_bank_deg": float(np.max(bank)) if len(bank) else None,
        "rms_rate_cmd_rad_s": float(np.sqrt(np.mean(rate[m] ** 2))) if m.any() else None,
        "saturated_frac": float(np.mean(cols["saturated"])) if len(t) else None,
    }
    if roll is not None and len(roll):
        out["max_bank_deg"] = float(np.degrees(np.max(np.abs(roll))))
    return out


COLUMNS_SHOWN = [
    ("law", "law", ""),
    ("verdict", "verdict", "{}"),
    ("convergence_s", "conv. (s)", "{:.1f}"),
    ("steady_rms_xt_m", "RMS xt (m)", "{:.3g}"),
    ("steady_max_xt_m", "max xt (m)", "{:.3g}"),
    ("steady_rms_pt_m", "RMS |pt| (m)", "{:.3g}"),
    ("steady_max_pt_m", "max |pt| (m)", "{:.3g}"),
    ("max_bank_deg", "max bank (deg)", "{:.1f}"),
    ("rms_rate_cmd_rad_s", "RMS rate cmd (rad/s)", "{:.3f}"),
    ("saturated_frac", "saturated", "{:.3f}"),
]


def best_baseline(
    rows: list[LawRow], key: str = "steady_rms_xt_m"
) -> tuple[str | None, float | None]:
    """The baseline (not MPF) with the smallest finite figure."""
    best: tuple[str | None, float | None] = (None, None)
    for r in rows:
        v = r.figures.get(key)
        if r.law == "mpf" or v is None or not math.isfinite(v):
            continue
        if best[1] is None or v < best[1]:
            best = (r.law, v)
    return best


def ratio_mpf_best(rows: list[LawRow], key: str = "steady_rms_xt_m") -> float | None:
    """MPF's figure over the best baseline's (< 1: MPF better)."""
    mpf = next((r.figures.get(key) for r in rows if r.law == "mpf"), None)
    _, b = best_baseline(rows, key)
    if mpf is None or b is None or b <= 0.0:
        return None
    return float(mpf / b)


def markdown_table(rows: list[LawRow]) -> str:
    head = "| " + " | ".join(h for _, h, _ in COLUMNS_SHOWN) + " |"
    sep = "|" + "|".join("---" for _ in COLUMNS_SHOWN) + "|"
    lines = [head, sep]
    for r in rows:
        cells = []
        for k, _, fmt in COLUMNS_SHOWN:
            if k == "law":
                cells.append(r.law)
                continue
            v = r.figures.get(k)
            cells.append("n/a" if v is None else fmt.format(v))
        lines.append("| " + " | ".join(cells) + " |")
    for r in rows:
        line = r.figures.get("verdict_line")
        if line and not str(line).endswith("PASS"):
            lines.append(f"\n{r.law}: {line}")
        if r.figures.get("exit_code") not in (None, *FLOWN_EXIT_CODES):
            lines.append(
                f"\n{r.law}: flight ended with exit {r.figures['exit_code']} after "
                f"{r.figures.get('tracked_s', 0.0):.0f} s ({r.figures.get('exit_reason')})"
            )
    ratio = ratio_mpf_best(rows)
    name, _ = best_baseline(rows)
    if ratio is not None:
        lines.append("")
        lines.append(f"MPF / best baseline ({name}), steady RMS cross-track: {ratio:.3f}")
    return "\n".join(lines)


def write_compare(
    out: Path,
    rows: list[LawRow],
    runs: dict[str, dict[str, NDArray[np.float64]]],
    path_nodes: NDArray[np.float64],
    closed: bool,
    header: str,
    plots: bool = True,
) -> list[Path]:
    """compare.md, compare.json and the overlay plots in ``out``; returns the files written."""
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "compare.md", out / "compare.json"]
    files[0].write_text(header + "\n\n" + markdown_table(rows) + "\n")
    files[1].write_text(
        json.dumps(
            {
                "rows": {r.law: r.figures for r in rows},
                "ratio_mpf_best": ratio_mpf_best(rows),
                "best_baseline": best_baseline(rows)[0],
                "header": header,
            },
            indent=2,
        )  # fmt: skip
    )
    if not plots:
        return files
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4.5))
    for law, cols in runs.items():
        rel = np.column_stack([cols["rel_x"], cols["rel_y"], cols["rel_z"]])
        ct = distance_to_polyline(path_nodes, rel, closed)
        ax.semilogy(cols["t"], np.maximum(ct, 1e-3), label=law, lw=0.9)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("cross-track distance (m)")
    ax.set_title(header, fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    p = out / "compare_cross_track.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    files.append(p)
    fig, ax = plt.subplots(figsize=(7, 7))
    P = np.asarray(path_nodes)
    ax.plot(P[:, 1], P[:, 0], "k-", lw=2.5, alpha=0.35, label="path")
    for law, cols in runs.items():
        ax.plot(cols["rel_y"], cols["rel_x"], lw=0.8, label=law)
    ax.set_xlabel("target frame y (m)")
    ax.set_ylabel("target frame x (m)")
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.legend()
    ax.set_title("trajectories in the target frame", fontsize=9)
    fig.tight_layout()
    p = out / "compare_target_frame.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    files.append(p)
    return files
