"""The path IK's seed predictors (:mod:`optplan.planners.ik_seed`, TCBiRRT's ``ik_predictor``) paired on
identical extensions, and the share of an extension's C time spent in the IK.

``python -m optplan.bench.ik_predictor --scene suite --n 30 --repeats 3``

Per scene: the extensions of :func:`optplan.bench.tcbirrt_native.ik_costs` (random object targets around the
start and goal object poses of trials 0-2, ``extension="loop"``: path IK with restarts, configuration and edge
checks in one C call, the restarts' stream reseeded before each pass), run with each predictor in alternating
passes; per predictor the CPU µs per extension (best pass), the waypoints' IK calls and their IK iterations
(restarts not counted), the restarts and the checks. Then the C IK's cost per iteration: single solves of
unreachable targets (every solve runs to its cap, both arms iterating) with caps of 1 and 201 iterations:
``b`` = µs per iteration (an upper bound: in the path IK one arm often converges first and costs nothing more),
so ``b`` × the IK iterations per extension / the µs per extension bounds the IK's share of the extension's time.
CPU clock throughout.
"""
from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

__all__ = ["predictor_costs", "main"]

COUNTERS = ("ik_calls", "ik_iterations", "ik_path_iterations", "ik_restarts", "ik_failures", "ik_jumps",
            "collisions", "edge_checks", "edge_collisions")


def predictor_costs(scene_name: str, n: int = 30, repeats: int = 3, seed: int = 0,
                    robot_name: str = "tcbirrt_dual_arm") -> dict[str, Any]:
    """The measurements of the module docstring for one scene (``n`` targets per start/goal configuration)."""
    from ..planners.ik_seed import PREDICTORS
    from .tcbirrt_native import loop_extension_setup, timed_extensions

    setup = loop_extension_setup(scene_name, n, seed, robot_name)
    if setup is None:
        return {"available": False}
    pl, ck, kin, ext, cases = setup
    out: dict[str, Any] = {"available": True, "extensions": len(cases)}
    for rep in range(repeats):
        for k in (PREDICTORS if rep % 2 == 0 else PREDICTORS[::-1]):
            ext._ctx.predictor = PREDICTORS.index(k)
            us, st, checks = timed_extensions(pl, ck, cases, COUNTERS, seed)
            row = out.setdefault(k, {})
            row["extension_us"] = min(row.get("extension_us", np.inf), us)
            row.update({c: st.get(c, 0) for c in COUNTERS}, checks=checks)
    ext._ctx.predictor = PREDICTORS.index(pl.options.ik_predictor)
    out["ik_fit"] = _ik_cost_fit(ext, kin, pl.options, cases)
    return out


def _ik_cost_fit(ext: Any, kin: Any, o: Any, cases: list[Any], reps: int = 3) -> dict[str, float]:
    """µs per iteration of the native IK with both arms iterating: solves toward each case's target moved 10 m
    away (unreachable: every solve runs to its iteration cap) with caps of 1 and 201 iterations, timed over the
    cases; ``b`` = the difference / 200, ``a`` = the 1-iteration solve's µs less ``b`` (the call from Python)."""
    from dataclasses import replace

    nik = ext._ik
    far = [(q0, Rs, ps + 10.0) for q0, _, (Rs, ps) in cases]
    t: dict[int, float] = {}
    for cap in (1, 201, 1, 201)[:2 * reps]:
        s = replace(o.ik, max_iterations=cap)
        c0 = time.process_time()
        for q0, R, p in far:
            nik.solve(q0, R, p, s)
        t[cap] = min(t.get(cap, np.inf), 1e6 * (time.process_time() - c0) / len(far))
    b = (t[201] - t[1]) / 200.0
    return {"a_us": float(t[1] - b), "b_us_per_iteration": float(b), "solves": float(len(far))}


def main(argv: list[str] | None = None) -> int:
    from ..planners.ik_seed import PREDICTORS
    from .tcbirrt import expand_scenes

    ap = argparse.ArgumentParser(prog="python -m optplan.bench.ik_predictor", description=__doc__.split("\n")[0])
    ap.add_argument("--scene", default="suite", help="comma-separated scenes ('suite', 'ssps', names)")
    ap.add_argument("--n", type=int, default=30, help="targets per start/goal configuration of trials 0-2 [count]")
    ap.add_argument("--repeats", type=int, default=3, help="alternating passes per predictor [count]")
    ap.add_argument("--seed", type=int, default=0, help="trial seed and the targets' generator seed")
    a = ap.parse_args(argv)
    tot: dict[str, dict[str, float]] = {k: {} for k in PREDICTORS}
    for sc in expand_scenes(a.scene.split(",")):
        r = predictor_costs(sc, a.n, a.repeats, a.seed)
        if not r["available"]:
            print(f"{sc}: the native loop is not available")
            continue
        fit = r["ik_fit"]
        print(f"{sc}: {r['extensions']} extensions; C IK per iteration {fit['b_us_per_iteration']:.2f} µs "
              f"(+ {fit['a_us']:.1f} µs per call from Python)")
        for k in PREDICTORS:
            x = r[k]
            ik_us = fit["b_us_per_iteration"] * x["ik_iterations"] / r["extensions"]
            print(f"  {k:7s} {x['extension_us']:7.1f} µs/extension; waypoint IK {x['ik_calls']} calls, "
                  f"{x['ik_path_iterations'] / max(x['ik_calls'], 1):.2f} iterations per call; all IK iterations "
                  f"{x['ik_iterations']} (restarts {x['ik_restarts']}); checks {x['checks']}; IK ≈ {ik_us:.1f} µs "
                  f"({100 * ik_us / x['extension_us']:.0f} % of the extension)")
            for c in ("extension_us", "ik_calls", "ik_path_iterations", "ik_iterations", "checks"):
                tot[k][c] = tot[k].get(c, 0.0) + float(x[c])
    if all(tot.values()):
        print("all scenes: " + "; ".join(f"{k} {t['ik_path_iterations'] / t['ik_calls']:.2f} IK iterations per waypoint "
                                          f"call, {t['ik_iterations']:.0f} IK iterations, {t['checks']:.0f} checks"
                                          for k, t in tot.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
