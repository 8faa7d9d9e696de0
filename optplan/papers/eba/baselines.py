"""The paper's baselines (the EBA paper, Section 4): the 5th-order polynomial in joint space (Eq. 34),
the leader-follower method for the end-constrained case, and the "near-optimal" Fourier method
(Eq. 35) — solved here with IPOPT instead of the paper's modified quasi-Newton method.

Fourier method (what we solve)
------------------------------
Joint rates ``u_j(t) = k_j0/2 + Σ_{i=1..h} [kc_ji cos(2πit/T) + ks_ji sin(2πit/T)]`` (h = 3: 7
coefficients per joint, 98 in all), integrated in closed form to ``θ(t)`` (so ``θ(T) = θ0 + k0 T/2``).
The base quaternion is integrated by RK4 (``n_steps`` steps, zero momentum, CasADi mirror of the
centroidal map). IPOPT (limited-memory Hessian) solves

    min  (1/T) ∫‖u‖² dt + penalty·‖θ(T) − θf‖² [+ penalty·mean_k ‖r_cc(t_k)‖²]
    s.t. final base attitude = initial (3 equations), |u_j(t_k)| ≤ velocity limit at samples.

The paper minimises the final attitude with a 1e4 penalty on the final joint error; with IPOPT
the attitude becomes an exact constraint, the penalty (1e4) is kept for the final joints (and, in
the end-constrained case, for the closed-chain residual at ``closed_chain_samples`` instants,
which a 98-coefficient Fourier series cannot keep exactly), and the effort term makes the
minimiser unique. The velocities do not vanish at t = 0 and T — the jumps the paper reports.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np
import pinocchio as pin

from ...constraints.closed_chain import relative_pose_residual
from ...geometry.splines import quintic_time_law
from ...model.robot import RobotModel
from ...model.symbolic import SymbolicKinematics
from ...problem.nlp import NlpSolver, SolverOptions
from .core import EBAKinematics, MethodResult, Scenario, Segment, hermite_segment, integrate_rpy, rpy_matrix

__all__ = ["QuinticOptions", "LeaderFollowerOptions", "FourierOptions", "run_quintic",
           "run_leader_follower", "run_fourier", "quintic_profile", "closed_chain_reference"]
log = logging.getLogger(__name__)


def _check_positive(owner: str, **kw) -> None:
    for n, v in kw.items():
        if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
            raise ValueError(f"{owner}.{n}: expected a positive finite number, got {v!r}")


def _check_int(owner: str, minimum: int, **kw) -> None:
    for n, v in kw.items():
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < minimum:
            raise ValueError(f"{owner}.{n}: expected an integer ≥ {minimum}, got {v!r}")


quintic_profile = quintic_time_law   # (p, p', p'') of the rest-to-rest quintic (:mod:`optplan.geometry.splines`)


# --------------------------------------------------------------------------- 5th-order polynomial
@dataclass(frozen=True)
class QuinticOptions:
    """Eq. 34 with zero boundary velocity and acceleration."""

    #: Duration of the motion [s] (the paper: 20).
    duration: float = 20.0
    #: Samples of the output trajectory [count].
    samples: int = 401

    def __post_init__(self):
        _check_positive("QuinticOptions", duration=self.duration)
        _check_int("QuinticOptions", 3, samples=self.samples)


def run_quintic(robot: RobotModel, scenario: Scenario, options: QuinticOptions | None = None) -> MethodResult:
    """Joint-space quintic from θ0 to θf; the planned base attitude is the paper's Eq. 1 (RPY)
    integrated along it."""
    o = options or QuinticOptions()
    t0 = time.perf_counter()
    T = o.duration
    t = np.linspace(0.0, T, o.samples)
    p, dp, ddp = quintic_profile(t / T)
    d = scenario.thetaf - scenario.theta0
    seg = Segment(t, scenario.theta0 + p[:, None] * d, dp[:, None] * d / T, ddp[:, None] * d / T**2)
    rpy = integrate_rpy(EBAKinematics(robot), [seg])
    return MethodResult("quintic", [seg], time.perf_counter() - t0, rpy_matrix(rpy[-1]),
                        info={"options": o.__dict__.copy()})


# --------------------------------------------------------------------------- leader-follower
@dataclass(frozen=True)
class LeaderFollowerOptions:
    """Leader-follower (the EBA paper, Section 4.2): the leader arm follows the quintic to its goal; the
    follower solves ``H_F θ̇_F = −H_L θ̇_L − K e`` (velocity-level IK keeping the relative hand pose;
    minimum-norm, ``e`` the relative-pose error).
    """

    #: Duration of the motion [s] (the paper: 20).
    duration: float = 20.0
    #: The leader arm's name.
    leader: str = "A"
    #: RK4 step [s].
    dt: float = 0.02
    #: K: gain of the closed-loop correction of integration drift [1/s].
    clik_gain: float = 5.0

    def __post_init__(self):
        _check_positive("LeaderFollowerOptions", duration=self.duration, dt=self.dt)
        if not (np.isfinite(self.clik_gain) and self.clik_gain >= 0):
            raise ValueError(f"LeaderFollowerOptions.clik_gain: expected a finite number ≥ 0, got {self.clik_gain!r}")
        if self.dt > self.duration / 10:
            raise ValueError(f"LeaderFollowerOptions.dt: {self.dt} s is too large for {self.duration} s")


def run_leader_follower(robot: RobotModel, scenario: Scenario,
                        options: LeaderFollowerOptions | None = None) -> MethodResult:
    """Leader by quintic, follower by velocity-level IK (end-constrained scenario)."""
    o = options or LeaderFollowerOptions()
    if not scenario.closed_chain:
        raise ValueError("run_leader_follower needs an end-constrained scenario")
    t_start = time.perf_counter()
    kin = EBAKinematics(robot)
    lead = robot.arm(o.leader).j_idx
    follow = np.array([j for j in range(robot.nj) if j not in set(lead.tolist())])
    T = o.duration
    dL = scenario.thetaf[lead] - scenario.theta0[lead]
    rel0 = scenario.relative

    def leader(t):
        p, dp, ddp = quintic_profile(np.clip(t / T, 0.0, 1.0))
        return scenario.theta0[lead] + p * dL, dp * dL / T

    def follower_rate(t, thF):
        qL, vL = leader(t)
        th = np.empty(robot.nj)
        th[lead], th[follow] = qL, thF
        H = kin.constraint_jacobian(th)
        rhs = -H[:, lead] @ vL
        if o.clik_gain > 0:
            e, Ra = kin.closed_chain_error(th, rel0)
            rhs -= o.clik_gain * np.concatenate([Ra @ e[:3], Ra @ e[3:]])
        return np.linalg.lstsq(H[:, follow], rhs, rcond=None)[0]

    n = int(round(T / o.dt))
    h = T / n
    ts = np.linspace(0.0, T, n + 1)
    x = scenario.theta0[follow].copy()
    Q = np.empty((n + 1, robot.nj))
    V = np.empty((n + 1, robot.nj))
    for i in range(n + 1):
        t = ts[i]
        k1 = follower_rate(t, x)
        qL, vL = leader(t)
        Q[i, lead], Q[i, follow] = qL, x
        V[i, lead], V[i, follow] = vL, k1
        if i == n:
            break
        k2 = follower_rate(t + h / 2, x + h / 2 * k1)
        k3 = follower_rate(t + h / 2, x + h / 2 * k2)
        k4 = follower_rate(t + h, x + h * k3)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    seg = hermite_segment(ts, Q, V)
    rpy = integrate_rpy(kin, [seg])
    return MethodResult("leader_follower", [seg], time.perf_counter() - t_start, rpy_matrix(rpy[-1]),
                        info={"options": o.__dict__.copy(),
                              "follower_final_error_deg": float(np.rad2deg(np.max(np.abs(
                                  Q[-1, follow] - scenario.thetaf[follow]))))})


def closed_chain_reference(robot: RobotModel, scenario: Scenario, n: int, duration: float):
    """A rest-to-rest path on the closed-chain manifold: the joint-space quintic from θ0 to θf,
    every sample projected (minimum-norm Newton) onto ``relative_pose = scenario.relative``.
    Returns ``(t, q)``. A warm start, not a method of the paper."""
    kin = EBAKinematics(robot)
    t = np.linspace(0.0, duration, n + 1)
    p = quintic_profile(t / duration)[0]
    Q = scenario.theta0 + p[:, None] * (scenario.thetaf - scenario.theta0)
    out = [scenario.theta0.copy()]
    for k in range(1, n):
        out.append(kin.project_closed_chain(Q[k], scenario.relative, tol=1e-12))
    out.append(scenario.thetaf.copy())
    return t, np.array(out)


# --------------------------------------------------------------------------- Fourier (near-optimal)
@dataclass(frozen=True)
class FourierOptions:
    """Near-optimal Fourier method (the EBA paper, Eq. 35) with IPOPT."""

    #: h: harmonics per joint [count] (the paper: 98 = 14 × 7 coefficients, i.e. h = 3).
    n_harmonics: int = 3
    #: T: duration of the motion [s] (the paper: 20).
    duration: float = 20.0
    #: Weight of the penalty terms [-] (the paper: 1e4).
    penalty: float = 1e4
    #: RK4 steps of the base quaternion [count].
    n_steps: int = 40
    #: Joint velocity limit [deg/s] (the paper's 10; None: no limit).
    velocity_limit_deg_s: float | None = 10.0
    #: Instants at which the velocity limit is imposed [count].
    n_limit_samples: int = 81
    #: Instants at which the closed chain is imposed (end-constrained case) [count].
    closed_chain_samples: int = 21
    #: IPOPT's ``tol`` [-].
    tol: float = 1e-8
    #: IPOPT iterations, at most [count].
    max_iter: int = 300
    #: ``"limited-memory"`` (L-BFGS), ``"gauss-newton"`` (the objective's exact Hessian with the closed-chain
    #: residual's JᵀJ, constraint curvature ignored) or ``"auto"`` (L-BFGS free end, Gauss-Newton
    #: end-constrained; see docs/decisions/0009-eba-nlp-solver-settings.md).
    hessian: str = "auto"

    def __post_init__(self):
        if self.hessian not in ("auto", "gauss-newton", "limited-memory"):
            raise ValueError("FourierOptions.hessian: expected 'auto', 'gauss-newton' or 'limited-memory', "
                             f"got {self.hessian!r}")
        _check_int("FourierOptions", 1, n_harmonics=self.n_harmonics, n_steps=self.n_steps,
                   max_iter=self.max_iter)
        _check_int("FourierOptions", 2, n_limit_samples=self.n_limit_samples,
                   closed_chain_samples=self.closed_chain_samples)
        _check_positive("FourierOptions", duration=self.duration, penalty=self.penalty, tol=self.tol)
        if self.velocity_limit_deg_s is not None:
            _check_positive("FourierOptions", velocity_limit_deg_s=self.velocity_limit_deg_s)


def _fourier_basis(t, h: int, T: float, lib=np):
    """Rows of the rate basis ``[1/2, cos(ω_i t).., sin(ω_i t)..]`` and of its integral from 0."""
    b, bi = [0.5 + 0 * t], [t / 2]
    for i in range(1, h + 1):
        w = 2 * np.pi * i / T
        b.append(lib.cos(w * t))
        bi.append(lib.sin(w * t) / w)
    for i in range(1, h + 1):
        w = 2 * np.pi * i / T
        b.append(lib.sin(w * t))
        bi.append((1 - lib.cos(w * t)) / w)
    return b, bi


def _quat_mul(a, b):
    ax, ay, az, aw = a[0], a[1], a[2], a[3]
    bx, by, bz, bw = b[0], b[1], b[2], b[3]
    return ca.vertcat(aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                      aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def run_fourier(robot: RobotModel, scenario: Scenario, options: FourierOptions | None = None,
                samples: int = 401) -> MethodResult:
    """The near-optimal Fourier method with IPOPT (see the module docstring)."""
    o = options or FourierOptions()
    t_start = time.perf_counter()
    nj, h, T = robot.nj, o.n_harmonics, o.duration
    nb = 2 * h + 1
    th0, thf = scenario.theta0, scenario.thetaf
    sym = SymbolicKinematics(robot)
    # base angular velocity (base frame) from the CasADi centroidal map
    th, thd = ca.SX.sym("th", nj), ca.SX.sym("thd", nj)
    qfull = ca.vertcat(ca.DM([0, 0, 0, 0, 0, 0, 1.0]), th)
    X = sym.joint_placements(qfull)
    Ag = sym.centroidal_map(qfull, X)
    wfun = ca.Function("w", [th, thd], [-ca.solve(Ag[:, :6], Ag[:, 6:] @ thd)[3:6]])
    # one RK4 step of the base quaternion along the Fourier joint motion
    quat, Cs, ts, dts = ca.SX.sym("quat", 4), ca.SX.sym("C", nj, nb), ca.SX.sym("t"), ca.SX.sym("dt")

    def f(qu, t):
        b, bi = _fourier_basis(t, h, T, ca)
        thv = ca.DM(th0) + Cs @ ca.vertcat(*bi)
        return 0.5 * _quat_mul(qu, ca.vertcat(wfun(thv, Cs @ ca.vertcat(*b)), 0))

    k1 = f(quat, ts)
    k2 = f(quat + dts / 2 * k1, ts + dts / 2)
    k3 = f(quat + dts / 2 * k2, ts + dts / 2)
    k4 = f(quat + dts * k3, ts + dts)
    qn = quat + dts / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    step = ca.Function("fourier_base_step", [quat, Cs, ts, dts], [qn / ca.norm_2(qn)])
    M = o.n_steps
    dt = T / M
    # decision variables: Y = C with the k0 column scaled by the penalty (preconditioning for
    # L-BFGS: the penalty term has unit curvature in Y)
    Y = ca.MX.sym("Y", nj, nb)
    k0ref = 2 * (thf - th0) / T
    sc = 1.0 / (np.sqrt(o.penalty) * T / 2)
    C = ca.horzcat(ca.DM(k0ref) + Y[:, 0] * sc, Y[:, 1:])
    F = step.mapaccum("fourier_base", M)
    Qb = F(ca.DM([0, 0, 0, 1.0]), ca.repmat(C, 1, M), ca.DM(np.arange(M) * dt).T, dt)
    qT = Qb[:, -1]
    att = 2 * qT[:3]  # ≈ rotation vector of the final attitude (qT[3] > 0 near the identity)
    thT = ca.DM(th0) + C[:, 0] * T / 2
    effort = ca.sumsqr(C[:, 0]) / 4 + 0.5 * ca.sumsqr(C[:, 1:])  # (1/T)∫‖u‖² dt, exact
    obj = effort + o.penalty * ca.sumsqr(thT - thf)
    x = ca.vec(Y)
    hess = ca.hessian(obj, x)[0]  # constant: the objective is quadratic in Y (free-end case)
    g, lbg, ubg = [att], [np.zeros(3)], [np.zeros(3)]
    if o.velocity_limit_deg_s is not None:
        tl = np.linspace(0.0, T, o.n_limit_samples)
        Bl = np.array(_fourier_basis(tl, h, T)[0])  # nb × n
        vmax = np.deg2rad(o.velocity_limit_deg_s)
        g.append(ca.vec(C @ ca.DM(Bl)))
        lbg.append(-vmax * np.ones(nj * tl.size))
        ubg.append(vmax * np.ones(nj * tl.size))
    if scenario.closed_chain:
        fa, fb = robot.arm("A").ee_frame, robot.arm("B").ee_frame
        Ra, pa = sym.frame_placement(qfull, fa, X)
        Rb, pb = sym.frame_placement(qfull, fb, X)
        rel0 = scenario.relative
        r, _ = relative_pose_residual(Ra, pa, Rb, pb, rel0)
        ccfun = ca.Function("cc", [th], [r])
        tc = np.linspace(0.0, T, o.closed_chain_samples)[1:-1]
        Bi = np.array(_fourier_basis(tc, h, T)[1])
        THc = ca.repmat(ca.DM(th0), 1, tc.size) + C @ ca.DM(Bi)
        R = ca.vec(ccfun.map(tc.size)(THc))
        obj = obj + o.penalty * ca.sumsqr(R) / tc.size
        JR = ca.jacobian(R, x)
        hess = hess + 2 * o.penalty / tc.size * (JR.T @ JR)  # Gauss-Newton
    # initial guess: least-squares fit of a rest-to-rest reference's rates (the quintic, or its
    # projection on the closed-chain manifold)
    tf = np.linspace(0.0, T, 201)
    if scenario.closed_chain:
        from scipy.interpolate import CubicSpline

        tr, qr = closed_chain_reference(robot, scenario, 40, T)
        vref = CubicSpline(tr, qr, axis=0, bc_type="clamped")(tf, 1)
    else:
        vref = quintic_profile(tf / T)[1][:, None] * (thf - th0)[None, :] / T
    B = np.array(_fourier_basis(tf, h, T)[0]).T
    C0 = np.linalg.lstsq(B, vref, rcond=None)[0].T
    Y0 = C0.copy()
    Y0[:, 0] = 0.0
    gexpr = ca.vertcat(*g)
    hess_mode = o.hessian if o.hessian != "auto" else ("gauss-newton" if scenario.closed_chain else "limited-memory")
    extra = {}
    if hess_mode != "limited-memory":  # Gauss-Newton: the objective's (constant / JᵀJ) Hessian, constraint curvature ignored
        lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", gexpr.shape[0])
        extra["hess_lag"] = ca.Function("nlp_hess_l", [x, ca.MX(0, 1), lam_f, lam_g], [ca.triu(lam_f * hess)],
                                        ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
    sopts = SolverOptions(tol=o.tol, max_iter=o.max_iter,
                          hessian="limited-memory" if hess_mode == "limited-memory" else None)
    solver = NlpSolver("fourier", {"x": x, "f": obj, "g": gexpr}, sopts, casadi_options=extra)
    outcome = solver.solve(Y0.reshape(-1, order="F"), lbg=np.concatenate(lbg), ubg=np.concatenate(ubg))
    stats = solver.stats() if outcome.iterations >= 0 else {"return_status": outcome.status.value}
    Yv = np.array(outcome.x).reshape((nj, nb), order="F")
    Cv = Yv.copy()
    Cv[:, 0] = k0ref + Yv[:, 0] * sc
    qT_val = np.array(ca.Function("qT", [Y], [qT])(Yv)).ravel()
    x, y, z, w = qT_val / np.linalg.norm(qT_val)
    Rf = pin.Quaternion(w, x, y, z).toRotationMatrix()
    runtime = time.perf_counter() - t_start
    t = np.linspace(0.0, T, samples)
    b, bi = _fourier_basis(t, h, T)
    qs = th0[None, :] + (Cv @ np.array(bi)).T
    vs = (Cv @ np.array(b)).T
    seg = hermite_segment(t, qs, vs)
    status = stats.get("return_status", "unknown")
    ok = bool(stats.get("success", False))
    return MethodResult("fourier", [seg], runtime, np.asarray(Rf), None, ok,
                        "" if ok else f"IPOPT: {status}",
                        info={"options": o.__dict__.copy(), "ipopt_status": status,
                              "iterations": int(outcome.iterations), "n_coefficients": int(Cv.size),
                              "outcome": outcome.to_dict(),
                              "coefficients": Cv.tolist()})
