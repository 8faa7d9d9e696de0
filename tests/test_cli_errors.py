"""Every user error of the ``optplan`` command: one line on stderr naming the value and what was
expected, exit status 2, no traceback — and nothing long runs before the check.

In-process through :func:`optplan.cli.main` (fast); two cases also as a real subprocess, so the
exit status and the absence of a traceback are those a shell sees.
"""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from optplan import cli


def _run(argv, capsys):
    try:
        rc = cli.main(argv)
    except SystemExit as exc:  # argparse
        rc = exc.code
    out = capsys.readouterr()
    return rc, out.out, out.err


@pytest.fixture
def not_a_dir(tmp_path):
    f = tmp_path / "file.txt"
    f.write_text("x")
    return f


USER_ERRORS = [
    # (argv, text the message must contain)
    (["plan", "--scene", "9"], "'9'"),
    (["plan", "--scene", "no_such_scene"], "no_such_scene"),
    (["plan", "--planner", "rrtstar"], "rrtstar"),
    (["plan", "--trial", "-1"], "'-1'"),
    (["plan", "--seed", "-3"], "'-3'"),
    (["plan", "--seed", "abc"], "'abc'"),
    (["plan", "--time-limit", "nan"], "'nan'"),
    (["plan", "--time-limit", "-5"], "'-5'"),
    (["plan", "--time-limit", "inf"], "'inf'"),
    (["plan", "--time-limit", "ten"], "'ten'"),
    (["plan", "--json", "{missing}/out.json"], "out.json"),
    (["plan", "--save", "{tmp}"], "is a directory"),
    (["plan", "--json", "{file}/out.json"], "out.json"),
    (["bench", "tcbirrt", "--trials", "0"], "'0'"),
    (["bench", "tcbirrt", "--trials", "1.5"], "'1.5'"),
    (["bench", "tcbirrt", "--jobs", "0"], "'0'"),
    (["bench", "tcbirrt", "--time-limit", "0"], "'0'"),
    (["bench", "tcbirrt", "--scene", "7"], "'7'"),
    (["bench", "tcbirrt", "--generated", "2", "--witness", "rrt"], "'rrt'"),
    (["bench", "tcbirrt", "--planners", "nope"], "nope"),
    (["bench", "tcbirrt", "--planners", "tcbirrt:range"], "range"),
    (["bench", "tcbirrt", "--out", "{file}/sub"], "sub"),
    (["bench", "warmstart", "--trials", "0"], "'0'"),
    (["bench", "warmstart", "--time-limit", "nan"], "'nan'"),
    (["bench", "warmstart", "--ipopt-max-wall-time", "-1"], "'-1'"),
    (["bench", "warmstart", "--scene", "zz"], "zz"),
    (["bench", "warmstart", "--modes", "hot"], "hot"),
    (["bench", "warmstart", "--out", "{file}"], "not a directory"),
    (["bench", "transport", "--knots", "1,25"], "1"),
    (["bench", "transport", "--knots", "a"], "'a'"),
    (["bench", "transport", "--json", "{missing}/t.json"], "t.json"),
    (["bench", "kinematics", "--calls", "0"], "'0'"),
    (["bench", "kinematics", "--robot", "r2d2"], "r2d2"),
    (["demo", "--duration", "-1"], "'-1'"),
    (["demo", "--duration", "nan"], "'nan'"),
    (["demo", "--json", "{tmp}"], "is a directory"),
]


@pytest.mark.parametrize("argv,needle", USER_ERRORS, ids=[" ".join(a) for a, _ in USER_ERRORS])
def test_user_error_is_one_line_exit_2(argv, needle, capsys, tmp_path, not_a_dir):
    subst = {"{tmp}": str(tmp_path), "{missing}": str(tmp_path / "missing"), "{file}": str(not_a_dir)}
    for k, v in subst.items():
        argv = [a.replace(k, v) for a in argv]
    rc, out, err = _run(argv, capsys)
    assert rc == 2, (argv, rc, out, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err and "Traceback" not in out
    assert needle in lines[0], (needle, lines[0])
    assert "error" in lines[0]


def test_bad_optplan_root(capsys, monkeypatch, tmp_path):
    for root in (str(tmp_path / "nowhere"), str(tmp_path)):
        monkeypatch.setenv("OPTPLAN_ROOT", root)
        rc, out, err = _run(["models", "list"], capsys)
        assert rc == 2 and err.count("\n") == 1 and root in err and "OPTPLAN_ROOT" in err, err
    monkeypatch.setenv("OPTPLAN_ROOT", "")   # empty = unset, as in the library
    rc, out, err = _run(["models", "list"], capsys)
    assert rc == 0 and "eba_ffsr" in out, err


def test_output_paths_are_checked_before_the_run(capsys, tmp_path, monkeypatch):
    """The run function is never entered when --json cannot be written."""
    called = []
    monkeypatch.setattr(cli, "_cmd_demo", lambda args: called.append(args) or 0)
    rc, _, err = _run(["demo", "--json", str(tmp_path / "no" / "x.json")], capsys)
    assert rc == 2 and not called, err
    rc, _, err = _run(["demo", "--json", str(tmp_path / "x.json")], capsys)
    assert rc == 0 and called
    assert not (tmp_path / "x.json").exists()   # the write probe leaves nothing behind


def test_failed_plan_still_writes_its_json(capsys, tmp_path, monkeypatch):
    """An exception inside the run (here: a planner crash injected into the pipeline) still leaves
    the JSON with success: false and the error."""
    import optplan.model.robot as robot
    import optplan.trials as trials

    def boom(*a, **k):
        raise RuntimeError("injected failure")

    monkeypatch.setattr(trials, "TrialGenerator", boom)
    monkeypatch.setattr(robot.RobotModel, "from_name", classmethod(lambda cls, name: None))
    out = tmp_path / "r.json"
    with pytest.raises(RuntimeError):
        cli.main(["plan", "--scene", "1", "--json", str(out)])
    d = json.loads(out.read_text())
    assert d["success"] is False and "injected failure" in d["error"]


def test_subprocess_exit_status_and_no_traceback():
    r = subprocess.run([sys.executable, "-m", "optplan.cli", "bench", "tcbirrt", "--trials", "0"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_plan_robot_option_is_checked_against_the_scene(capsys):
    """``optplan plan --robot``: an unknown robot, or one the scene was not made for, is a one-line
    user error (exit 2) before any planning."""
    from optplan import cli

    assert cli.main(["plan", "--scene", "1", "--robot", "nosuch"]) == 2
    assert "unknown robot" in capsys.readouterr().err
    assert cli.main(["plan", "--scene", "1", "--robot", "eba_ffsr"]) == 2
    assert "made for robot 'tcbirrt_dual_arm'" in capsys.readouterr().err


def test_plan_clock_reaches_the_pipeline_and_bad_values_are_refused(capsys, monkeypatch):
    """``optplan plan --clock cpu`` plans on the CPU clock; an unknown clock is a usage error."""
    import optplan.pipeline as pipeline

    seen = {}

    def fake(robot, scene, q_start, q_goal, options=None, seed=0):
        seen["clock"] = options.plan_clock
        raise RuntimeError("stop here")

    monkeypatch.setattr(pipeline, "run_pipeline", fake)
    with pytest.raises(RuntimeError, match="stop here"):
        cli.main(["plan", "--scene", "1", "--clock", "cpu"])
    assert seen["clock"] == "cpu"
    assert cli.main(["plan", "--scene", "1", "--clock", "moon"]) == 2
    assert "moon" in capsys.readouterr().err
