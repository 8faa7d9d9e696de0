"""Rotation and rigid-transform conventions — the one place where they are defined.

Internally optplan uses rotation matrices and :class:`pinocchio.SE3`. Angles are converted only at
the edges, and every converter names its convention:

* ``rpy`` (roll-pitch-yaw, Pinocchio's ``rpyToMatrix``): ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``,
  argument order ``(roll, pitch, yaw)`` [rad].
* ``zyx`` (Z-Y-X Euler, as in seed 004's Eq. 1 ``[αz, αy, αx]``): ``R = Rz(a) @ Ry(b) @ Rx(c)``,
  argument order ``(a, b, c)`` [rad]. Same matrix as ``rpy(c, b, a)``.
* exponential coordinates ``log3``/``exp3`` (rotation vector, [rad]) for interpolation.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

__all__ = [
    "rotx", "roty", "rotz", "rpy_to_matrix", "matrix_to_rpy", "zyx_to_matrix", "matrix_to_zyx",
    "exp3", "log3", "se3", "pose_to_vector_rpy", "interpolate_pose", "rotation_angle",
]


def rotx(a: float) -> np.ndarray:
    """Rotation about x by ``a`` [rad]."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def roty(a: float) -> np.ndarray:
    """Rotation about y by ``a`` [rad]."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotz(a: float) -> np.ndarray:
    """Rotation about z by ``a`` [rad]."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """``Rz(yaw) Ry(pitch) Rx(roll)`` from roll, pitch, yaw [rad]."""
    return rotz(yaw) @ roty(pitch) @ rotx(roll)


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rpy_to_matrix`: ``(roll, pitch, yaw)`` [rad], pitch in [-π/2, π/2]."""
    return np.asarray(pin.rpy.matrixToRpy(np.asarray(R, dtype=float)))


def zyx_to_matrix(a: float, b: float, c: float) -> np.ndarray:
    """``Rz(a) Ry(b) Rx(c)`` [rad] — seed 004's ``[αz, αy, αx]`` order."""
    return rotz(a) @ roty(b) @ rotx(c)


def matrix_to_zyx(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`zyx_to_matrix`: ``(a, b, c)`` [rad]."""
    return matrix_to_rpy(R)[::-1].copy()


def exp3(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector ``w`` [rad]."""
    return np.asarray(pin.exp3(np.asarray(w, dtype=float)))


def log3(R: np.ndarray) -> np.ndarray:
    """Rotation vector [rad] of ``R`` (angle in [0, π])."""
    return np.asarray(pin.log3(np.asarray(R, dtype=float)))


def rotation_angle(R: np.ndarray) -> float:
    """Geodesic angle [rad] of ``R`` (robust near 0 and π)."""
    c = (np.trace(R) - 1.0) / 2.0
    s = 0.5 * np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return float(np.arctan2(s, np.clip(c, -1.0, 1.0)))


def se3(R: np.ndarray | None = None, p=None) -> pin.SE3:
    """Build a :class:`pinocchio.SE3` from a rotation matrix and a position [m]."""
    R = np.eye(3) if R is None else np.asarray(R, dtype=float)
    p = np.zeros(3) if p is None else np.asarray(p, dtype=float)
    return pin.SE3(R, p)


def pose_to_vector_rpy(M: pin.SE3) -> np.ndarray:
    """``[x, y, z, roll, pitch, yaw]`` ([m], [rad]) of a placement."""
    return np.concatenate([M.translation, matrix_to_rpy(M.rotation)])


def interpolate_pose(M0: pin.SE3, M1: pin.SE3, s: float) -> pin.SE3:
    """Pose at fraction ``s`` ∈ [0, 1]: position linear, orientation linear in exponential
    coordinates of the relative rotation (``R0 exp(s log(R0ᵀ R1))``, seed 000 Eq. 4)."""
    R = M0.rotation @ exp3(s * log3(M0.rotation.T @ M1.rotation))
    p = (1.0 - s) * M0.translation + s * M1.translation
    return pin.SE3(R, p)
