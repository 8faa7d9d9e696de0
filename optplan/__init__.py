"""optplan — motion planning and trajectory optimization for dual-arm space robots.

Robots from URDF into Pinocchio (fixed or free-floating base), exact collision distances with coal,
CasADi mirrors of the kinematics for IPOPT trajectory NLPs, and sampling planners that warm-start
them. Start with :class:`optplan.RobotModel`, a :class:`optplan.Scene`, then either
:func:`optplan.run_pipeline` (sampler → optimizer → verified trajectory) or an
:class:`optplan.OptProblem` of your own terms.

Layers (each imports only the ones below it; see docs/architecture.md): ``geometry`` → ``model``
→ ``constraints``, ``collision``, ``scene`` → ``problem``, ``planners`` → ``tasks``, ``verify``,
``pipeline`` → ``cli``; the paper reproductions (``optplan.papers.<key>``) and the benchmarks
(``optplan.bench``) sit on top and are never imported by the library.

The names below are loaded on first use (``import optplan`` stays cheap).
"""
from __future__ import annotations

import importlib

from . import _compat

_compat.install()

__version__ = "0.1.0"

#: public name → module that defines it
_EXPORTS = {
    # errors
    "OptplanError": "errors", "ConfigurationError": "errors", "ModelError": "errors",
    "UnknownNameError": "errors", "OptionError": "errors",
    # robot models and kinematics
    "RobotModel": "model.robot", "Arm": "model.robot",
    "Kinematics": "model.kinematics", "SymbolicKinematics": "model.symbolic",
    "simulate_base": "model.floating", "FloatingResult": "model.floating",
    "IKOptions": "model.ik", "IKResult": "model.ik", "solve_arm_ik": "model.ik",
    # scene, collision, closed chain
    "Scene": "scene", "CollisionChecker": "collision.checker",
    "solve_grasp_ik": "constraints.closed_chain", "project_closed_chain": "constraints.closed_chain",
    "closure_error": "constraints.closed_chain",
    # trajectory optimization
    "OptProblem": "problem", "TermHandle": "problem", "Solution": "problem", "IpoptStatus": "problem",
    "SolverOptions": "problem", "Infeasibility": "problem", "Term": "problem",
    "JointBoundary": "problem", "JointPositionLimits": "problem", "JointVelocityLimits": "problem",
    "JointAccelerationLimits": "problem", "FramePose": "problem", "FramePath": "problem",
    "ClosedChain": "problem", "CollisionAvoidance": "problem", "OrientationConstraint": "problem",
    "BaseAttitude": "problem", "Smoothness": "problem", "PathLength": "problem", "Duration": "problem",
    "JointTorqueLimits": "problem", "TorqueCost": "problem", "GuaranteeOptions": "problem",
    "SymbolicDynamics": "model.dynamics",
    "verify": "verification", "VerifyReport": "verification",
    # planners
    "make_planner": "planners", "planner_names": "planners", "Planner": "planners",
    "PlanResult": "planners", "PlanStatus": "planners",
    # the pipeline
    "run_pipeline": "pipeline", "PipelineOptions": "pipeline", "PipelineResult": "pipeline",
}

__all__ = sorted(_EXPORTS) + ["__version__"]

# modules that moved (optplan.robot, ...): still reachable as attributes after ``import optplan``
_OLD_SUBMODULES = {k.split(".", 1)[1] for k in _compat.MOVED_MODULES if k.count(".") == 1}


def __getattr__(name: str):
    mod = _EXPORTS.get(name)
    if mod is not None:
        value = getattr(importlib.import_module(f"{__name__}.{mod}"), name)
        globals()[name] = value
        return value
    if name in _OLD_SUBMODULES and name not in _EXPORTS:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
