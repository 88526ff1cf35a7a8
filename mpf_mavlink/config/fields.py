"""What every configuration section is built from: the field checks and their documentation.
Its own module so that the section modules and the schema both import it and neither imports
the other.

A field's ``metadata`` may hold ``check`` (a bound :func:`mpf_mavlink.config.schema` enforces:
``("gt", x)``, ``("ge", x)``, ``("range", lo, hi)``, ``("range_open", lo, hi)``, ``("sign",)``)
and ``doc`` (one sentence for the configuration reference, docs/configuration.md).
"""

from __future__ import annotations

from typing import Any

from mpf_mavlink.errors import ConfigError

Vec3 = tuple[float, float, float]

Check = tuple[Any, ...]


def _pos(doc: str = "") -> dict[str, Any]:
    """A number > 0."""
    return {"check": ("gt", 0.0), "doc": doc}


def _nonneg(doc: str = "") -> dict[str, Any]:
    """A number >= 0."""
    return {"check": ("ge", 0.0), "doc": doc}


def _rng(lo: float, hi: float, doc: str = "") -> dict[str, Any]:
    """A number in [lo, hi]."""
    return {"check": ("range", lo, hi), "doc": doc}


def _open(lo: float, hi: float, doc: str = "") -> dict[str, Any]:
    """A number in (lo, hi)."""
    return {"check": ("range_open", lo, hi), "doc": doc}


def _ge(lo: float, doc: str = "") -> dict[str, Any]:
    """A number >= lo."""
    return {"check": ("ge", lo), "doc": doc}


def _doc(doc: str) -> dict[str, Any]:
    """No bound, a description only."""
    return {"doc": doc}


def _fail(src: str, key: str, msg: str) -> ConfigError:
    return ConfigError(f"{src}: {key}: {msg}")
