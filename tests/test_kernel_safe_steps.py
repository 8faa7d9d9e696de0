"""The native kernel's uniform edge check with safe steps (``verify_path``'s re-check of a found path): the
first point in collision must be the one a check of every point finds, the pair clearances it reads must be
lower bounds on the exact (coal) distances, and the sweep weights it advances by must bound how fast those
distances change."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from kernel_scenes import native_checker

from optplan.bench.hardscenes import nominal_configurations
from optplan.constraints.closed_chain import ClosedChainKinematics
from optplan.planners.kernel import KernelUnavailable, NativeKernel


def _extreme_points(gtype: int, prm: np.ndarray) -> np.ndarray:
    """Points of a primitive farthest from its centre along its axes, in its frame: a box's corners; a
    sphere's or capsule's points on its axes (a capsule's cap tips and its end circles' extreme points)."""
    if gtype == 2:
        return np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * prm
    r, hl = prm[0], (prm[1] if gtype == 1 else 0.0)
    pts = [[0.0, 0.0, z * (hl + r)] for z in (-1, 1)]
    pts += [[x, y, z * hl] for z in (-1, 1) for x, y in ((r, 0.0), (-r, 0.0), (0.0, r), (0.0, -r))]
    return np.array(pts)


@pytest.mark.parametrize("scene_name,margin,balls", [("ssps_scene1", 0.0, False), ("hard_window", 0.0, False),
                                                     ("hard_clutter_dense", 0.03, True)])
def test_safe_steps_find_the_first_point_in_collision(tcb, scene_name, margin, balls):
    rng = np.random.default_rng(2911)
    vc = native_checker(tcb, scene_name, margin, balls, rng)
    nv = vc._native
    scene = vc.scene
    kin = ClosedChainKinematics(tcb, scene.object.grasps)
    qs, qg = nominal_configurations(tcb, scene)
    points = checked = colliding = edges = 0
    for mode in ("held", "fixed", "free"):
        M = kin.object_pose(qs) if mode == "fixed" else None
        W = vc.sweep_weights(mode)
        for t in range(90):
            s = (0.02, 0.1, 0.4)[t % 3]
            a = np.clip((qs if t % 2 else qg) + rng.normal(0.0, s, tcb.model.nq), tcb.lower, tcb.upper)
            b = np.clip(a + rng.normal(0.0, s, tcb.model.nq), tcb.lower, tcb.upper)
            n = max(2, int(np.ceil(float(np.max(W @ np.abs(b - a))) / 0.01)))
            want = nv.edge_first_invalid(a, b, np.arange(1, n) / n, mode, M)
            got, k = nv.uniform_edge_first_invalid(a, b, n, mode, M)
            assert got == want, f"{scene_name} {mode}: first invalid {got}, every point's check says {want} (n = {n})"
            assert 1 <= k <= (n - 1 if want < 0 else want + 1)
            points += n - 1 if want < 0 else want + 1
            checked += k
            colliding += want >= 0
            edges += 1
        # the checker's verdict through it agrees as well
        a, b = qs, np.clip(qs + rng.normal(0.0, 0.05, tcb.model.nq), tcb.lower, tcb.upper)
        w = vc.sweep_weights(mode)
        n = max(1, int(np.ceil(float(np.max(w @ np.abs(b - a))) / 0.01)))
        want_ok = n < 2 or nv.edge_first_invalid(a, b, np.arange(1, n) / n, mode, M) < 0
        assert vc.uniform_edge_is_valid(a, b, 0.01, w, mode, M) == want_ok
    assert 0.1 * edges < colliding < 0.9 * edges   # both verdicts, many first indices deep in an edge
    assert checked < 0.5 * points, f"{scene_name}: {checked} of {points} points checked: the safe steps skip little"


def test_safe_steps_without_broad_phase_and_short_edges(tcb):
    rng = np.random.default_rng(7)
    vc = native_checker(tcb, "hard_window", 0.0, False, rng)
    pairs = [(cp.first, cp.second) for cp in vc.gmodel.collisionPairs]
    try:
        plain = NativeKernel(tcb.model, vc.gmodel, pairs, broad_phase=False)
    except KernelUnavailable as e:
        pytest.skip(str(e))
    act = vc._native.masks["held"]
    qs, _ = nominal_configurations(tcb, vc.scene)
    for _ in range(20):
        a = np.clip(qs + rng.normal(0.0, 0.3, tcb.model.nq), tcb.lower, tcb.upper)
        b = np.clip(qs + rng.normal(0.0, 0.3, tcb.model.nq), tcb.lower, tcb.upper)
        want = plain.edge_first_invalid(a, b, np.arange(1, 40) / 40, act)
        got, k = plain.uniform_edge_first_invalid(a, b, 40, act)
        assert got == want and k == (39 if want < 0 else want + 1)   # every point checked
    assert plain.uniform_edge_first_invalid(qs, qs, 1, act) == (-1, 0)


def test_pair_slacks_are_lower_bounds_on_exact_distances(tcb):
    """Sphere, capsule and capsule-box pairs: the exact distance (coal's, to 1e-6 m); box-box pairs: never
    above it."""
    rng = np.random.default_rng(11)
    vc = native_checker(tcb, "hard_clutter_dense", 0.0, True, rng)
    K, gm = vc._native.kernel, vc.gmodel
    data = tcb.model.createData()
    gd = pin.GeometryData(gm)
    thr = K._km.margin + 1e-5
    qs, qg = nominal_configurations(tcb, vc.scene)
    types = K.types
    exact_pairs = [k for k, cp in enumerate(gm.collisionPairs) if not (types[cp.first] == 2 and types[cp.second] == 2)]
    cyl = {g for g, go in enumerate(gm.geometryObjects) if type(go.geometry).__name__ == "Cylinder"}
    n_exact = n_box = 0
    for q0 in (qs, qg):
        for _ in range(15):
            q = np.clip(q0 + rng.normal(0.0, 0.3, tcb.model.nq), tcb.lower, tcb.upper)
            s = K.pair_slacks(q)
            pin.updateGeometryPlacements(tcb.model, data, gm, gd, q)
            for k, cp in enumerate(gm.collisionPairs):
                d = pin.computeDistance(gm, gd, k).min_distance
                if d < 1e-3:   # in contact: a penetration depth is not a distance
                    continue
                assert s[k] + thr <= d + 1e-6, f"pair {k}: lower bound {s[k] + thr} above the exact distance {d}"
                if k in exact_pairs and cp.first not in cyl and cp.second not in cyl:
                    assert s[k] + thr == pytest.approx(d, abs=1e-6)
                    n_exact += 1
                else:
                    n_box += 1
    assert n_exact > 100 and n_box > 10


def test_sweep_weights_bound_how_fast_pair_clearances_change(tcb):
    """Between two configurations no pair's slack changes by more than its sweep-weight bound, and no extreme
    point of a primitive moves farther than its geometry's bound."""
    rng = np.random.default_rng(3)
    vc = native_checker(tcb, "hard_clutter_dense", 0.0, True, rng)
    K, gm = vc._native.kernel, vc.gmodel
    assert K._wg is not None and K._wp is not None
    types = K.types
    exact = np.array([not (types[cp.first] == 2 and types[cp.second] == 2) for cp in gm.collisionPairs])
    prm = K._arrays[8]
    qs, _ = nominal_configurations(tcb, vc.scene)
    worst = 0.0
    for _ in range(40):
        q = np.clip(qs + rng.normal(0.0, 0.4, tcb.model.nq), tcb.lower, tcb.upper)
        q2 = np.clip(q + rng.normal(0.0, 0.05, tcb.model.nq), tcb.lower, tcb.upper)
        dq = np.abs(q2 - q)
        s1, s2 = K.pair_slacks(q), K.pair_slacks(q2)
        bound = K._wp @ dq
        assert np.all(np.abs(s2 - s1) <= bound + 1e-9)   # box-box pairs too: their slack is a Lipschitz one
        worst = max(worst, float(np.max((np.abs(s2 - s1) / np.maximum(bound, 1e-12))[exact])))
        P1, P2 = K.placements(q), K.placements(q2)
        for g in range(K.ng):
            corners = _extreme_points(int(types[g]), prm[g])
            x1 = corners @ P1[g, :9].reshape(3, 3).T + P1[g, 9:]
            x2 = corners @ P2[g, :9].reshape(3, 3).T + P2[g, 9:]
            assert np.max(np.linalg.norm(x2 - x1, axis=1)) <= K._wg[g] @ dq + 1e-9
    assert worst > 0.05   # the bound is not vacuous: some pair's clearance changes by a fair share of it


def test_box_pairs_near_corners_keep_the_separating_axis_verdicts():
    """A box swung on one revolute joint past turned boxes, with a 20 cm margin: the kernel's box-box test
    (separating axes, conservative near corners and edges) calls some configurations colliding whose exact
    distance exceeds the margin; the skipped points must still be those it calls free, and its verdicts must
    not depend on which pair it tried first (the last one that collided, which skips the broad phase)."""
    import coal

    rng = np.random.default_rng(44)
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "swing")
    model.addJointFrame(j)
    n_edges = n_diff = n_coll = checked = points = 0
    for _trial in range(60):
        gm = pin.GeometryModel()
        h = rng.uniform(0.05, 0.3, 3)
        gm.addGeometryObject(pin.GeometryObject("arm", j, j, pin.SE3(pin.exp3(rng.normal(0.0, 1.0, 3)), np.array([1.0, 0.0, 0.0])),
                                                coal.Box(*(2 * h))))
        for i in range(3):
            ang = rng.uniform(-np.pi, np.pi)
            c = np.array([np.cos(ang), np.sin(ang), rng.normal(0.0, 0.2)]) * rng.uniform(0.9, 1.6)
            gm.addGeometryObject(pin.GeometryObject(f"obs{i}", 0, 0, pin.SE3(pin.exp3(rng.normal(0.0, 1.0, 3)), c),
                                                    coal.Box(*rng.uniform(0.05, 0.5, 3))))
        try:
            k = NativeKernel(model, gm, [(0, 1), (0, 2), (0, 3)], margin=0.2)
        except KernelUnavailable as e:
            pytest.skip(str(e))
        act = k.all_active()
        plain = NativeKernel(model, gm, [(0, 1), (0, 2), (0, 3)], margin=0.2, broad_phase=False)
        Q = np.linspace(-np.pi, np.pi, 400)[:, None]
        v = k.valid(Q, act)   # the verdicts do not depend on the pair tried first (the last colliding one)
        assert np.array_equal(v, k.valid(Q[::-1], act)[::-1]) and np.array_equal(v, plain.valid(Q, act))
        assert np.array_equal(v, [not k.collides(q, act) for q in Q[::-1]][::-1])
        for _ in range(5):
            a, b = rng.uniform(-np.pi, np.pi, 1), rng.uniform(-np.pi, np.pi, 1)
            n = max(2, int(np.ceil(float(k._wg[0] @ np.abs(b - a)) / 0.005)))
            want = k.edge_first_invalid(a, b, np.arange(1, n) / n, act)
            got, c = k.uniform_edge_first_invalid(a, b, n, act)
            n_diff += got != want
            n_coll += want >= 0
            n_edges += 1
            checked += c
            points += n - 1 if want < 0 else want + 1
    assert n_diff == 0, f"{n_diff} of {n_edges} edges: another first point in collision"
    assert 0.2 * n_edges < n_coll < 0.95 * n_edges and checked < 0.5 * points


def test_expected_free_edges_get_the_coarse_to_fine_verdicts(tcb):
    """``edge_is_valid(..., expect_free=True)`` (a found regrasp motion's re-check: the Jacobian-spaced points in
    order, with safe steps) gives the coarse-to-fine check's verdicts, with fewer points checked."""
    rng = np.random.default_rng(12)
    vc = native_checker(tcb, "ssps_scene2", 0.0, False, rng)
    scene = vc.scene
    kin = ClosedChainKinematics(tcb, scene.object.grasps)
    qs, qg = nominal_configurations(tcb, scene)
    verdicts, fewer = [], 0
    for mode in ("fixed", "held"):
        M = kin.object_pose(qg) if mode == "fixed" else None
        for t in range(60):
            a = np.clip((qs if t % 2 else qg) + rng.normal(0.0, 0.03, tcb.model.nq), tcb.lower, tcb.upper)
            b = np.clip(a + rng.normal(0.0, (0.05, 0.3)[t % 2], tcb.model.nq), tcb.lower, tcb.upper)
            c0 = vc.n_checks
            want = vc.edge_is_valid(a, b, 0.01, mode, M)
            c1 = vc.n_checks
            got = vc.edge_is_valid(a, b, 0.01, mode, M, expect_free=True)
            assert got == want, f"{mode} edge {t}: {got} != {want}"
            fewer += want and (vc.n_checks - c1) < (c1 - c0)
            verdicts.append(want)
    assert 0 < sum(verdicts) < len(verdicts)
    assert fewer > 0.5 * sum(verdicts)


def test_a_prismatic_joint_checks_every_point():
    """A prismatic joint lengthens the arm above it, so the configuration-free sweep weights do not bound it: every
    point is checked, with the every-point answer."""
    import coal

    model = pin.Model()
    j1 = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "turn")
    j2 = model.addJoint(j1, pin.JointModelPX(), pin.SE3.Identity(), "slide")
    gm = pin.GeometryModel()
    gm.addGeometryObject(pin.GeometryObject("hand", j2, j2, pin.SE3(np.eye(3), np.array([0.7, 0.0, 0.0])), coal.Sphere(0.1)))
    gm.addGeometryObject(pin.GeometryObject("post", 0, 0, pin.SE3(np.eye(3), np.array([0.0, 1.0, 0.0])), coal.Box(0.2, 0.2, 0.2)))
    try:
        k = NativeKernel(model, gm, [(0, 1)])
    except KernelUnavailable as e:
        pytest.skip(str(e))
    assert k._wg is None
    act = k.all_active()
    a, b = np.array([0.0, 0.0]), np.array([np.pi, 0.5])
    want = k.edge_first_invalid(a, b, np.arange(1, 50) / 50, act)
    got, checked = k.uniform_edge_first_invalid(a, b, 50, act)
    assert want >= 0 and got == want and checked == want + 1
    free = np.array([0.0, -0.4]), np.array([0.3, -0.4])
    assert k.uniform_edge_first_invalid(*free, 50, act) == (-1, 49)
