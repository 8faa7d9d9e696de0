"""Where the wall time of ``optplan plan`` goes: one fresh process, the command's steps timed in
sections (wall ``perf_counter`` and this process's CPU time, both [s]).

``python -m optplan.bench.plan_wall [--scene 1] [--seed 0] [--html FILE] [--save FILE]``

Sections, in order: the modules the ``optplan`` command imports (``optplan.cli``, NumPy with it),
the libraries the plan command loads (CasADi, coal, Pinocchio, one by one; no SciPy), the
plan command's own modules (the pipeline, the scene, the trials), the scene and the robot loaded,
the trial, the planner made (collision checker, planner kernels), planning, the shortcuts, per
segment NLP set-up (its build: kernel loading included) and IPOPT, the verification by coal, the
report, the output files. ``kernel cache`` is the part of the set-up spent verifying and loading
the cached compiled kernels (already inside the set-up rows, not added again). The segments are
solved in this process one after the other (``workers = 1``) so that the sections add up; the
command's default solves them in two processes where the machine has two CPUs. What the
interpreter itself spends before the first line and at exit is not in the sections: time the
whole command from outside for that (``farm-bench -- optplan plan --scene 1``).
"""
from __future__ import annotations

import time

_T0, _C0 = time.perf_counter(), time.process_time()   # before any optplan module but this one

import argparse  # noqa: E402
import contextlib  # noqa: E402
import importlib  # noqa: E402
import sys  # noqa: E402
from collections import defaultdict  # noqa: E402

#: third-party modules the plan command loads, timed one by one before optplan's own (NumPy already
#: with ``optplan.cli``)
_LIBRARIES = ("casadi", "coal", "pinocchio")


class Sections:
    """Wall and CPU seconds per named section, in the order they were first entered."""

    def __init__(self) -> None:
        self.rows: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0, 0])

    @contextlib.contextmanager
    def __call__(self, name: str):
        t, c = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            row = self.rows[name]
            row[0] += time.perf_counter() - t
            row[1] += time.process_time() - c
            row[2] += 1

    def add(self, name: str, wall: float, cpu: float = float("nan")) -> None:
        row = self.rows[name]
        row[0] += wall
        row[1] += cpu
        row[2] += 1


def _wrap(sec: Sections, name: str, owner, attr: str) -> None:
    """Time every call of ``owner.attr`` as section ``name``."""
    fn = getattr(owner, attr)

    def timed(*a, **k):
        with sec(name):
            return fn(*a, **k)

    setattr(owner, attr, timed)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.plan_wall", description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="1")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--html", help="also write the 3D view (as optplan plan --html)")
    ap.add_argument("--save", help="also write the trajectory npz (as optplan plan --save)")
    args = ap.parse_args(argv)
    sec = Sections()
    # what the `optplan` command imports first (by name: a benchmark does not depend on the command line)
    sec.add("import optplan.cli", *_since(_T0, _C0, lambda: importlib.import_module("optplan.cli")))
    # the libraries the plan command's modules load, each before them (its CPU with what it needs that
    # is not loaded yet); then optplan's own modules, which find them loaded
    for lib in _LIBRARIES:
        with sec(f"import {lib}"):
            importlib.import_module(lib)
    with sec("import the plan command's modules (optplan's own)"):
        from optplan import pipeline
        from optplan.cli_args import check_scene
        from optplan.model.example_robots import load_robot
        from optplan.scene import Scene
        from optplan.trials import TrialGenerator
    import optplan.cache
    import optplan.codegen
    import optplan.planners
    import optplan.problem.kernels as kernels

    for owner in (optplan.cache, optplan.codegen, kernels):   # each module's own name of it
        _wrap(sec, "  kernel cache: verify entries", owner, "usable")
    _wrap(sec, "  kernel cache: verify and load libraries", kernels, "load_library")
    _wrap(sec, "verify (coal, 10 samples per interval)", pipeline, "verify")
    _wrap(sec, "planner made (checker, kernels)", optplan.planners, "make_planner")
    _PlannerOf(sec, optplan.planners)
    for name in ("shortcut_constrained", "shortcut_free"):
        _wrap(sec, "shortcuts", pipeline, name)
    segs = _SegmentCpu(pipeline)
    with sec("scene load"):
        scene = Scene.load(check_scene(args.scene))
    with sec("robot load"):
        robot = load_robot(scene.robot or "tcbirrt_dual_arm")
    with sec("trial"):
        trial = TrialGenerator(robot, scene).generate(0, args.seed)
    # the command's options: its TCBiRRT variant (improved), one process
    planner_options = pipeline.PLANNER_DEFAULTS["tcbirrt"] + (("variant", "improved"),)
    opts = pipeline.PipelineOptions(planner_options=planner_options, workers=1)
    t, c = time.perf_counter(), time.process_time()
    res = pipeline.run_pipeline(robot, scene, trial.q_start, trial.q_goal, opts, seed=args.seed)
    run_wall, run_cpu = time.perf_counter() - t, time.process_time() - c
    for i, (s, (seg_cpu, ipopt_cpu, callback_cpu, verify_cpu)) in enumerate(zip(res.segments, segs.rows)):
        setup_s = sum(a["setup_s"] for a in s.attempts)
        ipopt_s = sum(a["ipopt_s"] for a in s.attempts)
        label = f"segment {i} {s.kind} ({'+'.join(a['reason'] for a in s.attempts)})"
        # its CPU: the segment's own less IPOPT's and the verification's (a row of its own above)
        sec.add(f"{label}: NLP set-up", setup_s, seg_cpu - ipopt_cpu - verify_cpu)
        sec.add(f"{label}: IPOPT ({s.solution.total_iterations} it)", ipopt_s, ipopt_cpu)
        sec.add(f"{label}:   of which callbacks (CasADi functions)", float("nan"), callback_cpu)
    with sec("report (figures, pair counts)"):
        from optplan.collision.checker import pair_budget_counts

        out = res.to_dict()
        out["pairs"] = pair_budget_counts(robot, scene)
    with sec("outputs (--save, --html)"):
        if args.save:
            res.save(args.save, robot=robot.name, scene=scene.name)
        if args.html:
            from optplan.viz.outputs import write_views

            write_views(robot, scene, res.t, res.q, res.constrained, html=args.html, title="plan_wall")
    total_wall, total_cpu = time.perf_counter() - _T0, time.process_time() - _C0
    print(f"optplan plan --scene {args.scene} --seed {args.seed} --workers 1: success {res.success}, "
          f"{res.iterations} IPOPT iterations")
    print(f"{'section':58s} {'wall s':>8s} {'cpu s':>8s} {'calls':>6s}")
    for name, (w, cp, n) in sec.rows.items():
        print(f"{name:58s} {w:8.3f} {cp:8.3f} {n:6d}")
    print(f"{'run_pipeline (all of its rows above)':58s} {run_wall:8.3f} {run_cpu:8.3f}")
    print(f"{'total since this module started':58s} {total_wall:8.3f} {total_cpu:8.3f}")
    return 0 if res.success else 1


class _PlannerOf:
    """``make_planner`` whose planners' ``plan`` calls are timed as one section (wall and CPU)."""

    def __init__(self, sec: Sections, planners) -> None:
        self.sec, self.make = sec, planners.make_planner
        planners.make_planner = self.make_planner

    def make_planner(self, *a, **k):
        planner = self.make(*a, **k)
        _wrap(self.sec, "planning", planner, "plan")
        return planner


class _SegmentCpu:
    """Per segment optimized in this process: its CPU [s] in all, in IPOPT, in IPOPT's callbacks
    (the CasADi functions' own ``t_proc_*``) and in the verification, in the order solved."""

    def __init__(self, pipeline) -> None:
        from optplan.problem import nlp

        self.rows: list[list[float]] = []
        seg_fn, solve_fn, verify_fn = pipeline._spline_segment, nlp.NlpSolver.solve, pipeline.verify

        def segment(*a, **k):
            self.rows.append([0.0, 0.0, 0.0, 0.0])
            c = time.process_time()
            try:
                return seg_fn(*a, **k)
            finally:
                self.rows[-1][0] = time.process_time() - c

        def solve(solver, *a, **k):
            out = solve_fn(solver, *a, **k)
            if self.rows:
                stats = getattr(solver, "_stats", None) or {}
                self.rows[-1][1] += out.cpu_time
                self.rows[-1][2] += sum(v for n, v in stats.items() if n.startswith("t_proc_nlp_"))
            return out

        def verify(*a, **k):
            c = time.process_time()
            try:
                return verify_fn(*a, **k)
            finally:
                if self.rows:
                    self.rows[-1][3] += time.process_time() - c

        pipeline._spline_segment, pipeline.verify = segment, verify
        setattr(nlp.NlpSolver, "solve", solve)   # noqa: B010 - a benchmark times the method in place


def _since(t0: float, c0: float, fn) -> tuple[float, float]:
    """(wall, CPU) seconds from (t0, c0) to the end of ``fn()``."""
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


if __name__ == "__main__":
    sys.exit(main())
