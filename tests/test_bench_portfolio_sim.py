import json
import math

import pytest


def test_portfolio_time_by_hand():
    from optplan.bench.portfolio_sim import portfolio_time

    # the first member alone solves within N0: its own time
    assert portfolio_time([(0.001, 500), (0.002, 10)], 1000) == pytest.approx(0.5)
    # after N0 = 100 (0.1 s), each portfolio iteration costs 0.001 + 0.002: the second finishes its 10 at 0.13 s
    assert portfolio_time([(0.001, 5000), (0.002, 10)], 100) == pytest.approx(0.1 + 10 * 0.003)
    # the first finishes its remaining 50 iterations at 0.1 + 50 * 0.003 before the second's 100 iterations
    assert portfolio_time([(0.001, 150), (0.002, 100)], 100) == pytest.approx(0.1 + 50 * 0.003)
    assert portfolio_time([(0.001, math.inf), (0.002, math.inf)], 0) == math.inf


def test_simulate_counts_scenes_solved_within_the_limit(tmp_path):
    from optplan.bench.portfolio_sim import simulate

    runs = {0: [("a", True, 1.0, 1000), ("b", False, 10.0, 10000), ("c", True, 9.0, 9000)],
            1: [("a", True, 2.0, 2000), ("b", True, 2.0, 2000), ("c", False, 10.0, 10000)]}
    paths = []
    for off, rows in runs.items():
        p = tmp_path / f"off{off}.jsonl"
        p.write_text("".join(json.dumps({"scene": s, "status": "exact" if ok else "timeout", "success": ok, "cpu_s": c,
                                         "iterations": n}) + "\n" for s, ok, c, n in rows))
        paths.append(str(p))
    rows = simulate(paths, 10.0, n0s=(0,))
    singles = [r["solved"] for r in rows if r["members"] == 1]
    assert singles == [2, 2]
    # two members from the start (each iteration 2 ms): a by member 0 at 2 s, b by member 1 at 4 s, c by member 0
    # only after 18 s: two scenes
    pair = [r for r in rows if r["members"] == 2 and r["first"] == 0][0]
    assert pair["solved"] == 2 and pair["scenes"] == 3
