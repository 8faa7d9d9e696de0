"""The C source of TCBiRRT's trapped streaks (:mod:`optplan.planners.tcbirrt_streak`).

It is appended to the extension library's source (after the sampler's, whose ``tcb_sample_near`` and clock it
uses, and the extension's ``tcb_extend_prefix``) and compiled with it.

``tcb_streak`` runs iterations of Alg. 1 as :meth:`~optplan.planners.tcbirrt.TCBiRRT._search` does while each
one is a plain trapped extension: the trees take turns (tree a, tree b, tree a, ...); each draws ξ_rand and its
nearest live node (``tcb_sample_near``), steps toward it (Eq. 3, with the node's adaptive step), and runs the
extension (``tcb_extend_prefix``). A trapped extension updates its node's step (``trap_adapt="step"``) and trap
count, and the next iteration runs. It stops, handing the iteration to the Python code, when

* the sampled node has other IK branches (code 1: its twins are chosen in Python) or is at ξ_rand;
* the extension is not trapped (code 2: its poses and configurations are in ``P``, ``Q``);
* a trapped extension makes its node's trap count reach ``trap_count`` (code 3: the trap graft is due);

and returns (code 0) after ``max_n`` iterations or when the deadline is reached (checked before every
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

typedef struct {
    const double *X; long long n; const unsigned char *alive;   /* keys (n x 6), live mask or NULL */
    const double *pose;      /* n x 12: rotation row-major, position */
    const double *q;         /* n x nq */
    double *dom;             /* n: the node's adaptive step (inf: unset) */
    long long *trapn;        /* n: trapped extensions counted at the node */
    const unsigned char *twin;   /* n: 1 when the node has other IK branches */
    int count_traps;         /* trapped extensions are counted (trap grafts left) */
} tcb_stree;

typedef struct {
    double step_size; int step_adapt; int prefix; long long n_interp;
    long long trap_count, trap_after, it0, max_n;
    int clock_kind; double end;
    /* out */
    long long n_done, i_near, k; int code, reach;
    double xi_rand[6], xi_s[6], Ps[12];
} tcb_streak_args;

/* returns the code (0..3; -2: the model is too large); a->n_done iterations were completed */
int tcb_streak(tcb_sampler *s, const tcb_ctx *c, tcb_stree *t0, tcb_stree *t1, tcb_streak_args *a,
               double *P, double *Q, long long *cnt) {
    a->n_done = 0;
    for (long long j = 0; j < a->max_n; ++j) {
        if (j > 0 && tcb_clock(a->clock_kind) >= a->end) { a->code = 0; return 0; }
        tcb_stree *ta = (j & 1) ? t1 : t0, *tb = (j & 1) ? t0 : t1;
        long long i = tcb_sample_near(s, tb->X, tb->n, tb->alive, ta->X, ta->n, ta->alive, a->xi_rand);
        a->i_near = i;
        if (ta->twin[i]) { a->code = 1; return 1; }
        const double *xn = ta->X + 6*i;
        double d[6], dd = 0.0;
        for (int k = 0; k < 6; ++k) { d[k] = a->xi_rand[k] - xn[k]; dd += d[k]*d[k]; }
        double dist = sqrt(dd);
        if (dist <= 0.0) { a->code = 1; return 1; }
        double step = (a->step_adapt && isfinite(ta->dom[i])) ? ta->dom[i] : a->step_size;
        a->reach = dist <= step;
        if (a->reach) memcpy(a->xi_s, a->xi_rand, 6*sizeof(double));
        else { double f = step / dist; for (int k = 0; k < 6; ++k) a->xi_s[k] = xn[k] + f*d[k]; }
        tcb_pose_xi(a->xi_s, a->Ps);
        const double *R0 = ta->pose + 12*i;
        long long k = tcb_extend_prefix(c, R0, R0 + 9, a->Ps, a->Ps + 9, a->n_interp, ta->q + (long long)c->nq*i,
                                        P, Q, cnt, a->prefix);
        if (k < -1) return -2;
        a->k = k;
        if (k > 0) { a->code = 2; return 2; }
        if (a->step_adapt) {   /* trapped: the node's step halved, down to s/8 */
            double cur = isfinite(ta->dom[i]) ? ta->dom[i] : a->step_size, h = cur * 0.5, lo = a->step_size / 8.0;
            ta->dom[i] = h > lo ? h : lo;
        }
        if (ta->count_traps && a->it0 + j + 1 > a->trap_after) {
            ta->trapn[i] += 1;
            if (ta->trapn[i] == a->trap_count) { a->code = 3; return 3; }
        }
        a->n_done = j + 1;
    }
    a->code = 0;
    return 0;
}
"""
