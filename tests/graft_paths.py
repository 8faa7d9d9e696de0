"""Checks shared by the graft tests: a regrasp (one arm's joint path after another's, the other
joints untouched) starts where the tree left off and every edge of it passes the validity sweep."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from optplan.planners.rrtconnect import edge_is_valid


def check_regrasp_moves(kin, nq: int, moves, start: np.ndarray, valid: Callable[[np.ndarray], bool],
                        sweep: float, weights) -> np.ndarray:
    """Walk ``moves`` = [(arm, joint path), ...] from ``start``: each path starts at the previous
    end, moves only its arm's joints, and every edge is valid by ``edge_is_valid`` at ``sweep``
    [m] (no point moves farther between checks); returns the last configuration."""
    prev = start
    for arm, full in moves:
        idx = kin.idx[kin.arm_names.index(arm)]
        other = np.setdiff1d(np.arange(nq), idx)
        assert np.allclose(full[0], prev) and all(np.array_equal(q[other], prev[other]) for q in full)
        for q0, q1 in zip(full[:-1], full[1:]):
            assert edge_is_valid(q0, q1, valid, sweep, weights=weights)
        prev = full[-1]
    return prev


def check_planned_path(tcb, scene, ck, res, q_start: np.ndarray, q_goal: np.ndarray) -> None:
    """A planner's returned path: from ``q_start`` to ``q_goal``, every configuration in the joint
    limits, the constrained ones on the closed chain (Pinocchio FK, ≤ 1e-6) and collision-free, and the
    benchmark's sweep of every edge valid."""
    from optplan.bench.tcbirrt import _path_checks
    from optplan.constraints.closed_chain import closure_error

    assert np.allclose(res.path[0], q_start) and np.allclose(res.path[-1], q_goal)
    for q, c in zip(res.path, res.constrained):
        assert ck.in_limits(q)
        if c:
            assert max(closure_error(tcb, scene.object.grasps, q)) <= 1e-6 and ck.is_valid(q)
    chk = _path_checks(tcb, scene, ck, res)
    assert chk["swept_invalid_edges"] == 0 and chk["max_closed_chain_residual"] <= 1e-6
