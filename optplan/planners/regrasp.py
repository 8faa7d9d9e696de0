"""The regrasp of TCBiRRT (Section 4.3 of the TCBiRRT paper): the object stands still while the arms move,
one at a time, from one IK solution of its pose to another (an RRTConnect in the moving arm's joints, then
shortcuts, its edges re-checked at the planner's sweep bound); both orders are tried, and optionally both arms
at once. The hand's contacts with the object at the grasps are exempted from the checks while it moves
(:meth:`.ValidityChecker.grasp_contacts`).

:class:`RegraspMixin` holds these methods of :class:`~.tcbirrt.TCBiRRT`; it uses the planner's options,
closed-chain kinematics, validity checker and sweep weights.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, cast

import numpy as np
import pinocchio as pin

from ..constraints.closed_chain import ClosedChainKinematics
from ..model.robot import RobotModel
from .base import BOTH_ARMS, Deadline
from .rrtconnect import edge_is_valid, joint_space_path
from .tcbirrt_options import TCBiRRTOptions
from .validity import ValidityChecker

__all__ = ["RegraspMixin"]


class RegraspMixin:
    """The regrasp methods of :class:`~.tcbirrt.TCBiRRT` (the attributes below are the planner's)."""

    options: TCBiRRTOptions
    kin: ClosedChainKinematics
    checker: ValidityChecker
    robot: RobotModel
    _w_fixed: np.ndarray

    def regrasp(self, q_from: np.ndarray, q_to: np.ndarray, R: np.ndarray, p: np.ndarray, rng: np.random.Generator,
                deadline: Deadline, st: dict[str, Any]) -> list[tuple[str, list[np.ndarray]]] | None:
        """Move the arms one at a time from ``q_from`` to ``q_to`` (same object pose (R, p)), the
        object fixed; with ``regrasp_both_arms``, both arms at once when neither order passes.
        Returns ``[(arm, [full configurations from start to end of that arm's motion]), ...]``
        (``arm`` is :data:`.BOTH_ARMS` for a both-arm motion; empty when no arm needs to move) or None.

        A hand geometry on the object's ``exclude_links`` that touches the object at either end (at its
        grasp) is not checked against the object during the regrasp (:meth:`.ValidityChecker.grasp_contacts`).
        The regrasp ends when its work budget ``regrasp_iterations`` (RRT-Connect iterations) or its time limit
        ``regrasp_time_limit`` (a backstop) is spent, or at ``deadline`` (a graft's, with its own budget); both halved
        after each failed regrasp of the query with ``regrasp_backoff`` (down to ``regrasp_min_iterations`` and
        ``regrasp_min_time_limit``; a success restores them)."""
        o, kin = self.options, self.kin
        moving = [(name, idx) for name, idx in zip(kin.arm_names, kin.idx)
                  if float(np.abs(q_to[idx] - q_from[idx]).max()) > o.regrasp_tolerance]
        if not moving:
            return []
        st["regrasp_attempts"] += 1
        M = pin.SE3(R, p)
        limit, work = o.regrasp_time_limit, float(o.regrasp_iterations or math.inf)
        if o.regrasp_backoff:
            f = 0.5 ** st.get("regrasp_failure_run", 0)
            limit = max(o.regrasp_min_time_limit, limit * f)
            work = max(o.regrasp_min_iterations, 1, math.floor(work * f)) if o.regrasp_iterations else work
        sub = deadline.sub(limit, work)
        t0 = sub.clock()
        with self._grasp_exempt(M, q_from, q_to):
            out = self._regrasp_orders(q_from, q_to, M, moving, rng, sub, st)
            if out is None and o.regrasp_both_arms and len(moving) == 2 and not sub.expired():
                st["both_arm_attempts"] = st.get("both_arm_attempts", 0) + 1
                both = self._regrasp_motion(q_from, q_to, np.concatenate([idx for _, idx in moving]), M, rng, sub, st)
                if both is not None:
                    st["both_arm_regrasps"] = st.get("both_arm_regrasps", 0) + 1
                    out = [(BOTH_ARMS, both)]
        st["regrasp_time_s"] = st.get("regrasp_time_s", 0.0) + (sub.clock() - t0)
        if out is None:
            st["regrasp_failures"] += 1
            st["regrasp_failure_run"] = st.get("regrasp_failure_run", 0) + 1
        else:
            st["regrasp_failure_run"] = 0
        return out

    def graft_deadline(self, deadline: Deadline) -> Deadline:
        """The deadline of one graft's regrasp: ``graft_iterations`` RRT-Connect iterations, ``graft_time_limit`` a backstop."""
        return deadline.sub(self.options.graft_time_limit, float(self.options.graft_iterations or math.inf))

    def _grasp_exempt(self, M: pin.SE3, *qs: np.ndarray) -> Any:
        """Context: the object-fixed checks skip the grasp contacts of the configurations ``qs``."""
        pairs: set[int] = set()
        for q in qs:
            pairs.update(self.checker.grasp_contacts(q, M))
        return self.checker.exempt(tuple(sorted(pairs)))

    def _regrasp_orders(self, q_from: np.ndarray, q_to: np.ndarray, M: pin.SE3, moving: list[tuple[str, np.ndarray]],
                        rng: np.random.Generator, sub: Deadline, st: dict[str, Any]) -> list[tuple[str, list[np.ndarray]]] | None:
        """Section 4.3's sequential regrasp: the arms of ``moving`` one at a time, both orders."""
        o, ck = self.options, self.checker
        orders = [moving] if len(moving) == 1 else [moving, moving[::-1]]
        for n_order, order in enumerate(orders):
            if o.regrasp_share_orders:   # this order's share of what is left of the regrasp's budget
                sub_o = sub.sub(sub.remaining() / (len(orders) - n_order), sub.work / (len(orders) - n_order))
            else:
                sub_o = sub
            cur = q_from.copy()
            segs: list[tuple[str, list[np.ndarray]]] | None = []
            for name, idx in order:
                y = cur.copy()
                y[idx] = q_to[idx]
                if not ck.is_valid_object_fixed(y, M):   # the intermediate grasp configuration itself
                    st["regrasp_refused"] = st.get("regrasp_refused", 0) + 1
                    segs = None
                    break
                full = self._regrasp_motion(cur, q_to, idx, M, rng, sub_o, st)
                if full is None:
                    segs = None
                    break
                segs.append((name, full))  # type: ignore[union-attr]  # segs is None only on the paths that break out of this loop
                cur = full[-1].copy()
            if segs is not None:
                return segs
            if sub.expired():
                break
        return None

    def _regrasp_motion(self, cur: np.ndarray, q_to: np.ndarray, idx: np.ndarray, M: pin.SE3, rng: np.random.Generator,
                        sub: Deadline, st: dict[str, Any]) -> list[np.ndarray] | None:
        """The joints ``idx`` from ``cur`` to ``q_to[idx]`` (the others still, the object fixed at M) by
        RRTConnect + shortcuts (:func:`.joint_space_path`: one native call when the checks are native; it gives up
        early when a tree stalls, ``regrasp_stall_iterations``), its edges re-checked at ``edge_tolerance``: the
        full configurations, or None."""
        o, ck = self.options, self.checker
        if sub.expired():   # the work budget or the time spent
            return None
        valid = ck.validity("fixed", M, base=cur, joints=idx)   # these joints move, the rest and the object stand still
        rs: dict[str, Any] = {}
        lo, hi = self.robot.lower, self.robot.upper
        ro = o.regrasp if not o.regrasp_stall_iterations else replace(o.regrasp, stall_iterations=o.regrasp_stall_iterations)
        if o.regrasp_balance and not ro.balance:
            ro = replace(ro, balance=float(o.regrasp_balance))
        cap = sub.work_cap()   # the work left: the RRT-Connect's iteration cap
        if cap and not 0 < ro.max_iterations <= cap:
            ro = replace(ro, max_iterations=cap)
        sub_path = joint_space_path(cur[idx], q_to[idx], lo[idx], hi[idx], valid, rng, sub, ro, rs)
        sub.spend(rs.get("iterations", 0))
        st["regrasp_iterations"] = st.get("regrasp_iterations", 0) + rs.get("iterations", 0)
        st["regrasp_nodes"] += rs.get("nodes", 0)
        if rs.get("stalled"):
            st["regrasp_stalled"] = st.get("regrasp_stalled", 0) + 1
        if sub_path is None:
            return None
        if o.edge_tolerance and not all(   # the found motion re-checked at the sweep bound of these joints
                self._regrasp_edge_ok(cur, idx, x, y, M) for x, y in zip(sub_path[:-1], sub_path[1:])):
            st["edge_collisions"] += 1
            return None
        full = []
        for x in sub_path:
            y = cur.copy()
            y[idx] = x
            full.append(y)
        return full

    def _regrasp_edge_ok(self, base: np.ndarray, idx: np.ndarray, x: np.ndarray, y: np.ndarray, M: pin.SE3) -> bool:
        """One arm's straight segment x → y (its joints ``idx``; the rest of ``base`` still, the
        object fixed at M) at ``edge_tolerance`` with the ``edge_bound`` (ends not checked)."""
        o = self.options
        if o.edge_bound in ("jacobian", "certified"):
            a, b = base.copy(), base.copy()
            a[idx], b[idx] = x, y
            if o.edge_bound == "certified":
                return self.checker.edge_is_certified(a, b, "fixed", object_pose=M, min_clearance=o.edge_min_clearance,
                                                      cache=True)
            return self.checker.edge_is_valid(a, b, cast(float, o.edge_tolerance), "fixed", object_pose=M, expect_free=True)
        return edge_is_valid(x, y, self.checker.validity("fixed", M, base=base, joints=idx), cast(float, o.edge_tolerance),
                             False, self._w_fixed[:, idx])
