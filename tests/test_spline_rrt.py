"""Spline-RRT* (Yu et al.): coordinated RRT* with separated sampling, quartic splines, Bézier
orientation, resolved-rate tracking on the free-floating robot, optimized variant (slow)."""
from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

from optplan.model.floating import simulate_base
from optplan.model.robot import RobotModel
from optplan.papers.spline_rrt import (
    BezierOrientation,
    SplineRRTResult,
    SplineRRTTask,
    TrackingOptions,
    evaluate,
    link_distances,
    smooth_hand_paths,
    track,
)
from optplan.planners.base import PlanStatus
from optplan.planners.spline_rrt import (
    CoordinatedRRTStar,
    CoordinatedRRTStarOptions,
    VirtualWall,
    point_obstacle_distance,
)
from optplan.scene import Scene


@pytest.fixture(scope="module")
def robot():
    return RobotModel.from_name("splinerrt_ffsr")


@pytest.fixture(scope="module")
def task(robot):
    return SplineRRTTask.from_scene(robot)


def _ends(task):
    return {a: (task.start[a].translation, task.goal[a].translation) for a in ("A", "B")}


@pytest.fixture(scope="module")
def plan(task):
    # a generous time limit: the iteration cap decides, so the plan is the same on a loaded machine
    return CoordinatedRRTStar(task.scene, CoordinatedRRTStarOptions(hand_radius=0.15, max_iterations=400,
                                                                    seed=0, time_limit=30.0)).plan(_ends(task))


@pytest.fixture(scope="module")
def smoothed(task, plan):
    return smooth_hand_paths(plan.paths, task.start, task.goal, 0.1)


@pytest.fixture(scope="module")
def tracked(robot, task, smoothed):
    hands, T, _ = smoothed
    return track(robot, hands, task.q_start, T, TrackingOptions(dt=0.05))


def _dense(path, step=0.005):
    out = [path[0]]
    for a, b in zip(path[:-1], path[1:]):
        k = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        out += [a + (b - a) * s for s in np.linspace(0, 1, k + 1)[1:]]
    return np.array(out)


# ------------------------------------------------------------------ geometry
def test_point_obstacle_distance_matches_coal():
    rng = np.random.default_rng(3)
    scene = Scene.from_dict({"obstacles": [
        {"name": "s", "shape": "sphere", "radius": 0.2, "xyz": [0.1, 0.2, 0.3]},
        {"name": "b", "shape": "box", "size": [0.3, 0.5, 0.2], "xyz": [0, 0, 0], "rpy": [0.3, -0.2, 1.0]},
        {"name": "c", "shape": "capsule", "radius": 0.1, "length": 0.6, "xyz": [0, 0.1, 0], "rpy": [1.0, 0.4, 0.0]}]})
    point = coal.Sphere(1e-9)
    for o in scene.obstacles:
        P = rng.uniform(-1.0, 1.0, (200, 3))
        ours = point_obstacle_distance(P, o)
        outside = ours > 1e-6
        assert outside.sum() > 100
        ref = np.array([coal.distance(point, coal.Transform3s(np.eye(3), p), o.coal_geometry(),
                                      coal.Transform3s(o.placement.rotation, o.placement.translation),
                                      coal.DistanceRequest(), coal.DistanceResult()) for p in P[outside]])
        np.testing.assert_allclose(ours[outside], ref, atol=1e-7)


def test_virtual_wall_moves_with_the_hands():
    wall = VirtualWall.from_task(([0, -0.1, 0], [1, -0.6, 0.2]), ([0, 0.1, 0], [1, 0.0, 0.6]))
    # the wall passes through the hands' midpoints at start and goal, normal along their separation
    np.testing.assert_allclose(wall.coordinate(np.array([[0, 0, 0], [1, -0.3, 0.4]])), 0.0, atol=1e-12)
    assert wall.coordinate(np.array([[0, -0.1, 0]]))[0] < 0 < wall.coordinate(np.array([[1, 0.0, 0.6]]))[0]
    assert not np.allclose(wall.n0, wall.n1)  # it turns between start and goal
    P = np.random.default_rng(1).uniform(-1, 2, (50, 3))
    np.testing.assert_allclose([wall.coordinate_point(p) for p in P], wall.coordinate(P), atol=1e-12)
    with pytest.raises(ValueError, match="not separated"):
        VirtualWall.from_task(([0, 0, 0], [1, 0, 0]), ([0.5, 0, 0], [2, 0, 0]))


# ------------------------------------------------------------------ planner
def test_separated_sampling_never_crosses_hand_paths():
    """12 random asymmetric tasks (the wall moves and turns), random obstacles: every vertex and edge
    point stays on its own side, and the two hand paths never come close to each other."""
    rng = np.random.default_rng(20261123)
    for trial in range(12):
        a0 = rng.uniform(-0.3, 0.3, 3)
        a0[1] -= 0.15
        b0 = a0 + np.r_[rng.uniform(-0.1, 0.1), 0.3, rng.uniform(-0.1, 0.1)]
        a1 = a0 + np.r_[1.0, rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4)]
        b1 = a1 + np.r_[rng.uniform(-0.1, 0.1), rng.uniform(0.2, 0.5), rng.uniform(-0.1, 0.1)]
        obs = [{"name": f"o{i}", "shape": "sphere", "radius": 0.05,
                "xyz": (0.5 * (a0 + a1) if i == 0 else 0.5 * (b0 + b1)).tolist()} for i in range(2)]
        scene = Scene.from_dict({"obstacles": obs})
        pl = CoordinatedRRTStar(scene, CoordinatedRRTStarOptions(max_iterations=150, seed=trial,
                                                                 hand_radius=0.03, time_limit=30.0))
        res = pl.plan({"A": (a0, a1), "B": (b0, b1)})
        assert res.status is PlanStatus.EXACT, (trial, res.message)
        PA, PB = _dense(res.paths["A"]), _dense(res.paths["B"])
        assert np.all(res.wall.coordinate(PA) <= -0.03 + 1e-9) and np.all(res.wall.coordinate(PB) >= 0.03 - 1e-9)
        gap = np.min(np.linalg.norm(PA[:, None, :] - PB[None, :, :], axis=2))
        assert gap > 0.03, (trial, gap)
        for t in res.trees.values():  # every tree vertex too
            assert np.all(np.sign(res.wall.coordinate(t.X)) == np.sign(res.wall.coordinate(t.X[:1])))


def test_rrt_star_cost_decreases_and_rewiring_keeps_tree_consistent(task):
    improved = 0
    for seed in range(6):
        res = CoordinatedRRTStar(task.scene, CoordinatedRRTStarOptions(hand_radius=0.15, max_iterations=400,
                                                                       seed=seed, time_limit=30.0)).plan(_ends(task))
        assert res.success, res.message
        for a, t in res.trees.items():
            t.check_consistency()
            assert t.rewired > 0
            c = np.array(t.best_cost)
            found = c[np.isfinite(c)]
            assert np.all(np.diff(found) <= 1e-12)  # never gets worse
            improved += found[-1] < found[0] - 1e-6
            # the path is a chain of tree edges with the reported cost
            P = res.paths[a]
            assert np.isclose(np.sum(np.linalg.norm(np.diff(P, axis=0), axis=1)), res.stats["cost_m"][a])
            assert res.stats["cost_m"][a] >= np.linalg.norm(task.goal[a].translation - task.start[a].translation)
    assert improved >= 9  # of 12 trees: rewiring keeps shortening the first path found


def test_same_seed_same_plan(task):
    o = CoordinatedRRTStarOptions(hand_radius=0.15, max_iterations=150, seed=5, time_limit=30.0)
    r1, r2 = CoordinatedRRTStar(task.scene, o).plan(_ends(task)), CoordinatedRRTStar(task.scene, o).plan(_ends(task))
    for a in ("A", "B"):
        np.testing.assert_array_equal(r1.paths[a], r2.paths[a])


def test_invalid_start_and_bad_options(task):
    ends = _ends(task)
    ends["A"] = (task.scene.obstacle("debris_a").placement.translation, ends["A"][1])
    res = CoordinatedRRTStar(task.scene, CoordinatedRRTStarOptions(seed=0)).plan(ends)
    assert res.status is PlanStatus.INVALID_START and "debris" not in res.message and "clearance" in res.message
    with pytest.raises(ValueError, match="step"):
        CoordinatedRRTStarOptions(step=-1.0)
    with pytest.raises(ValueError, match="exactly two arms"):
        CoordinatedRRTStar(task.scene).plan({"A": ends["B"]})


# ------------------------------------------------------------------ splines, orientation
def test_quartic_splines_meet_the_paper_conditions(plan, smoothed):
    hands, T, _ = smoothed
    for a, h in hands.items():
        pp = h.position
        assert pp.tf == pytest.approx(T)
        np.testing.assert_allclose(pp(0.0, 1), 0.0, atol=1e-12)
        np.testing.assert_allclose(pp(0.0, 2), 0.0, atol=1e-12)
        np.testing.assert_allclose(pp(T, 1), 0.0, atol=1e-12)
        np.testing.assert_allclose(pp(pp.breakpoints), plan.paths[a], atol=1e-12)  # through every waypoint
        hseg = pp.durations
        for k in range(4):  # C0..C3 at the inner waypoints
            dc = pp.derivative(k).coefficients
            left = sum(dc[:-1, p] * hseg[:-1, None] ** p for p in range(dc.shape[1]))
            np.testing.assert_allclose(left, dc[1:, 0], atol=1e-9 * max(1.0, np.abs(dc).max()))
        v = np.linalg.norm(pp(np.linspace(0, T, 20001), 1), axis=1)
        assert v.max() <= 0.1 * (1 + 1e-9)
    assert max(h.max_speed() for h in hands.values()) == pytest.approx(0.1, rel=1e-6)  # the limit binds


def test_spline_stays_on_its_side_of_the_wall(plan, smoothed):
    hands, T, _ = smoothed
    t = np.linspace(0, T, 4001)
    assert np.all(plan.wall.coordinate(hands["A"].position(t)) < 0)
    assert np.all(plan.wall.coordinate(hands["B"].position(t)) > 0)


def test_bezier_orientation_ends_and_angular_velocity():
    R0 = pin.rpy.rpyToMatrix(-np.pi / 2, 0, np.pi / 4)
    R1 = pin.rpy.rpyToMatrix(-np.pi / 2, 0, np.pi / 6)
    ori = BezierOrientation(R0, R1, 10.0)
    np.testing.assert_allclose(ori(0.0)[0], R0, atol=1e-14)
    np.testing.assert_allclose(ori(10.0)[0], R1, atol=1e-14)
    np.testing.assert_allclose(ori(0.0)[1], 0.0, atol=1e-14)
    np.testing.assert_allclose(ori(10.0)[1], 0.0, atol=1e-14)
    rng = np.random.default_rng(0)
    general = BezierOrientation(R0, R1, 10.0, control=rng.normal(size=(6, 3)) * 0.3)
    for t in (1.0, 3.3, 7.9):  # world angular velocity = central difference of the rotation
        h = 1e-5
        Rm, Rp = general(t - h)[0], general(t + h)[0]
        w_fd = Rm @ pin.log3(Rm.T @ Rp) / (2 * h)
        np.testing.assert_allclose(general(t)[1], w_fd, atol=1e-7)


# ------------------------------------------------------------------ tracking on the floating base
def test_tracking_reproduces_the_planned_hand_paths(robot, task, smoothed, tracked):
    hands, T, _ = smoothed
    ev = evaluate(robot, hands, tracked.t, tracked.joints, tracked.qd, scene=task.scene)
    for a in hands:
        assert ev[f"tracking_position_m_{a}"].max() < 1e-6
        assert ev[f"tracking_orientation_rad_{a}"].max() < 1e-6
    assert np.abs(tracked.qd[0]).max() < 1e-9  # starts at rest
    assert ev["link_distance_m"].min() > 0.1
    assert ev["momentum_residual"] < 1e-9


def test_reported_base_attitude_equals_independent_simulator(robot, tracked):
    """The controller integrates the base with the joints (pin.integrate, RK4); simulate_base
    integrates it again from the joint samples alone (quaternion RK4, Hermite interpolation)."""
    sim = simulate_base(robot, (tracked.t, tracked.joints, tracked.qd), tracked.t, substeps=4)
    drift = np.linalg.norm(pin.log3(pin.XYZQUATToSE3(sim.q[-1, :7]).rotation))
    assert drift > 1e-3  # the base does turn: the check below is not trivially zero
    for qc, qs in zip(tracked.q[::10], sim.q[::10]):
        Rc, Rs = pin.XYZQUATToSE3(qc[:7]).rotation, pin.XYZQUATToSE3(qs[:7]).rotation
        assert np.linalg.norm(pin.log3(Rc.T @ Rs)) < 1e-5 * drift  # two integrators, dt = 0.05 s
        np.testing.assert_allclose(qc[:3], qs[:3], atol=1e-7)  # base position too [m]


def test_link_distances_are_the_coal_distances_of_links_3_5_7(robot, task):
    d = link_distances(robot, np.array([robot.configuration(task.q_start)]))
    names = {n for pair in d["pairs"] for n in pair}
    assert names == {f"{p}_link{i}_{k}" for p in "ab" for i, k in ((3, 0), (3, 1), (5, 0), (7, 0))}
    gm, gd = robot.collision_model, pin.GeometryData(robot.collision_model)
    q = robot.configuration(task.q_start)
    pin.updateGeometryPlacements(robot.model, robot.model.createData(), gm, gd, q)
    ref = min(coal.distance(gm.geometryObjects[gm.getGeometryId(x)].geometry,
                            coal.Transform3s(gd.oMg[gm.getGeometryId(x)].rotation, gd.oMg[gm.getGeometryId(x)].translation),
                            gm.geometryObjects[gm.getGeometryId(y)].geometry,
                            coal.Transform3s(gd.oMg[gm.getGeometryId(y)].rotation, gd.oMg[gm.getGeometryId(y)].translation),
                            coal.DistanceRequest(), coal.DistanceResult()) for x, y in d["pairs"])
    assert d["links"][0] == pytest.approx(ref, abs=1e-12)


# ------------------------------------------------------------------ optimized variant (slow)
@pytest.mark.slow
def test_optimized_variant_restores_the_base_attitude():
    from optplan.papers.spline_rrt import run_spline_rrt

    res = run_spline_rrt()
    sol = res.optimized["solution"]
    assert sol.success, sol.status
    kn = res.optimized["knots"]
    ex = res.optimized["executed_evaluation"]
    for a in ("A", "B"):
        assert kn[f"tracking_position_m_{a}"].max() < 1e-6  # at the knots
        assert ex[f"tracking_position_m_{a}"].max() < 1e-6  # executed, everywhere
        assert ex[f"tracking_orientation_rad_{a}"][-1] < 1e-5  # goal orientation
    assert np.linalg.norm(kn["base_rpy"][-1]) < 1e-6
    assert np.linalg.norm(ex["base_rpy"][-1]) < 1e-6  # the targets, on the independent simulator
    assert np.linalg.norm(res.evaluation["base_rpy"][-1]) > 1e-3  # Spline-RRT* alone leaves the base turned
    assert ex["link_distance_m"].min() >= 0.1
    assert np.abs(ex["qd"]).max() <= robot_rate_limit()


def robot_rate_limit():
    return float(RobotModel.from_name("splinerrt_ffsr").velocity_limit.min())


def test_quartic_nlp_durations_shorten_the_motion(task, plan, smoothed):
    """Where the speed limit binds, the quartic NLP (free durations) finds a shorter T than the
    length-proportional times of the linear solve, still within the limit and the paper's conditions."""
    _, T_lin, _ = smoothed
    hands, T, info = smooth_hand_paths(plan.paths, task.start, task.goal, 0.1, optimize_durations=True)
    assert all(v["status"] == "Solve_Succeeded" for v in info["nlp"].values())
    assert T < T_lin
    for h in hands.values():
        pp = h.position
        assert h.max_speed() <= 0.1 * (1 + 1e-9)
        np.testing.assert_allclose([pp(0.0, 1), pp(0.0, 2), pp(T, 1)], 0.0, atol=1e-9)


def test_joint_limits_stretch_the_duration(robot, task):
    """Eq. 6: with a tighter joint-acceleration limit the pipeline stretches T until the tracked
    joint motion respects it."""
    from optplan.papers.spline_rrt import run_spline_rrt

    po = CoordinatedRRTStarOptions(hand_radius=0.15, max_iterations=200, seed=1, time_limit=30.0)
    res = run_spline_rrt(robot, task, plan_options=po, joint_accel_limit=0.02, run_optimizer=False,
                         tracking=TrackingOptions(dt=0.25))
    rounds = res.info["stretch_rounds"]
    assert len(rounds) >= 2 and res.T > res.info["T_speed_s"]
    assert rounds[-1]["peak_accel_rad_s2"] <= 0.02 and rounds[-1]["peak_rate_rad_s"] <= robot.velocity_limit.min()
    assert rounds[0]["peak_accel_rad_s2"] > 0.02


def test_task_from_scene_needs_the_poses(robot):
    bad = Scene.from_dict({"name": "empty", "obstacles": []})
    with pytest.raises(ValueError, match="start_A"):
        SplineRRTTask.from_scene(robot, bad)


def test_figures_of_a_result_without_evaluation_is_a_clear_error():
    # a failed plan leaves ``evaluation`` None: its figures are a ValueError that says so, not a
    # TypeError from indexing None (found by mypy)
    from types import SimpleNamespace

    failed = SimpleNamespace(evaluation=None, hands={"left": None}, T=float("nan"))
    with pytest.raises(ValueError, match="no evaluation"):
        SplineRRTResult.figures(failed)  # type: ignore[arg-type]


def test_knot_selector_picks_the_knot_value_at_every_knot():
    """The hat functions the B-spline builder selects per-knot path samples with: one at their
    knot, zero at the others (so P @ w is P's column exactly), linear in between."""
    import casadi as ca

    from optplan.papers.spline_rrt import knot_selector

    N, T = 7, 3.3
    t = ca.SX.sym("t")
    f = ca.Function("w", [t], [knot_selector(t, T, N)])
    P = np.random.default_rng(3).normal(size=(3, N + 1))
    for k in range(N + 1):
        w = np.asarray(f(T * k / N)).ravel()
        assert np.abs(w - np.eye(N + 1)[k]).max() < 1e-12
        assert np.abs(P @ w - P[:, k]).max() < 1e-12
    w = np.asarray(f(T * 2.25 / N)).ravel()
    assert np.allclose(w[[2, 3]], [0.75, 0.25], atol=1e-12) and abs(w.sum() - 1.0) < 1e-12


def test_optimize_options_are_checked():
    from optplan.errors import OptionError
    from optplan.papers.spline_rrt import OptimizeOptions

    with pytest.raises(OptionError, match="transcription"):
        OptimizeOptions(transcription="collocation")
    with pytest.raises(OptionError, match="n_intervals"):
        OptimizeOptions(n_intervals=3)
    assert OptimizeOptions().transcription == "bspline"
