"""What every configuration section is built from: the field checks and the registry of the
sections other layers add (bridge, SIL, target estimator). Its own module so that the sections
and the schema both import it and neither imports the other."""

from __future__ import annotations

from typing import Any

from mpf_mavlink.errors import ConfigError

Vec3 = tuple[float, float, float]


def _pos(**kw: Any) -> dict[str, Any]:
    return {"check": ("gt", 0.0), **kw}


def _nonneg(**kw: Any) -> dict[str, Any]:
    return {"check": ("ge", 0.0), **kw}


# Sections other modules add (bridge, SIL) register here: name -> dataclass.
EXTRA_SECTIONS: dict[str, type] = {}


def _fail(src: str, key: str, msg: str) -> ConfigError:
    return ConfigError(f"{src}: {key}: {msg}")
