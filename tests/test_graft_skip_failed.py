"""``graft_skip_failed``: a branch graft does not search again for a regrasp from a node to a joint solution within
``graft_min_distance`` of one whose regrasp from that node failed; without it the same regrasp is searched again."""
from __future__ import annotations

import numpy as np
import pytest
from graft_paths import task_tree, truss_case

from optplan.planners import TCBiRRT, TCBiRRTOptions
from optplan.planners.base import Deadline


def _stats() -> dict:
    return {"ik_iterations": 0, "ik_calls": 0, "ik_failures": 0, "ik_jumps": 0, "collisions": 0, "ik_restarts": 0,
            "edge_checks": 0, "edge_collisions": 0, "regrasp_attempts": 0, "regrasp_failures": 0, "regrasp_nodes": 0,
            "graft_attempts": 0, "grafts": 0}


@pytest.mark.parametrize("skip", [False, True])
def test_a_failed_graft_regrasp_is_not_searched_again(tcb, skip):
    scene, ck, kin, gen = truss_case(tcb)
    t = gen.generate(1, 0)   # the start root: its IK seeded from the goal tree gives another, valid branch
    pl = TCBiRRT(tcb, scene, TCBiRRTOptions(variant="improved", branch_grafts=4, graft_skip_failed=skip), checker=ck,
                 kinematics=kin)
    pl._rng = np.random.default_rng(3)
    tried: list[np.ndarray] = []

    def failing_regrasp(q_from, q_to, R, p, rng, deadline, st):   # every regrasp fails; its targets recorded
        assert np.array_equal(q_from, a.q[0])
        tried.append(q_to.copy())
        return None

    pl.regrasp = failing_regrasp   # type: ignore[method-assign]
    a, b = task_tree(kin, t.q_start), task_tree(kin, t.q_goal)
    st = _stats()
    for _ in range(4):   # the same node, the same other tree: the first seed's IK solution comes back each time
        assert pl._graft(a, 0, b, Deadline(5.0, "cpu"), st) is None
    assert tried, st   # some solution of another branch was valid (else the case tests nothing)
    d_min = pl.options.graft_min_distance
    close = [(i, j) for i in range(len(tried)) for j in range(i) if np.linalg.norm(tried[i] - tried[j]) < d_min]
    if skip:
        assert not close and st["graft_repeats_skipped"] >= 1
        assert len(a.failed_grafts[0]) == len(tried)
        assert st["graft_regrasp_failures"] == len(tried)
    else:
        assert close and "graft_repeats_skipped" not in st and not a.failed_grafts


def test_the_option_is_checked():
    assert TCBiRRTOptions(variant="improved").graft_skip_failed is True and TCBiRRTOptions().graft_skip_failed is True
    with pytest.raises(ValueError, match="graft_skip_failed"):
        TCBiRRTOptions(graft_skip_failed=1)   # type: ignore[arg-type]
