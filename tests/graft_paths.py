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
