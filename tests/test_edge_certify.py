"""Certified edges (conservative advancement on exact distances) against dense brute force with the
independent exact checker :class:`optplan.collision.CollisionChecker`."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.bench.hardscenes import nominal_configurations
from optplan.collision import CollisionChecker
from optplan.planners.edge_certify import EdgeCertifier
from optplan.planners.validity import ValidityChecker
from optplan.scene import Scene


@pytest.fixture(scope="module")
def setup(tcb):
    scene = Scene.load("hard_clutter_dense")
    ck = ValidityChecker(tcb, scene)
    ex = CollisionChecker(tcb, scene)
    qs, qg = nominal_configurations(tcb, scene)
    return tcb, scene, ck, ex, qs, qg


def _dense(a, b, step):
    n = max(1, int(np.ceil(float(np.abs(b - a).max()) / step)))
    return a + (np.arange(n + 1) / n)[:, None] * (b - a)


def _edges(ck, qs, qg, rng, n, sigma):
    out = []
    while len(out) < n:
        a = (qs if len(out) % 2 else qg) + rng.normal(0.0, 0.05, qs.size)
        b = a + rng.normal(0.0, sigma, a.size)
        if ck.in_limits(a) and ck.in_limits(b) and ck.is_valid(a) and ck.is_valid(b):
            out.append((a, b))
    return out


def test_certified_edges_never_collide_brute_force(setup):
    """Certified ⇒ no collision anywhere at 1e-4 rad spacing (exact checker), and the exact
    clearance never below min_clearance / 2; an edge with a colliding dense sample is rejected.
    The discrete security-margin alternative is held to the same standard."""
    robot, scene, ck, ex, qs, qg = setup
    rng = np.random.default_rng(7)
    cert = ck.certifier(2e-3)
    n_cert = n_rejected_colliding = 0
    for a, b in _edges(ck, qs, qg, rng, 30, 0.2):
        ok = ck.edge_is_certified(a, b, "held", min_clearance=2e-3)
        ok_discrete = cert.discrete_segment(a, b, 0.01)
        coarse = _dense(a, b, 2e-3)
        colliding = any(not ex.is_valid(q) for q in coarse)
        if ok or ok_discrete:
            fine = _dense(a, b, 1e-4)
            assert all(ex.is_valid(q) for q in fine)
            assert min(ex.min_distance(q)[0] for q in coarse[::3]) >= 1e-3 - 1e-9
            n_cert += 1
        if colliding:
            assert not ok and not ok_discrete
            n_rejected_colliding += 1
    assert n_cert >= 5 and n_rejected_colliding >= 3, (n_cert, n_rejected_colliding)


def test_edge_through_an_obstacle_is_rejected_and_clear_long_edge_passes(setup):
    """A long straight edge between two valid configurations whose middle collides is rejected;
    the same scene without obstacles certifies it (also in the ``free`` mode)."""
    robot, scene, ck, ex, qs, qg = setup
    mid_colliding = not ex.is_valid(0.5 * (qs + qg)) or any(not ex.is_valid(q) for q in _dense(qs, qg, 0.01))
    assert mid_colliding
    assert not ck.edge_is_certified(qs, qg)
    empty = ValidityChecker(robot, None)
    ok = empty.edge_is_certified(qs, qg, "free")
    assert ok == all(empty.is_valid_free(q) for q in _dense(qs, qg, 1e-3))


def test_certified_paths_and_fixed_object_brute_force(setup):
    """Piecewise-linear paths (the OC-RRT case) and the object standing still (regrasp mode)."""
    robot, scene, ck, ex, qs, qg = setup
    rng = np.random.default_rng(3)
    cert = EdgeCertifier(ck, 1e-3)
    n_ok = 0
    for k in range(40):
        if n_ok >= 4:
            break
        a = (qs if k % 2 else qg) + rng.normal(0.0, 0.03, qs.size)
        Q = a + np.cumsum(rng.normal(0.0, 0.015, (12, qs.size)), axis=0)
        if not all(ck.is_valid(q) for q in Q):
            continue
        if cert.path(Q, "held"):
            n_ok += 1
            for u, v in zip(Q[:-1], Q[1:]):
                assert all(ex.is_valid(q) for q in _dense(u, v, 2e-4))
    assert n_ok >= 2
    # fixed object: the object left at the start pose while the arms move
    M = ex.object_pose(qs)
    ex_free = CollisionChecker(robot, scene, held_object=False)
    exo = CollisionChecker(robot, None, held_object=False)
    from optplan.collision.checker import _tf

    og = scene.object.coal_geometry()
    import coal

    def fixed_ok(q):
        if not ex_free.is_valid(q):
            return False
        exo.update_placements(q)
        req, res = coal.CollisionRequest(), coal.CollisionResult()
        for k, go in enumerate(robot.collision_model.geometryObjects):
            if go.parentJoint == 0:
                continue
            res.clear()
            if coal.collide(go.geometry, _tf(exo.gdata.oMg[k]), og, _tf(M), req, res):
                return False
        return True

    n_fixed = 0
    for a, b in _edges(ck, qs, qs, rng, 10, 0.08):
        if not (ck.is_valid_object_fixed(a, M) and ck.is_valid_object_fixed(b, M)):
            continue
        if ck.edge_is_certified(a, b, "fixed", object_pose=M):
            n_fixed += 1
            assert all(fixed_ok(q) for q in _dense(a, b, 1e-3))
    assert n_fixed >= 2


def test_bad_input_errors(setup):
    robot, scene, ck, ex, qs, qg = setup
    with pytest.raises(ValueError, match="min_clearance"):
        EdgeCertifier(ck, 0.0)
    with pytest.raises(ValueError, match="min_clearance"):
        EdgeCertifier(ck, float("nan"))
    cert = ck.certifier()
    with pytest.raises(ValueError, match="mode"):
        cert.segment(qs, qg, mode="bogus")
    with pytest.raises(ValueError, match="object_pose"):
        cert.segment(qs, qg, mode="fixed")
    with pytest.raises(ValueError, match="array of configurations"):
        cert.path(np.zeros((3, qs.size + 1)))
    with pytest.raises(ValueError, match="finite"):
        cert.segment(qs, np.full_like(qs, np.nan))
    with pytest.raises(ValueError, match="tolerance"):
        cert.discrete_segment(qs, qg, -1.0)
    # a configuration in collision: rejected at once, no exception
    assert not cert.segment(qg, qg) or ck.is_valid(qg)
    assert isinstance(pin.SE3.Identity(), pin.SE3)


def test_tcbirrt_certified_edges_clean_without_path_verification(setup):
    """TCBiRRT (improved, ``edge_bound="certified"``): the bench's independent dense and 1 cm
    sweep checks find no clipping edge, and no path re-verification ran."""
    from optplan.bench.tcbirrt import _path_checks
    from optplan.planners import TCBiRRT, TCBiRRTOptions

    robot = setup[0]
    scene = Scene.load("hard_flip")
    qs, qg = nominal_configurations(robot, scene)
    ck = ValidityChecker(robot, scene)
    pl = TCBiRRT(robot, scene, TCBiRRTOptions(variant="improved", edge_bound="certified"), checker=ck)
    res = pl.plan(qs, qg, time_limit=10.0, seed=1, clock="cpu")
    assert res.success, res.message
    chk = _path_checks(robot, scene, ck, res)
    assert chk["swept_invalid_edges"] == 0 and chk["dense_invalid_edges"] == 0
    assert res.stats.get("path_verified_edges", 0) == 0 and res.stats["edge_checks"] > 0
    with pytest.raises(ValueError, match="edge_bound"):
        TCBiRRTOptions(edge_bound="exact")
    with pytest.raises(ValueError, match="edge_min_clearance"):
        TCBiRRTOptions(edge_min_clearance=0.0)


_pr2 = pytest.mark.skipif("not __import__('optplan.model.example_robots', fromlist=['x']).example_robots_available()",
                          reason="needs example-robot-data (pip install 'optplan[robots]')")


@_pr2
def test_pr2_hulls_are_convex_and_coal_distances_exact():
    """Every PR2 collision geometry is a true convex hull (every stored point a hull vertex), and
    coal's distance between two of them never exceeds the closest vertex pair (a support function
    stuck on a non-convex face graph did: decimetres too far)."""
    import coal
    from scipy.spatial import ConvexHull
    from scipy.spatial.distance import cdist

    from optplan.model.example_robots import load_pr2

    robot = load_pr2()
    gm = robot.collision_model
    pts = {}
    for k, go in enumerate(gm.geometryObjects):
        g = go.geometry
        if not isinstance(g, coal.ConvexBase):
            continue                      # primitives (boxes, cylinders) from the URDF
        P = np.asarray(g.points())
        assert len(ConvexHull(P).vertices) == len(P), go.name
        pts[k] = P
    data, gd = robot.model.createData(), pin.GeometryData(gm)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = np.clip(rng.uniform(robot.lower, robot.upper), -3.0, 3.0)
        pin.updateGeometryPlacements(robot.model, data, gm, gd, q)
        for a, b in robot.collision_pairs[::7]:
            if a not in pts or b not in pts:
                continue
            Ta, Tb = gd.oMg[a], gd.oMg[b]
            d = coal.distance(gm.geometryObjects[a].geometry, coal.Transform3s(Ta.rotation, Ta.translation),
                              gm.geometryObjects[b].geometry, coal.Transform3s(Tb.rotation, Tb.translation),
                              coal.DistanceRequest(), coal.DistanceResult())
            Wa, Wb = pts[a] @ Ta.rotation.T + Ta.translation, pts[b] @ Tb.rotation.T + Tb.translation
            assert d <= cdist(Wa, Wb).min() + 1e-9


@_pr2
@pytest.mark.parametrize("planner", ["oc_rrt_connect", "cbirrt"])
def test_certified_orientation_planners_paths_clear_everywhere(planner):
    """OC-RRT-Connect and CBiRRT with certified edges on the tray scene: every configuration of the
    path as executed (OC-RRT: densified at the certified resolution; CBiRRT: its waypoints) and 4
    points on every chord between them are collision-free by the exact checker."""
    from optplan.bench.oc_rrt import densify_linear, setup_scene

    s = setup_scene("oc_tabletop", [planner])
    pl, ex = s["planners"][planner], CollisionChecker(s["robot"], s["scene"])
    assert pl.options.certified_edges
    res = pl.plan(s["q_start"], s["q_goal"], time_limit=10.0, seed=3, clock="cpu")
    assert res.success, res.message
    P = pl.densify(res.path, pl.options.certify_resolution) if planner == "oc_rrt_connect" else res.path
    dense = densify_linear(P, 2e-3)
    assert all(ex.is_valid(q) for q in dense)


def test_vertex_cache_certifies_the_same_and_saves_distance_calls(setup):
    """Edge after edge along random walks (as a planner's extensions: each edge starts where the last
    ended): with the vertex cache every certified edge is collision-free at 2e-4 rad spacing and keeps
    ≥ min_clearance / 2 by exact distances, the decisions equal those without the cache, and the
    cache needs fewer distance calls. Clearing it gives the same calls again (a query's result does
    not depend on the queries before it)."""
    robot, scene, ck, ex, qs, qg = setup
    rng = np.random.default_rng(11)
    walks = []
    while len(walks) < 6:
        a = (qs if len(walks) % 2 else qg) + rng.normal(0.0, 0.04, qs.size)
        if not (ck.in_limits(a) and ck.is_valid(a)):
            continue
        W = [a]
        for _ in range(8):
            b = W[-1] + rng.normal(0.0, 0.03, a.size)
            if not ck.is_valid(b):
                break
            W.append(b)
        if len(W) >= 4:
            walks.append(W)
    plain, cached = EdgeCertifier(ck, 1e-3), EdgeCertifier(ck, 1e-3)

    def run(cert, cache):
        out = []
        for W in walks:
            for u, v in zip(W[:-1], W[1:]):
                ok = cert.segment(u, v, "held", cache=cache)
                out.append(ok)
                if not ok:
                    break
        return out

    ok_plain, ok_cached = run(plain, False), run(cached, True)
    # equal on these walks (a borderline edge could in principle be decided differently: the distances
    # are evaluated at other points)
    assert ok_cached == ok_plain
    assert sum(ok_cached) >= 10 and cached.n_cache_hits >= 10
    assert cached.n_distance_calls < 0.7 * plain.n_distance_calls, (cached.n_distance_calls, plain.n_distance_calls)
    k = 0
    for W in walks:
        for u, v in zip(W[:-1], W[1:]):
            if not ok_cached[k]:
                break
            fine = _dense(u, v, 2e-4)
            assert all(ex.is_valid(q) for q in fine)
            floor = min(1e-3, 0.5 * min(ex.min_distance(u)[0], ex.min_distance(v)[0]))   # ≤ the certifier's floor
            assert min(ex.min_distance(q)[0] for q in fine[::10]) >= 0.5 * floor - 1e-9
            k += 1
    n1 = cached.n_distance_calls
    cached.clear_cache()
    run(cached, True)
    assert cached.n_distance_calls - n1 == n1


def test_relative_motion_bound_against_dense_exact_distances(setup):
    """The held object's speed relative to each robot geometry it is paired with (the rows after the
    per-geometry ones of the compiled cell speeds): on tree-like edges between closed-chain
    configurations, the exact coal distance of every such pair changes between any two of 12 points
    of a cell by at most that bound times their spacing, and so does every per-geometry pair
    (sum of the two speeds). The relative bound is below the sum on most cells (what it is for)."""
    import coal

    from optplan.constraints.closed_chain import ClosedChainKinematics, IKSettings
    from optplan.planners.task_space import interpolate_task

    robot, scene, ck, ex, qs, qg = setup
    kin = ClosedChainKinematics(robot, scene.object.grasps)
    gids = ck._moving_geometries("held")
    rel = ck._relative_pairs("held")
    assert len(rel) >= 4
    fn = ck._cell_speed_function("held")
    G, m = len(gids), ck.CELLS
    model, gm = ck.model, ck.gmodel
    data, gd = model.createData(), pin.GeometryData(gm)
    rng = np.random.default_rng(5)
    edges = []
    for q0 in (qs, qg):   # consecutive closed-chain configurations of object-pose interpolations (as the planner's)
        M0 = kin.object_pose(q0)
        for _ in range(6):
            M1 = M0 * pin.exp6(np.r_[rng.normal(0.0, 0.08, 3), rng.normal(0.0, 0.15, 3)])
            q = q0
            for R, p in interpolate_task(M0.rotation, M0.translation, M1.rotation, M1.translation, 5, "geodesic"):
                x, _ = kin.ik(q, R, p, IKSettings())
                if x is None:
                    break
                edges.append((q, x))
                q = x
    assert len(edges) >= 15

    def pair_distance(g1, g2):
        o1, o2 = gm.geometryObjects[g1], gm.geometryObjects[g2]
        T1, T2 = gd.oMg[g1], gd.oMg[g2]
        return coal.distance(o1.geometry, coal.Transform3s(T1.rotation, T1.translation), o2.geometry,
                             coal.Transform3s(T2.rotation, T2.translation), coal.DistanceRequest(), coal.DistanceResult())

    n_tighter = n_cells = 0
    worst = 0.0
    for a, b in edges:
        V = np.asarray(fn(a, b), float).reshape(G + len(rel), m, order="F")
        for i in range(m):
            ts = (i + np.linspace(0.0, 1.0, 12)) / m
            dist = np.empty((len(ts), len(rel)))
            for k, t in enumerate(ts):
                pin.updateGeometryPlacements(model, data, gm, gd, a + t * (b - a))
                dist[k] = [pair_distance(gids[o], gids[l]) for o, l in rel]
            h = ts[1] - ts[0]
            for p, (o, l) in enumerate(rel):
                bound_rel, bound_sum = V[G + p, i], V[o, i] + V[l, i]
                change = np.abs(np.subtract.outer(dist[:, p], dist[:, p]))
                spacing = h * np.abs(np.subtract.outer(np.arange(12), np.arange(12)))
                assert np.all(change <= bound_rel * spacing + 1e-9), (p, i, change.max(), bound_rel)
                assert np.all(change <= bound_sum * spacing + 1e-9)
                worst = max(worst, float((change[spacing > 0] / (spacing[spacing > 0] * bound_rel)).max()))
                n_tighter += bound_rel < bound_sum
                n_cells += 1
    assert n_tighter > 0.5 * n_cells, (n_tighter, n_cells)
    assert worst > 0.05   # the check has teeth: distances do change at a visible fraction of the bound


def test_reach_never_advances_a_group_without_budget():
    """A group whose (cached lower-bound) clearance is below half the floor gets no reach beyond s
    (it is evaluated at once), whatever its travel bound; with budget, the reach is where the travel
    bound uses it up (piecewise-linear inverse)."""
    K = np.array([[0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8],
                  [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                  [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8]])
    gs = np.arange(3)
    half = 5e-4
    d = np.array([1e-4, 1e-4, 0.05 + half])           # budgets: negative, negative, 0.05
    rate = np.array([1.0, 1.0, 10.0])                  # static bound: reach s + budget / rate
    out0 = EdgeCertifier._reach(0.0, gs, d, rate, half, K)       # at a chord's start (a cached vertex)
    assert out0[0] <= 1e-9 and out0[1] <= 1e-9
    out = EdgeCertifier._reach(0.25, gs, d, rate, half, K)
    assert out[0] <= 0.25 + 1e-9 and out[1] <= 0.25 + 1e-9
    # K(0.25) = 0.2; +0.05 -> 0.25 -> s = 0.3125 (static: 0.255)
    assert out[2] == pytest.approx(0.3125)


def test_vertex_cache_is_per_object_pose_in_the_fixed_mode(setup):
    """Regrasp motions (object standing at a pose): cached bounds are kept per object pose — a chain
    certified with the object at one pose gives no cache hit to the same configurations with the
    object elsewhere — and the cached decisions equal the uncached ones, each accepted edge free at
    2e-4 rad spacing."""
    robot, scene, ck, ex, qs, qg = setup
    M1, M2 = ex.object_pose(qs), ex.object_pose(qg)
    rng = np.random.default_rng(4)
    chain = [qs + rng.normal(0.0, 0.02, qs.size)]
    while len(chain) < 7:
        chain.append(chain[-1] + rng.normal(0.0, 0.03, qs.size))
    plain, cached = EdgeCertifier(ck, 1e-3), EdgeCertifier(ck, 1e-3)
    n_ok = 0
    for M in (M1, M2):
        hits0 = cached.n_cache_hits
        for k, (u, v) in enumerate(zip(chain[:-1], chain[1:])):
            ok = cached.segment(u, v, "fixed", M, cache=True)
            if k == 0:
                assert cached.n_cache_hits == hits0        # nothing cached for this pose's first vertex
            assert ok == plain.segment(u, v, "fixed", M)
            if ok:
                n_ok += 1
                assert all(ck.is_valid_object_fixed(q, M) for q in _dense(u, v, 2e-4))
    assert cached.n_cache_hits >= 4 and n_ok >= 6, (cached.n_cache_hits, n_ok)
