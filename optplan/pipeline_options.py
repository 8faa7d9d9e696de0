"""Options of :func:`optplan.pipeline.run_pipeline`: the planner and its options, the segment NLPs'
grids and margins, and the ordered retry policy's limits."""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .errors import OptionError

__all__ = ["PipelineOptions", "PLANNER_DEFAULTS", "check_segment_nlp"]


#: the pipeline's planner options when ``PipelineOptions.planner_options`` is None, per planner
PLANNER_DEFAULTS: dict[str, tuple] = {"tcbirrt": (("edge_resolution", 0.05),)}


def check_segment_nlp(value: Any, name: str) -> None:
    """Raise :class:`~optplan.errors.OptionError` naming ``name`` unless ``value`` is ``"optproblem"``
    (the removed ``"closed"`` gets a message saying so and what to use)."""
    if value == "closed":
        raise OptionError(f"{name}: 'closed' was removed — the closed segment class is retired and every segment NLP "
                          "is an OptProblem on the shared B-spline core; use 'optproblem' (the default) or leave the "
                          "option out (docs/decisions/0023-one-stack.md)")
    if value != "optproblem":
        raise OptionError(f"{name}: expected 'optproblem', got {value!r}")


@dataclass(frozen=True)
class PipelineOptions:
    """Options of :func:`run_pipeline`: plan → shortcut → one trajectory NLP per segment → verify.

    Retry policy of a B-spline segment, in order (each attempt is recorded in ``SegmentResult.attempts``):
    (0) velocity rows: after any solve, a velocity control point beyond its joint's limit → rows added,
    re-solve within the same solve call (≤ ``velocity_retries``; listed as ``velocity rows`` in the
    solution's attempts); after any solve that ends without converging, ``globalization``: the same NLP
    again from the same first guess with ``globalization_retry_options``; (1) ``collision``: coal finds a contact after a converged solve →
    pairs activated along the solution, margins raised between knots
    (:meth:`CollisionAvoidance.boost_between_knots`), re-solve (≤ ``collision_retries``; from the first guess
    again unless ``collision_warm_start``); (2)
    ``finer-grid``: IPOPT failed or a contact remains → 1.6× the intervals from the same initial guess,
    the pairs of every solution coal found in contact kept active, then (1) again on that grid (≤
    ``failure_retries``); (3) ``refine``: the closed-chain residual between knots exceeds
    ``closed_chain_tol`` → the grid refined by (residual / (tol/2))^¼, warm-started from the solution (≤
    ``refinements``); (4) ``fallback-knots``: still not verified → the knot transcription with free plane
    normals (not on a robot with cylinder or mesh collision geometry, which that transcription does not
    model). A segment whose fixed-normal NLP fails is re-solved with free normals before any other retry.
    """

    #: Planner name for :func:`optplan.planners.make_planner` (``"tcbirrt"``, ``"cbirrt2"``, ...).
    planner: str = "tcbirrt"
    #: The planner's keyword options as ``(name, value)`` pairs, passed to whichever planner is chosen (an
    #: option the planner does not have is an :class:`~optplan.errors.OptionError`). None: the planner's
    #: :data:`PLANNER_DEFAULTS` (TCBiRRT also checks edges every 0.05 rad; see
    #: docs/decisions/0001-tcbirrt-benchmark-ssps-scenes.md).
    planner_options: tuple | None = None
    #: Time limit of the planner [s].
    plan_time_limit: float = 10.0
    #: The clock of ``plan_time_limit`` and of the planner's inner budgets: ``"wall"`` (elapsed time) or
    #: ``"cpu"`` (this process's CPU time: a seeded plan then hardly depends on what else the machine runs; the
    #: planner's own budgets still end at a CPU time, not at an iteration count).
    plan_clock: str = "wall"
    #: Random task-space shortcuts tried per constrained segment [count].
    shortcut_attempts: int = 40
    #: Random joint-space shortcuts tried per regrasp segment (the moving arm's path; 0: none) [count].
    free_shortcut_attempts: int = 40
    #: Minimum number of NLP intervals per segment (knot transcription) [count].
    n_intervals: int = 20
    #: Segment duration = joint path length / (speed_fraction × smallest joint speed limit) [fraction, 0-1].
    speed_fraction: float = 0.5
    #: Shortest segment duration [s].
    min_duration: float = 10.0
    #: Clearance required by the NLP [m].
    margin: float = 0.02
    #: Start IPOPT from the planner's path; False: cold start from the task-space straight line between the
    #: segment's end poses through IK, or the joint-space line
    #: (docs/decisions/0002-warm-start-and-ipopt-settings.md).
    warm_start: bool = True
    #: Closed-chain collocation points inside each interval (knot transcription) [count]; 0 with enough knots is
    #: better than 1, which makes the NLP nearly square per interval.
    closed_chain_interior: int = 0
    #: A constrained segment gets ⌈joint path length / max_interval_step⌉ intervals (knot transcription) [rad].
    max_interval_step: float = 0.1
    #: A regrasp segment (no closed chain) gets ⌈joint path length / free_interval_step⌉ intervals [rad].
    free_interval_step: float = 0.15
    #: At most this many intervals per segment (knot transcription) [count].
    max_intervals: int = 100
    #: Closed-chain residual allowed between knots when verified at 10 samples per interval [m and rad]; more →
    #: the segment is refined (the residual falls like h⁴).
    closed_chain_tol: float = 1e-6
    #: Grid refinements per segment for the closed-chain residual, at most [count].
    refinements: int = 2
    #: Re-solves on a 1.6× finer grid after IPOPT fails or coal still finds a contact [count].
    failure_retries: int = 1
    #: Re-solves after coal finds a collision in a solution [count].
    collision_retries: int = 3
    #: A B-spline collision re-solve starts from the control points of the solution coal found in contact
    #: (rows planned as before, along the first guess) instead of the segment's first guess. Off: measured
    #: over seeds 0-9 of scenes 1-3 it saved iterations on 15 plans and cost them on 5, one of them +269
    #: (a re-solve that ran into the iteration limit); docs/decisions/0021-pipeline-on-the-shared-core.md.
    collision_warm_start: bool = False
    #: IPOPT options as ``(name, value)`` pairs, passed to the solve. Default: stop at IPOPT's "acceptable"
    #: level (overall error 1e-4 for 5 iterations; the constraint tolerance stays 1e-6) and ``perturb_always_cd
    #: = yes`` (a permanent constraint regularisation of the KKT system); see
    #: docs/decisions/0002-warm-start-and-ipopt-settings.md; and the adaptive μ that never falls back to its
    #: monotone mode (``never-monotone-mode``, the modelling core's default; a solve that does not converge
    #: with it is repeated with ``globalization_retry_options``; docs/decisions/0021-pipeline-on-the-shared-core.md);
    #: ``mumps_mem_percent`` 100 (MUMPS's workspace at 2 × its estimate instead of IPOPT's 11 ×: the same
    #: iterations without ~36,000 page faults per factorization of a long segment); docs/concepts/pipeline.md.
    ipopt_options: tuple = (("acceptable_tol", 1e-4), ("acceptable_iter", 5), ("perturb_always_cd", "yes"),
                            ("adaptive_mu_globalization", "never-monotone-mode"), ("mumps_mem_percent", 100))
    #: IPOPT options as ``(name, value)`` pairs, laid over ``ipopt_options`` for one re-solve of the same
    #: B-spline NLP from the same first guess when a solve ends without converging (the iteration limit, a
    #: restoration failure, ...), before the rest of the retry policy (a ``globalization`` attempt). Default:
    #: IPOPT's own globalization of the adaptive μ, which falls back to a monotone μ when progress stalls (a
    #: segment whose ends sit off the closed chain converged with it where never-monotone μ ran into the
    #: iteration limit). ``()``: no such re-solve.
    globalization_retry_options: tuple = (("adaptive_mu_globalization", "obj-constr-filter"),)
    #: Hold the separating-plane normals at coal's witness normals along the warm start
    #: (:attr:`CollisionAvoidance.fixed_normals`); see docs/decisions/0003-fixed-plane-normals.md.
    fixed_plane_normals: bool = True
    #: ``"bspline"``: each segment a joint-space B-spline NLP (control points, closed chain and fixed-normal
    #: planes at the knots, limits on the control points; implementation: ``segment_nlp``); ``"knots"``: the
    #: :class:`~optplan.problem.OptProblem` knot-state transcription.
    transcription: str = "bspline"
    #: A constrained B-spline segment gets ⌈joint path length / spline_interval_step⌉ intervals [rad] (a
    #: regrasp: ⌈length / free_interval_step⌉).
    spline_interval_step: float = 0.05
    #: Fewest intervals of a B-spline segment [count].
    spline_min_intervals: int = 30
    #: Most intervals of a B-spline segment [count] (the finer-grid re-solves; the first grid: ``spline_first_max_intervals``).
    spline_max_intervals: int = 160
    #: Most intervals of a B-spline segment's first grid [count] (its first solve and collision re-solves; within
    #: ``spline_max_intervals``): a segment longer than this many steps starts with its knots further apart
    #: than ``spline_interval_step`` (cheaper factorizations); the finer-grid and refinement re-solves still go
    #: up to ``spline_max_intervals`` / ``spline_refine_max_intervals`` (docs/concepts/pipeline.md).
    spline_first_max_intervals: int = 100
    #: Most intervals of the refinement re-solve [count] (≥ ``spline_max_intervals``): when the
    #: closed chain drifts too far between knots of a segment already at ``spline_max_intervals``,
    #: the grid is refined beyond it, warm-started from the solution.
    spline_refine_max_intervals: int = 240
    #: IPOPT's wall-clock cap per solve [s] (a solve that hits it ends with ``Maximum_WallTime_Exceeded``;
    #: B-spline path).
    ipopt_max_wall_time: float = 60.0
    #: IPOPT's iteration cap per B-spline solve [count]; a solve that hits it goes on to the next retry of the policy
    #: (see docs/decisions/0012-segment-nlp-rows.md for the iteration counts this is set from).
    spline_max_iterations: int = 200
    #: Weight of the jerk penalty that smooths the B-spline warm start before IPOPT
    #: (:meth:`OptProblem.smooth_initial <optplan.problem.OptProblem.smooth_initial>`) [-]; 0: off.
    smooth_warm_start: float = 0.0
    #: Only velocity control points the warm start brings past this fraction of their joint's limit get rows
    #: [fraction, 0-1].
    spline_velocity_activation: float = 0.5
    #: The B-spline NLP's kernels from C compiled once per robot and cached on disk: ``"auto"`` uses what an
    #: earlier run compiled, True compiles what is missing (about a second of the C compiler per kernel, once),
    #: False never.
    compile_kernels: bool | str = "auto"
    #: Re-solves with velocity rows added for control points beyond their limit [count].
    velocity_retries: int = 2
    #: k [-], ≥ 2: solve a constrained segment first on ⌈N / k⌉ intervals (at least 8) and start the N-interval NLP
    #: from that optimum, projected onto the closed chain (a ``coarse`` attempt); 0: off.
    coarse_factor: int = 0
    #: Processes that optimize a plan's segments side by side (this one and ``workers − 1`` forked workers that
    #: inherit the robot, scene and caches; :mod:`optplan.workers`) [count]; None: 2 on a machine with at least
    #: 2 CPUs, else 1. The results do not depend on it.
    workers: int | None = None
    #: Fork the segment worker before planning, to import the optimization stack (the problem and
    #: NLP modules, IPOPT) while this process plans, instead of after planning,
    #: inheriting it from this process (:func:`optplan.pipeline_workers.warm_worker`). It saves that time of the wall
    #: on a machine with a core to spare and costs that much CPU more in all (both processes import);
    #: None: only when the 1-minute load average leaves a core free (``os.getloadavg``). The results do not
    #: depend on it.
    early_worker: bool | None = None
    #: Your own terms on every B-spline segment NLP: called as ``segment_terms(problem, kind)`` with the
    #: segment's :class:`~optplan.problem.OptProblem` (``kind``: "constrained" or "regrasp") right after
    #: it is built, before its first guess and solve, on every grid the retry policy builds; add
    #: constraints and costs with ``problem.add_constraint`` / ``problem.add_cost``. None: none.
    segment_terms: Callable[[Any, str], None] | None = None
    #: The B-spline segment NLP: ``"optproblem"``, the only one — an :class:`~optplan.problem.OptProblem`
    #: on the shared B-spline core (:func:`optplan.tasks.segment_problem`). The closed segment class
    #: (``"closed"``) was removed: it measured no faster (docs/decisions/0023-one-stack.md).
    segment_nlp: str = "optproblem"

    def planner_kwargs(self) -> dict:
        """Keyword options for :func:`~optplan.planners.make_planner` (module defaults when
        ``planner_options`` is None)."""
        opts = PLANNER_DEFAULTS.get(self.planner.lower(), ()) if self.planner_options is None else self.planner_options
        return dict(opts)

    def spline_intervals(self, length: float, kind: str) -> int:
        """Intervals of a B-spline segment's first grid for a joint path of ``length`` [rad]: ⌈length /
        step⌉ (``spline_interval_step`` for a ``kind`` "constrained" segment, else ``free_interval_step``)
        within ``spline_min_intervals`` and ``min(spline_first_max_intervals, spline_max_intervals)`` [count]."""
        step = self.spline_interval_step if kind == "constrained" else self.free_interval_step
        hi = max(self.spline_min_intervals, min(self.spline_first_max_intervals, self.spline_max_intervals))
        return int(min(max(math.ceil(length / step), self.spline_min_intervals), hi))

    def __post_init__(self):
        if self.plan_time_limit <= 0 or self.n_intervals < 2 or not 0 < self.speed_fraction <= 1:
            raise ValueError(f"PipelineOptions: invalid values {self}")
        if self.plan_clock not in ("wall", "cpu"):
            raise ValueError(f"PipelineOptions.plan_clock: expected 'wall' or 'cpu', got {self.plan_clock!r}")
        if self.segment_terms is not None and not callable(self.segment_terms):
            raise ValueError(f"PipelineOptions.segment_terms: expected a callable (problem, kind) or None, got "
                             f"{self.segment_terms!r}")
        check_segment_nlp(self.segment_nlp, "PipelineOptions.segment_nlp")
        if self.transcription not in ("bspline", "knots"):
            raise ValueError(f"PipelineOptions.transcription: expected 'bspline' or 'knots', got {self.transcription!r}")
        if not (self.spline_interval_step > 0 and 4 <= self.spline_min_intervals <= self.spline_max_intervals):
            raise ValueError("PipelineOptions: expected spline_interval_step > 0 and 4 ≤ spline_min_intervals ≤ "
                             f"spline_max_intervals, got {self.spline_interval_step}, {self.spline_min_intervals}, "
                             f"{self.spline_max_intervals}")
        if isinstance(self.spline_first_max_intervals, bool) or not isinstance(self.spline_first_max_intervals, int) \
                or self.spline_first_max_intervals < 4:
            raise OptionError(f"PipelineOptions.spline_first_max_intervals: expected an integer >= 4, got "
                              f"{self.spline_first_max_intervals!r}")
        if self.workers is not None and (isinstance(self.workers, bool) or not isinstance(self.workers, int)
                                         or self.workers < 1):
            raise ValueError(f"PipelineOptions.workers: expected an integer >= 1 or None, got {self.workers!r}")
        if self.early_worker not in (None, True, False):
            raise OptionError(f"PipelineOptions.early_worker: expected True, False or None (when a core is free), got "
                              f"{self.early_worker!r}")
        if self.compile_kernels not in (True, False, "auto"):
            raise ValueError(f"PipelineOptions.compile_kernels: expected True, False or 'auto', got "
                             f"{self.compile_kernels!r}")
        if not (isinstance(self.spline_max_iterations, int) and self.spline_max_iterations >= 1):
            raise ValueError(f"PipelineOptions.spline_max_iterations: expected an int >= 1, got "
                             f"{self.spline_max_iterations!r}")
        if isinstance(self.spline_refine_max_intervals, bool) or not isinstance(self.spline_refine_max_intervals, int) \
                or self.spline_refine_max_intervals < self.spline_max_intervals:
            raise ValueError(f"PipelineOptions.spline_refine_max_intervals: expected an integer >= spline_max_intervals "
                             f"({self.spline_max_intervals}), got {self.spline_refine_max_intervals!r}")
        for name in ("shortcut_attempts", "free_shortcut_attempts"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"PipelineOptions.{name}: expected an integer >= 0, got {v!r}")
        for name in ("ipopt_options", "globalization_retry_options"):
            v = getattr(self, name)
            if not isinstance(v, tuple) or not all(isinstance(kv, tuple) and len(kv) == 2 and isinstance(kv[0], str)
                                                   for kv in v):
                raise OptionError(f"PipelineOptions.{name}: expected a tuple of (name, value) pairs, got {v!r}")
            # the pairs a user gave (not the defaults): checked by IPOPT now, not at the first segment's solve
            default = {f.name: f.default for f in dataclasses.fields(self)}[name]
            given = {k: val for k, val in v if (k, val) not in default}
            if given:
                from .solver_options import check_ipopt_options

                try:
                    check_ipopt_options(given)
                except OptionError as exc:
                    raise OptionError(f"PipelineOptions.{name}: {exc}") from None
        if not isinstance(self.collision_warm_start, bool):
            raise OptionError(f"PipelineOptions.collision_warm_start: expected True or False, got "
                              f"{self.collision_warm_start!r}")
        if not self.ipopt_max_wall_time > 0:
            raise ValueError(f"PipelineOptions.ipopt_max_wall_time: expected a positive time [s], got "
                             f"{self.ipopt_max_wall_time}")
