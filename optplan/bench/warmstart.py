"""Warm vs cold start of the trajectory optimization: on every trial of every
scene, the pipeline (:func:`optplan.pipeline.run_pipeline`) runs twice with the same trial and
seed — IPOPT from the TCBiRRT path (``warm``) and from a straight line (``cold``: the task-space
line through IK for closed-chain segments, the joint-space line for regrasps). The plan is
computed in both modes because it defines the segments.

``optplan bench warmstart --scene 1,2,3 --trials 20 --seed 0 --jobs 2 --out DIR [--time-limit 10]``

* Trials come from :class:`optplan.trials.TrialGenerator` (``generate(index, seed)``); the
  pipeline seed is the trial's own seed, so results do not depend on ``--jobs`` or on the order in
  which units run.
* ``DIR/results.jsonl``: one JSON line per (scene, trial, mode), appended as soon as it finishes;
  a killed run resumes without redoing finished lines (a truncated last line is dropped and redone).
  Each line holds :meth:`PipelineResult.to_dict` plus scene, trial, mode, wall and worker CPU time,
  per-segment figures, and a hash of the planned path (warm and cold should share it).
* ``--ipopt-max-wall-time S`` caps every IPOPT solve at S seconds (IPOPT's ``max_wall_time``; a
  capped solve fails with ``Maximum_WallTime_Exceeded``). Default: no cap, only IPOPT's iteration
  limit — some solves then run ~1 s per iteration for 1000 iterations. Lines of runs with different
  caps (or seeds, time limits) are kept apart.
* A trial whose plan fails has no optimization: it counts as "no plan", not as an optimizer failure.
* ``DIR/summary.json`` and ``DIR/summary.txt``: per scene and mode, trials with a plan, optimizer
  success rate (``success``: all segments solved, closed-chain residual <= 1e-6, clearance >= 0),
  IPOPT-converged fraction, IPOPT iterations (median, mean), IPOPT time (median, mean, max), NLP
  setup time (median), failure modes, and for the warm mode the issue's targets.
"""
from __future__ import annotations

import hashlib
import json
import logging
import math
import resource
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import interrupt
from .._io import append_line, write_json, write_text
from .engine import map_unordered, validate_engine
from .folder import folder_lock
from .tcbirrt import _repair_tail, load_results, scene_name

if TYPE_CHECKING:
    pass

__all__ = ["WarmstartConfig", "MODES", "TARGETS", "validate", "pending_units", "run", "summarize", "format_summary"]
log = logging.getLogger(__name__)

MODES = ("warm", "cold")
#: targets for the warm start: fraction of planned trials IPOPT converges on, median IPOPT time [s], and
#: the optimization wall time per trial (setup + solve + verify of every segment) [s], median and p95
TARGETS = {"warm_converged": 0.98, "warm_median_ipopt_s": 1.0, "warm_median_opt_wall_s": 1.0,
           "warm_p95_opt_wall_s": 3.0}
RESIDUAL_TOL = 1e-6


@dataclass
class WarmstartConfig:
    """Configuration of ``optplan bench warmstart``."""

    #: Scene names (``models/scenes/*.toml``) to run.
    scenes: list = field(default_factory=lambda: ["ssps_scene1", "ssps_scene2", "ssps_scene3"])
    #: Trials per scene [count].
    trials: int = 20
    #: Base seed of the trials.
    seed: int = 0
    #: Worker processes [count].
    jobs: int = 1
    #: Output directory.
    out: str = "bench_warmstart"
    #: Planning time limit per query [s].
    time_limit: float = 10.0
    #: Initial guesses to compare: ``"warm"`` (the planner's path) and/or ``"cold"`` (straight line).
    modes: tuple = MODES
    #: Index of the first trial [index] (to resume or split a run).
    first_trial: int = 0
    #: Show a progress bar.
    progress: bool = True
    #: IPOPT's wall-clock cap per solve [s] (None: IPOPT's iteration limit only).
    ipopt_max_wall_time: float | None = None
    #: Free separating-plane normals (``PipelineOptions.fixed_plane_normals = not this``; result lines record
    #: it).
    free_plane_normals: bool = False
    #: ``PipelineOptions.transcription`` (result lines record it).
    transcription: str = "bspline"
    #: ``PipelineOptions.compile_kernels = True`` (else ``"auto"``).
    compile_kernels: bool = False
    #: Processes per trial that optimize its segments side by side (``PipelineOptions.workers``) [count]; None: the
    #: pipeline's default with ``jobs`` = 1, else 1 (the trials already run side by side). Recorded per result line.
    segment_workers: int | None = None
    #: ``PipelineOptions.segment_nlp``: the segment NLP's implementation, ``"optproblem"`` (the only one since
    #: the closed class was removed; result lines record it, lines without it were the closed class's).
    segment_nlp: str = "optproblem"
    #: Write ``DIR/time_distributions.png`` (IPOPT time and iterations per trial).
    plot: bool = True
    #: ``"local"`` (a process pool of ``jobs``) or ``"dask"`` (:mod:`optplan.bench.engine`).
    engine: str = "local"
    #: Dask scheduler address (None: a local cluster of ``jobs`` workers).
    address: str | None = None


def validate(cfg: WarmstartConfig) -> list[str]:
    """Check the configuration; returns the resolved scene names. Raises ``ValueError`` with a
    message naming the bad argument."""
    from ..pipeline_options import check_segment_nlp
    from ..scene import Scene, available_scenes

    if not isinstance(cfg.trials, int) or cfg.trials < 1:
        raise ValueError(f"--trials: expected an integer >= 1, got {cfg.trials!r}")
    if not isinstance(cfg.jobs, int) or cfg.jobs < 1:
        raise ValueError(f"--jobs: expected an integer >= 1, got {cfg.jobs!r}")
    if cfg.segment_workers is not None and (isinstance(cfg.segment_workers, bool)
                                            or not isinstance(cfg.segment_workers, int) or cfg.segment_workers < 1):
        raise ValueError(f"--segment-workers: expected an integer >= 1, got {cfg.segment_workers!r}")
    check_segment_nlp(cfg.segment_nlp, "--segment-nlp")
    validate_engine(cfg.engine, cfg.jobs, cfg.address)
    if not isinstance(cfg.first_trial, int) or cfg.first_trial < 0:
        raise ValueError(f"--first-trial: expected an integer >= 0, got {cfg.first_trial!r}")
    if not (isinstance(cfg.time_limit, (int, float)) and math.isfinite(cfg.time_limit) and cfg.time_limit > 0):
        raise ValueError(f"--time-limit: expected a number > 0, got {cfg.time_limit!r}")
    mw = cfg.ipopt_max_wall_time
    if mw is not None and not (isinstance(mw, (int, float)) and math.isfinite(mw) and mw > 0):
        raise ValueError(f"--ipopt-max-wall-time: expected a number > 0, got {mw!r}")
    modes = list(cfg.modes)
    bad = [m for m in modes if m not in MODES]
    if not modes or bad or len(set(modes)) != len(modes):
        raise ValueError(f"--modes: expected distinct values among {', '.join(MODES)}, got {', '.join(modes) or 'none'}")
    scenes = [scene_name(s) for s in cfg.scenes if str(s).strip()]
    if not scenes:
        raise ValueError("--scene: no scene given")
    known = available_scenes()
    for sc in scenes:
        if sc not in known:
            raise ValueError(f"--scene: unknown scene {sc!r} (known: {', '.join(known)}; 1, 2, 3 = ssps_scene1..3)")
        s = Scene.load(sc)
        if s.object is None or s.start is None or s.goal is None:
            raise ValueError(f"--scene: scene {sc!r} has no [object], [start] and [goal], so no trials")
    if len(set(scenes)) != len(scenes):
        raise ValueError(f"--scene: repeated scene in {', '.join(scenes)}")
    return scenes


# ---------------------------------------------------------------------- worker
_W: dict = {}


def _state(robot_name: str, scene: str) -> dict:
    """Per-process cache of the robots, scenes and trial generators. The robot is the scene's own
    (its ``robot`` field: a shipped model or one of example-robot-data's), else ``robot_name``."""
    from ..model.example_robots import EXAMPLE_ROBOTS, load_example_robot
    from ..model.robot import RobotModel
    from ..scene import Scene
    from ..trials import TrialGenerator

    if scene not in _W:
        sc = Scene.load(scene)
        name = sc.robot or robot_name
        robots = _W.setdefault("robots", {})
        if name not in robots:
            robots[name] = load_example_robot(name) if name in EXAMPLE_ROBOTS else RobotModel.from_name(name)
        _W[scene] = {"scene": sc, "gen": TrialGenerator(robots[name], sc)}
    return _W[scene]


def _finite(v):
    """JSON-friendly: non-finite floats → None."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _path_hash(plan) -> str | None:
    if plan is None or not getattr(plan, "success", False) or len(plan.path) == 0:
        return None
    return hashlib.sha1(np.round(np.asarray(plan.path, float), 9).tobytes()).hexdigest()[:16]


def _segment_rows(res) -> list[dict]:
    out = []
    for s in res.segments:
        sol, rep = s.solution, s.report
        resid = rep.max_closed_chain_residual if s.kind == "constrained" else float("nan")
        reasons = []
        if not sol.success:
            reasons.append("ipopt:" + sol.status.value)
        if s.kind == "constrained" and not (resid <= RESIDUAL_TOL):
            reasons.append("residual")
        if not (rep.min_clearance_m >= 0.0):
            reasons.append("clearance")
        out.append({"kind": s.kind, "arm": s.arm, "status": sol.status.value, "converged": bool(sol.success),
                    "cost": _finite(float(sol.cost)),
                    "iterations": int(sol.iterations), "ipopt_s": float(sol.wall_time),
                    "setup_s": float(sol.setup_time), "n_intervals": int(len(sol.t) - 1),
                    "duration_s": _finite(float(sol.duration)),
                    "max_closed_chain_residual": _finite(float(resid)),
                    "min_clearance_m": _finite(float(rep.min_clearance_m)),
                    "min_clearance_pair": rep.min_clearance_pair, "failure": reasons,
                    "attempts": [{k: (_finite(v) if isinstance(v, float) else v) for k, v in a.items()}
                                 for a in getattr(s, "attempts", [])]})
    return out


def _run_unit(args) -> dict:
    """One (scene, trial, mode): generate the trial, run the pipeline, return the result line."""
    from ..pipeline import PipelineOptions, run_pipeline
    from ..workers import default_workers

    robot_name, scene, index, mode, time_limit, seed, max_wall, fixed_normals, transcription, compile_kernels = args[:10]
    seg_workers = args[10] if len(args) > 10 else None
    segment_nlp = args[11] if len(args) > 11 else "optproblem"
    line = {"segment_nlp": segment_nlp, "scene": scene, "trial": int(index), "mode": mode, "seed": int(seed), "time_limit_s": float(time_limit),
            "ipopt_max_wall_time_s": max_wall, "fixed_plane_normals": bool(fixed_normals),
            "transcription": transcription, "compile_kernels": bool(compile_kernels)}
    w = _state(robot_name, scene)
    t0 = time.perf_counter()
    try:
        trial = w["gen"].generate(index, seed)
    except Exception as exc:   # no valid start/goal: no plan, no optimization
        log.warning("%s trial %d: trial generation failed: %s", scene, index, exc)
        return {**line, "success": False, "plan_ok": False, "plan_status": "no_trial", "opt_status": "not_run",
                "error": f"{type(exc).__name__}: {exc}", "wall_time_s": time.perf_counter() - t0,
                "cpu_time_s": None, "segments": []}
    line.update({"pipeline_seed": int(trial.seed), "regenerations": int(trial.regenerations),
                 "trial_generation_s": time.perf_counter() - t0})
    opts = PipelineOptions(plan_time_limit=float(time_limit), warm_start=(mode == "warm"),
                           fixed_plane_normals=bool(fixed_normals), transcription=transcription,
                           compile_kernels=True if compile_kernels else "auto", workers=seg_workers,
                           segment_nlp=segment_nlp, ipopt_options=PipelineOptions.ipopt_options
                           + (() if max_wall is None else (("max_wall_time", float(max_wall)),)))
    c0, ch0, w0 = time.process_time(), resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    res, err = None, None
    try:
        res = run_pipeline(w["gen"].robot, w["scene"], trial.q_start, trial.q_goal, opts, seed=int(trial.seed))
    except Exception as exc:   # run_pipeline reports failures as statuses; anything else is recorded, not fatal
        log.warning("%s trial %d %s: pipeline raised %s: %s", scene, index, mode, type(exc).__name__, exc)
        err = f"{type(exc).__name__}: {exc}"
    wall = time.perf_counter() - w0
    cpu = time.process_time() - c0
    ch1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    line.update({"segment_workers": opts.workers if opts.workers is not None else default_workers(),
                 "wall_time_s": wall, "cpu_time_s": cpu,
                 "child_cpu_time_s": (ch1.ru_utime + ch1.ru_stime) - (ch0.ru_utime + ch0.ru_stime)})
    if res is None:
        line.update({"success": False, "plan_ok": None, "plan_status": "error", "opt_status": "error",
                     "error": err, "segments": []})
        return line
    d = {k: _finite(v) for k, v in res.to_dict().items()}
    line.update(d)
    plan = res.plan
    line.update({"plan_ok": bool(plan is not None and plan.success), "plan_hash": _path_hash(res.plan),
                 "converged": bool(res.segments) and all(s.solution.success for s in res.segments),
                 "segments": _segment_rows(res), "error": None})
    return line


def _init_pool(level: int = logging.ERROR):
    logging.getLogger("optplan").setLevel(level)


# ---------------------------------------------------------------------- driver
def _key(r: dict) -> tuple:
    return (r["scene"], int(r["trial"]), r["mode"])


def _matches(r: dict, cfg: WarmstartConfig) -> bool:
    mw = None if cfg.ipopt_max_wall_time is None else float(cfg.ipopt_max_wall_time)
    # lines written before the option existed were solved with free normals
    return (r.get("seed") == cfg.seed and r.get("time_limit_s") == float(cfg.time_limit)
            and r.get("ipopt_max_wall_time_s") == mw
            and r.get("fixed_plane_normals", False) == (not cfg.free_plane_normals)
            and r.get("transcription", "knots") == cfg.transcription
            and r.get("compile_kernels", False) == bool(cfg.compile_kernels)
            and r.get("segment_nlp", "closed") == cfg.segment_nlp)


def pending_units(cfg: WarmstartConfig, scenes: list[str], rows: list[dict],
                  robot_name: str = "tcbirrt_dual_arm") -> list[tuple]:
    """The (robot, scene, trial, mode, time_limit, seed, ipopt_max_wall_time, fixed_plane_normals,
    transcription, compile_kernels, segment_workers, segment_nlp) units not yet in ``rows``."""
    done = {_key(r) for r in rows if _matches(r, cfg)}
    mw = None if cfg.ipopt_max_wall_time is None else float(cfg.ipopt_max_wall_time)
    seg_workers = cfg.segment_workers if cfg.segment_workers is not None else (None if cfg.jobs == 1 else 1)
    return [(robot_name, sc, i, m, float(cfg.time_limit), int(cfg.seed), mw, not cfg.free_plane_normals,
             cfg.transcription, bool(cfg.compile_kernels), seg_workers, cfg.segment_nlp)
            for sc in scenes for i in range(cfg.first_trial, cfg.first_trial + cfg.trials) for m in cfg.modes
            if (sc, i, m) not in done]


def run(cfg: WarmstartConfig, robot_name: str = "tcbirrt_dual_arm") -> list[dict]:
    """Run (or resume) the benchmark; writes the summary files and returns the result lines of
    this configuration (scenes, trials, modes, seed, time limit)."""
    scenes = validate(cfg)
    out = Path(cfg.out)
    with folder_lock(out):   # one writer per folder
        return _run_locked(cfg, robot_name, scenes, out)


def _run_locked(cfg: WarmstartConfig, robot_name: str, scenes: list[str], out: Path) -> list[dict]:
    res_path = out / "results.jsonl"
    _repair_tail(res_path)
    units = pending_units(cfg, scenes, load_results(res_path), robot_name)
    write_json(out / "config.json", {**cfg.__dict__, "modes": list(cfg.modes), "scenes": scenes, "robot": robot_name})
    n_all = len(scenes) * cfg.trials * len(cfg.modes)
    log.info("%d pipeline runs to do (%d of %d already in %s)", len(units), n_all - len(units), n_all, res_path)
    bar = None
    if cfg.progress and units:
        from tqdm import tqdm

        bar = tqdm(total=len(units), desc="bench warmstart", unit="run", smoothing=0.05)
    n_ok, n_done = 0, n_all - len(units)
    interrupt.progress(n_done, n_all, "trial runs")
    with open(res_path, "a") as f:
        def write(line):
            nonlocal n_ok, n_done
            with interrupt.deferred():   # the line written and the count the interruption prints agree
                append_line(f, json.dumps(line), res_path)
                n_ok += bool(line.get("success"))
                n_done += 1
                interrupt.progress(n_done, n_all, "trial runs")
            if bar is not None:
                bar.update(1)
                bar.set_postfix_str(f"{line['scene']} #{line['trial']} {line['mode']} "
                                    f"{'ok' if line.get('success') else line.get('opt_status')}; {n_ok} ok")

        for line in map_unordered(_run_unit, units, engine=cfg.engine, jobs=cfg.jobs, address=cfg.address,
                                  initializer=_init_pool, serial_initializer=False):
            write(line)
    if bar is not None:
        bar.close()
    rows = select_rows(load_results(res_path), cfg, scenes)
    summ = summarize(rows)
    write_json(out / "summary.json", summ)
    write_text(out / "summary.txt", format_summary(summ) + "\n")
    if cfg.plot:
        from ..viz.bench_plots import plot_warmstart_distributions

        plot_warmstart_distributions(rows, out / "time_distributions.png")
    return rows


def select_rows(rows: list[dict], cfg: WarmstartConfig, scenes: list[str]) -> list[dict]:
    """The lines of this configuration, one per (scene, trial, mode) (the last one wins)."""
    keep = {}
    for r in rows:
        if (_matches(r, cfg) and r.get("scene") in scenes and r.get("mode") in cfg.modes
                and cfg.first_trial <= int(r["trial"]) < cfg.first_trial + cfg.trials):
            keep[_key(r)] = r
    return [keep[k] for k in sorted(keep)]


# ---------------------------------------------------------------------- statistics
def _stats(vals: list[float | None]) -> dict:
    v = np.asarray([x for x in vals if x is not None], float)
    if v.size == 0:
        return {"n": 0, "median": None, "mean": None, "p95": None, "max": None}
    return {"n": int(v.size), "median": float(np.median(v)), "mean": float(v.mean()),
            "p95": float(np.percentile(v, 95)), "max": float(v.max())}


def _failure_modes(rows: list[dict]) -> dict:
    """``"<segment kind>:<reason>"`` → number of trials (planned, not successful) showing it."""
    out: dict = {}
    for r in rows:
        if not r.get("plan_ok") or r.get("success"):
            continue
        keys = set()
        for s in r.get("segments", []):
            for reason in s.get("failure", []):
                keys.add(f"{s['kind']}:{reason}")
        if r.get("error"):
            keys.add("error")
        if not keys:
            keys.add("other")
        for k in keys:
            out[k] = out.get(k, 0) + 1
    return dict(sorted(out.items(), key=lambda kv: (-kv[1], kv[0])))


def _mode_summary(rows: list[dict]) -> dict:
    planned = [r for r in rows if r.get("plan_ok")]
    succ = [r for r in planned if r.get("success")]
    conv = [r for r in planned if r.get("converged")]
    plan_fail: dict[str, int] = {}
    for r in rows:
        if not r.get("plan_ok"):
            plan_fail[r.get("plan_status", "?")] = plan_fail.get(r.get("plan_status", "?"), 0) + 1
    n_p = len(planned)
    return {
        "n": len(rows), "planned": n_p, "plan_failures": plan_fail,
        "successes": len(succ), "success_rate": len(succ) / n_p if n_p else None,
        "converged": len(conv), "converged_rate": len(conv) / n_p if n_p else None,
        "iterations": _stats([r.get("opt_iterations") for r in planned]),
        "ipopt_time_s": _stats([r.get("opt_time_s") for r in planned]),
        "ipopt_time_successful_s": _stats([r.get("opt_time_s") for r in succ]),
        "setup_time_s": _stats([r.get("opt_setup_time_s") for r in planned]),
        "opt_wall_s": _stats([r.get("opt_wall_s") for r in planned]),
        "opt_cpu_s": _stats([r.get("opt_cpu_s") for r in planned]),
        "wall_time_s": _stats([r.get("wall_time_s") for r in rows]),
        "cpu_time_s": _stats([r.get("cpu_time_s") for r in rows]),
        "max_closed_chain_residual": _stats([r.get("max_closed_chain_residual") for r in planned])["max"],
        "min_clearance_m": (min((r["min_clearance_m"] for r in planned if r.get("min_clearance_m") is not None),
                                default=None)),
        "opt_statuses": {s: sum(1 for r in planned if r.get("opt_status") == s)
                         for s in sorted({r.get("opt_status") for r in planned}, key=str)},
        "failure_modes": _failure_modes(rows),
    }


def _paired(rows: list[dict]) -> dict:
    """Trials where both modes have a plan: how often the plans differ, and on the trials both
    modes solve, median cold/warm ratios of iterations and IPOPT time."""
    by: dict[tuple[str, int], dict[str, dict]] = {}
    for r in rows:
        by.setdefault((r["scene"], int(r["trial"])), {})[r["mode"]] = r
    pairs = [(d["warm"], d["cold"]) for d in by.values() if "warm" in d and "cold" in d
             and d["warm"].get("plan_ok") and d["cold"].get("plan_ok")]
    both = [(w, c) for w, c in pairs if w.get("success") and c.get("success")]
    it = [c["opt_iterations"] / w["opt_iterations"] for w, c in both if w.get("opt_iterations")]
    tm = [c["opt_time_s"] / w["opt_time_s"] for w, c in both if w.get("opt_time_s")]
    return {"pairs": len(pairs), "plans_differ": sum(1 for w, c in pairs if w.get("plan_hash") != c.get("plan_hash")),
            "both_success": len(both), "warm_only": sum(1 for w, c in pairs if w.get("success") and not c.get("success")),
            "cold_only": sum(1 for w, c in pairs if c.get("success") and not w.get("success")),
            "median_iteration_ratio_cold_warm": float(np.median(it)) if it else None,
            "median_ipopt_time_ratio_cold_warm": float(np.median(tm)) if tm else None}


def summarize(rows: list[dict]) -> dict:
    """Per scene (and ``"all"`` when there are several): per mode :func:`_mode_summary`, paired
    comparison, and for the warm mode the targets."""
    scenes = sorted({r["scene"] for r in rows})
    groups = [(sc, [r for r in rows if r["scene"] == sc]) for sc in scenes]
    if len(scenes) > 1:
        groups.append(("all", list(rows)))
    out: dict = {}
    for sc, rs in groups:
        modes = [m for m in MODES if any(r["mode"] == m for r in rs)]
        entry: dict[str, Any] = {"n_trials": len({(r["scene"], int(r["trial"])) for r in rs}),
                 "modes": {m: _mode_summary([r for r in rs if r["mode"] == m]) for m in modes}}
        if "warm" in modes and "cold" in modes:
            entry["paired"] = _paired(rs)
        if "warm" in modes:
            w = entry["modes"]["warm"]
            med = w["ipopt_time_s"]["median"]
            ow = w["opt_wall_s"]
            entry["targets"] = {
                "warm_median_opt_wall_s": ow["median"], "warm_p95_opt_wall_s": ow["p95"],
                "warm_opt_wall_met": (ow["median"] is not None and ow["median"] <= TARGETS["warm_median_opt_wall_s"]
                                      and ow["p95"] <= TARGETS["warm_p95_opt_wall_s"]),
                "warm_converged": w["converged_rate"], "warm_converged_target": TARGETS["warm_converged"],
                "warm_converged_met": w["converged_rate"] is not None and w["converged_rate"] >= TARGETS["warm_converged"],
                "warm_median_ipopt_s": med, "warm_median_ipopt_s_target": TARGETS["warm_median_ipopt_s"],
                "warm_median_ipopt_s_met": med is not None and med <= TARGETS["warm_median_ipopt_s"]}
        out[sc] = entry
    return out


def _f(v, fmt: str = ".2f", none: str = "/") -> str:
    return none if v is None else format(v, fmt)


def _pct(a: int, n: int) -> str:
    return f"{a}/{n} {100.0 * a / n:3.0f}%" if n else f"{a}/{n}   /"


def format_summary(summ: dict) -> str:
    """The table: one row per scene and mode, then failure modes, paired figures and targets."""
    hdr = (f"{'scene':12s} {'mode':4s} {'planned':>7s} {'success':>11s} {'converged':>11s} "
           f"{'iter med/mean':>13s} {'IPOPT s med/mean/max':>21s} {'setup s':>7s} {'opt s med/p95':>13s}")
    lines = ["warm vs cold start: IPOPT from the TCBiRRT path (warm) vs from a straight line (cold); "
             "rates over trials with a plan", hdr, "-" * len(hdr)]
    notes = []
    for sc, e in summ.items():
        for m, d in e["modes"].items():
            it, tm = d["iterations"], d["ipopt_time_s"]
            lines.append(f"{sc:12s} {m:4s} {d['planned']:3d}/{d['n']:<3d} {_pct(d['successes'], d['planned']):>11s} "
                         f"{_pct(d['converged'], d['planned']):>11s} "
                         f"{_f(it['median'], '.0f'):>6s}/{_f(it['mean'], '.1f'):<6s} "
                         f"{_f(tm['median']):>6s}/{_f(tm['mean']):>6s}/{_f(tm['max']):>7s} "
                         f"{_f(d['setup_time_s']['median'], '.2f'):>7s} "
                         f"{_f(d['opt_wall_s']['median']):>6s}/{_f(d['opt_wall_s']['p95']):<6s}")
            bits = []
            if d["plan_failures"]:
                bits.append("no plan: " + ", ".join(f"{k} {v}" for k, v in d["plan_failures"].items()))
            if d["failure_modes"]:
                bits.append("failures: " + ", ".join(f"{k} {v}" for k, v in d["failure_modes"].items()))
            if bits and sc != "all":
                notes.append(f"  {sc} {m}: " + "; ".join(bits))
    lines.append("-" * len(hdr))
    lines.extend(notes)
    for sc, e in summ.items():
        p = e.get("paired")
        if p:
            lines.append(f"  {sc} paired: both solved {p['both_success']}/{p['pairs']}, warm only {p['warm_only']}, "
                         f"cold only {p['cold_only']}; cold/warm median ratio iterations "
                         f"{_f(p['median_iteration_ratio_cold_warm'])}, IPOPT time {_f(p['median_ipopt_time_ratio_cold_warm'])}"
                         + (f"; plans differ between modes in {p['plans_differ']}" if p["plans_differ"] else ""))
    for sc, e in summ.items():
        t = e.get("targets")
        if t:
            cr = t["warm_converged"]
            lines.append(f"  {sc} targets: warm converged {_f(None if cr is None else 100 * cr, '.0f')}% "
                         f"(target >= {100 * t['warm_converged_target']:.0f}%: {'met' if t['warm_converged_met'] else 'NOT met'}), "
                         f"median IPOPT {_f(t['warm_median_ipopt_s'])} s "
                         f"(target <= {t['warm_median_ipopt_s_target']:.0f} s: {'met' if t['warm_median_ipopt_s_met'] else 'NOT met'}), "
                         f"optimization (setup + solve + verify) median {_f(t['warm_median_opt_wall_s'])} s / p95 "
                         f"{_f(t['warm_p95_opt_wall_s'])} s wall, {_f(e['modes']['warm']['opt_cpu_s']['median'])} / "
                         f"{_f(e['modes']['warm']['opt_cpu_s']['p95'])} s CPU (target <= {TARGETS['warm_median_opt_wall_s']:.0f} / "
                         f"{TARGETS['warm_p95_opt_wall_s']:.0f} s: {'met' if t['warm_opt_wall_met'] else 'NOT met'})")
    return "\n".join(lines)
