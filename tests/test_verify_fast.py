"""The fast paths of verification and projection against their references: the exact clearance
along a sampled trajectory (pruned by sweep bounds) against every row; the batched closure errors
against the per-configuration Pinocchio check; the compiled closed-chain residual and Jacobian
against Pinocchio's; the sweep bound against the real displacement of geometry points."""
import numpy as np
import pinocchio as pin
import pytest

from optplan.collision.checker import CollisionChecker
from optplan.collision.sweep import sweep_weights
from optplan.constraints import closed_chain as ccm
from optplan.constraints.closed_chain import (
    ChainSpec,
    ClosedChainKinematics,
    closed_chain_residual,
    closure_error,
    closure_errors,
    project_closed_chain,
)
from optplan.planners.validity import ValidityChecker
from optplan.scene import Scene


@pytest.fixture(scope="module")
def scene1():
    return Scene.load("ssps_scene1")


def _smooth_path(robot, rng, q0, n=201, scale=0.6):
    """A smooth random joint path from ``q0`` (sum of a few sines per joint)."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    amp = rng.normal(scale=scale, size=(3, robot.nq))
    Q = q0 + sum(amp[k] * np.sin((k + 1) * np.pi * t) / (k + 1) for k in range(3))
    return np.clip(Q, robot.lower, robot.upper)


def test_sweep_weights_bound_every_point_displacement(tcb, rng):
    W = sweep_weights(tcb.model, tcb.collision_model)
    data, gdata = tcb.model.createData(), pin.GeometryData(tcb.collision_model)
    gd2 = pin.GeometryData(tcb.collision_model)
    data2 = tcb.model.createData()
    worst = 0.0
    for _ in range(200):
        q1 = tcb.random_configuration(rng)
        q2 = np.clip(q1 + rng.normal(scale=0.3, size=tcb.nq), tcb.lower, tcb.upper)
        pin.updateGeometryPlacements(tcb.model, data, tcb.collision_model, gdata, q1)
        pin.updateGeometryPlacements(tcb.model, data2, tcb.collision_model, gd2, q2)
        bound = W @ np.abs(q2 - q1)
        for g, go in enumerate(tcb.collision_model.geometryObjects):
            go.geometry.computeLocalAABB()
            lo, hi = np.asarray(go.geometry.aabb_local.min_), np.asarray(go.geometry.aabb_local.max_)
            pts = lo + rng.random((8, 3)) * (hi - lo)         # points of the geometry's box, local frame
            d = max(np.linalg.norm(gd2.oMg[g].act(p) - gdata.oMg[g].act(p)) for p in pts)
            assert d <= bound[g] + 1e-12
            if bound[g] > 0:
                worst = max(worst, d / bound[g])
    assert worst > 0.2          # the bound is not vacuous


def test_validity_checker_rows_are_the_shared_sweep_weights(tcb, scene1):
    vc = ValidityChecker(tcb, scene1)
    W = sweep_weights(tcb.model, vc.gmodel)
    for mode in ("held", "fixed", "free"):
        np.testing.assert_array_equal(vc.sweep_weights(mode, per_geometry=True), W[vc._moving_geometries(mode)])


@pytest.mark.parametrize("collide", [False, True])
def test_min_distance_along_is_the_exact_minimum(tcb, scene1, rng, collide):
    chk = CollisionChecker(tcb, scene1)
    q0 = np.zeros(tcb.nq)
    for _ in range(3):
        Q = _smooth_path(tcb, rng, q0, scale=1.5 if collide else 0.3)
        ref = [chk.min_distance(q) for q in Q]
        i = int(np.argmin([d for d, _ in ref]))
        d, pair, n = chk.min_distance_along(Q)
        assert abs(d - ref[i][0]) < 1e-9 and pair == ref[i][1]
        assert n <= len(Q) * len(chk.pairs)
        if not collide:
            assert n < 0.5 * len(Q) * len(chk.pairs)     # the bounds spare most pair distances


def test_min_distance_along_checks_its_input(tcb, scene1):
    chk = CollisionChecker(tcb, scene1)
    with pytest.raises(ValueError, match="configurations"):
        chk.min_distance_along(np.zeros((3, tcb.nq + 1)))
    with pytest.raises(ValueError, match="anchor_every"):
        chk.min_distance_along(np.zeros((3, tcb.nq)), anchor_every=0)
    assert chk.min_distance_along(np.zeros((0, tcb.nq)))[1] is None


def test_closure_errors_match_the_per_configuration_check(tcb, scene1, rng):
    cc = ChainSpec.from_grasps(scene1.object.grasps)
    Q = np.array([tcb.random_configuration(rng) for _ in range(30)])
    ep, er = closure_errors(tcb, cc, Q)
    ref = np.array([closure_error(tcb, cc, q) for q in Q])
    np.testing.assert_allclose(ep, ref[:, 0], rtol=0, atol=1e-13)
    np.testing.assert_allclose(er, ref[:, 1], rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="configurations"):
        closure_errors(tcb, cc, Q[:, :-1])


def test_compiled_closed_chain_residual_matches_pinocchio(tcb, scene1, rng):
    cc = ChainSpec.from_grasps(scene1.object.grasps)
    fn = ccm._compiled_residual(tcb, cc.arm_a, cc.arm_b)
    if fn is None:
        pytest.skip("no C compiler")
    Rt, pt = np.asarray(cc.relative.rotation).reshape(-1, order="F"), np.asarray(cc.relative.translation)
    for _ in range(20):
        q = tcb.random_configuration(rng)
        out = fn(q, Rt, pt)
        h, J = closed_chain_residual(tcb, q, cc)
        np.testing.assert_allclose(out[:6], h, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out[6:].reshape(6, tcb.nq, order="F"), J, rtol=0, atol=1e-10)


def test_projection_same_with_and_without_the_compiled_residual(tcb, scene1, rng):
    cc = ChainSpec.from_grasps(scene1.object.grasps)
    qs = [tcb.random_configuration(rng) * 0.3 for _ in range(10)]
    fast = [project_closed_chain(tcb, q, cc) for q in qs]
    key = (id(tcb.model), cc.arm_a, cc.arm_b)
    saved = ccm._RESIDUAL_FNS.get(key)
    ccm._RESIDUAL_FNS[key] = (tcb.model, None)         # force the Pinocchio path
    try:
        slow = [project_closed_chain(tcb, q, cc) for q in qs]
    finally:
        if saved is None:
            ccm._RESIDUAL_FNS.pop(key)
        else:
            ccm._RESIDUAL_FNS[key] = saved
    assert sum(r.success for r in fast) >= 5
    for a, b in zip(fast, slow):
        assert a.success == b.success and a.iterations == b.iterations
        np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-6)   # Newton from far off the manifold amplifies round-off


def test_closed_chain_kinematics_reused_within_a_process(tcb, scene1, rng):
    k1 = ClosedChainKinematics(tcb, scene1.object.grasps)
    k2 = ClosedChainKinematics(tcb, scene1.object.grasps)
    assert k1._block is k2._block
    q = tcb.random_configuration(rng)
    np.testing.assert_array_equal(k1.h(q), k2.h(q))


@pytest.mark.parametrize("threshold", [0.0, 0.05])
def test_distances_below_match_every_pair_at_every_row(tcb, scene1, rng, threshold):
    chk = CollisionChecker(tcb, scene1)
    Q = _smooth_path(tcb, rng, np.zeros(tcb.nq), n=151, scale=1.5)
    D = np.array([chk.distances(q) for q in Q])
    r_ref, p_ref = np.nonzero(D < threshold)
    rows, pairs, dist = chk.distances_below(Q, threshold)
    assert len(r_ref) > 0
    np.testing.assert_array_equal(rows, r_ref)
    np.testing.assert_array_equal(pairs, p_ref)
    np.testing.assert_allclose(dist, D[r_ref, p_ref], rtol=0, atol=1e-9)


@pytest.mark.parametrize("step", [0.0, 1e-3, 3e-2, 0.3])
def test_distances_below_from_an_earlier_call_match_every_pair_at_every_row(tcb, scene1, rng, step):
    """A later call that starts from an earlier call's bounds (a re-solve's dense check) finds
    the same (row, pair) entries as every pair at every row, however far the rows moved."""
    chk = CollisionChecker(tcb, scene1)
    Q0 = _smooth_path(tcb, rng, np.zeros(tcb.nq), n=151, scale=1.5)
    _, _, _, prev = chk.distance_bounds_below(Q0, 0.05)
    Q = Q0 + step * rng.normal(size=Q0.shape)
    for threshold in (0.0, 0.05):
        D = np.array([chk.distances(q) for q in Q])
        r_ref, p_ref = np.nonzero(D < threshold)
        rows, pairs, dist, nxt = chk.distance_bounds_below(Q, threshold, previous=prev)
        assert len(r_ref) > 0
        np.testing.assert_array_equal(rows, r_ref)
        np.testing.assert_array_equal(pairs, p_ref)
        # coal's penetration depth (EPA) differs between its one-pair and all-pair queries by ~1e-7
        np.testing.assert_allclose(dist, D[r_ref, p_ref], rtol=0, atol=1e-6)
        excess = nxt[1] - D.T
        assert excess.max() <= 1e-6, f"a bound handed on exceeds the distance by {excess.max():.3g} m"


def test_shared_checker_is_reused_per_robot_scene_and_options(tcb, scene1):
    a = CollisionChecker.shared(tcb, scene1)
    assert CollisionChecker.shared(tcb, scene1) is a
    assert CollisionChecker.shared(tcb, scene1, held_object=False) is not a
    other = Scene.load("ssps_scene1")                   # another scene object: its own checker
    assert CollisionChecker.shared(tcb, other) is not a


@pytest.mark.parametrize("scale", [0.05, 0.4])
def test_min_distance_along_a_floating_base_is_the_exact_minimum(rng, scale):
    """A free-flyer root: the bound carries the base's translation and rotation (pairs against the
    world) and leaves the robot's own pairs to the joints; the base path is arbitrary here (not
    zero momentum), turning by up to ~0.6 rad, so every term of the bound is exercised."""
    from optplan.model.robot import RobotModel

    eba = RobotModel.from_name("eba_ffsr")
    scene = Scene.load("floating_truss")
    chk = CollisionChecker(eba, scene)
    assert chk._floating_base()
    q0 = np.asarray(scene.extra["q_start"], float) * np.pi / 180.0
    t = np.linspace(0.0, 1.0, 301)[:, None]
    for _ in range(3):
        amp = rng.normal(scale=scale, size=(3, eba.nj))
        J = np.clip(q0 + sum(amp[k] * np.sin((k + 1) * np.pi * t) / (k + 1) for k in range(3)),
                    eba.lower, eba.upper)
        axis = rng.normal(size=3)
        rows = []
        for k, tk in enumerate(t[:, 0]):
            B = pin.SE3(pin.exp3(axis / np.linalg.norm(axis) * 0.6 * scale / 0.4 * np.sin(np.pi * tk)),
                        np.array([0.2, -0.1, 0.05]) * np.sin(2 * np.pi * tk) * scale / 0.4)
            rows.append(np.r_[pin.SE3ToXYZQUAT(B), J[k]])
        Q = np.array(rows)
        ref = [chk.min_distance(q) for q in Q]
        i = int(np.argmin([d for d, _ in ref]))
        d, pair, n = chk.min_distance_along(Q)
        assert d == ref[i][0] and pair == ref[i][1]
        assert n <= len(Q) * len(chk.pairs)
    assert n < 0.5 * len(Q) * len(chk.pairs)     # the bounds spare most pair distances


def test_a_floating_base_bound_covers_the_real_displacement(rng):
    """The per-pair motion bound of a segment is never below the real change of a pair's distance."""
    from optplan.model.robot import RobotModel

    eba = RobotModel.from_name("eba_ffsr")
    scene = Scene.load("floating_truss")
    chk = CollisionChecker(eba, scene)
    q0 = np.asarray(scene.extra["q_start"], float) * np.pi / 180.0
    worst = 0.0
    for _ in range(100):
        B0 = pin.SE3(pin.exp3(rng.normal(scale=0.3, size=3)), rng.normal(scale=0.2, size=3))
        B1 = B0 * pin.SE3(pin.exp3(rng.normal(scale=0.3, size=3)), rng.normal(scale=0.1, size=3))
        a = np.r_[pin.SE3ToXYZQUAT(B0), np.clip(q0 + rng.normal(scale=0.2, size=eba.nj), eba.lower, eba.upper)]
        b = np.r_[pin.SE3ToXYZQUAT(B1), np.clip(q0 + rng.normal(scale=0.2, size=eba.nj), eba.lower, eba.upper)]
        Q = np.vstack([a, b])
        bound = chk._segment_motion(Q, np.array([0]), np.array([1]), np.array([0]), np.array([0]))[:, 0]
        change = np.abs(chk.distances(b) - chk.distances(a))
        assert np.all(change <= bound + 1e-12)
        sub = rng.choice(len(chk.pairs), size=17, replace=False)   # a subset of the pairs: their rows
        assert np.array_equal(chk._segment_motion(Q, None, np.array([1]), np.array([0]), np.array([0]), sub)[:, 0],
                              bound[sub])
        worst = max(worst, float(np.max(change / bound)))
    assert worst > 0.1          # the bound is not vacuous
