"""Closed-form pieces of analytic arm IK (Paden-Kahan subproblems): rotations about an axis, the
angle turning one vector into another about an axis, ``A cos θ + B sin θ = C``, the cone roots of
subproblem 2, a wrist's three angles for a required rotation, angle wrapping and joint-limit
candidates. Angles [rad]; vectors in the world frame. Used by :mod:`.ik_analytic`."""
from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..errors import ModelError
from ..geometry.spatial import skew

__all__ = ["rotation_about", "wrist_angles"]

TWO_PI = 2.0 * math.pi
_I3 = np.eye(3)

def _cross(a, b) -> np.ndarray:
    """3-vector cross product (numpy.cross costs ~20x more for single 3-vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def rotation_about(w: np.ndarray, theta: float) -> np.ndarray:
    """Rotation by ``theta`` [rad] about the unit axis ``w`` (Rodrigues)."""
    K = skew(w)
    return _I3 + math.sin(theta) * K + (1.0 - math.cos(theta)) * (K @ K)


def _angle_to(w, a, b) -> float:
    """Angle of the rotation about unit ``w`` that takes a (projected ⊥ w) to b (projected ⊥ w)."""
    a = a - w * (w @ a)
    b = b - w * (w @ b)
    return math.atan2(float(w @ _cross(a, b)), float(a @ b))


def _cos_sin_eq(A: float, B: float, C: float, tol: float) -> list[float]:
    """Solutions θ of ``A cos θ + B sin θ = C`` (0, 1 or 2; a double root within ``tol`` → [])."""
    r = math.hypot(A, B)
    if r < 1e-14:
        return []
    c = C / r
    if abs(c) > 1.0 + tol:
        return []
    if abs(c) >= 1.0 - tol:
        return []   # tangent (singular) case: reported as no solution
    phi = math.atan2(B, A)
    d = math.acos(c)
    return [phi + d, phi - d]


def _sx_cos_sin_eq(A: float, B: float, C, tol: float) -> list[tuple]:
    """:func:`_cos_sin_eq` with a symbolic right-hand side C (A, B numbers): the two roots and a
    flag (1 where the roots exist and are not a double root within ``tol``)."""
    r = math.hypot(A, B)
    if r < 1e-14:
        raise ModelError("DecoupledArmIK: degenerate axis geometry (A cos θ + B sin θ with A = B = 0)")
    c = C / r
    ok = ca.fabs(c) < 1.0 - tol
    d = ca.acos(ca.fmin(ca.fmax(c, -1.0), 1.0))
    phi = math.atan2(B, A)
    return [(phi + d, ok), (phi - d, ok)]


def _sx_angle_to(w: np.ndarray, a, b):
    """:func:`_angle_to` with symbolic a, b (numeric unit axis w)."""
    W = ca.DM(w)
    a = a - W * ca.dot(W, a)
    b = b - W * ca.dot(W, b)
    return ca.atan2(ca.dot(W, ca.cross(a, b)), ca.dot(a, b))


def _cone_roots(u, a, v, x, tol: float, sx: bool = False):
    """θ with ``u · R(a, θ) v = u · x`` (unit vectors; the wrist's middle joint), accurate to
    rounding up to the double root: with α = ∠(u, a), β = ∠(a, v) the left side is
    ``cos α cos β + sin α sin β cos(θ − φ)``, between cos(α + β) and cos|α − β|; instead of
    ``acos`` of a ratio near ±1 (error ε / sin d), ``d = atan2(√((r − C)(r + C)), C)`` with
    ``r ∓ C`` as products of half-angle sines of γ = ∠(u, x) computed by atan2 (relative accuracy
    near the singular wrist). Returns (roots, ok) with ``sx`` (CasADi SX x), else a list (empty
    when unreachable or within ``tol`` of the double root)."""
    al = math.atan2(float(np.linalg.norm(_cross(u, a))), float(u @ a))
    be = math.atan2(float(np.linalg.norm(_cross(a, v))), float(a @ v))
    gmin, gmax = abs(al - be), al + be
    r = math.sin(al) * math.sin(be)
    phi = math.atan2(float(u @ _cross(a, v)), float(u @ v) - math.cos(al) * math.cos(be))
    k = float(u @ a) * float(a @ v)
    if r < 1e-14:
        raise ModelError("DecoupledArmIK: degenerate wrist axes (middle axis parallel to an outer one)")
    if sx:
        U = ca.DM(u)
        c = ca.dot(U, x)
        g = ca.atan2(ca.norm_2(ca.cross(U, x)), c)
        rm = 2.0 * ca.sin(0.5 * (g + gmin)) * ca.sin(0.5 * (g - gmin))
        rp = 2.0 * ca.sin(0.5 * (gmax + g)) * ca.sin(0.5 * (gmax - g))
        ok = ca.logic_and(rm > tol * r, rp > tol * r)
        d = ca.atan2(ca.sqrt(ca.fmax(rm * rp, 0.0)), c - k)
        return [(phi + d, ok), (phi - d, ok)]
    c = float(u @ x)
    g = math.atan2(float(np.linalg.norm(_cross(u, x))), c)
    rm = 2.0 * math.sin(0.5 * (g + gmin)) * math.sin(0.5 * (g - gmin))
    rp = 2.0 * math.sin(0.5 * (gmax + g)) * math.sin(0.5 * (gmax - g))
    if rm <= tol * r or rp <= tol * r:
        return []
    d = math.atan2(math.sqrt(rm * rp), c - k)
    return [phi + d, phi - d]


def wrist_angles(w5, w6, w7, Rt, singular_tol: float = 1e-10) -> list[tuple[float, float, float]]:
    """All (θ5, θ6, θ7) with ``R(w5, θ5) R(w6, θ6) R(w7, θ7) = Rt`` (angles in (−π, π]; no
    limits). Empty when Rt is unreachable or the wrist is singular (w5, w7 aligned)."""
    u, a, v = w5, w6, w7
    out = []
    for t6 in _cone_roots(u, a, v, Rt @ v, singular_tol):
        R6 = rotation_about(a, t6)
        t5 = _angle_to(u, R6 @ v, Rt @ v)
        R56 = rotation_about(u, t5) @ R6
        x = _cross(v, np.array([1.0, 0.0, 0.0]) if abs(v[0]) < 0.9 else np.array([0.0, 1.0, 0.0]))
        t7 = _angle_to(v, x, R56.T @ Rt @ x)
        out.append((t5, _wrap(t6), t7))
    return out


def _wrap_vec(x):
    return (x + math.pi) % TWO_PI - math.pi


def _wrap(t: float) -> float:
    return (t + math.pi) % TWO_PI - math.pi


def _in_limits(t: float, lo: float, hi: float, tol: float = 1e-12) -> list[float]:
    """Every ``t + 2πk`` inside [lo, hi]."""
    if hi - lo < TWO_PI and lo <= t <= hi:
        return [t]
    out = []
    k0 = math.ceil((lo - tol - t) / TWO_PI)
    while True:
        x = t + k0 * TWO_PI
        if x > hi + tol:
            break
        out.append(min(max(x, lo), hi) if (x < lo or x > hi) else x)
        k0 += 1
    return out



def _closest_point(lines) -> tuple[np.ndarray, float]:
    """Least-squares point nearest to several lines (p, w) and its largest distance to them."""
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for p, w in lines:
        P = np.eye(3) - np.outer(w, w)
        A += P
        b += P @ p
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    off = max(float(np.linalg.norm((np.eye(3) - np.outer(w, w)) @ (x - p))) for p, w in lines)
    return x, off
