"""Descriptions validated as physics, results that say what happened, no raw library exceptions.

(The generated bad-input cases are in test_properties.py, the CLI's in test_cli_errors.py.)
"""
from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
import pytest

from optplan.collision.checker import CollisionChecker
from optplan.errors import ConfigurationError, ModelError, OptionError, ResultFileError, UnknownNameError
from optplan.geometry.spatial import se3, vector_to_pose
from optplan.model.description import load_description, models_dir, urdf_dir
from optplan.model.robot import RobotModel
from optplan.pipeline import PipelineResult
from optplan.planners.base import PlanResult, PlanStatus
from optplan.problem.solution import IpoptStatus, Solution
from optplan.scene import Scene

EBA_TOML = (models_dir() / "robots" / "eba_ffsr.toml").read_text()
TCB_URDF = (urdf_dir() / "tcbirrt_dual_arm.urdf").read_text()


def _toml(tmp_path, text):
    p = tmp_path / "robot.toml"
    p.write_text(text)
    return p


# --------------------------------------------------------------------------- TOML robots
def test_typo_table_does_not_drop_an_arm(tmp_path):
    with pytest.raises(ModelError, match=r"armsx.*did you mean 'arms'"):
        load_description(_toml(tmp_path, EBA_TOML.replace("[[arms]]", "[[armsx]]", 1)))


def test_no_arms(tmp_path):
    text = "arms = []\n" + re.sub(r"\[\[arms\]\].*", "", EBA_TOML, flags=re.S)
    with pytest.raises(ModelError, match="at least one"):
        load_description(_toml(tmp_path, text))


@pytest.mark.parametrize("key,value,needle", [
    ("velocity", "0", "velocity"), ("effort", "-1", "effort"), ("radius", "nan", "radius"),
    ("mass", "inf", "base.mass"), ("masses", '"1.0"', "masses")])
def test_physical_values(tmp_path, key, value, needle):
    text = EBA_TOML.replace("velocity = [", "effort = [-1, 1, 1, 1, 1, 1, 1]\nvelocity = [", 1) if key == "effort" \
        else EBA_TOML
    lines = text.splitlines()
    i = next(k for k, ln in enumerate(lines) if re.match(rf"\s*{key}\s*=", ln) or f" {key} = " in ln)
    if key == "radius":
        lines[i] = re.sub(r"radius = [0-9.]+", f"radius = {value}", lines[i], count=1)
    elif key in ("velocity", "effort", "masses"):
        lines[i] = re.sub(r"(=\s*\[)\s*[-0-9.e]+", rf"\g<1>{value}", lines[i], count=1)
    else:
        lines[i] = f"{key} = {value}"
    with pytest.raises(ModelError, match=needle):
        load_description(_toml(tmp_path, "\n".join(lines) + "\n"))


def test_non_utf8_toml(tmp_path):
    p = tmp_path / "robot.toml"
    p.write_bytes(b"name = \"\xff\xfe\"\n")
    with pytest.raises(ModelError, match="UTF-8"):
        load_description(p)


# --------------------------------------------------------------------------- URDFs
ARMS = {"A": "a_ee", "B": "b_ee"}


def _urdf(tmp_path, text):
    p = tmp_path / "r.urdf"
    p.write_text(text)
    return p


def _first_revolute(text):
    m = re.search(r'<joint name="([^"]+)" type="revolute">', text)
    return m.group(1), m.start()


def test_urdf_zero_axis_names_joint_and_line(tmp_path):
    name, start = _first_revolute(TCB_URDF)
    end = TCB_URDF.index("</joint>", start)
    block = re.sub(r'<axis xyz="[^"]+"', '<axis xyz="0 0 0"', TCB_URDF[start:end])
    text = TCB_URDF[:start] + block + TCB_URDF[end:]
    line = TCB_URDF.count("\n", 0, start) + 1
    with pytest.raises(ModelError, match=rf"r.urdf:{line}: joint '{name}': zero axis"):
        RobotModel.from_urdf(_urdf(tmp_path, text), ARMS)


def test_urdf_lower_above_upper(tmp_path):
    name, start = _first_revolute(TCB_URDF)
    end = TCB_URDF.index("</joint>", start)
    block = re.sub(r'lower="[^"]+"', 'lower="2.0"', TCB_URDF[start:end])
    block = re.sub(r'upper="[^"]+"', 'upper="1.0"', block)
    with pytest.raises(ModelError, match=rf"joint '{name}': lower limit 2.0 > upper limit 1.0"):
        RobotModel.from_urdf(_urdf(tmp_path, TCB_URDF[:start] + block + TCB_URDF[end:]), ARMS)


def test_urdf_parse_error_has_line(tmp_path):
    text = TCB_URDF.replace("</link>", "</lnk>", 1)
    with pytest.raises(ModelError, match=r"line \d+"):
        RobotModel.from_urdf(_urdf(tmp_path, text), ARMS)


def test_stale_urdf_is_refused(tmp_path, monkeypatch):
    """A URDF generated from an older TOML is never used silently."""
    (tmp_path / "models" / "robots").mkdir(parents=True)
    (tmp_path / "urdf").mkdir()
    (tmp_path / "models" / "robots" / "eba_ffsr.toml").write_text(EBA_TOML.replace("mass = 510", "mass = 520", 1))
    (tmp_path / "urdf" / "eba_ffsr.urdf").write_text((urdf_dir() / "eba_ffsr.urdf").read_text())
    monkeypatch.setenv("OPTPLAN_ROOT", str(tmp_path))
    assert "mass = 510" in EBA_TOML
    with pytest.raises(ModelError, match="out of date.*optplan models build"):
        RobotModel.from_name("eba_ffsr")


# --------------------------------------------------------------------------- scenes
@pytest.mark.parametrize("patch,exc,needle", [
    ({"start": [1, 2, 3]}, ModelError, "start"),
    ({"obstacles": {"name": "x"}}, ModelError, "obstacles"),
    ({"robot": "r2d2"}, UnknownNameError, "r2d2"),
    ({"obstacle": []}, ModelError, "did you mean 'obstacles'"),
])
def test_scene_types(patch, exc, needle):
    import tomllib

    d = tomllib.loads((models_dir() / "scenes" / "transport.toml").read_text())
    d.update(patch)
    with pytest.raises(exc, match=needle):
        Scene.from_dict(d, "transport.toml")


def test_unknown_exclude_link(tcb):
    import dataclasses
    import tomllib

    d = tomllib.loads((models_dir() / "scenes" / "transport.toml").read_text())
    d["object"]["exclude_links"] = ["a_link6", "a_lnk7"]
    with pytest.raises(UnknownNameError, match="a_lnk7"):   # a scene naming a shipped robot: at load
        Scene.from_dict(d, "transport.toml")
    del d["robot"]
    scene = Scene.from_dict(d, "transport.toml")
    with pytest.raises(UnknownNameError, match="a_lnk7"):   # any robot: when its checker is built
        CollisionChecker(tcb, scene)
    assert dataclasses.is_dataclass(scene)


# --------------------------------------------------------------------------- results
def test_plan_result_truthiness_is_not_existence():
    empty = PlanResult(PlanStatus.TIMEOUT, "tcbirrt", np.zeros((0, 14)))
    with pytest.raises(TypeError, match="ambiguous"):
        bool(empty)
    assert PipelineResult(plan=empty).to_dict()["plan_status"] == "timeout"
    assert PipelineResult(plan=None).to_dict()["plan_status"] == "not_run"


def test_plan_result_never_exact_without_a_path():
    with pytest.raises(ResultFileError, match="exact"):
        PlanResult.from_dict({"status": "exact", "path": []}, "p.json")
    with pytest.raises(ResultFileError, match="unknown status 'great'"):
        PlanResult.from_dict({"status": "great", "path": []}, "p.json")


def test_plan_result_file_round_trip_and_corruption(tmp_path):
    path = np.linspace(0, 1, 28).reshape(2, 14)
    res = PlanResult(PlanStatus.EXACT, "tcbirrt", path, [pin.SE3.Identity()] * 2, np.ones(2, bool))
    p = res.save(tmp_path / "plan.json")
    back = PlanResult.load(p)
    np.testing.assert_array_equal(back.path, path)
    assert back.success
    p.write_text(p.read_text()[:50])
    with pytest.raises(ResultFileError, match="plan.json"):
        PlanResult.load(p)
    p.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ResultFileError, match="plan.json"):
        PlanResult.load(p)


def test_zero_quaternion():
    with pytest.raises(ConfigurationError, match="zero quaternion"):
        vector_to_pose([0, 0, 0, 0, 0, 0, 0])


def test_se3_refuses_non_rotation():
    with pytest.raises(ConfigurationError, match="not a rotation"):
        se3(2 * np.eye(3), [0, 0, 0])


def test_solution_never_claims_success_on_nan():
    t = np.linspace(0, 1, 3)
    z = np.zeros((3, 2))
    sol = Solution(success=True, status=IpoptStatus.SOLVE_SUCCEEDED, iterations=1, wall_time=0.0, cost=0.0,
                   max_constraint_violation=0.0, terms={}, t=t, q=z * np.nan, qd=z, qdd=z, jerk=np.zeros((2, 2)),
                   joint_names=("a", "b"))
    assert not sol.success
    ok = Solution(success=True, status=IpoptStatus.MAXIMUM_ITERATIONS_EXCEEDED, iterations=1, wall_time=0.0,
                  cost=0.0, max_constraint_violation=0.0, terms={}, t=t, q=z, qd=z, qdd=z, jerk=np.zeros((2, 2)),
                  joint_names=("a", "b"))
    assert not ok.success


def test_invalid_ipopt_option_is_a_value_error_before_the_solve(tcb):
    from optplan.problem import OptProblem

    prob = OptProblem(tcb, n_intervals=2, duration=1.0)
    prob.set_initial_straight_line(np.zeros(tcb.nj), np.full(tcb.nj, 0.1))
    with pytest.raises(OptionError, match="mu_strategy"):
        prob.solve({"mu_strategy": "fastest"})
    with pytest.raises(ValueError, match="no_such_option"):
        prob.solve({"no_such_option": 1})
    assert prob._built is None   # refused before the NLP was built


def test_zero_counts_are_not_zero_divisions(tmp_path):
    from optplan.bench import kinematics as bk
    from optplan.bench.tcbirrt import BenchConfig, run, success_curve

    assert all(np.isnan(success_curve([], 0, [0.1, 1.0])))
    with pytest.raises(OptionError, match="calls"):
        bk.run("eba_ffsr", calls=0)
    for field, value in (("trials", 0), ("jobs", 0), ("time_limit", float("nan")), ("first_trial", -1)):
        with pytest.raises(OptionError, match=field):
            run(BenchConfig(out=str(tmp_path / "o"), **{field: value}))
    assert not (tmp_path / "o").exists()
