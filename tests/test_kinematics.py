"""Numeric kinematics (optplan.model.kinematics): momentum conservation of the base twist, the
generalized Jacobian against an independent formula (mass matrix, SPART/SpaceDyn form) and
against Pinocchio's own velocity propagation."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.model.kinematics import Kinematics

N = 30
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def _momentum(m, d, q, v):
    """Centroidal momentum with Pinocchio's recursive algorithm (not the map)."""
    h = pin.computeCentroidalMomentum(m, d, q, v)
    return np.concatenate([h.linear, h.angular])


def _samples(robot, rng, n=N):
    for _ in range(n):
        yield robot.random_configuration(rng), rng.normal(size=robot.nj)


# --------------------------------------------------------------------------- momentum
def test_base_velocity_gives_zero_momentum(eba, rng):
    kin = Kinematics(eba)
    m, d = eba.model, eba.model.createData()
    for q, qd in _samples(eba, rng):
        v = kin.full_velocity(q, qd)
        assert v.shape == (eba.nv,)
        np.testing.assert_array_equal(v[6:], qd)
        np.testing.assert_allclose(v[:6], kin.base_velocity(q, qd), rtol=0, atol=1e-14)
        h = _momentum(m, d, q, v)
        # scale: momentum of the joints alone
        scale = np.abs(pin.computeCentroidalMap(m, d, q)[:, 6:] @ qd).max()
        assert np.abs(h).max() <= 1e-12 * scale, h
        np.testing.assert_allclose(kin.centroidal_map(q) @ v, 0.0, atol=1e-12 * scale)
        np.testing.assert_allclose(kin.momentum(q, v), h, atol=1e-12 * scale)


def test_base_velocity_gives_requested_momentum(eba, rng):
    kin = Kinematics(eba)
    m, d = eba.model, eba.model.createData()
    for q, qd in _samples(eba, rng):
        h0 = rng.normal(size=6) * [5, 5, 5, 20, 20, 20]
        v = kin.full_velocity(q, qd, h0=h0)
        np.testing.assert_allclose(_momentum(m, d, q, v), h0, rtol=0, atol=1e-10)
        np.testing.assert_allclose(kin.base_velocity(q, np.zeros(eba.nj), h0=h0), v[:6] - kin.base_velocity(q, qd),
                                   atol=1e-12)


def test_pure_base_translation_momentum_is_mass_times_world_velocity(eba, rng):
    """h0 = [p; 0] with the joints at rest: the base translates at p/M (world axes), no spin."""
    kin = Kinematics(eba)
    M = 593.58
    for q, _ in _samples(eba, rng, 5):
        p = np.array([1.0, -2.0, 0.5])
        vb = kin.base_velocity(q, np.zeros(eba.nj), h0=np.r_[p, 0, 0, 0])
        R = eba.base_placement(q).rotation
        np.testing.assert_allclose(R @ vb[:3], p / M, atol=1e-12)
        np.testing.assert_allclose(vb[3:], 0.0, atol=1e-12)


def test_center_of_mass_is_mass_weighted_body_coms(eba, tcb, rng):
    for robot in (eba, tcb):
        kin = Kinematics(robot)
        m, d = robot.model, robot.model.createData()
        for q, _ in _samples(robot, rng, 5):
            pin.forwardKinematics(m, d, q)
            ms = np.array([m.inertias[j].mass for j in range(1, m.njoints)])
            cs = np.array([d.oMi[j].act(m.inertias[j].lever) for j in range(1, m.njoints)])
            np.testing.assert_allclose(kin.center_of_mass(q), ms @ cs / ms.sum(), atol=1e-12)


def test_fixed_base_full_velocity_is_the_joint_rates(tcb, rng):
    kin = Kinematics(tcb)
    qd = rng.normal(size=tcb.nj)
    np.testing.assert_array_equal(kin.full_velocity(tcb.random_configuration(rng), qd), qd)


# --------------------------------------------------------------------------- generalized Jacobian
def test_generalized_jacobian_predicts_the_ee_velocity_of_the_free_floating_robot(eba, rng):
    """J* q̇ = EE velocity (origin, world axes) that Pinocchio's forward kinematics gives with the
    momentum-conserving base twist."""
    kin = Kinematics(eba)
    m, d = eba.model, eba.model.createData()
    for q, qd in _samples(eba, rng):
        v = kin.full_velocity(q, qd)
        pin.forwardKinematics(m, d, q, v)
        pin.updateFramePlacements(m, d)
        for name, arm in eba.arms.items():
            Js = kin.generalized_jacobian(q, name)
            assert Js.shape == (6, eba.nj)
            vel = pin.getFrameVelocity(m, d, arm.ee_frame_id, LWA)
            np.testing.assert_allclose(Js @ qd, np.r_[vel.linear, vel.angular], atol=1e-10)


def test_generalized_jacobian_equals_mass_matrix_formula(eba, rng):
    """J* = J_m − J_b H_b⁻¹ H_bm (SPART / SpaceDyn form) with the joint-space inertia matrix."""
    kin = Kinematics(eba)
    m, d = eba.model, eba.model.createData()
    for q, _ in _samples(eba, rng, 10):
        Hm = pin.crba(m, d, q)
        Hm = np.triu(Hm) + np.triu(Hm, 1).T
        for name, arm in eba.arms.items():
            J = pin.computeFrameJacobian(m, d, q, arm.ee_frame_id, LWA)
            Js = J[:, 6:] - J[:, :6] @ np.linalg.solve(Hm[:6, :6], Hm[:6, 6:])
            np.testing.assert_allclose(kin.generalized_jacobian(q, name), Js, atol=1e-10)


def test_generalized_jacobian_frame_and_arm_columns(eba, rng):
    kin = Kinematics(eba)
    m, d = eba.model, eba.model.createData()
    q = eba.random_configuration(rng)
    Ag = pin.computeCentroidalMap(m, d, q)
    K = np.linalg.solve(Ag[:, :6], Ag[:, 6:])
    for frame in ("a_link4", "b_link2", "base"):
        J = pin.computeFrameJacobian(m, d, q, m.getFrameId(frame), LWA)
        np.testing.assert_allclose(kin.generalized_jacobian(q, frame=frame), J[:, 6:] - J[:, :6] @ K, atol=1e-10)
    full = kin.generalized_jacobian(q, "B")
    cols = kin.generalized_jacobian(q, "B", arm_columns=True)
    assert cols.shape == (6, 7)
    np.testing.assert_array_equal(cols, full[:, eba.arm("B").j_idx])
    np.testing.assert_array_equal(eba.arm("B").j_idx, np.arange(7, 14))
    # the frame argument wins over the arm's EE, arm only selects the columns
    np.testing.assert_allclose(kin.generalized_jacobian(q, "A", frame="a_link4", arm_columns=True),
                               kin.generalized_jacobian(q, frame="a_link4")[:, :7], atol=1e-14)
    with pytest.raises(ValueError):
        kin.generalized_jacobian(q)
    with pytest.raises(ValueError):
        kin.generalized_jacobian(q, frame="a_ee", arm_columns=True)


def test_generalized_jacobians_match_per_arm_calls(eba, tcb, rng):
    for robot in (eba, tcb):
        kin = Kinematics(robot)
        for q, _ in _samples(robot, rng, 10):
            allj = kin.generalized_jacobians(q)
            assert set(allj) == set(robot.arms)
            for name in robot.arms:
                np.testing.assert_allclose(allj[name], kin.generalized_jacobian(q, name), rtol=0, atol=1e-12)
            # and a second call at another q does not reuse stale data
            q2 = robot.random_configuration(rng)
            kin.frame_placement(robot.random_configuration(rng), "a_ee")
            allj2 = kin.generalized_jacobians(q2)
            for name in robot.arms:
                np.testing.assert_allclose(allj2[name], Kinematics(robot).generalized_jacobian(q2, name),
                                           rtol=0, atol=1e-12)


def test_fixed_base_generalized_jacobian_is_the_frame_jacobian(tcb, rng):
    kin = Kinematics(tcb)
    for q, _ in _samples(tcb, rng, 10):
        for name, arm in tcb.arms.items():
            J = kin.frame_jacobian(q, arm.ee_frame, "world_aligned")
            assert J.shape == (6, 14)
            np.testing.assert_allclose(kin.generalized_jacobian(q, name), J, rtol=0, atol=1e-14)
            np.testing.assert_allclose(kin.generalized_jacobians(q)[name], J, rtol=0, atol=1e-14)
            # arm A's EE does not depend on arm B's joints
            other = tcb.arm("B" if name == "A" else "A")
            np.testing.assert_array_equal(J[:, other.j_idx], 0.0)


# --------------------------------------------------------------------------- placements, Jacobians
@pytest.mark.parametrize("reference", ["world_aligned", "local", "world"])
def test_frame_jacobian_matches_finite_differences(tcb, rng, reference):
    """Fixed base: J (each reference) against a central difference of the placement."""
    kin = Kinematics(tcb)
    q = tcb.random_configuration(rng)
    M0 = kin.frame_placement(q, "b_ee")
    J = kin.frame_jacobian(q, "b_ee", reference)
    h = 1e-6
    for i in range(tcb.nq):
        e = np.zeros(tcb.nq)
        e[i] = h
        Mp, Mm = kin.frame_placement(q + e, "b_ee"), kin.frame_placement(q - e, "b_ee")
        dp = (Mp.translation - Mm.translation) / (2 * h)
        w = pin.log3(Mp.rotation @ Mm.rotation.T) / (2 * h)  # world axes
        if reference == "world_aligned":
            expected = np.r_[dp, w]
        elif reference == "local":
            expected = np.r_[M0.rotation.T @ dp, M0.rotation.T @ w]
        else:  # spatial velocity at the world origin
            expected = np.r_[dp - np.cross(w, M0.translation), w]
        np.testing.assert_allclose(J[:, i], expected, atol=1e-8, err_msg=f"column {i}")


def test_frame_placements_equal_single_calls(eba, rng):
    kin = Kinematics(eba)
    q = eba.random_configuration(rng)
    frames = ["a_ee", "b_ee", "base", eba.model.getFrameId("a_link3")]
    many = kin.frame_placements(q, frames)
    for f, M in zip(frames, many):
        assert M.isApprox(kin.frame_placement(q, f), 1e-14)
    # returned placements are copies, not views into the shared data
    M = kin.frame_placement(q, "a_ee")
    kin.frame_placement(eba.random_configuration(rng), "a_ee")
    assert M.isApprox(many[0], 1e-14)


def test_returned_arrays_are_not_overwritten_by_later_calls(eba, rng):
    """Kinematics owns one pin.Data: results must be copies, not views into it."""
    kin = Kinematics(eba)
    q1, q2 = eba.random_configuration(rng), eba.random_configuration(rng)
    J1 = kin.frame_jacobian(q1, "a_ee")
    A1 = kin.centroidal_map(q1)
    G1 = kin.generalized_jacobians(q1)["A"]
    c1 = kin.center_of_mass(q1)
    J1c, A1c, G1c, c1c = J1.copy(), A1.copy(), G1.copy(), c1.copy()
    kin.frame_jacobian(q2, "a_ee")
    kin.centroidal_map(q2)
    kin.generalized_jacobians(q2)
    kin.generalized_jacobian(q2, "A")
    kin.center_of_mass(q2)
    np.testing.assert_array_equal(J1, J1c)
    np.testing.assert_array_equal(A1, A1c)
    np.testing.assert_array_equal(G1, G1c)
    np.testing.assert_array_equal(c1, c1c)
    # and the input configuration is not modified
    q1c = q1.copy()
    kin.generalized_jacobians(q1)
    kin.base_velocity(q1, np.ones(eba.nj))
    np.testing.assert_array_equal(q1, q1c)
