"""Smooth, conservative signed distances between spheres, capsules and boxes.

Made for collision-avoidance constraints ``d(x) >= margin`` in IPOPT trajectory NLPs. Every
function works on numpy floats (returns a ``float``) and on CasADi ``SX``/``MX``/``DM``
expressions (returns an expression) with the same formula. All lengths are in metres [m].

Guarantees (``d_exact`` = exact signed distance as computed by coal, ``d`` = value returned here)
--------------------------------------------------------------------------------------------
* **Conservative**: ``d <= d_exact`` for every separated configuration (``d_exact >= 0``).
* **Accurate**: ``d_exact - d <= error_bound(shape1, shape2)`` for separated configurations:

  ==================  ==============================================  ==================
  pair                bound                                           defaults
  ==================  ==============================================  ==================
  sphere-sphere       ``0.1411 eps`` (0 if ``r1 + r2 >= eps``)        0.14 mm
  capsule-sphere      ``0.1411 eps`` (0 if ``r + rs >= eps``)         0.14 mm
  sphere-box          ``eps``                                         1 mm
  capsule-capsule     ``(rho - r) + 0.1411 eps + softmin_tol``        <= 4.2 mm
  capsule-box         ``(rho - r) + eps + softmin_tol``               <= 5 mm
  ==================  ==============================================  ==================

  with ``rho - r <= cover_tol`` when the number of covering spheres is chosen automatically.
* **Penetration** (``d_exact < 0``): ``d < 0`` always (sign-consistent), so ``d >= 0`` certifies
  ``d_exact >= 0``; and ``d`` decreases with deeper penetration (useful gradient inside). For the
  sphere-sphere, capsule-sphere and sphere-box pairs ``d`` is moreover a lower bound of coal's
  (negative) penetration depth; for the covered pairs its magnitude is only indicative. An NLP
  constraint only needs the sign and the monotonic behaviour.
* **Smooth**: C1 everywhere (piecewise C-infinity; the Hessian may jump where a closest point
  moves from a face/endpoint to another, never where the value or gradient could jump); no
  ``sqrt(0)`` is ever evaluated; degenerate inputs (coincident centres, zero-length capsule, point
  on a box surface) give finite values and gradients.

Construction (and why)
----------------------
* **Point-segment and point-box squared distances are computed exactly** (hard clamp of the
  segment parameter / of the box coordinates). The squared distance to a convex set is C1 by the
  envelope (Danskin) theorem, and automatic differentiation of the clamped formula returns that
  continuous gradient. A *smooth* clamp is not used on purpose: an approximate parameter picks a
  non-closest point *on* the segment, which over-estimates the distance (non-conservative).
* ``sqrt(D^2)`` is kept exactly for ``D >= eps`` and continued below by the C2 polynomial
  ``eps (15 y - 10 y^2 + 3 y^3) / 8`` in ``y = D^2 / eps^2`` (proved ``<= D``, error
  ``<= 0.1411 eps``). Unlike ``sqrt(D^2 + eps^2) - eps`` (which is off by ~eps everywhere) this is
  exact for separated spheres/capsules whose radii sum to >= eps, and equally smooth at ``D = 0``.
* Sphere-box adds a smooth lower bound of the box's inside signed distance (log-sum-exp over the six
  face planes, temperature ``eps / (2 log 6)``), so the value keeps decreasing inside the box; it
  costs at most ``0.81 eps`` just outside the surface and vanishes like ``eps^2 / (4 gap)``.
* **Capsule-capsule and capsule-box** use a **sphere covering** of one capsule: k spheres centred
  at ``a + j/(k-1) (b - a)`` with radius ``rho = sqrt(r^2 + (L / (2 (k-1)))^2)``. Their union
  contains the capsule (conservative) and lies within ``rho - r`` of it (accuracy). Each sphere is
  then handled by the exact capsule-sphere / sphere-box formulas and the k values are combined
  by a log-sum-exp soft minimum with temperature ``softmin_tol / log k`` (error <= softmin_tol).
  The exact segment-segment distance is *not* C1 (parallel segments), so some approximation is
  unavoidable; the covering gives a provable one-sided error. With ``reduce=False`` the k
  per-sphere distances are returned instead (imposing all ``>= margin`` avoids the soft-min
  error). For capsule-capsule the capsule needing fewer spheres is covered.

Options (keyword-only, everywhere): ``eps`` [m] (default 1e-3), ``n_spheres`` (default: smallest
k with ``rho - r <= cover_tol``, i.e. ``k = ceil(L / (2 sqrt(2 r tol + tol^2))) + 1``; e.g. 12 for
r = 5 cm, L = 30 cm), ``cover_tol`` [m] (default 2e-3), ``softmin_tol`` [m] (default 2e-3).

Measured against coal (5000 random separated placements per pair, half within 3 cm of contact):
``d - d_exact <= 4.4e-16`` m; worst ``d_exact - d``: 0 (sphere-sphere, capsule-sphere),
0.06 mm (sphere-box), 3.3 mm (capsule-capsule), 3.7 mm (capsule-box), always below the bound.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from optplan.geometry._distance_smooth import n_covering_spheres

from . import _distance_smooth as _s

__all__ = [
    "DEFAULT_EPS", "DEFAULT_COVER_TOL", "DEFAULT_SOFTMIN_TOL", "Sphere", "Capsule", "Box", "Shape",
    "sphere_sphere", "point_segment_distance", "point_segment_distance_sq", "capsule_sphere",
    "capsule_capsule", "sphere_box", "capsule_box", "signed_distance", "error_bound",
    "make_distance_function", "n_covering_spheres",
]

DEFAULT_EPS = 1e-3  #: [m] below this distance the norm is replaced by a C2 polynomial lower bound
DEFAULT_COVER_TOL = 2e-3  #: [m] max enlargement rho - r of a capsule's covering spheres
DEFAULT_SOFTMIN_TOL = 2e-3  #: [m] max error of the log-sum-exp soft minimum

Expr = Any  # float | numpy.ndarray | casadi.SX | casadi.MX | casadi.DM
Pose = tuple  # (R (3x3 rotation), p (3,) position [m])


def _tuple3(x: Any, name: str) -> tuple[float, float, float]:
    arr = _s.vec3(x, name, _s.NUMPY)
    return (float(arr[0]), float(arr[1]), float(arr[2]))


@dataclass(frozen=True)
class Sphere:
    """Sphere of ``radius`` [m] centred at ``center`` [m] in its body frame."""

    radius: float
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "radius", _s.numeric_radius(self.radius, "Sphere.radius"))
        object.__setattr__(self, "center", _tuple3(self.center, "Sphere.center"))


@dataclass(frozen=True)
class Capsule:
    """Capsule: points within ``radius`` [m] of the segment ``[a, b]`` (body frame, [m])."""

    radius: float
    a: tuple[float, float, float]
    b: tuple[float, float, float]

    def __post_init__(self) -> None:
        object.__setattr__(self, "radius", _s.numeric_radius(self.radius, "Capsule.radius"))
        object.__setattr__(self, "a", _tuple3(self.a, "Capsule.a"))
        object.__setattr__(self, "b", _tuple3(self.b, "Capsule.b"))

    @classmethod
    def along_z(cls, radius: float, length: float) -> Capsule:
        """Capsule along the local z axis centred at the origin, like ``coal.Capsule(radius, length)``."""
        length = float(length)
        if not math.isfinite(length) or length < 0.0:
            raise ValueError(f"length must be a finite non-negative length [m], got {length!r}")
        return cls(radius, (0.0, 0.0, -0.5 * length), (0.0, 0.0, 0.5 * length))

    @property
    def length(self) -> float:
        """Segment length ``|b - a|`` [m] (total length minus 2 radius)."""
        return float(np.linalg.norm(np.subtract(self.b, self.a)))


@dataclass(frozen=True)
class Box:
    """Box ``|x_i| <= half_extents_i`` [m] in its body frame (``coal.Box(2 * half_extents)``)."""

    half_extents: tuple[float, float, float]

    def __post_init__(self) -> None:
        h = _s.half_extents(self.half_extents, "Box.half_extents")
        object.__setattr__(self, "half_extents", (float(h[0]), float(h[1]), float(h[2])))


Shape = Sphere | Capsule | Box


def _options(eps: float, cover_tol: float, softmin_tol: float) -> tuple[float, float, float]:
    return (_s.positive(eps, "eps"), _s.positive(cover_tol, "cover_tol"),
            _s.positive(softmin_tol, "softmin_tol"))


def _softmin_tau(k: int, softmin_tol: float) -> float:
    return softmin_tol / math.log(k) if k > 1 else 1.0


def _numeric_length(a: Any, b: Any, name: str) -> float:
    if isinstance(a, (ca.SX, ca.MX)) or isinstance(b, (ca.SX, ca.MX)):
        raise ValueError(f"n_spheres must be given when the endpoints of {name} are symbolic "
                         "(use signed_distance()/make_distance_function(), or n_covering_spheres())")
    return float(np.linalg.norm(np.asarray(b, float).ravel() - np.asarray(a, float).ravel()))


def _plan_cover(length1: float, r1: float, length2: float, r2: float, n_spheres: int | None,
                cover_tol: float) -> tuple[bool, int]:
    """(swap, k): cover capsule 2 instead of 1 if ``swap``; auto: fewest spheres, else least error."""
    k1 = n_spheres or n_covering_spheres(length1, r1, cover_tol)
    k2 = n_spheres or n_covering_spheres(length2, r2, cover_tol)
    if n_spheres is None:
        return (k2 < k1, min(k1, k2))
    err1 = _s.covering_radius(r1, length1, k1) - r1
    err2 = _s.covering_radius(r2, length2, k2) - r2
    return (err2 < err1, n_spheres)


# --------------------------------------------------------------------------------------------
# pair functions on world-frame placements
# --------------------------------------------------------------------------------------------
def sphere_sphere(c1: Expr, r1: Expr, c2: Expr, r2: Expr, *, eps: float = DEFAULT_EPS) -> Expr:
    """Smooth distance [m] between spheres ``(c1, r1)`` and ``(c2, r2)``.

    ``|c1 - c2| - r1 - r2`` with the C2 lower bound of the norm: error in ``[0, 0.1411 eps]`` and
    exactly 0 when ``|c1 - c2| >= eps``; a lower bound of the signed distance everywhere.
    """
    ops = _s.select_ops(c1, r1, c2, r2)
    eps = _s.positive(eps, "eps")
    c1, c2 = _s.vec3(c1, "c1", ops), _s.vec3(c2, "c2", ops)
    r1, r2 = _s.radius(r1, "r1"), _s.radius(r2, "r2")
    diff = c1 - c2
    return ops.scalar(_s.smooth_norm(ops.dot(diff, diff), eps, ops) - r1 - r2)


def point_segment_distance_sq(p: Expr, a: Expr, b: Expr) -> Expr:
    """Exact squared distance [m^2] from point ``p`` to segment ``[a, b]`` (C1 in p, a, b)."""
    ops = _s.select_ops(p, a, b)
    p, a, b = _s.vec3(p, "p", ops), _s.vec3(a, "a", ops), _s.vec3(b, "b", ops)
    return ops.scalar(_s.point_segment_sq(p, a, b, ops))


def point_segment_distance(p: Expr, a: Expr, b: Expr, *, eps: float = DEFAULT_EPS) -> Expr:
    """Smooth distance [m] from ``p`` to segment ``[a, b]``, in ``[D - 0.1411 eps, D]``, = D if D >= eps."""
    ops = _s.select_ops(p, a, b)
    eps = _s.positive(eps, "eps")
    p, a, b = _s.vec3(p, "p", ops), _s.vec3(a, "a", ops), _s.vec3(b, "b", ops)
    return ops.scalar(_s.smooth_norm(_s.point_segment_sq(p, a, b, ops), eps, ops))


def capsule_sphere(a: Expr, b: Expr, r: Expr, c: Expr, rs: Expr, *, eps: float = DEFAULT_EPS) -> Expr:
    """Smooth distance [m] between capsule ``(a, b, r)`` and sphere ``(c, rs)``.

    Error in ``[0, 0.1411 eps]`` (0 when the centre is >= eps from the segment); also a lower bound
    of the signed distance when they penetrate.
    """
    ops = _s.select_ops(a, b, r, c, rs)
    eps = _s.positive(eps, "eps")
    a, b, c = _s.vec3(a, "a", ops), _s.vec3(b, "b", ops), _s.vec3(c, "c", ops)
    r, rs = _s.radius(r, "r"), _s.radius(rs, "rs")
    return ops.scalar(_s.smooth_norm(_s.point_segment_sq(c, a, b, ops), eps, ops) - r - rs)


def capsule_capsule(a1: Expr, b1: Expr, r1: Expr, a2: Expr, b2: Expr, r2: Expr, *,
                    eps: float = DEFAULT_EPS, n_spheres: int | None = None,
                    cover_tol: float = DEFAULT_COVER_TOL, softmin_tol: float = DEFAULT_SOFTMIN_TOL,
                    reduce: bool = True) -> Expr:
    """Smooth conservative distance [m] between capsules ``(a1, b1, r1)`` and ``(a2, b2, r2)``.

    One capsule is covered by ``k`` spheres (see module docstring), each compared exactly with the
    other capsule; ``d_exact - d <= (rho - r) + 0.1411 eps + softmin_tol`` when separated. With
    ``n_spheres=None`` (numeric input only) ``k`` is chosen so that ``rho - r <= cover_tol`` and
    the capsule needing fewer spheres is covered; with an explicit ``n_spheres`` capsule 1 is
    covered. ``reduce=False`` returns the ``k`` per-sphere distances (vector) instead.
    """
    ops = _s.select_ops(a1, b1, r1, a2, b2, r2)
    eps, cover_tol, softmin_tol = _options(eps, cover_tol, softmin_tol)
    a1, b1, a2, b2 = (_s.vec3(v, n, ops) for v, n in ((a1, "a1"), (b1, "b1"), (a2, "a2"), (b2, "b2")))
    r1, r2 = _s.radius(r1, "r1"), _s.radius(r2, "r2")
    if n_spheres is None:
        swap, k = _plan_cover(_numeric_length(a1, b1, "capsule 1"), _s.numeric_radius(r1, "r1"),
                              _numeric_length(a2, b2, "capsule 2"), _s.numeric_radius(r2, "r2"),
                              None, cover_tol)
        if swap:
            a1, b1, r1, a2, b2, r2 = a2, b2, r2, a1, b1, r1
    else:
        k = _s.sphere_count(n_spheres)
    centres, rho = _s.covering_spheres(a1, b1, r1, k, ops)
    vals = [_s.smooth_norm(_s.point_segment_sq(c, a2, b2, ops), eps, ops) - rho - r2 for c in centres]
    if not reduce:
        return ops.stack(vals)
    return ops.scalar(_s.softmin(vals, _softmin_tau(k, softmin_tol), ops))


def _sphere_box_local(q: Expr, rs: Expr, h: np.ndarray, eps: float, ops: Any) -> Expr:
    """Sphere (centre ``q`` in box frame, radius ``rs``) vs box of half extents ``h`` (numpy)."""
    h_b = ca.DM(h) if ops.symbolic else h
    outer = _s.smooth_norm(_s.point_box_sq(q, h_b, ops), eps, ops)
    return outer + _s.box_inside_term(q, h, eps, ops) - rs


def sphere_box(c: Expr, r: Expr, R: Expr, p: Expr, h: Any, *, eps: float = DEFAULT_EPS) -> Expr:
    """Smooth distance [m] between sphere ``(c, r)`` and box (rotation ``R``, centre ``p``, half extents ``h``).

    Exact C1 point-box distance, eps-smoothed, plus a smooth inside term; error in ``[0, eps]``
    when separated and a lower bound of the signed distance when penetrating.
    """
    ops = _s.select_ops(c, r, R, p)
    eps = _s.positive(eps, "eps")
    c, p, R = _s.vec3(c, "c", ops), _s.vec3(p, "p", ops), _s.mat3(R, "R", ops)
    r = _s.radius(r, "r")
    h_arr = _s.half_extents(h, "h")
    return ops.scalar(_sphere_box_local(ops.mtv(R, c - p), r, h_arr, eps, ops))


def capsule_box(a: Expr, b: Expr, r: Expr, R: Expr, p: Expr, h: Any, *, eps: float = DEFAULT_EPS,
                n_spheres: int | None = None, cover_tol: float = DEFAULT_COVER_TOL,
                softmin_tol: float = DEFAULT_SOFTMIN_TOL, reduce: bool = True) -> Expr:
    """Smooth conservative distance [m] between capsule ``(a, b, r)`` and box ``(R, p, h)``.

    Sphere covering of the capsule + :func:`sphere_box` per sphere + soft minimum;
    ``d_exact - d <= (rho - r) + eps + softmin_tol`` when separated. ``n_spheres=None`` needs
    numeric endpoints and radius (``rho - r <= cover_tol``). ``reduce=False`` returns the vector of
    per-sphere distances.
    """
    ops = _s.select_ops(a, b, r, R, p)
    eps, cover_tol, softmin_tol = _options(eps, cover_tol, softmin_tol)
    a, b, p = _s.vec3(a, "a", ops), _s.vec3(b, "b", ops), _s.vec3(p, "p", ops)
    R, r = _s.mat3(R, "R", ops), _s.radius(r, "r")
    h_arr = _s.half_extents(h, "h")
    if n_spheres is None:
        k = n_covering_spheres(_numeric_length(a, b, "the capsule"), _s.numeric_radius(r, "r"), cover_tol)
    else:
        k = _s.sphere_count(n_spheres)
    centres, rho = _s.covering_spheres(ops.mtv(R, a - p), ops.mtv(R, b - p), r, k, ops)
    vals = [_sphere_box_local(q, rho, h_arr, eps, ops) for q in centres]
    if not reduce:
        return ops.stack(vals)
    return ops.scalar(_s.softmin(vals, _softmin_tau(k, softmin_tol), ops))


# --------------------------------------------------------------------------------------------
# dispatcher, error bounds, CasADi functions
# --------------------------------------------------------------------------------------------
def _check_shape(shape: Any, name: str) -> None:
    if not isinstance(shape, (Sphere, Capsule, Box)):
        raise ValueError(f"{name} must be a Sphere, Capsule or Box, got {shape!r}")


def _pose(pose: Any, name: str, ops: Any) -> tuple[Expr, Expr]:
    if not isinstance(pose, (tuple, list)) or len(pose) != 2:
        raise ValueError(f"{name} must be a pair (R, p) of a 3x3 rotation and a 3-vector [m], got {pose!r}")
    return _s.mat3(pose[0], f"{name}[0] (R)", ops), _s.vec3(pose[1], f"{name}[1] (p)", ops)


def _world(R: Expr, p: Expr, local: tuple[float, float, float], ops: Any) -> Expr:
    if not any(local):
        return p
    loc = ca.DM(local) if ops.symbolic else np.asarray(local, float)
    return p + ops.mv(R, loc)


_ORDER = {Sphere: 0, Capsule: 1, Box: 2}


def signed_distance(shape1: Shape, pose1: Pose, shape2: Shape, pose2: Pose, *, eps: float = DEFAULT_EPS,
                    n_spheres: int | None = None, cover_tol: float = DEFAULT_COVER_TOL,
                    softmin_tol: float = DEFAULT_SOFTMIN_TOL) -> Expr:
    """Smooth conservative signed distance [m] between two shapes placed at ``pose = (R, p)``.

    ``R`` is the body-to-world rotation (3x3), ``p`` the body origin [m] in world; both may be
    CasADi expressions. ``error_bound(shape1, shape2, ...)`` bounds ``d_exact - d`` when separated.
    Box-box is not supported (TypeError: cover one box by capsules or spheres).
    """
    _check_shape(shape1, "shape1")
    _check_shape(shape2, "shape2")
    ops = _s.select_ops(*pose1, *pose2) if all(isinstance(x, (tuple, list)) for x in (pose1, pose2)) else _s.NUMPY
    if n_spheres is not None:
        n_spheres = _s.sphere_count(n_spheres)
    R1, p1 = _pose(pose1, "pose1", ops)
    R2, p2 = _pose(pose2, "pose2", ops)
    if _ORDER[type(shape1)] > _ORDER[type(shape2)]:
        shape1, R1, p1, shape2, R2, p2 = shape2, R2, p2, shape1, R1, p1
    if isinstance(shape2, Box):
        if isinstance(shape1, Box):
            raise TypeError("box-box distance is not supported: cover one box by spheres/capsules")
        if isinstance(shape1, Sphere):
            return sphere_box(_world(R1, p1, shape1.center, ops), shape1.radius, R2, p2, shape2.half_extents, eps=eps)
        k = n_spheres or n_covering_spheres(shape1.length, shape1.radius, cover_tol)
        return capsule_box(_world(R1, p1, shape1.a, ops), _world(R1, p1, shape1.b, ops), shape1.radius,
                           R2, p2, shape2.half_extents, n_spheres=k, eps=eps, cover_tol=cover_tol,
                           softmin_tol=softmin_tol)
    if isinstance(shape2, Capsule):
        a2, b2 = _world(R2, p2, shape2.a, ops), _world(R2, p2, shape2.b, ops)
        if isinstance(shape1, Sphere):
            return capsule_sphere(a2, b2, shape2.radius, _world(R1, p1, shape1.center, ops), shape1.radius, eps=eps)
        assert isinstance(shape1, Capsule)   # ordered: shape1 precedes shape2 in _ORDER
        a1, b1 = _world(R1, p1, shape1.a, ops), _world(R1, p1, shape1.b, ops)
        swap, k = _plan_cover(shape1.length, shape1.radius, shape2.length, shape2.radius, n_spheres, cover_tol)
        caps = [(a1, b1, shape1.radius), (a2, b2, shape2.radius)]
        if swap:
            caps.reverse()
        return capsule_capsule(*caps[0], *caps[1], n_spheres=k, eps=eps, cover_tol=cover_tol,
                               softmin_tol=softmin_tol)
    assert isinstance(shape1, Sphere) and isinstance(shape2, Sphere)   # ordered: neither is a box or capsule
    return sphere_sphere(_world(R1, p1, shape1.center, ops), shape1.radius,
                         _world(R2, p2, shape2.center, ops), shape2.radius, eps=eps)


def error_bound(shape1: Shape, shape2: Shape, *, eps: float = DEFAULT_EPS, n_spheres: int | None = None,
                cover_tol: float = DEFAULT_COVER_TOL, softmin_tol: float = DEFAULT_SOFTMIN_TOL) -> float:
    """Upper bound [m] on ``d_exact - signed_distance(...)`` for separated shapes (same options)."""
    _check_shape(shape1, "shape1")
    _check_shape(shape2, "shape2")
    eps, cover_tol, softmin_tol = _options(eps, cover_tol, softmin_tol)
    if n_spheres is not None:
        n_spheres = _s.sphere_count(n_spheres)
    kinds = sorted((shape1, shape2), key=lambda s: _ORDER[type(s)])
    s1, s2 = kinds
    if isinstance(s2, Box):
        if isinstance(s1, Box):
            raise TypeError("box-box distance is not supported: cover one box by spheres/capsules")
        if isinstance(s1, Sphere):
            return eps
        k = n_spheres or n_covering_spheres(s1.length, s1.radius, cover_tol)
        cov = _s.covering_radius(s1.radius, s1.length, k) - s1.radius
        return cov + eps + (softmin_tol if k > 1 else 0.0)
    norm_err = _s.SMOOTH_NORM_ERROR * eps
    if isinstance(s2, Capsule) and isinstance(s1, Capsule):
        swap, k = _plan_cover(s1.length, s1.radius, s2.length, s2.radius, n_spheres, cover_tol)
        c = s2 if swap else s1
        cov = _s.covering_radius(c.radius, c.length, k) - c.radius
        return cov + norm_err + (softmin_tol if k > 1 else 0.0)
    assert not isinstance(s1, Box) and not isinstance(s2, Box)   # ordered: a box is always s2
    return 0.0 if s1.radius + s2.radius >= eps else norm_err


def make_distance_function(shape1: Shape, shape2: Shape, *, name: str | None = None, eps: float = DEFAULT_EPS,
                           n_spheres: int | None = None, cover_tol: float = DEFAULT_COVER_TOL,
                           softmin_tol: float = DEFAULT_SOFTMIN_TOL) -> ca.Function:
    """``casadi.Function(R1 (3x3), p1 (3x1), R2 (3x3), p2 (3x1)) -> d`` [m] built on SX.

    Same value and options as :func:`signed_distance`; differentiable by CasADi (jacobian/hessian).
    """
    R1, p1 = ca.SX.sym("R1", 3, 3), ca.SX.sym("p1", 3)
    R2, p2 = ca.SX.sym("R2", 3, 3), ca.SX.sym("p2", 3)
    d = signed_distance(shape1, (R1, p1), shape2, (R2, p2), eps=eps, n_spheres=n_spheres,
                        cover_tol=cover_tol, softmin_tol=softmin_tol)
    fname = name or f"d_{type(shape1).__name__.lower()}_{type(shape2).__name__.lower()}"
    return ca.Function(fname, [R1, p1, R2, p2], [d], ["R1", "p1", "R2", "p2"], ["d"])
