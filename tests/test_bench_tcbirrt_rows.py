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


def test_bench_tcbirrt_checks_its_edges_at_the_bench_density():
    """The benchmark runs TCBiRRT with its edge checks at the sweep tolerance and a final path check, so a path
    its planner returns passes the benchmark's independent 1 cm sweep check (the paper variant alone, which
    checks only the configurations, had 19-34 of 100 returned paths per scene rejected)."""
    from optplan.bench import tcbirrt as bt

    bt._worker_setup("tcbirrt_dual_arm", ["ssps_scene2"], ["tcbirrt", "tcbirrt:edge_tolerance=0:verify_path=false"])
    pl = bt._W["ssps_scene2"]["planners"]
    assert pl["tcbirrt"].options.edge_tolerance == bt.SWEEP_TOLERANCE and pl["tcbirrt"].options.verify_path
    assert pl["tcbirrt:edge_tolerance=0:verify_path=false"].options.edge_tolerance == 0.0   # a spec overrides
    returned = 0
    for trial in range(6):
        (row,) = bt._run_unit(("tcbirrt_dual_arm", "ssps_scene2", trial, ["tcbirrt"], 2.0, 0, "cpu"))
        returned += row["planner_success"]
        assert row["success"] == row["planner_success"], row["checks"]
    assert returned >= 3
