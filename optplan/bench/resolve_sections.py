"""``python -m optplan.bench.resolve_sections``: where a re-solve's overhead besides IPOPT goes —
the modelling benchmark's ``reach_free_time_collision`` (warm cache), ``--rounds`` rounds of
re-solves (from its solution / again / after ``set_value`` to a target never set before, +1 mm
per round), CPU (``time.process_time``) of each section per re-solve, by wrapping the functions
that make it: the dense check and its parts, the solution object and its parts, the set-up before
the IPOPT call, the solver wrapper around it. Prints one JSON object: per kind of re-solve and
section, the median and the max [ms]. Sections nest (``check.*`` is part of ``check``)."""
from __future__ import annotations

import argparse
import functools
import gc
import json
import sys
import time
from collections import defaultdict
from typing import Any

import numpy as np

__all__ = ["sections"]


def sections(rounds: int = 30) -> dict[str, Any]:
    """Per kind (``resolve``, ``again``, ``set_value``), per section: CPU median and max [ms]."""
    from optplan.bench import modelling as bm
    from optplan.collision import checker as ck
    from optplan.model import floating as fl
    from optplan.problem import guarantees as g
    from optplan.problem import nlp, solution, spline_core, spline_solve

    acc: dict[str, float] = defaultdict(float)
    undo: list[tuple[Any, str, Any]] = []

    def wrap(owner: Any, name: str, label: str) -> None:
        f = getattr(owner, name)

        @functools.wraps(f)
        def timed(*a: Any, **k: Any) -> Any:
            c = time.process_time()
            try:
                return f(*a, **k)
            finally:
                acc[label] += time.process_time() - c
        undo.append((owner, name, f))
        setattr(owner, name, timed)

    for owner, name, label in (
            (g, "check_between_knots", "check"), (g, "_base_attitudes", "check.attitudes"),
            (fl, "zero_momentum_rates", "check.attitudes.rates"), (g, "_collision", "check.collision"),
            (ck.CollisionChecker, "distance_bounds_below", "check.collision.bounds_and_coal"),
            (g, "sampled_trajectory", "check.samples"), (g, "_check_inputs", "check.key"),
            (spline_solve.SplineBackend, "_solution", "solution"),
            (spline_solve, "base_placements", "solution.base_placements"),
            (solution.Solution, "__post_init__", "solution.post_init"),
            (spline_solve.SplineBackend, "_solve_once", "solve_once"),
            (spline_core.SplineCore, "structure", "solve_once.structure"),
            (spline_core.SplineCore, "row_bounds", "solve_once.row_bounds"),
            (nlp.NlpSolver, "solve", "nlp_solve"), (nlp.NlpSolver, "_call_buffered", "ipopt_call")):
        wrap(owner, name, label)
    try:
        prob, _ = bm._reach(True, collision=True)
        prob.compile_kernels = True
        prob.solve()                      # the kernels compiled into the cache (not timed)
        bm._forget_memory()
        prob, _ = bm._reach(True, collision=True)
        sol = prob.solve()
        gc.collect()
        target = np.asarray(prob._params[0].value, float).ravel().copy()
        rows: dict[str, list[dict[str, float]]] = defaultdict(list)
        for i in range(max(1, int(rounds))):
            for kind in ("resolve", "again", "set_value"):
                if kind == "set_value":
                    prob.set_value(prob._params[0].sym, target + [0.0, 0.001 * (i + 1), 0.0])
                else:
                    prob.set_initial(solution=sol)
                acc.clear()
                c = time.process_time()
                s = prob.solve()
                total = time.process_time() - c
                d = dict(acc)
                d["overhead"] = total - s.cpu_time
                d["nlp_solve.around_the_call"] = d.get("nlp_solve", 0.0) - d.get("ipopt_call", 0.0)
                d["solve_once.setup"] = d.get("solve_once", 0.0) - d.get("nlp_solve", 0.0) - d.get("solution", 0.0)
                d["iterations"] = 1e-3 * s.iterations   # printed ×1e3 below, as the times
                rows[kind].append(d)
    finally:
        for owner, name, f in reversed(undo):
            setattr(owner, name, f)
    out: dict[str, Any] = {"rounds": int(rounds)}
    for kind, v in rows.items():
        keys = sorted({k for r in v for k in r} - {"ipopt_call", "nlp_solve", "solve_once"})
        out[kind] = {k: {"median_ms": round(1e3 * float(np.median([r.get(k, 0.0) for r in v])), 3),
                         "max_ms": round(1e3 * float(np.max([r.get(k, 0.0) for r in v])), 3)} for k in keys}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.resolve_sections", description=__doc__)
    ap.add_argument("--rounds", type=int, default=30, help="rounds of the three re-solves (default 30)")
    args = ap.parse_args(argv)
    if args.rounds < 1:
        ap.error(f"--rounds: expected an integer ≥ 1, got {args.rounds}")
    print(json.dumps(sections(args.rounds), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
