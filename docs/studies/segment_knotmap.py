"""The pipeline's segment NLP on recorded segments: process CPU, IPOPT iterations and IPOPT's
callback CPU per segment, for comparing two trees paired on the same segments (decision 0023,
addendum on the shared knot-value map). Record the segments ``pipeline._spline_segment`` receives
in ``bench warmstart`` (or ``bench generalize``) trials once, then replay them in one process per
tree, alternating the trees (``PYTHONPATH``) run by run:

    python docs/studies/segment_knotmap.py record segs.pkl --trials 3
    python docs/studies/segment_knotmap.py record gen.pkl --bench generalize --trials 1
    PYTHONPATH=/tmp/b_main python docs/studies/segment_knotmap.py replay segs.pkl --reps 2 --out main.jsonl
    python docs/studies/segment_knotmap.py replay segs.pkl --reps 2 --out branch.jsonl
    python docs/studies/segment_knotmap.py compare main.jsonl branch.jsonl
    python docs/studies/segment_knotmap.py replay segs.pkl --reps 2 --profile prof.out   # cProfile, last rep

The shared knot-value map itself was measured neutral and not kept (decision 0023's addendum); the
in-process ``ab`` mode that switched it on and off went with it.

The first repetition pays for loading kernels and building structures; ``compare`` uses the last.
The machine's load changes CPU times: only compare runs made close together, alternated.
"""
from __future__ import annotations

import argparse
import collections
import json
import pickle
import time

import numpy as np

import optplan.pipeline as PL
import optplan.problem.nlp as NLP
from optplan.bench import warmstart as W
from optplan.pipeline_options import PipelineOptions

ROBOT = "tcbirrt_dual_arm"
SCENES = ("ssps_scene1", "ssps_scene2", "ssps_scene3")
CALLBACKS = ("nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l")


def record(out: str, trials: int, bench: str, scenes: str) -> None:
    segs: list[dict] = []
    orig = PL._spline_segment
    cur: list[tuple[str, int]] = [("", 0)]

    def rec(robot, scene, seg_path, kind, arm, opts, ipopt):
        segs.append({"scene": scene.name, "path": np.array(seg_path), "kind": kind, "arm": arm,
                     "ipopt": dict(ipopt), "trial": cur[0], "robot": robot.name})
        return orig(robot, scene, seg_path, kind, arm, opts, ipopt)

    PL._spline_segment = rec
    cfg = W.WarmstartConfig(trials=trials, modes=("warm",), segment_workers=1)
    names = scenes.split(",")
    if bench == "generalize":
        from optplan.bench import generalize as G

        names = G.expand(names)
        gcfg = G.GeneralizeConfig(trials=trials, progress=False)
        PL.default_workers = lambda: 1   # one process: the recording sees every segment
    try:
        for scene in names:
            for i in range(trials):
                cur[0] = (scene, i)
                if bench == "generalize":
                    line = G.run_trial(scene, i, gcfg)
                else:
                    line = W._run_unit((ROBOT, scene, i, "warm", cfg.time_limit, cfg.seed, None, True, "bspline",
                                        False, 1))
                print(scene, i, line.get("success"), sum(s["trial"] == cur[0] for s in segs), flush=True)
    finally:
        PL._spline_segment = orig
    with open(out, "wb") as f:
        pickle.dump(segs, f)
    print(f"{len(segs)} segments -> {out}")


_SCENES: dict = {}


def _world(s: dict) -> tuple:
    """(robot, scene) of a recorded segment (the scene file's robot, the dual arm by default)."""
    from optplan.bench import generalize as G
    from optplan.scene import Scene

    sc = _SCENES.get(s["scene"])
    if sc is None:
        sc = _SCENES[s["scene"]] = Scene.load(s["scene"])
    return G._robot(sc.robot or ROBOT), sc


def replay(path: str, reps: int, out: str | None, profile: str | None, ipopt: str = "") -> None:
    with open(path, "rb") as f:
        segs = pickle.load(f)
    cb: collections.Counter = collections.Counter()
    orig = NLP.NlpSolver.solve

    def spy(self, x0, **kw):
        c0 = time.process_time()
        o = orig(self, x0, **kw)
        cb["t_solve"] += time.process_time() - c0
        st = self.stats()
        for k in CALLBACKS:
            cb["t_" + k] += st.get("t_proc_" + k, 0.0)
            cb["n_" + k] += st.get("n_call_" + k, 0)
        return o

    orig_init = NLP.NlpSolver.__init__

    def init(self, *a, **kw):
        c0 = time.process_time()
        orig_init(self, *a, **kw)
        cb["t_nlpsol"] += time.process_time() - c0
        cb["n_nlpsol"] += 1

    NLP.NlpSolver.solve = spy
    NLP.NlpSolver.__init__ = init
    fout = open(out, "w") if out else None
    prof = None
    extra = tuple((k, _value(v)) for k, v in (kv.split("=", 1) for kv in ipopt.split(",") if kv))
    popts = PipelineOptions()
    try:
        for r in range(reps):
            if profile and r == reps - 1:
                import cProfile

                prof = cProfile.Profile(time.process_time)
                prof.enable()
            tot, its, ok = 0.0, 0, 0
            cb.clear()
            for n, s in enumerate(segs):
                robot, scene = _world(s)
                c0 = time.process_time()
                sol, rep, att = PL._spline_segment(robot, scene, s["path"], s["kind"], s["arm"], popts, {**s["ipopt"], **dict(extra)})
                c = time.process_time() - c0
                it = sum(a["iterations"] for a in att)
                v = bool(sol.success and rep.min_clearance_m >= 0.0)
                tot, its, ok = tot + c, its + it, ok + v
                if fout:
                    fout.write(json.dumps({"rep": r, "seg": n, "scene": s["scene"], "kind": s["kind"], "cpu": c,
                                           "it": it, "ok": v, "attempts": len(att)}) + "\n")
            if prof is not None:
                prof.disable()
                prof.dump_stats(profile)
            cbt = sum(cb["t_" + k] for k in CALLBACKS)
            print(f"repetition {r}: {len(segs)} segments, CPU {tot:.2f} s, iterations {its}, verified {ok}; "
                  f"IPOPT {cb['t_solve']:.2f} s of which callbacks {cbt:.2f} s ("
                  + ", ".join(f"{k[4:]} {cb['t_' + k]:.2f} s / {cb['n_' + k]}" for k in CALLBACKS)
                  + f"); {cb['n_nlpsol']} IPOPT instances made, {cb['t_nlpsol']:.2f} s",
                  flush=True)
    finally:
        NLP.NlpSolver.solve = orig
        NLP.NlpSolver.__init__ = orig_init
        if fout:
            fout.close()


def _value(v: str) -> object:
    for t in (int, float):
        try:
            return t(v)
        except ValueError:
            pass
    return v


def compare(a: str, b: str) -> None:
    def load(p: str) -> dict:
        rows = [json.loads(line) for line in open(p)]
        last = max(r["rep"] for r in rows)
        return {r["seg"]: r for r in rows if r["rep"] == last}

    A, B = load(a), load(b)
    segs = sorted(set(A) & set(B))
    for kind in sorted({A[s]["kind"] for s in segs}) + ["all"]:
        ss = [s for s in segs if kind == "all" or A[s]["kind"] == kind]
        ca_, cb_ = sum(A[s]["cpu"] for s in ss), sum(B[s]["cpu"] for s in ss)
        r = np.array([B[s]["cpu"] / A[s]["cpu"] for s in ss])
        same = sum(A[s]["it"] == B[s]["it"] for s in ss)
        print(f"{kind}: {len(ss)} segments; iterations {sum(A[s]['it'] for s in ss)} / {sum(B[s]['it'] for s in ss)} "
              f"(same on {same}); verified {sum(A[s]['ok'] for s in ss)} / {sum(B[s]['ok'] for s in ss)}; "
              f"CPU {ca_:.2f} / {cb_:.2f} s, sum ratio {cb_ / ca_:.3f}, per segment median "
              f"{np.median(r):.3f} (quartiles {np.quantile(r, 0.25):.3f} / {np.quantile(r, 0.75):.3f})")


def parser(doc: str) -> tuple[argparse.ArgumentParser, argparse._SubParsersAction, argparse.ArgumentParser]:
    """The studies' command line: ``record`` (as :func:`record`) and ``replay``; returns the parser,
    its sub-parsers and the replay parser, for a study to add its own options and commands."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("out")
    r.add_argument("--trials", type=int, default=3)
    r.add_argument("--bench", choices=["warmstart", "generalize"], default="warmstart")
    r.add_argument("--scenes", default=None, help="comma-separated scenes (generalize: groups too)")
    p = sub.add_parser("replay")
    p.add_argument("segments")
    p.add_argument("--reps", type=int, default=2)
    p.add_argument("--out", default=None)
    return ap, sub, p


def record_from(a: argparse.Namespace) -> None:
    """:func:`record` with the parsed ``record`` options (default scenes per benchmark)."""
    record(a.out, a.trials, a.bench, a.scenes or (",".join(SCENES) if a.bench == "warmstart" else "suite,stress,panda"))


def main() -> None:
    ap, sub, p = parser(__doc__)
    p.add_argument("--profile", default=None, help="cProfile of the last repetition (process CPU) to this file")
    p.add_argument("--ipopt", default="", help="extra IPOPT options of every solve: name=value,name=value")
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    a = ap.parse_args()
    if a.cmd == "record":
        record_from(a)
    elif a.cmd == "replay":
        replay(a.segments, a.reps, a.out, a.profile, a.ipopt)
    else:
        compare(a.a, a.b)


if __name__ == "__main__":
    main()
