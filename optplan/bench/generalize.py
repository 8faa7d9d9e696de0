"""Generalisation of the pipeline: plan → optimize → verify on scenes the optimizer was not tuned
on, with each scene's own robot (the scene's ``robot`` field: a shipped model or one of
example-robot-data's, e.g. the two-Panda ``dual_panda``).

``optplan bench generalize --scene suite,stress,panda_shelf --trials 5 --out DIR``
``optplan bench generalize --robot models/robots/files/dual_ur5.toml --trials 5 --out DIR``

* ``suite`` = the hard-scene suite (``hard_*``), ``stress`` = the stress scenes (``stress_*``),
  ``panda`` = the dual-Panda scenes (``panda_*``), ``own`` = the scenes of robots loaded from
  robot files (``own_*``), ``floating`` = the free-floating carry scenes (``floating_*``: the job of
  :mod:`optplan.floating_pipeline`, start = the scene's witness, goal perturbed per trial); any
  scene name works too. ``--robot`` runs every trial on that robot
  (a robot file or URDF path; without ``--scene``, on the scenes made for it); the summary adds
  the process's peak memory.
* Planner: TCBiRRT, ``variant="improved"`` (the hard scenes' planner), edges checked every 0.05 rad,
  ``--time-limit`` [s] per query; the sampling box and step scale with the robot's reach.
* Per trial: :func:`optplan.pipeline.run_pipeline` with the product's defaults (B-spline segment
  NLP, its retry policy, IPOPT capped at ``--ipopt-max-wall-time`` per solve). A trial the
  planner does not solve counts as "no plan", not as an optimizer failure.
* ``DIR/results.jsonl``: one line per (scene, trial), the same fields as ``optplan bench
  warmstart`` (mode ``warm``) plus the robot, its collision-pair count and the attempts per
  segment; resumable. ``DIR/summary.txt``: per scene, planner successes, optimizer converged and
  verified among them, optimization wall/CPU time per trial (median / p95), IPOPT iterations and
  the NLP attempts by reason (``initial``, ``collision``, ``finer-grid``, ``refine``,
  ``fallback-knots``), next to the targets (≥ 95 % of planned trials; median ≤ 1 s, p95 ≤ 3 s).
"""
from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .. import interrupt
from .._io import append_line, write_json, write_text

if TYPE_CHECKING:
    pass

__all__ = ["GeneralizeConfig", "expand", "run", "summarize", "format_summary", "TARGET_SUCCESS"]
log = logging.getLogger(__name__)

#: target: the optimizer succeeds (converged and verified) on this fraction of the planned trials
TARGET_SUCCESS = 0.95
GROUPS = {"suite": "hard_", "stress": "stress_", "panda": "panda_", "own": "own_", "floating": "floating_"}


@dataclass
class GeneralizeConfig:
    """Configuration of ``optplan bench generalize``."""

    #: Scene groups: ``"suite"`` (hard scenes), ``"stress"`` (stress scenes), ``"panda"`` (two Pandas).
    scenes: list = field(default_factory=lambda: ["suite", "stress", "panda"])
    #: Trials per scene [count].
    trials: int = 5
    #: Index of the first trial [index] (to resume or split a run).
    first_trial: int = 0
    #: Base seed of the trials (trial i uses ``SeedSequence(seed, spawn_key=(i,))``).
    seed: int = 0
    #: Output directory.
    out: str = "bench_generalize"
    #: Planning time limit per query [s].
    time_limit: float = 10.0
    #: The clock of ``time_limit``: ``"cpu"`` (the planner's CPU seconds: planning rates do not depend on
    #: the machine's load) or ``"wall"``. The optimization is timed on both clocks either way.
    clock: str = "cpu"
    #: IPOPT's wall-clock cap per solve [s].
    ipopt_max_wall_time: float = 60.0
    #: TCBiRRT variant, ``"paper"`` or ``"improved"``.
    planner_variant: str = "improved"
    #: Show a progress bar.
    progress: bool = True
    #: The robot of every trial: a robot file or URDF path, or a model name (None: each scene's own
    #: robot). With a robot and no scenes given, the scenes in ``models/scenes`` made for it.
    robot: str | None = None
    #: Floating scenes with a goal in the world: end at the initial base attitude (restoration; None:
    #: each scene's ``[extra] restore_attitude``); scenes with a base-frame goal keep their own.
    restore_attitude: bool | None = None


def scenes_for_robot(robot: str) -> list[str]:
    """The scenes of ``models/scenes`` whose ``robot`` is ``robot`` (a name, or a path compared
    resolved; a path also matches a scene naming its file's stem)."""
    from ..model.robot_file import is_robot_path
    from ..scene import Scene, available_scenes

    def same(a: str, b: str) -> bool:
        if is_robot_path(a) and is_robot_path(b):
            return Path(a).expanduser().resolve() == Path(b).expanduser().resolve()
        if is_robot_path(a) != is_robot_path(b):
            path, name = (a, b) if is_robot_path(a) else (b, a)
            return Path(path).stem == name
        return a == b
    out = []
    for n in available_scenes():
        try:
            sc = Scene.load(n)
        except Exception:   # a scene that does not load (e.g. a missing optional robot) is not one
            continue
        if sc.robot is not None and same(robot, sc.robot):
            out.append(n)
    return out


def expand(names) -> list[str]:
    """Scene names from ``suite`` / ``stress`` / ``panda`` groups and plain names (validated)."""
    from ..scene import available_scenes

    known = available_scenes()
    out: list[str] = []
    for s in (str(n).strip() for n in names):
        if not s:
            continue
        group = [k for k in known if k.startswith(GROUPS[s])] if s in GROUPS else None
        if group is None:
            if s not in known:
                raise ValueError(f"--scene: unknown scene {s!r} (groups: {', '.join(GROUPS)}; scenes: "
                                 f"{', '.join(known)})")
            group = [s]
        out += [g for g in group if g not in out]
    if not out:
        raise ValueError("--scene: no scene given")
    return out


_W: dict = {}


def _robot(name: str):
    from ..model.example_robots import load_robot

    if name not in _W:
        _W[name] = load_robot(name)   # shipped, example-robot-data's, robot file or URDF path
    return _W[name]


def run_trial(scene_name: str, index: int, cfg: GeneralizeConfig) -> dict:
    """One (scene, trial): the result line (see the module docstring)."""
    from ..pipeline import PLANNER_DEFAULTS, PipelineOptions, run_pipeline
    from ..scene import Scene
    from ..trials import TrialGenerator
    from .warmstart import _finite, _path_hash, _segment_rows

    scene = Scene.load(scene_name)
    robot = _robot(cfg.robot or scene.robot or "tcbirrt_dual_arm")
    scene.check_robot(robot)   # a clear error, not a traceback deep in a trial
    line = {"scene": scene_name, "trial": int(index), "mode": "warm", "seed": int(cfg.seed), "robot": robot.name,
            "n_collision_pairs": len(robot.collision_pairs), "time_limit_s": float(cfg.time_limit),
            "ipopt_max_wall_time_s": float(cfg.ipopt_max_wall_time), "planner_variant": cfg.planner_variant,
            "plan_clock": cfg.clock}
    if robot.is_floating:
        return {**line, **_floating_trial(robot, scene, index, cfg)}
    t0 = time.perf_counter()
    try:
        trial = TrialGenerator(robot, scene).generate(index, cfg.seed)
    except Exception as exc:  # no valid start/goal: no plan, no optimization
        return {**line, "success": False, "plan_ok": False, "plan_status": "no_trial", "opt_status": "not_run",
                "error": f"{type(exc).__name__}: {exc}", "segments": []}
    opts = PipelineOptions(plan_time_limit=float(cfg.time_limit), plan_clock=cfg.clock,
                           ipopt_max_wall_time=float(cfg.ipopt_max_wall_time),
                           planner_options=PLANNER_DEFAULTS["tcbirrt"] + (("variant", cfg.planner_variant),))
    c0, w0 = time.process_time(), time.perf_counter()
    res, err = None, None
    try:
        res = run_pipeline(robot, scene, trial.q_start, trial.q_goal, opts, seed=int(trial.seed))
    except Exception as exc:  # recorded, not fatal: the run goes on
        log.warning("%s trial %d: pipeline raised %s: %s", scene_name, index, type(exc).__name__, exc)
        err = f"{type(exc).__name__}: {exc}"
    line.update({"wall_time_s": time.perf_counter() - w0, "cpu_time_s": time.process_time() - c0,
                 "trial_generation_s": w0 - t0, "peak_rss_mb": _peak_rss_mb()})
    if res is None:
        return {**line, "success": False, "plan_ok": None, "plan_status": "error", "opt_status": "error",
                "error": err, "segments": []}
    line.update({k: _finite(v) for k, v in res.to_dict().items()})
    plan = res.plan
    line.update({"plan_ok": bool(plan is not None and plan.success), "plan_hash": _path_hash(res.plan),
                 "converged": bool(res.segments) and all(s.solution.success for s in res.segments),
                 "segments": _segment_rows(res), "error": None})
    return line


def _floating_trial(robot, scene, index: int, cfg: GeneralizeConfig) -> dict:
    """One trial of a free-floating scene (:func:`optplan.floating_pipeline.run_floating_pipeline`)."""
    from ..floating_pipeline import options_for_scene, run_floating_pipeline, scene_start, trial_goal
    from .warmstart import _finite

    # restoration is for a goal in the world; a scene whose goal is in the base frame keeps its own
    world = (scene.extra or {}).get("target_frame", "world") == "world"
    restore = cfg.restore_attitude if world else None
    c0, w0 = time.process_time(), time.perf_counter()
    res = run_floating_pipeline(robot, scene, scene_start(robot, scene), trial_goal(scene, index, cfg.seed),
                                options_for_scene(scene, restore_attitude=restore,
                                                  plan_time_limit=float(cfg.time_limit)),
                                seed=int(cfg.seed) + int(index))
    rep, sol = res.report, res.solution
    return {"wall_time_s": time.perf_counter() - w0, "cpu_time_s": time.process_time() - c0,
            "peak_rss_mb": _peak_rss_mb(), "success": res.success, "plan_ok": res.plan.success,
            "plan_status": res.plan.status.value, "plan_time_s": _finite(res.plan.time_s),
            "converged": bool(sol is not None and sol.success), "opt_status": sol.status.value if sol else "not_run",
            "opt_wall_s": _finite(res.opt_wall_s), "opt_cpu_s": _finite(res.opt_cpu_s),
            "opt_iterations": sol.iterations if sol else None,
            "max_closed_chain_residual": _finite(rep.max_closed_chain_residual) if rep else None,
            "min_clearance_m": _finite(rep.min_clearance_m) if rep else None,
            "final_base_attitude_error_rad": _finite(rep.final_base_attitude_error_rad) if rep else None,
            "object_goal_error": [_finite(v) for v in res.goal_error],
            "segments": [{"kind": "constrained", "attempts": [{"reason": f"N={n}"} for n, _, _ in res.attempts],
                          "failure": res.attempts[-1][2] if res.attempts and res.attempts[-1][2] else []}],
            "error": res.plan.message or None}


def _peak_rss_mb() -> float | None:
    """Peak resident memory of this process so far [MB] (``ru_maxrss``; None where unavailable)."""
    try:
        import resource
        import sys

        kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return float(kb) / (1024.0 * 1024.0 if sys.platform == "darwin" else 1024.0)
    except (ImportError, OSError):
        return None


def _done(rows: list[dict], cfg: GeneralizeConfig) -> set:
    return {(r["scene"], int(r["trial"])) for r in rows
            if r.get("seed") == cfg.seed and r.get("time_limit_s") == float(cfg.time_limit)
            and r.get("ipopt_max_wall_time_s") == float(cfg.ipopt_max_wall_time)
            and r.get("planner_variant") == cfg.planner_variant and r.get("plan_clock", "wall") == cfg.clock}


def run(cfg: GeneralizeConfig) -> list[dict]:
    """Run (or resume) the benchmark; writes ``results.jsonl`` and ``summary.txt`` / ``.json``. The
    output folder is held for the run (one writer)."""
    from .folder import folder_lock

    with folder_lock(cfg.out):
        return _run_locked(cfg)


def _run_locked(cfg: GeneralizeConfig) -> list[dict]:
    from .tcbirrt import _repair_tail, load_results

    scenes = expand(cfg.scenes) if cfg.scenes else []
    if not scenes:
        if cfg.robot is None:
            raise ValueError("--scene: no scene given")
        scenes = scenes_for_robot(cfg.robot)
        if not scenes:
            raise ValueError(f"--robot {cfg.robot!r}: no scene in models/scenes is made for it; pass --scene")
    if cfg.clock not in ("cpu", "wall"):
        raise ValueError(f"clock: expected 'cpu' or 'wall', got {cfg.clock!r}")
    if not isinstance(cfg.trials, int) or cfg.trials < 1:
        raise ValueError(f"--trials: expected an integer >= 1, got {cfg.trials!r}")
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "results.jsonl"
    _repair_tail(path)
    done = _done(load_results(path), cfg)
    units = [(s, i) for s in scenes for i in range(cfg.first_trial, cfg.first_trial + cfg.trials) if (s, i) not in done]
    bar = None
    if cfg.progress and units:
        from tqdm import tqdm

        bar = tqdm(total=len(units), desc="bench generalize", unit="trial")
    n_all = len(scenes) * cfg.trials
    with open(path, "a") as f:
        for k, (s, i) in enumerate(units):
            interrupt.progress(n_all - len(units) + k, n_all, "trials")
            line = run_trial(s, i, cfg)
            with interrupt.deferred():   # the line written and the count the interruption prints agree
                append_line(f, json.dumps(line), path)
                interrupt.progress(n_all - len(units) + k + 1, n_all, "trials")
            if bar is not None:
                bar.update(1)
                bar.set_postfix_str(f"{s} #{i} {'ok' if line.get('success') else line.get('opt_status')}")
    if bar is not None:
        bar.close()
    keep = {}
    for r in load_results(path):
        if (r["scene"], int(r["trial"])) in _done([r], cfg) and r["scene"] in scenes \
                and cfg.first_trial <= int(r["trial"]) < cfg.first_trial + cfg.trials:
            keep[(r["scene"], int(r["trial"]))] = r
    rows = [keep[k] for k in sorted(keep)]
    summ = summarize(rows)
    write_json(out / "summary.json", summ)
    write_text(out / "summary.txt", format_summary(summ) + "\n")
    return rows


def _stats(v) -> dict:
    v = np.asarray([x for x in v if x is not None and math.isfinite(x)], float)
    if not v.size:
        return {"median": None, "p95": None, "max": None}
    return {"median": float(np.median(v)), "p95": float(np.percentile(v, 95)), "max": float(v.max())}


def _group(rows: list[dict]) -> dict:
    planned = [r for r in rows if r.get("plan_ok")]
    ok = [r for r in planned if r.get("success")]
    attempts: dict = {}
    failures: dict = {}
    for r in planned:
        for s in r.get("segments", []):
            for a in s.get("attempts", []):
                attempts[a["reason"]] = attempts.get(a["reason"], 0) + 1
            for why in s.get("failure", []):
                key = f"{s['kind']}:{why}"
                failures[key] = failures.get(key, 0) + 1
    return {"trials": len(rows), "planned": len(planned), "success": len(ok),
            "converged": sum(1 for r in planned if r.get("converged")),
            "success_rate": len(ok) / len(planned) if planned else None,
            "opt_wall_s": _stats([r.get("opt_wall_s") for r in planned]),
            "opt_cpu_s": _stats([r.get("opt_cpu_s") for r in planned]),
            "iterations": _stats([r.get("opt_iterations") for r in planned]),
            "plan_time_s": _stats([r.get("plan_time_s") for r in planned]),
            "attempts": dict(sorted(attempts.items())), "failures": failures,
            "n_collision_pairs": max((r.get("n_collision_pairs", 0) for r in rows), default=0),
            "peak_rss_mb": max((r["peak_rss_mb"] for r in rows if r.get("peak_rss_mb") is not None), default=None),
            "robot": rows[0].get("robot") if rows else None}


def summarize(rows: list[dict]) -> dict:
    """Per scene and ``all``: :func:`_group` figures."""
    scenes = sorted({r["scene"] for r in rows})
    out = {s: _group([r for r in rows if r["scene"] == s]) for s in scenes}
    out["all"] = _group(rows)
    return out



def _attempts_text(attempts: dict, max_listed: int = 6) -> str:
    """The NLP attempts of a summary row, ``reason count`` each; past ``max_listed`` distinct grid sizes
    (``N=<intervals>``, one per trial when the grid follows the path's length) the sizes are pooled
    into their range and total so that the row stays one line."""
    sizes = {k: v for k, v in attempts.items() if k.startswith("N=") and k[2:].isdigit()}
    if len(sizes) <= max_listed:
        return ", ".join(f"{k} {v}" for k, v in attempts.items())
    ns = sorted(int(k[2:]) for k in sizes)
    rest = [f"{k} {v}" for k, v in attempts.items() if k not in sizes]
    return ", ".join([f"N={ns[0]}-{ns[-1]} {sum(sizes.values())} ({len(ns)} sizes)"] + rest)

def format_summary(summ: dict) -> str:
    f = lambda v, fmt=".2f": "/" if v is None else format(v, fmt)  # noqa: E731
    hdr = (f"{'scene':20s} {'robot':16s} {'pairs':>5s} {'planned':>7s} {'conv':>5s} {'verified':>8s} "
           f"{'opt wall s med/p95':>18s} {'opt CPU s med/p95':>17s} {'iter med/p95':>12s}  attempts")
    lines = ["plan -> optimize -> verify on scenes not tuned on (rates over the trials the planner solved)", hdr,
             "-" * len(hdr)]
    for s, g in summ.items():
        lines.append(f"{s:20s} {str(g['robot'] if s != 'all' else ''):16s} {g['n_collision_pairs'] if s != 'all' else '':>5} "
                     f"{g['planned']:3d}/{g['trials']:<3d} {g['converged']:5d} {g['success']:8d} "
                     f"{f(g['opt_wall_s']['median']):>8s}/{f(g['opt_wall_s']['p95']):<9s} "
                     f"{f(g['opt_cpu_s']['median']):>8s}/{f(g['opt_cpu_s']['p95']):<8s} "
                     f"{f(g['iterations']['median'], '.0f'):>5s}/{f(g['iterations']['p95'], '.0f'):<6s} "
                     + _attempts_text(g["attempts"]))
        if g["failures"] and s != "all":
            lines.append(f"{'':20s} failures: " + ", ".join(f"{k} {v}" for k, v in g["failures"].items()))
    a = summ.get("all", {})
    if a.get("planned"):
        met = a["success_rate"] >= TARGET_SUCCESS
        w = a["opt_wall_s"]
        # the floating-base carry's targets (momentum rows, restoration) are 2 / 6 s; the fixed base's 1 / 3 s
        floating = all(k.startswith(GROUPS["floating"]) for k in summ if k != "all")
        t_med, t_p95 = (2.0, 6.0) if floating else (1.0, 3.0)
        tmet = w["median"] is not None and w["median"] <= t_med and w["p95"] <= t_p95
        lines.append(f"targets: verified {a['success']}/{a['planned']} = {100 * a['success_rate']:.0f}% of planned "
                     f"trials (target >= {100 * TARGET_SUCCESS:.0f}%: {'met' if met else 'NOT met'}); optimization "
                     f"per trial median {f(w['median'])} s / p95 {f(w['p95'])} s wall (target <= {t_med:g} / {t_p95:g} s: "
                     f"{'met' if tmet else 'NOT met'})")
    if a.get("peak_rss_mb") is not None:
        lines.append(f"peak memory of the process: {a['peak_rss_mb']:.0f} MB (target <= 1024 MB: "
                     f"{'met' if a['peak_rss_mb'] <= 1024 else 'NOT met'})")
    return "\n".join(lines)


def command(args) -> int:
    """``optplan bench generalize``."""
    scene_arg = args.scene if args.scene is not None else ("" if args.robot else "suite,stress,panda")
    cfg = GeneralizeConfig(scenes=[s for s in scene_arg.split(",") if s.strip()], trials=args.trials,
                           first_trial=args.first_trial, seed=args.seed, out=args.out, time_limit=args.time_limit,
                           ipopt_max_wall_time=args.ipopt_max_wall_time, clock=args.clock, progress=not args.no_progress,
                           robot=args.robot, restore_attitude=True if args.restore_attitude else None)
    try:
        if cfg.scenes:
            expand(cfg.scenes)
        elif cfg.robot and not scenes_for_robot(cfg.robot):
            raise ValueError(f"--robot {cfg.robot!r}: no scene in models/scenes is made for it; pass --scene")
    except ValueError as exc:
        from ..errors import UsageError

        raise UsageError(str(exc)) from None
    t0 = time.perf_counter()
    rows = run(cfg)
    print(format_summary(summarize(rows)))
    print(f"{len(rows)} result lines in {cfg.out}/results.jsonl; run time {time.perf_counter() - t0:.1f} s")
    return 0


def add_arguments(p) -> None:
    from .. import cli_args as ca

    p.add_argument("--scene", default=None,
                   help="comma-separated scene names or groups: suite (hard_*), stress (stress_*), panda (panda_*), "
                        "own (own_*: robots loaded from robot files); default suite,stress,panda, or with --robot "
                        "the scenes made for that robot")
    p.add_argument("--robot", default=None,
                   help="robot of every trial: a robot file or URDF path, or a model name (default: each scene's)")
    p.add_argument("--trials", type=ca.positive_int, default=5, help="trials per scene")
    p.add_argument("--first-trial", type=ca.nonnegative_int, default=0)
    p.add_argument("--seed", type=ca.nonnegative_int, default=0)
    p.add_argument("--time-limit", type=ca.positive_float, default=10.0, help="planning time limit per query [s]")
    p.add_argument("--clock", choices=["cpu", "wall"], default="cpu",
                   help="the planning time limit in CPU seconds of the planner (default: rates independent of the "
                        "machine's load) or wall-clock seconds")
    p.add_argument("--ipopt-max-wall-time", type=ca.positive_float, default=60.0, metavar="S",
                   help="cap every IPOPT solve at S seconds (default 60)")
    p.add_argument("--out", default="bench_generalize", help="output directory (results.jsonl, summary.txt/json)")
    p.add_argument("--restore-attitude", action="store_true",
                   help="floating scenes with a goal in the world: end at the initial base attitude (default: each "
                        "scene's [extra] restore_attitude, else the plan's arrival attitude)")
    p.add_argument("--no-progress", action="store_true")
