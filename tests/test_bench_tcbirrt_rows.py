"""optplan bench tcbirrt: the result rows of a query that could not be set up."""
from __future__ import annotations


def test_bench_trial_without_start_goal_is_a_failed_row(monkeypatch):
    """A scene whose trial cannot be drawn for the benchmark's seed is a failed query per planner, not the
    end of the run (generated scenes pass their feasibility check with another seed)."""
    from optplan.bench import tcbirrt as bt
    from optplan.errors import UnreachableError

    class Gen:
        def generate(self, index, seed):
            raise UnreachableError(f"trial {index}: no valid start/goal IK")

    monkeypatch.setitem(bt._W, "sc", {"gen": Gen()})
    rows = bt._run_unit(("tcbirrt_dual_arm", "sc", 3, ["tcbirrt", "cbirrt2"], 10.0, 7, "cpu"))
    assert [(r["planner"], r["status"], r["success"], r["trial"], r["seed"]) for r in rows] == \
        [("tcbirrt", "no_trial", False, 3, 7), ("cbirrt2", "no_trial", False, 3, 7)]
    assert "no valid start/goal IK" in rows[0]["message"]
    summ = bt.summarize(rows, 10.0)
    assert summ["sc"]["planners"]["tcbirrt"]["successes"] == 0
