"""Per-knot kernels of the B-spline segment NLP (:mod:`.segment`): small SX functions of one
knot's joint vector — the closed chain and the plane rows of one collision pair — and their
symbolic derivatives, built once per robot and kept in memory and on disk (:class:`KernelCache`)."""
from __future__ import annotations

import logging
import os
import time
import weakref
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

import casadi as ca
import numpy as np

from ..cache import quarantine, record, usable
from ..constraints.closed_chain import relative_pose_residual
from ..model.robot import RobotModel
from ..model.symbolic import SymbolicKinematics
from . import kernel_compiler as background
from .frame_terms import ClosedChain
from .kernel_compiler import compile_library

__all__ = ["KernelCache", "geometry_points", "load_library"]
log = logging.getLogger(__name__)
_T = TypeVar("_T")


def load_library(name: str, lib: Path) -> ca.Function | None:
    """The compiled kernel ``name`` from the shared library ``lib`` (``casadi.external``), or None
    when there is none or it is damaged — checked against its recorded size and hash before it is
    loaded (:mod:`optplan.cache`); a damaged one is quarantined, with a warning, to be rebuilt."""
    if not usable(lib):
        return None
    try:
        return ca.external(name, str(lib))
    except RuntimeError as exc:   # dlopen refused it, or the symbol is missing
        quarantine(lib, f"does not load: {str(exc).splitlines()[0] if str(exc) else exc}")
        return None


class KernelCache:
    """SX kernels of one robot, built once and shared by every segment NLP of that robot.

    ``closed_chain(cc)``: ``f(q, n, s) -> 7 rows``; ``pair(...)``: ``f(q, n, s) -> rows`` of one
    collision pair; ``derivatives(f)``: their symbolic Jacobians and Hessians. Each function is
    also saved under ``$OPTPLAN_CACHE/kernels`` (default ``~/.cache/optplan``), keyed by a hash of
    the robot's kinematics and of what the kernel depends on, so a fresh process loads it instead
    of differentiating again (``disk=False``: memory only)."""

    _per_robot: weakref.WeakKeyDictionary[RobotModel, KernelCache] = weakref.WeakKeyDictionary()
    _by_digest: weakref.WeakValueDictionary[bytes, KernelCache] = weakref.WeakValueDictionary()

    #: the base these kernels are for (:class:`~optplan.problem.floating_kernels.FloatingKernels`
    #: is the free-floating subclass); added to the disk keys of a subclass
    floating_base = False
    _digest_tag = b""

    def __init__(self, robot: RobotModel, disk: bool = True):
        if robot.is_floating != self.floating_base:
            if robot.is_floating:
                raise ValueError("the B-spline segment NLP is for fixed-base robots; use FloatingSplineProblem "
                                 f"(optplan.problem.floating_segment) for the free-floating {robot.name!r}")
            raise ValueError(f"{type(self).__name__}: {robot.name!r} has a fixed base; use KernelCache")
        self.robot = robot
        self.sym = SymbolicKinematics(robot)
        self._q = ca.SX.sym("q", robot.nj)
        self._X_sym: Any = None   # the joint placements of ``_q``, built on first use (:attr:`_X`)
        self._fns: dict[tuple[Any, ...], ca.Function] = {}
        self._structures: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
        self._digest = self._robot_digest() + self._digest_tag
        self._dir: Path | None = None
        if disk:
            from ..codegen import cache_dir

            try:
                self._dir = cache_dir() / "kernels" / f"casadi-{ca.__version__}"  # type: ignore[attr-defined]  # casadi's stubs omit __version__
                self._dir.mkdir(parents=True, exist_ok=True)
            except OSError as exc:  # a read-only cache: memory only
                log.info("kernel cache on disk unavailable (%s)", exc)
                self._dir = None

    def _configuration(self, q: ca.SX) -> ca.SX:
        """The model configuration the kernels see for joint vector ``q`` (fixed base: ``q``)."""
        return q

    @property
    def _X(self) -> Any:
        """The symbolic world placements of every joint for the kernel input ``_q`` (SX), built
        on first use: a process whose kernels all load from the disk cache never needs them (their
        recursion cost ~8 ms per robot and process on the transport's dual arm)."""
        if self._X_sym is None:
            self._X_sym = self.sym.joint_placements(self._configuration(self._q))
        return self._X_sym

    def _robot_digest(self) -> bytes:
        return self.kinematics_digest(self.robot)

    @staticmethod
    def kinematics_digest(robot: RobotModel) -> bytes:
        """A hash of what the kernels of ``robot`` depend on (joints, frames)."""
        import hashlib

        from ..model.symbolic import _describe_joints

        h = hashlib.sha1(str(robot.nj).encode())
        for jt in _describe_joints(robot.model):
            if jt is None:
                h.update(b"-")
                continue
            h.update(repr((jt.kind, jt.parent, jt.q_index, jt.v_index, jt.scaling, jt.offset)).encode())
            for a in (jt.placement_R, jt.placement_p, jt.axis):
                h.update(np.asarray(a, float).tobytes())
        for f in robot.model.frames:
            h.update(repr((f.name, int(f.parentJoint))).encode() + np.asarray(f.placement.homogeneous).tobytes())
        return h.digest()

    def _get(self, key: tuple[Any, ...], build: Callable[[str], ca.Function]) -> ca.Function:
        """The function of ``key``: from memory, else from the disk cache, else ``build(name)``."""
        fn = self._fns.get(key)
        if fn is not None:
            return fn
        name = self._name(key)
        path = self._dir / f"{name}.casadi" if self._dir is not None else None
        if path is not None and usable(path):
            try:
                fn = ca.Function.load(str(path))
            except RuntimeError as exc:  # a damaged file: rebuild it
                quarantine(path, f"does not load: {str(exc).splitlines()[0] if str(exc) else exc}")
        if fn is None:
            fn = build(name)
            if path is not None:
                tmp = path.with_suffix(f".{os.getpid()}.tmp")
                try:
                    fn.save(str(tmp))
                    record(tmp, sidecar_for=path)
                    os.replace(tmp, path)  # atomic: concurrent processes never read half a file
                except (OSError, RuntimeError) as exc:
                    log.info("kernel %s not saved (%s)", path, exc)
        self._fns[key] = fn
        return fn

    def _name(self, key: tuple[Any, ...]) -> str:
        """The name (and disk-cache stem) of the function of ``key``."""
        import hashlib

        return f"{key[0]}_{hashlib.sha1(self._digest + repr(key).encode()).hexdigest()[:16]}"

    def _compiled_by_name(self, name: str, opt: str) -> ca.Function | None:
        """The compiled library of the function ``name`` if an earlier run left it, else None."""
        key = ("compiled", name, opt)
        got = self._fns.get(key)
        if got is None and self._dir is not None:
            got = load_library(name, self._dir / f"{name}{opt}.so")
            if got is not None:
                self._fns[key] = got
        return got

    def compiled(self, fn: ca.Function, opt: str = "-O1", build: bool = True) -> ca.Function | None:
        """``fn`` compiled to C: a shared library in the disk cache, named after the kernel (whose
        name is keyed by the robot's kinematics), loaded with ``casadi.external`` — several times
        faster to evaluate than CasADi's SX virtual machine. Compiling takes a C compiler and
        about a second per kernel, once per robot and kernel; every later process loads the
        library. ``build=False``: only load a library an earlier run compiled (None if there is
        none). Without a cache directory or a compiler, or if compiling fails: ``fn`` (logged)."""
        key = ("compiled", fn.name(), opt)
        got = self._fns.get(key)
        if got is not None:
            return got
        lib = None if self._dir is None else self._dir / f"{fn.name()}{opt}.so"
        ext = None if lib is None else load_library(fn.name(), lib)   # a damaged library: quarantined, None
        if ext is None:
            if not build:
                return None
            if lib is None:
                log.info("kernel %s not compiled (no cache directory)", fn.name())
                return fn
            t0 = time.perf_counter()
            if not compile_library(fn, lib, opt):
                return fn
            log.info("compiled kernel %s in %.1f s", fn.name(), time.perf_counter() - t0)
            ext = load_library(fn.name(), lib)
            if ext is None:
                return fn
        self._fns[key] = ext
        return ext

    def evaluators(self, fn: ca.Function, compiled: bool | str = False
                   ) -> tuple[tuple[ca.Function, ca.Function, ca.Function], bool]:
        """``((f, jac, hess), is_compiled)`` of kernel ``fn`` for an NLP: the symbolic functions
        (``compiled=False``), compiled C (``True``: compiled now where missing) or C where an
        earlier run left the libraries, else symbolic (``"auto"``; the missing libraries are then
        queued for a background compile, :mod:`optplan.problem.kernel_compiler`)."""
        if compiled not in (True, False, "auto"):
            raise ValueError(f"compile_kernels: expected True, False or 'auto', got {compiled!r}")
        if compiled is not False:  # all three compiled earlier: their symbolic forms are not loaded
            names = [fn.name(), self._name(("jac", fn.name())), self._name(("hess", fn.name()))]
            libs = [self._compiled_by_name(n, "-O1") for n in names]
            if all(lib is not None for lib in libs):
                return cast("tuple[ca.Function, ca.Function, ca.Function]", tuple(libs)), True
        jfn, hfn = self.derivatives(fn)
        fns = (fn, jfn, hfn)
        if compiled is False:
            return fns, False
        got = [self.compiled(f, build=compiled is True) for f in fns]
        if any(g is None for g in got) or any(g is f for g, f in zip(got, fns)):
            if compiled == "auto" and self._dir is not None:   # for the next NLPs and processes
                for f, g in zip(fns, got):
                    if g is None:
                        background.queue(self._dir, f.name(), "-O1")
            return fns, False
        # no None among them: checked above
        return cast("tuple[ca.Function, ca.Function, ca.Function]", tuple(got)), True

    #: how many segment-NLP structures (:meth:`structure`) stay in memory
    max_structures = 32

    def structure(self, key: tuple[Any, ...], build: Callable[[], _T]) -> _T:
        """The symbolic segment NLP of shape ``key`` (intervals, rows, pairs and their knots), from
        memory if an NLP of that shape was built in this process (with its IPOPT instances), else
        ``build()`` — kept in memory only, the ``max_structures`` most recently used."""
        st = self._structures.get(key)
        if st is None:
            st = self._structures[key] = build()
            while len(self._structures) > self.max_structures:
                self._structures.popitem(last=False)
        else:
            self._structures.move_to_end(key)
        return st

    def clear_structures(self) -> None:
        """Forget the NLP structures kept in memory (the next solve of any shape builds it)."""
        self._structures.clear()

    @classmethod
    def of(cls, robot: RobotModel) -> KernelCache:
        """The cache of ``robot`` (one per robot object; a robot loaded again, with the same
        kinematics, shares the cache of the first — its kernels and NLP structures)."""
        kc = cls._per_robot.get(robot)
        if kc is None:
            if robot.is_floating != cls.floating_base:
                return cls(robot)   # refused with the reason (the constructor's check)
            digest = cls.kinematics_digest(robot) + cls._digest_tag
            kc = cls._by_digest.get(digest)
            if kc is None:
                kc = cls._by_digest[digest] = cls(robot)
            cls._per_robot[robot] = kc
        return kc

    def frame(self, fid: int) -> tuple[ca.SX, ca.SX]:
        """(R, p) SX of frame ``fid`` as functions of the kernel input ``q``."""
        return self.sym.frame_placement(self._q, int(fid), self._X)

    def derivatives(self, fn: ca.Function) -> tuple[ca.Function, ca.Function]:
        """``(jac, hess)`` of a kernel ``f(q, n, s)``: ``jac(q, n, s) = ∂f/∂q`` (rows × nj, sparse) and
        ``hess(q, n, s, λ) = ∂²(λᵀf)/∂q²`` (nj × nj, symmetric, sparse) — symbolic, per knot."""
        def build_jac(name: str) -> ca.Function:
            q, n, s = fn.sx_in()
            return ca.Function(name, [q, n, s], [ca.jacobian(fn(q, n, s), q)])

        def build_hess(name: str) -> ca.Function:
            q, n, s = fn.sx_in()
            r = fn(q, n, s)
            lam = ca.SX.sym("lam", r.shape[0])
            return ca.Function(name, [q, n, s, lam], [ca.hessian(ca.dot(lam, r), q)[0]])

        return (self._get(("jac", fn.name()), build_jac), self._get(("hess", fn.name()), build_hess))

    def local_derivatives(self, fn: ca.Function) -> tuple[ca.Function, ca.Function]:
        """``(jac(z), hess(z, λ))`` of a kernel ``f(z)``: ``∂f/∂z`` and the upper triangle of
        ``∂²(λᵀf)/∂z²`` (sparse)."""
        def build_jac(name: str) -> ca.Function:
            z = fn.sx_in(0)
            return ca.Function(name, [z], [ca.jacobian(fn(z), z)])

        def build_hess(name: str) -> ca.Function:
            z = fn.sx_in(0)
            r = fn(z)
            lam = ca.SX.sym("lam", r.shape[0])
            return ca.Function(name, [z, lam], [ca.triu(ca.hessian(ca.dot(lam, r), z)[0])])

        return (self._get(("ljac", fn.name()), build_jac), self._get(("lhess_triu", fn.name()), build_hess))

    def closed_chain(self, cc: ClosedChain) -> ca.Function:
        rel = cc.relative
        assert rel is not None  # narrowing only: a ClosedChain without a relative pose failed below before too

        def build(name: str) -> ca.Function:
            Ra, pa = self.frame(self.robot.arm(cc.arm_a).ee_frame_id)
            Rb, pb = self.frame(self.robot.arm(cc.arm_b).ee_frame_id)
            r, tr = relative_pose_residual(Ra, pa, Rb, pb, rel)
            n, s = ca.SX.sym("n", 3), ca.SX.sym("s")  # unused: every kernel has the signature (q, n, s)
            return ca.Function(name, [self._q, n, s], [ca.vertcat(r, tr)])

        return self._get(("cc", cc.arm_a, cc.arm_b, np.asarray(rel.homogeneous).round(15).tobytes()), build)

    def pair(self, fa: int, Va: np.ndarray, ra: float, fb: int | None, Vb: np.ndarray, rb: float
             ) -> ca.Function:
        """Plane rows of one pair. Points ``Va`` (3 × m) in frame ``fa``, radius
        ``ra``; likewise B. B static (``fb is None``): ``f(q, n, s) = s − n·x_i − ra`` for A's
        points (``s``: the support value of B along n); both moving: ``f(q, n, b) =
        [b − n·x_i − ra; n·y_j − rb − b]``."""
        Va, Vb = np.ascontiguousarray(Va, float), np.ascontiguousarray(Vb, float)

        def build(name: str) -> ca.Function:
            n, s = ca.SX.sym("n", 3), ca.SX.sym("s")
            Ra, pa = self.frame(fa)
            Xa = Ra @ ca.DM(Va) + ca.repmat(pa, 1, Va.shape[1])
            if fb is None:
                rows = (s - n.T @ Xa - ra).T
            else:
                Rb, pb = self.frame(fb)
                Yb = Rb @ ca.DM(Vb) + ca.repmat(pb, 1, Vb.shape[1])
                rows = ca.vertcat((s - n.T @ Xa - ra).T, (n.T @ Yb - rb - s).T)
            return ca.Function(name, [self._q, n, s], [rows])

        # the static side's points are not in the kernel (only its support value, an input)
        key = ("pair", fa, Va.shape, Va.tobytes(), float(ra), fb,
               None if fb is None else (Vb.shape, Vb.tobytes(), float(rb)))
        return self._get(key, build)


def geometry_points(robot: RobotModel, g: int) -> tuple[int, np.ndarray, float]:
    """(parent frame, points 3 × m in that frame, radius) whose radius-inflated convex hull contains
    robot collision geometry ``g``: a cylinder by the capsule of its axis and radius, a convex
    mesh or a triangle mesh by its vertices (the convex hull). Anything else is refused."""
    import coal

    from ..errors import ConfigurationError

    o = robot.collision_model.geometryObjects[g]
    # the placement is in the parent joint's frame; the points are returned in the parent frame
    geo, M = o.geometry, robot.model.frames[o.parentFrame].placement.inverse() * o.placement
    if isinstance(geo, coal.Cylinder):
        V, r = np.array([[0, 0, -geo.halfLength], [0, 0, geo.halfLength]]).T, float(geo.radius)
    elif isinstance(geo, coal.Convex):
        V, r = np.asarray(geo.points(), float).reshape(-1, 3).T, 0.0
    elif hasattr(geo, "num_vertices") and geo.num_vertices > 0:
        V, r = np.array([np.asarray(geo.vertex(i), float) for i in range(geo.num_vertices)]).T, 0.0
    else:
        raise ConfigurationError(f"collision geometry {o.name!r} ({type(geo).__name__}): the trajectory NLP "
                                 "handles capsules, spheres, boxes, cylinders and meshes only")
    return o.parentFrame, M.rotation @ V + M.translation[:, None], r


