"""A portfolio of interleaved TCBiRRT searches, simulated from single searches: would k independent searches of a query
run side by side (the first alone for ``N0`` iterations) solve more queries within the time limit than one?

``python -m optplan.bench.portfolio_sim run --scenes A.toml,B.toml,... --seed S --offset K --out offK.jsonl``
plans trial 0 of each scene (base seed ``S``) once with the planner seed ``trial seed + K`` (improved variant,
CPU clock, ``--time-limit`` s) and appends status, CPU seconds and iterations per scene (a run resumes);
``python -m optplan.bench.portfolio_sim simulate off0.jsonl off1.jsonl off2.jsonl [--time-limit 10]`` then prints,
for portfolios of 2 and 3 members and several ``N0``, how many scenes would be solved within the limit.

The simulation: member i solves after ``n_i`` of its iterations at ``r_i`` CPU seconds per iteration (its single
run's time / iterations; a member that timed out never solves). The first member runs alone for ``N0`` iterations;
then all members take turns iteration by iteration, so that each iteration of the portfolio costs the sum of the
members' ``r``. A member that timed out alone within the limit cannot solve within it in a portfolio, so single runs
to the limit suffice.
"""
from __future__ import annotations

import argparse
import json
import math
import os
from typing import Any

import numpy as np

__all__ = ["portfolio_time", "simulate", "main"]


def portfolio_time(members: list[tuple[float, float]], n0: int) -> float:
    """CPU seconds until the first of ``members`` ((CPU s per iteration, iterations to solve or inf), the first one
    alone for ``n0`` iterations, then all in turns) finds its path; inf when none does."""
    r0, n_first = members[0]
    if n_first <= n0:
        return n_first * r0
    t0, cycle = n0 * r0, sum(r for r, _ in members)
    return min(t0 + (n - (n0 if i == 0 else 0)) * cycle for i, (r, n) in enumerate(members))


def _load(path: str) -> dict[str, dict[str, Any]]:
    rows = {}
    with open(path) as f:
        for line in f:
            r = json.loads(line)
            if r.get("status") != "no_trial":
                rows[r["scene"]] = r
    return rows


def simulate(paths: list[str], time_limit: float = 10.0, n0s: tuple[int, ...] = (0, 1000, 3000, 10000, 40000)) -> list[dict[str, Any]]:
    """Rows (members, N0, first member's run, solved) from single runs (one file per planner-seed offset)."""
    runs = [_load(p) for p in paths]
    scenes = sorted(set.intersection(*(set(r) for r in runs)))

    def member(r: dict[str, Any]) -> tuple[float, float]:
        rate = float(r["cpu_s"]) / max(int(r["iterations"]), 1)
        return rate, float(r["iterations"]) if r["success"] and r["cpu_s"] <= time_limit else math.inf

    out = [{"members": 1, "n0": 0, "first": i, "scenes": len(scenes),
            "solved": sum(bool(run[s]["success"]) and run[s]["cpu_s"] <= time_limit for s in scenes)}
           for i, run in enumerate(runs)]
    for k in range(2, len(runs) + 1):
        for n0 in n0s:
            for first in range(len(runs)):
                order = [first] + [i for i in range(len(runs)) if i != first][:k - 1]
                ts = [portfolio_time([member(runs[i][s]) for i in order], n0) for s in scenes]
                out.append({"members": k, "n0": n0, "first": first, "scenes": len(scenes),
                            "solved": int(sum(t <= time_limit for t in ts))})
    return out


def _run(scenes: list[str], seed: int, offset: int, time_limit: float, out: str, robot: str) -> None:
    from .tcbirrt import _W, _worker_setup

    spec = "tcbirrt:variant=improved"
    done = set(_load(out)) if os.path.exists(out) else set()
    for sc in scenes:
        if sc in done:
            continue
        _worker_setup(robot, [sc], [spec])
        w = _W.pop(sc)
        try:
            t = w["gen"].generate(0, seed)
        except Exception as e:  # noqa: BLE001 - a scene without a trial for this seed is a row, not a crash
            row: dict[str, Any] = {"scene": sc, "status": "no_trial", "message": str(e)}
        else:
            res = w["planners"][spec].plan(t.q_start, t.q_goal, time_limit=time_limit, seed=t.seed + offset, clock="cpu")
            row = {"scene": sc, "offset": offset, "status": res.status.value, "success": bool(res.success),
                   "cpu_s": float(res.stats["cpu_time_s"]), "iterations": int(res.stats.get("iterations", 0))}
        with open(out, "a") as f:
            f.write(json.dumps(row) + "\n")
        print(sc, row["status"], f"{row.get('cpu_s', 0.0):.2f} s", flush=True)


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.portfolio_sim", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="single searches with one planner-seed offset")
    r.add_argument("--scenes", required=True, help="scene TOMLs or names, comma-separated")
    r.add_argument("--seed", type=int, required=True, help="the trials' base seed")
    r.add_argument("--offset", type=int, default=0, help="added to each trial's planner seed")
    r.add_argument("--time-limit", type=float, default=10.0, help="CPU seconds [s] per query")
    r.add_argument("--robot", default="tcbirrt_dual_arm")
    r.add_argument("--out", required=True, help="JSON-lines file (appended; a run resumes)")
    s = sub.add_parser("simulate", help="portfolios from single runs")
    s.add_argument("runs", nargs="+", help="the run files, one per offset")
    s.add_argument("--time-limit", type=float, default=10.0, help="CPU seconds [s] per query")
    a = ap.parse_args(argv)
    if a.cmd == "run":
        _run(a.scenes.split(","), a.seed, a.offset, a.time_limit, a.out, a.robot)
        return []
    rows = simulate(a.runs, a.time_limit)
    print("| members | N0 (iterations) | first member | solved |")
    print("|---|---|---|---|")
    for row in rows:
        print(f"| {row['members']} | {row['n0']} | {row['first']} | {row['solved']} / {row['scenes']} |")
    best = max((r["solved"] for r in rows if r["members"] > 1), default=0)
    singles = [r["solved"] for r in rows if r["members"] == 1]
    print(f"single searches {min(singles)}-{max(singles)}; best portfolio {best}; mean single "
          f"{float(np.mean(singles)):.1f}")
    return rows


if __name__ == "__main__":
    main()
