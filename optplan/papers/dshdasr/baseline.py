"""The DSHDASR paper (``dshdasr``): the classical baseline and the initial configuration.

* :func:`dls_track` — damped least squares on the joints of both arms (tips only, no obstacles).
* :func:`arm_a_on_swivel`, :func:`initial_configuration` — joints holding the first desired tips
  (the paper's initial joint angles :data:`PAPER_INITIAL_JOINTS_DEG` as the DLS seed).

Public entry point: :mod:`optplan.papers.dshdasr`.
"""
from __future__ import annotations

import math
import time

import numpy as np
import pinocchio as pin

# after .dshdasr_task, which loads .arcs: importing .arcs_arms first fails (the two import each other)
from .arc_models import frame_on
from .task import DshdasrArcs, TrackResult, TransposeTask


# --------------------------------------------------------------------------- DLS baseline
def _tip_errors(arcs: DshdasrArcs, data, pa_goal: pin.SE3, pb, kb):
    Ma, Mb = data.oMf[arcs.fid_a], data.oMf[arcs.fid_b]
    ea = np.r_[pa_goal.translation - Ma.translation, Ma.rotation @ pin.log3(Ma.rotation.T @ pa_goal.rotation)]
    kcur = Mb.rotation[:, 0]
    eb = np.r_[pb - Mb.translation, np.cross(kcur, kb)]
    return ea, eb, kcur


def dls_track(arcs: DshdasrArcs, task: TransposeTask, q0, *, damping: float = 1e-4, tol: float = 1e-9,
              max_iterations: int = 100, max_step: float = 0.2, times=None) -> TrackResult:
    """Classical baseline: damped least squares, ``Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e`` (steps clipped to
    ``max_step`` rad, joints clipped to their limits), on the full joint model of each arm,
    warm-started at every waypoint from the previous joints, iterated until every error component
    is below ``tol``. Arm-a: 6-D pose error (position; exponential coordinates); Arm-b: position
    and pointing direction (error k × k_d against the Jacobian (I − k kᵀ) J_ω). No obstacle
    term: the baseline only tracks the tips."""
    model, data = arcs.model, arcs.model.createData()
    t = task.times() if times is None else np.asarray(times, float)
    des = task.desired(t)
    A, B = arcs.arm_a, arcs.arm_b
    lo, hi = arcs.robot.lower, arcs.robot.upper
    q = np.asarray(q0, float).copy()
    Q = np.zeros((len(t), len(q)))
    iters = np.zeros(len(t), int)
    ok = np.zeros(len(t), bool)
    lam2I = damping ** 2 * np.eye(6)
    t_start = time.perf_counter()
    for k in range(len(t)):
        goal_a = pin.SE3(des["Ra"][k], des["pa"][k])
        it = 0
        for it in range(max_iterations + 1):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            ea, eb, kcur = _tip_errors(arcs, data, goal_a, des["pb"][k], des["kb"][k])
            if max(np.abs(ea).max(), np.abs(eb).max()) < tol:
                ok[k] = True
                break
            if it == max_iterations:
                break
            Ja = pin.getFrameJacobian(model, data, arcs.fid_a, pin.LOCAL_WORLD_ALIGNED)[:, A.v_idx]
            Jb6 = pin.getFrameJacobian(model, data, arcs.fid_b, pin.LOCAL_WORLD_ALIGNED)[:, B.v_idx]
            Jb = np.vstack([Jb6[:3], (np.eye(3) - np.outer(kcur, kcur)) @ Jb6[3:]])
            for arm, J, e in ((A, Ja, ea), (B, Jb, eb)):
                dq = J.T @ np.linalg.solve(J @ J.T + lam2I, e)
                m = np.abs(dq).max()
                if m > max_step:
                    dq *= max_step / m
                q[arm.q_idx] = np.clip(q[arm.q_idx] + dq, lo[arm.j_idx], hi[arm.j_idx])
        iters[k] = it
        Q[k] = q
    runtime = time.perf_counter() - t_start
    return TrackResult("dls", t, Q, des, runtime, iterations=iters, success=ok)


PAPER_INITIAL_JOINTS_DEG = {
    "a": [100.21, 73.88, 7.98, 65.73, 17.31, 51.88, 9.67],
    "b": [0.63, 0.35, 0.26, 2.88, 0.41, 0.34, 1.30, 1.51, 1.24, 8.03],
}


def arm_a_on_swivel(arcs: DshdasrArcs, pa, Ra, swivel: float) -> np.ndarray:
    """Arm-a joints holding the tip pose (pa, Ra) with the elbow at swivel angle ``swivel`` [rad]
    on its circle about the shoulder-wrist line u: measured from the horizontal y = e_z × u toward
    u × y (π/2: elbow up)."""
    A = arcs.a
    w = np.asarray(pa) - A.L7 * np.asarray(Ra)[:, 2]
    v = w - A.shoulder
    D = np.linalg.norm(v)
    if D >= A.L3 + A.L5:
        raise ValueError(f"wrist {D:.3f} m from the shoulder: out of reach")
    F = frame_on(v / D)
    h = math.sqrt(A.L3 ** 2 - (D / 2) ** 2)
    e = A.shoulder + v / 2 + h * (math.cos(swivel) * F[:, 1] + math.sin(swivel) * F[:, 2])
    Xa = A.params_from_points(A.shoulder, e, w, pa, np.asarray(Ra)[:, 2])
    return A.recover_joints(Xa, pa, Ra)


def initial_configuration(arcs: DshdasrArcs, task: TransposeTask, swivel_deg: float | None = 65.0,
                          seed=None, restarts: int = 20, rng_seed: int = 0) -> np.ndarray:
    """Joints holding the first desired tips. Arm-b (and Arm-a when ``swivel_deg`` is None) by DLS
    from ``seed`` — default: the paper's initial joint angles of Section 5.1 as printed (signs lost,
    another D-H zero: only a starting guess) — then from random seeds if that fails. Arm-a at the
    elbow swivel angle ``swivel_deg`` (see :func:`arm_a_on_swivel`; 65° is our choice, see
    docs/dshdasr.md)."""
    if seed is None:
        seed = arcs.q(np.radians(PAPER_INITIAL_JOINTS_DEG["a"]), np.radians(PAPER_INITIAL_JOINTS_DEG["b"]))
    rng = np.random.default_rng(rng_seed)
    q = np.asarray(seed, float)
    for _attempt in range(restarts + 1):
        res = dls_track(arcs, task, q, damping=1e-2, max_iterations=3000, max_step=0.1, times=[0.0])
        if res.success is not None and res.success[0]:
            q = res.q[0]
            if swivel_deg is not None:
                des = task.desired([0.0])
                q[arcs.arm_a.q_idx] = arm_a_on_swivel(arcs, des["pa"][0], des["Ra"][0], math.radians(swivel_deg))
            return q
        q = arcs.robot.random_configuration(rng)
    raise RuntimeError("no initial configuration found for the first waypoint")
