"""The C source of the native RRT-Connect (:mod:`optplan.planners.kernel.rrtc`).

It is appended to the planning kernel's source (:data:`~optplan.planners.kernel.csource.C_SOURCE`:
forward kinematics and the exact primitive tests) and compiled with it into one library, so that a
whole query — sampling, nearest neighbour, extensions, connections, edge checks, path extraction and
shortcuts — is one native call.

What it computes (the algorithm of :func:`optplan.planners.rrtconnect.rrt_connect` and
:func:`~optplan.planners.rrtconnect.shortcut_path`, edges checked as
:func:`~optplan.planners.rrtconnect.edge_is_valid` without weights):

* the search space is ``dim`` joints (indices ``jidx`` into the configuration); the others stay at
  ``base`` (one arm of a regrasp), or all joints (``dim = nq``);
* samples are uniform in the box ``[lower, upper]`` from xoshiro256** (Blackman & Vigna) seeded by
  splitmix64 from one 64-bit seed (the Python side draws it from the planner's NumPy Generator), or
  (``sampler`` 1) the Halton sequence (radical inverses in the first ``dim`` prime bases, point ``i`` at
  iteration ``i``) shifted by one uniform random vector modulo 1 (a Cranley-Patterson rotation: each
  query its own low-discrepancy sequence);
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

__all__ = ["RRTC_SOURCE", "RRTC_STATUS"]

#: the status codes of ``rrtc_plan`` (its return value)
RRTC_STATUS = {0: "found", 1: "iteration cap", 2: "time limit", 3: "node cap", 4: "out of memory", 5: "stalled",
               -2: "model too large for the kernel"}

RRTC_SOURCE = r"""
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

/* the broad phase: the pairs sorted into blocks by the groups of their two geometries (a group is the
   geometries of one joint, or one geometry on its own), each group bounded by one sphere; a block is
   skipped when its two spheres are farther apart than their radii and the margin, and a block of one capsule or
   box on no joint (an obstacle) and a joint's group when the group's sphere is farther than the margin from that
   primitive (exact: a long beam's bounding sphere meets nearly every link's) */
typedef struct {
    int ngroups, nblocks;
    const int *gkind;        /* ngroups: 0 one geometry (its pose's origin), 1 the geometries of a joint */
    const int *gref;         /* ngroups: the geometry (kind 0) or the joint (kind 1) */
    const double *gcenter;   /* ngroups x 3: the centre in the joint frame (kind 1) */
    const double *gradius;   /* ngroups: the radius [m] */
    const int *bstart;       /* nblocks + 1: the block's range in perm */
    const int *bga, *bgb;    /* nblocks: the block's groups */
    const int *perm;         /* npairs: pair indices, block after block */
    const unsigned char *gbox;   /* ngroups: 1 when a member of the group is a box */
} rrtc_groups;

/* 1 when the sphere (o, R) is farther than thr from the capsule or box g (exact; 0 when unknown: a sphere, whose
   bounding sphere the caller has tested, or a box against a group with a box, whose pair test is the conservative
   separating-axis one and may call a pair in contact that this test would call apart) */
static int rrtc_sphere_apart(const kmodel *m, const double **pose, int g, const double *o, double R, double thr,
                             int group_has_box) {
    int t = m->gtype[g];
    const double *P = pose[g], *prm = m->gparam + 3*g;
    if (t == 1) {
        double a[3], b[3], r = prm[0] + R + thr;
        capsule_ends(P, prm, a, b);
        return ptseg2(o, a, b) > r*r;
    }
    if (t == 2 && !group_has_box) {
        double x[3], r = R + thr;
        to_local(P, o, x);
        return ptbox2(x, prm) > r*r;
    }
    return 0;
}

typedef struct {
    const kmodel *m; const unsigned char *active; const double *opose; int og;
    const rrtc_groups *grp; double *gc;
    int dim; const int *jidx; double *q; double *oMi, *oMg; double res;
    int *queue; long long qcap; double *x;
    long long checks;
    int clock_kind; double end; int tick; int hint;
    /* the static part (NULL smov: none, every check computes everything): joints and geometries that no
       searched joint moves keep the placements of the first full FK; blocks of two static groups are
       checked once (static_hit: one of their pairs collides, so every configuration does) */
    const double **pose;          /* the geometries' poses, kept between checks */
    int nmj, nmg; int *mj, *mg;   /* the moving joints (parents first) and moving geometries */
    unsigned char *smov;          /* ngroups: 1 when the group moves */
    int static_hit;
    /* the blocks that a check tests, laid out for it (with the static part): per moving group, its blocks with a
       still group as arrays of the still group's centre, the squared sum of the radii and margin, the block; then
       the blocks of two moving groups */
    int nmv, nmm; int *mv, *sps, *spb, *mmb; double *spx, *spy, *spz, *sprr; long long *sph; void *spmem;
    int dd_on; int near;          /* the dynamic domain applies (sample extensions only); the last extension's node */
} rrtc_ctx;

static double rrtc_now(int kind) {
    struct timespec ts;
    clock_gettime(kind ? CLOCK_PROCESS_CPUTIME_ID : CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}
/* the deadline, read every 8th call */
static int rrtc_expired(rrtc_ctx *c) {
    if ((c->tick++ & 7) != 0) return 0;
    return rrtc_now(c->clock_kind) >= c->end;
}

/* block b whose spheres meet: 1 when one of its active pairs (other than the hint h) collides (it becomes the
   hint); an obstacle's capsule or box is first tested exactly against the joint group's sphere */
static int rrtc_block(rrtc_ctx *c, const double **pose, int b, double thr, int h) {
    const kmodel *m = c->m;
    const rrtc_groups *G = c->grp;
    int ga = G->bga[b], gb = G->bgb[b];
    if ((G->gkind[ga] == 0) != (G->gkind[gb] == 0)) {   /* one capsule or box (an obstacle) against a joint's
                                                           group: the exact distance from the group's sphere */
        int og = G->gkind[ga] == 0 ? ga : gb, jg = og == ga ? gb : ga;
        if (rrtc_sphere_apart(m, pose, G->gref[og], c->gc + 3*jg, G->gradius[jg], thr, G->gbox[jg])) return 0;
    }
    for (int i = G->bstart[b]; i < G->bstart[b+1]; ++i) {
        int k = G->perm[i];
        if (k != h && c->active[k] && pair_collides(m, pose, m->pa[k], m->pb[k])) { c->hint = k; return 1; }
    }
    return 0;
}

/* the kernel's configuration check (the same verdict: any active pair in contact), the pair that
   collided last tried first (a blocked region is usually blocked by the same pair again), then the
   blocks of the broad phase */
static int rrtc_valid(rrtc_ctx *c, const double *x) {
    const kmodel *m = c->m;
    const rrtc_groups *G = c->grp;
    const double *pose_local[KMAXG];
    const double **pose = c->smov ? c->pose : pose_local;
    for (int k = 0; k < c->dim; ++k) c->q[c->jidx[k]] = x[k];
    c->checks++;
    if (c->smov) {
        if (c->static_hit) return 0;
        for (int t = 0; t < c->nmj; ++t) fk_joint(m, c->q, c->oMi, c->mj[t]);
        for (int t = 0; t < c->nmg; ++t) fk_geom(m, c->opose, c->og, c->oMi, c->oMg, pose, 0, c->mg[t]);
    } else fk(m, c->q, c->opose, c->og, c->oMi, c->oMg, pose);
    int h = c->hint;
    if (h >= 0 && c->active[h] && pair_collides(m, pose, m->pa[h], m->pb[h])) return 0;
    for (int i = 0; i < G->ngroups; ++i) {
        if (c->smov && !c->smov[i]) continue;
        double *o = c->gc + 3*i;
        if (G->gkind[i] == 0) { const double *P = pose[G->gref[i]]; o[0] = P[9]; o[1] = P[10]; o[2] = P[11]; }
        else {
            const double *P = c->oMi + 12*G->gref[i], *l = G->gcenter + 3*i;
            for (int r = 0; r < 3; ++r) o[r] = P[3*r]*l[0] + P[3*r+1]*l[1] + P[3*r+2]*l[2] + P[9+r];
        }
    }
    double thr = m->margin + KEPS;
    if (c->mv) {   /* the laid-out blocks: each moving group's sphere against its still partners, in one pass */
        for (int u = 0; u < c->nmv; ++u) {
            const double *o = c->gc + 3*c->mv[u];
            const double ox = o[0], oy = o[1], oz = o[2];
            int t0 = c->sps[u], t1 = c->sps[u+1];
            const double *__restrict sx = c->spx, *__restrict sy = c->spy, *__restrict sz = c->spz,
                         *__restrict srr = c->sprr;
            long long *__restrict hit = c->sph;
            for (int t = t0; t < t1; ++t) {   /* no branch, no aliasing: vectorised */
                double dx = ox - sx[t], dy = oy - sy[t], dz = oz - sz[t];
                hit[t] = dx*dx + dy*dy + dz*dz <= srr[t];
            }
            for (int t = t0; t < t1; ++t)
                if (c->sph[t] && rrtc_block(c, pose, c->spb[t], thr, h)) return 0;
        }
        for (int u = 0; u < c->nmm; ++u) {
            int b = c->mmb[u], ga = G->bga[b], gb = G->bgb[b];
            const double *A = c->gc + 3*ga, *B = c->gc + 3*gb;
            double dx = A[0]-B[0], dy = A[1]-B[1], dz = A[2]-B[2], rr = G->gradius[ga] + G->gradius[gb] + thr;
            if (dx*dx + dy*dy + dz*dz > rr*rr) continue;
            if (rrtc_block(c, pose, b, thr, h)) return 0;
        }
        return 1;
    }
    for (int b = 0; b < G->nblocks; ++b) {
        int ga = G->bga[b], gb = G->bgb[b];
        if (c->smov && !c->smov[ga] && !c->smov[gb]) continue;
        const double *A = c->gc + 3*ga, *B = c->gc + 3*gb;
        double dx = A[0]-B[0], dy = A[1]-B[1], dz = A[2]-B[2], rr = G->gradius[ga] + G->gradius[gb] + thr;
        if (dx*dx + dy*dy + dz*dz > rr*rr) continue;
        if (rrtc_block(c, pose, b, thr, h)) return 0;
    }
    return 1;
}

/* 0: checks test the blocks in their order (for comparisons; the verdicts are the same) */
int rrtc_use_layout = 1;

/* the layout of the blocks that a check tests (after the static part: smov and the still groups' centres set);
   0, or -1 out of memory (then c->mv stays NULL: the blocks in their order) */
static int rrtc_layout_setup(rrtc_ctx *c) {
    const kmodel *m = c->m;
    const rrtc_groups *G = c->grp;
    int ng = G->ngroups, nb = G->nblocks;
    double thr = m->margin + KEPS;
    size_t bytes = sizeof(double) * 4 * (size_t)nb + sizeof(long long) * (size_t)nb
                   + sizeof(int) * (size_t)(ng + (ng + 1) + nb + nb) + 64;
    char *mem = (char *)malloc(bytes);
    if (!mem) return -1;
    double *dm = (double *)mem;
    c->spx = dm; c->spy = dm + nb; c->spz = dm + 2*nb; c->sprr = dm + 3*nb;
    c->sph = (long long *)(dm + 4*nb);
    int *im = (int *)(c->sph + nb);
    c->mv = im; c->sps = im + ng; c->spb = c->sps + ng + 1; c->mmb = c->spb + nb;
    c->nmv = 0; c->nmm = 0;
    int nt = 0;
    for (int i = 0; i < ng; ++i) {
        if (!c->smov[i]) continue;
        c->sps[c->nmv] = nt;
        c->mv[c->nmv++] = i;
        for (int b = 0; b < nb; ++b) {
            int ga = G->bga[b], gb = G->bgb[b];
            if ((ga != i && gb != i) || (c->smov[ga] && c->smov[gb])) continue;
            const double *S = c->gc + 3*(ga == i ? gb : ga);
            double rr = G->gradius[ga] + G->gradius[gb] + thr;
            c->spx[nt] = S[0]; c->spy[nt] = S[1]; c->spz[nt] = S[2]; c->sprr[nt] = rr*rr; c->spb[nt] = b;
            nt++;
        }
    }
    c->sps[c->nmv] = nt;
    for (int b = 0; b < nb; ++b)
        if (c->smov[G->bga[b]] && c->smov[G->bgb[b]]) c->mmb[c->nmm++] = b;
    c->spmem = mem;
    return 0;
}

/* 0: every check computes the whole model (for comparisons; the verdicts are the same) */
int rrtc_use_static_part = 1;

/* the static part of a query that searches the joints jidx[0..dim) with the others at c->q: one full FK, the
   moving joints and geometries listed, the static groups' centres placed and the blocks of two static groups
   checked once. 0, or -1 out of memory (then c->smov stays NULL: every check computes everything) */
static int rrtc_static_setup(rrtc_ctx *c) {
    const kmodel *m = c->m;
    const rrtc_groups *G = c->grp;
    size_t bytes = sizeof(const double *) * (size_t)m->ng + sizeof(int) * (size_t)(m->nj + m->ng)
                   + (size_t)G->ngroups + (size_t)m->nj + (size_t)m->nq + 16;
    char *mem = (char *)malloc(bytes);
    if (!mem) return -1;
    c->pose = (const double **)mem;
    c->mj = (int *)(mem + sizeof(const double *) * (size_t)m->ng);
    c->mg = c->mj + m->nj;
    unsigned char *smov = (unsigned char *)(c->mg + m->ng), *jmov = smov + G->ngroups, *qmov = jmov + m->nj;
    memset(qmov, 0, (size_t)m->nq);
    for (int k = 0; k < c->dim; ++k) qmov[c->jidx[k]] = 1;
    c->nmj = 0; c->nmg = 0;
    jmov[0] = 0;
    for (int j = 1; j < m->nj; ++j) {
        jmov[j] = (unsigned char)(jmov[m->jparent[j]] || (m->jtype[j] != 0 && qmov[m->jidx[j]]));
        if (jmov[j]) c->mj[c->nmj++] = j;
    }
    for (int g = 0; g < m->ng; ++g)
        if (g != c->og && m->gparent[g] != 0 && jmov[m->gparent[g]]) c->mg[c->nmg++] = g;
    fk(m, c->q, c->opose, c->og, c->oMi, c->oMg, c->pose);
    for (int i = 0; i < G->ngroups; ++i) {
        int r = G->gref[i];
        smov[i] = G->gkind[i] == 0 ? (unsigned char)(r != c->og && m->gparent[r] != 0 && jmov[m->gparent[r]])
                                   : jmov[r];
        if (smov[i]) continue;
        double *o = c->gc + 3*i;
        if (G->gkind[i] == 0) { const double *P = c->pose[r]; o[0] = P[9]; o[1] = P[10]; o[2] = P[11]; }
        else {
            const double *P = c->oMi + 12*r, *l = G->gcenter + 3*i;
            for (int k = 0; k < 3; ++k) o[k] = P[3*k]*l[0] + P[3*k+1]*l[1] + P[3*k+2]*l[2] + P[9+k];
        }
    }
    double thr = m->margin + KEPS;
    c->static_hit = 0;
    for (int b = 0; b < G->nblocks && !c->static_hit; ++b) {
        int ga = G->bga[b], gb = G->bgb[b];
        if (smov[ga] || smov[gb]) continue;
        const double *A = c->gc + 3*ga, *B = c->gc + 3*gb;
        double dx = A[0]-B[0], dy = A[1]-B[1], dz = A[2]-B[2], rr = G->gradius[ga] + G->gradius[gb] + thr;
        if (dx*dx + dy*dy + dz*dz > rr*rr) continue;
        for (int i = G->bstart[b]; i < G->bstart[b+1]; ++i) {
            int k = G->perm[i];
            if (c->active[k] && pair_collides(m, c->pose, m->pa[k], m->pb[k])) { c->static_hit = 1; break; }
        }
    }
    c->smov = smov;
    return 0;
}

/* the broad-phase check of the configurations Q (M x nq), for tests: out[i] = 1 when row i is free */
void rrtc_check_batch(const kmodel *m, const unsigned char *active, const double *override_pose, int override_g,
                      const rrtc_groups *grp, long long M, const double *Q, unsigned char *out) {
    double *work = (double *)malloc(sizeof(double) * (size_t)(12*KMAXJ + 12*KMAXG + 3*grp->ngroups + 1));
    int *jidx = (int *)malloc(sizeof(int) * (size_t)(m->nq + 1));
    if (!work || !jidx) { free(work); free(jidx); return; }
    rrtc_ctx c;
    memset(&c, 0, sizeof c);
    c.m = m; c.active = active; c.opose = override_pose; c.og = override_g; c.grp = grp; c.hint = -1;
    c.oMi = work; c.oMg = work + 12*KMAXJ; c.gc = c.oMg + 12*KMAXG; c.dim = m->nq; c.jidx = jidx;
    for (int k = 0; k < m->nq; ++k) jidx[k] = k;
    double q[KMAXJ];
    c.q = q;
    for (long long i = 0; i < M; ++i) out[i] = (unsigned char)rrtc_valid(&c, Q + i*m->nq);
    free(work); free(jidx);
}

/* the straight edge a -> b: 1 valid, 0 not, -1 out of memory */
static int rrtc_edge(rrtc_ctx *c, const double *a, const double *b) {
    int dim = c->dim;
    double size = 0.0;
    for (int k = 0; k < dim; ++k) { double d = fabs(b[k] - a[k]); if (d > size) size = d; }
    double nn = ceil(size / c->res);
    long long n = nn < 1.0 ? 1 : (long long)nn;
    if (!rrtc_valid(c, b)) return 0;
    if (n < 2) return 1;
    if (4*n + 4 > c->qcap) {   /* at most 2n - 1 intervals are queued, two ints each */
        int *qq = (int *)realloc(c->queue, sizeof(int) * (size_t)(4*n + 4));
        if (!qq) return -1;
        c->queue = qq; c->qcap = 4*n + 4;
    }
    /* coarse to fine: FIFO of intervals [lo, hi]; each with hi - lo >= 2 gives its midpoint, then its halves */
    int *Q = c->queue;
    long long head = 0, tail = 0;
    Q[tail++] = 0; Q[tail++] = (int)n;
    while (head < tail) {
        int lo = Q[head++], hi = Q[head++];
        if (hi - lo < 2) continue;
        int mid = (lo + hi) / 2;
        double f = (double)mid / (double)n;
        for (int k = 0; k < dim; ++k) c->x[k] = a[k] + f*(b[k] - a[k]);
        if (!rrtc_valid(c, c->x)) return 0;
        Q[tail++] = lo; Q[tail++] = mid; Q[tail++] = mid; Q[tail++] = hi;
    }
    return 1;
}

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
   in the iterations). With stall_iterations > 0 the search stops (status 5) when that run reaches stall_iterations. */
int rrtc_plan(const kmodel *m, const unsigned char *active, const double *override_pose, int override_g,
              const rrtc_groups *grp, int dim, const int *jidx, const double *base, const double *start, const double *goal,
              const double *lower, const double *upper, double range, double resolution,
              long long max_iterations, long long max_nodes, long long stall_iterations, int shortcut_iterations,
              int clock_kind, double end_time, unsigned long long seed, int sampler, const double *tune,
              double **path_out, int *path_len, long long *stats) {
    *path_out = NULL; *path_len = 0;
    stats[0] = stats[1] = stats[2] = stats[3] = stats[4] = stats[5] = stats[6] = 0;
    long long rejected = 0;
    if (m->nj > KMAXJ || m->ng > KMAXG || m->nq > KMAXJ || dim > KMAXJ) return -2;
    if (sampler && dim > RRTC_NPRIMES) return -2;
    /* tune: the dynamic domain's radius (0: off), its growth/shrink factor alpha and least radius [rad, -, rad];
       the balance ratio (0: off: the trees alternate; else tree A grows again while |A.n - B.n| / A.n >= it);
       the connection (0: tree B grows toward A's new node; 1: A grows from it toward B's nearest node) */
    double dd_radius = tune ? tune[0] : 0.0, dd_alpha = tune ? tune[1] : 0.0, dd_min = tune ? tune[2] : 0.0;
    double balance = tune ? tune[3] : 0.0;
    int grow_new = tune ? tune[4] != 0.0 : 0;
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
                if (!(balance > 0.0 && fabs((double)A->n - (double)B->n) / (double)A->n >= balance)) {
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
            if (!(balance > 0.0 && fabs((double)A->n - (double)B->n) / (double)A->n >= balance)) {
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
