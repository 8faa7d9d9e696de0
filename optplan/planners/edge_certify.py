"""Certified collision-free edges: conservative advancement on exact distances.

Checking configurations along an edge at ANY fixed spacing leaves the motion between two checks
unchecked: a graze thinner than the spacing's sweep passes. :class:`EdgeCertifier` instead
certifies a whole piecewise-linear joint path (a straight edge is the two-vertex case): no
collision pair is ever closer than ``min_clearance / 2`` (plus the checker's ``margin``) at ANY
point of it, and every configuration where a distance was evaluated has clearance ≥
``min_clearance``.

How (conservative advancement): the active collision pairs of a mode (those of
:class:`~optplan.planners.validity.ValidityChecker`'s ``"held"``, ``"fixed"`` or ``"free"`` mode)
are split into groups by the two joints that carry the pair's geometries (the world for
obstacles). For each group
``G`` the certifier keeps the exact distance ``d_G`` (coal, through ``pinocchio.computeDistances``
on the group's pairs only) at the configuration ``x_G`` where it was last evaluated and a weight
row ``w_G = max over pairs (W[g1] + W[g2])`` from the per-geometry sweep weights
(:func:`optplan.collision.sweep.sweep_weights`: no point of geometry ``g`` is displaced farther
than ``W[g]·|q − x|`` between any ``q`` and ``x``, so no pair's distance drops by more than
``w_G·|q − x|``), with the columns of the joints that carry BOTH geometries of a pair set to zero
(they move the pair rigidly: the held object and the forearm holding it stay where they are
relative to each other whatever the shoulder does). On a chord ``[u, v]`` of the path ``|q − x_G| ≤ max(|u − x_G|, |v − x_G|)``
component-wise, so the group stays clear on the whole chord (in fact on every chord of a run of
vertices, taking the maximum over them) when
``d_G − w_G·max|Q_i − x_G| ≥ min_clearance / 2``. Groups that fail are re-evaluated at the start
of the run; a run that still fails is halved, down to single chords, on which the certifier
advances from the start by the largest step ``t = (d_G − min_clearance/2) / (w_G·|v − u|)`` the
group allows and re-evaluates there. A distance below ``min_clearance`` rejects the path: the
advance never takes steps shorter than ``min_clearance / (2 w_G·|v − u|)``, so it terminates
(no Zeno behaviour near contact).

The pairs are those active in the checker's mode NOW: inside
:meth:`~optplan.planners.validity.ValidityChecker.exempt` (a regrasp's grasp contacts) the exempted
pairs are skipped here as in the boolean and batch checks. Groups, weights and the vertex cache are
kept per (mode, exempted pairs), so no bound or verdict crosses from one exemption to another.

Groups far from everything (the other arm's links, distant obstacles) are evaluated once per
path; only the pairs that are near contact cost distance calls. The distance call is ~10× a
collision check (all pairs of the group, no early exit, no broad phase), so planners run their
cheap configuration checks first and certify only the edges that pass them.

:meth:`EdgeCertifier.discrete_segment` is the simpler alternative measured against it: collision
checks at the Jacobian-bound spacing of
:meth:`~optplan.planners.validity.ValidityChecker.edge_checkpoints` (no point of any geometry
travels farther than ``tolerance`` between checks) with coal security margins of ``tolerance / 2``
on pairs with one moving geometry and ``tolerance`` on pairs of two moving geometries (plus
``min_clearance / 2``): every point of the segment is then within that travel of a checked
configuration, so it is certified too; the margins disable the broad phase.
"""
from __future__ import annotations

import bisect
import math
from typing import Any, cast

import numpy as np
import pinocchio as pin

from ..collision.checker import exact_contact_requests
from ..collision.sweep import sweep_weights

__all__ = ["EdgeCertifier"]

_MODES = ("held", "fixed", "free")

#: a mode and the pair indices the checker exempts in it (:meth:`ValidityChecker.exempt`)
_State = tuple[str, frozenset[int]]


class _Group:
    """Pairs of one mode whose faster-moving geometry hangs on the same joint."""

    __slots__ = ("gd", "w", "pairs")

    def __init__(self, gd: Any, w: np.ndarray, pairs: list[int]):
        self.gd, self.w, self.pairs = gd, w, pairs


class EdgeCertifier:
    """Certified collision checks of straight joint segments and piecewise-linear joint paths
    (module docstring) on the geometry and pair set of a
    :class:`~optplan.planners.validity.ValidityChecker`.

    ``min_clearance`` [m]: a path whose exact clearance (beyond the checker's ``margin``) drops
    below this at an evaluated configuration is rejected; a certified path keeps every pair at
    least ``min_clearance / 2`` (+ ``margin``) apart everywhere. When the path's first or last
    configuration is itself closer than ``min_clearance`` (a valid start or goal nearly in
    contact), half of that end's clearance replaces ``min_clearance`` for that path.

    Counters: ``n_distance_calls`` (group distance evaluations), ``n_paths`` (certify calls).
    """

    def __init__(self, checker: Any, min_clearance: float = 1e-3) -> None:
        if not (isinstance(min_clearance, (int, float)) and math.isfinite(min_clearance) and min_clearance > 0):
            raise ValueError(f"min_clearance: expected a positive number of metres, got {min_clearance!r}")
        self.checker = checker
        self.min_clearance = float(min_clearance)
        self.model, self.gmodel = checker.model, checker.gmodel
        self.data = self.model.createData()
        self._W = sweep_weights(self.model, self.gmodel)          # geometries × nv [m/rad]
        # per (mode, pairs the checker's ``exempt`` switches off now): the pair groups, their weight
        # rows and the rows of their pairs' speeds; a group's GeometryData per set of its pairs
        self._groups: dict[_State, list[_Group]] = {}
        self._Wg: dict[_State, np.ndarray] = {}
        self._pair_rows: dict[_State, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]] = {}
        self._group_gd: dict[tuple[int, ...], Any] = {}
        self._pair_w: dict[int, np.ndarray] = {}
        self._margin_gd: dict[tuple[_State, float, float], Any] = {}
        self.n_distance_calls = 0
        self.n_paths = 0
        self.n_checks = 0
        self.n_cache_hits = 0
        # vertex cache (``path(..., cache=True)``): per configuration (and mode, object pose) a lower
        # bound on each group's clearance there
        self._vertex: dict[tuple[Any, ...], np.ndarray] = {}
        if self.model.nq != self.model.nv:
            raise ValueError("EdgeCertifier: robots whose configuration is not a joint vector (nq != nv) are not supported")

    # ------------------------------------------------------------------ set-up
    def _mode(self, mode: str) -> str:
        if mode not in _MODES:
            raise ValueError(f"mode: expected one of {_MODES}, got {mode!r}")
        if mode in ("held", "fixed") and self.checker.object is None:
            return "free"
        return mode

    def _state(self, mode: str) -> _State:
        """``mode`` and the pairs the checker exempts in it now: the certifier's groups, weights, margin
        data and vertex cache are kept per state, so a regrasp's exemption switches off the same pairs
        here as in the boolean and batch checks, and no verdict is carried from one exemption to another."""
        return (mode, self.checker.exempted(mode))

    #: exemption states whose groups are kept (oldest dropped first)
    STATES_KEPT = 256

    def groups(self, mode: str) -> list[_Group]:
        """The pair groups of ``mode`` under the checker's current exemption (built on first use)."""
        mode = self._mode(mode)
        state = self._state(mode)
        if state in self._groups:
            return self._groups[state]
        if len(self._groups) >= self.STATES_KEPT:
            old = next(iter(self._groups))
            del self._groups[old], self._Wg[old], self._pair_rows[old]
            for mk in [mk for mk in self._margin_gd if mk[0] == old]:
                del self._margin_gd[mk]
        src = self.checker._gd[mode]      # its active pairs: the mode's, less the exempted ones
        pairs = self.gmodel.collisionPairs
        W = self._W
        rowsum = W.sum(axis=1)
        by_joint: dict[tuple[int, int], list[int]] = {}
        for k, cp in enumerate(pairs):
            if not src.activeCollisionPairs[k]:
                continue
            g, h = (cp.first, cp.second) if rowsum[cp.first] >= rowsum[cp.second] else (cp.second, cp.first)
            objs = self.gmodel.geometryObjects
            joints = (int(objs[g].parentJoint), int(objs[h].parentJoint))
            by_joint.setdefault(joints, []).append(k)
        out = []
        for _, ks in sorted(by_joint.items()):
            w = np.max([self._pair_weights_of(k) for k in ks], axis=0)
            out.append(_Group(self._group_data(tuple(ks)), w, ks))
        self._groups[state] = out
        self._Wg[state] = np.array([g.w for g in out]).reshape(len(out), self.model.nv)
        # per pair, the rows of its two geometries among the checker's moving geometries of this mode
        # (the speed rows of its compiled cell speeds; a static geometry gets the zero row at the end)
        # and the row of its relative speed (held object against a robot geometry), if it has one
        gids = self.checker._moving_geometries(mode)
        row_of = {gid: r for r, gid in enumerate(gids)}
        zero = len(gids)
        rel = {tuple(sorted((gids[a], gids[b]))): zero + i for i, (a, b) in enumerate(self.checker._relative_pairs(mode))}
        r1: list[int] = []
        r2: list[int] = []
        rr: list[int] = []
        starts: list[int] = []
        for g in out:
            starts.append(len(r1))
            for k in g.pairs:
                r1.append(row_of.get(pairs[k].first, -1))
                r2.append(row_of.get(pairs[k].second, -1))
                rr.append(rel.get(tuple(sorted((pairs[k].first, pairs[k].second))), -1))
        self._pair_rows[state] = (np.array(r1, dtype=int), np.array(r2, dtype=int), np.array(rr, dtype=int),
                                 np.array(starts, dtype=int), zero + len(rel))
        return out

    def _group_data(self, ks: tuple[int, ...]) -> Any:
        """A GeometryData with only the pairs ``ks`` active (shared by the states with this group)."""
        gd = self._group_gd.get(ks)
        if gd is None:
            gd = pin.GeometryData(self.gmodel)
            keep = set(ks)
            for k in range(len(self.gmodel.collisionPairs)):
                if k not in keep:
                    gd.deactivateCollisionPair(k)
            self._group_gd[ks] = gd
        return gd

    def _pair_weights_of(self, k: int) -> np.ndarray:
        """:meth:`_pair_weights` of pair ``k`` (kept)."""
        w = self._pair_w.get(k)
        if w is None:
            cp = self.gmodel.collisionPairs[k]
            w = self._pair_w[k] = self._pair_weights(cp.first, cp.second)
        return w

    def _pair_weights(self, g1: int, g2: int) -> np.ndarray:
        """``W[g1] + W[g2]`` without the joints that move both geometries: a joint that carries both
        moves them rigidly together (their distance is that of their placements in the frame of
        the deepest joint carrying both, which only the joints below it change)."""
        w = self._W[g1] + self._W[g2]
        objs, model = self.gmodel.geometryObjects, self.model
        j1, j2 = int(objs[g1].parentJoint), int(objs[g2].parentJoint)
        if j1 == 0 or j2 == 0:
            return w
        common = set(model.supports[j1]) & set(model.supports[j2])
        for j in common:
            if j > 0:
                jm = model.joints[j]
                w[jm.idx_v:jm.idx_v + jm.nv] = 0.0
        return w

    #: vertices kept by the vertex cache (oldest dropped first)
    CACHE_SIZE = 20000

    def clear_cache(self) -> None:
        """Forget the vertex cache (a planner does this at the start of each query, so that a query's
        result does not depend on the queries before it)."""
        self._vertex.clear()

    def _key(self, mode: str, x: np.ndarray, object_pose: pin.SE3 | None) -> tuple[Any, ...]:
        state = self._state(mode)
        if mode == "fixed":
            return (state, x.tobytes(), cast(pin.SE3, object_pose).homogeneous.tobytes())
        return (state, x.tobytes())

    def _remember(self, key: tuple[Any, ...], lower: np.ndarray) -> None:
        if len(self._vertex) >= self.CACHE_SIZE:
            del self._vertex[next(iter(self._vertex))]
        self._vertex[key] = lower

    def prepare(self, modes: tuple[str, ...] = ("held", "fixed")) -> None:
        """Build the pair groups of ``modes`` (and the compiled speed profiles) now, before a
        planner's time limit starts."""
        for mode in modes:
            self.groups(mode)
            self.checker._cell_speed_function(self._mode(mode))

    # ------------------------------------------------------------------ exact distances
    def _distances(self, mode: str, gs: np.ndarray, x: np.ndarray, object_pose: pin.SE3 | None) -> np.ndarray:
        """Exact clearance [m] (minus the checker's margin) of each group in ``gs`` at ``x``."""
        groups = self._groups[self._state(mode)]
        pin.forwardKinematics(self.model, self.data, x)
        out = np.empty(len(gs))
        fixed_id = self.checker.fixed_id
        for i, g in enumerate(gs):
            gd = groups[g].gd
            pin.updateGeometryPlacements(self.model, self.data, self.gmodel, gd)
            if mode == "fixed":
                gd.oMg[fixed_id] = object_pose
            k = pin.computeDistances(self.gmodel, gd)
            out[i] = gd.distanceResults[k].min_distance
        self.n_distance_calls += len(gs)
        return out - self.checker.margin

    def _distance1(self, mode: str, g: int, x: np.ndarray, object_pose: pin.SE3 | None) -> float:
        """:meth:`_distances` of the one group ``g``, as a float."""
        gd = self._groups[self._state(mode)][g].gd
        pin.updateGeometryPlacements(self.model, self.data, self.gmodel, gd, x)
        if mode == "fixed":
            gd.oMg[self.checker.fixed_id] = object_pose
        k = pin.computeDistances(self.gmodel, gd)
        self.n_distance_calls += 1
        return gd.distanceResults[k].min_distance - self.checker.margin

    # ------------------------------------------------------------------ public checks
    def segment(self, a: np.ndarray, b: np.ndarray, mode: str = "held", object_pose: pin.SE3 | None = None,
                cache: bool = False) -> bool:
        """The straight joint segment ``a → b`` (both ends included) certified collision-free."""
        return self.path(np.array([a, b], dtype=float), mode, object_pose, cache)

    def path(self, Q: np.ndarray, mode: str = "held", object_pose: pin.SE3 | None = None, cache: bool = False) -> bool:
        """The piecewise-linear joint path through the rows of ``Q`` (m × nq, m ≥ 1) certified
        collision-free (every point of every chord, vertices included). ``mode``: ``"held"``
        (object held by the hands), ``"fixed"`` (object standing at ``object_pose``), ``"free"``.

        ``cache``: start from what an earlier certified path left at this path's first vertex (a
        lower bound on each group's clearance there: the clearance where the group was last
        evaluated minus its motion bound to the vertex), and leave the same at its last vertex.
        A planner that certifies edge after edge from its tree's nodes then evaluates every group
        at a vertex once instead of once per edge; same certificate (every bound used is a valid
        lower bound), the distances are only evaluated at other points. The floor's exception for
        ends closer than ``min_clearance`` is applied only to paths rejected without it (same
        certificate: see :meth:`_path_cached`)."""
        Q = np.asarray(Q, dtype=float)
        if Q.ndim != 2 or Q.shape[0] < 1 or Q.shape[1] != self.model.nq:
            raise ValueError(f"path: expected an (m >= 1) × {self.model.nq} array of configurations, got shape {Q.shape}")
        if not np.all(np.isfinite(Q)):
            raise ValueError("path: configurations must be finite")
        mode = self._mode(mode)
        if mode == "fixed" and object_pose is None:
            raise ValueError("path: mode 'fixed' needs object_pose")
        G = len(self.groups(mode))
        self.n_paths += 1
        if G == 0:
            return True
        if cache:
            return self._path_cached(Q, mode, object_pose, G)
        X = np.repeat(Q[:1], G, axis=0)                    # where each group was evaluated
        exact = np.ones(G, dtype=bool)                     # D exact at X (else a lower bound)
        D = self._distances(mode, np.arange(G), Q[0], object_pose)
        # the floor: min_clearance, or half an end's own clearance when an end is closer than twice
        # that (start) or than that (end) (else no edge could leave a start or reach a goal that is
        # valid but nearly in contact)
        d0 = float(D.min())
        if d0 <= 0.0:
            return False
        floor = min(self.min_clearance, 0.5 * d0)
        if len(Q) > 1 and self._near(mode, Q[-1], object_pose):
            d1 = float(self._distances(mode, np.arange(G), Q[-1], object_pose).min())
            if d1 <= 0.0:
                return False
            floor = min(floor, 0.5 * d1)
        st = {"X": X, "D": D, "exact": exact, "floor": floor, "profile": len(Q) == 2}   # the profile pays off on long straight edges
        return self._run(Q, 0, len(Q) - 1, mode, object_pose, st)

    def _path_cached(self, Q: np.ndarray, mode: str, object_pose: pin.SE3 | None, G: int) -> bool:
        """:meth:`path` with the vertex cache. The ends' own clearances (the floor's exception) are
        looked at only when the path is rejected at the plain floor: a path certified at the higher
        floor is certified at a lower one too; a rejected one is certified again from scratch at the
        floor its ends allow, when that is lower."""
        key0 = self._key(mode, Q[0], object_pose)
        hit = self._vertex.get(key0)
        d0: float | None = None
        if hit is not None:
            self.n_cache_hits += 1
            D, exact = hit.copy(), np.zeros(G, dtype=bool)
        else:
            D, exact = self._distances(mode, np.arange(G), Q[0], object_pose), np.ones(G, dtype=bool)
            d0 = float(D.min())
            if d0 <= 0.0:
                return False
            self._remember(key0, D.copy())
        floor = self.min_clearance if d0 is None else min(self.min_clearance, 0.5 * d0)
        st = {"X": np.repeat(Q[:1], G, axis=0), "D": D, "exact": exact, "floor": floor, "profile": len(Q) == 2}
        ok = self._certify(Q, mode, object_pose, st)
        if not ok and len(Q) > 1:
            D0 = self._distances(mode, np.arange(G), Q[0], object_pose)
            d0 = float(D0.min())
            d1 = float(self._distances(mode, np.arange(G), Q[-1], object_pose).min())
            low = min(self.min_clearance, 0.5 * d0, 0.5 * d1 if d1 < self.min_clearance else np.inf)
            if d0 > 0.0 and d1 > 0.0 and low < floor:
                st = {"X": np.repeat(Q[:1], G, axis=0), "D": D0, "exact": np.ones(G, dtype=bool), "floor": low,
                      "profile": len(Q) == 2}
                ok = self._certify(Q, mode, object_pose, st)
        if ok and len(Q) > 1:
            key1 = self._key(mode, Q[-1], object_pose)
            if key1 not in self._vertex:
                self._remember(key1, st["D"] - np.einsum("gj,gj->g", self._Wg[self._state(mode)], np.abs(Q[-1] - st["X"])))
        return ok

    def _certify(self, Q: np.ndarray, mode: str, object_pose: pin.SE3 | None, st: dict[str, Any]) -> bool:
        if len(Q) == 2:      # one chord: advance along it at once
            return self._chord(Q[0], Q[1], mode, object_pose, st)
        return self._run(Q, 0, len(Q) - 1, mode, object_pose, st)

    def _near(self, mode: str, x: np.ndarray, object_pose: pin.SE3 | None, factor: float = 1.0) -> bool:
        """Some active pair closer than ``factor · min_clearance`` (+ margin) at x (boolean checks with
        a security margin: cheaper than the distances)."""
        gd = self._margin_data(mode, 0.0, factor)
        pin.updateGeometryPlacements(self.model, self.data, self.gmodel, gd, x)
        if mode == "fixed":
            gd.oMg[self.checker.fixed_id] = object_pose
        return bool(pin.computeCollisions(self.gmodel, gd, True))

    # ------------------------------------------------------------------ advancement
    def _uncovered(self, mode: str, V: np.ndarray, st: dict[str, Any]) -> np.ndarray:
        """Groups not certified on every chord through the vertices V (k × nq)."""
        M = np.abs(V[None, :, :] - st["X"][:, None, :]).max(axis=1)           # G × nq
        bound = np.einsum("gj,gj->g", self._Wg[self._state(mode)], M)
        return np.flatnonzero(st["D"] - bound < 0.5 * st["floor"])

    def _evaluate(self, mode: str, gs: np.ndarray, x: np.ndarray, object_pose: pin.SE3 | None, st: dict[str, Any]) -> bool:
        d = self._distances(mode, gs, x, object_pose)
        st["D"][gs] = d
        st["X"][gs] = x
        st["exact"][gs] = True
        return bool(d.min() >= st["floor"])

    def _run(self, Q: np.ndarray, i: int, j: int, mode: str, object_pose: pin.SE3 | None, st: dict[str, Any]) -> bool:
        if i == j:
            return True
        bad = self._uncovered(mode, Q[i:j + 1], st)
        if bad.size == 0:
            return True
        stale = bad[np.any(st["X"][bad] != Q[i], axis=1) | ~st["exact"][bad]]
        if stale.size:
            if not self._evaluate(mode, stale, Q[i], object_pose, st):
                return False
            bad = self._uncovered(mode, Q[i:j + 1], st)
            if bad.size == 0:
                return True
        if j - i == 1:
            return self._chord(Q[i], Q[j], mode, object_pose, st)
        m = (i + j) // 2
        return self._run(Q, i, m, mode, object_pose, st) and self._run(Q, m, j, mode, object_pose, st)

    def _chord(self, u: np.ndarray, v: np.ndarray, mode: str, object_pose: pin.SE3 | None, st: dict[str, Any]) -> bool:
        """Advance along the chord ``q(s) = u + s (v − u)``, ``s ∈ [0, 1]``. Each group is certified
        up to ``reach[G]``; the group(s) with the smallest reach are re-evaluated there and reach as
        far as the larger of two valid bounds on the distance lost allows: the static one
        ``w_G·|v − u|`` per unit s, and (straight segments longer than a few checks) the compiled
        Jacobian speed profile ``C(s)`` of :meth:`ValidityChecker.edge_checkpoints` (bound on the
        travel of any point of any geometry), times 2 for groups with pairs of two moving
        geometries; the profile only for straight segments (a path's short chords do not repay
        its compiled call)."""
        Wg = self._Wg[self._state(mode)]
        half = 0.5 * st["floor"]
        rate = Wg @ np.abs(v - u)                                # [m] per unit s, per group
        K = self._profile(mode, u, v, rate, st["profile"])
        reach = np.zeros(len(rate))
        # groups evaluated elsewhere and still certified on the whole chord
        M = np.maximum(np.abs(u - st["X"]), np.abs(v - st["X"]))
        reach[st["D"] - np.einsum("gj,gj->g", Wg, M) >= half] = np.inf
        at_u = np.flatnonzero(np.all(st["X"] == u, axis=1) & ~np.isinf(reach))
        reach[at_u] = self._reach(0.0, at_u, st["D"][at_u], rate[at_u], half, K)
        D, X, exact, floor, dq = st["D"], st["X"], st["exact"], st["floor"], v - u
        Kl = None if K is None else K.tolist()
        while True:
            g = int(reach.argmin())
            s = float(reach[g])
            if s >= 1.0:
                return True
            x = u + s * dq
            if np.count_nonzero(reach <= s) > 1:
                gs = np.flatnonzero(reach <= s)
                if not self._evaluate(mode, gs, x, object_pose, st):
                    return False
                reach[gs] = self._reach(s, gs, D[gs], rate[gs], half, K)
                continue
            # one group (the usual case): the same steps on scalars (numpy's per-call overhead is most
            # of a step's cost otherwise)
            d = self._distance1(mode, g, x, object_pose)
            D[g], X[g], exact[g] = d, x, True
            if d < floor:
                return False
            budget = d - half
            r = float(rate[g])
            out = s + budget / r if r > 0.0 else math.inf
            if Kl is not None:
                Kg = Kl[g]
                out = max(out, _inverse_travel(Kg, _travel(Kg, s) + budget))
            reach[g] = max(out, s + 1e-12)

    @staticmethod
    def _reach(s: float, gs: np.ndarray, d: np.ndarray, rate: np.ndarray, half: float, K: np.ndarray | None) -> np.ndarray:
        """How far (in s) the groups ``gs`` evaluated at s with clearances d stay certified: the larger
        of the static bound's and the per-group travel bound's (``K``, :meth:`_profile`) reach."""
        budget = d - half                                           # > 0 after a passed evaluation
        out = np.full_like(budget, np.inf)
        np.divide(budget, rate, out=out, where=rate > 0.0)
        out += s
        if K is not None and gs.size:
            Kg = K[gs]
            m = Kg.shape[1] - 1
            t = s * m
            i = min(int(t), m - 1)
            c = Kg[:, i] + (t - i) * (Kg[:, i + 1] - Kg[:, i]) + budget      # travel allowed up to here
            j = np.count_nonzero(Kg <= c[:, None], axis=1)                  # Kg[:, j-1] <= c < Kg[:, j]
            inside = (j <= m) & (j >= 1)   # j = 0: a cached lower bound below the floor (budget < 0), no reach
            jj, rows = j[inside], np.flatnonzero(inside)
            lo, hi = Kg[rows, jj - 1], Kg[rows, jj]
            sk = np.full_like(budget, np.inf)
            sk[inside] = (jj - 1 + (c[inside] - lo) / (hi - lo)) / m
            sk[j == 0] = s
            out = np.maximum(out, sk)
        # progress of at least min_clearance / 2 of travel per step, so never stuck
        return np.maximum(out, s + 1e-12)

    def _profile(self, mode: str, u: np.ndarray, v: np.ndarray, rate: np.ndarray, st_profile: bool) -> np.ndarray | None:
        """Per group, the cumulative bound ``K[G, i]`` [m] on how much any pair of the group can
        approach between s = 0 and s = i/m on the chord u → v (m = :attr:`ValidityChecker.CELLS`):
        the integral over the cells of the largest, over the group's pairs, sum of the two geometries'
        speed bounds (the compiled per-geometry cell speeds of
        :meth:`ValidityChecker._cell_speed_function`, Jacobian at the cell ends plus a second-order
        remainder; a static geometry adds 0). None when the static bound is short anyway or the
        robot has no compiled speeds."""
        if not st_profile or rate.size == 0 or float(rate.max()) < 0.01:
            return None
        fn = self.checker._cell_speed_function(mode)
        if fn is None:
            return None
        r1, r2, rr, starts, n_rows = self._pair_rows[self._state(mode)]
        m = self.checker.CELLS
        V = np.zeros((n_rows + 1, m))                 # the last row: a static geometry's speed, 0
        V[:n_rows] = np.asarray(fn(u, v), float).reshape(n_rows, m, order="F")
        Pv = V[r1] + V[r2]                            # sum of the pair's two speeds, or their relative speed
        np.minimum(Pv, V[rr], out=Pv, where=(rr >= 0)[:, None])
        Gm = np.maximum.reduceat(Pv, starts, axis=0)
        K = np.zeros((len(starts), m + 1))
        np.cumsum(Gm, axis=1, out=K[:, 1:])
        K[:, 1:] /= m
        return K

    # ------------------------------------------------------------------ the discrete alternative
    def discrete_segment(self, a: np.ndarray, b: np.ndarray, tolerance: float, mode: str = "held",
                         object_pose: pin.SE3 | None = None) -> bool:
        """The segment ``a → b`` (ends included) checked at the checkpoints of
        :meth:`~optplan.planners.validity.ValidityChecker.edge_checkpoints` with security margins
        (module docstring): certified as well, without distances and without the broad phase."""
        if not (isinstance(tolerance, (int, float)) and math.isfinite(tolerance) and tolerance > 0):
            raise ValueError(f"tolerance: expected a positive number of metres, got {tolerance!r}")
        mode = self._mode(mode)
        if mode == "fixed" and object_pose is None:
            raise ValueError("discrete_segment: mode 'fixed' needs object_pose")
        gd = self._margin_data(mode, float(tolerance))
        a = np.asarray(a, float)
        b = np.asarray(b, float)
        ts = np.r_[0.0, self.checker.edge_checkpoints(a, b, tolerance, mode), 1.0]
        d = b - a
        fixed_id = self.checker.fixed_id
        for t in ts:
            self.n_checks += 1
            pin.updateGeometryPlacements(self.model, self.data, self.gmodel, gd, a + t * d)
            if mode == "fixed":
                gd.oMg[fixed_id] = object_pose
            if pin.computeCollisions(self.gmodel, gd, True):
                return False
        return True

    def _margin_data(self, mode: str, tol: float, factor: float = 1.0) -> Any:
        key = (self._state(mode), tol, factor)
        if key not in self._margin_gd:
            src = self.checker._gd[mode]
            gd = pin.GeometryData(self.gmodel)
            moving = np.abs(self._W).sum(axis=1) > 0
            for k, cp in enumerate(self.gmodel.collisionPairs):
                if not src.activeCollisionPairs[k]:
                    gd.deactivateCollisionPair(k)
                    continue
                both = moving[cp.first] and moving[cp.second]
                # tol = 0: the near-contact test of an end (min_clearance); else the discrete alternative
                extra = factor * self.min_clearance if tol == 0.0 else 0.5 * self.min_clearance
                gd.collisionRequests[k].security_margin = (tol if both else 0.5 * tol) + extra + self.checker.margin
            if self.checker.exact_contacts:   # as the checker's own requests (margins below 1e-6 m need it)
                exact_contact_requests(gd)
            self._margin_gd[key] = gd
        return self._margin_gd[key]


def _travel(C: list[float], s: float) -> float:
    """The cumulative travel bound ``C`` (values at ``len(C)`` equally spaced knots of [0, 1]) at ``s``,
    linearly interpolated (as ``np.interp``, on Python floats: a step of the advancement is a few
    scalar operations)."""
    m = len(C) - 1
    t = s * m
    i = min(int(t), m - 1)
    return C[i] + (t - i) * (C[i + 1] - C[i])


def _inverse_travel(C: list[float], c: float) -> float:
    """The largest ``s`` in [0, 1] with interpolated ``C(s) ≤ c`` (``C`` nondecreasing), inf beyond
    the last knot's value."""
    if c > C[-1]:
        return math.inf
    j = bisect.bisect_right(C, c)          # C[j-1] <= c < C[j]
    if j == 0:
        return 0.0
    if j >= len(C):
        return 1.0
    m = len(C) - 1
    return (j - 1 + (c - C[j - 1]) / (C[j] - C[j - 1])) / m
