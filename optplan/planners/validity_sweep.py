"""The edge checks of :class:`~optplan.planners.validity.ValidityChecker`: per-joint sweep bounds of the checked
geometry, the compiled speed profiles that space an edge's checkpoints (:meth:`EdgeSweepMixin.edge_checkpoints`),
the edge test itself and the certified edges of :mod:`optplan.planners.edge_certify`.

:class:`EdgeSweepMixin` holds these methods of the checker; it uses the checker's models, modes, exemptions
and configuration checks.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

from ..collision.sweep import sweep_weights
from ..model.robot import RobotModel
from .bisection import _bisection_indices, _bisection_order
from .edge_certify import EdgeCertifier

if TYPE_CHECKING:
    from ..codegen import FastFunction
    from .kernel.checker import NativeValidity

__all__ = ["EdgeSweepMixin"]
#: compiled speed profiles shared by the checkers of one process (key: robot model, mode, geometry bounds)
_PROFILE_CACHE: dict[tuple[Any, ...], tuple[Any, FastFunction | None]] = {}


class EdgeSweepMixin:
    """The edge-check methods of :class:`~optplan.planners.validity.ValidityChecker` (the attributes below are
    the checker's)."""

    robot: RobotModel
    model: Any
    gmodel: Any
    object: Any
    fixed_id: int | None
    held_id: int | None
    n_checks: int
    _gd: dict[str, Any]
    _pool: dict[str, Any]
    _native: NativeValidity | None
    _profile_fns: dict[Any, FastFunction | None]
    _revolute_only: bool
    _spheres: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]
    _sweep: dict[str, np.ndarray]
    _certifiers: dict[float, EdgeCertifier]
    exempted: Callable[..., frozenset[int]]
    first_invalid: Callable[..., int]
    is_valid: Callable[[np.ndarray], bool]
    is_valid_free: Callable[[np.ndarray], bool]
    is_valid_object_fixed: Callable[[np.ndarray, pin.SE3], bool]

    def _sweep_bound(self, mode: str) -> np.ndarray:
        """One row per moving geometry of ``mode`` (:meth:`_moving_geometries`), one column per
        q index: :func:`optplan.collision.sweep.sweep_weights`."""
        return sweep_weights(self.model, self.gmodel)[self._moving_geometries(mode)]

    def _moving_geometries(self, mode: str) -> list[int]:
        """Geometry ids of the rows of :meth:`_sweep_bound` (same order)."""
        skip = {self.fixed_id}
        if mode != "held" and self.held_id is not None:
            skip.add(self.held_id)
        return [gid for gid, go in enumerate(self.gmodel.geometryObjects) if gid not in skip and go.parentJoint != 0]

    def _sweep_spheres(self, mode: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per row of :meth:`_sweep_bound`: (row index of its parent joint among the distinct parent
        joints, bounding-sphere centre in the parent joint's frame [m], radius [m]) and the distinct
        parent joint ids."""
        gids = self._moving_geometries(mode)
        joints = sorted({int(self.gmodel.geometryObjects[g].parentJoint) for g in gids})
        row = np.array([joints.index(int(self.gmodel.geometryObjects[g].parentJoint)) for g in gids], dtype=int)
        c = np.zeros((len(gids), 3))
        rad = np.zeros(len(gids))
        for k, g in enumerate(gids):
            go = self.gmodel.geometryObjects[g]
            go.geometry.computeLocalAABB()
            c[k] = go.placement.act(np.asarray(go.geometry.aabb_center))
            rad[k] = float(go.geometry.aabb_radius)
        return row, c, rad, np.array(joints, dtype=int)

    def _profile_function(self, mode: str) -> FastFunction | None:
        """Compiled ``(a, b) -> C``: ``C[i]`` [m] bounds the distance any point of the checked
        geometry travels along ``q(t) = a + t (b − a)`` for ``t ∈ [0, i/m]``, ``m =``
        :attr:`CELLS` (see :meth:`edge_checkpoints`). None when the robot has joints other than
        1-dof revolute ones."""
        return self._compiled_sweep(mode, "profile")

    def _cell_speed_function(self, mode: str) -> FastFunction | None:
        """Compiled ``(a, b) -> V`` (``V.reshape(G + P, m, order="F")``): ``V[g, i]`` [m per unit t]
        bounds the speed of every point of the g-th geometry of :meth:`_moving_geometries` on the cell
        ``[i/m, (i+1)/m]`` of ``q(t) = a + t (b − a)`` — the per-geometry terms whose maximum over g
        :meth:`_profile_function` integrates; ``V[G + p, i]`` bounds the speed of the held object's
        points relative to the other geometry of the p-th pair of :meth:`_relative_pairs` (how fast
        the pair can approach). None as there."""
        return self._compiled_sweep(mode, "cells")

    def _relative_pairs(self, mode: str) -> list[tuple[int, int]]:
        """``"held"`` mode: (row of the held object, row of a robot geometry) among
        :meth:`_moving_geometries` for every active pair of the two (the rows after the per-geometry
        ones in :meth:`_cell_speed_function`: their relative speed, which the closed chain keeps small).
        Empty in the other modes."""
        if mode != "held" or self.held_id is None:
            return []
        gids = self._moving_geometries(mode)
        row_of = {gid: r for r, gid in enumerate(gids)}
        gd, off = self._gd[mode], self.exempted(mode)   # exempted pairs keep their rows (the compiled rows do not change)
        out = []
        for k, cp in enumerate(self.gmodel.collisionPairs):
            if not (gd.activeCollisionPairs[k] or k in off) or self.held_id not in (cp.first, cp.second):
                continue
            other = cp.second if cp.first == self.held_id else cp.first
            if other in row_of:
                out.append((row_of[self.held_id], row_of[other]))
        return out

    def _compiled_sweep(self, mode: str, what: str) -> FastFunction | None:
        key_fn = mode if what == "profile" else (mode, what)
        if key_fn in self._profile_fns:
            return self._profile_fns[key_fn]
        row, c, rad, joints = self._spheres[mode]
        W = self._sweep[mode]
        key = (id(self.model), mode, what, W.tobytes(), c.tobytes(), rad.tobytes(), row.tobytes(), joints.tobytes())
        if key in _PROFILE_CACHE:           # another checker of the same robot and held object
            self._profile_fns[key_fn] = _PROFILE_CACHE[key][1]
            return self._profile_fns[key_fn]
        fn = None
        if self._revolute_only:
            from ..codegen import FastFunction, memo_functions
            from ..model.digest import kinematics_digest

            rel = self._relative_pairs(mode) if what == "cells" else []
            memo_key = (kinematics_digest(self.robot), mode, what, self.CELLS, tuple(rel), *key[3:])
            fn = FastFunction.of(memo_functions("sweep", memo_key, lambda: self._sweep_functions(mode, what, rel)),
                                 what, "-O1")
        self._profile_fns[key_fn] = fn
        _PROFILE_CACHE[key] = (self.model, fn)     # the model is kept alive so that its id stays unique
        return fn

    def _sweep_functions(self, mode: str, what: str, rel: list[tuple[int, int]]) -> dict[str, Any]:
        """The symbolic function of :meth:`_compiled_sweep` (``{what: casadi.Function}``); ``rel``:
        :meth:`_relative_pairs` for ``"cells"``, else empty."""
        import casadi as ca

        from ..model.symbolic import SymbolicKinematics

        row, c, rad, joints = self._spheres[mode]
        W = self._sweep[mode]
        sk = SymbolicKinematics(self.robot)
        n, m, G = self.model.nq, self.CELLS, W.shape[0]
        q, d = ca.SX.sym("q", n), ca.SX.sym("d", n)
        X = sk.joint_placements(q)
        twist = {}
        for j in joints:                       # spatial velocity (ω, v at the world origin) of each body
            w, v = ca.SX.zeros(3), ca.SX.zeros(3)
            for k in sk._support(int(j)):
                for vi, wk, vk in sk._columns(k, X):
                    w, v = w + wk * d[vi], v + vk * d[vi]
            twist[int(j)] = (w, v)
        speed, centre = [], []
        for g in range(G):                     # |v_c| + |ω| ρ of each bounding sphere
            j = int(joints[row[g]])
            R, p = X[j]
            w, v = twist[j]
            centre.append(R @ ca.DM(c[g]) + p)
            speed.append(ca.norm_2(v + ca.cross(w, centre[g])) + ca.norm_2(w) * float(rad[g]))
        rel_speed, rel_gap = [], []
        for gO, gL in rel:                     # the speed of gO's sphere in gL's frame; centre distance
            (wO, vO), (wL, vL) = twist[int(joints[row[gO]])], twist[int(joints[row[gL]])]
            dw = wO - wL
            rel_speed.append(ca.norm_2(vO - vL + ca.cross(dw, centre[gO])) + ca.norm_2(dw) * float(rad[gO]))
            rel_gap.append(ca.norm_2(centre[gO] - centre[gL]))
        f1 = ca.Function("sweep_speed", [q, d], [ca.vertcat(*speed, *rel_speed, *rel_gap)])
        a, b = ca.SX.sym("a", n), ca.SX.sym("b", n)
        dd = b - a
        Q = ca.horzcat(*[a + (i / m) * dd for i in range(m + 1)])
        SS = f1.map(m + 1)(Q, ca.repmat(dd, 1, m + 1))         # speeds (and pair terms) at the cell ends
        S = SS[:G, :]                                           # G × (m+1): speed at the cell ends
        D = ca.fabs(dd)
        r2: Any = []
        static: Any = []
        accs, anc_sum, anc_pairs = [], [], []
        for g in range(G):                     # rate of change of the speed bound; configuration-free bound
            anc = [k for k in range(n) if W[g, k] > 0.0]
            acc: Any = 0
            before: Any = 0
            pairs: Any = 0
            for k in anc:
                acc = acc + W[g, k] * D[k] * (D[k] + 2 * before)
                pairs = pairs + D[k] * before
                before = before + D[k]
            r2.append(acc + float(rad[g]) * pairs)
            static.append(ca.dot(ca.DM(W[g]), D))
            accs.append(acc)
            anc_sum.append(before)
            anc_pairs.append(pairs)
        r2, static = ca.vertcat(*r2), ca.vertcat(*static)
        # per cell i and geometry g: the speed bound min(static, (s_i + s_i+1 + r/m)/2)
        cells = [ca.fmin(static, 0.5 * (S[:, i] + S[:, i + 1] + r2 / m)) for i in range(m)]
        if rel:
            # relative speed of gO's points in gL's frame, u = ẋ_O(x) − (v_L + ω_L × x), bounded by
            # |u(c_O)| + |ω_O − ω_L| ρ_O. Its rate of change: d/dt (v_L + ω_L × c_O) = ÿ − ω_L × ẏ + ω_L × ċ_O
            # with y the point of gL's body at c_O, so ≤ |ẍ_O(c_O)| + |ÿ| + |ω_L| (|ẏ| + |ċ_O|)
            # + ρ_O (|ω̇_O| + |ω̇_L|); |ÿ| ≤ Σ_jk |d_j||d_k| dist(c_O, axis_max(j,k)) and |ẏ| ≤ Σ_j |d_j|
            # dist(c_O, axis_j) over gL's joints, with dist(c_O, axis_j) ≤ |c_O − c_L| + W_L[j]
            # (|c_O − c_L| bounded on a cell by its values at the cell ends and the centres' speeds)
            P = len(rel)
            RS, RG = SS[G:G + P, :], SS[G + P:G + 2 * P, :]
            for i in range(m):
                col = []
                for p_, (gO, gL) in enumerate(rel):
                    vmax = static[gO] + static[gL]
                    gap = 0.5 * (RG[p_, i] + RG[p_, i + 1] + vmax / m)
                    rr = (accs[gO] + accs[gL] + gap * anc_sum[gL] ** 2
                          + anc_sum[gL] * (static[gO] + static[gL] + gap * anc_sum[gL])
                          + float(rad[gO]) * (anc_pairs[gO] + anc_pairs[gL]))
                    col.append(ca.fmin(vmax, 0.5 * (RS[p_, i] + RS[p_, i + 1] + rr / m)))
                cells[i] = ca.vertcat(cells[i], *col)
        if what == "profile":
            cum: list[Any] = [ca.SX(0.0)]
            for i in range(m):                 # ∫ over cell i of max_g of the cell's bound
                cum.append(cum[-1] + ca.mmax(cells[i]) / m)
            return {what: ca.Function(f"sweep_profile_{mode}", [a, b], [ca.vertcat(*cum)])}
        return {what: ca.Function(f"sweep_cells_{mode}", [a, b], [ca.vertcat(*cells)])}

    def prepare_edge_checks(self, modes: tuple[str, ...] = ("held", "fixed")) -> None:
        """Build (or load from the compile cache) the compiled speed profiles of
        :meth:`edge_checkpoints` now rather than at the first edge check (a planner calls this
        before its time limit starts; the first build compiles C code, seconds)."""
        for mode in modes:
            if mode not in self._sweep:
                raise ValueError(f"prepare_edge_checks: mode must be one of {tuple(self._sweep)}, got {mode!r}")
            self._profile_function(mode)

    def edge_checkpoints(self, a: np.ndarray, b: np.ndarray, tolerance: float, mode: str = "held") -> np.ndarray:
        """Interior parameters ``0 < t_1 < … < t_m < 1`` of the straight joint segment
        ``q(t) = a + t (b − a)`` such that no point of the checked geometry (``mode`` as in
        :meth:`sweep_weights`) travels farther than ``tolerance`` [m] between consecutive ones
        (``t_0 = 0``, ``t_{m+1} = 1``); ``a`` and ``b`` are full configurations.

        Conservative bound, per geometry g (bounding sphere of centre c and radius ρ on body i):
        a point x of g moves at speed ``|ẋ| ≤ s(t) = |v_c| + |ω| ρ`` with ``(v_c, ω)`` the twist of
        body i for the joint velocity ``d = b − a``. ``s`` is evaluated exactly (Jacobian) at the
        ends of :attr:`CELLS` equal cells of [0, 1], so joint motions that cancel — an arm's
        self-motion — count as they are; in between it changes at most at the rate
        ``r = Σ_{j,k} |d_j||d_k| W_{max(j,k)} + ρ Σ_{j<k} |d_j||d_k|`` (j, k over the revolute joints
        that move g, ordered base to tip; ``|∂²x/∂q_j∂q_k| ≤ |x − o_{max(j,k)}| ≤ W_{max(j,k)}``, the
        per-geometry weight of :meth:`sweep_weights`, and ``|dω/dt| ≤ Σ_{j<k} |d_j||d_k|``). On a
        cell ``[t_i, t_i + h]`` both ``s ≤ s(t_i) + (t − t_i) r`` and ``s ≤ s(t_i + h) + (t_i + h − t) r``
        hold, so ``s ≤ (s(t_i) + s(t_i + h) + h r) / 2``, and ``s ≤ W·|d|`` (configuration-free).
        The maximum over g of the smaller is integrated over the cells (compiled, one call per edge)
        and a checkpoint placed every ``tolerance`` of the integral.

        Robots with joints other than 1-dof revolute, and edges short enough that the
        configuration-free bound needs at most 4 interior checks, get uniform checkpoints
        ``⌈max_g W_g·|d| / tolerance⌉`` (the configuration-free bound alone)."""
        a = np.asarray(a, float)
        b = np.asarray(b, float)
        W = self._sweep[mode]
        static = W @ np.abs(b - a)                          # [m] per unit t, per geometry
        smax = float(static.max()) if static.size else 0.0
        n_static = int(math.ceil(smax / tolerance)) if smax > 0 else 1
        if n_static <= 5 or (fn := self._profile_function(mode)) is None:
            return np.arange(1, n_static) / n_static
        C = fn(a, b)
        n = max(1, int(math.ceil(C[-1] / tolerance)))
        if n >= n_static:
            return np.arange(1, n_static) / n_static
        return np.interp(np.arange(1, n) * tolerance, C, np.linspace(0.0, 1.0, C.size))

    #: cells of [0, 1] on which :meth:`edge_checkpoints` bounds the speed by a constant
    CELLS = 8

    def edge_is_valid(self, a: np.ndarray, b: np.ndarray, tolerance: float, mode: str = "held",
                      object_pose: pin.SE3 | None = None, check_end: bool = False, expect_free: bool = False) -> bool:
        """The straight joint segment ``a → b`` collision-free at the checkpoints of
        :meth:`edge_checkpoints` (no point of the checked geometry travels farther than ``tolerance``
        [m] between two checks), checked coarse-to-fine; ``a`` itself is not checked, ``b`` only with
        ``check_end``. ``mode``: ``"held"`` (:meth:`is_valid`), ``"fixed"``
        (:meth:`is_valid_object_fixed` at ``object_pose``) or ``"free"``. ``expect_free``: for an edge
        expected to pass (a found path's re-check), the native kernel checks the points in order and proves
        most of them free by the pairs' clearance at a checked one
        (:meth:`~optplan.planners.kernel.native.NativeKernel.edge_first_invalid_skip`); the same verdict."""
        fn: Callable[[np.ndarray], bool]
        if mode == "held":
            fn = self.is_valid if self.object is not None else self.is_valid_free
        elif mode == "fixed":
            if object_pose is None:
                raise ValueError("edge_is_valid: mode 'fixed' needs object_pose")
            fn = lambda x: self.is_valid_object_fixed(x, object_pose)   # noqa: E731
        elif mode == "free":
            fn = self.is_valid_free
        else:
            raise ValueError(f"edge_is_valid: mode must be 'held', 'fixed' or 'free', got {mode!r}")
        a = np.asarray(a, float)
        b = np.asarray(b, float)
        if check_end and not fn(b):
            return False
        ts = self.edge_checkpoints(a, b, tolerance, mode)
        d = b - a
        if self._native is not None:   # interpolation and checks in one native call, same order
            if not len(ts):
                return True
            m = "free" if mode == "held" and self.object is None else mode
            if expect_free:   # in order, most points proven free by the clearance at a checked one
                k, checked = self._native.edge_first_invalid_skip(a, b, ts, m, object_pose)
                self.n_checks += checked
                return k < 0
            k = self._native.edge_first_invalid(a, b, ts[_bisection_indices(len(ts) + 1)], m, object_pose)
            self.n_checks += len(ts) if k < 0 else k + 1
            return k < 0
        if self._pool:   # the same points in the same order, one batch call
            if not len(ts):
                return True
            return self.first_invalid(a + ts[_bisection_indices(len(ts) + 1)][:, None] * d, mode, object_pose) < 0
        for k in _bisection_order(len(ts) + 1):
            if not fn(a + ts[k - 1] * d):
                return False
        return True

    def uniform_edge_is_valid(self, a: np.ndarray, b: np.ndarray, tolerance: float, weights: np.ndarray,
                              mode: str = "held", object_pose: pin.SE3 | None = None) -> bool:
        """The interior points ``a + (k/n)(b − a)``, ``k = 1 … n−1``, ``n = ⌈max(weights @ |b − a|) / tolerance⌉``,
        all collision-free: the same points, hence the same verdict, as :func:`optplan.planners.rrtconnect.edge_is_valid`
        with ``weights`` (e.g. :meth:`sweep_weights` per geometry) and ``check_end=False``. With the native kernel
        the points are checked in index order, interpolated in one native call (no coarse-to-fine order to build:
        for edges that are expected to pass, as a found path's re-check, the order changes nothing but the cost),
        and most of them are proven free by the pairs' clearance at a checked point and the sweep weights of the
        kernel's primitives, not checked (:meth:`~optplan.planners.kernel.native.NativeKernel.edge_first_invalid_skip`:
        the same verdict; ``n_checks`` counts the points checked)."""
        a = np.asarray(a, float)
        b = np.asarray(b, float)
        size = float(np.max(weights @ np.abs(b - a)))
        n = max(1, int(math.ceil(size / tolerance)))
        if n < 2:
            return True
        if self._native is None or (mode == "fixed" and (object_pose is None or self.object is None)):
            return self.first_invalid(a + (np.arange(1, n) / n)[:, None] * (b - a), mode, object_pose) < 0
        m = "free" if mode == "held" and self.object is None else mode
        k, checked = self._native.uniform_edge_first_invalid(a, b, n, m, object_pose)
        self.n_checks += checked
        return k < 0

    def certifier(self, min_clearance: float = 1e-3) -> EdgeCertifier:
        """The :class:`~optplan.planners.edge_certify.EdgeCertifier` of this checker for
        ``min_clearance`` [m] (built once per value; shares the geometry and the pair set)."""
        key = float(min_clearance)
        if key not in self._certifiers:
            self._certifiers[key] = EdgeCertifier(self, key)
        return self._certifiers[key]

    def edge_is_certified(self, a: np.ndarray, b: np.ndarray, mode: str = "held", object_pose: pin.SE3 | None = None,
                          min_clearance: float = 1e-3, cache: bool = False) -> bool:
        """The straight joint segment ``a → b`` (ends included) CERTIFIED collision-free by
        conservative advancement on exact distances (:mod:`optplan.planners.edge_certify`): no pair
        closer than ``min_clearance / 2`` [m] (+ ``margin``) at any point of it. Unlike
        :meth:`edge_is_valid` no fixed check spacing is involved. ``mode`` as in :meth:`edge_is_valid`;
        ``cache``: the certifier's vertex cache (:meth:`.EdgeCertifier.path`)."""
        return self.certifier(min_clearance).segment(a, b, mode, object_pose, cache)

    def path_is_certified(self, Q: np.ndarray, mode: str = "held", object_pose: pin.SE3 | None = None,
                          min_clearance: float = 1e-3) -> bool:
        """:meth:`edge_is_certified` for the piecewise-linear joint path through the rows of ``Q``."""
        return self.certifier(min_clearance).path(Q, mode, object_pose)

    def sweep_weights(self, mode: str = "held", per_geometry: bool = False) -> np.ndarray:
        """Per-joint bound [m/rad] on the displacement of any checked point (see the module
        docstring); ``mode``: ``"held"`` (robot + held object), ``"fixed"`` / ``"free"`` (robot only).
        With ``per_geometry`` one row per moving geometry (a point of geometry g moves at most
        ``W[g] @ |Δq|``, a tighter bound than the per-joint maximum over all geometries)."""
        if mode not in self._sweep:
            raise ValueError(f"sweep_weights: mode must be 'held', 'fixed' or 'free', got {mode!r}")
        W = self._sweep[mode]
        return W.copy() if per_geometry else W.max(axis=0)

    # ------------------------------------------------------------------ queries
