"""Boolean collision checks against coal's exact distances where a capsule's segment touches a box.

A study script (not part of the package). Pinocchio's default collision requests do not ask coal for
contacts; coal's GJK then reports a capsule whose segment touches a box's face (to within 1e-6 m,
from outside) as free although it is sunk by its radius. :class:`optplan.planners.validity.ValidityChecker`
asks for contacts (``exact_contacts=True``). This script measures, paired in one process, the
checker with Pinocchio's default requests (``exact_contacts=False``, "before") and with contacts
("after"):

* ``agree``: on the dual Panda's start and goal grasps of trials 0-9 (scenes panda_bar and
  panda_shelf; the object standing still at the grasp, the regrasp's ``"fixed"`` mode), every
  hand-object pair: its boolean verdict (``grasp_contacts``; one configuration; one batch call of
  ``first_invalid``) against the sign of coal's exact distance. Needs example-robot-data.
* ``cost``: µs per check on the benchmark robot in ``hard_bay``: 3000 random configurations in the
  joint limits (seed 0), ``is_valid`` one by one and ``first_invalid`` on the collision-free ones
  (one batch call, every row checked), best of ``--repeat`` paired rounds.

    python docs/studies/collision_contacts.py agree
    python docs/studies/collision_contacts.py cost --repeat 5
"""
from __future__ import annotations

import argparse
import time
import warnings

import coal
import numpy as np
import pinocchio as pin

from optplan.planners.validity import ValidityChecker
from optplan.scene import Scene


def exact_distance(ck: ValidityChecker, k: int, gd) -> float:
    """coal's exact distance [m] of pair ``k`` at the placements in ``gd`` (independent of the request settings)."""
    cp = ck.gmodel.collisionPairs[k]
    g1, g2 = ck.gmodel.geometryObjects[cp.first].geometry, ck.gmodel.geometryObjects[cp.second].geometry
    T1, T2 = gd.oMg[cp.first], gd.oMg[cp.second]
    return float(coal.distance(g1, coal.Transform3s(T1.rotation, T1.translation), g2,
                               coal.Transform3s(T2.rotation, T2.translation), coal.DistanceRequest(), coal.DistanceResult()))


def hand_pairs(ck: ValidityChecker) -> list[int]:
    """The ``"fixed"``-mode pairs of a robot geometry on one of the object's ``exclude_links`` (the hands)."""
    assert ck.object is not None
    excl = set(ck.object.exclude_links)
    objs, out = ck.gmodel.geometryObjects, []
    for k, cp in enumerate(ck.gmodel.collisionPairs):
        if ck._pair_group[k] == "fixed":
            g = cp.first if cp.second == ck.fixed_id else cp.second
            if ck.model.frames[objs[g].parentFrame].name in excl:
                out.append(k)
    return out


def agree() -> None:
    from optplan.bench.generalize import _robot
    from optplan.constraints.closed_chain import ClosedChainKinematics
    from optplan.trials import TrialGenerator

    robot = _robot("dual_panda")
    for name in ("panda_bar", "panda_shelf"):
        scene = Scene.load(name)
        assert scene.object is not None
        cks = {"before": ValidityChecker(robot, scene, exact_contacts=False), "after": ValidityChecker(robot, scene)}
        kin, gen = ClosedChainKinematics(robot, scene.object.grasps), TrialGenerator(robot, scene)
        ref = cks["after"]
        pairs = hand_pairs(ref)
        n_pen = n_pairs = 0
        miss = {k: {"grasp_contacts": 0, "is_valid_object_fixed": 0, "first_invalid": 0} for k in cks}
        false_hit = {k: 0 for k in cks}
        for i in range(10):
            tr = gen.generate(i, 0)
            for q in (tr.q_start, tr.q_goal):
                M = kin.object_pose(q)
                gd = pin.GeometryData(ref.gmodel)
                pin.updateGeometryPlacements(ref.model, ref.data, ref.gmodel, gd, q)
                gd.oMg[ref.fixed_id] = M
                d = {k: exact_distance(ref, k, gd) for k in pairs}
                pen = {k for k, v in d.items() if v <= 0.0}
                n_pen += len(pen)
                n_pairs += len(pairs)
                for tag, ck in cks.items():
                    found = set(ck.grasp_contacts(q, M))
                    miss[tag]["grasp_contacts"] += len(pen - found)
                    false_hit[tag] += len(found - pen)
                    for k in pen:   # the pair alone: every other pair switched off
                        with ck.exempt(tuple(j for j in range(len(ck.gmodel.collisionPairs)) if j != k)):
                            miss[tag]["is_valid_object_fixed"] += ck.is_valid_object_fixed(q, M)
                            miss[tag]["first_invalid"] += ck.first_invalid(np.array([q, q]), "fixed", M) < 0
        print(f"{name}: {n_pen} penetrating hand-object pairs of {n_pairs} (trials 0-9, start and goal grasps)")
        for tag in cks:
            print(f"  {tag:6s} missed: " + ", ".join(f"{k} {v}" for k, v in miss[tag].items())
                  + f"; free pairs reported in contact: {false_hit[tag]}")


def cost(repeat: int) -> None:
    from optplan.model.robot import RobotModel

    robot, scene = RobotModel.from_name("tcbirrt_dual_arm"), Scene.load("hard_bay")
    cks = {"before": ValidityChecker(robot, scene, exact_contacts=False), "after": ValidityChecker(robot, scene)}
    Q = np.random.default_rng(0).uniform(robot.lower, robot.upper, (3000, robot.model.nq))
    verdict = {tag: np.array([ck.is_valid(q) for q in Q]) for tag, ck in cks.items()}
    print(f"benchmark robot, hard_bay, 3000 random configurations: valid {verdict['before'].sum()} (before), "
          f"{verdict['after'].sum()} (after), verdicts differ on {(verdict['before'] != verdict['after']).sum()}")
    free = Q[verdict["before"] & verdict["after"]]
    best: dict[tuple[str, str, str], float] = {}
    for _ in range(repeat):
        for tag, ck in cks.items():   # paired: both checkers in every round
            t0 = time.perf_counter()
            for q in Q:
                ck.is_valid(q)
            t1 = time.perf_counter()
            assert ck.first_invalid(free, "held") < 0
            t2 = time.perf_counter()
            coll = Q[~verdict[tag]]
            t3 = time.perf_counter()
            for q in coll:
                ck.is_valid(q)
            t4 = time.perf_counter()
            for key, v in ((("is_valid", "all 3000"), (t1 - t0) / len(Q)), (("first_invalid", "valid rows"), (t2 - t1) / len(free)),
                           (("is_valid", "colliding"), (t4 - t3) / max(1, len(coll)))):
                best[(tag, *key)] = min(best.get((tag, *key), np.inf), v)
    for what in (("is_valid", "all 3000"), ("first_invalid", "valid rows"), ("is_valid", "colliding")):
        b, a = best[("before", *what)], best[("after", *what)]
        print(f"  {what[0]:13s} ({what[1]:10s}): before {1e6 * b:7.2f} µs, after {1e6 * a:7.2f} µs per configuration "
              f"({100 * (a / b - 1):+.1f} %)")


def main() -> None:
    warnings.simplefilter("ignore", DeprecationWarning)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=["agree", "cost"])
    ap.add_argument("--repeat", type=int, default=5, help="paired rounds of the cost measurement (best of)")
    a = ap.parse_args()
    agree() if a.what == "agree" else cost(a.repeat)


if __name__ == "__main__":
    main()
