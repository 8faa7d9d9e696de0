"""Collision meshes as bounding boxes (optplan.model.mesh_boxes): the box encloses every mesh
vertex in the link frame (checked against the vertices placed by the URDF's own origin with
Pinocchio's SE3), and a missing mesh is a clear error."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.errors import ModelError
from optplan.model.mesh_boxes import collision_meshes_as_boxes
from optplan.model.robot import RobotModel

RPY = (0.3, -0.4, 0.9)
XYZ = (0.05, -0.02, 0.1)


def _write(tmp_path, rng: np.random.Generator, scale: str = "1 1 1") -> tuple:
    V = rng.normal(size=(30, 3)) * [0.04, 0.02, 0.07] + [0.01, 0.0, 0.03]
    obj = tmp_path / "part.obj"
    obj.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in V)
                   + "".join(f"f {i} {i + 1} {i + 2}\n" for i in range(1, 29)))
    urdf = tmp_path / "one.urdf"
    urdf.write_text(f"""<robot name="one">
  <link name="base"/>
  <link name="l1"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><geometry><mesh filename="part.obj"/></geometry></visual>
    <collision><origin xyz="{' '.join(map(str, XYZ))}" rpy="{' '.join(map(str, RPY))}"/>
      <geometry><mesh filename="part.obj" scale="{scale}"/></geometry></collision></link>
  <link name="ee"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
  <joint name="jee" type="fixed"><parent link="l1"/><child link="ee"/><origin xyz="0 0 0.2"/></joint>
</robot>""")
    return urdf, V


@pytest.mark.parametrize("scale", ["1 1 1", "2 0.5 1"])
def test_box_encloses_the_mesh_in_the_link_frame(tmp_path, scale):
    urdf, V = _write(tmp_path, np.random.default_rng(3), scale)
    out = collision_meshes_as_boxes(urdf)
    assert "<mesh" not in out.read_text() and "<visual" not in out.read_text()
    r = RobotModel.from_urdf(out, arms={"A": "ee"})
    (go,) = [g for g in r.collision_model.geometryObjects if g.parentJoint == r.model.getJointId("j1")]
    M = go.placement  # box placement in the joint frame (l1's frame: the joint has no offset)
    half = np.asarray(go.geometry.halfSide)
    s = np.array([float(v) for v in scale.split()])
    Mc = pin.SE3(pin.rpy.rpyToMatrix(*RPY), np.array(XYZ))
    pts = (Mc.rotation @ (V * s).T).T + Mc.translation
    local = (M.rotation.T @ (pts - M.translation).T).T
    assert np.all(np.abs(local) <= half + 1e-6)   # the mesh loader reads float32
    assert np.any(np.isclose(np.abs(local), half, atol=1e-6))   # tight: a vertex on the box


def test_missing_mesh_is_a_model_error(tmp_path):
    urdf, _ = _write(tmp_path, np.random.default_rng(0))
    (tmp_path / "part.obj").unlink()
    with pytest.raises(ModelError, match="part.obj"):
        collision_meshes_as_boxes(urdf)
    with pytest.raises(ModelError, match="does not exist"):
        collision_meshes_as_boxes(tmp_path / "nope.urdf")
