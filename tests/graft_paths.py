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


SWEEP = 0.01   # [m] the bench's sweep spacing (no point of the robot or object moves farther between checks)


def truss_case(tcb):
    """The hard truss scene with its checker, closed-chain kinematics and trial generator."""
    from optplan.constraints.closed_chain import ClosedChainKinematics
    from optplan.planners.validity import ValidityChecker
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    scene = Scene.load("hard_truss")
    return scene, ValidityChecker(tcb, scene), ClosedChainKinematics(tcb, scene.object.grasps), TrialGenerator(tcb, scene)


def task_tree(kin, q: np.ndarray):
    """A task-space tree rooted at ``q`` (its object pose)."""
    from optplan.planners.task_space import xi_from_pose
    from optplan.planners.tcbirrt import _TaskTree

    M = kin.object_pose(q)
    return _TaskTree(q, xi_from_pose(M), M.rotation.copy(), M.translation.copy())


def extension_stats() -> dict[str, int]:
    """The counters an extension updates, all zero."""
    return {k: 0 for k in ("ik_iterations", "ik_calls", "ik_failures", "ik_jumps", "collisions", "ik_restarts",
                           "edge_checks", "edge_collisions", "regrasp_attempts", "regrasp_failures", "regrasp_nodes")}


def check_graft_node(pl, tcb, scene, ck, kin, q_root: np.ndarray, a, b, n: int) -> None:
    """Node ``n`` of tree ``a`` hangs below a graft at the root's pose: the graft's configuration is not the
    root's (beyond one restart's joint step) and is reached from the root by one-arm regrasp motions with the
    object fixed; ``n`` lies one step (``step_size`` in ξ) from the root toward ``b``'s root; every
    configuration closes the chain (Pinocchio FK, ≤ 1e-6), is free and in the limits, and every edge passes
    the sweep check at ``SWEEP``."""
    from optplan.constraints.closed_chain import closure_error

    g = int(a.parent[n])
    assert g in a.graft and a.parent[g] == 0 and np.array_equal(a.xi[g], a.xi[0])
    y = a.q[g]
    assert float(np.abs(y - q_root).max()) > pl.options.max_joint_step
    d = b.xi[0] - a.xi[0]
    assert np.allclose(a.xi[n], a.xi[0] + pl.step_size * d / np.linalg.norm(d), atol=1e-9)
    w_fixed, w_held = ck.sweep_weights("fixed", per_geometry=True), ck.sweep_weights("held", per_geometry=True)
    M0 = kin.object_pose(q_root)
    prev = check_regrasp_moves(kin, tcb.nq, a.graft[g], q_root, lambda z: ck.is_valid_object_fixed(z, M0),
                               SWEEP, w_fixed)
    assert np.allclose(prev, y)
    qs = [y, *a.edge[n][0], a.q[n]]
    for q in qs:   # both hands on the object (Pinocchio FK) and free
        assert max(closure_error(tcb, scene.object.grasps, q)) <= 1e-6 and ck.is_valid(q) and ck.in_limits(q)
    for x0, x1 in zip(qs[:-1], qs[1:]):
        assert edge_is_valid(x0, x1, ck.is_valid, SWEEP, weights=w_held)
