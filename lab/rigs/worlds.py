"""``scripts/sitl compare px4|arduplane --out DIR [flight options]``: MPF against the firmware's
own guidance, on the real firmware, one after the other.

It runs the rig twice with the same options, each flight with its own firmware start:
``--guidance mpf`` into ``DIR/mpf`` and ``--guidance native`` into ``DIR/native`` (same mission
placement, start, duration and target), then writes ``DIR/compare.md`` (one table: guidance,
target, RMS e, max e, mean radial, mean vertical), ``DIR/compare.json`` and ``DIR/compare.png``
(e against time for both; both tracks in the target's frame). e is the same function for both
rows (:func:`lab.rigs.figures.moving_path_figures`). ``--record`` also writes
``docs/results/native-<flight>.json`` and regenerates ``docs/results/native.md`` from all of them.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

from lab.rigs.bundles import ROOT, RigError
from lab.rigs.figures import fmt, read_json

RESULTS = ROOT / "docs" / "results"
GUIDANCES = ("mpf", "native")
_DROP_WITH_VALUE = ("--out", "--guidance")
_DROP = ("--record",)


def sub_argv(argv: list[str], guidance: str, out: Path) -> list[str]:
    """The rig's arguments for one of the two flights: the compare's own, without --out,
    --guidance and --record, with this flight's guidance and run directory."""
    keep: list[str] = []
    skip = False
    for tok in argv:
        if skip:
            skip = False
            continue
        if tok in _DROP_WITH_VALUE:
            skip = True
            continue
        if tok in _DROP or any(tok.startswith(f"{d}=") for d in _DROP_WITH_VALUE):
            continue
        keep.append(tok)
    return [*keep, "--guidance", guidance, "--out", str(out)]


def validate(argv: list[str]) -> tuple[Any, Path]:
    """The compare's options, checked as the rig checks a flight's (nothing created)."""
    from lab.rigs import common

    a = common.parser().parse_args(argv)
    if a.guidance != "mpf" and "--guidance" in " ".join(argv):
        raise RigError("compare flies both guidances: no --guidance")
    if a.sil or a.kill_after is not None or a.serial:
        raise RigError(
            "compare flies MPF and native on the firmware: no --sil/--kill-after/--serial"
        )
    a.guidance = "native"  # the stricter of the two (a circle about a scripted target)
    v = common.validate(a)
    return a, v["out"]


def render(dirs: list[str], record_it: bool) -> int:
    """``scripts/sitl compare --render DIR... [--record]``: the table, figure and record of
    compare directories already flown (their compare.json), computed again by this code."""
    for d in dirs:
        out = Path(d)
        old = read_json(out / "compare.json")
        if not old.get("rows"):
            print(f"sitl compare: {d}: no compare.json", file=sys.stderr)
            return 2
        argv = old["command"].split()[2:]
        from lab.rigs import common

        a = common.parser().parse_args(argv)
        codes = {r["guidance"]: r.get("exit_code") for r in old["rows"]}
        res = collect(out, a, argv, codes)
        res["commit"], res["date"] = old.get("commit"), old.get("date")
        (out / "compare.json").write_text(json.dumps(res, indent=2, default=str) + "\n")
        md = markdown(res)
        (out / "compare.md").write_text(md + "\n")
        overlay(out, res, out / "compare.png")
        print(md)
        if record_it:
            record(res, out / "compare.png")
    return 0


def main(argv: list[str]) -> int:
    if argv[:1] == ["--render"]:
        rest = [x for x in argv[1:] if x != "--record"]
        return render(rest, "--record" in argv)
    try:
        a, out = validate(argv)
    except RigError as e:
        print(f"sitl compare: {e}", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    codes: dict[str, int] = {}
    for gd in GUIDANCES:
        cmd = [sys.executable, "-m", "lab.rigs", *sub_argv(argv, gd, out / gd)]
        print(f"compare: flying {gd}: scripts/sitl {' '.join(cmd[3:])}", flush=True)
        with open(out / f"{gd}.log", "w") as log:
            r = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, check=False)
        codes[gd] = r.returncode
        print(f"compare: {gd} exited {r.returncode} (log {out / f'{gd}.log'})", flush=True)
    res = collect(out, a, argv, codes)
    (out / "compare.json").write_text(json.dumps(res, indent=2, default=str) + "\n")
    md = markdown(res)
    (out / "compare.md").write_text(md + "\n")
    try:
        overlay(out, res, out / "compare.png")
    except (OSError, ValueError, KeyError) as e:
        print(f"compare: no overlay figure: {e}", file=sys.stderr)
    print("\n" + md)
    if a.record:
        record(res, out / "compare.png")
    ok = all(r["verdict"] in ("PASS", "FLOWN") for r in res["rows"])
    return 0 if ok and len(res["rows"]) == 2 else 1


def collect(out: Path, a: Any, argv: list[str], codes: dict[str, int]) -> dict[str, Any]:
    """The two flights' rows (from their summary.json) and what was flown."""
    rows = []
    for gd in GUIDANCES:
        s = read_json(out / gd / "summary.json")
        f = s.get("figures") or {}
        floor = s.get("estimator_floor")
        if (floor is None or "error" in floor) and a.autopilot == "px4" and f:
            from lab.rigs.common import _estimator_floor

            floor = _estimator_floor(out / gd)
        n = s.get("native") or {}
        rows.append(
            {
                "guidance": gd,
                "words": "MPF (mpf-mavlink run)" + "".join(f", --set {x}" for x in a.overrides)
                if gd == "mpf"
                else f"{n.get('command', 'native')}, re-sent at {fmt(n.get('rate_hz'), 'g')} Hz",
                "target": (s.get("mission") or {}).get("target"),
                "e_rms_m": f.get("e_rms_m"),
                "e_max_m": f.get("e_max_m"),
                "e_mean_radial_m": f.get("e_mean_radial_m"),
                "e_mean_vertical_m": f.get("e_mean_vertical_m"),
                "cross_track_rms_m": f.get("cross_track_rms_m"),
                "tracked_s": f.get("tracked_s"),
                "speed": n.get("speed"),
                "firmware_params": s.get("firmware_params"),
                "verdict": s.get("verdict", f"no summary (exit {codes.get(gd)})"),
                "exit_code": codes.get(gd),
                "flight": s.get("flight"),
                "bundle": s.get("bundle"),
                "estimator_floor": floor,
            }
        )
    from lab.rigs.common import _git_commit, flight_name

    a.guidance = "mpf"
    # the MPF flight's name (its inputs are the compare's): the record's, unique per inputs
    name = rows[0].get("flight") or flight_name(a)
    return {
        "name": name,
        "autopilot": a.autopilot,
        "command": " ".join(["scripts/sitl", "compare", *argv]),
        "wind": list(a.wind) if a.wind else None,
        "turbulence": a.turbulence,
        "duration_s": a.duration,
        "commit": _git_commit(),
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "rows": rows,
    }


def _row_md(autopilot: str, r: dict[str, Any], wind: str) -> str:
    return (
        f"| {autopilot} | {r['words']} | {r.get('target')}{wind} | {fmt(r.get('e_rms_m'))} "
        f"| {fmt(r.get('e_max_m'))} | {_signed(r.get('e_mean_radial_m'))} "
        f"| {_signed(r.get('e_mean_vertical_m'))} | {fmt(r.get('tracked_s'), '.0f')} "
        f"| {r.get('verdict')} |"
    )


def _signed(v: Any) -> str:
    return "n/a" if v is None else f"{v:+.3g}"


HEADER = [
    "| autopilot | guidance | target | RMS e (m) | max e (m) | mean radial (m, out +) "
    "| mean vertical (m, up +) | tracked (s) | verdict |",
    "|---|---|---|---|---|---|---|---|---|",
]


FLOOR_HEADER = [
    "PX4: EKF2's estimate against SIH's truth over the same steady window (`python -m "
    "lab.rigs.ulog`): the position error (its constant origin offset removed), the roll error, "
    "how closely the radial error follows the roll error (correlation of 5 s means, the radial "
    "lagging), and e measured from the truth instead of the estimate. An aircraft banks by its "
    "estimate and turns by its true bank: a roll error is a lateral acceleration error the "
    "position shows seconds later, and a radial error that follows it closely is a floor that "
    "neither guidance removes from the estimate it is given.",
    "",
    "| autopilot | guidance | position error RMS horiz. / vert. (m) | roll error mean / RMS (deg) "
    "| radial vs roll error: corr., lag (s) | e RMS from estimate / truth (m) |",
    "|---|---|---|---|---|---|",
]


def _floor_md(autopilot: str, guidance: str, fl: dict[str, Any]) -> str:
    am = fl.get("attitude_error_mean_rpy_deg") or [None]
    ar = fl.get("attitude_error_rms_about_mean_rpy_deg") or [None]
    return (
        f"| {autopilot} | {guidance} | {fmt(fl.get('estimate_error_rms_horizontal_m'))} / "
        f"{fmt(fl.get('estimate_error_rms_vertical_m'))} | {_signed(am[0])} / {fmt(ar[0])} "
        f"| {fmt(fl.get('radial_vs_roll_error_corr'), '.2f')}, "
        f"{fmt(fl.get('radial_lag_behind_roll_error_s'), '.1f')} "
        f"| {fmt(fl.get('e_rms_from_estimate_m'))} / {fmt(fl.get('e_rms_from_truth_m'))} |"
    )


def _wind_words(res: dict[str, Any]) -> str:
    w = res.get("wind")
    return f", wind {w[0]:g} m/s from {w[1]:g} deg" if w else ""


def markdown(res: dict[str, Any]) -> str:
    lines = [
        f"# MPF against the firmware's own guidance: {res['autopilot']}",
        "",
        f"`{res['command']}` ({res['commit']}, {res['date'][:10]}; firmware "
        f"{res['rows'][0].get('bundle')})",
        "",
        "e: the 3D distance of the aircraft from the moving path (the target's frame), the same "
        "function for both rows; steady window from 60 s of tracking.",
        "",
        *HEADER,
        *(_row_md(res["autopilot"], r, _wind_words(res)) for r in res["rows"]),
    ]
    floors = [(r["words"], r["estimator_floor"]) for r in res["rows"] if r.get("estimator_floor")]
    if floors and all("error" not in fl for _, fl in floors):
        lines += ["", *FLOOR_HEADER, *(_floor_md(res["autopilot"], g, fl) for g, fl in floors)]
    for r in res["rows"]:
        sp = r.get("speed")
        if sp:
            lines.append("")
            lines.append(
                f"{r['guidance']}: {sp.get('set')} (true airspeed wanted "
                f"{fmt(sp.get('true_airspeed_wanted_m_s'))} m/s, flown "
                f"{fmt(sp.get('true_airspeed_flown_m_s'))} m/s)"
            )
    return "\n".join(lines)


def e_series(run: Path, guidance: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t s, e m, rel (n, 3) m, path nodes (m, 3) m) of one flight's record."""
    from mpf_mavlink.runs.compare import distance_to_polyline

    track, nodes = ("bridge/timeseries.csv", "bridge/path_T.csv") if guidance == "mpf" else (
        "native_track.csv", "native_path_T.csv")  # fmt: skip
    d = np.genfromtxt(run / track, delimiter=",", names=True)
    P = np.genfromtxt(run / nodes, delimiter=",", skip_header=1).reshape(-1, 3)
    rel = np.column_stack([d["rel_x"], d["rel_y"], d["rel_z"]])
    return d["t"], distance_to_polyline(P, rel, True), rel, P


def overlay(out: Path, res: dict[str, Any], png: Path) -> None:
    """e against time for both flights; both tracks (steady window) in the target's frame."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 5))
    colours = {"mpf": "tab:blue", "native": "tab:red"}
    for r in res["rows"]:
        gd = r["guidance"]
        try:
            t, e, rel, P = e_series(out / gd, gd)
        except (OSError, ValueError):
            continue
        lab = f"{r['words']} (RMS {fmt(r.get('e_rms_m'))} m)"
        ax1.plot(t, np.maximum(e, 0.01), color=colours[gd], lw=0.8, label=lab)
        m = t >= 60.0
        ax2.plot(rel[m, 1], rel[m, 0], color=colours[gd], lw=0.6, label=gd)
        ax2.plot(P[:, 1], P[:, 0], "k--", lw=0.8)
    ax1.axvline(60.0, color="grey", lw=0.5)
    ax1.set_xlabel("time since engaging (s)")
    ax1.set_ylabel("e: distance from the moving path (m)")
    ax1.set_yscale("log")
    ax1.legend(fontsize=8)
    ax1.set_title(f"{res['autopilot']}: {res['rows'][0].get('target')}{_wind_words(res)}")
    ax2.set_aspect("equal")
    ax2.set_xlabel("east in the target's frame (m)")
    ax2.set_ylabel("north in the target's frame (m)")
    ax2.set_title("tracks from 60 s (dashed: the path)")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=90)
    plt.close(fig)


def record(res: dict[str, Any], png: Path) -> None:
    """docs/results/native-<name>.json (+ .png) and the regenerated native.md."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"native-{res['name']}.json").write_text(
        json.dumps(res, indent=2, default=str) + "\n"
    )
    if png.is_file():
        (RESULTS / f"native-{res['name']}.png").write_bytes(png.read_bytes())
    write_results_table()


def write_results_table() -> Path:
    """docs/results/native.md from every docs/results/native-*.json."""
    lines = [
        "# MPF against the firmware's own guidance on the real firmware",
        "",
        "Written by `scripts/sitl compare ... --record` (do not edit by hand). Each pair of rows "
        "is one command: MPF (`mpf-mavlink run`) and the firmware's own circle re-centred on the "
        "target, each from its own firmware start, the same mission placement, start, duration "
        "and target motion. e: the 3D distance of the aircraft from the moving path (in the "
        "target's frame), computed by the same function for both rows from what each flight "
        "recorded (the bridge's run record; the rig's LOCAL_POSITION_NED track); steady window "
        "from 60 s of tracking. Stock firmware parameters unless a row says otherwise.",
        "",
        *HEADER,
    ]
    cmds: list[str] = []
    floors: list[str] = []
    for p in sorted(RESULTS.glob("native-*.json")):
        res = read_json(p)
        if not res.get("rows"):
            continue
        for r in res["rows"]:
            par = r.get("firmware_params") or {}
            extra = ", " + ", ".join(f"{k}={v:g}" for k, v in par.items()) if par else ""
            lines.append(_row_md(res["autopilot"], {**r, "words": r["words"] + extra},
                                 _wind_words(res)))  # fmt: skip
        for r in res["rows"]:
            fl = r.get("estimator_floor")
            if fl and "error" not in fl:
                floors.append(_floor_md(res["autopilot"], f"{r['words']}, {r.get('target')}", fl))
        cmds.append(
            f"- `{res['command']}` ({res.get('commit')}, {str(res.get('date'))[:10]}; "
            f"figure: native-{res['name']}.png)"
        )
    if floors:
        lines += ["", *FLOOR_HEADER, *floors]
    lines += ["", "Commands:", "", *cmds]
    md = RESULTS / "native.md"
    md.write_text("\n".join(lines) + "\n")
    return md
