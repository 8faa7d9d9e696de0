"""The C source of the native RRT-Connect's configuration and edge checks (:mod:`optplan.planners.kernel.rrtc`):
the broad phase and its layout, the still part of a query placed once, the batch check for the tests and the edge
check; the search itself is in :mod:`.rrtc_csource`, which places this text inside its own (one compiled source).

* the broad phase: the pairs sorted into blocks by the groups of their two geometries (a group: the geometries of
  one joint, or one geometry), each group bounded by one sphere; a block is skipped when the spheres are apart, and
  a block of an obstacle's capsule or box and a joint's group when the group's sphere is apart from that primitive
  (exact; a box against a group with a box is left to the pairs);
* with the still part: the joints and geometries no searched joint moves are placed once per query and their blocks
  checked once, and the blocks a check tests are laid out per moving group (the still partners' centres and squared
  radius sums as arrays, tested in one vectorised pass);
* a block of two joints' groups (a spherized link beside its wrist: hundreds of sphere pairs) tests each member's
  bounding sphere against the other group's sphere first, and skips the pairs of a member apart from it (the pairs
  are in runs of one first geometry: a run at once); the member is tested in its joint's frame, where its centre is
  its placement, against the other sphere's centre brought into that frame once per block (no member is placed
  for this test); with at most 64 members a group, the members near the other sphere are one 64-bit mask per side
  (a branch-free pass), a run's pairs are ordered by their second member, and only the pairs whose both members are
  near are visited (the bits of the run's mask and the near mask; a pair found by its rank in the run's mask):
  0.74 → 0.47 µs per check of VAMP's sphere Panda on MBM scenes (2026-11-30);
* with the still part, a moving geometry is placed when a test first needs it in a check (most of a sphere robot's
  spheres are never needed when their joint's group is apart from everything);
* the pair that collided last is tried first; the verdicts are the kernel's.
"""
from __future__ import annotations

__all__ = ["RRTC_CHECK_SOURCE"]

RRTC_CHECK_SOURCE = r"""
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
    const int *ggroup;       /* ng: the group of each geometry */
    const int *rownext;      /* npairs: the position in perm after the run of pairs with the same first geometry */
    /* a block of two joints' groups of at most 64 members each (bmask[b] = 1): its runs' pairs ordered by the
       member index of their second geometry, and at a run's first position the mask of those member indices */
    const unsigned char *bmask;        /* nblocks */
    const int *gmstart, *gmlist;       /* ngroups + 1, and the members of each group (joint groups; ascending) */
    const int *gmidx;                  /* ng: a geometry's index among its group's members */
    const unsigned long long *runmask; /* npairs: at a run's first position, the run's second members' mask */
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
    /* a block of two joints' groups: per geometry, whether its bounding sphere is apart from the other group's
       sphere (then none of its pairs in the block can be in contact), computed once per block test (stamped) */
    unsigned gtick; unsigned gst[KMAXG]; unsigned char gfar[KMAXG];
    /* with the static part, a moving geometry (gmv) is placed when a test first needs it in a check (stamped) */
    unsigned ptick; unsigned pst[KMAXG]; unsigned char gmv[KMAXG];
} rrtc_ctx;

/* 0: a block of two joints' groups tests its pairs run by run without the members' masks (for comparisons; the
   verdicts are the same) */
int rrtc_use_masks = 1;

/* geometry g placed for the current check (a moving geometry's pose is computed at its first use in the check) */
static inline void rrtc_need(rrtc_ctx *c, const double **pose, int g) {
    if (c->gmv[g] && c->pst[g] != c->ptick) {
        fk_geom(c->m, c->opose, c->og, c->oMi, c->oMg, pose, 0, g);
        c->pst[g] = c->ptick;
    }
}

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
    else if (ga != gb && G->gkind[ga] == 1 && G->gkind[gb] == 1) {
        /* two joints' groups (many pairs when two links stay close, e.g. a wrist's spheres): a geometry whose
           bounding sphere is apart from the other group's sphere is apart from every member of that group (the
           group's sphere holds the members' spheres), so pair_collides would reject its pairs at its first test */
        if (++c->gtick == 0) { memset(c->gst, 0, sizeof c->gst); c->gtick = 1; }   /* wrapped: no stale stamp */
        unsigned tick = c->gtick;
        /* each group's sphere centre in the other group's joint frame (R^T (o - p)): a member is tested at its
           centre in its joint's frame (the geometry's placement there), without placing it in the world; the
           rounding (~1e-15 m) is far below the groups' radii's slack (1e-12) */
        double ol[2][3], orr[2];
        for (int side = 0; side < 2; ++side) {
            const double *P = c->oMi + 12*G->gref[side ? gb : ga], *o = c->gc + 3*(side ? ga : gb);
            double v0 = o[0] - P[9], v1 = o[1] - P[10], v2 = o[2] - P[11];
            for (int r = 0; r < 3; ++r) ol[side][r] = P[r]*v0 + P[3+r]*v1 + P[6+r]*v2;
            orr[side] = G->gradius[side ? ga : gb] + thr;
        }
        int end = G->bstart[b+1];
        if (rrtc_use_masks && G->bmask[b]) {
            /* each group's members near the other group's sphere, as a mask (a branch-free pass); then per run of
               a near first member, its pairs whose second member is near: the bits of the run's mask and the near
               mask, a pair found by its rank in the run's mask (its pairs are in member order) */
            unsigned long long near[2] = {0, 0};
            for (int side = 0; side < 2; ++side) {
                int grp = side ? gb : ga, t0 = G->gmstart[grp], n = G->gmstart[grp+1] - t0;
                const double *o = ol[side];
                unsigned long long mk = 0;
                for (int u = 0; u < n; ++u) {
                    int g = G->gmlist[t0 + u];
                    const double *L = m->gplace + 12*g + 9;
                    double dx = L[0]-o[0], dy = L[1]-o[1], dz = L[2]-o[2], rr = m->grad[g] + orr[side];
                    mk |= (unsigned long long)(dx*dx + dy*dy + dz*dz <= rr*rr) << u;
                }
                near[side] = mk;
            }
            for (int i = G->bstart[b]; i < end; i = G->rownext[i]) {
                int a = m->pa[G->perm[i]], sa = G->ggroup[a] != ga;
                if (!((near[sa] >> G->gmidx[a]) & 1ULL)) continue;
                unsigned long long rm = G->runmask[i], cand = rm & near[!sa];
                while (cand) {
                    int bit = __builtin_ctzll(cand);
                    cand &= cand - 1;
                    int k = G->perm[i + __builtin_popcountll(rm & ((1ULL << bit) - 1ULL))];
                    if (k == h || !c->active[k]) continue;
                    rrtc_need(c, pose, m->pa[k]); rrtc_need(c, pose, m->pb[k]);
                    if (pair_collides(m, pose, m->pa[k], m->pb[k])) { c->hint = k; return 1; }
                }
            }
            return 0;
        }
        for (int i = G->bstart[b]; i < end; ) {
            int run = G->rownext[i];
            for (int e = 0; e < 2; ++e) {   /* the run's first geometry, then each pair's second */
                for (; i < run; ++i) {
                    int k = G->perm[i];
                    int g = e ? m->pb[k] : m->pa[k];
                    if (c->gst[g] != tick) {
                        int side = G->ggroup[g] != ga;
                        const double *L = m->gplace + 12*g + 9, *o = ol[side];
                        double dx = L[0]-o[0], dy = L[1]-o[1], dz = L[2]-o[2], rr = m->grad[g] + orr[side];
                        c->gst[g] = tick;
                        c->gfar[g] = dx*dx + dy*dy + dz*dz > rr*rr;
                    }
                    if (!e) { if (c->gfar[g]) i = run; break; }   /* far: the whole run is apart */
                    if (c->gfar[g] || k == h || !c->active[k]) continue;
                    rrtc_need(c, pose, m->pa[k]); rrtc_need(c, pose, m->pb[k]);
                    if (pair_collides(m, pose, m->pa[k], m->pb[k])) { c->hint = k; return 1; }
                }
            }
        }
        return 0;
    }
    for (int i = G->bstart[b]; i < G->bstart[b+1]; ++i) {
        int k = G->perm[i];
        if (k == h || !c->active[k]) continue;
        rrtc_need(c, pose, m->pa[k]); rrtc_need(c, pose, m->pb[k]);
        if (pair_collides(m, pose, m->pa[k], m->pb[k])) { c->hint = k; return 1; }
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
        if (++c->ptick == 0) { memset(c->pst, 0, sizeof c->pst); c->ptick = 1; }   /* wrapped: no stale stamp */
    } else fk(m, c->q, c->opose, c->og, c->oMi, c->oMg, pose);
    int h = c->hint;
    if (h >= 0 && c->active[h]) {
        rrtc_need(c, pose, m->pa[h]); rrtc_need(c, pose, m->pb[h]);
        if (pair_collides(m, pose, m->pa[h], m->pb[h])) return 0;
    }
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
        if (g != c->og && m->gparent[g] != 0 && jmov[m->gparent[g]]) { c->mg[c->nmg++] = g; c->gmv[g] = 1; }
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

/* the search's own check (the static part and the blocks' layout as rrtc_plan sets them up) of the rows of X
   (M x dim values of the joints jidx, the others at base), for tests: out[i] = 1 when row i is free; -1 out of
   memory or too large a model */
int rrtc_check_batch_search(const kmodel *m, const unsigned char *active, const double *override_pose, int override_g,
                            const rrtc_groups *grp, int dim, const int *jidx, const double *base, long long M,
                            const double *X, unsigned char *out) {
    if (m->nj > KMAXJ || m->ng > KMAXG || m->nq > KMAXJ || dim > KMAXJ) return -1;
    double *work = (double *)malloc(sizeof(double) * (size_t)(12*KMAXJ + 12*KMAXG + KMAXJ + 3*grp->ngroups + 1));
    rrtc_ctx *c = (rrtc_ctx *)calloc(1, sizeof(rrtc_ctx));
    int rc = -1;
    if (!work || !c) goto done;
    c->m = m; c->active = active; c->opose = override_pose; c->og = override_g; c->grp = grp; c->hint = -1;
    c->dim = dim; c->jidx = jidx; c->oMi = work; c->oMg = work + 12*KMAXJ; c->q = c->oMg + 12*KMAXG;
    c->gc = c->q + KMAXJ;
    memcpy(c->q, base, sizeof(double) * (size_t)m->nq);
    if (rrtc_use_static_part && rrtc_static_setup(c) != 0) goto done;
    if (c->smov && rrtc_use_layout && rrtc_layout_setup(c) != 0) goto done;
    for (long long i = 0; i < M; ++i) out[i] = (unsigned char)rrtc_valid(c, X + i*dim);
    rc = 0;
done:
    if (c) { free((void *)c->pose); free(c->spmem); }
    free(c); free(work);
    return rc;
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

"""
