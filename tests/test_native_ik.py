"""The hand-written closed-chain IK of TCBiRRT's native extension (optplan.planners.kernel.ik) against the
compiled CasADi block it replaces (ClosedChainKinematics.ik) and against Pinocchio's Jacobians."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.planners.kernel.extend import load_extend_library, nearest_available

pytestmark = pytest.mark.skipif(not nearest_available(), reason="no C compiler: the native extension is not built")


def _setup(robot, name):
    from optplan.constraints.closed_chain import ClosedChainKinematics
    from optplan.planners.kernel.ik import NativeIK
    from optplan.planners.validity import ValidityChecker
    from optplan.scene import Scene

    sc = Scene.load(name)
    ck = ValidityChecker(robot, sc)
    if ck._native is None:
        pytest.skip("the native planning kernel is not available here")
    kin = ClosedChainKinematics(robot, sc.object.grasps)
    if not kin.compiled:
        pytest.skip("the closed-chain IK block is not compiled here")
    return sc, kin, NativeIK(ck._native.kernel, kin, load_extend_library())


@pytest.mark.parametrize("scene", ["hard_bay", "ssps_scene1"])
def test_solves_match_the_casadi_block(tcb, scene):
    """Near and far seeds and targets (converged, clipped steps, joint limits, failures): the same verdict, the
    same iteration count and the same configuration to round-off."""
    from optplan.constraints.closed_chain import IKSettings
    from optplan.trials import TrialGenerator

    sc, kin, nik = _setup(tcb, scene)
    rng = np.random.default_rng(4)
    kinds = set()
    for s in (IKSettings(), IKSettings(max_step=0.1, gain=0.8, damping=1e-2, max_iterations=40)):
        for t in range(3):
            q0 = TrialGenerator(tcb, sc).generate(t, 0).q_start
            M = kin.object_pose(q0)
            for k in range(60):
                big = k % 3 == 0
                R = M.rotation @ np.asarray(pin.exp3(rng.normal(0.0, 0.6 if big else 0.1, 3)))
                p = M.translation + rng.normal(0.0, 0.3 if big else 0.05, 3)
                seed = np.clip(q0 + rng.normal(0.0, 0.8 if big else 0.05, q0.size), tcb.lower, tcb.upper)
                qa, ia = kin.ik(seed, R, p, s)
                qb, ib = nik.solve(seed, R, p, s)
                assert ia == ib and (qa is None) == (qb is None)
                if qa is not None:
                    assert np.abs(qa - qb).max() < 1e-9
                    data = tcb.model.createData()            # the hands on their grasps, by Pinocchio
                    pin.framesForwardKinematics(tcb.model, data, qb)
                    for arm in kin.arms:
                        oMg, oMh = pin.SE3(R, p) * kin.grasps[arm.name], data.oMf[arm.ee_frame_id]
                        assert np.linalg.norm(oMg.translation - oMh.translation) < s.tol_position + 1e-12
                        assert np.linalg.norm(pin.log3(oMh.rotation.T @ oMg.rotation)) < s.tol_orientation + 1e-12
                    kinds.add("limit" if np.any((qb <= tcb.lower) | (qb >= tcb.upper)) else "converged")
                else:
                    kinds.add("failed")
                kinds.add("many" if ia > 8 else "few")
    assert {"converged", "failed", "many", "few"} <= kinds


def test_jacobian_and_errors_match_pinocchio(tcb):
    _, kin, nik = _setup(tcb, "hard_bay")
    model, data = tcb.model, tcb.model.createData()
    rng = np.random.default_rng(9)
    for _ in range(20):
        q = rng.uniform(tcb.lower, tcb.upper)
        R, p = np.asarray(pin.exp3(rng.normal(size=3))), rng.normal(size=3)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for a, arm in enumerate(kin.arms):
            e, J = nik.jacobian(a, q, R, p)
            Jp = pin.getFrameJacobian(model, data, arm.ee_frame_id, pin.LOCAL_WORLD_ALIGNED)[:, arm.v_idx]
            assert np.abs(J - Jp).max() < 1e-12
            oMg = pin.SE3(R, p) * kin.grasps[arm.name]
            oMh = data.oMf[arm.ee_frame_id]
            assert np.allclose(e[:3], oMg.translation - oMh.translation, atol=1e-12)
            # e_o = R_g log(R_h^T R_g) (Eq. 6), away from a half turn
            w = pin.log3(oMh.rotation.T @ oMg.rotation)
            if np.linalg.norm(w) < 3.0:
                assert np.allclose(e[3:], oMg.rotation @ w, atol=1e-9)


def test_extensions_are_the_same_with_either_ik(tcb):
    """The extension with the C IK and with the CasADi block: the same configurations, counters and draws."""
    from optplan.planners import TCBiRRT, TCBiRRTOptions, ValidityChecker
    from optplan.planners.task_space import pose_from_xi, xi_from_pose
    from optplan.planners.tcbirrt_native import loop_extend
    from optplan.trials import TrialGenerator

    sc, kin, _ = _setup(tcb, "hard_window")
    ck = ValidityChecker(tcb, sc)
    pl = TCBiRRT(tcb, sc, TCBiRRTOptions(variant="improved", extension="loop"), checker=ck, kinematics=kin)
    pl._rng = np.random.default_rng(1)
    pl._sampler()
    if pl._nrng is None or pl._ext is None or pl._ext._ik is None:
        pytest.skip("the native loop is not available here")
    ext = pl._ext
    assert ext.native_ik                                   # the default
    q0 = TrialGenerator(tcb, sc).generate(0, 0).q_start
    M = kin.object_pose(q0)
    runs = {}
    for on in (True, False):
        ext.native_ik = on
        pl._nrng.lib.tcb_rng_seed(pl._nrng.address, 5)
        r = np.random.default_rng(2)
        out = []
        for _ in range(60):
            Rs, ps = pose_from_xi(xi_from_pose(M) + r.normal(0.0, 1.0, 6) * np.r_[[0.15] * 3, [0.3] * 3])
            st = {k: 0 for k in ("ik_calls", "ik_iterations", "ik_restarts", "ik_failures", "ik_jumps", "collisions",
                                 "edge_checks", "edge_collisions")}
            _, Q = loop_extend(pl, M.rotation, M.translation, Rs, ps, q0, st, True)
            out.append((None if Q is None else np.array(Q), st))
        runs[on] = out
    ext.native_ik = True
    n_restarts = 0
    for (Qa, sa), (Qb, sb) in zip(runs[True], runs[False]):
        assert sa == sb and (Qa is None) == (Qb is None)
        if Qa is not None:
            assert Qa.shape == Qb.shape and (Qa.size == 0 or np.abs(Qa - Qb).max() < 1e-9)
        n_restarts += sa["ik_restarts"]
    assert n_restarts > 0


def test_bad_input(tcb):
    from optplan.constraints.closed_chain import IKSettings
    from optplan.errors import OptplanError

    _, _, nik = _setup(tcb, "ssps_scene1")
    with pytest.raises(OptplanError, match="q_seed: expected 14 joint values"):
        nik.solve(np.zeros(3), np.eye(3), np.zeros(3), IKSettings())
    with pytest.raises(OptplanError, match="arm: expected 0 or 1"):
        nik.jacobian(2, np.zeros(14), np.eye(3), np.zeros(3))


def test_benchmarks_compare_identical_work():
    """`python -m optplan.bench.tcbirrt_native --ik-units` / `--regrasp-units`: both sides do the same work."""
    from optplan.bench.tcbirrt_native import ik_costs, regrasp_search_costs

    u = ik_costs("ssps_scene1", n=5, repeats=1)
    if not u["available"]:
        pytest.skip("the native loop is not available here")
    assert u["c_ik_iterations"] == u["casadi_ik_iterations"] > 0 and u["c_checks"] == u["casadi_checks"] > 0
    assert u["c_extension_us"] > 0 and u["casadi_extension_us"] > 0
    r = regrasp_search_costs("ssps_scene1", trials=1, goals=1)
    assert r["static_checks"] == r["whole_checks"] > 0 and r["static_us"] > 0 and r["whole_us"] > 0


def test_the_extensions_ik_is_the_hand_written_one_and_the_block_without_it(tcb):
    """``NativeExtender.ik`` (the look-ahead grafts' IK from uniform seeds): with the hand-written IK on, the CasADi
    block's verdict and iteration count and its configuration to round-off on almost every seed (a seed drawn over
    the whole joint box may sit where round-off tips a step: a rare difference, not a rule), and the hands on their
    grasps by Pinocchio; with it off, the block itself, bit for bit."""
    from optplan.planners.tcbirrt import TCBiRRT
    from optplan.planners.tcbirrt_options import TCBiRRTOptions
    from optplan.trials import TrialGenerator

    sc, kin, _ = _setup(tcb, "hard_bay")
    pl = TCBiRRT(tcb, sc, TCBiRRTOptions(variant="improved"), kinematics=kin)
    ext = pl._ext
    if ext is None or ext._ik is None:
        pytest.skip("the native extension is not available here")
    assert ext.native_ik
    s = pl.options.ik
    rng = np.random.default_rng(11)
    M = kin.object_pose(TrialGenerator(tcb, sc).generate(0, 0).q_start)
    R, p = M.rotation, M.translation
    same = conv = 0
    n = 300
    for _ in range(n):
        seed = rng.uniform(tcb.lower, tcb.upper)
        qa, ia = ext.ik(seed, R, p)
        qb, ib = ext.ik_block(seed, R, p)
        if ia == ib and (qa is None) == (qb is None) and (qa is None or np.abs(qa - qb).max() < 1e-9):
            same += 1
        if qa is not None:
            conv += 1
            data = tcb.model.createData()
            pin.framesForwardKinematics(tcb.model, data, qa)
            for arm in kin.arms:
                oMg, oMh = M * kin.grasps[arm.name], data.oMf[arm.ee_frame_id]
                assert np.linalg.norm(oMg.translation - oMh.translation) < s.tol_position + 1e-12
                assert np.linalg.norm(pin.log3(oMh.rotation.T @ oMg.rotation)) < s.tol_orientation + 1e-12
    assert conv >= 10 and same >= 0.95 * n, (conv, same)
    ext.native_ik = False
    try:
        for _ in range(50):
            seed = rng.uniform(tcb.lower, tcb.upper)
            (qa, ia), (qb, ib) = ext.ik(seed, R, p), ext.ik_block(seed, R, p)
            assert ia == ib and (qa is None) == (qb is None) and (qa is None or np.array_equal(qa, qb))
    finally:
        ext.native_ik = True
