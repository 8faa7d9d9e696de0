"""The C source of TCBiRRT's look-ahead graft loop (:mod:`optplan.planners.tcbirrt_lookahead`).

It is appended to the extension library's source after the streaks' (:mod:`.streak_csource`), whose NumPy PCG64
mirror it draws with. ``tcb_lookahead`` runs the candidate loop of
:func:`optplan.planners.frontier_graft.lookahead_graft`, step for step: a seed drawn as ``Generator.uniform(lower,
upper)`` draws it (``lower + (upper − lower) u``, ``u`` the 53-bit double of the next 64-bit output), the extension's
IK at the node's object pose (``tcb_ik``: the hand-written one, as the path IK's; the compiled CasADi block before
2026-11-30), then per candidate (one arm re-grasped, each arm in turn,
then both) the twin test, the joint limits, the collision check and the look-ahead — the path IK of the look-ahead
poses (restarts in C) and its edges. It returns at the first candidate that passes, for the regrasp (in Python), and
goes on from the next candidate when called again.
"""
from __future__ import annotations

__all__ = ["LOOKAHEAD_SOURCE"]

LOOKAHEAD_SOURCE = r"""
typedef struct {
    const double *lower, *range;   /* the seeds: lower + range u per joint (range = upper - lower, as NumPy computes it) */
    const double *lim_lo, *lim_hi; /* a candidate's joint limits (the checker's in_limits bounds) */
    const double *node;            /* the node's object pose: rotation row-major, position (12) */
    const double *q_i;             /* the node's configuration */
    const double *twins; long long ntw;   /* ntw x nq: the configurations of the node's pose (a candidate within
                                             step of one, in every joint, is skipped) */
    const unsigned char *arm; int narm;   /* narm x nq: 1 where a joint is the arm's */
    double step;
    const double *P; long long n;  /* the look-ahead's poses (n x 12) */
    long long nseeds;
    int clock_kind; double end;    /* the deadline, tested before each seed (but a first one the caller has tested) */
    int checked;                   /* the caller has just tested the deadline (reset here at the first seed) */
    int stop;                      /* the caller's work budget is spent: no new seed */
    tcb_pcg pcg;                   /* the search Generator's state (in: its state; out: advanced) */
    /* state, kept between calls: the next seed; the next candidate of the current seed (narm + 1: none left); its IK */
    long long seed_k; int cand; double x[KMAXJ];
    /* out */
    double y[KMAXJ];               /* code 1: the candidate that passed */
    long long its, failures;       /* IK block iterations; candidates whose look-ahead failed */
} tcb_la_args;

#if TCB_HAVE_PCG
static double tcb_pcg_double(tcb_pcg *g) {   /* NumPy's pcg64_next_double (the 32-bit buffer untouched) */
    g->used = 1;
    return (double)(tcb_pcg_next64(g) >> 11) * (1.0 / 9007199254740992.0);
}
#endif

/* for the tests: Generator.uniform(lower, lower + range) of nq values into out, the state advanced in g */
int tcb_pcg_uniform(tcb_pcg *g, const double *lower, const double *range, int nq, double *out) {
#if TCB_HAVE_PCG
    for (int k = 0; k < nq; ++k) out[k] = lower[k] + range[k]*tcb_pcg_double(g);
    return 0;
#else
    (void)g; (void)lower; (void)range; (void)nq; (void)out;
    return -1;
#endif
}

/* 1: a candidate passed (a->y; the look-ahead's configurations in Q); 0: no seed left; 2: the deadline;
   -1: no PCG64 mirror on this compiler; -2: the model is too large */
int tcb_lookahead(const tcb_ctx *c, tcb_la_args *a, double *Q, long long *cnt) {
    int nq = c->nq;
    if (!TCB_HAVE_PCG) return -1;
    if (nq > KMAXJ || c->km->nj > KMAXJ || c->km->ng > KMAXG) return -2;
#if TCB_HAVE_PCG
    for (;;) {
        if (a->cand > a->narm) {
            if (a->seed_k >= a->nseeds) return 0;
            if (!a->checked && (a->stop || tcb_clock(a->clock_kind) >= a->end)) return 2;
            a->checked = 0;
            a->seed_k += 1;
            double seed[KMAXJ];
            for (int k = 0; k < nq; ++k) seed[k] = a->lower[k] + a->range[k]*tcb_pcg_double(&a->pcg);
            long long its = 0;
            int ok = tcb_ik(c, seed, a->node, a->x, &its);
            a->its += its;
            if (ok < 0) return -2;
            if (!ok) continue;
            a->cand = 0;
        }
        int j = a->cand++;
        double *y = a->y;
        for (int k = 0; k < nq; ++k) y[k] = (j == a->narm || a->arm[(long long)j*nq + k]) ? a->x[k] : a->q_i[k];
        int same = 0;
        for (long long t = 0; t < a->ntw && !same; ++t) {
            double m = 0.0;
            for (int k = 0; k < nq; ++k) { double d = fabs(y[k] - a->twins[t*nq + k]); if (d > m) m = d; }
            same = m <= a->step;
        }
        if (same) continue;
        int inside = 1;
        for (int k = 0; k < nq; ++k) if (!(y[k] >= a->lim_lo[k]) || !(y[k] <= a->lim_hi[k])) inside = 0;
        if (!inside) continue;
        cnt[5] += 1;
        if (tcb_collides(c, y)) continue;
        long long r = tcb_path_ik(c, y, NULL, a->P, 0, a->n, Q, cnt);
        if (r < -1) return -2;
        if (r == a->n && c->edge_on) {
            long long e = tcb_edges(c, y, Q, a->n, cnt);
            if (e < -1) return -2;
            if (e < a->n) r = e;
        }
        if (r < a->n) { a->failures += 1; continue; }
        return 1;
    }
#endif
}
"""
