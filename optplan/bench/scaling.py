"""Scaling of a benchmark engine with the number of workers: the same ``optplan bench tcbirrt``
workload run with 1, 2, ... workers, alternating (1, 2, 2, 1, 1, 2, ...) so that a changing load
on the machine hits every worker count alike. Reports per run the wall time, the CPU seconds the
units themselves used (their throughput per wall second is the speed-up that does not depend on
how fast one unit is), the machine's load average, and checks that every run produced the same
per-trial results.

    python -m optplan.bench.scaling [--engine dask] [--workers 1,2] [--repeats 3] [--trials 8] [--out DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["measure", "plot_scaling", "main"]


def _fingerprint(rows: list[dict]) -> list:
    """What must not depend on the engine: per unit the status, iterations and path size (a query
    stopped by its time limit is timing-dependent: only its status counts)."""
    return sorted((r["scene"], r["trial"], r["planner"], r["status"],
                   None if r["status"] == "timeout" else (r["stats"].get("iterations"), r["n_configurations"]))
                  for r in rows)


def measure(workers=(1, 2), repeats: int = 3, engine: str = "dask", trials: int = 8, scenes=("1", "2", "3"),
            planners=("tcbirrt", "cbirrt2"), time_limit: float = 1.0, out="scaling") -> dict:
    """Run the workload ``repeats`` times per worker count (alternating order); returns the runs."""
    from .tcbirrt import BenchConfig, run

    out = Path(out)
    order = []
    for k in range(repeats):
        order += list(workers) if k % 2 == 0 else list(reversed(workers))
    runs = []
    ref = None
    for i, w in enumerate(order):
        d = out / f"run{i}_{engine}_{w}"
        shutil.rmtree(d, ignore_errors=True)
        cfg = BenchConfig(scenes=list(scenes), planners=list(planners), trials=trials, time_limit=time_limit, seed=0,
                          jobs=w, out=str(d), progress=False, plot=False, engine=engine, clock="cpu")
        load0 = os.getloadavg()[0]
        t0 = time.perf_counter()
        rows = run(cfg)
        wall = time.perf_counter() - t0
        load1 = os.getloadavg()[0]
        cpu = float(sum((r.get("cpu_time_s") or 0.0) for r in rows))
        fp = _fingerprint(rows)
        ref = fp if ref is None else ref
        runs.append({"workers": w, "wall_s": wall, "unit_cpu_s": cpu, "cpu_per_wall": cpu / wall, "units": len(rows),
                     "loadavg_1min_before": load0, "loadavg_1min_after": load1, "same_results": fp == ref})
        print(f"  {engine} {w} worker(s): wall {wall:6.1f} s, planner CPU {cpu:6.1f} s ({cpu / wall:.2f} per wall s), "
              f"load {load0:.1f} -> {load1:.1f}, results {'identical' if fp == ref else 'DIFFER'}", flush=True)
    summary = {}
    for w in workers:
        rs = [r for r in runs if r["workers"] == w]
        summary[str(w)] = {"median_wall_s": float(np.median([r["wall_s"] for r in rs])),
                           "median_cpu_per_wall": float(np.median([r["cpu_per_wall"] for r in rs]))}
    base = summary[str(workers[0])]
    for w in workers:
        s = summary[str(w)]
        s["wall_speedup"] = base["median_wall_s"] / s["median_wall_s"]
        s["throughput_speedup"] = s["median_cpu_per_wall"] / base["median_cpu_per_wall"]
    res = {"engine": engine, "workers": list(workers), "repeats": repeats, "trials": trials, "scenes": list(scenes),
           "planners": list(planners), "time_limit_s": time_limit, "cores": os.cpu_count(), "runs": runs,
           "summary": summary, "all_results_identical": all(r["same_results"] for r in runs)}
    (out / "scaling.json").write_text(json.dumps(res, indent=2))
    return res


def plot_scaling(res: dict, path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
    for r in res["runs"]:
        ax[0].scatter(r["workers"], r["wall_s"], color="C0", alpha=0.6)
        ax[1].scatter(r["workers"], r["cpu_per_wall"], color="C1", alpha=0.6)
    ws = res["workers"]
    ax[0].plot(ws, [res["summary"][str(w)]["median_wall_s"] for w in ws], "-o", color="C0", label="median")
    ax[1].plot(ws, [res["summary"][str(w)]["median_cpu_per_wall"] for w in ws], "-o", color="C1", label="median")
    ax[0].set_ylabel("wall time of the run [s]")
    ax[1].set_ylabel("planner CPU s per wall s")
    for a in ax:
        a.set_xlabel(f"{res['engine']} workers")
        a.set_xticks(ws)
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    n = res["runs"][0]["units"]
    fig.suptitle(f"{n} planner runs ({', '.join(res['planners'])}; {res['trials']} trials x {len(res['scenes'])} scenes), "
                 f"{res['cores']} cores shared with other jobs", fontsize=9)
    fig.tight_layout()
    p = Path(path)
    fig.savefig(p, dpi=110)
    plt.close(fig)
    return p


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="scaling of a benchmark engine with the number of workers")
    ap.add_argument("--engine", default="dask", choices=["local", "dask"])
    ap.add_argument("--workers", default="1,2", help="comma-separated worker counts")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--trials", type=int, default=8, help="trials per scene")
    ap.add_argument("--time-limit", type=float, default=1.0, help="per planner query [s CPU]")
    ap.add_argument("--out", default="scaling")
    ap.add_argument("--plot", help="PNG of the runs")
    a = ap.parse_args(argv)
    res = measure(tuple(int(w) for w in a.workers.split(",")), a.repeats, a.engine, a.trials, time_limit=a.time_limit,
                  out=a.out)
    for w, s in res["summary"].items():
        print(f"{res['engine']} {w} worker(s): median wall {s['median_wall_s']:.1f} s (speed-up {s['wall_speedup']:.2f}), "
              f"planner CPU per wall s {s['median_cpu_per_wall']:.2f} (speed-up {s['throughput_speedup']:.2f})")
    print(f"per-trial results identical in every run: {res['all_results_identical']}")
    if a.plot:
        print(f"wrote {plot_scaling(res, a.plot)}")
    return 0 if res["all_results_identical"] else 1


if __name__ == "__main__":
    sys.exit(main())
