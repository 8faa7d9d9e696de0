"""What ``success`` guarantees between knots: a dense check of a solved problem and the ordered
refinement :meth:`OptProblem.solve` runs before it reports success.

The NLP enforces its constraint rows at the knots (and at a term's own interior points). Joint
positions are cubic and rates quadratic between knots, torques, frame poses and distances are
nonlinear in them: a row that holds at every knot can be violated in between (a link cutting a
corner of an obstacle, a closed chain drifting ∝ h⁴, a torque peak). :func:`check_between_knots`
samples the exact piecewise-cubic trajectory at ``density`` points per interval and evaluates every
constraint that is imposed along the trajectory with its numeric twin (Pinocchio, coal):

* collision: exact coal distances of **every** checked pair (not only the pairs the NLP activated)
  against the term's margin (relaxed next to a given boundary configuration as in the NLP). A
  (sample, pair) entry is computed unless a lower bound puts it at or above the margin: its
  distance at a knot (or at the previous check's sample) minus how far its two geometries can
  have moved since (:meth:`CollisionChecker.distance_bounds_below`,
  :mod:`optplan.collision.motion_bounds`), so the entries found are those of every pair at every
  sample;
* every other term whose rows are imposed along the trajectory (joint limits, torque limits, closed
  chain, orientation, frame poses at every knot, ...): its rows against its bounds.

Terms tied to given knots (boundaries, a pose at one knot) hold there by construction and are not
sampled. A free-floating base's attitude between knots is integrated with zero momentum from each
knot's attitude along the exact joint trajectory. A row is violated when it leaves its bounds by more than ``tol + rel_tol · |bound|``.
On the B-spline core a problem keeps its last four checks: a check whose inputs are equal bit for
bit to a kept one's (the solution, the parameters' values, the checked terms and their fields, the
options) returns its violations without computing them again — a re-solve that reproduced an
earlier solution; any other check is computed.

:func:`enforce_between_knots` is the loop ``OptProblem.solve`` runs after a converged solve,
in the pipeline's order: (1) **collision** — pairs activated along the solution and margins
raised at the knots around a contact, re-solve on the same grid warm-started; (2) **refine** —
``growth``× the intervals, warm-started from the solution (terms at given knot indices are
moved to the same times), with its own collision re-solves; then, if a violation remains, the solution is returned with
``success=False`` and status :attr:`IpoptStatus.VIOLATED_BETWEEN_KNOTS`, its violations in
``Solution.between_knots``. See docs/decisions/0017-dense-check-between-knots.md.
"""
from __future__ import annotations

import dataclasses
import logging
import threading
import weakref
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

from ..errors import OptionError
from .collision_term import CollisionAvoidance, CollisionModel
from .evaluate import sampled_trajectory
from .nlp import IpoptStatus
from .solution import Solution
from .terms import JointAccelerationLimits, JointPositionLimits, JointVelocityLimits

__all__ = ["GuaranteeOptions", "Violation", "check_between_knots", "enforce_between_knots"]
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GuaranteeOptions:
    """Options of the dense check after a solve (``OptProblem.solve(guarantees=...)``)."""

    #: Samples per knot interval of the dense check (≥ 10) [-].
    density: int = 10
    #: Absolute tolerance of a row between knots, in the row's units [m, rad, rad/s, N·m].
    tol: float = 1e-3
    #: Relative tolerance, times the magnitude of the violated bound [-].
    rel_tol: float = 1e-3
    #: Re-solves with pairs activated and margins raised around a contact, per grid [-].
    collision_retries: int = 3
    #: Re-solves on a finer grid, warm-started from the solution [-].
    refinements: int = 2
    #: Factor by which a refinement multiplies the number of intervals (an integer ≥ 2) [-].
    growth: int = 2
    #: No refinement past this many intervals [-].
    max_intervals: int = 400

    def __post_init__(self) -> None:
        for name, lo in (("density", 10), ("collision_retries", 0), ("refinements", 0), ("growth", 2),
                         ("max_intervals", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
                raise OptionError(f"GuaranteeOptions.{name}: expected an integer ≥ {lo}, got {v!r}")
        for name in ("tol", "rel_tol"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not (np.isfinite(v) and v >= 0):
                raise OptionError(f"GuaranteeOptions.{name}: expected a finite number ≥ 0, got {v!r}")

    @classmethod
    def coerce(cls, value: Any) -> GuaranteeOptions | None:
        """``None``/``True`` → defaults, ``False`` → no check, an instance → itself."""
        if value is None or value is True:
            return cls()
        if value is False:
            return None
        if isinstance(value, cls):
            return value
        raise OptionError(f"guarantees: expected a GuaranteeOptions, True or False, got {value!r}")


@dataclass(frozen=True)
class Violation:
    """A constraint violated between knots: ``term`` (its name), ``t`` [s] (the worst sample of
    the interval), ``interval`` (knot interval ``k``: between knots k and k+1), ``component``
    (joint name, collision pair ``"a | b"`` or ``"row i"``), ``value`` and the violated ``bound``
    (row units), ``amount`` (how far beyond the bound, ≥ 0)."""

    term: str
    t: float
    interval: int
    component: str
    value: float
    bound: float
    amount: float

    def __str__(self) -> str:
        return (f"{self.term}[{self.component}] at t={self.t:.4g} s: {self.value:.6g} beyond {self.bound:.6g} "
                f"by {self.amount:.3g}")


def _components(n: int, robot: Any) -> list[str]:
    return list(robot.joint_names) if n == robot.nj else [f"row {i}" for i in range(n)]


def _allowed(bound: np.ndarray, o: GuaranteeOptions) -> np.ndarray:
    b = np.where(np.isfinite(bound), np.abs(bound), 0.0)
    return o.tol + o.rel_tol * b


def _worst(out: list[Violation], name: str, t: np.ndarray, h: float, N: int, comp: list[str],
           value: np.ndarray, lo: np.ndarray, hi: np.ndarray, o: GuaranteeOptions) -> None:
    """Append the worst violation per (component, interval) of sampled rows ``value`` (M × n)."""
    below, above = lo - value, value - hi
    amount = np.maximum(np.maximum(below, above), 0.0)
    bound = np.where(below > above, lo, hi)
    bad = amount > _allowed(bound, o)
    k = np.clip((t / h).astype(int), 0, N - 1)
    best: dict[tuple[int, int], int] = {}
    for i, j in zip(*np.nonzero(bad)):
        key = (int(j), int(k[i]))
        if key not in best or amount[i, j] > amount[best[key], j]:
            best[key] = int(i)
    for (j, kk), i in best.items():
        out.append(Violation(name, float(t[i]), kk, comp[j], float(value[i, j]), float(bound[i, j]),
                             float(amount[i, j])))


def _collision(out: list[Violation], name: str, term: CollisionAvoidance, data: Any, traj: Any, t: np.ndarray,
               h: float, N: int, o: GuaranteeOptions) -> None:
    model = data.info.get("model")
    if model is None:
        return
    checker = model.checker
    Q = traj.configurations()
    margin = float(term.margin)
    constant = set(data.info.get("constant_pairs", ()))
    relaxed: Mapping[Any, float] = data.info.get("relaxed", {})
    # a re-solve of the same problem starts from the previous check's distance bounds (kept with
    # the term's model for the check): only pairs its motion may have brought close are computed
    keep = isinstance(data, SimpleNamespace)
    rows, idx, dist, prev = checker.distance_bounds_below(Q, margin, previous=getattr(data, "previous", None))
    if keep:
        data.previous = prev
    k = np.clip((t / h).astype(int), 0, N - 1)
    best: dict[tuple[int, int], tuple[int, float, float]] = {}
    for r_, p_, d_ in zip(rows.tolist(), idx.tolist(), dist.tolist()):
        pair = checker.pairs[p_]
        if pair in constant:
            continue   # no free joint moves this pair: its clearance is given, not the NLP's
        kk = int(k[r_])
        bound = min(relaxed.get((pair, kk), margin), relaxed.get((pair, kk + 1), margin))
        amount = bound - d_
        if amount <= o.tol + o.rel_tol * abs(bound):
            continue
        if (p_, kk) not in best or amount > best[(p_, kk)][2]:
            best[(p_, kk)] = (r_, bound, amount)
    for (p_, kk), (r_, bound, amount) in best.items():
        pair = checker.pairs[p_]
        d = bound - amount
        out.append(Violation(name, float(t[r_]), kk, f"{pair.name_a} | {pair.name_b}", float(d), float(bound),
                             float(amount)))


#: per robot model: (the model, kept alive so that its id stays unique; the last few attitudes'
#: inputs as bytes -> those attitudes, oldest first): a re-solve whose solution did not change
#: (warm starts from one solution, parameters set back) reuses them
_ATTITUDES: dict[int, tuple[Any, dict[bytes, np.ndarray]]] = {}
_ATTITUDES_KEPT = 4
_ATTITUDES_LOCK = threading.Lock()


def _attitude_inputs(sol: Solution, t: np.ndarray, density: int) -> bytes:
    """Everything :func:`_base_attitudes` reads, as bytes (equal bytes: the same attitudes)."""
    arrays = (sol.t, sol.q, sol.qd, sol.qdd, sol.jerk, sol.base_quat, t)
    parts = [np.asarray([density], np.int64).tobytes()]
    for a in arrays:
        a = np.ascontiguousarray(a, float)
        parts += [np.asarray(a.shape, np.int64).tobytes(), a.tobytes()]
    return b"".join(parts)


def _base_attitudes(robot: Any, sol: Solution, t: np.ndarray, density: int) -> np.ndarray:
    """Base quaternions of a free-floating robot at the sample times ``t`` (``density`` per
    interval): integrated with zero momentum (Pinocchio's centroidal map, the RK4 scheme of
    :func:`~optplan.model.floating.simulate_base`) from each knot's attitude over its interval,
    along the exact joint trajectory; all intervals at once
    (:func:`~optplan.model.floating.attitudes_on_intervals`). The same inputs bit for bit as the
    last call for this robot (a re-solve that did not move the solution): that call's attitudes."""
    from ..model.floating import attitudes_on_intervals

    key = _attitude_inputs(sol, t, density)
    with _ATTITUDES_LOCK:
        got = _ATTITUDES.get(id(robot.model))
        if got is None or got[0] is not robot.model:
            got = _ATTITUDES[id(robot.model)] = (robot.model, {})
        kept = got[1]
        if key in kept:
            kept[key] = kept.pop(key)          # the most recent now
            return kept[key].copy()

    def joints(ts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = sol.sample(np.clip(ts, sol.t[0], sol.t[-1]))
        return s["q"], s["qd"]

    out = attitudes_on_intervals(robot, joints, t, np.asarray(sol.base_quat, float), density, substeps=2)
    with _ATTITUDES_LOCK:
        kept[key] = out.copy()
        while len(kept) > _ATTITUDES_KEPT:
            kept.pop(next(iter(kept)))
    return out


def check_between_knots(problem: Any, sol: Solution, options: GuaranteeOptions | None = None) -> list[Violation]:
    """Every constraint of ``problem`` not enforced between knots by construction, checked at
    ``options.density`` samples per interval of the solution ``sol`` (module docstring); the worst
    violation per (term, component, interval), worst first. An empty list: nothing violated."""
    o = options or GuaranteeOptions()
    ev = sol.evaluator
    if ev is None or sol.x is None:
        raise ValueError("check_between_knots: the solution carries no problem to evaluate (solve the problem and "
                         "pass its solution)")
    N = len(sol.t) - 1
    T = float(sol.t[-1] - sol.t[0])
    h = T / N
    t = np.linspace(0.0, T, o.density * N + 1)
    spline = not hasattr(ev, "data")   # the B-spline core: no knot TermData
    todo: list[tuple[str, Any, Any]] = []   # (name, term, its build's data): what is checked
    for name, hd in ev.handles.items():
        if hd.role != "constraint":
            continue
        term = hd.term
        if spline and sol.success and isinstance(term, _HULL_GUARANTEED):
            continue   # holds between knots by construction (below)
        if not isinstance(term, CollisionAvoidance):
            term = _sampled(term)
            if term is None:
                continue   # tied to given knots: holds there by construction
        todo.append((name, term, _collision_data(term, problem.robot) if spline else ev.data[name]))
    memo = _checks_of(problem) if spline else None
    key = _check_inputs(problem, sol, o, [tm for _, tm, _ in todo]) if memo is not None else b""
    if memo is not None:
        with _CHECKS_LOCK:
            got = memo.get(key)
            if got is not None and _same_terms(got[0], todo):
                memo[key] = memo.pop(key)          # the most recent now
                COUNTS["reused"] += 1
                return list(got[1])
    COUNTS["computed"] += 1
    traj = sampled_trajectory(problem.robot, sol, t + sol.t[0], getattr(ev, "com0", None))
    # the base attitude between knots is integrated only when a checked term reads it
    if traj.base_quat is not None and any(term.reads_base_attitude(problem.robot) for _, term, _ in todo):
        traj.base_quat = _base_attitudes(problem.robot, sol, t + sol.t[0], o.density)
    out: list[Violation] = []
    for name, term, data in todo:
        if isinstance(term, CollisionAvoidance):
            _collision(out, name, term, data, traj, t, h, N, o)
            continue
        v = np.asarray(term.numeric_built(traj, data), float).reshape(t.size, -1)
        lo, hi = (np.asarray(b, float).reshape(t.size, -1) for b in term.bounds_numeric(traj))
        _worst(out, name, t, h, N, _components(v.shape[1], problem.robot), v, lo, hi, o)
    out.sort(key=lambda x: -x.amount)
    if memo is not None:
        with _CHECKS_LOCK:
            memo[key] = (tuple((nm, type(tm), tuple(tm.__dict__.values())) for nm, tm, _ in todo), tuple(out))
            while len(memo) > max(_CHECKS_KEPT, 0):
                memo.pop(next(iter(memo)))
    return out


#: per problem on the B-spline core: the last few checks, by their inputs as bytes
#: (:func:`_check_inputs`) -> (the checked terms with their field values, the violations),
#: oldest first. A check whose inputs are equal bit for bit (a re-solve that reproduced an
#: earlier solution: a warm start IPOPT leaves where it was, a parameter set back to an earlier
#: value) returns the kept violations; anything else is checked again.
_CHECKS: weakref.WeakKeyDictionary[Any, dict[bytes, tuple[tuple[Any, ...], tuple[Violation, ...]]]] = \
    weakref.WeakKeyDictionary()
_CHECKS_KEPT = 4
_CHECKS_LOCK = threading.Lock()
#: checks computed / returned from :data:`_CHECKS` in this process [count] (what tests read)
COUNTS = {"computed": 0, "reused": 0}


def _checks_of(problem: Any) -> dict[bytes, Any] | None:
    """The kept checks of ``problem`` (None when none can be kept: 0 kept, or not weakly referable)."""
    if _CHECKS_KEPT <= 0:
        return None
    with _CHECKS_LOCK:
        try:
            got = _CHECKS.get(problem)
            if got is None:
                got = _CHECKS[problem] = {}
        except TypeError:
            return None
    return got


def _check_inputs(problem: Any, sol: Solution, o: GuaranteeOptions, terms: list[Any]) -> bytes:
    """Everything a check on the B-spline core reads, as bytes, besides which term objects it
    checks (:func:`_same_terms`): the options, the robot, whether ``sol`` converged (the
    hull-guaranteed terms are skipped only then), the solution's knots, trajectory and base, its
    variables and parameter vector, the parameters' current values (an expression term reads
    them) and the numbers of the terms' array fields (an array changed in place)."""
    ev = sol.evaluator
    arrays = [sol.t, sol.q, sol.qd, sol.qdd, sol.jerk, sol.x, getattr(ev, "p", None), getattr(ev, "com0", None),
              sol.base_quat, sol.base_position] + [p.value for p in getattr(problem, "_params", ())] \
        + [v for tm in terms for v in tm.__dict__.values() if isinstance(v, np.ndarray) and v.dtype.kind in "biuf"]
    parts = [repr(o).encode(), np.asarray([id(problem.robot.model), int(bool(sol.success))], np.int64).tobytes()]
    for a in arrays:
        if a is None:
            parts.append(b"-")
            continue
        a = np.ascontiguousarray(a, float)
        parts += [np.asarray(a.shape, np.int64).tobytes(), a.tobytes()]
    return b"".join(parts)


def _same_terms(kept: tuple[Any, ...], todo: list[tuple[str, Any, Any]]) -> bool:
    """Whether the checked terms are those of a kept check: the same names and types, each field
    the same object (an in-place change replaces the field's value; the kept check holds the
    field values, not the terms: nothing of the problem is kept alive by it)."""
    return len(kept) == len(todo) and all(
        nm == n2 and typ is type(t2) and len(f) == len(t2.__dict__)
        and all(a is b for a, b in zip(f, t2.__dict__.values()))
        for (nm, typ, f), (n2, t2, _) in zip(kept, todo))


#: Terms a converged solve on the B-spline core satisfies between knots by construction: position
#: limits bound every control point (the convex hull holds the spline), acceleration limits hold at
#: every knot and q̈ is linear between knots, velocity limits bound the velocity control points
#: (entries without rows are checked exactly after the solve, :mod:`.spline_rows`).
_HULL_GUARANTEED = (JointPositionLimits, JointVelocityLimits, JointAccelerationLimits)
#: a term's twin along the trajectory (``Term.sampled``), kept per term with the field values it
#: was made from: re-solves of one problem make (and validate) it once; None: tied to given knots
_SAMPLED: weakref.WeakKeyDictionary[Any, tuple[tuple[Any, ...], Any]] = weakref.WeakKeyDictionary()
_ITSELF = object()   # the term is its own twin


def _sampled(term: Any) -> Any:
    """``term.sampled()``, or None for a term tied to given knots; made again when a field of
    ``term`` was set since (an in-place change replaces the field's value)."""
    fields = tuple(term.__dict__.values())
    got = _SAMPLED.get(term)
    if got is not None and len(got[0]) == len(fields) and all(a is b for a, b in zip(got[0], fields)):
        return term if got[1] is _ITSELF else got[1]
    try:
        twin = term.sampled()
    except TypeError:
        twin = None
    _SAMPLED[term] = (fields, _ITSELF if twin is term else twin)   # never a strong reference to the key
    return twin


#: a collision term's model for the dense check, kept per term (terms are frozen) and robot:
#: re-solves of one problem build it once
_MODELS: weakref.WeakKeyDictionary[Any, tuple[Any, SimpleNamespace]] = weakref.WeakKeyDictionary()


def _collision_data(term: Any, robot: Any) -> Any:
    """What the dense check reads of a term's build on the B-spline core: for a collision term
    its checker and constant pairs (a :class:`CollisionModel` of the term, made once per term
    and robot), else nothing."""
    if not isinstance(term, CollisionAvoidance):
        return None
    got = _MODELS.get(term)
    if got is not None and got[0]() is robot:
        return got[1]
    m = CollisionModel(term, robot)
    ns = SimpleNamespace(info={"model": m, "constant_pairs": tuple(m.constant_pairs), "relaxed": {}})
    _MODELS[term] = (weakref.ref(robot), ns)
    return ns


# --------------------------------------------------------------------------- the refinement loop
def _lineage(new: Any, old: Any) -> Any:
    """Mark ``new`` as derived from ``old`` (a user's handle to ``old`` keeps working)."""
    object.__setattr__(new, "_origin", getattr(old, "_origin", old))
    return new


def _collision_retry(problem: Any, sol: Solution, viol: list[Violation], o: GuaranteeOptions) -> bool:
    """Activate pairs along the solution and raise margins around contacts; False if no collision
    term has a violation."""
    names = {v.term for v in viol}
    if getattr(problem, "_mode", lambda: "knots")() == "bspline":
        # the B-spline core plans its pairs along a trajectory: along this solution, on the same
        # grid, if it missed a pair; else a finer grid from this solution
        hits = [v for v in viol if v.term in problem.terms and isinstance(problem.terms[v.term].term, CollisionAvoidance)]
        if not problem._spline.replan_collision(sol, hits):
            return False
        log.info("between knots: collision rows planned again along the solution; re-solving")
        return True
    changed = False
    t = np.linspace(sol.t[0], sol.t[-1], o.density * (len(sol.t) - 1) + 1)
    for name, hd in list(problem.terms.items()):
        if name not in names or hd.role != "constraint" or not isinstance(hd.term, CollisionAvoidance):
            continue
        col = hd.term.with_activation(problem.numeric_trajectory(sol.x))
        if problem.robot.is_floating:
            tr = sol.evaluator.sampled_trajectory(sol, t)
            q = np.array([tr.q_full(i) for i in range(t.size)])
        else:
            q = sol.sample(t)["q"]
        col, n = col.with_boost(problem.term_data(hd), t, q, sol.t, min_clearance=float(hd.term.margin))
        log.info("between knots: %s: %d rows with a larger margin, pairs activated along the solution; re-solving",
                 name, n)
        problem.replace_term(hd, _lineage(col, hd.term))
        changed = True
    if changed:
        problem.set_initial(solution=sol)
    return changed


def _remap_at(at: Any, N: int, f: int) -> Any:
    if isinstance(at, (int, np.integer)):
        return int(at) % (N + 1) * f
    if isinstance(at, tuple):
        return tuple(int(a) % (N + 1) * f for a in at)
    return at


def _regriddable(problem: Any) -> bool:
    for hd in problem.terms.values():
        poses = getattr(hd.term, "poses", None)
        if poses is not None and not callable(poses):
            return False   # a path given per knot has no value at new knots
    return True


def _refine(problem: Any, sol: Solution, o: GuaranteeOptions) -> bool:
    """Re-grid the problem with ``growth``× the intervals, warm-started from ``sol``; False if
    not possible (interval cap, terms given per knot)."""
    f = int(o.growth)
    if problem.N * f > o.max_intervals or not _regriddable(problem):
        return False
    N = problem.N
    for _, hd in list(problem.terms.items()):
        term, new = hd.term, None
        at = getattr(term, "at", None)
        if at is not None and not isinstance(at, str):
            new = dataclasses.replace(term, at=_remap_at(at, N, f))
        if isinstance(term, CollisionAvoidance):
            # per-knot boosts and activating trajectories belong to the old grid; the warm start (this
            # solution) activates the pairs it brings close
            new = dataclasses.replace(term, activate_with=(), margin_boost={})
        if new is not None:
            problem.replace_term(hd, _lineage(new, term))
    spline = getattr(problem, "_mode", lambda: "knots")() == "bspline"
    problem.N = N * f
    problem._tp = None
    problem._changed()
    if spline or problem.robot.is_floating:
        problem.set_initial(solution=sol)   # base states re-integrated on the new grid
    else:
        # the solution itself, exactly: each interval split in f with the same constant jerk
        tk = np.linspace(sol.t[0], sol.t[-1], problem.N + 1)
        s = sol.sample(tk)
        problem._x0 = problem.tp.pack(s["q"], s["qd"], s["qdd"], np.repeat(np.asarray(sol.jerk), f, axis=0),
                                      T=sol.duration)
        problem._lam_g0 = problem._lam_x0 = None
    log.info("between knots: re-solving on %d intervals (was %d)", problem.N, N)
    return True


def enforce_between_knots(problem: Any, sol: Solution, solve_once: Callable[[], Solution],
                          options: GuaranteeOptions | None) -> Solution:
    """After a solve: check densely and refine (module docstring) until nothing is violated or
    the bounds are reached. Never returns ``success=True`` with a dense violation."""
    if options is None or not sol.success:
        return sol
    o = options
    viol = check_between_knots(problem, sol, o)
    n_col = n_ref = 0
    while viol:
        log.info("between knots: %d violation(s), worst %s", len(viol), viol[0])
        col = any(isinstance(problem.terms[v.term].term, CollisionAvoidance) for v in viol if v.term in problem.terms)
        if col and n_col < o.collision_retries and _collision_retry(problem, sol, viol, o):
            n_col += 1
            label = "collision"
        elif n_ref < o.refinements and _refine(problem, sol, o):
            n_ref += 1
            n_col = 0   # a new grid: its own collision retries
            label = "refine"
        else:
            break
        new = solve_once().labelled(label).after(sol)
        if not new.success:
            # keep the converged solution (with the failed attempt listed); a failed collision
            # re-solve passes on to the next step, a failed refinement ends the loop
            sol = dataclasses.replace(sol, attempts=new.attempts)
            if label == "refine":
                break
            n_col = o.collision_retries
            problem.set_initial(solution=sol)
            continue
        sol = new
        viol = check_between_knots(problem, sol, o)
    if viol:
        return dataclasses.replace(sol, success=False, status=IpoptStatus.VIOLATED_BETWEEN_KNOTS,
                                   between_knots=tuple(viol))
    return sol
