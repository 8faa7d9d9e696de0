"""The C source of the closed-chain IK of TCBiRRT's native extension (:mod:`optplan.planners.kernel.ik`).

It computes what the compiled CasADi block of
:class:`~optplan.constraints.closed_chain.ClosedChainKinematics` computes (Alg. 4 of the TCBiRRT paper),
by hand and with less work per iteration:

* per arm, the forward kinematics of its chain only (the planning kernel's joint model: placements, axes,
  the right-angle frames taken as signed permutations), the hand frame, the errors of Eq. 5-6
  (``e_p = p_g − p``, ``e_o = R_g vee_log(Rᵀ R_g)``), the world-aligned Jacobian column by column
  (``ω × (p − o)``, ``ω``), and the damped step ``Jᵀ (J Jᵀ + δ² I)⁻¹ e`` by a 6 × 6 Cholesky solve;
* the step scaled by ``gain``, its largest joint change clipped to ``max_step``, the joints clamped to
  their limits;
* an arm whose errors are below ``(ε_p, ε_o)`` stops (as in the block) and costs nothing more: its chain
  is not evaluated again, where the generated block evaluates both arms in every iteration;
* an iteration counts while either arm has not converged; the solve fails after ``max_iterations``.

The iterates are the block's up to round-off (the CasADi code solves the 6 × 6 system by another
factorisation), so the iteration counts and the configurations agree with it to ~1e-12 rad away from a
tolerance tie (``tests/test_native_ik.py``).
"""
from __future__ import annotations

__all__ = ["IK_SOURCE"]

IK_SOURCE = r"""
#define TIK_MAXC 32

typedef struct {
    const kmodel *km;
    int nchain[2];             /* joints of each arm's chain, root first (kernel joint indices, no universe) */
    const int *chain;          /* 2 x TIK_MAXC */
    const int *col;            /* 2 x TIK_MAXC: the joint's column in the arm's Jacobian, -1 when not the arm's */
    int na[2];                 /* the arm's joints */
    const int *qidx;           /* 2 x TIK_MAXC: q index of column k */
    int eej[2];                /* the hand frame's parent joint */
    const double *eeplace;     /* 2 x 12: the hand frame in its joint (R row-major, p) */
    const double *grasp;       /* 2 x 12: the grasp frame in the object frame */
    const double *lower, *upper;
} tcb_ikm;

/* the chain of arm a at q into oMi (only its joints are written) */
static void tik_chain_fk(const tcb_ikm *m, int a, const double *q, double *oMi) {
    const kmodel *km = m->km;
    static const double I[12] = {1,0,0, 0,1,0, 0,0,1, 0,0,0};
    memcpy(oMi, I, sizeof I);
    for (int i = 0; i < m->nchain[a]; ++i) {
        int j = m->chain[TIK_MAXC*a + i];
        double L[12];
        const double *P = oMi + 12*km->jparent[j], *B = km->jplace + 12*j;
        const int *pm = km->jperm ? km->jperm + 3*j : 0;
        if (pm && pm[0]) {
            for (int c = 0; c < 3; ++c) {
                int r = (pm[c] > 0 ? pm[c] : -pm[c]) - 1;
                for (int k = 0; k < 3; ++k) L[3*k+c] = pm[c] > 0 ? P[3*k+r] : -P[3*k+r];
            }
            for (int k = 0; k < 3; ++k) L[9+k] = P[3*k]*B[9] + P[3*k+1]*B[10] + P[3*k+2]*B[11] + P[9+k];
        } else compose(P, B, L);
        joint_motion(L, km->jtype[j], km->jaxis + 3*j, q[km->jidx[j]], oMi + 12*j);
    }
}

/* the hand of arm a at q against its grasp target G (= P * grasp: R_g = R_o R_G, p_g = p_o + R_o t_G):
   |e_p|, |e_o|, e = (e_p, e_o) and the hand position (for the Jacobian); oMi holds the chain */
static void tik_errors(const tcb_ikm *m, int a, const double *q, const double *G, double *oMi, double *e,
                       double *pe, double *np_, double *no_) {
    tik_chain_fk(m, a, q, oMi);
    double H[12];
    compose(oMi + 12*m->eej[a], m->eeplace + 12*a, H);
    double M[9];                                     /* R^T R_g */
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) M[3*i+j] = H[i]*G[j] + H[3+i]*G[3+j] + H[6+i]*G[6+j];
    double v[3] = {0.5*(M[7] - M[5]), 0.5*(M[2] - M[6]), 0.5*(M[3] - M[1])};
    double s = sqrt(dot3(v, v)), c = (M[0] + M[4] + M[8] - 1.0) / 2.0;
    double th = atan2(s, c), f = s > 1e-12 ? th / (s > 1e-300 ? s : 1e-300) : 1.0;
    double w[3] = {v[0]*f, v[1]*f, v[2]*f};
    for (int i = 0; i < 3; ++i) {
        e[i] = G[9+i] - H[9+i];
        e[3+i] = G[3*i]*w[0] + G[3*i+1]*w[1] + G[3*i+2]*w[2];
        pe[i] = H[9+i];
    }
    *np_ = sqrt(e[0]*e[0] + e[1]*e[1] + e[2]*e[2]);
    *no_ = sqrt(e[3]*e[3] + e[4]*e[4] + e[5]*e[5]);
}

/* the world-aligned 6 x na Jacobian of arm a's hand (row-major; linear rows first) from its chain in oMi */
static void tik_jacobian(const tcb_ikm *m, int a, const double *oMi, const double *pe, double *J) {
    const kmodel *km = m->km;
    int na = m->na[a];
    memset(J, 0, sizeof(double) * 6 * (size_t)na);
    for (int i = 0; i < m->nchain[a]; ++i) {
        int k = m->col[TIK_MAXC*a + i];
        if (k < 0) continue;
        int j = m->chain[TIK_MAXC*a + i], t = km->jtype[j];
        const double *O = oMi + 12*j;
        double w[3];
        if (t >= 3) { int c = t - 3; w[0] = O[c]; w[1] = O[3+c]; w[2] = O[6+c]; }
        else {
            const double *u = km->jaxis + 3*j;
            for (int r = 0; r < 3; ++r) w[r] = O[3*r]*u[0] + O[3*r+1]*u[1] + O[3*r+2]*u[2];
        }
        if (t == 2) { J[k] += w[0]; J[na+k] += w[1]; J[2*na+k] += w[2]; continue; }
        double r[3] = {pe[0] - O[9], pe[1] - O[10], pe[2] - O[11]};
        J[k] += w[1]*r[2] - w[2]*r[1]; J[na+k] += w[2]*r[0] - w[0]*r[2]; J[2*na+k] += w[0]*r[1] - w[1]*r[0];
        J[3*na+k] += w[0]; J[4*na+k] += w[1]; J[5*na+k] += w[2];
    }
}

/* the damped step of arm a into dq (its columns): J^T (J J^T + d^2 I)^-1 e; na = m->na[a] (inlined with a
   constant na for the usual 6- and 7-joint arms: the compiler then unrolls the products) */
static inline __attribute__((always_inline)) void tik_step_n(const tcb_ikm *m, int a, const double *oMi,
                                                             const double *e, const double *pe, double d2,
                                                             double *dq, const int na) {
    double J[6*TIK_MAXC];
    tik_jacobian(m, a, oMi, pe, J);
    double A[36], x[6];
    for (int i = 0; i < 6; ++i)
        for (int j = 0; j <= i; ++j) {
            double s = 0.0;
            for (int k = 0; k < na; ++k) s += J[i*na+k]*J[j*na+k];
            A[6*i+j] = A[6*j+i] = s + (i == j ? d2 : 0.0);
        }
    for (int j = 0; j < 6; ++j) {                    /* Cholesky A = L L^T in the lower triangle */
        double s = A[7*j];
        for (int k = 0; k < j; ++k) s -= A[6*j+k]*A[6*j+k];
        s = s > 0.0 ? sqrt(s) : 1e-300;
        A[7*j] = s;
        for (int i = j + 1; i < 6; ++i) {
            double t = A[6*i+j];
            for (int k = 0; k < j; ++k) t -= A[6*i+k]*A[6*j+k];
            A[6*i+j] = t / s;
        }
    }
    for (int i = 0; i < 6; ++i) { double s = e[i]; for (int k = 0; k < i; ++k) s -= A[6*i+k]*x[k]; x[i] = s / A[7*i]; }
    for (int i = 5; i >= 0; --i) { double s = x[i]; for (int k = i + 1; k < 6; ++k) s -= A[6*k+i]*x[k]; x[i] = s / A[7*i]; }
    for (int k = 0; k < na; ++k) {
        double s = 0.0;
        for (int i = 0; i < 6; ++i) s += J[i*na+k]*x[i];
        dq[k] = s;
    }
}

static void tik_step(const tcb_ikm *m, int a, const double *oMi, const double *e, const double *pe, double d2,
                     double *dq) {
    int na = m->na[a];
    if (na == 7) tik_step_n(m, a, oMi, e, pe, d2, dq, 7);
    else if (na == 6) tik_step_n(m, a, oMi, e, pe, d2, dq, 6);
    else tik_step_n(m, a, oMi, e, pe, d2, dq, na);
}

/* Alg. 4 for both arms from seed toward the object pose P: 1 when converged (q in qout); *its = iterations */
static int tik_solve(const tcb_ikm *m, int nq, const double *seed, const double *P, double damping, double tol_p,
                     double tol_o, double gain, double max_step, int max_it, double *qout, long long *its) {
    double q[KMAXJ], oMi[2][12*KMAXJ], e[2][6], pe[2][3], dq[TIK_MAXC], G[2][12];
    int conv[2];
    memcpy(q, seed, (size_t)nq * sizeof(double));
    for (int a = 0; a < 2; ++a) {
        double ep, eo;
        compose(P, m->grasp + 12*a, G[a]);
        tik_errors(m, a, q, G[a], oMi[a], e[a], pe[a], &ep, &eo);
        conv[a] = ep < tol_p && eo < tol_o;
    }
    long long n = 0;
    for (;;) {
        if (conv[0] && conv[1]) { memcpy(qout, q, (size_t)nq * sizeof(double)); *its = n; return 1; }
        if (n >= max_it) { *its = n; return 0; }
        for (int a = 0; a < 2; ++a) {
            if (conv[a]) continue;
            int na = m->na[a];
            const int *qi = m->qidx + TIK_MAXC*a;
            tik_step(m, a, oMi[a], e[a], pe[a], damping*damping, dq);
            double mx = 0.0;
            for (int k = 0; k < na; ++k) { dq[k] *= gain; if (fabs(dq[k]) > mx) mx = fabs(dq[k]); }
            double sc = max_step / (mx > 1e-300 ? mx : 1e-300);
            if (sc > 1.0) sc = 1.0;
            for (int k = 0; k < na; ++k) {
                int i = qi[k];
                q[i] = fmin(fmax(q[i] + dq[k]*sc, m->lower[i]), m->upper[i]);
            }
        }
        ++n;
        for (int a = 0; a < 2; ++a) {
            if (conv[a]) continue;
            double ep, eo;
            tik_errors(m, a, q, G[a], oMi[a], e[a], pe[a], &ep, &eo);
            conv[a] = ep < tol_p && eo < tol_o;
        }
    }
}

/* for the tests: one solve; returns 1 converged, 0 not, with q and the iterations */
int tik_solve_api(const tcb_ikm *m, int nq, const double *seed, const double *P, const double *par, double *qout,
                  long long *its) {
    return tik_solve(m, nq, seed, P, par[0], par[1], par[2], par[3], par[4], (int)par[5], qout, its);
}

/* for the tests: the errors (e_p, e_o) and the 6 x na Jacobian (row-major) of arm a at q */
void tik_jacobian_api(const tcb_ikm *m, int a, const double *q, const double *P, double *e, double *J) {
    double oMi[12*KMAXJ], pe[3], ep, eo, G[12];
    compose(P, m->grasp + 12*a, G);
    tik_errors(m, a, q, G, oMi, e, pe, &ep, &eo);
    tik_jacobian(m, a, oMi, pe, J);
}
"""
