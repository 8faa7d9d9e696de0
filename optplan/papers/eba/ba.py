"""The bidirectional approach (BA, the EBA paper, Eq. 1-7) and the enhanced bidirectional approach
(EBA, Eq. 8-24 without and Eq. 25-33 with end constraints).

A real robot starts at the initial state ``x1(0) = [α0; θ0]``, a virtual one at the final state
``x2(0) = [αf; θf]``; both move toward each other under a Lyapunov feedback on ``Δx = x1 − x2``
until the meeting time ``t_m`` (half the horizon). The joint trajectory is the real robot's path
on ``[0, t_m]`` followed by the virtual robot's path reversed in time on ``[t_m, 2 t_m]``.

* BA (Eq. 5, 7): ``ũ = −(Q W̄)† Δx`` with ``W̄ = [W1, −W2]``, ``W = [J_sa; I]``.
* EBA (Eq. 8, 20-22, 32-33): acceleration-level state ``X = [z; x]`` (z = joint rates),
  ``Ũ = −m (k + S(S−1)) S W̄‡ Δx − (m W̄‡ W̄ + k I) z`` with the damped least-squares inverse
  ``W̄‡ = W̄ᵀ (W̄ W̄ᵀ + λ I)⁻¹`` (= Eq. 21 by the push-through identity; the Moore-Penrose
  inverse when λ = 0) and the sigmoid ``S = Sig(t, t0) = 1 − 1/(1 + e^{t0−t})`` (t0 = 1000 s makes
  S ≡ 1, i.e. Eq. 20). With end constraints (Eq. 28-31) the joint rates are ``θ̇ = L z`` with
  ``L = I − H† H`` and ``W`` is replaced by ``W_L = W L``.
* Optional (not in the paper, off by default): ``pinv_derivative=True`` keeps the term
  ``−m Ẇ̄† Δx`` of Eq. 18 that the paper neglects (``Ẇ̄†`` from Eq. 19 for a full-row-rank
  ``W̄``, ``Ẇ̄`` by a central difference along the motion).

Both ODEs are integrated with the classical fixed-step RK4 (``integrator="rk4"``, default) or, to
check that a result is not a discretisation artefact, with scipy's adaptive DOP853
(``integrator="dop853"``, error-controlled to ``rtol``); the base attitude of each robot is
integrated in the paper's RPY coordinates inside the same ODE. The meeting time is ``t_m =
horizon / 2`` (Section 4.1: "the simulation time of the planning simulation is set as 300 s";
BA's jumps at 150 s and 300 s); ``meet_tol`` implements the other reading of the same paragraph
("the time is determined by the value of Δx"): both robots stop at the first instant at which
``max |Δx| ≤ meet_tol``. Because the free-floating system is driftless and its attitude equation
is left-invariant (``Ṙ = R [K(θ) θ̇]×``), the planned final base rotation is
``R(α1(t_m)) R(α2(t_m))ᵀ R(αf)`` exactly.

The equation-by-equation audit of this module against the paper is ``docs/_eba_audit.md``.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.special import expit

from ...model.floating import rk4_step
from ...model.robot import RobotModel
from .core import EBAKinematics, MethodResult, Scenario, Segment, rpy_matrix, rpy_rate_matrix

__all__ = ["BAOptions", "EBAOptions", "run_ba", "run_eba", "sig", "eba_input", "dls_inverse"]
log = logging.getLogger(__name__)


def _positive(name: str, v: float, allow_zero: bool = False) -> None:
    ok = np.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        raise ValueError(f"{name}: expected a {'non-negative' if allow_zero else 'positive'} finite number, got {v!r}")


_INTEGRATORS = ("rk4", "dop853")


def _check_common(cls: str, o) -> None:
    """Validation shared by :class:`BAOptions` and :class:`EBAOptions` (integrator, meeting rule)."""
    if o.integrator not in _INTEGRATORS:
        raise ValueError(f"{cls}.integrator: expected one of {_INTEGRATORS}, got {o.integrator!r}")
    if not (np.isfinite(o.rtol) and 0.0 < o.rtol <= 1e-3):
        raise ValueError(f"{cls}.rtol: expected a relative tolerance in (0, 1e-3], got {o.rtol!r}")
    if o.meet_tol is not None:
        _positive(f"{cls}.meet_tol", o.meet_tol)


@dataclass(frozen=True)
class BAOptions:
    """BA options (the EBA paper, Section 4.1)."""

    #: The Lyapunov weight is ``Q·I`` [-] (the paper: 8).
    Q: float = 8.0
    #: Simulated time, 2 t_m [s] (the paper: 300).
    horizon: float = 300.0
    #: RK4 step, and the output sampling with DOP853 [s].
    dt: float = 0.05
    #: The run is stopped and reported as diverged when a joint rate exceeds this [rad/s].
    max_rate: float = 10.0
    #: ``"rk4"`` (fixed step ``dt``) or ``"dop853"`` (adaptive, ``rtol``).
    integrator: str = "rk4"
    #: Relative tolerance of DOP853 [-].
    rtol: float = 1e-9
    #: None: meet at ``horizon / 2`` (the paper's 300 s); a number [rad]: meet as soon as ``max |Δx| ≤
    #: meet_tol`` (the "time is determined by the value of Δx" reading; still at most ``horizon / 2``).
    meet_tol: float | None = None

    def __post_init__(self):
        for n in ("Q", "horizon", "dt", "max_rate"):
            _positive(f"BAOptions.{n}", getattr(self, n))
        if self.dt > self.horizon / 4:
            raise ValueError(f"BAOptions.dt: {self.dt} s is too large for a {self.horizon} s horizon")
        _check_common("BAOptions", self)


@dataclass(frozen=True)
class EBAOptions:
    """EBA options. Defaults are the paper's free-end values (Section 4.1); the end-constrained
    values (Section 4.2) are :meth:`paper_end_constrained`. Readings of the paper that the audit
    (``docs/eba_audit.md``) found ambiguous are options whose defaults are the most literal reading.
    """

    #: Gain k of the EBA law [-] (the paper: 1.3).
    k: float = 1.3
    #: Exponent m of the EBA law [-] (the paper: 0.125).
    m: float = 0.125
    #: Time constant t0 of the EBA law [s] (the paper: 1000).
    t0: float = 1000.0
    #: λ of the EBA law [-] (the paper: 0).
    lam: float = 0.0
    #: Simulated time, 2 t_m [s] (default 300 s; ``horizon=600`` for the t_m = 300 s reading).
    horizon: float = 300.0
    #: RK4 step, and the output sampling with DOP853 [s].
    dt: float = 0.1
    #: Stop and report divergence above this joint rate [rad/s] (not in the paper: a guard).
    max_rate: float = 10.0
    #: Keep Eq. 18's ``Ẇ̄†`` term (not the paper's method, which neglects it).
    pinv_derivative: bool = False
    #: ``"rk4"`` (fixed step ``dt``) or ``"dop853"`` (scipy's adaptive 8th-order Runge-Kutta with ``rtol``; an
    #: accuracy check, not a reading of the paper).
    integrator: str = "rk4"
    #: Relative tolerance of DOP853 [-].
    rtol: float = 1e-9
    #: None: ``t_m = horizon / 2`` (Section 4.1's 300 s simulation); a number [rad]: the robots meet as soon as
    #: ``max |Δx| ≤ meet_tol``, never later than ``horizon / 2``.
    meet_tol: float | None = None

    def __post_init__(self):
        for n in ("k", "m", "horizon", "dt", "max_rate"):
            _positive(f"EBAOptions.{n}", getattr(self, n))
        _positive("EBAOptions.lam", self.lam, allow_zero=True)
        if not np.isfinite(self.t0):
            raise ValueError(f"EBAOptions.t0: expected a finite time [s], got {self.t0!r}")
        if self.dt > self.horizon / 4:
            raise ValueError(f"EBAOptions.dt: {self.dt} s is too large for a {self.horizon} s horizon")
        if self.k <= 0.25:
            raise ValueError(f"EBAOptions.k: Eq. 32's gain k + S(S−1) must stay positive, so k > 0.25; got {self.k}")
        _check_common("EBAOptions", self)

    @classmethod
    def paper_free_end(cls, **overrides) -> EBAOptions:
        """Section 4.1: k = 1.3, m = 0.125, t0 = 1000 s, λ = 0, 300 s."""
        return cls(**overrides)

    @classmethod
    def paper_end_constrained(cls, **overrides) -> EBAOptions:
        """Section 4.2: k = 1.1, m = 0.1, t0 = 95 s, λ = 1e-5, 200 s."""
        base: dict[str, Any] = dict(k=1.1, m=0.1, t0=95.0, lam=1e-5, horizon=200.0)
        base.update(overrides)
        return cls(**base)


def dls_inverse(Wb: np.ndarray, lam: float) -> np.ndarray:
    """``W̄‡`` of Eq. 21: damped least-squares inverse, computed as ``W̄ᵀ (W̄ W̄ᵀ + λ I)⁻¹``
    ((n+3) × (n+3) system) — equal to the printed ``(W̄ᵀ W̄ + λ I)⁻¹ W̄ᵀ`` (2n × 2n; the printed
    ``I_{N×N}`` is a typo) by the push-through identity; the Moore-Penrose inverse when λ = 0, as
    the paper states (the printed form is then undefined: ``W̄ᵀ W̄`` has rank ≤ n + 3 < 2n)."""
    if lam == 0.0:
        return np.linalg.pinv(Wb)
    n = Wb.shape[0]
    return np.linalg.solve(Wb @ Wb.T + lam * np.eye(n), Wb).T



def sig(t: float, t0: float) -> float:
    """``Sig(t, t0) = 1 − 1/(1 + e^{−t + t0})`` (Eq. 33), evaluated as ``expit(t0 − t)`` so that
    t0 = 1000 s gives exactly 1 without overflow."""
    return float(expit(t0 - t))


def eba_input(Wb: np.ndarray, dx: np.ndarray, z: np.ndarray, t: float, o: EBAOptions,
              Wd: np.ndarray | None = None) -> np.ndarray:
    """The EBA input ``Ũ = [U1; U2]`` of Eq. 32 (Eq. 20 when ``Sig ≡ 1``, i.e. t0 ≫ t):
    ``Ũ = −m [k + S(S−1)] S W̄‡ Δx − (m W̄‡ W̄ + k I) z`` with ``S = Sig(t, t0)`` and ``W̄‡`` of
    Eq. 21 (``Wd``, computed from ``Wb`` and ``o.lam`` when not given). The neglected
    ``−m Ẇ̄† Δx`` of Eq. 18 is not included (see ``pinv_derivative``)."""
    if Wd is None:
        Wd = dls_inverse(Wb, o.lam)
    S = sig(t, o.t0)
    return -o.m * (o.k + S * (S - 1.0)) * S * (Wd @ dx) - o.m * (Wd @ (Wb @ z)) - o.k * z


class _Robots:
    """Real + virtual robot kinematics: ``J_i = E(α_i)⁻¹ K(θ_i) L_i`` and ``L_i``."""

    def __init__(self, kin: EBAKinematics, closed_chain: bool):
        self.kin = kin
        self.cc = closed_chain
        self.nj = kin.nj
        self.I = np.eye(kin.nj)

    def maps(self, th, al):
        if self.cc:
            K, H = self.kin.rate_map_and_constraint(th)
            L = self.I - np.linalg.pinv(H) @ H
            return rpy_rate_matrix(al) @ K @ L, L
        return rpy_rate_matrix(al) @ self.kin.base_rate_map(th), self.I

    def wbar(self, J1, L1, J2, L2):
        nj = self.nj
        Wb = np.empty((3 + nj, 2 * nj))
        Wb[:3, :nj], Wb[:3, nj:] = J1, -J2
        Wb[3:, :nj], Wb[3:, nj:] = L1, -L2
        return Wb


def _rk4(f, X, t_end, dt, max_rate, rate_of, met=None):
    """Fixed-step RK4 from t = 0; returns (t (n+1,), X (n+1, ·), Ẋ at the samples, diverged).
    The run stops (diverged) when the state is not finite or ``rate_of(X, Ẋ) > max_rate``, and
    (not diverged) after the first step at which ``met(X)`` is true."""
    n = int(round(t_end / dt))
    dt = t_end / n
    Xs, Fs, ts = [X.copy()], [], [0.0]
    t = 0.0
    diverged = False
    for _ in range(n):
        if met is not None and len(ts) > 1 and met(X):
            break
        k1 = f(t, X)
        if not (np.all(np.isfinite(k1)) and rate_of(X, k1) <= max_rate):
            diverged = True
            break
        Fs.append(k1)
        X = rk4_step(f, t, X, dt, k1)
        t += dt
        Xs.append(X.copy())
        ts.append(t)
    if diverged:
        Xs.pop()
        ts.pop()
        if len(ts) < 2:
            raise FloatingPointError("the ODE diverged in its first step")
        Fs = Fs[:len(Xs) - 1]
        X, t = Xs[-1], ts[-1]
    Fs.append(f(t, X))
    return np.array(ts), np.array(Xs), np.array(Fs), diverged


def _dop853(f, X, t_end, dt, max_rate, rate_of, met_fn=None, rtol=1e-9):
    """Adaptive DOP853 (scipy) with terminal events for ``rate_of > max_rate`` (diverged) and
    ``met_fn(X) ≤ 0`` (meeting); the dense solution is sampled every ``dt`` (and at the stop).
    Same return value as :func:`_rk4`."""
    from scipy.integrate import solve_ivp

    def ev_rate(t, X):
        F = f(t, X)
        return max_rate - rate_of(X, F) if np.all(np.isfinite(F)) else -1.0

    ev_rate.terminal = True
    events = [ev_rate]
    if met_fn is not None:
        def ev_met(t, X):
            return met_fn(X)

        ev_met.terminal = True
        ev_met.direction = -1.0
        events.append(ev_met)
    sol = solve_ivp(f, (0.0, t_end), X, method="DOP853", rtol=rtol, atol=rtol * 1e-3, dense_output=True,
                    events=events)
    if sol.sol is None or sol.t[-1] <= 0.0:
        raise FloatingPointError(f"the ODE diverged in its first step ({sol.message})")
    t_stop = float(sol.t[-1])
    diverged = (not sol.success) or (sol.status == 1 and len(sol.t_events[0]) > 0)
    n = max(int(np.ceil(t_stop / dt - 1e-9)), 1)
    ts = np.linspace(0.0, t_stop, n + 1)
    Xs = sol.sol(ts).T
    Xs[0], Xs[-1] = X, sol.y[:, -1]
    Fs = np.array([f(t, x) for t, x in zip(ts, Xs)])
    return ts, Xs, Fs, bool(diverged)


def _meeting_rule(dx_of, tol):
    """``(met(X) -> bool, met_fn(X) -> float ≤ 0 once met)`` for ``max |Δx| ≤ tol``; (None, None)
    when ``tol`` is None (meet at the horizon)."""
    if tol is None:
        return None, None

    def met_fn(X):
        return float(np.max(np.abs(dx_of(X)))) - tol

    def met(X):
        return met_fn(X) <= 0.0

    return met, met_fn


def _integrate(o, f, X0, rate_of, dx_of):
    """Integrate the two robots to the meeting (``o.horizon / 2`` or, with ``o.meet_tol``, the
    first time ``max |Δx| ≤ meet_tol``) with ``o.integrator``."""
    met, met_fn = _meeting_rule(dx_of, o.meet_tol)
    if o.integrator == "dop853":
        return _dop853(f, X0, o.horizon / 2, o.dt, o.max_rate, rate_of, met_fn, o.rtol)
    return _rk4(f, X0, o.horizon / 2, o.dt, o.max_rate, rate_of, met)


def _two_segments(ts, th1, th2, v1, v2, a1, a2):
    """Real robot on [0, t_m], virtual robot reversed on [t_m, 2 t_m] (θ̇ → −θ̇, θ̈ → θ̈)."""
    tm = ts[-1]
    seg1 = Segment(ts.copy(), th1, v1, a1)
    seg2 = Segment(2 * tm - ts[::-1], th2[::-1].copy(), -v2[::-1], a2[::-1].copy())
    return [seg1, seg2]


def run_ba(robot: RobotModel, scenario: Scenario, options: BAOptions | None = None) -> MethodResult:
    """The bidirectional approach (Eq. 1-7) on a free-end scenario."""
    o = options or BAOptions()
    if scenario.closed_chain:
        raise ValueError("run_ba: the paper applies BA to the free-end case only (Section 4.2 drops it)")
    t_start = time.perf_counter()
    kin = EBAKinematics(robot)
    rob = _Robots(kin, False)
    nj = rob.nj
    Qinv = 1.0 / o.Q

    def rates(t, X):
        th1, th2, al1, al2 = X[:nj], X[nj:2 * nj], X[2 * nj:2 * nj + 3], X[2 * nj + 3:]
        J1, L1 = rob.maps(th1, al1)
        J2, L2 = rob.maps(th2, al2)
        Wb = rob.wbar(J1, L1, J2, L2)
        dx = np.concatenate([al1 - al2, th1 - th2])
        u = -Qinv * (np.linalg.pinv(Wb) @ dx)  # (Q W̄)† = W̄† / Q for Q·I
        return np.concatenate([u[:nj], u[nj:], J1 @ u[:nj], J2 @ u[nj:]])

    X0 = np.concatenate([scenario.theta0, scenario.thetaf, np.zeros(3), np.zeros(3)])

    def dx_of(X):
        return np.concatenate([X[2 * nj:2 * nj + 3] - X[2 * nj + 3:], X[:nj] - X[nj:2 * nj]])

    ts, Xs, Fs, div = _integrate(o, rates, X0, lambda X, F: float(np.max(np.abs(F[:2 * nj]))), dx_of)
    th1, th2 = Xs[:, :nj], Xs[:, nj:2 * nj]
    u1, u2 = Fs[:, :nj], Fs[:, nj:2 * nj]
    a1, a2 = np.gradient(u1, ts, axis=0), np.gradient(u2, ts, axis=0)
    segs = _two_segments(ts, th1, th2, u1, u2, a1, a2)
    al1, al2 = Xs[-1, 2 * nj:2 * nj + 3], Xs[-1, 2 * nj + 3:]
    Rf = rpy_matrix(al1) @ rpy_matrix(al2).T
    runtime = time.perf_counter() - t_start
    msg = f"diverged at t = {ts[-1]:.1f} s (joint rate > {o.max_rate} rad/s)" if div else ""
    info = {"meeting_dx_joint_deg": float(np.rad2deg(np.max(np.abs(th1[-1] - th2[-1])))),
            "meeting_dx_attitude_deg": float(np.rad2deg(np.max(np.abs(al1 - al2)))),
            "options": o.__dict__.copy()}
    return MethodResult("ba", segs, runtime, Rf, float(ts[-1]), bool(not div), msg, info)


def run_eba(robot: RobotModel, scenario: Scenario, options: EBAOptions | None = None) -> MethodResult:
    """The enhanced bidirectional approach: Eq. 20-22 (free end) or Eq. 29-33 (end-constrained
    scenario: joint rates in the null space of the closed-chain constraint)."""
    if options is None:
        options = EBAOptions.paper_end_constrained() if scenario.closed_chain else EBAOptions.paper_free_end()
    o = options
    t_start = time.perf_counter()
    kin = EBAKinematics(robot)
    rob = _Robots(kin, scenario.closed_chain)
    nj = rob.nj
    m = o.m
    i_th1, i_th2 = slice(0, nj), slice(nj, 2 * nj)
    i_al1, i_al2 = slice(2 * nj, 2 * nj + 3), slice(2 * nj + 3, 2 * nj + 6)
    i_z = slice(2 * nj + 6, 4 * nj + 6)
    eps = 1e-6

    def wbar_at(X):
        J1, L1 = rob.maps(X[i_th1], X[i_al1])
        J2, L2 = rob.maps(X[i_th2], X[i_al2])
        return rob.wbar(J1, L1, J2, L2), J1, L1, J2, L2

    def dx_of(X):  # Δx = x1 − x2 = [α1 − α2; θ1 − θ2]
        return np.concatenate([X[i_al1] - X[i_al2], X[i_th1] - X[i_th2]])

    def rhs(t, X):
        zc = X[i_z]
        Wb, J1, L1, J2, L2 = wbar_at(X)
        dx = dx_of(X)
        Wd = dls_inverse(Wb, o.lam)
        S = sig(t, o.t0)
        U = eba_input(Wb, dx, zc, t, o, Wd)  # Eq. 32 (Eq. 20 when S ≡ 1)
        z1, z2 = zc[:nj], zc[nj:]
        th1d, th2d = L1 @ z1, L2 @ z2
        al1d, al2d = J1 @ z1, J2 @ z2
        if o.pinv_derivative:
            Xd = np.zeros_like(X)
            Xd[i_th1], Xd[i_th2], Xd[i_al1], Xd[i_al2] = th1d, th2d, al1d, al2d
            Wp = wbar_at(X + eps * Xd)[0]
            Wm = wbar_at(X - eps * Xd)[0]
            Wdot = (Wp - Wm) / (2 * eps)
            G = np.linalg.inv(Wb @ Wb.T + o.lam * np.eye(Wb.shape[0]))
            Wd_dot = Wdot.T @ G - Wd @ (Wdot @ Wb.T + Wb @ Wdot.T) @ G
            U = U - m * S * (Wd_dot @ dx)
        return np.concatenate([th1d, th2d, al1d, al2d, U])

    X0 = np.concatenate([scenario.theta0, scenario.thetaf, np.zeros(3), np.zeros(3), np.zeros(2 * nj)])

    def rate_of(X, F):
        return float(np.max(np.abs(X[i_z])))

    with np.errstate(over="ignore", invalid="ignore"):
        ts, Xs, Fs, div = _integrate(o, rhs, X0, rate_of, dx_of)
    th1, th2 = Xs[:, i_th1], Xs[:, i_th2]
    v1, v2 = Fs[:, i_th1], Fs[:, i_th2]
    if scenario.closed_chain:
        a1, a2 = np.gradient(v1, ts, axis=0), np.gradient(v2, ts, axis=0)
    else:  # θ̈ = U exactly (L = I)
        a1, a2 = Fs[:, i_z][:, :nj], Fs[:, i_z][:, nj:]
    segs = _two_segments(ts, th1, th2, v1, v2, a1, a2)
    al1, al2 = Xs[-1, i_al1], Xs[-1, i_al2]
    Rf = rpy_matrix(al1) @ rpy_matrix(al2).T
    runtime = time.perf_counter() - t_start
    msg = f"diverged at t = {ts[-1]:.1f} s (joint rate > {o.max_rate} rad/s)" if div else ""
    if div:
        log.warning("EBA %s", msg)
    info = {"meeting_dx_joint_deg": float(np.rad2deg(np.max(np.abs(th1[-1] - th2[-1])))),
            "meeting_dx_attitude_deg": float(np.rad2deg(np.max(np.abs(al1 - al2)))),
            "meeting_velocity_deg_s": float(np.rad2deg(np.max(np.abs(v1[-1])))),
            "max_abs_dx_at_meeting_rad": float(np.max(np.abs(dx_of(Xs[-1])))),
            "options": o.__dict__.copy()}
    return MethodResult("eba", segs, runtime, Rf, float(ts[-1]), bool(not div), msg, info)
