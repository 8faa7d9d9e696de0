"""The plan → shortcut → resample → optimize → verify pipeline (issue 4, item 4)."""
import numpy as np
import pinocchio as pin
import pytest

from optplan.collision import CollisionChecker
from optplan.pipeline import PipelineOptions, PipelineResult, shortcut_constrained
from optplan.scene import Scene
from optplan.tasks import grasp_configuration, straight_line_poses, task_space_path


@pytest.fixture(scope="module")
def transport(tcb):
    sc = Scene.load("transport")
    rng = np.random.default_rng(3)
    chk = CollisionChecker(tcb, sc)
    for _ in range(20):
        g = grasp_configuration(tcb, sc, sc.start, rng, checker=chk)
        mid = pin.SE3(sc.start.rotation, sc.start.translation + np.array([-0.3, 0.0, 0.3]))
        poses = straight_line_poses(sc.start, mid, 6)[:-1] + straight_line_poses(mid, sc.start * pin.SE3(
            np.eye(3), np.array([0.0, 0.0, 0.0])), 6)
        Q, ok = task_space_path(tcb, sc, g.q, poses)
        if ok and all(chk.is_valid(q) for q in Q):
            return sc, Q
    pytest.skip("no valid detour path found")


def _closure(robot, scene, q):
    d = robot.model.createData()
    pin.framesForwardKinematics(robot.model, d, q)
    Ma, Mb = d.oMf[robot.arm("A").ee_frame_id], d.oMf[robot.arm("B").ee_frame_id]
    rel = Ma.actInv(Mb)
    ref = scene.object.grasps["A"].actInv(scene.object.grasps["B"])
    e = ref.actInv(rel)
    return max(np.linalg.norm(e.translation), np.linalg.norm(pin.log3(e.rotation)))


def test_shortcut_keeps_ends_closure_and_validity_and_shortens(tcb, transport):
    sc, Q = transport
    chk = CollisionChecker(tcb, sc)
    out = shortcut_constrained(tcb, sc, Q, np.random.default_rng(0), attempts=30, checker=chk)
    np.testing.assert_allclose(out[0], Q[0])
    np.testing.assert_allclose(out[-1], Q[-1])
    assert all(_closure(tcb, sc, q) < 1e-8 for q in out)
    assert all(chk.is_valid(q) for q in out)
    L = lambda P: np.linalg.norm(np.diff(P, axis=0), axis=1).sum()  # noqa: E731
    assert L(out) <= L(Q) + 1e-12
    assert L(out) < 0.9 * L(Q)  # the detour out and back is shortened


def test_pipeline_result_reports_failed_plan_as_status():
    class _Plan:
        success = False
        n_regrasp = 0

        class status:  # noqa: N801
            value = "timeout"

    res = PipelineResult(plan=_Plan())
    d = res.to_dict()
    assert d["success"] is False and d["plan_status"] == "timeout" and d["opt_status"] == "not_run"


def test_options_validated():
    with pytest.raises(ValueError):
        PipelineOptions(n_intervals=1)


@pytest.mark.slow
def test_pipeline_scene1_trial(tcb):
    from optplan.bench.trials import TrialGenerator
    from optplan.pipeline import run_pipeline

    sc = Scene.load("ssps_scene1")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    res = run_pipeline(tcb, sc, tr.q_start, tr.q_goal, PipelineOptions(), seed=0)
    assert res.plan.success
    assert res.success, res.to_dict()
    assert res.max_closed_chain_residual <= 1e-6 and res.min_clearance_m >= 0.0
    assert res.q.shape[1] == tcb.nq and res.constrained.shape == res.t.shape
