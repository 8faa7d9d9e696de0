"""The C source of the trees' nearest-neighbour search (:func:`optplan.planners.kernel.extend.nearest`): the linear
scan ``tcb_nearest`` (the first live row with the least squared Euclidean distance), the k-d index ``tcb_nearest_kd``
that gives the scan's answer through a balanced tree kept in :func:`~optplan.planners.kernel.extend.kd_index`'s
slots, and ``tcb_nearest_batch``, the benchmark's loop over many queries in one call.

It is part of the extension library's source (:data:`~optplan.planners.kernel.extend_csource.EXTEND_SOURCE`, which
holds it in place), so the native extension, sampler and streaks call it without leaving C.
"""
from __future__ import annotations

__all__ = ["NEAREST_SOURCE"]

NEAREST_SOURCE = r"""long long tcb_nearest(const double *X, long long n, int dim, const unsigned char *alive, const double *x) {
    long long best = -1;
    double bd = 0.0;
    for (long long i = 0; i < n; ++i) {
        if (alive && !alive[i]) continue;
        const double *r = X + i*dim;
        double s = 0.0;
        for (int k = 0; k < dim; ++k) { double d = r[k] - x[k]; s += d*d; }
        if (best < 0 || s < bd) { best = i; bd = s; }
    }
    return best;
}

/* A k-d index over a tree's key rows for tcb_nearest_kd, kept in the int64 slots of K (2 + dim per row of the key
   array, so that it grows with it): a balanced tree built over the first *kdn rows, the rows after them (appended since)
   scanned one by one, and the tree built again over all rows once that tail outgrows a sixteenth of it. Slot 0 holds
   the rows built over (nb), slot 1 the nodes; then nb row numbers in leaf order; then the nodes, each 2*dim doubles
   (the box of its rows' keys, lower corner then upper, exact) and two slots: a leaf's first and one-past-last position
   in the row order (first stored as -1 - first), or an inner node's two children. A node splits its rows at the median
   of the coordinate of the largest extent; a leaf holds at most TCB_KD_LEAF rows (at least half of that), so the nodes
   take at most 2 nb / (TCB_KD_LEAF / 2) of 2 dim + 2 slots: within K for every dim up to 8. */
#define TCB_KD_MIN 512       /* below this many rows the linear scan is as fast for far queries (measured) */
#define TCB_KD_LEAF 12       /* rows of a leaf, at most */
#define TCB_KD_STACK 128     /* pending far branches (a balanced tree is far shallower) */
#define TCB_KD_HDR 2

static inline long long tcb_kd_nw(int dim) { return 2*(long long)dim + 2; }

/* rows perm[lo..hi) reordered so that the (mid-lo)-th smallest in coordinate d sits at mid, the smaller ones before */
static void tcb_kd_select(const double *X, int dim, long long *perm, long long lo, long long hi, long long mid, int d) {
    while (hi - lo > 1) {
        long long a = lo, b = hi - 1, m = lo + (hi - lo)/2;
        double va = X[dim*perm[a] + d], vb = X[dim*perm[b] + d], vm = X[dim*perm[m] + d];
        double piv = va < vb ? (vm < va ? va : vm < vb ? vm : vb) : (vm < vb ? vb : vm < va ? vm : va);
        long long i = lo, j = hi - 1;
        while (i <= j) {                                  /* Hoare partition around the median of three */
            while (X[dim*perm[i] + d] < piv) ++i;
            while (X[dim*perm[j] + d] > piv) --j;
            if (i <= j) { long long t = perm[i]; perm[i] = perm[j]; perm[j] = t; ++i; --j; }
        }
        if (mid <= j) hi = j + 1;
        else if (mid >= i) lo = i;
        else return;
    }
}

/* node `node` over perm[lo..hi): its box and its subtree; returns the next free node */
static long long tcb_kd_build_node(const double *X, int dim, long long *perm, double *nodes, long long node, long long lo,
                                   long long hi) {
    long long nw = tcb_kd_nw(dim);
    double *bx = nodes + nw*node;
    long long *link = (long long *)(bx + 2*dim);
    if (hi - lo <= TCB_KD_LEAF) {
        for (int k = 0; k < dim; ++k) { bx[k] = INFINITY; bx[dim + k] = -INFINITY; }
        for (long long i = lo; i < hi; ++i) {
            const double *r = X + dim*perm[i];
            for (int k = 0; k < dim; ++k) {
                if (r[k] < bx[k]) bx[k] = r[k];
                if (r[k] > bx[dim + k]) bx[dim + k] = r[k];
            }
        }
        link[0] = -1 - lo; link[1] = hi;
        return node + 1;
    }
    /* the coordinate of the largest extent over these rows, then its median */
    double mn[8], mx[8];
    for (int k = 0; k < dim; ++k) { mn[k] = INFINITY; mx[k] = -INFINITY; }
    for (long long i = lo; i < hi; ++i) {
        const double *r = X + dim*perm[i];
        for (int k = 0; k < dim; ++k) { if (r[k] < mn[k]) mn[k] = r[k]; if (r[k] > mx[k]) mx[k] = r[k]; }
    }
    int d = 0;
    for (int k = 1; k < dim; ++k) if (mx[k] - mn[k] > mx[d] - mn[d]) d = k;
    long long mid = lo + (hi - lo)/2;
    tcb_kd_select(X, dim, perm, lo, hi, mid, d);
    long long left = node + 1;
    long long right = tcb_kd_build_node(X, dim, perm, nodes, left, lo, mid);
    long long next = tcb_kd_build_node(X, dim, perm, nodes, right, mid, hi);
    const double *bl = nodes + nw*left, *br = nodes + nw*right;
    for (int k = 0; k < dim; ++k) {
        bx[k] = bl[k] < br[k] ? bl[k] : br[k];
        bx[dim + k] = bl[dim + k] > br[dim + k] ? bl[dim + k] : br[dim + k];
    }
    link[0] = left; link[1] = right;
    return next;
}

/* the tree over rows 0..n-1 into K */
static void tcb_kd_build(const double *X, long long n, int dim, long long *K) {
    long long *perm = K + TCB_KD_HDR;
    for (long long i = 0; i < n; ++i) perm[i] = i;
    double *nodes = (double *)(perm + n);
    K[1] = tcb_kd_build_node(X, dim, perm, nodes, 0, 0, n);
    K[0] = n;
}

/* a lower bound of the squared distances from x to the keys in a box: the sum, term by term in the distances' order, of
   the squared offsets of x outside the box; each offset is no larger than that term of a key's distance in floating point
   too (a difference rounds monotonically), and so is the sum */
static inline double tcb_kd_bound(const double *bx, int dim, const double *x) {
    double s = 0.0;
    for (int k = 0; k < dim; ++k) {
        double t = x[k] < bx[k] ? bx[k] - x[k] : x[k] > bx[dim + k] ? x[k] - bx[dim + k] : 0.0;
        s += t*t;
    }
    return s;
}

/* tcb_nearest's answer (the first live row among the least squared distances, the same sums term by term) through the
   index K, *kdn (see above); K NULL or few rows: the scan. A subtree is skipped when the lower bound of its box exceeds
   the best distance (an equal one is searched, for its rows' indices): the scan's answer, always. Dead rows stay in
   the boxes (a looser bound, the same answer). */
long long tcb_nearest_kd(const double *X, long long n, int dim, const unsigned char *alive, const double *x,
                         long long *K, long long *kdn) {
    if (!K || n < TCB_KD_MIN || dim > 8) return tcb_nearest(X, n, dim, alive, x);
    for (int k = 0; k < dim; ++k) if (x[k] != x[k]) return tcb_nearest(X, n, dim, alive, x);
    long long nb = *kdn;
    if (nb > n || nb < TCB_KD_MIN || K[0] != nb || n - nb > (nb >> 4)) {   /* rows taken back, none yet, a long tail */
        tcb_kd_build(X, n, dim, K);
        *kdn = nb = n;
    }
    const long long *perm = K + TCB_KD_HDR;
    const double *nodes = (const double *)(perm + nb);
    long long nw = tcb_kd_nw(dim), best = -1, stk[TCB_KD_STACK];
    double bd = 0.0, sb[TCB_KD_STACK];
    for (long long i = nb; i < n; ++i) {              /* the tail: rows appended since the build */
        if (alive && !alive[i]) continue;
        const double *r = X + i*dim;
        double s = 0.0;
        for (int k = 0; k < dim; ++k) { double q = r[k] - x[k]; s += q*q; }
        if (best < 0 || s < bd) { best = i; bd = s; }
    }
    int top = 0;
    stk[0] = 0; sb[0] = tcb_kd_bound(nodes, dim, x); top = 1;
    while (top > 0) {
        --top;
        long long cur = stk[top];
        double b = sb[top];
        for (;;) {
            if (best >= 0 && b > bd) break;
            const double *bx = nodes + nw*cur;
            const long long *link = (const long long *)(bx + 2*dim);
            if (link[0] < 0) {                        /* a leaf: its rows */
                for (long long p = -1 - link[0]; p < link[1]; ++p) {
                    long long i = perm[p];
                    if (alive && !alive[i]) continue;
                    const double *r = X + i*dim;
                    double s = 0.0;
                    for (int k = 0; k < dim; ++k) { double q = r[k] - x[k]; s += q*q; }
                    if (best < 0 || s < bd || (s == bd && i < best)) { best = i; bd = s; }
                }
                break;
            }
            long long l = link[0], r = link[1];
            double bl = tcb_kd_bound(nodes + nw*l, dim, x), br = tcb_kd_bound(nodes + nw*r, dim, x);
            if (br < bl) { long long t = l; l = r; r = t; double u = bl; bl = br; br = u; }
            if (best < 0 || br <= bd) {
                if (top == TCB_KD_STACK) return tcb_nearest(X, n, dim, alive, x);
                stk[top] = r; sb[top] = br; ++top;
            }
            cur = l; b = bl;
        }
    }
    return best;
}

/* tcb_nearest_kd (K non-NULL) or tcb_nearest for each of the nq queries Q (nq x dim) into out: the benchmark's loop,
   timed without a call per query */
void tcb_nearest_batch(const double *X, long long n, int dim, const unsigned char *alive, const double *Q, long long nq,
                       long long *K, long long *kdn, long long *out) {
    for (long long j = 0; j < nq; ++j)
        out[j] = K ? tcb_nearest_kd(X, n, dim, alive, Q + j*(long long)dim, K, kdn)
                   : tcb_nearest(X, n, dim, alive, Q + j*(long long)dim);
}

"""
