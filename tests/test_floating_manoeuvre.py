"""Steering manoeuvres kept as planned (optplan.floating_manoeuvre) and a steered plan verified end to
end by optplan.floating_pipeline, judged independently: a finer re-integration of the base from zero
momentum (another density and RK4 step), Pinocchio FK for the closed chain and the object's goal,
coal's exact distances for the clearance."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.collision.checker import CollisionChecker
from optplan.errors import OptionError
from optplan.floating_manoeuvre import ChainedMotion, ManoeuvreMotion, MotionPart, manoeuvre_spans, sharp_corners
from optplan.floating_pipeline import options_for_scene, run_floating_pipeline, scene_start, trial_goal
from optplan.model.floating import simulate_base
from optplan.model.robot import RobotModel
from optplan.scene import Scene


def test_spans_are_exact_returns_of_the_joints():
    rng = np.random.default_rng(1)
    J = rng.normal(size=(9, 3))
    J[6] = J[2]          # a loop 2 → 6
    J[4] = J[2]          # inside it
    J[8] = J[7]          # a repeated waypoint alone: no loop
    assert manoeuvre_spans(J) == [(2, 6)]
    assert manoeuvre_spans(J + 1e-12 * (np.arange(9) == 6)[:, None]) == [(2, 4)]
    corners = sharp_corners(np.array([[0, 0], [1, 0], [2, 0], [2, 1], [1, 1.0]]), 0.5)
    assert corners == [2, 3]
    assert sharp_corners(np.array([[0, 0], [1, 0], [2, 0], [2, 1], [1, 1.0]]), 0.5, [(1, 3)]) == []


def test_edge_splines_are_scipys_not_a_knot_splines():
    """The edges' splines built from the cached linear map are scipy's CubicSpline of the same points."""
    from scipy.interpolate import CubicSpline

    rng = np.random.default_rng(4)
    J = np.cumsum(rng.normal(0.0, 0.1, size=(6, 3)), axis=0)
    pts: list[np.ndarray] = []

    def bend(q):   # a smooth, point-dependent "projection"
        p = q + 0.01 * np.sin(3.0 * q[::-1])
        pts.append(p)
        return p

    mm = ManoeuvreMotion(J, bend, speed=1.0, step_rad=0.03)
    assert mm.projections == len(pts) > 0
    for k, (a, b) in enumerate(zip(J[:-1], J[1:])):
        sp = mm._splines[k]
        s = sp.x
        ref = CubicSpline(s, sp(s), axis=0)
        u = np.linspace(0.0, 1.0, 57)
        assert np.allclose(sp(u), ref(u), atol=1e-13) and np.allclose(sp(u, 1), ref(u, 1), atol=1e-11)
        assert np.allclose(sp(s[[0, -1]]), [a, b], atol=1e-14)


def test_sampling_all_times_at_once_equals_each_edges_spline():
    """``sample`` evaluates every edge's pieces from one table: the same positions and velocities as
    each edge's scipy ``PPoly`` at its time-law parameter (edges of different point counts, repeated
    edges, times at the waypoints and outside the motion)."""
    rng = np.random.default_rng(6)
    loop = np.vstack([np.zeros(4), np.cumsum(rng.normal(0.0, 0.15, size=(4, 4)), axis=0), np.zeros(4)])
    J = np.vstack([loop, loop[1:], [0.4, -0.2, 0.1, 0.3]])
    mm = ManoeuvreMotion(J, lambda q: q + 0.01 * np.sin(3.0 * q[::-1]), speed=0.7, step_rad=0.04)
    assert mm.repeated_edges > 0 and len({len(sp.x) for sp in mm._splines}) > 1
    t = np.r_[rng.uniform(-0.1, mm.duration + 0.1, 2000), mm._t0]   # and the waypoints, and beyond the ends
    got = mm.sample(t)
    tc = np.clip(t, 0.0, mm.duration)
    e = np.clip(np.searchsorted(mm._t0, tc, side="right") - 1, 0, len(mm._splines) - 1)
    for k in range(len(tc)):
        sp, d = mm._splines[e[k]], mm._dur[e[k]]
        tau = np.clip((tc[k] - mm._t0[e[k]]) / d, 0.0, 1.0)
        s, ds = tau**3 * (10 - 15 * tau + 6 * tau**2), 30 * tau**2 * (1 - tau) ** 2
        assert np.allclose(got["q"][k], sp(s), rtol=0, atol=1e-13)
        assert np.allclose(got["qd"][k], sp(s, 1) * ds / d, rtol=0, atol=1e-12)


def test_repeated_loop_edges_are_projected_once():
    """A loop traversed three times: each distinct edge projected once, and the motion equal, edge by
    edge, to that of the loop traversed once (its own projections); a failed projection of a
    repeated edge leaves the motion not ok."""
    rng = np.random.default_rng(5)
    loop = np.vstack([np.zeros(3), np.cumsum(rng.normal(0.0, 0.1, size=(3, 3)), axis=0), np.zeros(3)])
    J = np.vstack([loop, loop[1:], loop[1:]])
    calls: list[np.ndarray] = []

    def bend(q):
        calls.append(q.copy())
        return q + 0.01 * np.sin(3.0 * q[::-1])

    once = ManoeuvreMotion(loop, bend, speed=1.0, step_rad=0.03)
    n_once = len(calls)
    thrice = ManoeuvreMotion(J, bend, speed=1.0, step_rad=0.03)
    assert thrice.projections == once.projections == n_once == len(calls) - n_once > 0
    assert thrice.repeated_edges == 2 * (len(loop) - 1) and thrice.ok
    assert thrice.duration == pytest.approx(3 * once.duration)
    t = np.linspace(0.0, once.duration, 101)
    for k in range(3):
        a, b = once.sample(t), thrice.sample(t + k * once.duration)
        assert np.allclose(a["q"], b["q"], atol=1e-12) and np.allclose(a["qd"], b["qd"], atol=1e-10)
    fail_at = loop[2] + 0.5 * (loop[3] - loop[2])
    bad = ManoeuvreMotion(J, lambda q: None if np.allclose(q, fail_at) else q, speed=1.0, step_rad=0.03)
    assert not bad.ok and bad.repeated_edges == 2 * (len(loop) - 1)


def test_manoeuvre_time_law_and_chaining():
    """Rest at every waypoint, through every waypoint, velocities = finite differences; the chain
    plays its parts one after the other."""
    J = np.array([[0.0, 0.0], [0.3, -0.1], [0.1, 0.2]])
    mm = ManoeuvreMotion(J, lambda q: q, speed=1.0, duration_factor=3.0, step_rad=0.05)
    assert mm.ok and mm.duration == pytest.approx(3.0 * (0.3 + 0.3))
    s = mm.sample([0.0, 0.9, mm.duration])
    assert np.allclose(s["q"], J, atol=1e-12) and np.allclose(s["qd"], 0.0, atol=1e-12)
    t = np.linspace(0.01, mm.duration - 0.01, 50)
    h = 1e-6
    fd = (mm.sample(t + h)["q"] - mm.sample(t - h)["q"]) / (2 * h)
    assert np.allclose(mm.sample(t)["qd"], fd, atol=1e-6)
    assert np.max(np.abs(mm.sample(np.linspace(0, mm.duration, 400))["qd"])) <= 1.875 / 3.0 + 1e-9
    ch = ChainedMotion([MotionPart(mm), MotionPart(ManoeuvreMotion(J[::-1], lambda q: q, speed=1.0))])
    assert ch.t[-1] == pytest.approx(2 * mm.duration) and ch.success and ch.status.value == "Kept_Manoeuvre"
    assert np.allclose(ch.sample([mm.duration + 0.9])["q"], J[1])
    with pytest.raises(OptionError, match="waypoints"):
        ManoeuvreMotion(J[:1], lambda q: q, speed=1.0)
    with pytest.raises(OptionError, match="at least one part"):
        ChainedMotion([])


@pytest.fixture(scope="module")
def steered():
    """Trial 13 of ``optplan bench generalize --scene floating`` (seed 0): a plan with a steering
    manoeuvre, as the benchmark runs it."""
    robot = RobotModel.from_name("eba_ffsr")
    scene = Scene.load("floating_truss")
    goal = trial_goal(scene, 13, 0)
    res = run_floating_pipeline(robot, scene, scene_start(robot, scene), goal, options_for_scene(scene), seed=13)
    return robot, scene, goal, res



def _reintegrated(robot, res):
    """The result's base re-integrated independently at 4× verify's density with finer RK4 steps;
    its final attitude checked against the result's target (≤ 1e-6 rad); the simulation and the samples."""
    sol = res.solution
    t = np.linspace(sol.t[0], sol.t[-1], 40 * (len(sol.t) - 1) + 1)
    smp = sol.sample(t)
    sim = simulate_base(robot, (t, smp["q"], smp["qd"]), t, substeps=4)
    assert float(np.linalg.norm(pin.log3(res.end_attitude.T @ sim.final_base.rotation))) <= 1e-6
    return sim, smp

def test_a_steered_plan_is_verified_end_to_end(steered):
    robot, scene, goal, res = steered
    spans = manoeuvre_spans(res.plan.joints)
    assert spans and spans[0][1] - spans[0][0] > 20, "trial 13 is no longer a steered plan"
    assert any(a[1] == "Kept_Manoeuvre" for a in res.attempts)
    assert res.solution.status.value == "Solve_Succeeded" and res.solution.iterations > 0
    assert res.success, res.attempts
    # independent: the base re-integrated at 4× verify's density with finer RK4 steps
    sim, smp = _reintegrated(robot, res)
    d = robot.model.createData()
    grasp = scene.object.grasps
    rel = []
    for q in sim.q[::7]:
        pin.framesForwardKinematics(robot.model, d, q)
        MA = d.oMf[robot.arm("A").ee_frame_id] * grasp["A"].inverse()
        MB = d.oMf[robot.arm("B").ee_frame_id] * grasp["B"].inverse()
        rel.append(MA.actInv(MB))
    err = [max(np.linalg.norm(r.translation - rel[0].translation), np.linalg.norm(pin.log3(rel[0].rotation.T @ r.rotation)))
           for r in rel]
    assert max(err) <= 2e-6     # the object held by both hands all along (1e-6 each from the grasp)
    pin.framesForwardKinematics(robot.model, d, sim.q[-1])
    e = goal.actInv(d.oMf[robot.arm("A").ee_frame_id] * grasp["A"].inverse())
    assert np.linalg.norm(e.translation) <= 1e-3 and np.linalg.norm(pin.log3(e.rotation)) <= 1e-3
    dmin, _, _ = CollisionChecker(robot, scene).min_distance_along(sim.q[::3])
    assert dmin >= 0.0
    assert np.all(smp["q"] >= robot.lower - 1e-12) and np.all(smp["q"] <= robot.upper + 1e-12)


@pytest.mark.slow
def test_restored_attitude_end_to_end_after_resteering():
    """Truss trial 2 with restoration: the plan ends with the restoring manoeuvre, whose kept
    version misses the initial attitude by ~1e-3 rad; the pipeline steers the rest off from the real
    end (kept manoeuvres again) until verify passes. Judged independently: the base re-integrated
    at 4× verify's density with finer RK4 steps ends at the INITIAL attitude (≤ 1e-6 rad) and the
    object at the world goal (Pinocchio FK), coal clearance ≥ 0."""
    robot = RobotModel.from_name("eba_ffsr")
    scene = Scene.load("floating_truss")
    goal = trial_goal(scene, 2, 0)
    res = run_floating_pipeline(robot, scene, scene_start(robot, scene), goal,
                                options_for_scene(scene, restore_attitude=True), seed=2)
    assert any(a[1] == "resteer" for a in res.attempts), "trial 2 no longer needs the re-steering"
    assert res.success, res.attempts
    sol = res.solution
    t = np.linspace(sol.t[0], sol.t[-1], 40 * (len(sol.t) - 1) + 1)
    smp = sol.sample(t)
    sim = simulate_base(robot, (t, smp["q"], smp["qd"]), t, substeps=4)
    assert float(np.linalg.norm(pin.log3(sim.final_base.rotation))) <= 1e-6   # the initial attitude: identity
    d = robot.model.createData()
    pin.framesForwardKinematics(robot.model, d, sim.q[-1])
    e = goal.actInv(d.oMf[robot.arm("A").ee_frame_id] * scene.object.grasps["A"].inverse())
    assert np.linalg.norm(e.translation) <= 1e-3 and np.linalg.norm(pin.log3(e.rotation)) <= 1e-3
    dmin, _, _ = CollisionChecker(robot, scene).min_distance_along(sim.q[::3])
    assert dmin >= 0.0


def test_resteer_options_are_checked():
    from optplan.floating_pipeline import FloatingPipelineOptions

    assert FloatingPipelineOptions(resteer_rounds=0).resteer_rounds == 0
    with pytest.raises(OptionError, match="resteer_rounds"):
        FloatingPipelineOptions(resteer_rounds=-1)
    with pytest.raises(OptionError, match="resteer_time_s"):
        FloatingPipelineOptions(resteer_time_s=0.0)
    with pytest.raises(OptionError, match="retry_corner_cos"):
        FloatingPipelineOptions(retry_corner_cos=1.5)
    with pytest.raises(OptionError, match="max_iter"):
        FloatingPipelineOptions(max_iter=0)


def test_refinement_goes_to_the_intervals_the_chain_drift_predicts():
    """Twice the intervals, or as many as the h⁴ drift of the closed chain predicts for half the
    tolerance (multiple of 8), never past the cap."""
    from types import SimpleNamespace

    from optplan.floating_pipeline import FloatingPipelineOptions, _refined_intervals

    o = FloatingPipelineOptions(max_intervals=128)
    rep = lambda r: SimpleNamespace(max_closed_chain_residual=r)   # noqa: E731
    assert _refined_intervals(24, rep(2e-6), o) == 48            # 24 · 4^¼ = 34 < 48
    assert _refined_intervals(24, rep(float("nan")), o) == 48    # a clearance failure: doubled
    n = _refined_intervals(24, rep(3.2e-5), o)                   # 24 · 64^¼ = 67.9
    assert n == 72 and 3.2e-5 * (24 / n) ** 4 <= 0.5e-6
    assert _refined_intervals(24, rep(3.2e-5), FloatingPipelineOptions()) == 64


@pytest.mark.slow
@pytest.mark.parametrize("scene_name, index", [("floating_stow", 9), ("floating_truss", 17)])
def test_former_failures_are_verified(scene_name, index):
    """Stow trial 9 (its first solve does not converge: the retry cuts the corners and lowers the
    knots' margin to what the plan keeps) and truss trial 17 (a steering manoeuvre that grazed a
    beam: the loops now keep a clearance). Judged independently: the base re-integrated at 4×
    verify's density, coal clearance ≥ 0, the object at its goal."""
    robot = RobotModel.from_name("eba_ffsr")
    scene = Scene.load(scene_name)
    goal = trial_goal(scene, index, 0)
    res = run_floating_pipeline(robot, scene, scene_start(robot, scene), goal, options_for_scene(scene), seed=index)
    assert res.success, res.attempts
    sim, smp = _reintegrated(robot, res)
    dmin, _, _ = CollisionChecker(robot, scene).min_distance_along(sim.q[::2])
    assert dmin >= 0.0
    d = robot.model.createData()
    pin.framesForwardKinematics(robot.model, d, sim.q[-1])
    M = d.oMf[robot.arm("A").ee_frame_id] * scene.object.grasps["A"].inverse()
    world = (scene.extra or {}).get("target_frame", "world") == "world"   # stow: a goal in the base frame
    e = goal.actInv(M if world else sim.final_base.actInv(M))   # sim.q holds the base: oMf is in the world
    assert np.linalg.norm(e.translation) <= 1e-3 and np.linalg.norm(pin.log3(e.rotation)) <= 1e-3
