"""MotionBenchMaker's Panda problems (Chamzas et al., RA-L 2022) as optplan scenes and queries.

VAMP ships them for its own benchmark (``resources/panda/problems.tar.bz2`` of its source: seven
scenarios — ``bookshelf_small``, ``bookshelf_tall``, ``bookshelf_thin``, ``box``, ``cage``,
``table_pick``, ``table_under_pick`` — of 100 problems each, MoveIt scene and request YAML files). A
problem here is one scene (boxes, spheres and cylinders) with one start and one goal of the Panda's seven
arm joints [rad]. The obstacles are mapped as VAMP maps them for its planners (``vamp.problem_dict_to_vamp``),
so that both planners see the same world: a cylinder becomes the capsule around it (its segment the
cylinder's axis, its radius the cylinder's), except in the ``box`` scenario, where it becomes the box
around it (VAMP: the problem needs a top-down grasp that the capsule's caps would block).

Needs PyYAML (``pip install pyyaml``; the ``docs`` extra brings it). Nothing here is used by the planners.
"""
from __future__ import annotations

import re
import tarfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..scene import Obstacle, Scene

__all__ = ["MBM_SCENARIOS", "MBMProblem", "load_mbm", "mbm_scene"]

#: the Panda scenarios of MotionBenchMaker, in the archive's order of names
MBM_SCENARIOS = ("bookshelf_small", "bookshelf_tall", "bookshelf_thin", "box", "cage", "table_pick",
                 "table_under_pick")
#: the arm joints of a request, in the planners' order
PANDA_JOINTS = tuple(f"panda_joint{k}" for k in range(1, 8))


@dataclass(frozen=True)
class MBMProblem:
    """One MotionBenchMaker problem: ``scenario`` (one of :data:`MBM_SCENARIOS`), ``index`` (1-100, the
    archive's file number), the mapped ``scene`` and the ``start`` and ``goal`` arm configurations [rad]."""

    scenario: str
    index: int
    scene: Scene
    start: np.ndarray
    goal: np.ndarray

    @property
    def key(self) -> str:
        return f"{self.scenario}_{self.index:04d}"


def _pose(d: dict[str, Any]) -> pin.SE3:
    """A MoveIt pose (``position``; ``orientation`` as x, y, z, w) as an SE3."""
    x, y, z, w = (float(v) for v in d["orientation"])
    q = pin.Quaternion(w, x, y, z)
    q.normalize()
    return pin.SE3(q.toRotationMatrix(), np.asarray(d["position"], dtype=float))


def mbm_scene(scene_yaml: dict[str, Any], scenario: str, name: str = "mbm") -> Scene:
    """The collision objects of a MoveIt planning-scene document as a :class:`~optplan.scene.Scene`
    (module docstring: cylinders as capsules, or as boxes in the ``box`` scenario). An object's pose, where
    given, is composed with its primitive's pose, as VAMP's loader does; one primitive per object."""
    obstacles = []
    for co in scene_yaml["world"]["collision_objects"]:
        base = _pose(co["pose"]) if "pose" in co else pin.SE3.Identity()
        prims, poses = co.get("primitives", []), co.get("primitive_poses", [])
        if len(prims) != 1 or len(poses) != 1:
            raise ValueError(f"mbm_scene: object {co.get('id')!r} has {len(prims)} primitives; one is expected")
        M = base * _pose(poses[0])
        kind, dims = prims[0]["type"], [float(v) for v in prims[0]["dimensions"]]
        oid = str(co["id"])
        if kind == "box":
            obstacles.append(Obstacle(oid, "box", M, size=(dims[0], dims[1], dims[2])))
        elif kind == "sphere":
            obstacles.append(Obstacle(oid, "sphere", M, radius=dims[0]))
        elif kind == "cylinder":   # MoveIt: dimensions = (height, radius)
            length, radius = dims[0], dims[1]
            if scenario == "box":
                obstacles.append(Obstacle(oid, "box", M, size=(2 * radius, 2 * radius, length)))
            else:
                obstacles.append(Obstacle(oid, "capsule", M, radius=radius, length=length))
        else:
            raise ValueError(f"mbm_scene: object {oid!r} is a {kind!r}; box, sphere and cylinder are mapped")
    return Scene(name=name, robot=None, obstacles=tuple(obstacles))


def _request(req: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    js = req["start_state"]["joint_state"]
    names, pos = list(js["name"]), list(js["position"])
    start = np.array([float(pos[names.index(j)]) for j in PANDA_JOINTS])
    gc = {c["joint_name"]: float(c["position"]) for c in req["goal_constraints"][0]["joint_constraints"]}
    goal = np.array([gc[j] for j in PANDA_JOINTS])
    return start, goal


def load_mbm(path: str | Path, scenarios: tuple[str, ...] | list[str] | None = None,
             per_scenario: int | None = None) -> list[MBMProblem]:
    """The problems of VAMP's ``problems.tar.bz2`` (or of a directory it was unpacked into, holding
    ``problems/<scenario>_panda/``): the first ``per_scenario`` (all: None) of each of ``scenarios`` (all:
    None), in index order."""
    try:
        import yaml
    except ImportError as e:   # pragma: no cover - depends on the environment
        raise ImportError("load_mbm needs PyYAML (pip install pyyaml)") from e
    chosen = tuple(MBM_SCENARIOS if scenarios is None else scenarios)
    for s in chosen:
        if s not in MBM_SCENARIOS:
            raise ValueError(f"load_mbm: unknown scenario {s!r}; expected one of {', '.join(MBM_SCENARIOS)}")
    if per_scenario is not None and (isinstance(per_scenario, bool) or not isinstance(per_scenario, int)
                                     or per_scenario < 1):
        raise ValueError(f"load_mbm: per_scenario must be a positive int or None, got {per_scenario!r}")
    p = Path(path)
    texts: dict[str, bytes] = {}
    pat = re.compile(r"(?:^|/)problems/([a-z_]+)_panda/(scene|request)(\d{4})\.yaml$")
    if p.is_dir():
        for f in p.rglob("*.yaml"):
            if pat.search(f.as_posix()):
                texts[f.as_posix()] = f.read_bytes()
    elif p.is_file():
        with tarfile.open(p) as tar:
            for member in tar.getmembers():
                if member.isfile() and pat.search(member.name):
                    fh = tar.extractfile(member)
                    if fh is not None:
                        texts[member.name] = fh.read()
    else:
        raise FileNotFoundError(f"load_mbm: {p} is neither VAMP's problems.tar.bz2 nor a directory")
    files: dict[tuple[str, int], dict[str, bytes]] = {}
    for name, data in texts.items():
        hit = pat.search(name)
        assert hit is not None
        files.setdefault((hit.group(1), int(hit.group(3))), {})[hit.group(2)] = data
    out = []
    for s in chosen:
        idx = sorted(i for (sc, i), d in files.items() if sc == s and len(d) == 2)
        if not idx:
            raise ValueError(f"load_mbm: no problems of {s!r} in {p}")
        for i in idx[:per_scenario]:
            d = files[(s, i)]
            scene = mbm_scene(yaml.safe_load(d["scene"]), s, name=f"mbm_{s}_{i:04d}")
            start, goal = _request(yaml.safe_load(d["request"]))
            out.append(MBMProblem(s, i, scene, start, goal))
    return out
