"""Quartic-spline smoothing (seed paper Sec. 3.3, Eq. 8-11) posed as an NLP and solved with IPOPT.

Variables: the quartic coefficients of every segment, stored normalised as
``p_{i,k} = coef_{i,k} h_i^k`` (position units, ``x_i = sum_k p_{i,k} tau^k``, ``tau = (t-t_i)/h_i``;
a scaling of the paper's ``a_i .. e_i`` that keeps the NLP well conditioned in any time unit), and
with ``free_durations`` the segment durations ``h_i`` [s]. Equalities: exactly the Eq. 11
conditions (positions at the waypoints, equal velocity / acceleration / jerk at the inner ones,
v0, a0, vf), each times ``h_ref^k`` (``h_ref`` = mean initial duration) to be in position units.
Inequalities: ``|x'| <= qdot_max``, ``|x''| <= qddot_max``, ``||ee_velocity(x, x')|| <= ee_speed_max``
at ``samples_per_segment`` uniform points of every segment, both ends included (shared ends once).

Between samples (``refine=True``): every limit is also imposed at 3 movable points per segment
(and dimension), NLP parameters starting at the warm start's worst points. After a solve the
whole trajectory is checked (exact maxima of |x'|, |x''| by sampling + Newton; end-effector speed
by sampling + parabolic refinement); where a maximum exceeds its limit by more than
``refine_tol`` (relative) the point with the smallest multiplier moves there and the NLP is
re-solved (an exchange method), at most ``max_refinements`` times. The overshoot left is removed
by stretching all durations by the worst ratio and re-solving Eq. 11 (an exact time scaling when
v0 = a0 = vf = 0): the spline then meets the limits everywhere, for a relative time cost
<= refine_tol (``QuarticSmoothingResult.stretch``).

With fixed durations the equalities alone determine the spline (5m equations for 5m unknowns per
dimension): the only feasible point is :func:`optplan.geometry.splines.quartic_spline`, the cost (J below)
is irrelevant, and a limit this spline violates makes the NLP infeasible. With free durations the
cost is ``time_weight * T + smooth_weight * (T_ws / J_ws) * J`` with T = sum(h) [s],
``J = sum_i integral ||x^(r)||^2 dt`` (r = 3 for ``cost="jerk"``, 2 for ``"acceleration"``) and
T_ws, J_ws their warm-start values: ``smooth_weight`` is unit-free (1e-3: the smoothness term is
worth 0.1 % of the duration at the warm start). An absolute weight on J (~h^-5) was tried and made
IPOPT need 3-20x more iterations.

Numerics: the NLP is built in MX from one per-segment Function mapped over the segments (building
the exact Hessian takes ~0.1 s instead of ~1.6 s for 20 x 14 with one big SX graph); IPOPT uses
MUMPS with the AMD ordering (``mumps_pivot_order=0``), ~4x faster here than the automatic choice.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from numbers import Real
from typing import Any

import casadi as ca
import numpy as np

from optplan.geometry.splines import PiecewisePolynomial, _broadcast_vec, _check_int, _check_positive, _float_array

from ._quartic_nlp import _check_input_sizes, _ee_wrapper, _limit_vec, _Problem
from .nlp import NlpSolver, SolverOptions

__all__ = ["QuarticSmoothingResult", "smooth_quartic"]

_log = logging.getLogger(__name__)
_COSTS = {"jerk": 3, "acceleration": 2}


@dataclass(frozen=True)
class QuarticSmoothingResult:
    """Outcome of :func:`smooth_quartic` (returned for failed solves too, never None).

    Attributes:
        success: IPOPT reported success on the last solve.
        status: IPOPT return status (e.g. ``"Solve_Succeeded"``, ``"Infeasible_Problem_Detected"``),
            or ``"Exception: ..."`` if the solver raised.
        iterations: IPOPT iterations summed over all (refinement) solves.
        wall_time: total wall time [s] of the call (building, solving, checking).
        spline: the resulting degree-4 spline (the warm start if the solver raised).
            Evaluate it with ``spline(t, derivative=k)``.
        durations: (m,) segment durations [s].
        max_constraint_violation: max over the Eq. 11 residuals (position [unit], derivative jumps
            [unit/s^k], boundary conditions) and the violations of the limits along the whole
            trajectory (exact for joint velocity / acceleration, dense sampling for the
            end-effector speed), in the units of each quantity.
        objective: cost of the returned spline.
        refinements: number of re-solves with moved constraint points.
        stretch: factor (>= 1) by which the durations were finally stretched to remove the
            remaining overshoot between samples (1.0 if none).
        attempts: every IPOPT run, in order (:class:`~optplan.problem.nlp.SolveOutcome`
            summaries: status, iterations, wall/CPU time; ``label`` "solve" or "refinement k").
    """

    success: bool
    status: str
    iterations: int
    wall_time: float
    spline: PiecewisePolynomial
    durations: np.ndarray
    max_constraint_violation: float
    objective: float = float("nan")
    refinements: int = 0
    stretch: float = 1.0
    attempts: tuple[Any, ...] = ()


# ----------------------------------------------------------------------------- public entry point
def smooth_quartic(times_or_durations: Any, waypoints: Any, *, v0: Any = None, a0: Any = None, vf: Any = None,
                   qdot_max: Any = None, qddot_max: Any = None, ee_velocity: ca.Function | None = None,
                   ee_speed_max: float | None = None, ee_acceleration: ca.Function | None = None,
                   ee_accel_max: float | None = None, free_durations: bool = False, min_duration: float = 1e-3,
                   max_duration: float | None = None, cost: str = "jerk", time_weight: float = 1.0,
                   smooth_weight: float = 1e-3, samples_per_segment: int = 8, refine: bool = True,
                   max_refinements: int = 8, refine_tol: float = 1e-4,
                   ipopt_options: dict[str, Any] | None = None) -> QuarticSmoothingResult:
    """Smooth waypoints with a C3 quartic spline under velocity / acceleration / end-effector-speed limits.

    Args:
        times_or_durations: (m+1,) strictly increasing waypoint times [s], or (m,) positive segment
            durations [s] (the spline then starts at t = 0). With ``free_durations`` these are the
            initial guess.
        waypoints: (m+1,) or (m+1, n) positions [rad or m].
        v0, a0, vf: initial velocity [unit/s], initial acceleration [unit/s^2], final velocity
            [unit/s]; scalar or (n,), default 0.
        qdot_max, qddot_max: |x'| [unit/s] and |x''| [unit/s^2] limits, scalar or (n,) (inf = none).
        ee_velocity: ``casadi.Function`` (q (n,), qdot (n,)) -> end-effector linear velocity [m/s];
            required with ``ee_speed_max`` [m/s] (limit on its Euclidean norm).
        ee_acceleration: ``casadi.Function`` (q, qdot, qddot) -> end-effector linear acceleration
            [m/s²] (e.g. ``J(q) q̈ + J̇(q, q̇) q̇``); required with ``ee_accel_max`` [m/s²], imposed at
            the ``samples_per_segment`` points of every segment (not refined between them).
        free_durations: optimise the durations h_i in [min_duration, max_duration] [s] too.
        cost: "jerk" or "acceleration": integral of the squared derivative (the whole cost with fixed
            durations, where it does not change the unique solution).
        time_weight, smooth_weight: weights (>= 0, unit-free) of total time and smoothness with
            free durations: cost ``time_weight * T + smooth_weight * (T_ws / J_ws) * J`` (module
            docstring); with fixed durations the cost is J alone.
        min_duration, max_duration: bounds on each h_i [s] with free durations.
        samples_per_segment: constraint samples per segment, both ends included (>= 2).
        refine: impose the limits between samples too (movable points + re-solves + final
            stretch, see the module docstring); False: at the samples only.
        max_refinements: maximum number of re-solves; refine_tol: relative overshoot that
            triggers one (smaller ones are removed by the final stretch).
        ipopt_options: IPOPT options overriding the defaults (``print_level=0``, ``sb="yes"``,
            ``max_iter=1000``, ``mumps_pivot_order=0``); ``print_time`` and other ``nlpsol``
            options may be given in the same dict, or a nested ``{"ipopt": {...}}`` dict; or a
            :class:`~optplan.problem.nlp.SolverOptions`. Unknown options are an OptionError.

    Returns:
        QuarticSmoothingResult; failures (infeasible, iteration limit, solver exception) are
        reported through ``success``/``status``, never raised (then ``spline`` is IPOPT's last
        iterate, or the warm start if that violates the constraints less). Invalid inputs raise
        ValueError/TypeError.
    """
    t_start = time.perf_counter()
    X = _float_array(waypoints, "waypoints")
    X = X[:, None] if X.ndim == 1 else X
    if X.ndim != 2 or X.shape[0] < 2 or X.shape[1] < 1:
        raise ValueError(f"waypoints: expected shape (m+1,) or (m+1, n) with m >= 1, got shape {np.shape(waypoints)}")
    m, n = X.shape[0] - 1, X.shape[1]
    td = _float_array(times_or_durations, "times_or_durations")
    if td.ndim != 1 or td.size not in (m, m + 1):
        raise ValueError(f"times_or_durations: expected {m + 1} times or {m} durations [s] for {m + 1} waypoints, "
                         f"got shape {td.shape}")
    if td.size == m + 1:
        h, t0 = np.diff(td), float(td[0])
        if np.any(h <= 0):
            k = int(np.flatnonzero(h <= 0)[0])
            raise ValueError("times_or_durations: times must be strictly increasing, "
                             f"got t[{k}]={td[k]} >= t[{k + 1}]={td[k + 1]}")
    else:
        h, t0 = td.copy(), 0.0
        if np.any(h <= 0):
            raise ValueError(f"times_or_durations: durations must be > 0 s, got {h.tolist()}")
    v0v, a0v, vfv = (_broadcast_vec(v, n, nm) for v, nm in ((v0, "v0"), (a0, "a0"), (vf, "vf")))
    vmax, amax = _limit_vec(qdot_max, n, "qdot_max"), _limit_vec(qddot_max, n, "qddot_max")
    if (ee_velocity is None) != (ee_speed_max is None):
        raise ValueError("ee_velocity and ee_speed_max must be given together (got ee_velocity="
                         f"{'a Function' if ee_velocity is not None else None}, ee_speed_max={ee_speed_max!r})")
    if (ee_acceleration is None) != (ee_accel_max is None):
        raise ValueError("ee_acceleration and ee_accel_max must be given together (got ee_acceleration="
                         f"{'a Function' if ee_acceleration is not None else None}, ee_accel_max={ee_accel_max!r})")
    if ee_acceleration is not None:
        if not isinstance(ee_acceleration, ca.Function) or ee_acceleration.n_in() != 3:
            raise TypeError("ee_acceleration: expected a casadi.Function (q, qdot, qddot) -> linear acceleration, "
                            f"got {ee_acceleration!r}")
        _check_input_sizes(ee_acceleration, n, "ee_acceleration")
    ee = _ee_wrapper(ee_velocity, n) if ee_velocity is not None else None
    ee_max = _check_positive(ee_speed_max, "ee_speed_max") if ee is not None else None
    if cost not in _COSTS:
        raise ValueError(f"cost: expected one of {sorted(_COSTS)}, got {cost!r}")
    if not isinstance(free_durations, bool):
        raise TypeError(f"free_durations: expected a bool, got {free_durations!r}")
    hmin = _check_positive(min_duration, "min_duration")
    hmax = math.inf if max_duration is None else _check_positive(max_duration, "max_duration")
    if hmax <= hmin:
        raise ValueError(f"max_duration: expected > min_duration={hmin}, got {max_duration}")
    for val, nm in ((time_weight, "time_weight"), (smooth_weight, "smooth_weight")):
        if isinstance(val, bool) or not isinstance(val, Real):
            raise TypeError(f"{nm}: expected a finite number >= 0, got {val!r}")
        if not (math.isfinite(val) and val >= 0):
            raise ValueError(f"{nm}: expected a finite number >= 0, got {val!r}")
    S = _check_int(samples_per_segment, "samples_per_segment", 2)
    max_ref = _check_int(max_refinements, "max_refinements", 0)
    tol = _check_positive(refine_tol, "refine_tol")
    if ipopt_options is not None and not isinstance(ipopt_options, (dict, SolverOptions)):
        raise TypeError(f"ipopt_options: expected a dict of IPOPT options or SolverOptions, got "
                        f"{type(ipopt_options).__name__}")

    prob = _Problem(t0, h, X, v0v, a0v, vfv, vmax, amax, ee, ee_max, free_durations, _COSTS[cost],
                    float(time_weight), float(smooth_weight), S, slots=bool(refine))
    if ee_acceleration is not None:
        prob.ee_acc = ee_acceleration
        prob.ee_acc_max = _check_positive(ee_accel_max, "ee_accel_max")
    # warm start: the linear solve; with free durations stretched uniformly until it meets the limits
    # (scaling single segments by their own limit ratio was tried and diverges: the spline couples them)
    h_ws = np.clip(h, hmin * 1.01, hmax) if free_durations else h
    pp_ws = prob.spline(h_ws)
    if free_durations and prob.has_limits:
        for _ in range(10):
            ratio = float(prob.segment_ratio(pp_ws).max())
            if ratio <= 1.0 or not np.all(h_ws * ratio * 1.02 <= hmax):
                break
            h_ws = h_ws * ratio * 1.02
            pp_ws = prob.spline(h_ws)

    if free_durations and prob.sw > 0:
        # the smoothness weight is relative to the warm start: smooth_weight * (T_ws / J_ws) * J
        j_ws = (prob.objective(pp_ws) - prob.tw * float(h_ws.sum())) / prob.sw
        if j_ws > 0:
            prob.sw = prob.sw * float(h_ws.sum()) / j_ws
    defaults: dict[str, Any] = {"print_level": 0, "sb": "yes", "max_iter": 1000, "mumps_pivot_order": 0}
    if not free_durations and ee is None and ee_acceleration is None:
        defaults.update({"jac_c_constant": "yes", "jac_d_constant": "yes", "hessian_constant": "yes"})
    casadi_opts: dict[str, Any] = {"error_on_fail": False}
    if isinstance(ipopt_options, SolverOptions):
        sopts = ipopt_options
    else:
        top_level = set(ca.nlpsol_options("ipopt"))
        raw: dict[str, Any] = {}
        for key, val in (ipopt_options or {}).items():
            if key == "ipopt" and isinstance(val, dict):
                raw.update(val)
            elif key in top_level:
                casadi_opts[key] = val
            else:
                raw[key[6:] if key.startswith("ipopt.") else key] = val
        sopts = SolverOptions(raw=raw)

    # slots start at the worst points of the warm start (plus two neighbours)
    delta = 0.25 / (S - 1)
    slots = {}
    ws_viol = prob.limit_violations(pp_ws)
    for name in prob.slot_shape:
        loc = ws_viol[name][1]
        slots[name] = np.stack([loc, np.clip(loc + delta, 0, 1), np.clip(loc - delta, 0, 1)])

    x0 = prob.pack(pp_ws)
    lbx, ubx = np.full(x0.size, -np.inf), np.full(x0.size, np.inf)
    if free_durations:
        lbx[-m:], ubx[-m:] = hmin, hmax
    iterations, refinements, stretch = 0, 0, 1.0
    attempts = []
    status, success = "Not_Solved", False
    pp, h_out = pp_ws, h_ws.copy()
    last_good: tuple[PiecewisePolynomial, np.ndarray, str] | None = None
    try:
        nlp, lbg, ubg = prob.build(h)
        solver = NlpSolver("quartic_smoothing", nlp, sopts, defaults=defaults, casadi_options=casadi_opts)
    except Exception as exc:  # noqa: BLE001 - a failed solve is a status, not an exception
        _log.debug("quartic smoothing: building the NLP raised %s", exc)
        solver, status = None, f"Exception: {type(exc).__name__}: {exc}"
    for rnd in range(max_ref + 1 if solver is not None else 0):
        assert solver is not None   # the loop runs only with a solver
        out = solver.solve(x0, p=prob.pack_slots(slots), lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg,
                           label="solve" if rnd == 0 else f"refinement {rnd}")
        attempts.append(out.summary())
        if out.iterations < 0 and out.message:  # the solver raised
            _log.debug("quartic smoothing: solver raised %s", out.message)
            status, success = f"Exception: RuntimeError: {out.message}", False
            break
        stats = solver.stats()
        status = str(stats.get("return_status", "Unknown"))
        success = bool(stats.get("success", False))
        iterations += max(int(out.iterations), 0)
        w = np.array(out.x, float)
        if not success and last_good is not None:  # a refinement round failed: keep the last good solution
            _log.debug("quartic smoothing: refinement round failed with %s, keeping the previous solution", status)
            pp, h_out, status = last_good
            success = True
            break
        if np.all(np.isfinite(w)):
            pp, h_out = prob.unpack(w, h)
        if not (success and refine) or rnd == max_ref:
            break
        last_good = (pp, h_out, status)
        moved = 0
        lam = np.abs(np.asarray(out.lam_g, float))
        for name, (excess, loc, ratios) in prob.limit_violations(pp).items():
            bad = (ratios > 1.0 + tol) & (excess > 0.0)
            if np.any(bad):
                # exchange: the slot with the smallest multiplier (the least active one) moves
                rows = prob.slot_rows[name]
                mult = np.where(rows >= 0, lam[np.maximum(rows, 0)], 0.0)
                weakest = np.argmin(mult, axis=0)
                seg, dim = np.nonzero(bad)
                slots[name][weakest[seg, dim], seg, dim] = loc[seg, dim]
                moved += int(bad.sum())
        if not moved:
            break
        refinements += 1
        x0 = w
        _log.debug("quartic smoothing: refinement %d moves %d constraint points", refinements, moved)

    if success and free_durations and refine and prob.has_limits:
        # remaining overshoot (<= refine_tol, or IPOPT's bound relaxation): stretch all durations by
        # the worst ratio and re-solve Eq. 11 (exact time scaling when v0 = a0 = vf = 0)
        for _ in range(5):
            ratio = float(prob.segment_ratio(pp).max())
            if ratio <= 1.0 or not np.all(h_out * ratio <= hmax):
                break
            stretch *= ratio * (1.0 + 1e-12)
            h_out = h_out * ratio * (1.0 + 1e-12)
            pp = prob.spline(h_out)
    elif not success and free_durations:
        # report the less infeasible of IPOPT's last iterate and the (stretched) warm start
        if prob.max_violation(pp_ws) < prob.max_violation(pp):
            pp, h_out = pp_ws, h_ws.copy()

    return QuarticSmoothingResult(success=success, status=status, iterations=iterations,
                                  wall_time=time.perf_counter() - t_start, spline=pp, durations=h_out,
                                  max_constraint_violation=prob.max_violation(pp), objective=prob.objective(pp),
                                  refinements=refinements, stretch=stretch, attempts=tuple(attempts))
