"""Analytic inverse kinematics of a decoupled 7-joint arm (main arm q1..q4, wrist q5..q7), as used
by OC-RRT (orientation-constrained RRT for decoupled dual arms).

The arm is written as a product of exponentials in the world frame at ``q = 0``
(``g(q) = exp(ξ1 q1) ⋯ exp(ξ7 q7) M``, ξ read from Pinocchio), and solved with Paden-Kahan
subproblems:

* :meth:`DecoupledArmIK.wrist` — given q1..q4 and a required hand orientation, all (q5, q6, q7)
  in closed form. Orientation does not depend on link offsets, so this is exact for ANY three
  wrist axes (consecutive axes not parallel), intersecting or not.
* :meth:`DecoupledArmIK.solve` — full-pose IK parameterised by the redundancy angle q1 (the first
  joint): given q1 and the hand pose, all solutions of q2..q7. With a spherical wrist (axes 5-7
  meet at a point W) and axes 2, 3 meeting at a shoulder point S: q4 from ``|g W − S|``
  (subproblem 3, ≤ 2 solutions), (q2, q3) from the wrist point (subproblem 2, ≤ 2), (q5..q7)
  from :meth:`wrist` (≤ 2): at most 8 solutions. When axis 5 misses the point where axes 6 and 7
  meet (Baxter: 0.01 m offset between w0 and w1), the same construction with W on axes 6-7 gives a
  seed and a few Newton steps on q2..q7 (6 × 6, PoE Jacobian) finish the job; solutions whose
  Newton iteration does not reach ``newton_tolerance`` are dropped.

Joint limits are applied to every joint (``θ + 2πk`` candidates inside the limits are all
returned). Poses out of reach and singular wrists (axes 5 and 7 aligned: q5 + q7 undetermined)
return no solution (an empty array), never an inaccurate one: a solution is returned only if its
forward kinematics matches the request to ``accept_tolerance``.

Angles [rad], lengths [m]; ``R`` 3 × 3 rotation matrices, ``p`` 3-vectors in the world frame.
"""
from __future__ import annotations

import itertools
import math

import casadi as ca
import numpy as np
import pinocchio as pin

from ..errors import ConfigurationError, ModelError
from ..geometry.spatial import skew
from .ik_trig import (
    _angle_to,
    _closest_point,
    _cone_roots,
    _cos_sin_eq,
    _cross,
    _in_limits,
    _sx_angle_to,
    _sx_cos_sin_eq,
    _wrap,
    _wrap_vec,
    rotation_about,
    wrist_angles,
)
from .robot import RobotModel

__all__ = ["DecoupledArmIK", "rotation_about", "wrist_angles"]



_skew = skew


_I3 = np.eye(3)


class DecoupledArmIK:
    """Analytic IK of one 7-joint arm of a fixed-base :class:`RobotModel` (see the module doc).

    ``arm``: arm group name (exactly 7 revolute joints). ``singular_tol``: wrist / elbow / shoulder
    configurations closer than this (in cosine) to a double root are reported as no solution.
    ``accept_tolerance`` [m, rad]: a returned solution reproduces the request to this accuracy
    (checked with the PoE forward kinematics). ``newton_tolerance`` / ``max_newton``: refinement
    of non-spherical wrists.
    """

    def __init__(self, robot: RobotModel, arm: str, *, singular_tol: float = 1e-9, accept_tolerance: float = 1e-11,
                 newton_tolerance: float = 1e-14, max_newton: int = 30):
        if robot.is_floating:
            raise ModelError("DecoupledArmIK: fixed-base robots only")
        a = robot.arm(arm)
        if a.n != 7:
            raise ModelError(f"DecoupledArmIK: arm {arm!r} has {a.n} joints, expected 7")
        self.robot, self.arm = robot, a
        self.q_idx = np.asarray(a.q_idx)
        self.lower = robot.lower[a.j_idx].copy()
        self.upper = robot.upper[a.j_idx].copy()
        self.singular_tol = float(singular_tol)
        self.accept_tolerance = float(accept_tolerance)
        self.newton_tolerance = float(newton_tolerance)
        self.max_newton = int(max_newton)
        m = robot.model
        d = m.createData()
        q0 = np.zeros(m.nq)
        pin.computeJointJacobians(m, d, q0)
        pin.updateFramePlacements(m, d)
        J = pin.getFrameJacobian(m, d, a.ee_frame_id, pin.ReferenceFrame.WORLD)
        cols = np.asarray(a.v_idx)
        self.w = np.zeros((7, 3))
        self.p = np.zeros((7, 3))
        for k, c in enumerate(cols):
            v, om = J[:3, c], J[3:, c]
            n = np.linalg.norm(om)
            if abs(n - 1.0) > 1e-9 or np.linalg.norm(v + _cross(om, _cross(om, v)) - v) > 1e9:
                raise ModelError(f"DecoupledArmIK: joint {a.joint_names[k]!r} is not a revolute joint")
            self.w[k] = om / n
            self.p[k] = _cross(self.w[k], v)   # point on the axis closest to the origin (v = −ω × p)
        M = d.oMf[a.ee_frame_id]
        self.M_R, self.M_p = M.rotation.copy(), M.translation.copy()
        self.S, self.shoulder_offset = _closest_point([(self.p[1], self.w[1]), (self.p[2], self.w[2])])
        self.W, self.wrist_offset = _closest_point([(self.p[k], self.w[k]) for k in (4, 5, 6)])
        self.W67, off67 = _closest_point([(self.p[5], self.w[5]), (self.p[6], self.w[6])])
        if self.shoulder_offset > 1e-9:
            raise ModelError(f"DecoupledArmIK: axes 2 and 3 of arm {arm!r} do not intersect "
                             f"(gap {self.shoulder_offset:.3g} m); the full-pose IK needs a shoulder point")
        #: the three wrist axes meet at one point (else: analytic seed + Newton in :meth:`solve`)
        self.spherical = self.wrist_offset < 1e-9
        if not self.spherical and off67 > 1e-9:
            raise ModelError(f"DecoupledArmIK: wrist axes 6 and 7 of arm {arm!r} do not intersect ({off67:.3g} m)")
        self.Wseed = self.W if self.spherical else self.W67
        self._K = [_skew(w) for w in self.w]
        self._K2 = [K @ K for K in self._K]
        a, v = self.w[5], self.w[6]
        self._axv, self._av = _cross(a, v), float(a @ v)
        x = _cross(v, np.array([1.0, 0.0, 0.0]) if abs(v[0]) < 0.9 else np.array([0.0, 1.0, 0.0]))
        self._wx, self._vxx = x, _cross(v, x)
        self._chk_q = None

    # ------------------------------------------------------------------ forward kinematics (PoE)
    def _exp(self, k: int, t: float) -> tuple[np.ndarray, np.ndarray]:
        R = _I3 + math.sin(t) * self._K[k] + (1.0 - math.cos(t)) * self._K2[k]
        return R, self.p[k] - R @ self.p[k]

    def fk(self, q7) -> tuple[np.ndarray, np.ndarray]:
        """Hand orientation and position for the arm's 7 joint angles (PoE; equals Pinocchio's FK)."""
        R, p = np.eye(3), np.zeros(3)
        for k in range(7):
            Rk, pk = self._exp(k, q7[k])
            p = p + R @ pk
            R = R @ Rk
        return R @ self.M_R, R @ self.M_p + p

    def _prefix(self, qs) -> tuple[np.ndarray, np.ndarray]:
        R, p = np.eye(3), np.zeros(3)
        for k, t in enumerate(qs):
            Rk, pk = self._exp(k, t)
            p = p + R @ pk
            R = R @ Rk
        return R, p

    def main_rotation(self, q4) -> np.ndarray:
        """Rotation of the first four PoE factors."""
        return self._prefix(q4)[0]

    # ------------------------------------------------------------------ wrist
    def wrist(self, q4, R_des, *, limits: bool = True) -> np.ndarray:
        """All wrist solutions (k × 3: q5, q6, q7) that give the hand orientation ``R_des`` with
        the main-arm joints ``q4`` (4 angles). Exact for any wrist geometry (orientation only)."""
        Rt = self.main_rotation(q4).T @ np.asarray(R_des, float) @ self.M_R.T
        sols = self._wrist_angles(Rt)
        out = []
        for t5, t6, t7 in sols:
            if not limits:
                out.append((t5, t6, t7))
                continue
            for a5 in _in_limits(t5, self.lower[4], self.upper[4]):
                for a6 in _in_limits(t6, self.lower[5], self.upper[5]):
                    for a7 in _in_limits(t7, self.lower[6], self.upper[6]):
                        out.append((a5, a6, a7))
        return np.array(out, float).reshape(-1, 3)

    def _wrist_angles(self, Rt) -> list[tuple[float, float, float]]:
        """:func:`wrist_angles` for this arm's wrist axes with the axis constants precomputed."""
        u, a, v = self.w[4], self.w[5], self.w[6]
        Rtv = Rt @ v
        uRtv = float(u @ Rtv)
        out = []
        for t6 in _cone_roots(u, a, v, Rtv, self.singular_tol):
            c6, s6 = math.cos(t6), math.sin(t6)
            r6v = v * c6 + self._axv * s6 + a * (self._av * (1.0 - c6))
            # project on the plane ⊥ u first: near the singular wrist both projections are small and
            # the angle keeps its relative accuracy (dot products of the unprojected vectors would not)
            x5 = r6v - u * float(u @ r6v)
            y5 = Rtv - u * uRtv
            t5 = math.atan2(float(u @ _cross(x5, y5)), float(x5 @ y5))
            R56 = (_I3 + math.sin(t5) * self._K[4] + (1.0 - math.cos(t5)) * self._K2[4]) @ \
                (_I3 + s6 * self._K[5] + (1.0 - c6) * self._K2[5])
            y = R56.T @ (Rt @ self._wx)
            t7 = math.atan2(float(y @ self._vxx), float(self._wx @ y))
            out.append((t5, _wrap(t6), t7))
        return out

    # ------------------------------------------------------------------ full pose
    def solve(self, R_des, p_des, q1: float) -> np.ndarray:
        """All joint vectors (k × 7) with ``q[0] = q1`` whose hand pose is (R_des, p_des), inside
        the joint limits. Empty (0 × 7) when unreachable or singular."""
        R_des = np.asarray(R_des, float)
        p_des = np.asarray(p_des, float)
        if not (self.lower[0] - 1e-12 <= q1 <= self.upper[0] + 1e-12):
            return np.zeros((0, 7))
        R1, p1 = self._exp(0, q1)
        # g1 = exp(ξ1 q1)^-1 g_d M^-1
        Rg = R1.T @ R_des @ self.M_R.T
        pg = R1.T @ (p_des - R_des @ self.M_R.T @ self.M_p - p1)
        if self.spherical:
            sols = [x for _, x in self._position_branches(Rg, pg, q1, self.Wseed)]
        else:
            sols = self._offset_wrist_solutions(Rg, pg, q1, R_des, p_des)
        out: list[np.ndarray] = []
        for x in sols:
            ys = self._limit_variants(x)
            if not ys:
                continue
            R, p = self.fk(x)
            if (np.linalg.norm(p - p_des) > self.accept_tolerance
                    or np.linalg.norm(pin.log3(R.T @ R_des)) > self.accept_tolerance):
                continue
            for y in ys:
                if not any(np.max(np.abs(y - z)) < 1e-9 for z in out):
                    out.append(y)
        return np.array(out, float).reshape(-1, 7)

    def _position_branches(self, Rg, pg, q1, W) -> list[tuple[tuple[int, int, int], np.ndarray]]:
        """Branches (q1, q2..q7): the point ``Wseed`` (fixed by q6, q7) is where the pose needs it
        once it has been carried to ``W`` by q5 (W = Wseed for a spherical wrist), then the wrist."""
        Q = Rg @ self.Wseed + pg             # where the wrist point must go (before q2, q3, q4)
        S = self.S
        dist2 = float((Q - S) @ (Q - S))
        w4, p4 = self.w[3], self.p[3]
        u, v = W - p4, S - p4
        up, vp = u - w4 * (w4 @ u), v - w4 * (w4 @ v)
        delta2 = dist2 - float(w4 @ (u - v)) ** 2
        C = 0.5 * (float(up @ up) + float(vp @ vp) - delta2)
        out = []
        for i4, t4 in enumerate(_cos_sin_eq(float(up @ vp), float(w4 @ _cross(up, vp)), C, self.singular_tol)):
            R4, p4t = self._exp(3, t4)
            P = R4 @ W + p4t
            for i2, (t2, t3) in enumerate(self._sub2(P - S, Q - S)):
                R234 = self._exp(1, t2)[0] @ self._exp(2, t3)[0] @ R4
                Rt = R234.T @ Rg
                for i5, (t5, t6, t7) in enumerate(self._wrist_angles(Rt)):
                    out.append(((i4, i2, i5), np.array([q1, t2, t3, t4, t5, t6, t7])))
        return out

    def _offset_wrist_solutions(self, Rg, pg, q1, R_des, p_des, n_grid: int = 36) -> list[np.ndarray]:
        """Axis 5 misses the wrist point: for a trial q5 the point is carried to W(q5) and every
        analytic branch returns its own q5'; solutions are the roots of q5' − q5 on each branch.
        Roots are bracketed on a grid of ``n_grid`` q5 values, refined by secant steps on the
        same function and polished by Newton on q2..q7 (analytic seed + Newton)."""
        grid = np.linspace(-math.pi, math.pi, n_grid + 1)
        vals: dict = {}
        for g, t in enumerate(grid):
            W5 = rotation_about(self.w[4], t) @ (self.W67 - self.p[4]) + self.p[4]
            for key, x in self._position_branches(Rg, pg, q1, W5):
                vals.setdefault(key, {})[g] = (_wrap(x[4] - t), x)
        out: list[np.ndarray] = []
        for key, d in vals.items():
            for g in range(n_grid):
                if g not in d or g + 1 not in d:
                    continue
                fa, xa = d[g]
                fb, xb = d[g + 1]
                if fa == 0.0 or fa * fb > 0 or abs(fa - fb) > 1.0:
                    continue   # no root, or the wrap-around jump of the angle difference
                ta, tb = grid[g], grid[g + 1]
                x = xa
                for _ in range(8):   # secant / regula falsi on f(q5) = q5'(q5) − q5
                    t = tb - fb * (tb - ta) / (fb - fa)
                    W5 = rotation_about(self.w[4], t) @ (self.W67 - self.p[4]) + self.p[4]
                    cand = [y for k, y in self._position_branches(Rg, pg, q1, W5) if k == key]
                    if not cand:
                        break
                    x = cand[0]
                    f = _wrap(x[4] - t)
                    if abs(f) < 1e-13:
                        break
                    if f * fa < 0:
                        tb, fb = t, f
                    else:
                        ta, fa = t, f
                xn = self._newton(x, R_des, p_des)
                if xn is not None and not any(np.abs(_wrap_vec(xn - y)).max() < 1e-8 for y in out):
                    out.append(xn)
        # the two elbow roots (i4 = 0, 1) of a branch merge at a fold where the wrist point leaves
        # the reach of the elbow: a root between the fold and the last grid point is bracketed by
        # the two roots' values at that grid point; Newton from the one closer to zero
        for key, d in vals.items():
            if key[0] != 0:
                continue
            other = vals.get((1,) + key[1:], {})
            for g, (fa, xa) in d.items():
                if g not in other or (g - 1 in d and g + 1 in d):
                    continue
                fb, xb = other[g]
                if fa * fb > 0 or abs(fa - fb) > 1.0:
                    continue
                xn = self._newton(xa if abs(fa) < abs(fb) else xb, R_des, p_des)
                if xn is not None and not any(np.abs(_wrap_vec(xn - y)).max() < 1e-8 for y in out):
                    out.append(xn)
        return out

    def _limit_variants(self, x) -> list[np.ndarray]:
        """Every 2πk shift of q2..q7 inside the limits (q1 is given: kept as it is)."""
        cands = [[float(x[0])]] + [_in_limits(float(x[k]), self.lower[k], self.upper[k]) for k in range(1, 7)]
        if any(not c for c in cands):
            return []
        return [np.array(c) for c in itertools.product(*cands)]

    def _sub2(self, p: np.ndarray, q: np.ndarray) -> list[tuple[float, float]]:
        """Paden-Kahan subproblem 2: (θ2, θ3) with R(w2, θ2) R(w3, θ3) p = q (axes through the origin)."""
        w2, w3 = self.w[1], self.w[2]
        if abs(float(p @ p) - float(q @ q)) > 1e-9 * max(1.0, float(q @ q)):
            return []
        c = float(w2 @ w3)
        den = c * c - 1.0
        al = (c * float(w3 @ p) - float(w2 @ q)) / den
        be = (c * float(w2 @ q) - float(w3 @ p)) / den
        n = _cross(w2, w3)
        g2 = (float(p @ p) - al * al - be * be - 2 * al * be * c) / float(n @ n)
        if g2 < self.singular_tol * float(p @ p):
            return []   # no solution or the tangent (singular) case
        out = []
        for g in (math.sqrt(g2), -math.sqrt(g2)):
            z = al * w2 + be * w3 + g * n
            out.append((_angle_to(w2, z, q), _angle_to(w3, p, z)))
        return out

    def _newton(self, x: np.ndarray, R_des, p_des) -> np.ndarray | None:
        """Newton on q2..q7 (q1 fixed) to the pose (non-spherical wrists)."""
        x = x.copy()
        for _ in range(self.max_newton):
            R, p = self.fk(x)
            ep = p_des - p
            eo = R @ pin.log3(R.T @ R_des)    # world-frame rotation error
            if max(np.abs(ep).max(), np.abs(eo).max()) < self.newton_tolerance:
                return x
            J = self._jacobian(x)[:, 1:]
            try:
                dx = np.linalg.solve(J, np.r_[ep, eo])
            except np.linalg.LinAlgError:
                return None
            if not np.all(np.isfinite(dx)) or np.abs(dx).max() > 0.5:
                return None
            x[1:] += dx
        R, p = self.fk(x)
        err = max(np.linalg.norm(p_des - p), np.linalg.norm(pin.log3(R.T @ R_des)))
        return x if err < 10 * self.newton_tolerance else None

    def _jacobian(self, x) -> np.ndarray:
        """6 × 7 world Jacobian of the hand-origin velocity [v; ω] (PoE)."""
        _, p_e = self.fk(x)
        J = np.zeros((6, 7))
        R, p = np.eye(3), np.zeros(3)
        for k in range(7):
            wk = R @ self.w[k]
            pk = R @ self.p[k] + p
            J[:3, k] = _cross(wk, p_e - pk)
            J[3:, k] = wk
            Rk, tk = self._exp(k, x[k])
            p = p + R @ tk
            R = R @ Rk
        return J

    # ------------------------------------------------------------------ symbolic branches (compiled kernels)
    def sx_exp(self, k: int, t):
        """:meth:`_exp` on a CasADi SX angle."""
        R = ca.DM.eye(3) + ca.sin(t) * ca.DM(self._K[k]) + (1.0 - ca.cos(t)) * ca.DM(self._K2[k])
        return R, ca.DM(self.p[k]) - R @ ca.DM(self.p[k])

    def sx_fk(self, q) -> tuple:
        """:meth:`fk` on 7 CasADi SX angles: (R 3 × 3, p 3 × 1)."""
        R, p = ca.SX.eye(3), ca.SX.zeros(3)
        for k in range(7):
            Rk, pk = self.sx_exp(k, q[k])
            p = p + R @ pk
            R = R @ Rk
        return R @ ca.DM(self.M_R), R @ ca.DM(self.M_p) + p

    def sx_wrist_angles(self, Rt) -> list[tuple]:
        """:meth:`_wrist_angles` in CasADi SX: both branches ``(t5, t6, t7, ok)`` (``ok`` = 1 where
        the branch exists and is not singular; the angles stay finite either way)."""
        u, a, v = (ca.DM(x) for x in (self.w[4], self.w[5], self.w[6]))
        Rtv = Rt @ v
        c = ca.dot(u, Rtv)
        out = []
        for t6, ok in _cone_roots(self.w[4], self.w[5], self.w[6], Rtv, self.singular_tol, sx=True):
            c6, s6 = ca.cos(t6), ca.sin(t6)
            r6v = v * c6 + ca.DM(self._axv) * s6 + a * (self._av * (1.0 - c6))
            x5, y5 = r6v - u * ca.dot(u, r6v), Rtv - u * c
            t5 = ca.atan2(ca.dot(u, ca.cross(x5, y5)), ca.dot(x5, y5))
            R56 = (ca.DM.eye(3) + ca.sin(t5) * ca.DM(self._K[4]) + (1.0 - ca.cos(t5)) * ca.DM(self._K2[4])) @ \
                (ca.DM.eye(3) + s6 * ca.DM(self._K[5]) + (1.0 - c6) * ca.DM(self._K2[5]))
            y = R56.T @ (Rt @ ca.DM(self._wx))
            t7 = ca.atan2(ca.dot(y, ca.DM(self._vxx)), ca.dot(ca.DM(self._wx), y))
            out.append((t5, ca.atan2(s6, c6), t7, ok))
        return out

    def sx_prefix(self, qs) -> tuple:
        """Product of the first ``len(qs)`` PoE factors on CasADi SX angles: (R 3 × 3, p 3 × 1)."""
        R, p = ca.SX.eye(3), ca.SX.zeros(3)
        for k, t in enumerate(qs):
            Rk, pk = self.sx_exp(k, t)
            p = p + R @ pk
            R = R @ Rk
        return R, p

    def sx_wrist(self, q4, R_des) -> list[tuple]:
        """:meth:`wrist` before joint limits, in CasADi SX: two ``(t5, t6, t7, ok)``."""
        return self.sx_wrist_angles(self.sx_prefix(q4)[0].T @ R_des @ ca.DM(self.M_R.T))

    def sx_hand_position(self, q4, R_des):
        """Hand position [m] for main-arm joints ``q4`` and hand orientation ``R_des`` (spherical
        wrists: the same for every wrist branch, the wrist point W being fixed by q5..q7):
        ``g_1..4(W) + R_des M_Rᵀ (M_p − W)``."""
        if not self.spherical:
            raise ModelError("DecoupledArmIK.sx_hand_position: needs a spherical wrist")
        R, p = self.sx_prefix(q4)
        W = ca.DM(self.W)
        return R @ W + p + R_des @ (ca.DM(self.M_R.T) @ (ca.DM(self.M_p) - W))

    def sx_solve(self, R_des, p_des, q1) -> list[tuple]:
        """:meth:`solve` before joint limits, in CasADi SX (spherical wrists only): eight branches
        ``(x, ok)`` in the order of :meth:`solve`, ``x`` 7 SX angles; ``ok`` = 1 where the branch
        exists and its PoE forward kinematics reproduces the request to ``accept_tolerance``."""
        if not self.spherical:
            raise ModelError("DecoupledArmIK.sx_solve: the closed-form full-pose IK needs a spherical wrist")
        R1, p1 = self.sx_exp(0, q1)
        MRt = ca.DM(self.M_R.T)
        Rg = R1.T @ R_des @ MRt
        pg = R1.T @ (p_des - R_des @ (MRt @ ca.DM(self.M_p)) - p1)
        Q = Rg @ ca.DM(self.Wseed) + pg
        S = self.S
        QS = Q - ca.DM(S)
        dist2 = ca.dot(QS, QS)
        w4, p4, W = self.w[3], self.p[3], self.Wseed
        u, v = W - p4, S - p4
        up, vp = u - w4 * (w4 @ u), v - w4 * (w4 @ v)
        delta2 = dist2 - float(w4 @ (u - v)) ** 2
        C = 0.5 * (float(up @ up) + float(vp @ vp) - delta2)
        out = []
        for t4, ok4 in _sx_cos_sin_eq(float(up @ vp), float(w4 @ _cross(up, vp)), C, self.singular_tol):
            R4, p4t = self.sx_exp(3, t4)
            P = R4 @ ca.DM(W) + p4t
            for t2, t3, ok2 in self._sx_sub2(P - ca.DM(S), QS):
                R234 = self.sx_exp(1, t2)[0] @ self.sx_exp(2, t3)[0] @ R4
                for t5, t6, t7, ok5 in self.sx_wrist_angles(R234.T @ Rg):
                    x = [q1, t2, t3, t4, t5, t6, t7]
                    R, p = self.sx_fk(x)
                    dp = p - p_des
                    # |R - R_des|_F = 2 sqrt(2) |sin(angle / 2)|: the rotation angle without acos
                    dR = ca.reshape(R - R_des, 9, 1)
                    acc = ca.logic_and(ca.dot(dp, dp) <= self.accept_tolerance ** 2,
                                       0.5 * ca.dot(dR, dR) <= self.accept_tolerance ** 2)
                    out.append((x, ok4 * ok2 * ok5 * acc))
        return out

    def _sx_sub2(self, p, q) -> list[tuple]:
        """:meth:`_sub2` in CasADi SX: two ``(θ2, θ3, ok)``."""
        w2, w3 = self.w[1], self.w[2]
        pp, qq = ca.dot(p, p), ca.dot(q, q)
        ok = ca.fabs(pp - qq) <= 1e-9 * ca.fmax(1.0, qq)
        c = float(w2 @ w3)
        den = c * c - 1.0
        w3p, w2q = ca.dot(ca.DM(w3), p), ca.dot(ca.DM(w2), q)
        al = (c * w3p - w2q) / den
        be = (c * w2q - w3p) / den
        n = _cross(w2, w3)
        g2 = (pp - al * al - be * be - 2 * al * be * c) / float(n @ n)
        ok = ca.logic_and(ok, g2 >= self.singular_tol * pp)
        g = ca.sqrt(ca.fmax(g2, 0.0))
        out = []
        for s in (g, -g):
            z = al * ca.DM(w2) + be * ca.DM(w3) + s * ca.DM(n)
            out.append((_sx_angle_to(w2, z, q), _sx_angle_to(w3, p, z), ok))
        return out

    # ------------------------------------------------------------------ helpers
    def arm_joints(self, q) -> np.ndarray:
        """This arm's 7 angles of a full configuration."""
        return np.asarray(q, float)[self.q_idx]

    def check_pose_inputs(self, R_des, p_des):
        R = np.asarray(R_des, float)
        if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9):
            raise ConfigurationError(f"R_des: expected a 3 × 3 rotation matrix, got {R!r}")
        p = np.asarray(p_des, float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ConfigurationError(f"p_des: expected 3 finite numbers [m], got {p!r}")
        return R, p
