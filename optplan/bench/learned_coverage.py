"""How well an on-manifold data set covers the configurations a task-space planner passes through:
``python -m optplan.bench.learned_coverage --scene 1 --trials 20 --data default,region,task``.

For trials ``0..trials-1`` of the benchmark (seed 0 unless told), TCBiRRT with the benchmark's edge checks
plans each query; every configuration of each returned path is measured against the data set by the joint-space
distance to its nearest member (a k-d tree over the set) [rad, Euclidean over the 14 joints]. Per path:
the start's, the goal's, the median and the largest distance (the largest lies between the two regions: the
"corridor"). Printed per data set as medians over the paths, with the range of the largest. Needs no learning
library: it measures the data the learned planners are trained on (:mod:`optplan.planners.manifold_samples`).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["DATA_SETS", "path_coverage", "coverage_table", "planner_paths", "main"]

#: named data sets [-]: ``ManifoldSampleSettings`` fields of each (the rest default)
DATA_SETS: dict[str, dict[str, Any]] = {
    "default": {},
    "region": {"region_fraction": 0.3},
    "task": {"task_fraction": 1.0},
    "task+walk": {"task_fraction": 0.5},
}


def path_coverage(Q: np.ndarray, paths: list[np.ndarray], masks: list[np.ndarray] | None = None) -> list[dict[str, float]]:
    """Per path: distance [rad] of its first, last, median and farthest configuration to the nearest row of ``Q``;
    with ``masks``, the median and the farthest over the masked configurations only (the on-chain ones)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(np.asarray(Q, float))
    out = []
    for k, P in enumerate(paths):
        d, _ = tree.query(np.asarray(P, float))
        m = d if masks is None else d[np.asarray(masks[k], bool)]
        out.append({"start": float(d[0]), "goal": float(d[-1]), "median": float(np.median(m)), "max": float(m.max())})
    return out


def coverage_table(rows: dict[str, list[dict[str, float]]]) -> str:
    """One line per data set: medians over the paths [rad] and the range of the per-path maximum."""
    lines = [f"{'data':12s} {'paths':>5s} {'start':>6s} {'goal':>6s} {'median':>6s} {'max (median, range)':>22s}"]
    for name, r in rows.items():
        if not r:
            lines.append(f"{name:12s} {0:5d}")
            continue
        med = {k: float(np.median([x[k] for x in r])) for k in ("start", "goal", "median", "max")}
        mx = [x["max"] for x in r]
        lines.append(f"{name:12s} {len(r):5d} {med['start']:6.2f} {med['goal']:6.2f} {med['median']:6.2f} "
                     f"{med['max']:7.2f} ({min(mx):.2f}-{max(mx):.2f})")
    return "\n".join(lines)


def planner_paths(scene_name: str, trials: int, time_limit: float, seed: int = 0,
                  planner: str = "tcbirrt") -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The configurations of ``planner``'s successful paths on trials ``0..trials-1`` (the benchmark's planner
    options, trials and seeds; CPU-time limit ``time_limit`` [s]) and, per path, which are on the closed chain
    (TCBiRRT's regrasps let one hand go: those configurations are off the manifold the data sample)."""
    from ..constraints.closed_chain import ClosedChainKinematics
    from ..model.robot import RobotModel
    from ..planners import make_planner
    from ..planners.validity import ValidityChecker
    from ..scene import Scene
    from ..trials import TrialGenerator
    from .tcbirrt import BENCH_PLANNER_DEFAULTS

    scene = Scene.load(scene_name)
    robot = RobotModel.from_name(scene.robot or "tcbirrt_dual_arm")
    assert scene.object is not None
    kin = ClosedChainKinematics(robot, scene.object.grasps)
    pl = make_planner(planner, robot, scene, checker=ValidityChecker(robot, scene), kinematics=kin,
                      **BENCH_PLANNER_DEFAULTS.get(planner, {}))
    gen = TrialGenerator(robot, scene)
    paths, masks = [], []
    for k in range(trials):
        t = gen.generate(k, seed)
        res = pl.plan(t.q_start, t.q_goal, time_limit=time_limit, seed=t.seed, clock="cpu")
        if res.success:
            P = np.asarray(res.path, float)
            paths.append(P)
            c = np.asarray(res.constrained, bool)
            masks.append(c if len(c) == len(P) else np.ones(len(P), bool))
    return paths, masks


def data_set(scene_name: str, name: str, n: int = 10_000, progress: bool = False) -> Any:
    """The cached (or generated) data set ``name`` of :data:`DATA_SETS` for the scene."""
    from ..model.robot import RobotModel
    from ..planners.manifold_samples import ManifoldSampleSettings, manifold_samples
    from ..scene import Scene

    if name not in DATA_SETS:
        raise ValueError(f"data set {name!r}: expected one of {', '.join(DATA_SETS)}")
    scene = Scene.load(scene_name)
    robot = RobotModel.from_name(scene.robot or "tcbirrt_dual_arm")
    return manifold_samples(robot, scene, ManifoldSampleSettings(n=n, **DATA_SETS[name]), progress=progress)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.learned_coverage", description=__doc__)
    ap.add_argument("--scene", default="1", help="scene name or SSPS number")
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--time-limit", type=float, default=2.0, help="TCBiRRT's CPU-time limit per query [s]")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--data", default="default,region,task", help=f"comma-separated, of: {', '.join(DATA_SETS)}")
    ap.add_argument("--planner", default="tcbirrt", help="the planner whose paths are measured (tcbirrt, cbirrt2)")
    ap.add_argument("--json", default=None, help="write the per-path figures here")
    a = ap.parse_args(argv)
    names = [x.strip() for x in a.data.split(",") if x.strip()]
    bad = [x for x in names if x not in DATA_SETS]
    if bad or a.trials < 1 or not a.time_limit > 0:
        print(f"--data: expected names among {', '.join(DATA_SETS)} (got {bad}); --trials >= 1; --time-limit > 0",
              file=sys.stderr)
        return 2
    scene = f"ssps_scene{a.scene}" if a.scene.isdigit() else a.scene
    paths, masks = planner_paths(scene, a.trials, a.time_limit, a.seed, a.planner)
    rows, on_chain = {}, {}
    for name in names:
        ds = data_set(scene, name, progress=True)
        rows[name] = path_coverage(ds.Q, paths)
        on_chain[name] = path_coverage(ds.Q, paths, masks)
        print(f"{name}: {ds.Q.shape[0]} configurations, {ds.draws} draws, {ds.time_s:.0f} s to generate, "
              f"file {ds.path}", flush=True)
    off = sum(int((~m).sum()) for m in masks)
    print(f"{scene}: {a.planner} solved {len(paths)} of {a.trials} trials (seed {a.seed}, {a.time_limit} s CPU); "
          f"{off} of {sum(len(P) for P in paths)} path configurations off the closed chain (regrasps)")
    print("every configuration of the paths:")
    print(coverage_table(rows))
    print("the on-chain configurations only (median, max):")
    print(coverage_table(on_chain))
    if a.json:
        Path(a.json).write_text(json.dumps({"scene": scene, "trials": a.trials, "planner": a.planner, "rows": rows,
                                             "on_chain": on_chain}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
