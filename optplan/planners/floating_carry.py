"""Carrying a held object with a free-floating robot whose base drifts by momentum conservation.

A configuration of a free-floating robot is its joints plus the base pose; along a joint path the
base pose is not free but integrated from zero momentum (path-dependent, nonholonomic). This
planner plans in the joints and carries the integrated base pose along: every edge (a straight
line in the joints between two closed-chain configurations) is integrated with
:func:`~optplan.model.floating.simulate_base` from the base pose at its start, and collision is
checked in the world with the base where momentum puts it.

Both hands hold one rigid object, so the closed chain (the hands' relative pose) does not depend
on the base: it is solved in the base frame (damped least squares, each arm to its grasp on the
object's pose in the base frame). The object's target is given in the world (default): the base
drifts while the arms move, so after a task-space motion to the target expressed in the base frame
at its start the object misses the world target by the drift; the planner re-targets from the
drifted base and repeats (each round's miss is the drift of a shorter motion). With
``target_frame="base"`` the target is the object's pose in the base frame (a servicer moving a
module on its own body) and no correction is needed. When the straight task-space motion
collides, the planner tries random via poses of the object (seeded generator).

What the planner guarantees for ``EXACT``: the closed chain holds to the IK tolerance at every
waypoint; the configurations sampled along every edge (joint steps ≤ ``check_step_rad``), with the
base integrated from zero momentum, are collision-free by exact coal distances; the object's world
pose at the end (base integrated along the whole path) is within the goal tolerance. Between the
samples and between the waypoints (where the joint-linear edge leaves the closed chain by a
second-order amount) nothing is guaranteed: :func:`optplan.verify` is the judge of the final
trajectory.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from ..collision.checker import CollisionChecker
from ..errors import ConfigurationError, OptionError
from ..model.floating import simulate_base
from ..model.robot import RobotModel
from ..scene import Scene
from .base import PlanStatus

__all__ = ["FloatingCarryOptions", "FloatingCarryPlan", "FloatingCarryPlanner", "integrate_edge"]

#: one motion: its waypoints (joints), the base pose after each, its smallest checked clearance [m]
_Motion = tuple[list[np.ndarray], list[pin.SE3], float]


@dataclass(frozen=True)
class FloatingCarryOptions:
    """Options of :class:`FloatingCarryPlanner`."""

    #: largest joint change between two collision-checked samples of an edge [rad].
    check_step_rad: float = 0.02
    #: largest object translation between two closed-chain waypoints [m].
    task_step_m: float = 0.05
    #: largest object rotation between two closed-chain waypoints [rad].
    task_step_rad: float = 0.1
    #: the object's world (or base-frame) goal tolerance, position [m].
    goal_tol_m: float = 1e-3
    #: the object's goal tolerance, rotation [rad].
    goal_tol_rad: float = 1e-3
    #: drift-correction rounds after the first motion to a world target [count].
    max_corrections: int = 10
    #: random via poses tried when the straight task-space motion collides [count].
    via_tries: int = 40
    #: range of a via pose's offset from the straight motion's midpoint, per axis [m].
    via_position_range_m: float = 0.4
    #: range of a via pose's rotation offset, per RPY angle [rad].
    via_angle_range_rad: float = 0.4
    #: closed-chain IK tolerance (hand pose error norm, the log of SE(3)) [m, rad].
    ik_tol: float = 1e-10
    #: the frame of the goal pose: "world" or "base" (the object's pose in the base frame).
    target_frame: str = "world"

    def __post_init__(self) -> None:
        for name in ("check_step_rad", "task_step_m", "task_step_rad", "goal_tol_m", "goal_tol_rad", "ik_tol",
                     "via_position_range_m", "via_angle_range_rad"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise OptionError(f"FloatingCarryOptions.{name}: expected a positive finite number, got {v!r}")
        for name in ("max_corrections", "via_tries"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 0):
                raise OptionError(f"FloatingCarryOptions.{name}: expected an integer ≥ 0, got {v!r}")
        if self.target_frame not in ("world", "base"):
            raise OptionError(f"FloatingCarryOptions.target_frame: expected 'world' or 'base', got {self.target_frame!r}")


@dataclass
class FloatingCarryPlan:
    """Result of :meth:`FloatingCarryPlanner.plan`.

    ``joints`` (M, nj) waypoints [rad]; ``q`` (M, nq) with the base integrated from zero momentum;
    ``object_poses`` the object's world pose at each waypoint; ``min_clearance_m`` over the checked
    samples; ``goal_error`` (position [m], rotation [rad]) of the object at the end in the goal's
    frame; ``corrections`` drift-correction rounds used.
    """

    status: PlanStatus
    joints: np.ndarray
    q: np.ndarray
    object_poses: list[pin.SE3] = field(default_factory=list)
    min_clearance_m: float = float("nan")
    goal_error: tuple[float, float] = (float("nan"), float("nan"))
    corrections: int = 0
    time_s: float = float("nan")
    message: str = ""

    @property
    def success(self) -> bool:
        return self.status.success

    @property
    def final_base(self) -> pin.SE3:
        return pin.XYZQUATToSE3(self.q[-1, :7])


def integrate_edge(robot: RobotModel, base: pin.SE3, qa: np.ndarray, qb: np.ndarray, n: int) -> np.ndarray:
    """Full configurations (n + 1, nq) at ``n + 1`` evenly spaced points of the straight joint edge
    ``qa → qb``, the base integrated from ``base`` with zero momentum (driftless: the edge's timing
    does not matter; it is parametrised over [0, 1])."""
    qa, qb = np.asarray(qa, float), np.asarray(qb, float)
    d = qb - qa
    s = np.linspace(0.0, 1.0, int(n) + 1)

    def line(t: Any) -> tuple[np.ndarray, np.ndarray]:   # vectorised over times: the same numbers as one time at a time
        t = np.asarray(t, float)
        return qa + t[..., None] * d, np.broadcast_to(d, t.shape + d.shape)
    # the base poses only (the momentum cross-check at every point left out: the same poses)
    return simulate_base(robot, line, s, base0=base, substeps=2, vectorised=True, momentum=False).q


class FloatingCarryPlanner:
    """Momentum-aware closed-chain planner for a free-floating robot holding ``scene.object`` with
    two arms (module docstring)."""

    def __init__(self, robot: RobotModel, scene: Scene, options: FloatingCarryOptions | None = None):
        if not robot.is_floating:
            raise ConfigurationError(f"FloatingCarryPlanner needs a free-floating robot; {robot.name!r} has a fixed base")
        if scene.object is None or len(scene.object.grasps) != 2:
            raise ConfigurationError(f"scene {scene.name!r}: the floating carry needs an [object] held by two arms")
        self.robot, self.scene = robot, scene
        self.options = options or FloatingCarryOptions()
        self.grasps = dict(scene.object.grasps)
        self.arm_names = tuple(self.grasps)
        self.checker = CollisionChecker(robot, scene)
        self._data = robot.model.createData()
        self._base_id = pin.SE3ToXYZQUAT(pin.SE3.Identity())
        self._chain: tuple[Any, ...] | None = None   # onto_chain's indices, built on first use

    # ------------------------------------------------------------------ closed chain in the base frame
    def _full(self, joints: np.ndarray, base: pin.SE3 | None = None) -> np.ndarray:
        b = self._base_id if base is None else pin.SE3ToXYZQUAT(base)
        return np.concatenate([b, joints])

    def object_in_base(self, joints: np.ndarray) -> pin.SE3:
        """The object's pose in the base frame, read from the first arm's hand."""
        m, d = self.robot.model, self._data
        pin.framesForwardKinematics(m, d, self._full(joints))
        arm = self.robot.arm(self.arm_names[0])
        return d.oMf[arm.ee_frame_id] * self.grasps[self.arm_names[0]].inverse()

    def hold(self, joints: np.ndarray, object_in_base: pin.SE3, iters: int = 200) -> np.ndarray | None:
        """Joints near ``joints`` with both hands at their grasps on the object at ``object_in_base``
        (Levenberg–Marquardt per arm: a step is taken only if it reduces the hand's pose error, else
        the damping grows; clamped to the limits); None if it does not converge."""
        m, d, r = self.robot.model, self._data, self.robot
        q = self._full(np.array(joints, float))
        nb = r.base_nq
        eye, tol = np.eye(6), self.options.ik_tol
        for arm_name in self.arm_names:
            arm = r.arm(arm_name)
            target = object_in_base * self.grasps[arm_name]
            fid, q_idx, v_idx = arm.ee_frame_id, arm.q_idx, arm.v_idx
            lo, hi = r.lower[arm.j_idx], r.upper[arm.j_idx]

            def error(qq: np.ndarray, target: pin.SE3 = target, fid: int = fid) -> np.ndarray:
                pin.forwardKinematics(m, d, qq)   # the one frame needed: the same numbers as all frames
                return pin.log6(target.actInv(pin.updateFramePlacement(m, d, fid))).vector

            err = error(q)
            e, lam, ok = math.sqrt(err @ err), 1e-8, False   # = np.linalg.norm, bit for bit
            for _ in range(iters):
                if e < tol:
                    ok = True
                    break
                J = pin.computeFrameJacobian(m, d, q, fid, pin.LOCAL)[:, v_idx]
                step = J.T @ np.linalg.solve(J @ J.T + lam * eye, err)
                n = float(np.abs(step).max())
                if n > 0.3:
                    step *= 0.3 / n
                qt = q.copy()
                qt[q_idx] = np.clip(q[q_idx] - step, lo, hi)
                et = error(qt)
                et_n = math.sqrt(et @ et)
                if et_n < e:
                    q, err, e, lam = qt, et, et_n, max(lam * 0.1, 1e-12)
                else:
                    lam *= 10.0
                    if lam > 1e2:
                        break
            if not ok:
                return None
        return q[nb:].copy()

    def onto_chain(self, joints: np.ndarray, iters: int = 50) -> np.ndarray | None:
        """``joints`` [rad] with the second hand put on its grasp on the object held by the first
        (the first arm's joints unchanged): what ``hold(joints, object_in_base(joints))`` returns,
        the same damped steps, one kinematics pass (placements and Jacobians) per step; None if it
        does not converge."""
        m, d, r = self.robot.model, self._data, self.robot
        if self._chain is None:   # the arms' indices and the hands' relative grasp, once
            first, second = (r.arm(n) for n in self.arm_names)
            self._chain = (first.ee_frame_id, second.ee_frame_id, second.q_idx, second.v_idx,
                           self.grasps[self.arm_names[0]].inverse() * self.grasps[self.arm_names[1]],
                           r.lower[second.j_idx].copy(), r.upper[second.j_idx].copy())
        f1, f2, q_idx, v_idx, rel, lo, hi = self._chain
        q = self._full(np.array(joints, float))

        def error(qq: np.ndarray) -> np.ndarray:
            pin.computeJointJacobians(m, d, qq)   # the two hands' frames only: the same numbers as all frames
            return pin.log6((pin.updateFramePlacement(m, d, f1) * rel).actInv(pin.updateFramePlacement(m, d, f2))).vector

        err = error(q)
        e, lam = math.sqrt(err @ err), 1e-8   # = np.linalg.norm, bit for bit
        J = pin.getFrameJacobian(m, d, f2, pin.LOCAL)[:, v_idx]
        eye, tol = np.eye(6), self.options.ik_tol
        for _ in range(iters):
            if e < tol:
                return q[r.base_nq:].copy()
            step = J.T @ np.linalg.solve(J @ J.T + lam * eye, err)
            n = float(np.abs(step).max())
            if n > 0.3:
                step *= 0.3 / n
            qt = q.copy()
            qt[q_idx] = np.clip(q[q_idx] - step, lo, hi)
            et = error(qt)
            et_n = math.sqrt(et @ et)
            if et_n < e:
                q, err, e, lam = qt, et, et_n, max(lam * 0.1, 1e-12)
                J = pin.getFrameJacobian(m, d, f2, pin.LOCAL)[:, v_idx]
            else:
                lam *= 10.0
                if lam > 1e2:
                    return None
        return q[r.base_nq:].copy() if e < tol else None

    # ------------------------------------------------------------------ one task-space motion
    def _edge(self, base: pin.SE3, qa: np.ndarray, qb: np.ndarray) -> tuple[np.ndarray, float]:
        n = max(1, math.ceil(float(np.max(np.abs(qb - qa))) / self.options.check_step_rad))
        Q = integrate_edge(self.robot, base, qa, qb, n)
        dmin, _, _ = self.checker.min_distance_along(Q)
        return Q, float(dmin)

    def _move(self, joints: np.ndarray, base: pin.SE3, target_b: pin.SE3) -> _Motion | None:
        """Straight task-space motion of the object (base frame at the motion's start) to
        ``target_b``: waypoints, base after each, clearance; None where IK fails or it collides."""
        o = self.options
        start_b = self.object_in_base(joints)
        delta = pin.log6(start_b.actInv(target_b)).vector
        n = max(1, math.ceil(max(np.linalg.norm(delta[:3]) / o.task_step_m, np.linalg.norm(delta[3:]) / o.task_step_rad)))
        ws: list[np.ndarray] = []
        bs: list[pin.SE3] = []
        dmin, q = np.inf, joints
        for k in range(1, n + 1):
            qn = self.hold(q, start_b * pin.exp6(pin.Motion(delta * k / n)))
            if qn is None:
                return None
            Q, d = self._edge(base, q, qn)
            if d < 0.0:
                return None
            base, q, dmin = pin.XYZQUATToSE3(Q[-1, :7]), qn, min(dmin, d)
            ws.append(qn)
            bs.append(base)
        return ws, bs, dmin

    # ------------------------------------------------------------------ the query
    def plan(self, q_start: np.ndarray, goal: pin.SE3, *, base0: pin.SE3 | None = None, seed: int = 0,
             time_limit: float = 10.0) -> FloatingCarryPlan:
        """Plan from the joints ``q_start`` (holding the object; base at ``base0``, default the
        identity, at rest) to the object's ``goal`` (world or base frame: ``options.target_frame``)."""
        r, o = self.robot, self.options
        t0 = time.perf_counter()
        q0 = r.check_joints(np.asarray(q_start, float), "q_start")
        base0 = pin.SE3.Identity() if base0 is None else base0
        rng = np.random.default_rng(seed)
        qp = self.hold(q0, self.object_in_base(q0))   # the start onto the closed chain (rounded inputs)
        if qp is None or float(np.max(np.abs(qp - q0))) > 1e-3:
            return self._result(PlanStatus.INVALID_START, [q0], [base0], float("nan"), t0, goal, 0,
                                "q_start does not hold the object with both hands (closed chain off by > 1e-3 rad)")
        q0 = qp
        d0, _ = self.checker.min_distance(self._full(q0, base0))
        if d0 < 0.0:
            return self._result(PlanStatus.INVALID_START, [q0], [base0], d0, t0, goal, 0, "start in collision")
        joints, bases, dmin = [q0], [base0], float(d0)
        rounds = o.max_corrections + 1 if o.target_frame == "world" else 1
        for rnd in range(rounds):
            if time.perf_counter() - t0 > time_limit:
                return self._result(PlanStatus.TIMEOUT, joints, bases, dmin, t0, goal, rnd, "time limit")
            base = bases[-1]
            target_b = base.actInv(goal) if o.target_frame == "world" else goal
            got = self._move(joints[-1], base, target_b)
            tries = 0
            while got is None and tries < o.via_tries and time.perf_counter() - t0 <= time_limit:
                tries += 1
                got = self._via(joints[-1], base, target_b, rng)
            if got is None:
                return self._result(PlanStatus.FAILED, joints, bases, dmin, t0, goal, rnd,
                                    f"no collision-free closed-chain motion found ({tries} via poses tried)")
            joints += got[0]
            bases += got[1]
            dmin = min(dmin, got[2])
            ep, er = self._goal_error(joints[-1], bases[-1], goal)
            if ep <= o.goal_tol_m and er <= o.goal_tol_rad:
                return self._result(PlanStatus.EXACT, joints, bases, dmin, t0, goal, rnd, "")
        return self._result(PlanStatus.FAILED, joints, bases, dmin, t0, goal, rounds - 1,
                            "the drift corrections did not reach the world goal tolerance")

    def _via(self, joints: np.ndarray, base: pin.SE3, target_b: pin.SE3,
             rng: np.random.Generator) -> _Motion | None:
        o = self.options
        start_b = self.object_in_base(joints)
        mid = start_b * pin.exp6(pin.Motion(0.5 * pin.log6(start_b.actInv(target_b)).vector))
        off = pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-o.via_angle_range_rad, o.via_angle_range_rad, 3)),
                      rng.uniform(-o.via_position_range_m, o.via_position_range_m, 3))
        via = pin.SE3(mid.rotation @ off.rotation, mid.translation + off.translation)
        a = self._move(joints, base, via)
        if a is None:
            return None
        # the same target after the via: in the world, or in the (moving) base frame
        after = target_b if o.target_frame == "base" else a[1][-1].actInv(base * target_b)
        b = self._move(a[0][-1], a[1][-1], after)
        if b is None:
            return None
        return a[0] + b[0], a[1] + b[1], min(a[2], b[2])

    def _goal_error(self, joints: np.ndarray, base: pin.SE3, goal: pin.SE3) -> tuple[float, float]:
        M = self.object_in_base(joints)
        if self.options.target_frame == "world":
            M = base * M
        e = goal.actInv(M)
        return float(np.linalg.norm(e.translation)), float(np.linalg.norm(pin.log3(e.rotation)))

    def _result(self, status: PlanStatus, joints: list[np.ndarray], bases: list[pin.SE3], dmin: float, t0: float,
                goal: pin.SE3, rounds: int, msg: str) -> FloatingCarryPlan:
        J = np.array(joints)
        Q = np.array([self._full(j, b) for j, b in zip(joints, bases)])
        poses = [b * self.object_in_base(j) for j, b in zip(joints, bases)]
        return FloatingCarryPlan(status, J, Q, poses, float(dmin), self._goal_error(joints[-1], bases[-1], goal),
                                 int(rounds), time.perf_counter() - t0, msg)
