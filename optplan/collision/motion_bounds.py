"""Lower bounds on pair distances from how far geometries can have moved, for a robot on a
free-flyer root (``q[:7]`` = base position, quaternion x y z w, then 1-dof joints), and the
dense "every pair below a threshold" query built on them.

The bound (:func:`pair_motion`): between two configurations ``r`` and ``x`` no point of a robot
geometry ``g`` moves, relative to the base, farther than ``W[g, 6:] @ |x_j − r_j|`` (the joints'
sweep weights, :func:`optplan.collision.sweep.sweep_weights`: valid between ANY two
configurations). In the world it moves in addition at most ``|Δp| + ρ_g θ`` (``Δp`` the base
translation, ``θ`` the base rotation angle between the two attitudes, ``ρ_g = W[g, 0]`` the
farthest point of ``g`` from the base origin: ``|(R_x − R_r) v| ≤ θ |v|``). A pair's distance is
1-Lipschitz in the displacement of each of its two geometries, so it changes by at most the sum
of the two displacements; two geometries on the robot move together with the base, which does
not change their distance, so for them only the joints' part counts. Geometries fixed to the
world do not move (zero rows of ``W``).
"""
from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

__all__ = ["floating_distance_bounds_below", "pair_motion"]


def pair_motion(W: np.ndarray, pa: np.ndarray, pb: np.ndarray, on_robot: np.ndarray, R: np.ndarray,
                X: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """(pairs × segments) How much each pair's distance can change [m] between row ``R[i]`` and
    row ``X[i]`` (configurations of a free-flyer root, row-matched, n × nq), the largest over the
    rows of each segment (``seg``: the first row of each segment, increasing, ``seg[0] = 0``): the
    module docstring's bound with the largest joint change, base translation and base rotation
    angle of the segment. ``W`` the sweep weights (geometries × nv), ``pa``/``pb`` the two
    geometries of each pair, ``on_robot`` per geometry: attached to the robot (not the world)."""
    dj = np.maximum.reduceat(np.abs(X[:, 7:] - R[:, 7:]), seg, axis=0)             # segments × joints
    dp = np.maximum.reduceat(np.linalg.norm(X[:, :3] - R[:, :3], axis=1), seg)
    a = R[:, 3:7] / np.linalg.norm(R[:, 3:7], axis=1)[:, None]
    b = X[:, 3:7] / np.linalg.norm(X[:, 3:7], axis=1)[:, None]
    ax, ay, az, aw = a.T
    bx, by, bz, bw = b.T
    # the rotation angle 2 atan2(|vec(r)|, |w(r)|) of r = a⁻¹ ⊗ b (stable at small angles)
    vx = aw * bx - ax * bw - ay * bz + az * by
    vy = aw * by + ax * bz - ay * bw - az * bx
    vz = aw * bz - ax * by + ay * bx - az * bw
    w = aw * bw + ax * bx + ay * by + az * bz
    th = np.maximum.reduceat(2.0 * np.arctan2(np.sqrt(vx * vx + vy * vy + vz * vz), np.abs(w)), seg)
    m = W[:, 6:] @ dj.T                                                             # geometries × segments
    base = on_robot[:, None] * (dp[None, :] + W[:, :1] * th[None, :])
    mixed = (on_robot[pa] != on_robot[pb])[:, None]
    return m[pa] + m[pb] + mixed * (base[pa] + base[pb])


def floating_distance_bounds_below(chk: Any, Q: np.ndarray, thr: float, every: int, previous: Any = None
                                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Any]:
    """:meth:`CollisionChecker.distance_bounds_below` for a free-flyer root: every (row, pair) of
    ``Q`` (M × nq) whose exact distance is below ``thr`` [m] — the same entries as all distances
    at every row, with fewer coal calls — and ``(Q, lower)`` (``lower``: pairs × rows [m], a lower
    bound on every pair's distance at every row, exact where computed) for a later call.

    Without ``previous``: all pair distances at every ``every``-th row and the last (anchors);
    between two anchors a pair's distance at any row is at least the larger of (its distance at
    an anchor minus :func:`pair_motion` from that anchor over the segment), and only the entries
    whose bound is below ``thr`` are computed. With ``previous = (Q0, L0)`` of an earlier call on
    as many rows: a pair's distance at row i is at least ``L0[pair, i]`` minus
    :func:`pair_motion` from ``Q0[i]`` to ``Q[i]``; only the entries below ``thr`` are computed.
    Every entry left out is bounded at or above ``thr``."""
    W, pa, pb = chk._sweep_data()
    on = chk._on_robot_mask()
    M, P = len(Q), len(chk.pairs)
    rows: list[int] = []
    pairs: list[int] = []
    dist: list[float] = []
    fresh = previous is None or previous[0].shape != Q.shape
    A, D = np.zeros(0, int), np.zeros((0, P))
    if not fresh:
        Q0, L0 = previous
        lower = L0 - pair_motion(W, pa, pb, on, Q0, Q, np.arange(M))
    else:
        anchors = list(range(0, M, every))
        if anchors[-1] != M - 1:
            anchors.append(M - 1)
        A = np.asarray(anchors)
        D = np.array([chk.distances(Q[i]) for i in anchors])          # anchors × pairs
        lower = np.empty((P, M))
        lower[:, A] = D.T
        inner = np.setdiff1d(np.arange(M), A, assume_unique=True)
        if len(inner):
            left = np.searchsorted(A, inner, side="right") - 1        # each inner row's left anchor
            segs, seg = np.unique(left, return_index=True)
            seg_low = np.maximum(D[segs].T - pair_motion(W, pa, pb, on, Q[A[left]], Q[inner], seg),
                                 D[segs + 1].T - pair_motion(W, pa, pb, on, Q[A[left + 1]], Q[inner], seg))
            lower[:, inner] = seg_low[:, np.searchsorted(segs, left)]
        ra, pr = np.nonzero(D < thr)
        rows, pairs, dist = A[ra].tolist(), pr.tolist(), D[ra, pr].tolist()
        lower[:, A] = np.inf          # done: no coal call below
    model, data, gm, gd = chk.model, chk.data, chk._cgm, chk._cgd
    todo = lower < thr
    for i in np.nonzero(todo.any(axis=0))[0].tolist():
        pin.updateGeometryPlacements(model, data, gm, gd, Q[i])
        for p in np.nonzero(todo[:, i])[0].tolist():
            d = pin.computeDistance(gm, gd, p).min_distance
            lower[p, i] = d
            if d < thr:
                rows.append(i)
                pairs.append(p)
                dist.append(d)
    if fresh:
        lower[:, A] = D.T             # exact at the anchors
    r_, p_, d_ = np.asarray(rows, int), np.asarray(pairs, int), np.asarray(dist, float)
    order = np.lexsort((p_, r_))
    return r_[order], p_[order], d_[order], (Q.copy(), lower)
