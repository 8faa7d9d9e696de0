"""The C source of TCBiRRT's native task-space sampler and object lead path
(:mod:`optplan.planners.kernel.sampler`).

It is appended to the extension library's source (:data:`~optplan.planners.kernel.extend_csource.EXTEND_SOURCE`,
which defines the task-space filter ``tcb_filt``) and compiled with it, so a sample, its filter tests and the
nearest-neighbour search of the tree it is drawn for run in one call.

What it computes (the algorithms of :class:`optplan.planners.task_sampling.TaskSampler` and
:func:`~optplan.planners.task_sampling.object_lead_path`, with a random stream of their own):

* ``tcb_rng``: xoshiro256** (Blackman & Vigna) seeded by splitmix64 from one 64-bit seed, uniform doubles
  from the top 53 bits, standard normals by Marsaglia's polar method (the second value of a pair kept);
* ``tcb_sample``: one ξ_rand — goal bias (a random live node of the other tree), a pose near the lead
  path, a bridge test, or a uniform draw in the box rejected by the filter up to ``filter_tries`` times; a
  draw's orientation follows the lead path's nearest pose or the start-goal geodesic with the sampler's
  probabilities (orientation matrices converted back to roll, pitch, yaw with pitch in [−π/2, π/2]);
* ``tcb_sample_near``: ``tcb_sample`` and the nearest live node of the tree being extended;
* ``tcb_lead_path``: RRT-Connect of the object alone in ξ (straight segments checked by the filter every
  ``resolution`` of the largest coordinate change, end first then coarse-to-fine), then random shortcuts;
  the time limit is an end time on ``CLOCK_MONOTONIC`` or ``CLOCK_PROCESS_CPUTIME_ID``, the work budget a cap on
  its iterations (0: none).
"""
from __future__ import annotations

__all__ = ["RNG_SOURCE", "SAMPLER_SOURCE", "SAMPLER_STATS"]

#: the sampler's counters, in the order of the C code
SAMPLER_STATS = ("samples", "goal_samples", "bridge_samples", "guide_samples", "filter_rejections", "filter_calls")

#: the random stream and the clock, placed before the extension source (its restarts draw from it)
RNG_SOURCE = r"""
#include <time.h>

typedef struct { unsigned long long s[4]; double spare; int has_spare; } tcb_rng;

static unsigned long long tcb_splitmix(unsigned long long *x) {
    unsigned long long z = (*x += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}
static unsigned long long tcb_rotl(unsigned long long x, int k) { return (x << k) | (x >> (64 - k)); }
static unsigned long long tcb_next(tcb_rng *r) {   /* xoshiro256** */
    unsigned long long *s = r->s, out = tcb_rotl(s[1] * 5, 7) * 9, t = s[1] << 17;
    s[2] ^= s[0]; s[3] ^= s[1]; s[1] ^= s[2]; s[0] ^= s[3]; s[2] ^= t; s[3] = tcb_rotl(s[3], 45);
    return out;
}
void tcb_rng_seed(tcb_rng *r, unsigned long long seed) {
    unsigned long long x = seed;
    for (int i = 0; i < 4; ++i) r->s[i] = tcb_splitmix(&x);
    r->has_spare = 0; r->spare = 0.0;
}
static double tcb_uniform(tcb_rng *r) { return (double)(tcb_next(r) >> 11) * 0x1.0p-53; }
static double tcb_normal(tcb_rng *r) {   /* Marsaglia's polar method */
    if (r->has_spare) { r->has_spare = 0; return r->spare; }
    double u, v, s;
    do { u = 2.0*tcb_uniform(r) - 1.0; v = 2.0*tcb_uniform(r) - 1.0; s = u*u + v*v; } while (s >= 1.0 || s == 0.0);
    double f = sqrt(-2.0*log(s)/s);
    r->spare = v*f; r->has_spare = 1;
    return u*f;
}
static long long tcb_randint(tcb_rng *r, long long n) {   /* uniform in [0, n) */
    return (long long)(tcb_uniform(r) * (double)n) % n;
}
double tcb_rng_uniform(tcb_rng *r) { return tcb_uniform(r); }
double tcb_rng_normal(tcb_rng *r) { return tcb_normal(r); }

static double tcb_clock(int kind) {
    struct timespec ts;
    clock_gettime(kind ? CLOCK_PROCESS_CPUTIME_ID : CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

"""

SAMPLER_SOURCE = r"""
typedef struct {
    tcb_rng *rng;
    const tcb_filt *f;              /* NULL: no filter */
    double lo[6], span[6];
    int filter_tries, bridge_tries;
    double p_bridge, sigma[6], goal_bias, p_guide, gsigma[6], p_geo, geo_sigma, p_lead;
    const double *guide; long long nguide;   /* nguide x 6; nguide 0: no lead path */
    int has_ends; double R0[9], w[3];        /* the start orientation and log(R0^T R_goal) */
    long long stats[6];   /* samples, goal, bridge, guide, filter_rejections, filter_calls */
} tcb_sampler;

static void tcb_mat_to_rpy(const double *R, double *rpy) {   /* R row-major = Rz(y) Ry(p) Rx(r) */
    double cp = sqrt(R[0]*R[0] + R[3]*R[3]);
    double p = atan2(-R[6], cp), r, y;
    if (cp < 1e-9) { r = 0.0; y = atan2(-R[1], R[4]); }
    else { r = atan2(R[7], R[8]); y = atan2(R[3], R[0]); }
    rpy[0] = r; rpy[1] = p; rpy[2] = y;
}
static void tcb_mul3(const double *A, const double *B, double *C) {
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) C[3*i+j] = A[3*i]*B[j] + A[3*i+1]*B[3+j] + A[3*i+2]*B[6+j];
}
static void tcb_perturbed_rpy(tcb_sampler *s, const double *R, double *rpy) {   /* rpy(R exp(N(0, geo_sigma^2))) */
    double w[3] = {s->geo_sigma*tcb_normal(s->rng), s->geo_sigma*tcb_normal(s->rng), s->geo_sigma*tcb_normal(s->rng)};
    double E[9], M[9];
    tcb_exp3(w, E);
    tcb_mul3(R, E, M);
    tcb_mat_to_rpy(M, rpy);
}

static void tcb_draw(tcb_sampler *s, double *xi) {
    tcb_rng *r = s->rng;
    for (int i = 0; i < 6; ++i) xi[i] = s->lo[i] + s->span[i]*tcb_uniform(r);
    if (s->p_lead > 0.0 && s->nguide > 0 && tcb_uniform(r) < s->p_lead) {
        long long best = 0; double bd = INFINITY;
        for (long long k = 0; k < s->nguide; ++k) {
            const double *g = s->guide + 6*k;
            double dx = g[0]-xi[0], dy = g[1]-xi[1], dz = g[2]-xi[2], d = dx*dx + dy*dy + dz*dz;
            if (d < bd) { bd = d; best = k; }
        }
        double P[12];
        tcb_rpy(s->guide + 6*best, P);
        tcb_perturbed_rpy(s, P, xi + 3);
    } else if (s->has_ends && tcb_uniform(r) < s->p_geo) {
        double t = tcb_uniform(r), wt[3] = {t*s->w[0], t*s->w[1], t*s->w[2]}, E[9], M[9];
        tcb_exp3(wt, E);
        tcb_mul3(s->R0, E, M);
        tcb_perturbed_rpy(s, M, xi + 3);
    }
}

static int tcb_class(tcb_sampler *s, const double *xi, int reach) { return tcb_filter_xi(s->f, xi, reach); }

static int tcb_bridge(tcb_sampler *s, double *out) {
    double a[6], b[6], Pa[12], Pb[12];
    for (int k = 0; k < s->bridge_tries; ++k) {
        tcb_draw(s, a);
        if (tcb_class(s, a, 1) != 1) continue;
        for (int i = 0; i < 6; ++i) b[i] = a[i] + tcb_normal(s->rng)*s->sigma[i];
        if (tcb_class(s, b, 0) != 1) continue;
        tcb_rpy(a, Pa);
        tcb_rpy(b, Pb);
        double Rr[9], w[3], E[9], Pm[12];
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) Rr[3*i+j] = Pa[i]*Pb[j] + Pa[3+i]*Pb[3+j] + Pa[6+i]*Pb[6+j];
        tcb_log3(Rr, w);
        w[0] *= 0.5; w[1] *= 0.5; w[2] *= 0.5;
        tcb_exp3(w, E);
        tcb_mul3(Pa, E, Pm);
        for (int i = 0; i < 3; ++i) Pm[9+i] = 0.5*(a[i] + b[i]);
        s->stats[5] += 1;
        if (tcb_filter_pose(s->f, Pm, 1) == 2) {
            out[0] = Pm[9]; out[1] = Pm[10]; out[2] = Pm[11];
            tcb_mat_to_rpy(Pm, out + 3);
            return 1;
        }
    }
    return 0;
}

/* TaskSampler.sample: other (n_other x 6, alive mask or NULL) is the other tree for the goal bias */
void tcb_sample(tcb_sampler *s, const double *other, long long n_other, const unsigned char *alive, double *out) {
    tcb_rng *r = s->rng;
    s->stats[0] += 1;
    double u = tcb_uniform(r);
    if (other && n_other > 0 && u < s->goal_bias) {
        long long i = tcb_randint(r, n_other);
        for (int t = 0; alive && !alive[i] && t < 64; ++t) i = tcb_randint(r, n_other);
        if (alive && !alive[i]) {   /* a sparse live set: the first live node after i, cyclically */
            long long k = 0;
            while (k < n_other && !alive[(i + k) % n_other]) ++k;
            i = (i + k) % n_other;
        }
        if (!alive || alive[i]) {
            s->stats[1] += 1;
            memcpy(out, other + 6*i, 6*sizeof(double));
            return;
        }
    }
    u -= s->goal_bias;
    if (s->nguide > 0 && u < s->p_guide) {
        s->stats[3] += 1;
        const double *g = s->guide + 6*tcb_randint(r, s->nguide);
        for (int i = 0; i < 6; ++i) out[i] = g[i] + tcb_normal(r)*s->gsigma[i];
        return;
    }
    u -= s->p_guide;
    if (s->f && u < s->p_bridge && tcb_bridge(s, out)) { s->stats[2] += 1; return; }
    tcb_draw(s, out);
    if (!s->f) return;
    for (int k = 0; k < s->filter_tries; ++k) {
        s->stats[5] += 1;
        if (tcb_class(s, out, 1) == 2) return;
        s->stats[4] += 1;
        tcb_draw(s, out);
    }
}

/* tcb_sample, then the nearest live row of Xa (na x 6) to the sample: its index */
long long tcb_sample_near(tcb_sampler *s, const double *other, long long n_other, const unsigned char *alive_other,
                          const double *Xa, long long na, const unsigned char *alive_a, double *out, long long *Ka,
                          long long *kdn_a) {
    tcb_sample(s, other, n_other, alive_other, out);
    return tcb_nearest_kd(Xa, na, 6, alive_a, out, Ka, kdn_a);
}

typedef struct { double *X; long long *parent; long long n, cap; } tcb_xtree;

static int tcb_xtree_add(tcb_xtree *t, const double *x, long long parent) {
    if (t->n == t->cap) {
        long long cap = t->cap ? 2*t->cap : 256;
        double *X = (double *)realloc(t->X, sizeof(double)*6*(size_t)cap);
        if (!X) return -1;
        t->X = X;
        long long *P = (long long *)realloc(t->parent, sizeof(long long)*(size_t)cap);
        if (!P) return -1;
        t->parent = P; t->cap = cap;
    }
    memcpy(t->X + 6*t->n, x, 6*sizeof(double));
    t->parent[t->n] = parent;
    return (int)(t->n++ >= 0);
}

/* extend tree t toward target (connect: until reached or blocked): *reached; the last node; -1 out of memory */
static long long tcb_lead_extend(tcb_sampler *s, tcb_xtree *t, const double *target, int connect, double range,
                                 double resolution, int *reached) {
    long long i = tcb_nearest(t->X, t->n, 6, NULL, target);
    *reached = 0;
    for (;;) {
        const double *x = t->X + 6*i;
        double d[6], y[6], dist = 0.0;
        for (int k = 0; k < 6; ++k) { d[k] = target[k] - x[k]; dist += d[k]*d[k]; }
        dist = sqrt(dist);
        if (dist < 1e-9) { *reached = 1; return i; }
        for (int k = 0; k < 6; ++k) y[k] = dist <= range ? target[k] : x[k] + (range/dist)*d[k];
        long long nc = 0;
        int ok = tcb_filter_segment(s->f, x, y, resolution, 1, &nc);
        s->stats[5] += nc;
        if (ok < 0) return -1;
        if (!ok) return i;
        if (tcb_xtree_add(t, y, i) < 0) return -1;
        i = t->n - 1;
        if (dist <= range) { *reached = 1; return i; }
        if (!connect) return i;
    }
}

/* object_lead_path's search: RRT-Connect in xi from xs to xg with the sampler s (which has a filter), then
   `shortcuts` random shortcuts. Returns the number of path rows written into a malloc'ed *out (free with
   tcb_free), 0 at the time limit or after max_iters iterations (0: no cap), -1 when out of memory;
   *iters = iterations */
long long tcb_lead_path(tcb_sampler *s, const double *xs, const double *xg, double range, double resolution,
                        int shortcuts, int clock_kind, double end, long long max_iters, double **out, long long *iters) {
    tcb_xtree A = {0}, B = {0}, *ta = &A, *tb = &B;
    long long ia = -1, ib = -1, np = 0;
    int a_first = 1, found = 0, reached = 0;
    *out = NULL; *iters = 0;
    if (tcb_xtree_add(&A, xs, -1) < 0 || tcb_xtree_add(&B, xg, -1) < 0) goto oom;
    while ((max_iters <= 0 || *iters < max_iters) && tcb_clock(clock_kind) < end) {
        double xi[6], tgt[6];
        *iters += 1;
        tcb_sample(s, NULL, 0, NULL, xi);
        ia = tcb_lead_extend(s, ta, xi, 1, range, resolution, &reached);
        if (ia < 0) goto oom;
        memcpy(tgt, ta->X + 6*ia, sizeof tgt);
        ib = tcb_lead_extend(s, tb, tgt, 1, range, resolution, &reached);
        if (ib < 0) goto oom;
        if (reached) { found = 1; break; }
        tcb_xtree *tt = ta; ta = tb; tb = tt; a_first = !a_first;
    }
    if (!found) { free(A.X); free(A.parent); free(B.X); free(B.parent); return 0; }
    {
        long long la = 0, lb = 0;
        for (long long i = ia; i >= 0; i = ta->parent[i]) ++la;
        for (long long i = ib; i >= 0; i = tb->parent[i]) ++lb;
        np = la + lb - 1;
        double *P = (double *)malloc(sizeof(double)*6*(size_t)np);
        if (!P) goto oom;
        long long k = la - 1;
        for (long long i = ia; i >= 0; i = ta->parent[i], --k) memcpy(P + 6*k, ta->X + 6*i, 6*sizeof(double));
        k = la;   /* tree b's node ib holds the same pose as ia: kept once */
        for (long long i = tb->parent[ib]; i >= 0; i = tb->parent[i], ++k) memcpy(P + 6*k, tb->X + 6*i, 6*sizeof(double));
        if (!a_first)
            for (long long i = 0; i < np/2; ++i)
                for (int c = 0; c < 6; ++c) { double t = P[6*i+c]; P[6*i+c] = P[6*(np-1-i)+c]; P[6*(np-1-i)+c] = t; }
        for (int it = 0; it < shortcuts && np > 2; ++it) {
            long long i = tcb_randint(s->rng, np), j = tcb_randint(s->rng, np - 1);
            if (j >= i) ++j;
            if (i > j) { long long t = i; i = j; j = t; }
            if (j - i < 2) continue;
            long long nc = 0;
            int ok = tcb_filter_segment(s->f, P + 6*i, P + 6*j, resolution, 1, &nc);
            s->stats[5] += nc;
            if (ok < 0) { free(P); goto oom; }
            if (ok) { memmove(P + 6*(i+1), P + 6*j, sizeof(double)*6*(size_t)(np - j)); np -= j - i - 1; }
        }
        *out = P;
    }
    free(A.X); free(A.parent); free(B.X); free(B.parent);
    return np;
oom:
    free(A.X); free(A.parent); free(B.X); free(B.parent);
    return -1;
}

void tcb_free(void *p) { free(p); }
"""
