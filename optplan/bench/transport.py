"""Benchmark of the closed-chain transport NLP at several knot counts, both transcriptions paired.

Each (size, transcription) runs in a fresh process so that the peak resident memory
(``ru_maxrss``) is that of one solve. Prints IPOPT time, setup (NLP build + solver creation) time,
build + solve CPU time, iterations, peak memory, the verified closed-chain residual and clearance,
and the knots/B-spline CPU ratio. Target: N = 50 built and solved in ≤ 0.3 s, residual ≤ 1e-6 and
clearance ≥ 0 (coal).

Run: ``optplan bench transport [--knots 25,50,100]``
"""
from __future__ import annotations

import multiprocessing as mp
import resource

TRANSCRIPTIONS = ("bspline", "knots")


def _one(knots: int, seed: int, transcription: str = "bspline") -> dict:
    import importlib.util
    from pathlib import Path

    from ..model.description import repo_root

    path = Path(repo_root()) / "examples" / "closed_chain_transport.py"
    spec = importlib.util.spec_from_file_location("cct", path)
    if spec is None or spec.loader is None:
        raise FileNotFoundError(f"transport benchmark: cannot load the example {path}")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out, _ = mod.run(knots=knots, seed=seed, transcription=transcription)
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return out


def run(knots=(25, 50, 100), seed: int = 0, transcriptions=TRANSCRIPTIONS) -> list[dict]:
    """One row per (N, transcription), in that order."""
    ctx = mp.get_context("spawn")
    rows = []
    for n in knots:
        for tr in transcriptions:
            with ctx.Pool(1) as pool:
                rows.append({"N": int(n), **pool.apply(_one, (int(n), seed, tr))})
    return rows


def report(rows: list[dict], knots=None) -> str:
    nan = float("nan")
    lines = [f"{'N':>4s} {'NLP':>8s} {'status':>26s} {'iter':>5s} {'ipopt [s]':>10s} {'setup [s]':>10s} "
             f"{'CPU [s]':>8s} {'peak MB':>8s} {'cc resid':>9s} {'clear [m]':>9s} {'jerk':>9s}"]
    by_n: dict = {}
    for r in rows:
        by_n.setdefault(r["N"], {})[r.get("transcription", "knots")] = r
        lines.append(f"{r['N']:4d} {r.get('transcription', '?'):>8s} {r.get('ipopt_status', '?'):>26s} "
                     f"{r.get('iterations', -1):5d} {r.get('solve_time_s', nan):10.2f} {r.get('setup_time_s', nan):10.2f} "
                     f"{r.get('build_and_solve_cpu_s', nan):8.2f} {r.get('peak_rss_mb', nan):8.0f} "
                     f"{r.get('max_closed_chain_residual', nan):9.1e} {r.get('min_clearance_m', nan):9.3f} "
                     f"{r.get('cost', nan):9.2e}")
    for n, d in by_n.items():
        if "bspline" in d and "knots" in d:
            b, k = d["bspline"].get("build_and_solve_cpu_s"), d["knots"].get("build_and_solve_cpu_s")
            if b and k:
                lines.append(f"N={n}: knots / B-spline build + solve CPU = {k / b:.1f}x")
    lines.append("target: N=50 built and solved in <= 0.3 s, closed-chain residual <= 1e-6, clearance >= 0 by coal "
                 "(the knot transcription uses free plane normals, the B-spline one fixed normals)")
    return "\n".join(lines)
