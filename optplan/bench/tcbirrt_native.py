"""TCBiRRT's extension step and nearest neighbour in native code against the Python ones, paired: whole
queries on the same trials and seeds with ``extension="native"`` (and the trees' native nearest-neighbour
scan) and ``extension="python"`` (and numpy's), alternating which runs first, CPU clock. Both use the
native collision kernel (``validity_kernel="native"``), today's default.

``python -m optplan.bench.tcbirrt_native --scene hard_bay,hard_window,ssps_scene1 --trials 0,1,2``
(``--units``: only the CPU per extension of the two, on the same random extensions)

Per query: status, CPU seconds, iterations, CPU per iteration; per scene the medians, the paired ratio
python / native of the CPU per iteration, and in how many pairs the two ran the same search (same
iteration and node counts: they should, up to rounding in the last bits of the pose interpolation).
"""
from __future__ import annotations

import argparse
import contextlib
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

__all__ = ["extension_costs", "ik_costs", "lead_path_costs", "loop_costs", "regrasp_search_costs", "paired_queries", "python_nearest", "main"]

KINDS = ("native", "python")


@contextlib.contextmanager
def python_nearest() -> Iterator[None]:
    """Inside: :meth:`optplan.planners.tree.Tree.nearest` uses numpy's search (the native scan off)."""
    from ..planners import tree

    tree._native_nearest()
    saved = list(tree._NATIVE_NN)
    tree._NATIVE_NN[:] = [None]
    try:
        yield
    finally:
        tree._NATIVE_NN[:] = saved


def paired_queries(scenes: list[str], trials: list[int], planner: str = "tcbirrt:variant=improved", *,
                   seed: int = 0, time_limit: float = 10.0, robot_name: str = "tcbirrt_dual_arm",
                   kinds: tuple[str, str] = KINDS) -> list[dict[str, Any]]:
    """Each trial of each scene planned both ways (``kinds``: two ``extension`` values, the first runs first on
    even trials, the second on odd ones), same trial seed. One row per query."""
    from .planning_kernel import paired_rows

    specs = {k: f"{planner}:extension={k}" for k in kinds}

    def context(kind: str) -> Any:
        return python_nearest() if kind == "python" else contextlib.nullcontext()

    return paired_rows(scenes, trials, specs, key="kind", seed=seed, time_limit=time_limit, robot_name=robot_name,
                       context=context)


def _pose_cases(robot: Any, sc: Any, kin: Any, n: int, seed: int, rng: np.random.Generator, lin: float,
                ang: float) -> tuple[list[tuple[Any, Any, Any]], list[Any]]:
    """Extension cases ``(q0, M0, M_target)``: from the start and goal of trials 0-2, ``n`` object targets
    each, the pose's twist coordinates perturbed by normal noise of ``lin`` [m] and ``ang`` [rad] per
    component; and the three trials."""
    from ..planners.task_space import pose_from_xi, xi_from_pose
    from ..trials import TrialGenerator

    trs = [TrialGenerator(robot, sc).generate(t, seed) for t in range(3)]
    cases = []
    for tr in trs:
        for q0 in (tr.q_start, tr.q_goal):
            M = kin.object_pose(q0)
            for _ in range(n):
                xi = xi_from_pose(M) + rng.normal(0.0, 1.0, 6) * np.r_[[lin] * 3, [ang] * 3]
                cases.append((q0, M, pose_from_xi(xi)))
    return cases, trs


def extension_costs(scene_name: str, n: int = 100, repeats: int = 3, seed: int = 0,
                    robot_name: str = "tcbirrt_dual_arm") -> dict[str, float]:
    """CPU microseconds per constrained extension (improved variant: interpolation, path IK with restarts,
    configuration and edge checks), native and Python, on the same extensions: ``n`` random targets around
    the object pose of each start and goal configuration of trials 0-2 (position σ 0.1 m, angles σ 0.2 rad),
    best of ``repeats`` alternating passes; also the IK iterations and edge checks of one pass."""
    from ..constraints.closed_chain import ClosedChainKinematics
    from ..model.robot import RobotModel
    from ..planners.task_space import interpolate_task
    from ..planners.tcbirrt import TCBiRRT, TCBiRRTOptions
    from ..planners.tcbirrt_native import native_extend
    from ..planners.validity import ValidityChecker
    from ..scene import Scene

    robot = RobotModel.from_name(robot_name)
    sc = Scene.load(scene_name)
    assert sc.object is not None
    ck, kin = ValidityChecker(robot, sc), ClosedChainKinematics(robot, sc.object.grasps)
    pls = {k: TCBiRRT(robot, sc, TCBiRRTOptions(variant="improved", extension=k), checker=ck, kinematics=kin)
           for k in KINDS}
    rng = np.random.default_rng(seed)
    cases, _ = _pose_cases(robot, sc, kin, n, seed, rng, 0.1, 0.2)
    best: dict[str, float] = {}
    st: dict[str, int] = {}
    for rep in range(repeats):
        for kind in (KINDS if rep % 2 == 0 else KINDS[::-1]):
            pl = pls[kind]
            pl._rng = np.random.default_rng(1)
            st = {k: 0 for k in ("ik_calls", "ik_iterations", "ik_restarts", "ik_failures", "ik_jumps", "collisions",
                                 "edge_checks", "edge_collisions")}
            c0 = time.process_time()
            for q0, M, (Rs, ps) in cases:
                if kind == "native" and pl._ext is not None:
                    native_extend(pl, M.rotation, M.translation, Rs, ps, q0, st, True)
                else:
                    pl.path_ik(interpolate_task(M.rotation, M.translation, Rs, ps, pl.options.n_interp), q0, st, prefix=True)
            best[kind] = min(best.get(kind, np.inf), time.process_time() - c0)
    return {"native_us": 1e6 * best["native"] / len(cases), "python_us": 1e6 * best["python"] / len(cases),
            "extensions": float(len(cases)), "ik_iterations": float(st["ik_iterations"]),
            "edge_checks": float(st["edge_checks"]), "native_available": float(pls["native"]._ext is not None)}


def loop_costs(scene_name: str, n: int = 200, repeats: int = 3, seed: int = 0,
               robot_name: str = "tcbirrt_dual_arm") -> dict[str, float]:
    """CPU µs per extension and per sample with its nearest node, ``extension="loop"`` against ``"native"`` on
    identical work: the same ``n`` random extensions around each start and goal configuration of trials 0-2
    (position σ 0.15 m, angles σ 0.3 rad), and 2,000 samples toward 500-node trees around trial 0's end poses
    (lead path: the straight ξ segment between them); best of ``repeats`` alternating passes."""
    from ..constraints.closed_chain import ClosedChainKinematics
    from ..model.robot import RobotModel
    from ..planners.task_space import xi_from_pose
    from ..planners.tcbirrt import TCBiRRT, TCBiRRTOptions
    from ..planners.tcbirrt_native import loop_extend, native_extend
    from ..planners.tcbirrt_tree import _TaskTree
    from ..planners.validity import ValidityChecker
    from ..scene import Scene

    robot = RobotModel.from_name(robot_name)
    sc = Scene.load(scene_name)
    assert sc.object is not None
    ck, kin = ValidityChecker(robot, sc), ClosedChainKinematics(robot, sc.object.grasps)
    pls = {k: TCBiRRT(robot, sc, TCBiRRTOptions(variant="improved", extension=k), checker=ck, kinematics=kin)
           for k in ("loop", "native")}
    smp: dict[str, Any] = {}
    for k, pl in pls.items():
        pl._rng = np.random.default_rng(seed + 1)
        smp[k] = pl._sampler()
    if pls["loop"]._nrng is None:
        return {"available": 0.0}
    rng = np.random.default_rng(seed)
    cases, trs = _pose_cases(robot, sc, kin, n, seed, rng, 0.15, 0.3)
    xa, xb = xi_from_pose(kin.object_pose(trs[0].q_start)), xi_from_pose(kin.object_pose(trs[0].q_goal))
    ta = _TaskTree(trs[0].q_start, xa, np.eye(3), xa[:3], cap=1024)
    tb = _TaskTree(trs[0].q_goal, xb, np.eye(3), xb[:3], cap=1024)
    for _ in range(499):
        ta.add(trs[0].q_start, xa + rng.normal(size=6) * 0.3, np.eye(3), xa[:3], 0, [], [])
        tb.add(trs[0].q_goal, xb + rng.normal(size=6) * 0.3, np.eye(3), xb[:3], 0, [], [])
    for smp_k in smp.values():
        smp_k.set_endpoints(xa, xb)
        smp_k.guide = np.linspace(xa, xb, 40)
    best: dict[str, float] = {}
    counters = ("ik_calls", "ik_iterations", "ik_restarts", "ik_failures", "ik_jumps", "collisions", "edge_checks",
                "edge_collisions")
    for rep in range(repeats):
        for k in (("loop", "native") if rep % 2 == 0 else ("native", "loop")):
            pl = pls[k]
            st = {c: 0 for c in counters}
            ext_fn = loop_extend if k == "loop" else native_extend
            c0 = time.process_time()
            for q0, M, (Rs, ps) in cases:
                ext_fn(pl, M.rotation, M.translation, Rs, ps, q0, st, True)
            best[k + "_extension_us"] = min(best.get(k + "_extension_us", np.inf), 1e6 * (time.process_time() - c0) / len(cases))
            srng = np.random.default_rng(seed + 2)
            c0 = time.process_time()
            for _ in range(2000):
                if k == "loop":
                    smp[k].sample_near(ta.X, ta.n, None, tb.X, tb.n, None)
                else:
                    ta.nearest(smp[k].sample(srng, tb.alive_xi()))
            best[k + "_sample_us"] = min(best.get(k + "_sample_us", np.inf), 1e6 * (time.process_time() - c0) / 2000)
    return dict(best, extensions=float(len(cases)), available=1.0)


def loop_extension_setup(scene_name: str, n: int, seed: int, robot_name: str = "tcbirrt_dual_arm") -> tuple | None:
    """The improved variant's planner with the native loop extension (``extension="loop"``) and its native IK set
    up on ``scene_name`` (its sampler built, seeded from ``seed``), and ``n`` extension cases per start/goal
    configuration (:func:`_pose_cases`): ``(planner, checker, kinematics, extender, cases)``, or None when the
    native extension or IK is not available here."""
    from ..constraints.closed_chain import ClosedChainKinematics
    from ..model.robot import RobotModel
    from ..planners.tcbirrt import TCBiRRT, TCBiRRTOptions
    from ..planners.validity import ValidityChecker
    from ..scene import Scene

    robot = RobotModel.from_name(robot_name)
    sc = Scene.load(scene_name)
    assert sc.object is not None
    ck, kin = ValidityChecker(robot, sc), ClosedChainKinematics(robot, sc.object.grasps)
    pl = TCBiRRT(robot, sc, TCBiRRTOptions(variant="improved", extension="loop"), checker=ck, kinematics=kin)
    pl._rng = np.random.default_rng(seed + 1)
    pl._sampler()
    ext = pl._ext
    if pl._nrng is None or ext is None or ext._ik is None:
        return None
    cases, _ = _pose_cases(robot, sc, kin, n, seed, np.random.default_rng(seed), 0.15, 0.3)
    return pl, ck, kin, ext, cases


def timed_extensions(pl: Any, ck: Any, cases: list[Any], counters: tuple[str, ...], seed: int) -> tuple[float, dict, int]:
    """One pass of the native loop extension over ``cases`` (the restarts' stream reseeded from ``seed`` first, so that
    passes do identical work): CPU µs per extension, the counters ``counters`` and the configuration checks made."""
    from ..planners.tcbirrt_native import loop_extend

    pl._nrng.lib.tcb_rng_seed(pl._nrng.address, seed + 7)
    st = {c: 0 for c in counters}
    n_checks = ck.n_checks
    c0 = time.process_time()
    for q0, M, (Rs, ps) in cases:
        loop_extend(pl, M.rotation, M.translation, Rs, ps, q0, st, True)
    return 1e6 * (time.process_time() - c0) / len(cases), st, ck.n_checks - n_checks


def ik_costs(scene_name: str, n: int = 200, repeats: int = 3, seed: int = 0,
             robot_name: str = "tcbirrt_dual_arm") -> dict[str, float]:
    """CPU µs per extension (``extension="loop"``: path IK with restarts, checks, edges, one C call) with the
    hand-written C IK against the compiled CasADi block (:attr:`~optplan.planners.kernel.extend.NativeExtender.native_ik`),
    on identical work: the extensions of :func:`loop_costs`, the restarts' stream reseeded before each pass;
    best of ``repeats`` alternating passes, with each pass's counters (equal when the two IKs agree)."""
    setup = loop_extension_setup(scene_name, n, seed, robot_name)
    if setup is None:
        return {"available": 0.0}
    pl, ck, kin, ext, cases = setup
    counters = ("ik_calls", "ik_iterations", "ik_restarts", "ik_failures", "ik_jumps", "collisions", "edge_checks",
                "edge_collisions")
    out: dict[str, float] = {}
    for rep in range(repeats):
        for k in (("c", "casadi") if rep % 2 == 0 else ("casadi", "c")):
            ext.native_ik = k == "c"
            us, st, checks = timed_extensions(pl, ck, cases, counters, seed)
            out[k + "_extension_us"] = min(out.get(k + "_extension_us", np.inf), us)
            for c in ("ik_iterations", "ik_restarts", "edge_checks"):
                out[f"{k}_{c}"] = float(st[c])
            out[k + "_checks"] = float(checks)
    ext.native_ik = True
    return dict(out, extensions=float(len(cases)), available=1.0)


def regrasp_search_costs(scene_name: str, trials: int = 4, goals: int = 3, seed: int = 0,
                         robot_name: str = "tcbirrt_dual_arm") -> dict[str, float]:
    """CPU µs per configuration check of the native RRT-Connect on regrasp queries (one arm of each trial's start
    configuration moving, the other arm and the object still, ``goals`` random valid goals per arm, 3,000-iteration
    cap, 50 shortcuts) with the still part placed once (the default) and with the whole model computed at every
    check (``rrtc_use_static_part = 0``), the two alternating on the same queries and seeds; also the checks of each
    (equal: the same searches)."""
    import ctypes

    from ..constraints.closed_chain import ClosedChainKinematics
    from ..model.robot import RobotModel
    from ..planners.base import Deadline
    from ..planners.kernel.rrtc import load_rrtc_library, native_rrt_connect
    from ..planners.validity import ValidityChecker
    from ..scene import Scene
    from ..trials import TrialGenerator

    robot = RobotModel.from_name(robot_name)
    sc = Scene.load(scene_name)
    assert sc.object is not None
    ck, kin = ValidityChecker(robot, sc), ClosedChainKinematics(robot, sc.object.grasps)
    if ck._native is None:
        return {"available": 0.0}
    flag = ctypes.c_int.in_dll(load_rrtc_library(), "rrtc_use_static_part")
    cpu = {1: 0.0, 0: 0.0}
    checks = {1: 0, 0: 0}
    try:
        for t in range(trials):
            tr = TrialGenerator(robot, sc).generate(t, seed)
            base, M = tr.q_start.copy(), tr.object_start
            for arm in (0, 1):
                idx = np.asarray(kin.idx[arm])
                lo, hi = robot.lower[idx], robot.upper[idx]
                with ck.exempt(tuple(sorted(ck.grasp_contacts(base, M)))):
                    f = ck.validity("fixed", M, base=base, joints=idx)
                    rng = np.random.default_rng(seed + t)
                    gs = [x for x in (rng.uniform(lo, hi) for _ in range(3000)) if f(x)][:goals]
                    for k, g in enumerate(gs):
                        for on in ((1, 0) if k % 2 == 0 else (0, 1)):
                            flag.value = on
                            c0 = time.process_time()
                            got = native_rrt_connect(base[idx], g, lo, hi, f, np.random.default_rng(seed + 5), Deadline(30.0),
                                                     range_=1.0, resolution=0.03, max_iterations=3000, shortcut_iterations=50)
                            cpu[on] += time.process_time() - c0
                            checks[on] += 0 if got is None else got.checks
    finally:
        flag.value = 1
    return {"available": 1.0, "static_us": 1e6 * cpu[1] / max(checks[1], 1), "whole_us": 1e6 * cpu[0] / max(checks[0], 1),
            "static_checks": float(checks[1]), "whole_checks": float(checks[0])}


def lead_path_costs(scene_name: str, trials: int = 10, budget: float = 2.0, seed: int = 0,
                    robot_name: str = "tcbirrt_dual_arm") -> dict[str, dict[str, float]]:
    """The object lead path between the object poses of the start and goal of trials ``0..trials−1``, native
    (one C call) and Python, alternating which runs first, ``budget`` CPU seconds each: per kind the paths found,
    the median CPU [ms] and the median waypoints."""
    from ..constraints.closed_chain import ClosedChainKinematics
    from ..model.robot import RobotModel
    from ..planners.base import Deadline
    from ..planners.kernel.sampler import NativeRandom
    from ..planners.task_sampling import ObjectPoseFilter, object_lead_path
    from ..planners.task_space import xi_from_pose
    from ..planners.tcbirrt_options import TCBiRRTOptions, reach_scaled_workspace
    from ..scene import Scene
    from ..trials import TrialGenerator

    robot = RobotModel.from_name(robot_name)
    sc = Scene.load(scene_name)
    assert sc.object is not None
    lo, hi, _ = reach_scaled_workspace(robot, TCBiRRTOptions())
    filt = ObjectPoseFilter(robot, sc)
    kin = ClosedChainKinematics(robot, sc.object.grasps)
    runs: dict[str, list[tuple[float, bool, int]]] = {"native": [], "python": []}
    for t in range(trials):
        tr = TrialGenerator(robot, sc).generate(t, seed)
        a, b = xi_from_pose(kin.object_pose(tr.q_start)), xi_from_pose(kin.object_pose(tr.q_goal))
        for k in (("native", "python") if t % 2 == 0 else ("python", "native")):
            c0 = time.process_time()
            p = object_lead_path(filt, a, b, lo, hi, np.random.default_rng(t), Deadline(budget, "cpu"),
                                 native_rng=NativeRandom(t) if k == "native" else None)
            runs[k].append((time.process_time() - c0, p is not None, 0 if p is None else len(p)))
    return {k: {"found": float(sum(x[1] for x in v)), "median_ms": 1e3 * float(np.median([x[0] for x in v])),
                "median_waypoints": float(np.median([x[2] for x in v]))} for k, v in runs.items()}


def summary(rows: list[dict[str, Any]], kinds: tuple[str, str] = KINDS) -> str:
    """Per scene: success, median CPU and CPU per iteration of each kind, the paired ratio (second / first),
    same searches."""
    from .planning_kernel import paired_summary

    return paired_summary(rows, "kind", kinds[0], kinds[1], ("iterations", "nodes"))


def _fmt_units(sc: str, u: dict[str, Any]) -> str:
    return (f"{sc}: {int(u['extensions'])} extensions ({int(u['ik_iterations'])} IK iterations, "
            f"{int(u['edge_checks'])} edge checks): native {u['native_us']:.0f} µs, Python {u['python_us']:.0f} µs "
            f"per extension ({u['python_us'] / u['native_us']:.2f}x)"
            + ("" if u["native_available"] else " (native extension unavailable: Python ran twice)"))


def _fmt_ik(sc: str, u: dict[str, Any]) -> str:
    if not u["available"]:
        return f"{sc}: the native loop or the C IK is not available here"
    n = u["extensions"]
    saved = (u["casadi_extension_us"] - u["c_extension_us"]) * n / max(u["c_ik_iterations"], 1.0)
    return (f"{sc}: {int(n)} extensions, IK iterations {u['c_ik_iterations']:.0f} (C) / {u['casadi_ik_iterations']:.0f} "
            f"(CasADi), checks {u['c_checks']:.0f} / {u['casadi_checks']:.0f}: C IK {u['c_extension_us']:.0f} µs, "
            f"CasADi block {u['casadi_extension_us']:.0f} µs per extension "
            f"({u['casadi_extension_us'] / u['c_extension_us']:.2f}x; {saved:.2f} µs saved per IK iteration)")


def _fmt_regrasp(sc: str, u: dict[str, Any]) -> str:
    if not u["available"]:
        return f"{sc}: the native kernel is not available here"
    return (f"{sc}: checks {u['static_checks']:.0f} / {u['whole_checks']:.0f}; µs per check with the still part "
            f"placed once {u['static_us']:.2f}, the whole model {u['whole_us']:.2f} "
            f"({u['whole_us'] / u['static_us']:.2f}x)")


def _fmt_lead(sc: str, costs: dict[str, Any]) -> str:
    return "\n".join(f"{sc} {k}: found {int(v['found'])}/10, median CPU {v['median_ms']:.1f} ms, "
                     f"median waypoints {v['median_waypoints']:.0f}" for k, v in costs.items())


def _fmt_loop(sc: str, u: dict[str, Any]) -> str:
    if not u["available"]:
        return f"{sc}: the native loop is not available here"
    return (f"{sc}: {int(u['extensions'])} extensions: loop {u['loop_extension_us']:.0f} µs, native "
            f"{u['native_extension_us']:.0f} µs ({u['native_extension_us'] / u['loop_extension_us']:.2f}x); "
            f"sample + nearest node: loop {u['loop_sample_us']:.1f} µs, native {u['native_sample_us']:.1f} µs "
            f"({u['native_sample_us'] / u['loop_sample_us']:.2f}x)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.tcbirrt_native",
                                 description="TCBiRRT's native extension step vs the Python one: paired queries")
    ap.add_argument("--scene", default="hard_bay,hard_window,ssps_scene1", help="comma-separated scenes")
    ap.add_argument("--trials", default="0,1,2", help="comma-separated trial indices [index]")
    ap.add_argument("--planners", default="tcbirrt:variant=improved", help="one planner spec")
    ap.add_argument("--seed", type=int, default=0, help="trial seed")
    ap.add_argument("--time-limit", type=float, default=10.0, help="CPU seconds per query [s]")
    ap.add_argument("--units", action="store_true", help="only the CPU per extension, native vs Python")
    ap.add_argument("--loop-units", action="store_true",
                    help="only the CPU per extension and per sample, extension='loop' vs 'native', on identical work")
    ap.add_argument("--ik-units", action="store_true",
                    help="only the CPU per extension with the hand-written C IK vs the CasADi IK block, on identical work")
    ap.add_argument("--regrasp-units", action="store_true",
                    help="only the CPU per check of the regrasps' native RRT-Connect, the still part placed once vs "
                         "the whole model at every check, on the same queries")
    ap.add_argument("--lead-path", action="store_true",
                    help="only the object lead path, native vs Python (10 trials per scene, 2 s CPU each)")
    ap.add_argument("--kinds", default="native,python",
                    help="the two 'extension' values paired (loop, native, python); the ratio is second / first")
    a = ap.parse_args(argv)
    from .tcbirrt import expand_scenes

    unit_modes = ((a.units, extension_costs, _fmt_units), (a.ik_units, ik_costs, _fmt_ik),
                  (a.regrasp_units, regrasp_search_costs, _fmt_regrasp), (a.lead_path, lead_path_costs, _fmt_lead),
                  (a.loop_units, loop_costs, _fmt_loop))
    for chosen, measure, fmt in unit_modes:
        if chosen:
            for sc in expand_scenes(a.scene.split(",")):
                print(fmt(sc, measure(sc, seed=a.seed)))
            return 0
    kinds = tuple(k.strip() for k in a.kinds.split(","))
    if len(kinds) != 2 or any(k not in ("loop", "native", "python") for k in kinds) or kinds[0] == kinds[1]:
        ap.error(f"--kinds: expected two different values of loop, native, python, got {a.kinds!r}")
    rows = paired_queries(expand_scenes(a.scene.split(",")), [int(x) for x in a.trials.split(",") if x.strip()],
                          a.planners, seed=a.seed, time_limit=a.time_limit, kinds=(kinds[0], kinds[1]))
    for r in rows:
        print(f"{r['scene']} trial {r['trial']} {r['kind']:6s}: {r['status']}, {r['cpu_s']:.3f} s CPU, "
              f"{r['iterations']} iterations, {r['nodes']} nodes, {r['cpu_per_iteration_ms']:.3f} ms/iteration"
              + ("" if r["native"] or r["kind"] == "python" else " (native extension unavailable: Python ran)"))
    print(summary(rows, (kinds[0], kinds[1])))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
