"""The threads of the BLAS under IPOPT's linear solver, limited during a solve.

CasADi's wheels bundle their own OpenBLAS (``libcasadi-tp-openblas``), which MUMPS calls for the
dense frontal matrices of IPOPT's factorizations. By default it starts one thread per core, and
after each factorization its idle worker threads spin in ``sched_yield`` before they sleep: on
the re-solve of a small problem (the free-floating reach, N = 20) the process used about twice
its wall time in CPU, most of it system time, and the spinning thread competed with the rest of
the solve whenever the other core was busy. The fronts of optplan's NLPs are small: one thread
solves them as fast (docs/optproblem.md, "Re-solve overhead and the BLAS threads").

:func:`limited_blas_threads` sets that library's thread count for the duration of a solve and
restores the previous count afterwards, so a user's own use of the library is untouched. It
only acts on OpenBLAS copies shipped inside CasADi's package directory and loaded in the process
(found once; a CasADi linked against another BLAS is left as it is). numpy's and scipy's own
OpenBLAS copies are not involved: IPOPT does not call them.
"""
from __future__ import annotations

import ctypes
import glob
import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["casadi_blas_libraries", "limited_blas_threads"]

_lock = threading.Lock()
_depth = 0                          # solves inside the limit now (several threads may solve at once)
_saved: list[int] = []              # the libraries' thread counts before the outermost limit
_libs: list[Any] | None = None      # the ctypes handles, once found


def _candidates() -> list[str]:
    """Files of CasADi's package directory that look like an OpenBLAS (one per real file)."""
    try:
        import casadi
    except ImportError:   # pragma: no cover - CasADi is a core dependency
        return []
    d = os.path.dirname(os.path.abspath(casadi.__file__))
    seen: dict[str, str] = {}
    for path in sorted(glob.glob(os.path.join(d, "*openblas*"))):
        if path.endswith((".so", ".dylib", ".dll")) or ".so." in os.path.basename(path):
            seen.setdefault(os.path.realpath(path), path)
    return list(seen.values())


def casadi_blas_libraries() -> list[Any]:
    """The OpenBLAS libraries of CasADi's package that are loaded in this process and can set
    their thread count (``openblas_set_num_threads``), as ``ctypes`` handles; found once, after
    the first IPOPT instance loaded them (an empty list until then, and on other builds)."""
    global _libs
    if _libs is not None:
        return _libs
    mode = getattr(os, "RTLD_NOLOAD", None)
    if mode is None:   # no way to ask for an already loaded library only (e.g. Windows)
        _libs = []
        return _libs
    found, pending = [], False
    for path in _candidates():
        try:
            lib = ctypes.CDLL(path, mode=mode | getattr(os, "RTLD_LAZY", 1))
        except OSError:   # not loaded (yet): CasADi loads it with its IPOPT plugin
            pending = True
            continue
        try:
            get, put = lib.openblas_get_num_threads, lib.openblas_set_num_threads
        except AttributeError:
            continue
        get.restype, get.argtypes = ctypes.c_int, []
        put.restype, put.argtypes = None, [ctypes.c_int]
        found.append(lib)
    if found or not pending:
        _libs = found
    return found


@contextmanager
def limited_blas_threads(n: int | None) -> Iterator[None]:
    """CasADi's OpenBLAS runs ``n`` threads inside the block (``None``: unchanged), then the
    counts it had before. Nested and concurrent blocks share one limit: the outermost sets it
    and the last to leave restores it."""
    global _depth, _saved
    libs = casadi_blas_libraries() if n is not None else []
    if not libs:
        yield
        return
    with _lock:
        if _depth == 0:
            _saved = [int(lib.openblas_get_num_threads()) for lib in libs]
            for lib in libs:
                lib.openblas_set_num_threads(int(n))   # type: ignore[arg-type]
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                for lib, k in zip(libs, _saved):
                    lib.openblas_set_num_threads(k)
