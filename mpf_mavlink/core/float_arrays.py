"""The numpy arrays of a frozen state that travels as floats, built when first read.

The law's states (:class:`~mpf_mavlink.core.target.TargetState`,
:class:`~mpf_mavlink.core.guidance.law.VehicleState`) may carry their numbers as a tuple of
floats (``floats``): the hot path reads those, and the array fields are made only when
something asks for them, as read-only views of one array.
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

    def fill(self, d: dict[str, Any], name: str) -> NDArray[np.float64]:
        """For ``__getattr__`` (called only for an attribute the instance does not hold): with
        the instance's ``__dict__`` ``d``, set every array field from ``d["floats"]`` and give
        ``name``'s; AttributeError when the state has no floats or ``name`` is not an array."""
        f = d.get("floats")
        if f is None or name not in self.names:
            raise AttributeError(name)
        a = np.frombuffer(self._pack(*f))  # one read-only array, the fields views of it
        for field_name, i, j in self.fields:
            d[field_name] = a[i:j].reshape(3, 3) if j - i == 9 else a[i:j]
        return d[name]
