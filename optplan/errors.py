"""Exceptions raised by optplan.

Every error carries the offending value and what was expected, so a user can fix the input
without reading the source. Failed *solves* and *plans* are never exceptions: they are statuses
in the result objects.
"""
from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    import numpy as np


class OptplanError(Exception):
    """Base class of every optplan exception."""


class ModelError(OptplanError, ValueError):
    """A robot/scene description (TOML, URDF) is missing or malformed."""


class UnknownNameError(OptplanError, KeyError):
    """A frame, arm, joint or model name does not exist; the message lists the valid names."""

    def __init__(self, kind: str, name: object, valid: Iterable[str]):
        self.kind = kind
        self.name = name
        self.valid = sorted(str(v) for v in valid)
        shown = ", ".join(self.valid[:40]) + (" ..." if len(self.valid) > 40 else "")
        super().__init__(f"unknown {kind} {name!r}; valid {kind} names: [{shown}]")

    def __str__(self) -> str:  # KeyError would otherwise repr() the message
        return self.args[0]


class ConfigurationError(OptplanError, ValueError):
    """A configuration / velocity vector has the wrong size or non-finite entries."""


class UsageError(OptplanError, ValueError):
    """A command-line argument or environment setting is invalid (the command exits with status 2)."""


class ResultFileError(OptplanError, ValueError):
    """A saved result file (Solution, PlanResult) is unreadable, corrupted or fails its own checks;
    the message names the file and what is wrong."""


class OptionError(OptplanError, ValueError):
    """A solver or method option is unknown or has a value of the wrong type/range."""


class OutputError(OptplanError, OSError):
    """An output file or folder cannot be written (no space, file-size limit, permissions); the
    message names the path and the operating system's error (the command exits with status 2)."""


class CacheError(OptplanError, OSError):
    """The kernel cache folder (``OPTPLAN_CACHE``) is not a usable folder; the message names it."""


class FolderBusyError(OptplanError, OSError):
    """Another process writes to the same benchmark output folder; the message names the folder and
    that process's id."""


def real_array(value, what: str, error: type | None = None) -> np.ndarray:
    """``value`` as a float array, refusing what would silently become numbers: strings, booleans,
    complex numbers (NumPy drops the imaginary part), None and other objects, ragged nesting.
    Raises ``error`` (ConfigurationError by default) naming ``what`` and the value; finiteness and
    shape are the caller's checks."""
    import numbers

    import numpy as np

    error = error or ConfigurationError
    if isinstance(value, np.ndarray) and value.dtype.kind in "iuf":
        return value.astype(float, copy=False)
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError):
        raw = None
    kind = raw.dtype.kind if raw is not None else "?"
    raw = cast(np.ndarray, raw)   # None only with kind "?", which is refused below before raw is used
    shown = repr(value)
    shown = shown if len(shown) <= 200 else shown[:200] + "..."
    if kind == "O":
        flat = raw.ravel().tolist()
        if all(isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_)) for v in flat):
            return raw.astype(float)
    if kind not in "iuf":
        names = {"b": "booleans", "c": "complex numbers", "U": "strings", "S": "bytes", "O": "non-numbers",
                 "?": "a ragged or non-numeric value"}
        what_kind = names[kind] if kind in names else f"dtype {raw.dtype}"
        raise error(f"{what}: expected real numbers, got {what_kind}: {shown}")
    return raw.astype(float)


def check_vector(value, size: int, what: str, *, allow_none: bool = False):
    """Return ``value`` as a finite float vector of length ``size`` or raise ConfigurationError.

    ``what`` names the quantity in the message (e.g. ``"q (Pinocchio configuration)"``).
    """
    import numpy as np

    if value is None:
        if allow_none:
            return None
        raise ConfigurationError(f"{what}: expected an array of {size} floats, got None")
    arr = real_array(value, f"{what}: expected an array of {size} floats")
    if arr.ndim != 1:
        arr = arr.reshape(-1) if arr.size == size and arr.ndim == 2 and 1 in arr.shape else arr
    if arr.shape != (size,):
        raise ConfigurationError(f"{what}: expected shape ({size},), got shape {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        bad = np.flatnonzero(~np.isfinite(arr)).tolist()
        raise ConfigurationError(f"{what}: entries {bad} are not finite (values {arr[bad].tolist()})")
    return arr


class UnreachableError(OptplanError, RuntimeError):
    """A task asks for an object or hand pose out of the robot's reach (or, after every allowed
    redraw, no valid configuration holds it); the message names the pose, the arm and the reach.
    (A RuntimeError too: what trial generation raised before it had its own class.)"""


def check_int(value, what: str, *, minimum: int | None = None, maximum: int | None = None,
              error: type | None = None) -> int:
    """``value`` as an ``int``, refusing what ``int()`` would silently truncate or convert: floats
    with a fraction (2.7), strings ("10"), booleans, None, NaN. A float equal to an integer (10.0)
    is accepted. Raises ``error`` (OptionError by default) naming ``what`` and the value."""
    if type(value) is int and (minimum is None or value >= minimum) and (maximum is None or value <= maximum):
        return value   # the common case, without building the message
    import numbers

    import numpy as np

    error = error or OptionError
    rng = " and".join(r for r in (f" ≥ {minimum}" if minimum is not None else "",
                                  f" ≤ {maximum}" if maximum is not None else "") if r)
    ok = isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))
    if not ok and isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)):
        ok = bool(np.isfinite(float(value))) and float(value).is_integer()
    if not ok:
        raise error(f"{what}: expected an integer{rng}, got {type(value).__name__} {value!r}")
    out = int(value)
    if (minimum is not None and out < minimum) or (maximum is not None and out > maximum):
        raise error(f"{what}: expected an integer{rng}, got {value!r}")
    return out


def check_real(value, what: str, *, minimum: float | None = None, maximum: float | None = None,
               strict_minimum: bool = False, unit: str = "", error: type | None = None) -> float:
    """``value`` as a finite ``float`` within ``[minimum, maximum]`` (``minimum`` excluded when
    ``strict_minimum``), refusing strings, booleans, None, NaN and infinities. Raises ``error``
    (OptionError by default) naming ``what``, the value and the expected range with its unit."""
    if (type(value) is float or type(value) is int) and value == value and abs(value) != float("inf") and \
            (minimum is None or (value > minimum if strict_minimum else value >= minimum)) and \
            (maximum is None or value <= maximum):
        return float(value)   # the common case, without building the message
    import math
    import numbers

    import numpy as np

    error = error or OptionError
    lo = "" if minimum is None else (f" > {minimum:g}" if strict_minimum else f" ≥ {minimum:g}")
    hi = "" if maximum is None else f" ≤ {maximum:g}"
    rng = lo + (" and" if lo and hi else "") + hi + (f" {unit}" if unit and (lo or hi) else "")
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise error(f"{what}: expected a finite number{rng}, got {type(value).__name__} {value!r}")
    out = float(value)
    if not math.isfinite(out) or (minimum is not None and (out <= minimum if strict_minimum else out < minimum)) \
            or (maximum is not None and out > maximum):
        raise error(f"{what}: expected a finite number{rng}, got {value!r}")
    return out
