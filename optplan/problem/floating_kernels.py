"""Kernels and row assembly of the free-floating B-spline transcription, shared by the modelling
core (:mod:`.spline_core`) and :class:`~optplan.problem.floating_segment.FloatingSplineProblem`:
the zero-momentum, RK4 attitude and closed-chain kernels of one robot (:class:`FloatingKernels`,
cached in memory and on disk like :class:`~optplan.problem.kernels.KernelCache`) and
:class:`_LocalAssembly`, which scatters mapped kernel derivatives into the exact Jacobian and
Hessian of rows whose inputs are fixed linear combinations of the decision variables. The
transcription itself is described in :mod:`.floating_segment`."""
from __future__ import annotations

import logging
import weakref
from collections.abc import Callable
from typing import Any, cast

import casadi as ca
import numpy as np
import numpy.typing as npt

from ..constraints.closed_chain import relative_pose_residual
from ..model.robot import RobotModel
from .assembly import RowAssembly, nonzeros, scatter
from .frame_terms import ClosedChain
from .kernels import KernelCache, load_library
from .sparse import SparseMatrix, as_sparse, to_dm
from .transcription import quat_mul

__all__ = ["FloatingKernels", "momentum_template", "spline_basis"]
log = logging.getLogger(__name__)

#: a kernel's cache key and its builder ``build(name) -> Function`` (:meth:`KernelCache._get`)
_KernelSpec = tuple[tuple[Any, ...], Callable[[str], ca.Function]]


def momentum_template(bk: np.ndarray, dbk: np.ndarray, nj: int) -> np.ndarray:
    """Scatter template ``(kernel input, local slot, weight)`` rows of a momentum kernel at one
    point: q and dq/du from the 4 control points by the basis values ``bk`` and derivatives
    ``dbk``, then the 3 slots of the quadrature weights passed through."""
    tm = []
    for a in range(4):
        for j in range(nj):
            if bk[a] != 0:
                tm.append((j, a * nj + j, bk[a]))
            if dbk[a] != 0:
                tm.append((nj + j, a * nj + j, dbk[a]))
    tm += [(2 * nj + c, 4 * nj + c, 1.0) for c in range(3)]
    return np.array(tm, float)


def spline_basis(u: float) -> tuple[np.ndarray, np.ndarray]:
    """Weights of ``P_k … P_{k+3}`` in ``q(t_k + u h)`` and in ``dq/du`` (uniform cubic B-spline)."""
    u = float(u)
    b = np.array([(1 - u) ** 3, 3 * u**3 - 6 * u**2 + 4, -3 * u**3 + 3 * u**2 + 3 * u + 1, u**3]) / 6
    db = np.array([-(1 - u) ** 2, 3 * u**2 - 4 * u, -3 * u**2 + 2 * u + 1, u**2]) / 2
    return b, db


# --------------------------------------------------------------------------- kernels
class FloatingKernels(KernelCache):
    """SX kernels of one free-floating robot, built once and shared (memory and disk cache of
    :class:`KernelCache`, the same key scheme). Every kernel has the signature ``f(z) -> rows``
    with ``z`` its local input vector; :meth:`local_derivatives` gives ``∂f/∂z`` and
    ``∂²(λᵀf)/∂z²``. The kinematics are those of the base frame (base pose identity)."""

    _per_robot: weakref.WeakKeyDictionary[RobotModel, KernelCache] = weakref.WeakKeyDictionary()
    _by_digest: weakref.WeakValueDictionary[bytes, KernelCache] = weakref.WeakValueDictionary()

    floating_base = True
    _digest_tag = b"floating-v1"

    #: how many NLP structures (:meth:`~optplan.problem.kernels.KernelCache.structure`) stay in
    #: memory [count]. A floating carry's NLP has its collision rows' pairs and knots in its shape,
    #: so one trial's structures are not met again by the next; each holds its IPOPT instances and
    #: compiled maps (~10-35 MB measured on ``floating_truss``): the fixed base's 32 let a run of
    #: trials grow by that much per trial. 4 keeps a problem's re-solves and its refinement.
    max_structures = 4

    def _configuration(self, q: ca.SX) -> ca.SX:
        return ca.vertcat(ca.DM([0, 0, 0, 0, 0, 0, 1.0]), q)  # base frame: the base pose is the identity

    def momentum(self) -> ca.Function:
        """``f([q; q'; ω']) -> A_ω(q) ω' + A_m(q) q'`` (3 rows): the angular momentum about the
        centre of mass [base frame, per unit of normalised time] with zero base linear velocity."""
        return self._get(*self._momentum_spec())

    def _momentum_spec(self) -> _KernelSpec:
        def build(name: str) -> ca.Function:
            nj = self.robot.nj
            qd, w = ca.SX.sym("qd", nj), ca.SX.sym("w", 3)
            qf = ca.vertcat(ca.DM([0, 0, 0, 0, 0, 0, 1.0]), self._q)
            h = self.sym.momentum(qf, ca.vertcat(ca.DM.zeros(3), w, qd), self._X)
            G = self.sym.center_of_mass(qf, self._X)
            return ca.Function(name, [ca.vertcat(self._q, qd, w)], [h[3:] - ca.cross(G, h[:3])])

        return ("fb_momentum",), build

    def attitude_step(self, n_sub: int) -> ca.Function:
        """``f([ξ_a; ξ_b; ω'_0 … ω'_{2 n_sub}]) -> ξ_b − RK4(ξ_a)`` (4 rows): ``n_sub`` RK4 steps of
        ``ξ' = ½ ξ ⊗ [ω'; 0]`` over one interval (u from 0 to 1), renormalised."""
        return self._get(*self._attitude_spec(n_sub))

    def _attitude_spec(self, n_sub: int) -> _KernelSpec:
        n_sub = int(n_sub)

        def build(name: str) -> ca.Function:
            qa, qb = ca.SX.sym("xi_a", 4), ca.SX.sym("xi_b", 4)
            W = ca.SX.sym("w", 3, 2 * n_sub + 1)
            hs = 1.0 / n_sub

            def f(x: ca.SX, w: ca.SX) -> ca.SX:
                return 0.5 * quat_mul(x, ca.vertcat(w, 0))

            x = qa
            for s in range(n_sub):
                w0, wm, w1 = W[:, 2 * s], W[:, 2 * s + 1], W[:, 2 * s + 2]
                k1 = f(x, w0)
                k2 = f(x + hs / 2 * k1, wm)
                k3 = f(x + hs / 2 * k2, wm)
                k4 = f(x + hs * k3, w1)
                x = x + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
                x = x / ca.norm_2(x)
            return ca.Function(name, [ca.vertcat(qa, qb, ca.vec(W))], [qb - x])

        return ("fb_attitude", n_sub), build

    def closed_chain(self, cc: ClosedChain) -> ca.Function:
        """``f(q) -> [pose residual (6); trace (1)]`` of the hands' relative pose (base frame)."""
        return self._get(*self._closed_chain_spec(cc))

    def _closed_chain_spec(self, cc: ClosedChain) -> _KernelSpec:
        rel = cc.relative

        def build(name: str) -> ca.Function:
            Ra, pa = self.frame(self.robot.arm(cc.arm_a).ee_frame_id)
            Rb, pb = self.frame(self.robot.arm(cc.arm_b).ee_frame_id)
            r, tr = relative_pose_residual(Ra, pa, Rb, pb, rel)
            return ca.Function(name, [self._q], [ca.vertcat(r, tr)])

        # a chain without its relative pose fails here (AttributeError), as it always did
        return ("fb_cc", cc.arm_a, cc.arm_b,
                np.asarray(rel.homogeneous).round(15).tobytes()), build  # type: ignore[union-attr]

    def _name(self, key: tuple[Any, ...]) -> str:
        """The name :meth:`KernelCache._get` gives the kernel of ``key``."""
        import hashlib

        return f"{key[0]}_{hashlib.sha1(self._digest + repr(key).encode()).hexdigest()[:16]}"

    def kernel_set(self, kind: str, *args: Any, compiled: bool | str = False,
                   opt: str = "-O1") -> tuple[ca.Function, ...]:
        """``(f, ∂f/∂z, ∂²(λᵀf)/∂z²)`` of kernel ``kind`` ("momentum", "attitude" (n_sub),
        "closed_chain" (cc)); ``compiled``: True — from C (:meth:`KernelCache.compiled`; compiled
        now if missing), loaded straight from the libraries when they exist, without reading or
        differentiating the symbolic kernels; "auto" — from C when the libraries exist, else the
        symbolic kernels (nothing is compiled); False — the symbolic kernels."""
        specs: dict[str, Callable[..., _KernelSpec]] = {
            "momentum": self._momentum_spec, "attitude": self._attitude_spec,
            "closed_chain": self._closed_chain_spec}
        key, build = specs[kind](*args)
        if compiled not in (True, False, "auto"):
            raise ValueError(f"compiled: expected True, False or 'auto', got {compiled!r}")
        if compiled and self._dir is not None:
            base = self._name(key)
            names = [base, self._name(("ljac", base)), self._name(("lhess_triu", base))]
            libs = [self._dir / f"{n}{opt}.so" for n in names]
            if all(lib.exists() for lib in libs):
                out = []
                for n, lib in zip(names, libs):
                    k = ("compiled", n, opt)
                    if k not in self._fns:
                        ext = load_library(n, lib)   # None: damaged, quarantined (rebuilt below)
                        if ext is None:
                            break
                        self._fns[k] = ext
                    out.append(self._fns[k])
                else:
                    return tuple(out)
        f = self._get(key, build)
        fns = (f, *self.local_derivatives(f))
        if compiled is True:
            got = tuple(self.compiled(g, opt) for g in fns)
            if all(g is not None and g is not o for g, o in zip(got, fns)):
                return cast("tuple[ca.Function, ...]", got)  # every entry compiled (checked above)
        return fns


# --------------------------------------------------------------------------- assembly
class _LocalAssembly(RowAssembly):
    """Rows of the NLP from kernels whose inputs are fixed linear combinations of the decision
    variables ``x`` (nx) and parameters ``p``: input ``i`` of instance ``t`` is
    ``Σ w · xp[slot[t, s]]`` over the template entries ``(i, s, w)`` of its family (``xp = [x; p]``;
    a slot ≥ nx is a parameter, −1 is zero). Exact Jacobian ``Wᵀ``-weighted and Hessian
    ``Wᵀ H W`` as constant sparse scatters of the mapped kernel derivatives."""

    def __init__(self, nx: int, np_: int):
        super().__init__()
        self.nx, self.np = nx, np_
        # per family: (Hessian kernel, K, kernel inputs Z, first row, rows per instance, template, slots)
        self._fams: list[tuple[ca.Function, int, ca.MX, int, int, np.ndarray, np.ndarray]] = []

    def linear(self, name: str, xp: ca.MX, A: Any, lo: npt.ArrayLike, hi: npt.ArrayLike) -> None:
        """Rows ``A @ [x; p]`` (A: rows × (nx + np), dense or sparse)."""
        A = as_sparse(A)
        r0 = self._rows(name, ca.mtimes(to_dm(A), xp), lo, hi)
        Ax = A.columns(self.nx)
        self.jt.append(np.array([r0 + Ax.row, Ax.col, np.full(Ax.nnz, -1), Ax.data], float))

    def family(self, name: str, fn: ca.Function, jfn: ca.Function, hfn: ca.Function, template: np.ndarray,
               slots: np.ndarray, xp: ca.MX, lo: npt.ArrayLike, hi: npt.ArrayLike) -> None:
        """``template``: (n_entries, 3) rows ``(input i, slot s, weight)``; ``slots``: (K, n_slots)
        global indices into ``[x; p]`` (−1: zero)."""
        K = slots.shape[0]
        nz, m = fn.size1_in(0), fn.size1_out(0)
        ti, ts, tw = template[:, 0].astype(int), template[:, 1].astype(int), template[:, 2]
        # kernel inputs Z (nz × K) = M @ xp, only the inputs the kernel depends on (the structural
        # columns of its Jacobian; the others stay zero): a closed chain reads q, not q̇, q̈ or the
        # time — a third of the entries of M, which every callback evaluates
        jr, ji = (np.asarray(v) for v in jfn.sparsity_out(0).get_triplet())
        used = np.isin(ti, ji)
        g = slots[:, ts]  # K × n_entries
        rows = (np.arange(K)[:, None] * nz + ti[None, :])
        ok = (g >= 0) & used[None, :]
        M = SparseMatrix(np.broadcast_to(tw, g.shape)[ok], rows[ok], g[ok], (K * nz, self.nx + self.np))
        Z = ca.reshape(ca.mtimes(to_dm(M), xp), nz, K)
        r0 = self._rows(name, ca.vec(fn.map(K)(Z)), lo, hi)
        # Jacobian: kernel entry (r, i) → (r0 + t m + r, x-slot of entry (i, s), w)
        e = len(jr)
        self.jsrc.append(nonzeros(jfn.map(K)(Z)))
        pe, pt = np.nonzero(ji[:, None] == ti[None, :])  # pairs (kernel entry, template entry)
        col = slots[:, ts[pt]]  # K × n_pairs
        t = np.broadcast_to(np.arange(K)[:, None], col.shape)
        ok = (col >= 0) & (col < self.nx)
        self.jt.append(np.array([(r0 + t * m + jr[pe])[ok], col[ok], (self.j_off + t * e + pe)[ok],
                                 np.broadcast_to(tw[pt], col.shape)[ok]], float))
        self.j_off += K * e
        self._fams.append((hfn, K, Z, r0, m, template, slots))

    def finish(self, lam_f: ca.MX, lam_g: ca.MX, Hf: Any) -> tuple[ca.MX, ca.MX, ca.MX]:
        """``(g, ∂g/∂x, triu ∇²L)``; ``Hf``: the objective's constant Hessian (nx × nx, sparse)."""
        nx = self.nx
        G = ca.vertcat(*self.g)
        self.lbg, self.ubg = np.concatenate(self.lbg), np.concatenate(self.ubg)
        T = np.hstack(self.jt)
        src = ca.vertcat(*self.jsrc, ca.MX(1.0))
        srcidx = np.where(T[2] < 0, self.j_off, T[2]).astype(int)
        Jg = scatter(self.ng, nx, T[0].astype(int), T[1].astype(int), srcidx, T[3], src, self.j_off + 1)
        hs, blocks, off = [], [], 0
        for hfn, K, Z, r0, m, template, slots in self._fams:
            L = ca.reshape(lam_g[r0:r0 + m * K], m, K)
            hs.append(nonzeros(hfn.map(K)(Z, L)))
            hi, hj = (np.asarray(v) for v in hfn.sparsity_out(0).get_triplet())
            e = len(hi)
            ti, ts, tw = template[:, 0].astype(int), template[:, 1].astype(int), template[:, 2]
            pe, pa, pb = _entry_pairs(hi, hj, ti)
            # the kernel gives its upper triangle: an off-diagonal entry (i < j) stands for (i, j) and
            # (j, i), i.e. global (min, max) of its two variables — twice on the diagonal
            va, vb = slots[:, ts[pa]], slots[:, ts[pb]]
            ca_, cb_ = np.minimum(va, vb), np.maximum(va, vb)
            offd = np.broadcast_to(hi[pe] != hj[pe], va.shape)
            t = np.broadcast_to(np.arange(K)[:, None], va.shape)
            ok = (va >= 0) & (va < nx) & (vb >= 0) & (vb < nx) & (offd | (va <= vb))
            w = np.broadcast_to(tw[pa] * tw[pb], va.shape) * np.where(offd & (va == vb), 2.0, 1.0)
            blocks.append(np.array([ca_[ok], cb_[ok], (off + t * e + pe)[ok], w[ok]], float))
            off += K * e
        Hu = as_sparse(Hf).triu()
        blocks.append(np.array([Hu.row, Hu.col, np.full(Hu.nnz, off), Hu.data], float))
        T = np.hstack(blocks)
        Hl = scatter(nx, nx, T[0].astype(int), T[1].astype(int), T[2].astype(int), T[3],
                      ca.vertcat(*hs, lam_f), off + 1)
        return G, Jg, Hl


def _entry_pairs(hi: np.ndarray, hj: np.ndarray, ti: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For kernel-derivative entries ``(hi[e], hj[e])`` and template inputs ``ti``: every triple
    ``(e, a, b)`` with ``ti[a] == hi[e]`` and ``ti[b] == hj[e]`` (vectorised)."""
    hi, hj = np.asarray(hi, int), np.asarray(hj, int)   # a linear kernel's Hessian has no entries
    order = np.argsort(ti, kind="stable")
    n_in = int(max(ti.max(), hi.max(initial=0), hj.max(initial=0))) + 1
    start = np.searchsorted(ti[order], np.arange(n_in), side="left")
    stop = np.searchsorted(ti[order], np.arange(n_in), side="right")
    na, nb = stop[hi] - start[hi], stop[hj] - start[hj]
    cnt = na * nb
    pe = np.repeat(np.arange(len(hi)), cnt)
    local = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    nbr = np.repeat(nb, cnt)
    pa = order[np.repeat(start[hi], cnt) + local // np.maximum(nbr, 1)]
    pb = order[np.repeat(start[hj], cnt) + local % np.maximum(nbr, 1)]
    return pe, pa, pb

