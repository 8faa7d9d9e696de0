"""Projection of a configuration onto a closed chain's manifold ``h(q) = 0`` by damped Newton
steps: the one projection the offline sample sets, the task-space exploration, Constrained PRM and
the learned samplers share."""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["project_onto_chain"]


def project_onto_chain(kin: Any, q: np.ndarray, lower: np.ndarray, upper: np.ndarray, tolerance: float = 1e-7,
                       max_iterations: int = 50, damping: float = 1e-6) -> np.ndarray | None:
    """Newton-Raphson onto ``h(q) = 0`` with the damped pseudo-inverse ``Jᵀ (J Jᵀ + δ² I)⁻¹``
    (``kin.h_jacobian``); None when it does not reach ``max |h| < tolerance`` within
    ``max_iterations`` or ends outside ``[lower, upper]``."""
    lam2 = damping ** 2 * np.eye(6)
    for _ in range(max_iterations):
        h, J = kin.h_jacobian(q)
        if not np.all(np.isfinite(h)):
            return None
        if float(np.abs(h).max()) < tolerance:
            if np.any(q < lower) or np.any(q > upper):
                return None
            return q
        q = q - J.T @ np.linalg.solve(J @ J.T + lam2, h)
    return None
