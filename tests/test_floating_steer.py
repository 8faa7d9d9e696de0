"""Attitude steering of a free-floating base by closed loops of the held object
(optplan.planners.floating_steer), judged independently: one simulate_base run along the whole
joint path with another timing and finer RK4 steps gives the base, Pinocchio FK the closed chain,
coal's exact distances the clearance."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from floating_paths import reintegrate

from optplan.collision.checker import CollisionChecker
from optplan.errors import OptionError
from optplan.floating_pipeline import options_for_scene, scene_start
from optplan.model.robot import RobotModel
from optplan.planners.base import Deadline
from optplan.planners.floating_reach import nearest_held_attitude, zero_momentum_ik
from optplan.planners.floating_steer import AttitudeSteerer, SteerOptions, left_multiply
from optplan.planners.floating_tcbirrt import FloatingTCBiRRT
from optplan.scene import Scene


@pytest.fixture(scope="module")
def robot():
    return RobotModel.from_name("eba_ffsr")


@pytest.fixture(scope="module")
def truss(robot):
    scene = Scene.load("floating_truss")
    pl = FloatingTCBiRRT(robot, scene, options_for_scene(scene).planner)
    q0 = scene_start(robot, scene)
    return scene, pl.carry.hold(q0, pl.object_in_base(q0)), pl   # the witness onto the chain (1e-10)


def _reintegrate(robot, joints, base0, per_edge=10):
    """:func:`floating_paths.reintegrate` (smoothstep timing per edge, one simulate_base run)."""
    return reintegrate(robot, joints, base0, per_edge=per_edge, substeps=2)


def test_loops_turn_the_base_by_the_wanted_rotation(robot, truss):
    scene, q0, pl = truss
    base0 = pin.SE3(pin.rpy.rpyToMatrix(0.1, -0.2, 0.3), np.array([0.2, -0.1, 0.05]))
    steer = AttitudeSteerer(pl.carry, pl.validity)
    wanted = pin.exp3(np.array([0.0, 0.01, 0.03]))
    res = steer.steer(q0, pin.SE3.Identity(), wanted, np.random.default_rng(3), Deadline(60.0, "cpu"))
    assert res is not None and res.loops >= 2
    assert res.error_rad <= steer.options.tol_rad
    assert np.array_equal(res.joints[-1], q0)                       # the joints come back exactly
    joints = [q0] + res.joints
    s, sim = _reintegrate(robot, joints, pin.SE3.Identity())
    R_end = sim.final_base.rotation
    assert np.linalg.norm(pin.log3(R_end.T @ wanted)) <= steer.options.tol_rad + 1e-6
    assert np.linalg.norm(pin.log3(R_end)) > 0.02                   # it really turned
    for k in range(0, len(res.bases), 37):                           # the manoeuvre's bases = the integration
        e = res.bases[k].actInv(pin.XYZQUATToSE3(sim.q[(k + 1) * 10, :7]))
        assert np.linalg.norm(pin.log6(e).vector) < 1e-6
    # the base position follows the centre of mass, which did not move
    d = robot.model.createData()
    c0 = pin.centerOfMass(robot.model, d, sim.q[0])
    assert np.linalg.norm(pin.centerOfMass(robot.model, d, sim.q[-1]) - c0) < 1e-8
    assert np.max(sim.momentum_residual) < 1e-8
    ga, gb = scene.object.grasps["A"], scene.object.grasps["B"]
    for q in sim.q[::10][::25]:                                      # closed chain at waypoints
        pin.framesForwardKinematics(robot.model, d, q)
        hA, hB = (d.oMf[robot.arm(a).ee_frame_id] for a in ("A", "B"))
        rel = (hA * ga.inverse()).actInv(hB * gb.inverse())
        assert np.linalg.norm(pin.log6(rel).vector) < 1e-8
    dmin, _, _ = CollisionChecker(robot, scene).min_distance_along(sim.q[::2])   # the shipped truss, base from the origin
    assert dmin >= 0.5 * steer.options.clearance_m    # the loops keep their margin (≥ 0 between the samples)
    # from another base: the same manoeuvre composed by left-invariance (the samples moved by base0)
    s2, sim2 = _reintegrate(robot, joints, base0)
    e = (base0 * sim.final_base).actInv(sim2.final_base)
    assert np.linalg.norm(pin.log6(e).vector) < 1e-8
    assert len(res.rows) > len(res.joints)
    moved = left_multiply(res.rows[-1:], base0)
    assert np.linalg.norm(pin.log6(pin.XYZQUATToSE3(moved[0, :7]).actInv(sim2.final_base)).vector) < 1e-6


def test_a_loop_backwards_undoes_it(robot, truss):
    # driftless and reversible: the reversed joint loop moves the base by the inverse displacement
    _, q0, pl = truss
    steer = AttitudeSteerer(pl.carry, pl.validity)
    rng = np.random.default_rng(0)
    loop = next(lp for lp in (steer._loop(q0, rng) for _ in range(20)) if lp is not None)
    _, fwd = _reintegrate(robot, loop.joints, pin.SE3.Identity())
    _, back = _reintegrate(robot, loop.joints[::-1], pin.SE3.Identity())
    assert np.linalg.norm(pin.log3(fwd.final_base.rotation)) > 1e-4
    assert np.linalg.norm(pin.log6(fwd.final_base * back.final_base).vector) < 1e-8
    assert np.linalg.norm(pin.log6(loop.D.actInv(fwd.final_base)).vector) < 1e-6


def test_small_loop_holonomy_is_quadratic_and_bilinear(robot, truss):
    """The law steer_small solves with, checked on loops re-integrated independently: a small loop's
    rotation grows with the square of its size, and with the first via offset fixed it is linear
    in the second (b(ξ₁, ξ₂ + ξ₃) ≈ b(ξ₁, ξ₂) + b(ξ₁, ξ₃)) to leading order."""
    _, q0, pl = truss
    steer = AttitudeSteerer(pl.carry, pl.validity)
    rng = np.random.default_rng(5)

    def b(xis, s):
        lp = steer._loop(q0, None, np.asarray(xis), s)
        assert lp is not None
        _, sim = _reintegrate(robot, lp.joints, pin.SE3.Identity())
        return np.asarray(pin.log3(sim.final_base.rotation))

    o = steer.options
    xi = [np.r_[rng.uniform(-o.loop_m, o.loop_m, 3), rng.uniform(-o.loop_rad, o.loop_rad, 3)] for _ in range(3)]
    b1, b2 = b([xi[0], xi[1]], 0.1), b([xi[0], xi[1]], 0.2)
    assert np.linalg.norm(b1) > 1e-7
    assert abs(np.linalg.norm(b2) / np.linalg.norm(b1) - 4.0) < 0.4          # ∝ s²
    b12, b13, bs = b([xi[0], xi[1]], 0.1), b([xi[0], xi[2]], 0.1), b([xi[0], xi[1] + xi[2]], 0.1)
    assert np.linalg.norm(bs - (b12 + b13)) < 0.15 * np.linalg.norm(bs)       # linear in ξ₂
    assert np.linalg.norm(b([xi[1], xi[0]], 0.1) + b12) < 0.15 * np.linalg.norm(b12)   # antisymmetric


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_steer_small_solves_for_a_small_rotation(robot, truss, seed):
    """A re-steering's small rotation (1e-5-1e-3 rad, random axis) made by solved-for loops from the
    truss witness, judged by an independent re-integration (another timing, finer RK4 steps) and
    coal: the rotation to 1e-7 rad beyond the steering's own tolerance, the joints back exactly,
    clearance ≥ 0; and with far fewer loops than the search (which draws whole loops first)."""
    _, q0, pl = truss
    steer = AttitudeSteerer(pl.carry, pl.validity)
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    wanted = pin.exp3(10 ** rng.uniform(-5, -3) * axis / np.linalg.norm(axis))
    built = []
    loop = steer._loop
    steer._loop = lambda *a, **k: built.append(1) or loop(*a, **k)   # count the loops built
    res = steer.steer_small(q0, pin.SE3.Identity(), wanted, rng, Deadline(60.0, "cpu"), tol_rad=1e-7)
    assert res is not None and res.error_rad <= 1e-7
    assert np.array_equal(res.joints[-1], q0)
    assert len(built) <= 40
    _, sim = _reintegrate(robot, [q0] + res.joints, pin.SE3.Identity())
    assert np.linalg.norm(pin.log3(sim.final_base.rotation.T @ wanted)) <= 2e-7
    dmin, _, _ = CollisionChecker(robot, pl.carry.scene).min_distance_along(sim.q[::2])
    assert dmin >= 0.0


def test_nearest_held_attitude_holds_the_goal(robot, truss):
    scene, q0, pl = truss
    d = robot.model.createData()
    com = pin.centerOfMass(robot.model, d, pl.carry._full(q0))
    goal = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.25), scene.goal.translation + np.array([0.0, 0.1, 0.0]))
    got = nearest_held_attitude(robot, pl.carry.grasps, goal, [q0], com, np.random.default_rng(0), pin.SE3.Identity())
    assert got is not None
    R, q = got
    # at that attitude, with the base where the centre of mass puts it, both hands are at their grasps
    q_full_id = pl.carry._full(q)
    cb = pin.centerOfMass(robot.model, d, q_full_id)
    base = pin.SE3(R, com - R @ cb)
    pin.framesForwardKinematics(robot.model, d, pl.carry._full(q, base))
    for a in ("A", "B"):
        e = (goal * scene.object.grasps[a]).actInv(d.oMf[robot.arm(a).ee_frame_id])
        assert np.linalg.norm(pin.log6(e).vector) < 1e-8
    # the free solution's attitude is not nearer than this one by more than a step of the walk
    _, bf, _ = zero_momentum_ik(robot, pl.carry.grasps, goal, [q0], com, np.random.default_rng(0), n_random=4)
    assert np.linalg.norm(pin.log3(R)) <= np.linalg.norm(pin.log3(bf.rotation)) + 1e-9


def test_steer_options_are_checked():
    with pytest.raises(OptionError, match="loop_m"):
        SteerOptions(loop_m=-0.1)
    with pytest.raises(OptionError, match="max_rounds"):
        SteerOptions(max_rounds=0)
    with pytest.raises(OptionError, match="clearance_m"):
        SteerOptions(clearance_m=-1e-3)
    with pytest.raises(OptionError, match="probe_scale"):
        SteerOptions(probe_scale=0.0)
    with pytest.raises(OptionError, match="max_probes"):
        SteerOptions(max_probes=0)
    assert SteerOptions(clearance_m=0).clearance_m == 0
