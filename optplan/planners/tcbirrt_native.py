"""TCBiRRT's constrained extension (Alg. 2 of the TCBiRRT paper) in one native call per extension.

:func:`make_extender` builds the :class:`~optplan.planners.kernel.extend.NativeExtender` of a
:class:`~optplan.planners.tcbirrt.TCBiRRT` planner when its parts are compiled (the validity checker's
native kernel, the closed-chain IK block, the edge speed profile) and its options are ones the C code
covers; otherwise the planner keeps its Python extension. :func:`native_extend`
and :func:`native_path_ik` are the planner's ``interpolate_task`` + :meth:`~.TCBiRRT.path_ik` with the
same results: the C code runs the waypoints until one fails, the random restarts of that waypoint run
here with the planner's generator (the same draws as the Python extension), and the C code goes on from
the next waypoint; the edges between the accepted configurations are checked in C as
:meth:`~.TCBiRRT._edges_prefix` does (Jacobian spacing), or by that method for the other edge bounds.
"""
from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from .ik_seed import restart_seed
from .kernel.native import KernelUnavailable, pose12
from .rrtconnect import edge_is_valid

if TYPE_CHECKING:
    from .kernel.extend import NativeExtender
    from .tcbirrt import TCBiRRT

__all__ = ["make_extender", "loop_extend", "native_extend", "native_path_ik", "poses_array"]
log = logging.getLogger(__name__)



def make_extender(pl: TCBiRRT) -> NativeExtender | None:
    """The native extension of planner ``pl`` (None: the Python one; why is logged)."""
    o = pl.options
    native_edges = bool(o.edge_tolerance) and not o.lazy_edges and o.edge_bound == "jacobian"
    try:
        from .kernel.extend import NativeExtender

        return NativeExtender(pl.checker, pl.kin, o.ik, cast(float, o.max_joint_step),
                              cast(float, o.edge_tolerance) if native_edges else 0.0, o.edge_resolution,
                              cast(str, o.ik_predictor))
    except KernelUnavailable as e:
        log.info("TCBiRRT extends in Python: %s", e)
        return None


def poses_array(poses: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Object poses ``(R, p)`` as the n × 12 array of the native code (rotation row-major, position [m])."""
    P = np.empty((len(poses), 12))
    for j, (R, p) in enumerate(poses):
        P[j] = pose12(R, p)
    return P


def pose_list(P: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The rows of an n × 12 pose array as ``(R, p)`` views."""
    return [(P[j, :9].reshape(3, 3), P[j, 9:]) for j in range(P.shape[0])]


def _merge(st: dict[str, Any], ext: NativeExtender) -> None:
    """The native counters into the planner's statistics (and the checks into the checker's count); reset."""
    cnt = ext.cnt
    c = cnt.tolist()
    cnt.fill(0)
    st["ik_calls"] += c[0]
    st["ik_iterations"] += c[1]
    st["ik_failures"] += c[2]
    st["ik_jumps"] += c[3]
    st["collisions"] += c[4]
    st["edge_checks"] += c[6]
    st["edge_collisions"] += c[7]
    st["ik_restarts"] += c[9]
    st["ik_path_iterations"] = st.get("ik_path_iterations", 0) + c[10]   # absent in a caller's own counters
    if c[11]:
        st["ik_restarts_skipped"] = st.get("ik_restarts_skipped", 0) + c[11]
    if c[12]:
        st["ik_restart_iterations"] = st.get("ik_restart_iterations", 0) + c[12]
    if c[13]:
        st["pose_blocked"] = st.get("pose_blocked", 0) + c[13]
    ext.checker.n_checks += c[5]


def native_extend(pl: TCBiRRT, R0: np.ndarray, p0: np.ndarray, R1: np.ndarray, p1: np.ndarray, q_near: np.ndarray,
                  st: dict[str, Any], prefix: bool) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[np.ndarray] | None]:
    """``interpolate_task`` (geodesic) from ``(R0, p0)`` to ``(R1, p1)`` and :meth:`~.TCBiRRT.path_ik` from
    ``q_near``: ``(poses, configurations)`` as the Python code returns them."""
    ext = cast("NativeExtender", pl._ext)
    n = pl.options.n_interp
    P, Q, r, edge_k = ext.extend(R0, p0, R1, p1, n, q_near)
    return pose_list(P), native_path_ik(pl, P, q_near, st, prefix, (Q, r, edge_k))


def loop_extend(pl: TCBiRRT, R0: np.ndarray, p0: np.ndarray, R1: np.ndarray, p1: np.ndarray, q_near: np.ndarray,
                st: dict[str, Any], prefix: bool) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[np.ndarray] | None]:
    """:func:`native_extend` in one call for ``extension="loop"`` (restarts in C, Jacobian-spaced edges):
    ``(poses, configurations)`` as the Python code returns them."""
    ext: NativeExtender = pl._ext   # type: ignore[assignment]  # set when the loop runs (no cast per call)
    P, Q, k = ext.extend_prefix(R0, p0, R1, p1, pl.options.n_interp, q_near, prefix)
    _merge(st, ext)
    if k <= 0:   # trapped (most extensions on the hard scenes): the caller reads no pose
        return [], (None if k < 0 else [])
    return pose_list(P), list(Q[:k])


def native_path_ik(pl: TCBiRRT, P: np.ndarray, q_near: np.ndarray, st: dict[str, Any], prefix: bool = False,
                   first: tuple[np.ndarray, int, int] | None = None) -> list[np.ndarray] | None:
    """:meth:`~.TCBiRRT.path_ik` of the poses ``P`` (n × 12) from ``q_near``; ``first``: the result of
    :meth:`~.NativeExtender.extend` for these poses when already run."""
    ext = cast("NativeExtender", pl._ext)
    o, ck, kin = pl.options, pl.checker, pl.kin
    n = P.shape[0]
    if first is None:
        Q = np.empty((n, ext.nq))
        r, edge_k = ext.path_ik(P, 0, q_near, Q), -1
    else:
        Q, r, edge_k = first
    mjs = cast(float, o.max_joint_step)
    while r < n:                      # waypoint r failed (counted in C): the random restarts, as path_ik
        q = q_near if r == 0 else Q[r - 1]
        R, p = P[r, :9].reshape(3, 3), P[r, 9:]
        qn = None
        terminal = ext.terminal() or ext.native_restarts   # no restarts after a failed segment, or run in C
        for i in range(0 if terminal else cast(int, o.ik_restarts)):
            st["ik_restarts"] += 1
            x, its = kin.ik(restart_seed(q, pl._rng, o, i), R, p, pl._ik_restart)
            st["ik_iterations"] += its
            st["ik_restart_iterations"] = st.get("ik_restart_iterations", 0) + its
            if x is not None and float(np.abs(x - q).max()) <= mjs and ck.in_limits(x) and ck.is_valid(x):
                qn = x
                break
        if qn is not None and o.edge_resolution is not None and \
                not edge_is_valid(q, qn, ck.is_valid, o.edge_resolution, False):
            st["collisions"] += 1
            qn = None
        if qn is None:
            if not prefix:
                _merge(st, ext)
                return None
            n = r                      # the valid prefix
            break
        Q[r] = qn
        r = ext.path_ik(P, r + 1, qn, Q, q)
        edge_k = -1
    out = list(Q[:n])
    if ext.edge_on:
        if edge_k < 0 or n < P.shape[0]:
            edge_k = ext.edges(q_near, Q, n)
        _merge(st, ext)
        if edge_k < n:
            return None if not prefix else out[:edge_k]
        return out
    _merge(st, ext)
    return pl._edges_prefix(q_near, out, out if prefix else None, st)
