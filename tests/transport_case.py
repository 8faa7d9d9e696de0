"""The bench's transport NLP (N = 50, fixed normals, first guess from a seed), shared by the tests
that count its rows and its solve work."""
from __future__ import annotations

import numpy as np


def transport(seed: int = 0):
    """(robot, scene, problem, closed chain) of the transport with the first guess of ``seed``."""
    from optplan import RobotModel
    from optplan.scene import Scene
    from optplan.tasks import transport_initial_path, transport_problem

    robot = RobotModel.from_name("tcbirrt_dual_arm")
    scene = Scene.load("transport")
    Q = transport_initial_path(robot, scene, 50, np.random.default_rng(seed))
    assert Q is not None
    prob, cc, _ = transport_problem(robot, scene, Q, fixed_normals=True, transcription="auto")
    return robot, scene, prob, cc
