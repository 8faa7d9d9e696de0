"""Planning trials of the TCBiRRT paper, Section 5.1: both nominal object poses of a scene are perturbed
by ``T = T_nominal · T_e`` with ``T_e`` = (Euler RPY uniform in [-0.5, 0.5] rad per axis, position
uniform in [-0.2, 0.2] m per axis — scaled by the robot's arm reach / the paper robot's when the
scene does not set ``[extra] trial_position_range``), and start/goal joint configurations are solved by IK. A trial
whose start or goal has no valid IK (no convergence, collision, clearance below
``min_clearance``) is regenerated with a new perturbation, and the regenerations are counted.

IK of a trial pose: PathInverseKinematics (the TCBiRRT paper Alg. 3) from the scene's nominal
configuration (``[extra] q_start`` / ``q_goal`` in the scene TOML, both hands on the object at the
nominal pose) along the interpolated object poses to the perturbed pose, i.e. the IK solution on
the nominal configuration's branch; when that fails, closed-chain IK from ``ik_restarts`` random
seeds. Every trial has its own seed (``SeedSequence(seed, spawn_key=(index,))``), so a trial is the
same whatever order or process it is generated in.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .constraints.closed_chain import ClosedChainKinematics, IKSettings, closure_error
from .errors import ModelError, OptionError, UnreachableError, check_real, real_array
from .geometry.spatial import pose_to_vector, rpy_to_matrix, vector_to_pose
from .model.robot import RobotModel
from .planners.task_space import interpolate_task
from .planners.validity import ValidityChecker
from .scene import Scene

__all__ = ["TrialOptions", "Trial", "TrialGenerator", "perturb_pose", "trial_seed"]
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrialOptions:
    """How the benchmark's start/goal tasks are drawn (the TCBiRRT paper, Section 5.1)."""

    #: Half-width of the uniform position perturbation of the object [m] (the paper: 0.2).
    position_range: float = 0.2
    #: Half-width of the uniform RPY perturbation, per axis [rad] (the paper: 0.5).
    angle_range: float = 0.5
    #: Clearance required at start and goal [m].
    min_clearance: float = 0.02
    #: Random-seed IK attempts after the continuation from the nominal configuration fails [count].
    ik_restarts: int = 20
    #: Object poses between the nominal and the perturbed pose [count].
    continuation_steps: int = 10
    #: Start and goal joints at least this far inside their limits [rad].
    limit_margin: float = 0.05
    #: Redraws per trial before giving up [count].
    max_regenerations: int = 200

    def __post_init__(self):
        from .limits import MAX_COORDINATE_M

        maxima = {"position_range": MAX_COORDINATE_M, "angle_range": 2 * math.pi, "min_clearance": MAX_COORDINATE_M,
                  "limit_margin": 2 * math.pi}
        for name, hi in maxima.items():
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and 0 <= v <= hi):
                raise OptionError(f"TrialOptions.{name}: expected a number >= 0 and <= {hi:g}, got {v!r}")
        for name in ("ik_restarts", "continuation_steps", "max_regenerations"):
            v = getattr(self, name)
            if not (isinstance(v, int) and not isinstance(v, bool) and v >= 1):
                raise OptionError(f"TrialOptions.{name}: expected an int >= 1, got {v!r}")


@dataclass(frozen=True)
class Trial:
    """One planning task: object poses, joint configurations (both hands on the object), the
    planner seed, and how many perturbations were rejected before this one."""

    scene: str
    index: int
    seed: int
    object_start: pin.SE3
    object_goal: pin.SE3
    q_start: np.ndarray
    q_goal: np.ndarray
    regenerations: int

    def to_dict(self) -> dict:
        return {"scene": self.scene, "index": self.index, "seed": self.seed,
                "object_start": pose_to_vector(self.object_start).tolist(),
                "object_goal": pose_to_vector(self.object_goal).tolist(),
                "q_start": self.q_start.tolist(), "q_goal": self.q_goal.tolist(), "regenerations": self.regenerations}

    @classmethod
    def from_dict(cls, d: dict) -> Trial:
        return cls(d["scene"], int(d["index"]), int(d["seed"]), vector_to_pose(d["object_start"]),
                   vector_to_pose(d["object_goal"]), np.asarray(d["q_start"], float), np.asarray(d["q_goal"], float),
                   int(d["regenerations"]))


def trial_seed(seed: int, index: int) -> np.random.SeedSequence:
    """The seed sequence of trial ``index`` of a run with base ``seed``."""
    return np.random.SeedSequence(int(seed), spawn_key=(int(index),))


def perturb_pose(nominal: pin.SE3, rng: np.random.Generator, position_range: float = 0.2,
                 angle_range: float = 0.5) -> pin.SE3:
    """``nominal · T_e`` with T_e's position uniform in ±position_range [m] and RPY uniform in
    ±angle_range [rad] per axis (Section 5.1)."""
    pe = rng.uniform(-position_range, position_range, 3)
    eu = rng.uniform(-angle_range, angle_range, 3)
    return nominal * pin.SE3(rpy_to_matrix(*eu), pe)


def _reach_scale(robot: RobotModel) -> float:
    """The robot's mean sampled arm reach / the TCBiRRT paper robot's (1 for that robot; the
    paper's 0.2 m perturbation is sized for its 2.7 m arms)."""
    from .planners.tcbirrt_options import reach_scale

    if robot.is_floating or not robot.arms:
        return 1.0
    return reach_scale(robot)


class TrialGenerator:
    """Trials of one scene. ``generate(index, seed)`` → :class:`Trial` (deterministic)."""

    def __init__(self, robot: RobotModel, scene: Scene, options: TrialOptions | None = None,
                 ik: IKSettings | None = None):
        if scene.object is None or scene.start is None or scene.goal is None:
            raise ModelError(f"scene {scene.name!r}: trials need [object], [start] and [goal]")
        self.robot, self.scene = robot, scene
        if options is None:   # a scene may narrow the perturbation ([extra] trial_position_range [m], trial_angle_range [rad])
            ex = scene.extra or {}
            where = f"scene {scene.name!r}: extra."
            options = TrialOptions(
                position_range=check_real(ex.get("trial_position_range", 0.2 * _reach_scale(robot)),
                                          where + "trial_position_range", minimum=0.0, unit="m", error=ModelError),
                angle_range=check_real(ex.get("trial_angle_range", 0.5), where + "trial_angle_range", minimum=0.0,
                                       unit="rad", error=ModelError))
        self.options = options
        self._check_reach()
        self.ik = ik or IKSettings()
        self.ik_restart = IKSettings(tol_position=self.ik.tol_position, tol_orientation=self.ik.tol_orientation,
                                     max_iterations=200, damping=0.02, max_step=0.3)
        self.kin = ClosedChainKinematics(robot, scene.object.grasps)
        self.checker = ValidityChecker(robot, scene, margin=self.options.min_clearance)
        extra = scene.extra or {}
        self.q_nominal = {}
        for key, M in (("q_start", scene.start), ("q_goal", scene.goal)):
            q = None
            if key in extra:
                q = real_array(extra[key], f"scene {scene.name!r}: extra.{key}", ModelError) * (
                    math.pi / 180.0 if extra.get("q_unit", "rad") == "deg" else 1.0)
                if q.shape != (robot.nq,) or not np.all(np.isfinite(q)):
                    raise ModelError(f"scene {scene.name!r}: extra.{key} must have {robot.nq} finite joint values, "
                                     f"got {extra[key]!r}")
                q, _ = self.kin.ik(q, M.rotation, M.translation, self.ik)   # polish to the IK tolerance
            self.q_nominal[key] = q

    def _check_reach(self) -> None:
        """:class:`UnreachableError` before any sampling when a hand's grasp at the nominal start or
        goal pose is farther from its arm's first joint than the arm can reach, even after the
        most favourable perturbation (position ±position_range per axis, rotation ≤ √3·angle_range
        about the object's origin). A necessary condition only (an upper bound on the reach);
        fixed-base robots (a floating base moves the shoulders)."""
        from .planners.task_sampling import arm_reach

        if self.robot.is_floating:
            return
        assert self.scene.object is not None   # the constructor checked [object]
        o = self.options
        for which, M in (("start", self.scene.start), ("goal", self.scene.goal)):
            assert M is not None
            for arm, G in self.scene.object.grasps.items():
                shoulder, reach = arm_reach(self.robot, arm)
                hand = (M * G).translation
                dist = float(np.linalg.norm(hand - shoulder))
                slack = math.sqrt(3.0) * o.position_range + min(2.0, math.sqrt(3.0) * o.angle_range) * float(
                    np.linalg.norm(G.translation))
                if dist - slack > reach:
                    raise UnreachableError(
                        f"scene {self.scene.name!r}: unreachable {which}: arm {arm!r}'s grasp at "
                        f"{np.round(hand, 3).tolist()} m is {dist:.3f} m from the arm's first joint at "
                        f"{np.round(shoulder, 3).tolist()} m; the arm reaches at most {reach:.3f} m "
                        f"(+{slack:.3f} m of trial perturbation); move the object's [{which}] pose closer")

    # ------------------------------------------------------------------ IK of one pose
    def _acceptable(self, q: np.ndarray) -> bool:
        m = self.options.limit_margin
        r = self.robot
        return bool(np.all(q >= r.lower + m) and np.all(q <= r.upper - m) and self.checker.is_valid(q))

    def solve(self, M: pin.SE3, nominal_pose: pin.SE3, q_nominal: np.ndarray | None,
              rng: np.random.Generator) -> np.ndarray | None:
        """A valid configuration holding the object at ``M`` (continuation, then random restarts)."""
        kin = self.kin
        q: np.ndarray | None
        if q_nominal is not None:
            q = q_nominal
            for R, p in interpolate_task(nominal_pose.rotation, nominal_pose.translation, M.rotation, M.translation,
                                         self.options.continuation_steps):
                q, _ = kin.ik(q, R, p, self.ik)
                if q is None:
                    break
            if q is not None and self._acceptable(q):
                return q
        for _ in range(self.options.ik_restarts):
            q, _ = kin.ik(self.random_seed(rng), M.rotation, M.translation, self.ik_restart)
            if q is not None:
                q, _ = kin.ik(q, M.rotation, M.translation, self.ik)   # polish
            if q is not None and self._acceptable(q):
                return q
        return None

    def random_seed(self, rng: np.random.Generator) -> np.ndarray:
        """IK seed: joints uniform in [-π, π] ∩ their limits (not [-π, π] clipped to the limits: that
        puts a joint with a one-sided range — a Panda elbow in [-3.07, -0.07] rad — at its limit
        half of the time, where IK stalls; the same draws for limits that contain [-π, π])."""
        r = self.robot
        return rng.uniform(np.maximum(r.lower, -np.pi), np.minimum(r.upper, np.pi), self.robot.nq)

    def nominal_configuration(self, which: str, rng: np.random.Generator, tries: int = 200,
                              min_limit_margin: float = 1.0) -> np.ndarray | None:
        """A configuration for the nominal start (``which="start"``) or goal pose: among ``tries``
        random-seed IK solutions with all joints ``min_limit_margin`` [rad] inside their limits, the
        one with the largest exact clearance (coal; helper used to write a scene's ``[extra]
        q_start / q_goal``)."""
        from .collision.checker import CollisionChecker

        M = self.scene.start if which == "start" else self.scene.goal
        assert M is not None   # the constructor checked [start] and [goal]
        cc = CollisionChecker(self.robot, self.scene)
        best, best_d = None, -np.inf
        for _ in range(tries):
            q, _ = self.kin.ik(self.random_seed(rng), M.rotation, M.translation, self.ik_restart)
            if q is None:
                continue
            q, _ = self.kin.ik(q, M.rotation, M.translation, self.ik)
            if q is None or not self._acceptable(q):
                continue
            if np.any(q < self.robot.lower + min_limit_margin) or np.any(q > self.robot.upper - min_limit_margin):
                continue
            d = cc.min_distance(q)[0]
            if d > best_d:
                best, best_d = q, d
        return best

    # ------------------------------------------------------------------ trials
    def generate(self, index: int, seed: int) -> Trial:
        """Trial ``index`` of a run with base ``seed`` (regenerates until both ends have valid IK)."""
        ss = trial_seed(seed, index)
        rng = np.random.default_rng(ss)
        planner_seed = int(ss.generate_state(1)[0])
        o = self.options
        for k in range(o.max_regenerations + 1):
            Ms = perturb_pose(self.scene.start, rng, o.position_range, o.angle_range)
            Mg = perturb_pose(self.scene.goal, rng, o.position_range, o.angle_range)
            qs = self.solve(Ms, self.scene.start, self.q_nominal["q_start"], rng)
            if qs is None:
                continue
            qg = self.solve(Mg, self.scene.goal, self.q_nominal["q_goal"], rng)
            if qg is None:
                continue
            return Trial(self.scene.name, int(index), planner_seed, Ms, Mg, qs, qg, k)
        raise UnreachableError(f"scene {self.scene.name!r}, trial {index}: no valid start/goal IK after "
                               f"{o.max_regenerations} regenerations (object poses perturbed by ±{o.position_range:g} "
                               f"m, ±{o.angle_range:g} rad around the scene's [start] and [goal]): the poses are "
                               "out of reach or in collision")

    def check_trial(self, t: Trial, tol: float = 1e-6) -> bool:
        """Both configurations hold the object at the trial's poses within ``tol``."""
        assert self.scene.object is not None   # the constructor checked [object]
        for q in (t.q_start, t.q_goal):
            ep, eo = closure_error(self.robot, self.scene.object.grasps, q)
            if ep > tol or eo > tol:
                return False
        return True
