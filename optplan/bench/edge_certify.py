"""Benchmark of the certified edge checks (:mod:`optplan.planners.edge_certify`), paired on the same
edges: conservative advancement on exact distances, the discrete alternative with coal security
margins (both certified), and the uncertified 1 cm Jacobian-spaced checks for scale.

    python -m optplan.bench.edge_certify [--edges 150] [--seed 0]

Edges: straight joint segments between valid configurations near each scene's start and goal
(σ 0.05 rad, then a step of σ 0.1 rad). PR2 scenes need ``optplan[robots]``.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

__all__ = ["compare", "main"]

HARD_SCENES = ("hard_clutter_dense", "hard_clutter_sparse", "hard_corridor")
PR2_SCENES = ("oc_industrial_1", "oc_tabletop")


def compare(robot, scene, q_start: np.ndarray, q_goal: np.ndarray, n: int = 150, seed: int = 0,
            tolerance: float = 0.01, min_clearance: float = 1e-3) -> dict[str, dict[str, float]]:
    """Per method: ``ms_per_edge`` (CPU), ``accepted``, ``distance_calls`` and ``collision_checks``
    per edge, on ``n`` random edges (see the module docstring)."""
    from ..planners.validity import ValidityChecker

    ck = ValidityChecker(robot, scene)
    cert = ck.certifier(min_clearance)
    cert.prepare(("held",))
    ck.prepare_edge_checks(("held",))
    rng = np.random.default_rng(seed)
    edges: list[tuple[np.ndarray, np.ndarray]] = []
    for _ in range(200 * n):
        if len(edges) == n:
            break
        a = (q_start if len(edges) % 2 else q_goal) + rng.normal(0.0, 0.05, q_start.size)
        b = a + rng.normal(0.0, 0.1, a.size)
        a, b = np.clip(a, robot.lower, robot.upper), np.clip(b, robot.lower, robot.upper)
        if ck.is_valid(a) and ck.is_valid(b):
            edges.append((a, b))
    if not edges:
        raise RuntimeError(f"no valid edge found near the start and goal of {scene.name!r}")
    methods = {"advancement": lambda a, b: cert.segment(a, b),
               "discrete margins": lambda a, b: cert.discrete_segment(a, b, tolerance),
               "uncertified 1 cm": lambda a, b: ck.edge_is_valid(a, b, tolerance)}
    out = {}
    for name, fn in methods.items():
        d0, c0, t0 = cert.n_distance_calls, cert.n_checks + ck.n_checks, time.process_time()
        acc = sum(bool(fn(a, b)) for a, b in edges)
        t = time.process_time() - t0
        m = len(edges)
        out[name] = {"ms_per_edge": 1e3 * t / m, "accepted": acc, "edges": m,
                     "distance_calls": (cert.n_distance_calls - d0) / m,
                     "collision_checks": (cert.n_checks + ck.n_checks - c0) / m}
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--edges", type=int, default=150)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    from ..bench.hardscenes import nominal_configurations
    from ..model.example_robots import example_robots_available
    from ..model.robot import RobotModel
    from ..scene import Scene

    rows = []
    tcb = RobotModel.from_name("tcbirrt_dual_arm")
    for sc in HARD_SCENES:
        scene = Scene.load(sc)
        rows.append((sc, compare(tcb, scene, *nominal_configurations(tcb, scene), n=args.edges, seed=args.seed)))
    if example_robots_available():
        from .oc_rrt import setup_scene

        for sc in PR2_SCENES:
            s = setup_scene(sc, [])
            rows.append((sc, compare(s["robot"], s["scene"], s["q_start"], s["q_goal"], n=args.edges, seed=args.seed)))
    else:
        print("note: example-robot-data missing (pip install \"optplan[robots]\"): PR2 scenes skipped")
    print(f"{'scene':22s} {'method':18s} {'ms/edge':>8s} {'accepted':>9s} {'dist/edge':>9s} {'checks/edge':>11s}")
    for sc, r in rows:
        for name, d in r.items():
            print(f"{sc:22s} {name:18s} {d['ms_per_edge']:8.3f} {d['accepted']:5d}/{d['edges']:<3d} "
                  f"{d['distance_calls']:9.1f} {d['collision_checks']:11.1f}")
    print("target: the certified check kept is the faster of the two certified ones; both accept only edges "
          "clear at every point (advancement: pairs >= min_clearance/2 apart; margins: >= 0)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
