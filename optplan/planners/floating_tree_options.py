"""Options of :class:`~optplan.planners.floating_tcbirrt.FloatingTCBiRRT`, the closed-chain planner
for a free-floating robot (extension steps, goal trees, steering and restoration of the base
attitude), validated when created."""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import OptionError

__all__ = ["FloatingTreeOptions"]


@dataclass(frozen=True)
class FloatingTreeOptions:
    """Options of :class:`FloatingTCBiRRT`'s trees (the steps, tolerances and goal frame are the
    :class:`~optplan.planners.floating_carry.FloatingCarryOptions` it is given)."""

    #: largest object translation of one extension (TCBiRRT's s_ξ) [m].
    extend_m: float = 0.25
    #: largest object rotation of one extension [rad].
    extend_rad: float = 0.5
    #: probability that a sample is the other tree's root pose [probability].
    goal_bias: float = 0.1
    #: the sampling box: start and goal object positions (base frame) widened by this, per axis [m].
    sample_margin_m: float = 0.4
    #: range of a sample's rotation offset from the start-goal geodesic, per RPY angle [rad].
    sample_angle_rad: float = 0.6
    #: largest joint change between consecutive closed-chain waypoints (path-IK continuity) [rad].
    max_joint_step: float = 0.3
    #: a connection that reaches a node's object pose joins it directly within this joint distance
    #: (max norm), else by a self-motion join at that pose [rad].
    join_step_rad: float = 0.05
    #: rotation weight of the nearest-neighbour distance [m/rad].
    rotation_weight_m: float = 0.3
    #: random IK seeds tried for a joint solution of the goal pose [count].
    goal_seeds: int = 20
    #: joint spread of those seeds around the start (normal, per joint) [rad].
    goal_seed_spread_rad: float = 0.6
    #: times the goal tree is re-rooted at the real arrival base when the world-goal correction fails [count].
    max_reroots: int = 8
    #: iterations without a join after which the goal tree gains another root (another joint
    #: solution of the goal pose: another IK branch) [count].
    root_interval: int = 60
    #: most roots of the goal tree [count].
    max_goal_roots: int = 6
    #: Newton steps of the generalized-Jacobian correction of the world goal [count].
    correction_steps: int = 12
    #: largest joint change of one correction step [rad].
    correction_step_rad: float = 0.1
    #: the clock of the time limit: "cpu" (this process's CPU time) or "wall".
    clock: str = "cpu"
    #: steer the base attitude (closed object loops) when a joined path arrives at an attitude from
    #: which the correction cannot land the world goal.
    steer_attitude: bool = True
    #: with a world goal, end with the base at its INITIAL attitude: the goal tree is rooted where the
    #: arms hold the object at the goal with that attitude, and the joined path is steered to it
    #: (closed object loops) within ``restore_tol_rad``.
    restore_attitude: bool = False
    #: the restored attitude's tolerance [rad].
    restore_tol_rad: float = 1e-7

    def __post_init__(self) -> None:
        for name in ("extend_m", "extend_rad", "sample_margin_m", "sample_angle_rad", "max_joint_step",
                     "join_step_rad", "rotation_weight_m", "goal_seed_spread_rad", "correction_step_rad",
                     "restore_tol_rad"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise OptionError(f"FloatingTreeOptions.{name}: expected a positive finite number, got {v!r}")
        if not (isinstance(self.goal_bias, (int, float)) and 0.0 <= self.goal_bias <= 1.0):
            raise OptionError(f"FloatingTreeOptions.goal_bias: expected a probability in [0, 1], got {self.goal_bias!r}")
        for name in ("goal_seeds", "max_reroots", "root_interval", "max_goal_roots", "correction_steps"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 0):
                raise OptionError(f"FloatingTreeOptions.{name}: expected an integer ≥ 0, got {v!r}")
        if self.clock not in ("cpu", "wall"):
            raise OptionError(f"FloatingTreeOptions.clock: expected 'cpu' or 'wall', got {self.clock!r}")
