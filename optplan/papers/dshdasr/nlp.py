"""The DSHDASR paper (``dshdasr``): the space-arc NLP (Eq. 50), solved per waypoint with IPOPT.

* :class:`ArcPlanner` — the NLP ``min ||G1||² + ||G2||² + w ||X − X_prev||²`` (or its constrained
  form) subject to the arc-to-sphere distances ≥ d_sd, built once (desired poses, previous
  solution and obstacles are parameters) and solved at every waypoint warm-started from the
  previous one; :meth:`ArcPlanner.track` returns a :class:`~.dshdasr_task.TrackResult`.
* ``_external`` — optional C compilation of the NLP's derivative functions.

Public entry point: :mod:`optplan.papers.dshdasr`.
"""
from __future__ import annotations

import logging
import math
import time
from typing import Any

import casadi as ca
import numpy as np

from ...problem.nlp import NlpSolver, SolveOutcome, SolverOptions
from .arc_models import frame_on
from .arcs import arc_point_distance, sph, sph_angles
from .task import DshdasrArcs, TrackResult, TransposeTask

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- the NLP
def _external(fun: ca.Function, opt: str = "-O1"):
    """``fun`` compiled to C as a ``casadi.external`` (shared library cached in
    ``optplan.codegen.cache_dir()`` by a hash of the code); None without a C compiler."""
    import hashlib
    import os
    import shutil
    import tempfile
    from pathlib import Path

    from ...codegen import build_library, cache_dir
    from ...problem.kernels import load_library

    cc = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if cc is None:
        log.warning("no C compiler: the arc NLP stays interpreted")
        return None
    name = fun.name()
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(f"{name}.c", {"with_header": False})
        cg.add(fun)
        cg.generate(tmp + os.sep)
        code = Path(tmp, f"{name}.c").read_bytes()
        lib = cache_dir() / f"dshdasr_{name}_{hashlib.sha1(code + opt.encode()).hexdigest()[:16]}.so"
        ext = load_library(name, lib)   # checked first; a damaged library is quarantined (None)
        if ext is None:
            t0 = time.perf_counter()
            err = build_library(Path(tmp, f"{name}.c"), lib, opt)
            if err is not None:
                log.warning("compiling %s failed: %s", name, err[-400:])
                return None
            log.info("compiled %s in %.1f s", name, time.perf_counter() - t0)
            ext = load_library(name, lib)
    return ext


class ArcPlanner:
    """Eq. 50 as one IPOPT NLP, built once and re-solved per waypoint.

    Decision ``X = (X_a (8), X_b (15))``; parameters: the desired tips (pa, ka = z axis of Ra, pb,
    kb), the proximal centre X_c (the previous solution), the three angle frames, the obstacle
    centres and the thresholds. Inequalities: every arc-to-obstacle distance ≥ d_sd^k (+ the arc's
    deviation from its links when ``margin="links"``); bounds |φ| ≤ φ_max (Arm-b: the joint limits).

    * ``formulation="constrained"`` (default): ``min Σ (X − X_c)²`` s.t. ``G1 = 0, G2 = 0`` and the
      inequalities — the same solutions as Eq. 50 whenever its minimum is zero (the arms reach their
      poses without violating a threshold), found by Newton steps in 2-3 IPOPT iterations and to
      IPOPT's tolerance. Of the redundant solutions it takes the one nearest the previous one (the
      role of the paper's warm-started gradient descent).
    * ``formulation="least-squares"``: the paper's form, ``min ||G1||² + ||G2||² + w Σ (X − X_c)²``
      (``w`` small picks among the redundant solutions); ``hessian="gauss-newton"`` gives IPOPT
      ``2σ (JᵀJ + w I)`` for the objective (exact at a zero residual, always positive definite).

    IPOPT starts from the previous solution extrapolated one step. ``constraint_curvature=False``
    (default) leaves the distances' second derivatives out of the Hessian of the constrained form
    (a quasi-Newton approximation that is exact away from active obstacle constraints; 17× smaller
    Hessian code). Constraints farther than ``activation`` [m] from their threshold at the start get
    no lower bound for that solve, and the far-away φ bounds are dropped when no constraint is near
    — IPOPT then takes plain Newton steps; a result violating anything dropped is re-solved with
    everything. ``compile=True`` compiles the derivative functions to C (cached, ~10 s the first
    time)."""

    def __init__(self, arcs: DshdasrArcs | None = None, n_obstacles: int = 2, *, w: float = 1e-6,
                 margin: str = "paper", tol: float = 1e-10, max_iter: int = 100,
                 hessian: str = "exact", constraint_curvature: bool = False,
                 activation: float = 0.3, extrapolate: bool = True, formulation: str = "constrained",
                 compile: bool = False, options: dict | None = None):
        if margin not in ("paper", "links"):
            raise ValueError(f"margin: expected 'paper' or 'links', got {margin!r}")
        if hessian not in ("gauss-newton", "exact"):
            raise ValueError(f"hessian: expected 'gauss-newton' or 'exact', got {hessian!r}")
        self.arcs = arcs or DshdasrArcs()
        A, B = self.arcs.a, self.arcs.b
        self.n_obs, self.margin, self.activation, self.extrapolate = n_obstacles, margin, activation, extrapolate
        X = ca.SX.sym("X", A.nx + B.nx)
        pa, ka, pb, kb = (ca.SX.sym(n, 3) for n in ("pa", "ka", "pb", "kb"))
        Xc = ca.SX.sym("Xc", A.nx + B.nx)
        Rs = [ca.SX.sym(f"R{i}", 3, 3) for i in range(3)]
        obs = ca.SX.sym("obs", 3, n_obstacles)
        thr = ca.SX.sym("thr", 2)
        P = ca.vertcat(pa, ka, pb, kb, Xc, *[ca.vec(R) for R in Rs], ca.vec(obs), thr)
        Xa, Xb = X[:A.nx], X[A.nx:]
        G1 = A.residuals(Xa, pa, ka, Rs[0])
        G2 = B.residuals(Xb, pb, kb, (Rs[1], Rs[2]))
        G = ca.vertcat(G1, G2)
        if formulation not in ("least-squares", "constrained"):
            raise ValueError(f"formulation: expected 'least-squares' or 'constrained', got {formulation!r}")
        self.formulation = formulation
        if formulation == "least-squares":
            f = ca.sumsqr(G) + w * ca.sumsqr(X - Xc)
        else:
            f = ca.sumsqr(X - Xc)
        arcs_a, arcs_b = A.arcs(Xa, pa, ka, Rs[0]), B.arcs(Xb, pb, kb, (Rs[1], Rs[2]))
        dev_a = A.deviations(Xa) if margin == "links" else [0] * A.n_arcs
        dev_b = B.deviations(Xb) if margin == "links" else [0] * B.n_arcs
        dist, g = [], []
        for i in range(n_obstacles):
            o = obs[:, i]
            for arc, dv in zip(arcs_a, dev_a):
                d = arc_point_distance(arc, o)
                dist.append(d)
                g.append(d - thr[0] - dv)
            for arc, dv in zip(arcs_b, dev_b):
                d = arc_point_distance(arc, o)
                dist.append(d)
                g.append(d - thr[1] - dv)
        g = ca.vertcat(*g)
        self.n_dist = g.numel()
        if formulation == "constrained":
            g = ca.vertcat(g, G)
        self.nx, self.np_, self.ng = X.numel(), P.numel(), g.numel()
        defaults = {"ipopt.mu_strategy": "adaptive", "ipopt.warm_start_init_point": "yes",
                    "ipopt.mu_init": 1e-9, "ipopt.warm_start_bound_push": 1e-9,
                    "ipopt.warm_start_mult_bound_push": 1e-9, "ipopt.warm_start_slack_bound_push": 1e-9,
                    "ipopt.acceptable_tol": 1e-10, "ipopt.acceptable_iter": 3,
                    "ipopt.nlp_scaling_method": "none", "ipopt.bound_relax_factor": 0.0}
        casadi_opts: dict[str, Any] = {"expand": True, "calc_lam_p": False}
        sopts = SolverOptions.coerce(options, tol=tol, max_iter=max_iter)
        lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", self.ng)
        H = None
        if hessian == "gauss-newton" and formulation == "least-squares":
            J = ca.jacobian(G, X)
            H = lam_f * 2 * (ca.mtimes(J.T, J) + w * ca.SX.eye(self.nx))
            if constraint_curvature:
                H = H + ca.hessian(ca.dot(lam_g, g), X)[0]
        elif formulation == "constrained" and not constraint_curvature:
            # exact for the objective and the equality residuals, no curvature of the distances
            H = lam_f * 2 * ca.SX.eye(self.nx) + ca.hessian(ca.dot(lam_g[self.n_dist:], G), X)[0]
        if H is not None:
            casadi_opts["hess_lag"] = ca.Function("hess_lag", [X, P, lam_f, lam_g], [ca.triu(H)],
                                                  ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
        nlp = {"x": X, "p": P, "f": f, "g": g}
        self.nlp_solver = NlpSolver("dshdasr_arcs", nlp, sopts, defaults=defaults, casadi_options=casadi_opts)
        self.compiled = False
        if compile:
            ext = {}
            for name, opt_name in (("nlp_grad_f", "grad_f"), ("nlp_jac_g", "jac_g"), ("nlp_hess_l", "hess_lag")):
                e = _external(self.nlp_solver.solver.get_function(name))
                if e is None:
                    break
                ext[opt_name] = e
            else:
                self.nlp_solver = NlpSolver("dshdasr_arcs", nlp, sopts, defaults=defaults,
                                            casadi_options={**casadi_opts, **ext})
                self.compiled = True
        self.solver = self.nlp_solver.solver
        lba, uba = A.bounds()
        lbb, ubb = B.bounds(self.arcs.b_phi_max)
        self.lbx, self.ubx = np.r_[lba, lbb], np.r_[uba, ubb]
        self.lbg_all = np.zeros(self.ng)
        self.ubg_all = np.r_[np.full(self.n_dist, np.inf), np.zeros(self.ng - self.n_dist)]
        self.f_eval = ca.Function("arc_eval", [X, P], [G1, G2, ca.vertcat(*dist), g[:self.n_dist]],
                                  ["X", "P"], ["G1", "G2", "dist", "g"])

    # ------------------------------------------------------------------ parameters
    def pack(self, des: dict, k: int, Xc, refs, obstacles, thresholds) -> np.ndarray:
        return np.concatenate([des["pa"][k], des["Ra"][k][:, 2], des["pb"][k], des["kb"][k], Xc,
                               *[np.asarray(R).ravel(order="F") for R in refs],
                               np.asarray(obstacles, float).T.ravel(order="F"),
                               [thresholds["a"], thresholds["b"]]])

    @staticmethod
    def _dirs(X, refs) -> list[np.ndarray]:
        """World directions of the three direction unknowns (k3 of Arm-a, k1, k3 of Arm-b)."""
        return [refs[0] @ sph(X[6], X[7]), refs[1] @ sph(X[8 + 8], X[9 + 8]),
                refs[2] @ sph(X[13 + 8], X[14 + 8])]

    _ANG = ((6, 7), (16, 17), (21, 22))  # positions of the direction angles in X

    def recentre(self, X, refs, X_old=None, refs_old=None):
        """Express X in angle frames centred on its own directions (angles (π/2, 0)); with the
        previous solution also given, return the linear extrapolation one step ahead too."""
        dirs = self._dirs(X, refs)
        new = tuple(frame_on(d) for d in dirs)
        Xn = X.copy()
        for (i, j) in self._ANG:
            Xn[i], Xn[j] = math.pi / 2, 0.0
        if X_old is None:
            return Xn, new, Xn.copy()
        Xo = X_old.copy()
        for R, d_old, (i, j) in zip(new, self._dirs(X_old, refs_old), self._ANG):
            Xo[i], Xo[j] = sph_angles(R.T @ d_old, 0.0)
        return Xn, new, 2 * Xn - Xo

    # ------------------------------------------------------------------ tracking
    def solve(self, p, x0, lam_g0=None, lam_x0=None, lbg=None, bounds: bool = True) -> SolveOutcome:
        """One IPOPT solve (a :class:`~optplan.problem.nlp.SolveOutcome`, also when IPOPT raised).
        ``lbg``: lower bounds of the distance constraints (default 0); ``bounds=False`` drops the
        |φ| bounds for this solve."""
        lb = self.lbg_all.copy()
        if lbg is not None:
            lb[:self.n_dist] = lbg
        inf = np.full(self.nx, np.inf)
        return self.nlp_solver.solve(x0, p=p, lbx=self.lbx if bounds else -inf, ubx=self.ubx if bounds else inf,
                                     lbg=lb, ubg=self.ubg_all, lam_g0=0.0 if lam_g0 is None else lam_g0,
                                     lam_x0=0.0 if lam_x0 is None or not bounds else lam_x0)

    def solve_waypoint(self, p, x0, lam_g0=None, lam_x0=None, g0=None):
        """Solve one waypoint from the start ``x0``. Distance constraints farther than
        ``activation`` from their threshold (at ``x0``, or ``g0`` when given: the previous
        solution's values) get no lower bound, and when none is near, the far-away |φ| bounds are
        dropped too — IPOPT then has no inequality at all and takes plain Newton steps without a
        barrier; the full problem is re-solved if the result violates anything that was dropped.
        Returns (x, outcome, resolved)."""
        if g0 is None:
            g0 = np.array(self.f_eval(x0, p)[3]).ravel()
        near = g0 < self.activation
        at_bound = ((x0 - self.lbx) < 0.2).any() or ((self.ubx - x0) < 0.2).any()
        out = self.solve(p, x0, lam_g0, lam_x0, np.where(near, 0.0, -np.inf), bounds=bool(near.any() or at_bound))
        x = np.array(out.x)
        bad = (out.g is None or (out.g[:self.n_dist] < -1e-9).any() or (x < self.lbx).any() or (x > self.ubx).any())
        if bad or not out.success:
            out = self.solve(p, x0, lam_g0, lam_x0, None, bounds=True)
            x = np.array(out.x)
        return x, out, bool(bad or not out.success)

    def track(self, task: TransposeTask, q0: np.ndarray, times=None) -> TrackResult:
        """Solve every waypoint of ``task`` from the configuration ``q0`` (which must hold the first
        desired tips); returns the recovered joints and the per-waypoint NLP statistics."""
        arcs = self.arcs
        t = task.times() if times is None else np.asarray(times, float)
        des = task.desired(t)
        thr = task.thresholds
        n, nA = len(t), arcs.a.nx
        Q = np.zeros((n, arcs.robot.nq))
        Xs = np.zeros((n, self.nx))
        iters = np.zeros(n, int)
        ok = np.zeros(n, bool)
        resolves = 0
        refs = (np.eye(3),) * 3
        X = np.r_[arcs.params_from_q(q0, refs)]
        X_old = refs_old = None
        lam_g, lam_x = np.zeros(self.ng), np.zeros(self.nx)
        g_prev = None
        q_prev = np.asarray(q0, float)
        t_nlp = 0.0
        t_start = time.perf_counter()
        for k in range(n):
            Xn, refs_n, Xpred = self.recentre(X, refs, X_old if self.extrapolate else None, refs_old)
            X_old, refs_old, refs = Xn, refs_n, refs_n
            p = self.pack(des, k, Xn, refs, task.obstacles, thr)   # proximal centre: previous solution
            t0 = time.perf_counter()
            X, out, again = self.solve_waypoint(p, Xpred, lam_g, lam_x, g_prev)
            g_prev = np.array(out.g[:self.n_dist]) if out.g is not None else None
            t_nlp += time.perf_counter() - t0
            resolves += again
            if out.lam_g is not None:
                lam_g, lam_x = np.array(out.lam_g), np.array(out.lam_x)
            iters[k], ok[k] = out.iterations, out.success
            Q[k] = arcs.q_from_params(X[:nA], X[nA:], des["pa"][k], des["Ra"][k], des["pb"][k], des["kb"][k],
                                      q_prev=q_prev, refs=refs)
            q_prev = Q[k]
            Xs[k] = self._world_angles(X, refs)
        runtime = time.perf_counter() - t_start
        return TrackResult("arcs", t, Q, des, runtime, nlp_time=t_nlp, iterations=iters, success=ok, X=Xs,
                           resolves=resolves)

    def clear_start(self, task: TransposeTask, q: np.ndarray, clearance: float = 0.2) -> np.ndarray:
        """Move a configuration holding the first desired tips so that every arc is at least
        ``clearance`` [m] beyond its obstacle threshold (one NLP solve with raised thresholds,
        proximal to ``q``); returns the recovered joints."""
        des = task.desired([0.0])
        refs = (np.eye(3),) * 3
        X, refs, _ = self.recentre(np.r_[self.arcs.params_from_q(q, refs)], refs)
        thr = {k: v + clearance for k, v in task.thresholds.items()}
        p = self.pack(des, 0, X, refs, task.obstacles, thr)
        out = self.solve(p, X)
        if not out.success:
            raise RuntimeError(f"clear_start: IPOPT {out.status.value}")
        x = np.array(out.x)
        nA = self.arcs.a.nx
        return self.arcs.q_from_params(x[:nA], x[nA:], des["pa"][0], des["Ra"][0], des["pb"][0], des["kb"][0],
                                       q_prev=q, refs=refs)

    def _world_angles(self, X, refs) -> np.ndarray:
        """The solution with its direction angles in the paper's frame (Eq. 25, identity)."""
        X = X.copy()
        for d, (i, j) in zip(self._dirs(X, refs), self._ANG):
            X[i], X[j] = sph_angles(d)
        return X

    def arc_distances(self, X, des: dict, k: int, task: TransposeTask, constraints: bool = False):
        """Arc-model distances (n_obs × (3 + 5), Arm-a's three arcs then Arm-b's five) of a
        solution stored with world angles; with ``constraints`` also the constraint values
        (distance − threshold [− deviation]) in the same layout."""
        p = self.pack(des, k, X, (np.eye(3),) * 3, task.obstacles, task.thresholds)
        out = self.f_eval(X, p)
        d = np.array(out[2]).ravel().reshape(self.n_obs, -1)
        return (d, np.array(out[3]).ravel().reshape(self.n_obs, -1)) if constraints else d
