"""Does a seed give the same TCBiRRT search on a faster clock? The benchmark's trials (``bench tcbirrt``'s generator
and planner construction), each planned once per clock factor K (alternating which goes first): the CPU clock of the
planner's deadlines runs K times faster (Python's deadlines and the end times handed to the native searches), the
query's limit is ``--time-limit`` × K so that it stays the same CPU time. One JSON row per query: per K the status,
iterations, nodes, lead-path and regrasp attempts, a digest of the path and the CPU seconds.

A study script (not part of the package); it runs on any tree that has ``optplan.planners.base.CLOCKS`` and the
kernels' ``_clock`` (``main`` before the work budgets too: ``PYTHONPATH=<tree>``).

    python docs/studies/fast_clock_repro.py --fast 1 --scenes hard_window --trials 78,79          # a plain run
    python docs/studies/fast_clock_repro.py --fast 1,5 --scenes suite,ssps --trials 100-109       # paired clocks
"""
from __future__ import annotations

import argparse
import hashlib
import json
import time

import numpy as np

import optplan.planners.base as base
import optplan.planners.kernel.rrtc as rrtc
import optplan.planners.kernel.sampler as sampler
from optplan.bench.tcbirrt import _W, _worker_setup, expand_scenes

REAL = (dict(base.CLOCKS), rrtc._clock, sampler._clock)


def set_clock(k: float) -> None:
    """The planner's "cpu" clock K times fast (1: the real one)."""
    if k == 1.0:
        base.CLOCKS.update(REAL[0])
        rrtc._clock, sampler._clock = REAL[1], REAL[2]
        return
    t0 = time.process_time()
    base.CLOCKS["cpu"] = lambda: t0 + k * (time.process_time() - t0)

    def native(d: base.Deadline) -> tuple[int, float]:
        return 1, time.process_time() + max(0.0, d.remaining()) / k

    rrtc._clock = sampler._clock = native


def _trials(s: str) -> list[int]:
    if "-" in s:
        a, b = s.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(x) for x in s.split(",")]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fast", default="1,5", help="clock factors, comma-separated")
    ap.add_argument("--scenes", default="hard_window")
    ap.add_argument("--trials", default="78,79", help="a-b or a,b,...")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--spec", default="tcbirrt:variant=improved")
    ap.add_argument("--time-limit", type=float, default=10.0, help="CPU seconds [s] per query")
    a = ap.parse_args()
    factors = [float(x) for x in a.fast.split(",")]
    for sc in expand_scenes(a.scenes.split(",")):
        _worker_setup("tcbirrt_dual_arm", [sc], [a.spec])
        w = _W[sc]
        for n, tr in enumerate(_trials(a.trials)):
            t = w["gen"].generate(tr, a.seed)
            row: dict = {"scene": sc, "trial": tr}
            for k in (factors if n % 2 == 0 else factors[::-1]):
                set_clock(k)
                res = w["planners"][a.spec].plan(t.q_start, t.q_goal, time_limit=a.time_limit * k, seed=t.seed, clock="cpu")
                set_clock(1.0)
                s = res.stats
                row[f"x{k:g}"] = {"status": res.status.value, "iterations": s.get("iterations"), "nodes": s.get("nodes"),
                                  "guide_attempts": s.get("guide_attempts"), "regrasp_attempts": s.get("regrasp_attempts"),
                                  "path": hashlib.sha1(np.asarray(res.path, float).tobytes()).hexdigest()[:16]
                                  if res.success else None, "cpu_s": round(float(s["cpu_time_s"]), 3)}
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
