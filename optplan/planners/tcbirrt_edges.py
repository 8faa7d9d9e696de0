"""TCBiRRT's edge checks: the straight joint-space segments between consecutive configurations of a constrained
edge or a regrasp motion, checked at ``edge_tolerance`` when an extension is made (eagerly), once a start-goal
path is found (``lazy_edges``, with repairs by joint-space connections), and once more at the
configuration-free bound's uniform spacing (``verify_path``).

:class:`EdgeCheckMixin` holds these methods of :class:`~.tcbirrt.TCBiRRT`; it uses the planner's options,
validity checker, sweep weights and (through :class:`~.tcbirrt_grafts.BranchMixin`) its regrasps and
joint-space connections.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import numpy as np
import pinocchio as pin

from .base import Deadline
from .rrtconnect import edge_is_valid
from .tcbirrt_grafts import BranchMixin
from .tcbirrt_tree import _TaskTree

__all__ = ["EdgeCheckMixin"]


class EdgeCheckMixin(BranchMixin):
    """The edge-check methods of :class:`~.tcbirrt.TCBiRRT` (the attributes are the planner's)."""

    _w_held: np.ndarray

    def _edges_prefix(self, q_near: np.ndarray, out: list[np.ndarray], fail: list[np.ndarray] | None, st: dict[str, Any]) -> list[np.ndarray] | None:
        """Eager edge checks after the waypoints' own checks (a failing waypoint costs no edge check):
        ``out`` if every edge passes, else the prefix before the first failing edge (or None)."""
        o = self.options
        if not o.edge_tolerance or o.lazy_edges:
            return out
        prev = q_near
        for k, x in enumerate(out):
            if not self._edge_ok(prev, x, st):
                return None if fail is None else out[:k]
            prev = x
        return out

    def _edge_ok(self, a: np.ndarray, b: np.ndarray, st: dict[str, Any]) -> bool:
        """The straight joint segment a → b (object held) at ``edge_tolerance`` (ends not checked)."""
        st["edge_checks"] += 1
        o = self.options
        if o.edge_bound == "certified":
            ok = self.checker.edge_is_certified(a, b, "held", min_clearance=o.edge_min_clearance, cache=True)
        elif o.edge_bound == "jacobian":
            ok = self.checker.edge_is_valid(a, b, cast(float, o.edge_tolerance), "held")
        else:
            ok = edge_is_valid(a, b, self.checker.validity("held"), cast(float, o.edge_tolerance), False, self._w_held)
        if ok:
            return True
        st["edge_collisions"] += 1
        return False

    def _static_edge_ok(self, a: np.ndarray, b: np.ndarray, st: dict[str, Any], object_pose: pin.SE3 | None = None) -> bool:
        """The segment a → b at ``edge_tolerance`` with the configuration-free bound's uniform spacing
        (object held, or fixed at ``object_pose``); ends not checked."""
        st["path_verified_edges"] += 1
        tol = cast(float, self.options.edge_tolerance)
        if object_pose is None:
            return self.checker.uniform_edge_is_valid(a, b, tol, self._w_held, "held")
        return self.checker.uniform_edge_is_valid(a, b, tol, self._w_fixed, "fixed", object_pose)

    def _verify_branch(self, tree: _TaskTree, i: int, st: dict[str, Any]) -> int | None:
        """``verify_path``: every not yet verified edge from the root to node i at the uniform
        spacing; the first node whose edge fails, or None (verified edges are marked)."""
        chain: list[int] = []
        while i > 0 and not tree.checked[i]:
            chain.append(i)
            i = tree.parent[i]
        for k in reversed(chain):
            if k in tree.graft:   # a graft's regrasp motions, object fixed at the node's pose
                M = pin.SE3(*tree.pose[k])
                with self._grasp_exempt(M, tree.q[tree.parent[k]], tree.q[k]):
                    ok = all(self._static_edge_ok(a, b, st, M) for _, full in tree.graft[k]
                             for a, b in zip(full[:-1], full[1:]))
            else:
                eq, _ = tree.edge[k]
                qs = [tree.q[tree.parent[k]], *eq, tree.q[k]]
                ok = all(self._static_edge_ok(a, b, st) for a, b in zip(qs[:-1], qs[1:]))
            if not ok:
                return k
            tree.checked[k] = True
        return None

    def _verify_connection(self, ta: _TaskTree, i_a: int, reg: Sequence[tuple[str | None, list[np.ndarray]]] | None,
                           st: dict[str, Any]) -> bool:
        """``verify_path``: the regrasp motions (object fixed at tree a's node pose) and joint-space
        connections of a connection at the uniform spacing."""
        M = pin.SE3(*ta.pose[i_a])
        for arm, full in reg or []:
            if arm is None:
                ok = all(self._static_edge_ok(a, b, st) for a, b in zip(full[:-1], full[1:]))
            else:
                with self._grasp_exempt(M, full[0], full[-1]):
                    ok = all(self._static_edge_ok(a, b, st, M) for a, b in zip(full[:-1], full[1:]))
            if not ok:
                return False
        return True

    def _branch_ok(self, tree: _TaskTree, i: int, st: dict[str, Any], deadline: Deadline) -> int | None:
        """Lazy edges: verify every unchecked edge from the root to node i (root side first); a
        straight segment in collision is repaired, when ``joint_connect`` is on, by a joint-space
        constrained path between its ends (:meth:`joint_connect`), spliced into the node's edge.
        Returns the first node whose edge cannot be made valid, or None when all pass."""
        chain = []
        while i > 0 and not tree.checked[i]:
            chain.append(i)
            i = tree.parent[i]
        for k in reversed(chain):
            if k in tree.graft:      # regrasp motions: checked at edge_tolerance when planned
                tree.checked[k] = True
                continue
            eq, ep = tree.edge[k]
            qs = [tree.q[tree.parent[k]], *eq, tree.q[k]]
            new_q, new_p = [], []
            for j, (a, b) in enumerate(zip(qs[:-1], qs[1:])):
                if not self._edge_ok(a, b, st):
                    jp = self.joint_connect(a, b, deadline, st) if self.options.joint_connect else None
                    if jp is None:
                        return k
                    st["edge_repairs"] = st.get("edge_repairs", 0) + 1
                    for x in jp[:-1]:
                        M = self.kin.object_pose(x)
                        new_q.append(x)
                        new_p.append((M.rotation.copy(), M.translation.copy()))
                if j < len(eq):
                    new_q.append(eq[j])
                    new_p.append(ep[j])
            tree.edge[k] = (new_q, new_p)
            tree.checked[k] = True
        return None
