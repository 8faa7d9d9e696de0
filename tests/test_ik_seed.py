"""The path IK's seed predictor (TCBiRRT's ``ik_predictor``, optplan.planners.ik_seed): the option's checks, the
seed's value, the converged waypoints against Pinocchio's forward kinematics, and fewer IK iterations per
waypoint than the previous-solution seed on fixed extensions. (The native extension against the Python one
with the predictor: tests/test_native_extend.py.)"""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.planners.ik_seed import predicted_seed


def test_option_and_seed_are_checked():
    from optplan.planners import TCBiRRTOptions

    assert TCBiRRTOptions().ik_predictor == "none" and TCBiRRTOptions(variant="paper").ik_predictor == "none"
    with pytest.raises(ValueError, match=r"ik_predictor: expected one of \('none', 'secant'\), got 'tangent'"):
        TCBiRRTOptions(ik_predictor="tangent")
    with pytest.raises(ValueError, match="ik_predictor: expected one of .* got 'euler'"):
        predicted_seed("euler", np.zeros(2), np.ones(2), -np.ones(2), np.ones(2))


def test_secant_seed_values():
    q, qpp = np.array([0.1, 0.9, -0.5]), np.array([0.0, 0.5, -0.2])
    lo, hi = -np.ones(3), np.ones(3)
    assert predicted_seed("none", q, qpp, lo, hi) is q
    assert predicted_seed("secant", q, None, lo, hi) is q               # the first waypoint: no q_{k-2}
    assert np.array_equal(predicted_seed("secant", q, qpp, lo, hi), [0.2, 1.0, -0.8])   # 1.3 clamped to 1
    assert np.array_equal(q, [0.1, 0.9, -0.5])                          # inputs untouched


def _extensions(robot, scene_name, predictor, extension, n_targets=12):
    """Extensions (improved variant, restarts off) from the start and goal of trials 0-1 toward random object
    targets: per extension (poses, configurations or None) and the summed counters."""
    from optplan.constraints.closed_chain import ClosedChainKinematics
    from optplan.planners import TCBiRRT, TCBiRRTOptions, ValidityChecker
    from optplan.planners.task_space import interpolate_task, pose_from_xi, xi_from_pose
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    sc = Scene.load(scene_name)
    ck, kin = ValidityChecker(robot, sc), ClosedChainKinematics(robot, sc.object.grasps)
    pl = TCBiRRT(robot, sc, TCBiRRTOptions(variant="improved", extension=extension, ik_predictor=predictor,
                                           ik_restarts=0), checker=ck, kinematics=kin)
    if extension == "native" and pl._ext is None:
        pytest.skip("the native extension is not available here")
    pl._rng = np.random.default_rng(1)
    rng = np.random.default_rng(6)
    st: dict[str, int] = {}
    out = []
    for t in range(2):
        tr = TrialGenerator(robot, sc).generate(t, 0)
        for q0 in (tr.q_start, tr.q_goal):
            M = kin.object_pose(q0)
            for _ in range(n_targets):
                Rs, ps = pose_from_xi(xi_from_pose(M) + rng.normal(0.0, 1.0, 6) * np.r_[[0.1] * 3, [0.2] * 3])
                poses = interpolate_task(M.rotation, M.translation, Rs, ps, pl.options.n_interp)
                s = {k: 0 for k in ("ik_calls", "ik_iterations", "ik_restarts", "ik_failures", "ik_jumps",
                                    "collisions", "edge_checks", "edge_collisions")}
                Q = pl.path_ik(poses, q0, s, prefix=True)
                for k, v in s.items():
                    st[k] = st.get(k, 0) + v
                out.append((q0, poses, Q))
    return pl, out, st


@pytest.mark.parametrize("extension", ["native", "python"])
def test_secant_waypoints_satisfy_the_hands_pose_constraint(tcb, extension):
    """Every accepted waypoint puts each hand on its grasp of the object pose to the IK's tolerances, by
    Pinocchio's forward kinematics, and lies within the joint-jump bound of the waypoint before it."""
    pl, out, _ = _extensions(tcb, "hard_bay", "secant", extension)
    model, data, s = tcb.model, tcb.model.createData(), pl.options.ik
    n_checked = 0
    for q0, poses, Q in out:
        prev = q0
        for q, (R, p) in zip(Q or [], poses):
            pin.framesForwardKinematics(model, data, q)
            for arm in pl.kin.arms:
                target = pin.SE3(np.asarray(R), np.asarray(p)) * pl.kin.grasps[arm.name]
                H = data.oMf[arm.ee_frame_id]
                assert np.linalg.norm(target.translation - H.translation) < s.tol_position * 1.01
                assert np.linalg.norm(pin.log3(H.rotation.T @ target.rotation)) < s.tol_orientation * 1.01
            assert np.abs(q - prev).max() <= pl.options.max_joint_step
            assert np.all(q >= tcb.lower - 1e-12) and np.all(q <= tcb.upper + 1e-12)
            prev = q
            n_checked += 1
    assert n_checked >= 60


def test_secant_takes_fewer_iterations_per_waypoint(tcb):
    """The same extensions seeded by the previous solution and by the secant prediction: fewer IK iterations per
    waypoint IK call with the secant (the first waypoint of each extension is seeded alike)."""
    per_call = {}
    for predictor in ("none", "secant"):
        _, out, st = _extensions(tcb, "hard_bay", predictor, "native")
        assert st["ik_calls"] >= 120
        per_call[predictor] = st["ik_path_iterations"] / st["ik_calls"]
    assert per_call["secant"] < 0.9 * per_call["none"], per_call


def test_benchmark_compares_identical_extensions():
    """`python -m optplan.bench.ik_predictor`: both predictors on the same extensions, the secant with fewer waypoint
    IK iterations per call, and a positive IK cost per iteration."""
    from optplan.bench.ik_predictor import predictor_costs

    r = predictor_costs("ssps_scene1", n=4, repeats=1)
    if not r["available"]:
        pytest.skip("the native loop is not available here")
    a, b = r["none"], r["secant"]
    assert a["ik_calls"] > 0 and b["ik_calls"] > 0 and r["extensions"] == 24
    assert b["ik_path_iterations"] / b["ik_calls"] < a["ik_path_iterations"] / a["ik_calls"]
    assert r["ik_fit"]["b_us_per_iteration"] > 0
