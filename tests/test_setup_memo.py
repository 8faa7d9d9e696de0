"""Set-up memos (:mod:`optplan.cache`): what a run computes from the robot alone before it plans — an
arm's sampled reach, the symbolic functions behind the compiled planner kernels and which library each
compiled to — is read back by a later process instead of being computed again, gives exactly what a
fresh computation gives, is keyed by everything it depends on (robot, settings, optplan source), and a
damaged entry is quarantined and recomputed. And the ``plan`` command's imports stay light."""
from __future__ import annotations

import json
import logging
import os
import subprocess
import sys

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from optplan import cache, codegen
from optplan.constraints import closed_chain as cc_mod
from optplan.constraints.closed_chain import ClosedChainKinematics
from optplan.model import reach
from optplan.model.digest import kinematics_digest
from optplan.model.robot import RobotModel
from optplan.planners import validity_sweep
from optplan.planners.tcbirrt_options import PAPER_REACH_ESTIMATE
from optplan.planners.validity import ValidityChecker


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    """An empty cache folder and empty in-process caches (restored after the test)."""
    monkeypatch.setenv("OPTPLAN_CACHE", str(tmp_path))
    monkeypatch.setattr(reach, "_REACH_CACHE", {})
    monkeypatch.setattr(ClosedChainKinematics, "_BUILT", {})
    monkeypatch.setattr(validity_sweep, "_PROFILE_CACHE", {})
    monkeypatch.setattr(cc_mod, "_RESIDUAL_FNS", {})
    return tmp_path


def _fail(*_a, **_k):
    raise AssertionError("built again although the memo holds it")


def test_reach_estimate_is_read_back_exactly_and_a_damaged_memo_is_recomputed(fresh_cache, tcb, monkeypatch, caplog):
    first = reach.arm_reach_estimate(tcb, "A")
    # the paper robot's estimate, recorded when the planner's scaling was introduced
    assert first[0] == PAPER_REACH_ESTIMATE
    (entry,) = (fresh_cache / "memo").glob("reach_*.json")
    monkeypatch.setattr(reach, "_REACH_CACHE", {})           # a later process
    real = reach._estimate
    monkeypatch.setattr(reach, "_estimate", _fail)
    assert reach.arm_reach_estimate(tcb, "A") == first
    entry.write_text("{not json")                           # damaged (its record no longer matches)
    monkeypatch.setattr(reach, "_REACH_CACHE", {})
    monkeypatch.setattr(reach, "_estimate", real)
    with caplog.at_level(logging.WARNING, logger="optplan.cache"):
        assert reach.arm_reach_estimate(tcb, "A") == first
    assert caplog.text.count("is damaged") == 1 and len(list((fresh_cache / "quarantine").iterdir())) >= 1
    assert json.loads(entry.read_text())["estimate"] == first[0]   # rewritten


def test_memo_names_follow_the_robot_the_settings_and_the_source(monkeypatch):
    a, b = RobotModel.from_name("tcbirrt_dual_arm"), RobotModel.from_name("tcbirrt_dual_arm")
    assert kinematics_digest(a) == kinematics_digest(b)
    b.model.jointPlacements[3].translation = b.model.jointPlacements[3].translation + np.array([0.0, 0.0, 1e-9])
    c = RobotModel.from_name("tcbirrt_dual_arm")
    c.upper = c.upper.copy()
    c.upper[0] -= 1e-6
    assert len({kinematics_digest(r) for r in (a, b, c)}) == 3
    name = cache.memo_name("reach", kinematics_digest(a), "A", 4000, 0)
    assert name != cache.memo_name("reach", kinematics_digest(a), "A", 4000, 1)
    assert name != cache.memo_name("reach", kinematics_digest(a), "B", 4000, 0)
    monkeypatch.setattr(cache, "_FINGERPRINT", ["an edited optplan"])
    assert name != cache.memo_name("reach", kinematics_digest(a), "A", 4000, 0)
    with pytest.raises(ValueError, match="memo kind"):
        cache.memo_name("two words")


def _function(name: str = "memo_fn") -> ca.Function:
    x = ca.SX.sym("x", 3)
    return ca.Function(name, [x], [ca.vertcat(ca.sin(x[0]) * x[1], ca.sumsqr(x), ca.exp(-x[2]))])


def test_memo_functions_and_their_library_are_loaded_without_building_or_generating(fresh_cache, monkeypatch,
                                                                                      caplog, rng):
    built = []

    def build():
        built.append(1)
        return {"f": _function(), "g": _function("memo_g")}

    fns = codegen.memo_functions("test_fn", ("key", 1), build)
    ref = codegen.FastFunction.of(fns, "f", "-O1")
    assert built == [1] and ref.compiled
    # a later process: the library comes from the memo's record, no function is read, built or generated
    again = codegen.memo_functions("test_fn", ("key", 1), _fail)
    assert again.name == fns.name and sorted(again) == ["f", "g"]
    monkeypatch.setattr(codegen.ca, "CodeGenerator", _fail)
    monkeypatch.setattr(codegen.ca.Function, "load", _fail)
    fast = codegen.FastFunction.of(again, "f", "-O1")
    assert fast.compiled and not again._fns
    for x in rng.normal(size=(5, 3)):
        want = np.asarray(_function()(x), float).ravel()
        assert np.array_equal(fast(x), want) and np.array_equal(ref(x), want)
    monkeypatch.undo()
    monkeypatch.setenv("OPTPLAN_CACHE", str(fresh_cache))
    x = rng.normal(size=3)   # the interpreted function, read when asked for
    assert np.array_equal(np.asarray(fast.f(x), float), np.asarray(_function()(x), float))
    assert np.array_equal(np.asarray(again["g"](x), float), np.asarray(_function("memo_g")(x), float))
    # other inputs: another memo
    assert codegen.memo_functions("test_fn", ("key", 2), build).name != fns.name and built == [1, 1]
    # a damaged saved function: quarantined, built again
    (saved,) = (fresh_cache / "memo").glob(f"{fns.name}_g.casadi")
    saved.write_bytes(saved.read_bytes()[:100])
    with caplog.at_level(logging.WARNING, logger="optplan.cache"):
        g = codegen.memo_functions("test_fn", ("key", 1), build)["g"]
    assert built == [1, 1, 1] and caplog.text.count("is damaged") == 1
    assert np.array_equal(np.asarray(g(x), float), np.asarray(_function("memo_g")(x), float))


def test_planner_kernels_from_the_memo_give_the_same_ik_and_edge_checks(fresh_cache, tcb, scene1, monkeypatch, rng):
    """The closed-chain IK block and the edge sweep profiles loaded from the memo (nothing built, no C
    generated) give bit-identical results to the ones built from scratch."""
    from optplan.constraints.closed_chain import IKSettings

    grasps = scene1.object.grasps
    k1 = ClosedChainKinematics(tcb, grasps)
    v1 = ValidityChecker(tcb, scene1)
    v1.prepare_edge_checks()
    monkeypatch.setattr(ClosedChainKinematics, "_BUILT", {})
    monkeypatch.setattr(validity_sweep, "_PROFILE_CACHE", {})
    monkeypatch.setattr(ClosedChainKinematics, "_functions", _fail)
    monkeypatch.setattr(ValidityChecker, "_sweep_functions", _fail)
    monkeypatch.setattr(codegen.ca, "CodeGenerator", _fail)
    k2 = ClosedChainKinematics(tcb, grasps)
    v2 = ValidityChecker(tcb, scene1)
    v2.prepare_edge_checks()
    assert k2.compiled and k2._block is not k1._block
    s = IKSettings()
    converged = 0
    for _ in range(8):   # object poses near the scene's start, seeds around the neutral configuration
        R = scene1.start.rotation @ pin.exp3(rng.normal(scale=0.2, size=3))
        p = scene1.start.translation + rng.normal(scale=0.1, size=3)
        seed = tcb.neutral() + rng.normal(scale=0.3, size=tcb.nq)
        a, b = k1.ik(seed.copy(), R, p, s), k2.ik(seed.copy(), R, p, s)
        assert a[1] == b[1] and ((a[0] is None and b[0] is None) or np.array_equal(a[0], b[0]))
        converged += a[0] is not None
    assert converged >= 1
    for _ in range(6):
        qa, qb = tcb.neutral() + rng.normal(scale=0.5, size=tcb.nq), tcb.neutral() + rng.normal(scale=0.5, size=tcb.nq)
        for mode in ("held", "fixed"):
            assert np.array_equal(v1.edge_checkpoints(qa, qb, 0.01, mode), v2.edge_checkpoints(qa, qb, 0.01, mode))


_HEAVY = ("matplotlib", "dask", "distributed", "jax", "optax", "meshcat", "example_robot_data", "torch", "pydrake",
          "ompl", "rockit", "tqdm", "optplan.bench", "optplan.viz", "optplan.papers", "xml.sax", "http", "ssl",
          # the roadmap planners and the floating-base simulation (another planner's, a floating robot's)
          "optplan.planners.constrained_prm", "optplan.planners.manifold_samples",
          "optplan.planners.precomputed_graph", "optplan.model.floating")
#: the benchmark engines' names (standard library only) that the argument parser offers
_LIGHT = ("optplan.bench", "optplan.bench.engine")

_PLAN_IMPORTS = """
import sys
import optplan, optplan.cli
args = optplan.cli.build_parser().parse_args(["plan", "--scene", "1"])
from optplan.pipeline import run_pipeline, PipelineOptions
from optplan.planners import make_planner
from optplan.scene import Scene
from optplan.trials import TrialGenerator
robot = optplan.cli._load_robot("tcbirrt_dual_arm")
scene = Scene.load("ssps_scene1")
trial = TrialGenerator(robot, scene).generate(0, 1)
plan = make_planner("tcbirrt", robot, scene, variant="improved").plan(trial.q_start, trial.q_goal, time_limit=20, seed=1)
assert plan.success, plan.status
heavy = %r
light = %r
print(" ".join(sorted(m for m in sys.modules if m not in light and any(m == h or m.startswith(h + ".") for h in heavy))))
"""


def test_the_plan_command_does_not_import_the_optional_or_unrelated_modules(tmp_path):
    """``import optplan``, the command line and the plan command's set-up and planning (a fresh process)
    load none of the optional extras (plotting, Dask, JAX, viz, example-robot-data, peers), the
    benchmarks or the paper reproductions."""
    env = dict(os.environ, OPTPLAN_CACHE=str(tmp_path), OPTPLAN_BACKGROUND_COMPILE="0")
    out = subprocess.run([sys.executable, "-c", _PLAN_IMPORTS % (_HEAVY, _LIGHT)], env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "", f"imported: {out.stdout.strip()}"
    bare = subprocess.run([sys.executable, "-c", "import sys, optplan; print(len([m for m in sys.modules "
                           "if m.split('.')[0] in ('numpy', 'scipy', 'casadi', 'pinocchio', 'coal')]))"],
                          env=env, capture_output=True, text=True, timeout=120)
    assert bare.returncode == 0 and bare.stdout.strip() == "0", bare.stdout + bare.stderr   # `import optplan` is cheap
