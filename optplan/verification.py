"""Verify a trajectory independently of the NLP that produced it.

At ``density`` × the knot density (default 10×) the exact joint trajectory of the
:class:`~optplan.problem.Solution` is sampled and checked with Pinocchio and coal only:
closed-chain residual (FK of both hands), exact minimum clearance (coal, robot + held object vs
scene and self), joint position/velocity limit violations, and for a free-floating robot the base
attitude re-integrated by :func:`optplan.model.floating.simulate_base` (momentum residual, and its
difference from the NLP's own base states).
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass

import numpy as np
import pinocchio as pin

from .collision.checker import CollisionChecker
from .constraints.closed_chain import closure_errors
from .geometry.spatial import rotation_angle
from .model.floating import simulate_base
from .model.robot import RobotModel
from .scene import Scene

__all__ = ["VerifyReport", "verify"]


@dataclass(frozen=True)
class VerifyReport:
    """Figures of :func:`verify` (``nan`` where a check does not apply).

    ``max_closed_chain_residual``: max over samples of max(position error [m], rotation error
    [rad]) of the hands' relative pose; ``min_clearance_m``: smallest exact coal distance and
    ``min_clearance_pair`` its pair; ``max_position_limit_violation`` [rad];
    ``max_velocity_limit_violation`` [rad/s]; ``max_momentum_residual``; ``base_attitude_mismatch_rad``:
    largest angle between the NLP's base attitude and the simulator's at the knots;
    ``final_base_attitude_error_rad``: angle between final and initial base attitude (simulator).
    """

    n_samples: int
    max_closed_chain_residual: float
    max_closed_chain_position_error_m: float
    max_closed_chain_rotation_error_rad: float
    min_clearance_m: float
    min_clearance_pair: str
    max_position_limit_violation: float
    max_velocity_limit_violation: float
    max_momentum_residual: float
    base_attitude_mismatch_rad: float
    final_base_attitude_error_rad: float

    def to_dict(self) -> dict:
        return asdict(self)

    def to_json(self) -> str:
        return json.dumps(self.to_dict())


_angle = rotation_angle


def verify(robot: RobotModel, solution, scene: Scene | None = None, *, closed_chain=None,
           density: int = 10, held_object: bool = True, object_arm: str | None = None,
           check_velocity: bool = True) -> VerifyReport:
    """Check ``solution`` (anything with ``t``, ``sample(t)`` and, for floating robots,
    ``base_quat``) at ``density`` × its knot density. ``closed_chain`` is a
    :class:`~optplan.problem.terms.ClosedChain` (or None)."""
    if int(density) < 1:
        raise ValueError(f"density: expected ≥ 1, got {density}")
    N = len(solution.t) - 1
    ts = np.linspace(solution.t[0], solution.t[-1], N * int(density) + 1)
    smp = solution.sample(ts)
    Q, QD = smp["q"], smp["qd"]
    data = robot.model.createData()
    base_mismatch = final_err = mom = float("nan")
    if robot.is_floating:
        sim = simulate_base(robot, (ts, Q, QD), ts, substeps=2)
        qfull = sim.q
        mom = float(sim.momentum_residual.max())
        R0 = pin.XYZQUATToSE3(qfull[0, :7]).rotation
        final_err = _angle(R0.T @ pin.XYZQUATToSE3(qfull[-1, :7]).rotation)
        if getattr(solution, "base_quat", None) is not None:
            knots = np.arange(0, len(ts), int(density))
            mism = []
            for k, i in enumerate(knots):
                x, y, z, w = solution.base_quat[k] / np.linalg.norm(solution.base_quat[k])
                Rn = pin.Quaternion(w, x, y, z).toRotationMatrix()
                mism.append(_angle(Rn.T @ pin.XYZQUATToSE3(qfull[i, :7]).rotation))
            base_mismatch = float(max(mism))
    else:
        qfull = Q
    # closed chain
    cc_p = cc_r = float("nan")
    if closed_chain is not None:
        ep, er = closure_errors(robot, closed_chain, qfull, data)
        cc_p, cc_r = float(ep.max()), float(er.max())
    # clearance: exactly the smallest coal distance over the samples
    # the exact geometry when the robot plans on fitted primitives (robot.judge)
    checker = CollisionChecker.shared(robot.judge, scene, object_arm=object_arm,
                                      held_object=held_object and scene is not None and scene.object is not None)
    dmin, pair, _ = checker.min_distance_along(qfull)
    pair_name = "" if pair is None else f"{pair.name_a} / {pair.name_b}"
    # limits
    pos_v = float(np.max(np.maximum(np.maximum(robot.lower - Q, Q - robot.upper), 0.0)))
    vel_v = float(np.max(np.maximum(np.abs(QD) - robot.velocity_limit, 0.0))) if check_velocity else float("nan")
    return VerifyReport(
        n_samples=len(ts), max_closed_chain_residual=max(cc_p, cc_r) if closed_chain is not None else float("nan"),
        max_closed_chain_position_error_m=cc_p, max_closed_chain_rotation_error_rad=cc_r,
        min_clearance_m=dmin, min_clearance_pair=pair_name, max_position_limit_violation=pos_v,
        max_velocity_limit_violation=vel_v, max_momentum_residual=mom,
        base_attitude_mismatch_rad=base_mismatch, final_base_attitude_error_rad=final_err)
