"""The paired table of ``optplan.bench.tcbirrt_versions`` (two source trees, query by query)."""
from __future__ import annotations

import json

import pytest

from optplan.bench.tcbirrt_versions import main, summary


def _row(scene, trial, a, b):
    keys = ("success", "cpu_s", "iterations", "path")
    return {"scene": scene, "trial": trial, "first": "a", "a": dict(zip(keys, a)), "b": dict(zip(keys, b))}


def test_summary_pairs_per_query(tmp_path):
    rows = [_row("s1", 0, (True, 0.2, 10, "p"), (True, 0.1, 10, "p")),       # same search, ratio 2
            _row("s1", 1, (True, 0.3, 12, "q"), (True, 0.6, 15, "r")),       # another search, ratio 0.5
            _row("s1", 2, (False, 10.0, 900, None), (True, 0.4, 20, "s")),   # a failed: no ratio
            _row("s2", 0, (True, 0.1, 1, "t"), (True, 0.05, 1, "t"))]
    f = tmp_path / "versions.jsonl"
    f.write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    lines = summary(f)
    s1 = next(x for x in lines if x.startswith("| s1 "))
    assert "| 3 | 2 / 3 |" in s1 and "0.3000 / 0.4000" in s1 and "| 12 / 15 |" in s1
    assert "1.250, 1.000" in s1 and s1.endswith("| 1 / 3 |")   # median of (2, 0.5), geometric mean 1
    assert next(x for x in lines if x.startswith("| s2 ")).endswith("| 1 / 1 |")


def test_main_needs_both_trees():
    with pytest.raises(SystemExit):
        main(["--tree-a", "/tmp"])


def test_summary_leaves_out_trials_neither_version_could_draw(tmp_path):
    nt = {"status": "no_trial", "success": False, "cpu_s": float("nan"), "iterations": 0, "path": None}
    rows = [_row("s1", 0, (True, 0.2, 10, "p"), (True, 0.1, 10, "p")),
            {"scene": "s1", "trial": 1, "first": "b", "a": nt, "b": nt}]
    f = tmp_path / "versions.jsonl"
    f.write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    s1 = next(x for x in summary(f) if x.startswith("| s1 "))
    assert "| 1 | 1 / 1 |" in s1 and s1.endswith("| 1 / 1 |")
