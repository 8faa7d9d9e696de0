"""Independent re-integration of a floating robot's joint path for the planner tests (shared by
``test_floating_tcbirrt.py`` and ``test_floating_steer.py``)."""
from __future__ import annotations

import numpy as np

from optplan.model.floating import simulate_base


def reintegrate(robot, joints, base0, per_edge: int = 20, substeps: int = 4):
    """The joint path re-integrated in one run from ``base0``, with another timing than the planner's:
    each edge traversed with the smoothstep 3τ² − 2τ³ (at rest at every waypoint, so the trajectory is
    C¹ and RK4 steps across waypoints stay 4th order). With zero momentum the base depends on the
    path only, not on its timing. Returns ``(s, simulate_base result)``, ``s`` the path parameter."""
    s = np.linspace(0.0, len(joints) - 1, (len(joints) - 1) * per_edge + 1)

    def traj(t):
        k = min(int(t), len(joints) - 2)
        tau = t - k
        d = joints[k + 1] - joints[k]
        return joints[k] + (3 * tau**2 - 2 * tau**3) * d, (6 * tau - 6 * tau**2) * d

    return s, simulate_base(robot, traj, s, base0=base0, substeps=substeps)
