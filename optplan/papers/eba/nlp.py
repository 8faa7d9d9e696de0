"""optplan's own base-attitude restoration: one trajectory NLP solved by IPOPT.

    θ(0) = θ0, θ(T) = θf, θ̇ = θ̈ = 0 at both ends       (JointBoundary)
    R_base(T) = R_base(0)                               (BaseAttitude, a hard constraint)
    joint position and velocity limits at every knot     (JointPositionLimits, JointVelocityLimits)
    [hands keep their relative pose at every knot]       (ClosedChain, end-constrained case)
    min ∫‖d³θ/dt³‖² dt                                   (Smoothness("jerk"))

Two transcriptions of the same problem (``NLPOptions.transcription``):

* ``"bspline"`` (default): an :class:`optplan.problem.OptProblem` on the B-spline kernel core — the
  joints as a uniform cubic B-spline (control points are the joint variables, the rest ends fix
  theirs; limits hold between the knots too), the base attitude from zero momentum by RK4 per
  interval, every row family a per-point kernel built once per robot and cached on disk, exact
  derivatives assembled from the mapped kernels (the former closed builder
  ``FloatingSplineProblem`` measured equal: docs/decisions/0022-papers-on-the-shared-core.md).
* ``"knots"``: :class:`optplan.problem.OptProblem` on the knot transcription
  (see :mod:`optplan.problem.transcription`): the state (q, q̇, q̈) and jerk at every knot, the same
  C2 piecewise cubic, the base quaternion by RK4 between knots; the NLP is one expanded symbolic
  graph (slower to build).

All give the same trajectory space (C2 piecewise cubics on the grid) and the same constraints;
the warm start is the joint-space quintic (free end) or its knot-wise projection onto the
closed-chain manifold.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pinocchio as pin

from ...geometry.splines import quintic_time_law
from ...model.robot import RobotModel
from ...problem import (
    BaseAttitude,
    ClosedChain,
    JointBoundary,
    JointPositionLimits,
    JointVelocityLimits,
    OptProblem,
    Smoothness,
)
from ...verification import verify
from .baselines import closed_chain_reference
from .core import MethodResult, Scenario, hermite_segment

__all__ = ["NLPOptions", "run_nlp", "build_nlp"]
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class NLPOptions:
    """Options of the base-attitude restoration NLP."""

    #: N: intervals of the grid (N+1 knots) [count].
    n_intervals: int = 20
    #: T: duration of the motion [s] (20 s as the paper's polynomial).
    duration: float = 20.0
    #: RK4 sub-steps of the base attitude per interval [count].
    n_sub: int = 1
    #: Minimised derivative: ``"jerk"`` or ``"acceleration"``.
    smoothness: str = "jerk"
    #: Impose the model's joint position limits (±360°) at every knot.
    position_limits: bool = True
    #: Impose the model's joint velocity limits (10 °/s) at every knot.
    velocity_limits: bool = True
    #: IPOPT's constraint-violation tolerance, and the one ``Solution.success`` requires [-].
    tol: float = 1e-8
    #: IPOPT's overall ``tol`` (dual infeasibility of the objective scaled to ≈ 1) [-]; see
    #: docs/decisions/0009-eba-nlp-solver-settings.md.
    dual_tol: float = 1e-6
    #: IPOPT iterations, at most [count].
    max_iter: int = 500
    #: Samples per interval of the returned trajectory [count].
    sample_density: int = 10
    #: ``"bspline"`` (:class:`~optplan.problem.OptProblem` on the B-spline kernel core) or ``"knots"``
    #: (:class:`~optplan.problem.OptProblem` on the knot transcription).
    transcription: str = "bspline"
    #: B-spline kernels from compiled C: True, False or ``"auto"`` (what an earlier run compiled).
    compile_kernels: bool | str = "auto"
    #: Warm-start the NLP from the same NLP solved on this many intervals [count] (None: off; ≥ 4).
    coarse_intervals: int | None = None
    #: IPOPT's wall-clock cap per solve [s].
    max_wall_time: float = 120.0

    def __post_init__(self):
        for n in ("n_intervals", "n_sub", "max_iter", "sample_density"):
            v = getattr(self, n)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"NLPOptions.{n}: expected an integer ≥ 1, got {v!r}")
        for n in ("duration", "tol", "dual_tol", "max_wall_time"):
            v = getattr(self, n)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise ValueError(f"NLPOptions.{n}: expected a positive finite number, got {v!r}")
        c = self.coarse_intervals
        if c is not None and (isinstance(c, bool) or not isinstance(c, (int, np.integer)) or c < 4):
            raise ValueError(f"NLPOptions.coarse_intervals: expected None or an integer ≥ 4, got {c!r}")
        if self.compile_kernels not in (True, False, "auto"):
            raise ValueError(f"NLPOptions.compile_kernels: expected True, False or 'auto', got {self.compile_kernels!r}")
        if self.transcription not in ("bspline", "knots"):
            raise ValueError(f"NLPOptions.transcription: expected 'bspline' or 'knots', got {self.transcription!r}")
        if self.smoothness not in ("jerk", "acceleration"):
            raise ValueError(f"NLPOptions.smoothness: expected 'jerk' or 'acceleration', got {self.smoothness!r}")

    @classmethod
    def free_end(cls, **overrides) -> NLPOptions:
        """N = 20, one RK4 step per interval. See docs/decisions/0011-paper-reproduction-grids-and-guards.md."""
        return cls(**overrides)

    @classmethod
    def end_constrained(cls, **overrides) -> NLPOptions:
        """N = 48: the closed chain holds at the knots only and drifts ∝ h⁴ between them;
        warm-started from the same NLP on 12 intervals (``coarse_intervals``).
        See docs/decisions/0011-paper-reproduction-grids-and-guards.md."""
        base: dict[str, Any] = dict(n_intervals=48, coarse_intervals=12)
        base.update(overrides)
        return cls(**base)


def build_nlp(robot: RobotModel, scenario: Scenario, options: NLPOptions | None = None):
    """The problem (with its warm start) and the :class:`ClosedChain` term (or None): an
    :class:`OptProblem` on the B-spline kernel core (``transcription="bspline"``) or on the knot
    transcription (``"knots"``)."""
    o = options or (NLPOptions.end_constrained() if scenario.closed_chain else NLPOptions.free_end())
    if o.transcription == "bspline":
        return _build_spline(robot, scenario, o)
    # the paper's reproduction as measured (knots); "bspline" above is the kernel NLP
    prob = OptProblem(robot, o.n_intervals, o.duration, n_sub=o.n_sub, transcription="knots")
    cc = _restoration_terms(prob, robot, scenario, o)
    if cc is not None:
        t, Q = closed_chain_reference(robot, scenario, o.n_intervals, o.duration)
        prob.set_initial(q=Q, t=t)
    else:
        prob.set_initial_straight_line(scenario.theta0, scenario.thetaf)
    prob.add_cost(Smoothness(o.smoothness))
    return prob, cc


def _restoration_terms(prob: OptProblem, robot: RobotModel, scenario: Scenario, o: NLPOptions) -> ClosedChain | None:
    """The restoration NLP's constraints on ``prob`` (either transcription): rest at both ends at the
    scenario's joints, the base attitude restored at the end, the limits the options ask for and,
    for a closed-chain scenario, the closed chain (returned; None otherwise)."""
    zero = np.zeros(robot.nj)
    prob.add_constraint(JointBoundary("start", q=scenario.theta0, qd=zero, qdd=zero))
    prob.add_constraint(JointBoundary("end", q=scenario.thetaf, qd=zero, qdd=zero))
    prob.add_constraint(BaseAttitude(at="end"))
    if o.position_limits:
        prob.add_constraint(JointPositionLimits())
    if o.velocity_limits:
        prob.add_constraint(JointVelocityLimits())
    if not scenario.closed_chain:
        return None
    # at the two pinned end knots the closed chain holds already: leave those rows out (measured:
    # with them IPOPT ended "acceptable" after 60 iterations before the variable scaling, and
    # 20 iterations / 3.0 s vs 26 / 2.8 s now)
    cc = replace(ClosedChain.from_configuration(robot, robot.configuration(scenario.theta0), "A", "B"),
                 skip_pinned=True)
    prob.add_constraint(cc)
    return cc


def _warm_start(robot: RobotModel, scenario: Scenario, o: NLPOptions) -> np.ndarray:
    """Knot configurations of the warm start: the quintic, projected onto the closed chain."""
    if scenario.closed_chain:
        return closed_chain_reference(robot, scenario, o.n_intervals, o.duration)[1]
    s = np.linspace(0.0, 1.0, o.n_intervals + 1)
    s = quintic_time_law(s)[0]
    return scenario.theta0 + s[:, None] * (scenario.thetaf - scenario.theta0)


def _build_spline(robot: RobotModel, scenario: Scenario, o: NLPOptions, warm_start=None):
    """The restoration NLP as an :class:`OptProblem` on the B-spline kernel core: the rest ends fix
    their control points, the closed chain's rows at the pinned ends are left out."""
    prob = OptProblem(robot, o.n_intervals, o.duration, n_sub=o.n_sub, transcription="bspline",
                      compile_kernels=o.compile_kernels)
    cc = _restoration_terms(prob, robot, scenario, o)
    prob.add_cost(Smoothness(o.smoothness))
    Q = _warm_start(robot, scenario, o) if warm_start is None else warm_start
    prob.set_initial(q=Q, t=np.linspace(0.0, o.duration, o.n_intervals + 1))
    return prob, cc


def _solve(prob: OptProblem, o: NLPOptions):
    """Solve the B-spline problem with the options' tolerances; the dense check between knots is
    verify's (run_nlp): the closed chain drifts ∝ h⁴ there by design."""
    return prob.solve({"tol": o.dual_tol, "max_wall_time": o.max_wall_time}, tol=o.tol, max_iter=o.max_iter,
                      guarantees=False)


def _coarse_warm_start(robot: RobotModel, scenario: Scenario, o: NLPOptions):
    """Solve the NLP on ``o.coarse_intervals`` intervals; return (knot configurations of its
    solution on the fine grid, projected onto the closed chain, or None if it failed; the coarse
    Solution)."""
    assert o.coarse_intervals is not None   # the caller checks
    oc = replace(o, n_intervals=o.coarse_intervals, coarse_intervals=None)
    prob, _ = _build_spline(robot, scenario, oc)
    sol = _solve(prob, o)
    if not sol.success:
        return None, sol
    Q = sol.sample(np.linspace(0.0, o.duration, o.n_intervals + 1))["q"]
    Q[0], Q[-1] = scenario.theta0, scenario.thetaf
    if scenario.closed_chain:
        from .core import EBAKinematics

        kin = EBAKinematics(robot)
        for k in range(1, o.n_intervals):
            Q[k] = kin.project_closed_chain(Q[k], scenario.relative, tol=1e-12)
    return Q, sol


def run_nlp(robot: RobotModel, scenario: Scenario, options: NLPOptions | None = None) -> MethodResult:
    """Solve the restoration NLP; ``runtime_s`` is IPOPT's wall time (both solves with
    ``coarse_intervals``), ``info`` holds the NLP construction time (``setup_s``), the CPU time of
    build + solve, the status, the iterations (``iterations`` of the final NLP,
    ``total_iterations``) and :func:`optplan.verify`'s independent figures."""
    o = options or (NLPOptions.end_constrained() if scenario.closed_chain else NLPOptions.free_end())
    t0, c0 = time.perf_counter(), time.process_time()
    coarse = None
    if o.transcription != "knots" and o.coarse_intervals is not None and o.coarse_intervals < o.n_intervals:
        Q, coarse = _coarse_warm_start(robot, scenario, o)
        prob, cc = _build_spline(robot, scenario, o, warm_start=Q)
    else:
        prob, cc = build_nlp(robot, scenario, o)
    t_decl = time.perf_counter() - t0 - (coarse.wall_time if coarse is not None else 0.0)
    if o.transcription != "knots":
        sol = _solve(prob, o)
    else:
        sol = prob.solve(tol=o.tol, max_iter=o.max_iter, ipopt_options={"tol": o.dual_tol})
    cpu = time.process_time() - c0
    t_total = time.perf_counter() - t0
    t = np.linspace(sol.t[0], sol.t[-1], o.sample_density * (len(sol.t) - 1) + 1)
    smp = sol.sample(t)
    seg = hermite_segment(t, smp["q"], smp["qd"])
    seg = type(seg)(seg.t, seg.q, seg.qd, smp["qdd"])  # exact (piecewise-linear) acceleration
    x, y, z, w = sol.base_quat[-1] / np.linalg.norm(sol.base_quat[-1])
    Rf = pin.Quaternion(w, x, y, z).toRotationMatrix()
    rep = verify(robot, sol, closed_chain=cc)
    info = {"options": o.__dict__.copy(), "ipopt_status": sol.status.value, "iterations": sol.iterations,
            "setup_s": float(sol.setup_time + t_decl), "total_s": float(t_total), "cost": sol.cost,
            "transcription": o.transcription, "build_and_solve_cpu_s": float(cpu),
            "coarse": None if coarse is None else {"n_intervals": o.coarse_intervals, "status": coarse.status.value,
                                                   "iterations": coarse.iterations, "ipopt_s": float(coarse.wall_time)},
            "max_constraint_violation": sol.max_constraint_violation,
            "boundary_velocity_max": float(max(np.abs(sol.qd[0]).max(), np.abs(sol.qd[-1]).max())),
            "boundary_acceleration_max": float(max(np.abs(sol.qdd[0]).max(), np.abs(sol.qdd[-1]).max())),
            "verify_final_base_attitude_error_rad": rep.final_base_attitude_error_rad,
            "verify_base_attitude_mismatch_rad": rep.base_attitude_mismatch_rad,
            "verify_max_closed_chain_residual": rep.max_closed_chain_residual,
            "verify_max_velocity_limit_violation": rep.max_velocity_limit_violation,
            "verify_max_position_limit_violation": rep.max_position_limit_violation}
    ipopt_s = float(sol.wall_time + (coarse.wall_time if coarse is not None else 0.0))
    info["total_iterations"] = int(sol.iterations + (coarse.iterations if coarse is not None else 0))
    return MethodResult("nlp", [seg], ipopt_s, np.asarray(Rf), None, bool(sol.success),
                        "" if sol.success else f"IPOPT: {sol.status.value}", info, raw=sol)
