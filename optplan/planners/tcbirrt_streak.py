"""TCBiRRT's trapped streaks in one native call (``extension="loop"``).

On hard scenes most iterations of Alg. 1 are one trapped extension: a sample, its nearest node, a step toward
it whose first waypoint already fails, the node's step halved and its trap counted, and the trees swap. Each
of those crossed from Python into C two or three times. :class:`NativeStreak` runs a run of such iterations
in one call (``tcb_streak``, :mod:`.kernel.streak_csource`): the same draws from the query's native stream,
the same extensions, the same step and trap bookkeeping, and it hands the iteration that is not a plain
trapped one back to the Python loop at the point where it stopped (the sampled node has other IK branches;
the extension was not trapped; a trap graft is due). :func:`quiet_iterations` bounds a streak so that no
event of the loop's head (branch and frontier grafts, the lead path, a stall, the iteration cap) falls inside
it. A search with streaks is the search without them, iteration for iteration (tested).
"""
from __future__ import annotations

import ctypes
import math
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from .kernel.extend import load_extend_library
from .kernel.native import KernelUnavailable
from .kernel.sampler import _clock

if TYPE_CHECKING:
    from .base import Deadline
    from .tcbirrt import TCBiRRT
    from .tcbirrt_tree import _TaskTree

__all__ = ["NativeStreak", "quiet_iterations", "STREAK_DONE", "STREAK_SAMPLED", "STREAK_EXTENDED", "STREAK_TRAP_GRAFT"]

_P = ctypes.c_void_p
_LL = ctypes.c_longlong
_D = ctypes.c_double
#: codes of a streak's end: its iterations done (or the deadline); an iteration stopped after its sample, after
#: an extension that was not trapped, or at a trap graft that is due
STREAK_DONE, STREAK_SAMPLED, STREAK_EXTENDED, STREAK_TRAP_GRAFT = 0, 1, 2, 3


class _STree(ctypes.Structure):
    _fields_ = [("X", _P), ("n", _LL), ("alive", _P), ("pose", _P), ("q", _P), ("dom", _P), ("trapn", _P),
                ("twin", _P), ("count_traps", ctypes.c_int)]


class _SArgs(ctypes.Structure):
    _fields_ = [("step_size", _D), ("step_adapt", ctypes.c_int), ("prefix", ctypes.c_int), ("n_interp", _LL),
                ("trap_count", _LL), ("trap_after", _LL), ("it0", _LL), ("max_n", _LL),
                ("clock_kind", ctypes.c_int), ("end", _D),
                ("n_done", _LL), ("i_near", _LL), ("k", _LL), ("code", ctypes.c_int), ("reach", ctypes.c_int),
                ("xi_rand", _D * 6), ("xi_s", _D * 6), ("Ps", _D * 12)]


def _declare(lib: Any) -> None:
    if getattr(lib, "_streak_declared", False):
        return
    lib.tcb_streak.restype = ctypes.c_int
    lib.tcb_streak.argtypes = [_P, _P, _P, _P, _P, _P, _P, _P]
    lib.tcb_pose_xi.restype = None
    lib.tcb_pose_xi.argtypes = [_P, _P]
    lib._streak_declared = True


class NativePose:
    """``pose(xi)``: the rotation (3 × 3) and position [m] of ξ as the native code computes them (``tcb_pose_xi``:
    Rz(yaw) Ry(pitch) Rx(roll) as Pinocchio's ``rpyToMatrix`` computes it, operation for operation). The loop's
    extensions take their target pose from it, in the streaks and outside them, so that the two give the same
    search even where a compiler's fused multiply-adds would make it differ from Pinocchio's in the last bits."""

    __slots__ = ("_f", "_x", "_out", "_px", "_po")

    def __init__(self) -> None:
        lib = load_extend_library()
        _declare(lib)
        self._f = lib.tcb_pose_xi
        self._x, self._out = np.empty(6), np.empty(12)
        self._px, self._po = self._x.ctypes.data, self._out.ctypes.data

    def __call__(self, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self._x[:] = xi
        self._f(self._px, self._po)
        out = self._out.copy()
        return out[:9].reshape(3, 3), out[9:]


class NativeStreak:
    """Trapped streaks of one planner's query (its native extender, sampler and options)."""

    def __init__(self, pl: TCBiRRT, sampler: Any) -> None:
        ext = pl._ext
        if ext is None or pl._nrng is None or not ext.native_restarts:
            raise KernelUnavailable("trapped streaks need the native loop (extension='loop')")
        lib = load_extend_library()
        _declare(lib)
        self._f = lib.tcb_streak
        self.ext, self.sampler, o = ext, sampler, pl.options
        n = int(o.n_interp)
        self.P, self.Q = np.empty((n, 12)), np.empty((n, ext.nq))
        a = self.args = _SArgs()
        a.step_size, a.step_adapt = float(pl.step_size), int(o.trap_adapt == "step")
        a.prefix, a.n_interp = int(bool(o.keep_prefix)), n
        a.trap_count = int(o.trap_graft_count or 0)
        a.trap_after = int(o.trap_graft_after or 0)
        #: per tree (by identity): its structure, the key array and live mask it points to, its address
        self._trees: dict[int, list[Any]] = {}
        self._ptrs = (ext._cp, ctypes.addressof(a), self.P.ctypes.data, self.Q.ctypes.data, ext._cnt_p)

    def take(self) -> tuple[np.ndarray, np.ndarray]:
        """The poses and configurations of the extension a streak stopped at (``STREAK_EXTENDED``), handed over:
        the next call writes into new arrays."""
        P, Q = self.P, self.Q
        self.P, self.Q = np.empty_like(P), np.empty_like(Q)
        cp, ap, _, _, cnt = self._ptrs
        self._ptrs = (cp, ap, self.P.ctypes.data, self.Q.ctypes.data, cnt)
        return P, Q

    def _tree(self, t: _TaskTree, count_traps: bool) -> int:
        e = self._trees.get(id(t))
        if e is None or e[0] is not t:
            e = self._trees[id(t)] = [t, _STree(), None, None, 0]
            e[4] = ctypes.addressof(e[1])
        s = e[1]
        alive = t.alive if t.n_dead else None
        if e[2] is not t.X or e[3] is not alive:   # new, grown, or nodes killed
            s.X, s.pose, s.q, s.dom = t.X.ctypes.data, t.pose12.ctypes.data, t.q.ctypes.data, t.dom.ctypes.data
            s.trapn, s.twin = t.trapn.ctypes.data, t.twin.ctypes.data
            s.alive = None if alive is None else alive.ctypes.data
            e[2], e[3] = t.X, alive
        s.n, s.count_traps = t.n, int(count_traps)
        return cast(int, e[4])

    def run(self, ta: _TaskTree, tb: _TaskTree, count_a: bool, count_b: bool, it0: int, max_n: int,
            deadline: Deadline) -> _SArgs:
        """Up to ``max_n`` iterations from ``ta`` (then ``tb``, ...); ``it0``: the loop's iterations before the first;
        ``count_*``: whether that tree counts trapped extensions. The arguments' outputs: ``code``, ``n_done``
        (iterations completed), and for the iteration it stopped in ``xi_rand``, ``i_near``, ``xi_s``, ``reach``,
        ``Ps`` and ``k`` (an extension's configurations kept, in :attr:`Q`, its poses in :attr:`P`)."""
        a = self.args
        a.it0, a.max_n = int(it0), int(max_n)
        a.clock_kind, a.end = _clock(deadline)
        pa, pb = self._tree(ta, count_a), self._tree(tb, count_b)
        cp, ap, pp, qp, cnt = self._ptrs
        r = self._f(self.sampler._sp, cp, pa, pb, ap, pp, qp, cnt)
        if r < 0:
            raise KernelUnavailable("the native extension refused the model (too many joints or geometries)")
        return a


def _next(v0: int, offset: int, interval: int) -> int:
    """The least v > v0 with v − offset > 0 and (v − offset) divisible by ``interval``."""
    k = v0 + 1 - offset
    if k <= 0:
        return offset + interval
    return offset + interval * -(-k // interval)


def quiet_iterations(pl: TCBiRRT, v0: int, since_gap: int, max_iterations: int, sampler: Any, lead_on: bool,
                     fronts_left: bool) -> int:
    """How many iterations from the current one (whose head has run: ``v0`` iterations before it, ``since_gap``
    counted with it) may run before an event of the loop's head could fire: at least 1. ``lead_on``: the lead
    path may still be attempted; ``fronts_left``: either tree has frontier grafts left."""
    o = pl.options
    n = math.inf
    if max_iterations:
        n = min(n, max_iterations - v0)
    if o.branch_grafts:
        n = min(n, _next(v0, int(o.graft_after), int(o.graft_interval)) - v0)
    if lead_on and sampler is not None and float(o.guide_probability or 0) > 0 and sampler.guide is None:
        n = min(n, _next(v0, 0, 25) - v0)
    if o.frontier_grafts and fronts_left:
        # the head of iteration v0 + j tests k_front = v0 + j + 1 − graft_after and since_gap + j
        n = min(n, _next(v0 + 1, int(o.graft_after), int(o.frontier_interval)) - (v0 + 1))
        if o.stall_iterations:
            n = min(n, max(1, int(o.stall_iterations) - since_gap + 1))
    return int(max(1, min(n, 1 << 30)))
