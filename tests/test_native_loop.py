"""TCBiRRT's native loop (``extension="loop"``): the native random stream, the task-space sampler and the
object lead path in C (optplan.planners.kernel.sampler) against independent references — distribution
tests, Pinocchio's rotations, the Python filter on coal — and whole searches paired with the Python
sampler's on fixed seeds (success and path length no worse)."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from scipy import stats

from optplan.planners.kernel.extend import nearest_available

pytestmark = pytest.mark.skipif(not nearest_available(), reason="no C compiler: the native sampler is not built")


def _box(robot):
    from optplan.planners.tcbirrt_options import TCBiRRTOptions, reach_scaled_workspace

    lo, hi, _ = reach_scaled_workspace(robot, TCBiRRTOptions())
    return np.asarray(lo, float), np.asarray(hi, float)


def test_native_random_stream_is_uniform_and_normal_and_seeded():
    from optplan.planners.kernel.sampler import NativeRandom

    r = NativeRandom(np.random.default_rng(5))
    u = np.array([r.uniform() for _ in range(20000)])
    z = np.array([r.normal() for _ in range(20000)])
    assert stats.kstest(u, "uniform").pvalue > 1e-3
    assert stats.kstest(z, "norm").pvalue > 1e-3
    assert u.min() >= 0.0 and u.max() < 1.0
    a, b = NativeRandom(123), NativeRandom(123)
    assert [a.uniform() for _ in range(5)] == [b.uniform() for _ in range(5)]
    assert NativeRandom(np.random.default_rng(1)).uniform() == NativeRandom(np.random.default_rng(1)).uniform()
    with pytest.raises(ValueError, match=r"seed in \[0, 2\*\*64\)"):
        NativeRandom(-1)


def test_uniform_draws_fill_the_box_and_geodesic_draws_lie_on_the_geodesic(tcb):
    """Box draws uniform per coordinate; with geodesic_probability 1 and a tiny spread the orientation is
    R0 exp(t w) for t in [0, 1] (RPY read back through Pinocchio)."""
    from optplan.planners.kernel.sampler import NativeRandom, NativeTaskSampler
    from optplan.planners.task_sampling import _rpy_matrix

    lo, hi = _box(tcb)
    s = NativeTaskSampler(None, lo, hi, NativeRandom(7))
    X = np.array([s.sample() for _ in range(4000)])
    for k in range(6):
        assert stats.kstest((X[:, k] - lo[k]) / (hi[k] - lo[k]), "uniform").pvalue > 1e-3
    xa, xb = np.r_[0.1, 0.2, 0.3, 0.4, -0.5, 2.9], np.r_[0.0, 0.0, 0.5, -2.8, 0.3, -2.9]
    g = NativeTaskSampler(None, lo, hi, NativeRandom(8), geodesic_probability=1.0, geodesic_sigma=1e-9,
                          endpoints=(xa, xb))
    R0 = _rpy_matrix(xa)
    w = np.asarray(pin.log3(R0.T @ _rpy_matrix(xb)))
    ts = []
    for _ in range(300):
        xi = g.sample()
        assert np.all(xi[3:] >= -np.pi - 1e-12) and np.all(xi[3:] <= np.pi + 1e-12)
        v = np.asarray(pin.log3(R0.T @ _rpy_matrix(xi)))
        t = float(v @ w / (w @ w))
        assert np.allclose(v, t * w, atol=1e-6)
        ts.append(t)
    assert stats.kstest(ts, "uniform").pvalue > 1e-3


def test_goal_bias_guide_and_nearest(tcb):
    from optplan.planners.kernel.sampler import NativeRandom, NativeTaskSampler
    from optplan.planners.tree import Tree

    lo, hi = _box(tcb)
    rng = np.random.default_rng(3)
    other = Tree(rng.uniform(lo, hi), cap=4)
    mine = Tree(rng.uniform(lo, hi), cap=4)
    for _ in range(60):
        other.add(rng.uniform(lo, hi), int(rng.integers(other.n)))
        mine.add(rng.uniform(lo, hi), int(rng.integers(mine.n)))
    other.kill(20)
    mine.kill(30)
    s = NativeTaskSampler(None, lo, hi, NativeRandom(1), goal_bias=1.0)
    live = {tuple(x) for x in other.live_keys()}
    picked = set()
    for _ in range(500):
        xi, i = s.sample_near(mine.X, mine.n, mine.alive, other.X, other.n, other.alive)
        assert tuple(xi) in live
        assert i == mine.nearest(xi)
        picked.add(tuple(xi))
    assert len(picked) > 0.8 * len(live)   # every live node can be drawn
    assert s.stats["goal_samples"] == 500
    guide = rng.uniform(lo, hi, size=(5, 6))
    gs = NativeTaskSampler(None, lo, hi, NativeRandom(2), guide_probability=1.0, guide_sigma=(0.05, 0.05))
    gs.guide = guide
    D = np.array([gs.sample() for _ in range(2000)])
    k = np.argmin(np.linalg.norm(D[:, None, :] - guide[None], axis=2), axis=1)
    res = (D - guide[k]) / 0.05
    assert stats.kstest(res.ravel(), "norm").pvalue > 1e-3
    with pytest.raises(ValueError, match="guide: expected an"):
        gs.guide = np.zeros((3, 5))


def test_filtered_and_bridge_samples_pass_the_coal_filter(tcb):
    """Filtered draws and bridge midpoints pass the filter as coal computes it (the native kernel is
    conservative); the filter's rejection rate matches the Python sampler's."""
    from optplan.planners.kernel.sampler import NativeRandom, NativeTaskSampler
    from optplan.planners.task_sampling import ObjectPoseFilter, TaskSampler, _rpy_matrix
    from optplan.scene import Scene

    sc = Scene.load("hard_window")
    f = ObjectPoseFilter(tcb, sc)
    ref = ObjectPoseFilter(tcb, sc, native=False)
    if f._xi_native is None:
        pytest.skip("no native filter here")
    lo, hi = _box(tcb)
    s = NativeTaskSampler(f, lo, hi, NativeRandom(4), filter_tries=30)
    py = TaskSampler(f, lo, hi, filter_tries=30)
    rng = np.random.default_rng(4)
    n = 600
    ok_n = sum(ref(_rpy_matrix(x), x[:3]) for x in (s.sample() for _ in range(n)))
    ok_p = sum(ref(_rpy_matrix(x), x[:3]) for x in (py.sample(rng) for _ in range(n)))
    assert ok_n >= ok_p - 4 * np.sqrt(n * 0.25) and ok_n > 0.5 * n
    rej_n, rej_p = s.stats["filter_rejections"] / n, py.stats["filter_rejections"] / n
    assert abs(rej_n - rej_p) < 0.25 * max(rej_p, 1.0)
    b = NativeTaskSampler(f, lo, hi, NativeRandom(5), bridge_probability=1.0, bridge_tries=60)
    for _ in range(200):
        before = b.stats["bridge_samples"]
        xi = b.sample()
        if b.stats["bridge_samples"] > before:
            assert ref(_rpy_matrix(xi), xi[:3])
    pb = TaskSampler(f, lo, hi, bridge_probability=1.0, bridge_tries=60)
    for _ in range(200):
        pb.sample(rng)
    k_n, k_p = b.stats["bridge_samples"], pb.stats["bridge_samples"]   # the same success rate (binomial, 200 draws)
    assert k_n > 0 and abs(k_n - k_p) <= 4 * np.sqrt(200 * 0.25)
    calls = f.n_calls
    b.sync_filter_calls()
    assert f.n_calls > calls


def test_native_lead_path_is_valid_under_coal(tcb):
    """The lead path joins the start and goal object poses of a hard_window trial, and each of its poses and
    segments passes the coal filter."""
    from optplan.constraints.closed_chain import ClosedChainKinematics
    from optplan.planners.base import Deadline
    from optplan.planners.kernel.sampler import NativeRandom
    from optplan.planners.task_sampling import ObjectPoseFilter, _rpy_matrix, object_lead_path
    from optplan.planners.task_space import xi_from_pose
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    sc = Scene.load("hard_window")
    f = ObjectPoseFilter(tcb, sc)
    ref = ObjectPoseFilter(tcb, sc, native=False)
    if f._xi_native is None:
        pytest.skip("no native filter here")
    ref._xi_native = None
    kin = ClosedChainKinematics(tcb, sc.object.grasps)
    lo, hi = _box(tcb)
    found = 0
    for t in range(3):
        tr = TrialGenerator(tcb, sc).generate(t, 0)
        a, b = xi_from_pose(kin.object_pose(tr.q_start)), xi_from_pose(kin.object_pose(tr.q_goal))
        path = object_lead_path(f, a, b, lo, hi, np.random.default_rng(t), Deadline(5.0, "cpu"),
                                native_rng=NativeRandom(t))
        if path is None:
            continue
        found += 1
        assert np.allclose(path[0], a) and np.allclose(path[-1], b)
        assert np.all(np.abs(np.diff(path, axis=0)).max(axis=1) <= 0.1 + 1e-9)
        for x in path:
            assert ref(_rpy_matrix(x), x[:3])
    assert found >= 2


def _path_length(res) -> float:
    return float(np.linalg.norm(np.diff(res.path, axis=0), axis=1).sum())


def _queries(tcb, scene_name, kinds, n, time_limit=5.0):
    from optplan.constraints.closed_chain import ClosedChainKinematics
    from optplan.planners import TCBiRRT, TCBiRRTOptions, ValidityChecker
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    sc = Scene.load(scene_name)
    ck, kin = ValidityChecker(tcb, sc), ClosedChainKinematics(tcb, sc.object.grasps)
    pls = {k: TCBiRRT(tcb, sc, TCBiRRTOptions(variant="improved", extension=k), checker=ck, kinematics=kin)
           for k in kinds}
    if pls["loop"]._ext is None:
        pytest.skip("the native extension is not available here")
    gen = TrialGenerator(tcb, sc)
    out: dict[str, list] = {k: [] for k in kinds}
    for i in range(n):
        tr = gen.generate(i % 10, i // 10)
        for k in kinds:
            out[k].append(pls[k].plan(tr.q_start, tr.q_goal, time_limit=time_limit, seed=1000 + i, clock="cpu"))
    return out


def test_loop_search_is_reproducible_and_uses_the_native_stream(tcb):
    res = _queries(tcb, "ssps_scene1", ("loop",), 2)["loop"]
    again = _queries(tcb, "ssps_scene1", ("loop",), 2)["loop"]
    for a, b in zip(res, again):
        assert a.status == b.status and a.stats["iterations"] == b.stats["iterations"]
        assert np.array_equal(a.path, b.path)
    assert all(r.stats["samples"] > 0 for r in res)


@pytest.mark.slow
@pytest.mark.parametrize("scene_name", ["ssps_scene1", "hard_corridor"])
def test_loop_success_and_path_length_no_worse_than_the_python_sampler_paired(tcb, scene_name):
    """50 paired queries (10 trials x 5 seeds): the native loop against ``extension="native"`` (the Python
    sampler and restarts; the same search as ``"python"``): success no lower, median path length within 10 %."""
    got = _queries(tcb, scene_name, ("loop", "native"), 50)
    ok = {k: [r.status.value == "exact" for r in v] for k, v in got.items()}
    assert sum(ok["loop"]) >= sum(ok["native"]) - 1
    both = [i for i in range(50) if ok["loop"][i] and ok["native"][i]]
    ln = np.median([_path_length(got["loop"][i]) for i in both])
    lp = np.median([_path_length(got["native"][i]) for i in both])
    assert ln <= 1.1 * lp


def test_bench_lead_path_costs_rows():
    from optplan.bench.tcbirrt_native import lead_path_costs

    got = lead_path_costs("ssps_scene1", trials=2, budget=2.0)
    assert set(got) == {"native", "python"}
    for v in got.values():
        assert v["found"] == 2 and v["median_ms"] > 0 and v["median_waypoints"] >= 2
