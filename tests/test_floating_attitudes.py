"""The vectorised zero-momentum base attitudes of the dense check between knots
(optplan.model.floating.attitudes_on_intervals, zero_momentum_twists) against the
step-by-step simulation :func:`simulate_base` and momentum conservation."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan import RobotModel
from optplan.model.floating import attitudes_on_intervals, simulate_base, zero_momentum_twists


@pytest.fixture(scope="module")
def eba():
    return RobotModel.from_name("eba_ffsr")


def _poly(rng, nj, T):
    """A random quintic per joint on [0, T], vectorised over times: t -> (q, q̇) (M × nj)."""
    C = rng.normal(size=(6, nj)) * np.array([1.0, 0.5, 0.5, 0.3, 0.2, 0.1])[:, None]

    def traj(t):
        tau = np.atleast_1d(np.asarray(t, float))[:, None] / T
        q = sum(C[k] * tau ** k for k in range(6))
        qd = sum(k * C[k] * tau ** (k - 1) for k in range(1, 6)) / T
        return q, qd
    return traj


def _random_quat(rng):
    v = rng.normal(size=4)
    return v / np.linalg.norm(v)


def test_twists_conserve_zero_momentum_at_any_base_placement(eba):
    rng = np.random.default_rng(3)
    q = rng.uniform(-2, 2, size=(6, eba.nj))
    qd = rng.normal(size=(6, eba.nj))
    V = zero_momentum_twists(eba, q, qd)
    data = eba.model.createData()
    for i in range(6):
        x = _random_quat(rng)
        base = pin.SE3(pin.Quaternion(x[3], *x[:3]).toRotationMatrix(), rng.normal(size=3))
        h = pin.computeCentroidalMomentum(eba.model, data, eba.configuration(q[i], base), np.r_[V[i], qd[i]])
        assert np.abs(np.r_[h.linear, h.angular]).max() < 1e-9 * (1 + np.abs(qd[i]).max())
        assert np.abs(V[i]).max() > 1e-3          # the arms do move the base


@pytest.mark.parametrize("M", [16, 37, 300])
def test_compiled_twists_match_pinocchio_s_centroidal_map(eba, M):
    """Many states at once (the compiled map over chunks, the last padded) against Pinocchio's
    centroidal map per state, and zero momentum by Pinocchio's recursive algorithm."""
    from optplan.model import floating

    rng = np.random.default_rng(11 + M)
    q = rng.uniform(eba.lower, eba.upper, size=(M, eba.nj))
    qd = rng.normal(size=(M, eba.nj))
    V = zero_momentum_twists(eba, q, qd)
    ref = zero_momentum_twists(eba, q, qd, compiled=False)
    if floating._twist_kernels(eba) is None:
        pytest.skip("no C compiler: the twists are Pinocchio's")
    assert np.abs(V - ref).max() <= 1e-10 * (1 + np.abs(ref).max())
    data = eba.model.createData()
    for i in rng.choice(M, size=8, replace=False):
        x = _random_quat(rng)
        base = pin.SE3(pin.Quaternion(x[3], *x[:3]).toRotationMatrix(), rng.normal(size=3))
        h = pin.computeCentroidalMomentum(eba.model, data, eba.configuration(q[i], base), np.r_[V[i], qd[i]])
        assert np.abs(np.r_[h.linear, h.angular]).max() < 1e-9 * (1 + np.abs(qd[i]).max())


def test_attitudes_match_simulate_base_per_interval(eba):
    rng = np.random.default_rng(7)
    K, density, T = 5, 4, 6.0
    traj = _poly(rng, eba.nj, T)
    t = np.linspace(0.0, T, K * density + 1)
    quat0 = np.array([_random_quat(rng) for _ in range(K + 1)])
    got = attitudes_on_intervals(eba, traj, t, quat0, density, substeps=2)
    for k in range(K):
        x = quat0[k]
        base0 = pin.SE3(pin.Quaternion(x[3], *x[:3]).toRotationMatrix(), np.zeros(3))
        ref = simulate_base(eba, lambda tt: tuple(a[0] for a in traj(tt)), t[k * density:(k + 1) * density + 1],
                            base0=base0, substeps=2)
        # the quaternion's sign is free: compare rotations
        for j in range(density):
            a, b = got[k * density + j], ref.q[j, 3:7]
            assert min(np.abs(a - b).max(), np.abs(a + b).max()) < 1e-12
        assert np.abs(ref.q[-1, 3:7] - quat0[k]).max() > 1e-3    # the base turned over the interval
    assert np.allclose(got[-1], quat0[-1])


def test_attitudes_reject_a_grid_that_does_not_fit(eba):
    from optplan.errors import ConfigurationError

    with pytest.raises(ConfigurationError, match="intervals"):
        attitudes_on_intervals(eba, _poly(np.random.default_rng(0), eba.nj, 1.0), np.linspace(0, 1, 7),
                               np.tile([0, 0, 0, 1.0], (3, 1)), 4)


@pytest.mark.parametrize("M", [16, 37, 300])
def test_compiled_angular_rates_match_pinocchio(eba, M):
    """The kernel of ω alone (Schur complement of the base's linear rows) against Pinocchio's
    centroidal map and a 6 × 6 solve per state, to 1e-12."""
    from optplan.model import floating

    rng = np.random.default_rng(29 + M)
    q = rng.uniform(eba.lower, eba.upper, size=(M, eba.nj))
    qd = rng.normal(size=(M, eba.nj))
    if floating._twist_kernels(eba, "omega") is None:
        pytest.skip("no C compiler: the rates are Pinocchio's")
    W = floating.zero_momentum_rates(eba, q, qd)
    ref = zero_momentum_twists(eba, q, qd, compiled=False)[:, 3:]
    assert W.shape == (M, 3)
    assert np.abs(W - ref).max() <= 1e-12 * (1 + np.abs(ref).max())


def test_dense_check_reuses_attitudes_only_for_identical_inputs(eba):
    """The dense check's attitudes are reused only when every input is the same bit for bit; a
    changed solution is integrated again (and agrees with a fresh integration)."""
    from types import SimpleNamespace

    from optplan.problem import guarantees as G

    rng = np.random.default_rng(5)
    K, density = 4, 5
    t = np.linspace(0.0, 4.0, K + 1)
    n = eba.nj
    sol = SimpleNamespace(t=t, q=rng.normal(size=(K + 1, n)) * 0.3, qd=rng.normal(size=(K + 1, n)) * 0.1,
                          qdd=rng.normal(size=(K + 1, n)) * 0.05, jerk=rng.normal(size=(K, n)) * 0.01,
                          base_quat=np.array([_random_quat(rng) for _ in range(K + 1)]))

    def sample(ts):
        k = np.clip((ts / 1.0).astype(int), 0, K - 1)
        tau = (ts - sol.t[k])[:, None]
        return {"q": sol.q[k] + tau * sol.qd[k] + tau**2 / 2 * sol.qdd[k] + tau**3 / 6 * sol.jerk[k],
                "qd": sol.qd[k] + tau * sol.qdd[k] + tau**2 / 2 * sol.jerk[k]}
    sol.sample = sample
    ts = np.linspace(0.0, 4.0, K * density + 1)
    G._ATTITUDES.clear()
    a = G._base_attitudes(eba, sol, ts, density)
    a[:] = np.nan                                   # the caller's copy: the kept one is untouched
    b = G._base_attitudes(eba, sol, ts, density)
    assert np.isfinite(b).all()
    sol.qd = sol.qd.copy()
    sol.qd[2, 0] += 1e-3                            # one input changed: integrated again
    c = G._base_attitudes(eba, sol, ts, density)
    G._ATTITUDES.clear()
    fresh = G._base_attitudes(eba, sol, ts, density)
    assert np.array_equal(c, fresh) and not np.allclose(b, c, atol=1e-9, rtol=0)


def test_compiled_base_frame_coms_match_pinocchio(eba):
    """The compiled centre of mass in the base frame (the dense check's configurations) against
    Pinocchio's centerOfMass per state, to 1e-12; too few rows: None (Pinocchio per row)."""
    from optplan.model.floating import _twist_kernels, base_frame_coms

    rng = np.random.default_rng(31)
    q = rng.uniform(eba.lower, eba.upper, size=(40, eba.nj))
    assert base_frame_coms(eba, q[:3]) is None
    if _twist_kernels(eba, "com") is None:
        pytest.skip("no C compiler: the centres of mass are Pinocchio's")
    c = base_frame_coms(eba, q)
    data = eba.model.createData()
    ref = np.array([pin.centerOfMass(eba.model, data, eba.configuration(qi)) for qi in q])
    assert c.shape == (40, 3)
    assert np.abs(c - ref).max() <= 1e-12
