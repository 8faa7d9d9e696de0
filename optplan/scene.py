"""Scenes: obstacles, the grasped object with its grasp frames, and start/goal object poses,
from ``models/scenes/<name>.toml``.

Schema (lengths [m], angles in ``angle_unit``; ``rpy`` = roll, pitch, yaw with
``R = Rz(yaw) Ry(pitch) Rx(roll)``)::

    name = "transport"
    robot = "tcbirrt_dual_arm"
    angle_unit = "deg"

    [object]                       # optional: a box held by the arms
    size = [2.0, 0.8, 0.8]         # full edge lengths
    grasps = { A = { xyz = [1, 0, 0], rpy = [0, 90, 0] }, B = { xyz = [-1, 0, 0], rpy = [0, -90, 0] } }
    exclude_links = ["a_link6", "a_link7", "b_link6", "b_link7"]   # robot links allowed to touch it

    [start]                        # object pose(s)
    xyz = [0, 0, 3.0]
    rpy = [0, 0, 90]
    [goal]
    xyz = [1.5, 0, 2.5]
    rpy = [0, 0, 90]

    [[obstacles]]
    name = "truss_1"
    shape = "box"                  # "box" (size), "sphere" (radius), "capsule" (radius, length along local z)
    size = [0.2, 0.2, 4.0]
    xyz = [2.0, 0.0, 2.0]
    rpy = [0, 0, 0]
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from . import limits
from .errors import ModelError, UnknownNameError
from .geometry.spatial import rpy_to_matrix
from .model.description import models_dir, read_model_toml

__all__ = ["Obstacle", "GraspedObject", "Scene", "available_scenes", "held_object", "scene_name"]


def available_scenes() -> list[str]:
    return sorted(p.stem for p in (models_dir() / "scenes").glob("*.toml"))


def scene_name(s: str) -> str:
    """``"1"`` → ``"ssps_scene1"`` (the space-solar-power-station scenes by number); other names unchanged."""
    s = str(s).strip()
    return f"ssps_scene{s}" if s.isdigit() else s


@dataclass(frozen=True)
class Obstacle:
    """A static convex obstacle. ``size``: full box edges [m]; ``radius`` [m]; ``length``: capsule
    segment length along local z [m]."""

    name: str
    shape: str
    placement: pin.SE3
    size: tuple[float, float, float] | None = None
    radius: float | None = None
    length: float | None = None
    #: robot links allowed to touch it (not checked against it), e.g. the hands at their grasps when a
    #: released object stands still as an obstacle during a both-arm regrasp
    exclude_links: tuple[str, ...] = ()

    def coal_geometry(self) -> coal.CollisionGeometry:
        if self.shape == "box":
            if self.size is None:
                raise ModelError(f"box obstacle {self.name!r} has no size")
            return coal.Box(*self.size)
        if self.shape == "sphere":
            return coal.Sphere(self.radius)
        return coal.Capsule(self.radius, self.length)

    def primitive(self):
        """The shape for :mod:`optplan.geometry.distance` (local frame)."""
        from .geometry import distance as D

        if self.shape == "box":
            return D.Box(np.asarray(self.size) / 2)
        if self.shape == "sphere":
            return D.Sphere(self.radius)
        return D.Capsule.along_z(self.radius, self.length)


@dataclass(frozen=True)
class GraspedObject:
    """A box held by the arms: ``size`` full edges [m]; ``grasps`` maps arm name → grasp frame in the
    object frame (where that arm's end-effector frame sits)."""

    size: tuple[float, float, float]
    grasps: dict[str, pin.SE3]
    exclude_links: tuple[str, ...] = ()

    def coal_geometry(self) -> coal.Box:
        return coal.Box(*self.size)

    def check_robot(self, robot) -> None:
        """Every grasp names an arm of ``robot`` and every ``exclude_links`` entry is one of its
        links (a typo would silently keep the hands in collision with the object)."""
        for arm in self.grasps:
            robot.arm(arm)   # UnknownNameError listing the arms
        links = {f.name for f in robot.model.frames if f.type == pin.FrameType.BODY}
        for name in self.exclude_links:
            if name not in links:
                raise UnknownNameError("link in the scene's object.exclude_links", name, links)

    def hand_pose(self, arm: str, object_pose: pin.SE3) -> pin.SE3:
        return object_pose * self.grasps[arm]

    def object_pose_from_hand(self, arm: str, hand_pose: pin.SE3) -> pin.SE3:
        return hand_pose * self.grasps[arm].inverse()


@dataclass(frozen=True)
class Scene:
    name: str
    robot: str | None
    obstacles: tuple[Obstacle, ...]
    object: GraspedObject | None = None
    start: pin.SE3 | None = None
    goal: pin.SE3 | None = None
    extra: dict = field(default_factory=dict)

    @classmethod
    def load(cls, name_or_path: str | Path) -> Scene:
        """Load ``models/scenes/<name>.toml`` or a TOML path."""
        data, p = read_model_toml(name_or_path, "scenes", "scene", available_scenes)
        robot = data.get("robot")
        if isinstance(robot, str):   # a robot file or URDF path: relative to the scene file
            from .model.robot_file import is_robot_path

            if is_robot_path(robot) and not Path(robot).expanduser().is_absolute():
                data = {**data, "robot": str((p.parent / robot).resolve())}
        return cls.from_dict(data, where=p.name)

    @classmethod
    def from_dict(cls, data: dict, where: str = "scene") -> Scene:
        from .model.description import _known_keys

        _known_keys(data, ("name", "robot", "angle_unit", "object", "start", "goal", "obstacles", "extra", "notes"),
                    where)
        unit = data.get("angle_unit", "rad")
        ang = {"deg": math.pi / 180, "rad": 1.0}.get(unit) if isinstance(unit, str) else None
        if ang is None:
            raise ModelError(f"{where}.angle_unit: expected 'deg' or 'rad', got {data.get('angle_unit')!r}")

        def pose(d: dict, w: str) -> pin.SE3:
            _known_keys(d, ("xyz", "rpy"), w)
            xyz = _vec(d.get("xyz", [0, 0, 0]), 3, f"{w}.xyz", limits.MAX_COORDINATE_M)
            rpy = _vec(d.get("rpy", [0, 0, 0]), 3, f"{w}.rpy") * ang
            return pin.SE3(rpy_to_matrix(*rpy), xyz)

        robot = data.get("robot")
        if robot is not None:
            if not isinstance(robot, str):
                raise ModelError(f"{where}.robot: expected a robot model name, got {robot!r}")
            from .model.example_robots import known_robot_names
            from .model.robot_file import is_robot_path

            known = known_robot_names()  # shipped, example-robot-data's, robot files in models/robots/files
            if not is_robot_path(robot) and robot not in known:
                raise UnknownNameError("robot model (scene's robot; or a robot file / URDF path)", robot, known)
        obstacles = []
        names = set()
        obs_list = data.get("obstacles", [])
        if not isinstance(obs_list, list):
            raise ModelError(f"{where}: obstacles: expected a list of [[obstacles]] tables, got {obs_list!r}")
        if len(obs_list) > limits.MAX_OBSTACLES:
            raise ModelError(f"{where}: {len(obs_list)} obstacles; the limit is {limits.MAX_OBSTACLES} "
                             "(optplan.limits.MAX_OBSTACLES)")
        for k, o in enumerate(obs_list):
            w = f"{where}: obstacles[{k}]"
            _known_keys(o, ("name", "shape", "size", "radius", "length", "xyz", "rpy"), w)
            name = str(o.get("name", f"obstacle_{k}"))
            if name in names:
                raise ModelError(f"{w}: duplicate obstacle name {name!r}")
            names.add(name)
            shape = o.get("shape")
            if shape == "box":
                size = _vec(o.get("size"), 3, f"{w}.size", limits.MAX_SIZE_M)
                if np.any(size <= 0):
                    raise ModelError(f"{w}.size: edges must be > 0 m, got {size.tolist()}")
                obstacles.append(Obstacle(name, "box", pose({kk: o[kk] for kk in ("xyz", "rpy") if kk in o}, w), size=tuple(size)))
            elif shape in ("sphere", "capsule"):
                r = o.get("radius")
                if isinstance(r, bool) or not isinstance(r, (int, float)) or not math.isfinite(r) or r <= 0 \
                        or r > limits.MAX_SIZE_M:
                    raise ModelError(f"{w}.radius: expected a number > 0 m and ≤ {limits.MAX_SIZE_M:g} m, got {r!r}")
                L = None
                if shape == "capsule":
                    L = o.get("length")
                    if isinstance(L, bool) or not isinstance(L, (int, float)) or not math.isfinite(L) or L < 0 \
                            or L > limits.MAX_SIZE_M:
                        raise ModelError(f"{w}.length: expected a number ≥ 0 m and ≤ {limits.MAX_SIZE_M:g} m, "
                                         f"got {L!r}")
                    L = float(L)
                obstacles.append(Obstacle(name, shape, pose({kk: o[kk] for kk in ("xyz", "rpy") if kk in o}, w), radius=float(r), length=L))
            else:
                raise ModelError(f"{w}.shape: expected 'box', 'sphere' or 'capsule', got {shape!r}")
        obj = None
        if "object" in data:
            o = data["object"]
            _known_keys(o, ("size", "grasps", "exclude_links"), f"{where}: object")
            size = _vec(o.get("size"), 3, f"{where}: object.size", limits.MAX_SIZE_M)
            if np.any(size <= 0):
                raise ModelError(f"{where}: object.size: edges must be > 0 m, got {size.tolist()}")
            gr = o.get("grasps", {})
            if not isinstance(gr, dict):
                raise ModelError(f"{where}: object.grasps: expected a table {{ A = {{ xyz, rpy }}, ... }}, got {gr!r}")
            grasps = {arm: pose(g, f"{where}: object.grasps.{arm}") for arm, g in gr.items()}
            excl = o.get("exclude_links", [])
            if not isinstance(excl, list) or not all(isinstance(e, str) for e in excl):
                raise ModelError(f"{where}: object.exclude_links: expected a list of link names, got {excl!r}")
            obj = GraspedObject(tuple(size), grasps, tuple(excl))
            if isinstance(robot, str):
                _check_exclude_links(robot, excl, f"{where}: object.exclude_links")
        for key in ("start", "goal", "extra"):
            if key in data and not isinstance(data[key], dict):
                raise ModelError(f"{where}: {key}: expected a table, got {data[key]!r}")
        start = pose(data["start"], f"{where}: start") if "start" in data else None
        goal = pose(data["goal"], f"{where}: goal") if "goal" in data else None
        return cls(str(data.get("name", where)), data.get("robot"), tuple(obstacles), obj, start, goal,
                   dict(data.get("extra", {})))

    def check_robot(self, robot) -> None:
        """Does the scene fit ``robot``? Its grasps name arms of the robot, its ``exclude_links``
        are the robot's links and its ``[extra] q_start`` / ``q_goal`` have the robot's joint
        count; else a :class:`ModelError` naming what does not fit."""
        try:
            if self.object is not None:
                self.object.check_robot(robot)
            for key in ("q_start", "q_goal"):
                q = self.extra.get(key)
                if q is not None and len(q) != robot.nj:   # a floating robot's witness: its joints, not the base
                    raise ModelError(f"extra.{key} has {len(q)} joint values, the robot has {robot.nj} "
                                     f"({', '.join(robot.joint_names)})")
        except (ModelError, UnknownNameError) as exc:
            raise ModelError(f"scene {self.name!r} does not fit robot {robot.name!r}: {exc}") from None

    def obstacle(self, name: str) -> Obstacle:
        for o in self.obstacles:
            if o.name == name:
                return o
        raise UnknownNameError("obstacle", name, [o.name for o in self.obstacles])


def held_object(scene: Scene) -> GraspedObject:
    """The scene's held object; a ValueError naming the scene when it has none."""
    if scene.object is None:
        raise ValueError(f"scene {scene.name!r} has no [object] with grasps")
    return scene.object


def _vec(v, n: int, where: str, bound: float | None = None) -> np.ndarray:
    """``n`` finite numbers; with ``bound`` [m], each within ±bound (a physical range)."""
    from .errors import real_array

    a = real_array(v, f"{where}: expected {n} numbers", ModelError)
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise ModelError(f"{where}: expected {n} finite numbers, got {v!r}")
    if bound is not None and np.any(np.abs(a) > bound):
        raise ModelError(f"{where}: expected {n} numbers within ±{bound:g} m, got {a.tolist()} "
                         "(optplan.limits: MAX_COORDINATE_M for positions, MAX_SIZE_M for sizes)")
    return a


def _link_names_of_shipped_robot(robot: str) -> set[str] | None:
    """The link names of a shipped robot model (from its generated URDF), None for other robots."""
    import re

    from .model.description import available_models, urdf_dir

    if robot not in available_models():
        return None
    path = urdf_dir() / f"{robot}.urdf"
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None   # RobotModel.from_name reports a missing URDF with the command that builds it
    return set(re.findall(r'<link\s+name="([^"]+)"', text))


def _check_exclude_links(robot: str, names: list[str], where: str) -> None:
    """Every name in an ``exclude_links`` list is a link of the scene's robot (shipped models; the
    other robots are checked when a collision checker is built): a typo would silently keep the
    hands in collision with the object."""
    links = _link_names_of_shipped_robot(robot)
    if links is None:
        return
    for name in names:
        if name not in links:
            raise UnknownNameError(f"link of {robot!r} in {where}", name, links)
