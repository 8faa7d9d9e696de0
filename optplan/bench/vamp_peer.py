"""optplan's RRT-Connect paired against VAMP's (vector-accelerated motion planning, Kavraki Lab) on the
single-Panda queries of :mod:`optplan.bench.panda_rrtc`. Optional: needs the ``vamp`` module (PyPI
``vamp-planner``; its sdist fetches its C++ dependencies from GitHub at build time) and
``example-robot-data``; without them it says so and exits with status 0.

The setup, per query (the two planners alternate which goes first):

* the same obstacles (spheres as spheres; boxes as VAMP cuboids of the same centre and half edges),
  the same start and goal, the same joint limits as the sampling box, the same ``range`` (largest
  extension [rad]);
* VAMP's RRT-Connect with ``dynamic_domain`` off (optplan's default) and its tree balancing as optplan's
  (``--balance``, default optplan's default 1, VAMP's ``tree_ratio`` default; ``--vamp-defaults`` keeps VAMP's own
  settings, the dynamic domain on), its Halton sampler, no simplification; optplan's
  :class:`~optplan.planners.rrtconnect.RRTConnect` with the native search, no shortcuts, and by default
  its Halton sampler too (``--sampler uniform``: independent uniform draws; optplan's Halton points are
  shifted by a random vector per query, VAMP's sequence is fixed);
* NOT the same robot model: VAMP's Panda is a set of spheres, optplan's the vendor's capsules; nor the
  same edge checks: VAMP checks an edge at 32 points per unit of joint-space distance, optplan at every
  ``resolution`` rad of the largest joint change. How many of VAMP's paths optplan's model (coal,
  exact, at 0.01 rad) accepts is reported; they are checked after all the timed calls, so that the garbage of
  those checks is not collected inside a timed call.

``--mbm PATH`` plans MotionBenchMaker's Panda problems instead (VAMP's ``resources/panda/problems.tar.bz2``;
:mod:`optplan.bench.mbm`: seven scenarios of 100 problems, shelves, tables, a box and a cage of turned boxes and
capsules), the first ``--per-scenario`` of each, one query per problem; with ``--spheres-urdf`` both planners check
the same robot (VAMP's spheres, and the self-collision pairs of VAMP's ``panda.srdf`` beside that URDF: every
pair of links it does not disable — on 14,000 random configurations of 70 of these scenes VAMP's verdict and
optplan's agree on every one). A problem whose start or goal either side calls invalid is skipped and counted.

Times are CPU seconds of this process around each call (``time.process_time``); VAMP's own
``nanoseconds`` (wall, inside the call) are reported beside them.

``python -m optplan.bench.vamp_peer --queries 25``;
``python -m optplan.bench.vamp_peer --mbm <vamp>/resources/panda/problems.tar.bz2 --spheres-urdf
<vamp>/resources/panda/panda_spherized.urdf --per-scenario 100``
"""
from __future__ import annotations

import argparse
import importlib
import statistics
import time
from typing import Any

import numpy as np
import pinocchio as pin

from .panda_rrtc import GOAL, START, queries, run_optplan

__all__ = ["vamp_available", "vamp_environment", "run_vamp", "main"]

#: the per-query target: optplan's RRT-Connect within this factor of VAMP's on the same queries
TARGET_RATIO = 5.0


def vamp_available() -> Any:
    """The ``vamp`` module, or None when it cannot be imported."""
    try:
        return importlib.import_module("vamp")
    except ImportError:
        return None


def vamp_environment(vamp: Any, scene: Any) -> Any:
    """The scene's spheres, boxes (turned too) and capsules as a ``vamp.Environment``."""
    env = vamp.Environment()
    for o in scene.obstacles:
        p = [float(v) for v in o.placement.translation]
        R = o.placement.rotation
        if o.shape == "sphere":
            env.add_sphere(vamp.Sphere(p, float(o.radius)))
        elif o.shape == "box":   # VAMP's Euler XYZ: R = Rz(c) Ry(b) Rx(a), as Pinocchio's roll-pitch-yaw
            euler = [float(v) for v in pin.rpy.matrixToRpy(R)]
            env.add_cuboid(vamp.Cuboid(p, euler, [float(v) / 2 for v in o.size]))
        elif o.shape == "capsule":   # the segment along the local z axis, by its end points
            h = 0.5 * float(o.length) * R[:, 2]
            env.add_capsule(vamp.Cylinder([float(v) for v in o.placement.translation - h],
                                          [float(v) for v in o.placement.translation + h], float(o.radius)))
        else:
            raise ValueError(f"vamp_environment: obstacle {o.name!r} is a {o.shape}; spheres, boxes and capsules are mapped")
    return env


def run_vamp(vamp: Any, env: Any, *, range_: float, vamp_defaults: bool = False, start: Any = START,
             goal: Any = GOAL, balance: float = 0.0) -> dict[str, Any]:
    """One VAMP RRT-Connect query from ``start`` to ``goal`` (default: the cage example's): CPU seconds around
    the call, VAMP's own time, iterations, solved and path. Without ``vamp_defaults`` its dynamic domain is off
    and its tree balancing is ``balance`` (its ``tree_ratio``; 0: off), as optplan's."""
    planner = vamp.panda.rrtc
    settings = vamp.RRTCSettings()
    settings.range = float(range_)
    if not vamp_defaults:
        settings.dynamic_domain = False
        settings.balance = balance > 0
        if balance > 0:
            settings.tree_ratio = float(balance)
    sampler = vamp.panda.halton()
    c0 = time.process_time()
    res = planner([float(v) for v in start], [float(v) for v in goal], env, settings, sampler)
    cpu = time.process_time() - c0
    solved = bool(res.solved)
    path = np.asarray(res.path.numpy(), dtype=float) if solved else None   # (a Path object cannot be iterated)
    return {"cpu_s": cpu, "own_s": float(res.nanoseconds) * 1e-9, "iterations": int(res.iterations),
            "status": "exact" if solved else "failed", "path": path}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.vamp_peer", description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="cage,boxes", help="comma-separated: cage, boxes")
    ap.add_argument("--queries", type=int, default=25, help="queries per scene")
    ap.add_argument("--seed", type=int, default=0, help="seed of the scene perturbations and of optplan's planner")
    ap.add_argument("--range", type=float, default=1.0, help="largest extension of both planners [rad]")
    ap.add_argument("--resolution", type=float, default=0.03, help="optplan's edge check step [rad]")
    ap.add_argument("--vamp-defaults", action="store_true", help="keep VAMP's dynamic domain and tree balancing")
    ap.add_argument("--sampler", default="halton", choices=("uniform", "halton"),
                    help="optplan's sampler (default halton: the same kind of sequence as VAMP's sampler)")
    ap.add_argument("--dynamic-domain", type=float, default=0.0,
                    help="optplan's dynamic domain radius [rad] (RRTConnectOptions.dynamic_domain; 0: off; VAMP's "
                         "default radius is 4)")
    ap.add_argument("--balance", type=float, default=None,
                    help="both planners' tree balancing ratio (RRTConnectOptions.balance and VAMP's tree_ratio; 0: "
                         "off; default: optplan's default, 1, which is VAMP's)")
    ap.add_argument("--spheres-urdf", default=None,
                    help="plan with this Panda URDF's collision spheres instead of the vendor's capsules, e.g. VAMP's "
                         "resources/panda/panda_spherized.urdf (the robot VAMP checks)")
    ap.add_argument("--mbm", default=None, metavar="PATH",
                    help="plan MotionBenchMaker's Panda problems instead (VAMP's resources/panda/problems.tar.bz2, "
                         "or the directory it was unpacked into); with VAMP's sphere robot (--spheres-urdf), the same "
                         "robot and self-collision pairs on both sides")
    ap.add_argument("--scenarios", default=None, help="with --mbm: comma-separated scenarios (default: all seven)")
    ap.add_argument("--per-scenario", type=int, default=20, help="with --mbm: the first N problems of each scenario")
    ap.add_argument("--json", default=None, metavar="OUT", help="write every query's row (no paths) to this JSON file")
    args = ap.parse_args(argv)
    vamp = vamp_available()
    if vamp is None:
        print("vamp is not importable here (pip install vamp-planner; its build fetches from GitHub): nothing to pair")
        return 0
    from ..model.example_robots import example_robots_available

    if not example_robots_available():
        print("example-robot-data is not installed (pip install 'optplan[robots]'): nothing to pair")
        return 0
    from .panda_rrtc import load_single_panda

    if args.balance is None:
        from ..planners import RRTConnectOptions

        args.balance = RRTConnectOptions().balance
    robot = load_single_panda(args.spheres_urdf)
    if args.mbm is not None:
        return _run_mbm(args, vamp, robot)
    for kind in args.scenes.split(","):
        rows: dict[str, list[dict[str, Any]]] = {"vamp": [], "optplan": []}
        to_validate = []   # VAMP's paths, checked by coal after the timed runs (its garbage stays out of them)
        for k, (sc, ck) in enumerate(queries(robot, kind, args.queries, args.seed)):
            env = vamp_environment(vamp, sc)
            if not (vamp.panda.validate(list(START), env) and vamp.panda.validate(list(GOAL), env)):
                continue
            for name in (("vamp", "optplan") if k % 2 == 0 else ("optplan", "vamp")):
                if name == "vamp":
                    rows[name].append(run_vamp(vamp, env, range_=args.range, vamp_defaults=args.vamp_defaults,
                                               balance=args.balance))
                else:
                    rows[name].append(run_optplan(robot, sc, ck, args.seed + k, native=True, range_=args.range,
                                                  resolution=args.resolution, sampler=args.sampler,
                                                  dynamic_domain=args.dynamic_domain, balance=args.balance))
            to_validate.append((sc, rows["vamp"][-1]["path"]))
        _line(kind, rows, _accepted(robot, to_validate))
    return 0


def _accepted(robot: Any, to_validate: list[tuple[Any, Any]]) -> int:
    """How many of VAMP's paths (``(scene, path or None)``) optplan's exact model (coal, edges at 0.01 rad) accepts;
    run after the timed calls, so that the garbage of these checks is not collected inside one."""
    from ..planners.rrtconnect import edge_is_valid
    from ..planners.validity import ValidityChecker

    n = 0
    for sc, P in to_validate:
        if P is not None:
            f = ValidityChecker(robot, sc, kernel="coal").validity("free")
            n += bool(f(P[0])) and all(edge_is_valid(a, b, f, 0.01) for a, b in zip(P[:-1], P[1:]))
    return n


def _line(label: str, rows: dict[str, list[dict[str, Any]]], accepted: int) -> None:
    """One summary line per planner and their ratio of medians, and the median of the per-query ratios."""
    med = {}
    for name, rs in rows.items():
        ok = [r for r in rs if r["status"] == "exact"]
        med[name] = statistics.median(r["cpu_s"] for r in rs) * 1e3 if rs else float("nan")
        per_it = [r["cpu_s"] / r["iterations"] * 1e6 for r in ok if r["iterations"] > 0]
        extra = (f", VAMP's own median {statistics.median(r['own_s'] for r in rs) * 1e3:.3f} ms"
                 if name == "vamp" and rs else "")
        print(f"{label:18s} {name:8s} {len(ok)}/{len(rs)} solved, median {med[name]:.3f} ms CPU per query, "
              f"{statistics.median(per_it) if per_it else float('nan'):.2f} us per iteration, median "
              f"{statistics.median(r['iterations'] for r in rs) if rs else float('nan'):.0f} iterations{extra}")
    q = [a["cpu_s"] / b["cpu_s"] for a, b in zip(rows["optplan"], rows["vamp"]) if b["cpu_s"] > 0]
    print(f"{label:18s} optplan / vamp: {med['optplan'] / med['vamp']:.1f}x (medians; target <= {TARGET_RATIO:g}x), per query median "
          f"{statistics.median(q) if q else float('nan'):.1f}x; VAMP paths valid in optplan's model: "
          f"{accepted}/{len(rows['vamp'])}")


def _run_mbm(args: Any, vamp: Any, robot: Any) -> int:
    """MotionBenchMaker's problems (``--mbm``): per problem both planners, alternating which goes first; a problem
    whose start or goal is invalid for either side is skipped and counted."""
    import json

    from ..planners.kernel.rrtc import prepare_native_search
    from ..planners.validity import ValidityChecker
    from .mbm import load_mbm

    scen = None if args.scenarios is None else [s.strip() for s in args.scenarios.split(",") if s.strip()]
    try:
        problems = load_mbm(args.mbm, scen, args.per_scenario)
    except (OSError, ValueError, ImportError) as e:
        print(f"--mbm {args.mbm}: {e}")
        return 2
    by: dict[str, list[Any]] = {}
    for pr in problems:
        by.setdefault(pr.scenario, []).append(pr)
    every: dict[str, list[dict[str, Any]]] = {"vamp": [], "optplan": []}
    dump = []
    acc_all = 0
    k = 0
    for scenario, prs in by.items():
        rows: dict[str, list[dict[str, Any]]] = {"vamp": [], "optplan": []}
        to_validate, skipped = [], 0
        for pr in prs:
            env = vamp_environment(vamp, pr.scene)
            ck = ValidityChecker(robot, pr.scene)
            if not (vamp.panda.validate(list(pr.start), env) and vamp.panda.validate(list(pr.goal), env)
                    and ck.is_valid_free(pr.start) and ck.is_valid_free(pr.goal)):
                skipped += 1
                continue
            prepare_native_search(ck)   # the per-scene set-up, outside the timed queries (as VAMP's environment)
            for name in (("vamp", "optplan") if k % 2 == 0 else ("optplan", "vamp")):
                if name == "vamp":
                    r = run_vamp(vamp, env, range_=args.range, vamp_defaults=args.vamp_defaults, start=pr.start,
                                 goal=pr.goal, balance=args.balance)
                else:
                    r = run_optplan(robot, pr.scene, ck, args.seed + k, native=True, range_=args.range,
                                    resolution=args.resolution, sampler=args.sampler, start=pr.start, goal=pr.goal,
                                    dynamic_domain=args.dynamic_domain, balance=args.balance)
                rows[name].append(r)
            k += 1
            to_validate.append((pr, rows["vamp"][-1]["path"]))
            dump.append({"key": pr.key, **{n: {kk: v for kk, v in rows[n][-1].items() if kk not in ("path", "search")}
                                           for n in rows}})
        accepted = _accepted(robot, [(pr.scene, P) for pr, P in to_validate])
        if skipped:
            print(f"{scenario}: {skipped} of {len(prs)} problems skipped (start or goal invalid for one side)")
        _line(scenario, rows, accepted)
        for n in rows:
            every[n] += rows[n]
        acc_all += accepted
    if len(by) > 1:
        _line("all", every, acc_all)
    if args.json:
        from .._io import write_text

        write_text(args.json, json.dumps(dump, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
