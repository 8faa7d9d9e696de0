"""Attitude-steering manoeuvres of a floating plan kept as planned, and the chained motion.

With zero momentum the base's rotation along a joint path depends on the path only, not on its
timing. A steering manoeuvre of :class:`~optplan.planners.floating_tcbirrt.FloatingTCBiRRT` (closed
joint loops with the object held, tens of them) is therefore kept as the planner's waypoints — its
exact, collision-checked samples — with a smooth time law, instead of being approximated by a
coarse B-spline that cannot follow its loops:

* :func:`manoeuvre_spans` finds the manoeuvres in a plan's joint waypoints: every loop of a
  manoeuvre brings the joints back EXACTLY to its start, so a manoeuvre is the span from a waypoint
  to the last waypoint with the very same joints;
* :class:`ManoeuvreMotion` moves along each straight joint edge of the manoeuvre with a quintic
  rest-to-rest time law (zero velocity and acceleration at every waypoint, where the path has its
  corners); the edge's points are put back on the closed chain (the second hand solved onto the
  object held by the first: the straight joint edge leaves the chain by a second-order amount) and
  joined by a cubic spline in the edge's parameter;
* :class:`ChainedMotion` concatenates timed parts (optimized pieces and manoeuvres) into one
  trajectory with the interface :func:`optplan.verify` judges (``t``, ``sample``).
"""
from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline, PPoly

from .errors import OptionError

__all__ = ["manoeuvre_spans", "sharp_corners", "ManoeuvreMotion", "ChainedMotion", "MotionPart", "KeptStatus"]


class KeptStatus(str, Enum):
    """Status of a kept manoeuvre (no NLP ran on it)."""

    KEPT = "Kept_Manoeuvre"
    #: a point of an edge could not be put back on the closed chain
    NOT_PROJECTED = "Manoeuvre_Not_Projected"


def manoeuvre_spans(joints: np.ndarray) -> list[tuple[int, int]]:
    """``(i, j)`` index pairs of the waypoints ``joints`` (M × nj) [rad] where the joints at ``j`` are
    exactly those at ``i`` (``j > i + 1`` the last such waypoint): the closed loops of a steering
    manoeuvre. Spans do not overlap; in order."""
    J = np.asarray(joints, float)
    out, i = [], 0
    while i < len(J) - 1:
        same = np.flatnonzero(np.all(J[i + 1:] == J[i], axis=1))
        if len(same) and same[-1] > 0:   # a repeated waypoint alone is no loop
            j = i + 1 + int(same[-1])
            out.append((i, j))
            i = j
        else:
            i += 1
    return out


def sharp_corners(joints: np.ndarray, min_cos: float, spans: Sequence[tuple[int, int]] = ()) -> list[int]:
    """Interior waypoints of ``joints`` (M × nj) [rad] where the cosine between the incoming and the
    outgoing joint direction is below ``min_cos`` [1], outside the ``spans`` (their ends excluded)."""
    J = np.asarray(joints, float)
    d = np.diff(J, axis=0)
    n = np.linalg.norm(d, axis=1)
    out = []
    for k in range(1, len(J) - 1):
        if n[k - 1] == 0 or n[k] == 0 or any(a <= k <= b for a, b in spans):
            continue
        if float(d[k - 1] @ d[k]) / (n[k - 1] * n[k]) < min_cos:
            out.append(k)
    return out


@functools.lru_cache(maxsize=64)
def _spline_map(n: int) -> np.ndarray:
    """(4, n, n + 1): the not-a-knot cubic spline's coefficients on the uniform grid of ``n`` intervals
    of [0, 1] as a linear map of the ``n + 1`` values (scipy's ``CubicSpline`` on the unit vectors):
    the spline of an edge's points without solving its system again."""
    c = CubicSpline(np.linspace(0.0, 1.0, n + 1), np.eye(n + 1), axis=0).c
    c.setflags(write=False)
    return c


def _law(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quintic rest-to-rest law s(τ) and ds/dτ on [0, 1]."""
    return tau**3 * (10 - 15 * tau + 6 * tau**2), 30 * tau**2 * (1 - tau) ** 2


class ManoeuvreMotion:
    """The joint waypoints ``joints`` (M × nj) [rad] timed edge by edge (module docstring).

    ``project(q)`` returns ``q`` put back on the closed chain (or None when it cannot); each edge
    gets ``ceil(max |Δq| / step_rad)`` (≥ 4) projected points; its duration is
    ``duration_factor × max |Δq| / speed`` [s] (≥ ``min_edge_s``), so that the peak joint speed is
    about 1.9 / ``duration_factor`` of ``speed`` [rad/s]. ``t`` [s]: the knots, as many per edge as
    put :func:`optplan.verify`'s samples (10 per knot interval) at most ``sample_step_rad`` apart in
    the joints (the planner's own check step by default). ``ok`` is False when a
    point could not be projected (the edge is then kept straight). An edge with the very same end
    joints as an earlier one (a repeated loop) reuses that edge's spline: ``project`` must depend
    on its argument alone."""

    def __init__(self, joints: np.ndarray, project: Callable[[np.ndarray], np.ndarray | None], speed: float,
                 duration_factor: float = 3.0, step_rad: float = 0.02, sample_step_rad: float = 0.02,
                 min_edge_s: float = 0.05):
        J = np.asarray(joints, float)
        if J.ndim != 2 or len(J) < 2:
            raise OptionError(f"ManoeuvreMotion: expected at least 2 joint waypoints (M × nj), got shape {J.shape}")
        if not (speed > 0 and step_rad > 0 and duration_factor > 0):
            raise OptionError(f"ManoeuvreMotion: speed [rad/s], step_rad [rad] and duration_factor must be positive, "
                              f"got {speed!r}, {step_rad!r}, {duration_factor!r}")
        self.ok = True
        self._splines: list[PPoly] = []
        #: points projected onto the closed chain [count]
        self.projections = 0
        #: edges whose spline was that of an earlier edge with the very same ends [count]
        self.repeated_edges = 0
        # a steering manoeuvre repeats its loops (each up to ``max_repeat`` times): an edge with the
        # very same end joints as an earlier one gets that edge's spline (the projection is a
        # function of the points alone), so each distinct edge is projected once
        seen: dict[tuple[bytes, bytes, int], tuple[PPoly, bool]] = {}
        durs = []
        for a, b in zip(J[:-1], J[1:]):
            d = float(np.max(np.abs(b - a)))
            n = max(4, math.ceil(d / step_rad))
            key = (a.tobytes(), b.tobytes(), n)
            got = seen.get(key)
            if got is None:
                ok0, self.ok = self.ok, True
                got = seen[key] = (self._edge(a, b, n, project), self.ok)
                self.ok = ok0 and self.ok
            else:
                self.repeated_edges += 1
                self.ok = self.ok and got[1]
            self._splines.append(got[0])
            durs.append(max(min_edge_s, duration_factor * d / speed))
        # every edge's cubic pieces in one table, evaluated for all times at once (sample)
        nseg = np.array([len(sp.x) - 1 for sp in self._splines])
        self._first = np.r_[0, np.cumsum(nseg)[:-1]]
        self._nseg = nseg
        self._coef = np.concatenate([sp.c for sp in self._splines], axis=1)      # (4, pieces, nj)
        self._brk = np.concatenate([sp.x[:-1] for sp in self._splines])         # each piece's start in s
        self._t0 = np.r_[0.0, np.cumsum(durs)]
        self._dur = np.asarray(durs)
        self.duration = float(self._t0[-1])
        # knots: verify's 10 samples per knot interval at most sample_step_rad apart in the joints
        per = [max(1, math.ceil(float(np.max(np.abs(b - a))) / (10 * sample_step_rad))) for a, b in zip(J[:-1], J[1:])]
        self.t = np.concatenate([np.linspace(self._t0[e], self._t0[e + 1], per[e] + 1)[:-1]
                                 for e in range(len(durs))] + [self._t0[-1:]])

    def _edge(self, a: np.ndarray, b: np.ndarray, n: int, project: Callable[[np.ndarray], np.ndarray | None]) -> PPoly:
        """The spline (in the edge's parameter s ∈ [0, 1]) through ``n + 1`` evenly spaced points of
        the straight edge ``a → b`` [rad], its ``n − 1`` inner points projected."""
        s = np.linspace(0.0, 1.0, n + 1)
        P = a + s[:, None] * (b - a)
        # each point projected from the straight one (a start extrapolated from the points before
        # carries the redundant arm's self-motion along the edge, and the spline then misses the
        # chain by more between the points)
        for k in range(1, n):
            self.projections += 1
            p = project(P[k])
            if p is None:
                self.ok = False
            else:
                P[k] = p
        return PPoly.construct_fast(np.einsum("kij,jd->kid", _spline_map(n), P), s)

    def sample(self, t) -> dict[str, np.ndarray]:
        """Joint positions ``q`` [rad] and velocities ``qd`` [rad/s] at times ``t`` [s] in [0, duration]."""
        t = np.clip(np.atleast_1d(np.asarray(t, float)), 0.0, self.duration)
        e = np.clip(np.searchsorted(self._t0, t, side="right") - 1, 0, len(self._splines) - 1)
        dur = self._dur[e]
        s, ds = _law(np.clip((t - self._t0[e]) / dur, 0.0, 1.0))
        # the piece of each edge's spline holding s (its pieces evenly spaced on [0, 1]), Horner
        n = self._nseg[e]
        piece = self._first[e] + np.minimum((s * n).astype(int), n - 1)
        x = (s - self._brk[piece])[:, None]
        c = self._coef[:, piece]
        q = ((c[0] * x + c[1]) * x + c[2]) * x + c[3]
        qd = ((3.0 * c[0] * x + 2.0 * c[1]) * x + c[2]) * (ds / dur)[:, None]
        return {"t": t, "q": q, "qd": qd}


@dataclass
class MotionPart:
    """One part of a :class:`ChainedMotion`: anything with ``t`` (its knots [s], from 0) and
    ``sample``; ``success``/``status``/``iterations`` of its optimization (a kept manoeuvre:
    :class:`KeptStatus`, 0 iterations)."""

    motion: Any
    success: bool = True
    status: Any = KeptStatus.KEPT
    iterations: int = 0


class ChainedMotion:
    """Parts played one after the other (each starts where and when the previous one stops, at
    rest): ``t`` the union of their knots [s], ``sample(t)`` → ``q`` [rad], ``qd`` [rad/s]."""

    base_quat = None   # no base of its own: verify re-integrates it

    def __init__(self, parts: list[MotionPart]):
        #: the base placement at the end from the identity, when the builder integrated it part by
        #: part (pinocchio.SE3); None: not known
        self.end_base: Any = None
        if not parts:
            raise OptionError("ChainedMotion: expected at least one part, got none")
        self.parts = parts
        offs, knots, t = [], [], 0.0
        for p in parts:
            pt = np.asarray(p.motion.t, dtype=float)
            offs.append(t - pt[0])
            knots.append(pt[:-1] - pt[0] + t)
            t += float(pt[-1] - pt[0])
        self._off = np.asarray(offs)
        self._start = np.r_[[k[0] for k in knots], t]
        self.t = np.r_[np.concatenate(knots), t]
        self.success = all(p.success for p in parts)
        #: the first failed part's status, else the last optimized part's, else KEPT
        bad = [p.status for p in parts if not p.success]
        nlp = [p.status for p in parts if not isinstance(p.status, KeptStatus)]
        self.status = bad[0] if bad else (nlp[-1] if nlp else KeptStatus.KEPT)
        self.iterations = int(sum(p.iterations for p in parts))

    def sample(self, t) -> dict[str, np.ndarray]:
        """Joint positions ``q`` [rad] and velocities ``qd`` [rad/s] at times ``t`` [s]."""
        t = np.clip(np.atleast_1d(np.asarray(t, float)), self.t[0], self.t[-1])
        idx = np.clip(np.searchsorted(self._start, t, side="right") - 1, 0, len(self.parts) - 1)
        q: np.ndarray = np.empty(0)
        qd: np.ndarray = np.empty(0)
        for k in np.unique(idx):
            m = idx == k
            mo = self.parts[k].motion
            s = mo.sample(np.clip(t[m] - self._off[k], mo.t[0], mo.t[-1]))
            if q.size == 0:
                q, qd = np.empty((len(t), s["q"].shape[1])), np.empty((len(t), s["q"].shape[1]))
            q[m], qd[m] = s["q"], s["qd"]
        return {"t": t, "q": q, "qd": qd}
