"""The object's lead path inside a TCBiRRT query (the improved variant's ``guide_probability``).

While no lead path is known, every 25 iterations the search runs one attempt of
:func:`~.task_sampling.object_lead_path` (the object alone, from the start's pose to the goal's) and, once one
is found, draws ξ_rand near it. An attempt ends at its work budget ``guide_attempt_iterations`` (the lead
path's RRT-Connect iterations) and the attempts of a query at ``guide_iterations`` — counts, so the same seed
runs the same attempts on any machine and load; ``guide_attempt_time`` and ``guide_time_limit`` [s] are
backstops (docs/planners.md, "Reproducible searches"). What a query has spent is kept across the restarts of
its search (:class:`LeadState`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from .task_sampling import ObjectPoseFilter, TaskSampler, object_lead_path

if TYPE_CHECKING:
    from .base import Deadline
    from .tcbirrt import TCBiRRT

__all__ = ["LeadState", "lead_attempt"]

#: the work budget of an attempt without one: a count never reached, so that its iterations are still counted
_NEVER = 1e15


@dataclass
class LeadState:
    """A query's lead path (None until found) and what its attempts have spent: seconds (of the query's clock)
    and iterations [count]."""

    path: np.ndarray | None = None
    seconds: float = 0.0
    iterations: float = 0.0

    def budget_left(self, pl: TCBiRRT) -> bool:
        o = pl.options
        return self.seconds < o.guide_time_limit and (not o.guide_iterations or self.iterations < o.guide_iterations)


def lead_attempt(pl: TCBiRRT, sampler: TaskSampler | Any, lead: LeadState, xi_start: np.ndarray, xi_goal: np.ndarray,
                 rng: np.random.Generator, deadline: Deadline, st: dict[str, Any]) -> None:
    """One attempt at the lead path from ``xi_start`` to ``xi_goal`` within what is left of the query's lead-path
    budgets; sets ``sampler.guide`` and updates ``lead`` and the counters ``guide_attempts``, ``guide_waypoints``,
    ``guide_time_s`` and ``guide_iterations``."""
    o = pl.options
    work = min(o.guide_attempt_iterations or _NEVER, (o.guide_iterations or _NEVER) - lead.iterations)
    sub = deadline.sub(min(o.guide_attempt_time, o.guide_time_limit - lead.seconds), work)
    w0 = sub.work
    sampler.guide = object_lead_path(cast(ObjectPoseFilter, pl._filter), xi_start, xi_goal, pl._lo, pl._hi, rng, sub,
                                     native_rng=pl._nrng)
    dt = sub.elapsed()
    used = w0 - sub.work
    lead.path, lead.seconds, lead.iterations = sampler.guide, lead.seconds + dt, lead.iterations + used
    st["guide_attempts"] += 1
    st["guide_waypoints"] = 0 if sampler.guide is None else len(sampler.guide)
    st["guide_time_s"] = st.get("guide_time_s", 0.0) + dt
    st["guide_iterations"] = st.get("guide_iterations", 0) + int(used)
