"""optplan vs Drake's ``KinematicTrajectoryOptimization`` on the same problems, in one run.

``optplan bench drake [--problems transport,scene1] [--trials N] [--solvers snopt,ipopt] [--json PATH]``

Problems (:class:`PeerProblem`): the closed-chain transport problem (scene ``transport``, the
straight-line IK warm start of ``examples/closed_chain_transport.py``, N = 50, 60 s) and the
constrained segments of the pipeline on the perturbed trials of the assembly scenes (planner path
→ :func:`optplan.pipeline.shortcut_constrained` → the arc-length resampled, manifold-projected
warm start of ``OptProblem.set_initial_path``, with the pipeline's N and duration). Every method
gets the same start/goal, duration, margin, collision geometry and warm start, and every result
is checked by :func:`optplan.verify.verify` (closed-chain residual at 10× the knot density ≤ 1e-6,
coal clearance ≥ 0) and its jerk cost ``∫‖d³q/dt³‖² dt`` computed from the trajectory itself.

The optplan side is a callable ``optplan_solve(problem) -> PeerOutcome`` (default
:func:`optplan_current`: the transport example's single ``OptProblem`` solve, and for a pipeline
segment the pipeline's own per-segment optimization with its retries), so that another optimizer
can be benchmarked against the same peer by passing another callable.
"""
from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Callable

import numpy as np

from ..problem import ClosedChain
from ..robot import RobotModel
from ..scene import Scene
from ..verify import verify

__all__ = ["PeerProblem", "PeerOutcome", "transport_instance", "pipeline_segment_instances", "optplan_current",
           "drake_solve", "jerk_cost", "evaluate", "run", "format_report", "RESIDUAL_TOL"]
log = logging.getLogger(__name__)

RESIDUAL_TOL = 1e-6
LIMIT_TOL = 1e-6  # [rad], [rad/s]: joint-limit violations between knots reported (not part of the pass)


@dataclass
class PeerProblem:
    """One trajectory problem both optimizers solve: ``q_knots`` ((N+1) × nj) the warm start at N
    uniform intervals over ``duration`` [s] (its first/last rows are the rest configurations),
    ``closed_chain`` (or None), ``margin`` [m], ``object_arm`` (the arm the held object follows),
    ``path`` the planner path the warm start was resampled from (pipeline segments)."""

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

    @property
    def n_intervals(self) -> int:
        return int(self.q_knots.shape[0] - 1)


@dataclass
class PeerOutcome:
    """What a method returns for a problem: ``solution`` is anything :func:`optplan.verify.verify`
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


def _closed_chain(scene: Scene) -> ClosedChain:
    arms = list(scene.object.grasps)
    return ClosedChain.from_grasps(scene.object.grasps[arms[0]], scene.object.grasps[arms[1]], arms[0], arms[1])


def _warm_start_knots(prob) -> np.ndarray:
    """The joint knots of an ``OptProblem``'s initial guess (what IPOPT starts from)."""
    return np.asarray(prob.tp.unpack(prob.initial_guess)["q"], float)


# --------------------------------------------------------------------------- problems
def transport_instance(robot: RobotModel | None = None, *, knots: int = 50, duration: float = 60.0,
                       margin: float = 0.02, seed: int = 0) -> PeerProblem:
    """The closed-chain transport problem of ``examples/closed_chain_transport.py``."""
    from ..collision import CollisionChecker
    from ..tasks import transport_initial_path

    robot = robot or RobotModel.from_name("tcbirrt_dual_arm")
    scene = Scene.load("transport")
    rng = np.random.default_rng(seed)
    Q = transport_initial_path(robot, scene, knots, rng, checker=CollisionChecker(robot, scene))
    if Q is None:
        raise RuntimeError("transport: no collision-free start grasp whose straight-line IK path reaches the goal")
    return PeerProblem("transport", "transport", robot, scene, Q, float(duration), _closed_chain(scene), margin,
                       next(iter(scene.object.grasps)), None, {"seed": seed, "knots": knots})


def pipeline_segment_instances(scene_name: str, trial: int, *, seed: int = 0, robot: RobotModel | None = None,
                               options=None) -> list[PeerProblem]:
    """The constrained segments of the pipeline on trial ``trial`` of ``scene_name`` (trials and
    seeds as ``optplan bench warmstart``): planner path → shortcut (the pipeline's RNG sequence) →
    ``OptProblem.set_initial_path`` warm start on the pipeline's N and duration. Empty when the
    plan fails."""
    from ..collision import CollisionChecker
    from ..pipeline import PipelineOptions, shortcut_constrained
    from ..planners import make_planner
    from ..problem import OptProblem
    from .trials import TrialGenerator

    opts = options or PipelineOptions()
    robot = robot or RobotModel.from_name("tcbirrt_dual_arm")
    scene = Scene.load(scene_name)
    tr = TrialGenerator(robot, scene).generate(int(trial), int(seed))
    kw = dict(opts.planner_options) if opts.planner == "tcbirrt" else {}
    plan = make_planner(opts.planner, robot, scene, **kw).plan(tr.q_start, tr.q_goal, time_limit=opts.plan_time_limit,
                                                               seed=tr.seed)
    if not plan.success:
        log.warning("%s trial %d: plan failed (%s)", scene_name, trial, plan.status.value)
        return []
    rng = np.random.default_rng(tr.seed)  # run_pipeline's RNG: consumed by the shortcuts in segment order
    checker = CollisionChecker(robot, scene)
    cc = _closed_chain(scene)
    out = []
    for i, seg in enumerate(plan.segments):
        seg_path = np.asarray(plan.path[seg.start:seg.stop + 1])
        if seg.kind != "constrained" or len(seg_path) < 2 or np.abs(seg_path[-1] - seg_path[0]).max() < 1e-9:
            continue
        seg_path = shortcut_constrained(robot, scene, seg_path, rng, opts.shortcut_attempts, checker)
        # the pipeline's grid and duration for a constrained segment (PipelineOptions docstring)
        length = float(np.linalg.norm(np.diff(seg_path, axis=0), axis=1).sum())
        T = max(opts.min_duration, length / (opts.speed_fraction * float(np.min(robot.velocity_limit))))
        N = int(np.clip(np.ceil(length / opts.max_interval_step), opts.n_intervals, opts.max_intervals))
        prob = OptProblem(robot, n_intervals=N, duration=T)
        prob.set_initial_path(seg_path, cc)
        out.append(PeerProblem(f"{scene.name}/t{trial}/s{i}", "segment", robot, scene, _warm_start_knots(prob), T, cc,
                               opts.margin, next(iter(scene.object.grasps)), seg_path,
                               {"scene": scene.name, "trial": int(trial), "segment": i, "path_length_rad": length}))
    return out


# --------------------------------------------------------------------------- methods
def optplan_current(problem: PeerProblem) -> PeerOutcome:
    """optplan's current optimizer, as the product runs it: the transport example's single
    B-spline segment NLP solve (:class:`optplan.problem.segment.SplineSegmentProblem`), or for a pipeline segment
    :func:`optplan.pipeline.optimize_segments` on that one segment (its retries included; times
    and iterations summed over its attempts). ``setup_time``: problem declaration + NLP build +
    solver creation."""
    if problem.kind == "transport":
        from ..problem import ClosedChain
        from ..problem.segment import SegmentSpec, SplineSegmentProblem

        t0 = time.perf_counter()
        sc, q = problem.scene, np.asarray(problem.q_knots)
        arms = list(sc.object.grasps)
        cc = ClosedChain.from_grasps(sc.object.grasps[arms[0]], sc.object.grasps[arms[1]], arms[0], arms[1])
        prob = SplineSegmentProblem(problem.robot, sc, SegmentSpec(len(q) - 1, problem.duration, q[0], q[-1], cc,
                                                                   margin=problem.margin, object_arm=arms[0]))
        prob.set_initial(q)
        declare = time.perf_counter() - t0
        sol = prob.solve()
        return PeerOutcome("optplan", "ipopt", bool(sol.success), sol.status.value, declare + sol.setup_time,
                           sol.wall_time, int(sol.iterations), sol, {"attempts": 1})
    from ..pipeline import PipelineOptions, optimize_segments
    from ..planners.base import PathSegment

    opts = PipelineOptions(shortcut_attempts=0)  # the path is already shortcut
    path = problem.path
    plan = SimpleNamespace(path=path, segments=[PathSegment("constrained", 0, len(path) - 1)])
    t0 = time.perf_counter()
    results, _ = optimize_segments(problem.robot, problem.scene, plan, opts, np.random.default_rng(0))
    wall = time.perf_counter() - t0
    sol = results[0].solution
    return PeerOutcome("optplan", "ipopt", bool(sol.success), sol.status.value, float(sol.setup_time),
                       float(sol.wall_time), int(sol.iterations), sol,
                       {"wall_time_s": wall, "n_intervals_final": int(len(sol.t) - 1)})


def drake_solve(problem: PeerProblem, options=None, model=None) -> PeerOutcome:
    """Drake's ``KinematicTrajectoryOptimization`` (:mod:`.drake_peer`) on ``problem``; the plant
    and scene-graph construction counts as setup."""
    from .drake_peer import DrakeModel, DrakeOptions, solve_drake

    opts = options or DrakeOptions()
    t0 = time.perf_counter()
    dm = model or DrakeModel(problem.robot, problem.scene, object_arm=problem.object_arm)
    build = time.perf_counter() - t0
    r = solve_drake(dm, problem.q_knots, problem.duration, closed_chain=problem.closed_chain, margin=problem.margin,
                    options=opts)
    return PeerOutcome(f"drake-{r.solver}", r.solver, r.success, r.status, build + r.setup_time, r.solve_time,
                       r.iterations, r.solution,
                       {"model_build_s": build, "n_variables": r.n_variables, "n_constraints": r.n_constraints,
                        "missing_pairs": len(dm.missing_pairs), "extra_pairs": len(dm.extra_pairs),
                        "candidate_pairs": dm.n_candidate_pairs, **r.info})


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


def _problems(names, trials: int, first_trial: int, seed: int, robot: RobotModel) -> list[PeerProblem]:
    out = []
    for name in names:
        if name == "transport":
            out.append(transport_instance(robot, seed=seed))
            continue
        scene = f"ssps_scene{name[5:]}" if name.startswith("scene") and name[5:].isdigit() else name
        for k in range(first_trial, first_trial + trials):
            out += pipeline_segment_instances(scene, k, seed=seed, robot=robot)
    return out


def run(problems=("transport", "scene1"), *, trials: int = 3, first_trial: int = 0, seed: int = 0,
        solvers=("snopt", "ipopt"), optplan_solve: Callable[[PeerProblem], PeerOutcome] | None = None,
        drake_options: dict | None = None, progress: bool = True, on_row: Callable[[dict], None] | None = None
        ) -> list[dict]:
    """Solve every problem with ``optplan_solve`` (default :func:`optplan_current`) and with Drake
    under each solver in ``solvers``, paired in this process; returns the rows of :func:`evaluate`.
    ``problems``: "transport", "scene1".."scene3" or scene names (their trials ``first_trial`` …
    ``first_trial + trials − 1``, constrained segments). ``drake_options``: fields of
    :class:`~optplan.bench.drake_peer.DrakeOptions` other than ``solver``."""
    from .drake_peer import DrakeOptions

    known = {"transport", "scene1", "scene2", "scene3"}
    from ..scene import available_scenes

    for n in problems:
        if n not in known and n not in available_scenes():
            raise ValueError(f"--problems: unknown problem {n!r} (expected transport, scene1, scene2, scene3 or a scene name)")
    if int(trials) < 1:
        raise ValueError(f"--trials: expected an integer >= 1, got {trials!r}")
    for s in solvers:
        DrakeOptions(solver=s)  # validates the name
    if solvers:
        from .drake_peer import require_drake

        require_drake()  # fail before any solve when Drake is missing
    solve = optplan_solve or optplan_current
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    probs = _problems(list(problems), int(trials), int(first_trial), int(seed), robot)
    rows = []
    for i, p in enumerate(probs):
        methods = [solve] + [lambda p, s=s: drake_solve(p, DrakeOptions(solver=s, **(drake_options or {})))
                             for s in solvers]
        for method in methods:
            c0 = time.process_time()
            out = method(p)
            cpu = time.process_time() - c0
            row = evaluate(p, out)
            row["cpu_s"] = cpu
            rows.append(row)
            if on_row:
                on_row(row)
            if progress:
                print(f"[{i + 1}/{len(probs)}] {p.name:22s} {row['method']:12s} {row['status'][:40]:40s} "
                      f"{row['time_s']:8.2f} s  it={row['iterations']}  verify={'pass' if row['verified'] else 'FAIL'}",
                      flush=True)
    return rows


def _ratio(a, b) -> float:
    return float(a / b) if (b and np.isfinite(a) and np.isfinite(b) and b != 0) else math.nan


def _lim(r: dict) -> float:
    return max(r.get("max_position_limit_violation", math.nan), r.get("max_velocity_limit_violation", math.nan))


def format_report(rows: list[dict]) -> str:
    """The table: per problem and method the figures, and Drake / optplan ratios (time, jerk)."""
    hdr = (f"{'problem':22s} {'method':12s} {'status':34s} {'setup s':>8s} {'solve s':>8s} {'cpu s':>7s} {'iter':>5s} "
           f"{'jerk':>9s} {'cc resid':>9s} {'clear mm':>8s} {'lim viol':>8s} {'verify':>6s} {'t/optplan':>9s} {'cpu/opt':>7s} {'jerk/opt':>8s}")
    lines = [hdr, "-" * len(hdr)]
    base = {}
    for r in rows:
        if r["method"] == "optplan":
            base[r["problem"]] = r
    for r in rows:
        b = base.get(r["problem"])
        rt = _ratio(r["time_s"], b["time_s"]) if b and r is not b else math.nan
        rj = _ratio(r["jerk"], b["jerk"]) if b and r is not b else math.nan
        rc = _ratio(r.get("cpu_s", math.nan), b.get("cpu_s", math.nan)) if b and r is not b else math.nan
        lines.append(f"{r['problem']:22s} {r['method']:12s} {str(r['status'])[:34]:34s} {r['setup_s']:8.2f} "
                     f"{r['solve_s']:8.2f} {r.get('cpu_s', math.nan):7.1f} {r['iterations']:5d} {r['jerk']:9.2e} "
                     f"{r['max_closed_chain_residual']:9.1e} {1e3 * r['min_clearance_m']:8.1f} {_lim(r):8.1e} "
                     f"{'pass' if r['passed'] else 'FAIL':>6s} {'' if math.isnan(rt) else f'{rt:9.3g}':>9s} "
                     f"{'' if math.isnan(rc) else f'{rc:7.3g}':>7s} {'' if math.isnan(rj) else f'{rj:8.3g}':>8s}")
    lines.append("verify: converged, closed-chain residual <= 1e-6 at 10x the knot density, coal clearance >= 0; "
                 "lim viol: largest joint position [rad] / velocity [rad/s] limit violation there; t/optplan = (setup + solve) wall time of the method / that of optplan, same run; "
                 "cpu: process CPU time of the whole method call (optplan: its verify calls included)")
    lines.append("target: optplan faster than the Drake peer on every problem at equal or better verified quality")
    return "\n".join(lines)


def save_json(rows: list[dict], path: str) -> None:
    def clean(v):
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, (np.floating, np.integer, np.bool_)):
            return v.item()
        return v

    with open(path, "w") as f:
        json.dump([{k: clean(v) for k, v in r.items()} for r in rows], f, indent=2)
