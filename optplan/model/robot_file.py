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

import copy
import fnmatch
import hashlib
import logging
import math
import os
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from ..errors import ModelError

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


def package_search_dirs(package_dirs: Sequence[str | Path] = ()) -> list[Path]:
    """Where ``package://NAME/...`` is looked up, in order: ``package_dirs``, ``ROS_PACKAGE_PATH``,
    ``AMENT_PREFIX_PATH``'s ``share/`` directories, and the ``share/`` directories of installed
    Python packages (``cmeel.prefix/share``, e.g. example-robot-data)."""
    import site
    import sys

    out = [Path(p).expanduser() for p in package_dirs]
    out += [Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    out += [Path(p) / "share" for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    roots = list(site.getsitepackages()) + [site.getusersitepackages()] + list(sys.path)
    for r in roots:
        p = Path(r) / "cmeel.prefix" / "share"
        if p.is_dir() and p not in out:
            out.append(p)
    return out


def resolve_uri(uri: str, base_dir: Path, package_dirs: Sequence[str | Path] = ()) -> Path:
    """A URDF file name as a path: ``package://NAME/rest`` (see :func:`package_search_dirs`: a
    directory named NAME, or one containing NAME/), ``file://``, absolute, or relative to
    ``base_dir``."""
    if uri.startswith("package://"):
        pkg, _, rest = uri[len("package://"):].partition("/")
        dirs = package_search_dirs(package_dirs)
        for d in dirs:
            for cand in ((d / rest) if d.name == pkg else None, d / pkg / rest):
                if cand is not None and cand.exists():
                    return cand
        raise ModelError(f"cannot resolve {uri!r}: package {pkg!r} not found in {[str(d) for d in dirs]} "
                         "(add its parent directory to package_dirs or ROS_PACKAGE_PATH)")
    if uri.startswith("file://"):
        uri = uri[len("file://"):]
    p = Path(uri).expanduser()
    return p if p.is_absolute() else (base_dir / p)


def _parse(path: Path) -> ET.Element:
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ModelError(f"{path}: malformed URDF XML: {exc}") from exc
    except OSError as exc:
        raise ModelError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if root.tag != "robot":
        raise ModelError(f"{path}: expected a <robot> root element, got <{root.tag}>")
    return root


def _resolve_meshes(root: ET.Element, base_dir: Path, package_dirs: Sequence[str | Path]) -> None:
    """Mesh file names as absolute paths: a collision mesh that cannot be found is an error, a
    visual one is left as it is (only the collision geometry is loaded)."""
    for kind in ("collision", "visual"):
        for el in root.iter(kind):
            for m in el.iter("mesh"):
                fn = m.get("filename")
                if not fn:
                    continue
                try:
                    p = resolve_uri(fn, base_dir, package_dirs)
                    if not p.exists():
                        raise ModelError(f"{kind} mesh {fn!r}: {p} does not exist")
                except ModelError:
                    if kind == "collision":
                        raise
                    continue
                m.set("filename", str(p))


def _floats(s: str | None, default: str) -> np.ndarray:
    return np.array([float(x) for x in (s or default).split()])


def freeze_prismatic(e: ET.Element, opening: float) -> None:
    """A prismatic joint element made fixed, its origin moved by ``opening`` [m] along its axis (a
    gripper's finger frozen open); any other element is left alone."""
    if e.tag != "joint" or e.get("type") != "prismatic":
        return
    o, axis = e.find("origin"), e.find("axis")
    if o is None:
        o = ET.SubElement(e, "origin")
    ax = _floats(axis.get("xyz") if axis is not None else None, "1 0 0")
    o.set("xyz", " ".join(repr(float(v)) for v in _floats(o.get("xyz"), "0 0 0") + opening * ax))
    e.set("type", "fixed")
    for tag in ("limit", "mimic", "dynamics", "axis", "safety_controller"):
        for x in e.findall(tag):
            e.remove(x)


def _origin(col: ET.Element) -> pin.SE3:
    o = col.find("origin")
    xyz = _floats(o.get("xyz") if o is not None else None, "0 0 0")
    rpy = _floats(o.get("rpy") if o is not None else None, "0 0 0")
    return pin.SE3(pin.rpy.rpyToMatrix(*rpy), xyz)


def merge_capsules(link: ET.Element, tol: float = 2e-3) -> int:
    """In one URDF ``<link>``: every ``<cylinder>`` collision with a ``<sphere>`` collision of the
    same radius (± ``tol`` [m]) centred at each end of its axis (± ``tol``) becomes one collision
    named ``<link>_<k>_capsule`` (the union of the three is exactly that capsule) and the two
    spheres are removed. Returns the number of capsules made."""
    cols = link.findall("collision")
    spheres = []
    for c in cols:
        s = c.find("geometry/sphere")
        if s is not None:
            spheres.append((c, float(s.attrib["radius"]), _origin(c).translation))
    used: set[int] = set()
    n = 0
    for c in cols:
        cyl = c.find("geometry/cylinder")
        if cyl is None:
            continue
        r, L = float(cyl.attrib["radius"]), float(cyl.attrib["length"])
        M = _origin(c)
        ends = [M.translation + M.rotation @ np.array([0.0, 0.0, s * L / 2]) for s in (-1, 1)]
        match = []
        for e in ends:
            k = next((i for i, (_, rs, p) in enumerate(spheres)
                      if i not in used and i not in match and abs(rs - r) <= tol and np.linalg.norm(p - e) <= tol), None)
            if k is None:
                break
            match.append(k)
        if len(match) != 2:
            continue
        used.update(match)
        c.set("name", f"{link.get('name')}_{n}_capsule")
        n += 1
    for i in sorted(used, reverse=True):
        link.remove(spheres[i][0])
    return n


def _root_link(root: ET.Element) -> str:
    links = [e.get("name") for e in root.findall("link")]
    children = {j.find("child").get("link") for j in root.findall("joint") if j.find("child") is not None}  # type: ignore[union-attr]
    roots = [n for n in links if n not in children]
    if len(roots) != 1:
        raise ModelError(f"URDF {root.get('name')!r}: expected one root link, found {roots}")
    return str(roots[0])


def _prefixed(root: ET.Element, prefix: str) -> list[ET.Element]:
    out = []
    for el in root:
        if el.tag not in ("link", "joint"):
            continue
        e = copy.deepcopy(el)
        e.set("name", prefix + e.attrib["name"])
        if e.tag == "joint":
            for tag in ("parent", "child"):
                t = e.find(tag)
                if t is not None:
                    t.set("link", prefix + t.attrib["link"])
            m = e.find("mimic")
            if m is not None:
                m.set("joint", prefix + m.attrib["joint"])
        out.append(e)
    return out


def _pose_attrs(d: Any, where: str) -> dict[str, str]:
    if not isinstance(d, Mapping):
        raise ModelError(f"{where}: expected a table {{ xyz = [x, y, z], rpy = [r, p, y] }}, got {d!r}")
    out = {}
    for k in ("xyz", "rpy"):
        v = d.get(k, [0.0, 0.0, 0.0])
        if not (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                              and math.isfinite(x) for x in v)):
            raise ModelError(f"{where}.{k}: expected 3 finite numbers, got {v!r}")
        out[k] = " ".join(repr(float(x)) for x in v)
    extra = set(d) - {"xyz", "rpy"}
    if extra:
        raise ModelError(f"{where}: unknown keys {sorted(extra)}; expected xyz, rpy")
    return out


def _fix_joints(root: ET.Element, spec: Any, prefixes: Sequence[str] = ()) -> list[str]:
    """Make the joints matching ``spec`` (names or fnmatch patterns; a table gives values [rad or
    m]) fixed at their value; returns the joints fixed. A pattern matches a joint's name, or its
    name without one of ``prefixes`` (the mounted arms' prefixes: patterns in the arm's own names)."""
    if isinstance(spec, (list, tuple)):
        table = {str(s): 0.0 for s in spec}
    elif isinstance(spec, Mapping):
        table = {}
        for k, v in spec.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ModelError(f"fixed_joints.{k}: expected a number [rad or m], got {v!r}")
            table[str(k)] = float(v)
    else:
        raise ModelError(f"fixed_joints: expected a list of joint names/patterns or a table {{ name = value }}, "
                         f"got {spec!r}")
    done, used = [], set()
    for j in root.findall("joint"):
        name, typ = j.get("name", ""), j.get("type")
        if typ == "fixed":
            continue
        own = [name[len(px):] for px in prefixes if px and name.startswith(px)]
        pat = next((p for p in table if any(fnmatch.fnmatchcase(n, p) for n in [name, *own])), None)
        if pat is None:
            continue
        used.add(pat)
        val = table[pat]
        if val != 0.0:
            o = j.find("origin")
            if o is None:
                o = ET.SubElement(j, "origin", {"xyz": "0 0 0", "rpy": "0 0 0"})
            ax = j.find("axis")
            axis = _floats(ax.get("xyz") if ax is not None else None, "1 0 0")
            axis = axis / np.linalg.norm(axis)
            M = pin.SE3(pin.rpy.rpyToMatrix(*_floats(o.get("rpy"), "0 0 0")), _floats(o.get("xyz"), "0 0 0"))
            motion = pin.SE3(np.eye(3), val * axis) if typ == "prismatic" else \
                pin.SE3(pin.exp3(val * axis), np.zeros(3))
            M = M * motion
            o.set("xyz", " ".join(repr(float(x)) for x in M.translation))
            o.set("rpy", " ".join(repr(float(x)) for x in pin.rpy.matrixToRpy(M.rotation)))
        j.set("type", "fixed")
        for tag in ("limit", "mimic", "dynamics", "safety_controller", "calibration", "axis"):
            for e in j.findall(tag):
                j.remove(e)
        done.append(name)
    unused = [p for p in table if p not in used]
    if unused:
        names = [j.get("name") for j in root.findall("joint") if j.get("type") != "fixed"]
        raise ModelError(f"fixed_joints: {unused} match no movable joint; movable joints: {names}")
    return done


def _base_link(spec: Any) -> ET.Element:
    link = ET.Element("link", {"name": "base"})
    inert = ET.SubElement(link, "inertial")
    ET.SubElement(inert, "mass", {"value": "10"})
    ET.SubElement(inert, "inertia", dict(zip(("ixx", "ixy", "ixz", "iyy", "iyz", "izz"), ("1", "0", "0", "1", "0", "1"))))
    if spec is None:
        return link
    if not isinstance(spec, Mapping) or set(spec) - {"boxes"}:
        raise ModelError(f"base: expected a table {{ boxes = [{{ size, xyz, rpy }}, ...] }}, got {spec!r}")
    for k, b in enumerate(spec.get("boxes", [])):
        w = f"base.boxes[{k}]"
        if not isinstance(b, Mapping) or "size" not in b:
            raise ModelError(f"{w}: expected a table with size = [x, y, z] [m], got {b!r}")
        size = b["size"]
        if not (isinstance(size, list) and len(size) == 3 and all(isinstance(x, (int, float)) and x > 0 for x in size)):
            raise ModelError(f"{w}.size: expected 3 edges > 0 m, got {size!r}")
        col = ET.SubElement(link, "collision", {"name": f"base_box{k}"})
        ET.SubElement(col, "origin", _pose_attrs({kk: b[kk] for kk in ("xyz", "rpy") if kk in b}, w))
        ET.SubElement(ET.SubElement(col, "geometry"), "box", {"size": " ".join(repr(float(x)) for x in size)})
    return link


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
