"""Two TCBiRRT configurations paired on the same queries: freshly generated, certified scenes drawn and run one
at a time, or the fixed scenes; success, CPU seconds and path lengths (joint space and task space) per query.

``python -m optplan.bench.tcbirrt_paired --base-seed 8802 --n 216 --time-limit 5 --out OUT``

Generated scenes: index ``i`` draws family ``FAMILIES[i % 6]`` from ``generate_scenes(..., seed=base_seed * 1000 + i,
trial_seed=base_seed)`` (:mod:`optplan.bench.scenegen`: a scene is kept only with a certified witness path,
``--witness-time`` CPU seconds [s] per search, at most ``--max-draws`` draws; an index whose every draw fails is
recorded as skipped; ``--families bay,wall`` keeps only the indices of those families), writes it to ``OUT/scenes`` and runs both planners on trial 0 of ``base_seed`` (the query the
witness certified), in alternating order (alternating within each family), with the same planner seed. Fixed scenes (``--scenes suite,ssps
--trials N``): each trial of each scene the same way. One JSON line per query in ``OUT/paired.jsonl``; a run
resumes where the file ends. A path counts only when it passes the benchmark's 1 cm sweep check
(:func:`optplan.bench.tcbirrt._path_checks`). Lengths are of the path the planner returns (its regrasp motions
shortcut by the regrasp RRT-Connect; the held path is not shortcut): joint space [rad], and the held object's
translation [m] and rotation angle [rad] summed over consecutive held poses. Each row also carries the search's
trap-graft attempts and grafts made (``trap_attempts``, ``trap_grafts``; 0 with trap grafts off).

``python -m optplan.bench.tcbirrt_paired --summary OUT --time-limit 5`` prints the paired statistics
(:func:`paired_summary`).

Drawing and certifying scenes does not depend on the two planners: ``--generate-only`` draws and writes the
certified scenes (one JSON line per index in ``OUT/scenes.jsonl``) without planning, and ``--from DIR`` later pairs
two planners on the scenes written there (each grouped by its family), so that scenes certified by one version of
the code can be paired by another. ``--planner-seeds K`` plans each of those queries with K planner seeds (a query's
success over seeds: a search's tail against a scene's difficulty).
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

__all__ = ["SPECS", "task_length", "run_query", "paired_summary", "main"]

#: the two configurations compared by default: the improved variant with ``branch_roots`` off and on
SPECS = ("tcbirrt:variant=improved:branch_roots=false", "tcbirrt:variant=improved:branch_roots=true")
KEYS = ("a", "b")


def task_length(object_poses: list[Any]) -> tuple[float, float]:
    """The held object's path length: translation [m] and rotation angle [rad] summed over consecutive
    poses (None entries, configurations without the object held, are skipped)."""
    tr = rot = 0.0
    prev = None
    for M in object_poses:
        if M is None:
            continue
        if prev is not None:
            tr += float(np.linalg.norm(M.translation - prev.translation))
            rot += float(np.linalg.norm(pin.log3(prev.rotation.T @ M.rotation)))
        prev = M
    return tr, rot


def _order(index: int) -> tuple[str, str]:
    """The run order of a generated index: it alternates between consecutive indices of one family (index ``i`` draws
    family ``i % 6``), so that no family always runs the same planner first — the first planner on a fresh scene pays
    its warm-up (~10 % of a 10 ms query), which an order tied to the family would book to one side."""
    from .scenegen import FAMILIES

    return KEYS if (index // len(FAMILIES)) % 2 == 0 else KEYS[::-1]


#: the planner seed of a query's k-th planner seed is the trial's seed + k * SEED_STRIDE (``--planner-seeds``)
SEED_STRIDE = 7919


def run_query(scene: str, trial: int, seed: int, time_limit: float, specs: tuple[str, str] = SPECS,
              order: tuple[str, str] = KEYS, seed_offset: int = 0) -> dict[str, Any]:
    """Both planners on trial ``trial`` of base seed ``seed`` of ``scene`` (``time_limit`` CPU seconds [s] each),
    in ``order``, with the planner seed the trial's seed + ``seed_offset``; ``{"a": row, "b": row}`` or
    ``{"no_trial": why}``."""
    from ..errors import UnreachableError
    from .tcbirrt import _W, _path_checks, _worker_setup

    _worker_setup("tcbirrt_dual_arm", [scene], list(specs))
    w = _W[scene]
    try:
        t = w["gen"].generate(int(trial), int(seed))
    except (UnreachableError, RuntimeError) as exc:
        return {"no_trial": str(exc)}
    out: dict[str, Any] = {}
    for key in order:
        res = w["planners"][specs[KEYS.index(key)]].plan(t.q_start, t.q_goal, time_limit=time_limit,
                                                         seed=t.seed + int(seed_offset), clock="cpu")
        checks = _path_checks(w["robot"], w["scene"], w["checker"], res)
        tl, rl = task_length(res.object_poses) if res.success else (None, None)
        out[key] = {"success": bool(res.success and checks.get("swept_invalid_edges", 0) == 0),
                    "status": res.status.value, "cpu_s": float(res.stats.get("cpu_time_s", float("nan"))),
                    "iterations": int(res.stats.get("iterations") or 0), "joint_len": checks.get("joint_path_length_rad"),
                    "task_len_m": tl, "task_rot_rad": rl, "n_regrasp": res.n_regrasp, "n_conf": len(res.path),
                    **{k: int(res.stats.get(k) or 0) for k in ("ik_calls", "ik_path_iterations", "ik_iterations",
                                                               "trap_attempts", "trap_grafts")}}
    return out


def _pair_lines(rows: list[dict[str, Any]], limit: float, label: str) -> list[str]:
    from scipy.stats import binomtest, wilcoxon

    q = [r for r in rows if "a" in r and "b" in r]
    if not q:
        return [f"{label}: no query"]
    n = len(q)
    sa, sb = (sum(r[k]["success"] for r in q) for k in KEYS)
    won = sum(not r["a"]["success"] and r["b"]["success"] for r in q)
    lost = sum(r["a"]["success"] and not r["b"]["success"] for r in q)
    p_sign = binomtest(won, won + lost).pvalue if won + lost else 1.0
    ca, cb = (np.array([r[k]["cpu_s"] if r[k]["success"] else limit for r in q]) for k in KEYS)
    ratio = cb / ca
    pw = wilcoxon(np.log(cb), np.log(ca)).pvalue if n > 5 and np.any(cb != ca) else float("nan")
    out = [f"{label}: {n} queries; success a {sa}/{n}, b {sb}/{n} (b wins {won}, loses {lost}; sign test p = {p_sign:.3g}); "
           f"median CPU s (a failure at the limit) a {np.median(ca):.3f}, b {np.median(cb):.3f}; CPU b/a geometric mean "
           f"{np.exp(np.mean(np.log(ratio))):.2f} (b faster in {int(np.sum(ratio < 1))}, Wilcoxon p = {pw:.3g})"]
    both = [r for r in q if r["a"]["success"] and r["b"]["success"]]
    if len(both) < 2:
        return out
    out.append(f"  both solved: {len(both)}; regrasp segments per path (mean) a "
               f"{np.mean([r['a']['n_regrasp'] for r in both]):.2f}, b {np.mean([r['b']['n_regrasp'] for r in both]):.2f}")
    for field, name in (("joint_len", "joint length [rad]"), ("task_len_m", "object translation [m]"),
                        ("task_rot_rad", "object rotation [rad]")):
        x = np.array([[r[k][field] for k in KEYS] for r in both], float)
        d = x[:, 1] - x[:, 0]
        ok = (x[:, 0] > 0) & (x[:, 1] > 0)
        rr = x[ok, 1] / x[ok, 0]
        p = wilcoxon(x[:, 1], x[:, 0]).pvalue if len(x) > 5 and np.any(d != 0) else float("nan")
        out.append(f"  {name}: median a {np.median(x[:, 0]):.2f}, b {np.median(x[:, 1]):.2f}; b/a geometric mean "
                   f"{np.exp(np.mean(np.log(rr))) if rr.size else float('nan'):.3f}, median {np.median(rr) if rr.size else float('nan'):.3f}; "
                   f"b longer in {int(np.sum(d > 1e-9))}, shorter in {int(np.sum(d < -1e-9))}; Wilcoxon p = {p:.3g}")
    return out


def paired_summary(rows: list[dict[str, Any]], time_limit: float,
                   grid: tuple[float, ...] = (0.1, 0.25, 0.5, 1.0, 2.0, 5.0, 10.0)) -> str:
    """The paired statistics of ``rows`` (lines of ``paired.jsonl``): all queries, then per family (generated
    scenes) or per scene; p(t) (success within t CPU seconds [s]) for each planner on ``grid`` up to ``time_limit``."""
    lines = [f"{len(rows)} lines; indices without a certified draw {sum(bool(r.get('skipped')) for r in rows)}; "
             f"queries without a trial {sum('no_trial' in r for r in rows)}"]
    lines += _pair_lines(rows, time_limit, "all")
    q = [r for r in rows if "a" in r and "b" in r]
    for k in KEYS:
        lines.append(f"  p(t) {k}: " + " ".join(f"{t:g} s {np.mean([r[k]['success'] and r[k]['cpu_s'] <= t for r in q]):.3f}"
                                                for t in grid if t <= time_limit))
    groups = dict.fromkeys(r.get("group", "") for r in rows)
    for g in groups:
        sub = [r for r in rows if r.get("group", "") == g]
        lines += _pair_lines(sub, time_limit, g)
        fails: dict[str, int] = {}
        for r in sub:
            for k in KEYS:
                if k in r and not r[k]["success"]:
                    fails[f"{k} {r[k]['status']}"] = fails.get(f"{k} {r[k]['status']}", 0) + 1
        if fails or any(r.get("skipped") for r in sub):
            lines.append(f"  failures: {fails or 'none'}; skipped indices {sum(bool(r.get('skipped')) for r in sub)}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    import logging

    ap = argparse.ArgumentParser(prog="python -m optplan.bench.tcbirrt_paired", description=__doc__.split("\n")[0])
    ap.add_argument("--base-seed", type=int, default=0, help="generated scenes' base seed (and the trials' seed)")
    ap.add_argument("--first", type=int, default=0, help="first generated index")
    ap.add_argument("--n", type=int, default=0, help="generated indices to draw")
    ap.add_argument("--time-limit", type=float, default=10.0, help="CPU seconds [s] per query")
    ap.add_argument("--witness-time", type=float, default=10.0, help="CPU seconds [s] per witness search")
    ap.add_argument("--max-draws", type=int, default=4, help="draws per generated index")
    ap.add_argument("--families", default="",
                    help="only the generated indices of these families, drawn or (with --from) paired (comma-separated; default all)")
    ap.add_argument("--planners", default=",".join(SPECS), help="the two planner specs a,b")
    ap.add_argument("--scenes", default="", help="instead of generated scenes: fixed scenes (suite, ssps, names)")
    ap.add_argument("--trials", type=int, default=0, help="trials per fixed scene")
    ap.add_argument("--first-trial", type=int, default=0, help="first trial of the fixed scenes")
    ap.add_argument("--out", help="output directory (paired.jsonl, scenes/)")
    ap.add_argument("--summary", nargs="+", metavar="DIR", help="print the paired statistics of these outputs")
    ap.add_argument("--generate-only", action="store_true",
                    help="draw and certify the generated scenes only (OUT/scenes.jsonl, OUT/scenes/), no planning")
    ap.add_argument("--planner-seeds", type=int, default=1,
                    help="with --from: plan each certified query with this many planner seeds (the trial's seed + k * "
                         f"{SEED_STRIDE}, k = 0, 1, ...; key suffix ~k for k > 0), the order alternating with k too")
    ap.add_argument("--from", dest="from_dir", metavar="DIR",
                    help="pair on the scenes a --generate-only run wrote to DIR (in its index order)")
    a = ap.parse_args(argv)
    if a.summary:
        rows = [json.loads(x) for d in a.summary for x in (Path(d) / "paired.jsonl").read_text().splitlines() if x.strip()]
        rows = list({r["key"]: r for r in rows[::-1]}.values())[::-1]   # a key written twice counts once (its first line)
        print(paired_summary(rows, a.time_limit))
        return 0
    specs = tuple(s.strip() for s in a.planners.split(","))
    if (len(specs) != 2 and not a.generate_only) or not a.out:
        ap.error("--planners: expected two comma-separated specs, and --out")
    if a.planner_seeds < 1:
        ap.error(f"--planner-seeds: expected a positive count, got {a.planner_seeds}")
    logging.getLogger("optplan").setLevel(logging.ERROR)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / ("scenes.jsonl" if a.generate_only else "paired.jsonl")
    done = {json.loads(x)["key"] for x in path.read_text().splitlines() if x.strip()} if path.exists() else set()
    with path.open("a") as f:
        def emit(rec: dict[str, Any]) -> None:
            f.write(json.dumps({**rec, "specs": specs, "time_limit_s": a.time_limit}) + "\n")
            f.flush()

        if a.from_dir:
            only = {x.strip() for x in a.families.split(",") if x.strip()}
            for line in (Path(a.from_dir) / "scenes.jsonl").read_text().splitlines():
                drawn_rec: dict[str, Any] = json.loads(line) if line.strip() else {}
                if not drawn_rec or (only and drawn_rec.get("group") not in only):
                    continue
                if drawn_rec.get("skipped"):
                    if drawn_rec.get("key") not in done:
                        emit(drawn_rec)
                    continue
                for k in range(a.planner_seeds):
                    key = drawn_rec["key"] if k == 0 else f"{drawn_rec['key']}~{k}"
                    if key in done:
                        continue
                    order = _order(drawn_rec["index"])
                    order = order if k % 2 == 0 else order[::-1]
                    emit({**drawn_rec, "key": key, "order": order, "planner_seed_offset": SEED_STRIDE * k,
                          **run_query(drawn_rec["scene"], 0, a.base_seed, a.time_limit, specs, order, SEED_STRIDE * k)})
            return 0
        if a.scenes:
            from .tcbirrt import expand_scenes

            for k, (sc, t) in enumerate((sc, t) for sc in expand_scenes(a.scenes.split(","))
                                        for t in range(a.first_trial, a.first_trial + a.trials)):
                if f"{sc}#{t}" not in done:
                    order = KEYS if k % 2 == 0 else KEYS[::-1]
                    emit({"key": f"{sc}#{t}", "group": Path(sc).stem, "scene": sc, "trial": t, "order": order,
                          **run_query(sc, t, a.base_seed, a.time_limit, specs, order)})
            return 0
        from ..model.robot import RobotModel
        from .scenegen import FAMILIES, generate_scenes, write_scenes

        robot = RobotModel.from_name("tcbirrt_dual_arm")
        wanted = tuple(x.strip() for x in a.families.split(",") if x.strip()) or FAMILIES
        bad = [x for x in wanted if x not in FAMILIES]
        if bad:
            ap.error(f"--families: unknown {bad}; expected some of {FAMILIES}")
        rej: list[Any]
        for i in range(a.first, a.first + a.n):
            fam, key = FAMILIES[i % len(FAMILIES)], f"{a.base_seed}_{i}"
            if key in done or fam not in wanted:
                continue
            c0, rej = time.process_time(), []
            drawn = generate_scenes(robot, 1, seed=a.base_seed * 1000 + i, families=(fam,), trial_seed=a.base_seed,
                                    witness_time=a.witness_time, max_draws=a.max_draws, rejections=rej)
            rec: dict[str, Any] = {"key": key, "index": i, "group": fam, "gen_cpu_s": time.process_time() - c0,
                                   "rejections": [r.reason for r in rej]}
            if not drawn:
                emit({**rec, "skipped": True})
                continue
            g = drawn[0]
            g = replace(g, scene=replace(g.scene, name=f"gen_{a.base_seed}_{i:03d}_{fam}"))
            sc = write_scenes([g], out / "scenes")[0]
            if a.generate_only:
                emit({**rec, "scene": str(Path(sc).resolve()), "witness_cpu_s": g.witness.cpu_time_s if g.witness else None})
                continue
            order = _order(i)
            emit({**rec, "scene": sc, "witness_cpu_s": g.witness.cpu_time_s if g.witness else None, "order": order,
                  **run_query(sc, 0, a.base_seed, a.time_limit, specs, order)})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
