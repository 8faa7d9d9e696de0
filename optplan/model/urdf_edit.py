"""URDF text edits behind robot files: resolving ``package://`` names, freezing joints, merging a
cylinder and its end spheres into one capsule, prefixing an arm's tree, and the base link of
mounted arms. Used by :mod:`.robot_file`, :mod:`.dual_panda` and :mod:`.mesh_boxes`."""
from __future__ import annotations

import copy
import fnmatch
import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..errors import ModelError

__all__ = ["package_search_dirs", "resolve_uri", "freeze_prismatic", "merge_capsules"]


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
