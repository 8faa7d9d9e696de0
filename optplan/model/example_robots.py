"""Robots we did not write: PR2 and Baxter from the PyPI package ``example-robot-data``
(optional extra ``robots``: ``pip install "optplan[robots]"``).

Both are loaded as fixed-base dual-arm robots with 14 planning joints (two 7-joint arms):

* everything else (PR2: base, torso lift, head, laser tilt, grippers; Baxter: head, grippers) is
  frozen in the URDF (made ``fixed``) at a documented value, so the Pinocchio model has exactly the
  arm joints and :class:`~optplan.model.robot.RobotModel` works unchanged;
* PR2's continuous joints (forearm roll, wrist roll) become revolute joints with limits ``[-2π, 2π]``
  (a planner in joint space needs a bounded box; ±2π rather than ±π so that a path can cross
  ±π, where PR2's wrist often sits when the gripper points forward);
* collision geometry: the convex hull of every link's collision mesh (coal ``Convex``).
  Hulls rather than the raw triangle meshes because GJK on a hull is ~10× faster than a BVH
  mesh-mesh test and a hull is conservative (it contains the mesh: no collision is missed);
  rather than fitted capsules because the hulls come straight from the vendor meshes (nothing to
  fit or tune) and are tighter around the grippers and the PR2 forearm.

Arm groups: ``"left"`` and ``"right"``. End-effector frames: PR2 ``{l,r}_gripper_tool_frame``
(between the fingertips, x along the gripper), Baxter ``{left,right}_gripper`` (z along the
gripper).
"""
from __future__ import annotations

import logging
import math
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from ..errors import ModelError
from ._robot_data import _require_dir, example_robot_data_dir
from .robot import RobotModel

__all__ = ["example_robot_data_dir", "example_robots_available", "known_robot_names", "load_robot", "load_pr2", "load_baxter", "load_example_robot",
           "EXAMPLE_ROBOTS", "PR2_ARM_JOINTS", "BAXTER_ARM_JOINTS"]
log = logging.getLogger(__name__)

PR2_ARM_JOINTS = {s: [f"{p}_{j}_joint" for j in ("shoulder_pan", "shoulder_lift", "upper_arm_roll", "elbow_flex",
                                                  "forearm_roll", "wrist_flex", "wrist_roll")]
                  for s, p in (("left", "l"), ("right", "r"))}
BAXTER_ARM_JOINTS = {s: [f"{s}_{j}" for j in ("s0", "s1", "e0", "e1", "w0", "w1", "w2")] for s in ("left", "right")}
PR2_TORSO_LIFT = 0.15   # [m] frozen torso lift (range 0 .. 0.31 m)
EXAMPLE_ROBOTS = ("pr2", "baxter", "dual_panda")


def known_robot_names() -> list[str]:
    """Every robot loadable by name (:func:`load_robot`): shipped descriptions, example-robot-data's,
    robot files in ``models/robots/files``."""
    from .description import available_models
    from .robot_file import available_robot_files

    return list(available_models()) + list(EXAMPLE_ROBOTS) + available_robot_files()


def load_robot(name: str) -> RobotModel:
    """A robot by name or path: one of example-robot-data's (``pr2``, ``baxter``, ``dual_panda``)
    or anything :meth:`RobotModel.from_name` loads (shipped, robot file, URDF path)."""
    return load_example_robot(name) if name in EXAMPLE_ROBOTS else RobotModel.from_name(name)


def example_robots_available() -> bool:
    d = example_robot_data_dir()
    return d is not None and (d / "robots/pr2_description/urdf/pr2.urdf").exists()


def _freeze(urdf: Path, keep: set[str], *, share: Path, continuous_limit: float = 2 * math.pi,
            frozen_values: dict[str, float] | None = None) -> str:
    """URDF text with every movable joint not in ``keep`` made fixed (at ``frozen_values`` or 0),
    continuous joints in ``keep`` made revolute in ``[-continuous_limit, continuous_limit]``, and
    ``package://example-robot-data/`` mesh paths made absolute."""
    frozen_values = frozen_values or {}
    root = ET.parse(urdf).getroot()
    for t in list(root.findall("transmission")) + list(root.findall("gazebo")):
        root.remove(t)
    found = set()
    for j in root.findall("joint"):
        name, typ = j.attrib["name"], j.get("type")
        if typ == "fixed":
            continue
        if name in keep:
            found.add(name)
            if typ == "continuous":
                j.set("type", "revolute")
                lim = j.find("limit")
                if lim is None:
                    lim = ET.SubElement(j, "limit", {"effort": "30", "velocity": "3"})
                lim.set("lower", repr(-continuous_limit))
                lim.set("upper", repr(continuous_limit))
            continue
        val = float(frozen_values.get(name, 0.0))
        if val != 0.0:
            o = j.find("origin")
            if o is None:
                o = ET.SubElement(j, "origin", {"xyz": "0 0 0", "rpy": "0 0 0"})
            ax = j.find("axis")
            axis = np.array([float(x) for x in (ax.attrib["xyz"].split() if ax is not None else ["1", "0", "0"])])
            if typ != "prismatic":
                raise ModelError(f"freezing {name!r} at a non-zero value is only implemented for prismatic joints")
            xyz = np.array([float(x) for x in o.get("xyz", "0 0 0").split()])
            rpy = [float(x) for x in o.get("rpy", "0 0 0").split()]
            if any(abs(a) > 0 for a in rpy):
                raise ModelError(f"freezing {name!r}: rotated origins are not supported")
            o.set("xyz", " ".join(repr(float(v)) for v in xyz + val * axis))
        j.set("type", "fixed")
        for tag in ("limit", "mimic", "dynamics", "safety_controller", "calibration"):
            for e in j.findall(tag):
                j.remove(e)
    missing = keep - found
    if missing:
        raise ModelError(f"{urdf}: joints {sorted(missing)} not found")
    for m in root.iter("mesh"):
        fn = m.get("filename", "")
        if fn.startswith("package://example-robot-data/"):
            m.set("filename", str(share / fn[len("package://example-robot-data/"):]))
    return ET.tostring(root, encoding="unicode")


def _convex_hulls(robot: RobotModel) -> int:
    """Replace every mesh collision geometry by its convex hull (see the module docstring)."""
    n = 0
    for obj in robot.collision_model.geometryObjects:
        g = obj.geometry
        if isinstance(g, coal.BVHModelBase):
            # the hull (qhull), not buildConvexRepresentation: that one keeps the mesh's own triangles as
            # the polytope's faces, and on a non-convex mesh coal's hill-climbing support function then
            # stops at local maxima: distances too large by centimetres to decimetres, collisions missed
            g.buildConvexHull(True, "Qt")
            obj.geometry = g.convex
            n += 1
    return n


#: self-collision pairs whose HULLS overlap where the meshes never touch: PR2's torso hull fills the
#: concave shoulder mounts, so the upper arms enter it in a third of the joint box (sampled: 196 of
#: 600 pair tests in collision as hulls, 0 as meshes, mesh distance ≥ 3.6 cm); they are not checked
_HULL_ONLY_PAIRS = {"pr2": (("torso_lift_link_0", "l_upper_arm_link_0"), ("torso_lift_link_0", "r_upper_arm_link_0"))}


def _drop_hull_only_pairs(robot: RobotModel, kind: str) -> None:
    drop = {frozenset(p) for p in _HULL_ONLY_PAIRS.get(kind, ())}
    if not drop:
        return
    objs = robot.collision_model.geometryObjects
    robot.collision_pairs = [(a, b) for a, b in robot.collision_pairs
                             if frozenset((objs[a].name, objs[b].name)) not in drop]
    robot.collision_model.removeAllCollisionPairs()
    for a, b in robot.collision_pairs:
        robot.collision_model.addCollisionPair(pin.CollisionPair(a, b))
    robot.collision_data = pin.GeometryData(robot.collision_model)


def _load(kind: str) -> RobotModel:
    share = _require_dir()
    if kind == "pr2":
        urdf = share / "robots/pr2_description/urdf/pr2.urdf"
        joints = PR2_ARM_JOINTS
        ee = {"left": "l_gripper_tool_frame", "right": "r_gripper_tool_frame"}
        frozen = {"torso_lift_joint": PR2_TORSO_LIFT}
    elif kind == "baxter":
        urdf = share / "robots/baxter_description/urdf/baxter.urdf"
        joints = BAXTER_ARM_JOINTS
        ee = {"left": "left_gripper", "right": "right_gripper"}
        frozen = {}
    else:
        raise ModelError(f"unknown example robot {kind!r}; expected one of {EXAMPLE_ROBOTS}")
    if not urdf.exists():
        raise ModelError(f"{urdf} is missing from the example-robot-data installation")
    keep = set(joints["left"]) | set(joints["right"])
    text = _freeze(urdf, keep, share=share, frozen_values=frozen)
    cache = Path(tempfile.gettempdir()) / "optplan_example_robots"
    cache.mkdir(exist_ok=True)
    path = cache / f"{kind}_arms.urdf"
    if not path.exists() or path.read_text() != text:
        from .._io import write_text

        write_text(path, text)   # atomic: a concurrent process never reads half a URDF
    # RobotModel builds its default self-collision pairs on the geometry it is given: convert the
    # meshes to hulls first by building, converting, then rebuilding the pair list.
    arms = {s: {"ee": ee[s], "joints": joints[s]} for s in ("left", "right")}
    robot = RobotModel.from_urdf(path, arms=arms, name=kind)
    _convex_hulls(robot)
    RobotModel.__init__(robot, robot.model, robot.collision_model, arms, name=kind, floating=False, urdf_path=path)
    _drop_hull_only_pairs(robot, kind)
    order = [robot.model.getJointId(n) for n in joints["left"] + joints["right"]]
    if robot.nj != 14 or sorted(order) != order:
        log.info("%s: joint order %s", kind, robot.joint_names)
    return robot


def load_pr2() -> RobotModel:
    """PR2's two arms (base and torso fixed, torso lift 0.15 m), arms ``left``/``right``."""
    return _load("pr2")


def load_baxter() -> RobotModel:
    """Baxter's two arms (head and grippers fixed), arms ``left``/``right``."""
    return _load("baxter")


def load_example_robot(name: str) -> RobotModel:
    """``"pr2"``, ``"baxter"`` or ``"dual_panda"`` (two Pandas on a plate, :mod:`optplan.model.dual_panda`)."""
    if name.lower() == "dual_panda":
        from .dual_panda import load_dual_panda

        return load_dual_panda()
    return _load(name.lower())
