"""What a new process with a warm kernel cache recomputes when it builds a problem whose kernels
are on disk, counted instead of timed: the robot's symbolic kinematics are not built again (the
boundary and closed-chain knot kernels load from the kernel cache's files), and a damaged file
falls back to building the kernel, which then equals the one it replaces."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def new_process(monkeypatch, tmp_path):
    """``fresh()`` forgets what this process keeps in memory of kernels and symbols (the disk
    cache, a temporary ``OPTPLAN_CACHE``, stays), as a new process; ``calls`` counts the builds
    of the symbolic joint placements (the robot's kinematics under every knot kernel)."""
    import weakref

    from optplan.model import symbolic
    from optplan.problem import expressions, spline_problem
    from optplan.problem.kernels import KernelCache

    monkeypatch.setenv("OPTPLAN_CACHE", str(tmp_path))
    calls = [0]
    placements = symbolic.SymbolicKinematics.joint_placements

    def counted(self, q):
        calls[0] += 1
        return placements(self, q)

    monkeypatch.setattr(symbolic.SymbolicKinematics, "joint_placements", counted)

    def fresh() -> None:
        monkeypatch.setattr(KernelCache, "_per_robot", weakref.WeakKeyDictionary())
        monkeypatch.setattr(KernelCache, "_by_digest", weakref.WeakValueDictionary())
        monkeypatch.setattr(expressions, "_SYMBOLS", weakref.WeakKeyDictionary())
        monkeypatch.setattr(spline_problem, "_KNOT_KERNELS", {})

    fresh()
    return fresh, calls


def _families(robot):
    """The knot families of a closed-chain problem with both boundaries (the transport's terms
    without collision), built as a solve builds them."""
    from optplan.problem import OptProblem
    from optplan.problem.frame_terms import ClosedChain
    from optplan.problem.terms import JointBoundary, Smoothness

    rng = np.random.default_rng(3)
    q0 = rng.uniform(-0.5, 0.5, robot.nj)
    prob = OptProblem(robot, n_intervals=8, duration=2.0, transcription="bspline")
    prob.add_constraint(ClosedChain.from_configuration(robot, q0))
    prob.add_constraint(JointBoundary("start", q=q0))
    prob.add_constraint(JointBoundary("end", q=q0 + 0.01))
    prob.add_cost(Smoothness("jerk"))
    prob._spline.prepare()
    return {f.name: f.fn for f in prob._spline.fams if f.kind == "knot"}


def test_new_process_builds_no_symbolic_kinematics_and_a_damaged_kernel_file_is_rebuilt(new_process, tmp_path, caplog):
    from optplan import RobotModel

    fresh, calls = new_process
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    first = _families(robot)
    assert "closed_chain" in first and len(first) == 3   # the chain and the two boundaries
    assert calls[0] == 1                     # built once, for the closed chain's frames
    files = sorted(tmp_path.rglob("knot_kernel_*.casadi"))
    assert len(files) >= 2                   # the chain's kernel and the boundaries' kernel

    fresh()                                  # a new process: everything from the files
    again = _families(robot)
    assert calls[0] == 1
    assert {k: f.name() for k, f in again.items()} == {k: f.name() for k, f in first.items()}
    z = np.random.default_rng(4).uniform(-1, 1, first["closed_chain"].size1_in(0))
    for k in first:
        assert np.array_equal(np.asarray(again[k](z[:first[k].size1_in(0)])),
                              np.asarray(first[k](z[:first[k].size1_in(0)])))

    for f in files:                          # damaged files: set aside, the kernels built again
        f.write_text("not a casadi function")
    fresh()
    with caplog.at_level("WARNING", logger="optplan.cache"):
        rebuilt = _families(robot)
    assert sum("is damaged" in r.getMessage() for r in caplog.records) == len(files)
    assert not any(f.read_text() == "not a casadi function" for f in files)   # rewritten
    assert calls[0] == 2
    assert {k: f.name() for k, f in rebuilt.items()} == {k: f.name() for k, f in first.items()}
    for k in first:
        assert np.allclose(np.asarray(rebuilt[k](z[:first[k].size1_in(0)])),
                           np.asarray(first[k](z[:first[k].size1_in(0)])), atol=1e-14, rtol=0)


def test_an_edited_formulation_never_reads_an_older_knot_kernel_file(new_process, tmp_path, monkeypatch):
    from optplan import RobotModel
    from optplan.problem import spline_problem

    fresh, calls = new_process
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    _families(robot)
    before = set(tmp_path.rglob("knot_kernel_*.casadi"))
    fresh()
    monkeypatch.setattr(spline_problem, "_KNOT_SOURCE", ["edited"])   # as after an edit of the source
    _families(robot)
    assert calls[0] == 2                                                # built again, not read
    assert len(set(tmp_path.rglob("knot_kernel_*.casadi")) - before) == len(before)
