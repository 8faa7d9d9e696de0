"""The paired TCBiRRT benchmark (optplan.bench.tcbirrt_paired): the object's path length against Pinocchio FK of
the returned configurations, and the paired statistics against counts made by hand."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.bench.tcbirrt_paired import paired_summary, run_query, task_length


def test_task_length_of_known_poses():
    """1 m along x in 10 steps while turning 0.5 rad about z; configurations without the object (None) skipped."""
    poses = [pin.SE3(pin.exp3(np.array([0.0, 0.0, 0.05 * k])), np.array([0.1 * k, 0.0, 0.0])) for k in range(11)]
    tr, rot = task_length(poses[:4] + [None, None] + poses[4:])
    assert tr == pytest.approx(1.0, abs=1e-12) and rot == pytest.approx(0.5, abs=1e-12)
    assert task_length([None, poses[0]]) == (0.0, 0.0)


def test_run_query_lengths_match_forward_kinematics(tcb):
    """Both planners solve ssps_scene1's trial 0; the path's object length recomputed by Pinocchio FK of arm A's hand
    at its held configurations agrees with the recorded one (IK tolerance), and the joint length is the path's."""
    from optplan.bench.tcbirrt import _W
    from optplan.scene import Scene
    from optplan.tasks import object_pose

    out = run_query("ssps_scene1", 0, 0, 10.0)
    assert set(out) == {"a", "b"} and all(out[k]["success"] for k in out)
    w = _W["ssps_scene1"]
    t = w["gen"].generate(0, 0)
    pl = w["planners"]["tcbirrt:variant=improved:branch_roots=false"]
    res = pl.plan(t.q_start, t.q_goal, time_limit=10.0, seed=t.seed, clock="cpu")
    assert res.success
    sc = Scene.load("ssps_scene1")
    held = [M if c else None for M, c in zip(res.object_poses, res.constrained)]
    fk = [object_pose(tcb, sc, q, "A") if c else None for q, c in zip(res.path, res.constrained)]
    tr, rot = task_length(res.object_poses)
    assert task_length(held) == pytest.approx((tr, rot), abs=1e-9)   # a pose during a regrasp is the held one's
    tr_fk, rot_fk = task_length(fk)
    n = int(np.sum(res.constrained))
    assert tr == pytest.approx(tr_fk, abs=2e-3 * n) and rot == pytest.approx(rot_fk, abs=2e-3 * n)
    assert tr > 0.1


def _row(group, a, b, ca=1.0, cb=1.0, la=10.0, lb=10.0):
    q = lambda ok, c, L: {"success": ok, "status": "exact" if ok else "timeout", "cpu_s": c, "iterations": 1,  # noqa: E731
                          "joint_len": L, "task_len_m": L / 10, "task_rot_rad": L / 20, "n_regrasp": 2, "n_conf": 5}
    return {"group": group, "a": q(a, ca, la), "b": q(b, cb, lb)}


def test_paired_summary_counts():
    rows = [_row("bay", False, True, 5.0, 1.0), _row("bay", False, True, 5.0, 2.0), _row("bay", True, False, 0.5, 5.0),
            _row("wall", True, True, 1.0, 0.5, 10.0, 12.0), _row("wall", True, True, 2.0, 1.0, 10.0, 12.0),
            {"group": "wall", "skipped": True}]
    s = paired_summary(rows, 5.0)
    assert "indices without a certified draw 1" in s
    assert "all: 5 queries; success a 3/5, b 4/5 (b wins 2, loses 1;" in s
    assert "bay: 3 queries; success a 1/3, b 2/3 (b wins 2, loses 1;" in s
    assert "joint length [rad]: median a 10.00, b 12.00; b/a geometric mean 1.200" in s
    assert "failures: {'a timeout': 2, 'b timeout': 1}" in s


def test_from_and_summary_count_each_key_once(tmp_path, capsys):
    """``--from`` carries a generated index without a certified draw over as skipped (no planning), and
    ``--summary`` counts a key written twice once (its first line)."""
    import json

    from optplan.bench.tcbirrt_paired import main

    drawn = tmp_path / "drawn"
    drawn.mkdir()
    (drawn / "scenes.jsonl").write_text(json.dumps({"key": "7_0", "index": 0, "group": "bay", "skipped": True}) + "\n")
    out = tmp_path / "out"
    assert main(["--from", str(drawn), "--out", str(out), "--base-seed", "7"]) == 0
    assert main(["--from", str(drawn), "--out", str(out), "--base-seed", "7"]) == 0   # resumes: nothing new
    lines = [json.loads(x) for x in (out / "paired.jsonl").read_text().splitlines()]
    assert len(lines) == 1 and lines[0]["skipped"] and lines[0]["group"] == "bay"
    first, again = {**_row("wall", True, False, 1.0, 5.0), "key": "k"}, {**_row("wall", True, True, 1.0, 0.5), "key": "k"}
    (out / "paired.jsonl").write_text("".join(json.dumps(r) + "\n" for r in (first, again, *lines)))
    capsys.readouterr()
    assert main(["--summary", str(out), "--time-limit", "5"]) == 0
    s = capsys.readouterr().out
    assert s.startswith("2 lines; indices without a certified draw 1")
    assert "all: 1 queries; success a 1/1, b 0/1 (b wins 0, loses 1;" in s


def test_from_pairs_only_the_families_asked_for(tmp_path):
    """``--from DIR --families bay`` pairs only the bay indices of DIR (the other families are left to another run)."""
    import json

    from optplan.bench.tcbirrt_paired import main

    drawn = tmp_path / "drawn"
    drawn.mkdir()
    (drawn / "scenes.jsonl").write_text("".join(json.dumps({"key": f"7_{i}", "index": i, "group": g, "skipped": True})
                                                + "\n" for i, g in enumerate(("wall", "bay", "corridor"))))
    out = tmp_path / "out"
    assert main(["--from", str(drawn), "--out", str(out), "--base-seed", "7", "--families", "bay"]) == 0
    lines = [json.loads(x) for x in (out / "paired.jsonl").read_text().splitlines()]
    assert [r["group"] for r in lines] == ["bay"]


def test_families_draws_only_those_indices(tmp_path, monkeypatch):
    """``--families bay`` draws only the indices whose family (``FAMILIES[i % 6]``) is a bay, each with its own seed
    ``base_seed * 1000 + i``; an unknown family is refused."""
    import json

    from optplan.bench import scenegen
    from optplan.bench.tcbirrt_paired import main

    calls = []

    def fake(robot, n, seed, families, **kw):
        calls.append((seed, families))
        return []   # no certified draw: recorded as skipped

    monkeypatch.setattr(scenegen, "generate_scenes", fake)
    out = tmp_path / "g"
    assert main(["--generate-only", "--families", "bay", "--base-seed", "5", "--n", "14", "--out", str(out)]) == 0
    assert calls == [(5001, ("bay",)), (5007, ("bay",)), (5013, ("bay",))]
    keys = [json.loads(x)["key"] for x in (out / "scenes.jsonl").read_text().splitlines()]
    assert keys == ["5_1", "5_7", "5_13"]
    with pytest.raises(SystemExit):
        main(["--generate-only", "--families", "bays", "--n", "2", "--out", str(tmp_path / "h")])


def test_run_order_alternates_within_each_family():
    """Index i draws family i % 6: the order must not follow the family (the first planner on a fresh scene pays its
    warm-up), so each family runs a first and b first equally often over consecutive draws."""
    from optplan.bench.scenegen import FAMILIES
    from optplan.bench.tcbirrt_paired import _order

    n = len(FAMILIES)
    for f in range(n):
        orders = [_order(f + n * k) for k in range(8)]
        assert orders.count(("a", "b")) == orders.count(("b", "a")) == 4


def test_from_with_several_planner_seeds(tmp_path, monkeypatch):
    """``--planner-seeds 3``: each certified query three times, the planner seed the trial's + k * 7919, the run order
    alternating with k, keys ``K``, ``K~1``, ``K~2``; a rerun resumes without repeating a key; 0 is refused."""
    import json

    from optplan.bench import tcbirrt_paired as tp

    calls = []

    def fake(scene, trial, seed, limit, specs, order, seed_offset=0):
        calls.append((scene, trial, seed, order, seed_offset))
        return {"a": {"success": True}, "b": {"success": True}}

    monkeypatch.setattr(tp, "run_query", fake)
    drawn = tmp_path / "drawn"
    drawn.mkdir()
    (drawn / "scenes.jsonl").write_text(json.dumps({"key": "7_1", "index": 1, "group": "bay", "scene": "s.toml"}) + "\n")
    out = tmp_path / "out"
    args = ["--from", str(drawn), "--out", str(out), "--base-seed", "7", "--planner-seeds", "3"]
    assert tp.main(args) == 0 and tp.main(args) == 0
    assert [c[4] for c in calls] == [0, 7919, 15838]
    assert calls[0][3] == calls[2][3] == calls[1][3][::-1]
    rows = [json.loads(x) for x in (out / "paired.jsonl").read_text().splitlines()]
    assert [r["key"] for r in rows] == ["7_1", "7_1~1", "7_1~2"]
    assert [r["planner_seed_offset"] for r in rows] == [0, 7919, 15838]
    with pytest.raises(SystemExit):
        tp.main(["--from", str(drawn), "--out", str(out), "--planner-seeds", "0"])
