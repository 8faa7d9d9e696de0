"""Other IK branches and joint-space connections of TCBiRRT: ``joint_connect`` (CBiRRT2's ConstrainedExtend in
joint space between two configurations on the closed chain), ``branch_grafts`` (another IK solution of a
node's object pose, joined to the node by a regrasp) and ``branch_roots`` (before the search, one tree's root
re-grasped onto the other root's IK branch, so that the trees can meet without a regrasp).

:class:`BranchMixin` holds these methods of :class:`~.tcbirrt.TCBiRRT`; it uses the planner's options,
closed-chain kinematics, validity checker, random generator and regrasps (:class:`~.regrasp.RegraspMixin`).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any, cast

import numpy as np
import pinocchio as pin

from ..scene import Scene
from .base import Deadline
from .cbirrt2 import CBiRRT2
from .regrasp import RegraspMixin
from .task_space import interpolate_task
from .tcbirrt_tree import _TaskTree
from .tree import Tree

__all__ = ["BranchMixin"]


class BranchMixin(RegraspMixin):
    """The joint-space connection and branch-graft methods of :class:`~.tcbirrt.TCBiRRT` (the attributes are the
    planner's)."""

    scene: Scene
    _cb: CBiRRT2 | None
    _rng: np.random.Generator
    step_size: float

    _edge_ok: Callable[[np.ndarray, np.ndarray, dict[str, Any]], bool]   # :class:`~.tcbirrt_edges.EdgeCheckMixin`'s

    def joint_connect(self, q_from: np.ndarray, q_to: np.ndarray, deadline: Deadline, st: dict[str, Any]) -> list[np.ndarray] | None:
        """CBiRRT2's ConstrainedExtend in joint space from ``q_from`` to ``q_to`` (both on the closed
        chain); the configurations after ``q_from`` up to ``q_to`` (its edges checked at
        ``edge_tolerance`` when set), or None when trapped."""
        from .cbirrt2 import REACHED as CB_REACHED

        if self._cb is None:
            self._cb = CBiRRT2(self.robot, self.scene, self.options.joint_connect_options, checker=self.checker,
                               kinematics=self.kin)
        st["joint_connect_attempts"] += 1
        cst = {"projections": 0, "projection_failures": 0}
        tree = Tree(np.asarray(q_from, float), 512, edges=True)
        res, i = self._cb.extend(tree, 0, np.asarray(q_to, float), cst, deadline)
        st["joint_connect_projections"] += cst["projections"]
        if res != CB_REACHED:
            return None
        path = tree.branch(i)[1:] + [np.asarray(q_to, float).copy()]
        if self.options.edge_tolerance:
            prev = q_from
            for x in path:
                if not self._edge_ok(prev, x, st):
                    return None
                prev = x
        st["joint_connect_successes"] += 1
        return path

    def branch_at(self, q_from: np.ndarray, R: np.ndarray, p: np.ndarray) -> np.ndarray | None:
        """The joints holding the object at ``(R, p)`` on ``q_from``'s IK branch: PathInverseKinematics along the
        straight task-space motion (geodesic, Eq. 4) from ``q_from``'s object pose, one waypoint per
        ``step_size / n_interp`` of ξ distance, every solution within ``max_joint_step`` of the previous one;
        collisions and joint limits are not checked. None when a waypoint fails."""
        o, kin = self.options, self.kin
        M0 = kin.object_pose(q_from)
        dp = float(np.linalg.norm(p - M0.translation))
        dr = float(np.linalg.norm(pin.log3(M0.rotation.T @ R)))
        n = max(1, int(np.ceil(max(dp, dr) / (self.step_size / o.n_interp))))
        q = np.asarray(q_from, float)
        for Rk, pk in interpolate_task(M0.rotation, M0.translation, R, p, n, "geodesic"):
            x, _ = kin.ik(q, Rk, pk, o.ik)
            if x is None or float(np.abs(x - q).max()) > cast(float, o.max_joint_step):
                return None
            q = x
        return q

    def _root_branches(self, ta: _TaskTree, tb: _TaskTree, deadline: Deadline, st: dict[str, Any]) -> None:
        """``branch_roots``: before the search, the goal tree's root (``tb``) gets the start's IK branch at the goal's
        object pose (:meth:`branch_at`), arm by arm: an arm farther than ``graft_min_distance`` from its goal
        joints takes the start branch's, the other keeps the goal's. When that configuration is free and in the
        limits, the arms regrasp to it at the goal pose (``graft_time_limit``) and it becomes a graft of the root,
        from which the goal tree grows; otherwise the start's root is tried the same way with the goal's branch."""
        o, kin = self.options, self.kin
        for tree, other, side in ((tb, ta, "goal"), (ta, tb, "start")):
            if deadline.expired():
                return
            R, p = tree.pose[0]
            x = self.branch_at(other.q[0], R, p)
            if x is None:
                st["root_branch_ik_failures"] = st.get("root_branch_ik_failures", 0) + 1
                continue
            q0 = tree.q[0]
            arms = [idx for idx in kin.idx if float(np.linalg.norm(x[idx] - q0[idx])) >= o.graft_min_distance]
            if not arms:
                st["root_branch_same"] = st.get("root_branch_same", 0) + 1
                return   # the roots already hold the arms on the same branches
            y = self._root_branch_free(q0, x, arms, R, p)
            if y is None:
                st["root_branch_collisions"] = st.get("root_branch_collisions", 0) + 1
                continue
            st["root_branch_attempts"] = st.get("root_branch_attempts", 0) + 1
            reg = self.regrasp(q0, y, R, p, self._rng, self.graft_deadline(deadline), st)
            if reg is None:
                st["root_branch_regrasp_failures"] = st.get("root_branch_regrasp_failures", 0) + 1
                continue
            st["root_branch"] = side
            g = tree.add_graft(0, y, reg)
            tree.prefer[0] = tree.prefer[g] = g   # the root's extensions grow from the shared branch
            return

    def _root_branch_free(self, q0: np.ndarray, x: np.ndarray, arms: list[np.ndarray], R: np.ndarray,
                          p: np.ndarray) -> np.ndarray | None:
        """A free configuration in the limits holding the object at ``(R, p)`` whose ``arms`` are on ``x``'s branch
        and whose other joints are ``q0``'s: ``x``'s arms themselves, then (both arms differing) one arm alone,
        then other points of the arms' self-motion (IK from ``x`` perturbed by ``ik_restart_sigma``, ``graft_seeds``
        times; kept when each arm is nearer ``x``'s than ``q0``'s). None when none is free."""
        o, ck, kin = self.options, self.checker, self.kin
        sets = [arms] + ([[a] for a in arms] if len(arms) > 1 else [])
        for k in range(len(sets) + o.graft_seeds):
            use = sets[min(k, len(sets) - 1)] if k < len(sets) else arms
            src: np.ndarray | None = x
            if k >= len(sets):   # another point of the same self-motion
                src, _ = kin.ik(x + self._rng.normal(0.0, o.ik_restart_sigma, x.size), R, p, o.ik)
                if src is None or any(float(np.linalg.norm(src[i] - x[i])) >= float(np.linalg.norm(src[i] - q0[i]))
                                      for i in use):
                    continue
            y = q0.copy()
            for idx in use:
                y[idx] = cast(np.ndarray, src)[idx]
            if ck.in_limits(y) and ck.is_valid(y):
                return y
        return None

    def _graft(self, tree: _TaskTree, i: int | None, other: _TaskTree, deadline: Deadline, st: dict[str, Any]) -> int | None:
        """``branch_grafts``: another IK branch at node i of ``tree`` (when None: the node nearest a random
        live node of ``other``):
        IK of its object pose seeded from ``other``'s configuration nearest in ξ; a valid solution at
        least ``graft_min_distance`` from the node's joins the tree by a regrasp. The new node, or None."""
        o, ck, kin = self.options, self.checker, self.kin
        rng = self._rng
        if i is None:
            if o.graft_node == "any" or (o.graft_node == "mixed" and rng.random() < 0.5):   # a random live node
                live = np.flatnonzero(tree.alive[:tree.n]) if tree.alive is not None else np.arange(tree.n)
                i = int(live[int(rng.integers(live.size))])
            else:   # the node nearest a random node of the other tree: where the trees meet, more often
                live = np.flatnonzero(other.alive[:other.n]) if other.alive is not None else np.arange(other.n)
                i = tree.nearest(other.xi[int(live[int(rng.integers(live.size))])])
        if i in tree.graft:
            return None
        st["graft_attempts"] += 1
        R, p = tree.pose[i]
        q_i = tree.q[i]
        seed = other.q[other.nearest(tree.xi[i])]
        branches = [other.q[0], *(other.q[g] for g in other.graft)] if o.graft_branch_seeds else []
        for k in range(-len(branches), o.graft_seeds):
            if k < 0:      # the other tree's branches: its root's and its grafts' configurations
                q0 = branches[k]
            elif k == 0:
                q0 = seed
            elif k % 2:
                q0 = seed + rng.normal(0.0, o.ik_restart_sigma, seed.size)
            else:          # a random configuration: a branch neither tree has
                q0 = rng.uniform(self.robot.lower, self.robot.upper)
            x, its = kin.ik(q0, R, p, o.ik)
            st["ik_iterations"] += its
            if x is None:
                st["graft_ik_failures"] = st.get("graft_ik_failures", 0) + 1
                continue
            cands = [x]
            if o.graft_single_arm:   # each arm's IK is independent at a fixed object pose: one arm's new branch alone
                for idx in kin.idx:
                    y = q_i.copy()
                    y[idx] = x[idx]
                    cands.append(y)
            for y in cands:
                if float(np.linalg.norm(y - q_i)) < o.graft_min_distance:
                    st["graft_same_branch"] = st.get("graft_same_branch", 0) + 1
                    continue
                if not ck.in_limits(y) or not ck.is_valid(y):
                    st["graft_collisions"] = st.get("graft_collisions", 0) + 1
                    continue
                if any(float(np.linalg.norm(tree.q[j] - y)) < o.graft_min_distance for j in tree.twins.get(i, ())):
                    continue   # a branch this pose already has
                if o.graft_skip_failed and any(float(np.linalg.norm(f - y)) < o.graft_min_distance
                                               for f in tree.failed_grafts.get(i, ())):
                    st["graft_repeats_skipped"] = st.get("graft_repeats_skipped", 0) + 1
                    continue   # a branch this node's regrasp already failed to reach
                reg = self.regrasp(q_i, y, R, p, rng, self.graft_deadline(deadline), st)
                if reg is None:
                    st["graft_regrasp_failures"] = st.get("graft_regrasp_failures", 0) + 1
                    if o.graft_skip_failed:
                        tree.failed_grafts.setdefault(i, []).append(y.copy())
                    continue
                st["grafts"] += 1   # its regrasp motions are verified (verify_path) once on a start-goal path
                return tree.add_graft(i, y, reg)
        return None
