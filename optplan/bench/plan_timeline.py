"""``optplan plan`` as the command runs it (its segment worker included), as a timeline per process:
when each step starts and ends (wall ``perf_counter``, shared by the processes) and each process's own
CPU time then [s]; and the wall an idle machine would take, from the CPU times alone.

``python -m optplan.bench.plan_timeline [--scene 1] [--seed 0] [--workers 2] [--early-worker auto|on|off]``

On a loaded machine the wall figures are inflated by waiting for a core; the CPU figures are not. The
estimate ``idle wall`` assumes each process has a core of its own: the longer of the two chains
(this process up to the segments sent, or up to the fork plus the worker's preparation, then the
worker's segments; or this process's own segments), plus this process's work after the segments
(report, exit not included). :mod:`optplan.bench.plan_wall` splits the same run into sections, in
one process.
"""
from __future__ import annotations

import time

_T0 = time.perf_counter()   # the process's CPU clock counts from its start (interpreter included)

import argparse  # noqa: E402
import importlib  # noqa: E402
import os  # noqa: E402
import sys  # noqa: E402
from typing import Any  # noqa: E402

#: the write end of the pipe the processes report their events to (inherited by the forked worker)
_FD: list[int] = []


def _event(what: str) -> None:
    """One event of this process: name, pid, wall [s since the run began], this process's CPU [s]."""
    if _FD:
        os.write(_FD[0], f"{what}\t{os.getpid()}\t{time.perf_counter() - _T0:.4f}\t{time.process_time():.4f}\n"
                 .encode())


def _timed_warm(robot, scene) -> None:
    """The pipeline's worker preparation, timed (runs in the worker)."""
    _event("worker: preparation starts")
    _WARM[0](robot, scene)
    _event("worker: preparation ends")


def _timed_segment(robot, scene, seg_path, kind, arm, *rest):
    """The pipeline's segment job, timed (in whichever process runs it)."""
    _event(f"segment {kind} {arm or ''} ({len(seg_path)} configurations) starts")
    out = _SEGMENT[0](robot, scene, seg_path, kind, arm, *rest)
    _event(f"segment {kind} {arm or ''} ends: {out[0].total_iterations} iterations")
    return out


_WARM: list = []
_SEGMENT: list = []


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.plan_timeline", description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="1")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=None, help="segment processes (default: the command's)")
    ap.add_argument("--early-worker", choices=("auto", "on", "off"), default="auto",
                    help="fork the segment worker before planning (PipelineOptions.early_worker; auto: the "
                         "command's choice, when the load average leaves a core free)")
    args = ap.parse_args(argv)
    r, w = os.pipe()
    _FD.append(w)
    _event("start (after the interpreter)")
    # what the `optplan` command imports first (by name, as bench.plan_wall: a benchmark does not depend on
    # the command line), then the plan command's modules
    importlib.import_module("optplan.cli")
    from optplan import pipeline
    from optplan import workers as W
    from optplan.cli_args import check_scene
    from optplan.model.example_robots import load_robot
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    _event("optplan.cli and the plan command's modules imported")
    _SEGMENT.append(pipeline._spline_segment)
    pipeline._spline_segment = _timed_segment
    main_pid = os.getpid()
    # where the segment workers are prepared and sent: their own module, or (an older tree, for a paired
    # comparison) the pipeline itself; the oldest forks its worker in run_jobs and prepares nothing
    sched: Any
    try:
        sched = importlib.import_module("optplan.pipeline_workers")
    except ImportError:
        sched = pipeline
    run_jobs = sched.run_jobs
    start = getattr(sched, "start_workers", None)
    if start is not None:
        _WARM.append(sched.warm_worker)
        sched.warm_worker = _timed_warm
        if args.early_worker != "auto":   # the command's default (None) asks this function
            sched._a_core_is_free = lambda: args.early_worker == "on"

    def start_workers(*a, **k):
        _event("start_workers (fork)")
        return start(*a, **k)

    def timed_run_jobs(*a, **k):
        _event("segments sent (run_jobs)")
        try:
            return run_jobs(*a, **k)
        finally:
            _event("segments back")

    sched.run_jobs = timed_run_jobs
    if start is not None:
        sched.start_workers = start_workers
    # the plan command's steps and options (its TCBiRRT variant, improved; its segment processes)
    scene = Scene.load(check_scene(args.scene))
    robot = load_robot(scene.robot or "tcbirrt_dual_arm")
    trial = TrialGenerator(robot, scene).generate(0, args.seed)
    planner_options = pipeline.PLANNER_DEFAULTS["tcbirrt"] + (("variant", "improved"),)
    opts = pipeline.PipelineOptions(planner_options=planner_options, workers=args.workers)
    res = pipeline.run_pipeline(robot, scene, trial.q_start, trial.q_goal, opts, seed=args.seed)
    res.to_dict()
    _event("command done")
    W.shutdown()
    os.close(w)
    rows = []
    with os.fdopen(r) as f:
        for line in f:
            name, pid_s, wall_s, cpu_s = line.rstrip("\n").split("\t")
            rows.append((float(wall_s), name, int(pid_s), float(cpu_s)))
    rows.sort()
    print(f"{'event':58s} {'process':>8s} {'wall s':>8s} {'cpu s':>8s}")
    for wall, what, pid, cpu in rows:
        print(f"{what:58s} {'main' if pid == main_pid else 'worker':>8s} {wall:8.3f} {cpu:8.3f}")
    print(f"optplan plan --scene {args.scene} --seed {args.seed}: success {res.success}, {res.iterations} IPOPT "
          "iterations")
    print(f"idle wall (estimate from CPU, see the module's docstring): {_idle_estimate(rows, main_pid):.3f} s")
    return 0 if res.success else 1


def _idle_estimate(rows, main_pid: int) -> float:
    """The wall on an idle machine from the events' CPU times (module docstring)."""
    def first(name: str, pid_main: bool = True) -> float | None:
        for _, what, pid, cpu in rows:
            if what.startswith(name) and (pid == main_pid) == pid_main:
                return cpu
        return None

    sent, back, done = first("segments sent"), first("segments back"), first("command done")
    if sent is None or back is None or done is None:
        return float("nan")
    fork = first("start_workers")
    warm_end = first("worker: preparation ends", False)
    # per process: CPU in segment jobs
    seg: dict[int, float] = {}
    start: dict[int, float] = {}
    for _, what, pid, cpu in rows:
        if what.startswith("segment ") and what.endswith("starts"):
            start[pid] = cpu
        elif what.startswith("segment ") and pid in start:
            seg[pid] = seg.get(pid, 0.0) + cpu - start.pop(pid)
    # the worker's segments start when it is prepared and the segments are sent, whichever is later
    worker_ready = sent if fork is None or warm_end is None else max(sent, fork + warm_end)
    chains = [sent + seg.get(main_pid, 0.0)]
    chains += [worker_ready + s for p, s in seg.items() if p != main_pid]
    return max(chains) + (done - back)


if __name__ == "__main__":
    sys.exit(main())
