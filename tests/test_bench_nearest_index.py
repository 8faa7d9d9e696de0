import numpy as np
import pytest


def test_nearest_index_bench_rows_and_the_same_answers():
    """The benchmark's cases run on a small tree (its own check: the index's answers are the scan's)."""
    from optplan.planners.kernel.native import KernelUnavailable

    try:
        from optplan.bench.nearest_index import nearest_costs
        rows = nearest_costs(1500, 40, seed=3)
    except (KernelUnavailable, OSError) as e:
        pytest.skip(f"no native kernel here: {e}")
    assert [(r["keys"], r["queries"]) for r in rows] == [("gauss", "near"), ("gauss", "far"), ("rrt", "near"),
                                                        ("rrt", "far")]
    assert all(r["kd_us"] > 0 and r["scan_us"] > 0 and r["ckdtree_us"] > 0 for r in rows)
    assert all(r["kd_c_us"] > 0 and r["scan_c_us"] > 0 and r["ckdtree_batch_us"] > 0 for r in rows)


def test_nearest_batch_answers_as_nearest_one_by_one_and_rejects_bad_input():
    from optplan.planners.kernel.extend import kd_index, nearest, nearest_batch
    from optplan.planners.kernel.native import KernelUnavailable

    rng = np.random.default_rng(8)
    X = rng.normal(size=(3000, 6))
    Q = rng.normal(size=(50, 6)) * 3
    alive = rng.random(3000) < 0.8
    try:
        got = nearest_batch(X, 2500, Q, alive, kd_index(3000, 6))
    except (KernelUnavailable, OSError) as e:
        pytest.skip(f"no native kernel here: {e}")
    assert got.tolist() == [nearest(X, 2500, q, alive) for q in Q]
    assert nearest_batch(X, 2500, Q).tolist() == [nearest(X, 2500, q) for q in Q]
    with pytest.raises(ValueError, match="n = 4000"):
        nearest_batch(X, 4000, Q)
    with pytest.raises(ValueError, match="Q"):
        nearest_batch(X, 10, Q[:, :3])
    with pytest.raises(ValueError, match="boolean mask"):
        nearest_batch(X, 10, Q, np.ones(3000))


def test_rrt_keys_are_steps_from_earlier_rows():
    from optplan.bench.nearest_index import rrt_keys

    X = rrt_keys(200, np.random.default_rng(0))
    d = np.linalg.norm(X[1:, None, :] - X[None, :, :], axis=2)
    for i in range(1, 200):   # some earlier row lies one step away
        assert np.isclose(d[i - 1, :i], 0.05).any()
