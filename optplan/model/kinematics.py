"""Numeric kinematics with Pinocchio: frame placements and Jacobians, the centroidal momentum
matrix, base twist from joint rates (momentum conservation) and the generalized Jacobian.

Frames and units
----------------
* Jacobians are 6 × nv with rows ``[linear (3) [m/s]; angular (3) [rad/s]]``. ``reference`` is
  ``"world_aligned"`` (Pinocchio LOCAL_WORLD_ALIGNED: velocity of the frame origin, world axes;
  the default), ``"local"`` (frame axes) or ``"world"`` (spatial velocity at the world origin).
* The centroidal momentum matrix ``Ag`` (6 × nv) maps ``v`` to ``h = [p (3) [kg m/s]; L (3)
  [kg m²/s]]``, the momentum about the centre of mass in world axes (``pin.computeCentroidalMap``).
* Base velocities of a floating robot are in the base's own frame (Pinocchio's free-flyer ``v``).
"""
from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ConfigurationError, OptionError, check_vector
from .robot import Arm, RobotModel

__all__ = ["Kinematics", "REFERENCE_FRAMES"]

REFERENCE_FRAMES = {
    "world_aligned": pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
    "local": pin.ReferenceFrame.LOCAL,
    "world": pin.ReferenceFrame.WORLD,
}

#: LAPACK's dgesv, imported on first use
_dgesv: Any = None


def _base_coupling(Ag: np.ndarray) -> np.ndarray:
    """``Ag_b⁻¹ Ag_m`` (6 × nj) with LAPACK's dgesv directly (numpy.linalg.solve costs ~2× more
    for a 6 × 6 system, which dominates the generalized Jacobian); scipy.linalg imported here, on
    first use (~0.1 s of start-up that a fixed-base plan does not need)."""
    global _dgesv
    if _dgesv is None:
        from scipy.linalg.lapack import dgesv

        _dgesv = dgesv
    _, _, K, info = _dgesv(Ag[:, :6], Ag[:, 6:])
    if info != 0:
        raise np.linalg.LinAlgError(f"singular base block of the centroidal map (dgesv info={info})")
    return K


def _ref(reference: str) -> pin.ReferenceFrame:
    try:
        return REFERENCE_FRAMES[reference]
    except (KeyError, TypeError):
        raise OptionError(f"reference: expected one of {sorted(REFERENCE_FRAMES)}, got {reference!r}") from None


class Kinematics:
    """Numeric kinematics of a :class:`RobotModel` (owns one ``pin.Data``; not thread-safe)."""

    def __init__(self, robot: RobotModel):
        self.robot = robot
        self.model = robot.model
        self.data = robot.model.createData()

    # ------------------------------------------------------------------ placements, Jacobians
    def frame_placement(self, q, frame: str | int) -> pin.SE3:
        """World placement of ``frame`` at configuration ``q``."""
        q = self.robot.check_q(q)
        fid = self.robot.frame_id(frame)
        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[fid].copy()

    def frame_placements(self, q, frames) -> list[pin.SE3]:
        """World placements of several frames with one forward-kinematics pass."""
        q = self.robot.check_q(q)
        fids = [self.robot.frame_id(f) for f in frames]
        pin.framesForwardKinematics(self.model, self.data, q)
        return [self.data.oMf[f].copy() for f in fids]

    def frame_jacobian(self, q, frame: str | int, reference: str = "world_aligned") -> np.ndarray:
        """6 × nv frame Jacobian (rows linear; angular) in ``reference`` (see module doc)."""
        q = self.robot.check_q(q)
        fid = self.robot.frame_id(frame)
        return pin.computeFrameJacobian(self.model, self.data, q, fid, _ref(reference))

    # ------------------------------------------------------------------ momentum
    def centroidal_map(self, q) -> np.ndarray:
        """Centroidal momentum matrix Ag (6 × nv), momentum about the CoM in world axes."""
        q = self.robot.check_q(q)
        return pin.computeCentroidalMap(self.model, self.data, q).copy()

    def momentum(self, q, v) -> np.ndarray:
        """Centroidal momentum ``[p; L]`` at (q, v) with Pinocchio's recursive algorithm."""
        q, v = self.robot.check_q(q), self.robot.check_v(v)
        h = pin.computeCentroidalMomentum(self.model, self.data, q, v)
        return np.concatenate([h.linear, h.angular])

    def center_of_mass(self, q) -> np.ndarray:
        """World position of the system CoM [m]."""
        return pin.centerOfMass(self.model, self.data, self.robot.check_q(q)).copy()

    def _require_floating(self, what: str) -> None:
        if not self.robot.is_floating:
            raise ConfigurationError(f"{what} needs a free-floating robot; {self.robot.name!r} has a fixed base")

    def base_velocity(self, q, joint_rates, h0=None) -> np.ndarray:
        """Base twist ``[v; ω]`` (base frame) [m/s, rad/s] that keeps the momentum equal to ``h0``
        (default 0) while the joints move at ``joint_rates`` [rad/s]:
        ``Ag[:, :6] v_b + Ag[:, 6:] q̇ = h0``."""
        self._require_floating("base_velocity")
        qd = self.robot.check_joints(joint_rates, "joint_rates")
        h0 = np.zeros(6) if h0 is None else check_vector(h0, 6, "h0 (momentum [p; L])")
        Ag = self.centroidal_map(q)
        return np.linalg.solve(Ag[:, :6], h0 - Ag[:, 6:] @ qd)

    def full_velocity(self, q, joint_rates, h0=None) -> np.ndarray:
        """Full ``v`` (base twist from momentum conservation, then joint rates)."""
        if not self.robot.is_floating:
            return self.robot.check_joints(joint_rates, "joint_rates").copy()
        return np.concatenate([self.base_velocity(q, joint_rates, h0), np.asarray(joint_rates, float)])

    def generalized_jacobian(self, q, arm: str | None = None, frame: str | int | None = None,
                             arm_columns: bool = False) -> np.ndarray:
        """Generalized Jacobian J* = J_m − J_b Ag_b⁻¹ Ag_m of an end-effector (zero momentum).

        Maps the actuated joint rates (all ``nj``, or only the arm's own columns when
        ``arm_columns``) to the end-effector twist ``[v; ω]`` of the frame origin in **world
        axes** (LOCAL_WORLD_ALIGNED) of a free-floating robot whose base moves so that the
        momentum stays zero. (Same as SPART's Jstar / SpaceDyn's calc_gj, up to their frames;
        Ag_b⁻¹ Ag_m = H_b⁻¹ H_bm.) For a fixed-base robot it is the ordinary Jacobian.
        """
        q = self.robot.check_q(q)
        a: Arm | None
        if frame is None:
            if arm is None:
                raise ValueError("generalized_jacobian: give an arm name or a frame")
            a = self.robot.arm(arm)
            fid = a.ee_frame_id
        else:
            a = self.robot.arm(arm) if arm is not None else None
            fid = self.robot.frame_id(frame)
        J = pin.computeFrameJacobian(self.model, self.data, q, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        if self.robot.is_floating:
            J = J[:, 6:] - J[:, :6] @ _base_coupling(pin.computeCentroidalMap(self.model, self.data, q))
        if arm_columns:
            if a is None:
                raise ValueError("arm_columns=True needs an arm name")
            return J[:, a.j_idx]
        return J

    def generalized_jacobians(self, q) -> dict[str, np.ndarray]:
        """J* (6 × nj, world axes) of every arm's end-effector, sharing one forward pass and one
        ``Ag_b⁻¹ Ag_m`` solve."""
        q = self.robot.check_q(q)
        m, d = self.model, self.data
        LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        if self.robot.is_floating:
            K = _base_coupling(pin.computeCentroidalMap(m, d, q))  # also runs forward kinematics
            pin.computeJointJacobians(m, d)  # reuses the placements just computed
        else:
            pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacements(m, d)
        arms = list(self.robot.arms.values())
        J = np.empty((6 * len(arms), self.robot.nv))
        for i, a in enumerate(arms):  # one stacked product instead of one per arm
            J[6 * i:6 * i + 6] = pin.getFrameJacobian(m, d, a.ee_frame_id, LWA)
        G = J[:, 6:] - J[:, :6] @ K if self.robot.is_floating else J
        out = {a.name: G[6 * i:6 * i + 6] for i, a in enumerate(arms)}
        return out
