"""The pipeline's segment NLP, closed class against the shared core, split into IPOPT, its callbacks and
the rest, on one recorded segment of a kind per scene, two passes in one process, alternating which
implementation goes first (docs/decisions/0023-one-stack.md). Runs at commit 527f399 (the last with the
closed class), on a file written by ``segment_nlp_pair.py record --bench generalize``:

    python docs/studies/segment_nlp_split.py gen.pkl regrasp
"""
from __future__ import annotations

import collections
import pickle
import sys
import time

import optplan.pipeline as PL
import optplan.problem.nlp as NLP
from optplan.bench import warmstart as W
from optplan.pipeline_options import PipelineOptions

CALLBACKS = ("nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l")


def main() -> None:
    kind = sys.argv[2] if len(sys.argv) > 2 else "regrasp"
    with open(sys.argv[1], "rb") as f:
        segs = [s for s in pickle.load(f) if s["kind"] == kind]
    seen: set[str] = set()
    pick = []
    for s in segs:
        if s["scene"] not in seen:
            seen.add(s["scene"])
            pick.append(s)
    acc: collections.Counter = collections.Counter()
    cur = ["closed"]
    orig = NLP.NlpSolver.solve

    def spy(self, x0, **kw):
        c0 = time.process_time()
        out = orig(self, x0, **kw)
        acc[cur[0] + ":ipopt"] += time.process_time() - c0
        st = self.stats()
        acc[cur[0] + ":callbacks"] += sum(st.get("t_proc_" + k, 0.0) for k in CALLBACKS)
        return out

    NLP.NlpSolver.solve = spy
    try:
        for rep in range(2):
            acc.clear()
            for n, s in enumerate(pick):
                w = W._state("tcbirrt_dual_arm", s["scene"])
                for impl in (("closed", "optproblem") if (n + rep) % 2 == 0 else ("optproblem", "closed")):
                    cur[0] = impl
                    c0 = time.process_time()
                    _, _, att = PL._spline_segment(w["gen"].robot, w["scene"], s["path"], s["kind"], s["arm"],
                                                   PipelineOptions(segment_nlp=impl), s["ipopt"])
                    acc[impl + ":total"] += time.process_time() - c0
                    acc[impl + ":it"] += sum(a["iterations"] for a in att)
            print(kind, "pass", rep, len(pick), "segments", {k: round(v, 3) for k, v in sorted(acc.items())}, flush=True)
    finally:
        NLP.NlpSolver.solve = orig


if __name__ == "__main__":
    main()
