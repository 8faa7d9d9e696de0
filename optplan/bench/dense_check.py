"""``python -m optplan.bench.dense_check``: where the dense check between knots of a free-floating
problem with collision rows spends its time — the modelling benchmark's
``reach_free_time_collision`` solved once, then :func:`~optplan.problem.guarantees.check_between_knots`
and each of its parts timed alone on the same samples (CPU, median over ``--repeat`` calls), with
the samples × pairs it checks and the coal calls it makes (a first check and a re-check that
starts from the first one's bounds). The whole check and the attitudes are timed without the
checks and attitudes kept for an unchanged solution, and the whole check once more with the kept
attitudes and once with the kept check (the same inputs bit for bit).
Prints one JSON object."""
from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["breakdown"]


def _cpu_ms(f: Callable[[], Any], repeat: int) -> float:
    f()
    ts = []
    for _ in range(repeat):
        c = time.process_time()
        f()
        ts.append(time.process_time() - c)
    return round(1e3 * float(np.median(ts)), 3)


def breakdown(repeat: int = 30) -> dict[str, Any]:
    """The dense check's parts [ms CPU] and counts (module docstring)."""
    import pinocchio as pin

    from optplan.bench.modelling import _reach
    from optplan.problem import CollisionAvoidance
    from optplan.problem import guarantees as G
    from optplan.problem.evaluate import sampled_trajectory

    prob, _ = _reach(True, collision=True)
    sol = prob.solve()
    o = G.GuaranteeOptions()
    N = len(sol.t) - 1
    t = np.linspace(0.0, float(sol.t[-1] - sol.t[0]), o.density * N + 1) + sol.t[0]
    com0 = getattr(sol.evaluator, "com0", None)
    out: dict[str, Any] = {"success": bool(sol.success), "iterations": sol.total_iterations}

    def fresh(f: Callable[[], Any], attitudes: bool = False) -> Callable[[], Any]:
        """``f`` without the checks (and unless ``attitudes``, the attitudes) kept from an
        earlier check of the same solution."""
        def g() -> Any:
            G._CHECKS.clear()
            if not attitudes:
                G._ATTITUDES.clear()
            return f()
        return g

    out["whole check [ms]"] = _cpu_ms(fresh(lambda: G.check_between_knots(prob, sol)), repeat)
    out["whole check, attitudes kept from the last check [ms]"] = _cpu_ms(
        fresh(lambda: G.check_between_knots(prob, sol), attitudes=True), repeat)
    out["whole check, the same inputs as the last check (its kept result) [ms]"] = _cpu_ms(
        lambda: G.check_between_knots(prob, sol), repeat)
    out["sampling the joints [ms]"] = _cpu_ms(lambda: sampled_trajectory(prob.robot, sol, t, com0), repeat)
    out["base attitudes [ms]"] = _cpu_ms(fresh(lambda: G._base_attitudes(prob.robot, sol, t, o.density)), repeat)
    traj = sampled_trajectory(prob.robot, sol, t, com0)
    traj.base_quat = G._base_attitudes(prob.robot, sol, t, o.density)
    out["configurations [ms]"] = _cpu_ms(traj.configurations, repeat)
    Q = traj.configurations()
    term = next(h.term for h in sol.evaluator.handles.values() if isinstance(h.term, CollisionAvoidance))
    chk = G._collision_data(term, prob.robot).info["model"].checker
    thr = float(term.margin)
    out["samples x pairs"] = [len(Q), len(chk.pairs)]
    out["distances, first check [ms]"] = _cpu_ms(lambda: chk.distance_bounds_below(Q, thr), repeat)
    prev = chk.distance_bounds_below(Q, thr)[3]
    out["distances, re-check [ms]"] = _cpu_ms(lambda: chk.distance_bounds_below(Q, thr, previous=prev), repeat)
    calls = {"single": 0, "all": 0}
    one, every = pin.computeDistance, pin.computeDistances

    def count_one(*a: Any) -> Any:
        calls["single"] += 1
        return one(*a)

    def count_all(*a: Any) -> Any:
        calls["all"] += 1
        return every(*a)

    pin.computeDistance, pin.computeDistances = count_one, count_all
    try:
        chk.distance_bounds_below(Q, thr)
        out["coal calls, first check (single pair, all pairs)"] = [calls["single"], calls["all"]]
        calls["single"] = calls["all"] = 0
        chk.distance_bounds_below(Q, thr, previous=prev)
        out["coal calls, re-check (single pair, all pairs)"] = [calls["single"], calls["all"]]
    finally:
        pin.computeDistance, pin.computeDistances = one, every
    m, d, gm, gd = chk.model, chk.data, chk._cgm, chk._cgd
    out["every pair at every sample, coal in C++ [ms]"] = _cpu_ms(
        lambda: [pin.computeDistances(m, d, gm, gd, q) for q in Q], repeat)
    out["load"] = float(open("/proc/loadavg").read().split()[0]) if sys.platform.startswith("linux") else None
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.dense_check", description=__doc__)
    ap.add_argument("--repeat", type=int, default=30, help="timed calls per part (the median is printed)")
    args = ap.parse_args(argv)
    if args.repeat < 1:
        ap.error(f"--repeat: expected an integer >= 1, got {args.repeat}")
    print(json.dumps(breakdown(args.repeat)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
