"""The peer of ``optplan bench modelling``: its tasks written in rockit (``pip install
rockit-meco``, extra ``rockit``), solved by the same IPOPT and checked by the same
:func:`~optplan.verification.verify`.

The trajectory class is the same as the kernel core's: states q, q̇, q̈ and a piecewise-constant
jerk (a cubic spline, C² — what the core's B-spline is), multiple shooting on N intervals, the
rows at the N + 1 grid points. The kinematics are optplan's CasADi expressions of the robot
(a rockit user brings their own; these are exact and checked against Pinocchio).

* ``transport`` — closed chain (relative pose of the hands, at the grid points), joint position
  and velocity limits at the grid points, rest at both ends, minimum jerk, guess: the same knot
  path. rockit has no collision model: the rows of collision avoidance are **not** in its
  problem (a user would write point–plane distances by hand); ``verify`` reports its clearance.
* ``reach`` (free-floating) — rockit has no floating base: the zero-momentum base is written by
  hand as a rockit user must (a base-attitude quaternion state, ``ξ̇ = ½ ξ ⊗ [ω; 0]`` with the body
  rate ω solved from zero angular momentum about the fixed centre of mass, the hand placed through
  the base), with optplan's CasADi momentum map. Guess: the start configuration held (rockit has
  no seeded guess; ours is seeded from the rows without user code).
"""
from __future__ import annotations

import time
from typing import Any

import casadi as ca
import numpy as np

__all__ = ["available", "REACH_NOTE", "CubicSolution", "transport", "reach"]

REACH_NOTE = "rockit has no free-floating base: zero momentum and the base attitude written by hand"


def available() -> bool:
    """Whether rockit is installed."""
    try:
        import rockit  # noqa: F401
    except ImportError:
        return False
    return True


class CubicSolution:
    """A rockit solution as optplan's checks read it: knot times ``t`` [s], knot values and the
    piecewise-constant jerk; :meth:`sample` evaluates the exact cubic between knots."""

    def __init__(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, jerk: np.ndarray):
        self.t, self.q, self.qd, self.qdd, self.jerk = t, q, qd, qdd, jerk
        self.duration = float(t[-1] - t[0])
        self.base_quat: np.ndarray | None = None        # (N+1) × 4, x y z w (floating)
        self.base_position: np.ndarray | None = None    # (N+1) × 3 [m] (floating)

    def sample(self, ts: Any) -> dict[str, np.ndarray]:
        ts = np.atleast_1d(np.asarray(ts, float))
        k = np.clip(np.searchsorted(self.t, ts, side="right") - 1, 0, len(self.t) - 2)
        tau = (ts - self.t[k])[:, None]
        j = self.jerk[k]
        return {"q": self.q[k] + self.qd[k] * tau + self.qdd[k] * tau**2 / 2 + j * tau**3 / 6,
                "qd": self.qd[k] + self.qdd[k] * tau + j * tau**2 / 2,
                "qdd": self.qdd[k] + j * tau, "jerk": j}


def transport(robot: Any, Q: np.ndarray, cc: Any, duration: float = 60.0, tol: float = 1e-6,
              upright: tuple[int, np.ndarray, float] | None = None, acceleration_weight: float = 0.0) -> dict[str, Any]:
    """The transport of :func:`optplan.tasks.transport_problem` (without collision rows) in
    rockit, from the knot path ``Q`` ((N+1) × nj); the build and solve times [s], IPOPT
    iterations, success and the solution (:class:`CubicSolution`). ``upright = (frame id,
    R_grasp, c_min)``: also ``(R_frame R_graspᵀ)[2, 2] ≥ c_min`` at the grid points (the object
    stays upright); ``acceleration_weight``: also ``w ∫‖q̈‖² dt`` [1/s³]."""
    from rockit import MultipleShooting, Ocp

    from ..geometry.spatial import pose_residual
    from ..problem.kernels import KernelCache

    N, nj = len(Q) - 1, robot.nj
    c0, t0 = time.process_time(), time.perf_counter()
    kc = KernelCache.of(robot)
    fa, fb = (kc.frame(robot.arm(a).ee_frame_id) for a in (cc.arm_a, cc.arm_b))
    (Ra, pa), (Rb, pb) = fa, fb
    r, tr = pose_residual(Ra.T @ Rb, Ra.T @ (pb - pa), np.array(cc.relative.rotation),
                          ca.DM(np.array(cc.relative.translation)))
    chain = ca.Function("chain", [kc._q], [ca.vertcat(r, tr)])

    ocp = Ocp(T=float(duration))
    q, qd, qdd = ocp.state(nj), ocp.state(nj), ocp.state(nj)
    jerk = ocp.control(nj)
    ocp.set_der(q, qd)
    ocp.set_der(qd, qdd)
    ocp.set_der(qdd, jerk)
    z = np.zeros(nj)
    ocp.subject_to(ocp.at_t0(q) == Q[0])
    ocp.subject_to(ocp.at_tf(q) == Q[-1])
    for v in (qd, qdd):
        ocp.subject_to(ocp.at_t0(v) == z)
        ocp.subject_to(ocp.at_tf(v) == z)
    e = chain(q)
    ocp.subject_to(e[:6] == 0)
    ocp.subject_to(e[6] >= 1)
    ocp.subject_to(robot.lower <= (q <= robot.upper))
    ocp.subject_to(-robot.velocity_limit <= (qd <= robot.velocity_limit))
    ocp.add_objective(ocp.integral(ca.sumsqr(jerk)))
    if upright is not None:            # one line each in rockit too
        fid, Rg, cmin = upright
        up = ca.Function("upright", [kc._q], [(kc.frame(fid)[0] @ ca.DM(np.asarray(Rg).T))[2, 2]])
        ocp.subject_to(up(q) >= cmin)
    if acceleration_weight:
        ocp.add_objective(acceleration_weight * ocp.integral(ca.sumsqr(qdd)))
    h = duration / N
    V = np.gradient(Q, h, axis=0)
    A = np.gradient(V, h, axis=0)
    ocp.set_initial(q, Q.T)
    ocp.set_initial(qd, V.T)
    ocp.set_initial(qdd, A.T)
    ocp.set_initial(jerk, (np.diff(A, axis=0) / h).T)
    ocp.solver("ipopt", {"expand": True, "print_time": False,
                         "ipopt": {"print_level": 0, "tol": tol, "constr_viol_tol": tol, "sb": "yes"}})
    ocp.method(MultipleShooting(N=N))
    built, cb = time.perf_counter(), time.process_time()
    try:
        sol = ocp.solve()
        stats, ok = sol.stats, True
    except RuntimeError:   # rockit raises on a failed solve; its last iterate is in non_converged_solution
        sol = ocp.non_converged_solution
        stats, ok = sol.stats, False
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    ts, Qs = sol.sample(q, grid="control")
    _, Vs = sol.sample(qd, grid="control")
    _, As = sol.sample(qdd, grid="control")
    _, Js = sol.sample(jerk, grid="control")
    out = CubicSolution(np.asarray(ts, float), np.asarray(Qs), np.asarray(Vs), np.asarray(As), np.asarray(Js))
    return {"total_s": wall, "total_cpu_s": cpu, "build_s": built - t0, "solve_cpu_s": cpu - (cb - c0),
            "iterations": int(stats.get("iter_count", -1)), "success": bool(ok and stats.get("success", False)),
            "cost": float(np.sum(np.sum(np.asarray(Js)[:-1] ** 2, axis=1)) * h), "solution": out}


def _qmul_w(xi: Any, w: Any) -> Any:
    """``ξ ⊗ [w; 0]`` (x y z w)."""
    v, s = xi[:3], xi[3]
    return ca.vertcat(s * w + ca.cross(v, w), -ca.dot(v, w))


def reach(robot: Any, q0: np.ndarray, target: np.ndarray, frame: str, N: int = 20, duration: float = 20.0,
          still: slice = slice(7, None), tol: float = 1e-6, free_time: bool = False,
          duration_bounds: tuple[float, float] = (2.0, 60.0), velocity_limit: float = 0.1,
          acceleration_limit: float = 0.02, jerk_weight: float = 1e-2) -> dict[str, Any]:
    """The free-floating reach of ``optplan bench modelling`` in rockit: ``frame`` to ``target``
    [m] (world; base starts at the identity), joints ``still`` at rest throughout, rest at both
    ends, base attitude back to the start at the end, minimum jerk. ``free_time``: the duration
    free within ``duration_bounds`` [s] (rockit's ``FreeTime``, guess ``duration``),
    ``|q̇| ≤ velocity_limit`` [rad/s] and ``|q̈| ≤ acceleration_limit`` [rad/s²] at the grid
    points, cost ``T + jerk_weight ∫‖j‖² dt``."""
    from rockit import FreeTime, MultipleShooting, Ocp

    from ..problem.floating_kernels import FloatingKernels

    nj = robot.nj
    c0, t0 = time.process_time(), time.perf_counter()
    kc = FloatingKernels.of(robot)
    assert isinstance(kc, FloatingKernels)
    qs = kc._q
    R_h, p_h = kc.frame(robot.model.getFrameId(frame))          # in the base frame
    com = kc.sym.center_of_mass(kc._configuration(qs), kc._X)    # in the base frame
    mom = kc.momentum()
    qd_s, w_s = ca.SX.sym("qd", nj), ca.SX.sym("w", 3)
    m = mom(ca.vertcat(qs, qd_s, w_s))
    A_w = ca.jacobian(m, w_s)
    omega = ca.Function("omega", [qs, qd_s], [-ca.solve(A_w, ca.substitute(m, w_s, ca.DM.zeros(3)))])
    hand_rel = ca.Function("hand_rel", [qs], [p_h - com])
    com0 = np.asarray(ca.Function("c", [qs], [com])(q0)).ravel()

    ocp = Ocp(T=FreeTime(float(duration)) if free_time else float(duration))
    q, qd, qdd = ocp.state(nj), ocp.state(nj), ocp.state(nj)
    xi = ocp.state(4)
    jerk = ocp.control(nj)
    ocp.set_der(q, qd)
    ocp.set_der(qd, qdd)
    ocp.set_der(qdd, jerk)
    ocp.set_der(xi, 0.5 * _qmul_w(xi, omega(q, qd)))
    z = np.zeros(nj)
    ocp.subject_to(ocp.at_t0(q) == q0)
    ocp.subject_to(ocp.at_t0(xi) == np.array([0, 0, 0, 1.0]))
    for v in (qd, qdd):
        ocp.subject_to(ocp.at_t0(v) == z)
        ocp.subject_to(ocp.at_tf(v) == z)
    ocp.subject_to(qd[still] == 0, include_first=False)
    x, y, zz, w = (xi[i] for i in range(4))
    R = ca.vertcat(ca.horzcat(1 - 2 * (y * y + zz * zz), 2 * (x * y - zz * w), 2 * (x * zz + y * w)),
                   ca.horzcat(2 * (x * y + zz * w), 1 - 2 * (x * x + zz * zz), 2 * (y * zz - x * w)),
                   ca.horzcat(2 * (x * zz - y * w), 2 * (y * zz + x * w), 1 - 2 * (x * x + y * y)))
    ocp.subject_to(ocp.at_tf(com0 + R @ hand_rel(q)) == target)
    ocp.subject_to(ocp.at_tf(xi[:3]) == 0)
    if free_time:
        ocp.subject_to(duration_bounds[0] <= (ocp.T <= duration_bounds[1]))
        ocp.subject_to(-velocity_limit <= (qd <= velocity_limit))
        ocp.subject_to(-acceleration_limit <= (qdd <= acceleration_limit))
        ocp.add_objective(ocp.T + jerk_weight * ocp.integral(ca.sumsqr(jerk)))
    else:
        ocp.add_objective(ocp.integral(ca.sumsqr(jerk)))
    ocp.set_initial(q, q0)
    ocp.set_initial(xi, np.array([0, 0, 0, 1.0]))
    ocp.solver("ipopt", {"expand": True, "print_time": False,
                         "ipopt": {"print_level": 0, "tol": tol, "constr_viol_tol": tol, "sb": "yes", "max_iter": 1000}})
    ocp.method(MultipleShooting(N=N))
    built = time.perf_counter()
    try:
        sol = ocp.solve()
        stats, ok = sol.stats, True
    except RuntimeError:
        sol = ocp.non_converged_solution
        stats, ok = sol.stats, False
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    ts, Qs = sol.sample(q, grid="control")
    Vs, As, Js, Xs = (np.asarray(sol.sample(e, grid="control")[1]) for e in (qd, qdd, jerk, xi))
    out = CubicSolution(np.asarray(ts, float), np.asarray(Qs), Vs, As, Js)
    Xs = Xs / np.linalg.norm(Xs, axis=1, keepdims=True)
    out.base_quat = Xs
    cfn = ca.Function("c", [qs], [com])
    pos = []
    for qk, xk in zip(np.asarray(Qs), Xs):
        Rk = _rot(xk)
        pos.append(com0 - Rk @ np.asarray(cfn(qk)).ravel())
    out.base_position = np.array(pos)
    return {"total_s": wall, "total_cpu_s": cpu, "build_s": built - t0, "iterations": int(stats.get("iter_count", -1)),
            "success": bool(ok and stats.get("success", False)), "solution": out}


def _rot(xq: np.ndarray) -> np.ndarray:
    import pinocchio as pin

    return pin.Quaternion(xq[3], *xq[:3]).normalized().toRotationMatrix()
