"""The ``optplan bench ...`` commands: each parses nothing itself (:mod:`optplan.cli` builds the
parser), runs one benchmark of :mod:`optplan.bench` and prints its summary."""
from __future__ import annotations

import sys
import time

from . import cli_args as ca
from ._io import write_json
from .errors import OptplanError, UsageError


def _cmd_bench_kinematics(args) -> int:
    from .bench.kinematics import report, run

    times = run(args.robot, args.calls)
    print(report(times))
    if args.json:
        write_json(args.json, times)
    return 0


def _cmd_bench_transport(args) -> int:
    from .bench.transport import report, run

    knots = args.knots
    rows = run(knots, args.seed)
    print(report(rows, knots))
    if args.json:
        write_json(args.json, rows)
    return 0


def _cmd_bench_restoration(args) -> int:
    from .bench.restoration import main

    return main(["--cases", args.cases] + (["--json", args.json] if args.json else []))


def _cmd_bench_tcbirrt(args) -> int:
    from .bench.engine import engine_error
    from .bench.tcbirrt import BenchConfig, format_summary, parse_planner_spec, run, summarize
    from .planners import check_planner_options

    if (err := engine_error(args.engine, args.jobs, args.address)) is not None:
        raise UsageError(err)
    from .bench.tcbirrt import expand_scenes

    scenes: list[str] = []
    for s in (t.strip() for t in args.scene.split(",")):
        for name in (expand_scenes([s]) if s in ("suite", "ssps") else [ca.check_scene(s)] if s else []):
            if name not in scenes:
                scenes.append(name)
    scenes = scenes or [ca.check_scene("")]
    from .bench.tcbirrt_tables import expand_planners, format_tables

    out, trials = args.out, args.trials
    if args.generated:   # fresh random draws of the scene families, reported apart from the fixed scenes
        from pathlib import Path

        from .bench.scenegen import generate_scenes, rejection_summary, write_scenes
        from .model.robot import RobotModel

        if not (args.witness_time >= 0 and args.witness_time < float("inf")):
            raise UsageError(f"--witness-time {args.witness_time!r}: expected CPU seconds >= 0")
        from .bench.scene_witness import check_witness_planners

        try:
            wplanners = check_witness_planners(args.witness)
        except OptplanError as exc:
            raise UsageError(f"--witness {args.witness!r}: {exc}") from None
        rejected: list = []
        drawn = generate_scenes(RobotModel.from_name("tcbirrt_dual_arm"), args.generated, args.seed,
                                witness_time=args.witness_time, rejections=rejected, witnesses=wplanners)
        out = str(Path(args.out) / "generated")
        scenes = write_scenes(drawn, Path(out) / "scenes")
        trials = 1
        print(f"{len(drawn)} generated scenes (seed {args.seed}) in {out}/scenes, one trial each; each kept "
              f"with a certified witness path ({' or '.join(wplanners)}, search budget {args.witness_time:g} s CPU "
              "each)" if args.witness_time > 0
              else f"{len(drawn)} generated scenes (seed {args.seed}) in {out}/scenes, one trial each; "
              "NO witness (--witness-time 0): some may be infeasible for the robot")
        print(rejection_summary(drawn, rejected))
        certified = {p: g.certified_by for p, g in zip(scenes, drawn)}
        if len(wplanners) > 1:
            print("certified by: " + ", ".join(f"{w} {sum(w in g.certified_by for g in drawn)}" for w in wplanners)
                  + f" of {len(drawn)}")
    planners = expand_planners([p for p in args.planners.split(",") if p.strip()])
    for p in planners or [""]:
        try:
            spec, opts = parse_planner_spec(p)
        except ValueError as exc:
            raise UsageError(f"--planners {args.planners!r}: {exc}") from None
        ca.check_planner(spec, "--planners")
        try:
            check_planner_options(spec, **opts)
        except OptplanError as exc:
            raise UsageError(f"--planners {args.planners!r}: {exc}") from None
    from .planners.learned import LEARNED, available

    learned = [p for p in planners if parse_planner_spec(p)[0].lower() in LEARNED]
    if learned and not available():
        raise UsageError(f"--planners {','.join(learned)}: the learned planners need the optional extra 'learned': "
                         "pip install \"optplan[learned]\"")
    cfg = BenchConfig(scenes=scenes, planners=planners,
                      trials=trials, time_limit=args.time_limit, seed=args.seed, jobs=args.jobs, out=out,
                      clock=args.clock, progress=not args.no_progress, plot=not args.no_plot,
                      first_trial=args.first_trial, merge=list(args.merge or []),
                      engine=args.engine, address=args.address)
    t0 = time.perf_counter()
    rows = run(cfg)
    summ = summarize(rows, cfg.time_limit)
    print(format_summary(summ))
    print(format_tables(summ, cfg.time_limit, cfg.clock))
    if args.generated:
        from .bench.scenegen import family_summary

        print(family_summary(rows, certified))
    print(f"summary of {len(rows)} result lines ({out}/results.jsonl"
          f"{' and merged runs' if cfg.merge else ''}); run time {time.perf_counter() - t0:.1f} s (clock: {cfg.clock}); "
          f"figures {out}/success_curves.png, {out}/fig6_success_rate.png, {out}/time_distributions.png")
    return 0


def _cmd_bench_modelling(args) -> int:
    from .bench.modelling import main

    argv = ["--tasks", args.tasks] + (["--warm-cache"] if args.warm_cache else []) + (["--json", args.json]
                                                                                      if args.json else [])
    argv += ["--peer", args.peer] if args.peer else []
    argv += ["--repeat", str(args.repeat), "--resolves", str(args.resolves)]
    return main(argv)


def _cmd_bench_oc_rrt(args) -> int:
    from .bench.oc_rrt import command

    return command(args)


def _cmd_bench_warmstart(args) -> int:
    from .bench.engine import engine_error
    from .bench.warmstart import WarmstartConfig, format_summary, run, summarize, validate

    if (err := engine_error(args.engine, args.jobs, args.address)) is not None:
        print(f"optplan bench warmstart: error: {err}", file=sys.stderr)
        return 2

    cfg = WarmstartConfig(scenes=[s for s in args.scene.split(",") if s.strip()], trials=args.trials, seed=args.seed,
                          jobs=args.jobs, out=args.out, time_limit=args.time_limit,
                          modes=tuple(m.strip() for m in args.modes.split(",") if m.strip()),
                          first_trial=args.first_trial, progress=not args.no_progress,
                          ipopt_max_wall_time=args.ipopt_max_wall_time,
                          free_plane_normals=args.free_plane_normals, transcription=args.transcription,
                          compile_kernels=args.compile_kernels, engine=args.engine, address=args.address,
                          segment_workers=args.segment_workers, segment_nlp=args.segment_nlp)
    try:
        validate(cfg)
    except ValueError as exc:
        print(f"optplan bench warmstart: error: {exc}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    rows = run(cfg)
    print(format_summary(summarize(rows)))
    print(f"summary of {len(rows)} result lines ({args.out}/results.jsonl, {args.out}/summary.txt, "
          f"{args.out}/summary.json); run time {time.perf_counter() - t0:.1f} s")
    return 0


def _cmd_bench_generalize(args) -> int:
    from .bench.generalize import command

    return command(args)


def _cmd_bench_drake(args) -> int:
    from .bench.drake_bench import format_report, format_row, run, save_json

    drake_opts = {"time_limit": args.time_limit, "samples_per_interval": args.samples_per_interval}
    done: list = []
    command = "optplan " + " ".join(sys.argv[1:])

    def on_row(r):  # progress; the JSON file grows with every result, so a long run keeps what it measured
        print(format_row(r), flush=True)
        if args.json:
            done.append(r)
            save_json(done, args.json, command)

    try:
        rows = run([p.strip() for p in args.problems.split(",") if p.strip()], trials=args.trials,
                   first_trial=args.first_trial, seed=args.seed,
                   solvers=[s.strip() for s in args.solvers.split(",") if s.strip()], drake_options=drake_opts,
                   drake_refinements=args.refinements, on_row=on_row, progress=False,
                   segments=[s.strip() for s in args.segments.split(",") if s.strip()],
                   only=[s.strip() for s in (args.only or "").split(",") if s.strip()])
    except (ValueError, ImportError) as exc:
        print(f"optplan bench drake: error: {exc}", file=sys.stderr)
        return 2
    print(format_report(rows))
    if args.json:
        save_json(rows, args.json, command)
    return 0
