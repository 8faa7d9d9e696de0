"""The quartic-smoothing NLP itself (variables, Eq. 11 equalities, limit rows, refinement points):
the model behind :func:`optplan.problem.quartic.smooth_quartic`, which documents it."""
from __future__ import annotations

import math
from typing import Any, cast

import casadi as ca
import numpy as np

from optplan.geometry.splines import PiecewisePolynomial, _falling, quartic_spline, segment_max_abs

_SLOTS = 3  # movable constraint points per segment (and dimension) for the refinement


def _limit_vec(value: Any, n: int, name: str) -> np.ndarray | None:
    """None, a scalar or (n,) positive limits (inf allowed) -> (n,) array or None."""
    if value is None:
        return None
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}: expected a positive scalar or an array of {n} positive limits, got {value!r}") from exc
    arr = np.full(n, float(arr)) if arr.ndim == 0 else arr.reshape(-1)
    if arr.shape != (n,) or np.any(np.isnan(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name}: expected a positive scalar or {n} positive limits (inf allowed), got {value!r}")
    return arr


def _check_input_sizes(fun: ca.Function, n: int, name: str) -> None:
    """Every input of ``fun`` has ``n`` entries (one per waypoint dimension), else ValueError."""
    for i in range(fun.n_in()):
        if fun.numel_in(i) != n:
            raise ValueError(f"{name}: input {i} must have {n} entries (one per waypoint dimension), "
                             f"got shape {fun.size_in(i)}")


def _ee_wrapper(fun: Any, n: int) -> tuple[ca.Function, type]:
    """Canonical (q (n,1), qdot (n,1)) -> v (k,1) Function, SX if the user's Function inlines into SX."""
    if not isinstance(fun, ca.Function):
        raise TypeError("ee_velocity: expected a casadi.Function (q, qdot) -> linear velocity, "
                        f"got {type(fun).__name__}")
    if fun.n_in() != 2 or fun.n_out() < 1:
        raise ValueError("ee_velocity: expected 2 inputs (q, qdot) and >= 1 output, "
                         f"got {fun.n_in()} inputs, {fun.n_out()} outputs")
    _check_input_sizes(fun, n, "ee_velocity")
    sym: Any
    for sym in (ca.SX, ca.MX):
        try:
            q: Any = sym.sym("q", n)
            qd: Any = sym.sym("qd", n)
            out = fun(ca.reshape(q, *fun.size_in(0)), ca.reshape(qd, *fun.size_in(1)))
            out = out[0] if isinstance(out, (list, tuple)) else out
            return ca.Function("ee_velocity_col", [q, qd], [ca.vec(out)]), sym
        except Exception:  # noqa: BLE001 - SX evaluation unsupported: use MX
            continue
    raise ValueError("ee_velocity: the Function cannot be evaluated symbolically with (n,) inputs")


def _jerk_matrix(r: int) -> np.ndarray:
    """Q with integral_0^1 (d^r/dtau^r sum_k p_k tau^k)^2 dtau = p^T Q p (k = 0..4)."""
    Q = np.zeros((5, 5))
    for p in range(r, 5):
        for q in range(r, 5):
            Q[p, q] = _falling(p, r) * _falling(q, r) / (p + q - 2 * r + 1)
    return Q


class _Problem:
    """Data of one smoothing problem (numpy side) and its CasADi transcription."""

    def __init__(self, t0: float, h: np.ndarray, X: np.ndarray, v0: Any, a0: Any, vf: Any, vmax: Any, amax: Any,
                 ee: Any, ee_max: Any,
                 free: bool, cost_order: int, time_weight: float, smooth_weight: float, samples: int,
                 slots: bool = True) -> None:
        self.t0, self.X = t0, X
        self.m, self.n = h.size, X.shape[1]
        self.v0, self.a0, self.vf = v0, a0, vf
        self.lims = {"qdot_max": vmax, "qddot_max": amax}
        self.ee_max, self.free = ee_max, free
        self.ee: Any
        self.sym: Any
        self.ee, self.sym = (ee if ee is not None else (None, ca.SX))
        self.r, self.tw, self.sw, self.S = cost_order, time_weight, smooth_weight, samples
        self.h_ref = float(h.mean())
        # movable constraint points ("slots", fractions of a segment): per (segment, dimension) for
        # the joint limits, per segment for the end-effector speed; set to the worst points found
        self.slot_shape = {name: (_SLOTS, self.m, self.n) for name, lim in self.lims.items()
                           if lim is not None and slots}
        if ee is not None and slots:
            self.slot_shape["ee_speed_max"] = (_SLOTS, self.m, 1)

    ee_acc: Any = None  # optional Function (q, qdot, qddot) -> EE linear acceleration; set by smooth_quartic
    ee_acc_max: float | None = None

    @property
    def has_limits(self) -> bool:
        return any(v is not None for v in self.lims.values()) or self.ee is not None or self.ee_acc is not None

    def segment_ratio(self, pp: PiecewisePolynomial) -> np.ndarray:
        """(m,) factor by which each segment must be slowed down to meet its limits (<1: may speed up)."""
        out = np.zeros(pp.n_segments)
        for name, (_, _, ratio) in self.limit_violations(pp).items():
            r = np.max(ratio, axis=1)
            out = np.maximum(out, np.sqrt(r) if name == "qddot_max" else r)
        return out

    def spline(self, h: np.ndarray) -> PiecewisePolynomial:
        return quartic_spline(self.t0 + np.concatenate([[0.0], np.cumsum(h)]), self.X, self.v0, self.a0, self.vf)

    # -- symbolic NLP
    def _segment_function(self, fracs: Any, slot_shape: dict[str, Any]) -> tuple[Any, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Per-segment Function (p (5n), h, slot fractions) -> (limit constraints, smoothness integral).

        The limits are imposed at the fixed fractions ``fracs`` and at the slots. Also returns the
        bounds of the constraint output and, per limit name, the local row of slot (s, j) in that
        output (-1: no constraint because the limit is infinite).
        """
        n, sym = self.n, self.sym
        ps, hs = sym.sym("p", 5 * n), sym.sym("h")
        sl = sym.sym("slots", sum(shape[0] * shape[2] for shape in slot_shape.values()))
        P = [ps[k * n:(k + 1) * n] for k in range(5)]
        g: list[Any] = []
        lb: list[np.ndarray] = []
        ub: list[np.ndarray] = []

        def at(f: Any) -> tuple[Any, Any, Any]:  # position, velocity, acceleration at fraction f of the segment
            q = P[0] + P[1] * f + P[2] * f**2 + P[3] * f**3 + P[4] * f**4
            v = (P[1] + 2 * P[2] * f + 3 * P[3] * f**2 + 4 * P[4] * f**3) / hs
            a = (2 * P[2] + 6 * P[3] * f + 12 * P[4] * f**2) / hs**2
            return q, v, a

        def add(expr: Any, lo: Any, hi: Any) -> int:
            first = sum(e.numel() for e in g)
            g.append(expr)
            lb.append(np.broadcast_to(np.asarray(lo, float), (expr.numel(),)))
            ub.append(np.broadcast_to(np.asarray(hi, float), (expr.numel(),)))
            return first

        for f in fracs:
            q, v, a = at(float(f))
            for name, val in (("qdot_max", v), ("qddot_max", a)):
                lim = self.lims[name]
                dims = [] if lim is None else np.flatnonzero(np.isfinite(lim)).tolist()
                if dims:
                    add(val[dims], lim[dims] * -1.0, lim[dims])
            if self.ee is not None:
                add(ca.sumsqr(self.ee(q, v)), 0.0, self.ee_max**2)
            if self.ee_acc is not None:
                add(ca.sumsqr(self.ee_acc(q, v, a)), 0.0, cast(float, self.ee_acc_max)**2)
        slot_rows = {name: np.full((shape[0], shape[2]), -1) for name, shape in slot_shape.items()}
        off = 0
        for name, shape in slot_shape.items():
            for s in range(shape[0]):
                for j in range(shape[2]):
                    q, v, a = at(sl[off])
                    off += 1
                    if name == "ee_speed_max":
                        slot_rows[name][s, j] = add(ca.sumsqr(self.ee(q, v)), 0.0, self.ee_max**2)
                    elif np.isfinite(self.lims[name][j]):  # slot (s, j) constrains dimension j only
                        lim = self.lims[name][j]
                        slot_rows[name][s, j] = add((v if name == "qdot_max" else a)[j], -lim, lim)
        Qm = _jerk_matrix(self.r)
        J = sum(Qm[a_, b_] * ca.dot(P[a_], P[b_]) for a_ in range(5) for b_ in range(5) if Qm[a_, b_] != 0.0)
        J = J * hs ** (1 - 2 * self.r)
        fun = ca.Function("quartic_segment", [ps, hs, sl], [ca.vertcat(*g) if g else sym(0, 1), J])
        def cat(v: list[np.ndarray]) -> np.ndarray:
            return np.concatenate(v) if v else np.zeros(0)

        return fun, cat(lb), cat(ub), slot_rows

    def build(self, h_fixed: np.ndarray) -> tuple[dict[str, Any], np.ndarray, np.ndarray]:
        """NLP dict (x, p, f, g) and the bounds of g; p holds the slot fractions (see pack_slots).

        Built in MX from a per-segment Function mapped over the segments, which keeps the
        construction of IPOPT's derivative functions fast for many segments and dimensions.
        """
        m, n = self.m, self.n
        nP = 5 * m * n
        w = ca.MX.sym("w", nP + (m if self.free else 0))
        Pm = ca.reshape(w[:nP], 5 * n, m)                      # column i = p_i (k-major, j-minor)
        H = w[nP:].T if self.free else ca.DM(h_fixed).T        # (1, m)
        # fixed samples (a segment's end is the next one's start) and slots, mapped over the segments
        fracs = np.linspace(0.0, 1.0, self.S)[:-1]
        seg_fun, seg_lb, seg_ub, local_rows = self._segment_function(fracs, self.slot_shape)
        n_sl = seg_fun.numel_in(2)
        psym = ca.MX.sym("p", n_sl * m)
        X = self.X
        g: list[Any] = []
        lb: list[np.ndarray] = []
        ub: list[np.ndarray] = []

        def add(expr: Any, lo: Any, hi: Any) -> None:
            g.append(ca.vec(expr))
            size = expr.numel()
            lb.append(np.broadcast_to(lo, (size,)) if np.ndim(lo) == 0 else np.ravel(lo, order="F"))
            ub.append(np.broadcast_to(hi, (size,)) if np.ndim(hi) == 0 else np.ravel(hi, order="F"))

        P = [Pm[k * n:(k + 1) * n, :] for k in range(5)]      # (n, m) each
        Hn = ca.repmat(H, n, 1)
        add(P[0], X[:-1].T, X[:-1].T)                           # a_i = x_i
        add(P[0] + P[1] + P[2] + P[3] + P[4], X[1:].T, X[1:].T)  # x_i(t_{i+1}) = x_{i+1}
        # C1, C2, C3 at inner waypoints and the boundary conditions, times h_ref^o (position units).
        # (Multiplying through by h_i h_{i+1} to get polynomial constraints was tried: IPOPT then
        # needs many more iterations or stalls.)
        end = {}
        for o in (1, 2, 3):
            end[o] = sum(_falling(k, o) * P[k] for k in range(o, 5)) / Hn**o
            if m > 1:
                add(self.h_ref**o * (end[o][:, :-1] - math.factorial(o) * P[o][:, 1:] / Hn[:, 1:] ** o), 0.0, 0.0)
        add(self.h_ref * P[1][:, 0] / H[0], self.h_ref * self.v0, self.h_ref * self.v0)
        add(self.h_ref**2 * 2 * P[2][:, 0] / H[0] ** 2, self.h_ref**2 * self.a0, self.h_ref**2 * self.a0)
        add(self.h_ref * end[1][:, m - 1], self.h_ref * self.vf, self.h_ref * self.vf)
        g_seg, J = seg_fun.map(m)(Pm, H, ca.reshape(psym, n_sl, m))
        first = sum(e.numel() for e in g)
        n_gs = seg_lb.size
        if n_gs:
            add(g_seg, np.tile(seg_lb, m), np.tile(seg_ub, m))
        if self.has_limits:  # the end of the last segment
            end_fun, end_lb, end_ub, _ = self._segment_function([1.0], {})
            add(end_fun(Pm[:, m - 1], H[m - 1], ca.DM(0, 1))[0], end_lb, end_ub)
        # global row of slot (s, segment i, dimension j)
        self.slot_rows = {}
        for name, rows in local_rows.items():
            glob = first + np.arange(m)[None, :, None] * n_gs + rows[:, None, :]
            self.slot_rows[name] = np.where(rows[:, None, :] >= 0, glob, -1)
        J = ca.sum2(J)
        f = self.tw * ca.sum2(H) + self.sw * J if self.free else J
        nlp = {"x": w, "p": psym, "f": f, "g": ca.vertcat(*g)}
        return nlp, np.concatenate(lb).astype(float), np.concatenate(ub).astype(float)

    def pack_slots(self, slots: dict[str, np.ndarray]) -> np.ndarray:
        """Slot arrays {name: (K, m, n|1)} -> parameter vector, segment-major (matching build)."""
        if not self.slot_shape:
            return np.zeros(0)
        per_seg = [np.transpose(slots[name], (1, 0, 2)).reshape(self.m, -1) for name in self.slot_shape]
        return np.concatenate(per_seg, axis=1).ravel()

    def pack(self, pp: PiecewisePolynomial) -> np.ndarray:
        h = pp.durations
        p = pp.coefficients * h[:, None, None] ** np.arange(5)[None, :, None]
        return np.concatenate([p.ravel(), h]) if self.free else p.ravel()

    def unpack(self, w: np.ndarray, h_fixed: np.ndarray) -> tuple[PiecewisePolynomial, np.ndarray]:
        m, n = self.m, self.n
        h = np.asarray(w[5 * m * n:], float).copy() if self.free else h_fixed.copy()
        p = np.asarray(w[:5 * m * n], float).reshape(m, 5, n)
        coef = p / h[:, None, None] ** np.arange(5)[None, :, None]
        return PiecewisePolynomial(self.t0 + np.concatenate([[0.0], np.cumsum(h)]), coef), h

    # -- numeric checks (independent of the NLP expressions)
    def limit_violations(self, pp: PiecewisePolynomial, dense: int = 32) -> dict[str, tuple[Any, ...]]:
        """{limit name: (excess, worst fraction, ratio)}, arrays (m, n) (joint limits) or (m, 1) (ee speed).

        ``excess`` = max over the segment minus the limit (in the limit's units), ``ratio`` = max / limit.
        """
        out = {}
        for name, k in (("qdot_max", 1), ("qddot_max", 2)):
            lim = self.lims[name]
            if lim is not None:
                mx, loc = segment_max_abs(pp, k, dense)
                out[name] = (mx - lim[None, :], loc, mx / lim[None, :])
        if self.ee is not None:
            m, G = pp.n_segments, dense
            frac = np.linspace(0.0, 1.0, G)
            t0, h = pp.breakpoints[:-1], pp.durations

            def speed_at(f: np.ndarray) -> np.ndarray:  # f (m, k) fractions -> (m, k) speeds
                return self._ee_speed(pp, np.minimum(t0[:, None] + f * h[:, None], pp.tf).ravel()).reshape(f.shape)

            speed = speed_at(np.broadcast_to(frac, (m, G)))
            rows = np.arange(m)
            best_f = frac[np.argmax(speed, axis=1)]
            best = speed[rows, np.argmax(speed, axis=1)]
            loc = best_f.copy()
            for it in range(4):  # successive parabolic refinement on shrinking brackets
                d = 1.0 / ((G - 1) * 4**it)
                f3 = np.clip(loc[:, None] + np.array([-d, 0.0, d])[None, :], 0.0, 1.0)
                y0, y1, y2 = speed_at(f3).T
                den = y0 - 2 * y1 + y2
                ok = den < 0
                shift = np.where(ok, 0.5 * d * (y0 - y2) / np.where(ok, den, -1.0), 0.0)
                loc = np.clip(loc + np.clip(shift, -d, d), 0.0, 1.0)
            s_loc = speed_at(loc[:, None])[:, 0]
            better = s_loc > best
            best = np.where(better, s_loc, best)
            loc = np.where(better, loc, best_f)
            out["ee_speed_max"] = ((best - self.ee_max)[:, None], loc[:, None], (best / self.ee_max)[:, None])
        return out

    def _ee_speed(self, pp: PiecewisePolynomial, t: np.ndarray) -> np.ndarray:
        v = self.ee.map(t.size)(pp(t).T, pp(t, 1).T)
        return np.sqrt(np.sum(np.asarray(v, float) ** 2, axis=0))

    def max_violation(self, pp: PiecewisePolynomial) -> float:
        viol = [float(np.max(excess)) for excess, _, _ in self.limit_violations(pp).values()]
        return max([self.equality_residual(pp)] + [max(v, 0.0) for v in viol])

    def objective(self, pp: PiecewisePolynomial) -> float:
        """The NLP cost of a spline, evaluated in numpy."""
        h = pp.durations
        p = pp.coefficients * h[:, None, None] ** np.arange(5)[None, :, None]  # (m, 5, n)
        J = float(np.sum(np.einsum("ikj,kl,ilj->i", p, _jerk_matrix(self.r), p) * h ** (1 - 2 * self.r)))
        return self.tw * float(h.sum()) + self.sw * J if self.free else J

    def equality_residual(self, pp: PiecewisePolynomial) -> float:
        """Max |residual| of the Eq. 11 conditions, each in its own units (unit, unit/s^k)."""
        c, h = pp.coefficients, pp.durations
        hp = h[:, None, None] ** np.arange(5)[None, :, None]
        res = [np.abs(c[:, 0] - self.X[:-1]).ravel(), np.abs((c * hp).sum(axis=1) - self.X[1:]).ravel()]
        for o in (1, 2, 3):
            d = pp.derivative(o).coefficients
            endv = (d * h[:, None, None] ** np.arange(d.shape[1])[None, :, None]).sum(axis=1)
            res.append(np.abs(endv[:-1] - d[1:, 0]).ravel())
            if o == 1:
                res.append(np.abs(np.concatenate([d[0, 0] - self.v0, endv[-1] - self.vf])))
            if o == 2:
                res.append(np.abs(d[0, 0] - self.a0))
        return float(max(r.max() if r.size else 0.0 for r in res))


