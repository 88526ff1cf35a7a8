"""Build the guidance core's objects (path, target motion, gains, extensions) from a validated
Config: the one place that knows both the YAML sections and the core's types, so the core stays
free of configuration."""

from __future__ import annotations

from mpf_mavlink.config.schema import Config, PathConfig, TargetConfig
from mpf_mavlink.core.guidance.capture import CaptureGuard, CaptureParams
from mpf_mavlink.core.guidance.law import Extensions, Gains
from mpf_mavlink.core.paths import TabulatedPath, circle, helix, lemniscate, line, spline
from mpf_mavlink.core.target import ConstantTurn, PaperProfile, Stationary, TargetMotion


def build_path(p: PathConfig) -> TabulatedPath:
    """The path described by the config, tabulated (a few ms to a second for a long one: the
    caller builds it once and hands it on)."""
    if p.type == "lemniscate":
        assert p.size_m is not None
        path = lemniscate(p.size_m, p.center_m)
    elif p.type == "circle":
        assert p.radius_m is not None
        path = circle(p.center_m, p.radius_m, p.clockwise)
    elif p.type == "helix":
        assert p.radius_m is not None and p.climb_per_turn_m is not None and p.turns is not None
        path = helix(p.center_m, p.radius_m, p.climb_per_turn_m, p.turns, p.clockwise)
    elif p.type == "line":
        assert p.start_m is not None and p.end_m is not None
        path = line(p.start_m, p.end_m)
    else:
        assert p.waypoints_m is not None
        path = spline(p.waypoints_m, p.closed)
    return path


def build_target(t: TargetConfig) -> TargetMotion:
    """A scripted target motion (``mavlink`` targets are built by the bridge)."""
    if t.type == "stationary":
        return Stationary(t.position_ned_m, t.yaw_rad)
    if t.type == "constant_turn":
        return ConstantTurn(
            t.position_ned_m, t.speed_m_s, t.heading_rad, t.turn_rate_rad_s, t.climb_rate_m_s
        )
    if t.type == "paper":
        return PaperProfile(t.position_ned_m, t.yaw_rad)
    raise ValueError("a live MAVLink target has no scripted motion")


def build_gains(cfg: Config) -> Gains:
    g = cfg.guidance
    return Gains(K_p=g.K_p, K_R=g.K_R, alpha=g.alpha_m)


def build_extensions(cfg: Config) -> Extensions:
    g = cfg.guidance
    return Extensions(
        rate_limit=g.rate_limit_rad_s,
        rate_limit_mode=g.rate_limit_mode,
        psi_turn=g.psi_turn,
        psi_turn_threshold=g.psi_turn_threshold,
        psi_turn_rate=g.psi_turn_rate_rad_s,
        wind_compensation=g.wind_compensation,
    )


def build_capture(cfg: Config, path: TabulatedPath | None = None) -> CaptureGuard | None:
    """The capture guards of ``guidance`` (core/guidance/capture.py) for the config's path
    (``path``: that path already built), or None when ``guidance.capture_guards`` is off or the
    law is a baseline."""
    g = cfg.guidance
    if not g.capture_guards or g.law != "mpf":
        return None
    v, a = cfg.vehicle, cfg.section("adapter")
    bank = (
        v.max_bank_rad
        if v.autopilot_bank_limit_rad is None
        else min(v.max_bank_rad, v.autopilot_bank_limit_rad)
    )
    trim = a.trim_pitch_rad
    params = CaptureParams(
        distance_m=g.capture_distance_m,
        bank_limit_rad=bank,
        bank_margin_rad=g.capture_bank_margin_rad,
        turn_gain=v.turn_gain,
        pitch_min_rad=a.min_pitch_rad - trim,
        pitch_max_rad=a.max_pitch_rad - trim,
        tau_s=a.tau_pitch_s if a.tau_pitch_s > 0.0 else 1.0,
        floor_margin_m=g.capture_floor_margin_m,
        altitude_floor_m=cfg.metrics.altitude_floor_m,
    )
    return CaptureGuard((build_path(cfg.path) if path is None else path).positions(), params)
