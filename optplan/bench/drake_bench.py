"""optplan vs Drake's ``KinematicTrajectoryOptimization`` on the same problems, in one run.

``optplan bench drake [--problems transport,scene1] [--trials N] [--solvers snopt,ipopt] [--json PATH]``

Problems (:class:`PeerProblem`): the closed-chain transport problem (scene ``transport``, the
straight-line IK warm start of ``examples/closed_chain_transport.py``, N = 50, 60 s) and the
constrained segments of the pipeline on the perturbed trials of the assembly scenes (planner path
→ :func:`optplan.pipeline.shortcut_constrained` → the arc-length resampled, manifold-projected
warm start of ``OptProblem.set_initial_path``, with the pipeline's N and duration). Every method
gets the same start/goal, duration, margin, collision geometry and warm start, and every result
is checked by :func:`optplan.verify` (closed-chain residual at 10× the knot density ≤ 1e-6,
coal clearance ≥ 0) and its jerk cost ``∫‖d³q/dt³‖² dt`` computed from the trajectory itself.

The optplan side is a callable ``optplan_solve(problem) -> PeerOutcome`` (default
:func:`optplan_current`: the transport example's single ``OptProblem`` solve, and for a pipeline
segment the pipeline's own per-segment optimization with its retries), so that another optimizer
can be benchmarked against the same peer by passing another callable.
"""
from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, cast

import numpy as np

from ..model.robot import RobotModel
from ..problem import ClosedChain
from ..scene import Scene
from ..verification import verify

if TYPE_CHECKING:
    from .drake_peer import BsplineSolution

__all__ = ["PeerProblem", "PeerOutcome", "transport_instance", "pipeline_segment_instances", "optplan_current",
           "drake_solve", "jerk_cost", "evaluate", "run", "summarize", "format_report", "RESIDUAL_TOL"]
log = logging.getLogger(__name__)

RESIDUAL_TOL = 1e-6
LIMIT_TOL = 1e-6  # [rad], [rad/s]: joint-limit violations between knots reported (not part of the pass)


@dataclass
class PeerProblem:
    """One trajectory problem both optimizers solve: ``q_knots`` ((N+1) × nj) the warm start at N
    uniform intervals over ``duration`` [s] (its first/last rows are the rest configurations),
    ``closed_chain`` (or None), ``margin`` [m], ``object_arm`` (the arm the held object follows),
    ``path`` the planner path the warm start was resampled from (pipeline segments). ``kind``:
    "transport", "segment" (a constrained segment of the pipeline) or "regrasp" (one arm moves,
    ``arm``; the other holds the object, its joints fixed by ``lower`` = ``upper`` [rad])."""

    name: str
    kind: str  # "transport" | "segment"
    robot: RobotModel
    scene: Scene
    q_knots: np.ndarray
    duration: float
    closed_chain: ClosedChain | None
    margin: float = 0.02
    object_arm: str | None = None
    path: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    arm: str | None = None

    @property
    def n_intervals(self) -> int:
        return int(self.q_knots.shape[0] - 1)


@dataclass
class PeerOutcome:
    """What a method returns for a problem: ``solution`` is anything :func:`optplan.verify`
    takes (``t`` and ``sample(t)``); ``success`` the solver's own verdict; times [s]."""

    method: str
    solver: str
    success: bool
    status: str
    setup_time: float
    solve_time: float
    iterations: int
    solution: object | None
    info: dict = field(default_factory=dict)


def _grasps(scene: Scene) -> dict:
    """The scene's grasps (arm name → grasp frame in the object); a clear error for a scene without
    a held object (these are closed-chain problems)."""
    if scene.object is None:
        raise ValueError(f"scene {scene.name!r}: no held object, so no closed chain to benchmark")
    return scene.object.grasps


def _closed_chain(scene: Scene) -> ClosedChain:
    grasps = _grasps(scene)
    arms = list(grasps)
    return ClosedChain.from_grasps(grasps[arms[0]], grasps[arms[1]], arms[0], arms[1])


def _warm_start_knots(prob) -> np.ndarray:
    """The joint knots of an ``OptProblem``'s initial guess (what IPOPT starts from)."""
    return np.asarray(prob.tp.unpack(prob.initial_guess)["q"], float)


# --------------------------------------------------------------------------- problems
def transport_instance(robot: RobotModel | None = None, *, knots: int = 50, duration: float = 60.0,
                       margin: float = 0.02, seed: int = 0) -> PeerProblem:
    """The closed-chain transport problem of ``examples/closed_chain_transport.py``."""
    from ..collision.checker import CollisionChecker
    from ..tasks import transport_initial_path

    robot = robot or RobotModel.from_name("tcbirrt_dual_arm")
    scene = Scene.load("transport")
    rng = np.random.default_rng(seed)
    Q = transport_initial_path(robot, scene, knots, rng, checker=CollisionChecker(robot, scene))
    if Q is None:
        raise RuntimeError("transport: no collision-free start grasp whose straight-line IK path reaches the goal")
    return PeerProblem("transport", "transport", robot, scene, Q, float(duration), _closed_chain(scene), margin,
                       next(iter(_grasps(scene))), None, {"seed": seed, "knots": knots})


def _spline_warm_start(robot: RobotModel, scene: Scene, seg_path: np.ndarray, opts, kind: str = "constrained",
                       lower=None, upper=None, holder: str | None = None) -> tuple[np.ndarray, float]:
    """The knot configurations and duration [s] of the B-spline segment NLP's first attempt in the
    pipeline (``PipelineOptions.transcription = "bspline"``): its N and T, ``set_initial_path`` on the
    shortcut path (and ``smooth_initial`` when the options ask for it). The B-spline through these
    knots at rest is the NLP's initial trajectory (:func:`.drake_peer.fit_bspline` reproduces it
    exactly: both are the C2 cubic on the same grid with the same knot values and end velocities)."""
    from ..tasks import segment_problem

    cc = _closed_chain(scene) if kind == "constrained" else None
    length = float(np.linalg.norm(np.diff(seg_path, axis=0), axis=1).sum())
    T = max(opts.min_duration, length / (opts.speed_fraction * float(np.min(robot.velocity_limit))))
    N = opts.spline_intervals(length, kind)
    limits = None if lower is None or upper is None else (lower, upper)
    prob, _ = segment_problem(robot, scene, seg_path[0], seg_path[-1], N, T, closed_chain=cc, joint_limits=limits,
                              margin=opts.margin, object_arm=holder or next(iter(_grasps(scene))),
                              fixed_normals=True, transcription="bspline")
    prob.set_initial_path(seg_path, cc)
    if opts.smooth_warm_start > 0:
        prob.smooth_initial(opts.smooth_warm_start, cc)
    x0 = prob.initial_guess
    assert x0 is not None   # set_initial_path set it
    return prob.tp.unpack(x0)["q"], float(T)


def pipeline_segment_instances(scene_name: str, trial: int, *, seed: int = 0, robot: RobotModel | None = None,
                               options=None, kinds=("constrained",)) -> list[PeerProblem]:
    """The segments of the pipeline on trial ``trial`` of ``scene_name`` (trials and seeds as
    ``optplan bench warmstart``) whose kind is in ``kinds`` ("constrained", "regrasp"): planner
    path → shortcut of the constrained segments (the pipeline's RNG sequence) → the warm start, N
    and duration of the pipeline's B-spline segment NLP (its first attempt). Empty when the plan
    fails."""
    from ..collision.checker import CollisionChecker
    from ..pipeline import PipelineOptions, shortcut_constrained
    from ..planners import make_planner
    from ..trials import TrialGenerator

    bad = set(kinds) - {"constrained", "regrasp"}
    if bad:
        raise ValueError(f"kinds: expected 'constrained' and/or 'regrasp', got {sorted(bad)}")
    opts = options or PipelineOptions()
    if opts.transcription != "bspline":
        raise ValueError(f"pipeline_segment_instances: the peer compares the B-spline segment NLP, got "
                         f"transcription {opts.transcription!r}")
    robot = robot or RobotModel.from_name("tcbirrt_dual_arm")
    scene = Scene.load(scene_name)
    tr = TrialGenerator(robot, scene).generate(int(trial), int(seed))
    plan = make_planner(opts.planner, robot, scene, **opts.planner_kwargs()).plan(tr.q_start, tr.q_goal, time_limit=opts.plan_time_limit,
                                                               seed=tr.seed)
    if not plan.success:
        log.warning("%s trial %d: plan failed (%s)", scene_name, trial, plan.status.value)
        return []
    rng = np.random.default_rng(tr.seed)  # run_pipeline's RNG: consumed by the shortcuts in segment order
    checker = CollisionChecker(robot, scene)
    cc = _closed_chain(scene)
    out = []
    arms = list(_grasps(scene))
    for i, seg in enumerate(plan.segments):
        seg_path = np.asarray(plan.path[seg.start:seg.stop + 1])
        if len(seg_path) < 2 or np.abs(seg_path[-1] - seg_path[0]).max() < 1e-9:
            continue
        kind = "constrained" if seg.kind == "constrained" else "regrasp"  # as optimize_segments
        if kind == "constrained":  # shortcut even when not compared: it consumes the pipeline's RNG
            seg_path = shortcut_constrained(robot, scene, seg_path, rng, opts.shortcut_attempts, checker)
        if kind not in kinds:
            continue
        length = float(np.linalg.norm(np.diff(seg_path, axis=0), axis=1).sum())
        info = {"scene": scene.name, "trial": int(trial), "segment": i, "path_length_rad": length}
        if kind == "constrained":
            Q, T = _spline_warm_start(robot, scene, seg_path, opts)
            out.append(PeerProblem(f"{scene.name}/t{trial}/s{i}", "segment", robot, scene, Q, T, cc,
                                   opts.margin, arms[0], seg_path, info))
            continue
        holder = next(a for a in arms if a != seg.arm)  # the pipeline's regrasp: the holding arm is fixed
        lo, hi = robot.lower.copy(), robot.upper.copy()
        idx = robot.arm(holder).j_idx
        lo[idx] = hi[idx] = seg_path[0][idx]
        Q, T = _spline_warm_start(robot, scene, seg_path, opts, "regrasp", lo, hi, holder)
        out.append(PeerProblem(f"{scene.name}/t{trial}/s{i}r", "regrasp", robot, scene, Q, T, None, opts.margin,
                               holder, seg_path, info, lo, hi, seg.arm))
    return out


# --------------------------------------------------------------------------- methods
def optplan_current(problem: PeerProblem) -> PeerOutcome:
    """optplan's current optimizer, as the product runs it: the transport example's single
    B-spline segment NLP solve (an :class:`optplan.problem.OptProblem` on the kernel core,
    :func:`optplan.tasks.segment_problem`), or for a pipeline segment
    the pipeline's B-spline segment optimization (``optplan.pipeline._spline_segment``, called
    as the pipeline calls it, with its retry policy: collision re-solves, a finer grid, closed-chain
    refinement, the knot-transcription fallback; times and iterations summed over its attempts). ``setup_time``: problem declaration + NLP build +
    solver creation."""
    if problem.kind == "transport":
        from ..problem import ClosedChain
        from ..tasks import segment_problem

        t0 = time.perf_counter()
        sc, q = problem.scene, np.asarray(problem.q_knots)
        grasps = _grasps(sc)
        arms = list(grasps)
        cc = ClosedChain.from_grasps(grasps[arms[0]], grasps[arms[1]], arms[0], arms[1])
        prob, _ = segment_problem(problem.robot, sc, q[0], q[-1], len(q) - 1, problem.duration, closed_chain=cc,
                                  margin=problem.margin, object_arm=arms[0], fixed_normals=True,
                                  transcription="bspline")
        prob.set_initial(q=q)
        declare = time.perf_counter() - t0
        sol = prob.solve(guarantees=False)
        return PeerOutcome("optplan", "ipopt", bool(sol.success), sol.status.value, declare + sol.setup_time,
                           sol.wall_time, int(sol.iterations), sol, {"attempts": 1})
    from ..pipeline import PipelineOptions, _spline_segment

    opts = PipelineOptions()
    kind = "constrained" if problem.kind == "segment" else "regrasp"
    t0 = time.perf_counter()
    sol, rep, attempts = _spline_segment(problem.robot, problem.scene, np.asarray(problem.path), kind, problem.arm,
                                         opts, dict(opts.ipopt_options))
    wall = time.perf_counter() - t0
    if attempts and attempts[0]["N"] != problem.n_intervals:
        log.warning("%s: the pipeline's first attempt has N = %d, the peer problem %d", problem.name,
                    attempts[0]["N"], problem.n_intervals)
    return PeerOutcome("optplan", "ipopt", bool(sol.success), sol.status.value, float(sol.setup_time),
                       float(sol.wall_time), int(sol.iterations), sol,
                       {"wall_time_s": wall, "n_intervals_first": int(attempts[0]["N"]) if attempts else -1,
                        "n_intervals_final": int(len(sol.t) - 1), "attempts": len(attempts),
                        "attempt_log": ",".join(a["reason"] for a in attempts)})


KILL_GRACE = 30.0  # [CPU s] beyond the time limit before an isolated Drake solve is killed


def drake_solve(problem: PeerProblem, options=None, model=None, *, refinements: int = 0,
                closed_chain_tol: float = RESIDUAL_TOL, max_intervals: int = 160, isolate: bool = False) -> PeerOutcome:
    """Drake's ``KinematicTrajectoryOptimization`` (:mod:`.drake_peer`) on ``problem``; the plant
    and scene-graph construction counts as setup.

    refinements: as the pipeline does for its own segments, a converged solution whose closed-chain
    residual between knots (``verify``) exceeds ``closed_chain_tol`` is re-solved on a grid refined
    by ``(residual / (tol/2))^¼`` (at most ``max_intervals``), warm-started from the solution, at
    most this many times. ``options.time_limit`` [CPU s] bounds all attempts together.

    isolate: solve in a forked child process whose CPU time the kernel caps at ``time_limit`` +
    ``KILL_GRACE`` (POSIX only). The time limit is otherwise checked at every function evaluation,
    and SNOPT was measured cycling inside one QP subproblem for 876,000 minor iterations without
    any (a pipeline segment of scene 2, N = 65); a killed solve is a status without a trajectory."""
    if isolate:
        return _drake_solve_isolated(problem, options, refinements=refinements, closed_chain_tol=closed_chain_tol,
                                     max_intervals=max_intervals)
    from dataclasses import replace

    from .drake_peer import DrakeModel, DrakeOptions, solve_drake

    opts = options or DrakeOptions()
    t0 = time.perf_counter()
    dm = model or DrakeModel(problem.robot, problem.scene, object_arm=problem.object_arm)
    build = time.perf_counter() - t0
    c0 = time.process_time()
    r = solve_drake(dm, problem.q_knots, problem.duration, closed_chain=problem.closed_chain, margin=problem.margin,
                    options=opts, lower=problem.lower, upper=problem.upper)
    setup, solve, iters, N = build + r.setup_time, r.solve_time, r.iterations, problem.n_intervals
    attempts = [f"N={N}:{r.status}"]
    for _ in range(int(refinements)):
        if not r.success or problem.closed_chain is None:
            break
        res = verify(problem.robot, r.solution, problem.scene, closed_chain=problem.closed_chain,
                     object_arm=problem.object_arm).max_closed_chain_residual
        remaining = opts.time_limit - (time.process_time() - c0)
        N2 = int(min(max_intervals, np.ceil(N * 1.05 * (res / (0.5 * closed_chain_tol)) ** 0.25)))
        if not res > closed_chain_tol or N2 <= N or remaining < 1.0:
            break
        N = N2
        assert r.solution is not None  # r.success: the solver returned a trajectory
        Q2 = r.solution.sample(np.linspace(0.0, problem.duration, N + 1))["q"]
        r = solve_drake(dm, Q2, problem.duration, closed_chain=problem.closed_chain, margin=problem.margin,
                        options=replace(opts, time_limit=remaining), lower=problem.lower, upper=problem.upper)
        setup, solve, iters = setup + r.setup_time, solve + r.solve_time, iters + max(r.iterations, 0)
        attempts.append(f"N={N}:{r.status}")
    return PeerOutcome(f"drake-{r.solver}", r.solver, r.success, r.status, setup, solve, iters, r.solution,
                       {"model_build_s": build, "n_variables": r.n_variables, "n_constraints": r.n_constraints,
                        "missing_pairs": len(dm.missing_pairs), "extra_pairs": len(dm.extra_pairs),
                        "candidate_pairs": dm.n_candidate_pairs, "n_intervals_final": N, "attempts": len(attempts),
                        "attempt_log": " | ".join(attempts), **r.info})


def _drake_child(conn, problem, options, kw) -> None:  # pragma: no cover - runs in the forked child
    import resource

    limit = int(np.ceil(options.time_limit + KILL_GRACE))
    resource.setrlimit(resource.RLIMIT_CPU, (limit, limit + 5))
    out = drake_solve(problem, options, **kw)
    sol = cast("BsplineSolution", out.solution)  # drake_solve always returns Drake's trajectory
    tr = sol.trajectory
    P = np.column_stack([np.asarray(c).ravel() for c in tr.control_points()])
    conn.send({"outcome": {k: getattr(out, k) for k in ("method", "solver", "success", "status", "setup_time",
                                                        "solve_time", "iterations", "info")},
               "P": P, "T": float(tr.end_time()), "N": int(sol.n_intervals)})
    conn.close()


def _drake_solve_isolated(problem: PeerProblem, options, **kw) -> PeerOutcome:
    import multiprocessing as mp

    from pydrake.trajectories import BsplineTrajectory

    from .drake_peer import BsplineSolution, DrakeModel, DrakeOptions, _basis

    opts = options or DrakeOptions()
    ctx = mp.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    t0 = time.perf_counter()
    proc = ctx.Process(target=_drake_child, args=(send, problem, opts, kw), daemon=True)
    proc.start()
    send.close()
    msg = None
    try:
        msg = recv.recv()
    except EOFError:  # the child died: killed at its CPU limit
        pass
    proc.join()
    wall = time.perf_counter() - t0
    if msg is None:
        status = (f"{opts.solver.upper()}: killed at the CPU limit ({opts.time_limit + KILL_GRACE:g} s) inside the "
                  f"solver (exit code {proc.exitcode}); no point returned")
        return PeerOutcome(f"drake-{opts.solver}", opts.solver, False, status, 0.0, wall, -1, None,
                           {"killed": True, "n_intervals_final": problem.n_intervals})
    dm = DrakeModel(problem.robot, problem.scene, object_arm=problem.object_arm)
    N, T, P = msg["N"], msg["T"], msg["P"]
    traj = BsplineTrajectory(_basis(N, T), [P[:, [i]] for i in range(P.shape[1])])
    o = msg["outcome"]
    return PeerOutcome(o["method"], o["solver"], o["success"], o["status"], o["setup_time"], o["solve_time"],
                       o["iterations"], BsplineSolution(traj, dm, N, tuple(problem.robot.joint_names)),
                       {**o["info"], "killed": False})


# --------------------------------------------------------------------------- evaluation
def jerk_cost(solution, density: int = 4) -> float:
    """∫‖d³q/dt³‖² dt [rad²/s⁵] of a trajectory whose acceleration is piecewise linear between its
    knots ``solution.t`` (optplan's transcription, a cubic B-spline): from ``sample`` at
    ``density`` points per interval, exact for such trajectories."""
    t = np.asarray(solution.t, float)
    ts = np.linspace(t[0], t[-1], density * (len(t) - 1) + 1)
    a = solution.sample(ts)["qdd"]
    dt = np.diff(ts)
    return float(np.sum(np.sum(np.diff(a, axis=0) ** 2, axis=1) / dt))


def evaluate(problem: PeerProblem, outcome: PeerOutcome) -> dict:
    """A result row: the outcome's figures, jerk cost, and ``verify``'s checks."""
    row = {"problem": problem.name, "method": outcome.method, "solver": outcome.solver, "success": outcome.success,
           "status": outcome.status, "setup_s": outcome.setup_time, "solve_s": outcome.solve_time,
           "time_s": outcome.setup_time + outcome.solve_time, "iterations": outcome.iterations,
           "n_intervals": problem.n_intervals, "duration_s": problem.duration, **outcome.info}
    sol = outcome.solution
    if sol is None:
        row.update({"jerk": math.nan, "max_closed_chain_residual": math.nan, "min_clearance_m": math.nan,
                    "verified": False, "passed": False})
        return row
    rep = verify(problem.robot, sol, problem.scene, closed_chain=problem.closed_chain, object_arm=problem.object_arm)
    resid = rep.max_closed_chain_residual if problem.closed_chain is not None else 0.0
    verified = bool(resid <= RESIDUAL_TOL and rep.min_clearance_m >= 0.0)  # the pipeline's criterion
    row.update({"jerk": jerk_cost(sol), "max_closed_chain_residual": rep.max_closed_chain_residual,
                "min_clearance_m": rep.min_clearance_m, "min_clearance_pair": rep.min_clearance_pair,
                "max_position_limit_violation": rep.max_position_limit_violation,
                "max_velocity_limit_violation": rep.max_velocity_limit_violation,
                "limits_ok": bool(rep.max_position_limit_violation <= LIMIT_TOL
                                  and rep.max_velocity_limit_violation <= LIMIT_TOL),
                "verified": verified, "passed": bool(outcome.success and verified)})
    return row


def _problems(names, trials: int, first_trial: int, seed: int, robot: RobotModel,
              segments=("constrained",)) -> list[PeerProblem]:
    out = []
    for name in names:
        if name == "transport":
            out.append(transport_instance(robot, seed=seed))
            continue
        scene = f"ssps_scene{name[5:]}" if name.startswith("scene") and name[5:].isdigit() else name
        for k in range(first_trial, first_trial + trials):
            out += pipeline_segment_instances(scene, k, seed=seed, robot=robot, kinds=segments)
    return out


def _cpu() -> float:
    """CPU time [s] of this process and of its waited-for children."""
    import resource

    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime


def format_row(row: dict) -> str:
    """One result row as a progress line: problem, method, status, time, iterations, verify."""
    return (f"{row['problem']:22s} {row['method']:12s} {row['status'][:40]:40s} {row['time_s']:8.2f} s  "
            f"it={row['iterations']}  verify={'pass' if row['verified'] else 'FAIL'}")


def run(problems=("transport", "scene1"), *, trials: int = 3, first_trial: int = 0, seed: int = 0,
        solvers=("snopt", "ipopt"), optplan_solve: Callable[[PeerProblem], PeerOutcome] | None = None,
        drake_options: dict | None = None, drake_refinements: int = 2, segments=("constrained",), only=(),
        isolate: bool = True, progress: bool = True,
        on_row: Callable[[dict], None] | None = None) -> list[dict]:
    """Solve every problem with ``optplan_solve`` (default :func:`optplan_current`) and with Drake
    under each solver in ``solvers``, paired in this process; returns the rows of :func:`evaluate`.
    ``problems``: "transport", "scene1".."scene3" or scene names (their trials ``first_trial`` …
    ``first_trial + trials − 1``, their segments of the kinds in ``segments``: "constrained",
    "regrasp"); ``only``: if given, the names of the problems to keep (e.g. "ssps_scene1/t0/s3").
    ``drake_options``: fields of
    :class:`~optplan.bench.drake_peer.DrakeOptions` other than ``solver``. ``drake_refinements``:
    closed-chain grid refinements Drake gets (:func:`drake_solve`; default as many as the pipeline's).
    ``isolate``: each Drake solve in a child process with a hard CPU limit (:func:`drake_solve`).
    Each row carries ``wall_s`` and ``cpu_s``: wall and CPU time [s] of the whole method call
    (retries and the method's own checks included; child processes' CPU time included)."""
    from .drake_peer import DrakeOptions

    known = {"transport", "scene1", "scene2", "scene3"}
    from ..scene import available_scenes

    for n in problems:
        if n not in known and n not in available_scenes():
            raise ValueError(f"--problems: unknown problem {n!r} (expected transport, scene1, scene2, scene3 or a scene name)")
    if int(trials) < 1:
        raise ValueError(f"--trials: expected an integer >= 1, got {trials!r}")
    bad = set(segments) - {"constrained", "regrasp"}
    if bad or not segments:
        raise ValueError(f"--segments: expected constrained and/or regrasp, got {','.join(segments)}")
    for s in solvers:
        DrakeOptions(solver=s)  # validates the name
    if solvers:
        from .drake_peer import require_drake

        require_drake()  # fail before any solve when Drake is missing
    solve = optplan_solve or optplan_current
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    probs = _problems(list(problems), int(trials), int(first_trial), int(seed), robot, tuple(segments))
    if only:
        missing = set(only) - {p.name for p in probs}
        if missing:
            raise ValueError(f"--only: no problem named {', '.join(sorted(missing))} (have: "
                             f"{', '.join(p.name for p in probs)})")
        probs = [p for p in probs if p.name in set(only)]
    rows = []
    for i, p in enumerate(probs):
        methods = [solve] + [lambda p, s=s: drake_solve(p, DrakeOptions(solver=s, **(drake_options or {})),
                                                        refinements=drake_refinements, isolate=isolate)
                             for s in solvers]
        for method in methods:
            c0, w0 = _cpu(), time.perf_counter()
            out = method(p)
            cpu, wall = _cpu() - c0, time.perf_counter() - w0
            row = evaluate(p, out)
            row["cpu_s"], row["wall_s"] = cpu, wall
            rows.append(row)
            if on_row:
                on_row(row)
            if progress:
                log.info("[%d/%d] %s", i + 1, len(probs), format_row(row))
    return rows


def _ratio(a, b) -> float:
    return float(a / b) if (b and np.isfinite(a) and np.isfinite(b) and b != 0) else math.nan


def _lim(r: dict) -> float:
    return max(r.get("max_position_limit_violation", math.nan), r.get("max_velocity_limit_violation", math.nan))


def _wall(r: dict) -> float:
    return float(r.get("wall_s", r["time_s"]))


def _finite(f, values) -> float:
    v = [x for x in values if np.isfinite(x)]
    return float(f(v)) if v else math.nan


def _paired(rows: list[dict]) -> list[tuple[dict, dict | None]]:
    """Each row with the optplan row it is paired with: the latest optplan row of the same problem
    before it (the same run), None for optplan rows and unpaired rows."""
    last: dict[str, dict] = {}
    out: list[tuple[dict, dict | None]] = []
    for r in rows:
        if r["method"] == "optplan":
            last[r["problem"]] = r
            out.append((r, None))
        else:
            out.append((r, last.get(r["problem"])))
    return out


def summarize(rows: list[dict], jerk_slack: float = 1.01) -> dict:
    """Per Drake method: problems compared, passes, and on how many problems optplan met the target
    (it passed ``verify``, and Drake either failed or was slower (wall) at a jerk cost no lower than
    optplan's / ``jerk_slack``); median Drake/optplan wall and CPU ratios."""
    base = [r for r in rows if r["method"] == "optplan"]
    out: dict[str, dict] = {"optplan": {"problems": len({r["problem"] for r in base}), "runs": len(base),
                       "passed": sum(bool(r["passed"]) for r in base)}}
    pairs = _paired(rows)
    for m in sorted({r["method"] for r in rows} - {"optplan"}):
        rs = [(r, b) for r, b in pairs if r["method"] == m and b is not None]
        won, wall, cpu = 0, [], []
        for r, b in rs:
            wall.append(_ratio(_wall(r), _wall(b)))
            cpu.append(_ratio(r.get("cpu_s", math.nan), b.get("cpu_s", math.nan)))
            quality = not r["passed"] or (b["jerk"] <= jerk_slack * r["jerk"])
            won += bool(b["passed"] and quality and (not r["passed"] or _wall(b) < _wall(r)))
        out[m] = {"problems": len(rs), "passed": sum(bool(r["passed"]) for r, _ in rs), "optplan_met_target": won,
                  "median_wall_ratio": _finite(np.median, wall), "min_wall_ratio": _finite(np.min, wall),
                  "median_cpu_ratio": _finite(np.median, cpu)}
    return out


def format_report(rows: list[dict]) -> str:
    """The table: per problem and method the figures, the Drake / optplan ratios (wall time, CPU
    time, jerk) and a summary line per Drake solver."""
    hdr = (f"{'problem':18s} {'method':12s} {'status':34s} {'N':>8s} {'wall s':>7s} {'cpu s':>7s} {'iter':>5s} "
           f"{'jerk':>8s} {'cc resid':>8s} {'clear mm':>8s} {'verify':>6s} {'wall/opt':>8s} {'cpu/opt':>7s} "
           f"{'jerk/opt':>8s}")
    lines = [hdr, "-" * len(hdr)]

    def f(v, spec, width):
        return f"{v:{spec}}".rjust(width) if isinstance(v, (int, float)) and math.isfinite(v) else " " * width

    for r, b in _paired(rows):
        rt = _ratio(_wall(r), _wall(b)) if b is not None else math.nan
        rj = _ratio(r["jerk"], b["jerk"]) if b is not None else math.nan
        rc = _ratio(r.get("cpu_s", math.nan), b.get("cpu_s", math.nan)) if b is not None else math.nan
        n0, n1 = r.get("n_intervals", 0), r.get("n_intervals_final", r.get("n_intervals", 0))
        ns = f"{n0}" if n0 == n1 else f"{n0}>{n1}"
        lines.append(f"{r['problem'][:18]:18s} {r['method']:12s} {str(r['status'])[:34]:34s} {ns:>8s} "
                     f"{_wall(r):7.1f} {f(r.get('cpu_s', math.nan), '.1f', 7)} {r['iterations']:5d} "
                     f"{f(r['jerk'], '.2e', 8)} {f(r['max_closed_chain_residual'], '.1e', 8)} "
                     f"{f(1e3 * r['min_clearance_m'], '.1f', 8)} {'pass' if r['passed'] else 'FAIL':>6s} "
                     f"{f(rt, '.3g', 8)} {f(rc, '.3g', 7)} {f(rj, '.3g', 8)}")
    lines.append("N: intervals (first > final attempt); wall/cpu: wall and process CPU time [s] of the whole method "
                 "call (retries, refinements and the method's own verify calls included); verify: converged, "
                 "closed-chain residual <= 1e-6 at 10x the knot density, coal clearance >= 0; x/opt: Drake / optplan "
                 "in the same run")
    summ = summarize(rows)
    o = summ.pop("optplan")
    for m, d in summ.items():
        lines.append(f"summary {m}: optplan passed {o['passed']}/{o['runs']} runs, {m} passed {d['passed']}/{d['problems']}; "
                     f"optplan faster at equal or better verified quality on {d['optplan_met_target']}/{d['problems']}; "
                     f"wall ratio {m}/optplan median {d['median_wall_ratio']:.3g} (min {d['min_wall_ratio']:.3g}), "
                     f"CPU ratio median {d['median_cpu_ratio']:.3g}")
    lines.append("target: optplan faster than the Drake peer on every problem at equal or better verified quality")
    return "\n".join(lines)


def save_json(rows: list[dict], path: str, command: str | None = None) -> None:
    """``{"command", "rows", "summary"}`` to ``path`` (rows as :func:`evaluate` makes them, non-finite
    numbers as null; the summary of :func:`summarize`)."""
    def clean(v):
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, (np.floating, np.integer, np.bool_)):
            v = v.item()
        if isinstance(v, float) and not math.isfinite(v):
            return None
        return v

    from .._io import write_json

    write_json(path, {"command": command, "rows": [clean(r) for r in rows], "summary": clean(summarize(rows))})
