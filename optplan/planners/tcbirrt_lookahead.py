"""TCBiRRT's look-ahead graft candidates in one native call (``extension="loop"``).

A look-ahead graft (:func:`~.frontier_graft.lookahead_graft`) tries ``frontier_seeds`` random IK seeds at a node's
object pose and, per IK solution, three candidates (each arm re-grasped alone, then both), each through the twin
test, the joint limits, a collision check and a constrained step toward the target. On the long searches most
attempts find nothing, and that loop was a fifth of their CPU time, most of it Python around native calls.
:class:`NativeLookahead` runs it in C (``tcb_lookahead``, :mod:`.kernel.lookahead_csource`): the seeds drawn from the
state of the search's NumPy Generator as ``Generator.uniform`` draws them (:class:`~.tcbirrt_streak._Pcg`), the same
IK block, checks and path IK. It returns at a candidate that passes, for the regrasp in Python, and goes on from the
next candidate when that regrasp fails. The search is the same as the Python loop's, draw for draw (tested).
"""
from __future__ import annotations

import ctypes
from typing import TYPE_CHECKING, Any

import numpy as np

from .kernel.extend import load_extend_library
from .kernel.native import KernelUnavailable
from .kernel.sampler import _clock
from .tcbirrt_streak import _Pcg

if TYPE_CHECKING:
    from .base import Deadline
    from .kernel.extend import NativeExtender

__all__ = ["NativeLookahead"]

_P = ctypes.c_void_p
_LL = ctypes.c_longlong
_D = ctypes.c_double
#: joints the argument structure holds (the C code's KMAXJ)
_KMAXJ = 256


class _LArgs(ctypes.Structure):
    _fields_ = [("lower", _P), ("range", _P), ("lim_lo", _P), ("lim_hi", _P), ("node", _P), ("q_i", _P),
                ("twins", _P), ("ntw", _LL), ("arm", _P), ("narm", ctypes.c_int), ("step", _D), ("P", _P), ("n", _LL),
                ("nseeds", _LL), ("clock_kind", ctypes.c_int), ("end", _D), ("checked", ctypes.c_int),
                ("stop", ctypes.c_int), ("pcg", _Pcg), ("seed_k", _LL), ("cand", ctypes.c_int), ("x", _D * _KMAXJ),
                ("y", _D * _KMAXJ), ("its", _LL), ("failures", _LL)]


class NativeLookahead:
    """The candidate loop of one planner's look-ahead grafts (its native extender, robot limits and arms)."""

    def __init__(self, ext: NativeExtender, lower: np.ndarray, upper: np.ndarray, arms: list[np.ndarray],
                 max_joint_step: float) -> None:
        if not (ext.native_restarts and ext.edge_on):
            raise KernelUnavailable("the native look-ahead needs the native loop's restarts and edge checks")
        nq = int(ext.nq)
        if nq > _KMAXJ:
            raise KernelUnavailable(f"the native look-ahead holds at most {_KMAXJ} joints, got {nq}")
        lib = load_extend_library()
        lib.tcb_lookahead.restype = ctypes.c_int
        lib.tcb_lookahead.argtypes = [_P, _P, _P, _P]
        self._f, self.ext, self.nq = lib.tcb_lookahead, ext, nq
        lower, upper = np.asarray(lower, float), np.asarray(upper, float)
        # Generator.uniform(lower, upper)'s operands, and the checker's in_limits bounds (ValidityChecker.in_limits)
        self._keep = [np.ascontiguousarray(lower), np.ascontiguousarray(np.subtract(upper, lower)),
                      np.ascontiguousarray(lower - 1e-9), np.ascontiguousarray(upper + 1e-9)]
        arm = np.zeros((len(arms), nq), np.uint8)
        for k, idx in enumerate(arms):
            arm[k, np.asarray(idx)] = 1
        self._keep.append(arm)
        a = self.args = _LArgs()
        a.lower, a.range, a.lim_lo, a.lim_hi = (v.ctypes.data for v in self._keep[:4])
        a.arm, a.narm, a.step = arm.ctypes.data, len(arms), float(max_joint_step)
        self._ap = ctypes.addressof(a)
        self._call: list[Any] = []

    def start(self, node_pose: np.ndarray, q_i: np.ndarray, twins: np.ndarray, P: np.ndarray, nseeds: int,
              deadline: Deadline) -> None:
        """A new attempt at a node: its object pose (12 values: rotation row-major, position [m]), configuration
        ``q_i`` [rad], the configurations of its pose ``twins`` (rows), the look-ahead poses ``P`` (n × 12) and the
        number of seeds; the caller has just found the deadline not expired."""
        node, q = np.ascontiguousarray(node_pose, float), np.ascontiguousarray(q_i, float)
        tw, P = np.ascontiguousarray(twins, float), np.ascontiguousarray(P, float)
        self._call = [node, q, tw, P, np.empty((P.shape[0], self.nq))]
        a = self.args
        a.node, a.q_i, a.twins, a.ntw = node.ctypes.data, q.ctypes.data, tw.ctypes.data, tw.shape[0]
        a.P, a.n, a.nseeds = P.ctypes.data, P.shape[0], int(nseeds)
        a.clock_kind, a.end = _clock(deadline)
        a.checked, a.stop, a.seed_k, a.cand, a.its, a.failures = 1, 0, 0, a.narm + 1, 0, 0

    def next(self, rng: np.random.Generator, deadline: Deadline) -> tuple[np.ndarray, np.ndarray] | None:
        """The next candidate that passes ``(y, Q)`` (its configuration and the look-ahead's configurations), or None
        when no seed is left or the deadline has come. The seeds are drawn from ``rng``'s state (advanced here)."""
        a = self.args
        if not a.pcg.load(rng):
            raise KernelUnavailable("the native look-ahead draws as NumPy's PCG64 does; the generator is another")
        a.stop = int(deadline.work <= 0)
        Q = self._call[4]
        r = self._f(self.ext._cp, self._ap, Q.ctypes.data, self.ext._cnt_p)
        if a.pcg.used:
            a.pcg.store(rng)
        a.checked = 0
        if r < 0:
            raise KernelUnavailable("the native look-ahead refused the model (too many joints or geometries, or no "
                                    "128-bit integers for the PCG64 mirror)")
        if r != 1:
            return None
        self._call[4] = np.empty_like(Q)
        return np.array(a.y[:self.nq]), Q
