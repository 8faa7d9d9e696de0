"""Constrained PRM — a probabilistic roadmap on the closed-chain manifold (Jang et al. 2022; the TCBiRRT paper's
Section 5.2 item 5: "handles closed-chain constraints by sampling the pose of the manipulated
object; the sampling range is identical to that used in TCBiRRT; the collision checking step size
is 0.2 rad").

One query grows one roadmap until start and goal are in the same connected component:

1. **Sample** an object pose ξ = (x, y, z, roll, pitch, yaw) uniformly in TCBiRRT's box
   (:attr:`ConstrainedPRMOptions.xi_lower`/``xi_upper``), solve both hands onto it by IK from a
   random joint seed (:meth:`~optplan.constraints.closed_chain.ClosedChainKinematics.ik`) unless the
   object collides or a grasp is out of reach (``sample_filter``), keep
   the configuration when it is inside the joint limits and collision-free (object held).
2. **Connect** it to its ``k_neighbours`` nearest roadmap nodes (joint-space Euclidean distance,
   at most ``max_edge_length`` away) that lie in another component, with the **constrained local
   planner**: the straight joint segment cut every ``collision_step`` rad, each cut point projected
   onto the manifold (Newton-Raphson, damped pseudo-inverse) and checked; an edge fails when a
   projection fails, a projected point collides, or two consecutive points are farther apart than
   ``2 · collision_step`` (the projection jumped to another branch).
3. When start and goal share a component, the roadmap path between them (breadth-first over the
   forest of connecting edges; every edge joins two components, so it is the only path) with each
   edge's projected points is returned: every configuration satisfies the closed chain to
   ``tolerance``.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..constraints.closed_chain import ClosedChainKinematics, IKSettings, closure_error
from ..errors import ConfigurationError
from ..geometry.spatial import rpy_to_matrix
from .base import Deadline, PathSegment, Planner, PlanResult, PlanStatus
from .manifold_samples import project_onto_chain
from .task_sampling import ObjectPoseFilter
from .tcbirrt_options import PAPER_XI_LOWER, PAPER_XI_UPPER
from .validity import ValidityChecker

__all__ = ["ConstrainedPRMOptions", "ConstrainedPRM", "constrained_edge"]


def _sampling_ik() -> IKSettings:
    return IKSettings(max_iterations=200, damping=0.02, max_step=0.3)


@dataclass(frozen=True)
class ConstrainedPRMOptions:
    """Options of :class:`ConstrainedPRM`."""

    #: Roadmap neighbours a new node tries to connect to [count].
    k_neighbours: int = 10
    #: Longest roadmap edge tried [rad] (joint-space Euclidean distance; IK from random seeds puts nodes on
    #: different arm branches, several rad apart in 14 joints).
    max_edge_length: float = 6.0
    #: Joint spacing of the projected, collision-checked points of an edge [rad] (the paper: 0.2).
    collision_step: float = 0.2
    #: Projection tolerance on the closed-chain residual, max |h| [m or rad per row].
    tolerance: float = 1e-7
    #: Newton iterations of one projection [count].
    max_projection_iterations: int = 50
    #: Lower corner of the object-pose sampling box (x, y, z [m], roll, pitch, yaw [rad]; TCBiRRT's).
    xi_lower: tuple[float, ...] = PAPER_XI_LOWER
    #: Upper corner of the object-pose sampling box (x, y, z [m], roll, pitch, yaw [rad]).
    xi_upper: tuple[float, ...] = PAPER_XI_UPPER
    #: IK of a sampled object pose from a random joint seed (tolerances [m, rad], iterations, damping).
    ik: IKSettings = field(default_factory=_sampling_ik)
    #: Reject an object pose before IK when the object collides with an obstacle or a grasp lies out of
    #: its arm's reach (:class:`~optplan.planners.task_sampling.ObjectPoseFilter`: necessary conditions, so
    #: no valid configuration is lost) [-].
    sample_filter: bool = True
    #: Clearance counted as contact [m].
    margin: float = 0.0
    #: Cap on the sampling iterations [count] (0: only the time limit).
    max_iterations: int = 0

    def __post_init__(self) -> None:
        for name in ("k_neighbours", "max_projection_iterations"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"ConstrainedPRMOptions.{name}: expected an integer >= 1, got {v!r}")
        if isinstance(self.max_iterations, bool) or not isinstance(self.max_iterations, int) or self.max_iterations < 0:
            raise ValueError(f"ConstrainedPRMOptions.max_iterations: expected an integer >= 0, got {self.max_iterations!r}")
        for name in ("max_edge_length", "collision_step", "tolerance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"ConstrainedPRMOptions.{name}: expected a positive number, got {v!r}")
        if not (isinstance(self.margin, (int, float)) and math.isfinite(self.margin) and self.margin >= 0):
            raise ValueError(f"ConstrainedPRMOptions.margin: expected a number >= 0 m, got {self.margin!r}")
        lo, hi = np.asarray(self.xi_lower, float), np.asarray(self.xi_upper, float)
        if lo.shape != (6,) or hi.shape != (6,) or not np.all(np.isfinite(lo)) or np.any(lo > hi):
            raise ValueError(f"ConstrainedPRMOptions.xi_lower/xi_upper: expected two 6-vectors with lower <= upper, "
                             f"got {self.xi_lower!r}, {self.xi_upper!r}")
        object.__setattr__(self, "xi_lower", tuple(float(x) for x in lo))
        object.__setattr__(self, "xi_upper", tuple(float(x) for x in hi))
        if not isinstance(self.sample_filter, bool):
            raise ValueError(f"ConstrainedPRMOptions.sample_filter: expected True/False, got {self.sample_filter!r}")
        if not isinstance(self.ik, IKSettings):
            raise ValueError(f"ConstrainedPRMOptions.ik: expected IKSettings, got {type(self.ik).__name__}")


def constrained_edge(qa: np.ndarray, qb: np.ndarray, project: Any, valid: Any, step: float,
                     deadline: Deadline | None = None) -> list[np.ndarray] | None:
    """The constrained local planner: projected, valid points strictly between ``qa`` and ``qb``
    (both on the manifold), one every ``step`` rad along the straight segment, or None when a
    projection fails (``project(q) is None``), a point is invalid (``valid(q)`` false), two
    consecutive points are more than ``2 · step`` apart, or the deadline expires."""
    d = qb - qa
    n = max(1, int(math.ceil(float(np.sqrt(d @ d)) / step)))
    out: list[np.ndarray] = []
    prev = qa
    for k in range(1, n):
        if deadline is not None and deadline.expired():
            return None
        x = project(qa + (k / n) * d)
        if x is None or float(np.linalg.norm(x - prev)) > 2.0 * step or not valid(x):
            return None
        out.append(x)
        prev = x
    if float(np.linalg.norm(qb - prev)) > 2.0 * step:
        return None
    return out


class _Roadmap:
    """Nodes (growing array), union-find components and the connecting edges' points."""

    def __init__(self, nq: int, cap: int = 1024) -> None:
        self.X = np.empty((cap, nq))
        self.n = 0
        self.parent: list[int] = []
        self.adj: list[list[int]] = []
        self.edges: dict[tuple[int, int], list[np.ndarray]] = {}

    def add(self, q: np.ndarray) -> int:
        if self.n == len(self.X):
            self.X = np.concatenate([self.X, np.empty_like(self.X)])
        self.X[self.n] = q
        self.parent.append(self.n)
        self.adj.append([])
        self.n += 1
        return self.n - 1

    def find(self, i: int) -> int:
        while self.parent[i] != i:
            self.parent[i] = self.parent[self.parent[i]]
            i = self.parent[i]
        return i

    def connect(self, i: int, j: int, pts: list[np.ndarray]) -> None:
        self.parent[self.find(i)] = self.find(j)
        self.adj[i].append(j)
        self.adj[j].append(i)
        self.edges[(i, j)] = pts
        self.edges[(j, i)] = pts[::-1]

    def path(self, a: int, b: int) -> list[np.ndarray]:
        prev = {a: a}
        todo = deque([a])
        while todo:
            i = todo.popleft()
            if i == b:
                break
            for j in self.adj[i]:
                if j not in prev:
                    prev[j] = i
                    todo.append(j)
        chain = [b]
        while chain[-1] != a:
            chain.append(prev[chain[-1]])
        chain.reverse()
        out = [self.X[chain[0]].copy()]
        for i, j in zip(chain[:-1], chain[1:]):
            out.extend(p.copy() for p in self.edges[(i, j)])
            out.append(self.X[j].copy())
        return out

    def components(self) -> int:
        return len({self.find(i) for i in range(self.n)})


class ConstrainedPRM(Planner):
    """Constrained PRM on the closed chain of ``scene.object``'s two grasps (module docstring)."""

    name = "constrained-prm"

    def __init__(self, robot: Any, scene: Any, options: ConstrainedPRMOptions | None = None, *,
                 checker: ValidityChecker | None = None, kinematics: ClosedChainKinematics | None = None) -> None:
        super().__init__(robot, scene)
        if scene is None or scene.object is None or len(scene.object.grasps) != 2:
            raise ConfigurationError("ConstrainedPRM needs a scene with an [object] grasped by two arms")
        self.options = options or ConstrainedPRMOptions()
        if not isinstance(self.options, ConstrainedPRMOptions):
            raise TypeError(f"options: expected ConstrainedPRMOptions, got {type(self.options).__name__}")
        self.checker = checker or ValidityChecker(robot, scene, margin=self.options.margin)
        self.kin = kinematics or ClosedChainKinematics(robot, scene.object.grasps)
        self.grasps = scene.object.grasps
        self.pose_filter = ObjectPoseFilter(robot, scene, self.options.margin) if self.options.sample_filter else None

    def _project(self, q: np.ndarray, st: dict[str, Any]) -> np.ndarray | None:
        st["projections"] += 1
        o = self.options
        x = project_onto_chain(self.kin, q, self.robot.lower, self.robot.upper, o.tolerance, o.max_projection_iterations)
        if x is None:
            st["projection_failures"] += 1
        return x

    def sample(self, rng: np.random.Generator, st: dict[str, Any]) -> np.ndarray | None:
        """One roadmap node: an object pose in the box, IK from a random seed, limits and collisions
        checked; None when any step fails."""
        o = self.options
        xi = rng.uniform(o.xi_lower, o.xi_upper)
        R = rpy_to_matrix(*xi[3:])
        if self.pose_filter is not None and not self.pose_filter(R, xi[:3]):
            st["filtered_poses"] += 1
            return None
        lo, hi = self.robot.lower, self.robot.upper
        seed = rng.uniform(np.maximum(lo, -np.pi), np.minimum(hi, np.pi))
        q, _ = self.kin.ik(seed, R, xi[:3], o.ik)
        if q is None:
            st["ik_failures"] += 1
            return None
        q = self._project(q, st)   # to the planner's residual tolerance (the IK stops at its own)
        if q is None or not self.checker.is_valid(q):
            st["invalid_samples"] += 1
            return None
        return q

    def _connect(self, rm: _Roadmap, i: int, st: dict[str, Any], deadline: Deadline) -> None:
        o = self.options
        q = rm.X[i]
        d = np.linalg.norm(rm.X[:rm.n] - q, axis=1)
        d[i] = np.inf
        for j in np.argsort(d)[:o.k_neighbours]:
            j = int(j)
            if d[j] > o.max_edge_length or deadline.expired():
                break
            if rm.find(i) == rm.find(j):
                continue
            st["edge_attempts"] += 1
            pts = constrained_edge(q, rm.X[j], lambda x: self._project(x, st), self.checker.is_valid,
                                   o.collision_step, deadline)
            if pts is not None:
                rm.connect(i, j, pts)
                st["edges"] += 1

    def _plan(self, q_start: np.ndarray, q_goal: np.ndarray, deadline: Deadline, rng: np.random.Generator,
              seed: int) -> PlanResult:
        o, ck = self.options, self.checker
        st = {"iterations": 0, "projections": 0, "projection_failures": 0, "filtered_poses": 0, "ik_failures": 0, "invalid_samples": 0,
              "edge_attempts": 0, "edges": 0}
        c0 = ck.n_checks
        bad = invalid_endpoints(self, q_start, q_goal, st)
        if bad is not None:
            return bad
        rm = _Roadmap(self.robot.nq)
        rm.add(q_start)
        rm.add(q_goal)
        self._connect(rm, 1, st, deadline)
        while rm.find(0) != rm.find(1) and not deadline.expired():
            if o.max_iterations and st["iterations"] >= o.max_iterations:
                break
            st["iterations"] += 1
            q_new = self.sample(rng, st)
            if q_new is None:
                continue
            self._connect(rm, rm.add(q_new), st, deadline)
        st["nodes"] = rm.n
        st["components"] = rm.components()
        st["collision_checks"] = ck.n_checks - c0
        if rm.find(0) != rm.find(1):
            if deadline.expired():
                return self.empty_result(PlanStatus.TIMEOUT, "time limit reached", **st)
            return self.empty_result(PlanStatus.FAILED, "iteration cap reached", **st)
        P = np.array(rm.path(0, 1))
        P[0], P[-1] = q_start, q_goal
        poses = [self.kin.object_pose(q) for q in P]
        return PlanResult(PlanStatus.EXACT, self.name, P, poses, np.ones(len(P), bool),
                          [PathSegment("constrained", 0, len(P) - 1)], st)


def invalid_endpoints(planner: Any, q_start: np.ndarray, q_goal: np.ndarray, stats: dict[str, Any]) -> PlanResult | None:
    """The result of a closed-chain planner (``planner``: ``robot``, ``grasps``, ``checker``,
    ``empty_result``) whose start or goal is outside the joint limits, off the closed chain (>
    1e-6) or in collision, with ``stats``; None when both are valid."""
    ck = planner.checker
    for which, q, status in (("start", q_start, PlanStatus.INVALID_START), ("goal", q_goal, PlanStatus.INVALID_GOAL)):
        ep, eo = closure_error(planner.robot, planner.grasps, q)
        if not ck.in_limits(q):
            return planner.empty_result(status, f"{which} outside the joint limits", **stats)
        if max(ep, eo) > 1e-6:
            return planner.empty_result(status, f"{which} off the closed-chain manifold ({max(ep, eo):.1e})", **stats)
        if not ck.is_valid(q):
            return planner.empty_result(status, f"{which} in collision", **stats)
    return None
