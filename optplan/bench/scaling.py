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
import logging
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from ..viz import save_figure

__all__ = ["measure", "compare_runs", "plot_scaling", "main"]


def compare_runs(a: list[dict], b: list[dict], time_limit: float) -> dict:
    """Per-unit comparison of two runs of the same workload. A unit solved in both runs must have
    the same iterations and path size (per-unit seeds); a unit that one run solved and the other
    stopped at its time limit is timing-dependent and counted apart, as long as the solved run
    needed at least half the limit. ``other`` counts every other difference (should be 0)."""
    ka = {(r["scene"], r["trial"], r["planner"]): r for r in a}
    kb = {(r["scene"], r["trial"], r["planner"]): r for r in b}
    out = {"units": len(ka), "both_solved": 0, "identical": 0, "limit_flips": 0, "both_timeout": 0, "other": 0}
    if set(ka) != set(kb):
        out["other"] += len(set(ka) ^ set(kb))
    for k in set(ka) & set(kb):
        x, y = ka[k], kb[k]
        if x["status"] == y["status"] == "exact":
            out["both_solved"] += 1
            same = (x["stats"].get("iterations"), x["n_configurations"]) == (y["stats"].get("iterations"),
                                                                              y["n_configurations"])
            out["identical" if same else "other"] += 1
        elif x["status"] == y["status"] == "timeout":
            out["both_timeout"] += 1
        elif {x["status"], y["status"]} == {"exact", "timeout"}:
            solved = x if x["status"] == "exact" else y
            out["limit_flips" if (solved.get("cpu_time_s") or 0.0) >= 0.5 * time_limit else "other"] += 1
        else:
            out["other"] += x["status"] != y["status"]
    return out


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
        cluster = None
        if engine == "dask":   # started here so that its start-up is timed apart from the work
            from distributed import Client, LocalCluster

            cluster = LocalCluster(n_workers=w, threads_per_worker=1, processes=True, dashboard_address=None,
                                   silence_logs=logging.CRITICAL)
            with Client(cluster) as c:
                c.wait_for_workers(w)
            cfg.address, cfg.jobs = cluster.scheduler_address, 1
        startup = time.perf_counter() - t0
        t1 = time.perf_counter()
        try:
            rows = run(cfg)
        finally:
            if cluster is not None:
                cluster.close()
        wall = time.perf_counter() - t1
        load1 = os.getloadavg()[0]
        cpu = float(sum((r.get("cpu_time_s") or 0.0) for r in rows))
        ref = rows if ref is None else ref
        cmp = compare_runs(ref, rows, time_limit)
        runs.append({"workers": w, "startup_s": startup, "wall_s": wall, "units_per_s": len(rows) / wall,
                     "unit_cpu_s": cpu, "cpu_per_wall": cpu / wall, "units": len(rows),
                     "loadavg_1min_before": load0, "loadavg_1min_after": load1, "vs_first_run": cmp,
                     "same_results": cmp["other"] == 0, "dir": str(d)})
        print(f"  {engine} {w} worker(s): start-up {startup:5.1f} s, work wall {wall:6.1f} s, planner CPU {cpu:6.1f} s ({cpu / wall:.2f} per wall s), "
              f"load {load0:.1f} -> {load1:.1f}; vs the first run: {cmp['identical']}/{cmp['both_solved']} solved in both "
              f"identical, {cmp['limit_flips']} solved/timed out at the limit, {cmp['other']} other differences",
              flush=True)
    summary = {}
    for w in workers:
        rs = [r for r in runs if r["workers"] == w]
        summary[str(w)] = {"median_wall_s": float(np.median([r["wall_s"] for r in rs])),
                           "median_startup_s": float(np.median([r["startup_s"] for r in rs])),
                           "median_cpu_per_wall": float(np.median([r["cpu_per_wall"] for r in rs]))}
    base = summary[str(workers[0])]
    for w in workers:
        s = summary[str(w)]
        s["wall_speedup"] = base["median_wall_s"] / s["median_wall_s"]
        s["throughput_speedup"] = s["median_cpu_per_wall"] / base["median_cpu_per_wall"]
    res = {"engine": engine, "workers": list(workers), "repeats": repeats, "trials": trials, "scenes": list(scenes),
           "planners": list(planners), "time_limit_s": time_limit, "cores": os.cpu_count(), "runs": runs,
           "summary": summary, "all_results_identical": all(r["same_results"] for r in runs)}
    from .._io import write_json

    write_json(out / "scaling.json", res)
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
    ax[0].set_ylabel("wall time of the work [s] (start-up apart)")
    ax[1].set_ylabel("planner CPU s per wall s")
    for a in ax:
        a.set_xlabel(f"{res['engine']} workers")
        a.set_xticks(ws)
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    n = res["runs"][0]["units"]
    fig.suptitle(f"{n} planner runs ({', '.join(res['planners'])}; {res['trials']} trials x {len(res['scenes'])} scenes), "
                 f"{res['cores']} cores shared with other jobs", fontsize=9)
    return save_figure(fig, path)


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
    print(f"per-trial results equal in every run (apart from queries at the time limit): {res['all_results_identical']}")
    if a.plot:
        print(f"wrote {plot_scaling(res, a.plot)}")
    return 0 if res["all_results_identical"] else 1


if __name__ == "__main__":
    sys.exit(main())
