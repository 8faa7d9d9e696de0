"""The self-collision pair budget of a robot: which geometry pairs the planner, the trajectory NLP
and :func:`optplan.verify` check.

1. **all pairs** of collision geometries;
2. **adjacent**: pairs fewer than three joints apart in the tree and pairs in contact at the
   neutral configuration are dropped (:meth:`RobotModel._default_collision_pairs`);
3. **never in collision within the joint limits**: ``samples`` configurations drawn uniformly in
   the joint box find the candidates (pairs never closer than :data:`SAMPLE_CLEARANCE`); each
   candidate is then *certified* over the whole box of the joints between its two links (only
   those move one relative to the other), by branch and bound on a Lipschitz bound: a revolute
   joint turning by Δ moves a point by at most Δ × its distance from the joint's axis, bounded
   by the sum of the link offsets from that joint to the geometry plus the geometry's radius,
   so ``d(q) ≥ d(centre) − Σ ρ_k · half-width_k`` on every cell. A candidate is pruned only when
   every cell is certified (at most ``max_cells`` distance evaluations, at most
   :data:`MAX_PATH_JOINTS` joints between the links); else it is kept. Pairs of links that cannot
   meet at all — their *reach balls* (centred on the first joint below their common ancestor, of
   radius the link offsets down to the geometry plus its radius) are apart, e.g. links of two
   arms mounted far apart — are certified by that alone, whatever the joints between them.

(Pairs between the held object and the links rigidly attached to a holding hand need no rows:
the trajectory NLP leaves them out while both hands hold; see the own-robot guide.)
"""
from __future__ import annotations

import heapq
import math

import coal
import numpy as np
import pinocchio as pin

__all__ = ["prune_pairs", "certify_pair", "certify_apart", "joint_path", "sampled_min_distances", "MAX_CELLS", "MAX_PATH_JOINTS",
           "SAMPLE_CLEARANCE"]

#: pairs with more joints than this between their links are never certified (kept)
MAX_PATH_JOINTS = 4
#: [m] candidates for certification: pairs whose sampled distance never falls below this
SAMPLE_CLEARANCE = 0.005
#: distance evaluations allowed to certify one pair [count] (past it the pair is kept)
MAX_CELLS = 1000


def _chain(model: pin.Model, j: int) -> list[int]:
    out = [j]
    while j > 0:
        j = int(model.parents[j])
        out.append(j)
    return out


def joint_path(model: pin.Model, ja: int, jb: int) -> tuple[list[int], list[int]]:
    """Joints between two joints' bodies: (a's side: from ``ja`` up to, excluding, the common
    ancestor; b's side likewise). Their motion is all that changes the two bodies' relative pose."""
    ca_, cb = _chain(model, ja), _chain(model, jb)
    common = next(j for j in ca_ if j in cb)
    return ca_[:ca_.index(common)], cb[:cb.index(common)]


def _radius(geo: coal.CollisionGeometry) -> float:
    """Radius [m] of a ball about the geometry's origin containing it."""
    if isinstance(geo, coal.Capsule):
        return float(geo.radius + geo.halfLength)
    if isinstance(geo, coal.Sphere):
        return float(geo.radius)
    if isinstance(geo, coal.Box):
        return float(np.linalg.norm(geo.halfSide))
    if isinstance(geo, coal.Cylinder):
        return float(math.hypot(geo.radius, geo.halfLength))
    if isinstance(geo, coal.Convex):
        return float(np.linalg.norm(np.asarray(geo.points(), float).reshape(-1, 3), axis=1).max())
    if hasattr(geo, "num_vertices") and geo.num_vertices > 0:
        return float(max(np.linalg.norm(np.asarray(geo.vertex(i), float)) for i in range(geo.num_vertices)))
    return math.inf


def _lever(model: pin.Model, side: list[int], g: pin.GeometryObject) -> dict[int, float]:
    """ρ_k [m per rad, or 1 for a prismatic joint] of every joint k on one side of the path."""
    out = {}
    r_geo = float(np.linalg.norm(g.placement.translation)) + _radius(g.geometry)
    # side = [the geometry's joint, its parent, ...]: lever of side[i] = offsets of side[i-1..0] + r_geo
    acc = r_geo
    for i, k in enumerate(side):
        if i > 0:
            acc += float(np.linalg.norm(model.jointPlacements[side[i - 1]].translation))
        kind = model.joints[k].shortname()
        out[k] = 1.0 if "Prismatic" in kind or kind.startswith("JointModelP") else acc
    return out


def _reach_ball(model: pin.Model, data: pin.Data, side: list[int], g: pin.GeometryObject
                ) -> tuple[np.ndarray, float] | None:
    """A ball (centre in the world at the current configuration [m], radius [m]) that contains the
    geometry ``g`` for every value of the joints ``side`` (its joint first, up to the joint whose
    parent is the common ancestor): centred on the origin of that last joint, which those joints
    cannot move, of radius the sum of the link offsets down to the geometry plus its own radius.
    None when a joint of ``side`` is not revolute (a prismatic joint moves the origin)."""
    if not side:
        M = data.oMi[int(g.parentJoint)] * g.placement
        return np.array(M.translation, float), _radius(g.geometry)
    for k in side:
        kind = model.joints[k].shortname()
        if model.nvs[k] != 1 or "Prismatic" in kind or kind.startswith("JointModelP") or kind == "JointModelMimic":
            return None
    r = _lever(model, side, g)[side[-1]]
    return np.array(data.oMi[side[-1]].translation, float), r


def certify_apart(robot, a: int, b: int) -> bool:
    """Are geometries ``a`` and ``b`` apart for EVERY joint configuration (no joint limits needed)?
    True when their reach balls (:func:`_reach_ball`) do not meet — e.g. links of two arms mounted
    far enough apart. Sound for any number of joints between them."""
    model, gm = robot.model, robot.collision_model
    oa, ob = gm.geometryObjects[a], gm.geometryObjects[b]
    sa, sb = joint_path(model, int(oa.parentJoint), int(ob.parentJoint))
    data = model.createData()
    pin.forwardKinematics(model, data, robot.neutral())
    ba, bb = _reach_ball(model, data, sa, oa), _reach_ball(model, data, sb, ob)
    if ba is None or bb is None or not (math.isfinite(ba[1]) and math.isfinite(bb[1])):
        return False
    return bool(np.linalg.norm(ba[0] - bb[0]) > ba[1] + bb[1])


def certify_pair(robot, a: int, b: int, max_cells: int = MAX_CELLS) -> bool:
    """Is geometry pair (a, b) collision-free over the whole joint box? (module docstring; pairs
    with more joints between them than :data:`MAX_PATH_JOINTS` only by :func:`certify_apart`)."""
    model, gm = robot.model, robot.collision_model
    oa, ob = gm.geometryObjects[a], gm.geometryObjects[b]
    sa, sb = joint_path(model, int(oa.parentJoint), int(ob.parentJoint))
    path = sa + sb
    if path and certify_apart(robot, a, b):
        return True
    if not path or len(path) > MAX_PATH_JOINTS:
        return False
    rho = {**_lever(model, sa, oa), **_lever(model, sb, ob)}
    base = 2 if robot.is_floating else 1
    idx, lo, hi, w = [], [], [], []
    for k in path:
        if k < base or model.nqs[k] != 1 or model.joints[k].shortname() == "JointModelMimic":
            return False
        qi = int(model.idx_qs[k])
        lo_k, hi_k = float(model.lowerPositionLimit[qi]), float(model.upperPositionLimit[qi])
        if not (math.isfinite(lo_k) and math.isfinite(hi_k)) or not math.isfinite(rho[k]):
            return False
        idx.append(qi)
        lo.append(lo_k)
        hi.append(hi_k)
        w.append(rho[k])
    lo_a, hi_a, w_a = np.array(lo), np.array(hi), np.array(w)
    data = model.createData()
    q = robot.neutral()
    req, res = coal.DistanceRequest(), coal.DistanceResult()

    def dist(c: np.ndarray) -> float:
        q[idx] = c
        pin.forwardKinematics(model, data, q)
        Ma = data.oMi[int(oa.parentJoint)] * oa.placement
        Mb = data.oMi[int(ob.parentJoint)] * ob.placement
        res.clear()
        return float(coal.distance(oa.geometry, coal.Transform3s(Ma.rotation, Ma.translation),
                                   ob.geometry, coal.Transform3s(Mb.rotation, Mb.translation), req, res))

    # cells as (priority, counter, lo, hi); the one with the smallest lower bound first
    heap: list = []
    n = 0

    def push(l_: np.ndarray, h_: np.ndarray) -> bool:
        nonlocal n
        c = 0.5 * (l_ + h_)
        d = dist(c)
        n += 1
        if d <= 0.0:
            return False
        bound = d - float(w_a @ (0.5 * (h_ - l_)))
        if bound <= 0.0:
            heapq.heappush(heap, (bound, n, l_, h_))
        return True

    if not push(lo_a, hi_a):
        return False
    while heap:
        if n + 2 > max_cells:
            return False
        _, _, l_, h_ = heapq.heappop(heap)
        k = int(np.argmax(w_a * (h_ - l_)))
        m = 0.5 * (l_[k] + h_[k])
        h1, l2 = h_.copy(), l_.copy()
        h1[k], l2[k] = m, m
        if not (push(l_, h1) and push(l2, h_)):
            return False
    return True


def sampled_min_distances(robot, pairs, n: int, seed: int) -> np.ndarray:
    """Smallest exact (coal) distance [m] of each geometry pair ``(a, b)`` over ``n`` joint vectors
    drawn uniformly in the joint limits (``numpy.random.default_rng(seed)``; a floating base at
    its neutral placement: it moves no pair relative to the other)."""
    gm = pin.GeometryModel()
    for o in robot.collision_model.geometryObjects:
        gm.addGeometryObject(pin.GeometryObject(o))
    for a, b in pairs:
        gm.addCollisionPair(pin.CollisionPair(int(a), int(b)))
    gd = pin.GeometryData(gm)
    data = robot.model.createData()
    rng = np.random.default_rng(seed)
    out = np.full(len(pairs), math.inf)
    q0 = robot.neutral()
    for _ in range(int(n)):
        q = robot.configuration(robot.random_joints(rng)) if robot.is_floating else robot.random_joints(rng)
        if robot.is_floating:
            q[:7] = q0[:7]
        pin.computeDistances(robot.model, data, gm, gd, q)
        out = np.minimum(out, [r.min_distance for r in gd.distanceResults])
    return out


def prune_pairs(robot, samples: int = 1000, seed: int = 0, max_cells: int = MAX_CELLS) -> dict:
    """Prune ``robot``'s self-collision pairs (module docstring) in place; returns the budget:
    ``geometries``, ``all_pairs``, ``after_adjacent`` (stage 2), ``candidates`` (never closer
    than :data:`SAMPLE_CLEARANCE` in ``samples`` configurations), ``certified`` (pruned), ``kept``."""
    n_geom = len(robot.collision_model.geometryObjects)
    before = list(robot.collision_pairs)
    cand: list[tuple[int, int]] = []
    if samples > 0 and before:
        d = sampled_min_distances(robot, before, samples, seed)
        cand = [p for p, x in zip(before, d) if x > SAMPLE_CLEARANCE]
    certified = {p for p in cand if certify_pair(robot, p[0], p[1], max_cells)}
    keep = [p for p in before if p not in certified]
    robot.set_collision_pairs(keep)
    return {"geometries": n_geom, "all_pairs": n_geom * (n_geom - 1) // 2, "after_adjacent": len(before),
            "samples": int(samples), "candidates": len(cand), "certified": len(certified), "kept": len(keep)}
