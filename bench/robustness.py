"""Robustness table (``scripts/bench --only sil_robustness``; issue 13): the demo under real
links, wind, turbulence, airspeed and other airframes, one change at a time.

Each row is the acceptance command itself, ``mpf-mavlink sim CONFIG --set ...`` in a child
process (its exit code and its last line are part of the row), measured on the plant's truth
(``metrics.json``: steady RMS and max |pt| from ``metrics.steady_after_s``). Same seeds as the
demo (``sil.seed: 7``) in every row. A row's bound comes from the issue's acceptance: relative
rows (latency, telemetry rate, wind) are judged against the demo or calm figure of the same
table. Rows the pre-flight gate refuses are flown again with ``--force`` to show what the gate
spared; the refusal itself is the row's verdict.

With ``--profile NAME`` (``px4``, ``arduplane`` or a profile YAML) the rows whose config flies
that profile's autopilot (:func:`profile_rows`; ``--rows`` names others) fly the SIL with that
identified autopilot profile (``sil.autopilot_profile``, ``sil.flavour`` following its
autopilot): what the firmware adds to the same mission. The profile's ``thrust`` section is the
airframe the firmware was identified on (PX4 SIH's airplane), not the X8 these rows fly, so it
is left out unless ``--profile-thrust``.

Run alone: ``python -m bench.robustness [--rows demo,calm] [--duration S]
[--profile px4]``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
DEMO = "configs/default.yaml"
PROFILES = {
    "px4": "configs/autopilots/px4-1.16-sih.yaml",
    "arduplane": "configs/autopilots/arduplane-4.7.yaml",
}
CALM = ["sil.wind_ned_m_s=[0,0,0]", "sil.turbulence=none"]


@dataclass(frozen=True)
class Row:
    """One condition: config, overrides, and the acceptance bound.

    rel: the bound is ``factor`` x the RMS of row ``rel`` (None: ``rms_m`` absolute);
    max_m: bound on the steady max |pt|; expect: ``fly`` (exit 0 within the bounds),
    ``refuse`` (sim refuses without --force: exit 3) or ``fail`` (flies, fails its verdict).
    """

    name: str
    sets: list[str] = field(default_factory=list)
    config: str = DEMO
    rms_m: float | None = None
    rel: str | None = None
    factor: float = 1.0
    max_m: float | None = None
    expect: str = "fly"
    note: str = ""


ROWS: list[Row] = [
    Row("demo", [], rms_m=0.25, note="4 m/s wind, light turbulence, 20 ms command latency, 50 Hz"),
    Row("calm", CALM, rms_m=0.10, note="no wind, no turbulence"),
    Row("cmd_latency_60ms", ["sil.command_latency_s=0.06"], rel="demo", factor=1.5, max_m=1.5),
    Row("tel_latency_50ms", ["sil.telemetry_latency_s=0.05"], rel="demo", factor=1.5, max_m=1.5),
    # the bridge asks for ATTITUDE at mavlink.attitude_rate_hz (50) and the SIL vehicle, like
    # PX4, grants it: a link that carries only 25 / 10 Hz is the vehicle's rate AND the request
    Row(
        "attitude_25hz",
        ["sil.telemetry.attitude_hz=25", "mavlink.attitude_rate_hz=25"],
        rel="demo",
        factor=1.5,
        max_m=1.5,
    ),  # fmt: skip
    Row(
        "attitude_10hz",
        [
            "sil.telemetry.attitude_hz=10",
            "mavlink.attitude_rate_hz=10",
            "mavlink.attitude_min_hz=8",
        ],
        rel="demo",
        factor=2.0,
        max_m=2.0,
    ),  # fmt: skip
    # every stream at 10 Hz (a slow radio link): no position instant between two ATTITUDEs
    Row(
        "telemetry_10hz",
        [
            "sil.telemetry.attitude_hz=10",
            "sil.telemetry.local_position_hz=10",
            "mavlink.attitude_rate_hz=10",
            "mavlink.attitude_min_hz=8",
            "mavlink.position_rate_hz=10",
        ],
        rel="demo",
        factor=2.0,
        max_m=2.0,
    ),  # fmt: skip
    Row("wind_6", ["sil.wind_ned_m_s=[0,6,0]", "sil.turbulence=none"], rel="calm", factor=1.5),
    Row("wind_6_light_turb", ["sil.wind_ned_m_s=[0,6,0]"], note="no bound (reported)"),
    # energy (issue 25): a 2 sigma_w updraft (3.0 m/s) for L_w / V (6 s) holds 9.7 m of height
    # the X8 cannot shed at idle (sink 1.5 m/s), more than the 8.8 m that speeding up to the
    # verdict's 20.7 m/s absorbs: `check` refuses it (forced: the figures of that energy)
    Row(
        "moderate_turbulence",
        ["sil.turbulence=moderate"],
        expect="refuse",
        note="updrafts beyond idle sink (check: climb)",
    ),
    # 3D missions (issue 25): climbs and descents the energy control must fly
    Row("spline3d", [], config="configs/spline3d_turning_target.yaml", rms_m=0.30),
    Row("helix", [], config="configs/helix.yaml", rms_m=0.30),
    # the 1.5 m/s climb is within the X8's 4.1 m/s, but at 430 m above the sea (seed 7) a
    # 3.2 m/s downdraft over 9 s (2.4 sigma_w there) needs 4.7 m/s where full thrust gives 3.9
    # in that air: 6.5 m of height beyond full thrust, 3.1 m of which slowing to
    # vehicle.airspeed_min_m_s buys, so thrust is at its ceiling and the X8 5 m below the path
    # for ~10 s. `check` warns (2-sigma gusts need 4.37 m/s: deficit 3.2 of the 5.8 m
    # reserve); the bound is the and this row misses it on energy, not on tracking
    Row(
        "climbing_target_240",
        ["sim.duration_s=240"],
        config="configs/compare/helix_climbing_target.yaml",
        rms_m=0.30,
        note="downdraft beyond full-thrust climb at 220 s (check warns)",
    ),
    # 600 s take the target to 1000 m, where the turbulence's 2 sigma_w downdrafts (4.4 m/s for
    # 33 s) and its 1.5 m/s climb need more than the X8's 3.8 m/s in that air: `check` refuses
    Row(
        "climbing_target_600",
        [],
        config="configs/compare/helix_climbing_target.yaml",
        expect="refuse",
        note="downdrafts beyond full-thrust climb (check: climb)",
    ),
    Row("wind_8", ["sil.wind_ned_m_s=[0,8,0]"], expect="refuse"),
    Row("wind_10", ["sil.wind_ned_m_s=[0,10,0]"], expect="refuse"),
    Row(
        "airspeed_20",
        ["vehicle.airspeed_m_s=20", "vehicle.airspeed_max_m_s=22"],
        expect="refuse",
        note="peak bank 44.6 deg of 45: inside no margin",
    ),
    Row("c172x", [], config="configs/sil_c172x.yaml", rms_m=2.0),
]

# Issue 13 item 4: the stock JSBSim airframes on the c172x mission (45 m/s, 600 m circle, 300 m
# up), trim and rate-loop gains derived from the FDM itself (aircraft.gains_from_fdm, shipped on
# in configs/sil_c172x.yaml: sim/plant/airframe_ident.py), and the same
# mission made infeasible: a 150 m circle at 45 m/s needs atan(45^2 / (g 150)) = 54 deg of bank,
# beyond the 34 deg limit, so sim must refuse it (exit 3) without --force.
AIRFRAMES = ("c172p", "c172x", "c182", "pa28")
DERIVED = "aircraft.gains_from_fdm=true"
for _m in AIRFRAMES:
    ROWS.append(
        Row(
            f"{_m}_derived",
            [f"aircraft.model={_m}", DERIVED],
            config="configs/sil_c172x.yaml",
            rms_m=2.0,
        )
    )  # fmt: skip
    ROWS.append(
        Row(
            f"{_m}_infeasible",
            [f"aircraft.model={_m}", DERIVED, "path.radius_m=150", "sil.loiter_radius_m=400"],
            config="configs/sil_c172x.yaml",
            expect="refuse",
            note="54 deg of bank needed, 34 deg limit",
        )
    )
# The demo's mission scaled to these airframes (figure-eight over a turning convoy, 4 m/s wind,
# light turbulence, 20 ms latency: configs/sil_cessna_convoy.yaml), same 2 m bound.
CONVOY = "configs/sil_cessna_convoy.yaml"
for _m in AIRFRAMES:
    ROWS.append(Row(f"{_m}_convoy", [f"aircraft.model={_m}"], config=CONVOY, rms_m=2.0))
# flown by sil_airframes only (sil_robustness keeps its own rows, c172x as shipped among them)
AIRFRAME_ONLY = [r.name for r in ROWS if r.name.startswith(AIRFRAMES) and r.name != "c172x"]
AIRFRAME_ROWS = ["c172x", *AIRFRAME_ONLY]


def sil_airframes(duration_s: float | None = None, log: Any = None) -> dict[str, Any]:
    """The airframe rows of :data:`ROWS` (scripts/bench --only sil_airframes)."""
    return sil_robustness(AIRFRAME_ROWS, duration_s, log)


def config_flavour(config: str) -> str:
    """``sil.flavour`` of a row's config file (the SIL's default, px4, when it names none)."""
    import yaml

    raw = yaml.safe_load((ROOT / config).read_text()) or {}
    return str((raw.get("sil") or {}).get("flavour", "px4"))


def profile_rows(profile: str) -> list[str]:
    """The rows a profile of ``profile``'s autopilot applies to: those whose config flies that
    flavour (PX4: the X8 demo family; ArduPlane: the Cessna rows of configs/sil_c172x.yaml and
    sil_cessna_convoy.yaml). The X8 demo missions flown by the ArduPlane flavour fail even
    without a profile (the figure-eight saturates its bank), so they are no row of it."""
    want = "px4" if profile == "px4" else "ardupilot"
    return [r.name for r in ROWS if config_flavour(r.config) == want]


def sil_robustness_px4(duration_s: float | None = None, log: Any = None) -> dict[str, Any]:
    """The PX4-flavoured rows with PX4 v1.16 SIH's identified profile (scripts/bench --only
    sil_robustness_px4): EKF2's estimate errors and turn per bank added to the same missions."""
    return sil_robustness(profile_rows("px4"), duration_s, log, profile="px4")


def sil_robustness_arduplane(duration_s: float | None = None, log: Any = None) -> dict[str, Any]:
    """The ArduPlane-flavoured rows with ArduPlane 4.7's identified profile (scripts/bench
    --only sil_robustness_arduplane): its attitude loop, turn per bank, reported wind, stamps."""
    return sil_robustness(profile_rows("arduplane"), duration_s, log, profile="arduplane")


def profile_sets(profile: str, workdir: Path, thrust: bool = False) -> list[str]:
    """The overrides that fly a row with ``profile`` (a name of :data:`PROFILES` or a YAML
    file): ``sil.autopilot_profile`` (a copy in ``workdir`` without the ``thrust`` section
    unless ``thrust``) and ``sil.flavour`` of its autopilot. Raises ConfigError on a bad
    profile (a one-line message naming it)."""
    import yaml

    from mpf_mavlink.config.autopilot_profile import load_profile

    path = Path(PROFILES.get(profile, profile))
    if not path.is_absolute():
        path = ROOT / path if (ROOT / path).is_file() else path.resolve()
    prof = load_profile(path)  # validated: a bad file fails here, before any row flies
    if not thrust and prof.thrust.full_thrust_airspeed_m_s is not None:
        raw = yaml.safe_load(path.read_text())
        raw.pop("thrust", None)
        copy = workdir / f"{path.stem}-no-thrust.yaml"
        copy.write_text(json.dumps(raw))  # JSON is YAML
        path = copy
    flavour = "px4" if prof.autopilot == "px4" else "ardupilot"
    return [f"sil.autopilot_profile={path}", f"sil.flavour={flavour}"]


def _fly(
    row: Row, out: Path, duration_s: float | None, force: bool, extra: list[str] | None = None
) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "mpf_mavlink.cli", "sim", row.config, "--out", str(out)]
    cmd += ["--no-plots", "-q"]
    for s in [*row.sets, *(extra or [])]:
        cmd += ["--set", s]
    if duration_s is not None:
        cmd += ["--set", f"sim.duration_s={duration_s}"]
    if force:
        cmd.append("--force")
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    lines = [ln for ln in (p.stdout + p.stderr).splitlines() if ln.strip()]
    verdict = next((ln for ln in reversed(lines) if ln.startswith("verdict:")), "") or next(
        (ln for ln in reversed(lines) if ln.startswith(("mpf-mavlink: error", "bridge:"))), ""
    )
    res: dict[str, Any] = {"exit": p.returncode, "verdict": verdict or (lines[-1] if lines else "")}
    res["wall_s"] = round(time.perf_counter() - t0, 1)
    mf = out / "metrics.json"
    if mf.is_file():
        m = json.loads(mf.read_text())
        for k in ("steady_rms_m", "steady_max_m", "convergence_time_s", "max_rate_cmd_rad_s"):
            res[k] = m.get(k)
        res["verdict_failures"] = m.get("verdict_failures")
    return res


def _judge(
    row: Row, r: dict[str, Any], table: dict[str, dict[str, Any]]
) -> tuple[float | None, bool | None]:
    bound = row.rms_m
    if row.rel is not None:
        ref = table.get(row.rel, {}).get("steady_rms_m")
        bound = None if ref is None else row.factor * ref
    rms, mx = r.get("steady_rms_m"), r.get("steady_max_m")
    if row.expect == "refuse":
        return bound, r.get("exit_unforced") == 3
    if bound is None and row.max_m is None:
        return bound, None
    ok = r["exit"] == 0 and rms is not None
    if ok and bound is not None:
        ok = rms is not None and rms <= bound
    if ok and row.max_m is not None:
        ok = mx is not None and mx <= row.max_m
    return bound, ok


def sil_robustness(
    rows: list[str] | None = None,
    duration_s: float | None = None,
    log: Any = None,
    profile: str | None = None,
    profile_thrust: bool = False,
) -> dict[str, Any]:
    """Fly the rows (all, or those named) in sequence; the figures and verdicts by row.
    ``profile``: fly every row with that autopilot profile (module docstring)."""
    table: dict[str, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory(prefix="mpf-bench-rob-prof-") as pd:
        extra = profile_sets(profile, Path(pd), profile_thrust) if profile else []
        for row in ROWS:
            if (rows and row.name not in rows) or (not rows and row.name in AIRFRAME_ONLY):
                continue
            table[row.name] = _row(row, table, duration_s, extra)
            if log is not None:
                log(format_row(row.name, table[row.name]))
    return table


def _row(
    row: Row, table: dict[str, dict[str, Any]], duration_s: float | None, extra: list[str]
) -> dict[str, Any]:
    """Fly one row (twice when it expects a refusal) and judge it against ``table``."""
    with tempfile.TemporaryDirectory(prefix="mpf-bench-rob-") as d:
        if row.expect == "refuse":
            r0 = _fly(row, Path(d) / "unforced", duration_s, False, extra)
            r = _fly(row, Path(d) / "forced", duration_s, True, extra)
            r["exit_unforced"], r["refusal"] = r0["exit"], r0["verdict"]
        else:
            r = _fly(row, Path(d) / "run", duration_s, False, extra)
    bound, ok = _judge(row, r, table)
    r.update(bound_rms_m=bound, bound_max_m=row.max_m, expect=row.expect, pass_=ok)
    return r


def _f(v: Any, fmt: str = "{:.3f}") -> str:
    return "-" if v is None else fmt.format(v)


HEADER = (
    f"{'row':<22} {'exit':>4} {'RMS m':>7} {'max m':>7} {'conv s':>7} "
    f"{'bound':>12} {'pass':>5}  verdict"
)


def format_row(name: str, r: dict[str, Any]) -> str:
    bound = f"{_f(r.get('bound_rms_m'), '{:.2f}')}/{_f(r.get('bound_max_m'), '{:.1f}')}"
    if r.get("expect") == "refuse":
        bound = f"refuse({r.get('exit_unforced')})"
    ok = {True: "yes", False: "NO", None: "-"}[r.get("pass_")]
    return (
        f"{name:<22} {r['exit']:>4} {_f(r.get('steady_rms_m')):>7} {_f(r.get('steady_max_m')):>7} "
        f"{_f(r.get('convergence_time_s'), '{:.1f}'):>7} {bound:>12} {ok:>5}  "
        f"{r.get('verdict', '')[:90]}"
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.robustness")
    p.add_argument("--rows", help="comma-separated row names (default: all)")
    p.add_argument("--duration", type=float, help="sim.duration_s of every row (default: config)")
    p.add_argument("--json", type=Path, help="also write the table as JSON here")
    p.add_argument(
        "--profile",
        help=f"fly every row with this autopilot profile ({', '.join(PROFILES)} or a YAML file)",
    )
    p.add_argument(
        "--profile-thrust",
        action="store_true",
        help="keep the profile's thrust section (the identified airframe's, not the X8's)",
    )
    a = p.parse_args(argv)
    names = a.rows.split(",") if a.rows else None
    if a.profile:
        from mpf_mavlink.config.autopilot_profile import load_profile
        from mpf_mavlink.errors import ConfigError

        try:
            prof = load_profile(ROOT / PROFILES[a.profile] if a.profile in PROFILES else a.profile)
        except ConfigError as e:
            print(f"robustness: --profile: {e}", file=sys.stderr)
            return 2
        if names is None:  # the rows of the profile's autopilot's flavour
            names = profile_rows(prof.autopilot)
    unknown = [n for n in names or [] if n not in {r.name for r in ROWS}]
    if unknown:
        print(f"robustness: unknown row {unknown[0]!r}", file=sys.stderr)
        return 2
    print(HEADER, flush=True)
    table = sil_robustness(
        names, a.duration, lambda s: print(s, flush=True), a.profile, a.profile_thrust
    )
    if a.json:
        a.json.write_text(json.dumps(table, indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
