"""The numpy arrays of a frozen state that travels as floats, built when first read.

The law's states (:class:`~mpf_mavlink.core.target.TargetState`,
:class:`~mpf_mavlink.core.guidance.law.VehicleState`) may carry their numbers as a tuple of
floats (``floats``): the hot path reads those, and the array fields are made only when
something asks for them, as read-only views of one array.

The fields are non-data descriptors put on the class after the dataclass is made (so that the
dataclass does not take them for defaults): an instance that holds a field reads it from its
``__dict__`` as any attribute, and the descriptor runs only for one that does not. Not a
``__getattr__``: a class with one makes every attribute read of its instances a generic look-up,
several times slower than the interpreter's specialised one, and the hot path reads these
states' ``floats``, ``t`` and ``airspeed`` at every step.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np
from numpy.typing import NDArray


class FloatArrays:
    """The layout of a state's ``floats``: each array field a slice ``[start, stop)`` of them,
    a 3x3 matrix by rows when the slice holds 9, a 3-vector otherwise."""

    __slots__ = ("fields", "names", "_pack")

    def __init__(self, fields: tuple[tuple[str, int, int], ...]) -> None:
        self.fields = fields
        self.names = frozenset(name for name, _, _ in fields)
        self._pack = struct.Struct(f"{max(stop for _, _, stop in fields)}d").pack

    def install(self, cls: type) -> None:
        """Give ``cls`` (a dataclass, already made) a descriptor for each array field."""
        for name, _, _ in self.fields:
            setattr(cls, name, _ArrayField(self, name))

    def fill(self, d: dict[str, Any], name: str) -> NDArray[np.float64]:
        """With an instance's ``__dict__`` ``d`` that lacks the array field ``name``: set every
        array field from ``d["floats"]`` and give ``name``'s; AttributeError when the state has
        no floats."""
        f = d.get("floats")
        if f is None:
            raise AttributeError(name)
        a = np.frombuffer(self._pack(*f))  # one read-only array, the fields views of it
        for field_name, i, j in self.fields:
            d[field_name] = a[i:j].reshape(3, 3) if j - i == 9 else a[i:j]
        got: NDArray[np.float64] = d[name]
        return got


class _ArrayField:
    """An array field of a state, made from its floats when first read (see the module)."""

    __slots__ = ("layout", "name")

    def __init__(self, layout: FloatArrays, name: str) -> None:
        self.layout, self.name = layout, name

    def __get__(self, obj: Any, objtype: Any = None) -> Any:
        if obj is None:
            raise AttributeError(self.name)  # no class-level value (dataclasses, help())
        return self.layout.fill(obj.__dict__, self.name)
