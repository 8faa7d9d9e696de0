"""MotionBenchMaker problems (VAMP's ``problems.tar.bz2``) as optplan scenes: the mapping of MoveIt's primitives,
the requests' joints, the archive and directory readers and their errors. Needs PyYAML (skipped without it)."""
from __future__ import annotations

import io
import tarfile

import coal
import numpy as np
import pinocchio as pin
import pytest

yaml = pytest.importorskip("yaml")

from optplan.bench.mbm import MBM_SCENARIOS, load_mbm, mbm_scene  # noqa: E402

JOINTS = [f"panda_joint{k}" for k in range(1, 8)]


def _scene_doc() -> dict:
    q = pin.Quaternion(pin.rpy.rpyToMatrix(0.2, -0.4, 1.1))   # stored x, y, z, w as MoveIt does
    return {"world": {"collision_objects": [
        {"id": "shelf", "primitives": [{"type": "box", "dimensions": [0.6, 0.3, 0.02]}],
         "primitive_poses": [{"position": [0.5, 0.1, 0.4], "orientation": [q.x, q.y, q.z, q.w]}]},
        {"id": "ball", "primitives": [{"type": "sphere", "dimensions": [0.07]}],
         "primitive_poses": [{"position": [0.3, -0.2, 0.6], "orientation": [0, 0, 0, 1]}]},
        {"id": "can", "pose": {"position": [0.1, 0.0, 0.2], "orientation": [0, 0, 0.3826834, 0.9238795]},
         "primitives": [{"type": "cylinder", "dimensions": [0.2, 0.04]}],     # height, radius
         "primitive_poses": [{"position": [0.4, 0.0, 0.1], "orientation": [0.7071068, 0, 0, 0.7071068]}]},
    ]}}


def _request_doc(start, goal) -> dict:
    order = [6, 0, 3, 1, 5, 2, 4]   # the names in another order than the planners'
    return {"start_state": {"joint_state": {"name": [JOINTS[i] for i in order] + ["panda_finger_joint1"],
                                            "position": [float(start[i]) for i in order] + [0.04]}},
            "goal_constraints": [{"joint_constraints": [{"joint_name": JOINTS[i], "position": float(goal[i])}
                                                        for i in order]}]}


def _inside(obstacle, points) -> bool:
    """Every point inside the obstacle's shape (coal's distance from a 1 µm sphere at the point)."""
    geom = obstacle.coal_geometry()
    tiny = coal.Sphere(1e-6)
    M = obstacle.placement
    for p in points:
        req, res = coal.DistanceRequest(), coal.DistanceResult()
        d = coal.distance(geom, coal.Transform3s(M.rotation, M.translation), tiny,
                          coal.Transform3s(np.eye(3), np.asarray(p)), req, res)
        if d > 0:
            return False
    return True


def _cylinder_points(doc_obj, rng, n=300):
    """Points filling the cylinder of ``doc_obj`` (its composed pose), for the containment checks."""
    def pose(d):
        x, y, z, w = d["orientation"]
        return pin.SE3(pin.Quaternion(w, x, y, z).normalized().toRotationMatrix(), np.asarray(d["position"], float))

    M = pose(doc_obj["pose"]) * pose(doc_obj["primitive_poses"][0])
    h, r = doc_obj["primitives"][0]["dimensions"]
    ang, rad = rng.uniform(0, 2 * np.pi, n), r * np.sqrt(rng.uniform(0, 1, n)) * (1 - 1e-9)
    local = np.c_[rad * np.cos(ang), rad * np.sin(ang), rng.uniform(-h / 2, h / 2, n) * (1 - 1e-9)]
    local[:8] = [[sx * r * 0.999999, 0, sz * h / 2 * 0.999999] for sx in (-1, 1) for sz in (-1, 1)] * 2   # rims
    return [M.act(p) for p in local], M


def test_scene_mapping_keeps_poses_and_covers_the_cylinders():
    doc = _scene_doc()
    sc = mbm_scene(doc, "cage")
    by = {o.name: o for o in sc.obstacles}
    assert set(by) == {"shelf", "ball", "can"}
    shelf = by["shelf"]
    assert shelf.shape == "box" and shelf.size == (0.6, 0.3, 0.02)
    assert np.allclose(shelf.placement.rotation, pin.rpy.rpyToMatrix(0.2, -0.4, 1.1), atol=1e-12)
    assert by["ball"].shape == "sphere" and by["ball"].radius == 0.07
    can = by["can"]
    assert can.shape == "capsule" and can.radius == 0.04 and can.length == 0.2
    rng = np.random.default_rng(0)
    pts, M = _cylinder_points(doc["world"]["collision_objects"][2], rng)
    assert np.allclose(can.placement.homogeneous, M.homogeneous)   # the object's pose composed with its primitive's
    assert _inside(can, pts)
    # the box scenario: the box around the cylinder (VAMP's mapping there), which also holds every point
    boxed = {o.name: o for o in mbm_scene(doc, "box").obstacles}["can"]
    assert boxed.shape == "box" and boxed.size == (0.08, 0.08, 0.2)
    assert _inside(boxed, pts)
    # and a capsule only as long as the cylinder would not: the check can fail
    import dataclasses

    short = dataclasses.replace(can, length=0.1)
    assert not _inside(short, pts)


def test_scene_mapping_errors():
    doc = _scene_doc()
    doc["world"]["collision_objects"][1]["primitives"][0]["type"] = "cone"
    with pytest.raises(ValueError, match="'ball' is a 'cone'"):
        mbm_scene(doc, "cage")
    doc = _scene_doc()
    doc["world"]["collision_objects"][0]["primitives"] *= 2
    with pytest.raises(ValueError, match="2 primitives"):
        mbm_scene(doc, "cage")


def _write_problems(root, n_per=3):
    rng = np.random.default_rng(1)
    want = {}
    for s in ("cage", "box"):
        d = root / "problems" / f"{s}_panda"
        d.mkdir(parents=True)
        for i in range(1, n_per + 1):
            start, goal = rng.uniform(-2, 2, 7), rng.uniform(-2, 2, 7)
            (d / f"scene{i:04d}.yaml").write_text(yaml.safe_dump(_scene_doc()))
            (d / f"request{i:04d}.yaml").write_text(yaml.safe_dump(_request_doc(start, goal)))
            want[(s, i)] = (start, goal)
    return want


def test_load_from_a_directory_and_an_archive(tmp_path):
    want = _write_problems(tmp_path)
    probs = load_mbm(tmp_path, ["box", "cage"], 2)
    assert [p.key for p in probs] == ["box_0001", "box_0002", "cage_0001", "cage_0002"]
    for p in probs:
        start, goal = want[(p.scenario, p.index)]
        assert np.array_equal(p.start, start) and np.array_equal(p.goal, goal)
    assert {o.shape for o in probs[0].scene.obstacles} == {"box", "sphere"}       # box scenario: no capsule
    assert "capsule" in {o.shape for o in probs[2].scene.obstacles}
    arc = tmp_path / "problems.tar.bz2"
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:bz2") as tar:
        tar.add(tmp_path / "problems", arcname="problems")
    arc.write_bytes(buf.getvalue())
    again = load_mbm(arc, ["cage"])
    assert [p.key for p in again] == ["cage_0001", "cage_0002", "cage_0003"]
    assert np.array_equal(again[1].goal, want[("cage", 2)][1])


def test_load_errors(tmp_path):
    _write_problems(tmp_path, 1)
    with pytest.raises(ValueError, match="unknown scenario 'kitchen'"):
        load_mbm(tmp_path, ["kitchen"])
    with pytest.raises(ValueError, match="per_scenario must be a positive int"):
        load_mbm(tmp_path, ["cage"], 0)
    with pytest.raises(ValueError, match="no problems of 'table_pick'"):
        load_mbm(tmp_path, ["table_pick"])
    with pytest.raises(FileNotFoundError, match="neither"):
        load_mbm(tmp_path / "missing.tar.bz2")
    assert len(MBM_SCENARIOS) == 7
