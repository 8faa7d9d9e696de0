"""``optplan bench warmstart`` (issue 4, item 5): argument validation, resume logic and summary
statistics with a fake unit runner (the real pipeline takes 10-70 s per run: see the slow test)."""
import json

import pytest

from optplan import cli
from optplan.bench import warmstart as ws


def _line(scene="ssps_scene1", trial=0, mode="warm", seed=0, time_limit=10.0, max_wall=None, success=True, plan_ok=True,
          converged=None, iters=20, t=0.5, setup=5.0, segments=None, plan_hash="h", fixed=True,
          transcription="bspline", **kw):
    d = {"scene": scene, "trial": trial, "mode": mode, "seed": seed, "time_limit_s": time_limit,
         "ipopt_max_wall_time_s": max_wall, "fixed_plane_normals": fixed, "transcription": transcription,
         "success": success, "plan_ok": plan_ok, "plan_status": "exact" if plan_ok else "timeout",
         "opt_status": ("Solve_Succeeded" if plan_ok else "not_run"), "converged": success if converged is None else converged,
         "opt_iterations": iters if plan_ok else 0, "opt_time_s": t if plan_ok else 0.0,
         "opt_setup_time_s": setup if plan_ok else 0.0, "max_closed_chain_residual": 1e-7 if plan_ok else None,
         "min_clearance_m": 0.01 if plan_ok else None, "wall_time_s": 10.0, "cpu_time_s": 9.0,
         "plan_hash": plan_hash if plan_ok else None, "segments": segments or [], "error": None,
         "segment_nlp": "optproblem"}   # the default segment NLP, recorded on every line
    d.update(kw)
    return d


@pytest.fixture
def fake_runner(monkeypatch):
    calls = []

    def fake(args):
        robot, scene, index, mode, time_limit, seed, max_wall, fixed, transcription, _compile = args[:10]
        calls.append((scene, index, mode))
        line = _line(scene, index, mode, seed, time_limit, max_wall, iters=10 if mode == "warm" else 40,
                     t=0.2 if mode == "warm" else 1.0, fixed=fixed, transcription=transcription)
        return {**line, "segment_nlp": args[11]}   # as the real unit records it

    monkeypatch.setattr(ws, "_run_unit", fake)
    return calls


# ---------------------------------------------------------------------- arguments
@pytest.mark.parametrize("kw, msg", [
    ({"scenes": ["7"]}, "unknown scene 'ssps_scene7'"),
    ({"scenes": ["nope"]}, "unknown scene"),
    ({"scenes": []}, "no scene"),
    ({"scenes": ["1", "1"]}, "repeated"),
    ({"trials": 0}, "--trials"),
    ({"trials": -3}, "--trials"),
    ({"jobs": 0}, "--jobs"),
    ({"time_limit": 0.0}, "--time-limit"),
    ({"time_limit": float("nan")}, "--time-limit"),
    ({"first_trial": -1}, "--first-trial"),
    ({"modes": ("warm", "lukewarm")}, "--modes"),
    ({"modes": ()}, "--modes"),
    ({"ipopt_max_wall_time": 0.0}, "--ipopt-max-wall-time"),
])
def test_validate_rejects_bad_arguments(kw, msg):
    with pytest.raises(ValueError, match=msg):
        ws.validate(ws.WarmstartConfig(**kw))


def test_validate_resolves_scene_numbers():
    assert ws.validate(ws.WarmstartConfig(scenes=["1", " 3", "ssps_scene2"])) == ["ssps_scene1", "ssps_scene3",
                                                                                    "ssps_scene2"]


@pytest.mark.parametrize("argv, msg", [
    (["--scene", "9"], "unknown scene"),
    (["--trials", "0"], "--trials"),
    (["--jobs", "0"], "--jobs"),
])
def test_cli_bad_arguments_exit_2_with_message(tmp_path, capsys, argv, msg):
    rc = cli.main(["bench", "warmstart", "--out", str(tmp_path / "o"), *argv])
    assert rc == 2
    err = capsys.readouterr().err
    assert "optplan bench warmstart: error:" in err and msg in err
    assert not (tmp_path / "o").exists()


def test_cli_runs_and_prints_table(tmp_path, capsys, fake_runner):
    out = tmp_path / "o"
    rc = cli.main(["bench", "warmstart", "--scene", "1,2", "--trials", "2", "--out", str(out), "--no-progress"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "ssps_scene1  warm" in text and "ssps_scene2  cold" in text and "targets" in text
    assert len(fake_runner) == 8
    assert (out / "summary.txt").read_text().strip() in text
    assert set(json.loads((out / "summary.json").read_text())) == {"ssps_scene1", "ssps_scene2", "all"}


# ---------------------------------------------------------------------- resume
def test_resume_runs_only_missing_units_and_redoes_truncated_line(tmp_path, fake_runner):
    out = tmp_path / "o"
    out.mkdir()
    done = [_line("ssps_scene1", 0, "warm"), _line("ssps_scene1", 0, "cold"), _line("ssps_scene1", 1, "warm"),
            _line("ssps_scene1", 2, "cold", seed=5),          # other seed: not this run's
            _line("ssps_scene1", 2, "warm", time_limit=3.0),  # other time limit: not this run's
            _line("ssps_scene1", 2, "warm", max_wall=60.0)]   # other IPOPT cap: not this run's
    text = "".join(json.dumps(d) + "\n" for d in done)
    text += json.dumps(_line("ssps_scene1", 1, "cold"))[:40]   # killed while writing
    (out / "results.jsonl").write_text(text)
    cfg = ws.WarmstartConfig(scenes=["1"], trials=3, out=str(out), progress=False)
    rows = ws.run(cfg)
    assert sorted(fake_runner) == [("ssps_scene1", 1, "cold"), ("ssps_scene1", 2, "cold"), ("ssps_scene1", 2, "warm")]
    assert len(rows) == 6 and {(r["trial"], r["mode"]) for r in rows} == {(i, m) for i in range(3) for m in ws.MODES}
    lines = (out / "results.jsonl").read_text().splitlines()
    assert len(lines) == 6 + 3 and all(json.loads(x) for x in lines)   # the truncated line is gone
    # a second run has nothing to do
    fake_runner.clear()
    ws.run(cfg)
    assert fake_runner == []


def test_pending_units_order_and_keys():
    cfg = ws.WarmstartConfig(scenes=["1", "2"], trials=2, first_trial=3, seed=7, time_limit=4.0, ipopt_max_wall_time=60)
    rows = [_line("ssps_scene2", 4, "cold", seed=7, time_limit=4.0, max_wall=60.0),
            _line("ssps_scene2", 3, "cold", seed=7, time_limit=4.0),   # uncapped: not this run's
            _line("ssps_scene2", 3, "warm", seed=7, time_limit=4.0, max_wall=60.0, fixed=False)]  # free normals
    units = ws.pending_units(cfg, ["ssps_scene1", "ssps_scene2"], rows)
    assert len(units) == 7
    assert units[0] == ("tcbirrt_dual_arm", "ssps_scene1", 3, "warm", 4.0, 7, 60.0, True, "bspline", False, None,
                        "optproblem")
    assert ("tcbirrt_dual_arm", "ssps_scene2", 4, "cold", 4.0, 7, 60.0, True, "bspline", False, None, "optproblem") not in units
    assert ("tcbirrt_dual_arm", "ssps_scene2", 3, "cold", 4.0, 7, 60.0, True, "bspline", False, None, "optproblem") in units
    assert ("tcbirrt_dual_arm", "ssps_scene2", 3, "warm", 4.0, 7, 60.0, True, "bspline", False, None, "optproblem") in units
    # lines without the key (written before the option existed) were solved with free normals
    old = {k: v for k, v in _line("ssps_scene1", 3, "warm", seed=7, time_limit=4.0, max_wall=60.0).items()
           if k != "fixed_plane_normals"}
    assert ("tcbirrt_dual_arm", "ssps_scene1", 3, "warm", 4.0, 7, 60.0, True, "bspline", False, None, "optproblem") in ws.pending_units(
        cfg, ["ssps_scene1"], [old])
    # ... with the knot transcription (lines without the key predate the B-spline one)
    old = {k: v for k, v in old.items() if k != "transcription"}
    free = ws.WarmstartConfig(scenes=["1"], trials=1, first_trial=3, seed=7, time_limit=4.0, ipopt_max_wall_time=60,
                              free_plane_normals=True, transcription="knots")
    assert ws.pending_units(free, ["ssps_scene1"], [old]) == [
        ("tcbirrt_dual_arm", "ssps_scene1", 3, "cold", 4.0, 7, 60.0, False, "knots", False, None, "optproblem")]
    spline_free = ws.WarmstartConfig(scenes=["1"], trials=1, first_trial=3, seed=7, time_limit=4.0,
                                     ipopt_max_wall_time=60, free_plane_normals=True)
    assert len(ws.pending_units(spline_free, ["ssps_scene1"], [old])) == 2


# ---------------------------------------------------------------------- statistics
def _seg(kind, failure=()):
    return {"kind": kind, "failure": list(failure)}


def test_summary_statistics_on_synthetic_rows():
    rows = []
    for i, (it, t) in enumerate([(10, 0.2), (20, 0.4), (30, 0.6), (40, 3.0)]):
        rows.append(_line(trial=i, mode="warm", iters=it, t=t, setup=4.0 + i))
    rows.append(_line(trial=4, mode="warm", success=False, converged=False, iters=3000, t=20.0,
                      segments=[_seg("constrained"), _seg("regrasp", ["ipopt:Maximum_Iterations_Exceeded"])]))
    rows.append(_line(trial=5, mode="warm", plan_ok=False, success=False))   # no plan: not an optimizer failure
    for i in range(5):
        ok = i != 1
        rows.append(_line(trial=i, mode="cold", success=ok, converged=True, iters=4 * (i + 1) * 10, t=2.0 * (i + 1),
                          segments=[] if ok else [_seg("regrasp", ["clearance"])], plan_hash="h" if i else "other"))
    rows.append(_line(trial=5, mode="cold", plan_ok=False, success=False))
    s = ws.summarize(rows)
    assert list(s) == ["ssps_scene1"]
    e = s["ssps_scene1"]
    w, c = e["modes"]["warm"], e["modes"]["cold"]
    assert w["n"] == 6 and w["planned"] == 5 and w["plan_failures"] == {"timeout": 1}
    assert w["successes"] == 4 and w["success_rate"] == pytest.approx(0.8) and w["converged_rate"] == pytest.approx(0.8)
    assert w["iterations"]["median"] == 30 and w["iterations"]["mean"] == pytest.approx(3100 / 5)
    assert w["ipopt_time_s"]["median"] == pytest.approx(0.6) and w["ipopt_time_s"]["max"] == pytest.approx(20.0)
    assert w["ipopt_time_s"]["mean"] == pytest.approx(24.2 / 5)
    assert w["setup_time_s"]["median"] == pytest.approx(5.0)   # 4, 5, 6, 7 and 5
    assert w["failure_modes"] == {"regrasp:ipopt:Maximum_Iterations_Exceeded": 1}
    assert c["successes"] == 4 and c["converged"] == 5 and c["failure_modes"] == {"regrasp:clearance": 1}
    p = e["paired"]
    assert p["pairs"] == 5 and p["plans_differ"] == 1 and p["both_success"] == 3
    assert p["warm_only"] == 1 and p["cold_only"] == 1
    # both solved: trials 0, 2, 3 → iteration ratios 4, 4, 4; time ratios 10, 10, 8/3
    assert p["median_iteration_ratio_cold_warm"] == pytest.approx(4.0)
    assert p["median_ipopt_time_ratio_cold_warm"] == pytest.approx(10.0)
    t = e["targets"]
    assert t["warm_converged"] == pytest.approx(0.8) and not t["warm_converged_met"]
    assert t["warm_median_ipopt_s"] == pytest.approx(0.6) and t["warm_median_ipopt_s_met"]
    text = ws.format_summary(s)
    assert "4/5  80%" in text and "timeout 1" in text and "regrasp:clearance 1" in text
    assert "NOT met" in text and "plans differ between modes in 1" in text


def test_summary_all_scenes_pairs_by_scene_and_trial():
    rows = [_line("ssps_scene1", 0, "warm"), _line("ssps_scene1", 0, "cold", success=False),
            _line("ssps_scene2", 0, "warm", success=False), _line("ssps_scene2", 0, "cold")]
    s = ws.summarize(rows)
    assert set(s) == {"ssps_scene1", "ssps_scene2", "all"}
    p = s["all"]["paired"]
    assert p["pairs"] == 2 and p["warm_only"] == 1 and p["cold_only"] == 1 and p["both_success"] == 0
    assert s["all"]["modes"]["warm"]["successes"] == 1 and s["all"]["modes"]["warm"]["planned"] == 2


def test_summary_without_plans_or_rows():
    s = ws.summarize([_line(plan_ok=False, success=False)])
    w = s["ssps_scene1"]["modes"]["warm"]
    assert w["planned"] == 0 and w["success_rate"] is None and w["iterations"]["median"] is None
    assert not s["ssps_scene1"]["targets"]["warm_converged_met"]
    assert "0/1" in ws.format_summary(s)
    assert ws.summarize([]) == {}


def test_summary_counts_a_planned_row_without_an_opt_status():
    """A planned row that lacks ``opt_status`` (e.g. a hand-edited or older results line) is
    counted under None beside the others, not a TypeError from sorting None with strings."""
    rows = [_line(trial=0), _line(trial=1)]
    del rows[1]["opt_status"]
    w = ws.summarize(rows)["ssps_scene1"]["modes"]["warm"]
    assert w["opt_statuses"] == {"Solve_Succeeded": 1, None: 1}


@pytest.mark.slow
def test_real_run_scene1_trial0(tmp_path):
    cfg = ws.WarmstartConfig(scenes=["1"], trials=1, out=str(tmp_path), progress=False)
    rows = ws.run(cfg)
    assert len(rows) == 2 and {r["mode"] for r in rows} == set(ws.MODES)
    for r in rows:
        assert r["plan_ok"] and r["n_segments"] == len(r["segments"]) and r["cpu_time_s"] > 0
    assert rows[0]["plan_hash"] == rows[1]["plan_hash"]
    assert (tmp_path / "summary.txt").exists()
