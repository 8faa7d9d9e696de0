"""IPOPT's ``perturb_always_cd`` on the floating pipeline's carry NLP (plane rows, closed chain,
base attitude), paired: every ``_optimize`` call of the pipeline is solved with the setting off
and on (same problem, same guess; the pipeline continues with the "on" result, as it ran before).

    python docs/studies/floating_plane_rows_settings.py [--scenes floating_truss floating_stow] [--trials 4]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from optplan import floating_pipeline as fp
from optplan.model.robot import RobotModel
from optplan.problem import OptProblem
from optplan.scene import Scene

_SETTING = {"value": "yes"}
_ROWS: list[tuple[str, int, float, bool, str, int, float, bool]] = []
_orig_solve = OptProblem.solve
_orig_optimize = fp._optimize


def _solve(self, ipopt_options=None, **kw):
    return _orig_solve(self, {**(ipopt_options or {}), "perturb_always_cd": _SETTING["value"]}, **kw)


def _optimize(*a, **k):
    out = {}
    for v in ("no", "yes") if len(_ROWS) % 2 == 0 else ("yes", "no"):   # alternate the order
        _SETTING["value"] = v
        c0 = time.process_time()
        sol = _orig_optimize(*a, **k)
        out[v] = (sol, time.process_time() - c0)
    (s0, c0_), (s1, c1) = out["no"], out["yes"]
    _ROWS.append((s0.status.value, s0.total_iterations, c0_, s0.success, s1.status.value, s1.total_iterations, c1,
                  s1.success))
    print(f"    N={len(s1.t) - 1}: off {s0.status.value} it={s0.total_iterations} cpu={c0_:.2f} | "
          f"on {s1.status.value} it={s1.total_iterations} cpu={c1:.2f} | cost off/on {s0.cost:.6g}/{s1.cost:.6g}",
          flush=True)
    return out["yes"][0]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", nargs="+", default=["floating_truss", "floating_stow"])
    ap.add_argument("--trials", type=int, default=4)
    args = ap.parse_args()
    OptProblem.solve = _solve          # type: ignore[method-assign]
    fp._optimize = _optimize
    robot = RobotModel.from_name("eba_ffsr")
    for name in args.scenes:
        scene = Scene.load(name)
        for i in range(args.trials):
            print(f"{name} trial {i}", flush=True)
            res = fp.run_floating_pipeline(robot, scene, fp.scene_start(robot, scene), fp.trial_goal(scene, i, 0),
                                           fp.options_for_scene(scene), seed=i)
            print(f"  success={res.success}", flush=True)
    if _ROWS:
        it0, it1 = np.array([r[1] for r in _ROWS]), np.array([r[5] for r in _ROWS])
        c0, c1 = np.array([r[2] for r in _ROWS]), np.array([r[6] for r in _ROWS])
        print(f"{len(_ROWS)} solves: converged off {sum(r[3] for r in _ROWS)} / on {sum(r[7] for r in _ROWS)}; "
              f"iterations off {it0.sum()} / on {it1.sum()}; CPU off {c0.sum():.1f} s / on {c1.sum():.1f} s; "
              f"paired CPU ratio off/on median {np.median(c0 / c1):.2f}")


if __name__ == "__main__":
    main()
