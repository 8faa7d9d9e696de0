"""The hands' smoothed trajectories of the Spline-RRT* reproduction and their tracking: Bézier
orientation blends and quartic position splines under the end-effector speed limit
(:func:`smooth_hand_paths`), the resolved-rate tracking of both hands with the free-floating base
(:func:`track`), and the figures the paper reports on a tracked motion (:func:`evaluate`, link
distances)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ...collision.checker import CollisionChecker
from ...geometry.spatial import exp3, log3
from ...geometry.splines import PiecewisePolynomial, quartic_spline, time_grid_from_path
from ...model.floating import simulate_base
from ...model.kinematics import Kinematics
from ...model.robot import RobotModel
from ...scene import Scene

__all__ = ["BezierOrientation", "HandTrajectory", "smooth_hand_paths", "TrackingOptions", "TrackingResult",
           "track", "link_distances", "evaluate"]


# --------------------------------------------------------------------------- orientation
class BezierOrientation:
    """Orientation along a 5th-order Bézier curve in exponential coordinates relative to the start:
    ``R(τ) = R0 exp(B(τ))``, ``B(τ) = Σ_k C(5,k) (1−τ)^(5−k) τ^k c_k``, τ = t/T. The default control
    points ``c = (0, 0, 0, φ, φ, φ)`` with ``φ = log(R0ᵀ R1)`` give zero angular velocity and
    acceleration at both ends (rest to rest)."""

    def __init__(self, R0: np.ndarray, R1: np.ndarray, T: float, control: np.ndarray | None = None):
        if not (np.isfinite(T) and T > 0):
            raise ValueError(f"T: expected a positive duration [s], got {T}")
        self.R0, self.R1, self.T = np.asarray(R0, float), np.asarray(R1, float), float(T)
        phi = log3(self.R0.T @ self.R1)
        self.control = (np.array([np.zeros(3)] * 3 + [phi] * 3) if control is None
                        else np.asarray(control, float).reshape(6, 3))

    def _B(self, tau: float, k: int = 0) -> np.ndarray:
        c = self.control
        n = 5
        for _ in range(k):  # derivative control points
            c = n * np.diff(c, axis=0)
            n -= 1
        out = np.zeros(3)
        for i in range(n + 1):
            out += math.comb(n, i) * (1 - tau) ** (n - i) * tau ** i * c[i]
        return out

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """``(R (3, 3), ω (3,) world axes [rad/s])`` at time t [s]."""
        tau = float(np.clip(t / self.T, 0.0, 1.0))
        B, dB = self._B(tau), self._B(tau, 1) / self.T
        R = self.R0 @ exp3(B)
        return R, R @ (np.asarray(pin.Jexp3(B)) @ dB)


@dataclass
class HandTrajectory:
    """One hand's reference: position spline [m] (quartic, C3) and Bézier orientation."""

    position: PiecewisePolynomial
    orientation: BezierOrientation
    waypoints: np.ndarray

    def pose(self, t: float) -> pin.SE3:
        R, _ = self.orientation(t)
        return pin.SE3(R, self.position(t))

    def twist(self, t: float) -> np.ndarray:
        """``[v; ω]`` world axes [m/s, rad/s]."""
        _, w = self.orientation(t)
        return np.concatenate([self.position(t, 1), w])

    def max_speed(self, n: int = 4001) -> float:
        """max ‖ẋ‖ [m/s] (dense sampling refined by a bounded 1-D search around the best sample)."""
        return _max_norm(self.position, 1, n)


def _max_norm(pp: PiecewisePolynomial, k: int, n: int = 4001) -> float:
    from scipy.optimize import minimize_scalar

    t = np.linspace(pp.t0, pp.tf, n)
    v = np.linalg.norm(pp(t, k), axis=1)
    i = int(np.argmax(v))
    a, b = t[max(i - 1, 0)], t[min(i + 1, n - 1)]
    if b <= a:
        return float(v[i])
    r = minimize_scalar(lambda s: -np.linalg.norm(pp(s, k)), bounds=(a, b), method="bounded",
                        options={"xatol": 1e-10 * max(1.0, pp.tf)})
    return float(max(v[i], -r.fun))


def smooth_hand_paths(paths: dict, start: dict, goal: dict, speed_limit: float = 0.1,
                      optimize_durations: bool = False) -> tuple[dict, float, dict]:
    """Quartic splines (v0 = a0 = vf = 0) through the waypoints of every hand, one duration T [s]
    for both: the smallest with ‖ẋ‖ ≤ ``speed_limit`` [m/s] for every hand (exact time scaling).
    Returns ``({arm: HandTrajectory}, T, info)``; ``info`` holds per-arm durations before the common
    T and, with ``optimize_durations``, the quartic NLP's status."""
    if not (np.isfinite(speed_limit) and speed_limit > 0):
        raise ValueError(f"speed_limit: expected a positive speed [m/s], got {speed_limit}")
    info: dict[str, Any] = {"nlp": {}}
    splines, T_arm = {}, {}
    for a, W in paths.items():
        W = np.asarray(W, float)
        if W.ndim != 2 or W.shape[1] != 3 or len(W) < 2:
            raise ValueError(f"paths[{a!r}]: expected (M ≥ 2, 3) waypoints, got shape {W.shape}")
        times = time_grid_from_path(W, 1.0)
        pp = quartic_spline(times, W, 0.0, 0.0, 0.0)
        if optimize_durations:
            import casadi as ca

            from ...problem.quartic import smooth_quartic

            x, xd = ca.SX.sym("x", 3), ca.SX.sym("xd", 3)
            vmax = _max_norm(pp, 1)
            res = smooth_quartic(times * vmax / speed_limit, W, free_durations=True,
                                 ee_velocity=ca.Function("v", [x, xd], [xd]), ee_speed_max=speed_limit,
                                 ipopt_options={"max_iter": 300})
            info["nlp"][a] = {"status": res.status, "iterations": res.iterations, "wall_time_s": res.wall_time}
            if res.success:
                pp = res.spline
        vmax = _max_norm(pp, 1)
        T_arm[a] = pp.duration * vmax / speed_limit
        splines[a] = (pp, W)
    T = max(T_arm.values()) * (1.0 + 1e-9)
    out = {}
    for a, (pp, W) in splines.items():
        pp = pp.time_scaled(T / pp.duration)
        ori = BezierOrientation(start[a].rotation, goal[a].rotation, T)
        out[a] = HandTrajectory(pp, ori, W)
    info["T_arm_s"] = T_arm
    return out, T, info


# --------------------------------------------------------------------------- tracking
@dataclass(frozen=True)
class TrackingOptions:
    """Resolved-rate tracking options."""

    #: Integration and output step [s].
    dt: float = 0.05
    #: K: gain of the closed-loop correction [1/s].
    gain: float = 5.0
    #: Damping of the pseudo-inverse [-] (0: Moore-Penrose).
    damping: float = 0.0

    def __post_init__(self):
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"TrackingOptions.dt: expected a positive step [s], got {self.dt}")
        if not (np.isfinite(self.gain) and self.gain >= 0):
            raise ValueError(f"TrackingOptions.gain: expected ≥ 0 [1/s], got {self.gain}")


@dataclass
class TrackingResult:
    """Joint trajectory of the resolved-rate tracking: ``t`` (N,) [s], ``q`` (N, nq) full
    configurations (the controller's own base), ``qd`` (N, nj) joint rates [rad/s], ``qdd`` (N, nj)
    joint accelerations [rad/s²]: the derivative of the closed-loop rate field along the motion
    (central differences with a 1e-4 s step, one-sided at the ends) — exact up to O(1e-8), unlike
    differences of the samples, which miss short peaks (the quartic's abrupt stop at T)."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    wall_time_s: float = 0.0
    qdd: np.ndarray | None = None

    @property
    def joints(self) -> np.ndarray:
        return self.q[:, 7:]


def _pose_error(M: pin.SE3, goal: pin.SE3) -> np.ndarray:
    from ...model.ik import pose_error

    return pose_error(M, goal)


def track(robot: RobotModel, hands: dict, q_start, T: float, options: TrackingOptions | None = None,
          reference=None, null_gain: float = 1.0) -> TrackingResult:
    """Resolved-rate motion ``q̇ = J*⁺ (ξ_d + K e)`` (J* the stacked generalized Jacobians, world
    axes) from the joint vector ``q_start`` [rad], base at the origin with identity attitude and
    zero momentum; RK4 on the configuration manifold (``pin.integrate``) with step ``dt``.

    With ``reference`` (``t -> (q_ref, q̇_ref)`` joint trajectory, e.g. an optimizer's solution)
    only the hand *positions* are tracked and the redundancy follows the reference:
    ``q̇ = J_p⁺ (v_d + K e_p) + (I − J_p⁺ J_p)(q̇_ref + null_gain (q_ref − q))``."""
    o = options or TrackingOptions()
    t0 = time.perf_counter()
    kin = Kinematics(robot)
    arms = list(hands)
    fids = [robot.arm(a).ee_frame_id for a in arms]
    data = robot.model.createData()
    model = robot.model
    n = int(math.ceil(T / o.dt - 1e-9))
    t = np.linspace(0.0, T, n + 1)

    def rates(tt: float, q: np.ndarray) -> np.ndarray:
        G = kin.generalized_jacobians(q)
        pin.framesForwardKinematics(model, data, q)
        if reference is not None:
            J = np.vstack([G[a][:3] for a in arms])
            xi = np.concatenate([hands[a].position(tt, 1) + o.gain * (hands[a].position(tt) - data.oMf[f].translation)
                                 for a, f in zip(arms, fids)])
            Jp = np.linalg.pinv(J)
            qr, qdr = reference(tt)
            z = np.asarray(qdr, float) + null_gain * (np.asarray(qr, float) - q[robot.base_nq:])
            return Jp @ xi + z - Jp @ (J @ z)
        J = np.vstack([G[a] for a in arms])
        xi = np.concatenate([hands[a].twist(tt) + o.gain * _pose_error(data.oMf[f], hands[a].pose(tt))
                             for a, f in zip(arms, fids)])
        if o.damping > 0:
            return J.T @ np.linalg.solve(J @ J.T + o.damping ** 2 * np.eye(J.shape[0]), xi)
        return np.linalg.lstsq(J, xi, rcond=None)[0]

    def vel(tt: float, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        qd = rates(tt, q)
        return kin.full_velocity(q, qd), qd

    q = robot.configuration(q_start)
    Q = np.empty((n + 1, robot.nq))
    QD = np.empty((n + 1, robot.nj))
    QDD = np.empty((n + 1, robot.nj))
    eps = 1e-4
    for k in range(n + 1):
        v1, qd = vel(t[k], q)
        Q[k], QD[k] = q, qd
        lo, hi = max(t[k] - eps, 0.0), min(t[k] + eps, T)
        qd_hi = rates(hi, pin.integrate(model, q, (hi - t[k]) * v1))
        qd_lo = rates(lo, pin.integrate(model, q, (lo - t[k]) * v1))
        QDD[k] = (qd_hi - qd_lo) / (hi - lo)
        if k == n:
            break
        h = t[k + 1] - t[k]
        v2, _ = vel(t[k] + h / 2, pin.integrate(model, q, h / 2 * v1))
        v3, _ = vel(t[k] + h / 2, pin.integrate(model, q, h / 2 * v2))
        v4, _ = vel(t[k] + h, pin.integrate(model, q, h * v3))
        q = pin.integrate(model, q, h / 6 * (v1 + 2 * v2 + 2 * v3 + v4))
    return TrackingResult(t, Q, QD, time.perf_counter() - t0, QDD)


# --------------------------------------------------------------------------- evaluation
def _link_pairs(checker: CollisionChecker, links=(3, 5, 7), arms=("a", "b")) -> list[int]:
    names_a = tuple(f"{arms[0]}_link{i}_" for i in links)
    names_b = tuple(f"{arms[1]}_link{i}_" for i in links)
    out = []
    for k, p in enumerate(checker.pairs):
        if p.kind != "self":
            continue
        if (p.name_a.startswith(names_a) and p.name_b.startswith(names_b)) or \
           (p.name_a.startswith(names_b) and p.name_b.startswith(names_a)):
            out.append(k)
    return out


def link_distances(robot: RobotModel, Q: np.ndarray, links=(3, 5, 7), scene: Scene | None = None) -> dict:
    """Exact (coal) distances along configurations ``Q`` (N, nq): ``"links"`` (N,) the smallest
    distance between links ``links`` of arm A and of arm B [m] (the paper's Fig. 8), ``"pairs"``
    their names, ``"obstacles"`` (N,) the smallest link–obstacle distance (inf without a scene)."""
    checker = CollisionChecker(robot, scene, held_object=False)
    sel = _link_pairs(checker, links)
    if not sel:
        raise ValueError(f"no collision pair between links {links} of the two arms")
    obs = [k for k, p in enumerate(checker.pairs) if p.kind == "robot-obstacle"]
    L, O = np.empty(len(Q)), np.full(len(Q), np.inf)
    per_pair = np.empty((len(Q), len(sel)))
    for i, q in enumerate(Q):
        d = checker.distances(q)
        per_pair[i] = d[sel]
        L[i] = d[sel].min()
        if obs:
            O[i] = d[obs].min()
    return {"links": L, "per_pair": per_pair, "pairs": [(checker.pairs[k].name_a, checker.pairs[k].name_b) for k in sel],
            "obstacles": O}


def evaluate(robot: RobotModel, hands: dict, t: np.ndarray, joints: np.ndarray, joint_rates: np.ndarray,
             scene: Scene | None = None, base0: pin.SE3 | None = None,
             joint_accelerations: np.ndarray | None = None) -> dict:
    """Figures of a joint trajectory on the free-floating robot, from the independent base simulator
    (:func:`optplan.model.floating.simulate_base`, cubic Hermite through the samples): per-arm
    ``tracking_position_m``/``tracking_orientation_rad`` (N,), ``base_rpy`` (N, 3) [rad],
    ``q`` (N, nq), link distances, joint-rate/acceleration peaks [rad/s, rad/s²] (accelerations as
    given, else central differences of the rates)."""
    sim = simulate_base(robot, (t, joints, joint_rates), t, base0=base0, substeps=4)
    kin = Kinematics(robot)
    out = {"t": t, "q": sim.q, "base_rpy": sim.base_rpy, "momentum_residual": float(sim.momentum_residual.max())}
    for a, h in hands.items():
        ep, eo = np.empty(len(t)), np.empty(len(t))
        fr = robot.arm(a).ee_frame
        for i, (tt, q) in enumerate(zip(t, sim.q)):
            e = _pose_error(kin.frame_placement(q, fr), h.pose(tt))
            ep[i], eo[i] = np.linalg.norm(e[:3]), np.linalg.norm(e[3:])
        out[f"tracking_position_m_{a}"] = ep
        out[f"tracking_orientation_rad_{a}"] = eo
    qdd = np.gradient(joint_rates, t, axis=0) if joint_accelerations is None else np.asarray(joint_accelerations)
    out["qd"], out["qdd"] = joint_rates, qdd
    out["max_joint_rate_rad_s"] = float(np.abs(joint_rates).max())
    out["max_joint_accel_rad_s2"] = float(np.abs(qdd).max())
    d = link_distances(robot, sim.q, scene=scene)
    out["link_distance_m"], out["obstacle_distance_m"] = d["links"], d["obstacles"]
    out["link_pairs"] = d["pairs"]
    return out
