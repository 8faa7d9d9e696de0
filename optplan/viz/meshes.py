"""Mesh files prepared for the browser views."""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["stl_with_normals"]


def stl_with_normals(path: str | Path) -> Path:
    """``path`` itself, or a copy of the STL file with its facet normals computed from the vertices
    when the file's are zero (CAD exports, e.g. the UR5 meshes of example-robot-data, write 0 0 0):
    three.js lights a face by its normal, so a mesh without normals renders black whatever its
    material colour. Copies go to ``<tmp>/optplan_viz_meshes/`` (named by the content's hash)."""
    import hashlib
    import re
    import struct
    import tempfile

    p = Path(path)
    raw = p.read_bytes()
    tri = None
    if len(raw) >= 84:
        n = struct.unpack("<I", raw[80:84])[0]
        if 84 + 50 * n == len(raw):   # binary STL
            rec = np.frombuffer(raw, dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]),
                                count=n, offset=84)
            if n == 0 or np.all(np.linalg.norm(rec["n"], axis=1) > 1e-6):
                return p
            tri = rec["v"].astype(float)
    if tri is None:   # ASCII STL
        text = raw.decode("ascii", "replace")
        normals = re.findall(r"facet\s+normal\s+(\S+)\s+(\S+)\s+(\S+)", text)
        try:
            if not normals or all(abs(float(x)) + abs(float(y)) + abs(float(z)) > 1e-6 for x, y, z in normals):
                return p
            v = np.array(re.findall(r"vertex\s+(\S+)\s+(\S+)\s+(\S+)", text), float)
        except ValueError:
            return p   # not an STL we can read: three.js gets the file as it is
        if v.size == 0 or len(v) % 3:
            return p
        tri = v.reshape(-1, 3, 3)
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    out = np.zeros(len(tri), dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    out["n"], out["v"] = nrm, tri
    blob = b"optplan: facet normals computed from the vertices".ljust(80, b" ") + struct.pack("<I", len(tri)) \
        + out.tobytes()
    d = Path(tempfile.gettempdir()) / "optplan_viz_meshes"
    d.mkdir(exist_ok=True)
    q = d / f"{hashlib.sha1(blob).hexdigest()[:20]}.stl"
    if not q.exists():
        tmp = q.with_suffix(f".{id(blob)}.tmp")
        tmp.write_bytes(blob)
        tmp.replace(q)
    return q
