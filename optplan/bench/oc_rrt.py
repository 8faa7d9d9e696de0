"""Benchmark of OC-RRT (orientation-constrained RRT for decoupled dual arms) against CBiRRT and an
OMPL constrained planner on the four PR2 scenes (Industrial I open chain; Industrial II, Tabletop,
Narrow Passageway closed chain): the paper's protocol of 20 seeded trials per scene and planner.

Per run: success, planning time (``clock``: "cpu" by default, immune to other load), node count,
and ORMSD [rad] / PRMSD [m] of the path densely interpolated every ``resolution`` rad (OC-RRT:
its manifold edges, re-solved analytically; CBiRRT and OMPL: straight joint-space segments
between their returned configurations, which is how their paths are executed).

``DIR/results.jsonl`` gets one line per (scene, trial, planner) as soon as it finishes; a killed
run resumes (lines already there are skipped). ``summary.json`` holds
``{"scenes": {SCENE: {PLANNER: {"success_rate", "median_time_s", "median_nodes",
"max_ormsd_rad", "max_prmsd_m", ...}}}}``.

Needs ``example-robot-data`` (``pip install "optplan[robots]"``); the OMPL peer needs ``ompl``.
"""
from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import interrupt
from .._io import append_line, atomic_path, write_json, write_text
from .folder import dedupe, folder_lock
from .tcbirrt import _repair_tail, load_results

__all__ = ["OCBenchConfig", "SCENES", "PLANNERS", "OMPL_PEER", "run", "summarize", "format_table", "densify_linear",
           "setup_scene", "save_path", "plot_scene"]
log = logging.getLogger(__name__)

SCENES = ("oc_industrial_1", "oc_industrial_2", "oc_tabletop", "oc_passageway")
OMPL_PEER = "ompl-projected-bkpiece1"   # the strongest OMPL constrained configuration we found (peers.md)
PLANNERS = ("oc_rrt", "oc_rrt_connect", "cbirrt", OMPL_PEER)
#: also accepted: "oc_rrt_paper" (the paper's single-tree Algorithm 2, OCRRTOptions.paper()) and each planner's
#: "<name>_uncertified" (edges checked at their configurations only, not certified)
EXTRA_PLANNERS = ("oc_rrt_paper", "oc_rrt_uncertified", "oc_rrt_connect_uncertified", "cbirrt_uncertified")


@dataclass
class OCBenchConfig:
    """Configuration of ``optplan bench oc-rrt``."""

    #: Scene names (``models/scenes/*.toml``) to run.
    scenes: list = field(default_factory=lambda: list(SCENES))
    #: Planner specs to compare (``name[:option=value...]``).
    planners: list = field(default_factory=lambda: list(PLANNERS))
    #: Trials per scene [count].
    trials: int = 20
    #: Time limit per query [s] (of ``clock``).
    time_limit: float = 20.0
    #: Base seed of the trials.
    seed: int = 0
    #: Output directory.
    out: str = "bench_oc_rrt"
    #: ``"cpu"`` (CPU seconds of the worker) or ``"wall"``.
    clock: str = "cpu"
    #: Spacing of the independent re-check of every returned path [rad].
    resolution: float = 0.01
    #: Show a progress bar.
    progress: bool = True
    #: Directory for the paths found (None: not saved).
    save_dir: str | None = None


def densify_linear(path: np.ndarray, resolution: float) -> np.ndarray:
    """Straight joint-space segments resampled every ``resolution`` rad (max-norm)."""
    out = [path[0]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, int(math.ceil(float(np.abs(b - a).max()) / resolution)))
        for k in range(1, n + 1):
            out.append(a + (k / n) * (b - a))
    return np.array(out)


_CACHE: dict = {}


def setup_scene(scene_name: str, planners) -> dict:
    """Robot, scene, constraint, start/goal and planners of one scene (cached per process)."""
    from ..model.example_robots import load_pr2
    from ..planners.base import Planner
    from ..planners.cbirrt2 import CBiRRT2, CBiRRT2Options
    from ..planners.oc_rrt import OCRRT, OCRRTOptions
    from ..planners.orientation import OrientationManifold, constraint_from_scene, endpoints_from_scene
    from ..planners.validity import ValidityChecker
    from ..scene import Scene

    key = (scene_name, tuple(planners))
    if key in _CACHE:
        return _CACHE[key]
    if "robot" not in _CACHE:
        _CACHE["robot"] = load_pr2()
    robot = _CACHE["robot"]
    scene = Scene.load(scene_name)
    con = constraint_from_scene(robot, scene)
    mf = OrientationManifold(con)
    q_start, q_goal = endpoints_from_scene(mf, scene)
    ck = ValidityChecker(robot, scene)
    pl: dict[str, Planner] = {}
    for p in planners:
        cert = not p.endswith("_uncertified")
        base = p.removesuffix("_uncertified")
        if base == "oc_rrt":
            pl[p] = OCRRT(robot, scene, con, OCRRTOptions(connect=False, certified_edges=cert), checker=ck, manifold=mf)
            pl[p].name = p
        elif p == "oc_rrt_paper":
            pl[p] = OCRRT(robot, scene, con, OCRRTOptions.paper(), checker=ck, manifold=mf)
            pl[p].name = p
        elif base == "oc_rrt_connect":
            pl[p] = OCRRT(robot, scene, con, OCRRTOptions(connect=True, certified_edges=cert), checker=ck, manifold=mf)
            pl[p].name = p
        elif base == "cbirrt":
            pl[p] = CBiRRT2(robot, scene, CBiRRT2Options(certified_edges=cert), checker=ck, constraint=con)
            pl[p].name = p
        elif p.startswith("ompl-"):
            from ..planners.ompl_peers import make_ompl_peer

            pl[p] = make_ompl_peer(p, robot, scene, checker=ck, constraint=con)
        else:
            raise ValueError(f"unknown planner {p!r}; expected one of {PLANNERS + EXTRA_PLANNERS}")
        opts: Any = getattr(pl[p], "options", None)
        if opts is not None and getattr(opts, "certified_edges", False):
            ck.certifier(opts.edge_min_clearance).prepare(("held",))   # before any time limit
    out = {"robot": robot, "scene": scene, "constraint": con, "manifold": mf, "q_start": q_start,
           "q_goal": q_goal, "checker": ck, "planners": pl}
    _CACHE[key] = out
    return out


def _dense(s: dict, name: str, path: np.ndarray, resolution: float) -> np.ndarray:
    pl = s["planners"][name]
    if hasattr(pl, "densify"):
        return pl.densify(path, resolution)
    return densify_linear(path, resolution)


def _run_one(s: dict, scene: str, name: str, trial: int, cfg: OCBenchConfig) -> tuple[dict, np.ndarray | None]:
    pl = s["planners"][name]
    seed = int(np.random.SeedSequence(cfg.seed, spawn_key=(trial,)).generate_state(1)[0] % (2 ** 31))
    res = pl.plan(s["q_start"], s["q_goal"], time_limit=cfg.time_limit, seed=seed, clock=cfg.clock)
    line = {"scene": scene, "trial": trial, "planner": name, "seed": cfg.seed, "planner_seed": seed,
            "status": res.status.value, "success": res.success, "time_s": res.stats.get("time_s"),
            "cpu_time_s": res.stats.get("cpu_time_s"), "clock": cfg.clock, "time_limit_s": cfg.time_limit,
            "nodes": res.stats.get("nodes"), "n_configurations": len(res.path), "message": res.message}
    dense = None
    if res.success:
        dense = _dense(s, name, res.path, cfg.resolution)
        o, p = s["constraint"].rmsd(dense)
        ck = s["checker"]
        line.update({"ormsd_rad": o, "prmsd_m": None if math.isnan(p) else p, "n_dense": len(dense),
                     "dense_collisions": int(sum(not ck.is_valid(q) for q in dense[::5]))})
    return line, dense


def save_path(directory, scene: str, planner: str, dense: np.ndarray, joint_names, resolution: float) -> Path:
    """``DIR/<scene>_<planner>.npz`` with ``t`` (path parameter, one unit per ``resolution`` rad
    step, [-]), ``q`` (M × 14 [rad]) and ``joint_names``."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    p = d / f"{scene}_{planner}.npz"
    with atomic_path(p) as tmp, open(tmp, "wb") as f:
        np.savez(f, t=np.arange(len(dense), dtype=float) * resolution, q=dense, joint_names=np.array(joint_names))
    return p


def run(cfg: OCBenchConfig) -> list[dict]:
    """Run (or resume) the benchmark; returns every line of ``cfg.out/results.jsonl`` for cfg (one
    per scene, trial and planner). The output folder is held for the run (one writer)."""
    with folder_lock(cfg.out):
        return _run_locked(cfg)


def _run_locked(cfg: OCBenchConfig) -> list[dict]:
    out = Path(cfg.out)
    rp = out / "results.jsonl"
    _repair_tail(rp)
    match = lambda r: (r.get("seed") == cfg.seed and r.get("clock") == cfg.clock  # noqa: E731
                       and r.get("time_limit_s") == cfg.time_limit)
    done = {(r["scene"], int(r["trial"]), r["planner"]) for r in load_results(rp) if match(r)}
    todo = [(sc, i, p) for sc in cfg.scenes for i in range(cfg.trials) for p in cfg.planners if (sc, i, p) not in done]
    bar = None
    if cfg.progress and todo:
        from tqdm import tqdm

        bar = tqdm(total=len(todo), desc="bench oc_rrt", unit="run")
    saved = set()
    with open(rp, "a") as f:
        n_all = len(todo) + len(done)
        for k, (sc, i, p) in enumerate(todo):
            interrupt.progress(len(done) + k, n_all, "trial runs")
            s = setup_scene(sc, cfg.planners)
            line, dense = _run_one(s, sc, p, i, cfg)
            with interrupt.deferred():   # the line written and the count the interruption prints agree
                append_line(f, json.dumps(line), rp)
                interrupt.progress(len(done) + k + 1, n_all, "trial runs")
            if cfg.save_dir and dense is not None and (sc, p) not in saved:
                save_path(cfg.save_dir, sc, p, dense, s["robot"].joint_names, cfg.resolution)
                saved.add((sc, p))
            if bar is not None:
                bar.update(1)
                bar.set_postfix_str(f"{sc} #{i} {p} {line['status']}")
    if bar is not None:
        bar.close()
    rows = dedupe([r for r in load_results(rp) if match(r) and r["scene"] in cfg.scenes
                   and r.get("planner") in cfg.planners and int(r["trial"]) < cfg.trials],
                  lambda r: (r["scene"], int(r["trial"]), r["planner"]))
    summ = summarize(rows)
    write_json(out / "summary.json", summ)
    write_text(out / "summary.txt", format_table(summ))
    return rows


def _t(r):
    return float(r["cpu_time_s"] if r.get("clock") == "cpu" else r["time_s"])


def summarize(rows: list[dict]) -> dict:
    """``{"scenes": {scene: {planner: {...}}}, "ratios": {scene: {peer: median_peer / median_ocrrt}}}``;
    medians over successful runs; ``max_*rmsd`` over successful runs (None without one)."""
    scenes: dict = {}
    for sc in sorted({r["scene"] for r in rows}, key=lambda x: (SCENES.index(x) if x in SCENES else 99, x)):
        e = {}
        order = PLANNERS[:1] + EXTRA_PLANNERS + PLANNERS[1:]
        for p in sorted({r["planner"] for r in rows if r["scene"] == sc}, key=lambda x: (order.index(x) if x in order else 99, x)):
            pr = [r for r in rows if r["scene"] == sc and r["planner"] == p]
            ok = [r for r in pr if r["success"]]
            nodes = [r["nodes"] for r in ok if r.get("nodes") is not None]
            pm = [r["prmsd_m"] for r in ok if r.get("prmsd_m") is not None]
            e[p] = {"success_rate": len(ok) / len(pr) if pr else 0.0,
                    "median_time_s": float(np.median([_t(r) for r in ok])) if ok else None,
                    "median_nodes": float(np.median(nodes)) if nodes else None,
                    "max_ormsd_rad": float(max(r["ormsd_rad"] for r in ok)) if ok else None,
                    "max_prmsd_m": float(max(pm)) if pm else None,
                    "n_trials": len(pr), "successes": len(ok),
                    "paths_with_dense_collisions": int(sum(1 for r in ok if r.get("dense_collisions", 0) > 0))}
        scenes[sc] = e
    ratios = {}
    for sc, e in scenes.items():
        best = min((e[p]["median_time_s"] for p in ("oc_rrt", "oc_rrt_connect") if p in e and e[p]["median_time_s"] is not None),
                   default=None)
        ratios[sc] = {p: (d["median_time_s"] / best if (best and d["median_time_s"] is not None) else None)
                      for p, d in e.items() if not p.startswith("oc_rrt")}
    per = {sc: {v: {p: (d["median_time_s"] / e[v]["median_time_s"] if d["median_time_s"] is not None else None)
                    for p, d in e.items() if not p.startswith("oc_rrt")}
                for v in e if v.startswith("oc_rrt") and e[v]["median_time_s"]}
           for sc, e in scenes.items()}
    return {"scenes": scenes, "speedup_of_best_oc_rrt": ratios, "speedup_of_each_oc_rrt": per}


def format_table(summ: dict) -> str:
    lines = [f"{'scene':18s} {'planner':26s} {'success':>8s} {'median t [s]':>12s} {'nodes':>7s} "
             f"{'max ORMSD [rad]':>15s} {'max PRMSD [m]':>13s} {'hit@0.05':>8s}"]
    fm = lambda v, f: "/" if v is None else format(v, f)  # noqa: E731
    for sc, e in summ["scenes"].items():
        for p, d in e.items():
            lines.append(f"{sc:18s} {p:26s} {d['success_rate']:8.2f} {fm(d['median_time_s'], '12.3f')} "
                         f"{fm(d['median_nodes'], '7.0f')} {fm(d['max_ormsd_rad'], '15.1e')} {fm(d['max_prmsd_m'], '13.1e')} "
                         f"{d['paths_with_dense_collisions']:8d}")
        for v, r in summ.get("speedup_of_each_oc_rrt", {}).get(sc, {}).items():
            if r:
                lines.append(f"    median time of peer / {v}: " + ", ".join(f"{p} {fm(x, '.1f')}x" for p, x in r.items()))
    lines.append("hit@0.05: successful paths with a configuration in collision when re-checked every 0.05 rad "
                 "of the dense path (collisions between the configurations the planner checked)")
    lines.append("targets: ORMSD, PRMSD <= 1e-9 along the path; success >= 0.95 per scene; OC-RRT faster than "
                 "CBiRRT and the best OMPL peer on every scene (median, same trials). Paper (PR2, 20 trials): "
                 "OC-RRT faster than CBiRRT with fewer nodes and ORMSD/PRMSD near zero in all four scenes.")
    return "\n".join(lines)


def plot_scene(directory, scene: str, dense: np.ndarray, constraint, joint_names, label: str) -> list[Path]:
    """The paper's Fig. 5-8 panels for one path: ORMSD / PRMSD along the path (running RMS) and the
    joint trajectories of the two arms. Returns the PNG paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    E = np.array([constraint.errors(q) for q in dense])
    k = np.arange(1, len(E) + 1)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    axes[0].semilogy(np.sqrt(np.cumsum(E[:, 0] ** 2) / k) + 1e-18, label="ORMSD [rad]")
    if constraint.mode == "closed":
        axes[0].semilogy(np.sqrt(np.cumsum(E[:, 1] ** 2) / k) + 1e-18, label="PRMSD [m]")
    axes[0].set_xlabel("path sample")
    axes[0].set_title(f"{scene} / {label}: running RMSD")
    axes[0].legend()
    for ax, sl, nm in ((axes[1], slice(0, 7), "left arm"), (axes[2], slice(7, 14), "right arm")):
        for j in range(sl.start, sl.stop):
            ax.plot(dense[:, j], label=joint_names[j])
        ax.set_title(f"{nm} joints [rad]")
        ax.legend(fontsize=6)
    fig.tight_layout()
    p = d / f"{scene}_{label}.png"
    with atomic_path(p) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return [p]


def add_arguments(p) -> None:
    """Command-line options of ``optplan bench oc-rrt`` and ``examples/oc_rrt.py``."""
    p.add_argument("--scenes", default=",".join(SCENES), help="comma-separated scene names")
    p.add_argument("--planners", default=",".join(PLANNERS),
                   help="comma-separated: oc_rrt, oc_rrt_connect, cbirrt, ompl-<projected|atlas|tb>[-<planner>], "
                        "oc_rrt_paper (the paper's single-tree Algorithm 2)")
    p.add_argument("--trials", type=int, default=20, help="seeded trials per scene and planner (paper: 20)")
    p.add_argument("--time-limit", type=float, default=20.0, help="per query [s]")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--clock", choices=["cpu", "wall"], default="cpu",
                   help="time measured and limited in CPU seconds (default) or wall-clock seconds")
    p.add_argument("--resolution", type=float, default=0.01, help="dense path resolution for ORMSD/PRMSD [rad]")
    p.add_argument("--out", default="bench_oc_rrt",
                   help="output directory (results.jsonl, summary.json/txt; a run resumes from it); "
                        "examples/oc_rrt.py writes none unless given")
    p.add_argument("--json", metavar="PATH", help="write the per-scene, per-planner summary as JSON")
    p.add_argument("--plot", metavar="DIR", help="write the RMSD and joint figures (one path per scene and planner)")
    p.add_argument("--save", metavar="DIR", help="write one dense path per scene and planner (npz: t, q, joint_names)")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--quick", action="store_true",
                   help="one trial per scene of OC-RRT-Connect and CBiRRT, 5 s per query (a smoke run, under a minute)")


def command(args) -> int:
    """Run the benchmark from parsed arguments; prints the table."""
    from ..model.example_robots import example_robots_available

    if not example_robots_available():
        log.error("OC-RRT benchmark: PR2 needs the example-robot-data package: pip install \"optplan[robots]\"")
        return 2
    if getattr(args, "quick", False):
        args.trials, args.time_limit, args.planners = 1, min(args.time_limit, 5.0), "oc_rrt_connect,cbirrt"
    planners = [p for p in args.planners.split(",") if p]
    if any(p.startswith("ompl-") for p in planners):
        from ..planners.ompl_peers import ompl_available

        if not ompl_available():
            log.warning("ompl is not installed (pip install \"optplan[ompl]\"): OMPL peer skipped")
            planners = [p for p in planners if not p.startswith("ompl-")]
    if args.trials < 1:
        raise ValueError(f"--trials: expected >= 1, got {args.trials}")
    import tempfile

    with tempfile.TemporaryDirectory(prefix="optplan-oc-rrt-") as scratch:
        # no --out (the example's default): the resumable results go to a temporary folder, removed
        # after the run, never into the current directory
        out = args.out if args.out is not None else scratch
        cfg = OCBenchConfig(scenes=[s for s in args.scenes.split(",") if s], planners=planners, trials=args.trials,
                            time_limit=args.time_limit, seed=args.seed, out=out, clock=args.clock,
                            resolution=args.resolution, progress=not args.no_progress, save_dir=args.save)
        rows = run(cfg)
    return _report(args, cfg, rows)


def _report(args, cfg: OCBenchConfig, rows: list[dict]) -> int:
    """Print the table; write ``--json`` and ``--plot`` when asked."""
    summ = summarize(rows)
    print(format_table(summ))
    if args.json:
        js = {"scenes": {sc: {p: dict(d) for p, d in e.items()} for sc, e in summ["scenes"].items()}}
        for sc, r in summ["speedup_of_best_oc_rrt"].items():
            for p, v in r.items():
                js["scenes"][sc][p]["median_time_ratio_to_best_oc_rrt"] = v
        for sc, per in summ["speedup_of_each_oc_rrt"].items():
            for v, r in per.items():
                js["scenes"][sc][v]["peer_median_time_ratios"] = r
        write_json(args.json, js)
        print(f"wrote {args.json}")
    if args.plot:
        for sc in cfg.scenes:
            for p in cfg.planners:
                ok = [r for r in rows if r["scene"] == sc and r["planner"] == p and r["success"]]
                if not ok:
                    continue
                s = setup_scene(sc, cfg.planners)
                res = s["planners"][p].plan(s["q_start"], s["q_goal"], time_limit=cfg.time_limit,
                                            seed=ok[0]["planner_seed"], clock=cfg.clock)
                if res.success:
                    dense = _dense(s, p, res.path, cfg.resolution)
                    for f in plot_scene(args.plot, sc, dense, s["constraint"], s["robot"].joint_names, p):
                        print(f"wrote {f}")
    return 0
