"""RRTConnect (Kuffner & LaValle 2000) in joint space, and joint-space path shortcutting.

:func:`rrt_connect` is the algorithm on any box-bounded vector space with a validity function; it
is what TCBiRRT calls for a regrasp (7-D: one arm's joints, the rest of the robot fixed).
:class:`RRTConnect` is the stand-alone planner in the robot's full joint space without an object
(self-collision and obstacles only): edges are straight lines in joint space, checked every
``resolution`` rad (largest joint change between checks).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .base import Deadline, PathSegment, Planner, PlanResult, PlanStatus
from .tree import Tree, joined_path
from .validity import ValidityChecker, _bisection_fractions, _bisection_order

if TYPE_CHECKING:
    from ..scene import Scene

__all__ = ["RRTConnectOptions", "RRTConnect", "rrt_connect", "shortcut_path", "edge_is_valid", "joint_space_path",
           "SAMPLERS", "halton_point"]
log = logging.getLogger(__name__)

TRAPPED, ADVANCED, REACHED = 0, 1, 2


@dataclass(frozen=True)
class RRTConnectOptions:
    """Options of :class:`RRTConnect` (joint-space RRT-Connect)."""

    #: Largest edge added per extension, Euclidean joint distance [rad].
    range: float = 1.0
    #: Largest per-joint change between two collision checks on an edge [rad].
    resolution: float = 0.03
    #: Cap on sample iterations [count] (0: only the time limit).
    max_iterations: int = 0
    #: Give up when one of the two trees has added no node for this many iterations [count] (0: never): its
    #: root is walled in (a pocket the tree cannot leave), and the search would run to its time limit.
    stall_iterations: int = 0
    #: Random shortcut attempts on the found path [count] (0: the raw tree path).
    shortcut_iterations: int = 100
    #: Clearance counted as contact by the validity checker [m].
    margin: float = 0.0
    #: Backend of the boolean collision checks: ``"native"`` (the compiled planning kernel,
    #: :mod:`optplan.planners.kernel`; coal when it cannot be built) or ``"coal"`` (Pinocchio + coal).
    validity_kernel: str = "native"
    #: Run the whole query (sampling, nearest neighbour, extensions, edge checks, shortcuts) as one call
    #: of the compiled kernel when the checks are native (:mod:`optplan.planners.kernel.rrtc`); its random
    #: stream is its own, seeded from the planner's generator. False, or a coal checker: the Python search.
    native_search: bool = True
    #: How the samples are drawn in the joint box: ``"uniform"`` (independent uniform draws) or ``"halton"``
    #: (the Halton sequence shifted by one uniform random vector modulo 1, :func:`halton_point`: a
    #: low-discrepancy sequence, each query its own; fewer iterations where a narrow region must be hit).
    sampler: str = "uniform"
    #: Dynamic domain (Yershova et al. 2005; VAMP's RRT-Connect): a node whose extension was trapped gets this
    #: radius [rad] (Euclidean joint distance), and a sample farther than its nearest node's radius is drawn
    #: again; the radius grows by ``1 + dynamic_domain_alpha`` at each later extension from the node that
    #: passes and shrinks by ``1 - dynamic_domain_alpha`` (to ``dynamic_domain_min``) at each that is trapped.
    #: 0: off. Native search only.
    dynamic_domain: float = 0.0
    #: The dynamic domain's growth and shrink factor [-] (VAMP: 1e-4).
    dynamic_domain_alpha: float = 1e-4
    #: The dynamic domain's least radius [rad].
    dynamic_domain_min: float = 1.0
    #: Tree balancing (VAMP's ``tree_ratio``): the tree that just grew grows again, instead of the trees
    #: alternating, while ``|n_this - n_other| / n_this >= balance`` (it is at most half the other's size
    #: for 1) [-]. 0: off (the trees alternate). The native and the Python search. Default 1 (VAMP's), since
    #: 2026-11-30: on MotionBenchMaker's Panda problems it halves the CPU per query (docs/planners.md).
    balance: float = 1.0
    #: The connection after a sample's extension: ``"other"`` (Kuffner and LaValle's connect: the other tree
    #: grows toward the new node, step after step of ``range``) or ``"new"`` (VAMP's: the new node's tree grows
    #: from it toward the other tree's nearest node, in equal steps of at most ``range``). Native search only.
    connect: str = "other"

    def __post_init__(self) -> None:
        for name in ("range", "resolution"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"RRTConnectOptions.{name}: expected a positive number, got {v!r}")
        for name in ("max_iterations", "stall_iterations", "shortcut_iterations"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 0):
                raise ValueError(f"RRTConnectOptions.{name}: expected an int >= 0, got {v!r}")
        if not (isinstance(self.margin, (int, float)) and math.isfinite(self.margin) and self.margin >= 0):
            raise ValueError(f"RRTConnectOptions.margin: expected a number >= 0 m, got {self.margin!r}")
        if not isinstance(self.native_search, bool):
            raise ValueError(f"RRTConnectOptions.native_search: expected True or False, got {self.native_search!r}")
        if self.validity_kernel not in ("native", "coal"):
            raise ValueError(f"RRTConnectOptions.validity_kernel: expected 'native' or 'coal', got {self.validity_kernel!r}")
        for name in ("dynamic_domain", "dynamic_domain_alpha", "dynamic_domain_min", "balance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"RRTConnectOptions.{name}: expected a number >= 0, got {v!r}")
        if self.dynamic_domain_alpha >= 1:
            raise ValueError(f"RRTConnectOptions.dynamic_domain_alpha: expected a number in [0, 1), got {self.dynamic_domain_alpha!r}")
        if self.connect not in CONNECTS:
            raise ValueError(f"RRTConnectOptions.connect: expected one of {CONNECTS}, got {self.connect!r}")
        if not self.native_search and (self.dynamic_domain > 0 or self.connect != "other"):
            raise ValueError("RRTConnectOptions: dynamic_domain and connect='new' are options of the native search; "
                             "native_search=False runs the Python search, which has neither (got "
                             f"dynamic_domain={self.dynamic_domain!r}, connect={self.connect!r})")
        if self.sampler not in SAMPLERS:
            raise ValueError(f"RRTConnectOptions.sampler: expected one of {SAMPLERS}, got {self.sampler!r}")


#: the samplers of :attr:`RRTConnectOptions.sampler`
SAMPLERS = ("uniform", "halton")
#: the connections of :attr:`RRTConnectOptions.connect`
CONNECTS = ("other", "new")
_PRIMES = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61, 67, 71, 73, 79, 83, 89, 97, 101, 103,
           107, 109, 113, 127, 131, 137, 139, 149, 151, 157, 163, 167, 173)


def halton_point(i: int, shift: np.ndarray) -> np.ndarray:
    """Point ``i`` (>= 1) of the Halton sequence in ``len(shift)`` dimensions (coordinate k: the radical
    inverse of ``i`` in the k-th prime base) plus ``shift`` modulo 1: a point of the unit cube [-]."""
    if len(shift) > len(_PRIMES):
        raise ValueError(f"halton_point: at most {len(_PRIMES)} dimensions, got {len(shift)}")
    out = np.empty(len(shift))
    for k, b in enumerate(_PRIMES[:len(shift)]):
        f, r, j = 1.0, 0.0, i
        while j > 0:
            f /= b
            r += f * (j % b)
            j //= b
        u = r + float(shift[k])
        out[k] = u - 1.0 if u >= 1.0 else u
    return out


def edge_is_valid(a: np.ndarray, b: np.ndarray, is_valid: Callable[[np.ndarray], bool], resolution: float,
                  check_end: bool = True, weights: np.ndarray | None = None) -> bool:
    """Straight joint-space edge a → b valid at every ``resolution`` step (largest joint change
    between checks [rad]; with ``weights`` w, the weighted step ``Σ w_j |Δq_j|`` instead, or with a
    matrix of weights the largest row's — e.g. :meth:`ValidityChecker.sweep_weights`, in which case
    ``resolution`` is a distance [m] that no point of the robot moves farther than between two checks); ``a`` itself is not checked, ``b``
    only with ``check_end``. Interior points are checked coarse-to-fine. An ``is_valid`` with a
    ``first_invalid(X)`` method (:meth:`ValidityChecker.validity`) gets them in one batch, in that order."""
    d = b - a
    size = float(np.abs(d).max()) if weights is None else float(np.max(weights @ np.abs(d)))
    n = max(1, int(math.ceil(size / resolution)))
    if check_end and not is_valid(b):
        return False
    batch = getattr(is_valid, "first_invalid", None)
    if batch is not None:   # e.g. ValidityChecker.validity: the same points in the same order, one call
        return n < 2 or batch(a + _bisection_fractions(n)[:, None] * d) < 0
    for k in _bisection_order(n):
        if not is_valid(a + (k / n) * d):
            return False
    return True


def _other_turn(ta: Tree, tb: Tree, balance: float) -> bool:
    """Whether tree b takes the next iteration: always, unless balancing (``balance`` > 0) keeps tree a, which just
    tried to grow, growing while ``|n_a − n_b| / n_a >= balance`` (the native search's ``rrtc_other_turn``)."""
    return not (balance > 0 and abs(ta.n - tb.n) / ta.n >= balance)


def rrt_connect(start: np.ndarray, goal: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                is_valid: Callable[[np.ndarray], bool], rng: np.random.Generator, deadline: Deadline, *,
                range_: float = 1.0, resolution: float = 0.03, max_iterations: int = 0,
                stats: dict[str, Any] | None = None, weights: np.ndarray | None = None,
                sampler: str = "uniform", stall_iterations: int = 0, balance: float = 0.0) -> list[np.ndarray] | None:
    """RRTConnect between two valid points of the box ``[lower, upper]``, its samples drawn by ``sampler``
    (:attr:`RRTConnectOptions.sampler`); ``balance`` (:attr:`RRTConnectOptions.balance`, 0: off) keeps the tree
    that just tried to grow growing while ``|n_a − n_b| / n_a >= balance``, as the native search does.

    Returns the list of tree nodes from ``start`` to ``goal`` (consecutive nodes joined by valid
    straight edges, checked as :func:`edge_is_valid` with ``resolution`` and ``weights``) or None
    (deadline / iteration cap / ``stall_iterations`` > 0 iterations in which one tree added no node).
    ``stats`` (optional dict) receives ``iterations``, ``nodes`` and, when the search stalled, ``stalled``.
    """
    start = np.asarray(start, float)
    goal = np.asarray(goal, float)
    stats = stats if stats is not None else {}
    if edge_is_valid(start, goal, is_valid, resolution, weights=weights):
        stats["iterations"] = stats.get("iterations", 0)
        stats["nodes"] = stats.get("nodes", 0) + 2
        return [start.copy(), goal.copy()]
    ta, tb = Tree(start), Tree(goal)
    a_is_start = True
    it = 0
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    shift = rng.uniform(size=len(lower)) if sampler == "halton" else None

    def extend(tree: Tree, target: np.ndarray) -> tuple[int, int]:
        i = tree.nearest(target)
        xn = tree.X[i]
        d = target - xn
        dist = float(np.sqrt(d @ d))
        if dist <= range_:
            xnew, res = target.copy(), REACHED
        else:
            xnew, res = xn + (range_ / dist) * d, ADVANCED
        if not edge_is_valid(xn, xnew, is_valid, resolution, weights=weights):
            return TRAPPED, -1
        return res, tree.add(xnew, i)

    found = None
    grew, n_prev = [0, 0], [1, 1]   # the last iteration each tree (start's, goal's) grew; its size then
    while not deadline.expired() and (max_iterations <= 0 or it < max_iterations):
        if it > 0 and stall_iterations > 0:
            for k, t in enumerate((ta, tb) if a_is_start else (tb, ta)):
                if t.n != n_prev[k]:
                    grew[k], n_prev[k] = it, t.n
            if it - min(grew) >= stall_iterations:
                stats["stalled"] = stats.get("stalled", 0) + 1
                break
        it += 1
        xr = rng.uniform(lower, upper) if shift is None else lower + (upper - lower) * halton_point(it, shift)
        res, ia = extend(ta, xr)
        if res == TRAPPED:
            if _other_turn(ta, tb, balance):
                ta, tb, a_is_start = tb, ta, not a_is_start
            continue
        target = ta.X[ia].copy()
        while True:
            res, ib = extend(tb, target)
            if res != ADVANCED or deadline.expired():
                break
        if res == REACHED:
            found = (ia, ib)
            break
        if _other_turn(ta, tb, balance):
            ta, tb, a_is_start = tb, ta, not a_is_start
    stats["iterations"] = stats.get("iterations", 0) + it
    stats["nodes"] = stats.get("nodes", 0) + ta.n + tb.n
    if found is None:
        return None
    return joined_path(ta, found[0], tb, found[1], a_is_start)


def shortcut_path(path: list[np.ndarray], is_valid: Callable[[np.ndarray], bool], resolution: float,
                  rng: np.random.Generator, iterations: int = 100, deadline: Deadline | None = None,
                  weights: np.ndarray | None = None) -> list[np.ndarray]:
    """Random shortcutting: replace the sub-path between two random nodes by a straight edge
    when that edge is valid (:func:`edge_is_valid` with ``resolution`` and ``weights``). Endpoints
    are kept."""
    path = [np.asarray(p, float) for p in path]
    for _ in range(iterations):
        if len(path) <= 2 or (deadline is not None and deadline.expired()):
            break
        i, j = sorted(rng.choice(len(path), size=2, replace=False))
        if j - i < 2:
            continue
        if edge_is_valid(path[i], path[j], is_valid, resolution, weights=weights):
            path = path[:i + 1] + path[j:]
    return path


def _tune(o: RRTConnectOptions) -> tuple[float, float, float, float, float]:
    """The native search's ``tune`` of ``o``: the dynamic domain, the balance ratio and the connection."""
    return (o.dynamic_domain, o.dynamic_domain_alpha, o.dynamic_domain_min, o.balance, float(o.connect == "new"))


def _native_query(start: np.ndarray, goal: np.ndarray, lower: np.ndarray, upper: np.ndarray, validity: Any,
                  rng: np.random.Generator | None, deadline: Deadline, o: RRTConnectOptions, *, seed: int | None = None,
                  check_ends: bool = False) -> Any:
    """:func:`~optplan.planners.kernel.rrtc.native_rrt_connect` with the options ``o`` (its result, or None when
    the native search cannot run)."""
    from .kernel.rrtc import native_rrt_connect

    return native_rrt_connect(start, goal, lower, upper, validity, rng, deadline, range_=o.range,
                              resolution=o.resolution, max_iterations=o.max_iterations,
                              stall_iterations=o.stall_iterations, shortcut_iterations=o.shortcut_iterations,
                              sampler=o.sampler, tune=_tune(o), seed=seed, check_ends=check_ends)


def _native_stats(got: Any, o: RRTConnectOptions, stats: dict[str, Any]) -> None:
    """A native query's counts into ``stats`` (as :func:`joint_space_path` reports them)."""
    stats["search"] = "native"
    stats["iterations"] = stats.get("iterations", 0) + got.iterations
    stats["nodes"] = stats.get("nodes", 0) + got.nodes
    if o.dynamic_domain > 0:
        stats["rejected"] = stats.get("rejected", 0) + got.rejected
    if got.status == "stalled":
        stats["stalled"] = stats.get("stalled", 0) + 1
    elif got.status not in ("found", "iteration cap", "time limit"):
        log.warning("native RRT-Connect stopped: %s", got.status)


def joint_space_path(start: np.ndarray, goal: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                     validity: Callable[[np.ndarray], bool], rng: np.random.Generator, deadline: Deadline,
                     options: RRTConnectOptions, stats: dict[str, Any] | None = None) -> list[np.ndarray] | None:
    """RRT-Connect from ``start`` to ``goal`` in the box ``[lower, upper]`` with ``options`` (range,
    resolution, iteration cap) and then ``options.shortcut_iterations`` shortcuts: the path or None.

    With ``options.native_search`` and a ``validity`` of a checker on the native kernel
    (:meth:`ValidityChecker.validity`) the whole query is one native call
    (:func:`optplan.planners.kernel.rrtc.native_rrt_connect`); else :func:`rrt_connect` and
    :func:`shortcut_path`. ``stats`` receives ``iterations``, ``nodes`` (added) and ``search``
    (``"native"`` or ``"python"``)."""
    stats = stats if stats is not None else {}
    o = options
    if o.native_search:
        got = _native_query(start, goal, lower, upper, validity, rng, deadline, o)
        if got is not None:
            _native_stats(got, o, stats)
            return None if got.path is None else list(got.path)
    if o.dynamic_domain > 0 or o.connect != "other":
        log.warning("the native RRT-Connect is unavailable here: the Python search runs without dynamic_domain and "
                    "connect='new'")
    stats["search"] = "python"
    path = rrt_connect(start, goal, lower, upper, validity, rng, deadline, range_=o.range, resolution=o.resolution,
                       max_iterations=o.max_iterations, stats=stats, sampler=o.sampler,
                       stall_iterations=o.stall_iterations, balance=o.balance)
    if path is not None and o.shortcut_iterations:
        path = shortcut_path(path, validity, o.resolution, rng, o.shortcut_iterations)
    return path


class RRTConnect(Planner):
    """RRTConnect in the full joint space, without the held object (self-collision and obstacles).

    ``plan(q_start, q_goal, time_limit, seed)`` → :class:`PlanResult` with one ``"free"``
    segment; ``object_poses`` are None and ``constrained`` False.
    """

    name = "rrtconnect"
    _lazy_rng = True   # the native query takes the seed itself; the Python search makes its Generator

    def __init__(self, robot: Any, scene: Scene | None = None, options: RRTConnectOptions | None = None, *,
                 checker: ValidityChecker | None = None) -> None:
        super().__init__(robot, scene)
        self.options = options or RRTConnectOptions()
        if not isinstance(self.options, RRTConnectOptions):
            raise TypeError(f"options: expected RRTConnectOptions, got {type(self.options).__name__}")
        self.checker = checker or ValidityChecker(robot, scene, margin=self.options.margin,
                                                   kernel=self.options.validity_kernel)

    def _plan(self, q_start: np.ndarray, q_goal: np.ndarray, deadline: Deadline, rng: np.random.Generator | None,
              seed: int) -> PlanResult:
        o, ck = self.options, self.checker
        stats: dict[str, Any] = {}
        if o.native_search:   # one native call: the ends' checks and the search (the seed's Generator draw made there)
            got = _native_query(q_start, q_goal, self.robot.lower, self.robot.upper, ck.validity("free"), None,
                                deadline, o, seed=seed, check_ends=True)
            if got is not None:
                if got.status == "invalid start":
                    return self.empty_result(PlanStatus.INVALID_START, "start out of limits or in collision")
                if got.status == "invalid goal":
                    return self.empty_result(PlanStatus.INVALID_GOAL, "goal out of limits or in collision")
                _native_stats(got, o, stats)
                checks = got.checks - got.end_checks
                if got.path is None:
                    st = PlanStatus.TIMEOUT if deadline.expired() else PlanStatus.FAILED
                    return self.empty_result(st, "no path", **stats, collision_checks=checks)
                P = got.path
                stats["collision_checks"] = checks
                return PlanResult(PlanStatus.EXACT, self.name, P, [None] * len(P), np.zeros(len(P), bool),
                                  [PathSegment("free", 0, len(P) - 1)], stats)
        if rng is None:
            rng = np.random.default_rng(seed)
        valid = ck.is_valid_free
        if not (ck.in_limits(q_start) and valid(q_start)):
            return self.empty_result(PlanStatus.INVALID_START, "start out of limits or in collision")
        if not (ck.in_limits(q_goal) and valid(q_goal)):
            return self.empty_result(PlanStatus.INVALID_GOAL, "goal out of limits or in collision")
        c0 = ck.n_checks
        path = joint_space_path(q_start, q_goal, self.robot.lower, self.robot.upper, ck.validity("free"), rng, deadline,
                                o, stats)
        if path is None:
            st = PlanStatus.TIMEOUT if deadline.expired() else PlanStatus.FAILED
            return self.empty_result(st, "no path", **stats, collision_checks=ck.n_checks - c0)
        P = np.array(path)
        stats["collision_checks"] = ck.n_checks - c0
        return PlanResult(PlanStatus.EXACT, self.name, P, [None] * len(P), np.zeros(len(P), bool),
                          [PathSegment("free", 0, len(P) - 1)], stats)
