"""The segment NLP behind the pipeline's retry policy: the :class:`~optplan.problem.OptProblem` on
the shared B-spline core (:func:`optplan.tasks.segment_problem`; user terms through
``PipelineOptions.segment_terms``; docs/decisions/0021-pipeline-on-the-shared-core.md and
0023-one-stack.md). The policy's operations — activate pairs along knot configurations, raise
margins where a solution cut a corner, the first guess's knots, the geometry without plane rows —
are one function each here, through the problem's public API."""
from __future__ import annotations

import numpy as np

from .model.robot import RobotModel
from .problem import ClosedChain, CollisionAvoidance, OptProblem
from .problem.solution import Solution
from .problem.terms import NumericTrajectory

__all__ = ["activate", "boost_and_activate", "guess_knots", "project_knots", "unmodelled_geometry"]


def _knot_trajectory(robot: RobotModel, Q: np.ndarray, T: float) -> NumericTrajectory:
    """Knot configurations ``Q`` ((N+1) × nj) over T [s] as a trajectory a collision term
    activates its pairs along (:meth:`CollisionAvoidance.with_activation`)."""
    Q = np.asarray(Q, float)
    return NumericTrajectory(robot, Q, Q, Q, Q[:-1], T)


def activate(prob: OptProblem, knots: list[np.ndarray], T: float) -> None:
    """Also activate the collision pairs that come close along each of ``knots`` (this grid's
    knot configurations [rad], e.g. solutions coal found colliding; T [s])."""
    if not knots:
        return
    h = prob.terms["collision"]
    assert isinstance(h.term, CollisionAvoidance)   # segment_problem's collision term
    prob.replace_term(h, h.term.with_activation(*[_knot_trajectory(prob.robot, Q, T) for Q in knots]))


def boost_and_activate(prob: OptProblem, sol: Solution, t: np.ndarray, T: float, restart: bool = False) -> bool:
    """After coal found ``sol`` in contact: the margin raised where it cut a corner between knots
    (on the pairs the solved NLP had rows for; ``t`` [s]: its dense sample times) and the pairs
    close along it activated.

    ``restart`` (``PipelineOptions.collision_warm_start``): the next solve starts from ``sol``'s
    control points (a converged solve of this build of ``prob``) instead of the first guess, its
    rows planned as before (along the first guess) and their plane offsets where they are planned.
    Returns whether it does (False: ``sol`` is not a solution of this build; the first guess then
    stays). The solution is verified by coal afterwards as any other."""
    spline = prob._spline   # the B-spline backend (the build's variables: control points, plane offsets)
    core = spline.core
    along = None
    if restart and core is not None and sol.x is not None and np.size(sol.x) == core.nx:
        along = np.array(sol.x[:core.x_aux], float)
    q = sol.sample(t)["q"]
    h = prob.terms["collision"]
    assert isinstance(h.term, CollisionAvoidance)   # segment_problem's collision term
    col, _ = h.term.with_boost(prob.term_data(h), t, q, sol.t)
    prob.replace_term(h, col.with_activation(_knot_trajectory(prob.robot, sol.q, T)))
    if along is None:
        return False
    spline.prepare()   # the new build's rows, as the next solve would plan them
    assert spline.core is not None
    if along.size != spline.core.x_aux:
        return False
    spline.x0 = np.r_[along, spline.aux0]
    return True


def guess_knots(prob: OptProblem) -> np.ndarray:
    """Knot configurations ((N+1) × nj) [rad] of the problem's first guess."""
    x0 = prob.initial_guess
    assert x0 is not None   # the pipeline sets a guess when it builds a problem
    return np.asarray(prob.tp.unpack(x0)["q"], float)


def unmodelled_geometry(prob: OptProblem) -> list[int]:
    """The robot's collision geometries the plane rows have no model for (cylinders, meshes)."""
    model = prob.term_data("collision").info.get("model")
    return [] if model is None else [g for g, shape in model.robot_shape.items() if shape is None]


def project_knots(robot: RobotModel, Q: np.ndarray, cc: ClosedChain | None) -> np.ndarray:
    """The interior knots of ``Q`` projected onto the closed chain ``cc`` (None: ``Q`` as it is)."""
    if cc is None:
        return Q
    from .constraints.closed_chain import project_closed_chain

    Q = np.array(Q, float)
    data = robot.model.createData()
    for k in range(1, len(Q) - 1):
        Q[k] = project_closed_chain(robot, Q[k], cc, data=data).q
    return Q
