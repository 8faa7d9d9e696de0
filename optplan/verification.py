"""Verify a trajectory independently of the NLP that produced it.

At ``density`` × the knot density (default 10×) the exact joint trajectory of the
:class:`~optplan.problem.Solution` is sampled and checked with Pinocchio and coal only:
closed-chain residual (FK of both hands), exact minimum clearance (coal, robot + held object vs
scene and self), joint position/velocity limit violations, and for a free-floating robot the base
attitude re-integrated by :func:`optplan.model.floating.simulate_base` (momentum residual, and its
difference from the NLP's own base states).

For a free-floating robot the base is never taken from the NLP: it is re-integrated from zero
momentum (from ``base0``, default the identity) and every check — closed chain, clearance, final
attitude — uses the base where momentum puts it. :meth:`VerifyReport.failures` turns the figures
into a verdict against :class:`VerifyTolerances`.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

import numpy as np
import pinocchio as pin

from .collision.checker import CollisionChecker
from .constraints.closed_chain import closure_errors
from .geometry.spatial import rotation_angle
from .model.robot import RobotModel
from .scene import Scene

__all__ = ["VerifyReport", "VerifyTolerances", "verify"]


@dataclass(frozen=True)
class VerifyReport:
    """Figures of :func:`verify` (``nan`` where a check does not apply).

    ``max_closed_chain_residual``: max over samples of max(position error [m], rotation error
    [rad]) of the hands' relative pose; ``min_clearance_m``: smallest exact coal distance and
    ``min_clearance_pair`` its pair; ``max_position_limit_violation`` [rad];
    ``max_velocity_limit_violation`` [rad/s]; ``max_momentum_residual``; ``base_attitude_mismatch_rad``:
    largest angle between the NLP's base attitude and the simulator's at the knots;
    ``final_base_attitude_error_rad``: angle between the final base attitude relative to the initial
    one (simulator) and the target (``verify(end_attitude=...)``, default the identity).
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
    #: a floating robot: (sample times [s], full configurations — the re-integrated base
    #: (XYZ-quaternion), then the joints) of the check; None for a fixed base. Not in :meth:`to_dict`.
    samples: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict:
        out = asdict(self)
        out.pop("samples")
        return out

    def failures(self, tol: VerifyTolerances | None = None) -> list[str]:
        """The checks this report fails against ``tol`` (default :class:`VerifyTolerances`), each
        named with its value and bound; empty when it passes. A figure that is ``nan`` fails only
        where it must exist: the final base attitude of a floating robot when
        ``tol.final_base_attitude_rad`` is set."""
        tol = tol or VerifyTolerances()
        out: list[str] = []

        def over(name: str, value: float, bound: float, unit: str) -> None:
            if not np.isnan(value) and not value <= bound:
                out.append(f"{name} {value:.3g} {unit} > {bound:.3g} {unit}")

        over("closed chain residual", self.max_closed_chain_residual, tol.closed_chain, "m|rad")
        if np.isnan(self.min_clearance_m) or not self.min_clearance_m >= tol.clearance_m:
            out.append(f"clearance {self.min_clearance_m:.3g} m < {tol.clearance_m:.3g} m"
                       + (f" ({self.min_clearance_pair})" if self.min_clearance_pair else ""))
        over("joint position limit violation", self.max_position_limit_violation, tol.position_limit_rad, "rad")
        if tol.velocity_limit_rad_s is not None:
            over("joint velocity limit violation", self.max_velocity_limit_violation, tol.velocity_limit_rad_s,
                 "rad/s")
        if tol.final_base_attitude_rad is not None and self.floating:
            if np.isnan(self.final_base_attitude_error_rad):
                out.append("final base attitude error: not computed")
            else:
                over("final base attitude error", self.final_base_attitude_error_rad, tol.final_base_attitude_rad,
                     "rad")
        return out

    def passed(self, tol: VerifyTolerances | None = None) -> bool:
        """No :meth:`failures` against ``tol``."""
        return not self.failures(tol)

    @property
    def floating(self) -> bool:
        """The report is of a free-floating robot (the base was re-integrated)."""
        return not np.isnan(self.max_momentum_residual)

    def to_json(self) -> str:
        return json.dumps(self.to_dict())


@dataclass(frozen=True)
class VerifyTolerances:
    """Bounds of the verdict :meth:`VerifyReport.failures`."""

    #: largest closed-chain residual (max of position [m] and rotation [rad] error of the hands' relative pose).
    closed_chain: float = 1e-6
    #: smallest exact clearance [m] (0: touching is allowed, penetration is not).
    clearance_m: float = 0.0
    #: largest joint position limit violation [rad].
    position_limit_rad: float = 0.0
    #: largest joint velocity limit violation [rad/s]; None: not checked.
    velocity_limit_rad_s: float | None = 1e-6
    #: largest angle between the final and the initial base attitude of a floating robot, by the independent
    #: re-integration [rad]; None: not checked (a task without restoration).
    final_base_attitude_rad: float | None = 1e-6


_angle = rotation_angle


def verify(robot: RobotModel, solution, scene: Scene | None = None, *, closed_chain=None,
           density: int = 10, held_object: bool = True, object_arm: str | None = None,
           check_velocity: bool = True, base0: pin.SE3 | None = None, end_attitude=None) -> VerifyReport:
    """Check ``solution`` (anything with ``t``, ``sample(t)`` and, for floating robots,
    ``base_quat``) at ``density`` × its knot density. ``closed_chain`` is a
    :class:`~optplan.problem.terms.ClosedChain` (or None). ``base0``: the floating base's placement
    at the start (default the identity); the base along the motion is re-integrated from it with
    zero momentum, whatever the solution says of the base. ``end_attitude``: the final base attitude
    relative to the initial one that the motion must reach (3 × 3 rotation; default the identity,
    i.e. restoration): ``final_base_attitude_error_rad`` is the angle between the two."""
    if int(density) < 1:
        raise ValueError(f"density: expected ≥ 1, got {density}")
    N = len(solution.t) - 1
    ts = np.linspace(solution.t[0], solution.t[-1], N * int(density) + 1)
    smp = solution.sample(ts)
    Q, QD = smp["q"], smp["qd"]
    data = robot.model.createData()
    base_mismatch = final_err = mom = float("nan")
    if robot.is_floating:
        # (imported here: a fixed-base robot's verification does not load it)
        from .model.floating import simulate_base

        sim = simulate_base(robot, (ts, Q, QD), ts, base0=base0, substeps=2)
        qfull = sim.q
        mom = float(sim.momentum_residual.max())
        R0 = pin.XYZQUATToSE3(qfull[0, :7]).rotation
        Rt = np.eye(3) if end_attitude is None else np.asarray(end_attitude, float)
        if Rt.shape != (3, 3) or not np.allclose(Rt.T @ Rt, np.eye(3), atol=1e-9):
            raise ValueError(f"end_attitude: expected a 3 × 3 rotation matrix, got {end_attitude!r}")
        final_err = _angle(Rt.T @ R0.T @ pin.XYZQUATToSE3(qfull[-1, :7]).rotation)
        if getattr(solution, "base_quat", None) is not None:
            knots = np.arange(0, len(ts), int(density))
            mism = []
            for k, i in enumerate(knots):
                x, y, z, w = solution.base_quat[k] / np.linalg.norm(solution.base_quat[k])
                Rn = pin.Quaternion(w, x, y, z).toRotationMatrix()
                mism.append(_angle(Rn.T @ R0.T @ pin.XYZQUATToSE3(qfull[i, :7]).rotation))   # ξ: relative to the start
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
        base_attitude_mismatch_rad=base_mismatch, final_base_attitude_error_rad=final_err,
        samples=(ts, qfull) if robot.is_floating else None)
