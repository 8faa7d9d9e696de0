"""Collision primitives fitted to a link's mesh, with their containment certified.

A capsule is a segment ``[a, b]`` and a radius ``r``: it contains a point ``p`` iff the distance
from ``p`` to the segment is ≤ ``r``. :func:`fit_capsule` finds a small capsule around a mesh's
vertices (the axis from a local search started on the principal axis, the radius and the ends
exact for that axis) and :func:`certify` then *sets* the radius to the largest vertex–segment
distance, computed in closed form in float64, plus :data:`CERT_EPS`. A capsule is convex, so a
capsule that contains every vertex contains every triangle of the mesh and its convex hull: no
collision of the mesh is missed by a check on the capsule.

One capsule is poor for an L-shaped or flat link: when its volume exceeds
:data:`SPLIT_RATIO` × the volume of the mesh's convex hull, :func:`fit_mesh` splits the mesh's
*triangles* in two along their principal axis (recursively, up to ``max_capsules``) and keeps the
split when it cuts the total volume by a quarter. Each triangle is then inside one capsule (its
three vertices are), so the union contains the mesh's surface — what coal's mesh checks see.

Fits are cached per mesh (a SHA-256 of the vertices and triangles) under
``$OPTPLAN_CACHE/capsule_fits`` (default ``~/.cache/optplan``).
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize

__all__ = ["CapsuleFit", "MeshFit", "fit_capsule", "fit_mesh", "certify", "segment_distances", "CERT_EPS",
           "SPLIT_RATIO", "capsule_volume"]

#: [m] added to the largest vertex distance: the certified radius's safety over float64 rounding
CERT_EPS = 1e-6
#: a single capsule whose volume exceeds this multiple of the mesh hull's volume is split [ratio]
SPLIT_RATIO = 2.0
_VERSION = 2   # of the fitting algorithm: part of the cache key


@dataclass(frozen=True)
class CapsuleFit:
    """A certified capsule: ends ``a``, ``b`` [m] (mesh frame), radius [m] (≥ every vertex's
    distance to the segment + :data:`CERT_EPS`), and the largest vertex distance [m] it was
    certified on (``max_distance``)."""

    a: tuple[float, float, float]
    b: tuple[float, float, float]
    radius: float
    max_distance: float

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.subtract(self.b, self.a)))

    @property
    def volume(self) -> float:
        return capsule_volume(self.radius, self.length)


@dataclass(frozen=True)
class MeshFit:
    """The capsules of one mesh, the mesh's hull volume [m³] and their total volume [m³]
    (``ratio`` = capsules / hull, ≥ 1 up to the overlap of several capsules)."""

    capsules: tuple[CapsuleFit, ...]
    hull_volume: float
    n_vertices: int

    @property
    def volume(self) -> float:
        return float(sum(c.volume for c in self.capsules))

    @property
    def ratio(self) -> float:
        return self.volume / self.hull_volume if self.hull_volume > 0 else math.inf


def capsule_volume(r: float, length: float) -> float:
    """Volume [m³] of a capsule of radius r [m] and segment length [m]."""
    return math.pi * r * r * length + 4.0 / 3.0 * math.pi * r ** 3


def segment_distances(P: npt.ArrayLike, a: npt.ArrayLike, b: npt.ArrayLike) -> np.ndarray:
    """Distances [m] of the points P (n × 3) to the segment [a, b] (closed form)."""
    P, a, b = np.asarray(P, float), np.asarray(a, float), np.asarray(b, float)
    d = b - a
    dd = float(d @ d)
    t = np.zeros(len(P)) if dd == 0.0 else np.clip((P - a) @ d / dd, 0.0, 1.0)
    return np.linalg.norm(P - (a + t[:, None] * d), axis=1)


def certify(P: np.ndarray, a, b) -> CapsuleFit:
    """The capsule on segment [a, b] containing every point of P: radius = max distance + eps."""
    dmax = float(segment_distances(P, a, b).max())
    return CapsuleFit(tuple(map(float, a)), tuple(map(float, b)), dmax + CERT_EPS, dmax)   # type: ignore[arg-type]


def _axis_capsule(P: np.ndarray, c: np.ndarray, u: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Smallest-volume capsule whose axis is the line c + t·u: (volume, a, b). For radius r a
    point at abscissa t_i and distance d_i from the line is inside iff the segment reaches within
    √(r² − d_i²) of t_i; the volume is minimised over r by a bounded scalar search."""
    u = u / np.linalg.norm(u)
    X = P - c
    t = X @ u
    d2 = np.maximum(np.einsum("ij,ij->i", X, X) - t * t, 0.0)
    rmin = math.sqrt(float(d2.max()))
    span = float(t.max() - t.min())

    def volumes(r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        s = np.sqrt(np.maximum(r[:, None] ** 2 - d2[None, :], 0.0))
        # point i is within r of [lo, hi] iff lo − s_i ≤ t_i ≤ hi + s_i
        lo, hi = np.min(t + s, axis=1), np.max(t - s, axis=1)
        mid = 0.5 * (lo + hi)
        flip = lo > hi   # one point of the line is within r of every point
        lo, hi = np.where(flip, mid, lo), np.where(flip, mid, hi)
        return np.pi * r * r * (hi - lo) + 4.0 / 3.0 * np.pi * r ** 3, lo, hi

    a_r, b_r = rmin, max(rmin, 0.5 * span + rmin) + 1e-9
    for _ in range(4):   # grid, then three refinements of the bracket around the best
        rs = np.linspace(a_r, b_r, 24)
        vs, _, _ = volumes(rs)
        k = int(np.argmin(vs))
        a_r, b_r = rs[max(k - 1, 0)], rs[min(k + 1, len(rs) - 1)]
    v, lo, hi = volumes(np.array([rs[k]]))
    return float(v[0]), c + float(lo[0]) * u, c + float(hi[0]) * u


def fit_capsule(P: np.ndarray) -> CapsuleFit:
    """A small certified capsule around the points P (n × 3) [m]: the axis direction and offset
    searched (Nelder–Mead, from the principal axis through the centroid) for the smallest volume
    of :func:`_axis_capsule`, then :func:`certify`."""
    P_all = P = np.asarray(P, float).reshape(-1, 3)
    if len(P) == 0:
        raise ValueError("fit_capsule: no points")
    if len(P) > 8:   # a convex capsule contains the points iff it contains their hull's vertices
        from scipy.spatial import ConvexHull, QhullError

        try:
            P = P[ConvexHull(P).vertices]
        except (QhullError, ValueError):
            pass
    c0 = P.mean(axis=0)
    if len(P) == 1 or np.ptp(P, axis=0).max() == 0.0:
        return certify(P, c0, c0)
    _, _, Vt = np.linalg.svd(P - c0, full_matrices=False)
    u0, e1, e2 = Vt[0], Vt[1] if len(Vt) > 1 else np.cross(Vt[0], [1, 0, 0]), None
    e2 = np.cross(u0, e1)
    scale = float(np.linalg.norm(np.ptp(P, axis=0)))

    def line(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u = u0 + x[0] * e1 + x[1] * e2
        return c0 + scale * (x[2] * e1 + x[3] * e2), u

    def f(x: np.ndarray) -> float:
        c, u = line(x)
        return _axis_capsule(P, c, u)[0]

    best = minimize(f, np.zeros(4), method="Nelder-Mead",
                    options={"xatol": 1e-4, "fatol": 1e-12, "maxiter": 250, "initial_simplex":
                             np.vstack([np.zeros(4), 0.2 * np.eye(4)])})
    x = best.x if best.fun <= f(np.zeros(4)) else np.zeros(4)
    c, u = line(x)
    _, a, b = _axis_capsule(P, c, u)
    return certify(P_all, a, b)   # on every point, not only the hull's


def _hull_volume(P: np.ndarray) -> float:
    from scipy.spatial import ConvexHull, QhullError

    try:
        return float(ConvexHull(P).volume)
    except (QhullError, ValueError):   # flat or degenerate: no volume
        return 0.0


def _split(V: np.ndarray, T: np.ndarray, depth: int, max_capsules: int) -> list[CapsuleFit]:
    """Capsules for the triangles T (indices into V): one, or the two halves' fits along the
    triangles' principal axis when that cuts the volume by a quarter (recursively)."""
    P = V[np.unique(T)]
    one = fit_capsule(P)
    if max_capsules < 2 or len(T) < 4:
        return [one]
    hull = _hull_volume(P)
    if hull > 0 and one.volume <= SPLIT_RATIO * hull:
        return [one]
    C = V[T].mean(axis=1)
    c0 = C.mean(axis=0)
    u = np.linalg.svd(C - c0, full_matrices=False)[2][0]
    s = (C - c0) @ u
    left = s <= np.median(s)
    if left.all() or not left.any():
        return [one]
    half = max_capsules // 2
    parts = _split(V, T[left], depth + 1, half) + _split(V, T[~left], depth + 1, max_capsules - half)
    if sum(c.volume for c in parts) <= 0.75 * one.volume:
        return parts
    return [one]


def _cache_dir() -> Path:
    return Path(os.environ.get("OPTPLAN_CACHE", Path.home() / ".cache" / "optplan")) / "capsule_fits"


def mesh_hash(V: np.ndarray, T: np.ndarray, max_capsules: int) -> str:
    h = hashlib.sha256()
    h.update(f"v{_VERSION} n{max_capsules} eps{CERT_EPS!r} split{SPLIT_RATIO!r}".encode())
    h.update(np.ascontiguousarray(V, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(T, dtype=np.int64).tobytes())
    return h.hexdigest()


def fit_mesh(V: np.ndarray, T: np.ndarray | None = None, max_capsules: int = 3, cache: bool = True) -> MeshFit:
    """Certified capsules of a mesh: vertices V (n × 3) [m], triangles T (m × 3 indices; None:
    the points alone, one capsule). The fit is cached per mesh hash; a cached fit is
    re-certified on load (its radius recomputed from the vertices), so a stale or edited cache
    entry can never loosen containment."""
    V = np.asarray(V, float).reshape(-1, 3)
    if len(V) == 0:
        raise ValueError("fit_mesh: the mesh has no vertices")
    T = np.zeros((0, 3), np.int64) if T is None else np.asarray(T, np.int64).reshape(-1, 3)
    key = mesh_hash(V, T, max_capsules)
    path = _cache_dir() / f"{key}.json"
    caps: list[CapsuleFit] | None = None
    if cache and path.exists():
        try:
            data = json.loads(path.read_text())
            caps = [certify(V[np.asarray(c["vertices"], int)] if c.get("vertices") is not None else V, c["a"], c["b"])
                    for c in data["capsules"]]
        except (OSError, ValueError, KeyError, IndexError):
            caps = None
    if caps is None:
        if len(T) and max_capsules > 1:
            caps = _split(V, T, 0, max_capsules)
        else:
            caps = [fit_capsule(V)]
        if cache:
            entries = []
            for c in caps:
                inside = np.flatnonzero(segment_distances(V, c.a, c.b) <= c.radius)
                entries.append({"a": c.a, "b": c.b, "vertices": None if len(inside) == len(V) else inside.tolist()})
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(json.dumps({"capsules": entries}))
            except OSError:
                pass
    return MeshFit(tuple(caps), _hull_volume(V), len(V))
