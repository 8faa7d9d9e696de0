"""The ``optplan`` command."""
from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from . import cli_args as ca
from . import interrupt
from .cli_bench import (
    _cmd_bench_drake,
    _cmd_bench_generalize,
    _cmd_bench_kinematics,
    _cmd_bench_modelling,
    _cmd_bench_oc_rrt,
    _cmd_bench_restoration,
    _cmd_bench_tcbirrt,
    _cmd_bench_transport,
    _cmd_bench_warmstart,
)
from .cli_plan import _cmd_plan, _load_robot, _write_json  # noqa: F401  (the plan command; _load_robot re-exported)
from .errors import OptplanError

interrupt.ignore_in_spawned_child()   # a benchmark's spawned worker imports this module first: no Ctrl-C there


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``optplan plan: error: argument --trials: expected ...`` (exit 2).
    ``fill``: a function that adds this parser's arguments when it is first used (parsing or help),
    so that a command does not import the modules of the others' arguments."""

    def __init__(self, *args, fill=None, **kwargs):
        super().__init__(*args, **kwargs)
        self._fill = fill

    def _filled(self) -> None:
        fill, self._fill = self._fill, None
        if fill is not None:
            fill(self)

    def parse_known_args(self, args=None, namespace=None):
        self._filled()
        return super().parse_known_args(args, namespace)

    def format_help(self):
        self._filled()
        return super().format_help()

    def format_usage(self):
        self._filled()
        return super().format_usage()

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _cmd_models_build(args) -> int:
    from .model.description import available_models, load_description, urdf_dir
    from .model.urdf_writer import urdf_string, write_urdf

    stale = []
    for name in available_models():
        desc = load_description(name)
        path = urdf_dir() / f"{name}.urdf"
        if args.check:
            if not path.exists() or path.read_text() != urdf_string(desc):
                stale.append(name)
        else:
            print(f"wrote {write_urdf(desc)}")
    if args.check:
        if stale:
            print(f"out of date: {', '.join(stale)} (run `optplan models build`)")
            return 1
        print("all URDFs up to date")
    return 0


def _cmd_models_list(args) -> int:
    from .model.description import available_models, load_description

    for name in available_models():
        d = load_description(name)
        print(f"{name:20s} {d.base_type:8s} arms={[a.name for a in d.arms]} mass={d.total_mass:.2f} kg")
    return 0


def _cmd_models_info(args) -> int:
    from .errors import UnknownNameError
    from .model.modelinfo import format_model_info, model_info

    try:
        info = model_info(args.name)
    except UnknownNameError as exc:
        print(f"optplan models info: error: {exc}", file=sys.stderr)
        return 2
    print(format_model_info(info))
    if args.json:
        _write_json(args.json, info)
    return 0


def _cmd_reproduce(args) -> int:
    from .reproduce import ReproduceError, reproduce

    try:
        rec = reproduce(args.paper, out=args.out or f"reproduce_{args.paper}", quick=args.quick, html=not args.no_html)
    except ReproduceError as exc:
        print(f"optplan reproduce: error: {exc}", file=sys.stderr)
        return 2
    return 0 if rec["success"] else 1


def _cmd_view(args) -> int:
    """``optplan view TRAJ.npz [--scene] [--robot] [--html] [--plot DIR] [--playback S]``."""
    from dataclasses import replace

    from .viz.html import ViewOptions, VizUnavailable, load_trajectory, resolve_scene, view_file

    try:
        p = view_file(args.traj, scene=args.scene, robot=args.robot, out=args.html,
                      options=replace(ViewOptions(), playback_s=args.playback))
    except (ValueError, FileNotFoundError, VizUnavailable) as exc:
        print(f"optplan view: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {p} (open it in a browser: play/pause and the time slider are at the bottom)")
    if args.plot:
        from .model.robot import RobotModel
        from .viz.plan_plots import plot_trajectory

        tr = load_trajectory(args.traj)
        sc = resolve_scene(args.scene if args.scene is not None else tr.get("scene"))
        rm = RobotModel.from_name(args.robot or tr.get("robot") or sc.robot)
        for f in plot_trajectory(rm, sc, tr["t"], tr["q"], args.plot, name=Path(args.traj).stem,
                                 constrained=tr.get("constrained")):
            print(f"wrote {f}")
    return 0


def _cmd_demo(args) -> int:
    from .demo import run

    t0 = time.perf_counter()
    out = run(duration=args.duration)
    out["runtime_s"] = time.perf_counter() - t0
    rpy, paper = out["final_base_rpy_deg"], out["paper_final_base_rpy_deg"]
    print("EBA robot, free-end case, 5th-order polynomial joint motion (EBA paper, Sec. 4.1)")
    print(f"  final base RPY [deg]   optplan ({rpy[0]:+.3f}, {rpy[1]:+.3f}, {rpy[2]:+.3f})   "
          f"paper ({paper[0]:+.2f}, {paper[1]:+.2f}, {paper[2]:+.2f})")
    print(f"  max momentum residual  {out['max_momentum_residual']:.2e}")
    print(f"  CoM drift              {out['com_drift_m']:.2e} m")
    print(f"  run time               {out['runtime_s']:.2f} s")
    print("  (the paper's tables do not reproduce its numbers exactly; see docs/models.md)")
    if args.json:
        _write_json(args.json, out)
    return 0 if out["max_momentum_residual"] < 1e-9 else 1


# output-path options of each command, checked before the command runs
_OUTPUT_FILES = ("json", "save", "html")
_OUTPUT_DIRS = ("out", "plot")


def _check_before_run(args) -> None:
    """Before a long run: the kernel cache is a usable folder, and the output folders have room."""
    from ._io import check_output_space
    from .cache import check_cache_setting

    if args.command in ("plan", "bench", "reproduce"):
        check_cache_setting()
    check_output_space({f"--{o}": getattr(args, o, None) for o in _OUTPUT_FILES + _OUTPUT_DIRS})


def _engine_args(p) -> None:
    from .bench.engine import ENGINES

    p.add_argument("--engine", choices=ENGINES, default="local",
                   help="local: this process or a pool of --jobs processes; dask: a local Dask cluster of --jobs "
                        "workers, or the cluster at --address (extra 'dask')")
    p.add_argument("--address", metavar="URL", help="Dask scheduler, e.g. tcp://10.0.0.5:8786 (with --engine dask)")


def _oc_rrt_arguments(p) -> None:
    from .bench.oc_rrt import add_arguments

    add_arguments(p)


def _generalize_arguments(p) -> None:
    from .bench.generalize import add_arguments

    add_arguments(p)


def _version() -> str:
    from . import __version__

    return __version__


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="optplan", description="Motion planning and trajectory optimization "
                                "for dual-arm space robots")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress (INFO)")
    p.add_argument("--version", action="version", version=f"optplan {_version()}")
    sub = p.add_subparsers(dest="command", required=True)

    models = sub.add_parser("models", help="robot descriptions").add_subparsers(dest="action", required=True)
    b = models.add_parser("build", help="regenerate urdf/<name>.urdf from models/robots/<name>.toml")
    b.add_argument("--check", action="store_true", help="only check that the URDFs are up to date")
    b.set_defaults(func=_cmd_models_build)
    models.add_parser("list", help="list robot descriptions").set_defaults(func=_cmd_models_list)
    mi = models.add_parser("info", help="joints, limits, arms and masses of a robot model")
    mi.add_argument("name", help="model name (see `optplan models list`)")
    mi.add_argument("--json", help="write the description as JSON to this path")
    mi.set_defaults(func=_cmd_models_info)

    bench = sub.add_parser("bench", help="benchmarks").add_subparsers(dest="what", required=True)
    k = bench.add_parser("kinematics", help="per-call times of numeric and CasADi kinematics")
    k.add_argument("--robot", default="eba_ffsr")
    k.add_argument("--calls", type=ca.positive_int, default=5000)
    k.add_argument("--json", help="write the figures as JSON to this path")
    k.set_defaults(func=_cmd_bench_kinematics)

    tr = bench.add_parser("transport", help="closed-chain transport NLP at several knot counts")
    tr.add_argument("--knots", type=ca.int_list(2), default=[25, 50, 100], help="comma-separated interval counts N")
    tr.add_argument("--seed", type=ca.nonnegative_int, default=0)
    tr.add_argument("--json", help="write the rows as JSON to this path")
    tr.set_defaults(func=_cmd_bench_transport)

    rs = bench.add_parser("restoration", help="base-attitude restoration NLP (EBA paper): B-spline kernels vs "
                          "knot transcription, cold/warm kernel cache")
    rs.add_argument("--cases", default="free_end,end_constrained", help="comma-separated: free_end, end_constrained")
    rs.add_argument("--json", help="write the rows as JSON to this path")
    rs.set_defaults(func=_cmd_bench_restoration)

    mo = bench.add_parser("modelling", help="problems written with the public OptProblem API (expressions, "
                          "seeded guess): build and solve times, iterations, independent checks")
    mo.add_argument("--tasks", default="reach,reach_knots,reach_free_time,transport,transport_custom,ur5",
                    help="comma-separated: reach, reach_knots, reach_free_time, transport, transport_custom, ur5 "
                         "(ur5 needs example-robot-data)")
    mo.add_argument("--warm-cache", action="store_true",
                    help="keep the kernel cache (default: each task's first run with an empty cache)")
    mo.add_argument("--json", help="write the rows as JSON to this path")
    mo.add_argument("--repeat", type=int, default=1,
                    help="warm problems per task (median and spread of wall and CPU time; default 1)")
    mo.add_argument("--resolves", type=int, default=1,
                    help="rounds of re-solves per warm problem (from its solution, again, after set_value); "
                         "their overhead besides IPOPT as a distribution when > 1 (default 1)")
    mo.add_argument("--peer", choices=["rockit"], help="also the tasks rockit can write, in rockit (extra 'rockit')")
    mo.set_defaults(func=_cmd_bench_modelling)

    tb = bench.add_parser("tcbirrt", help="TCBiRRT benchmark: planners x space-solar-power-station scenes x perturbed trials")
    tb.add_argument("--scene", default="1,2,3", help="comma-separated scenes (1, 2, 3 = ssps_scene1..3, names or TOML "
                    "paths; 'suite' = the hard-scene suite hard_*, 'ssps' = scenes 1-3)")
    tb.add_argument("--trials", type=ca.positive_int, default=100, help="trials per scene")
    tb.add_argument("--first-trial", type=ca.nonnegative_int, default=0, help="index of the first trial")
    tb.add_argument("--planners", default="tcbirrt:variant=improved,cbirrt2,ompl-atlas",
                    help="comma-separated: tcbirrt, cbirrt2, constrained-prm, precomputed-graph, latent-sampling, "
                         "lcbirrt, lcbirrt-lpo, rrtconnect, ompl-<projected|atlas|tb>[-<planner>]; 'all' = the paper's "
                         "seven (the learned ones need optplan[learned]); "
                         "options after colons, e.g. ompl-atlas:tolerance=1e-4:range=0.5")
    tb.add_argument("--time-limit", type=ca.positive_float, default=10.0,
                    help="per query [s] (default 10 s, CI-sized; the paper's Tables 2-3 use 1000 s)")
    tb.add_argument("--seed", type=ca.nonnegative_int, default=0)
    tb.add_argument("--jobs", type=ca.positive_int, default=1, help="worker processes")
    tb.add_argument("--clock", choices=["cpu", "wall"], default="cpu",
                    help="time measured and limited in CPU seconds of the worker (default) or wall-clock seconds")
    tb.add_argument("--out", default="bench_tcbirrt", help="output directory (results.jsonl, summary, PNG)")
    tb.add_argument("--merge", action="append", metavar="DIR",
                    help="also summarize the result lines of another output directory (repeatable)")
    tb.add_argument("--no-progress", action="store_true")
    tb.add_argument("--no-plot", action="store_true")
    tb.add_argument("--generated", type=ca.positive_int, default=None, metavar="N",
                    help="instead of --scene: N fresh random scenes of the generator's families (seeded by --seed), "
                         "one trial each, results in OUT/generated")
    tb.add_argument("--witness-time", type=float,
                    default=30.0, metavar="S",
                    help="with --generated: CPU seconds [s] of the independent search for each scene's witness path "
                         "(a scene without a certified witness is redrawn; 0: no witness, object-only check)")
    tb.add_argument("--witness", default="tcbirrt", metavar="PLANNERS",
                    help="with --generated: comma-separated witness searches, tcbirrt (improved variant) and/or "
                         "cbirrt2 (joint space, certified edges); each runs with --witness-time, a scene is kept "
                         "when any certifies it, and the success is also reported per witness")
    _engine_args(tb)
    tb.set_defaults(func=_cmd_bench_tcbirrt)

    oc = bench.add_parser("oc-rrt", help="OC-RRT vs CBiRRT vs OMPL: orientation-constrained dual-arm PR2 scenes",
                          fill=_oc_rrt_arguments)   # its module is imported only for this command
    oc.set_defaults(func=_cmd_bench_oc_rrt)

    ws = bench.add_parser("warmstart", help="IPOPT from the TCBiRRT path (warm) vs from a straight line "
                          "(cold) on perturbed trials")
    ws.add_argument("--scene", default="1,2,3", help="comma-separated scenes (1, 2, 3 = ssps_scene1..3, or names)")
    ws.add_argument("--trials", type=ca.positive_int, default=20, help="trials per scene")
    ws.add_argument("--first-trial", type=ca.nonnegative_int, default=0, help="index of the first trial")
    ws.add_argument("--seed", type=ca.nonnegative_int, default=0)
    ws.add_argument("--jobs", type=ca.positive_int, default=1, help="worker processes")
    ws.add_argument("--time-limit", type=ca.positive_float, default=10.0, help="planning time limit per query [s]")
    ws.add_argument("--modes", default="warm,cold", help="comma-separated: warm, cold")
    ws.add_argument("--ipopt-max-wall-time", type=ca.positive_float, default=None, metavar="S",
                    help="cap every IPOPT solve at S seconds (default: iteration limit only)")
    ws.add_argument("--compile-kernels", action="store_true",
                    help="compile the optimizer's kernels to C where an earlier run has not (the compile time "
                         "counts in the trial that needs it; later runs use the libraries automatically)")
    ws.add_argument("--segment-workers", type=ca.positive_int, default=None, metavar="N",
                    help="processes per trial that optimize its segments side by side (default: 2 on a machine "
                         "with 2 or more CPUs when --jobs is 1, else 1)")
    ws.add_argument("--transcription", choices=["bspline", "knots"], default="bspline",
                    help="trajectory NLP: B-spline control points (default) or the knot-state transcription")
    ws.add_argument("--segment-nlp", default="optproblem", metavar="optproblem",
                    help="the B-spline segment NLP: an OptProblem on the shared core, the only one ('closed', the "
                         "former closed class, was removed; PipelineOptions.segment_nlp)")
    ws.add_argument("--free-plane-normals", action="store_true",
                    help="let IPOPT move the separating-plane normals (PipelineOptions.fixed_plane_normals=False)")
    ws.add_argument("--out", default="bench_warmstart", help="output directory (results.jsonl, summary.txt/json)")
    ws.add_argument("--no-progress", action="store_true")
    _engine_args(ws)
    ws.set_defaults(func=_cmd_bench_warmstart)

    ge = bench.add_parser("generalize", help="plan -> optimize -> verify on scenes not tuned on (hard-scene suite, "
                          "stress scenes, a dual-Panda robot from example-robot-data): success among planned trials",
                          fill=_generalize_arguments)   # its module is imported only for this command
    ge.set_defaults(func=_cmd_bench_generalize)

    dk = bench.add_parser("drake", help="optplan vs Drake's KinematicTrajectoryOptimization (SNOPT, IPOPT) on the "
                          "transport problem and the pipeline's constrained segments, paired in one run")
    dk.add_argument("--problems", default="transport,scene1",
                    help="comma-separated: transport, scene1, scene2, scene3 (their trials' constrained segments)")
    dk.add_argument("--trials", type=ca.positive_int, default=3, help="trials per scene")
    dk.add_argument("--first-trial", type=ca.nonnegative_int, default=0, help="index of the first trial")
    dk.add_argument("--seed", type=ca.nonnegative_int, default=0)
    dk.add_argument("--solvers", default="snopt,ipopt", help="Drake solvers: snopt, ipopt")
    dk.add_argument("--time-limit", type=ca.positive_float, default=150.0,
                    help="CPU seconds per Drake problem, refinements included (the solve then ends with that status)")
    dk.add_argument("--segments", default="constrained",
                    help="pipeline segments to compare: constrained, regrasp (one arm moves, the other holds)")
    dk.add_argument("--only", help="comma-separated problem names to keep, e.g. transport,ssps_scene1/t0/s3")
    dk.add_argument("--refinements", type=ca.nonnegative_int, default=2,
                    help="Drake: closed-chain grid refinements after a converged solve, as the pipeline's")
    dk.add_argument("--samples-per-interval", type=ca.positive_int, default=1,
                    help="Drake: closed-chain and distance constraints per B-spline interval (1 = at the knots)")
    dk.add_argument("--json", help="write the result rows as JSON to this path")
    dk.set_defaults(func=_cmd_bench_drake)

    pl = sub.add_parser("plan", help="TCBiRRT -> IPOPT -> verify on an assembly scene (the main job)")
    pl.add_argument("--scene", default="1", help="1, 2, 3 (ssps_scene<N>) or a scene name")
    pl.add_argument("--trial", type=ca.nonnegative_int, default=0, help="trial index (perturbed start/goal, Section 5.1)")
    pl.add_argument("--seed", type=ca.nonnegative_int, default=0)
    pl.add_argument("--planner", default="tcbirrt")
    pl.add_argument("--robot", default=None, help="robot model (default: the scene's robot, else tcbirrt_dual_arm); "
                    "also example-robot-data's pr2, baxter, dual_panda (extra 'robots')")
    pl.add_argument("--variant", choices=["paper", "improved"], default=None,
                    help="TCBiRRT variant: the improved sampler (default) or the paper's algorithm")
    pl.add_argument("--time-limit", type=ca.positive_float, default=10.0, help="planning time limit [s]")
    pl.add_argument("--clock", choices=["wall", "cpu"], default="wall",
                    help="the planning time limit in wall-clock seconds (default) or CPU seconds of the planner "
                         "(a seeded plan then hardly depends on how busy the machine is)")
    pl.add_argument("--cold", action="store_true", help="cold start: IPOPT from straight lines, not the plan")
    pl.add_argument("--restore-attitude", action="store_true",
                    help="free-floating robot: end at the initial base attitude with the world goal (default: the "
                         "scene's [extra] restore_attitude, else the plan's arrival attitude)")
    pl.add_argument("--compile-kernels", action="store_true",
                    help="compile the optimizer's kernels to C where an earlier run has not (once per robot and "
                         "collision pair, about a second each; later runs use them automatically)")
    pl.add_argument("--workers", type=ca.positive_int, default=None, metavar="N",
                    help="processes that optimize the plan's segments side by side (default: 2 on a machine with "
                         "2 or more CPUs, else 1; the trajectory does not depend on it)")
    pl.add_argument("--json", help="write the figures as JSON")
    pl.add_argument("--save", help="write the trajectory npz (t, q, joint_names, constrained, robot, scene)")
    pl.add_argument("--html", help="write a 3D view of the motion (self-contained HTML, opens offline)")
    pl.add_argument("--plot", metavar="DIR", help="write PNG figures: joints with limits, closed-chain residual "
                    "and clearance over time")
    pl.set_defaults(func=_cmd_plan)

    vw = sub.add_parser("view", help="3D view of a saved trajectory as a self-contained HTML file")
    vw.add_argument("traj", metavar="TRAJ.npz", help="trajectory file (optplan plan --save, examples' --save)")
    vw.add_argument("--scene", help="1, 2, 3 (ssps_scene<N>), a scene name or a scene TOML path "
                    "(default: the one recorded in the file)")
    vw.add_argument("--robot", help="robot model name (default: recorded in the file, else the scene's robot)")
    vw.add_argument("--html", help="output HTML path (default: TRAJ with .html)")
    vw.add_argument("--plot", metavar="DIR", help="also write the PNG figures of the trajectory to DIR")
    vw.add_argument("--playback", type=float, default=20.0, help="seconds the whole motion takes to play (default 20)")
    vw.set_defaults(func=_cmd_view)

    rp = sub.add_parser("reproduce", help="reproduce a source paper with one command (figures, JSON, 3D views)")
    rp.add_argument("paper", choices=["tcbirrt", "eba", "dshdasr", "spline-rrt", "oc-rrt"],
                    type=lambda s: s.replace("_", "-"), help="the paper's key (docs/papers.md; spline_rrt = spline-rrt)")
    rp.add_argument("--quick", action="store_true", help="a reduced run (under a minute)")
    rp.add_argument("--out", help="output directory (default reproduce_<paper>)")
    rp.add_argument("--no-html", action="store_true", help="no HTML views")
    rp.set_defaults(func=_cmd_reproduce)

    d = sub.add_parser("demo", help="free-floating base of the EBA robot under a quintic joint motion")
    d.add_argument("--duration", type=ca.positive_float, default=20.0, help="motion duration [s]")
    d.add_argument("--json", help="write the figures as JSON to this path")
    d.set_defaults(func=_cmd_demo)
    return p


def _end_plan_process(code: int) -> None:
    """End the ``optplan plan`` process now, with exit status ``code``, once its report and files are
    written (each file closed when written): its idle segment workers are stopped and the interpreter's
    shutdown — freeing the optimization stack's objects one by one and joining the worker pool's threads,
    0.1-0.25 s of wall after the command is done — is skipped (``os._exit``), as after an interruption
    (:func:`optplan.interrupt.finish`). Only for the command line's own process."""
    interrupt.stop_children()   # the segment workers: idle now, nothing of theirs to keep
    logging.shutdown()
    interrupt.end_now(code)


def main(argv: list[str] | None = None) -> int:
    """Run the command; a user error (bad argument, unknown name, unwritable output path, bad
    ``OPTPLAN_ROOT``, malformed description) prints one line and returns 2."""
    if argv is None:   # the command line: a signal while the modules load ends it with one line too
        interrupt.before_start()
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:   # --help (0) or an argparse error, already printed as one line (2)
        return int(exc.code or 0)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    prog = " ".join(["optplan"] + [str(getattr(args, k)) for k in ("command", "action", "what")
                                   if isinstance(getattr(args, k, None), str)])
    # Ctrl-C, SIGTERM, SIGHUP: one line, exit 128 + signal, no worker left
    with interrupt.handling(prog, quiet=not args.verbose, ignore_after=argv is None):
        try:
            ca.check_root()
            for opt in _OUTPUT_FILES:
                ca.check_output_file(getattr(args, opt, None), f"--{opt}")
            for opt in _OUTPUT_DIRS:
                ca.check_output_dir(getattr(args, opt, None), f"--{opt}")
            _check_before_run(args)
            code = int(args.func(args) or 0)
            interrupt.check()   # a signal a library turned into its own error still ends as an interruption
            if argv is None and args.func is _cmd_plan:
                _end_plan_process(code)
            return code
        except OptplanError as exc:  # the user's input: one line, no traceback
            if interrupt.received() is not None:
                return interrupt.finish(exit_now=argv is None)
            msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            print(f"{prog}: error: {msg}", file=sys.stderr)
            return 2
        except BaseException:
            if interrupt.received() is not None:
                return interrupt.finish(exit_now=argv is None)
            raise


if __name__ == "__main__":
    sys.exit(main())
