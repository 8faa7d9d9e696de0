"""Warm starts from planner paths: closed-chain projection and manifold resampling."""
import numpy as np
import pinocchio as pin
import pytest

from optplan.constraints.closed_chain import closed_chain_residual, manifold_resample, project_closed_chain
from optplan.geometry.spatial import rpy_to_matrix
from optplan.problem import ClosedChain, JointBoundary, OptProblem, Smoothness


@pytest.fixture
def cc():
    # a rigid 2.4 m bar held at its ends, hands facing outwards (as in the transport scene)
    ga = pin.SE3(rpy_to_matrix(0, np.pi / 2, 0), np.array([1.2, 0, 0]))
    gb = pin.SE3(rpy_to_matrix(0, -np.pi / 2, 0), np.array([-1.2, 0, 0]))
    return ClosedChain.from_grasps(ga, gb)


def _on_manifold(tcb, cc, rng):
    """A configuration on the manifold: random arm A, arm B projected."""
    for _ in range(50):
        q = tcb.random_configuration(rng) * 0.5
        r = project_closed_chain(tcb, q, cc)
        if r.success:
            return r.q
    raise RuntimeError("no manifold configuration found")


def test_residual_jacobian_matches_finite_differences(tcb, cc, rng):
    q = tcb.random_configuration(rng)
    _, J = closed_chain_residual(tcb, q, cc)
    eps = 1e-6
    Jfd = np.array([(closed_chain_residual(tcb, q + eps * e, cc)[0] - closed_chain_residual(tcb, q - eps * e, cc)[0])
                    / (2 * eps) for e in np.eye(tcb.nq)]).T
    assert np.abs(J - Jfd).max() < 1e-6


def test_projection_converges_quadratically_and_lands_on_the_manifold(tcb, cc, rng):
    q0 = _on_manifold(tcb, cc, rng)
    q = q0 + rng.normal(scale=0.05, size=tcb.nq)
    r = project_closed_chain(tcb, q, cc)
    assert r.success and r.iterations <= 10
    # independent check with Pinocchio FK
    d = tcb.model.createData()
    pin.framesForwardKinematics(tcb.model, d, r.q)
    rel = d.oMf[tcb.arm("A").ee_frame_id].actInv(d.oMf[tcb.arm("B").ee_frame_id])
    err = cc.relative.actInv(rel)
    assert np.linalg.norm(err.translation) < 1e-9 and np.linalg.norm(pin.log3(err.rotation)) < 1e-9


def test_manifold_resample_uniform_and_projected(tcb, cc, rng):
    qa = _on_manifold(tcb, cc, rng)
    path = [qa]
    for _ in range(4):  # a planner-like path: small steps along the manifold
        path.append(project_closed_chain(tcb, path[-1] + rng.normal(scale=0.05, size=tcb.nq), cc).q)
    path = np.array(path)
    Q, ok = manifold_resample(tcb, path, 21, cc)
    assert ok and Q.shape == (21, tcb.nq)
    np.testing.assert_allclose(Q[0], path[0])
    np.testing.assert_allclose(Q[-1], path[-1])
    for q in Q:
        h, _ = closed_chain_residual(tcb, q, cc)
        assert np.abs(h).max() < 1e-9
    # roughly uniform in arc length (projection moves samples only slightly)
    steps = np.linalg.norm(np.diff(Q, axis=0), axis=1)
    assert steps.max() < 3 * steps.mean()


def test_set_initial_path_then_solve(tcb, cc, rng):
    qa = _on_manifold(tcb, cc, rng)
    path = [qa]
    for _ in range(3):
        path.append(project_closed_chain(tcb, path[-1] + rng.normal(scale=0.05, size=tcb.nq), cc).q)
    path = np.array(path)
    z = np.zeros(tcb.nj)
    prob = OptProblem(tcb, n_intervals=12, duration=20.0)
    prob.add_constraint(JointBoundary("start", q=path[0], qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=path[-1], qd=z, qdd=z))
    prob.add_constraint(cc)
    prob.add_cost(Smoothness("jerk"))
    assert prob.set_initial_path(path, cc)
    x0 = prob.numeric_trajectory(prob.initial_guess)
    assert np.allclose(x0.q[0], path[0]) and np.allclose(x0.q[-1], path[-1])
    assert np.allclose(x0.qd[0], 0, atol=1e-9) and np.allclose(x0.qd[-1], 0, atol=1e-9)
    sol = prob.solve()
    assert sol.success, sol.status


def test_bad_path_shape(tcb, cc):
    with pytest.raises(ValueError, match="expected"):
        manifold_resample(tcb, np.zeros((3, 5)), 10, cc)


_SEGMENT_WARM_START = """
import sys
from pathlib import Path
import numpy as np
import optplan.pipeline as PL
from optplan.pipeline_options import PipelineOptions
from optplan.problem import ClosedChain
from optplan.model.robot import RobotModel
from optplan.scene import Scene
from optplan.tasks import segment_problem
d = np.load(Path(%r) / "data" / "segment_ssps_scene3_ends.npz")
path, scene = np.asarray(d["path"], float), Scene.load(str(d["scene"]))
robot = RobotModel.from_name("tcbirrt_dual_arm")
grasps = PL._held_object(scene).grasps
a, b = list(grasps)
cc = ClosedChain.from_grasps(grasps[a], grasps[b], a, b)
prob, _ = segment_problem(robot, scene, path[0], path[-1], 40, 20.0, closed_chain=cc, margin=0.02, object_arm=a,
                          fixed_normals=True, transcription="bspline")
assert prob.set_initial_path(path, cc)
print(" ".join(sorted(m for m in sys.modules if m.split(".")[:2] in (["scipy", "interpolate"], ["scipy", "optimize"]))))
"""


def test_a_segments_warm_start_does_not_import_scipy_interpolate(tmp_path):
    """The pipeline's warm start (a clamped cubic spline through the planner's samples) needs neither
    scipy.interpolate nor what it imports (scipy.optimize, ...): 0.1-0.2 s of every plan's start-up."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    env = dict(os.environ, OPTPLAN_CACHE=str(tmp_path), OPTPLAN_BACKGROUND_COMPILE="0")
    out = subprocess.run([sys.executable, "-c", _SEGMENT_WARM_START % str(Path(__file__).parent)], env=env,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "", f"imported: {out.stdout.strip()}"
