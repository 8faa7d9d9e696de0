"""Shortcuts of a planner's path before the optimizer: closed-chain segments (joint-space lines
projected back onto the closed-chain manifold) and regrasp segments (one arm's joint-space lines).
The optimizer starts from a path without the planner's detours, and a segment's grid follows its
length."""
from __future__ import annotations

import numpy as np

from .collision.checker import CollisionChecker
from .model.robot import RobotModel
from .scene import Scene, held_object

__all__ = ["shortcut_constrained", "shortcut_free"]


def shortcut_constrained(robot: RobotModel, scene: Scene, path: np.ndarray, rng: np.random.Generator,
                         attempts: int = 40, checker: CollisionChecker | None = None,
                         step: float = 0.05) -> np.ndarray:
    """Random shortcuts of a closed-chain path: two random configurations are joined by the
    joint-space straight line, each ``step`` [rad] projected back onto the closed-chain manifold
    (Newton, :func:`optplan.constraints.closed_chain.project_closed_chain`); kept when every projection converges,
    every configuration is collision free (coal), consecutive configurations stay within 2·step,
    and the path gets shorter. (Joint space rather than task space: with 14 joints and 12 closure
    equations a pose does not fix the configuration, and IK continuation drifts along the
    self-motion manifold.)"""
    from .constraints.closed_chain import ChainSpec, project_closed_chain

    checker = checker or CollisionChecker(robot, scene)
    cc = ChainSpec.from_grasps(held_object(scene).grasps)   # (no import of the optimization stack)
    data = robot.model.createData()
    path = np.array(path, float)
    seglen = lambda P: float(np.linalg.norm(np.diff(P, axis=0), axis=1).sum())  # noqa: E731
    for _ in range(int(attempts)):
        if len(path) < 3:
            break
        i, j = sorted(rng.choice(len(path), 2, replace=False))
        if j - i < 2:
            continue
        n = max(2, int(np.ceil(np.abs(path[j] - path[i]).max() / step)))
        qs, ok = [path[i]], True
        for k in range(1, n):
            r = project_closed_chain(robot, path[i] + (k / n) * (path[j] - path[i]), cc, data=data)
            if (not r.success or np.abs(r.q - qs[-1]).max() > 2 * step or not checker.is_valid(r.q)):
                ok = False
                break
            qs.append(r.q)
        if not ok or np.abs(path[j] - qs[-1]).max() > 2 * step:
            continue
        qs.append(path[j])
        if seglen(np.array(qs)) < seglen(path[i:j + 1]):
            path = np.vstack([path[:i], np.array(qs), path[j + 1:]])
    return path


def shortcut_free(robot: RobotModel, scene: Scene, path: np.ndarray, rng: np.random.Generator,
                  attempts: int = 40, checker: CollisionChecker | None = None,
                  step: float = 0.02) -> np.ndarray:
    """Random shortcuts of a regrasp path (one arm moves, the other holds the object still): two
    random configurations are joined by the joint-space straight line when it is collision free
    at samples ``step`` [rad] apart (the largest joint change between samples; checked coarse to
    fine, stopping at the first contact) and shorter. ``checker`` must place the held object on
    the holding arm. The optimizer then starts from a path without the planner's detours: fewer
    corners for the minimum-jerk motion to cut into obstacles it had no rows for, and fewer knots
    (a segment's grid follows its length)."""
    checker = checker or CollisionChecker(robot, scene)
    path = np.array(path, float)
    seglen = lambda P: float(np.linalg.norm(np.diff(P, axis=0), axis=1).sum())  # noqa: E731
    tried: set[tuple[int, int]] = set()  # pairs refused on the current path
    for _ in range(int(attempts)):
        if len(path) < 3:
            break
        i, j = (int(v) for v in sorted(rng.choice(len(path), 2, replace=False)))
        if j - i < 2 or (i, j) in tried:
            continue
        tried.add((i, j))
        if float(np.linalg.norm(path[j] - path[i])) >= seglen(path[i:j + 1]) - 1e-12:
            continue
        n = max(2, int(np.ceil(np.abs(path[j] - path[i]).max() / step)))
        if all(checker.is_valid(path[i] + (k / n) * (path[j] - path[i])) for k in _coarse_to_fine(n)):
            path = np.vstack([path[:i + 1], path[j:]])
            tried.clear()
    return path


def _coarse_to_fine(n: int):
    """The interior sample indices 1 … n−1 of a line of n intervals, midpoints first (breadth first)."""
    queue = [(0, n)]
    while queue:
        a, b = queue.pop(0)
        if b - a > 1:
            m = (a + b) // 2
            yield m
            queue += [(a, m), (m, b)]
