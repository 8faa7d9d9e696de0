"""The boundary configurations of a trajectory NLP that no solve can fix: a configuration a
``JointBoundary`` pins is given, the NLP has no collision rows there (``skip_pinned``), so a start
or end in collision would come back as a converged solve. :func:`pinned_collisions` finds them
before IPOPT runs; :meth:`OptProblem.solve` then reports ``IpoptStatus.BOUNDARY_IN_COLLISION``."""
from __future__ import annotations

from typing import Any, Protocol

import numpy as np
import pinocchio as pin

from ..model.robot import RobotModel

__all__ = ["pinned_collisions"]


class PinnedProblem(Protocol):
    """What :func:`pinned_collisions` reads of a problem (an ``OptProblem``)."""

    robot: RobotModel
    N: int
    base0: pin.SE3
    _handles: list[Any]

    def _pinned_q(self) -> dict[int, np.ndarray]: ...


def pinned_collisions(problem: PinnedProblem, built: dict[str, Any], tol: float) -> str:
    """The first configuration pinned by a JointBoundary at which a pair of a CollisionAvoidance
    term is in collision (exact coal distance < −``tol`` [m]), as a message naming the knot, the pair
    and the depth; "" when there is none. The pairs checked are the term's own: the ones its
    activation chose (a penetrating pair is closer than any ``activation`` ≥ 0) and the constant
    ones; a term whose activation leaves every pair out checks nothing. A floating robot's end knot
    is not checked (its base placement there is an outcome of the solve)."""
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
        own = list(info.get("active_pairs", ())) + list(info.get("constant_pairs", ()))
        if model is None or not own:
            continue
        idx = [model.checker.pairs.index(p) for p in own]
        for k, qj in sorted(pinned.items()):
            if robot.is_floating:
                if k != 0:
                    continue
                q_full = np.concatenate([pin.SE3ToXYZQUAT(problem.base0), qj])
            else:
                q_full = qj
            dist = model.checker.distances(q_full)[idx]
            j = int(np.argmin(dist))
            d, pair = float(dist[j]), own[j]
            if d < -tol:
                which = "start" if k == 0 else ("end" if k == problem.N else f"knot {k}")
                names = f"{pair.name_a} and {pair.name_b}"
                return (f"the {which} configuration (pinned by JointBoundary) is in collision: {names} "
                        f"penetrate by {-d:.4g} m (term {h.name!r}); the NLP cannot move a pinned "
                        "configuration: choose a collision-free one")
    return ""
