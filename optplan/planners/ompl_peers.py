"""Peers from OMPL (PyPI ``ompl`` 2.x, optional): constrained planning on the same closed-chain
constraint and the same collision checker as optplan's own planners.

* state space: ``ProjectedStateSpace`` (Newton projection), ``AtlasStateSpace`` (atlas of
  tangent charts) or ``TangentBundleStateSpace`` (lazy tangent bundle) over the 14 joints;
* constraint: h(q) of the TCBiRRT paper Eq. 1-2 (``ClosedChainKinematics.h`` / ``h_jacobian``, compiled C),
  tolerance ``tolerance``;
* validity: :class:`~optplan.planners.validity.ValidityChecker` (object held);
* planner: RRTConnect (the default), BKPIECE1, KPIECE1, RRT or PRM.

What works (see docs/decisions/0001-tcbirrt-benchmark-ssps-scenes.md): Projected + RRTConnect practically never extends in the full ±270° joint
box; Atlas + RRTConnect extends but slowly; Projected + BKPIECE1 with range ≈ 0.3 rad is the
strongest general configuration we found. Every configuration is available by name
(:func:`make_ompl_peer`), e.g. ``"ompl-atlas"`` (Atlas + RRTConnect), ``"ompl-projected-bkpiece1"``.

Returned paths are re-checked (``path.check()``, then after ``path.interpolate()`` every state is
validated again with our checker and the closed-chain residual): a path that fails is reported as
``FAILED`` (message says why), never as a success.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..constraints.closed_chain import ClosedChainKinematics, closure_error
from ..errors import ConfigurationError
from .base import Deadline, PathSegment, Planner, PlanResult, PlanStatus
from .validity import ValidityChecker

__all__ = ["OMPLPeerOptions", "OMPLPeer", "make_ompl_peer", "ompl_available", "SPACES", "PLANNERS"]
log = logging.getLogger(__name__)

SPACES = ("projected", "atlas", "tangent_bundle")
_OMPL_SEEDED = False
PLANNERS = ("rrtconnect", "bkpiece1", "kpiece1", "rrt", "prm")


def ompl_available() -> bool:
    try:
        import ompl  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class OMPLPeerOptions:
    """Options of the OMPL constrained-planning peers."""

    #: Constrained state space, one of :data:`SPACES`.
    space: str = "atlas"
    #: OMPL planner, one of :data:`PLANNERS`.
    planner: str = "rrtconnect"
    #: Extension range of the tree planners [rad] (None: 0.3 for the projected space, ρ_s of the atlas / tangent
    #: bundle).
    range: float | None = None
    #: Tolerance of the constraint, max |h| [m or rad per row].
    tolerance: float = 1e-6
    #: Manifold traversal step [rad] (OMPL's default 0.05).
    delta: float = 0.05
    #: Newton iterations of one projection [count].
    max_projection_iterations: int = 50
    #: Run OMPL's path simplifier on the solution.
    simplify: bool = False
    #: Clearance counted as contact [m].
    margin: float = 0.0
    #: Constraint residual allowed on the returned, interpolated path [m or rad per row].
    recheck_tolerance: float = 1e-4

    def __post_init__(self) -> None:
        if self.space not in SPACES:
            raise ValueError(f"OMPLPeerOptions.space: expected one of {SPACES}, got {self.space!r}")
        if self.planner not in PLANNERS:
            raise ValueError(f"OMPLPeerOptions.planner: expected one of {PLANNERS}, got {self.planner!r}")
        for name in ("tolerance", "delta", "recheck_tolerance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"OMPLPeerOptions.{name}: expected a positive number, got {v!r}")
        if self.range is not None and not (isinstance(self.range, (int, float)) and self.range > 0):
            raise ValueError(f"OMPLPeerOptions.range: expected a positive number or None, got {self.range!r}")
        if not (isinstance(self.max_projection_iterations, int) and self.max_projection_iterations >= 1):
            raise ValueError("OMPLPeerOptions.max_projection_iterations: expected an int >= 1")
        if not (isinstance(self.margin, (int, float)) and self.margin >= 0):
            raise ValueError(f"OMPLPeerOptions.margin: expected a number >= 0 m, got {self.margin!r}")


def make_ompl_peer(name: str, robot: Any, scene: Any, *, checker: ValidityChecker | None = None,
                   kinematics: ClosedChainKinematics | None = None, constraint: Any = None,
                   **kw: Any) -> OMPLPeer:
    """``"ompl-<space>[-<planner>]"`` → :class:`OMPLPeer` (planner defaults to RRTConnect);
    ``space`` ∈ projected, atlas, tb (tangent bundle)."""
    parts = name.lower().split("-")
    if len(parts) < 2 or parts[0] != "ompl":
        raise ValueError(f"OMPL peer name: expected 'ompl-<space>[-<planner>]', got {name!r}")
    space = {"projected": "projected", "proj": "projected", "atlas": "atlas", "tb": "tangent_bundle",
             "tangent_bundle": "tangent_bundle"}.get(parts[1])
    if space is None:
        raise ValueError(f"OMPL peer {name!r}: unknown space {parts[1]!r} (projected, atlas, tb)")
    planner = parts[2] if len(parts) > 2 else "rrtconnect"
    planner = {"bkpiece": "bkpiece1", "kpiece": "kpiece1"}.get(planner, planner)
    opts = OMPLPeerOptions(space=space, planner=planner, **kw)
    return OMPLPeer(robot, scene, opts, name=name, checker=checker, kinematics=kinematics, constraint=constraint)


class OMPLPeer(Planner):
    """An OMPL constrained planner behind optplan's :class:`Planner` interface.

    Seeding: OMPL's global seed can be set once per process, before the first sampler exists
    (``ou.RNG.setSeed``; later calls have no effect), and ``RNG.setLocalSeed`` only seeds one RNG
    instance, not the planners' own. So the first query of a process is seeded with its ``seed``;
    later queries continue that process's random stream: OMPL results are NOT reproducible per
    query (unlike optplan's planners), and the ``seed`` in their stats is informational.
    """

    name = "ompl"

    def __init__(self, robot: Any, scene: Any, options: OMPLPeerOptions | None = None, *, name: str | None = None,
                 checker: ValidityChecker | None = None, kinematics: ClosedChainKinematics | None = None,
                 constraint: Any = None) -> None:
        super().__init__(robot, scene)
        if constraint is None and (scene is None or scene.object is None or len(scene.object.grasps) != 2):
            raise ConfigurationError("OMPL peers need a scene with an [object] grasped by two arms, or a constraint "
                                     "(an object with h(q), h_jacobian(q) and dim)")
        try:
            from ompl import base as ob
            from ompl import geometric as og
            from ompl import util as ou
        except ImportError as exc:
            raise ImportError("the OMPL peers need the `ompl` package: pip install ompl") from exc
        self._ob, self._og, self._ou = ob, og, ou
        ou.setLogLevel(ou.LOG_NONE)
        self.options = options or OMPLPeerOptions()
        self.name = name or f"ompl-{self.options.space}-{self.options.planner}"
        self.checker = checker or ValidityChecker(robot, scene, margin=self.options.margin)
        self.constraint = constraint
        if constraint is None:
            self.kin = kinematics or ClosedChainKinematics(robot, scene.object.grasps)
            self.grasps = scene.object.grasps
        else:
            self.kin, self.grasps = constraint, None

    def _residual(self, q: np.ndarray) -> float:
        if self.constraint is None:
            return max(closure_error(self.robot, self.grasps, q))
        return float(np.abs(self.constraint.h(q)).max())

    def _constraint(self, counters: dict[str, int]) -> Any:
        ob, kin, nq = self._ob, self.kin, self.robot.nq
        o = self.options
        dim = 6 if self.constraint is None else int(self.constraint.dim)

        class _ClosedChain(ob.Constraint):  # type: ignore[misc,name-defined]  # OMPL's class, known at run time only
            def __init__(self) -> None:
                super().__init__(nq, dim, o.tolerance)
                self.setMaxIterations(o.max_projection_iterations)

            def function(self, x: Any, out: Any) -> None:
                counters["constraint_calls"] += 1
                out[:] = kin.h(x)

            def jacobian(self, x: Any, out: Any) -> None:
                counters["jacobian_calls"] += 1
                out[:, :] = kin.h_jacobian(x)[1]

        return _ClosedChain()

    def _plan(self, q_start: np.ndarray, q_goal: np.ndarray, deadline: Deadline, rng: np.random.Generator,
              seed: int) -> PlanResult:
        ob, og, ou = self._ob, self._og, self._ou
        o, ck, nq = self.options, self.checker, self.robot.nq
        st: dict[str, Any] = {"constraint_calls": 0, "jacobian_calls": 0, "validity_calls": 0}
        for which, q, status in (("start", q_start, PlanStatus.INVALID_START), ("goal", q_goal, PlanStatus.INVALID_GOAL)):
            if not ck.in_limits(q) or not ck.is_valid(q) or self._residual(q) > max(o.tolerance, 1e-6):
                return self.empty_result(status, f"{which} out of limits, in collision or off the manifold", **st)
        global _OMPL_SEEDED
        if not _OMPL_SEEDED:
            ou.RNG.setSeed(int(seed) % (2 ** 31 - 1) + 1)
            _OMPL_SEEDED = True
            st["ompl_global_seed"] = int(seed) % (2 ** 31 - 1) + 1
        rvss = ob.RealVectorStateSpace(nq)
        bounds = ob.RealVectorBounds(nq)
        for i in range(nq):
            bounds.setLow(i, float(self.robot.lower[i]))
            bounds.setHigh(i, float(self.robot.upper[i]))
        rvss.setBounds(bounds)
        constraint = self._constraint(st)
        if o.space == "projected":
            css = ob.ProjectedStateSpace(rvss, constraint)
            csi = ob.ConstrainedSpaceInformation(css)
        elif o.space == "atlas":
            css = ob.AtlasStateSpace(rvss, constraint)
            csi = ob.ConstrainedSpaceInformation(css)
        else:
            css = ob.TangentBundleStateSpace(rvss, constraint)
            csi = ob.TangentBundleSpaceInformation(css)
        css.setDelta(o.delta)
        valid_fn = ck.is_valid

        def valid(state: Any) -> bool:
            st["validity_calls"] += 1
            return valid_fn(np.fromiter((state[i] for i in range(nq)), float, nq))

        ss = og.SimpleSetup(csi)
        ss.setStateValidityChecker(valid)
        s0, s1 = csi.allocState(), csi.allocState()
        s0.copy(q_start.tolist())
        s1.copy(q_goal.tolist())
        if o.space != "projected":
            css.anchorChart(s0)
            css.anchorChart(s1)
        ss.setStartAndGoalStates(s0, s1)
        planner = {"rrtconnect": og.RRTConnect, "bkpiece1": og.BKPIECE1, "kpiece1": og.KPIECE1,
                   "rrt": og.RRT, "prm": og.PRM}[o.planner](csi)
        if o.planner != "prm":
            rng_ = o.range if o.range is not None else (0.3 if o.space == "projected" else css.getRho_s())
            planner.setRange(float(rng_))
            st["range"] = float(rng_)
        ss.setPlanner(planner)
        ss.setup()
        ptc = ob.PlannerTerminationCondition(deadline.expired)
        status = ss.solve(ptc)
        exact = bool(ss.haveExactSolutionPath())
        st["ompl_status"] = str(status)
        if not exact:
            if deadline.expired():
                return self.empty_result(PlanStatus.TIMEOUT, "time limit reached", **st)
            return self.empty_result(PlanStatus.FAILED, f"OMPL: {status}", **st)
        path = ss.getSolutionPath()
        if o.simplify:
            ss.simplifySolution(max(deadline.remaining(), 0.01))
            path = ss.getSolutionPath()
        ok = bool(path.check())   # (checkAndRepair's return value is not convertible in ompl 2.0.1)
        st["path_check"] = ok
        path.interpolate()
        P = np.array([[path.getState(k)[i] for i in range(nq)] for k in range(path.getStateCount())])
        resid = max(self._residual(q) for q in P)
        bad = sum(1 for q in P if not ck.is_valid(q))
        st["max_closed_chain_residual"] = resid
        st["invalid_states"] = bad
        if not ok or bad or resid > o.recheck_tolerance:
            return self.empty_result(PlanStatus.FAILED, f"returned path fails re-validation (check={ok}, "
                                     f"{bad} invalid states, residual {resid:.1e})", **st)
        P[0], P[-1] = q_start, q_goal
        poses = [self.kin.object_pose(q) for q in P] if self.constraint is None else [None] * len(P)
        return PlanResult(PlanStatus.EXACT, self.name, P, poses, np.ones(len(P), bool),
                          [PathSegment("constrained", 0, len(P) - 1)], st)
