"""Two Franka Emika Panda arms on a common base plate, from the PyPI package
``example-robot-data`` (optional extra ``robots``): a robot optplan does not ship, loaded the way a
user would load theirs.

* **Kinematics**: the vendor's ``panda_collision.urdf`` twice, every link and joint prefixed
  ``left_`` / ``right_``, the arms' ``panda_link0`` fixed to a 0.5 × 1.1 × 0.05 m plate at
  y = ±:data:`BASE_OFFSET` (both facing +x, so their workspaces overlap in front of the plate).
  The fingers are frozen (made ``fixed``, open); 14 planning joints, arms ``"left"`` and
  ``"right"``, end-effector frames ``{left,right}_panda_hand_tcp`` (z along the gripper).
* **Collision geometry**: the vendor models every link as a ``<cylinder>`` with a ``<sphere>`` of
  the same radius at each end of its axis — exactly a capsule. :func:`merge_capsules` replaces
  each such triple by one capsule (named ``*_capsule``, which :class:`~optplan.model.robot.RobotModel`
  turns into a coal capsule), so every link is a shape the trajectory NLP handles exactly; a
  cylinder or sphere that is not part of such a triple stays what it is (the NLP bounds a
  cylinder by the capsule of its axis and radius). The plate is a box.
* **Collision-pair budget** (:func:`pair_budget`): all geometry pairs, minus pairs fewer than
  three joints apart (:meth:`RobotModel._default_collision_pairs`), minus the pairs of one arm the
  vendor's SRDF disables (``disable_collisions``: adjacent, in contact by default, or never in
  collision — computed by the MoveIt Setup Assistant by sampling the vendor's meshes), except those
  that random configurations bring into contact with the capsules (checked at load, 2,000
  samples); pairs between the two arms are kept. The trajectory NLP then constrains only the pairs that come within its activation
  distance along a segment's initial guess; ``verify`` checks every pair of the budget.
"""
from __future__ import annotations

import logging
import math
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..errors import ModelError
from ._robot_data import _require_dir
from .robot import RobotModel
from .robot_file import _prefixed as _prefix_tree  # one URDF tree-prefixing step
from .robot_file import freeze_prismatic, merge_capsules  # the general steps, re-exported here

__all__ = ["load_dual_panda", "merge_capsules", "pair_budget", "srdf_disabled_pairs", "BASE_OFFSET",
           "DUAL_PANDA_ARMS"]
log = logging.getLogger(__name__)

#: [m] distance of each arm's base from the plate's centre line (y = ±BASE_OFFSET)
BASE_OFFSET = 0.35
#: the plate: full edges [m] and the z of its centre [m] (its top face is z = 0, where the arms stand)
PLATE_SIZE = (0.5, 1.1, 0.05)
FINGER_OPENING = 0.04  # [m] per finger (fully open)
SIDES = ("left", "right")
DUAL_PANDA_ARMS = {s: [f"{s}_panda_joint{k}" for k in range(1, 8)] for s in SIDES}


def dual_panda_urdf(share: Path) -> str:
    """The URDF text of the dual-Panda robot (module docstring), meshes by absolute path."""
    src = share / "robots/panda_description/urdf/panda_collision.urdf"
    if not src.exists():
        raise ModelError(f"{src} is missing from the example-robot-data installation")
    arm = ET.parse(src).getroot()
    robot = ET.Element("robot", {"name": "dual_panda"})
    plate = ET.SubElement(robot, "link", {"name": "base_plate"})
    col = ET.SubElement(plate, "collision", {"name": "base_plate_box"})
    ET.SubElement(col, "origin", {"xyz": f"0 0 {-PLATE_SIZE[2] / 2!r}", "rpy": "0 0 0"})
    ET.SubElement(ET.SubElement(col, "geometry"), "box", {"size": " ".join(repr(float(v)) for v in PLATE_SIZE)})
    inert = ET.SubElement(plate, "inertial")
    ET.SubElement(inert, "mass", {"value": "10"})
    ET.SubElement(inert, "inertia", {k: v for k, v in zip(("ixx", "ixy", "ixz", "iyy", "iyz", "izz"),
                                                           ("1", "0", "0", "1", "0", "1"))})
    for side, y in zip(SIDES, (BASE_OFFSET, -BASE_OFFSET)):
        for e in _prefix_tree(arm, f"{side}_"):
            freeze_prismatic(e, FINGER_OPENING)  # the fingers: frozen, open
            if e.tag == "link":
                merge_capsules(e)
            robot.append(e)
        j = ET.SubElement(robot, "joint", {"name": f"{side}_mount", "type": "fixed"})
        ET.SubElement(j, "parent", {"link": "base_plate"})
        ET.SubElement(j, "child", {"link": f"{side}_panda_link0"})
        ET.SubElement(j, "origin", {"xyz": f"0 {y!r} 0", "rpy": "0 0 0"})
    for m in robot.iter("mesh"):
        fn = m.get("filename", "")
        if fn.startswith("package://example-robot-data/"):
            m.set("filename", str(share / fn[len("package://example-robot-data/"):]))
    return ET.tostring(robot, encoding="unicode")


def srdf_disabled_pairs(share: Path) -> set[frozenset]:
    """Link pairs of one Panda that the vendor's SRDF disables (``disable_collisions``)."""
    path = share / "robots/panda_description/srdf/panda.srdf"
    if not path.exists():
        raise ModelError(f"{path} is missing from the example-robot-data installation")
    root = ET.parse(path).getroot()
    return {frozenset((d.get("link1"), d.get("link2"))) for d in root.iter("disable_collisions")}


def _link_of(robot: RobotModel, g: int) -> str:
    o = robot.collision_model.geometryObjects[g]
    return robot.model.frames[o.parentFrame].name


def pair_budget(robot: RobotModel, disabled: set[frozenset], samples: int = 2000, seed: int = 0) -> dict:
    """Filter ``robot``'s self-collision pairs by the SRDF's per-arm ``disabled`` link pairs (in
    place: ``robot.collision_pairs`` and its coal collision data), except pairs that ``samples``
    random configurations (``seed``) bring into contact with *this* geometry: the SRDF was
    computed on the vendor's meshes, and the capsules are fatter (see
    docs/decisions/0011-paper-reproduction-grids-and-guards.md). Returns the counts of each
    stage (``geometries``, ``all_pairs``, ``joint_distance`` — after the three-joint rule and the
    neutral-contact rule —, ``srdf_disabled``, ``restored``: disabled by the SRDF but found in
    contact, ``kept``) and ``restored_pairs`` (geometry names)."""
    n_geom = len(robot.collision_model.geometryObjects)
    before = list(robot.collision_pairs)
    keep, off = [], []
    for a, b in before:
        la, lb = _link_of(robot, a), _link_of(robot, b)
        sa, sb = la.split("_", 1), lb.split("_", 1)
        if sa[0] == sb[0] and sa[0] in SIDES and frozenset((sa[1], sb[1])) in disabled:
            off.append((a, b))
            continue
        keep.append((a, b))
    # the arms are identical: sample the left arm's disabled pairs, apply the verdict to both
    names = [o.name for o in robot.collision_model.geometryObjects]
    left = [(a, b) for a, b in off if names[a].startswith("left_")]
    d = sampled_min_distances(robot, left, samples, seed) if left else np.zeros(0)
    touching = {(names[a].split("_", 1)[1], names[b].split("_", 1)[1]) for (a, b), x in zip(left, d) if x <= 0.0}
    restored = [(a, b) for a, b in off if (names[a].split("_", 1)[1], names[b].split("_", 1)[1]) in touching]
    keep = sorted(keep + restored)
    robot.collision_pairs = keep
    robot.collision_model.removeAllCollisionPairs()
    for a, b in keep:
        robot.collision_model.addCollisionPair(pin.CollisionPair(a, b))
    robot.collision_data = pin.GeometryData(robot.collision_model)
    return {"geometries": n_geom, "all_pairs": n_geom * (n_geom - 1) // 2, "joint_distance": len(before),
            "srdf_disabled": len(off), "restored": len(restored), "kept": len(keep),
            "restored_pairs": [(names[a], names[b]) for a, b in restored]}


def load_dual_panda() -> RobotModel:
    """The dual-Panda robot of the module docstring (needs ``example-robot-data``). Its pair
    budget is in ``robot.pair_budget`` (:func:`pair_budget`)."""
    share = _require_dir()
    text = dual_panda_urdf(share)
    cache = Path(tempfile.gettempdir()) / "optplan_example_robots"
    cache.mkdir(exist_ok=True)
    path = cache / "dual_panda.urdf"
    if not path.exists() or path.read_text() != text:
        from .._io import write_text

        write_text(path, text)   # atomic: a concurrent process never reads half a URDF
    arms = {s: {"ee": f"{s}_panda_hand_tcp", "joints": DUAL_PANDA_ARMS[s]} for s in SIDES}
    robot = RobotModel.from_urdf(path, arms=arms, name="dual_panda")
    robot.pair_budget = pair_budget(robot, srdf_disabled_pairs(share))
    if robot.nj != 14:
        raise ModelError(f"dual_panda: expected 14 joints, got {robot.nj} ({robot.joint_names})")
    log.info("dual_panda: %s", robot.pair_budget)
    return robot


def sampled_min_distances(robot: RobotModel, pairs, n: int, seed: int) -> np.ndarray:
    """Smallest exact (coal) distance [m] of each geometry pair ``(a, b)`` over ``n`` configurations
    drawn uniformly in the joint limits (``numpy.random.default_rng(seed)``): an independent check
    of pairs a budget leaves out."""
    from .robot import _geom_distance

    rng = np.random.default_rng(seed)
    gd = pin.GeometryData(robot.collision_model)
    data = robot.model.createData()
    out = np.full(len(pairs), math.inf)
    for _ in range(int(n)):
        q = rng.uniform(robot.lower, robot.upper)
        pin.updateGeometryPlacements(robot.model, data, robot.collision_model, gd, q)
        for i, (a, b) in enumerate(pairs):
            out[i] = min(out[i], _geom_distance(robot.collision_model, gd, a, b))
    return out
