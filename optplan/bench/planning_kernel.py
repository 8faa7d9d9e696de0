"""The native planning kernel against coal, paired: unit costs of a configuration check (the dual arm
holding the object) and whole TCBiRRT queries on the same trials and seeds with
``validity_kernel="native"`` and ``"coal"`` (alternating, CPU clock).

``python -m optplan.bench.planning_kernel --scene hard_bay,hard_window,ssps_scene1 --trials 0,1,2``
(``--agreement``: only the two backends' verdicts on random configurations, per mode; ``--units-only``:
only the unit costs, with the kernel's broad phase on and off paired; ``--counters``: the kernel's
counters per check — pairs tested, exact tests, box tests — from a profiling build)

Per query: status, CPU seconds, iterations, CPU per iteration; per scene the medians and the paired
ratio coal / native of the CPU per iteration. The two backends give the same verdicts on the shipped
scenes (tests/test_planning_kernel.py), so a paired query normally runs the same search.
"""
from __future__ import annotations

import argparse
import contextlib
import time
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["COUNTERS", "unit_costs", "counters", "paired_queries", "agreement", "main"]


def _unit_configurations(robot: Any, scene: Any, n: int, seed: int) -> np.ndarray:
    """``n`` random configurations around the scene's start and goal (two spreads each, seeded)."""
    from .hardscenes import nominal_configurations

    rng = np.random.default_rng(seed)
    qs, qg = nominal_configurations(robot, scene)
    return np.vstack([np.clip(q0 + rng.normal(0.0, s, (n // 4, qs.size)), robot.lower, robot.upper)
                      for q0 in (qs, qg) for s in (0.05, 0.3)])


def unit_costs(robot: Any, scene: Any, n: int = 4000, seed: int = 0, repeats: int = 3,
               kinds: tuple[str, ...] = ("native", "coal")) -> dict[str, float]:
    """CPU microseconds per check of a held-object configuration, for each backend of ``kinds``:
    batches of the configurations that are valid (every pair is checked: the expensive case) and single
    calls; random configurations around the scene's start and goal (``n`` of them, seeded). With the
    native backend also ``plain_batch_us``: the same batch through the kernel without its broad phase
    (the plain pair loop), alternating with it."""
    from ..planners.kernel import NativeKernel
    from ..planners.validity import ValidityChecker

    Q = _unit_configurations(robot, scene, n, seed)
    out: dict[str, float] = {}
    for kind in kinds:
        ck = ValidityChecker(robot, scene, kernel=kind)
        ok = Q[ck.valid_batch(Q)]
        best_b = best_s = np.inf
        for _ in range(repeats):
            t0 = time.process_time()
            ck.first_invalid(ok, "held")
            best_b = min(best_b, time.process_time() - t0)
            t0 = time.process_time()
            for q in ok[:1000]:
                ck.is_valid(q)
            best_s = min(best_s, time.process_time() - t0)
        out[f"{kind}_batch_us"] = 1e6 * best_b / max(len(ok), 1)
        out[f"{kind}_single_us"] = 1e6 * best_s / max(min(len(ok), 1000), 1)
        out["valid_configurations"] = float(len(ok))
        if kind == "native" and ck.kernel == "native":
            pairs = [(cp.first, cp.second) for cp in ck.gmodel.collisionPairs]
            fast = NativeKernel(robot.model, ck.gmodel, pairs, margin=ck.margin)
            plain = NativeKernel(robot.model, ck.gmodel, pairs, margin=ck.margin, broad_phase=False)
            act = np.array([bool(x) for x in ck._gd["held"].activeCollisionPairs], np.uint8)
            best = {"fast": np.inf, "plain": np.inf}
            for _ in range(repeats):
                for name, k in (("fast", fast), ("plain", plain)):
                    t0 = time.process_time()
                    k.first_invalid(ok, act)
                    best[name] = min(best[name], time.process_time() - t0)
            out["broad_batch_us"] = 1e6 * best["fast"] / max(len(ok), 1)
            out["plain_batch_us"] = 1e6 * best["plain"] / max(len(ok), 1)
    return out


#: the kernel's profiling counters (a build with ``KCOUNT`` defined), in the order of ``kcount``
COUNTERS = ("checks", "pairs tested", "exact tests", "chain-obstacle box tests", "link-obstacle box tests",
            "bucket tests", "link-link box tests")


def counters(robot: Any, scene: Any, n: int = 4000, seed: int = 0) -> dict[str, dict[str, float]]:
    """Per check, on the valid configurations of :func:`unit_costs` and on all of them (held object):
    the counts of :data:`COUNTERS` with and without the broad phase, from a profiling build of the
    kernel (compiled into a temporary folder, not the cache)."""
    import ctypes
    import tempfile
    from pathlib import Path

    from ..codegen import build_library
    from ..planners.kernel import NativeKernel
    from ..planners.kernel.csource import C_SOURCE
    from ..planners.validity import ValidityChecker

    Q = _unit_configurations(robot, scene, n, seed)
    ck = ValidityChecker(robot, scene, kernel="native")
    ok = np.ascontiguousarray(Q[ck.valid_batch(Q)])
    pairs = [(cp.first, cp.second) for cp in ck.gmodel.collisionPairs]
    act = np.array([bool(x) for x in ck._gd["held"].activeCollisionPairs], np.uint8)
    out: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        c_file, lib_file = Path(tmp, "kcount.c"), Path(tmp, "kcount.so")
        c_file.write_text("#define KCOUNT 1\n" + C_SOURCE)
        err = build_library(c_file, lib_file, "-O3")
        if err is not None:
            raise RuntimeError(f"the profiling build failed: {err}")
        lib = ctypes.CDLL(str(lib_file))
        lib.kernel_first_invalid.restype = ctypes.c_longlong
        cnt = (ctypes.c_longlong * 8).in_dll(lib, "kcount")
        for broad in (True, False):
            k = NativeKernel(robot.model, ck.gmodel, pairs, margin=ck.margin, broad_phase=broad)
            for name, X in (("valid", ok), ("all", np.ascontiguousarray(Q))):
                for i in range(8):
                    cnt[i] = 0
                res = np.empty(len(X), np.uint8)
                lib.kernel_first_invalid(ctypes.c_void_p(k._km_p), ctypes.c_void_p(act.ctypes.data), None, -1,
                                         ctypes.c_longlong(len(X)), ctypes.c_void_p(X.ctypes.data),
                                         ctypes.c_void_p(res.ctypes.data))
                c = max(cnt[0], 1)
                row = {"configurations": float(len(X)), "free": float(res.sum())}
                row.update({label: cnt[i] / c for i, label in enumerate(COUNTERS) if i})
                out[f"{'broad' if broad else 'plain'} {name}"] = row
    return out


def agreement(robot: Any, scene: Any, n: int = 4000, seed: int = 1) -> list[tuple[str, int, int, int, int]]:
    """Verdicts of the two backends on ``n`` random configurations (three quarters around the start and
    goal at three spreads, a quarter uniform in the joint limits), per mode: (mode, configurations, colliding
    by coal, false "free" by the kernel, false "colliding" by the kernel)."""
    from ..constraints.closed_chain import ClosedChainKinematics
    from ..planners.validity import ValidityChecker
    from .hardscenes import nominal_configurations

    rng = np.random.default_rng(seed)
    qs, qg = nominal_configurations(robot, scene)
    m = n // 8
    Q = np.vstack([np.clip(q0 + rng.normal(0.0, s, (m, qs.size)), robot.lower, robot.upper)
                   for q0 in (qs, qg) for s in (0.05, 0.2, 0.5)] + [np.array([robot.random_configuration(rng) for _ in range(n - 6 * m)])])
    ref, nat = ValidityChecker(robot, scene, kernel="coal"), ValidityChecker(robot, scene, kernel="native")
    pose = ClosedChainKinematics(robot, scene.object.grasps).object_pose(qs)
    out = []
    for mode, M in (("held", None), ("free", None), ("fixed", pose)):
        want = np.array([ref.first_invalid(q[None], mode, M) < 0 for q in Q])
        got = nat.valid_batch(Q, mode, M)
        out.append((mode, len(Q), int((~want).sum()), int(np.sum(got & ~want)), int(np.sum(~got & want))))
    return out


def paired_rows(scenes: list[str], trials: list[int], specs: dict[str, str], *, key: str, seed: int = 0,
                time_limit: float = 10.0, robot_name: str = "tcbirrt_dual_arm",
                context: Callable[[str], Any] | None = None) -> list[dict[str, Any]]:
    """Each trial of each scene planned with every planner spec of ``specs`` (``{kind: spec}``; the
    first kind first on even trials, the order reversed on odd ones), same trial seed, CPU clock
    [s]. ``context(kind)`` (optional) is entered around each query. One row per query, the kind
    under ``key``."""
    from .tcbirrt import _W, _worker_setup, expand_scenes

    kinds = list(specs)
    scenes = expand_scenes(scenes)
    _worker_setup(robot_name, scenes, list(specs.values()))
    rows = []
    for sc in scenes:
        w = _W[sc]
        for i in trials:
            t = w["gen"].generate(int(i), seed)
            for kind in (kinds if i % 2 == 0 else kinds[::-1]):
                pl = w["planners"][specs[kind]]
                with context(kind) if context is not None else contextlib.nullcontext():
                    c0 = time.process_time()
                    res = pl.plan(t.q_start, t.q_goal, time_limit=time_limit, seed=t.seed, clock="cpu")
                    cpu = time.process_time() - c0
                it = int(res.stats.get("iterations") or 0)
                rows.append({"scene": sc, "trial": int(i), key: kind, "status": res.status.value, "cpu_s": cpu,
                             "iterations": it, "cpu_per_iteration_ms": 1e3 * cpu / max(it, 1),
                             "collision_checks": res.stats.get("collision_checks"), "nodes": res.stats.get("nodes"),
                             "native": getattr(pl, "_ext", None) is not None})
    return rows


def paired_summary(rows: list[dict[str, Any]], key: str, fast: str, slow: str,
                   same_fields: tuple[str, ...] = ("iterations",)) -> str:
    """Per scene: success, median CPU [s] and CPU per iteration [ms] of each kind, the paired
    ``slow``/``fast`` ratio per iteration, and how many pairs agree on ``same_fields``."""
    lines = [f"{'scene':22s} {key:7s} {'success':>8s} {'median CPU s':>13s} {'median ms/iter':>15s}"]
    for sc in dict.fromkeys(r["scene"] for r in rows):
        per = {}
        for kind in (fast, slow):
            rr = [r for r in rows if r["scene"] == sc and r[key] == kind]
            per[kind] = rr
            succ = np.mean([r["status"] == "exact" for r in rr])
            lines.append(f"{sc:22s} {kind:7s} {succ:8.2f} {np.median([r['cpu_s'] for r in rr]):13.3f} "
                         f"{np.median([r['cpu_per_iteration_ms'] for r in rr]):15.3f}")
        pairs = list(zip(per[fast], per[slow]))
        ratio = [b["cpu_per_iteration_ms"] / a["cpu_per_iteration_ms"] for a, b in pairs]
        same = sum(all(a[f] == b[f] for f in same_fields) for a, b in pairs)
        lines.append(f"{sc:22s} paired {slow}/{fast} CPU per iteration: median {np.median(ratio):.2f}x "
                     f"(min {min(ratio):.2f}, max {max(ratio):.2f}); same {'/'.join(same_fields)} in {same}/{len(ratio)}")
    return "\n".join(lines)


def paired_queries(scenes: list[str], trials: list[int], planner: str = "tcbirrt:variant=improved", *,
                   seed: int = 0, time_limit: float = 10.0, robot_name: str = "tcbirrt_dual_arm") -> list[dict[str, Any]]:
    """Each trial of each scene planned with both backends (native first on even trials, coal first on
    odd ones), same trial seed. One row per query."""
    specs = {k: f"{planner}:validity_kernel={k}" for k in ("native", "coal")}
    return paired_rows(scenes, trials, specs, key="kernel", seed=seed, time_limit=time_limit, robot_name=robot_name)


def _summary(rows: list[dict[str, Any]]) -> str:
    return paired_summary(rows, "kernel", "native", "coal")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.planning_kernel",
                                 description="native planning kernel vs coal: unit costs and paired TCBiRRT queries")
    ap.add_argument("--scene", default="hard_bay,hard_window,ssps_scene1", help="comma-separated scenes")
    ap.add_argument("--trials", default="0,1,2", help="comma-separated trial indices [index]")
    ap.add_argument("--planners", default="tcbirrt:variant=improved", help="one planner spec")
    ap.add_argument("--seed", type=int, default=0, help="trial seed")
    ap.add_argument("--time-limit", type=float, default=10.0, help="CPU seconds per query [s]")
    ap.add_argument("--no-units", action="store_true", help="skip the unit costs")
    ap.add_argument("--units-only", action="store_true",
                    help="only the unit costs (with the broad phase on and off), no queries")
    ap.add_argument("--native-only", action="store_true", help="unit costs of the native kernel only (not coal)")
    ap.add_argument("--counters", action="store_true",
                    help="only the kernel's counters per check (pairs tested, exact tests, box tests)")
    ap.add_argument("--agreement", action="store_true",
                    help="only compare the two backends' verdicts on random configurations of each scene")
    a = ap.parse_args(argv)
    from ..model.robot import RobotModel
    from ..scene import Scene
    from .tcbirrt import expand_scenes

    scenes = expand_scenes(a.scene.split(","))
    if a.agreement:
        robot = RobotModel.from_name("tcbirrt_dual_arm")
        for sc in scenes:
            for mode, n, coll, ff, fc in agreement(robot, Scene.load(sc)):
                print(f"{sc} {mode:5s}: {n} configurations, {coll} colliding (coal); kernel: {ff} false free, "
                      f"{fc} false colliding")
        return 0
    if a.counters:
        robot = RobotModel.from_name("tcbirrt_dual_arm")
        for sc in scenes:
            for name, row in counters(robot, Scene.load(sc)).items():
                print(f"{sc} {name}: {int(row['configurations'])} configurations ({int(row['free'])} free); per check "
                      + ", ".join(f"{label} {row[label]:.1f}" for label in COUNTERS[1:]))
        return 0
    if not a.no_units:
        robot = RobotModel.from_name("tcbirrt_dual_arm")
        kinds = ("native",) if a.native_only else ("native", "coal")
        for sc in scenes:
            u = unit_costs(robot, Scene.load(sc), kinds=kinds)
            line = (f"{sc}: held-object check, CPU µs per valid configuration: native {u['native_batch_us']:.2f} batched / "
                    f"{u['native_single_us']:.2f} single")
            if "coal_batch_us" in u:
                line += f", coal {u['coal_batch_us']:.2f} batched / {u['coal_single_us']:.2f} single"
            if "plain_batch_us" in u:
                line += (f"; paired, broad phase {u['broad_batch_us']:.2f} / plain pair loop {u['plain_batch_us']:.2f} "
                         f"({u['plain_batch_us'] / u['broad_batch_us']:.2f}x)")
            print(line + f" ({int(u['valid_configurations'])} configurations)", flush=True)
        if a.units_only:
            return 0
    rows = paired_queries(scenes, [int(x) for x in a.trials.split(",") if x.strip()], a.planners, seed=a.seed,
                          time_limit=a.time_limit)
    for r in rows:
        print(f"{r['scene']} trial {r['trial']} {r['kernel']:6s}: {r['status']}, {r['cpu_s']:.3f} s CPU, "
              f"{r['iterations']} iterations, {r['cpu_per_iteration_ms']:.3f} ms/iteration, {r['collision_checks']} checks")
    print(_summary(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
