"""Transcription of a trajectory NLP: decision variables, dynamics constraints and the kinematic
expressions terms are written in.

Joint trajectory (documented transcription)
-------------------------------------------
N intervals of equal length ``h = T / N`` (``T`` fixed or a decision variable). At each of the N+1
knots the state is ``(q_k, q̇_k, q̈_k)`` (actuated joints, [rad], [rad/s], [rad/s²]); on each interval
the jerk ``j_k`` [rad/s³] is constant and the state is integrated *exactly*::

    q_{k+1} = q_k + h q̇_k + h²/2 q̈_k + h³/6 j_k
    q̇_{k+1} = q̇_k + h q̈_k + h²/2 j_k
    q̈_{k+1} = q̈_k + h j_k

so the joint trajectory is a C2 piecewise cubic — the continuous-time trajectory, not an
approximation of it — and ``∫ j² dt = h Σ j_k²`` exactly.

Scaling: the decision variables are ``q``, ``h₀ q̇``, ``h₀² q̈`` and ``h₀³ j`` with the nominal
interval ``h₀ = duration / N`` (a constant, also for free time), so the integration rows have
O(1) coefficients. Unscaled, the closed-chain rows at knot 1 act on the first jerk through
``h³/6`` only — with the boundary knot pinned, the equality Jacobian had a dozen singular values of
1e-7..1e-5, IPOPT saw the wrong KKT inertia at every iteration and raised MUMPS's pivot tolerance.
See docs/decisions/0010-knot-transcription-defaults.md.
The accessors ``q(k)``, ``qd(k)``, ``qdd(k)``, ``jerk(k)`` and ``V``, ``A``, ``J`` are in physical units.

Free-floating base
------------------
The base twist ``u = [v_b; ω_b]`` (base frame) is a decision variable at every half RK4 sub-step
(``2 n_sub + 1`` points per interval, shared at the knots), tied to the joints by zero total momentum, ``h(q, [u; q̇]) = 0`` — the momentum itself,
computed by an O(n) recursion (linear in the velocities, no matrix inverse), in base-frame
coordinates (valid because the momentum is zero). The base orientation (unit quaternion,
Pinocchio's ``(x, y, z, w)``) is a state at each knot, tied by ``n_sub`` classical RK4 steps per
interval using the twists at the start, middle and end of each sub-step (4th order; renormalised). The
base position follows in closed form from the fixed centre of mass: ``p_b = c₀ − R_b c_b(q)``.
This keeps the exact Hessian cheap: the earlier form (RK4 stages each solving ``Ag_b⁻¹ Ag_m``
symbolically) cost 15-80 s of setup at N = 10.
"""
from __future__ import annotations

import weakref
from typing import Any

import casadi as ca
import numpy as np

from ..model.robot import RobotModel
from ..model.symbolic import SymbolicKinematics, quat_to_matrix

__all__ = ["Transcription", "quat_mul"]

#: a floating robot's base functions (momentum, base CoM, RK4 attitude step), built once per robot
_BASE_FUNCTIONS: weakref.WeakKeyDictionary[RobotModel, tuple[ca.Function, ca.Function, ca.Function]] = \
    weakref.WeakKeyDictionary()

#: a CasADi expression (MX, SX or DM)
Expr = Any


def quat_mul(a: Expr, b: Expr) -> Expr:
    """Hamilton product of CasADi quaternions stored (x, y, z, w)."""
    ax, ay, az, aw = a[0], a[1], a[2], a[3]
    bx, by, bz, bw = b[0], b[1], b[2], b[3]
    return ca.vertcat(aw * bx + ax * bw + ay * bz - az * by,
                      aw * by - ax * bz + ay * bw + az * bx,
                      aw * bz + ax * by - ay * bx + az * bw,
                      aw * bw - ax * bx - ay * by - az * bz)


class Transcription:
    """Variables and kinematic expressions of one trajectory NLP (built by :class:`OptProblem`).

    Terms use: ``N``, ``T``, ``h``, ``q(k)``, ``qd(k)``, ``qdd(k)``, ``jerk(k)`` (k < N),
    ``q_full(k)`` (Pinocchio layout), ``frame(name, k) -> (R, p)`` (world), ``base_quat(k)``,
    ``base_rotation(k)``, ``base_position(k)``, ``sym`` (:class:`SymbolicKinematics`).
    """

    def __init__(self, robot: RobotModel, n_intervals: int, duration: float, free_time: bool,
                 base0_quat: Any = None, com0: Any = None, n_sub: int = 2) -> None:
        self.robot = robot
        self.N = int(n_intervals)
        self.nj = robot.nj
        self.sym = SymbolicKinematics(robot)
        self.free_time = free_time
        self.n_sub = int(n_sub)
        nj, N = self.nj, self.N
        #: nominal interval h₀ [s]: the variables are q, h₀ q̇, h₀² q̈, h₀³ j (module docstring)
        self.h0 = float(duration) / N
        self.Q = ca.MX.sym("q", nj, N + 1)
        self.Vs = ca.MX.sym("qd_scaled", nj, N + 1)
        self.As = ca.MX.sym("qdd_scaled", nj, N + 1)
        self.Js = ca.MX.sym("jerk_scaled", nj, N)
        self.V = self.Vs / self.h0
        self.A = self.As / self.h0**2
        self.J = self.Js / self.h0**3
        blocks = [ca.vec(self.Q), ca.vec(self.Vs), ca.vec(self.As), ca.vec(self.Js)]
        self.T_var: ca.MX | None
        if free_time:
            self.T_var = ca.MX.sym("T")
            self.T = self.T_var
            blocks.append(self.T_var)
        else:
            self.T_var = None
            self.T = ca.MX(float(duration))
        self.h = self.T / N
        self.floating = robot.is_floating
        if self.floating:
            self.QB = ca.MX.sym("base_quat", 4, N + 1)
            # twist at every half RK4 sub-step: column c is time c·h/(2 n_sub)
            self.U = ca.MX.sym("base_twist", 6, 2 * self.n_sub * N + 1)
            # joint positions and (scaled) rates at the twist points inside the intervals: own
            # variables tied linearly to the cubic, so that the momentum constraint there involves
            # 34 variables instead of the 62 of (q, q̇, q̈, j)_k — half the exact Hessian's cost
            nm = (2 * self.n_sub - 1) * N
            self.QM = ca.MX.sym("q_mid", nj, nm)
            self.VMs = ca.MX.sym("qd_mid_scaled", nj, nm)
            blocks += [ca.vec(self.QB), ca.vec(self.U), ca.vec(self.QM), ca.vec(self.VMs)]
            self.base0_quat = np.array([0, 0, 0, 1.0]) if base0_quat is None else np.asarray(base0_quat, float)
            self.com0 = np.zeros(3) if com0 is None else np.asarray(com0, float)
        self.x = ca.vertcat(*blocks)
        self._frame_cache: dict[tuple[Any, ...], tuple[Expr, Expr]] = {}
        self._joint_cache: dict[Any, list[tuple[Expr, Expr]]] = {}
        self._joints_fn: ca.Function | None = None
        self._build_base_functions()

    def set_com0(self, com0: Any) -> None:
        """The (fixed) centre of mass [m] of a floating robot, from the initial configuration."""
        if self.floating:
            self.com0 = np.asarray(com0, float).copy()

    # ------------------------------------------------------------------ variable layout
    def variable_scale(self, which: str) -> float:
        """Factor from physical units to the decision variable of ``which`` ∈ q, qd, qdd, jerk."""
        return {"q": 1.0, "qd": self.h0, "qdd": self.h0**2, "jerk": self.h0**3}[which]

    def unpack(self, xval: np.ndarray) -> dict[str, np.ndarray]:
        """Split a numeric decision vector into named arrays in physical units (knots along axis 0)."""
        nj, N = self.nj, self.N
        out: dict[str, Any] = {}
        i = 0
        for name, shape in (("q", (nj, N + 1)), ("qd", (nj, N + 1)), ("qdd", (nj, N + 1)), ("jerk", (nj, N))):
            n = shape[0] * shape[1]
            out[name] = np.asarray(xval[i:i + n]).reshape(shape, order="F").T / self.variable_scale(name)
            i += n
        if self.free_time:
            out["T"] = float(xval[i])
            i += 1
        if self.floating:
            out["base_quat"] = np.asarray(xval[i:i + 4 * (N + 1)]).reshape((4, N + 1), order="F").T.copy()
            i += 4 * (N + 1)
            nu = 2 * self.n_sub * N + 1
            out["base_twist"] = np.asarray(xval[i:i + 6 * nu]).reshape((6, nu), order="F").T.copy()
            i += 6 * nu
        return out

    @property
    def T_index(self) -> int:
        """Index of the free duration T [s] in the decision vector."""
        if not self.free_time:
            raise ValueError("the duration is not a decision variable (free_time=False)")
        return self.nj * (4 * self.N + 3)

    def pack(self, q: Any, qd: Any, qdd: Any, jerk: Any, T: Any = None, base_quat: Any = None,
             base_twist: Any = None) -> np.ndarray:
        """Decision vector from knot arrays in physical units (inverse of :meth:`unpack`; the
        interior joint variables of a floating robot are computed from the cubic)."""
        parts = [self.variable_scale(n) * np.asarray(a, float).T.reshape(-1, order="F")
                 for n, a in (("q", q), ("qd", qd), ("qdd", qdd), ("jerk", jerk))]
        if self.free_time:
            parts.append(np.array([float(T)]))
        if self.floating:
            parts.append(np.asarray(base_quat, float).T.reshape(-1, order="F"))
            if base_twist is None:
                base_twist = np.zeros((2 * self.n_sub * self.N + 1, 6))
            parts.append(np.asarray(base_twist, float).T.reshape(-1, order="F"))
            h = (float(T) if self.free_time else self.h0 * self.N) / self.N
            q, qd, qdd, jerk = (np.asarray(a, float) for a in (q, qd, qdd, jerk))
            qm, vm = [], []
            for k, i in self._mid_points():
                tau = h * i / (2 * self.n_sub)
                qm.append(q[k] + tau * qd[k] + tau**2 / 2 * qdd[k] + tau**3 / 6 * jerk[k])
                vm.append(qd[k] + tau * qdd[k] + tau**2 / 2 * jerk[k])
            parts += [np.concatenate(qm), self.h0 * np.concatenate(vm)]
        return np.concatenate(parts)

    def _mid_points(self) -> list[tuple[int, int]]:
        """(interval, half-sub-step index i ∈ 1..2 n_sub − 1) of the interior twist points."""
        m = 2 * self.n_sub
        return [(k, i) for k in range(self.N) for i in range(1, m)]

    # ------------------------------------------------------------------ expressions
    def q(self, k: int) -> Expr:
        return self.Q[:, k]

    def qd(self, k: int) -> Expr:
        return self.V[:, k]

    def qdd(self, k: int) -> Expr:
        return self.A[:, k]

    def jerk(self, k: int) -> Expr:
        return self.J[:, k]

    def knot_time(self, k: int) -> Expr:
        return self.h * k

    def dynamics_constraints(self) -> tuple[Expr, np.ndarray, np.ndarray]:
        """Exact integration of the piecewise-constant jerk (and the base quaternion)."""
        h = self.h
        r = h / self.h0 if self.free_time else 1.0  # h / h₀ (exactly 1 for a fixed duration)
        g = []
        for k in range(self.N):  # the integration in scaled variables: O(1) coefficients
            q, v, a, j = self.Q[:, k], self.Vs[:, k], self.As[:, k], self.Js[:, k]
            g.append(self.Q[:, k + 1] - (q + r * v + r**2 / 2 * a + r**3 / 6 * j))
            g.append(self.Vs[:, k + 1] - (v + r * a + r**2 / 2 * j))
            g.append(self.As[:, k + 1] - (a + r * j))
        if self.floating:
            g.append(self.QB[:, 0] - ca.DM(self.base0_quat))
            m = 2 * self.n_sub  # twist columns per interval
            mid = {ki: j for j, ki in enumerate(self._mid_points())}
            for (k, i), j in mid.items():  # the interior joint variables follow the cubic
                qq, vv = self._joint_at(k, h * i / m)
                g.append(self.QM[:, j] - qq)
                g.append(self.VMs[:, j] - self.h0 * vv)
            for c in range(m * self.N + 1):  # zero momentum at every half sub-step
                k, i = divmod(c, m)
                if i == 0:
                    qq, vv = self.Q[:, k], self.V[:, k]
                else:
                    qq, vv = self.QM[:, mid[(k, i)]], self.VMs[:, mid[(k, i)]] / self.h0
                g.append(self.momentum_fn(qq, self.U[:, c], vv))
            for k in range(self.N):
                x = self.QB[:, k]
                for s_ in range(self.n_sub):
                    c = m * k + 2 * s_
                    x = self.quat_step_fn(x, self.U[3:, c], self.U[3:, c + 1], self.U[3:, c + 2], h / self.n_sub)
                g.append(self.QB[:, k + 1] - x)
        G = ca.vertcat(*g)
        return G, np.zeros(G.shape[0]), np.zeros(G.shape[0])

    # ------------------------------------------------------------------ floating base
    def _joint_at(self, k: int, tau: Expr) -> tuple[Expr, Expr]:
        """Joint position and rate at time tau into interval k (exact cubic)."""
        q, v, a, j = self.Q[:, k], self.V[:, k], self.A[:, k], self.J[:, k]
        return q + tau * v + tau**2 / 2 * a + tau**3 / 6 * j, v + tau * a + tau**2 / 2 * j

    def _build_base_functions(self) -> None:
        if not self.floating:
            return
        got = _BASE_FUNCTIONS.get(self.robot)
        if got is None:   # symbolic momentum and RK4 step: once per robot (a problem's set_initial makes one)
            got = _BASE_FUNCTIONS[self.robot] = self._base_functions()
        self.momentum_fn, self.base_com_fn, self.quat_step_fn = got

    def _base_functions(self) -> tuple[ca.Function, ca.Function, ca.Function]:
        nj = self.nj
        qj, qdj, u = ca.SX.sym("qj", nj), ca.SX.sym("qdj", nj), ca.SX.sym("u", 6)
        qfull = ca.vertcat(ca.DM([0, 0, 0, 0, 0, 0, 1.0]), qj)
        X = self.sym.joint_placements(qfull)
        h = self.sym.momentum(qfull, ca.vertcat(u, qdj), X)
        momentum_fn = ca.Function("momentum", [qj, u, qdj], [h], ["qj", "u", "qdj"], ["h"])
        com_b = self.sym.center_of_mass(qfull, X)
        base_com_fn = ca.Function("base_com", [qj], [com_b], ["qj"], ["com_b"])
        quat, w0, wm, w1, hs = (ca.SX.sym(n, m) for n, m in (("quat", 4), ("w0", 3), ("wm", 3), ("w1", 3), ("h", 1)))

        def f(x: Expr, w: Expr) -> Expr:
            return 0.5 * quat_mul(x, ca.vertcat(w, 0))

        k1 = f(quat, w0)
        k2 = f(quat + hs / 2 * k1, wm)
        k3 = f(quat + hs / 2 * k2, wm)
        k4 = f(quat + hs * k3, w1)
        x = quat + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return momentum_fn, base_com_fn, ca.Function("quat_step", [quat, w0, wm, w1, hs], [x / ca.norm_2(x)])

    def base_quat(self, k: int) -> Expr:
        if not self.floating:
            return ca.DM([0, 0, 0, 1.0])
        return self.QB[:, k]

    def base_rotation(self, k: int) -> Expr:
        return quat_to_matrix(self.base_quat(k)) if self.floating else ca.DM.eye(3)

    def base_position(self, k: int) -> Expr:
        if not self.floating:
            return ca.DM.zeros(3)
        return ca.DM(self.com0) - self.base_rotation(k) @ self.base_com_fn(self.Q[:, k])

    def q_full(self, k: int) -> Expr:
        if not self.floating:
            return self.Q[:, k]
        return ca.vertcat(self.base_position(k), self.base_quat(k), self.Q[:, k])

    # ------------------------------------------------------------------ frames
    def _joints_function(self) -> ca.Function:
        """SX ``f(q_full) -> [R_1, p_1, ..., R_n, p_n]``: every joint placement in one pass (one call
        per knot instead of one chain per frame)."""
        if self._joints_fn is None:
            q = ca.SX.sym("q", self.robot.nq)
            X = self.sym.joint_placements(q)
            outs = []
            for R, p in X[1:]:
                outs += [R, p]
            self._joints_fn = ca.Function("joint_placements", [q], outs)
        return self._joints_fn

    def q_full_interior(self, k: int, frac: float) -> Expr:
        """Full configuration at fraction ``frac`` ∈ (0, 1) of interval k (exact cubic joints; for a
        floating robot the base pose is interpolated from the knots — use knots for base terms)."""
        qj, _ = self._joint_at(k, self.h * frac)
        if not self.floating:
            return qj
        raise ValueError("interior points are only available for fixed-base robots")

    def _joint_placements_at(self, k: Any, base_frame: bool = False) -> list[tuple[Expr, Expr]]:
        key = ("base", k) if base_frame else k
        if base_frame and not self.floating:
            key = k
        if key not in self._joint_cache:
            if base_frame and self.floating:
                q = ca.vertcat(ca.DM([0, 0, 0, 0, 0, 0, 1.0]), self.Q[:, k])
            else:
                q = self.q_full(k) if isinstance(k, int) else self.q_full_interior(*k)
            outs = self._joints_function()(q)
            self._joint_cache[key] = [(ca.DM.eye(3), ca.DM.zeros(3))] + [
                (outs[2 * i], outs[2 * i + 1]) for i in range(len(outs) // 2)]
        return self._joint_cache[key]

    def frame(self, frame: str | int, k: Any, base_frame: bool = False) -> tuple[Expr, Expr]:
        """World placement ``(R, p)`` of a frame at knot ``k`` (an int) or at the interior point
        ``k = (interval, fraction)`` (expressions, cached). ``base_frame=True``: the placement
        relative to the base (a function of the joints only; the same as world for a fixed base) —
        for base-invariant quantities such as the relative pose of two hands, whose derivatives are
        then much cheaper than through the floating base's pose."""
        fid = self.robot.frame_id(frame)
        key = (fid, k, bool(base_frame and self.floating))
        if key not in self._frame_cache:
            f = self.robot.model.frames[fid]
            Rj, pj = self._joint_placements_at(k, base_frame)[f.parentJoint]
            M = f.placement
            self._frame_cache[key] = (Rj @ ca.DM(np.array(M.rotation)), pj + Rj @ ca.DM(np.array(M.translation)))
        return self._frame_cache[key]

    def clear_caches(self) -> None:
        self._frame_cache.clear()
        self._joint_cache.clear()
