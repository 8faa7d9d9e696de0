"""RRT-Connect as one native call: the search of :func:`optplan.planners.rrtconnect.rrt_connect` and
the shortcuts of :func:`~optplan.planners.rrtconnect.shortcut_path` in C (:mod:`.rrtc_csource`), on the
planning kernel's forward kinematics and exact primitive tests.

:func:`native_rrt_connect` runs one query for a validity function of a
:class:`~optplan.planners.validity.ValidityChecker` whose backend is the native kernel; it returns
None when that is not the case (the caller then runs the Python search). The random stream is the
kernel's own (xoshiro256**), seeded once per query by a 64-bit integer drawn from the caller's NumPy
Generator: the same Generator state gives the same search, but not the Python search's.
"""
from __future__ import annotations

import ctypes
import hashlib
import logging
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...codegen import build_library, cache_dir
from .csource import C_SOURCE
from .native import KernelUnavailable
from .rrtc_csource import RRTC_SOURCE, RRTC_STATUS

if TYPE_CHECKING:
    from ..base import Deadline
    from ..validity import ConfigValidity

__all__ = ["NativeRRTCResult", "load_rrtc_library", "native_rrt_connect"]
log = logging.getLogger(__name__)

_LIB: list[Any] = []
_FAILED: list[str] = []
_P = ctypes.c_void_p
#: nodes of both trees at which a native query stops (status ``"node cap"``) [count]
MAX_NODES = 2_000_000


def load_rrtc_library() -> Any:
    """The compiled kernel with the RRT-Connect entry points (``ctypes.CDLL``), built at first use and
    cached under :func:`optplan.codegen.cache_dir` by a hash of its source. Raises
    :class:`~.native.KernelUnavailable` when it cannot be built."""
    if _LIB:
        return _LIB[0]
    if _FAILED:
        raise KernelUnavailable(_FAILED[0])
    source = C_SOURCE + RRTC_SOURCE
    digest = hashlib.sha1(source.encode()).hexdigest()[:16]
    lib_path = cache_dir() / f"optplan_rrtc_kernel_{digest}.so"
    lib = None
    for attempt in range(2):
        if not lib_path.exists():
            with tempfile.TemporaryDirectory() as tmp:
                c_file = Path(tmp, "rrtc_kernel.c")
                c_file.write_text(source)
                err = build_library(c_file, lib_path, "-O3")
            if err is not None:
                _FAILED.append(f"the native RRT-Connect could not be compiled: {err}")
                raise KernelUnavailable(_FAILED[0])
        try:
            lib = ctypes.CDLL(str(lib_path))
            break
        except OSError as e:   # a damaged cache file: rebuilt once
            if attempt:
                raise KernelUnavailable(f"the native RRT-Connect library {lib_path} cannot be loaded: {e}") from None
            log.warning("the cached RRT-Connect kernel %s cannot be loaded (%s); rebuilding it", lib_path, e)
            lib_path.unlink(missing_ok=True)
    assert lib is not None
    lib.rrtc_plan.restype = ctypes.c_int
    lib.rrtc_plan.argtypes = [_P, _P, _P, ctypes.c_int, ctypes.c_int, _P, _P, _P, _P, _P, _P, ctypes.c_double,
                              ctypes.c_double, ctypes.c_longlong, ctypes.c_longlong, ctypes.c_int, ctypes.c_int,
                              ctypes.c_double, ctypes.c_ulonglong, ctypes.POINTER(ctypes.POINTER(ctypes.c_double)),
                              ctypes.POINTER(ctypes.c_int), _P]
    lib.rrtc_free.restype = None
    lib.rrtc_free.argtypes = [_P]
    _LIB.append(lib)
    return lib


class NativeRRTCResult:
    """One native query: ``status`` (``"found"``, ``"iteration cap"``, ``"time limit"``, ``"node cap"``,
    ``"out of memory"``), ``path`` (list of configurations of the searched joints, start to goal, after
    the shortcuts; None unless found), ``iterations``, ``nodes`` (both trees) and ``checks``
    (configurations checked) [counts]."""

    __slots__ = ("status", "path", "iterations", "nodes", "checks")

    def __init__(self, status: str, path: list[np.ndarray] | None, iterations: int, nodes: int, checks: int) -> None:
        self.status, self.path, self.iterations, self.nodes, self.checks = status, path, iterations, nodes, checks


def _clock(deadline: Deadline) -> tuple[int, float]:
    """(0 CLOCK_MONOTONIC / 1 CLOCK_PROCESS_CPUTIME_ID, the deadline's end on that clock [s])."""
    if deadline.clock is time.perf_counter:
        return 0, float(deadline.end)
    if deadline.clock is time.process_time:
        return 1, float(deadline.end)
    return 0, time.perf_counter() + float(deadline.remaining())


def native_rrt_connect(start: np.ndarray, goal: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                       validity: Any, rng: np.random.Generator, deadline: Deadline, *, range_: float,
                       resolution: float, max_iterations: int = 0,
                       shortcut_iterations: int = 0) -> NativeRRTCResult | None:
    """RRT-Connect from ``start`` to ``goal`` in the box ``[lower, upper]`` and ``shortcut_iterations``
    random shortcuts, in one native call; ``range_`` [rad] is the largest extension, ``resolution`` [rad]
    the largest joint change between two checks of an edge, ``max_iterations`` the cap on samples (0:
    the deadline only). ``validity`` must be a :class:`~optplan.planners.validity.ConfigValidity` of a
    checker with the native backend, else None is returned (as when the library cannot be built).
    One 64-bit seed is drawn from ``rng``. The checker's ``n_checks`` grows by the configurations checked."""
    from ..validity import ConfigValidity

    if not isinstance(validity, ConfigValidity):
        return None
    ck = validity.checker
    nat = getattr(ck, "_native", None)
    if nat is None:
        return None
    try:
        lib = load_rrtc_library()
    except KernelUnavailable as e:
        log.debug("native RRT-Connect unavailable (%s): the Python search runs", e)
        return None
    mode, pose = _mode(validity)
    nq = int(ck.model.nq)
    if validity.base is None:
        base = np.zeros(nq)
        jidx = np.arange(nq, dtype=np.int32)
    else:
        base = np.ascontiguousarray(validity.base, dtype=float)
        jidx = np.ascontiguousarray(validity.joints, dtype=np.int32)
    arrays = [np.ascontiguousarray(a, dtype=float) for a in (start, goal, lower, upper)]
    dim = int(jidx.size)
    if any(a.shape != (dim,) for a in arrays):
        raise ValueError(f"native_rrt_connect: start, goal, lower and upper must have {dim} values, got shapes "
                         f"{[a.shape for a in arrays]}")
    kern = nat.kernel
    g = kern._override(nat._override(mode, pose))
    mask = nat.masks[mode]
    clock_kind, end = _clock(deadline)
    seed = int(rng.integers(0, 2**63))
    out = ctypes.POINTER(ctypes.c_double)()
    n_out = ctypes.c_int(0)
    stats = np.zeros(3, np.int64)
    code = lib.rrtc_plan(kern._km_p, mask.ctypes.data, kern._pose_p, g, dim, jidx.ctypes.data, base.ctypes.data,
                         *(a.ctypes.data for a in arrays), float(range_), float(resolution), int(max_iterations),
                         MAX_NODES, int(shortcut_iterations), clock_kind, end, seed, ctypes.byref(out),
                         ctypes.byref(n_out), stats.ctypes.data)
    ck.n_checks += int(stats[2])
    if code == -2:
        return None
    path = None
    if code == 0:
        try:
            P = np.ctypeslib.as_array(out, shape=(n_out.value, dim)).copy()
        finally:
            lib.rrtc_free(out)
        path = list(P)
    return NativeRRTCResult(RRTC_STATUS.get(code, f"status {code}"), path, int(stats[0]), int(stats[1]), int(stats[2]))


def _mode(validity: ConfigValidity) -> tuple[str, Any]:
    """The checker mode and still-object pose a validity function's checks use (as
    :meth:`~optplan.planners.validity.ValidityChecker.first_invalid` resolves them)."""
    ck, mode, pose = validity.checker, validity.mode, validity.object_pose
    if ck.object is None and mode in ("held", "fixed"):
        return "free", None
    return mode, (pose if mode == "fixed" else None)
