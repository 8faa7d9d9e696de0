"""Free-floating simulation (optplan.model.floating.simulate_base) against physics it must obey:
momentum conservation, a fixed (or uniformly moving) centre of mass, path-dependence only
(driftless), 4th-order convergence, and the generalized Jacobian for small motions."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.model.floating import FloatingResult, joint_trajectory_from_samples, simulate_base
from optplan.model.kinematics import Kinematics

DEG = np.pi / 180.0
TOTAL_MASS = 593.58  # the EBA paper Table 2
# the EBA paper, Section 4.1 free-end case (same start for both arms)
Q0 = np.r_[[-23.44, -90, 12.51, 104.8, -27.33, 66.56, -38] * 2] * DEG
QF = np.r_[[-23.44, -80, -17.49, 134.8, -12.33, 111.56, -38],
           [-23.44, -180, 47.51, 144.8, 7.67, 86.56, -38]] * DEG
BEND = 0.3 * np.cos(np.arange(14))


def path(s):
    """A curved joint path q(s), s ∈ [0, 1], and dq/ds."""
    return (Q0 + (QF - Q0) * s + BEND * np.sin(np.pi * s),
            (QF - Q0) + BEND * np.pi * np.cos(np.pi * s))


def timed(T, law):
    """Trajectory t -> (q, q̇) following `path` with the time law s(t) on [0, T]."""
    def traj(t):
        tau = t / T
        if law == "quintic":
            s = 10 * tau ** 3 - 15 * tau ** 4 + 6 * tau ** 5
            sd = (30 * tau ** 2 - 60 * tau ** 3 + 30 * tau ** 4) / T
        elif law == "sin2":
            s = np.sin(np.pi * tau / 2) ** 2
            sd = np.pi / (2 * T) * np.sin(np.pi * tau)
        else:
            raise ValueError(law)
        q, dq = path(s)
        return q, dq * sd
    return traj


def random_quintic(rng, nj, T):
    """Independent random quintic polynomial per joint on [0, T]."""
    C = rng.normal(size=(6, nj)) * np.array([1.0, 0.5, 0.5, 0.3, 0.2, 0.1])[:, None]
    C[0] = Q0

    def traj(t):
        tau = t / T
        q = sum(C[k] * tau ** k for k in range(6))
        qd = sum(k * C[k] * tau ** (k - 1) for k in range(1, 6)) / T
        return q, qd
    return traj


def angle(R1, R2):
    return float(np.linalg.norm(pin.log3(R1.T @ R2)))


def random_base(rng):
    quat = rng.normal(size=4)
    return pin.XYZQUATToSE3(np.r_[rng.uniform(-1, 1, 3), quat / np.linalg.norm(quat)])


def _momentum(m, d, q, v):
    h = pin.computeCentroidalMomentum(m, d, q, v)
    return np.concatenate([h.linear, h.angular])


# --------------------------------------------------------------------------- (a) J* small motion
def test_generalized_jacobian_predicts_small_simulated_ee_motion(eba, rng):
    """q(t) = q0 + t δ on [0, ε]: the simulated EE displacement is J* δ ε + O(ε²) — the error
    shrinks 4× when ε halves (a wrong J* would leave an O(ε) error: ratio 2)."""
    kin = Kinematics(eba)
    q0j = eba.random_joints(rng)
    base0 = random_base(rng)
    delta = rng.normal(size=eba.nj)
    q0 = eba.configuration(q0j, base0)
    Js = kin.generalized_jacobians(q0)
    M0 = {a: kin.frame_placement(q0, arm.ee_frame) for a, arm in eba.arms.items()}

    def errors(eps):
        res = simulate_base(eba, lambda t: (q0j + t * delta, delta), [0.0, eps], base0=base0, substeps=4)
        np.testing.assert_allclose(res.q[-1, 7:], q0j + eps * delta, atol=1e-15)
        out = []
        for a, arm in eba.arms.items():
            M1 = kin.frame_placement(res.q[-1], arm.ee_frame)
            disp = np.r_[M1.translation - M0[a].translation, pin.log3(M1.rotation @ M0[a].rotation.T)]
            pred = Js[a] @ delta * eps
            out.append((np.linalg.norm(disp - pred), np.linalg.norm(pred)))
        return out

    e1, e2 = errors(2e-3), errors(1e-3)
    for (err1, _size1), (err2, size2) in zip(e1, e2):
        assert err2 < 2e-2 * size2  # first order right
        assert 3.6 < err1 / err2 < 4.4, (err1, err2)  # remainder is second order


# --------------------------------------------------------------------------- (b) momentum
@pytest.mark.parametrize("h0", [None, [0.1, 0.0, 0.0, 0.0, 0.0, 0.2], [0.3, -0.2, 0.5, 1.0, -2.0, 0.7]])
def test_momentum_is_conserved_along_a_random_quintic(eba, rng, h0):
    T = 10.0
    traj = random_quintic(rng, eba.nj, T)
    t = np.linspace(0, T, 101)
    res = simulate_base(eba, traj, t, base0=random_base(rng), h0=h0, substeps=2)
    assert isinstance(res, FloatingResult)
    assert res.q.shape == (101, 21) and res.v.shape == (101, 20) and res.momentum.shape == (101, 6)
    h_ref = np.zeros(6) if h0 is None else np.asarray(h0)
    m, d = eba.model, eba.model.createData()
    for k in range(len(t)):
        qj, qdj = traj(t[k])
        np.testing.assert_allclose(res.q[k, 7:], qj, atol=1e-14)
        np.testing.assert_allclose(res.v[k, 6:], qdj, atol=1e-14)
        assert abs(np.linalg.norm(res.q[k, 3:7]) - 1) < 1e-14
        h = _momentum(m, d, res.q[k], res.v[k])  # recursive algorithm, independent of the map
        assert np.abs(h - h_ref).max() <= 1e-9, (k, h)
    assert res.momentum_residual.max() <= 1e-9
    np.testing.assert_allclose(res.momentum, np.tile(h_ref, (len(t), 1)), atol=1e-9)


def test_recorded_base_twist_is_the_derivative_of_the_recorded_base_pose(eba, rng):
    """Central differences of the integrated base poses reproduce the recorded base twist (base
    frame), so the momentum computed from the *motion* is h0 as well — this checks that the
    integrator rotates the linear velocity into the world and integrates the quaternion right."""
    T, n = 10.0, 2001
    h0 = np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.2])
    traj = random_quintic(rng, eba.nj, T)
    t = np.linspace(0, T, n)
    res = simulate_base(eba, traj, t, base0=random_base(rng), h0=h0, substeps=1)
    dt = t[1] - t[0]
    m, d = eba.model, eba.model.createData()
    Ms = res.base_placements
    for k in range(1, n - 1, 100):
        vfd = pin.log6(Ms[k].actInv(Ms[k + 1])).vector - pin.log6(Ms[k].actInv(Ms[k - 1])).vector
        vfd /= 2 * dt
        scale = np.abs(res.v[k, :6]).max()
        np.testing.assert_allclose(vfd, res.v[k, :6], atol=1e-5 * scale)
        h = _momentum(m, d, res.q[k], np.r_[vfd, res.v[k, 6:]])
        np.testing.assert_allclose(h, h0, atol=1e-3 * np.abs(h0).max())


# --------------------------------------------------------------------------- (c) centre of mass
def test_center_of_mass_stays_fixed_with_zero_momentum(eba, rng):
    T = 5.0
    res = simulate_base(eba, timed(T, "quintic"), np.linspace(0, T, 51), base0=random_base(rng), substeps=4)
    m, d = eba.model, eba.model.createData()
    c = np.array([pin.centerOfMass(m, d, q) for q in res.q])
    assert np.abs(c - c[0]).max() <= 1e-9
    # and the base really moved (the test is not vacuous)
    assert np.linalg.norm(res.q[-1, :3] - res.q[0, :3]) > 1e-3


def test_center_of_mass_moves_uniformly_with_linear_momentum(eba, rng):
    T = 5.0
    p = np.array([0.3, -0.2, 0.5])
    h0 = np.r_[p, 1.0, -2.0, 0.7]
    t = np.linspace(0, T, 51)
    res = simulate_base(eba, timed(T, "quintic"), t, base0=random_base(rng), h0=h0, substeps=4)
    m, d = eba.model, eba.model.createData()
    c = np.array([pin.centerOfMass(m, d, q) for q in res.q])
    np.testing.assert_allclose(c - c[0], np.outer(t, p / TOTAL_MASS), rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- (d) driftless
DRIFTLESS_SUBSTEPS = 4  # with 40 output intervals: 160 RK4 steps per run


def test_final_base_pose_depends_on_the_path_not_its_timing(eba, rng):
    """Same joint path, T = 5 s with a quintic time law vs T = 300 s with s = sin²(πt/2T)."""
    base0 = random_base(rng)
    a = simulate_base(eba, timed(5.0, "quintic"), np.linspace(0, 5.0, 41), base0=base0,
                      substeps=DRIFTLESS_SUBSTEPS)
    b = simulate_base(eba, timed(300.0, "sin2"), np.linspace(0, 300.0, 41), base0=base0,
                      substeps=DRIFTLESS_SUBSTEPS)
    np.testing.assert_allclose(a.q[-1, 7:], b.q[-1, 7:], atol=1e-12)
    assert angle(a.final_base.rotation, b.final_base.rotation) <= 1e-8
    assert np.linalg.norm(a.final_base.translation - b.final_base.translation) <= 1e-8
    # the base did turn (about a degree), so the agreement is not trivial
    assert angle(base0.rotation, a.final_base.rotation) > 0.5 * DEG


def test_base_rotation_matches_the_seed_order_of_magnitude(eba):
    """conventions.md: the seed's path for 004 §4.1 under a 5th-order polynomial leaves the base at
    about a degree; here a straight joint path with a quintic law, T = 20 s (seed: 20 s)."""
    def traj(t):
        tau = t / 20.0
        s = 10 * tau ** 3 - 15 * tau ** 4 + 6 * tau ** 5
        sd = (30 * tau ** 2 - 60 * tau ** 3 + 30 * tau ** 4) / 20.0
        return Q0 + (QF - Q0) * s, (QF - Q0) * sd
    res = simulate_base(eba, traj, np.linspace(0, 20.0, 81), substeps=2)
    rpy = res.base_rpy[-1] / DEG
    # conventions.md quotes roughly (-0.64, 0.09, -1.31) deg under the adopted reading
    np.testing.assert_allclose(rpy, [-0.64, 0.09, -1.31], atol=0.02)


# --------------------------------------------------------------------------- (e) convergence
@pytest.mark.parametrize("T,law", [(5.0, "quintic"), (300.0, "sin2")])
def test_rk4_converges_with_fourth_order(eba, T, law):
    finals = []
    for n in (10, 20, 40):
        res = simulate_base(eba, timed(T, law), np.linspace(0, T, n + 1), substeps=1)
        finals.append(res.final_base)
    d1 = angle(finals[0].rotation, finals[1].rotation)
    d2 = angle(finals[1].rotation, finals[2].rotation)
    assert d2 > 1e-11  # well above round-off, so the ratio means something
    assert 12.0 < d1 / d2 < 20.0, (d1, d2)
    p1 = np.linalg.norm(finals[0].translation - finals[1].translation)
    p2 = np.linalg.norm(finals[1].translation - finals[2].translation)
    assert 12.0 < p1 / p2 < 20.0, (p1, p2)


def test_substeps_equal_a_finer_grid(eba):
    """substeps=k on a grid equals substeps=1 on the k-times finer grid (same RK4 steps)."""
    a = simulate_base(eba, timed(5.0, "quintic"), np.linspace(0, 5.0, 11), substeps=4)
    b = simulate_base(eba, timed(5.0, "quintic"), np.linspace(0, 5.0, 41), substeps=1)
    np.testing.assert_allclose(a.q[-1], b.q[-1], atol=1e-13)
    np.testing.assert_allclose(a.q, b.q[::4], atol=1e-13)


# --------------------------------------------------------------------------- inputs
def test_samples_trajectory_and_tuple_input(eba):
    T = 5.0
    t = np.linspace(0, T, 201)
    f = timed(T, "quintic")
    Q = np.array([f(tt)[0] for tt in t])
    Qd = np.array([f(tt)[1] for tt in t])
    traj = joint_trajectory_from_samples(t, Q, Qd)
    for tt in (0.0, 1.234, T):
        np.testing.assert_allclose(traj(tt)[0], f(tt)[0], atol=1e-6)
    ref = simulate_base(eba, f, np.linspace(0, T, 41), substeps=4)
    res = simulate_base(eba, (t, Q, Qd), np.linspace(0, T, 41), substeps=4)
    assert angle(res.final_base.rotation, ref.final_base.rotation) < 1e-6
    res2 = simulate_base(eba, (t, Q), np.linspace(0, T, 41), substeps=4)
    assert angle(res2.final_base.rotation, ref.final_base.rotation) < 1e-5


def test_zero_joint_motion_keeps_the_base_still(eba, rng):
    base0 = random_base(rng)
    qj = eba.random_joints(rng)
    res = simulate_base(eba, lambda t: (qj, np.zeros(eba.nj)), np.linspace(0, 3, 7), base0=base0)
    for M in res.base_placements:
        assert M.isApprox(base0, 1e-14)
    np.testing.assert_allclose(res.v, 0.0, atol=1e-15)


def test_zero_momentum_path_equals_the_general_integrator(eba, rng):
    """With zero momentum the base-frame twists are solved before the integration (they do not
    depend on the base pose) and the RK4 runs on plain floats: the result equals the general
    integrator's (a momentum of 1e-300 takes that path), for sampled and callable trajectories."""
    T = 8.0
    f = random_quintic(rng, eba.nj, T)
    t = np.linspace(0, T, 161)
    Q = np.array([f(tt)[0] for tt in t])
    Qd = np.array([f(tt)[1] for tt in t])
    base0 = random_base(rng)
    tiny = np.full(6, 1e-300)
    for traj in ((t, Q, Qd), f):
        a = simulate_base(eba, traj, t, base0=base0, substeps=2)
        b = simulate_base(eba, traj, t, base0=base0, substeps=2, h0=tiny)
        assert angle(a.final_base.rotation, base0.rotation) > 1e-3      # the base did turn
        np.testing.assert_allclose(a.q, b.q, atol=1e-13)
        np.testing.assert_allclose(a.v, b.v, atol=1e-13)
        np.testing.assert_allclose(a.momentum, b.momentum, atol=1e-12)


def test_without_the_momentum_cross_check_the_base_poses_are_the_same(eba, rng):
    """``momentum=False`` leaves out Pinocchio's recursive momentum at each sample (NaN), nothing
    else: the very same base poses and twists; with it the residual is at rounding."""
    T = 4.0
    t = np.linspace(0, T, 121)
    f = timed(T, "quintic")
    Q = np.array([f(tt)[0] for tt in t])
    Qd = np.array([f(tt)[1] for tt in t])
    base0 = random_base(rng)
    full = simulate_base(eba, (t, Q, Qd), t, base0=base0, substeps=2)
    fast = simulate_base(eba, (t, Q, Qd), t, base0=base0, substeps=2, momentum=False)
    assert np.array_equal(full.q, fast.q) and np.array_equal(full.v, fast.v)
    assert np.all(np.isnan(fast.momentum)) and np.all(np.isnan(fast.momentum_residual))
    assert float(full.momentum_residual.max()) < 1e-9
