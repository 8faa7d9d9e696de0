"""check_real and check_int: the fast path for plain int and float values gives what the general path gives
(the value, or the same error naming it), for values in, on and outside the bounds."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from optplan.errors import OptionError, check_int, check_real

_BOUNDS = st.one_of(st.none(), st.floats(-10, 10), st.integers(-10, 10))


def _real_expected(v, minimum, maximum, strict):
    ok = math.isfinite(v) and (minimum is None or (v > minimum if strict else v >= minimum)) and \
        (maximum is None or v <= maximum)
    return float(v) if ok else None


@settings(max_examples=300, deadline=None)
@given(v=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-20, 20)), minimum=_BOUNDS,
       maximum=_BOUNDS, strict=st.booleans())
def test_check_real_plain_values(v, minimum, maximum, strict):
    want = _real_expected(v, minimum, maximum, strict)
    if want is None:
        with pytest.raises(OptionError, match="expected a finite number"):
            check_real(v, "x", minimum=minimum, maximum=maximum, strict_minimum=strict)
    else:
        got = check_real(v, "x", minimum=minimum, maximum=maximum, strict_minimum=strict)
        assert type(got) is float and got == want


@pytest.mark.parametrize("v", [True, False, "1", None, np.bool_(True), [1.0]])
def test_check_real_refuses_non_numbers(v):
    with pytest.raises(OptionError, match="x: expected a finite number"):
        check_real(v, "x")


def test_check_real_numpy_scalars_take_the_general_path():
    assert check_real(np.float32(0.5), "x", minimum=0.0) == 0.5
    with pytest.raises(OptionError, match="x: expected a finite number > 0 s, got np.float64\\(0.0\\)|got 0.0"):
        check_real(np.float64(0.0), "x", minimum=0.0, strict_minimum=True, unit="s")


@settings(max_examples=300, deadline=None)
@given(v=st.integers(-50, 50), minimum=st.one_of(st.none(), st.integers(-10, 10)),
       maximum=st.one_of(st.none(), st.integers(-10, 10)))
def test_check_int_plain_values(v, minimum, maximum):
    ok = (minimum is None or v >= minimum) and (maximum is None or v <= maximum)
    if ok:
        got = check_int(v, "n", minimum=minimum, maximum=maximum)
        assert type(got) is int and got == v
    else:
        with pytest.raises(OptionError, match="n: expected an integer"):
            check_int(v, "n", minimum=minimum, maximum=maximum)


@pytest.mark.parametrize("v", [True, 2.5, "3", None, float("nan")])
def test_check_int_refuses(v):
    with pytest.raises(OptionError, match="n: expected an integer"):
        check_int(v, "n")


def test_check_int_accepts_integral_floats_and_numpy():
    assert check_int(10.0, "n") == 10 and type(check_int(10.0, "n")) is int
    assert check_int(np.int64(3), "n", minimum=0) == 3
