"""The C source of the native RRT-Connect (:mod:`optplan.planners.kernel.rrtc`).

It (with the checks of :mod:`.rrtc_check_csource` placed inside it) is appended to the planning kernel's source
(:data:`~optplan.planners.kernel.csource.C_SOURCE`: forward kinematics and the exact primitive tests) and compiled
with it into one library, so that a
whole query — sampling, nearest neighbour, extensions, connections, edge checks, path extraction and
shortcuts — is one native call.

What it computes (the algorithm of :func:`optplan.planners.rrtconnect.rrt_connect` and
:func:`~optplan.planners.rrtconnect.shortcut_path`, edges checked as
:func:`~optplan.planners.rrtconnect.edge_is_valid` without weights):

* the search space is ``dim`` joints (indices ``jidx`` into the configuration); the others stay at
  ``base`` (one arm of a regrasp), or all joints (``dim = nq``);
* samples are uniform in the box ``[lower, upper]`` from xoshiro256** (Blackman & Vigna) seeded by
  splitmix64 from one 64-bit seed (the Python side draws it from the planner's NumPy Generator, or passes the
  plan's seed and the draw ``np.random.default_rng(seed).integers(0, 2**63)`` is computed here), or
  (``sampler`` 1) the Halton sequence (radical inverses in the first ``dim`` prime bases, point ``i`` at
  iteration ``i``) shifted by one uniform random vector modulo 1 (a Cranley-Patterson rotation: each
  query its own low-discrepancy sequence);
* the start and the goal may be checked first (in the box, valid: statuses 6 and 7 otherwise), so that a plan is
  one native call;
* nearest neighbour is a linear scan over a contiguous node array (squared Euclidean distance), except
  in a connection's steps after the first, where the node the previous step added is the nearest;
* a configuration check tries the pair that collided last first (the same verdict);
* the joints that no searched joint moves (the other arm of a regrasp), the geometries on them and a fixed
  object are placed once per query, and the pairs of two such geometries checked once: every configuration
  of the query collides when one of them does, and none of them is tested again otherwise (the same
  verdicts, with the forward kinematics of the moving chain only);
* an edge a → b is checked at ``n = max(1, ceil(max_j |b_j - a_j| / resolution))`` steps: the end b
  first, then the interior points ``a + (k/n)(b - a)`` in coarse-to-fine (bisection) order;
* ``tune`` (NULL: all off): with a dynamic domain (Yershova et al. 2005, as VAMP's RRT-Connect) a node whose
  extension toward a sample was trapped gets the domain's radius, and a sample farther than its nearest node's
  radius is drawn again for the same tree (the rejected sample counts as an iteration, as in VAMP: the
  iteration cap bounds a search whose samples the domains reject); the radius grows by 1 + alpha at each passing
  extension from that node and shrinks by 1 - alpha (to its least value) at each trapped one. With balancing
  (VAMP's ``tree_ratio``) the tree that just grew grows again while |n_A - n_B| / n_A >= the ratio. The
  connection ``"new"`` (VAMP's) grows the new node's tree toward the other tree's nearest node in equal steps
  of at most ``range`` instead of the other tree toward the new node;
* with ``stall_iterations`` > 0 the search gives up (status 5, "stalled") when one of the two trees has
  added no node for that many iterations (the goal or the start of the moving arm walled in: its tree
  cannot leave a pocket, while the other fills the free space; a check of two counters per iteration);
* the time limit is an end time on ``CLOCK_MONOTONIC`` (Python's ``time.perf_counter``) or
  ``CLOCK_PROCESS_CPUTIME_ID`` (``time.process_time``), read every 8 iterations / connection steps.
"""
from __future__ import annotations

from .rrtc_check_csource import RRTC_CHECK_SOURCE

__all__ = ["RRTC_SOURCE", "RRTC_STATUS"]

#: the status codes of ``rrtc_plan`` (its return value)
RRTC_STATUS = {0: "found", 1: "iteration cap", 2: "time limit", 3: "node cap", 4: "out of memory", 5: "stalled",
               6: "invalid start", 7: "invalid goal", -2: "model too large for the kernel"}

_RRTC_HEAD = r"""
#include <stdlib.h>
#include <time.h>

typedef struct { unsigned long long s[4]; } rrtc_rng;

static unsigned long long rrtc_splitmix(unsigned long long *x) {
    unsigned long long z = (*x += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}
static unsigned long long rrtc_rotl(unsigned long long x, int k) { return (x << k) | (x >> (64 - k)); }
static unsigned long long rrtc_next(rrtc_rng *r) {   /* xoshiro256** */
    unsigned long long *s = r->s, out = rrtc_rotl(s[1] * 5, 7) * 9, t = s[1] << 17;
    s[2] ^= s[0]; s[3] ^= s[1]; s[1] ^= s[2]; s[0] ^= s[3]; s[2] ^= t; s[3] = rrtc_rotl(s[3], 45);
    return out;
}
static double rrtc_uniform(rrtc_rng *r) { return (double)(rrtc_next(r) >> 11) * 0x1.0p-53; }

/* NumPy's int(np.random.default_rng(seed).integers(0, 2**63)) without NumPy: the SeedSequence of the seed's
   32-bit words (pool of 4, hashmix / mix), its first 8 words as PCG64's state and increment, one PCG64 step
   (XSL-RR output), and Lemire's bound 2**63, which for this bound is the output shifted right by one */
static unsigned long long rrtc_mulhi(unsigned long long a, unsigned long long b) {
    unsigned long long a0 = a & 0xffffffffULL, a1 = a >> 32, b0 = b & 0xffffffffULL, b1 = b >> 32;
    unsigned long long p00 = a0*b0, p01 = a0*b1, p10 = a1*b0, p11 = a1*b1;
    unsigned long long mid = (p00 >> 32) + (p01 & 0xffffffffULL) + (p10 & 0xffffffffULL);
    return p11 + (p01 >> 32) + (p10 >> 32) + (mid >> 32);
}
/* (h, l) = (h, l) * (mh, ml) + (ih, il) mod 2**128 */
static void rrtc_pcg_step(unsigned long long *h, unsigned long long *l, unsigned long long ih, unsigned long long il) {
    const unsigned long long mh = 0x2360ED051FC65DA4ULL, ml = 0x4385DF649FCCF645ULL;
    unsigned long long lo = *l * ml, hi = rrtc_mulhi(*l, ml) + *l * mh + *h * ml;
    unsigned long long nl = lo + il;
    *h = hi + ih + (nl < lo); *l = nl;
}
static unsigned rrtc_hashmix(unsigned v, unsigned *hc) {
    v ^= *hc; *hc *= 0x931e8875U; v *= *hc; v ^= v >> 16; return v;
}
static unsigned rrtc_mix(unsigned x, unsigned y) { unsigned r = 0xca01f9ddU * x - 0x4973f715U * y; r ^= r >> 16; return r; }
unsigned long long rrtc_numpy_seed(unsigned long long seed) {
    unsigned ent[2], pool[4], hc = 0x43b0d7e5U, hb = 0x8b51f9ddU, st[8];
    int ne = 0;
    if (seed == 0) ent[ne++] = 0;
    while (seed) { ent[ne++] = (unsigned)(seed & 0xffffffffULL); seed >>= 32; }
    for (int i = 0; i < 4; ++i) pool[i] = rrtc_hashmix(i < ne ? ent[i] : 0U, &hc);
    for (int s = 0; s < 4; ++s)
        for (int d = 0; d < 4; ++d)
            if (s != d) pool[d] = rrtc_mix(pool[d], rrtc_hashmix(pool[s], &hc));
    for (int i = 0; i < 8; ++i) {
        unsigned v = pool[i & 3] ^ hb;
        hb *= 0x58f38dedU; v *= hb; v ^= v >> 16; st[i] = v;
    }
    unsigned long long w[4];
    for (int i = 0; i < 4; ++i) w[i] = (unsigned long long)st[2*i] | ((unsigned long long)st[2*i+1] << 32);
    /* PCG64 seeding: inc = (w2, w3) << 1 | 1; state = 0; step; state += (w0, w1); step; then one step per output */
    unsigned long long ih = (w[2] << 1) | (w[3] >> 63), il = (w[3] << 1) | 1ULL, h = 0, l = 0;
    rrtc_pcg_step(&h, &l, ih, il);
    unsigned long long nl = l + w[1];
    h += w[0] + (nl < l); l = nl;
    rrtc_pcg_step(&h, &l, ih, il);
    rrtc_pcg_step(&h, &l, ih, il);
    unsigned long long x = h ^ l;
    int rot = (int)(h >> 58);
    unsigned long long out = (x >> rot) | (x << ((64 - rot) & 63));
    return out >> 1;
}

/* the Halton sequence: coordinate k of point i is the radical inverse of i in the k-th prime base */
#define RRTC_NPRIMES 40
static const int rrtc_primes[RRTC_NPRIMES] = {2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61, 67,
    71, 73, 79, 83, 89, 97, 101, 103, 107, 109, 113, 127, 131, 137, 139, 149, 151, 157, 163, 167, 173};
static double rrtc_radical_inverse(int b, unsigned long long i) {
    double f = 1.0, r = 0.0, inv = 1.0 / (double)b;
    while (i > 0) { f *= inv; r += f * (double)(i % (unsigned long long)b); i /= (unsigned long long)b; }
    return r;
}

typedef struct { int dim, n, cap; double *X; int *parent; double *rad; } rrtc_tree;

static int rrtc_tree_init(rrtc_tree *t, int dim, const double *root) {
    t->dim = dim; t->n = 0; t->cap = 256;
    t->X = (double *)malloc(sizeof(double) * (size_t)dim * (size_t)t->cap);
    t->parent = (int *)malloc(sizeof(int) * (size_t)t->cap);
    t->rad = (double *)malloc(sizeof(double) * (size_t)t->cap);
    if (!t->X || !t->parent || !t->rad) return -1;
    memcpy(t->X, root, sizeof(double) * (size_t)dim);
    t->parent[0] = -1; t->rad[0] = INFINITY; t->n = 1;
    return 0;
}
static void rrtc_tree_free(rrtc_tree *t) { free(t->X); free(t->parent); free(t->rad); t->X = NULL; t->parent = NULL; t->rad = NULL; }

static int rrtc_tree_add(rrtc_tree *t, const double *x, int parent) {
    if (t->n == t->cap) {
        int cap = 2 * t->cap;
        double *X = (double *)realloc(t->X, sizeof(double) * (size_t)t->dim * (size_t)cap);
        if (!X) return -1;
        t->X = X;
        int *P = (int *)realloc(t->parent, sizeof(int) * (size_t)cap);
        if (!P) return -1;
        t->parent = P;
        double *R = (double *)realloc(t->rad, sizeof(double) * (size_t)cap);
        if (!R) return -1;
        t->rad = R; t->cap = cap;
    }
    memcpy(t->X + (size_t)t->dim * t->n, x, sizeof(double) * (size_t)t->dim);
    t->parent[t->n] = parent; t->rad[t->n] = INFINITY;
    return t->n++;
}

static int rrtc_nearest(const rrtc_tree *t, const double *x) {
    int best = 0, dim = t->dim;
    double bd = INFINITY;
    for (int i = 0; i < t->n; ++i) {
        const double *y = t->X + (size_t)dim * i;
        double s = 0.0;
        for (int k = 0; k < dim; ++k) { double d = y[k] - x[k]; s += d*d; }
        if (s < bd) { bd = s; best = i; }
    }
    return best;
}

"""

_RRTC_SEARCH = r"""
#define RRTC_TRAPPED 0
#define RRTC_ADVANCED 1
#define RRTC_REACHED 2
#define RRTC_REJECTED 3   /* dynamic domain: the sample lies outside its nearest node's radius */

/* extend tree t toward target from its nearest node (near: that node when known, -1: the linear scan finds
   it): RRTC_* and the new node's index in *inew (-1 when none); -1 on out of memory */
static int rrtc_extend(rrtc_ctx *c, rrtc_tree *t, const double *target, double range, double *xnew, int *inew, int near) {
    int dim = c->dim, i = near >= 0 ? near : rrtc_nearest(t, target), res;
    const double *xn = t->X + (size_t)dim * i;
    double s = 0.0;
    for (int k = 0; k < dim; ++k) { double d = target[k] - xn[k]; s += d*d; }
    double dist = sqrt(s);
    c->near = i;
    if (c->dd_on && dist > t->rad[i]) { *inew = -1; return RRTC_REJECTED; }
    if (dist <= range) { memcpy(xnew, target, sizeof(double) * (size_t)dim); res = RRTC_REACHED; }
    else {
        double f = range / dist;
        for (int k = 0; k < dim; ++k) xnew[k] = xn[k] + f*(target[k] - xn[k]);
        res = RRTC_ADVANCED;
    }
    *inew = -1;
    int ok = rrtc_edge(c, xn, xnew);
    if (ok < 0) return -1;
    if (!ok) return RRTC_TRAPPED;
    int j = rrtc_tree_add(t, xnew, i);
    if (j < 0) return -1;
    *inew = j;
    return res;
}

/* whether the other tree takes the next iteration: always, unless balancing (ratio > 0) keeps tree A, which just
   tried to grow, growing while |n_A - n_B| / n_A >= ratio (VAMP's tree_ratio) */
static int rrtc_other_turn(const rrtc_tree *A, const rrtc_tree *B, double ratio) {
    return !(ratio > 0.0 && fabs((double)A->n - (double)B->n) / (double)A->n >= ratio);
}

/* the node indices from node i of t up to its root, into idx; returns their count */
static int rrtc_branch(const rrtc_tree *t, int i, int *idx) {
    int n = 0;
    while (i >= 0) { idx[n++] = i; i = t->parent[i]; }
    return n;
}

void rrtc_free(void *p) { free(p); }

/* One RRT-Connect query with shortcuts. Returns a status (RRTC_STATUS in Python); on success *path_out
   (free with rrtc_free) holds *path_len configurations of dim values, start to goal.
   stats[0] iterations, stats[1] nodes of both trees, stats[2] configurations checked, stats[3] and stats[4]
   the nodes of the start's and the goal's tree, stats[5] the longest run of iterations in which one tree
   added no node (up to the last iteration), stats[6] the samples the dynamic domain rejected (drawn again; counted
   in the iterations), stats[7] the configurations of stats[2] checked for the ends (tune[5]). With stall_iterations > 0
   the search stops (status 5) when that run reaches stall_iterations. tune[5] != 0: the start and the goal are first
   checked (within [lower, upper] widened by 1e-9, and valid): status 6 or 7 when one is not; tune[6] != 0: the seed
   is NumPy's (rrtc_numpy_seed: the 64-bit value drawn as the Python side's Generator would draw it). */
int rrtc_plan(const kmodel *m, const unsigned char *active, const double *override_pose, int override_g,
              const rrtc_groups *grp, int dim, const int *jidx, const double *base, const double *start, const double *goal,
              const double *lower, const double *upper, double range, double resolution,
              long long max_iterations, long long max_nodes, long long stall_iterations, int shortcut_iterations,
              int clock_kind, double end_time, unsigned long long seed, int sampler, const double *tune,
              double **path_out, int *path_len, long long *stats) {
    *path_out = NULL; *path_len = 0;
    stats[0] = stats[1] = stats[2] = stats[3] = stats[4] = stats[5] = stats[6] = stats[7] = 0;
    long long rejected = 0;
    if (m->nj > KMAXJ || m->ng > KMAXG || m->nq > KMAXJ || dim > KMAXJ) return -2;
    if (sampler && dim > RRTC_NPRIMES) return -2;
    /* tune: the dynamic domain's radius (0: off), its growth/shrink factor alpha and least radius [rad, -, rad];
       the balance ratio (0: off: the trees alternate; else tree A grows again while |A.n - B.n| / A.n >= it);
       the connection (0: tree B grows toward A's new node; 1: A grows from it toward B's nearest node) */
    double dd_radius = tune ? tune[0] : 0.0, dd_alpha = tune ? tune[1] : 0.0, dd_min = tune ? tune[2] : 0.0;
    double balance = tune ? tune[3] : 0.0;
    int grow_new = tune ? tune[4] != 0.0 : 0;
    int check_ends = tune ? tune[5] != 0.0 : 0;
    if (tune && tune[6] != 0.0) seed = rrtc_numpy_seed(seed);
    rrtc_ctx c;
    memset(&c, 0, sizeof c);
    c.m = m; c.active = active; c.opose = override_pose; c.og = override_g;
    c.dim = dim; c.jidx = jidx; c.res = resolution; c.clock_kind = clock_kind; c.end = end_time; c.hint = -1;
    double *work = (double *)malloc(sizeof(double) * (size_t)(12*KMAXJ + 12*KMAXG + KMAXJ + 4*dim + 3*grp->ngroups));
    rrtc_tree ta, tb;
    memset(&ta, 0, sizeof ta); memset(&tb, 0, sizeof tb);
    int status = 4;
    int *idx = NULL;
    double *path = NULL;
    if (!work) goto done;
    c.oMi = work; c.oMg = work + 12*KMAXJ; c.q = c.oMg + 12*KMAXG; c.x = c.q + KMAXJ;
    double *xr = c.x + dim, *target = xr + dim, *xnew = target + dim;
    c.grp = grp; c.gc = xnew + dim;
    memcpy(c.q, base, sizeof(double) * (size_t)m->nq);
    if (rrtc_use_static_part && rrtc_static_setup(&c) != 0) goto done;
    if (c.smov && rrtc_use_layout && rrtc_layout_setup(&c) != 0) goto done;
    rrtc_rng rng;
    unsigned long long sm = seed;
    for (int k = 0; k < 4; ++k) rng.s[k] = rrtc_splitmix(&sm);

    int plen = 0;
    if (check_ends) {   /* the ends: within the box (widened by 1e-9) and valid */
        for (int e = 0; e < 2; ++e) {
            const double *x = e ? goal : start;
            int in = 1;
            for (int k = 0; k < dim; ++k) in &= x[k] >= lower[k] - 1e-9 && x[k] <= upper[k] + 1e-9;
            if (!in || !rrtc_valid(&c, x)) { status = 6 + e; break; }
        }
        stats[7] = c.checks;
        if (status != 4) goto done;
    }
    int ok = rrtc_edge(&c, start, goal);
    if (ok < 0) goto done;
    if (ok) {
        path = (double *)malloc(sizeof(double) * (size_t)(2*dim));
        if (!path) goto done;
        memcpy(path, start, sizeof(double) * (size_t)dim); memcpy(path + dim, goal, sizeof(double) * (size_t)dim);
        plen = 2; stats[1] = 2; status = 0;
    } else {
        if (rrtc_tree_init(&ta, dim, start) || rrtc_tree_init(&tb, dim, goal)) goto done;
        rrtc_tree *A = &ta, *B = &tb;
        int a_is_start = 1, fa = -1, fb = -1;
        long long it = 0, grew_a = 0, grew_b = 0, longest = 0;   /* the last iteration each tree grew */
        int na_prev = 1, nb_prev = 1;
        double hshift[RRTC_NPRIMES];   /* sampler 1: the Halton points shifted by one uniform vector (mod 1) */
        if (sampler) for (int k = 0; k < dim; ++k) hshift[k] = rrtc_uniform(&rng);
        status = 2;
        while (!rrtc_expired(&c)) {
            if (max_iterations > 0 && it >= max_iterations) { status = 1; break; }
            if (ta.n + tb.n >= max_nodes) { status = 3; break; }
            if (it > 0) {   /* did each tree grow in iteration it? */
                if (ta.n != na_prev) { grew_a = it; na_prev = ta.n; }
                if (tb.n != nb_prev) { grew_b = it; nb_prev = tb.n; }
                long long run = it - (grew_a < grew_b ? grew_a : grew_b);
                if (run > longest) longest = run;
                if (stall_iterations > 0 && run >= stall_iterations) { status = 5; break; }
            }
            it++;
            for (int k = 0; k < dim; ++k) {
                double u = sampler ? rrtc_radical_inverse(rrtc_primes[k], (unsigned long long)it) + hshift[k] : rrtc_uniform(&rng);
                if (u >= 1.0) u -= 1.0;
                xr[k] = lower[k] + (upper[k] - lower[k]) * u;
            }
            c.dd_on = dd_radius > 0.0;
            int ia, ib = -1, res = rrtc_extend(&c, A, xr, range, xnew, &ia, -1);
            c.dd_on = 0;
            if (res < 0) { status = 4; break; }
            if (res == RRTC_REJECTED) { rejected++; continue; }   /* the same tree draws again (an iteration, as VAMP counts) */
            if (dd_radius > 0.0) {   /* the dynamic domain of the extended node (Yershova et al. 2005) */
                double *r = A->rad + c.near;
                if (res == RRTC_TRAPPED) *r = isinf(*r) ? dd_radius : fmax(*r * (1.0 - dd_alpha), dd_min);
                else if (!isinf(*r)) *r *= 1.0 + dd_alpha;
            }
            if (res == RRTC_TRAPPED) {
                if (rrtc_other_turn(A, B, balance)) {
                    rrtc_tree *w = A; A = B; B = w; a_is_start = !a_is_start;
                }
                continue;
            }
            if (grow_new) {   /* A grows from its new node toward B's nearest node, in equal steps of <= range */
                int jb = rrtc_nearest(B, A->X + (size_t)dim * ia);
                const double *xb = B->X + (size_t)dim * jb;
                double s2 = 0.0;
                for (int k = 0; k < dim; ++k) { double d = xb[k] - A->X[(size_t)dim * ia + k]; s2 += d*d; }
                long long nst = (long long)ceil(sqrt(s2) / range), st = 0;
                int prev = ia, bad = 0, stopped = 0;
                for (; st < nst; ++st) {
                    const double *xp = A->X + (size_t)dim * prev;
                    double f = 1.0 / (double)(nst - st);
                    for (int k = 0; k < dim; ++k) xnew[k] = xp[k] + f * (xb[k] - xp[k]);
                    if (st == nst - 1) memcpy(xnew, xb, sizeof(double) * (size_t)dim);
                    int e = rrtc_edge(&c, xp, xnew);
                    if (e < 0) { bad = 1; break; }
                    if (!e) break;
                    int j = rrtc_tree_add(A, xnew, prev);
                    if (j < 0) { bad = 1; break; }
                    prev = j;
                    if (st + 1 < nst && (rrtc_expired(&c) || ta.n + tb.n >= max_nodes)) { stopped = 1; break; }
                }
                if (bad) { status = 4; break; }
                if (!stopped && st >= nst) { fa = prev; fb = jb; status = 0; break; }
            } else {
                memcpy(target, A->X + (size_t)dim * ia, sizeof(double) * (size_t)dim);
                /* connect: after an ADVANCED step the node just added is B's nearest to the target (it lies
                   range closer to it than the previous nearest, and every other node is at least as far as that
                   one), so the scan runs only for the first step: the same search, without a scan per step */
                for (;;) {
                    res = rrtc_extend(&c, B, target, range, xnew, &ib, ib);
                    if (res != RRTC_ADVANCED || rrtc_expired(&c)) break;
                    if (ta.n + tb.n >= max_nodes) break;
                }
                if (res < 0) { status = 4; break; }
                if (res == RRTC_REACHED) { fa = ia; fb = ib; status = 0; break; }
            }
            if (rrtc_other_turn(A, B, balance)) {
                rrtc_tree *w = A; A = B; B = w; a_is_start = !a_is_start;
            }
        }
        stats[0] = it;
        stats[1] = ta.n + tb.n;
        stats[3] = ta.n; stats[4] = tb.n; stats[5] = longest; stats[6] = rejected;
        if (status == 0) {
            idx = (int *)malloc(sizeof(int) * (size_t)(ta.n + tb.n));
            path = (double *)malloc(sizeof(double) * (size_t)dim * (size_t)(ta.n + tb.n));
            if (!idx || !path) { status = 4; goto done; }
            /* A's root -> fa, then fb's parent in B -> B's root (fa and fb hold the same configuration) */
            int na = rrtc_branch(A, fa, idx);
            for (int k = 0; k < na; ++k)
                memcpy(path + (size_t)dim * k, A->X + (size_t)dim * idx[na - 1 - k], sizeof(double) * (size_t)dim);
            int nb = rrtc_branch(B, fb, idx);
            for (int k = 1; k < nb; ++k)
                memcpy(path + (size_t)dim * (na + k - 1), B->X + (size_t)dim * idx[k], sizeof(double) * (size_t)dim);
            plen = na + nb - 1;
            if (!a_is_start) {   /* reverse: start first */
                for (int i = 0, j = plen - 1; i < j; ++i, --j)
                    for (int k = 0; k < dim; ++k) {
                        double w = path[(size_t)dim*i + k]; path[(size_t)dim*i + k] = path[(size_t)dim*j + k]; path[(size_t)dim*j + k] = w;
                    }
            }
        }
    }
    if (status == 0) {
        /* random shortcuts: two distinct nodes i < j with j - i >= 2, replaced by their straight edge when valid */
        for (int s = 0; s < shortcut_iterations && plen > 2; ++s) {
            int i = (int)(rrtc_uniform(&rng) * plen), j = (int)(rrtc_uniform(&rng) * (plen - 1));
            if (i >= plen) i = plen - 1;
            if (j >= plen - 1) j = plen - 2;
            if (j >= i) j++;
            if (i > j) { int w = i; i = j; j = w; }
            if (j - i < 2) continue;
            int e = rrtc_edge(&c, path + (size_t)dim * i, path + (size_t)dim * j);
            if (e < 0) { status = 4; break; }
            if (e) {
                memmove(path + (size_t)dim * (i + 1), path + (size_t)dim * j, sizeof(double) * (size_t)dim * (size_t)(plen - j));
                plen -= j - i - 1;
            }
        }
    }
done:
    stats[2] = c.checks;
    rrtc_tree_free(&ta); rrtc_tree_free(&tb);
    free(idx); free(work); free(c.queue); free((void *)c.pose); free(c.spmem);
    if (status == 0) { *path_out = path; *path_len = plen; }
    else free(path);
    return status;
}
"""

#: the whole source: the random streams and trees, the checks (:mod:`.rrtc_check_csource`), the search
RRTC_SOURCE = _RRTC_HEAD + RRTC_CHECK_SOURCE.lstrip("\n") + _RRTC_SEARCH.lstrip("\n")
