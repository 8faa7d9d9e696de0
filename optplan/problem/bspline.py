"""Uniform cubic B-splines in joint space: the trajectory space of the fast transcription.

A joint trajectory on ``[0, T]`` with ``N`` equal intervals ``h = T / N`` is
``q(t) = Σ_i P_i B_i(t)`` with ``N + 3`` control points ``P_i`` (columns of ``P``, nj × (N+3)) and
the uniform cubic B-spline basis. On interval k (``t = (k + u) h``, ``u ∈ [0, 1]``) only
``P_k … P_{k+3}`` act, and at the knots::

    q(t_k)  = (P_k + 4 P_{k+1} + P_{k+2}) / 6
    q̇(t_k)  = (P_{k+2} − P_k) / (2h)
    q̈(t_k)  = (P_k − 2 P_{k+1} + P_{k+2}) / h²
    j_k     = (−P_k + 3 P_{k+1} − 3 P_{k+2} + P_{k+3}) / h³      (constant on interval k)

This is exactly the space of C2 piecewise cubics on the grid — the space of the knot
transcription (:mod:`.transcription`), whose ``(q, q̇, q̈, j)`` per knot and integration rows it
replaces by ``N + 3`` points per joint and no rows at all. Derivatives are linear maps, continuity
is built in, and by the convex-hull property ``min P ≤ q(t) ≤ max P`` and
``min ΔP/h ≤ q̇(t) ≤ max ΔP/h`` hold *between* the knots too (the velocity is a quadratic B-spline
with control points ``(P_{i+1} − P_i) / h``).

Boundary states: the three control points at each end follow from ``(q, q̇, q̈)`` there
(:func:`boundary_points`); rest (q̇ = q̈ = 0) makes them equal to q.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    from ..model.robot import RobotModel

__all__ = ["smooth_knots", "knot_matrices", "boundary_points", "knot_values", "fit_interior", "jerk_integral_reference",
           "rest_to_rest"]


def knot_matrices(N: int) -> dict[str, np.ndarray]:
    """Constant maps from the control points (as rows: ``(N+3) × nj``) to knot values.

    ``q = Mq @ P`` ((N+1) rows), ``qd = Mv @ P / h``, ``qdd = Ma @ P / h²``, ``jerk = Mj @ P / h³``
    (N rows), ``dP = Md @ P`` ((N+2) rows: the velocity control points times h)."""
    N = int(N)
    if N < 4:
        raise ValueError(f"N: a B-spline segment with pinned ends needs at least 4 intervals, got {N}")
    n = N + 3
    Mq, Mv, Ma = np.zeros((N + 1, n)), np.zeros((N + 1, n)), np.zeros((N + 1, n))
    for k in range(N + 1):
        Mq[k, k:k + 3] = (1 / 6, 4 / 6, 1 / 6)
        Mv[k, k:k + 3] = (-0.5, 0.0, 0.5)
        Ma[k, k:k + 3] = (1.0, -2.0, 1.0)
    Mj = np.zeros((N, n))
    for k in range(N):
        Mj[k, k:k + 4] = (-1.0, 3.0, -3.0, 1.0)
    Md = np.zeros((N + 2, n))
    for i in range(N + 2):
        Md[i, i:i + 2] = (-1.0, 1.0)
    return {"q": Mq, "qd": Mv, "qdd": Ma, "jerk": Mj, "dP": Md}


def boundary_points(q: ArrayLike, qd: ArrayLike, qdd: ArrayLike, h: float, at: str) -> np.ndarray:
    """The three control points (3 × nj, in order) fixed by the state ``(q, q̇, q̈)`` at the start
    (``at="start"``: P_0, P_1, P_2) or the end (``"end"``: P_N, P_{N+1}, P_{N+2})."""
    q, qd, qdd = (np.asarray(a, float) for a in (q, qd, qdd))
    mid = q - qdd * h**2 / 6
    lo = mid + qdd * h**2 / 2 - h * qd
    hi = mid + qdd * h**2 / 2 + h * qd
    if at not in ("start", "end"):
        raise ValueError(f"at: expected 'start' or 'end', got {at!r}")
    return np.vstack([lo, mid, hi])


def knot_values(P: np.ndarray, h: float, M: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """Knot arrays in physical units from control points ``P`` ((N+3) × nj): ``q`` [rad],
    ``qd`` [rad/s], ``qdd`` [rad/s²] ((N+1) × nj) and ``jerk`` [rad/s³] (N × nj). ``M``: the
    :func:`knot_matrices` of this N when the caller keeps them (made here otherwise)."""
    P = np.asarray(P, float)
    M = M if M is not None else knot_matrices(P.shape[0] - 3)
    return {"q": M["q"] @ P, "qd": M["qd"] @ P / h, "qdd": M["qdd"] @ P / h**2, "jerk": M["jerk"] @ P / h**3}


def check_knot_guess(q: ArrayLike | None, N: int, nj: int) -> np.ndarray:
    """``q`` as an (N+1) × nj array of finite knot configurations [rad], or a ValueError naming
    what ``set_initial`` got."""
    Q = np.asarray(q, float)
    if Q.shape != (N + 1, nj):
        raise ValueError(f"set_initial: expected ({N + 1}, {nj}) knot configurations, got shape {Q.shape}")
    if not np.all(np.isfinite(Q)):
        raise ValueError("set_initial: the initial guess has non-finite entries")
    return Q


def fit_interior(Q: np.ndarray, P_start: np.ndarray, P_end: np.ndarray) -> np.ndarray:
    """Interior control points ``P_3 … P_{N−1}`` ((N−3) × nj) whose knot values are closest (least
    squares) to ``Q`` ((N+1) × nj) at the interior knots 1 … N−1, the end points being fixed."""
    Q = np.asarray(Q, float)
    N = Q.shape[0] - 1
    Mq = knot_matrices(N)["q"]
    fixed = np.r_[0:3, N:N + 3]
    free = np.r_[3:N]
    Pf = np.vstack([P_start, P_end])
    rhs = Q[1:N] - Mq[1:N][:, fixed] @ Pf
    X, *_ = np.linalg.lstsq(Mq[1:N][:, free], rhs, rcond=None)
    return X


def jerk_integral_reference(q0: ArrayLike, q1: ArrayLike, T: float) -> float:
    """∫‖j‖² dt of the rest-to-rest quintic from q0 to q1 over T [s]: 720 ‖Δq‖² / T⁵ (the scale
    of a minimum-jerk objective)."""
    d = np.asarray(q1, float) - np.asarray(q0, float)
    return float(720.0 * (d @ d) / T**5)


def rest_to_rest(robot: RobotModel, N: int, duration: float, q_start: ArrayLike, q_end: ArrayLike,
                 lower: ArrayLike | None = None, upper: ArrayLike | None = None
                 ) -> tuple[float, float, dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                            np.ndarray, np.ndarray]:
    """The grid of a rest-to-rest motion of ``robot`` on N intervals over ``duration`` [s]:
    ``(T, h, knot matrices, q0, q1, P_start, P_end, lower, upper)`` — the three boundary control
    points at each end from rest at the checked configurations, and the joint limits [rad]
    (``None``: the robot's)."""
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"duration: expected a positive time [s], got {duration!r}")
    T = float(duration)
    h = T / N
    q0, q1 = robot.check_joints(q_start, "q_start"), robot.check_joints(q_end, "q_end")
    z = np.zeros(robot.nj)
    lo = robot.lower.copy() if lower is None else robot.check_joints(lower, "lower")
    hi = robot.upper.copy() if upper is None else robot.check_joints(upper, "upper")
    return (T, h, knot_matrices(N), q0, q1, boundary_points(q0, z, z, h, "start"),
            boundary_points(q1, z, z, h, "end"), lo, hi)


def smooth_knots(Q: ArrayLike, weight: float) -> np.ndarray:
    """Knot configurations ((N+1) × nj) of the rest-to-rest B-spline between ``Q[0]`` and ``Q[-1]``
    whose interior control points minimise ``Σ_k ‖q(t_k) − Q_k‖² + weight · Σ_k ‖ΔP³_k‖²`` (a fit
    of the interior knots plus a discrete jerk penalty; ``weight`` is dimensionless, per unit of
    squared control-point third difference [rad²]). A planner path's corners give a guess a
    jerk thousands of times the optimum's; rounding them off before IPOPT starts saves iterations."""
    Q = np.asarray(Q, float)
    if Q.ndim != 2 or Q.shape[0] < 5:
        raise ValueError(f"smooth_knots: expected (N+1) × nj knot configurations with N ≥ 4, got shape {Q.shape}")
    if not (np.isfinite(weight) and weight >= 0):
        raise ValueError(f"smooth_knots: weight: expected a finite number ≥ 0, got {weight!r}")
    N = Q.shape[0] - 1
    M = knot_matrices(N)
    Mq, Mj = M["q"], M["jerk"]
    free, fixed = np.r_[3:N], np.r_[0:3, N:N + 3]
    Pf = np.vstack([np.repeat(Q[:1], 3, axis=0), np.repeat(Q[-1:], 3, axis=0)])   # rest at both ends
    A = np.vstack([Mq[1:N][:, free], np.sqrt(weight) * Mj[:, free]])
    rhs = np.vstack([Q[1:N] - Mq[1:N][:, fixed] @ Pf, -np.sqrt(weight) * Mj[:, fixed] @ Pf])
    X = np.linalg.lstsq(A, rhs, rcond=None)[0]
    return np.asarray(Mq @ np.vstack([Pf[:3], X, Pf[3:]]))
