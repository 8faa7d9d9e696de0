"""Robot files: a user's own URDF robot described in a small TOML file (or a bare URDF path).

```toml
name = "dual_ur5"
urdf = "package://example-robot-data/robots/ur_description/urdf/ur5_robot.urdf"
package_dirs = []                 # extra directories to resolve package:// (also ROS_PACKAGE_PATH,
                                  # AMENT_PREFIX_PATH and installed packages' share/ directories)
floating = false                  # true: a free-flyer root joint (free-floating base)
collision = "auto"                # "auto" | "primitives" | "mesh"
fixed_joints = ["*finger_joint*"] # locked at 0, or a table { name_or_pattern = value [rad or m] }

[base]                            # optional, when arms are mounted: the common base link
boxes = [{ size = [0.4, 1.2, 0.05], xyz = [0, 0, -0.025], rpy = [0, 0, 0] }]

[arms.left]
ee = "tool0"                      # end-effector frame (in the arm's own URDF when mounted)
mount = { xyz = [0, 0.4, 0], rpy = [0, 0, 0] }   # [m], [rad]: copy of `urdf` fixed to the base here
# joints = [...]                  # default: every 1-DoF joint from the root to `ee`
# urdf = "..."                    # this arm's own URDF (default: the top-level one)
# prefix = "left_"                # default "<arm>_" (mounted arms only)
```

Without ``mount`` the URDF is the whole robot and ``ee``/``joints`` name its frames. ``collision``
(in every mode but ``"mesh"``, a link's ``<cylinder>`` with a ``<sphere>`` of its radius at each end
of its axis becomes one capsule, :func:`merge_capsules`):

* ``"mesh"`` — the URDF's collision geometry as is (the trajectory NLP bounds a mesh by its vertices);
* ``"primitives"`` — every mesh replaced by certified capsules (:mod:`.primitive_fit`) everywhere;
* ``"auto"`` (default) — the planner and the NLP work on the capsules, :func:`optplan.verify`
  judges on the meshes (``robot.exact``), each as its convex hull (it contains the mesh, so no
  contact of the mesh is missed; GJK on a hull is ~10× faster than coal's mesh–mesh distance,
  which made a verification of the UR5's meshes take seconds per segment).

Self-collision pairs are then pruned (:mod:`.pair_budget`), and the report is in
``robot.pair_budget``; the capsule fits per link in ``robot.primitive_report``.
"""
from __future__ import annotations

import hashlib
import logging
import os
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from ..errors import ModelError
from .urdf_edit import (  # noqa: F401  (re-exported: the edits a robot file is made of)
    _base_link,
    _fix_joints,
    _floats,
    _origin,
    _parse,
    _pose_attrs,
    _prefixed,
    _resolve_meshes,
    _root_link,
    freeze_prismatic,
    merge_capsules,
    package_search_dirs,
    resolve_uri,
)

__all__ = ["available_robot_files", "robot_files_dir", "load_robot_file", "load_urdf_robot", "resolve_uri", "package_search_dirs", "is_robot_path",
           "infer_arms", "COLLISION_MODES"]
log = logging.getLogger(__name__)

COLLISION_MODES = ("auto", "primitives", "mesh")
_KEYS = ("name", "urdf", "package_dirs", "floating", "collision", "fixed_joints", "arms", "base", "max_capsules",
         "pair_samples", "notes")
_ARM_KEYS = ("ee", "joints", "mount", "urdf", "prefix")


def robot_files_dir() -> Path:
    """``models/robots/files``: the robot files shipped with optplan."""
    from .description import models_dir

    return models_dir() / "robots" / "files"


def available_robot_files() -> list[str]:
    """Names of the robot files in :func:`robot_files_dir` (loadable by name)."""
    d = robot_files_dir()
    return sorted(p.stem for p in d.glob("*.toml")) if d.is_dir() else []


def is_robot_path(name: str) -> bool:
    """Is ``name`` a robot file or URDF path rather than a shipped model's name?"""
    s = str(name)
    return s.endswith((".toml", ".urdf", ".xml")) or os.sep in s or "/" in s


def _compose(data: dict, base_dir: Path, package_dirs: list) -> tuple[str, dict[str, dict]]:
    """URDF text of the robot of a robot file, and the arms' ``{ee, joints}`` in its names."""
    arms_spec = data.get("arms")
    if not isinstance(arms_spec, Mapping) or not arms_spec:
        raise ModelError("arms: expected at least one [arms.NAME] table with ee = \"frame\"")
    for a, s in arms_spec.items():
        if not isinstance(s, Mapping):
            raise ModelError(f"arms.{a}: expected a table with ee = \"frame\", got {s!r}")
        extra = set(s) - set(_ARM_KEYS)
        if extra:
            raise ModelError(f"arms.{a}: unknown keys {sorted(extra)}; expected {', '.join(_ARM_KEYS)}")
        if "ee" not in s:
            raise ModelError(f"arms.{a}: missing ee (the end-effector frame)")
    mounted = [a for a, s in arms_spec.items() if "mount" in s or "urdf" in s]
    if mounted and len(mounted) != len(arms_spec):
        raise ModelError(f"arms: {mounted} are mounted (mount/urdf) and the others not; mount every arm or none")
    top = data.get("urdf")
    if not mounted:
        if not isinstance(top, str):
            raise ModelError(f"urdf: expected the URDF's path, got {top!r}")
        p = resolve_uri(top, base_dir, package_dirs)
        root = _parse(p)
        _resolve_meshes(root, p.parent, package_dirs)
        arms = {a: {"ee": str(s["ee"]), "joints": s.get("joints")} for a, s in arms_spec.items()}
    else:
        root = ET.Element("robot", {"name": str(data.get("name", "robot"))})
        root.append(_base_link(data.get("base")))
        arms = {}
        for a, s in arms_spec.items():
            src = s.get("urdf", top)
            if not isinstance(src, str):
                raise ModelError(f"arms.{a}.urdf: expected a URDF path (or a top-level urdf), got {src!r}")
            p = resolve_uri(src, base_dir, package_dirs)
            arm_root = _parse(p)
            _resolve_meshes(arm_root, p.parent, package_dirs)
            prefix = str(s.get("prefix", f"{a}_"))
            for e in _prefixed(arm_root, prefix):
                root.append(e)
            j = ET.SubElement(root, "joint", {"name": f"{prefix}mount", "type": "fixed"})
            ET.SubElement(j, "parent", {"link": "base"})
            ET.SubElement(j, "child", {"link": prefix + _root_link(arm_root)})
            ET.SubElement(j, "origin", _pose_attrs(s.get("mount", {}), f"arms.{a}.mount"))
            joints = s.get("joints")
            arms[a] = {"ee": prefix + str(s["ee"]), "joints": None if joints is None else [prefix + str(x) for x in joints]}
    for t in list(root.findall("transmission")) + list(root.findall("gazebo")):
        root.remove(t)
    if data.get("collision", "auto") != "mesh":   # a cylinder with a sphere at each end: one capsule
        for link in root.findall("link"):
            merge_capsules(link)
    if "fixed_joints" in data:
        _fix_joints(root, data["fixed_joints"],
                    [str(s.get("prefix", f"{a}_")) for a, s in arms_spec.items()] if mounted else ())
    return ET.tostring(root, encoding="unicode"), arms


def _cached_urdf(text: str, name: str) -> Path:
    d = Path(tempfile.gettempdir()) / "optplan_robot_files"
    d.mkdir(exist_ok=True)
    p = d / f"{name}-{hashlib.sha256(text.encode()).hexdigest()[:16]}.urdf"
    if not p.exists():
        p.write_text(text)
    return p


def infer_arms(model: pin.Model) -> dict[str, str]:
    """Arms of a bare URDF: at every leaf joint of the tree that has at least three movable joints
    above it, the last frame attached to it (a tool frame when there is one), named ``A`` and
    ``B`` in name order. Raises naming the candidates when there are not exactly two."""
    children: dict[int, list[int]] = {}
    for j in range(1, model.njoints):
        children.setdefault(int(model.parents[j]), []).append(j)
    leaves = [j for j in range(1, model.njoints) if j not in children]

    def depth(j: int) -> int:
        n = 0
        while j > 0:
            n += 1
            j = int(model.parents[j])
        return n
    cands = [j for j in leaves if depth(j) >= 3]
    frames = {}
    for j in cands:   # the last frame hanging from the leaf joint (a tool frame if there is one)
        fr = [f for f in model.frames if f.parentJoint == j and f.type in (pin.FrameType.OP_FRAME, pin.FrameType.BODY)]
        if fr:
            frames[j] = fr[-1].name
    if len(frames) != 2:
        raise ModelError(f"cannot infer the arms: {len(frames)} candidate end-effector frames "
                         f"{sorted(frames.values())}; write a robot file naming [arms.NAME] ee = \"frame\"")
    a, b = sorted(frames.values())
    return {"A": a, "B": b}


def load_urdf_robot(path: str | Path, cls: Any, **kw: Any) -> Any:
    """A bare URDF as a robot (a ``cls``, :class:`~optplan.model.robot.RobotModel`): arms inferred
    (:func:`infer_arms`), collision ``"auto"``."""
    path = Path(path)
    if not path.exists():
        raise ModelError(f"URDF file {str(path)!r} does not exist")
    try:
        m = pin.buildModelFromUrdf(str(path))
    except (RuntimeError, ValueError) as exc:
        raise ModelError(f"{path}: Pinocchio could not parse the URDF: {str(exc).strip().splitlines()[0]}") from exc
    data = {"name": path.stem, "urdf": str(path.resolve()), "arms": {k: {"ee": v} for k, v in infer_arms(m).items()}}
    data.update(kw)
    return _load(data, path.parent, cls)


def load_robot_file(path: str | Path, cls: Any = None) -> Any:
    """The :class:`~optplan.model.robot.RobotModel` (or ``cls``) of a robot file (module docstring)
    or bare URDF. (``RobotModel.from_name(path)`` is the usual way in.)"""
    import tomllib

    if cls is None:   # called directly: the model class, imported here (robot.py imports this module)
        import importlib

        cls = importlib.import_module(__package__ + ".robot").RobotModel
    path = Path(path)
    if path.suffix in (".urdf", ".xml"):
        return load_urdf_robot(path, cls)
    if not path.exists():
        raise ModelError(f"robot file {str(path)!r} does not exist")
    try:
        data = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ModelError(f"{path}: not a valid TOML robot file: {exc}") from None
    extra = set(data) - set(_KEYS)
    if extra:
        raise ModelError(f"{path}: unknown keys {sorted(extra)}; expected {', '.join(_KEYS)}")
    data.setdefault("name", path.stem)
    try:
        return _load(data, path.parent, cls)
    except ModelError as exc:
        raise ModelError(f"{path}: {exc}") from None


def _load(data: dict, base_dir: Path, RobotModel: Any) -> Any:   # noqa: N803 (the class)
    from .pair_budget import prune_pairs

    pdirs = data.get("package_dirs", [])
    if not isinstance(pdirs, list) or not all(isinstance(p, str) for p in pdirs):
        raise ModelError(f"package_dirs: expected a list of directories, got {pdirs!r}")
    pdirs = [str(resolve_uri(p, base_dir)) for p in pdirs]
    mode = data.get("collision", "auto")
    if mode not in COLLISION_MODES:
        raise ModelError(f"collision: expected one of {COLLISION_MODES}, got {mode!r}")
    floating = data.get("floating", False)
    if not isinstance(floating, bool):
        raise ModelError(f"floating: expected true or false, got {floating!r}")
    ncap = data.get("max_capsules", 3)
    if isinstance(ncap, bool) or not isinstance(ncap, int) or ncap < 1:
        raise ModelError(f"max_capsules: expected an integer ≥ 1 (capsules per mesh), got {ncap!r}")
    samples = data.get("pair_samples", 1000)
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 0:
        raise ModelError(f"pair_samples: expected an integer ≥ 0 (configurations), got {samples!r}")
    name = str(data["name"])
    text, arms = _compose(data, base_dir, pdirs)
    upath = _cached_urdf(text, name)
    robot = RobotModel.from_urdf(upath, arms=arms, floating=floating, name=name)
    report: dict[str, dict] = {}
    if mode != "mesh":
        exact_gm = robot.collision_model
        gm, report = fitted_geometry(robot.model, exact_gm, max_capsules=ncap)
        exact = robot if mode == "auto" and report else None
        if exact is not None:
            _convex_hulls(exact.collision_model)
        robot = RobotModel(robot.model, gm, arms, name=name, floating=floating, urdf_path=upath)
        if exact is not None:
            robot.exact = exact
    robot.primitive_report = report
    robot.robot_file = data
    robot.pair_budget = _cached_budget(robot, text, mode, ncap, samples, prune_pairs)
    exact = getattr(robot, "exact", None)
    if exact is not None:
        _map_pairs(robot, exact)
    log.info("%s: %s", name, robot.pair_budget)
    return robot


def _cached_budget(robot: Any, text: str, mode: str, ncap: int, samples: int, prune: Any) -> dict:
    """:func:`~.pair_budget.prune_pairs` of ``robot``, cached under ``$OPTPLAN_CACHE/pair_budgets``
    by the URDF text and the settings (pairs stored by geometry names)."""
    import json

    from .pair_budget import MAX_CELLS, MAX_PATH_JOINTS, SAMPLE_CLEARANCE
    from .primitive_fit import _VERSION, _cache_dir

    key = hashlib.sha256(json.dumps([text, mode, ncap, samples, MAX_PATH_JOINTS, SAMPLE_CLEARANCE, MAX_CELLS, _VERSION, 3])
                         .encode()).hexdigest()
    path = _cache_dir().parent / "pair_budgets" / f"{key}.json"
    names = [o.name for o in robot.collision_model.geometryObjects]
    if path.exists():
        try:
            got = json.loads(path.read_text())
            index = {n: i for i, n in enumerate(names)}
            robot.set_collision_pairs([(index[a], index[b]) for a, b in got["pairs"]])
            return dict(got["budget"])
        except (OSError, ValueError, KeyError):
            pass
    budget = prune(robot, samples=samples)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"budget": budget, "pairs": [(names[a], names[b]) for a, b in robot.collision_pairs]}))
    except OSError:
        pass
    return budget


def _convex_hulls(gm: pin.GeometryModel) -> None:
    """Every triangle mesh of ``gm`` replaced by its convex hull (coal ``Convex``, qhull): it
    contains the mesh, and GJK on a hull is ~10× faster than coal's mesh–mesh distance."""
    for o in gm.geometryObjects:
        g = o.geometry
        if isinstance(g, coal.BVHModelBase):
            g.buildConvexHull(True, "Qt")
            o.geometry = g.convex


def _link_of(model: pin.Model, gm: pin.GeometryModel, g: int) -> str:
    return model.frames[gm.geometryObjects[g].parentFrame].name


def _map_pairs(robot: Any, exact: Any) -> None:
    """The exact model checks the pairs of links the primitive model keeps."""
    links = {frozenset((_link_of(robot.model, robot.collision_model, a), _link_of(robot.model, robot.collision_model, b)))
             for a, b in robot.collision_pairs}
    gm = exact.collision_model
    n = len(gm.geometryObjects)
    names = [_link_of(exact.model, gm, g) for g in range(n)]
    exact.set_collision_pairs([(a, b) for a in range(n) for b in range(a + 1, n)
                               if frozenset((names[a], names[b])) in links])


def fitted_geometry(model: pin.Model, gm: pin.GeometryModel, max_capsules: int = 3
                    ) -> tuple[pin.GeometryModel, dict[str, dict]]:
    """A copy of ``gm`` with every triangle mesh replaced by its certified capsules
    (:func:`~optplan.model.primitive_fit.fit_mesh`, named ``<geometry>_cap<k>``); returns it and
    the per-geometry report (capsules, vertices, hull and capsule volumes [m³], ratio)."""
    from .primitive_fit import fit_mesh

    out = pin.GeometryModel()
    report: dict[str, dict] = {}
    for o in gm.geometryObjects:
        geo = o.geometry
        if not isinstance(geo, coal.BVHModelBase):
            out.addGeometryObject(pin.GeometryObject(o))
            continue
        V = np.array([np.asarray(geo.vertex(i), float) for i in range(geo.num_vertices)])
        T = np.array([[geo.tri_indices(i)[k] for k in range(3)] for i in range(geo.num_tris)], np.int64) \
            if geo.num_tris else None
        fit = fit_mesh(V, T, max_capsules=max_capsules)
        for k, c in enumerate(fit.capsules):
            a, b = np.asarray(c.a), np.asarray(c.b)
            d = b - a
            L = float(np.linalg.norm(d))
            z = d / L if L > 0 else np.array([0.0, 0.0, 1.0])
            R = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), z).toRotationMatrix()
            M = o.placement * pin.SE3(R, 0.5 * (a + b))
            cap = pin.GeometryObject(f"{o.name}_cap{k}", int(o.parentJoint), int(o.parentFrame), M,
                                     coal.Capsule(c.radius, L))
            out.addGeometryObject(cap)
        report[o.name] = {"link": model.frames[o.parentFrame].name, "capsules": len(fit.capsules),
                          "vertices": fit.n_vertices, "hull_volume_m3": fit.hull_volume,
                          "capsule_volume_m3": fit.volume, "ratio": fit.ratio,
                          "max_vertex_distance_m": [c.max_distance for c in fit.capsules],
                          "radius_m": [c.radius for c in fit.capsules]}
    return out, report
