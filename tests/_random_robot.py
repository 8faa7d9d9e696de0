"""Random two-arm test robots: every link carries a random collision shape (sphere, capsule, box,
cylinder, convex mesh), written as a URDF (and STL meshes) in a directory. Shared by the geometry
tests; randomness only through the given numpy Generator."""
from __future__ import annotations

from pathlib import Path

import numpy as np

SHAPES = ("sphere", "capsule", "box", "cylinder", "mesh")


def write_stl(path: Path, V: np.ndarray) -> None:
    """ASCII STL of the convex hull of the points V (n × 3) [m]."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(V)
    c = V.mean(axis=0)
    lines = ["solid hull"]
    for s in hull.simplices:
        a, b, d = V[s]
        n = np.cross(b - a, d - a)
        if n @ (a - c) < 0:   # outward
            b, d, n = d, b, -n
        n = n / np.linalg.norm(n)
        lines += [f"facet normal {n[0]:.9g} {n[1]:.9g} {n[2]:.9g}", "outer loop"]
        lines += [f"vertex {p[0]:.9g} {p[1]:.9g} {p[2]:.9g}" for p in (a, b, d)]
        lines += ["endloop", "endfacet"]
    lines.append("endsolid hull")
    path.write_text("\n".join(lines) + "\n")


def _geometry(kind: str, rng: np.random.Generator, L: float, out: Path, tag: str) -> tuple[str, str, str]:
    """(collision name suffix, <geometry> inner XML, origin xyz) of one link's shape along its +z."""
    r = float(rng.uniform(0.03, 0.06))
    mid = f"0 0 {L / 2:.6f}"
    if kind == "sphere":
        return "", f'<sphere radius="{r:.6f}"/>', f"0 0 {L:.6f}"
    if kind == "capsule":
        return "_capsule", f'<cylinder radius="{r:.6f}" length="{0.7 * L:.6f}"/>', mid
    if kind == "cylinder":
        return "", f'<cylinder radius="{r:.6f}" length="{0.7 * L:.6f}"/>', mid
    if kind == "box":
        return "", f'<box size="{2 * r:.6f} {1.5 * r:.6f} {0.8 * L:.6f}"/>', mid
    V = rng.normal(size=(24, 3)) * np.array([r, r, 0.3 * L]) + np.array([0, 0, L / 2])
    p = out / f"{tag}.stl"
    write_stl(p, V)
    return "", f'<mesh filename="{p}"/>', "0 0 0"


def random_dual_arm_urdf(rng: np.random.Generator, out: Path, n_joints: int = 3,
                         kinds: tuple[str, ...] = SHAPES) -> Path:
    """A fixed-base robot ``rand``: arms ``A`` (y = +0.3 m) and ``B`` (y = −0.3 m) of ``n_joints``
    revolute joints (z, y, y, ...), 0.25 m links, each link a random shape of ``kinds``; EE frames
    ``A_ee``, ``B_ee``."""
    out.mkdir(parents=True, exist_ok=True)
    inert = ('<inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" '
             'izz="0.01"/></inertial>')
    parts = ['<robot name="rand">', f'<link name="base">{inert}</link>']
    for arm, y in (("A", 0.3), ("B", -0.3)):
        parent = "base"
        for k in range(n_joints):
            L = 0.25
            link = f"{arm}_link{k + 1}"
            kind = kinds[int(rng.integers(len(kinds)))]
            suffix, geo, xyz = _geometry(kind, rng, L, out, link)
            parts.append(f'<link name="{link}">{inert}<collision name="{link}_0{suffix}"><origin xyz="{xyz}" rpy="0 0 0"/>'
                         f"<geometry>{geo}</geometry></collision></link>")
            origin = f"0 {y} 0.1" if k == 0 else f"0 0 {L}"
            axis = "0 0 1" if k == 0 else "0 1 0"
            parts.append(f'<joint name="{arm}_j{k + 1}" type="revolute"><parent link="{parent}"/><child link="{link}"/>'
                         f'<origin xyz="{origin}" rpy="0 0 0"/><axis xyz="{axis}"/>'
                         '<limit lower="-2.5" upper="2.5" velocity="2" effort="10"/></joint>')
            parent = link
        parts.append(f'<link name="{arm}_tool">{inert}</link>')
        parts.append(f'<joint name="{arm}_ee_joint" type="fixed"><parent link="{parent}"/><child link="{arm}_tool"/>'
                     f'<origin xyz="0 0 {0.25}" rpy="0 0 0"/></joint>')
    parts.append("</robot>")
    path = out / "rand.urdf"
    path.write_text("\n".join(parts))
    return path
