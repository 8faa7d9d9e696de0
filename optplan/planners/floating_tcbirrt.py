"""Closed-chain bidirectional RRT for a free-floating robot whose base drifts by momentum conservation.

TCBiRRT's task-space extension (the object's pose interpolated, position linear and rotation along
the geodesic, both hands solved by IK seeded with the previous waypoint) run in the joints of a
free-floating robot. The closed chain does not depend on the base, so the object's poses are
expressed in the BASE frame; the base pose is not free but integrated from zero momentum along every
edge (a straight line in the joints between two closed-chain waypoints), and collision is checked in
the world with the base where momentum puts it (:class:`~optplan.planners.validity.ValidityChecker`,
the base pose being part of each configuration, so of every geometry's placement).

Joining two trees with drift. With zero momentum the base's motion along a joint path is
left-invariant: an edge moves the base by a displacement that depends on the joints only, not on
where the base is. So each tree is a tree of joint paths, and a node's base pose is its tree root's
base composed with the displacements along the path from the root:

* the start tree is rooted at the start with the base where it really is: its base poses are exact;
* the goal tree is rooted at a joint solution of the goal. With a goal in the base frame (a servicer
  moving a module on its own body) that root is the goal. With a world goal, the root holds the
  object at the goal as seen from an ESTIMATE of the base pose at arrival (first the start's base);
  the goal tree integrates its edges from that estimate, so its collision checks are provisional;
* the trees are joined where a connection reaches a node's object pose (base frame) with joints
  within ``join_step_rad``, or by a self-motion join at that pose (interpolated joints projected on
  the closed chain with the object held still);
* a joined path is re-integrated as a whole from the start's base and every collision sample is
  checked again with the base where that integration puts it (a collision there rejects the
  join, the search goes on); with a world goal, the object then misses the goal by the difference
  between the estimate and the real arrival pose: short closed-chain motions re-targeted from the
  drifted base correct it (as :class:`~optplan.planners.floating_carry.FloatingCarryPlanner` does).
  The correction's Newton steps keep the joints within their limits (:func:`limited_step`: a
  joint at its limit is held there and the others re-solved). When the correction fails because
  the goal is out of reach at the arrival attitude, the path is STEERED: closed object loops
  (:mod:`~optplan.planners.floating_steer`) turn the base to the nearest attitude at which the arms
  hold the goal (:func:`~optplan.planners.floating_reach.nearest_held_attitude`), then the
  correction lands it. When that fails too, the goal tree is re-rooted with the real arrival pose as
  the new estimate (``max_reroots`` times) while the start tree is kept: the zero-momentum IK first
  holds the base attitude at that arrival, then searches near it.
* with ``restore_attitude`` the goal tree is rooted where the arms hold the goal with the base at
  its INITIAL attitude and the joined path is steered back to that attitude.

What an ``EXACT`` plan guarantees: the closed chain holds to the IK tolerance at every waypoint; the
returned base poses are those of one integration from the start's base along the whole joint path
(RK4 edge by edge, the same map as :func:`~optplan.model.floating.simulate_base`); the
configurations sampled along every edge (joint steps ≤ ``check_step_rad``) at those base poses are
collision-free (ValidityChecker, and the smallest exact coal distance over them is ≥ 0,
``min_clearance_m``); the object's pose at the end is within the goal tolerance in the goal's frame.
Between the samples, and between the waypoints (where the joint-linear edge leaves the closed chain
by a second-order amount), nothing is guaranteed: :func:`optplan.verify` judges the optimized
trajectory. Not complete: no regrasps (a hand never lets go).
"""
from __future__ import annotations

import math
import time

import numpy as np
import pinocchio as pin

from ..errors import ConfigurationError
from ..model.kinematics import Kinematics
from ..model.robot import RobotModel
from ..scene import Scene
from .base import Deadline, PlanStatus
from .floating_carry import FloatingCarryOptions, FloatingCarryPlan, FloatingCarryPlanner, integrate_edge
from .floating_reach import limited_step, nearest_held_attitude, self_motion_clear, zero_momentum_ik
from .floating_steer import AttitudeSteerer, SteerOptions, SteerResult, left_multiply
from .floating_tree import FloatingTree
from .floating_tree_options import FloatingTreeOptions
from .task_space import interpolate_task
from .validity import ValidityChecker

__all__ = ["FloatingTreeOptions", "FloatingTCBiRRT", "FloatingTree"]


class FloatingTCBiRRT:
    """Bidirectional closed-chain RRT with base drift (module docstring). ``options``: the shared
    steps, tolerances and goal frame (:class:`FloatingCarryOptions`); ``tree``: the trees' options."""

    def __init__(self, robot: RobotModel, scene: Scene, options: FloatingCarryOptions | None = None,
                 tree: FloatingTreeOptions | None = None, steer: SteerOptions | None = None):
        if not robot.is_floating:
            raise ConfigurationError(f"FloatingTCBiRRT needs a free-floating robot; {robot.name!r} has a fixed base")
        self.carry = FloatingCarryPlanner(robot, scene, options)   # closed chain, corrections, results
        self.robot, self.scene = robot, scene
        self.options = self.carry.options
        self.tree_options = tree or FloatingTreeOptions()
        self.arm_names = self.carry.arm_names
        self.validity = ValidityChecker(robot, scene)
        #: the attitude steering (closed object loops) used when the world goal is out of reach at
        #: the attitude a joined path arrives with
        self.steerer = AttitudeSteerer(self.carry, self.validity, steer)
        self._kin = Kinematics(robot)
        self._data = robot.model.createData()
        #: statistics of the last query: nodes per tree, joins tried / rejected at re-integration, re-roots
        self.stats: dict[str, int] = {}
        #: the last query's first join that reached the end of the goal tree with a world goal: its
        #: joints [rad] and real arrival base pose (before the drift correction), or None
        self.first_arrival: tuple[np.ndarray, pin.SE3] | None = None
        self._restore = False
        self._known: tuple[int, SteerResult] | None = None

    def object_in_base(self, joints: np.ndarray) -> pin.SE3:
        """The object's pose in the base frame (read from the first arm's hand)."""
        return self.carry.object_in_base(joints)

    # ------------------------------------------------------------------ edges and extensions
    def _edge(self, base: pin.SE3, qa: np.ndarray, qb: np.ndarray) -> tuple[np.ndarray, bool]:
        """The edge ``qa → qb`` integrated from ``base`` (rows every ≤ ``check_step_rad``) and
        whether every row after the first is collision-free."""
        n = max(1, math.ceil(float(np.max(np.abs(qb - qa))) / self.options.check_step_rad))
        Q = integrate_edge(self.robot, base, qa, qb, n)
        return Q, self.validity.first_invalid(Q[1:]) < 0

    def _grow(self, tree: FloatingTree, k: int, poses: list[pin.SE3],
              toward: np.ndarray | None = None) -> tuple[int, bool]:
        """Path IK through ``poses`` (object in the base frame) from node ``k``, each waypoint a new
        node; returns (last node, whether every pose was reached). With ``toward`` (joints), each
        waypoint's IK is seeded a share of the way toward them (the arms' self-motion drifts toward
        that configuration while the object follows its path)."""
        q, last = tree.joints[k], k
        half = 0.5 * self.tree_options.max_joint_step
        for j, M in enumerate(poses):
            seed = q
            if toward is not None:
                step = (toward - q) / (len(poses) - j)
                seed = q + step * min(1.0, half / max(float(np.max(np.abs(step))), 1e-12))
            qn = self.carry.hold(seed, M)
            if qn is None or float(np.max(np.abs(qn - q))) > self.tree_options.max_joint_step:
                return last, False
            Q, ok = self._edge(tree.bases[last], q, qn)
            if not ok:
                return last, False
            last = tree.add(qn, M, pin.XYZQUATToSE3(Q[-1, :7]), last)
            q = qn
        return last, True

    def _extend(self, tree: FloatingTree, target: pin.SE3, toward: np.ndarray | None = None) -> tuple[int, bool]:
        """ConstrainedExtend: from the nearest node at most one extension step toward ``target``
        (``toward``: the joints the IK seeds lean to, :meth:`_grow`); returns (last node added or the
        nearest, whether the target pose was reached)."""
        o, to = self.options, self.tree_options
        k = tree.nearest(target, to.rotation_weight_m)
        M0 = tree.objs[k]
        dp = float(np.linalg.norm(target.translation - M0.translation))
        dr = float(np.linalg.norm(pin.log3(M0.rotation.T @ target.rotation)))
        if dp < 1e-9 and dr < 1e-9:
            return k, True
        s = min(1.0, to.extend_m / max(dp, 1e-12), to.extend_rad / max(dr, 1e-12))
        w = pin.log3(M0.rotation.T @ target.rotation)
        R1 = M0.rotation @ pin.exp3(s * w) if s < 1.0 else target.rotation
        p1 = M0.translation + s * (target.translation - M0.translation)
        n = max(1, math.ceil(max(s * dp / o.task_step_m, s * dr / o.task_step_rad)))
        poses = [pin.SE3(R, p) for R, p in interpolate_task(M0.rotation, M0.translation, R1, p1, n)]
        last, ok = self._grow(tree, k, poses, toward if s >= 1.0 else None)
        return last, ok and s >= 1.0

    def _connect(self, tree: FloatingTree, node_pose: pin.SE3, node_joints: np.ndarray,
                 deadline: Deadline) -> tuple[int, bool]:
        """Extend ``tree`` toward the other tree's node (``node_pose``; the last extension's IK seeds
        lean to ``node_joints``) until trapped or reached."""
        last, prev = -1, -2
        while not deadline.expired():
            last, reached = self._extend(tree, node_pose, node_joints)
            if reached:
                return last, True
            if last == prev:
                return last, False
            prev = last
        return last, False

    def _join(self, tree: FloatingTree, k: int, q_target: np.ndarray, deadline: Deadline) -> int | None:
        """Joints from node ``k`` to ``q_target`` (both holding the object at node ``k``'s pose): a
        direct edge when close, else a self-motion join (interpolated joints projected onto the
        closed chain, the object held still); returns the node at ``q_target`` or None."""
        to = self.tree_options
        q0, M = tree.joints[k], tree.objs[k]
        gap = float(np.max(np.abs(q_target - q0)))
        n = max(1, math.ceil(gap / to.join_step_rad))
        last, q = k, q0
        for i in range(1, n + 1):
            if deadline.expired():
                return None
            qn = q_target if i == n else self.carry.hold(q0 + (i / n) * (q_target - q0), M)
            if qn is None or float(np.max(np.abs(qn - q))) > to.max_joint_step:
                return None
            Q, ok = self._edge(tree.bases[last], q, qn)
            if not ok:
                return None
            last, q = tree.add(qn, M, pin.XYZQUATToSE3(Q[-1, :7]), last), qn
        return last

    # ------------------------------------------------------------------ goal configurations
    def _path_ik(self, q: np.ndarray, target_b: pin.SE3) -> np.ndarray | None:
        """Joints holding the object at ``target_b`` reached by path IK along the straight task-space
        motion from ``q`` (collisions ignored): a solution on the same IK branch as ``q``."""
        o = self.options
        M0 = self.carry.object_in_base(q)
        dp = float(np.linalg.norm(target_b.translation - M0.translation))
        dr = float(np.linalg.norm(pin.log3(M0.rotation.T @ target_b.rotation)))
        n = max(1, math.ceil(max(dp / o.task_step_m, dr / o.task_step_rad)))
        for R, p in interpolate_task(M0.rotation, M0.translation, target_b.rotation, target_b.translation, n):
            qn = self.carry.hold(q, pin.SE3(R, p))
            if qn is None or float(np.max(np.abs(qn - q))) > self.tree_options.max_joint_step:
                return None
            q = qn
        return q

    def _goal_joints(self, seed_joints: list[np.ndarray], target_b: pin.SE3, base: pin.SE3,
                     rng: np.random.Generator, deadline: Deadline, tries: int | None = None) -> np.ndarray | None:
        """A collision-free (base at ``base``) joint solution holding the object at ``target_b``:
        path IK from the first of ``seed_joints`` (the same IK branch), IK from each of them (when
        such a solution collides, a collision-free one on its self-motion,
        :func:`~optplan.planners.floating_reach.self_motion_clear`), then from ``tries`` (default
        ``goal_seeds``) random seeds around them."""
        to, r = self.tree_options, self.robot
        seeds: list[np.ndarray | None] = [self._path_ik(seed_joints[0], target_b)] + list(seed_joints)
        base_seeds = [q for q in seeds if q is not None]
        for k in range(to.goal_seeds if tries is None else tries):
            s0 = base_seeds[k % len(base_seeds)]
            seeds.append(np.clip(s0 + rng.normal(0.0, to.goal_seed_spread_rad, r.nj), r.lower, r.upper))
        for i, s in enumerate(seeds):
            if deadline.expired():
                return None
            if s is None:
                continue
            q = self.carry.hold(s, target_b)
            if q is not None and self.validity.is_valid(self.carry._full(q, base)):
                return q
            if q is not None and i <= len(seed_joints):   # on the seeds' own IK branch: its self-motion
                qc = self_motion_clear(self.carry, self.validity, q, target_b, base, rng)
                if qc is not None:
                    return qc
        return None

    def _sample(self, rng: np.random.Generator, a: pin.SE3, b: pin.SE3) -> pin.SE3:
        to = self.tree_options
        lo = np.minimum(a.translation, b.translation) - to.sample_margin_m
        hi = np.maximum(a.translation, b.translation) + to.sample_margin_m
        R = a.rotation @ pin.exp3(rng.uniform() * pin.log3(a.rotation.T @ b.rotation))
        off = pin.rpy.rpyToMatrix(*rng.uniform(-to.sample_angle_rad, to.sample_angle_rad, 3))
        return pin.SE3(R @ off, rng.uniform(lo, hi))

    # ------------------------------------------------------------------ the query
    def plan(self, q_start: np.ndarray, goal: pin.SE3, *, base0: pin.SE3 | None = None, seed: int = 0,
             time_limit: float = 10.0) -> FloatingCarryPlan:
        """Plan from the joints ``q_start`` [rad] (holding the object; base at ``base0``, default the
        identity, at rest) to the object's ``goal`` (world, or base frame with
        ``options.target_frame = "base"``) within ``time_limit`` [s] on ``tree.clock``."""
        r, to = self.robot, self.tree_options
        t0 = time.perf_counter()
        deadline = Deadline(float(time_limit), to.clock)
        q0 = r.check_joints(np.asarray(q_start, float), "q_start")
        base0 = pin.SE3.Identity() if base0 is None else base0
        rng = np.random.default_rng(seed)
        self.first_arrival = None
        self.stats = {"iterations": 0, "nodes_start": 1, "nodes_goal": 0, "goal_roots": 0, "reached": 0,
                      "joins": 0, "joins_rejected": 0, "corrections_failed": 0, "reroots": 0,
                      "steers": 0, "steers_landed": 0, "steer_loops": 0, "steer_no_target": 0, "steer_short": 0,
                      "steer_rest_collides": 0, "steer_not_landed": 0}
        qp = self.carry.hold(q0, self.carry.object_in_base(q0))
        if qp is None or float(np.max(np.abs(qp - q0))) > 1e-3:
            return self.carry._result(PlanStatus.INVALID_START, [q0], [base0], float("nan"), t0, goal, 0,
                                      "q_start does not hold the object with both hands (closed chain off by > 1e-3 rad)")
        q0 = qp
        if not self.validity.is_valid(self.carry._full(q0, base0)):
            return self.carry._result(PlanStatus.INVALID_START, [q0], [base0], float("nan"), t0, goal, 0,
                                      "start in collision")
        start = FloatingTree(q0, self.carry.object_in_base(q0), base0)
        self._restore = to.restore_attitude and self.options.target_frame == "world"
        if self._restore:   # the goal held with the base at its initial attitude, or no plan
            goal_tree = self._world_goal_tree(q0, goal, base0, rng, deadline, attitude=base0, held_only=True)
            if goal_tree is None:
                return self.carry._result(PlanStatus.TIMEOUT if deadline.expired() else PlanStatus.INVALID_GOAL,
                                          [q0], [base0], float("nan"), t0, goal, 0,
                                          "the arms cannot hold the object at its world goal with the base at its "
                                          "initial attitude (zero-momentum IK with the attitude held)")
        else:
            goal_tree = self._world_goal_tree(q0, goal, base0, rng, deadline) if self.options.target_frame == "world" else None
        if goal_tree is None:
            goal_tree = self._root_goal_tree(goal, base0, [q0], rng, deadline)
        if goal_tree is None:
            status = PlanStatus.TIMEOUT if deadline.expired() else PlanStatus.INVALID_GOAL
            return self.carry._result(status, [q0], [base0], float("nan"), t0, goal, 0,
                                      f"no collision-free joint solution of the goal pose found ({to.goal_seeds + 1} IK seeds)")
        trees = [start, goal_tree]
        since_join = 0
        while not deadline.expired():
            self.stats["iterations"] += 1
            since_join += 1
            if since_join >= to.root_interval and len(goal_tree.roots) < to.max_goal_roots:
                since_join = 0   # another IK branch of the goal pose
                q = self._goal_joints([goal_tree.joints[0], q0], goal_tree.objs[0], goal_tree.bases[0], rng, deadline,
                                      tries=to.goal_seeds)
                if q is not None:
                    goal_tree.add(q, goal_tree.objs[0], goal_tree.bases[0], -1)
            target = goal_tree.objs[0] if rng.uniform() < to.goal_bias else self._sample(rng, start.objs[0], goal_tree.objs[0])
            a, b = trees
            n_before = len(a)
            ka, _ = self._extend(a, target)
            if len(a) > n_before or ka == 0:
                kb, reached = self._connect(b, a.objs[ka], a.joints[ka], deadline)
                kb2 = None
                if reached:
                    self.stats["reached"] += 1
                    kb2 = self._join(b, kb, a.joints[ka], deadline)
                if kb2 is not None:
                    since_join = 0
                    ks, kg = (ka, kb2) if a is start else (kb2, ka)
                    out = self._finish(start, ks, goal_tree, kg, goal, base0, rng, deadline, t0)
                    if isinstance(out, FloatingCarryPlan):
                        return out
                    if out == "reroot" and not self._restore and self.stats["reroots"] < to.max_reroots:
                        self.stats["reroots"] += 1
                        b_est = self._integrate_path(self._joint_path(start, ks, goal_tree, kg)[len(start.path_to_root(ks)) - 1:],
                                                     start.bases[ks])[1][-1]
                        old_root = goal_tree.joints[goal_tree.path_to_root(kg)[-1]]
                        new = self._world_goal_tree(q0, goal, base0, rng, deadline, attitude=b_est, seeds=[old_root])
                        if new is None:
                            new = self._root_goal_tree(goal, b_est, [old_root, q0], rng, deadline)
                        if new is not None:
                            goal_tree = new
                            trees = [start, goal_tree]
                            continue
            trees = [trees[1], trees[0]]
        self.stats.update(nodes_start=len(start), nodes_goal=len(goal_tree), goal_roots=len(goal_tree.roots))
        st = self.stats
        return self.carry._result(PlanStatus.TIMEOUT, [q0], [base0], float("nan"), t0, goal, 0,
                                  f"time limit ({len(start)} + {len(goal_tree)} nodes, {st['goal_roots']} goal roots, "
                                  f"{st['reached']} connections reached a node's pose, {st['joins']} joined, "
                                  f"{st['joins_rejected']} rejected at the re-integration, {st['corrections_failed']} "
                                  "world-goal corrections failed)")

    def _world_goal_tree(self, q0: np.ndarray, goal: pin.SE3, base0: pin.SE3, rng: np.random.Generator,
                         deadline: Deadline, attitude: pin.SE3 | None = None, seeds: list[np.ndarray] | None = None,
                         held_only: bool = False) -> FloatingTree | None:
        """The goal tree of a world goal rooted at a zero-momentum IK solution
        (:func:`~optplan.planners.floating_reach.zero_momentum_ik`: the centre of mass stays put, so
        the base's arrival POSITION is known for a given attitude; the attitude is searched near
        the start's, or after a join first held at the attitude that join arrived with, then
        searched near it), or None when it does not converge or collides."""
        com = pin.centerOfMass(self.robot.model, self._data, self.carry._full(q0, base0))
        if seeds is None:
            seed = self._path_ik(q0, base0.actInv(goal))
            seeds = [q0] if seed is None else [seed, q0]
        for attempt in range(1 + self.tree_options.goal_seeds // 4):   # more seeds while it collides
            if deadline.expired():
                return None
            trial = seeds if attempt == 0 else [
                np.clip(seeds[0] + rng.normal(0.0, self.tree_options.goal_seed_spread_rad, self.robot.nj),
                        self.robot.lower, self.robot.upper)]
            res = math.inf
            # after a join: first the attitude that join arrived with, held (else the search drifts
            # back toward the seed's attitude and the re-rooting creeps), then searched near it
            for fix in ((True,) if held_only else (True, False) if attitude is not None else (False,)):
                q, b_est, res = zero_momentum_ik(self.robot, self.carry.grasps, goal, trial, com, rng,
                                                 attitude=base0 if attitude is None else attitude, n_random=2,
                                                 fix_attitude=fix)
                if res <= self.options.ik_tol:
                    break
            if res > self.options.ik_tol:
                continue
            qg = self.carry.hold(q, b_est.actInv(goal))   # onto the chain to the IK tolerance, in the base frame
            if qg is not None and self.validity.is_valid(self.carry._full(qg, b_est)):
                return FloatingTree(qg, b_est.actInv(goal), b_est)
        return None

    def _root_goal_tree(self, goal: pin.SE3, b_est: pin.SE3, seeds: list[np.ndarray], rng: np.random.Generator,
                        deadline: Deadline) -> FloatingTree | None:
        target_b = b_est.actInv(goal) if self.options.target_frame == "world" else goal
        qg = self._goal_joints(seeds, target_b, b_est, rng, deadline)
        if qg is None:
            return None
        return FloatingTree(qg, target_b, b_est)

    def _joint_path(self, start: FloatingTree, ks: int, goal_tree: FloatingTree, kg: int) -> list[np.ndarray]:
        """Joints from the start to the goal tree's root through the join ``ks`` ~ ``kg`` (same joints)."""
        fwd = [start.joints[i] for i in reversed(start.path_to_root(ks))]
        back = [goal_tree.joints[i] for i in goal_tree.path_to_root(kg)]
        return fwd + back[1:]

    def _integrate_path(self, joints: list[np.ndarray], base0: pin.SE3,
                        known: tuple[int, SteerResult] | None = None) -> tuple[np.ndarray, list[pin.SE3]]:
        """Every collision sample of the joint path (rows, base integrated from ``base0`` edge by
        edge) and the base at each waypoint. ``known = (k, steer)``: the waypoints after ``k`` are
        the manoeuvre ``steer``, its samples and bases composed from the base at ``k``
        (left-invariance: the same as integrating its edges, to rounding)."""
        rows, bases, base = [], [base0], base0
        i = 0
        while i < len(joints) - 1:
            if known is not None and i == known[0]:
                s, to_here = known[1], base * known[1].start.inverse()
                rows.append(left_multiply(s.rows, base))
                bases += [to_here * b for b in s.bases]
                base = bases[-1]
                i += len(s.joints)
                continue
            qa, qb = joints[i], joints[i + 1]
            i += 1
            n = max(1, math.ceil(float(np.max(np.abs(qb - qa))) / self.options.check_step_rad))
            Q = integrate_edge(self.robot, base, qa, qb, n)
            rows.append(Q[1:])
            base = pin.XYZQUATToSE3(Q[-1, :7])
            bases.append(base)
        return (np.vstack(rows) if rows else np.empty((0, self.robot.nq))), bases

    def _correct(self, q: np.ndarray, base: pin.SE3, goal: pin.SE3,
                 deadline: Deadline) -> tuple[list[np.ndarray], list[pin.SE3]] | None:
        """Closed-chain correction of the world goal from ``(q, base)``: Newton steps on both hands'
        world poses with the generalized Jacobian (zero momentum), each step's joints re-closed on
        the chain in the base frame, then integrated and collision-checked as an edge. Returns the
        new waypoints and bases, or None when it does not reach the goal tolerance."""
        o, to = self.options, self.tree_options
        m, d = self.robot.model, self._data
        ws: list[np.ndarray] = []
        bs: list[pin.SE3] = []
        for _ in range(to.correction_steps + 1):
            full = self.carry._full(q, base)
            pin.framesForwardKinematics(m, d, full)
            errs = []
            for a in self.arm_names:
                H, T = d.oMf[self.robot.arm(a).ee_frame_id], goal * self.carry.grasps[a]
                errs.append(np.r_[H.translation - T.translation, pin.log3(H.rotation @ T.rotation.T)])
            ep, er = self.carry._goal_error(q, base, goal)
            if ep <= o.goal_tol_m and er <= o.goal_tol_rad:
                return ws, bs
            if deadline.expired():
                return None
            G = self._kin.generalized_jacobians(full)
            J = np.vstack([G[a] for a in self.arm_names])
            dq = limited_step(J, -np.concatenate(errs), q, self.robot.lower, self.robot.upper,
                              to.correction_step_rad)
            q_lin = np.clip(q + dq, self.robot.lower, self.robot.upper)
            qn = self.carry.hold(q_lin, self.carry.object_in_base(q_lin))
            if qn is None or float(np.max(np.abs(qn - q))) > to.max_joint_step:
                return None
            Q, ok = self._edge(base, q, qn)
            if not ok:
                return None
            q, base = qn, pin.XYZQUATToSE3(Q[-1, :7])
            ws.append(q)
            bs.append(base)
        return None

    def _steer(self, joints: list[np.ndarray], bases: list[pin.SE3], goal: pin.SE3, base0: pin.SE3, k_join: int,
               rng: np.random.Generator, deadline: Deadline
               ) -> tuple[list[np.ndarray], list[pin.SE3], tuple[list[np.ndarray], list[pin.SE3]]] | None:
        """Attitude steering of a joined path whose arrival cannot land the world goal: an attitude
        near the arrival's at which the goal can be held (:func:`nearest_held_attitude`), closed
        object loops (:class:`~optplan.planners.floating_steer.AttitudeSteerer`) inserted at the
        arrival, else at the join, else at the start, that turn the arrival to it (the rest of the
        path moves the base by a displacement of its joints only), then the correction. Returns the
        new joints, bases and the correction's waypoints, or None."""
        self.stats["steers"] += 1
        if self._restore:   # to the initial attitude, where the goal tree's root holds the goal
            return self._steer_to(joints, bases, goal, base0.rotation, k_join, rng, deadline)
        com = pin.centerOfMass(self.robot.model, self._data, self.carry._full(joints[0], base0))
        tgt = nearest_held_attitude(self.robot, self.carry.grasps, goal, [joints[-1]], com, rng, bases[-1])
        if tgt is None or deadline.expired():
            self.stats["steer_no_target"] += 1
            return None
        return self._steer_to(joints, bases, goal, tgt[0], k_join, rng, deadline)

    def _steer_to(self, joints: list[np.ndarray], bases: list[pin.SE3], goal: pin.SE3, R_t: np.ndarray, k_join: int,
                  rng: np.random.Generator, deadline: Deadline
                  ) -> tuple[list[np.ndarray], list[pin.SE3], tuple[list[np.ndarray], list[pin.SE3]]] | None:
        """:meth:`_steer` to the world attitude ``R_t`` (3×3) at the path's end."""
        o = self.options
        tol = self.tree_options.restore_tol_rad if self._restore else None
        for k in dict.fromkeys((len(joints) - 1, k_join, 0)):
            wanted = bases[k].rotation.T @ R_t @ (bases[k].rotation.T @ bases[-1].rotation).T
            s = self.steerer.steer(joints[k], bases[k], wanted, rng, deadline, tol_rad=tol)
            if s is None or s.error_rad > (tol if tol is not None else 0.5 * float(np.linalg.norm(pin.log3(wanted)))):
                self.stats["steer_short"] += 1
                continue
            rest = joints[k + 1:]
            rows, tail = self._integrate_path([joints[k]] + rest, s.bases[-1])
            if rest and self.validity.first_invalid(rows) >= 0:
                self.stats["steer_rest_collides"] += 1
                continue
            new_j, new_b = joints[:k + 1] + s.joints + rest, bases[:k + 1] + s.bases + tail[1:]
            if self._restore:
                ep, er = self.carry._goal_error(new_j[-1], new_b[-1], goal)
                got: tuple[list[np.ndarray], list[pin.SE3]] | None = (
                    ([], []) if ep <= o.goal_tol_m and er <= o.goal_tol_rad else None)
            else:
                got = self._correct(new_j[-1], new_b[-1], goal, deadline)
            if got is not None:
                self._known = (k, s)
                self.stats["steers_landed"] += 1
                self.stats["steer_loops"] += s.loops
                return new_j, new_b, got
            self.stats["steer_not_landed"] += 1
            if deadline.expired():
                break
        return None

    def _finish(self, start: FloatingTree, ks: int, goal_tree: FloatingTree, kg: int, goal: pin.SE3, base0: pin.SE3,
                rng: np.random.Generator, deadline: Deadline, t0: float) -> FloatingCarryPlan | str:
        """A joined path: re-integrated from ``base0`` as a whole and re-checked, then (world goal)
        corrected for the drift. Returns the plan, ``"collides"`` or ``"reroot"``."""
        o = self.options
        self.stats["joins"] += 1
        self._known = None
        joints = self._joint_path(start, ks, goal_tree, kg)
        fwd = list(reversed(start.path_to_root(ks)))
        # the start tree's part is exact already; the goal tree's part re-integrated from the join
        rows, back = self._integrate_path(joints[len(fwd) - 1:], start.bases[ks])
        bases = [start.bases[i] for i in fwd] + back[1:]
        if self.validity.first_invalid(rows) >= 0:
            self.stats["joins_rejected"] += 1
            return "collides"
        n_wp = len(joints)
        if o.target_frame == "world":
            if self.first_arrival is None:
                self.first_arrival = (joints[-1].copy(), bases[-1].copy())
            got: tuple[list[np.ndarray], list[pin.SE3]] | None = None
            if self._restore:   # already at the initial attitude (within its tolerance): nothing to steer
                miss = float(np.linalg.norm(pin.log3(base0.rotation.T @ bases[-1].rotation)))
                got = ([], []) if miss <= self.tree_options.restore_tol_rad else None
            else:
                got = self._correct(joints[-1], bases[-1], goal, deadline)
            if got is None and (self.tree_options.steer_attitude or self._restore):
                steered = self._steer(joints, bases, goal, base0, len(fwd) - 1, rng, deadline)
                if steered is not None:
                    joints, bases, got = steered
            if got is None:
                self.stats["corrections_failed"] += 1
                return "reroot"
            joints += got[0]
            bases += got[1]
        # one integration of the whole path, edge by edge (a steering manoeuvre composed)
        rows, bases = self._integrate_path(joints, base0, self._known)
        dmin, _, _ = self.carry.checker.min_distance_along(np.vstack([self.carry._full(joints[0], base0), rows]))
        if dmin < 0.0:   # the boolean checks and the exact distances disagree: reject rather than return it
            self.stats["joins_rejected"] += 1
            return "collides"
        self.stats.update(nodes_start=len(start), nodes_goal=len(goal_tree), goal_roots=len(goal_tree.roots))
        return self.carry._result(PlanStatus.EXACT, joints, bases, float(dmin), t0, goal, len(joints) - n_wp, "")
