"""Frontier grafts of TCBiRRT (:mod:`optplan.planners.frontier_graft`): at a tree's frontier the arms re-grasp
into an IK solution from which a constrained step toward the other tree passes. Checked against
Pinocchio FK (the closed chain), the checker's exact collision queries at every configuration and the
bench's 1 cm sweep spacing along every straight edge."""
from __future__ import annotations

import numpy as np
import pytest
from graft_paths import (
    check_graft_node,
    check_planned_path,
    task_tree,
    truss_case,
)

from optplan.planners import TCBiRRT, TCBiRRTOptions
from optplan.planners.base import Deadline
from optplan.planners.frontier_graft import closest_pair, frontier_graft
from optplan.planners.task_space import xi_from_pose


@pytest.fixture(scope="module")
def truss(tcb):
    scene, ck, kin, gen = truss_case(tcb)
    return scene, ck, kin, gen.generate(6, 0)


def test_closest_pair_is_the_closest_of_the_sampled_pairs(tcb, truss, rng):
    scene, ck, kin, t = truss
    a, b = task_tree(kin, t.q_start), task_tree(kin, t.q_goal)
    for _ in range(30):   # random nodes (poses only matter here)
        q = rng.uniform(tcb.lower, tcb.upper)
        for tr in (a, b):
            M = kin.object_pose(q)
            xi = xi_from_pose(M) + rng.normal(0.0, 0.5, 6)
            tr.add(q, xi, M.rotation, M.translation, 0, [], [])
    i, j = closest_pair(a, b, np.random.default_rng(1), pairs=10_000)   # every node of b sampled: the closest pair
    D = np.linalg.norm(a.xi[:a.n, None] - b.xi[None, :b.n], axis=2)
    assert D[i, j] == pytest.approx(D.min())


def test_frontier_graft_regrasps_into_a_configuration_that_steps_toward_the_other_tree(tcb, truss):
    """From the start of a truss trial toward its goal: the new node lies one step (``step_size`` in ξ) toward
    the goal tree's root, below a graft at the start's pose whose configuration closes the chain, is free and is
    not the start's (beyond one restart's joint step); the graft's regrasp motions each move one arm with the
    object fixed, and every edge (regrasp motions and the constrained step) passes the 1 cm sweep check."""
    scene, ck, kin, t = truss
    pl = TCBiRRT(tcb, scene, TCBiRRTOptions(variant="improved", frontier_grafts=4), checker=ck, kinematics=kin)
    pl._rng = np.random.default_rng(3)
    a, b = task_tree(kin, t.q_start), task_tree(kin, t.q_goal)
    st = {"ik_iterations": 0, "ik_calls": 0, "ik_failures": 0, "ik_jumps": 0, "collisions": 0, "ik_restarts": 0,
          "edge_checks": 0, "edge_collisions": 0, "regrasp_attempts": 0, "regrasp_failures": 0, "regrasp_nodes": 0}
    n = None
    for _ in range(10):
        n = frontier_graft(pl, a, b, Deadline(5.0, "cpu"), st)
        if n is not None:
            break
    assert n is not None, st
    check_graft_node(pl, tcb, scene, ck, kin, t.q_start, a, b, n)
    assert st["frontier_grafts"] == 1 and st["frontier_attempts"] >= 1


def test_frontier_options_are_checked():
    assert TCBiRRTOptions(variant="improved").frontier_grafts == 4 and TCBiRRTOptions().frontier_grafts == 0
    for bad in (dict(frontier_grafts=-1), dict(frontier_interval=0), dict(frontier_seeds=0), dict(frontier_pairs=0),
                dict(frontier_radius=-0.1),
                dict(graft_node="frontier"), dict(graft_branch_seeds=1)):
        with pytest.raises(ValueError, match=next(iter(bad))):
            TCBiRRTOptions(**bad)


def test_planner_with_frontier_grafts_returns_a_verified_path(tcb, truss):
    """The search with frontier grafts from iteration 50 (``graft_after=0``; branch grafts off) on a truss trial
    whose trees stop at the grid from either side: a path from start to goal whose constrained configurations
    close the chain (Pinocchio FK) and are free, every straight edge passes the bench's independent 1 cm sweep
    check, and each regrasp segment moves one arm with the object still."""
    from optplan.trials import TrialGenerator

    scene, ck, kin, _ = truss
    t = TrialGenerator(tcb, scene).generate(18, 0)
    pl = TCBiRRT(tcb, scene, TCBiRRTOptions(variant="improved", graft_after=0, branch_grafts=0), checker=ck,
                 kinematics=kin)
    res = pl.plan(t.q_start, t.q_goal, time_limit=30.0, seed=t.seed, clock="cpu")
    assert res.success, res.message
    assert res.stats["frontier_attempts"] >= 1 and res.stats["grafts"] == 0
    check_planned_path(tcb, scene, ck, res, t.q_start, t.q_goal)
    regs = [s for s in res.segments if s.kind == "regrasp"]
    assert len(regs) == res.n_regrasp >= 2
    for s in regs:
        P = res.path[s.start:s.stop + 1]
        moved = [a for a, idx in zip(kin.arm_names, kin.idx) if np.ptp(P[:, idx], axis=0).max() > 0]
        assert moved == [s.arm]
        for M in res.object_poses[s.start:s.stop + 1]:
            assert np.allclose(M.homogeneous, s.object_pose.homogeneous)
