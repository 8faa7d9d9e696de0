"""How far a robot's collision geometries can move: per-geometry, per-joint displacement bounds.

For a geometry attached to joint ``k`` (bounding sphere of centre ``c`` and radius ``ρ`` in the
joint's frame), ``W[g, j]`` [m/rad] is the length of the kinematic chain from joint ``j``'s
origin to joint ``k`` plus ``|c| + ρ`` when joint ``j`` moves geometry ``g``, else 0 (a
prismatic joint counts 1 m/m). Then between ANY two configurations ``q`` and ``q'`` no point of
geometry ``g`` is farther apart than ``W[g] @ |q' − q|`` (the displacement is bounded along the
straight joint segment between them, whatever path the robot took). Geometries fixed to the world
get a zero row.

Used by the planners' edge checks (:class:`optplan.planners.validity.ValidityChecker`) and by the
exact clearance along a sampled trajectory (:meth:`optplan.collision.CollisionChecker.min_distance_along`).
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

__all__ = ["sweep_weights"]


def sweep_weights(model: pin.Model, gmodel: pin.GeometryModel) -> np.ndarray:
    """``W`` (geometries × ``model.nv``) [m/rad] of the module docstring, one row per geometry of
    ``gmodel`` in its order (revolute joints 1-dof; prismatic joints 1 m/m)."""
    geoms = list(gmodel.geometryObjects)
    w = np.zeros((len(geoms), model.nv))
    for gid, go in enumerate(geoms):
        if go.parentJoint == 0:
            continue
        g = go.geometry
        g.computeLocalAABB()
        length = float(np.linalg.norm(go.placement.act(np.asarray(g.aabb_center)))) + float(g.aabb_radius)
        j = int(go.parentJoint)
        while j > 0:            # joint j moves the geometry; its origin is `length` away at most
            jm = model.joints[j]
            prismatic = "P" in jm.shortname().replace("JointModel", "")[:1]
            w[gid, jm.idx_v:jm.idx_v + jm.nv] = 1.0 if prismatic else length
            length += float(np.linalg.norm(model.jointPlacements[j].translation))
            j = int(model.parents[j])
    return w
