"""Sampling planners for closed-chain dual-arm motion behind one interface.

Every planner is built for a robot and a scene and answers ``plan(q_start, q_goal, time_limit=,
seed=, clock=)`` with a :class:`PlanResult` (status, path, per-configuration object poses and
closed-chain flags, segments, stats) — see :mod:`optplan.planners.base`.

* :class:`TCBiRRT` — the TCBiRRT paper's task-space constrained bidirectional RRT with regrasp;
* :class:`CBiRRT2` — joint-space constrained BiRRT with Newton-Raphson projection;
* :class:`RRTConnect` — unconstrained joint-space RRTConnect (no object; also the regrasp planner);
* :class:`~optplan.planners.ompl_peers.OMPLPeer` — OMPL's Projected / Atlas / TangentBundle state
  spaces with RRTConnect, BKPIECE1, ... (needs ``pip install ompl``).

``make_planner(name, robot, scene, **options)`` builds one by name ("tcbirrt", "cbirrt2",
"rrtconnect", "ompl-atlas", "ompl-projected-bkpiece1", ...).
"""
from __future__ import annotations

from .base import CLOCKS, Deadline, PathSegment, Planner, PlanResult, PlanStatus
from .cbirrt2 import CBiRRT2, CBiRRT2Options
from .closed_chain import ClosedChainKinematics, IKSettings, closure_error
from .rrtconnect import RRTConnect, RRTConnectOptions, rrt_connect, shortcut_path
from .tcbirrt import TCBiRRT, TCBiRRTOptions, exp_coordinates, interpolate_task
from .validity import ValidityChecker

__all__ = [
    "CBiRRT2", "CBiRRT2Options", "CLOCKS", "ClosedChainKinematics", "Deadline", "IKSettings", "PathSegment",
    "PlanResult", "PlanStatus", "Planner", "RRTConnect", "RRTConnectOptions", "TCBiRRT", "TCBiRRTOptions",
    "ValidityChecker", "closure_error", "exp_coordinates", "interpolate_task", "make_planner", "planner_names",
    "rrt_connect", "shortcut_path",
]


def planner_names() -> list[str]:
    """Names accepted by :func:`make_planner` (OMPL: ``ompl-<projected|atlas|tb>[-<planner>]``)."""
    return ["tcbirrt", "cbirrt2", "rrtconnect", "ompl-projected", "ompl-atlas", "ompl-tb",
            "ompl-projected-bkpiece1", "ompl-atlas-bkpiece1", "ompl-projected-kpiece1"]


def make_planner(name: str, robot, scene, *, checker: ValidityChecker | None = None,
                 kinematics: ClosedChainKinematics | None = None, **options) -> Planner:
    """Build a planner by name; ``options`` are the fields of its options dataclass.
    ``checker``/``kinematics`` may be shared between planners of the same robot and scene."""
    key = name.lower()
    if key == "tcbirrt":
        return TCBiRRT(robot, scene, TCBiRRTOptions(**options), checker=checker, kinematics=kinematics)
    if key == "cbirrt2":
        return CBiRRT2(robot, scene, CBiRRT2Options(**options), checker=checker, kinematics=kinematics)
    if key == "rrtconnect":
        return RRTConnect(robot, scene, RRTConnectOptions(**options), checker=checker)
    if key.startswith("ompl-"):
        from .ompl_peers import make_ompl_peer

        return make_ompl_peer(key, robot, scene, checker=checker, kinematics=kinematics, **options)
    raise ValueError(f"unknown planner {name!r}; known: {', '.join(planner_names())}")
