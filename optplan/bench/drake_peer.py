"""Drake's ``KinematicTrajectoryOptimization`` as a peer of optplan's trajectory optimizer, on the
same problem: same robot (our URDF), same collision geometry (the robot's capsules, the scene's
obstacles, the held object), same collision pairs, same start/goal, duration, margin and warm start.

Formulation (optional extra ``drake``; ``pip install "optplan[drake]"``):

* the joint trajectory is a clamped cubic B-spline (order 4) whose uniform breakpoints are the
  optimizer's knots: ``N`` intervals ↔ ``N + 3`` control points, duration fixed to ``T`` [s];
* rest at both ends: position, path velocity and path acceleration fixed at ``s = 0`` and ``s = 1``;
* joint position and velocity limits on the control points (they then hold *between* the
  breakpoints as well, a property of B-splines);
* closed chain: :class:`ClosedChainResidual`, the 6-row residual of optplan's
  :class:`~optplan.problem.ClosedChain` (relative-position error and ``vee(E − Eᵀ)/2`` of the
  relative-rotation error ``E``) plus ``trace(E) ≥ 1``, written by hand with Drake's kinematics
  and exact Jacobians, imposed at the sampled times;
* collision: Drake's ``MinimumDistanceLowerBoundConstraint(bound = margin)`` at the sampled times,
  with SceneGraph's collision filter set so that exactly optplan's pairs are candidates
  (:class:`DrakeModel` checks this);
* cost: the integral of the squared jerk ``∫‖d³q/dt³‖² dt``, exact for the piecewise-constant third
  derivative of the cubic B-spline, written by hand (Drake has no jerk cost), scaled like optplan's
  objective (1 on the rest-to-rest quintic between the end configurations) unless told otherwise.

Solvers: SNOPT (bundled in the pip wheel) or IPOPT (Drake supplies gradients only, so IPOPT runs
with a limited-memory Hessian). :func:`solve_drake` returns a :class:`DrakeResult` with the solver,
its status, the times and iterations, and a :class:`BsplineSolution` — the adapter that
:func:`optplan.verify` checks like any optplan solution.
"""
from __future__ import annotations

import logging
import os
import re
import tempfile
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["DrakeUnavailable", "require_drake", "DrakeModel", "ClosedChainResidual", "BsplineSolution", "DrakeOptions",
           "DrakeResult", "fit_bspline", "jerk_matrix", "solve_drake", "SOLVERS"]
from .drake_model import ClosedChainResidual, DrakeModel, DrakeUnavailable, require_drake  # noqa: F401

log = logging.getLogger(__name__)

SOLVERS = ("snopt", "ipopt")


def _basis(n_intervals: int, duration: float = 1.0):
    from pydrake.math import BsplineBasis

    order = 4
    inner = np.linspace(0.0, duration, n_intervals + 1)
    knots = np.r_[np.zeros(order - 1), inner, np.full(order - 1, duration)]
    return BsplineBasis(order, knots.tolist())


def fit_bspline(q_knots: np.ndarray, duration: float):
    """Control points (nq × (N+3)) of the clamped cubic B-spline on N uniform intervals over
    ``duration`` [s] that interpolates ``q_knots`` ((N+1) × nq, at the breakpoints) with zero
    velocity at both ends (the clamped cubic spline through the knots)."""
    Q = np.asarray(q_knots, float)
    N = Q.shape[0] - 1
    basis = _basis(N, duration)
    n = N + 3
    ts = np.linspace(0.0, duration, N + 1)
    A = np.zeros((n, n))
    for k, t in enumerate(ts):
        for i in range(n):
            A[k, i] = basis.EvaluateBasisFunctionI(i, min(t, duration))
    # zero end velocity of a clamped cubic: P1 = P0, P_{n-2} = P_{n-1}
    A[N + 1, 0], A[N + 1, 1] = 1.0, -1.0
    A[N + 2, n - 2], A[N + 2, n - 1] = 1.0, -1.0
    rhs = np.vstack([Q, np.zeros((2, Q.shape[1]))])
    return np.linalg.solve(A, rhs).T


def jerk_matrix(n_intervals: int) -> np.ndarray:
    """``M`` (N × (N+3)): the third derivative d³q/ds³ on interval k of a cubic B-spline over
    s ∈ [0, 1] with uniform breakpoints is ``M[k] @ control_points`` (per joint; constant on the
    interval)."""
    from pydrake.trajectories import BsplineTrajectory

    N = int(n_intervals)
    basis = _basis(N)
    mids = (np.arange(N) + 0.5) / N
    M = np.zeros((N, N + 3))
    for i in range(N + 3):
        cp = [np.array([[1.0 if j == i else 0.0]]) for j in range(N + 3)]
        d3 = BsplineTrajectory(basis, cp).MakeDerivative(3)
        M[:, i] = [float(d3.value(s)[0, 0]) for s in mids]
    return M


def _quintic_reference_jerk(q0, q1, T: float) -> float:
    """∫‖d³q/dt³‖² dt of the rest-to-rest quintic from q0 to q1 over T [s] (= 720 ‖Δq‖² / T⁵)."""
    dq = np.asarray(q1, float) - np.asarray(q0, float)
    return float(720.0 * dq @ dq / T**5)


@dataclass
class BsplineSolution:
    """A Drake B-spline joint trajectory in the form :func:`optplan.verify` takes: ``t``
    (the N+1 breakpoints [s]; ``verify`` samples density × N intervals), ``sample(t)`` →
    ``{"t", "q", "qd", "qdd"}`` in optplan's joint order, evaluated from the B-spline itself."""

    trajectory: Any             # pydrake BsplineTrajectory (Drake joint order), time in [0, T] s
    dm: DrakeModel
    n_intervals: int
    joint_names: tuple = ()
    _derivs: list = field(default_factory=list, repr=False)

    @property
    def t(self) -> np.ndarray:
        return np.linspace(self.trajectory.start_time(), self.trajectory.end_time(), self.n_intervals + 1)

    @property
    def duration(self) -> float:
        return float(self.trajectory.end_time() - self.trajectory.start_time())

    def _d(self, k: int):
        if not self._derivs:
            self._derivs = [self.trajectory] + [self.trajectory.MakeDerivative(i) for i in (1, 2, 3)]
        return self._derivs[k]

    def sample(self, t) -> dict[str, np.ndarray]:
        t = np.atleast_1d(np.asarray(t, float))
        t0, t1 = self.trajectory.start_time(), self.trajectory.end_time()
        if np.any(t < t0 - 1e-12) or np.any(t > t1 + 1e-12):
            raise ValueError(f"sample: times must be in [{t0}, {t1}] s, got [{t.min()}, {t.max()}]")
        t = np.clip(t, t0, t1)
        out = {"t": t}
        for k, key in enumerate(("q", "qd", "qdd")):
            vals = np.array([self._d(k).value(ti).ravel() for ti in t])
            out[key] = self.dm.from_drake(vals)
        return out

    def jerk_cost(self) -> float:
        """∫‖d³q/dt³‖² dt [rad²/s⁵], exact (the jerk is constant on each interval)."""
        ts = self.t
        mids = 0.5 * (ts[:-1] + ts[1:])
        j = np.array([self._d(3).value(ti).ravel() for ti in mids])
        return float(np.sum(np.diff(ts)[:, None] * j**2))


# --------------------------------------------------------------------------- solve
@dataclass(frozen=True)
class DrakeOptions:
    """Options of :func:`solve_drake`."""

    #: ``"snopt"`` or ``"ipopt"``.
    solver: str = "snopt"
    #: Closed-chain and minimum-distance constraints at this many equally spaced times per interval [count] (1:
    #: at the breakpoints).
    samples_per_interval: int = 1
    #: MinimumDistanceLowerBoundConstraint's influence-distance offset above the margin [m].
    influence_distance: float = 0.01
    #: Feasibility / optimality tolerance (SNOPT major feasibility and optimality, IPOPT ``tol`` and
    #: ``constr_viol_tol``) [-].
    tol: float = 1e-6
    #: SNOPT major / IPOPT iterations, at most [count].
    max_iterations: int = 3000
    #: SNOPT's total minor-iteration limit ("Iterations limit") [count]; 250,000 was too few for the larger
    #: problems (docs/drake_peer.md).
    max_minor_iterations: int = 10_000_000
    #: SNOPT's time limit and IPOPT's ``max_cpu_time``, and a deadline checked at every evaluation [CPU s] (the
    #: solve then ends with a status saying so).
    time_limit: float = 600.0
    #: ``"auto"`` (the jerk cost divided by that of the rest-to-rest quintic between the end configurations, as
    #: optplan scales its objective) or a number [-].
    objective_scaling: float | str = "auto"
    #: Add the closed chain's ``trace(E) ≥ 1`` row.
    trace_row: bool = True

    def __post_init__(self):
        if self.solver not in SOLVERS:
            raise ValueError(f"DrakeOptions.solver: expected one of {', '.join(SOLVERS)}, got {self.solver!r}")
        if int(self.samples_per_interval) < 1:
            raise ValueError(f"DrakeOptions.samples_per_interval: expected ≥ 1, got {self.samples_per_interval}")
        if not (self.time_limit > 0 and self.tol > 0 and self.max_iterations >= 1):
            raise ValueError(f"DrakeOptions: time_limit, tol > 0 and max_iterations ≥ 1 required, got {self}")


@dataclass
class DrakeResult:
    """What :func:`solve_drake` returns. ``success``: Drake's ``MathematicalProgramResult.is_success``
    (the solver's own verdict). ``status``: the solver's status text (SNOPT info code / IPOPT
    status). ``setup_time`` [s]: building the plant, the program and the constraints;
    ``solve_time`` [s]: the solver call. ``iterations``: SNOPT major iterations / IPOPT
    iterations (-1 when unknown). ``solution``: a :class:`BsplineSolution`."""

    solver: str
    success: bool
    status: str
    setup_time: float
    solve_time: float
    iterations: int
    cost: float
    solution: BsplineSolution | None
    n_variables: int = 0
    n_constraints: int = 0
    info: dict = field(default_factory=dict)


_SNOPT_INFO = {1: "optimality conditions satisfied", 2: "feasible point found", 3: "requested accuracy could not be achieved",
               11: "infeasible linear constraints", 12: "infeasible linear equalities", 13: "nonlinear infeasibilities minimized",
               14: "infeasibilities minimized", 31: "iteration limit reached", 32: "major iteration limit reached",
               33: "the superbasics limit is too small", 34: "time limit reached", 41: "current point cannot be improved",
               42: "singular basis", 43: "cannot satisfy the general constraints", 44: "ill-conditioned null-space basis",
               91: "invalid input argument"}


def _iterations_from(path: str, solver: str) -> int:
    """Iterations from the solver's log: the final summary, else the last iteration line (a solve
    stopped at the deadline has no summary)."""
    try:
        text = open(path, errors="replace").read()
    except OSError:
        return -1
    pat = r"No\. of major iterations\s+(\d+)" if solver == "snopt" else r"Number of Iterations\.+:\s*(\d+)"
    m = re.findall(pat, text)
    if m:
        return int(m[-1])
    if solver == "snopt":  # major-iteration lines: "   Itns Major Minors ..." rows of integers
        rows = re.findall(r"^\s*\d+\s+(\d+)\s+\d+\s", text, flags=re.M)
    else:                  # IPOPT iteration lines: "iter objective inf_pr ..."
        rows = re.findall(r"^\s*(\d+)r?\s+[-+]?\d\.\d+e[-+]\d+", text, flags=re.M)
    return int(rows[-1]) if rows else -1


class _Deadline:
    """A visualization callback (called at every evaluation) that keeps the last point and raises
    once ``limit`` CPU seconds have passed since :meth:`start`."""

    MARK = "optplan: CPU time limit reached"

    def __init__(self, limit: float):
        self.limit = float(limit)
        self.t0: float | None = None
        self.last: np.ndarray | None = None

    def start(self) -> None:
        self.t0 = time.process_time()

    def __call__(self, x) -> None:
        self.last = np.array(x, float)
        if self.t0 is not None and time.process_time() - self.t0 > self.limit:
            raise RuntimeError(self.MARK)


def solve_drake(dm: DrakeModel, q_knots: np.ndarray, duration: float, *, closed_chain=None, margin: float = 0.02,
                options: DrakeOptions | None = None, collision: bool = True, lower=None, upper=None) -> DrakeResult:
    """Solve the trajectory problem with ``KinematicTrajectoryOptimization`` (module docstring).

    ``q_knots`` ((N+1) × nj, optplan's joint order): the warm start at N uniform intervals over
    ``duration`` [s]; its first and last rows are the boundary configurations (at rest).
    ``closed_chain``: an optplan :class:`~optplan.problem.ClosedChain` (None: no closed chain).
    ``margin`` [m]: lower bound on every candidate pair's signed distance at the sampled times.
    ``lower``, ``upper`` [rad] (optplan's joint order; default the robot's limits): bounds on the
    control points; equal entries fix a joint (the holding arm of a regrasp).
    Never raises for a failed solve: the status is in the result."""
    pd = require_drake()
    from pydrake.planning import KinematicTrajectoryOptimization
    from pydrake.trajectories import BsplineTrajectory

    opts = options or DrakeOptions()
    t0 = time.perf_counter()
    Q = dm.to_drake(np.asarray(q_knots, float))
    if Q.ndim != 2 or Q.shape[1] != dm.plant.num_positions() or Q.shape[0] < 2:
        raise ValueError(f"q_knots: expected (N+1 ≥ 2, {dm.plant.num_positions()}), got shape {Q.shape}")
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"duration: expected a positive time [s], got {duration}")
    N, nq, T = Q.shape[0] - 1, Q.shape[1], float(duration)
    kto = KinematicTrajectoryOptimization(nq, N + 3, 4, T)
    prog = kto.get_mutable_prog()
    P = fit_bspline(Q, T)
    kto.SetInitialGuess(BsplineTrajectory(_basis(N, T), [P[:, [i]] for i in range(N + 3)]))
    kto.AddDurationConstraint(T, T)
    z = np.zeros(nq)
    for s, q in ((0.0, Q[0]), (1.0, Q[-1])):
        kto.AddPathPositionConstraint(q, q, s)
        kto.AddPathVelocityConstraint(z, z, s)
        kto.AddPathAccelerationConstraint(z, z, s)
    lo = dm.lower if lower is None else dm.to_drake(dm.robot.check_joints(lower, "lower"))
    hi = dm.upper if upper is None else dm.to_drake(dm.robot.check_joints(upper, "upper"))
    kto.AddPositionBounds(lo, hi)
    kto.AddVelocityBounds(-dm.velocity_limit, dm.velocity_limit)
    # sampled path constraints (interior samples; the ends are fixed configurations)
    m = int(opts.samples_per_interval)
    svals = [i / (N * m) for i in range(1, N * m)]
    keep = []
    if closed_chain is not None:
        ccr = ClosedChainResidual(dm, closed_chain, trace_row=opts.trace_row)
        ccon = ccr.constraint()
        keep += [ccr, ccon]
        for s in svals:
            kto.AddPathPositionConstraint(ccon, s)
    if collision and dm.n_candidate_pairs:
        from pydrake.multibody.inverse_kinematics import MinimumDistanceLowerBoundConstraint

        mdc = MinimumDistanceLowerBoundConstraint(dm.plant, float(margin), dm.plant_context, None,
                                                  float(opts.influence_distance))
        keep.append(mdc)
        for s in svals:
            kto.AddPathPositionConstraint(mdc, s)
    # exact jerk cost: ∫‖q'''(t)‖² dt = T⁻⁵ Σ_k Δs ‖M_k P_j‖² summed over joints
    M = jerk_matrix(N)
    H1 = (M.T @ M) / N / T**5
    scale = opts.objective_scaling
    if scale == "auto":
        ref = _quintic_reference_jerk(Q[0], Q[-1], T)
        scale = float(np.clip(1.0 / ref, 1e-6, 1e8)) if ref > 0 else 1.0
    scale = float(scale)
    cps = kto.control_points()  # nq × (N+3) decision variables
    for j in range(nq):
        prog.AddQuadraticCost(2.0 * scale * H1, np.zeros(N + 3), cps[j, :], is_convex=True)
    solver_name = opts.solver
    fd, outfile = tempfile.mkstemp(prefix=f"optplan_drake_{solver_name}_", suffix=".out")
    os.close(fd)
    so = pd.SolverOptions()
    if solver_name == "snopt":
        solver = pd.SnoptSolver()
        sid = solver.solver_id()
        for k, v in (("Major feasibility tolerance", opts.tol), ("Major optimality tolerance", opts.tol),
                     ("Major iterations limit", int(opts.max_iterations)), ("Iterations limit", int(opts.max_minor_iterations)),
                     ("Time limit", float(opts.time_limit)), ("Major print level", 1)):
            so.SetOption(sid, k, v)
        so.SetOption(pd.CommonSolverOption.kPrintFileName, outfile)
    else:
        solver = pd.IpoptSolver()
        sid = solver.solver_id()
        for name, value in (("tol", opts.tol), ("constr_viol_tol", opts.tol), ("max_iter", int(opts.max_iterations)),
                            ("max_cpu_time", float(opts.time_limit)), ("print_level", 0), ("output_file", outfile),
                            ("file_print_level", 5)):
            so.SetOption(sid, name, value)
    if not solver.available() or not solver.enabled():
        raise DrakeUnavailable(f"Drake's {solver_name} solver is not available in this build")
    # SNOPT 7.4's own "Time limit" is not enforced on these problems (measured: 330 CPU s past a
    # 150 s limit), so every evaluation checks the CPU deadline and stops the solver with an exception
    watch = _Deadline(float(opts.time_limit))
    prog.AddVisualizationCallback(watch, prog.decision_variables())
    cp_idx = np.array(prog.FindDecisionVariableIndices(cps.reshape(-1))).reshape(cps.shape)
    setup = time.perf_counter() - t0
    t1 = time.perf_counter()
    watch.start()
    res = None
    try:
        res = solver.Solve(prog, prog.GetInitialGuess(prog.decision_variables()), so)
    except RuntimeError as exc:
        if _Deadline.MARK not in str(exc):
            raise
    solve = time.perf_counter() - t1
    iters = _iterations_from(outfile, solver_name)
    try:
        os.remove(outfile)
    except OSError:
        pass
    if res is None:  # stopped at the deadline: the last evaluated point
        status = f"{solver_name.upper()}: stopped at the time limit ({opts.time_limit:g} s CPU)"
        assert watch.last is not None  # the deadline is raised from an evaluation, which kept its point
        Pl = watch.last[cp_idx]
        traj = BsplineTrajectory(_basis(N, T), [Pl[:, [i]] for i in range(N + 3)])
        success, cost = False, float("nan")
    else:
        det = res.get_solver_details()
        if solver_name == "snopt":
            code = int(det.info)
            status = f"SNOPT {code}: {_SNOPT_INFO.get(code, 'see the SNOPT manual')}"
        else:
            status = f"IPOPT: {det.ConvertStatusToString()}"
        traj = kto.ReconstructTrajectory(res)
        success, cost = bool(res.is_success()), float(res.get_optimal_cost()) / scale
    sol = BsplineSolution(traj, dm, N, tuple(dm.robot.joint_names))
    return DrakeResult(solver=solver_name, success=success, status=status, setup_time=setup,
                       solve_time=solve, iterations=iters, cost=cost, solution=sol,
                       n_variables=prog.num_vars(),
                       n_constraints=sum(b.evaluator().num_constraints() for b in prog.GetAllConstraints()),
                       info={"result_code": str(res.get_solution_result()) if res is not None else "deadline",
                             "objective_scale": scale,
                             "n_samples": len(svals), "n_control_points": N + 3})
