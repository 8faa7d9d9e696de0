"""Build and solve an :class:`~optplan.problem.OptProblem` on the B-spline kernel core: the
numbers of one solve (parameters, bounds, first guess) around the cached structure of
:mod:`.spline_core`; a re-solve after ``set_value`` or ``set_initial(solution=...)`` only changes
numbers."""
from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np
import pinocchio as pin

from ..codegen import call_dense
from .bspline import knot_values
from .build import TermData
from .collision_term import CollisionAvoidance
from .expressions import Parameter
from .floating_collision import base_placements
from .nlp import IpoptStatus, NlpSolver, SolverOptions
from .solution import LazyTerms, Solution
from .spline_core import Family, SplineCore
from .spline_problem import SplineEvaluator, _quintic, families_of, seed_guess
from .spline_rows import VELOCITY_ACTIVATION, RowSelection

__all__ = ["COUNTS", "SplineBackend", "VELOCITY_ACTIVATION"]

#: what solves on the B-spline core computed in this process [count] (what tests read): builds
#: (``prepared``), IPOPT instances created, solutions made, and their ``terms`` evaluated (only
#: when read: :class:`~optplan.problem.solution.LazyTerms`)
COUNTS = {"prepared": 0, "solvers_created": 0, "solutions": 0, "terms_computed": 0}


#: IPOPT's options of a solve started from a previous solution and its multipliers
_WARM_START: dict[str, Any] = {"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6,
                               "ipopt.warm_start_bound_push": 1e-9, "ipopt.warm_start_mult_bound_push": 1e-9,
                               "ipopt.warm_start_slack_bound_push": 1e-9}


def _new_solver(st: dict[str, Any], sopts: SolverOptions, defaults: dict[str, Any]) -> NlpSolver:
    """An IPOPT instance of the structure ``st`` (its derivative Functions) with ``defaults``."""
    COUNTS["solvers_created"] += 1
    extra = {**st["derivs"], "no_nlp_grad": True, "calc_lam_x": False, "calc_lam_p": False,
             "calc_f": False, "calc_g": False}
    return NlpSolver("optproblem_spline", st["nlp"], sopts, defaults=defaults, casadi_options=extra)


class SplineBackend(RowSelection):
    """The B-spline side of one problem: families (rebuilt when the terms change), parameters,
    guess and solve; which rows a solve has is :class:`~.spline_rows.RowSelection`'s."""

    def __init__(self, prob: Any):
        super().__init__()
        self.prob = prob
        self.core: SplineCore | None = None
        self.fams: list[Family] = []
        self.owner: dict[str, list[str]] = {}
        self.pbounds: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.x0: np.ndarray | None = None       # a guess in this core's variables
        self.lam: tuple[Any, Any] | None = None
        self.scale: float | None = None          # the objective scale of the last solve
        self.last_x: np.ndarray | None = None    # the last converged solution (the next solve's start)
        self.aux0, self.col_p = np.zeros(0), np.zeros(0)   # collision plane offsets / normals, supports
        self.collision_model: Any = None
        self.collision_models: dict[str, Any] = {}   # by term name (several on a floating robot)
        self.last_build_time = 0.0
        #: core variables (without collision plane offsets) the next :meth:`prepare` plans the
        #: collision rows along, instead of the first guess (:meth:`replan_collision`)
        self.plan_along: np.ndarray | None = None
        #: a floating robot's margins raised after a solve collided between the knots:
        #: (pair, knot) -> added margin [m], on a grid of ``boost_n`` intervals (:meth:`replan_collision`)
        self.margin_boost: dict[tuple[Any, int], float] = {}
        self.boost_n = 0
        #: re-solves with the velocity rows a solve missed (:meth:`_missed_velocity`) [count]
        self.velocity_retries = 2
        # (key, core variables) of the last guess fitted to the user's knots (:meth:`_guess`)
        self._fitted: tuple[tuple[Any, ...], np.ndarray] | None = None

    # ------------------------------------------------------------------ structure
    def prepare(self) -> None:
        """Families of the problem's terms (raises spline_problem.Unsupported)."""
        prob = self.prob
        t0 = time.perf_counter()
        COUNTS["prepared"] += 1
        self._fitted = None   # the boundary terms may have changed: fit the guess again
        self._constant_memo = {}   # the families (their kernels and bounds) are made again
        params: list[Parameter] = prob._params
        npar = sum(p.size for p in params)
        core = SplineCore(prob.robot, prob.N, prob.free_time, prob.n_sub, npar)
        self.collision_models = {}
        self.fams, self.owner, self.pbounds, cols = families_of(prob, core, params)
        self.core, self.aux0, self.col_p = core, np.zeros(0), np.zeros(0)
        self.fixed = self._fixed_families(core)
        along, self.plan_along = self.plan_along, None
        if along is not None and along.size != core.nx:
            along = None
        x = along if along is not None else \
            self.guess(prob.duration) if cols or (self._velocity_families() and not prob.free_time) else None
        if cols:   # the active pairs follow the first guess: plan them along it
            from .spline_collision import plan_collision

            assert x is not None
            Qk = core.M["q"] @ core.control_points(x)
            lbx, ubx = self._bounds(fixed=False)
            owners: list[str] = []   # the term of each item
            if core.fl:   # planes with the base pose (floating_collision); one plan per term
                from .floating_collision import plan_floating_collision

                boost = self.margin_boost if self.boost_n == core.N else {}
                items: list[Any] = []
                for h in cols:
                    fitems, m = plan_floating_collision(prob, core, h.term, x, prob.base0, self._com0(Qk[0]),
                                                        lbx[:core.nj], ubx[:core.nj], boost)
                    self.collision_models[h.name] = m
                    items += fitems
                    owners += [h.name] * len(fitems)
                self.collision_model = self.collision_models[cols[0].name]
            else:
                items, self.collision_model = plan_collision(prob, core, cols[0].term, Qk, lbx[:core.nj],
                                                             ubx[:core.nj], steady=along is None)
                self.collision_models[cols[0].name] = self.collision_model
                owners = [cols[0].name] * len(items)
            nb = sum(len(it.knots) for it in items if not it.static)
            core = SplineCore(prob.robot, prob.N, prob.free_time, prob.n_sub, npar, n_aux=nb,
                              n_colp=sum(4 * len(it.knots) for it in items))
            po = ao = 0
            colp, aux = [], []
            for h in cols:
                self.owner[h.name] = []
            for it, own in zip(items, owners):
                pair = it.name.removeprefix("collision:")
                if len(cols) > 1:   # family names stay unique when two terms hold the same pair
                    it.name = f"collision:{own}:{pair}"
                self.fams.append(Family(it.name, "pair", it.fn, it.knots,
                                        labels=tuple(f"{pair}.point{i}" for i in range(it.nrow)),
                                        data={"item": it, "p_off": po, "aux_off": ao,
                                              "world": bool(getattr(it, "world", False))}))
                self.owner[own].append(it.name)
                colp += [it.normals.ravel(order="F"), it.offsets if it.static else np.zeros(len(it.knots))]
                if not it.static:
                    aux.append(it.offsets)
                    ao += len(it.knots)
                po += 4 * len(it.knots)
            self.core, self.aux0 = core, np.concatenate(aux) if aux else np.zeros(0)
            self.col_p = np.concatenate(colp) if colp else np.zeros(0)
            if along is not None:   # the next solve starts from the trajectory the rows were planned along
                self.x0 = np.r_[along, self.aux0]
        if x is not None and not core.free_time:
            self._select_velocity(x)
        self.last_build_time = time.perf_counter() - t0

    def replan_collision(self, sol: Any, violations: list[Any]) -> bool:
        """After a solve whose collision rows ``violations`` (:class:`~.guarantees.Violation`,
        component ``"a | b"``) found violated between the knots: plan the rows again along the
        solution ``sol`` of this build, on the same grid — pairs activated where it brings them
        close, planes from coal's witnesses along it — and start the next solve from it. A pair
        that already had rows gets, for a floating robot, its margin raised by the violation at
        the two knots around it (as the segment NLP's margin boost). False (nothing changed) when
        this build has no collision rows, or every violated pair had rows and the robot has a
        fixed base — a finer grid is then what helps."""
        core, m = self.core, self.collision_model
        if core is None or m is None or sol.x is None or np.size(sol.x) != core.nx:
            return False
        models = list(self.collision_models.values()) or [m]   # every term's (several on a floating robot)
        names = {f"{p.name_a} | {p.name_b}": p for mm in models for p in mm.active_pairs}
        missed = {v.component for v in violations} - set(names)
        if not missed:
            if not core.fl:
                return False
            if self.boost_n != core.N:
                self.margin_boost, self.boost_n = {}, core.N
            for v in violations:
                pair = names[v.component]
                for k in (v.interval, v.interval + 1):
                    self.margin_boost[(pair, k)] = self.margin_boost.get((pair, k), 0.0) + float(v.amount)
        self.plan_along = np.array(sol.x[:core.x_aux], float)
        self.core = None
        return True

    def term_data(self, handle: Any) -> TermData:
        """What this build decided for a term (:meth:`OptProblem.term_data`): for a collision
        term its :class:`~optplan.problem.collision_term.CollisionModel` (``info["model"]``:
        checker, active pairs and knots, relaxed margins — what ``with_boost`` reads), else nothing."""
        if self.core is None:
            self.prepare()
        m = self.collision_models.get(handle.name, self.collision_model)
        if not isinstance(handle.term, CollisionAvoidance) or m is None:
            return TermData()
        return TermData(info={"model": m, "active_pairs": tuple(m.active_pairs),
                              "constant_pairs": tuple(m.constant_pairs), "relaxed": dict(m.relaxed),
                              "active_knots": dict(m.active_knots)})

    def _pvec(self, T: float, com0: np.ndarray, scale: float) -> np.ndarray:
        core, prob = self.core, self.prob
        assert core is not None
        N = core.N
        p = np.zeros(core.np)
        p[core.p_s:core.p_s + N + 1] = np.arange(N + 1) / N
        qw = np.ones(N + 1)
        qw[[0, -1]] = 0.5
        p[core.p_qw:core.p_qw + N + 1] = qw
        p[core.p_one] = 1.0
        p[core.p_T] = T
        if core.fl:
            p[core.p_xi0:core.p_xi0 + 4] = [0, 0, 0, 1.0]
            p[core.p_b0:core.p_b0 + 4] = pin.Quaternion(prob.base0.rotation).coeffs()
            p[core.p_c0:core.p_c0 + 3] = com0
        off = core.p_par
        for par in prob._params:
            p[off:off + par.size] = np.asarray(par.value, float).ravel(order="F")
            off += par.size
        p[core.p_scale] = scale
        p[core.p_col:] = self.col_p
        return p

    def _bounds(self, fixed: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Variable bounds: the control points' position limits, a free duration's range and
        (``fixed``) the end control points fixed by a boundary (:meth:`_fixed_families`)."""
        core, prob = self.core, self.prob
        assert core is not None
        lbx, ubx = np.full(core.nx, -np.inf), np.full(core.nx, np.inf)
        nj = core.nj
        for lo, hi in self.pbounds.values():
            lbx[:core.nP] = np.maximum(lbx[:core.nP], np.tile(lo, core.N + 3))
            ubx[:core.nP] = np.minimum(ubx[:core.nP], np.tile(hi, core.N + 3))
        if core.free_time:
            assert core.i_T is not None
            lbx[core.i_T], ubx[core.i_T] = prob.duration_bounds
        if fixed:
            for idx, val, _ in self.fixed.values():
                lbx[idx], ubx[idx] = val, val
        assert nj > 0
        return lbx, ubx

    def _pinned(self) -> dict[int, np.ndarray]:
        return self.prob._pinned_q()

    def _com0(self, q_start: np.ndarray) -> np.ndarray:
        prob = self.prob
        if not prob.robot.is_floating:
            return np.zeros(3)
        model = prob.robot.model
        full = np.zeros(model.nq)
        full[6] = 1.0
        full[7:] = q_start
        c = pin.centerOfMass(model, prob.robot.data, full)
        return prob.base0.translation + prob.base0.rotation @ c

    def guess(self, T: float) -> np.ndarray:
        core = self.core
        assert core is not None
        x = self._guess(T)
        n_aux = core.nx - core.x_aux
        return x if x.size == core.nx else np.r_[x, self.aux0 if self.aux0.size == n_aux else np.zeros(n_aux)]

    def _guess(self, T: float) -> np.ndarray:
        """The guess in core variables: a solution given to ``set_initial``, the user's knots
        fitted, the last converged solution of this problem, or seeded from its rows."""
        core, prob = self.core, self.prob
        assert core is not None
        if self.x0 is not None and self.x0.size == core.nx:
            return self.x0
        if prob._x0 is not None:
            # the fit of the user's knots: the same numbers give the same guess (prepare plans the
            # collision rows along it and the solve starts from it: one fit, not two)
            key = (core.N, core.nP, core.fl, core.free_time, float(T), float(prob.duration),
                   np.asarray(prob._x0, float).tobytes())
            if self._fitted is not None and self._fitted[0] == key:
                return self._fitted[1].copy()
            u: dict[str, Any] = prob.tp.unpack(prob._x0)
            Tg = float(u.get("T", T))
            P = core.fit(u["q"], u["qd"][0], u["qd"][-1], Tg / core.N)
            P = self._fit_between_fixed(P, np.asarray(u["q"], float))
            parts = [P.ravel()]
            if core.fl:
                parts.append(core.integrate_base(P))
            if core.free_time:
                parts.append(np.array([Tg]))
            x = np.concatenate(parts)
            self._fitted = (key, x.copy())
            return x
        if self.last_x is not None and self.last_x.size == core.nx:
            return self.last_x
        lbx, ubx = self._bounds(fixed=False)
        lo, hi = lbx[:core.nj], ubx[:core.nj]
        return seed_guess(core, self.fams, lambda q0: self._pvec(T, self._com0(q0) if q0 is not None else np.zeros(3),
                                                                  1.0), T, lo, hi, self._pinned())

    # ------------------------------------------------------------------ solve
    def solve(self, tol: float, max_iter: int, sopts: SolverOptions, compile_kernels: bool | str) -> Solution:
        """Solve; with a fixed duration, re-solve from the solution (at most ``velocity_retries``
        times) when a velocity
        entry without a row exceeded its limit (:meth:`_missed_velocity`)."""
        sol = self._solve_once(tol, max_iter, sopts, compile_kernels)
        for _ in range(int(self.velocity_retries)):
            if not sol.success or sol.x is None or not self._missed_velocity(sol.x, max(tol, 1e-9)):
                break
            prev = sol
            self.x0, self.lam = np.asarray(sol.x, float), None
            sol = self._solve_once(tol, max_iter, sopts, compile_kernels).labelled("velocity rows").after(prev)
        if sol.success and sol.x is not None and self.core is not None and not self.core.free_time \
                and self._velocity_families():
            V = self._velocity_points(sol.x).ravel()
            for f in self._velocity_families():
                lo, hi = (np.tile(b, self.core.N + 2) for b in np.asarray(f.data))
                if np.any((V > hi + max(tol, 1e-9) * 10) | (V < lo - max(tol, 1e-9) * 10)):
                    # a limit missed after the re-solves: never success
                    sol = dataclasses.replace(sol, success=False, status=IpoptStatus.VIOLATED_BETWEEN_KNOTS)
        return sol

    def _solve_once(self, tol: float, max_iter: int, sopts: SolverOptions, compile_kernels: bool | str) -> Solution:
        prob = self.prob
        t_setup = time.perf_counter()
        if self.core is None:
            self.prepare()
        core = self.core
        assert core is not None
        self.fixed = self._fixed_families(core)   # the duration or the option may have changed
        T = prob.duration
        lbx, ubx = self._bounds()
        # the start configuration fixes the centre of mass of a floating robot: from the guess
        x0 = np.clip(self.guess(T), lbx, ubx)
        p = self._pvec(T, self._com0(core.control_points(x0)[:3].T @ np.array([1, 4, 1]) / 6), 1.0)
        ctol = float(sopts.casadi_options({"ipopt.constr_viol_tol": tol}).get("ipopt.constr_viol_tol", tol))
        self.constant = self._constant_rows(x0, p, ctol)
        rows = self.row_families()
        st = core.structure(rows, bool(self.pbounds), compile_kernels)
        from_last = prob._x0 is None and self.last_x is not None and self.last_x.size == core.nx
        if self.scale is not None and (self.x0 is not None or from_last):
            scale = self.scale        # a previous solve's (its multipliers are in that scale)
        else:
            # the objective is scaled to 1 on the rest-to-rest quintic between the guess's end
            # configurations (a planner path's jerk can be thousands of times the optimum's),
            # else at the guess
            Q = core.M["q"] @ core.control_points(x0)
            xr = _quintic(core, Q[0], Q[-1], core.duration_of(x0, T))
            xr = np.r_[xr, x0[xr.size:]]
            f0 = abs(float(st["ffun"](xr, p)))
            if not (np.isfinite(f0) and f0 > 1e-12):
                f0 = abs(float(st["ffun"](x0, p)))
            scale = 1.0 / f0 if np.isfinite(f0) and f0 > 1e-12 else 1.0
            scale = float(10.0 ** (np.round(np.log10(np.clip(scale, 1e-8, 1e8)) * 2) / 2))
        p[core.p_scale] = scale
        lbg, ubg = core.row_bounds(st, rows, None if core.free_time else T)
        n_ineq = int(np.sum(lbg != ubg))
        defaults: dict[str, Any] = {
            "ipopt.tol": tol, "ipopt.constr_viol_tol": tol, "ipopt.acceptable_constr_viol_tol": tol,
            "ipopt.max_iter": int(max_iter),
            "ipopt.mu_strategy": "adaptive" if n_ineq > 0.5 * (lbg.size - n_ineq) else "monotone",
            "ipopt.jacobian_regularization_value": 1e-6,
            # no residuals computed to verify each search direction, no least-squares estimate of the
            # first multipliers (a factorization; the transport's iterates are unchanged): IPOPT CPU
            # 0.87-0.96×, the same iterations ±3 % (docs/optproblem.md, "The transport's solve, by section");
            # MUMPS's workspace 2× its estimate, not 11×: pipeline system time ~0.7× ("The transport's first build")
            "ipopt.fast_step_computation": "yes", "ipopt.constr_mult_init_max": 0.0, "ipopt.mumps_mem_percent": 100}
        if core.fl:
            defaults.update({"ipopt.mumps_pivot_order": 6, "ipopt.mu_init": 1e-3})
        if core.nx > core.x_aux or self.col_p.size:
            # the segment NLP's settings for its plane rows (docs/decisions/0015-segment-nlp-stalls.md);
            # a floating robot's NLP without IPOPT's permanent constraint regularisation: with the
            # momentum and attitude rows it stalled at a primal infeasibility ~1e-3 (decision 0022)
            defaults.update({"ipopt.mu_strategy": "adaptive", "ipopt.theta_max_fact": 10.0})
            if not core.fl:
                defaults["ipopt.perturb_always_cd"] = "yes"
        if defaults["ipopt.mu_strategy"] == "adaptive":
            # the adaptive μ's fallback to monotone mode let one inactive inequality family (a user's
            # "upright within 5°" on the transport) send IPOPT 9.6 m off at iteration 10: 45-48
            # iterations instead of 20. Never switching: 20; the same or fewer iterations on every
            # converged benchmark problem measured (docs/decisions/0016-modelling-on-the-kernel-core.md).
            # The pipeline's segments use it too, and re-solve once with IPOPT's own globalization when a
            # solve does not converge (PipelineOptions.globalization_retry_options, decision 0021).
            defaults["ipopt.adaptive_mu_globalization"] = "never-monotone-mode"
        warm = self.lam is not None and self.lam[0] is not None and np.size(self.lam[0]) == lbg.size \
            and self.x0 is not None
        if warm:
            defaults.update(_WARM_START)
        okey = repr(sorted(sopts.casadi_options(defaults).items()))
        solver = st["solvers"].get(okey)
        setup = time.perf_counter() - t_setup   # the solver adds its own creation time
        if solver is None:
            solver = st["solvers"][okey] = _new_solver(st, sopts, defaults)
            if not warm and prob.prepare_warm_start:
                # the warm-started instance too, with the build: a re-solve after
                # set_initial(solution=...) then creates nothing (its creation is this build's)
                wd = {**defaults, **_WARM_START}
                wkey = repr(sorted(sopts.casadi_options(wd).items()))
                if wkey not in st["solvers"]:
                    twin = st["solvers"][wkey] = _new_solver(st, sopts, wd)
                    setup += twin.take_setup_time()
        args: dict[str, Any] = {}
        if warm:
            assert self.lam is not None
            args["lam_g0"] = np.asarray(self.lam[0]) * scale   # the solver's multipliers are scaled
            if self.lam[1] is not None and np.size(self.lam[1]) == core.nx:
                args["lam_x0"] = np.asarray(self.lam[1]) * scale
        out = solver.solve(x0, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, cost_scale=scale, extra_setup=setup, **args)
        return self._solution(out, st, rows, p, lbx, ubx, lbg, ubg, tol, scale)

    def _solution(self, out: Any, st: dict[str, Any], rows: list[Family], p: np.ndarray, lbx: np.ndarray,
                  ubx: np.ndarray, lbg: np.ndarray, ubg: np.ndarray, tol: float, scale: float) -> Solution:
        core, prob = self.core, self.prob
        assert core is not None
        x = np.array(out.x, float)
        COUNTS["solutions"] += 1
        g = self._g_at(st["gfun"], x, p)
        vv = np.maximum(np.maximum(lbg - g, g - ubg), 0.0)
        viol = float(vv.max()) if vv.size else 0.0
        viol = max(viol, float(np.max(np.maximum(np.maximum(lbx - x, x - ubx), 0.0))))
        if not np.isfinite(viol):
            viol = float("inf")
        terms = LazyTerms(self._terms_of(x, p, vv, st))
        T = core.duration_of(x, prob.duration)
        P = core.control_points(x)
        kv = knot_values(P, T / core.N, core.M)
        bq = bp = None
        if core.fl:
            bq, bp = base_placements(core, kv["q"], core.knot_xi(x), prob.base0, p[core.p_c0:core.p_c0 + 3])
        success = bool(out.status.succeeded and viol <= max(tol, 1e-9) * 10)
        self.x0, self.lam, self.scale = None, None, scale
        if success:
            self.last_x = x
        # the knots of the families that lost constant rows (_constant_rows), for the evaluator
        row_points = {f.name: list(f.points) for f in rows if self.constant.get(f.name)}
        ev = SplineEvaluator(prob, core, {**st, "lbg": lbg, "ubg": ubg, "fixed": dict(self.fixed),
                                          "row_points": row_points}, self.fams, self.owner, self.pbounds, p)
        lam_g = None if out.lam_g is None else np.asarray(out.lam_g) / scale   # multipliers of the unscaled cost
        lam_x = None if out.lam_x is None else np.asarray(out.lam_x) / scale
        return Solution(success=success, status=out.status, iterations=out.iterations, wall_time=out.wall_time,
                        cost=out.cost, max_constraint_violation=viol, terms=terms,
                        t=np.linspace(0.0, T, core.N + 1), q=kv["q"], qd=kv["qd"], qdd=kv["qdd"], jerk=kv["jerk"],
                        joint_names=prob.robot.joint_names, base_quat=bq, base_position=bp, x=x,
                        lam_g=lam_g, lam_x=lam_x, x_scale_h=None, setup_time=out.setup_time,
                        cpu_time=out.cpu_time, attempts=(out,), evaluator=ev)

    def _g_at(self, gfun: Any, x: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The rows ``g(x, p)`` (a copy), through a CasADi function buffer kept with this backend
        for ``gfun`` (``call_dense`` makes one per call: the same numbers)."""
        kept = getattr(self, "_gbuf", None)
        if kept is None or kept[0] is not gfun or kept[1].size != x.size or kept[2].size != p.size:
            kept = None
            if gfun.n_in() == 2 and gfun.nnz_in(0) == x.size and gfun.nnz_in(1) == p.size and gfun.n_out() == 1 \
                    and all(gfun.sparsity_in(i).is_dense() for i in range(2)) and gfun.sparsity_out(0).is_dense():
                try:
                    buf, run = gfun.buffer()
                    xb, pb, gb = np.zeros(x.size), np.zeros(p.size), np.zeros(gfun.nnz_out(0))
                    buf.set_arg(0, xb.data)
                    buf.set_arg(1, pb.data)
                    buf.set_res(0, gb.data)
                    kept = (gfun, xb, pb, gb, buf, run)
                except (AttributeError, NotImplementedError, RuntimeError, TypeError):
                    kept = None
            self._gbuf = kept
        if kept is None:
            return call_dense(gfun, x, p)[0].ravel()
        _, xb, pb, gb, buf, run = kept
        xb[:] = x
        pb[:] = p
        run()
        if buf.ret() != 0:
            raise RuntimeError(f"{gfun.name()}: evaluation failed (return code {buf.ret()})")
        return gb.copy()

    def _terms_of(self, x: np.ndarray, p: np.ndarray, vv: np.ndarray, st: dict[str, Any]) -> Any:
        """The computation of a solution's ``terms`` (cost terms: weighted cost; constraints: max
        violation; ``"dynamics"``) from this solve's numbers, for :class:`LazyTerms`: what it reads
        of this backend is taken now (a later solve replaces it)."""
        core, prob = self.core, self.prob
        assert core is not None
        handles = [(h.name, h.role) for h in prob._handles]
        owner, fixed, constant = dict(self.owner), dict(self.fixed), dict(self.constant)
        pbounds, cviol = dict(self.pbounds), self.constant_violation
        cfun, slices, cslices = st["cfun"], st["slices"], st["cslices"]

        def compute() -> dict[str, float]:
            COUNTS["terms_computed"] += 1
            terms: dict[str, float] = {}
            c = call_dense(cfun, x, p)[0].ravel()
            for name, role in handles:
                fs = owner.get(name, [])
                if role == "cost":
                    terms[name] = float(sum(c[cslices[f]].sum() for f in fs))
                else:
                    v = [float(vv[slices[f]].max()) for f in fs if f in slices and slices[f].stop > slices[f].start]
                    v += [float(np.max(np.abs(x[fixed[f][0]] - fixed[f][1]))) for f in fs if f in fixed]
                    v += [cviol for f in fs if constant.get(f)]
                    if name in pbounds:
                        lo, hi = pbounds[name]
                        P = core.control_points(x)
                        v.append(float(np.max(np.maximum(np.maximum(lo - P, P - hi), 0.0))))
                    terms[name] = max(v) if v else 0.0
            dyn = [float(vv[sl].max()) for n, sl in slices.items()
                   if n.startswith(("momentum", "base_attitude_dynamics")) and sl.stop > sl.start]
            terms["dynamics"] = max(dyn) if dyn else 0.0
            return terms

        return compute
