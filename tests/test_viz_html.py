"""The offline HTML view (optplan.viz.html): structure, bad input, and a real headless Chromium
that loads the page from disk, must log no console error, must show the robot (pixels of the arms'
colours, not a blank canvas) and must move a free-floating robot's base with the trajectory.

The browser tests need the ``viz`` extra, selenium, and Debian's ``chromium`` + ``chromium-driver``;
they skip cleanly without them. Set ``OPTPLAN_SCREENSHOT_DIR`` to keep the screenshots.
"""
from __future__ import annotations

import math
import os
import re
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("meshcat")

from optplan.model.robot import RobotModel  # noqa: E402
from optplan.scene import Scene  # noqa: E402
from optplan.viz.html import (  # noqa: E402
    ARM_COLORS,
    ViewOptions,
    load_trajectory,
    save_metadata,
    trajectory_html,
    view_file,
    write_trajectory_html,
)


@pytest.fixture(scope="module")
def dual():
    return RobotModel.from_name("tcbirrt_dual_arm")


@pytest.fixture(scope="module")
def scene1():
    return Scene.load("ssps_scene1")


def _scene_motion(scene, robot, n=40):
    """Joint-space line between the scene's nominal start and goal configurations (deg in the TOML)."""
    ex = scene.extra
    f = math.pi / 180 if ex.get("q_unit", "rad") == "deg" else 1.0
    q0, q1 = np.asarray(ex["q_start"], float) * f, np.asarray(ex["q_goal"], float) * f
    s = np.linspace(0, 1, n)[:, None]
    return np.linspace(0.0, 30.0, n), (1 - s) * q0 + s * q1


def _floating_motion(robot, n=30):
    """A free-floating base translating 1 m along x and turning 90 deg about z while the joints move."""
    import pinocchio as pin

    t = np.linspace(0.0, 10.0, n)
    q = np.zeros((n, robot.nq))
    for k, s in enumerate(np.linspace(0, 1, n)):
        M = pin.SE3(pin.rpy.rpyToMatrix(0, 0, s * math.pi / 2), np.array([s, 0.0, 0.0]))
        q[k, :7] = pin.SE3ToXYZQUAT(M)
        q[k, 7:] = np.clip(0.5 * s * np.ones(robot.nj), robot.lower, robot.upper)
    return t, q


# --------------------------------------------------------------------------- page structure
def test_page_is_self_contained(dual, scene1):
    t, q = _scene_motion(scene1, dual, 10)
    page = trajectory_html(dual, scene1, t, q)
    assert page.startswith("<!DOCTYPE html>")
    # no external resources: no src/href attributes, no URL other than XML namespaces
    assert not re.search(r"<script[^>]+src=", page)
    assert not re.search(r"<link[^>]+href=", page)
    urls = set(re.findall(r"https?://[^\s\"'<>)]+", page))
    assert all("w3.org" in u for u in urls), urls
    assert "MeshCat.Viewer" in page and "optplan-slider" in page and "optplan-play" in page


def test_bad_input(dual, scene1):
    t, q = _scene_motion(scene1, dual, 5)
    with pytest.raises(ValueError, match="q: expected an"):
        trajectory_html(dual, scene1, t, q[:, :3])
    with pytest.raises(ValueError, match="t: expected 5 times"):
        trajectory_html(dual, scene1, t[:3], q)
    with pytest.raises(ValueError, match="non-decreasing"):
        trajectory_html(dual, scene1, t[::-1], q)
    with pytest.raises(ValueError, match="ViewOptions.fps"):
        ViewOptions(fps=0)


def test_npz_roundtrip_and_view_file(tmp_path, dual, scene1):
    t, q = _scene_motion(scene1, dual, 8)
    p = tmp_path / "traj.npz"
    np.savez(p, t=t, q=q, constrained=np.ones(len(t), bool))
    with pytest.raises(ValueError, match="does not name its robot or scene"):
        view_file(p)
    save_metadata(p, robot=dual.name, scene=scene1.name)
    tr = load_trajectory(p)
    assert tr["robot"] == dual.name and tr["scene"] == scene1.name and tr["q"].shape == q.shape
    out = view_file(p)
    assert out == tmp_path / "traj.html" and out.stat().st_size > 100_000
    bad = tmp_path / "bad.npz"
    np.savez(bad, t=t)
    with pytest.raises(ValueError, match="expected arrays 't' and 'q'"):
        load_trajectory(bad)
    with pytest.raises(ValueError, match="q has 14 columns but robot .dshdasr. has nq = 17"):
        view_file(p, robot="dshdasr")
    # 14 joints of the free-floating eba_ffsr: the base motion is re-integrated (momentum conservation)
    assert view_file(p, robot="eba_ffsr", out=tmp_path / "floating.html").stat().st_size > 100_000


# --------------------------------------------------------------------------- real browser
def _browser():
    webdriver = pytest.importorskip("selenium.webdriver")
    chrome = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    if chrome is None or driver is None:
        pytest.skip("Debian's chromium and chromium-driver are not installed")
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = chrome
    for a in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
              "--disable-background-networking", "--disable-component-update", "--disable-sync",
              "--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--window-size=960,640",
              f"--user-data-dir={tempfile.mkdtemp(prefix='optplan-chromium-')}"):
        opts.add_argument(a)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    try:
        return webdriver.Chrome(service=Service(driver), options=opts)
    except Exception as exc:   # pragma: no cover - depends on the machine
        pytest.skip(f"headless Chromium could not start: {exc}")


@pytest.fixture(scope="module")
def browser():
    d = _browser()
    yield d
    d.quit()


def _load(browser, path: Path):
    browser.get_log("browser")   # drop earlier entries
    browser.get(path.resolve().as_uri())
    for _ in range(100):
        if browser.execute_script("return typeof viewer !== 'undefined' && viewer.animator !== undefined"):
            break
        time.sleep(0.1)
    time.sleep(0.5)   # a few animation frames


def _errors(browser) -> list:
    return [e for e in browser.get_log("browser") if e.get("level") == "SEVERE"]


def _screenshot(browser, name: str) -> np.ndarray:
    import io

    from PIL import Image

    png = browser.get_screenshot_as_png()
    keep = os.environ.get("OPTPLAN_SCREENSHOT_DIR")
    if keep:
        Path(keep).mkdir(parents=True, exist_ok=True)
        (Path(keep) / name).write_bytes(png)
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), float)


def _color_pixels(img: np.ndarray, rgba, tol: float = 0.25) -> int:
    """Pixels whose chromaticity (colour with brightness divided out) is that of ``rgba`` (shading
    changes brightness, not chromaticity)."""
    c = np.asarray(rgba[:3], float)
    c = c / c.sum()
    s = img.sum(axis=2, keepdims=True)
    chrom = img / np.maximum(s, 1.0)
    mask = (s[..., 0] > 60) & (np.linalg.norm(chrom - c, axis=2) < tol * np.linalg.norm(c))
    return int(mask.sum())


def test_browser_shows_robot_scene1(tmp_path, browser, dual, scene1):
    t, q = _scene_motion(scene1, dual)
    page = write_trajectory_html(tmp_path / "scene1.html", dual, scene1, t, q,
                                 options=ViewOptions(title="ssps_scene1, nominal start to goal", max_frames=80))
    _load(browser, page)
    assert _errors(browser) == []
    for _ in range(20):   # WebGL in software: the first frames may take a moment
        img = _screenshot(browser, "viewer_ssps_scene1.png")
        a, b = _color_pixels(img, ARM_COLORS[0]), _color_pixels(img, ARM_COLORS[1])
        if a > 150 and b > 300:
            break
        time.sleep(0.25)
    assert img.std() > 10.0   # not a blank canvas
    # both arms are drawn (arm A sits behind a translucent beam of the truss from the default
    # viewpoint, which framing the whole scene keeps: ~200 of its pixels keep their colour)
    assert a > 150 and b > 300, (a, b)
    # play/pause and the slider drive the animation
    assert browser.execute_script("return viewer.animator.actions.length") > 0
    click = "document.getElementById('optplan-play').click(); return viewer.animator.playing"
    assert browser.execute_script(click) is True   # (a JS click: WebDriver's waits for the page to idle)
    time.sleep(0.5)
    t_play = browser.execute_script("return viewer.animator.actions[0].time")
    assert t_play > 0.0
    assert browser.execute_script(click) is False
    # the slider seeks: half way along the slider is half the clip
    frac = browser.execute_script("var s = document.getElementById('optplan-slider'); s.value = 500;"
                                  "s.dispatchEvent(new Event('input'));"
                                  "return viewer.animator.actions[0].time / viewer.animator.duration")
    assert abs(frac - 0.5) < 1e-6
    assert _errors(browser) == []


def test_browser_floating_base_moves(tmp_path, browser):
    robot = RobotModel.from_name("eba_ffsr")
    t, q = _floating_motion(robot)
    page = write_trajectory_html(tmp_path / "floating.html", robot, None, t, q, options=ViewOptions(max_frames=60))
    _load(browser, page)
    assert _errors(browser) == []
    base_geom = next(g.name for g in robot.collision_model.geometryObjects if g.parentJoint == 1)
    js = ("var o = viewer.scene_tree.find(['meshcat','robot','visuals',arguments[0]]).object;"
          "viewer.animator.seek(arguments[1]); viewer.animator.mixer.update(0);"
          "return [o.position.x, o.position.y, o.position.z];")
    dur = browser.execute_script("return viewer.animator.duration")
    p0 = np.array(browser.execute_script(js, base_geom, 0.0))
    p1 = np.array(browser.execute_script(js, base_geom, dur))
    import pinocchio as pin

    # the base geometry's world position follows q[:3] (Pinocchio forward kinematics at both ends)
    data = robot.model.createData()
    gd = pin.GeometryData(robot.collision_model)
    gid = robot.collision_model.getGeometryId(base_geom)
    ref = []
    for qk in (q[0], q[-1]):
        pin.updateGeometryPlacements(robot.model, data, robot.collision_model, gd, qk)
        ref.append(gd.oMg[gid].translation.copy())
    assert np.allclose(p0, ref[0], atol=1e-3) and np.allclose(p1, ref[1], atol=1e-3), (p0, p1, ref)
    assert np.linalg.norm(p1 - p0) > 0.5
    img = _screenshot(browser, "viewer_eba_ffsr_floating.png")
    assert img.std() > 10.0


# --------------------------------------------------------------------------- what the page shows
def _commands(page: str) -> list[dict]:
    """The MeshCat commands a page replays, decoded."""
    import base64
    import json

    import umsgpack

    m = re.search(r"var optplanCommands = \[\n(.*?)\n\];", page, re.S)
    assert m is not None
    return [umsgpack.unpackb(base64.b64decode(b)) for b in json.loads("[" + m.group(1) + "]")]


def _stl_normals(data) -> np.ndarray:
    import struct

    raw = data.data if hasattr(data, "data") else data
    n = struct.unpack("<I", raw[80:84])[0]
    rec = np.frombuffer(raw, dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]), count=n, offset=84)
    return rec["n"]


def _ur5(tmp_path):
    from optplan.model.example_robots import example_robot_data_dir

    d = example_robot_data_dir()
    urdf = None if d is None else d / "robots" / "ur_description" / "urdf" / "ur5_robot.urdf"
    if urdf is None or not urdf.exists():
        pytest.skip("example-robot-data (UR5 meshes) not installed")
    text = urdf.read_text().replace("package://example-robot-data/robots/", f"{d / 'robots'}/")
    p = tmp_path / "ur5.urdf"
    p.write_text(text)
    return RobotModel.from_urdf(p, {"A": "tool0"})


def test_mesh_robot_has_its_arm_colour_and_lit_normals(tmp_path):
    """UR5's collision STLs carry zero facet normals (three.js then renders them black whatever
    the material): the page gets copies with normals, and every arm link the arm's colour."""
    from optplan.viz.html import _color_int, arm_color

    robot = _ur5(tmp_path)
    page = trajectory_html(robot, None, np.array([0.0, 1.0]), np.zeros((2, robot.nq)))
    meshes = [c for c in _commands(page) if c["type"] == "set_object" and "/robot/collisions/" in c["path"]
              and c["object"]["geometries"][0].get("format") == "stl"]
    assert len(meshes) >= 6
    orange = _color_int(arm_color(robot, "A"))
    assert sum(c["object"]["materials"][0]["color"] == orange for c in meshes) >= 6   # every link past the base
    for c in meshes:
        n = _stl_normals(c["object"]["geometries"][0]["data"])
        assert np.all(np.abs(np.linalg.norm(n, axis=1) - 1.0) < 1e-4), c["path"]


def test_stl_with_normals_keeps_good_files_and_fixes_zero_normals(tmp_path):
    """The facet normal computed from the vertices is the unit normal of the triangle (right hand
    rule); a file that has normals is returned unchanged."""
    import struct

    from optplan.viz.meshes import stl_with_normals

    rec = np.zeros(2, dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    rec["v"][0] = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]    # normal +z
    rec["v"][1] = [[0, 0, 0], [0, 0, 1], [0, 1, 0]]    # normal -x
    p = tmp_path / "zero.stl"
    p.write_bytes(b"x" * 80 + struct.pack("<I", 2) + rec.tobytes())
    q = stl_with_normals(p)
    assert q != p
    assert np.allclose(_stl_normals(q.read_bytes()), [[0, 0, 1], [-1, 0, 0]])
    assert stl_with_normals(q) == q


def test_camera_sees_both_arms_of_the_floating_robot():
    """Every joint and geometry of both arms, at every shown configuration of the EBA free-end
    motion (joints from the paper's start to its goal, the base from momentum conservation), is
    inside the default camera's vertical field of view. The camera used to frame the hand paths
    only, and cut arm B off (42° off the axis for a 37.5° half-angle)."""
    from optplan.papers import eba
    from optplan.viz.html import CAMERA_FOV_DEG, _default_camera, _shown_points, floating_configurations

    robot = RobotModel.from_name("eba_ffsr")
    sc = eba.scenario("free_end", robot)
    t = np.linspace(0.0, 10.0, 40)
    s = np.linspace(0.0, 1.0, 40)[:, None]
    q = floating_configurations(robot, t, (1 - s) * sc.theta0 + s * sc.thetaf, None)
    pts = _shown_points(robot, None, q, np.zeros((0, 3)), None)
    assert len(pts) >= 40 * robot.model.njoints   # both arms' joints, not only the hands
    target, cam = _default_camera(pts)
    axis = (target - cam) / np.linalg.norm(target - cam)
    ang = np.degrees(np.arccos(np.clip((pts - cam) @ axis / np.linalg.norm(pts - cam, axis=1), -1, 1)))
    assert ang.max() < CAMERA_FOV_DEG / 2, ang.max()


def test_dshdasr_view_shows_the_target():
    """The DSHDASR view has the target (held by Arm-a at T_et^a, legend 'target'): its pose in
    the view is Arm-a's hand pose times T_et^a, the pose the task prescribes for the target."""
    import pinocchio as pin

    from optplan.papers.dshdasr.evaluate import view_scene
    from optplan.papers.dshdasr.task import paper_task
    from optplan.viz.html import _object_poses

    robot = RobotModel.from_name("dshdasr")
    task = paper_task()
    scene = view_scene(robot, task)
    q = np.random.default_rng(3).uniform(-0.5, 0.5, (2, robot.nq))
    poses = _object_poses(robot, scene, q, None)
    data = robot.model.createData()
    for k in range(2):
        pin.framesForwardKinematics(robot.model, data, q[k])
        hand = data.oMf[robot.arm("A").ee_frame_id].homogeneous
        assert np.allclose(poses[k].homogeneous, hand @ task.T_et_a, atol=1e-9)
    page = trajectory_html(robot, scene, np.array([0.0, 1.0]), q)
    assert '"object": true' in page and "&#9632;</span> target" in page
    assert any(c["type"] == "set_object" and c["path"].endswith("/object") for c in _commands(page))
    assert len(scene.obstacles) == len(task.obstacles)


def test_residual_plot_labels_the_regrasp_band(tmp_path, dual, scene1, monkeypatch):
    """The grey band of a regrasp has a legend entry in the residual/clearance figure."""
    from optplan.viz import plan_plots

    figs = []
    monkeypatch.setattr(plan_plots, "save_figure", lambda fig, path: figs.append(fig) or Path(path))
    t, q = _scene_motion(scene1, dual, 12)
    cons = np.ones(len(t), bool)
    cons[4:8] = False
    plan_plots.plot_trajectory(dual, scene1, t, q, tmp_path, constrained=cons, max_samples=12)
    res = figs[-1]
    for ax in res.axes:
        labels = [tx.get_text() for tx in ax.get_legend().get_texts()]
        assert plan_plots.REGRASP_LABEL in labels, labels


def test_browser_mesh_robot_is_not_black(tmp_path, browser):
    """A mesh robot (UR5) shows the arm's orange in a real browser."""
    robot = _ur5(tmp_path)
    q = np.tile(np.array([0.0, -1.2, 1.2, 0.0, 0.0, 0.0]), (2, 1))
    page = write_trajectory_html(tmp_path / "ur5.html", robot, None, np.array([0.0, 1.0]), q)
    _load(browser, page)
    assert _errors(browser) == []
    for _ in range(20):
        img = _screenshot(browser, "viewer_ur5.png")
        a = _color_pixels(img, ARM_COLORS[0])
        if a > 300:
            break
        time.sleep(0.25)
    assert a > 300, a
