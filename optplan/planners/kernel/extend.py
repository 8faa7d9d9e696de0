"""TCBiRRT's extension step and the trees' nearest-neighbour scan in native code.

:class:`NativeExtender` runs one constrained extension of TCBiRRT (Alg. 2 of the TCBiRRT paper: the
object poses between two tree nodes, the closed-chain path IK of both arms along them, the collision
check of every configuration, and the edge checks between consecutive ones) in one C call
(:mod:`optplan.planners.kernel.extend_csource`). It reuses what is already compiled: the planning
kernel's collision model (:class:`~optplan.planners.kernel.checker.NativeValidity` of the planner's
:class:`~optplan.planners.validity.ValidityChecker`), the IK block of
:class:`~optplan.constraints.closed_chain.ClosedChainKinematics` and the checker's edge speed profile,
called by address. The random restarts of a failed waypoint stay in Python (they draw from the
planner's ``numpy.random.Generator``, so the search for a seed is the Python one's).

:func:`nearest` is the first live row of ``X`` nearest a point (squared Euclidean distance), a linear
scan in C: :meth:`optplan.planners.tree.Tree.nearest` uses it when the library is available.

The library (the planning kernel's C source followed by this one) is built with the system C compiler
at first use and cached like the kernel's (:func:`load_extend_library`); without a compiler
:class:`~optplan.planners.kernel.native.KernelUnavailable` is raised and the callers keep their
Python code.
"""
from __future__ import annotations

import ctypes
import hashlib
import logging
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ...codegen import build_library, build_tag, cache_dir
from ..ik_seed import PREDICTORS
from .addresses import AddressCache
from .csource import C_SOURCE
from .extend_csource import EXTEND_SOURCE
from .ik_csource import IK_SOURCE
from .lookahead_csource import LOOKAHEAD_SOURCE
from .native import KernelUnavailable, se3_pose12
from .sampler_csource import RNG_SOURCE, SAMPLER_SOURCE
from .streak_csource import STREAK_SOURCE

__all__ = ["NativeExtender", "NativePoseFilter", "load_extend_library", "nearest", "nearest_available", "nearest_batch"]
log = logging.getLogger(__name__)

_P = ctypes.c_void_p
_LL = ctypes.c_longlong
_LIB: list[Any] = []        # the loaded library (one per process), or [None] after a failed build
SOURCE = C_SOURCE + RNG_SOURCE + IK_SOURCE + EXTEND_SOURCE + SAMPLER_SOURCE + STREAK_SOURCE + LOOKAHEAD_SOURCE
#: counters of one native call, in the order of the C code
COUNTERS = ("ik_calls", "ik_iterations", "ik_failures", "ik_jumps", "collisions", "checks", "edge_checks",
            "edge_collisions", "terminal", "ik_restarts", "ik_path_iterations", "ik_restarts_skipped",
            "ik_restart_iterations", "pose_blocked")


class _Ctx(ctypes.Structure):
    _fields_ = [("km", _P), ("active", _P), ("nq", ctypes.c_int),
                ("ik", _P), ("ik_iw", _P), ("ik_w", _P),
                ("damping", ctypes.c_double), ("tol_p", ctypes.c_double), ("tol_o", ctypes.c_double),
                ("gain", ctypes.c_double), ("max_step", ctypes.c_double), ("max_it", ctypes.c_int),
                ("max_joint_step", ctypes.c_double),
                ("edge_on", ctypes.c_int), ("edge_tol", ctypes.c_double),
                ("W", _P), ("nw", ctypes.c_int),
                ("prof", _P), ("prof_iw", _P), ("prof_w", _P), ("nprof", ctypes.c_int), ("edge_res", ctypes.c_double),
                ("rng", _P), ("restarts", ctypes.c_int), ("restart_sigma", ctypes.c_double), ("lower", _P), ("upper", _P),
                ("ikm", _P), ("predictor", ctypes.c_int), ("qlo", _P), ("qhi", _P), ("pfix", _P),
                ("restart_max_it", ctypes.c_int), ("restart_clip", ctypes.c_int),
                ("npfl", ctypes.c_int), ("pfl", _P), ("npfg", ctypes.c_int), ("pfg", _P), ("pfa", _P), ("pfT", _P)]


def load_extend_library() -> Any:
    """The compiled extension library (``ctypes.CDLL``), built at first use and cached under
    :func:`optplan.codegen.cache_dir` by a hash of its source. Raises
    :class:`~optplan.planners.kernel.native.KernelUnavailable` when it cannot be built (and remembers
    that for the process)."""
    if _LIB:
        if _LIB[0] is None:
            raise KernelUnavailable("the native extension library could not be built in this process")
        return _LIB[0]
    digest = hashlib.sha1(SOURCE.encode()).hexdigest()[:16] + "_" + build_tag()
    lib_path = cache_dir() / f"optplan_tcb_extend_{digest}.so"
    lib = None
    for attempt in range(2):
        if not lib_path.exists():
            with tempfile.TemporaryDirectory() as tmp:
                c_file = Path(tmp, "tcb_extend.c")
                c_file.write_text(SOURCE)
                err = build_library(c_file, lib_path, "-O3", native=True)
            if err is not None:
                _LIB.append(None)
                raise KernelUnavailable(f"the native extension library could not be compiled: {err}")
        try:
            lib = ctypes.CDLL(str(lib_path))
            break
        except OSError as e:   # a damaged cache file: rebuilt once
            if attempt:
                _LIB.append(None)
                raise KernelUnavailable(f"the native extension library {lib_path} cannot be loaded: {e}") from None
            log.warning("the cached extension library %s cannot be loaded (%s); rebuilding it", lib_path, e)
            lib_path.unlink(missing_ok=True)
    assert lib is not None
    lib.tcb_nearest.restype = _LL
    lib.tcb_nearest.argtypes = [_P, _LL, ctypes.c_int, _P, _P]
    lib.tcb_nearest_kd.restype = _LL
    lib.tcb_nearest_kd.argtypes = [_P, _LL, ctypes.c_int, _P, _P, _P, _P]
    lib.tcb_nearest_batch.restype = None
    lib.tcb_nearest_batch.argtypes = [_P, _LL, ctypes.c_int, _P, _P, _LL, _P, _P, _P]
    lib.tcb_interpolate.restype = None
    lib.tcb_interpolate.argtypes = [_P, _P, _P, _P, ctypes.c_int, _P]
    lib.tcb_path_ik.restype = _LL
    lib.tcb_path_ik.argtypes = [_P, _P, _P, _P, _LL, _LL, _P, _P]
    lib.tcb_pose_blocked_api.restype = ctypes.c_int
    lib.tcb_pose_blocked_api.argtypes = [_P, _P]
    lib.tcb_edges.restype = _LL
    lib.tcb_edges.argtypes = [_P, _P, _P, _LL, _P]
    lib.tcb_filter_xi.restype = ctypes.c_int
    lib.tcb_filter_xi.argtypes = [_P, _P, ctypes.c_int]
    lib.tcb_filter_segment.restype = ctypes.c_int
    lib.tcb_filter_segment.argtypes = [_P, _P, _P, ctypes.c_double, ctypes.c_int, _P]
    lib.tcb_extend.restype = _LL
    lib.tcb_extend.argtypes = [_P, _P, _P, _P, _P, _LL, _P, _P, _P, _P, _P]
    lib.tcb_ik_block.restype = ctypes.c_int
    lib.tcb_ik_block.argtypes = [_P, _P, _P, _P, _P]
    lib.tcb_ik_api.restype = ctypes.c_int
    lib.tcb_ik_api.argtypes = [_P, _P, _P, _P, _P]
    lib.tcb_extend_prefix.restype = _LL
    lib.tcb_extend_prefix.argtypes = [_P, _P, _P, _P, _P, _LL, _P, _P, _P, _P, ctypes.c_int]
    _declare_sampler_functions(lib)
    _LIB.append(lib)
    return lib


def _declare_sampler_functions(lib: Any) -> None:
    """The ctypes signatures of the sampler's C functions (:mod:`.sampler`)."""
    _D = ctypes.c_double
    lib.tcb_rng_seed.restype = None
    lib.tcb_rng_seed.argtypes = [_P, ctypes.c_ulonglong]
    lib.tcb_rng_uniform.restype = _D
    lib.tcb_rng_uniform.argtypes = [_P]
    lib.tcb_rng_normal.restype = _D
    lib.tcb_rng_normal.argtypes = [_P]
    lib.tcb_sample.restype = None
    lib.tcb_sample.argtypes = [_P, _P, _LL, _P, _P]
    lib.tcb_sample_near.restype = _LL
    lib.tcb_sample_near.argtypes = [_P, _P, _LL, _P, _P, _LL, _P, _P, _P, _P]
    lib.tcb_lead_path.restype = _LL
    lib.tcb_lead_path.argtypes = [_P, _P, _P, _D, _D, ctypes.c_int, ctypes.c_int, _D, _LL, ctypes.POINTER(ctypes.POINTER(_D)),
                                  ctypes.POINTER(_LL)]
    lib.tcb_free.restype = None
    lib.tcb_free.argtypes = [_P]


def nearest_available() -> bool:
    """Whether :func:`nearest` runs in C here (the library builds and loads)."""
    try:
        load_extend_library()
    except (KernelUnavailable, OSError):
        return False
    return True


def _checked_index(index: tuple[np.ndarray, np.ndarray], X: np.ndarray, who: str) -> tuple[np.ndarray, np.ndarray]:
    """``index`` (:func:`kd_index`) when it fits the key array ``X``, else a ValueError naming ``who``."""
    K, kdn = index
    width = 2 + X.shape[1]
    if K.shape != (len(X), width) or K.dtype != np.int64 or not K.flags.c_contiguous or kdn.shape != (1,) \
            or kdn.dtype != np.int64:
        raise ValueError(f"{who}: expected a k-d index of {len(X)} x {width} and 1 int64 values, got {K.dtype} "
                         f"{K.shape} and {kdn.dtype} {kdn.shape}")
    return K, kdn


def nearest(X: np.ndarray, n: int, x: np.ndarray, alive: np.ndarray | None = None,
            index: tuple[np.ndarray, np.ndarray] | None = None) -> int:
    """Index of the row of ``X[:n]`` (C-contiguous float64, rows of ``x.size``) nearest ``x`` in squared
    Euclidean distance, the first among equals; rows with ``alive[i]`` False are skipped (``alive``:
    a boolean array, or None). −1 when no row is live. ``index``: the rows' k-d index ``(K, kdn)`` (:func:`kd_index`
    for rows of ``x.size`` values, as many rows as ``X``), searched instead of every row from 512 rows on (the same
    answer); it takes rows added since its last use (rows are only ever appended to ``X``)."""
    lib = load_extend_library()
    x = np.ascontiguousarray(x, dtype=float)
    if X.dtype != np.float64 or not X.flags.c_contiguous or X.ndim != 2 or x.size != X.shape[1] or not 0 <= n <= len(X):
        raise ValueError(f"nearest: expected a C-contiguous float64 array of rows of {x.size} values and "
                         f"0 <= n <= {len(X)}, got {X.dtype} {X.shape} and n = {n}")
    if index is None:
        return int(lib.tcb_nearest(_ADDR(X), n, x.size, _ADDR(alive), x.ctypes.data))
    K, kdn = _checked_index(index, X, "nearest")
    return int(lib.tcb_nearest_kd(_ADDR(X), n, x.size, _ADDR(alive), x.ctypes.data, _ADDR(K), _ADDR(kdn)))


def nearest_batch(X: np.ndarray, n: int, Q: np.ndarray, alive: np.ndarray | None = None,
                  index: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """:func:`nearest` of every row of ``Q`` (queries of ``X.shape[1]`` values) in one native call: their row
    indices (int64). The benchmark's loop (:mod:`optplan.bench.nearest_index`), timed without a call per query."""
    lib = load_extend_library()
    Q = np.ascontiguousarray(Q, dtype=float)
    if Q.ndim != 2 or X.ndim != 2 or Q.shape[1] != X.shape[1] or X.dtype != np.float64 or not X.flags.c_contiguous \
            or not 0 <= n <= len(X):
        raise ValueError(f"nearest_batch: expected C-contiguous float64 rows X and queries Q of one width and "
                         f"0 <= n <= {len(X)}, got X {X.dtype} {X.shape}, Q {Q.shape} and n = {n}")
    if alive is not None and (alive.dtype != np.bool_ or alive.shape[0] < n or not alive.flags.c_contiguous):
        raise ValueError(f"nearest_batch: expected a boolean mask of at least {n} rows, got {alive.dtype} {alive.shape}")
    K, kdn = (None, None) if index is None else _checked_index(index, X, "nearest_batch")
    out = np.empty(len(Q), np.int64)
    lib.tcb_nearest_batch(X.ctypes.data, n, X.shape[1], None if alive is None else alive.ctypes.data, Q.ctypes.data,
                          len(Q), None if K is None else K.ctypes.data, None if kdn is None else kdn.ctypes.data,
                          out.ctypes.data)
    return out


def kd_index(rows: int, dim: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """An empty k-d index for :func:`nearest` over a key array of ``rows`` rows of ``dim`` values: ``(K, kdn)``.
    ``K`` (``rows`` × (2 + ``dim``) int64 slots) holds a balanced tree built by the native code over the first
    ``kdn[0]`` rows (their order in the leaves, and per node the exact box of its keys), built again over all rows once
    the rows appended since outgrow a sixteenth of them (those are scanned until then); ``kdn`` (1 int64, 0 now) is
    that count. Grow ``K`` with its key array (rows appended, the old ones kept)."""
    return np.full((int(rows), 2 + int(dim)), -1, np.int64), np.zeros(1, np.int64)


#: the trees' key arrays and masks, passed to :func:`nearest` at every call
_ADDR = AddressCache(16)


class _Filt(ctypes.Structure):
    _fields_ = [("km", _P), ("active", _P), ("g", ctypes.c_int), ("nobs", ctypes.c_int), ("ngrasp", ctypes.c_int),
                ("gt", _P), ("sh", _P), ("reach", _P)]


class NativePoseFilter:
    """The test of :class:`~optplan.planners.task_sampling.ObjectPoseFilter` on ξ = (position [m], roll,
    pitch, yaw [rad]) in one native call: each grasp point within its arm's reach bound, then the object
    free of the obstacles (the filter's native object model). ``kernel``, ``g``, ``active``: the filter's
    obstacle model, object geometry and pair mask; ``grasps``: (grasp point in the object frame [m],
    shoulder [m], reach bound [m]) per arm; ``n_obstacles``: 0 skips the object test."""

    #: :meth:`check` results
    UNREACHABLE, COLLIDES, FREE = 0, 1, 2

    def __init__(self, kernel: Any, g: int, active: np.ndarray, grasps: list[tuple[np.ndarray, np.ndarray, float]],
                 n_obstacles: int) -> None:
        self.lib = load_extend_library()
        self._gt = np.ascontiguousarray([t for t, _, _ in grasps], dtype=float).reshape(-1, 3)
        self._sh = np.ascontiguousarray([s for _, s, _ in grasps], dtype=float).reshape(-1, 3)
        self._r = np.ascontiguousarray([r for _, _, r in grasps], dtype=float)
        self._keep = (kernel, active)
        f = _Filt()
        f.km, f.active, f.g, f.nobs, f.ngrasp = kernel._km_p, active.ctypes.data, int(g), int(n_obstacles), len(grasps)
        f.gt, f.sh, f.reach = self._gt.ctypes.data, self._sh.ctypes.data, self._r.ctypes.data
        self._f = f
        self._fp = ctypes.addressof(f)
        self._xi = np.zeros(6)
        self._b = np.zeros(6)
        self._xi_p, self._b_p = self._xi.ctypes.data, self._b.ctypes.data   # cached: .ctypes.data costs ~1 µs
        self._n = _LL(0)
        self._np = ctypes.addressof(self._n)
        self._check = self.lib.tcb_filter_xi

    def check(self, xi: np.ndarray, reach: bool = True) -> int:
        """:attr:`UNREACHABLE`, :attr:`COLLIDES` or :attr:`FREE` for the pose ``xi`` (``reach`` False: the
        object test alone, never UNREACHABLE)."""
        self._xi[:] = xi
        return int(self._check(self._fp, self._xi_p, int(reach)))

    def segment(self, a: np.ndarray, b: np.ndarray, resolution: float, check_end: bool = True) -> tuple[bool, int]:
        """The straight ξ segment ``a → b`` passes at every point of
        :func:`~optplan.planners.rrtconnect.edge_is_valid` (largest coordinate change ``resolution`` between
        checks, coarse-to-fine, ``b`` first with ``check_end``): ``(passes, filter calls made)``."""
        xa, xb = self._xi, self._b
        xa[:] = a
        xb[:] = b
        ok = self.lib.tcb_filter_segment(self._fp, self._xi_p, self._b_p, float(resolution), int(check_end), self._np)
        if ok < 0:
            raise KernelUnavailable("the native filter refused the model (too many geometries)")
        return bool(ok), int(self._n.value)


def _cfun(ff: Any) -> tuple[int, Any, Any, int] | None:
    """(function address, iw, w, output size) of a compiled :class:`~optplan.codegen.FastFunction`, or None."""
    cf = getattr(ff, "_cf", None)
    if cf is None or len(cf._arg) > 64 or len(cf._res) > 64:
        return None
    return ctypes.cast(cf._fn, ctypes.c_void_p).value or 0, cf._iw, cf._w, int(ff.n_out)


def pose_fixed_pairs(kernel: Any, kin: Any) -> np.ndarray | None:
    """Per collision pair of ``kernel`` (:class:`~optplan.planners.kernel.native.NativeKernel`): 1 when both its
    geometries are placed by the object's pose alone — static (parent joint 0) or on the joint that carries a
    hand's frame, which the closed-chain IK puts at its grasp of the object — so that every IK solution of one
    object pose has that pair in the same contact (up to the IK's tolerance). None when the kernel's joints are not
    the robot model's."""
    model = kin.robot.model
    jparent, gparent, pa, pb = kernel._arrays[0], kernel._arrays[5], kernel._arrays[10], kernel._arrays[11]
    if len(jparent) != model.njoints:
        return None
    placed = {0, *(int(model.frames[int(arm.ee_frame_id)].parentJoint) for arm in kin.arms)}
    fixed = np.array([int(g) in placed for g in gparent], bool)
    return np.ascontiguousarray(fixed[np.asarray(pa)] & fixed[np.asarray(pb)], dtype=np.uint8)


def pose_test_layout(kernel: Any, kin: Any, pfix: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                                np.ndarray] | None:
    """What the native pose test before a waypoint's IK needs (``tcb_pose_blocked``): the pairs of ``pfix``
    (:func:`pose_fixed_pairs`) with a moving geometry, those moving geometries, the arm whose hand joint carries each,
    and per arm the hand joint's placement in the object frame at its grasp (``grasp · frame placement⁻¹``, 2 × 12).
    None when there is nothing to test (no such pair, not two arms, or more than 8 such geometries)."""
    if pfix is None or len(kin.arms) != 2:
        return None
    model = kin.robot.model
    gparent, pa, pb = kernel._arrays[5], kernel._arrays[10], kernel._arrays[11]
    hands = [int(model.frames[int(arm.ee_frame_id)].parentJoint) for arm in kin.arms]
    pairs = [k for k in range(len(pfix)) if pfix[k] and (int(gparent[pa[k]]) != 0 or int(gparent[pb[k]]) != 0)]
    geoms = sorted({int(g) for k in pairs for g in (pa[k], pb[k]) if int(gparent[g]) != 0})
    if not pairs or len(geoms) > 8 or hands[0] == hands[1]:
        return None
    arm_of = np.array([hands.index(int(gparent[g])) for g in geoms], np.int32)
    T = np.array([se3_pose12(kin.grasps[arm.name] * model.frames[int(arm.ee_frame_id)].placement.inverse())
                  for arm in kin.arms], float)
    return (np.asarray(pairs, np.int32), np.asarray(geoms, np.int32), arm_of, np.ascontiguousarray(T))


class NativeExtender:
    """One TCBiRRT extension per native call for a planner's checker, kinematics and options.

    ``checker``: a :class:`~optplan.planners.validity.ValidityChecker` with the native backend;
    ``kin``: :class:`~optplan.constraints.closed_chain.ClosedChainKinematics` (compiled);
    ``ik``: :class:`~optplan.constraints.closed_chain.IKSettings`; ``max_joint_step`` [rad];
    ``edge_tolerance`` [m] (0: no edge checks) with the Jacobian spacing of
    :meth:`~optplan.planners.validity.ValidityChecker.edge_checkpoints`; ``edge_resolution`` [rad] (None: off):
    each new waypoint's segment from the previous one checked every ``edge_resolution`` of its largest joint
    change, right after the waypoint (TCBiRRT's ``edge_resolution`` option); ``ik_predictor``: a waypoint's IK
    seed, ``"none"`` (the previous solution) or ``"secant"`` (TCBiRRT's ``ik_predictor`` option).

    Raises :class:`~optplan.planners.kernel.native.KernelUnavailable` when any part is not compiled."""

    def __init__(self, checker: Any, kin: Any, ik: Any, max_joint_step: float, edge_tolerance: float,
                 edge_resolution: float | None = None, ik_predictor: str = "none") -> None:
        if ik_predictor not in PREDICTORS:
            raise ValueError(f"ik_predictor: expected one of {PREDICTORS}, got {ik_predictor!r}")
        self.lib = load_extend_library()
        nv = getattr(checker, "_native", None)
        if nv is None:
            raise KernelUnavailable("the validity checker does not use the native kernel")
        if checker.object is None:
            raise KernelUnavailable("the native extension needs a held object")
        block = _cfun(kin._block)
        if block is None:
            raise KernelUnavailable("the closed-chain IK block is not compiled")
        self.nq = int(kin.nq)
        if self.nq != nv.kernel.nq:
            raise KernelUnavailable("the kinematics and the checker have different configurations")
        prof = None
        if edge_tolerance:
            fn = checker._profile_function("held")
            if fn is not None:
                prof = _cfun(fn)
                if prof is None or prof[3] > 64:
                    raise KernelUnavailable("the edge speed profile is not compiled")
        self._W = np.ascontiguousarray(checker._sweep["held"], dtype=float)
        self._keep = (nv, block, prof)   # the buffers the C code points into stay alive with this object
        self.checker = checker
        c = _Ctx()
        c.km, c.active, c.nq = nv.kernel._km_p, nv._mask_p["held"], self.nq
        c.ik, c.ik_iw, c.ik_w = block[0], block[1].ctypes.data, block[2].ctypes.data
        c.damping, c.tol_p, c.tol_o, c.gain, c.max_step = ik.damping, ik.tol_position, ik.tol_orientation, ik.gain, ik.max_step
        c.max_it = int(ik.max_iterations)
        c.max_joint_step = float(max_joint_step)
        c.edge_on, c.edge_tol = int(bool(edge_tolerance)), float(edge_tolerance or 0.0)
        c.W, c.nw = self._W.ctypes.data, int(self._W.shape[0])
        if prof is not None:
            c.prof, c.prof_iw, c.prof_w, c.nprof = prof[0], prof[1].ctypes.data, prof[2].ctypes.data, prof[3]
        c.edge_res = float(edge_resolution or 0.0)
        self._qlim = (np.ascontiguousarray(kin.lower, dtype=float), np.ascontiguousarray(kin.upper, dtype=float))
        c.predictor, c.qlo, c.qhi = PREDICTORS.index(ik_predictor), self._qlim[0].ctypes.data, self._qlim[1].ctypes.data
        self._pfix = pose_fixed_pairs(nv.kernel, kin)
        c.pfix = None if self._pfix is None else self._pfix.ctypes.data
        #: the pose test before each waypoint's IK (None: off): the pairs the object pose alone places
        self._pose_test = pose_test_layout(nv.kernel, kin, self._pfix)
        if self._pose_test is not None:
            pfl, pfg, pfa, pfT = self._pose_test
            c.npfl, c.pfl, c.npfg, c.pfg, c.pfa, c.pfT = len(pfl), pfl.ctypes.data, len(pfg), pfg.ctypes.data, \
                pfa.ctypes.data, pfT.ctypes.data
        self._ctx = c
        self._ik: Any = None
        try:
            from .ik import NativeIK

            self._ik = NativeIK(nv.kernel, kin, load_extend_library())
        except KernelUnavailable as e:
            log.info("the native extension calls the CasADi IK block: %s", e)
        self.native_ik = self._ik is not None
        #: a failing waypoint's random restarts run in C, drawn from :meth:`restarts_in_c`'s generator
        self.native_restarts = False
        #: the edges between an extension's configurations are checked here (else by the caller)
        self.edge_on = bool(edge_tolerance)
        self._cp = ctypes.addressof(c)
        self.cnt = np.zeros(len(COUNTERS), np.int64)
        self._cnt_p = self.cnt.ctypes.data
        self._edge_k = _LL(-1)
        self._edge_kp = ctypes.addressof(self._edge_k)
        self._its = _LL(0)
        self._its_p = ctypes.addressof(self._its)
        self._seed, self._pose_in = np.zeros(self.nq), np.zeros(12)
        self._seed_p, self._pose_in_p = self._seed.ctypes.data, self._pose_in.ctypes.data
        self._R0 = np.zeros(9)
        self._p0 = np.zeros(3)
        self._R1 = np.zeros(9)
        self._p1 = np.zeros(3)
        self._qn = np.zeros(self.nq)
        self._bufs = [ctypes.addressof(x) if isinstance(x, ctypes.Structure) else x.ctypes.data
                      for x in (self._R0, self._p0, self._R1, self._p1, self._qn)]
        self._R0m, self._R1m = self._R0.reshape(3, 3), self._R1.reshape(3, 3)   # views: no reshape per call
        #: :meth:`extend_prefix`'s output arrays and their addresses while no caller holds them (None: make new)
        self._out: tuple[np.ndarray, np.ndarray, int, int] | None = None

    @property
    def native_ik(self) -> bool:
        """Whether the path IK runs the hand-written C IK (:class:`~optplan.planners.kernel.ik.NativeIK`; the
        default when the arms are serial chains of the kernel's model) rather than the compiled CasADi block of
        :class:`~optplan.constraints.closed_chain.ClosedChainKinematics` (False; the same iterates up to
        round-off). Settable, e.g. to compare the two."""
        return bool(self._ctx.ikm)

    @native_ik.setter
    def native_ik(self, on: bool) -> None:
        if on and self._ik is None:
            raise KernelUnavailable("the hand-written IK does not cover these arms")
        self._ctx.ikm = self._ik.address if on else None

    def restarts_in_c(self, rng: Any, restarts: int, sigma: float, lower: np.ndarray, upper: np.ndarray,
                      max_iterations: int = 0, clip: bool | str = False) -> None:
        """Run a failing waypoint's random restarts in C: ``restarts`` IK attempts [count] from the previous
        configuration perturbed by ``N(0, sigma²)`` [rad] per joint, drawn from ``rng`` (a
        :class:`~optplan.planners.kernel.sampler.NativeRandom`), accepted inside ``[lower, upper]`` [rad], within
        the joint-jump bound and collision-free (what :meth:`~optplan.planners.tcbirrt.TCBiRRT.path_ik` does with
        the planner's NumPy generator); each IK stops after ``max_iterations`` [count] (0: the extension's IK
        limit). ``clip``: each offset clipped to the joint-jump bound (``TCBiRRTOptions.ik_restart_clip``: False,
        True, or ``"first"``: in a waypoint's first restart only)."""
        if clip not in (False, True, "first"):
            raise ValueError(f"restarts_in_c: clip expected False, True or 'first', got {clip!r}")
        self._lim = (np.ascontiguousarray(lower, dtype=float), np.ascontiguousarray(upper, dtype=float), rng)
        c = self._ctx
        c.rng, c.restarts, c.restart_sigma = rng.address, int(restarts), float(sigma)
        c.restart_max_it = int(max_iterations)
        c.restart_clip = 2 if clip == "first" else int(bool(clip))
        c.lower, c.upper = self._lim[0].ctypes.data, self._lim[1].ctypes.data
        self.native_restarts = True

    def ik(self, q_seed: np.ndarray, R: np.ndarray, p: np.ndarray) -> tuple[np.ndarray | None, int]:
        """The extension's own IK toward the object pose ``(R, p)`` from ``q_seed`` [rad]: the hand-written one while
        :attr:`native_ik` is on (the path IK's), else :meth:`ik_block`. ``(q, iterations)``, ``q`` None when not
        converged."""
        return self._solve(self.lib.tcb_ik_api, q_seed, R, p)

    def ik_block(self, q_seed: np.ndarray, R: np.ndarray, p: np.ndarray) -> tuple[np.ndarray | None, int]:
        """:meth:`~optplan.constraints.closed_chain.ClosedChainKinematics.ik` with this extension's IK settings, its
        loop in C over the same compiled block (the same result bit for bit, without a Python call per block call):
        ``(q, iterations)``, ``q`` None when not converged."""
        return self._solve(self.lib.tcb_ik_block, q_seed, R, p)

    def _solve(self, fn: Any, q_seed: np.ndarray, R: np.ndarray, p: np.ndarray) -> tuple[np.ndarray | None, int]:
        """One IK solve by the library function ``fn`` (``tcb_ik_api`` or ``tcb_ik_block``)."""
        self._seed[:] = q_seed
        self._pose_in[:9] = np.asarray(R).reshape(9)
        self._pose_in[9:] = p
        out = np.empty(self.nq)
        r = fn(self._cp, self._seed_p, self._pose_in_p, out.ctypes.data, self._its_p)
        if r < 0:
            raise KernelUnavailable("the native extension refused the model (too many joints)")
        return (out if r else None), int(self._its.value)

    def take_counts(self) -> dict[str, int]:
        """The counters since the last call (reset); ``checks`` are also added to the checker's ``n_checks``."""
        out = dict(zip(COUNTERS, (int(v) for v in self.cnt)))
        self.cnt[:] = 0
        self.checker.n_checks += out["checks"]
        return out

    def terminal(self) -> bool:
        """Whether the last failing waypoint failed its ``edge_resolution`` segment (then no restarts); reset."""
        t = bool(self.cnt[8])
        self.cnt[8] = 0
        return t

    def _load(self, R0: np.ndarray, p0: np.ndarray, R1: np.ndarray, p1: np.ndarray, q_near: np.ndarray,
              n: int) -> tuple[np.ndarray, np.ndarray]:
        """The end poses and ``q_near`` into the call's buffers; fresh outputs ``P`` (n × 12), ``Q`` (n × nq)."""
        self._fill(R0, p0, R1, p1, q_near)
        return np.empty((n, 12)), np.empty((n, self.nq))

    def _fill(self, R0: np.ndarray, p0: np.ndarray, R1: np.ndarray, p1: np.ndarray, q_near: np.ndarray) -> None:
        """The end poses (3 × 3 or 9 rotation values, row-major) and ``q_near`` into the call's buffers."""
        if R0.shape == (3, 3):
            self._R0m[:] = R0
        else:
            self._R0[:] = R0.reshape(9)
        self._p0[:] = p0
        if R1.shape == (3, 3):
            self._R1m[:] = R1
        else:
            self._R1[:] = R1.reshape(9)
        self._p1[:] = p1
        self._qn[:] = q_near

    def extend(self, R0: np.ndarray, p0: np.ndarray, R1: np.ndarray, p1: np.ndarray, n: int,
               q_near: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, int]:
        """The poses ``j = 1..n`` from ``(R0, p0)`` to ``(R1, p1)`` (``P``: n × 12, rotation row-major then
        position [m]), the path IK from ``q_near`` into ``Q`` (n × nq) and, when every waypoint passes, the
        edge checks: ``(P, Q, r, e)`` with ``r`` the waypoints accepted (``r < n``: waypoint ``r`` failed)
        and ``e`` the first edge in collision (``n``: none; −1: not checked)."""
        P, Q = self._load(R0, p0, R1, p1, q_near, n)
        a = self._bufs
        r = self.lib.tcb_extend(self._cp, a[0], a[1], a[2], a[3], n, a[4], P.ctypes.data, Q.ctypes.data,
                                self._cnt_p, self._edge_kp)
        if r < -1:
            raise KernelUnavailable("the native extension refused the model (too many joints or geometries)")
        return P, Q, int(r), int(self._edge_k.value)

    def extend_prefix(self, R0: np.ndarray, p0: np.ndarray, R1: np.ndarray, p1: np.ndarray, n: int,
                      q_near: np.ndarray, prefix: bool) -> tuple[np.ndarray, np.ndarray, int]:
        """:meth:`extend` with the restarts in C (:meth:`restarts_in_c`) and the edges of the accepted
        configurations checked: ``(P, Q, k)`` with ``Q[:k]`` the configurations kept (with ``prefix``: the valid
        prefix, ``k`` possibly 0; without it ``k`` is n, or −1 when the extension fails)."""
        self._fill(R0, p0, R1, p1, q_near)
        out = self._out
        if out is None or out[0].shape[0] != n:
            P, Q = np.empty((n, 12)), np.empty((n, self.nq))
            out = (P, Q, P.ctypes.data, Q.ctypes.data)
        P, Q, pp, qp = out
        a = self._bufs
        k = self.lib.tcb_extend_prefix(self._cp, a[0], a[1], a[2], a[3], n, a[4], pp, qp, self._cnt_p, int(prefix))
        if k < -1:
            raise KernelUnavailable("the native extension refused the model (too many joints or geometries)")
        # kept for the next call only when no configuration is returned (k ≤ 0: a trapped extension, whose
        # arrays the caller reads no further); else the caller owns them and the next call makes new ones
        self._out = out if k <= 0 else None
        return P, Q, int(k)

    def path_ik(self, P: np.ndarray, j0: int, q_prev: np.ndarray, Q: np.ndarray, q_pp: np.ndarray | None = None) -> int:
        """Waypoints ``j0..n−1`` of the poses ``P`` into ``Q`` seeded by ``q_prev`` (``q_pp``: the solution before
        it, for the predictor; None: none): the first that fails, or n."""
        self._qn[:] = q_prev
        pp = None if q_pp is None else np.ascontiguousarray(q_pp, dtype=float)
        r = self.lib.tcb_path_ik(self._cp, self._bufs[4], None if pp is None else pp.ctypes.data, P.ctypes.data, j0,
                                 P.shape[0], Q.ctypes.data, self._cnt_p)
        if r < -1:
            raise KernelUnavailable("the native extension refused the model (too many joints or geometries)")
        return int(r)

    def edges(self, q_prev: np.ndarray, Q: np.ndarray, n: int) -> int:
        """The edges ``q_prev → Q[0] → … → Q[n−1]``: the first in collision, or n."""
        self._qn[:] = q_prev
        Q = np.ascontiguousarray(Q, dtype=float)
        r = self.lib.tcb_edges(self._cp, self._bufs[4], Q.ctypes.data, n, self._cnt_p)
        if r < -1:
            raise KernelUnavailable("the native extension refused the model (too many joints or geometries)")
        return int(r)

    def interpolate(self, R0: np.ndarray, p0: np.ndarray, R1: np.ndarray, p1: np.ndarray, n: int) -> np.ndarray:
        """The poses ``j = 1..n`` (n × 12) of :meth:`extend` alone."""
        P, _ = self._load(R0, p0, R1, p1, self._qn, n)
        a = self._bufs
        self.lib.tcb_interpolate(a[0], a[1], a[2], a[3], n, P.ctypes.data)
        return P
