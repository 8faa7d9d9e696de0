"""A trajectory sampled numerically for the terms' Pinocchio twins: joint positions, rates and
accelerations at the points a term is evaluated, with the frames' placements from one forward
kinematics per point (:class:`NumericTrajectory`), and the pose residuals written on those
placements (position error; ``vee(E − Eᵀ)/2`` of ``E = R_targetᵀ R``)."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..geometry.spatial import pose_residual
from ..model.floating import base_frame_coms
from ..model.robot import RobotModel

__all__ = ["NumericTrajectory", "pose_residual_numeric", "pose_residuals"]


def pose_residual_numeric(M: pin.SE3, target: pin.SE3) -> tuple[np.ndarray, float]:
    """:func:`~optplan.geometry.spatial.pose_residual` of a placement against a target placement (numpy)."""
    return pose_residual(M.rotation, M.translation, target.rotation, target.translation)


@dataclass
class NumericTrajectory:
    """Knot values for numeric term evaluation: ``q`` (N+1, nj), ``qd``, ``qdd``, ``jerk`` (N, nj),
    ``T`` [s], ``base_quat`` (N+1, 4) for floating robots (base position from the fixed CoM)."""

    robot: RobotModel
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    jerk: np.ndarray
    T: float
    base_quat: np.ndarray | None = None
    com0: np.ndarray | None = None
    _data: pin.Data | None = field(default=None, repr=False)
    #: knots pinned by a JointBoundary (k -> q), as ``Transcription.pinned_q``
    pinned_q: dict[int, np.ndarray] = field(default_factory=dict)

    @property
    def N(self) -> int:
        return self.q.shape[0] - 1

    @property
    def h(self) -> float:
        return self.T / self.N

    def q_full(self, k: int) -> np.ndarray:
        r = self.robot
        if not r.is_floating:
            return self.q[k]
        assert self.base_quat is not None  # narrowing only: a floating robot's trajectory has base_quat
        quat = self.base_quat[k] / np.linalg.norm(self.base_quat[k])
        qf = np.concatenate([np.zeros(3), quat, self.q[k]])
        data = self.data
        c_b = pin.centerOfMass(r.model, data, np.concatenate([np.zeros(3), [0, 0, 0, 1.0], self.q[k]]))
        R = pin.Quaternion(quat[3], quat[0], quat[1], quat[2]).toRotationMatrix()
        qf[:3] = (self.com0 if self.com0 is not None else np.zeros(3)) - R @ c_b
        return qf

    def configurations(self) -> np.ndarray:
        """Every point's configuration in Pinocchio's layout, (N+1, nq): :meth:`q_full` of every
        point at once (the centre of mass of a floating robot's points by one compiled kernel,
        :func:`~optplan.model.floating.base_frame_coms`, or Pinocchio per point; the rest
        vectorised)."""
        r = self.robot
        if not r.is_floating:
            return np.asarray(self.q, float)
        assert self.base_quat is not None  # narrowing only: a floating robot's trajectory has base_quat
        n = self.q.shape[0]
        quat = np.asarray(self.base_quat, float)
        quat = quat / np.linalg.norm(quat, axis=1, keepdims=True)
        out = np.empty((n, 7 + self.q.shape[1]))
        out[:, :6] = 0.0
        out[:, 6] = 1.0
        out[:, 7:] = self.q
        model, data, com = r.model, self.data, pin.centerOfMass
        c_b = base_frame_coms(r, self.q)                              # the CoM in the base frame
        if c_b is None:
            c_b = np.array([com(model, data, qi) for qi in out])
        x, y, z, w = quat.T
        # R(quat) c_b = c_b + 2 w (v × c_b) + 2 v × (v × c_b), v = (x, y, z)
        v = quat[:, :3]
        vc = np.cross(v, c_b)
        out[:, :3] = (self.com0 if self.com0 is not None else np.zeros(3)) - (c_b + 2.0 * w[:, None] * vc
                                                                             + 2.0 * np.cross(v, vc))
        out[:, 3:7] = quat
        return out

    @property
    def data(self) -> pin.Data:
        """The Pinocchio ``Data`` the kinematics are computed in: the robot's own scratch ``Data``
        unless one was given (making one per trajectory cost a dense check up to 4 ms)."""
        if self._data is None:
            self._data = self.robot.data
        return self._data

    def _point_q(self, k: int | tuple[int, float]) -> np.ndarray:
        """The configuration (Pinocchio layout) at knot k or interior point (interval, fraction)."""
        if isinstance(k, tuple):
            i, f = k
            tau = f * self.h
            return self.q[i] + tau * self.qd[i] + tau**2 / 2 * self.qdd[i] + tau**3 / 6 * self.jerk[i]
        return self.q_full(k)

    def frame(self, frame: str | int, k: int | tuple[int, float]) -> pin.SE3:
        """Frame placement at knot k (int) or interior point (interval, fraction) (fixed base)."""
        fid = self.robot.frame_id(frame)
        pin.framesForwardKinematics(self.robot.model, self.data, self._point_q(k))
        return self.data.oMf[fid].copy()

    def placements(self, frames: Sequence[str | int], points: Sequence[int | tuple[int, float]]
                   ) -> list[tuple[np.ndarray, np.ndarray]]:
        """World placements of ``frames`` at ``points`` (knots or (interval, fraction)), one
        forward kinematics per point for all frames (Pinocchio): per frame ``(R (n, 3, 3), p (n, 3)
        [m])`` — what :meth:`frame` gives point by point, for vectorised residuals."""
        model, data = self.robot.model, self.data
        fids = [self.robot.frame_id(f) for f in frames]
        H = np.empty((len(fids), len(points), 4, 4))
        fk, update = pin.forwardKinematics, pin.updateFramePlacement
        for i, k in enumerate(points):
            fk(model, data, self._point_q(k))
            for j, fid in enumerate(fids):
                H[j, i] = update(model, data, fid).homogeneous   # one array from Pinocchio per frame
        return [(np.ascontiguousarray(H[j, :, :3, :3]), np.ascontiguousarray(H[j, :, :3, 3])) for j in range(len(fids))]


def pose_residuals(R: np.ndarray, p: np.ndarray, R_target: np.ndarray, p_target: np.ndarray) -> np.ndarray:
    """:func:`~optplan.geometry.spatial.pose_residual` of n placements at once: rows
    ``[p − p_t (3) [m]; vee_skew(E) (3); trace(E)]`` (n × 7) with ``E = R_tᵀ R``; ``R`` (n, 3, 3),
    ``p`` (n, 3), a target (3, 3), (3,) or one per placement (n, 3, 3), (n, 3)."""
    Rt = np.asarray(R_target, float)
    E = np.einsum("ji,njk->nik", Rt, R) if Rt.ndim == 2 else np.einsum("nji,njk->nik", Rt, R)
    vee = 0.5 * np.stack([E[:, 2, 1] - E[:, 1, 2], E[:, 0, 2] - E[:, 2, 0], E[:, 1, 0] - E[:, 0, 1]], axis=1)
    return np.hstack([p - np.asarray(p_target, float), vee, np.trace(E, axis1=1, axis2=2)[:, None]])
