"""Benchmark of the base-attitude restoration NLP (EBA paper's Sections 4.1 / 4.2 on `eba_ffsr`):
the B-spline kernel transcription against the knot transcription, paired on the same scenarios.

Every run is a fresh process (``spawn``). The B-spline NLP runs twice per case: first with an empty
kernel cache (``cold``: the per-robot kernels and their derivatives are built and saved) and then
with the cache that run left on disk (``warm``: a fresh process that loads them). Prints build
(NLP construction + IPOPT instance) and IPOPT wall times, the CPU time of build + solve,
iterations (coarse + fine NLP), the C compiler's CPU time (cold compiled runs), the end
attitude error [deg] and closed-chain residual from the independent
simulator (:func:`optplan.verify`), and the cost. Target: end-constrained restoration
built and solved in ≤ 1 s. The paper's own method (EBA) took ≈ 370 s (free end) and ≈ 270 s
(end constraints) and left 0.01-0.12° of attitude error in its planned trajectories.

Run: ``optplan bench restoration [--cases free_end,end_constrained] [--json out.json]``;
``python -m optplan.bench.restoration --accuracy``: the integrated attitude against an adaptive
integration (the stated RK4 bound).
"""
from __future__ import annotations

import logging
import multiprocessing as mp
import os
import tempfile
from typing import Any, cast

from .._io import write_json

CASES = ("free_end", "end_constrained")
TARGET_S = 1.0
PAPER = {"free_end": "EBA ≈ 370 s, planned end attitude (0, 0, 0)°",
         "end_constrained": "EBA ≈ 270 s, planned end attitude (0.11, 0.01, −0.05)°"}


log = logging.getLogger(__name__)

def _one(case: str, transcription: str, cache: str, compiled=False) -> dict:
    os.environ["OPTPLAN_CACHE"] = cache
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import time

    from ..model.robot import RobotModel
    from ..papers import eba

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


def ivp_attitude(robot, sol):
    """Base attitude quaternions (x, y, z, w) at ``sol.t`` along the solution's joint motion,
    integrated adaptively (scipy RK45, rtol 1e-12) with Pinocchio's centroidal map at the current
    base pose: independent of the NLP's kernels and of its RK4."""
    import numpy as np
    import pinocchio as pin
    from scipy.integrate import solve_ivp

    model, data = robot.model, robot.model.createData()

    def rhs(t, x):
        xi = x / np.linalg.norm(x)
        s = sol.sample(np.array([min(t, sol.t[-1])]))
        q, qd = s["q"][0], s["qd"][0]
        Ag = pin.computeCentroidalMap(model, data, np.r_[np.zeros(3), xi, q])
        w = np.linalg.solve(Ag[:, :6], -Ag[:, 6:] @ qd)[3:]  # base-frame angular velocity
        return 0.5 * (pin.Quaternion(xi[3], *xi[:3]) * pin.Quaternion(0.0, *w)).coeffs()

    out = solve_ivp(rhs, (0.0, float(sol.t[-1])), np.array([0, 0, 0, 1.0]), t_eval=sol.t, rtol=1e-12,
                    atol=1e-14, max_step=float(sol.t[1] - sol.t[0]) / 2)
    return out.y.T


def quat_angle(q1, q2) -> float:
    """Rotation angle [rad] between two quaternions stored (x, y, z, w)."""
    import numpy as np
    import pinocchio as pin

    a = pin.Quaternion(q1[3], *q1[:3]).normalized()
    b = pin.Quaternion(q2[3], *q2[:3]).normalized()
    return float(np.linalg.norm(pin.log3((a.inverse() * b).toRotationMatrix())))


ACCURACY_RUNS = (("free_end", 10, 1), ("free_end", 20, 1), ("free_end", 40, 1), ("free_end", 20, 2),
                 ("end_constrained", 16, 1), ("end_constrained", 48, 1))


def accuracy(runs=ACCURACY_RUNS) -> list[dict]:
    """The B-spline NLP's knot attitudes against :func:`ivp_attitude`, per (case, N, n_sub)."""
    from ..model.robot import RobotModel
    from ..papers import eba

    robot = RobotModel.from_name("eba_ffsr")
    rows = []
    for case, N, n_sub in runs:
        sc = eba.free_end_scenario() if case == "free_end" else eba.end_constrained_scenario(robot)
        o = (eba.NLPOptions.free_end if case == "free_end" else eba.NLPOptions.end_constrained)(
            n_intervals=N, n_sub=n_sub)
        res = eba.run_nlp(robot, sc, o)
        raw = cast(Any, res.raw)  # the NLP's Solution (MethodResult.raw is typed object)
        ref = ivp_attitude(robot, raw)
        rows.append({"case": case, "N": N, "n_sub": n_sub, "success": bool(res.success),
                     "max_knot_attitude_error_rad": max(quat_angle(a, b) for a, b in zip(raw.base_quat, ref)),
                     "end_attitude_independent_rad": quat_angle(ref[-1], [0, 0, 0, 1.0]),
                     "closed_chain_residual": float(res.info["verify_max_closed_chain_residual"])})
        r = rows[-1]
        log.info("%-16s N = %3d n_sub = %d: knot attitude vs solve_ivp %.2e rad, end attitude (independent) %.2e rad, "
                 "closed chain %.1e", case, N, n_sub, r["max_knot_attitude_error_rad"],
                 r["end_attitude_independent_rad"], r["closed_chain_residual"])
    return rows


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma-separated subset of {','.join(CASES)}")
    ap.add_argument("--json", help="write the rows as JSON")
    ap.add_argument("--accuracy", action="store_true",
                    help="instead: the integrated attitude against an adaptive integration, N = 10…48")
    args = ap.parse_args(argv)
    if args.accuracy:
        rows = accuracy()
        for r in rows:
            print(f"{r['case']:16s} N = {r['N']:3d} n_sub = {r['n_sub']}: knot attitude vs solve_ivp "
                  f"{r['max_knot_attitude_error_rad']:.2e} rad, end attitude (independent) "
                  f"{r['end_attitude_independent_rad']:.2e} rad, closed chain {r['closed_chain_residual']:.1e}")
        if args.json:
            write_json(args.json, rows, default=float)
        return 0 if all(r["success"] for r in rows) else 1
    rows = run([c.strip() for c in args.cases.split(",") if c.strip()])
    print(report(rows))
    if args.json:
        write_json(args.json, rows, default=float)
    return 0 if all(r["success"] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
