"""The TCBiRRT profile by function family: it profiles the benchmark's query and its families add up."""
from __future__ import annotations

import pstats

import pytest

from optplan.bench.tcbirrt_profile import families, format_families, main, profile_queries


def test_profile_of_one_query(tmp_path, capsys):
    stats, rows = profile_queries(["1"], [2])
    assert len(rows) == 1 and rows[0]["scene"] == "ssps_scene1" and rows[0]["status"] == "exact"
    assert rows[0]["collision_checks"] > 0 and rows[0]["iterations"] >= 1
    fam = dict(families(stats))
    total = fam["whole queries (TCBiRRT._plan)"]
    assert total > 0
    assert fam["C++ collision queries, self time"] > 0          # every query checks collisions
    for label, t in fam.items():                                 # nested families never exceed the whole
        assert 0.0 <= t <= total * 1.001, label
    assert "share" in format_families(families(stats))
    out = tmp_path / "p.prof"
    assert main(["--scene", "ssps_scene1", "--trials", "2", "--out", str(out)]) == 0
    assert "whole queries" in capsys.readouterr().out
    assert pstats.Stats(str(out)).total_tt > 0


def test_profile_needs_trials():
    with pytest.raises(ValueError, match="trial"):
        profile_queries(["1"], [])
