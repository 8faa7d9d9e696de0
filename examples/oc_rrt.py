#!/usr/bin/env python3
"""OC-RRT (orientation-constrained RRT with analytic IK) on PR2's two arms, against CBiRRT and
the strongest OMPL constrained planner, on four scenes: Industrial I (two cups kept upright, open
chain), Industrial II, Tabletop and Narrow Passageway (a level tray held by both hands, closed
chain). Prints success rate, median planning time, nodes and the orientation / position RMSD of
the densely interpolated paths.

    python examples/oc_rrt.py [--trials N] [--json PATH] [--plot DIR] [--save DIR] [--out DIR]

Writes files only where asked: without ``--out`` the per-trial results live in a temporary folder
that is removed after the run (with ``--out DIR`` they stay there and a rerun resumes from them).

Needs ``pip install "optplan[robots]"`` (PR2 from example-robot-data); the OMPL peer needs
``ompl`` (``optplan[ompl]``). Defaults to 3 trials per scene (the paper used 20: --trials 20).
"""
from __future__ import annotations

import argparse
import sys

from optplan.bench.oc_rrt import add_arguments, command

if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(p)
    p.set_defaults(trials=3, time_limit=10.0, out=None)
    sys.exit(command(p.parse_args()))
