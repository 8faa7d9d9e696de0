"""The pipeline's segment NLPs under two IPOPT μ globalizations, on the same segments (decision 0021,
fifth addendum): record the segments ``pipeline._spline_segment`` receives in ``optplan plan``'s
trials (trial 0, the given seeds), then optimize each under the retry policy with the segments'
IPOPT options and ``adaptive_mu_globalization`` set to each value given, and count iterations and
verified segments.

    python docs/studies/segment_globalization.py record segs.pkl --scenes 1,2,3 --seeds 0-4
    python docs/studies/segment_globalization.py replay segs.pkl --modes obj-constr-filter,never-monotone-mode

Iterations do not depend on the machine's load; the CPU column does.
"""
from __future__ import annotations

import argparse
import pickle
import time

import numpy as np

import optplan.pipeline as PL
from optplan.model.robot import RobotModel
from optplan.pipeline_options import PLANNER_DEFAULTS, PipelineOptions
from optplan.scene import Scene
from optplan.trials import TrialGenerator

ROBOT = "tcbirrt_dual_arm"


def _ints(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi) + 1)) if hi else [int(v) for v in text.split(",")]


def record(out: str, scenes: list[str], seeds: list[int]) -> None:
    robot = RobotModel.from_name(ROBOT)
    segs: list[dict] = []
    orig = PL._spline_segment

    def rec(robot_, scene, seg_path, kind, arm, opts, ipopt):
        segs.append({"scene": scene.name, "path": np.array(seg_path), "kind": kind, "arm": arm, "seed": seed})
        return orig(robot_, scene, seg_path, kind, arm, opts, ipopt)

    PL._spline_segment = rec
    opts = PipelineOptions(workers=1, planner_options=PLANNER_DEFAULTS["tcbirrt"] + (("variant", "improved"),))
    try:
        for name in scenes:
            scene = Scene.load(name)
            for seed in seeds:   # as `optplan plan --scene N --seed S` (trial 0)
                trial = TrialGenerator(robot, scene).generate(0, seed)
                res = PL.run_pipeline(robot, scene, trial.q_start, trial.q_goal, opts, seed=seed)
                print(name, seed, "verified" if res.success else "NOT verified", res.iterations, flush=True)
    finally:
        PL._spline_segment = orig
    with open(out, "wb") as f:
        pickle.dump(segs, f)
    print(f"{len(segs)} segments -> {out}")


def replay(path: str, modes: list[str]) -> None:
    robot = RobotModel.from_name(ROBOT)
    with open(path, "rb") as f:
        segs = pickle.load(f)
    for mode in modes:
        opts = PipelineOptions(ipopt_options=tuple(kv for kv in PipelineOptions().ipopt_options
                                                   if kv[0] != "adaptive_mu_globalization")
                               + (("adaptive_mu_globalization", mode),))
        it = ok = retries = 0
        cpu = time.process_time()
        per_kind: dict[str, int] = {}
        for s in segs:
            scene = Scene.load(s["scene"])
            sol, rep, att = PL._spline_segment(robot, scene, s["path"], s["kind"], s["arm"], opts, dict(opts.ipopt_options))
            n = sum(a["iterations"] for a in att)
            it += n
            per_kind[s["kind"]] = per_kind.get(s["kind"], 0) + n
            retries += sum(a["reason"] == "globalization" for a in att)
            ok += bool(sol.success and rep.min_clearance_m >= 0.0 and (s["kind"] != "constrained"
                       or rep.max_closed_chain_residual <= opts.closed_chain_tol))
        print(f"{mode}: {ok}/{len(segs)} verified, {it} iterations {per_kind}, {retries} globalization re-solves, "
              f"{time.process_time() - cpu:.1f} s CPU", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("out")
    r.add_argument("--scenes", default="1,2,3")
    r.add_argument("--seeds", default="0-4", help="'0-4' or '0,3,7'")
    p = sub.add_parser("replay")
    p.add_argument("segments")
    p.add_argument("--modes", default="obj-constr-filter,never-monotone-mode")
    a = ap.parse_args()
    if a.cmd == "record":
        record(a.out, [f"ssps_scene{s}" if s.isdigit() else s for s in a.scenes.split(",")], _ints(a.seeds))
    else:
        replay(a.segments, a.modes.split(","))


if __name__ == "__main__":
    main()
