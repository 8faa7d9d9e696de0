"""``python -m optplan.bench.edge_skip``: the recorded re-checks of a real query, paired both ways."""
from __future__ import annotations

from optplan.bench.edge_skip import main, paired_costs, record_edges


def test_edge_skip_bench_pairs_the_recorded_edges(capsys):
    rec = record_edges("hard_corridor", [0])
    if not rec:   # no native kernel here: nothing recorded
        return
    rows = paired_costs(rec, repeats=1)   # raises if a first point in collision differs
    assert "verify" in rows
    v = rows["verify"]
    assert v["edges"] > 5 and 0 < v["checked"] < v["points"] and v["cpu_skip_s"] > 0.0
    assert main(["--scene", "hard_flip", "--trials", "0", "--repeats", "1"]) == 0
    out = capsys.readouterr().out
    assert "hard_flip" in out and "verify" in out
