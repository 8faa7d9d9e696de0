"""TCBiRRT's task space ξ = (position, exponential coordinates of the rotation): the maps between
poses and ξ (the TCBiRRT paper Appendix, Eq. 12-14) and the interpolation between two poses (Eq. 4)."""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ..geometry.spatial import check_rotation, vee_skew

__all__ = ["exp_coordinates", "rotation_from_exp", "interpolate_task", "xi_from_pose", "pose_from_xi"]


def exp_coordinates(R: np.ndarray) -> np.ndarray:
    """Rotation vector ω̂θ of ``R`` (the TCBiRRT paper Appendix, Eq. 12-14), θ ∈ [0, π].

    Eq. 12 (θ from the trace) and Eq. 14 (axis from the skew part) away from 0 and π; Eq. 13's
    θ = π case is generalised to use the largest diagonal entry (Eq. 13 divides by 1 + r11, which
    vanishes for a half turn about any axis ⊥ x) and is used whenever sin θ is too small for Eq. 14.
    """
    if not (type(R) is np.ndarray and R.shape == (3, 3) and R.dtype == np.float64 and np.isfinite(R).all()):
        R = check_rotation(R, "exp_coordinates: R (3 x 3 rotation matrix)")   # the error names the value
    v = vee_skew(R)
    s = float(np.linalg.norm(v))
    c = float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))
    theta = math.atan2(s, c)                      # Eq. 12, robust form
    if s < 1e-12 and c > 0:
        return np.zeros(3)                        # θ = 0
    if c > -0.9:
        return v * (theta / s)                    # Eq. 14: ω̂ = vee(R − Rᵀ) / (2 sin θ)
    # near π: ω̂ω̂ᵀ = (R + Rᵀ)/2 − cos θ I) / (1 − cos θ), take the best-conditioned column (Eq. 13)
    B = (0.5 * (R + R.T) - c * np.eye(3)) / (1.0 - c)
    k = int(np.argmax(np.diag(B)))
    w = B[:, k] / math.sqrt(max(B[k, k], 1e-300))
    if w @ v < 0:                                 # sign from the skew part (undetermined at exactly π)
        w = -w
    return w * theta


def rotation_from_exp(phi: np.ndarray) -> np.ndarray:
    """Rodrigues: ``exp([φ]×)``."""
    return np.asarray(pin.exp3(np.asarray(phi, dtype=float)))


def _unwrap_near(phi: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """The representative of the rotation ``exp(φ)`` (φ + 2πk φ̂) closest to ``ref``."""
    th = float(np.linalg.norm(phi))
    if th < 1e-12:
        return phi
    u = phi / th
    cands = [phi + 2.0 * math.pi * k * u for k in (-1, 0, 1)]
    return min(cands, key=lambda c: float(np.linalg.norm(c - ref)))


def interpolate_task(R0: np.ndarray, p0: np.ndarray, R1: np.ndarray, p1: np.ndarray, n: int,
                     mode: str = "geodesic") -> list[tuple[np.ndarray, np.ndarray]]:
    """Object poses ``j = 1..n`` from ``(R0, p0)`` to ``(R1, p1)`` (Eq. 4): position linear,
    orientation linear in exponential coordinates — of the relative rotation (``"geodesic"``) or of
    the absolute rotations (``"absolute"``, literal Eq. 4 with φ_s unwrapped next to φ_near)."""
    out = []
    if mode == "geodesic":
        w = np.asarray(pin.log3(R0.T @ R1))
        for j in range(1, n + 1):
            s = j / n
            out.append((R0 @ np.asarray(pin.exp3(s * w)), p0 + s * (p1 - p0)))
    elif mode == "absolute":
        f0 = exp_coordinates(R0)
        f1 = _unwrap_near(exp_coordinates(R1), f0)
        for j in range(1, n + 1):
            s = j / n
            out.append((rotation_from_exp(f0 + s * (f1 - f0)), p0 + s * (p1 - p0)))
    else:
        raise ValueError(f"interpolation mode: expected 'geodesic' or 'absolute', got {mode!r}")
    if out:
        out[-1] = (np.array(R1, dtype=float), np.array(p1, dtype=float))  # exact end pose ξ_s
    return out


def xi_from_pose(M: pin.SE3) -> np.ndarray:
    """ξ = [x, y, z, roll, pitch, yaw] of an object pose (Eq. 2's RPY)."""
    return np.concatenate([M.translation, pin.rpy.matrixToRpy(M.rotation)])


def pose_from_xi(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(R, p)`` of ξ."""
    return np.asarray(pin.rpy.rpyToMatrix(float(xi[3]), float(xi[4]), float(xi[5]))), np.array(xi[:3], dtype=float)
