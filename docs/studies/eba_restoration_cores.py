"""The EBA restoration NLP's builders interleaved in one process on the same scenarios (decision
0022: the shared core ``OptProblem`` against the former closed ``FloatingSplineProblem``).

    python docs/studies/eba_restoration_cores.py [--repeat 2] [--cases free_end,end_constrained]
        [--builders bspline,knots]

The closed builder was ``--builders closed,bspline`` at commit 246b6d1 (the option left with it).

A first untimed run of each builder warms the kernel cache; then, per repeat, each case with each
builder: process CPU of build + solve, IPOPT's iterations (coarse + fine), build and IPOPT wall
times, rows and nonzeros of the final NLP, and verify's independent figures.
"""
from __future__ import annotations

import argparse
import time

from optplan.model.robot import RobotModel
from optplan.papers import eba


def one(robot, case: str, tr: str) -> dict:
    sc = eba.free_end_scenario() if case == "free_end" else eba.end_constrained_scenario(robot)
    o = (eba.NLPOptions.free_end if case == "free_end" else eba.NLPOptions.end_constrained)(transcription=tr)
    c0 = time.process_time()
    res = eba.run_nlp(robot, sc, o)
    cpu = time.process_time() - c0
    rep = eba.evaluate(robot, res, sc)
    i = res.info
    st = getattr(res.raw, "attempts", None)
    stats = st[-1].stats if st and hasattr(st[-1], "stats") else {}
    return {"case": case, "tr": tr, "success": res.success, "it": i["total_iterations"], "cpu": cpu,
            "setup": i["setup_s"], "ipopt": res.runtime_s, "cost": i["cost"],
            "att_deg": rep.final_base_attitude_error_deg,
            "cc": rep.max_closed_chain_residual if sc.closed_chain else float("nan"),
            "nlp_cpu": {k: v for k, v in stats.items() if k.startswith("t_proc")} if stats else {}}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--cases", default="free_end,end_constrained")
    ap.add_argument("--builders", default="bspline")
    args = ap.parse_args()
    robot = RobotModel.from_name("eba_ffsr")
    cases, builders = args.cases.split(","), args.builders.split(",")
    for case in cases:                       # warm-up: kernels and structures into the caches
        for tr in builders:
            one(robot, case, tr)
    for r in range(args.repeat):
        for case in cases:
            for tr in builders:
                d = one(robot, case, tr)
                print(f"{r} {d['case']:16s} {d['tr']:8s} ok={d['success']} it={d['it']:3d} cpu={d['cpu']:.2f}s "
                      f"setup={d['setup']:.2f}s ipopt={d['ipopt']:.2f}s cost={d['cost']:.7g} "
                      f"att={d['att_deg']:.2e}deg cc={d['cc']:.1e}", flush=True)


if __name__ == "__main__":
    main()
