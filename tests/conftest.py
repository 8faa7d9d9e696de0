"""Shared fixtures of the optplan test-suite.

* ``eba`` / ``tcb``: the two shipped robots (session-scoped: loading builds collision pairs).
* ``scene1`` / ``kin`` / ``checker``: SSPS scene 1, the closed-chain kinematics of its grasps on
  ``tcb`` and its validity checker (module-scoped; a test module may define its own).
* ``rng``: a fresh ``np.random.default_rng(12345)`` for every test, so a test draws the same
  numbers whether it runs alone or inside the whole suite.
* ``OPTPLAN_CACHE`` points to a session temporary directory, so compiled CasADi code never
  touches the user's ``~/.cache/optplan``; background kernel compiles are off
  (``OPTPLAN_BACKGROUND_COMPILE=0``).
"""
from __future__ import annotations

import numpy as np
import pytest

from optplan.model.robot import RobotModel
from optplan.scene import Scene


@pytest.fixture(scope="session", autouse=True)
def _optplan_cache(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    mp.setenv("OPTPLAN_CACHE", str(tmp_path_factory.mktemp("optplan_cache")))
    mp.setenv("OPTPLAN_BACKGROUND_COMPILE", "0")   # no compiler processes outliving the tests
    yield
    mp.undo()


@pytest.fixture(scope="session")
def eba() -> RobotModel:
    return RobotModel.from_name("eba_ffsr")


@pytest.fixture(scope="session")
def tcb() -> RobotModel:
    return RobotModel.from_name("tcbirrt_dual_arm")


@pytest.fixture(scope="module")
def scene1() -> Scene:
    return Scene.load("ssps_scene1")


@pytest.fixture(scope="module")
def kin(tcb, scene1):
    from optplan.constraints.closed_chain import ClosedChainKinematics

    return ClosedChainKinematics(tcb, scene1.object.grasps)


@pytest.fixture(scope="module")
def checker(tcb, scene1):
    from optplan.planners import ValidityChecker

    return ValidityChecker(tcb, scene1)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture
def deadline_gaps(monkeypatch):
    """``deadline_gaps()`` patches :class:`optplan.planners.base.Deadline` so that every ``expired()`` call
    records the clock time since the previous call of the same deadline (the longest stretch a planner
    runs without looking at its limit), and returns the list it fills."""
    from optplan.planners.base import Deadline

    def install() -> list[float]:
        gaps: list[float] = []
        last: dict[int, float] = {}
        orig = Deadline.expired

        def expired(self) -> bool:
            now = self.clock()
            gaps.append(now - last.get(id(self), self.t0))
            last[id(self)] = now
            return orig(self)

        monkeypatch.setattr(Deadline, "expired", expired)
        return gaps

    return install
