"""Historical record (decision 0006): written against the closed segment NLP class before the pipeline
moved onto OptProblem's shared core (decision 0021); it reads that class's internals and does not run
on the current package. Its figures stand as measured then.

Structure-exploiting solvers for the B-spline segment NLP, measured against IPOPT + MUMPS.

A study script (not part of the package): it rebuilds the pipeline's constrained B-spline segments
of the warm-start benchmark's trials (same planner, seeds, shortcut and grid as
``optplan.pipeline``) and solves each one, paired in the same process, with

* ``order``:  IPOPT + MUMPS on the NLP as assembled, reordered by knot, randomly permuted, and with
  other MUMPS pivot orders (IPOPT's ``print_timing_statistics``; fill = MUMPS INFO(9));
* ``fatrop``: CasADi's ``fatrop`` nlpsol on the stage-wise form (state: three consecutive control
  points, control: the next one and the plane offsets of its knot), next to IPOPT on the original;
* ``sqp``:    CasADi's ``sqpmethod`` with ``qpsol='hpipm'`` (same stage-wise form) or another QP solver;
* ``csqp``:   mim-solvers' ``SolverCSQP`` on crocoddyl action models of the same stage-wise form.

Every result goes through ``SplineSegmentProblem.solve``'s own post-processing and
:func:`optplan.verification.verify`. Results: docs/optproblem.md, "Structure-exploiting solvers".

    python docs/studies/segment_solvers.py order  --cases "1:0,1:5,2:0,2:3,3:0,3:2"
    python docs/studies/segment_solvers.py fatrop --cases "1:0,1:5,2:0,2:3,3:0,3:2"
    python docs/studies/segment_solvers.py fatrop-toy
    python docs/studies/segment_solvers.py sqp    --cases 3:2 --only s3t2g3 --qpsol hpipm
    python docs/studies/segment_solvers.py csqp   --cases "1:0,1:5,2:0,2:3,3:0,3:2" --maxiter 10
"""
from __future__ import annotations

import argparse
import ctypes
import os
import re
import sys
import tempfile
import time

import casadi as ca
import numpy as np

from optplan.trials import TrialGenerator
from optplan.pipeline import PipelineOptions, shortcut_constrained
from optplan.planners import make_planner
from optplan.problem import ClosedChain
from optplan.problem.segment import SegmentSpec, SplineSegmentProblem
from optplan.model.robot import RobotModel
from optplan.scene import Scene
from optplan.verification import verify

robot = RobotModel.from_name("tcbirrt_dual_arm")
opts = PipelineOptions()


# ----------------------------------------------------------------------------- segments
def seg_paths(sc: int, tr: int):
    """The planned, shortcut segments of one benchmark trial (as the pipeline makes them)."""
    scene = Scene.load(f"ssps_scene{sc}")
    trial = TrialGenerator(robot, scene).generate(tr, 0)
    plan = make_planner(opts.planner, robot, scene, **dict(opts.planner_options)).plan(
        trial.q_start, trial.q_goal, time_limit=10, seed=int(trial.seed))
    rng = np.random.default_rng(int(trial.seed))
    segs = []
    for seg in plan.segments:
        p = np.asarray(plan.path[seg.start:seg.stop + 1])
        if len(p) < 2 or np.abs(p[-1] - p[0]).max() < 1e-9:
            continue
        kind = "constrained" if seg.kind == "constrained" else "regrasp"
        if kind == "constrained":
            p = shortcut_constrained(robot, scene, p, rng, opts.shortcut_attempts)
        segs.append((kind, seg.arm, p))
    return scene, segs


def problems(cases):
    """[(scene, trial)] -> [(label, problem, closed chain, scene)] for every constrained segment,
    on the pipeline's first grid, warm-started from the planner's path."""
    out = []
    for sc, tr in cases:
        scene, segs = seg_paths(sc, tr)
        arms = list(scene.object.grasps)
        for i, (kind, arm, p) in enumerate(segs):
            if kind != "constrained":
                continue
            length = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
            T = max(opts.min_duration, length / (opts.speed_fraction * float(np.min(robot.velocity_limit))))
            cc = ClosedChain.from_grasps(scene.object.grasps[arms[0]], scene.object.grasps[arms[1]], arms[0], arms[1])
            N = int(np.clip(np.ceil(length / opts.spline_interval_step), opts.spline_min_intervals,
                            opts.spline_max_intervals))
            spec = SegmentSpec(N, T, p[0], p[-1], cc, robot.lower.copy(), robot.upper.copy(), margin=opts.margin,
                               object_arm=arms[0])
            prob = SplineSegmentProblem(robot, scene, spec)
            prob.set_initial_path(p, cc)
            out.append((f"s{sc}t{tr}g{i}", prob, cc, scene))
    return out


def ipopt_opts():
    """The pipeline's IPOPT options."""
    ip = dict(opts.ipopt_options)
    ip["max_wall_time"] = 60.0
    return ip


def report(lab, prob, meth, sol, rep, cpu, extra=""):
    print(f"{lab} N={prob.N} {meth:10s} {sol.status.value:26s} it={sol.iterations:4d} cpu={cpu:.2f} "
          f"jerk={sol.cost:.5e} viol={sol.max_constraint_violation:.1e} res={rep.max_closed_chain_residual:.1e} "
          f"clr={rep.min_clearance_m:+.4f}{extra}", flush=True)


class Fixed:
    """Hands a finished result to ``SplineSegmentProblem.solve`` in place of its nlpsol, so the
    post-processing (violation, knot values, Solution) is the problem's own."""

    def __init__(self, x, f, status, iters):
        self.x, self.f, self.status, self.iters = x, f, status, iters

    def __call__(self, x0, p, lbx, ubx, lbg, ubg):
        return {"x": self.x, "lam_g": np.zeros(lbg.size), "f": ca.DM(self.f)}

    def stats(self):
        return {"return_status": self.status, "iter_count": self.iters}


# ----------------------------------------------------------------------------- 1. variable order
def knot_order(prob):
    """Variable permutation (new -> old): each plane offset right after the control point P_{k+1}
    of its knot k; rows sorted by their first (new) column, then their last."""
    b = prob._built
    N, nj, nP = prob.N, robot.nj, prob._nfree
    key = [((p + 3) * 10 + 0, p * nj + j) for p in range(N - 3) for j in range(nj)]  # point index p+3
    bi = 0
    for it in prob._plan:
        if it.static: continue
        for k in it.knots:
            key.append(((min(max(k + 1, 3), N - 1)) * 10 + 5, nP + bi)); bi += 1
    order = np.array([v for _, v in sorted(key, key=lambda t: (t[0], t[1]))])
    inv = np.empty_like(order); inv[order] = np.arange(len(order))
    Jsp = prob._derivs["jac_g"].sparsity_out(1)
    r, c = (np.asarray(a) for a in Jsp.get_triplet())
    newc = inv[c]
    ng = Jsp.size1()
    lo = np.full(ng, 1 << 30); hi = np.zeros(ng, int)
    np.minimum.at(lo, r, newc); np.maximum.at(hi, r, newc)
    rorder = np.lexsort((np.arange(ng), hi, lo))
    return order, rorder

def permuted(prob, order, rorder):
    nlp, d = prob._nlp, prob._derivs
    n = order.size
    inv = np.empty_like(order); inv[order] = np.arange(n)
    y = ca.MX.sym("y", n); p = nlp["p"]
    x_of_y = y[inv.tolist()]
    f = ca.Function("f", [nlp["x"], p], [nlp["f"]])(x_of_y, p)
    G, J = d["jac_g"](x_of_y, p)
    G, J = G[rorder.tolist()], J[rorder.tolist(), order.tolist()]
    lf, lg = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", rorder.size)
    rinv = np.empty_like(rorder); rinv[rorder] = np.arange(rorder.size)
    H = d["hess_lag"](x_of_y, p, lf, lg[rinv.tolist()])
    H = H + H.T - ca.diag(ca.diag(H))
    H = ca.triu(H[order.tolist(), order.tolist()])
    der = {"jac_g": ca.Function("jac_g", [y, p], [G, J], ["x", "p"], ["g", "jac_g_x"]),
           "hess_lag": ca.Function("hess_lag", [y, p, lf, lg], [H], ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])}
    return {"x": y, "p": p, "f": f, "g": G}, der

def make_solver(nlp, der, extra, tol=1e-6, max_iter=500):
    from optplan.solver_options import casadi_option_name
    opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.tol": tol,
            "ipopt.constr_viol_tol": tol, "ipopt.acceptable_constr_viol_tol": tol,
            "ipopt.mu_strategy": "adaptive", "ipopt.max_iter": int(max_iter),
            "ipopt.jacobian_regularization_value": 1e-6}
    for k, v in extra.items(): opts[casadi_option_name(k)] = v
    opts.update(der)
    opts.update({"no_nlp_grad": True, "calc_lam_x": False, "calc_lam_p": False, "calc_f": False, "calc_g": False})
    return ca.nlpsol("seg", "ipopt", nlp, opts)

class Wrapped:
    """Looks like the nlpsol prob.solve calls; maps the permuted solution back."""
    def __init__(self, solver, order, rorder):
        self.s, self.o, self.r = solver, order, rorder
        self.cpu = 0.0
    def __call__(self, x0, p, lbx, ubx, lbg, ubg):
        o, r = self.o, self.r
        c0 = time.process_time()
        out = self.s(x0=x0[o], p=p, lbx=lbx[o], ubx=ubx[o], lbg=lbg[r], ubg=ubg[r])
        self.cpu = time.process_time() - c0
        x = np.zeros(o.size); x[o] = np.array(out["x"]).ravel()
        lg = np.zeros(r.size); lg[r] = np.array(out["lam_g"]).ravel()
        return {"x": x, "lam_g": lg, "f": out["f"]}
    def stats(self): return self.s.stats()

def timing(fn):
    txt = open(fn).read() if os.path.exists(fn) else ""
    out = {}
    m = re.findall(r"INFO\(9\)\) = (\d+)", txt)
    out["fill"] = max(map(int, m)) if m else -1
    for key, lab in (("StdAugSystemSolverMultiSolve", "fact"), ("LinearSystemSymbolicFactorization", "symb"),
                     ("LinearSystemBackSolve", "back"), ("OverallAlgorithm", "total")):
        m = re.search(key + r"\.*:\s+([\d.]+)", txt)
        out[lab] = float(m.group(1)) if m else float("nan")
    m = re.search(r"Function Evaluations\.*:\s+([\d.]+)", txt)
    out["feval"] = float(m.group(1)) if m else float("nan")
    return out


# ----------------------------------------------------------------------------- 2. stage-wise form
def stagewise(prob):
    b = prob._built or prob._build()
    N, nj, h = prob.N, prob.robot.nj, prob.h
    T = N - 3
    Pc = prob._P(np.zeros((N - 3) * nj))  # fixed rows: 0..2 and N..N+2
    plan = prob._plan
    # plane data from the parameter vector (layout of _build)
    off = 6 * nj
    items = []
    bi = 0
    for it in plan:
        K = len(it.knots)
        Nrm = b.p[off:off + 3 * K].reshape(K, 3).T; off += 3 * K
        if it.static:
            s = b.p[off:off + K]; off += K; bidx = None
        else:
            s = None; bidx = list(range(bi, bi + K)); bi += K
        items.append((it, Nrm, s, bidx))
    nP = prob._nfree
    stage_of = lambda kk: min(kk - 1, T - 1)
    # b's per stage: list of (item, t index, global b index)
    bs = [[] for _ in range(T + 1)]
    for it, Nrm, s, bidx in items:
        if bidx is None: continue
        for t, kk in enumerate(it.knots):
            bs[stage_of(kk)].append(bidx[t])
    xs = [ca.MX.sym(f"x{k}", 0 if k == 0 else 3 * nj) for k in range(T + 1)]
    us = [ca.MX.sym(f"u{k}", (nj if k < T else 0) + len(bs[k])) for k in range(T + 1)]
    bpos = {}  # global b index -> (stage, position in u)
    for k in range(T + 1):
        for i, gb in enumerate(bs[k]):
            bpos[gb] = (k, (nj if k < T else 0) + i)

    def P(k, j):
        if j < 3 and (k == 0 or j < k): return ca.DM(Pc[j])
        if j >= N: return ca.DM(Pc[j])
        if k < T and j == k + 3: return us[k][:nj]
        return xs[k][(j - k) * nj:(j - k + 1) * nj]

    cc_fn = prob.kernels.closed_chain(prob.spec.closed_chain) if prob.spec.closed_chain is not None else None
    w, lbw, ubw, g, lbg, ubg = [], [], [], [], [], []
    nx, nu, ng = [], [], []
    f = 0
    scale = prob._scale
    for k in range(T + 1):
        w += [xs[k], us[k]]
        nx.append(xs[k].numel()); nu.append(us[k].numel())
        lbw += [np.full(xs[k].numel(), -np.inf)]; ubw += [np.full(xs[k].numel(), np.inf)]
        if k < T:
            lbw += [prob.lower, np.full(len(bs[k]), -np.inf)]; ubw += [prob.upper, np.full(len(bs[k]), np.inf)]
            g.append(xs[k + 1] if k + 1 <= T else None)
            g[-1] = xs[k + 1] - ca.vertcat(P(k, k + 1), P(k, k + 2), P(k, k + 3))
            lbg.append(np.zeros(3 * nj)); ubg.append(np.zeros(3 * nj))
        else:
            lbw += [np.full(len(bs[k]), -np.inf)]; ubw += [np.full(len(bs[k]), np.inf)]
        n0 = sum(e.numel() for e in g)
        # velocity points
        vb = prob.vlim * h
        vel = [k + 2] if k < T - 1 else ([N - 2, N - 1] if k == T - 1 else [])
        for i in vel:
            g.append(P(k, i + 1) - P(k, i)); lbg.append(-vb); ubg.append(vb)
        knots = [k + 1] if k < T - 1 else ([N - 3, N - 2, N - 1] if k == T - 1 else [])
        intervals = [k] if k < T - 1 else ([N - 4, N - 3, N - 2, N - 1] if k == T - 1 else [])
        for kk in knots:
            q = (P(k, kk) + 4 * P(k, kk + 1) + P(k, kk + 2)) / 6
            if cc_fn is not None:
                g.append(cc_fn(q, ca.DM.zeros(3), 0)); lbg.append(np.r_[np.zeros(6), 1.0]); ubg.append(np.r_[np.zeros(6), np.inf])
            for it, Nrm, s, bidx in items:
                if kk not in it.knots: continue
                t = it.knots.index(kk)
                mk = it.margins[t]
                if bidx is None:
                    g.append(it.fn(q, ca.DM(Nrm[:, t]), float(s[t]))); lbg.append(np.full(it.nrow, mk)); ubg.append(np.full(it.nrow, np.inf))
                else:
                    st, pos = bpos[bidx[t]]
                    g.append(it.fn(q, ca.DM(Nrm[:, t]), us[st][pos])); lbg.append(np.full(it.nrow, mk / 2)); ubg.append(np.full(it.nrow, np.inf))
        for ii in intervals:
            jk = -P(k, ii) + 3 * P(k, ii + 1) - 3 * P(k, ii + 2) + P(k, ii + 3)
            f = f + scale * ca.sumsqr(jk) / h**5
        ng.append(sum(e.numel() for e in g) - n0)
    nlp = {"x": ca.vertcat(*w), "f": f, "g": ca.vertcat(*g)}
    # map original x (free points, b's) -> stage-wise w, and back
    nw = nlp["x"].numel()
    idx_P = np.full((N + 3, nj), -1)  # position in w of (a copy of) P_j: the control u_{j-3}
    pos = 0
    wmap_src = np.full(nw, -1)  # source index in original x for each w entry (-1: constant)
    for k in range(T + 1):
        for r in range(nx[k] // nj):
            j = k + r
            if 3 <= j <= N - 1: wmap_src[pos + r * nj:pos + (r + 1) * nj] = (j - 3) * nj + np.arange(nj)
        pos += nx[k]
        if k < T:
            wmap_src[pos:pos + nj] = k * nj + np.arange(nj)  # P_{k+3}
        for i, gb in enumerate(bs[k]):
            wmap_src[pos + (nj if k < T else 0) + i] = nP + gb
        pos += nu[k]
    const = np.zeros(nw)  # constant state entries (P_1, P_2 in x_1, P_2 in x_2)
    pos = 0
    for k in range(T + 1):
        for r in range(nx[k] // nj):
            j = k + r
            if j < 3 or j >= N: const[pos + r * nj:pos + (r + 1) * nj] = Pc[j]
        pos += nx[k] + nu[k]
    # original index -> its position in w as a control (unique)
    back = np.full(nP + bi, -1)
    pos = 0
    for k in range(T + 1):
        pos += nx[k]
        if k < T: back[k * nj:(k + 1) * nj] = pos + np.arange(nj)
        for i, gb in enumerate(bs[k]):
            back[nP + gb] = pos + (nj if k < T else 0) + i
        pos += nu[k]
    assert (back >= 0).all()
    return dict(nlp=nlp, lbx=np.concatenate(lbw), ubx=np.concatenate(ubw), lbg=np.concatenate(lbg),
                ubg=np.concatenate(ubg), N=T, nx=nx, nu=nu, ng=ng, src=wmap_src, const=const, back=back)


def to_w(sw, x):
    w = sw["const"].copy()
    m = sw["src"] >= 0
    w[m] = x[sw["src"][m]]
    return w


class StageSolver:
    """Callable like the nlpsol SplineSegmentProblem.solve calls: original x in and out."""
    def __init__(self, solver, sw, ng_orig):
        self.s, self.sw, self.ng = solver, sw, ng_orig
        self.cpu = 0.0

    def __call__(self, x0, p, lbx, ubx, lbg, ubg):
        import time
        sw = self.sw
        c0 = time.process_time()
        out = self.s(x0=to_w(sw, x0), lbx=sw["lbx"], ubx=sw["ubx"], lbg=sw["lbg"], ubg=sw["ubg"])
        self.cpu = time.process_time() - c0
        wv = np.array(out["x"]).ravel()
        return {"x": wv[sw["back"]], "lam_g": np.zeros(self.ng), "f": out["f"]}

    def stats(self):
        return self.s.stats()

# ----------------------------------------------------------------------------- 3. mim-solvers CSQP
W = (1 / 6, 4 / 6, 1 / 6)


def stage_rows(prob):
    """Per stage k = 0..T-1: (nb, rows) with rows = [(kind, fn, jfn, slots, n, s_or_bslot, sign, lo, hi)];
    slots: 3 (source, offset|const) of the knot's control points; plus jerk intervals and velocity."""
    b = prob._built or prob._build()
    N, nj, h = prob.N, prob.robot.nj, prob.h
    T = N - 3
    Pc = prob._P(np.zeros((N - 3) * nj))
    off = 6 * nj; items = []; bi = 0
    for it in prob._plan:
        K = len(it.knots); Nrm = b.p[off:off + 3 * K].reshape(K, 3).T; off += 3 * K
        if it.static: s = b.p[off:off + K]; off += K; bidx = None
        else: s = None; bidx = list(range(bi, bi + K)); bi += K
        items.append((it, Nrm, s, bidx))
    stage_of = lambda kk: min(kk - 1, T - 1)
    bs = [[] for _ in range(T)]
    for it, Nrm, s, bidx in items:
        if bidx is None: continue
        for t, kk in enumerate(it.knots): bs[stage_of(kk)].append(bidx[t])
    bpos = {gb: (k, nj + i) for k in range(T) for i, gb in enumerate(bs[k])}

    def slot(k, j):
        if j >= N or (k == 0 and j < 3): return ("c", Pc[j])
        if j == k + 3: return ("u", 0)
        return ("x", (j - k) * nj)
    cc_fn = prob.kernels.closed_chain(prob.spec.closed_chain)
    cc_j, _ = prob.kernels.derivatives(cc_fn)
    stages = []
    for k in range(T):
        knots = [k + 1] if k < T - 1 else [N - 3, N - 2, N - 1]
        intervals = [k] if k < T - 1 else [N - 4, N - 3, N - 2, N - 1]
        vel = [k + 2] if k < T - 1 else [N - 2, N - 1]
        rows = []
        for kk in knots:
            sl = [slot(k, kk + a) for a in range(3)]
            rows.append((cc_fn, cc_j, sl, np.zeros(3), 0.0, None, np.r_[np.zeros(6), 1.0], np.r_[np.zeros(6), np.inf]))
            for it, Nrm, s, bidx in items:
                if kk not in it.knots: continue
                t = it.knots.index(kk); jf, _ = prob.kernels.derivatives(it.fn); mk = it.margins[t]
                if bidx is None:
                    rows.append((it.fn, jf, sl, Nrm[:, t], float(s[t]), None, np.full(it.nrow, mk), np.full(it.nrow, np.inf)))
                else:
                    st, pos = bpos[bidx[t]]; assert st == k
                    ma = it.a[1].shape[1]
                    sign = np.r_[np.ones(ma), -np.ones(it.nrow - ma)]
                    rows.append((it.fn, jf, sl, Nrm[:, t], pos, sign, np.full(it.nrow, mk / 2), np.full(it.nrow, np.inf)))
        jerk = [[slot(k, i + a) for a in range(4)] for i in intervals]
        velo = [(slot(k, i), slot(k, i + 1)) for i in vel]
        stages.append(dict(nb=len(bs[k]), rows=rows, jerk=jerk, vel=velo))
    return stages, bs, T


def _load_crocoddyl():
    """crocoddyl and mim_solvers, or (None, None). mim-solvers 0.3.0's wheel misses the run path of
    cmeel's libboost_atomic: preload it."""
    try:
        import crocoddyl
    except ImportError:
        return None, None
    for p in sys.path:
        lib = os.path.join(p, "cmeel.prefix", "lib", "libboost_atomic.so.1.90.0")
        if os.path.exists(lib):
            ctypes.CDLL(lib, mode=ctypes.RTLD_GLOBAL)
            break
    try:
        import mim_solvers
    except ImportError:
        return crocoddyl, None
    return crocoddyl, mim_solvers


crocoddyl, mim_solvers = _load_crocoddyl()

if crocoddyl is not None:
    class SplineStage(crocoddyl.ActionModelAbstract):
        def __init__(self, state, st, nj, h, scale, vlim, lower, upper):
            self.st, self.nj = st, nj
            nu = nj + st["nb"]
            self.ncon = sum(len(r[6]) for r in st["rows"]) + nj * len(st["vel"]) + nj
            crocoddyl.ActionModelAbstract.__init__(self, state, nu, 1, self.ncon, 0)
            lo = [r[6] for r in st["rows"]] + [-vlim * h] * len(st["vel"]) + [lower]
            hi = [r[7] for r in st["rows"]] + [vlim * h] * len(st["vel"]) + [upper]
            self.g_lb, self.g_ub = np.concatenate(lo), np.concatenate(hi)
            self.c = scale / h**5
            n = 3 * nj
            self.Fx = np.zeros((n, n)); self.Fx[:2 * nj, nj:] = np.eye(2 * nj)
            self.Fu = np.zeros((n, nu)); self.Fu[2 * nj:, :nj] = np.eye(nj)
            # jerk: constant quadratic form in z = (x, u): J_i = A_i z + c_i
            self.A, self.c0 = [], []
            for sl in st["jerk"]:
                A = np.zeros((nj, n + nu)); c = np.zeros(nj)
                for a, wgt in zip(sl, (-1.0, 3.0, -3.0, 1.0)):
                    self._acc(A, c, a, wgt, n)
                self.A.append(A); self.c0.append(c)
            self.V = []
            for s0, s1 in st["vel"]:
                A = np.zeros((nj, n + nu)); c = np.zeros(nj)
                self._acc(A, c, s1, 1.0, n); self._acc(A, c, s0, -1.0, n)
                self.V.append((A, c))
            self.H = sum(2 * self.c * A.T @ A for A in self.A)

        def _acc(self, A, c, s, w, n):
            kind, v = s
            if kind == "c": c += w * v
            elif kind == "x": A[:, v:v + self.nj] += w * np.eye(self.nj)
            else: A[:, n + v:n + v + self.nj] += w * np.eye(self.nj)

        def _P(self, s, x, u):
            kind, v = s
            return v if kind == "c" else (x[v:v + self.nj] if kind == "x" else u[v:v + self.nj])

        def _q(self, sl, x, u):
            return sum(w * self._P(s, x, u) for w, s in zip(W, sl))

        def calc(self, data, x, u=None):
            nj = self.nj
            if u is None: u = np.zeros(self.nu)
            data.xnext[:] = np.r_[x[nj:], u[:nj]]
            z = np.r_[x, u]
            data.cost = self.c * sum(float(np.sum((A @ z + c) ** 2)) for A, c in zip(self.A, self.c0))
            g = []
            for fn, jf, sl, n, s, sign, lo, hi in self.st["rows"]:
                sv = u[s] if sign is not None else s
                g.append(np.asarray(fn(self._q(sl, x, u), n, sv)).ravel())
            for A, c in self.V: g.append(A @ z + c)
            g.append(u[:nj])
            data.g[:] = np.concatenate(g)

        def calcDiff(self, data, x, u=None):
            nj, n = self.nj, 3 * self.nj
            if u is None: u = np.zeros(self.nu)
            z = np.r_[x, u]
            grad = sum(2 * self.c * A.T @ (A @ z + c) for A, c in zip(self.A, self.c0))
            data.Lx[:] = grad[:n]; data.Lu[:] = grad[n:]
            data.Lxx[:, :] = self.H[:n, :n]; data.Lxu[:, :] = self.H[:n, n:]; data.Luu[:, :] = self.H[n:, n:]
            data.Fx[:, :] = self.Fx; data.Fu[:, :] = self.Fu
            G = np.zeros((self.ncon, n + self.nu)); r = 0
            for fn, jf, sl, nv, s, sign, lo, hi in self.st["rows"]:
                sv = u[s] if sign is not None else s
                J = np.asarray(jf(self._q(sl, x, u), nv, sv)); m = J.shape[0]
                for w, sdesc in zip(W, sl):
                    kind, v = sdesc
                    if kind == "x": G[r:r + m, v:v + nj] += w * J
                    elif kind == "u": G[r:r + m, n + v:n + v + nj] += w * J
                if sign is not None: G[r:r + m, n + s] += sign
                r += m
            for A, c in self.V: G[r:r + nj] = A; r += nj
            G[r:r + nj, n:n + nj] = np.eye(nj)
            data.Gx[:, :] = G[:, :n]; data.Gu[:, :] = G[:, n:]

        def createData(self):
            return crocoddyl.ActionDataAbstract(self)


    class Terminal(crocoddyl.ActionModelAbstract):
        def __init__(self, state):
            crocoddyl.ActionModelAbstract.__init__(self, state, 0, 1, 0, 0)
        def calc(self, data, x, u=None):
            data.cost = 0.0
        def calcDiff(self, data, x, u=None):
            pass
        def createData(self):
            return crocoddyl.ActionDataAbstract(self)


def solve_csqp(prob, maxiter=200, tol=1e-6):
    """Returns (x in the original NLP's variables, iterations, converged, cpu)."""
    nj = prob.robot.nj
    stages, bs, T = stage_rows(prob)
    state = crocoddyl.StateVector(3 * nj)
    models = [SplineStage(state, st, nj, prob.h, prob._scale, prob.vlim, prob.lower, prob.upper) for st in stages]
    x0 = np.tile(prob.q0, 3)
    problem = crocoddyl.ShootingProblem(x0, models, Terminal(state))
    S = mim_solvers.SolverCSQP(problem)
    S.termination_tolerance = tol
    S.eps_abs = float(os.environ.get("EPS", "1e-4")); S.eps_rel = float(os.environ.get("EPSR", "1e-4")); S.max_qp_iters = int(os.environ.get("QPIT", "1000"))
    S.with_callbacks = False
    P = prob._P(prob._X0.ravel())
    nP = prob._nfree
    xb = prob._xb0
    us = [np.r_[P[k + 3], xb[bs[k]]] if bs[k] else P[k + 3].copy() for k in range(T)]
    xs = [np.r_[P[k], P[k + 1], P[k + 2]] for k in range(T + 1)]
    c0 = time.process_time()
    S._keep = (xs, us)
    ok = S.solve(xs, us, maxiter, False)
    cpu = time.process_time() - c0
    US = [np.array(v, copy=True) for v in S.us]
    X = np.array([US[k][:nj] for k in range(T)])
    bvec = np.zeros(xb.size)
    for k in range(T):
        for i, gb in enumerate(bs[k]): bvec[gb] = US[k][nj + i]
    return np.r_[X.ravel(), bvec], S.iter, bool(ok), cpu, S




# ----------------------------------------------------------------------------- runners
def run_order(cases, variants):
    for lab, prob, cc, scene in problems(cases):
        prob._build()
        n, ng = prob._nlp["x"].numel(), prob._nlp["g"].numel()
        ko, kr = knot_order(prob)
        rng = np.random.default_rng(0)
        for var in variants:
            name, _, piv = var.partition("@")
            o, r = {"asm": (np.arange(n), np.arange(ng)), "knot": (ko, kr)}.get(name) or (rng.permutation(n), rng.permutation(ng))
            nlp, der = permuted(prob, o, r)
            fn = os.path.join(tempfile.gettempdir(), f"segment_solvers_ipopt_{os.getpid()}.txt")
            ex = ipopt_opts()
            ex.update({"print_timing_statistics": "yes", "output_file": fn, "file_print_level": 6})
            if piv:
                ex["mumps_pivot_order"] = int(piv)
            if os.path.exists(fn):
                os.remove(fn)
            w = Wrapped(make_solver(nlp, der, ex), o, r)
            prob._built.solver = w
            sol = prob.solve()
            rep = verify(robot, sol, scene, closed_chain=cc)
            tm = timing(fn)
            report(lab, prob, var, sol, rep, w.cpu, f" n={n} m={ng} kkt={tm['fact']:.3f} fill={tm['fill']} "
                   f"symb={tm['symb']:.3f} back={tm['back']:.3f} feval={tm['feval']:.3f}")


def _band(sw, band):
    """Closed-chain equalities as ``|r| ≤ band`` (Fatrop 1.1.8 stalls at its first iteration on
    nonlinear path equalities; gap-closing rows stay equalities)."""
    eq = sw["lbg"] == sw["ubg"]
    gap = np.zeros(eq.size, bool)
    o = 0
    for k in range(sw["N"]):
        gap[o:o + sw["nx"][k + 1]] = True
        o += sw["nx"][k + 1] + sw["ng"][k]
    m = eq & ~gap
    out = dict(sw)
    out["lbg"], out["ubg"] = sw["lbg"] - band * m, sw["ubg"] + band * m
    return out


def run_fatrop(cases, band, with_ipopt=True):
    for lab, prob, cc, scene in problems(cases):
        b = prob._build()
        if with_ipopt:
            c0 = time.process_time()
            sol = prob.solve(ipopt_opts())
            cpu = time.process_time() - c0
            report(lab, prob, "ipopt", sol, verify(robot, sol, scene, closed_chain=cc), cpu)
        sw = stagewise(prob)
        t0 = time.perf_counter()
        S = ca.nlpsol("fatrop", "fatrop", sw["nlp"], {
            "structure_detection": "manual", "N": sw["N"], "nx": sw["nx"], "nu": sw["nu"], "ng": sw["ng"],
            "print_time": False, "fatrop": {"print_level": 0, "tol": 1e-6, "max_iter": 500}})
        setup = time.perf_counter() - t0
        swb = _band(sw, band) if band > 0 else sw
        x0 = np.r_[prob._X0.ravel(), prob._xb0]
        c0 = time.process_time()
        out = S(x0=to_w(sw, x0), lbx=swb["lbx"], ubx=swb["ubx"], lbg=swb["lbg"], ubg=swb["ubg"])
        cpu = time.process_time() - c0
        fs = S.stats()["fatrop"]
        wv = np.array(out["x"]).ravel()
        status = "Solve_Succeeded" if fs["return_flag"] == 0 else "Maximum_Iterations_Exceeded"
        b.solver = Fixed(wv[sw["back"]], float(out["f"]), status, int(fs["iterations_count"]))
        sol = prob.solve()
        report(lab, prob, "fatrop", sol, verify(robot, sol, scene, closed_chain=cc), cpu,
               f" flag={fs['return_flag']} setup={setup:.2f} wall:sd={fs['compute_sd_time']:.2f} "
               f"hess={fs['eval_hess_time']:.2f} jac={fs['eval_jac_time']:.2f} total={fs['time_total']:.2f}")


def run_fatrop_toy(equality: bool, timeout: float = 60.0):
    """Fatrop on a 2-joint shift system (the stage-wise B-spline form in miniature) with the path
    constraint ``‖q_k‖² = 1`` (``equality``) or ``≤ 1`` at every stage; run in a child process so a
    stall ends at ``timeout`` [s]."""
    import multiprocessing as mp

    def work(q):
        N, nj = 20, 2
        xs = [ca.MX.sym(f"x{k}", 3 * nj) for k in range(N + 1)]
        us = [ca.MX.sym(f"u{k}", nj if k < N else 0) for k in range(N + 1)]
        w, g, lbg, ubg, nx, nu, ng, f = [], [], [], [], [], [], [], 0
        for k in range(N + 1):
            w += [xs[k], us[k]]
            nx.append(3 * nj)
            nu.append(us[k].numel())
            P = [xs[k][i * nj:(i + 1) * nj] for i in range(3)] + ([us[k]] if k < N else [])
            n0 = sum(e.numel() for e in g)
            if k < N:
                g.append(xs[k + 1] - ca.vertcat(P[1], P[2], P[3]))
                lbg += [0.0] * 6
                ubg += [0.0] * 6
                n0 += 6
                f += ca.sumsqr(-P[0] + 3 * P[1] - 3 * P[2] + P[3])
                qk = (P[1] + 4 * P[2] + P[3]) / 6
                g.append(ca.sumsqr(qk) - 1)
                lbg.append(0.0 if equality else -np.inf)
                ubg.append(0.0)
            else:
                g.append((P[0] + 4 * P[1] + P[2]) / 6 - ca.DM([0.0, 1.0]))
                lbg += [0.0, 0.0]
                ubg += [0.0, 0.0]
            if k == 0:
                g.append(xs[0] - ca.DM(np.tile([1.0, 0.0], 3)))
                lbg += [0.0] * 6
                ubg += [0.0] * 6
            ng.append(sum(e.numel() for e in g) - n0)
        S = ca.nlpsol("toy", "fatrop", {"x": ca.vertcat(*w), "f": f, "g": ca.vertcat(*g)},
                      {"structure_detection": "manual", "N": N, "nx": nx, "nu": nu, "ng": ng,
                       "print_time": False, "fatrop": {"print_level": 0, "max_iter": 100}})
        S(x0=0.1, lbg=lbg, ubg=ubg)
        st = S.stats()["fatrop"]
        q.put((st["return_flag"], st["iterations_count"]))

    q = mp.get_context("fork").Queue()
    p = mp.get_context("fork").Process(target=work, args=(q,))
    p.start()
    p.join(timeout)
    kind = "= 1" if equality else "≤ 1"
    if p.is_alive():
        p.terminate()
        print(f"toy, ‖q‖² {kind}: no result after {timeout:.0f} s (stalled)")
    else:
        flag, it = q.get()
        print(f"toy, ‖q‖² {kind}: return flag {flag}, {it} iterations")


def run_sqp(cases, qpsol, convexify, max_iter):
    for lab, prob, cc, scene in problems(cases):
        b = prob._build()
        sw = stagewise(prob)
        qo = {"N": sw["N"], "nx": sw["nx"], "nu": sw["nu"], "ng": sw["ng"]} if qpsol == "hpipm" else {}
        if qpsol == "qrqp":
            qo = {"print_iter": False, "print_header": False}
        S = ca.nlpsol("sqp", "sqpmethod", sw["nlp"], {
            "qpsol": qpsol, "qpsol_options": qo, "print_time": False, "print_iteration": False,
            "print_header": False, "max_iter": max_iter, "tol_pr": 1e-6, "tol_du": 1e-6,
            "convexify_strategy": convexify, "error_on_fail": False})
        x0 = np.r_[prob._X0.ravel(), prob._xb0]
        c0 = time.process_time()
        out = S(x0=to_w(sw, x0), lbx=sw["lbx"], ubx=sw["ubx"], lbg=sw["lbg"], ubg=sw["ubg"])
        cpu = time.process_time() - c0
        st = S.stats()
        wv = np.array(out["x"]).ravel()
        status = "Solve_Succeeded" if st.get("success") else "Maximum_Iterations_Exceeded"
        b.solver = Fixed(wv[sw["back"]], float(out["f"]), status, int(st["iter_count"]))
        sol = prob.solve()
        report(lab, prob, f"sqp/{qpsol}", sol, verify(robot, sol, scene, closed_chain=cc), cpu,
               f" ({st['return_status']})")


def run_csqp(cases, maxiter):
    if mim_solvers is None:
        sys.exit("csqp: needs `pip install mim-solvers crocoddyl`")
    for lab, prob, cc, scene in problems(cases):
        b = prob._build()
        x, it, ok, cpu, S = solve_csqp(prob, maxiter)
        b.solver = Fixed(x, float(S.cost), "Solve_Succeeded" if ok else "Maximum_Iterations_Exceeded", it)
        sol = prob.solve()
        report(lab, prob, "csqp", sol, verify(robot, sol, scene, closed_chain=cc), cpu,
               f" KKT={S.KKT:.1e} constraint_norm={S.constraint_norm:.1e}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study", choices=["order", "fatrop", "fatrop-toy", "sqp", "csqp"])
    ap.add_argument("--cases", default="1:0,1:5,2:0,2:3,3:0,3:2", help="scene:trial,…")
    ap.add_argument("--variants", default="asm,knot,rand,asm@0,asm@4,asm@5,asm@6",
                    help="order: asm|knot|rand[@mumps_pivot_order],…")
    ap.add_argument("--band", type=float, default=1e-7, help="fatrop: closed-chain rows as |r| ≤ band (0: equalities)")
    ap.add_argument("--qpsol", default="hpipm")
    ap.add_argument("--convexify", default="regularize")
    ap.add_argument("--maxiter", type=int, default=100)
    ap.add_argument("--only", default="", help="comma-separated segment labels to keep (e.g. s3t2g3)")
    a = ap.parse_args(argv)
    cases = [tuple(int(v) for v in c.split(":")) for c in a.cases.split(",")]
    if a.only:
        keep = set(a.only.split(","))
        global problems
        _all = problems
        problems = lambda cs: [t for t in _all(cs) if t[0] in keep]  # noqa: E731
    if a.study == "order":
        run_order(cases, a.variants.split(","))
    elif a.study == "fatrop-toy":
        run_fatrop_toy(False)
        run_fatrop_toy(True)
    elif a.study == "fatrop":
        run_fatrop(cases, a.band)
    elif a.study == "sqp":
        run_sqp(cases, a.qpsol, a.convexify, a.maxiter)
    else:
        run_csqp(cases, a.maxiter)


if __name__ == "__main__":
    main()
