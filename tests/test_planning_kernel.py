"""The native planning kernel against independent references: its forward kinematics against
Pinocchio's geometry placements, its primitive tests against coal's exact distances (a pair within
reach is never called free), and its batch verdicts against the coal-based ValidityChecker on random
configurations of the shipped scenes (no false "free"; the false "colliding" rate is reported)."""
from __future__ import annotations

import dataclasses

import coal
import numpy as np
import pinocchio as pin
import pytest

from optplan.bench.hardscenes import nominal_configurations
from optplan.constraints.closed_chain import ClosedChainKinematics
from optplan.planners.kernel import KernelUnavailable, NativeKernel
from optplan.planners.kernel.csource import KERNEL_EPS
from optplan.planners.validity import ValidityChecker
from optplan.scene import Obstacle, Scene


def _kernel_or_skip(*args, **kw) -> NativeKernel:
    try:
        return NativeKernel(*args, **kw)
    except KernelUnavailable as e:   # no C compiler on this machine
        pytest.skip(str(e))


def _random_pose(rng: np.random.Generator, spread: float) -> pin.SE3:
    return pin.SE3(pin.exp3(rng.normal(0.0, 2.0, 3)), rng.uniform(-spread, spread, 3))


def _shape(rng: np.random.Generator, kind: str) -> coal.CollisionGeometry:
    if kind == "sphere":
        return coal.Sphere(rng.uniform(0.02, 0.4))
    if kind == "capsule":
        return coal.Capsule(rng.uniform(0.02, 0.3), rng.uniform(0.0, 1.2))
    if kind == "cylinder":
        return coal.Cylinder(rng.uniform(0.02, 0.3), rng.uniform(0.05, 1.2))
    return coal.Box(*rng.uniform(0.02, 1.0, 3))


KINDS = ["sphere", "capsule", "box", "cylinder"]


@pytest.mark.parametrize("ka", KINDS)
@pytest.mark.parametrize("kb", KINDS)
def test_primitive_pairs_against_coal_distance(ka, kb):
    """Random placements of two primitives: whenever coal's exact distance is ≤ margin the kernel says
    colliding; for the exact primitives (no cylinder) it says free whenever the distance exceeds
    margin + 1e-6 m."""
    rng = np.random.default_rng(100 * KINDS.index(ka) + KINDS.index(kb))
    model = pin.Model()   # no joints: both geometries placed in the world
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    counts = {"hit": 0, "free": 0, "false_coll": 0}
    for trial in range(150):
        ga, gb = _shape(rng, ka), _shape(rng, kb)
        Ma, Mb = _random_pose(rng, 0.8), _random_pose(rng, 0.8)
        margin = float(rng.choice([0.0, 0.05]))
        gm = pin.GeometryModel()
        gm.addGeometryObject(pin.GeometryObject("a", 0, 0, Ma, ga))
        gm.addGeometryObject(pin.GeometryObject("b", 0, 0, Mb, gb))
        k = _kernel_or_skip(model, gm, [(0, 1)], margin=margin)
        free = k.first_invalid(np.zeros((1, 0)), k.all_active()) < 0
        res.clear()
        d = coal.distance(ga, coal.Transform3s(Ma.rotation, Ma.translation), gb,
                          coal.Transform3s(Mb.rotation, Mb.translation), req, res)
        if d <= margin:
            counts["hit"] += 1
            assert not free, f"{ka}/{kb} trial {trial}: kernel says free at coal distance {d:.3g} m (margin {margin})"
        else:
            counts["free"] += 1
            if not free:
                counts["false_coll"] += 1
                # exact primitives; two boxes with a margin are tested as boxes grown by it (a box, not rounded)
                if "cylinder" not in (ka, kb) and not (ka == kb == "box" and margin > 0):
                    assert d <= margin + 1e-6, f"{ka}/{kb} trial {trial}: colliding at distance {d:.3g} m"
    assert counts["hit"] > 5 and counts["free"] > 5, counts   # both verdicts occur


@pytest.mark.parametrize("moving", ["one", "both"])
@pytest.mark.parametrize("ka", KINDS)
@pytest.mark.parametrize("kb", KINDS)
def test_primitive_pairs_near_the_margin_through_the_broad_phase(ka, kb, moving):
    """Two primitives on joints (``moving="both"``: a pair of moving geometries, bucketed; ``"one"``: one
    moving, one static, culled by the obstacle's box) placed at random and then moved along coal's
    separation direction to within two margins of each other: whenever coal's exact distance is ≤ the
    margin the kernel says colliding, and for exact primitives it says free beyond margin + 1e-6 m."""
    rng = np.random.default_rng(1000 + 100 * KINDS.index(ka) + KINDS.index(kb) + (7 if moving == "both" else 0))
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    counts = {"hit": 0, "free": 0}
    for trial in range(60):
        ga, gb = _shape(rng, ka), _shape(rng, kb)
        Ma, Mb = _random_pose(rng, 0.8), _random_pose(rng, 0.8)
        margin = 0.05
        res.clear()
        d0 = coal.distance(ga, coal.Transform3s(Ma.rotation, Ma.translation), gb,
                           coal.Transform3s(Mb.rotation, Mb.translation), req, res)
        if d0 > 1e-9:   # within two margins along the separation direction, on any side of the box
            n = (res.getNearestPoint2() - res.getNearestPoint1()) / d0
            Mb = pin.SE3(Mb.rotation, Mb.translation - (d0 - rng.uniform(0.0, 2.0 * margin)) * n)
        res.clear()
        d = coal.distance(ga, coal.Transform3s(Ma.rotation, Ma.translation), gb,
                          coal.Transform3s(Mb.rotation, Mb.translation), req, res)
        model = pin.Model()
        ja = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "ja")
        jb = model.addJoint(0, pin.JointModelRX(), pin.SE3.Identity(), "jb") if moving == "both" else 0
        gm = pin.GeometryModel()
        gm.addGeometryObject(pin.GeometryObject("a", ja, ja, Ma, ga))
        gm.addGeometryObject(pin.GeometryObject("b", jb, jb, Mb, gb))
        k = _kernel_or_skip(model, gm, [(0, 1)], margin=margin)
        assert k._km.ngrp >= 1
        free = k.first_invalid(np.zeros((1, model.nq)), k.all_active()) < 0
        if d <= margin:
            counts["hit"] += 1
            assert not free, f"{ka}/{kb} trial {trial}: kernel says free at coal distance {d:.3g} m (margin {margin})"
        else:
            counts["free"] += 1
            if not free and "cylinder" not in (ka, kb) and not (ka == kb == "box"):
                assert d <= margin + 1e-6, f"{ka}/{kb} trial {trial}: colliding at distance {d:.3g} m"
    assert counts["hit"] > 5 and counts["free"] > 5, counts


def test_forward_kinematics_matches_pinocchio(tcb):
    scene = Scene.load("hard_bay")
    vc = ValidityChecker(tcb, scene)
    k = _kernel_or_skip(tcb.model, vc.gmodel, [])
    data, gd = tcb.model.createData(), pin.GeometryData(vc.gmodel)
    rng = np.random.default_rng(7)
    for _ in range(20):
        q = tcb.random_configuration(rng)
        pin.updateGeometryPlacements(tcb.model, data, vc.gmodel, gd, q)
        P = k.placements(q)
        for g, M in enumerate(gd.oMg):
            assert np.allclose(P[g, :9].reshape(3, 3), M.rotation, atol=1e-12)
            assert np.allclose(P[g, 9:], M.translation, atol=1e-12)


def test_floating_base_is_not_covered(eba):
    with pytest.raises(KernelUnavailable, match="revolute and prismatic"):
        NativeKernel(eba.model, eba.collision_model, [])


def _with_round_obstacles(scene: Scene) -> Scene:
    """``scene`` plus spheres and capsules of random placement around the robot (seeded)."""
    rng = np.random.default_rng(21)
    extra = []
    for i in range(8):
        M = pin.SE3(pin.exp3(rng.normal(0.0, 1.0, 3)), rng.uniform([-0.5, -2.5, 0.5], [3.0, 2.5, 4.0]))
        if i % 2:
            extra.append(Obstacle(f"ball_{i}", "sphere", M, radius=float(rng.uniform(0.1, 0.4))))
        else:
            extra.append(Obstacle(f"rod_{i}", "capsule", M, radius=float(rng.uniform(0.05, 0.2)),
                                  length=float(rng.uniform(0.3, 1.5))))
    return dataclasses.replace(scene, name=scene.name + "_round", obstacles=scene.obstacles + tuple(extra))


@pytest.mark.parametrize("scene_name", ["hard_clutter_dense", "hard_bay", "ssps_scene1", "hard_window+round"])
def test_batch_verdicts_never_free_where_coal_collides(tcb, scene_name):
    """Random configurations (around the scene's start and goal and uniform in the limits), every mode:
    no configuration the coal checker calls colliding is called free; the false "colliding" rate stays
    below 1 % (all primitives of this robot and these scenes are exact in the kernel)."""
    scene = Scene.load(scene_name.split("+")[0])
    ref = ValidityChecker(tcb, scene, kernel="coal")
    nat = ValidityChecker(tcb, scene, kernel="native")
    if nat.kernel != "native":
        pytest.skip("no native kernel here")
    rng = np.random.default_rng(11)
    qs, qg = nominal_configurations(tcb, scene)
    if scene_name.endswith("+round"):
        scene = _with_round_obstacles(scene)
        ref, nat = ValidityChecker(tcb, scene, kernel="coal"), ValidityChecker(tcb, scene, kernel="native")
    Q = np.vstack([np.clip(q0 + rng.normal(0.0, s, (150, tcb.model.nq)), tcb.lower, tcb.upper)
                   for q0 in (qs, qg) for s in (0.05, 0.3)] + [np.array([tcb.random_configuration(rng) for _ in range(200)])])
    modes = [("held", None), ("free", None),
             ("fixed", ClosedChainKinematics(tcb, scene.object.grasps).object_pose(qs))]
    for mode, pose in modes:
        want = np.array([ref.first_invalid(q[None], mode, pose) < 0 for q in Q])
        got = nat.valid_batch(Q, mode, pose)
        assert not np.any(got & ~want), f"{scene_name}/{mode}: {int(np.sum(got & ~want))} false free verdicts"
        assert np.mean(~got & want) <= 0.01, f"{scene_name}/{mode}: false colliding rate {np.mean(~got & want):.3f}"
        assert 0.0 < np.mean(want) < 1.0 or mode == "free"


def _with_turned_boxes(scene: Scene, rng: np.random.Generator) -> Scene:
    """``scene`` with every box obstacle turned by a random rotation about its centre (their world
    boxes are then loose bounds) plus the spheres and capsules of :func:`_with_round_obstacles`."""
    obs = tuple(dataclasses.replace(o, placement=pin.SE3(pin.exp3(rng.normal(0.0, 0.6, 3)) @ o.placement.rotation,
                                                         o.placement.translation)) if o.shape == "box" else o
                for o in scene.obstacles)
    return _with_round_obstacles(dataclasses.replace(scene, obstacles=obs))


@pytest.mark.parametrize("scene_name,margin", [("hard_truss", 0.0), ("hard_clutter_dense", 0.05),
                                               ("ssps_scene3", 0.02)])
def test_broad_phase_gives_the_pair_loops_verdicts(tcb, scene_name, margin):
    """The broad phase (boxes of chains and links against the obstacles' boxes, buckets of self pairs, the
    last colliding pair first) culls pairs, never verdicts: on turned boxes, spheres and capsules, with a
    margin, in every mode and in either order of the configurations, the verdicts equal the plain pair
    loop's; and no configuration that coal (with the same margin) calls colliding is called free."""
    rng = np.random.default_rng(29)
    scene = _with_turned_boxes(Scene.load(scene_name), rng)
    ref = ValidityChecker(tcb, scene, kernel="coal", margin=margin)
    vc = ValidityChecker(tcb, scene, margin=margin)
    if vc.kernel != "native":
        pytest.skip("no native kernel here")
    pairs = [(cp.first, cp.second) for cp in vc.gmodel.collisionPairs]
    fast = _kernel_or_skip(tcb.model, vc.gmodel, pairs, margin=margin)
    plain = _kernel_or_skip(tcb.model, vc.gmodel, pairs, margin=margin, broad_phase=False)
    assert fast._km.ngrp > 1 and fast._km.nstat > 0 and fast._km.nbuck > 1 and plain._km.ngrp == 0
    qs, qg = nominal_configurations(tcb, scene)
    Q = np.vstack([np.clip(q0 + rng.normal(0.0, s, (120, tcb.model.nq)), tcb.lower, tcb.upper)
                   for q0 in (qs, qg) for s in (0.05, 0.3)] + [np.array([tcb.random_configuration(rng) for _ in range(120)])])
    perm = rng.permutation(len(Q))
    for mode in ("held", "free"):
        act = np.array([bool(x) for x in vc._gd[mode].activeCollisionPairs], np.uint8)
        want = plain.valid(Q, act)
        got = fast.valid(Q, act)
        assert np.array_equal(got, want), f"{scene_name}/{mode}: {int(np.sum(got != want))} verdicts differ"
        assert np.array_equal(fast.valid(Q[perm], act), want[perm])
        assert all((fast.first_invalid(Q[i:i + 9], act) >= 0) == (not want[i:i + 9].all()) for i in range(0, 90, 9))
        exact = np.array([ref.first_invalid(q[None], mode) < 0 for q in Q])
        assert not np.any(got & ~exact), f"{scene_name}/{mode}: {int(np.sum(got & ~exact))} false free verdicts"
        assert 0.05 < np.mean(exact) < 0.95 or mode == "free"


def test_edge_and_first_invalid_agree(tcb):
    scene = Scene.load("hard_clutter_dense")
    vc = ValidityChecker(tcb, scene)
    pairs = [(cp.first, cp.second) for cp in vc.gmodel.collisionPairs]
    k = _kernel_or_skip(tcb.model, vc.gmodel, pairs)
    act = np.array([bool(x) for x in vc._gd["held"].activeCollisionPairs], np.uint8)
    rng = np.random.default_rng(3)
    qs, qg = nominal_configurations(tcb, scene)
    hits = 0
    for _ in range(40):
        a = np.clip(qs + rng.normal(0, 0.1, qs.size), tcb.lower, tcb.upper)
        b = np.clip(qs + rng.normal(0, 0.1, qs.size), tcb.lower, tcb.upper)
        f = rng.permutation(np.linspace(0.0, 1.0, 17))
        i = k.edge_first_invalid(a, b, f, act)
        assert i == k.first_invalid(a + f[:, None] * (b - a), act)
        hits += i >= 0
    assert 0 < hits < 40
    assert KERNEL_EPS <= 1e-4   # a slack far below any clearance (tests/test_kernel_coal_band.py: above coal's tolerance)


@pytest.mark.parametrize("scene_name", ["hard_window", "stress_posts"])
def test_object_pose_filter_native_matches_coal(tcb, scene_name):
    """The task-space filter's object test in the kernel against coal on random object poses (boxes,
    and the capsules and sphere of stress_posts): the same verdicts."""
    from optplan.planners.task_sampling import ObjectPoseFilter, _rpy_matrix

    scene = Scene.load(scene_name)
    nat, ref = ObjectPoseFilter(tcb, scene, native=True), ObjectPoseFilter(tcb, scene, native=False)
    if nat._native is None:
        pytest.skip("no native kernel here")
    rng = np.random.default_rng(4)
    X = np.hstack([rng.uniform([-1, -3, 0], [4, 3, 5], (1500, 3)), rng.uniform(-np.pi, np.pi, (1500, 3))])
    got = np.array([nat.object_free(_rpy_matrix(x), x[:3]) for x in X])
    want = np.array([ref.object_free(_rpy_matrix(x), x[:3]) for x in X])
    assert not np.any(got & ~want)
    assert np.mean(got != want) <= 0.002
    assert 0.2 < want.mean() < 0.95


@pytest.mark.parametrize("planner,options", [("tcbirrt", {"variant": "improved", "max_iterations": 400}),
                                             ("tcbirrt", {"variant": "paper", "max_iterations": 300}),
                                             ("cbirrt2", {"max_iterations": 300}),
                                             ("rrtconnect", {"max_iterations": 300, "native_search": False})])
def test_same_search_with_either_backend(tcb, planner, options):
    """A planner with ``validity_kernel="native"`` and ``"coal"`` runs the same search on the same seed
    (same status, node count and path): the kernel gives coal's verdicts on these primitives. (The
    RRT-Connect searches are the Python ones in both: the native search has its own random stream.)"""
    from optplan.planners import RRTConnectOptions, make_planner

    if planner == "tcbirrt":
        options = dict(options, regrasp=RRTConnectOptions(range=1.0, resolution=0.03, shortcut_iterations=50,
                                                          native_search=False),
                       extension="native")   # the native loop ("loop") draws from a stream of its own
    from optplan.trials import TrialGenerator

    sc = Scene.load("hard_bay")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    out = []
    for kind in ("native", "coal"):
        pl = make_planner(planner, tcb, sc, validity_kernel=kind, **options)
        if pl.checker.kernel != kind:
            pytest.skip("no native kernel here")
        res = pl.plan(tr.q_start, tr.q_goal, time_limit=100, seed=3)
        out.append((res.status.value, res.stats["nodes"], res.path.shape, float(np.abs(res.path).sum())))
    assert out[0] == out[1]


def test_without_a_compiler_the_checker_falls_back_to_coal(tcb, monkeypatch, tmp_path):
    """No C compiler and no cached library: the native kernel is unavailable, the checker (and the
    task-space filter) use coal, and TCBiRRT runs the same search as with the kernel."""
    from optplan.planners import make_planner
    from optplan.planners.kernel import native
    from optplan.planners.task_sampling import ObjectPoseFilter

    monkeypatch.setattr(native, "_LIB", [])
    monkeypatch.setenv("OPTPLAN_CACHE", str(tmp_path))
    monkeypatch.setattr(native, "build_library", lambda *a, **k: "no C compiler")
    scene = Scene.load("ssps_scene1")
    with pytest.raises(KernelUnavailable, match="no C compiler"):
        native.load_library()
    ck = ValidityChecker(tcb, scene, kernel="native")
    assert ck.kernel == "coal"
    assert ObjectPoseFilter(tcb, scene)._native is None
    from optplan.trials import TrialGenerator

    tr = TrialGenerator(tcb, scene).generate(0, 0)
    res = make_planner("tcbirrt", tcb, scene, checker=ck, variant="improved", max_iterations=1000).plan(
        tr.q_start, tr.q_goal, time_limit=100, seed=0)
    # the search tests/test_tree.py records for the same query with the native kernel (its regrasp motions balanced)
    assert (res.status.value, res.stats["nodes"], len(res.path)) == ("exact", 114, 82)
    assert float(np.abs(res.path).sum()) == pytest.approx(1906.3002102344522, rel=1e-9)


def test_a_damaged_cached_library_is_rebuilt(monkeypatch, tmp_path):
    """A damaged file where the cached library should be (never one this process has loaded: it is
    mapped) is replaced by a fresh build."""
    import hashlib

    from optplan.codegen import c_compiler
    from optplan.planners.kernel import native

    if c_compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setattr(native, "_LIB", [])
    monkeypatch.setenv("OPTPLAN_CACHE", str(tmp_path))
    from optplan.codegen import build_tag

    so = tmp_path / f"optplan_planning_kernel_{hashlib.sha1(native.SOURCE.encode()).hexdigest()[:16]}_{build_tag()}.so"
    so.write_bytes(b"not a shared library")
    lib = native.load_library()
    assert so.stat().st_size > 1000 and hasattr(lib, "kernel_first_invalid")


def test_counters_of_the_profiling_build(tcb):
    """``bench.planning_kernel.counters``: the profiling build finds the same free configurations with the
    broad phase on and off, the plain loop tests every active pair of a free configuration, and the
    broad phase leaves a fraction of them to the pair test."""
    from optplan.bench.planning_kernel import counters

    if ValidityChecker(tcb, Scene.load("hard_flip")).kernel != "native":
        pytest.skip("no native kernel here")
    c = counters(tcb, Scene.load("hard_clutter_dense"), n=400, seed=2)
    vc = ValidityChecker(tcb, Scene.load("hard_clutter_dense"))
    n_active = sum(bool(x) for x in vc._gd["held"].activeCollisionPairs)
    assert c["broad all"]["free"] == c["plain all"]["free"] == c["plain valid"]["configurations"] > 0
    assert c["plain valid"]["pairs tested"] == pytest.approx(n_active)
    assert c["broad valid"]["pairs tested"] < 0.1 * n_active
    assert c["broad valid"]["chain-obstacle box tests"] > 0 and c["plain valid"]["chain-obstacle box tests"] == 0


def test_kernel_sincos_is_within_one_ulp_of_libm():
    """The kernels' inline sine and cosine (forward kinematics of every joint) against libm (Python's math module):
    within one unit in the last place over joint-like angles, the same bits for most of them, libm's own values
    from |x| = 1e5 on, and NaN for inf and NaN."""
    import ctypes
    import math

    from optplan.planners.kernel import native

    try:
        lib = native.load_library()
    except KernelUnavailable as e:
        pytest.skip(str(e))
    rng = np.random.default_rng(7)
    x = np.concatenate([rng.uniform(-8.0, 8.0, 200_000), rng.uniform(-1e-6, 1e-6, 1000),
                        np.arange(-40, 41) * (np.pi / 4), np.nextafter(np.arange(-8, 9) * (np.pi / 2), np.inf),
                        [0.0, -0.0, 1e-300, 99_999.0, 1e5, -1e5, 3e7, 1e300]])
    x = np.ascontiguousarray(x)
    s, c = np.empty_like(x), np.empty_like(x)
    dp = ctypes.POINTER(ctypes.c_double)
    lib.kernel_sincos_api(x.ctypes.data_as(dp), ctypes.c_longlong(x.size), s.ctypes.data_as(dp), c.ctypes.data_as(dp))
    ls, lc = np.array([math.sin(v) for v in x]), np.array([math.cos(v) for v in x])
    for got, want in ((s, ls), (c, lc)):
        ulp = np.spacing(np.abs(want))
        assert np.all(np.abs(got - want) <= ulp), float(np.max(np.abs(got - want) / ulp))
        assert np.mean(got == want) > 0.9
    big = np.abs(x) >= 1e5
    assert np.array_equal(s[big], ls[big]) and np.array_equal(c[big], lc[big])
    assert math.copysign(1.0, s[x.size - 7]) == -1.0             # sin(-0) = -0
    bad = np.array([np.inf, -np.inf, np.nan])
    s, c = np.empty(3), np.empty(3)
    lib.kernel_sincos_api(bad.ctypes.data_as(dp), ctypes.c_longlong(3), s.ctypes.data_as(dp), c.ctypes.data_as(dp))
    assert np.isnan(s).all() and np.isnan(c).all()


_SEARCH_SCRIPT = """
import hashlib, json
from optplan.codegen import build_tag
from optplan.model.robot import RobotModel
from optplan.planners import make_planner
from optplan.scene import Scene
from optplan.trials import TrialGenerator
robot = RobotModel.from_name("tcbirrt_dual_arm")
sc = Scene.load("hard_truss")
tr = TrialGenerator(robot, sc).generate(2, 0)
pl = make_planner("tcbirrt", robot, sc, variant="improved")
r = pl.plan(tr.q_start, tr.q_goal, time_limit=120, seed=tr.seed)
print(json.dumps({"tag": build_tag(), "status": r.status.value, "iterations": r.stats["iterations"],
                  "regrasps": r.stats.get("regrasp_attempts", 0), "path": hashlib.sha1(r.path.tobytes()).hexdigest()}))
"""


def test_a_build_for_this_cpu_searches_as_a_portable_build(tmp_path):
    """The planning kernels built for this machine's CPU (-march=native, no fused multiply-adds) and built
    portable (OPTPLAN_NATIVE_BUILD=0) give the same search bit for bit: TCBiRRT on hard_truss (the extension's
    IK and checks, the regrasps' RRT-Connect), each in a fresh process with its own cache."""
    import json
    import os
    import subprocess
    import sys

    from optplan.codegen import c_compiler, cpu_tag

    if c_compiler() is None or cpu_tag() == "generic":
        pytest.skip("no C compiler, or the CPU cannot be identified (portable builds only)")
    out = {}
    for name, flag in (("native", "1"), ("portable", "0")):
        env = dict(os.environ, OPTPLAN_CACHE=str(tmp_path / name), OPTPLAN_NATIVE_BUILD=flag)
        done = subprocess.run([sys.executable, "-c", _SEARCH_SCRIPT], env=env, capture_output=True, text=True,
                              timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
        out[name] = json.loads(done.stdout.strip().splitlines()[-1])
        assert any(p.name.endswith(f"_{out[name]['tag']}.so") for p in (tmp_path / name).iterdir())
    assert out["native"]["tag"] == cpu_tag() and out["portable"]["tag"] == "portable"
    assert out["native"]["regrasps"] > 0
    assert {k: v for k, v in out["native"].items() if k != "tag"} == {k: v for k, v in out["portable"].items() if k != "tag"}
