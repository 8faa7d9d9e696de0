"""The boolean collision checks agree with the sign of coal's exact distance where a capsule's segment
touches a box's face.

coal's GJK treats a capsule as a segment with a swept-sphere radius. When that segment touches a box
from outside to within GJK's tolerance (1e-6 m), Pinocchio's default collision requests (no contacts
asked) report the pair as free although the capsule's cap is sunk by its radius. The checkers ask
for contacts (:func:`optplan.collision.checker.exact_contact_requests`). Reference everywhere:
``coal.distance`` on the same placements (exact signed distances, independent of the collision
requests).
"""
from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

from optplan.collision.checker import CollisionChecker, exact_contact_requests
from optplan.model.example_robots import example_robot_data_dir
from optplan.planners.kernel.csource import KERNEL_EPS
from optplan.planners.validity import ValidityChecker
from optplan.scene import Obstacle, Scene

_ERD = example_robot_data_dir()
needs_panda = pytest.mark.skipif(_ERD is None or not (_ERD / "robots/panda_description/urdf/panda_collision.urdf").exists(),
                                 reason="needs example-robot-data (pip install optplan[robots])")


def _pair_distances(ck: ValidityChecker, mode: str, q: np.ndarray, object_pose: pin.SE3 | None = None) -> dict[int, float]:
    """coal's exact distance [m] of every pair ``mode`` checks at ``q``."""
    gm = ck.gmodel
    gd = pin.GeometryData(gm)
    pin.updateGeometryPlacements(ck.model, ck.model.createData(), gm, gd, q)
    if object_pose is not None:
        gd.oMg[ck.fixed_id] = object_pose
    active = ck._gd[mode].activeCollisionPairs
    out = {}
    for k, cp in enumerate(gm.collisionPairs):
        if not active[k]:
            continue
        T1, T2 = gd.oMg[cp.first], gd.oMg[cp.second]
        out[k] = coal.distance(gm.geometryObjects[cp.first].geometry, coal.Transform3s(T1.rotation, T1.translation),
                               gm.geometryObjects[cp.second].geometry, coal.Transform3s(T2.rotation, T2.translation),
                               coal.DistanceRequest(), coal.DistanceResult())
    return out


# --------------------------------------------------------------------------- a bare capsule and box
R_X = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])   # the capsule's axis (local z) along world x


@pytest.mark.parametrize("gap", [-1e-3, -1e-9, 0.0, 1e-12, 1e-9, 1e-7, 5e-7, 1e-6, 1e-5,
                                 0.015 - 1e-5, 0.015 + 1e-7, 0.015 + 1e-5, 0.015 + 1e-3])
def test_capsule_end_on_a_box_face(gap):
    """Capsule (radius 15 mm, segment 30 mm) along x, its segment ending ``gap`` [m] before the face
    x = −0.15 of a box (half sides 0.15, 0.06, 0.06), near the face's edge as on the Panda's finger.
    Pinocchio's collision check with the contact requests agrees with the exact distance's sign (the
    gaps 1e-12 … 1e-6 are where the default requests see the 15 mm penetration as free); gaps beyond
    the radius stay free."""
    r, hl = 0.015, 0.015
    gm = pin.GeometryModel()
    gm.addGeometryObject(pin.GeometryObject("capsule", 0, 0, pin.SE3(R_X, np.array([-0.15 - hl - gap, 0.055, 0.0])),
                                            coal.Capsule(r, 2 * hl)))
    gm.addGeometryObject(pin.GeometryObject("box", 0, 0, pin.SE3.Identity(), coal.Box(0.30, 0.12, 0.12)))
    gm.addCollisionPair(pin.CollisionPair(0, 1))
    gd = pin.GeometryData(gm)
    exact_contact_requests(gd)
    model = pin.Model()
    pin.updateGeometryPlacements(model, model.createData(), gm, gd, np.zeros(0))
    T1, T2 = gd.oMg[0], gd.oMg[1]
    d = coal.distance(gm.geometryObjects[0].geometry, coal.Transform3s(T1.rotation, T1.translation),
                      gm.geometryObjects[1].geometry, coal.Transform3s(T2.rotation, T2.translation),
                      coal.DistanceRequest(), coal.DistanceResult())
    assert d == pytest.approx(gap - r, abs=1e-8)
    assert pin.computeCollision(gm, gd, 0) == (d <= 0.0)
    assert pin.computeCollisions(gm, gd, True) == (d <= 0.0)


# --------------------------------------------------------------------------- the checkers on a robot
def _touching_scene(robot, q: np.ndarray, geometry: str, gap: float, tilt: float, spin: float, lateral: float) -> Scene:
    """A box obstacle whose face lies ``gap`` [m] beyond the far end of capsule ``geometry``'s segment at
    ``q`` (the capsule outside the box, its axis tilted by ``tilt`` [rad] from the face normal, the box
    turned by ``spin`` [rad] about that normal, the end ``lateral`` [m] off the face's centre)."""
    gm = robot.collision_model
    g = next(k for k, go in enumerate(gm.geometryObjects) if go.name == geometry)
    data = robot.model.createData()
    gd = pin.GeometryData(gm)
    pin.updateGeometryPlacements(robot.model, data, gm, gd, q)
    M, cap = gd.oMg[g], gm.geometryObjects[g].geometry
    end = M.act(np.array([0.0, 0.0, cap.halfLength]))
    # the face normal n: the capsule's axis turned by tilt about its local x; the box frame's z is n
    Rn = M.rotation @ pin.rpy.rpyToMatrix(tilt, 0.0, 0.0) @ pin.rpy.rpyToMatrix(0.0, 0.0, spin)
    n = Rn[:, 2]
    h = np.array([0.05, 0.04, 0.03])                 # half sides [m]
    centre = end + (gap + h[2]) * n - lateral * Rn[:, 0]
    box = Obstacle("plate", "box", pin.SE3(Rn, centre), size=tuple(2 * h))
    return Scene(name="touching", robot=None, obstacles=(box,))


GAPS = [0.0, 1e-12, 1e-9, 1e-7, 5e-7, 9e-7, 1e-5, -1e-4]   # touching band and a shallow overlap of the segment
FREE = [1e-7, 1e-6, 1e-5, 1e-3]                              # beyond the radius: near-touching, free


@pytest.fixture(scope="module")
def tcb_touching(tcb):
    q = 0.5 * (tcb.lower + tcb.upper)
    free = ValidityChecker(tcb, None)
    assert free.is_valid_free(q)
    return tcb, q


@pytest.mark.parametrize("geometry", ["a_link7_0", "b_link5_0"])
def test_checkers_agree_with_exact_distance_on_capsule_touching_box(tcb_touching, geometry):
    """The benchmark robot's capsule ``geometry`` with a box face at its segment's end (several tilts,
    turns and positions on the face): every boolean check — one configuration, the batch
    ``first_invalid``, the check without the batch API, and the exact checker's ``is_valid`` — says
    "in collision" exactly when some pair's exact distance is ≤ 0; near-touching free placements stay valid."""
    robot, q = tcb_touching
    r = next(go.geometry.radius for go in robot.collision_model.geometryObjects if go.name == geometry)
    rng = np.random.default_rng(7)
    n_hit = n_free = 0
    for gap in GAPS + [r + f for f in FREE]:
        for _ in range(3):
            tilt, spin, lateral = rng.uniform(-0.6, 0.6), rng.uniform(-np.pi, np.pi), rng.uniform(0.0, 0.025)
            scene = _touching_scene(robot, q, geometry, gap, tilt, spin, lateral)
            # coal's checks (what this test is about: contacts requested so EPA runs)
            cks = [ValidityChecker(robot, scene, kernel="coal"), ValidityChecker(robot, scene, batch=False, kernel="coal"),
                   ValidityChecker(robot, scene, broadphase=False, kernel="coal")]
            dmin = min(_pair_distances(cks[0], "free", q).values())
            hit = dmin <= 0.0
            if gap < r:
                assert hit, f"gap {gap}: the capsule's cap reaches into the box, exact distance {dmin}"
            n_hit += hit
            n_free += not hit
            for ck in cks:
                assert ck.is_valid(q) == (not hit), f"gap {gap}, tilt {tilt:.2f}: exact distance {dmin:.3e}"
                assert ck.first_invalid(np.array([q, q]), "free") == (0 if hit else -1)
            assert CollisionChecker(robot, scene).is_valid(q) == (not hit)
            # the native planning kernel (the default) is conservative: never free where coal says hit,
            # colliding where free only within its KERNEL_EPS band
            nat = ValidityChecker(robot, scene)
            if hit:
                assert not nat.is_valid(q)
            else:
                assert nat.is_valid(q) or dmin <= 2 * KERNEL_EPS, f"gap {gap}: native kernel refuses at {dmin:.3e} m"
    assert n_hit >= 3 * len(GAPS) and n_free >= len(FREE)   # both verdicts were tested


def test_default_requests_option(tcb):
    """``exact_contacts=False`` keeps Pinocchio's default requests (no contacts asked), for comparison."""
    scene = Scene.load("hard_bay")
    on, off = ValidityChecker(tcb, scene), ValidityChecker(tcb, scene, exact_contacts=False)
    assert all(req.enable_contact for gd in on._gd.values() for req in gd.collisionRequests)
    assert not any(req.enable_contact for gd in off._gd.values() for req in gd.collisionRequests)
    for pool in on._pool.values():
        assert all(req.enable_contact for req in pool.getGeometryData(0).collisionRequests)


# --------------------------------------------------------------------------- the dual Panda's grasps
@pytest.fixture(scope="module")
def panda():
    from optplan.model.dual_panda import load_dual_panda

    return load_dual_panda()


def _robot_side(ck: ValidityChecker, k: int) -> int:
    cp = ck.gmodel.collisionPairs[k]
    return cp.first if cp.second == ck.fixed_id else cp.second


@needs_panda
@pytest.mark.parametrize("scene_name", ["panda_bar", "panda_shelf"])
def test_panda_grasp_contacts_agree_with_exact_distances(panda, scene_name):
    """At the start and goal grasps of trials 0-9, the object standing still at the grasp (a regrasp):
    the fingers' capsules end on the box's face. ``grasp_contacts`` lists exactly the hand pairs whose
    exact distance is ≤ 0; each such pair alone is found by ``is_valid_object_fixed`` and by the batch
    ``first_invalid``; the whole configuration's verdict is the sign of the smallest exact distance."""
    from optplan.constraints.closed_chain import ClosedChainKinematics
    from optplan.trials import TrialGenerator

    scene = Scene.load(scene_name)
    ck = ValidityChecker(panda, scene)
    kin, gen = ClosedChainKinematics(panda, scene.object.grasps), TrialGenerator(panda, scene)
    excl = set(scene.object.exclude_links)
    objs = ck.gmodel.geometryObjects
    n_pen = 0
    for i in range(10):
        tr = gen.generate(i, 0)
        for q in (tr.q_start, tr.q_goal):
            M = kin.object_pose(q)
            d = _pair_distances(ck, "fixed", q, M)
            hands = {k for k in d if ck._pair_group[k] == "fixed" and panda.model.frames[objs[_robot_side(ck, k)].parentFrame].name in excl}
            pen = {k for k in hands if d[k] <= 0.0}
            n_pen += len(pen)
            assert set(ck.grasp_contacts(q, M)) == pen
            assert ck.is_valid_object_fixed(q, M) == (min(d.values()) > 0.0)
            for k in pen:
                with ck.exempt(tuple(j for j in d if j != k)):     # the pair alone
                    assert not ck.is_valid_object_fixed(q, M)
                    assert ck.first_invalid(np.array([q]), "fixed", M) == 0
            with ck.exempt(tuple(pen)):                           # the regrasp's exemption leaves the rest
                rest = [v for k, v in d.items() if k not in pen]
                assert ck.is_valid_object_fixed(q, M) == (min(rest) > 0.0)
    assert n_pen >= 40   # fingers on the box at most grasps
