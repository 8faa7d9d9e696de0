"""The B-spline kernel transcription of :class:`~optplan.problem.OptProblem`: every constraint
and cost is a family of per-point kernels mapped over its points, with the exact Jacobian and
Hessian assembled by constant scatters (:class:`~optplan.problem.floating_kernels._LocalAssembly`).

Decision variables ``x``: all ``N + 3`` control points of the joint B-spline (:mod:`.bspline`;
boundary states are constraints like any other), for a floating robot the base attitude at the
knots 1 … N and the base angular velocity at the RK4 half steps (as
:class:`~optplan.problem.floating_segment.FloatingSplineProblem`: zero momentum and RK4 attitude
rows from its kernels), and T when the duration is free. Parameters ``p`` (changed between
solves without a rebuild): the knots' time fractions and quadrature weights, T (fixed duration),
the base's start attitude and centre of mass, the user's parameters and the objective scale.

A kernel's input at knot k is a fixed linear combination of ``[x; p]``: q = (P_k + 4P_{k+1} +
P_{k+2})/6, dq/du = (P_{k+2} − P_k)/2, d²q/du² = P_k − 2P_{k+1} + P_{k+2}; the kernel itself
divides by h = T/N (so a free T needs no other change). The structure (kernels, their points,
linear rows) is kept per robot (:meth:`KernelCache.structure`) with its IPOPT instances: a second
problem of the same structure, or a re-solve after ``set_value``, builds nothing.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from ..geometry.banded import solve_banded_dense
from ..model.robot import RobotModel
from . import kernel_compiler
from .bspline import knot_matrices
from .expressions import PointSymbols, symbols_of
from .floating_kernels import FloatingKernels, _LocalAssembly, momentum_template, spline_basis
from .sparse import SparseMatrix, to_dm

__all__ = ["Family", "SplineCore"]

_ID_Q = np.array([0.0, 0.0, 0.0, 1.0])
#: local kernels whose compiled library was seen in the cache, by (robot digest, cache directory,
#: kernel name) (the libraries are never removed)
_FOUND_LIBS: set[tuple[bytes, str, str]] = set()
#: per smoothness kernel (by name: robot, kind, N and weight): its local quadratic block over P_k … P_k+3
_QUAD_BLOCKS: dict[str, Any] = {}


@dataclass
class Family:
    """One row family (constraint) or cost family: a kernel evaluated at ``points``.

    kind: "knot" (inputs of :func:`~.expressions.point_kernel` at knots), "jerk"/"acceleration"
    (per interval, costs), "velocity" (linear rows on the velocity control points; its points are
    entries ``i·nj + j`` of the (N+2) × nj velocity control points, ``sides`` rows each: one
    two-sided row ``ΔP`` within ``[lower, upper]·h`` with a fixed duration, else two one-sided
    rows ``N ΔP − bound·T``, upper then lower).
    ``lower``/``upper``: bounds per row of one point (constraints); ``labels``: component names."""

    name: str
    kind: str
    fn: ca.Function | None
    points: list[int]
    lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    labels: tuple[str, ...] = ()
    cost: bool = False
    data: Any = None       # kind-specific (velocity: (lower, upper) per joint [rad/s])
    sides: int = 2         # velocity: rows per entry (1: two-sided, fixed duration)

    @property
    def rows_per_point(self) -> int:
        if self.kind == "velocity":
            return self.sides
        if self.kind == "pair":
            return int(self.data["item"].nrow)
        return 1 if self.cost else int(self.lower.size)


class SplineCore:
    """Layout, build and solve of one B-spline problem (see the module docstring)."""

    def __init__(self, robot: RobotModel, N: int, free_time: bool, n_sub: int, npar: int, n_aux: int = 0,
                 n_colp: int = 0):
        self.robot, self.N, self.free_time, self.n_sub = robot, int(N), bool(free_time), int(n_sub)
        self.sym: PointSymbols = symbols_of(robot)
        self.kc = self.sym.kc
        self.fl = robot.is_floating
        nj = self.nj = robot.nj
        self.M = knot_matrices(self.N)
        self.nP = (self.N + 3) * nj
        self.nW = 2 * self.n_sub * self.N + 1 if self.fl else 0
        self.nx = self.nP + (4 * self.N + 3 * self.nW if self.fl else 0) + (1 if self.free_time else 0)
        #: index of the duration T in x (free duration; before the collision planes' offsets), else None
        self.i_T: int | None = self.nx - 1 if self.free_time else None
        self.x_aux = self.nx            # collision plane offsets of moving pairs
        self.nx += int(n_aux)
        N = self.N
        # p = [s (N+1) | qw (N+1) | one | T | xi0 (4) | base0 (4) | com0 (3) | params | scale]
        self.p_s, self.p_qw, self.p_one, self.p_T = 0, N + 1, 2 * N + 2, 2 * N + 3
        self.p_xi0 = 2 * N + 4
        self.p_b0 = self.p_xi0 + (4 if self.fl else 0)
        self.p_c0 = self.p_b0 + (4 if self.fl else 0)
        self.p_par = self.p_c0 + (3 if self.fl else 0)
        self.npar = int(npar)
        self.p_scale = self.p_par + self.npar
        self.p_col = self.p_scale + 1   # collision plane normals and supports
        self.np = self.p_col + int(n_colp)
        self._input_maps: dict[tuple[int, Any], Any] = {}
        self._quad_blocks = _QUAD_BLOCKS

    # ------------------------------------------------------------------ slots in [x; p]
    def slot_P(self, i: int) -> np.ndarray:
        return i * self.nj + np.arange(self.nj)

    def slot_xi(self, k: int) -> np.ndarray:
        if k == 0:
            return self.nx + self.p_xi0 + np.arange(4)
        return self.nP + 4 * (k - 1) + np.arange(4)

    def slot_w(self, c: int) -> np.ndarray:
        return self.nP + 4 * self.N + 3 * c + np.arange(3)

    def slot_T(self) -> int:
        return self.i_T if self.i_T is not None else self.nx + self.p_T

    def duration_of(self, x: np.ndarray, T: float) -> float:
        """The duration [s] of the core variables ``x``: their T when it is free, else ``T``."""
        return float(x[self.i_T]) if self.i_T is not None else float(T)

    def _tail_slots(self, k: int, cost: Any) -> np.ndarray:
        """Slots of the inputs after q, dq/du, d²q/du²: xi, s, T, base0, com0, params[, w]."""
        nx = self.nx
        parts = [self.slot_xi(k)] if self.fl else []
        parts += [np.array([nx + self.p_s + k, self.slot_T()])]
        if self.fl:
            parts += [nx + self.p_b0 + np.arange(4), nx + self.p_c0 + np.arange(3)]
        parts.append(nx + self.p_par + np.arange(self.npar))
        if cost:   # the quadrature weight ("quad") or 1 ("one")
            parts.append(np.array([nx + (self.p_qw + k if cost == "quad" else self.p_one)]))
        return np.concatenate(parts).astype(int)

    # ------------------------------------------------------------------ templates
    def knot_template(self, cost: Any) -> tuple[np.ndarray, int]:
        """Template rows (input, slot, weight) of a knot kernel and its number of slots."""
        nj = self.nj
        t = []
        for j in range(nj):
            t += [(j, j, 1 / 6), (j, nj + j, 4 / 6), (j, 2 * nj + j, 1 / 6)]
            t += [(nj + j, j, -0.5), (nj + j, 2 * nj + j, 0.5)]
            t += [(2 * nj + j, j, 1.0), (2 * nj + j, nj + j, -2.0), (2 * nj + j, 2 * nj + j, 1.0)]
        ntail = self._tail_slots(0, "one" if cost else None).size
        t += [(3 * nj + r, 3 * nj + r, 1.0) for r in range(ntail)]
        return np.array(t, float), 3 * nj + ntail

    def knot_slots(self, k: int, cost: Any) -> np.ndarray:
        return np.concatenate([self.slot_P(k), self.slot_P(k + 1), self.slot_P(k + 2), self._tail_slots(k, cost)])

    def knot_inputs(self, x: np.ndarray, p: np.ndarray, k: int, cost: Any) -> np.ndarray:
        """The numeric kernel input of knot k (what the NLP feeds the kernel)."""
        key = (k, cost)
        W = self._input_maps.get(key)
        if W is None:
            tm, _ = self.knot_template(cost)
            sl = self.knot_slots(k, cost)
            W = self._input_maps[key] = SparseMatrix(tm[:, 2], tm[:, 0].astype(int), sl[tm[:, 1].astype(int)],
                                                     (int(tm[:, 0].max()) + 1, self.nx + self.np))
        return np.asarray(W @ np.r_[x, p]).ravel()

    def interval_template(self, kind: str) -> np.ndarray:
        nj = self.nj
        t: list[tuple[int, int, float]] = []
        if kind == "jerk":
            for j in range(nj):
                t += [(j, a * nj + j, c) for a, c in enumerate((-1.0, 3.0, -3.0, 1.0))]
            t.append((nj, 4 * nj, 1.0))
        else:  # acceleration at the interval's two knots
            for j in range(nj):
                t += [(j, j, 1.0), (j, nj + j, -2.0), (j, 2 * nj + j, 1.0)]
                t += [(nj + j, nj + j, 1.0), (nj + j, 2 * nj + j, -2.0), (nj + j, 3 * nj + j, 1.0)]
            t.append((2 * nj, 4 * nj, 1.0))
        return np.array(t, float)

    def interval_slots(self, k: int) -> np.ndarray:
        return np.concatenate([self.slot_P(k + a) for a in range(4)] + [np.array([self.slot_T()])])

    def smoothness_kernel(self, kind: str, weight: float) -> ca.Function:
        """``weight · ∫_interval ‖j‖² dt`` (z = [ΔP³; T]) or ``‖q̈‖²`` (z = [a_k; a_k+1; T], exact
        for the piecewise-linear q̈), cached per robot."""
        nj, N = self.nj, self.N

        def build(name: str) -> ca.Function:
            if kind == "jerk":
                d, T = ca.SX.sym("d3", nj), ca.SX.sym("T")
                return ca.Function(name, [ca.vertcat(d, T)], [weight * ca.sumsqr(d) * N**5 / T**5])
            a0, a1, T = ca.SX.sym("a0", nj), ca.SX.sym("a1", nj), ca.SX.sym("T")
            val = ca.sumsqr(a0) + ca.dot(a0, a1) + ca.sumsqr(a1)
            return ca.Function(name, [ca.vertcat(a0, a1, T)], [weight * val / 3 * N**3 / T**3])

        return self.kc._get(("spline_smooth", kind, N, float(weight)), build)

    # ------------------------------------------------------------------ kernels
    def kernel_set(self, fn: ca.Function, compiled: bool | str) -> tuple[ca.Function, ca.Function, ca.Function]:
        """``(f, ∂f/∂z, triu ∂²(λᵀf)/∂z²)`` of a local kernel: from C when an earlier run compiled
        them (``compiled`` "auto"/True), else symbolic (and queued for a background compile)."""
        kc = self.kc
        if compiled is not False and kc._dir is not None:   # compiled earlier: the symbolic forms are not loaded
            name = kc._name(("local", fn.name()))
            libs = [kc._compiled_by_name(n, "-O1") for n in (name, kc._name(("ljac", name)),
                                                               kc._name(("lhess_triu", name)))]
            if all(lib is not None for lib in libs):
                return libs[0], libs[1], libs[2]  # type: ignore[return-value]  # checked just above
        f = kc._get(("local", fn.name()), lambda name: ca.Function(name, [fn.sx_in(0)], [fn(fn.sx_in(0))]))
        jfn, hfn = kc.local_derivatives(f)
        fns = (f, jfn, hfn)
        if compiled is False or kc._dir is None:
            return fns
        libs = [kc._compiled_by_name(g.name(), "-O1") for g in fns]
        if all(lib is not None for lib in libs):
            return libs[0], libs[1], libs[2]  # type: ignore[return-value]  # checked just above
        if compiled is True:
            got = [kc.compiled(g) for g in fns]
            if all(g is not None for g in got):
                return got[0], got[1], got[2]  # type: ignore[return-value]
        for g in fns:
            kernel_compiler.queue(kc._dir, g.name(), "-O1")
        return fns

    # ------------------------------------------------------------------ build
    def structure(self, families: list[Family], P_bounded: bool, compiled: bool | str) -> Any:
        """The symbolic NLP of these families (memory cache per robot and structure)."""
        state: Any = compiled
        if compiled == "auto" and self.kc._dir is not None:   # which kernels an earlier run compiled
            state = tuple(self._compiled_exists(f.fn.name()) for f in families if f.fn is not None)
        key = ("optproblem_spline", self.kc._digest, self.N, self.n_sub, self.free_time, self.npar, P_bounded,
               state, self.nx, self.np, tuple((f.name, f.kind, None if f.fn is None else f.fn.name(), tuple(f.points), f.cost,
                                None if f.kind != "velocity" else np.asarray(f.data, float).tobytes(),
                                f.data["item"].static if f.kind == "pair" else None) for f in families))
        st = self.kc.structure(key, lambda: self._build(families, compiled))
        kernel_compiler.launch()
        return st

    def _build(self, families: list[Family], compiled: bool | str) -> dict[str, Any]:
        t0 = time.perf_counter()
        nx, npp, N, nj = self.nx, self.np, self.N, self.nj
        x, p = ca.MX.sym("x", nx), ca.MX.sym("p", npp)
        xp = ca.vertcat(x, p)
        asm, casm = _LocalAssembly(nx, npp), _LocalAssembly(nx, npp)
        slices: dict[str, slice] = {}
        if self.fl:
            self._dynamics(asm, xp, compiled)
        quad = [f for f in families if self.is_quadratic(f)]
        for fam in families:
            if self.is_quadratic(fam):   # below: one constant quadratic form
                continue
            target = casm if fam.cost else asm
            if fam.kind == "velocity":
                lo, hi = fam.data
                rows, cols, vals = [], [], []
                r = 0
                for e in fam.points:
                    i, j = divmod(int(e), nj)
                    if fam.sides == 1:   # ΔP within [lo, hi]·h (h fixed: row_bounds); a row of unit
                        # coefficients, as the closed-chain rows' scale (N ΔP took IPOPT 1.4-2.5× the
                        # iterations on some pipeline segments, measured 2026-11-28)
                        rows += [r, r]
                        cols += [int(self.slot_P(i + 1)[j]), int(self.slot_P(i)[j])]
                        vals += [1.0, -1.0]
                        r += 1
                        continue
                    for bound in (hi[j], lo[j]):   # N ΔP − bound·T ≶ 0
                        rows += [r, r, r]
                        cols += [int(self.slot_P(i + 1)[j]), int(self.slot_P(i)[j]), self.slot_T()]
                        vals += [float(N), -float(N), -float(bound)]
                        r += 1
                if r == 0:   # no entry active (rows added after a solve if needed)
                    asm.slices[fam.name] = slice(asm.ng, asm.ng)
                    continue
                A = SparseMatrix(vals, rows, cols, (r, nx + npp))
                if fam.sides == 1:
                    asm.linear(fam.name, xp, A, np.full(r, -np.inf), np.full(r, np.inf))
                else:
                    asm.linear(fam.name, xp, A, np.tile([-np.inf, 0.0], r // 2), np.tile([0.0, np.inf], r // 2))
                continue
            assert fam.fn is not None
            f, jf, hf = self.kernel_set(fam.fn, compiled)
            if fam.kind == "knot":
                tm, _ = self.knot_template(fam.cost)
                slots = np.array([self.knot_slots(k, fam.data if fam.cost else None) for k in fam.points])
            elif fam.kind == "pair":
                tm, slots = self._pair_slots(fam)
            else:
                tm = self.interval_template(fam.kind)
                slots = np.array([self.interval_slots(k) for k in fam.points])
            m = f.size1_out(0)
            K = len(fam.points)
            lo = 0.0 if fam.cost or fam.kind == "pair" else np.tile(fam.lower, K)
            hi = 0.0 if fam.cost or fam.kind == "pair" else np.tile(fam.upper, K)
            if m == 0:
                continue
            target.family(fam.name, f, jf, hf, tm, slots, xp, lo, hi)
        lam_f = ca.MX.sym("lam_f")
        lam_g = ca.MX.sym("lam_g", asm.ng)
        zero = SparseMatrix.zeros((nx, nx))
        sc = p[self.p_scale]
        # quadratic costs xᵀQx · T^-e: value, gradient and a constant Hessian pattern (its first
        # exponent's group rides on the rows' Hessian scatter, weighted by lam_f · sc · T^-e)
        qvals, qgrad, qhess = [], ca.MX.zeros(nx, 1), []
        groups: dict[int, Any] = {}
        for fam in quad:
            Qf, e = self.quadratic_form(fam)
            Ti = xp[self.slot_T()] ** (-e)
            Qd = to_dm(Qf)
            Qx = ca.mtimes(Qd, x)
            qvals.append(Ti * ca.dot(x, Qx))
            qgrad = qgrad + 2 * Ti * Qx
            groups[e] = Qf if e not in groups else groups[e] + Qf
        Hq_first, coef_first = zero, lam_f
        for i, (e, Qf) in enumerate(groups.items()):
            Hu = 2 * Qf.triu()
            if i == 0 and asm.ng:
                Hq_first, coef_first = Hu, lam_f * sc * xp[self.slot_T()] ** (-e)
            else:
                qhess.append(lam_f * sc * xp[self.slot_T()] ** (-e) * to_dm(Hu))
        G, Jg, Hg = _finish(asm, nx, coef_first, lam_g, Hq_first)
        nc = casm.ng
        C, Jc, Hc = _finish(casm, nx, lam_f, ca.repmat(lam_f * sc, nc, 1), zero)
        fobj = sc * (ca.sum1(C) if nc else 0) + (sc * ca.sum1(ca.vertcat(*qvals)) if qvals else 0)
        fobj = ca.MX(fobj) if not isinstance(fobj, ca.MX) else fobj
        # dense: IPOPT reads every entry of the gradient (a structural zero would be stale memory)
        grad = ca.densify((sc * ca.sum1(Jc).T if nc else ca.MX.zeros(nx, 1)) + (sc * qgrad if quad else 0))
        H = Hg + Hc
        for hq in qhess:
            H = H + hq
        # the cost values per family (reports): the kernel families' rows, then one per quadratic family
        cslices = dict(casm.slices)
        for i, fam in enumerate(quad):
            cslices[fam.name] = slice(nc + i, nc + i + 1)
        C = ca.vertcat(C, *qvals)
        derivs = {"grad_f": ca.Function("grad_f", [x, p], [fobj, grad], ["x", "p"], ["f", "grad_f_x"]),
                  "jac_g": ca.Function("jac_g", [x, p], [G, Jg], ["x", "p"], ["g", "jac_g_x"]),
                  "hess_lag": ca.Function("hess_lag", [x, p, lam_f, lam_g], [H],
                                          ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])}
        slices.update(asm.slices)
        lbg = np.asarray(asm.lbg, float) if asm.ng else np.zeros(0)
        ubg = np.asarray(asm.ubg, float) if asm.ng else np.zeros(0)
        return {"nlp": {"x": x, "p": p, "f": fobj, "g": G}, "derivs": derivs, "lbg": lbg, "ubg": ubg,
                "slices": slices, "cslices": cslices, "gfun": ca.Function("g", [x, p], [G]),
                "cfun": ca.Function("c", [x, p], [C]), "ffun": ca.Function("f", [x, p], [fobj]),
                "solvers": {}, "build_time": time.perf_counter() - t0}

    def is_quadratic(self, fam: Family) -> bool:
        """Whether cost family ``fam`` is a quadratic form of the control points (``Smoothness``
        jerk / acceleration with a fixed duration): it then enters the NLP as ``xᵀQx · T^-e`` with
        its exact, constant Hessian pattern instead of a kernel family (:meth:`quadratic_form`)."""
        return fam.cost and fam.kind in ("jerk", "acceleration") and not self.free_time and fam.fn is not None

    def quadratic_form(self, fam: Family) -> tuple[SparseMatrix, int]:
        """``(Q, e)`` with ``Σ_k fam.fn(z_k) = xᵀQx · T^-e`` (Q: nx × nx, symmetric): the kernel's
        constant Hessian in its control-point inputs (evaluated at T = 1), scattered by the
        interval template over the family's intervals. Interval k's inputs are the control points
        P_k … P_k+3, so one local block ``L = Wᵀ H W`` (4·nj × 4·nj, cached per kernel) is added at
        offset k·nj for every interval — one vectorised scatter."""
        assert fam.fn is not None
        e = 5 if fam.kind == "jerk" else 3
        nj = self.nj
        L = self._quad_blocks.get(fam.fn.name())
        if L is None:
            tm = self.interval_template(fam.kind)
            z = ca.SX.sym("z", fam.fn.size1_in(0))
            nz = z.numel() - 1   # the last input is T
            H0 = np.array(ca.Function("h", [z], [ca.hessian(fam.fn(z), z)[0]])(np.r_[np.zeros(nz), 1.0]))[:nz, :nz]
            ti, ts, tw = tm[:, 0].astype(int), tm[:, 1].astype(int), tm[:, 2]
            keep = ti < nz
            ti, ts, tw = ti[keep], ts[keep], tw[keep]
            assert ts.max() < 4 * nj   # the control-point inputs: slots of P_k … P_k+3 (interval_slots)
            W = np.zeros((nz, 4 * nj))
            np.add.at(W, (ti, ts), tw)
            L = 0.5 * W.T @ H0 @ W
            L[np.abs(L) < 1e-14 * max(1.0, float(np.abs(L).max()))] = 0.0
            L = self._quad_blocks[fam.fn.name()] = SparseMatrix.from_dense(L)
        k = np.asarray(fam.points, int)
        off = (k * nj)[:, None]
        Q = SparseMatrix(np.tile(L.data, k.size), (off + L.row).ravel(), (off + L.col).ravel(), (self.nx, self.nx))
        return Q.eliminate_zeros(), e

    def _compiled_exists(self, name: str) -> bool:
        """Whether the compiled library of local kernel ``name`` is in the cache (remembered once
        found)."""
        assert self.kc._dir is not None
        if (self.kc._digest, str(self.kc._dir), name) in _FOUND_LIBS:   # a re-solve: no name hashed, no path made
            return True
        lib = str(self.kc._dir.joinpath(f"{self.kc._name(('local', name))}-O1.so"))
        ok = os.path.exists(lib)
        if ok:
            _FOUND_LIBS.add((self.kc._digest, str(self.kc._dir), name))
        return ok

    def _pair_slots(self, fam: Family) -> tuple[np.ndarray, np.ndarray]:
        """Template and slots of a collision pair's kernel ``f([q; n; s])`` at its knots."""
        if fam.data.get("world"):   # a floating robot's plane fixed in the world
            from .floating_collision import world_pair_slots

            return world_pair_slots(self, fam)
        nj, nx = self.nj, self.nx
        it, po, ao = fam.data["item"], fam.data["p_off"], fam.data["aux_off"]
        K = len(fam.points)
        tm = [(j, a * nj + j, w) for j in range(nj) for a, w in enumerate((1 / 6, 4 / 6, 1 / 6))]
        tm += [(nj + c, 3 * nj + c, 1.0) for c in range(4)]
        rows = []
        for t, k in enumerate(fam.points):
            n = nx + self.p_col + po + 3 * t + np.arange(3)
            s = nx + self.p_col + po + 3 * K + t if it.static else self.x_aux + ao + t
            rows.append(np.concatenate([self.slot_P(k), self.slot_P(k + 1), self.slot_P(k + 2), n, [s]]))
        return np.array(tm, float), np.array(rows, int)

    def _dynamics(self, asm: _LocalAssembly, xp: ca.MX, compiled: bool | str) -> None:
        """Zero momentum at every twist point and the RK4 attitude steps (floating robots), from
        :class:`FloatingKernels` (as :class:`FloatingSplineProblem`)."""
        kc = self.kc
        assert isinstance(kc, FloatingKernels)
        N, nj, m = self.N, self.nj, 2 * self.n_sub
        fmom, jm, hm = kc.kernel_set("momentum", compiled=compiled)
        for i in range(m):
            ks = list(range(N)) + ([N - 1] if i == 0 else [])
            bb = [spline_basis(0.0)] * N + [spline_basis(1.0)] if i == 0 else [spline_basis(i / m)] * N
            tmpl, slots = [], []
            for t, k in enumerate(ks):
                bk, dbk = bb[t]
                slots.append(np.concatenate([self.slot_P(k + a) for a in range(4)] +
                                            [self.slot_w(m * N if (i == 0 and t == N) else m * k + i)]))
                if t == 0 or (i == 0 and t == N):
                    tmpl.append(momentum_template(bk, dbk, nj))
            if i == 0:
                asm.family("momentum@knots", fmom, jm, hm, tmpl[0], np.array(slots[:N]), xp, 0.0, 0.0)
                asm.family("momentum@end", fmom, jm, hm, tmpl[1], np.array(slots[N:]), xp, 0.0, 0.0)
            else:
                asm.family(f"momentum@{i}/{m}", fmom, jm, hm, tmpl[0], np.array(slots), xp, 0.0, 0.0)
        fat, ja, ha = kc.kernel_set("attitude", self.n_sub, compiled=compiled)
        nin = fat.size1_in(0)
        slots_a = np.array([np.concatenate([self.slot_xi(k), self.slot_xi(k + 1)] +
                                           [self.slot_w(m * k + c) for c in range(m + 1)]) for k in range(N)])
        asm.family("base_attitude_dynamics", fat, ja, ha, np.array([(i, i, 1.0) for i in range(nin)]), slots_a,
                   xp, 0.0, 0.0)

    def row_bounds(self, st: dict[str, Any], families: list[Family], T: float | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
        """``(lbg, ubg)`` of these families' rows (the structure keeps only their shape); ``T``
        [s]: the fixed duration (the bounds of two-sided velocity rows)."""
        lbg, ubg = np.array(st["lbg"], float), np.array(st["ubg"], float)
        for fam in families:
            sl = st["slices"].get(fam.name)
            if sl is None or fam.cost:
                continue
            if fam.kind == "velocity":
                if fam.sides == 1 and sl.stop > sl.start:
                    if T is None:
                        raise ValueError(f"row_bounds: the velocity rows of {fam.name!r} need the duration T")
                    j = np.asarray(fam.points, int) % self.nj
                    lo, hi = np.asarray(fam.data, float)
                    lbg[sl], ubg[sl] = lo[j] * (T / self.N), hi[j] * (T / self.N)
                continue
            if fam.kind == "pair":
                it = fam.data["item"]
                m = it.margins if it.static else it.margins / 2
                lbg[sl], ubg[sl] = np.repeat(m, it.nrow), np.inf
                continue
            K = len(fam.points)
            lbg[sl], ubg[sl] = np.tile(fam.lower, K), np.tile(fam.upper, K)
        return lbg, ubg

    # ------------------------------------------------------------------ numeric helpers
    def fit(self, Q: np.ndarray, V0: np.ndarray, VN: np.ndarray, h: float) -> np.ndarray:
        """Control points ((N+3) × nj) with knot values Q ((N+1) × nj) and end velocities V0, VN."""
        M = self.M
        # the end velocities' rows first and last: a banded matrix (three entries per row), solved as one
        # (numpy alone: a dense solve of N = 160 took 0.5 s under a loaded BLAS; scipy.sparse.linalg
        # with scipy.linalg costs ~0.1 s of import)
        A = np.vstack([M["qd"][[0]] / h, M["q"], M["qd"][[self.N]] / h])
        X = solve_banded_dense(A, np.vstack([V0, Q, VN]))
        return np.asarray(X, float).reshape(self.N + 3, -1)

    def control_points(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(x[:self.nP], float).reshape(self.N + 3, self.nj)

    def integrate_base(self, P: np.ndarray) -> np.ndarray:
        """``[ξ_1 … ξ_N; ω'_0 …]`` of the joint B-spline P with zero momentum (the NLP's kernels)."""
        kc = self.kc
        assert isinstance(kc, FloatingKernels)
        N, nj, m = self.N, self.nj, 2 * self.n_sub
        fn = kc._fns.get(("fb_momentum_linear",))
        if fn is None:
            f = kc.momentum()
            z = ca.SX.sym("z", f.size1_in(0))
            J = ca.jacobian(f(z), z)
            fn = kc._fns[("fb_momentum_linear",)] = ca.Function("mom_lin", [z], [J[:, 2 * nj:], f(z)])
        # every twist point at once: q, dq/du from the basis, then one mapped call and a batched solve
        kk, ii = np.divmod(np.arange(self.nW), m)
        kk, ii = np.where(kk == N, N - 1, kk), np.where(kk == N, m, ii)
        B = np.array([np.concatenate(spline_basis(j / m)) for j in range(m + 1)])[ii]   # nW × 8
        Pk = P[kk[:, None] + np.arange(4)]                                               # nW × 4 × nj
        Z = np.hstack([np.einsum("ca,caj->cj", B[:, :4], Pk), np.einsum("ca,caj->cj", B[:, 4:], Pk),
                       np.zeros((self.nW, 3))])
        Aw, r = fn.map(self.nW)(Z.T)
        Aw = np.asarray(Aw).reshape(3, 3, self.nW, order="F").transpose(2, 0, 1)        # nW × 3 × 3
        W = -np.linalg.solve(Aw, np.asarray(r).T[:, :, None])[:, :, 0]
        xi = _ID_Q.copy()
        out = []
        step = kc.attitude_step(self.n_sub)
        for k in range(N):
            xi = -np.asarray(step(np.r_[xi, np.zeros(4), W[m * k:m * k + m + 1].ravel()])).ravel()
            out.append(xi)
        return np.r_[np.concatenate(out), W.ravel()]

    def knot_xi(self, x: np.ndarray) -> np.ndarray:
        """Base attitude relative to the start at the knots ((N+1) × 4)."""
        if not self.fl:
            return np.zeros((self.N + 1, 0))
        return np.vstack([_ID_Q, np.asarray(x[self.nP:self.nP + 4 * self.N]).reshape(self.N, 4)])


def _finish(asm: _LocalAssembly, nx: int, lam_f: ca.MX, lam_g: Any, Hf: Any) -> tuple[ca.MX, ca.MX, ca.MX]:
    """:meth:`_LocalAssembly.finish`, also for an assembly without rows."""
    if asm.ng == 0:
        asm.lbg, asm.ubg = np.zeros(0), np.zeros(0)
        return ca.MX(0, 1), ca.MX(0, nx), ca.MX(nx, nx)
    return asm.finish(lam_f, lam_g, Hf)
