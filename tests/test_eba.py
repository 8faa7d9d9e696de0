"""The EBA paper (issue 5): BA, EBA, quintic, leader-follower, Fourier and optplan's restoration NLP.

Every method runs once per module (fixtures); the tests check the issue's bullets: EBA's meeting
(Δθ → 0 with zero velocity at 0, t_m, 2 t_m), BA's velocity jumps, the NLP's exact restoration
and rest-to-rest boundaries, the closed chain of EBA/NLP, and that every method's final base
attitude equals what the independent simulator gives for its joint trajectory.
"""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pinocchio as pin
import pytest

from optplan import Kinematics, simulate_base
from optplan.papers import eba
from optplan.papers.eba.core import EBAKinematics, matrix_rpy, rpy_matrix, rpy_rate_matrix

AGREE_RAD = 1e-5  # method's own final attitude vs the independent simulator


@pytest.fixture(scope="module")
def fe():
    return eba.free_end_scenario()


@pytest.fixture(scope="module")
def ec(eba_robot):
    return eba.end_constrained_scenario(eba_robot)


@pytest.fixture(scope="module")
def eba_robot():
    from optplan import RobotModel

    return RobotModel.from_name("eba_ffsr")


def _run(robot, scen, name, options=None):
    res = eba.run_method(robot, scen, name, options)
    return res, eba.evaluate(robot, res, scen)


@pytest.fixture(scope="module")
def quintic(eba_robot, fe):
    return _run(eba_robot, fe, "quintic")


@pytest.fixture(scope="module")
def ba(eba_robot, fe):
    return _run(eba_robot, fe, "ba")


@pytest.fixture(scope="module")
def eba_free(eba_robot, fe):
    return _run(eba_robot, fe, "eba", eba.EBAOptions.paper_free_end(lam=1e-5))


@pytest.fixture(scope="module")
def eba_ec(eba_robot, ec):
    return _run(eba_robot, ec, "eba")  # the paper's Section 4.2 parameters


@pytest.fixture(scope="module")
def lf(eba_robot, ec):
    return _run(eba_robot, ec, "leader_follower")


@pytest.fixture(scope="module")
def nlp_free(eba_robot, fe):
    return _run(eba_robot, fe, "nlp")


@pytest.fixture(scope="module")
def fourier_free(eba_robot, fe):
    return _run(eba_robot, fe, "fourier")


# --------------------------------------------------------------------------- options
@pytest.mark.parametrize("cls, kw", [
    (eba.EBAOptions, {"k": 0.0}), (eba.EBAOptions, {"m": -1.0}), (eba.EBAOptions, {"lam": -1e-3}),
    (eba.EBAOptions, {"k": 0.2}), (eba.EBAOptions, {"dt": 200.0}), (eba.EBAOptions, {"t0": float("nan")}),
    (eba.BAOptions, {"Q": 0.0}), (eba.BAOptions, {"horizon": -1.0}),
    (eba.QuinticOptions, {"duration": 0.0}), (eba.QuinticOptions, {"samples": 2}),
    (eba.LeaderFollowerOptions, {"clik_gain": -1.0}), (eba.LeaderFollowerOptions, {"dt": 5.0}),
    (eba.FourierOptions, {"n_harmonics": 0}), (eba.FourierOptions, {"penalty": 0.0}),
    (eba.FourierOptions, {"hessian": "exact"}), (eba.FourierOptions, {"velocity_limit_deg_s": -1.0}),
    (eba.NLPOptions, {"n_intervals": 0}), (eba.NLPOptions, {"smoothness": "snap"}),
    (eba.NLPOptions, {"duration": float("inf")}),
])
def test_options_validated_on_construction(cls, kw):
    with pytest.raises(ValueError):
        cls(**kw)


def test_options_are_frozen_with_paper_defaults():
    o = eba.EBAOptions()
    assert (o.k, o.m, o.t0, o.lam, o.horizon) == (1.3, 0.125, 1000.0, 0.0, 300.0)
    c = eba.EBAOptions.paper_end_constrained()
    assert (c.k, c.m, c.t0, c.lam, c.horizon) == (1.1, 0.1, 95.0, 1e-5, 200.0)
    assert eba.BAOptions().Q == 8.0 and eba.BAOptions().horizon == 300.0
    f = eba.FourierOptions()
    assert f.penalty == 1e4 and 14 * (2 * f.n_harmonics + 1) == 98 and f.duration == 20.0
    assert eba.QuinticOptions().duration == 20.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.k = 2.0  # frozen
    with pytest.raises(TypeError):
        eba.run_method(None, None, "eba", eba.BAOptions())
    with pytest.raises(ValueError):
        eba.run_method(None, None, "rrt")


# --------------------------------------------------------------------------- kinematics
def test_rate_map_and_constraint_match_pinocchio(eba_robot, rng):
    kin, ekin = Kinematics(eba_robot), EBAKinematics(eba_robot)
    for _ in range(3):
        th = rng.uniform(-2, 2, eba_robot.nj)
        qd = rng.normal(size=eba_robot.nj)
        K, H = ekin.rate_map_and_constraint(th)
        vb = kin.base_velocity(eba_robot.configuration(th), qd)
        assert np.allclose(K @ qd, vb[3:], atol=1e-12)
        # H from fixed-base Jacobians = H from the generalized Jacobians (base motion cancels)
        q = eba_robot.configuration(th, pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3)))
        G = kin.generalized_jacobians(q)
        Ma, Mb = kin.frame_placements(q, ["a_ee", "b_ee"])
        r_ab = Ma.translation - Mb.translation
        S = np.array([[0, -r_ab[2], r_ab[1]], [r_ab[2], 0, -r_ab[0]], [-r_ab[1], r_ab[0], 0]])
        Hg = np.vstack([G["B"][:3] - G["A"][:3] - S @ G["A"][3:], G["B"][3:] - G["A"][3:]])
        Rw = eba_robot.base_placement(q).rotation  # H is in world axes at the identity base
        assert np.allclose(np.vstack([Rw.T @ Hg[:3], Rw.T @ Hg[3:]]), H, atol=1e-10)


def test_rpy_rate_matrix_is_the_paper_eq1_map(rng):
    for _ in range(5):
        a = rng.uniform(-0.3, 0.3, 3)
        w = rng.normal(size=3)  # base-frame angular velocity
        eps = 1e-7
        R1 = rpy_matrix(a) @ pin.exp3(eps * w)
        fd = (matrix_rpy(R1) - a) / eps
        assert np.allclose(rpy_rate_matrix(a) @ w, fd, atol=1e-5)


def test_end_constrained_goal_lies_on_the_start_manifold(eba_robot, ec):
    ekin = EBAKinematics(eba_robot)
    assert ekin.closed_chain_residual(ec.thetaf, ec.relative) < 1e-12
    assert 0.0 < ec.goal_adjustment_deg < 0.1  # the printed goal is rounded to 0.01°
    assert np.array_equal(ec.thetaf[:7], ec.thetaf_paper[:7])  # arm A's goal unchanged


# --------------------------------------------------------------------------- the bullets
def test_eba_meets_with_zero_velocity_at_0_tm_2tm(eba_free, eba_ec):
    for res, rep, dth_max in ((*eba_free, 0.02), (*eba_ec, 0.02)):
        assert res.success, res.message
        assert res.info["meeting_dx_joint_deg"] < dth_max  # Δθ(t_m) → 0
        (t0, j0), (tm, jm), (te, je) = rep.velocity_jumps_deg_s
        assert j0 == 0.0 and je == 0.0  # starts and ends at rest (z = 0 on both robots)
        assert abs(tm - res.meeting_time) < 1e-9 and jm < 0.2  # [deg/s] at the meeting
        assert rep.max_velocity_deg_s < 10.0  # within the model's speed limit
        # the attitude part of Δx is only reduced to a few tenths of a degree on our model
        assert res.info["meeting_dx_attitude_deg"] < 0.5
    # end-constrained meeting as the paper's Sec. 4.2: Δθ ≈ 0.01° at t0 = 95 s
    assert eba_ec[0].info["meeting_dx_joint_deg"] == pytest.approx(0.011, abs=0.003)


def test_eba_with_the_papers_free_end_lambda_diverges_and_says_so(eba_robot, fe):
    res = eba.run_eba(eba_robot, fe, eba.EBAOptions.paper_free_end())
    assert not res.success and "diverged" in res.message
    assert res.meeting_time < 150.0


def test_ba_has_the_velocity_jumps_of_the_paper(ba, eba_free):
    res, rep = ba
    assert res.success, res.message
    (t0, j0), (tm, jm), (te, je) = rep.velocity_jumps_deg_s
    assert t0 == 0.0 and tm == pytest.approx(150.0) and te == pytest.approx(300.0)
    assert j0 > 1.0 and je > 1.0 and jm > 0.1  # [deg/s]: jumps at 0, t_m, 2 t_m
    assert jm > eba_free[1].velocity_jumps_deg_s[1][1]
    # BA keeps Δα ≡ 0 (Δẋ = -Δx/8 exactly while W̄ has full rank) and meets in the joints
    assert res.info["meeting_dx_attitude_deg"] < 1e-9 and res.info["meeting_dx_joint_deg"] < 1e-5


def test_nlp_restores_the_attitude_with_rest_to_rest_boundaries(nlp_free):
    res, rep = nlp_free
    assert res.success, res.message
    assert res.info["verify_final_base_attitude_error_rad"] <= 1e-6
    assert np.deg2rad(rep.final_base_attitude_error_deg) <= 1e-6
    assert res.info["boundary_velocity_max"] <= 1e-9 and res.info["boundary_acceleration_max"] <= 1e-9
    assert rep.max_velocity_jump_deg_s < 1e-6
    assert rep.final_joint_error_deg < 1e-6
    assert res.info["verify_max_position_limit_violation"] == 0.0


def test_end_constrained_methods_keep_the_relative_hand_pose(eba_ec, lf):
    assert eba_ec[1].max_closed_chain_residual <= 1e-6
    assert lf[1].max_closed_chain_residual <= 1e-6  # velocity IK + drift correction


def test_nlp_end_constrained_short(eba_robot, ec):
    """N = 16: the closed chain holds at the knots (the NLP's constraint) and the attitude is
    restored; between knots it drifts ∝ h⁴ (the slow test checks N = 48 densely)."""
    res, rep = _run(eba_robot, ec, "nlp", eba.NLPOptions.end_constrained(n_intervals=16))
    assert res.success, res.message
    ekin = EBAKinematics(eba_robot)
    knots = res.raw.q
    assert max(ekin.closed_chain_residual(q, ec.relative) for q in knots) <= 1e-6
    assert res.info["verify_final_base_attitude_error_rad"] <= 1e-6
    assert rep.max_closed_chain_residual < 1e-3


@pytest.mark.slow
def test_nlp_end_constrained_dense_residual(eba_robot, ec):
    res, rep = _run(eba_robot, ec, "nlp")
    assert res.success, res.message
    assert rep.max_closed_chain_residual <= 1e-6
    assert res.info["verify_final_base_attitude_error_rad"] <= 1e-6


def test_every_method_agrees_with_the_independent_simulator(quintic, ba, eba_free, eba_ec, lf, nlp_free,
                                                            fourier_free):
    for res, rep in (quintic, ba, eba_free, eba_ec, lf, nlp_free, fourier_free):
        assert res.planned_final_rotation is not None
        assert rep.planned_vs_simulated_rad <= AGREE_RAD, (res.name, rep.planned_vs_simulated_rad)
        assert rep.max_momentum_residual < 1e-9


@pytest.mark.slow
def test_fourier_end_constrained_agrees_with_the_simulator(eba_robot, ec):
    res, rep = _run(eba_robot, ec, "fourier")
    assert res.success, res.message
    assert rep.planned_vs_simulated_rad <= AGREE_RAD
    assert rep.final_base_attitude_error_deg < 1e-3 and rep.max_closed_chain_residual < 5e-3
    assert rep.max_velocity_jump_deg_s > 0.5  # rates do not vanish at 0 and T


def test_ranking_of_the_paper(quintic, eba_free, nlp_free, fourier_free, eba_ec, lf):
    q, e, n, f = (r[1].final_base_attitude_error_deg for r in (quintic, eba_free, nlp_free, fourier_free))
    assert 0.3 < q < 3.0  # "about a degree"
    assert e < q / 4 and n < e and np.deg2rad(n) <= 1e-6
    assert f < 1e-3 and fourier_free[1].max_velocity_jump_deg_s > 0.5  # exact in attitude, jumps at 0/T
    assert eba_ec[1].final_base_attitude_error_deg < lf[1].final_base_attitude_error_deg


def test_quintic_matches_the_demo_and_is_driftless(eba_robot, fe, quintic):
    assert np.allclose(quintic[1].final_base_rpy_deg, (-0.644, 0.089, -1.311), atol=2e-3)  # optplan demo
    slow = eba.run_quintic(eba_robot, fe, eba.QuinticOptions(duration=300.0))
    assert np.allclose(eba.evaluate(eba_robot, slow, fe).final_base_rpy_deg, quintic[1].final_base_rpy_deg, atol=1e-7)


def test_leader_follower_reproduces_the_paper(lf):
    """Section 4.2's leader-follower figures are reproduced by our model (unlike Section 4.1's)."""
    res, rep = lf
    assert np.allclose(rep.final_base_rpy_deg, (0.32, 0.67, 1.75), atol=0.05)
    paper_b = np.array([3.15, -89.45, 33.67, 109.37, -55.55, 90.16, -36.61])
    assert np.allclose(np.rad2deg(res.segments[-1].q[-1, 7:]), paper_b, atol=0.1)
    assert rep.velocity_jumps_deg_s[0][1] < 1e-6 and rep.velocity_jumps_deg_s[-1][1] < 1e-6


def test_simulated_final_attitude_uses_simulate_base(eba_robot, quintic):
    res, rep = quintic
    seg = res.segments[0]
    sim = simulate_base(eba_robot, (seg.t, seg.q, seg.qd), seg.t, substeps=2)
    assert np.allclose(np.rad2deg(sim.base_rpy[-1]), rep.final_base_rpy_deg, atol=1e-9)


# --------------------------------------------------------------------------- outputs
def test_save_npz_contract(tmp_path, eba_robot, ba):
    res = ba[0]
    p = tmp_path / "ba.npz"
    res.save_npz(p, eba_robot.joint_names)
    with np.load(p) as z:
        assert z["q"].shape == (z["t"].size, 14) and np.all(np.diff(z["t"]) > 0)
        assert tuple(z["joint_names"]) == eba_robot.joint_names
        t, q = z["t"], z["q"]
    # sampled finely enough to integrate the base from: a spline through the samples gives the
    # method's final attitude
    sim = simulate_base(eba_robot, (t, q), t[::2], substeps=2)
    assert np.rad2deg(np.linalg.norm(pin.log3(sim.final_base.rotation))) < 1e-3


def _load_example(name):
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_example_json_and_save_contracts(tmp_path, capsys):
    mod = _load_example("eba_free_end")
    out = tmp_path / "fe.json"
    rc = mod.main(["--methods", "quintic", "--json", str(out), "--save", str(tmp_path / "traj")])
    assert rc == 0
    d = json.loads(out.read_text())
    m = d["methods"]["quintic"]
    for k in ("final_base_rpy_deg", "final_joint_error_deg", "max_velocity_jump_deg_s", "runtime_s"):
        assert k in m
    assert len(m["final_base_rpy_deg"]) == 3 and "max_closed_chain_residual" not in m
    assert (tmp_path / "traj" / "quintic.npz").exists()
    assert "paper" in capsys.readouterr().out
    mod = _load_example("eba_end_constraints")
    out = tmp_path / "ec.json"
    assert mod.main(["--methods", "leader_follower", "--json", str(out)]) == 0
    m = json.loads(out.read_text())["methods"]["leader_follower"]
    assert m["max_closed_chain_residual"] <= 1e-6 and m["final_joint_error_deg"] > 10.0


def test_paper_targets_are_reported_not_folded_into_the_criteria():
    """A run whose EBA ends at 0.18° (our model, docs/eba.md) meets its criteria but not the paper's
    0.01°: the verdict line says both, naming the missed target with its value."""
    from types import SimpleNamespace

    from optplan.papers import eba as E

    rep = {"quintic": SimpleNamespace(final_base_attitude_error_deg=0.9, runtime_s=0.1),
           "eba": SimpleNamespace(final_base_attitude_error_deg=0.18, runtime_s=1.0),
           "nlp": SimpleNamespace(final_base_attitude_error_deg=1e-6, runtime_s=3.0)}
    case = E.CaseResult("free_end", None, reports=rep)
    targets = E.paper_targets(case)
    met = {d.split(":")[0] + (" time" if "run time" in d else ""): m for d, m, _ in targets}
    assert met == {"quintic": True, "eba": False, "nlp": True, "eba time": True, "nlp time": False}
    line = E.verdict([("a", True, "x"), ("b", True, "y")], targets)
    assert line.startswith("criteria (pass/fail): 2/2 met; the paper's targets (reported, not pass/fail): 3/5 met")
    assert "≤ 0.01° (the paper's figure) — measured 0.18°" in line and "run time ≤ 2 s — measured 3.00 s" in line
