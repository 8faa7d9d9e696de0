"""The C source of the native planning kernel (:mod:`optplan.planners.kernel.native`).

Kept as a string in a Python module so that it ships with the package without any packaging change;
:func:`optplan.planners.kernel.native.load_library` compiles it with the system C compiler at first
use and caches the shared library under :func:`optplan.codegen.cache_dir`, keyed by a hash of this
text.

What it computes, for a batch of configurations: the forward kinematics of a tree of 1-dof revolute
and prismatic joints, the world placement of every geometry (spheres, capsules along local z, boxes;
a geometry may have its placement given per call: the still object of a regrasp), then the listed
geometry pairs in order — a bounding-sphere test, then the exact boolean test of the two primitives
(distance ≤ margin + ``KERNEL_EPS`` counts as colliding, so the verdict never says free where the
exact distance is ≤ margin, nor where coal calls the pair colliding within its 1e-6 m GJK tolerance; box-box
pairs: separating axes, the world axes first, so that a pair tried first — the last one in collision — gets
the verdict the broad phase's boxes give it) — stopping at the first configuration in collision.
"""
from __future__ import annotations

__all__ = ["C_SOURCE", "KERNEL_EPS"]

#: slack [m] added to every contact threshold: the kernel calls a pair colliding when its exact
#: distance is below margin + this, so neither rounding nor coal's tolerance turns a contact into a free
#: verdict. coal (the reference checks, and the benchmark's sweep check) calls pairs colliding up to its
#: GJK tolerance (1e-6 m) apart: two boxes 8e-7 m apart edge to edge are colliding for coal; 10x that
#: tolerance keeps every placement coal calls colliding colliding here too.
KERNEL_EPS = 1e-5

C_SOURCE = r"""
#include <math.h>
#include <string.h>

#define KMAXJ 256
#define KMAXG 1024
#define KEPS @KERNEL_EPS@

/* counters of a profiling build (KCOUNT defined: optplan.bench.planning_kernel --counters): checks,
   pairs tested, exact tests, group-obstacle box tests, link-obstacle box tests, bucket tests,
   link-link box tests */
#ifdef KCOUNT
long long kcount[8];
#define KCNT(i, n) (kcount[i] += (n))
#else
#define KCNT(i, n) ((void)0)
#endif

typedef struct {
    int nq, nj, ng, npairs;
    const int *jparent;      /* nj: parent joint (joint 0 = universe) */
    const int *jtype;        /* nj: 0 none/universe, 1 revolute (axis), 2 prismatic, 3/4/5 revolute about x/y/z */
    const int *jidx;         /* nj: index into q */
    const double *jplace;    /* nj x 12: R row-major, p */
    const double *jaxis;     /* nj x 3: unit axis in the joint frame */
    const int *gparent;      /* ng: parent joint */
    const int *gtype;        /* ng: 0 sphere, 1 capsule (z), 2 box */
    const double *gplace;    /* ng x 12 */
    const double *gparam;    /* ng x 3: sphere r; capsule r, half length; box half extents */
    const double *grad;      /* ng: bounding-sphere radius about the geometry origin */
    const int *pa, *pb;      /* npairs */
    double margin;
    /* the broad phase (nstat = 0: none, the pair loop alone). Moving geometries (parent joint != 0) in
       groups (a few consecutive links of a chain); static ones (parent joint 0) with their world AABB
       inflated by margin + KEPS. A check (also one placing a static geometry: its box made per call, scol): the AABB of each group, then of each
       moving geometry, against every static AABB (branch-free loops over the statics), the exact test
       only where the boxes overlap; then the remaining pairs (moving-moving) in their order. */
    int nmov, nstat, ngrp, nrest;
    const int *mov;          /* nmov: moving geometries, group after group */
    const int *grp;          /* ngrp + 1: group g is mov[grp[g] .. grp[g+1]) */
    const double *saabb;     /* 6 x nstat: lo x, lo y, lo z, hi x, hi y, hi z of each static geometry */
    const int *ms_pair;      /* nmov x nstat: the pair index of (mov[i], static j), -1 when not a pair */
    const int *rest;         /* nrest: the pairs in neither ms_pair nor a bucket, in their order */
    int *hint;               /* 1: the pair that collided last (tried first), -1 none; may be NULL */
    int nbuck;               /* pairs of two moving geometries, in buckets by their two groups */
    const int *bstart;       /* nbuck + 1: bucket b is bperm[bstart[b] .. bstart[b+1]) */
    const int *bga, *bgb;    /* nbuck: its two groups */
    const int *bperm;        /* the pair indices, bucket after bucket */
    const int *mrow;         /* ng: a geometry's row in mov, -1 for a static one */
    const int *jperm;        /* nj x 3, may be NULL: when the rotation of a joint's placement is a signed
                                permutation, column c is +-(row jperm[c] - 1) of the identity; else 0 0 0 */
    const int *scol;         /* ng, may be NULL: a static geometry's column in saabb / ms_pair, -1 otherwise. With
                                it a check that places a static geometry per call (the still object) keeps the
                                broad phase: that column's box is the placed geometry's, made per call */
} kmodel;

static void compose(const double *A, const double *B, double *C) {
    /* C = A * B, poses as R row-major (9) then p (3) */
    double R[9], p[3];
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j)
            R[3*i+j] = A[3*i]*B[j] + A[3*i+1]*B[3+j] + A[3*i+2]*B[6+j];
        p[i] = A[3*i]*B[9] + A[3*i+1]*B[10] + A[3*i+2]*B[11] + A[9+i];
    }
    memcpy(C, R, sizeof R); memcpy(C + 9, p, sizeof p);
}

/* sin x and cos x, inline, within 1 ulp: the argument reduced by the nearest multiple n of pi/2 (fdlibm's
   __ieee754_rem_pio2 for |x| < 1e5: pi/2 in parts, exact products, a 2nd and 3rd round where the remainder
   cancels), then fdlibm's kernel polynomials on [-pi/4, pi/4] with the
   reduction's tail, the quadrant from n & 3. |x| >= 1e5, inf and nan go to libm. (fdlibm: Copyright (C) 1993 by
   Sun Microsystems, Inc. All rights reserved. Developed at SunSoft, a Sun Microsystems, Inc. business.
   Permission to use, copy, modify, and distribute this software is freely granted, provided that this notice is
   preserved.) In a loop ~10 ns a call against 17.5 ns for glibc's sincos (2026-11-30); the last bit differs from
   glibc's for ~6 % of angles in [-4, 4] (tests/test_planning_kernel.py). */
static const double KSIN_S1 = -1.66666666666666324348e-01, KSIN_S2 = 8.33333333332248946124e-03,
    KSIN_S3 = -1.98412698298579493134e-04, KSIN_S4 = 2.75573137070700676789e-06,
    KSIN_S5 = -2.50507602534068634195e-08, KSIN_S6 = 1.58969099521155010221e-10,
    KCOS_C1 = 4.16666666666666019037e-02, KCOS_C2 = -1.38888888888741095749e-03,
    KCOS_C3 = 2.48015872894767294178e-05, KCOS_C4 = -2.75573143513906633035e-07,
    KCOS_C5 = 2.08757232129817482790e-09, KCOS_C6 = -1.13596475577881948265e-11,
    KINV_PIO2 = 6.36619772367581382433e-01, KPIO2_1 = 1.57079632673412561417e+00,
    KPIO2_1T = 6.07710050650619224932e-11, KPIO2_2 = 6.07710050630396597660e-11,
    KPIO2_2T = 2.02226624879595063154e-21, KPIO2_3 = 2.02226624871116645580e-21,
    KPIO2_3T = 8.47842766036889956997e-32;

static inline void kin_sincos(double x, double *s, double *c) {
    if (!(fabs(x) < 1e5)) { *s = sin(x); *c = cos(x); return; }
    double fn = (x*KINV_PIO2 + 0x1.8p52) - 0x1.8p52;   /* round to nearest (default rounding mode) */
    int n = (int)fn;
    double r = x - fn*KPIO2_1, w = fn*KPIO2_1T;
    double y0 = r - w;
    if (fabs(y0) < 0x1p-16*fabs(x)) {                  /* x near a multiple of pi/2: fdlibm's 2nd and 3rd rounds */
        double t = r;
        w = fn*KPIO2_2; r = t - w; w = fn*KPIO2_2T - ((t - r) - w); y0 = r - w;
        if (fabs(y0) < 0x1p-49*fabs(x)) {
            t = r; w = fn*KPIO2_3; r = t - w; w = fn*KPIO2_3T - ((t - r) - w); y0 = r - w;
        }
    }
    double y1 = (r - y0) - w;
    double z = y0*y0, zz = z*z, v = z*y0;
    double rs = KSIN_S2 + z*(KSIN_S3 + z*KSIN_S4) + z*zz*(KSIN_S5 + z*KSIN_S6);
    double sn = y0 - ((z*(0.5*y1 - v*rs) - y1) - v*KSIN_S1);
    double rc = z*(KCOS_C1 + z*(KCOS_C2 + z*KCOS_C3)) + zz*zz*(KCOS_C4 + z*(KCOS_C5 + z*KCOS_C6));
    double hz = 0.5*z, ww = 1.0 - hz;
    double cs = ww + (((1.0 - ww) - hz) + (z*rc - y0*y1));
    switch (n & 3) {
    case 0: *s = sn; *c = cs; break;
    case 1: *s = cs; *c = -sn; break;
    case 2: *s = -sn; *c = -cs; break;
    default: *s = -cs; *c = sn; break;
    }
}

/* for the tests: kin_sincos of n angles */
void kernel_sincos_api(const double *x, long long n, double *s, double *c) {
    for (long long i = 0; i < n; ++i) kin_sincos(x[i], s + i, c + i);
}

/* joint transform after the placement L: rotation about the unit axis u by x (jtype 1), about the
   joint's x, y or z axis (jtype 3, 4, 5: two columns mixed), or translation along u (jtype 2) */
static void joint_motion(const double *L, int type, const double *u, double x, double *O) {
    if (type >= 3 || type == 1) {
        double s, c;
        kin_sincos(x, &s, &c);
        if (type >= 3) {
            int a = (type - 2) % 3, b = (type - 1) % 3;   /* RX: columns y, z; RY: z, x; RZ: x, y */
            memcpy(O, L, 12*sizeof(double));
            for (int i = 0; i < 3; ++i) {
                double la = L[3*i+a], lb = L[3*i+b];
                O[3*i+a] = c*la + s*lb;
                O[3*i+b] = -s*la + c*lb;
            }
        } else {
            double t = 1.0 - c;
            double M[12] = {c + t*u[0]*u[0], t*u[0]*u[1] - s*u[2], t*u[0]*u[2] + s*u[1],
                            t*u[0]*u[1] + s*u[2], c + t*u[1]*u[1], t*u[1]*u[2] - s*u[0],
                            t*u[0]*u[2] - s*u[1], t*u[1]*u[2] + s*u[0], c + t*u[2]*u[2], 0, 0, 0};
            compose(L, M, O);
        }
    } else if (type == 2) {
        double M[12] = {1,0,0, 0,1,0, 0,0,1, u[0]*x, u[1]*x, u[2]*x};
        compose(L, M, O);
    } else {
        memcpy(O, L, 12*sizeof(double));
    }
}

/* world placements: joints into oMi, geometries into pose[g] (static geometries point to their
   placement, the override geometry to override_pose, moving ones into oMg). Unless full, a moving
   sphere's pose holds only its position and a moving capsule's only its position and axis (the third
   column of R): all that the tests read of them. */
/* joint j's world placement into oMi from its parent's (already there) and q */
static inline void fk_joint(const kmodel *m, const double *q, double *oMi, int j) {
    double L[12];
    const double *P = oMi + 12*m->jparent[j], *B = m->jplace + 12*j;
    const int *pm = m->jperm ? m->jperm + 3*j : 0;
    if (pm && pm[0]) {   /* a signed permutation: the parent's columns, no products */
        for (int c = 0; c < 3; ++c) {
            int r = (pm[c] > 0 ? pm[c] : -pm[c]) - 1;
            for (int i = 0; i < 3; ++i) L[3*i+c] = pm[c] > 0 ? P[3*i+r] : -P[3*i+r];
        }
        for (int i = 0; i < 3; ++i) L[9+i] = P[3*i]*B[9] + P[3*i+1]*B[10] + P[3*i+2]*B[11] + P[9+i];
    } else compose(P, B, L);
    joint_motion(L, m->jtype[j], m->jaxis + 3*j, q[m->jidx[j]], oMi + 12*j);
}

/* geometry g's world pose into pose[g] (see fk_) */
static inline void fk_geom(const kmodel *m, const double *override_pose, int override_g, const double *oMi,
                           double *oMg, const double **pose, int full, int g) {
    if (g == override_g) pose[g] = override_pose;
    else if (m->gparent[g] == 0) pose[g] = m->gplace + 12*g;
    else {
        const double *P = oMi + 12*m->gparent[g], *G = m->gplace + 12*g;
        double *O = oMg + 12*g;
        int t = m->gtype[g];
        if (full || t > 1) compose(P, G, O);
        else
            for (int i = 0; i < 3; ++i) {
                O[9+i] = P[3*i]*G[9] + P[3*i+1]*G[10] + P[3*i+2]*G[11] + P[9+i];
                if (t == 1) O[3*i+2] = P[3*i]*G[2] + P[3*i+1]*G[5] + P[3*i+2]*G[8];
            }
        pose[g] = O;
    }
}

static void fk_(const kmodel *m, const double *q, const double *override_pose, int override_g, double *oMi,
                double *oMg, const double **pose, int full) {
    static const double I[12] = {1,0,0, 0,1,0, 0,0,1, 0,0,0};
    memcpy(oMi, I, sizeof I);
    for (int j = 1; j < m->nj; ++j) fk_joint(m, q, oMi, j);
    for (int g = 0; g < m->ng; ++g) fk_geom(m, override_pose, override_g, oMi, oMg, pose, full, g);
}

static void fk(const kmodel *m, const double *q, const double *override_pose, int override_g, double *oMi,
               double *oMg, const double **pose) {
    fk_(m, q, override_pose, override_g, oMi, oMg, pose, 0);
}

static double dot3(const double *a, const double *b) { return a[0]*b[0] + a[1]*b[1] + a[2]*b[2]; }
static double clamp01(double x) { return x < 0.0 ? 0.0 : (x > 1.0 ? 1.0 : x); }

/* squared distance between segments p1-q1 and p2-q2 (Ericson, Real-Time Collision Detection 5.1.9) */
static double segseg2(const double *p1, const double *q1, const double *p2, const double *q2) {
    double d1[3], d2[3], r[3], c1[3], c2[3];
    for (int i = 0; i < 3; ++i) { d1[i] = q1[i]-p1[i]; d2[i] = q2[i]-p2[i]; r[i] = p1[i]-p2[i]; }
    double a = dot3(d1, d1), e = dot3(d2, d2), f = dot3(d2, r), s, t;
    if (a <= 1e-18 && e <= 1e-18) { s = t = 0.0; }
    else if (a <= 1e-18) { s = 0.0; t = clamp01(f / e); }
    else {
        double c = dot3(d1, r);
        if (e <= 1e-18) { t = 0.0; s = clamp01(-c / a); }
        else {
            double b = dot3(d1, d2), den = a*e - b*b;
            s = den > 1e-18 ? clamp01((b*f - c*e) / den) : 0.0;
            t = (b*s + f) / e;
            if (t < 0.0) { t = 0.0; s = clamp01(-c / a); }
            else if (t > 1.0) { t = 1.0; s = clamp01((b - c) / a); }
        }
    }
    for (int i = 0; i < 3; ++i) { c1[i] = p1[i] + d1[i]*s; c2[i] = p2[i] + d2[i]*t; c1[i] -= c2[i]; }
    return dot3(c1, c1);
}

/* squared distance from point x to segment p-q */
static double ptseg2(const double *x, const double *p, const double *q) {
    double d[3], w[3];
    for (int i = 0; i < 3; ++i) { d[i] = q[i]-p[i]; w[i] = x[i]-p[i]; }
    double dd = dot3(d, d), t = dd > 1e-18 ? clamp01(dot3(w, d) / dd) : 0.0;
    for (int i = 0; i < 3; ++i) w[i] -= t*d[i];
    return dot3(w, w);
}

/* point (box frame) to box of half extents h: squared distance (0 inside) */
static double ptbox2(const double *x, const double *h) {
    double s = 0.0;
    for (int i = 0; i < 3; ++i) {
        double v = fabs(x[i]) - h[i];
        if (v > 0.0) s += v*v;
    }
    return s;
}

/* world point -> box frame */
static void to_local(const double *P, const double *x, double *y) {
    double d[3] = {x[0]-P[9], x[1]-P[10], x[2]-P[11]};
    for (int i = 0; i < 3; ++i) y[i] = P[i]*d[0] + P[3+i]*d[1] + P[6+i]*d[2];
}

/* does the segment a-b (box frame) meet the axis-aligned box of half extents h (slab test) */
static int seg_hits_aabb(const double *a, const double *b, const double *h) {
    double t0 = 0.0, t1 = 1.0;
    for (int i = 0; i < 3; ++i) {
        double d = b[i] - a[i];
        if (fabs(d) < 1e-15) {
            if (a[i] < -h[i] || a[i] > h[i]) return 0;
        } else {
            double u = (-h[i] - a[i]) / d, v = (h[i] - a[i]) / d;
            if (u > v) { double w = u; u = v; v = w; }
            if (u > t0) t0 = u;
            if (v < t1) t1 = v;
            if (t0 > t1) return 0;
        }
    }
    return 1;
}

/* the smallest squared distance from the segment a-b (box frame) to the 12 edges of the box of half extents h,
   returned early at the first at most stop */
static double seg_box_edges2(const double *a, const double *b, const double *h, double stop) {
    double d = 1e300;
    for (int ax = 0; ax < 3; ++ax) {
        int u = (ax + 1) % 3, v = (ax + 2) % 3;
        for (int su = -1; su <= 1; su += 2)
            for (int sv = -1; sv <= 1; sv += 2) {
                double e0[3], e1[3];
                e0[ax] = -h[ax]; e1[ax] = h[ax];
                e0[u] = e1[u] = su*h[u];
                e0[v] = e1[v] = sv*h[v];
                double e = segseg2(a, b, e0, e1);
                if (e < d) { d = e; if (d <= stop) return d; }
            }
    }
    return d;
}

/* segment a-b (box frame) within distance r of the box of half extents h */
static int seg_box(const double *a, const double *b, const double *h, double r) {
    double hr[3] = {h[0] + r, h[1] + r, h[2] + r};
    for (int i = 0; i < 3; ++i)                        /* the segment's box in the box frame: no division */
        if ((a[i] < b[i] ? a[i] : b[i]) > hr[i] || (a[i] > b[i] ? a[i] : b[i]) < -hr[i]) return 0;
    if (!seg_hits_aabb(a, b, hr)) return 0;            /* beyond the inflated box: farther than r */
    double r2 = r*r;
    if (ptbox2(a, h) <= r2 || ptbox2(b, h) <= r2) return 1;
    if (seg_hits_aabb(a, b, h)) return 1;
    /* not intersecting: the closest pair is an end point (done above) or the segment and a box edge */
    return seg_box_edges2(a, b, h, r2) <= r2;
}

/* oriented boxes A, B (world poses, half extents) closer than r (separating axis test; conservative:
   the boxes inflated by r as boxes) */
static int box_box(const double *A, const double *ha, const double *B, const double *hb, double r) {
    double Rm[3][3], AR[3][3], t[3], d[3] = {B[9]-A[9], B[10]-A[10], B[11]-A[11]};
    /* Rm[i][j] = a_i . b_j (columns of the rotation matrices) */
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
            Rm[i][j] = A[i]*B[j] + A[3+i]*B[3+j] + A[6+i]*B[6+j];
            AR[i][j] = fabs(Rm[i][j]) + 1e-12;
        }
        t[i] = A[i]*d[0] + A[3+i]*d[1] + A[6+i]*d[2];
    }
    for (int i = 0; i < 3; ++i) {
        double rb = hb[0]*AR[i][0] + hb[1]*AR[i][1] + hb[2]*AR[i][2];
        if (fabs(t[i]) > ha[i] + rb + r) return 0;
    }
    for (int j = 0; j < 3; ++j) {
        double ra = ha[0]*AR[0][j] + ha[1]*AR[1][j] + ha[2]*AR[2][j];
        if (fabs(t[0]*Rm[0][j] + t[1]*Rm[1][j] + t[2]*Rm[2][j]) > ra + hb[j] + r) return 0;
    }
    for (int i = 0; i < 3; ++i) {
        int i1 = (i + 1) % 3, i2 = (i + 2) % 3;
        for (int j = 0; j < 3; ++j) {
            int j1 = (j + 1) % 3, j2 = (j + 2) % 3;
            double len2 = 1.0 - Rm[i][j]*Rm[i][j];
            if (len2 < 1e-6) continue;   /* near-parallel edges: skipping an axis only makes the test more conservative */
            double ra = ha[i1]*AR[i2][j] + ha[i2]*AR[i1][j];
            double rb = hb[j1]*AR[i][j2] + hb[j2]*AR[i][j1];
            double s = fabs(t[i2]*Rm[i1][j] - t[i1]*Rm[i2][j]);
            if (s > ra + rb + r*sqrt(len2)) return 0;
        }
    }
    return 1;
}

static void capsule_ends(const double *P, const double *prm, double *a, double *b) {
    double hl = prm[1];
    for (int i = 0; i < 3; ++i) { a[i] = P[9+i] - hl*P[3*i+2]; b[i] = P[9+i] + hl*P[3*i+2]; }
}

/* one pair: 1 when the primitives are within margin (+ KEPS) of each other */
static int pair_collides(const kmodel *m, const double **pose, int ga, int gb) {
    const double *A = pose[ga], *B = pose[gb];
    double thr = m->margin + KEPS;
    double dx = A[9]-B[9], dy = A[10]-B[10], dz = A[11]-B[11];
    double rr = m->grad[ga] + m->grad[gb] + thr;
    KCNT(1, 1);
    if (dx*dx + dy*dy + dz*dz > rr*rr) return 0;
    KCNT(2, 1);
    int ta = m->gtype[ga], tb = m->gtype[gb];
    if (ta > tb) { int w = ga; ga = gb; gb = w; w = ta; ta = tb; tb = w; const double *X = A; A = B; B = X; }
    const double *pa = m->gparam + 3*ga, *pb = m->gparam + 3*gb;
    double a0[3], a1[3], b0[3], b1[3], x[3], y[3], r;
    if (ta == 0 && tb == 0) {
        r = pa[0] + pb[0] + thr;
        return dx*dx + dy*dy + dz*dz <= r*r;
    }
    if (ta == 0 && tb == 1) {
        capsule_ends(B, pb, b0, b1);
        r = pa[0] + pb[0] + thr;
        return ptseg2(A + 9, b0, b1) <= r*r;
    }
    if (ta == 0 && tb == 2) {
        to_local(B, A + 9, x);
        r = pa[0] + thr;
        return ptbox2(x, pb) <= r*r;
    }
    if (ta == 1 && tb == 1) {
        capsule_ends(A, pa, a0, a1); capsule_ends(B, pb, b0, b1);
        r = pa[0] + pb[0] + thr;
        return segseg2(a0, a1, b0, b1) <= r*r;
    }
    if (ta == 1 && tb == 2) {
        capsule_ends(A, pa, a0, a1);
        to_local(B, a0, x); to_local(B, a1, y);
        return seg_box(x, y, pb, pa[0] + thr);
    }
    /* the world axes first, as the broad phase's boxes test them: so that a box pair tried first (the hint) or
       in the plain pair loop gets the verdict the broad phase gives it (separating axes alone are conservative
       near edges and corners, where the boxes can be apart along a world axis) */
    for (int i = 0; i < 3; ++i) {
        double ea = fabs(A[3*i])*pa[0] + fabs(A[3*i+1])*pa[1] + fabs(A[3*i+2])*pa[2];
        double eb = fabs(B[3*i])*pb[0] + fabs(B[3*i+1])*pb[1] + fabs(B[3*i+2])*pb[2];
        if (fabs(A[9+i] - B[9+i]) - ea - eb > thr + 4e-12) return 0;
    }
    return box_box(A, pa, B, pb, thr);
}

/* world AABB of geometry g at pose P, into b (lo[3], hi[3]) */
static void geom_aabb(const kmodel *m, int g, const double *P, double *b) {
    const double *prm = m->gparam + 3*g;
    double e[3];
    int t = m->gtype[g];
    for (int i = 0; i < 3; ++i) {
        if (t == 0) e[i] = prm[0];
        else if (t == 1) e[i] = prm[0] + prm[1]*fabs(P[3*i+2]);
        else e[i] = fabs(P[3*i])*prm[0] + fabs(P[3*i+1])*prm[1] + fabs(P[3*i+2])*prm[2];
        e[i] += 1e-12;                                  /* rounding of the bound itself */
        b[i] = P[9+i] - e[i]; b[3+i] = P[9+i] + e[i];
    }
}

/* 1 when the boxes A and B (lo[3], hi[3]) are more than thr apart along an axis */
static int boxes_apart(const double *A, const double *B, double thr) {
    return A[0] - B[3] > thr || B[0] - A[3] > thr || A[1] - B[4] > thr || B[1] - A[4] > thr
           || A[2] - B[5] > thr || B[2] - A[5] > thr;
}

/* the largest gap between two boxes (lo[3], hi[3]) along an axis (> 0: apart by at least that) */
static inline double box_gap(const double *A, const double *B) {
    double s = A[0] - B[3], t;
    t = B[0] - A[3]; s = s > t ? s : t;
    t = A[1] - B[4]; s = s > t ? s : t;
    t = B[1] - A[4]; s = s > t ? s : t;
    t = A[2] - B[5]; s = s > t ? s : t;
    t = B[2] - A[5]; s = s > t ? s : t;
    return s;
}

/* the world boxes of the moving geometries (mb, 6 per row of mov) and of their groups (gbx, 6 per group) */
static void broad_boxes(const kmodel *m, const double **pose, double *mb, double *gbx) {
    for (int i = 0; i < m->nmov; ++i) geom_aabb(m, m->mov[i], pose[m->mov[i]], mb + 6*i);
    for (int g = 0; g < m->ngrp; ++g) {
        double *gb = gbx + 6*g;
        for (int c = 0; c < 6; ++c) gb[c] = mb[6*m->grp[g] + c];
        for (int i = m->grp[g] + 1; i < m->grp[g+1]; ++i)
            for (int c = 0; c < 3; ++c) {
                if (mb[6*i+c] < gb[c]) gb[c] = mb[6*i+c];
                if (mb[6*i+3+c] > gb[3+c]) gb[3+c] = mb[6*i+3+c];
            }
    }
}

/* the largest gap between the box gb (lo[3], hi[3]) and each static box along an axis, into sep (> 0: apart;
   a - b > 0 exactly when a > b); branch-free, vectorised by the compiler even for the baseline x86-64 (SSE2) */
static void static_gaps(const kmodel *m, const double *gb, double *sep) {
    int ns = m->nstat;
    const double *S = m->saabb;
    const double *restrict x0 = S, *restrict y0 = S + ns, *restrict z0 = S + 2*ns;
    const double *restrict x1 = S + 3*ns, *restrict y1 = S + 4*ns, *restrict z1 = S + 5*ns;
    double ax0 = gb[0], ay0 = gb[1], az0 = gb[2], ax1 = gb[3], ay1 = gb[4], az1 = gb[5];
    for (int j = 0; j < ns; ++j) {
        double s = ax0 - x1[j], t;
        t = x0[j] - ax1; s = s > t ? s : t;
        t = ay0 - y1[j]; s = s > t ? s : t;
        t = y0[j] - ay1; s = s > t ? s : t;
        t = az0 - z1[j]; s = s > t ? s : t;
        t = z0[j] - az1; s = s > t ? s : t;
        sep[j] = s;
    }
}

/* the broad phase (see kmodel), static pairs: 1 when an active pair with a static geometry is in contact;
   mb: the moving geometries' boxes, gbx: the groups'; js >= 0: static column js has the box ob (a static
   geometry placed by this call) instead of its stored one */
static int static_pairs_collide(const kmodel *m, const unsigned char *active, const double **pose,
                                const double *mb, const double *gbx, int js, const double *ob) {
    enum { KMAXS = 4096 };
    double sep[KMAXS];
    int ns = m->nstat;
    const double *S = m->saabb;
    const double *restrict x0 = S, *restrict y0 = S + ns, *restrict z0 = S + 2*ns;
    const double *restrict x1 = S + 3*ns, *restrict y1 = S + 4*ns, *restrict z1 = S + 5*ns;
    for (int g = 0; g < m->ngrp; ++g) {
        const double *gb = gbx + 6*g;
        KCNT(3, ns);
        static_gaps(m, gb, sep);
        if (js >= 0) sep[js] = box_gap(gb, ob);   /* the same gap to the placed box */
        for (int j = 0; j < ns; ++j) {
            if (sep[j] > 0.0) continue;
            double X0 = x0[j], Y0 = y0[j], Z0 = z0[j], X1 = x1[j], Y1 = y1[j], Z1 = z1[j];
            if (j == js) { X0 = ob[0]; Y0 = ob[1]; Z0 = ob[2]; X1 = ob[3]; Y1 = ob[4]; Z1 = ob[5]; }
            for (int i = m->grp[g]; i < m->grp[g+1]; ++i) {
                int k = m->ms_pair[i*ns + j];
                const double *b = mb + 6*i;
                if (k < 0 || !active[k]) continue;
                KCNT(4, 1);
                if (b[0] > X1 || b[3] < X0 || b[1] > Y1 || b[4] < Y0 || b[2] > Z1 || b[5] < Z0)
                    continue;
                if (pair_collides(m, pose, m->pa[k], m->pb[k])) { if (m->hint) *m->hint = k; return 1; }
            }
        }
    }
    return 0;
}

/* the broad phase, pairs of moving geometries: bucket by bucket (the pairs of two groups), skipped when
   the groups' boxes are apart by more than the threshold, then each pair's two boxes */
static int moving_pairs_collide(const kmodel *m, const unsigned char *active, const double **pose,
                                const double *mb, const double *gbx) {
    double thr = m->margin + KEPS;
    for (int b = 0; b < m->nbuck; ++b) {
        KCNT(5, 1);
        if (boxes_apart(gbx + 6*m->bga[b], gbx + 6*m->bgb[b], thr)) continue;
        for (int i = m->bstart[b]; i < m->bstart[b+1]; ++i) {
            int k = m->bperm[i];
            KCNT(6, active[k] != 0);
            if (!active[k] || boxes_apart(mb + 6*m->mrow[m->pa[k]], mb + 6*m->mrow[m->pb[k]], thr)) continue;
            if (pair_collides(m, pose, m->pa[k], m->pb[k])) { if (m->hint) *m->hint = k; return 1; }
        }
    }
    return 0;
}

/* 1 when configuration q is in collision (an active pair in contact) */
static int config_collides(const kmodel *m, const unsigned char *active, const double *q,
                           const double *override_pose, int override_g, double *oMi, double *oMg) {
    const double *pose[KMAXG];
    double mb[6*KMAXG], gbx[6*KMAXG];
    KCNT(0, 1);
    fk(m, q, override_pose, override_g, oMi, oMg, pose);
    int js = -1;
    double ob[6];
    if (override_g >= 0 && m->scol && m->ngrp > 0) {   /* a static geometry placed by this call: its box now */
        js = m->scol[override_g];
        if (js >= 0) {
            geom_aabb(m, override_g, pose[override_g], ob);
            for (int c = 0; c < 3; ++c) { ob[c] -= m->margin + KEPS + 1e-12; ob[3+c] += m->margin + KEPS + 1e-12; }
        }
    }
    if (m->ngrp <= 0 || (override_g >= 0 && !m->scol) || m->nstat > 4096) {   /* no broad phase: every pair in order */
        for (int k = 0; k < m->npairs; ++k)
            if (active[k] && pair_collides(m, pose, m->pa[k], m->pb[k])) return 1;
        return 0;
    }
    int h = m->hint ? *m->hint : -1;
    if (h >= 0 && h < m->npairs && active[h] && pair_collides(m, pose, m->pa[h], m->pb[h])) return 1;
    broad_boxes(m, pose, mb, gbx);
    if (static_pairs_collide(m, active, pose, mb, gbx, js, ob) || moving_pairs_collide(m, active, pose, mb, gbx)) return 1;
    for (int r = 0; r < m->nrest; ++r) {
        int k = m->rest[r];
        if (active[k] && pair_collides(m, pose, m->pa[k], m->pb[k])) { if (m->hint) *m->hint = k; return 1; }
    }
    return 0;
}

/* the rows of Q (M x nq, row-major) in order: index of the first in collision, or -1.
   With out != NULL every row is checked and out[i] = 1 when row i is collision-free. */
long long kernel_first_invalid(const kmodel *m, const unsigned char *active, const double *override_pose,
                               int override_g, long long M, const double *Q, unsigned char *out) {
    double oMi[12*KMAXJ], oMg[12*KMAXG];
    if (m->nj > KMAXJ || m->ng > KMAXG) return -2;
    long long first = -1;
    for (long long i = 0; i < M; ++i) {
        int hit = config_collides(m, active, Q + i*m->nq, override_pose, override_g, oMi, oMg);
        if (out) out[i] = (unsigned char)!hit;
        if (hit && first < 0) { first = i; if (!out) break; }
    }
    return first;
}

/* the edge a -> b at the fractions f[0..n-1] (in that order): index of the first in collision, or -1 */
long long kernel_edge_first_invalid(const kmodel *m, const unsigned char *active, const double *override_pose,
                                    int override_g, const double *a, const double *b, long long n, const double *f) {
    double oMi[12*KMAXJ], oMg[12*KMAXG], q[KMAXJ];
    if (m->nj > KMAXJ || m->ng > KMAXG || m->nq > KMAXJ) return -2;
    for (long long i = 0; i < n; ++i) {
        for (int k = 0; k < m->nq; ++k) q[k] = a[k] + f[i]*(b[k] - a[k]);
        if (config_collides(m, active, q, override_pose, override_g, oMi, oMg)) return i;
    }
    return -1;
}

/* the world placements of every geometry at q (ng x 12), for tests */
void kernel_placements(const kmodel *m, const double *q, const double *override_pose, int override_g, double *oMg) {
    double oMi[12*KMAXJ], buf[12*KMAXG];
    const double *pose[KMAXG];
    if (m->nj > KMAXJ || m->ng > KMAXG) return;
    fk_(m, q, override_pose, override_g, oMi, buf, pose, 1);
    for (int g = 0; g < m->ng; ++g) memcpy(oMg + 12*g, pose[g], 12*sizeof(double));
}
""".replace("@KERNEL_EPS@", repr(KERNEL_EPS))
