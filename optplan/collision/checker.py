"""Exact collision checking and distances with coal: robot self-collision, robot vs scene
obstacles, and the grasped object vs obstacles and robot links.

Geometry entities are named: robot geometry objects by their Pinocchio names (``a_link3_0``),
obstacles by their scene names, the held object ``"object"``.

The checked pair set and the geometry model that holds robot, obstacles and held object are
defined once here (:func:`scene_geometry`, :func:`scene_pairs`) and shared by
:class:`CollisionChecker` (distances) and the planners'
:class:`~optplan.planners.validity.ValidityChecker` (boolean checks in C++).
"""
from __future__ import annotations

import logging
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from ..errors import ModelError
from ..model.robot import RobotModel
from ..scene import Scene

__all__ = ["CollisionChecker", "Pair", "SceneGeometry", "exact_contact_requests", "scene_geometry", "scene_pairs"]
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


def exact_contact_requests(gdata: Any) -> None:
    """Make every collision request of a Pinocchio ``GeometryData`` decide by the sign of coal's
    exact distance (``enable_contact = True``, which Pinocchio's default requests switch off).

    Without it, a pair that coal's GJK handles through a shape's inner core plus a swept-sphere
    radius (a capsule is a segment of radius r: capsule-box, capsule-cylinder, capsule-mesh) is
    reported FREE when that inner core touches the other shape to within GJK's tolerance (1e-6 m)
    from outside: GJK then stops with "collision, run EPA for the depth" at an inner distance
    above coal's collision threshold (1e-12 m), and without contacts EPA is skipped, so the
    penetration of the radius (up to r) is never seen. With contacts requested, EPA runs in that
    case and its depth decides; it runs only on pairs GJK finds in contact, so collision-free
    checks cost the same."""
    for req in gdata.collisionRequests:
        req.enable_contact = True


def _tf(M: pin.SE3) -> coal.Transform3s:
    return coal.Transform3s(M.rotation, M.translation)


@dataclass(frozen=True)
class SceneGeometry:
    """One Pinocchio ``GeometryModel`` with the robot's geometries (indices ``0 .. n_robot − 1``),
    then the scene's obstacles (``"obstacle/<name>"``, fixed in the world; ``obstacle_ids`` in the
    scene's order), then the held object (``"object/held"``, rigidly on ``object_arm``'s hand;
    ``held_id``, None without one). No collision pairs: see :func:`scene_pairs`."""

    model: pin.GeometryModel
    n_robot: int
    obstacle_ids: tuple
    held_id: int | None
    object_arm: str | None


def scene_geometry(robot: RobotModel, scene: Scene | None, object_arm: str | None = None, *,
                   held_object: bool = True) -> SceneGeometry:
    """The :class:`SceneGeometry` of ``robot`` in ``scene`` (``held_object``: include the scene's
    object, held by ``object_arm``, default its first grasping arm)."""
    gm = robot.collision_model.copy()
    gm.removeAllCollisionPairs()
    n_robot = len(gm.geometryObjects)
    obstacles = list(scene.obstacles) if scene is not None else []
    obs_ids = tuple(gm.addGeometryObject(pin.GeometryObject(f"obstacle/{o.name}", 0, 0, o.placement, o.coal_geometry()))
                    for o in obstacles)
    obj = scene.object if (scene is not None and held_object) else None
    held_id, arm_name = None, None
    if obj is not None:
        arm_name = object_arm or next(iter(obj.grasps))
        arm = robot.arm(arm_name)
        fr = robot.model.frames[arm.ee_frame_id]
        held_id = gm.addGeometryObject(pin.GeometryObject("object/held", fr.parentJoint, arm.ee_frame_id,
                                                          fr.placement * obj.grasps[arm_name].inverse(),
                                                          obj.coal_geometry()))
    return SceneGeometry(gm, n_robot, obs_ids, held_id, arm_name)


def scene_pairs(robot: RobotModel, scene: Scene | None, *, held_object: bool = True,
                self_collision: bool = True) -> list[Pair]:
    """THE checked pair set, in this order: the robot's own collision pairs
    (``robot.collision_pairs``); every robot geometry × every obstacle (a fixed base's own
    geometry excepted: the scene is built around it); the held object × every obstacle; the held
    object × every robot geometry whose link is not in the object's ``exclude_links`` (the hands
    on the fixtures)."""
    objs = robot.collision_model.geometryObjects
    obstacles = list(scene.obstacles) if scene is not None else []
    obj = scene.object if (scene is not None and held_object) else None
    pairs: list[Pair] = []
    if self_collision:
        pairs += [Pair("self", a, b, objs[a].name, objs[b].name) for a, b in robot.collision_pairs]
    for g in range(len(objs)):
        if not robot.is_floating and objs[g].parentJoint == 0:
            continue  # fixed base geometry vs static obstacles: the scene is built around it
        for i, o in enumerate(obstacles):
            if o.exclude_links and robot.model.frames[objs[g].parentFrame].name in o.exclude_links:
                continue  # a link allowed to touch this obstacle (Obstacle.exclude_links)
            pairs.append(Pair("robot-obstacle", g, i, objs[g].name, o.name))
    if obj is not None:
        for i, o in enumerate(obstacles):
            pairs.append(Pair("object-obstacle", -1, i, "object", o.name))
        excl = set(obj.exclude_links)
        for g in range(len(objs)):
            if robot.model.frames[objs[g].parentFrame].name not in excl:
                pairs.append(Pair("object-robot", -1, g, "object", objs[g].name))
    return pairs


def pair_budget_counts(robot: RobotModel, scene: Scene | None) -> dict[str, int]:
    """The checked pairs by kind (:func:`scene_pairs`) and ``object_robot_rigid``: held object ×
    robot geometry on the same rigid body as a grasping hand. Those never move relative to the
    object while both hands hold it, so the trajectory NLP gives them no rows then (the
    verification checks them all)."""
    pairs = scene_pairs(robot, scene)
    out = {"self": 0, "robot_obstacle": 0, "object_obstacle": 0, "object_robot": 0, "object_robot_rigid": 0}
    hands = set()
    if scene is not None and scene.object is not None:
        hands = {int(robot.model.frames[robot.arm(a).ee_frame_id].parentJoint) for a in scene.object.grasps}
    objs = robot.collision_model.geometryObjects
    for p in pairs:
        out[p.kind.replace("-", "_")] += 1
        if p.kind == "object-robot" and int(objs[p.b].parentJoint) in hands:
            out["object_robot_rigid"] += 1
    return out


def pair_indices(pair: Pair, geometry: SceneGeometry) -> tuple[int, int]:
    """The two geometry indices of ``pair`` in ``geometry.model``."""
    if pair.a == -1:
        if geometry.held_id is None:
            raise ModelError(f"pair {pair.name_a} / {pair.name_b} involves the held object, "
                             "but the scene geometry was built without one")
        a = geometry.held_id
    else:
        a = pair.a
    b = geometry.obstacle_ids[pair.b] if pair.kind in ("robot-obstacle", "object-obstacle") else pair.b
    return a, b


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
        self.obstacles = list(scene.obstacles) if scene is not None else []
        self._obs_geom = [o.coal_geometry() for o in self.obstacles]
        self._obs_tf = [_tf(o.placement) for o in self.obstacles]
        self.object = scene.object if (scene is not None and held_object) else None
        #: the arm whose hand carries the object (None without one)
        self.object_arm: str | None = None
        if self.object is not None:
            self.object.check_robot(robot)
            self.object_arm = object_arm or next(iter(self.object.grasps))
            robot.arm(self.object_arm)
            self._obj_geom = self.object.coal_geometry()
            self._grasp_inv = self.object.grasps[self.object_arm].inverse()
            self._hand_fid = robot.arm(self.object_arm).ee_frame_id
        self.pairs = scene_pairs(robot, scene, held_object=held_object, self_collision=self_collision)
        #: position of each pair in :attr:`pairs` (and in :meth:`distances`' result)
        self.pair_index: dict[Pair, int] = {p: i for i, p in enumerate(self.pairs)}
        self._build_combined()
        self._req = coal.DistanceRequest()
        self._res = coal.DistanceResult()
        self._creq = coal.CollisionRequest()
        self._cres = coal.CollisionResult()
        self._sweep: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None   # see min_distance_along
        self._on_robot: np.ndarray | None = None   # per combined geometry: attached to the robot (not the world)

    #: checkers of :meth:`shared`, most recently used last (key: robot, scene, options)
    _SHARED: OrderedDict[tuple[Any, ...], tuple[Any, Any, CollisionChecker]] = OrderedDict()
    _SHARED_MAX = 16

    @classmethod
    def shared(cls, robot: RobotModel, scene: Scene | None = None, *, held_object: bool = True,
               self_collision: bool = True, object_arm: str | None = None) -> CollisionChecker:
        """A checker for these arguments reused within the process (building one takes a few
        milliseconds: the verification of every solve and every segment NLP ask for one). The
        robot and scene are identified by object: a checker is never shared between two robot or
        scene objects, and holds on to the ones it was built for."""
        key = (id(robot), id(scene), bool(held_object), bool(self_collision), object_arm)
        got = cls._SHARED.get(key)
        if got is not None and got[0] is robot and got[1] is scene:
            cls._SHARED.move_to_end(key)
            return got[2]
        chk = cls(robot, scene, held_object=held_object, self_collision=self_collision, object_arm=object_arm)
        cls._SHARED[key] = (robot, scene, chk)
        while len(cls._SHARED) > cls._SHARED_MAX:
            cls._SHARED.popitem(last=False)
        return chk

    def _build_combined(self) -> None:
        """One Pinocchio GeometryModel with the robot's geometries, the held object (attached to its
        hand's joint) and the obstacles (attached to the world), with exactly ``pairs`` as its
        collision pairs in the same order, so that ``pinocchio.computeDistances`` runs the whole
        list in C++ (the same coal narrow phase and default request as :meth:`_geoms`)."""
        geo = scene_geometry(self.robot, self.scene, self.object_arm if self.object is not None else None,
                             held_object=self.object is not None)
        gm = geo.model
        flip = []
        for p in self.pairs:
            a, b = pair_indices(p, geo)
            gm.addCollisionPair(pin.CollisionPair(min(a, b), max(a, b)))
            flip.append(a > b)
        self._flip = np.array(flip, bool)  # the combined model's pair runs B -> A
        self._cgm = gm
        self._cgd = pin.GeometryData(gm)
        exact_contact_requests(self._cgd)   # is_valid's boolean test agrees with the distances' sign
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

    def witness_planes(self, q, pair_indices) -> np.ndarray:
        """Separating planes of the pairs ``pair_indices`` (indices into ``pairs``) at configuration
        ``q``: one row ``(n, n·m)`` per pair — coal's unit witness normal from A to B and the
        offset of the witness points' midpoint ``m`` (the same query as :func:`coal.distance` on
        :meth:`pair_geometries`; the placements are set once, each pair is one C++ call). A
        normal coal leaves unset (a triangle mesh) is the direction between the witness points of
        a separated pair, else (coincident witness points) the direction between the two
        geometries' origins."""
        q = self.robot.check_q(q)
        idx = np.asarray(pair_indices, int).ravel()
        out = np.zeros((idx.size, 4))
        if not idx.size:
            return out
        gm, gd = self._cgm, self._cgd
        pin.updateGeometryPlacements(self.model, self.data, gm, gd, q)
        for row, p in enumerate(idx.tolist()):
            res = pin.computeDistance(gm, gd, p)
            cp = gm.collisionPairs[p]
            n = np.asarray(res.normal, float)
            p1, p2 = np.asarray(res.getNearestPoint1(), float), np.asarray(res.getNearestPoint2(), float)
            unset = not np.all(np.isfinite(n)) or abs(float(np.linalg.norm(n)) - 1.0) > 1e-3
            if unset and res.min_distance > 0 and np.linalg.norm(p2 - p1) > 1e-12:
                n = p2 - p1   # coal leaves the normal unset for triangle meshes (BVH): the nearest points give it
            elif not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-9:
                n = gd.oMg[cp.second].translation - gd.oMg[cp.first].translation
            n = n / max(float(np.linalg.norm(n)), 1e-12)
            if self._flip[p]:
                n = -n
            mid = 0.5 * (p1 + p2)
            out[row, :3] = n
            out[row, 3] = n @ mid
        return out

    def min_distance(self, q) -> tuple[float, Pair | None]:
        """Smallest distance [m] and the pair that has it (inf, None without pairs)."""
        if not self.pairs:
            return float("inf"), None
        q = self.robot.check_q(q)
        i = int(pin.computeDistances(self.model, self.data, self._cgm, self._cgd, q))
        return float(self._cgd.distanceResults[i].min_distance), self.pairs[i]

    def _anchor_bounds(self, Q: np.ndarray, every: int) -> tuple[list[int], np.ndarray, np.ndarray]:
        """Anchor rows of ``Q`` (every ``every``-th and the last), all pair distances there
        (anchors × pairs), and a lower bound on every pair's distance at every row (pairs × rows;
        ``inf`` at the anchors): the distance at the anchor on either side minus how far the
        pair's two geometries can have moved since (the larger of the two)."""
        if self._sweep is None:
            from .sweep import sweep_weights

            W = sweep_weights(self.model, self._cgm)
            pa = np.array([cp.first for cp in self._cgm.collisionPairs], dtype=int)
            pb = np.array([cp.second for cp in self._cgm.collisionPairs], dtype=int)
            self._sweep = (W, pa, pb)
        W, pa, pb = self._sweep
        M = len(Q)
        anchors = list(range(0, M, every))
        if anchors[-1] != M - 1:
            anchors.append(M - 1)
        D = np.array([self.distances(Q[i]) for i in anchors])      # anchors × pairs
        lower = np.full((len(self.pairs), M), np.inf)
        for r in range(len(anchors) - 1):
            i0, i1 = anchors[r], anchors[r + 1]
            if i1 - i0 < 2:
                continue
            seg = Q[i0 + 1:i1]
            m0 = W @ np.abs(seg - Q[i0]).T                             # geometries × rows
            m1 = W @ np.abs(seg - Q[i1]).T
            lower[:, i0 + 1:i1] = np.maximum(D[r][:, None] - m0[pa] - m0[pb], D[r + 1][:, None] - m1[pa] - m1[pb])
        return anchors, D, lower

    def _check_rows(self, Q: Any, anchor_every: Any) -> np.ndarray:
        Q = np.asarray(Q, float)
        if Q.ndim != 2 or Q.shape[1] != self.robot.nq:
            raise ValueError(f"Q: expected an (M, {self.robot.nq}) array of configurations, got shape {Q.shape}")
        if isinstance(anchor_every, bool) or not isinstance(anchor_every, (int, np.integer)) or anchor_every < 1:
            raise ValueError(f"anchor_every: expected an int >= 1, got {anchor_every!r}")
        return Q

    def distances_below(self, Q, threshold: float, anchor_every: int = 10
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every (row of ``Q``, pair) whose exact distance is below ``threshold`` [m], as arrays
        ``(rows, pair indices, distances [m])`` — the same entries as ``distances`` at every row
        filtered by the threshold, with the anchor bounds of :meth:`min_distance_along` sparing
        the pairs that cannot be that close."""
        r_, p_, d_, _ = self.distance_bounds_below(Q, threshold, anchor_every)
        return r_, p_, d_

    def distance_bounds_below(self, Q, threshold: float, anchor_every: int = 10, previous: Any = None
                              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Any]:
        """:meth:`distances_below` and, as a fourth value, what a later call on configurations
        near ``Q`` can start from (``previous``; None for a robot without the sweep bound): a
        lower bound on every pair's distance at every row (pairs × rows [m]; exact where computed).
        Given ``previous`` of an earlier call with as many rows, a pair's distance at row i is
        bounded by its bound there minus how far its two geometries can have moved from that
        call's row i to ``Q[i]`` (the sweep bound of :meth:`min_distance_along`), and only the
        pairs whose bound is below ``threshold`` are computed — the same entries, fewer coal calls
        when ``Q`` moved little (a re-solve). A free-flyer root (base position and quaternion,
        then 1-dof joints) is bounded the same way with the base's motion added
        (:func:`~optplan.collision.motion_bounds.floating_distance_bounds_below`); other non-1-dof
        joints: every pair at every row."""
        Q = self._check_rows(Q, anchor_every)
        if not self.pairs or not len(Q):
            return np.zeros(0, int), np.zeros(0, int), np.zeros(0), None
        thr = float(threshold)
        if self.model.nq != self.model.nv and self._floating_base():
            from .motion_bounds import floating_distance_bounds_below

            return floating_distance_bounds_below(self, Q, thr, int(anchor_every), previous)
        if self.model.nq != self.model.nv:        # no bound: every row
            D = np.array([self.distances(q) for q in Q])
            r_, p_ = np.nonzero(D < thr)
            return r_, p_, D[r_, p_], None
        rows: list[np.ndarray] = []
        pairs: list[np.ndarray] = []
        dist: list[np.ndarray] = []
        anchors: list[int] = []
        if previous is not None and previous[0].shape == Q.shape and self._sweep is not None:
            Q0, L0 = previous
            W, pa, pb = self._sweep
            m = W @ np.abs(Q - Q0).T                                  # geometries × rows
            lower = L0 - m[pa] - m[pb]
        else:
            anchors, D, lower = self._anchor_bounds(Q, int(anchor_every))   # inf at the anchors
            ra, pa_ = np.nonzero(D < thr)
            rows, pairs, dist = [np.asarray(anchors)[ra]], [pa_], [D[ra, pa_]]
        gm, gd = self._cgm, self._cgd
        for i in np.nonzero((lower < thr).any(axis=0))[0].tolist():
            pin.updateGeometryPlacements(self.model, self.data, gm, gd, Q[i])
            for p in np.nonzero(lower[:, i] < thr)[0].tolist():
                d = pin.computeDistance(gm, gd, p).min_distance
                lower[p, i] = d
                if d < thr:
                    rows.append(np.array([i]))
                    pairs.append(np.array([p]))
                    dist.append(np.array([d]))
        if anchors:
            lower[:, anchors] = D.T   # exact at the anchors
        r_ = np.concatenate(rows).astype(int) if rows else np.zeros(0, int)
        p_ = np.concatenate(pairs).astype(int) if pairs else np.zeros(0, int)
        d_ = np.concatenate(dist) if dist else np.zeros(0)
        order = np.lexsort((p_, r_))
        return r_[order], p_[order], d_[order], (Q.copy(), lower)

    def min_distance_along(self, Q, anchor_every: int = 10) -> tuple[float, Pair | None, int]:
        """Exactly the smallest :meth:`min_distance` over the configurations ``Q`` (M × nq) and
        its pair, without computing every pair at every row: every ``anchor_every``-th row (and
        the last) gets all pair distances; in between, a pair's distance is bounded from below by
        its distance at the anchors on either side minus how far its two geometries can have moved
        since (:func:`optplan.collision.sweep.sweep_weights`), and only the pairs whose bound is
        below the smallest distance found so far are computed, rows with the lowest bound first
        (a free-flyer root: :meth:`_min_distance_floating`).
        Returns ``(distance [m], pair, pair distances computed)`` (``inf, None, 0`` without pairs or
        rows)."""
        Q = self._check_rows(Q, anchor_every)
        if not self.pairs or not len(Q):
            return float("inf"), None, 0
        n_pairs = len(self.pairs)
        if self.model.nq != self.model.nv and self._floating_base():
            return self._min_distance_floating(Q, int(anchor_every))
        if self.model.nq != self.model.nv:        # other non-1-dof joints: no bound, every row
            best_d, best_p = float("inf"), None
            for q in Q:
                d, p = self.min_distance(q)
                if d < best_d:
                    best_d, best_p = d, p
            return best_d, best_p, len(Q) * n_pairs
        anchors, D, lower = self._anchor_bounds(Q, int(anchor_every))
        amin = D.min(axis=1)
        r = int(amin.argmin())
        dmin, ibest = float(amin[r]), int(D[r].argmin())
        row_lower = lower.min(axis=0)
        rows = np.nonzero(row_lower < dmin)[0]
        n = len(anchors) * n_pairs
        gm, gd = self._cgm, self._cgd
        for i in rows[np.argsort(row_lower[rows], kind="stable")]:
            if row_lower[i] >= dmin:
                break
            pin.updateGeometryPlacements(self.model, self.data, gm, gd, Q[i])
            for k in np.nonzero(lower[:, i] < dmin)[0].tolist():
                d = pin.computeDistance(gm, gd, k).min_distance
                n += 1
                if d < dmin:
                    dmin, ibest = float(d), k
        return dmin, self.pairs[ibest], n

    def _floating_base(self) -> bool:
        """The model is a free-flyer root (``q[:7]`` = position, quaternion x y z w) with 1-dof
        joints after it: the non-1-dof layout :meth:`min_distance_along` bounds."""
        m = self.model
        if m.njoints < 2 or m.joints[1].shortname() != "JointModelFreeFlyer" or m.nq != m.nv + 1:
            return False
        return all(m.joints[j].nq == 1 and m.joints[j].nv == 1 for j in range(2, m.njoints))

    def _segment_motion(self, Q: np.ndarray, A: np.ndarray, inner: np.ndarray, seg: np.ndarray,
                        ref: np.ndarray, pairs: np.ndarray | None = None) -> np.ndarray:
        """(pairs × segments) How much each pair's distance can have changed between the anchor row
        ``ref[s]`` of segment ``s`` and ANY of its inner rows [m] (the rows ``inner`` of ``Q``, grouped
        by segment: ``seg`` their first positions): :func:`~optplan.collision.motion_bounds.pair_motion`
        (the joints' sweep plus, for a pair with ONE side on the robot, the base's translation and
        rotation). ``pairs``: only these pairs (indices), in this order (default all)."""
        from .motion_bounds import pair_motion

        W, pa, pb = self._sweep_data()
        if pairs is not None:
            pa, pb = pa[pairs], pb[pairs]
        return pair_motion(W, pa, pb, self._on_robot_mask(), Q[ref], Q[inner], seg)

    def _on_robot_mask(self) -> np.ndarray:
        """Per combined geometry: attached to the robot (not the world), built once."""
        if self._on_robot is None:
            self._on_robot = np.array([go.parentJoint != 0 for go in self._cgm.geometryObjects])
        return self._on_robot

    def _sweep_data(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(W, pa, pb)``: the sweep weights (:func:`optplan.collision.sweep.sweep_weights`) and the
        combined model's two geometries of every pair, built once."""
        if self._sweep is None:
            from .sweep import sweep_weights

            W = sweep_weights(self.model, self._cgm)
            pa = np.array([cp.first for cp in self._cgm.collisionPairs], dtype=int)
            pb = np.array([cp.second for cp in self._cgm.collisionPairs], dtype=int)
            self._sweep = (W, pa, pb)
        return self._sweep

    def _min_distance_floating(self, Q: np.ndarray, every: int) -> tuple[float, Pair | None, int]:
        """:meth:`min_distance_along` for a free-flyer root: all pair distances at every
        ``every``-th row (and the last); between two such anchors a pair is bounded from below on
        the whole segment by the larger of its anchor distances minus how far its geometries can
        have moved from that anchor (:meth:`_segment_motion`); the pairs whose bound is below the
        smallest distance found in some segment are then bounded at each row on its own (its own
        motion from either anchor: tighter than the segment's largest), and only the (row, pair)
        entries whose bound is below the smallest distance found so far are computed, the rows
        with the lowest bounds first. Exactly the smallest distance: every entry left out is
        bounded above it."""
        M, n_pairs = len(Q), len(self.pairs)
        anchors = list(range(0, M, every))
        if anchors[-1] != M - 1:
            anchors.append(M - 1)
        A = np.asarray(anchors)
        D = np.array([self.distances(Q[i]) for i in anchors])      # anchors × pairs
        amin = D.min(axis=1)
        r = int(amin.argmin())
        dmin, ibest = float(amin[r]), int(D[r].argmin())
        n = len(anchors) * n_pairs
        inner = np.setdiff1d(np.arange(M), A, assume_unique=True)
        if not len(inner):
            return dmin, self.pairs[ibest], n
        left = np.searchsorted(A, inner, side="right") - 1            # each inner row's segment (its left anchor)
        segs, seg = np.unique(left, return_index=True)
        lower = np.maximum(D[segs].T - self._segment_motion(Q, A, inner, seg, A[left]),
                           D[segs + 1].T - self._segment_motion(Q, A, inner, seg, A[left + 1]))   # pairs × segments
        live = np.nonzero(lower.min(axis=1) < dmin)[0]      # the pairs some segment cannot rule out
        if not len(live):
            return dmin, self.pairs[ibest], n
        # those pairs bounded at each inner row on its own (its motion from each of its two anchors,
        # not the segment's largest: tighter): inner rows × live pairs
        own = np.arange(len(inner))
        lower = np.maximum(D[np.ix_(left, live)] - self._segment_motion(Q, A, inner, own, A[left], live).T,
                           D[np.ix_(left + 1, live)] - self._segment_motion(Q, A, inner, own, A[left + 1], live).T)
        lower = np.ascontiguousarray(lower)
        row_low = lower.min(axis=1)
        gm, gd = self._cgm, self._cgd
        for j in np.argsort(row_low, kind="stable").tolist():
            if row_low[j] >= dmin:
                break
            ks = live[lower[j] < dmin].tolist()
            i = int(inner[j])
            if len(ks) > n_pairs // 8:   # many pairs: all of them in one C++ call is cheaper
                d_all = self.distances(Q[i])
                n += n_pairs
                k = int(d_all.argmin())
                if d_all[k] < dmin:
                    dmin, ibest = float(d_all[k]), k
                continue
            pin.updateGeometryPlacements(self.model, self.data, gm, gd, Q[i])
            for k in ks:
                d = pin.computeDistance(gm, gd, k).min_distance
                n += 1
                if d < dmin:
                    dmin, ibest = float(d), k
        return dmin, self.pairs[ibest], n

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
