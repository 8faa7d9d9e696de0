"""Benchmark of the base-attitude restoration NLP (EBA paper's Sections 4.1 / 4.2 on `eba_ffsr`):
the B-spline kernel transcription against the knot transcription, paired on the same scenarios.

Every run is a fresh process (``spawn``). The B-spline NLP runs twice per case: first with an empty
kernel cache (``cold``: the per-robot kernels and their derivatives are built and saved) and then
with the cache that run left on disk (``warm``: a fresh process that loads them). Prints build
(NLP construction + IPOPT instance) and IPOPT wall times, the CPU time of build + solve,
iterations (coarse + fine NLP), the C compiler's CPU time (cold compiled runs), the end
attitude error [deg] and closed-chain residual from the independent
simulator (:func:`optplan.verify.verify`), and the cost. Target: end-constrained restoration
built and solved in ≤ 1 s. The paper's own method (EBA) took ≈ 370 s (free end) and ≈ 270 s
(end constraints) and left 0.01-0.12° of attitude error in its planned trajectories.

Run: ``optplan bench restoration [--cases free_end,end_constrained] [--json out.json]``
"""
from __future__ import annotations

import multiprocessing as mp
import os
import tempfile

CASES = ("free_end", "end_constrained")
TARGET_S = 1.0
PAPER = {"free_end": "EBA ≈ 370 s, planned end attitude (0, 0, 0)°",
         "end_constrained": "EBA ≈ 270 s, planned end attitude (0.11, 0.01, −0.05)°"}


def _one(case: str, transcription: str, cache: str, compiled=False) -> dict:
    os.environ["OPTPLAN_CACHE"] = cache
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import time

    import numpy as np

    from ..methods import eba
    from ..robot import RobotModel

    robot = RobotModel.from_name("eba_ffsr")
    sc = eba.free_end_scenario() if case == "free_end" else eba.end_constrained_scenario(robot)
    o = (eba.NLPOptions.free_end if case == "free_end" else eba.NLPOptions.end_constrained)(transcription=transcription,
                                                                                       compile_kernels=compiled)
    import resource

    ch0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = eba.run_nlp(robot, sc, o)
    wall = time.perf_counter() - t0
    ch1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    compile_cpu = (ch1.ru_utime + ch1.ru_stime) - (ch0.ru_utime + ch0.ru_stime)  # the C compiler
    rep = eba.evaluate(robot, res, sc)
    i = res.info
    return {"case": case, "transcription": transcription, "N": o.n_intervals, "status": i["ipopt_status"],
            "success": bool(res.success), "iterations": i["total_iterations"], "build_s": i["setup_s"],
            "solve_s": float(res.runtime_s), "build_solve_wall_s": float(i["setup_s"] + res.runtime_s),
            "build_solve_cpu_s": i["build_and_solve_cpu_s"], "run_nlp_wall_s": wall,
            "compiler_cpu_s": float(compile_cpu),
            "end_attitude_error_deg": float(rep.final_base_attitude_error_deg),
            "closed_chain_residual": float(rep.max_closed_chain_residual) if sc.closed_chain else float("nan"),
            "cost": float(i["cost"]), "max_velocity_deg_s": float(rep.max_velocity_deg_s),
            "final_joint_error_deg": float(rep.final_joint_error_deg),
            "base_attitude_mismatch_rad": float(i["verify_base_attitude_mismatch_rad"]),
            "n_cores_load": os.getloadavg()[0]}


def run(cases=CASES) -> list[dict]:
    """Rows in the order: per case, B-spline with CasADi's VM (cold, warm cache), with compiled
    kernels (cold: compiles them; warm), knots."""
    ctx = mp.get_context("spawn")
    rows = []
    for case in cases:
        if case not in CASES:
            raise ValueError(f"cases: expected some of {CASES}, got {case!r}")
        with tempfile.TemporaryDirectory(prefix="optplan-restoration-") as cache:
            for tr, label, comp in (("bspline", "cold", False), ("bspline", "warm", False),
                                    ("bspline", "cold", True), ("bspline", "warm", True), ("knots", "-", False)):
                with ctx.Pool(1) as pool:
                    r = pool.apply(_one, (case, tr, cache, comp))
                r["cache"] = label
                r["kernels"] = "C" if comp else ("VM" if tr == "bspline" else "-")
                rows.append(r)
    return rows


def report(rows: list[dict]) -> str:
    head = (f"{'case':16s} {'transcription':13s} {'cache':5s} {'kern':4s} {'N':>3s} {'iter':>4s} {'build s':>8s} {'IPOPT s':>8s} "
            f"{'b+s wall':>8s} {'b+s CPU':>8s} {'end att. [deg]':>14s} {'closed chain':>12s} {'cost':>10s} {'cc CPU':>7s}  status")
    lines = [head]
    for r in rows:
        lines.append(f"{r['case']:16s} {r['transcription']:13s} {r['cache']:5s} {r['kernels']:4s} {r['N']:3d} {r['iterations']:4d} "
                     f"{r['build_s']:8.2f} {r['solve_s']:8.2f} {r['build_solve_wall_s']:8.2f} "
                     f"{r['build_solve_cpu_s']:8.2f} {r['end_attitude_error_deg']:14.2e} "
                     f"{r['closed_chain_residual']:12.1e} {r['cost']:10.5f} {r['compiler_cpu_s']:7.1f}  {r['status']}")
    lines.append(f"target: end-constrained restoration build + solve ≤ {TARGET_S} s (warm cache)")
    for case in dict.fromkeys(r["case"] for r in rows):
        by = {(r["transcription"], r["cache"], r["kernels"]): r for r in rows if r["case"] == case}
        old = by.get(("knots", "-", "-"))
        for kern in ("VM", "C"):
            new = by.get(("bspline", "warm", kern))
            if not (new and old):
                continue
            lines.append(f"{case} [{kern} kernels]: knots/bspline build+solve wall {old['build_solve_wall_s'] / new['build_solve_wall_s']:.1f}×, "
                         f"CPU {old['build_solve_cpu_s'] / new['build_solve_cpu_s']:.1f}×; "
                         f"target ≤ {TARGET_S} s: CPU {new['build_solve_cpu_s']:.2f} s "
                         f"({'met' if new['build_solve_cpu_s'] <= TARGET_S else 'NOT met'}), wall {new['build_solve_wall_s']:.2f} s "
                         f"({'met' if new['build_solve_wall_s'] <= TARGET_S else 'NOT met'} at this load); paper: {PAPER[case]}")
    lines.append(f"load average during the runs: {max(r['n_cores_load'] for r in rows):.1f} (2 cores)")
    return "\n".join(lines)


def main(argv=None) -> int:
    import argparse
    import json

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma-separated subset of {','.join(CASES)}")
    ap.add_argument("--json", help="write the rows as JSON")
    args = ap.parse_args(argv)
    rows = run([c.strip() for c in args.cases.split(",") if c.strip()])
    print(report(rows))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=2, default=float)
    return 0 if all(r["success"] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
