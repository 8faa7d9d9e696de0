"""Space-arc equivalent kinematics (the DSHDASR paper, Section 3 and 4.3-4.4) in CasADi.

Each arm is described by a chain of tangent circular arcs instead of its joints:

* **Arm-a**, a 7-DOF non-offset (S-R-S) arm with L1 = L7, L3 = L5: three arcs inscribed in the link
  polyline (Fig. 4): C1 tangent to link 1 and the upper arm, C2 to the upper arm and the forearm,
  C3 to the forearm and the last link, every tangent length half an arm link (L3/2 = L5/2).
  Unknowns (Eq. 26) ``X_a = (φ1, φ2, φ3, x3, y3, z3, α31, α32)``: arc angles, the shoulder point p3
  (where joints 2 and 3 meet) and the upper-arm direction ``k3 = sph(α31, α32)`` (Eq. 25).
* **Arm-b**, the serpentine arm: one arc per segment. The six equal links of a segment are tangent to
  its arc at their midpoints (each link subtends φ_i/6, Eq. 28: R_i = (L_b/2)/tan(φ_i/12)).
  Unknowns (Eq. 40) ``X_b = (φ1..φ5, p1 (3), α11, α12, p3 (3), α31, α32)``: arc angles, the end
  point and direction of segment 1 and of segment 3.

Both curves are split into a single-arc set (C1) and double-arc sets (C2-C3, and for Arm-b C4-C5)
whose two arcs share a common tangent line P̃2P̃3. The residual functions below are the paper's
Eq. 19-40 with these changes (all documented in docs/dshdasr.md):

* angles enter as ``cos φ − k·k'`` instead of ``φ − arccos(k·k')`` (the same zero set for
  φ ∈ [0, π]; arccos has an infinite slope at a straight arm, where the serpentine starts);
* the single-arc chord residual F2 is the chord *vector* (P2 − P1 = T (t1 + t2), T the tangent
  length) instead of its length only — the scalar form leaves the chord direction free, so a
  zero residual would not define a serpentine configuration;
* in each double-arc set the chord of the first arc (F4, implied by F3) is replaced by the common-
  tangent length |P̃3 − P̃2| = T2 + T3, which is what the second chord residual (F6) encodes without
  its spurious second root;
* Arm-a's shoulder p3 is tied to the arm's base by ``p3 − (b0 + L1 k1) = 0``: the paper lists p3
  among the unknowns but no residual fixes it.

With these, a zero residual is exactly a configuration of the arm (checked by the tests from the
robot's own forward kinematics), the residual count of Arm-b equals the paper's ten, and the
redundancy left is 1 (Arm-a: the elbow circle) and 5 (Arm-b).

The arc-to-sphere distance (Eq. 45-47) is the exact minimum distance from a point to a circular
arc, written so that it stays smooth and finite for a straight arc (zero curvature); the joint
recovery (Eq. 51-62) works from the arc tangents.

This module holds the arc geometry; the two arm models (residuals, arcs, joint recovery) are in
:mod:`optplan.papers.dshdasr.arc_models` and re-exported here. The per-waypoint NLP and the task are in
:mod:`optplan.papers.dshdasr`; the choices and the paper comparison in docs/dshdasr.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

__all__ = [
    "sph", "sph_angles", "Arc", "arc_point_distance", "arc_sample", "arc_deviation",
    "arc_from_tangent_length",
]


# --------------------------------------------------------------------------- helpers
def sph(a1, a2):
    """Unit vector of Eq. 25: ``(sin a1 cos a2, sin a1 sin a2, cos a1)`` (CasADi or numpy)."""
    if isinstance(a1, (ca.SX, ca.MX, ca.DM)) or isinstance(a2, (ca.SX, ca.MX, ca.DM)):
        return ca.vertcat(ca.sin(a1) * ca.cos(a2), ca.sin(a1) * ca.sin(a2), ca.cos(a1))
    return np.array([math.sin(a1) * math.cos(a2), math.sin(a1) * math.sin(a2), math.cos(a1)])


def sph_angles(k, a2_near: float | None = None) -> tuple[float, float]:
    """Inverse of :func:`sph` (a1 ∈ [0, π]); a2 is unwrapped to the 2π-branch nearest ``a2_near``."""
    k = np.asarray(k, float) / np.linalg.norm(k)
    a1 = math.atan2(math.hypot(k[0], k[1]), k[2])
    a2 = math.atan2(k[1], k[0])
    if a2_near is not None:
        a2 += 2 * math.pi * round((a2_near - a2) / (2 * math.pi))
    return a1, a2


def _is_sym(*xs) -> bool:
    return any(isinstance(x, (ca.SX, ca.MX)) for x in xs)


def _series_guard(x, small: float, exact, series):
    """``exact(x)`` away from 0, its Taylor ``series(x)`` for |x| < small (both CasADi)."""
    xs = ca.if_else(ca.fabs(x) < small, small, x)  # keeps the unused branch finite
    return ca.if_else(ca.fabs(x) < small, series(x), exact(xs))


def _sinc(x):
    """sin(x)/x."""
    return _series_guard(x, 1e-3, lambda y: ca.sin(y) / y, lambda y: 1 - y * y / 6 + y ** 4 / 120)


def _atanc(x):
    """atan(x)/x."""
    return _series_guard(x, 1e-3, lambda y: ca.atan(y) / y, lambda y: 1 - y * y / 3 + y ** 4 / 5)


def _norm(v):
    return ca.sqrt(ca.sumsqr(v))


def _dot(a, b):
    return ca.dot(a, b)


# --------------------------------------------------------------------------- arcs
@dataclass
class Arc:
    """A circular arc: start point ``P`` with unit tangent ``t0``, end tangent ``t1``, angle ``phi``
    [rad], curvature ``kappa`` [1/m], ``lam`` = κ / sin φ (finite for a straight arc) and length
    ``length`` [m] (CasADi expressions or numbers). ``v = t1 − (t0·t1) t0`` points from the arc
    toward its centre with norm sin φ, so κ u = λ v for the unit normal u."""

    P: Any
    t0: Any
    t1: Any
    phi: Any
    kappa: Any
    lam: Any
    length: Any

    def _v(self):
        return self.t1 - _dot(self.t0, self.t1) * self.t0

    def point(self, s):
        """Point at arc length ``s`` ∈ [0, length]: P + (sin κs / κ) t0 + ((1 − cos κs) / κ) u,
        written with sinc so that it is smooth and finite at zero curvature."""
        th = self.kappa * s
        return (self.P + s * _sinc(th) * self.t0
                + 0.5 * s * s * _sinc(0.5 * th) ** 2 * self.lam * self._v())

    def end(self):
        return self.point(self.length)


def arc_point_distance(arc: Arc, o):
    """Exact minimum distance from the point ``o`` to the arc (Eq. 45-47): the closest point of the
    full circle when it lies on the arc, the nearer end point otherwise. Smooth wherever the closest
    point is unique (C¹ across the switch to an end point) and finite for a straight arc."""
    r = o - arc.P
    x = _dot(r, arc.t0)                      # along the start tangent
    c = 1 - arc.lam * _dot(r, arc._v())      # 1 − κ y, y = offset toward the centre
    kap = arc.kappa
    # arc length of the circle's closest point: θ*/κ with θ* = atan2(κ x, 1 − κ y)
    th = ca.atan2(kap * x, c)
    th = ca.if_else(th < 0.5 * arc.phi - math.pi, th + 2 * math.pi, th)  # nearer end across the back
    cs = ca.if_else(c > 0.1, c, 0.1)
    s_star = ca.if_else(c > 0.1, x * _atanc(kap * x / cs) / cs, th / ca.fmax(kap, 1e-12))
    s_c = ca.fmin(ca.fmax(s_star, 0), arc.length)
    return _norm(o - arc.point(s_c))


def arc_sample(arc: Arc, n: int = 50) -> np.ndarray:
    """n × 3 points along an arc with numeric data (for plots and tests)."""
    s = ca.SX.sym("s")
    f = ca.Function("arc_point", [s], [arc.point(s)])
    return np.array([np.array(f(v)).ravel() for v in np.linspace(0.0, float(arc.length), n)])


def arc_deviation(T, phi):
    """Largest distance from the two tangent legs (length T each) to their inscribed arc, i.e.
    corner to arc: ``T tan(φ/4)`` [m] (CasADi or numbers)."""
    return T * (ca.tan(phi / 4.0) if _is_sym(phi) else math.tan(float(phi) / 4.0))


def arc_from_tangent_length(P, t0, t1, phi, T) -> Arc:
    """The arc tangent to t0 at P with angle φ whose tangent legs have the constant length T
    (Arm-a): κ = tan(φ/2)/T, λ = 1/(2T cos²(φ/2)), length = 2T cos(φ/2)/sinc(φ/2)."""
    return Arc(P, t0, t1, phi, ca.tan(phi / 2) / T, 1.0 / (2 * T * ca.cos(phi / 2) ** 2),
               2 * T * ca.cos(phi / 2) / _sinc(phi / 2))


def __getattr__(name):
    # the two arm models live in arcs_arms.py (which imports this module); the old path warns
    if name in ("DiscreteArcModel", "SerpentineArcModel"):
        from ..._compat import moved

        return moved(__name__, name, "optplan.papers.dshdasr.arc_models")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
