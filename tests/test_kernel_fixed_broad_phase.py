"""The native kernel's broad phase for checks that place the still object per call (the ``"fixed"`` mode of
regrasps and of ``verify_path``): the placed object's box is made per call, so the broad phase culls pairs
there too — the verdicts must stay those of the plain pair loop, and never free where coal collides."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from kernel_scenes import native_checker

from optplan.bench.hardscenes import nominal_configurations
from optplan.constraints.closed_chain import ClosedChainKinematics
from optplan.planners.kernel import KernelUnavailable, NativeKernel
from optplan.planners.validity import ValidityChecker
from optplan.scene import Scene


def _kernel_or_skip(*args, **kw) -> NativeKernel:
    try:
        return NativeKernel(*args, **kw)
    except KernelUnavailable as e:   # no C compiler on this machine
        pytest.skip(str(e))


@pytest.mark.parametrize("scene_name,margin,turned", [("ssps_scene1", 0.0, False), ("hard_window", 0.0, False),
                                                      ("hard_clutter_dense", 0.03, True)])
def test_fixed_mode_broad_phase_gives_the_pair_loops_verdicts(tcb, scene_name, margin, turned):
    rng = np.random.default_rng(2911)
    vc = native_checker(tcb, scene_name, margin, turned, rng)
    scene = vc.scene
    ref = ValidityChecker(tcb, scene, kernel="coal", margin=margin)
    pairs = [(cp.first, cp.second) for cp in vc.gmodel.collisionPairs]
    fast = _kernel_or_skip(tcb.model, vc.gmodel, pairs, margin=margin)
    plain = _kernel_or_skip(tcb.model, vc.gmodel, pairs, margin=margin, broad_phase=False)
    g = vc.fixed_id
    assert g is not None and fast._km.ngrp > 1 and plain._km.ngrp == 0
    assert fast._buckets[-1][g] >= 0, "the still object has a static column: the case under test"
    kin = ClosedChainKinematics(tcb, scene.object.grasps)
    qs, qg = nominal_configurations(tcb, scene)
    poses = [kin.object_pose(qs), kin.object_pose(qg)]
    poses += [pin.SE3(pin.exp3(rng.normal(0.0, 0.3, 3)) @ M.rotation, M.translation + rng.normal(0.0, 0.3, 3))
              for M in poses for _ in range(2)]
    act = np.array([bool(x) for x in vc._gd["fixed"].activeCollisionPairs], np.uint8)
    n_diff = n_coll = n_all = 0
    for M in poses:
        Q = np.vstack([np.clip(q0 + rng.normal(0.0, s, (60, tcb.model.nq)), tcb.lower, tcb.upper)
                       for q0 in (qs, qg) for s in (0.05, 0.4)])
        want = plain.valid(Q, act, (g, M))
        got = fast.valid(Q, act, (g, M))
        n_diff += int(np.sum(got != want))
        n_coll += int(np.sum(~want))
        n_all += len(Q)
        # the batch's first collision and the edge call agree with the verdicts
        for i in range(0, 60, 12):
            assert (fast.first_invalid(Q[i:i + 12], act, (g, M)) >= 0) == (not want[i:i + 12].all())
        f = np.linspace(0.0, 1.0, 25)[1:]
        assert fast.edge_first_invalid(Q[0], Q[1], f, act, (g, M)) == plain.edge_first_invalid(Q[0], Q[1], f, act, (g, M))
        exact = np.array([ref.first_invalid(q[None], "fixed", M) < 0 for q in Q[::4]])
        assert not np.any(got[::4] & ~exact), f"{scene_name}: a configuration coal calls colliding called free"
    assert n_diff == 0, f"{scene_name}: {n_diff} of {n_all} verdicts differ from the pair loop"
    assert 0.05 * n_all < n_coll < 0.95 * n_all   # both verdicts occur


def test_fixed_mode_broad_phase_with_exempted_grasp_pairs(tcb):
    """With the grasp contacts switched off (a regrasp's exemption) the verdicts stay the pair loop's."""
    scene = Scene.load("ssps_scene2")
    vc = ValidityChecker(tcb, scene)
    if vc.kernel != "native":
        pytest.skip("no native kernel here")
    pairs = [(cp.first, cp.second) for cp in vc.gmodel.collisionPairs]
    fast = _kernel_or_skip(tcb.model, vc.gmodel, pairs)
    plain = _kernel_or_skip(tcb.model, vc.gmodel, pairs, broad_phase=False)
    kin = ClosedChainKinematics(tcb, scene.object.grasps)
    qs, _ = nominal_configurations(tcb, scene)
    M = kin.object_pose(qs)
    act = np.array([bool(x) for x in vc._gd["fixed"].activeCollisionPairs], np.uint8)
    rng = np.random.default_rng(5)
    Q = np.clip(qs + rng.normal(0.0, 0.02, (200, tcb.model.nq)), tcb.lower, tcb.upper)
    contacts = vc.grasp_contacts(qs, M)
    act[list(contacts)] = 0
    want = plain.valid(Q, act, (vc.fixed_id, M))
    assert np.array_equal(fast.valid(Q, act, (vc.fixed_id, M)), want)
    assert want.any()
