"""The floating-base B-spline NLP: a rest-to-rest joint motion of a free-floating robot whose base
attitude is integrated from zero momentum and constrained at the end (base-attitude restoration),
built from per-knot / per-interval kernels that are compiled once and cached.

Transcription
-------------
Joint trajectory: the uniform cubic B-spline of :mod:`.bspline` on ``N`` intervals of ``h = T/N``
(control points ``P_0 … P_{N+2}``; the three at each end are fixed by rest at the pinned start and
end configurations). Decision variables:

* the interior control points ``P_3 … P_{N−1}`` (nj each);
* the base attitude at the knots 1 … N: unit quaternions ``ξ_k`` (Pinocchio's ``x, y, z, w``) of
  ``R_b(0)ᵀ R_b(t_k)`` — the attitude relative to the start, which is all zero momentum
  determines (the dynamics ``ξ̇ = ½ ξ ⊗ ω`` are left-invariant);
* the base angular velocity at every half RK4 sub-step (``2 n_sub + 1`` points per interval,
  shared at the knots), in the base frame and per unit of normalised time ``u = t/h``:
  ``ω'_c = h ω_b(t_c)`` [rad per interval].

Rows:

* **Zero momentum** at each twist point: the angular momentum about the centre of mass,
  ``A_ω(q) ω' + A_m(q) q' = 0`` with ``q' = dq/du`` (3 rows; linear in ``ω'`` and ``q'``, no matrix
  inverse). With zero linear momentum the centre of mass is fixed and the base translation does
  not enter the angular momentum about it, so these three rows determine ``ω_b``.
* **Attitude**: ``ξ_{k+1} = RK4(ξ_k; ω'_{2k}, ω'_{2k+1}, ω'_{2k+2})`` (``n_sub`` classical RK4
  steps per interval on ``ξ' = ½ ξ ⊗ [ω'; 0]``, renormalised) — 4 rows per interval; ``ξ_0`` is
  the identity.
* **End attitude**: the vector part of ``ξ_tgt⁻¹ ⊗ ξ_N`` is zero and its scalar part ≥ 0 (linear
  rows; ``ξ_tgt`` the identity for restoration).
* **Closed chain** (optional): the hands' relative pose at the interior knots (the singularity-free
  pose residual of :class:`~optplan.problem.ClosedChain`, taken in the base frame).
* **Joint limits** on the control points (convex hull: valid between the knots), **velocity limits**
  on the velocity control points (linear rows, valid between the knots).
* **Cost**: ``∫‖d³q/dt³‖² dt`` (exact, a constant quadratic form), scaled by the rest-to-rest
  quintic's value.

Kernels and derivatives
-----------------------
Each row family is one small SX function of one point's local inputs (``q``, ``q'``, ``ω'`` for the
momentum; ``q`` for the closed chain; the quaternions and twists of one interval for the attitude
step), built once per robot (:class:`FloatingKernels`, cached in memory and on disk like
:class:`~optplan.problem.kernels.KernelCache`) and evaluated over its points with
``Function.map``. A kernel input is a fixed linear combination of decision variables (the B-spline
weights ``b_a(u)``, ``b'_a(u)``), so the NLP's exact Jacobian and Lagrangian Hessian are
``Wᵀ ∇f`` and ``Wᵀ ∇²f W`` of the mapped kernel derivatives: one constant sparse scatter each
(:class:`_LocalAssembly`).

Accuracy between the knots: the attitude is integrated by RK4 along the exact cubic joint
motion, global error O(h⁴) (measured against an adaptive integration of the same ODE: see
``docs/eba.md``); the closed chain holds at the knots and drifts ∝ h⁴ between them.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any, cast

import casadi as ca
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from ..model.robot import RobotModel
from .bspline import check_knot_guess, fit_interior, jerk_integral_reference, knot_values, rest_to_rest
from .floating_kernels import FloatingKernels, _LocalAssembly, momentum_template, spline_basis
from .frame_terms import ClosedChain
from .solution import Solution

__all__ = ["FloatingKernels", "FloatingSegmentSpec", "FloatingSplineProblem", "spline_basis"]
log = logging.getLogger(__name__)

_IDENTITY_Q = np.array([0.0, 0.0, 0.0, 1.0])



# --------------------------------------------------------------------------- problem
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
    """The NLP of the module docstring. ``set_initial(q)`` (knot configurations), then ``solve``
    → :class:`~optplan.problem.Solution` (the B-spline's knot values, so ``sample`` and
    :func:`optplan.verify.verify` see exactly the optimised trajectory, and ``base_quat``: the
    integrated attitude at the knots)."""

    def __init__(self, robot: RobotModel, spec: FloatingSegmentSpec, *, compile_kernels: bool | str = "auto"):
        if not robot.is_floating:
            raise ValueError(f"FloatingSplineProblem needs a free-floating robot; {robot.name!r} has a fixed base")
        self.robot, self.spec = robot, spec
        self.kernels = cast(FloatingKernels, FloatingKernels.of(robot))  # of(): an instance of cls
        #: evaluate the kernels from C compiled once per robot (True: compile if needed; "auto": use
        #: the compiled kernels when a previous run left them in the cache; False: never; see
        #: :meth:`FloatingKernels.kernel_set`)
        if compile_kernels not in (True, False, "auto"):
            raise ValueError(f"compile_kernels: expected True, False or 'auto', got {compile_kernels!r}")
        self.compile_kernels = compile_kernels
        N = self.N = int(spec.n_intervals)
        if N < 4:
            raise ValueError(f"n_intervals: expected ≥ 4, got {spec.n_intervals!r}")
        if isinstance(spec.n_sub, bool) or int(spec.n_sub) != spec.n_sub or spec.n_sub < 1:
            raise ValueError(f"n_sub: expected an integer ≥ 1, got {spec.n_sub!r}")
        self.n_sub = int(spec.n_sub)
        if spec.smoothness not in ("jerk", "acceleration"):
            raise ValueError(f"smoothness: expected 'jerk' or 'acceleration', got {spec.smoothness!r}")
        (self.T, self.h, self.M, self.q0, self.q1, self.P_start, self.P_end, self.lower,
         self.upper) = rest_to_rest(robot, N, spec.duration, spec.q_start, spec.q_end, spec.lower, spec.upper)
        nj = robot.nj
        if not spec.position_limits:
            self.lower, self.upper = np.full(nj, -np.inf), np.full(nj, np.inf)
        if spec.velocity_limit is False:
            self.vlim = None
        else:
            self.vlim = robot.velocity_limit.copy() if spec.velocity_limit is None else np.broadcast_to(
                np.asarray(spec.velocity_limit, float), (nj,)).copy()
        if spec.end_attitude is False:
            self.target_quat = None
        else:
            R = np.eye(3) if spec.end_attitude is None else np.asarray(spec.end_attitude, float)
            if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
                raise ValueError(f"end_attitude: expected a 3 × 3 rotation matrix, got {R!r}")
            self.target_quat = pin.Quaternion(R).coeffs().copy()  # x, y, z, w
        # the objective's scale: 1 / its value on the rest-to-rest quintic
        if spec.smoothness == "jerk":
            fref = jerk_integral_reference(self.q0, self.q1, self.T)
        else:
            d = self.q1 - self.q0
            fref = float(120.0 / 7.0 * (d @ d) / self.T**3)  # ∫ q̈² dt of the quintic
        self._scale = 1.0 / fref if fref > 0 else 1.0
        self._X0: np.ndarray | None = None
        self._B0: np.ndarray | None = None
        self._built: dict[str, Any] | None = None
        # layout of x: [P_3 … P_{N−1} (nj each) | ξ_1 … ξ_N (4 each) | ω'_0 … ω'_{2 n_sub N} (3 each)]
        self.nP = (N - 3) * nj
        self.nW = 2 * self.n_sub * N + 1
        self.nx = self.nP + 4 * N + 3 * self.nW
        self.np = 6 * nj + 5  # [P_start, P_end, ξ_0, cost scale]

    # ------------------------------------------------------------------ indices
    def _slot_P(self, i: int) -> np.ndarray:
        """Indices in [x; p] of control point P_i's nj entries."""
        nj, N = self.robot.nj, self.N
        if 3 <= i <= N - 1:
            return (i - 3) * nj + np.arange(nj)
        if i < 3:
            return self.nx + i * nj + np.arange(nj)
        return self.nx + 3 * nj + (i - N) * nj + np.arange(nj)

    def _slot_xi(self, k: int) -> np.ndarray:
        if k == 0:
            return self.nx + 6 * self.robot.nj + np.arange(4)
        return self.nP + 4 * (k - 1) + np.arange(4)

    def _slot_w(self, c: int) -> np.ndarray:
        return self.nP + 4 * self.N + 3 * c + np.arange(3)

    # ------------------------------------------------------------------ initial guess
    def set_initial(self, q: npt.ArrayLike) -> None:
        """Initial guess from knot configurations ``q`` ((N+1) × nj [rad]); the base attitude and
        twists are initialised by integrating the guess (RK4, as the NLP)."""
        Q = check_knot_guess(q, self.N, self.robot.nj)
        self._X0 = np.clip(fit_interior(Q, self.P_start, self.P_end), self.lower, self.upper)
        self._B0 = self._integrate(self._X0)

    def _P(self, X: npt.ArrayLike) -> np.ndarray:
        return np.vstack([self.P_start, np.asarray(X).reshape(self.N - 3, self.robot.nj), self.P_end])

    def _integrate(self, X: npt.ArrayLike) -> np.ndarray:
        """[ξ_1 … ξ_N; ω'_0 …] of the joint trajectory of control points X, by the NLP's own
        kernels (numeric)."""
        P = self._P(X)
        W = np.zeros((self.nW, 3))
        A = self._omega_numeric
        m = 2 * self.n_sub
        for c in range(self.nW):
            k, i = divmod(c, m)
            if k == self.N:
                k, i = self.N - 1, m
            b, db = spline_basis(i / m)
            W[c] = A(b @ P[k:k + 4], db @ P[k:k + 4])
        xi = _IDENTITY_Q.copy()
        out = []
        step = self.kernels.attitude_step(self.n_sub)
        for k in range(self.N):
            z = np.r_[xi, np.zeros(4), W[m * k:m * k + m + 1].ravel()]
            xi = -np.asarray(step(z)).ravel()  # ξ_b − RK4 with ξ_b = 0
            out.append(xi)
        return np.r_[np.concatenate(out), W.ravel()]

    def _omega_numeric(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """ω' from the momentum kernel's linear structure (numeric, Pinocchio-free)."""
        kc = self.kernels
        fn = kc._fns.get(("fb_momentum_linear",))
        if fn is None:
            f = kc.momentum()
            z = ca.SX.sym("z", f.size1_in(0))
            J = ca.jacobian(f(z), z)
            fn = kc._fns[("fb_momentum_linear",)] = ca.Function("mom_lin", [z], [J[:, 2 * self.robot.nj:], f(z)])
        Aw, r = fn(np.r_[q, dq, np.zeros(3)])
        return -np.linalg.solve(np.asarray(Aw), np.asarray(r).ravel())

    # ------------------------------------------------------------------ build
    def _build(self) -> dict[str, Any]:
        t0 = time.perf_counter()
        N, nj, nx = self.N, self.robot.nj, self.nx
        m = 2 * self.n_sub
        x = ca.MX.sym("x", nx)
        p = ca.MX.sym("p", self.np)
        xp = ca.vertcat(x, p)
        asm = _LocalAssembly(nx, self.np)
        kc = self.kernels
        # momentum at every twist point: input [q; q'; ω'], u = i / (2 n_sub) in interval k
        def kernel(kind: str, *args: Any) -> tuple[ca.Function, ...]:
            return kc.kernel_set(kind, *args, compiled=self.compile_kernels)

        fmom, jm, hm = kernel("momentum")
        for i in range(m):  # points with the same fraction u share one template
            b, db = spline_basis(i / m)
            ks = list(range(N)) + ([N - 1] if i == 0 else [])  # the last knot: u = 1 of interval N − 1
            if i == 0:
                bb = [spline_basis(0.0)] * N + [spline_basis(1.0)]
            else:
                bb = [(b, db)] * N
            tmpl, slots = [], []
            for t, k in enumerate(ks):
                bk, dbk = bb[t]
                row = np.concatenate([self._slot_P(k + a) for a in range(4)] +
                                     [self._slot_w(m * N if (i == 0 and t == N) else m * k + i)])
                slots.append(row)
                if t == 0 or (i == 0 and t == N):
                    tmpl.append(momentum_template(bk, dbk, nj))
            if i == 0:  # two templates (u = 0 and the last knot's u = 1): two families
                asm.family("momentum@knots", fmom, jm, hm, tmpl[0], np.array(slots[:N]), xp, 0.0, 0.0)
                asm.family("momentum@end", fmom, jm, hm, tmpl[1], np.array(slots[N:]), xp, 0.0, 0.0)
            else:
                asm.family(f"momentum@{i}/{m}", fmom, jm, hm, tmpl[0], np.array(slots), xp, 0.0, 0.0)
        # attitude steps
        fat, ja, ha = kernel("attitude", self.n_sub)
        nin = fat.size1_in(0)
        slots_a = np.array([np.concatenate([self._slot_xi(k), self._slot_xi(k + 1)] +
                                           [self._slot_w(m * k + c) for c in range(m + 1)]) for k in range(N)])
        tmpl_a = np.array([(i, i, 1.0) for i in range(nin)])
        asm.family("base_attitude_dynamics", fat, ja, ha, tmpl_a, slots_a, xp, 0.0, 0.0)
        # closed chain at the interior knots
        cc = self.spec.closed_chain
        if cc is not None:
            fcc, jc, hc = kernel("closed_chain", cc)
            b, _ = spline_basis(0.0)
            tmpl_c = np.array([(j, a * nj + j, b[a]) for a in range(3) for j in range(nj)])
            slots_c = np.array([np.concatenate([self._slot_P(k + a) for a in range(3)]) for k in range(1, N)])
            asm.family("closed_chain", fcc, jc, hc, tmpl_c, slots_c, xp,
                       np.tile(np.r_[np.zeros(6), 1.0], N - 1), np.tile(np.r_[np.zeros(6), np.inf], N - 1))
        # velocity limits on the velocity control points touching a free point
        if self.vlim is not None:
            import scipy.sparse as sps

            rows, cols, vals = [], [], []
            r = 0
            for i in range(2, N):  # dP_i = P_{i+1} − P_i
                for j in range(nj):
                    for idx, w in ((self._slot_P(i + 1)[j], 1.0), (self._slot_P(i)[j], -1.0)):
                        rows.append(r)
                        cols.append(idx)
                        vals.append(w)
                    r += 1
            A = sps.csr_matrix((vals, (rows, cols)), shape=(r, nx + self.np))
            vb = np.tile(self.vlim * self.h, N - 2)
            asm.linear("velocity_limits", xp, A, -vb, vb)
        # end attitude: vector part of ξ_tgt⁻¹ ⊗ ξ_N = 0, scalar part ≥ 0 (linear in ξ_N)
        if self.target_quat is not None:
            L = _quat_left(_quat_conj(self.target_quat))
            A = np.zeros((4, nx + self.np))
            A[:, self._slot_xi(N)] = L
            asm.linear("end_attitude", xp, A, np.zeros(4), np.r_[0.0, 0.0, 0.0, np.inf])
        # cost: ∫‖j‖² dt = Σ‖ΔP³‖² / h⁵ or ∫‖q̈‖² dt = h Σ (a_k² + a_k a_{k+1} + a_{k+1}²)/3, scaled
        import scipy.sparse as sps

        Pm = ca.horzcat(*[xp[self._slot_P(i)] for i in range(N + 3)])  # nj × (N+3)
        if self.spec.smoothness == "jerk":
            Cq = self.M["jerk"].T @ self.M["jerk"] / self.h**5  # quadratic form over the control points
        else:
            Ma = self.M["qdd"] / self.h**2
            S = (np.diag(np.r_[1.0, np.full(N - 1, 2.0), 1.0]) + np.eye(N + 1, k=1) / 2 + np.eye(N + 1, k=-1) / 2)
            Cq = self.h / 3 * (Ma.T @ S @ Ma)
        scale = p[-1]  # a parameter: a built solver serves every start/goal of the same structure
        f = scale * ca.sum1(ca.sum2(ca.mtimes(Pm, ca.sparsify(ca.DM(Cq))) * Pm))
        Hp = 2 * Cq[3:N, 3:N]
        Hf = sps.block_diag((sps.kron(Hp, sps.eye(nj)), sps.csr_matrix((nx - self.nP, nx - self.nP))))
        lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", asm.ng)
        G, Jg, Hl = asm.finish(lam_f * scale, lam_g, Hf.tocsr())
        nlp = {"x": x, "p": p, "f": f, "g": G}
        derivs = {"jac_g": ca.Function("jac_g", [x, p], [G, Jg], ["x", "p"], ["g", "jac_g_x"]),
                  "hess_lag": ca.Function("hess_lag", [x, p, lam_f, lam_g], [Hl],
                                          ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])}
        lbx = np.full(nx, -np.inf)
        ubx = np.full(nx, np.inf)
        lbx[:self.nP], ubx[:self.nP] = np.tile(self.lower, N - 3), np.tile(self.upper, N - 3)
        self._built = dict(nlp=nlp, derivs=derivs, lbx=lbx, ubx=ubx, lbg=asm.lbg, ubg=asm.ubg,
                           gfun=ca.Function("g", [x, p], [G]), slices=asm.slices, solvers={},
                           build_time=time.perf_counter() - t0)
        return self._built

    def _structure_key(self) -> tuple[Any, ...]:
        """What the built NLP depends on (everything but the start/goal and the warm start)."""
        cc = self.spec.closed_chain
        def arr(a: npt.ArrayLike | None) -> bytes | None:
            return None if a is None else np.asarray(a, float).tobytes()

        return (self.kernels._digest, self.N, self.T, self.n_sub, self.spec.smoothness, self.compile_kernels,
                None if cc is None else (cc.arm_a, cc.arm_b,
                                          # a chain without its relative pose fails here (AttributeError), as it always did
                                          np.asarray(cc.relative.homogeneous).tobytes()),  # type: ignore[union-attr]
                arr(self.lower), arr(self.upper), arr(self.vlim), arr(self.target_quat))

    def _get_built(self) -> dict[str, Any]:
        """The built NLP of this problem's structure: from memory when one of the same structure
        was built in this process (:meth:`KernelCache.structure`, with its IPOPT instances; the
        start/goal and the objective scale are parameters), else built now."""
        if self._built is None:
            self._built = self.kernels.structure(("floating_segment",) + self._structure_key(), self._build)
        return self._built

    def _p(self) -> np.ndarray:
        return np.r_[self.P_start.ravel(), self.P_end.ravel(), _IDENTITY_Q, self._scale]

    # ------------------------------------------------------------------ solve
    def solve(self, ipopt_options: dict[str, Any] | None = None, *, tol: float = 1e-8, dual_tol: float = 1e-6,
              max_iter: int = 500, max_wall_time: float = 120.0) -> Solution:
        """Solve with IPOPT (exact Hessian from the kernels, MUMPS). ``tol``: constraint violation,
        ``dual_tol``: IPOPT's overall ``tol``; ``max_wall_time`` [s]: IPOPT stops there with the
        status ``Maximum_WallTime_Exceeded``. Never raises for a failed solve: the status is in the
        Solution. ``ipopt_options`` are passed through (``"ipopt."`` prefix optional)."""
        from ..solver_options import check_solve_arguments
        from .nlp import NlpSolver, SolverOptions

        check_solve_arguments(tol, max_iter, 1.0)
        check_solve_arguments(dual_tol, max_iter, 1.0)
        if not (isinstance(max_wall_time, (int, float)) and not isinstance(max_wall_time, bool)
                and np.isfinite(max_wall_time) and max_wall_time > 0):
            raise ValueError(f"max_wall_time: expected a positive number of seconds, got {max_wall_time!r}")
        if self._X0 is None:
            raise ValueError("no initial guess: call set_initial(...) first")
        sopts = SolverOptions.coerce(ipopt_options)  # an invalid option is an OptionError before the solve
        t_setup = time.perf_counter()
        b = self._get_built()
        # mu_init 1e-3: measured on the end-constrained restoration (N = 48), 30 iterations vs 34 at
        # IPOPT's default 0.1 (adaptive μ: 67)
        defaults = {"ipopt.tol": dual_tol, "ipopt.constr_viol_tol": tol, "ipopt.acceptable_constr_viol_tol": tol,
                    "ipopt.max_iter": int(max_iter), "ipopt.max_wall_time": float(max_wall_time),
                    "ipopt.mu_init": 1e-3}
        okey = repr(sorted(sopts.casadi_options(defaults).items()))
        solver = b["solvers"].get(okey)
        if solver is None:  # one IPOPT instance per structure and options
            extra = {**b["derivs"], "no_nlp_grad": True, "calc_lam_x": False, "calc_lam_p": False,
                     "calc_f": False, "calc_g": False}
            solver = b["solvers"][okey] = NlpSolver("floating_segment", b["nlp"], sopts, defaults=defaults,
                                                    casadi_options=extra)
        setup = time.perf_counter() - t_setup  # the build (when it happened now); NlpSolver adds its creation
        x0 = np.r_[self._X0.ravel(), self._B0]
        pval = self._p()
        out = solver.solve(x0, p=pval, lbx=b["lbx"], ubx=b["ubx"], lbg=b["lbg"], ubg=b["ubg"],
                           cost_scale=self._scale, extra_setup=setup)
        self.last_stats = solver.stats()
        status, x, lam_g, iters, cost = out.status, np.array(out.x), out.lam_g, out.iterations, out.cost
        wall, self.last_cpu_time = out.wall_time, out.cpu_time
        gval = np.array(b["gfun"](x, pval)).ravel()
        viol_vec = np.maximum(np.maximum(b["lbg"] - gval, gval - b["ubg"]), 0.0)
        viol = float(viol_vec.max()) if viol_vec.size else 0.0
        viol = max(viol, float(np.max(np.maximum(np.maximum(b["lbx"] - x, x - b["ubx"]), 0.0))))
        terms = {self.spec.smoothness: cost}
        for name, sl in b["slices"].items():
            key = "dynamics" if name.startswith(("momentum", "base_attitude_dynamics")) else name
            terms[key] = max(terms.get(key, 0.0), float(viol_vec[sl].max()) if sl.stop > sl.start else 0.0)
        kv = knot_values(self._P(x[:self.nP]), self.h)
        xi = np.vstack([_IDENTITY_Q, x[self.nP:self.nP + 4 * self.N].reshape(self.N, 4)])
        success = bool(status.succeeded and np.isfinite(viol) and viol <= max(tol, 1e-9) * 10)
        return Solution(success=success, status=status, iterations=iters, wall_time=wall, cost=cost,
                        max_constraint_violation=viol, terms=terms, t=np.linspace(0.0, self.T, self.N + 1),
                        q=kv["q"], qd=kv["qd"], qdd=kv["qdd"], jerk=kv["jerk"],
                        joint_names=self.robot.joint_names, base_quat=xi,
                        base_position=self._base_positions(kv["q"], xi), setup_time=out.setup_time,
                        cpu_time=out.cpu_time, x=x, lam_g=lam_g, attempts=(out,))

    def _base_positions(self, Q: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """Base position [m] at the knots with the centre of mass fixed at the origin."""
        model, data = self.robot.model, self.robot.model.createData()
        out = []
        for qk, xk in zip(Q, xi):
            c = pin.centerOfMass(model, data, np.r_[np.zeros(6), 1.0, qk])
            R = pin.Quaternion(xk[3], *xk[:3]).normalized().toRotationMatrix()
            out.append(-R @ c)
        return np.array(out)


def _quat_conj(q: np.ndarray) -> np.ndarray:
    return np.array([-q[0], -q[1], -q[2], q[3]])


def _quat_left(a: np.ndarray) -> np.ndarray:
    """Matrix L(a) with ``a ⊗ b = L(a) b`` (quaternions stored x, y, z, w)."""
    ax, ay, az, aw = a
    return np.array([[aw, -az, ay, ax],
                     [az, aw, -ax, ay],
                     [-ay, ax, aw, az],
                     [-ax, -ay, -az, aw]])
