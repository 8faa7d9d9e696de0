"""LCBiRRT's lazy latent trees: the tree bookkeeping against hand-built trees, and the lazy validation of a branch
against the independent closed-chain and collision checks. Skipped without the optional extra ``learned``."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("optax")

from optplan.constraints.closed_chain import closure_error  # noqa: E402
from optplan.planners import make_planner  # noqa: E402
from optplan.planners.base import Deadline  # noqa: E402
from optplan.planners.learned.latent_lazy import LazyLatentTree, _validate  # noqa: E402
from optplan.trials import TrialGenerator  # noqa: E402

SMALL_LC = {"n_data": 3000, "cvae_epochs": 40, "n_model_samples": 150, "classifier_epochs": 20, "distance_epochs": 10,
            "classifier_threshold": 0.0}


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    mp.setenv("OPTPLAN_CACHE", str(tmp_path_factory.mktemp("optplan_cache")))
    yield
    mp.undo()


def test_lazy_tree_removes_a_subtree_and_never_offers_it_again():
    z0 = np.zeros(3)
    t = LazyLatentTree(z0, np.zeros(4), 0.9, cap=2)   # cap 2: the array grows
    a = t.add_latent(np.array([1.0, 0, 0]), 0.8, 0)
    b = t.add_latent(np.array([2.0, 0, 0]), 0.8, a)
    c = t.add_latent(np.array([3.0, 0, 0]), 0.8, b)
    d = t.add(np.array([0, 1.0, 0]), np.ones(4), 0.7, 0, [])
    assert t.checked == [True, False, False, False, True] and t.verified == [0, d]
    assert t.nearest(np.array([3.1, 0, 0])) == c and t.path_to(c) == [0, a, b, c]
    assert t.remove(b) == 2 and t.alive == [True, True, False, False, True]
    assert t.children[a] == [] and t.size() == 3
    assert t.nearest(np.array([3.1, 0, 0])) == a          # the removed branch is never the nearest
    assert t.nearest_q(np.full(4, 0.9)) == (d, pytest.approx(0.2))
    assert t.branch(d) == [t.Q[0], t.Q[d]]


def test_lazy_validation_keeps_valid_decodings_and_removes_the_first_failure(tcb, scene1, kin, checker, cache):
    """A branch root → n1 (a latent vector whose decoding is valid) → n2 (one whose decoding is not) → n3: n1 is
    validated (its configuration project(decode(z1)), on the chain and collision-free by the independent checks),
    n2 and n3 are removed, and the last valid node is n1."""
    pl = make_planner("lcbirrt", tcb, scene1, checker=checker, kinematics=kin, **SMALL_LC)
    q0 = TrialGenerator(tcb, scene1).generate(0, 0).q_goal
    rng = np.random.default_rng(0)
    dl = Deadline(60.0, "cpu")
    st = dict.fromkeys(("decodes", "projection_failures", "collisions", "edge_checks", "validations",
                        "validated_nodes", "validated_valid", "edge_failures", "validation_failures", "removed_nodes",
                        "lpo_nodes", "lpo_moves"), 0)
    z0 = pl.cvae.encode(q0)
    z1 = z2 = None
    for _ in range(200):
        z = z0 + 0.2 * rng.standard_normal(z0.shape)
        q = pl._config(z, z, z, st)
        if z1 is None and q is not None and pl._edge(q0, q, st, dl) is not None:
            z1, q1 = z, q
        z = 3.0 * rng.standard_normal(z0.shape)
        if z2 is None and pl._config(z, z, z, st) is None:
            z2 = z
    assert z1 is not None and z2 is not None
    t = LazyLatentTree(z0, q0, 1.0)
    n1 = t.add_latent(z1, 1.0, 0)
    n2 = t.add_latent(z2, 1.0, n1)
    n3 = t.add_latent(z2 + 0.1, 1.0, n2)
    ok, last = _validate(pl, t, n3, st, dl)
    assert (ok, last) == (False, n1)
    assert t.checked[n1] and t.verified == [0, n1] and np.array_equal(t.Q[n1], q1)
    assert max(closure_error(tcb, scene1.object.grasps, t.Q[n1])) <= 1e-6 and checker.is_valid(t.Q[n1])
    assert not t.alive[n2] and not t.alive[n3] and st["removed_nodes"] == 2
    assert st["validated_nodes"] == 2 and st["validated_valid"] == 1 and st["validation_failures"] == 1
    for q in t.branch(n1):   # every point of the validated branch on the chain and valid
        assert max(closure_error(tcb, scene1.object.grasps, q)) <= 1e-6 and checker.is_valid(q)
    assert _validate(pl, t, n1, st, dl) == (True, n1)   # a validated branch is not checked again
    assert st["validated_nodes"] == 2


def test_learned_ends_refuses_bad_arguments(capsys):
    from optplan.bench.learned_ends import main

    assert main(["--trials", "0"]) == 2
    assert main(["--data-task-fraction", "1.5"]) == 2
    assert "--data-task-fraction in [0, 1] (got 1.5)" in capsys.readouterr().err


def test_cdf_step_is_a_straight_line_in_the_prior_cdf():
    """Park et al.'s latent step: Φ of the interpolated vector is the same fraction of the way between Φ of the two
    ends, coordinate by coordinate (Φ from math.erf, independent of scipy's ndtr)."""
    import math

    from optplan.planners.learned.latent_lazy import _toward

    phi = np.vectorize(lambda x: 0.5 * (1.0 + math.erf(x / math.sqrt(2.0))))
    a, b = np.array([-2.0, 0.0, 0.5, 1.5]), np.array([1.0, 0.3, 0.5, -2.5])
    for r in (0.0, 0.1, 0.5, 1.0):
        z = _toward(a, b, r, "cdf")
        np.testing.assert_allclose(phi(z), (1 - r) * phi(a) + r * phi(b), atol=1e-12)
        np.testing.assert_allclose(_toward(a, b, r, "linear"), a + r * (b - a), atol=1e-15)
    z = _toward(a, b, 0.1, "cdf")
    assert np.all((z - a) * (b - a) >= 0)   # every coordinate moves toward the target


class _FakeLPO:
    """A stand-in planner whose decodings follow a script: 'p' a failed projection, 'c' a collision, 'v' valid."""

    class _Dist:
        def value_and_gradient(self, z):
            return 0.0, np.ones_like(z)

    def __init__(self, script, interval=3):
        import types

        self.options = types.SimpleNamespace(lpo_iterations=10, lpo_gamma=0.8, lpo_interval=interval)
        self.distance = self._Dist()
        self.script = list(script)
        self.calls = 0

    def _config(self, z, z_near, near, st):
        self.calls += 1
        what = self.script.pop(0)
        if what == "p":
            st["projection_failures"] += 1
            return None
        if what == "c":
            st["collisions"] += 1
            return None
        return z.copy()


def test_lpo_repair_stops_at_a_failed_projection_and_keeps_the_first_valid_step():
    from optplan.planners.learned.latent_lazy import _repair

    st = dict.fromkeys(("projection_failures", "collisions", "lpo_nodes", "lpo_moves"), 0)
    pl = _FakeLPO("ccv")
    z, q = _repair(pl, np.zeros(2), st)
    np.testing.assert_allclose(z, [2.4, 2.4])   # three steps of γ · ∇d = 0.8 · 1
    assert pl.calls == 3 and st["lpo_moves"] == 1
    pl = _FakeLPO("cpv")
    assert _repair(pl, np.zeros(2), st) is None and pl.calls == 2   # abandoned at the failed projection
    pl = _FakeLPO("c" * 10)
    assert _repair(pl, np.zeros(2), st) is None and pl.calls == 10   # N_max steps at most
    assert st["lpo_nodes"] == 3 and st["lpo_moves"] == 1


def test_lpo_repairs_every_interval_th_meeting_from_the_first(monkeypatch):
    import optplan.planners.learned.latent_lazy as LL

    flags = []
    monkeypatch.setattr(LL, "_validate", lambda pl, t, i, st, dl, repair=False: (flags.append(repair), (False, 0))[1])
    monkeypatch.setattr(LL, "_jump", lambda *a: None)
    st = {"meetings": 0, "lpo_checks": 0}
    pl = _FakeLPO("", interval=3)
    for _ in range(7):
        assert LL._join(pl, None, 0, None, 0, st, None, None) is None
    assert flags == [True, False, False, True, False, False, True] and st["lpo_checks"] == 3
    pl.distance = None   # LCBiRRT: never
    flags.clear()
    LL._join(pl, None, 0, None, 0, st, None, None)
    assert flags == [False]


def test_cdf_tree_measures_in_the_prior_cdf():
    """With the CDF metric the nearest node and the distance are those of Φ(z) (Park et al.'s ``distance_z``)."""
    import math

    t = LazyLatentTree(np.array([3.0]), np.zeros(2), 0.9, metric="cdf")
    t.add_latent(np.array([-0.5]), 0.9, 0)
    lin = LazyLatentTree(np.array([3.0]), np.zeros(2), 0.9)
    lin.add_latent(np.array([-0.5]), 0.9, 0)
    z = np.array([0.8])
    phi = [0.5 * (1.0 + math.erf(x / math.sqrt(2.0))) for x in (0.8, 3.0)]
    assert t.nearest(z) == 0 and lin.nearest(z) == 1
    assert t.distance(0, z) == pytest.approx(abs(phi[1] - phi[0]), abs=1e-12)
    assert lin.distance(0, z) == pytest.approx(2.2)
