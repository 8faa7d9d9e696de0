"""Compare pipeline option sets paired on identical plans: each trial of each scene is run once per
variant with the same start, goal and planner seed (so the same plan), and one line per run shows
success, IPOPT iterations, attempts per segment, CPU time, jerk, residual and clearance.

    python examples/compare_pipeline_options.py --scene 1,2,3 --trials 8 \\
        --variants '{"all": {"spline_velocity_activation": 0.0}, "lazy": {}}'

Variants are JSON objects of :class:`optplan.pipeline.PipelineOptions` fields (lists become
tuples). The symbolic NLP structures are forgotten before every run, so no variant reuses what
another built; the kernels stay cached (in memory and on disk) for all of them.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time

import numpy as np


def _tuples(v):
    """JSON lists as tuples (PipelineOptions holds tuples, e.g. ``ipopt_options``)."""
    return tuple(_tuples(x) for x in v) if isinstance(v, list) else v


def main(argv=None) -> int:
    from optplan.model.robot import RobotModel
    from optplan.pipeline import PipelineOptions, run_pipeline
    from optplan.problem.kernels import KernelCache
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="1", help="comma-separated: 1, 2, 3 (ssps_scene<N>) or scene names")
    ap.add_argument("--trials", type=int, default=4, help="trials per scene (from --first-trial)")
    ap.add_argument("--first-trial", type=int, default=0)
    ap.add_argument("--variants", default='{"symbolic": {"compile_kernels": false}, "auto": {}}',
                    help='JSON: {"name": {PipelineOptions field: value, ...}, ...} (default: the symbolic '
                         'kernels against the default, which uses kernels an earlier run compiled to C)')
    args = ap.parse_args(argv)
    try:
        variants = json.loads(args.variants)
        if not isinstance(variants, dict) or not variants:
            raise ValueError("expected a non-empty JSON object")
        opts = {name: dataclasses.replace(PipelineOptions(), **{k: _tuples(v) for k, v in kw.items()})
                for name, kw in variants.items()}
    except (ValueError, TypeError) as exc:
        print(f"compare_pipeline_options: error: --variants: {exc}", file=sys.stderr)
        return 2
    if args.trials < 1 or args.first_trial < 0:
        print("compare_pipeline_options: error: --trials must be >= 1 and --first-trial >= 0", file=sys.stderr)
        return 2
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    kc = KernelCache.of(robot)
    totals = {name: [] for name in opts}
    for sc in [s.strip() for s in args.scene.split(",") if s.strip()]:
        scene = Scene.load(f"ssps_scene{sc}" if sc.isdigit() else sc)
        gen = TrialGenerator(robot, scene)
        for tr in range(args.first_trial, args.first_trial + args.trials):
            trial = gen.generate(tr, 0)
            for name, o in opts.items():
                kc.clear_structures()
                c0 = time.process_time()
                res = run_pipeline(robot, scene, trial.q_start, trial.q_goal, o, seed=int(trial.seed))
                cpu = time.process_time() - c0
                d = res.to_dict()
                jerk = sum(s.solution.cost for s in res.segments)
                totals[name].append((d["opt_iterations"], cpu))
                print(f"{scene.name} t{tr} {name:12s} ok={d['success']} it={d['opt_iterations']:4d} "
                      f"att={d['attempts']} cpu={cpu:.2f} s jerk={jerk:.3e} res={d['max_closed_chain_residual']:.1e} "
                      f"clr={d['min_clearance_m']:+.4f} m", flush=True)
    for name, rows in totals.items():
        r = np.array(rows, float)
        print(f"{name:12s} iterations total {int(r[:, 0].sum())}, pipeline CPU median {np.median(r[:, 1]):.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
