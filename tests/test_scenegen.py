"""The scene generator: each family's draws are reproducible from the seed, survive a TOML round
trip, and pass the feasibility check (which itself rejects a scene whose end configurations are in
collision)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from optplan.bench.scene_witness import certify_witness, load_witness
from optplan.bench.scenegen import (
    FAMILIES,
    family_of,
    family_summary,
    feasibility,
    generate_scene,
    generate_scenes,
    rejection_summary,
    scene_toml,
    write_scenes,
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
    got = generate_scenes(tcb, 2, seed=5, families=("bay", "overhang"), witness_time=0)
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


def test_kept_scene_has_a_certified_witness_for_the_benchmark_query(tcb, tmp_path):
    from optplan.constraints.closed_chain import closure_error
    from optplan.planners.validity import ValidityChecker
    from optplan.trials import TrialGenerator

    rej: list = []
    got = generate_scenes(tcb, 1, seed=5, families=("overhang",), witness_time=10, rejections=rej)
    assert len(got) == 1 and got[0].witness is not None
    g, w = got[0], got[0].witness
    trial = TrialGenerator(tcb, g.scene).generate(0, 5)          # the benchmark's query (base seed 5, trial 0)
    assert np.allclose(w.path[0], trial.q_start) and np.allclose(w.path[-1], trial.q_goal)
    assert w.seed != trial.seed                                  # its own seed stream, not the planner's
    ck = ValidityChecker(tcb, g.scene, kernel="coal")             # independent: exact coal, Pinocchio FK
    data = tcb.model.createData()
    for q, c in zip(w.path, w.constrained):
        if c:
            assert max(closure_error(tcb, g.scene.object.grasps, q, data)) < 1e-3
            assert ck.is_valid(q)
    write_scenes(got, tmp_path)
    back = load_witness(tmp_path / f"{g.scene.name}.witness.npz")
    assert np.array_equal(back.path, w.path) and back.seed == w.seed


def test_draws_without_a_witness_are_rejected_and_counted(tcb):
    rej: list = []
    got = generate_scenes(tcb, 1, seed=5, families=("overhang",), max_draws=2, witness_time=1e-4, rejections=rej)
    assert got == [] and len(rej) == 2
    assert all(r.family == "overhang" and r.index == 0 for r in rej)
    assert all(r.reason.startswith("witness search") or not r.reason.startswith("witness") for r in rej)
    text = rejection_summary(got, rej)
    line = next(ln for ln in text.splitlines() if ln.startswith("overhang"))
    assert line.split()[1:4] == ["0", "2", "1"]                # kept, rejected draws, skipped


def test_certify_rejects_a_path_through_an_obstacle(tcb):
    from optplan.planners import make_planner
    from optplan.trials import TrialGenerator

    # a draw whose witness search takes ~0.1 s (seed 5's took ~10 s, at its limit: a scene that depended on the load)
    sc = generate_scenes(tcb, 1, seed=1, families=("overhang",), witness_time=10)[0].scene
    trial = TrialGenerator(tcb, sc).generate(0, 1)
    res = make_planner("tcbirrt", tcb, sc, variant="improved").plan(trial.q_start, trial.q_goal, time_limit=10,
                                                                      seed=1, clock="cpu")
    assert res.success
    assert certify_witness(tcb, sc, res)[0] is None
    # a sphere on the object's centre half-way along the path: the certificate must now fail
    from optplan.constraints.closed_chain import ClosedChainKinematics

    M = ClosedChainKinematics(tcb, sc.object.grasps).object_pose(res.path[len(res.path) // 2])
    block = Obstacle("block", "sphere", pin.SE3(np.eye(3), M.translation), radius=0.05)
    bad = dataclasses.replace(sc, obstacles=sc.obstacles + (block,))
    why, _ = certify_witness(tcb, bad, res)
    assert why is not None and "collision" in why


def test_family_summary_per_witness():
    rows = [{"planner": "p", "scene": "/d/gen_0_000_wall.toml", "success": True, "cpu_time_s": 0.5, "time_limit_s": 10},
            {"planner": "p", "scene": "/d/gen_0_001_wall.toml", "success": False, "cpu_time_s": 10.0, "time_limit_s": 10}]
    text = family_summary(rows, {"/d/gen_0_000_wall.toml": ("cbirrt2", "tcbirrt"), "/d/gen_0_001_wall.toml": ("tcbirrt",)})
    rate = {(ln.split()[1], ln.split()[2]): ln.split()[3] for ln in text.splitlines()[1:]}
    assert rate[("any", "wall")] == "1/2" and rate[("tcbirrt", "wall")] == "1/2" and rate[("cbirrt2", "wall")] == "1/1"


def test_witness_planner_names_are_checked():
    from optplan.bench.scene_witness import check_witness_planners
    from optplan.errors import OptionError

    assert check_witness_planners("cbirrt2, tcbirrt") == ("cbirrt2", "tcbirrt")
    for bad in ("", "rrt", "tcbirrt,tcbirrt", ()):
        with pytest.raises(OptionError, match="witness planners"):
            check_witness_planners(bad)


def test_cbirrt2_witness_search_is_cbirrt2_with_certified_edges(tcb):
    from optplan.bench.scene_witness import plan_witness, witness_planner
    from optplan.planners import CBiRRT2

    sc = Scene.load("hard_corridor")
    pl = witness_planner(tcb, sc, "cbirrt2")
    assert isinstance(pl, CBiRRT2) and pl.options.certified_edges
    w, why = plan_witness(tcb, sc, 0, 1, time_limit=1e-3, planner="cbirrt2")
    assert w is None and why is not None and why.startswith("witness search")


@pytest.mark.slow
def test_cbirrt2_witness_is_certified_independently(tcb, tmp_path):
    """A scene kept by the CBiRRT2 witness (another algorithm than the planner under test: joint-space
    trees, no regrasps) has a path whose held configurations close the chain (Pinocchio) and are free
    by exact coal; the witness records its planner and survives the round trip."""
    from optplan.constraints.closed_chain import closure_error
    from optplan.planners.validity import ValidityChecker
    from optplan.trials import TrialGenerator

    got = generate_scenes(tcb, 1, seed=5, families=("overhang",), witness_time=15, witnesses=("cbirrt2",))
    assert len(got) == 1 and got[0].certified_by == ("cbirrt2",)
    g, w = got[0], got[0].witness
    assert w is not None and w.planner == "cbirrt2"
    trial = TrialGenerator(tcb, g.scene).generate(0, 5)
    assert np.allclose(w.path[0], trial.q_start) and np.allclose(w.path[-1], trial.q_goal)
    assert w.constrained.all()                                   # CBiRRT2 never lets go of the object
    ck, data = ValidityChecker(tcb, g.scene, kernel="coal"), tcb.model.createData()
    for q in w.path:
        assert max(closure_error(tcb, g.scene.object.grasps, q, data)) < 1e-3 and ck.is_valid(q)
    write_scenes(got, tmp_path)
    assert load_witness(tmp_path / f"{g.scene.name}.witness.npz").planner == "cbirrt2"
    assert Scene.load(tmp_path / f"{g.scene.name}.toml").extra["certified_by"] == ["cbirrt2"]


def test_feasibility_lead_path_is_bounded_by_iterations_not_seconds(tcb, monkeypatch):
    """The object-only lead path of the feasibility check ends at its iteration budget: the same verdict when the
    CPU clock runs 50x fast (the seconds are a backstop), and a budget of one iteration cannot find a path."""
    import time

    from optplan.errors import OptionError
    from optplan.planners import base

    sc = generate_scene("overhang", np.random.default_rng(1), robot=tcb)
    assert feasibility(tcb, sc, seed=3) is None
    assert feasibility(tcb, sc, seed=3, lead_iterations=1) == "no path of the object alone"
    t0 = time.process_time()
    monkeypatch.setitem(base.CLOCKS, "cpu", lambda: t0 + 50.0 * (time.process_time() - t0))
    assert feasibility(tcb, sc, seed=3) is None
    with pytest.raises(OptionError, match="lead_iterations"):
        feasibility(tcb, sc, lead_iterations=0)
