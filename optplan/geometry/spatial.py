"""Rotation and rigid-transform conventions — the one place where they are defined.

Internally optplan uses rotation matrices and :class:`pinocchio.SE3`. Angles are converted only at
the edges, and every converter names its convention:

* ``rpy`` (roll-pitch-yaw, Pinocchio's ``rpyToMatrix``): ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``,
  argument order ``(roll, pitch, yaw)`` [rad].
* ``zyx`` (Z-Y-X Euler, as in the EBA paper's Eq. 1 ``[αz, αy, αx]``): ``R = Rz(a) @ Ry(b) @ Rx(c)``,
  argument order ``(a, b, c)`` [rad]. Same matrix as ``rpy(c, b, a)``.
* exponential coordinates ``log3``/``exp3`` (rotation vector, [rad]) for interpolation.
* ``vee_skew(E)`` = vee((E − Eᵀ)/2) = sin θ · axis of a rotation ``E`` (numpy or CasADi), and the
  singularity-free pose residual built from it (:func:`pose_residual`), used by every pose and
  closed-chain constraint.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin

__all__ = [
    "rotx", "roty", "rotz", "rpy_to_matrix", "matrix_to_rpy", "zyx_to_matrix", "matrix_to_zyx",
    "exp3", "log3", "se3", "pose_to_vector_rpy", "interpolate_pose", "rotation_angle",
    "check_rotation", "check_pose", "quaternion_to_matrix", "vee_skew", "skew", "pose_residual", "pose_to_vector", "vector_to_pose",
]

#: how far ``RᵀR`` may be from the identity (and det R from 1) for R to count as a rotation
ROTATION_TOL = 1e-6


def check_rotation(R, what: str = "rotation", tol: float = ROTATION_TOL) -> np.ndarray:
    """``R`` as a 3×3 float rotation matrix, or :class:`~optplan.errors.ConfigurationError` naming
    ``what``, the value and what is wrong (shape, non-finite entries, not orthonormal, reflection)."""
    from ..errors import ConfigurationError

    try:
        A = np.asarray(R, dtype=float)
    except (TypeError, ValueError):
        raise ConfigurationError(f"{what}: expected a 3x3 rotation matrix of floats, got {R!r}") from None
    if A.shape != (3, 3):
        raise ConfigurationError(f"{what}: expected a 3x3 rotation matrix, got shape {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ConfigurationError(f"{what}: non-finite entries in {A.tolist()}")
    err = float(np.abs(A.T @ A - np.eye(3)).max())
    det = float(np.linalg.det(A))
    if err > tol or abs(det - 1.0) > tol:
        raise ConfigurationError(f"{what}: not a rotation matrix (|RᵀR − I| = {err:.3g}, det = {det:.6g}; expected "
                                 f"orthonormal with det +1 within {tol:g}): {A.round(6).tolist()}")
    return A


def check_pose(M, what: str = "pose") -> pin.SE3:
    """``M`` if it is a :class:`pinocchio.SE3` with a finite translation and a true rotation, else
    :class:`~optplan.errors.ConfigurationError` naming ``what`` and the value."""
    from ..errors import ConfigurationError

    if not isinstance(M, pin.SE3):
        raise ConfigurationError(f"{what}: expected a pinocchio.SE3, got {type(M).__name__} {M!r}")
    check_rotation(M.rotation, f"{what}.rotation")
    p = np.asarray(M.translation, dtype=float)
    if not np.all(np.isfinite(p)):
        raise ConfigurationError(f"{what}.translation: non-finite entries {p.tolist()}")
    return M


def quaternion_to_matrix(quat, what: str = "quaternion") -> np.ndarray:
    """Rotation matrix of a quaternion ``[qx, qy, qz, qw]`` (Pinocchio's order), normalised; a
    zero, non-finite or wrongly sized quaternion is a ConfigurationError."""
    from ..errors import ConfigurationError, check_vector

    v = check_vector(quat, 4, f"{what} [qx, qy, qz, qw]")
    n = float(np.linalg.norm(v))
    if n < 1e-9:
        raise ConfigurationError(f"{what}: zero quaternion {v.tolist()} has no orientation (expected a unit quaternion)")
    return np.asarray(pin.Quaternion(*(v[[3, 0, 1, 2]] / n)).toRotationMatrix())


def pose_to_vector(M: pin.SE3) -> np.ndarray:
    """``[x, y, z, qx, qy, qz, qw]`` of a placement (Pinocchio's XYZQUAT)."""
    return np.asarray(pin.SE3ToXYZQUAT(M), dtype=float)


def vector_to_pose(v) -> pin.SE3:
    """Inverse of :func:`pose_to_vector`; a vector that is not 7 finite numbers or whose quaternion
    is zero is a ConfigurationError."""
    from ..errors import check_vector

    a = check_vector(v, 7, "pose [x, y, z, qx, qy, qz, qw]")
    return pin.SE3(quaternion_to_matrix(a[3:], "pose quaternion"), a[:3])


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


def _finite_angles(angles, what: str) -> None:
    from ..errors import ConfigurationError

    try:
        ok = all(np.isfinite(float(a)) for a in angles)
    except (TypeError, ValueError):
        raise ConfigurationError(f"{what}: expected 3 numbers [rad], got {tuple(angles)!r}") from None
    if not ok:
        raise ConfigurationError(f"{what}: expected finite angles [rad], got {tuple(angles)!r}")


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """``Rz(yaw) Ry(pitch) Rx(roll)`` from roll, pitch, yaw [rad]."""
    _finite_angles((roll, pitch, yaw), "rpy_to_matrix: (roll, pitch, yaw)")
    return rotz(yaw) @ roty(pitch) @ rotx(roll)


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rpy_to_matrix`: ``(roll, pitch, yaw)`` [rad], pitch in [-π/2, π/2]."""
    return np.asarray(pin.rpy.matrixToRpy(check_rotation(R, "matrix_to_rpy: R")))


def zyx_to_matrix(a: float, b: float, c: float) -> np.ndarray:
    """``Rz(a) Ry(b) Rx(c)`` [rad] — the EBA paper's ``[αz, αy, αx]`` order."""
    _finite_angles((a, b, c), "zyx_to_matrix: (a, b, c)")
    return rotz(a) @ roty(b) @ rotx(c)


def matrix_to_zyx(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`zyx_to_matrix`: ``(a, b, c)`` [rad]."""
    return matrix_to_rpy(R)[::-1].copy()


def exp3(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector ``w`` [rad]."""
    from ..errors import check_vector

    return np.asarray(pin.exp3(check_vector(w, 3, "exp3: w (rotation vector [rad])")))


def log3(R: np.ndarray) -> np.ndarray:
    """Rotation vector [rad] of ``R`` (angle in [0, π])."""
    return np.asarray(pin.log3(check_rotation(R, "log3: R")))


def vee_skew(E):
    """``vee((E − Eᵀ)/2)`` — ``sin θ · axis`` of the rotation ``E`` — as a numpy (3,) array, or a
    CasADi column when ``E`` is a CasADi matrix. Exact to round-off near ``E = I`` (an acos-based
    log is not); zero also at θ = π, so constraints pair it with ``trace(E) ≥ 1``."""
    if isinstance(E, (ca.SX, ca.MX, ca.DM)):
        return 0.5 * ca.vertcat(E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1])
    E = np.asarray(E)
    return 0.5 * np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]])


def skew(v):
    """``[v]×`` (3 × 3) of a 3-vector: ``skew(v) @ w = v × w`` (a CasADi matrix when ``v`` is
    CasADi, numpy otherwise)."""
    if isinstance(v, (ca.SX, ca.MX, ca.DM)):
        return ca.vertcat(ca.horzcat(0, -v[2], v[1]), ca.horzcat(v[2], 0, -v[0]), ca.horzcat(-v[1], v[0], 0))
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def pose_residual(R, p, R_target, p_target):
    """``([p − p_t; vee_skew(E)] (6), trace(E))`` with ``E = R_tᵀ R``: the singularity-free pose
    residual (position [m], sin θ · axis) of every pose constraint; zero with ``trace(E) ≥ 1`` iff
    the pose is the target. CasADi when any of ``R``, ``p`` is CasADi (a numpy target is lifted),
    numpy otherwise."""
    if isinstance(R, (ca.SX, ca.MX)) or isinstance(p, (ca.SX, ca.MX)):
        Rt = ca.DM(R_target) if isinstance(R_target, np.ndarray) else R_target
        E = Rt.T @ R
        return ca.vertcat(p - p_target, vee_skew(E)), ca.trace(E)
    E = np.asarray(R_target).T @ np.asarray(R)
    return np.concatenate([np.asarray(p) - np.asarray(p_target), vee_skew(E)]), float(np.trace(E))


def rotation_angle(R: np.ndarray) -> float:
    """Geodesic angle [rad] of ``R`` (robust near 0 and π)."""
    c = (np.trace(R) - 1.0) / 2.0
    s = float(np.linalg.norm(vee_skew(R)))
    return float(np.arctan2(s, np.clip(c, -1.0, 1.0)))


def se3(R: np.ndarray | None = None, p=None) -> pin.SE3:
    """Build a :class:`pinocchio.SE3` from a rotation matrix and a position [m]."""
    from ..errors import check_vector

    R = np.eye(3) if R is None else check_rotation(R, "se3: R")
    p = np.zeros(3) if p is None else check_vector(p, 3, "se3: p (position [m])")
    return pin.SE3(R, p)


def pose_to_vector_rpy(M: pin.SE3) -> np.ndarray:
    """``[x, y, z, roll, pitch, yaw]`` ([m], [rad]) of a placement."""
    return np.concatenate([M.translation, matrix_to_rpy(M.rotation)])


def interpolate_pose(M0: pin.SE3, M1: pin.SE3, s: float) -> pin.SE3:
    """Pose at fraction ``s`` ∈ [0, 1]: position linear, orientation linear in exponential
    coordinates of the relative rotation (``R0 exp(s log(R0ᵀ R1))``, the TCBiRRT paper Eq. 4)."""
    R = M0.rotation @ exp3(s * log3(M0.rotation.T @ M1.rotation))
    p = (1.0 - s) * M0.translation + s * M1.translation
    return pin.SE3(R, p)
