"""TCBiRRT's trees and the path read from them: :class:`_TaskTree` (nodes keyed by the object pose ξ, with
their configurations, object poses, the edges from their parents and other IK branches grown by regrasps) and
:func:`extract_path` (ExtractPath of Alg. 1: the branches of the two trees that met and the connection
between them, as a :class:`~.base.PlanResult` with its constrained and regrasp segments)."""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from .base import PathSegment, PlanResult, PlanStatus
from .kernel.native import pose12 as _pose12
from .tree import Tree

__all__ = ["_TaskTree", "extract_path"]


class _Poses:
    """A task tree's object poses ``(R, p)`` by node, read from its ``pose12`` rows (the one copy of each pose; the
    native code reads the same rows): ``R`` 3 × 3 and ``p`` 3-vector views, read-only."""

    __slots__ = ("_t",)

    def __init__(self, tree: _TaskTree) -> None:
        self._t = tree

    def __len__(self) -> int:
        return self._t.n

    def __getitem__(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        n = self._t.n
        if not -n <= i < n:
            raise IndexError(f"node {i} of a tree of {n} nodes")
        r = self._t.pose12[i % n]
        R, p = r[:9].reshape(3, 3), r[9:]
        R.flags.writeable = p.flags.writeable = False
        return R, p


class _TaskTree(Tree):
    """Nodes keyed by ξ (nearest neighbour), their configurations ``q``, object poses and, per
    node, the edge from its parent: intermediate configurations and object poses (j = 1..N−1)
    of PathInverseKinematics; ``checked``: edge from the parent verified (lazy edges)."""

    q: np.ndarray       # columns the base class creates with setattr
    checked: np.ndarray
    dom: np.ndarray     # per node: its dynamic domain radius or its step (``trap_adapt``); inf: unset
    pose12: np.ndarray  # per node: its object pose as 12 values (rotation row-major, position), for the native code
    trapn: np.ndarray   # per node: trapped extensions from it counted for its trap graft (``trap_grafts``)
    twin: np.ndarray    # per node: whether it has other IK branches at its pose (a key of :attr:`twins`)
    tnext: np.ndarray   # per node in a twin group: the group's next node in :attr:`twins`' order (-1: last, or none)
    thead: np.ndarray   # per node in a twin group: the group's first node (-1: no group), for the native code
    edge: list[Any]     # always kept (edges=True)

    KD_INDEX = True     # nodes are only ever appended (pruned ones are marked dead)

    def __init__(self, q: np.ndarray, xi: np.ndarray, R: np.ndarray, p: np.ndarray, cap: int = 512):
        super().__init__(xi, cap, edges=True, q=q, checked=True, dom=np.inf, pose12=_pose12(R, p),
                         trapn=np.int64(0), twin=False, tnext=np.int64(-1), thead=np.int64(-1))
        #: node → its object pose (R, p), read from :attr:`pose12`
        self.pose = _Poses(self)
        self.edge[0] = ([], [])
        #: graft node → its regrasp motions from the parent's configuration (object fixed at the node's pose)
        self.graft: dict[int, list[tuple[str, list[np.ndarray]]]] = {}
        #: node → the live and dead nodes at the same object pose (itself included), for nodes that have grafts
        self.twins: dict[int, list[int]] = {}
        #: node → the twin an extension from that pose grows from (``branch_roots``: the root's shared-branch graft)
        self.prefer: dict[int, int] = {}
        #: node → the joint solutions a branch graft's regrasp from it failed to reach (``graft_skip_failed``)
        self.failed_grafts: dict[int, list[np.ndarray]] = {}

    @property
    def xi(self) -> np.ndarray:
        return self.X

    def add(self, q: np.ndarray, xi: np.ndarray, R: np.ndarray, p: np.ndarray, parent: int, edge_q: list[np.ndarray], edge_poses: list[tuple[np.ndarray, np.ndarray]]) -> int:  # type: ignore[override]  # a task node needs its q and object pose too; never used as a plain Tree
        return super().add(xi, parent, (edge_q, edge_poses), q=q, checked=False, dom=np.inf, pose12=_pose12(R, p),
                           trapn=0, twin=False, tnext=-1, thead=-1)

    def add_graft(self, i: int, q: np.ndarray, motions: list[tuple[str, list[np.ndarray]]]) -> int:
        """A node at node i's object pose with another joint solution ``q``, reached from node i's
        configuration by the regrasp ``motions``: a second IK branch of the same tree."""
        group = self.twins.setdefault(i, [i])
        k = super().add(self.X[i].copy(), i, ([], []), q=q, checked=False, dom=np.inf, pose12=self.pose12[i],
                        trapn=0, twin=True, tnext=-1, thead=group[0])
        self.graft[k] = motions
        self.tnext[group[-1]] = k      # the group as a list in its arrays: first node, then each one's next
        self.thead[group[0]] = group[0]
        group.append(k)
        self.twins[k] = group
        self.twin[i] = True
        return k

    def twin_nearest(self, i: int, q: np.ndarray | None, rng: np.random.Generator) -> int:
        """Among node i and the live nodes at its pose (other IK branches): the one whose configuration
        is nearest ``q``, or when ``q`` is None the pose's preferred twin (:attr:`prefer`) if live, else a random one."""
        group = self.twins.get(i)
        if group is None:
            return i
        if self.alive is not None:
            group = [k for k in group if self.alive[k]]
        if q is None:
            k = self.prefer.get(i)
            if k is not None and k in group:
                return k
            return int(group[int(rng.integers(len(group)))])
        return int(min(group, key=lambda k: float(np.sum((self.q[k] - q) ** 2))))

    def pieces(self, i: int) -> list[tuple[Any, ...]]:
        """The motion from the root to node i: ``("c", configurations, poses)`` (a constrained edge,
        both ends included) and ``("r", arm, configurations, pose)`` (one arm's regrasp motion)."""
        out: list[tuple[Any, ...]] = []
        idx = self.indices(i)
        for a, k in zip(idx[:-1], idx[1:]):
            if k in self.graft:
                out.extend(("r", arm, full, self.pose[k]) for arm, full in self.graft[k])
            else:
                eq, ep = self.edge[k]
                out.append(("c", [self.q[a].copy(), *(x.copy() for x in eq), self.q[k].copy()],
                            [self.pose[a], *ep, self.pose[k]]))
        return out

    def alive_xi(self) -> np.ndarray:
        return self.live_keys()

    def branch(self, i: int) -> tuple[list[np.ndarray], list[tuple[np.ndarray, np.ndarray]]]:  # type: ignore[override]  # configurations and poses; never used as a plain Tree
        """Configurations and poses from the root to node i (edge intermediates included)."""
        qs, ps = [], []  # type: list[np.ndarray], list[tuple[np.ndarray, np.ndarray]]
        for k in self.indices(i):
            eq, ep = self.edge[k]
            qs.extend(x.copy() for x in eq)
            ps.extend(ep)
            qs.append(self.q[k].copy())
            ps.append(self.pose[k])
        return qs, ps


def _reverse_move(m: tuple[Any, ...]) -> tuple[Any, ...]:
    """A move of :meth:`_TaskTree.pieces` run backwards."""
    if m[0] == "c":
        return ("c", m[1][::-1], m[2][::-1])
    return ("r", m[1], m[2][::-1], m[3])


def extract_path(pl: Any, ta: _TaskTree, tb: _TaskTree, a_is_start: bool,
                 found: tuple[int, int, Sequence[tuple[str | None, list[np.ndarray]]] | None], st: dict[str, Any]) -> PlanResult:
    """ExtractPath: tree-a branch, regrasp (q_b of tree b → q_a of tree a, reversed so the path
    runs start → goal), reversed tree-b branch; regrasp motions of grafts inside either branch
    become ``"regrasp"`` segments too."""
    i_a, i_b, reg = found
    M_I = ta.pose[i_a]
    moves: list[tuple[Any, ...]] = ta.pieces(i_a)
    n_joint = 0
    # the connection was planned from tree b's solution (q_s) to tree a's (q_rand): reversed
    for arm, full in reversed(reg or []):
        full = full[::-1]
        if arm is None:         # joint-space constrained connection (joint_connect): a constrained move
            n_joint += 1
            poses = []
            for x in full:
                M = pl.kin.object_pose(x)
                poses.append((M.rotation.copy(), M.translation.copy()))
            moves.append(("c", full, poses))
        else:
            moves.append(("r", arm, full, M_I))
    moves.extend(_reverse_move(m) for m in reversed(tb.pieces(i_b)))
    q0, pose0 = ta.q[0].copy(), ta.pose[0]
    if not a_is_start:   # tree a grew from the goal: flip everything
        moves = [_reverse_move(m) for m in reversed(moves)]
        q0, pose0 = tb.q[0].copy(), tb.pose[0]
    qs, poses, flags = [q0], [pose0], [True]
    segs: list[tuple[str, int, int, str | None, Any]] = []
    run0 = 0                    # start of the current constrained run
    for m in moves:
        if m[0] == "c":
            qs.extend(m[1][1:])
            poses.extend(m[2][1:])
            flags.extend([True] * (len(m[1]) - 1))
            continue
        _, arm, full, M = m
        i0 = len(qs) - 1
        segs.append(("constrained", run0, i0, None, None))
        qs.extend(full[1:])
        poses.extend([M] * (len(full) - 1))
        flags.extend([False] * (len(full) - 2) + [True])
        segs.append(("regrasp", i0, len(qs) - 1, arm, pin.SE3(np.asarray(M[0]), np.asarray(M[1]))))
        run0 = len(qs) - 1
    segs.append(("constrained", run0, len(qs) - 1, None, None))
    out_segs = [PathSegment(k, a, b, arm, M) for k, a, b, arm, M in segs if b > a]
    st["n_regrasp"] = sum(1 for m in moves if m[0] == "r")
    st["joint_connections"] = n_joint
    return PlanResult(PlanStatus.EXACT, pl.name, np.array(qs),
                      [pin.SE3(np.asarray(R), np.asarray(p)) for R, p in poses], np.array(flags, dtype=bool),
                      out_segs, st)
