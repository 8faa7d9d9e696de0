"""Fast validity checking for the planners.

:class:`optplan.collision.CollisionChecker` loops over its pairs in Python (~0.5-1 ms per
configuration); the planners check tens of thousands of configurations per query. This checker
puts the robot's capsules, the scene's obstacles and the object into ONE Pinocchio
``GeometryModel`` and lets ``pinocchio.computeCollisions`` run the whole pair list in C++ (coal
narrow phase, stop at the first collision): ~20-60 µs per configuration.

The pair set is :class:`~optplan.collision.CollisionChecker`'s, from the same function
(:func:`optplan.collision.checker.scene_pairs`; a test checks that they agree on random
configurations):

* robot self-collision pairs (``robot.collision_pairs``),
* every moving robot geometry × every obstacle (the fixed base is not checked against the scene),
* the held object (rigidly attached to ``object_arm``'s hand) × obstacles and × robot geometries
  except the scene's ``exclude_links`` (the hands on the fixtures).

Three modes:

* ``is_valid(q)``: the object held by the hands (closed-chain motion),
* ``is_valid_object_fixed(q, object_pose)``: the object standing still at ``object_pose`` while
  the hands move (regrasp); here EVERY robot geometry is checked against the object (a released
  hand must not pass through it), except the pairs a regrasp exempts with :meth:`exempt` — those
  :meth:`grasp_contacts` finds at its ends: a hand geometry on one of the object's ``exclude_links``
  that touches the object at its grasp (the Panda's fingers straddle the box's face; the benchmark
  robot's hand links stay ≥ 0.1 m from it, so nothing is exempted there),
* ``is_valid_free(q)``: no object (plain joint-space planning).

:meth:`ValidityChecker.first_invalid` checks many configurations of one mode in order, stopping at the
first collision, in one call; :meth:`ValidityChecker.validity` wraps a mode (and optionally one arm
moving while the rest of the robot stands still) as a function with that batch form, which
:func:`optplan.planners.rrtconnect.edge_is_valid` uses for an edge's checkpoints.

``margin`` [m]: pairs closer than this count as colliding (coal's security margin).

:meth:`ValidityChecker.sweep_weights` gives, per joint, an upper bound [m/rad] on how far any point
of the checked geometry (robot links, and the held object in the ``"held"`` mode) moves per radian
of that joint, whatever the other joints: along a straight joint-space segment no point moves
farther than ``Σ_j w_j |Δq_j|``. Edge checks spaced by that bound
(:func:`optplan.planners.rrtconnect.edge_is_valid` with ``weights``) tie the check density to the
geometry instead of to a joint angle. :meth:`ValidityChecker.edge_is_certified` goes further: a
segment certified collision-free at every point by conservative advancement on exact distances
(:mod:`optplan.planners.edge_certify`).
"""
from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import pinocchio as pin

from ..collision.checker import exact_contact_requests, pair_indices, scene_geometry, scene_pairs
from ..model.robot import RobotModel
from ..scene import Scene
from .bisection import _bisection_array as _bisection_array
from .bisection import _bisection_fractions as _bisection_fractions
from .bisection import _bisection_indices as _bisection_indices
from .bisection import _bisection_order as _bisection_order
from .edge_certify import EdgeCertifier
from .validity_sweep import EdgeSweepMixin

if TYPE_CHECKING:
    from ..codegen import FastFunction
    from .kernel.checker import NativeValidity

__all__ = ["ValidityChecker", "ConfigValidity"]
log = logging.getLogger(__name__)


#: the broad-phase pool of Pinocchio's batch collision API (Pinocchio built with its parallel module)
_POOL = getattr(pin, "BroadPhaseManagerPool_DynamicAABBTreeCollisionManager", None)


class ValidityChecker(EdgeSweepMixin):
    """Boolean collision checks in C++ (see the module docstring).

    Counters ``n_checks`` (all modes) are incremented on every call (by the configurations checked for
    a batch). ``broadphase``: a dynamic AABB tree in front of the narrow phase (only with
    ``margin = 0``); ``batch``: the queries go through Pinocchio's batch collision API (a pool of one
    broad-phase manager per mode, one thread) when this Pinocchio has it — the same verdicts, cheaper
    per call, and :meth:`first_invalid` checks many configurations in one call; False: one
    ``computeCollisions`` call per configuration. ``exact_contacts``: every collision request asks coal
    for contacts (:func:`optplan.collision.checker.exact_contact_requests`), so that a verdict agrees
    with the sign of the exact distance also where a capsule's segment touches a box's face (there
    Pinocchio's default requests report a capsule sunk by its radius as free); False: Pinocchio's
    default requests. ``kernel``: ``"native"`` (default) — the boolean checks (:meth:`is_valid`,
    :meth:`first_invalid`, :meth:`edge_is_valid`, :meth:`valid_batch`) run in the compiled planning
    kernel (:mod:`optplan.planners.kernel`: the same pairs on exact sphere/capsule/box primitives,
    never free where coal collides, 3-6× cheaper per configuration), falling back to coal when it
    cannot be built (no C compiler) or does not cover the robot; ``"coal"``: Pinocchio + coal as
    above. :attr:`kernel` tells which one is in use. Diagnostics (:meth:`colliding_pairs`,
    :meth:`grasp_contacts`) and certified edges always use coal.

    A free-floating robot: its configurations carry the base pose (XYZ-quaternion first), so the
    checks place every geometry where that base puts it; only the configuration checks
    (:meth:`is_valid`, :meth:`first_invalid`, :meth:`valid_batch`) apply, on coal (the edge bounds
    and the compiled kernel assume a fixed base and revolute joints).
    """

    def __init__(self, robot: RobotModel, scene: Scene | None = None, *, margin: float = 0.0,
                 object_arm: str | None = None, self_collision: bool = True, broadphase: bool = True,
                 batch: bool = True, exact_contacts: bool = True, kernel: str = "native"):
        if robot.is_floating:
            # the base pose is part of each configuration (XYZ-quaternion first) and so of every
            # geometry's placement; the compiled kernel and the edge bounds cover fixed bases only
            kernel = "coal"
        if not (np.isfinite(margin) and margin >= 0.0):
            raise ValueError(f"margin: expected a number >= 0 m, got {margin!r}")
        self.robot = robot
        self.scene = scene
        self.margin = float(margin)
        self.exact_contacts = bool(exact_contacts)
        self._limits: dict[float, tuple[np.ndarray, np.ndarray]] = {}   # in_limits: the widened limits per tolerance
        self.model = robot.model
        self.data = robot.model.createData()
        # robot, obstacles, held object and the pair set as the exact checker has them
        geo = scene_geometry(robot, scene, object_arm)
        gm = geo.model
        robot_geoms = list(range(geo.n_robot))
        self.object = scene.object if scene is not None else None
        self.held_id, self.fixed_id = geo.held_id, None
        if self.object is not None:
            self.object_arm = geo.object_arm
            self.fixed_id = gm.addGeometryObject(pin.GeometryObject("object/fixed", 0, 0, pin.SE3.Identity(),
                                                                    self.object.coal_geometry()))
        groups: dict[str, list[tuple[int, int]]] = {"held": [], "fixed": [], "obstacle": [], "self": []}
        group_of = {"object-obstacle": "held", "object-robot": "held", "robot-obstacle": "obstacle", "self": "self"}
        for p in scene_pairs(robot, scene, self_collision=self_collision):
            groups[group_of[p.kind]].append(pair_indices(p, geo))
        if self.object is not None:
            fixed_id = cast(int, self.fixed_id)   # set just above
            groups["fixed"] = [(g, fixed_id) for g in robot_geoms]
        # order: object pairs first (the big box collides most), then obstacles, then self
        order = ["held", "fixed", "obstacle", "self"]
        self._pair_group = []
        for name in order:
            for a, b in groups[name]:
                gm.addCollisionPair(pin.CollisionPair(min(a, b), max(a, b)))
                self._pair_group.append(name)
        self.gmodel = gm
        self.n_pairs = {k: len(v) for k, v in groups.items()}
        self._gd = {}
        for mode, active in (("held", {"held", "obstacle", "self"}), ("fixed", {"fixed", "obstacle", "self"}),
                             ("free", {"obstacle", "self"})):
            gd = pin.GeometryData(gm)
            for k, grp in enumerate(self._pair_group):
                if grp not in active:
                    gd.deactivateCollisionPair(k)
                if self.margin > 0:
                    gd.collisionRequests[k].security_margin = self.margin
            if self.exact_contacts:
                exact_contact_requests(gd)
            self._gd[mode] = gd
        # broad phase (dynamic AABB tree, coal) in front of the narrow phase: 3-5x faster in cluttered
        # scenes; its AABBs are not inflated by a security margin, so only used with margin = 0
        self.broadphase = bool(broadphase) and self.margin == 0.0
        self._bp = {}
        if self.broadphase:
            for mode, gd in self._gd.items():
                self._bp[mode] = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(self.model, gm, gd)
        # the boolean queries go through Pinocchio's batch API (a pool of one broad-phase manager per mode, one
        # thread): the same C++ checks as computeCollisions on the managers above, a third cheaper per single
        # configuration (less Python binding dispatch) and half the cost per configuration of a batch
        self._pool: dict[str, Any] = {}
        self._pool_object = None
        if self.broadphase and _POOL is not None and batch:
            for mode, gd in self._gd.items():
                pool = _POOL(self.model, gm, 1)
                pgd = pool.getGeometryData(0)
                for k in range(len(gm.collisionPairs)):
                    if not gd.activeCollisionPairs[k]:
                        pgd.deactivateCollisionPair(k)
                if self.exact_contacts:
                    exact_contact_requests(pgd)
                self._pool[mode] = pool
            if self.fixed_id is not None:   # the still object's placement, set per query
                self._pool_object = self._pool["fixed"].getGeometryModel(0).geometryObjects[self.fixed_id]
        self.n_checks = 0
        self._native = self._native_backend(kernel)
        #: the backend of the boolean checks in use: "native" or "coal"
        self.kernel = "coal" if self._native is None else "native"
        self._sweep = {mode: self._sweep_bound(mode) for mode in ("held", "fixed", "free")}
        self._spheres = {mode: self._sweep_spheres(mode) for mode in ("held", "fixed", "free")}
        # the velocity (Jacobian) bound of edge_checkpoints assumes revolute 1-dof joints
        self._revolute_only = all(jm.nv == 1 and jm.shortname().replace("JointModel", "").startswith("R")
                                  for jm in list(self.model.joints)[1:])
        self._profile_fns: dict[Any, FastFunction | None] = {}
        self._certifiers: dict[float, EdgeCertifier] = {}
        self._exempted: dict[str, frozenset[int]] = {}   # per mode, the pairs exempt() has switched off
        self._contacts: dict[tuple[Any, ...], tuple[int, ...]] = {}   # grasp_contacts' answers
        self._contact_gd: tuple[Any, tuple[int, ...]] | None = None   # its pairs' GeometryData (made at first use)

    def _native_backend(self, kernel: str) -> NativeValidity | None:
        """The native kernel for ``kernel == "native"`` (None for "coal", or when it cannot be built)."""
        if kernel not in ("native", "coal"):
            raise ValueError(f"kernel: expected 'native' or 'coal', got {kernel!r}")
        if kernel == "coal":
            return None
        from .kernel import KernelUnavailable
        from .kernel.checker import NativeValidity
        try:
            return NativeValidity(self.model, self.gmodel, self._gd, self.fixed_id, self.margin)
        except KernelUnavailable as e:
            log.info("validity checks stay with coal: %s", e)
            return None

    def _collides(self, mode: str, q: np.ndarray) -> bool:
        """One configuration in ``mode`` (the still object's pose already set): any active pair in contact."""
        if self._native is not None:
            return self._native.collides(q, mode)
        pool = self._pool.get(mode)
        if pool is not None:
            return bool(pin.computeCollisionsInParallel(1, pool, np.asarray(q, float).reshape(-1, 1), True, True)[0])
        if self.broadphase:
            return bool(pin.computeCollisions(self.model, self.data, self._bp[mode], q, True))
        return bool(pin.computeCollisions(self.model, self.data, self.gmodel, self._gd[mode], q, True))

    def _set_object_pose(self, object_pose: pin.SE3) -> None:
        """The still object's placement for the ``"fixed"`` mode's batch queries."""
        self._pool_object.placement = object_pose   # type: ignore[union-attr]  # set when the pool exists

    def is_valid(self, q: np.ndarray) -> bool:
        """Collision-free with the object held by the hands (falls back to ``free`` without an object)."""
        self.n_checks += 1
        return not self._collides("held" if self.object is not None else "free", q)

    def is_valid_free(self, q: np.ndarray) -> bool:
        """Collision-free without any object (self and obstacles only)."""
        self.n_checks += 1
        return not self._collides("free", q)

    def is_valid_object_fixed(self, q: np.ndarray, object_pose: pin.SE3) -> bool:
        """Collision-free with the object standing still at ``object_pose`` (regrasp)."""
        if self.object is None:
            return self.is_valid_free(q)
        self.n_checks += 1
        if self._native is not None:
            return not self._native.collides(q, "fixed", object_pose)
        if "fixed" in self._pool:
            self._set_object_pose(object_pose)
            return not self._collides("fixed", q)
        gd = self._gd["fixed"]
        pin.updateGeometryPlacements(self.model, self.data, self.gmodel, gd, q)
        gd.oMg[self.fixed_id] = object_pose
        if self.broadphase:
            mgr = self._bp["fixed"]
            mgr.update(False)
            return not pin.computeCollisions(mgr, True)
        return not pin.computeCollisions(self.gmodel, gd, True)

    def first_invalid(self, Q: np.ndarray, mode: str = "held", object_pose: pin.SE3 | None = None) -> int:
        """Index of the first row of ``Q`` (configurations, M × nq) in collision, or −1 when every row
        is valid: the rows are checked IN ORDER and the checks stop at the first collision (one C++
        call; ``n_checks`` grows by the number of rows checked, as with one :meth:`is_valid` per row).
        ``mode``: ``"held"`` (:meth:`is_valid`), ``"fixed"`` (:meth:`is_valid_object_fixed` at
        ``object_pose``) or ``"free"``."""
        if mode == "held" and self.object is None:
            mode = "free"
        if mode == "fixed":
            if object_pose is None:
                raise ValueError("first_invalid: mode 'fixed' needs object_pose")
            if self.object is None:
                mode = "free"
        elif mode not in ("held", "free"):
            raise ValueError(f"first_invalid: mode must be 'held', 'fixed' or 'free', got {mode!r}")
        Q = np.asarray(Q, float)
        if Q.ndim != 2 or Q.shape[1] != self.model.nq:
            raise ValueError(f"first_invalid: expected an (M, {self.model.nq}) array of configurations, got shape {Q.shape}")
        if self._native is not None:
            k = self._native.first_invalid(Q, mode, object_pose) if len(Q) else -1
            self.n_checks += len(Q) if k < 0 else k + 1
            return k
        pool = self._pool.get(mode)
        if pool is None:   # no batch API: one query per row
            one: Callable[[np.ndarray], bool] = ((lambda x: self.is_valid_object_fixed(x, object_pose)) if mode == "fixed"
                                                 else self.is_valid if mode == "held" else self.is_valid_free)
            for k, x in enumerate(Q):
                if not one(x):
                    return k
            return -1
        if not len(Q):
            return -1
        if mode == "fixed":
            self._set_object_pose(cast(pin.SE3, object_pose))
        hit = pin.computeCollisionsInParallel(1, pool, Q.T, True, True)
        k = int(np.argmax(hit)) if hit.any() else -1
        self.n_checks += len(Q) if k < 0 else k + 1
        return k

    def valid_batch(self, Q: np.ndarray, mode: str = "held", object_pose: pin.SE3 | None = None) -> np.ndarray:
        """Validity (booleans) of EVERY row of ``Q`` (M × nq) in ``mode`` (as :meth:`first_invalid`);
        ``n_checks`` grows by M."""
        Q = np.asarray(Q, float)
        if Q.ndim != 2 or Q.shape[1] != self.model.nq:
            raise ValueError(f"valid_batch: expected an (M, {self.model.nq}) array of configurations, got shape {Q.shape}")
        if mode == "held" and self.object is None or mode == "fixed" and self.object is None:
            mode = "free"
        if mode not in ("held", "fixed", "free"):
            raise ValueError(f"valid_batch: mode must be 'held', 'fixed' or 'free', got {mode!r}")
        if mode == "fixed" and object_pose is None:
            raise ValueError("valid_batch: mode 'fixed' needs object_pose")
        if self._native is not None:
            self.n_checks += len(Q)
            return self._native.valid(Q, mode, object_pose)
        return np.array([self.first_invalid(q[None], mode, object_pose) < 0 for q in Q], dtype=bool)

    def validity(self, mode: str = "held", object_pose: pin.SE3 | None = None, base: np.ndarray | None = None,
                 joints: np.ndarray | None = None) -> ConfigValidity:
        """A validity function ``f(x) -> bool`` of ``mode`` (as :meth:`first_invalid`) with a batch form
        ``f.first_invalid(X)`` that :func:`optplan.planners.rrtconnect.edge_is_valid` uses. With ``base``
        and ``joints``: ``x`` holds only the values of the joints ``joints`` (indices into q), the others
        stay at ``base`` (one arm moving while the rest of the robot stands still, as in a regrasp)."""
        return ConfigValidity(self, mode, object_pose, base, joints)

    def grasp_contacts(self, q: np.ndarray, object_pose: pin.SE3) -> tuple[int, ...]:
        """Indices of the ``"fixed"``-mode pairs in collision at ``q`` between the object standing at
        ``object_pose`` and a robot geometry on one of the object's ``exclude_links`` (the links allowed
        to touch it: a hand on the object at its grasp); other colliding pairs are not listed."""
        if self.object is None:
            return ()
        excl = set(self.object.exclude_links)
        if not excl:
            return ()
        # a regrasp asks at its ends, and verify_path again at the same ends: the answer per configuration, pose
        # and exempted pairs (the pairs it reads) is kept (a few hundred at most)
        key = (np.asarray(q, float).tobytes(), object_pose.homogeneous.tobytes(), self._exempted.get("fixed", frozenset()))
        got = self._contacts.get(key)
        if got is not None:
            return got
        if len(self._contacts) >= 256:
            self._contacts.clear()
        got = self._contacts[key] = self._grasp_contacts(q, object_pose, excl)
        return got

    def _grasp_contacts(self, q: np.ndarray, object_pose: pin.SE3, excl: set[str]) -> tuple[int, ...]:
        # only the candidate pairs (the still object and a geometry on an exclude link) are computed, in a
        # GeometryData of their own with the "fixed" mode's requests; the mode's exemptions filter the answer
        if self._contact_gd is None:
            objs = self.gmodel.geometryObjects
            cand: list[int] = []
            for k, cp in enumerate(self.gmodel.collisionPairs):
                g = cp.first if cp.second == self.fixed_id else cp.second
                if self._pair_group[k] == "fixed" and self.model.frames[objs[g].parentFrame].name in excl:
                    cand.append(k)
            cgd = pin.GeometryData(self.gmodel)
            keep = set(cand)
            for k in range(len(self.gmodel.collisionPairs)):
                if k not in keep:
                    cgd.deactivateCollisionPair(k)
                elif self.margin > 0:
                    cgd.collisionRequests[k].security_margin = self.margin
            if self.exact_contacts:
                exact_contact_requests(cgd)
            self._contact_gd = (cgd, tuple(cand))
        cgd, ks = self._contact_gd
        pin.updateGeometryPlacements(self.model, self.data, self.gmodel, cgd, q)
        cgd.oMg[cast(int, self.fixed_id)] = object_pose
        pin.computeCollisions(self.gmodel, cgd, False)
        active = self._gd["fixed"].activeCollisionPairs
        return tuple(k for k in ks if active[k] and cgd.collisionResults[k].isCollision())

    @contextmanager
    def exempt(self, pairs: tuple[int, ...], mode: str = "fixed") -> Iterator[None]:
        """Within the block, ``mode``'s checks skip the pair indices ``pairs`` (e.g. a regrasp's
        :meth:`grasp_contacts`); restored on exit. The boolean checks, the batch queries and the
        certified edges (:meth:`edge_is_certified`, :meth:`path_is_certified`) all skip them."""
        gd = self._gd[mode]
        off = [k for k in pairs if gd.activeCollisionPairs[k]]
        pool = self._pool.get(mode)
        gds = [gd] if pool is None else [gd, pool.getGeometryData(0)]   # the batch queries' pairs too
        before = self._exempted.get(mode, frozenset())
        for g in gds:
            for k in off:
                g.deactivateCollisionPair(k)
        self._exempted[mode] = before | frozenset(off)   # the certifiers read it (their pair groups per set)
        if self._native is not None:
            self._native.set_active(mode, off, False)
        try:
            yield
        finally:
            for g in gds:
                for k in off:
                    g.activateCollisionPair(k)
            if self._native is not None:
                self._native.set_active(mode, off, True)
            self._exempted[mode] = before

    def exempted(self, mode: str = "fixed") -> frozenset[int]:
        """The pair indices that :meth:`exempt` switches off in ``mode`` right now (empty outside it)."""
        return self._exempted.get(mode, frozenset())

    def in_limits(self, q: np.ndarray, tol: float = 1e-9) -> bool:
        """Whether ``q`` is within the joint limits widened by ``tol`` [rad or m]."""
        lim = self._limits.get(tol)
        if lim is None:   # the widened limits, computed once per tolerance
            lim = self._limits[tol] = (self.robot.lower - tol, self.robot.upper + tol)
        return bool((q >= lim[0]).all() and (q <= lim[1]).all())

    def colliding_pairs(self, q: np.ndarray, mode: str = "held", object_pose: pin.SE3 | None = None) -> list[tuple[str, str]]:
        """Names of every colliding pair at ``q`` (diagnostics; slow path)."""
        gd = self._gd[mode]
        pin.updateGeometryPlacements(self.model, self.data, self.gmodel, gd, q)
        if mode == "fixed" and object_pose is not None:
            gd.oMg[self.fixed_id] = object_pose
        pin.computeCollisions(self.gmodel, gd, False)
        out = []
        objs = self.gmodel.geometryObjects
        for k, cp in enumerate(self.gmodel.collisionPairs):
            if gd.activeCollisionPairs[k] and gd.collisionResults[k].isCollision():
                out.append((objs[cp.first].name, objs[cp.second].name))
        return out


class ConfigValidity:
    """A validity function of one :class:`ValidityChecker` mode (see :meth:`ValidityChecker.validity`):
    ``f(x)`` checks one configuration, ``f.first_invalid(X)`` the rows of ``X`` in order, stopping at
    the first collision (index, or −1 when all are valid)."""

    __slots__ = ("checker", "mode", "object_pose", "base", "joints")

    def __init__(self, checker: ValidityChecker, mode: str, object_pose: pin.SE3 | None = None,
                 base: np.ndarray | None = None, joints: np.ndarray | None = None) -> None:
        if mode not in ("held", "fixed", "free"):
            raise ValueError(f"validity: mode must be 'held', 'fixed' or 'free', got {mode!r}")
        if mode == "fixed" and object_pose is None:
            raise ValueError("validity: mode 'fixed' needs object_pose")
        if (base is None) != (joints is None):
            raise ValueError("validity: give both base (a full configuration) and joints (indices into it), or neither")
        self.checker, self.mode, self.object_pose = checker, mode, object_pose
        self.base = None if base is None else np.array(base, dtype=float)
        self.joints = None if joints is None else np.asarray(joints, dtype=int)

    def _full(self, x: np.ndarray) -> np.ndarray:
        if self.base is None:
            return x
        q = self.base.copy()
        q[self.joints] = x
        return q

    def __call__(self, x: np.ndarray) -> bool:
        q, ck = self._full(x), self.checker
        if self.mode == "held":
            return ck.is_valid(q)
        if self.mode == "fixed":
            return ck.is_valid_object_fixed(q, cast(pin.SE3, self.object_pose))
        return ck.is_valid_free(q)

    def first_invalid(self, X: np.ndarray) -> int:
        X = np.asarray(X, float)
        if self.base is not None:
            Q = np.repeat(self.base[None, :], len(X), axis=0)
            Q[:, self.joints] = X
            X = Q
        return self.checker.first_invalid(X, self.mode, self.object_pose)
