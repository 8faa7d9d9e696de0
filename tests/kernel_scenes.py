"""Scenes for the native kernel's tests: a scene's box obstacles turned about their centres (their world boxes then
loose bounds) and six random spheres and capsules around the robot, so that every primitive pair type occurs."""
from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from optplan.planners.validity import ValidityChecker
from optplan.scene import Obstacle, Scene


def with_turned_boxes_and_balls(scene: Scene, rng: np.random.Generator) -> Scene:
    """``scene`` with every box obstacle turned about its centre and six random spheres and capsules added."""
    obs = [dataclasses.replace(o, placement=pin.SE3(pin.exp3(rng.normal(0.0, 0.6, 3)) @ o.placement.rotation,
                                                    o.placement.translation)) if o.shape == "box" else o
           for o in scene.obstacles]
    for i in range(6):
        M = pin.SE3(pin.exp3(rng.normal(0.0, 1.0, 3)), rng.uniform([-0.5, -2.5, 0.5], [3.0, 2.5, 4.0]))
        obs.append(Obstacle(f"ball_{i}", "sphere", M, radius=float(rng.uniform(0.1, 0.4))) if i % 2 else
                   Obstacle(f"rod_{i}", "capsule", M, radius=float(rng.uniform(0.05, 0.2)), length=float(rng.uniform(0.3, 1.5))))
    return dataclasses.replace(scene, name=scene.name + "_turned", obstacles=tuple(obs))


def native_checker(robot, scene_name: str, margin: float, turned: bool, rng: np.random.Generator) -> ValidityChecker:
    """A validity checker on the native kernel for ``scene_name`` (:func:`with_turned_boxes_and_balls` when
    ``turned``), ``margin`` [m]; the test is skipped where the kernel cannot be built (no C compiler)."""
    scene = Scene.load(scene_name)
    if turned:
        scene = with_turned_boxes_and_balls(scene, rng)
    vc = ValidityChecker(robot, scene, margin=margin)
    if vc.kernel != "native":
        pytest.skip("no native kernel here (no C compiler)")
    return vc
