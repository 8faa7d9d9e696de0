"""RRT-Connect on single-Panda queries: optplan's native search against its Python search (and, in
:mod:`optplan.bench.vamp_peer`, against VAMP).

The robot is one Franka Panda from ``example-robot-data`` (extra ``robots``): the vendor's
``panda_collision.urdf``, fingers frozen open, every cylinder-and-two-spheres link model merged into
the capsule it is (:func:`optplan.model.robot_file.merge_capsules`), self-collision pairs at least
three joints apart minus the pairs the vendor's SRDF disables. Two scene families, each query a fresh
perturbation drawn from ``numpy.random.default_rng(seed)``:

* ``cage``: VAMP's sphere-cage example (fourteen spheres of radius 0.2 m around the arm in two rings,
  each centre moved by up to ±``variation`` m per query), from the ready pose
  ``[0, -0.785, 0, -2.356, 0, 1.571, 0.785]`` to ``[2.35, 1, 0, -0.8, 0, 2.5, 0.785]`` rad;
* ``boxes``: eight boxes (0.1-0.3 m edges) around the arm, the same start and goal.

Queries whose start or goal collide in optplan's model are redrawn. The per-scene set-up (the
validity checker and the native search's broad phase) is outside the timed queries. Each query is planned with
``range`` (largest extension [rad]) and ``resolution`` (edge check step [rad]) in the joint limits.

``python -m optplan.bench.panda_rrtc --queries 25`` prints the median CPU time per query and per
iteration of each search, and their ratio.
"""
from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..scene import Obstacle, Scene

__all__ = ["START", "GOAL", "CAGE_CENTRES", "load_single_panda", "panda_query", "main"]

#: the start and goal of VAMP's sphere-cage example [rad]
START = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
GOAL = np.array([2.35, 1.0, 0.0, -0.8, 0.0, 2.5, 0.785])
#: the sphere centres of VAMP's sphere-cage example [m] (radius :data:`CAGE_RADIUS`)
CAGE_CENTRES = np.array([[0.55, 0, 0.25], [0.35, 0.35, 0.25], [0, 0.55, 0.25], [-0.55, 0, 0.25], [-0.35, -0.35, 0.25],
                         [0, -0.55, 0.25], [0.35, -0.35, 0.25], [0.35, 0.35, 0.8], [0, 0.55, 0.8], [-0.35, 0.35, 0.8],
                         [-0.55, 0, 0.8], [-0.35, -0.35, 0.8], [0, -0.55, 0.8], [0.35, -0.35, 0.8]])
CAGE_RADIUS = 0.2  # [m]
#: the boxes scene: centres [m] and full edges [m] before the per-query perturbation
BOX_CENTRES = np.array([[0.55, 0.35, 0.15], [0.6, -0.3, 0.5], [-0.55, 0.35, 0.8], [-0.4, -0.45, 0.7],
                        [0.1, 0.6, 0.75], [0.05, -0.6, 0.2], [-0.6, 0.0, 0.1], [0.45, 0.0, 1.05]])
BOX_SIZES = np.array([[0.3, 0.2, 0.3], [0.15, 0.3, 0.2], [0.2, 0.2, 0.25], [0.25, 0.15, 0.2],
                      [0.2, 0.1, 0.2], [0.3, 0.2, 0.15], [0.1, 0.3, 0.2], [0.2, 0.3, 0.1]])
FINGER_OPENING = 0.04  # [m]


def load_single_panda(spheres_urdf: str | Path | None = None, srdf: str | Path | None = None) -> Any:
    """One Panda (module docstring) as a :class:`~optplan.model.robot.RobotModel` (needs ``example-robot-data``).

    ``spheres_urdf``: another URDF of the Panda to take instead of the vendor's, e.g. VAMP's
    ``resources/panda/panda_spherized.urdf`` (59 spheres: the robot VAMP checks); its visual
    elements are dropped, its collision spheres kept as they are. ``srdf``: an SRDF whose
    ``disable_collisions`` decide the self-collision pairs instead: every pair of geometries on two
    links that it does not disable (VAMP's rule with its ``panda.srdf``; default for a
    ``spheres_urdf``: the ``panda.srdf`` beside it, if there is one); without one, the pairs at least
    three joints apart minus those the vendor's SRDF disables."""
    from ..model._robot_data import _require_dir
    from ..model.dual_panda import srdf_disabled_pairs
    from ..model.robot import RobotModel
    from ..model.robot_file import freeze_prismatic, merge_capsules

    share = _require_dir()
    src = Path(spheres_urdf) if spheres_urdf is not None else share / "robots/panda_description/urdf/panda_collision.urdf"
    root = ET.parse(src).getroot()
    for link in root.iter("link"):
        for v in link.findall("visual"):
            link.remove(v)
    for e in root:
        freeze_prismatic(e, FINGER_OPENING)   # the fingers: frozen, open
        if e.tag == "link":
            merge_capsules(e)
    for m in root.iter("mesh"):
        fn = m.get("filename", "")
        if fn.startswith("package://example-robot-data/"):
            m.set("filename", str(share / fn[len("package://example-robot-data/"):]))
    name = "single_panda" if spheres_urdf is None else "single_panda_spheres"
    path = Path(tempfile.gettempdir()) / "optplan_example_robots" / f"{name}.urdf"
    path.parent.mkdir(exist_ok=True)
    text = ET.tostring(root, encoding="unicode")
    if not path.exists() or path.read_text() != text:
        from .._io import write_text

        write_text(path, text)
    ee = "panda_hand_tcp" if spheres_urdf is None else "panda_hand"
    robot = RobotModel.from_urdf(path, arms={"arm": {"ee": ee,
                                                     "joints": [f"panda_joint{k}" for k in range(1, 8)]}},
                                 name=name)
    if srdf is None and spheres_urdf is not None and (src.parent / "panda.srdf").exists():
        srdf = src.parent / "panda.srdf"
    objs = robot.collision_model.geometryObjects

    def link_of(g: int) -> str:
        return str(robot.model.frames[objs[g].parentFrame].name)

    if srdf is not None:
        sroot = ET.parse(srdf).getroot()
        disabled = {frozenset((d.get("link1"), d.get("link2"))) for d in sroot.iter("disable_collisions")}
        candidates = [(a, b) for a in range(len(objs)) for b in range(a + 1, len(objs)) if link_of(a) != link_of(b)]
    else:
        disabled = srdf_disabled_pairs(share)
        candidates = list(robot.collision_pairs)
    robot.set_collision_pairs([(a, b) for a, b in candidates if frozenset((link_of(a), link_of(b))) not in disabled])
    return robot


def panda_query(kind: str, rng: np.random.Generator, variation: float = 0.01) -> Scene:
    """One scene of the family ``kind`` (``"cage"`` or ``"boxes"``), its obstacles moved by up to
    ±``variation`` [m] (cage) or ±2 ``variation`` [m] (boxes) per coordinate."""
    obs = []
    if kind == "cage":
        for k, c in enumerate(CAGE_CENTRES):
            p = c + rng.uniform(-variation, variation, 3)
            obs.append(Obstacle(f"sphere{k}", "sphere", pin.SE3(np.eye(3), p), radius=CAGE_RADIUS))
    elif kind == "boxes":
        for k, (c, s) in enumerate(zip(BOX_CENTRES, BOX_SIZES)):
            p = c + rng.uniform(-2 * variation, 2 * variation, 3)
            obs.append(Obstacle(f"box{k}", "box", pin.SE3(np.eye(3), p), size=(float(s[0]), float(s[1]), float(s[2]))))
    else:
        raise ValueError(f"panda_query: kind must be 'cage' or 'boxes', got {kind!r}")
    return Scene(name=f"panda_{kind}", robot=None, obstacles=tuple(obs))


def queries(robot: Any, kind: str, n: int, seed: int, kernel: str = "native") -> list[tuple[Scene, Any]]:
    """``n`` scenes of ``kind`` with a valid start and goal, and their validity checkers."""
    from ..planners.kernel.rrtc import prepare_native_search
    from ..planners.validity import ValidityChecker

    rng = np.random.default_rng(seed)
    out: list[tuple[Scene, Any]] = []
    for _ in range(50 * n):
        if len(out) == n:
            break
        sc = panda_query(kind, rng)
        ck = ValidityChecker(robot, sc, kernel=kernel)
        if ck.is_valid_free(START) and ck.is_valid_free(GOAL):
            prepare_native_search(ck)   # the per-scene set-up, outside the timed queries (as VAMP's environment)
            out.append((sc, ck))
    return out


def run_optplan(robot: Any, sc: Scene, ck: Any, seed: int, *, native: bool, range_: float = 1.0,
                resolution: float = 0.03, time_limit: float = 10.0, shortcut_iterations: int = 0,
                sampler: str = "uniform", start: Any = START, goal: Any = GOAL, **options: Any) -> dict[str, Any]:
    """One RRT-Connect query from ``start`` to ``goal`` [rad] (default: the cage example's; ``sampler`` and
    ``options``: :class:`.RRTConnectOptions`): CPU and wall time [s], iterations, nodes, status and path."""
    from ..planners import RRTConnect, RRTConnectOptions

    pl = RRTConnect(robot, sc, RRTConnectOptions(range=range_, resolution=resolution, native_search=native,
                                                 shortcut_iterations=shortcut_iterations, sampler=sampler, **options),
                    checker=ck)
    t0, c0 = time.perf_counter(), time.process_time()
    res = pl.plan(np.asarray(start, dtype=float), np.asarray(goal, dtype=float), time_limit=time_limit, seed=seed)
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    return {"cpu_s": cpu, "wall_s": wall, "iterations": int(res.stats.get("iterations", 0)),
            "nodes": int(res.stats.get("nodes", 0)), "status": res.status.value, "path": res.path,
            "search": res.stats.get("search")}


def summary(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Median CPU per query [ms], median CPU per iteration [µs], successes."""
    ok = [r for r in rows if r["status"] == "exact"]
    per_it = [r["cpu_s"] / r["iterations"] * 1e6 for r in ok if r["iterations"] > 0]
    return {"median_ms": 1e3 * statistics.median(r["cpu_s"] for r in rows) if rows else math.nan,
            "median_us_per_iteration": statistics.median(per_it) if per_it else math.nan,
            "median_iterations": statistics.median(r["iterations"] for r in rows) if rows else math.nan,
            "success": len(ok), "n": len(rows)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.panda_rrtc", description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="cage,boxes", help="comma-separated: cage, boxes")
    ap.add_argument("--queries", type=int, default=25, help="queries per scene")
    ap.add_argument("--seed", type=int, default=0, help="seed of the scene perturbations and the planners")
    ap.add_argument("--range", type=float, default=1.0, help="largest extension [rad]")
    ap.add_argument("--resolution", type=float, default=0.03, help="edge check step [rad]")
    ap.add_argument("--time-limit", type=float, default=10.0, help="per query [s]")
    ap.add_argument("--sampler", default="uniform", choices=("uniform", "halton"), help="the planners' sampler")
    ap.add_argument("--spheres-urdf", default=None,
                    help="plan with this Panda URDF's collision spheres instead of the vendor's capsules, e.g. VAMP's "
                         "resources/panda/panda_spherized.urdf (the robot VAMP checks)")
    args = ap.parse_args(argv)
    robot = load_single_panda(args.spheres_urdf)
    for kind in args.scenes.split(","):
        qs = queries(robot, kind, args.queries, args.seed)
        rows: dict[str, list[dict[str, Any]]] = {"native": [], "python": []}
        for k, (sc, ck) in enumerate(qs):
            order = ("native", "python") if k % 2 == 0 else ("python", "native")   # alternate
            for name in order:
                rows[name].append(run_optplan(robot, sc, ck, args.seed + k, native=name == "native", range_=args.range,
                                              resolution=args.resolution, time_limit=args.time_limit,
                                              sampler=args.sampler))
        s = {name: summary(r) for name, r in rows.items()}
        for name, v in s.items():
            print(f"{kind:6s} {name:7s} {v['success']}/{v['n']} solved  median {v['median_ms']:.3f} ms CPU per query, "
                  f"{v['median_us_per_iteration']:.1f} us CPU per iteration, median {v['median_iterations']:.0f} iterations")
        print(f"{kind:6s} python / native: {s['python']['median_ms'] / s['native']['median_ms']:.1f}x per query, "
              f"{s['python']['median_us_per_iteration'] / s['native']['median_us_per_iteration']:.1f}x per iteration")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
