"""The dense collision check between knots of a free-floating robot (optplan.problem.guarantees
with optplan.collision.motion_bounds): the same violations and clearances as every pair at every
sampled time, computed the plain way (each sample's configuration by ``q_full``, all pair
distances by coal), including obstacles placed to graze the margin between knots."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.collision.checker import CollisionChecker
from optplan.model.robot import RobotModel
from optplan.problem import CollisionAvoidance
from optplan.problem import guarantees as G
from optplan.problem.evaluate import sampled_trajectory
from optplan.scene import Obstacle, Scene

MARGIN = 0.01


@pytest.fixture(scope="module")
def reach():
    """The free-floating reach (arm A's hand 0.3 m in 20 s, N = 20) solved, sampled at the dense
    check's times with the base integrated between knots."""
    from optplan.bench.modelling import _reach

    prob, _ = _reach(False)
    sol = prob.solve()
    assert sol.success
    o = G.GuaranteeOptions()
    N = len(sol.t) - 1
    T = float(sol.t[-1] - sol.t[0])
    t = np.linspace(0.0, T, o.density * N + 1)
    traj = sampled_trajectory(prob.robot, sol, t + sol.t[0], getattr(sol.evaluator, "com0", None))
    traj.base_quat = G._base_attitudes(prob.robot, sol, t + sol.t[0], o.density)
    return prob, sol, traj, t, T / N, N, o


def _plain_q(traj) -> np.ndarray:
    return np.array([traj.q_full(i) for i in range(traj.N + 1)])


def _reference(chk, Q, t, h, N, o, margin=MARGIN) -> dict[tuple[str, int], tuple[int, float]]:
    """Every pair at every sample (coal, all pairs per call): the worst violating sample per
    (pair, interval) -> (row, distance)."""
    D = np.array([chk.distances(q) for q in Q])
    k = np.clip((t / h).astype(int), 0, N - 1)
    out: dict[tuple[str, int], tuple[int, float]] = {}
    for r, p in zip(*np.nonzero(margin - D > o.tol + o.rel_tol * margin)):
        key = (f"{chk.pairs[p].name_a} | {chk.pairs[p].name_b}", int(k[r]))
        if key not in out or D[r, p] < out[key][1]:
            out[key] = (int(r), float(D[r, p]))
    return out


def _probe(robot, Q, row, gid, clearance, rng) -> Scene:
    """A sphere at ``clearance`` [m] from robot capsule ``gid`` at configuration ``Q[row]``, off
    the capsule's axis (so that the closest point is its middle)."""
    data, gd = robot.model.createData(), pin.GeometryData(robot.collision_model)
    pin.updateGeometryPlacements(robot.model, data, robot.collision_model, gd, Q[row])
    M = gd.oMg[gid]
    cap = robot.collision_model.geometryObjects[gid].geometry
    axis = M.rotation[:, 2]
    n = np.cross(axis, rng.normal(size=3))
    n /= np.linalg.norm(n)
    r = 0.04
    c = M.translation + n * (cap.radius + r + clearance)
    return Scene(name="graze", robot=robot.name,
                 obstacles=(Obstacle(name="probe", shape="sphere", placement=pin.SE3(np.eye(3), c), radius=r),))


def _check(term, robot, traj, t, h, N, o, data=None):
    data = G._collision_data(term, robot) if data is None else data
    out: list = []
    G._collision(out, "collision", term, data, traj, t, h, N, o)
    return {(v.component, v.interval): (v.t, v.value) for v in out}, data


def test_configurations_are_q_full_at_every_sample(reach):
    _, _, traj, *_ = reach
    np.testing.assert_allclose(traj.configurations(), _plain_q(traj), rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_dense_check_matches_every_pair_at_every_sample(reach, seed):
    """A sphere grazing the margin at a sample between knots (just inside, at and just outside
    the tolerance): the same (pair, interval) violations, worst samples and distances as the
    plain check; then the same after the trajectory moved (the check that starts from the
    previous check's bounds, as a re-solve does)."""
    prob, sol, traj, t, h, N, o = reach
    robot = prob.robot
    rng = np.random.default_rng(seed)
    Q = _plain_q(traj)
    arm = [g for g, go in enumerate(robot.collision_model.geometryObjects) if go.name.startswith("a_link")
           and hasattr(go.geometry, "halfLength")]
    row = int(rng.integers(0, N)) * o.density + int(rng.integers(1, o.density))    # never a knot
    allowed = o.tol + o.rel_tol * MARGIN
    clearance = MARGIN - allowed * float(rng.choice([0.5, 0.99, 1.01, 1.5, 3.0]))
    scene = _probe(robot, Q, row, int(rng.choice(arm)), clearance, rng)
    term = CollisionAvoidance(scene, margin=MARGIN, held_object=False)
    got, data = _check(term, robot, traj, t, h, N, o)
    chk = data.info["model"].checker
    ref = _reference(chk, Q, t, h, N, o)
    assert set(got) == set(ref)
    for key, (r, d) in ref.items():
        assert got[key][0] == pytest.approx(t[r], abs=1e-12)
        assert got[key][1] == pytest.approx(d, abs=1e-9)
    # the trajectory moved a little (a re-solve): from the previous check's bounds
    assert getattr(data, "previous", None) is not None
    moved = sampled_trajectory(robot, sol, t + sol.t[0], getattr(sol.evaluator, "com0", None))
    moved.q = moved.q + rng.normal(scale=2e-3, size=moved.q.shape)
    moved.base_quat = traj.base_quat + rng.normal(scale=1e-3, size=traj.base_quat.shape)
    got2, _ = _check(term, robot, moved, t, h, N, o, data=data)
    ref2 = _reference(chk, _plain_q(moved), t, h, N, o)
    assert set(got2) == set(ref2)
    for key, (_r, d) in ref2.items():
        assert got2[key][1] == pytest.approx(d, abs=1e-9)


def test_a_violation_between_knots_is_found_where_the_knots_are_clear(reach):
    """A sphere 5 mm inside the margin of arm A's wrist at a sample in the middle of an interval,
    with the pair clear of the margin at every knot: the check reports it there."""
    prob, _, traj, t, h, N, o = reach
    robot = prob.robot
    Q = _plain_q(traj)
    rng = np.random.default_rng(11)
    gid = robot.collision_model.getGeometryId("a_link7_0")
    for k in range(N):   # the first interval where the wrist moves enough that its knots stay clear
        row = k * o.density + o.density // 2
        scene = _probe(robot, Q, row, gid, MARGIN - 0.005, rng)
        chk = CollisionChecker(robot, scene, held_object=False)
        pair = next(i for i, p in enumerate(chk.pairs) if p.name_a == "a_link7_0" and p.name_b == "probe")
        knots = [chk.distances(Q[i])[pair] for i in (k * o.density, (k + 1) * o.density)]
        if min(knots) > MARGIN:
            break
    else:
        pytest.fail("no interval where the wrist moves enough")
    got, _ = _check(CollisionAvoidance(scene, margin=MARGIN, held_object=False), robot, traj, t, h, N, o)
    assert ("a_link7_0 | probe", k) in got
    ts, d = got[("a_link7_0 | probe", k)]
    assert d <= MARGIN - 0.005 + 1e-9 and t[k * o.density] < ts < t[(k + 1) * o.density]


@pytest.mark.parametrize("step", [0.0, 1e-3, 3e-2])
def test_floating_distances_below_match_every_pair_at_every_row(step):
    """:meth:`CollisionChecker.distance_bounds_below` of a free-flyer root, fresh and from an
    earlier call's bounds, against all distances at every row: the same entries, thresholds set
    at distances found between anchors (a pair exactly grazing it), bounds never above the
    distance."""
    rng = np.random.default_rng(5)
    eba = RobotModel.from_name("eba_ffsr")
    scene = Scene.load("floating_truss")
    chk = CollisionChecker(eba, scene)
    q0 = np.asarray(scene.extra["q_start"], float) * np.pi / 180.0
    s = np.linspace(0.0, 1.0, 121)[:, None]
    amp = rng.normal(scale=0.3, size=(3, eba.nj))
    J = np.clip(q0 + sum(amp[k] * np.sin((k + 1) * np.pi * s) / (k + 1) for k in range(3)), eba.lower, eba.upper)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    Q0 = np.array([np.r_[pin.SE3ToXYZQUAT(pin.SE3(pin.exp3(axis * 0.4 * np.sin(np.pi * sk)),
                                                  np.array([0.15, -0.1, 0.05]) * np.sin(2 * np.pi * sk))), J[i]]
                   for i, sk in enumerate(s[:, 0])])
    _, _, _, prev = chk.distance_bounds_below(Q0, 0.05)
    Q = Q0.copy()
    Q[:, 7:] += step * rng.normal(size=J.shape)
    Q[:, :3] += step * rng.normal(size=(len(Q), 3))
    D = np.array([chk.distances(q) for q in Q])
    inner = [i for i in range(len(Q)) if i % 10]
    graze = np.sort(D[inner].ravel())
    for threshold in (0.0, 0.05, float(graze[3]), float(np.nextafter(graze[40], np.inf))):
        r_ref, p_ref = np.nonzero(D < threshold)
        for previous in (None, prev):
            rows, pairs, dist, nxt = chk.distance_bounds_below(Q, threshold, previous=previous)
            np.testing.assert_array_equal(rows, r_ref)
            np.testing.assert_array_equal(pairs, p_ref)
            np.testing.assert_allclose(dist, D[r_ref, p_ref], rtol=0, atol=1e-6)
            assert (nxt[1] - D.T).max() <= 1e-6
    assert len(np.nonzero(D < 0.05)[0]) > 0


@pytest.mark.slow
def test_dense_check_breakdown_counts_fewer_coal_calls_than_it_checks():
    """``python -m optplan.bench.dense_check``: the collision reach is checked with fewer coal
    distances than samples × pairs, a re-check with fewer still."""
    from optplan.bench.dense_check import breakdown

    out = breakdown(repeat=1)
    assert out["success"]
    rows, pairs = out["samples x pairs"]
    single, every = out["coal calls, first check (single pair, all pairs)"]
    assert every == 21 and single + every * pairs < rows * pairs
    assert sum(out["coal calls, re-check (single pair, all pairs)"]) < single
