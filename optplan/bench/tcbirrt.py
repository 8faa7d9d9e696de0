"""Benchmark of the TCBiRRT paper (Section 5): planners × scenes × trials, success rate p(t) and planning
times (Eq. 9-11).

``optplan bench tcbirrt --scene 1,2,3 --trials 100 --planners tcbirrt,cbirrt2,ompl-atlas
--time-limit 10 --seed 0 --jobs 2 --out DIR``; ``--planners all`` runs the paper's seven planners
(:data:`optplan.bench.tcbirrt_tables.PAPER_ORDER`) and ``DIR/summary.txt`` ends with its Tables 2-3
beside the paper's figures, ``DIR/fig6_success_rate.png`` is its Fig. 6. The default time limit,
10 s, keeps a run CI-sized; the paper's is ``--time-limit 1000``.

* Trials come from :class:`optplan.trials.TrialGenerator` (Section 5.1), one seed per
  trial (``SeedSequence(seed, spawn_key=(index,))``): results do not depend on ``--jobs`` or on
  the order in which trials run, nor on the engine (``--engine local|dask``, see
  :mod:`optplan.bench.engine`); this process is the only writer of the results file.
* ``DIR/results.jsonl``: one JSON line per (scene, trial, planner), appended as soon as it
  finishes. A killed run resumes: lines already there are not redone (a truncated last line is
  ignored and redone).
* ``DIR/summary.json``, ``DIR/summary.txt``, ``DIR/success_curves.png`` and
  ``DIR/time_distributions.png`` (per-trial times, box per planner and scene): p(t) at several t,
  success counts, median time, and mean ± std of the n_min fastest successful times of every
  planner that has at least n_min successes (Eq. 10-11; n_min = 40, 30, 15 for scenes 1-3 per 100
  trials, scaled with the number of trials).
* ``clock``: "cpu" (default) measures and limits each query in CPU seconds of its worker process
  (immune to other load on the machine); "wall" uses wall-clock time as the paper. Both are
  recorded in every line (``time_s`` wall, ``cpu_time_s``).
* A returned path counts as a success only when every straight joint-space edge between its
  configurations is collision-free when checked so densely that no point of the robot or object
  moves more than :data:`SWEEP_TOLERANCE` between checks (``success``; the planner's own verdict
  is ``planner_success``, and the summary counts the difference as rejected paths).
* TCBiRRT is held to that check by its own options (:data:`BENCH_PLANNER_DEFAULTS`): its paper variant checks
  only the N + 1 configurations of an extension, so the benchmark runs it with ``edge_tolerance`` =
  :data:`SWEEP_TOLERANCE` (every edge checked at the bench's density while the tree grows) and ``verify_path``
  (a found path's edges re-checked; a failing edge removes its subtree and the search goes on), so that a
  returned path is a valid one. A spec that sets either option (``tcbirrt:edge_tolerance=0``) overrides it.
"""
from __future__ import annotations

import json
import logging
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import interrupt
from .._io import append_line, atomic_path, write_json, write_text
from ..errors import UnreachableError
from ..scene import scene_name
from .engine import map_unordered, parse_planner_spec, validate_engine
from .folder import dedupe, folder_lock, read_result_lines
from .tcbirrt_tables import PAPER, _time_of, format_tables, plot_fig6, success_curve

__all__ = ["BenchConfig", "run", "parse_planner_spec", "expand_scenes", "load_results", "summarize", "format_summary", "plot_success", "scene_name",
           "PAPER", "N_MIN",
           "BENCH_PLANNER_DEFAULTS"]
log = logging.getLogger(__name__)

N_MIN = {"ssps_scene1": 40, "ssps_scene2": 30, "ssps_scene3": 15}   # per 100 trials (Section 5.3)
#: [m] the bench's edge check of every returned path: no point of the robot or object moves farther
#: between two checked configurations; a path with an edge in collision at this density is not a success
SWEEP_TOLERANCE = 0.01
#: options the benchmark gives a planner unless its spec sets them: TCBiRRT checks its edges at the bench's density
BENCH_PLANNER_DEFAULTS: dict[str, dict[str, Any]] = {"tcbirrt": {"edge_tolerance": SWEEP_TOLERANCE, "verify_path": True}}
T_GRID = (0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 30.0, 60.0, 100.0, 1000.0)


def expand_scenes(names) -> list[str]:
    """Scene arguments → scene names: ``"1"`` → ``"ssps_scene1"``, ``"suite"`` → every scene of the
    hard-scene suite (:data:`optplan.bench.hardscenes.SUITE`), ``"ssps"`` → the three SSPS scenes,
    other names and TOML paths unchanged."""
    from .hardscenes import SUITE

    out: list[str] = []
    for s in names:
        s = str(s).strip()
        if not s:
            continue
        add = list(SUITE) if s == "suite" else [f"ssps_scene{k}" for k in (1, 2, 3)] if s == "ssps" else [scene_name(s)]
        out.extend(x for x in add if x not in out)
    return out


@dataclass
class BenchConfig:
    """Configuration of ``optplan bench tcbirrt``."""

    #: Scene names (``models/scenes/*.toml``) to run.
    scenes: list = field(default_factory=lambda: ["ssps_scene1", "ssps_scene2", "ssps_scene3"])
    #: Planner specs to compare (``name[:option=value...]``).
    planners: list = field(default_factory=lambda: ["tcbirrt", "cbirrt2", "ompl-atlas"])
    #: Trials per scene [count].
    trials: int = 100
    #: Time limit per query [s] (of ``clock``).
    time_limit: float = 10.0
    #: Base seed of the trials (trial i uses ``SeedSequence(seed, spawn_key=(i,))``).
    seed: int = 0
    #: Worker processes [count].
    jobs: int = 1
    #: Output directory (``results.jsonl``, summaries, figures).
    out: str = "bench_tcbirrt"
    #: ``"cpu"`` (CPU seconds of the worker process) or ``"wall"``.
    clock: str = "cpu"
    #: Show a progress bar.
    progress: bool = True
    #: Write ``success_curves.png``.
    plot: bool = True
    #: Index of the first trial [index] (to resume or split a run).
    first_trial: int = 0
    #: Other output directories whose result lines join the summary.
    merge: list = field(default_factory=list)
    #: ``"local"`` (a process pool of ``jobs``) or ``"dask"`` (:mod:`optplan.bench.engine`).
    engine: str = "local"
    #: Dask scheduler address (None: a local cluster of ``jobs`` workers).
    address: str | None = None


# ---------------------------------------------------------------------- worker
_W: dict = {}


def _worker_setup(robot_name: str, scenes: list[str], planners: list[str]):
    """Per-process cache: robot, scenes, trial generators, planners (shared checker/kinematics)."""
    if _W.get("key") == (robot_name, tuple(scenes), tuple(planners)):
        return
    from ..constraints.closed_chain import ClosedChainKinematics
    from ..model.example_robots import EXAMPLE_ROBOTS, load_example_robot
    from ..model.robot import RobotModel
    from ..planners import make_planner
    from ..planners.validity import ValidityChecker
    from ..scene import Scene
    from ..trials import TrialGenerator

    _W.clear()
    _W["key"] = (robot_name, tuple(scenes), tuple(planners))
    robots: dict = {}
    for sc in scenes:
        scene = Scene.load(sc)
        name = scene.robot or robot_name  # the scene's own robot (shipped or example-robot-data's)
        if name not in robots:
            robots[name] = load_example_robot(name) if name in EXAMPLE_ROBOTS else RobotModel.from_name(name)
        robot = robots[name]
        if scene.object is None:
            raise ValueError(f"scene {sc!r}: the TCBiRRT benchmark needs a held [object]")
        # the path checks use coal (exact); a planner gets the checker of its validity_kernel option
        checkers = {"coal": ValidityChecker(robot, scene, kernel="coal")}
        kin = ClosedChainKinematics(robot, scene.object.grasps)
        built = {}
        for p in planners:
            kind, kw = parse_planner_spec(p)
            kw = {**BENCH_PLANNER_DEFAULTS.get(kind, {}), **kw}
            backend = str(kw.get("validity_kernel", "native"))
            if backend not in checkers:
                checkers[backend] = ValidityChecker(robot, scene, kernel=backend)
            built[p] = make_planner(kind, robot, scene, checker=checkers[backend], kinematics=kin, **kw)
        _W[sc] = {"scene": scene, "robot": robot, "gen": TrialGenerator(robot, scene), "checker": checkers["coal"],
                  "planners": built}


def _path_checks(robot, scene, checker, res, resolution: float = 0.05, sweep: float = SWEEP_TOLERANCE) -> dict:
    """Independent checks of a returned path: closed-chain error (Pinocchio FK) at every
    configuration flagged constrained, and collision checks along straight joint-space edges
    (object held on constrained edges, fixed during regrasps) every ``resolution`` rad
    (``dense_invalid_edges``) and so densely that no point of the robot or object moves more than
    ``sweep`` [m] between checks (``swept_invalid_edges``, :meth:`ValidityChecker.sweep_weights`)."""
    from ..constraints.closed_chain import closure_error
    from ..planners.rrtconnect import edge_is_valid

    if not res.success:
        return {}
    P = res.path
    data = robot.model.createData()
    resid = 0.0
    for q, c in zip(P, res.constrained):
        if c:
            resid = max(resid, *closure_error(robot, scene.object.grasps, q, data))
    bad = swept = 0
    reg = {}
    for s in res.segments:
        if s.kind == "regrasp":
            for k in range(s.start, s.stop):
                reg[k] = s.object_pose
    for k in range(len(P) - 1):
        if k in reg:
            M = reg[k]
            fn, mode = (lambda x, M=M: checker.is_valid_object_fixed(x, M)), "fixed"
        elif res.segments and res.segments[0].kind == "free":
            fn, mode = checker.is_valid_free, "free"
        else:
            fn, mode = checker.is_valid, "held"
        bad += not edge_is_valid(P[k], P[k + 1], fn, resolution)
        swept += not edge_is_valid(P[k], P[k + 1], fn, sweep, weights=checker.sweep_weights(mode, per_geometry=True))
    length = float(np.sum(np.linalg.norm(np.diff(P, axis=0), axis=1))) if len(P) > 1 else 0.0
    return {"max_closed_chain_residual": resid, "dense_invalid_edges": bad, "swept_invalid_edges": swept,
            "sweep_tolerance_m": sweep, "joint_path_length_rad": length}


def _run_unit(args) -> list[dict]:
    robot_name, scene, index, planners, time_limit, seed, clock = args
    w = _W[scene]   # set up by _init_pool
    t0 = time.perf_counter()
    try:
        trial = w["gen"].generate(index, seed)
    except UnreachableError as exc:
        # no start/goal for this trial (a generated scene passed its feasibility check with another seed): a
        # failed query of every planner, not the end of the benchmark
        return [{"scene": scene, "trial": index, "planner": name, "seed": seed, "planner_seed": None,
                 "status": "no_trial", "success": False, "planner_success": False, "time_s": None, "cpu_time_s": None,
                 "clock": clock, "time_limit_s": time_limit, "n_regrasp": 0, "n_configurations": 0,
                 "message": str(exc), "regenerations": 0, "trial_generation_s": time.perf_counter() - t0,
                 "stats": {}, "checks": {}, "task": None} for name in planners]
    gen_time = time.perf_counter() - t0
    out = []
    for name in planners:
        pl = w["planners"][name]
        os0 = os.times()
        res = pl.plan(trial.q_start, trial.q_goal, time_limit=time_limit, seed=trial.seed, clock=clock)
        os1 = os.times()
        checks = _path_checks(w["robot"], w["scene"], w["checker"], res)
        clean = res.success and checks.get("swept_invalid_edges", 0) == 0
        line = {"scene": scene, "trial": index, "planner": name, "seed": seed, "planner_seed": trial.seed,
                "status": res.status.value, "success": clean, "planner_success": res.success, "time_s": res.stats.get("time_s"),
                "cpu_time_s": res.stats.get("cpu_time_s"), "clock": clock, "time_limit_s": time_limit,
                # user / system split of the query's CPU time [s] (system time: page faults, memory pressure)
                "cpu_user_s": os1.user - os0.user, "cpu_system_s": os1.system - os0.system,
                "n_regrasp": res.n_regrasp, "n_configurations": len(res.path), "message": res.message,
                "regenerations": trial.regenerations, "trial_generation_s": gen_time,
                "stats": {k: v for k, v in res.to_dict(include_path=False)["stats"].items()
                          if k not in ("time_s", "cpu_time_s", "clock", "time_limit_s", "seed")},
                "checks": checks,
                "task": trial.to_dict()}
        out.append(line)
    return out


def _init_pool(robot_name, scenes, planners):
    import logging as _lg

    _lg.getLogger("optplan").setLevel(_lg.ERROR)
    _worker_setup(robot_name, scenes, planners)


# ---------------------------------------------------------------------- results file
def load_results(path) -> list[dict]:
    """Result lines of a results.jsonl (or of ``DIR/results.jsonl``); other lines (a truncated last
    one, a foreign line) are skipped, each with a warning naming its line number
    (:func:`optplan.bench.folder.read_result_lines`)."""
    p = Path(path)
    if p.is_dir():
        p = p / "results.jsonl"
    return read_result_lines(p)


def _repair_tail(p: Path) -> None:
    """Drop a truncated last line (a killed run) so appended lines start on a fresh line."""
    if not p.exists() or p.stat().st_size == 0:
        return
    data = p.read_bytes()
    if data.endswith(b"\n"):
        return
    cut = data.rfind(b"\n")
    with atomic_path(p) as tmp:
        tmp.write_bytes(data[:cut + 1] if cut >= 0 else b"")


def run(cfg: BenchConfig, robot_name: str = "tcbirrt_dual_arm") -> list[dict]:
    """Run (or resume) the benchmark; returns all result lines of ``cfg.out``."""
    from ..errors import OptionError
    from ..planners.base import CLOCKS

    if cfg.clock not in CLOCKS:
        raise OptionError(f"clock: expected 'wall' or 'cpu', got {cfg.clock!r}")
    for name, lo in (("trials", 1), ("jobs", 1), ("first_trial", 0)):
        v = getattr(cfg, name)
        if isinstance(v, bool) or not isinstance(v, int) or v < lo:
            raise OptionError(f"BenchConfig.{name}: expected an integer >= {lo}, got {v!r}")
    tl = cfg.time_limit
    if isinstance(tl, bool) or not isinstance(tl, (int, float)) or not (np.isfinite(tl) and tl > 0):
        raise OptionError(f"BenchConfig.time_limit: expected a number of seconds > 0, got {tl!r}")
    validate_engine(cfg.engine, cfg.jobs, cfg.address)
    scenes = expand_scenes(cfg.scenes)
    out = Path(cfg.out)
    with folder_lock(out):   # one writer per folder
        return _run_locked(cfg, robot_name, scenes, out)


def _key(r: dict) -> tuple:
    return (r["scene"], int(r["trial"]), r.get("planner"))


def _run_locked(cfg: BenchConfig, robot_name: str, scenes: list[str], out: Path) -> list[dict]:
    res_path = out / "results.jsonl"
    _repair_tail(res_path)
    done = {(r["scene"], int(r["trial"]), r["planner"]) for r in load_results(res_path)
            if r.get("seed") == cfg.seed and r.get("time_limit_s") == cfg.time_limit and r.get("clock") == cfg.clock}
    units = []
    for sc in scenes:
        for i in range(cfg.first_trial, cfg.first_trial + cfg.trials):
            todo = [p for p in cfg.planners if (sc, i, p) not in done]
            if todo:
                units.append((robot_name, sc, i, todo, float(cfg.time_limit), int(cfg.seed), cfg.clock))
    write_json(out / "config.json", {**cfg.__dict__, "scenes": scenes})
    n_runs = sum(len(u[3]) for u in units)
    n_all, n_done = n_runs + len(done), len(done)
    interrupt.progress(n_done, n_all, "trial runs")
    log.info("%d planner runs to do (%d already in %s)", n_runs, len(done), res_path)
    bar = None
    if cfg.progress and n_runs:
        from tqdm import tqdm

        bar = tqdm(total=n_runs, desc="bench tcbirrt", unit="run", smoothing=0.05)
    with open(res_path, "a") as f:
        def write(lines):
            nonlocal n_done
            with interrupt.deferred():   # the lines written and the count the interruption prints agree
                for ln in lines:
                    append_line(f, json.dumps(ln), res_path)
                n_done += len(lines)
                interrupt.progress(n_done, n_all, "trial runs")
            if bar is not None:
                bar.update(len(lines))
                ok = [ln for ln in lines if ln["success"]]
                bar.set_postfix_str(f"{lines[0]['scene']} #{lines[0]['trial']} "
                                    f"{sum(1 for _ in ok)}/{len(lines)} ok")

        for lines in map_unordered(_run_unit, units, engine=cfg.engine, jobs=cfg.jobs, address=cfg.address,
                                   initializer=_init_pool, initargs=(robot_name, scenes, cfg.planners)):
            write(lines)
    if bar is not None:
        bar.close()
    rows = [r for r in load_results(res_path) if r.get("seed") == cfg.seed and r.get("clock") == cfg.clock
            and r.get("time_limit_s") == cfg.time_limit and r["scene"] in scenes and r["planner"] in cfg.planners
            and cfg.first_trial <= int(r["trial"]) < cfg.first_trial + cfg.trials]
    rows = dedupe(rows, _key)   # each trial counted once (the last line written wins)
    seen = {_key(r) for r in rows}
    for other in cfg.merge:   # lines of other runs (same seed and clock) join the summary
        for r in load_results(other):
            key = _key(r)
            if r.get("seed") == cfg.seed and r.get("clock") == cfg.clock and r["scene"] in scenes and key not in seen:
                rows.append(r)
                seen.add(key)
    summ = summarize(rows, cfg.time_limit)
    write_json(out / "summary.json", summ)
    write_text(out / "summary.txt", format_summary(summ) + "\n\n" + format_tables(summ, cfg.time_limit, cfg.clock))
    if cfg.plot:
        from ..viz.bench_plots import plot_time_distributions

        plot_success(rows, out / "success_curves.png", cfg.time_limit)
        plot_fig6(rows, out / "fig6_success_rate.png", cfg.time_limit)
        plot_time_distributions(rows, out / "time_distributions.png", cfg.time_limit)
    return rows


# ---------------------------------------------------------------------- metrics
def summarize(rows: list[dict], time_limit: float) -> dict:
    """Per scene and planner: trials, successes, p(t), median, mean ± std of the n_min fastest
    (only planners with ≥ n_min successes, Eq. 10-11), regenerations, path checks."""
    out: dict = {}
    scenes = sorted({r["scene"] for r in rows})
    for sc in scenes:
        rs = [r for r in rows if r["scene"] == sc]
        trials = sorted({int(r["trial"]) for r in rs})
        n = len(trials)
        nmin = max(2, int(math.ceil(N_MIN.get(sc, 15) * n / 100.0))) if n else 0
        regen = {int(r["trial"]): int(r.get("regenerations", 0)) for r in rs}
        entry: dict[str, Any] = {"n_trials": n, "n_min": nmin, "regenerations": int(sum(regen.values())), "planners": {}}
        for p in sorted({r["planner"] for r in rs}, key=lambda x: (x != "tcbirrt", x)):
            pr = [r for r in rs if r["planner"] == p]
            succ = [r for r in pr if r["success"]]
            clipping = sum(1 for r in pr if r.get("planner_success", r["success"]) and not r["success"])
            times = sorted(_time_of(r) for r in succ)
            all_times = sorted([_time_of(r) for r in succ] + [math.inf] * (len(pr) - len(succ)))
            ts = [t for t in T_GRID if t <= time_limit] or [time_limit]
            d = {"n": len(pr), "successes": len(succ), "success_rate": len(succ) / len(pr) if pr else 0.0,
                 "p_t": dict(zip([str(t) for t in ts], success_curve(times, len(pr), ts))),
                 "median_time_successful_s": float(np.median(times)) if times else None,
                 "median_time_all_s": (float(all_times[len(all_times) // 2]) if all_times and
                                       math.isfinite(all_times[len(all_times) // 2]) else None),
                 "clipping_paths": clipping,
                 "statuses": {s: sum(1 for r in pr if r["status"] == s) for s in sorted({r["status"] for r in pr})}}
            if len(times) >= nmin and nmin >= 2:
                f = np.asarray(times[:nmin])
                d["mean_fastest_nmin_s"] = float(f.mean())
                d["std_fastest_nmin_s"] = float(f.std(ddof=1))
            else:
                d["mean_fastest_nmin_s"] = d["std_fastest_nmin_s"] = None
            if succ:
                d["mean_n_regrasp"] = float(np.mean([r.get("n_regrasp", 0) for r in succ]))
                chk = [r.get("checks", {}) for r in succ]
                d["max_closed_chain_residual"] = float(max(c.get("max_closed_chain_residual", 0.0) for c in chk))
                d["paths_with_dense_collisions"] = int(sum(1 for c in chk if c.get("dense_invalid_edges", 0) > 0))
            entry["planners"][p] = d
        out[sc] = entry
    return out


def format_summary(summ: dict) -> str:
    lines = []
    for sc, e in summ.items():
        lines.append(f"{sc}: {e['n_trials']} trials, n_min = {e['n_min']}, start/goal regenerations = {e['regenerations']}")
        ts: list[Any] = []
        for d in e["planners"].values():
            ts = list(d["p_t"])
            break
        hdr = f"  {'planner':26s} {'succ':>7s} " + " ".join(f"p({t})".rjust(8) for t in ts) + \
              f" {'median[s]':>9s} {'mean±std n_min fastest':>24s} {'paper (succ, mean±std)':>24s}"
        lines.append(hdr)
        for p, d in e["planners"].items():
            med = d["median_time_successful_s"]
            mm = (f"{d['mean_fastest_nmin_s']:.3f} ± {d['std_fastest_nmin_s']:.3f}"
                  if d["mean_fastest_nmin_s"] is not None else "/")
            pp = PAPER.get(p.split(":", 1)[0].strip().lower(), {}).get(sc)
            ps = "" if pp is None else (f"{pp[0]:.2f}, " + (f"{pp[1]:.2f} ± {pp[2]:.2f}" if pp[1] is not None else "/"))
            lines.append(f"  {p:26s} {d['successes']:3d}/{d['n']:<3d} " + " ".join(f"{v:8.2f}" for v in d["p_t"].values())
                         + f" {f'{med:.3f}' if med is not None else '/':>9s} {mm:>24s} {ps:>24s}")
            extra = []
            if "mean_n_regrasp" in d:
                extra.append(f"mean regrasps {d['mean_n_regrasp']:.2f}")
                extra.append(f"max closed-chain residual {d['max_closed_chain_residual']:.1e}")
                extra.append(f"paths with collisions between configurations (dense 0.05 rad) {d['paths_with_dense_collisions']}")
            if d.get("clipping_paths"):
                extra.append(f"returned paths rejected for an edge in collision ({SWEEP_TOLERANCE * 100:g} cm sweep) "
                              f"{d['clipping_paths']}")
            extra.append("statuses " + ", ".join(f"{k} {v}" for k, v in d["statuses"].items()))
            lines.append("      " + "; ".join(extra))
    lines.append("targets: TCBiRRT success >= 0.99 per scene within 10 s, median <= 0.25 s; "
                 ">= 10x faster median than the best OMPL peer at equal or higher success")
    return "\n".join(lines)


def plot_success(rows: list[dict], path, time_limit: float) -> None:
    """PNG of p(t) (Eq. 9) for every planner, one panel per scene."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = sorted({r["scene"] for r in rows})
    if not scenes:
        return
    ncol = min(4, len(scenes))
    nrow = int(math.ceil(len(scenes) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(5 * ncol, 4 * nrow), squeeze=False)
    for ax in axes.flat[len(scenes):]:
        ax.set_visible(False)
    ts = np.logspace(-2, math.log10(max(time_limit, 0.011)), 300)
    for ax, sc in zip(axes.flat, scenes):
        rs = [r for r in rows if r["scene"] == sc]
        for p in sorted({r["planner"] for r in rs}, key=lambda x: (x != "tcbirrt", x)):
            pr = [r for r in rs if r["planner"] == p]
            times = [_time_of(r) for r in pr if r["success"]]
            ax.step(ts, success_curve(times, len(pr), ts), where="post", label=f"{p} ({len(pr)})")
        ax.set_xscale("log")
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("planning time t [s]" + (" (CPU)" if rs and rs[0].get("clock") == "cpu" else ""))
        ax.set_ylabel("success rate p(t)")
        ax.set_title(sc)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="upper left", fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)
