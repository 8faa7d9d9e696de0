#!/usr/bin/env python3
"""Plan → shortcut → resample → optimize → verify on a space-solar-power-station scene.

TCBiRRT (seed 000) plans a closed-chain motion of the two arms of `tcbirrt_dual_arm` carrying the
2 x 0.8 x 0.8 m object between two perturbed poses (trial generator of Section 5.1); its path
warm-starts IPOPT segment by segment (regrasp segments: the holding arm's joints fixed, the object
where it is); every segment is verified with Pinocchio and coal.

    python examples/tcbirrt_warmstart.py [--scene 1] [--trial 0] [--seed 0] [--json out.json] [--save traj.npz]
"""
from __future__ import annotations

import sys

from optplan.cli import main

if __name__ == "__main__":
    sys.exit(main(["plan"] + sys.argv[1:]))
