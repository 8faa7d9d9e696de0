"""Exact collision checking and distances with coal: robot self-collision, robot vs scene
obstacles, and the grasped object vs obstacles and robot links.

Geometry entities are named: robot geometry objects by their Pinocchio names (``a_link3_0``),
obstacles by their scene names, the held object ``"object"``.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from ..model.robot import RobotModel
from ..scene import Scene

__all__ = ["CollisionChecker", "Pair"]
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Pair:
    """A checked pair: ``kind`` in {"self", "robot-obstacle", "object-obstacle", "object-robot"};
    ``a``/``b`` are indices (robot geometry index, obstacle index, or -1 for the object)."""

    kind: str
    a: int
    b: int
    name_a: str
    name_b: str


def _tf(M: pin.SE3) -> coal.Transform3s:
    return coal.Transform3s(M.rotation, M.translation)


class CollisionChecker:
    """Exact distances [m] for a robot in a scene (optionally holding the scene's object).

    ``held_object``: include the grasped object (its pose follows ``object_arm``'s hand).
    ``self_collision``: include the robot's own collision pairs (``robot.collision_pairs``).
    """

    def __init__(self, robot: RobotModel, scene: Scene | None = None, *, held_object: bool = True,
                 self_collision: bool = True, object_arm: str | None = None):
        self.robot = robot
        self.scene = scene
        self.model = robot.model
        self.data = robot.model.createData()
        self.gmodel = robot.collision_model
        self.gdata = pin.GeometryData(self.gmodel)
        objs = self.gmodel.geometryObjects
        self.obstacles = list(scene.obstacles) if scene is not None else []
        self._obs_geom = [o.coal_geometry() for o in self.obstacles]
        self._obs_tf = [_tf(o.placement) for o in self.obstacles]
        self.object = scene.object if (scene is not None and held_object) else None
        if self.object is not None:
            self.object.check_robot(robot)
            self.object_arm = object_arm or next(iter(self.object.grasps))
            robot.arm(self.object_arm)
            self._obj_geom = self.object.coal_geometry()
            self._grasp_inv = self.object.grasps[self.object_arm].inverse()
            self._hand_fid = robot.arm(self.object_arm).ee_frame_id
        pairs: list[Pair] = []
        if self_collision:
            pairs += [Pair("self", a, b, objs[a].name, objs[b].name) for a, b in robot.collision_pairs]
        fixed_base_joint = 0
        for g in range(len(objs)):
            if not robot.is_floating and objs[g].parentJoint == fixed_base_joint:
                continue  # fixed base geometry vs static obstacles: the scene is built around it
            for i, o in enumerate(self.obstacles):
                pairs.append(Pair("robot-obstacle", g, i, objs[g].name, o.name))
        if self.object is not None:
            for i, o in enumerate(self.obstacles):
                pairs.append(Pair("object-obstacle", -1, i, "object", o.name))
            excl = set(self.object.exclude_links)
            for g in range(len(objs)):
                link = self.model.frames[objs[g].parentFrame].name
                if link in excl:
                    continue
                pairs.append(Pair("object-robot", -1, g, "object", objs[g].name))
        self.pairs = pairs
        #: position of each pair in :attr:`pairs` (and in :meth:`distances`' result)
        self.pair_index: dict[Pair, int] = {p: i for i, p in enumerate(pairs)}
        self._build_combined()
        self._req = coal.DistanceRequest()
        self._res = coal.DistanceResult()
        self._creq = coal.CollisionRequest()
        self._cres = coal.CollisionResult()

    def _build_combined(self) -> None:
        """One Pinocchio GeometryModel with the robot's geometries, the held object (attached to its
        hand's joint) and the obstacles (attached to the world), with exactly ``pairs`` as its
        collision pairs in the same order, so that ``pinocchio.computeDistances`` runs the whole
        list in C++ (the same coal narrow phase and default request as :meth:`_geoms`)."""
        gm = self.gmodel.copy()
        gm.removeAllCollisionPairs()
        obs_ids = [gm.addGeometryObject(pin.GeometryObject(f"obstacle/{o.name}", 0, 0, o.placement, g))
                   for o, g in zip(self.obstacles, self._obs_geom)]
        obj_id = None
        if self.object is not None:
            fr = self.model.frames[self._hand_fid]
            obj_id = gm.addGeometryObject(pin.GeometryObject("object/held", fr.parentJoint, self._hand_fid,
                                                             fr.placement * self._grasp_inv, self._obj_geom))
        for p in self.pairs:
            a = obj_id if p.a == -1 else p.a
            b = obs_ids[p.b] if p.kind in ("robot-obstacle", "object-obstacle") else p.b
            gm.addCollisionPair(pin.CollisionPair(min(a, b), max(a, b)))
        self._cgm = gm
        self._cgd = pin.GeometryData(gm)
        # references into the results vector (never resized after this): faster to read than
        # iterating ``distanceResults`` anew on every call
        self._dist_results = list(self._cgd.distanceResults)

    # ------------------------------------------------------------------ placements
    def _update(self, q) -> pin.SE3 | None:
        q = self.robot.check_q(q)
        pin.forwardKinematics(self.model, self.data, q)
        pin.updateGeometryPlacements(self.model, self.data, self.gmodel, self.gdata)
        if self.object is None:
            return None
        pin.updateFramePlacement(self.model, self.data, self._hand_fid)
        return self.data.oMf[self._hand_fid] * self._grasp_inv

    def update_placements(self, q) -> pin.SE3 | None:
        """Place every geometry at configuration ``q``; returns the held object's world pose (None
        without one). :meth:`pair_geometries` then gives a pair's shapes and placements."""
        return self._update(q)

    def pair_geometries(self, pair: Pair, obj_tf):
        """``(geometry A, transform A, geometry B, transform B)`` of a pair (coal objects) at the
        placements last set by :meth:`update_placements` (``obj_tf``: the held object's, a
        ``coal.Transform3s``)."""
        return self._geoms(pair, obj_tf)

    def object_pose(self, q) -> pin.SE3:
        """World pose of the held object at ``q`` (from ``object_arm``'s hand)."""
        if self.object is None:
            raise ValueError("this checker has no held object")
        return self._update(q)

    def _geoms(self, pair: Pair, obj_tf):
        objs = self.gmodel.geometryObjects
        if pair.kind == "self":
            return (objs[pair.a].geometry, _tf(self.gdata.oMg[pair.a]), objs[pair.b].geometry, _tf(self.gdata.oMg[pair.b]))
        if pair.kind == "robot-obstacle":
            return (objs[pair.a].geometry, _tf(self.gdata.oMg[pair.a]), self._obs_geom[pair.b], self._obs_tf[pair.b])
        if pair.kind == "object-obstacle":
            return (self._obj_geom, obj_tf, self._obs_geom[pair.b], self._obs_tf[pair.b])
        return (self._obj_geom, obj_tf, objs[pair.b].geometry, _tf(self.gdata.oMg[pair.b]))

    # ------------------------------------------------------------------ queries
    def distances(self, q) -> np.ndarray:
        """Exact signed distance [m] of every pair at configuration ``q`` (negative: penetration)."""
        q = self.robot.check_q(q)
        if not self.pairs:
            return np.empty(0)
        pin.computeDistances(self.model, self.data, self._cgm, self._cgd, q)
        return np.array([r.min_distance for r in self._dist_results])

    def min_distance(self, q) -> tuple[float, Pair | None]:
        """Smallest distance [m] and the pair that has it (inf, None without pairs)."""
        if not self.pairs:
            return float("inf"), None
        q = self.robot.check_q(q)
        i = int(pin.computeDistances(self.model, self.data, self._cgm, self._cgd, q))
        return float(self._cgd.distanceResults[i].min_distance), self.pairs[i]

    def is_valid(self, q, margin: float = 0.0) -> bool:
        """True when every pair is at least ``margin`` [m] apart (stops at the first failure;
        ``margin = 0`` uses coal's boolean collision test, the fastest)."""
        if margin <= 0.0:
            q = self.robot.check_q(q)
            return not pin.computeCollisions(self.model, self.data, self._cgm, self._cgd, q, True)
        Mo = self._update(q)
        obj_tf = _tf(Mo) if Mo is not None else None
        for p in self.pairs:
            g1, t1, g2, t2 = self._geoms(p, obj_tf)
            self._res.clear()
            if coal.distance(g1, t1, g2, t2, self._req, self._res) < margin:
                return False
        return True
