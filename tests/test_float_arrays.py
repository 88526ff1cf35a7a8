"""The lazily built arrays of the law's states (mpf_mavlink/core/float_arrays.py)."""

from __future__ import annotations

import numpy as np
import pytest

from mpf_mavlink.core.guidance.law import VehicleState, vehicle_state_of_floats
from mpf_mavlink.core.target import TargetState, target_state_of_floats


@pytest.mark.parametrize("cls", [VehicleState, TargetState])
def test_states_keep_the_interpreters_fast_attribute_reads(cls: type) -> None:
    # a __getattr__ on the class would turn every attribute read of every state (the hot path
    # reads floats, t and airspeed at every step) into the interpreter's generic look-up
    assert not hasattr(cls, "__getattr__")


def test_a_float_built_state_makes_its_arrays_once_and_read_only() -> None:
    floats = tuple(float(i) for i in range(15))
    vs = vehicle_state_of_floats(2.0, floats, 18.0)
    assert "position" not in vs.__dict__  # nothing made until read
    R = vs.R_W_I
    assert R.shape == (3, 3) and R.tolist() == [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [6.0, 7.0, 8.0]]
    assert vs.position.tolist() == [9.0, 10.0, 11.0] and vs.wind.tolist() == [12.0, 13.0, 14.0]
    assert vs.R_W_I is R  # made once, then an ordinary attribute
    with pytest.raises(ValueError):
        vs.position[0] = 1.0  # read-only: the floats stay the one truth
    eq = VehicleState(2.0, np.arange(9.0, 12.0), np.arange(9.0).reshape(3, 3), 18.0, vs.wind)
    assert repr(eq) == repr(vs)


def test_an_array_built_state_reads_its_own_arrays_and_lacks_what_it_never_had() -> None:
    p = np.array([1.0, 2.0, 3.0])
    st = TargetState(0.0, p, np.zeros(3), np.zeros(3), np.eye(3))
    assert st.position is p and st.floats is None
    ts = target_state_of_floats(1.0, tuple(float(i) for i in range(24)))
    assert ts.omega_dot_T.tolist() == [21.0, 22.0, 23.0]
    bare = object.__new__(TargetState)  # neither arrays nor floats
    with pytest.raises(AttributeError):
        _ = bare.position
