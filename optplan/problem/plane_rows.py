"""The fixed-normal separating-plane rows of collision pairs on a joint B-spline (decisions 0003,
0012): which pairs and knots are active along a first guess, each side's points (capsule end
points, box vertices) in its frame — or in the world when it depends on no free joint —, the
margins (relaxed next to pinned configurations closer than the margin, raised where a solution
cut a corner between knots), the normals from coal's witness planes and one kernel per pair.

The planner serves :class:`~optplan.problem.OptProblem`'s B-spline core
(:mod:`.spline_collision`) and the segment builder (:mod:`.segment`): one implementation of the
rows. For a static obstacle the plane's offset is eliminated: the row is
``min_y n·y − r_B − n·x − r_A ≥ margin`` for each point ``x`` of the moving body; two moving
bodies keep the offset ``b`` as a variable (rows ``b − n·x − r_A ≥ m/2``, ``n·y − r_B − b ≥ m/2``).
"""
from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np

from ..model.robot import RobotModel
from .collision_term import CollisionModel, _box_vertices
from .frame_terms import ClosedChain
from .kernels import KernelCache, geometry_points
from .terms import NumericTrajectory

__all__ = ["PlanePlanner", "SPLINE_ACTIVATION"]

#: Pairs closer than this along the first guess get plane rows [m] (a :class:`CollisionAvoidance`
#: left at its default activation; a third of the pairs and half the rows of 0.3 m on the
#: transport, docs/decisions/0012-segment-nlp-rows.md).
SPLINE_ACTIVATION = 0.12


class PlanePlanner:
    """Plans the plane rows of one collision model ``col`` (:meth:`CollisionAvoidance.model
    <optplan.problem.CollisionAvoidance.model>`) on N intervals over T [s] between the pinned
    configurations ``q0``, ``q1`` [rad]; ``fixed``: joint indices held fixed (lower == upper);
    ``closed_chain``: the two hands' constraint, if any (both hands then carry the object);
    ``window`` [knots] and ``relax_to_guess`` as :class:`~optplan.problem.segment.SegmentSpec`."""

    def __init__(self, robot: RobotModel, col: CollisionModel, N: int, T: float, q0: np.ndarray, q1: np.ndarray,
                 fixed: frozenset[int], closed_chain: ClosedChain | None = None, *, window: int = 3,
                 relax_to_guess: bool = True, kernels: KernelCache | None = None):
        self.robot, self.col, self.N, self.T = robot, col, int(N), float(T)
        self.q0, self.q1 = np.asarray(q0, float), np.asarray(q1, float)
        self.fixed, self.closed_chain = frozenset(fixed), closed_chain
        self.window, self.relax_to_guess = int(window), bool(relax_to_guess)
        self.kernels = KernelCache.of(robot) if kernels is None else kernels
        #: [m] a moving box keeps the rows of the vertices within this distance of its leading
        #: vertex along a plane's normal (``inf``: every vertex; see :meth:`_prune`)
        self.vertex_window = 0.5
        for g, shape in col.robot_shape.items():  # refuse unsupported geometry now, by name
            if shape is None:
                geometry_points(robot, g)

    def rows(self, Qk: np.ndarray) -> tuple[list[SimpleNamespace], list[tuple[np.ndarray, np.ndarray]]]:
        """The plan along the knot configurations ``Qk`` ((N+1) × nj): items (pair, kernel ``fn``,
        knots, margins, rows per knot ``nrow``, static side or not) and per item its normals
        (3 × K) and static supports / initial plane offsets (K)."""
        plan = self.plan(Qk)
        planes = self.plane_data(plan, Qk)
        self.kernels_for(plan, planes, Qk)
        return plan, planes

    def entity(self, kind: str, idx: int, holder: str | None) -> tuple[int | None, np.ndarray, float]:
        """(frame id or None, points 3 × m in that frame (world if None), radius) of an entity;
        an entity that depends on no free joint (an obstacle, the fixed base, a holding arm, the
        object it holds) comes back static: frame None and its world points."""
        col = self.col
        if kind == "obstacle":
            o = col.checker.obstacles[idx]
            if o.shape == "box":
                V, r = np.array(_box_vertices(np.asarray(o.size) / 2)).T, 0.0
            elif o.shape == "sphere":
                assert o.radius is not None  # a sphere obstacle has a radius
                V, r = np.zeros((3, 1)), float(o.radius)
            else:
                assert o.radius is not None and o.length is not None  # a capsule obstacle has both
                V, r = np.array([[0, 0, -o.length / 2], [0, 0, o.length / 2]]).T, float(o.radius)
            M = o.placement
            return None, M.rotation @ V + M.translation[:, None], r
        if kind == "object":
            assert col.checker.object is not None and holder is not None  # only with a held object
            V = np.array(_box_vertices(np.asarray(col.checker.object.size) / 2)).T
            G = col.grasp_inv
            fid, V, r = self.robot.arm(holder).ee_frame_id, G.rotation @ V + G.translation[:, None], 0.0
        else:
            spec = col.robot_shape.get(idx)
            if spec is None:
                fid, V, r = geometry_points(self.robot, idx)
                return self._static_or_moving(kind, idx, fid, V, r)
            fid, shape, Mbox = spec
            from ..geometry import distance as D
            if isinstance(shape, D.Box):
                assert Mbox is not None  # a box's placement in its frame is kept
                V, r = np.array([Mbox.act(v) for v in _box_vertices(np.asarray(shape.half_extents))]).T, 0.0
            elif isinstance(shape, D.Sphere):
                V, r = np.asarray(shape.center, float).reshape(3, 1), float(shape.radius)
            else:
                V, r = np.array([shape.a, shape.b], float).T, float(shape.radius)
        return self._static_or_moving(kind, idx, fid, V, r)

    def _static_or_moving(self, kind: str, idx: int, fid: int, V: np.ndarray,
                          r: float) -> tuple[int | None, np.ndarray, float]:
        if self.col.free_joints_of(self.robot, kind, idx, self.fixed) == set():
            M = self._static_placement(fid)
            return None, M.rotation @ V + M.translation[:, None], r
        return fid, V, r

    def _static_placement(self, fid: int) -> Any:
        import pinocchio as pin

        data = self.robot.model.createData()
        pin.framesForwardKinematics(self.robot.model, data, self.q0)
        return data.oMf[fid]

    def _boundary_margins(self, active: list[Any], pinned: set[int]) -> Any:
        """``margin_at(pair, k)`` [m] as :meth:`CollisionAvoidance._boundary_margins` (the margin,
        halved distance within ``window`` knots of a pinned configuration closer than the margin),
        from the exact coal distances of the pinned configurations: the rows here are planes, not
        the knot transcription's smooth distances."""
        col, N, w = self.col, self.N, int(self.window)
        assert col._init_dist is not None  # a scene, and the guess's distances (_activate)
        col.relaxed = {}
        index = col.checker.pair_index
        knots = set(range(N + 1)) if self.relax_to_guess else set(pinned)
        for kp in sorted(knots):
            d = col._init_dist[kp]  # exact distances along the initial guess (set by _activate)
            for p in active:
                dp = float(d[index[p]])
                # inside the path only a collision-free guess relaxes (a colliding one must be pushed out)
                if dp < col.margin and (kp in pinned or dp >= 0.0):
                    m = min(col.margin, 0.5 * dp)
                    for k in range(max(0, kp - w), min(N, kp + w) + 1):
                        col.relaxed[(p, k)] = min(m, col.relaxed.get((p, k), np.inf))
        return col._margin_at

    def plan(self, Qk: np.ndarray) -> list[SimpleNamespace]:
        """Active (pair, kernel, knots, …) along the knot configurations ``Qk``: one item per pair
        with its kernel, knots, margins and which side moves (``flip``: A is the static side)."""
        col = self.col
        robot, N = self.robot, self.N
        traj = NumericTrajectory(robot, Qk, Qk, Qk, Qk[:-1], self.T)
        active = col.activate(robot, traj)
        pinned = {0: self.q0, N: self.q1}
        # arms holding the object here (both under the closed chain, else its own arm): the object
        # keeps its distance to the geometry that rides on their hands (verify checks it)
        cc = self.closed_chain
        rigid = [cc.arm_a, cc.arm_b] if cc is not None else [a for a in (col.checker.object_arm,) if a is not None]
        const = [p for p in active if col.is_constant(robot, p, self.fixed, rigid)]
        active = [p for p in active if p not in const]
        col.active_pairs = active
        col.constant_pairs = const
        margin_at = self._boundary_margins(active, set(pinned))
        holder = col.checker.object_arm
        plan = []
        for pair in active:
            ka, kb = col.kinds(pair)
            ea, eb = self.entity(ka, pair.a, holder), self.entity(kb, pair.b, holder)
            if ea is None or eb is None:
                continue
            if ea[0] is None and eb[0] is None:
                continue  # both static: constant distance, checked by verify
            ks = [k for k in col.knots_of(pair, N) if k not in pinned]
            if not ks:
                continue
            flip = ea[0] is None
            mov, other = (eb, ea) if flip else (ea, eb)
            static = other[0] is None
            plan.append(SimpleNamespace(pair=pair, knots=ks, static=static, flip=flip, a=mov, b=other,
                                        margins=np.array([margin_at(pair, k) for k in ks])))
        return plan

    def _prune(self, it: SimpleNamespace, side: tuple[int | None, np.ndarray, float], normals: np.ndarray,
               Qk: np.ndarray, sign: float) -> tuple[int | None, np.ndarray, float]:
        """Keep the points of a moving box side that come within ``vertex_window`` [m] of its
        leading point along the (signed) normal at some knot of the pair: the others sit that far
        behind the plane and cannot reach it without the body turning by a large angle."""
        fid, V, r = side
        if V.shape[1] <= 2 or not np.isfinite(self.vertex_window):
            return side
        import pinocchio as pin

        data = self.robot.model.createData()
        keep = np.zeros(V.shape[1], bool)
        for t, k in enumerate(it.knots):
            pin.framesForwardKinematics(self.robot.model, data, Qk[k])
            proj = sign * normals[:, t] @ (data.oMf[fid].rotation @ V)
            keep |= proj >= proj.max() - self.vertex_window
        return fid, V[:, keep], r

    def kernels_for(self, plan: list[SimpleNamespace], planes: list[tuple[np.ndarray, np.ndarray]],
                     Qk: np.ndarray) -> None:
        """Point subsets (:meth:`_prune`), kernel and row count of every item."""
        for it, (Nrm, _) in zip(plan, planes):
            it.a = self._prune(it, it.a, Nrm, Qk, 1.0)  # rows b − n·x: x's leading along +n
            if not it.static:
                it.b = self._prune(it, it.b, Nrm, Qk, -1.0)  # rows n·y − b: y's leading along −n
            it.fn = self.kernels.pair(it.a[0], it.a[1], it.a[2], it.b[0], it.b[1], it.b[2])
            it.nrow = it.a[1].shape[1] + (0 if it.static else it.b[1].shape[1])

    def plane_data(self, plan: list[SimpleNamespace], Qk: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per item: normals (3 × K) from coal's witness at the knot configurations (pointing from
        the moving side to the other), and the offsets: the static side's support value, or the
        witness mid-plane offset (a variable's initial value) for two moving sides."""
        col = self.col
        per_knot: dict[int, list[tuple[int, int]]] = {}
        for i, it in enumerate(plan):
            for t, k in enumerate(it.knots):
                per_knot.setdefault(k, []).append((i, t))
        out = [(np.zeros((3, len(it.knots))), np.zeros(len(it.knots))) for it in plan]
        for k, items in per_knot.items():
            chk = col.checker
            W = chk.witness_planes(Qk[k], [chk.pair_index[plan[i].pair] for i, _ in items])
            for (i, t), nb in zip(items, W):
                it = plan[i]
                n, off = (-nb[:3], -nb[3]) if it.flip else (nb[:3], nb[3])
                if it.static:
                    Y, rb = it.b[1], it.b[2]
                    off = float(np.min(n @ Y)) - rb
                out[i][0][:, t] = n
                out[i][1][t] = off
        return out
