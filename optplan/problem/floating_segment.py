"""A rest-to-rest motion of a free-floating robot with its base attitude constrained at the end
(base-attitude restoration): a thin builder of the :class:`~optplan.problem.OptProblem` on the
B-spline kernel core.

:class:`FloatingSplineProblem` turns a :class:`FloatingSegmentSpec` into the problem's terms —

* ``JointBoundary`` at rest at both ends (the three end control points fixed by bounds);
* ``BaseAttitude(at="end")`` with the spec's end attitude (the base attitude from zero momentum,
  RK4 per interval, is the core's);
* ``JointPositionLimits`` on the control points and ``JointVelocityLimits`` on the velocity
  control points (both hold between the knots: convex hull);
* ``ClosedChain`` at the knots the ends do not pin (``skip_pinned``);
* ``Smoothness`` (``∫‖d³q/dt³‖² dt`` or ``∫‖q̈‖² dt``, exact)

— and solves it without the dense check between knots (``guarantees=False``: the closed chain
drifts ∝ h⁴ between knots by design; :func:`optplan.verify` judges a result). ``.problem`` is the
``OptProblem``: add your own terms there. Until 2026-11-28 this was a closed NLP of its own; the
two were measured equal in figures and CPU time (docs/decisions/0022-papers-on-the-shared-core.md).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..model.robot import RobotModel
from .bspline import check_knot_guess
from .floating_kernels import FloatingKernels, spline_basis
from .frame_terms import BaseAttitude, ClosedChain
from .problem import OptProblem
from .solution import Solution
from .terms import JointBoundary, JointPositionLimits, JointVelocityLimits, Smoothness

__all__ = ["FloatingKernels", "FloatingSegmentSpec", "FloatingSplineProblem", "spline_basis"]


@dataclass(frozen=True)
class FloatingSegmentSpec:
    """A rest-to-rest motion of a free-floating robot with its base attitude constrained at the end.

    n_intervals: N (≥ 4); duration: T [s]; q_start, q_end [rad]: pinned rest configurations;
    end_attitude: the base attitude at T relative to the one at 0 (3 × 3 rotation; None: the
    identity, i.e. attitude restoration; ``False``: free); closed_chain: the hands' relative pose
    to keep at the knots (None: free hands); lower, upper [rad]: joint position limits (default
    the model's); velocity_limit [rad/s] (default the model's; ``False``: none); n_sub: RK4 steps
    of the base attitude per interval; position_limits: False drops the joint position bounds;
    smoothness: the cost, ``"jerk"`` (∫‖d³q/dt³‖² dt) or ``"acceleration"`` (∫‖q̈‖² dt), both exact."""

    n_intervals: int
    duration: float
    q_start: np.ndarray
    q_end: np.ndarray
    end_attitude: object = None
    closed_chain: ClosedChain | None = None
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    velocity_limit: object = None
    n_sub: int = 1
    position_limits: bool = True
    smoothness: str = "jerk"


class FloatingSplineProblem:
    """The restoration problem of a :class:`FloatingSegmentSpec` (module docstring).
    ``set_initial(q)`` (knot configurations), then ``solve`` → :class:`~optplan.problem.Solution`
    (``base_quat``: the integrated attitude at the knots)."""

    def __init__(self, robot: RobotModel, spec: FloatingSegmentSpec, *, compile_kernels: bool | str = "auto"):
        if not robot.is_floating:
            raise ValueError(f"FloatingSplineProblem needs a free-floating robot; {robot.name!r} has a fixed base")
        if compile_kernels not in (True, False, "auto"):
            raise ValueError(f"compile_kernels: expected True, False or 'auto', got {compile_kernels!r}")
        N = int(spec.n_intervals)
        if N < 4:
            raise ValueError(f"n_intervals: expected ≥ 4, got {spec.n_intervals!r}")
        if isinstance(spec.n_sub, bool) or int(spec.n_sub) != spec.n_sub or spec.n_sub < 1:
            raise ValueError(f"n_sub: expected an integer ≥ 1, got {spec.n_sub!r}")
        if spec.smoothness not in ("jerk", "acceleration"):
            raise ValueError(f"smoothness: expected 'jerk' or 'acceleration', got {spec.smoothness!r}")
        R = None
        if spec.end_attitude is not False:
            R = np.eye(3) if spec.end_attitude is None else np.asarray(spec.end_attitude, float)
            if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
                raise ValueError(f"end_attitude: expected a 3 × 3 rotation matrix, got {R!r}")
        self.robot, self.spec, self.N, self.n_sub = robot, spec, N, int(spec.n_sub)
        self.T = float(spec.duration)
        self.h = self.T / N
        self.kernels = FloatingKernels.of(robot)
        nj, zero = robot.nj, np.zeros(robot.nj)
        q0 = robot.check_joints(spec.q_start, "q_start")
        q1 = robot.check_joints(spec.q_end, "q_end")
        prob = self.problem = OptProblem(robot, N, self.T, n_sub=self.n_sub, transcription="bspline",
                                         compile_kernels=compile_kernels)
        prob.add_constraint(JointBoundary("start", q=q0, qd=zero, qdd=zero))
        prob.add_constraint(JointBoundary("end", q=q1, qd=zero, qdd=zero))
        if R is not None:
            prob.add_constraint(BaseAttitude(target=R, at="end"))
        if spec.position_limits:
            lo = None if spec.lower is None else robot.check_joints(spec.lower, "lower").tolist()
            hi = None if spec.upper is None else robot.check_joints(spec.upper, "upper").tolist()
            prob.add_constraint(JointPositionLimits(lower=lo, upper=hi))
        if spec.velocity_limit is not False:
            vlim = robot.velocity_limit.copy() if spec.velocity_limit is None else np.broadcast_to(
                np.asarray(spec.velocity_limit, float), (nj,)).copy()
            prob.add_constraint(JointVelocityLimits(limit=vlim))
        if spec.closed_chain is not None:
            prob.add_constraint(dataclasses.replace(spec.closed_chain, skip_pinned=True))
        prob.add_cost(Smoothness(spec.smoothness))
        self._X0: np.ndarray | None = None

    def set_initial(self, q: npt.ArrayLike) -> None:
        """Initial guess from knot configurations ``q`` ((N+1) × nj [rad]); the core integrates
        the base attitude along it."""
        self._X0 = check_knot_guess(q, self.N, self.robot.nj)
        self.problem.set_initial(q=self._X0, t=np.linspace(0.0, self.T, self.N + 1))

    def solve(self, ipopt_options: dict[str, Any] | None = None, *, tol: float = 1e-8, dual_tol: float = 1e-6,
              max_iter: int = 500, max_wall_time: float = 120.0) -> Solution:
        """Solve with IPOPT (exact Hessian from the kernels, MUMPS). ``tol``: constraint violation,
        ``dual_tol``: IPOPT's overall ``tol``; ``max_wall_time`` [s]: IPOPT stops there with the
        status ``Maximum_WallTime_Exceeded``. Never raises for a failed solve: the status is in the
        Solution. ``ipopt_options`` are passed through (``"ipopt."`` prefix optional)."""
        from ..solver_options import check_solve_arguments

        check_solve_arguments(tol, max_iter, 1.0)
        check_solve_arguments(dual_tol, max_iter, 1.0)
        if not (isinstance(max_wall_time, (int, float)) and not isinstance(max_wall_time, bool)
                and np.isfinite(max_wall_time) and max_wall_time > 0):
            raise ValueError(f"max_wall_time: expected a positive number of seconds, got {max_wall_time!r}")
        if self._X0 is None:
            raise ValueError("no initial guess: call set_initial(...) first")
        opts = {"tol": dual_tol, "max_wall_time": float(max_wall_time), **dict(ipopt_options or {})}
        return self.problem.solve(opts, tol=tol, max_iter=max_iter, guarantees=False)
