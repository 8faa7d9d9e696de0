"""Free-floating simulation: the base pose along a joint trajectory from momentum conservation.

The base of a free-floating robot is not actuated; with momentum ``h0`` (default 0) its twist is
``v_b = Ag_b⁻¹ (h0 − Ag_m q̇)``. :func:`simulate_base` integrates the base position and quaternion
with the classical 4th-order Runge-Kutta method on R³ × R⁴ (``ṗ = R v``, ``q̇uat = ½ quat ⊗ ω``,
quaternion renormalised after each step), sub-stepping each sample interval. With ``h0 = 0`` the
system is driftless: the final base pose depends only on the joint *path*, not on its timing.
"""
from __future__ import annotations

import functools
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigurationError, check_vector
from ..geometry.spatial import check_pose
from .robot import RobotModel

__all__ = ["FloatingResult", "simulate_base", "joint_trajectory_from_samples", "rk4_step", "zero_momentum_twists",
           "zero_momentum_rates", "attitudes_on_intervals"]
log = logging.getLogger(__name__)

JointTrajectory = Callable[[float], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class FloatingResult:
    """Result of :func:`simulate_base`.

    Attributes: ``t`` (N,) [s]; ``q`` (N, nq) full configurations (base XYZ-quaternion then joints);
    ``v`` (N, nv) full velocities (base twist in the base frame); ``momentum`` (N, 6) computed by
    Pinocchio's recursive ``computeCentroidalMomentum`` (independent of the map used to solve for
    the base twist); ``momentum_residual`` (N,) = ‖momentum − h0‖∞.
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    momentum: np.ndarray
    momentum_residual: np.ndarray

    @property
    def base_placements(self) -> list[pin.SE3]:
        return [pin.XYZQUATToSE3(qk[:7]) for qk in self.q]

    @property
    def base_rpy(self) -> np.ndarray:
        """(N, 3) base roll-pitch-yaw [rad] (``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""
        return np.array([pin.rpy.matrixToRpy(M.rotation) for M in self.base_placements])

    @property
    def final_base(self) -> pin.SE3:
        return pin.XYZQUATToSE3(self.q[-1, :7])


def rk4_step(f, t: float, x: np.ndarray, h: float, k1: np.ndarray | None = None) -> np.ndarray:
    """One classical Runge–Kutta step of ``ẋ = f(t, x)`` from ``(t, x)`` over ``h`` (``k1``:
    ``f(t, x)`` when the caller has it already)."""
    k1 = f(t, x) if k1 is None else k1
    k2 = f(t + h / 2, x + h / 2 * k1)
    k3 = f(t + h / 2, x + h / 2 * k2)
    k4 = f(t + h, x + h * k3)
    return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def joint_trajectory_from_samples(t, q_joints, qd_joints=None) -> JointTrajectory:
    """A callable ``traj(t) -> (q, q̇)`` from samples: cubic Hermite with the given rates, or a
    not-a-knot cubic spline when ``qd_joints`` is None."""
    t = np.asarray(t, float)
    Q = np.asarray(q_joints, float)
    if t.ndim != 1 or Q.ndim != 2 or Q.shape[0] != t.size:
        raise ConfigurationError(f"samples: expected t (N,) and q (N, nj), got {t.shape} and {Q.shape}")
    if np.any(np.diff(t) <= 0):
        raise ConfigurationError("samples: times must be strictly increasing")
    if qd_joints is None:
        from scipy.interpolate import CubicSpline  # lazy: 0.13 s of import
        sp = CubicSpline(t, Q, axis=0)
        dsp = sp.derivative()
        return lambda tt: (sp(tt), dsp(tt))
    from scipy.interpolate import CubicHermiteSpline

    sp = CubicHermiteSpline(t, Q, np.asarray(qd_joints, float), axis=0)
    dsp = sp.derivative()
    return lambda tt: (sp(tt), dsp(tt))


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions stored (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def simulate_base(robot: RobotModel, trajectory: JointTrajectory | tuple, t_grid,
                  base0: pin.SE3 | None = None, h0=None, substeps: int = 4, vectorised: bool = False,
                  momentum: bool = True) -> FloatingResult:
    """Integrate the free-floating base along a joint trajectory.

    Parameters
    ----------
    robot: a floating :class:`RobotModel`.
    trajectory: ``traj(t) -> (q_joints, q̇_joints)`` [rad, rad/s], or a tuple ``(t, q)`` /
        ``(t, q, q̇)`` of samples (interpolated by :func:`joint_trajectory_from_samples`).
    t_grid: (N,) output times [s], strictly increasing.
    base0: base placement at ``t_grid[0]`` (default identity).
    h0: momentum ``[p; L]`` about the CoM, world axes (default 0).
    substeps: RK4 steps per interval of ``t_grid``.
    vectorised: the callable ``trajectory`` also takes an array of M times and returns (M × nj)
        arrays (then, with zero momentum, it is called once for all times; samples are always).
    momentum: with zero momentum, False leaves out the cross-check (Pinocchio's recursive momentum
        at every output sample: ``momentum`` and ``momentum_residual`` are then NaN) when only the
        base poses are wanted; the base poses are the same.
    """
    if not robot.is_floating:
        raise ConfigurationError(f"simulate_base needs a free-floating robot; {robot.name!r} has a fixed base")
    vectorised = bool(vectorised) or isinstance(trajectory, tuple)   # (our own spline: many times at once)
    if isinstance(trajectory, tuple):
        trajectory = joint_trajectory_from_samples(*trajectory)
    t_grid = np.asarray(t_grid, float)
    if t_grid.ndim != 1 or t_grid.size < 2 or np.any(np.diff(t_grid) <= 0):
        raise ConfigurationError(f"t_grid: expected ≥ 2 strictly increasing times, got shape {t_grid.shape}")
    if int(substeps) < 1:
        raise ValueError(f"substeps: expected ≥ 1, got {substeps}")
    h0 = np.zeros(6) if h0 is None else check_vector(h0, 6, "h0 (momentum [p; L])")
    model = robot.model
    nj = robot.nj
    base0 = pin.SE3.Identity() if base0 is None else base0
    if not isinstance(base0, pin.SE3):
        raise ConfigurationError(f"base0: expected a pinocchio.SE3, got {type(base0).__name__}")
    check_pose(base0, "simulate_base: base0")
    x = pin.SE3ToXYZQUAT(base0).copy()

    if not isinstance(base0, pin.SE3):
        raise ConfigurationError(f"base0: expected a pinocchio.SE3, got {type(base0).__name__}")
    q_first, qd_first = trajectory(float(t_grid[0]))
    robot.check_joints(q_first, f"trajectory({t_grid[0]}) joint values")
    robot.check_joints(qd_first, f"trajectory({t_grid[0]}) joint rates")
    if not np.any(h0):
        return _simulate_zero_momentum(robot, trajectory, t_grid, x, int(substeps), vectorised, bool(momentum))
    data = model.createData()   # (not made for zero momentum: its twists need none)

    def twist(tt: float, xb: np.ndarray):
        qj, qdj = trajectory(tt)
        qj = np.asarray(qj, float).reshape(nj)
        qdj = np.asarray(qdj, float).reshape(nj)
        q = np.concatenate([xb, qj])
        Ag = pin.computeCentroidalMap(model, data, q)
        vb = np.linalg.solve(Ag[:, :6], h0 - Ag[:, 6:] @ qdj)
        return vb, q, qdj

    def deriv(tt: float, xb: np.ndarray) -> np.ndarray:
        xn = xb.copy()
        xn[3:] /= np.linalg.norm(xn[3:])
        vb, _, _ = twist(tt, xn)
        R = pin.XYZQUATToSE3(xn).rotation
        dq = 0.5 * _quat_mul(xn[3:], np.r_[vb[3:], 0.0])
        return np.concatenate([R @ vb[:3], dq])

    N = t_grid.size
    Q = np.empty((N, robot.nq))
    V = np.empty((N, robot.nv))
    H = np.empty((N, 6))

    def record(k: int, tt: float, xb: np.ndarray):
        vb, q, qdj = twist(tt, xb)
        v = np.concatenate([vb, qdj])
        h = pin.computeCentroidalMomentum(model, data, q, v)
        Q[k], V[k], H[k] = q, v, np.concatenate([h.linear, h.angular])

    record(0, t_grid[0], x)
    for k in range(N - 1):
        dt = (t_grid[k + 1] - t_grid[k]) / substeps
        tt = t_grid[k]
        for _ in range(substeps):
            x = rk4_step(deriv, tt, x, dt)
            x[3:] /= np.linalg.norm(x[3:])
            tt += dt
        record(k + 1, t_grid[k + 1], x)
    if not np.all(np.isfinite(Q)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(Q), axis=1))[0])
        raise ConfigurationError(f"simulate_base: non-finite state at t = {t_grid[bad]} s (the joint trajectory "
                                 "returned NaN/inf or a singular momentum map was met)")
    res = np.max(np.abs(H - h0), axis=1)
    log.debug("simulate_base: %d samples, max momentum residual %.3g", N, res.max())
    return FloatingResult(t_grid.copy(), Q, V, H, res)


def _base_rate_sx(x, w):
    """``[R v; ½ quat ⊗ [ω; 0]]`` of the base state ``x`` = [p; quat (x y z w)] (the quaternion
    normalised first) and the base-frame twist ``w`` = [v; ω], as CasADi expressions."""
    import casadi as ca

    q = x[3:7] / ca.sqrt(ca.sumsqr(x[3:7]))
    qx, qy, qz, qw = q[0], q[1], q[2], q[3]
    vx, vy, vz, ox, oy, oz = (w[i] for i in range(6))
    # R v = v + 2 qw (u × v) + 2 u × (u × v), u = (qx, qy, qz)
    cx, cy, cz = qy * vz - qz * vy, qz * vx - qx * vz, qx * vy - qy * vx
    ddx, ddy, ddz = qy * cz - qz * cy, qz * cx - qx * cz, qx * cy - qy * cx
    return ca.vertcat(vx + 2 * (qw * cx + ddx), vy + 2 * (qw * cy + ddy), vz + 2 * (qw * cz + ddz),
                      0.5 * (qw * ox + qy * oz - qz * oy), 0.5 * (qw * oy + qz * ox - qx * oz),
                      0.5 * (qw * oz + qx * oy - qy * ox), -0.5 * (qx * ox + qy * oy + qz * oz))


@functools.cache
def _rk4_base_chain(n: int):
    """CasADi ``mapaccum`` of ``n`` RK4 steps of the base state (as :func:`rk4_step` on the base
    rate, the quaternion renormalised after each step): ``(x0 (7), W (18 × n) = [w_start; w_mid;
    w_end] per step, dt (1 × n) [s]) -> X (7 × n)``, the state after each step. One call runs ``n``
    steps in CasADi's virtual machine (~7× faster than the same arithmetic on Python floats, and
    the same numbers)."""
    import casadi as ca

    x, w, dt = ca.SX.sym("x", 7), ca.SX.sym("w", 18), ca.SX.sym("dt")
    w0, wm, w1 = w[0:6], w[6:12], w[12:18]
    k1 = _base_rate_sx(x, w0)
    k2 = _base_rate_sx(x + dt / 2 * k1, wm)
    k3 = _base_rate_sx(x + dt / 2 * k2, wm)
    k4 = _base_rate_sx(x + dt * k3, w1)
    y = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    y = ca.vertcat(y[:3], y[3:] / ca.sqrt(ca.sumsqr(y[3:])))
    return ca.Function("rk4_base", [x, w, dt], [y]).mapaccum("rk4_base_chain", n)


def _rk4_base_steps(x0: np.ndarray, W: np.ndarray, dts: np.ndarray) -> np.ndarray:
    """(G, 7) base states after each of G RK4 steps from ``x0``, step g using the twists
    ``W[2g], W[2g+1], W[2g+2]`` (start, middle, end; W is (2G + 1) × 6) over ``dts[g]`` [s]."""
    G = dts.size
    n = 64 if G <= 256 else 1024           # steps per call (the last call padded with dt = 0)
    F = _rk4_base_chain(n)
    Wst = np.hstack([W[0:2 * G:2], W[1:2 * G:2], W[2:2 * G + 1:2]])     # (G, 18)
    out = np.empty((G, 7))
    x = np.asarray(x0, float)
    for a in range(0, G, n):
        m = min(n, G - a)
        Wc, dc = Wst[a:a + m].T, dts[a:a + m][None, :]
        if m < n:
            Wc = np.hstack([Wc, np.zeros((18, n - m))])
            dc = np.hstack([dc, np.zeros((1, n - m))])
        X = np.asarray(F(x, Wc, dc))
        out[a:a + m] = X[:, :m].T
        x = X[:, m - 1]
    return out


def _simulate_zero_momentum(robot: RobotModel, trajectory: JointTrajectory, t_grid: np.ndarray, x: np.ndarray,
                            substeps: int, vectorised: bool, momentum: bool = True) -> FloatingResult:
    """:func:`simulate_base` with zero momentum: the same RK4 scheme on the same times, with the
    base-frame twist of every time the scheme evaluates solved first (with zero momentum it does
    not depend on the base pose: :func:`zero_momentum_twists`, Pinocchio's centroidal map), the
    joint trajectory evaluated once per time (all at once when ``vectorised``: a spline of ours).
    The momentum at each output sample is then Pinocchio's recursive ``computeCentroidalMomentum``
    at the integrated base pose, as in the general case."""
    nj, N, m = robot.nj, t_grid.size, 2 * substeps
    # RK4 evaluates the rate at the start, middle and end of each step: m times per interval + the last
    frac = np.arange(m) / m
    fine = np.r_[(t_grid[:-1, None] + np.diff(t_grid)[:, None] * frac).ravel(), t_grid[-1]]
    if vectorised:
        qs, qds = (np.asarray(a, float).reshape(fine.size, nj) for a in trajectory(fine))
    else:
        ev = [trajectory(float(tt)) for tt in fine]
        qs = np.array([np.asarray(a, float).reshape(nj) for a, _ in ev])
        qds = np.array([np.asarray(b, float).reshape(nj) for _, b in ev])
    if not (np.all(np.isfinite(qs)) and np.all(np.isfinite(qds))):
        bad = int(np.flatnonzero(~(np.all(np.isfinite(qs), axis=1) & np.all(np.isfinite(qds), axis=1)))[0])
        raise ConfigurationError(f"simulate_base: non-finite state at t = {fine[bad]} s (the joint trajectory "
                                 "returned NaN/inf or a singular momentum map was met)")
    W = zero_momentum_twists(robot, qs, qds)          # (M, 6) base-frame [v; ω]

    X = np.empty((N, 7))
    X[0] = x
    # step g = k·substeps + s uses W[2g], W[2g + 1], W[2g + 2] (m = 2·substeps rates per interval)
    steps = _rk4_base_steps(x, W, np.repeat(np.diff(t_grid) / substeps, substeps))
    X[1:] = steps[substeps - 1::substeps]
    idx = np.arange(N) * m
    Q = np.hstack([X, qs[idx]])
    V = np.hstack([W[idx], qds[idx]])
    if not np.all(np.isfinite(Q)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(Q), axis=1))[0])
        raise ConfigurationError(f"simulate_base: non-finite state at t = {t_grid[bad]} s (the joint trajectory "
                                 "returned NaN/inf or a singular momentum map was met)")
    H = np.full((N, 6), np.nan)
    if momentum:
        model, data = robot.model, robot.model.createData()
        for k in range(N):
            h = pin.computeCentroidalMomentum(model, data, Q[k], V[k])
            H[k] = np.concatenate([h.linear, h.angular])
    res = np.max(np.abs(H), axis=1)
    log.debug("simulate_base: %d samples, max momentum residual %.3g", N, res.max())
    return FloatingResult(t_grid.copy(), Q, V, H, res)


def zero_momentum_twists(robot: RobotModel, q: np.ndarray, qd: np.ndarray, compiled: bool = True) -> np.ndarray:
    """(M, 6) base twists ``[v; ω]`` [m/s; rad/s] in the base frame with zero momentum, at the
    joint states ``q``, ``q̇`` (M × nj) [rad, rad/s]. With zero momentum the base-frame twist does
    not depend on the base placement (the centroidal map turns with the base), so it is solved
    once per state, with the base at the identity: ``v_b = −Ag_b⁻¹ Ag_m q̇``.

    ``compiled`` (default): many states at once through one compiled CasADi function of the
    symbolic centroidal map (:class:`~optplan.model.symbolic.SymbolicKinematics`) mapped over
    chunks of states (~3× faster than a Pinocchio call per state; the same twists to ~1e-15,
    checked against Pinocchio by the tests); without a C compiler, or ``compiled=False``:
    Pinocchio's ``computeCentroidalMap`` and a 6 × 6 solve per state."""
    q, qd = np.atleast_2d(np.asarray(q, float)), np.atleast_2d(np.asarray(qd, float))
    if q.shape != qd.shape or q.shape[1] != robot.nj:
        raise ConfigurationError(f"zero_momentum_twists: expected q and qd of shape (M, {robot.nj}), got "
                                 f"{q.shape} and {qd.shape}")
    kernels = _twist_kernels(robot) if compiled and q.shape[0] >= _SMALL_CHUNK else None
    if kernels is not None:
        return _twists_compiled(kernels, q, qd)
    model, data = robot.model, robot.model.createData()
    full = robot.configuration(np.zeros(robot.nj))
    A = np.empty((q.shape[0], 6, 6))
    b = np.empty((q.shape[0], 6))
    for i in range(q.shape[0]):
        full[7:] = q[i]
        Ag = pin.computeCentroidalMap(model, data, full)
        A[i] = Ag[:, :6]
        b[i] = -Ag[:, 6:] @ qd[i]
    return np.linalg.solve(A, b[:, :, None])[:, :, 0]


#: states per call of the compiled twist functions (a large chunk for the bulk, a small one for the rest)
_BIG_CHUNK, _SMALL_CHUNK = 256, 16
#: per (robot model, part): (the model, kept alive so that its id stays unique; the compiled functions, or None)
_TWIST_FNS: dict[tuple[int, str], tuple[Any, Any]] = {}
_TWIST_LOCK = threading.Lock()


def _zero_momentum_function(robot: RobotModel, part: str) -> Any:
    """The symbolic zero-momentum base rate ``(q_j, q̇_j) ->`` the twist ``[v; ω]`` (``part =
    "twist"``) or only ``ω`` (``"omega"``); ``"com"``: the centre of mass in the base frame. With ``A = Ag[:, :6] = [[A11, A12], [A21, A22]]`` and
    ``b = −Ag[:, 6:] q̇``, ``ω`` is the solution of the Schur complement system
    ``(A22 − A21 A11⁻¹ A12) ω = b2 − A21 A11⁻¹ b1`` (``A11 = m I``: the linear momentum of the
    base's own translation), which skips the linear velocity's back-substitution."""
    import casadi as ca

    from .symbolic import SymbolicKinematics

    sk = SymbolicKinematics(robot)
    qj, qdj = ca.SX.sym("qj", robot.nj), ca.SX.sym("qdj", robot.nj)
    Ag = sk.centroidal_map(ca.vertcat(ca.DM([0, 0, 0, 0, 0, 0, 1.0]), qj))
    if part == "com":   # the centre of mass [m] in the base frame (q̇ unused)
        com = sk.center_of_mass(ca.vertcat(ca.DM([0, 0, 0, 0, 0, 0, 1.0]), qj))
        return ca.Function("base_frame_com", [qj, qdj], [com])
    A, b = Ag[:, :6], -Ag[:, 6:] @ qdj
    if part == "twist":
        return ca.Function("zero_momentum_twist", [qj, qdj], [ca.solve(A, b)])
    S = A[3:, 3:] - A[3:, :3] @ ca.solve(A[:3, :3], A[:3, 3:])
    r = b[3:] - A[3:, :3] @ ca.solve(A[:3, :3], b[:3])
    return ca.Function("zero_momentum_omega", [qj, qdj], [ca.solve(S, r)])


def _twist_kernels(robot: RobotModel, part: str = "twist") -> Any:
    """``{chunk: FastFunction}``: ``(q_j (nj × chunk), q̇_j (nj × chunk)) -> rates (r × chunk)``
    compiled (set-up memo keyed by the robot's kinematics digest and ``part``: ``"twist"``, r = 6,
    ``"omega"`` or ``"com"``, r = 3, :func:`_zero_momentum_function`); None without a C compiler."""
    key = (id(robot.model), part)
    got = _TWIST_FNS.get(key)
    if got is not None and got[0] is robot.model:
        return got[1]
    from ..codegen import FastFunction, memo_functions
    from .digest import kinematics_digest

    name = f"zero_momentum_{part}"

    def build() -> dict[str, Any]:
        f = _zero_momentum_function(robot, part)
        return {f"map{n}": f.map(f"{name}_{n}", "serial", n, [], []) for n in (_BIG_CHUNK, _SMALL_CHUNK)}

    fns: Any = None
    try:
        memo = memo_functions(name, (kinematics_digest(robot),), build)
        fast = {n: FastFunction.of(memo, f"map{n}", "-O1") for n in (_BIG_CHUNK, _SMALL_CHUNK)}
        if all(f.compiled for f in fast.values()):
            fns = fast
    except Exception as exc:   # noqa: BLE001 - any failure to build or compile: Pinocchio per state
        log.warning("zero_momentum_twists: the compiled %s rates are not available (%s); Pinocchio per state",
                    part, exc)
    _TWIST_FNS[key] = (robot.model, fns)
    return fns


def _twists_compiled(kernels: Any, q: np.ndarray, qd: np.ndarray, rows: int = 6) -> np.ndarray:
    """:func:`zero_momentum_twists` (``rows`` = 6) or its angular rows (3) through the compiled
    chunks (the last one padded with zeros)."""
    M = q.shape[0]
    out = np.empty((M, rows))
    with _TWIST_LOCK:   # the compiled functions' work buffers are shared
        a = 0
        while a < M:
            n = _BIG_CHUNK if M - a >= _BIG_CHUNK else _SMALL_CHUNK
            m = min(n, M - a)
            qc, qdc = q[a:a + m], qd[a:a + m]
            if m < n:
                qc = np.vstack([qc, np.zeros((n - m, q.shape[1]))])
                qdc = np.vstack([qdc, np.zeros((n - m, q.shape[1]))])
            out[a:a + m] = kernels[n](qc.ravel(), qdc.ravel()).reshape(n, rows)[:m]
            a += m
    return out


def base_frame_coms(robot: RobotModel, q: np.ndarray) -> np.ndarray | None:
    """(M, 3) the centre of mass [m] in the base frame at the joint positions ``q`` (M × nj)
    [rad], through a compiled kernel (the symbolic centre of mass, equal to Pinocchio's
    ``centerOfMass`` to rounding); None when fewer than a small chunk of rows are asked or no C
    compiler is there (the caller then asks Pinocchio per row)."""
    q = np.atleast_2d(np.asarray(q, float))
    if q.shape[0] < _SMALL_CHUNK or q.shape[1] != robot.nj:
        return None
    kernels = _twist_kernels(robot, "com")
    if kernels is None:
        return None
    return _twists_compiled(kernels, q, np.zeros_like(q), rows=3)


def zero_momentum_rates(robot: RobotModel, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """(M, 3) the angular rows ``ω`` [rad/s] of :func:`zero_momentum_twists` (base frame), at the
    joint states ``q``, ``q̇`` (M × nj) [rad, rad/s]: through a compiled kernel of ``ω`` alone
    (the Schur complement of the base's linear rows, :func:`_zero_momentum_function`) when many
    states are asked and a C compiler is there, else the full twists' angular rows."""
    q, qd = np.atleast_2d(np.asarray(q, float)), np.atleast_2d(np.asarray(qd, float))
    if q.shape != qd.shape or q.shape[1] != robot.nj:
        raise ConfigurationError(f"zero_momentum_rates: expected q and qd of shape (M, {robot.nj}), got "
                                 f"{q.shape} and {qd.shape}")
    kernels = _twist_kernels(robot, "omega") if q.shape[0] >= _SMALL_CHUNK else None
    if kernels is not None:
        return _twists_compiled(kernels, q, qd, rows=3)
    return zero_momentum_twists(robot, q, qd)[:, 3:]


def _quat_mul_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Quaternion products ``a ⊗ b`` (x y z w, the last axis), broadcast over the others."""
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([aw * bx + bw * ax + ay * bz - az * by,
                     aw * by + bw * ay + az * bx - ax * bz,
                     aw * bz + bw * az + ax * by - ay * bx,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def attitudes_on_intervals(robot: RobotModel, joints: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                           t: np.ndarray, quat0: np.ndarray, density: int, substeps: int = 2) -> np.ndarray:
    """Zero-momentum base quaternions (x y z w) at the sample times ``t`` [s] (``density`` samples
    per interval: ``t[k·density]`` starts interval k), each interval integrated from its own start
    quaternion ``quat0[k]`` along the joint trajectory ``joints(ts) -> (q, q̇)`` (vectorised over
    the times ``ts``, (M, nj) each). The same RK4 scheme as :func:`simulate_base` (``substeps``
    steps per sample, quaternion renormalised after each) on all intervals at once; the last row
    is ``quat0[-1]`` (the end knot's own quaternion)."""
    t = np.asarray(t, float)
    q0 = np.asarray(quat0, float)
    K = q0.shape[0] - 1
    if t.ndim != 1 or t.size != K * density + 1 or density < 1 or substeps < 1:
        raise ConfigurationError(f"attitudes_on_intervals: expected {K} intervals of {density} samples "
                                 f"({K * density + 1} times) and substeps ≥ 1, got {t.shape} times, substeps {substeps}")
    m = 2 * substeps                  # RK4 evaluates the rate at the start, middle and end of each step
    frac = np.arange(m) / m
    fine = np.r_[(t[:-1, None] + np.diff(t)[:, None] * frac).ravel(), t[-1]]
    qs, qds = joints(fine)
    W = zero_momentum_rates(robot, qs, qds)
    x = q0[:-1] / np.linalg.norm(q0[:-1], axis=1, keepdims=True)
    out = np.empty((t.size, 4))
    starts = np.arange(K) * density   # the first sample of each interval
    # Every RK4 stage is x ⊗ p for a quaternion p made of the rates alone: the rate ½ x ⊗ [ω; 0]
    # at a normalised stage x ⊗ b / |b| (|x ⊗ b| = |b| for a unit x) is x ⊗ (b ⊗ [ω; 0] / 2|b|).
    # So a whole step is x ⊗ P = R(P) x with P built for all steps at once — the same scheme and
    # stages as simulate_base, its products reordered (equal to rounding, ~1e-16).
    Wq = np.zeros((W.shape[0], 4))
    Wq[:, :3] = W
    first = (starts[None, :] + np.arange(density)[:, None]) * m                        # density × K
    at = first[:, None, :] + 2 * np.arange(substeps)[None, :, None]                    # density × substeps × K
    w0, wm, w1 = Wq[at], Wq[at + 1], Wq[at + 2]
    h = (np.diff(t)[starts[None, :] + np.arange(density)[:, None]] / substeps)[:, None, :, None]
    one = np.array([0.0, 0.0, 0.0, 1.0])

    def stage(b: np.ndarray, w: np.ndarray) -> np.ndarray:
        return _quat_mul_rows(b, w) / (2.0 * np.sqrt((b * b).sum(axis=-1, keepdims=True)))

    a1 = 0.5 * w0
    a2 = stage(one + h / 2 * a1, wm)
    a3 = stage(one + h / 2 * a2, wm)
    a4 = stage(one + h * a3, w1)
    px, py, pz, pw = np.moveaxis(one + h / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4), -1, 0)   # density × substeps × K
    R = np.stack([np.stack([pw, pz, -py, px], -1), np.stack([-pz, pw, px, py], -1),      # x ⊗ P = R x
                  np.stack([py, -px, pw, pz], -1), np.stack([-px, -py, -pz, pw], -1)], -2)
    # the normalisation after each step only scales x, which the linear steps carry along: the
    # products of the steps' matrices from each interval's start, normalised once per sample
    step = R[:, 0]
    for s in range(1, substeps):
        step = np.matmul(R[:, s], step)                                                # density × K × 4 × 4
    C = np.empty_like(step)
    C[0] = np.eye(4)
    for j in range(1, density):
        C[j] = np.matmul(step[j - 1], C[j - 1])
    X = np.einsum("jkab,kb->jka", C, x)
    X /= np.sqrt(np.einsum("jka,jka->jk", X, X))[:, :, None]
    out[:-1] = X.transpose(1, 0, 2).reshape(K * density, 4)
    out[-1] = q0[-1] / np.linalg.norm(q0[-1])
    return out
