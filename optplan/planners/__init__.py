"""Sampling planners for closed-chain dual-arm motion behind one interface.

Every planner is built for a robot and a scene and answers ``plan(q_start, q_goal, time_limit=,
seed=, clock=)`` with a :class:`PlanResult` (status, path, per-configuration object poses and
closed-chain flags, segments, stats) — see :mod:`optplan.planners.base`.

* :class:`TCBiRRT` — the TCBiRRT paper's task-space constrained bidirectional RRT with regrasp;
* :class:`CBiRRT2` — joint-space constrained BiRRT with Newton-Raphson projection;
* :class:`~optplan.planners.constrained_prm.ConstrainedPRM` — a roadmap of object-pose samples solved by IK,
  joined by a projection-based constrained local planner;
* :class:`~optplan.planners.precomputed_graph.PrecomputedGraph` — CBiRRT2 drawing its targets from 10,000
  precomputed on-manifold configurations of the scene (cached on disk);
* :mod:`optplan.planners.learned` — the learned baselines (CVAE latent sampling, LCBiRRT, LCBiRRT-LPO; optional
  extra ``learned``);
* :class:`RRTConnect` — unconstrained joint-space RRTConnect (no object; also the regrasp planner);
* :class:`~optplan.planners.ompl_peers.OMPLPeer` — OMPL's Projected / Atlas / TangentBundle state
  spaces with RRTConnect, BKPIECE1, ... (needs ``pip install ompl``).

``make_planner(name, robot, scene, **options)`` builds one by name ("tcbirrt", "cbirrt2",
"rrtconnect", "ompl-atlas", "ompl-projected-bkpiece1", ...).
"""
from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from ..errors import OptionError
from .base import PathSegment, Planner, PlanResult, PlanStatus
from .cbirrt2 import CBiRRT2, CBiRRT2Options
from .rrtconnect import RRTConnect, RRTConnectOptions
from .tcbirrt import TCBiRRT, TCBiRRTOptions
from .validity import ValidityChecker

if TYPE_CHECKING:
    from ..constraints.closed_chain import ClosedChainKinematics
    from ..model.robot import RobotModel

__all__ = [
    "check_planner_options", "CBiRRT2", "CBiRRT2Options", "PathSegment", "PlanResult", "PlanStatus", "Planner", "RRTConnect",
    "RRTConnectOptions", "TCBiRRT", "TCBiRRTOptions", "ValidityChecker", "make_planner", "planner_names",
]

#: names this package used to export, now imported from the module that defines them
_MOVED = {"CLOCKS": "optplan.planners.base", "Deadline": "optplan.planners.base",
          "ClosedChainKinematics": "optplan.constraints.closed_chain",
          "IKSettings": "optplan.constraints.closed_chain", "closure_error": "optplan.constraints.closed_chain",
          "rrt_connect": "optplan.planners.rrtconnect", "shortcut_path": "optplan.planners.rrtconnect",
          "exp_coordinates": "optplan.planners.tcbirrt", "interpolate_task": "optplan.planners.tcbirrt"}


def __getattr__(name: str) -> Any:
    if name in _MOVED:
        from .._compat import moved

        return moved(__name__, name, _MOVED[name])
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: the learned baselines of :mod:`optplan.planners.learned` (optional extra ``learned``)
LEARNED_PLANNERS = ("latent-sampling", "lcbirrt", "lcbirrt-lpo")
#: the seven planners of the TCBiRRT paper's comparison (Tables 2-3), in its order
PAPER_PLANNERS = ("cbirrt2", "precomputed-graph", "constrained-prm", *LEARNED_PLANNERS, "tcbirrt")


def planner_names() -> list[str]:
    """Names accepted by :func:`make_planner` (OMPL: ``ompl-<projected|atlas|tb>[-<planner>]``)."""
    return ["tcbirrt", "cbirrt2", "constrained-prm", "precomputed-graph", *LEARNED_PLANNERS, "rrtconnect", "ompl-projected", "ompl-atlas", "ompl-tb",
            "ompl-projected-bkpiece1", "ompl-atlas-bkpiece1", "ompl-projected-kpiece1"]


def check_planner_options(name: str, **options: Any) -> None:
    """Raise :class:`~optplan.errors.OptionError` when ``options`` are not valid fields and values
    of planner ``name``'s options dataclass (checked without a robot, e.g. before a benchmark
    starts its workers); OMPL peers' options are checked when they are built."""
    key = str(name).lower()
    cls = {"tcbirrt": TCBiRRTOptions, "cbirrt2": CBiRRT2Options, "rrtconnect": RRTConnectOptions}.get(key)
    if cls is None:
        return
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise OptionError(f"planner {name!r}: unknown option(s) {', '.join(unknown)}; "
                          f"{cls.__name__} has: {', '.join(sorted(known))}")
    try:
        cls(**options)
    except OptionError:
        raise
    except (TypeError, ValueError) as exc:
        raise OptionError(f"planner {name!r}: {exc}") from None


def make_planner(name: str, robot: RobotModel, scene: Any, *, checker: ValidityChecker | None = None,
                 kinematics: ClosedChainKinematics | None = None, **options: Any) -> Planner:
    """Build a planner by name; ``options`` are the fields of its options dataclass (another name
    is an :class:`~optplan.errors.OptionError` listing the planner's options).
    ``checker``/``kinematics`` may be shared between planners of the same robot and scene."""
    key = name.lower()
    cls: Any = {"tcbirrt": TCBiRRTOptions, "cbirrt2": CBiRRT2Options, "rrtconnect": RRTConnectOptions}.get(key)
    if key == "constrained-prm":   # imported for these planners only (their modules load the manifold samples)
        from .constrained_prm import ConstrainedPRMOptions as cls
    elif key == "precomputed-graph":
        from .precomputed_graph import PrecomputedGraphOptions as cls
    if cls is not None:
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise OptionError(f"make_planner({name!r}): unknown option(s) {', '.join(unknown)}; "
                              f"{cls.__name__} has: {', '.join(sorted(known))}")
    if key == "tcbirrt":
        return TCBiRRT(robot, scene, TCBiRRTOptions(**options), checker=checker, kinematics=kinematics)
    if key == "cbirrt2":
        return CBiRRT2(robot, scene, CBiRRT2Options(**options), checker=checker, kinematics=kinematics)
    if key == "rrtconnect":
        return RRTConnect(robot, scene, RRTConnectOptions(**options), checker=checker)
    if key == "constrained-prm":
        from .constrained_prm import ConstrainedPRM

        return ConstrainedPRM(robot, scene, cls(**options), checker=checker, kinematics=kinematics)
    if key == "precomputed-graph":
        from .precomputed_graph import PrecomputedGraph

        return PrecomputedGraph(robot, scene, cls(**options), checker=checker, kinematics=kinematics)
    if key in LEARNED_PLANNERS:
        from .learned import make_learned_planner

        return make_learned_planner(key, robot, scene, checker=checker, kinematics=kinematics, **options)
    if key.startswith("ompl-"):
        from .ompl_peers import make_ompl_peer

        return make_ompl_peer(key, robot, scene, checker=checker, kinematics=kinematics, **options)
    raise ValueError(f"unknown planner {name!r}; known: {', '.join(planner_names())}")
