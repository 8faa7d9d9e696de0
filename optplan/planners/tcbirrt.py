"""TCBiRRT — task-space constrained bidirectional RRT (the TCBiRRT paper, Alg. 1-4 and Section 4.3).

Two trees grow in the object's pose space ξ = [p; roll, pitch, yaw] (RPY as in Eq. 2,
``R = Rz(yaw) Ry(pitch) Rx(roll)``). Each node holds (q, ξ).

* RandomSampleT: ξ uniform in the box ``[xi_lower, xi_upper]`` (paper: [-2,-3,0,-π,-π,-π] ..
  [2,3,4,π,π,π], base frame = world).
* NearestNeighborT: Euclidean distance in ξ.
* ConstrainedExtendT (Alg. 2): ``ξ_s = ξ_near + min(s_ξ, d) (ξ_rand − ξ_near)/d`` (Eq. 3), N object
  poses from ξ_near to ξ_s (position linear, orientation linear in exponential coordinates, Eq. 4),
  PathInverseKinematics (Alg. 3: IK of each pose seeded by the previous solution), IK = Alg. 4
  (damped pseudo-inverse iterations on each hand's pose error, Eq. 5-8), every configuration
  collision-checked; Trapped / Advanced / Reached.
* Connection (Alg. 1 lines 7-11): tree b is extended toward tree a's new node until Trapped or
  Reached; when it reaches ξ of that node with a different joint solution, the two solutions are
  joined by a **regrasp** (Section 4.3, below). A failed regrasp counts as Trapped. A step whose
  node is no nearer the target in ξ than the node it grew from ends the connection too (not in the
  paper: a partial step's node keyed across an angle's ±π can be farther in ξ though nearer on the
  manifold, and the loop would grow the same node from the same node without end).

Regrasp (Section 4.3). The paper: "the same object pose ξ_I corresponds to two joint solutions
q_a, q_b"; the motion between them "can be interpreted as a regrasp ... an unconstrained motion
planning problem" solved by RRTConnect, during which "the manipulators must transition to new
joint configurations *sequentially* while maintaining the pose of the manipulated object
unchanged", and "only one manipulator or neither" moves when the solutions are close. We read it
as: the object stays at ξ_I; the arms move ONE AT A TIME: one arm holds the object while the other
lets go, moves on an unconstrained joint-space RRTConnect path (its 7 joints; the rest of the robot
fixed; the object a fixed obstacle) to its new joint solution and grasps again; then the other
arm does the same. An arm whose two solutions agree within ``regrasp_tolerance`` does not move.
Both orders (A first, B first) are tried. In the returned :class:`PlanResult` each such motion is
a ``"regrasp"`` segment (``constrained`` False inside it, True at its ends, where both hands are on
the object again).

``TCBiRRTOptions(variant="improved")`` adds task-space sampling aids (an object-only lead path,
start-goal geodesic orientations, a reach/collision filter, bridge tests, goal bias) and keeps the
valid prefix of a failed extension; see :class:`TCBiRRTOptions` and :mod:`.task_sampling`. The
default ``variant="paper"`` is the published algorithm.

Deviations from the paper, all options (defaults in brackets):

* ``interpolation`` ["geodesic"]: Eq. 4 applied to the relative rotation,
  ``R_j = R_near exp(j/N log(R_nearᵀ R_s))``. The literal Eq. 4 on absolute exponential
  coordinates ("absolute") swings through a full turn when the two rotations sit on either side
  of |φ| = π; "absolute" here unwraps φ_s to the representative nearest φ_near, which makes the
  two agree to first order. Same end poses either way.
* ``max_joint_step`` [paper 0.5 rad, improved 0.25 rad]: PathInverseKinematics counts a waypoint as failed when its IK
  solution jumps by more than this from the previous one (the paper seeds IK with the previous
  solution "to maintain the continuity of the joint motion"; this makes that a guarantee).
* ``edge_resolution`` [None]: the paper checks only the N+1 configurations of an extension; with a
  value [rad], the straight joint-space segments between consecutive configurations are checked
  too (every ``edge_resolution`` rad).
* ``joint_connect`` [False in both variants; see docs/decisions/0004-tcbirrt-improved-variant.md]: the trees are joined in JOINT space when the
  task-space connection cannot do it — CBiRRT2's ConstrainedExtend (Newton projection onto the
  closed chain, :class:`.CBiRRT2`, options ``joint_connect_options``) from tree b's configuration
  toward tree a's: (1) when the connect step reaches tree a's object pose with another joint
  solution, before a regrasp is tried (a regrasp releases a hand; the joint-space motion keeps
  both hands on the object); (2) when the connect step is trapped within ``joint_connect_radius``
  (ξ distance) of tree a's node; both only when the two configurations are within
  ``joint_connect_max_distance`` [rad, Euclidean] (farther ones are other IK branches). Its configurations close the chain to the projection tolerance
  and form a ``"constrained"`` part of the path.
* ``branch_grafts`` [paper 0; improved 4 per tree, from iteration ``graft_after`` = 1500]: a tree grows
  other IK branches of its own nodes. Constrained motion keeps each arm on its IK branch, so two trees
  on different branches meet only through a regrasp at the meeting pose, which in a tight passage
  often cannot be planned. Every ``graft_interval`` iterations one tree (in turn) takes a node — its
  root first, then the node nearest a random node of the other tree — solves the node's object pose
  by IK seeded from the other tree's configuration nearest in ξ (then perturbed, then random seeds),
  and when that solution is valid and another branch (≥ ``graft_min_distance`` away), joins it to
  the node by a regrasp (Section 4.3, ``graft_time_limit``): a "graft" node at the same pose. The
  extension picks one of a pose's branches at random, the connection the one nearest the other
  tree's configuration; a path through a graft has its regrasp segments where the graft is.
* ``frontier_grafts`` [paper 0; improved 4 per tree, every ``frontier_interval`` = 50 iterations after
  ``graft_after``]: at the node nearest the other tree, the arms re-grasp (one arm, or both) into an IK
  solution from random seeds that is valid AND from which one constrained step toward the other tree
  passes; the solution is a graft node, the step's end a node below it, and tree b is connected to it
  (:mod:`.frontier_graft`). Where the arms, not the object, block a passage, each tree's arms stop in a
  self-motion position that collides one step further on; the look-ahead picks one that does not.
* ``trap_grafts`` [paper 0 (off); improved 4, toward the sample, on own streams, after 1,500 iterations; see
  docs/generalization.md]: a node from which the extension
  toward a sample has been trapped ``trap_graft_count`` times gets, once, a look-ahead graft
  (:func:`.frontier_graft.lookahead_graft`): the arms re-grasp at its pose into an IK solution from which one
  constrained step toward ``trap_graft_target`` (the other tree's nearest node, or the trapping sample) passes.
  Unlike the frontier grafts it does not wait for ``graft_after`` (unless ``trap_graft_after`` is set): it aims at
  the node where the tree is stuck (in a deep bay, the arms of the goal's IK branch cannot carry the object out).
* ``branch_roots`` [False in both variants; measured in docs/planners.md]: before the search, the goal tree's
  root is re-grasped onto the start's IK branch at the goal's object pose (arm by arm; the branch found by path IK
  along the straight start-goal object motion, :meth:`~.tcbirrt_grafts.BranchMixin.branch_at`), or, where that
  configuration collides, the start's root onto the goal's branch; the tree grows from that graft. Trees on one
  branch can meet without a regrasp of a whole branch change.
* ``restart_iterations`` [0 (off) in both variants; measured in docs/planners.md]: a search without a path after
  that many iterations starts again from the two roots (lead path kept; the budget grows ``restart_growth``× per
  restart); with ``restart_branch_roots`` every second search has ``branch_roots`` the other way.
* ``filter_robot_body`` [False in both variants; measured in docs/generalization.md]: the task-space filter, and so the
  object's lead path, counts the robot's fixed body (its base) as an obstacle: in a bay opening towards the robot the
  object-only lead otherwise runs the object through the base, and the trees follow it until the arms cannot.
* ``stall_iterations`` [0 (off) in both variants; measured in docs/planners.md]: a frontier graft is also tried
  when the smallest ξ gap a connection has left between the trees (0 once a connection reached the other tree's
  pose and only its regrasp failed) has not shrunk by 1 % for that many iterations, before ``graft_after``.
* ``edge_tolerance`` [paper 0: off; improved 0.01 m]: the straight joint-space segments between consecutive
  configurations (constrained edges and regrasp motions) are checked so densely that no point of
  the arms or the object moves farther than this between two checks (per-joint sweep bound of
  :meth:`.ValidityChecker.sweep_weights`): a path is collision-free along its edges, not only at its
  configurations, up to obstacles or contacts thinner than ``edge_tolerance``. ``edge_bound``
  [paper and improved "jacobian"] picks the bound that spaces those checks: ``"jacobian"``
  (:meth:`.ValidityChecker.edge_checkpoints`: each geometry's speed from the Jacobian at the
  edge's cell ends plus a second-order remainder — an arm's self-motion moves joints a lot and
  the geometry little, and is counted as such) or ``"static"`` (the configuration-free
  per-geometry bound ``Σ_j W_gj |Δq_j|``); both are conservative, and ``"certified"``: no spacing at
  all, each edge is certified collision-free at every point by conservative advancement on exact
  distances (:meth:`.ValidityChecker.edge_is_certified`; every pair stays at least
  ``edge_min_clearance / 2`` apart), so ``verify_path`` is not needed and not done. With ``verify_path`` [paper False,
  improved True] and the Jacobian bound, a start-goal path, once found, has its edges checked once
  more at the configuration-free bound's uniform spacing: a second, different sampling at the same
  tolerance (a graze shallower than the tolerance that one sampling misses, the other may
  catch); a failing tree edge removes its node and that node's subtree, a failing regrasp motion
  the connection, and the search goes on. With
  ``lazy_edges`` [False] the constrained edges are checked only once they lie on a
  start-goal path; an edge that fails removes its node and that node's subtree from the tree and
  the search goes on (lazy collision checking, as LazyPRM / LazyRRT).
"""
from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from typing import Any, cast

import numpy as np

from ..constraints.closed_chain import ClosedChainKinematics, closure_error
from ..errors import ConfigurationError
from ..model.robot import RobotModel
from ..scene import Scene
from .base import Deadline, Planner, PlanResult, PlanStatus
from .cbirrt2 import CBiRRT2
from .frontier_graft import frontier_graft
from .ik_seed import predicted_seed, restart_seed
from .rrtconnect import edge_is_valid
from .task_sampling import ObjectPoseFilter
from .task_space import exp_coordinates, interpolate_task, pose_from_xi, rotation_from_exp, xi_from_pose
from .tcbirrt_edges import EdgeCheckMixin
from .tcbirrt_lead import LeadState, lead_attempt
from .tcbirrt_native import loop_extend, make_extender, native_extend, native_path_ik, poses_array
from .tcbirrt_options import (
    PAPER_REACH,
    PAPER_XI_LOWER,
    PAPER_XI_UPPER,
    VARIANTS,
    TCBiRRTOptions,
    reach_scaled_workspace,
)
from .tcbirrt_sampling import SamplingMixin, _twin_of, _xi_of_pose
from .tcbirrt_streak import STREAK_CONNECT, STREAK_CONNECTED, STREAK_DONE, STREAK_EXTENDED, STREAK_SAMPLED, NativeStreak
from .tcbirrt_traps import ADVANCED, PARTIAL, REACHED, TRAPPED, TrapMixin, no_nearer
from .tcbirrt_tree import _TaskTree as _TaskTree  # re-exported: frontier_graft types its trees with it
from .tcbirrt_tree import extract_path
from .validity import ValidityChecker

__all__ = ["TCBiRRTOptions", "TCBiRRT", "exp_coordinates", "rotation_from_exp", "interpolate_task",
           "xi_from_pose", "pose_from_xi", "PAPER_XI_LOWER", "PAPER_XI_UPPER", "PAPER_REACH", "VARIANTS",
           "reach_scaled_workspace"]
log = logging.getLogger(__name__)


# ---------------------------------------------------------------------- planner
class TCBiRRT(TrapMixin, EdgeCheckMixin, SamplingMixin, Planner):
    """TCBiRRT for a robot holding ``scene.object`` with two arms (``scene.object.grasps``).

    ``plan(q_start, q_goal, time_limit=10, seed=0)``: both configurations must hold the object
    (closed chain within ``closure_tolerance``), be inside the joint limits and collision-free.
    """

    name = "tcbirrt"
    scene: Scene   # __init__ refuses a scene without an object

    def __init__(self, robot: RobotModel, scene: Scene, options: TCBiRRTOptions | None = None, *,
                 checker: ValidityChecker | None = None, kinematics: ClosedChainKinematics | None = None):
        super().__init__(robot, scene)
        if scene is None or scene.object is None or len(scene.object.grasps) != 2:
            raise ConfigurationError("TCBiRRT needs a scene with an [object] grasped by two arms")
        self.options = options or TCBiRRTOptions()
        if not isinstance(self.options, TCBiRRTOptions):
            raise TypeError(f"options: expected TCBiRRTOptions, got {type(self.options).__name__}")
        self.checker = checker or ValidityChecker(robot, scene, margin=self.options.margin,
                                                   kernel=self.options.validity_kernel)
        self.kin = kinematics or ClosedChainKinematics(robot, scene.object.grasps)
        self.grasps = scene.object.grasps
        self._lo, self._hi, self.step_size = reach_scaled_workspace(robot, self.options)
        self._filter: ObjectPoseFilter | None = None
        self._w_held = self.checker.sweep_weights("held", per_geometry=True)
        self._w_fixed = self.checker.sweep_weights("fixed", per_geometry=True)
        if self.options.edge_tolerance and self.options.edge_bound in ("jacobian", "certified"):
            self.checker.prepare_edge_checks(("held", "fixed"))   # compiled once, before any time limit
            if self.options.edge_bound == "certified":
                self.checker.certifier(self.options.edge_min_clearance).prepare(("held", "fixed"))
        self._cb: CBiRRT2 | None = None
        self._rng = np.random.default_rng(0)
        #: the IK settings of a waypoint's restarts (``ik_restart_iterations``)
        self._ik_restart = self.options.ik if not self.options.ik_restart_iterations else \
            dataclasses.replace(self.options.ik, max_iterations=int(self.options.ik_restart_iterations))
        #: the extension step in native code (:mod:`.tcbirrt_native`), None: in Python
        self._ext = make_extender(self) if self.checker.kernel == "native" and self.options.extension != "python" else None
        #: ``extension="loop"``: the query's native random stream (sampler, lead path, restarts), None: NumPy's
        self._nrng: Any = None
        #: the look-ahead grafts' candidate loop in native code (:class:`.tcbirrt_lookahead.NativeLookahead`), None: in Python
        self._la: Any = None
        #: ξ → (R, p) of an extension's target: Pinocchio's, or with the native loop the native code's (:class:`.NativePose`)
        self._pose: Any = pose_from_xi
        #: (R, p) → ξ of a partial extension's node: Pinocchio's, or with the native loop the native code's (:class:`.NativeXi`)
        self._xi_of: Any = _xi_of_pose
        #: (tree, node, q, rng) → the node's twin nearest q (:meth:`._TaskTree.twin_nearest`), or the native code's (:class:`.NativeTwin`)
        self._twin_of: Any = _twin_of
        #: restarts: the object's lead path found by an earlier search of the query and what was spent on it
        self._lead = LeadState()

    # ------------------------------------------------------------------ public helpers
    def check_endpoint(self, q: np.ndarray) -> str | None:
        """None when ``q`` is a valid start/goal, else the reason."""
        ck = self.checker
        if not ck.in_limits(q):
            return "outside the joint limits"
        ep, eo = closure_error(self.robot, self.grasps, q)
        if ep > self.options.closure_tolerance or eo > self.options.closure_tolerance:
            return f"closed chain violated ({ep:.1e} m, {eo:.1e} rad > {self.options.closure_tolerance:g})"
        if not ck.is_valid(q):
            return "in collision: " + ", ".join(f"{a}/{b}" for a, b in ck.colliding_pairs(q)[:3])
        return None

    # ------------------------------------------------------------------ Alg. 3
    def path_ik(self, poses: list[tuple[np.ndarray, np.ndarray]], q_near: np.ndarray, st: dict[str, Any], prefix: bool = False) -> list[np.ndarray] | None:
        """PathInverseKinematics + CollisionFree of Alg. 2: IK of every pose seeded by the previous
        solution; None at the first failure (IK, continuity or collision) — or, with ``prefix``,
        the solutions before it (possibly empty)."""
        if self._ext is not None:
            return native_path_ik(self, poses_array(poses), q_near, st, prefix)
        o, kin, ck = self.options, self.kin, self.checker
        out, q, qpp = [], q_near, None  # type: list[np.ndarray], np.ndarray, np.ndarray | None
        fail = None if not prefix else out
        for R, p in poses:
            st["ik_calls"] += 1
            qn, its = kin.ik(predicted_seed(cast(str, o.ik_predictor), q, qpp, kin.lower, kin.upper), R, p, o.ik)
            st["ik_iterations"] += its
            st["ik_path_iterations"] = st.get("ik_path_iterations", 0) + its   # absent in a caller's own counters
            if qn is None:
                st["ik_failures"] += 1
            elif float(np.abs(qn - q).max()) > cast(float, o.max_joint_step):
                st["ik_jumps"] += 1
                qn = None
            elif not ck.is_valid(qn):
                st["collisions"] += 1
                qn = None
            for i in range(cast(int, o.ik_restarts) if qn is None else 0):
                st["ik_restarts"] += 1
                x, its = kin.ik(restart_seed(q, self._rng, o, i), R, p, self._ik_restart)
                st["ik_iterations"] += its
                st["ik_restart_iterations"] = st.get("ik_restart_iterations", 0) + its
                if x is not None and float(np.abs(x - q).max()) <= cast(float, o.max_joint_step) and ck.in_limits(x) \
                        and ck.is_valid(x):
                    qn = x
                    break
            if qn is None:
                return self._edges_prefix(q_near, out, fail, st) if fail is not None else None
            if o.edge_resolution is not None and not edge_is_valid(q, qn, ck.is_valid, o.edge_resolution, False):
                st["collisions"] += 1
                return self._edges_prefix(q_near, out, fail, st) if fail is not None else None
            out.append(qn)
            qpp, q = q, qn
        return self._edges_prefix(q_near, out, fail, st)

    # ------------------------------------------------------------------ Alg. 2
    def constrained_extend(self, tree: _TaskTree, i_near: int, xi_rand: np.ndarray, q_rand: np.ndarray | None,
                           rng: np.random.Generator, deadline: Deadline, st: dict[str, Any],
                           step: float | None = None) -> tuple[str, int, Sequence[tuple[str | None, list[np.ndarray]]] | None]:
        o = self.options
        st["extensions"] += 1
        step = self.step_size if step is None else step
        xi_near = tree.xi[i_near]
        d = xi_rand - xi_near
        dist = math.sqrt(d @ d)   # the float np.sqrt gives (both round the square root correctly)
        if dist <= step:
            xi_s, reach = xi_rand.copy(), True           # ξ_s = ξ_rand exactly
        else:
            xi_s, reach = xi_near + (step / dist) * d, False   # Eq. 3
        R0, p0 = tree.pose[i_near]
        Rs, ps = self._pose(xi_s)
        q_near = tree.q[i_near]
        if dist > 0.0:
            if self._nrng is not None and self._ext is not None and self._ext.edge_on and o.interpolation == "geodesic":
                poses, Q = loop_extend(self, R0, p0, Rs, ps, q_near, st, o.keep_prefix)   # type: ignore[arg-type]  # restarts in C
            elif self._ext is not None and o.interpolation == "geodesic":   # one native call
                poses, Q = native_extend(self, R0, p0, Rs, ps, q_near, st, cast(bool, o.keep_prefix))
            else:
                poses = interpolate_task(R0, p0, Rs, ps, o.n_interp, o.interpolation)
                Q = self.path_ik(poses, q_near, st, prefix=cast(bool, o.keep_prefix))
            if not Q:
                st["trapped"] += 1
                return TRAPPED, -1, None
        else:
            poses, Q = [], [q_near.copy()]
        return self._extended(tree, i_near, xi_s, reach, Rs, ps, poses, Q, q_rand, rng, deadline, st)

    def _extended(self, tree: _TaskTree, i_near: int, xi_s: np.ndarray, reach: bool, Rs: np.ndarray, ps: np.ndarray,
                  poses: list[Any], Q: list[np.ndarray], q_rand: np.ndarray | None, rng: np.random.Generator,
                  deadline: Deadline, st: dict[str, Any]) -> tuple[str, int, Sequence[tuple[str | None, list[np.ndarray]]] | None]:
        """The end of :meth:`constrained_extend` after its path IK: the configurations ``Q`` of the poses ``poses``
        toward ξ_s (pose ``(Rs, ps)``; no poses: ξ_s is the node's), not empty."""
        o = self.options
        if len(Q) < len(poses):          # keep_prefix: the valid part is a shorter extension
            st["partial"] += 1
            k = len(Q)
            Rk, pk = poses[k - 1]
            Rk, pk = np.asarray(Rk), np.asarray(pk)
            i_s = tree.add(Q[-1], self._xi_of(Rk, pk), Rk, pk, i_near, Q[:-1], poses[:k - 1])
            return PARTIAL, i_s, None
        q_s = Q[-1]
        reg: Sequence[tuple[str | None, list[np.ndarray]]] | None = None
        if reach and q_rand is not None:
            dq = float(np.linalg.norm(q_rand - q_s))
            if o.joint_connect and o.regrasp_tolerance < dq <= o.joint_connect_max_distance:
                jp = self.joint_connect(q_s, q_rand, deadline, st)
                if jp is not None:
                    reg = [(None, [q_s.copy(), *jp])]
            if reg is None:
                reg = self.regrasp(q_s, q_rand, Rs, ps, rng, deadline, st)
            if reg is None:
                st["trapped"] += 1
                return TRAPPED, -1, None
        if poses:
            i_s = tree.add(q_s, xi_s, Rs, ps, i_near, Q[:-1], poses[:-1])
        else:
            i_s = i_near
        return (REACHED if reach else ADVANCED), i_s, reg

    def _sample_near(self, ta: _TaskTree, tb: _TaskTree, sampler: Any, rng: np.random.Generator,
                     st: dict[str, Any]) -> tuple[np.ndarray, int]:
        """Alg. 1 lines 3-4: ξ_rand and the node of ``ta`` to extend from. With ``trap_adapt="domain"`` a sample
        outside its nearest node's dynamic domain is drawn again (up to ``domain_tries`` draws). A native sampler
        (``extension="loop"``) draws and finds the nearest node in one call."""
        o = self.options
        if self._nrng is not None:   # the native sampler (the streaks' draws: the same test of the domain)
            for _ in range(o.domain_tries if o.trap_adapt == "domain" else 1):
                xi_rand, i_near = sampler.sample_near(ta.X, ta.n, ta.alive if ta.n_dead else None,
                                                      tb.X, tb.n, tb.alive if tb.n_dead else None, ta.kd)
                if o.trap_adapt != "domain":
                    break
                x, e, d = ta.X[i_near], 0.0, float(ta.dom[i_near])
                for k in range(6):   # the streaks' arithmetic, term by term
                    u = float(xi_rand[k]) - float(x[k])
                    e += u * u
                if e <= d * d:
                    break
                st["domain_rejections"] = st.get("domain_rejections", 0) + 1
            return xi_rand, ta.twin_nearest(i_near, None, rng)
        for _ in range(o.domain_tries if o.trap_adapt == "domain" else 1):
            # lo + (hi − lo) u: Generator.uniform's formula and draws, without its argument checks
            xi_rand = self._lo + (self._hi - self._lo) * rng.random(6) if sampler is None else sampler.sample(rng, tb.alive_xi())
            i_near = ta.nearest(xi_rand)
            if o.trap_adapt != "domain" or float(np.sum((xi_rand - ta.xi[i_near]) ** 2)) <= ta.dom[i_near] ** 2:
                break
            st["domain_rejections"] = st.get("domain_rejections", 0) + 1
        return xi_rand, ta.twin_nearest(i_near, None, rng)

    # ------------------------------------------------------------------ restarts
    def _plan(self, q_start: np.ndarray, q_goal: np.ndarray, deadline: Deadline, rng: np.random.Generator, seed: int) -> PlanResult:
        """Alg. 1 (:meth:`_search`); with ``restart_iterations`` the search starts again from the two roots (new
        trees; the object's lead path, once found, kept; with ``restart_branch_roots`` every second search with
        ``branch_roots`` the other way), on the query's random stream as it has gone on, each time a search has run its iteration budget without a path
        (the budget grows by ``restart_growth`` per restart; the last one ends at ``max_iterations`` or the time
        limit). Counters of ``stats`` are summed over the searches; ``restarts`` counts the searches abandoned."""
        o = self.options
        budget = float(cast(int, o.restart_iterations))
        self._lead = LeadState()
        if not budget:
            return self._search(q_start, q_goal, deadline, rng, seed, o.max_iterations, bool(o.branch_roots))
        done: dict[str, float] = {}
        n_restarts = 0
        while True:
            cap = max(1, int(round(budget)))
            last = bool(o.max_iterations) and done.get("iterations", 0) + cap >= o.max_iterations
            if last:
                cap = o.max_iterations - int(done.get("iterations", 0))
            roots = bool(o.branch_roots) != (bool(o.restart_branch_roots) and n_restarts % 2 == 1)
            res = self._search(q_start, q_goal, deadline, rng, seed, cap, roots)
            for k, v in done.items():   # the counters of the abandoned searches
                if isinstance(res.stats.get(k, 0), (int, float)) and not isinstance(v, bool):
                    res.stats[k] = res.stats.get(k, 0) + v
            res.stats["restarts"] = n_restarts
            if res.status != PlanStatus.FAILED or last or deadline.expired() or "iteration cap" not in res.message:
                return res
            done = {k: v for k, v in res.stats.items() if isinstance(v, (int, float)) and not isinstance(v, bool)
                    and k not in ("restarts", "guide_waypoints")}
            n_restarts += 1
            budget *= o.restart_growth

    # ------------------------------------------------------------------ Alg. 1
    def _search(self, q_start: np.ndarray, q_goal: np.ndarray, deadline: Deadline, rng: np.random.Generator, seed: int,
                max_iterations: int, branch_roots: bool) -> PlanResult:
        """Alg. 1 from the two roots; at most ``max_iterations`` iterations (0: until the deadline); ``branch_roots``:
        the goal root re-grasped onto the start's IK branch first (:meth:`_root_branches`)."""
        o = self.options
        self._rng = rng
        st: dict[str, Any] = {k: 0 for k in ("iterations", "extensions", "trapped", "partial", "ik_calls", "ik_iterations", "ik_restarts",
                             "ik_failures", "ik_jumps", "collisions", "regrasp_attempts", "regrasp_failures",
                             "regrasp_nodes", "edge_checks", "edge_collisions", "lazy_rejections",
                             "joint_connect_attempts", "joint_connect_successes", "joint_connect_projections",
                             "path_rejections", "path_verified_edges", "graft_attempts", "grafts")}
        sampler = self._sampler()
        c0 = self.checker.n_checks
        cert = self.checker.certifier(o.edge_min_clearance) if o.edge_tolerance and o.edge_bound == "certified" else None
        if cert is not None:   # a query's result must not depend on the queries before it
            cert.clear_cache()
            n_dist0 = cert.n_distance_calls
        why = self.check_endpoint(q_start)
        if why:
            return self.empty_result(PlanStatus.INVALID_START, f"start {why}", **st)
        why = self.check_endpoint(q_goal)
        if why:
            return self.empty_result(PlanStatus.INVALID_GOAL, f"goal {why}", **st)
        Ms, Mg = self.kin.object_pose(q_start), self.kin.object_pose(q_goal)
        ta = _TaskTree(q_start, xi_from_pose(Ms), Ms.rotation.copy(), Ms.translation.copy())
        tb = _TaskTree(q_goal, xi_from_pose(Mg), Mg.rotation.copy(), Mg.translation.copy())
        a_is_start = True
        found = None
        lead = self._lead   # a restarted search reuses the lead path found before (.tcbirrt_lead)
        if sampler is not None:
            sampler.set_endpoints(ta.xi[0], tb.xi[0])
            if lead.path is not None:
                sampler.guide = lead.path
            st["guide_attempts"] = st["guide_waypoints"] = 0
        root_grafted = {id(ta): not o.root_grafts_first, id(tb): not o.root_grafts_first}
        fronts = {id(ta): 0, id(tb): 0}
        traps: dict[int, list[Any]] = {id(ta): [0, (seed, 0)], id(tb): [0, (seed, 1)]}   # trap_grafts (_trap_graft)
        if branch_roots:
            self._root_branches(ta, tb, deadline, st)
        best_gap, since_gap = np.inf, 0   # stall_iterations: the smallest gap a connection left, iterations since it shrank
        streak = self._streak(sampler, deadline)
        if o.branch_grafts and o.root_grafts_first and not o.graft_after:
            for tr, other in ((ta, tb), (tb, ta)):
                self._graft(tr, 0, other, deadline, st)
                root_grafted[id(tr)] = True
        while not deadline.expired():
            if max_iterations and st["iterations"] >= max_iterations:
                break
            k_graft = st["iterations"] - o.graft_after
            if o.branch_grafts and k_graft > 0 and k_graft % o.graft_interval == 0:
                # the trees take turns (tree a is the same tree at every multiple of an even interval)
                tr, other = (ta, tb) if (k_graft // o.graft_interval) % 2 else (tb, ta)
                if len(tr.graft) - fronts[id(tr)] < o.branch_grafts:   # frontier grafts have their own count
                    self._graft(tr, None if root_grafted[id(tr)] else 0, other, deadline, st)   # the root's first
                    root_grafted[id(tr)] = True
            if (sampler is not None and cast(float, o.guide_probability) > 0 and sampler.guide is None
                    and st["iterations"] % 25 == 0 and lead.budget_left(self)):
                lead_attempt(self, sampler, lead, (ta if a_is_start else tb).xi[0], (tb if a_is_start else ta).xi[0], rng,
                             deadline, st)
            st["iterations"] += 1
            k_front = st["iterations"] - o.graft_after
            i_front = None
            since_gap += 1
            stalled = bool(o.stall_iterations) and since_gap > cast(int, o.stall_iterations)
            if o.frontier_grafts and (stalled or (k_front > 0 and k_front % o.frontier_interval == 0)) and \
                    fronts[id(ta)] < o.frontier_grafts:   # tree a re-grasps at its frontier (.frontier_graft)
                if stalled:
                    st["stall_attempts"] = st.get("stall_attempts", 0) + 1
                    since_gap = 0
                i_front = frontier_graft(self, ta, tb, deadline, st)
                fronts[id(ta)] += i_front is not None
            sk = None
            if i_front is not None:       # the step beyond the frontier graft: connect tree b to it
                res, i_a = ADVANCED, i_front
            else:
                if streak is not None:    # this iteration and the trapped ones after it in one native call
                    sk, done = self._run_streak(streak, ta, tb, traps, fronts, since_gap, max_iterations, sampler, lead,
                                                deadline, st, rng)
                    since_gap += done
                    if done % 2:
                        ta, tb, a_is_start = tb, ta, not a_is_start
                if sk is not None and sk.code == STREAK_DONE:
                    res = TRAPPED
                elif sk is not None and sk.code == STREAK_EXTENDED:   # not trapped: the iteration goes on here
                    res, i_a = self._streak_extended(cast(NativeStreak, streak), ta, sk, rng, deadline, st)
                elif sk is not None and sk.code in (STREAK_CONNECT, STREAK_CONNECTED):   # its node added in C
                    res = PARTIAL if sk.k < o.n_interp else REACHED if sk.reach else ADVANCED
                    i_a = int(sk.i_a)
                else:
                    if sk is None:
                        xi_rand, i_near = self._sample_near(ta, tb, sampler, rng, st)              # lines 3-4
                    else:
                        xi_rand, i_near = np.array(sk.xi_rand), int(sk.i_near)
                    if sk is None or sk.code == STREAK_SAMPLED:
                        if sk is not None:
                            i_near = ta.twin_nearest(i_near, None, rng)
                        step = float(ta.dom[i_near]) if o.trap_adapt == "step" and np.isfinite(ta.dom[i_near]) else None
                        res, i_a, _ = self.constrained_extend(ta, i_near, xi_rand, None, rng, deadline, st, step)   # line 5
                        self._trap_update(ta, i_near, res)
                        if res == TRAPPED and o.trap_grafts and traps[id(ta)][0] < o.trap_grafts and \
                                st["iterations"] > (o.trap_graft_after or 0):   # no trap counted before trap_graft_after
                            i_trap = self._trap_graft(ta, i_near, xi_rand, tb, traps[id(ta)], deadline, st)
                            if i_trap is not None:   # the step beyond the trap graft: connect tree b to it
                                res, i_a = ADVANCED, i_trap
                    else:   # trapped, its step and trap count updated in C: the trap graft is due
                        st["extensions"] += 1
                        st["trapped"] += 1
                        res = TRAPPED
                        i_trap = self._trap_fire(ta, i_near, xi_rand, tb, traps[id(ta)], deadline, st)
                        if i_trap is not None:
                            res, i_a = ADVANCED, i_trap
            if res != TRAPPED:
                target_xi, target_q = ta.xi[i_a].copy(), ta.q[i_a].copy()
                gap = np.inf
                # the first connection step, taken by a streak (not trapped): its result applied here
                n_reg = st["regrasp_attempts"]
                first = self._streak_connected(cast(NativeStreak, streak), tb, sk, target_q, rng, deadline, st) \
                    if sk is not None and sk.code == STREAK_CONNECTED else None
                native = streak is not None and bool(streak.args.advance)   # its steps in C, as in the streaks
                while True:                                                              # lines 7-11
                    ended = False
                    if first is not None:
                        i_nb, (res, i_b, reg), first = int(cast(Any, sk).i_nb), first, None
                    elif native:
                        n_reg = st["regrasp_attempts"]
                        res, i_b, reg, i_nb, ended = self._connect_steps(cast(NativeStreak, streak), tb, target_xi,
                                                                         target_q, rng, deadline, st)
                    else:
                        i_nb = self._twin_of(tb, tb.nearest(target_xi), target_q, rng)
                        n_reg = st["regrasp_attempts"]
                        res, i_b, reg = self.constrained_extend(tb, i_nb, target_xi, target_q, rng, deadline, st)
                    if not ended and res in (ADVANCED, PARTIAL) and no_nearer(tb, i_b, i_nb, target_xi):
                        st["connect_no_nearer"] = st.get("connect_no_nearer", 0) + 1
                        ended = True   # the next step would grow from the same node toward the same target again
                    if o.stall_iterations:
                        i_gap = i_b if res in (ADVANCED, PARTIAL) else i_nb
                        gap = min(gap, 0.0 if res == REACHED or st["regrasp_attempts"] > n_reg   # met: a failed regrasp
                                  else float(np.linalg.norm(tb.xi[i_gap] - target_xi)))
                    if res not in (ADVANCED, PARTIAL) or ended or deadline.expired():
                        break
                if gap < 0.99 * best_gap:
                    best_gap, since_gap = gap, 0
                if res == TRAPPED and o.joint_connect and not deadline.expired():
                    i_nb = tb.nearest(target_xi)
                    if float(np.linalg.norm(tb.xi[i_nb] - target_xi)) <= o.joint_connect_radius and \
                            float(np.linalg.norm(tb.q[i_nb] - target_q)) <= o.joint_connect_max_distance:
                        jp = self.joint_connect(tb.q[i_nb], target_q, deadline, st)
                        if jp is not None:
                            res, i_b, reg = REACHED, i_nb, [(None, [tb.q[i_nb].copy(), *jp])]
                if res == REACHED:
                    if o.edge_tolerance and o.lazy_edges:
                        bad_a, bad_b = self._branch_ok(ta, i_a, st, deadline), self._branch_ok(tb, i_b, st, deadline)
                        if bad_a is not None or bad_b is not None:
                            st["lazy_rejections"] += 1
                            st["lazy_removed_nodes"] = st.get("lazy_removed_nodes", 0) + \
                                (ta.kill(bad_a) if bad_a is not None else 0) + (tb.kill(bad_b) if bad_b is not None else 0)
                            ta, tb, a_is_start = tb, ta, not a_is_start
                            continue
                    if o.edge_tolerance and o.verify_path and o.edge_bound == "jacobian":
                        bad_a, bad_b = self._verify_branch(ta, i_a, st), self._verify_branch(tb, i_b, st)
                        if bad_a is not None or bad_b is not None or not self._verify_connection(ta, i_a, reg, st):
                            st["path_rejections"] += 1
                            for tr, bad in ((ta, bad_a), (tb, bad_b)):
                                if bad is not None:
                                    tr.kill(bad)
                            ta, tb, a_is_start = tb, ta, not a_is_start
                            continue
                    found = (i_a, i_b, reg)
                    break
            ta, tb, a_is_start = tb, ta, not a_is_start                                  # line 15
        st["nodes"] = ta.n + tb.n
        st["collision_checks"] = self.checker.n_checks - c0
        if cert is not None:
            st["distance_calls"] = cert.n_distance_calls - n_dist0   # certified edges: exact group distances
        if sampler is not None:
            st.update(sampler.stats)
            if self._nrng is not None:
                sampler.sync_filter_calls()
        if found is None:
            if deadline.expired():
                return self.empty_result(PlanStatus.TIMEOUT, "time limit reached", **st)
            return self.empty_result(PlanStatus.FAILED, "iteration cap reached", **st)
        return self._extract(ta, tb, a_is_start, found, st)

    def _extract(self, ta: _TaskTree, tb: _TaskTree, a_is_start: bool,
                 found: tuple[int, int, Sequence[tuple[str | None, list[np.ndarray]]] | None], st: dict[str, Any]) -> PlanResult:
        """ExtractPath (:func:`.tcbirrt_tree.extract_path`)."""
        return extract_path(self, ta, tb, a_is_start, found, st)
