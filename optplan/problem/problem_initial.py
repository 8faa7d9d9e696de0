"""The first guess of :class:`~optplan.problem.OptProblem`: joint samples on any time grid, a
previous solution, a planner's path (resampled, projected onto a closed chain, timed by the quintic
law), its corners rounded off, or the straight line between two configurations."""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigurationError, check_real, real_array
from ..geometry.splines import clamped_cubic, quintic_time_law
from ..model.robot import RobotModel
from .solution import Solution
from .spline_problem import SplineEvaluator

if TYPE_CHECKING:
    from .frame_terms import ClosedChain
    from .transcription import Transcription

__all__ = ["InitialGuessAPI"]


class InitialGuessAPI:
    """Mixin of :class:`OptProblem`: the initial guess (``set_initial`` and its variants)."""

    robot: RobotModel
    N: int
    n_sub: int
    duration: float
    free_time: bool
    transcription: str   # "auto", "bspline" or "knots" (as given)
    base0: Any
    _spline: Any
    _built: Any
    _handles: list[Any]
    _x0: np.ndarray | None
    _lam_g0: Any
    _lam_x0: Any

    # the problem's own (OptProblem defines them): its knot transcription, a decision vector as a
    # trajectory, the guess unpacked
    numeric_trajectory: Callable[[ArrayLike], Any]
    _initial_unpacked: Callable[[], dict[str, np.ndarray]]

    if TYPE_CHECKING:   # OptProblem.tp: the problem's knot transcription
        @property
        def tp(self) -> Transcription: ...

    def set_initial(self, q: ArrayLike | None = None, t: ArrayLike | None = None, *, solution: Solution | None = None, T: float | None = None) -> None:
        """Initial guess.

        * ``q`` (M × nj) joint samples [rad] at times ``t`` (M,) [s] (default: uniform over the
          duration); resampled onto the knots by a cubic spline, with q̇, q̈, jerk from it.
        * ``solution``: a previous :class:`Solution` of a problem with the same knots and interval
          (its raw decision vector and multipliers are reused) or any other grid (resampled; a
          fixed-duration problem time-scales it to its own duration, a free-time one starts from
          the solution's).
        """
        Tg = check_real(T, "set_initial: T", minimum=0.0, strict_minimum=True, unit="s") if T is not None else self.duration
        if solution is not None and solution.x_scale_h is None and solution.x is not None \
                and len(solution.t) == self.N + 1 and isinstance(solution.evaluator, SplineEvaluator) \
                and solution.evaluator.problem is self:
            self._spline.x0 = np.array(solution.x, float)   # a solve of this problem: reused as it is
            self._spline.lam = (solution.lam_g, solution.lam_x)
            return
        self._spline.x0 = self._spline.lam = self._spline.scale = None
        tp = self.tp
        if solution is not None:
            same = (solution.x is not None and solution.x.size >= tp.x.shape[0] and len(solution.t) == self.N + 1
                    and solution.x_scale_h is not None and np.isclose(solution.x_scale_h, tp.h0, rtol=1e-12))
            if same:
                self._x0 = np.array(solution.x, float)
                self._lam_g0 = solution.lam_g
                self._lam_x0 = solution.lam_x
                return
            t, q = solution.t - solution.t[0], solution.q
            if T is None and self.free_time:
                Tg = solution.duration  # a fixed-duration problem time-scales the path to its own T
        if q is None:
            raise ValueError("set_initial: give q (M × nj samples) or solution")
        q = real_array(q, "set_initial: q (joint samples [rad])")
        if q.ndim != 2 or q.shape[1] != self.robot.nj:
            raise ConfigurationError(f"set_initial: q must be (M, {self.robot.nj}), got shape {q.shape}")
        if not np.all(np.isfinite(q)):
            raise ConfigurationError("set_initial: q has non-finite entries")
        if q.shape[0] == 1:
            q = np.vstack([q, q])
        if t is None:
            t = np.linspace(0.0, Tg, q.shape[0])
        t = real_array(t, "set_initial: t (sample times [s])")
        if t.shape != (q.shape[0],):
            raise ConfigurationError(f"set_initial: t (sample times [s]): expected {q.shape[0]} entries (one per row "
                                     f"of q), got shape {t.shape}")
        if not np.all(np.isfinite(t)):
            bad = np.flatnonzero(~np.isfinite(t)).tolist()
            raise ConfigurationError(f"set_initial: t (sample times [s]): entries {bad} are not finite "
                                     f"(values {t[bad].tolist()})")
        if np.any(np.diff(t) <= 0):
            raise ConfigurationError(f"set_initial: t must be strictly increasing with {q.shape[0]} entries")
        t = (t - t[0]) * (Tg / (t[-1] - t[0]))
        tk = np.linspace(0.0, Tg, self.N + 1)
        Q, V, A = clamped_cubic(np.asarray(t, float), q, tk)   # the cubic spline through the samples, at rest at both ends
        h = Tg / self.N
        J = np.diff(A, axis=0) / h
        base_quat = None
        if self.robot.is_floating and self.transcription == "bspline":
            # the core fits its control points to the knots and integrates the base itself
            base_quat, base_twist = np.tile([0.0, 0.0, 0.0, 1.0], (self.N + 1, 1)), None
        elif self.robot.is_floating:
            from ..model.floating import simulate_base

            m = 2 * self.n_sub
            tm = np.linspace(0.0, Tg, m * self.N + 1)
            res = simulate_base(self.robot, (tk, Q, V), tm, base0=self.base0, substeps=2)
            base_quat = res.q[::m, 3:7]
            base_twist = res.v[:, :6]
        self._x0 = tp.pack(Q, V, A, J, T=Tg, base_quat=base_quat,
                           base_twist=base_twist if self.robot.is_floating else None)
        self._lam_g0 = self._lam_x0 = None
        self._refresh_aux()

    def _refresh_aux(self) -> None:
        """After a new initial guess, re-seed auxiliary variables (separating planes) of a built
        problem; the problem structure (active collision pairs) is kept."""
        b = self._built
        if b is None:
            return
        assert self._x0 is not None  # narrowing only: set_initial set it
        traj = self.numeric_trajectory(self._x0)
        aux = []
        for h in self._handles:
            d = b["data"][h.name]
            if d.aux:
                new = h.term.reseed(d, traj)
                b["data"][h.name] = dataclasses.replace(d, aux=tuple(new))
                aux += list(new)
        if aux:
            nb = b["nbase"]
            b["aux_init"] = np.concatenate([a.init for a in aux])
            b["lbx"][nb:] = np.concatenate([a.lower for a in aux])
            b["ubx"][nb:] = np.concatenate([a.upper for a in aux])

    def set_initial_path(self, path: ArrayLike, closed_chain: ClosedChain | None = None,
                         T: float | None = None) -> bool:
        """Initial guess from a planner's path (M × nq configurations, no timing), timed by the
        rest-to-rest quintic time law over T. Fixed base: knot k is the path's point at the time
        law's arc length σ(k/N)·L (linear along the path), projected onto ``closed_chain`` when
        given — the knots lie on the manifold. Free-floating base: resampled uniformly in
        joint-space arc length (:func:`optplan.constraints.closed_chain.manifold_resample`), then
        timed. Returns whether every projection converged."""
        from ..constraints.closed_chain import manifold_resample, project_closed_chain

        Tg = check_real(T, "set_initial: T", minimum=0.0, strict_minimum=True, unit="s") if T is not None else self.duration
        if not self.robot.is_floating:
            manifold_resample(self.robot, path, 2)   # validates the path: (M ≥ 2, nq)
            P, ok = np.asarray(path, float), True
            cum = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))]
            arc = quintic_time_law(np.linspace(0.0, 1.0, self.N + 1))[0] * cum[-1]
            Q = np.column_stack([np.interp(arc, cum, P[:, j]) for j in range(P.shape[1])]) if cum[-1] > 0 \
                else np.repeat(P[:1], self.N + 1, axis=0)
            if closed_chain is not None:
                data = self.robot.model.createData()
                for k in range(1, self.N):
                    r = project_closed_chain(self.robot, Q[k], closed_chain, data=data)
                    Q[k] = r.q
                    ok &= bool(r.success)
            Q[0], Q[-1] = P[0], P[-1]
            self.set_initial(q=Q, T=Tg)
            return ok
        Q, ok = manifold_resample(self.robot, path, self.N + 1, closed_chain)
        tau = np.linspace(0.0, 1.0, 2001)
        t = Tg * np.interp(np.linspace(0.0, 1.0, self.N + 1), quintic_time_law(tau)[0], tau)
        t[0], t[-1] = 0.0, Tg
        self.set_initial(q=self.robot.joints_of(Q.T).T, t=t, T=Tg)
        return ok

    def smooth_initial(self, weight: float = 10.0, closed_chain: ClosedChain | None = None) -> None:
        """Round off the corners of the initial guess (e.g. a planner path's): the rest-to-rest
        B-spline between its end configurations fitted to its knots with ``weight`` × the discrete
        jerk [-] (:func:`~optplan.problem.bspline.smooth_knots`), each interior knot then projected
        onto ``closed_chain`` when given."""
        from ..constraints.closed_chain import project_closed_chain
        from .bspline import smooth_knots

        Q = smooth_knots(self._initial_unpacked()["q"], weight)   # the guess's knots (no guess: ValueError)
        if closed_chain is not None:
            data = self.robot.model.createData()
            for k in range(1, self.N):
                Q[k] = project_closed_chain(self.robot, Q[k], closed_chain, data=data).q
        self.set_initial(q=Q)

    def set_initial_straight_line(self, q_start: ArrayLike, q_end: ArrayLike, T: float | None = None) -> None:
        """Initial guess: rest-to-rest quintic from ``q_start`` to ``q_end`` (joint space)."""
        qa = self.robot.check_joints(q_start, "q_start")
        qb = self.robot.check_joints(q_end, "q_end")
        s = np.linspace(0, 1, self.N + 1)
        p = quintic_time_law(s)[0]
        self.set_initial(q=qa + p[:, None] * (qb - qa), T=T)
