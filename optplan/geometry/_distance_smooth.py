"""Backend-agnostic smooth building blocks for :mod:`optplan.geometry.distance`.

Every function here works on two backends with one code path:

* **numpy**: plain floats / ``numpy.ndarray`` (3-vectors of shape ``(3,)``, matrices ``(3, 3)``);
* **casadi**: ``casadi.SX`` / ``MX`` / ``DM`` (3-vectors are ``3 x 1`` columns).

The backend is chosen by :func:`select_ops` (CasADi as soon as one argument is a CasADi object) and
is passed around as an ``ops`` object exposing ``sqrt, exp, log, fmax, fmin, dot, mv, mtv, stack``.
All lengths are in metres [m], squared lengths in [m^2].

Private module: the public API lives in :mod:`optplan.geometry.distance`.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import casadi as ca
import numpy as np

#: Floor [m^2] for the squared length of a segment (avoids 0/0 for a zero-length capsule).
TINY_SQ = 1e-30
#: CasADi types that switch the computation to the symbolic backend.
CASADI_TYPES = (ca.SX, ca.MX, ca.DM)
#: Tolerance on ``|R^T R - I|`` for numeric rotation matrices.
ROTATION_TOL = 1e-4


class _NumpyOps:
    """numpy backend: inputs and outputs are floats / ``ndarray``."""

    symbolic = False
    sqrt = staticmethod(np.sqrt)
    exp = staticmethod(np.exp)
    log = staticmethod(np.log)
    fmax = staticmethod(np.maximum)
    fmin = staticmethod(np.minimum)

    @staticmethod
    def dot(a: Any, b: Any) -> Any:
        return np.dot(a, b)

    @staticmethod
    def mv(R: Any, v: Any) -> Any:
        return R @ v

    @staticmethod
    def mtv(R: Any, v: Any) -> Any:
        return R.T @ v

    @staticmethod
    def stack(items: Sequence[Any]) -> np.ndarray:
        return np.array([float(x) for x in items])

    @staticmethod
    def scalar(x: Any) -> Any:
        return float(x)


class _CasadiOps:
    """CasADi backend: inputs are SX/MX/DM, 3-vectors are 3x1 columns."""

    symbolic = True
    sqrt = staticmethod(ca.sqrt)
    exp = staticmethod(ca.exp)
    log = staticmethod(ca.log)
    fmax = staticmethod(ca.fmax)
    fmin = staticmethod(ca.fmin)

    @staticmethod
    def dot(a: Any, b: Any) -> Any:
        return ca.dot(a, b)

    @staticmethod
    def mv(R: Any, v: Any) -> Any:
        return ca.mtimes(R, v)

    @staticmethod
    def mtv(R: Any, v: Any) -> Any:
        return ca.mtimes(R.T, v)

    @staticmethod
    def stack(items: Sequence[Any]) -> Any:
        return ca.vertcat(*items)

    @staticmethod
    def scalar(x: Any) -> Any:
        return x


NUMPY = _NumpyOps()
CASADI = _CasadiOps()
Ops = Any  # either NUMPY or CASADI


def select_ops(*values: Any) -> Ops:
    """CASADI if any value is a CasADi object (SX/MX/DM), else NUMPY."""
    return CASADI if any(isinstance(v, CASADI_TYPES) for v in values) else NUMPY


# --------------------------------------------------------------------------------------------
# input validation (ValueError naming the offending argument)
# --------------------------------------------------------------------------------------------
def _numeric_array(x: Any, name: str, what: str) -> np.ndarray:
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be {what}, got {x!r}") from exc


def vec3(x: Any, name: str, ops: Ops) -> Any:
    """Validate a 3-vector [m] and convert it to the backend's representation."""
    if isinstance(x, CASADI_TYPES):
        if x.shape == (1, 3):
            x = x.T
        if x.shape != (3, 1):
            raise ValueError(f"{name} must be a 3-vector, got a CasADi object of shape {x.shape}")
        if isinstance(x, ca.DM) and not np.all(np.isfinite(np.asarray(x))):
            raise ValueError(f"{name} must be finite, got {np.asarray(x).ravel().tolist()}")
        return x
    arr = _numeric_array(x, name, "a numeric 3-vector")
    if arr.shape not in ((3,), (3, 1), (1, 3)):
        raise ValueError(f"{name} must be a 3-vector of shape (3,), got shape {arr.shape}")
    arr = arr.reshape(3)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    return ca.DM(arr) if ops.symbolic else arr


def mat3(R: Any, name: str, ops: Ops) -> Any:
    """Validate a 3x3 rotation matrix (orthonormality checked for numeric input)."""
    if isinstance(R, (ca.SX, ca.MX)):
        if R.shape != (3, 3):
            raise ValueError(f"{name} must be a 3x3 rotation matrix, got shape {R.shape}")
        return R
    arr = _numeric_array(R, name, "a numeric 3x3 rotation matrix")
    if arr.shape != (3, 3):
        raise ValueError(f"{name} must be a 3x3 rotation matrix, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    err = float(np.max(np.abs(arr.T @ arr - np.eye(3))))
    if err > ROTATION_TOL:
        raise ValueError(f"{name} must be a rotation matrix (|R^T R - I| = {err:.3g} > {ROTATION_TOL})")
    return ca.DM(arr) if ops.symbolic else arr


def radius(r: Any, name: str) -> Any:
    """Validate a radius [m]: finite and >= 0 (a 1x1 CasADi expression is passed through)."""
    if isinstance(r, CASADI_TYPES):
        if r.shape != (1, 1):
            raise ValueError(f"{name} must be a scalar radius [m], got shape {r.shape}")
        return r
    if isinstance(r, bool):
        raise ValueError(f"{name} must be a radius [m], got {r!r}")
    try:
        val = float(r)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a finite non-negative radius [m], got {r!r}") from exc
    if not math.isfinite(val) or val < 0.0:
        raise ValueError(f"{name} must be a finite non-negative radius [m], got {r!r}")
    return val


def numeric_radius(r: Any, name: str) -> float:
    """Like :func:`radius` but a number is required (used to size sphere coverings)."""
    if isinstance(r, CASADI_TYPES):
        if not isinstance(r, ca.DM):
            raise ValueError(f"{name} must be a number for a sphere covering, got a symbolic {type(r).__name__}")
        r = float(r)
    return float(radius(r, name))


def half_extents(h: Any, name: str) -> np.ndarray:
    """Validate box half extents [m]: three finite numbers >= 0."""
    if isinstance(h, (ca.SX, ca.MX)):
        raise ValueError(f"{name} must be three numbers (constant half extents), got a symbolic value")
    arr = _numeric_array(h, name, "three non-negative half extents [m]")
    if arr.shape not in ((3,), (3, 1), (1, 3)):
        raise ValueError(f"{name} must be three half extents [m] of shape (3,), got shape {arr.shape}")
    arr = arr.reshape(3)
    if not np.all(np.isfinite(arr)) or np.any(arr < 0.0):
        raise ValueError(f"{name} must be finite and non-negative half extents [m], got {arr.tolist()}")
    return arr


def positive(x: Any, name: str) -> float:
    """Validate a strictly positive finite float option (e.g. ``eps`` [m])."""
    try:
        val = float(x)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a positive number, got {x!r}") from exc
    if not math.isfinite(val) or val <= 0.0:
        raise ValueError(f"{name} must be a positive finite number, got {x!r}")
    return val


def sphere_count(n: Any, name: str = "n_spheres") -> int:
    """Validate a number of covering spheres (integer >= 1)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or int(n) < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {n!r}")
    return int(n)


# --------------------------------------------------------------------------------------------
# smooth scalar primitives
# --------------------------------------------------------------------------------------------
#: max over D of (D - smooth_norm(D^2)) / eps (attained at D = 0.3018 eps)
SMOOTH_NORM_ERROR = 0.1411058


def smooth_norm(sq: Any, eps: float, ops: Ops) -> Any:
    """C2 lower bound [m] of ``sqrt(sq)`` for a squared length ``sq >= 0`` [m^2], exact for sq >= eps^2.

    ``sqrt(sq)`` for ``sq >= eps^2``; below, with ``y = sq / eps^2``, the polynomial
    ``eps (15 y - 10 y^2 + 3 y^3) / 8``, which matches value, first and second derivative at
    ``y = 1`` and stays below ``sqrt``: with ``s = sqrt(y)``, ``sqrt - poly`` is
    ``eps s (8 - 15 s + 10 s^3 - 3 s^5)/8 >= 0`` because ``g(s) = 3 s^5 - 10 s^3 + 15 s - 8`` has
    ``g' = 15 (s^2 - 1)^2 >= 0`` and ``g(1) = 0``. Hence ``sqrt(sq) - SMOOTH_NORM_ERROR eps <= value
    <= sqrt(sq)``; the value is C2 in ``sq`` (C-infinity apart from ``sq = eps^2``), its derivative
    at ``sq = 0`` is finite (``15 / (8 eps)``), and sqrt is never evaluated near 0.
    """
    e2 = eps * eps
    y = sq / e2
    poly = (eps / 8.0) * (y * (15.0 + y * (-10.0 + 3.0 * y)))
    root = ops.sqrt(ops.fmax(sq, e2))
    if ops.symbolic:
        return ca.if_else(sq >= e2, root, poly)
    return np.where(sq >= e2, root, poly)[()]


def smooth_min0(y: Any, eps: float, ops: Ops) -> Any:
    """Smooth lower bound of ``min(y, 0)``: ``(y - sqrt(y^2 + eps^2)) / 2``, error <= eps/2."""
    return 0.5 * (y - ops.sqrt(y * y + eps * eps))


def softmin(values: Sequence[Any], tau: float, ops: Ops) -> Any:
    """Log-sum-exp soft minimum: ``min(v) - tau*log(k) <= softmin <= min(v)``.

    Computed with the exact min as shift (its kinks cancel analytically in value and derivatives),
    so it is overflow-free for any ``tau`` > 0.
    """
    if len(values) == 1:
        return values[0]
    m = values[0]
    for v in values[1:]:
        m = ops.fmin(m, v)
    total = 0
    for v in values:
        total = total + ops.exp(-(v - m) / tau)
    return m - tau * ops.log(total)


def softmax_lower(values: Sequence[Any], tau: float, ops: Ops) -> Any:
    """Smooth lower bound of ``max(v)``: ``LSE_tau(v) - tau*log(k)``, error <= tau*log(k)."""
    m = values[0]
    for v in values[1:]:
        m = ops.fmax(m, v)
    total = 0
    for v in values:
        total = total + ops.exp((v - m) / tau)
    return m + tau * ops.log(total) - tau * math.log(len(values))


def clip(x: Any, lo: Any, hi: Any, ops: Ops) -> Any:
    """Hard clamp (used only where the envelope theorem makes the result C1, see callers)."""
    return ops.fmin(ops.fmax(x, lo), hi)


# --------------------------------------------------------------------------------------------
# exact, C1 squared distances
# --------------------------------------------------------------------------------------------
def point_segment_sq(p: Any, a: Any, b: Any, ops: Ops) -> Any:
    """Exact squared distance [m^2] from point ``p`` to segment ``[a, b]``.

    ``D^2 = min_{t in [0,1]} |p - a - t (b - a)|^2`` evaluated at the clamped minimiser. The clamp
    is not smooth, but ``D^2`` is C1 in (p, a, b) by the envelope (Danskin) theorem: the derivative
    w.r.t. ``t`` vanishes at an interior minimiser and ``dt/dx = 0`` where the clamp is active, so
    automatic differentiation returns the continuous gradient ``2 (p - q) . d(p - q)``. The Hessian
    jumps where the clamp switches (C1, piecewise C-infinity).
    """
    e = b - a
    w = p - a
    t = clip(ops.dot(w, e) / ops.fmax(ops.dot(e, e), TINY_SQ), 0.0, 1.0, ops)
    diff = w - t * e
    return ops.dot(diff, diff)


def point_box_sq(q: Any, h: Any, ops: Ops) -> Any:
    """Exact squared distance [m^2] from a point ``q`` (box frame) to the box ``|q_i| <= h_i``.

    ``sum_i (q_i - clip(q_i, -h_i, h_i))^2`` = sum of squared positive parts: C1 (each term is a
    squared hinge), zero inside the box.
    """
    excess = q - clip(q, -h, h, ops)
    return ops.dot(excess, excess)


def box_inside_term(q: Any, h: Sequence[float] | np.ndarray, eps: float, ops: Ops) -> Any:
    """Smooth lower bound [m] of ``min(max_i(|q_i| - h_i), 0)`` (the inside part of the box SDF).

    ``max_i(|q_i| - h_i)`` is the max of the six affine functions ``+-q_i - h_i``; it is replaced by
    a log-sum-exp lower bound with temperature ``eps / (2 log 6)`` (error <= eps/2), then
    ``min(., 0)`` by :func:`smooth_min0` (error <= eps/2). Outside the box the term is in
    ``[-eps, 0]`` (and -> 0 away from the surface); inside it is <= minus the depth of ``q``.
    """
    faces = []
    for i in range(3):
        faces.append(q[i] - float(h[i]))
        faces.append(-q[i] - float(h[i]))
    m_lb = softmax_lower(faces, eps / (2.0 * math.log(6.0)), ops)
    return smooth_min0(m_lb, eps, ops)


# --------------------------------------------------------------------------------------------
# sphere coverings of a capsule
# --------------------------------------------------------------------------------------------
def n_covering_spheres(length: float, r: float, tol: float) -> int:
    """Smallest number k of equal spheres on the segment whose enlarged radius exceeds r by <= tol.

    Centres ``a + j/(k-1) (b - a)``, radius ``rho = sqrt(r^2 + (L / (2 (k-1)))^2)``; the union
    contains the capsule (consecutive spheres intersect exactly on the circle of radius r at the
    mid-point) and lies within ``rho - r`` [m] of it. ``rho - r <= tol`` iff the half spacing is
    ``<= sqrt(2 r tol + tol^2)``. A zero-length capsule is a sphere (k = 1).
    """
    if length <= 0.0:
        return 1
    half_gap = math.sqrt(2.0 * r * tol + tol * tol)
    return max(2, math.ceil(length / (2.0 * half_gap) * (1.0 - 1e-12)) + 1)


def covering_radius(r: float, length: float, k: int) -> float:
    """Radius [m] of each of the k covering spheres of a capsule (radius r, segment length L)."""
    if k == 1:
        return r + 0.5 * length
    return math.sqrt(r * r + (length / (2.0 * (k - 1))) ** 2)


def covering_spheres(a: Any, b: Any, r: Any, k: int, ops: Ops) -> tuple[list[Any], Any]:
    """Centres and common radius [m] of the k-sphere covering of capsule ``(a, b, r)``.

    The radius is computed from the (possibly symbolic) segment length; ``TINY_SQ`` under the
    square root keeps it differentiable for a zero-length, zero-radius capsule and only enlarges it
    (stays conservative).
    """
    e = b - a
    l_sq = ops.dot(e, e)
    if k == 1:
        return [0.5 * (a + b)], r + ops.sqrt(0.25 * l_sq + TINY_SQ)
    rho = ops.sqrt(r * r + l_sq / (4.0 * (k - 1) ** 2) + TINY_SQ)
    centres = [a + (j / (k - 1)) * e for j in range(k)]
    return centres, rho
