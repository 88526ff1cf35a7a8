"""Prints, as JSON, every float the hot paths give on a fixed set of inputs (float.hex, exact):
the law with its diagnostics and errors record on the scenarios of test_law_equivalence, the
path evaluation, the prediction, the bridge's controller over the real ArduPlane tlog, the live
target's filter and the paper scenario. tests/test_compiled.py runs it compiled (MPF_COMPILED=1)
and with MPF_PURE_PYTHON=1 and requires the same output. ``--quick`` leaves out the 300 s paper
scenario."""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mpf_mavlink._compiled import compiled_modules  # noqa: E402
from mpf_mavlink.core.guidance import VehicleState, mpf_law  # noqa: E402
from mpf_mavlink.core.guidance.law import mpf_errors  # noqa: E402
from mpf_mavlink.core.guidance.predict import predict_rows  # noqa: E402
from tests.test_law_equivalence import _scenarios, _states  # noqa: E402
from tests.test_target_filter_equivalence import radio_feed  # noqa: E402


def _hex(x: Any) -> list[str]:
    """Every float in x (nested tuples/lists/NamedTuples, strings kept) as float.hex."""
    if isinstance(x, float | int | np.floating) and not isinstance(x, bool):
        return [float(x).hex()]
    if isinstance(x, str | bool) or x is None:
        return [repr(x)]
    if isinstance(x, np.ndarray):
        return [hashlib.sha256(np.ascontiguousarray(x, dtype=float).tobytes()).hexdigest()]
    out: list[str] = []
    for v in x:
        out += _hex(v)
    return out


def law() -> list[str]:
    out: list[str] = []
    rng = np.random.default_rng(28)
    for _, path, motion, gains, ext, v_w, wind in _scenarios():
        for s, t, p, R, eta, tgt, _, _ in _states(path, motion, 40, rng, wind):
            veh = VehicleState(t, p, R, v_w, eta)
            cmd, diag = mpf_law(s, veh, tgt, path, gains, ext)
            out += _hex(cmd) + _hex(diag)
            out += _hex(mpf_law(s, veh, tgt, path, gains, ext, diagnostics=False))
            out += _hex(mpf_errors(s, veh, tgt, path, gains, ext, "probe"))
            out += _hex(path.eval_flat(s))
            rates = tuple(rng.normal(0.0, 0.5, 3))
            segments = [(0.02, rates), (0.0, rates), (0.05, tuple(rng.normal(0.0, 0.5, 3)))]
            vp, Rb, w1 = predict_rows(veh, R, segments)
            out += _hex((vp.t, vp.floats, Rb, w1))
    return out


def controller() -> list[str]:
    from bench.control_path import issue, record_calls
    from mpf_mavlink.bridge.controller import Controller

    cfg, calls = record_calls(
        ROOT / "tests" / "data" / "arduplane-quadplane-sitl-vtol.tlog",
        ROOT / "configs" / "replay_arduplane_sitl.yaml",
    )
    out: list[str] = []
    for st in issue(Controller(cfg), calls):
        out += ["None"] if st is None else _hex(tuple(st.setpoint)) + _hex(st.row())
    return out


def target_filter() -> list[str]:
    """The live target's filter on the radio feed of test_target_filter_equivalence (5 Hz
    fixes with noise, lost and late reports, attitude-only turn rates): what became of each
    report, the posterior, and the target placed at the control time."""
    import math

    from mpf_mavlink.core.target_filter import Report, TargetEstimator, TargetFilterParams

    stream = radio_feed()
    est = TargetEstimator(TargetFilterParams(latency_s=0.05))
    out: list[str] = []
    for rx, d in stream:
        out.append(est.add(Report(**d), rx))
        post = est.latest()
        if post is not None:
            out += _hex((post.t, post.x, post.Ph, post.Pv, post.yaw))
        placed = est.place(rx + 0.02)
        out += [placed] if isinstance(placed, str) else _hex(placed)
        out += _hex(est.position_sigma(rx + 0.02)) if math.isfinite(rx) else []
    return out


def estimator() -> list[str]:
    """The estimator alone over the vehicle samples of the real ArduPlane tlog, each fed as
    recorded and then as three spoiled copies (a NaN rate, a rotation off orthonormal by
    1e-5, a ground speed beyond the bound): what update() took, every estimate at the
    attitude and at the position instant, and the wind low-pass."""
    import dataclasses

    from bench.control_path import record_calls
    from mpf_mavlink.bridge.estimator import Estimator, EstimatorParams

    _, calls = record_calls(
        ROOT / "tests" / "data" / "arduplane-quadplane-sitl-vtol.tlog",
        ROOT / "configs" / "replay_arduplane_sitl.yaml",
    )
    est = Estimator(EstimatorParams(airspeed_from_wind=False))
    out: list[str] = []

    def spoiled(s: Any) -> list[Any]:
        name = type(s).__name__
        if name == "AttitudeSample":
            return [
                dataclasses.replace(s, rates_frd=np.array([np.nan, 0.0, 0.0])),
                dataclasses.replace(s, R_B_N=np.asarray(s.R_B_N) * (1.0 + 1e-5)),
            ]
        if name in ("LocalPositionSample", "GlobalPositionSample"):
            return [dataclasses.replace(s, vel_ned=np.asarray(s.vel_ned) * 0 + 250.0)]
        return []

    for key, args in calls:
        if key != "feed_vehicle":
            continue
        sample, rx = args
        for bad in spoiled(sample):
            out.append(str(est.update(bad, rx)))
        out.append(str(est.update(sample, rx)))
        out += _hex(est._wind_lp) if est._wind_lp is not None else ["None"]
        for at_position in (False, True):
            e, why = est.estimate(at_position)
            if e is None:
                out.append(why)
                continue
            out += _hex((e.vehicle.t, e.vehicle.floats, e.vehicle.airspeed, e.R_B_N))
            out += _hex((e.rates_frd, e.ground_velocity))
            out += [e.position_source, e.airspeed_source, e.wind_source]
    return out


def paper() -> list[str]:
    from mpf_mavlink.config.schema import load_config
    from sim.runner import run_kinematic

    res = run_kinematic(load_config(ROOT / "configs" / "paper_lemniscate.yaml"), progress=False)
    return _hex(res.metrics["steady_rms_m"]) + [
        f"{k}:{_hex(np.asarray(v, dtype=float))[0]}" for k, v in sorted(res.cols.items())
    ]


def domain() -> list[str]:
    """Math at and past its domain through the compiled modules' C math (mpf_mavlink/_cmath.pxd):
    each call's floats, or the exception Python's math module raises (type and message)."""
    from mpf_mavlink.core import adapter, target_filter
    from mpf_mavlink.core.guidance import predict

    inf, nan = float("inf"), float("nan")
    calls: list[tuple[Any, tuple[Any, ...]]] = [
        (adapter._euler_to_quat_wxyz, (inf, 0.1, 0.0)),  # cos/sin of inf: ValueError
        (adapter._euler_to_quat_wxyz, (nan, 0.1, -0.2)),  # nan: no error, nan out
        (adapter._euler_to_quat_wxyz, (0.3, -0.2, 1e300)),
        (adapter.bank_and_load_factor, ((0.6, 0.8, 0.0), (inf, 1.0, 0.0))),
        (adapter.bank_and_load_factor, ((0.6, 0.8, 0.0), (nan, 1.0, 0.0))),
        (adapter.heading_and_path_angle_rates, ((0.0, 0.0, 1.0), (0.1, 0.2, 0.3))),
        (adapter.roll_rate_gain, (0.5, 1e-320)),
        (adapter.roll_rate_gain, (-0.5, 800.0)),  # expm1 overflows: OverflowError
        (adapter.roll_rate_gain, (0.5, inf)),
        (adapter.reserve_airspeed, (18.0, 25.0, 2.0, 4.0, 3.0, 10.0)),
        (adapter.reserve_airspeed, (18.0, 25.0, inf, 4.0, 3.0, 10.0)),
        (adapter.reserve_airspeed, (-18.0, 25.0, 1e308, -1e-300, 3.0, 10.0)),
        (target_filter._turn_terms, (inf, 0.1)),
        (target_filter._turn_terms, (0.2, nan)),
        (target_filter._turn_terms, (1e-9, 0.1)),
        (predict._rodrigues, (inf, 0.0, 0.0)),
        (predict._rodrigues, (nan, 0.0, 0.0)),
        (predict._rodrigues, (1e200, 1e200, 0.0)),
    ]
    out: list[str] = []
    for fn, args in calls:
        try:
            out += _hex(fn(*args))
        except Exception as e:  # noqa: BLE001 - the exception is the result compared
            out.append(f"{type(e).__name__}: {e}")
    return out


def main() -> None:
    out: dict[str, Any] = {"compiled": compiled_modules(), "law": law()}
    out["controller"] = controller()
    out["target_filter"] = target_filter()
    out["estimator"] = estimator()
    out["domain"] = domain()
    if "--quick" not in sys.argv:
        out["paper"] = paper()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
