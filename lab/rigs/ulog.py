"""PX4's ULog, read for what the rig needs: EKF2's estimate against SIH's truth.

``python -m lab.rigs.ulog RUN_DIR`` (a PX4 rig run directory, MPF or ``--guidance native``):
the ULog in ``RUN_DIR/firmware/px4-work/log/`` gives ``vehicle_local_position`` (EKF2's
estimate, what PX4 flies on and streams as LOCAL_POSITION_NED) and
``vehicle_local_position_groundtruth`` (SIH's truth). It prints the estimate's error against the
truth over the steady window (its constant part, an origin offset that moves the whole mission,
removed) and the distance from the moving path ``e`` measured both ways: from the estimate (the
head-to-head's figure) and from the truth. A floor both guidances share is an estimate error
of the size of e.

A minimal reader of the ULog file format (PX4's documented dev guide, "ULog File Format"):
definitions (formats, subscriptions) and data messages of the topics asked for, decoded with
numpy structured types. No pyulog in the lock file.
"""

from __future__ import annotations

import json
import math
import struct
import sys
from pathlib import Path
from typing import Any

import numpy as np

_MAGIC = b"ULog\x01\x12\x35"
_BASIC = {
    "int8_t": "i1", "uint8_t": "u1", "int16_t": "<i2", "uint16_t": "<u2", "int32_t": "<i4",
    "uint32_t": "<u4", "int64_t": "<i8", "uint64_t": "<u8", "float": "<f4", "double": "<f8",
    "bool": "u1", "char": "S1",
}  # fmt: skip


def _dtype(name: str, formats: dict[str, str], cache: dict[str, np.dtype]) -> np.dtype:
    """The packed numpy type of format ``name`` ("type field;type[n] field;...")."""
    if name in cache:
        return cache[name]
    fields: list[tuple[str, Any, int]] = []  # (name, dtype, offset)
    off = 0
    for spec in filter(None, formats[name].split(";")):
        typ, fname = spec.rsplit(" ", 1)
        n = 1
        if "[" in typ:
            typ, cnt = typ[:-1].split("[")
            n = int(cnt)
        base = np.dtype(_BASIC[typ]) if typ in _BASIC else _dtype(typ, formats, cache)
        dt = base if n == 1 else np.dtype((base, (n,)))
        fields.append((fname, dt, off))
        off += dt.itemsize
    dt = np.dtype(
        {
            "names": [f[0] for f in fields],
            "formats": [f[1] for f in fields],
            "offsets": [f[2] for f in fields],
            "itemsize": off,
        }
    )
    cache[name] = dt
    return dt


def read_topics(path: Path, topics: set[str]) -> dict[str, np.ndarray]:
    """The data of ``topics`` (instance 0) as structured arrays (timestamp in us, boot time)."""
    data = Path(path).read_bytes()
    if not data.startswith(_MAGIC):
        raise ValueError(f"{path}: not a ULog file")
    i = 16
    formats: dict[str, str] = {}
    subs: dict[int, str] = {}
    chunks: dict[int, list[bytes]] = {}
    n = len(data)
    while i + 3 <= n:
        size, typ = struct.unpack_from("<HB", data, i)
        body = data[i + 3 : i + 3 + size]
        i += 3 + size
        if len(body) < size:
            break  # a log cut short
        if typ == ord("F"):
            fname, fields = body.decode(errors="replace").split(":", 1)
            formats[fname] = fields
        elif typ == ord("A"):
            multi, msg_id = struct.unpack_from("<BH", body, 0)
            name = body[3:].decode(errors="replace")
            if name in topics and multi == 0:
                subs[msg_id] = name
                chunks[msg_id] = []
        elif typ == ord("D"):
            (msg_id,) = struct.unpack_from("<H", body, 0)
            if msg_id in chunks:
                chunks[msg_id].append(body[2:])
    out: dict[str, np.ndarray] = {}
    cache: dict[str, np.dtype] = {}
    for msg_id, name in subs.items():
        dt = _dtype(name, formats, cache)
        # a message's trailing padding is not logged: zeros restore the packed size
        rows = [c[: dt.itemsize].ljust(dt.itemsize, b"\0") for c in chunks[msg_id]]
        out[name] = np.frombuffer(b"".join(rows), dtype=dt)
    return out


def _t0_of_bridge(run: Path) -> float | None:
    """The bridge's mission time origin (s, autopilot boot), from its tlog's ``MPF t0=``."""
    from mpf_mavlink.mavlink.tlog_read import iter_tlog

    for _, m in iter_tlog(run / "bridge" / "mavlink.tlog", types=("STATUSTEXT",)):
        text = str(m.text)
        if text.startswith("MPF t0="):
            try:
                return float(text.split("=", 1)[1].split()[0])
            except ValueError:
                return None
    return None


def _track(run: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, Path]:
    """(t boot s, aircraft NED, target NED, target yaw rad, rel (n,3), path nodes file)."""
    native = (run / "native_track.csv").is_file()
    d = np.genfromtxt(run / ("native_track.csv" if native else "bridge/timeseries.csv"),
                      delimiter=",", names=True)  # fmt: skip
    p, tp, rel = (np.column_stack([d[f"{w}{x}"] for x in xs]) for w, xs in
                  (("p_", "ned"), ("tgt_", "ned"), ("rel_", "xyz")))  # fmt: skip
    if native:
        t0 = float(json.loads((run / "summary.json").read_text())["native"]["t0_boot_s"])
        return d["t"] + t0, p, tp, _yaw(p, tp, rel), rel, run / "native_path_T.csv"
    t0b = _t0_of_bridge(run)
    if t0b is None:
        raise ValueError(f"{run}: no 'MPF t0=' in the bridge's tlog")
    return d["t"] + t0b, p, tp, d["tgt_yaw"], rel, run / "bridge" / "path_T.csv"


def _yaw(p: np.ndarray, tp: np.ndarray, rel: np.ndarray) -> np.ndarray:
    """The target's yaw (rad) from the aircraft in NED and in the target's frame (a level
    target: R_T^I = Rz(yaw))."""
    d = p - tp
    return np.arctan2(d[:, 1], d[:, 0]) - np.arctan2(rel[:, 1], rel[:, 0])


def _euler(q: np.ndarray) -> np.ndarray:
    """ZYX Euler angles (rad; roll, pitch, yaw) of quaternions (n, 4: w, x, y, z)."""
    w, x, y, z = q.T
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.column_stack([roll, pitch, yaw])


def _attitude_error(ul: dict[str, np.ndarray], tb: np.ndarray) -> dict[str, Any]:
    """EKF2's attitude error against SIH's (deg): mean and RMS about the mean, roll / pitch /
    yaw, at the boot times ``tb`` (s)."""
    a, g = ul.get("vehicle_attitude"), ul.get("vehicle_attitude_groundtruth")
    if a is None or g is None or not len(a) or not len(g):
        return {}
    ea, eg = _euler(a["q"].astype(float)), _euler(g["q"].astype(float))
    ta, tg = a["timestamp"] / 1e6, g["timestamp"] / 1e6
    err = []
    for k in range(3):
        ua, ug = np.unwrap(ea[:, k]), np.unwrap(eg[:, k])
        d = np.interp(tb, ta, ua) - np.interp(tb, tg, ug)
        err.append((d + np.pi) % (2 * np.pi) - np.pi)
    E = np.degrees(np.column_stack(err))
    mean = E.mean(axis=0)
    return {
        "attitude_error_mean_rpy_deg": mean.tolist(),
        "attitude_error_rms_about_mean_rpy_deg": np.sqrt(np.mean((E - mean) ** 2, axis=0)).tolist(),
    }


def _roll_error_explains_radial(
    ul: dict[str, np.ndarray], tb: np.ndarray, rel: np.ndarray, P: np.ndarray, m: np.ndarray
) -> dict[str, Any]:
    """How much of the radial error (m, from the estimate) follows EKF2's roll error: the
    correlation of the two (5 s moving means, steady window) with the radial error lagging by
    0..15 s, at the lag where it is largest. An aircraft banked by its estimate turns by the
    true bank: a roll error is a lateral acceleration error that the position shows seconds
    later, whatever guidance flies it."""
    a, g = ul.get("vehicle_attitude"), ul.get("vehicle_attitude_groundtruth")
    if a is None or g is None or not len(a) or not len(g) or m.sum() < 100:
        return {}
    ra = np.unwrap(_euler(a["q"].astype(float))[:, 0])
    rg = np.unwrap(_euler(g["q"].astype(float))[:, 0])
    droll = np.interp(tb, a["timestamp"] / 1e6, ra) - np.interp(tb, g["timestamp"] / 1e6, rg)
    c = P[:, :2].mean(axis=0)
    rad = np.hypot(*(rel[:, :2] - c).T) - float(np.mean(np.hypot(*(P[:, :2] - c).T)))
    dt = float(np.median(np.diff(tb)))
    k = max(1, round(5.0 / dt))
    x = np.convolve(droll, np.ones(k) / k, mode="same")[m]
    y = np.convolve(rad, np.ones(k) / k, mode="same")[m]
    best = (0.0, 0.0)
    for lag in range(0, round(15.0 / dt) + 1, max(1, round(0.5 / dt))):
        r = float(np.corrcoef(x[: len(x) - lag], y[lag:])[0, 1]) if lag < len(x) - 10 else 0.0
        if abs(r) > abs(best[0]):
            best = (r, lag * dt)
    return {"radial_vs_roll_error_corr": best[0], "radial_lag_behind_roll_error_s": best[1]}


def estimator_floor(run: Path, steady_after_s: float = 60.0) -> dict[str, Any]:
    """EKF2's position error against SIH's truth over the steady window, and e from both."""
    from mpf_mavlink.runs.compare import distance_to_polyline

    logs = sorted((run / "firmware" / "px4-work").rglob("*.ulg"))
    if not logs:
        raise ValueError(f"{run}: no ULog under firmware/px4-work")
    ul = read_topics(
        logs[-1],
        {
            "vehicle_local_position",
            "vehicle_local_position_groundtruth",
            "vehicle_attitude",
            "vehicle_attitude_groundtruth",
        },
    )
    est, tru = ul["vehicle_local_position"], ul["vehicle_local_position_groundtruth"]
    te, tt = est["timestamp"] / 1e6, tru["timestamp"] / 1e6
    tb, p, tp, yaw, rel, nodes_csv = _track(run)
    P = np.genfromtxt(nodes_csv, delimiter=",", skip_header=1).reshape(-1, 3)
    t_rel = tb - tb[0]
    m = t_rel >= steady_after_s
    # the truth at the rig's samples, and the estimate at the same instants (the ULog's own)
    truth = np.column_stack([np.interp(tb, tt, tru[k]) for k in ("x", "y", "z")])
    estim = np.column_stack([np.interp(tb, te, est[k]) for k in ("x", "y", "z")])
    err = estim - truth
    offset = err[m].mean(axis=0)  # the origins differ: a constant shift of the whole mission
    fl = err[m] - offset
    c, s = np.cos(yaw), np.sin(yaw)
    q = truth + offset - tp
    rel_true = np.column_stack([c * q[:, 0] + s * q[:, 1], -s * q[:, 0] + c * q[:, 1], q[:, 2]])
    e_est = distance_to_polyline(P, rel[m], True)
    e_true = distance_to_polyline(P, rel_true[m], True)
    # the part of the estimate's error that e sees: along the path's normal (radial) and height
    cen = P[:, :2].mean(axis=0)
    ur = rel[m, :2] - cen
    ur /= np.maximum(np.linalg.norm(ur, axis=1, keepdims=True), 1e-9)
    err_T = np.column_stack(
        [c[m] * fl[:, 0] + s[m] * fl[:, 1], -s[m] * fl[:, 0] + c[m] * fl[:, 1], fl[:, 2]]
    )
    radial = np.sum(err_T[:, :2] * ur, axis=1)
    att = _attitude_error(ul, tb[m])
    att.update(_roll_error_explains_radial(ul, tb, rel, P, m))
    return {
        "ulog": str(logs[-1]),
        **att,
        "steady_samples": int(np.count_nonzero(m)),
        "origin_offset_ned_m": offset.tolist(),
        "estimate_error_rms_horizontal_m": float(np.sqrt(np.mean(np.sum(fl[:, :2] ** 2, 1)))),
        "estimate_error_rms_radial_m": float(np.sqrt(np.mean(radial**2))),
        "estimate_error_rms_vertical_m": float(np.sqrt(np.mean(fl[:, 2] ** 2))),
        "estimate_error_max_3d_m": float(np.max(np.linalg.norm(fl, axis=1))),
        "e_rms_from_estimate_m": float(np.sqrt(np.mean(e_est**2))),
        "e_rms_from_truth_m": float(np.sqrt(np.mean(e_true**2))),
        "e_max_from_truth_m": float(np.max(e_true)),
        "e_mean_vertical_from_truth_m": float(np.mean(-rel_true[m, 2])),
    }


def _show(v: Any) -> str:
    if isinstance(v, list):
        return str([round(x, 3) for x in v])
    if isinstance(v, float) and math.isfinite(v):
        return f"{v:.3f}"
    return str(v)


def main(argv: list[str]) -> int:
    if not argv:
        print("usage: python -m lab.rigs.ulog RUN_DIR...", file=sys.stderr)
        return 2
    for d in argv:
        try:
            f = estimator_floor(Path(d))
        except (OSError, ValueError, KeyError) as e:
            print(f"{d}: {e}", file=sys.stderr)
            return 1
        print(d)
        for k, v in f.items():
            print(f"  {k}: {_show(v)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
