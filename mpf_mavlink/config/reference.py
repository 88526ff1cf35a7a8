"""The configuration reference, generated from the schema: every section, every key, its type,
default, bound and meaning, read from the dataclasses themselves (their docstrings and each
field's ``doc``), so the reference cannot drift from what the loader accepts.

    python -m mpf_mavlink.config.reference > docs/configuration.md

tests/test_config_reference.py fails when the committed file is not what this prints.
"""

from __future__ import annotations

import dataclasses
import inspect
import sys
import types
import typing
from dataclasses import MISSING
from typing import Any, Literal

from mpf_mavlink.config.build import describe_check
from mpf_mavlink.config.schema import Config, section_types

COMMAND = "python -m mpf_mavlink.config.reference > docs/configuration.md"


def _type(tp: Any) -> str:
    """A field's type as the table shows it."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in typing.get_args(tp) if a is not type(None)]
        return " or ".join(_type(a) for a in inner) + " or null"
    if origin is Literal:
        return " \\| ".join(f"`{a}`" for a in typing.get_args(tp))
    if origin is tuple:
        return f"[{', '.join(_type(a) for a in typing.get_args(tp))}]"
    if origin is list:
        (a,) = typing.get_args(tp)
        return f"list of {_type(a)}"
    if dataclasses.is_dataclass(tp):
        return "mapping"
    names = {float: "number", int: "integer", bool: "bool", str: "string"}
    return names.get(tp, str(tp))


def _value(v: object) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, tuple | list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def _default(f: dataclasses.Field[Any]) -> str:
    if f.default is not MISSING:
        if dataclasses.is_dataclass(f.default):
            return "(below)"
        return f"`{_value(f.default)}`"
    if f.default_factory is not MISSING:
        made = f.default_factory()
        return "(below)" if dataclasses.is_dataclass(made) else f"`{_value(made)}`"
    return "required"  # pragma: no cover - every key has a default


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


def _doc(cls: type) -> str:
    return _cell(inspect.cleandoc(cls.__doc__ or ""))


def _nested(tp: Any) -> type | None:
    """The dataclass a field holds (itself, in a list, or optional), or None."""
    for a in (tp, *typing.get_args(tp)):
        if dataclasses.is_dataclass(a):
            return typing.cast(type, a)
        for b in typing.get_args(a):
            if dataclasses.is_dataclass(b):
                return typing.cast(type, b)
    return None


def _section(name: str, cls: type, out: list[str]) -> None:
    hints = typing.get_type_hints(cls)
    fields = [f for f in dataclasses.fields(cls) if not f.metadata.get("internal")]
    out += [f"## `{name}`", "", _doc(cls), ""]
    out += ["| key | type | default | bound | meaning |", "|---|---|---|---|---|"]
    below: list[tuple[str, type]] = []
    for f in fields:
        tp = hints[f.name]
        sub = _nested(tp)
        key = f.name
        if sub is not None:
            is_list = typing.get_origin(tp) is list
            below.append((f"{name}.{f.name}" + ("[]" if is_list else ""), sub))
        chk = describe_check(f.metadata.get("check"))
        doc = _cell(str(f.metadata.get("doc", "")))
        out.append(f"| `{key}` | {_type(tp)} | {_default(f)} | {chk} | {doc} |")
    out.append("")
    for sub_name, sub_cls in below:
        _section(sub_name, sub_cls, out)


def reference() -> str:
    """docs/configuration.md."""
    out = [
        "# Configuration reference",
        "",
        f"Generated from the schema (`mpf_mavlink/config/`) by `{COMMAND}`; do not edit.",
        "",
        "A configuration is a YAML mapping of the sections below. Every key is optional (the",
        "default applies); an unknown key, a wrong type or a value outside its bound is an error",
        "naming the key and the file. `--set dotted.key=value` on any command overrides a key",
        "and is checked the same way. Units are in the key names (`_m`, `_m_s`, `_rad`, `_rad_s`,",
        "`_s`, `_hz`); angles in radians, NED inertial frame, FRD body.",
        "",
    ]
    hints = typing.get_type_hints(Config)
    for f in dataclasses.fields(Config):
        if f.metadata.get("internal"):
            continue
        cls = _nested(hints[f.name])
        if cls is None:
            out += [f"## `{f.name}`", "", f"{_type(hints[f.name])}, default {_default(f)}.", ""]
        else:
            _section(f.name, cls, out)
    for name, cls in section_types().items():
        _section(name, cls, out)
    return "\n".join(out).rstrip() + "\n"


def main() -> None:
    sys.stdout.write(reference())


if __name__ == "__main__":
    main()
