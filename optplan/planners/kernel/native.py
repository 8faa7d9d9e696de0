"""The compiled planning kernel: a batch of configurations (or an edge's checkpoints) → validity,
in one native call.

:class:`NativeKernel` takes a Pinocchio model (1-dof revolute and prismatic joints), a Pinocchio
``GeometryModel`` and a list of geometry pairs, and flattens them into arrays that the C code of
:mod:`optplan.planners.kernel.csource` reads: per joint its parent, placement and axis; per geometry
its parent joint, placement and primitive. Primitives: coal ``Sphere``, ``Capsule``, ``Box`` as
they are (exact tests: sphere/capsule pairs by point/segment distances, capsule-box by the segment's
distance to the box, box-box by separating axes); a ``Cylinder`` as the capsule that contains it. A
model with any other shape (meshes, convex hulls, ellipsoids ...) raises :class:`KernelUnavailable`
and its checks stay with coal: a bounding sphere would call a mesh robot's tight but valid start
configurations colliding (PR2's). A pair counts as colliding when its distance is at most ``margin`` +
:data:`~optplan.planners.kernel.csource.KERNEL_EPS`: the kernel never calls free a configuration that
coal calls colliding, coal's GJK tolerance (1e-6 m) included (the false "colliding" verdicts are limited to
cylinders and a 1e-5 m band).

The library is compiled with the system C compiler at first use and cached (:func:`load_library`);
without a compiler :class:`KernelUnavailable` is raised and the validity checker keeps coal.
"""
from __future__ import annotations

import ctypes
import hashlib
import logging
import tempfile
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from ...codegen import build_library, build_tag, cache_dir
from ...errors import OptplanError
from .clearance_csource import CLEARANCE_SOURCE
from .csource import C_SOURCE, KERNEL_EPS

__all__ = ["KernelUnavailable", "NativeKernel", "load_library", "primitive_sweep_weights"]
log = logging.getLogger(__name__)

_LIB: list[Any] = []   # the loaded library of this process (one)
#: the C source of this library: the checks, and the uniform edge check with safe steps
SOURCE = C_SOURCE + CLEARANCE_SOURCE
_P = ctypes.c_void_p


class KernelUnavailable(OptplanError):
    """The native kernel cannot be used here: no C compiler, a failed build, or a model the kernel
    does not cover (a joint other than a 1-dof revolute or prismatic one)."""


class _KModel(ctypes.Structure):
    _fields_ = [("nq", ctypes.c_int), ("nj", ctypes.c_int), ("ng", ctypes.c_int), ("npairs", ctypes.c_int),
                ("jparent", _P), ("jtype", _P), ("jidx", _P), ("jplace", _P), ("jaxis", _P),
                ("gparent", _P), ("gtype", _P), ("gplace", _P), ("gparam", _P), ("grad", _P),
                ("pa", _P), ("pb", _P), ("margin", ctypes.c_double),
                ("nmov", ctypes.c_int), ("nstat", ctypes.c_int), ("ngrp", ctypes.c_int), ("nrest", ctypes.c_int),
                ("mov", _P), ("grp", _P), ("saabb", _P), ("ms_pair", _P), ("rest", _P), ("hint", _P),
                ("nbuck", ctypes.c_int), ("bstart", _P), ("bga", _P), ("bgb", _P), ("bperm", _P), ("mrow", _P),
                ("jperm", _P), ("scol", _P)]


def _signed_permutation(R: np.ndarray, tol: float = 1e-12) -> np.ndarray:
    """(3,) int32: for each column c of the rotation ``R``, ±(1 + the row of its ±1 entry) when ``R`` is a
    signed permutation (entries within ``tol`` of 0 and ±1: URDF placements turned by right angles), else
    zeros."""
    out = np.zeros(3, np.int32)
    A = np.abs(R)
    if not (np.all((A < tol) | (np.abs(A - 1.0) < tol)) and np.all(np.sum(A > 0.5, axis=0) == 1)):
        return out
    for c in range(3):
        r = int(np.argmax(A[:, c]))
        out[c] = (r + 1) * (1 if R[r, c] > 0 else -1)
    return out


#: most moving geometries in one group of the broad phase (consecutive links of a chain share one
#: bounding box, tested against every obstacle's before the links' own boxes)
BROAD_GROUP_SIZE = 4


def _aabb(gtype: int, prm: np.ndarray, P: np.ndarray) -> np.ndarray:
    """World axis-aligned box (lo[3], hi[3]) [m] of a primitive at the pose ``P`` (12 values)."""
    R, p = P[:9].reshape(3, 3), P[9:]
    if gtype == 0:
        e = np.full(3, prm[0])
    elif gtype == 1:
        e = prm[0] + prm[1] * np.abs(R[:, 2])
    else:
        e = np.abs(R) @ prm
    return np.concatenate([p - e, p + e])


def broad_phase_arrays(jparent: np.ndarray, gparent: np.ndarray, gtype: np.ndarray, gplace: np.ndarray,
                       gparam: np.ndarray, pairs: list[tuple[int, int]], threshold: float,
                       group_size: int = BROAD_GROUP_SIZE) -> dict[str, np.ndarray]:
    """The kernel's broad-phase arrays (see ``kmodel`` in :mod:`~optplan.planners.kernel.csource`):
    the moving geometries (parent joint ≠ 0) in groups of at most ``group_size`` consecutive links of
    one chain, the static geometries' world boxes inflated by ``threshold`` [m] (margin + slack), the
    pair index of each (moving, static) couple and the remaining pairs in their order."""
    ng = len(gparent)
    mov_all = sorted((g for g in range(ng) if gparent[g] != 0), key=lambda g: (int(gparent[g]), g))
    stat = sorted({g for a, b in pairs for g in (a, b) if gparent[g] == 0
                   and gparent[b if g == a else a] != 0})
    grp = [0]
    for i in range(1, len(mov_all)):   # a new group when the chain breaks or the group is full
        j, jp = int(gparent[mov_all[i]]), int(gparent[mov_all[i - 1]])
        if (j != jp and jparent[j] != jp) or i - grp[-1] >= group_size:
            grp.append(i)
    grp.append(len(mov_all))
    col = {g: j for j, g in enumerate(stat)}
    row = {g: i for i, g in enumerate(mov_all)}
    group = np.zeros(len(mov_all), np.int32)
    for gi in range(len(grp) - 1):
        group[grp[gi]:grp[gi + 1]] = gi
    ms = -np.ones((len(mov_all), len(stat)), np.int32)
    rest: list[int] = []
    buckets: dict[tuple[int, int], list[int]] = {}
    for k, (a, b) in enumerate(pairs):
        m_, s_ = (a, b) if gparent[b] == 0 else (b, a)
        if gparent[m_] != 0 and gparent[s_] == 0 and ms[row[m_], col[s_]] < 0:
            ms[row[m_], col[s_]] = k
        elif gparent[a] != 0 and gparent[b] != 0:
            ga, gb = sorted((int(group[row[a]]), int(group[row[b]])))
            buckets.setdefault((ga, gb), []).append(k)
        else:
            rest.append(k)
    keys = sorted(buckets)
    mrow = -np.ones(ng, np.int32)
    for g, i in row.items():
        mrow[g] = i
    scol = -np.ones(ng, np.int32)   # a static geometry's column (the still object's box is made per call)
    for g, j in col.items():
        scol[g] = j
    box = np.array([_aabb(int(gtype[g]), gparam[g], gplace[g]) for g in stat]).reshape(-1, 6)
    box[:, :3] -= threshold + 1e-12
    box[:, 3:] += threshold + 1e-12
    return {"mov": np.array(mov_all, np.int32), "grp": np.array(grp if mov_all else [0], np.int32),
            "saabb": np.ascontiguousarray(box.T), "ms_pair": np.ascontiguousarray(ms),
            "rest": np.array(rest, np.int32),
            "bstart": np.cumsum([0] + [len(buckets[k]) for k in keys]).astype(np.int32),
            "bga": np.array([k[0] for k in keys], np.int32), "bgb": np.array([k[1] for k in keys], np.int32),
            "bperm": np.array([p for k in keys for p in buckets[k]], np.int32), "mrow": mrow, "scol": scol}


def primitive_sweep_weights(jparent: np.ndarray, jidx: np.ndarray, jplace: np.ndarray, gparent: np.ndarray,
                            gplace: np.ndarray, grad: np.ndarray, pa: np.ndarray, pb: np.ndarray,
                            nq: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-joint displacement bounds [m/rad] of the kernel's primitives (revolute joints): ``Wg`` (geometries
    × nq), as :func:`optplan.collision.sweep.sweep_weights` but with each primitive's own bounding radius
    (a cylinder's capsule is longer than the cylinder), so that between any two configurations no point
    of primitive g moves farther than ``Wg[g] @ |q' − q|``; and ``Wp`` (pairs × nq): ``Wg[a] + Wg[b]``
    without the joints that carry both geometries (they move the pair rigidly), a bound on how fast the
    pair's distance changes."""
    ng = len(gparent)
    wg = np.zeros((ng, nq))
    chains: list[set[int]] = []
    for g in range(ng):
        j = int(gparent[g])
        chain: set[int] = set()
        length = float(np.linalg.norm(gplace[g, 9:])) + float(grad[g])
        while j > 0:
            wg[g, jidx[j]] = length
            chain.add(j)
            length += float(np.linalg.norm(jplace[j, 9:]))
            j = int(jparent[j])
        chains.append(chain)
    wp = np.zeros((len(pa), nq))
    for k, (a, b) in enumerate(zip(pa, pb)):
        wp[k] = wg[a] + wg[b]
        for j in chains[a] & chains[b]:
            wp[k, jidx[j]] = 0.0
    return np.ascontiguousarray(wg), np.ascontiguousarray(wp)


def load_library() -> Any:
    """The compiled kernel (``ctypes.CDLL``), built with the system C compiler at first use and cached
    under :func:`optplan.codegen.cache_dir` by a hash of its source. Raises :class:`KernelUnavailable`
    when it cannot be built."""
    if _LIB:
        return _LIB[0]
    source = SOURCE
    digest = hashlib.sha1(source.encode()).hexdigest()[:16] + "_" + build_tag()
    lib_path = cache_dir() / f"optplan_planning_kernel_{digest}.so"
    lib = None
    for attempt in range(2):
        if not lib_path.exists():
            with tempfile.TemporaryDirectory() as tmp:
                c_file = Path(tmp, "planning_kernel.c")
                c_file.write_text(source)
                err = build_library(c_file, lib_path, "-O3", native=True)
            if err is not None:
                raise KernelUnavailable(f"the native planning kernel could not be compiled: {err}")
        try:
            lib = ctypes.CDLL(str(lib_path))
            break
        except OSError as e:   # a damaged cache file: rebuilt once
            if attempt:
                raise KernelUnavailable(f"the native planning kernel {lib_path} cannot be loaded: {e}") from None
            log.warning("the cached planning kernel %s cannot be loaded (%s); rebuilding it", lib_path, e)
            lib_path.unlink(missing_ok=True)
    assert lib is not None
    for name in ("kernel_first_invalid", "kernel_edge_first_invalid"):
        getattr(lib, name).restype = ctypes.c_longlong
    lib.kernel_first_invalid.argtypes = [_P, _P, _P, ctypes.c_int, ctypes.c_longlong, _P, _P]
    lib.kernel_edge_first_invalid.argtypes = [_P, _P, _P, ctypes.c_int, _P, _P, ctypes.c_longlong, _P]
    lib.kernel_edge_first_invalid_skip.restype = ctypes.c_longlong
    lib.kernel_edge_first_invalid_skip.argtypes = [_P, _P, _P, ctypes.c_int, _P, _P, ctypes.c_longlong, _P, _P, _P, _P]
    lib.kernel_pair_slacks.restype = None
    lib.kernel_pair_slacks.argtypes = [_P, _P, _P, ctypes.c_int, _P]
    lib.kernel_placements.restype = None
    lib.kernel_placements.argtypes = [_P, _P, _P, ctypes.c_int, _P]
    _LIB.append(lib)
    return lib


def pose12(R: Any, p: Any) -> np.ndarray:
    """A placement (rotation ``R``, position ``p`` [m]) as the 12 values of the native code: the rotation
    row-major, then the position."""
    out = np.empty(12)
    out[:9] = np.asarray(R, float).reshape(9)
    out[9:] = p
    return out


def se3_pose12(M: pin.SE3) -> np.ndarray:
    """A ``pin.SE3`` as :func:`pose12`'s 12 values."""
    return pose12(M.rotation, M.translation)


def _joint_kind(jm: Any) -> tuple[int, np.ndarray]:
    """(1 revolute about an unaligned axis / 2 prismatic / 3, 4, 5 revolute about x, y, z; unit axis)
    of a Pinocchio joint model."""
    name = jm.shortname()
    for prefix, kind in (("JointModelR", 1), ("JointModelP", 2)):
        if name.startswith(prefix) and jm.nq == 1 and jm.nv == 1:
            tail = name[len(prefix):]
            if tail in ("X", "Y", "Z"):
                axis = "XYZ".index(tail)
                return (kind if kind == 2 else 3 + axis), np.eye(3)[axis]
            if tail in ("evoluteUnaligned", "rismaticUnaligned"):
                ax = np.asarray(jm.axis, float)
                return kind, ax / np.linalg.norm(ax)
    raise KernelUnavailable(f"the native planning kernel covers 1-dof revolute and prismatic joints, got {name}")


def _primitive(go: Any) -> tuple[int, np.ndarray, pin.SE3, float]:
    """(type 0 sphere / 1 capsule / 2 box, parameters, offset in the geometry frame, bounding radius
    about the offset) of a geometry object; a cylinder becomes the capsule that contains it. Other shapes
    raise :class:`KernelUnavailable` (their checks stay with coal)."""
    g = go.geometry
    if isinstance(g, coal.Sphere):
        return 0, np.array([g.radius, 0.0, 0.0]), pin.SE3.Identity(), float(g.radius)
    if isinstance(g, (coal.Capsule, coal.Cylinder)):   # a cylinder lies inside the capsule of its radius and axis
        return 1, np.array([g.radius, g.halfLength, 0.0]), pin.SE3.Identity(), float(g.radius + g.halfLength)
    if isinstance(g, coal.Box):
        h = np.asarray(g.halfSide, float)
        return 2, h.copy(), pin.SE3.Identity(), float(np.linalg.norm(h))
    raise KernelUnavailable(f"the native planning kernel covers spheres, capsules, cylinders and boxes; "
                            f"geometry {go.name!r} is a {type(g).__name__}")


class NativeKernel:
    """Batched validity of configurations of ``model`` for the pairs ``pairs`` of ``gmodel``'s
    geometries (indices into ``gmodel.geometryObjects``; checked in this order), distance threshold
    ``margin`` [m]. Each query takes ``active`` (one uint8 per pair: 0 skips it) and optionally the
    world placement of one geometry (``override``: its index and pose), e.g. a still object.

    ``broad_phase`` (default True): a query (also one whose override places a static geometry, as the
    still object of the ``"fixed"`` mode: that geometry's box is then made from the placement per call) first compares axis-aligned boxes —
    chains of a few links against every static geometry, then each link, and the pairs of two moving
    geometries bucket by bucket of their chains — and runs the exact test only where they overlap; the
    pair that collided last is tried first. The verdicts are those of the plain pair loop (False).

    Raises :class:`KernelUnavailable` when the model has other joints or no C compiler is found."""

    def __init__(self, model: pin.Model, gmodel: pin.GeometryModel, pairs: list[tuple[int, int]], *,
                 margin: float = 0.0, broad_phase: bool = True) -> None:
        self.lib = load_library()
        nj = model.njoints
        jparent = np.zeros(nj, np.int32)
        jtype = np.zeros(nj, np.int32)
        jidx = np.zeros(nj, np.int32)
        jplace = np.zeros((nj, 12))
        jaxis = np.zeros((nj, 3))
        jplace[0] = se3_pose12(pin.SE3.Identity())
        for j in range(1, nj):
            kind, ax = _joint_kind(model.joints[j])
            jparent[j], jtype[j], jidx[j] = model.parents[j], kind, model.joints[j].idx_q
            jplace[j] = se3_pose12(model.jointPlacements[j])
            jaxis[j] = ax
        objs = list(gmodel.geometryObjects)
        ng = len(objs)
        gparent = np.zeros(ng, np.int32)
        gtype = np.zeros(ng, np.int32)
        gplace = np.zeros((ng, 12))
        gparam = np.zeros((ng, 3))
        grad = np.zeros(ng)
        self._offsets: list[pin.SE3] = []
        for g, go in enumerate(objs):
            t, prm, off, rad = _primitive(go)
            gparent[g], gtype[g], gparam[g], grad[g] = go.parentJoint, t, prm, rad
            gplace[g] = se3_pose12(go.placement * off)
            self._offsets.append(off)
        pa = np.array([a for a, _ in pairs], np.int32)
        pb = np.array([b for _, b in pairs], np.int32)
        if len(pairs) and (min(pa.min(), pb.min()) < 0 or max(pa.max(), pb.max()) >= ng):
            raise ValueError(f"NativeKernel: pair indices must lie in [0, {ng}), got {pairs!r}")
        if not (np.isfinite(margin) and margin >= 0.0):
            raise ValueError(f"margin: expected a number >= 0 m, got {margin!r}")
        self.nq, self.ng, self.n_pairs = int(model.nq), ng, len(pairs)
        self.types = gtype
        self._arrays = (jparent, jtype, jidx, jplace, jaxis, gparent, gtype, gplace, gparam, grad, pa, pb)
        ptr = [a.ctypes.data for a in self._arrays]
        bp = broad_phase_arrays(jparent, gparent, gtype, gplace, gparam, list(pairs), float(margin) + KERNEL_EPS)
        # the pair that collided last, shared by every call of this kernel (one thread at a time: a racing
        # write leaves some valid pair index, which only orders the tests, never changes a verdict)
        self._hint = np.full(1, -1, np.int32)
        self._broad = (bp["mov"], bp["grp"], bp["saabb"], bp["ms_pair"], bp["rest"], self._hint)
        jperm = np.array([_signed_permutation(jplace[j, :9].reshape(3, 3)) for j in range(nj)], np.int32).reshape(nj, 3)
        self._buckets = (bp["bstart"], bp["bga"], bp["bgb"], bp["bperm"], bp["mrow"], jperm, bp["scol"])
        nstat = bp["saabb"].shape[1] if bp["ms_pair"].size else 0
        self._km = _KModel(int(model.nq), nj, ng, len(pairs), *ptr, float(margin),
                           len(bp["mov"]), nstat, len(bp["grp"]) - 1 if broad_phase else 0, len(bp["rest"]),
                           *[a.ctypes.data for a in self._broad], len(bp["bga"]),
                           *[a.ctypes.data for a in self._buckets])
        self._km_p = ctypes.addressof(self._km)
        self._pose = np.zeros(12)
        self._pose_p = self._pose.ctypes.data
        self._q1 = np.zeros(max(self.nq, 1))            # one configuration, copied in (cached pointer)
        self._q1_p = self._q1.ctypes.data
        self._first = self.lib.kernel_first_invalid
        # the sweep weights of the kernel's own primitives, per geometry and per pair (uniform edges' safe steps);
        # None with a prismatic joint (its travel lengthens the arms above it: no configuration-free bound here)
        self._wg: np.ndarray | None = None
        self._wp: np.ndarray | None = None
        if not np.any(jtype == 2):
            self._wg, self._wp = primitive_sweep_weights(jparent, jidx, jplace, gparent, gplace, grad, pa, pb, int(model.nq))
        self._evaluated = np.zeros(1, np.int64)

    def all_active(self) -> np.ndarray:
        """An ``active`` mask with every pair on."""
        return np.ones(self.n_pairs, np.uint8)

    def _override(self, override: tuple[int, pin.SE3] | None) -> int:
        if override is None:
            return -1
        g, M = override
        self._pose[:] = se3_pose12(M * self._offsets[g])
        return int(g)

    def first_invalid(self, Q: np.ndarray, active: np.ndarray | int, override: tuple[int, pin.SE3] | None = None) -> int:
        """Index of the first row of ``Q`` (M × nq, C-contiguous float64) in collision, −1 if none.
        ``active``: the mask, or its data address (``mask.ctypes.data``, kept alive by the caller)."""
        Q = np.ascontiguousarray(Q, dtype=float)
        g = self._override(override)
        ap = active if isinstance(active, int) else active.ctypes.data
        return int(self._first(self._km_p, ap, self._pose_p, g, Q.shape[0], Q.ctypes.data, None))

    def collides(self, q: np.ndarray, active: np.ndarray | int, override: tuple[int, pin.SE3] | None = None) -> bool:
        """One configuration ``q`` (nq values) in collision (copied into a preallocated buffer: the
        cheapest single call)."""
        self._q1[:self.nq] = q
        g = -1 if override is None else self._override(override)
        ap = active if isinstance(active, int) else active.ctypes.data
        return self._first(self._km_p, ap, self._pose_p, g, 1, self._q1_p, None) >= 0

    def valid(self, Q: np.ndarray, active: np.ndarray, override: tuple[int, pin.SE3] | None = None) -> np.ndarray:
        """Boolean validity of EVERY row of ``Q`` (M × nq)."""
        Q = np.ascontiguousarray(Q, dtype=float)
        out = np.empty(Q.shape[0], np.uint8)
        g = self._override(override)
        self.lib.kernel_first_invalid(self._km_p, active.ctypes.data, self._pose_p, g, Q.shape[0], Q.ctypes.data,
                                      out.ctypes.data)
        return out.astype(bool)

    def edge_first_invalid(self, a: np.ndarray, b: np.ndarray, fractions: np.ndarray, active: np.ndarray,
                           override: tuple[int, pin.SE3] | None = None) -> int:
        """The points ``a + f (b − a)`` for ``f`` in ``fractions`` (in that order): index of the first in
        collision, −1 if none (one native call: interpolation and checks)."""
        a = np.ascontiguousarray(a, dtype=float)
        b = np.ascontiguousarray(b, dtype=float)
        f = np.ascontiguousarray(fractions, dtype=float)
        g = self._override(override)
        return int(self.lib.kernel_edge_first_invalid(self._km_p, active.ctypes.data, self._pose_p, g,
                                                      a.ctypes.data, b.ctypes.data, f.size, f.ctypes.data))

    def edge_first_invalid_skip(self, a: np.ndarray, b: np.ndarray, fractions: np.ndarray, active: np.ndarray,
                                override: tuple[int, pin.SE3] | None = None) -> tuple[int, int]:
        """The points ``a + f (b − a)`` for ``f`` in ``fractions`` (ascending), in order: ``(index of the first
        in collision or −1, points checked)``. The index is that of :meth:`edge_first_invalid`; most points are
        proven free by the pairs' clearance at a checked point and their sweep weights, and not checked
        (:mod:`~optplan.planners.kernel.clearance_csource`). A model with a prismatic joint checks every point."""
        f = np.ascontiguousarray(fractions, dtype=float)
        if f.size == 0:
            return -1, 0
        if self._wg is None or self._wp is None:
            k = self.edge_first_invalid(a, b, f, active, override)
            return k, (f.size if k < 0 else k + 1)
        a = np.ascontiguousarray(a, dtype=float)
        b = np.ascontiguousarray(b, dtype=float)
        g = self._override(override)
        k = int(self.lib.kernel_edge_first_invalid_skip(self._km_p, active.ctypes.data, self._pose_p, g,
                                                        a.ctypes.data, b.ctypes.data, f.size, f.ctypes.data,
                                                        self._wg.ctypes.data, self._wp.ctypes.data,
                                                        self._evaluated.ctypes.data))
        if k < -1:
            raise KernelUnavailable(f"the native planning kernel cannot hold this model ({self.nq} joints, {self.ng} geometries)")
        return k, int(self._evaluated[0])

    def uniform_edge_first_invalid(self, a: np.ndarray, b: np.ndarray, n: int, active: np.ndarray,
                                   override: tuple[int, pin.SE3] | None = None) -> tuple[int, int]:
        """:meth:`edge_first_invalid_skip` at the fractions ``k / n``, ``k = 1 … n − 1``."""
        if n < 2:
            return -1, 0
        return self.edge_first_invalid_skip(a, b, np.arange(1, n) / n, active, override)

    def pair_slacks(self, q: np.ndarray, override: tuple[int, pin.SE3] | None = None) -> np.ndarray:
        """Every pair's lower bound on its distance minus the contact threshold [m] at ``q`` (exact for
        sphere, capsule and capsule-box pairs; the separating-axis distance for box-box pairs), for tests."""
        q = np.ascontiguousarray(q, dtype=float)
        out = np.zeros(self.n_pairs)
        g = self._override(override)
        self.lib.kernel_pair_slacks(self._km_p, q.ctypes.data, self._pose_p, g, out.ctypes.data)
        return out

    def pose_free(self, g: int, R: np.ndarray, p: np.ndarray, active: np.ndarray | int) -> bool:
        """A model without joints (``nq = 0``): the geometry ``g`` placed at ``(R, p)`` (rotation [-],
        translation [m]; no offset: a sphere, capsule or box) free of every active pair."""
        pose = self._pose
        pose[:9] = R.reshape(9)
        pose[9:] = p
        ap = active if isinstance(active, int) else active.ctypes.data
        return self._first(self._km_p, ap, self._pose_p, g, 1, self._pose_p, None) < 0

    def placements(self, q: np.ndarray, override: tuple[int, pin.SE3] | None = None) -> np.ndarray:
        """World placements of the geometries' primitives at ``q`` (ng × 12: rotation row-major, then
        translation), for tests against Pinocchio's forward kinematics."""
        q = np.ascontiguousarray(q, dtype=float)
        out = np.zeros((self.ng, 12))
        g = self._override(override)
        self.lib.kernel_placements(self._km_p, q.ctypes.data, self._pose_p, g, out.ctypes.data)
        return out
