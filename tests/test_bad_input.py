"""Bad input is refused with an optplan exception whose message names the offending value.

Exception types (optplan.errors): ModelError (descriptions, URDFs), UnknownNameError (names; the
message lists the valid ones), ConfigurationError (vectors), plain ValueError for option strings.
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from optplan.errors import ConfigurationError, ModelError, OptplanError, UnknownNameError
from optplan.model.description import load_description, models_dir, urdf_dir
from optplan.model.floating import joint_trajectory_from_samples, simulate_base
from optplan.model.kinematics import Kinematics
from optplan.model.robot import RobotModel
from optplan.model.symbolic import SymbolicKinematics
from optplan.model.urdf_writer import urdf_string

EBA_TOML = (models_dir() / "robots" / "eba_ffsr.toml").read_text()
DH_BLOCK = re.compile(r"^dh = \[\[.*?\]\]\n", re.S | re.M)


def _write(tmp_path: Path, text: str, name: str = "robot.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _drop_table(text: str, header: str) -> str:
    out, skip = [], False
    for line in text.splitlines():
        if line.strip().startswith("["):
            skip = line.strip() == header
        if not skip:
            out.append(line)
    return "\n".join(out) + "\n"


def _still(robot):
    return lambda t: (np.zeros(robot.nj), np.zeros(robot.nj))


# --------------------------------------------------------------------------- files
def test_exception_hierarchy():
    assert issubclass(ModelError, ValueError) and issubclass(ModelError, OptplanError)
    assert issubclass(ConfigurationError, ValueError) and issubclass(ConfigurationError, OptplanError)
    assert issubclass(UnknownNameError, KeyError) and issubclass(UnknownNameError, OptplanError)


def test_missing_toml(tmp_path):
    p = tmp_path / "nope.toml"
    with pytest.raises(ModelError) as exc:
        load_description(p)
    assert str(p) in str(exc.value)


def test_missing_urdf(tmp_path):
    p = tmp_path / "nope.urdf"
    with pytest.raises(ModelError) as exc:
        RobotModel.from_urdf(p, {"A": "a_ee"})
    assert str(p) in str(exc.value)


def test_shipped_model_without_its_urdf(tmp_path, monkeypatch):
    (tmp_path / "models" / "robots").mkdir(parents=True)
    (tmp_path / "models" / "robots" / "eba_ffsr.toml").write_text(EBA_TOML)
    monkeypatch.setenv("OPTPLAN_ROOT", str(tmp_path))
    with pytest.raises(ModelError) as exc:
        RobotModel.from_name("eba_ffsr")
    assert "eba_ffsr.urdf" in str(exc.value) and "optplan models build" in str(exc.value)


def test_malformed_toml(tmp_path):
    p = _write(tmp_path, EBA_TOML.replace('base_type = "floating"', "base_type = "))
    with pytest.raises(ModelError) as exc:
        load_description(p)
    assert "malformed TOML" in str(exc.value) and str(p) in str(exc.value)


@pytest.mark.parametrize("text,needle", [
    ('<robot name="x"><link name="a"></robot>', "malformed URDF XML"),
    ("not xml at all", "malformed URDF XML"),
    ('<sdf version="1.6"><model name="x"/></sdf>', "<sdf>"),
    ('<robot name="x"/>', "could not parse"),  # no links
    ('<robot name="x"><link name="a"/><joint name="j" type="revolute"><parent link="a"/><child link="zz"/>'
     '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>',
     "child link 'zz' is not defined"),
])
def test_malformed_urdf(tmp_path, text, needle):
    p = _write(tmp_path, text, "bad.urdf")
    with pytest.raises(ModelError) as exc:
        RobotModel.from_urdf(p, {})
    assert needle in str(exc.value) and str(p) in str(exc.value)


def test_capsule_named_collision_must_be_a_cylinder(tmp_path):
    text = ('<robot name="x"><link name="a"><collision name="c_capsule"><geometry><box size="1 1 1"/>'
            "</geometry></collision></link></robot>")
    with pytest.raises(ModelError, match="c_capsule"):
        RobotModel.from_urdf(_write(tmp_path, text, "x.urdf"), {})


# --------------------------------------------------------------------------- TOML content
@pytest.mark.parametrize("key,mutate", [
    ("name", lambda s: s.replace('name = "eba_ffsr"\n', "")),
    ("base", lambda s: _drop_table(s, "[base]")),
    ("arms", lambda s: _drop_table(s, "[[arms]]")),
    ("mass", lambda s: s.replace("mass = 510.0\n", "")),
    ("inertia", lambda s: s.replace("inertia = [625.0, -4.95, 6.58, 452.5, -2.39, 450.0]\n", "")),
    ("dh", lambda s: DH_BLOCK.sub("", s)),
    ("masses", lambda s: s.replace("masses = [6.34, 6.34, 7.93, 5.67, 2.80, 2.70, 10.01]\n", "")),
    ("dh_convention", lambda s: s.replace('dh_convention = "modified"\n', "")),
    ("prefix", lambda s: s.replace('prefix = "b"\n', "")),
    ("type", lambda s: s.replace('type = "eba7"\nprefix = "a"', 'prefix = "a"')),
])
def test_missing_key_is_named(tmp_path, key, mutate):
    text = mutate(EBA_TOML)
    assert text != EBA_TOML
    with pytest.raises(ModelError) as exc:
        load_description(_write(tmp_path, text))
    assert f"missing key {key!r}" in str(exc.value)


@pytest.mark.parametrize("dh,needle", [
    ("[[0, 0, 0], [0, 0, 0]]", "(2, 3)"),
    ("[[0, 0, 0, 0, 0]]", "(1, 5)"),
    ("[0, 0, 0, 0]", "(4,)"),
    ("[]", "(0,)"),
    ("[[0, 0, 0.225], [0, 90, 0, 0.24]]", "[[0, 0, 0.225], [0, 90, 0, 0.24]]"),  # ragged
    ('[["x", 0, 0, 0]]', "'x'"),
])
def test_bad_dh_rows(tmp_path, dh, needle):
    with pytest.raises(ModelError) as exc:
        load_description(_write(tmp_path, DH_BLOCK.sub(f"dh = {dh}\n", EBA_TOML)))
    assert "dh" in str(exc.value) and needle in str(exc.value)


@pytest.mark.parametrize("old,new,needle", [
    ('angle_unit = "deg"', 'angle_unit = "grad"', "'grad'"),
    ('base_type = "floating"', 'base_type = "free"', "'free'"),
    ('dh_convention = "modified"', 'dh_convention = "craig"', "'craig'"),
    ("masses = [6.34, 6.34, 7.93", "masses = [6.34, -6.34, 7.93", "-6.34"),
    ("masses = [6.34, 6.34, 7.93, 5.67, 2.80, 2.70, 10.01]", "masses = [6.34, 6.34]", "(2,)"),
    ("masses = [6.34, 6.34, 7.93", "masses = [6.34, nan, 7.93", "nan"),
    ("lower = [-360.0,", "lower = [400.0,", "lower limits"),
    ("{ link = 7, a", "{ link = 8, a", "got 8"),
    ("b = [0, 0, 0], radius = 0.05 }]", "b = [0, 0, 0], radius = -0.05 }]", "-0.05"),
    ("mount_zyx = [90.0, 26.0, 0.0]", "mount_zyx = [90.0, 26.0]", "[90.0, 26.0]"),
    ('name = "eba_ffsr"', "name = 5", "5"),
    ('prefix = "b"', 'prefix = "a"', "['a', 'a']"),
])
def test_bad_values_are_named(tmp_path, old, new, needle):
    assert old in EBA_TOML
    with pytest.raises(ModelError) as exc:
        load_description(_write(tmp_path, EBA_TOML.replace(old, new)))
    assert needle in str(exc.value)


def test_unknown_arm_type_lists_the_valid_ones(tmp_path):
    text = EBA_TOML.replace('type = "eba7"\nprefix = "b"', 'type = "eba8"\nprefix = "b"')
    with pytest.raises(UnknownNameError) as exc:
        load_description(_write(tmp_path, text))
    assert "'eba8'" in str(exc.value) and "eba7" in str(exc.value)


def test_non_string_angle_unit(tmp_path):
    with pytest.raises(ModelError, match="angle_unit"):
        load_description(_write(tmp_path, EBA_TOML.replace('angle_unit = "deg"', 'angle_unit = ["deg"]')))


def test_non_table_tool(tmp_path):
    text = EBA_TOML.replace("velocity = [10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.0]",
                            "velocity = [10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.0]\ntool = 5")
    with pytest.raises(ModelError, match="tool"):
        load_description(_write(tmp_path, text))


def test_non_table_capsule(tmp_path):
    text = EBA_TOML.replace("{ link = 7, a = [0, 0, -0.476], b = [0, 0, 0], radius = 0.05 }]", "5]")
    with pytest.raises(ModelError, match=r"capsules\[8\]"):
        load_description(_write(tmp_path, text))


@pytest.mark.parametrize("mass", ["-510.0", "0.0"])
def test_non_positive_base_mass(tmp_path, mass):
    with pytest.raises(ModelError, match="mass"):
        load_description(_write(tmp_path, EBA_TOML.replace("mass = 510.0", f"mass = {mass}")))


def test_non_physical_inertia(tmp_path):
    text = EBA_TOML.replace("inertia = [625.0, -4.95", "inertia = [-625.0, -4.95")
    with pytest.raises(ModelError, match="inertia"):
        load_description(_write(tmp_path, text))


@pytest.mark.parametrize("old,new", [('prefix = "b"', 'prefix = "b\\"x"'),
                                     ('name = "eba_ffsr"', 'name = "eb\\"a"')])
def test_names_that_break_the_urdf_are_refused(tmp_path, old, new):
    try:
        desc = load_description(_write(tmp_path, EBA_TOML.replace(old, new)))
    except ModelError:
        return
    ET.fromstring(urdf_string(desc))  # must at least be well-formed XML


# --------------------------------------------------------------------------- names
def test_unknown_model_name_lists_valid_names():
    for call in (RobotModel.from_name, load_description):
        with pytest.raises(UnknownNameError) as exc:
            call("no_such_robot")
        assert "'no_such_robot'" in str(exc.value) and "eba_ffsr" in str(exc.value)


def test_unknown_frame_lists_valid_names(eba):
    kin, q = Kinematics(eba), eba.neutral()
    for call in (lambda: kin.frame_placement(q, "c_ee"), lambda: kin.frame_jacobian(q, "c_ee"),
                 lambda: kin.generalized_jacobian(q, frame="c_ee"), lambda: eba.frame_id("c_ee"),
                 lambda: SymbolicKinematics(eba).fk_function("c_ee")):
        with pytest.raises(UnknownNameError) as exc:
            call()
        assert "'c_ee'" in str(exc.value) and "a_ee" in str(exc.value)
    with pytest.raises(UnknownNameError) as exc:
        eba.frame_id(10_000)
    assert "10000" in str(exc.value)
    with pytest.raises(UnknownNameError):
        eba.frame_id(-1)


def test_unknown_arm_lists_valid_names(eba):
    kin, q = Kinematics(eba), eba.neutral()
    for call in (lambda: eba.arm("C"), lambda: kin.generalized_jacobian(q, "C"),
                 lambda: SymbolicKinematics(eba).generalized_jacobian_function("C")):
        with pytest.raises(UnknownNameError) as exc:
            call()
        assert "'C'" in str(exc.value) and "A" in exc.value.valid and "B" in exc.value.valid
        assert "[A, B]" in str(exc.value)


def test_unknown_ee_or_joint_in_arm_spec():
    path = urdf_dir() / "tcbirrt_dual_arm.urdf"
    with pytest.raises(UnknownNameError) as exc:
        RobotModel.from_urdf(path, {"X": "z_ee"})
    assert "'z_ee'" in str(exc.value) and "a_ee" in str(exc.value)
    with pytest.raises(UnknownNameError) as exc:
        RobotModel.from_urdf(path, {"X": {"ee": "a_ee", "joints": ["a_joint1", "z_joint9"]}})
    assert "'z_joint9'" in str(exc.value) and "a_joint1" in str(exc.value)
    with pytest.raises(ModelError, match="'X'"):
        RobotModel.from_urdf(path, {"X": {"joints": ["a_joint1"]}})
    with pytest.raises(ModelError, match="no actuated joint"):
        RobotModel.from_urdf(path, {"X": "base"})


# --------------------------------------------------------------------------- configurations
@pytest.mark.parametrize("name", ["eba", "tcb"])
def test_wrong_configuration_size(name, request):
    robot = request.getfixturevalue(name)
    kin = Kinematics(robot)
    bad = np.zeros(robot.nq - 1)
    for call in (robot.check_q, lambda q: kin.frame_placement(q, "a_ee"), lambda q: kin.centroidal_map(q),
                 lambda q: kin.generalized_jacobian(q, "A"), robot.self_distances):
        with pytest.raises(ConfigurationError) as exc:
            call(bad)
        assert f"({robot.nq - 1},)" in str(exc.value) and f"({robot.nq},)" in str(exc.value)
    with pytest.raises(ConfigurationError, match=r"\(3, 7\)"):
        robot.check_q(np.zeros((3, 7)))
    with pytest.raises(ConfigurationError, match="None"):
        robot.check_q(None)
    with pytest.raises(ConfigurationError, match="'a'"):
        robot.check_q(["a"] * robot.nq)
    with pytest.raises(ConfigurationError, match=r"\(5,\)"):
        robot.configuration(np.zeros(5))
    with pytest.raises(ConfigurationError, match=r"\(3,\)"):
        kin.momentum(robot.neutral(), np.zeros(3))
    with pytest.raises(ConfigurationError, match=r"\(3,\)"):
        kin.full_velocity(robot.neutral(), np.zeros(3))


@pytest.mark.parametrize("name", ["eba", "tcb"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_configuration(name, bad, request):
    robot = request.getfixturevalue(name)
    q = robot.neutral()
    q[robot.nq - 2] = bad
    for call in (robot.check_q, lambda q: Kinematics(robot).frame_jacobian(q, "b_ee")):
        with pytest.raises(ConfigurationError) as exc:
            call(q)
        assert f"[{robot.nq - 2}]" in str(exc.value) and str(bad) in str(exc.value)


@pytest.mark.parametrize("quat,norm", [([0, 0, 0, 2.0], "2"), ([0, 0, 0, 0.0], "0"), ([0.1, 0.2, 0.3, 0.4], "0.547723")])
def test_non_unit_quaternion(eba, quat, norm):
    q = eba.neutral()
    q[3:7] = quat
    for call in (eba.check_q, lambda q: Kinematics(eba).frame_placement(q, "a_ee"),
                 lambda q: Kinematics(eba).generalized_jacobians(q)):
        with pytest.raises(ConfigurationError) as exc:
            call(q)
        assert str([float(x) for x in quat]) in str(exc.value) and f"norm {norm}" in str(exc.value)


def test_nearly_unit_quaternion_is_accepted(eba):
    q = eba.neutral()
    q[6] = 1 + 1e-9
    eba.check_q(q)


def test_fixed_base_robot_takes_no_base_placement(tcb):
    with pytest.raises(ConfigurationError, match="tcbirrt_dual_arm"):
        tcb.configuration(np.zeros(14), pin.SE3.Identity())


def test_random_configuration_needs_a_generator(eba):
    with pytest.raises(TypeError, match="int"):
        eba.random_configuration(3)


# --------------------------------------------------------------------------- floating-only calls
def test_simulate_base_on_fixed_base_robot(tcb):
    with pytest.raises(ConfigurationError) as exc:
        simulate_base(tcb, _still(tcb), [0.0, 1.0])
    assert "'tcbirrt_dual_arm'" in str(exc.value) and "fixed base" in str(exc.value)


def test_base_velocity_on_fixed_base_robot(tcb):
    with pytest.raises(ConfigurationError, match="'tcbirrt_dual_arm'"):
        Kinematics(tcb).base_velocity(tcb.neutral(), np.zeros(14))


def test_simulate_base_bad_arguments(eba):
    with pytest.raises(ConfigurationError, match=r"\(2,\)"):
        simulate_base(eba, _still(eba), [1.0, 0.0])
    with pytest.raises(ConfigurationError, match=r"\(1,\)"):
        simulate_base(eba, _still(eba), [0.0])
    with pytest.raises(ValueError, match="substeps.*0"):
        simulate_base(eba, _still(eba), [0.0, 1.0], substeps=0)
    with pytest.raises(ConfigurationError, match=r"h0.*\(2,\)"):
        simulate_base(eba, _still(eba), [0.0, 1.0], h0=[1.0, 2.0])
    with pytest.raises(ConfigurationError, match="h0"):
        simulate_base(eba, _still(eba), [0.0, 1.0], h0=[np.nan] * 6)
    with pytest.raises(ValueError):
        simulate_base(eba, lambda t: (np.zeros(3), np.zeros(3)), [0.0, 1.0])


def test_simulate_base_refuses_non_finite_trajectory(eba):
    with pytest.raises(ConfigurationError, match="nan"):
        simulate_base(eba, lambda t: (np.full(eba.nj, np.nan), np.zeros(eba.nj)), [0.0, 1.0])


def test_joint_trajectory_from_bad_samples():
    with pytest.raises(ConfigurationError, match="increasing"):
        joint_trajectory_from_samples([0.0, 1.0, 1.0], np.zeros((3, 2)))
    with pytest.raises(ConfigurationError, match=r"\(3,\).*\(2, 2\)"):
        joint_trajectory_from_samples([0.0, 1.0, 2.0], np.zeros((2, 2)))


# --------------------------------------------------------------------------- option strings
def test_wrong_reference_string(tcb):
    kin = Kinematics(tcb)
    with pytest.raises(ValueError) as exc:
        kin.frame_jacobian(tcb.neutral(), "a_ee", "bogus")
    assert "'bogus'" in str(exc.value) and "world_aligned" in str(exc.value)
    sk = SymbolicKinematics(tcb)
    for call in (lambda: sk.jacobian_function("a_ee", "bogus"), lambda: sk.fk_jacobian_function("a_ee", "bogus")):
        with pytest.raises(ValueError) as exc:
            call()
        assert "'bogus'" in str(exc.value) and "world_aligned" in str(exc.value)
    with pytest.raises(ValueError):  # Pinocchio's own capitalised names are not accepted either
        kin.frame_jacobian(tcb.neutral(), "a_ee", "LOCAL_WORLD_ALIGNED")
