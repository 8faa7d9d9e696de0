"""The CasADi recursive Newton-Euler (optplan.model.dynamics) against Pinocchio's numeric
algorithms: ``pinocchio.rnea`` for fixed bases, the floating-base equations (zero momentum, base
rows of ``M a + h`` solved to zero with ``crba``) for free-floating robots, the momentum rate for
the base reaction wrench, and finite differences for the CasADi Jacobian."""
from __future__ import annotations

import copy

import numpy as np
import pinocchio as pin
import pytest

from optplan.errors import ModelError
from optplan.model.dynamics import SymbolicDynamics
from optplan.model.robot import RobotModel

ROBOTS = ["tcbirrt_dual_arm", "dshdasr", "eba_ffsr", "splinerrt_ffsr"]
TOL = 1e-10


@pytest.fixture(scope="module", params=ROBOTS)
def robot_dyn(request):
    r = RobotModel.from_name(request.param)
    return r, SymbolicDynamics(r)


def _close(a, b, tol=TOL):
    """Agreement to ``tol`` relative to the magnitude (≥ 1) of the reference."""
    a, b = np.asarray(a, float).ravel(), np.asarray(b, float).ravel()
    return np.abs(a - b).max() <= tol * max(1.0, np.abs(b).max())


def _floating_reference(r: RobotModel, qj, vj, aj, base: pin.SE3):
    """Joint torques of a free-floating robot from Pinocchio: base twist from zero momentum
    (centroidal map), base acceleration from the base rows of M a + h = 0 (crba + rnea)."""
    m, d = r.model, r.model.createData()
    q = np.r_[pin.SE3ToXYZQUAT(base), qj]
    Ag = pin.computeCentroidalMap(m, d, q)
    vb = np.linalg.solve(Ag[:, :6], -Ag[:, 6:] @ vj)
    v = np.r_[vb, vj]
    M = pin.crba(m, d, q)
    M = np.triu(M) + np.triu(M, 1).T
    h = pin.rnea(m, d, q, v, np.zeros(m.nv))
    ab = -np.linalg.solve(M[:6, :6], M[:6, 6:] @ aj + h[:6])
    tau = pin.rnea(m, d, q, v, np.r_[ab, aj])
    assert np.abs(tau[:6]).max() < 1e-8 * max(1.0, np.abs(tau).max())   # the base wrench is zero
    return tau[6:], vb, ab


def test_rnea_matches_pinocchio(robot_dyn, rng):
    r, sd = robot_dyn
    m, d = r.model, r.model.createData()
    f = sd.rnea_function
    for _ in range(20):
        q = r.random_configuration(rng)
        v, a = rng.normal(size=m.nv) * 2, rng.normal(size=m.nv) * 5
        assert _close(f(q, v, a), pin.rnea(m, d, q, v, a))


def test_joint_torques_match_pinocchio(robot_dyn, rng):
    r, sd = robot_dyn
    m, d = r.model, r.model.createData()
    for _ in range(20):
        qj = r.random_joints(rng)
        vj, aj = rng.normal(size=r.nj) * 2, rng.normal(size=r.nj) * 5
        tau = np.array(sd.tau(qj, vj, aj)).ravel()
        if r.is_floating:
            base = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3))   # any base pose: same torques
            ref, _, _ = _floating_reference(r, qj, vj, aj, base)
            # the base state the torques were computed with (base at the identity, where the
            # base acceleration includes free fall under the model's gravity)
            _, vb, ab = _floating_reference(r, qj, vj, aj, pin.SE3.Identity())
            q, v, a = (np.array(x).ravel() for x in sd.floating_state_function(qj, vj, aj))
            assert _close(v[:6], vb, 1e-9) and _close(a[:6], ab, 1e-9)
        else:
            ref = pin.rnea(m, d, qj, vj, aj)
        assert _close(tau, ref)


def test_floating_torques_gravity_free(rng):
    """In free fall a uniform gravity changes no internal force: the torques are the same with
    gravity switched off (a physical law the recursion must respect)."""
    r = RobotModel.from_name("eba_ffsr")
    sd = SymbolicDynamics(r)
    qj, vj, aj = r.random_joints(rng), rng.normal(size=r.nj), rng.normal(size=r.nj)
    m0 = r.model.copy()
    m0.gravity = pin.Motion.Zero()
    r0 = copy.copy(r)
    r0.model = m0
    assert _close(SymbolicDynamics(r0).tau(qj, vj, aj), sd.tau(qj, vj, aj))


def test_base_reaction_wrench_momentum_rate(rng):
    """The wrench on the mount is −(ḣ − m g) (Pinocchio's centroidal momentum rate, moved to the
    world origin); at rest it is the weight."""
    r = RobotModel.from_name("tcbirrt_dual_arm")
    sd = SymbolicDynamics(r)
    m, d = r.model, r.model.createData()
    mass = pin.computeTotalMass(m)
    g = m.gravity.linear
    for _ in range(10):
        q, v, a = r.random_joints(rng), rng.normal(size=r.nj), rng.normal(size=r.nj)
        dh = pin.computeCentroidalMomentumTimeVariation(m, d, q, v, a)
        c = d.com[0]
        F = dh.linear - mass * g
        ref = -np.r_[F, dh.angular + np.cross(c, F)]
        assert _close(sd.base_reaction_wrench_function(q, v, a), ref)
    q = r.random_joints(rng)
    w = np.array(sd.base_reaction_wrench_function(q, np.zeros(r.nj), np.zeros(r.nj))).ravel()
    assert _close(w[:3], mass * g)


def test_jacobian_vs_finite_differences(robot_dyn, rng):
    import casadi as ca

    r, sd = robot_dyn
    nj = r.nj
    x = ca.SX.sym("x", 3 * nj)
    tau = sd.tau(x[:nj], x[nj:2 * nj], x[2 * nj:])
    jac = ca.Function("tau_jacobian", [x], [ca.jacobian(tau, x)])
    f = ca.Function("f", [x], [tau])
    x0 = np.r_[r.random_joints(rng), rng.normal(size=nj), rng.normal(size=nj)]
    Jc = np.array(jac(x0))
    eps = 1e-6
    Jfd = np.column_stack([(np.array(f(x0 + eps * e)).ravel() - np.array(f(x0 - eps * e)).ravel()) / (2 * eps)
                           for e in np.eye(3 * nj)])
    assert np.abs(Jc - Jfd).max() <= 1e-5 * max(1.0, np.abs(Jfd).max())


def test_fixed_base_wrench_refused_on_floating():
    sd = SymbolicDynamics(RobotModel.from_name("eba_ffsr"))
    with pytest.raises(ModelError, match="free-floating"):
        _ = sd.base_reaction_wrench_function
