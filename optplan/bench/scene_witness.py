"""Witnesses of generated scenes: a scene counts as feasible only with a certified path of the robot.

A *witness* of a generated scene is a path of the dual arm for the benchmark's query on that scene
(trial 0 of :class:`optplan.trials.TrialGenerator` with the benchmark's base seed: the same start and
goal configurations the planners under test get), planned by an independent search — TCBiRRT, variant
``improved``, with its own seed stream (not the trial's planner seed) and a budget several times the
benchmark's — and then certified independently of the planner: the closed-chain residual (Pinocchio
forward kinematics) at every held configuration at most :data:`MAX_RESIDUAL_M`, and every edge
collision-free by exact coal distances checked so densely that no point of the robot or the object
moves more than ``sweep`` [m] between checks (:func:`optplan.bench.tcbirrt._path_checks`).

A scene without a certified witness is rejected by the generator. A TCBiRRT witness biases the kept
scenes towards those TCBiRRT solves; a CBiRRT2 witness is a different algorithm (another search space,
no regrasps), so the scenes it certifies are not selected by the planner under test. The generator can
run both and keeps a scene that either certifies, recording which did.

This is a sufficient condition of feasibility, not a necessary one: a scene the witness search does not solve in its budget may be
feasible and is rejected all the same (the rejections are counted per family and reported).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import OptionError

__all__ = ["Witness", "WITNESS_PLANNERS", "WITNESS_TIME_LIMIT", "MAX_RESIDUAL_M", "check_witness_planners",
           "witness_planner", "plan_witness", "certify_witness", "save_witness",
           "load_witness"]

#: CPU budget of the witness search [s] (three times the benchmark's 10 s)
WITNESS_TIME_LIMIT = 30.0
#: planners that can search a witness: ``"tcbirrt"`` (improved variant) and ``"cbirrt2"`` (certified edges)
WITNESS_PLANNERS = ("tcbirrt", "cbirrt2")
#: largest closed-chain residual accepted at a held configuration of a witness [m]
MAX_RESIDUAL_M = 1e-3
#: largest motion of any point of the robot or the object between two collision checks of a witness edge [m]
WITNESS_SWEEP_M = 0.01


@dataclass(frozen=True)
class Witness:
    """A certified path: configurations [rad], which are held (closed chain), the planner's seed and
    CPU time [s], the certificate's figures (largest residual [m], swept tolerance [m]) and the planner
    that found it (one of :data:`WITNESS_PLANNERS`)."""

    path: np.ndarray
    constrained: np.ndarray
    seed: int
    cpu_time_s: float
    max_residual_m: float
    sweep_m: float
    planner: str = "tcbirrt"


def check_witness_planners(planners: object) -> tuple[str, ...]:
    """``planners`` (a comma-separated string or a sequence of names) as a tuple of distinct names of
    :data:`WITNESS_PLANNERS`; :class:`OptionError` otherwise."""
    names = [p.strip() for p in planners.split(",")] if isinstance(planners, str) else list(planners)  # type: ignore[call-overload]
    if not names or any(n not in WITNESS_PLANNERS for n in names) or len(set(names)) != len(names):
        raise OptionError(f"witness planners: expected distinct names among {WITNESS_PLANNERS}, got {planners!r}")
    return tuple(names)


def witness_planner(robot: Any, scene: Any, planner: str) -> Any:
    """The witness search ``planner`` (one of :data:`WITNESS_PLANNERS`) for ``robot`` on ``scene``."""
    from ..planners import make_planner

    check_witness_planners((planner,))
    if planner == "cbirrt2":   # its edges certified as it plans (the paper's 0.2 rad checks would graze)
        return make_planner("cbirrt2", robot, scene, certified_edges=True)
    return make_planner("tcbirrt", robot, scene, variant="improved")


def certify_witness(robot: Any, scene: Any, res: Any, sweep: float = WITNESS_SWEEP_M) -> tuple[str | None, dict]:
    """``(None, checks)`` when the plan result ``res`` is a certified path of ``scene`` (see the module
    docstring), else ``(why not, checks)``; ``checks`` as :func:`optplan.bench.tcbirrt._path_checks`."""
    from ..planners.validity import ValidityChecker
    from .tcbirrt import _path_checks

    if not res.success:
        return f"witness search: {res.status.value}", {}
    checks = _path_checks(robot, scene, ValidityChecker(robot, scene, kernel="coal"), res, sweep=sweep)
    if checks["max_closed_chain_residual"] > MAX_RESIDUAL_M:
        return f"witness closed-chain residual {checks['max_closed_chain_residual']:.2e} m > {MAX_RESIDUAL_M:g} m", checks
    if checks["swept_invalid_edges"]:
        return f"witness: {checks['swept_invalid_edges']} edges in collision (exact, {sweep:g} m sweep)", checks
    return None, checks


def plan_witness(robot: Any, scene: Any, trial_seed: int, seed: int,
                 time_limit: float = WITNESS_TIME_LIMIT, planner: str = "tcbirrt") -> tuple[Witness | None, str | None]:
    """Plan and certify a witness of ``scene`` for trial 0 of base seed ``trial_seed``, the search
    (``planner``, one of :data:`WITNESS_PLANNERS`) seeded by ``seed`` within ``time_limit`` CPU seconds:
    ``(witness, None)`` or ``(None, why not)``."""
    from ..errors import UnreachableError
    from ..trials import TrialGenerator

    if not (isinstance(time_limit, (int, float)) and np.isfinite(time_limit) and time_limit > 0):
        raise OptionError(f"witness time_limit: expected a number of seconds > 0, got {time_limit!r}")
    try:
        trial = TrialGenerator(robot, scene).generate(0, int(trial_seed))
    except (UnreachableError, RuntimeError) as exc:
        return None, f"no trial: {exc}"
    search = witness_planner(robot, scene, planner)
    res = search.plan(trial.q_start, trial.q_goal, time_limit=float(time_limit), seed=int(seed), clock="cpu")
    why, checks = certify_witness(robot, scene, res)
    if why is not None:
        return None, why
    return Witness(np.asarray(res.path, float), np.asarray(res.constrained, bool), int(seed),
                   float(res.stats.get("cpu_time_s", 0.0)), float(checks["max_closed_chain_residual"]),
                   WITNESS_SWEEP_M, planner), None


def save_witness(w: Witness, path: str | Path) -> None:
    """Write ``w`` as an ``.npz`` (path [rad], constrained flags, seed, CPU seconds, planner)."""
    np.savez_compressed(path, path=w.path, constrained=w.constrained, seed=w.seed, cpu_time_s=w.cpu_time_s,
                        max_residual_m=w.max_residual_m, sweep_m=w.sweep_m, planner=w.planner)


def load_witness(path: str | Path) -> Witness:
    """Read a witness written by :func:`save_witness`."""
    d = np.load(path)
    return Witness(d["path"], d["constrained"], int(d["seed"]), float(d["cpu_time_s"]), float(d["max_residual_m"]),
                   float(d["sweep_m"]), str(d["planner"]) if "planner" in d.files else "tcbirrt")
