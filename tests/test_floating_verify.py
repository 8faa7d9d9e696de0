"""verify is the judge of a free-floating robot's motion: the base is re-integrated from zero
momentum (never read from the trajectory), the clearance is measured with the base where momentum
puts it, and the final base attitude is checked against the independent simulation."""
from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

from optplan.collision.checker import CollisionChecker
from optplan.model.floating import simulate_base
from optplan.scene import Obstacle, Scene
from optplan.verification import VerifyTolerances, verify

DEG = np.pi / 180.0
# a straight joint motion of both arms from a pose holding a module in front of the base, free of
# self-collision (self-clearance ≈ 0.10 m), that turns the base by ≈ 0.14 rad
Q0 = np.r_[[45.47, 42.5, -79.86, 20.38, -81.13, -150.5, 167.97] * 2] * DEG
QF = np.r_[[27.33, 24.26, -82.17, -28.42, -75.52, -99.93, 175.52],
           [74.74, 96.16, -38.81, 49.66, -43.55, -112.08, 138.42]] * DEG
T = 40.0   # [s]: the 10 deg/s joint speed limit holds


class Quintic:
    """Joint-only trajectory (what a floating Solution samples): rest-to-rest quintic from Q0 to QF,
    or out and back (``back=True``: the same path retraced, so the base must come back)."""

    def __init__(self, back: bool = False, N: int = 20):
        self.t, self.back, self.base_quat = np.linspace(0.0, T, N + 1), back, None

    def sample(self, ts):
        tau = np.asarray(ts) / T
        if self.back:   # s = sin²(π τ): 0 → 1 → 0
            s, sd = np.sin(np.pi * tau) ** 2, np.pi / T * np.sin(2 * np.pi * tau)
        else:
            s = 10 * tau ** 3 - 15 * tau ** 4 + 6 * tau ** 5
            sd = (30 * tau ** 2 - 60 * tau ** 3 + 30 * tau ** 4) / T
        return {"q": Q0 + np.outer(s, QF - Q0), "qd": np.outer(sd, QF - Q0)}


def _fixed_base(Q):
    """Full configurations with the base held at the identity."""
    return np.hstack([np.tile(pin.SE3ToXYZQUAT(pin.SE3.Identity()), (len(Q), 1)), Q])


def _drift_only_obstacle(robot):
    """A small sphere inside the base box where momentum puts it at the end of the one-way motion,
    and ≥ 2 cm from where the base would be without drift."""
    sol = Quintic()
    ts = np.linspace(0.0, T, 201)
    smp = sol.sample(ts)
    Mf = simulate_base(robot, (ts, smp["q"], smp["qd"]), ts).final_base
    half = np.array([0.6, 0.5, 0.8])
    best, best_d = None, -1.0
    box = coal.Box(*(2 * half))
    for corner in np.array(np.meshgrid(*[[-1, 1]] * 3)).T.reshape(-1, 3):
        p_local = corner * (half - 0.01)          # 1 cm inside the drifted box
        p = Mf.act(p_local)
        req, res = coal.DistanceRequest(), coal.DistanceResult()
        d = coal.distance(box, coal.Transform3s(), coal.Sphere(1e-4), coal.Transform3s(np.eye(3), p), req, res)
        if d > best_d:
            best, best_d = p, d
    radius = 0.005
    assert best_d > 0.02 + radius, f"the base drift is too small for this test ({best_d:.3f} m)"
    return Obstacle(name="drift_probe", shape="sphere", placement=pin.SE3(np.eye(3), best), radius=radius), sol


@pytest.fixture(scope="module")
def eba():
    from optplan.model.robot import RobotModel

    return RobotModel.from_name("eba_ffsr")


def test_a_motion_colliding_only_because_of_the_drift_fails(eba):
    obst, sol = _drift_only_obstacle(eba)
    scene = Scene(name="drift_probe", robot="eba_ffsr", obstacles=(obst,))
    rep = verify(eba, sol, scene, held_object=False)
    # the same joint motion with the base held still is clear (exact coal distance, no simulator)
    Q = sol.sample(np.linspace(0.0, T, 201))["q"]
    d_fixed, _, _ = CollisionChecker(eba, scene, held_object=False).min_distance_along(_fixed_base(Q))
    assert d_fixed > 0.02
    assert rep.min_clearance_m < 0.0 and "drift_probe" in rep.min_clearance_pair
    fails = rep.failures(VerifyTolerances(final_base_attitude_rad=None))
    assert len(fails) == 1 and fails[0].startswith("clearance"), fails
    assert not rep.passed(VerifyTolerances(final_base_attitude_rad=None))


def test_final_attitude_is_judged_by_the_independent_simulation(eba):
    scene = Scene(name="empty", robot="eba_ffsr", obstacles=())
    one_way = verify(eba, Quintic(), scene, held_object=False)
    ts = np.linspace(0.0, T, 2001)
    smp = Quintic().sample(ts)
    Rf = simulate_base(eba, (ts, smp["q"], smp["qd"]), ts, substeps=4).final_base.rotation
    expected = float(np.linalg.norm(pin.log3(Rf)))
    assert expected > 0.1   # the motion turns the base by degrees
    assert one_way.final_base_attitude_error_rad == pytest.approx(expected, rel=1e-4)
    assert any(f.startswith("final base attitude") for f in one_way.failures())
    assert one_way.passed(VerifyTolerances(final_base_attitude_rad=None))
    # out and back along the same path: the driftless base returns to its start attitude
    back = verify(eba, Quintic(back=True), scene, held_object=False)
    assert back.final_base_attitude_error_rad < 1e-6
    assert back.max_momentum_residual < 1e-8
    assert back.passed(), back.failures()


def test_verify_ignores_the_trajectory_s_base_and_starts_from_base0(eba):
    """The NLP's base states only enter the mismatch figure; a lying base does not move the verdict."""
    scene = Scene(name="empty", robot="eba_ffsr", obstacles=())
    sol = Quintic(back=True)
    ref = verify(eba, sol, scene, held_object=False)
    sol.base_quat = np.tile([0.0, 0.0, np.sin(0.25), np.cos(0.25)], (len(sol.t), 1))   # 0.5 rad about z
    lied = verify(eba, sol, scene, held_object=False)
    assert lied.base_attitude_mismatch_rad > 0.4
    assert lied.final_base_attitude_error_rad == ref.final_base_attitude_error_rad
    assert lied.min_clearance_m == ref.min_clearance_m and lied.passed()
    base0 = pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.2, 1.0), np.array([1.0, 2.0, 3.0]))
    moved = verify(eba, sol, scene, held_object=False, base0=base0)
    assert moved.final_base_attitude_error_rad < 1e-6
    assert moved.min_clearance_m == pytest.approx(ref.min_clearance_m, abs=1e-9)   # self-clearance only


def test_failures_name_each_check():
    from optplan.verification import VerifyReport

    rep = VerifyReport(n_samples=3, max_closed_chain_residual=2e-6, max_closed_chain_position_error_m=2e-6,
                       max_closed_chain_rotation_error_rad=0.0, min_clearance_m=0.01, min_clearance_pair="a / b",
                       max_position_limit_violation=0.1, max_velocity_limit_violation=0.0,
                       max_momentum_residual=float("nan"), base_attitude_mismatch_rad=float("nan"),
                       final_base_attitude_error_rad=float("nan"))
    f = rep.failures()
    assert len(f) == 2 and f[0].startswith("closed chain residual 2e-06") and "position limit" in f[1]
    assert rep.floating is False   # no attitude check for a fixed base
