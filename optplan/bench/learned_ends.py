"""How a scene's CVAE and latent classifier see the benchmark's starts and goals:
``python -m optplan.bench.learned_ends --scene 1 --trials 10 [--data-task-fraction 1.0]``.

For trials ``0..trials-1`` (seed 0 unless told), each start and goal configuration ``q`` is encoded (``z``); printed
per end, as medians and ranges over the trials: the classifier's score of ``z``, the CVAE's largest joint
reconstruction error ``max |decode(z) − q|`` [rad], the joint distance from ``q`` of ``project(decode(z))`` [rad],
and how many of the decodings of ``z`` and of ``z + r·ε`` (``ε`` standard normal over ``√latent_dim``, so that
``|r·ε| ≈ r``; ``draws`` per radius ``r``) are valid after the projection (shared checker); then the same share for
prior samples ``z ~ N(0, I)``. Needs the optional extra ``learned`` (the scene's models, cached or trained).
"""
from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np

__all__ = ["end_codes", "main"]


def end_codes(scene_name: str, trials: int, radii: tuple[float, ...] = (0.0, 0.3, 1.0), draws: int = 20,
              seed: int = 0, data_task_fraction: float = 0.0) -> dict[str, Any]:
    """Per end (``"start"``, ``"goal"``): lists over the trials of ``p``, ``recon_max``, ``dq`` and ``valid[r]``
    (valid decodings of ``draws``); ``"prior_valid"``: valid decodings of ``10·draws`` prior samples."""
    from ..constraints.closed_chain import ClosedChainKinematics
    from ..model.robot import RobotModel
    from ..planners import make_planner
    from ..planners.manifold_samples import project_onto_chain
    from ..planners.validity import ValidityChecker
    from ..scene import Scene
    from ..trials import TrialGenerator

    scene = Scene.load(scene_name)
    robot = RobotModel.from_name(scene.robot or "tcbirrt_dual_arm")
    assert scene.object is not None
    kin = ClosedChainKinematics(robot, scene.object.grasps)
    ck = ValidityChecker(robot, scene)
    pl: Any = make_planner("lcbirrt", robot, scene, checker=ck, kinematics=kin, data_task_fraction=data_task_fraction)
    lo, hi = robot.lower, robot.upper
    rng = np.random.default_rng(seed)

    def valid(z: np.ndarray) -> tuple[bool, np.ndarray | None]:
        x = project_onto_chain(kin, np.clip(pl.cvae.decode(z), lo, hi), lo, hi, 1e-7)
        return x is not None and bool(ck.is_valid(x)), x

    out: dict[str, Any] = {e: {"p": [], "recon_max": [], "dq": [], "valid": {r: [] for r in radii}}
                           for e in ("start", "goal")}
    gen = TrialGenerator(robot, scene)
    for k in range(trials):
        t = gen.generate(k, seed)
        for end, q in (("start", t.q_start), ("goal", t.q_goal)):
            z0 = pl.cvae.encode(q)
            e = out[end]
            e["p"].append(float(pl.classifier.probability(z0)))
            e["recon_max"].append(float(np.abs(pl.cvae.decode(z0) - q).max()))
            _, x = valid(z0)
            e["dq"].append(float(np.linalg.norm(x - q)) if x is not None else float("nan"))
            for r in radii:
                e["valid"][r].append(sum(valid(z0 + r * rng.standard_normal(len(z0)) / np.sqrt(len(z0)))[0]
                                         for _ in range(draws)))
    out["prior_valid"] = sum(valid(np.asarray(rng.standard_normal(pl.cvae.latent_dim)))[0] for _ in range(10 * draws))
    out["draws"], out["trials"] = draws, trials
    return out


def _fmt(v: list[float]) -> str:
    return f"{np.nanmedian(v):.2f} ({np.nanmin(v):.2f}-{np.nanmax(v):.2f})"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m optplan.bench.learned_ends", description=__doc__)
    ap.add_argument("--scene", default="1", help="scene name or SSPS number")
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--draws", type=int, default=20, help="decodings per radius and end")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--data-task-fraction", type=float, default=0.0, help="the models' data (as the planners' option)")
    a = ap.parse_args(argv)
    if a.trials < 1 or a.draws < 1 or not 0 <= a.data_task_fraction <= 1:
        print(f"--trials, --draws: expected >= 1 (got {a.trials}, {a.draws}); --data-task-fraction in [0, 1] "
              f"(got {a.data_task_fraction})", file=sys.stderr)
        return 2
    scene = f"ssps_scene{a.scene}" if a.scene.isdigit() else a.scene
    r = end_codes(scene, a.trials, draws=a.draws, seed=a.seed, data_task_fraction=a.data_task_fraction)
    n = a.draws * a.trials
    print(f"{scene}: trials 0-{a.trials - 1} (seed {a.seed}), data_task_fraction {a.data_task_fraction}; "
          "median (range) over the trials")
    for end in ("start", "goal"):
        e = r[end]
        valid = " / ".join(f"{sum(v)}" for v in e["valid"].values())
        print(f"{end:5s}: classifier {_fmt(e['p'])}, reconstruction max |err| {_fmt(e['recon_max'])} rad, "
              f"projected decoding at {_fmt(e['dq'])} rad; valid decodings at r = "
              f"{' / '.join(str(x) for x in e['valid'])}: {valid} of {n}")
    print(f"prior samples: {r['prior_valid']} of {10 * a.draws} valid")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
