"""The boundary configurations of a trajectory NLP that no solve can fix: a configuration a
``JointBoundary`` pins is given, the NLP has no collision rows there (``skip_pinned``), so a start
or end in collision would come back as a converged solve. :func:`pinned_collisions` finds them
before IPOPT runs; :meth:`OptProblem.solve` then reports ``IpoptStatus.BOUNDARY_IN_COLLISION``."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

if TYPE_CHECKING:
    from .problem import OptProblem

__all__ = ["pinned_collisions"]


def pinned_collisions(problem: OptProblem, built: dict[str, Any], tol: float) -> str:
    """The first configuration pinned by a JointBoundary that a CollisionAvoidance term's checker
    finds in collision (exact coal distance < −``tol`` [m]), as a message naming the knot, the pair
    and the depth; "" when there is none. A floating robot's end knot is not checked (its base
    placement there is an outcome of the solve)."""
    from .collision_term import CollisionAvoidance

    pinned = problem._pinned_q()
    if not pinned:
        return ""
    robot = problem.robot
    for h in problem._handles:
        if h.role != "constraint" or not isinstance(h.term, CollisionAvoidance):
            continue
        info = built["data"][h.name].info or {}
        model = info.get("model")
        if model is None:
            continue
        for k, qj in sorted(pinned.items()):
            if robot.is_floating:
                if k != 0:
                    continue
                q_full = np.concatenate([pin.SE3ToXYZQUAT(problem.base0), qj])
            else:
                q_full = qj
            d, pair = model.checker.min_distance(q_full)
            if d < -tol:
                which = "start" if k == 0 else ("end" if k == problem.N else f"knot {k}")
                names = f"{pair.name_a} and {pair.name_b}" if pair is not None else "a pair"
                return (f"the {which} configuration (pinned by JointBoundary) is in collision: {names} "
                        f"penetrate by {-d:.4g} m (term {h.name!r}); the NLP cannot move a pinned "
                        "configuration: choose a collision-free one")
    return ""
