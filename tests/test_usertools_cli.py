"""Friendly CLI and the one-command reproductions: --version, models info, help texts without
internal words, reproduce's errors and its run of a script, plan figures."""
from __future__ import annotations

import json
import math
import re
import sys
import textwrap

import numpy as np
import pytest

from optplan import __version__, cli
from optplan.reproduce import PAPERS, ReproduceError, plan_steps, reproduce


def test_version(capsys):
    assert cli.main(["--version"]) == 0  # main returns argparse's exit status instead of raising
    assert capsys.readouterr().out.strip() == f"optplan {__version__}"


def test_models_info_matches_pinocchio(tmp_path, capsys):
    from optplan.model.robot import RobotModel

    out = tmp_path / "info.json"
    assert cli.main(["models", "info", "eba_ffsr", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    d = json.loads(out.read_text())
    r = RobotModel.from_name("eba_ffsr")
    assert d["base"] == "floating" and d["nq"] == r.nq == 21 and d["n_joints"] == 14
    assert set(d["arms"]) == {"A", "B"} and d["arms"]["A"]["ee_frame"] == r.arms["A"].ee_frame
    assert math.isclose(d["base_mass_kg"], 510.0) and "floating base" in text
    # total mass: the sum of Pinocchio's body masses (paper Table 2: base 510 kg + 2 x 41.79 kg)
    assert math.isclose(d["total_mass_kg"], sum(i.mass for i in r.model.inertias), rel_tol=1e-12)
    assert math.isclose(d["total_mass_kg"], 510 + 2 * (6.34 + 6.34 + 7.93 + 5.67 + 2.80 + 2.70 + 10.01), rel_tol=1e-9)
    lim = {j["name"]: j for j in d["joints"]}
    k = r.joint_names.index("a_joint2")
    assert math.isclose(lim["a_joint2"]["upper_deg"], math.degrees(r.upper[k]))
    assert cli.main(["models", "info", "nope"]) == 2
    assert "unknown robot model 'nope'" in capsys.readouterr().err


def _all_help(parser) -> str:
    import argparse

    out = [parser.format_help()]
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            for p in a.choices.values():
                out.append(_all_help(p))
    return "\n".join(out)


def test_help_texts_have_no_internal_words():
    text = _all_help(cli.build_parser())
    assert not re.search(r"\bissue\s*\d", text, re.I), re.findall(r".{30}issue\s*\d.{10}", text, re.I)
    assert not re.search(r"\bseed\s+00\d", text, re.I), re.findall(r".{30}seed\s+00\d.{10}", text, re.I)
    for cmd in ("view", "reproduce", "--version", "--engine", "--html", "--plot"):
        assert cmd in text


def test_reproduce_errors(tmp_path, capsys, monkeypatch):
    import optplan.reproduce as rp

    with pytest.raises(ReproduceError, match="unknown paper 'nope'"):
        plan_steps("nope", tmp_path)
    with pytest.raises(ReproduceError, match=r"oc_rrt.py is missing"):
        plan_steps("oc-rrt", tmp_path, examples=tmp_path)
    assert set(PAPERS) == {"tcbirrt", "eba", "dshdasr", "spline-rrt", "oc-rrt"}
    monkeypatch.setattr(rp, "examples_dir", lambda: tmp_path)   # a checkout without the script
    assert cli.main(["reproduce", "spline-rrt", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "optplan reproduce: error:" in err and "spline_rrt_star.py is missing" in err
    assert not (tmp_path / "o").exists()


def test_reproduce_runs_a_script_with_the_flags_it_offers(tmp_path):
    """A stand-in paper script: reproduce passes --json/--plot/--quick (which it offers), records
    its exit code and output files."""
    ex = tmp_path / "examples"
    ex.mkdir()
    (ex / "oc_rrt.py").write_text(textwrap.dedent('''
        import argparse, json, pathlib
        ap = argparse.ArgumentParser()
        ap.add_argument("--json"); ap.add_argument("--plot"); ap.add_argument("--quick", action="store_true")
        a = ap.parse_args()
        print("ours 0.12 s   paper 0.50 s")
        json.dump({"quick": a.quick, "time_s": 0.12}, open(a.json, "w"))
        pathlib.Path(a.plot).mkdir(parents=True, exist_ok=True)
    '''))
    rec = reproduce("oc-rrt", out=tmp_path / "out", quick=True, html=False, examples=ex)
    assert rec["success"] and rec["steps"][0]["exit_code"] == 0
    assert "--quick" in rec["steps"][0]["argv"] and "--html" not in rec["steps"][0]["argv"]
    assert json.loads((tmp_path / "out" / "oc_rrt.json").read_text()) == {"quick": True, "time_s": 0.12}
    assert "ours 0.12 s" in (tmp_path / "out" / "oc_rrt.log").read_text()
    assert json.loads((tmp_path / "out" / "reproduce.json").read_text())["paper"] == "oc-rrt"
    # a failing script is a failed record, not an exception
    (ex / "oc_rrt.py").write_text("import sys; print('boom'); sys.exit(3)\n")
    rec = reproduce("oc-rrt", out=tmp_path / "out2", quick=False, html=False, examples=ex)
    assert not rec["success"] and rec["steps"][0]["exit_code"] == 3


def test_reproduce_reports_a_missing_extra_view(tmp_path, monkeypatch, caplog):
    """An extra HTML view that cannot be made (its optional dependency missing) is a logged
    warning and the run's record stands (the step log's file handle once shadowed the logger)."""
    import dataclasses

    import optplan.reproduce as rp

    ex = tmp_path / "examples"
    ex.mkdir()
    (ex / "oc_rrt.py").write_text("print('ok')\n")

    def no_view(out, quick):
        raise ImportError("the viz extra is not installed")

    monkeypatch.setitem(rp.PAPERS, "oc-rrt", dataclasses.replace(rp.PAPERS["oc-rrt"], extra_views=no_view))
    with caplog.at_level("WARNING", logger="optplan.reproduce"):
        rec = reproduce("oc-rrt", out=tmp_path / "out", quick=True, html=True, examples=ex)
    assert rec["success"]
    assert "no HTML view: the viz extra is not installed" in caplog.text


def test_plan_figures_and_profiles(tmp_path):
    from optplan.collision.checker import CollisionChecker
    from optplan.constraints.closed_chain import closure_error
    from optplan.model.robot import RobotModel
    from optplan.scene import Scene
    from optplan.viz.plan_plots import plot_trajectory, trajectory_profiles

    robot, scene = RobotModel.from_name("tcbirrt_dual_arm"), Scene.load("ssps_scene1")
    f = math.pi / 180
    q0, q1 = np.asarray(scene.extra["q_start"]) * f, np.asarray(scene.extra["q_goal"]) * f
    s = np.linspace(0, 1, 12)[:, None]
    q = (1 - s) * q0 + s * q1
    t = np.linspace(0, 11, 12)
    cons = np.array([True] * 4 + [False] * 4 + [True] * 4)
    prof = trajectory_profiles(robot, scene, t, q, cons)
    assert np.all(np.isnan(prof["residual_m"][4:8])) and np.all(np.isfinite(prof["residual_m"][[0, 11]]))
    assert math.isclose(prof["residual_m"][0], closure_error(robot, scene.object.grasps, q[0])[0])
    assert math.isclose(prof["clearance_m"][0], CollisionChecker(robot, scene).min_distance(q[0])[0])
    assert math.isclose(prof["clearance_m"][5],
                        CollisionChecker(robot, scene, held_object=False).min_distance(q[5])[0])
    paths = plot_trajectory(robot, scene, t, q, tmp_path, name="p", constrained=cons)
    assert [p.name for p in paths] == ["p_joints.png", "p_residual_clearance.png"]
    assert all(p.stat().st_size > 10_000 for p in paths)


@pytest.mark.slow
@pytest.mark.parametrize("paper", ["tcbirrt", "eba", "dshdasr"])
def test_reproduce_quick_end_to_end(tmp_path, paper):
    """``optplan reproduce PAPER --quick``: every step succeeds, JSON and figures are written, an
    HTML view exists when the viz extra is installed, and the run takes under a minute (measured
    25-45 s on a loaded 2-core machine; the limit leaves room for a slower one)."""
    import time

    t0 = time.perf_counter()
    rec = reproduce(paper, out=tmp_path / "r", quick=True)
    dt = time.perf_counter() - t0
    assert rec["success"], rec["steps"]
    assert all(s["exit_code"] == 0 for s in rec["steps"])
    assert any(f.endswith(".json") for f in rec["files"]) and any(f.endswith(".png") for f in rec["files"])
    try:
        import meshcat  # noqa: F401
        assert any(f.endswith(".html") for f in rec["files"])
    except ImportError:
        pass
    assert dt < 90.0, dt


def test_view_without_viz_extra_is_a_clear_error(tmp_path, capsys, monkeypatch):
    """Without meshcat, the 3D view is a message naming the extra (exit 2), not a traceback."""
    from optplan.viz.html import VizUnavailable, save_metadata, trajectory_html

    monkeypatch.setitem(sys.modules, "meshcat", None)   # import meshcat -> ImportError
    p = tmp_path / "t.npz"
    np.savez(p, t=[0.0, 1.0], q=np.zeros((2, 14)))
    save_metadata(p, robot="tcbirrt_dual_arm")
    with pytest.raises(VizUnavailable, match=r"optional extra 'viz'"):
        trajectory_html(None, None, [0.0], np.zeros((1, 14)))
    assert cli.main(["view", str(p)]) == 2
    assert "pip install \"optplan[viz]\"" in capsys.readouterr().err
