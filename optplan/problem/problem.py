"""`OptProblem`: declare a trajectory NLP for a :class:`RobotModel`, warm-start it, solve it with
IPOPT and get a :class:`Solution` that says honestly how good it is.

    prob = OptProblem(robot, n_intervals=50, duration=10.0)
    prob.add_constraint(JointBoundary("start", q=q0, qd=zeros, qdd=zeros))
    prob.add_constraint(JointBoundary("end", q=q1, qd=zeros, qdd=zeros))
    prob.add_constraint(ClosedChain.from_configuration(robot, q0_full))
    smooth = prob.add_cost(Smoothness("jerk"), weight=1.0)
    prob.set_initial(q=path)          # any (M × nj) array, on any time grid
    sol = prob.solve()                # always a Solution; sol.status is an IpoptStatus
    sol.value(smooth), sol.dual(h), sol.sample(t, h), prob.infeasibilities(sol)

Problem (terms: frozen configurations, each built into :class:`TermData` against a
:class:`BuildContext`) ≠ transcription (:mod:`.transcription`) ≠ solver (the NLP core
:mod:`.nlp`: IPOPT through ``casadi.nlpsol``, exact Hessian by default).
"""
from __future__ import annotations

import logging
import time
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from ..errors import OptionError, check_int, check_real
from ..geometry.spatial import check_pose
from ..geometry.splines import quintic_time_law
from ..model.robot import RobotModel
from ..solver_options import check_solve_arguments
from .boundary import pinned_collisions
from .build import BuildContext, TermData
from .collision_term import CollisionAvoidance
from .evaluate import Infeasibility, TermEvaluator
from .expressions import Parameter
from .guarantees import GuaranteeOptions, enforce_between_knots
from .handles import TermHandle
from .nlp import IpoptStatus, NlpSolver, SolveOutcome, SolverOptions
from .problem_expr import ExpressionAPI, check_weight
from .problem_initial import InitialGuessAPI
from .solution import Solution
from .spline_problem import SplineEvaluator
from .spline_solve import SplineBackend
from .terms import JointBoundary, JointPositionLimits, NumericTrajectory, Term
from .transcription import Transcription

__all__ = ["OptProblem", "TermHandle", "Infeasibility"]
log = logging.getLogger(__name__)


class OptProblem(InitialGuessAPI, ExpressionAPI):
    """A trajectory optimization problem over ``n_intervals`` equal intervals.

    Parameters
    ----------
    robot: the :class:`RobotModel` (fixed or free-floating base).
    n_intervals: N; the trajectory has N+1 knots.
    duration: T [s] (the initial guess when ``free_time``).
    free_time: make T a decision variable within ``duration_bounds`` [s].
    base0: initial base placement of a floating robot (default identity); the CoM stays where it
        is at the start (zero momentum).
    n_sub: RK4 sub-steps per interval for the floating-base attitude (each adds 2 base-twist
        collocation points per interval).
    transcription: ``"bspline"`` — the joint trajectory is a cubic B-spline and every term a
        family of compiled per-point kernels (:mod:`.spline_core`; what expressions need);
        ``"knots"`` — the knot transcription (:mod:`.transcription`: q, q̇, q̈, jerk per knot);
        ``"auto"`` (default) — the B-spline whenever it has kernels for every term and N ≥ 4.
    compile_kernels: the B-spline's kernels from C compiled once per robot and structure
        (True: compile now where missing; "auto": use what an earlier run compiled, queue the
        rest for a background compile; False: symbolic only).
    """

    def __init__(self, robot: RobotModel, n_intervals: int = 50, duration: float = 10.0, *,
                 free_time: bool = False, duration_bounds: tuple[float, float] = (1e-2, 1e4),
                 base0: pin.SE3 | None = None, n_sub: int = 2, transcription: str = "auto",
                 compile_kernels: bool | str = "auto"):
        if not isinstance(robot, RobotModel):
            raise OptionError(f"OptProblem: robot: expected an optplan.RobotModel, got {type(robot).__name__}")
        n_intervals = check_int(n_intervals, "OptProblem: n_intervals (number of intervals)", minimum=1,
                                maximum=100_000)
        duration = check_real(duration, "OptProblem: duration", minimum=0.0, strict_minimum=True, unit="s")
        if not isinstance(duration_bounds, (tuple, list)) or len(duration_bounds) != 2:
            raise OptionError(f"OptProblem: duration_bounds: expected (lower, upper) [s], got {duration_bounds!r}")
        lo = check_real(duration_bounds[0], "OptProblem: duration_bounds[0]", minimum=0.0, strict_minimum=True, unit="s")
        hi = check_real(duration_bounds[1], "OptProblem: duration_bounds[1]", minimum=0.0, strict_minimum=True, unit="s")
        if not 0 < lo < hi:
            raise OptionError(f"OptProblem: duration_bounds: expected 0 < lower < upper [s], got {duration_bounds}")
        if not isinstance(free_time, (bool, np.bool_)):
            raise OptionError(f"OptProblem: free_time: expected True or False, got {free_time!r}")
        self.robot = robot
        self.N = n_intervals
        self.duration = duration
        self.free_time = bool(free_time)
        self.duration_bounds = (lo, hi)
        self.base0 = pin.SE3.Identity() if base0 is None else check_pose(base0, "OptProblem: base0")
        self.n_sub = check_int(n_sub, "OptProblem: n_sub (RK4 sub-steps per interval)", minimum=1, maximum=1000)
        self._handles: list[TermHandle] = []
        self._x0: np.ndarray | None = None
        self._lam_g0: np.ndarray | None = None
        self._lam_x0: np.ndarray | None = None
        self._built: dict[str, Any] | None = None
        if transcription not in ("auto", "bspline", "knots"):
            raise OptionError(f"transcription: expected 'auto', 'bspline' or 'knots', got {transcription!r}")
        if compile_kernels not in (True, False, "auto"):
            raise OptionError(f"compile_kernels: expected True, False or 'auto', got {compile_kernels!r}")
        self.transcription = transcription
        self.compile_kernels = compile_kernels
        self._tp: Transcription | None = None
        self._params: list[Parameter] = []
        self._spline = SplineBackend(self)

    @property
    def tp(self) -> Transcription:
        """The knot transcription (made when first needed)."""
        if self._tp is None:
            self._tp = self._make_transcription()
        return self._tp

    def _make_transcription(self) -> Transcription:
        quat0 = pin.SE3ToXYZQUAT(self.base0)[3:] if self.robot.is_floating else None
        return Transcription(self.robot, self.N, self.duration, self.free_time, base0_quat=quat0,
                             com0=None, n_sub=self.n_sub)

    # ------------------------------------------------------------------ declaration
    def _add(self, term: Term, role: str, name: str | None, weight: float) -> TermHandle:
        if not isinstance(term, Term):
            raise TypeError(f"expected an optplan term (optplan.problem.terms), got {type(term).__name__}")
        if role == "constraint" and term.cost_only:
            raise TypeError(f"{type(term).__name__} is a cost-only term; use add_cost")
        check_weight(weight)
        for k, v in vars(term).items():   # poses given to a term (targets, relative poses) are true poses
            if isinstance(v, pin.SE3):
                check_pose(v, f"{type(term).__name__}.{k}")
        base = name or term.default_name
        names = {h.name for h in self._handles}
        final, i = base, 2
        while final in names:
            if name is not None:
                raise ValueError(f"a term named {name!r} exists already (names: {sorted(names)})")
            final, i = f"{base}_{i}", i + 1
        h = TermHandle(final, term, role, float(weight))
        self._handles.append(h)
        self._changed()
        return h

    def _changed(self) -> None:
        self._built = None
        self._spline.core = None

    def add_cost(self, term: Any, weight: Any = 1.0, name: str | None = None, *,
                 kind: str = "integral") -> TermHandle:
        """Add ``weight · cost(term)`` to the objective; returns a named handle.

        ``term`` may be an expression of the problem's quantities (``prob.qdd``,
        ``prob.frame("a_ee").translation``, parameters): ``kind="integral"`` — ``weight · ∫ e dt``
        (a vector expression: ``∫ ‖e‖² dt``; trapezoidal at the knots), ``kind="end"`` —
        ``weight · e`` at T. ``weight`` may then be a parameter expression."""
        if isinstance(term, Term):
            return self._add(term, "cost", name, weight)
        return self._add_expression("cost", term, name, kind=kind, weight=weight)

    def add_constraint(self, term: Any, name: str | None = None, *, lower: Any = None, upper: Any = None,
                       at: Any = "all") -> TermHandle:
        """Enforce ``lower ≤ residual ≤ upper`` of ``term``; returns a named handle.

        ``term`` may be an expression of the problem's quantities, with ``lower``/``upper``
        (numbers, arrays or parameters; None: unbounded) at ``at``: "all" (every knot),
        "start", "end", "interior" or knot indices."""
        if isinstance(term, Term):
            if lower is not None or upper is not None:
                raise OptionError(f"add_constraint: {type(term).__name__} carries its own bounds; lower/upper are "
                                  "for expressions")
            return self._add(term, "constraint", name, 1.0)
        return self._add_expression("constraint", term, name, lower=lower, upper=upper, at=at)

    def rebuild(self) -> None:
        """Rebuild the NLP at the next solve (after changing a term's settings, e.g. the
        collision pairs a :class:`CollisionAvoidance` activates)."""
        self._changed()

    @property
    def terms(self) -> dict[str, TermHandle]:
        return {h.name: h for h in self._handles}

    # ------------------------------------------------------------------ build & solve
    def _initial_com(self) -> np.ndarray:
        if not self.robot.is_floating:
            return np.zeros(3)
        qs = self._initial_unpacked()["q"][0]
        return pin.centerOfMass(self.robot.model, self.robot.model.createData(),
                                self.robot.configuration(qs, self.base0)).copy()

    def _initial_unpacked(self) -> dict[str, np.ndarray]:
        if self._x0 is None:
            raise ValueError("no initial guess: call set_initial(...) or set_initial_straight_line(...) first")
        return self.tp.unpack(self._x0)

    def _pinned_q(self) -> dict[int, np.ndarray]:
        """Knots whose joints a JointBoundary constraint fixes: ``{k: q [rad]}``."""
        out = {}
        for h in self._handles:
            if h.role == "constraint" and isinstance(h.term, JointBoundary) and h.term.q is not None:
                out[h.term.knot(self.N)] = self.robot.check_joints(h.term.q, "JointBoundary.q")
        return out

    def _fixed_joints(self) -> frozenset[int]:
        """Joint-vector indices that a JointPositionLimits constraint holds fixed (lower == upper)."""
        out: set[int] = set()
        for h in self._handles:
            if h.role == "constraint" and isinstance(h.term, JointPositionLimits):
                lo, hi = h.term.limits(self.robot)
                out |= set(np.flatnonzero(np.asarray(lo) == np.asarray(hi)).tolist())
        return frozenset(out)

    def context(self, role: str = "constraint") -> BuildContext:
        """The :class:`BuildContext` terms are built against (transcription, initial guess,
        pinned knots, fixed joints)."""
        return BuildContext(self.tp, role, self.numeric_trajectory(self._x0) if self._x0 is not None else None,
                            self._pinned_q(), self._fixed_joints())

    def _build(self) -> dict[str, Any]:
        tp = self.tp
        if self.robot.is_floating:
            tp.set_com0(self._initial_com())
        tp.clear_caches()
        ctx = {role: self.context(role) for role in ("constraint", "cost")}
        data: dict[str, TermData] = {}
        for h in self._handles:
            data[h.name] = h.term.build(ctx[h.role])
        aux = [a for h in self._handles for a in data[h.name].aux]
        xall = ca.vertcat(tp.x, *[a.sym for a in aux]) if aux else tp.x
        g: list[Any] = []
        lbg: list[Any] = []  # arrays (TermData's bounds are optional in type, set for every constraint row)
        ubg: list[Any] = []
        G, lo, hi = tp.dynamics_constraints()
        g.append(G)
        lbg.append(lo)
        ubg.append(hi)
        dyn = slice(0, G.shape[0])
        rows: dict[str, slice] = {}
        n = G.shape[0]
        f = 0
        cost_exprs = {}
        var_bounds: dict[str, tuple[Any, ...]] = {}
        for h in self._handles:
            d = data[h.name]
            if h.role == "constraint" and d.var_bounds is not None:
                var_bounds[h.name] = d.var_bounds
            elif h.role == "constraint":
                g.append(d.residual)
                lbg.append(d.lower)
                ubg.append(d.upper)
                rows[h.name] = slice(n, n + d.n_rows)
                n += d.n_rows
            else:
                c = h.weight * d.cost
                cost_exprs[h.name] = c
                f = f + c
        gexpr = ca.vertcat(*g)
        nbase = tp.x.shape[0]
        lbx = np.concatenate([-np.inf * np.ones(nbase)] + [a.lower for a in aux])
        ubx = np.concatenate([np.inf * np.ones(nbase)] + [a.upper for a in aux])
        if self.free_time:
            lbx[tp.T_index], ubx[tp.T_index] = self.duration_bounds
        for idx, lo, hi in var_bounds.values():
            lbx[idx] = np.maximum(lbx[idx], lo)
            ubx[idx] = np.minimum(ubx[idx], hi)
        costs = ca.Function("costs", [xall], [ca.vertcat(*cost_exprs.values()) if cost_exprs else ca.DM.zeros(0)])
        self._dyn_slice, self._con_slices, self._bound_terms = dyn, rows, var_bounds
        self._built = {"f": f, "g": gexpr, "lbg": np.concatenate(lbg), "ubg": np.concatenate(ubg),
                       "lbx": lbx, "ubx": ubx, "cost_names": list(cost_exprs), "costs": costs, "x": xall,
                       "nbase": nbase, "aux_init": np.concatenate([a.init for a in aux]) if aux else np.zeros(0),
                       "ffun": ca.Function("f", [xall], [f]), "gfun": ca.Function("g", [xall], [gexpr]),
                       "solver": None, "solver_opts": None, "data": data, "rows": rows, "var_bounds": var_bounds,
                       "dyn": dyn}
        return self._built

    def term_data(self, handle: TermHandle | str) -> TermData:
        """The built :class:`TermData` of a term (rows, bounds, auxiliary variables, ``info`` such
        as a collision term's active pairs); builds the NLP if needed."""
        h = self._handle(handle)
        if self._built is None and isinstance(h.term, CollisionAvoidance) and self._mode() == "bspline":
            return self._spline.term_data(h)   # the B-spline build's collision model (pairs, margins)
        b = self._built or self._build()
        return b["data"][h.name]

    def _handle(self, handle: TermHandle | str) -> TermHandle:
        name = handle if isinstance(handle, str) else getattr(handle, "name", None)
        if name not in self.terms:
            raise KeyError(f"no term named {name!r} in this problem (terms: {sorted(self.terms)})")
        return self.terms[name]

    def replace_term(self, handle: TermHandle | str, term: Term) -> TermHandle:
        """Swap the term behind a handle (same name, role and weight) for ``term`` — e.g. a
        collision term with more activated pairs; the NLP is rebuilt at the next solve."""
        old = self._handle(handle)
        if not isinstance(term, Term):
            raise TypeError(f"expected an optplan term (optplan.problem.terms), got {type(term).__name__}")
        new = TermHandle(old.name, term, old.role, old.weight)
        self._handles[self._handles.index(old)] = new
        self._changed()
        return new

    def _reference_x(self) -> np.ndarray:
        """Decision vector of the rest-to-rest quintic between the initial guess's end knots
        (auxiliary variables and base states as in the initial guess), for objective scaling."""
        assert self._x0 is not None  # narrowing only: solve() checked it
        u: dict[str, Any] = self.tp.unpack(self._x0)  # "T" is a float
        T = u.get("T", self.duration)
        s = np.linspace(0.0, 1.0, self.N + 1)[:, None]
        dq = u["q"][-1] - u["q"][0]
        p, dp, ddp = quintic_time_law(s)
        Q, V, A = u["q"][0] + p * dq, dp * dq / T, ddp * dq / T**2
        J = np.diff(A, axis=0) / (T / self.N)
        xb = self.tp.pack(Q, V, A, J, T=T, base_quat=u.get("base_quat"), base_twist=u.get("base_twist"))
        return np.concatenate([xb, self._full_x0()[xb.size:]])

    def _full_x0(self) -> np.ndarray:
        b = self._built
        assert self._x0 is not None and b is not None  # narrowing only: solve() checked and built them
        if self._x0.size == b["x"].shape[0]:
            return self._x0
        return np.concatenate([self._x0[:b["nbase"]], b["aux_init"]])

    def solve(self, ipopt_options: dict[str, Any] | None = None, *, tol: float = 1e-6, max_iter: int = 500,
              exact_hessian: bool = True, objective_scaling: float | str = "auto",
              options: SolverOptions | None = None, guarantees: GuaranteeOptions | bool | None = None) -> Solution:
        """Solve with IPOPT, then check the solution densely between knots and refine it
        (:mod:`optplan.problem.guarantees`; ``guarantees``: a :class:`GuaranteeOptions`, or False
        for no check). Never raises for a failed solve: the status is in the Solution; ``success``
        is never True with a constraint violated between knots (the grid, ``self.N``, may grow).
        The other arguments: :meth:`solve_knots`."""
        g = GuaranteeOptions.coerce(guarantees)
        args = dict(tol=tol, max_iter=max_iter, exact_hessian=exact_hessian, objective_scaling=objective_scaling,
                    options=options)
        sol = self.solve_knots(ipopt_options, **args)  # type: ignore[arg-type]
        return enforce_between_knots(self, sol, lambda: self.solve_knots(ipopt_options, **args), g)  # type: ignore[arg-type]

    def solve_knots(self, ipopt_options: dict[str, Any] | None = None, *, tol: float = 1e-6, max_iter: int = 500,
                    exact_hessian: bool = True, objective_scaling: float | str = "auto",
                    options: SolverOptions | None = None) -> Solution:
        """Solve with IPOPT, constraints at the knots only (no dense check). Never raises for a
        failed solve: the status is in the Solution.

        ``tol`` is both IPOPT's ``tol``/``constr_viol_tol`` and the constraint-violation bound that
        ``Solution.success`` requires. Defaults depend on the problem's structure
        (see docs/decisions/0010-knot-transcription-defaults.md):

        * inequality-heavy problems (collision planes, more inequality than equality rows):
          ``mu_strategy = adaptive`` and, with ``objective_scaling = "auto"``, the objective scaled
          to 1 on a reference trajectory (the rest-to-rest quintic between the initial guess's end
          configurations; smoothness costs scale like T⁻⁵ and are ~1e-5);
        * equality-dominated problems (e.g. attitude restoration): IPOPT's defaults (monotone μ,
          unscaled objective).

        Exact Hessian, MUMPS (QAMD ordering for floating-base robots). ``ipopt_options`` are passed through and override everything (e.g.
        ``{"print_level": 5}``, ``{"mu_strategy": "adaptive"}``). ``options``: a
        :class:`~optplan.problem.nlp.SolverOptions`; its ``tol``/``max_iter``, when set, replace
        the arguments of the same name, its other fields and ``raw`` override the defaults.
        """
        if options is not None and not isinstance(options, SolverOptions):
            raise OptionError(f"solve: options: expected a SolverOptions, got {type(options).__name__} {options!r}")
        if options is not None:
            tol = options.tol if options.tol is not None else tol
            max_iter = options.max_iter if options.max_iter is not None else max_iter
        check_solve_arguments(tol, max_iter, objective_scaling)
        # an invalid option is an OptionError (ValueError) before the (possibly long) build
        sopts = SolverOptions.coerce(options if options is not None else ipopt_options)
        if options is not None and ipopt_options:
            sopts = sopts.replace(raw={**dict(ipopt_options), **dict(sopts.raw)})
        if self._mode() == "bspline":
            # exact Hessian from the kernels; the objective is scaled to 1 at the first guess
            return self._spline.solve(tol, max_iter, sopts, self.compile_kernels)
        if self._x0 is None:
            raise ValueError("no initial guess: call set_initial(...) or set_initial_straight_line(...) first")
        t_setup = time.perf_counter()
        b = self._built or self._build()
        clash = pinned_collisions(self, b, self.BOUNDARY_PENETRATION_TOL)
        if clash:
            log.warning("OptProblem.solve: %s", clash)
            out0 = SolveOutcome(IpoptStatus.BOUNDARY_IN_COLLISION, -1, 0.0, setup_time=time.perf_counter() - t_setup,
                                x=self._full_x0(), message=clash)
            return self._make_solution(out0, tol)
        n_ineq = int(np.sum(b["lbg"] != b["ubg"]))
        inequality_heavy = n_ineq > 0.5 * (b["lbg"].size - n_ineq)
        if objective_scaling == "auto":
            if inequality_heavy:
                f0 = abs(float(b["ffun"](self._reference_x())))
                scale = float(np.clip(1.0 / f0, 1e-6, 1e8)) if np.isfinite(f0) and f0 > 0 else 1.0
            else:
                scale = 1.0
        else:
            scale = float(objective_scaling)
        # quantise the scale so that small changes of the warm start reuse the same solver
        scale = float(10.0 ** (np.round(np.log10(scale) * 2) / 2)) if scale > 0 else 1.0
        opts = {"expand": True, "ipopt.print_level": 0, "print_time": False, "ipopt.tol": tol,
                "ipopt.constr_viol_tol": tol, "ipopt.acceptable_constr_viol_tol": tol,
                "ipopt.mu_strategy": "adaptive" if inequality_heavy else "monotone",
                "ipopt.obj_scaling_factor": scale,
                "ipopt.max_iter": int(max_iter), "ipopt.sb": "yes"}
        if inequality_heavy:
            # A closed chain at knots a JointBoundary pins repeats those rows: the constraint Jacobian
            # is rank-deficient, MUMPS reports the KKT matrix singular and IPOPT regularises it with
            # δ_c = value·μ^¼ for the rest of the solve. With IPOPT's 1e-8 the scaled transport NLP
            # then creeps at μ_min (N = 25: 182 iterations, past 500 on other IPOPT/MUMPS builds);
            # with 1e-6: 15 (N = 50: 16 vs 15), identical on IPOPT 3.14.11 and 3.14.19. Unused when
            # the Jacobian has full rank; not for equality-dominated problems (closed-chain test
            # NLP: 71 → 500 iterations). docs/reliability.md
            opts["ipopt.jacobian_regularization_value"] = 1e-6
        if self.robot.is_floating:
            # MUMPS's automatic ordering (PORD here) on the floating-base transcription: 47
            # iterations, 12.5 s; QAMD: 26 iterations, 2.6 s (restoration N = 48, measured)
            opts["ipopt.mumps_pivot_order"] = 6
        if not exact_hessian:
            opts["ipopt.hessian_approximation"] = "limited-memory"
        if self._lam_g0 is not None and self._lam_g0.size == b["lbg"].size:
            # primal-dual warm start from a previous Solution (IPOPT ignores multipliers otherwise)
            opts.update({"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6,
                         "ipopt.warm_start_bound_push": 1e-9, "ipopt.warm_start_mult_bound_push": 1e-9,
                         "ipopt.warm_start_slack_bound_push": 1e-9})
        final = sopts.casadi_options(defaults=opts)
        key = repr(sorted(final.items()))
        setup = time.perf_counter() - t_setup   # the NlpSolver adds its own creation time
        if b["solver"] is None or b["solver_opts"] != key:
            b["solver"] = NlpSolver("optplan", {"x": b["x"], "f": b["f"], "g": b["g"]}, sopts, defaults=opts)
            b["solver_opts"] = key
        args = dict(lbg=b["lbg"], ubg=b["ubg"], lbx=b["lbx"], ubx=b["ubx"])
        if self._lam_g0 is not None and self._lam_g0.size == b["lbg"].size:
            args["lam_g0"] = self._lam_g0
            if self._lam_x0 is not None and self._lam_x0.size == b["lbx"].size:
                args["lam_x0"] = self._lam_x0
        out = b["solver"].solve(self._full_x0(), extra_setup=setup, **args)
        return self._make_solution(out, tol)

    #: penetration [m] beyond which a pinned boundary configuration counts as in collision
    BOUNDARY_PENETRATION_TOL = 1e-4
    #: B-spline: a ``JointBoundary`` that gives q [rad], q̇ [rad/s] and q̈ [rad/s²] at an end fixes
    #: that end's three control points by equal bounds instead of rows (False: rows, with multipliers)
    fix_boundary_points = True
    #: B-spline: the first solve of a structure also makes the IPOPT instance a warm-started
    #: re-solve (after ``set_initial(solution=...)``) takes, so that re-solve creates nothing; its
    #: ~1 ms is the build's. False for problems solved once (the pipeline's segments) [bool]
    prepare_warm_start = True

    def _make_solution(self, out: SolveOutcome, tol: float) -> Solution:
        b, tp = self._built, self.tp
        assert b is not None  # narrowing only: solve() built it
        x = np.array(out.x, float)
        gval = np.array(b["gfun"](x)).ravel()
        viol_vec = np.maximum(np.maximum(b["lbg"] - gval, gval - b["ubg"]), 0.0)
        viol = float(viol_vec.max()) if viol_vec.size else 0.0
        if not np.isfinite(viol):
            viol = float("inf")
        terms = {}
        cvals = np.array(b["costs"](x)).ravel()
        for name, v in zip(b["cost_names"], cvals):
            terms[name] = float(v)
        sl = self._dyn_slice
        terms["dynamics"] = float(viol_vec[sl].max()) if sl.stop > sl.start else 0.0
        for name, sl in self._con_slices.items():
            terms[name] = float(viol_vec[sl].max()) if sl.stop > sl.start else 0.0
        for name, (idx, lo, hi) in self._bound_terms.items():
            xv = x[idx]
            sc = b["data"][name].var_scale  # back to physical units
            terms[name] = float(np.max(np.maximum(np.maximum(lo - xv, xv - hi), 0.0))) / sc
            viol = max(viol, terms[name])
        u = tp.unpack(x)
        T = u.get("T", self.duration)
        t = np.linspace(0.0, T, self.N + 1)
        base_quat = base_pos = None
        if tp.floating:
            base_quat = u["base_quat"]
            traj = self.numeric_trajectory(x)
            base_pos = np.array([traj.q_full(k)[:3] for k in range(self.N + 1)])
        status = out.status
        success = status.succeeded and viol <= max(tol, 1e-9) * 10
        return Solution(success=bool(success), status=status, iterations=out.iterations, wall_time=out.wall_time,
                        cost=out.cost, max_constraint_violation=viol, terms=terms, t=t, q=u["q"], qd=u["qd"],
                        qdd=u["qdd"], jerk=u["jerk"], joint_names=self.robot.joint_names, base_quat=base_quat,
                        base_position=base_pos, x=x, lam_g=out.lam_g, lam_x=out.lam_x, x_scale_h=tp.h0,
                        setup_time=out.setup_time, cpu_time=out.cpu_time, attempts=(out,),
                        evaluator=TermEvaluator(self, b))

    # ------------------------------------------------------------------ evaluation helpers
    def numeric_trajectory(self, x: ArrayLike) -> NumericTrajectory:
        """Knot values of a decision vector, for numeric (Pinocchio) term evaluation."""
        u: dict[str, Any] = self.tp.unpack(np.asarray(x, float))  # "T" is a float
        return NumericTrajectory(self.robot, u["q"], u["qd"], u["qdd"], u["jerk"], u.get("T", self.duration),
                                 u.get("base_quat"), self.tp.com0 if self.robot.is_floating else None,
                                 pinned_q=self._pinned_q())

    def term_function(self, handle: TermHandle | str) -> ca.Function:
        """``f(x) -> residual`` (constraint terms; a bound term's bounded variables in physical
        units) or ``f(x) -> weighted cost`` as a ``casadi.Function`` of the full decision vector."""
        h = self._handle(handle)
        b = self._built or self._build()
        d = b["data"][h.name]
        if h.role == "constraint" and d.var_bounds is not None:
            r = b["x"][d.var_bounds[0].tolist()] / d.var_scale
        elif h.role == "constraint":
            r = b["g"][b["rows"][h.name]]
        else:
            r = h.weight * d.cost
        return ca.Function(h.name, [b["x"]], [r])

    def infeasibilities(self, sol: Solution, n: int = 10) -> list[Infeasibility]:
        """The ``n`` worst constraint rows of a solution of this problem, worst first: term name,
        row, point (knot ``k`` or ``(k, fraction)``; None when the rows are not per point),
        value, bounds and violation (≥ 0, physical units). The transcription's own rows are
        listed as ``"dynamics"``."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f"infeasibilities: n: expected an integer ≥ 0, got {n!r}")
        ev = sol.evaluator
        if isinstance(ev, SplineEvaluator) and ev.problem is self:
            return ev.infeasibilities(sol, int(n))
        if not isinstance(ev, TermEvaluator) or ev.problem is not self:
            raise ValueError("infeasibilities: the solution was not produced by this problem (or was loaded from "
                             "a file); solve this problem and pass its solution")
        return ev.infeasibilities(sol, int(n))

    @property
    def initial_guess(self) -> np.ndarray | None:
        """The initial decision vector: a previous solution's of this problem (B-spline) as it
        is, else the knot transcription's packed guess (None before ``set_initial``)."""
        if self._spline.x0 is not None:
            return np.array(self._spline.x0, float)
        return None if self._x0 is None else self._x0.copy()
