"""The main job for a free-floating robot carrying an object with both hands: plan → optimize → verify.

1. **Plan** with :class:`~optplan.planners.floating_tcbirrt.FloatingTCBiRRT` (default; or
   :class:`~optplan.planners.floating_carry.FloatingCarryPlanner`, ``planner_name="carry"``): joints, the
   base integrated from zero momentum along each edge, collision checked with the base where
   momentum puts it, the object's goal reached in the world (or in the base frame).
2. **Optimize** an :class:`~optplan.problem.OptProblem` on the B-spline kernel core (the shared
   modelling core): the same pinned ends at rest, joint position and velocity limits, the closed
   chain at the knots, the base attitude integrated (RK4) from zero momentum and constrained at the
   end to the plan's final attitude (so that the object lands at its world goal: with zero momentum
   the base position follows from the joints and the attitude), collision avoidance with the base
   pose in each body's placement (:mod:`optplan.problem.floating_collision`: planes fixed from the
   initial guess) and a minimum-jerk cost. Initial guess: the plan's path resampled by arc length.
3. **Verify** (:func:`optplan.verify`, the judge): base re-integrated independently; closed chain,
   clearance, joint limits and the final base attitude against :class:`~optplan.verification.VerifyTolerances`.
   Retry policy: the dense check between knots is verify's (every pair by coal, the closed chain,
   the limits, the base integrated from the start at 10 samples per interval); while its only
   failures are the closed chain or the clearance between knots, the grid is refined
   (:mod:`optplan.problem.guarantees`' refinement: twice the intervals, the last step up to the cap;
   the closed chain's drift falls ∝ h⁴; the planes re-seeded along the plan's path on the new grid), up to ``max_intervals``.

``nlp = "floating_segment"`` keeps the former optimizer (:class:`~optplan.problem.floating_segment.FloatingSplineProblem`,
no collision rows; the clearance left to the verification) for comparisons.

``success`` only when the plan is exact, the NLP converged and the verification passes.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin

from .errors import ConfigurationError, OptionError
from .floating_manoeuvre import (
    ChainedMotion,
    KeptStatus,
    ManoeuvreMotion,
    MotionPart,
    manoeuvre_spans,
    sharp_corners,
)
from .model.floating import simulate_base
from .model.robot import RobotModel
from .planners.base import PlanStatus
from .planners.floating_carry import FloatingCarryOptions, FloatingCarryPlan, FloatingCarryPlanner
from .planners.floating_tcbirrt import FloatingTCBiRRT, FloatingTreeOptions
from .problem.floating_segment import FloatingSegmentSpec, FloatingSplineProblem
from .problem.frame_terms import ClosedChain
from .problem.solution import Solution
from .scene import Scene
from .verification import VerifyReport, VerifyTolerances, verify

__all__ = ["FloatingPipelineOptions", "FloatingPipelineResult", "run_floating_pipeline"]


@dataclass(frozen=True)
class FloatingPipelineOptions:
    """Options of :func:`run_floating_pipeline`."""

    #: planner options (target frame, steps, tolerances).
    planner: FloatingCarryOptions = field(default_factory=FloatingCarryOptions)
    #: the planner: "tcbirrt" (:class:`~optplan.planners.floating_tcbirrt.FloatingTCBiRRT`, bidirectional
    #: trees) or "carry" (:class:`~optplan.planners.floating_carry.FloatingCarryPlanner`, straight + via poses).
    planner_name: str = "tcbirrt"
    #: the trees' options of the "tcbirrt" planner (its time limit runs on their ``clock``, CPU by default).
    tree: FloatingTreeOptions = field(default_factory=FloatingTreeOptions)
    #: planning time limit [s].
    plan_time_limit: float = 10.0
    #: B-spline intervals of the first solve [count] (24: the closed chain of the shipped scenes holds
    #: to 1e-6 between the knots without a refinement; 16 misses it by ~2×).
    intervals: int = 24
    #: most B-spline intervals of the retries [count].
    max_intervals: int = 64
    #: duration = this × the plan's joint path length / the smallest joint speed limit [s per (rad / (rad/s))].
    duration_factor: float = 3.0
    #: verification bounds (the final attitude is checked against the plan's final attitude).
    tolerances: VerifyTolerances = field(default_factory=VerifyTolerances)
    #: clearance every collision row keeps at the knots [m] (verify asks for ≥ 0 between them).
    margin: float = 0.01
    #: the optimizer: ``"optproblem"`` (OptProblem on the B-spline core, with collision rows) or
    #: ``"floating_segment"`` (the former FloatingSplineProblem, no collision rows).
    nlp: str = "optproblem"
    #: RK4 steps of the base attitude per interval [count].
    n_sub: int = 1
    #: keep the plan's attitude-steering manoeuvres as planned (timed, not re-optimized) and optimize
    #: only the pieces between them (:mod:`optplan.floating_manoeuvre`); ``"optproblem"`` only.
    keep_manoeuvres: bool = True
    #: the path is cut (a stop at rest, each piece optimized on its own) at a waypoint where the
    #: joint direction turns by more than the angle of this cosine [1] (a B-spline cannot follow
    #: the corner on the closed chain); ``"optproblem"`` only; -1: never.
    corner_cos: float = -1.0
    #: when a solve does not converge (IPOPT's iteration limit, a local infeasibility), the plan is
    #: optimized once more, cut also where the joint direction turns by more than the angle of this
    #: cosine [1], with the knots' clearance margin lowered to half the plan's smallest clearance (a
    #: margin the plan's own path does not keep leaves the NLP no feasible point near its guess).
    retry_corner_cos: float = 0.9
    #: IPOPT's iteration limit per ``"optproblem"`` solve [count] (the converging solves of the shipped scenes take
    #: ≤ ~45 iterations; one that has not converged by then goes to the retry sooner).
    max_iter: int = 150
    #: a plan ending with a kept manoeuvre whose end attitude misses: rounds of steering the rest off
    #: from the real end (each a kept manoeuvre, verified again) [count]; 0: none.
    resteer_rounds: int = 5
    #: CPU budget of each such steering [s].
    resteer_time_s: float = 2.0

    def __post_init__(self) -> None:
        if isinstance(self.resteer_rounds, bool) or not isinstance(self.resteer_rounds, int) \
                or not 0 <= self.resteer_rounds <= 20:
            raise OptionError(f"FloatingPipelineOptions.resteer_rounds: expected an integer in [0, 20], "
                              f"got {self.resteer_rounds!r}")
        if isinstance(self.resteer_time_s, bool) or not isinstance(self.resteer_time_s, (int, float)) \
                or not self.resteer_time_s > 0:
            raise OptionError(f"FloatingPipelineOptions.resteer_time_s: expected a positive time [s], "
                              f"got {self.resteer_time_s!r}")
        if self.planner_name not in ("tcbirrt", "carry"):
            raise OptionError(f"FloatingPipelineOptions.planner_name: expected 'tcbirrt' or 'carry', got {self.planner_name!r}")
        if not (isinstance(self.intervals, int) and 4 <= self.intervals <= self.max_intervals):
            raise OptionError(f"FloatingPipelineOptions.intervals: expected an integer in [4, max_intervals = "
                              f"{self.max_intervals}], got {self.intervals!r}")
        if self.nlp not in ("optproblem", "floating_segment"):
            raise OptionError(f"FloatingPipelineOptions.nlp: expected 'optproblem' or 'floating_segment', got {self.nlp!r}")
        if isinstance(self.max_iter, bool) or not (isinstance(self.max_iter, int) and self.max_iter >= 1):
            raise OptionError(f"FloatingPipelineOptions.max_iter: expected an integer ≥ 1, got {self.max_iter!r}")
        if not (isinstance(self.n_sub, int) and self.n_sub >= 1):
            raise OptionError(f"FloatingPipelineOptions.n_sub: expected an integer ≥ 1, got {self.n_sub!r}")
        if not (isinstance(self.margin, (int, float)) and np.isfinite(self.margin) and self.margin >= 0):
            raise OptionError(f"FloatingPipelineOptions.margin: expected a number ≥ 0 [m], got {self.margin!r}")
        for name in ("corner_cos", "retry_corner_cos"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and -1.0 <= v <= 1.0):
                raise OptionError(f"FloatingPipelineOptions.{name}: expected a cosine in [-1, 1], got {v!r}")
        for name in ("plan_time_limit", "duration_factor"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise OptionError(f"FloatingPipelineOptions.{name}: expected a positive number, got {v!r}")


@dataclass
class FloatingPipelineResult:
    """``plan``; ``solution`` and ``report`` of the last optimization attempt (None when the plan
    failed); ``attempts``: (intervals, NLP status, failures) of each solve; ``end_attitude``: the
    final base attitude relative to the initial one that the solution must reach (the plan's, or the
    identity with ``tree.restore_attitude``)."""

    plan: FloatingCarryPlan
    #: a :class:`~optplan.problem.solution.Solution`, or a :class:`~optplan.floating_manoeuvre.ChainedMotion`
    #: (optimized pieces and kept manoeuvres) for a plan with steering manoeuvres.
    solution: Solution | ChainedMotion | None = None
    report: VerifyReport | None = None
    attempts: list[tuple[int, str, list[str]]] = field(default_factory=list)
    end_attitude: np.ndarray | None = None
    opt_wall_s: float = float("nan")
    #: CPU time of this process over the optimization attempts (solves and verify) [s]
    opt_cpu_s: float = float("nan")
    tolerances: VerifyTolerances = field(default_factory=VerifyTolerances)

    #: the object's final pose error against its goal (position [m], rotation [rad]), the base re-integrated
    #: independently along the solution; ``base``: (t [s], base XYZ-quaternion) samples of that integration
    goal_error: tuple[float, float] = (float("nan"), float("nan"))
    base: tuple[np.ndarray, np.ndarray] | None = None
    goal_tol: tuple[float, float] = (1e-3, 1e-3)

    @property
    def success(self) -> bool:
        return bool(self.plan.success and self.solution is not None and self.solution.success
                    and self.report is not None and self.report.passed(self.tolerances)
                    and self.goal_error[0] <= self.goal_tol[0] and self.goal_error[1] <= self.goal_tol[1])

    def trajectory(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(t [s], full configurations: the independently re-integrated base, then the joints) at 10
        samples per knot interval; None without a solution."""
        if self.base is None or self.solution is None:
            return None
        t, B = self.base
        return t, np.hstack([B, self.solution.sample(t)["q"]])

    def base_path(self, n: int = 5) -> list[tuple[float, np.ndarray, np.ndarray]]:
        """``n`` samples (t [s], base position [m], base roll-pitch-yaw [rad]) of the independently
        re-integrated base along the solution (empty without a solution)."""
        if self.base is None:
            return []
        t, Q = self.base
        idx = np.linspace(0, len(t) - 1, n).round().astype(int)
        return [(float(t[i]), Q[i, :3].copy(), pin.rpy.matrixToRpy(pin.XYZQUATToSE3(Q[i]).rotation)) for i in idx]


def _resample(J: np.ndarray, N: int) -> tuple[np.ndarray, float]:
    L = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(J, axis=0), axis=1))]
    s = np.linspace(0.0, L[-1], N + 1)
    return np.array([np.interp(s, L, J[:, j]) for j in range(J.shape[1])]).T, float(L[-1])


def run_floating_pipeline(robot: RobotModel, scene: Scene, q_start, goal: pin.SE3 | None = None,
                          options: FloatingPipelineOptions | None = None, seed: int = 0) -> FloatingPipelineResult:
    """Plan, optimize and verify (module docstring) from the joints ``q_start`` [rad] (holding the
    object, base at the origin at rest) to the object's ``goal`` (default ``scene.goal``). Never
    raises for a failed plan or solve: the statuses are in the result."""
    if not robot.is_floating:
        raise ConfigurationError(f"run_floating_pipeline needs a free-floating robot; {robot.name!r} has a fixed base")
    opts = options or FloatingPipelineOptions()
    goal = scene.goal if goal is None else goal
    if goal is None:
        raise ConfigurationError(f"scene {scene.name!r}: no [goal] pose for the object")
    planner: FloatingCarryPlanner | FloatingTCBiRRT = (
        FloatingTCBiRRT(robot, scene, opts.planner, opts.tree) if opts.planner_name == "tcbirrt"
        else FloatingCarryPlanner(robot, scene, opts.planner))
    plan = planner.plan(q_start, goal, seed=seed, time_limit=opts.plan_time_limit)
    res = FloatingPipelineResult(plan=plan, tolerances=opts.tolerances,
                                 goal_tol=(opts.planner.goal_tol_m, opts.planner.goal_tol_rad))
    if plan.status is not PlanStatus.EXACT:
        return res
    J = plan.joints
    restore = opts.planner_name == "tcbirrt" and opts.tree.restore_attitude and opts.planner.target_frame == "world"
    # the plan's end attitude; restored: exactly the initial one (the plan reaches it within restore_tol_rad)
    res.end_attitude = np.eye(3) if restore else plan.final_base.rotation.copy()
    cc = ClosedChain.from_configuration(robot, robot.configuration(J[0]), *planner.arm_names)
    t0, c0 = time.perf_counter(), time.process_time()
    spans = manoeuvre_spans(J) if opts.nlp == "optproblem" and opts.keep_manoeuvres else []
    corners = sharp_corners(J, opts.corner_cos, spans) if opts.nlp == "optproblem" else []
    sol: Solution | ChainedMotion
    carry = planner.carry if isinstance(planner, FloatingTCBiRRT) else planner
    # a plan ending with a kept manoeuvre is re-steered when its end attitude misses (below): the
    # verification of the chained motion then waits for the re-steered one (verify judges that)
    resteers = isinstance(planner, FloatingTCBiRRT) and bool(spans) and spans[-1][1] == len(J) - 1 \
        and opts.resteer_rounds > 0
    if spans or corners:
        sol, rep = _chained(robot, scene, plan, spans, corners, cc, res, opts, carry, defer=resteers)
    else:
        sol, rep = _solve_piece(robot, scene, J, pin.SE3.Identity(), res.end_attitude, cc, opts, res.attempts)
    if not sol.success and opts.nlp == "optproblem":
        # the retry after a solve that did not converge: cut at the milder corners, a margin the plan keeps
        retry = replace(opts, corner_cos=max(opts.corner_cos, opts.retry_corner_cos),
                        margin=min(opts.margin, 0.5 * max(float(plan.min_clearance_m), 0.0)))
        corners2 = sharp_corners(J, retry.corner_cos, spans)
        if corners2 != corners or retry.margin < opts.margin:
            sol, rep = _chained(robot, scene, plan, spans, corners2, cc, res, retry, carry, defer=resteers)
    if resteers and isinstance(planner, FloatingTCBiRRT) and isinstance(sol, ChainedMotion):
        sol, rep = _resteer_end(robot, scene, planner, sol, rep, cc, res, opts, seed)
    assert rep is not None   # a deferred verification is done by the re-steering
    res.solution, res.report = sol, rep
    res.opt_wall_s = time.perf_counter() - t0
    res.opt_cpu_s = time.process_time() - c0
    # the object's world pose at the end, with the base re-integrated along the solution (not the
    # NLP's): verify's own integration of it (from the identity, 10 samples per knot interval, 2 RK4
    # steps each), else the same again
    t = np.linspace(sol.t[0], sol.t[-1], 10 * (len(sol.t) - 1) + 1)
    if rep.samples is not None and rep.samples[0].shape == t.shape and np.array_equal(rep.samples[0], t):
        qf = rep.samples[1]
    else:
        smp = sol.sample(t)
        qf = simulate_base(robot, (t, smp["q"], smp["qd"]), t, substeps=2).q
    res.base = (t, qf[:, :7].copy())
    q_last = qf[-1, robot.base_nq:]
    M = pin.XYZQUATToSE3(qf[-1, :7]) * planner.object_in_base(q_last)
    if opts.planner.target_frame == "base":
        M = planner.object_in_base(q_last)
    e = goal.actInv(M)
    res.goal_error = (float(np.linalg.norm(e.translation)), float(np.linalg.norm(pin.log3(e.rotation))))
    return res


def _solve_piece(robot: RobotModel, scene: Scene, J: np.ndarray, base0: pin.SE3, end_attitude: np.ndarray,
                 cc: ClosedChain, opts: FloatingPipelineOptions, attempts: list) -> tuple[Solution, VerifyReport]:
    """Optimize and verify the joint path ``J`` (rest to rest) from the base placement ``base0`` to the
    base attitude ``end_attitude`` relative to ``base0``, with the refinement of the module docstring;
    each attempt appended to ``attempts``. Returns the last solution and its verification."""
    _, length = _resample(J, opts.intervals)
    T = max(1.0, opts.duration_factor * length / float(np.min(robot.velocity_limit)))
    N = opts.intervals
    guess = _resample(J, N)[0]
    while True:
        if opts.nlp == "optproblem":
            # the core's attitude is the world's (base0 · ξ): its target too
            sol = _optimize(robot, scene, J, guess, N, T, cc, base0.rotation @ end_attitude, opts, base0)
        else:
            prob = FloatingSplineProblem(robot, FloatingSegmentSpec(N, T, J[0], J[-1], end_attitude=end_attitude,
                                                                    closed_chain=cc, n_sub=opts.n_sub))
            prob.set_initial(guess)
            sol = prob.solve()
        rep = verify(robot, sol, scene, closed_chain=cc, end_attitude=end_attitude, base0=base0)
        fails = rep.failures(opts.tolerances)
        n_sol = len(sol.t) - 1
        attempts.append((n_sol, sol.status.value, fails))
        between = bool(fails) and all(f.startswith(("closed chain", "clearance")) for f in fails)
        if opts.nlp != "optproblem":
            between = bool(fails) and all(f.startswith("closed chain") for f in fails)
        if not (sol.success and between) or n_sol >= opts.max_intervals:
            return sol, rep
        # the plan's path again on the finer grid: a start at the coarser optimum (its inequalities
        # active, no multipliers) costs IPOPT an order of magnitude more iterations
        N = _refined_intervals(n_sol, rep, opts)
        guess = _resample(J, N)[0]


def _refined_intervals(n: int, rep: VerifyReport, opts: FloatingPipelineOptions) -> int:
    """The intervals of the next attempt after ``n`` failed between the knots: twice as many, or,
    when the closed chain is what failed, as many as its drift (∝ h⁴) predicts for half the
    tolerance (one solve instead of a doubling that falls short), rounded up to a multiple of 8; at
    most ``opts.max_intervals``."""
    tol = float(opts.tolerances.closed_chain)
    res = float(rep.max_closed_chain_residual)
    N = 2 * n
    if np.isfinite(res) and res > tol:
        N = max(N, 8 * int(np.ceil(n * (2.0 * res / tol) ** 0.25 / 8.0)))
    return min(N, opts.max_intervals)


def _end_base(robot: RobotModel, motion, base0: pin.SE3) -> pin.SE3:
    """The base placement at the end of ``motion`` (``t``, ``sample``) from ``base0``, integrated from
    zero momentum at verify's density."""
    t = np.linspace(motion.t[0], motion.t[-1], 10 * (len(motion.t) - 1) + 1)
    smp = motion.sample(t)
    # the same integration as verify's (its base poses), without its momentum cross-check
    return simulate_base(robot, (t, smp["q"], smp["qd"]), t, base0=base0, substeps=2, momentum=False).final_base


def _chained(robot: RobotModel, scene: Scene, plan: FloatingCarryPlan, spans: list[tuple[int, int]],
             corners: list[int], cc: ClosedChain, res: FloatingPipelineResult, opts: FloatingPipelineOptions,
             carry: FloatingCarryPlanner, defer: bool = False) -> tuple[ChainedMotion, VerifyReport | None]:
    """A plan with steering manoeuvres (``spans`` of its waypoints) or sharp ``corners``: each
    manoeuvre kept as planned (:class:`~optplan.floating_manoeuvre.ManoeuvreMotion`), each piece
    between them and the corners optimized rest to rest from the base where the parts before it
    leave it, to the plan's attitude at its end (the last piece: ``res.end_attitude``); the chained
    motion verified as a whole. ``defer``: when every part succeeded and the end attitude,
    integrated part by part, misses the target by more than half the tolerance, the verification
    is left to the re-steering that follows (:func:`_resteer_end`; the report is then None)."""
    J, speed = plan.joints, float(np.min(robot.velocity_limit))
    cuts = sorted({0, len(J) - 1, *corners, *(k for sp in spans for k in sp)})
    parts: list[MotionPart] = []
    base = pin.SE3.Identity()
    for a, b in zip(cuts[:-1], cuts[1:]):
        if (a, b) in spans:
            mm = ManoeuvreMotion(J[a:b + 1], carry.onto_chain, speed,
                                 duration_factor=opts.duration_factor, sample_step_rad=opts.planner.check_step_rad)
            st = KeptStatus.KEPT if mm.ok else KeptStatus.NOT_PROJECTED
            res.attempts.append((len(mm.t) - 1, st.value, [] if mm.ok else ["closed chain: a point not projected"]))
            parts.append(MotionPart(mm, success=mm.ok, status=st))
            base = base * _end_base(robot, mm, pin.SE3.Identity())   # left-invariant: the same from any base
            continue
        if b == a or np.array_equal(J[a], J[b]) and b - a == 1:
            continue
        R_end = res.end_attitude if b == len(J) - 1 else pin.XYZQUATToSE3(plan.q[b, :7]).rotation
        sol, rep = _solve_piece(robot, scene, J[a:b + 1], base, base.rotation.T @ R_end, cc, opts, res.attempts)
        ok = bool(sol.success and rep.passed(opts.tolerances))
        parts.append(MotionPart(sol, success=ok, status=sol.status, iterations=sol.iterations))
        if not ok:
            break
        base = _end_base(robot, sol, base)
    motion = ChainedMotion(parts)
    if all(p.success for p in parts):
        motion.end_base = base   # integrated part by part: the re-steering starts from it
        left = float(np.linalg.norm(pin.log3(base.rotation.T @ res.end_attitude)))
        if defer and left > 0.5 * float(opts.tolerances.final_base_attitude_rad or 1e-6):
            res.attempts.append((len(motion.t) - 1, "chained", [f"end attitude {left:.3g} rad from the target "
                                                                "(integrated part by part; verified after the re-steering)"]))
            return motion, None
    rep = verify(robot, motion, scene, closed_chain=cc, end_attitude=res.end_attitude)
    res.attempts.append((len(motion.t) - 1, "chained", rep.failures(opts.tolerances)))
    return motion, rep


def _resteer_end(robot: RobotModel, scene: Scene, planner: FloatingTCBiRRT, motion: ChainedMotion,
                 rep: VerifyReport | None, cc: ClosedChain, res: FloatingPipelineResult, opts: FloatingPipelineOptions,
                 seed: int) -> tuple[ChainedMotion, VerifyReport]:
    """A plan that ENDS with a kept manoeuvre misses its end attitude by what putting the manoeuvre
    back on the closed chain changed (~1e-4-1e-3 rad; no optimized piece follows to take it out):
    steer the rest off from the real end (the planner's steerer: the loop that makes the small
    rotation left solved for from three measured probe loops,
    :meth:`~optplan.planners.floating_steer.AttitudeSteerer.steer_small`; its loop search only when
    that finds nothing) and keep that manoeuvre too, up to ``opts.resteer_rounds`` times until the end
    attitude, integrated part by part from zero momentum, is within half the tolerance; then
    verify the whole motion once more (the judge). ``rep`` None: the chained motion was not
    verified (its parts succeeded, its end attitude integrated part by part misses: :func:`_chained`);
    the re-steered motion is."""
    from .planners.base import Deadline

    if rep is not None:
        fails = rep.failures(opts.tolerances)
        if opts.resteer_rounds == 0 or not fails or not all(f.startswith("final base attitude") for f in fails):
            return motion, rep
    tol = float(opts.tolerances.final_base_attitude_rad or 1e-6)
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(7,)))
    speed = float(np.min(robot.velocity_limit))
    carry = planner.carry
    parts = list(motion.parts)
    q_end = np.asarray(motion.sample(np.array([motion.t[-1]]))["q"][-1], float)
    # left-invariant: each new part from here (the parts' own integrations, not the whole motion again)
    base_end = motion.end_base if motion.end_base is not None else _end_base(robot, motion, pin.SE3.Identity())
    # the loops drawn from q_end, kept for the next rounds: a kept manoeuvre ends at its start joints
    # (its end points are not projected), so every round steers from the very same joints
    pool: list = []
    q_pool = q_end.copy()
    for _ in range(opts.resteer_rounds):
        wanted = base_end.rotation.T @ res.end_attitude
        if float(np.linalg.norm(pin.log3(wanted))) <= 0.5 * tol:
            break
        steerer = planner.steerer
        whole = steerer.options
        if not np.array_equal(q_end, q_pool):
            pool, q_pool = [], q_end.copy()
        # the small rotation left solved for: three small probe loops measured, one loop of the size
        # and orientation that makes it (AttitudeSteerer.steer_small); only when that finds nothing,
        # the search: one round of new loops (three of them make the trio of the scaled-loop
        # refinement), then a few rounds, then the full search; the loops found are kept
        st = steerer.steer_small(q_end, base_end, wanted, rng, Deadline(opts.resteer_time_s, clock="cpu"),
                                 tol_rad=0.1 * tol, pool=pool)
        try:
            for rounds in dict.fromkeys((1, min(4, whole.max_rounds), whole.max_rounds)):
                if st is not None:
                    break
                steerer.options = replace(whole, max_rounds=rounds)
                st = steerer.steer(q_end, base_end, wanted, rng, Deadline(opts.resteer_time_s, clock="cpu"),
                                   tol_rad=0.1 * tol, pool=pool)
        finally:
            steerer.options = whole
        if st is None:
            res.attempts.append((0, "resteer", ["no collision-free loop turns the base the rest of the way"]))
            break
        mm = ManoeuvreMotion(np.vstack([q_end, *st.joints]), carry.onto_chain, speed,
                             duration_factor=opts.duration_factor, sample_step_rad=opts.planner.check_step_rad)
        parts.append(MotionPart(mm, success=mm.ok, status=KeptStatus.KEPT if mm.ok else KeptStatus.NOT_PROJECTED))
        base_end = _end_base(robot, mm, base_end)
        q_end = np.asarray(mm.sample(np.array([mm.t[-1]]))["q"][-1], float)
        left = float(np.linalg.norm(pin.log3(base_end.rotation.T @ res.end_attitude)))
        res.attempts.append((len(mm.t) - 1, "resteer", [f"end attitude {left:.3g} rad from the target (integrated)"]))
    motion = ChainedMotion(parts)
    rep = verify(robot, motion, scene, closed_chain=cc, end_attitude=res.end_attitude)
    res.attempts.append((len(motion.t) - 1, "chained", rep.failures(opts.tolerances)))
    return motion, rep


def _optimize(robot: RobotModel, scene: Scene, J: np.ndarray, guess: np.ndarray, N: int, T: float, cc: ClosedChain,
              end_attitude: np.ndarray, opts: FloatingPipelineOptions, base0: pin.SE3 | None = None) -> Solution:
    """One optimization of the carry on the shared modelling core (module docstring, step 2): the
    joint knots ``guess`` ((N+1) × nj) as the first guess; the dense check between knots and its
    refinement inside the solve (a clearance below 0 between knots, the closed chain)."""
    from .problem import OptProblem
    from .problem.collision_term import CollisionAvoidance
    from .problem.frame_terms import BaseAttitude
    from .problem.terms import JointBoundary, JointPositionLimits, JointVelocityLimits, Smoothness

    z = np.zeros(robot.nj)
    prob = OptProblem(robot, n_intervals=N, duration=T, n_sub=opts.n_sub, transcription="bspline", base0=base0)
    prob.add_constraint(JointBoundary("start", q=J[0], qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=J[-1], qd=z, qdd=z))
    prob.add_constraint(JointPositionLimits())
    prob.add_constraint(JointVelocityLimits())
    prob.add_constraint(cc)
    prob.add_constraint(BaseAttitude(target=end_attitude, at="end"))
    if scene.obstacles or scene.object is not None:
        prob.add_constraint(CollisionAvoidance(scene, margin=float(opts.margin), fixed_normals=True))
    prob.add_cost(Smoothness("jerk"))
    prob.set_initial(guess)
    prob.prepare_warm_start = False   # solved once; a refinement is a new problem
    # no dense check inside the solve: verify (the judge) samples the same trajectory at the same
    # density with the base integrated from the start, and its findings drive the refinement
    return prob.solve(guarantees=False, max_iter=opts.max_iter)


def trial_goal(scene: Scene, index: int, seed: int) -> pin.SE3:
    """The object's goal of trial ``index``: the scene's [goal] for trial 0, else perturbed by the
    scene's ``[extra] trial_position_range`` [m] / ``trial_angle_range`` [rad] (deterministic in
    ``(seed, index)``); the start is the scene's ``[extra] q_start`` witness."""
    from .trials import perturb_pose, trial_seed

    if scene.goal is None:
        raise ConfigurationError(f"scene {scene.name!r}: no [goal] pose for the object")
    if index == 0:
        return scene.goal
    ex = scene.extra or {}
    rng = np.random.default_rng(trial_seed(seed, index))
    return perturb_pose(scene.goal, rng, float(ex.get("trial_position_range", 0.05)),
                        float(ex.get("trial_angle_range", 0.1)))


def scene_start(robot: RobotModel, scene: Scene) -> np.ndarray:
    """The scene's ``[extra] q_start`` [rad] (``q_unit = "deg"`` allowed): joints holding the object at
    [start] with the base at the origin."""
    ex = scene.extra or {}
    if "q_start" not in ex:
        raise ConfigurationError(f"scene {scene.name!r}: a floating robot's scene needs [extra] q_start (the joints "
                                 "holding the object at [start] with the base at the origin)")
    q = np.asarray(ex["q_start"], float) * (np.pi / 180.0 if ex.get("q_unit", "rad") == "deg" else 1.0)
    return robot.check_joints(q, f"scene {scene.name!r}: extra.q_start")


def summary_lines(res: FloatingPipelineResult) -> list[str]:
    """What ``optplan plan`` prints for a floating robot: statuses, figures, the base's path."""
    rep, p = res.report, res.plan
    out = [f"  {'success':28s} {res.success}", f"  {'plan_status':28s} {p.status.value}",
           f"  {'plan_time_s':28s} {p.time_s:.3e}", f"  {'plan_drift_corrections':28s} {p.corrections}"]
    if p.message:
        out.append(f"  {'plan_message':28s} {p.message}")
    for n, status, fails in res.attempts:
        out.append(f"    optimize N={n:3d} {status:24s} {'verified' if not fails else '; '.join(fails)}")
    if rep is not None:
        out += [f"  {'opt_wall_s':28s} {res.opt_wall_s:.3e}",
                f"  {'max_closed_chain_residual':28s} {rep.max_closed_chain_residual:.3e}",
                f"  {'min_clearance_m':28s} {rep.min_clearance_m:.3e} ({rep.min_clearance_pair})",
                f"  {'final_base_attitude_error':28s} {rep.final_base_attitude_error_rad:.3e} rad (vs the plan's end "
                "attitude, independent integration)",
                f"  {'object_goal_error':28s} {res.goal_error[0]:.3e} m, {res.goal_error[1]:.3e} rad"]
        out.append("  base path (independent integration from zero momentum): t [s], position [m], rpy [deg]")
        for t, pos, rpy in res.base_path(5):
            out.append(f"    {t:7.2f}  {np.round(pos, 4).tolist()}  {np.round(np.degrees(rpy), 3).tolist()}")
    return out


def options_for_scene(scene: Scene, restore_attitude: bool | None = None, **kwargs) -> FloatingPipelineOptions:
    """:class:`FloatingPipelineOptions` (``kwargs``) with the scene's goal frame: ``[extra] target_frame``
    = ``"world"`` (default) or ``"base"`` (the goal is the object's pose in the base frame).

    ``restore_attitude``: end at the INITIAL base attitude with the world goal (the planner steers the
    base back, :attr:`~optplan.planners.floating_tcbirrt.FloatingTreeOptions.restore_attitude`, and
    the optimizer's end-attitude constraint is the initial attitude); None: the scene's
    ``[extra] restore_attitude`` (default false: the end attitude is the plan's arrival attitude)."""
    from dataclasses import replace

    extra = scene.extra or {}
    frame = extra.get("target_frame", "world")
    if restore_attitude is None:
        restore_attitude = extra.get("restore_attitude", False)
    if not isinstance(restore_attitude, bool):
        raise ConfigurationError(f"scene {scene.name!r}: [extra] restore_attitude: expected true or false, "
                                 f"got {restore_attitude!r}")
    if restore_attitude and frame != "world":
        raise ConfigurationError(f"scene {scene.name!r}: restore_attitude needs a goal in the world "
                                 f"(target_frame = 'world'), got target_frame = {frame!r}")
    opts = FloatingPipelineOptions(**kwargs)
    return replace(opts, planner=replace(opts.planner, target_frame=frame),
                   tree=replace(opts.tree, restore_attitude=restore_attitude))
