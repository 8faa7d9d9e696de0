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


def test_restart_clip_option_is_checked_and_off_in_both_variants():
    assert TCBiRRTOptions(variant="paper").ik_restart_clip is VARIANTS["paper"]["ik_restart_clip"] is False
    assert TCBiRRTOptions(variant="improved").ik_restart_clip is False
    assert TCBiRRTOptions(variant="improved", ik_restart_clip=True).ik_restart_clip is True
    assert TCBiRRTOptions(variant="improved", ik_restart_clip="first").ik_restart_clip == "first"
    for bad in (1, "true", 0.0, "First", "last"):
        with pytest.raises(ValueError, match="ik_restart_clip: expected True, False or 'first'"):
            TCBiRRTOptions(variant="improved", ik_restart_clip=bad)


def test_restart_seed_takes_the_same_draws_and_clips_them_to_the_jump_bound():
    import numpy as np

    from optplan.planners.ik_seed import restart_seed

    q = np.linspace(-1.0, 1.0, 14)
    free, clip = TCBiRRTOptions(variant="improved"), TCBiRRTOptions(variant="improved", ik_restart_clip=True)
    a = restart_seed(q, np.random.default_rng(3), free)
    b = restart_seed(q, np.random.default_rng(3), clip)
    want = q + np.random.default_rng(3).normal(0.0, free.ik_restart_sigma, q.size)
    assert np.array_equal(a, want)
    j = clip.max_joint_step
    assert np.abs(a - q).max() > j                       # some offset of N(0, 0.3²) over 14 joints exceeds 0.25
    assert np.array_equal(b, q + np.clip(want - q, -j, j))
    assert np.abs(b - q).max() <= j + 1e-12          # (q + o) - q rounds
    # "first": a waypoint's first restart (index 0) clipped, the second not; the same draws either way
    first = TCBiRRTOptions(variant="improved", ik_restart_clip="first")
    g = np.random.default_rng(3)
    r0, r1 = restart_seed(q, g, first, 0), restart_seed(q, g, first, 1)
    g = np.random.default_rng(3)
    w0, w1 = g.normal(0.0, first.ik_restart_sigma, q.size), g.normal(0.0, first.ik_restart_sigma, q.size)
    assert np.array_equal(r0, q + np.clip(w0, -j, j)) and np.array_equal(r1, q + w1)
    assert np.abs(w1).max() > j                      # so that the unclipped second seed is told apart
    assert np.array_equal(restart_seed(q, np.random.default_rng(3), clip, 1), b)   # True clips every restart


@pytest.mark.parametrize("extension", ["loop", "python"])
def test_clipped_restart_seeds_reach_the_restarts(tcb, extension):
    """The option reaches the restarts in C and in Python: the same query takes another search (the seeds differ
    wherever a draw exceeded the bound), and both paths are found."""
    from optplan.planners.tcbirrt import TCBiRRT
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    scene = Scene.load("hard_bay")
    tr = TrialGenerator(tcb, scene).generate(3, 0)
    got = []
    for clip in (False, True, "first"):
        pl = TCBiRRT(tcb, scene, TCBiRRTOptions(variant="improved", extension=extension, ik_restart_clip=clip))
        if extension != "python" and pl._ext is None:
            pytest.skip("no native extension here")
        r = pl.plan(tr.q_start, tr.q_goal, time_limit=20.0, seed=3, clock="cpu")
        assert r.success and r.stats["ik_restarts"] > 0
        got.append((r.stats["iterations"], r.stats["ik_restart_iterations"], len(r.path)))
    assert len(set(got)) == 3
