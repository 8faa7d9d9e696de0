"""Benchmark of the closed-chain transport NLP (issue 3) at several knot counts.

Each size runs in a fresh process so that the peak resident memory (``ru_maxrss``) is that of one
solve. Prints IPOPT time, setup (NLP build + solver creation) time, iterations, peak memory, and
the verified closed-chain residual and clearance. Target: N = 50 solved in ≤ 2 s with residual
≤ 1e-6 and clearance ≥ 0 (coal).

Run: ``optplan bench transport [--knots 25,50,100]``
"""
from __future__ import annotations

import multiprocessing as mp
import resource


def _one(knots: int, seed: int) -> dict:
    import importlib.util
    from pathlib import Path

    from ..description import repo_root

    spec = importlib.util.spec_from_file_location("cct", Path(repo_root()) / "examples" / "closed_chain_transport.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out, _ = mod.run(knots=knots, seed=seed)
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return out


def run(knots=(25, 50, 100), seed: int = 0) -> list[dict]:
    ctx = mp.get_context("spawn")
    rows = []
    for n in knots:
        with ctx.Pool(1) as pool:
            rows.append(pool.apply(_one, (int(n), seed)))
    return rows


def report(rows: list[dict], knots) -> str:
    lines = [f"{'N':>4s} {'status':>18s} {'iter':>5s} {'ipopt [s]':>10s} {'setup [s]':>10s} {'peak MB':>8s} "
             f"{'cc resid':>9s} {'clear [m]':>9s}"]
    for n, r in zip(knots, rows):
        lines.append(f"{n:4d} {r.get('ipopt_status', '?'):>18s} {r.get('iterations', -1):5d} "
                     f"{r.get('solve_time_s', float('nan')):10.2f} {r.get('setup_time_s', float('nan')):10.2f} "
                     f"{r.get('peak_rss_mb', float('nan')):8.0f} {r.get('max_closed_chain_residual', float('nan')):9.1e} "
                     f"{r.get('min_clearance_m', float('nan')):9.3f}")
    lines.append("target: N=50 in <= 2 s (IPOPT), closed-chain residual <= 1e-6, clearance >= 0 by coal")
    return "\n".join(lines)
