"""Two sampling aids of the improved TCBiRRT that are off by default (measured, not adopted:
docs/decisions/0004-tcbirrt-improved-variant.md, seventh round): what a trapped extension changes
at its node (adaptive step size, dynamic domain), and orientations read from the object's lead
path. Checked against their definitions, not against timings."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.bench.hardscenes import nominal_configurations
from optplan.bench.tcbirrt import _path_checks
from optplan.planners import TCBiRRT, TCBiRRTOptions
from optplan.planners.task_sampling import TaskSampler
from optplan.scene import Scene


@pytest.fixture(scope="module")
def robot(tcb):
    return tcb


def test_options_validate():
    o = TCBiRRTOptions(variant="improved")
    assert o.trap_adapt == "off" and o.lead_orientation_probability == 0.5
    assert TCBiRRTOptions().lead_orientation_probability == 0.0
    for bad in (dict(trap_adapt="shrink"), dict(domain_radius=0.0), dict(domain_tries=0), dict(domain_tries=1.5),
                dict(lead_orientation_probability=1.5), dict(lead_orientation_probability=-0.1)):
        with pytest.raises(ValueError, match=next(iter(bad))):
            TCBiRRTOptions(variant="improved", **bad)


def test_lead_orientation_samples_take_the_nearest_lead_pose(rng):
    """Every uniform sample's orientation is the lead pose nearest in position (no perturbation
    beyond ``geodesic_sigma``), its position stays uniform in the box."""
    lo, hi = np.array([-1, -1, 0, -np.pi, -np.pi, -np.pi]), np.array([1, 1, 2, np.pi, np.pi, np.pi])
    ts = TaskSampler(None, lo, hi, geodesic_sigma=1e-9, lead_orientation_probability=1.0)
    ts.guide = np.array([[-0.5, 0, 1, 0.3, 0.0, 0.0], [0.5, 0, 1, 0.0, -0.4, 1.0]])
    xs = np.array([ts.sample(rng) for _ in range(200)])
    assert np.all(xs[:, :3] >= lo[:3]) and np.all(xs[:, :3] <= hi[:3])
    near = np.argmin(((xs[:, None, :3] - ts.guide[None, :, :3]) ** 2).sum(-1), axis=1)
    for x, k in zip(xs, near):
        R, Rg = pin.rpy.rpyToMatrix(*x[3:]), pin.rpy.rpyToMatrix(*ts.guide[k, 3:])
        assert np.linalg.norm(pin.log3(Rg.T @ R)) < 1e-6
    assert set(near) == {0, 1}
    ts.guide = None   # no lead path yet: orientations uniform
    xs = np.array([ts.sample(rng) for _ in range(50)])
    assert np.std(xs[:, 5]) > 1.0


@pytest.mark.parametrize("mode", ["step", "domain"])
def test_trap_adapt_modes_act_and_still_plan(robot, mode):
    """Nominal window task: each mode changes the search (a node's step shrinks / samples outside a
    dynamic domain are drawn again) and the path passes the bench's independent 1 cm edge sweep."""
    scene = Scene.load("hard_window")
    qs, qg = nominal_configurations(robot, scene)
    seen: list[float] = []
    # the steps are read where the Python loop passes them (a trapped streak halves them in C, with the same
    # search: tests/test_tcbirrt_streaks.py)
    pl = TCBiRRT(robot, scene, TCBiRRTOptions(variant="improved", trap_adapt=mode, domain_radius=0.5, streaks=False))
    orig = pl.constrained_extend

    def spy(tree, i_near, xi_rand, q_rand, rng, deadline, st, step=None):
        if step is not None:
            seen.append(step)
        return orig(tree, i_near, xi_rand, q_rand, rng, deadline, st, step)

    pl.constrained_extend = spy   # type: ignore[method-assign]
    res = pl.plan(qs, qg, time_limit=20.0, seed=3, clock="cpu")
    assert res.success, res.message
    assert _path_checks(robot, scene, pl.checker, res)["swept_invalid_edges"] == 0
    if mode == "step":
        assert seen and min(seen) < pl.step_size and min(seen) >= pl.step_size / 8 - 1e-12
    else:
        assert not seen and res.stats.get("domain_rejections", 0) > 0

