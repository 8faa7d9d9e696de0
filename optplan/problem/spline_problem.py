"""OptProblem's terms and expressions on the B-spline kernel core (:mod:`.spline_core`): each
term becomes one or more kernel families, a first guess is seeded from the boundary and target
rows (damped least squares on their own kernels: IK for frame targets) and, for a floating robot,
the zero-momentum base; the solution's rows are named in the user's language."""
from __future__ import annotations

import os
from typing import Any

import casadi as ca
import numpy as np

from ..errors import ConfigurationError
from ..geometry.spatial import pose_residual, vee_skew
from ..geometry.splines import quintic_time_law
from .collision_term import CollisionAvoidance
from .evaluate import Infeasibility, sampled_trajectory
from .expr_term import ExprTerm, _bounds, knots_of
from .expressions import Parameter, point_kernel
from .frame_terms import BaseAttitude, ClosedChain, FramePose
from .spline_core import Family, SplineCore
from .terms import (
    Duration,
    JointAccelerationLimits,
    JointBoundary,
    JointPositionLimits,
    JointVelocityLimits,
    Smoothness,
    _knots,
)

__all__ = ["ExprTerm", "Unsupported", "families_of", "fixed_boundary", "SplineEvaluator", "seed_guess", "knots_of"]

_POSE = ("x", "y", "z", "rot_x", "rot_y", "rot_z", "trace")
#: point kernels of boundaries and closed chains, by robot, N, parameter shapes and what their
#: expression holds (a kind, frames and constants): a later build of the same kind reuses them
_KNOT_KERNELS: dict[tuple[Any, ...], Any] = {}
_KNOT_SOURCE: list[str] = []


def _knot_source() -> str:
    """A hash of the source that writes the knot kernels' expressions (their files in the kernel
    cache are keyed by it: an edited formulation is never read from an older file): size and
    modification time of the modules involved, computed once per process."""
    if not _KNOT_SOURCE:
        import hashlib
        import sys

        h = hashlib.sha1()
        for mod in (__name__, "optplan.problem.expressions", "optplan.geometry.spatial", "optplan.model.symbolic",
                    "optplan.problem.kernels"):
            path = getattr(sys.modules.get(mod), "__file__", None)
            try:
                st = os.stat(path) if path else None
            except OSError:
                st = None
            h.update(f"{mod}:{st.st_size if st else -1}:{st.st_mtime_ns if st else -1};".encode())
        _KNOT_SOURCE.append(h.hexdigest()[:12])
    return _KNOT_SOURCE[0]


class Unsupported(Exception):
    """A term the B-spline core has no kernels for (the knot transcription takes the problem)."""


def families_of(prob: Any, core: SplineCore, params: list[Parameter]
                ) -> tuple[list[Family], dict[str, list[str]], dict[str, tuple[np.ndarray, np.ndarray]], list[Any]]:
    """Families of every term of ``prob`` (by handle name: the names of its families), and the
    control-point bounds of position-limit terms, and the collision terms' handles (their
    families need the first guess: :mod:`.spline_collision`). Raises :class:`Unsupported` for a
    term the core has no kernels for."""
    robot, N, sym = prob.robot, prob.N, core.sym
    fams: list[Family] = []
    owner: dict[str, list[str]] = {}
    pbounds: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    collisions: list[Any] = []
    jn = list(robot.joint_names)
    pinned = {}
    for h in prob._handles:
        if h.role == "constraint" and isinstance(h.term, JointBoundary) and h.term.q is not None:
            pinned[0 if h.term.at == "start" else N] = robot.check_joints(h.term.q, "JointBoundary.q")

    def knot(name: str, expr: Any, lo: Any, hi: Any, ks: list[int], labels: tuple[str, ...],
             key: tuple[Any, ...] | None = None) -> Family:
        # ``key``: what determines the kernel (its expression, constants included), so that a
        # segment after another with the same chain or boundary kinds builds no kernel again
        fn = None
        if key is not None:
            key = (core.kc._digest, N, tuple(p.shape for p in params), *key)
            fn = _KNOT_KERNELS.get(key)
        if fn is None:
            def build(_name: str) -> Any:
                return point_kernel(sym, expr() if callable(expr) else expr, params, N, "point")

            # a kernel of a known kind is kept on disk too (the kernel cache's file, by its key;
            # the function keeps its own name, which its compiled libraries are named after): a new
            # process builds neither the expression nor the robot's symbolic kinematics under it
            fn = build("") if key is None else core.kc._get(("knot_kernel", _knot_source(), *key[1:]), build)
            if key is not None:
                _KNOT_KERNELS[key] = fn
                while len(_KNOT_KERNELS) > 256:
                    _KNOT_KERNELS.pop(next(iter(_KNOT_KERNELS)))
        return Family(name, "knot", fn, ks, np.asarray(lo, float), np.asarray(hi, float), labels)

    def cost(name: str, expr: Any, weight: Any, kind: str) -> Family:
        e = ca.SX(expr)
        if kind == "integral":
            e = (e if e.numel() == 1 else ca.sumsqr(e)) * sym.T / N
            fn = point_kernel(sym, e, params, N, "cost", weight)
            return Family(name, "knot", fn, list(range(N + 1)), cost=True, data="quad")
        fn = point_kernel(sym, e, params, N, "cost", weight)
        return Family(name, "knot", fn, [N], cost=True, data="one")

    for h in prob._handles:
        t, name = h.term, h.name
        new: list[Family] = []
        if isinstance(t, ExprTerm):
            if h.role == "cost":
                new.append(cost(name, t.expr, t.weight, t.kind))
            else:
                m = ca.vec(ca.SX(t.expr)).shape[0]
                expr, lo, hi = _bounds(t, m, params)
                labels = tuple(f"[{i}]" if m > 1 else "" for i in range(expr.shape[0]))
                new.append(knot(name, expr, lo, hi, knots_of(t.at, N, name), labels))
        elif h.role == "cost":
            if isinstance(t, Smoothness) and t.order in ("jerk", "acceleration"):
                fn = core.smoothness_kernel(t.order, h.weight)
                new.append(Family(name, t.order, fn, list(range(N)), cost=True))
            elif isinstance(t, Duration):
                new.append(cost(name, sym.T, h.weight, "end"))
            else:
                raise Unsupported(f"{type(t).__name__} as a cost")
        elif isinstance(t, JointBoundary):
            k, parts = t._parts(N)
            ex = ca.vertcat(*[{"q": sym.q, "qd": sym.qd, "qdd": sym.qdd}[n] for n, _ in parts])
            v = np.concatenate([robot.check_joints(val, f"JointBoundary.{n}") for n, val in parts])
            new.append(knot(name, ex, v, v, [k], tuple(f"{n}[{j}]" for n, _ in parts for j in jn),
                            key=("boundary", tuple(n for n, _ in parts))))
        elif isinstance(t, JointPositionLimits):
            pbounds[name] = t.limits(robot)
        elif isinstance(t, JointVelocityLimits):
            lo, hi = t.limits(robot)
            # every entry of the velocity control points; a fixed-duration build keeps those its
            # guess brings near the limit (SplineBackend.prepare)
            new.append(Family(name, "velocity", None, list(range((N + 2) * robot.nj)), labels=tuple(jn),
                              data=np.vstack([lo, hi]), sides=2 if core.free_time else 1))
        elif isinstance(t, JointAccelerationLimits):
            lo, hi = t.limits(robot)
            new.append(knot(name, sym.qdd, lo, hi, list(range(N + 1)), tuple(jn)))
        elif isinstance(t, ClosedChain):
            if t.relative is None or t.interior:
                raise Unsupported("ClosedChain without a relative pose or with interior points")
            fa = robot.model.frames[robot.arm(t.arm_a).ee_frame_id].name
            fb = robot.model.frames[robot.arm(t.arm_b).ee_frame_id].name
            Rt, pt = np.array(t.relative.rotation, float), np.array(t.relative.translation, float)

            def chain(fa: str = fa, fb: str = fb, Rt: np.ndarray = Rt, pt: np.ndarray = pt) -> Any:
                Ra, pa = _base_frame(core, fa)
                Rb, pb = _base_frame(core, fb)
                r, tr = pose_residual(Ra.T @ Rb, Ra.T @ (pb - pa), Rt, ca.DM(pt))
                return ca.vertcat(r, tr)

            ks = [k for k in range(N + 1)
                  if not t.skip_pinned or k not in pinned or not _chain_holds(robot, t, pinned[k], t.pinned_tol)]
            new.append(knot(name, chain, np.r_[np.zeros(6), 1.0], np.r_[np.zeros(6), np.inf], ks, _POSE,
                            key=("closed_chain", fa, fb, Rt.tobytes(), pt.tobytes())))
        elif isinstance(t, FramePose):
            assert t.target is not None
            fr = sym.frame(t.frame)
            r, tr = pose_residual(fr.rotation, fr.translation, np.array(t.target.rotation),
                                  ca.DM(t.target.translation))
            ks = _knots(t.at, N)
            if t.position_only:
                new.append(knot(name, r[:3], np.zeros(3), np.zeros(3), ks, _POSE[:3]))
            else:
                new.append(knot(name, ca.vertcat(r, tr), np.r_[np.zeros(6), 1.0], np.r_[np.zeros(6), np.inf],
                                ks, _POSE))
        elif isinstance(t, BaseAttitude):
            if not robot.is_floating:
                raise ConfigurationError("BaseAttitude needs a free-floating robot")
            E = ca.DM(t._target()).T @ sym.base_rotation()
            new.append(knot(name, ca.vertcat(vee_skew(E), ca.trace(E)), np.r_[0, 0, 0, 1.0],
                            np.r_[0, 0, 0, np.inf], _knots(t.at, N), ("rot_x", "rot_y", "rot_z", "trace")))
        elif isinstance(t, CollisionAvoidance):
            # the segment NLP's planes: fixed normals, its pair set (self-collision, held object)
            # (a floating robot's planner, floating_collision, reads the term's own pair set; activation
            # sets and margin boosts are the fixed-base planner's)
            # a floating robot may have several terms (each its own pairs and margin), one without a
            # scene (its own bodies only), and a free duration; a fixed base with a free duration is not
            # measured on the core (the knot transcription takes it)
            if not t.fixed_normals \
                    or (robot.is_floating and (t.margin_boost or t.activate_with)) \
                    or (not robot.is_floating and (collisions or t.scene is None or core.free_time
                                                   or not t.self_collision or not t.held_object)):
                raise Unsupported("CollisionAvoidance other than fixed normals (a fixed base: one term with a "
                                  "scene and a fixed duration)")
            collisions.append(h)
        else:
            raise Unsupported(type(t).__name__)
        owner[name] = [f.name for f in new]
        fams += new
    return fams, owner, pbounds, collisions


def fixed_boundary(core: SplineCore, term: JointBoundary, T: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The end control points a boundary determines exactly, as ``(variable indices, values, A)``
    (A: the 3 × 3 map from the three points to [q; q̇; q̈] of each joint):
    q [rad], q̇ [rad/s] and q̈ [rad/s²] at knot 0 fix P_0 … P_2 (at knot N: P_N … P_N+2) through
    ``knot_values``' 3 × 3 map per joint (duration ``T`` [s]); with a free duration only at rest
    (q̇ = q̈ = 0: the three points equal q whatever the duration). None when the boundary leaves
    some of them free (a q alone) or sits at an interior knot."""
    N, nj = core.N, core.nj
    k, parts = term._parts(N)
    given = dict(parts)
    if set(given) != {"q", "qd", "qdd"} or k not in (0, N):
        return None
    q, qd, qdd = (core.robot.check_joints(given[n], f"JointBoundary.{n}") for n in ("q", "qd", "qdd"))
    if core.free_time and (np.any(qd != 0.0) or np.any(qdd != 0.0)):
        return None
    h = T / N
    M = core.M
    cols = np.arange(3) + (0 if k == 0 else N)
    A = np.vstack([M["q"][k, cols], M["qd"][k, cols] / h, M["qdd"][k, cols] / h**2])
    P = np.linalg.solve(A, np.vstack([q, qd, qdd]))           # 3 × nj
    idx = (cols[:, None] * nj + np.arange(nj)[None, :]).ravel()
    return idx, P.ravel(), A


def _base_frame(core: SplineCore, frame: str) -> tuple[Any, Any]:
    """A frame's placement in the base frame (floating) or world (fixed), as SX of q."""
    return core.kc.frame(core.robot.model.getFrameId(frame))


def _chain_holds(robot: Any, cc: ClosedChain, q: np.ndarray, tol: float) -> bool:
    from .terms import pose_residual_numeric

    M = cc._relative_numeric(robot, robot.configuration(q) if robot.is_floating else q)
    assert cc.relative is not None
    r, tr = pose_residual_numeric(M, cc.relative)
    return bool(np.abs(r).max() <= tol and tr >= 1.0)


# --------------------------------------------------------------------------- first guess
def seed_guess(core: SplineCore, fams: list[Family], p_of: Any, T: float, lower: np.ndarray,
               upper: np.ndarray, pinned: dict[int, np.ndarray]) -> np.ndarray:
    """A first guess: the start and end configurations from the problem's own equality rows at
    those knots (damped least squares on their kernels — inverse kinematics for frame targets;
    a JointBoundary's q as given), a rest-to-rest quintic between them, and for a floating robot
    the zero-momentum base integrated along it (the end re-solved once with that base).
    ``p_of(q_start)``: the parameter vector once the start (hence a floating robot's centre of
    mass) is known."""
    N = core.N
    fin = np.isfinite(lower) & np.isfinite(upper)
    mid = np.where(fin, (np.where(fin, lower, 0.0) + np.where(fin, upper, 0.0)) / 2, 0.0)
    q0 = pinned.get(0)
    if q0 is None:
        q0 = _dls(core, fams, p_of(None), T, 0, np.clip(mid, lower, upper), lower, upper, None)
    p = p_of(q0)
    qN = pinned.get(N)
    x = np.zeros(core.nx)
    for rnd in range(3 if core.fl else 1):
        if pinned.get(N) is None:
            xiN = None if rnd == 0 else core.knot_xi(x)[N]
            qN = _dls(core, fams, p, T, N, q0 if rnd == 0 or qN is None else qN, lower, upper, xiN, q_from=q0)
        assert qN is not None  # pinned or solved for just above
        x = _quintic(core, q0, qN, T)
    return x


def _quintic(core: SplineCore, q0: np.ndarray, q1: np.ndarray, T: float) -> np.ndarray:
    N = core.N
    s = np.linspace(0.0, 1.0, N + 1)
    Q = q0 + quintic_time_law(s)[0][:, None] * (q1 - q0)
    P = core.fit(Q, np.zeros(core.nj), np.zeros(core.nj), T / N)
    parts = [P.ravel()]
    if core.fl:
        parts.append(core.integrate_base(P))
    if core.free_time:
        parts.append(np.array([T]))
    return np.concatenate(parts)


def _dls(core: SplineCore, fams: list[Family], p: np.ndarray, T: float, k: int, q: np.ndarray,
         lower: np.ndarray, upper: np.ndarray, xi: np.ndarray | None, iters: int = 100,
         q_from: np.ndarray | None = None) -> np.ndarray:
    """Damped least squares on the equality rows at knot k (rest: dq/du = d²q/du² = 0). With
    ``q_from`` (k = N), also the equality rows of the middle knot, evaluated where a rest-to-rest
    quintic from ``q_from`` to q is there: halfway, at its peak speed (so that a row such as "these
    joints do not move" keeps them)."""
    nj, N = core.nj, core.N
    km = N // 2
    pts = [(k, f) for f in fams if f.kind == "knot" and not f.cost and k in f.points]
    if q_from is not None:
        pts += [(km, f) for f in fams if f.kind == "knot" and not f.cost and km in f.points]
    q = np.array(q, float)
    if not pts:
        return q
    sets = [(kk, f, core.kernel_set(f.fn, False)) for kk, f in pts if f.fn is not None]
    x = np.zeros(core.nx)
    if core.i_T is not None:
        x[core.i_T] = T
    for _ in range(iters):
        res, jac = [], []
        for kk, f, (fn, jfn, _h) in sets:
            eq = (f.lower == f.upper) & np.isfinite(f.lower)
            if not eq.any():
                continue
            mid = kk != k
            qq = (q + q_from) / 2 if mid and q_from is not None else q
            P = np.repeat(qq[None, :], core.N + 3, axis=0)
            x[:core.nP] = P.ravel()
            z = core.knot_inputs(x, p, kk, False)
            if mid and q_from is not None:
                z[nj:2 * nj] = 1.875 * (q - q_from) / N       # dq/du at the quintic's peak
            if xi is not None and core.fl and not mid:
                z[3 * nj:3 * nj + 4] = xi
            r = np.asarray(fn(z)).ravel() - f.lower
            Jz = np.asarray(ca.densify(jfn(z)))
            J = Jz[:, :nj] * (0.5 if mid else 1.0) + (Jz[:, nj:2 * nj] * 1.875 / N if mid else 0.0)
            res.append(r[eq])
            jac.append(J[eq])
        if not res:
            return q
        r, J = np.concatenate(res), np.vstack(jac)
        if np.abs(r).max() < 1e-10:
            break
        dq = J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(J.shape[0]), r)
        m = np.abs(dq).max()
        if m < 1e-10:   # what is left does not depend on q here (e.g. the base attitude)
            break
        if m > 0.3:
            dq *= 0.3 / m
        q = np.clip(q - dq, lower, upper)
    return q


# --------------------------------------------------------------------------- evaluation
def _basis2(u: float) -> np.ndarray:
    """Weights of P_k … P_k+3 in d²q/du² at fraction u of interval k."""
    return np.array([1 - u, 3 * u - 2, 1 - 3 * u, u])


class SplineEvaluator:
    """Terms and expressions of one spline build, evaluated at its solutions (the
    :class:`~optplan.problem.Solution` methods value/violation/dual/sample)."""

    def __init__(self, problem: Any, core: SplineCore, st: dict[str, Any], fams: list[Family],
                 owner: dict[str, list[str]], pbounds: dict[str, tuple[np.ndarray, np.ndarray]], p: np.ndarray):
        self.problem, self.core, self.st, self.p = problem, core, st, p.copy()
        self.fams = {f.name: f for f in fams}
        self.owner, self.pbounds = owner, pbounds
        self.handles = dict(problem.terms)
        self.robot = problem.robot
        #: a floating robot's fixed centre of mass [m] (where the base's position follows from); else None
        self.com0 = np.array(p[core.p_c0:core.p_c0 + 3], float) if core.fl else None

    def sampled_trajectory(self, sol: Any, t: np.ndarray) -> Any:
        """The solution at the times ``t`` [s] as a :class:`NumericTrajectory` (joints exact)."""
        return sampled_trajectory(self.robot, sol, t, self.com0)

    def _handle(self, handle: Any) -> Any:
        name = handle if isinstance(handle, str) else getattr(handle, "name", None)
        if name not in self.handles:
            raise KeyError(f"no term named {name!r} in the problem of this solution (terms: {sorted(self.handles)})")
        return self.handles[name]

    def _rows(self, name: str, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        if name in self.pbounds:
            lo, hi = self.pbounds[name]
            P = self.core.control_points(x)
            return P, np.broadcast_to(lo, P.shape), np.broadcast_to(hi, P.shape), self.core.nj
        vel = [self.fams[fn] for fn in self.owner[name] if self.fams[fn].kind == "velocity"]
        if vel:   # velocity control points [rad/s] against their limits
            lo, hi = np.asarray(vel[0].data)
            V = np.diff(self.core.control_points(x), axis=0) * self.core.N / self._T(x)
            return V, np.broadcast_to(lo, V.shape), np.broadcast_to(hi, V.shape), self.core.nj
        vals, los, his, m = [], [], [], 0
        g = np.array(self.st["gfun"](x, self.p)).ravel()
        for fn in self.owner[name]:
            f = self.fams[fn]
            sl = self.st["slices"].get(fn)
            m = f.rows_per_point
            if sl is None or fn in self.st.get("row_points", {}):
                # a boundary fixed by bounds (no rows), or a family some of whose knots had constant
                # rows left out of the NLP: its kernel at every knot
                assert f.fn is not None
                for k in f.points:
                    vals.append(np.asarray(f.fn(self.core.knot_inputs(x, self.p, k, False))).ravel())
                    los.append(f.lower)
                    his.append(f.upper)
                continue
            vals.append(g[sl])
            los.append(np.asarray(self.st["lbg"])[sl])
            his.append(np.asarray(self.st["ubg"])[sl])
        v = np.concatenate(vals) if vals else np.zeros(0)
        return v, np.concatenate(los) if los else v, np.concatenate(his) if his else v, max(m, 1)

    def _T(self, x: np.ndarray) -> float:
        return self.core.duration_of(x, float(self.p[self.core.p_T]))

    def value(self, handle: Any, sol: Any) -> Any:
        h = self._handle(handle)
        x = np.asarray(sol.x, float)
        if h.role == "cost":
            c = np.array(self.st["cfun"](x, self.p)).ravel()
            return float(sum(c[self.st["cslices"][fn]].sum() for fn in self.owner[h.name]))
        v, _, _, m = self._rows(h.name, x)
        return v.reshape(-1, m)

    def violation(self, handle: Any, sol: Any) -> np.ndarray:
        h = self._handle(handle)
        if h.role == "cost":
            raise TypeError(f"violation: {h.name!r} is a cost (it has no rows); value() gives its cost")
        v, lo, hi, m = self._rows(h.name, np.asarray(sol.x, float))
        return np.maximum(np.maximum(lo - v, v - hi), 0.0).reshape(-1, m)

    def dual(self, handle: Any, sol: Any) -> np.ndarray:
        h = self._handle(handle)
        if h.role == "cost":
            raise TypeError(f"dual: {h.name!r} is a cost (it has no multipliers)")
        if h.name in self.pbounds:
            if sol.lam_x is None:
                raise ValueError("dual: no bound multipliers in this solution")
            return -np.asarray(sol.lam_x)[:self.core.nP].reshape(-1, self.core.nj)
        if sol.lam_g is None:
            raise ValueError(f"dual: no constraint multipliers in this solution (status {sol.status.value})")
        lam = np.asarray(sol.lam_g)
        if any(self.fams[fn].kind == "velocity" for fn in self.owner[h.name]):
            # rows N ΔP − bound·T per entry (upper, lower), or ΔP within [lower, upper]·h (fixed
            # duration): ∂f*/∂bound [per rad/s] = −λ T (−λ h)
            f = self.fams[self.owner[h.name][0]]
            lv = lam[self.st["slices"][f.name]].reshape(-1, f.sides)
            full = np.zeros((self.core.N + 2) * self.core.nj)   # an entry without a row: 0
            T = self._T(np.asarray(sol.x, float))
            full[np.asarray(f.points, int)] = lv.sum(axis=1) * (T if f.sides == 2 else T / self.core.N)
            return -full.reshape(-1, self.core.nj)
        fixed = self.st.get("fixed", {})
        if any(fn in fixed for fn in self.owner[h.name]):
            return self._fixed_dual(fixed[self.owner[h.name][0]], np.asarray(sol.x, float), lam)
        parts = []
        for fn in self.owner[h.name]:
            lf = lam[self.st["slices"][fn]]
            rp = self.st.get("row_points", {}).get(fn)
            if rp is not None:   # knots whose rows were constants left out of the NLP: no multiplier (NaN)
                f = self.fams[fn]
                full = np.full((len(f.points), f.rows_per_point), np.nan)
                full[[f.points.index(k) for k in rp]] = lf.reshape(-1, f.rows_per_point)
                lf = full.ravel()
            parts.append(lf)
        m = max(self.fams[fn].rows_per_point for fn in self.owner[h.name]) if self.owner[h.name] else 1
        return -np.concatenate(parts).reshape(-1, m)

    def _fixed_dual(self, fixed: tuple[np.ndarray, np.ndarray, np.ndarray], x: np.ndarray,
                    lam: np.ndarray) -> np.ndarray:
        """∂f*/∂b of a boundary fixed by bounds (b = [q; q̇; q̈] at its end): the fixed points'
        reduced gradient ∂L/∂P = ∇f + Jᵀλ (the negated multipliers of their bounds) mapped by A⁻ᵀ."""
        idx, _, A = fixed
        sc = float(self.p[self.core.p_scale])
        grad = np.asarray(self.st["derivs"]["grad_f"](x, self.p)[1]).ravel() / sc
        if lam.size:
            grad = grad + np.asarray(ca.densify(self.st["derivs"]["jac_g"](x, self.p)[1])).T @ lam
        gP = grad[idx].reshape(3, self.core.nj)
        return np.linalg.solve(A.T, gP).reshape(1, -1)

    def sample(self, handle: Any, sol: Any, t: Any) -> np.ndarray:
        """The term's per-point rows at times ``t`` [s], between the knots too (joints exact on the
        B-spline; a floating base's attitude interpolated between its knots)."""
        h = self._handle(handle)
        fams = [self.fams[fn] for fn in self.owner.get(h.name, [])]
        if h.name in self.pbounds:
            return sol.sample(t)["q"]
        if not fams or any(f.kind != "knot" or f.cost for f in fams):
            raise TypeError(f"sample: {h.name!r} is not evaluated point by point")
        core, x = self.core, np.asarray(sol.x, float)
        t = np.atleast_1d(np.asarray(t, float))
        T, N, nj = sol.duration, core.N, core.nj
        if np.any(t < -1e-12) or np.any(t > T + 1e-12):
            raise ValueError(f"sample: times must be in [0, {T}] s")
        P = core.control_points(x)
        xi = core.knot_xi(x)
        out = []
        for tt in t:
            uu = np.clip(tt / T * N, 0.0, N)
            k = min(int(uu), N - 1)
            u = uu - k
            b, db = spline_basis_np(u)
            row = []
            for f in fams:
                z = core.knot_inputs(x, self.p, min(k, N), False)
                z[:nj], z[nj:2 * nj], z[2 * nj:3 * nj] = b @ P[k:k + 4], db @ P[k:k + 4], _basis2(u) @ P[k:k + 4]
                off = 3 * nj
                if core.fl:
                    a, c = xi[k], xi[k + 1] if np.dot(xi[k], xi[k + 1]) >= 0 else -xi[k + 1]
                    qi = (1 - u) * a + u * c
                    z[off:off + 4] = qi / np.linalg.norm(qi)
                    off += 4
                z[off] = tt / T
                assert f.fn is not None
                row.append(np.asarray(f.fn(z)).ravel())
            out.append(np.concatenate(row))
        return np.array(out)

    def infeasibilities(self, sol: Any, n: int) -> list[Infeasibility]:
        core, x = self.core, np.asarray(sol.x, float)
        N, T = core.N, sol.duration
        h = T / N
        g = np.array(self.st["gfun"](x, self.p)).ravel()
        lbg, ubg = np.asarray(self.st["lbg"]), np.asarray(self.st["ubg"])
        viol = np.maximum(np.maximum(lbg - g, g - ubg), 0.0)
        out = []
        for fname, sl in self.st["slices"].items():
            f = self.fams.get(fname)
            term = next((hn for hn, fs in self.owner.items() if fname in fs), "dynamics")
            v = viol[sl]
            for i in np.flatnonzero(v > 0):
                gi = sl.start + int(i)
                if f is None:
                    out.append(Infeasibility("dynamics", int(i), None, float(g[gi]), float(lbg[gi]), float(ubg[gi]),
                                             float(v[i]), label=f"dynamics:{fname}[{i}]"))
                    continue
                m = f.rows_per_point
                pt, c = divmod(int(i), m)
                if f.kind == "velocity":   # in rad/s: the row is T·(v − bound), or h·v (two-sided)
                    side = c if f.sides == 2 else int(g[gi] < lbg[gi])
                    k, j = divmod(int(f.points[pt]), core.nj)
                    bound = float(np.asarray(f.data)[1 - side, j])
                    rs = T if f.sides == 2 else h
                    gv = float(g[gi]) if f.sides == 2 else float(g[gi]) - bound * rs
                    lab = f"{term}[{f.labels[j]}].{'upper' if side == 0 else 'lower'} at t={min(max(k - 0.5, 0), N) * h:.3g} s"
                    out.append(Infeasibility(term, int(i), k, gv / rs + bound, bound if side else -np.inf,
                                             bound if side == 0 else np.inf, float(v[i]) / rs, label=lab))
                    continue
                else:
                    k = self.st.get("row_points", {}).get(fname, f.points)[pt]
                    comp = f.labels[c] if c < len(f.labels) else f"[{c}]"
                    sep = "." if comp and not comp.startswith("[") else ""
                    lab = f"{term}[k={k}]{sep}{comp} at t={k * h:.3g} s"
                out.append(Infeasibility(term, int(i), k, float(g[gi]), float(lbg[gi]), float(ubg[gi]), float(v[i]),
                                         label=lab))
        for name, (lo, hi) in self.pbounds.items():
            P = core.control_points(x)
            for i, j in zip(*np.nonzero((P < lo - 1e-12) | (P > hi + 1e-12))):
                which = "upper" if P[i, j] > hi[j] else "lower"
                vv = float(max(lo[j] - P[i, j], P[i, j] - hi[j]))
                tc = min(max(i - 1, 0), N) * h   # the control point's Greville abscissa
                out.append(Infeasibility(name, int(i * core.nj + j), int(i), float(P[i, j]), float(lo[j]), float(hi[j]),
                                         vv, label=f"{name}[{self.robot.joint_names[j]}].{which} at t={tc:.3g} s"))
        out.sort(key=lambda r: -r.violation)
        return out[:n]


def spline_basis_np(u: float) -> tuple[np.ndarray, np.ndarray]:
    from .floating_kernels import spline_basis

    return spline_basis(u)
