"""RRT-Connect as one native call: the search of :func:`optplan.planners.rrtconnect.rrt_connect` and
the shortcuts of :func:`~optplan.planners.rrtconnect.shortcut_path` in C (:mod:`.rrtc_csource`), on the
planning kernel's forward kinematics and exact primitive tests.

:func:`native_rrt_connect` runs one query for a validity function of a
:class:`~optplan.planners.validity.ValidityChecker` whose backend is the native kernel; it returns
None when that is not the case (the caller then runs the Python search). The random stream is the
kernel's own (xoshiro256**), seeded once per query by a 64-bit integer drawn from the caller's NumPy
Generator: the same Generator state gives the same search, but not the Python search's. A plan's seed alone
(:meth:`RRTConnect.plan <optplan.planners.rrtconnect.RRTConnect>`) gives the same search as its Generator
``np.random.default_rng(seed)``: the draw is computed natively, without making the Generator (~30-80 µs a query).
"""
from __future__ import annotations

import ctypes
import hashlib
import logging
import tempfile
import time
import weakref
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...codegen import build_library, build_tag, cache_dir
from .csource import C_SOURCE
from .native import KernelUnavailable, NativeKernel
from .rrtc_csource import RRTC_SOURCE, RRTC_STATUS

if TYPE_CHECKING:
    from ..base import Deadline
    from ..validity import ConfigValidity

__all__ = ["NativeRRTCResult", "load_rrtc_library", "native_rrt_connect", "broad_phase_valid", "search_check_valid",
           "prepare_native_search"]
log = logging.getLogger(__name__)

_LIB: list[Any] = []
_FAILED: list[str] = []
_P = ctypes.c_void_p
#: nodes of both trees at which a native query stops (status ``"node cap"``) [count]
MAX_NODES = 2_000_000


class _Groups(ctypes.Structure):
    _fields_ = [("ngroups", ctypes.c_int), ("nblocks", ctypes.c_int), ("gkind", _P), ("gref", _P), ("gcenter", _P),
                ("gradius", _P), ("bstart", _P), ("bga", _P), ("bgb", _P), ("perm", _P), ("gbox", _P),
                ("ggroup", _P), ("rownext", _P), ("bmask", _P), ("gmstart", _P), ("gmlist", _P), ("gmidx", _P),
                ("runmask", _P)]


class BroadPhase:
    """The broad phase of the native search's checks for one :class:`~.native.NativeKernel`: the
    geometries of each joint form a group bounded by one sphere (centre in the joint frame, radius [m]);
    a geometry on no joint, and ``override`` (the still object, placed per query), is a group on its own
    (its bounding sphere); the kernel's pairs are sorted into blocks by their two groups, and a block is
    skipped when the two groups' spheres are apart. The verdicts are the kernel's."""

    def __init__(self, kern: NativeKernel, override: int | None) -> None:
        jparent, jtype, jidx, jplace, jaxis, gparent, gtype, gplace, gparam, grad, pa, pb = kern._arrays
        ng = kern.ng
        group = np.empty(ng, np.int64)
        kinds: list[int] = []
        refs: list[int] = []
        centers: list[np.ndarray] = []
        radii: list[float] = []
        joint_group: dict[int, int] = {}
        members: dict[int, list[int]] = {}
        for g in range(ng):
            j = int(gparent[g])
            if j == 0 or g == override:
                group[g] = len(kinds)
                kinds.append(0)
                refs.append(g)
                centers.append(np.zeros(3))
                radii.append(float(grad[g]))
            else:
                if j not in joint_group:
                    joint_group[j] = len(kinds)
                    kinds.append(1)
                    refs.append(j)
                    centers.append(np.zeros(3))
                    radii.append(0.0)
                group[g] = joint_group[j]
                members.setdefault(j, []).append(g)
        for j, gs in members.items():   # the sphere around the members' bounding spheres
            t = gplace[gs, 9:12]
            c = t.mean(axis=0)
            i = joint_group[j]
            centers[i] = c
            radii[i] = float(np.max(np.linalg.norm(t - c, axis=1) + grad[gs])) * (1 + 1e-12) + 1e-12
        a = group[np.asarray(pa, np.int64)] if len(pa) else np.zeros(0, np.int64)
        b = group[np.asarray(pb, np.int64)] if len(pb) else np.zeros(0, np.int64)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        perm = np.lexsort((hi, lo)).astype(np.int32)
        keys = lo[perm] * (len(kinds) + 1) + hi[perm]
        starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]]) if len(perm) else np.zeros(0, np.int64)
        ends = np.r_[starts[1:], len(perm)].astype(np.int64)
        # the blocks with a geometry on no joint (the obstacles) first: in clutter they hold most contacts
        kind = np.array(kinds, np.int32)
        bl, bh = lo[perm][starts], hi[perm][starts]
        order = np.argsort((kind[bl] != 0) & (kind[bh] != 0), kind="stable")
        perm = np.concatenate([perm[a:b] for a, b in zip(starts[order], ends[order])]).astype(np.int32) \
            if len(perm) else perm
        sizes = (ends - starts)[order]
        bstart = np.r_[0, np.cumsum(sizes)].astype(np.int32)
        # after each position of perm, the next whose first geometry differs or whose block begins (a run's end)
        pav = np.asarray(pa, np.int64)[perm] if len(perm) else np.zeros(0, np.int64)
        brk = np.flatnonzero(np.r_[True, pav[1:] != pav[:-1]]) if len(perm) else np.zeros(0, np.int64)
        brk = np.union1d(np.union1d(brk, bstart[:-1]), [len(perm)])
        rownext = brk[np.searchsorted(brk, np.arange(len(perm)), side="right")].astype(np.int32) \
            if len(perm) else np.zeros(0, np.int32)
        gbox = np.zeros(len(kinds), np.uint8)   # a group with a box member (the exact sphere test skips box pairs)
        for g in range(ng):
            if int(gtype[g]) == 2:
                gbox[group[g]] = 1
        # the members of each joint group (ascending) and each geometry's index among them; the blocks of two joint
        # groups of at most 64 members: their runs' pairs in the member order of the second geometry, and each run's
        # mask of those members (at its first position)
        gmlist: list[list[int]] = [[] for _ in kinds]
        for g in range(ng):
            if kinds[group[g]] == 1:
                gmlist[group[g]].append(g)
        gmidx = np.full(ng, -1, np.int32)
        for gs in gmlist:
            gmidx[gs] = np.arange(len(gs), dtype=np.int32)
        gmstart = np.r_[0, np.cumsum([len(gs) for gs in gmlist])].astype(np.int32)
        bga, bgb = bl[order].astype(np.int32), bh[order].astype(np.int32)
        bmask = np.zeros(len(starts), np.uint8)
        runmask = np.zeros(len(perm), np.uint64)
        pbv = np.asarray(pb, np.int64)
        for blk in range(len(starts)):
            a_, b_ = int(bga[blk]), int(bgb[blk])
            if a_ == b_ or kinds[a_] != 1 or kinds[b_] != 1 or len(gmlist[a_]) > 64 or len(gmlist[b_]) > 64:
                continue
            bmask[blk] = 1
            i = int(bstart[blk])
            while i < int(bstart[blk + 1]):
                j = int(rownext[i])
                seg = perm[i:j]
                seg = seg[np.argsort(gmidx[pbv[seg]], kind="stable")]
                perm[i:j] = seg
                runmask[i] = np.bitwise_or.reduce(np.left_shift(np.uint64(1), gmidx[pbv[seg]].astype(np.uint64)))
                i = j
        self.arrays = (kind, np.array(refs, np.int32), np.ascontiguousarray(centers, float), np.array(radii, float),
                       bstart, bga, bgb, perm, gbox, group.astype(np.int32), rownext, bmask, gmstart,
                       np.array([g for gs in gmlist for g in gs] or [0], np.int32), gmidx, runmask)
        self.n_groups, self.n_blocks = len(kinds), len(starts)
        self.struct = _Groups(self.n_groups, self.n_blocks, *(x.ctypes.data for x in self.arrays))
        self.pointer = ctypes.addressof(self.struct)


_BROAD: weakref.WeakKeyDictionary[NativeKernel, dict[int | None, BroadPhase]] = weakref.WeakKeyDictionary()


def _broad_phase(kern: NativeKernel, override: int | None) -> BroadPhase:
    per = _BROAD.setdefault(kern, {})
    got = per.get(override)
    if got is None:
        got = per[override] = BroadPhase(kern, override)
    return got


def prepare_native_search(checker: Any) -> bool:
    """Build, ahead of the first query, what the native search of ``checker`` (a
    :class:`~optplan.planners.validity.ValidityChecker`) builds at its first use: the compiled library and
    the broad phase of its kernel (a per-scene set-up, like the checker itself). False when the checker has
    no native backend or the library cannot be built."""
    nat = getattr(checker, "_native", None)
    if nat is None:
        return False
    try:
        load_rrtc_library()
    except KernelUnavailable:
        return False
    _broad_phase(nat.kernel, nat.fixed_id)
    return True


def broad_phase_valid(validity: Any, Q: np.ndarray) -> np.ndarray:
    """The native search's own check (broad phase, then the kernel's pair tests) of every row of ``Q``
    (full configurations) in the mode of ``validity`` (a :class:`~optplan.planners.validity.ConfigValidity`
    on the native kernel): booleans, for tests against the kernel's and coal's verdicts."""
    lib, kern, mask, g, bp = _check_args(validity)
    Q = np.ascontiguousarray(Q, dtype=float)
    out = np.zeros(len(Q), np.uint8)
    lib.rrtc_check_batch(kern._km_p, mask, kern._pose_p, g, bp.pointer, len(Q), Q.ctypes.data, out.ctypes.data)
    return out.astype(bool)


def _check_args(validity: Any) -> tuple[Any, Any, int, int, BroadPhase]:
    """The library, kernel, active-pair mask address, still-object slot and broad phase of ``validity``'s checks."""
    lib = load_rrtc_library()
    nat = validity.checker._native
    mode, pose = _mode(validity)
    kern = nat.kernel
    return lib, kern, nat.masks[mode].ctypes.data, kern._override(nat._override(mode, pose)), \
        _broad_phase(kern, nat.fixed_id)


def search_check_valid(validity: Any, joints: Any, base: np.ndarray, X: np.ndarray) -> np.ndarray:
    """The native search's check as a query sets it up — the joints ``joints`` (indices into the configuration)
    searched with the others at ``base``: the still part placed once, the blocks laid out, the moving geometries
    placed when first needed — on every row of ``X`` (values of ``joints``) in the mode of ``validity``:
    booleans, for tests against the kernel's and coal's verdicts."""
    lib, kern, mask, g, bp = _check_args(validity)
    jidx = np.ascontiguousarray(joints, dtype=np.int32)
    base = np.ascontiguousarray(base, dtype=float)
    X = np.ascontiguousarray(X, dtype=float).reshape(-1, len(jidx))
    out = np.zeros(len(X), np.uint8)
    rc = lib.rrtc_check_batch_search(kern._km_p, mask, kern._pose_p, g, bp.pointer, len(jidx),
                                     jidx.ctypes.data, base.ctypes.data, len(X), X.ctypes.data, out.ctypes.data)
    if rc != 0:
        raise MemoryError("rrtc_check_batch_search: out of memory or too large a model")
    return out.astype(bool)


def load_rrtc_library() -> Any:
    """The compiled kernel with the RRT-Connect entry points (``ctypes.CDLL``), built at first use and
    cached under :func:`optplan.codegen.cache_dir` by a hash of its source. Raises
    :class:`~.native.KernelUnavailable` when it cannot be built."""
    if _LIB:
        return _LIB[0]
    if _FAILED:
        raise KernelUnavailable(_FAILED[0])
    source = C_SOURCE + RRTC_SOURCE
    digest = hashlib.sha1(source.encode()).hexdigest()[:16] + "_" + build_tag()
    lib_path = cache_dir() / f"optplan_rrtc_kernel_{digest}.so"
    lib = None
    for attempt in range(2):
        if not lib_path.exists():
            with tempfile.TemporaryDirectory() as tmp:
                c_file = Path(tmp, "rrtc_kernel.c")
                c_file.write_text(source)
                err = build_library(c_file, lib_path, "-O3", native=True)
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
    lib.rrtc_plan.argtypes = [_P, _P, _P, ctypes.c_int, _P, ctypes.c_int, _P, _P, _P, _P, _P, _P, ctypes.c_double,
                              ctypes.c_double, ctypes.c_longlong, ctypes.c_longlong, ctypes.c_longlong, ctypes.c_int, ctypes.c_int,
                              ctypes.c_double, ctypes.c_ulonglong, ctypes.c_int, _P, ctypes.POINTER(ctypes.POINTER(ctypes.c_double)),
                              ctypes.POINTER(ctypes.c_int), _P]
    lib.rrtc_check_batch.restype = None
    lib.rrtc_check_batch.argtypes = [_P, _P, _P, ctypes.c_int, _P, ctypes.c_longlong, _P, _P]
    lib.rrtc_check_batch_search.restype = ctypes.c_int
    lib.rrtc_check_batch_search.argtypes = [_P, _P, _P, ctypes.c_int, _P, ctypes.c_int, _P, _P, ctypes.c_longlong,
                                            _P, _P]
    lib.rrtc_numpy_seed.restype = ctypes.c_ulonglong
    lib.rrtc_numpy_seed.argtypes = [ctypes.c_ulonglong]
    lib.rrtc_free.restype = None
    lib.rrtc_free.argtypes = [_P]
    _LIB.append(lib)
    return lib


class NativeRRTCResult:
    """One native query: ``status`` (``"found"``, ``"iteration cap"``, ``"time limit"``, ``"node cap"``,
    ``"out of memory"``, ``"stalled"``, ``"invalid start"``, ``"invalid goal"``), ``path`` (M × dim array of
    configurations of the searched joints, start to goal, after the shortcuts; None unless found), ``iterations``,
    ``nodes`` (both trees), ``checks`` (configurations checked), ``tree_nodes`` (the start's and the goal's tree),
    ``longest_stall`` (the longest run of iterations in which one of the trees added no node), ``rejected`` (samples
    the dynamic domain drew again, counted in ``iterations``) and ``end_checks`` (of ``checks``, those of the
    start and the goal) [counts]."""

    __slots__ = ("status", "path", "iterations", "nodes", "checks", "tree_nodes", "longest_stall", "rejected",
                 "end_checks")

    def __init__(self, status: str, path: np.ndarray | None, iterations: int, nodes: int, checks: int,
                 tree_nodes: tuple[int, int] = (0, 0), longest_stall: int = 0, rejected: int = 0,
                 end_checks: int = 0) -> None:
        self.status, self.path, self.iterations, self.nodes, self.checks = status, path, iterations, nodes, checks
        self.tree_nodes, self.longest_stall, self.rejected = tree_nodes, longest_stall, rejected
        self.end_checks = end_checks


def _clock(deadline: Deadline) -> tuple[int, float]:
    """(0 CLOCK_MONOTONIC / 1 CLOCK_PROCESS_CPUTIME_ID, the deadline's end on that clock [s])."""
    if deadline.clock is time.perf_counter:
        return 0, float(deadline.end)
    if deadline.clock is time.process_time:
        return 1, float(deadline.end)
    return 0, time.perf_counter() + float(deadline.remaining())


def native_rrt_connect(start: np.ndarray, goal: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                       validity: Any, rng: np.random.Generator | None, deadline: Deadline, *, range_: float,
                       resolution: float, max_iterations: int = 0, stall_iterations: int = 0,
                       shortcut_iterations: int = 0, sampler: str = "uniform",
                       tune: tuple[float, float, float, float, float] | None = None, seed: int | None = None,
                       check_ends: bool = False) -> NativeRRTCResult | None:
    """RRT-Connect from ``start`` to ``goal`` in the box ``[lower, upper]`` and ``shortcut_iterations``
    random shortcuts, in one native call; ``range_`` [rad] is the largest extension, ``resolution`` [rad]
    the largest joint change between two checks of an edge, ``max_iterations`` the cap on samples (0:
    the deadline only), ``stall_iterations`` the iterations after which a tree that added no node in them
    ends the search (status ``"stalled"``; 0: never), ``sampler`` ``"uniform"`` or ``"halton"`` (:class:`.RRTConnectOptions`),
    ``tune`` the dynamic domain's radius [rad], factor [-] and least radius [rad], the balance ratio [-] and the
    connection (0.0 ``"other"``, 1.0 ``"new"``) (None: all off). ``validity`` must be a :class:`~optplan.planners.validity.ConfigValidity` of a
    checker with the native backend, else None is returned (as when the library cannot be built).
    One 64-bit seed is drawn from ``rng``; with ``rng`` None, from ``seed`` [0, 2**63) as
    ``np.random.default_rng(seed)`` would draw it (computed natively: the same search as with that Generator, without
    making one). With ``check_ends`` the start and the goal are checked first (within ``[lower, upper]`` widened by
    1e-9, and valid): status ``"invalid start"`` or ``"invalid goal"`` when one is not; ``checks`` counts those
    checks too (``end_checks`` of them). The checker's ``n_checks`` grows by the configurations checked."""
    try:   # a ConfigValidity (duck-typed: this layer does not import validity)
        ck: Any = validity.checker
        vbase, vjoints = validity.base, validity.joints
        mode, pose = _mode(validity)
    except AttributeError:
        return None
    nat = getattr(ck, "_native", None)
    if nat is None:
        return None
    lib = _LIB[0] if _LIB else None
    if lib is None:
        try:
            lib = load_rrtc_library()
        except KernelUnavailable as e:
            log.debug("native RRT-Connect unavailable (%s): the Python search runs", e)
            return None
    kern = nat.kernel
    nq = kern.nq
    if vbase is None:
        jidx_p, base_p, dim = _whole(nq)
    else:
        base = np.ascontiguousarray(vbase, dtype=float)
        jidx = np.ascontiguousarray(vjoints, dtype=np.int32)
        jidx_p, base_p, dim = jidx.ctypes.data, base.ctypes.data, int(jidx.size)
    shapes = (np.shape(start), np.shape(goal), np.shape(lower), np.shape(upper))
    if shapes != ((dim,),) * 4:
        raise ValueError(f"native_rrt_connect: start, goal, lower and upper must have {dim} values, got shapes "
                         f"{list(shapes)}")
    # start, goal, lower, upper and the 7 values of tune: one buffer (NumPy arrays: a ctypes array type made per
    # call is collected with the garbage and made again, ~50 µs on a cold cache)
    buf = np.empty(4 * dim + 7)
    buf[:dim], buf[dim:2 * dim], buf[2 * dim:3 * dim], buf[3 * dim:4 * dim] = start, goal, lower, upper
    g = kern._override(nat._override(mode, pose))
    clock_kind, end = _clock(deadline)
    if rng is not None:
        seed = int(rng.integers(0, 2**63))
        numpy_seed = 0.0
    elif seed is None or not 0 <= seed < 2**63:
        raise ValueError(f"native_rrt_connect: without rng, seed must be an integer in [0, 2**63), got {seed!r}")
    else:
        numpy_seed = 1.0
    out = ctypes.POINTER(ctypes.c_double)()
    n_out = ctypes.c_int(0)
    stats = np.zeros(8, np.int64)
    bp = _broad_phase(kern, nat.fixed_id)
    if tune is not None:
        buf[4 * dim:4 * dim + 5] = tune
    else:
        buf[4 * dim:4 * dim + 5] = 0.0
    buf[4 * dim + 5], buf[4 * dim + 6] = (1.0 if check_ends else 0.0), numpy_seed
    e0 = buf.ctypes.data
    code = lib.rrtc_plan(kern._km_p, nat._mask_p[mode], kern._pose_p, g, bp.pointer, dim, jidx_p, base_p, e0,
                         e0 + 8 * dim, e0 + 16 * dim, e0 + 24 * dim, float(range_), float(resolution),
                         int(max_iterations), MAX_NODES, int(stall_iterations), int(shortcut_iterations), clock_kind,
                         end, seed, int(sampler == "halton"), e0 + 32 * dim, ctypes.byref(out), ctypes.byref(n_out),
                         stats.ctypes.data)
    st = stats.tolist()
    ck.n_checks += st[2]
    if code == -2:
        return None
    path = None
    if code == 0:
        try:
            P = np.empty((n_out.value, dim))
            ctypes.memmove(P.ctypes.data, out, P.nbytes)
        finally:
            lib.rrtc_free(out)
        path = P
    return NativeRRTCResult(RRTC_STATUS.get(code, f"status {code}"), path, st[0], st[1], st[2], (st[3], st[4]),
                            st[5], st[6], st[7])


_WHOLE: dict[int, tuple[int, int, int]] = {}
_WHOLE_ARRAYS: list[tuple[np.ndarray, np.ndarray]] = []   # kept alive: their addresses are in _WHOLE


def _whole(nq: int) -> tuple[int, int, int]:
    """The addresses of the joint indices 0 … nq − 1 and of a zero base, and nq (a query that searches every
    joint); the arrays are kept per nq (read only by the native call)."""
    got = _WHOLE.get(nq)
    if got is None:
        jidx, base = np.arange(nq, dtype=np.int32), np.zeros(nq)
        _WHOLE_ARRAYS.append((jidx, base))
        got = _WHOLE[nq] = (jidx.ctypes.data, base.ctypes.data, nq)
    return got


def _mode(validity: ConfigValidity) -> tuple[str, Any]:
    """The checker mode and still-object pose a validity function's checks use (as
    :meth:`~optplan.planners.validity.ValidityChecker.first_invalid` resolves them)."""
    ck, mode, pose = validity.checker, validity.mode, validity.object_pose
    if ck.object is None and mode in ("held", "fixed"):
        return "free", None
    return mode, (pose if mode == "fixed" else None)
