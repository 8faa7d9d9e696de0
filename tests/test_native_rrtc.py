"""The native RRT-Connect (optplan.planners.kernel.rrtc): valid paths by coal's exact checks at a fine
resolution, the same success statistics as the Python search, the regrasp's subspace search, statuses,
fallback, and the single-Panda benchmark queries."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from native_rrtc_case import native_or_skip, one_arm_case

from optplan.planners import make_planner
from optplan.planners.base import Deadline
from optplan.planners.rrtconnect import edge_is_valid
from optplan.planners.validity import ValidityChecker
from optplan.scene import Scene
from optplan.trials import TrialGenerator

FINE = 0.004   # [rad] the coal re-check's step (7.5x finer than the planners' default 0.03 rad)


def _coal_valid_path(robot, scene, P, mode="free", pose=None, base=None, joints=None) -> bool:
    coal_ck = ValidityChecker(robot, scene, kernel="coal")
    f = coal_ck.validity(mode, pose, base, joints)
    return bool(f(P[0])) and all(edge_is_valid(a, b, f, FINE) for a, b in zip(P[:-1], P[1:]))


@pytest.mark.parametrize("scene_name,native", [("hard_bay", True), ("hard_clutter_dense", True),
                                               ("hard_clutter_dense", False)])
def test_paths_are_valid_by_coal(tcb, scene_name, native):
    """Both searches' paths (after their shortcuts) re-checked by coal, exactly, at 0.004 rad — the planners'
    own edge resolution here (their contract: every edge free at the points ``resolution`` apart; at the default
    0.03 rad an edge may clip a box between two of them, as seed 2 of the native search's default on
    hard_clutter_dense does, and the pipeline certifies the final path's edges for that)."""
    sc = Scene.load(scene_name)
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    pl = make_planner("rrtconnect", tcb, sc, max_iterations=3000, native_search=native, resolution=FINE)
    native_or_skip(pl.checker)
    for seed in range(3):
        res = pl.plan(tr.q_start, tr.q_goal, time_limit=60, seed=seed)
        assert res.status.value == "exact" and res.stats["search"] == ("native" if native else "python")
        assert np.allclose(res.path[0], tr.q_start) and np.allclose(res.path[-1], tr.q_goal)
        assert np.all(res.path >= tcb.lower - 1e-12) and np.all(res.path <= tcb.upper + 1e-12)
        assert _coal_valid_path(tcb, sc, res.path)


def test_same_seed_same_search_and_a_different_seed_another(tcb):
    sc = Scene.load("hard_bay")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    pl = make_planner("rrtconnect", tcb, sc, max_iterations=3000)
    native_or_skip(pl.checker)
    a, b, c = (pl.plan(tr.q_start, tr.q_goal, time_limit=60, seed=s) for s in (5, 5, 6))
    assert a.stats["nodes"] == b.stats["nodes"] and np.array_equal(a.path, b.path)
    assert not (a.path.shape == c.path.shape and np.array_equal(a.path, c.path))


def test_success_statistics_match_the_python_search(tcb):
    """Fixed seeds, a small iteration cap so that about a third of the queries succeed: the two searches
    (different random streams, same algorithm) succeed equally often within sampling noise."""
    sc = Scene.load("hard_bay")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    rates = {}
    for native in (True, False):
        pl = make_planner("rrtconnect", tcb, sc, max_iterations=15, shortcut_iterations=0, native_search=native)
        if native:
            native_or_skip(pl.checker)
        res = [pl.plan(tr.q_start, tr.q_goal, time_limit=60, seed=s) for s in range(120)]
        assert {r.stats["search"] for r in res} == {"native" if native else "python"}
        rates[native] = np.mean([r.status.value == "exact" for r in res])
    assert 0.1 < rates[False] < 0.9
    # two binomial proportions of 120 trials: a difference beyond 0.18 is > 3 standard deviations
    assert abs(rates[True] - rates[False]) <= 0.18, rates


def test_regrasp_subspace_with_the_object_fixed(tcb):
    """One arm's joints moving, the rest and the still object fixed (the regrasp's search): the path of
    the arm's joints is valid by coal in the same mode."""
    from optplan.planners.kernel.rrtc import native_rrt_connect

    sc, tr, ck, idx, M, base, rng = one_arm_case(tcb, "ssps_scene1", 0)
    coal_ck = ValidityChecker(tcb, sc, kernel="coal")
    pairs = tuple(sorted(ck.grasp_contacts(base, M)))   # the hands touch the object at their grasps
    with ck.exempt(pairs), coal_ck.exempt(pairs):
        f = ck.validity("fixed", M, base=base, joints=idx)
        assert f(base[idx])
        goal = None
        for _ in range(2000):   # a valid goal for this arm
            x = rng.uniform(tcb.lower[idx], tcb.upper[idx])
            if f(x):
                goal = x
                break
        assert goal is not None
        got = native_rrt_connect(base[idx], goal, tcb.lower[idx], tcb.upper[idx], f, rng, Deadline(30.0), range_=1.0,
                                 resolution=0.03, max_iterations=5000, shortcut_iterations=50)
        assert got is not None and got.status == "found", got and got.status
        P = np.array(got.path)
        assert P.shape[1] == idx.size and np.allclose(P[0], base[idx]) and np.allclose(P[-1], goal)
        g = coal_ck.validity("fixed", M, base, idx)
        assert g(P[0]) and all(edge_is_valid(a, b, g, FINE) for a, b in zip(P[:-1], P[1:]))


def test_statuses_iteration_cap_and_time_limit(tcb):
    from optplan.planners.kernel.rrtc import native_rrt_connect

    sc = Scene.load("hard_window")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    ck = ValidityChecker(tcb, sc)
    native_or_skip(ck)
    f = ck.validity("free")
    a = native_rrt_connect(tr.q_start, tr.q_goal, tcb.lower, tcb.upper, f, np.random.default_rng(0), Deadline(60.0),
                           range_=1.0, resolution=0.03, max_iterations=3)
    assert a is not None and a.status == "iteration cap" and a.iterations == 3 and a.path is None
    b = native_rrt_connect(tr.q_start, tr.q_goal, tcb.lower, tcb.upper, f, np.random.default_rng(0), Deadline(0.0),
                           range_=1.0, resolution=0.03)
    assert b is not None and b.status == "time limit" and b.path is None and b.iterations <= 8
    pl = make_planner("rrtconnect", tcb, sc, max_iterations=3)
    res = pl.plan(tr.q_start, tr.q_goal, time_limit=60, seed=0)
    assert res.status.value == "failed" and res.path.shape[0] == 0 and res.stats["search"] == "native"


def test_coal_checker_falls_back_to_the_python_search(tcb):
    sc = Scene.load("hard_bay")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    pl = make_planner("rrtconnect", tcb, sc, max_iterations=2000, validity_kernel="coal")
    res = pl.plan(tr.q_start, tr.q_goal, time_limit=60, seed=0)
    assert res.stats["search"] == "python" and res.status.value == "exact"


def test_bad_native_search_option():
    from optplan.planners import RRTConnectOptions

    with pytest.raises(ValueError, match="native_search"):
        RRTConnectOptions(native_search="yes")


def test_tcbirrt_regrasps_run_natively(tcb):
    """The improved TCBiRRT on an SSPS query: its regrasps use the native search and the query succeeds."""
    sc = Scene.load("ssps_scene1")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    pl = make_planner("tcbirrt", tcb, sc, variant="improved", max_iterations=1000)
    native_or_skip(pl.checker)
    calls = []
    import optplan.planners.kernel.rrtc as rrtc

    real = rrtc.native_rrt_connect

    def spy(*a, **k):
        got = real(*a, **k)
        calls.append(got is not None)
        return got

    mp = pytest.MonkeyPatch()
    mp.setattr(rrtc, "native_rrt_connect", spy)
    try:
        res = pl.plan(tr.q_start, tr.q_goal, time_limit=100, seed=0)
    finally:
        mp.undo()
    assert res.status.value == "exact"
    assert res.stats["regrasp_attempts"] > 0 and calls and all(calls)


def test_single_panda_queries_solved_and_valid():
    from optplan.model.example_robots import example_robots_available

    if not example_robots_available():
        pytest.skip("example-robot-data not installed (pip install 'optplan[robots]')")
    from optplan.bench.panda_rrtc import GOAL, START, load_single_panda, queries, run_optplan

    robot = load_single_panda()
    assert robot.nq == 7
    for kind in ("cage", "boxes"):
        (sc, ck), = queries(robot, kind, 1, seed=0)
        native_or_skip(ck)
        r = run_optplan(robot, sc, ck, 0, native=True, shortcut_iterations=20)
        assert r["status"] == "exact" and r["search"] == "native"
        assert np.allclose(r["path"][0], START) and np.allclose(r["path"][-1], GOAL)
        assert _coal_valid_path(robot, sc, r["path"])
    assert pin.SE3 is not None


def test_vamp_peer_without_vamp_says_so(monkeypatch, capsys):
    from optplan.bench import vamp_peer

    monkeypatch.setattr(vamp_peer, "vamp_available", lambda: None)
    assert vamp_peer.main(["--queries", "1"]) == 0
    assert "vamp is not importable" in capsys.readouterr().out


def test_vamp_peer_pairs_when_vamp_is_there(capsys):
    pytest.importorskip("vamp")
    from optplan.model.example_robots import example_robots_available

    if not example_robots_available():
        pytest.skip("example-robot-data not installed (pip install 'optplan[robots]')")
    from optplan.bench import vamp_peer

    assert vamp_peer.main(["--queries", "2", "--scenes", "boxes"]) == 0
    out = capsys.readouterr().out
    assert "optplan / vamp" in out and "2/2 solved" in out


@pytest.mark.parametrize("mode", ["free", "fixed"])
@pytest.mark.parametrize("scene_name", ["hard_clutter_dense", "hard_truss"])
def test_broad_phase_gives_the_kernels_and_coals_verdicts(tcb, mode, scene_name):
    """The native search's check (groups of geometries bounded by spheres, an obstacle's exact distance from a
    group's sphere, then the kernel's pairs) on random configurations near and far from collisions: the kernel's
    verdict on every one, and never free where coal collides (hard_truss: beams 4-6 m long, whose bounding spheres
    meet nearly every link's)."""
    from optplan.planners.kernel.rrtc import broad_phase_valid

    sc = Scene.load(scene_name)
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    ck = ValidityChecker(tcb, sc)
    native_or_skip(ck)
    rng = np.random.default_rng(7)
    X = np.vstack([rng.uniform(tcb.lower, tcb.upper, (1500, tcb.nq)),
                   tr.q_start + rng.normal(0.0, 0.15, (1500, tcb.nq))])
    pose = tr.object_start if mode == "fixed" else None
    f = ck.validity(mode, pose)
    got = broad_phase_valid(f, X)
    assert np.array_equal(got, ck.valid_batch(X, mode, pose))
    coal_ck = ValidityChecker(tcb, sc, kernel="coal")
    want = coal_ck.valid_batch(X, mode, pose)
    assert not np.any(got & ~want)
    assert 0.05 < got.mean() < 0.95


def test_halton_points_are_the_radical_inverses():
    from optplan.planners.rrtconnect import halton_point

    assert np.allclose(halton_point(1, np.zeros(3)), [1 / 2, 1 / 3, 1 / 5])
    assert np.allclose(halton_point(6, np.zeros(2)), [3 / 8, 2 / 9])           # 6 = 110b, 20 in base 3
    assert np.allclose(halton_point(1, np.array([0.75, 0.0])), [0.25, 1 / 3])  # shifted modulo 1
    # low discrepancy: 512 points of the 7-D sequence fill the 2^7 orthants of the unit cube more evenly than
    # independent draws, whose counts are binomial (variance 512 p (1 - p) = 3.97 with p = 1/128)
    pts = np.array([halton_point(i, np.full(7, 0.3)) for i in range(1, 513)])
    counts = np.bincount((pts >= 0.5).astype(int) @ (1 << np.arange(7)), minlength=128)
    assert counts.sum() == 512 and counts.var() < 0.65 * 512 * (1 / 128) * (1 - 1 / 128)
    with pytest.raises(ValueError, match="sampler"):
        from optplan.planners.rrtconnect import RRTConnectOptions
        RRTConnectOptions(sampler="sobol")


@pytest.mark.parametrize("native", [True, False])
def test_halton_sampler_paths_valid_and_seeded(tcb, native):
    """Both searches with the Halton sampler: valid paths by coal at 0.004 rad, the same search for a seed,
    another for another seed (the shift is drawn from the planner's generator)."""
    sc = Scene.load("hard_clutter_dense")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    pl = make_planner("rrtconnect", tcb, sc, max_iterations=3000, sampler="halton", native_search=native)
    if native:
        native_or_skip(pl.checker)
    a, b, c = (pl.plan(tr.q_start, tr.q_goal, time_limit=60, seed=s) for s in (5, 5, 6))
    for r in (a, c):
        assert r.status.value == "exact" and r.stats["search"] == ("native" if native else "python")
        assert _coal_valid_path(tcb, sc, r.path)
    assert np.array_equal(a.path, b.path)
    assert not (a.path.shape == c.path.shape and np.array_equal(a.path, c.path))


@pytest.mark.parametrize("flag_name", ["rrtc_use_static_part", "rrtc_use_layout"])
@pytest.mark.parametrize("collide_static", [False, True])
def test_static_part_gives_the_same_search(tcb, collide_static, flag_name):
    """A regrasp's search (one arm, the other arm and the object still): placing the still part once and
    checking its pairs once gives the same search as checking the whole model every time — the same status,
    counts and path; with an obstacle on the still arm every configuration collides."""
    import ctypes
    import dataclasses

    from optplan.planners.kernel.rrtc import load_rrtc_library, native_rrt_connect
    from optplan.scene import Obstacle

    sc = Scene.load("hard_window")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    from optplan.constraints.closed_chain import ClosedChainKinematics

    kin = ClosedChainKinematics(tcb, sc.object.grasps)
    base = tr.q_start.copy()
    if collide_static:   # a sphere on the still arm's elbow link
        data = tcb.model.createData()
        pin.forwardKinematics(tcb.model, data, base)
        j = int(np.flatnonzero(np.asarray(tcb.model.idx_qs) == int(kin.idx[1][3]))[0])
        sc = dataclasses.replace(sc, obstacles=(*sc.obstacles, Obstacle(
            "on_still_arm", "sphere", pin.SE3(np.eye(3), data.oMi[j].translation), radius=0.05)))
    ck = ValidityChecker(tcb, sc)
    native_or_skip(ck)
    idx = np.asarray(kin.idx[0])
    M = tr.object_start
    flag = ctypes.c_int.in_dll(load_rrtc_library(), flag_name)
    pairs = tuple(sorted(ck.grasp_contacts(base, M)))
    out = []
    with ck.exempt(pairs):
        f = ck.validity("fixed", M, base=base, joints=idx)
        assert f(base[idx]) != collide_static
        rng = np.random.default_rng(1)
        goal = next(x for x in (rng.uniform(tcb.lower[idx], tcb.upper[idx]) for _ in range(5000))
                    if collide_static or f(x))
        for on in (1, 0):
            flag.value = on
            try:
                got = native_rrt_connect(base[idx], goal, tcb.lower[idx], tcb.upper[idx], f, np.random.default_rng(3),
                                         Deadline(30.0), range_=1.0, resolution=0.03, max_iterations=3000,
                                         shortcut_iterations=20)
            finally:
                flag.value = 1
            assert got is not None
            out.append(got)
    a, b = out
    assert (a.status, a.iterations, a.nodes, a.checks) == (b.status, b.iterations, b.nodes, b.checks)
    assert (a.path is None) == (b.path is None)
    if a.path is not None:
        assert np.array_equal(np.array(a.path), np.array(b.path))
    assert a.status == ("iteration cap" if collide_static else "found")


@pytest.mark.parametrize("opts", [{"dynamic_domain": 6.0}, {"balance": 1.0}, {"connect": "new"},
                                  {"dynamic_domain": 6.0, "balance": 1.0, "connect": "new", "sampler": "halton"}])
def test_dynamic_domain_balance_and_vamps_connect_give_valid_seeded_paths(tcb, opts):
    """VAMP's RRT-Connect heuristics in the native search: coal-valid paths (no shortcuts: every edge is a tree
    edge of at most ``range``), the same search for a seed, samples drawn again under a dynamic domain."""
    sc = Scene.load("hard_clutter_dense")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    pl = make_planner("rrtconnect", tcb, sc, max_iterations=20000, shortcut_iterations=0, **opts)
    native_or_skip(pl.checker)
    a, b = (pl.plan(tr.q_start, tr.q_goal, time_limit=60, seed=s) for s in (3, 3))
    assert a.status.value == "exact" and a.stats["search"] == "native"
    assert np.array_equal(a.path, b.path) and a.stats["iterations"] == b.stats["iterations"]
    assert np.allclose(a.path[0], tr.q_start) and np.allclose(a.path[-1], tr.q_goal)
    steps = np.linalg.norm(np.diff(a.path, axis=0), axis=1)
    assert np.all(steps <= pl.options.range * (1 + 1e-9))
    assert _coal_valid_path(tcb, sc, a.path)
    if "dynamic_domain" in opts:
        assert a.stats["rejected"] > 0


def test_a_dynamic_domain_and_balance_that_never_bind_give_the_plain_search(tcb):
    """A radius larger than any joint distance never rejects a sample, and a ratio no size difference reaches
    never keeps a tree growing: the same search as with both off, node for node."""
    sc = Scene.load("hard_bay")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    plain = make_planner("rrtconnect", tcb, sc, max_iterations=3000, balance=0.0)
    native_or_skip(plain.checker)
    wide = make_planner("rrtconnect", tcb, sc, max_iterations=3000, dynamic_domain=1e6, dynamic_domain_min=1e6,
                        balance=1e9)
    a, b = (p.plan(tr.q_start, tr.q_goal, time_limit=60, seed=7) for p in (plain, wide))
    assert a.status == b.status and a.stats["iterations"] == b.stats["iterations"]
    assert a.stats["nodes"] == b.stats["nodes"] and np.array_equal(a.path, b.path)
    assert b.stats["rejected"] == 0


def test_vamp_heuristics_options_are_checked():
    from optplan.planners.rrtconnect import RRTConnectOptions

    for bad in ({"dynamic_domain": -1.0}, {"dynamic_domain_alpha": 1.0}, {"balance": float("nan")},
                {"connect": "both"}, {"dynamic_domain": 2.0, "native_search": False},
                {"connect": "new", "native_search": False}):
        with pytest.raises(ValueError, match="RRTConnectOptions"):
            RRTConnectOptions(**bad)


@pytest.mark.parametrize("scene_name", ["hard_truss", "hard_clutter_dense"])
def test_laid_out_blocks_give_the_same_search(tcb, scene_name):
    """The blocks laid out per moving group (still partners as arrays, tested in one pass) against the blocks in
    their order: the same search of the whole robot (status, counts, path), with several planner seeds."""
    import ctypes

    from optplan.planners.kernel.rrtc import load_rrtc_library

    sc = Scene.load(scene_name)
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    pl = make_planner("rrtconnect", tcb, sc, max_iterations=2000, shortcut_iterations=10)
    native_or_skip(pl.checker)
    flag = ctypes.c_int.in_dll(load_rrtc_library(), "rrtc_use_layout")
    for seed in range(3):
        out = []
        for on in (1, 0):
            flag.value = on
            try:
                out.append(pl.plan(tr.q_start, tr.q_goal, time_limit=60, seed=seed))
            finally:
                flag.value = 1
        a, b = out
        assert a.status == b.status and a.stats["iterations"] == b.stats["iterations"]
        assert a.stats["collision_checks"] == b.stats["collision_checks"] and np.array_equal(a.path, b.path)


@pytest.mark.parametrize("scene_name", ["hard_truss", "hard_clutter_dense"])
def test_search_check_of_a_regrasp_query_gives_the_kernels_and_coals_verdicts(tcb, scene_name):
    """The check as a regrasp's query sets it up (arm A's joints searched; arm B and the object still, placed
    once; moving geometries placed at first use; two joints' groups tested member by member against the other's
    sphere): the kernel's verdict on 3,000 configurations near and far from the start, never free where coal
    collides."""
    from optplan.planners.kernel.rrtc import search_check_valid

    sc, tr, ck, idx, pose, base, rng = one_arm_case(tcb, scene_name, 5)
    X = np.vstack([rng.uniform(tcb.lower[idx], tcb.upper[idx], (1500, len(idx))),
                   base[idx] + rng.normal(0.0, 0.2, (1500, len(idx)))])
    full = np.tile(base, (len(X), 1))
    full[:, idx] = X
    f = ck.validity("fixed", pose)
    got = search_check_valid(f, idx, base, X)
    assert np.array_equal(got, ck.valid_batch(full, "fixed", pose))
    want = ValidityChecker(tcb, sc, kernel="coal").valid_batch(full, "fixed", pose)
    assert not np.any(got & ~want)
    assert 0.05 < got.mean() < 0.95


def test_vamp_environment_gives_vamps_own_verdicts():
    """Turned boxes, capsules and spheres mapped into VAMP's environment, and VAMP's sphere Panda loaded with VAMP's
    self-collision pairs: VAMP's check and optplan's (native and coal) agree on 3,000 random configurations. Needs
    ``vamp`` and VAMP's source tree (``OPTPLAN_VAMP_SOURCE``: its ``resources/panda`` holds the sphere robot)."""
    import os
    from pathlib import Path

    vamp = pytest.importorskip("vamp")
    from optplan.model.example_robots import example_robots_available

    src = os.environ.get("OPTPLAN_VAMP_SOURCE")
    if not src or not example_robots_available():
        pytest.skip("set OPTPLAN_VAMP_SOURCE to VAMP's source tree (and install optplan[robots])")
    from optplan.bench.panda_rrtc import load_single_panda
    from optplan.bench.vamp_peer import vamp_environment
    from optplan.scene import Obstacle

    robot = load_single_panda(Path(src) / "resources/panda/panda_spherized.urdf")
    sc = Scene(name="vamp_map", robot=None, obstacles=(
        Obstacle("shelf", "box", pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.5, 0.9), np.array([0.45, 0.1, 0.5])),
                 size=(0.5, 0.3, 0.04)),
        Obstacle("bar", "capsule", pin.SE3(pin.rpy.rpyToMatrix(1.1, 0.2, -0.4), np.array([-0.1, -0.45, 0.6])),
                 radius=0.05, length=0.5),
        Obstacle("ball", "sphere", pin.SE3(np.eye(3), np.array([-0.4, 0.3, 0.8])), radius=0.15)))
    env = vamp_environment(vamp, sc)
    rng = np.random.default_rng(2)
    Q = rng.uniform(robot.lower, robot.upper, (3000, robot.nq))
    theirs = np.array([bool(vamp.panda.validate([float(v) for v in q], env)) for q in Q])
    ours = ValidityChecker(robot, sc).valid_batch(Q, "free")
    exact = ValidityChecker(robot, sc, kernel="coal").valid_batch(Q, "free")
    assert 0.2 < theirs.mean() < 0.95
    assert np.array_equal(ours, theirs) and np.array_equal(exact, theirs)


def test_vamp_peer_mbm_bad_path_says_so(monkeypatch, capsys, tmp_path):
    """``--mbm`` with a path that holds no problems: a one-line error and exit status 2, no traceback."""
    from optplan.bench import vamp_peer
    from optplan.model.example_robots import example_robots_available

    if not example_robots_available():
        pytest.skip("example-robot-data not installed (pip install 'optplan[robots]')")
    monkeypatch.setattr(vamp_peer, "vamp_available", lambda: object())
    assert vamp_peer.main(["--mbm", str(tmp_path / "nothing.tar.bz2")]) == 2
    assert "neither VAMP's problems.tar.bz2 nor a directory" in capsys.readouterr().out


def test_native_seed_is_numpys_generator_draw():
    """The seed a plan hands the native search is the 63-bit value ``np.random.default_rng(seed).integers(0,
    2**63)`` draws (computed natively: SeedSequence, PCG64, Lemire's bound), for seeds of one and two 32-bit words
    and the ends of the range."""
    from optplan.planners.kernel import KernelUnavailable
    from optplan.planners.kernel.rrtc import load_rrtc_library

    try:
        lib = load_rrtc_library()
    except KernelUnavailable as e:
        pytest.skip(str(e))
    rng = np.random.default_rng(11)
    seeds = [0, 1, 2, 2**32 - 1, 2**32, 2**32 + 1, 2**62, 2**63 - 1, *range(3, 300),
             *(int(v) for v in rng.integers(0, 2**32, 300)), *(int(v) for v in rng.integers(0, 2**63, 300))]
    got = [int(lib.rrtc_numpy_seed(s)) for s in seeds]
    want = [int(np.random.default_rng(s).integers(0, 2**63)) for s in seeds]
    assert got == want


def test_a_plans_seed_gives_the_search_of_its_generator(tcb):
    """RRTConnect.plan(seed=s) runs the native search without a NumPy Generator: the same search (path, iterations,
    checks) as the native call with ``np.random.default_rng(s)``; a seed outside [0, 2**63) without a Generator is
    refused."""
    from optplan.planners.kernel.rrtc import native_rrt_connect
    from optplan.planners.rrtconnect import _tune

    sc = Scene.load("hard_clutter_dense")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    pl = make_planner("rrtconnect", tcb, sc, max_iterations=3000)
    native_or_skip(pl.checker)
    f = pl.checker.validity("free")
    for seed in (0, 7, 2**40 + 3):
        res = pl.plan(tr.q_start, tr.q_goal, time_limit=60, seed=seed)
        o = pl.options
        ref = native_rrt_connect(tr.q_start, tr.q_goal, tcb.lower, tcb.upper, f, np.random.default_rng(seed),
                                 Deadline(60.0), range_=o.range, resolution=o.resolution, max_iterations=3000,
                                 shortcut_iterations=o.shortcut_iterations, sampler=o.sampler, tune=_tune(o))
        assert ref is not None and ref.path is not None and res.status.value == "exact"
        assert np.array_equal(res.path, ref.path)
        assert res.stats["iterations"] == ref.iterations and res.stats["collision_checks"] == ref.checks
    with pytest.raises(ValueError, match="seed"):
        native_rrt_connect(tr.q_start, tr.q_goal, tcb.lower, tcb.upper, f, None, Deadline(1.0), range_=1.0,
                           resolution=0.03, seed=-1)


def test_native_plan_checks_its_ends(tcb):
    """The native plan checks the start and the goal itself: out of the limits or in collision is INVALID_START /
    INVALID_GOAL, as the Python search reports them; the checker's count holds those checks, the result's
    ``collision_checks`` only the search's."""
    from optplan.planners.base import PlanStatus

    sc = Scene.load("hard_clutter_dense")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    ck = ValidityChecker(tcb, sc)
    native_or_skip(ck)
    rng = np.random.default_rng(3)
    q_col = next(q for q in (rng.uniform(tcb.lower, tcb.upper) for _ in range(1000)) if not ck.is_valid_free(q))
    out = tr.q_start.copy()
    out[2] = tcb.upper[2] + 1e-6
    edge = tr.q_start.copy()
    edge[2] = tcb.upper[2] + 1e-10   # within the 1e-9 of the limits' check
    for native in (True, False):
        pl = make_planner("rrtconnect", tcb, sc, max_iterations=2000, native_search=native)
        for bad in (q_col, out):
            a = pl.plan(bad, tr.q_goal, time_limit=30, seed=0)
            b = pl.plan(tr.q_start, bad, time_limit=30, seed=0)
            assert (a.status, b.status) == (PlanStatus.INVALID_START, PlanStatus.INVALID_GOAL), (native, a.status, b.status)
            assert a.path.shape == (0, tcb.nq) and b.path.shape == (0, tcb.nq)
        if ck.is_valid_free(edge):
            assert pl.plan(edge, tr.q_goal, time_limit=30, seed=0).status is not PlanStatus.INVALID_START
    pl = make_planner("rrtconnect", tcb, sc, max_iterations=2000)
    n0 = pl.checker.n_checks
    res = pl.plan(tr.q_start, tr.q_goal, time_limit=30, seed=1)
    assert res.stats["search"] == "native" and pl.checker.n_checks - n0 == res.stats["collision_checks"] + 2
