"""The last bad inputs: files at the edges (size, count, nesting, physical ranges, URDF trees,
meshes), out-of-reach tasks, the remaining raw errors of the public API and the CLI, and the cases
that used to succeed silently. Every case must end in an ``optplan.errors`` exception whose
message contains the named detail (the argument, the value, the file, the element) or in a
failure status — never a raw exception, a traceback from the CLI, or a silent success.

``python tests/test_bad_inputs_edges.py`` runs every case once and prints the outcome counts by
category (clear / raw / silent / slow); docs/reliability.md quotes them before and after.
"""
from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

#: a case that takes longer than this [s] counts as "slow" (a 50 MB scene used to load for minutes)
SLOW_S = 20.0

_CACHE: dict = {}


def _tcb():
    from optplan import RobotModel

    if "tcb" not in _CACHE:
        _CACHE["tcb"] = RobotModel.from_name("tcbirrt_dual_arm")
    return _CACHE["tcb"]


def _write(tmp: Path, name: str, text: str) -> Path:
    p = tmp / name
    p.write_text(text)
    return p


def _obstacles(n: int, xyz: str = "[1, 2, 3]") -> str:
    return "".join(f'[[obstacles]]\nname = "o{i}"\nshape = "sphere"\nradius = 0.1\nxyz = {xyz}\n' for i in range(n))


def _load_scene(p: Path):
    from optplan import Scene

    return Scene.load(p)


_J = ('<joint name="{n}" type="{t}"><parent link="{p}"/><child link="{c}"/><origin xyz="{o}"/><axis xyz="0 0 1"/>'
      '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>')


def _urdf(tmp: Path, name: str, body: str):
    from optplan import RobotModel

    return RobotModel.from_urdf(_write(tmp, name, f'<robot name="x">\n{body}\n</robot>\n'), {})


# --------------------------------------------------------------------------- files and limits
def big_scene(tmp):
    p = tmp / "big.toml"
    chunk = _obstacles(1000)
    with open(p, "w") as f:
        while f.tell() < 50e6:
            f.write(chunk)
    _load_scene(p)   # the time is checked by test_big_scene_is_refused_fast


def many_obstacles(tmp):
    _load_scene(_write(tmp, "many.toml", _obstacles(6000)))


def nested_scene(tmp):
    _load_scene(_write(tmp, "deep.toml", "a = " + "[" * 200_000 + "]" * 200_000 + "\n"))


def far_obstacle(tmp):
    _load_scene(_write(tmp, "far.toml", _obstacles(1, "[1e308, 0, 0]")))


def huge_obstacle(tmp):
    _load_scene(_write(tmp, "huge.toml", '[[obstacles]]\nname = "o"\nshape = "box"\nsize = [1e308, 1, 1]\n'))


def far_object_start(tmp):
    _load_scene(_write(tmp, "obj.toml", '[object]\nsize = [1, 1, 1]\n[start]\nxyz = [0, 0, 1e308]\n'))


def long_scene_name(tmp):
    _load_scene(tmp / ("s" * 300 + ".toml"))


def long_urdf_path(tmp):
    from optplan import RobotModel

    RobotModel.from_urdf("/".join(["d" * 200] * 25) + "/r.urdf", {})


def urdf_missing_parent(tmp):
    _urdf(tmp, "mp.urdf", '<link name="a"/><link name="b"/>' + _J.format(n="j", t="revolute", p="zz", c="b", o="0 0 0"))


def urdf_two_roots(tmp):
    _urdf(tmp, "tr.urdf", '<link name="a"/><link name="b"/><link name="c"/>'
          + _J.format(n="j", t="revolute", p="a", c="b", o="0 0 0"))


def urdf_nan_origin(tmp):
    _urdf(tmp, "nan.urdf", '<link name="a"/><link name="b"/>' + _J.format(n="j", t="revolute", p="a", c="b", o="nan 0 0"))


def urdf_bogus_type(tmp):
    _urdf(tmp, "bogus.urdf", '<link name="a"/><link name="b"/>' + _J.format(n="j", t="bogus", p="a", c="b", o="0 0 0"))


def urdf_missing_mesh(tmp):
    _urdf(tmp, "mesh.urdf", f'<link name="a"><collision><geometry><mesh filename="{tmp}/nothere.stl"/></geometry>'
          '</collision></link>')


def urdf_garbage_mesh(tmp):
    (tmp / "garbage.stl").write_text("garbage")
    _urdf(tmp, "gmesh.urdf", f'<link name="a"><collision><geometry><mesh filename="{tmp}/garbage.stl"/></geometry>'
          '</collision></link>')


def robot_far_mount(tmp):
    from optplan.model.description import load_description, models_dir

    text = (models_dir() / "robots" / "eba_ffsr.toml").read_text()
    i = text.index("mount_xyz = ")
    j = text.index("\n", i)
    return load_description(_write(tmp, "far_mount.toml", text[:i] + "mount_xyz = [1e308, 0, 0]" + text[j:]))


def _trials_of_scene_with(tmp, extra: str):
    from optplan.trials import TrialGenerator

    src = (Path(__file__).resolve().parents[1] / "models" / "scenes" / "transport.toml").read_text()
    text = src.replace("[extra]\n", "[extra]\n" + extra + "\n", 1) if "[extra]" in src else src + "\n[extra]\n" + extra + "\n"
    return TrialGenerator(_tcb(), _load_scene(_write(tmp, "extra.toml", text)))


def scene_trial_range_text(tmp):
    return _trials_of_scene_with(tmp, 'trial_position_range = "wide"')


def scene_trial_range_huge(tmp):
    return _trials_of_scene_with(tmp, "trial_position_range = 1e308")


def scene_q_start_short(tmp):
    return _trials_of_scene_with(tmp, "q_start = [0.0, 1.0]")


def _moved_goal(offset_m: float):
    import pinocchio as pin

    from optplan import Scene
    from optplan.trials import TrialGenerator

    s = Scene.load("ssps_scene1")
    assert s.goal is not None
    s2 = dataclasses.replace(s, goal=pin.SE3(s.goal.rotation, s.goal.translation + np.array([offset_m, 0.0, 0.0])))
    return TrialGenerator(_tcb(), s2).generate(0, 0)


def goal_6m_out(tmp):
    return _moved_goal(6.0)


def goal_40m_out(tmp):
    return _moved_goal(40.0)


def _far_goal_scene(tmp: Path) -> Path:
    import re

    src = (Path(__file__).resolve().parents[1] / "models" / "scenes" / "ssps_scene1.toml").read_text()
    text = re.sub(r"(\[goal\]\nxyz = \[)([^,]+)", lambda m: m.group(1) + str(float(m.group(2)) + 40.0), src)
    assert text != src
    return _write(tmp, "far_goal.toml", text)


def cli_plan_goal_40m_out(tmp):
    return _cli(["plan", "--scene", str(_far_goal_scene(tmp)), "--time-limit", "2"])


def cli_bench_goal_40m_out(tmp):
    return _cli(["bench", "tcbirrt", "--scene", str(_far_goal_scene(tmp)), "--trials", "1", "--planners", "tcbirrt",
                 "--out", str(tmp / "bench"), "--no-progress", "--no-plot"])


# --------------------------------------------------------------------------- API: the raw errors
def arms_list(tmp):
    from optplan import RobotModel

    RobotModel.from_urdf(_tcb().urdf_path, ["A"])


def arms_int_frame(tmp):
    from optplan import RobotModel

    RobotModel.from_urdf(_tcb().urdf_path, {"A": 99999})


def fk_wrong_size(tmp):
    from optplan import SymbolicKinematics

    return SymbolicKinematics(_tcb()).fk_function("a_ee")(np.zeros(13))


def exp_coordinates_scalar(tmp):
    from optplan.planners.task_space import exp_coordinates

    return exp_coordinates(0)


def _problem(**kw):
    from optplan import OptProblem

    return OptProblem(_tcb(), **kw)


def n_intervals_nan(tmp):
    return _problem(n_intervals=float("nan"))


def n_intervals_none(tmp):
    return _problem(n_intervals=None)


def duration_str(tmp):
    return _problem(duration="10")


def duration_none(tmp):
    return _problem(duration=None)


def n_sub_zero(tmp):
    from optplan import RobotModel

    if "eba" not in _CACHE:
        _CACHE["eba"] = RobotModel.from_name("eba_ffsr")
    from optplan import OptProblem

    return OptProblem(_CACHE["eba"], n_intervals=4, n_sub=0)


def set_initial_nan_times(tmp):
    p = _problem(n_intervals=4)
    p.set_initial(np.zeros((3, 14)), t=[0.0, float("nan"), 2.0])


def _planner():
    from optplan import Scene, make_planner

    return make_planner("rrtconnect", _tcb(), Scene.load("transport"))


def plan_time_limit_str(tmp):
    q = np.zeros(14)
    return _planner().plan(q, q, time_limit="5")


def plan_seed_nan(tmp):
    q = np.zeros(14)
    return _planner().plan(q, q, seed=float("nan"))


def solution_save_missing_folder(tmp):
    from optplan import Solution

    n = 3
    sol = Solution(success=False, status="Unknown", iterations=0, wall_time=0.0, cost=0.0, max_constraint_violation=0.0,
                   terms={}, t=np.linspace(0, 1, n), q=np.zeros((n, 2)), qd=np.zeros((n, 2)), qdd=np.zeros((n, 2)),
                   jerk=np.zeros((n - 1, 2)), joint_names=("j1", "j2"))
    return sol.save(tmp / "no_such_folder" / "sol.npz")


def plan_result_ragged(tmp):
    from optplan import PlanResult

    return PlanResult.from_json(json.dumps({"status": "exact", "planner": "x", "path": [[0.0, 1.0], [1.0]]}))


def plan_result_nested(tmp):
    from optplan import PlanResult

    return PlanResult.from_json("[" * 200_000 + "]" * 200_000)


def _cli(argv: list[str], env: dict[str, str] | None = None) -> int:
    """``optplan ARGV`` in this process: its exit status; an exception escaping ``main`` is the
    traceback a user would see."""
    from optplan import cli

    old = {k: os.environ.get(k) for k in (env or {})}
    os.environ.update(env or {})
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            rc = cli.main(argv)
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    lines = [ln for ln in err.getvalue().splitlines() if ln.strip() and "%|" not in ln]
    if rc == 2 and len(lines) == 1 and ": error: " in lines[0]:
        from optplan.errors import UsageError

        raise UsageError(lines[0])   # the one line the user sees
    raise AssertionError(f"exit {rc}, stderr {err.getvalue()[-500:]!r}")


def cli_bench_bad_planner_option(tmp):
    return _cli(["bench", "tcbirrt", "--planners", "tcbirrt:step_size=-1", "--trials", "1", "--out", str(tmp / "b"),
                 "--no-progress"])


def cli_models_build_urdf_is_a_file(tmp):
    import shutil

    from optplan.model.description import models_dir

    root = tmp / "root"
    shutil.copytree(models_dir(), root / "models")
    (root / "urdf").write_text("not a folder")
    return _cli(["models", "build"], env={"OPTPLAN_ROOT": str(root)})


def _sparse(p: Path, size: int) -> Path:
    """A file of ``size`` bytes that takes no disk space (its size is all the check looks at)."""
    with open(p, "wb") as f:
        f.truncate(size)
    return p


def cli_plan_big_scene(tmp):
    return _cli(["plan", "--scene", str(_sparse(tmp / "big_cli.toml", 50_000_000))])


def cli_plan_json_long_name(tmp):
    return _cli(["plan", "--json", str(tmp / ("x" * 300 + ".json"))])


def cli_plan_save_long_path(tmp):
    return _cli(["plan", "--save", "/".join([str(tmp)] + ["d" * 200] * 25) + "/a.npz"])


def cli_view_long_name(tmp):
    return _cli(["view", str(tmp / ("v" * 300 + ".npz"))])


# --------------------------------------------------------------------------- the silent ones
def arm_with_other_arms_joints(tmp):
    from optplan import RobotModel

    r = _tcb()
    return RobotModel.from_urdf(r.urdf_path, {"A": {"ee": "a_ee", "joints": list(r.arm("B").joint_names)}})


def scene_unknown_exclude_link(tmp):
    text = (Path(__file__).resolve().parents[1] / "models" / "scenes" / "transport.toml").read_text()
    text = text.replace('"a_link7"', '"a_lnk7"', 1)
    assert "a_lnk7" in text
    return _load_scene(_write(tmp, "excl.toml", text))


def self_distances_huge_angle(tmp):
    return _tcb().self_distances(np.full(14, 1e6))


def fk_nan(tmp):
    from optplan import SymbolicKinematics

    return SymbolicKinematics(_tcb()).fk_function("a_ee")(np.full(14, np.nan))


def n_intervals_fraction(tmp):
    return _problem(n_intervals=2.7)


def n_intervals_str(tmp):
    return _problem(n_intervals="10")


def start_inside_obstacle(tmp):
    """A sphere obstacle of 0.3 m around the elbow of arm A at the start configuration: the start
    penetrates it by more than 0.3 m (the pinned start has no collision rows in the NLP)."""
    from optplan import CollisionAvoidance, JointBoundary, JointPositionLimits, Kinematics, Scene, Smoothness
    from optplan.collision.checker import CollisionChecker

    r = _tcb()
    q0 = np.zeros(14)
    elbow = Kinematics(r).frame_placement(q0, "a_link4").translation
    sc = Scene.from_dict({"name": "inside", "obstacles": [
        {"name": "ball", "shape": "sphere", "radius": 0.3, "xyz": [float(v) for v in elbow]}]})
    chk = CollisionChecker(r, sc, held_object=False, self_collision=False)
    assert chk.min_distance(q0)[0] < -0.3
    rng = np.random.default_rng(7)
    q1 = next(q for q in (r.random_joints(rng) for _ in range(50_000)) if chk.min_distance(q)[0] > 0.05)
    prob = _problem(n_intervals=8)
    prob.add_constraint(JointBoundary("start", q=q0))
    prob.add_constraint(JointBoundary("end", q=q1))
    prob.add_constraint(JointPositionLimits())
    prob.add_constraint(CollisionAvoidance(sc, margin=0.01, held_object=False, self_collision=False))
    prob.add_cost(Smoothness("jerk"))
    prob.set_initial_straight_line(q0, q1)
    return prob.solve(max_iter=100)


def _failed(result) -> bool:
    """A returned result that reports failure (a status, not an exception)."""
    return getattr(result, "success", True) is False


# (category, case, needle the message must contain, or a predicate a returned result must meet)
CASES: list[tuple[str, Callable, str | Callable]] = [
    ("files", big_scene, "MAX_SCENE_BYTES"),
    ("files", many_obstacles, "MAX_OBSTACLES"),
    ("files", nested_scene, "nested"),
    ("files", far_obstacle, "obstacles[0].xyz"),
    ("files", huge_obstacle, "obstacles[0].size"),
    ("files", far_object_start, "start.xyz"),
    ("files", long_scene_name, "limit is 255"),
    ("files", long_urdf_path, "limit is 4096"),
    ("files", urdf_missing_parent, "mp.urdf:2: joint 'j': parent link 'zz'"),
    ("files", urdf_two_roots, "tr.urdf:2: 2 root links"),
    ("files", urdf_nan_origin, "nan.urdf:2: joint 'j': <origin xyz='nan 0 0'>"),
    ("files", urdf_bogus_type, "bogus.urdf:2: joint 'j': type 'bogus'"),
    ("files", urdf_missing_mesh, "nothere.stl"),
    ("files", urdf_garbage_mesh, "garbage.stl"),
    ("files", robot_far_mount, "arms[0].mount_xyz: lengths must be within ±1000 m"),
    ("files", scene_trial_range_text, "extra.trial_position_range"),
    ("files", scene_trial_range_huge, "TrialOptions.position_range"),
    ("files", scene_q_start_short, "extra.q_start must have 14 finite joint values"),
    ("reach", goal_6m_out, "unreachable goal"),
    ("reach", goal_40m_out, "unreachable goal"),
    ("reach", cli_plan_goal_40m_out, "unreachable goal"),
    ("reach", cli_bench_goal_40m_out, "unreachable goal"),
    ("api", arms_list, "arms: expected a mapping"),
    ("api", arms_int_frame, "arms['A']"),
    ("api", fk_wrong_size, "expected 14 numbers"),
    ("api", exp_coordinates_scalar, "exp_coordinates: R"),
    ("api", n_intervals_nan, "n_intervals"),
    ("api", n_intervals_none, "n_intervals"),
    ("api", duration_str, "duration"),
    ("api", duration_none, "duration"),
    ("api", n_sub_zero, "n_sub"),
    ("api", set_initial_nan_times, "t (sample times [s]): entries [1] are not finite"),
    ("api", plan_time_limit_str, "time_limit"),
    ("api", plan_seed_nan, "seed"),
    ("api", solution_save_missing_folder, "does not exist"),
    ("api", plan_result_ragged, "path: expected a list of M configurations of equal length"),
    ("api", plan_result_nested, "nested 200000 levels"),
    ("cli", cli_bench_bad_planner_option, "step_size"),
    ("cli", cli_models_build_urdf_is_a_file, "is a file, not a folder"),
    ("cli", cli_plan_big_scene, "MAX_SCENE_BYTES"),
    ("cli", cli_plan_json_long_name, "--json: a file or folder name of 305 characters"),
    ("cli", cli_plan_save_long_path, "--save: the path has"),
    ("cli", cli_view_long_name, "trajectory file: a file or folder name of 304 characters"),
    ("silent", arm_with_other_arms_joints, "'b_joint1' does not move its end-effector frame 'a_ee'"),
    ("silent", scene_unknown_exclude_link, "a_lnk7"),
    ("silent", self_distances_huge_angle, "outside their limits"),
    ("silent", fk_nan, "not finite"),
    ("silent", n_intervals_fraction, "n_intervals"),
    ("silent", n_intervals_str, "n_intervals"),
    ("silent", start_inside_obstacle, _failed),
]


def classify(case: Callable, expect: str | Callable, tmp: Path) -> tuple[str, str, float]:
    """``(outcome, detail, seconds)``: outcome "clear" (an OptplanError naming ``expect``, or a
    returned result meeting ``expect``), "raw" (another exception, or an OptplanError without the
    detail), "silent" (a return where an error or a failure status was due) or "slow" (clear or
    not, it took more than :data:`SLOW_S`)."""
    import signal

    from optplan.errors import OptplanError

    def stop(signum, frame):
        raise TimeoutError(f"still running after {SLOW_S:g} s")

    alarm = sys.platform != "win32" and __import__("threading").current_thread() is __import__("threading").main_thread()
    if alarm:
        old_handler = signal.signal(signal.SIGALRM, stop)
        signal.alarm(int(SLOW_S) + 1)
    t0 = time.perf_counter()
    try:
        result = case(tmp)
    except OptplanError as exc:
        dt = time.perf_counter() - t0
        ok = isinstance(expect, str) and expect in str(exc)
        return ("clear" if ok else "raw") if dt < SLOW_S else "slow", f"{type(exc).__name__}: {exc}", dt
    except Exception as exc:   # noqa: BLE001 - what the harness counts
        return "raw" if time.perf_counter() - t0 < SLOW_S else "slow", f"{type(exc).__name__}: {exc}", \
            time.perf_counter() - t0
    finally:
        if alarm:
            signal.alarm(0)
            signal.signal(signal.SIGALRM, old_handler)
    dt = time.perf_counter() - t0
    if callable(expect) and expect(result):
        return "clear" if dt < SLOW_S else "slow", f"returned {getattr(result, 'status', result)!r}", dt
    return "silent", f"returned {str(getattr(result, 'status', result))[:200]}", dt


@pytest.mark.parametrize("category,case,expect", CASES, ids=[c.__name__ for _, c, _ in CASES])
def test_bad_input_is_a_clear_error_or_status(category, case, expect, tmp_path):
    outcome, detail, seconds = classify(case, expect, tmp_path)
    assert outcome == "clear", f"{category}/{case.__name__}: {outcome} after {seconds:.2f} s: {detail[:600]}"


def test_big_scene_is_refused_fast(tmp_path):
    """A 50 MB scene is refused by its size before parsing: well under a second."""
    from optplan.errors import ModelError

    p = _sparse(tmp_path / "big.toml", 50_000_000)
    t0 = time.perf_counter()
    with pytest.raises(ModelError, match="MAX_SCENE_BYTES"):
        _load_scene(p)
    assert time.perf_counter() - t0 < 1.0


def test_limits_leave_the_shipped_files_alone():
    """Every shipped scene and robot is far inside the limits, and a scene at the obstacle limit
    still loads (the limit is a count, not a failure of the parser)."""
    from optplan import RobotModel, limits
    from optplan.model.description import available_models
    from optplan.scene import Scene, available_scenes

    for name in available_scenes():
        Scene.load(name)
    for name in available_models():
        RobotModel.from_name(name)
    with tempfile.TemporaryDirectory() as d:
        s = _load_scene(_write(Path(d), "at_limit.toml", _obstacles(limits.MAX_OBSTACLES)))
    assert len(s.obstacles) == limits.MAX_OBSTACLES


def test_nesting_depth_ignores_brackets_in_strings_and_comments():
    from optplan.limits import nesting_depth

    assert nesting_depth('a = "[[[[" # ]]]]]]\nb = [[1, 2], [3]]\n[[obstacles]]\n') == 2
    assert nesting_depth('{"p": [[0.0, 1.0]], "m": "[{["}') == 3


def test_reach_check_is_necessary_only():
    """The reach check refuses only poses no perturbation brings within reach: the shipped
    scenes pass, and a goal moved 1 m (reachable after perturbation) is not refused by it."""
    import pinocchio as pin

    from optplan import Scene
    from optplan.trials import TrialGenerator

    s = Scene.load("ssps_scene1")
    assert s.goal is not None
    TrialGenerator(_tcb(), dataclasses.replace(
        s, goal=pin.SE3(s.goal.rotation, s.goal.translation + np.array([1.0, 0.0, 0.0]))))


def main() -> int:
    """Run every case once; print the outcome of each and the counts by category."""
    counts: dict[str, dict[str, int]] = {}
    with tempfile.TemporaryDirectory() as d:
        os.environ.setdefault("OPTPLAN_CACHE", str(Path(d) / "cache"))
        for k, (category, case, expect) in enumerate(CASES):
            tmp = Path(d) / f"case{k}"
            tmp.mkdir()
            outcome, detail, seconds = classify(case, expect, tmp)
            counts.setdefault(category, {}).setdefault(outcome, 0)
            counts[category][outcome] += 1
            print(f"{category:7s} {case.__name__:34s} {outcome:6s} {seconds:6.2f} s  {detail[:160]!r}", flush=True)
    total: dict[str, int] = {}
    for category, c in counts.items():
        print(f"{category}: " + ", ".join(f"{k} {v}" for k, v in sorted(c.items())))
        for k, v in c.items():
            total[k] = total.get(k, 0) + v
    print("total: " + ", ".join(f"{k} {v}" for k, v in sorted(total.items())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
