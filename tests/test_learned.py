"""The learned baselines (CVAE latent sampling, LCBiRRT, LCBiRRT-LPO): networks against JAX,
grids against exact coal distances, the CVAE's decoded samples against uniform joints by the
independent closed-chain and collision checks, the cache, and the planners' paths. Skipped without
the optional extra ``learned``."""
from __future__ import annotations

import coal
import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("optax")

from optplan.collision.checker import CollisionChecker  # noqa: E402
from optplan.constraints.closed_chain import IKSettings, closure_error  # noqa: E402
from optplan.planners import PlanStatus, make_planner  # noqa: E402
from optplan.planners.learned.cvae import CVAE, CVAESettings, load_or_train_cvae, validate_cvae  # noqa: E402
from optplan.planners.learned.latent_models import scene_grid  # noqa: E402
from optplan.planners.learned.latent_planners import LCBiRRTOptions  # noqa: E402
from optplan.planners.learned.nets import flatten_params, init_mlp, mlp_jax, mlp_numpy, unflatten_params  # noqa: E402
from optplan.planners.task_space import interpolate_task  # noqa: E402
from optplan.trials import TrialGenerator  # noqa: E402

SMALL = {"n_data": 3000, "cvae_epochs": 40}
# the small classifier of a test is not trusted to filter (threshold 0): the test is about the paths
SMALL_LC = {**SMALL, "n_model_samples": 150, "classifier_epochs": 20, "distance_epochs": 10, "classifier_threshold": 0.0}


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    d = tmp_path_factory.mktemp("optplan_cache")
    mp.setenv("OPTPLAN_CACHE", str(d))
    yield d
    mp.undo()


@pytest.fixture(scope="module")
def cvae(tcb, scene1, kin, checker, cache) -> CVAE:
    return load_or_train_cvae(tcb, scene1, CVAESettings(n_data=SMALL["n_data"], epochs=SMALL["cvae_epochs"]),
                              checker=checker, kinematics=kin)


@pytest.mark.parametrize("act", ["relu", "leaky_relu", "elu", "linear"])
def test_numpy_forward_matches_jax_and_round_trips(act):
    p = init_mlp([5, 7, 7, 3], seed=2)
    x = np.random.default_rng(0).normal(size=(4, 5))
    ref = np.asarray(mlp_jax(p, x.astype(np.float32), act))
    assert np.allclose(mlp_numpy(p, x, act), ref, atol=1e-4)
    back = unflatten_params("n", flatten_params("n", p))
    assert all(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) for a, b in zip(p, back))


def test_scene_grid_sdf_matches_coal(scene1):
    sdf = scene_grid(scene1, "sdf", n=8)
    occ = scene_grid(scene1, "occupancy", n=8)
    assert sdf.shape == occ.shape == (512,)
    assert np.array_equal(occ > 0, sdf <= 0)
    lo, hi = np.array([-3.0, -4.0, -1.0]), np.array([3.0, 4.0, 5.0])   # the ξ box ± 1 m
    axes = [lo[k] + (np.arange(8) + 0.5) * (hi[k] - lo[k]) / 8 for k in range(3)]
    P = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    ball = coal.Sphere(1e-9)
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    for k in np.random.default_rng(0).choice(len(P), 40, replace=False):
        if sdf[k] <= 0 or sdf[k] >= 5.0:
            continue
        d = np.inf
        for o in scene1.obstacles:
            res.clear()
            M = o.placement
            d = min(d, coal.distance(ball, coal.Transform3s(np.eye(3), P[k]), o.coal_geometry(),
                                     coal.Transform3s(M.rotation, M.translation), req, res))
        assert abs(d - sdf[k]) < 1e-5


def test_cvae_decodes_near_the_manifold_and_is_cached(tcb, scene1, kin, checker, cvae, cache):
    h = cvae.history
    assert len(h["train_loss"]) == SMALL["cvae_epochs"] and h["val_loss"][-1] < h["val_loss"][0]
    m = cvae.metrics
    dec, uni = m["decoded_prior"], m["uniform_joints"]
    # decoded prior samples lie nearer the manifold than uniform joints and more of them project and are valid
    assert dec["median_residual_before"] < uni["median_residual_before"]
    assert dec["valid_rate"] > uni["valid_rate"] and dec["projection_rate"] > uni["projection_rate"]
    # the same figures recomputed independently: Pinocchio closure error and exact coal distances
    again = validate_cvae(cvae, tcb, scene1, kin, checker, n=100, seed=3)
    assert again["decoded_prior"]["valid_rate"] > again["uniform_joints"]["valid_rate"]
    Q = np.random.default_rng(0).uniform(tcb.lower, tcb.upper, (3, tcb.nq))
    assert np.allclose(cvae.decode(cvae.encode(Q)).shape, Q.shape)
    assert cvae.path is not None and cvae.path.exists()
    loaded = load_or_train_cvae(tcb, scene1, CVAESettings(n_data=SMALL["n_data"], epochs=SMALL["cvae_epochs"]),
                                checker=checker, kinematics=kin)
    z = np.random.default_rng(1).normal(size=(5, cvae.latent_dim))
    assert loaded.path == cvae.path and np.allclose(loaded.decode(z), cvae.decode(z))


def test_settings_are_validated():
    for bad in ({"epochs": 0}, {"activation": "tanh"}, {"val_fraction": 0.7}, {"kl_weight": -1.0}, {"augment": 1}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            CVAESettings(**bad)
    for bad in ({"latent_step": 0.0}, {"classifier_threshold": 1.0}, {"lpo_interval": 0}, {"lpo": "yes"},
                {"cvae_epochs": 0}, {"lpo_clearance": -1.0}, {"data_task_fraction": 1.5},
                {"latent_interpolation": "spline"}, {"random_growth": 1.5}, {"random_growth": True}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            LCBiRRTOptions(**bad)
    with pytest.raises(ValueError, match="data_task_fraction"):
        CVAESettings(data_task_fraction=-0.5)
    with pytest.raises(ValueError, match="data_region_fraction \\+ data_task_fraction"):
        LCBiRRTOptions(data_region_fraction=0.5, data_task_fraction=0.6)


def test_path_coverage_matches_brute_force_nearest_distances():
    """The coverage measurement's k-d tree distances equal the brute-force nearest distances (numpy)."""
    from optplan.bench.learned_coverage import coverage_table, path_coverage

    rng = np.random.default_rng(5)
    Q = rng.uniform(-3, 3, (400, 14))
    paths = [rng.uniform(-3, 3, (n, 14)) for n in (7, 12)]
    masks = [np.arange(7) % 2 == 0, np.ones(12, bool)]
    for mk in (None, masks):
        got = path_coverage(Q, paths, mk)
        for k, P in enumerate(paths):
            d = np.linalg.norm(P[:, None, :] - Q[None], axis=2).min(axis=1)
            m = d if mk is None else d[mk[k]]
            assert got[k]["start"] == pytest.approx(d[0]) and got[k]["goal"] == pytest.approx(d[-1])
            assert got[k]["median"] == pytest.approx(np.median(m)) and got[k]["max"] == pytest.approx(m.max())
    assert "2" in coverage_table({"x": path_coverage(Q, paths)}).splitlines()[1]


@pytest.fixture(scope="module")
def query(tcb, scene1, kin, checker):
    """Trial 0's start and a valid goal 0.3 m above it (IK continuation)."""
    t = TrialGenerator(tcb, scene1).generate(0, 0)
    M = t.object_start
    for off in ([0, 0, 0.3], [0, 0, -0.3], [0.3, 0, 0], [-0.3, 0, 0]):
        q = t.q_start
        for R, p in interpolate_task(M.rotation, M.translation, M.rotation, M.translation + np.array(off, float), 10):
            q, _ = kin.ik(q, R, p, IKSettings())
            if q is None or not checker.is_valid(q):
                break
        if q is not None and checker.is_valid(q):
            return t.q_start, q
    pytest.fail("no valid goal near the start")


@pytest.mark.parametrize("name", ["latent-sampling",
                                  # a query may use its whole 60 s CPU limit on 2 loaded cores
                                  pytest.param("lcbirrt", marks=pytest.mark.slow),
                                  pytest.param("lcbirrt-lpo", marks=pytest.mark.slow)])
def test_learned_planners_return_valid_closed_chain_paths(tcb, scene1, kin, checker, cache, query, name):
    opts = SMALL if name == "latent-sampling" else SMALL_LC
    pl = make_planner(name, tcb, scene1, checker=checker, kinematics=kin, **opts)
    assert pl.name == name
    qs, qg = query
    res = pl.plan(qs, qg, time_limit=60.0, seed=4, clock="cpu")
    assert res.status is PlanStatus.EXACT, res.message
    assert np.allclose(res.path[0], qs) and np.allclose(res.path[-1], qg)
    exact = CollisionChecker(tcb, scene1)
    for q in res.path:
        assert max(closure_error(tcb, scene1.object.grasps, q)) <= 1e-6
        assert exact.min_distance(q)[0] > 0.0
    assert np.linalg.norm(np.diff(res.path, axis=0), axis=1).max() <= 0.6 + 1e-9
    assert np.array_equal(pl.plan(qs, qg, time_limit=60.0, seed=4, clock="cpu").path, res.path)
    off = qs.copy()
    off[0] += 0.3
    assert pl.plan(off, qg).status is PlanStatus.INVALID_START


def test_unknown_learned_option_is_an_error(tcb, scene1, checker, kin):
    from optplan.errors import OptionError

    with pytest.raises(OptionError, match="lpo"):
        make_planner("lcbirrt", tcb, scene1, checker=checker, kinematics=kin, lpo=True)


@pytest.fixture(scope="module")
def distance_model(tcb, scene1, kin, checker, cvae, cache):
    from optplan.planners.learned.latent_models import LatentModelSettings, load_or_train_distance
    from optplan.planners.manifold_samples import ManifoldSampleSettings, manifold_samples

    data = manifold_samples(tcb, scene1, ManifoldSampleSettings(n=SMALL["n_data"], seed=0), checker=checker,
                            kinematics=kin)
    s = LatentModelSettings(n_distance=300, distance_epochs=40, patience=10)
    return load_or_train_distance(tcb, scene1, cvae, kin, checker, data.Q, s), data.Q


def test_learned_distance_predicts_exact_distances_on_fresh_configurations(tcb, scene1, kin, checker, cvae,
                                                                           distance_model):
    from optplan.planners.manifold_samples import project_onto_chain

    model, Q = distance_model
    held = model.meta["held_out"]
    assert model.meta["epochs_run"] <= 40 and 1 <= model.meta["best_epoch"] <= model.meta["epochs_run"]
    assert held["corr"] > 0.2, model.meta
    # independent: fresh on-manifold configurations (not in the training rows), exact coal distances
    rng = np.random.default_rng(123)
    exact = CollisionChecker(tcb, scene1)
    X, d = [], []
    while len(X) < 150:
        x = project_onto_chain(kin, np.clip(Q[int(rng.integers(len(Q)))] + rng.normal(0, 0.3, tcb.nq), tcb.lower,
                                            tcb.upper), tcb.lower, tcb.upper)
        if x is not None:
            X.append(x)
            d.append(float(np.clip(exact.min_distance(x)[0], -0.2, 0.5)))
    pred = model.distance(cvae.encode(np.array(X)))
    assert np.corrcoef(pred, d)[0, 1] > 0.2
    # the gradient (JAX, scaled back to metres) against central finite differences of the numpy prediction
    z = cvae.encode(np.array(X[:1]))[0]
    g = model.gradient(z)
    fd = np.array([(model.distance(z + 1e-4 * e) - model.distance(z - 1e-4 * e)) / 2e-4 for e in np.eye(len(z))])
    assert np.allclose(g, fd, rtol=1e-3, atol=1e-5)


def test_fixed_encoder_is_cached_as_its_features(tcb, scene1, kin, checker, cvae, distance_model):
    from optplan.planners.learned.latent_models import LatentDistance

    model, _ = distance_model
    assert model.path is not None and model.meta["encoder_trained"] is False
    with np.load(model.path) as z:
        assert "enc_W0" not in z and z["features"].shape == (16,)
    loaded = LatentDistance.load(model.path, scene_grid(scene1, "sdf"))
    Z = np.random.default_rng(2).normal(size=(4, cvae.latent_dim))
    assert np.allclose(loaded.distance(Z), model.distance(Z))


def test_classifier_beats_chance_on_held_out_latent_samples(tcb, scene1, kin, checker, cvae, distance_model):
    from optplan.planners.learned.latent_models import LatentModelSettings, load_or_train_classifier

    _, Q = distance_model
    s = LatentModelSettings(n_classifier=300, classifier_epochs=60, patience=10)
    clf = load_or_train_classifier(tcb, scene1, cvae, kin, checker, s, samples=Q)
    m = clf.meta
    assert m["n_valid"] == m["n_invalid"] == 300        # balanced: chance is 0.5
    assert m["held_out"]["accuracy"] > 0.6, m


class _RefusingClassifier:
    """A classifier that scores every latent vector invalid (the gating logic under test, not a model)."""

    def probability(self, z):
        return np.zeros(np.shape(z)[:-1]) if np.ndim(z) > 1 else 0.0


def test_classifier_does_not_veto_steps_out_of_a_verified_node(tcb, scene1, kin, checker, cache, query):
    """Where the classifier scores a tree's verified node invalid, a step out of it is decided by the
    decode + projection + collision check: with a classifier that refuses everything, the trees still
    grow (every step checked for real); the strict setting never grows them."""
    import dataclasses

    qs, qg = query
    pl = make_planner("lcbirrt", tcb, scene1, checker=checker, kinematics=kin,
                      **{**SMALL_LC, "classifier_threshold": 0.5, "max_iterations": 20})
    pl.classifier = _RefusingClassifier()
    res = pl.plan(qs, qg, time_limit=60.0, seed=1, clock="cpu")
    st = res.stats
    assert st["classifier_rejects"] == 0 and st["classifier_overruled"] > 0 and st["decodes"] > 0
    assert st["nodes"] > 2 or res.status is PlanStatus.EXACT, st
    assert st["start_tree_nodes"] + st["goal_tree_nodes"] == st["nodes"]
    assert st["start_root_probability"] == st["goal_root_probability"] == 0.0
    pl.options = dataclasses.replace(pl.options, classifier_trusts_verified=False)
    strict = pl.plan(qs, qg, time_limit=60.0, seed=1, clock="cpu").stats
    assert strict["start_tree_nodes"] == strict["goal_tree_nodes"] == 1
    assert strict["classifier_rejects"] > 0 and strict["decodes"] == 0
    with pytest.raises(ValueError, match="classifier_trusts_verified"):
        LCBiRRTOptions(classifier_trusts_verified=1)


@pytest.mark.parametrize("name", ["latent-sampling", "lcbirrt", "lcbirrt-lpo"])
def test_learned_planners_respect_the_cpu_time_limit(tcb, scene1, kin, checker, cache, deadline_gaps, name):
    """Trial 0 (a hard query) at 0.4 s of CPU: deadline looked at every < 0.1 s, returned within 0.1 s."""
    t = TrialGenerator(tcb, scene1).generate(0, 0)
    pl = make_planner(name, tcb, scene1, checker=checker, kinematics=kin,
                      **(SMALL if name == "latent-sampling" else SMALL_LC))
    gaps = deadline_gaps()
    res = pl.plan(t.q_start, t.q_goal, time_limit=0.4, seed=3, clock="cpu")
    assert res.status in (PlanStatus.TIMEOUT, PlanStatus.EXACT), res.message
    assert gaps and max(gaps) < 0.1 and res.stats["cpu_time_s"] <= 0.5, (max(gaps), res.stats)


def test_lcbirrt_trees_meeting_in_latent_space_meet_in_joint_space(tcb, scene1, kin, checker, cache, query):
    """A latent node's configuration is project(decode(z)) in either tree, so where the start tree and the goal
    tree reach the same latent vector they hold the same configuration and the link is that point; with a
    per-tree decoding offset (anchored_decoding) the two configurations differ."""
    import dataclasses

    from optplan.planners.base import Deadline
    from optplan.planners.learned.latent_planners import _LatentTree

    qs, qg = query
    pl = make_planner("lcbirrt", tcb, scene1, checker=checker, kinematics=kin, **{**SMALL_LC, "max_extend_steps": 60})
    rng = np.random.default_rng(0)
    zs, zg = pl.cvae.encode(qs), pl.cvae.encode(qg)
    results = {}
    for anchored in (False, True):
        pl.options = dataclasses.replace(pl.options, anchored_decoding=anchored, lazy=False)
        for _ in range(40):   # a shared target between the two roots whose decoding is valid
            z = 0.5 * (zs + zg) + 0.3 * rng.standard_normal(zs.shape)
            st = dict.fromkeys(("decodes", "projection_failures", "collisions"), 0)
            if pl._config(z, z, pl.cvae.decode(z), st) is not None:
                break
        st = {k: 0 for k in ("decodes", "projection_failures", "collisions", "classifier_rejects", "classifier_overruled",
                             "edge_checks", "latent_jumps", "jump_nodes", "link_attempts", "q_link_attempts",
                             "link_successes", "lpo_nodes", "lpo_moves")}
        st["link_gap_min"] = np.inf
        ta, tb = _LatentTree(zs, qs, 1.0), _LatentTree(zg, qg, 1.0)
        dl = Deadline(60.0, "cpu")
        ra, ia = pl.extend(ta, 0, z, st, dl)
        rb, ib = pl.extend(tb, 0, z, st, dl)
        assert ra and rb, st
        assert np.array_equal(ta.Z[ia], tb.Z[ib])
        results[anchored] = float(np.linalg.norm(ta.Q[ia] - tb.Q[ib]))
        if not anchored:
            assert ta.decoded[ia] and tb.decoded[ib]
            link = pl._link(ta, ia, tb, ib, st, dl)
            assert link is not None and link[2] == [] and st["link_successes"] == 1
            for tree, i in ((ta, ia), (tb, ib)):   # every branch point on the chain and valid
                for q in tree.branch(i):
                    assert max(closure_error(tcb, scene1.object.grasps, q)) <= 1e-6 and checker.is_valid(q)
    assert results[False] == 0.0
    assert results[True] > 1e-3, results
