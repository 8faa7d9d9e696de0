"""Structural checks of a URDF before Pinocchio parses it.

urdfdom, under Pinocchio, reports a broken kinematic tree as "The XML stream does not contain a
valid URDF model" and prints the reason to the console. These checks find the same faults in the
XML first and name the file, the line and the element: a link defined twice, a joint of an unknown
type, a joint without a parent or child, a parent or child link that does not exist, a link with
two parent joints, a kinematic loop, zero or several root links, and an ``<origin>`` whose xyz/rpy
are not three finite numbers.
"""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from ..errors import ModelError

__all__ = ["check_urdf_structure", "URDF_JOINT_TYPES"]

#: joint types of the URDF specification
URDF_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")


def _line_of(text: str, tag: str, name: str | None) -> int:
    """Line (1-based) of the first ``<tag ... name="name"`` in ``text`` (0 when not found)."""
    if name is None:
        m = re.search(rf"<{tag}\b", text)
    else:
        m = re.search(rf"<{tag}\b[^>]*\bname\s*=\s*[\"']{re.escape(name)}[\"']", text)
    return text.count("\n", 0, m.start()) + 1 if m else 0


def _triple(s: str | None) -> bool:
    if s is None:
        return True   # urdfdom's default: zeros
    parts = s.split()
    try:
        return len(parts) == 3 and all(math.isfinite(float(t)) for t in parts)
    except ValueError:
        return False


def check_urdf_structure(root: ET.Element, text: str, path: Path | str) -> None:
    """Raise :class:`ModelError` ``"<file>:<line>: <element>: <what is wrong>"`` for the tree
    faults urdfdom reports only as an invalid model (see module docstring)."""
    links: dict[str, int] = {}
    for link in root.findall("link"):
        name = link.get("name")
        if not name:
            raise ModelError(f"{path}:{_line_of(text, 'link', None)}: <link> without a name attribute")
        if name in links:
            raise ModelError(f"{path}:{_line_of(text, 'link', name)}: link {name!r} is defined twice")
        links[name] = 1
    if not links:
        raise ModelError(f"{path}: the URDF defines no <link>; could not parse a robot from it")
    parent_of: dict[str, str] = {}
    children: dict[str, list[str]] = {}
    seen_joints: set[str] = set()
    for j in root.findall("joint"):
        jn = j.get("name")
        where = f"{path}:{_line_of(text, 'joint', jn)}: joint {jn!r}"
        if not jn:
            raise ModelError(f"{path}:{_line_of(text, 'joint', None)}: <joint> without a name attribute")
        if jn in seen_joints:
            raise ModelError(f"{where} is defined twice")
        seen_joints.add(jn)
        jt = j.get("type")
        if jt not in URDF_JOINT_TYPES:
            raise ModelError(f"{where}: type {jt!r} is not a URDF joint type; expected one of {', '.join(URDF_JOINT_TYPES)}")
        ends = {}
        for tag in ("parent", "child"):
            el = j.find(tag)
            ln = el.get("link") if el is not None else None
            if not ln:
                raise ModelError(f"{where}: missing <{tag} link=\"...\"/>")
            if ln not in links:
                raise ModelError(f"{where}: {tag} link {ln!r} is not defined in the file (define <link name=\"{ln}\"/> "
                                 f"or fix the name; links: {', '.join(sorted(links)[:20])})")
            ends[tag] = ln
        if ends["child"] in parent_of:
            raise ModelError(f"{where}: link {ends['child']!r} already has the parent joint to "
                             f"{parent_of[ends['child']]!r}; a link has at most one parent")
        if ends["child"] == ends["parent"]:
            raise ModelError(f"{where}: link {ends['child']!r} is its own parent")
        parent_of[ends["child"]] = ends["parent"]
        children.setdefault(ends["parent"], []).append(ends["child"])
        origin = j.find("origin")
        if origin is not None:
            for attr in ("xyz", "rpy"):
                if not _triple(origin.get(attr)):
                    raise ModelError(f"{where}: <origin {attr}={origin.get(attr)!r}>: expected 3 finite numbers")
    roots = [n for n in links if n not in parent_of]
    if len(roots) != 1:
        if not roots:
            raise ModelError(f"{path}: no root link: every link has a parent joint (a kinematic loop)")
        raise ModelError(f"{path}:{_line_of(text, 'link', roots[1])}: {len(roots)} root links "
                         f"({', '.join(repr(r) for r in roots[:10])}); a URDF robot is one tree: connect each "
                         "extra root to the tree by a joint")
    reached, stack = {roots[0]}, [roots[0]]
    while stack:
        for c in children.get(stack.pop(), []):
            if c not in reached:
                reached.add(c)
                stack.append(c)
    if len(reached) != len(links):
        loop = sorted(set(links) - reached)
        raise ModelError(f"{path}: links {loop[:10]} are not reachable from the root link {roots[0]!r} "
                         "(a kinematic loop)")
    for link in root.findall("link"):
        for tag in ("inertial", "visual", "collision"):
            for el in link.findall(tag):
                o = el.find("origin")
                if o is None:
                    continue
                for attr in ("xyz", "rpy"):
                    if not _triple(o.get(attr)):
                        raise ModelError(f"{path}:{_line_of(text, 'link', link.get('name'))}: link {link.get('name')!r}: "
                                         f"<{tag}><origin {attr}={o.get(attr)!r}>: expected 3 finite numbers")
