"""``ValidityChecker.grasp_contacts`` keeps its answers per configuration, object pose and exempted pairs: a kept
answer is the one coal gives again, also after the exemptions or the pose change."""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from optplan.bench.hardscenes import nominal_configurations
from optplan.constraints.closed_chain import ClosedChainKinematics
from optplan.planners.validity import ValidityChecker
from optplan.scene import Scene


def _every_pair_reference(vc: ValidityChecker, q: np.ndarray, M: pin.SE3, excl: set[str]) -> tuple[int, ...]:
    """The contacts from coal's collisions of EVERY active "fixed" pair (the checker computes only the candidates)."""
    gd = pin.GeometryData(vc.gmodel)
    ref = vc._gd["fixed"]
    for k in range(len(vc.gmodel.collisionPairs)):
        if not ref.activeCollisionPairs[k]:
            gd.deactivateCollisionPair(k)
        gd.collisionRequests[k].enable_contact = ref.collisionRequests[k].enable_contact
        gd.collisionRequests[k].security_margin = ref.collisionRequests[k].security_margin
    pin.updateGeometryPlacements(vc.model, vc.model.createData(), vc.gmodel, gd, q)
    gd.oMg[vc.fixed_id] = M
    pin.computeCollisions(vc.gmodel, gd, False)
    objs, out = vc.gmodel.geometryObjects, []
    for k, cp in enumerate(vc.gmodel.collisionPairs):
        if vc._pair_group[k] != "fixed" or not gd.activeCollisionPairs[k] or not gd.collisionResults[k].isCollision():
            continue
        g = cp.first if cp.second == vc.fixed_id else cp.second
        if vc.model.frames[objs[g].parentFrame].name in excl:
            out.append(k)
    return tuple(out)


def test_grasp_contacts_kept_answers_are_coals(tcb):
    scene = Scene.load("ssps_scene1")
    vc = ValidityChecker(tcb, scene)
    kin = ClosedChainKinematics(tcb, scene.object.grasps)
    qs, qg = nominal_configurations(tcb, scene)
    rng = np.random.default_rng(8)
    poses = [kin.object_pose(qs), kin.object_pose(qg)]
    qs_list = [qs, qg] + [np.clip(q + rng.normal(0.0, 0.02, q.size), tcb.lower, tcb.upper) for q in (qs, qg)]
    seen = []
    for _ in range(2):   # the second round answers from the kept ones
        for M in poses:
            for q in qs_list:
                got = vc.grasp_contacts(q, M)
                assert got == vc._grasp_contacts(q, M, set(scene.object.exclude_links))
                assert got == _every_pair_reference(vc, q, M, set(scene.object.exclude_links))
                seen.append(got)
                with vc.exempt(got):   # inside the exemption the contacts are not active: none reported
                    inside = vc.grasp_contacts(q, M)
                    assert inside == vc._grasp_contacts(q, M, set(scene.object.exclude_links))
                    assert inside == _every_pair_reference(vc, q, M, set(scene.object.exclude_links))
                    assert not set(inside) & set(got)
    assert any(seen) and len(vc._contacts) > 0
    M2 = pin.SE3(poses[0].rotation, poses[0].translation + np.array([0.0, 0.0, 0.5]))   # another pose, another answer
    assert vc.grasp_contacts(qs, M2) == vc._grasp_contacts(qs, M2, set(scene.object.exclude_links))
