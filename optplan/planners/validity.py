"""Fast validity checking for the planners.

:class:`optplan.collision.CollisionChecker` loops over its pairs in Python (~0.5-1 ms per
configuration); the planners check tens of thousands of configurations per query. This checker
puts the robot's capsules, the scene's obstacles and the object into ONE Pinocchio
``GeometryModel`` and lets ``pinocchio.computeCollisions`` run the whole pair list in C++ (coal
narrow phase, stop at the first collision): ~20-60 µs per configuration.

The pair set is :class:`~optplan.collision.CollisionChecker`'s, from the same function
(:func:`optplan.collision.checker.scene_pairs`; a test checks that they agree on random
configurations):

* robot self-collision pairs (``robot.collision_pairs``),
* every moving robot geometry × every obstacle (the fixed base is not checked against the scene),
* the held object (rigidly attached to ``object_arm``'s hand) × obstacles and × robot geometries
  except the scene's ``exclude_links`` (the hands on the fixtures).

Three modes:

* ``is_valid(q)``: the object held by the hands (closed-chain motion),
* ``is_valid_object_fixed(q, object_pose)``: the object standing still at ``object_pose`` while
  the hands move (regrasp); here EVERY robot geometry is checked against the object (a released
  hand must not pass through it), except the pairs a regrasp exempts with :meth:`exempt` — those
  :meth:`grasp_contacts` finds at its ends: a hand geometry on one of the object's ``exclude_links``
  that touches the object at its grasp (the Panda's fingers straddle the box's face; the benchmark
  robot's hand links stay ≥ 0.1 m from it, so nothing is exempted there),
* ``is_valid_free(q)``: no object (plain joint-space planning).

:meth:`ValidityChecker.first_invalid` checks many configurations of one mode in order, stopping at the
first collision, in one call; :meth:`ValidityChecker.validity` wraps a mode (and optionally one arm
moving while the rest of the robot stands still) as a function with that batch form, which
:func:`optplan.planners.rrtconnect.edge_is_valid` uses for an edge's checkpoints.

``margin`` [m]: pairs closer than this count as colliding (coal's security margin).

:meth:`ValidityChecker.sweep_weights` gives, per joint, an upper bound [m/rad] on how far any point
of the checked geometry (robot links, and the held object in the ``"held"`` mode) moves per radian
of that joint, whatever the other joints: along a straight joint-space segment no point moves
farther than ``Σ_j w_j |Δq_j|``. Edge checks spaced by that bound
(:func:`optplan.planners.rrtconnect.edge_is_valid` with ``weights``) tie the check density to the
geometry instead of to a joint angle. :meth:`ValidityChecker.edge_is_certified` goes further: a
segment certified collision-free at every point by conservative advancement on exact distances
(:mod:`optplan.planners.edge_certify`).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import pinocchio as pin

from ..collision.checker import exact_contact_requests, pair_indices, scene_geometry, scene_pairs
from ..collision.sweep import sweep_weights
from ..model.robot import RobotModel
from ..scene import Scene
from .edge_certify import EdgeCertifier

if TYPE_CHECKING:
    from ..codegen import FastFunction
    from .kernel.checker import NativeValidity

__all__ = ["ValidityChecker", "ConfigValidity"]
log = logging.getLogger(__name__)
#: compiled speed profiles shared by the checkers of one process (key: robot model, mode, geometry bounds)
_PROFILE_CACHE: dict[tuple[Any, ...], tuple[Any, FastFunction | None]] = {}


_ORDERS: dict[int, list[int]] = {}
_ORDER_ARRAYS: dict[int, np.ndarray] = {}
#: the broad-phase pool of Pinocchio's batch collision API (Pinocchio built with its parallel module)
_POOL = getattr(pin, "BroadPhaseManagerPool_DynamicAABBTreeCollisionManager", None)


def _bisection_order(n: int) -> list[int]:
    """1..n−1 in coarse-to-fine (bisection) order, so a blocked edge is usually found early."""
    if n not in _ORDERS:
        _ORDERS[n] = _bisection_array(n).tolist()
    return _ORDERS[n]


_ORDER_ARRAY: dict[int, np.ndarray] = {}


def _bisection_array(n: int) -> np.ndarray:
    """:func:`_bisection_order` as an integer array (cached)."""
    got = _ORDER_ARRAY.get(n)
    if got is None:
        # level by level, each interval [lo, hi] (hi − lo ≥ 2) gives its midpoint, then its two halves in
        # order; the midpoints lie strictly inside disjoint intervals, so none repeats
        lo, hi = np.array([0]), np.array([int(n)])
        out: list[np.ndarray] = []
        while lo.size:
            keep = hi - lo >= 2
            lo, hi = lo[keep], hi[keep]
            mid = (lo + hi) // 2
            out.append(mid)
            lo, hi = np.stack([lo, mid], 1).ravel(), np.stack([mid, hi], 1).ravel()
        got = _ORDER_ARRAY[n] = np.concatenate(out)
    return got


def _bisection_fractions(n: int) -> np.ndarray:
    """``k / n`` for the ``k`` of :func:`_bisection_order` (same order), as one array."""
    f = _ORDER_ARRAYS.get(n)
    if f is None:
        f = _ORDER_ARRAYS[n] = _bisection_array(n) / n
    return f


_ORDER_INDICES: dict[int, np.ndarray] = {}


def _bisection_indices(n: int) -> np.ndarray:
    """``k − 1`` for the ``k`` of :func:`_bisection_order` (same order): indices into the n − 1 interior points."""
    f = _ORDER_INDICES.get(n)
    if f is None:
        f = _ORDER_INDICES[n] = _bisection_array(n) - 1
    return f


class ValidityChecker:
    """Boolean collision checks in C++ (see the module docstring).

    Counters ``n_checks`` (all modes) are incremented on every call (by the configurations checked for
    a batch). ``broadphase``: a dynamic AABB tree in front of the narrow phase (only with
    ``margin = 0``); ``batch``: the queries go through Pinocchio's batch collision API (a pool of one
    broad-phase manager per mode, one thread) when this Pinocchio has it — the same verdicts, cheaper
    per call, and :meth:`first_invalid` checks many configurations in one call; False: one
    ``computeCollisions`` call per configuration. ``exact_contacts``: every collision request asks coal
    for contacts (:func:`optplan.collision.checker.exact_contact_requests`), so that a verdict agrees
    with the sign of the exact distance also where a capsule's segment touches a box's face (there
    Pinocchio's default requests report a capsule sunk by its radius as free); False: Pinocchio's
    default requests. ``kernel``: ``"native"`` (default) — the boolean checks (:meth:`is_valid`,
    :meth:`first_invalid`, :meth:`edge_is_valid`, :meth:`valid_batch`) run in the compiled planning
    kernel (:mod:`optplan.planners.kernel`: the same pairs on exact sphere/capsule/box primitives,
    never free where coal collides, 3-6× cheaper per configuration), falling back to coal when it
    cannot be built (no C compiler) or does not cover the robot; ``"coal"``: Pinocchio + coal as
    above. :attr:`kernel` tells which one is in use. Diagnostics (:meth:`colliding_pairs`,
    :meth:`grasp_contacts`) and certified edges always use coal.

    A free-floating robot: its configurations carry the base pose (XYZ-quaternion first), so the
    checks place every geometry where that base puts it; only the configuration checks
    (:meth:`is_valid`, :meth:`first_invalid`, :meth:`valid_batch`) apply, on coal (the edge bounds
    and the compiled kernel assume a fixed base and revolute joints).
    """

    def __init__(self, robot: RobotModel, scene: Scene | None = None, *, margin: float = 0.0,
                 object_arm: str | None = None, self_collision: bool = True, broadphase: bool = True,
                 batch: bool = True, exact_contacts: bool = True, kernel: str = "native"):
        if robot.is_floating:
            # the base pose is part of each configuration (XYZ-quaternion first) and so of every
            # geometry's placement; the compiled kernel and the edge bounds cover fixed bases only
            kernel = "coal"
        if not (np.isfinite(margin) and margin >= 0.0):
            raise ValueError(f"margin: expected a number >= 0 m, got {margin!r}")
        self.robot = robot
        self.scene = scene
        self.margin = float(margin)
        self.exact_contacts = bool(exact_contacts)
        self.model = robot.model
        self.data = robot.model.createData()
        # robot, obstacles, held object and the pair set as the exact checker has them
        geo = scene_geometry(robot, scene, object_arm)
        gm = geo.model
        robot_geoms = list(range(geo.n_robot))
        self.object = scene.object if scene is not None else None
        self.held_id, self.fixed_id = geo.held_id, None
        if self.object is not None:
            self.object_arm = geo.object_arm
            self.fixed_id = gm.addGeometryObject(pin.GeometryObject("object/fixed", 0, 0, pin.SE3.Identity(),
                                                                    self.object.coal_geometry()))
        groups: dict[str, list[tuple[int, int]]] = {"held": [], "fixed": [], "obstacle": [], "self": []}
        group_of = {"object-obstacle": "held", "object-robot": "held", "robot-obstacle": "obstacle", "self": "self"}
        for p in scene_pairs(robot, scene, self_collision=self_collision):
            groups[group_of[p.kind]].append(pair_indices(p, geo))
        if self.object is not None:
            fixed_id = cast(int, self.fixed_id)   # set just above
            groups["fixed"] = [(g, fixed_id) for g in robot_geoms]
        # order: object pairs first (the big box collides most), then obstacles, then self
        order = ["held", "fixed", "obstacle", "self"]
        self._pair_group = []
        for name in order:
            for a, b in groups[name]:
                gm.addCollisionPair(pin.CollisionPair(min(a, b), max(a, b)))
                self._pair_group.append(name)
        self.gmodel = gm
        self.n_pairs = {k: len(v) for k, v in groups.items()}
        self._gd = {}
        for mode, active in (("held", {"held", "obstacle", "self"}), ("fixed", {"fixed", "obstacle", "self"}),
                             ("free", {"obstacle", "self"})):
            gd = pin.GeometryData(gm)
            for k, grp in enumerate(self._pair_group):
                if grp not in active:
                    gd.deactivateCollisionPair(k)
                if self.margin > 0:
                    gd.collisionRequests[k].security_margin = self.margin
            if self.exact_contacts:
                exact_contact_requests(gd)
            self._gd[mode] = gd
        # broad phase (dynamic AABB tree, coal) in front of the narrow phase: 3-5x faster in cluttered
        # scenes; its AABBs are not inflated by a security margin, so only used with margin = 0
        self.broadphase = bool(broadphase) and self.margin == 0.0
        self._bp = {}
        if self.broadphase:
            for mode, gd in self._gd.items():
                self._bp[mode] = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(self.model, gm, gd)
        # the boolean queries go through Pinocchio's batch API (a pool of one broad-phase manager per mode, one
        # thread): the same C++ checks as computeCollisions on the managers above, a third cheaper per single
        # configuration (less Python binding dispatch) and half the cost per configuration of a batch
        self._pool: dict[str, Any] = {}
        self._pool_object = None
        if self.broadphase and _POOL is not None and batch:
            for mode, gd in self._gd.items():
                pool = _POOL(self.model, gm, 1)
                pgd = pool.getGeometryData(0)
                for k in range(len(gm.collisionPairs)):
                    if not gd.activeCollisionPairs[k]:
                        pgd.deactivateCollisionPair(k)
                if self.exact_contacts:
                    exact_contact_requests(pgd)
                self._pool[mode] = pool
            if self.fixed_id is not None:   # the still object's placement, set per query
                self._pool_object = self._pool["fixed"].getGeometryModel(0).geometryObjects[self.fixed_id]
        self.n_checks = 0
        self._native = self._native_backend(kernel)
        #: the backend of the boolean checks in use: "native" or "coal"
        self.kernel = "coal" if self._native is None else "native"
        self._sweep = {mode: self._sweep_bound(mode) for mode in ("held", "fixed", "free")}
        self._spheres = {mode: self._sweep_spheres(mode) for mode in ("held", "fixed", "free")}
        # the velocity (Jacobian) bound of edge_checkpoints assumes revolute 1-dof joints
        self._revolute_only = all(jm.nv == 1 and jm.shortname().replace("JointModel", "").startswith("R")
                                  for jm in list(self.model.joints)[1:])
        self._profile_fns: dict[Any, FastFunction | None] = {}
        self._certifiers: dict[float, EdgeCertifier] = {}
        self._exempted: dict[str, frozenset[int]] = {}   # per mode, the pairs exempt() has switched off

    def _native_backend(self, kernel: str) -> NativeValidity | None:
        """The native kernel for ``kernel == "native"`` (None for "coal", or when it cannot be built)."""
        if kernel not in ("native", "coal"):
            raise ValueError(f"kernel: expected 'native' or 'coal', got {kernel!r}")
        if kernel == "coal":
            return None
        from .kernel import KernelUnavailable
        from .kernel.checker import NativeValidity
        try:
            return NativeValidity(self.model, self.gmodel, self._gd, self.fixed_id, self.margin)
        except KernelUnavailable as e:
            log.info("validity checks stay with coal: %s", e)
            return None

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
            import casadi as ca

            from ..codegen import FastFunction
            from ..model.symbolic import SymbolicKinematics

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
            rel = self._relative_pairs(mode) if what == "cells" else []
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
                fn = FastFunction(ca.Function(f"sweep_profile_{mode}", [a, b], [ca.vertcat(*cum)]), "-O1")
            else:
                fn = FastFunction(ca.Function(f"sweep_cells_{mode}", [a, b], [ca.vertcat(*cells)]), "-O1")
        self._profile_fns[key_fn] = fn
        _PROFILE_CACHE[key] = (self.model, fn)     # the model is kept alive so that its id stays unique
        return fn

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
                      object_pose: pin.SE3 | None = None, check_end: bool = False) -> bool:
        """The straight joint segment ``a → b`` collision-free at the checkpoints of
        :meth:`edge_checkpoints` (no point of the checked geometry travels farther than ``tolerance``
        [m] between two checks), checked coarse-to-fine; ``a`` itself is not checked, ``b`` only with
        ``check_end``. ``mode``: ``"held"`` (:meth:`is_valid`), ``"fixed"``
        (:meth:`is_valid_object_fixed` at ``object_pose``) or ``"free"``."""
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
    def _collides(self, mode: str, q: np.ndarray) -> bool:
        """One configuration in ``mode`` (the still object's pose already set): any active pair in contact."""
        if self._native is not None:
            return self._native.collides(q, mode)
        pool = self._pool.get(mode)
        if pool is not None:
            return bool(pin.computeCollisionsInParallel(1, pool, np.asarray(q, float).reshape(-1, 1), True, True)[0])
        if self.broadphase:
            return bool(pin.computeCollisions(self.model, self.data, self._bp[mode], q, True))
        return bool(pin.computeCollisions(self.model, self.data, self.gmodel, self._gd[mode], q, True))

    def _set_object_pose(self, object_pose: pin.SE3) -> None:
        """The still object's placement for the ``"fixed"`` mode's batch queries."""
        self._pool_object.placement = object_pose   # type: ignore[union-attr]  # set when the pool exists

    def is_valid(self, q: np.ndarray) -> bool:
        """Collision-free with the object held by the hands (falls back to ``free`` without an object)."""
        self.n_checks += 1
        return not self._collides("held" if self.object is not None else "free", q)

    def is_valid_free(self, q: np.ndarray) -> bool:
        """Collision-free without any object (self and obstacles only)."""
        self.n_checks += 1
        return not self._collides("free", q)

    def is_valid_object_fixed(self, q: np.ndarray, object_pose: pin.SE3) -> bool:
        """Collision-free with the object standing still at ``object_pose`` (regrasp)."""
        if self.object is None:
            return self.is_valid_free(q)
        self.n_checks += 1
        if self._native is not None:
            return not self._native.collides(q, "fixed", object_pose)
        if "fixed" in self._pool:
            self._set_object_pose(object_pose)
            return not self._collides("fixed", q)
        gd = self._gd["fixed"]
        pin.updateGeometryPlacements(self.model, self.data, self.gmodel, gd, q)
        gd.oMg[self.fixed_id] = object_pose
        if self.broadphase:
            mgr = self._bp["fixed"]
            mgr.update(False)
            return not pin.computeCollisions(mgr, True)
        return not pin.computeCollisions(self.gmodel, gd, True)

    def first_invalid(self, Q: np.ndarray, mode: str = "held", object_pose: pin.SE3 | None = None) -> int:
        """Index of the first row of ``Q`` (configurations, M × nq) in collision, or −1 when every row
        is valid: the rows are checked IN ORDER and the checks stop at the first collision (one C++
        call; ``n_checks`` grows by the number of rows checked, as with one :meth:`is_valid` per row).
        ``mode``: ``"held"`` (:meth:`is_valid`), ``"fixed"`` (:meth:`is_valid_object_fixed` at
        ``object_pose``) or ``"free"``."""
        if mode == "held" and self.object is None:
            mode = "free"
        if mode == "fixed":
            if object_pose is None:
                raise ValueError("first_invalid: mode 'fixed' needs object_pose")
            if self.object is None:
                mode = "free"
        elif mode not in ("held", "free"):
            raise ValueError(f"first_invalid: mode must be 'held', 'fixed' or 'free', got {mode!r}")
        Q = np.asarray(Q, float)
        if Q.ndim != 2 or Q.shape[1] != self.model.nq:
            raise ValueError(f"first_invalid: expected an (M, {self.model.nq}) array of configurations, got shape {Q.shape}")
        if self._native is not None:
            k = self._native.first_invalid(Q, mode, object_pose) if len(Q) else -1
            self.n_checks += len(Q) if k < 0 else k + 1
            return k
        pool = self._pool.get(mode)
        if pool is None:   # no batch API: one query per row
            one: Callable[[np.ndarray], bool] = ((lambda x: self.is_valid_object_fixed(x, object_pose)) if mode == "fixed"
                                                 else self.is_valid if mode == "held" else self.is_valid_free)
            for k, x in enumerate(Q):
                if not one(x):
                    return k
            return -1
        if not len(Q):
            return -1
        if mode == "fixed":
            self._set_object_pose(cast(pin.SE3, object_pose))
        hit = pin.computeCollisionsInParallel(1, pool, Q.T, True, True)
        k = int(np.argmax(hit)) if hit.any() else -1
        self.n_checks += len(Q) if k < 0 else k + 1
        return k

    def valid_batch(self, Q: np.ndarray, mode: str = "held", object_pose: pin.SE3 | None = None) -> np.ndarray:
        """Validity (booleans) of EVERY row of ``Q`` (M × nq) in ``mode`` (as :meth:`first_invalid`);
        ``n_checks`` grows by M."""
        Q = np.asarray(Q, float)
        if Q.ndim != 2 or Q.shape[1] != self.model.nq:
            raise ValueError(f"valid_batch: expected an (M, {self.model.nq}) array of configurations, got shape {Q.shape}")
        if mode == "held" and self.object is None or mode == "fixed" and self.object is None:
            mode = "free"
        if mode not in ("held", "fixed", "free"):
            raise ValueError(f"valid_batch: mode must be 'held', 'fixed' or 'free', got {mode!r}")
        if mode == "fixed" and object_pose is None:
            raise ValueError("valid_batch: mode 'fixed' needs object_pose")
        if self._native is not None:
            self.n_checks += len(Q)
            return self._native.valid(Q, mode, object_pose)
        return np.array([self.first_invalid(q[None], mode, object_pose) < 0 for q in Q], dtype=bool)

    def validity(self, mode: str = "held", object_pose: pin.SE3 | None = None, base: np.ndarray | None = None,
                 joints: np.ndarray | None = None) -> ConfigValidity:
        """A validity function ``f(x) -> bool`` of ``mode`` (as :meth:`first_invalid`) with a batch form
        ``f.first_invalid(X)`` that :func:`optplan.planners.rrtconnect.edge_is_valid` uses. With ``base``
        and ``joints``: ``x`` holds only the values of the joints ``joints`` (indices into q), the others
        stay at ``base`` (one arm moving while the rest of the robot stands still, as in a regrasp)."""
        return ConfigValidity(self, mode, object_pose, base, joints)

    def grasp_contacts(self, q: np.ndarray, object_pose: pin.SE3) -> tuple[int, ...]:
        """Indices of the ``"fixed"``-mode pairs in collision at ``q`` between the object standing at
        ``object_pose`` and a robot geometry on one of the object's ``exclude_links`` (the links allowed
        to touch it: a hand on the object at its grasp); other colliding pairs are not listed."""
        if self.object is None:
            return ()
        excl = set(self.object.exclude_links)
        if not excl:
            return ()
        gd = self._gd["fixed"]
        pin.updateGeometryPlacements(self.model, self.data, self.gmodel, gd, q)
        gd.oMg[self.fixed_id] = object_pose
        pin.computeCollisions(self.gmodel, gd, False)
        objs, out = self.gmodel.geometryObjects, []
        for k, cp in enumerate(self.gmodel.collisionPairs):
            if self._pair_group[k] != "fixed" or not gd.activeCollisionPairs[k] or not gd.collisionResults[k].isCollision():
                continue
            g = cp.first if cp.second == self.fixed_id else cp.second
            if self.model.frames[objs[g].parentFrame].name in excl:
                out.append(k)
        return tuple(out)

    @contextmanager
    def exempt(self, pairs: tuple[int, ...], mode: str = "fixed") -> Iterator[None]:
        """Within the block, ``mode``'s checks skip the pair indices ``pairs`` (e.g. a regrasp's
        :meth:`grasp_contacts`); restored on exit. The boolean checks, the batch queries and the
        certified edges (:meth:`edge_is_certified`, :meth:`path_is_certified`) all skip them."""
        gd = self._gd[mode]
        off = [k for k in pairs if gd.activeCollisionPairs[k]]
        pool = self._pool.get(mode)
        gds = [gd] if pool is None else [gd, pool.getGeometryData(0)]   # the batch queries' pairs too
        before = self._exempted.get(mode, frozenset())
        for g in gds:
            for k in off:
                g.deactivateCollisionPair(k)
        self._exempted[mode] = before | frozenset(off)   # the certifiers read it (their pair groups per set)
        if self._native is not None:
            self._native.set_active(mode, off, False)
        try:
            yield
        finally:
            for g in gds:
                for k in off:
                    g.activateCollisionPair(k)
            if self._native is not None:
                self._native.set_active(mode, off, True)
            self._exempted[mode] = before

    def exempted(self, mode: str = "fixed") -> frozenset[int]:
        """The pair indices that :meth:`exempt` switches off in ``mode`` right now (empty outside it)."""
        return self._exempted.get(mode, frozenset())

    def in_limits(self, q: np.ndarray, tol: float = 1e-9) -> bool:
        return bool(np.all(q >= self.robot.lower - tol) and np.all(q <= self.robot.upper + tol))

    def colliding_pairs(self, q: np.ndarray, mode: str = "held", object_pose: pin.SE3 | None = None) -> list[tuple[str, str]]:
        """Names of every colliding pair at ``q`` (diagnostics; slow path)."""
        gd = self._gd[mode]
        pin.updateGeometryPlacements(self.model, self.data, self.gmodel, gd, q)
        if mode == "fixed" and object_pose is not None:
            gd.oMg[self.fixed_id] = object_pose
        pin.computeCollisions(self.gmodel, gd, False)
        out = []
        objs = self.gmodel.geometryObjects
        for k, cp in enumerate(self.gmodel.collisionPairs):
            if gd.activeCollisionPairs[k] and gd.collisionResults[k].isCollision():
                out.append((objs[cp.first].name, objs[cp.second].name))
        return out


class ConfigValidity:
    """A validity function of one :class:`ValidityChecker` mode (see :meth:`ValidityChecker.validity`):
    ``f(x)`` checks one configuration, ``f.first_invalid(X)`` the rows of ``X`` in order, stopping at
    the first collision (index, or −1 when all are valid)."""

    __slots__ = ("checker", "mode", "object_pose", "base", "joints")

    def __init__(self, checker: ValidityChecker, mode: str, object_pose: pin.SE3 | None = None,
                 base: np.ndarray | None = None, joints: np.ndarray | None = None) -> None:
        if mode not in ("held", "fixed", "free"):
            raise ValueError(f"validity: mode must be 'held', 'fixed' or 'free', got {mode!r}")
        if mode == "fixed" and object_pose is None:
            raise ValueError("validity: mode 'fixed' needs object_pose")
        if (base is None) != (joints is None):
            raise ValueError("validity: give both base (a full configuration) and joints (indices into it), or neither")
        self.checker, self.mode, self.object_pose = checker, mode, object_pose
        self.base = None if base is None else np.array(base, dtype=float)
        self.joints = None if joints is None else np.asarray(joints, dtype=int)

    def _full(self, x: np.ndarray) -> np.ndarray:
        if self.base is None:
            return x
        q = self.base.copy()
        q[self.joints] = x
        return q

    def __call__(self, x: np.ndarray) -> bool:
        q, ck = self._full(x), self.checker
        if self.mode == "held":
            return ck.is_valid(q)
        if self.mode == "fixed":
            return ck.is_valid_object_fixed(q, cast(pin.SE3, self.object_pose))
        return ck.is_valid_free(q)

    def first_invalid(self, X: np.ndarray) -> int:
        X = np.asarray(X, float)
        if self.base is not None:
            Q = np.repeat(self.base[None, :], len(X), axis=0)
            Q[:, self.joints] = X
            X = Q
        return self.checker.first_invalid(X, self.mode, self.object_pose)
