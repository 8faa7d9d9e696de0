"""LCBiRRT's lazy latent trees (Park et al. 2024), the growth :class:`~.latent_planners.LCBiRRT` uses by default.

The two trees grow **in the latent space alone**: a step (``latent_step``, interpolated in the prior's CDF as Park
et al.'s) is added when the latent validity classifier accepts it, without decoding, projecting or collision-checking
it. When a connect extension of one tree reaches the other tree's new latent vector, the two branches that meet there
are **validated lazily**, from the roots outward: each unchecked node's configuration is ``project(decode(z))``,
collision-checked, and joined to its parent's configuration by the constrained local planner. A node that fails is
removed with its subtree. From the last valid node of a failed branch a **latent jump** follows: a constrained
joint-space extension of at most ``jump_steps`` steps of ``joint_step`` rad toward the other tree's nearest
verified configuration, whose nodes enter the tree with their encodings (and lead the latent tree into the
encoder's image of a new region). When both branches hold, the trees are joined where they met (the same latent
vector: the same configuration when both are decodings) or, when one end is a root or jump node, by a
constrained joint-space connect between the two configurations; a jump that reaches the other tree's
configuration joins them too. With probability ``random_growth`` per iteration a tree also takes one joint-space
step toward a uniform random configuration (Park et al.'s).

LPO (Zhang et al. 2025), as its authors' code: every ``lpo_interval``-th meeting (the first included) the two
branches are validated with the **repair** — a node whose projection holds but collides is moved by gradient
ascent on the learned distance, ``z ← z + γ ∇d(z)`` (at most ``lpo_iterations`` steps, kept at the first
collision-free projection, abandoned at the first failed projection), and an edge that fails is cut every
``collision_step`` rad and its cuts moved the same way. The other meetings are checked as LCBiRRT's. (Their LPO
code also turns the latent jump off; here it stays on, without it no start tree grows on our scenes.)

Where the classifier scores a verified node (a root, a jump node, a validated node) below the threshold it is
known to be wrong there (``classifier_trusts_verified``): a step out of such a node is then not refused but
validated at once (without the repair), so that a tree can leave a start the classifier calls invalid.

Counters (``stats``): ``latent_nodes`` added, ``meetings`` and ``validations`` of branches and
``validation_failures`` with their reason (``projection_failures``, ``collisions``, ``edge_failures``),
``validated_nodes`` / ``validated_valid`` (how often a decoded node near the trees' frontier is valid),
``removed_nodes``, ``latent_jumps`` and the jump nodes, ``random_growths``; LPO: ``lpo_checks`` (meetings checked
with the repair), ``lpo_nodes`` / ``lpo_moves`` (repairs tried / kept), ``lpo_edges`` / ``lpo_edge_moves``.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.special import ndtr, ndtri

from ..base import Deadline
from ..manifold_samples import project_onto_chain

__all__ = ["LazyLatentTree", "plan_lazy"]

_FAR = 1e9   # the latent vector a removed node is parked at, so that it is never the nearest


class LazyLatentTree:
    """Nodes with a latent vector ``Z`` (rows of a growing array), a configuration ``Q`` (None until the node is
    validated), ``checked`` (validated), ``decoded`` (``Q`` is ``project(decode(Z))``; false for a root or jump
    node, whose ``Z`` is its configuration's encoding), ``alive``, ``parent``, ``children`` and ``edge`` (the
    projected points from the parent's configuration to the node's)."""

    def __init__(self, z: np.ndarray, q: np.ndarray, p: float, cap: int = 1024, metric: str = "linear") -> None:
        self.metric = metric   # the latent distance: "linear" (Euclidean in z) or "cdf" (Euclidean in Φ(z))
        self._Z = np.full((cap, len(z)), _FAR)
        self._Z[0] = z
        self._M = np.full((cap, len(z)), _FAR)   # the nodes in the metric's coordinates
        self._M[0] = self.coords(z)
        self.n = 1
        self.Q: list[np.ndarray | None] = [q]
        self.P = [p]
        self.checked = [True]
        self.decoded = [False]
        self.alive = [True]
        self.parent = [-1]
        self.children: list[list[int]] = [[]]
        self.edge: list[list[np.ndarray]] = [[]]
        self.verified = [0]   # indices of the alive, checked nodes
        self.added = 0

    @property
    def Z(self) -> np.ndarray:
        return self._Z[:self.n]

    def coords(self, z: np.ndarray) -> np.ndarray:
        """``z`` in the coordinates of the tree's latent metric (``z`` itself, or ``Φ(z)`` for ``"cdf"``)."""
        return np.asarray(ndtr(z), dtype=float) if self.metric == "cdf" else z

    def distance(self, i: int, z: np.ndarray) -> float:
        """The latent distance from node ``i`` to ``z`` [latent units, or prior-CDF units for ``"cdf"``]."""
        return float(np.linalg.norm(self.coords(z) - self._M[i]))

    def _append(self, z: np.ndarray, q: np.ndarray | None, p: float, parent: int, edge: list[np.ndarray],
                checked: bool, decoded: bool) -> int:
        if self.n == len(self._Z):
            self._Z = np.concatenate([self._Z, np.full_like(self._Z, _FAR)])
            self._M = np.concatenate([self._M, np.full_like(self._M, _FAR)])
        i = self.n
        self._Z[i] = z
        self._M[i] = self.coords(z)
        self.n += 1
        self.Q.append(q)
        self.P.append(p)
        self.checked.append(checked)
        self.decoded.append(decoded)
        self.alive.append(True)
        self.parent.append(parent)
        self.children.append([])
        self.children[parent].append(i)
        self.edge.append(edge)
        if checked:
            self.verified.append(i)
        self.added += 1
        return i

    def add_latent(self, z: np.ndarray, p: float, parent: int) -> int:
        """An unchecked latent node."""
        return self._append(z, None, p, parent, [], False, True)

    def add(self, z: np.ndarray, q: np.ndarray, p: float, parent: int, edge: list[np.ndarray],
            decoded: bool = True) -> int:
        """A verified node (the interface of :meth:`~.latent_planners.LCBiRRT.connect_q`)."""
        return self._append(z, q, p, parent, edge, True, decoded)

    def set_valid(self, i: int, z: np.ndarray, q: np.ndarray, edge: list[np.ndarray], p: float) -> None:
        self._Z[i] = z
        self._M[i] = self.coords(z)
        self.Q[i], self.edge[i], self.P[i], self.checked[i], self.decoded[i] = q, edge, p, True, True
        self.verified.append(i)

    def remove(self, i: int) -> int:
        """Remove node ``i`` and its subtree; the number of nodes removed."""
        stack, count = [i], 0
        while stack:
            k = stack.pop()
            if not self.alive[k]:
                continue
            self.alive[k] = False
            self._Z[k] = _FAR
            self._M[k] = _FAR
            stack.extend(self.children[k])
            count += 1
        par = self.parent[i]
        self.children[par] = [c for c in self.children[par] if c != i]
        if any(not self.alive[k] for k in self.verified):
            self.verified = [k for k in self.verified if self.alive[k]]
        return count

    def size(self) -> int:
        return sum(self.alive)

    def nearest(self, z: np.ndarray) -> int:
        """The node nearest to ``z`` in the tree's latent metric."""
        d = self._M[:self.n] - self.coords(z)
        return int(np.argmin(np.einsum("ij,ij->i", d, d)))

    def nearest_q(self, q: np.ndarray) -> tuple[int, float]:
        """The verified node nearest to ``q`` in joint space and its distance [rad]."""
        Q = np.asarray([self.Q[k] for k in self.verified])
        d = np.linalg.norm(Q - q, axis=1)
        j = int(np.argmin(d))
        return self.verified[j], float(d[j])

    def path_to(self, i: int) -> list[int]:
        out = []
        while i >= 0:
            out.append(i)
            i = self.parent[i]
        return out[::-1]

    def branch(self, i: int) -> list[np.ndarray]:
        """Configurations from the root to the verified node ``i``, edge points included."""
        out: list[np.ndarray] = []
        while i >= 0:
            q = self.Q[i]
            assert q is not None
            out[:0] = [*self.edge[i], q]
            i = self.parent[i]
        return out


def _repair(pl: Any, z: np.ndarray, st: dict[str, Any]) -> tuple[np.ndarray, np.ndarray] | None:
    """LPO's node repair (the LPO authors' ``node_dis``): gradient ascent on the learned distance from ``z``,
    ``z ← z + γ ∇d(z)``, at most ``lpo_iterations`` steps; kept at the first step whose projected decoding is
    collision-free, abandoned at the first step whose projection fails. ``(z, q)`` or None."""
    o = pl.options
    st["lpo_nodes"] += 1
    for _ in range(o.lpo_iterations):
        _, grad = pl.distance.value_and_gradient(z)
        z = z + o.lpo_gamma * grad
        failed = st["projection_failures"]
        q = pl._config(z, z, z, st)
        if q is not None:
            st["lpo_moves"] += 1
            return z, q
        if st["projection_failures"] > failed:
            return None
    return None


def _repair_edge(pl: Any, q_par: np.ndarray, q: np.ndarray, st: dict[str, Any], deadline: Deadline,
                 ) -> list[np.ndarray] | None:
    """LPO's repair of an edge that failed its check (the LPO authors' whole-path check): the segment is cut every
    ``collision_step`` rad, each cut projected, its encoding moved by :func:`_repair`, and the pieces between the
    moved configurations checked by the constrained local planner; the edge points (moved configurations included)
    or None."""
    o = pl.options
    lo, hi = pl.robot.lower, pl.robot.upper
    st["lpo_edges"] += 1
    n = max(1, int(float(np.linalg.norm(q - q_par)) / o.collision_step))
    pts = [q_par]
    for j in range(n):
        x = project_onto_chain(pl.kin, q_par + (j + 1) / (n + 1) * (q - q_par), lo, hi, o.tolerance)
        if x is None:
            return None
        moved = _repair(pl, pl.cvae.encode(x), st)
        if moved is None:
            return None
        pts.append(moved[1])
    pts.append(q)
    out: list[np.ndarray] = []
    for a, b in zip(pts[:-1], pts[1:]):
        if deadline.expired():
            return None
        e = pl._edge(a, b, st, deadline)
        if e is None:
            return None
        out += [*e, b]
    st["lpo_edge_moves"] += 1
    return out[:-1]


def _check_node(pl: Any, z: np.ndarray, q_par: np.ndarray, st: dict[str, Any], deadline: Deadline,
                repair: bool = False) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]] | None:
    """A node's real check: ``project(decode(z))`` valid and joined to ``q_par`` by the constrained local planner.
    With ``repair`` (LPO's whole-path check): a node whose projection holds but collides is moved by
    :func:`_repair`, and an edge that fails is repaired by :func:`_repair_edge`; a failed projection is not
    repaired (as the LPO authors'). ``(z, q, edge points)`` or None."""
    st["validated_nodes"] += 1
    failed = st["projection_failures"]
    q = pl._config(z, z, z, st)
    if q is None and repair and st["projection_failures"] == failed:
        moved = _repair(pl, z, st)
        if moved is not None:
            z, q = moved
    edge = None
    if q is not None:
        edge = pl._edge(q_par, q, st, deadline)
        if edge is None:
            st["edge_failures"] += 1
            if repair:
                edge = _repair_edge(pl, q_par, q, st, deadline)
    if edge is None or q is None:
        st["validation_failures"] += 1
        return None
    st["validated_valid"] += 1
    return z, q, edge


def _validate(pl: Any, tree: LazyLatentTree, i: int, st: dict[str, Any], deadline: Deadline,
              repair: bool = False) -> tuple[bool, int]:
    """Validate the branch from the root to node ``i`` (with ``repair``: LPO's whole-path check, :func:`_check_node`);
    ``(True, i)`` or ``(False, last valid node)`` after removing the first node that fails (and its subtree)."""
    st["validations"] += 1
    path = tree.path_to(i)
    for k in path[1:]:
        if tree.checked[k]:
            continue
        if deadline.expired():
            return False, tree.parent[k]
        par = tree.parent[k]
        q_par = tree.Q[par]
        assert q_par is not None
        got = _check_node(pl, tree.Z[k].copy(), q_par, st, deadline, repair)
        if got is None:
            st["removed_nodes"] += tree.remove(k)
            return False, par
        z, q, edge = got
        tree.set_valid(k, z, q, edge, float(pl.classifier.probability(z)))
    return True, i


def _toward(z_from: np.ndarray, z_to: np.ndarray, ratio: float, how: str) -> np.ndarray:
    """The latent vector ``ratio`` of the way from ``z_from`` to ``z_to``: on the straight line (``"linear"``) or,
    as Park et al.'s, on the straight line between the two vectors' images under the prior's CDF, mapped back
    (``"cdf"``: each coordinate ``Φ⁻¹((1 − ratio) Φ(a) + ratio Φ(b))``, so that a step covers equal prior mass)."""
    if how == "linear":
        return z_from + ratio * (z_to - z_from)
    return np.asarray(ndtri((1.0 - ratio) * ndtr(z_from) + ratio * ndtr(z_to)), dtype=float)


def _grow(pl: Any, tree: LazyLatentTree, z_target: np.ndarray, other: LazyLatentTree, st: dict[str, Any],
          deadline: Deadline, rng: np.random.Generator) -> tuple[str, int, tuple[int, int, list[np.ndarray]] | None]:
    """One latent step of ``tree`` from its nearest node toward ``z_target``: ``("reached" | "advanced" |
    "trapped", node, join)``; join (with ``other``, as :func:`_jump`'s) only when a step validated at once failed
    and the latent jump that follows reached ``other``."""
    o = pl.options
    i = tree.nearest(z_target)
    dist = tree.distance(i, z_target)
    if dist < 1e-12:
        return "reached", i, None
    reached = dist <= o.latent_step
    z = z_target.copy() if reached else _toward(tree.Z[i], z_target, o.latent_step / dist, o.latent_interpolation)
    p = float(pl.classifier.probability(z))
    if p < o.classifier_threshold:
        if not (o.classifier_trusts_verified and tree.checked[i] and tree.P[i] < o.classifier_threshold):
            st["classifier_rejects"] += 1
            return "trapped", i, None
        # the classifier is wrong around this verified node: the real checks decide, now
        st["classifier_overruled"] += 1
        q_par = tree.Q[i]
        assert q_par is not None
        got = _check_node(pl, z, q_par, st, deadline)
        if got is None:   # a failed validation: the latent jump follows
            return "trapped", i, _jump(pl, tree, i, other, st, deadline, rng)
        z, q, edge = got
        j = tree.add(z, q, float(pl.classifier.probability(z)), i, edge, decoded=True)
    else:
        j = tree.add_latent(z, p, i)
    st["latent_nodes"] += 1
    return ("reached" if reached else "advanced"), j, None


def _jump(pl: Any, ta: LazyLatentTree, i: int, tb: LazyLatentTree, st: dict[str, Any], deadline: Deadline,
          rng: np.random.Generator) -> tuple[int, int, list[np.ndarray]] | None:
    """Latent jump from ``ta``'s verified node ``i`` toward ``tb``'s nearest verified configuration; the join
    ``(last node of ta, node of tb, edge points)`` when it arrives. A jump trapped at its first step is followed by
    one step toward a uniform random configuration (as Park et al.'s)."""
    q_i = ta.Q[i]
    assert q_i is not None
    j, _ = tb.nearest_q(q_i)
    q_j = tb.Q[j]
    assert q_j is not None
    st["latent_jumps"] += 1
    n0 = ta.n
    edge, last = pl.connect_q(ta, i, q_j, st, deadline, max_steps=pl.options.jump_steps)
    if edge is not None:
        st["link_successes"] += 1
        return last, j, edge
    if ta.n == n0 and not deadline.expired():
        st["random_jumps"] += 1
        pl.connect_q(ta, i, rng.uniform(pl.robot.lower, pl.robot.upper), st, deadline, max_steps=1)
    return None


def _join(pl: Any, ta: LazyLatentTree, ia: int, tb: LazyLatentTree, ib: int, st: dict[str, Any],
          deadline: Deadline, rng: np.random.Generator) -> tuple[int, int, list[np.ndarray]] | None:
    """Validate the two branches that met in the latent space and join them (module docstring); with LPO, every
    ``lpo_interval``-th meeting (the first included) validates them with the repair (:func:`_check_node`)."""
    repair = pl.distance is not None and st["meetings"] % pl.options.lpo_interval == 0
    st["meetings"] += 1
    st["lpo_checks"] += repair
    ok, last = _validate(pl, ta, ia, st, deadline, repair)
    if not ok:
        return _jump(pl, ta, last, tb, st, deadline, rng)
    ok, last = _validate(pl, tb, ib, st, deadline, repair)
    if not ok:
        found = _jump(pl, tb, last, ta, st, deadline, rng)
        return None if found is None else (found[1], found[0], found[2][::-1])
    qa, qb = ta.Q[ia], tb.Q[ib]
    assert qa is not None and qb is not None
    st["link_attempts"] += 1
    gap = float(np.linalg.norm(qa - qb))
    st["link_gap_min"] = min(st["link_gap_min"], gap)
    if gap < 1e-12:
        st["link_successes"] += 1
        return ia, ib, []
    edge, j = pl.connect_q(tb, ib, qa, st, deadline)
    if edge is None:
        return None
    st["link_successes"] += 1
    return ia, j, edge[::-1]


def _sample(pl: Any, rng: np.random.Generator, st: dict[str, Any]) -> np.ndarray:
    """A latent sample the classifier accepts (at most 20 draws of ``N(0, σ²)``; the last otherwise)."""
    o = pl.options
    z = rng.normal(0.0, o.sample_sigma, pl.cvae.latent_dim)
    for _ in range(19):
        if float(pl.classifier.probability(z)) >= o.classifier_threshold:
            break
        st["sample_rejects"] += 1
        z = rng.normal(0.0, o.sample_sigma, pl.cvae.latent_dim)
    return z


def plan_lazy(pl: Any, q_start: np.ndarray, q_goal: np.ndarray, deadline: Deadline, rng: np.random.Generator,
              st: dict[str, Any]) -> tuple[LazyLatentTree, LazyLatentTree, bool, tuple[int, int, list[np.ndarray]] | None]:
    """The lazy LCBiRRT search of planner ``pl`` (an :class:`~.latent_planners.LCBiRRT`); ``(tree a, tree b,
    a is the start tree, join or None)`` with the join as in :meth:`~.latent_planners.LCBiRRT._link`."""
    o = pl.options
    for key in ("latent_nodes", "validations", "validation_failures", "validated_nodes", "validated_valid",
                "edge_failures", "removed_nodes", "sample_rejects", "random_jumps", "meetings", "lpo_checks",
                "lpo_edges", "lpo_edge_moves", "random_growths"):
        st[key] = 0
    roots = []
    for q in (q_start, q_goal):
        z = pl.cvae.encode(q)
        roots.append(LazyLatentTree(z, q, float(pl.classifier.probability(z)), metric=o.latent_interpolation))
    ta, tb = roots
    st["start_root_probability"], st["goal_root_probability"] = ta.P[0], tb.P[0]
    a_is_start, found = True, None
    while not deadline.expired():
        if o.max_iterations and st["iterations"] >= o.max_iterations:
            break
        st["iterations"] += 1
        status, ia, found = _grow(pl, ta, _sample(pl, rng, st), tb, st, deadline, rng)
        if found is not None:
            break
        if status != "trapped":
            target = ta.Z[ia].copy()
            status = "advanced"
            while status == "advanced" and not deadline.expired():
                status, ib, jumped = _grow(pl, tb, target, ta, st, deadline, rng)
                if jumped is not None:   # tb's jump reached ta: as (ta node, tb node, points from ta to tb)
                    found = (jumped[1], jumped[0], jumped[2][::-1])
            if found is not None:
                break
            if status == "reached":
                found = _join(pl, ta, ia, tb, ib, st, deadline, rng)
                if found is not None:
                    break
        if o.random_growth > 0 and rng.random() < o.random_growth and not deadline.expired():
            # Park et al.'s occasional joint-space growth: one step from the nearest verified node toward a uniform
            # random configuration
            st["random_growths"] += 1
            q_rand = rng.uniform(pl.robot.lower, pl.robot.upper)
            pl.connect_q(ta, ta.nearest_q(q_rand)[0], q_rand, st, deadline, max_steps=1)
        ta, tb, a_is_start = tb, ta, not a_is_start
    if not math.isfinite(st["link_gap_min"]):
        st["link_gap_min"] = None
    return ta, tb, a_is_start, found
