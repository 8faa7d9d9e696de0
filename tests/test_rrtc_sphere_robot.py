"""The native search's check on a robot made of many spheres per link (as VAMP's Panda: 59 spheres): two links'
groups that stay close test only the members near the other group's sphere (by 64-bit masks of the members, or run
by run for groups of more than 64), and a moving geometry is placed when a test first needs it. Independent
references: the kernel's plain pair loop and coal's exact verdicts."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from native_rrtc_case import native_or_skip

from optplan.planners import RRTConnect, RRTConnectOptions
from optplan.planners.rrtconnect import edge_is_valid
from optplan.planners.validity import ValidityChecker
from optplan.scene import Obstacle, Scene

N_LINKS = 6


def _sphere_chain_urdf(extra_last: int = 0) -> str:
    """Six revolute joints (axes z, y, y, z, y, z), links of 0.3 m along z, each with five spheres along it and
    two off its axis (a fat, lumpy link like a spherized arm's); the last link ``extra_last`` more small spheres
    around its axis."""
    axes = ["0 0 1", "0 1 0", "0 1 0", "0 0 1", "0 1 0", "0 0 1"]
    parts = ['<robot name="spheres">', '<link name="base"><collision><origin xyz="0 0 0.05"/><geometry>'
             '<sphere radius="0.08"/></geometry></collision></link>']
    parent = "base"
    for i in range(N_LINKS):
        link = f"l{i}"
        cols = "".join(f'<collision><origin xyz="{dx} {dy} {z:.3f}"/><geometry><sphere radius="{r}"/></geometry>'
                       f"</collision>"
                       for (dx, dy, z, r) in [(0, 0, 0.03 + 0.06 * k, 0.045 - 0.003 * i) for k in range(5)]
                       + [(0.05, 0, 0.15, 0.03), (0, -0.05, 0.2, 0.03)]
                       + ([(round(0.04 * np.cos(0.7 * k), 4), round(0.04 * np.sin(0.7 * k), 4),
                            round(0.02 + 0.26 * k / max(extra_last, 1), 4), 0.02) for k in range(extra_last)]
                          if i == N_LINKS - 1 else []))
        parts.append(f'<link name="{link}">{cols}</link>')
        z0 = 0.1 if i == 0 else 0.3
        parts.append(f'<joint name="j{i}" type="revolute"><parent link="{parent}"/><child link="{link}"/>'
                     f'<origin xyz="0 0 {z0}"/><axis xyz="{axes[i]}"/>'
                     f'<limit lower="-2.8" upper="2.8" effort="1" velocity="1"/></joint>')
        parent = link
    parts.append('<link name="tip"/><joint name="jtip" type="fixed"><parent link="l5"/><child link="tip"/>'
                 '<origin xyz="0 0 0.3"/></joint></robot>')
    return "".join(parts)


def _load(tmp_path_factory, extra_last: int = 0, drop_every: int = 0):
    from optplan.model.robot import RobotModel

    path = tmp_path_factory.mktemp("spheres") / "spheres.urdf"
    path.write_text(_sphere_chain_urdf(extra_last))
    robot = RobotModel.from_urdf(path, arms={"arm": {"ee": "tip", "joints": [f"j{i}" for i in range(N_LINKS)]}},
                                 name="sphere_chain")
    objs = robot.collision_model.geometryObjects

    def link_of(g: int) -> int:   # -1 the base, else the link's number
        name = robot.model.frames[objs[g].parentFrame].name
        return -1 if name == "base" else int(name[1:])

    # every pair of geometries on links at least two apart (neighbours share a joint and always touch)
    pairs = [(a, b) for a in range(len(objs)) for b in range(a + 1, len(objs)) if abs(link_of(a) - link_of(b)) >= 2]
    if drop_every:   # a partial pair list (as an SRDF's): every drop_every-th pair left out
        pairs = [p for k, p in enumerate(pairs) if k % drop_every != 1]
    robot.set_collision_pairs(pairs)
    return robot


@pytest.fixture(scope="module")
def sphere_robot(tmp_path_factory):
    return _load(tmp_path_factory)


def _scene() -> Scene:
    R = pin.rpy.rpyToMatrix(0.3, -0.2, 0.7)
    return Scene(name="spheres_world", robot=None, obstacles=(
        Obstacle("slab", "box", pin.SE3(R, np.array([0.45, 0.1, 0.6])), size=(0.1, 0.5, 0.4)),
        Obstacle("ball", "sphere", pin.SE3(np.eye(3), np.array([-0.3, 0.35, 0.9])), radius=0.15),
        Obstacle("bar", "capsule", pin.SE3(pin.rpy.rpyToMatrix(1.2, 0.0, 0.4), np.array([0.0, -0.45, 0.7])),
                 radius=0.05, length=0.6),
    ))


def _configs(robot, rng, n):
    """Uniform draws and draws folded toward self-contact (the wrist bent back over the arm)."""
    U = rng.uniform(robot.lower, robot.upper, (n, robot.nq))
    F = rng.uniform(robot.lower, robot.upper, (n, robot.nq))
    F[:, 2] = rng.choice([-1, 1], n) * rng.uniform(2.2, 2.8, n)
    F[:, 4] = rng.choice([-1, 1], n) * rng.uniform(2.0, 2.8, n)
    return np.vstack([U, F])


@pytest.mark.parametrize("masks", [1, 0])
@pytest.mark.parametrize("searched", [list(range(N_LINKS)), [2, 3, 4, 5], [1, 2, 4]])
def test_search_check_gives_the_kernels_and_coals_verdicts(sphere_robot, searched, masks):
    """The search's own check, set up as a query sets it up (the joints not searched still, placed once), on
    4,000 configurations: the kernel's verdict on every one (its plain loop over every pair) and never free where
    coal collides; self-contacts and obstacle contacts both occur. With and without the members' masks of two
    joints' groups (``rrtc_use_masks``)."""
    import ctypes

    from optplan.planners.kernel.rrtc import load_rrtc_library

    ck = ValidityChecker(sphere_robot, _scene())
    native_or_skip(ck)
    flag = ctypes.c_int.in_dll(load_rrtc_library(), "rrtc_use_masks")
    flag.value = masks
    try:
        _check_verdicts(sphere_robot, searched)
    finally:
        flag.value = 1


def test_groups_of_more_than_64_members_test_run_by_run(tmp_path_factory):
    """A link of 71 spheres: its blocks with other links' groups go run by run (no 64-bit masks), the others by
    masks; the verdicts are the kernel's and never free where coal collides."""
    from optplan.planners.kernel.rrtc import _broad_phase

    robot = _load(tmp_path_factory, extra_last=64)
    ck = ValidityChecker(robot, _scene())
    native_or_skip(ck)
    bp = _broad_phase(ck._native.kernel, ck._native.fixed_id)
    kind, _refs, _c, _r, _bs, bga, bgb, *_rest = bp.arrays
    bmask, gmstart = bp.arrays[11], bp.arrays[12]
    size = np.diff(gmstart)
    joint_joint = (kind[bga] == 1) & (kind[bgb] == 1) & (bga != bgb)
    big = (size[bga] > 64) | (size[bgb] > 64)
    assert size.max() == 71 and np.any(joint_joint & big) and np.any(joint_joint & ~big)
    assert np.array_equal(bmask.astype(bool), joint_joint & ~big)
    _check_verdicts(robot, list(range(N_LINKS)))


def test_partial_pair_lists_find_each_pair_by_its_rank(tmp_path_factory):
    """Pairs left out (as an SRDF disables some): a run's pairs are a subset of the other group's members, found by
    their rank in the run's mask; the verdicts are the kernel's and never free where coal collides."""
    from optplan.planners.kernel.rrtc import _broad_phase

    robot = _load(tmp_path_factory, drop_every=3)
    ck = ValidityChecker(robot, _scene())
    native_or_skip(ck)
    bp = _broad_phase(ck._native.kernel, ck._native.fixed_id)
    runmask = bp.arrays[15]
    masks = [int(v) for v in runmask if v]
    assert masks and any(m & (m + 1) for m in masks)   # some run's members are not 0 … n-1: gaps in the mask
    _check_verdicts(robot, list(range(N_LINKS)))
    _check_verdicts(robot, [2, 3, 4, 5])


def _check_verdicts(robot, searched) -> None:
    from optplan.planners.kernel.rrtc import broad_phase_valid, search_check_valid

    sc = _scene()
    ck = ValidityChecker(robot, sc)
    native_or_skip(ck)
    rng = np.random.default_rng(11)
    X = _configs(robot, rng, 2000)
    base = next(q for q in rng.uniform(robot.lower, robot.upper, (200, robot.nq)) if ck.is_valid_free(q))
    full = np.tile(base, (len(X), 1))
    full[:, searched] = X[:, searched]
    f = ck.validity("free")
    got = search_check_valid(f, searched, base, full[:, searched])
    want = ck.valid_batch(full, "free")
    assert np.array_equal(got, want)
    assert np.array_equal(broad_phase_valid(f, full), want)
    exact = ValidityChecker(robot, sc, kernel="coal").valid_batch(full, "free")
    assert not np.any(got & ~exact)
    assert 0.1 < got.mean() < 0.9
    # both kinds of contact among the rejected: against the obstacles, and of the robot with itself
    empty = ValidityChecker(robot, Scene(name="none", robot=None, obstacles=()))
    self_free = empty.valid_batch(full, "free")
    assert np.sum(~self_free) > 50 and np.sum(self_free & ~got) > 50


def test_native_search_paths_on_the_sphere_robot_are_free_and_seeded(sphere_robot):
    """RRT-Connect through the same checks: every edge free by coal at 0.004 rad, the same path for a seed."""
    robot = sphere_robot
    sc = _scene()
    ck = ValidityChecker(robot, sc)
    native_or_skip(ck)
    exact = ValidityChecker(robot, sc, kernel="coal").validity("free")
    rng = np.random.default_rng(3)
    free = [q for q in rng.uniform(robot.lower, robot.upper, (400, robot.nq)) if ck.is_valid_free(q)]
    pl = RRTConnect(robot, sc, RRTConnectOptions(range=1.0, resolution=0.03, native_search=True,
                                                 shortcut_iterations=0), checker=ck)
    solved = 0
    for k in range(6):
        a, b = free[2 * k], free[2 * k + 1]
        r1 = pl.plan(a, b, time_limit=30, seed=k, clock="cpu")
        r2 = pl.plan(a, b, time_limit=30, seed=k, clock="cpu")
        assert r1.stats["search"] == "native"
        if r1.status.value != "exact":
            continue
        solved += 1
        assert np.array_equal(r1.path, r2.path)
        assert all(edge_is_valid(p, q, exact, 0.004) for p, q in zip(r1.path[:-1], r1.path[1:]))
    assert solved >= 5
