"""Checks of the options a user passes to IPOPT, before a (possibly long) NLP is built and solved.

IPOPT and CasADi refuse unknown names and out-of-range values only when the solver instance is
created, as a ``RuntimeError`` whose text names neither the value nor, for range errors, the
option. :func:`check_ipopt_options` creates one one-variable IPOPT instance with the options not accepted
before in this process (about 2 ms), one per option only when IPOPT refuses the set, and turns a
refusal into :class:`~optplan.errors.OptionError` naming the option, the value and what IPOPT accepts.
"""
from __future__ import annotations

import contextlib
import math
import os
import sys
from typing import Any

from .errors import OptionError

__all__ = ["casadi_option_name", "check_ipopt_options", "check_solve_arguments"]

_CASADI_LEVEL = ("print_time", "expand")


def casadi_option_name(key: str) -> str:
    """``"tol"`` → ``"ipopt.tol"``; names with a dot and CasADi's own (print_time, expand) unchanged."""
    return key if "." in key or key in _CASADI_LEVEL else f"ipopt.{key}"


@contextlib.contextmanager
def _quiet_stdout():
    """IPOPT prints its option documentation to the C-level stdout on a refusal: silence it."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), fd)
            yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


#: (option name, value type, repr of the value[, library options]) IPOPT accepted in this process
_ACCEPTED: set[tuple[str, ...]] = set()
#: options naming the library a linear solver loads
_LIBRARY_OPTIONS = ("hsllib", "pardisolib")


def check_ipopt_options(options: dict | None) -> None:
    """Raise :class:`OptionError` for an option name IPOPT/CasADi does not know or a value it refuses.

    The options not accepted before in this process are tried together in one IPOPT instance (~2 ms);
    only when IPOPT refuses them is each tried alone, to name the one it refuses."""
    if options is None:
        return
    if not isinstance(options, dict):
        raise OptionError(f"ipopt_options: expected a dict {{name: value}}, got {type(options).__name__} {options!r}")
    # the libraries a linear solver loads at the first solve (HSL's, Pardiso's): checked with it
    libs = {casadi_option_name(k): v for k, v in options.items() if isinstance(k, str) and k.split(".")[-1] in _LIBRARY_OPTIONS}
    todo: list[tuple[str, object, str, tuple[str, ...]]] = []   # (key, value, CasADi name, record)
    for key, value in options.items():
        if not isinstance(key, str):
            raise OptionError(f"ipopt_options: option names are strings, got {key!r}")
        if isinstance(value, float) and not math.isfinite(value):
            raise OptionError(f"ipopt_options[{key!r}] = {value!r}: expected a finite number")
        name = casadi_option_name(key)
        seen: tuple[str, ...] = (name, type(value).__name__, repr(value))
        if name == "ipopt.linear_solver":
            seen = seen + (repr(sorted(libs.items())),)
        if seen not in _ACCEPTED:   # IPOPT took this value before: a solve that passes its options again checks nothing
            todo.append((key, value, name, seen))
    if not todo:
        return
    if len(todo) > 1 and _accepted_together({name: value for _, value, name, _ in todo}, libs):
        _ACCEPTED.update(seen for *_, seen in todo)
        return
    for key, value, name, seen in todo:
        try:
            _try_options({name: value}, libs)
        except OptionError as exc:
            raise OptionError(f"ipopt_options[{key!r}] = {value!r}: {exc}") from None
        except (RuntimeError, TypeError, NotImplementedError) as exc:
            text = str(exc).strip().splitlines()
            why = text[-1] if text else type(exc).__name__
            if "No such IPOPT option" in str(exc) or "Unknown option" in str(exc) or "print_options" in why:
                raise OptionError(f"ipopt_options[{key!r}]: unknown IPOPT/CasADi option (see the IPOPT options "
                                  "documentation, e.g. tol, max_iter, mu_strategy, print_level)") from None
            raise OptionError(f"ipopt_options[{key!r}] = {value!r}: refused by IPOPT (wrong type or out of range; "
                              f"{why.split(':')[-1].strip()})") from None
        _ACCEPTED.add(seen)


def _accepted_together(named: dict[str, object], libs: dict[str, object]) -> bool:
    """Does IPOPT take all of ``named`` in one instance? (False: one of them is refused; each is then
    tried alone to name it.)"""
    try:
        _try_options(named, libs)
    except (RuntimeError, TypeError, NotImplementedError, OptionError):
        return False
    return True


def _try_options(named: dict[str, object], libs: dict[str, object]) -> None:
    """Create a one-variable IPOPT instance with ``named`` (CasADi names); with a linear solver among
    them, also solve once (IPOPT takes any linear solver's name and loads its library only when it
    solves). Raises what CasADi raises, or :class:`OptionError` for a linear solver it cannot load."""
    import casadi as ca

    x = ca.SX.sym("x")
    opts: dict[str, Any] = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", **named}
    solve = "ipopt.linear_solver" in named
    if solve:
        opts.update(libs)
    with _quiet_stdout():
        solver = ca.nlpsol("optplan_option_check", "ipopt", {"x": x, "f": (x - 1) * (x - 1)}, opts)
        if solve:
            solver(x0=0.0)
    if solve and solver.stats().get("return_status") == "Invalid_Option":
        raise OptionError("this IPOPT cannot load that linear solver (its library is not installed"
                          f"{'' if libs else ', or not named by hsllib / pardisolib'}); "
                          "'mumps' is always available, 'spral' in CasADi's own build")


def check_solve_arguments(tol, max_iter, objective_scaling) -> None:
    """``tol`` a finite number > 0, ``max_iter`` an integer ≥ 0, ``objective_scaling`` "auto" or a number > 0."""
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not (math.isfinite(tol) and tol > 0):
        raise OptionError(f"solve: tol: expected a finite number > 0, got {tol!r}")
    if isinstance(max_iter, bool) or not isinstance(max_iter, int) or max_iter < 0:
        try:
            import numpy as np

            ok = isinstance(max_iter, np.integer) and max_iter >= 0
        except ImportError:  # pragma: no cover
            ok = False
        if not ok:
            raise OptionError(f"solve: max_iter: expected an integer >= 0, got {max_iter!r}")
    if isinstance(objective_scaling, str) and objective_scaling == "auto":
        return
    if (isinstance(objective_scaling, bool)
                                        or not isinstance(objective_scaling, (int, float))
                                        or not (math.isfinite(objective_scaling) and objective_scaling > 0)):
        raise OptionError(f"solve: objective_scaling: expected 'auto' or a finite number > 0, got {objective_scaling!r}")
