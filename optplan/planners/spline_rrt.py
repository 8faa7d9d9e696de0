"""Coordinated task-space RRT* for two end-effectors with separated sampling (Spline-RRT*, Yu et al.,
Sec. 3.2).

One RRT* tree (Karaman & Frazzoli 2011: choose-parent and rewiring inside a shrinking ball, cost =
Euclidean path length [m]) grows per end-effector *position*, from its start towards its goal. The
two hands never cross because each samples only on its own side of a **virtual wall** that moves
with the end-effectors (the separated-space strategy): at progress ``s ∈ [0, 1]`` along the travel of
the hands' midpoint ``m(s) = (1 − s) m_start + s m_goal`` the wall is the plane through ``m(s)`` with
normal ``n(s)``, the hands' separation direction interpolated between start and goal (component
orthogonal to the travel). A point ``x`` has progress ``s(x)`` = its projection on the travel
(clipped to [0, 1]) and wall coordinate ``w(x) = (x − m(s(x)))·n(s(x))``; hand ``first`` keeps
``w ≤ −wall_margin``, hand ``second`` ``w ≥ wall_margin`` — on samples, new vertices and every point
of every edge (checked at ``edge_resolution``). Hand positions are also kept ``hand_radius`` away from
the scene's obstacles (exact point distances to spheres, capsules and boxes).

    planner = CoordinatedRRTStar(scene, CoordinatedRRTStarOptions(seed=1))
    res = planner.plan({"A": (pa0, pa1), "B": (pb0, pb1)})     # positions [m], world frame
    res.status, res.paths["A"]                                   # PlanStatus, (M, 3) waypoints

With ``separate=False`` both trees sample the whole box (the unseparated baseline of the paper's
Fig. 4(a)).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from ..scene import Obstacle, Scene
from .base import PlanStatus

__all__ = ["CoordinatedRRTStarOptions", "VirtualWall", "Tree", "CoordinatedPlan", "CoordinatedRRTStar",
           "point_obstacle_distance"]


@dataclass(frozen=True)
class CoordinatedRRTStarOptions:
    """Options of :class:`CoordinatedRRTStar`."""

    #: Maximal edge length of the steering function [m].
    step: float = 0.1
    #: Upper bound of the RRT* neighbourhood radius [m]; with n vertices the radius is ``min(rewire_radius,
    #: gamma (log n / n)^(1/3))``.
    rewire_radius: float = 0.3
    #: RRT* constant [m] (None: Karaman-Frazzoli's ``2 (1 + 1/3)^(1/3) (vol / ζ₃)^(1/3)`` with the sampling
    #: box's volume, times 1.1).
    gamma: float | None = None
    #: Iterations per tree [count] (every iteration draws one sample).
    max_iterations: int = 600
    #: Wall-time limit of the whole query [s].
    time_limit: float = 1.0
    #: Probability of sampling the goal [-].
    goal_bias: float = 0.05
    #: Stop a tree as soon as it reaches its goal (plain RRT behaviour with rewiring); False keeps improving the
    #: path until the iteration or time limit (RRT*).
    stop_at_first: bool = False
    #: Clearance of a hand position from the obstacles [m].
    hand_radius: float = 0.05
    #: Distance each hand keeps from the virtual wall [m].
    wall_margin: float = 0.03
    #: Sample each hand on its own side of the wall (False: the unseparated baseline).
    separate: bool = True
    #: The sampling box is the bounding box of the starts and goals grown by this [m].
    padding: float = 0.25
    #: Spacing of the points checked along an edge [m].
    edge_resolution: float = 0.01
    #: Seed of the numpy Generator (None: nondeterministic).
    seed: int | None = None

    def __post_init__(self) -> None:
        for name in ("step", "rewire_radius", "time_limit", "edge_resolution"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"CoordinatedRRTStarOptions.{name}: expected a positive number, got {v!r}")
        for name in ("hand_radius", "wall_margin", "padding"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"CoordinatedRRTStarOptions.{name}: expected a number ≥ 0 [m], got {v!r}")
        if self.gamma is not None and not (math.isfinite(self.gamma) and self.gamma > 0):
            raise ValueError(f"CoordinatedRRTStarOptions.gamma: expected a positive number or None, got {self.gamma!r}")
        if isinstance(self.max_iterations, bool) or not isinstance(self.max_iterations, int) or self.max_iterations < 1:
            raise ValueError(f"CoordinatedRRTStarOptions.max_iterations: expected an integer ≥ 1, got {self.max_iterations!r}")
        if not 0.0 <= self.goal_bias < 1.0:
            raise ValueError(f"CoordinatedRRTStarOptions.goal_bias: expected a probability in [0, 1), got {self.goal_bias!r}")


# --------------------------------------------------------------------------- geometry
def point_obstacle_distance(points: np.ndarray, obstacle: Obstacle) -> np.ndarray:
    """Exact Euclidean distance [m] from points (K, 3) to a scene obstacle (sphere, capsule or box;
    negative inside a sphere/capsule, 0 inside a box)."""
    P = np.atleast_2d(np.asarray(points, float))
    M = obstacle.placement
    local = (P - M.translation) @ M.rotation  # R^T (p - t) for every row
    if obstacle.shape == "sphere":
        return np.linalg.norm(local, axis=1) - obstacle.radius
    if obstacle.shape == "capsule":
        h = cast(float, obstacle.length) / 2.0   # a capsule has a length
        z = np.clip(local[:, 2], -h, h)
        d = local.copy()
        d[:, 2] -= z
        return np.linalg.norm(d, axis=1) - obstacle.radius
    half = np.asarray(obstacle.size, float) / 2.0
    q = np.abs(local) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=1)


@dataclass(frozen=True)
class VirtualWall:
    """The moving wall between two hands (module docstring): midpoints ``m0``, ``m1`` [m] of the hands
    at start and goal and unit separation normals ``n0``, ``n1`` (from the first hand to the second,
    orthogonal to the travel ``m1 − m0``)."""

    m0: np.ndarray
    m1: np.ndarray
    n0: np.ndarray
    n1: np.ndarray

    @classmethod
    def from_task(cls, first: tuple[Any, Any], second: tuple[Any, Any]) -> VirtualWall:
        """Wall of the task ``first = (start, goal)``, ``second = (start, goal)`` (positions [m])."""
        (a0, a1), (b0, b1) = (np.asarray(first[0], float), np.asarray(first[1], float)), \
                             (np.asarray(second[0], float), np.asarray(second[1], float))
        m0, m1 = 0.5 * (a0 + b0), 0.5 * (a1 + b1)
        travel = m1 - m0
        L = np.linalg.norm(travel)
        u = travel / L if L > 1e-12 else np.zeros(3)

        def normal(d: np.ndarray, when: str) -> np.ndarray:
            d = d - (d @ u) * u
            n = np.linalg.norm(d)
            if n < 1e-9:
                raise ValueError(f"virtual wall: the two hands' {when} positions are not separated across the "
                                 f"travel direction (separation {np.round(d, 6).tolist()} m)")
            return d / n
        return cls(m0, m1, normal(b0 - a0, "start"), normal(b1 - a1, "goal"))

    def coordinate_point(self, x: np.ndarray) -> float:
        """:meth:`coordinate` of one point (3,), without numpy's per-call overhead (the sampler's
        rejection loop calls it once per candidate)."""
        m0, m1, n0, n1 = self.m0, self.m1, self.n0, self.n1
        dx, dy, dz = m1[0] - m0[0], m1[1] - m0[1], m1[2] - m0[2]
        L2 = dx * dx + dy * dy + dz * dz
        px, py, pz = x[0] - m0[0], x[1] - m0[1], x[2] - m0[2]
        s = 0.0 if L2 < 1e-24 else min(1.0, max(0.0, (px * dx + py * dy + pz * dz) / L2))
        nx, ny, nz = (1 - s) * n0[0] + s * n1[0], (1 - s) * n0[1] + s * n1[1], (1 - s) * n0[2] + s * n1[2]
        nn = (nx * nx + ny * ny + nz * nz) ** 0.5
        return ((px - s * dx) * nx + (py - s * dy) * ny + (pz - s * dz) * nz) / nn

    def progress(self, P: np.ndarray) -> np.ndarray:
        """Progress s ∈ [0, 1] of points (K, 3)."""
        d = self.m1 - self.m0
        L2 = float(d @ d)
        if L2 < 1e-24:
            return np.zeros(len(P))
        return np.clip((P - self.m0) @ d / L2, 0.0, 1.0)

    def coordinate(self, P: np.ndarray) -> np.ndarray:
        """Signed wall coordinate w [m] of points (K, 3): < 0 on the first hand's side."""
        P = np.atleast_2d(np.asarray(P, float))
        s = self.progress(P)[:, None]
        m = self.m0 + s * (self.m1 - self.m0)
        n = (1 - s) * self.n0 + s * self.n1
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        return np.einsum("ij,ij->i", P - m, n)


@dataclass
class Tree:
    """One RRT* tree: vertices ``X`` (n, 3) [m], ``parent`` (n,) (−1 for the root), ``cost`` (n,)
    path length from the root [m]; ``samples`` (drawn points), ``rewired`` (number of parent
    changes), ``goal_index`` (vertex at the goal, or −1), ``best_cost`` per iteration (inf until the
    goal is reached)."""

    X: np.ndarray
    parent: np.ndarray
    cost: np.ndarray
    n: int = 1
    samples: list[np.ndarray] = field(default_factory=list)
    rewired: int = 0
    rewired_edges: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)
    goal_index: int = -1
    best_cost: list[float] = field(default_factory=list)

    def path_to(self, i: int) -> np.ndarray:
        idx = []
        while i >= 0:
            idx.append(i)
            i = int(self.parent[i])
        return self.X[idx[::-1]].copy()

    def check_consistency(self, tol: float = 1e-9) -> None:
        """Raise AssertionError unless every vertex reaches the root without a cycle and
        ``cost[i] = cost[parent[i]] + |X[i] − X[parent[i]]|``."""
        n = self.n
        assert self.parent[0] == -1 and self.cost[0] == 0.0, "root must have no parent and zero cost"
        for i in range(1, n):
            p = int(self.parent[i])
            assert 0 <= p < n, f"vertex {i}: parent {p} out of range"
            c = self.cost[p] + np.linalg.norm(self.X[i] - self.X[p])
            assert abs(c - self.cost[i]) <= tol * max(1.0, c), f"vertex {i}: cost {self.cost[i]} != {c}"
            seen, j = 0, i
            while j > 0:
                j = int(self.parent[j])
                seen += 1
                assert seen <= n, f"vertex {i}: cycle in the parent links"


@dataclass
class CoordinatedPlan:
    """Result of :meth:`CoordinatedRRTStar.plan`: ``status``; ``paths`` arm → (M, 3) waypoints [m]
    (start first, goal last; empty on failure); ``trees`` arm → :class:`Tree`; ``wall`` (None when
    not separated); ``stats`` (``time_s``, ``iterations``, ``nodes``, ``rewired``, ``cost_m`` per
    arm, ``seed``); ``message``."""

    status: PlanStatus
    paths: dict[str, np.ndarray]
    trees: dict[str, Tree]
    wall: VirtualWall | None
    stats: dict[str, Any]
    message: str = ""

    @property
    def success(self) -> bool:
        return self.status.success


class CoordinatedRRTStar:
    """Coordinated RRT* of two hand positions among the obstacles of ``scene`` (module docstring)."""

    def __init__(self, scene: Scene | None = None, options: CoordinatedRRTStarOptions | None = None) -> None:
        if scene is not None and not isinstance(scene, Scene):
            raise TypeError(f"scene: expected an optplan Scene or None, got {type(scene).__name__}")
        self.scene = scene
        self.options = options or CoordinatedRRTStarOptions()
        self.obstacles = tuple(scene.obstacles) if scene is not None else ()

    # ------------------------------------------------------------------ validity
    def clearance(self, P: np.ndarray) -> np.ndarray:
        """Smallest distance [m] from points (K, 3) to any obstacle (inf without obstacles)."""
        P = np.atleast_2d(P)
        out = np.full(len(P), np.inf)
        for o in self.obstacles:
            out = np.minimum(out, point_obstacle_distance(P, o))
        return out

    def _valid_points(self, P: np.ndarray, side: float, wall: VirtualWall | None) -> bool:
        o = self.options
        if self.obstacles and np.any(self.clearance(P) < o.hand_radius):
            return False
        if wall is not None and np.any(side * wall.coordinate(P) < o.wall_margin):
            return False
        return True

    def _edge_points(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        L = float(np.linalg.norm(b - a))
        k = max(1, int(math.ceil(L / self.options.edge_resolution)))
        s = np.linspace(0.0, 1.0, k + 1)[:, None]
        return a + s * (b - a)

    def valid_edge(self, a: np.ndarray, b: np.ndarray, side: float, wall: VirtualWall | None) -> bool:
        """Every point of the edge a→b (at ``edge_resolution``) is clear of the obstacles and on the
        hand's side of the wall (``side`` −1 for the first hand, +1 for the second)."""
        return self._valid_points(self._edge_points(np.asarray(a, float), np.asarray(b, float)), side, wall)

    # ------------------------------------------------------------------ planning
    def plan(self, task: dict[str, Any], seed: int | None = None) -> CoordinatedPlan:
        """Plan both hands: ``task = {arm: (start (3,), goal (3,)), ...}`` with exactly two arms, the
        first on the negative side of the wall. ``seed`` overrides ``options.seed``."""
        t0 = time.perf_counter()
        o = self.options
        if not isinstance(task, dict) or len(task) != 2:
            raise ValueError(f"task: expected {{arm: (start, goal)}} for exactly two arms, got {task!r}")
        arms = list(task)
        ends = {}
        for a in arms:
            try:
                s, g = (np.asarray(v, float).reshape(3) for v in task[a])
            except (TypeError, ValueError) as exc:
                raise ValueError(f"task[{a!r}]: expected (start, goal) positions of 3 numbers [m]") from exc
            if not (np.all(np.isfinite(s)) and np.all(np.isfinite(g))):
                raise ValueError(f"task[{a!r}]: non-finite position")
            ends[a] = (s, g)
        seed = o.seed if seed is None else seed
        rng = np.random.default_rng(seed)
        wall = VirtualWall.from_task(ends[arms[0]], ends[arms[1]]) if o.separate else None
        pts = np.array([p for a in arms for p in ends[a]])
        lo, hi = pts.min(axis=0) - o.padding, pts.max(axis=0) + o.padding
        vol = float(np.prod(hi - lo))
        gamma = o.gamma if o.gamma is not None else 1.1 * 2.0 * (4.0 / 3.0) ** (1 / 3) * (vol / (4 / 3 * math.pi)) ** (1 / 3)
        sides = {arms[0]: -1.0, arms[1]: 1.0}
        trees, status, msg = {}, PlanStatus.EXACT, ""
        for a in arms:
            s, g = ends[a]
            side = sides[a]
            for what, p, st in (("start", s, PlanStatus.INVALID_START), ("goal", g, PlanStatus.INVALID_GOAL)):
                if not self._valid_points(p[None], side, wall):
                    clr = float(self.clearance(p[None])[0])
                    w = float(side * wall.coordinate(p[None])[0]) if wall is not None else float("nan")
                    return CoordinatedPlan(st, {}, {}, wall, {"time_s": time.perf_counter() - t0, "seed": seed},
                                           f"arm {a!r}: {what} {p.tolist()} m is invalid (obstacle clearance "
                                           f"{clr:.4g} m, needs {o.hand_radius}; wall distance {w:.4g} m, needs "
                                           f"{o.wall_margin})")
        deadline = t0 + o.time_limit
        iters = 0
        for a in arms:
            s, g = ends[a]
            tree = self._grow(s, g, sides[a], wall, lo, hi, gamma, rng, deadline)
            trees[a] = tree
            iters += len(tree.best_cost)
        paths: dict[str, np.ndarray] = {}
        for a in arms:
            t = trees[a]
            if t.goal_index < 0:
                timed_out = time.perf_counter() >= deadline
                status = PlanStatus.TIMEOUT if timed_out else PlanStatus.FAILED
                msg = (f"arm {a!r}: the tree did not reach the goal in {len(t.best_cost)} iterations "
                       f"({t.n} vertices){' (time limit)' if timed_out else ''}")
                paths = {}
                break
            paths[a] = t.path_to(t.goal_index)
        stats = {"time_s": time.perf_counter() - t0, "iterations": iters,
                 "nodes": int(sum(t.n for t in trees.values())),
                 "rewired": int(sum(t.rewired for t in trees.values())),
                 "cost_m": {a: float(trees[a].cost[trees[a].goal_index]) if trees[a].goal_index >= 0 else float("inf")
                            for a in arms},
                 "gamma_m": gamma, "seed": seed}
        return CoordinatedPlan(status, paths, trees, wall, stats, msg)

    def _grow(self, start: np.ndarray, goal: np.ndarray, side: float, wall: VirtualWall | None, lo: np.ndarray,
              hi: np.ndarray, gamma: float, rng: np.random.Generator, deadline: float) -> Tree:
        o = self.options
        cap = o.max_iterations + 2
        X = np.empty((cap, 3))
        parent = np.full(cap, -1, dtype=int)
        cost = np.zeros(cap)
        children: list[list[int]] = [[] for _ in range(cap)]
        X[0] = start
        tree = Tree(X, parent, cost)
        n = 1
        goal_idx = -1
        best = np.inf
        for _iteration in range(o.max_iterations):
            if time.perf_counter() >= deadline:
                break
            if goal_idx >= 0 and o.stop_at_first:
                break
            # sample (on the hand's side of the wall)
            if rng.random() < o.goal_bias:
                xr = goal.copy()
            else:
                for _ in range(100):
                    xr = lo + rng.random(3) * (hi - lo)
                    if wall is None or side * wall.coordinate_point(xr) >= o.wall_margin:
                        break
            tree.samples.append(xr)
            d = np.linalg.norm(X[:n] - xr, axis=1)
            i_near = int(np.argmin(d))
            if d[i_near] < 1e-12:
                tree.best_cost.append(best)
                continue
            xn = X[i_near] + (xr - X[i_near]) * min(1.0, o.step / d[i_near])
            if goal_idx < 0 and np.linalg.norm(xn - goal) < 1e-9:
                xn = goal.copy()
            if not self.valid_edge(X[i_near], xn, side, wall):
                tree.best_cost.append(best)
                continue
            r = min(o.rewire_radius, gamma * (math.log(n + 1) / (n + 1)) ** (1 / 3))
            dn = np.linalg.norm(X[:n] - xn, axis=1)
            near = np.flatnonzero(dn <= max(r, 1e-12))
            if i_near not in near:
                near = np.append(near, i_near)
            # choose parent
            order = near[np.argsort(cost[near] + dn[near])]
            p_best = -1
            for j in order:
                if j == i_near or self.valid_edge(X[j], xn, side, wall):
                    p_best = int(j)
                    break
            k = n
            X[k], parent[k], cost[k] = xn, p_best, cost[p_best] + dn[p_best]
            children[p_best].append(k)
            n += 1
            tree.n = n
            # rewire
            for j in near:
                j = int(j)
                if j == p_best:
                    continue
                c_new = cost[k] + dn[j]
                if c_new + 1e-12 < cost[j] and self.valid_edge(xn, X[j], side, wall):
                    old = int(parent[j])
                    tree.rewired_edges.append((X[old].copy(), X[j].copy(), xn.copy()))
                    children[old].remove(j)
                    parent[j] = k
                    children[k].append(j)
                    delta = c_new - cost[j]
                    stack = [j]
                    while stack:  # propagate the cost change to the subtree
                        v = stack.pop()
                        cost[v] += delta
                        stack.extend(children[v])
                    tree.rewired += 1
            # goal
            if np.linalg.norm(xn - goal) < 1e-9 and goal_idx < 0:
                goal_idx = k
            elif goal_idx < 0 and np.linalg.norm(xn - goal) <= o.step and self.valid_edge(xn, goal, side, wall):
                X[n], parent[n], cost[n] = goal, k, cost[k] + np.linalg.norm(goal - xn)
                children[k].append(n)
                goal_idx = n
                n += 1
                tree.n = n
            if goal_idx >= 0:
                best = float(cost[goal_idx])
            tree.best_cost.append(best)
            if n >= cap - 1:
                break
        tree.n = n
        tree.X, tree.parent, tree.cost = X[:n], parent[:n], cost[:n]
        tree.goal_index = goal_idx
        return tree
