"""Frontier grafts for TCBiRRT: re-grasp the arms at a tree's frontier into a configuration from which the
tree can move on toward the other tree.

Why. A constrained extension keeps each arm on its IK branch and, for a redundant (7-joint) arm, close to
its self-motion position: PathInverseKinematics seeds every pose with the previous solution, and a restart
may move a joint by at most ``max_joint_step``. Where the arms, not the object, block a passage (the truss:
the elbows hit the beams beside the bay the module passes through), both trees stop at the passage
on either side, each with arms in a position that collides one step further on. A branch graft
(:meth:`.TCBiRRT._graft`) grows another IK solution at a node, but accepts any valid one: it is mostly
one that collides one step further too.

What. Every ``frontier_interval`` iterations (after ``graft_after``) one tree takes the node nearest the
other tree (the closest of ``frontier_pairs`` random pairs: a node of the other tree and its nearest
node in this tree) and the other tree's node's pose as the direction. At the node's object pose it solves
IK from random seeds (``frontier_seeds``); a solution — or the node's configuration with one arm moved to
that solution (one arm re-grasps only) — is kept only when it is valid AND a constrained extension from
it one step (``step_size``) toward the other tree's node passes (PathInverseKinematics, every waypoint
and edge checked as in the search). Only then are the arms re-grasped to it (the regrasp of Section 4.3:
one arm at a time, an RRTConnect in the arm's joint space, the object fixed; ``graft_time_limit``); the
solution becomes a graft node (another branch of the tree at the same pose) and the step's end a node
below it, which the search then tries to connect to the other tree.

The same look-ahead graft (:func:`lookahead_graft`) serves ``trap_grafts``: there the node is one whose
extensions have been trapped ``trap_graft_count`` times, and the step goes toward ``trap_graft_target``
(:func:`trap_lookahead`; with ``trap_graft_stream="own"`` from the tree's own random streams).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, cast

import numpy as np

from .task_space import interpolate_task, pose_from_xi

if TYPE_CHECKING:   # the planner and its tree; imported only for the type checker (tcbirrt imports this module)
    from .base import Deadline
    from .kernel.extend import NativeExtender
    from .tcbirrt import TCBiRRT, _TaskTree

__all__ = ["closest_pair", "frontier_graft", "lookahead_graft", "trap_lookahead"]


def closest_pair(tree: _TaskTree, other: _TaskTree, rng: np.random.Generator, pairs: int) -> tuple[int, int]:
    """The closest in ξ of ``pairs`` pairs (a random live node j of ``other``, the node i of ``tree``
    nearest it): ``(i, j)``. A tournament: biased toward where the trees come closest, not always the same pair."""
    live = np.flatnonzero(other.alive[:other.n]) if other.alive is not None else np.arange(other.n)
    best, out = np.inf, (0, 0)
    for j in live[rng.integers(live.size, size=pairs)]:
        i = tree.nearest(other.xi[int(j)])
        d = float(np.linalg.norm(tree.xi[i] - other.xi[int(j)]))
        if d < best:
            best, out = d, (int(i), int(j))
    return out


def frontier_graft(pl: TCBiRRT, tree: _TaskTree, other: _TaskTree, deadline: Deadline, st: dict[str, Any]) -> int | None:
    """One frontier-graft attempt of ``tree`` toward ``other`` (module docstring). The new node one step
    beyond the graft, or None."""
    o = pl.options
    i, j = closest_pair(tree, other, pl._rng, o.frontier_pairs)
    dist = float(np.linalg.norm(other.xi[j] - tree.xi[i]))
    if dist <= 1e-9 or (o.frontier_radius and dist > o.frontier_radius):
        return None
    return lookahead_graft(pl, tree, i, other.xi[j], deadline, st, "frontier")


def lookahead_graft(pl: TCBiRRT, tree: _TaskTree, i: int, xi_target: np.ndarray, deadline: Deadline,
                    st: dict[str, Any], kind: str) -> int | None:
    """Re-grasp the arms at node ``i`` of ``tree`` into an IK solution (``frontier_seeds`` random seeds; one arm
    moved, or both) that is valid and from which one constrained step (``step_size``, ξ) toward ``xi_target``
    passes; the solution becomes a graft node and the step's end a node below it, which is returned (None:
    no such solution, or its regrasp failed). ``kind`` names the counters (``<kind>_attempts``,
    ``<kind>_grafts``, ``<kind>_lookahead_failures``, ``<kind>_regrasp_failures``)."""
    o, ck, kin, rng = pl.options, pl.checker, pl.kin, pl._rng
    d = np.asarray(xi_target, float) - tree.xi[i]
    dist = float(np.linalg.norm(d))
    if dist <= 1e-9:
        return None
    st[f"{kind}_attempts"] = st.get(f"{kind}_attempts", 0) + 1
    R, p = tree.pose[i]
    q_i = tree.q[i]
    xi_s = np.array(xi_target, float) if dist <= pl.step_size else tree.xi[i] + (pl.step_size / dist) * d
    Rs, ps = pose_from_xi(xi_s)
    poses = interpolate_task(R, p, Rs, ps, o.n_interp, o.interpolation)
    twins = [tree.q[k] for k in tree.twins.get(i, [i])]
    if pl._la is not None:   # the same candidates, checks and draws in one native call per candidate that passes
        return _lookahead_native(pl, tree, i, xi_s, (Rs, ps), poses, twins, deadline, st, kind)
    step = cast(float, o.max_joint_step)   # resolved from the variant
    # the extension's IK when it is native (the hand-written one, as the native look-ahead's), else kin.ik
    ik = pl._ext.ik if pl._ext is not None else (lambda q, R_, p_: kin.ik(q, R_, p_, o.ik))
    for _ in range(o.frontier_seeds):
        if deadline.expired():
            return None
        x, its = ik(rng.uniform(pl.robot.lower, pl.robot.upper), R, p)
        st["ik_iterations"] += its
        if x is None:
            continue
        cands = []
        for idx in kin.idx:   # one arm re-grasps (the other keeps its configuration), then both
            y = q_i.copy()
            y[idx] = x[idx]
            cands.append(y)
        cands.append(x)
        for y in cands:
            if any(float(np.abs(y - t).max()) <= step for t in twins):
                continue   # the node's own configuration (or one of its grafts'), give or take a restart
            if not ck.in_limits(y) or not ck.is_valid(y):
                continue
            Q = pl.path_ik(poses, y, st)   # the look-ahead: one constrained step toward the target
            if not Q or len(Q) < len(poses):
                st[f"{kind}_lookahead_failures"] = st.get(f"{kind}_lookahead_failures", 0) + 1
                continue
            got = _regrasp_to(pl, tree, i, y, list(Q), xi_s, (Rs, ps), poses, deadline, st, kind)
            if got is not None:
                return got
    return None


def _regrasp_to(pl: TCBiRRT, tree: _TaskTree, i: int, y: np.ndarray, Q: list[np.ndarray], xi_s: np.ndarray,
                pose_s: tuple[np.ndarray, np.ndarray], poses: list[tuple[np.ndarray, np.ndarray]], deadline: Deadline,
                st: dict[str, Any], kind: str) -> int | None:
    """A candidate ``y`` whose look-ahead step ``Q`` (toward ``xi_s``, object poses ``poses``) passed: the arms regrasp
    from node i's configuration to it; on success ``y`` becomes a graft of node i and the step's end a node below it
    (returned), else None (counted in ``<kind>_regrasp_failures``)."""
    R, p = tree.pose[i]
    reg = pl.regrasp(tree.q[i], y, R, p, pl._rng, pl.graft_deadline(deadline), st)
    if reg is None:
        st[f"{kind}_regrasp_failures"] = st.get(f"{kind}_regrasp_failures", 0) + 1
        return None
    st[f"{kind}_grafts"] = st.get(f"{kind}_grafts", 0) + 1
    g = tree.add_graft(i, y, reg)
    return tree.add(Q[-1], xi_s, pose_s[0], pose_s[1], g, Q[:-1], poses[:-1])


def _lookahead_native(pl: TCBiRRT, tree: _TaskTree, i: int, xi_s: np.ndarray, pose_s: tuple[np.ndarray, np.ndarray],
                      poses: list[tuple[np.ndarray, np.ndarray]], twins: list[np.ndarray], deadline: Deadline,
                      st: dict[str, Any], kind: str) -> int | None:
    """The candidate loop of :func:`lookahead_graft` with the native loop (:class:`.tcbirrt_lookahead.NativeLookahead`):
    each candidate that passes its look-ahead is regrasped here, and the loop goes on after a failed regrasp."""
    from .tcbirrt_native import _merge, poses_array

    if deadline.expired():
        return None
    la = pl._la
    la.start(tree.pose12[i], tree.q[i], np.asarray(twins), poses_array(poses), pl.options.frontier_seeds, deadline)
    try:
        while True:
            got = la.next(pl._rng, deadline)
            _merge(st, cast("NativeExtender", pl._ext))
            if got is None:
                return None
            node = _regrasp_to(pl, tree, i, got[0], list(got[1]), xi_s, pose_s, poses, deadline, st, kind)
            if node is not None:
                return node
    finally:
        st["ik_iterations"] += int(la.args.its)
        if la.args.failures:
            st[f"{kind}_lookahead_failures"] = st.get(f"{kind}_lookahead_failures", 0) + int(la.args.failures)


def trap_lookahead(pl: TCBiRRT, tree: _TaskTree, i: int, xi_target: np.ndarray, trap: list[Any], deadline: Deadline,
                   st: dict[str, Any]) -> int | None:
    """A trap graft's :func:`lookahead_graft` (counters ``trap_*``). With ``trap_graft_stream="own"`` its IK seeds,
    look-ahead restarts (the native ones too) and regrasp draw from the tree's own streams — ``trap[1]``: at the
    first attempt ``(query seed, tree)``, then the streams — and the search's are restored after it, untouched."""
    if pl.options.trap_graft_stream != "own":
        return lookahead_graft(pl, tree, i, xi_target, deadline, st, "trap")
    if isinstance(trap[1], tuple):   # the tree's first attempt: its streams, from the query's seed
        from .kernel.sampler import NativeRandom

        g = np.random.default_rng([0x7A9, *(abs(int(v)) for v in trap[1])])
        trap[1] = [g, NativeRandom(g) if pl._nrng is not None else None]
    o, ext, rng, nrng = pl.options, pl._ext, pl._rng, pl._nrng
    native = ext is not None and ext.native_restarts and trap[1][1] is not None and nrng is not None

    def restarts(r: Any) -> None:   # the extension's restarts in C draw from ``r``
        cast(Any, ext).restarts_in_c(r, cast(int, o.ik_restarts), o.ik_restart_sigma, pl.robot.lower - 1e-9,
                                     pl.robot.upper + 1e-9, cast(int, o.ik_restart_iterations), cast(Any, o.ik_restart_clip))
    pl._rng = trap[1][0]
    if native:
        restarts(trap[1][1])
    try:
        return lookahead_graft(pl, tree, i, xi_target, deadline, st, "trap")
    finally:
        pl._rng = rng
        if native:
            restarts(nrng)
