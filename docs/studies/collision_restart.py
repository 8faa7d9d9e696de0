"""IPOPT iterations and verification of ``optplan plan --scene S --seed K`` (trial 0) over scenes and
seeds, with the command's options (improved TCBiRRT, the default pipeline), the planner on the CPU
clock (a seeded plan then does not depend on the machine's load) and every segment in this process.
Used for decision 0021's sixth addendum (the collision re-solve from the previous solution).

    python docs/studies/collision_restart.py OUT.json default|warm|cold [--scenes 1,2,3] [--seeds 10]
    python docs/studies/collision_restart.py --compare BASE.json NEW.json

``default``: the tree's default options (run it on a ``git archive`` of main with ``PYTHONPATH``);
``warm`` / ``cold``: ``PipelineOptions.collision_warm_start`` True / False.
"""
from __future__ import annotations

import argparse
import json
import sys
import time


def run(out: str, mode: str, scenes: list[int], seeds: int) -> None:
    from optplan.model.example_robots import load_robot
    from optplan.pipeline import PLANNER_DEFAULTS, PipelineOptions, run_pipeline
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    rows = []
    for sc in scenes:
        scene = Scene.load(f"ssps_scene{sc}")
        robot = load_robot(scene.robot or "tcbirrt_dual_arm")
        for seed in range(seeds):
            trial = TrialGenerator(robot, scene).generate(0, seed)
            kw = {} if mode == "default" else {"collision_warm_start": mode == "warm"}
            opts = PipelineOptions(planner="tcbirrt", plan_time_limit=10.0, plan_clock="cpu", workers=1,
                                   planner_options=PLANNER_DEFAULTS["tcbirrt"] + (("variant", "improved"),), **kw)
            c0 = time.process_time()
            res = run_pipeline(robot, scene, trial.q_start, trial.q_goal, opts, seed=seed)
            r = {"scene": sc, "seed": seed, "success": res.success, "it": res.iterations,
                 "cpu_s": time.process_time() - c0, "clear": res.min_clearance_m,
                 "res": res.max_closed_chain_residual,
                 "att": [[(a["reason"], a["iterations"]) for a in s.attempts] for s in res.segments]}
            print(json.dumps(r), flush=True)
            rows.append(r)
    with open(out, "w") as f:
        json.dump(rows, f)


def compare(base: str, new: str) -> None:
    with open(base) as f:
        a = {(r["scene"], r["seed"]): r for r in json.load(f)}
    with open(new) as f:
        b = {(r["scene"], r["seed"]): r for r in json.load(f)}
    fewer = more = 0
    for k in sorted(a):
        if b[k]["it"] != a[k]["it"]:
            print(f"scene {k[0]} seed {k[1]}: {a[k]['it']} -> {b[k]['it']} iterations, verified {b[k]['success']}")
        fewer += b[k]["it"] < a[k]["it"]
        more += b[k]["it"] > a[k]["it"]
    for sc in sorted({k[0] for k in a}):
        print(f"scene {sc}: {sum(r['it'] for k, r in a.items() if k[0] == sc)} -> "
              f"{sum(r['it'] for k, r in b.items() if k[0] == sc)} iterations")
    print(f"total {sum(r['it'] for r in a.values())} -> {sum(r['it'] for r in b.values())}; fewer on {fewer}, more on "
          f"{more}; verified {sum(r['success'] for r in a.values())} / {sum(r['success'] for r in b.values())} of {len(a)}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?")
    ap.add_argument("mode", nargs="?", choices=["default", "warm", "cold"])
    ap.add_argument("--scenes", default="1,2,3")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--compare", nargs=2, metavar=("BASE", "NEW"))
    args = ap.parse_args(argv)
    if args.compare:
        compare(*args.compare)
        return 0
    if not args.out or not args.mode:
        ap.error("give OUT.json and a mode, or --compare BASE.json NEW.json")
    run(args.out, args.mode, [int(s) for s in args.scenes.split(",")], args.seeds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
