"""The per-build data of a collision-avoidance term (:class:`CollisionModel`): the collision checker,
the NLP shapes of the robot's geometries, the activated pairs, relaxed margins and separating
planes, and the geometric helpers they share (box vertices, witness planes, the held object's
capsules). The term itself (:class:`~optplan.problem.collision_term.CollisionAvoidance`, its
options and documentation) lives in :mod:`.collision_term`; this module reads its configuration
through the term object only (no import of the term's module)."""
from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Sequence
from typing import Any, cast

import casadi as ca
import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from ..collision.checker import CollisionChecker, Pair
from ..geometry import distance as D
from ..model.robot import RobotModel
from .build import AuxVariable, BuildContext, TermData
from .terms import NumericTrajectory
from .transcription import Expr, Transcription

__all__ = ["CollisionModel", "object_capsules", "witness_plane"]
def _ro(a: ArrayLike) -> np.ndarray:
    a = np.array(a, float)
    a.flags.writeable = False
    return a


def _box_vertices(h: ArrayLike) -> list[np.ndarray]:
    h = np.asarray(h, float)
    return [np.array([sx * h[0], sy * h[1], sz * h[2]]) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
log = logging.getLogger(__name__)


def witness_plane(checker: CollisionChecker, pair: Pair, obj_tf: coal.Transform3s | None) -> np.ndarray:
    """(n, b): coal's unit witness normal from A to B and the mid-plane offset ``n·mid`` of a pair,
    at the placements last set by ``checker.update_placements`` (``obj_tf``: the held object's)."""
    g1, t1, g2, t2 = checker.pair_geometries(pair, obj_tf)
    res = coal.DistanceResult()
    coal.distance(g1, t1, g2, t2, coal.DistanceRequest(), res)
    n = np.asarray(res.normal, float)
    p1, p2 = np.asarray(res.getNearestPoint1(), float), np.asarray(res.getNearestPoint2(), float)
    unset = not np.all(np.isfinite(n)) or abs(float(np.linalg.norm(n)) - 1.0) > 1e-3
    if unset and res.min_distance > 0 and np.linalg.norm(p2 - p1) > 1e-12:
        n = p2 - p1   # unset for triangle meshes (BVH): the nearest points of a separated pair give it
    elif not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-9:
        n = t2.getTranslation() - t1.getTranslation()
    n = n / max(np.linalg.norm(n), 1e-12)
    mid = 0.5 * (p1 + p2)
    return np.r_[n, n @ mid]


def object_capsules(size: ArrayLike, grid: int = 2) -> list[D.Capsule]:
    """Capsules covering a box of full edges ``size`` [m]: a ``grid × grid`` array over the
    cross-section, each along the longest axis over the full length."""
    size = np.asarray(size, float)
    ax = int(np.argmax(size))
    others = [i for i in range(3) if i != ax]
    cell = size[others] / grid
    r = 0.5 * float(np.linalg.norm(cell))
    caps = []
    for i in range(grid):
        for j in range(grid):
            c = np.zeros(3)
            c[others[0]] = -size[others[0]] / 2 + (i + 0.5) * cell[0]
            c[others[1]] = -size[others[1]] / 2 + (j + 0.5) * cell[1]
            a, b = c.copy(), c.copy()
            a[ax], b[ax] = -size[ax] / 2, size[ax] / 2
            caps.append(D.Capsule(r, cast("tuple[float, float, float]", tuple(a)),
                                  cast("tuple[float, float, float]", tuple(b))))
    return caps


_FIELDS: dict[type, frozenset[str]] = {}


def _config_fields(term_type: Any) -> frozenset[str]:
    """The term's configuration fields a model reads through (all but the two that grow per build)."""
    got = _FIELDS.get(term_type)
    if got is None:
        got = _FIELDS[term_type] = frozenset(f.name for f in dataclasses.fields(term_type)) - {"activate_with",
                                                                                                "margin_boost"}
    return got


class CollisionModel:
    """The per-build data of a :class:`CollisionAvoidance` term: its collision checker, the NLP
    shapes of the robot's geometries, the pairs it activates, relaxed margins and separating
    planes. Configuration values are read from ``term``; ``activate_with`` and ``margin_boost``
    start as the term's and may grow (``boost_between_knots``)."""

    def __init__(self, term: Any, robot: RobotModel) -> None:
        self.term = term
        self.activate_with = list(term.activate_with)
        self.margin_boost = dict(term.margin_boost)
        self.skipped: list[Pair] = []
        self.active_pairs: list[Pair] = []
        self.constant_pairs: list[Pair] = []
        self.relaxed: dict[tuple[Pair, int], float] = {}
        self.active_knots: dict[Pair, list[int] | None] = {}
        self._plane_slots: list[tuple[Pair, int, int]] = []
        self._fns: dict[tuple[str, str], ca.Function | None] = {}
        self._pfns: dict[tuple[bytes, float, bytes, float], ca.Function] = {}
        self._init_dist: np.ndarray | None = None
        #: ``(band, spread)`` [m] or None: :meth:`activate` leaves out the *steady* pairs — those
        #: whose exact distance along the initial guess stays at least ``band`` above the margin
        #: and varies by at most ``spread`` (set by the B-spline core for a term at its default
        #: activation; never with ``activate_with`` or ``margin_boost``)
        self.steady: tuple[float, float] | None = None
        #: the pairs :meth:`activate` left out as steady (checked after the solve like every pair)
        self.steady_pairs: list[Pair] = []
        self._setup(robot)

    def __getattr__(self, name: str) -> Any:  # the configuration (margin, scene, window …) is the term's
        term = self.__dict__.get("term")
        if term is not None and name in _config_fields(type(term)):
            return term.__dict__[name]
        raise AttributeError(f"CollisionModel has no attribute {name!r}")

    # ------------------------------------------------------------------ entities
    def _setup(self, robot: RobotModel) -> None:
        self.checker = CollisionChecker.shared(robot, self.scene, held_object=self.held_object,
                                               self_collision=self.self_collision, object_arm=self.object_arm)
        objs = robot.collision_model.geometryObjects
        # geometry index -> (parent frame, shape, box placement or None); None: no NLP model
        self.robot_shape: dict[int, tuple[int, D.Shape, Any] | None] = {}
        for g, o in enumerate(objs):
            geo = o.geometry
            # a geometry's placement is in its parent JOINT's frame; the rows use its parent frame
            # (not the joint's when the link hangs from fixed joints: a hand, fingers, a mount)
            M = robot.model.frames[o.parentFrame].placement.inverse() * o.placement
            if isinstance(geo, coal.Capsule):
                hl = geo.halfLength
                a = M.translation + M.rotation @ np.array([0, 0, -hl])
                b = M.translation + M.rotation @ np.array([0, 0, hl])
                self.robot_shape[g] = (o.parentFrame, D.Capsule(geo.radius, tuple(a), tuple(b)), None)
            elif isinstance(geo, coal.Sphere):
                self.robot_shape[g] = (o.parentFrame, D.Sphere(geo.radius, tuple(M.translation)), None)
            elif isinstance(geo, coal.Box):
                self.robot_shape[g] = (o.parentFrame, D.Box(tuple(np.asarray(geo.halfSide))), M)
            else:
                self.robot_shape[g] = None
        obj, holder = self.checker.object, self.checker.object_arm
        if obj is not None:
            assert holder is not None  # a checker with an object has its holding arm
            self._obj_caps = object_capsules(obj.size, self.object_grid)
            self.grasp_inv = obj.grasps[holder].inverse()
            self._hand_frame = robot.arm(holder).ee_frame

    # ------------------------------------------------------------------ activation (read by the segment NLP)
    def activate(self, robot: RobotModel, initial: NumericTrajectory | None) -> list[Pair]:
        """Active (pair, knots): knots within ``window`` of a knot where the initial guess brings
        the pair closer than ``activation``. Sets ``active_pairs`` and ``active_knots``."""
        pairs = self.checker.pairs
        if initial is None:
            self.active_pairs = list(pairs)
            self.active_knots = {p: None for p in pairs}
            return self.active_pairs
        # exact distances below the activation (and the margin), +inf elsewhere: the anchor bounds
        # of distances_below spare the pairs that cannot come that close
        thr = max(float(self.activation), float(self.margin))

        def below(tr: NumericTrajectory) -> np.ndarray:
            Q = np.array([tr.q_full(k) for k in range(initial.N + 1)])
            D = np.full((len(Q), len(pairs)), np.inf)
            r_, p_, d_ = self.checker.distances_below(Q, thr)
            D[r_, p_] = d_
            return D

        Dm = below(initial)
        self._init_dist = Dm.copy()  # (N+1) × pairs, exact where below max(activation, margin): boundary_margins
        for tr in self.activate_with:  # e.g. a previous solution that verification found colliding
            Dm = np.minimum(Dm, below(tr))
        close = Dm < self.activation
        self.steady_pairs = []
        if self.steady is not None and not self.activate_with and not self.margin_boost:
            band, spread = self.steady
            lo, hi = Dm.min(axis=0), Dm.max(axis=0)   # +inf where a knot is past the threshold
            var = hi - np.where(np.isfinite(lo), lo, 0.0)
            for j in np.flatnonzero(close.any(axis=0) & (lo >= float(self.margin) + band) & (var <= spread)).tolist():
                close[:, j] = False
                self.steady_pairs.append(pairs[j])
        for (p, k) in self.margin_boost:  # boosted rows are always constrained
            if p in pairs and 0 <= k <= initial.N:
                close[k, self.checker.pair_index[p]] = True
        w = int(self.window)
        self.active_pairs, self.active_knots = [], {}
        for i, p in enumerate(pairs):
            if not close[:, i].any():
                continue
            ks = np.flatnonzero(close[:, i])
            mask = np.zeros(initial.N + 1, bool)
            for kc in ks:
                mask[max(0, kc - w):kc + w + 1] = True
            self.active_pairs.append(p)
            self.active_knots[p] = np.flatnonzero(mask).tolist()
        return self.active_pairs

    def knots_of(self, pair: Pair, N: int) -> Sequence[int]:
        ks = self.active_knots.get(pair)
        return range(N + 1) if ks is None else ks

    def free_joints_of(self, robot: RobotModel, kind: str, idx: int, fixed: frozenset[int]) -> set[int] | None:
        """Free joint-vector indices an entity's pose depends on (``None``: unknown, e.g. a mimic
        joint; treated as moving). Obstacles: none; the object: its holding hand's joints."""
        if kind == "obstacle":
            return set()
        m = robot.model
        if kind == "object":
            assert self.checker.object_arm is not None  # an "object" entity exists only with a held object
            jid = m.frames[robot.arm(self.checker.object_arm).ee_frame_id].parentJoint
        else:
            jid = robot.collision_model.geometryObjects[idx].parentJoint
        first = 2 if robot.is_floating else 1
        out = set()
        for j in m.supports[jid]:
            if j < first:
                continue
            name = m.names[j]
            if name not in robot.joint_names:
                return None
            i = robot.joint_names.index(name)
            if i not in fixed:
                out.add(i)
        return out

    def is_constant(self, robot: RobotModel, pair: Pair, fixed: frozenset[int],
                    rigid_arms: Sequence[str] = ()) -> bool:
        """True when the pair's distance cannot change: neither entity depends on a free joint and,
        for a floating base, the pair does not involve the (world-fixed) obstacles; or the pair is
        the held object and a robot geometry on the same rigid body as the hand of one of
        ``rigid_arms`` (the arms holding the object in this NLP: the object's own arm, and the
        other one where the closed chain holds — e.g. a wrist link just behind a grasping hand)."""
        ka, kb = self.kinds(pair)
        if rigid_arms and {ka, kb} == {"object", "robot"}:
            g = pair.b if kb == "robot" else pair.a
            hands = {robot.model.frames[robot.arm(a).ee_frame_id].parentJoint for a in rigid_arms}
            if robot.collision_model.geometryObjects[g].parentJoint in hands:
                return True
        if not fixed:
            return False
        if robot.is_floating and "obstacle" in (ka, kb):
            return False
        fa = self.free_joints_of(robot, ka, pair.a, fixed)
        fb = self.free_joints_of(robot, kb, pair.b, fixed)
        return fa is not None and fb is not None and not fa and not fb

    # ------------------------------------------------------------------ expressions
    def _entity(self, tp: Transcription, kind: str, idx: int, k: int
                ) -> tuple[Sequence[D.Shape], Expr, Expr] | None:
        """(shapes list, R, p) of an entity at knot k; kind in robot/obstacle/object."""
        if kind == "robot":
            spec = self.robot_shape.get(idx)
            if spec is None:
                return None
            fid, shape, Mbox = spec
            R, p = tp.frame(fid, k)
            if Mbox is not None:
                return [shape], R @ ca.DM(Mbox.rotation), p + R @ ca.DM(Mbox.translation)
            return [shape], R, p
        if kind == "obstacle":
            o = self.checker.obstacles[idx]
            # Obstacle.primitive is not annotated yet
            return [o.primitive()], ca.DM(o.placement.rotation), ca.DM(o.placement.translation)  # type: ignore[no-untyped-call]
        Rh, ph = tp.frame(self._hand_frame, k)
        G = self.grasp_inv
        return self._obj_caps, Rh @ ca.DM(G.rotation), ph + Rh @ ca.DM(G.translation)

    def _dist_fn(self, s1: D.Shape, s2: D.Shape) -> ca.Function | None:
        key = (repr(s1), repr(s2))
        if key not in self._fns:
            if isinstance(s1, D.Box) and isinstance(s2, D.Box):
                self._fns[key] = None
            else:
                self._fns[key] = D.make_distance_function(s1, s2, eps=self.eps, cover_tol=self.cover_tol)
        return self._fns[key]

    @staticmethod
    def kinds(pair: Pair) -> tuple[str, str]:
        return {"self": ("robot", "robot"), "robot-obstacle": ("robot", "obstacle"),
                "object-obstacle": ("object", "obstacle"), "object-robot": ("object", "robot")}[pair.kind]

    def _local_points(self, kind: str, idx: int
                      ) -> tuple[np.ndarray, float, Callable[[Transcription, int], tuple[Expr, Expr]]]:
        """(local points 3×m, radius, placement getter) of an entity for the plane formulation."""
        if kind == "obstacle":
            o = self.checker.obstacles[idx]
            if o.shape == "box":
                V = np.array(_box_vertices(np.asarray(o.size) / 2)).T
                r = 0.0
            elif o.shape == "sphere":
                assert o.radius is not None  # narrowing only: a sphere obstacle has its radius
                V, r = np.zeros((3, 1)), o.radius
            else:
                assert o.radius is not None and o.length is not None  # narrowing only: a capsule has both
                V, r = np.array([[0, 0, -o.length / 2], [0, 0, o.length / 2]]).T, o.radius
            M = o.placement
            return V, r, lambda tp, k: (ca.DM(M.rotation), ca.DM(M.translation))
        if kind == "object":
            assert self.checker.object is not None  # narrowing only: an object pair has the held object
            V = np.array(_box_vertices(np.asarray(self.checker.object.size) / 2)).T
            G = self.grasp_inv

            def obj_pose(tp: Transcription, k: int) -> tuple[Expr, Expr]:
                Rh, ph = tp.frame(self._hand_frame, k)
                return Rh @ ca.DM(G.rotation), ph + Rh @ ca.DM(G.translation)
            return V, 0.0, obj_pose
        spec = self.robot_shape[idx]
        assert spec is not None  # narrowing only: pairs without an NLP model are skipped before
        fid, shape, Mbox = spec
        if isinstance(shape, D.Box):
            V = np.array([Mbox.act(v) for v in _box_vertices(np.asarray(shape.half_extents))]).T
            r = 0.0
        elif isinstance(shape, D.Sphere):
            V, r = np.asarray(shape.center, float).reshape(3, 1), shape.radius
        else:
            V, r = np.array([shape.a, shape.b], float).T, shape.radius
        return V, r, lambda tp, k: tp.frame(fid, k)

    def _plane_fn(self, Va: np.ndarray, ra: float, Vb: np.ndarray, rb: float) -> ca.Function:
        """SX Function (Ra, pa, Rb, pb, nb) -> plane residuals, cached per shape pair."""
        key = (Va.tobytes(), ra, Vb.tobytes(), rb)
        if key not in self._pfns:
            Ra, Rb = ca.SX.sym("Ra", 3, 3), ca.SX.sym("Rb", 3, 3)
            pa, pb, nb = ca.SX.sym("pa", 3), ca.SX.sym("pb", 3), ca.SX.sym("nb", 4)
            n, b = nb[:3], nb[3]
            Pa = Ra @ ca.DM(Va) + ca.repmat(pa, 1, Va.shape[1])
            Pb = Rb @ ca.DM(Vb) + ca.repmat(pb, 1, Vb.shape[1])
            r = ca.vertcat((b - n.T @ Pa - ra).T, (n.T @ Pb - b - rb).T, 1.0 - ca.sumsqr(n))
            self._pfns[key] = ca.Function(f"plane_{len(self._pfns)}", [Ra, pa, Rb, pb, nb], [r])
        return self._pfns[key]

    def _is_box(self, kind: str, idx: int) -> bool:
        if kind == "object":
            return True
        if kind == "obstacle":
            return self.checker.obstacles[idx].shape == "box"
        spec = self.robot_shape.get(idx)
        return spec is not None and isinstance(spec[1], D.Box)

    def _plane_init(self, pair: Pair, q_full: np.ndarray) -> np.ndarray:
        """(n, b) from coal's witness points at a configuration (normal from A to B)."""
        Mo = self.checker.update_placements(q_full)
        return witness_plane(self.checker, pair, coal.Transform3s(Mo.rotation, Mo.translation) if Mo is not None else None)

    def build_rows(self, ctx: BuildContext) -> TermData:
        """The rows of the term for one NLP (``ctx``: the transcription, initial guess, pinned
        knots, fixed joints); ``info`` holds this model and what it decided."""
        tp = ctx.tp
        robot = tp.robot
        self.skipped = []
        init = ctx.initial
        active = self.activate(robot, init)
        fixed = ctx.fixed_joints if self.skip_constant else frozenset()
        self.constant_pairs = [p for p in active if self.is_constant(robot, p, fixed)]
        if self.constant_pairs:
            self.active_pairs = active = [p for p in active if p not in self.constant_pairs]
            log.info("collision term: %d pair(s) with no free joint left out: %s", len(self.constant_pairs),
                     [(p.name_a, p.name_b) for p in self.constant_pairs[:5]])
        self._plane_slots = []  # (pair, k, aux index) for refreshing the initial planes
        aux: list[AuxVariable] = []
        rs: list[Expr] = []
        lo: list[float] = []
        pinned = set(ctx.pinned_q) if self.skip_pinned else set()
        margin_at = self.boundary_margins(tp, init, active, pinned)
        knots_of: Callable[[Pair], list[int]] = lambda pair: [k for k in self.knots_of(pair, tp.N) if k not in pinned]  # noqa: E731
        for pair in active:
            ka, kb = self.kinds(pair)
            if (ka == "robot" and self.robot_shape.get(pair.a) is None) or \
                    (kb == "robot" and self.robot_shape.get(pair.b) is None):
                self.skipped.append(pair)
                continue
            if self._is_box(ka, pair.a) or self._is_box(kb, pair.b):
                Va, ra, pose_a = self._local_points(ka, pair.a)
                Vb, rb, pose_b = self._local_points(kb, pair.b)
                fn = self._plane_fn(Va, ra, Vb, rb)
                nrow = Va.shape[1] + Vb.shape[1]
                for k in knots_of(pair):
                    x0 = self._plane_init(pair, init.q_full(k)) if init is not None else np.r_[1.0, 0, 0, 0]
                    a = AuxVariable.create(f"plane_{len(self._plane_slots)}", 4, x0, *self._plane_bounds(x0))
                    aux.append(a)
                    v = a.sym
                    self._plane_slots.append((pair, k, len(aux) - 1))
                    Ra_, pa_ = pose_a(tp, k)
                    Rb_, pb_ = pose_b(tp, k)
                    rs.append(fn(Ra_, pa_, Rb_, pb_, v))
                    lo += [margin_at(pair, k) / 2] * nrow + [0.0]
                continue
            for k in knots_of(pair):
                ea = self._entity(tp, ka, pair.a, k)
                eb = self._entity(tp, kb, pair.b, k)
                assert ea is not None and eb is not None  # narrowing only: pairs without a model were skipped
                for sa in ea[0]:
                    for sb in eb[0]:
                        # a smooth pair (no box: those have planes above), so there is a distance function
                        rs.append(cast(ca.Function, self._dist_fn(sa, sb))(ea[1], ea[2], eb[1], eb[2]))
                        lo.append(margin_at(pair, k))
        if self.skipped:
            log.info("collision term: %d pair(s) without an NLP model: %s", len(self.skipped),
                     [(p.name_a, p.name_b) for p in self.skipped[:5]])
        info = {"model": self, "active_pairs": tuple(self.active_pairs), "constant_pairs": tuple(self.constant_pairs),
                "skipped": tuple(self.skipped), "relaxed": dict(self.relaxed), "plane_slots": tuple(self._plane_slots),
                "active_knots": dict(self.active_knots)}
        if not rs:
            return TermData(residual=ca.MX.zeros(0), lower=np.zeros(0), upper=np.zeros(0), info=info)
        r = ca.vertcat(*rs)
        return TermData(residual=r, lower=np.array(lo), upper=np.full(r.shape[0], np.inf), aux=tuple(aux), info=info)

    def boundary_margins(self, tp: Transcription, init: NumericTrajectory | None, active: list[Pair],
                         pinned: set[int]) -> Callable[[Pair, int], float]:
        """``margin_at(pair, k)`` [m]: ``margin``, except within ``window`` knots of a pinned knot
        whose given configuration is closer than ``margin`` for that pair: there
        ``min(margin, d_pinned / 2)``. Next to a pinned knot (rest: zero rate and acceleration)
        the joints move by O(h³ jerk), so a boundary configuration inside the margin would make the
        neighbouring rows need a huge jerk. See docs/decisions/0010-knot-transcription-defaults.md."""
        self.relaxed = {}
        if init is not None and pinned:
            idx = [self.checker.pair_index[p] for p in active]
            w = int(self.window)
            D0 = self._init_dist
            for kp in sorted(pinned):
                qf = init.q_full(kp)
                d = (D0[kp] if D0 is not None and D0.shape[0] == tp.N + 1 else self.checker.distances(qf))[idx]
                for p, dp in zip(active, d):
                    if dp < self.margin and self._smooth_pair(p):
                        dp = self._smooth_value(tp.robot, p, qf)  # the row's own (conservative) value
                    if dp < self.margin:
                        m = min(self.margin, 0.5 * float(dp))
                        for k in range(max(0, kp - w), min(tp.N, kp + w) + 1):
                            self.relaxed[(p, k)] = min(m, self.relaxed.get((p, k), np.inf))
        if self.relaxed:
            log.info("collision term: margin relaxed at %d (pair, knot) rows next to boundary configurations "
                     "closer than %.3g m", len(self.relaxed), self.margin)
        return self._margin_at

    def _margin_at(self, pair: Pair, k: int) -> float:
        """Lower bound [m] of the pair's rows at knot k: ``margin``, relaxed next to close boundary
        configurations (``relaxed``), plus any ``margin_boost``."""
        return self.relaxed.get((pair, k), self.margin) + self.margin_boost.get((pair, k), 0.0)

    def boost_between_knots(self, traj_t: np.ndarray, traj_q: ArrayLike, knot_t: ArrayLike,
                            min_clearance: float = 0.0) -> int:
        """Raise the margin of the pairs that collide *between* knots of a solution.

        ``traj_t`` [s], ``traj_q``: the solution sampled finely (e.g. 10 per interval) — full
        Pinocchio configurations, or joint vectors for a fixed-base robot; ``knot_t`` [s]: its
        knot times. For every pair whose exact distance at a sample
        is below ``min_clearance`` [m], the margin at the two knots around that sample grows by
        ``margin − d`` (d: the smallest distance in the interval), so that a re-solve keeps the
        pair clear of the sweep between the knots (the knots alone held the margin, the motion
        between them cut the corner; see docs/decisions/0010-knot-transcription-defaults.md). Returns the number of (pair, knot) rows boosted; call
        :meth:`OptProblem.rebuild` afterwards."""
        robot = self.checker.robot
        knot_t = np.asarray(knot_t, float)
        Q = np.atleast_2d(np.asarray(traj_q, float))
        if Q.shape[1] != robot.nq:
            if robot.is_floating or Q.shape[1] != robot.nj:
                raise ValueError(f"boost_between_knots: expected configurations of size {robot.nq}"
                                 f"{'' if robot.is_floating else f' or joint vectors of size {robot.nj}'}, "
                                 f"got shape {Q.shape}")
            Q = np.array([robot.configuration(q) for q in Q])
        if len(Q) != len(traj_t):
            raise ValueError(f"boost_between_knots: {len(traj_t)} times for {len(Q)} configurations")
        rows, idx, dist = self.checker.distances_below(Q, min_clearance)   # exact, pairs that cannot be close skipped
        n = 0
        active = set(self.active_pairs)
        for i, p in enumerate(self.checker.pairs):
            if p not in active:
                continue  # not constrained at all: activation (``activate_with``) is the remedy
            ks = set(self.knots_of(p, len(knot_t) - 1))
            mine = idx == i
            worst: dict[int, float] = {}
            for s_, d_ in zip(rows[mine].tolist(), dist[mine].tolist()):
                k = int(np.clip(np.searchsorted(knot_t, traj_t[s_], side="right") - 1, 0, len(knot_t) - 2))
                worst[k] = min(worst.get(k, np.inf), float(d_))
            for k, d in worst.items():
                if k not in ks or k + 1 not in ks:
                    continue  # a knot next to it was unconstrained: activation widens the window
                for kk in (k, k + 1):
                    self.margin_boost[(p, kk)] = self.margin_boost.get((p, kk), 0.0) + (self.margin - d)
                    n += 1
        return n

    def _smooth_pair(self, pair: Pair) -> bool:
        ka, kb = self.kinds(pair)
        return not (self._is_box(ka, pair.a) or self._is_box(kb, pair.b))

    def _smooth_value(self, robot: RobotModel, pair: Pair, q_full: np.ndarray) -> float:
        """Smallest smooth-distance row [m] of a sphere/capsule pair at a configuration (what the
        NLP's rows evaluate to there; ≤ the exact distance)."""
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, q_full)

        def entity(kind: str, idx: int) -> tuple[Sequence[D.Shape], np.ndarray, np.ndarray]:
            if kind == "obstacle":
                o = self.checker.obstacles[idx]
                # Obstacle.primitive is not annotated yet
                return [o.primitive()], o.placement.rotation, o.placement.translation  # type: ignore[no-untyped-call]
            if kind == "object":
                M = data.oMf[robot.frame_id(self._hand_frame)] * self.grasp_inv
                return self._obj_caps, M.rotation, M.translation
            spec = self.robot_shape[idx]
            assert spec is not None  # narrowing only: a smooth pair's robot geometries have a model
            fid, shape, _ = spec
            M = data.oMf[robot.frame_id(fid)]
            return [shape], M.rotation, M.translation

        ka, kb = self.kinds(pair)
        ea, eb = entity(ka, pair.a), entity(kb, pair.b)
        # a smooth pair (no box), so there is a distance function
        return min(float(cast(ca.Function, self._dist_fn(sa, sb))(ea[1], ea[2], eb[1], eb[2]))
                   for sa in ea[0] for sb in eb[0])

    def _plane_bounds(self, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of a plane variable (n, b): free, or n held at x0's normal (``fixed_normals``)."""
        if not self.fixed_normals:
            return np.full(4, -np.inf), np.full(4, np.inf)
        return np.r_[x0[:3], -np.inf], np.r_[x0[:3], np.inf]

    def reseed(self, data: TermData, traj: NumericTrajectory) -> tuple[AuxVariable, ...]:
        """``data.aux`` with the separating planes (and, with ``fixed_normals``, their fixed
        normals) re-seeded from a new initial guess (same active pairs)."""
        aux = list(data.aux)
        for pair, k, i in data.info["plane_slots"]:
            x0 = self._plane_init(pair, traj.q_full(k))
            lo, hi = self._plane_bounds(x0)
            aux[i] = dataclasses.replace(aux[i], init=_ro(x0), lower=_ro(lo), upper=_ro(hi))
        return tuple(aux)

    def numeric(self, traj: NumericTrajectory) -> np.ndarray:
        """Exact coal distances of the active pairs at every knot, ``(N+1) × n_active``."""
        idx = [self.checker.pair_index[p] for p in self.active_pairs]
        return np.array([self.checker.distances(traj.q_full(k))[idx] for k in range(traj.N + 1)])

    def bounds_numeric(self, traj: NumericTrajectory) -> tuple[np.ndarray, np.ndarray]:
        D = self.numeric(traj)
        lo = np.full(D.shape, self.margin)
        for j, p in enumerate(self.active_pairs):
            for k in range(D.shape[0]):
                lo[k, j] = self._margin_at(p, k)
        return lo.reshape(-1), np.full(D.size, np.inf)
