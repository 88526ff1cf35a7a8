"""``mpf-mavlink compare``: the same mission per law, one table (kinematic plant, short)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from mpf_mavlink.runs.compare import LawRow, distance_to_polyline, ratio_mpf_best

ROOT = Path(__file__).resolve().parents[1]


def test_distance_to_polyline_of_a_square() -> None:
    sq = np.array([[0.0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]])
    q = np.array([[5.0, -3, 0], [5, 5, 4], [-1, 5, 0]])
    # closed: the segment (0,10)-(0,0) counts; open it does not (then (0,10) is nearest: 5.10)
    assert np.allclose(distance_to_polyline(sq, q, True), [3.0, np.hypot(5, 4), 1.0])
    assert np.isclose(distance_to_polyline(sq, q, False)[2], np.hypot(1, 5))


def _brute_force(nodes: np.ndarray, q: np.ndarray, closed: bool) -> np.ndarray:
    """Every point against every segment, one at a time (the definition)."""
    segs = list(zip(nodes[:-1], nodes[1:], strict=True))
    if closed:
        segs.append((nodes[-1], nodes[0]))
    out = []
    for p in q:
        best = np.inf
        for a, b in segs:
            d = b - a
            u = min(1.0, max(0.0, float((p - a) @ d) / max(float(d @ d), 1e-12)))
            best = min(best, float(np.linalg.norm(p - (a + u * d))))
        out.append(best)
    return np.array(out)


def test_distance_to_polyline_is_exact_where_the_nearest_node_misleads() -> None:
    # 1 m below the middle of a 100 m segment whose ends are far, next to a node 4.5 m away whose
    # own segments lead elsewhere: the nearest node's segments alone would say ~4.5 m
    far = [[100.0 + 40 * i, 500.0, 0.0] for i in range(10)]  # > 8 nodes: the k-d tree path
    nodes = np.array([[0.0, 0, 0], [100, 0, 0], [100, 50, 0], [52, 3, 0], *far])
    q = np.array([[50.0, -1, 0]])
    for closed in (False, True):
        assert distance_to_polyline(nodes, q, closed)[0] == 1.0
    # a tight lemniscate (its branches cross) and a coarse random polygon, points near and far
    rng = np.random.default_rng(7)
    th = np.linspace(0.0, 2 * np.pi, 300, endpoint=False)
    lem = np.column_stack([150 * np.cos(th), 75 * np.sin(2 * th), 5 * np.sin(th)])
    poly = rng.uniform(-200, 200, size=(25, 3))
    for nodes, closed in ((lem, True), (lem[:170], False), (poly, True), (poly, False)):
        q = np.vstack(
            [
                rng.uniform(-250, 250, size=(150, 3)),
                nodes[::7] + rng.normal(size=(len(nodes[::7]), 3)),
            ]
        )
        np.testing.assert_allclose(
            distance_to_polyline(nodes, q, closed),
            _brute_force(nodes, q, closed),
            rtol=0,
            atol=1e-9,
        )


def test_ratio_is_mpf_over_the_best_baseline() -> None:
    rows = [LawRow("mpf", {"steady_rms_xt_m": 0.2}), LawRow("npfg", {"steady_rms_xt_m": 0.8}),
            LawRow("pursuit", {"steady_rms_xt_m": 0.5})]  # fmt: skip
    assert ratio_mpf_best(rows) == 0.2 / 0.5


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "mpf_mavlink.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)  # fmt: skip


def test_compare_flies_each_law_on_the_same_mission_and_writes_the_table(tmp_path: Path) -> None:
    out = tmp_path / "cmp"
    r = run("compare", "configs/compare/static_circle.yaml", "--laws", "mpf,pursuit",
            "--duration", "30", "--set", "metrics.steady_after_s=20", "--out", str(out),
            "-q")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "| mpf |" in r.stdout and "| pursuit |" in r.stdout and "MPF / best baseline" in r.stdout
    js = json.loads((out / "compare.json").read_text())
    assert set(js["rows"]) == {"mpf", "pursuit"} and js["best_baseline"] == "pursuit"
    for f in ("compare.md", "compare_cross_track.png", "compare_target_frame.png"):
        assert (out / f).is_file()
    # the same start for both: the first recorded vehicle position is identical
    a = np.genfromtxt(out / "mpf" / "timeseries.csv", delimiter=",", names=True, max_rows=1)
    b = np.genfromtxt(out / "pursuit" / "timeseries.csv", delimiter=",", names=True, max_rows=1)
    assert (a["p_n"], a["p_e"], a["p_d"]) == (b["p_n"], b["p_e"], b["p_d"])


def test_compare_refuses_an_unknown_law_and_l1_on_a_figure_eight_in_one_line(
    tmp_path: Path,
) -> None:
    r = run(
        "compare",
        "configs/compare/static_circle.yaml",
        "--laws",
        "mpf,carrot",
        "--out",
        str(tmp_path / "a"),
    )
    assert r.returncode != 0 and "carrot" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = run(
        "compare", "configs/default.yaml", "--laws", "mpf,l1_loiter", "--out", str(tmp_path / "b")
    )
    assert r.returncode != 0 and "l1_loiter" in r.stderr and len(r.stderr.strip().splitlines()) == 1
