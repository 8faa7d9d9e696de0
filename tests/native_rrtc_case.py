"""Shared by the native RRT-Connect tests: skip when this machine has no native kernel or no RRT-Connect library."""
from __future__ import annotations

import pytest

from optplan.planners.validity import ValidityChecker


def native_or_skip(ck: ValidityChecker) -> None:
    """Skip the calling test unless ``ck`` checks with the native kernel and the native RRT-Connect loads."""
    from optplan.planners.kernel import KernelUnavailable
    from optplan.planners.kernel.rrtc import load_rrtc_library

    if ck.kernel != "native":
        pytest.skip("no native kernel here")
    try:
        load_rrtc_library()
    except KernelUnavailable as e:
        pytest.skip(str(e))


def one_arm_case(robot, scene_name: str, seed: int):
    """A regrasp's kind of query on trial 0 of ``scene_name``: arm A's joints move, the rest and the object
    stand still at the trial's start. Returns (scene, trial, native checker, arm A's joint indices, object pose,
    base configuration, a Generator of ``seed``); skips without the native kernel."""
    import numpy as np

    from optplan.constraints.closed_chain import ClosedChainKinematics
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    sc = Scene.load(scene_name)
    tr = TrialGenerator(robot, sc).generate(0, 0)
    ck = ValidityChecker(robot, sc)
    native_or_skip(ck)
    idx = np.asarray(ClosedChainKinematics(robot, sc.object.grasps).idx[0])
    return sc, tr, ck, idx, tr.object_start, tr.q_start.copy(), np.random.default_rng(seed)
