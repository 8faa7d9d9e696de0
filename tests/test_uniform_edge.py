"""``ValidityChecker.uniform_edge_is_valid`` (``verify_path``'s re-check of a found path's edges, one native call
per edge, points in index order) gives the verdicts of :func:`optplan.planners.rrtconnect.edge_is_valid` at the
same uniform spacing (coarse-to-fine, a batch of configurations) — on free and colliding edges, object held and
object still (with a regrasp's grasp contacts exempted), and on coal's checker too."""
from __future__ import annotations

import numpy as np
import pytest

from optplan.bench.hardscenes import nominal_configurations
from optplan.constraints.closed_chain import ClosedChainKinematics
from optplan.planners.rrtconnect import edge_is_valid
from optplan.planners.validity import ValidityChecker
from optplan.scene import Scene


@pytest.mark.parametrize("scene_name,kernel", [("ssps_scene1", "native"), ("hard_corridor", "native"),
                                               ("ssps_scene3", "coal")])
def test_uniform_edge_gives_the_batch_verdicts(tcb, scene_name, kernel):
    scene = Scene.load(scene_name)
    vc = ValidityChecker(tcb, scene, kernel=kernel)
    if vc.kernel != kernel:
        pytest.skip("no native kernel here")
    rng = np.random.default_rng(1129)
    qs, qg = nominal_configurations(tcb, scene)
    M = ClosedChainKinematics(tcb, scene.object.grasps).object_pose(qs)
    verdicts = []
    n_edges = 60 if kernel == "native" else 15
    for mode, pose, w in (("held", None, vc.sweep_weights("held", per_geometry=True)),
                          ("fixed", M, vc.sweep_weights("fixed", per_geometry=True))):
        with vc.exempt(vc.grasp_contacts(qs, M) if mode == "fixed" else ()):
            for i in range(n_edges):
                q0 = qs if i % 2 else qg
                a = np.clip(q0 + rng.normal(0.0, 0.03, q0.size), tcb.lower, tcb.upper)
                b = np.clip(a + rng.normal(0.0, 0.25 if i % 3 else 0.02, q0.size), tcb.lower, tcb.upper)
                n0 = vc.n_checks
                got = vc.uniform_edge_is_valid(a, b, 0.01, w, mode, pose)
                n_checked = vc.n_checks - n0
                want = edge_is_valid(a, b, vc.validity(mode, pose), 0.01, False, w)
                assert got == want, f"{scene_name}/{mode} edge {i}: {got} != {want}"
                n = max(1, int(np.ceil(np.max(w @ np.abs(b - a)) / 0.01)))
                if kernel == "coal":   # a free edge: every interior point checked once
                    assert got is False or n_checked == n - 1
                else:                  # the native kernel proves most points free by their clearance (safe steps)
                    assert got is False or 1 <= n_checked <= n - 1
                verdicts.append(got)
    assert 0 < sum(verdicts) < len(verdicts)   # both verdicts occur


def test_verify_path_same_search(tcb, monkeypatch):
    """The improved TCBiRRT's searches are those of ``verify_path`` on the batch of
    :func:`~optplan.planners.rrtconnect.edge_is_valid` (the earlier code): the same status, iterations,
    checked edges and path for a seed."""
    from optplan.planners.tcbirrt import TCBiRRT
    from optplan.planners.tcbirrt_edges import EdgeCheckMixin
    from optplan.planners.tcbirrt_options import TCBiRRTOptions
    from optplan.trials import TrialGenerator

    def batch_edge_ok(self, a, b, st, object_pose=None):   # the earlier _static_edge_ok
        st["path_verified_edges"] += 1
        if object_pose is None:
            return edge_is_valid(a, b, self.checker.validity("held"), self.options.edge_tolerance, False, self._w_held)
        return edge_is_valid(a, b, self.checker.validity("fixed", object_pose), self.options.edge_tolerance, False,
                             self._w_fixed)

    scene = Scene.load("ssps_scene2")
    planner = TCBiRRT(tcb, scene, TCBiRRTOptions(variant="improved"))
    gen = TrialGenerator(tcb, scene)
    runs = []
    for patched in (False, True):
        with monkeypatch.context() as mp:
            if patched:
                mp.setattr(EdgeCheckMixin, "_static_edge_ok", batch_edge_ok)
            runs.append([planner.plan(t.q_start, t.q_goal, time_limit=10.0, seed=t.seed, clock="cpu")
                         for t in (gen.generate(i, 0) for i in range(3))])
    for new, old in zip(*runs):
        assert new.status == old.status and new.status.value == "exact"
        for k in ("iterations", "path_verified_edges", "regrasp_attempts"):
            assert new.stats[k] == old.stats[k], k
        assert new.stats["path_verified_edges"] > 0
        assert len(new.path) == len(old.path) and all(np.array_equal(x, y) for x, y in zip(new.path, old.path))
