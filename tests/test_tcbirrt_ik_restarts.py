"""TCBiRRT's IK restarts of a failing waypoint: their own iteration limit (``ik_restart_iterations``), in the native
loop's restarts (C) and in the Python extension's, counted in ``ik_restart_iterations``."""
from __future__ import annotations

import pytest

from optplan.planners.tcbirrt_options import VARIANTS, TCBiRRTOptions


def test_restart_iteration_limit_option_is_checked_and_has_variant_values():
    assert TCBiRRTOptions(variant="paper").ik_restart_iterations == VARIANTS["paper"]["ik_restart_iterations"] == 0
    assert TCBiRRTOptions(variant="improved").ik_restart_iterations == 0
    assert TCBiRRTOptions(variant="improved", ik_restart_iterations=12).ik_restart_iterations == 12
    for bad in (-1, 1.5, True, "12"):
        with pytest.raises(ValueError, match="ik_restart_iterations: expected an int >= 0"):
            TCBiRRTOptions(variant="improved", ik_restart_iterations=bad)


def _run(robot, extension: str, limit: int, trial: int = 3):
    from optplan.planners.tcbirrt import TCBiRRT
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    scene = Scene.load("hard_bay")
    pl = TCBiRRT(robot, scene, TCBiRRTOptions(variant="improved", extension=extension, ik_restart_iterations=limit))
    if extension != "python" and pl._ext is None:
        pytest.skip("no native extension here")
    tr = TrialGenerator(robot, scene).generate(trial, 0)
    return pl.plan(tr.q_start, tr.q_goal, time_limit=20.0, seed=trial, clock="cpu").stats


@pytest.mark.parametrize("extension", ["loop", "python"])
def test_restarts_stop_at_their_own_iteration_limit(tcb, extension):
    """With a limit of 4 no restart runs more than 4 IK iterations; with the IK's own limit (30) restarts that do not
    converge run past 4 (so the bound above is the limit's doing)."""
    capped, free = _run(tcb, extension, 4), _run(tcb, extension, 0)
    assert capped["ik_restarts"] > 0 and free["ik_restarts"] > 0
    assert 0 < capped["ik_restart_iterations"] <= 4 * capped["ik_restarts"]
    assert free["ik_restart_iterations"] > 4 * free["ik_restarts"]
