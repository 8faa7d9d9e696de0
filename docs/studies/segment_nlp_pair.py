"""The pipeline's segment NLP, closed class against the shared core, on the same segments in one
process (decision 0021): record the segments ``pipeline._spline_segment`` receives in
``bench warmstart`` trials, then optimize each with both implementations, alternating which goes
first, and compare process CPU, iterations and IPOPT's callback CPU.

    python docs/studies/segment_nlp_pair.py record segs.pkl --trials 3     # 3 scenes x 3 trials: 36 segments
    python docs/studies/segment_nlp_pair.py record gen.pkl --bench generalize --scenes suite,stress,panda --trials 2
    python docs/studies/segment_nlp_pair.py replay segs.pkl --reps 2 [--out pairs.jsonl]

``record --bench generalize`` records the segments of ``bench generalize`` trials (the fixed-base scene
groups ``suite``, ``stress``, ``panda``: every scene with its own robot). ``replay`` prints the sums per
segment kind (constrained / regrasp) as well.

The closed class was retired by docs/decisions/0023-one-stack.md: this comparison runs at commit
527f399 (the last with ``segment_nlp="closed"``): run that commit's copy of this file
(``git show 527f399:docs/studies/segment_nlp_pair.py``). On later commits ``record`` is
``segment_knotmap.py``'s, which records the same segments.

The machine's load changes CPU times: compare the two implementations within one run only
(the last repetition's sums; the first pays for kernel loading and structure builds).
"""
from __future__ import annotations

import collections
import json
import pickle
import time

from segment_knotmap import CALLBACKS, ROBOT, parser, record_from  # noqa: E402  (this directory: the same recording)

import optplan.pipeline as PL
import optplan.problem.nlp as NLP
from optplan.bench import warmstart as W
from optplan.pipeline_options import PipelineOptions


def replay(path: str, reps: int, out: str | None, impls: tuple[str, str] = ("closed", "optproblem")) -> None:
    with open(path, "rb") as f:
        segs = pickle.load(f)
    acc: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    kinds: dict[tuple[str, str], collections.Counter] = collections.defaultdict(collections.Counter)
    cur = [impls[0]]
    orig = NLP.NlpSolver.solve

    def spy(self, x0, **kw):
        c0 = time.process_time()
        o = orig(self, x0, **kw)
        st = self.stats()
        acc[cur[0]]["ipopt"] += time.process_time() - c0
        for k in CALLBACKS:
            acc[cur[0]][k] += st.get("t_proc_" + k, 0.0)
        return o

    NLP.NlpSolver.solve = spy
    fout = open(out, "w") if out else None
    try:
        for r in range(reps):
            tot: collections.Counter = collections.Counter()
            its: collections.Counter = collections.Counter()
            for n, s in enumerate(segs):
                w = W._state(ROBOT, s["scene"])
                res = {}
                for impl in (impls if (n + r) % 2 == 0 else impls[::-1]):
                    cur[0] = impl
                    c0 = time.process_time()
                    sol, rep, att = PL._spline_segment(w["gen"].robot, w["scene"], s["path"], s["kind"], s["arm"],
                                                       PipelineOptions(segment_nlp=impl), s["ipopt"])
                    c = time.process_time() - c0
                    it = sum(a["iterations"] for a in att)
                    res[impl] = [c, it, bool(sol.success and rep.min_clearance_m >= 0.0)]
                    tot[impl] += c
                    its[impl] += it
                    if r == reps - 1:
                        kinds[(s["kind"], impl)].update({"cpu": c, "it": it, "n": 1, "ok": int(res[impl][2])})
                if fout:
                    fout.write(json.dumps({"rep": r, "seg": n, "scene": s["scene"], "kind": s["kind"], **res}) + "\n")
            a, b = impls
            print(f"repetition {r}: CPU {a} {tot[a]:.2f} s, {b} {tot[b]:.2f} s, ratio {tot[b] / tot[a]:.3f}; "
                  f"iterations {its[a]} / {its[b]}", flush=True)
    finally:
        NLP.NlpSolver.solve = orig
        if fout:
            fout.close()
    a, b = impls
    for kind in sorted({k for k, _ in kinds}):
        ka, kb = kinds[(kind, a)], kinds[(kind, b)]
        print(f"{kind} (last repetition, {ka['n']} segments): {a} {ka['it']} iterations, {ka['cpu']:.2f} s CPU, "
              f"{ka['ok']} verified; {b} {kb['it']} iterations, {kb['cpu']:.2f} s CPU, {kb['ok']} verified; "
              f"CPU ratio {kb['cpu'] / ka['cpu']:.3f}")
    for k, c in acc.items():
        cb = sum(c[x] for x in CALLBACKS)
        print(f"{k} (all repetitions): IPOPT {c['ipopt']:.2f} s, callbacks {cb:.2f} s "
              f"(Jacobian {c['nlp_jac_g']:.2f}, Hessian {c['nlp_hess_l']:.2f}, g {c['nlp_g']:.2f})")


def main() -> None:
    ap, _, _ = parser(__doc__)
    a = ap.parse_args()
    if a.cmd == "record":
        record_from(a)
    else:
        replay(a.segments, a.reps, a.out)


if __name__ == "__main__":
    main()
