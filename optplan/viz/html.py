"""Self-contained, offline HTML views of a trajectory, through MeshCat.

:func:`trajectory_html` loads the robot's collision geometry (capsules, boxes, meshes) with
Pinocchio's :class:`pinocchio.visualize.MeshcatVisualizer`, adds the scene's obstacles, the carried
object and the hand paths, records the motion as a MeshCat animation, and writes one HTML file
that inlines MeshCat's JavaScript viewer (no server, no network: it opens from disk in any
browser). The page has a play/pause button and a time slider (and MeshCat's own control panel).
A free-floating robot's base moves with the trajectory's base configuration ``q[:7]``.

Needs the optional extra ``viz`` (``pip install "optplan[viz]"``: the ``meshcat`` package).

    from optplan.viz.html import write_trajectory_html
    write_trajectory_html("motion.html", robot, scene, t, q, constrained=constrained)

or from the command line: ``optplan view traj.npz --html motion.html``.
"""
from __future__ import annotations

import base64
import html as _html
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .meshes import stl_with_normals

__all__ = ["ViewOptions", "trajectory_html", "write_trajectory_html", "load_trajectory", "save_metadata", "view_file",
           "resolve_scene", "VizUnavailable", "floating_configurations", "arm_color",
           "ARM_COLORS", "OBJECT_COLOR", "OBSTACLE_COLOR"]

#: RGBA colours of the arms' links, in arm order (orange, blue, then green, purple)
ARM_COLORS = ((1.0, 0.55, 0.0, 1.0), (0.12, 0.47, 0.95, 1.0), (0.2, 0.75, 0.3, 1.0), (0.6, 0.3, 0.8, 1.0))
BASE_COLOR = (0.78, 0.78, 0.80, 1.0)
OBJECT_COLOR = (0.15, 0.8, 0.55, 0.85)
OBSTACLE_COLOR = (0.55, 0.55, 0.6, 0.55)
PATH_COLORS = (0xff8c00, 0x1f78f2, 0x33bf4d, 0x994dcc)


def arm_color(robot, arm: str) -> tuple[float, float, float, float]:
    """The RGBA colour of ``arm``'s links in the views (:data:`ARM_COLORS` in the robot's arm
    order); figures use it too, so that an arm has one colour in the HTML view and the PNGs."""
    names = list(robot.arms)
    if arm not in names:
        from ..errors import UnknownNameError

        raise UnknownNameError("arm", arm, names)
    return ARM_COLORS[names.index(arm) % len(ARM_COLORS)]


class VizUnavailable(ImportError):
    """The optional ``viz`` extra (meshcat) is not installed."""


def _need_meshcat():
    try:
        import meshcat  # noqa: F401
        import meshcat.geometry  # noqa: F401
    except ImportError as exc:   # pragma: no cover - depends on the environment
        raise VizUnavailable("the 3D view needs the optional extra 'viz': pip install \"optplan[viz]\" "
                             f"(meshcat could not be imported: {exc})") from exc


@dataclass(frozen=True)
class ViewOptions:
    """Options of the offline HTML views."""

    #: Frames per second of playback [1/s].
    fps: float = 25.0
    #: How long the whole motion plays [s] (None: in real time, at ``speed``).
    playback_s: float | None = 20.0
    #: Playback speed-up when ``playback_s`` is None [motion s per shown s].
    speed: float = 1.0
    #: At most this many frames [count] (longer motions are sampled more coarsely).
    max_frames: int = 600
    #: Draw the end-effector paths.
    hand_paths: bool = True
    #: Start playing on load.
    autoplay: bool = False
    #: Page title.
    title: str = "optplan trajectory"
    #: Camera position in the world [m] (None: looking at the scene from the front, above).
    camera: tuple | None = None

    def __post_init__(self):
        for name in ("fps", "speed", "playback_s"):
            v = getattr(self, name)
            if name == "playback_s" and v is None:
                continue
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"ViewOptions.{name}: expected a number > 0, got {v!r}")
        if not isinstance(self.max_frames, int) or self.max_frames < 2:
            raise ValueError(f"ViewOptions.max_frames: expected an int >= 2, got {self.max_frames!r}")


# --------------------------------------------------------------------------- recording "window"
class _RecordingWindow:
    """Stands in for meshcat's ZMQ window: keeps the scene tree exactly as meshcat-server does, so
    the page replays the same commands as meshcat's own static export (without a server)."""

    def __init__(self):
        from meshcat.servers.tree import SceneTree

        self.tree = SceneTree()

    def send(self, command):
        import umsgpack
        from meshcat.servers.tree import find_node

        data = command.lower()
        path = [p for p in data["path"].split("/") if p]
        blob = umsgpack.packb(data)
        kind = data["type"]
        if kind == "set_transform":
            find_node(self.tree, path).transform = blob
        elif kind == "set_object":
            node = find_node(self.tree, path)
            node.object, node.properties = blob, []
        elif kind == "set_property":
            find_node(self.tree, path).properties.append(blob)
        elif kind == "set_animation":
            find_node(self.tree, path).animation = blob
        elif kind == "delete":
            if path:
                parent = find_node(self.tree, path[:-1])
                parent.pop(path[-1], None)
            else:
                from meshcat.servers.tree import SceneTree

                self.tree = SceneTree()
        # capture_image and other interactive commands have no meaning in a static page

    def commands(self) -> list[bytes]:
        from meshcat.servers.tree import walk

        out = []
        for node in walk(self.tree):
            if node.object is not None:
                out.append(node.object)
            out.extend(node.properties)
            if node.transform is not None:
                out.append(node.transform)
            if node.animation is not None:
                out.append(node.animation)
        return out


# --------------------------------------------------------------------------- geometry helpers
def _color_int(rgba) -> int:
    return int(rgba[0] * 255) * 65536 + int(rgba[1] * 255) * 256 + int(rgba[2] * 255)


def _material(rgba):
    import meshcat.geometry as mg

    m = mg.MeshPhongMaterial(color=_color_int(rgba))
    if rgba[3] < 1.0:
        m.transparent = True
        m.opacity = float(rgba[3])
    return m


def _obstacle_geometry(ob):
    import meshcat.geometry as mg
    from pinocchio.visualize.meshcat_visualizer import createCapsule

    if ob.shape == "box":
        return mg.Box(list(ob.size))
    if ob.shape == "sphere":
        return mg.Sphere(float(ob.radius))
    return createCapsule(float(ob.length), float(ob.radius))


def _colored_geometry(robot) -> pin.GeometryModel:
    """A copy of the collision model with one colour per arm (links of the base in grey); STL
    meshes without normals are replaced by copies with normals (:func:`stl_with_normals`)."""
    gm = robot.collision_model.copy()
    for g in gm.geometryObjects:
        if g.meshPath and g.meshPath.lower().endswith(".stl") and Path(g.meshPath).is_file():
            g.meshPath = str(stl_with_normals(g.meshPath))
    joint_arm: dict[int, int] = {}
    for k, arm in enumerate(robot.arms.values()):
        for jn in arm.joint_names:
            joint_arm[int(robot.model.getJointId(jn))] = k
    # links below an arm's last joint (wrist, hand) belong to that arm too
    for jid in range(1, robot.model.njoints):
        j = jid
        while j > 0 and j not in joint_arm:
            j = int(robot.model.parents[j])
        if j > 0:
            joint_arm.setdefault(jid, joint_arm[j])
    for g in gm.geometryObjects:
        ka = joint_arm.get(int(g.parentJoint))
        g.meshColor = np.array(BASE_COLOR if ka is None else ARM_COLORS[ka % len(ARM_COLORS)], float)
    return gm


def _resample(t: np.ndarray, q: np.ndarray, robot, times: np.ndarray) -> np.ndarray:
    """Configurations at ``times`` (linear in the joints; the floating base's position linear and
    its quaternion normalized-linear between samples)."""
    out = np.empty((len(times), q.shape[1]))
    for j in range(q.shape[1]):
        out[:, j] = np.interp(times, t, q[:, j])
    if robot.is_floating:
        out[:, 3:7] /= np.linalg.norm(out[:, 3:7], axis=1, keepdims=True)
    return out


def _object_poses(robot, scene, q: np.ndarray, constrained: np.ndarray | None) -> list[pin.SE3] | None:
    """The carried object's pose at every configuration: held by the first arm (grasp frame) while
    the closed chain holds, kept where it was while unconstrained (regrasp: it stays in place)."""
    if scene is None or scene.object is None:
        return None
    arm = next((a for a in robot.arms if a in scene.object.grasps), None)
    if arm is None:
        return None
    fid = robot.arm(arm).ee_frame_id
    G_inv = scene.object.grasps[arm].inverse()
    data = robot.model.createData()
    held = np.ones(len(q), bool) if constrained is None or len(constrained) != len(q) else np.asarray(constrained, bool)
    poses: list = [None] * len(q)
    last = None
    for k in range(len(q)):
        if held[k]:
            pin.framesForwardKinematics(robot.model, data, q[k])
            last = data.oMf[fid] * G_inv
        poses[k] = last
    first = next((p for p in poses if p is not None), scene.start if scene.start is not None else pin.SE3.Identity())
    return [first if p is None else p for p in poses]


#: MeshCat's default camera: vertical field of view [deg]
CAMERA_FOV_DEG = 75.0


def _shown_points(robot, scene, qs: np.ndarray, hand_points: np.ndarray, obj_poses) -> np.ndarray:
    """Points that must be in view [m]: the hand paths, every joint and every collision geometry
    of the robot at the shown configurations (both arms and the base, not only the hands), the
    obstacles and the carried object."""
    pts = [hand_points.reshape(-1, 3)]
    data = robot.model.createData()
    gd = pin.GeometryData(robot.collision_model)
    step = max(1, len(qs) // 50)
    for qk in qs[::step]:
        pin.updateGeometryPlacements(robot.model, data, robot.collision_model, gd, qk)
        pts.append(np.array([M.translation for M in data.oMi[1:]] + [M.translation for M in gd.oMg]).reshape(-1, 3))
    if scene is not None:
        for o in scene.obstacles:
            pts.append(np.asarray(o.placement.translation)[None])
    if obj_poses is not None:
        pts.append(np.array([M.translation for M in obj_poses[::step]]))
    return np.concatenate([p for p in pts if p.size])


def _default_camera(points: np.ndarray, pad: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """Camera target (centre of the points) and position (front, above) in the world [m]: the
    nearest distance along that direction at which every point, padded by ``pad`` [m] for the
    link radii, projects inside the vertical field of view (:data:`CAMERA_FOV_DEG`; the same
    angle sideways: the window is at least as wide as tall), plus 5 %."""
    c = (points.min(axis=0) + points.max(axis=0)) / 2
    d = np.array([1.25, -1.0, 0.7])
    d /= np.linalg.norm(d)
    right = np.cross(np.array([0.0, 0.0, 1.0]), d)
    right /= np.linalg.norm(right)
    up = np.cross(d, right)
    rel = points - c
    lateral = np.maximum(np.abs(rel @ right), np.abs(rel @ up)) + pad
    # a point at depth s - rel·d in front of the camera is in view when lateral ≤ depth · tan(fov/2)
    need = rel @ d + pad + lateral / math.tan(math.radians(CAMERA_FOV_DEG) / 2)
    dist = max(1.05 * float(np.max(need)), 1.0)
    return c, c + dist * d


# --------------------------------------------------------------------------- main entry points
def trajectory_html(robot, scene, t, q, *, constrained=None, options: ViewOptions | None = None) -> str:
    """The HTML page (a string) animating ``q`` (M × nq, Pinocchio order) at times ``t`` [s] (M,).

    ``scene``: obstacles and the carried object (``None``: the robot alone); ``constrained`` (M,):
    where the closed chain holds (the object follows the first arm's hand; elsewhere it stays
    put). Raises ``ValueError`` naming the argument for shapes that do not fit the robot."""
    _need_meshcat()
    import meshcat
    import meshcat.geometry as mg
    from meshcat.animation import Animation
    from pinocchio.visualize import MeshcatVisualizer

    o = options or ViewOptions()
    t = np.asarray(t, float).reshape(-1)
    q = np.asarray(q, float)
    if q.ndim != 2 or q.shape[1] != robot.nq:
        raise ValueError(f"q: expected an (M, {robot.nq}) array of {robot.name!r} configurations, got shape {q.shape}")
    if len(t) != len(q) or len(t) < 1:
        raise ValueError(f"t: expected {len(q)} times (one per configuration), got {len(t)}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
        raise ValueError("t, q: expected finite values")
    if len(t) > 1 and np.any(np.diff(t) < 0):
        raise ValueError("t: expected non-decreasing times")

    window = _RecordingWindow()
    vis = meshcat.Visualizer(window=window)
    gm = _colored_geometry(robot)
    viz = MeshcatVisualizer(robot.model, gm, gm.copy())
    viz.initViewer(viewer=vis)
    viz.loadViewerModel(rootNodeName="robot")
    vis["/Grid"].set_property("visible", False)
    vis["/Background"].set_property("top_color", [0.93, 0.94, 0.97])
    vis["/Background"].set_property("bottom_color", [0.62, 0.66, 0.75])

    # timeline
    duration = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    speed = o.speed if o.playback_s is None or duration <= 0 else duration / o.playback_s
    n_frames = 1 if duration <= 0 else int(min(o.max_frames, max(2, math.ceil(duration / speed * o.fps) + 1)))
    times = t[0] + np.linspace(0.0, duration, n_frames) if n_frames > 1 else t[:1].copy()
    qs = _resample(t, q, robot, times) if n_frames > 1 else q[:1].copy()
    cons = None
    if constrained is not None and len(constrained) == len(q):
        idx = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 1)
        cons = np.asarray(constrained, bool)[idx]
    fps = (n_frames - 1) / (duration / speed) if n_frames > 1 else o.fps

    # static scene
    if scene is not None:
        for ob in scene.obstacles:
            node = vis["obstacles"][ob.name]
            node.set_object(_obstacle_geometry(ob), _material(OBSTACLE_COLOR))
            node.set_transform(ob.placement.homogeneous)
    obj_poses = _object_poses(robot, scene, qs, cons)
    if obj_poses is not None:
        vis["object"].set_object(mg.Box(list(scene.object.size)), _material(OBJECT_COLOR))
        vis["object"].set_transform(obj_poses[0].homogeneous)

    # hand (and base) paths from the original samples, densified
    data = robot.model.createData()
    dense_t = t[0] + np.linspace(0.0, duration, min(2000, max(2, 10 * len(t)))) if len(t) > 1 else t
    dense = _resample(t, q, robot, dense_t) if len(t) > 1 else q
    hands = np.zeros((len(robot.arms), len(dense), 3))
    base = np.zeros((len(dense), 3))
    for k, qk in enumerate(dense):
        pin.framesForwardKinematics(robot.model, data, qk)
        for a, arm in enumerate(robot.arms.values()):
            hands[a, k] = data.oMf[arm.ee_frame_id].translation
        base[k] = qk[:3] if robot.is_floating else 0.0
    if o.hand_paths and len(dense) > 1:
        for a, name in enumerate(robot.arms):
            pts = mg.PointsGeometry(hands[a].T.astype(np.float32))
            vis["paths"][f"hand_{name}"].set_object(
                mg.Line(pts, mg.LineBasicMaterial(color=PATH_COLORS[a % len(PATH_COLORS)], linewidth=3)))
        if robot.is_floating:
            vis["paths"]["base"].set_object(mg.Line(mg.PointsGeometry(base.T.astype(np.float32)),
                                                    mg.LineBasicMaterial(color=0x333333, linewidth=3)))

    # first frame as the static pose, then the animation
    viz.display(qs[0])
    anim = Animation(default_framerate=fps)
    root = viz.viewer
    for k, qk in enumerate(qs):
        with anim.at_frame(vis, k) as frame:
            viz.viewer = frame
            viz.display(qk)
            if obj_poses is not None:
                frame["object"].set_transform(obj_poses[k].homogeneous)
    viz.viewer = root
    if n_frames > 1:
        vis.set_animation(anim, play=o.autoplay, repetitions=1)

    target, cam = _default_camera(_shown_points(robot, scene, qs, hands, obj_poses))
    if o.camera is not None:
        cam = np.asarray(o.camera, float)
    # meshcat's camera lives in a y-up frame rotated from the world's z-up: (x, y, z) -> (x, z, -y)
    vis["/Cameras/default"].set_transform(pin.SE3(np.eye(3), target).homogeneous)
    rel = cam - target
    vis["/Cameras/default/rotated/<object>"].set_property("position", [float(rel[0]), float(rel[2]), float(-rel[1])])

    meta = {"title": o.title, "robot": robot.name, "scene": None if scene is None else scene.name,
            "duration_s": duration, "frames": int(n_frames), "fps": float(fps), "speed": float(speed),
            "floating": bool(robot.is_floating), "arms": list(robot.arms), "object": obj_poses is not None,
            "object_label": str((scene.extra or {}).get("object_label", "object")) if scene is not None else "object"}
    return _page(window.commands(), meta)


def write_trajectory_html(path, robot, scene, t, q, *, constrained=None, options: ViewOptions | None = None) -> Path:
    """Write :func:`trajectory_html` to ``path`` (parent directories are created); returns the path."""
    p = Path(path)
    page = trajectory_html(robot, scene, t, q, constrained=constrained, options=options)
    p.parent.mkdir(parents=True, exist_ok=True)
    from .._io import write_text

    write_text(p, page)   # atomic: complete or absent
    return p


def _page(commands: Sequence[bytes], meta: dict) -> str:
    import meshcat

    js_path = Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js"
    js = js_path.read_text(encoding="utf-8")
    blobs = ",\n".join(json.dumps(base64.b64encode(c).decode("ascii")) for c in commands)
    title = _html.escape(meta["title"])
    legend = " &middot; ".join(
        f'<span style="color:#{PATH_COLORS[i % len(PATH_COLORS)]:06x}">&#9632;</span> arm {_html.escape(a)}'
        for i, a in enumerate(meta["arms"]))
    info = _html.escape(f"{meta['robot']}" + (f" in {meta['scene']}" if meta["scene"] else "")
                        + f", {meta['duration_s']:.2f} s" + (", free-floating base" if meta["floating"] else ""))
    obj_legend = (f' &middot; <span style="color:#{_color_int(OBJECT_COLOR):06x}">&#9632;</span> '
                  f'{_html.escape(meta.get("object_label", "object"))}') if meta.get("object") else ""
    # </script> cannot occur inside the inline script
    js = js.replace("</script", "<\\/script")
    return f"""<!DOCTYPE html>
<html>
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>
body {{ margin: 0; font-family: sans-serif; }}
#meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
#optplan-bar {{ position: fixed; left: 0; right: 0; bottom: 0; padding: 6px 12px; background: rgba(255,255,255,0.85);
  display: flex; align-items: center; gap: 10px; font-size: 13px; z-index: 10; }}
#optplan-bar input[type=range] {{ flex: 1; }}
#optplan-info {{ position: fixed; left: 10px; top: 8px; font-size: 13px; background: rgba(255,255,255,0.7);
  padding: 4px 8px; border-radius: 4px; z-index: 10; }}
</style>
</head>
<body>
<div id="meshcat-pane"></div>
<div id="optplan-info"><b>{title}</b><br>{info}<br>{legend}{obj_legend}</div>
<div id="optplan-bar">
  <button id="optplan-play" type="button">&#9654; play</button>
  <input id="optplan-slider" type="range" min="0" max="1000" value="0" step="1">
  <span id="optplan-time">0.00 s</span>
</div>
<script>
{js}
</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
var optplanMeta = {json.dumps(meta)};
var optplanCommands = [
{blobs}
];
function optplanDecode(s) {{
  var b = atob(s), a = new Uint8Array(b.length);
  for (var i = 0; i < b.length; i++) a[i] = b.charCodeAt(i);
  return a;
}}
for (var i = 0; i < optplanCommands.length; i++) viewer.handle_command_bytearray(optplanDecode(optplanCommands[i]));
(function () {{
  var an = viewer.animator, btn = document.getElementById("optplan-play"),
      sl = document.getElementById("optplan-slider"), lab = document.getElementById("optplan-time");
  var dur = optplanMeta.duration_s, speed = optplanMeta.speed;
  function clipLen() {{ return an.duration > 0 ? an.duration : 1; }}
  function show() {{
    var f = an.actions.length ? an.actions[0].time / clipLen() : 0;
    if (document.activeElement !== sl) sl.value = Math.round(1000 * f);
    lab.textContent = (f * dur).toFixed(2) + " / " + dur.toFixed(2) + " s";
    btn.innerHTML = an.playing ? "&#10074;&#10074; pause" : "&#9654; play";
  }}
  btn.onclick = function () {{
    if (an.playing) {{ an.pause(); }} else {{
      if (an.actions.length && an.actions[0].time >= clipLen() - 1e-6) an.reset();
      an.play();
    }}
    show();
  }};
  sl.oninput = function () {{ if (an.playing) an.pause(); an.seek(sl.value / 1000 * clipLen()); show(); }};
  if (dur <= 0 || !an.actions.length) {{ btn.disabled = true; sl.disabled = true; }}
  else if (!an.playing) {{ an.play(); an.pause(); an.seek(0); }}   // actions active, so that seeking shows a frame
  setInterval(show, 100);
  show();
}})();
</script>
</body>
</html>
"""


# --------------------------------------------------------------------------- trajectory files
def load_trajectory(path) -> dict:
    """A trajectory npz (``t`` [s], ``q`` [rad] M × nq, optional ``constrained``, ``joint_names``,
    ``robot``, ``scene``; ``base_q`` (M × 7) is put in front of joint-only ``q``) as a dict;
    raises ``ValueError`` naming what is missing."""
    from ..limits import check_path

    p = check_path(path, "trajectory file", ValueError)
    if not p.exists():
        raise FileNotFoundError(f"trajectory file {str(p)!r} does not exist")
    try:
        z = np.load(p, allow_pickle=False)
    except Exception as exc:
        raise ValueError(f"{p}: not a trajectory npz ({type(exc).__name__}: {exc})") from exc
    with z:
        keys = set(z.files)
        if not {"t", "q"} <= keys:
            raise ValueError(f"{p}: expected arrays 't' and 'q' in the npz, found {sorted(keys)}")
        out: dict[str, Any] = {"t": np.asarray(z["t"], float), "q": np.asarray(z["q"], float)}
        if "base_q" in keys:   # a free-floating base's [x, y, z, qx, qy, qz, qw] stored apart from the joints
            bq = np.asarray(z["base_q"], float)
            if bq.ndim == 2 and bq.shape == (len(out["q"]), 7):
                out["q"] = np.hstack([bq, out["q"]])
        for k in ("constrained", "joint_names", "qd"):
            if k in keys:
                out[k] = z[k]
        for k in ("robot", "scene"):
            if k in keys:
                out[k] = str(z[k])
    if out["q"].ndim != 2 or len(out["t"]) != len(out["q"]):
        raise ValueError(f"{p}: expected q of shape (M, nq) with M = len(t) = {len(out['t'])}, got {out['q'].shape}")
    return out


def floating_configurations(robot, t, q_joints, qd_joints=None) -> np.ndarray:
    """Full configurations (base XYZ-quaternion, then joints) of a free-floating robot whose file
    holds only the joints: the base motion follows from momentum conservation (zero momentum,
    base at the origin at t[0]; :func:`optplan.model.floating.simulate_base`)."""
    from ..model.floating import joint_trajectory_from_samples, simulate_base

    t = np.asarray(t, float)
    traj = joint_trajectory_from_samples(t, np.asarray(q_joints, float),
                                         None if qd_joints is None else np.asarray(qd_joints, float))
    return simulate_base(robot, traj, t).q


def save_metadata(path, *, robot: str | None = None, scene: str | None = None) -> None:
    """Add the robot and scene names to a trajectory npz, so ``optplan view`` needs no ``--scene``."""
    p = Path(path)
    if p.suffix != ".npz" and not p.exists():
        p = p.with_name(p.name + ".npz")   # np.savez appends .npz
    with np.load(p, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    if robot is not None:
        arrays["robot"] = np.array(robot)
    if scene is not None:
        arrays["scene"] = np.array(scene)
    from .._io import atomic_path

    with atomic_path(p) as tmp, open(tmp, "wb") as f:
        np.savez(f, **arrays)


def resolve_scene(name_or_path: str | None):
    """``"1"`` → ``ssps_scene1``; a scene name or a TOML path → :class:`optplan.scene.Scene`."""
    from ..scene import Scene

    if name_or_path is None or str(name_or_path).strip() == "":
        return None
    s = str(name_or_path).strip()
    return Scene.load(f"ssps_scene{s}" if s.isdigit() else s)


def view_file(traj_path, *, scene: str | None = None, robot: str | None = None, out=None,
              options: ViewOptions | None = None) -> Path:
    """Write the HTML view of a trajectory npz (``optplan view``). The scene and robot come from
    the arguments, else from the npz (``optplan plan --save`` records them), else the robot from
    the scene's ``robot``. Returns the HTML path (default: the npz path with ``.html``)."""
    from ..model.robot import RobotModel

    tr = load_trajectory(traj_path)
    sc = resolve_scene(scene if scene is not None else tr.get("scene"))
    robot_name = robot or tr.get("robot") or (sc.robot if sc is not None else None)
    if robot_name is None:
        raise ValueError(f"{traj_path}: the file does not name its robot or scene; pass --scene NAME|PATH "
                         "(or --robot NAME)")
    rm = RobotModel.from_name(robot_name) if not str(robot_name).endswith(".urdf") else None
    if rm is None:
        raise ValueError(f"--robot: expected the name of a shipped model, got {robot_name!r}")
    if rm.is_floating and tr["q"].shape[1] == rm.nj:
        tr["q"] = floating_configurations(rm, tr["t"], tr["q"], tr.get("qd"))
    if tr["q"].shape[1] != rm.nq:
        raise ValueError(f"{traj_path}: q has {tr['q'].shape[1]} columns but robot {rm.name!r} has nq = {rm.nq}; "
                         "pass the right --robot/--scene")
    out = Path(out) if out is not None else Path(traj_path).with_suffix(".html")
    title = (options.title if options is not None and options.title != ViewOptions.title
             else f"optplan: {Path(traj_path).name}")
    opts = options or ViewOptions()
    from dataclasses import replace

    return write_trajectory_html(out, rm, sc, tr["t"], tr["q"], constrained=tr.get("constrained"),
                                 options=replace(opts, title=title))
