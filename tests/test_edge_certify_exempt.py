"""Certified edges under a regrasp's grasp exemption (``ValidityChecker.exempt``): the dual Panda's
fingers straddle the box's face at its grasps, so a regrasp's certified edges must skip the same
finger-object pairs as the boolean checks, and only those. Reference: the Jacobian-bound edge check
on the same edges, and coal distances at dense samples (:class:`optplan.collision.CollisionChecker`
for the robot and the scene, ``coal.distance`` against the standing object)."""
from __future__ import annotations

import coal
import numpy as np
import pytest

from optplan.collision import CollisionChecker
from optplan.collision.checker import _tf
from optplan.constraints.closed_chain import ClosedChainKinematics
from optplan.model.example_robots import example_robot_data_dir
from optplan.planners.validity import ValidityChecker
from optplan.scene import Scene
from optplan.trials import TrialGenerator


def _panda_available() -> bool:
    d = example_robot_data_dir()
    return d is not None and (d / "robots/panda_description/urdf/panda_collision.urdf").exists()


pytestmark = pytest.mark.skipif(not _panda_available(), reason="needs example-robot-data (pip install optplan[robots])")

CLEAR = 1e-3   # the certifier's min_clearance [m]


@pytest.fixture(scope="module")
def grasp():
    """The dual Panda holding the box at a ``panda_bar`` trial's goal: both hands' fingers in the box."""
    from optplan.bench.generalize import _robot

    robot = _robot("dual_panda")
    scene = Scene.load("panda_bar")
    ck = ValidityChecker(robot, scene)
    q = TrialGenerator(robot, scene).generate(0, 0).q_goal
    M = ClosedChainKinematics(robot, scene.object.grasps).object_pose(q)
    contacts = ck.grasp_contacts(q, M)
    assert len(contacts) == 4          # two fingers per hand
    ck.certifier(CLEAR).prepare(("held", "fixed"))   # as TCBiRRT does before its time limit starts
    return robot, scene, ck, q, M, contacts


def _dense(a, b, step):
    n = max(1, int(np.ceil(float(np.abs(b - a).max()) / step)))
    return a + (np.arange(n + 1) / n)[:, None] * (b - a)


def _one_arm_edges(q, rng, n, sigma):
    """Straight edges leaving the grasp q with one arm (the first edge of a regrasp), the other still."""
    out = []
    for k in range(n):
        b = q.copy()
        idx = np.arange(7) if k % 2 == 0 else np.arange(7, 14)
        b[idx] += rng.normal(0.0, sigma, 7)
        out.append((q, b))
    return out


def _reference(robot, scene, ck, M, exempt):
    """Clearance [m] at q of every pair the regrasp checks (robot self, robot-obstacle, robot-object
    except the exempted geometries), by coal independently of the ValidityChecker's pair groups."""
    ex = CollisionChecker(robot, scene, held_object=False)
    skip = {ck.gmodel.geometryObjects[ck.gmodel.collisionPairs[k].first].name for k in exempt}
    og, tf_obj = scene.object.coal_geometry(), _tf(M)
    geoms = [(k, go) for k, go in enumerate(robot.collision_model.geometryObjects)
             if go.parentJoint != 0 and go.name not in skip]

    def clearance(q):
        d = ex.min_distance(q)[0]
        ex.update_placements(q)
        for k, go in geoms:
            res = coal.DistanceResult()
            d = min(d, coal.distance(go.geometry, _tf(ex.gdata.oMg[k]), og, tf_obj, coal.DistanceRequest(), res))
        return d
    return clearance


def test_certified_regrasp_edges_agree_with_the_jacobian_check_under_the_exemption(grasp):
    """Inside ``exempt(grasp_contacts)`` a certified edge leaving the grasp passes exactly where the
    Jacobian-bound check passes, and every certified edge keeps min_clearance / 2 from every pair that
    is not exempted at dense samples (coal). Outside the block (and with the cache on) the same edges
    are refused again: the fingers are in the box."""
    robot, scene, ck, q, M, contacts = grasp
    rng = np.random.default_rng(5)
    edges = _one_arm_edges(q, rng, 12, 0.1)
    clearance = _reference(robot, scene, ck, M, contacts)
    n_pass = 0
    with ck.exempt(contacts):
        for a, b in edges:
            jac = ck.edge_is_valid(a, b, 0.005, "fixed", object_pose=M, check_end=True)
            cert = ck.edge_is_certified(a, b, "fixed", object_pose=M, min_clearance=CLEAR, cache=True)
            assert cert == jac
            if cert:
                n_pass += 1
                Q = _dense(a, b, 2e-3)
                assert all(ck.is_valid_object_fixed(x, M) for x in Q)
                assert min(clearance(x) for x in Q[1::4]) >= CLEAR / 2 - 1e-9
    assert 3 <= n_pass < len(edges)      # some pass, some hit something else
    # the exemption is gone after the block: the ends (fingers in the box) are refused, cache or not
    for a, b in edges:
        assert not ck.edge_is_certified(a, b, "fixed", object_pose=M, min_clearance=CLEAR, cache=True)
        assert not ck.edge_is_certified(a, b, "fixed", object_pose=M, min_clearance=CLEAR)
    assert ck.exempted("fixed") == frozenset()


def test_pairs_not_exempted_are_still_certified(grasp):
    """Exempting one hand's fingers only: the left arm's edges are refused (the right hand's fingers,
    not exempted, are in the box), as by the boolean checks; and an edge along which a hand whose
    fingers ARE exempted meets something else (bar, table, other arm, the box with another link) is
    refused (a dense sample collides with a pair that is not exempted)."""
    robot, scene, ck, q, M, contacts = grasp
    left = tuple(k for k in contacts if "left_panda" in ck.gmodel.geometryObjects[ck.gmodel.collisionPairs[k].first].name)
    assert len(left) == 2
    rng = np.random.default_rng(5)
    edges = _one_arm_edges(q, rng, 12, 0.1)
    with ck.exempt(left):
        assert not ck.is_valid_object_fixed(q, M)
        for a, b in edges[::2]:       # the left arm moves
            assert not ck.edge_is_certified(a, b, "fixed", object_pose=M, min_clearance=CLEAR, cache=True)
            assert not ck.edge_is_valid(a, b, 0.005, "fixed", object_pose=M)
    # longer edges: the ones whose dense samples collide with a pair that is not exempted
    clearance = _reference(robot, scene, ck, M, contacts)
    n_hit = 0
    with ck.exempt(contacts):
        for a, b in _one_arm_edges(q, rng, 16, 0.4):
            if not ck.is_valid_object_fixed(b, M):
                continue
            Q = _dense(a, b, 2e-3)
            if any(not ck.is_valid_object_fixed(x, M) for x in Q):
                n_hit += 1
                assert min(clearance(x) for x in Q[1:]) < 0.0       # the reference agrees: a real collision
                assert not ck.edge_is_certified(a, b, "fixed", object_pose=M, min_clearance=CLEAR, cache=True)
    assert n_hit >= 2


def test_certifier_state_follows_nested_exemptions(grasp):
    """Nested blocks: the certifier's pair groups are those of the current exemption (the union of the
    open blocks), restored block by block; the boolean and certified verdicts at the grasp agree."""
    robot, scene, ck, q, M, contacts = grasp
    cert = ck.certifier(CLEAR)

    def n_pairs():
        return sum(len(g.pairs) for g in cert.groups("fixed"))
    n0 = n_pairs()
    with ck.exempt(contacts[:2]):
        assert n_pairs() == n0 - 2 and not ck.path_is_certified(q[None, :], "fixed", M, CLEAR)
        with ck.exempt(contacts[2:]):
            assert ck.exempted("fixed") == frozenset(contacts)
            assert n_pairs() == n0 - 4
            assert ck.path_is_certified(q[None, :], "fixed", M, CLEAR) and ck.is_valid_object_fixed(q, M)
        assert n_pairs() == n0 - 2 and not ck.path_is_certified(q[None, :], "fixed", M, CLEAR)
    assert n_pairs() == n0 and not ck.is_valid_object_fixed(q, M)
