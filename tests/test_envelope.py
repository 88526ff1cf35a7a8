"""The envelope monitor (bridge/envelope.py, issue 40) on synthetic sequences: episodes, one
STATUSTEXT per episode, the policy's timing, the summary the verdict names."""

from __future__ import annotations

import math

import pytest

from mpf_mavlink.bridge.envelope import (
    Demand,
    EnvelopeLimits,
    EnvelopeMonitor,
    demand_of,
    envelope_monitor,
    verdict_words,
)
from mpf_mavlink.config import load_config
from mpf_mavlink.core.adapter import AdapterParams, Setpoint

G = 9.80665
LIM = EnvelopeLimits(
    bank_rad=math.radians(30.0), pitch_min_rad=-0.35, pitch_max_rad=0.35,
    airspeed_min_m_s=15.3, airspeed_max_m_s=29.9, thrust_max=1.0, climb_max_m_s=4.0,
    sink_max_m_s=2.0, wind_max_m_s=9.0,
)  # fmt: skip
DT = 0.02  # 50 Hz steps


def calm(t: float, **kw) -> Demand:
    """A step well inside every limit (10 deg of bank, level, 22 m/s, half thrust, 5 m/s
    wind), with ``kw`` replacing some of it."""
    d = dict(bank_rad=math.radians(10.0), pitch_rad=0.0, climb_m_s=0.0, airspeed_m_s=22.0,
             thrust=0.5, wind_m_s=5.0)  # fmt: skip
    d.update(kw)
    return Demand(t, **d)


def fly(mon: EnvelopeMonitor, t0: float, t1: float, **kw):
    """Steps at 50 Hz from t0 to t1 (excluded); the texts sent and the first hand-back."""
    texts, hand = [], None
    n = round((t1 - t0) / DT)
    for i in range(n):
        a = mon.update(calm(t0 + i * DT, **kw))
        texts += a.texts
        hand = hand or a.hand_back
    return texts, hand


def test_a_limit_touched_on_and_off_is_one_episode_with_one_text():
    mon = EnvelopeMonitor(LIM, policy="warn", clear_s=1.0)
    texts, _ = fly(mon, 0.0, 10.0)
    assert texts == [] and mon.episodes() == []
    # 35 deg for 2 s, 0.5 s back at 10 deg (shorter than clear_s: the same episode), 35 deg for
    # 1 s, then calm for 3 s: one episode from 10.0 to 13.48 s (the last step at 35 deg)
    t, _ = fly(mon, 10.0, 12.0, bank_rad=math.radians(35.0))
    texts += t
    texts += fly(mon, 12.0, 12.5)[0]
    texts += fly(mon, 12.5, 13.5, bank_rad=math.radians(-36.0))[0]  # the other way: still bank
    texts += fly(mon, 13.5, 16.5)[0]
    assert texts == ["MPF envelope: bank 35.0deg > 30.0deg"]
    (ep,) = mon.episodes()
    assert ep.kind == "bank"
    assert ep.start == pytest.approx(10.0) and ep.end == pytest.approx(13.48)
    assert math.degrees(ep.peak) == pytest.approx(36.0)  # |-36| > 35
    # a second excursion after the clearing is a second episode and a second text
    t, _ = fly(mon, 16.5, 17.0, bank_rad=math.radians(31.0))
    assert t == ["MPF envelope: bank 31.0deg > 30.0deg"] and len(mon.episodes()) == 2


def test_every_kind_has_its_own_episode_and_text():
    mon = EnvelopeMonitor(LIM, policy="warn")
    a = mon.update(calm(0.0, pitch_rad=-0.5, climb_m_s=-3.0, airspeed_m_s=31.0, thrust=1.0,
                        wind_m_s=9.5))  # fmt: skip
    kinds = [t.split()[2] for t in a.texts]
    assert kinds == ["pitch", "sink", "airspeed", "thrust", "wind"]
    assert all(len(t) <= 50 for t in a.texts)  # MAVLink's STATUSTEXT carries 50 characters
    assert "pitch -28.6deg > -20.1deg" in a.texts[0]  # -0.5 rad against -0.35 rad
    assert "sink 3.00m/s > 2.00m/s" in a.texts[1]


def test_climb_and_sink_compare_a_sustained_demand():
    # the climb capability is a steady one: the demand is low-passed over 5 s. From 0 at
    # t = 10 s a held 4.5 m/s demand reaches the 4 m/s limit when 4.5 (1 - exp(-T / 5)) = 4,
    # T = 5 ln 9 = 10.99 s: the first step beyond is the 550th (550 x 0.02 s = 11.00 s > 10.99)
    mon = EnvelopeMonitor(LIM, policy="warn")
    fly(mon, 0.0, 10.0)
    texts, t_first = [], None
    for i in range(800):
        a = mon.update(calm(10.0 + i * DT, climb_m_s=4.5))
        if a.texts and t_first is None:
            texts, t_first = a.texts, 10.0 + i * DT
    assert t_first == pytest.approx(10.0 + 549 * DT)
    assert texts == ["MPF envelope: climb 4.00m/s > 4.00m/s"]  # just beyond, at 2 decimals
    # a 2 s burst of -6 m/s from level: -6 (1 - exp(-2 / 5)) = -1.98 m/s, inside the 2 m/s sink
    mon = EnvelopeMonitor(LIM, policy="warn")
    fly(mon, 0.0, 10.0)
    assert fly(mon, 10.0, 12.0, climb_m_s=-6.0)[0] == [] and mon.episodes() == []


def test_the_hold_policy_hands_back_after_exceeded_for_s_once_armed():
    # armed 60 s after engagement (t = 0): an episode from 10 s to 30 s is the capture's
    mon = EnvelopeMonitor(LIM, policy="hold", exceeded_for_s=5.0, armed_after_s=60.0)
    fly(mon, 0.0, 10.0)
    _, hand = fly(mon, 10.0, 30.0, bank_rad=0.7)
    assert hand is None and mon.handed_back is None
    fly(mon, 30.0, 70.0)
    # from 70 s on at 0.7 rad: the step at which the episode has lasted 5 s is 75.00 s; the
    # one before (74.98 s) has 4.98 s. The hand-back comes once, with its text.
    texts, hand = [], None
    for i in range(500):
        a = mon.update(calm(70.0 + i * DT, bank_rad=0.7))
        texts += a.texts
        if a.hand_back:
            hand, t_hand = a.hand_back, 70.0 + i * DT
            break
    assert hand is not None and t_hand == pytest.approx(75.0)
    assert "bank beyond its limit for 5.0 s" in hand and "peak 40.1deg, limit 30.0deg" in hand
    assert texts[-1] == "MPF envelope: bank 5s, hold"
    assert mon.update(calm(75.02, bank_rad=0.7)).hand_back is None  # said once


def test_the_hold_policy_does_not_act_on_the_wind_or_thrust_alone():
    # a wind beyond the checked one, thrust at its ceiling: said (an episode and a text
    # each), the flight goes on
    mon = EnvelopeMonitor(LIM, policy="hold", exceeded_for_s=5.0, armed_after_s=0.0)
    texts, hand = fly(mon, 0.0, 30.0, wind_m_s=12.0, thrust=1.0)
    assert hand is None
    assert texts == ["MPF envelope: thrust 1.00 > 1.00", "MPF envelope: wind 12.00m/s > 9.00m/s"]
    # the airspeed leaving its window is acted on: 5 s after it left
    _, hand = fly(mon, 30.0, 40.0, airspeed_m_s=14.0)
    assert hand is not None and "airspeed beyond its limit for 5.0 s" in hand


def test_the_warn_policy_never_hands_back():
    mon = EnvelopeMonitor(LIM, policy="warn", exceeded_for_s=5.0, armed_after_s=0.0)
    _, hand = fly(mon, 0.0, 30.0, thrust=1.0)
    assert hand is None and mon.episodes()[0].duration == pytest.approx(29.98)


def test_the_summary_counts_the_steady_window_and_the_clipped_steps():
    mon = EnvelopeMonitor(LIM, policy="warn", clear_s=1.0)
    fly(mon, 0.0, 50.0)
    fly(mon, 50.0, 70.0, bank_rad=0.6)  # 20 s in the capture's end and the steady window
    fly(mon, 70.0, 100.0)
    s = mon.summary(steady_after_s=60.0, t_end=100.0)
    k = s["kinds"]["bank"]
    # the episode is 50.00 .. 69.98 s; of the steady window 60 .. 100 s it covers 9.98 s
    assert k["episodes"] == 1 and k["longest_s"] == pytest.approx(19.98)
    assert k["steady_fraction"] == pytest.approx(9.98 / 40.0)
    # 1000 of the 5000 steps demanded a bank beyond the limit: the autopilot flew less
    assert s["clipped_fraction"] == pytest.approx(1000 / 5000)
    assert verdict_words(s) == (
        "bank at its limit 25 % of the steady window (1 episode, longest 20.0 s)"
    )
    assert s["episodes"][0]["kind"] == "bank"
    # an episode of the capture alone (before the steady window) is not named in the verdict
    mon = EnvelopeMonitor(LIM, policy="warn")
    fly(mon, 0.0, 5.0, thrust=1.0)
    fly(mon, 5.0, 100.0)
    assert verdict_words(mon.summary(60.0, 100.0)) == ""
    assert mon.summary(60.0, 100.0)["kinds"]["thrust"]["episodes"] == 1


def test_the_demanded_bank_uses_the_learned_turn_gain():
    # a level turn of rate w at airspeed v: omega_w1 = (0, 0, w) about down, w1 north; the
    # coordinated bank is atan(v w / g), and an airframe that turns 0.745 of it needs
    # atan(v w / g / 0.745)
    v, w = 22.0, 0.2
    sp = Setpoint((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), 0.5, 0.3, 0.0, 1.0)
    d = demand_of(0.0, (0.0, 0.0, w), (1.0, 0.0, 0.0), v, (0.0, 3.0, 0.0), sp, 0.745, 0.03,
                  1.0, False, LIM)  # fmt: skip
    assert d.bank_rad == pytest.approx(math.atan(v * w / G / 0.745), abs=1e-9)
    assert d.pitch_rad == pytest.approx(0.03) and d.climb_m_s == pytest.approx(0.0, abs=1e-12)
    assert d.wind_m_s == pytest.approx(3.0) and not d.clipped
    # a climbing w1 (gamma = asin(0.1)) with no path-angle rate: v sin(gamma) = 2.2 m/s
    w1 = (math.sqrt(1 - 0.01), 0.0, -0.1)
    d = demand_of(0.0, (0.0, 0.0, 0.0), w1, v, (0.0, 0.0, 0.0), sp, 1.0, 0.0, 1.0, False, LIM)
    assert d.climb_m_s == pytest.approx(2.2)
    # a set-point at the adapter's pitch clip is a clipped command
    lim = envelope_monitor(load_config("configs/bridge_arduplane.yaml"), AdapterParams()).lim
    clip = Setpoint((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), 0.5, 0.0, lim.pitch_max_rad, 1.0)
    assert demand_of(
        0.0, (0, 0, 0), (1, 0, 0), v, (0, 0, 0), clip, 1.0, 0.0, 1.0, False, lim
    ).clipped


def test_the_monitor_of_a_config_reads_its_limits_and_policy():
    cfg = load_config("configs/bridge_arduplane.yaml")
    mon = envelope_monitor(cfg, AdapterParams())
    assert mon.lim.bank_rad == pytest.approx(0.61)  # vehicle.max_bank_rad (no autopilot limit)
    # the verdict's airspeed window: 18 (1 - 0.15) .. 26 (1 + 0.15)
    assert mon.lim.airspeed_min_m_s == pytest.approx(15.3)
    assert mon.lim.airspeed_max_m_s == pytest.approx(29.9)
    assert mon.policy == "hold" and mon.exceeded_for_s == 5.0
    assert mon.armed_after_s == cfg.metrics.steady_after_s
    cfg = load_config("configs/bridge_arduplane.yaml", ["envelope.policy=warn",
                      "envelope.exceeded_for_s=2", "envelope.armed_after_s=0"])  # fmt: skip
    mon = envelope_monitor(cfg, AdapterParams())
    assert (mon.policy, mon.exceeded_for_s, mon.armed_after_s) == ("warn", 2.0, 0.0)


def test_the_capture_guards_acting_is_a_warning_episode_the_user_sees():
    """A far capture whose guards bound the turn for 20 s: one episode of kind capture, one
    STATUSTEXT naming the guard and the distance, in the summary; never a hand-back (the guards
    are how the capture stays in the envelope: POLICY_KINDS leaves them out)."""
    lim = EnvelopeLimits(**{**LIM.__dict__, "capture_m": 150.0})
    mon = EnvelopeMonitor(lim, policy="hold", exceeded_for_s=5.0, armed_after_s=0.0)
    texts, hand = fly(mon, 0.0, 20.0, capture=("turn", "path"), pt_m=412.0)
    texts += fly(mon, 20.0, 25.0)[0]
    assert hand is None and mon.handed_back is None
    assert texts == ["MPF capture: turn,path bounded at 412m"]
    (ep,) = mon.episodes()
    assert ep.kind == "capture" and ep.limit == 150.0 and ep.peak == 412.0
    assert mon.summary(10.0, 25.0)["kinds"]["capture"]["episodes"] == 1
