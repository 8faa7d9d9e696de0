"""A URDF's collision meshes as boxes: each ``<collision>`` mesh becomes the axis-aligned bounding
box of its vertices in the mesh frame (scale applied), placed by the collision's own origin.

The NLP's collision rows (:class:`~optplan.problem.CollisionAvoidance`) model boxes, capsules and
spheres, not triangle meshes; a robot whose URDF has only meshes (e.g. a UR5 of
example-robot-data) gets a conservative box model this way. The box encloses the mesh, so a
clearance certified for the boxes holds for the meshes. For tighter fits use a robot file with
``collision: primitives`` (certified capsules, :mod:`.primitive_fit`)."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..errors import ModelError
from .robot_file import _cached_urdf, _origin, _parse, resolve_uri

__all__ = ["collision_meshes_as_boxes"]


def _mesh_aabb(path: Path, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import coal

    try:
        bvh = coal.MeshLoader().load(str(path), scale)
    except Exception as exc:   # coal raises plain RuntimeError/ValueError for unreadable files
        raise ModelError(f"collision mesh {str(path)!r} cannot be loaded: {exc}") from None
    bvh.computeLocalAABB()
    return np.array(bvh.aabb_local.min_, float), np.array(bvh.aabb_local.max_, float)


def collision_meshes_as_boxes(path: str | Path, package_dirs: Sequence[str | Path] = (),
                              keep_visual: bool = False) -> Path:
    """A copy of the URDF at ``path`` with every collision mesh replaced by its bounding box.

    ``package_dirs``: where ``package://`` names are looked up first
    (:func:`~.robot_file.package_search_dirs`). Visual elements are dropped unless
    ``keep_visual`` (they are not loaded for planning). Returns the path of the new URDF, cached
    by content in the temporary directory; load it with
    :meth:`~optplan.model.robot.RobotModel.from_urdf`."""
    path = Path(path)
    if not path.is_file():
        raise ModelError(f"URDF file {str(path)!r} does not exist; expected a .urdf file")
    root = _parse(path)
    n = 0
    for link in root.iter("link"):
        if not keep_visual:
            for vis in list(link.findall("visual")):
                link.remove(vis)
        for col in link.findall("collision"):
            geom = col.find("geometry")
            mesh = None if geom is None else geom.find("mesh")
            if geom is None or mesh is None:
                continue
            fn = mesh.get("filename") or ""
            file = resolve_uri(fn, path.parent, package_dirs)
            if not file.exists():
                raise ModelError(f"collision mesh {fn!r}: {file} does not exist")
            scale = np.array([float(v) for v in (mesh.get("scale") or "1 1 1").split()], float)
            if scale.size == 1:
                scale = np.repeat(scale, 3)
            lo, hi = _mesh_aabb(file, scale)
            M = _origin(col) * pin.SE3(np.eye(3), (lo + hi) / 2)
            for o in col.findall("origin"):
                col.remove(o)
            rpy = pin.rpy.matrixToRpy(M.rotation)
            origin = ET.Element("origin", xyz=" ".join(f"{v:.9g}" for v in M.translation),
                                rpy=" ".join(f"{v:.9g}" for v in rpy))
            col.insert(0, origin)
            geom.remove(mesh)
            ET.SubElement(geom, "box", size=" ".join(f"{v:.9g}" for v in np.maximum(hi - lo, 1e-6)))
            n += 1
    return _cached_urdf(ET.tostring(root, encoding="unicode"), f"{path.stem}_boxes{n}")
