"""The SIL's realistic target feed (sim/target/feed.py): what leaves it, decoded by the bridge's
own decoders. Bounds are binomial / chi-square ones for the drawn counts and noise."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pymavlink.dialects.v20 import ardupilotmega as M  # noqa: E402

from mpf_mavlink.config.schema import load_config  # noqa: E402
from mpf_mavlink.core.frames import geodetic_to_ned  # noqa: E402
from mpf_mavlink.core.target import ConstantTurn  # noqa: E402
from mpf_mavlink.errors import ConfigError  # noqa: E402
from mpf_mavlink.mavlink.codec import decode_follow_target  # noqa: E402
from sim.plant.jsbsim_plant import LocalNED  # noqa: E402
from sim.plant.kinematic_plant import ned_to_geodetic_fast  # noqa: E402
from sim.target.feed import TargetFeed  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BOAT = ConstantTurn(speed=3.0, turn_rate=0.01)
FRAME = 0.02  # s, the vehicle's telemetry frame


ORIGIN = LocalNED(41.185, -8.76, 0.0)


def fly(seconds: float, **kw):
    """Run a feed for ``seconds`` of frames; [(delivery time, decoded message)]."""
    mav = M.MAVLink(None, srcSystem=2, srcComponent=1)
    feed = TargetFeed(BOAT, mav, ned_to_geodetic_fast, ORIGIN, **kw)
    rx = M.MAVLink(None)
    out = []
    for k in range(int(seconds / FRAME)):
        t = k * FRAME
        for buf in feed.poll(t, t):
            out.append((t, rx.decode(bytearray(buf))))
    return feed, out


def follow_targets(msgs):
    return [(t, decode_follow_target(m)) for t, m in msgs if m.get_type() == "FOLLOW_TARGET"]


def test_same_seed_same_reports_other_seed_other_reports():
    kw = dict(rate_hz=2.0, position_noise_m=2.0, velocity_noise_m_s=0.3, dropout=0.1, latency_s=0.3)
    _, a = fly(60.0, seed=3, **kw)
    _, b = fly(60.0, seed=3, **kw)
    _, c = fly(60.0, seed=4, **kw)
    pa = [(t, m.pack(M.MAVLink(None, 2, 1))) for t, m in a]
    assert pa == [(t, m.pack(M.MAVLink(None, 2, 1))) for t, m in b]
    assert pa != [(t, m.pack(M.MAVLink(None, 2, 1))) for t, m in c]


def test_one_hz_feed_with_10_percent_dropouts_latency_and_noise():
    """1000 reports: the loss count is binomial (mean 100, sigma 9.5): within 4 sigma. Each
    FOLLOW_TARGET arrives latency_s after its stamp (sender clock = ours + clock_offset_s) to
    within a frame. The position noise per axis has the configured sigma: the sample standard
    deviation of ~900 draws is within 4 x 1/sqrt(2N) (9.4 %) of it."""
    feed, msgs = fly(1000.0, rate_hz=1.0, position_noise_m=2.0, velocity_noise_m_s=0.3,
                     latency_s=0.3, dropout=0.1, clock_offset_s=100.0, messages="follow_target",
                     seed=7)  # fmt: skip
    fts = follow_targets(msgs)
    n_sent = len(fts)
    assert abs((1000 - n_sent) - 100) < 4 * math.sqrt(1000 * 0.1 * 0.9)
    assert feed.lost == 1000 - n_sent
    errs = []
    for t_rx, s in fts:
        t_true = s.t_s - 100.0
        assert abs(t_rx - (t_true + 0.3)) <= FRAME + 1e-9
        truth = BOAT.state(t_true).position
        ned = geodetic_to_ned(s.lat_deg, s.lon_deg, s.alt_amsl_m, 41.185, -8.76, 0.0)
        errs.append(ned - truth)
        assert s.est_capabilities == 0b11 and s.R_B_N is None  # position + velocity only
    sd = np.std(np.array(errs), axis=0)
    tol = 4.0 / math.sqrt(2 * n_sent)
    # 1e-7 deg quantisation (1.1 cm) is negligible against 2 m
    assert np.all(np.abs(sd / 2.0 - 1.0) < tol), sd


def test_dropout_bursts_have_the_configured_mean_length():
    """Gilbert model, mean burst 3 reports: the bursts' lengths are geometric with mean 3 (sd
    sqrt(6)); over ~N bursts the mean is within 4 sd / sqrt(N)."""
    feed, msgs = fly(3000.0, rate_hz=1.0, dropout=0.2, dropout_burst=3.0, messages="follow_target")
    stamps = sorted(round(s.t_s) for _, s in follow_targets(msgs))
    gaps = [b - a - 1 for a, b in zip(stamps, stamps[1:], strict=False) if b - a > 1]
    assert abs(np.mean(gaps) - 3.0) < 4.0 * math.sqrt(6.0) / math.sqrt(len(gaps))
    assert abs(feed.lost / 3000.0 - 0.2) < 0.05


def test_an_outage_sends_nothing_and_jitter_reorders():
    """No report is stamped inside the outage; a latency jitter of 2 s on a 1 Hz feed delivers
    some reports after later ones (the estimator must re-order them)."""
    _, msgs = fly(200.0, rate_hz=1.0, outages=[(50.0, 5.0)], latency_jitter_s=2.0,
                  messages="follow_target")  # fmt: skip
    stamps = [s.t_s for _, s in follow_targets(msgs)]
    assert not [t for t in stamps if 50.0 <= t < 55.0]
    assert any(b < a for a, b in zip(stamps, stamps[1:], strict=False))


def test_attitude_feed_carries_the_turn_rate():
    """With attitude: FOLLOW_TARGET has the attitude bit and the boat's 0.01 rad/s yaw rate,
    and an ATTITUDE follows each GLOBAL_POSITION_INT."""
    _, msgs = fly(5.0, rate_hz=1.0, attitude=True)
    fts = follow_targets(msgs)
    assert fts and all(s.est_capabilities == 0b1011 for _, s in fts)
    assert all(abs(s.rates_frd[2] - 0.01) < 1e-7 for _, s in fts)
    types = [m.get_type() for _, m in msgs]
    assert types.count("ATTITUDE") == types.count("GLOBAL_POSITION_INT") == len(fts)


def test_feed_and_estimator_keys_are_validated(tmp_path):
    cfg = load_config(ROOT / "configs" / "default.yaml", ["sil.target_feed.rate_hz=1"])
    assert cfg.section("sil").target_feed.rate_hz == 1.0
    assert cfg.section("target_estimator").mode == "filter"
    for bad, key in (
        ("sil.target_feed.rate=1", "sil.target_feed.rate"),
        ("target_estimator.gate_sigma=3", "target_estimator.gate_sigma"),
        ("target_estimator.gate_probability=1.5", "target_estimator.gate_probability"),
        ("sil.target_feed.dropout=1", "sil.target_feed.dropout"),
        ("target_estimator.history_s=20", "target_estimator.history_s"),  # > max_age_s (10)
        ("target_estimator.mode=ukf", "target_estimator.mode"),
    ):
        try:
            load_config(ROOT / "configs" / "default.yaml", [bad])
        except ConfigError as e:
            assert key in str(e) and "\n" not in str(e)
        else:
            raise AssertionError(f"{bad} accepted")
    try:
        load_config(ROOT / "configs" / "default.yaml",
                    ["sil.target_live=false", "sil.target_feed.rate_hz=1"])  # fmt: skip
    except ConfigError as e:
        assert "sil.target_feed" in str(e)
    else:
        raise AssertionError("a feed without a live target accepted")
