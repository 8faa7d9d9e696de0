"""Collision avoidance as NLP constraints: smooth, conservative distances (:mod:`optplan.distance`)
between the robot's link capsules, the scene's obstacles and the held object.

* Robot links: their exact capsules (the URDF ``*_capsule`` collision elements).
* Held object (a box): covered by ``object_grid × object_grid`` capsules along its longest axis,
  each spanning the full length (their union contains the box: conservative; the value can be up
  to the capsule radius below the exact distance near the end faces).
* Obstacles: exact boxes, spheres and capsules. Box–box pairs (a robot box vs an obstacle box) are
  not modelled in the NLP and are reported by ``skipped``; :func:`optplan.verify.verify` still
  checks them exactly with coal.

Pair activation: a pair is constrained at every knot when its exact coal distance along the
*initial guess* comes below ``activation`` [m] anywhere; far pairs are left out (the same pruning
TrajOpt uses). ``verify`` checks every pair exactly afterwards; :meth:`OptProblem.solve` callers
re-solve with a larger activation if it finds a violation (see ``solve_with_collision_retry``).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import casadi as ca
import coal
import numpy as np
import pinocchio as pin

from .. import distance as D
from ..collision import CollisionChecker
from ..scene import Scene
from .terms import NumericTrajectory, Term

__all__ = ["CollisionAvoidance", "object_capsules"]
log = logging.getLogger(__name__)


def object_capsules(size, grid: int = 2) -> list[D.Capsule]:
    """Capsules covering a box of full edges ``size`` [m]: a ``grid × grid`` array over the
    cross-section, each along the longest axis over the full length."""
    size = np.asarray(size, float)
    ax = int(np.argmax(size))
    others = [i for i in range(3) if i != ax]
    cell = size[others] / grid
    r = 0.5 * float(np.linalg.norm(cell))
    caps = []
    for i in range(grid):
        for j in range(grid):
            c = np.zeros(3)
            c[others[0]] = -size[others[0]] / 2 + (i + 0.5) * cell[0]
            c[others[1]] = -size[others[1]] / 2 + (j + 0.5) * cell[1]
            a, b = c.copy(), c.copy()
            a[ax], b[ax] = -size[ax] / 2, size[ax] / 2
            caps.append(D.Capsule(r, tuple(a), tuple(b)))
    return caps


@dataclass
class CollisionAvoidance(Term):
    """``d_smooth ≥ margin`` [m] for every active pair at every knot.

    scene: obstacles and (if ``held_object``) the grasped object; ``object_arm`` carries it.
    activation [m]: see module docstring. cover_tol [m]: sphere-covering tolerance of the smooth
    capsule distances (coarser = fewer spheres = faster NLP, more conservative).
    """

    scene: Scene | None = None
    margin: float = 0.0
    activation: float = 0.4
    self_collision: bool = True
    held_object: bool = True
    object_arm: str | None = None
    object_grid: int = 2
    cover_tol: float = 0.02
    eps: float = 1e-3
    default_name = "collision"
    skipped: list = field(default_factory=list)
    active_pairs: list = field(default_factory=list)

    # ------------------------------------------------------------------ entities
    def _setup(self, robot):
        self.checker = CollisionChecker(robot, self.scene, held_object=self.held_object,
                                        self_collision=self.self_collision, object_arm=self.object_arm)
        objs = robot.collision_model.geometryObjects
        self._robot_shape = {}
        for g, o in enumerate(objs):
            geo = o.geometry
            M = o.placement
            if isinstance(geo, coal.Capsule):
                hl = geo.halfLength
                a = M.translation + M.rotation @ np.array([0, 0, -hl])
                b = M.translation + M.rotation @ np.array([0, 0, hl])
                self._robot_shape[g] = (o.parentFrame, D.Capsule(geo.radius, tuple(a), tuple(b)), None)
            elif isinstance(geo, coal.Sphere):
                self._robot_shape[g] = (o.parentFrame, D.Sphere(geo.radius, tuple(M.translation)), None)
            elif isinstance(geo, coal.Box):
                self._robot_shape[g] = (o.parentFrame, D.Box(tuple(np.asarray(geo.halfSide))), M)
            else:
                self._robot_shape[g] = None
        obj = self.checker.object
        if obj is not None:
            self._obj_caps = object_capsules(obj.size, self.object_grid)
            self._grasp_inv = obj.grasps[self.checker.object_arm].inverse()
            self._hand_frame = robot.arm(self.checker.object_arm).ee_frame

    def _activate(self, robot, initial: NumericTrajectory | None):
        pairs = self.checker.pairs
        if initial is None:
            keep = list(range(len(pairs)))
        else:
            dmin = np.full(len(pairs), np.inf)
            for k in range(initial.N + 1):
                dmin = np.minimum(dmin, self.checker.distances(initial.q_full(k)))
            keep = [i for i in range(len(pairs)) if dmin[i] < self.activation]
        self.active_pairs = [pairs[i] for i in keep]
        return self.active_pairs

    # ------------------------------------------------------------------ expressions
    def _entity(self, tp, kind: str, idx: int, k: int):
        """(shapes list, R, p) of an entity at knot k; kind in robot/obstacle/object."""
        if kind == "robot":
            spec = self._robot_shape.get(idx)
            if spec is None:
                return None
            fid, shape, Mbox = spec
            R, p = tp.frame(fid, k)
            if Mbox is not None:
                return [shape], R @ ca.DM(Mbox.rotation), p + R @ ca.DM(Mbox.translation)
            return [shape], R, p
        if kind == "obstacle":
            o = self.checker.obstacles[idx]
            return [o.primitive()], ca.DM(o.placement.rotation), ca.DM(o.placement.translation)
        Rh, ph = tp.frame(self._hand_frame, k)
        G = self._grasp_inv
        return self._obj_caps, Rh @ ca.DM(G.rotation), ph + Rh @ ca.DM(G.translation)

    def _dist_fn(self, s1, s2) -> ca.Function | None:
        key = (repr(s1), repr(s2))
        if key not in self._fns:
            if isinstance(s1, D.Box) and isinstance(s2, D.Box):
                self._fns[key] = None
            else:
                self._fns[key] = D.make_distance_function(s1, s2, eps=self.eps, cover_tol=self.cover_tol)
        return self._fns[key]

    @staticmethod
    def _kinds(pair):
        return {"self": ("robot", "robot"), "robot-obstacle": ("robot", "obstacle"),
                "object-obstacle": ("object", "obstacle"), "object-robot": ("object", "robot")}[pair.kind]

    def residual(self, tp):
        robot = tp.robot
        self._setup(robot)
        self._fns: dict = {}
        self.skipped = []
        active = self._activate(robot, getattr(tp, "initial_traj", None))
        rs = []
        for pair in active:
            ka, kb = self._kinds(pair)
            for k in range(tp.N + 1):
                ea = self._entity(tp, ka, pair.a, k)
                eb = self._entity(tp, kb, pair.b, k)
                if ea is None or eb is None:
                    self.skipped.append(pair)
                    break
                for sa in ea[0]:
                    for sb in eb[0]:
                        f = self._dist_fn(sa, sb)
                        if f is None:
                            if pair not in self.skipped:
                                self.skipped.append(pair)
                            continue
                        rs.append(f(ea[1], ea[2], eb[1], eb[2]))
        if self.skipped:
            log.info("collision term: %d pair(s) not modelled in the NLP (box-box): %s", len(self.skipped),
                     [(p.name_a, p.name_b) for p in self.skipped[:5]])
        if not rs:
            return ca.MX.zeros(0), np.zeros(0), np.zeros(0)
        r = ca.vertcat(*rs)
        return r, np.full(r.shape[0], self.margin), np.full(r.shape[0], np.inf)

    def numeric(self, traj: NumericTrajectory) -> np.ndarray:
        """Exact coal distances of the active pairs at every knot, ``(N+1) × n_active``."""
        if not hasattr(self, "checker"):
            self._setup(traj.robot)
            self._activate(traj.robot, traj)
        idx = [self.checker.pairs.index(p) for p in self.active_pairs]
        return np.array([self.checker.distances(traj.q_full(k))[idx] for k in range(traj.N + 1)])

    def _bounds_numeric(self, traj):
        n = self.numeric(traj).size
        return np.full(n, self.margin), np.full(n, np.inf)
