"""Building a typed dataclass from YAML data, strictly: unknown keys, wrong types and values
outside a field's declared check are one-line ConfigErrors naming the key and the file. Shared by
the config schema, the campaign spec and the autopilot profiles."""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from typing import Any, Literal, TypeVar

import yaml

from mpf_mavlink.config.fields import _fail
from mpf_mavlink.errors import ConfigError

S = TypeVar("S")


def _describe(tp: Any) -> str:
    """A type as the error messages and the reference name it."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in typing.get_args(tp) if a is not type(None)]
        return " or ".join(_describe(a) for a in inner) + " or null"
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is bool:
        return "true or false"
    if tp is str:
        return "a string"
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in typing.get_args(tp))
    if origin is tuple:
        return f"a list of {len(typing.get_args(tp))} numbers"
    if origin is list:
        return "a list"
    if dataclasses.is_dataclass(tp):
        return "a mapping"
    return str(tp)


def _float_spelling(text: str, src: str, key: str) -> float:
    """A number YAML 1.1 (PyYAML) left a string, for a float-typed field: ``1e-9``, ``1E5``,
    ``+3`` and ``.5e1`` are numbers to anyone typing them as Python or C would, so every spelling
    :func:`float` accepts is one (finiteness is still checked by the caller)."""
    try:
        return float(text)
    except ValueError:
        raise _fail(src, key, f"must be a number, got {text!r}") from None


def _convert(tp: Any, value: Any, src: str, key: str) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        if len(inner) == 1:
            return _convert(inner[0], value, src, key)
        raise _fail(src, key, "unsupported union")  # pragma: no cover
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise _fail(src, key, f"must be a mapping, got {value!r}")
        return _build(typing.cast(type, tp), value, src, key)
    if tp is float:
        if isinstance(value, str):
            value = _float_spelling(value, src, key)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise _fail(src, key, f"must be a number, got {value!r}")
        v = float(value)
        if not math.isfinite(v):
            raise _fail(src, key, f"must be finite, got {value!r}")
        return v
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise _fail(src, key, f"must be an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise _fail(src, key, f"must be true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise _fail(src, key, f"must be a string, got {value!r}")
        return value
    if origin is Literal:
        if value not in typing.get_args(tp):
            raise _fail(src, key, f"must be {_describe(tp)}, got {value!r}")
        return value
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, list | tuple) or len(value) != len(args):
            raise _fail(src, key, f"must be {_describe(tp)}, got {value!r}")
        return tuple(
            _convert(a, v, src, f"{key}[{i}]")
            for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if origin is list:
        (a,) = typing.get_args(tp)
        if not isinstance(value, list):
            raise _fail(src, key, f"must be a list, got {value!r}")
        return [_convert(a, v, src, f"{key}[{i}]") for i, v in enumerate(value)]
    raise _fail(src, key, f"unsupported type {tp}")  # pragma: no cover


def describe_check(chk: tuple[Any, ...] | None) -> str:
    """A field's bound in words (``> 0``, ``in [0, 1]``, ...), or "" without one."""
    if chk is None:
        return ""
    kind = chk[0]
    if kind == "gt":
        return f"> {chk[1]:g}"
    if kind == "ge":
        return f">= {chk[1]:g}"
    if kind == "range":
        return f"in [{chk[1]:g}, {chk[2]:g}]"
    if kind == "range_open":
        return f"in ({chk[1]:g}, {chk[2]:g})"
    if kind == "sign":
        return "1 or -1"
    raise ValueError(f"unknown check {chk!r}")  # pragma: no cover


def _check(meta: typing.Mapping[str, Any], v: Any, src: str, key: str) -> None:
    chk = meta.get("check")
    if chk is None or v is None:
        return
    kind = chk[0]
    if kind == "gt":
        ok = v > chk[1]
    elif kind == "ge":
        ok = v >= chk[1]
    elif kind == "range":
        ok = chk[1] <= v <= chk[2]
    elif kind == "range_open":
        ok = chk[1] < v < chk[2]
    else:
        ok = v in (-1.0, 1.0)
    if not ok:
        raise _fail(src, key, f"must be {describe_check(chk)}, got {v!r}")


def _build(cls: type[S], data: dict[str, Any], src: str, prefix: str) -> S:
    hints = typing.get_type_hints(cls)
    all_fields = dataclasses.fields(typing.cast(Any, cls))
    fields = {f.name: f for f in all_fields if not f.metadata.get("internal")}
    kwargs: dict[str, Any] = {}
    for k, v in data.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        if k not in fields:
            known = ", ".join(sorted(fields))
            raise _fail(src, key, f"unknown key (known here: {known})")
        val = _convert(hints[k], v, src, key)
        _check(fields[k].metadata, val, src, key)
        kwargs[k] = val
    return cls(**kwargs)


def parse_yaml(text: str, src: str) -> Any:
    """``text`` parsed as YAML; ConfigError "SRC: not valid YAML at line N" otherwise (every
    file the project reads: configuration, campaign, certify conditions)."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{src}: not valid YAML{where}") from None
