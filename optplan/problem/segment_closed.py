"""The closed segment NLP: the pipeline's default until the segment on OptProblem's shared core
(:class:`~optplan.problem.segment.ClosedSegmentProblem`, :func:`optplan.tasks.segment_problem`) is as
fast; measured 1.3-1.4× its CPU time on the warm-start and generalization benchmarks
(docs/decisions/0021-pipeline-on-the-shared-core.md). Same rows as that problem, with the three
boundary control points at each end fixed (not rows) and the interior ones free.

The fast segment NLP: one motion of a fixed-base robot between two rest configurations, as a
joint-space B-spline (:mod:`.bspline`) with the closed chain, joint limits, collision avoidance
and a minimum-jerk cost — built from per-knot kernels that are compiled once and reused.

Transcription
-------------
Decision variables: the interior control points ``P_3 … P_{N−1}`` (the three at each end are fixed
by rest at the pinned boundary configurations) and one offset per separating plane between two
moving bodies. Nothing else: no velocities, accelerations, jerks or integration rows.

* **Joint limits** hold on the control points, hence everywhere in between (convex hull).
* **Velocity limits** hold on the velocity control points ``(P_{i+1} − P_i)/h``: linear rows,
  again valid between the knots. Only the entries the initial guess brings near the limit
  (``velocity_activation``) get a row; :meth:`ClosedSegmentProblem.velocity_violations` checks all
  of them after a solve and :meth:`~ClosedSegmentProblem.add_velocity_rows` adds what was missed
  (each row is one more row of every KKT system IPOPT factorizes).
* **Closed chain** at the interior knots (the same singularity-free pose residual as
  :class:`~optplan.problem.ClosedChain`: 6 equality rows and ``trace ≥ 1`` per knot).
* **Collision avoidance**: each active (pair, knot) gets a separating plane whose unit normal ``n``
  is fixed at coal's witness normal along the initial guess (the fixed-normal planes of
  :class:`~optplan.problem.CollisionAvoidance`). For a static obstacle the plane's offset is
  eliminated exactly: the row is ``min_y n·y − r_B − n·x − r_A ≥ margin`` for each point ``x`` of
  the moving body (capsule end points, box vertices) — the obstacle's support value is a constant
  of the normal. Two moving bodies keep the offset ``b`` as a variable (rows
  ``b − n·x − r_A ≥ m/2``, ``n·y − r_B − b ≥ m/2``). Rows are exact and conservative: the true
  distance is at least the margin wherever a row holds.
* **Cost**: ∫‖j‖² dt (exact; a constant quadratic form of the control points), scaled by the
  rest-to-rest quintic's value so that IPOPT sees an objective of order 1.

Kernels
-------
Every row family is one small SX function of one knot's joint vector (and the plane data), built
once per robot and pair (:class:`KernelCache`) and evaluated over its knots with ``Function.map``;
the NLP graph therefore has a handful of nodes whatever N is, and building the IPOPT instance
costs a fraction of a second instead of the symbolic expansion of the whole trajectory.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from ..model.robot import RobotModel
from ..scene import Scene
from . import kernel_compiler
from .assembly import Assembly
from .bspline import check_knot_guess, fit_interior, jerk_integral_reference, knot_values, rest_to_rest, smooth_knots
from .collision_term import CollisionAvoidance, CollisionModel
from .frame_terms import ClosedChain
from .kernels import KernelCache
from .plane_rows import PlanePlanner
from .segment import SegmentSpec, knots_from_solution
from .solution import Solution
from .terms import NumericTrajectory

__all__ = ["ClosedSegmentProblem"]
log = logging.getLogger(__name__)


def _sparse(A: np.ndarray) -> ca.DM:
    """A constant matrix with its zeros structural (a dense DM would couple every variable)."""
    return ca.sparsify(ca.DM(A))


# --------------------------------------------------------------------------- problem
@dataclass
class _Built:
    solver: SimpleNamespace  # the symbolic structure and its IPOPT instances (KernelCache.structure)
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    p: np.ndarray
    gfun: ca.Function
    slices: dict[str, slice] = field(default_factory=dict)
    setup_time: float = 0.0


class ClosedSegmentProblem:
    """The segment NLP of the module docstring. ``set_initial_path`` / ``set_initial``, then
    ``solve`` → :class:`~optplan.problem.Solution` (knot values of the B-spline, so ``sample`` and
    :func:`optplan.verify.verify` see exactly the optimized trajectory)."""

    def __init__(self, robot: RobotModel, scene: Scene | None, spec: SegmentSpec):
        self.robot, self.scene, self.spec = robot, scene, spec
        self.kernels = KernelCache.of(robot)
        N = self.N = int(spec.n_intervals)
        (self.T, self.h, self.M, self.q0, self.q1, self.P_start, self.P_end, self.lower,
         self.upper) = rest_to_rest(robot, N, spec.duration, spec.q_start, spec.q_end, spec.lower, spec.upper)
        nj = robot.nj
        self.vlim = robot.velocity_limit.copy() if spec.velocity_limit is None else np.broadcast_to(
            np.asarray(spec.velocity_limit, float), (nj,)).copy()
        self.fixed = frozenset(np.flatnonzero(self.lower == self.upper).tolist())
        va = spec.velocity_activation
        if isinstance(va, bool) or not isinstance(va, (int, float, np.integer, np.floating)) or not 0 <= va <= 1:
            raise ValueError(f"velocity_activation: expected a fraction of the limit in [0, 1], got {va!r}")
        self._vel_extra: set[int] = set()  # velocity entries added after a solve (add_velocity_rows)
        self.col: CollisionModel | None = None
        self.planes: PlanePlanner | None = None
        if scene is not None:
            # the term's per-build data (checker, shapes, active pairs): a CollisionModel
            self.col = CollisionAvoidance(scene, margin=spec.margin, activation=spec.activation,
                                          window=spec.window, object_arm=spec.object_arm,
                                          fixed_normals=True).model(robot)
            self.planes = PlanePlanner(robot, self.col, N, self.T, self.q0, self.q1, self.fixed, spec.closed_chain,
                                       window=spec.window, kernels=self.kernels)
        self._X0: np.ndarray | None = None  # interior control points (N−3) × nj
        self._lam: tuple[Any, ...] | None = None
        self._built: _Built | None = None
        self._plan: list[SimpleNamespace] | None = None
        #: use the kernel-assembled Jacobian and Hessian (False: CasADi's own AD of the whole graph)
        self.exact_derivatives = True
        #: kernels evaluated from C compiled once per robot and kept in the disk cache
        #: (:meth:`KernelCache.compiled`): True — compile what is missing (about a second of the
        #: C compiler per kernel, once); "auto" — use what an earlier run compiled, else the
        #: symbolic kernels; False — the symbolic kernels only
        self.compile_kernels: bool | str = "auto"

    @property
    def vertex_window(self) -> float:
        """[m] a moving box keeps the rows of the vertices within this distance of its leading
        vertex along a plane's normal (``inf``: every vertex; :class:`PlanePlanner`)."""
        return 0.5 if self.planes is None else self.planes.vertex_window

    @vertex_window.setter
    def vertex_window(self, value: float) -> None:
        if self.planes is not None:
            self.planes.vertex_window = float(value)

    # ------------------------------------------------------------------ initial guess
    def set_initial(self, q: ArrayLike | None = None, *, solution: Solution | None = None,
                    closed_chain: ClosedChain | None = None) -> None:
        """Initial guess from knot configurations ``q`` ((N+1) × nj, on this problem's grid) or from
        a :class:`Solution` of any grid (sampled at this grid's knots; with ``closed_chain``, each
        interior knot is projected onto it — a coarser grid's solution drifts between its knots).
        Re-seeds the plane normals at the next build."""
        if solution is not None:
            q = knots_from_solution(self.robot, solution, self.N, closed_chain)
        Q = check_knot_guess(q, self.N, self.robot.nj)
        X = fit_interior(Q, self.P_start, self.P_end)
        self._X0 = np.clip(X, self.lower, self.upper)
        self._lam = None
        self._built = None

    def set_initial_path(self, path: ArrayLike, closed_chain: ClosedChain | None = None) -> bool:
        """Initial guess from a planner's path (M × nj, no timing): the path is followed with the
        rest-to-rest quintic time law in joint-space arc length, each knot projected onto the
        closed-chain manifold. Returns whether every projection converged."""
        from ..constraints.closed_chain import project_closed_chain
        from ..geometry.splines import quintic_time_law, resample_path

        path = np.asarray(path, float)
        s, _ = resample_path(path, 2)  # validates the path
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        cum = np.r_[0.0, np.cumsum(seg)]
        tau = np.linspace(0.0, 1.0, self.N + 1)
        sigma = quintic_time_law(tau)[0]
        if cum[-1] > 0:
            target = sigma * cum[-1]
            Q = np.column_stack([np.interp(target, cum, path[:, j]) for j in range(path.shape[1])])
        else:
            Q = np.repeat(path[:1], self.N + 1, axis=0)
        ok = True
        if closed_chain is not None:
            data = self.robot.model.createData()
            for k in range(1, self.N):
                r = project_closed_chain(self.robot, Q[k], closed_chain, data=data)
                Q[k] = r.q
                ok &= r.success
        Q[0], Q[-1] = self.q0, self.q1
        self.set_initial(Q)
        return bool(ok)

    def smooth_initial(self, weight: float = 10.0, closed_chain: ClosedChain | None = None) -> None:
        """Smooth the initial guess: the interior control points minimising
        ``Σ_k ‖q(t_k) − Q_k‖² + weight · Σ_k ‖ΔP³_k‖²`` (knot fit plus a discrete jerk penalty;
        ``weight`` is dimensionless, per unit of squared control-point third difference [rad²]),
        then each knot projected back onto the closed-chain manifold. A planner path's corners
        give the guess a jerk thousands of times the optimum's; rounding them off before IPOPT
        starts saves iterations."""
        from ..constraints.closed_chain import project_closed_chain

        if self._X0 is None:
            raise ValueError("no initial guess to smooth: call set_initial(...) first")
        if not (np.isfinite(weight) and weight >= 0):
            raise ValueError(f"weight: expected a finite number ≥ 0, got {weight!r}")
        N = self.N
        Qs = smooth_knots(self.knot_configurations(), weight)
        if closed_chain is not None:
            data = self.robot.model.createData()
            for k in range(1, N):
                Qs[k] = project_closed_chain(self.robot, Qs[k], closed_chain, data=data).q
        self.set_initial(Qs)

    # ------------------------------------------------------------------ helpers
    def _P(self, X: ArrayLike) -> np.ndarray:
        return np.vstack([self.P_start, np.asarray(X).reshape(self.N - 3, self.robot.nj), self.P_end])

    def knot_configurations(self, X: ArrayLike | None = None) -> np.ndarray:
        """Knot configurations ((N+1) × nj) of interior control points X (default: the guess)."""
        X = self._X0 if X is None else X
        assert X is not None  # callers check that there is a guess
        return self.M["q"] @ self._P(X)

    # ------------------------------------------------------------------ collision rows
    def _plan_collision(self, Qk: np.ndarray) -> list[SimpleNamespace]:
        """Active pairs along the knot configurations ``Qk`` (:meth:`PlanePlanner.plan`)."""
        return [] if self.planes is None else self.planes.plan(Qk)

    # ------------------------------------------------------------------ build
    def _build(self) -> _Built:
        """Numeric data of the NLP (collision plan, plane parameters, row bounds, boundary control
        points, objective weight) for the current initial guess, and its symbolic structure —
        taken from the robot's :class:`KernelCache` when an NLP of the same shape (N, rows, pairs
        and knots) was built before in this process, so that only the numbers change."""
        if self._X0 is None:
            raise ValueError("no initial guess: call set_initial(...) or set_initial_path(...) first")
        t0 = time.perf_counter()
        N, nj, h = self.N, self.robot.nj, self.h
        Qk0 = self.knot_configurations()
        plan, planes = self.planes.rows(Qk0) if self.planes is not None else ([], [])
        sel = self._velocity_entries()
        ccfn = self.kernels.closed_chain(self.spec.closed_chain) if self.spec.closed_chain is not None else None
        nP = (N - 3) * nj
        # numbers: parameters (boundary points, plane normals, static supports, objective weight),
        # row bounds in row order, initial plane offsets
        pvals = [self.P_start.T.ravel(order="F"), self.P_end.T.ravel(order="F")]
        lbg, ubg, x_b0 = [], [], []
        if sel.size:
            vb = np.tile(self.vlim * h, N - 2)[sel]
            lbg.append(-vb)
            ubg.append(vb)
        if ccfn is not None:
            lbg.append(np.tile(np.r_[np.zeros(6), 1.0], N - 1))
            ubg.append(np.tile(np.r_[np.zeros(6), np.inf], N - 1))
        for it, (Nrm, s0) in zip(plan, planes):
            pvals.append(Nrm.ravel(order="F"))
            if it.static:
                pvals.append(np.asarray(s0, float).ravel())
                lbg.append(np.repeat(it.margins, it.nrow))
            else:
                x_b0.append(s0)
                lbg.append(np.repeat(it.margins / 2, it.nrow))
            ubg.append(np.full(len(it.knots) * it.nrow, np.inf))
        fref = jerk_integral_reference(self.q0, self.q1, self.T)
        self._scale = scale = 1.0 / fref if fref > 0 else 1.0
        pvals.append(np.array([scale / h**5]))  # ∫‖j‖² dt = h Σ ‖ΔP³/h³‖², scaled to order 1
        evals = {fn.name(): self.kernels.evaluators(fn, self.compile_kernels)
                 for fn in ([ccfn] if ccfn is not None else []) + [it.fn for it in plan]}
        kernel_compiler.launch()   # kernels evaluated symbolically here: compiled in the background for later NLPs
        key = (N, nj, sel.tobytes(), None if ccfn is None else ccfn.name(), self.exact_derivatives,
               tuple((it.fn.name(), tuple(it.knots), it.static) for it in plan),
               tuple(sorted((name, c) for name, (_, c) in evals.items())))
        st = self.kernels.structure(key, lambda: self._structure(sel, ccfn, plan, evals))
        self._nlp, self._derivs = st.nlp, st.derivs
        self._plan = plan
        nb = st.nb
        lbx = np.r_[np.tile(self.lower, N - 3), np.full(nb, -np.inf)]
        ubx = np.r_[np.tile(self.upper, N - 3), np.full(nb, np.inf)]
        self._xb0 = np.concatenate(x_b0) if x_b0 else np.zeros(0)
        b = _Built(solver=st, lbx=lbx, ubx=ubx, lbg=np.concatenate(lbg) if lbg else np.zeros(0),
                   ubg=np.concatenate(ubg) if ubg else np.zeros(0), p=np.concatenate(pvals),
                   gfun=st.gfun, slices=st.slices)
        if b.lbg.size != st.ng or b.p.size != st.np:
            raise AssertionError(f"segment NLP: {b.lbg.size} row bounds / {b.p.size} parameters for a structure "
                                 f"of {st.ng} rows / {st.np} parameters")
        b.setup_time = time.perf_counter() - t0
        self._built = b
        self._nfree = nP
        return b

    def _structure(self, sel: np.ndarray, ccfn: ca.Function | None, plan: list[SimpleNamespace],
                   evals: dict[str, Any]) -> SimpleNamespace:
        """The symbolic NLP of one shape: decision variables, parameters, rows in the order of
        :meth:`_build`'s bounds, and the exact Jacobian / Hessian functions (:class:`Assembly`)."""
        N, nj = self.N, self.robot.nj
        nP = (N - 3) * nj
        nb = sum(len(it.knots) for it in plan if not it.static)
        x = ca.MX.sym("x", nP + nb)
        Xs = ca.reshape(x[:nP], nj, N - 3)
        Bv = x[nP:]
        Pstart, Pend = ca.MX.sym("P_start", nj, 3), ca.MX.sym("P_end", nj, 3)
        P = ca.horzcat(Pstart, Xs, Pend)  # nj × (N+3)
        Qk = ca.mtimes(P, _sparse(self.M["q"].T))  # nj × (N+1)
        params = [Pstart, Pend]
        asm = Assembly(N, nj, nP + nb)
        if sel.size:  # velocity control points touching a free point (convex hull: q̇ bounded everywhere)
            dP = ca.vec(ca.mtimes(P, _sparse(self.M["dP"].T[:, 2:N])))
            asm.linear("velocity_limits", dP[sel.tolist()], self.M["dP"][2:N], 0.0, 0.0, select=sel)
        fams: list[tuple[str, Any, list[int], Any, Any, tuple[int, np.ndarray] | None]] = []
        if ccfn is not None:
            fams.append(("closed_chain", ccfn, list(range(1, N)), ca.DM.zeros(3, N - 1), ca.DM.zeros(1, N - 1), None))
        bi = 0
        for it in plan:
            K = len(it.knots)
            Np = ca.MX.sym("n", 3, K)
            params.append(Np)
            name = f"collision:{it.pair.name_a}|{it.pair.name_b}"
            if it.static:
                Sp = ca.MX.sym("s", 1, K)
                params.append(Sp)
                fams.append((name, it.fn, it.knots, Np, Sp, None))
            else:
                ma = it.a[1].shape[1]
                sign = np.r_[np.ones(ma), -np.ones(it.nrow - ma)]
                fams.append((name, it.fn, it.knots, Np, Bv[bi:bi + K].T, (nP + bi, sign)))
                bi += K
        for name, fn, knots, Nin, Sin, bcoup in fams:
            (f, jfn, hfn), _ = evals[fn.name()]
            asm.family(name, f, jfn, hfn,
                       knots, Qk[:, knots], Nin, Sin, bcoup, 0.0, 0.0)
        w = ca.MX.sym("w")  # objective weight: scale / h⁵
        params.append(w)
        p = ca.vertcat(*[ca.vec(a) for a in params])
        Jm = self.M["jerk"]
        f = w * ca.sumsqr(ca.mtimes(P, _sparse(Jm.T)))
        Hj = 2 * (Jm[:, 3:N].T @ Jm[:, 3:N])  # per joint, over the free points (times w)
        lam_f = ca.MX.sym("lam_f")
        lam_g = ca.MX.sym("lam_g", asm.ng)
        G, Jg, Hl = asm.finish(x, lam_f * w, lam_g, Hj)
        derivs = {"jac_g": ca.Function("jac_g", [x, p], [G, Jg], ["x", "p"], ["g", "jac_g_x"]),
                  "hess_lag": ca.Function("hess_lag", [x, p, lam_f, lam_g], [Hl],
                                          ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])}
        return SimpleNamespace(nlp={"x": x, "p": p, "f": f, "g": G}, derivs=derivs, gfun=ca.Function("g", [x, p], [G]),
                               slices=asm.slices, points=asm.points, ng=asm.ng, np=p.shape[0], nb=nb, solvers={})

    def rebuild(self) -> None:
        """Rebuild at the next solve (after ``add_activation`` or ``boost_between_knots``)."""
        self._built = None

    # ------------------------------------------------------------------ velocity rows
    def _velocity_cp(self, X: ArrayLike) -> np.ndarray:
        """Velocity control points [rad/s] touching a free point, (N−2) × nj."""
        return self.M["dP"][2:self.N] @ self._P(X) / self.h

    def _fast_entries(self, X: ArrayLike) -> set[int]:
        """Entries ``i·nj + j`` of the velocity control points of ``X`` past ``velocity_activation``
        of their joint's limit (fixed joints excluded)."""
        on = np.abs(self._velocity_cp(X)) >= self.spec.velocity_activation * self.vlim
        on[:, sorted(self.fixed)] = False
        return set(np.flatnonzero(on.ravel()).tolist())

    def _velocity_entries(self) -> np.ndarray:
        """Entries of the velocity control points that get a row: those the initial guess drives
        past ``velocity_activation`` of the limit, plus those added after a solve."""
        assert self._X0 is not None  # _build checks that there is a guess
        return np.array(sorted(self._fast_entries(self._X0) | self._vel_extra), int)

    def activate_velocity(self, solution: Solution) -> int:
        """Add the rows of every velocity entry of ``solution`` past ``velocity_activation`` of its
        limit (the violators among them) for the next solve; returns how many rows are new."""
        if solution.x is None:
            return 0
        new = self._fast_entries(np.asarray(solution.x)[:(self.N - 3) * self.robot.nj]) - self._vel_extra
        new -= set(self._velocity_entries().tolist())
        self.add_velocity_rows(sorted(new))
        return len(new)

    def velocity_violations(self, solution: Solution, tol: float = 1e-9) -> np.ndarray:
        """Entries (``i·nj + j``) of the velocity control points of ``solution`` that have no row
        and exceed the joint speed limit by more than ``tol`` [rad/s] — what the lazy selection
        missed (entries with a row hold to the solver's constraint tolerance). Empty: q̇ is within
        its limits everywhere."""
        if solution.x is None:
            return np.zeros(0, int)
        V = np.abs(self._velocity_cp(np.asarray(solution.x)[:(self.N - 3) * self.robot.nj]))
        over = np.flatnonzero((V - self.vlim > tol).ravel())
        return np.setdiff1d(over, self._velocity_entries())

    def add_velocity_rows(self, entries: ArrayLike) -> None:
        """Constrain these velocity entries (from :meth:`velocity_violations`) at the next solve."""
        n = (self.N - 2) * self.robot.nj
        e = np.asarray(entries, int).ravel()
        if e.size and (e.min() < 0 or e.max() >= n):
            raise ValueError(f"add_velocity_rows: entries must lie in [0, {n}), got {e.min()}..{e.max()}")
        self._vel_extra |= set(e.tolist())
        self._built = None

    def add_activation(self, q_knots: np.ndarray) -> None:
        """Also activate the pairs that come close along ``q_knots`` ((N+1) × nj), e.g. a solution
        that verification found colliding."""
        if self.col is not None:
            Q = np.asarray(q_knots, float)
            self.col.activate_with = list(self.col.activate_with) + [
                NumericTrajectory(self.robot, Q, Q, Q, Q[:-1], self.T)]
        self._built = None

    def boost_between_knots(self, traj_t: ArrayLike, traj_q: ArrayLike, knot_t: ArrayLike) -> int:
        """:meth:`CollisionAvoidance.boost_between_knots` for this problem's collision rows."""
        if self.col is None:
            return 0
        self._built = None
        return self.col.boost_between_knots(np.asarray(traj_t, float), traj_q, knot_t)

    def infeasibilities(self, solution: Solution, n: int = 10) -> list[Any]:
        """The ``n`` worst constraint rows of ``solution`` (a solve of this problem), worst first,
        as :class:`~optplan.problem.evaluate.Infeasibility`: row family (``velocity_limits``,
        ``closed_chain``, ``collision:A|B``), row within it, knot (None for velocity rows),
        value, bounds and violation (≥ 0; rad·h for velocity rows, m and rad otherwise)."""
        from .evaluate import Infeasibility

        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f"infeasibilities: n: expected an integer ≥ 0, got {n!r}")
        b = self._built
        if b is None or solution.x is None or np.asarray(solution.x).size != b.lbx.size:
            raise ValueError("infeasibilities: the solution was not produced by this problem's last build; "
                             "solve this problem and pass its solution")
        g = np.array(b.gfun(np.asarray(solution.x), b.p)).ravel()
        viol = np.maximum(np.maximum(b.lbg - g, g - b.ubg), 0.0)
        out = []
        for i in np.argsort(-viol, kind="stable")[:int(n)]:
            if not viol[i] > 0:
                break
            name, sl = next((k, v) for k, v in b.slices.items() if v.start <= i < v.stop)
            row = int(i - sl.start)
            pts = b.solver.points.get(name)
            point = None if pts is None else int(pts[1][row // pts[0]])
            out.append(Infeasibility(name, row, point, float(g[i]), float(b.lbg[i]), float(b.ubg[i]), float(viol[i])))
        return out

    # ------------------------------------------------------------------ solve
    def solve(self, ipopt_options: dict[str, Any] | None = None, *, tol: float = 1e-6, max_iter: int = 500) -> Solution:
        """Solve with IPOPT (exact Hessian, MUMPS). Never raises for a failed solve: the status is
        in the Solution. ``ipopt_options`` are passed through (``"ipopt."`` prefix optional)."""
        from ..solver_options import check_solve_arguments
        from .nlp import NlpSolver, SolverOptions

        check_solve_arguments(tol, max_iter, 1.0)
        sopts = SolverOptions.coerce(ipopt_options)  # an invalid option is an OptionError before the solve
        b = self._built or self._build()  # its time is charged to this solve's setup_time
        t_setup = time.perf_counter()
        st = b.solver
        # jacobian_regularization_value: IPOPT's constraint regularisation, used only when it
        # finds the Jacobian rank-deficient (docs/optproblem.md: a long segment on 136 intervals
        # went from 339 iterations without convergence to 19 with it)
        defaults = {"ipopt.tol": tol, "ipopt.constr_viol_tol": tol, "ipopt.acceptable_constr_viol_tol": tol,
                    "ipopt.mu_strategy": "adaptive", "ipopt.max_iter": int(max_iter),
                    "ipopt.jacobian_regularization_value": 1e-6,
                    # theta_max_fact: the filter refuses points whose constraint violation exceeds
                    # 10 × max(1, the initial one) (IPOPT's default: 10⁴ ×). A warm start lies near the
                    # manifold; one long segment accepted a step to a closed-chain residual of 3.3 and
                    # never came back (200 iterations; with 10: 50 iterations, verified;
                    # docs/decisions/0015)
                    "ipopt.theta_max_fact": 10.0,
                    # perturb_always_cd: IPOPT's permanent regularisation of the constraint block of
                    # its KKT system (rank-deficient closed-chain rows next to the pinned ends). The
                    # pipeline's default since it was measured on its segments (decision 0002); the
                    # problem's own default too since the transport example (N = 50) went from 32
                    # iterations (20 inertia corrections) to 20 (docs/decisions/0015)
                    "ipopt.perturb_always_cd": "yes"}
        okey = repr(sorted(sopts.casadi_options(defaults).items()))
        setup = time.perf_counter() - t_setup + b.setup_time   # the NlpSolver adds its own creation time
        b.setup_time = 0.0
        solver = st.solvers.get(okey)
        if solver is None:  # one IPOPT instance per shape and options, reused by later solves
            extra = {}
            if self.exact_derivatives:
                # the kernels may be compiled (no derivatives of their own): IPOPT's multipliers
                # are used as they are, not recomputed from a gradient of the Lagrangian
                extra = {**st.derivs, "no_nlp_grad": True, "calc_lam_x": False, "calc_lam_p": False,
                         "calc_f": False, "calc_g": False}
            solver = st.solvers[okey] = NlpSolver("segment", st.nlp, sopts, defaults=defaults, casadi_options=extra)
        assert self._X0 is not None  # _build refuses to run without a guess
        x0 = np.r_[self._X0.ravel(), self._xb0]
        out = solver.solve(x0, p=b.p, lbx=b.lbx, ubx=b.ubx, lbg=b.lbg, ubg=b.ubg, cost_scale=self._scale,
                           extra_setup=setup)
        status, x, lam_g, iters, cost, wall = out.status, np.array(out.x), out.lam_g, out.iterations, out.cost, out.wall_time
        gval = np.array(b.gfun(x, b.p)).ravel()
        viol_vec = np.maximum(np.maximum(b.lbg - gval, gval - b.ubg), 0.0)
        viol = float(viol_vec.max()) if viol_vec.size else 0.0
        xb = np.clip(x[:self._nfree], b.lbx[:self._nfree], b.ubx[:self._nfree])
        viol = max(viol, float(np.abs(xb - x[:self._nfree]).max()) if self._nfree else 0.0)
        terms = {"jerk": cost}
        for name, sl in b.slices.items():
            key = "collision" if name.startswith("collision:") else name
            v = float(viol_vec[sl].max()) if sl.stop > sl.start else 0.0
            terms[key] = max(terms.get(key, 0.0), v)
        P = self._P(x[:self._nfree])
        kv = knot_values(P, self.h)
        success = bool(status.succeeded and np.isfinite(viol) and viol <= max(tol, 1e-9) * 10)
        return Solution(success=success, status=status, iterations=iters, wall_time=wall, cost=cost,
                        max_constraint_violation=viol, terms=terms, t=np.linspace(0.0, self.T, self.N + 1),
                        q=kv["q"], qd=kv["qd"], qdd=kv["qdd"], jerk=kv["jerk"],
                        joint_names=self.robot.joint_names, setup_time=out.setup_time, cpu_time=out.cpu_time, x=x,
                        lam_g=lam_g, attempts=(out,))
