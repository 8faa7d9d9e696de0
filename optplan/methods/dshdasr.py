"""Seed 003: coordinated collision-free target transposition by the discrete-serpentine dual-arm
space robot ``dshdasr`` with the space-arc equivalent kinematics, solved as one NLP per waypoint
(Eq. 50) with IPOPT — and a damped least-squares baseline on the full joint model.

* :class:`TransposeTask` — the task of Section 5: the target's centre of mass follows the quintic of
  Eq. 42 from X0 to Xf (Z-Y-X Euler angles, 60 s, 10 Hz); Arm-a holds the target at the locked point
  (``T_et^a``); Arm-b's tip sits at the point given by ``T_et^b`` and points at the locked point;
  two spherical obstacles. :func:`paper_task` is our reading of the paper's numbers (minus signs
  were lost in the text; the reading is documented there and in docs/dshdasr.md).
* :class:`DshdasrArcs` — the two arc models of the robot (:mod:`optplan.methods.arcs`), arc
  parameters from joint angles and joints recovered from arc parameters.
* :class:`ArcPlanner` — the NLP ``min ||G1||² + ||G2||² + w ||X − X_prev||²`` subject to the arc-to-
  sphere distances ≥ d_sd, built once (desired poses, previous solution and obstacles are
  parameters) and solved at every waypoint warm-started from the previous one.
* :func:`dls_track` — the classical baseline: damped least squares on the joints of both arms.
* :func:`evaluate` — tip errors by Pinocchio FK of the joints, coal distances on the link capsules.

The code lives in four modules split by concept; this module re-exports their public names:

========================  ======================================================================
module                    holds
========================  ======================================================================
:mod:`.dshdasr_task`      ``PAPER``, ``TABLE1_XF``, ``quintic``, ``TransposeTask``, ``paper_task``,
                          ``DshdasrArcs``, ``TrackResult``
:mod:`.dshdasr_nlp`       ``ArcPlanner`` (the NLP)
:mod:`.dshdasr_baseline`  ``dls_track``, ``arm_a_on_swivel``, ``initial_configuration``
:mod:`.dshdasr_eval`      ``evaluate``, ``make_checker``, ``coal_centreline_distances``, ``run_case``
========================  ======================================================================
"""
from __future__ import annotations

from .dshdasr_baseline import PAPER_INITIAL_JOINTS_DEG, arm_a_on_swivel, dls_track, initial_configuration
from .dshdasr_eval import coal_centreline_distances, evaluate, make_checker, run_case
from .dshdasr_nlp import ArcPlanner
from .dshdasr_task import (D2R, PAPER, ROBOT, TABLE1_XF, DshdasrArcs, TrackResult, TransposeTask, paper_task,
                           quintic)

__all__ = [
    "ROBOT", "PAPER", "TransposeTask", "paper_task", "quintic", "DshdasrArcs", "ArcPlanner",
    "TrackResult", "dls_track", "evaluate", "initial_configuration", "run_case", "TABLE1_XF",
    "arm_a_on_swivel", "make_checker", "coal_centreline_distances",
]

# Module constants not in ``__all__``, still importable from here as before the split.
_COMPAT = (D2R, PAPER_INITIAL_JOINTS_DEG)
