"""The segment NLP of a fixed-base robot — one motion between two rest configurations with the
closed chain, joint position and velocity limits, collision avoidance and a minimum-jerk cost —
as a thin builder of an :class:`~optplan.problem.OptProblem` on the B-spline kernel core
(:mod:`.spline_core`; docs/decisions/0021-pipeline-on-the-shared-core.md).

What the problem is made of (the same terms as :func:`optplan.tasks.segment_problem`, which the
pipeline uses): ``JointBoundary`` at rest at both ends, the ``ClosedChain`` at the knots,
``JointPositionLimits`` on the control points (hence everywhere, convex hull),
``JointVelocityLimits`` on the velocity control points (rows only where the first guess is fast,
:attr:`JointVelocityLimits.activation`; the rest checked after each solve), ``CollisionAvoidance``
as fixed-normal separating planes (:mod:`.plane_rows`), ``Smoothness("jerk")``. Every method
below is a call on :attr:`SplineSegmentProblem.problem`; add your own terms there.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigurationError
from ..model.robot import RobotModel
from ..scene import Scene
from .bspline import check_knot_guess, rest_to_rest
from .collision_term import CollisionAvoidance, CollisionModel
from .frame_terms import ClosedChain
from .kernels import KernelCache, geometry_points
from .plane_rows import SPLINE_ACTIVATION
from .problem import OptProblem
from .solution import Solution
from .terms import JointBoundary, JointPositionLimits, JointVelocityLimits, NumericTrajectory, Smoothness

__all__ = ["KernelCache", "SegmentSpec", "SplineSegmentProblem", "knots_from_solution"]


def knots_from_solution(robot: RobotModel, solution: Solution, N: int,
                        closed_chain: ClosedChain | None = None) -> np.ndarray:
    """A solution of any grid sampled at the N + 1 knots of a grid of the same duration ((N+1) × nj
    [rad]); with ``closed_chain`` each interior knot is projected onto it (a coarser grid's solution
    drifts between its knots)."""
    q = np.array(solution.sample(np.linspace(solution.t[0], solution.t[-1], N + 1))["q"], float)
    if closed_chain is not None:
        from ..constraints.closed_chain import project_closed_chain

        data = robot.model.createData()
        for k in range(1, N):
            q[k] = project_closed_chain(robot, q[k], closed_chain, data=data).q
    return q


@dataclass(frozen=True)
class SegmentSpec:
    """What a segment NLP is: a rest-to-rest motion of ``robot`` in ``scene``.

    n_intervals: N (≥ 4); duration: T [s]; q_start, q_end [rad]: pinned rest configurations;
    closed_chain: the two hands' relative pose to keep at the knots (None: no closed chain);
    lower, upper [rad]: joint position limits (equal entries fix a joint, e.g. a holding arm);
    velocity_limit [rad/s]; margin [m]: clearance of every active collision pair;
    object_arm: the arm whose hand carries the scene's object (None: the first grasp's arm);
    activation [m], window [knots]: collision pairs closer than ``activation`` along the initial
    guess are constrained at the knots within ``window`` (as :class:`CollisionAvoidance`; the
    rest are checked by ``verify`` after the solve, see docs/decisions/0012-segment-nlp-rows.md);
    velocity_activation [fraction of the limit, 0-1]: a velocity control point's entry gets a row
    when the initial guess's exceeds this fraction of the joint's limit (0: every entry). A pair's
    margin is at most half the guess's exact clearance within ``window`` knots of every knot where
    a collision-free guess runs closer than ``margin`` (a planner's path may pass closer than the
    margin where nothing wider fits); see docs/decisions/0010-knot-transcription-defaults.md."""

    n_intervals: int
    duration: float
    q_start: np.ndarray
    q_end: np.ndarray
    closed_chain: ClosedChain | None = None
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    velocity_limit: np.ndarray | None = None
    margin: float = 0.02
    object_arm: str | None = None
    activation: float = SPLINE_ACTIVATION
    window: int = 3
    velocity_activation: float = 0.5


class SplineSegmentProblem:
    """The segment NLP of the module docstring: ``set_initial_path`` / ``set_initial``, then
    ``solve`` → :class:`~optplan.problem.Solution`. :attr:`problem` is the
    :class:`~optplan.problem.OptProblem` it builds (add constraints and costs there)."""

    def __init__(self, robot: RobotModel, scene: Scene | None, spec: SegmentSpec):
        KernelCache.of(robot)   # a floating robot is refused here, by name
        va = spec.velocity_activation
        if isinstance(va, bool) or not isinstance(va, (int, float, np.integer, np.floating)) or not 0 <= va <= 1:
            raise ValueError(f"velocity_activation: expected a fraction of the limit in [0, 1], got {va!r}")
        N = int(spec.n_intervals)
        if N < 4:
            raise ConfigurationError(f"SegmentSpec.n_intervals: expected at least 4 intervals, got {N}")
        self.robot, self.scene, self.spec, self.N = robot, scene, spec, N
        (self.T, self.h, self.M, self.q0, self.q1, _, _, self.lower,
         self.upper) = rest_to_rest(robot, N, spec.duration, spec.q_start, spec.q_end, spec.lower, spec.upper)
        z = np.zeros(robot.nj)
        prob = self.problem = OptProblem(robot, N, self.T, transcription="bspline")
        prob.add_constraint(JointBoundary("start", q=self.q0, qd=z, qdd=z), name="start")
        prob.add_constraint(JointBoundary("end", q=self.q1, qd=z, qdd=z), name="end")
        if spec.closed_chain is not None:
            prob.add_constraint(spec.closed_chain, name="closed_chain")
        prob.add_constraint(JointPositionLimits(lower=self.lower.tolist(), upper=self.upper.tolist()), name="joint_limits")
        prob.add_constraint(JointVelocityLimits(limit=spec.velocity_limit, activation=float(va)), name="velocity_limits")
        if scene is not None:
            term = CollisionAvoidance(scene, margin=spec.margin, activation=spec.activation, window=spec.window,
                                      object_arm=spec.object_arm, fixed_normals=True)
            for g, shape in term.model(robot).robot_shape.items():   # unsupported geometry: refused now, by name
                if shape is None:
                    geometry_points(robot, g)
            prob.add_constraint(term, name="collision")
        prob.add_cost(Smoothness("jerk"), name="jerk")

    # ------------------------------------------------------------------ settings
    @property
    def compile_kernels(self) -> bool | str:
        """Kernels from C compiled once per robot (:class:`~optplan.problem.OptProblem`'s option)."""
        return self.problem.compile_kernels

    @compile_kernels.setter
    def compile_kernels(self, value: bool | str) -> None:
        self.problem.compile_kernels = value

    @property
    def col(self) -> CollisionModel | None:
        """The collision model of the current build (checker, active and constant pairs, relaxed
        margins); None without a scene. Plans the rows along the initial guess if needed."""
        if self.scene is None:
            return None
        return self.problem.term_data("collision").info.get("model")

    # ------------------------------------------------------------------ initial guess
    def set_initial(self, q: ArrayLike | None = None, *, solution: Solution | None = None,
                    closed_chain: ClosedChain | None = None) -> None:
        """Initial guess from knot configurations ``q`` ((N+1) × nj [rad], on this problem's grid;
        clipped to the joint limits) or from a :class:`Solution` of any grid (sampled at this
        grid's knots; with ``closed_chain``, each interior knot is projected onto it)."""
        if solution is not None:
            q = knots_from_solution(self.robot, solution, self.N, closed_chain)
        Q = np.array(check_knot_guess(q, self.N, self.robot.nj), float)
        Q[1:-1] = np.clip(Q[1:-1], self.lower, self.upper)
        self.problem.set_initial(q=Q)

    def set_initial_path(self, path: ArrayLike, closed_chain: ClosedChain | None = None) -> bool:
        """Initial guess from a planner's path (M × nj, no timing;
        :meth:`OptProblem.set_initial_path`). Returns whether every projection converged."""
        return self.problem.set_initial_path(path, closed_chain)

    def smooth_initial(self, weight: float = 10.0, closed_chain: ClosedChain | None = None) -> None:
        """Round off the initial guess's corners (:meth:`OptProblem.smooth_initial`; ``weight`` [-])."""
        if self.problem.initial_guess is None:
            raise ValueError("no initial guess to smooth: call set_initial(...) first")
        self.problem.smooth_initial(weight, closed_chain)

    def knot_configurations(self) -> np.ndarray:
        """Knot configurations ((N+1) × nj [rad]) of the initial guess the NLP starts from: on the
        B-spline core, the spline fitted to the given knots between the fixed ends (the guess the
        collision rows were planned along)."""
        x0 = self.problem.initial_guess
        if x0 is None:
            raise ValueError("no initial guess: call set_initial(...) or set_initial_path(...) first")
        backend = getattr(self.problem, "_spline", None)
        core = getattr(backend, "core", None)
        if backend is not None and core is not None:
            return np.asarray(core.M["q"] @ core.control_points(backend.guess(self.spec.duration)), float)
        return np.asarray(self.problem.tp.unpack(x0)["q"], float)

    # ------------------------------------------------------------------ retries
    def rebuild(self) -> None:
        """Rebuild at the next solve."""
        self.problem.rebuild()

    def add_activation(self, q_knots: np.ndarray) -> None:
        """Also activate the pairs that come close along ``q_knots`` ((N+1) × nj), e.g. a solution
        that verification found colliding (:meth:`CollisionAvoidance.with_activation`)."""
        if self.scene is None:
            return
        Q = np.asarray(q_knots, float)
        h = self.problem.terms["collision"]
        assert isinstance(h.term, CollisionAvoidance)   # the term this builder added
        self.problem.replace_term(h, h.term.with_activation(NumericTrajectory(self.robot, Q, Q, Q, Q[:-1], self.T)))

    def boost_between_knots(self, traj_t: ArrayLike, traj_q: ArrayLike, knot_t: ArrayLike) -> int:
        """Raise the margin where a solution cut a corner between knots
        (:meth:`CollisionAvoidance.with_boost` on the pairs of the last build); the number of
        (pair, knot) rows boosted."""
        if self.scene is None:
            return 0
        h = self.problem.terms["collision"]
        assert isinstance(h.term, CollisionAvoidance)   # the term this builder added
        col, n = h.term.with_boost(self.problem.term_data(h), np.asarray(traj_t, float), traj_q, knot_t)
        self.problem.replace_term(h, col)
        return n

    def velocity_violations(self, solution: Solution, tol: float = 1e-9) -> np.ndarray:
        """Entries (``i·nj + j``) of the velocity control points ((N+2) × nj) of ``solution`` that
        exceed the joint speed limit by more than ``tol`` [rad/s]. Empty: q̇ is within its limits
        everywhere (convex hull). The problem's solve already re-solves with the rows it missed."""
        if solution.x is None:
            return np.zeros(0, int)
        nj = self.robot.nj
        P = np.asarray(solution.x, float)[:(self.N + 3) * nj].reshape(self.N + 3, nj)
        V = np.abs(np.diff(P, axis=0)) / self.h
        _, hi = JointVelocityLimits(limit=self.spec.velocity_limit).limits(self.robot)
        return np.flatnonzero((V - hi > tol).ravel())

    def infeasibilities(self, solution: Solution, n: int = 10) -> list[Any]:
        """The ``n`` worst constraint rows of ``solution`` (:meth:`OptProblem.infeasibilities`)."""
        return self.problem.infeasibilities(solution, n)

    # ------------------------------------------------------------------ solve
    def solve(self, ipopt_options: dict[str, Any] | None = None, *, tol: float = 1e-6, max_iter: int = 500) -> Solution:
        """Solve with IPOPT (:meth:`OptProblem.solve`, no dense check: the caller verifies). Never
        raises for a failed solve: the status is in the Solution."""
        if self.problem.initial_guess is None:
            raise ValueError("no initial guess: call set_initial(...) or set_initial_path(...) first")
        return self.problem.solve(ipopt_options, tol=tol, max_iter=max_iter, guarantees=False)
