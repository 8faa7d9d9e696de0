"""The C source of TCBiRRT's native extension step and nearest-neighbour scan
(:mod:`optplan.planners.kernel.extend`).

It is appended to the planning kernel's own source (:data:`~optplan.planners.kernel.csource.C_SOURCE`:
forward kinematics and the primitive collision tests) and compiled into a library of its own, so the
collision checks of an extension run without leaving C. The closed-chain IK is not generated again:
the caller passes the address of the compiled CasADi function that
:class:`~optplan.constraints.closed_chain.ClosedChainKinematics` already uses (and of the edge speed
profile of :meth:`~optplan.planners.validity.ValidityChecker.edge_checkpoints`), with their work
buffers, and this code calls them through the CasADi calling convention.

What one extension computes (the same steps, in the same order, as the Python code of
:meth:`optplan.planners.tcbirrt.TCBiRRT.path_ik`):

* ``tcb_interpolate``: the object poses ``j = 1..n`` from ``(R0, p0)`` to ``(R1, p1)``, position
  linear, orientation ``R0 exp(j/n log(R0ᵀ R1))`` (the geodesic interpolation of Eq. 4), the last pose
  exactly ``(R1, p1)``;
* ``tcb_path_ik``: per pose the damped-least-squares IK of both hands seeded by the previous solution, or
  with ``predictor`` by the secant prediction from the two previous solutions (the hand-written IK of
  :mod:`~optplan.planners.kernel.ik_csource` when the context has one, else the compiled CasADi block of
  iterations, repeated until converged or out of iterations), the joint-jump
  bound and the configuration's collision check; it stops at the first waypoint that fails, so the
  caller can run its random restarts there;
* ``tcb_edges``: the joint-space segments between consecutive configurations checked at the spacing of
  ``edge_checkpoints`` (the compiled speed profile, or the configuration-free bound), in bisection order;
* ``tcb_nearest`` / ``tcb_nearest_kd``: the first live row of ``X`` with the least squared Euclidean distance to
  ``x``, by the scan or the k-d index (:mod:`.nearest_csource`, held in place here);
* ``tcb_filter_xi`` / ``tcb_filter_segment``: the task-space filter of
  :class:`~optplan.planners.task_sampling.ObjectPoseFilter` (each grasp point within its arm's reach
  bound, then the object free of the obstacles) at one pose ξ = (position, roll, pitch, yaw), or at the
  points of a straight ξ segment in the order of :func:`~optplan.planners.rrtconnect.edge_is_valid`.
"""
from __future__ import annotations

from .nearest_csource import NEAREST_SOURCE

__all__ = ["EXTEND_SOURCE"]

EXTEND_SOURCE = r"""
#include <stdlib.h>

typedef int (*tcb_cfun)(const double **arg, double **res, long long *iw, double *w, int mem);

typedef struct {
    const kmodel *km;
    const unsigned char *active;   /* the checker's "held" mask (live: a regrasp exemption shows) */
    int nq;
    tcb_cfun ik; long long *ik_iw; double *ik_w;        /* occ_ik_block: (q, vec(R) col-major, p, par) -> q, 4 errors, its */
    double damping, tol_p, tol_o, gain, max_step; int max_it;
    double max_joint_step;
    int edge_on; double edge_tol;
    const double *W; int nw;                              /* nw x nq sweep weights (row-major) */
    tcb_cfun prof; long long *prof_iw; double *prof_w; int nprof;   /* (a, b) -> nprof cumulative bounds; NULL: none */
    double edge_res;              /* > 0: each new waypoint's segment from the previous one checked every edge_res
                                     rad of its largest joint change (rrtconnect.edge_is_valid), no restarts after */
    tcb_rng *rng;                 /* non-NULL: a failing waypoint's random restarts run here, drawn from it */
    int restarts; double restart_sigma;
    const double *lower, *upper;  /* joint limits of a restart's solution */
    const tcb_ikm *ikm;           /* non-NULL: the hand-written IK (ik_csource) instead of the CasADi block */
    int predictor;                /* a waypoint's IK seed: 0 the previous solution, 1 the secant prediction */
    const double *qlo, *qhi;      /* joint limits of the IK (a predicted seed is clamped to them) */
    const unsigned char *pfix;    /* per pair of km, may be NULL: 1 when both its geometries are placed by the waypoint's
                                     object pose alone (static, or on a hand's last link), so that every IK solution
                                     of that pose has the pair in the same contact */
    int restart_max_it;           /* > 0: a restart's IK iteration limit (else max_it) */
    int restart_clip;             /* a restart's seed offset clipped to +-max_joint_step per joint: 0 never, 1 always,
                                     2 in the first restart only */
    /* the pose test before a waypoint's IK (tcb_pose_blocked); npfl 0: none */
    int npfl;                     /* the pose-fixed pairs (pfix) with a moving geometry: their indices pfl[0..npfl) */
    const int *pfl;
    int npfg;                     /* the moving geometries of those pairs: pfg[i] on arm pfa[i]'s hand joint */
    const int *pfg, *pfa;
    const double *pfT;            /* 2 x 12: arm a's hand joint at the object pose P is P pfT[a] (grasp_a eeplace_a^-1) */
} tcb_ctx;

/* counters: 0 ik_calls, 1 ik_iterations, 2 ik_failures, 3 ik_jumps, 4 collisions, 5 checks, 6 edge_checks,
   7 edge_collisions, 8 set to 1 when the failing waypoint failed its edge_res segment (no restarts),
   9 ik_restarts, 10 ik_path_iterations (the iterations of the waypoints' first IK, restarts not counted),
   11 ik_restarts_skipped (restarts of a waypoint whose pose alone collides: drawn, not run), 12 ik_restart_iterations
   (the restarts' IK iterations), 13 pose_blocked (waypoints whose pose alone collides, found before their IK) */

""" + NEAREST_SOURCE + r"""static void tcb_log3(const double *R, double *w) {
    double v[3] = {0.5*(R[7]-R[5]), 0.5*(R[2]-R[6]), 0.5*(R[3]-R[1])};
    double s = sqrt(dot3(v, v)), c = 0.5*(R[0] + R[4] + R[8] - 1.0);
    if (c > 1.0) c = 1.0;
    if (c < -1.0) c = -1.0;
    double th = atan2(s, c);
    if (s < 1e-12 && c > 0) { w[0] = w[1] = w[2] = 0.0; return; }
    if (c > -0.9) { double f = th / s; w[0] = v[0]*f; w[1] = v[1]*f; w[2] = v[2]*f; return; }
    double B[9];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            B[3*i+j] = (0.5*(R[3*i+j] + R[3*j+i]) - (i == j ? c : 0.0)) / (1.0 - c);
    int k = 0;
    if (B[4] > B[0]) k = 1;
    if (B[8] > B[4*k]) k = 2;
    double nk = sqrt(B[4*k] > 1e-300 ? B[4*k] : 1e-300);
    double u[3] = {B[k]/nk, B[3+k]/nk, B[6+k]/nk};
    if (dot3(u, v) < 0) { u[0] = -u[0]; u[1] = -u[1]; u[2] = -u[2]; }
    w[0] = u[0]*th; w[1] = u[1]*th; w[2] = u[2]*th;
}

static void tcb_exp3(const double *w, double *E) {
    double t2 = dot3(w, w), t = sqrt(t2), a, b, c;
    if (t < 1e-4) { a = 1.0 - t2/6.0; b = 0.5 - t2/24.0; c = 1.0 - 0.5*t2; }
    else { a = sin(t)/t; b = (1.0 - cos(t))/t2; c = cos(t); }
    E[0] = c + b*w[0]*w[0];      E[1] = b*w[0]*w[1] - a*w[2]; E[2] = b*w[0]*w[2] + a*w[1];
    E[3] = b*w[0]*w[1] + a*w[2]; E[4] = c + b*w[1]*w[1];      E[5] = b*w[1]*w[2] - a*w[0];
    E[6] = b*w[0]*w[2] - a*w[1]; E[7] = b*w[1]*w[2] + a*w[0]; E[8] = c + b*w[2]*w[2];
}

/* poses j = 1..n (n x 12: R row-major, p) */
void tcb_interpolate(const double *R0, const double *p0, const double *R1, const double *p1, int n, double *out) {
    double Rr[9], w[3];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            Rr[3*i+j] = R0[i]*R1[j] + R0[3+i]*R1[3+j] + R0[6+i]*R1[6+j];   /* R0^T R1 */
    tcb_log3(Rr, w);
    for (int j = 1; j <= n; ++j) {
        double *P = out + 12*(j-1);
        if (j == n) { memcpy(P, R1, 9*sizeof(double)); memcpy(P + 9, p1, 3*sizeof(double)); break; }
        double s = (double)j / (double)n, ws[3] = {s*w[0], s*w[1], s*w[2]}, E[9];
        tcb_exp3(ws, E);
        for (int a = 0; a < 3; ++a) {
            for (int b = 0; b < 3; ++b) P[3*a+b] = R0[3*a]*E[b] + R0[3*a+1]*E[3+b] + R0[3*a+2]*E[6+b];
            P[9+a] = p0[a] + s*(p1[a] - p0[a]);
        }
    }
}

/* ClosedChainKinematics.ik: 1 when converged (q in qout), its = iterations used */
static int tcb_ik(const tcb_ctx *c, const double *seed, const double *P, double *qout, long long *its) {
    int nq = c->nq;
    if (c->ikm)
        return tik_solve(c->ikm, nq, seed, P, c->damping, c->tol_p, c->tol_o, c->gain, c->max_step, c->max_it, qout, its);
    double Rf[9], par[6], out[KMAXJ + 8], qin[KMAXJ];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) Rf[3*j+i] = P[3*i+j];
    par[0] = c->damping; par[1] = c->tol_p; par[2] = c->tol_o; par[3] = c->gain; par[4] = c->max_step;
    memcpy(qin, seed, nq*sizeof(double));
    const double *arg[64] = {qin, Rf, P + 9, par};
    double *res[64] = {out};
    long long n = 0;
    for (;;) {
        par[5] = (double)(c->max_it - n);
        if (c->ik(arg, res, c->ik_iw, c->ik_w, 0) != 0) { *its = n; return 0; }
        memcpy(qin, out, nq*sizeof(double));
        n += (long long)out[nq + 4];
        if (out[nq] < c->tol_p && out[nq+1] < c->tol_o && out[nq+2] < c->tol_p && out[nq+3] < c->tol_o) {
            memcpy(qout, out, nq*sizeof(double)); *its = n; return 1;
        }
        if (n >= c->max_it) { *its = n; return 0; }
    }
}

static int tcb_collides(const tcb_ctx *c, const double *q) {
    double oMi[12*KMAXJ], oMg[12*KMAXG];
    return config_collides(c->km, c->active, q, NULL, -1, oMi, oMg);
}

/* after tcb_collides returned 1: whether the pair that collided (the broad phase's hint) is one the waypoint's pose
   alone places (c->pfix), so that no restart toward the same pose can pass */
static int tcb_pose_collision(const tcb_ctx *c) {
    const kmodel *m = c->km;
    if (!c->pfix || !m->hint || m->ngrp <= 0 || m->nstat > 4096) return 0;
    int h = *m->hint;
    return h >= 0 && h < m->npairs && c->pfix[h];
}

/* 1 when a pair that the object pose P alone places (c->pfl: a static geometry, the held object, a hand's last link)
   is in contact at P. Every IK solution of P has its hands at P's grasps (to the IK's tolerance), hence those
   geometries where this test puts them: the waypoint fails whatever its IK does, and so does every restart. */
static int tcb_pose_blocked(const tcb_ctx *c, const double *P) {
    const kmodel *m = c->km;
    if (c->npfl <= 0 || c->npfg > 8 || m->ng > KMAXG) return 0;
    double J[24], O[12*8];
    const double *pose[KMAXG];
    compose(P, c->pfT, J);
    compose(P, c->pfT + 12, J + 12);
    for (int i = 0; i < c->npfg; ++i) {
        int g = c->pfg[i];
        compose(J + 12*c->pfa[i], m->gplace + 12*g, O + 12*i);
        pose[g] = O + 12*i;
    }
    for (int i = 0; i < c->npfl; ++i) {
        int k = c->pfl[i], ga = m->pa[k], gb = m->pb[k];
        if (!c->active[k]) continue;
        if (m->gparent[ga] == 0) pose[ga] = m->gplace + 12*ga;
        if (m->gparent[gb] == 0) pose[gb] = m->gplace + 12*gb;
        if (pair_collides(m, pose, ga, gb)) return 1;
    }
    return 0;
}

/* for the tests: tcb_pose_blocked at the object pose P (12: R row-major, p) */
int tcb_pose_blocked_api(const tcb_ctx *c, const double *P) {
    return tcb_pose_blocked(c, P);
}

/* the extension's own IK (the hand-written one when c->ikm is set, else the compiled CasADi block): 1 when converged */
int tcb_ik_api(const tcb_ctx *c, const double *seed, const double *P, double *qout, long long *its) {
    if (c->nq > KMAXJ) return -2;
    return tcb_ik(c, seed, P, qout, its);
}

/* ClosedChainKinematics.ik itself (the compiled CasADi block, never the hand-written IK): 1 when converged */
int tcb_ik_block(const tcb_ctx *c, const double *seed, const double *P, double *qout, long long *its) {
    if (c->nq > KMAXJ) return -2;
    tcb_ctx d = *c;
    d.ikm = NULL;
    return tcb_ik(&d, seed, P, qout, its);
}

/* the edge_res segment q -> qn (midpoints in bisection order): 1 free, 0 colliding, -2 out of memory */
static int tcb_segment_ok(const tcb_ctx *c, const double *q, const double *qn, long long *cnt) {
    int nq = c->nq;
    double d[KMAXJ], size = 0.0, x[KMAXJ];
    for (int k = 0; k < nq; ++k) { d[k] = qn[k] - q[k]; if (fabs(d[k]) > size) size = fabs(d[k]); }
    long long ns = (long long)ceil(size / c->edge_res);
    if (ns < 2) return 1;
    long long *lo = (long long *)malloc((size_t)(2*ns + 4) * sizeof(long long));
    long long *hi = (long long *)malloc((size_t)(2*ns + 4) * sizeof(long long));
    if (!lo || !hi) { free(lo); free(hi); return -2; }
    long long head = 0, tail = 0;
    int ok = 1;
    lo[tail] = 0; hi[tail] = ns; ++tail;
    while (head < tail) {
        long long l = lo[head], h = hi[head]; ++head;
        if (h - l < 2) continue;
        long long mid = (l + h) / 2;
        double f = (double)mid / (double)ns;
        for (int k = 0; k < nq; ++k) x[k] = q[k] + f*d[k];
        cnt[5] += 1;
        if (tcb_collides(c, x)) { ok = 0; break; }
        lo[tail] = l; hi[tail] = mid; ++tail;
        lo[tail] = mid; hi[tail] = h; ++tail;
    }
    free(lo); free(hi);
    return ok;
}

/* restart r's IK seed, q + N(0, sigma^2) per joint (with c->restart_clip each offset clipped to the joint-jump
   bound: in every restart, or in the first only), drawn from c->rng: every restart, run or skipped, draws through
   here, so that the stream goes on the same either way */
static void tcb_restart_seed(const tcb_ctx *c, const double *q, double *seed, int r) {
    double J = c->max_joint_step;
    int clip = c->restart_clip == 1 || (c->restart_clip == 2 && r == 0);
    for (int k = 0; k < c->nq; ++k) {
        double o = c->restart_sigma*tcb_normal(c->rng);
        if (clip) o = o > J ? J : o < -J ? -J : o;
        seed[k] = q[k] + o;
    }
}

/* the restarts of a waypoint that none of them can pass: their draws taken, so that the stream goes on as if they had
   run, their IK not run */
static void tcb_skip_restarts(const tcb_ctx *c, const double *q, long long *cnt) {
    double unused[KMAXJ];
    for (int r = 0; r < c->restarts; ++r) tcb_restart_seed(c, q, unused, r);
    cnt[11] += c->restarts;
}

/* the random restarts of a failing waypoint (TCBiRRT.path_ik): IK from q + N(0, sigma^2), accepted within the
   joint-jump bound, the joint limits and collision-free; 1 with the solution in qn */
static int tcb_restarts(const tcb_ctx *c, const double *q, const double *P, double *qn, long long *cnt) {
    int nq = c->nq;
    double seed[KMAXJ], x[KMAXJ];
    tcb_ctx d = *c;                                   /* the restarts' own IK iteration limit */
    if (c->restart_max_it > 0) d.max_it = c->restart_max_it;
    for (int r = 0; r < c->restarts; ++r) {
        cnt[9] += 1;
        tcb_restart_seed(c, q, seed, r);
        long long its = 0;
        int ok = tcb_ik(&d, seed, P, x, &its);
        cnt[1] += its;
        cnt[12] += its;
        if (!ok) continue;
        double m = 0.0;
        int inside = 1;
        for (int k = 0; k < nq; ++k) {
            double d = fabs(x[k] - q[k]); if (d > m) m = d;
            if (x[k] < c->lower[k] || x[k] > c->upper[k]) inside = 0;
        }
        if (m > c->max_joint_step || !inside) continue;
        cnt[5] += 1;
        if (tcb_collides(c, x)) continue;
        memcpy(qn, x, nq*sizeof(double));
        return 1;
    }
    return 0;
}

/* the IK seed of a waypoint after q (the previous solution; q_pp the one before it, NULL: none): q itself, or with
   c->predictor == 1 and q_pp the secant prediction q + (q - q_pp) clamped to the joint limits (into buf) */
static const double *tcb_seed(const tcb_ctx *c, const double *q, const double *q_pp, double *buf) {
    if (c->predictor != 1 || !q_pp) return q;
    for (int k = 0; k < c->nq; ++k) buf[k] = fmin(fmax(q[k] + (q[k] - q_pp[k]), c->qlo[k]), c->qhi[k]);
    return buf;
}

/* waypoints j0..n-1 of the poses P (n x 12), each seeded by the previous solution (q_prev for j0; q_pp the
   solution before q_prev, NULL: none) or its prediction (c->predictor); solutions into Q (n x nq). Returns the
   first waypoint that fails (its reason counted), or n. With c->rng, a failing waypoint's restarts run here
   first (cnt[8] is then never set). The joint-jump bound and the restarts are relative to the previous solution. */
long long tcb_path_ik(const tcb_ctx *c, const double *q_prev, const double *q_pp, const double *P, long long j0,
                      long long n, double *Q, long long *cnt) {
    int nq = c->nq;
    if (nq > KMAXJ || c->km->nj > KMAXJ || c->km->ng > KMAXG) return -2;
    const double *q = q_prev, *qpp = q_pp;
    double seed[KMAXJ];
    for (long long j = j0; j < n; ++j) {
        double *qn = Q + j*nq;
        long long its = 0;
        if (c->npfl > 0 && c->rng && tcb_pose_blocked(c, P + 12*j)) {
            /* the pose alone collides: the waypoint fails as its IK solution's check or its restarts would make it
               fail; the restarts' draws are taken, so that the stream goes on the same. Only where the restarts run
               here (c->rng): a caller that runs them itself counts what the Python code counts */
            cnt[4] += 1; cnt[13] += 1;
            if (c->restarts > 0) tcb_skip_restarts(c, q, cnt);
            return j;
        }
        cnt[0] += 1;
        int ok = tcb_ik(c, tcb_seed(c, q, qpp, seed), P + 12*j, qn, &its);
        cnt[1] += its;
        cnt[10] += its;
        if (!ok) cnt[2] += 1;
        if (ok) {
            double m = 0.0;
            for (int k = 0; k < nq; ++k) { double d = fabs(qn[k] - q[k]); if (d > m) m = d; }
            if (m > c->max_joint_step) { cnt[3] += 1; ok = 0; }
        }
        int posed = 0;
        if (ok) {
            cnt[5] += 1;
            if (tcb_collides(c, qn)) { cnt[4] += 1; ok = 0; posed = tcb_pose_collision(c); }
        }
        int restarted = 0;
        if (!ok) {
            if (posed && c->rng && c->restarts > 0) {   /* every restart would fail on the same pair */
                tcb_skip_restarts(c, q, cnt);
                return j;
            }
            if (!c->rng || c->restarts <= 0 || !tcb_restarts(c, q, P + 12*j, qn, cnt)) return j;
            restarted = 1;
        }
        if (c->edge_res > 0) {
            int sok = tcb_segment_ok(c, q, qn, cnt);
            if (sok < 0) return -2;
            if (!sok) { cnt[4] += 1; if (!restarted && !c->rng) cnt[8] = 1; return j; }
        }
        qpp = q;
        q = qn;
    }
    return n;
}

/* ValidityChecker.edge_checkpoints + edge_is_valid ("held", native): 1 when the segment a -> b is free */
static int tcb_edge_ok(const tcb_ctx *c, const double *a, const double *b, long long *cnt) {
    int nq = c->nq;
    double d[KMAXJ], smax = 0.0, tol = c->edge_tol;
    for (int k = 0; k < nq; ++k) d[k] = fabs(b[k] - a[k]);
    for (int g = 0; g < c->nw; ++g) {
        double s = 0.0;
        for (int k = 0; k < nq; ++k) s += c->W[g*nq + k] * d[k];
        if (s > smax) smax = s;
    }
    long long n_static = smax > 0 ? (long long)ceil(smax / tol) : 1, m;
    double *ts;
    int uniform = 1;
    double C[64];
    long long n = 0;
    if (n_static > 5 && c->prof != NULL && c->nprof <= 64) {
        const double *arg[64] = {a, b};
        double *res[64] = {C};
        if (c->prof(arg, res, c->prof_iw, c->prof_w, 0) != 0) return -1;
        n = (long long)ceil(C[c->nprof - 1] / tol);
        if (n < 1) n = 1;
        if (n < n_static) uniform = 0;
    }
    m = uniform ? n_static - 1 : n - 1;
    if (m <= 0) return 1;
    ts = (double *)malloc((size_t)m * sizeof(double));
    long long *lo = (long long *)malloc((size_t)(2*m + 4) * sizeof(long long));
    long long *hi = (long long *)malloc((size_t)(2*m + 4) * sizeof(long long));
    if (!ts || !lo || !hi) { free(ts); free(lo); free(hi); return -1; }
    if (uniform) {
        for (long long k = 1; k <= m; ++k) ts[k-1] = (double)k / (double)n_static;
    } else {
        int np = c->nprof;
        long long j = 0;
        for (long long k = 1; k <= m; ++k) {   /* np.interp(k tol, C, linspace(0, 1, np)) */
            double x = (double)k * tol;
            if (x <= C[0]) { ts[k-1] = 0.0; continue; }
            if (x >= C[np-1]) { ts[k-1] = 1.0; continue; }
            while (j + 1 < np - 1 && C[j+1] <= x) ++j;
            while (j > 0 && C[j] > x) --j;
            double fj = (double)j / (double)(np - 1), fj1 = (double)(j + 1) / (double)(np - 1);
            if (x == C[j]) ts[k-1] = fj;
            else ts[k-1] = (fj1 - fj) / (C[j+1] - C[j]) * (x - C[j]) + fj;
        }
    }
    /* bisection order over the n_pts = m + 1 intervals: FIFO of [lo, hi], midpoints */
    long long head = 0, tail = 0, nchk = 0;
    int free_ = 1;
    double q[KMAXJ];
    lo[tail] = 0; hi[tail] = m + 1; ++tail;
    double oMi[12*KMAXJ], oMg[12*KMAXG];
    while (head < tail) {
        long long l = lo[head], h = hi[head]; ++head;
        if (h - l < 2) continue;
        long long mid = (l + h) / 2;
        double f = ts[mid - 1];
        for (int k = 0; k < nq; ++k) q[k] = a[k] + f*(b[k] - a[k]);
        ++nchk;
        if (config_collides(c->km, c->active, q, NULL, -1, oMi, oMg)) { free_ = 0; break; }
        lo[tail] = l; hi[tail] = mid; ++tail;
        lo[tail] = mid; hi[tail] = h; ++tail;
    }
    cnt[5] += nchk;
    free(ts); free(lo); free(hi);
    return free_;
}

/* the edges q_prev -> Q[0] -> ... -> Q[n-1]: index of the first in collision, or n */
long long tcb_edges(const tcb_ctx *c, const double *q_prev, const double *Q, long long n, long long *cnt) {
    if (c->nq > KMAXJ || c->km->nj > KMAXJ || c->km->ng > KMAXG) return -2;
    const double *a = q_prev;
    for (long long k = 0; k < n; ++k) {
        cnt[6] += 1;
        int ok = tcb_edge_ok(c, a, Q + k*c->nq, cnt);
        if (ok < 0) return -2;
        if (!ok) { cnt[7] += 1; return k; }
        a = Q + k*c->nq;
    }
    return n;
}

typedef struct {
    const kmodel *km;               /* the object (geometry g, placed per call) and the obstacles, no joints */
    const unsigned char *active;
    int g, nobs, ngrasp;
    const double *gt;               /* ngrasp x 3: grasp point in the object frame */
    const double *sh;               /* ngrasp x 3: shoulder */
    const double *reach;            /* ngrasp: reach bound [m] */
} tcb_filt;

static void tcb_rpy(const double *xi, double *P) {   /* R = Rz(yaw) Ry(pitch) Rx(roll), row-major; then p */
    double cr = cos(xi[3]), sr = sin(xi[3]), cp = cos(xi[4]), sp = sin(xi[4]), cy = cos(xi[5]), sy = sin(xi[5]);
    P[0] = cy*cp; P[1] = cy*sp*sr - sy*cr; P[2] = cy*sp*cr + sy*sr;
    P[3] = sy*cp; P[4] = sy*sp*sr + cy*cr; P[5] = sy*sp*cr - cy*sr;
    P[6] = -sp;   P[7] = cp*sr;            P[8] = cp*cr;
    P[9] = xi[0]; P[10] = xi[1]; P[11] = xi[2];
}

/* ObjectPoseFilter: 0 unreachable, 1 reachable (or not tested) but the object collides, 2 passes */
static int tcb_filter_pose(const tcb_filt *f, const double *P, int reach) {
    for (int k = 0; reach && k < f->ngrasp; ++k) {
        const double *t = f->gt + 3*k, *s = f->sh + 3*k;
        double v[3];
        for (int i = 0; i < 3; ++i) v[i] = P[9+i] + P[3*i]*t[0] + P[3*i+1]*t[1] + P[3*i+2]*t[2] - s[i];
        if (sqrt(dot3(v, v)) > f->reach[k]) return 0;
    }
    if (f->nobs == 0) return 2;
    double oMi[12*KMAXJ], oMg[12*KMAXG];
    if (f->km->ng > KMAXG || f->km->nj > KMAXJ) return -2;
    return config_collides(f->km, f->active, P, P, f->g, oMi, oMg) ? 1 : 2;
}

int tcb_filter_xi(const tcb_filt *f, const double *xi, int reach) {
    double P[12];
    tcb_rpy(xi, P);
    return tcb_filter_pose(f, P, reach);
}

/* rrtconnect.edge_is_valid(a, b, filter, resolution, check_end) over xi: 1 when every point passes;
   *ncalls = filter calls made */
int tcb_filter_segment(const tcb_filt *f, const double *a, const double *b, double resolution, int check_end,
                       long long *ncalls) {
    double d[6], x[6], size = 0.0;
    for (int i = 0; i < 6; ++i) { d[i] = b[i] - a[i]; if (fabs(d[i]) > size) size = fabs(d[i]); }
    long long n = (long long)ceil(size / resolution);
    if (n < 1) n = 1;
    *ncalls = 0;
    if (check_end) { *ncalls += 1; if (tcb_filter_xi(f, b, 1) != 2) return 0; }
    if (n < 2) return 1;
    long long *lo = (long long *)malloc((size_t)(2*n + 4) * sizeof(long long));
    long long *hi = (long long *)malloc((size_t)(2*n + 4) * sizeof(long long));
    if (!lo || !hi) { free(lo); free(hi); return -2; }
    long long head = 0, tail = 0;
    int ok = 1;
    lo[tail] = 0; hi[tail] = n; ++tail;
    while (head < tail) {
        long long l = lo[head], h = hi[head]; ++head;
        if (h - l < 2) continue;
        long long mid = (l + h) / 2;
        double s = (double)mid / (double)n;
        for (int i = 0; i < 6; ++i) x[i] = a[i] + s*d[i];
        *ncalls += 1;
        if (tcb_filter_xi(f, x, 1) != 2) { ok = 0; break; }
        lo[tail] = l; hi[tail] = mid; ++tail;
        lo[tail] = mid; hi[tail] = h; ++tail;
    }
    free(lo); free(hi);
    return ok;
}

/* one extension: the poses (into P, n x 12), the path IK from q_near (into Q) and, when every waypoint
   passes and the edges are on, their edge checks. Returns the waypoints accepted (< n: the first failing
   one, for the caller's restarts); *edge_k = the first failing edge, n when they pass, -1 when not run */
long long tcb_extend(const tcb_ctx *c, const double *R0, const double *p0, const double *R1, const double *p1,
                     long long n, const double *q_near, double *P, double *Q, long long *cnt, long long *edge_k) {
    tcb_interpolate(R0, p0, R1, p1, (int)n, P);
    long long r = tcb_path_ik(c, q_near, NULL, P, 0, n, Q, cnt);
    *edge_k = -1;
    if (r == n && c->edge_on) *edge_k = tcb_edges(c, q_near, Q, n, cnt);
    return r;
}

/* one extension as TCBiRRT.constrained_extend takes it (restarts in C, Jacobian-spaced edges on): the poses
   (into P), the path IK with restarts (into Q), the edges of the accepted configurations. Returns the number of
   configurations kept (with prefix: the valid prefix, possibly 0), -1 when the extension fails without prefix,
   -2 when the model is too large */
long long tcb_extend_prefix(const tcb_ctx *c, const double *R0, const double *p0, const double *R1, const double *p1,
                            long long n, const double *q_near, double *P, double *Q, long long *cnt, int prefix) {
    tcb_interpolate(R0, p0, R1, p1, (int)n, P);
    long long r = tcb_path_ik(c, q_near, NULL, P, 0, n, Q, cnt);
    if (r < -1) return r;
    if (r < n && !prefix) return -1;
    if (c->edge_on && r > 0) {
        long long e = tcb_edges(c, q_near, Q, r, cnt);
        if (e < -1) return e;
        if (e < r) { if (!prefix) return -1; r = e; }
    }
    return r;
}
"""
