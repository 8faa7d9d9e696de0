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


def test_rrt_keys_are_steps_from_earlier_rows():
    from optplan.bench.nearest_index import rrt_keys

    X = rrt_keys(200, np.random.default_rng(0))
    d = np.linalg.norm(X[1:, None, :] - X[None, :, :], axis=2)
    for i in range(1, 200):   # some earlier row lies one step away
        assert np.isclose(d[i - 1, :i], 0.05).any()
