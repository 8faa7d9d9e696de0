"""TCBiRRT's streaks of iterations in one native call (``extension="loop"``).

On hard scenes most iterations of Alg. 1 are one trapped extension: a sample, its nearest node, a step toward it
whose first waypoint already fails, the node's step halved and its trap counted, and the trees swap. Each of those
crossed from Python into C two or three times. :class:`NativeStreak` runs a run of iterations in one call
(``tcb_streak``, :mod:`.kernel.streak_csource`): the same draws from the query's native stream, the same extensions,
the same step and trap bookkeeping. An extension that is not trapped goes on in C as well: its node is added to the
tree's arrays (and, when the call returns, to the tree's lists of poses and edges), and tree b connects toward it
step by step, each advanced or partial step's node added; a trapped step (or one that got no nearer) ends the
iteration there. :meth:`NativeStreak.connect` runs the same connection alone for the loop's other connections. A sampled node's other IK branches are drawn in
C from the state of the search's NumPy Generator (:class:`_Pcg`, NumPy's PCG64 and ``integers`` step for step), and
the connection's twin is chosen by :class:`NativeTwin`. A call hands the iteration back to the Python loop where it
must go on there: a connection step that reached its target (its regrasp test, in Python), a trap graft that is due, a node at the sample or a twin preferred by the tree, a full tree array or node log.
:func:`quiet_iterations` bounds a streak so that no event of the loop's head (branch and frontier grafts, the lead
path, a stall, the iteration cap) falls inside it. A search with streaks is the search without them, iteration for
iteration (tested).
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

__all__ = ["NativeStreak", "NativeTwin", "NativeXi", "quiet_iterations", "STREAK_DONE", "STREAK_SAMPLED", "STREAK_EXTENDED", "STREAK_TRAP_GRAFT",
           "STREAK_CONNECT", "STREAK_CONNECTED"]

_P = ctypes.c_void_p
_LL = ctypes.c_longlong
_D = ctypes.c_double
#: codes of a streak's end: its iterations done (or the deadline); an iteration stopped after its sample, after
#: an extension that was not trapped, or at a trap graft that is due; an advanced extension's node added, its
#: connection to run in Python (tree b's nearest node has other IK branches or is at the node); the node added
#: and tree b's first connection step not trapped (its result to apply)
STREAK_DONE, STREAK_SAMPLED, STREAK_EXTENDED, STREAK_TRAP_GRAFT, STREAK_CONNECT, STREAK_CONNECTED = 0, 1, 2, 3, 4, 5
#: nodes a streak may add before it returns (rows of its log)
LOG_ROWS = 64


class _Pcg(ctypes.Structure):
    _fields_ = [("hi", ctypes.c_ulonglong), ("lo", ctypes.c_ulonglong), ("inc_hi", ctypes.c_ulonglong),
                ("inc_lo", ctypes.c_ulonglong), ("has_uint32", ctypes.c_int), ("uinteger", ctypes.c_uint),
                ("used", ctypes.c_int)]

    def load(self, rng: np.random.Generator) -> bool:
        """The state of ``rng`` (PCG64), or False for another bit generator."""
        st = rng.bit_generator.state
        if st.get("bit_generator") != "PCG64":
            return False
        v, inc = int(st["state"]["state"]), int(st["state"]["inc"])
        self.hi, self.lo, self.inc_hi, self.inc_lo = v >> 64, v & _M64, inc >> 64, inc & _M64
        self.has_uint32, self.uinteger, self.used = int(st["has_uint32"]), int(st["uinteger"]), 0
        return True

    def store(self, rng: np.random.Generator) -> None:
        """This state into ``rng``."""
        rng.bit_generator.state = {"bit_generator": "PCG64",
                                   "state": {"state": (int(self.hi) << 64) | int(self.lo),
                                             "inc": (int(self.inc_hi) << 64) | int(self.inc_lo)},
                                   "has_uint32": int(self.has_uint32), "uinteger": int(self.uinteger)}


_M64 = (1 << 64) - 1


class _STree(ctypes.Structure):
    _fields_ = [("X", _P), ("n", _LL), ("alive", _P), ("pose", _P), ("q", _P), ("dom", _P), ("trapn", _P),
                ("twin", _P), ("count_traps", ctypes.c_int), ("parent", _P), ("thead", _P), ("tnext", _P),
                ("checked", _P), ("cap", _LL), ("twin_draw", ctypes.c_int), ("K", _P), ("kdn", _P)]


class _SArgs(ctypes.Structure):
    _fields_ = [("step_size", _D), ("step_adapt", ctypes.c_int), ("prefix", ctypes.c_int), ("n_interp", _LL),
                ("trap_count", _LL), ("trap_after", _LL), ("it0", _LL), ("max_n", _LL),
                ("clock_kind", ctypes.c_int), ("end", _D), ("advance", ctypes.c_int), ("log_cap", _LL),
                ("pcg_on", ctypes.c_int), ("pcg", _Pcg),
                ("n_done", _LL), ("i_near", _LL), ("k", _LL), ("code", ctypes.c_int), ("reach", ctypes.c_int),
                ("xi_rand", _D * 6), ("xi_s", _D * 6), ("Ps", _D * 12),
                ("n_ext", _LL), ("n_trap", _LL), ("n_log", _LL), ("n_partial", _LL), ("i_a", _LL), ("i_nb", _LL),
                ("k_b", _LL),
                ("reach_b", ctypes.c_int), ("xi_sb", _D * 6), ("conn_trapped", ctypes.c_int),
                ("domain_adapt", ctypes.c_int), ("domain_tries", ctypes.c_int), ("domain_radius", _D), ("n_rej", _LL)]


def _declare(lib: Any) -> None:
    if getattr(lib, "_streak_declared", False):
        return
    lib.tcb_streak.restype = ctypes.c_int
    lib.tcb_streak.argtypes = [_P, _P, _P, _P, _P, _P, _P, _P, _P, _P, _P]
    lib.tcb_pose_xi.restype = None
    lib.tcb_pose_xi.argtypes = [_P, _P]
    lib.tcb_xi_of_pose.restype = None
    lib.tcb_xi_of_pose.argtypes = [_P, _P]
    lib.tcb_twin_nearest.restype = _LL
    lib.tcb_connect.restype = ctypes.c_int
    lib.tcb_connect.argtypes = [_P, _P, _P, _P, _P, _P, _P, _P, _P, _P, _P]
    lib.tcb_pcg_integers.restype = ctypes.c_int
    lib.tcb_pcg_integers.argtypes = [_P, _LL, _LL, _P]
    lib.tcb_twin_nearest.argtypes = [_P, ctypes.c_int, _P, _P, _P, _LL, _P]
    lib._streak_declared = True


class _NativeMap:
    """A native function of one fixed-size input to one fixed-size output (``f(in, out)``), with its buffers."""

    __slots__ = ("_f", "_in", "_out", "_pi", "_po")

    def __init__(self, name: str, n_in: int, n_out: int) -> None:
        lib = load_extend_library()
        _declare(lib)
        self._f = getattr(lib, name)
        self._in, self._out = np.empty(n_in), np.empty(n_out)
        self._pi, self._po = self._in.ctypes.data, self._out.ctypes.data


class NativePose(_NativeMap):
    """``pose(xi)``: the rotation (3 × 3) and position [m] of ξ as the native code computes them (``tcb_pose_xi``:
    Rz(yaw) Ry(pitch) Rx(roll) as Pinocchio's ``rpyToMatrix`` computes it, operation for operation). The loop's
    extensions take their target pose from it, in the streaks and outside them, so that the two give the same
    search even where a compiler's fused multiply-adds would make it differ from Pinocchio's in the last bits."""

    __slots__ = ()

    def __init__(self) -> None:
        super().__init__("tcb_pose_xi", 6, 12)

    def __call__(self, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self._in[:] = xi
        self._f(self._pi, self._po)
        out = self._out.copy()
        return out[:9].reshape(3, 3), out[9:]


class NativeXi(_NativeMap):
    """``xi(R, p)``: ξ = (position, roll, pitch, yaw) of a pose as the native code computes it (``tcb_xi_of_pose``:
    Pinocchio's ``rpy.matrixToRpy``, operation for operation). The loop keys a partial extension's node with it, in
    the streaks and outside them."""

    __slots__ = ()

    def __init__(self) -> None:
        super().__init__("tcb_xi_of_pose", 12, 6)

    def __call__(self, R: np.ndarray, p: np.ndarray) -> np.ndarray:
        self._in[:9] = np.asarray(R).reshape(9)
        self._in[9:] = p
        self._f(self._pi, self._po)
        return self._out.copy()


class NativeTwin:
    """``twin(tree, i, q, rng)``: :meth:`~.tcbirrt_tree._TaskTree.twin_nearest` with a configuration ``q`` as the native
    code computes it (``tcb_twin_nearest``: the same squared distances summed joint by joint, the first of the group
    among equals). The loop's connections take their node from it, in the streaks and outside them."""

    __slots__ = ("_f",)

    def __init__(self) -> None:
        lib = load_extend_library()
        _declare(lib)
        self._f = lib.tcb_twin_nearest

    def __call__(self, t: _TaskTree, i: int, q: np.ndarray, rng: np.random.Generator) -> int:
        if not t.twin[i]:
            return i
        q = np.ascontiguousarray(q, float)
        alive = t.alive if t.n_dead else None
        return int(self._f(t.q.ctypes.data, t.q.shape[1], t.thead.ctypes.data, t.tnext.ctypes.data,
                           None if alive is None else alive.ctypes.data, int(i), q.ctypes.data))


class NativeStreak:
    """Trapped streaks of one planner's query (its native extender, sampler and options)."""

    def __init__(self, pl: TCBiRRT, sampler: Any) -> None:
        ext = pl._ext
        if ext is None or pl._nrng is None or not ext.native_restarts:
            raise KernelUnavailable("trapped streaks need the native loop (extension='loop')")
        lib = load_extend_library()
        _declare(lib)
        self._f, self._fc = lib.tcb_streak, lib.tcb_connect
        self.ext, self.sampler, o = ext, sampler, pl.options
        n = int(o.n_interp)
        self.P, self.Q = np.empty((n, 12)), np.empty((n, ext.nq))
        #: the streaks' arguments, and the connections' (:meth:`connect`)
        self.args, self.cargs = _SArgs(), _SArgs()
        for a in (self.args, self.cargs):
            a.step_size, a.step_adapt = float(pl.step_size), int(o.trap_adapt == "step")
            a.domain_adapt, a.domain_tries = int(o.trap_adapt == "domain"), int(o.domain_tries)
            a.domain_radius = float(cast(float, o.domain_radius))
            a.prefix, a.n_interp = int(bool(o.keep_prefix)), n
            a.trap_count = int(o.trap_graft_count or 0)
            a.trap_after = int(o.trap_graft_after or 0)
            # advanced extensions and their connections in C too, unless the loop watches the connections' gaps (a
            # stall bound) or joins trapped connections in joint space
            a.advance = int(not o.stall_iterations and not o.joint_connect)
            a.log_cap = LOG_ROWS
        a = self.args
        #: the log of the nodes a call added: (tree, node, configurations kept), their poses and configurations
        self.LM = np.zeros((LOG_ROWS, 3), np.int64)
        self.LP, self.LQ = np.empty((LOG_ROWS, n, 12)), np.empty((LOG_ROWS, n, ext.nq))
        self._logs = (self.LP.ctypes.data, self.LQ.ctypes.data, self.LM.ctypes.data)
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
            s.parent, s.checked, s.cap = t.parent.ctypes.data, t.checked.ctypes.data, len(t.X)
            s.thead, s.tnext = t.thead.ctypes.data, t.tnext.ctypes.data
            s.alive = None if alive is None else alive.ctypes.data
            s.K, s.kdn = (None, None) if t.kd is None else (t.kd[0].ctypes.data, t.kd[1].ctypes.data)
            e[2], e[3] = t.X, alive
        s.n, s.count_traps, s.twin_draw = t.n, int(count_traps), int(not t.prefer)
        return cast(int, e[4])

    def run(self, ta: _TaskTree, tb: _TaskTree, count_a: bool, count_b: bool, it0: int, max_n: int,
            deadline: Deadline, rng: np.random.Generator | None = None) -> _SArgs:
        """Up to ``max_n`` iterations from ``ta`` (then ``tb``, ...); ``it0``: the loop's iterations before the first;
        ``count_*``: whether that tree counts trapped extensions. The arguments' outputs: ``code``, ``n_done``
        (iterations completed), and for the iteration it stopped in ``xi_rand``, ``i_near``, ``xi_s``, ``reach``,
        ``Ps`` and ``k`` (an extension's configurations kept, in :attr:`Q`, its poses in :attr:`P`); for codes 4 and 5
        ``i_a`` (the node added), ``i_nb``, ``xi_sb``, ``reach_b`` and ``k_b`` (tree b's connection step). ``rng``: the
        search's Generator, from which the sampled nodes' twins are drawn (None: twins end the call)."""
        a = self.args
        a.it0, a.max_n = int(it0), int(max_n)
        a.clock_kind, a.end = _clock(deadline)
        pa, pb = self._tree(ta, count_a), self._tree(tb, count_b)
        cp, ap, pp, qp, cnt = self._ptrs
        a.pcg_on = int(rng is not None and bool(ta.twins or tb.twins) and a.pcg.load(rng))
        r = self._f(self.sampler._sp, cp, pa, pb, ap, pp, qp, cnt, *self._logs)
        if a.pcg_on and a.pcg.used:
            a.pcg.store(cast(np.random.Generator, rng))
        if a.n_log:
            self._added(a, (ta, tb))
        if r < 0:
            raise KernelUnavailable("the native extension refused the model (too many joints or geometries)")
        return a

    def connect(self, tb: _TaskTree, target_xi: np.ndarray, target_q: np.ndarray, deadline: Deadline) -> _SArgs:
        """Tree b's connection (Alg. 1 lines 7-11) toward the node with key ``target_xi`` and configuration ``target_q``
        in one native call (``tcb_connect``), its advanced and partial steps' nodes added to ``tb``. The arguments'
        outputs: ``code`` 0 (ended: by a trapped step when ``conn_trapped``, else by the deadline), 4 (tree b's nearest
        node is at the target: the next step runs in Python) or 5 (a step to apply in Python: ``i_nb``, ``xi_sb``,
        ``reach_b``, ``k_b``, its poses and configurations in :attr:`P`, :attr:`Q`); ``n_ext``, ``n_trap``,
        ``n_partial`` its counts."""
        a = self.cargs
        a.clock_kind, a.end = _clock(deadline)
        pb = self._tree(tb, False)
        x, q = np.ascontiguousarray(target_xi, float), np.ascontiguousarray(target_q, float)
        cp, ap, pp, qp, cnt = self._ptrs
        r = self._fc(cp, pb, x.ctypes.data, q.ctypes.data, ctypes.addressof(a), pp, qp, cnt, *self._logs)
        if a.n_log:
            self._added(a, (tb, tb))
        if r < 0:
            raise KernelUnavailable("the native extension refused the model (too many joints or geometries)")
        return a

    def _added(self, a: _SArgs, trees: tuple[_TaskTree, _TaskTree]) -> None:
        """The nodes the call added to the trees' arrays, into their Python lists as
        :meth:`~.tcbirrt_tree._TaskTree.add` keeps them: each node's edge, the configurations and poses before it
        (its own pose is its ``pose12`` row, written in C). ``trees``: the trees the log's tags 0 and 1 name."""
        for e, (w, m, k) in enumerate(self.LM[:a.n_log].tolist()):
            t = trees[w]
            if m != len(t.edge):   # pragma: no cover - the log's rows are in the order the nodes were added
                raise RuntimeError(f"streak log out of order: node {m} of a tree with {len(t.edge)} edges")
            P, Q = self.LP[e, :k].copy(), self.LQ[e, :k].copy()   # the waypoints kept (all, or a prefix)
            t.edge.append((list(Q[:-1]), [(P[j, :9].reshape(3, 3), P[j, 9:]) for j in range(k - 1)]))
        for t in trees:
            t.n = int(self._trees[id(t)][1].n)


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
