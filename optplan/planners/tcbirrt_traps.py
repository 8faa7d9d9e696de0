"""TCBiRRT's trapped extensions: what a trapped extension changes at its node (``trap_adapt``), the trap grafts it
counts toward (``trap_grafts``), and the trapped streaks that run series of them in one native call
(:mod:`.tcbirrt_streak`).

:class:`TrapMixin` holds these methods of :class:`~.tcbirrt.TCBiRRT`; it uses the planner's options, its native
extension and its constrained extension's end (``_extended``).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from .frontier_graft import trap_lookahead
from .tcbirrt_native import _merge, pose_list
from .tcbirrt_options import TCBiRRTOptions
from .tcbirrt_streak import STREAK_CONNECTED, STREAK_DONE, NativeStreak, quiet_iterations

if TYPE_CHECKING:
    from .base import Deadline
    from .kernel.extend import NativeExtender
    from .tcbirrt import TCBiRRT
    from .tcbirrt_tree import _TaskTree

__all__ = ["TrapMixin", "no_nearer"]

#: the results of a constrained extension (Alg. 2): trapped, advanced a step, reached its target, or the valid prefix
TRAPPED, ADVANCED, REACHED, PARTIAL = "trapped", "advanced", "reached", "partial"


class TrapMixin:
    """The trap methods of :class:`~.tcbirrt.TCBiRRT` (the attributes below are the planner's)."""

    options: TCBiRRTOptions
    step_size: float
    _ext: NativeExtender | None
    _nrng: Any
    _extended: Any
    _twin_of: Any
    constrained_extend: Any

    def _trap_update(self, tree: _TaskTree, i: int, res: str) -> None:
        """``trap_adapt``: after an extension from node i, its dynamic domain (set when trapped) or its step
        (halved when trapped, down to s_ξ/8; doubled back, up to s_ξ, when not)."""
        o = self.options
        if o.trap_adapt == "domain" and res == TRAPPED:
            tree.dom[i] = self.step_size * cast(float, o.domain_radius)
        elif o.trap_adapt == "step":
            cur = self.step_size if not np.isfinite(tree.dom[i]) else float(tree.dom[i])
            tree.dom[i] = max(cur * 0.5, self.step_size / 8.0) if res == TRAPPED else min(cur * 2.0, self.step_size)

    def _trap_graft(self, tree: _TaskTree, i: int, xi_rand: np.ndarray, other: _TaskTree, trap: list[Any],
                    deadline: Deadline, st: dict[str, Any]) -> int | None:
        """``trap_grafts``: count a trapped extension from node i of ``tree`` (toward ``xi_rand``); at its
        ``trap_graft_count``-th, the arms re-grasp at the node into a branch from which a step toward
        ``trap_graft_target`` (``other``'s node nearest in ξ, or ``xi_rand``) passes
        (:func:`.frontier_graft.trap_lookahead`); the counts per node are the tree's ``trapn``. ``trap``: the tree's
        ``[grafts made, stream]``. The node
        one step beyond the graft, or None."""
        tree.trapn[i] += 1
        if tree.trapn[i] != self.options.trap_graft_count:
            return None
        return self._trap_fire(tree, i, xi_rand, other, trap, deadline, st)

    def _trap_fire(self, tree: _TaskTree, i: int, xi_rand: np.ndarray, other: _TaskTree, trap: list[Any],
                   deadline: Deadline, st: dict[str, Any]) -> int | None:
        """The trap graft of :meth:`_trap_graft` at node i, its count reached: the node one step beyond it, or None."""
        target = other.xi[other.nearest(tree.xi[i])] if self.options.trap_graft_target == "other" else xi_rand
        got = trap_lookahead(cast("TCBiRRT", self), tree, i, target, trap, deadline, st)
        trap[0] += got is not None
        return got

    def _streak(self, sampler: Any, deadline: Deadline) -> NativeStreak | None:
        """The query's trapped streaks (:mod:`.tcbirrt_streak`), or None where the loop runs them one by one: the
        option off, no native loop (its sampler, restarts and Jacobian-spaced edges), a deadline with a work budget."""
        o, ext = self.options, self._ext
        if not (o.streaks and self._nrng is not None and ext is not None and ext.edge_on and ext.native_restarts
                and o.interpolation == "geodesic" and math.isinf(deadline.work)):
            return None
        return NativeStreak(cast("TCBiRRT", self), sampler)

    def _run_streak(self, streak: NativeStreak, ta: _TaskTree, tb: _TaskTree, traps: dict[int, list[Any]],
                    fronts: dict[int, int], since_gap: int, max_iterations: int, sampler: Any, lead: Any,
                    deadline: Deadline, st: dict[str, Any], rng: np.random.Generator) -> tuple[Any, int]:
        """The loop's current iteration (its head has run) and the plain trapped ones after it in one native call:
        ``(result, iterations completed after the current one)``; the counters merged. The caller swaps the trees
        once per completed iteration and goes on with the result's code."""
        o = self.options
        lead_on = sampler.guide is None and lead.budget_left(self)
        n_max = quiet_iterations(cast("TCBiRRT", self), st["iterations"] - 1, since_gap, max_iterations, sampler, lead_on,
                                 min(fronts.values()) < cast(int, o.frontier_grafts))
        sk = streak.run(ta, tb, bool(o.trap_grafts) and traps[id(ta)][0] < cast(int, o.trap_grafts),
                        bool(o.trap_grafts) and traps[id(tb)][0] < cast(int, o.trap_grafts),
                        st["iterations"] - 1, n_max, deadline, rng)
        _merge(st, streak.ext)
        n = int(sk.n_done)
        st["extensions"] += int(sk.n_ext)
        st["trapped"] += int(sk.n_trap)
        st["partial"] += int(sk.n_partial)
        if sk.n_rej:
            st["domain_rejections"] = st.get("domain_rejections", 0) + int(sk.n_rej)
        done = n - 1 if sk.code == STREAK_DONE else n
        st["iterations"] += done
        return sk, done

    def _streak_extended(self, streak: NativeStreak, ta: _TaskTree, sk: Any, rng: np.random.Generator,
                         deadline: Deadline, st: dict[str, Any]) -> tuple[str, int]:
        """The end of the extension a streak stopped at, not trapped: the node it adds to ``ta`` (Python's tree)."""
        st["extensions"] += 1
        i_near = int(sk.i_near)
        P, Q = streak.take()
        res, i_a, _ = self._extended(ta, i_near, np.array(sk.xi_s), bool(sk.reach), P[-1, :9].reshape(3, 3), P[-1, 9:],
                                     pose_list(P), list(Q[:sk.k]), None, rng, deadline, st)
        self._trap_update(ta, i_near, res)
        return res, i_a

    def _streak_connected(self, streak: NativeStreak, tb: _TaskTree, sk: Any, target_q: np.ndarray,
                          rng: np.random.Generator, deadline: Deadline, st: dict[str, Any]) -> tuple[str, int, Any]:
        """The end of a connection step of tree b that a native call took and stopped at, not trapped
        (``STREAK_CONNECTED``; the step and its extension counted in C): ``constrained_extend``'s result."""
        P, Q = streak.take()
        return cast(tuple[str, int, Any], self._extended(
            tb, int(sk.i_nb), np.array(sk.xi_sb), bool(sk.reach_b), P[-1, :9].reshape(3, 3), P[-1, 9:], pose_list(P),
            list(Q[:sk.k_b]), target_q, rng, deadline, st))

    def _connect_steps(self, streak: NativeStreak, tb: _TaskTree, target_xi: np.ndarray, target_q: np.ndarray,
                       rng: np.random.Generator, deadline: Deadline, st: dict[str, Any]) -> tuple[str, int, Any, int, bool]:
        """Tree b's connection toward the target node (lines 7-11) in one native call, up to its last step:
        ``(result, node, regrasp motions, tree b's node it stepped from, ended)`` of that step as
        ``constrained_extend`` gives them; ``ended``: the call ended the connection after a step that was not trapped —
        it got no nearer (:func:`no_nearer`), or the deadline came (then the result is ``ADVANCED``, its nodes added)."""
        c = streak.connect(tb, target_xi, target_q, deadline)
        _merge(st, streak.ext)
        st["extensions"] += int(c.n_ext)
        st["trapped"] += int(c.n_trap)
        st["partial"] += int(c.n_partial)
        i_nb = int(c.i_nb)
        if c.code == STREAK_DONE:
            if c.conn_trapped == 2:
                st["connect_no_nearer"] = st.get("connect_no_nearer", 0) + 1
            return (TRAPPED if c.conn_trapped == 1 else ADVANCED), -1, None, i_nb, c.conn_trapped != 1
        if c.code == STREAK_CONNECTED:
            return (*self._streak_connected(streak, tb, c, target_q, rng, deadline, st), i_nb, False)
        # tree b's nearest node is at the target: that step in Python
        i_nb = self._twin_of(tb, tb.nearest(target_xi), target_q, rng)
        return (*self.constrained_extend(tb, i_nb, target_xi, target_q, rng, deadline, st), i_nb, False)


def no_nearer(tree: _TaskTree, i_new: int, i_from: int, target_xi: np.ndarray) -> bool:
    """Whether a connection step's node ``i_new`` is no nearer ``target_xi`` in the key than the node ``i_from`` it
    grew from (the squared distances summed coordinate by coordinate, as the native connection sums them). A partial
    step's node keyed across an angle's ±π can be farther than its start in ξ although nearer on the manifold; the
    next step would then grow from the same node toward the same target again, without end."""
    a, b, t = tree.xi[i_new].tolist(), tree.xi[i_from].tolist(), np.asarray(target_xi, float).tolist()
    dn = df = 0.0
    for k in range(len(t)):
        e, f = t[k] - a[k], t[k] - b[k]
        dn += e * e
        df += f * f
    return not dn < df
