"""Two versions of the code (two source trees) paired query by query: one worker process per tree, the same
TCBiRRT spec, trial and planner seed sent to both in alternating order (one process plans at a time), so that load
drift hits both alike. Per query: status, CPU seconds of the planner (``cpu_time_s``, CPU clock), iterations, the
benchmark's sweep check of the returned path, and a digest of the path (the same search gives the same path).

``python -m optplan.bench.tcbirrt_versions --tree-a /tmp/base --tree-b . --scenes ssps,hard_flip --trials 20 --out OUT``

Each worker runs the benchmark's planner set-up (:mod:`optplan.bench.tcbirrt`) with ``PYTHONPATH`` set to its tree (and the
kernel cache of ``--cache-a`` / ``--cache-b`` when given). One JSON line per query in ``OUT/versions.jsonl``;
``--summary OUT`` prints success, median CPU and iterations per scene, the per-query CPU ratio a/b (median and
geometric mean over the queries both solve) and how many queries took the same search (same iterations and path).
A trial that cannot be drawn for its seed (no start/goal IK) is a row with status ``no_trial``, left out of the
summary when neither version could draw it.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["summary", "main"]


#: the worker: runs in either tree (the older one has no copy of this module), one JSON query per line on stdin
_WORKER = """
import hashlib, json, sys
import numpy as np
import optplan
from optplan.bench.tcbirrt import _W, _path_checks, _worker_setup
for line in sys.stdin:
    q = json.loads(line)
    _worker_setup("tcbirrt_dual_arm", [q["scene"]], [q["spec"]])
    w = _W[q["scene"]]
    try:
        t = w["gen"].generate(int(q["trial"]), int(q["seed"]))
    except Exception as exc:   # no start/goal IK for this trial: a row, not the end of the run
        print(json.dumps({"status": "no_trial", "error": f"{type(exc).__name__}: {exc}", "cpu_s": float("nan"),
                          "iterations": 0, "path": None, "success": False, "package": optplan.__file__}), flush=True)
        continue
    res = w["planners"][q["spec"]].plan(t.q_start, t.q_goal, time_limit=q["time_limit"], seed=t.seed, clock="cpu")
    checks = _path_checks(w["robot"], w["scene"], w["checker"], res)
    digest = hashlib.sha1(np.asarray(res.path, float).tobytes()).hexdigest()[:16] if res.success else None
    print(json.dumps({"status": res.status.value, "cpu_s": float(res.stats.get("cpu_time_s", float("nan"))),
                      "iterations": int(res.stats.get("iterations") or 0), "path": digest,
                      "swept_invalid_edges": checks.get("swept_invalid_edges"),
                      "success": bool(res.success and checks.get("swept_invalid_edges", 0) == 0),
                      "package": optplan.__file__}), flush=True)
"""


def _spawn(tree: str, cache: str | None) -> subprocess.Popen[str]:
    env = dict(os.environ, PYTHONPATH=str(Path(tree).resolve()))
    if cache:
        env["OPTPLAN_CACHE"] = cache
    return subprocess.Popen([sys.executable, "-c", _WORKER], env=env,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd="/tmp")


def _ask(p: subprocess.Popen[str], q: dict[str, Any]) -> dict[str, Any]:
    assert p.stdin is not None and p.stdout is not None
    p.stdin.write(json.dumps(q) + "\n")
    p.stdin.flush()
    line = p.stdout.readline()
    if not line:
        raise RuntimeError(f"a worker ended without answering {q}")
    return dict(json.loads(line))


def summary(path: Path) -> list[str]:
    """The per-scene lines of a ``versions.jsonl``."""
    rows = [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
    # a trial neither version could draw (no start/goal IK for its seed) is no query
    rows = [r for r in rows if not (r["a"].get("status") == "no_trial" and r["b"].get("status") == "no_trial")]
    out = ["| scene | queries | success a / b | median CPU s a / b | median iterations a / b | CPU a/b per query: "
           "median, geo. mean | same search |", "|---|---|---|---|---|---|---|"]
    for sc in dict.fromkeys(r["scene"] for r in rows):   # scenes in the order of their first row
        R = [r for r in rows if r["scene"] == sc]
        both = [r for r in R if r["a"]["success"] and r["b"]["success"]]
        ratio = np.array([r["a"]["cpu_s"] / r["b"]["cpu_s"] for r in both])
        same = sum(r["a"]["iterations"] == r["b"]["iterations"] and r["a"]["path"] == r["b"]["path"] for r in R)

        def med(k: str, key: str, R: list[dict[str, Any]] = R) -> float:
            return float(np.median([r[k][key] for r in R]))
        out.append(f"| {sc} | {len(R)} | {sum(r['a']['success'] for r in R)} / {sum(r['b']['success'] for r in R)} | "
                   f"{med('a', 'cpu_s'):.4f} / {med('b', 'cpu_s'):.4f} | {med('a', 'iterations'):g} / {med('b', 'iterations'):g} | "
                   f"{np.median(ratio):.3f}, {np.exp(np.mean(np.log(ratio))):.3f} | {same} / {len(R)} |")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree-a", help="source tree of version a (its optplan package is imported)")
    ap.add_argument("--tree-b", help="source tree of version b")
    ap.add_argument("--cache-a", help="OPTPLAN_CACHE of version a's worker (its compiled kernels)")
    ap.add_argument("--cache-b", help="OPTPLAN_CACHE of version b's worker")
    ap.add_argument("--scenes", default="ssps", help="scenes (names, ssps, suite), comma-separated")
    ap.add_argument("--trials", type=int, default=20, help="trials per scene")
    ap.add_argument("--first-trial", type=int, default=0, help="first trial")
    ap.add_argument("--seed", type=int, default=0, help="the trials' base seed")
    ap.add_argument("--spec", default="tcbirrt:variant=improved", help="the planner spec (bench --planners form)")
    ap.add_argument("--time-limit", type=float, default=10.0, help="CPU seconds [s] per query")
    ap.add_argument("--out", help="output directory (versions.jsonl; a run resumes where it ends)")
    ap.add_argument("--summary", metavar="DIR", help="print the paired table of DIR/versions.jsonl")
    a = ap.parse_args(argv)
    if a.summary:
        print("\n".join(summary(Path(a.summary) / "versions.jsonl")))
        return 0
    if not (a.tree_a and a.tree_b and a.out):
        ap.error("--tree-a, --tree-b and --out are required (or --summary DIR)")
    from .tcbirrt import expand_scenes

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "versions.jsonl"
    done = {(r["scene"], r["trial"]) for r in (json.loads(x) for x in log.read_text().splitlines() if x.strip())} \
        if log.exists() else set()
    workers = {"a": _spawn(a.tree_a, a.cache_a), "b": _spawn(a.tree_b, a.cache_b)}
    try:
        k = 0
        for sc in expand_scenes(a.scenes.split(",")):
            for trial in range(a.first_trial, a.first_trial + a.trials):
                if (sc, trial) in done:
                    continue
                q = {"scene": sc, "trial": trial, "seed": a.seed, "spec": a.spec, "time_limit": a.time_limit}
                order = ("a", "b") if k % 2 == 0 else ("b", "a")
                row: dict[str, Any] = {"scene": sc, "trial": trial, "first": order[0]}
                for key in order:
                    row[key] = _ask(workers[key], q)
                k += 1
                with log.open("a") as f:
                    f.write(json.dumps(row) + "\n")
    finally:
        for p in workers.values():
            if p.stdin:
                p.stdin.close()
            p.wait(timeout=60)
    print("\n".join(summary(log)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
