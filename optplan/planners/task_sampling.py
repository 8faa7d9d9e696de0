"""Task-space (object-pose) sampling for TCBiRRT's improved variant.

Everything here works on the object pose ξ = [x, y, z, roll, pitch, yaw] alone, without IK, so it
costs microseconds where one ConstrainedExtend costs tenths of a millisecond or more:

* :class:`ObjectPoseFilter` — the object box against the scene's obstacles (coal, with a bounding
  sphere pre-test) and a reach test: each hand's grasp point must lie within the arm's reach bound
  (sum of the link offsets from the first joint to the end-effector frame — a true upper bound on
  the distance any configuration can place the hand from the shoulder).
* :class:`TaskSampler` — draws ξ_rand for ConstrainedExtend: uniform in the ξ box, rejected while
  the filter says "unreachable or object in collision" (``filter_tries`` attempts, then the last
  draw is used); with probability ``bridge_probability`` a **bridge test** (Hsu et al. 2003) in ξ:
  two object poses ``ξ1`` (uniform) and ``ξ2 = ξ1 + N(0, σ)`` both with the object in collision and
  their midpoint free — poses inside narrow openings, whatever rotation the opening asks for;
  with probability ``goal_bias`` the ξ of a random node of the other tree; with probability
  ``guide_probability`` a pose near a **lead path**: a path of the object ALONE from the start to the
  goal pose (RRTConnect in ξ with :class:`ObjectPoseFilter` as validity: object free, hands within
  reach; :func:`object_lead_path`), which finds the openings the object fits through in
  milliseconds; the arms' constraints are left to TCBiRRT's extensions.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, cast

import coal
import numpy as np
import pinocchio as pin

from ..model.reach import arm_reach, arm_reach_estimate
from ..model.robot import RobotModel
from ..scene import Obstacle, Scene

__all__ = ["ObjectPoseFilter", "TaskSampler", "arm_reach", "arm_reach_estimate", "object_lead_path",
           "robot_body_obstacles"]


class ObjectPoseFilter:
    """Cheap necessary conditions on an object pose (no IK): object ∩ obstacles = ∅ and both grasp
    points within reach. ``margin`` [m] shrinks the reach bound's slack (0: the exact bound). ``native``:
    the object test in the native planning kernel (:mod:`optplan.planners.kernel`; exact box, sphere and
    capsule tests) when it can be built, else coal. ``robot_body``: the robot's geometries fixed to the world
    (:func:`robot_body_obstacles`: a fixed base's body, which no configuration moves) count as obstacles too."""

    def __init__(self, robot: RobotModel, scene: Scene, margin: float = 0.0, native: bool = True,
                 robot_body: bool = False) -> None:
        held = scene.object
        if held is None:
            raise ValueError("ObjectPoseFilter needs a scene with an [object]")
        if robot_body:   # the robot's own fixed body is an obstacle of the object too
            scene = replace(scene, obstacles=tuple(scene.obstacles) + robot_body_obstacles(robot))
        self.obj = held.coal_geometry()
        half = np.asarray(held.size, float) / 2
        self.obj_radius = float(np.linalg.norm(half))
        self.obs = []
        centres, radii = [], []
        for o in scene.obstacles:
            g = o.coal_geometry()
            M = o.placement
            self.obs.append((g, coal.Transform3s(M.rotation, M.translation)))
            centres.append(M.translation)
            if o.shape == "box":
                radii.append(float(np.linalg.norm(np.asarray(o.size) / 2)))
            elif o.shape == "sphere":
                radii.append(cast(float, o.radius))
            else:   # a capsule: radius and length are set
                radii.append(cast(float, o.radius) + cast(float, o.length) / 2)
        self.centres = np.asarray(centres, float).reshape(-1, 3)
        self.radii = np.asarray(radii, float)
        self.grasps = []
        for arm, G in held.grasps.items():
            sh, r = arm_reach(robot, arm)
            self.grasps.append((np.asarray(G.rotation), np.asarray(G.translation), sh, r - margin))
        self._req = coal.CollisionRequest()
        self._res = coal.CollisionResult()
        self.n_calls = 0
        self._native = _native_object_check(scene) if native else None
        #: the whole test on ξ in one native call (:class:`~optplan.planners.kernel.extend.NativePoseFilter`)
        self._xi_native = _native_pose_filter(self) if self._native is not None else None

    def _object_free_native(self, R: np.ndarray, p: np.ndarray) -> bool:
        kernel, g, active, _ = cast(tuple[Any, int, int, np.ndarray], self._native)
        return bool(kernel.pose_free(g, R, p, active))

    def reachable(self, R: np.ndarray, p: np.ndarray) -> bool:
        for _, t, sh, r in self.grasps:
            v = p + R @ t - sh
            if math.sqrt(v.dot(v)) > r:   # |v|, as np.linalg.norm computes it, without its dispatch
                return False
        return True

    def object_free(self, R: np.ndarray, p: np.ndarray) -> bool:
        if not len(self.radii):
            return True
        if self._native is not None:
            return self._object_free_native(R, p)
        d = np.linalg.norm(self.centres - p, axis=1)
        near = np.nonzero(d < self.radii + self.obj_radius)[0]
        if not near.size:
            return True
        tf = coal.Transform3s(R, p)
        for k in near:
            g, to = self.obs[k]
            self._res.clear()
            if coal.collide(self.obj, tf, g, to, self._req, self._res):
                return False
        return True

    def __call__(self, R: np.ndarray, p: np.ndarray) -> bool:
        self.n_calls += 1
        return self.reachable(R, p) and self.object_free(R, p)

    def xi_ok(self, xi: np.ndarray) -> bool:
        """The filter at ξ = (position [m], roll, pitch, yaw [rad]) (Eq. 2's RPY)."""
        nf = self._xi_native
        if nf is None:
            return self(_rpy_matrix(xi), xi[:3])
        self.n_calls += 1
        return nf.check(xi) == 2

    def xi_class(self, xi: np.ndarray, reach: bool = True) -> int:
        """0: a grasp point beyond reach (with ``reach``), 1: the object collides, 2: both pass (ξ as
        :meth:`xi_ok`; not counted in ``n_calls``)."""
        nf = self._xi_native
        if nf is not None:
            return nf.check(xi, reach)
        R = _rpy_matrix(xi)
        if reach and not self.reachable(R, xi[:3]):
            return 0
        return 2 if self.object_free(R, xi[:3]) else 1

    def segment_ok(self, a: np.ndarray, b: np.ndarray, resolution: float) -> bool:
        """The straight ξ segment ``a → b`` passes at the points of
        :func:`~optplan.planners.rrtconnect.edge_is_valid` (every ``resolution`` of the largest coordinate
        change, ``b`` included)."""
        nf = self._xi_native
        if nf is None:
            from .rrtconnect import edge_is_valid

            return edge_is_valid(a, b, self.xi_ok, resolution)
        ok, n = nf.segment(a, b, resolution)
        self.n_calls += n
        return ok


def robot_body_obstacles(robot: RobotModel) -> tuple[Obstacle, ...]:
    """The robot's collision geometries fixed to the world (on its universe joint; none for a floating base) as
    scene obstacles (boxes, spheres and capsules; other shapes are left out): the object can never pass through
    them, whatever the arms do."""
    if robot.is_floating:
        return ()
    out = []
    for g in robot.collision_model.geometryObjects:
        if g.parentJoint != 0:
            continue
        geo, M = g.geometry, pin.SE3(g.placement)
        if isinstance(geo, coal.Box):
            hx, hy, hz = (float(x) for x in np.asarray(geo.halfSide))
            out.append(Obstacle(f"robot/{g.name}", "box", M, size=(2.0 * hx, 2.0 * hy, 2.0 * hz)))
        elif isinstance(geo, coal.Sphere):
            out.append(Obstacle(f"robot/{g.name}", "sphere", M, radius=float(geo.radius)))
        elif isinstance(geo, coal.Capsule):
            out.append(Obstacle(f"robot/{g.name}", "capsule", M, radius=float(geo.radius), length=2.0 * float(geo.halfLength)))
    return tuple(out)


def _native_object_check(scene: Scene) -> tuple[Any, int, int, np.ndarray] | None:
    """(kernel, object geometry index, address of the active mask, the mask) of a native
    object-vs-obstacles check, or None when the kernel cannot be built here."""
    from .kernel import KernelUnavailable, NativeKernel

    assert scene.object is not None
    gm = pin.GeometryModel()
    for o in scene.obstacles:
        gm.addGeometryObject(pin.GeometryObject(f"obstacle/{o.name}", 0, 0, o.placement, o.coal_geometry()))
    g = gm.addGeometryObject(pin.GeometryObject("object", 0, 0, pin.SE3.Identity(), scene.object.coal_geometry()))
    try:
        kernel = NativeKernel(pin.Model(), gm, [(g, k) for k in range(g)])
    except KernelUnavailable:
        return None
    mask = kernel.all_active()
    return kernel, g, int(mask.ctypes.data), mask


def _native_pose_filter(filt: ObjectPoseFilter) -> Any:
    """The :class:`~optplan.planners.kernel.extend.NativePoseFilter` of ``filt`` (which has a native object
    model), or None when the extension library cannot be built here."""
    from .kernel import KernelUnavailable

    kernel, g, _, mask = cast(tuple[Any, int, int, np.ndarray], filt._native)
    try:
        from .kernel.extend import NativePoseFilter

        return NativePoseFilter(kernel, g, mask, [(t, sh, r) for _, t, sh, r in filt.grasps], len(filt.radii))
    except KernelUnavailable:
        return None


def _rpy_matrix(xi: np.ndarray) -> np.ndarray:
    return np.asarray(pin.rpy.rpyToMatrix(float(xi[3]), float(xi[4]), float(xi[5])))


def object_lead_path(filt: ObjectPoseFilter, xi_start: np.ndarray, xi_goal: np.ndarray, lo: Any, hi: Any,
                     rng: np.random.Generator, deadline: Any, *, resolution: float = 0.04, range_: float = 0.3,
                     spacing: float = 0.1, shortcut_iterations: int = 50, bridge_probability: float = 0.5,
                     bridge_sigma: tuple[float, float] = (0.3, 0.4),
                     geodesic_probability: float = 0.5, native_rng: Any = None) -> np.ndarray | None:
    """Rigid-body path of the object alone in ξ: RRTConnect (straight ξ segments checked every
    ``resolution`` by ``filt``) whose samples are bridge-test poses with probability
    ``bridge_probability`` (else uniform in the box), shortcut, then resampled every ``spacing``;
    ``(n, 6)`` or None (at the deadline: its time, or its work budget, the iterations it spends). With ``native_rng`` (a
    :class:`~optplan.planners.kernel.sampler.NativeRandom`) and the filter's native pose test, the search and
    the shortcuts are one native call drawing from it (``rng`` is then not used)."""
    from .rrtconnect import shortcut_path
    from .tree import Tree

    valid = filt.xi_ok

    lo = np.minimum(np.asarray(lo, float), np.minimum(xi_start, xi_goal))
    hi = np.maximum(np.asarray(hi, float), np.maximum(xi_start, xi_goal))
    if native_rng is not None and filt._xi_native is not None:
        from .kernel.sampler import native_lead_path

        got = native_lead_path(filt, xi_start, xi_goal, lo, hi, native_rng, deadline, resolution=resolution,
                               range_=range_, shortcut_iterations=shortcut_iterations,
                               bridge_probability=bridge_probability, bridge_sigma=bridge_sigma,
                               geodesic_probability=geodesic_probability)
        return None if got is None else _resample(got, spacing)
    sampler = TaskSampler(filt, lo, hi, filter_tries=0, bridge_probability=bridge_probability,
                          bridge_sigma=bridge_sigma, bridge_tries=20, geodesic_probability=geodesic_probability,
                          endpoints=(xi_start, xi_goal))
    ta, tb = Tree(np.asarray(xi_start, float)), Tree(np.asarray(xi_goal, float))
    a_first = True

    def extend(tree: Any, target: np.ndarray, connect: bool) -> tuple[int, bool]:
        i = tree.nearest(target)
        while True:
            x = tree.X[i]
            d = target - x
            dist = float(np.sqrt(d @ d))
            if dist < 1e-9:
                return i, True
            y = target if dist <= range_ else x + (range_ / dist) * d
            if not filt.segment_ok(x, y, resolution):
                return i, False
            i = tree.add(y, i)
            if dist <= range_:
                return i, True
            if not connect:
                return i, False

    found = None
    while not deadline.expired():
        deadline.spend(1)
        xi = sampler.sample(rng)
        ia, _ = extend(ta, xi, True)
        ib, reached = extend(tb, ta.X[ia].copy(), True)
        if reached:
            found = (ia, ib)
            break
        ta, tb, a_first = tb, ta, not a_first
    if found is None:
        return None
    pa, pb = ta.branch(found[0]), tb.branch(found[1])
    path = pa + pb[::-1][1:]
    if not a_first:
        path = path[::-1]
    if shortcut_iterations:
        path = shortcut_path(path, valid, resolution, rng, shortcut_iterations)
    return _resample(path, spacing)


def _resample(path: list[np.ndarray], spacing: float) -> np.ndarray:
    """The poses of ``path`` with each segment cut into pieces no longer than ``spacing``."""
    out = [path[0]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, int(np.ceil(float(np.linalg.norm(b - a)) / spacing)))
        out.extend(a + (k / n) * (b - a) for k in range(1, n + 1))
    return np.asarray(out)


class TaskSampler:
    """ξ_rand for the improved TCBiRRT (see the module docstring). ``lo``/``hi``: the ξ box;
    ``bridge_sigma``: (position [m], angle [rad]) standard deviations of the bridge test's second
    pose; counters in :attr:`stats`."""

    def __init__(self, filt: ObjectPoseFilter | None, lo: Any, hi: Any, *, filter_tries: int = 30,
                 bridge_probability: float = 0.0, bridge_sigma: tuple[float, float] = (0.3, 0.4),
                 bridge_tries: int = 60, goal_bias: float = 0.0, guide_probability: float = 0.0,
                 guide_sigma: tuple[float, float] = (0.05, 0.05), geodesic_probability: float = 0.0,
                 geodesic_sigma: float = 0.15, endpoints: tuple[np.ndarray, np.ndarray] | None = None,
                 lead_orientation_probability: float = 0.0) -> None:
        self.filt = filt
        self.lo, self.hi = np.asarray(lo, float), np.asarray(hi, float)
        self._span = self.hi - self.lo
        self.filter_tries = int(filter_tries)
        self.p_bridge = float(bridge_probability)
        self.sigma = np.r_[[bridge_sigma[0]] * 3, [bridge_sigma[1]] * 3]
        self.bridge_tries = int(bridge_tries)
        self.goal_bias = float(goal_bias)
        self.p_guide = float(guide_probability)
        self.guide_sigma = np.r_[[guide_sigma[0]] * 3, [guide_sigma[1]] * 3]
        self.guide: np.ndarray | None = None
        self.p_geo = float(geodesic_probability)
        self.geo_sigma = float(geodesic_sigma)
        self.p_lead = float(lead_orientation_probability)
        self._R0: np.ndarray | None = None
        self._w: np.ndarray | None = None
        if endpoints is not None:
            self.set_endpoints(*endpoints)
        self.stats = {"samples": 0, "goal_samples": 0, "bridge_samples": 0, "guide_samples": 0,
                      "filter_rejections": 0}

    def set_endpoints(self, xi_a: np.ndarray, xi_b: np.ndarray) -> None:
        """Start and goal poses: orientation samples follow their geodesic (``geodesic_probability``)."""
        self._R0 = _rpy_matrix(xi_a)
        self._w = np.asarray(pin.log3(self._R0.T @ _rpy_matrix(xi_b)))

    def _draw(self, rng: np.random.Generator) -> np.ndarray:
        """Uniform in the box; with probability ``geodesic_probability`` the orientation is instead
        a point of the start-goal rotation geodesic (uniform parameter) perturbed by
        ``N(0, geodesic_sigma²)`` per axis — the orientations tight openings between them allow; with
        probability ``lead_orientation_probability`` (once a lead path is known) the orientation is that of
        the lead path's pose nearest in position, perturbed the same way — the orientation the passage
        there lets the object through with."""
        # lo + (hi − lo) u with u = rng.random(6): Generator.uniform's own formula and draws, bit for bit,
        # without its per-call argument checks (7 µs → 1 µs)
        xi = self.lo + self._span * rng.random(self.lo.size)
        if self.p_lead > 0.0 and self.guide is not None and rng.random() < self.p_lead:
            d = self.guide[:, :3] - xi[:3]
            g = self.guide[int(np.argmin(np.einsum("ij,ij->i", d, d)))]
            R = _rpy_matrix(g) @ np.asarray(pin.exp3(rng.normal(0.0, self.geo_sigma, 3)))
            xi[3:] = np.asarray(pin.rpy.matrixToRpy(R))
        elif self._R0 is not None and rng.random() < self.p_geo:
            R = self._R0 @ np.asarray(pin.exp3(rng.random() * cast(np.ndarray, self._w))) @ np.asarray(pin.exp3(rng.normal(0.0, self.geo_sigma, 3)))
            xi[3:] = np.asarray(pin.rpy.matrixToRpy(R))
        return xi

    def _ok(self, xi: np.ndarray) -> bool:
        return self.filt is None or self.filt.xi_ok(xi)

    def uniform(self, rng: np.random.Generator) -> np.ndarray:
        xi = self._draw(rng)
        if self.filt is None:
            return xi
        for _ in range(self.filter_tries):
            if self._ok(xi):
                return xi
            self.stats["filter_rejections"] += 1
            xi = self._draw(rng)
        return xi

    def bridge(self, rng: np.random.Generator) -> np.ndarray | None:
        f = cast(ObjectPoseFilter, self.filt)   # called only with a filter
        for _ in range(self.bridge_tries):
            a = self._draw(rng)
            if f.xi_class(a) != 1:          # beyond reach, or the object free: not a bridge end
                continue
            b = a + rng.normal(0.0, 1.0, 6) * self.sigma
            if f.xi_class(b, reach=False) != 1:
                continue
            Ra, Rb = _rpy_matrix(a), _rpy_matrix(b)
            # midpoint on the geodesic between the two orientations, expressed back in RPY
            Rm = Ra @ np.asarray(pin.exp3(0.5 * np.asarray(pin.log3(Ra.T @ Rb))))
            pm = 0.5 * (a[:3] + b[:3])
            if f(Rm, pm):
                return np.r_[pm, np.asarray(pin.rpy.matrixToRpy(Rm))]
        return None

    def sample(self, rng: np.random.Generator, other_xi: np.ndarray | None = None) -> np.ndarray:
        """One ξ_rand; ``other_xi``: the other tree's node poses (n × 6) for the goal bias."""
        self.stats["samples"] += 1
        u = rng.random()
        if other_xi is not None and len(other_xi) and u < self.goal_bias:
            self.stats["goal_samples"] += 1
            return other_xi[rng.integers(len(other_xi))].copy()
        u -= self.goal_bias
        if self.guide is not None and u < self.p_guide:
            self.stats["guide_samples"] += 1
            return self.guide[rng.integers(len(self.guide))] + rng.normal(0.0, 1.0, 6) * self.guide_sigma
        u -= self.p_guide
        if self.filt is not None and u < self.p_bridge:
            xi = self.bridge(rng)
            if xi is not None:
                self.stats["bridge_samples"] += 1
                return xi
        return self.uniform(rng)
