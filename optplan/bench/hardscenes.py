"""The hard-scene suite for the closed-chain planners (``models/scenes/hard_*.toml``) and its
feasibility witnesses.

Every scene of :data:`SUITE` carries the robot and object of the SSPS scenes (``tcbirrt_dual_arm``,
the 2 × 0.8 × 0.8 m module held at its end faces) and a comment saying what makes it hard. Each
has a **witness** (``models/scenes/witnesses/<scene>.json.gz``): one path from the nominal start
to the nominal goal configuration (``[extra] q_start / q_goal``), found once by a planner with a
recorded seed, so that a planner failing on the scene fails on a feasible problem.
:func:`verify_path` checks a witness independently of the planner that made it:

* every configuration inside the joint limits and collision-free (object held, or fixed during a
  regrasp), every configuration flagged constrained closes the chain to ``closure_tolerance``
  (Pinocchio FK);
* every constrained edge is re-traced: object poses interpolated between its end poses every
  ``task_step`` (m / rad), IK continued from the first configuration through them (the same
  closed-chain IK, compiled), the joint step between consecutive solutions stays ≤
  ``max_joint_step``, the straight joint segments between solutions are collision-checked every
  ``resolution`` rad, and the last solution lies within ``max_joint_step`` of the stored
  configuration (the arms are redundant: IK may end elsewhere on the same pose's self-motion
  manifold) with a collision-free segment to it;
* every regrasp edge (one arm moves, object fixed) is collision-checked every ``resolution`` rad.

``python -m optplan.bench.hardscenes witness <scene>`` (re)makes a witness; ``... verify`` checks
them all.
"""
from __future__ import annotations

import gzip
import json
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..constraints.closed_chain import ClosedChainKinematics, IKSettings, closure_error
from ..model.description import models_dir
from ..model.robot import RobotModel
from ..planners.base import PlanResult
from ..planners.rrtconnect import edge_is_valid
from ..planners.task_space import interpolate_task
from ..planners.validity import ValidityChecker
from ..scene import Scene

__all__ = ["SUITE", "witness_path", "load_witness", "verify_path", "make_witness", "nominal_configurations"]
log = logging.getLogger(__name__)

#: the hard-scene suite, in the order of the benchmark table
SUITE = ("hard_window", "hard_bay", "hard_corridor", "hard_clutter_sparse", "hard_clutter_dense", "hard_flip",
         "hard_truss")


def witness_path(scene: str) -> Path:
    return models_dir() / "scenes" / "witnesses" / f"{scene}.json.gz"


def load_witness(scene: str) -> tuple[PlanResult, dict]:
    """``(path as a PlanResult, provenance dict)`` of a scene's witness."""
    with gzip.open(witness_path(scene), "rt") as f:
        d = json.load(f)
    return PlanResult.from_dict(d["result"]), d["provenance"]


def nominal_configurations(robot: RobotModel, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """The scene's ``[extra] q_start / q_goal`` [rad], polished to the closed chain."""
    from ..trials import TrialGenerator

    gen = TrialGenerator(robot, scene)
    qs, qg = gen.q_nominal["q_start"], gen.q_nominal["q_goal"]
    if qs is None or qg is None:
        raise ValueError(f"scene {scene.name!r}: [extra] q_start / q_goal missing or not on the closed chain")
    return qs, qg


def verify_path(robot: RobotModel, scene: Scene, res: PlanResult, *, resolution: float = 0.01,
                task_step: float = 0.01, max_joint_step: float = 0.2, closure_tolerance: float = 1e-6,
                checker: ValidityChecker | None = None, kin: ClosedChainKinematics | None = None) -> dict:
    """Independent check of a closed-chain path with regrasps (see the module docstring).
    Returns ``{"ok": bool, "problems": [...], "configurations": M, "dense_configurations": n,
    "max_closure": ...}``."""
    if scene.object is None:
        raise ValueError(f"scene {scene.name!r}: a closed-chain path needs a held [object]")
    grasps = scene.object.grasps
    ck = checker or ValidityChecker(robot, scene)
    kin = kin or ClosedChainKinematics(robot, grasps)
    ik = IKSettings(tol_position=1e-9, tol_orientation=1e-9, max_iterations=50)
    P, C = np.asarray(res.path), np.asarray(res.constrained, bool)
    problems: list[str] = []
    data = robot.model.createData()
    reg: dict[int, Any] = {}
    for s in res.segments:
        if s.kind == "regrasp":
            for k in range(s.start, s.stop):
                reg[k] = s.object_pose
    max_cl, n_dense, max_gap = 0.0, 0, 0.0
    for k, q in enumerate(P):
        if not ck.in_limits(q):
            problems.append(f"configuration {k} outside the joint limits")
        if C[k]:
            e = max(closure_error(robot, grasps, q, data))
            max_cl = max(max_cl, e)
            if e > closure_tolerance:
                problems.append(f"configuration {k}: closed chain violated by {e:.1e}")
            if not ck.is_valid(q):
                problems.append(f"configuration {k} in collision")
    for k in range(len(P) - 1):
        a, b = P[k], P[k + 1]
        if k in reg:
            M = reg[k]
            def valid_fixed(x: np.ndarray, M: Any = M) -> bool:
                return ck.is_valid_object_fixed(x, M)

            if not edge_is_valid(a, b, valid_fixed, resolution):
                problems.append(f"regrasp edge {k}-{k + 1} in collision")
            n_dense += 1
            continue
        Ma, Mb = kin.object_pose(a), kin.object_pose(b)
        dp = float(np.linalg.norm(Mb.translation - Ma.translation))
        dr = float(np.linalg.norm(pin.log3(Ma.rotation.T @ Mb.rotation)))
        n = max(1, int(math.ceil(max(dp, dr) / task_step)))
        q = a
        for R, p in interpolate_task(Ma.rotation, Ma.translation, Mb.rotation, Mb.translation, n):
            qn, _ = kin.ik(q, R, p, ik)
            if qn is None:
                problems.append(f"edge {k}-{k + 1}: IK along the object's path failed")
                break
            if float(np.abs(qn - q).max()) > max_joint_step:
                problems.append(f"edge {k}-{k + 1}: joint jump {float(np.abs(qn - q).max()):.3f} rad")
                break
            if not edge_is_valid(q, qn, ck.is_valid, resolution):
                problems.append(f"edge {k}-{k + 1} in collision")
                break
            q = qn
            n_dense += 1
        else:
            # the arms are redundant (7 joints, 6 constraints each): the re-traced IK may end elsewhere on the
            # self-motion manifold of the same object pose; the gap to the stored configuration must be short
            # and collision-free
            gap = float(np.abs(q - b).max())
            max_gap = max(max_gap, gap)
            if gap > max_joint_step:
                problems.append(f"edge {k}-{k + 1}: re-traced IK ends {gap:.1e} rad from the stored configuration")
            elif not edge_is_valid(q, b, ck.is_valid, resolution):
                problems.append(f"edge {k}-{k + 1}: the last re-traced configuration and the stored one are joined through a collision")
    return {"ok": not problems, "problems": problems[:20], "configurations": int(len(P)),
            "dense_configurations": n_dense, "max_closure": max_cl, "max_self_motion_gap_rad": max_gap}


def make_witness(scene_name: str, *, planner: str = "tcbirrt:variant=improved:edge_resolution=0.02", time_limit: float = 60.0,
                 seeds=range(10), write: bool = True) -> tuple[PlanResult, dict]:
    """Plan nominal start → nominal goal with ``planner`` for each seed until a path passes
    :func:`verify_path`; write it to :func:`witness_path`."""
    from ..planners import make_planner
    from .engine import parse_planner_spec

    robot = RobotModel.from_name("tcbirrt_dual_arm")
    scene = Scene.load(scene_name)
    qs, qg = nominal_configurations(robot, scene)
    if scene.object is None:
        raise ValueError(f"scene {scene_name!r}: TCBiRRT needs a held [object]")
    ck = ValidityChecker(robot, scene)
    kin = ClosedChainKinematics(robot, scene.object.grasps)
    name, opts = parse_planner_spec(planner)
    pl = make_planner(name, robot, scene, checker=ck, kinematics=kin, **opts)
    for seed in seeds:
        res = pl.plan(qs, qg, time_limit=time_limit, seed=seed, clock="cpu")
        if not res.success:
            log.info("%s seed %d: %s", scene_name, seed, res.status.value)
            continue
        chk = verify_path(robot, scene, res, checker=ck, kin=kin)
        log.info("%s seed %d: %d configurations, %s", scene_name, seed, len(res.path), chk["problems"][:3])
        if chk["ok"]:
            prov = {"planner": planner, "seed": int(seed), "time_limit_s": time_limit, "clock": "cpu",
                    "cpu_time_s": res.stats.get("cpu_time_s"), "check": chk}
            if write:
                p = witness_path(scene_name)
                p.parent.mkdir(parents=True, exist_ok=True)
                d = {"provenance": prov, "result": res.to_dict()}
                from .._io import atomic_path

                with atomic_path(p) as tmp, gzip.open(tmp, "wt") as f:
                    json.dump(d, f)
            return res, prov
    raise RuntimeError(f"{scene_name}: no verified path with {planner} for seeds {list(seeds)}")


def _main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m optplan.bench.hardscenes")
    ap.add_argument("what", choices=["witness", "verify"])
    ap.add_argument("scenes", nargs="*", default=list(SUITE))
    ap.add_argument("--planner", default="tcbirrt:variant=improved:edge_resolution=0.02")
    ap.add_argument("--time-limit", type=float, default=60.0)
    ap.add_argument("--seeds", type=int, default=10)
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO)
    bad = 0
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    for sc in a.scenes:
        if a.what == "witness":
            _, prov = make_witness(sc, planner=a.planner, time_limit=a.time_limit, seeds=range(a.seeds))
            print(sc, "witness:", prov["planner"], "seed", prov["seed"], prov["check"]["configurations"], "configurations")
        else:
            res, prov = load_witness(sc)
            chk = verify_path(robot, Scene.load(sc), res)
            bad += not chk["ok"]
            print(sc, "OK" if chk["ok"] else "FAIL", chk)
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(_main())


def clutter_obstacles(n: int, seed: int, *, region=((0.6, 3.2), (-2.2, 2.2), (0.2, 4.0)),
                      size_range=(0.2, 0.35), clearance: float = 0.15) -> list[dict]:
    """``n`` axis-aligned cubes (edges uniform in ``size_range`` [m], centres uniform in ``region``)
    kept only when they are ``clearance`` [m] away from the object at the SSPS scene-1 start and
    goal poses and do not touch the robot at scene 1's nominal configurations: the generator of
    ``hard_clutter_*.toml`` (their comments give ``n`` and ``seed``)."""
    import coal

    from ..trials import TrialGenerator

    robot = RobotModel.from_name("tcbirrt_dual_arm")
    s1 = Scene.load("ssps_scene1")
    gen = TrialGenerator(robot, s1)
    rng = np.random.default_rng(seed)
    assert s1.object is not None and s1.start is not None and s1.goal is not None  # the shipped scene has them
    obj = s1.object.coal_geometry()
    out: list[dict[str, Any]] = []
    tries = 0
    while len(out) < n and tries < 100 * n:
        tries += 1
        e = float(rng.uniform(*size_range))
        c = np.array([rng.uniform(*r) for r in region])
        box = coal.Box(e, e, e)
        tf = coal.Transform3s(np.eye(3), c)
        far = True
        for M in (s1.start, s1.goal):
            req, res = coal.DistanceRequest(), coal.DistanceResult()
            if coal.distance(obj, coal.Transform3s(M.rotation, M.translation), box, tf, req, res) < clearance:
                far = False
        if not far:
            continue
        d = {"name": f"box_{len(out):02d}", "shape": "box", "size": [round(e, 3)] * 3,
             "xyz": [round(float(x), 3) for x in c]}
        trial = Scene.from_dict({"obstacles": [d], "object": _obj_dict(), "robot": s1.robot})
        ck = ValidityChecker(robot, trial)
        if all(q is not None and ck.is_valid(q) for q in gen.q_nominal.values()):
            out.append(d)
    return out


def _obj_dict() -> dict:
    return {"size": [2.0, 0.8, 0.8], "grasps": {"A": {"xyz": [1.2, 0, 0], "rpy": [0, math.pi / 2, 0]},
                                                 "B": {"xyz": [-1.2, 0, 0], "rpy": [0, -math.pi / 2, 0]}},
            "exclude_links": ["a_link6", "a_link7", "b_link6", "b_link7"]}
