"""Scenes (optplan.scene), exact collision checking (optplan.collision.checker) and independent trajectory
verification (optplan.verification).

* Scene.load refuses bad files with a ModelError / UnknownNameError naming the offending value.
* Scene.load("transport") has the content of models/scenes/transport.toml.
* CollisionChecker distances equal a direct coal computation (placements from Pinocchio, the
  object pose from the hand frame and the grasp); is_valid agrees with min_distance.
* verify() on hand-made solution-like objects with known closed-chain, limit and clearance
  figures reports exactly those figures.
"""
from __future__ import annotations

from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest

from optplan.collision.checker import CollisionChecker
from optplan.errors import ModelError, UnknownNameError
from optplan.geometry.spatial import exp3, rotx, roty, rotz
from optplan.problem import ClosedChain
from optplan.scene import Scene, available_scenes
from optplan.verification import verify

DEG = np.pi / 180

GOOD = """
name = "tiny"
robot = "tcbirrt_dual_arm"
angle_unit = "deg"

[object]
size = [2.0, 0.8, 0.8]
grasps = { A = { xyz = [1.2, 0.0, 0.0], rpy = [0.0, 90.0, 0.0] }, B = { xyz = [-1.2, 0.0, 0.0], rpy = [0.0, -90.0, 0.0] } }

[start]
xyz = [1.6, 0.0, 1.4]

[[obstacles]]
name = "box_1"
shape = "box"
size = [0.3, 0.3, 0.3]
xyz = [2.1, 0.0, 2.3]

[[obstacles]]
name = "ball"
shape = "sphere"
radius = 0.25
xyz = [0.0, 0.0, 5.0]

[[obstacles]]
name = "rod"
shape = "capsule"
radius = 0.1
length = 1.0
xyz = [-2.0, 0.0, 2.0]
rpy = [90.0, 0.0, 0.0]
"""


def _write(tmp_path: Path, text: str, name: str = "scene.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


# --------------------------------------------------------------------------- Scene.load errors
def test_good_scene_file_loads(tmp_path):
    sc = Scene.load(_write(tmp_path, GOOD))
    assert [o.name for o in sc.obstacles] == ["box_1", "ball", "rod"]
    assert [o.shape for o in sc.obstacles] == ["box", "sphere", "capsule"]
    assert sc.obstacle("rod").length == 1.0 and sc.obstacle("rod").radius == 0.1
    np.testing.assert_allclose(sc.obstacle("rod").placement.rotation, rotx(90 * DEG), atol=1e-15)
    assert sc.goal is None
    # the same text as a str path works too
    assert Scene.load(str(tmp_path / "scene.toml")).name == "tiny"


def test_missing_scene_file(tmp_path):
    p = tmp_path / "does_not_exist.toml"
    with pytest.raises(ModelError, match="does_not_exist.toml"):
        Scene.load(p)


def test_unknown_scene_name_lists_the_valid_ones():
    with pytest.raises(UnknownNameError) as ei:
        Scene.load("no_such_scene")
    msg = str(ei.value)
    assert "no_such_scene" in msg and "transport" in msg
    assert "transport" in available_scenes()


def test_malformed_toml(tmp_path):
    with pytest.raises(ModelError, match="malformed TOML"):
        Scene.load(_write(tmp_path, GOOD.replace('shape = "sphere"', 'shape = "sphere')))


@pytest.mark.parametrize("old,new,needle", [
    ('shape = "sphere"', 'shape = "cone"', "'cone'"),
    ('size = [0.3, 0.3, 0.3]', 'size = [0.3, -0.3, 0.3]', "-0.3"),
    ('size = [0.3, 0.3, 0.3]', 'size = [0.3, 0.0, 0.3]', "0.0"),
    ('size = [0.3, 0.3, 0.3]', 'size = [0.3, 0.3]', "[0.3, 0.3]"),
    ('radius = 0.25', 'radius = -0.25', "-0.25"),
    ('radius = 0.25', 'radius = "big"', "'big'"),
    ('length = 1.0', 'length = -1.0', "-1.0"),
    ('name = "ball"', 'name = "box_1"', "'box_1'"),
    ('angle_unit = "deg"', 'angle_unit = "grad"', "'grad'"),
    ('xyz = [2.1, 0.0, 2.3]', 'xyz = [2.1, 0.0, nan]', "nan"),
])
def test_bad_scene_values_are_named(tmp_path, old, new, needle):
    assert old in GOOD
    with pytest.raises(ModelError) as ei:
        Scene.load(_write(tmp_path, GOOD.replace(old, new, 1)))
    assert needle in str(ei.value), str(ei.value)


def test_duplicate_obstacle_message_names_the_obstacle(tmp_path):
    with pytest.raises(ModelError, match=r"duplicate obstacle name 'box_1'"):
        Scene.load(_write(tmp_path, GOOD.replace('name = "ball"', 'name = "box_1"')))


@pytest.mark.parametrize("old,new", [('radius = 0.25', 'radius = nan'), ('radius = 0.25', 'radius = inf'),
                                     ('length = 1.0', 'length = nan')])
def test_non_finite_radius_or_length_refused(tmp_path, old, new):
    with pytest.raises(ModelError):
        Scene.load(_write(tmp_path, GOOD.replace(old, new)))


@pytest.mark.parametrize("bad", ["[2.0, -0.8, 0.8]", "[0.0, 0.8, 0.8]"])
def test_non_positive_object_size_refused(tmp_path, bad):
    with pytest.raises(ModelError):
        Scene.load(_write(tmp_path, GOOD.replace("size = [2.0, 0.8, 0.8]", f"size = {bad}")))


# --------------------------------------------------------------------------- transport content
def test_transport_scene_content():
    sc = Scene.load("transport")
    assert sc.name == "transport" and sc.robot == "tcbirrt_dual_arm"
    assert [o.name for o in sc.obstacles] == ["hanging_box", "truss_beam"]
    hb, tb = sc.obstacle("hanging_box"), sc.obstacle("truss_beam")
    assert hb.shape == tb.shape == "box"
    np.testing.assert_allclose(hb.size, (0.3, 0.3, 0.3))
    np.testing.assert_allclose(tb.size, (3.0, 0.2, 0.2))
    np.testing.assert_allclose(hb.placement.translation, (2.1, 0.0, 2.3))
    np.testing.assert_allclose(tb.placement.translation, (1.6, 0.0, 0.6))
    np.testing.assert_allclose(hb.placement.rotation, np.eye(3))
    obj = sc.object
    np.testing.assert_allclose(obj.size, (2.0, 0.8, 0.8))
    assert set(obj.grasps) == {"A", "B"}
    np.testing.assert_allclose(obj.grasps["A"].translation, (1.2, 0, 0))
    np.testing.assert_allclose(obj.grasps["B"].translation, (-1.2, 0, 0))
    np.testing.assert_allclose(obj.grasps["A"].rotation, roty(90 * DEG), atol=1e-15)
    np.testing.assert_allclose(obj.grasps["B"].rotation, roty(-90 * DEG), atol=1e-15)
    # tool z axis points out of the end face: +x of the object for A, -x for B
    np.testing.assert_allclose(obj.grasps["A"].rotation[:, 2], (1, 0, 0), atol=1e-15)
    np.testing.assert_allclose(obj.grasps["B"].rotation[:, 2], (-1, 0, 0), atol=1e-15)
    assert obj.exclude_links == ("a_link6", "a_link7", "b_link6", "b_link7")
    np.testing.assert_allclose(sc.start.translation, (1.6, 0.0, 1.4))
    np.testing.assert_allclose(sc.goal.translation, (1.6, 0.0, 3.2))
    np.testing.assert_allclose(sc.start.rotation, rotz(90 * DEG), atol=1e-15)
    np.testing.assert_allclose(sc.goal.rotation, rotz(90 * DEG), atol=1e-15)
    # object frame → hand frame and back
    H = obj.hand_pose("A", sc.start)
    assert obj.object_pose_from_hand("A", H).isApprox(sc.start, 1e-12)
    with pytest.raises(UnknownNameError, match="nope"):
        sc.obstacle("nope")


# --------------------------------------------------------------------------- CollisionChecker
def _direct_distances(robot, scene, q, pairs):
    """Distances of the given pairs computed directly with Pinocchio placements + coal."""
    gm = robot.collision_model
    gd = pin.GeometryData(gm)
    data = robot.model.createData()
    pin.updateGeometryPlacements(robot.model, data, gm, gd, q)
    pin.framesForwardKinematics(robot.model, data, q)
    hand = data.oMf[robot.frame_id(robot.arm("A").ee_frame)]
    Mo = hand * scene.object.grasps["A"].inverse()
    obj = (coal.Box(*scene.object.size), coal.Transform3s(Mo.rotation, Mo.translation))

    def geo(kind, i):
        if kind == "robot":
            M = gd.oMg[i]
            return gm.geometryObjects[i].geometry, coal.Transform3s(M.rotation, M.translation)
        if kind == "obstacle":
            o = scene.obstacles[i]
            g = coal.Box(*o.size) if o.shape == "box" else coal.Sphere(o.radius)
            return g, coal.Transform3s(o.placement.rotation, o.placement.translation)
        return obj

    kinds = {"self": ("robot", "robot"), "robot-obstacle": ("robot", "obstacle"),
             "object-obstacle": ("object", "obstacle"), "object-robot": ("object", "robot")}
    out = []
    for p in pairs:
        ka, kb = kinds[p.kind]
        (g1, t1), (g2, t2) = geo(ka, p.a), geo(kb, p.b)
        out.append(coal.distance(g1, t1, g2, t2, coal.DistanceRequest(), coal.DistanceResult()))
    return np.array(out)


@pytest.fixture(scope="module")
def transport():
    return Scene.load("transport")


def test_checker_pairs(tcb, transport):
    chk = CollisionChecker(tcb, transport)
    kinds = [p.kind for p in chk.pairs]
    assert kinds.count("self") == len(tcb.collision_pairs)
    assert kinds.count("object-obstacle") == 2
    # fixed base geometry is not checked against obstacles; every moving link is
    n_moving = sum(1 for o in tcb.collision_model.geometryObjects if o.parentJoint != 0)
    assert kinds.count("robot-obstacle") == 2 * n_moving
    # the object is checked against every link except the excluded (gripping) ones
    names = {p.name_b for p in chk.pairs if p.kind == "object-robot"}
    assert not any(n.startswith(("a_link6", "a_link7", "b_link6", "b_link7")) for n in names)
    assert "base_0" in names and "a_link4_0" in names
    assert CollisionChecker(tcb, transport, held_object=False).object is None
    assert not any(p.kind.startswith("object") for p in CollisionChecker(tcb, transport, held_object=False).pairs)


def test_checker_distances_equal_direct_coal(tcb, transport, rng):
    chk = CollisionChecker(tcb, transport)
    by_kind = {}
    for i, p in enumerate(chk.pairs):
        by_kind.setdefault(p.kind, []).append(i)
    idx = np.concatenate([rng.choice(v, size=min(6, len(v)), replace=False) for v in by_kind.values()])
    n_sep = n_pen = 0
    for _ in range(6):
        q = tcb.random_configuration(rng)
        d = chk.distances(q)
        ref = _direct_distances(tcb, transport, q, [chk.pairs[i] for i in idx])
        np.testing.assert_allclose(d[idx], ref, atol=1e-12)
        n_sep += int(np.sum(ref > 0))
        n_pen += int(np.sum(ref < 0))
        dmin, pair = chk.min_distance(q)
        # a second coal evaluation may differ in the last bit (GJK/EPA warm start): ties by value
        assert dmin == pytest.approx(d.min(), abs=1e-9) and d[chk.pairs.index(pair)] == pytest.approx(dmin, abs=1e-9)
    assert n_sep > 0 and n_pen > 0, "random configurations should give separated and penetrating pairs"


def test_checker_object_pose_follows_hand(tcb, transport, rng):
    chk = CollisionChecker(tcb, transport)
    q = tcb.random_configuration(rng)
    Mo = chk.object_pose(q)
    data = tcb.model.createData()
    pin.framesForwardKinematics(tcb.model, data, q)
    hand = data.oMf[tcb.arm("A").ee_frame_id]
    assert (Mo * transport.object.grasps["A"]).isApprox(hand, 1e-12)
    with pytest.raises(ValueError):
        CollisionChecker(tcb, transport, held_object=False).object_pose(q)


def test_is_valid_agrees_with_min_distance(tcb, transport, rng):
    chk = CollisionChecker(tcb, transport)
    seen = {True: 0, False: 0}
    for _ in range(40):
        q = tcb.random_configuration(rng)
        dmin, _ = chk.min_distance(q)
        valid = chk.is_valid(q)
        assert valid == (dmin > 0), f"is_valid={valid} but min_distance={dmin}"
        seen[valid] += 1
        for m in (0.05, 0.3):
            assert chk.is_valid(q, margin=m) == (dmin >= m)
    # self-collision only, arms folded away: a valid configuration must exist
    chk_self = CollisionChecker(tcb, None)
    q = tcb.neutral()
    assert chk_self.is_valid(q) == (chk_self.min_distance(q)[0] > 0)
    assert seen[False] > 0
    assert chk_self.min_distance(q)[0] > 0


def test_checker_without_pairs(tcb):
    chk = CollisionChecker(tcb, None, self_collision=False)
    assert chk.pairs == []
    assert chk.min_distance(tcb.neutral()) == (float("inf"), None)
    assert chk.is_valid(tcb.neutral())


# --------------------------------------------------------------------------- verify
class FakeSolution:
    """Solution-like object: knots ``t`` and a user-defined ``sample``."""

    def __init__(self, t, fn):
        self.t = np.asarray(t, float)
        self._fn = fn

    def sample(self, t):
        t = np.atleast_1d(np.asarray(t, float))
        q, qd = zip(*(self._fn(tt) for tt in t))
        return {"t": t, "q": np.array(q), "qd": np.array(qd)}


def _hands(robot, q):
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.arm("A").ee_frame_id].copy(), data.oMf[robot.arm("B").ee_frame_id].copy()


def test_verify_reports_known_closed_chain_violation(tcb, rng):
    q0 = tcb.random_joints(rng) * 0.5
    Ma, Mb = _hands(tcb, q0)
    offset = pin.SE3(exp3(np.array([0.0, 0.06, 0.08])), np.array([0.03, -0.04, 0.0]))  # 0.1 rad, 0.05 m
    cc = ClosedChain("A", "B", Ma.actInv(Mb) * offset)
    sol = FakeSolution(np.linspace(0, 4, 5), lambda t: (q0, np.zeros(14)))
    rep = verify(tcb, sol, closed_chain=cc, density=3)
    assert rep.n_samples == 4 * 3 + 1
    assert rep.max_closed_chain_position_error_m == pytest.approx(0.05, abs=1e-12)
    assert rep.max_closed_chain_rotation_error_rad == pytest.approx(0.1, abs=1e-12)
    assert rep.max_closed_chain_residual == pytest.approx(0.1, abs=1e-12)
    assert rep.max_position_limit_violation == 0.0 and rep.max_velocity_limit_violation == 0.0
    assert np.isnan(rep.max_momentum_residual) and np.isnan(rep.final_base_attitude_error_rad)
    # a consistent closed chain reports ~0
    rep0 = verify(tcb, sol, closed_chain=ClosedChain.from_configuration(tcb, q0))
    assert rep0.max_closed_chain_residual < 1e-12
    assert np.isnan(verify(tcb, sol).max_closed_chain_residual)


def test_verify_violation_in_the_middle_of_a_motion(tcb, rng):
    """Arm B's last joint turns by 0.3 sin(πt/T): the relative rotation error peaks at 0.3 rad at
    t = T/2 (a sample time), the hands' relative position changes only through that joint."""
    q0 = tcb.random_joints(rng) * 0.5
    cc = ClosedChain.from_configuration(tcb, q0)
    T = 2.0
    j7 = tcb.joint_names.index("b_joint7")

    def fn(t):
        q = q0.copy()
        q[j7] += 0.3 * np.sin(np.pi * t / T)
        qd = np.zeros(14)
        qd[j7] = 0.3 * np.pi / T * np.cos(np.pi * t / T)
        return q, qd

    rep = verify(tcb, FakeSolution(np.linspace(0, T, 3), fn), closed_chain=cc, density=4)
    assert rep.max_closed_chain_rotation_error_rad == pytest.approx(0.3, abs=1e-9)
    # joint 7 rotates the hand about its own axis: the position error is the hand frame's offset
    # from that axis swept by 0.3 rad, computed here directly from Pinocchio
    q = q0.copy()
    q[j7] += 0.3
    _, Mb1 = _hands(tcb, q)
    Ma0, Mb0 = _hands(tcb, q0)
    err = (Ma0.actInv(Mb0)).actInv(Ma0.actInv(Mb1))
    assert rep.max_closed_chain_position_error_m == pytest.approx(np.linalg.norm(err.translation), abs=1e-9)
    vmax = 0.3 * np.pi / T
    assert rep.max_velocity_limit_violation == pytest.approx(max(0.0, vmax - tcb.velocity_limit[j7]), abs=1e-12)


def test_verify_limits_and_clearance(tcb, transport, rng):
    q0 = tcb.random_joints(rng) * 0.3
    q0[2] = tcb.upper[2] + 0.125
    qd = np.zeros(14)
    qd[5] = -(tcb.velocity_limit[5] + 0.25)
    sol = FakeSolution([0.0, 1.0], lambda t: (q0, qd))
    rep = verify(tcb, sol, transport, density=2)
    assert rep.max_position_limit_violation == pytest.approx(0.125, abs=1e-12)
    assert rep.max_velocity_limit_violation == pytest.approx(0.25, abs=1e-12)
    dmin, pair = CollisionChecker(tcb, transport).min_distance(q0)
    assert rep.min_clearance_m == pytest.approx(dmin, abs=1e-12)
    assert rep.min_clearance_pair == f"{pair.name_a} / {pair.name_b}"
    assert np.isnan(verify(tcb, sol, transport, check_velocity=False).max_velocity_limit_violation)
    with pytest.raises(ValueError, match="density"):
        verify(tcb, sol, density=0)
    d = rep.to_dict()
    assert d["min_clearance_pair"] == rep.min_clearance_pair and '"n_samples": 3' in rep.to_json()


def test_verify_floating_base_static(eba):
    """A floating robot that does not move: the simulated base stays at the identity, the NLP's base
    attitude (here a known 0.2 rad rotation at the last knot) is reported as the mismatch."""
    q0 = np.full(eba.nj, 0.1)
    sol = FakeSolution(np.linspace(0, 2, 3), lambda t: (q0, np.zeros(eba.nj)))
    quat = np.tile([0, 0, 0, 1.0], (3, 1))
    quat[2] = pin.Quaternion(exp3(np.array([0.2, 0.0, 0.0]))).coeffs()
    sol.base_quat = quat
    rep = verify(eba, sol)
    assert rep.final_base_attitude_error_rad == pytest.approx(0.0, abs=1e-14)
    assert rep.max_momentum_residual < 1e-12
    assert rep.base_attitude_mismatch_rad == pytest.approx(0.2, abs=1e-12)
