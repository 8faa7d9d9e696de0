"""The main job: plan → shortcut → resample → optimize → verify, for a dual-arm robot carrying an
object.

1. **Plan** with a sampling planner (TCBiRRT by default) between two configurations that hold the
   object. Its path is split into segments: *constrained* (both hands on the object) and *regrasp*
   (the object stays where it is, held by one arm whose joints do not move, while the other arm
   lets go, moves and grasps again — the TCBiRRT paper Section 4.3; or both arms let go and move
   while the released object stands still where it is, ``arm`` =
   :data:`~optplan.planners.base.BOTH_ARMS`).
2. **Shortcut** each constrained segment: random pairs of its configurations are joined by the
   joint-space straight line projected onto the closed-chain manifold step by step; a shortcut is
   kept when it is collision free (coal) and shorter.
3. **Resample** each segment uniformly in joint-space arc length onto the NLP knots, projected back
   onto the closed-chain manifold (:mod:`optplan.warmstart`).
4. **Optimize** each segment with :class:`~optplan.problem.OptProblem`: rest at both ends, joint
   position and velocity limits, collision avoidance, minimum jerk, and either the closed chain
   (constrained) or the holding arm's joints fixed (regrasp; the object then stays put and is
   checked for collisions where it is; a both-arm regrasp has no joint fixed and the object as an
   obstacle at its pose, B-spline transcription only).
5. **Verify** every segment independently (Pinocchio + coal at 10× the knot density).

The trajectory is the concatenation of the segments; ``constrained`` flags the samples where both
hands hold the object.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .collision.checker import CollisionChecker
from .errors import ConfigurationError
from .model.ik import IKOptions
from .model.robot import RobotModel
from .pipeline_options import PLANNER_DEFAULTS, PipelineOptions
from .pipeline_workers import segment_cost, send_if_longest, solve_segments, start_early_worker
from .pipeline_workers import warm_worker as warm_worker  # (where it was; the worker's preparation)
from .planners.base import BOTH_ARMS
from .scene import Scene
from .scene import held_object as _held_object
from .shortcuts import shortcut_constrained, shortcut_free
from .verification import VerifyReport, verify

# the optimization stack (optplan.problem, the NLP modules) is imported where a
# segment is optimized, not here: ``optplan plan`` plans while a forked worker imports it (pipeline_workers)
if TYPE_CHECKING:
    from .planners.base import PlanResult
    from .problem import ClosedChain, OptProblem
    from .problem.solution import Solution

__all__ = ["PipelineOptions", "PLANNER_DEFAULTS", "SegmentResult", "PipelineResult", "run_pipeline", "shortcut_constrained",
           "shortcut_free"]
log = logging.getLogger(__name__)


@dataclass
class SegmentResult:
    """One optimized segment: ``kind`` ("constrained" or "regrasp"), the moving ``arm`` of a
    regrasp, the final ``solution`` (its ``attempts`` list every NLP solved for the segment; the
    totals are ``total_iterations``, ``total_wall_time``, ``total_setup_time``), its
    ``report`` (:func:`verify`), its start time ``t0`` [s] in the whole trajectory, and
    ``attempts``: one dict per NLP solved, in order (``reason``, ``N``, ``status``,
    ``iterations``, ``setup_s``, ``ipopt_s``, ``min_clearance_m``, ``closed_chain_residual``)."""

    kind: str
    arm: str | None
    solution: Solution
    report: VerifyReport
    t0: float
    attempts: list = field(default_factory=list)


@dataclass
class PipelineResult:
    """``plan`` (PlanResult), per-segment results, and the concatenated trajectory ``t`` [s],
    ``q`` (M × nq), ``constrained`` (M,). ``success``: planned, every segment solved and verified
    (closed-chain residual ≤ ``closed_chain_tol``, clearance ≥ 0)."""

    plan: PlanResult | None
    segments: list = field(default_factory=list)
    t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    q: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    constrained: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    plan_time_s: float = float("nan")
    shortcut_time_s: float = 0.0
    #: wall time of the optimization of every segment [s]: NLP setup, IPOPT and verify (not the shortcut)
    opt_wall_s: float = 0.0
    #: the same in this process's CPU time [s] (what a loaded machine does not inflate)
    opt_cpu_s: float = 0.0
    joint_names: tuple = ()
    #: the closed-chain tolerance [m, rad] the trajectory is verified against (PipelineOptions.closed_chain_tol)
    closed_chain_tol: float = 1e-6

    @property
    def opt_status(self) -> str:
        if not self.segments:
            return "not_run"
        bad = [s.solution.status for s in self.segments if not s.solution.success]
        return (bad[0] if bad else self.segments[0].solution.status).value

    @property
    def opt_time_s(self) -> float:
        """IPOPT time summed over the segments [s]."""
        return float(sum(s.solution.total_wall_time for s in self.segments))

    @property
    def setup_time_s(self) -> float:
        return float(sum(s.solution.total_setup_time for s in self.segments))

    @property
    def iterations(self) -> int:
        return int(sum(s.solution.total_iterations for s in self.segments))

    @property
    def max_closed_chain_residual(self) -> float:
        vals = [s.report.max_closed_chain_residual for s in self.segments if s.kind == "constrained"]
        return float(max(vals)) if vals else float("nan")

    @property
    def min_clearance_m(self) -> float:
        return float(min((s.report.min_clearance_m for s in self.segments), default=float("nan")))

    @property
    def n_regrasp(self) -> int:
        return int(self.plan.n_regrasp) if self.plan is not None else 0

    @property
    def success(self) -> bool:
        return bool(self.plan is not None and self.plan.success and self.segments
                    and all(s.solution.success for s in self.segments)
                    and (np.isnan(self.max_closed_chain_residual)
                         or self.max_closed_chain_residual <= self.closed_chain_tol)
                    and self.min_clearance_m >= 0.0)

    def to_dict(self) -> dict:
        return {"success": self.success, "plan_status": self.plan.status.value if self.plan is not None else "not_run",
                "plan_time_s": self.plan_time_s, "opt_status": self.opt_status, "opt_time_s": self.opt_time_s,
                "opt_setup_time_s": self.setup_time_s, "opt_iterations": self.iterations,
                "max_closed_chain_residual": self.max_closed_chain_residual, "min_clearance_m": self.min_clearance_m,
                "n_regrasp": self.n_regrasp, "n_segments": len(self.segments),
                "shortcut_time_s": self.shortcut_time_s, "opt_wall_s": self.opt_wall_s, "opt_cpu_s": self.opt_cpu_s,
                "attempts": [len(s.attempts) for s in self.segments]}

    def save(self, path, *, robot: str | None = None, scene: str | None = None) -> Path:
        """npz with ``t`` [s], ``q`` [rad] (M × nq, Pinocchio order), ``joint_names``, ``constrained``,
        and the ``robot`` and ``scene`` names when given (``optplan view`` then needs no ``--scene``).
        ``.npz`` is appended to a path without it. Written atomically: the file is complete or
        absent; a failed write raises :class:`optplan.errors.OutputError`. Returns the path written."""
        from ._io import atomic_path

        p = Path(path)
        if p.suffix != ".npz" and (p.is_file() or not p.exists()):   # not a device such as /dev/null
            p = p.with_name(p.name + ".npz")
        arrays: dict[str, Any] = {"t": self.t, "q": self.q, "joint_names": np.array(self.joint_names),
                  "constrained": self.constrained}
        arrays.update({k: np.array(v) for k, v in (("robot", robot), ("scene", scene)) if v is not None})
        with atomic_path(p) as tmp, open(tmp, "wb") as f:
            np.savez(f, **arrays)
        return p


# --------------------------------------------------------------------------- shortcut
# --------------------------------------------------------------------------- optimization
def _segment_problem(robot: RobotModel, scene: Scene, seg_path: np.ndarray, kind: str, arm: str | None,
                     opts: PipelineOptions, n_intervals: int | None = None, fixed_normals: bool | None = None
                     ) -> tuple[OptProblem, ClosedChain | None, str | None]:
    from .problem import ClosedChain
    from .tasks import segment_problem

    length = float(np.linalg.norm(np.diff(seg_path, axis=0), axis=1).sum())
    vmin = float(np.min(robot.velocity_limit))
    T = max(opts.min_duration, length / (opts.speed_fraction * vmin))
    step = opts.max_interval_step if kind == "constrained" else opts.free_interval_step
    N = n_intervals or int(np.clip(np.ceil(length / step), opts.n_intervals, opts.max_intervals))
    grasps = _held_object(scene).grasps
    arms = list(grasps)
    cc, holder, limits = None, None, None
    if kind == "constrained":
        cc = dataclasses.replace(ClosedChain.from_grasps(grasps[arms[0]], grasps[arms[1]],
                                                         arms[0], arms[1]), interior=opts.closed_chain_interior)
    else:  # regrasp: the holding arm's joints stay where they are, so the object does too
        lo, hi = robot.lower.copy(), robot.upper.copy()
        scene, holder = _regrasp_scene(robot, scene, seg_path, arm, lo, hi)
        limits = (lo, hi)
    prob, _ = segment_problem(robot, scene, seg_path[0], seg_path[-1], N, T, closed_chain=cc, joint_limits=limits,
                              margin=opts.margin, object_arm=holder or arms[0],
                              fixed_normals=opts.fixed_plane_normals if fixed_normals is None else fixed_normals)
    return prob, cc, holder


def _regrasp_scene(robot: RobotModel, scene: Scene, seg_path: np.ndarray, arm: str | None,
                   lo: np.ndarray | None = None, hi: np.ndarray | None = None) -> tuple[Scene, str | None]:
    """A regrasp segment's scene and holding arm. One arm moves: the other (returned) holds the object
    and its joints are pinned in ``lo``/``hi`` to the segment's first configuration. Both move
    (``arm`` = :data:`~optplan.planners.base.BOTH_ARMS`): no holder, no pinned joints; the object
    stands still at its pose as an obstacle of the returned scene, which the links of the object's
    ``exclude_links`` may touch (as the hands' links may in a one-arm regrasp)."""
    from .scene import Obstacle

    obj = _held_object(scene)
    if arm == BOTH_ARMS:
        from .tasks import object_pose

        first = next(iter(obj.grasps))
        M = object_pose(robot, scene, np.asarray(seg_path[0], float), first, robot.model.createData())
        sx, sy, sz = (float(v) for v in obj.size)
        fixed = Obstacle("object", "box", M, size=(sx, sy, sz), exclude_links=tuple(obj.exclude_links))
        return dataclasses.replace(scene, obstacles=(*scene.obstacles, fixed), object=None), None
    holder = next(a for a in obj.grasps if a != arm)
    if lo is not None and hi is not None:
        idx = robot.arm(holder).j_idx
        lo[idx] = hi[idx] = seg_path[0][idx]
    return scene, holder


def _cold_path(robot: RobotModel, scene: Scene, q0: np.ndarray, q1: np.ndarray, kind: str, n: int) -> np.ndarray:
    """Cold start: task-space straight line through IK (constrained) or the joint-space line."""
    if kind == "constrained":
        from .tasks import object_pose, straight_line_poses, task_space_path

        arm = next(iter(_held_object(scene).grasps))
        data = robot.model.createData()
        M0, M1 = object_pose(robot, scene, q0, arm, data), object_pose(robot, scene, q1, arm, data)
        Q, _ = task_space_path(robot, scene, q0, straight_line_poses(M0, M1, n), max_step=0.05,
                               options=IKOptions(tol_position=1e-10, tol_orientation=1e-10))
        Q[-1] = q1
        return Q
    s = np.linspace(0, 1, n + 1)[:, None]
    return q0 + s * (q1 - q0)


def _initial_guess(robot, scene, prob: OptProblem, seg_path, cc, kind: str, opts: PipelineOptions) -> None:
    """Warm start from the (shortcut) planner path, or the cold straight line."""
    if opts.warm_start:
        if not prob.set_initial_path(seg_path, cc):
            log.info("segment %s: some resampled configurations did not project onto the manifold", kind)
    else:
        prob.set_initial(q=_cold_path(robot, scene, seg_path[0], seg_path[-1], kind, prob.N))


def _accumulate(sol, prev: Solution) -> Solution:
    """``sol`` with the attempts of an earlier solution ``prev`` listed before its own (a
    Solution is immutable; totals are ``total_iterations``, ``total_wall_time``, …)."""
    return sol.after(prev)


def _dense_times(sol, per_interval: int = 10) -> np.ndarray:
    """``per_interval`` samples per knot interval of a solution [s] (what ``verify`` checks)."""
    return np.linspace(sol.t[0], sol.t[-1], per_interval * (len(sol.t) - 1) + 1)


def _solve_verified(robot, scene, prob: OptProblem, cc, holder, opts: PipelineOptions, ipopt: dict, kind: str):
    """Solve and verify; re-solve with more collision pairs when coal finds a collision the
    NLP's active pairs missed (at most ``opts.collision_retries`` times). The pipeline verifies and
    retries itself (its ordered policy), so the problem's own dense check is off here."""
    from .problem import CollisionAvoidance

    sol = prob.solve(ipopt, guarantees=False)
    rep = verify(robot, sol, scene, closed_chain=cc, object_arm=holder)
    for _ in range(opts.collision_retries):
        if not sol.success or rep.min_clearance_m >= 0.0:
            break
        # activate pairs from the union of the initial guess and this solution; where the solution
        # collides between knots, raise those pairs' margin at the knots around; rebuild, re-solve
        h = prob.terms["collision"]
        assert isinstance(h.term, CollisionAvoidance) and sol.x is not None   # the collision term; a solved NLP
        col = h.term.with_activation(prob.numeric_trajectory(sol.x))
        t = _dense_times(sol)
        col, n = col.with_boost(prob.term_data(h), t, sol.sample(t)["q"], sol.t)
        log.info("segment %s: clearance %.3g m by coal (%s); re-solving with more pairs (%d rows with a "
                 "larger margin)", kind, rep.min_clearance_m, rep.min_clearance_pair, n)
        prob.replace_term(h, col)
        sol = _accumulate(prob.solve(ipopt, guarantees=False).labelled("collision"), sol)
        rep = verify(robot, sol, scene, closed_chain=cc, object_arm=holder)
    return sol, rep


def _attempt(reason: str, N: int, sol: Solution, rep: VerifyReport | None) -> dict:
    nan = float("nan")
    return {"reason": reason, "N": int(N), "status": sol.status.value, "iterations": int(sol.iterations),
            "setup_s": float(sol.setup_time), "ipopt_s": float(sol.wall_time),
            "min_clearance_m": nan if rep is None else float(rep.min_clearance_m),
            "closed_chain_residual": nan if rep is None else float(rep.max_closed_chain_residual)}


def _spline_segment(robot: RobotModel, scene: Scene, seg_path: np.ndarray, kind: str, arm: str | None,
                    opts: PipelineOptions, ipopt: dict) -> tuple[Solution, VerifyReport, list[dict]]:
    """Optimize one segment with the B-spline NLP (an :class:`~optplan.problem.OptProblem` on the
    shared kernel core, :mod:`optplan.segment_nlp`) under the retry policy of
    :func:`optimize_segments`; returns (solution, report, attempts)."""
    from .problem import ClosedChain, IpoptStatus
    from .segment_nlp import activate, boost_and_activate, guess_knots, project_knots, unmodelled_geometry
    from .tasks import segment_problem

    length = float(np.linalg.norm(np.diff(seg_path, axis=0), axis=1).sum())
    T = max(opts.min_duration, length / (opts.speed_fraction * float(np.min(robot.velocity_limit))))
    grasps = _held_object(scene).grasps
    arms = list(grasps)
    cc, holder = None, None
    lo, hi = robot.lower.copy(), robot.upper.copy()
    if kind == "constrained":
        cc = ClosedChain.from_grasps(grasps[arms[0]], grasps[arms[1]], arms[0], arms[1])
    else:  # regrasp: the holding arm's joints stay where they are, so the object does too
        scene, holder = _regrasp_scene(robot, scene, seg_path, arm, lo, hi)
    # the closed-chain rows hold per component to constr_viol_tol; verify measures the norm of the
    # position error (and the rotation angle), up to √3 times that: hold the rows to a quarter of
    # closed_chain_tol / √3 so that knots pass with room for the drift between them (measured: a
    # segment verified at 2e-6 on 48, 70 and 103 intervals alike — knot-level, not h⁴ drift)
    cv = 0.5 * opts.closed_chain_tol / (2.0 * np.sqrt(3.0))
    if cc is not None:
        # the end configurations are pinned: rows next to them cannot be held much tighter than
        # the ends' own residual (a planner's start 2.1e-7 m off the manifold against a row
        # tolerance of 1.4e-7: IPOPT stalled at 1.5e-7 until its iteration limit, docs/decisions/0015);
        # hold them to twice that residual, up to half of closed_chain_tol / √3
        from .constraints.closed_chain import closure_errors

        pos, rot = closure_errors(robot, grasps, np.asarray([seg_path[0], seg_path[-1]], float))
        cv = float(min(max(cv, 2.0 * max(pos.max(), rot.max())), opts.closed_chain_tol / (2.0 * np.sqrt(3.0))))
    ipopt = {"max_wall_time": opts.ipopt_max_wall_time, "max_iter": opts.spline_max_iterations,
             "constr_viol_tol": cv, "acceptable_constr_viol_tol": cv, **ipopt}

    def build(N: int, initial: Solution | None = None, project: bool = False) -> Any:
        prob, _ = segment_problem(robot, scene, seg_path[0], seg_path[-1], int(N), T, closed_chain=cc,
                                  joint_limits=(lo, hi), margin=opts.margin, object_arm=holder or arms[0],
                                  fixed_normals=True, transcription="bspline",
                                  velocity_activation=opts.spline_velocity_activation)
        prob.compile_kernels = opts.compile_kernels
        prob._spline.velocity_retries = opts.velocity_retries   # (0) of the retry policy, inside the solve
        prob.prepare_warm_start = False   # solved once from a guess: no warm-started re-solve
        if opts.segment_terms is not None:   # the user's own terms
            opts.segment_terms(prob, kind)
        if initial is not None:   # another grid's solution at this grid's knots (projected: drift between its knots)
            Q = initial.sample(np.linspace(initial.t[0], initial.t[-1], int(N) + 1))["q"]
            Q = project_knots(robot, Q, cc) if project else Q
            prob.set_initial(q=Q)
        elif opts.warm_start:
            if not prob.set_initial_path(seg_path, cc):
                log.info("segment %s: some resampled configurations did not project onto the manifold", kind)
            if opts.smooth_warm_start > 0:
                prob.smooth_initial(opts.smooth_warm_start, cc)
        else:
            Q = _cold_path(robot, scene, seg_path[0], seg_path[-1], kind, int(N))
            prob.set_initial(q=Q)
        return prob

    attempts: list[dict] = []
    total: Solution | None = None

    retry_ipopt = {**ipopt, **dict(opts.globalization_retry_options)} if opts.globalization_retry_options else None

    current = [ipopt]   # the segment's IPOPT options: the retry's from its first use on

    def run(prob: Any, reason: str):
        nonlocal total
        # the problem re-solves itself when a joint speed without a row exceeds its limit (velocity
        # rows activated after the solve, listed in the solution's attempts); the pipeline verifies
        # and retries (its ordered policy), so the problem's own dense check is off
        sol = prob.solve(current[0], guarantees=False)
        if not sol.success and retry_ipopt is not None and current[0] is not retry_ipopt \
                and sol.status is not IpoptStatus.MAXIMUM_WALLTIME_EXCEEDED:
            # the same NLP from the same first guess with the retry's μ globalization, and so every
            # later NLP of this segment (decision 0021)
            attempts.append(_attempt(reason, prob.N, sol, None))  # not verified: it is re-solved
            total = sol if total is None else _accumulate(sol, total)
            log.info("segment %s: %s N=%d -> %s after %d iterations; re-solving with %s", kind, reason, prob.N,
                     sol.status.value, sol.iterations, opts.globalization_retry_options)
            current[0], reason = retry_ipopt, "globalization"
            sol = prob.solve(retry_ipopt, guarantees=False)
        rep = verify(robot, sol, scene, closed_chain=cc, object_arm=holder)
        attempts.append(_attempt(reason, prob.N, sol, rep))
        log.info("segment %s: %s N=%d -> %s, %d iterations, setup %.2f s, IPOPT %.2f s, clearance %+.4f m, "
                 "closed-chain residual %.1e", kind, reason, prob.N, sol.status.value, sol.iterations,
                 sol.setup_time, sol.wall_time, rep.min_clearance_m, rep.max_closed_chain_residual)
        total = sol if total is None else _accumulate(sol, total)
        return sol, rep

    def good(sol, rep) -> bool:
        res = rep.max_closed_chain_residual
        return bool(sol.success and rep.min_clearance_m >= 0.0
                    and (kind != "constrained" or res <= opts.closed_chain_tol))

    N = opts.spline_intervals(length, kind)   # the first grid: ⌈length / step⌉ up to spline_first_max_intervals
    prob = None
    Nc = int(np.ceil(N / opts.coarse_factor)) if opts.coarse_factor >= 2 else 0
    if kind == "constrained" and opts.warm_start and Nc >= 8:
        # coarse-to-fine: the planner path's corners are smoothed on a coarse grid first, and the
        # fine NLP starts from (and activates its pairs along) the coarse optimum
        coarse = build(Nc)
        csol = coarse.solve(ipopt)
        attempts.append(_attempt("coarse", Nc, csol, None))
        total = csol
        log.info("segment %s: coarse N=%d -> %s, %d iterations", kind, Nc, csol.status.value, csol.iterations)
        if csol.success:
            prob = build(N, initial=csol, project=True)
    if prob is None:
        prob = build(N)
    sol, rep = run(prob, "initial")
    colliding: list[Solution] = []  # solutions coal found in contact: their pairs stay active on a finer grid

    def fix_contacts(prob, sol, rep):
        for _ in range(opts.collision_retries):  # 1. coal finds a contact the active rows missed
            if not sol.success or rep.min_clearance_m >= 0.0:
                break
            colliding.append(sol)
            boost_and_activate(prob, sol, _dense_times(sol), T, restart=opts.collision_warm_start)
            sol, rep = run(prob, "collision")
        return sol, rep

    sol, rep = fix_contacts(prob, sol, rep)
    for _ in range(opts.failure_retries):  # 2. IPOPT failed, or still a contact: a finer grid
        if (sol.success and rep.min_clearance_m >= 0.0) or N >= opts.spline_max_intervals:
            break
        N = int(min(opts.spline_max_intervals, np.ceil(N * 1.6)))
        prob = build(N)
        if rep.min_clearance_m < 0.0 and all(c is not sol for c in colliding):
            colliding.append(sol)
        # measured: without them the finer grid missed the same pair again (−199 mm)
        activate(prob, [c.sample(np.linspace(c.t[0], c.t[-1], N + 1))["q"] for c in colliding], T)
        sol, rep = fix_contacts(prob, *run(prob, "finer-grid"))  # the finer grid's own contacts too
    for _ in range(opts.refinements):  # 3. the closed chain drifts between knots (∝ h⁴)
        res = rep.max_closed_chain_residual
        if kind != "constrained" or not sol.success or not res > opts.closed_chain_tol:
            break
        N2 = int(min(opts.spline_refine_max_intervals, np.ceil(N * 1.05 * (res / (0.5 * opts.closed_chain_tol)) ** 0.25)))
        if N2 <= N:
            break
        N = N2
        prev = prob
        prob = build(N, initial=sol)
        # the pairs the previous grid had rows for stay active (its guess and every colliding
        # solution): activated along the solution alone, a pair whose rows held it > 0.12 m away lost
        # them, and the refined solve went 64 mm into it (decision 0015)
        Qp = guess_knots(prev)   # the previous grid's first guess at its knots
        tq = np.linspace(0.0, 1.0, N + 1)
        tp = np.linspace(0.0, 1.0, len(Qp))
        activate(prob, [np.column_stack([np.interp(tq, tp, Qp[:, j]) for j in range(Qp.shape[1])])]
                  + [c.sample(np.linspace(c.t[0], c.t[-1], N + 1))["q"] for c in colliding], T)
        sol, rep = fix_contacts(prob, *run(prob, "refine"))  # the refined grid's own contacts too
    # the knot transcription has no rows for cylinders and meshes (the B-spline NLP bounds them):
    # on such a robot its solution would ignore them, so it is not tried
    unmodelled = unmodelled_geometry(prob)
    if not good(sol, rep) and unmodelled:
        log.info("segment %s: no knot-transcription fallback (it does not model %d of the robot's collision "
                 "geometries)", kind, len(unmodelled))
    assert total is not None   # run() set it
    if not good(sol, rep) and not unmodelled:  # 4. last resort: the knot transcription with free plane normals
        prob2, cc2, h2 = _segment_problem(robot, scene, seg_path, kind, arm, opts, fixed_normals=False)
        _initial_guess(robot, scene, prob2, seg_path, cc2, kind, opts)
        sol2, rep2 = _solve_verified(robot, scene, prob2, cc2, h2, opts, ipopt, kind)
        attempts.append(_attempt("fallback-knots", prob2.N, sol2, rep2))
        log.info("segment %s: fallback to the knot transcription -> %s", kind, sol2.status.value)
        if good(sol2, rep2) or not sol.success:
            total, rep = _accumulate(sol2, total), rep2
        else:  # keep the spline solution; the fallback's time still counts (listed in its attempts)
            total = dataclasses.replace(total, attempts=total.attempts + sol2.attempts)
    return total, rep, attempts


def optimize_segments(robot: RobotModel, scene: Scene, plan, opts: PipelineOptions, rng: np.random.Generator,
                      checker: CollisionChecker | None = None, with_cpu: bool = False):
    """Shortcut, resample and optimize every segment of a plan; returns (results, shortcut wall
    time [s]) and, with ``with_cpu``, the shortcut's CPU time [s] and the CPU time [s] worker
    processes spent on segments (``opts.workers``) too."""
    checker = checker or CollisionChecker(robot, scene)
    results, t0, t_short, c_short = [], 0.0, 0.0, 0.0
    ipopt = dict(opts.ipopt_options)
    jobs: list[tuple[np.ndarray, str, str | None]] = []
    free_rng = rng.spawn(1)[0]  # its own stream: the constrained shortcuts draw as before
    paths = [np.asarray(plan.path[seg.start:seg.stop + 1]) for seg in plan.segments]
    kinds = ["constrained" if seg.kind == "constrained" else "regrasp" for seg in plan.segments]
    early: dict[int, Any] = {}
    for n, seg in enumerate(plan.segments):
        seg_path, kind = paths[n], kinds[n]
        if len(seg_path) < 2 or np.abs(seg_path[-1] - seg_path[0]).max() < 1e-9:
            continue
        if kind == "constrained" and opts.warm_start:
            ts, cs = time.perf_counter(), time.process_time()
            seg_path = shortcut_constrained(robot, scene, seg_path, rng, opts.shortcut_attempts, checker)
            t_short += time.perf_counter() - ts
            c_short += time.process_time() - cs
        elif kind == "regrasp" and opts.warm_start and opts.free_shortcut_attempts > 0 and seg.arm is not None:
            ts, cs = time.perf_counter(), time.process_time()
            seg_scene, holding = _regrasp_scene(robot, scene, seg_path, seg.arm)
            seg_path = shortcut_free(robot, scene, seg_path, free_rng, opts.free_shortcut_attempts,
                                     CollisionChecker.shared(robot, seg_scene, object_arm=holding)
                                     if seg_scene is scene else CollisionChecker(robot, seg_scene))
            t_short += time.perf_counter() - ts
            c_short += time.process_time() - cs
        jobs.append((seg_path, kind, seg.arm))
        if not early:   # the longest segment to the worker now, while this process shortcuts the rest
            early = send_if_longest(robot, scene, _spline_segment, jobs, list(zip(paths[n + 1:], kinds[n + 1:])),
                                    (opts, ipopt), opts)
    if opts.transcription == "bspline":
        # the segments are independent NLPs: solved side by side (same results in any process)
        cost = [segment_cost(p, k) for p, k, _ in jobs]
        solved, worker_cpu = solve_segments(robot, scene, _spline_segment, [(p, k, a, opts, ipopt) for p, k, a in jobs],
                                            cost, opts, early=early)
        for (_, kind, arm), (sol, rep, attempts) in zip(jobs, solved):
            results.append(SegmentResult(kind, arm, sol, rep, t0, attempts))
            t0 += sol.duration
        return (results, t_short, c_short, worker_cpu) if with_cpu else (results, t_short)
    for seg_path, kind, arm in jobs:
        if arm == BOTH_ARMS:
            raise ConfigurationError("a regrasp in which both arms move needs the B-spline transcription "
                                     "(PipelineOptions.transcription='bspline')")
        fixed = opts.fixed_plane_normals
        prob, cc, holder = _segment_problem(robot, scene, seg_path, kind, arm, opts, fixed_normals=fixed)
        _initial_guess(robot, scene, prob, seg_path, cc, kind, opts)
        sol, rep = _solve_verified(robot, scene, prob, cc, holder, opts, ipopt, kind)
        if fixed and not sol.success:
            # fixed normals confine the NLP to half-spaces around the initial guess, which can be
            # infeasible (measured: 1 regrasp in 240 segments); the free-normal NLP is not
            log.info("segment %s: IPOPT %s with fixed plane normals; re-solving with free normals", kind,
                     sol.status.value)
            fixed = False
            prob, cc, holder = _segment_problem(robot, scene, seg_path, kind, arm, opts, fixed_normals=fixed)
            _initial_guess(robot, scene, prob, seg_path, cc, kind, opts)
            sol2, rep = _solve_verified(robot, scene, prob, cc, holder, opts, ipopt, kind)
            sol = _accumulate(sol2, sol)
        for _ in range(opts.failure_retries):
            if (sol.success and rep.min_clearance_m >= 0.0) or prob.N >= opts.max_intervals:
                break
            # a coarse grid can make the NLP hard (measured: N = 30 ran into max_iter where the
            # same segment on 48 knots converged in 10 iterations), and long intervals let a link
            # cut a corner between knots that the collision retries did not fix: retry on a finer
            # grid from the same initial guess
            N = int(min(opts.max_intervals, np.ceil(prob.N * 1.6)))
            log.info("segment %s: IPOPT %s on %d intervals; retrying on %d", kind, sol.status.value, prob.N, N)
            prob, cc, holder = _segment_problem(robot, scene, seg_path, kind, arm, opts, n_intervals=N,
                                                fixed_normals=fixed)
            _initial_guess(robot, scene, prob, seg_path, cc, kind, opts)
            sol2, rep = _solve_verified(robot, scene, prob, cc, holder, opts, ipopt, kind)
            sol = _accumulate(sol2, sol)
        for _ in range(opts.refinements):
            res_cc = rep.max_closed_chain_residual
            if kind != "constrained" or not sol.success or not res_cc > opts.closed_chain_tol:
                break
            # the closed chain drifts between knots (∝ h⁴): refine the grid, warm start from the solution
            N = int(min(opts.max_intervals,
                        np.ceil(prob.N * 1.05 * (res_cc / (0.5 * opts.closed_chain_tol)) ** 0.25)))
            if N <= prob.N:
                break
            log.info("segment %s: closed-chain residual %.2g between knots; re-solving with N = %d", kind, res_cc, N)
            prob, cc, holder = _segment_problem(robot, scene, seg_path, kind, arm, opts, n_intervals=N,
                                                fixed_normals=fixed)
            prob.set_initial(solution=sol)
            sol2, rep = _solve_verified(robot, scene, prob, cc, holder, opts, ipopt, kind)
            sol = _accumulate(sol2, sol)
        results.append(SegmentResult(kind, arm, sol, rep, t0, [_attempt("knots", prob.N, sol, rep)]))
        t0 += sol.duration
    return (results, t_short, c_short, 0.0) if with_cpu else (results, t_short)


def run_pipeline(robot: RobotModel, scene: Scene, q_start, q_goal, options: PipelineOptions | None = None,
                 seed: int = 0) -> PipelineResult:
    """Plan, shortcut, resample, optimize and verify (module docstring). Never raises for a failed
    plan or solve: the statuses are in the result."""
    from .planners import make_planner

    opts = options or PipelineOptions()
    # the segment worker forked now (when a core is free) imports the optimization stack while this
    # process makes its planner and plans
    start_early_worker(robot, scene, opts)
    rng = np.random.default_rng(seed)
    checker = CollisionChecker(robot, scene)
    planner = make_planner(opts.planner, robot, scene, **opts.planner_kwargs())
    t0 = time.perf_counter()
    plan = planner.plan(q_start, q_goal, time_limit=opts.plan_time_limit, seed=seed, clock=opts.plan_clock)
    res = PipelineResult(plan=plan, plan_time_s=float(plan.stats.get("time_s", time.perf_counter() - t0)),
                         joint_names=robot.joint_names, closed_chain_tol=opts.closed_chain_tol)
    if not plan.success:
        return res
    t1, c1 = time.perf_counter(), time.process_time()
    res.segments, res.shortcut_time_s, shortcut_cpu, worker_cpu = optimize_segments(robot, scene, plan, opts, rng,
                                                                                    checker, with_cpu=True)
    res.opt_wall_s = time.perf_counter() - t1 - res.shortcut_time_s
    res.opt_cpu_s = time.process_time() - c1 - shortcut_cpu + worker_cpu   # this process's and the workers'

    ts: list[np.ndarray] = []
    qs: list[np.ndarray] = []
    flags: list[np.ndarray] = []
    for s in res.segments:
        sol = s.solution
        t = _dense_times(sol)
        q = sol.sample(t)["q"]
        start = 1 if ts else 0
        ts.append(s.t0 + t[start:])
        qs.append(q[start:])
        f = np.full(len(t) - start, s.kind == "constrained")
        f[-1] = True  # a regrasp ends with the hand back on the object
        flags.append(f)
    if ts:
        res.t, res.q, res.constrained = np.concatenate(ts), np.vstack(qs), np.concatenate(flags)
    return res
