"""The DSHDASR paper (``dshdasr``): evaluation of a joint trajectory and one whole case.

* :func:`evaluate` — tip errors by Pinocchio FK of the joints, coal distances on the link capsules
  (:func:`make_checker`, :func:`coal_centreline_distances`) and, for the arc planner, the
  arc-model distances.
* :func:`run_case` — one transposition by :class:`~.dshdasr_nlp.ArcPlanner`, judged 'S' or 'F'.

Public entry point: :mod:`optplan.papers.dshdasr`.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...collision.checker import CollisionChecker
from ...geometry.spatial import log3
from ...model.robot import RobotModel
from ...scene import GraspedObject, Scene
from .nlp import ArcPlanner
from .task import DshdasrArcs, TrackResult, TransposeTask


# --------------------------------------------------------------------------- evaluation
def _direction_error(k, kd) -> float:
    return math.atan2(np.linalg.norm(np.cross(k, kd)), float(k @ kd))


def evaluate(res: TrackResult, task: TransposeTask, arcs: DshdasrArcs, planner: ArcPlanner | None = None,
             checker: CollisionChecker | None = None) -> dict:
    """Errors of the joint trajectory by Pinocchio FK (what a controller would execute) and the
    arm-obstacle distances: by coal on the link capsules (centre-line distance = coal clearance +
    R_k + R_obs, comparable to d_sd^k) and, when ``planner`` and arc parameters are given, by the arc
    model. Stores and returns ``res.metrics``."""
    des = res.des
    n = len(res.t)
    ep_a, eo_a, ep_b, eo_b = (np.zeros(n) for _ in range(4))
    for k in range(n):
        Ma, Mb = arcs.tips(res.q[k])
        ep_a[k] = np.linalg.norm(Ma.translation - des["pa"][k])
        eo_a[k] = np.linalg.norm(log3(Ma.rotation.T @ des["Ra"][k]))
        ep_b[k] = np.linalg.norm(Mb.translation - des["pb"][k])
        eo_b[k] = _direction_error(Mb.rotation[:, 0], des["kb"][k])
    checker = checker or make_checker(arcs.robot, task)
    clear = coal_centreline_distances(checker, res.q, task)
    thr = task.thresholds
    m: dict[str, Any] = {
        "max_tip_position_error_a_m": float(ep_a.max()),
        "max_tip_attitude_error_a_rad": float(eo_a.max()),
        "max_tip_position_error_b_m": float(ep_b.max()),
        "max_tip_direction_error_b_rad": float(eo_b.max()),
        "min_clearance_m": {arm: {f"obs{i + 1}": float(clear[arm][:, i].min()) for i in range(len(task.obstacles))}
                            for arm in ("a", "b")},
        "thresholds_m": {arm: {f"obs{i + 1}": thr[arm] for i in range(len(task.obstacles))} for arm in ("a", "b")},
        "runtime_s": float(res.runtime),
        "n_waypoints": int(n),
    }
    series = {"t": res.t, "ep_a": ep_a, "eo_a": eo_a, "ep_b": ep_b, "eo_b": eo_b, "coal": clear}
    if planner is not None and res.X is not None:
        dg = [planner.arc_distances(res.X[k], des, k, task, constraints=True) for k in range(n)]
        d = np.array([x[0] for x in dg])  # n × obs × 8
        g = np.array([x[1] for x in dg])
        arc = {"a": d[:, :, :3].min(axis=2), "b": d[:, :, 3:].min(axis=2)}
        con = {"a": g[:, :, :3].min(axis=2), "b": g[:, :, 3:].min(axis=2)}
        series["arc"], series["arc_constraint"] = arc, con
        m["min_arc_distance_m"] = {arm: {f"obs{i + 1}": float(arc[arm][:, i].min())
                                         for i in range(len(task.obstacles))} for arm in ("a", "b")}
        m["min_arc_constraint_m"] = {arm: {f"obs{i + 1}": float(con[arm][:, i].min())
                                           for i in range(len(task.obstacles))} for arm in ("a", "b")}
        m["threshold_time_s"] = {}
        for arm in ("a", "b"):
            for i in range(len(task.obstacles)):
                hit = np.nonzero(con[arm][:, i] <= 1e-6)[0]
                m["threshold_time_s"][f"{arm}_obs{i + 1}"] = float(res.t[hit[0]]) if len(hit) else None
    if res.iterations is not None and res.success is not None:
        m["nlp_time_s"] = float(res.nlp_time)
        m["nlp_iterations_mean"] = float(res.iterations.mean())
        m["nlp_failures"] = int((~res.success).sum())
    res.metrics = m
    res.series = series
    return m


def make_checker(robot: RobotModel, task: TransposeTask) -> CollisionChecker:
    scene = Scene.from_dict({"name": "dshdasr_obstacles", "obstacles": [
        {"name": f"obs{i + 1}", "shape": "sphere", "radius": task.obstacle_radius, "xyz": list(map(float, c))}
        for i, c in enumerate(task.obstacles)]})
    return CollisionChecker(robot, scene, held_object=False, self_collision=False)


def view_scene(robot: RobotModel, task: TransposeTask, target_size: float = 0.4) -> Scene:
    """The scene of the 3D view: the obstacles and the target, drawn as a cube of ``target_size``
    [m] around its centre of mass, held by Arm-a at ``T_et_a`` (so the view's object pose is the
    target pose the task prescribes wherever Arm-a's tip is on its desired pose)."""
    import pinocchio as pin

    obs = make_checker(robot, task).scene
    assert obs is not None   # make_checker builds the obstacles' scene
    arm = list(robot.arms)[0]   # Arm-a
    grasp = pin.SE3(np.linalg.inv(np.asarray(task.T_et_a, float)))   # the hand in the target's frame
    obj = GraspedObject((target_size,) * 3, {arm: grasp})
    return Scene("dshdasr_view", None, obs.obstacles, obj, None, None, {"object_label": "target"})


def coal_centreline_distances(checker: CollisionChecker, Q, task: TransposeTask) -> dict[str, np.ndarray]:
    """Per arm, n × n_obs smallest coal distance between the arm's link capsules and each obstacle,
    plus R_k + R_obs (the distance from the obstacle centre to the links' centre lines)."""
    pairs = checker.pairs
    rad = {"a": task.radius_a, "b": task.radius_b}
    out = {arm: np.full((len(Q), len(task.obstacles)), np.inf) for arm in ("a", "b")}
    sel = {(arm, i): [j for j, p in enumerate(pairs) if p.name_a.startswith(f"{arm}_") and p.b == i]
           for arm in ("a", "b") for i in range(len(task.obstacles))}
    for k, q in enumerate(Q):
        d = checker.distances(q)
        for (arm, i), js in sel.items():
            out[arm][k, i] = d[js].min() + rad[arm] + task.obstacle_radius
    return out


def run_case(planner: ArcPlanner, task: TransposeTask, q0, tol_position: float = 1e-6,
             tol_attitude: float = 1e-6) -> tuple[str, TrackResult, dict]:
    """One transposition: 'S' when every NLP converged, the recovered joints put both tips on their
    desired poses within the tolerances at every waypoint, and no coal centre-line distance goes
    below its threshold by more than the arc model's deviation from the links allows."""
    res = planner.track(task, q0)
    m = evaluate(res, task, planner.arcs, planner)
    ok = (m["nlp_failures"] == 0
          and max(m["max_tip_position_error_a_m"], m["max_tip_position_error_b_m"]) <= tol_position
          and max(m["max_tip_attitude_error_a_rad"], m["max_tip_direction_error_b_rad"]) <= tol_attitude
          and all(m["min_arc_constraint_m"][arm][o] >= -1e-6
                  for arm in ("a", "b") for o in m["thresholds_m"][arm]))
    return ("S" if ok else "F"), res, m
