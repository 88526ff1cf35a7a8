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
            "--duration", "30", "--set", "metrics.steady_after_s=20", "--out", str(out), "-q")  # fmt: skip
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
