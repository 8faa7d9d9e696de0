"""The C source of the uniform edge check with safe steps (appended to the planning kernel's
:data:`~optplan.planners.kernel.csource.C_SOURCE` by :func:`optplan.planners.kernel.native.load_library`).

``kernel_edge_first_invalid_skip`` answers exactly what ``kernel_edge_first_invalid`` answers for ascending
fractions (the index of the first point in collision, or −1), but proves most points free without checking
them. At a point it checks, the broad phase that decides the verdict also
gives a lower bound on every active pair's distance beyond the contact threshold (its slack): the gap
between the two axis-aligned boxes, or where those overlap the exact distance (sphere, capsule and
capsule-box pairs, whose tests compare that distance with the threshold). Box-box pairs are tested by
separating axes that turn with the boxes, which is no distance and not Lipschitz in the motion; their
slack is the bounding spheres' gap or, where one box stands still (an obstacle, the still object), the
separation along its fixed face normals — both Lipschitz, and either > 0 makes the box-box test say free.
Each of these bounds shrinks by at most the pair's rate per step: the per-step displacement bound of its
two geometries (the per-joint sweep weights of each primitive times ``|b − a| / n``, without the joints
that carry both and so move them rigidly). The next ``J`` points are then free for that pair when
``J < slack / rate``; the smallest ``J`` over the pairs is skipped. At a skipped point every active pair
keeps such a certificate by a 1e-9 m reserve at least, so the kernel's check there would say free: the
verdict and the first point in collision are those of checking every point; only the work differs.
"""
from __future__ import annotations

__all__ = ["CLEARANCE_SOURCE"]

CLEARANCE_SOURCE = r"""
#include <stdlib.h>

#define KRESERVE 1e-9   /* [m] kept between a skipped point's lower bound and the threshold */

/* squared distance from the segment a-b (box frame) to the box of half extents h (0 when they meet):
   an end point or a box edge holds the closest pair when they do not meet (see seg_box) */
static double segbox2(const double *a, const double *b, const double *h) {
    if (seg_hits_aabb(a, b, h)) return 0.0;
    double d = ptbox2(a, h), e = ptbox2(b, h);
    if (e < d) d = e;
    e = seg_box_edges2(a, b, h, -1.0);
    return e < d ? e : d;
}

/* the separation of the box A (world pose, half extents ha) from the box S (hs) along S's three face normals
   (the first three axes of box_box, with its rounding allowance): where S stands still, a Lipschitz bound on
   the kernel's own box-box verdict (box_box says free where one of them exceeds the threshold) */
static double face_sep(const double *S, const double *hs, const double *A, const double *ha) {
    double d[3] = {A[9]-S[9], A[10]-S[10], A[11]-S[11]}, best = -1e300;
    for (int j = 0; j < 3; ++j) {
        double t = S[j]*d[0] + S[3+j]*d[1] + S[6+j]*d[2], r = 0.0;
        for (int k = 0; k < 3; ++k) r += ha[k]*(fabs(S[j]*A[k] + S[3+j]*A[3+k] + S[6+j]*A[6+k]) + 1e-12);
        double s = fabs(t) - hs[j] - r;
        if (s > best) best = s;
    }
    return best;
}

/* a lower bound on a pair's distance minus the contact threshold that is also Lipschitz in the motion of the two
   primitives (no point moving farther than d changes it by more than d) and whose being > 0 makes the kernel's
   pair test say free: the exact distance for sphere, capsule and capsule-box pairs (their tests compare it with
   the threshold); for box-box pairs (a separating-axis test, whose axes turn with the boxes) the larger of the
   bounding spheres' gap and, where one box stands still, the separation along its fixed face normals */
static double pair_slack(const kmodel *m, const double **pose, int ga, int gb) {
    const double *A = pose[ga], *B = pose[gb];
    double thr = m->margin + KEPS;
    int ta = m->gtype[ga], tb = m->gtype[gb];
    if (ta > tb) { int w = ga; ga = gb; gb = w; w = ta; ta = tb; tb = w; const double *X = A; A = B; B = X; }
    const double *pa = m->gparam + 3*ga, *pb = m->gparam + 3*gb;
    double a0[3], a1[3], b0[3], b1[3], x[3], y[3];
    if (ta == 0 && tb == 0) {
        double dx = A[9]-B[9], dy = A[10]-B[10], dz = A[11]-B[11];
        return sqrt(dx*dx + dy*dy + dz*dz) - pa[0] - pb[0] - thr;
    }
    if (ta == 0 && tb == 1) { capsule_ends(B, pb, b0, b1); return sqrt(ptseg2(A + 9, b0, b1)) - pa[0] - pb[0] - thr; }
    if (ta == 0 && tb == 2) { to_local(B, A + 9, x); return sqrt(ptbox2(x, pb)) - pa[0] - thr; }
    if (ta == 1 && tb == 1) {
        capsule_ends(A, pa, a0, a1); capsule_ends(B, pb, b0, b1);
        return sqrt(segseg2(a0, a1, b0, b1)) - pa[0] - pb[0] - thr;
    }
    if (ta == 1 && tb == 2) {
        capsule_ends(A, pa, a0, a1); to_local(B, a0, x); to_local(B, a1, y);
        return sqrt(segbox2(x, y, pb)) - pa[0] - thr;
    }
    double dx = A[9]-B[9], dy = A[10]-B[10], dz = A[11]-B[11];
    double g = sqrt(dx*dx + dy*dy + dz*dz) - m->grad[ga] - m->grad[gb], f;
    if (m->gparent[gb] == 0) { f = face_sep(B, pb, A, pa); if (f > g) g = f; }
    if (m->gparent[ga] == 0) { f = face_sep(A, pa, B, pb); if (f > g) g = f; }
    return g - thr;
}

/* the stretch of the edge parameter (at most cap) over which a pair with this slack [m] and rate [m per unit of
   the parameter] stays free beyond this point */
static inline double free_len(double slack, double rate, double cap) {
    double s = slack - KRESERVE;
    if (s <= 0.0) return 0.0;
    if (rate <= 0.0) return cap;
    double t = s / rate;
    return t < cap ? t : cap;
}

/* -1 when q is in collision (the verdict of config_collides), else the stretch T (at most cap) of the edge
   parameter beyond q over which every point is certainly free: vmov, vgrp, vpair, vbuck are the rates [m per
   unit of the parameter] of the moving geometries, the groups, the pairs and the buckets; *lim the pair that
   limited the last call's stretch (tried first), updated */
static double config_free_len(const kmodel *m, const unsigned char *active, const double *q,
                                const double *override_pose, int override_g, double *oMi, double *oMg,
                                const double *vmov, const double *vgrp, const double *vpair, const double *vbuck,
                                double cap, int *lim) {
    const double *pose[KMAXG];
    double mb[6*KMAXG], gbx[6*KMAXG], ob[6];
    enum { KMAXS = 4096 };
    double sep[KMAXS];
    double J = cap, thr = m->margin + KEPS;
    KCNT(0, 1);
    fk(m, q, override_pose, override_g, oMi, oMg, pose);
    int js = -1;
    if (override_g >= 0) {
        js = m->scol[override_g];
        if (js >= 0) {
            geom_aabb(m, override_g, pose[override_g], ob);
            for (int c = 0; c < 3; ++c) { ob[c] -= thr + 1e-12; ob[3+c] += thr + 1e-12; }
        }
    }
    int h = m->hint ? *m->hint : -1;
    if (h >= 0 && h < m->npairs && active[h] && pair_collides(m, pose, m->pa[h], m->pb[h])) return -1.0;
    /* the pair that limited the last point's steps first: a small bound early prunes most of the rest */
    if (*lim >= 0 && active[*lim]) J = free_len(pair_slack(m, pose, m->pa[*lim], m->pb[*lim]), vpair[*lim], J);
#define KLOWER(f_, k_) do { double f__ = (f_); if (f__ < J) { J = f__; *lim = (k_); } } while (0)
    broad_boxes(m, pose, mb, gbx);
    /* pairs of a moving and a static geometry: group boxes against every static box, then each link's */
    int ns = m->nstat;
    const double *S = m->saabb;
    for (int g = 0; g < m->ngrp; ++g) {
        const double *gb = gbx + 6*g;
        double vg = vgrp[g];
        static_gaps(m, gb, sep);
        if (js >= 0) sep[js] = box_gap(gb, ob);
        for (int j = 0; j < ns; ++j) {
            if (sep[j] > 0.0 && (J <= 0.0 || vg <= 0.0 || sep[j] - KRESERVE > J*vg)) continue;
            double sb[6] = {S[j], S[ns+j], S[2*ns+j], S[3*ns+j], S[4*ns+j], S[5*ns+j]};
            if (j == js) memcpy(sb, ob, sizeof sb);
            for (int i = m->grp[g]; i < m->grp[g+1]; ++i) {
                int k = m->ms_pair[i*ns + j];
                if (k < 0 || !active[k]) continue;
                double s = box_gap(mb + 6*i, sb);   /* the static box carries the threshold */
                if (s > 0.0) { if (J > 0.0) KLOWER(free_len(s, vmov[i], J), k); continue; }
                if (pair_collides(m, pose, m->pa[k], m->pb[k])) { if (m->hint) *m->hint = k; return -1.0; }
                if (J > 0.0) KLOWER(free_len(pair_slack(m, pose, m->pa[k], m->pb[k]), vmov[i], J), k);
            }
        }
    }
    /* pairs of two moving geometries, bucket by bucket */
    for (int b = 0; b < m->nbuck; ++b) {
        double s = box_gap(gbx + 6*m->bga[b], gbx + 6*m->bgb[b]) - thr;
        if (s > 0.0 && (J <= 0.0 || vbuck[b] <= 0.0 || s - KRESERVE > J*vbuck[b])) continue;
        for (int i = m->bstart[b]; i < m->bstart[b+1]; ++i) {
            int k = m->bperm[i];
            if (!active[k]) continue;
            double t = box_gap(mb + 6*m->mrow[m->pa[k]], mb + 6*m->mrow[m->pb[k]]) - thr;
            if (t > 0.0) { if (J > 0.0) KLOWER(free_len(t, vpair[k], J), k); continue; }
            if (pair_collides(m, pose, m->pa[k], m->pb[k])) { if (m->hint) *m->hint = k; return -1.0; }
            if (J > 0.0) KLOWER(free_len(pair_slack(m, pose, m->pa[k], m->pb[k]), vpair[k], J), k);
        }
    }
    for (int r = 0; r < m->nrest; ++r) {
        int k = m->rest[r];
        if (!active[k]) continue;
        if (pair_collides(m, pose, m->pa[k], m->pb[k])) { if (m->hint) *m->hint = k; return -1.0; }
        if (J > 0.0 && vpair[k] > 0.0) KLOWER(free_len(pair_slack(m, pose, m->pa[k], m->pb[k]), vpair[k], J), k);
    }
#undef KLOWER
    return J;
}

/* the points a + f[i] (b - a), f ascending, in order: index of the first in collision, or -1, as
   kernel_edge_first_invalid with these fractions. wg (ng x nq) and wp (npairs x nq): the sweep weights of the
   geometries and the pairs [m/rad]. *evaluated: the points checked (the rest were proven free). */
long long kernel_edge_first_invalid_skip(const kmodel *m, const unsigned char *active, const double *override_pose,
                                         int override_g, const double *a, const double *b, long long n, const double *f,
                                         const double *wg, const double *wp, long long *evaluated) {
    double oMi[12*KMAXJ], oMg[12*KMAXG], q[KMAXJ], dq[KMAXJ];
    *evaluated = 0;
    if (m->nj > KMAXJ || m->ng > KMAXG || m->nq > KMAXJ) return -2;
    int nq = m->nq;
    int broad = m->ngrp > 0 && m->nstat <= 4096 && (override_g < 0 || m->scol);
    if (!broad) {   /* no broad phase: every point */
        for (long long k = 0; k < n; ++k) {
            for (int i = 0; i < nq; ++i) q[i] = a[i] + f[k]*(b[i] - a[i]);
            ++*evaluated;
            if (config_collides(m, active, q, override_pose, override_g, oMi, oMg)) return k;
        }
        return -1;
    }
    for (int i = 0; i < nq; ++i) dq[i] = fabs(b[i] - a[i]);
    double *v = (double *)malloc(sizeof(double) * (size_t)(m->nmov + m->ngrp + m->npairs + m->nbuck + 1));
    if (!v) return -2;
    double *vmov = v, *vgrp = v + m->nmov, *vpair = vgrp + m->ngrp, *vbuck = vpair + m->npairs;
    for (int i = 0; i < m->nmov; ++i) {
        const double *w = wg + (size_t)m->mov[i]*nq;
        double s = 0.0;
        for (int c = 0; c < nq; ++c) s += w[c]*dq[c];
        vmov[i] = s;
    }
    for (int g = 0; g < m->ngrp; ++g) {
        double s = 0.0;
        for (int i = m->grp[g]; i < m->grp[g+1]; ++i) if (vmov[i] > s) s = vmov[i];
        vgrp[g] = s;
    }
    for (int k = 0; k < m->npairs; ++k) {
        const double *w = wp + (size_t)k*nq;
        double s = 0.0;
        for (int c = 0; c < nq; ++c) s += w[c]*dq[c];
        vpair[k] = s;
    }
    for (int bk = 0; bk < m->nbuck; ++bk) {
        double s = 0.0;
        for (int i = m->bstart[bk]; i < m->bstart[bk+1]; ++i) if (vpair[m->bperm[i]] > s) s = vpair[m->bperm[i]];
        vbuck[bk] = s;
    }
    long long out = -1;
    int lim = -1;
    for (long long k = 0; k < n; ) {
        for (int i = 0; i < nq; ++i) q[i] = a[i] + f[k]*(b[i] - a[i]);
        ++*evaluated;
        double T = config_free_len(m, active, q, override_pose, override_g, oMi, oMg, vmov, vgrp, vpair, vbuck,
                                   f[n-1] - f[k], &lim);
        if (T < 0.0) { out = k; break; }
        long long i = k + 1;
        while (i < n && f[i] - f[k] < T) ++i;   /* free: closer than T along the edge */
        k = i;
    }
    free(v);
    return out;
}

/* every pair's pair_slack at q (npairs values), for tests against exact distances */
void kernel_pair_slacks(const kmodel *m, const double *q, const double *override_pose, int override_g, double *out) {
    double oMi[12*KMAXJ], oMg[12*KMAXG];
    const double *pose[KMAXG];
    if (m->nj > KMAXJ || m->ng > KMAXG) return;
    fk(m, q, override_pose, override_g, oMi, oMg, pose);
    for (int k = 0; k < m->npairs; ++k) out[k] = pair_slack(m, pose, m->pa[k], m->pb[k]);
}
"""
