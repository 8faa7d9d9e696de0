"""The scene generator: each family's draws are reproducible from the seed, survive a TOML round
trip, and pass the feasibility check (which itself rejects a scene whose end configurations are in
collision)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from optplan.bench.scenegen import (
    FAMILIES,
    family_of,
    family_summary,
    feasibility,
    generate_scene,
    generate_scenes,
    scene_toml,
)
from optplan.scene import Obstacle, Scene


def _same(a: Scene, b: Scene) -> None:
    assert [o.name for o in a.obstacles] == [o.name for o in b.obstacles]
    for oa, ob in zip(a.obstacles, b.obstacles):
        assert oa.shape == ob.shape
        assert np.allclose(oa.placement.homogeneous, ob.placement.homogeneous, atol=1e-9)
        for f in ("size", "radius", "length"):
            va, vb = getattr(oa, f), getattr(ob, f)
            assert (va is None) == (vb is None) and (va is None or np.allclose(va, vb))
    for M, N in ((a.start, b.start), (a.goal, b.goal)):
        assert np.allclose(M.homogeneous, N.homogeneous, atol=1e-9)


@pytest.mark.parametrize("family", FAMILIES)
def test_family_draws_are_seeded_and_round_trip(tcb, family, tmp_path):
    a = generate_scene(family, np.random.default_rng(4), robot=tcb)
    b = generate_scene(family, np.random.default_rng(4), robot=tcb)
    _same(a, b)
    if not a.obstacles:   # clutter or truss whose every obstacle was in the robot's way at an end
        assert feasibility(tcb, a).startswith("no obstacles")
        return
    p = tmp_path / "s.toml"
    p.write_text(scene_toml(a), encoding="utf-8")
    back = Scene.load(p)
    _same(a, back)
    assert np.allclose(back.extra["q_start"], np.asarray(a.extra["q_start"]) * (np.pi / 180 if a.extra.get("q_unit") == "deg" else 1))
    assert family_of(f"/x/gen_1_002_{family}.toml") == family


def test_generated_scenes_pass_feasibility(tcb):
    got = generate_scenes(tcb, 2, seed=5, families=("bay", "overhang"))
    assert [g.family for g in got] == ["bay", "overhang"]
    for g in got:
        assert feasibility(tcb, g.scene, seed=1) is None


def test_feasibility_rejects_an_obstacle_on_the_start(tcb):
    base = Scene.load("hard_bay")
    from optplan.trials import TrialGenerator

    q = TrialGenerator(tcb, base).q_nominal["q_start"]
    data = tcb.model.createData()
    pin.forwardKinematics(tcb.model, data, q)
    elbow = data.oMi[4].translation          # a point on arm A at the start configuration
    block = Obstacle("block", "sphere", pin.SE3(np.eye(3), elbow), radius=0.2)
    sc = dataclasses.replace(base, obstacles=base.obstacles + (block,))
    assert feasibility(tcb, sc) == "q_start in collision"


def test_family_summary_counts():
    rows = [{"planner": "p", "scene": "/d/gen_0_000_wall.toml", "success": True, "cpu_time_s": 0.5, "time_limit_s": 10},
            {"planner": "p", "scene": "/d/gen_0_001_wall.toml", "success": False, "cpu_time_s": 10.0, "time_limit_s": 10}]
    text = family_summary(rows)
    assert "wall" in text and "1/2" in text and "5.250" in text
