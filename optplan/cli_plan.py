"""``optplan plan``: a scene's trial planned, optimized and verified (fixed or free-floating base),
its report and its output files."""
from __future__ import annotations

import contextlib
import time
from pathlib import Path

from . import cli_args as ca
from . import interrupt
from .errors import ModelError, OptplanError, UsageError


def _load_robot(name: str):
    """A shipped robot (models/robots), one of example-robot-data's (pr2, baxter, dual_panda;
    extra 'robots'), a robot file (models/robots/files, or any path) or a bare URDF path."""
    from .model.example_robots import load_robot

    return load_robot(name)


def _check_fits(scene, robot, robot_name: str, given: bool) -> None:
    """A clear error when the scene's grasps or configurations do not fit the robot (never a
    silent fallback to another robot)."""
    if robot is None:
        return
    try:
        scene.check_robot(robot)
    except ModelError as exc:
        hint = "" if given else \
            f" (the scene names no robot, so {robot_name!r} was tried: pass --robot or set the scene's robot)"
        raise UsageError(f"{exc}{hint}") from None


def _same_robot(a: str, b: str) -> bool:
    """Do two robot names / paths name the same robot (paths compared resolved)?"""
    from .model.robot_file import is_robot_path

    if is_robot_path(a) and is_robot_path(b):
        return Path(a).expanduser().resolve() == Path(b).expanduser().resolve()
    if is_robot_path(a) != is_robot_path(b):   # a path and a name: the name's robot file?
        path, name = (a, b) if is_robot_path(a) else (b, a)
        return Path(path).stem == name
    return a == b


def _plan_planner_options(planner: str, variant: str | None) -> tuple | None:
    """``--variant`` is a TCBiRRT option (default: the improved variant, which plans more of the hard and the
    generated scenes, see docs/decisions/0019-native-planning-kernel.md); other planners take the pipeline's
    defaults."""
    from .pipeline import PLANNER_DEFAULTS

    if planner == "tcbirrt":
        return PLANNER_DEFAULTS["tcbirrt"] + (("variant", variant or "improved"),)
    if variant not in (None, "paper"):
        raise UsageError(f"--variant {variant!r}: only the tcbirrt planner has variants, not {planner!r}")
    return None


def _cmd_plan(args) -> int:
    from .pipeline import PipelineOptions, run_pipeline
    from .scene import Scene
    from .trials import TrialGenerator

    interrupt.progress(0, 1, "trials")
    scene_name = ca.check_scene(args.scene)
    planner = ca.check_planner(args.planner)
    scene = Scene.load(scene_name)
    if args.robot is not None:
        from .model.example_robots import known_robot_names
        from .model.robot_file import is_robot_path

        known = known_robot_names()
        if args.robot not in known and not is_robot_path(args.robot):
            raise UsageError(f"--robot {args.robot!r}: unknown robot; expected one of {', '.join(known)}, "
                             "or a robot file / URDF path")
    if args.robot is not None and scene.robot is not None and not _same_robot(args.robot, scene.robot):
        raise UsageError(f"--robot {args.robot!r}: scene {scene.name!r} is made for robot {scene.robot!r} "
                         "(its grasps and poses belong to that robot)")
    robot_name = args.robot or scene.robot or "tcbirrt_dual_arm"
    robot = _load_robot(robot_name)
    if getattr(robot, "is_floating", False):   # (a stand-in robot object of the tests has no base)
        return _cmd_plan_floating(args, robot, scene)
    if getattr(args, "restore_attitude", False):
        raise UsageError(f"--restore-attitude: robot {robot_name!r} has a fixed base (the option is for a "
                         "free-floating robot's base attitude)")
    t0 = time.perf_counter()
    files: list[str] = []   # outputs written so far (each complete: written atomically)
    try:
        _check_fits(scene, robot, robot_name, given=bool(args.robot or scene.robot))
        trial = TrialGenerator(robot, scene).generate(args.trial, args.seed)
        opts = PipelineOptions(planner=planner, plan_time_limit=args.time_limit, plan_clock=args.clock,
                               warm_start=not args.cold,
                               compile_kernels=True if args.compile_kernels else "auto", workers=args.workers,
                               planner_options=_plan_planner_options(planner, args.variant))
        res = run_pipeline(robot, scene, trial.q_start, trial.q_goal, opts, seed=args.seed + args.trial)
        interrupt.check()
        out = res.to_dict()
        out["wall_time_s"] = time.perf_counter() - t0
        from .collision.checker import pair_budget_counts

        out["pairs"] = pair_budget_counts(robot, scene)
        _plan_report(args, scene, out, res, robot)
        _plan_outputs(args, robot, scene, res, files)   # the files first, then the JSON that names them
        with interrupt.committing():   # the record of a complete run: a signal from here on does not undo it
            interrupt.progress(1, 1, "trials")
            if args.json:
                out["files"] = files
                _write_json(args.json, out)
    except BaseException as exc:  # a failed or interrupted run still says what it has, never success
        if args.json:
            sig = interrupt.received()
            rec = {"success": False, "status": "interrupted" if sig is not None else "error",
                   "error": f"{type(exc).__name__}: {exc}" if sig is None else f"interrupted by {exc}",
                   "files": files, "wall_time_s": time.perf_counter() - t0}
            with contextlib.suppress(OptplanError):   # the first error is the one reported
                _write_json(args.json, rec)
        raise
    return 0 if res.success else 1


def _plan_report(args, scene, out: dict, res, robot) -> None:
    pc = out["pairs"]
    print(f"plan -> optimize -> verify   scene {scene.name!r}, trial {args.trial}, seed {args.seed}, robot {robot.name!r}")
    print(f"  pairs checked: self {pc['self']}, robot-obstacle {pc['robot_obstacle']}, object-obstacle "
          f"{pc['object_obstacle']}, object-robot {pc['object_robot']} ({pc['object_robot_rigid']} rigid with a "
          "holding hand: no NLP rows while both hands hold)")
    for k in ("success", "plan_status", "plan_time_s", "n_regrasp", "opt_status", "opt_time_s", "opt_setup_time_s",
              "opt_iterations", "opt_wall_s", "opt_cpu_s", "max_closed_chain_residual", "min_clearance_m", "wall_time_s"):
        v = out[k]
        print(f"  {k:28s} {v:.3e}" if isinstance(v, float) else f"  {k:28s} {v}")
    for s in res.segments:
        print(f"    segment {s.kind:11s} {s.arm or '':2s} {s.solution.status.value:28s} it={s.solution.total_iterations:4d} "
              f"ipopt={s.solution.total_wall_time:6.2f}s clearance={s.report.min_clearance_m:+.3f} m "
              f"attempts={'+'.join(a['reason'] for a in s.attempts)}")


def _plan_outputs(args, robot, scene, res, files: list[str]) -> None:
    """``--save``, ``--html``, ``--plot`` of ``optplan plan``, each file written atomically and added
    to ``files`` once complete."""
    if args.save and res.segments:
        files.append(str(res.save(args.save, robot=robot.name, scene=scene.name)))
    if (args.html or args.plot) and res.segments:
        from .viz.outputs import write_views

        for p in write_views(robot, scene, res.t, res.q, res.constrained, html=args.html, plot_dir=args.plot,
                             title=f"optplan plan: {scene.name}, trial {args.trial}"):
            files.append(str(p))
            print(f"wrote {p}")


def _cmd_plan_floating(args, robot, scene) -> int:
    """``optplan plan`` for a free-floating robot: :func:`optplan.floating_pipeline.run_floating_pipeline`."""
    from .floating_pipeline import (
        options_for_scene,
        run_floating_pipeline,
        scene_start,
        summary_lines,
        trial_goal,
    )

    res = run_floating_pipeline(robot, scene, scene_start(robot, scene), trial_goal(scene, args.trial, args.seed),
                                options_for_scene(scene, restore_attitude=True if args.restore_attitude else None,
                                                  plan_time_limit=args.time_limit), seed=args.seed + args.trial)
    print(f"plan -> optimize -> verify   scene {scene.name!r}, trial {args.trial}, seed {args.seed}, robot "
          f"{robot.name!r} (free-floating base, zero momentum)")
    print("\n".join(summary_lines(res)))
    traj = res.trajectory()
    if args.html and traj is not None:   # the view shows the base moving (full configurations)
        from .viz.outputs import write_views

        for p in write_views(robot, scene, traj[0], traj[1], html=args.html,
                             title=f"optplan plan: {scene.name}, trial {args.trial}"):
            print(f"wrote {p}")
    with interrupt.committing():   # the record last: a signal from here on does not undo it
        if args.json:
            r = res.report
            _write_json(args.json, {"success": res.success, "plan_status": res.plan.status.value,
                                    "report": r.to_dict() if r is not None else None, "attempts": res.attempts,
                                    "object_goal_error": list(res.goal_error)})
    return 0 if res.success else 1


def _write_json(path: str, data) -> None:
    """``data`` as JSON at ``path``, atomically (complete or absent; a failed write is one line, exit 2)."""
    from ._io import write_json

    write_json(path, data)
