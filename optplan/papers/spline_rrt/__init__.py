"""Spline-RRT* (Yu et al., "Spline-RRT*: coordinated motion planning of dual-arm space robot"):
coordinated task-space RRT* → quartic splines → resolved-rate joint motion on the free-floating
robot — and optplan's optimized variant of the same task.

Pipeline (:func:`run_spline_rrt`):

1. :class:`~optplan.planners.spline_rrt.CoordinatedRRTStar` plans both hand *positions* (separated
   sampling behind a moving virtual wall).
2. :func:`smooth_hand_paths`: a C3 quartic spline through each tree's waypoints (Eq. 8-11 with
   v0 = a0 = vf = 0, :func:`optplan.geometry.splines.quartic_spline`), waypoint times proportional to the
   segment lengths; the duration T is the smallest one for which both hands keep ‖ẋ‖ ≤ the speed
   limit (an exact time scaling, since v0 = a0 = vf = 0 are invariant under it). With
   ``optimize_durations`` the segment durations come from the quartic NLP
   (:func:`optplan.problem.quartic.smooth_quartic`, minimum time under the speed limit).
   Orientation: a 5th-order Bézier between the start and goal orientations (:class:`BezierOrientation`).
3. :func:`track`: resolved rates through the generalized Jacobian (Eq. 5) with closed-loop
   correction, ``q̇ = J*⁺ (ξ_d + K e)``, the base integrated with the joints (momentum zero). The
   figures reported are recomputed from :func:`optplan.model.floating.simulate_base` (independent
   integrator) on the joint samples.
4. :func:`optimize`: the same task as an :class:`~optplan.problem.OptProblem` on the floating base,
   warm-started from the tracked joint trajectory: hand paths as constraints, links ≥ 0.1 m apart,
   base attitude restored at the end.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ...geometry.spatial import rpy_to_matrix
from ...model.kinematics import Kinematics
from ...model.robot import RobotModel
from ...planners.spline_rrt import CoordinatedPlan, CoordinatedRRTStar, CoordinatedRRTStarOptions
from ...scene import Scene
from .optimized import EndOrientation, InteriorVelocityLimits, OptimizeOptions, knot_selector, optimize
from .tracking import (
    BezierOrientation,
    HandTrajectory,
    TrackingOptions,
    TrackingResult,
    evaluate,
    link_distances,
    smooth_hand_paths,
    track,
)

__all__ = ["SplineRRTTask", "BezierOrientation", "HandTrajectory", "smooth_hand_paths", "TrackingOptions",
           "TrackingResult", "track", "link_distances", "evaluate", "OptimizeOptions", "EndOrientation", "InteriorVelocityLimits", "optimize", "knot_selector", "SplineRRTResult", "run_spline_rrt", "hand_separation", "PAPER"]
log = logging.getLogger(__name__)

#: the paper's figures (Section 4)
PAPER = {"duration_s": 16.0, "ee_speed_limit_m_s": 0.1, "tracking_error": 1e-4, "min_link_distance_m": 0.1,
         "joint_rate_limit_deg_s": 0.1, "joint_accel_limit_deg_s2": 0.1}


# --------------------------------------------------------------------------- task
@dataclass(frozen=True)
class SplineRRTTask:
    """Start and goal hand poses (world, [m]) per arm and the initial joint vector [rad]."""

    robot: RobotModel
    scene: Scene
    start: dict
    goal: dict
    q_start: np.ndarray

    @classmethod
    def from_scene(cls, robot: RobotModel, scene: Scene | str = "splinerrt_capture") -> SplineRRTTask:
        """Read ``start_<arm>``/``goal_<arm>`` ([x, y, z, roll, pitch, yaw], [m] and the scene's angle
        unit) and ``q_start_<arm>`` from the scene's ``[extra]`` table."""
        scene = Scene.load(scene) if isinstance(scene, str) else scene
        e = scene.extra
        unit = math.pi / 180.0  # the shipped scene is in degrees
        start: dict[str, pin.SE3] = {}
        goal: dict[str, pin.SE3] = {}
        qs = robot.neutral()[robot.base_nq:].copy()
        for a in robot.arms:
            for key, out in (("start", start), ("goal", goal)):
                v = e.get(f"{key}_{a}")
                if v is None or len(v) != 6:
                    raise ValueError(f"scene {scene.name!r}: [extra] needs {key}_{a} = [x, y, z, roll, pitch, yaw]")
                out[a] = pin.SE3(rpy_to_matrix(*(np.asarray(v[3:], float) * unit)), np.asarray(v[:3], float))
            qa = e.get(f"q_start_{a}")
            if qa is None or len(qa) != robot.arm(a).n:
                raise ValueError(f"scene {scene.name!r}: [extra] needs q_start_{a} ({robot.arm(a).n} joint angles)")
            qs[robot.arm(a).j_idx] = np.asarray(qa, float) * unit
        # the stored angles choose the IK branch; the exact start configuration is the IK solution
        from ...model.ik import IKOptions, solve_arm_ik

        q = robot.configuration(qs)
        for a in robot.arms:
            res = solve_arm_ik(robot, a, start[a], q, IKOptions(tol_position=1e-12, tol_orientation=1e-12,
                                                               max_iterations=100))
            if res.position_error > 1e-9 or res.orientation_error > 1e-9:
                raise ValueError(f"scene {scene.name!r}: q_start_{a} does not lead IK to start_{a} (error "
                                 f"{res.position_error:.3g} m, {res.orientation_error:.3g} rad)")
            q = res.q
        return cls(robot, scene, start, goal, robot.joints_of(q).copy())


def _time_scaled(hands: dict, T_old: float, T_new: float) -> dict:
    """The same hand paths run over ``T_new`` instead of ``T_old`` [s] (exact time scaling)."""
    return {a: HandTrajectory(h.position.time_scaled(T_new / T_old),
                              BezierOrientation(h.orientation.R0, h.orientation.R1, T_new, h.orientation.control),
                              h.waypoints) for a, h in hands.items()}


def hand_separation(task: SplineRRTTask, trials: int, separate: bool, options: CoordinatedRRTStarOptions | None = None,
                    speed_limit: float = 0.1) -> np.ndarray:
    """Smallest distance [m] between the two hands along the smoothed, time-synchronised splines for
    ``trials`` seeds (0 .. trials−1), with separated sampling or without (the paper's Fig. 4 (b)
    vs (a)); NaN for failed plans."""
    base = options or CoordinatedRRTStarOptions(hand_radius=0.15, max_iterations=400, time_limit=10.0)
    from dataclasses import replace

    out = np.full(trials, np.nan)
    arms = list(task.start)
    for k in range(trials):
        pl = CoordinatedRRTStar(task.scene, replace(base, separate=separate, seed=k))
        res = pl.plan({a: (task.start[a].translation, task.goal[a].translation) for a in arms})
        if not res.success:
            continue
        hands, T, _ = smooth_hand_paths(res.paths, task.start, task.goal, speed_limit)
        t = np.linspace(0.0, T, 2001)
        out[k] = float(np.linalg.norm(hands[arms[0]].position(t) - hands[arms[1]].position(t), axis=1).min())
    return out


# --------------------------------------------------------------------------- pipeline
@dataclass
class SplineRRTResult:
    """Everything :func:`run_spline_rrt` produced: the plan, the hand references, the duration T
    [s], the tracked joint trajectory and its independent evaluation (:func:`evaluate`), timings
    [s], and the optimized variant (``optimized``: the :class:`~optplan.problem.Solution` and its
    evaluation on a dense grid; None when not run)."""

    task: SplineRRTTask
    plan: CoordinatedPlan
    hands: dict
    T: float
    tracking: TrackingResult | None
    evaluation: dict | None
    timings: dict
    info: dict = field(default_factory=dict)
    optimized: dict | None = None

    @property
    def success(self) -> bool:
        return self.plan.success and self.tracking is not None

    def figures(self, ev: dict | None = None, T: float | None = None) -> dict:
        """The headline figures of one evaluation (the example's JSON keys)."""
        ev = self.evaluation if ev is None else ev
        if ev is None:
            raise ValueError("SplineRRTResult.figures: no evaluation to report (the plan failed)")
        arms = list(self.hands)
        out = {"duration_s": float(self.T if T is None else T),
               "max_ee_speed_m_s": {a: float(np.linalg.norm(np.gradient(_ee_positions(self.task.robot, ev["q"], a),
                                                                        ev["t"], axis=0), axis=1).max())
                                    for a in arms},
               "max_tracking_error_m": float(max(ev[f"tracking_position_m_{a}"].max() for a in arms)),
               "max_tracking_error_rad": float(max(ev[f"tracking_orientation_rad_{a}"].max() for a in arms)),
               "min_link_distance_m": float(ev["link_distance_m"].min()),
               "final_base_rpy_deg": np.degrees(ev["base_rpy"][-1]).tolist()}
        return out


def _ee_positions(robot: RobotModel, Q: np.ndarray, arm: str) -> np.ndarray:
    kin = Kinematics(robot)
    fr = robot.arm(arm).ee_frame
    return np.array([kin.frame_placement(q, fr).translation for q in Q])


def run_spline_rrt(robot: RobotModel | None = None, task: SplineRRTTask | None = None, *,
                   plan_options: CoordinatedRRTStarOptions | None = None, speed_limit: float = 0.1,
                   joint_accel_limit: float = 0.1, optimize_durations: bool = False,
                   tracking: TrackingOptions | None = None, optimize_options: OptimizeOptions | None = None,
                   run_optimizer: bool = True, sample_dt: float = 0.05) -> SplineRRTResult:
    """Spline-RRT* on the shipped task (robot ``splinerrt_ffsr``, scene ``splinerrt_capture``) or
    the given one: plan → quartic splines (T from ‖ẋ‖ ≤ ``speed_limit`` [m/s]) → resolved-rate
    tracking; T is then stretched (an exact time scaling of the references) until the tracked joint
    rates stay within the robot's velocity limits and the joint accelerations within
    ``joint_accel_limit`` [rad/s²] (the joint limits of the paper's Eq. 6). With ``run_optimizer``
    the optimized variant follows: the NLP (evaluated on a dense grid and at its knots) and its
    execution (:func:`track` of the hand positions with the NLP's joints as the redundancy
    reference, ``optimized["executed"]``). Never raises for a failed plan: ``result.plan.status`` says."""
    robot = robot or RobotModel.from_name("splinerrt_ffsr")
    task = task or SplineRRTTask.from_scene(robot)
    po = plan_options or CoordinatedRRTStarOptions(hand_radius=0.15, max_iterations=400, seed=0, time_limit=5.0)
    tim = {}
    t0 = time.perf_counter()
    plan = CoordinatedRRTStar(task.scene, po).plan({a: (task.start[a].translation, task.goal[a].translation)
                                                    for a in robot.arms})
    tim["plan_s"] = time.perf_counter() - t0
    if not plan.success:
        return SplineRRTResult(task, plan, {}, float("nan"), None, None, tim, {"message": plan.message})
    t1 = time.perf_counter()
    hands, T, info = smooth_hand_paths(plan.paths, task.start, task.goal, speed_limit, optimize_durations)
    tim["smooth_s"] = time.perf_counter() - t1
    tim["plan_and_smooth_s"] = tim["plan_s"] + tim["smooth_s"]
    info["T_speed_s"] = T
    t2 = time.perf_counter()
    vlim = float(np.min(robot.velocity_limit))
    tr = ev = None
    for _round in range(4):
        tr = track(robot, hands, task.q_start, T, tracking)
        assert tr.qdd is not None   # track() fills it
        peak_v = float(np.abs(tr.qd).max())
        peak_a = float(np.abs(tr.qdd).max())
        ratio = max(peak_v / vlim, math.sqrt(peak_a / joint_accel_limit))
        info.setdefault("stretch_rounds", []).append({"T_s": T, "peak_rate_rad_s": peak_v, "peak_accel_rad_s2": peak_a})
        if ratio <= 1.0:
            break
        T_new = T * ratio * 1.02
        hands = _time_scaled(hands, T, T_new)
        T = T_new
    tim["track_s"] = time.perf_counter() - t2
    assert tr is not None   # the stretch loop runs at least once
    ev = evaluate(robot, hands, tr.t, tr.joints, tr.qd, scene=task.scene, joint_accelerations=tr.qdd)
    res = SplineRRTResult(task, plan, hands, T, tr, ev, tim, info)
    if run_optimizer:
        oo = optimize_options or OptimizeOptions()
        T_opt = T * oo.duration_factor
        hands_opt = _time_scaled(hands, T, T_opt)
        t3 = time.perf_counter()
        sol, prob = optimize(robot, task, hands_opt, T_opt, tr, oo)
        tim["optimize_s"] = time.perf_counter() - t3
        t = np.linspace(0.0, T_opt, int(round(T_opt / sample_dt)) + 1)
        s = sol.sample(t)
        ev_o = evaluate(robot, hands_opt, t, s["q"], s["qd"], scene=task.scene, joint_accelerations=s["qdd"])
        knots = evaluate(robot, hands_opt, sol.t, sol.q, sol.qd, scene=task.scene, joint_accelerations=sol.qdd)
        t4 = time.perf_counter()

        def reference(tt):
            smp = sol.sample([min(max(tt, 0.0), sol.t[-1])])
            return smp["q"][0], smp["qd"][0]
        ex = track(robot, hands_opt, task.q_start, T_opt, tracking, reference=reference)
        ev_x = evaluate(robot, hands_opt, ex.t, ex.joints, ex.qd, scene=task.scene, joint_accelerations=ex.qdd)
        tim["execute_s"] = time.perf_counter() - t4
        res.optimized = {"solution": sol, "evaluation": ev_o, "knots": knots, "problem": prob, "T": T_opt,
                         "hands": hands_opt, "executed": ex, "executed_evaluation": ev_x}
    return res
