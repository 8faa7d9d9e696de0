"""Other IK branches and joint-space connections of TCBiRRT: ``joint_connect`` (CBiRRT2's ConstrainedExtend in
joint space between two configurations on the closed chain) and ``branch_grafts`` (another IK solution of a
node's object pose, joined to the node by a regrasp).

:class:`BranchMixin` holds these methods of :class:`~.tcbirrt.TCBiRRT`; it uses the planner's options,
closed-chain kinematics, validity checker, random generator and regrasps (:class:`~.regrasp.RegraspMixin`).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..scene import Scene
from .base import Deadline
from .cbirrt2 import CBiRRT2
from .regrasp import RegraspMixin
from .tcbirrt_tree import _TaskTree
from .tree import Tree

__all__ = ["BranchMixin"]


class BranchMixin(RegraspMixin):
    """The joint-space connection and branch-graft methods of :class:`~.tcbirrt.TCBiRRT` (the attributes are the
    planner's)."""

    scene: Scene
    _cb: CBiRRT2 | None
    _rng: np.random.Generator

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
                reg = self.regrasp(q_i, y, R, p, rng, deadline.sub(o.graft_time_limit), st)
                if reg is None:
                    st["graft_regrasp_failures"] = st.get("graft_regrasp_failures", 0) + 1
                    continue
                st["grafts"] += 1   # its regrasp motions are verified (verify_path) once on a start-goal path
                return tree.add_graft(i, y, reg)
        return None
