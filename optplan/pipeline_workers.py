"""The pipeline's segment workers: how many processes optimize a plan's segments, the early fork
that prepares a worker while the plan is made, and the hand-out of the segment NLPs to them.

The optimization stack (:mod:`optplan.problem`, the NLP modules, IPOPT; no SciPy)
is not imported by the planning modules. With ``PipelineOptions.early_worker`` the segment worker is
forked before planning and imports it (:func:`warm_worker`) while this process plans; otherwise this
process imports it just before the segments are sent, so that a worker forked then inherits it.
Which process solves a segment changes no result (:mod:`optplan.workers`).
"""
from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .workers import default_workers, run_jobs, send_early, start_workers, workers_started

if TYPE_CHECKING:
    from .model.robot import RobotModel
    from .pipeline_options import PipelineOptions
    from .scene import Scene

__all__ = ["segment_cost", "segment_workers", "send_if_longest", "send_segment_early", "start_early_worker",
           "solve_segments", "warm_worker"]


def segment_workers(opts: PipelineOptions) -> int:
    """Processes for the segments [count]: ``opts.workers`` (None: :func:`~optplan.workers.default_workers`)."""
    return opts.workers if opts.workers is not None else default_workers()


def _a_core_is_free() -> bool:
    """Does the 1-minute load average leave one of this process's CPUs free?"""
    try:
        return os.getloadavg()[0] <= len(os.sched_getaffinity(0)) - 1.0
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return False


def _import_optimization_stack() -> None:
    """Import what a segment's optimization needs (optplan.problem, the NLP modules) and load IPOPT."""
    import casadi

    from . import segment_nlp, tasks  # noqa: F401 - imported for their import time
    from .problem import nlp  # noqa: F401

    casadi.load_nlpsol("ipopt")


def warm_worker(robot: RobotModel, scene: Scene) -> None:
    """In a segment worker forked before planning (:func:`optplan.workers.start_workers`,
    ``PipelineOptions.early_worker``): import the optimization stack and load IPOPT while the parent
    process plans, so that the first segment's NLP is built without that wait. Changes no result."""
    _import_optimization_stack()


def start_early_worker(robot: RobotModel, scene: Scene, opts: PipelineOptions) -> bool:
    """Before planning: fork the segment worker now (``opts.early_worker``; None: when the load average
    leaves a core free) to run :func:`warm_worker` while this process plans. Only for the B-spline
    transcription (the one whose segments go to workers). The jobs find that worker by the same robot
    and scene objects (:func:`solve_segments`). Returns whether a worker was started."""
    n = segment_workers(opts)
    if opts.transcription != "bspline" or n < 2:   # one process: the segments are solved here, no fork
        return False
    early = opts.early_worker if opts.early_worker is not None else _a_core_is_free()
    return start_workers((robot, scene), n, warm_worker) if early else False


def send_segment_early(robot: RobotModel, scene: Scene, fn: Callable[..., Any], job: tuple[Any, ...],
                       opts: PipelineOptions) -> Any:
    """Send one segment (the plan's longest, known before the others are shortcut) to the worker
    started before planning, now: it starts while this process shortcuts the rest. The future for
    :func:`solve_segments`' ``early``, or None (no such worker; the segment goes with the others)."""
    return send_early((robot, scene), segment_workers(opts), fn, job)


def segment_cost(path: np.ndarray, kind: str) -> float:
    """The estimate by which the segments are handed out, longest first: the path's joint-space
    length (L1) [rad], three times for a constrained segment (its closed-chain rows)."""
    return float(np.abs(np.diff(path, axis=0)).sum()) * (3.0 if kind == "constrained" else 1.0) if len(path) > 1 else 0.0


def send_if_longest(robot: RobotModel, scene: Scene, fn: Callable[..., Any], jobs: Sequence[tuple[Any, ...]],
                    later: Sequence[tuple[np.ndarray, str]], extra: tuple[Any, ...], opts: PipelineOptions
                    ) -> dict[int, Any]:
    """While the segments are shortcut one by one: send the one just shortcut, ``jobs[-1]`` = (path,
    kind, arm), to the worker started before planning (:func:`send_segment_early`, with the further
    arguments ``extra``) when it is a constrained segment longer than every other can be — the jobs
    before it, and ``later``'s (path, kind) as they are before their shortcut. The worker would take it
    first anyway; the results do not depend on it. ``{its index: future}``, or {} (not sent)."""
    path, kind, arm = jobs[-1]
    if opts.transcription != "bspline" or kind != "constrained":
        return {}
    others = [segment_cost(p, k) for p, k, *_ in jobs[:-1]] + [segment_cost(p, k) for p, k in later]
    if segment_cost(path, kind) <= max(others, default=0.0):
        return {}
    fut = send_segment_early(robot, scene, fn, (path, kind, arm, *extra), opts)
    return {len(jobs) - 1: fut} if fut is not None else {}


def solve_segments(robot: RobotModel, scene: Scene, fn: Callable[..., Any], jobs: Sequence[tuple[Any, ...]],
                   cost: Sequence[float], opts: PipelineOptions, early: dict[int, Any] | None = None
                   ) -> tuple[list[Any], float]:
    """``[fn(robot, scene, *job) for job in jobs]`` in this process and the segment workers
    (:func:`optplan.workers.run_jobs`, longest ``cost`` first; ``early``: jobs sent already,
    :func:`send_segment_early`); returns the results in job order and the CPU time [s] the workers
    spent. A worker not started before planning is forked now, after this process imported the
    optimization stack, so it inherits it."""
    workers = segment_workers(opts)
    if not early and not workers_started((robot, scene), min(workers, len(jobs))):
        _import_optimization_stack()
    return run_jobs((robot, scene), fn, jobs, cost, workers, early=early)
