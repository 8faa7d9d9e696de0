"""Demo: the free-floating base of the EBA robot under a joint motion (the EBA paper, Section 4.1 path).

Both arms move from the paper's θ0 to θf (free-end case) along a rest-to-rest quintic in joint space
over 20 s; the base attitude follows from momentum conservation. This is the "5th-order
polynomial" baseline of the EBA paper, which leaves roughly a degree of base attitude error
(paper: (-0.81, 0.53, 0.78)°; see conventions.md for why our model gives a different value).
"""
from __future__ import annotations

import numpy as np

from .geometry.splines import quintic_time_law
from .model.floating import simulate_base
from .model.kinematics import Kinematics
from .model.robot import RobotModel

THETA0_DEG = np.array([-23.44, -90, 12.51, 104.8, -27.33, 66.56, -38] * 2, float)
THETAF_DEG = np.array([-23.44, -80, -17.49, 134.8, -12.33, 111.56, -38,
                       -23.44, -180, 47.51, 144.8, 7.67, 86.56, -38], float)
PAPER_FINAL_RPY_DEG = (-0.81, 0.53, 0.78)


def run(duration: float = 20.0, samples: int = 401) -> dict:
    """Simulate and return the figures (final base RPY [deg], momentum residual, CoM drift [m])."""
    robot = RobotModel.from_name("eba_ffsr")
    q0, qf = np.deg2rad(THETA0_DEG), np.deg2rad(THETAF_DEG)

    def traj(t: float):
        s = t / duration
        p, dp, _ = quintic_time_law(s)
        dp = dp / duration
        return q0 + p * (qf - q0), dp * (qf - q0)

    res = simulate_base(robot, traj, np.linspace(0.0, duration, samples))
    kin = Kinematics(robot)
    com_drift = float(np.linalg.norm(kin.center_of_mass(res.q[-1]) - kin.center_of_mass(res.q[0])))
    return {
        "final_base_rpy_deg": np.rad2deg(res.base_rpy[-1]).tolist(),
        "paper_final_base_rpy_deg": list(PAPER_FINAL_RPY_DEG),
        "max_momentum_residual": float(res.momentum_residual.max()),
        "com_drift_m": com_drift,
        "duration_s": duration,
    }
