"""Object-step redraws for TCBiRRT: a sample whose extension the held object alone already forbids is drawn again.

Why. In a bay (the goal recessed between two plates, the arms reaching in from its mouth) most samples lie
outside, and the node nearest one is often deep inside: the straight task-space step toward it drives the object
into a plate. Path IK then solves the first waypoint (with its random restarts) only for the configuration check to
find the object in collision, and the extension is trapped — on generated bays in about half of all trapped
extensions, and for the tree rooted in the bay in most of its own. No IK branch, graft or regrasp changes that.

What. Before tree a extends toward ξ_rand from its nearest node, the object alone is tested at the extension's
first waypoint (the pose of Eq. 4 one ``1/n_interp`` of the step ``s_ξ`` along, the geodesic interpolation of the
search); when it collides the sample is drawn again (the same sampler, the same nearest-node search), up to
``object_step_tries`` draws, the last one extended toward regardless. The connection step (tree b toward tree a's
new node) is unchanged. An extension redrawn this way would have been trapped at its first waypoint whatever the
arms do, so what changes is only where the iteration's extension goes: to a node and direction in which the object
can move.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from .task_space import pose_from_xi

__all__ = ["first_waypoint", "first_waypoint_free"]


def first_waypoint(R0: np.ndarray, p0: np.ndarray, xi_near: np.ndarray, xi_rand: np.ndarray, step: float,
                   n_interp: int) -> tuple[np.ndarray, np.ndarray]:
    """The object pose ``(R, p)`` of an extension's first waypoint from the node at ``(R0, p0)`` (ξ ``xi_near``)
    toward ``xi_rand``: ξ_s by Eq. 3 (at most ``step`` [m and rad, as ξ] from the node), then the first of
    ``n_interp`` poses of the geodesic interpolation (Eq. 4 on the relative rotation)."""
    d = np.asarray(xi_rand, float) - xi_near
    dist = float(np.sqrt(d @ d))
    xi_s = xi_rand if dist <= step else xi_near + (step / dist) * d
    Rs, ps = pose_from_xi(np.asarray(xi_s, float))
    s = 1.0 / n_interp
    return R0 @ np.asarray(pin.exp3(s * np.asarray(pin.log3(R0.T @ Rs)))), p0 + s * (ps - p0)


def first_waypoint_free(filt: Any, R0: np.ndarray, p0: np.ndarray, xi_near: np.ndarray, xi_rand: np.ndarray,
                        step: float, n_interp: int) -> bool:
    """Whether the object alone is free of the obstacles at :func:`first_waypoint` (``filt``: an
    :class:`~optplan.planners.task_sampling.ObjectPoseFilter`; the grasp points' reach is not tested)."""
    R, p = first_waypoint(R0, p0, xi_near, xi_rand, step, n_interp)
    return bool(filt.object_free(R, p))
