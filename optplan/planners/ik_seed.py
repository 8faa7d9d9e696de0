"""The IK seed of a waypoint of TCBiRRT's path IK (Alg. 3 of the TCBiRRT paper), predicted from the solutions
of the waypoints before it.

Alg. 3 seeds each waypoint's IK with the previous waypoint's solution ``q_{k−1}`` (``"none"``). The object
poses of one extension are equally spaced along a geodesic (Eq. 4), so the solutions along it are samples of
a smooth curve ``q(s)``: the previous solution is ``O(h)`` from the next one, the secant (linear)
extrapolation ``q_{k−1} + (q_{k−1} − q_{k−2})`` only ``O(h²)`` (``"secant"``, the predictor of continuation
methods without the Jacobian), so the damped Newton iteration of Alg. 4 starts nearer its solution. The
prediction is clamped to the joint limits and only seeds the IK: the joint-jump bound and the random restarts
stay relative to ``q_{k−1}``. The first waypoint of an extension (no ``q_{k−2}``) is seeded by ``q_{k−1}``.

The native extension (:mod:`optplan.planners.kernel.extend_csource`, ``tcb_seed``) computes the same values,
operation for operation.
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["PREDICTORS", "predicted_seed", "restart_seed"]

#: the seed predictors: ``"none"`` (the previous solution, Alg. 3 as published), ``"secant"``
PREDICTORS = ("none", "secant")


def predicted_seed(predictor: str, q: np.ndarray, q_pp: np.ndarray | None, lower: np.ndarray,
                   upper: np.ndarray) -> np.ndarray:
    """The IK seed after the solution ``q`` [rad] (``q_pp``: the solution before it, None when there is none):
    ``q`` itself, or for ``"secant"`` ``q + (q − q_pp)`` clamped to ``[lower, upper]`` [rad]."""
    if predictor == "none" or q_pp is None:
        return q
    if predictor != "secant":
        raise ValueError(f"ik_predictor: expected one of {PREDICTORS}, got {predictor!r}")
    return np.minimum(np.maximum(q + (q - q_pp), lower), upper)


def restart_seed(q: np.ndarray, rng: np.random.Generator, options: Any, index: int = 0) -> np.ndarray:
    """Restart ``index``'s (0: a failing waypoint's first) random IK seed after the solution ``q`` [rad]
    (``TCBiRRTOptions``: ``ik_restart_sigma``, ``ik_restart_clip``, ``max_joint_step``): ``q + N(0, sigma²)`` per
    joint, each offset clipped to ±``max_joint_step`` when ``ik_restart_clip`` is True, or is ``"first"`` and
    ``index`` is 0 (the same draws; the native extension's ``tcb_restart_seed`` does the same with its own random
    stream)."""
    o = rng.normal(0.0, options.ik_restart_sigma, q.size)
    clip = options.ik_restart_clip
    if clip is True or (clip == "first" and index == 0):
        j = float(options.max_joint_step)
        o = np.clip(o, -j, j)
    return q + o
