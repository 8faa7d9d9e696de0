"""The two arm models of the space-arc equivalent kinematics (the DSHDASR paper): residuals (Eq. 19-40),
arcs for the obstacle distances (Eq. 45-47), arc parameters from a joint configuration, and joint
recovery from the arc parameters (Eq. 51-62). See :mod:`optplan.papers.dshdasr.arcs` for the conventions.

Directions among the unknowns are two spherical angles (Eq. 25) measured in a reference frame
``R_ref``: ``k = R_ref · sph(a1, a2)``. With ``R_ref = I`` this is the paper's parameterization; the
planner re-centres ``R_ref`` at every waypoint on the previous direction (so the angles start at
(π/2, 0)), which keeps them away from the poles of Eq. 25 where a direction has no unique angles.
"""
from __future__ import annotations

import math

import casadi as ca
import numpy as np

from .arcs import Arc, _dot, _norm, _series_guard, _sinc, arc_from_tangent_length, sph, sph_angles

__all__ = ["DiscreteArcModel", "SerpentineArcModel", "frame_on", "pair_angles"]


def _np(x) -> np.ndarray:
    # casadi converts a constant SX/MX to DM at run time; its stubs list only numeric inputs
    return np.array(ca.DM(x)).ravel() if isinstance(x, (ca.DM, ca.SX, ca.MX)) else np.asarray(x, float)  # type: ignore[arg-type]


def frame_on(k) -> np.ndarray:
    """A rotation whose x axis is the unit vector k (so sph(π/2, 0) in it is k)."""
    k = np.asarray(k, float) / np.linalg.norm(k)
    a = np.array([0.0, 0.0, 1.0]) if abs(k[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    y = _cross(a, k)
    y /= math.sqrt(y @ y)
    z = _cross(k, y)
    # sph(a1, a2) = (s1 c2, s1 s2, c1): at (π/2, 0) it is e_x of R_ref
    return np.column_stack([k, y, z])


def _dir(R_ref, a1, a2):
    return ca.mtimes(ca.DM(R_ref) if isinstance(R_ref, np.ndarray) else R_ref, sph(a1, a2))


def _angles_in(R_ref, k, a2_near=None):
    return sph_angles(np.asarray(R_ref, float).T @ k, a2_near)


def _rot(axis, ang):
    axis = np.asarray(axis, float)
    n = math.sqrt(axis @ axis)
    if n < 1e-300:
        return np.eye(3)
    x, y, z = axis / n
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * (K @ K)


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _cross(a, b) -> np.ndarray:
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _angle(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    c = _cross(a, b)
    return math.atan2(math.sqrt(c @ c), float(a @ b))


def _nearest(value: float, ref: float | None) -> float:
    if ref is None:
        return value
    return value + 2 * math.pi * round((ref - value) / (2 * math.pi))


def pair_angles(v, prev: tuple[float, float] | None = None) -> tuple[float, float]:
    """Roll/bend pair of an S-R-S joint pair: angles (θo, θe) with
    ``Rz(θo) Rx(−90°) Rz(θe) Rx(90°) e_z = v`` (v in the pair's input frame). Of the two branches
    (θe ≥ 0 and θo + π, −θe) the one nearest ``prev`` (after 2π unwrapping) is returned."""
    v = np.asarray(v, float)
    v = v / math.sqrt(v @ v)
    h = math.hypot(v[0], v[1])
    te = math.atan2(h, v[2])
    to = math.atan2(v[1], v[0]) if h > 1e-12 else (prev[0] if prev is not None else 0.0)
    cands = [(to, te), (to + math.pi, -te)]
    if prev is None:
        return cands[0][0], cands[0][1]
    best = None
    for o, e in cands:
        o, e = _nearest(o, prev[0]), _nearest(e, prev[1])
        dist = (o - prev[0]) ** 2 + (e - prev[1]) ** 2
        if best is None or dist < best[0]:
            best = (dist, o, e)
    assert best is not None   # cands is not empty
    return best[1], best[2]


# =========================================================================== Arm-a
class DiscreteArcModel:
    """Arm-a: three inscribed arcs of a non-offset 7-DOF (S-R-S) arm with standard D-H rows
    (θ1, L1, 0, −90°), (θ2, 0, 0, 90°), (θ3, L3, 0, −90°), (θ4, 0, 0, 90°), (θ5, L5, 0, −90°),
    (θ6, 0, 0, 90°), (θ7, L7, 0, 0) on a mount at ``base_xyz`` with axes ``base_R`` (world).

    Unknowns ``X = (φ1, φ2, φ3, x3, y3, z3, α31, α32)``; ``pe``, ``ke`` the desired tip position and
    approach (z) axis."""

    nx = 8
    names = ("phi1", "phi2", "phi3", "x3", "y3", "z3", "a31", "a32")
    residual_names = ("F1 angle C1", "F3 angle C2", "F4 forearm |P3~-P2~| = L5", "F5 angle C3",
                      "p3 - shoulder (x)", "p3 - shoulder (y)", "p3 - shoulder (z)")
    n_res = 7
    n_arcs = 3

    def __init__(self, L1: float, L3: float, L5: float, L7: float, base_xyz, base_R):
        self.L1, self.L3, self.L5, self.L7 = float(L1), float(L3), float(L5), float(L7)
        self.base_xyz = np.asarray(base_xyz, float)
        self.base_R = np.asarray(base_R, float)
        self.k1 = self.base_R[:, 2].copy()
        self.shoulder = self.base_xyz + self.L1 * self.k1
        self.T = (self.L3 / 2, self.L3 / 2, self.L5 / 2)   # tangent lengths of C1, C2, C3

    # ------------------------------------------------------------------ symbolic
    def _parts(self, X, pe, ke, R_ref=None):
        R_ref = np.eye(3) if R_ref is None else R_ref
        p3 = X[3:6]
        k3 = _dir(R_ref, X[6], X[7])
        V2 = p3 + self.L3 * k3          # elbow  (P̃2)
        V3 = pe - self.L7 * ke          # wrist  (P̃3)
        w = V3 - V2
        return p3, k3, V2, V3, w, _norm(w)

    def residuals(self, X, pe, ke, R_ref=None):
        """G1 (7 entries, see ``residual_names``); zero exactly on arm configurations."""
        p3, k3, V2, V3, w, n = self._parts(X, pe, ke, R_ref)
        k1 = ca.DM(self.k1)
        return ca.vertcat(
            ca.cos(X[0]) - _dot(k1, k3),
            ca.cos(X[1]) - _dot(k3, w) / n,
            n - (self.T[1] + self.T[2]),
            ca.cos(X[2]) - _dot(w, ke) / n,
            p3 - ca.DM(self.shoulder),
        )

    def paper_residuals(self, X, pe, ke, R_ref=None):
        """The paper's F1-F6 (Eq. 21, 24) in cos form — F2 and F6 included although F1 implies F2
        and F3/F4 imply F6 — plus the shoulder anchor; for comparison with the paper only."""
        p3, k3, V2, V3, w, n = self._parts(X, pe, ke, R_ref)
        k1 = ca.DM(self.k1)
        L3, L5 = self.L3, self.L5
        return ca.vertcat(
            ca.cos(X[0]) - _dot(k1, k3),
            L3 / 2 * _norm(k1 + k3) - L3 * ca.cos(X[0] / 2),
            ca.cos(X[1]) - _dot(k3, w) / n,
            _norm(V3 - p3) / 2 - L3 * ca.cos(X[1] / 2),
            ca.cos(X[2]) - _dot(w, ke) / n,
            _norm(w + L5 * ke) / 2 - L5 * ca.cos(X[2] / 2),
            p3 - ca.DM(self.shoulder),
        )

    def arcs(self, X, pe, ke, R_ref=None) -> list[Arc]:
        p3, k3, V2, V3, w, n = self._parts(X, pe, ke, R_ref)
        wh = w / n
        k1 = ca.DM(self.k1)
        T1, T2, T3 = self.T
        f = [ca.fabs(X[i]) for i in range(3)]   # every residual is even in φ (cos, T); arcs use |φ|
        return [arc_from_tangent_length(p3 - T1 * k1, k1, k3, f[0], T1),
                arc_from_tangent_length(V2 - T2 * k3, k3, wh, f[1], T2),
                arc_from_tangent_length(V2 + T2 * wh, wh, ke, f[2], T3)]

    def deviations(self, X):
        """Per arc, the largest distance between the arc and its two tangent link legs [m]."""
        return [self.T[i] * ca.tan(ca.fabs(X[i]) / 4) for i in range(3)]

    def bounds(self, phi_max: float = math.radians(175.0)):
        """Bounds on X. The residuals are even in φ (the sign of φ carries no information, the
        tangents do), so φ is bounded symmetrically: no bound is active at a straight joint."""
        lb = [-phi_max] * 3 + [-np.inf] * 5
        ub = [phi_max] * 3 + [np.inf] * 5
        return np.array(lb), np.array(ub)

    # ------------------------------------------------------------------ numeric
    def params_from_points(self, shoulder, elbow, wrist, tip, ke, R_ref=None, a_near=None) -> np.ndarray:
        """Arc parameters of a configuration given by its joint centres (world)."""
        R_ref = np.eye(3) if R_ref is None else R_ref
        k3 = (np.asarray(elbow) - shoulder) / np.linalg.norm(np.asarray(elbow) - shoulder)
        k5 = (np.asarray(wrist) - elbow) / np.linalg.norm(np.asarray(wrist) - elbow)
        a31, a32 = _angles_in(R_ref, k3, a_near)
        return np.array([_angle(self.k1, k3), _angle(k3, k5), _angle(k5, ke), *shoulder, a31, a32])

    def recover_joints(self, X, p_ed, R_ed, q_prev=None, R_ref=None) -> np.ndarray:
        """Joint angles (7) from the arc parameters and the desired tip pose (Eq. 51-57): the
        bending joints from the arc tangents (θ2, θ4, θ6 = φ1, φ2, φ3 up to the branch), the roll
        joints from the arc planes (atan2 of the plane normal in the previous joint frame), θ7 from
        ``R6ᵀ R_ed``. The branch of each roll/bend pair nearest ``q_prev`` is taken."""
        X = _np(X)
        R_ref = np.eye(3) if R_ref is None else R_ref
        R_ed = np.asarray(R_ed, float)
        ke = R_ed[:, 2]
        k3 = np.asarray(R_ref, float) @ sph(X[6], X[7])
        elbow = self.shoulder + self.L3 * k3
        wrist = np.asarray(p_ed, float) - self.L7 * ke
        k5 = (wrist - elbow) / np.linalg.norm(wrist - elbow)
        q = np.zeros(7)
        F = self.base_R.copy()
        for i, k in enumerate((k3, k5, ke)):
            prev = None if q_prev is None else (q_prev[2 * i], q_prev[2 * i + 1])
            q[2 * i], q[2 * i + 1] = pair_angles(F.T @ k, prev)
            F = F @ _rz(q[2 * i]) @ _rx(-math.pi / 2) @ _rz(q[2 * i + 1]) @ _rx(math.pi / 2)
        M = F.T @ R_ed
        q[6] = _nearest(math.atan2(M[1, 0], M[0, 0]), None if q_prev is None else q_prev[6])
        return q


# =========================================================================== Arm-b
class SerpentineArcModel:
    """Arm-b: one arc per segment of a serpentine arm of ``segments`` (5) segments, each of
    ``m`` (6) coupled universal joints and links of length ``Lb``; mount at ``base_xyz`` with axes
    ``base_R`` (k0 = its x axis; the first joint sits at the mount origin).

    Unknowns ``X = (φ1..φ5, x1, y1, z1, α11, α12, x3, y3, z3, α31, α32)``: segment 1 and segment 3 end
    points p1, p3 (the centre of the next segment's first joint) and directions k1, k3."""

    nx = 15
    names = ("phi1", "phi2", "phi3", "phi4", "phi5", "x1", "y1", "z1", "a11", "a12",
             "x3", "y3", "z3", "a31", "a32")
    residual_names = ("F1 angle C1", "F2 chord C1 (x)", "F2 chord C1 (y)", "F2 chord C1 (z)",
                      "F3 angle C2", "F4/F6 common tangent C2-C3", "F5 angle C3",
                      "F7 angle C4", "F8/F10 common tangent C4-C5", "F9 angle C5")
    n_res = 10
    n_arcs = 5

    def __init__(self, Lb: float, base_xyz, base_R, m: int = 6, segments: int = 5):
        if segments != 5:
            raise ValueError("the arc model is written for 5 segments (one single-arc set, two double-arc sets)")
        self.Lb, self.m, self.segments = float(Lb), int(m), segments
        self.base_xyz = np.asarray(base_xyz, float)
        self.base_R = np.asarray(base_R, float)
        self.k0 = self.base_R[:, 0].copy()
        self.p0 = self.base_xyz.copy()

    # ------------------------------------------------------------------ arc of one segment
    def tangent_length(self, phi):
        """T(φ) = (L_b/2) tan(φ/2) / tan(φ/2m), written as (L_b/2) U_{m−1}(cos u) cos u / cos(m u)
        with u = φ/2m (Chebyshev U: no 0/0 at a straight segment, T(0) = m L_b / 2)."""
        cos = math.cos if isinstance(phi, (float, int, np.floating)) else ca.cos
        u = phi / (2 * self.m)
        x = cos(u)
        U0, U1 = 1, 2 * x
        for _ in range(self.m - 2):
            U0, U1 = U1, 2 * x * U1 - U0
        return self.Lb / 2 * U1 * x / cos(self.m * u)

    def kappa(self, phi):
        return ca.tan(phi / (2 * self.m)) / (self.Lb / 2)

    def lam(self, phi):
        m = self.m
        c2 = 1.0 / (24 * m ** 3) + 1.0 / (12 * m)
        return _series_guard(phi, 1e-2, lambda y: ca.tan(y / (2 * m)) / ca.sin(y),
                             lambda y: 1.0 / (2 * m) + c2 * y * y) / (self.Lb / 2)

    def length(self, phi):
        u = phi / (2 * self.m)
        return self.m * self.Lb * ca.cos(u) / _sinc(u)

    def _arc(self, P, t0, t1, phi) -> Arc:
        phi = ca.fabs(phi)  # the residuals are even in φ; the arc uses |φ|
        return Arc(P, t0, t1, phi, self.kappa(phi), self.lam(phi), self.length(phi))

    # ------------------------------------------------------------------ symbolic
    def _unpack(self, X, R_ref):
        R1, R3 = (np.eye(3), np.eye(3)) if R_ref is None else R_ref
        return X[0:5], X[5:8], _dir(R1, X[8], X[9]), X[10:13], _dir(R3, X[13], X[14])

    def _double(self, pA, kA, pB, kB, fa, fb):
        Ta, Tb = self.tangent_length(fa), self.tangent_length(fb)
        Va = pA + (Ta - self.Lb / 2) * kA
        Vb = pB - (Tb + self.Lb / 2) * kB
        w = Vb - Va
        n = _norm(w)
        return Va, w, n, Ta, Tb

    def residuals(self, X, pe, ke, R_ref=None):
        """G2 (10 entries, see ``residual_names``); zero exactly on arm configurations."""
        phi, p1, k1, p3, k3 = self._unpack(X, R_ref)
        k0, p0, h = ca.DM(self.k0), ca.DM(self.p0), self.Lb / 2
        T1 = self.tangent_length(phi[0])
        out = [ca.cos(phi[0]) - _dot(k0, k1), p1 - p0 - (T1 - h) * k0 - (T1 + h) * k1]
        for pA, kA, pB, kB, fa, fb in ((p1, k1, p3, k3, phi[1], phi[2]), (p3, k3, pe, ke, phi[3], phi[4])):
            Va, w, n, Ta, Tb = self._double(pA, kA, pB, kB, fa, fb)
            out += [ca.cos(fa) - _dot(kA, w) / n, n - (Ta + Tb), ca.cos(fb) - _dot(w, kB) / n]
        return ca.vertcat(*out)

    def arcs(self, X, pe, ke, R_ref=None) -> list[Arc]:
        phi, p1, k1, p3, k3 = self._unpack(X, R_ref)
        k0, p0, h = ca.DM(self.k0), ca.DM(self.p0), self.Lb / 2
        out = [self._arc(p0 - h * k0, k0, k1, phi[0])]
        for pA, kA, pB, kB, fa, fb in ((p1, k1, p3, k3, phi[1], phi[2]), (p3, k3, pe, ke, phi[3], phi[4])):
            Va, w, n, Ta, Tb = self._double(pA, kA, pB, kB, fa, fb)
            wh = w / n
            out += [self._arc(pA - h * kA, kA, wh, fa), self._arc(Va + Ta * wh, wh, kB, fb)]
        return out

    def deviations(self, X):
        """Per arc, the largest distance between the arc and its link polygon [m]: a vertex of the
        tangent polygon (legs L_b/2, turn β = φ/m) is (L_b/2) tan(β/4) from the arc."""
        return [self.Lb / 2 * ca.tan(ca.fabs(X[i]) / (4 * self.m)) for i in range(5)]

    def bounds(self, phi_max: float):
        """Bounds on X: |φ_i| ≤ φ_max = m × the joint-axis limit keeps every joint in its limits
        (each joint bends by β = φ/m, and |pitch|, |yaw| ≤ β)."""
        lb = [-phi_max] * 5 + [-np.inf] * 10
        ub = [phi_max] * 5 + [np.inf] * 10
        return np.array(lb), np.array(ub)

    # ------------------------------------------------------------------ numeric
    def directions(self, X, pe, ke, R_ref=None) -> list[np.ndarray]:
        """Segment end directions k0..k5 (world) of arc parameters X and tip (pe, ke) (numpy)."""
        X = _np(X)
        R1, R3 = (np.eye(3), np.eye(3)) if R_ref is None else R_ref
        k1 = np.asarray(R1, float) @ sph(float(X[8]), float(X[9]))
        k3 = np.asarray(R3, float) @ sph(float(X[13]), float(X[14]))
        p1, p3 = X[5:8], X[10:13]
        pe, ke = np.asarray(pe, float), np.asarray(ke, float)
        ks = [self.k0, k1]
        h = self.Lb / 2
        for pA, kA, pB, kB, fa, fb in ((p1, k1, p3, k3, X[1], X[2]), (p3, k3, pe, ke, X[3], X[4])):
            Va = pA + (self.tangent_length(float(fa)) - h) * kA
            Vb = pB - (self.tangent_length(float(fb)) + h) * kB
            ks += [Vb - Va, kB]
        return [k / math.sqrt(k @ k) for k in ks]

    def params_from_segments(self, ends, dirs, R_ref=None, a_near=None) -> np.ndarray:
        """Arc parameters from the segment end points p_{i,e} and directions k_{i,e}, i = 1..5."""
        ks = [self.k0] + [np.asarray(d, float) for d in dirs]
        phi = [_angle(ks[i], ks[i + 1]) for i in range(5)]
        R1, R3 = (np.eye(3), np.eye(3)) if R_ref is None else R_ref
        n1 = n3 = None if a_near is None else a_near
        a1 = _angles_in(R1, ks[1], None if n1 is None else n1[0])
        a3 = _angles_in(R3, ks[3], None if n3 is None else n3[1])
        return np.array([*phi, *ends[0], *a1, *ends[2], *a3])

    def segment_joint_angles(self, R_in: np.ndarray, k_out) -> tuple[float, float, np.ndarray]:
        """(pitch, yaw) of a segment that turns the frame ``R_in`` (x = incoming direction) to the
        outgoing direction ``k_out`` in one plane, and the outgoing frame. Each pitch-yaw/yaw-pitch
        pair is a pure rotation by 2β about the normal of the bending plane (β = φ/m per joint)."""
        v = R_in.T @ np.asarray(k_out, float)
        v = v / math.sqrt(v @ v)
        h = math.hypot(v[1], v[2])
        phi = math.atan2(h, v[0])
        if h < 1e-300:
            return 0.0, 0.0, R_in.copy()
        uy, uz = v[1] / h, v[2] / h
        beta = phi / self.m
        d1 = np.array([math.cos(beta), math.sin(beta) * uy, math.sin(beta) * uz])
        yaw = math.asin(max(-1.0, min(1.0, d1[1])))
        pitch = math.atan2(-d1[2], d1[0])
        return pitch, yaw, R_in @ _rot([0.0, -uz, uy], phi)

    def recover_joints(self, X, pe, ke, R_ref=None) -> np.ndarray:
        """Joint angles (pitch, yaw of each segment's first joint; 10) from the arc parameters and
        the desired tip (Eq. 58-62): each segment's bending plane (normal k_{i-1} × k_i expressed in
        the segment's input frame) and angle from its end tangents, then the universal-joint angles
        that turn a link by φ_i/m in that plane. The tangents k2, k4 of the inner segments are the
        common tangents of the double-arc sets."""
        ks = self.directions(X, pe, ke, R_ref)
        F = self.base_R.copy()
        q = np.zeros(10)
        for i in range(5):
            q[2 * i], q[2 * i + 1], F = self.segment_joint_angles(F, ks[i + 1])
        return q
