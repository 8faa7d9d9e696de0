"""Generalisation: a robot we do not ship (two Pandas from example-robot-data), its collision-pair
budget, collision geometry the NLP handles or refuses, reach-scaled planner defaults, and the
pipeline on a stress scene."""
from __future__ import annotations

import xml.etree.ElementTree as ET

import coal
import numpy as np
import pinocchio as pin
import pytest

from optplan.errors import ConfigurationError
from optplan.model.example_robots import example_robot_data_dir
from optplan.model.robot import RobotModel
from optplan.scene import Scene


def _panda_available() -> bool:
    d = example_robot_data_dir()
    return d is not None and (d / "robots/panda_description/urdf/panda_collision.urdf").exists()


needs_panda = pytest.mark.skipif(not _panda_available(), reason="needs example-robot-data (pip install optplan[robots])")


@pytest.fixture(scope="module")
def panda():
    from optplan.model.dual_panda import load_dual_panda

    return load_dual_panda()


# --------------------------------------------------------------------------- capsule merge (no data needed)
def test_merge_capsules_joins_a_cylinder_and_its_end_spheres():
    from optplan.model.dual_panda import merge_capsules

    link = ET.fromstring("""<link name="l">
      <collision><origin rpy="0 1.5707963267948966 0" xyz="-0.075 0 0.06"/><geometry><cylinder length="0.03" radius="0.09"/></geometry></collision>
      <collision><origin xyz="-0.06 0 0.06"/><geometry><sphere radius="0.09"/></geometry></collision>
      <collision><origin xyz="-0.09 0 0.06"/><geometry><sphere radius="0.09"/></geometry></collision>
      <collision><origin xyz="0 0 1"/><geometry><sphere radius="0.05"/></geometry></collision>
      <collision><geometry><cylinder length="0.2" radius="0.01"/></geometry></collision>
    </link>""")
    assert merge_capsules(link) == 1
    cols = link.findall("collision")
    assert len(cols) == 3  # capsule, the unmatched sphere, the unmatched cylinder
    assert cols[0].get("name") == "l_0_capsule" and cols[0].find("geometry/cylinder") is not None
    assert cols[1].find("geometry/sphere") is not None and cols[2].get("name") is None


# --------------------------------------------------------------------------- dual Panda
@needs_panda
def test_dual_panda_loads_with_a_pair_budget(panda):
    assert panda.nj == 14 and set(panda.arms) == {"left", "right"}
    kinds = {type(o.geometry).__name__ for o in panda.collision_model.geometryObjects}
    assert kinds == {"Capsule", "Box"}  # every vendor cylinder + sphere pair merged into an exact capsule
    b = panda.pair_budget
    assert b["geometries"] == len(panda.collision_model.geometryObjects)
    assert b["kept"] == len(panda.collision_pairs) < b["joint_distance"] < b["all_pairs"]
    assert b["restored"] > 0 and b["kept"] == b["joint_distance"] - b["srdf_disabled"] + b["restored"]
    # the two arms can touch: every left-right pair is kept but those fewer than three joints apart
    # through the plate (link0-link0, link0-link1, link0-link2, link1-link1, both ways: 6 pairs)
    objs = panda.collision_model.geometryObjects
    side = [o.name.split("_")[0] for o in objs]
    cross = {(a, b) for a, b in panda.collision_pairs if {side[a], side[b]} == {"left", "right"}}
    n_l, n_r = side.count("left"), side.count("right")
    assert len(cross) == n_l * n_r - 6


@needs_panda
def test_disabled_pairs_stay_apart_on_random_configurations(panda):
    """Independent check of the SRDF's "never in collision" claim: pairs of one arm the budget
    leaves out (and that are not adjacent) keep a positive coal distance on random configurations."""
    from optplan.model.dual_panda import sampled_min_distances

    kept = set(panda.collision_pairs)
    objs = panda.collision_model.geometryObjects
    left = [g for g, o in enumerate(objs) if o.name.startswith("left_")]
    out = [(a, b) for i, a in enumerate(left) for b in left[i + 1:]
           if (a, b) not in kept and panda._joint_distance(objs[a].parentJoint, objs[b].parentJoint) >= 3]
    assert out, "the SRDF removes pairs three or more joints apart"
    d = sampled_min_distances(panda, out, n=300, seed=1)  # not the budget's own samples (seed 0)
    assert np.all(d > 0.0)


@needs_panda
def test_nlp_collision_points_match_coal_placements(panda):
    """The NLP's capsule end points (in each geometry's parent frame) land where Pinocchio/coal
    place the geometry, also for links hanging from fixed joints (hand, fingers, mount)."""
    from optplan.problem.collision_term import CollisionAvoidance

    col = CollisionAvoidance(Scene.load("panda_shelf")).model(panda)
    rng = np.random.default_rng(0)
    q = rng.uniform(panda.lower, panda.upper)
    data, gd = panda.model.createData(), pin.GeometryData(panda.collision_model)
    pin.updateGeometryPlacements(panda.model, data, panda.collision_model, gd, q)
    pin.framesForwardKinematics(panda.model, data, q)
    checked = 0
    for g, o in enumerate(panda.collision_model.geometryObjects):
        if not isinstance(o.geometry, coal.Capsule):
            continue
        fid, cap, _ = col.robot_shape[g]
        hl = o.geometry.halfLength
        want = [gd.oMg[g].act(np.array([0, 0, s * hl])) for s in (-1, 1)]
        got = [data.oMf[fid].act(np.asarray(p)) for p in (cap.a, cap.b)]
        assert np.allclose(got, want, atol=1e-9), o.name
        checked += 1
    assert checked == 26


@needs_panda
def test_planner_defaults_scale_with_reach(panda):
    from optplan.planners.task_sampling import arm_reach_estimate
    from optplan.planners.tcbirrt import (
        PAPER_XI_LOWER,
        PAPER_XI_UPPER,
        TCBiRRTOptions,
        reach_scaled_workspace,
    )

    lo, hi, step = reach_scaled_workspace(RobotModel.from_name("tcbirrt_dual_arm"), TCBiRRTOptions())
    assert tuple(lo) == PAPER_XI_LOWER and tuple(hi) == PAPER_XI_UPPER and step == 0.6  # the paper's robot
    lo, hi, step = reach_scaled_workspace(panda, TCBiRRTOptions())
    from optplan.planners.tcbirrt_options import PAPER_REACH_ESTIMATE as PAPER_REACH

    reach = arm_reach_estimate(panda, "left")[0]
    assert step == pytest.approx(0.6 * reach / PAPER_REACH)
    assert np.allclose(0.5 * (lo[:3] + hi[:3]), [0.0, 0.0, 0.333])   # the shoulders' midpoint
    assert np.allclose(hi[:3] - lo[:3], np.array([4.0, 6.0, 4.0]) * reach / PAPER_REACH)
    assert np.allclose(lo[3:], PAPER_XI_LOWER[3:])                    # angles are not scaled
    given = TCBiRRTOptions(xi_lower=(-1, -1, 0, -3, -3, -3), xi_upper=(1, 1, 1, 3, 3, 3))
    assert tuple(reach_scaled_workspace(panda, given)[0]) == (-1, -1, 0, -3, -3, -3)  # explicit: as given
    off = TCBiRRTOptions(scale_to_reach=False)
    assert tuple(reach_scaled_workspace(panda, off)[0]) == PAPER_XI_LOWER


# --------------------------------------------------------------------------- geometry refused or handled
def test_unsupported_robot_geometry_is_refused_by_name():
    from optplan.problem.segment import SegmentSpec, SplineSegmentProblem

    robot = RobotModel.from_name("tcbirrt_dual_arm")
    robot.collision_model.geometryObjects[3].geometry = coal.Ellipsoid(0.1, 0.2, 0.3)
    name = robot.collision_model.geometryObjects[3].name
    q = np.zeros(robot.nj)
    with pytest.raises(ConfigurationError, match=name):
        SplineSegmentProblem(robot, Scene.load("ssps_scene1"), SegmentSpec(10, 5.0, q, q))


def test_plain_cylinder_is_bounded_conservatively():
    """A URDF cylinder not named *_capsule: the NLP bounds it by the capsule of its axis and
    radius, whose distance never exceeds coal's exact distance to the cylinder."""
    from optplan.problem.kernels import geometry_points

    robot = RobotModel.from_name("tcbirrt_dual_arm")
    g = next(i for i, o in enumerate(robot.collision_model.geometryObjects) if isinstance(o.geometry, coal.Capsule))
    o = robot.collision_model.geometryObjects[g]
    cyl = coal.Cylinder(o.geometry.radius, 2 * o.geometry.halfLength)
    o.geometry = cyl
    fid, V, r = geometry_points(robot, g)
    cap = coal.Capsule(r, float(np.linalg.norm(V[:, 1] - V[:, 0])))
    rng = np.random.default_rng(3)
    data = robot.model.createData()
    q = rng.uniform(robot.lower, robot.upper)
    pin.framesForwardKinematics(robot.model, data, q)
    Mf = data.oMf[fid]
    gd = pin.GeometryData(robot.collision_model)
    pin.updateGeometryPlacements(robot.model, data, robot.collision_model, gd, q)
    mid, axis = 0.5 * (V[:, 0] + V[:, 1]), V[:, 1] - V[:, 0]
    z = axis / np.linalg.norm(axis)
    x = np.cross(z, [1, 0, 0] if abs(z[0]) < 0.9 else [0, 1, 0])
    x /= np.linalg.norm(x)
    Mcap = Mf * pin.SE3(np.column_stack([x, np.cross(z, x), z]), mid)
    ball = coal.Sphere(0.05)
    for _ in range(50):
        c = gd.oMg[g].translation + rng.normal(0, 0.5, 3)
        tb = coal.Transform3s(np.eye(3), c)
        d_cyl = coal.distance(cyl, coal.Transform3s(gd.oMg[g].rotation, gd.oMg[g].translation), ball, tb,
                              coal.DistanceRequest(), coal.DistanceResult())
        d_cap = coal.distance(cap, coal.Transform3s(Mcap.rotation, Mcap.translation), ball, tb,
                              coal.DistanceRequest(), coal.DistanceResult())
        assert d_cap <= d_cyl + 1e-9


# --------------------------------------------------------------------------- bench helpers
def test_bench_scene_groups_expand_and_unknown_names_are_refused():
    from optplan.bench.generalize import expand

    names = expand(["stress", "hard_flip", "stress_posts"])
    assert names[-1] == "hard_flip" and {"stress_posts", "stress_shelf", "stress_cage"} <= set(names)
    assert len(names) == len(set(names))
    with pytest.raises(ValueError, match="nope"):
        expand(["nope"])


@needs_panda
def test_trial_perturbation_scales_with_reach(panda):
    from optplan.trials import TrialGenerator, _reach_scale

    paper = RobotModel.from_name("tcbirrt_dual_arm")
    assert _reach_scale(paper) == 1.0
    assert TrialGenerator(paper, Scene.load("ssps_scene1")).options.position_range == 0.2
    assert 0.3 < _reach_scale(panda) < 0.45  # Panda trials: 0.2 m × that, unless the scene sets its range


@needs_panda
def test_panda_bar_witness_is_feasible_and_the_straight_line_is_not(panda):
    """``panda_bar``: the nominal start and goal hold the box; IK continuation from the start
    (box straight up, then forward to the goal) is collision-free by coal at every pose and ends at
    the scene's goal configuration (one IK branch: no regrasp needed); the straight line collides."""
    from optplan.collision.checker import CollisionChecker
    from optplan.constraints.closed_chain import closure_error
    from optplan.planners.task_space import interpolate_task
    from optplan.trials import TrialGenerator

    scene = Scene.load("panda_bar")
    tg = TrialGenerator(panda, scene)
    qs, qg = tg.q_nominal["q_start"], tg.q_nominal["q_goal"]
    assert max(closure_error(panda, scene.object.grasps, qs)) <= 1e-6
    assert max(closure_error(panda, scene.object.grasps, qg)) <= 1e-6
    checker = CollisionChecker(panda, scene)
    S, G = scene.start, scene.goal
    up = pin.SE3(S.rotation, np.array([S.translation[0], S.translation[1], G.translation[2]]))

    def follow(poses):
        q, path = qs.copy(), [qs.copy()]
        for A, B in zip(poses[:-1], poses[1:]):
            for R, p in interpolate_task(A.rotation, A.translation, B.rotation, B.translation, 40):
                q2, _ = tg.kin.ik(q, R, p, tg.ik)
                assert q2 is not None and np.abs(q2 - q).max() < 0.3, "IK continuation left its branch"
                q = q2
                path.append(q.copy())
        return path

    witness = follow([S, up, G])
    assert min(checker.min_distance(q)[0] for q in witness) > 0.02
    assert np.abs(witness[-1] - qg).max() < 1e-3   # the scene's goal configuration: same branch
    assert min(checker.min_distance(q)[0] for q in follow([S, G])) < -0.02


def test_pipeline_verified_on_a_stress_scene():
    """A scene the optimizer was not tuned on (capsule bars, a sphere, a 180° roll of the module):
    plan -> optimize -> verify succeeds, checked independently here (coal clearance, FK closure)."""
    from optplan.collision.checker import CollisionChecker
    from optplan.constraints.closed_chain import closure_error
    from optplan.pipeline import PipelineOptions, run_pipeline
    from optplan.trials import TrialGenerator

    robot, scene = RobotModel.from_name("tcbirrt_dual_arm"), Scene.load("stress_cage")
    tr = TrialGenerator(robot, scene).generate(0, 0)
    opts = PipelineOptions(planner_options=(("edge_resolution", 0.05), ("variant", "improved")))
    res = run_pipeline(robot, scene, tr.q_start, tr.q_goal, opts, seed=tr.seed)
    assert res.plan.success and res.success, res.to_dict()
    assert all(len(s.attempts) >= 1 for s in res.segments)
    # where both hands hold the module (during a regrasp it stays with the holding arm)
    held = [q for q, c in zip(res.q, res.constrained) if c][::5]
    checker = CollisionChecker(robot, scene)
    assert min(checker.min_distance(q)[0] for q in held) >= 0.0
    assert max(max(closure_error(robot, scene.object.grasps, q)) for q in held) <= 1e-6


def test_margins_relax_only_where_a_collision_free_guess_is_closer_than_the_margin():
    """``relax_to_guess``: inside the path a pair's margin becomes half the guess's exact (coal)
    clearance only where that clearance is in [0, margin); where the guess collides it stays."""
    from optplan.constraints.closed_chain import project_closed_chain
    from optplan.problem import ClosedChain
    from optplan.problem.segment import SegmentSpec, SplineSegmentProblem

    robot, scene = RobotModel.from_name("tcbirrt_dual_arm"), Scene.load("transport")
    g = scene.object.grasps
    cc = ClosedChain.from_grasps(g["A"], g["B"], "A", "B")
    from optplan.trials import TrialGenerator

    tr = TrialGenerator(robot, scene).generate(0, 0)
    N = 24
    Q = np.linspace(tr.q_start, tr.q_goal, N + 1)
    Q[1:-1] = [project_closed_chain(robot, q, cc).q for q in Q[1:-1]]
    prob = SplineSegmentProblem(robot, scene, SegmentSpec(N, 30.0, Q[0], Q[-1], cc, margin=0.05, object_arm="A",
                                                          activation=0.5))
    prob.set_initial(Q)
    col = prob.col   # planned along the initial guess
    Qk = prob.knot_configurations()
    D = np.array([col.checker.distances(q) for q in Qk])
    pairs = col.checker.pairs
    w = prob.spec.window
    assert col.relaxed, "the straight guess passes closer than 5 cm somewhere"
    active = [pairs.index(p) for p in col.active_pairs]
    assert (D[1:-1][:, active] < 0).any(), "and collides somewhere (those rows keep the margin)"
    for (p, k), m in col.relaxed.items():
        near = [j for j in range(max(0, k - w), min(N, k + w) + 1)]
        d = D[near, pairs.index(p)]
        cand = [0.5 * x for j, x in zip(near, d) if x < 0.05 and (x >= 0 or j in (0, N))]
        assert cand and m == pytest.approx(min(min(cand), 0.05), abs=1e-12)


def test_summary_pools_many_grid_sizes_into_one_range():
    from optplan.bench.generalize import _attempts_text

    few = {"N=24": 3, "N=48": 1}
    assert _attempts_text(few) == "N=24 3, N=48 1"
    many = {f"N={n}": 1 for n in (8, 10, 1005, 2592, 24, 48, 700)}
    many["N=24"] = 23
    text = _attempts_text(many)
    assert text == "N=8-2592 29 (7 sizes)", text
    assert _attempts_text({**many, "collision": 2}).endswith(", collision 2")
