"""The C source of TCBiRRT's trapped streaks (:mod:`optplan.planners.tcbirrt_streak`).

It is appended to the extension library's source (after the sampler's, whose ``tcb_sample_near`` and clock it
uses, and the extension's ``tcb_extend_prefix``) and compiled with it.

``tcb_streak`` runs iterations of Alg. 1 as :meth:`~optplan.planners.tcbirrt.TCBiRRT._search` does while each
one is a plain trapped extension: the trees take turns (tree a, tree b, tree a, ...); each draws ξ_rand and its
nearest live node (``tcb_sample_near``), steps toward it (Eq. 3, with the node's adaptive step), and runs the
extension (``tcb_extend_prefix``). A trapped extension updates its node's step (``trap_adapt="step"``) and trap
count, and the next iteration runs. It stops, handing the iteration to the Python code, when

* the sampled node is at ξ_rand, or has other IK branches that cannot be drawn here (code 1: chosen in Python; they
  are drawn here, from the state of the search's NumPy Generator, unless the tree prefers a twin);
* the extension is not trapped (code 2: its poses and configurations are in ``P``, ``Q``);
* a trapped extension makes its node's trap count reach ``trap_count`` (code 3: the trap graft is due).

With ``advance`` set, an extension that is not trapped goes on here instead of code 2: its node (at its last valid
waypoint when it kept a prefix, keyed by ``tcb_xi_of_pose``) is added to the tree (into the tree's arrays, below their capacity; its poses and configurations logged for the
Python lists of poses and edges), its parent's step doubled back, and tree b connects toward the node step by step
(``tcb_connect_loop``, lines 7-11: the full step; among the nearest node's other IK branches the one whose
configuration is nearest the node's, ``tcb_twin_nearest``), each advanced or partial step's node added. A trapped
step, a step whose node is no nearer the target in ξ than the node it grew from, or the deadline after a step ends the
iteration here. The iteration is handed back with the node added when tree b's nearest node sits at the target (code
4: the connection goes on in Python), or after a step that reached the target or whose node has no room (code 5: its
poses and configurations in ``P``, ``Q``, its target in ``xi_sb``). ``tcb_connect`` runs the connection alone for the
Python loop's other connections (after a graft, a sampled twin, a handed-back extension).

It returns (code 0) after ``max_n`` iterations or when the deadline is reached (checked before every
iteration but the first). The caller computes ``max_n`` so that no event of the loop's head (grafts, lead
path, frontier grafts, stall, iteration cap) falls inside the streak. The pose of ξ_s comes from
``tcb_pose_xi``, which the Python code of the same search uses too.
"""
from __future__ import annotations

__all__ = ["STREAK_SOURCE"]

STREAK_SOURCE = r"""
/* R = Rz(yaw) Ry(pitch) Rx(roll) of xi (row-major) and its position: the pose of an extension's target, computed
   as Pinocchio's rpy.rpyToMatrix does (Eigen: the product of the three axis-angle quaternions, then its matrix),
   operation for operation, so that the two agree to the bit where neither is compiled with fused multiply-adds */
typedef struct { double x, y, z, w; } tcb_quat;

static tcb_quat tcb_quat_axis(double angle, int axis) {
    double h = 0.5*angle, s = sin(h);
    tcb_quat q = {(axis == 0 ? 1.0 : 0.0)*s, (axis == 1 ? 1.0 : 0.0)*s, (axis == 2 ? 1.0 : 0.0)*s, cos(h)};
    return q;
}

static tcb_quat tcb_quat_mul(tcb_quat a, tcb_quat b) {
    tcb_quat r;
    r.w = a.w*b.w - a.x*b.x - a.y*b.y - a.z*b.z;
    r.x = a.w*b.x + a.x*b.w + a.y*b.z - a.z*b.y;
    r.y = a.w*b.y + a.y*b.w + a.z*b.x - a.x*b.z;
    r.z = a.w*b.z + a.z*b.w + a.x*b.y - a.y*b.x;
    return r;
}

void tcb_pose_xi(const double *xi, double *P) {
    tcb_quat q = tcb_quat_mul(tcb_quat_mul(tcb_quat_axis(xi[5], 2), tcb_quat_axis(xi[4], 1)), tcb_quat_axis(xi[3], 0));
    double tx = 2.0*q.x, ty = 2.0*q.y, tz = 2.0*q.z, twx = tx*q.w, twy = ty*q.w, twz = tz*q.w,
           txx = tx*q.x, txy = ty*q.x, txz = tz*q.x, tyy = ty*q.y, tyz = tz*q.y, tzz = tz*q.z;
    P[0] = 1.0 - (tyy + tzz); P[1] = txy - twz;         P[2] = txz + twy;
    P[3] = txy + twz;         P[4] = 1.0 - (txx + tzz); P[5] = tyz - twx;
    P[6] = txz - twy;         P[7] = tyz + twx;         P[8] = 1.0 - (txx + tyy);
    P[9] = xi[0]; P[10] = xi[1]; P[11] = xi[2];
}

/* xi = (position, roll, pitch, yaw) of a pose P (rotation row-major, position): Pinocchio's rpy.matrixToRpy as it
   computes it, operation for operation (Eigen 3.4's eulerAngles(2, 1, 0), reversed, its pitch folded into
   [-pi/2, pi/2]): the node a partial extension adds gets its key from here, in the streaks and outside them */
void tcb_xi_of_pose(const double *P, double *xi) {
    const double pi = 3.14159265358979323846;
    /* eulerAngles(2, 1, 0): i = 2, j = 1, k = 0, odd */
    double e0 = atan2(P[3], P[0]);                        /* atan2(R(j,k), R(k,k)) */
    double a = P[8], b = P[7], c2 = sqrt(a*a + b*b);      /* |(R(i,i), R(i,j))| */
    double e1;
    if (e0 < 0.0) { e0 += pi; e1 = atan2(-P[6], -c2); }
    else e1 = atan2(-P[6], c2);
    double s1 = sin(e0), c1 = cos(e0);
    double e2 = atan2(s1*P[2] - c1*P[5], c1*P[4] - s1*P[1]);
    double r = e2, p = e1, y = e0;
    if (p < -pi / 2) p += 2 * pi;
    if (p > pi / 2) {
        p = pi - p;
        if (r < 0.0) r += pi; else r -= pi;
        y -= pi;
    }
    xi[0] = P[9]; xi[1] = P[10]; xi[2] = P[11]; xi[3] = r; xi[4] = p; xi[5] = y;
}

/* among node i and the other live nodes of its twin group (first node thead[i], then tnext; none: i alone), the one
   whose configuration (rows of Q, nq each) is nearest q: the first of the group's order among equals */
long long tcb_twin_nearest(const double *Q, int nq, const long long *thead, const long long *tnext,
                           const unsigned char *alive, long long i, const double *q) {
    if (thead[i] < 0) return i;
    long long best = -1;
    double bd = 0.0;
    for (long long m = thead[i]; m >= 0; m = tnext[m]) {
        if (alive && !alive[m]) continue;
        const double *r = Q + (long long)nq*m;
        double s = 0.0;
        for (int k = 0; k < nq; ++k) { double d = r[k] - q[k]; s += d*d; }
        if (best < 0 || s < bd) { best = m; bd = s; }
    }
    return best;
}

/* NumPy's PCG64 (XSL-RR 128/64) and Generator.integers(n) for a small n (Lemire's bounded 32-bit draws on the
   generator's buffered 32-bit halves), step for step, on the state of the search's Generator: a node's twin is
   drawn here as TCBiRRT's Python loop draws it (_TaskTree.twin_nearest) */
typedef struct {
    unsigned long long hi, lo, inc_hi, inc_lo;   /* the 128-bit state and increment */
    int has_uint32; unsigned int uinteger;       /* the buffered upper half of the last 64-bit output */
    int used;                                    /* draws were taken (the Generator's state to be written back) */
} tcb_pcg;

#ifdef __SIZEOF_INT128__
static unsigned long long tcb_pcg_next64(tcb_pcg *g) {
    unsigned __int128 st = ((unsigned __int128)g->hi << 64) | g->lo, inc = ((unsigned __int128)g->inc_hi << 64) | g->inc_lo;
    const unsigned __int128 mult = ((unsigned __int128)0x2360ED051FC65DA4ULL << 64) | 0x4385DF649FCCF645ULL;
    st = st * mult + inc;
    g->hi = (unsigned long long)(st >> 64); g->lo = (unsigned long long)st;
    unsigned long long x = g->hi ^ g->lo;
    unsigned int rot = (unsigned int)(g->hi >> 58);
    return (x >> rot) | (x << ((-rot) & 63));
}

static unsigned int tcb_pcg_next32(tcb_pcg *g) {
    g->used = 1;
    if (g->has_uint32) { g->has_uint32 = 0; return g->uinteger; }
    unsigned long long v = tcb_pcg_next64(g);
    g->has_uint32 = 1;
    g->uinteger = (unsigned int)(v >> 32);
    return (unsigned int)(v & 0xffffffffULL);
}

/* Generator.integers(n), 1 <= n < 2^32 (no draw for n = 1) */
static long long tcb_pcg_below(tcb_pcg *g, long long n) {
    unsigned int rng = (unsigned int)(n - 1);
    if (rng == 0) return 0;
    unsigned int excl = rng + 1;
    unsigned long long m = (unsigned long long)tcb_pcg_next32(g) * excl;
    unsigned int left = (unsigned int)(m & 0xffffffffULL);
    if (left < excl) {
        unsigned int thr = (0xffffffffU - rng) % excl;
        while (left < thr) {
            m = (unsigned long long)tcb_pcg_next32(g) * excl;
            left = (unsigned int)(m & 0xffffffffULL);
        }
    }
    return (long long)(m >> 32);
}
#define TCB_HAVE_PCG 1
#else
#define TCB_HAVE_PCG 0
static long long tcb_pcg_below(tcb_pcg *g, long long n) { (void)g; (void)n; return -1; }
#endif

/* for the tests: k draws of Generator.integers(n) into out, the state advanced in g */
int tcb_pcg_integers(tcb_pcg *g, long long n, long long k, long long *out) {
    if (!TCB_HAVE_PCG) return -1;
    for (long long j = 0; j < k; ++j) out[j] = tcb_pcg_below(g, n);
    return 0;
}

typedef struct {
    double *X; long long n; const unsigned char *alive;   /* keys (n x 6), live mask or NULL */
    double *pose;            /* n x 12: rotation row-major, position */
    double *q;               /* n x nq */
    double *dom;             /* n: the node's adaptive step (inf: unset) */
    long long *trapn;        /* n: trapped extensions counted at the node */
    unsigned char *twin;     /* n: 1 when the node has other IK branches */
    int count_traps;         /* trapped extensions are counted (trap grafts left) */
    long long *parent;       /* n: the parent node */
    long long *thead, *tnext;   /* n: the node's twin group (its first node, -1: none; the next one, -1: last) */
    unsigned char *checked;  /* n: the edge from the parent verified (lazy edges) */
    long long cap;           /* rows the arrays hold: a node is added here only below it */
    int twin_draw;           /* a sampled node's twin is drawn here (no preferred twins in this tree) */
    long long *K, *kdn;      /* the keys' k-d index (tcb_nearest_kd; K NULL: none) */
} tcb_stree;

typedef struct {
    double step_size; int step_adapt; int prefix; long long n_interp;
    long long trap_count, trap_after, it0, max_n;
    int clock_kind; double end;
    int advance; long long log_cap;   /* advanced extensions and their trapped connections here; node log rows */
    int pcg_on; tcb_pcg pcg;          /* the search Generator's state: twins drawn here (in: its state; out: advanced) */
    /* out */
    long long n_done, i_near, k; int code, reach;
    double xi_rand[6], xi_s[6], Ps[12];
    long long n_ext, n_trap, n_log;   /* extensions applied here, of them trapped; nodes added (log rows) */
    long long n_partial;              /* extensions applied here that kept a prefix of their waypoints */
    long long i_a, i_nb, k_b; int reach_b;   /* codes 4, 5: the node added; the connection's node, kept, reach */
    double xi_sb[6];                  /* code 5: the connection step's target */
    int conn_trapped;                 /* a connection ended here: 1 a trapped step, 2 no nearer, 0 the deadline */
    /* the dynamic domain (trap_adapt "domain"): a sample farther than its nearest node's dom is drawn again, up to
       domain_tries draws (the last one kept); a trapped extension sets its node's dom to domain_radius * step_size */
    int domain_adapt, domain_tries; double domain_radius;
    long long n_rej;                  /* out: draws outside their nearest node's domain */
} tcb_streak_args;

/* node i's extension toward xi_s (n waypoints), not trapped, its first k waypoints kept (P, Q): its node added to tree t as
   TCBiRRT._extended adds it, logged (LM: tree, node, kept; LP, LQ: the extension's poses and configurations) for the
   Python lists of poses and edges; the node's index */
static long long tcb_streak_add(const tcb_ctx *c, tcb_stree *t, int which, long long i, const double *xi_s, long long n,
                                const double *P, const double *Q, long long k, double *LP, double *LQ, long long *LM,
                                long long row) {
    long long m = t->n, nq = c->nq;
    if (k == n) memcpy(t->X + 6*m, xi_s, 6*sizeof(double));
    else tcb_xi_of_pose(P + 12*(k - 1), t->X + 6*m);      /* partial: the node at its last valid waypoint */
    memcpy(t->q + nq*m, Q + nq*(k - 1), (size_t)nq*sizeof(double));
    memcpy(t->pose + 12*m, P + 12*(k - 1), 12*sizeof(double));
    t->parent[m] = i; t->checked[m] = 0; t->dom[m] = INFINITY; t->trapn[m] = 0; t->twin[m] = 0;
    t->thead[m] = -1; t->tnext[m] = -1;
    t->n = m + 1;
    LM[3*row] = which; LM[3*row + 1] = m; LM[3*row + 2] = k;
    memcpy(LP + 12*n*row, P, (size_t)(12*n)*sizeof(double));
    memcpy(LQ + nq*n*row, Q, (size_t)(nq*k)*sizeof(double));
    return m;
}

/* Eq. 3's step from the key xn toward xt (d = xt - xn, its length dist > 0) by at most step, into out: xt itself
   when it is within the step (returns 1), else xn + step d / dist (0) */
static int tcb_step_toward(const double *xn, const double *xt, const double *d, double dist, double step, double *out) {
    if (dist <= step) { memcpy(out, xt, 6*sizeof(double)); return 1; }
    double f = step / dist;
    for (int k = 0; k < 6; ++k) out[k] = xn[k] + f*d[k];
    return 0;
}

/* lines 7-11 of Alg. 1: tree b (t; which: its log tag) connects toward the node with key tx and configuration tq, step
   by step (the full step; among the nearest node's twins the one nearest tq). An advanced or partial step's node is
   added here. Returns 0 when a step was trapped (a->conn_trapped = 1), a step's node is no nearer the target in the key
   than the node it grew from (2), or the deadline has come after a step (0);
   4 when tree b's nearest node is at the target (the connection goes on in Python from there); 5 after a step that
   reached the target (its regrasp test) or whose node has no room here (its result in P, Q, a->i_nb, xi_sb, reach_b,
   k_b); -2: the model is too large */
static int tcb_connect_loop(const tcb_ctx *c, tcb_stree *tb, int which, const double *tx, const double *tq,
                            tcb_streak_args *a, double *P, double *Q, long long *cnt, double *LP, double *LQ,
                            long long *LM) {
    a->conn_trapped = 0;
    long long ib_key = -1, n_seen = 0;   /* the nearest row to tx so far and the rows it was taken from */
    double bd_key = 0.0;
    for (;;) {
        /* the nearest live row to tx: the rows are only appended here (none killed), so after the first search it is
           the last answer or one of the rows added since, nearer by strictly less (the first among equals stays) */
        long long ib;
        if (ib_key < 0) {
            ib = tcb_nearest_kd(tb->X, tb->n, 6, tb->alive, tx, tb->K, tb->kdn);
            const double *r = tb->X + 6*ib;
            bd_key = 0.0;
            for (int u = 0; u < 6; ++u) { double e = r[u] - tx[u]; bd_key += e*e; }
        } else {
            ib = ib_key;
            for (long long m = n_seen; m < tb->n; ++m) {
                if (tb->alive && !tb->alive[m]) continue;
                const double *r = tb->X + 6*m;
                double sm = 0.0;
                for (int u = 0; u < 6; ++u) { double e = r[u] - tx[u]; sm += e*e; }
                if (sm < bd_key) { ib = m; bd_key = sm; }
            }
        }
        ib_key = ib; n_seen = tb->n;
        if (tb->twin[ib]) ib = tcb_twin_nearest(tb->q, c->nq, tb->thead, tb->tnext, tb->alive, ib, tq);
        a->i_nb = ib;
        const double *xb = tb->X + 6*ib;
        double db[6], ddb = 0.0;
        for (int u = 0; u < 6; ++u) { db[u] = tx[u] - xb[u]; ddb += db[u]*db[u]; }
        double distb = sqrt(ddb);
        if (distb <= 0.0) return 4;
        a->reach_b = tcb_step_toward(xb, tx, db, distb, a->step_size, a->xi_sb);
        double Pb[12];
        tcb_pose_xi(a->xi_sb, Pb);
        const double *Rb = tb->pose + 12*ib;
        long long kb = tcb_extend_prefix(c, Rb, Rb + 9, Pb, Pb + 9, a->n_interp, tb->q + (long long)c->nq*ib,
                                         P, Q, cnt, a->prefix);
        if (kb < -1) return -2;
        a->n_ext += 1;
        if (kb <= 0) { a->n_trap += 1; a->conn_trapped = 1; return 0; }   /* trapped (-1: without a prefix kept) */
        a->k_b = kb;
        if ((kb == a->n_interp && a->reach_b) || tb->n >= tb->cap || a->n_log >= a->log_cap) return 5;
        long long m = tcb_streak_add(c, tb, which, ib, a->xi_sb, a->n_interp, P, Q, kb, LP, LQ, LM, a->n_log++);
        if (kb < a->n_interp) a->n_partial += 1;
        /* no nearer the target in the key than the node it grew from (a partial step's node keyed across an
           angle's +-pi): the connection ends, or it would grow the same node again and again */
        const double *xm = tb->X + 6*m;
        double dm = 0.0;
        for (int u = 0; u < 6; ++u) { double e = tx[u] - xm[u]; dm += e*e; }
        if (!(dm < ddb)) { a->conn_trapped = 2; return 0; }
        if (tcb_clock(a->clock_kind) >= a->end) return 0;
    }
}

/* the connection of lines 7-11 alone, for the Python loop (after a graft, a sampled twin, a handed-back extension):
   tcb_connect_loop with the counters and the node log reset; the return value is also a->code */
int tcb_connect(const tcb_ctx *c, tcb_stree *tb, const double *tx, const double *tq, tcb_streak_args *a, double *P,
                double *Q, long long *cnt, double *LP, double *LQ, long long *LM) {
    a->n_ext = 0; a->n_trap = 0; a->n_log = 0; a->n_partial = 0;
    int r = tcb_connect_loop(c, tb, 1, tx, tq, a, P, Q, cnt, LP, LQ, LM);
    a->code = r;
    return r;
}

/* returns the code (0..5; -2: the model is too large); a->n_done iterations were completed */
int tcb_streak(tcb_sampler *s, const tcb_ctx *c, tcb_stree *t0, tcb_stree *t1, tcb_streak_args *a,
               double *P, double *Q, long long *cnt, double *LP, double *LQ, long long *LM) {
    a->n_done = 0; a->n_ext = 0; a->n_trap = 0; a->n_log = 0; a->n_partial = 0; a->n_rej = 0;
    for (long long j = 0; j < a->max_n; ++j) {
        if (j > 0 && tcb_clock(a->clock_kind) >= a->end) { a->code = 0; return 0; }
        tcb_stree *ta = (j & 1) ? t1 : t0, *tb = (j & 1) ? t0 : t1;
        long long i = -1;
        for (int tr = 0; tr < (a->domain_adapt ? a->domain_tries : 1); ++tr) {
            i = tcb_sample_near(s, tb->X, tb->n, tb->alive, ta->X, ta->n, ta->alive, a->xi_rand, ta->K, ta->kdn);
            if (!a->domain_adapt) break;
            const double *xd = ta->X + 6*i;
            double e = 0.0;
            for (int k = 0; k < 6; ++k) { double u = a->xi_rand[k] - xd[k]; e += u*u; }
            if (e <= ta->dom[i] * ta->dom[i]) break;   /* inside the domain (inf: none set) */
            a->n_rej += 1;
        }
        a->i_near = i;
        const double *xn = ta->X + 6*i;
        double d[6], dd = 0.0;
        for (int k = 0; k < 6; ++k) { d[k] = a->xi_rand[k] - xn[k]; dd += d[k]*d[k]; }
        double dist = sqrt(dd);
        if (dist <= 0.0) { a->code = 1; return 1; }
        /* (twins share the node's key: the distance and the step's target are the same for each) */
        if (ta->twin[i]) {   /* one of the pose's live IK branches, drawn as _TaskTree.twin_nearest draws it */
            if (!a->pcg_on || !ta->twin_draw || !TCB_HAVE_PCG) { a->code = 1; return 1; }
            long long live = 0, r;
            for (long long m = ta->thead[i]; m >= 0; m = ta->tnext[m]) live += !ta->alive || ta->alive[m];
            r = tcb_pcg_below(&a->pcg, live);
            for (long long m = ta->thead[i]; m >= 0; m = ta->tnext[m])
                if (!ta->alive || ta->alive[m]) { if (r-- == 0) { i = m; break; } }
            a->i_near = i;
        }
        double step = (a->step_adapt && isfinite(ta->dom[i])) ? ta->dom[i] : a->step_size;
        a->reach = tcb_step_toward(xn, a->xi_rand, d, dist, step, a->xi_s);
        tcb_pose_xi(a->xi_s, a->Ps);
        const double *R0 = ta->pose + 12*i;
        long long k = tcb_extend_prefix(c, R0, R0 + 9, a->Ps, a->Ps + 9, a->n_interp, ta->q + (long long)c->nq*i,
                                        P, Q, cnt, a->prefix);
        if (k < -1) return -2;
        a->k = k;
        if (k > 0) {
            if (!a->advance || ta->n >= ta->cap || a->n_log >= a->log_cap) { a->code = 2; return 2; }
            /* advanced, reached its sample, or partial: the node, its parent's step doubled back (up to s) */
            long long m = tcb_streak_add(c, ta, ta == t1, i, a->xi_s, a->n_interp, P, Q, k, LP, LQ, LM, a->n_log++);
            a->n_ext += 1;
            a->k = k;
            if (k < a->n_interp) a->n_partial += 1;
            if (a->step_adapt) {
                double cur = isfinite(ta->dom[i]) ? ta->dom[i] : a->step_size, h = cur * 2.0;
                ta->dom[i] = h < a->step_size ? h : a->step_size;
            }
            /* lines 7-11: tree b connects toward the new node */
            a->i_a = m;
            int r = tcb_connect_loop(c, tb, tb == t1, ta->X + 6*m, ta->q + (long long)c->nq*m, a, P, Q, cnt, LP, LQ, LM);
            if (r != 0) { if (r > 0) a->code = r; return r; }
            a->n_done = j + 1;
            continue;
        }
        a->n_ext += 1; a->n_trap += 1;
        if (a->domain_adapt) ta->dom[i] = a->step_size * a->domain_radius;   /* trapped: the node's domain */
        if (a->step_adapt) {   /* trapped: the node's step halved, down to s/8 */
            double cur = isfinite(ta->dom[i]) ? ta->dom[i] : a->step_size, h = cur * 0.5, lo = a->step_size / 8.0;
            ta->dom[i] = h > lo ? h : lo;
        }
        if (ta->count_traps && a->it0 + j + 1 > a->trap_after) {
            ta->trapn[i] += 1;
            if (ta->trapn[i] == a->trap_count) { a->n_ext -= 1; a->n_trap -= 1; a->code = 3; return 3; }
        }
        a->n_done = j + 1;
    }
    a->code = 0;
    return 0;
}
"""
