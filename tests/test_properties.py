"""Property-based bad-input tests (hypothesis) over the public entry points.

Every generated case must end in an optplan exception (:class:`optplan.errors.OptplanError`) whose
message names the argument (and the file, for files), or in a result that passes its own checks —
never another exception type, never a success on bad data. Runs derandomized (fixed seed) with a
small number of examples per property so the default test run stays fast.

Categories: configuration vectors (shapes, dtypes bool/int/complex/object, NaN/inf, strings,
None), rotations and poses (non-orthonormal, reflections, scaled, NaN; zero/NaN quaternions),
IK targets, solver options (tol, max_iter, objective scaling, IPOPT option names/values), IK
options, corrupted Solution files (npz and JSON: random bytes, truncation, field mutations),
corrupted PlanResult JSON, robot-description TOML mutations, scene mutations, CLI numbers.
"""
from __future__ import annotations

import copy
import json
import math
import tomllib
import zipfile

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from optplan import cli
from optplan.cli_args import positive_float, positive_int
from optplan.errors import OptplanError, ResultFileError
from optplan.geometry.spatial import check_rotation, exp3, log3, se3, vector_to_pose
from optplan.model.description import load_description, models_dir
from optplan.model.ik import IKOptions, solve_arm_ik
from optplan.model.kinematics import Kinematics
from optplan.model.robot import RobotModel
from optplan.planners.base import PlanResult, PlanStatus
from optplan.problem import JointBoundary, OptProblem
from optplan.problem.solution import IpoptStatus, Solution
from optplan.scene import Scene

FAST = settings(max_examples=40, deadline=None, derandomize=True, database=None,
                suppress_health_check=list(HealthCheck))
FEW = settings(FAST, max_examples=15)

NAN, INF = float("nan"), float("inf")


@pytest.fixture(scope="module")
def robots():
    return {"tcb": RobotModel.from_name("tcbirrt_dual_arm"), "eba": RobotModel.from_name("eba_ffsr")}


# ----------------------------------------------------------------------------- strategies
def junk_scalars():
    """Values that are not a usable finite real number."""
    return st.one_of(st.sampled_from([NAN, INF, -INF, None, True, False, "1.0", "abc", "", 1 + 2j, [], {}, b"1"]),
                     st.text(max_size=5), st.complex_numbers(allow_nan=False, allow_infinity=False, max_magnitude=10)
                     .filter(lambda z: z.imag != 0))


def bad_vectors(n: int):
    """Anything that is not ``n`` finite real numbers."""
    wrong_len = st.integers(0, 2 * n + 2).filter(lambda m: m != n).map(lambda m: np.linspace(0.1, 0.2, m))
    wrong_dims = st.sampled_from([(n, 2), (2, n), (1, 1, n), ()]).map(lambda s: np.full(s, 0.1))
    non_finite = st.tuples(st.integers(0, n - 1), st.sampled_from([NAN, INF, -INF])).map(
        lambda t: np.where(np.arange(n) == t[0], t[1], 0.1))
    dtypes = st.sampled_from(["bool", "complex", "str", "object-str", "object-none", "bytes"]).map(
        lambda kind: {"bool": np.ones(n, bool), "complex": np.full(n, 0.1 + 0.5j),
                      "str": np.array(["0.1"] * n), "object-str": np.array([0.1] * (n - 1) + ["x"], dtype=object),
                      "object-none": np.array([0.1] * (n - 1) + [None], dtype=object),
                      "bytes": np.array([b"1"] * n)}[kind])
    strings = st.one_of(st.text(max_size=8), st.just(["0.1"] * n), st.just(None), st.just({"q": 1}))
    return st.one_of(wrong_len, wrong_dims, non_finite, dtypes, strings)


def not_rotations():
    """3 × 3 matrices that are not rotations (and some that are not 3 × 3 or not finite)."""
    R0 = st.builds(lambda w: exp3(np.asarray(w)), st.lists(st.floats(-3, 3), min_size=3, max_size=3))
    scaled = st.tuples(R0, st.floats(0.0, 3.0).filter(lambda s: abs(s - 1) > 1e-3)).map(lambda t: t[0] * t[1])
    reflected = R0.map(lambda R: R @ np.diag([1.0, 1.0, -1.0]))
    sheared = st.tuples(R0, st.floats(0.01, 1.0)).map(lambda t: t[0] @ np.array([[1, t[1], 0], [0, 1, 0], [0, 0, 1.0]]))
    nonfinite = st.tuples(R0, st.integers(0, 8), st.sampled_from([NAN, INF])).map(
        lambda t: np.where(np.arange(9).reshape(3, 3) == t[1], t[2], t[0]))
    shapes = st.sampled_from([np.eye(2), np.eye(4), np.zeros(3), np.zeros((3, 3))])
    return st.one_of(scaled, reflected, sheared, nonfinite, shapes)


def _expect_refusal(fn, *names):
    with pytest.raises(OptplanError) as exc:
        fn()
    msg = str(exc.value)
    assert msg and any(n in msg for n in names), (names, msg)
    return msg


# ----------------------------------------------------------------------------- vectors
@FAST
@given(q=bad_vectors(14))
def test_configuration_vectors(robots, q):
    kin = Kinematics(robots["tcb"])
    _expect_refusal(lambda: kin.frame_placement(q, "a_ee"), "q (Pinocchio configuration")


@FEW
@given(quat=st.one_of(st.just([0.0, 0.0, 0.0, 0.0]),
                      st.lists(st.floats(-2, 2), min_size=4, max_size=4).filter(lambda v: abs(np.linalg.norm(v) - 1) > 1e-3)))
def test_floating_base_quaternion(robots, quat):
    eba = robots["eba"]
    q = eba.neutral()
    q[3:7] = quat
    _expect_refusal(lambda: Kinematics(eba).center_of_mass(q), "quaternion")


# ----------------------------------------------------------------------------- rotations, poses, IK
@FAST
@given(R=not_rotations())
def test_rotations_are_checked(R):
    _expect_refusal(lambda: check_rotation(R, "R"), "R")
    _expect_refusal(lambda: se3(R, [0, 0, 0]), "se3: R")
    _expect_refusal(lambda: log3(R), "log3")


@FAST
@given(R=not_rotations().filter(lambda R: R.shape == (3, 3)), p=st.lists(st.floats(-2, 2), min_size=3, max_size=3))
def test_ik_refuses_non_rotation_targets(robots, R, p):
    tcb = robots["tcb"]
    goal = pin.SE3.Identity()
    goal.rotation = R
    goal.translation = np.asarray(p)
    _expect_refusal(lambda: solve_arm_ik(tcb, "A", goal, tcb.neutral(), IKOptions(max_iterations=2)), "goal")


@FEW
@given(p=st.tuples(st.integers(0, 2), st.sampled_from([NAN, INF, -INF])))
def test_ik_refuses_non_finite_targets(robots, p):
    tcb = robots["tcb"]
    goal = pin.SE3.Identity()
    t = np.zeros(3)
    t[p[0]] = p[1]
    goal.translation = t
    _expect_refusal(lambda: solve_arm_ik(tcb, "A", goal, tcb.neutral()), "goal")


@FAST
@given(v=st.one_of(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=9),
                   st.tuples(st.lists(st.floats(-5, 5), min_size=3, max_size=3)).map(lambda t: t[0] + [0.0] * 4),
                   junk_scalars()))
def test_pose_vectors(v):
    try:
        M = vector_to_pose(v)
    except OptplanError as exc:
        assert "pose" in str(exc)
        return
    check_rotation(M.rotation)       # accepted: a true pose from a nonzero finite quaternion
    assert np.all(np.isfinite(M.translation))


@FEW
@given(name=st.sampled_from(["tol_position", "tol_orientation", "damping", "max_step", "max_iterations"]),
       value=st.one_of(junk_scalars(), st.floats(max_value=0.0), st.integers(max_value=0)))
def test_ik_options(name, value):
    _expect_refusal(lambda: IKOptions(**{name: value}), f"IKOptions.{name}")


# ----------------------------------------------------------------------------- solver options
@pytest.fixture(scope="module")
def small_problem(robots):
    tcb = robots["tcb"]
    prob = OptProblem(tcb, n_intervals=2, duration=1.0)
    prob.add_constraint(JointBoundary("start", q=np.zeros(tcb.nj)))
    prob.set_initial_straight_line(np.zeros(tcb.nj), np.full(tcb.nj, 0.1))
    return prob


_IPOPT_BAD = st.one_of(
    st.tuples(st.sampled_from(["tol", "max_iter", "acceptable_tol", "print_level", "max_wall_time"]),
              st.one_of(st.just(-1), st.just("abc"), st.just(-0.5), st.just([1]))),
    st.tuples(st.sampled_from(["mu_strategy", "linear_solver", "hessian_approximation"]),
              st.one_of(st.just("bogus"), st.just(3), st.just(1.5))),
    st.tuples(st.text(alphabet="abcdefghijklmnopqrstuvwxyz_", min_size=3, max_size=12).map(lambda s: "zz_" + s),
              st.integers(0, 3)))


@FAST
@given(case=st.one_of(
    st.tuples(st.just("tol"), st.one_of(junk_scalars(), st.floats(max_value=0.0))),
    st.tuples(st.just("max_iter"), st.one_of(junk_scalars(), st.integers(max_value=-1), st.just(2.5))),
    st.tuples(st.just("objective_scaling"), st.one_of(junk_scalars(), st.floats(max_value=0.0), st.just("off"))),
    st.tuples(st.just("ipopt_options"), _IPOPT_BAD)))
def test_solve_arguments_and_ipopt_options(small_problem, case):
    what, value = case
    if what == "ipopt_options":
        key, val = value
        msg = _expect_refusal(lambda: small_problem.solve({key: val}), key)
    else:
        msg = _expect_refusal(lambda: small_problem.solve(**{what: value}), what)
    assert "Traceback" not in msg


# ----------------------------------------------------------------------------- result files
def _solution(n=4, nj=3) -> Solution:
    t = np.linspace(0.0, 1.0, n + 1)
    z = np.zeros((n + 1, nj))
    return Solution(success=True, status=IpoptStatus.SOLVE_SUCCEEDED, iterations=3, wall_time=0.1, cost=1.0,
                    max_constraint_violation=1e-9, terms={"jerk": 1.0}, t=t, q=z + 0.1, qd=z, qdd=z,
                    jerk=np.zeros((n, nj)), joint_names=("j1", "j2", "j3"))


_FIELD_JUNK = st.sampled_from(["nan", "shape", "status", "missing", "string", "success-on-nan", "null", "list"])


@FAST
@given(field=st.sampled_from(["t", "q", "qd", "qdd", "jerk", "status", "success", "iterations", "cost",
                              "max_constraint_violation", "terms", "joint_names"]), how=_FIELD_JUNK)
def test_solution_json_mutations(tmp_path_factory, field, how):
    path = _solution().save(tmp_path_factory.mktemp("sol") / "s.json")
    d = json.loads(path.read_text())
    if how == "missing":
        d.pop(field)
    elif how == "nan":
        d[field] = [NAN] * len(d[field]) if field == "joint_names" else (
            (np.asarray(d[field], float) * NAN).tolist() if isinstance(d[field], list) else NAN)
    elif how == "shape":
        d[field] = np.zeros((2, 7)).tolist()
    elif how == "status":
        d["status"] = "Converged_Sort_Of"
    elif how == "string":
        d[field] = "abc"
    elif how == "null":
        d[field] = None
    elif how == "list":
        d[field] = [[1, 2], [3]]
    else:
        d["q"] = (np.asarray(d["q"]) * NAN).tolist()
        d["success"] = True
    path.write_text(json.dumps(d))
    _check_loaded_or_refused(path)


def _check_loaded_or_refused(path):
    try:
        sol = Solution.load(path)
    except ResultFileError as exc:
        assert str(path) in str(exc)
        return
    sol.check()   # whatever loads is consistent, and success only on converged, finite data
    if sol.success:
        assert sol.status.succeeded and np.isfinite(sol.max_constraint_violation)


@FAST
@given(cut=st.floats(0.0, 1.0), noise=st.binary(min_size=0, max_size=64), mode=st.sampled_from(["truncate", "bytes", "meta"]))
def test_solution_npz_corruption(tmp_path_factory, cut, noise, mode):
    path = _solution().save(tmp_path_factory.mktemp("sol") / "s.npz")
    raw = path.read_bytes()
    if mode == "truncate":
        path.write_bytes(raw[:int(cut * len(raw))])
    elif mode == "bytes":
        path.write_bytes(noise)
    else:   # a valid zip whose metadata is not JSON / not an object
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
        arrays["meta"] = np.array(noise.decode("latin-1"))
        np.savez(path, **arrays)
    _check_loaded_or_refused(path)


def _plan_dict():
    path = np.linspace(0, 1, 3 * 14).reshape(3, 14)
    res = PlanResult(PlanStatus.EXACT, "tcbirrt", path, [pin.SE3.Identity()] * 3, np.ones(3, bool), [], {"nodes": 3})
    return res.to_dict()


@FAST
@given(field=st.sampled_from(["status", "path", "object_poses", "constrained", "segments", "stats", "message"]),
       value=st.one_of(junk_scalars(), st.just([[NAN] * 14] * 3), st.just([[0.0] * 7] * 3),
                       st.just([{"kind": "constrained", "start": 0, "stop": 9}]), st.just("exact"), st.just([])))
def test_plan_result_json(field, value):
    d = _plan_dict()
    d[field] = value
    try:
        text = json.dumps(d)
    except (TypeError, ValueError):
        return   # not representable as JSON (e.g. complex): nothing to load
    try:
        res = PlanResult.from_json(text, "plan.json")
    except ResultFileError as exc:
        assert "plan.json" in str(exc)
        return
    res.check()
    if res.status is PlanStatus.EXACT:
        assert len(res.path) >= 2 and np.all(np.isfinite(res.path))


@FEW
@given(text=st.one_of(st.text(max_size=30), st.just("{"), st.just("[]"), st.just("null"), st.just('{"status": 3}')))
def test_plan_result_garbage_json(text):
    try:
        PlanResult.from_json(text, "plan.json")
    except ResultFileError as exc:
        assert "plan.json" in str(exc)


# ----------------------------------------------------------------------------- descriptions
_EBA = (models_dir() / "robots" / "eba_ffsr.toml").read_text()
_NUMERIC_LINES = [i for i, ln in enumerate(_EBA.splitlines())
                  if "=" in ln and not ln.lstrip().startswith("#") and any(c.isdigit() for c in ln.split("=", 1)[1])
                  and not ln.split("=", 1)[0].strip().startswith(("name", "notes"))]
_TOML_JUNK = ["nan", "inf", "-inf", "-1.0", "0.0", '"abc"', "true", "[]", "1e308", "-1e-9", "[nan, 1, 2]"]


@FAST
@given(line=st.sampled_from(_NUMERIC_LINES), junk=st.sampled_from(_TOML_JUNK), mode=st.sampled_from(["value", "entry"]))
def test_robot_toml_value_mutations(tmp_path_factory, line, junk, mode):
    lines = _EBA.splitlines()
    key, rhs = lines[line].split("=", 1)
    if mode == "entry" and "[" in rhs:   # replace the first number inside a list
        import re

        rhs = re.sub(r"-?\d+(\.\d+)?(e-?\d+)?", junk, rhs, count=1)
    else:
        rhs = " " + junk
    lines[line] = key + "=" + rhs
    p = tmp_path_factory.mktemp("toml") / "robot.toml"
    p.write_text("\n".join(lines) + "\n")
    try:
        tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError:
        pass
    try:
        desc = load_description(p)
    except OptplanError as exc:
        assert "robot.toml" in str(exc) or key.strip() in str(exc)
        return
    _assert_physical(desc)


def _assert_physical(desc):
    assert desc.base_mass > 0 and math.isfinite(desc.base_mass) and desc.arms
    for at in desc.arm_types.values():
        for name in ("masses", "lower", "upper", "velocity", "effort"):
            v = np.atleast_1d(getattr(at, name))
            assert np.all(np.isfinite(v)), name
        assert np.all(np.atleast_1d(at.masses) > 0) and np.all(np.atleast_1d(at.velocity) > 0)
        assert np.all(np.atleast_1d(at.effort) > 0)
        assert np.all(np.atleast_1d(at.lower) < np.atleast_1d(at.upper))


@FEW
@given(edit=st.sampled_from([("[[arms]]", "[[armsx]]"), ("[base]", "[basex]"), ("mass =", "mas ="),
                             ("dh_convention", "dh_conv"), ("name = \"A\"", "name = \"A\"\ncolour = 3"),
                             ("radius =", "radius_m ="), ("[[arms]]", "[[arms]]\nextra_key = 1")]))
def test_robot_toml_unknown_keys(tmp_path_factory, edit):
    p = tmp_path_factory.mktemp("toml") / "robot.toml"
    p.write_text(_EBA.replace(edit[0], edit[1], 1))
    _expect_refusal(lambda: load_description(p), "robot.toml")


_SCENE = tomllib.loads((models_dir() / "scenes" / "transport.toml").read_text())
_SCENE_PATHS = [("robot",), ("angle_unit",), ("obstacles",), ("obstacles", 0, "size"), ("obstacles", 0, "shape"),
                ("obstacles", 0, "xyz"), ("object",), ("object", "size"), ("object", "grasps"),
                ("object", "exclude_links"), ("start",), ("start", "xyz"), ("goal", "rpy"), ("extra",), ("typo",)]


@FAST
@given(where=st.sampled_from(_SCENE_PATHS),
       value=st.one_of(junk_scalars(), st.just([NAN, 0, 0]), st.just([1, 2]), st.just({"x": 1}), st.just("r2d2"),
                       st.just(["a_link99"]), st.just([-1.0, 1.0, 1.0])))
def test_scene_mutations(robots, where, value):
    d = copy.deepcopy(_SCENE)
    node = d
    for k in where[:-1]:
        node = node[k]
    node[where[-1]] = value
    try:
        scene = Scene.from_dict(d, "scene.toml")
        if scene.object is not None:
            scene.object.check_robot(robots["tcb"])
    except OptplanError as exc:
        assert str(exc)
        return
    for o in scene.obstacles:    # accepted: a physical scene
        assert o.size is None or (np.all(np.isfinite(o.size)) and min(o.size) > 0)
        assert np.all(np.isfinite(o.placement.translation))


# ----------------------------------------------------------------------------- CLI numbers
@FAST
@given(text=st.one_of(st.text(max_size=6), st.sampled_from(["0", "-1", "nan", "inf", "1e400", "1.5", " 3", "0x10"])))
def test_cli_number_arguments(text):
    import argparse

    for conv in (positive_int, positive_float):
        try:
            v = conv(text)
        except argparse.ArgumentTypeError as exc:
            assert repr(text) in str(exc)
            continue
        assert v > 0 and math.isfinite(v)
    try:
        args = cli.build_parser().parse_args(["bench", "tcbirrt", "--trials", text, "--time-limit", text])
    except SystemExit as exc:
        assert exc.code == 2
        return
    assert args.trials >= 1 and args.time_limit > 0


def test_zipfile_is_not_a_library_error(tmp_path):
    """The one error type: a zip that is not an npz of a Solution."""
    p = tmp_path / "s.npz"
    with zipfile.ZipFile(p, "w") as z:
        z.writestr("hello.txt", "hi")
    with pytest.raises(ResultFileError, match="s.npz"):
        Solution.load(p)


@FAST
@given(frame=st.one_of(junk_scalars(), st.integers(), st.text(max_size=8)),
       reference=st.one_of(st.sampled_from(["local", "world", "world_aligned"]), st.text(max_size=6), junk_scalars()))
def test_frame_and_reference_names(robots, frame, reference):
    tcb = robots["tcb"]
    kin = Kinematics(tcb)
    try:
        J = kin.frame_jacobian(tcb.neutral(), frame, reference=reference)
    except OptplanError as exc:
        assert str(exc)
        return
    assert J.shape == (6, tcb.nv) and np.all(np.isfinite(J))
