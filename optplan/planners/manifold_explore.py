"""On-manifold configurations over the object's whole reachable workspace: a task-space exploration tree.

:func:`~optplan.planners.manifold_samples.generate_manifold_samples` draws joints (uniform, or a valid
configuration perturbed) and projects them onto the closed chain. Such draws spread over the arms' joint
space but not over the *object's* workspace: where the object must pass between obstacles, few projected
draws land, and nothing pulls them there. :func:`task_space_exploration` draws the set the other way round,
as TCBiRRT's task-space extension does, with no goal: an RRT in the object pose ξ = (position, roll, pitch,
yaw), roots the scene's nominal configurations, each iteration

1. draws ξ_rand uniform in the planner's ξ box (TCBiRRT's ``RandomSampleT``, scaled to the arms' reach as
   the planner scales it), redrawn up to ``task_filter_tries`` times while the object alone collides or a
   grasp point is beyond its arm's reach (:class:`~optplan.planners.task_sampling.ObjectPoseFilter`);
2. takes the tree's node nearest in ξ (Euclidean) and steps at most ``task_step`` toward ξ_rand;
3. solves both hands onto ``task_waypoints`` object poses interpolated to the new pose (position linear,
   rotation along the geodesic), each IK seeded with the previous solution, each solution polished onto
   ``h(q) = 0`` and checked (limits, collisions with the object held); the valid prefix is kept and its last
   configuration becomes a node and a member of the set.

The RRT's Voronoi bias spreads the nodes over the reachable object poses (not toward any query), and IK
continuation keeps the arms on the branches joined to the roots — the configurations a task-space planner
passes through. Seeded by one ``numpy.random.Generator``.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..constraints.closed_chain import ClosedChainKinematics, IKSettings, closure_error
from ..errors import ConfigurationError
from ..model.robot import RobotModel
from ..scene import Scene
from .chain_projection import project_onto_chain
from .validity import ValidityChecker

__all__ = ["task_space_exploration"]


def task_space_exploration(robot: RobotModel, scene: Scene, kin: ClosedChainKinematics, ck: ValidityChecker,
                           s: Any, n: int, rng: np.random.Generator,   # s: ManifoldSampleSettings
                           roots: list[np.ndarray], bar: Any = None) -> dict[str, Any]:
    """``n`` valid configurations, the nodes of a task-space exploration tree grown from ``roots``
    (module docstring); ``draws`` counts extensions, ``fails`` those trapped at their first waypoint by
    IK, ``coll`` those trapped there by a collision or the limits."""
    import pinocchio as pin

    from .task_sampling import ObjectPoseFilter
    from .task_space import interpolate_task, pose_from_xi, xi_from_pose
    from .tcbirrt_options import TCBiRRTOptions, reach_scaled_workspace

    if not roots:
        raise ConfigurationError(f"scene {scene.name!r}: task_fraction > 0 needs a valid root configuration "
                                 f"(the scene's [extra] q_start / q_goal)")
    assert scene.object is not None   # checked by the caller
    grasps = scene.object.grasps
    lo_xi, hi_xi, _ = reach_scaled_workspace(robot, TCBiRRTOptions())
    filt = ObjectPoseFilter(robot, scene)
    data = robot.model.createData()
    lo, hi = robot.lower, robot.upper
    ik = IKSettings()
    X = np.empty((n + len(roots), 6))
    Qn: list[np.ndarray] = []
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    for q0 in roots:
        M = kin.object_pose(q0)
        X[len(Qn)] = xi_from_pose(M)
        Qn.append(q0)
        poses.append((np.asarray(M.rotation), np.asarray(M.translation)))
    out: list[np.ndarray] = []
    draws = fails = coll = 0
    limit = n * s.max_draws_factor
    while len(out) < n:
        if draws >= limit:
            raise ConfigurationError(f"scene {scene.name!r}: only {len(out)} of {n} task-space exploration "
                                     f"configurations in {draws} extensions (max_draws_factor={s.max_draws_factor})")
        draws += 1
        xi = lo_xi + (hi_xi - lo_xi) * rng.random(6)
        for _ in range(s.task_filter_tries - 1):
            if filt.xi_ok(xi):
                break
            xi = lo_xi + (hi_xi - lo_xi) * rng.random(6)
        m = len(Qn)
        d2 = np.sum((X[:m] - xi) ** 2, axis=1)
        i = int(np.argmin(d2))
        dist = float(np.sqrt(d2[i]))
        if dist > s.task_step:
            xi = X[i] + (s.task_step / dist) * (xi - X[i])
        Rs, ps = pose_from_xi(xi)
        R0, p0 = poses[i]
        q: np.ndarray | None = Qn[i]
        last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        for k, (R, p) in enumerate(interpolate_task(R0, p0, Rs, ps, s.task_waypoints)):
            assert q is not None
            x, _ = kin.ik(q, R, p, ik)
            if x is not None:
                x = project_onto_chain(kin, x, lo, hi, s.tolerance, s.max_projection_iterations)
            if x is None or max(closure_error(robot, grasps, x, data)) > 10 * s.tolerance:
                fails += k == 0
                break
            if not ck.is_valid(x):
                coll += k == 0
                break
            q = x
            last = (x, np.asarray(R), np.asarray(p))
        if last is None:
            continue
        x, R, p = last
        X[len(Qn)] = xi_from_pose(pin.SE3(R, p))
        Qn.append(x)
        poses.append((R, p))
        out.append(x)
        if bar is not None:
            bar.update(1)
    return {"Q": out, "draws": draws, "fails": fails, "coll": coll}
