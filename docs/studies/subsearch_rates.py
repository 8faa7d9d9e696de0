"""The iteration rates of TCBiRRT's sub-searches on the CPU clock (decision 0024's calibration).

A study script (not part of the package). Plans the benchmark's trials (``bench tcbirrt``'s generator and
planner construction) with the sub-searches' work budgets off by default (``--spec`` may set them), one
process, on the CPU clock, and reports per query and per kind — **regrasp** (the RRT-Connect of every
regrasp, graft regrasps included) and **lead path** (the object's RRT-Connect) — the rate = iterations / CPU
seconds of that kind, then the median over the queries with a non-zero time of the kind, and the budgets of
decision 0024's rule (rate × the seconds limit, 2 significant figures).

    OPTPLAN_CACHE=... python docs/studies/subsearch_rates.py --scenes suite --trials 10 --seed 0 --out rates.jsonl
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from optplan.bench.tcbirrt import _W, _worker_setup, expand_scenes

SPEC = ("tcbirrt:variant=improved:regrasp_iterations=0:regrasp_min_iterations=0:graft_iterations=0:"
        "guide_iterations=0:guide_attempt_iterations=0:regrasp_time_limit=2.0:regrasp_min_time_limit=0.05:"
        "graft_time_limit=0.5:guide_time_limit=3.0:guide_attempt_time=0.3")
#: budget option: (kind, the seconds limit it replaces [s])
BUDGETS = {"regrasp_iterations": ("regrasp", 2.0), "regrasp_min_iterations": ("regrasp", 0.05),
           "graft_iterations": ("regrasp", 0.5), "guide_iterations": ("lead", 3.0),
           "guide_attempt_iterations": ("lead", 0.3)}


def sig2(x: float) -> int:
    """``x`` rounded to 2 significant figures."""
    e = math.floor(math.log10(x)) - 1
    return int(round(x / 10 ** e) * 10 ** e)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="suite")
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--first-trial", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--spec", default=SPEC)
    ap.add_argument("--time-limit", type=float, default=10.0)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    rows = []
    out = Path(a.out)
    with out.open("w") as f:
        for sc in expand_scenes(a.scenes.split(",")):
            _worker_setup("tcbirrt_dual_arm", [sc], [a.spec])
            w = _W[sc]
            for trial in range(a.first_trial, a.first_trial + a.trials):
                t = w["gen"].generate(trial, a.seed)
                res = w["planners"][a.spec].plan(t.q_start, t.q_goal, time_limit=a.time_limit, seed=t.seed, clock="cpu")
                s = res.stats
                row = {"scene": sc, "trial": trial, "status": res.status.value, "iterations": int(s.get("iterations", 0)),
                       "cpu_s": float(s["cpu_time_s"]), "regrasp_attempts": int(s.get("regrasp_attempts", 0)),
                       "regrasp_iterations": int(s.get("regrasp_iterations", 0)),
                       "regrasp_time_s": float(s.get("regrasp_time_s", 0.0)),
                       "guide_attempts": int(s.get("guide_attempts", 0)),
                       "guide_iterations": int(s.get("guide_iterations", 0)), "guide_time_s": float(s.get("guide_time_s", 0.0))}
                rows.append(row)
                f.write(json.dumps(row) + "\n")
                f.flush()
                print(json.dumps(row), flush=True)
    rates = {}
    for kind, it, tm in (("regrasp", "regrasp_iterations", "regrasp_time_s"), ("lead", "guide_iterations", "guide_time_s")):
        r = [x[it] / x[tm] for x in rows if x[tm] > 0]
        rates[kind] = float(np.median(r))
        print(f"{kind}: {len(r)} queries with time; rate median {rates[kind]:.0f} it/s (quartiles "
              f"{np.percentile(r, 25):.0f} / {np.percentile(r, 75):.0f}); iterations {sum(x[it] for x in rows)}, "
              f"CPU {sum(x[tm] for x in rows):.2f} s")
    for name, (kind, sec) in BUDGETS.items():
        print(f"{name} = {sig2(rates[kind] * sec)}   ({kind} {rates[kind]:.0f} it/s x {sec} s)")


if __name__ == "__main__":
    main()
