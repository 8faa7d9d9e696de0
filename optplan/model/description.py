"""Robot descriptions: ``models/robots/*.toml`` (D-H tables, mounting, inertias, limits,
collision capsules) and the URDF generator behind ``optplan models build``.

TOML schema (all lengths [m], masses [kg], inertias [kg m²] about the link CoM in D-H frame axes;
angles in the unit named by ``angle_unit``, "deg" or "rad")::

    name = "my_robot"
    base_type = "floating"          # "floating" (free-flyer added on load) or "fixed"
    angle_unit = "deg"

    [base]
    link = "base"
    mass = 510.0
    com = [0, 0, 0]
    inertia = [Ixx, Ixy, Ixz, Iyy, Iyz, Izz]
    boxes = [{ size = [1.2, 1.0, 1.6], xyz = [0, 0, 0], rpy = [0, 0, 0] }]   # collision

    [arm_types.my_arm]
    dh_convention = "modified"      # "modified" (Craig) or "standard" (distal)
    # one row per joint: [theta_offset, alpha, a, d]; joint angle = variable + theta_offset.
    # modified: T_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i) (row i holds alpha_{i-1}, a_{i-1})
    # standard: T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)
    dh = [[0, 0, 0, 0.225], ...]
    masses = [...]; coms = [[x, y, z], ...]; inertias = [[Ixx, Ixy, Ixz, Iyy, Iyz, Izz], ...]
    lower = [...]; upper = [...]    # joint limits (angle_unit)
    velocity = [...]                # joint speed limits (angle_unit per second)
    effort = [...]                  # optional [N m]
    capsules = [{ link = 3, a = [0, 0, 0], b = [0.56, 0, 0], radius = 0.06 }, ...]  # in D-H frame `link`
    tool = { xyz = [0, 0, 0], rpy = [0, 0, 0] }   # end-effector frame in the last D-H frame

    [[arms]]
    name = "A"                      # arm group name
    type = "my_arm"
    prefix = "a"                    # joint names a_joint1..; links a_link1..; EE frame a_ee
    mount_xyz = [0.3, 0.51, 0.83]   # arm base frame (D-H frame 0) in the base link
    mount_zyx = [90, 26, 0]         # Rz(a) Ry(b) Rx(c)   (or mount_rpy = [roll, pitch, yaw])

Serpentine (segmented, cable-driven) arm types — ``kind = "serpentine"``::

    [arm_types.my_snake]
    kind = "serpentine"
    segments = 5                    # n_b segments
    joints_per_segment = 6          # m universal joints per segment (even)
    link_length = 0.15              # L_b: every rigid link, joint centre to joint centre [m]
    link_mass = 0.8                 # per rigid link [kg] (slender rod about its CoM)
    capsule_radius = 0.035          # collision capsule along every link [m]
    lower = -20.0; upper = 20.0     # limits of every joint axis (angle_unit)
    velocity = 10.0                 # speed limit of every joint axis (angle_unit per second)
    effort = 50.0                   # optional [N m]
    tool = { xyz = [0, 0, 0], rpy = [0, 0, 0] }   # end-effector frame in the last link frame

  Universal joint j of segment i is two revolute joints with intersecting axes,
  ``<prefix>_joint<i>_<j>_1`` then ``<prefix>_joint<i>_<j>_2``: pitch (link y) then yaw (link z)
  for odd j, yaw then pitch for even j (the pitch-yaw-yaw-pitch layout), followed by a rigid link
  ``<prefix>_link<i>_<j>`` of length L_b along its x axis (the next joint sits at its end, the
  end-effector ``<prefix>_ee`` at the end of the last link). Within a segment every joint copies
  the first one (the DSHDASR paper, Eq. 1: ``θ_{i,j,1} = θ_{i,j+1,2}``, ``θ_{i,j,2} = θ_{i,j+1,1}``, i.e. all
  pitches equal and all yaws equal): ``<prefix>_joint<i>_1_1`` (pitch) and ``<prefix>_joint<i>_1_2``
  (yaw) are actuated, the others are URDF ``<mimic>`` joints (multiplier 1, offset 0), so the arm
  has 2·segments degrees of freedom. The arm frame (``mount_*``) has its x axis along the
  unbent arm. With this layout each pitch-yaw/yaw-pitch pair is a pure rotation about an axis
  normal to the incoming link, so a segment bends in one plane and its links are tangent to a
  circular arc (the space-arc model of :mod:`optplan.papers.dshdasr.arcs`).

Link and collision frames: the URDF link ``<prefix>_link<i>`` is the frame that joint ``i`` rotates
about its z axis. In the modified convention it *is* D-H frame i; in the standard convention D-H
frame i is ``<prefix>_link<i> · Tz(d_i) Tx(a_i) Rx(alpha_i)``. CoMs, inertias and capsules are given
in D-H frame i and converted by the generator. Capsules are written to the URDF as ``<cylinder>``
collision elements whose ``name`` ends in ``_capsule`` (URDF has no capsule); :mod:`optplan.model.robot`
turns them back into exact ``coal.Capsule`` objects, plain URDF loaders see cylinders.
"""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ModelError, UnknownNameError
from ..geometry.spatial import rotx, rotz, rpy_to_matrix, zyx_to_matrix

__all__ = [
    "ArmType", "SerpentineArmType", "ArmMount", "RobotDescription", "load_description",
    "repo_root", "models_dir", "urdf_dir", "available_models",
]


def repo_root() -> Path:
    """Root of the optplan checkout (``models/`` and ``urdf/`` live there).

    Override with the environment variable ``OPTPLAN_ROOT``.
    """
    import os

    env = os.environ.get("OPTPLAN_ROOT")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2]


def models_dir() -> Path:
    return repo_root() / "models"


def urdf_dir() -> Path:
    return repo_root() / "urdf"


def available_models() -> list[str]:
    """Names of the robot descriptions in ``models/robots``."""
    return sorted(p.stem for p in (models_dir() / "robots").glob("*.toml"))


# --------------------------------------------------------------------------- data classes
@dataclass(frozen=True)
class ArmType:
    """A serial arm given by a D-H table (angles in rad after loading)."""

    name: str
    convention: str
    dh: np.ndarray  # (n, 4): theta_offset, alpha, a, d
    masses: np.ndarray
    coms: np.ndarray  # (n, 3) in D-H frame i
    inertias: np.ndarray  # (n, 6)
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    capsules: tuple[dict, ...]
    tool_xyz: np.ndarray
    tool_rpy: np.ndarray

    @property
    def n(self) -> int:
        return self.dh.shape[0]

    def link_to_dh(self, i: int) -> np.ndarray:
        """4×4 transform from URDF link ``i`` (1-based) to D-H frame i."""
        if self.convention == "modified":
            return np.eye(4)
        _, alpha, a, d = self.dh[i - 1]
        return _tz(d) @ _tx(a) @ _hrot(rotx(alpha))

    def joint_origin(self, i: int) -> np.ndarray:
        """4×4 transform from URDF link ``i-1`` (D-H frame 0 for i = 1) to the joint-``i`` frame
        at zero joint variable (offset included)."""
        off, alpha, a, d = self.dh[i - 1]
        if self.convention == "modified":
            return _hrot(rotx(alpha)) @ _tx(a) @ _tz(d) @ _hrot(rotz(off))
        prev = np.eye(4) if i == 1 else self.link_to_dh(i - 1)
        return prev @ _hrot(rotz(off))


@dataclass(frozen=True)
class SerpentineArmType:
    """A segmented serpentine arm of coupled universal joints (see the module doc; angles in rad)."""

    name: str
    segments: int
    joints_per_segment: int
    link_length: float
    link_mass: float
    capsule_radius: float
    lower: float
    upper: float
    velocity: float
    effort: float
    tool_xyz: np.ndarray
    tool_rpy: np.ndarray
    kind: str = "serpentine"

    @property
    def n(self) -> int:
        """Actuated joints (2 per segment)."""
        return 2 * self.segments

    @property
    def n_links(self) -> int:
        return self.segments * self.joints_per_segment

    @property
    def masses(self) -> np.ndarray:
        return np.full(self.n_links, self.link_mass)

    def axes(self, j: int) -> tuple[str, str]:
        """Axes (``"pitch"``/``"yaw"``) of the two revolute joints of universal joint j (1-based)."""
        return ("pitch", "yaw") if j % 2 == 1 else ("yaw", "pitch")

    def joint_names(self, prefix: str) -> list[str]:
        """The actuated joints, segment by segment: pitch then yaw of each segment's first joint."""
        return [f"{prefix}_joint{i}_1_{k}" for i in range(1, self.segments + 1) for k in (1, 2)]


@dataclass(frozen=True)
class ArmMount:
    name: str
    type: str
    prefix: str
    xyz: np.ndarray
    R: np.ndarray


@dataclass(frozen=True)
class RobotDescription:
    """A parsed ``models/robots/*.toml``."""

    name: str
    base_type: str
    base_link: str
    base_mass: float
    base_com: np.ndarray
    base_inertia: np.ndarray
    base_boxes: tuple[dict, ...]
    arm_types: dict[str, ArmType | SerpentineArmType]
    arms: tuple[ArmMount, ...]
    source: Path | None = None
    notes: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def total_mass(self) -> float:
        return float(self.base_mass + sum(self.arm_types[a.type].masses.sum() for a in self.arms))


# --------------------------------------------------------------------------- parsing helpers
def _tx(a):
    T = np.eye(4)
    T[0, 3] = a
    return T


def _tz(d):
    T = np.eye(4)
    T[2, 3] = d
    return T


def _hrot(R):
    T = np.eye(4)
    T[:3, :3] = R
    return T


def _get(d: dict, key: str, where: str, types=None):
    if not isinstance(d, dict):
        raise ModelError(f"{where}: expected a table (key = value pairs), got {type(d).__name__} {d!r}")
    if key not in d:
        raise ModelError(f"{where}: missing key {key!r} (present keys: {sorted(d)})")
    v = d[key]
    if types is not None and not isinstance(v, types):
        raise ModelError(f"{where}.{key}: expected {types}, got {type(v).__name__} {v!r}")
    return v


def _array(v, shape, where: str) -> np.ndarray:
    from ..errors import real_array

    arr = real_array(v, f"{where}: expected numbers of shape {shape}", ModelError)
    if shape is not None and arr.shape != tuple(shape):
        raise ModelError(f"{where}: expected shape {tuple(shape)}, got {arr.shape} ({v!r})")
    if not np.all(np.isfinite(arr)):
        raise ModelError(f"{where}: non-finite values in {v!r}")
    return arr


def _known_keys(d: dict, allowed: tuple[str, ...], where: str) -> None:
    """Refuse keys (tables) the schema does not have: a typo must not silently drop data."""
    import difflib

    if not isinstance(d, dict):
        raise ModelError(f"{where}: expected a table (key = value pairs), got {type(d).__name__} {d!r}")
    for k in d:
        if k not in allowed:
            close = difflib.get_close_matches(str(k), allowed, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ModelError(f"{where}: unknown key {k!r}{hint}; expected keys: {', '.join(allowed)}")


def _positive(v, where: str, unit: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
        raise ModelError(f"{where}: expected a finite number > 0 {unit}, got {v!r}")
    return float(v)


_TOP_KEYS = ("name", "base_type", "angle_unit", "base", "arm_types", "arms", "notes", "extra")
_BASE_KEYS = ("link", "mass", "com", "inertia", "boxes")
_BOX_KEYS = ("size", "xyz", "rpy")
_DH_KEYS = ("kind", "dh_convention", "dh", "masses", "coms", "inertias", "lower", "upper", "velocity", "effort",
            "capsules", "tool")
_SERPENTINE_KEYS = ("kind", "segments", "joints_per_segment", "link_length", "link_mass", "capsule_radius",
                    "lower", "upper", "velocity", "effort", "tool")
_CAPSULE_KEYS = ("link", "a", "b", "radius")
_TOOL_KEYS = ("xyz", "rpy")
_ARM_KEYS = ("name", "type", "prefix", "mount_xyz", "mount_zyx", "mount_rpy")

_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")


def _check_inertia(I6: np.ndarray, where: str) -> None:
    """A physical rotational inertia: symmetric positive definite and the triangle inequalities."""
    xx, xy, xz, yy, yz, zz = I6
    I = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    ev = np.linalg.eigvalsh(I)
    if ev.min() <= 0 or ev[0] + ev[1] < ev[2] * (1 - 1e-9):
        raise ModelError(f"{where}: [Ixx, Ixy, Ixz, Iyy, Iyz, Izz] = {I6.tolist()} is not a physical inertia "
                         f"(principal moments {ev.round(6).tolist()} must be > 0 and satisfy the triangle inequality)")


def _parse_arm_type(name: str, d: dict, ang: float, src: str) -> ArmType:
    where = f"{src}: arm_types.{name}"
    _known_keys(d, _DH_KEYS, where)
    conv = _get(d, "dh_convention", where, str)
    if conv not in ("modified", "standard"):
        raise ModelError(f"{where}.dh_convention: expected 'modified' or 'standard', got {conv!r}")
    dh = _array(_get(d, "dh", where), None, f"{where}.dh")
    if dh.ndim != 2 or dh.shape[1] != 4 or dh.shape[0] < 1:
        raise ModelError(f"{where}.dh: expected rows [theta_offset, alpha, a, d], got shape {dh.shape}")
    n = dh.shape[0]
    dh = dh.copy()
    dh[:, :2] *= ang
    masses = _array(_get(d, "masses", where), (n,), f"{where}.masses")
    if np.any(masses <= 0):
        raise ModelError(f"{where}.masses: every mass must be > 0 kg, got {masses.tolist()}")
    coms = _array(_get(d, "coms", where), (n, 3), f"{where}.coms")
    inertias = _array(_get(d, "inertias", where), (n, 6), f"{where}.inertias")
    for i in range(n):
        _check_inertia(inertias[i], f"{where}.inertias[{i}] (link {i + 1})")
    lower = _array(_get(d, "lower", where), (n,), f"{where}.lower") * ang
    upper = _array(_get(d, "upper", where), (n,), f"{where}.upper") * ang
    if np.any(lower >= upper):
        raise ModelError(f"{where}: lower limits must be < upper limits ({lower} vs {upper})")
    velocity = _array(_get(d, "velocity", where), (n,), f"{where}.velocity") * ang
    if np.any(velocity <= 0):
        raise ModelError(f"{where}.velocity: every joint speed limit must be > 0, got {(velocity / ang).tolist()}")
    effort = _array(d.get("effort", [100.0] * n), (n,), f"{where}.effort")
    if np.any(effort <= 0):
        raise ModelError(f"{where}.effort: every effort limit must be > 0 N m, got {effort.tolist()}")
    caps = []
    capsules = d.get("capsules", [])
    if not isinstance(capsules, list):
        raise ModelError(f"{where}.capsules: expected a list of {{ link, a, b, radius }} tables, got {capsules!r}")
    for k, c in enumerate(capsules):
        cw = f"{where}.capsules[{k}]"
        _known_keys(c, _CAPSULE_KEYS, cw)
        link = _get(c, "link", cw, int)
        if isinstance(link, bool) or not 1 <= link <= n:
            raise ModelError(f"{cw}.link: expected 1..{n}, got {link}")
        r = _positive(_get(c, "radius", cw, (int, float)), f"{cw}.radius", "m")
        caps.append({"link": link, "a": _array(_get(c, "a", cw), (3,), f"{cw}.a"),
                     "b": _array(_get(c, "b", cw), (3,), f"{cw}.b"), "radius": r})
    tool = d.get("tool", {})
    if not isinstance(tool, dict):
        raise ModelError(f"{where}.tool: expected a table {{ xyz = [...], rpy = [...] }}, got {tool!r}")
    _known_keys(tool, _TOOL_KEYS, f"{where}.tool")
    return ArmType(
        name=name, convention=conv, dh=dh, masses=masses, coms=coms, inertias=inertias,
        lower=lower, upper=upper, velocity=velocity, effort=effort, capsules=tuple(caps),
        tool_xyz=_array(tool.get("xyz", [0, 0, 0]), (3,), f"{where}.tool.xyz"),
        tool_rpy=_array(tool.get("rpy", [0, 0, 0]), (3,), f"{where}.tool.rpy") * ang,
    )


def _parse_serpentine_arm_type(name: str, d: dict, ang: float, src: str) -> SerpentineArmType:
    where = f"{src}: arm_types.{name}"
    _known_keys(d, _SERPENTINE_KEYS, where)

    def pos_int(key):
        v = _get(d, key, where, int)
        if isinstance(v, bool) or v < 1:
            raise ModelError(f"{where}.{key}: expected a positive integer, got {v!r}")
        return v

    def pos(key, default=None):
        v = d.get(key, default) if default is not None else _get(d, key, where, (int, float))
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
            raise ModelError(f"{where}.{key}: expected a number > 0, got {v!r}")
        return float(v)

    segments = pos_int("segments")
    m = pos_int("joints_per_segment")
    if m % 2:
        raise ModelError(f"{where}.joints_per_segment: expected an even number (pitch-yaw-yaw-pitch units), got {m}")
    lower = float(_array(_get(d, "lower", where), (), f"{where}.lower")) * ang
    upper = float(_array(_get(d, "upper", where), (), f"{where}.upper")) * ang
    if lower >= upper:
        raise ModelError(f"{where}: lower limit must be < upper limit ({lower} vs {upper})")
    tool = d.get("tool", {})
    if not isinstance(tool, dict):
        raise ModelError(f"{where}.tool: expected a table {{ xyz = [...], rpy = [...] }}, got {tool!r}")
    _known_keys(tool, _TOOL_KEYS, f"{where}.tool")
    return SerpentineArmType(
        name=name, segments=segments, joints_per_segment=m, link_length=pos("link_length"),
        link_mass=pos("link_mass"), capsule_radius=pos("capsule_radius"), lower=lower, upper=upper,
        velocity=pos("velocity") * ang, effort=pos("effort", 100.0),
        tool_xyz=_array(tool.get("xyz", [0, 0, 0]), (3,), f"{where}.tool.xyz"),
        tool_rpy=_array(tool.get("rpy", [0, 0, 0]), (3,), f"{where}.tool.rpy") * ang,
    )


def _parse_any_arm_type(name: str, d: dict, ang: float, src: str):
    kind = d.get("kind", "dh") if isinstance(d, dict) else "dh"
    if kind == "serpentine":
        return _parse_serpentine_arm_type(name, d, ang, src)
    if kind != "dh":
        raise ModelError(f"{src}: arm_types.{name}.kind: expected 'dh' (default) or 'serpentine', got {kind!r}")
    return _parse_arm_type(name, d, ang, src)


def read_model_toml(name_or_path: str | Path, folder: str, what: str, available) -> tuple[dict, Path]:
    """``(data, path)`` of a TOML file: a path ending in ``.toml``, or a name in
    ``models/<folder>`` (``what``: "robot model", "scene"; ``available()``: the known names for the
    error). A missing, malformed, non-UTF-8 or unreadable file is a :class:`ModelError`."""
    from .. import limits

    if not isinstance(name_or_path, (str, Path)):
        raise ModelError(f"{what}: expected a name or a path to a .toml file, got {type(name_or_path).__name__} "
                         f"{name_or_path!r}")
    p = limits.check_path(name_or_path, f"{what} file", ModelError)
    if p.suffix != ".toml":
        cand = models_dir() / folder / f"{name_or_path}.toml"
        if not cand.exists():
            raise UnknownNameError(what, str(name_or_path), available())
        p = cand
    if not p.exists():
        raise ModelError(f"{what} file {str(p)!r} does not exist")
    if p.is_dir():
        raise ModelError(f"{what} file {str(p)!r} is a folder; expected a TOML file")
    limit_name = "MAX_SCENE_BYTES" if folder == "scenes" else "MAX_ROBOT_BYTES"
    limits.check_file_size(p, getattr(limits, limit_name), what, ModelError, limit_name)
    try:
        text = p.read_bytes().decode("utf-8")
        limits.check_nesting(text, str(p), ModelError)
        return tomllib.loads(text), p
    except tomllib.TOMLDecodeError as exc:
        raise ModelError(f"{p}: malformed TOML: {exc}") from exc
    except RecursionError:   # belt and braces: check_nesting refuses the deep files first
        raise ModelError(f"{p}: arrays/tables nested too deeply to parse") from None
    except UnicodeDecodeError as exc:
        raise ModelError(f"{p}: not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    except OSError as exc:
        raise ModelError(f"{p}: cannot be read ({exc.strerror or exc})") from None


def load_description(name_or_path: str | Path) -> RobotDescription:
    """Parse a robot description TOML (a path, or a model name in ``models/robots``)."""
    data, p = read_model_toml(name_or_path, "robots", "robot model", available_models)
    src = p.name
    _known_keys(data, _TOP_KEYS, src)
    unit = data.get("angle_unit", "rad")
    ang = {"deg": math.pi / 180.0, "rad": 1.0}.get(unit) if isinstance(unit, str) else None
    if ang is None:
        raise ModelError(f"{src}.angle_unit: expected 'deg' or 'rad', got {data.get('angle_unit')!r}")
    name = _get(data, "name", src, str)
    base_type = data.get("base_type", "fixed")
    if base_type not in ("fixed", "floating"):
        raise ModelError(f"{src}.base_type: expected 'fixed' or 'floating', got {base_type!r}")
    base = _get(data, "base", src, dict)
    _known_keys(base, _BASE_KEYS, f"{src}: base")
    boxes = []
    base_boxes = base.get("boxes", [])
    if not isinstance(base_boxes, list):
        raise ModelError(f"{src}: base.boxes: expected a list of {{ size, xyz, rpy }} tables, got {base_boxes!r}")
    for k, b in enumerate(base_boxes):
        bw = f"{src}: base.boxes[{k}]"
        _known_keys(b, _BOX_KEYS, bw)
        size = _array(_get(b, "size", bw), (3,), f"{bw}.size")
        if np.any(size <= 0):
            raise ModelError(f"{bw}.size: box edges must be > 0 m, got {size.tolist()}")
        boxes.append({"size": size,
                      "xyz": _array(b.get("xyz", [0, 0, 0]), (3,), f"{bw}.xyz"),
                      "rpy": _array(b.get("rpy", [0, 0, 0]), (3,), f"{bw}.rpy") * ang})
    arm_types = {k: _parse_any_arm_type(k, v, ang, src)
                 for k, v in _get(data, "arm_types", src, dict).items()}
    arms = []
    arm_list = _get(data, "arms", src, list)
    if not arm_list:
        raise ModelError(f"{src}: arms: expected at least one [[arms]] table (name, type, prefix, mount_*), got none")
    for k, a in enumerate(arm_list):
        aw = f"{src}: arms[{k}]"
        _known_keys(a, _ARM_KEYS, aw)
        t = _get(a, "type", aw, str)
        if t not in arm_types:
            raise UnknownNameError("arm type", t, arm_types)
        if "mount_zyx" in a:
            R = zyx_to_matrix(*(_array(a["mount_zyx"], (3,), f"{aw}.mount_zyx") * ang))
        else:
            R = rpy_to_matrix(*(_array(a.get("mount_rpy", [0, 0, 0]), (3,), f"{aw}.mount_rpy") * ang))
        arms.append(ArmMount(name=_get(a, "name", aw, str), type=t,
                             prefix=_get(a, "prefix", aw, str),
                             xyz=_array(a.get("mount_xyz", [0, 0, 0]), (3,), f"{aw}.mount_xyz"), R=R))
    names = [a.name for a in arms]
    prefixes = [a.prefix for a in arms]
    if len(set(names)) != len(names) or len(set(prefixes)) != len(prefixes):
        raise ModelError(f"{src}: arm names {names} and prefixes {prefixes} must be unique")
    base_mass = _positive(_get(base, "mass", f"{src}: base"), f"{src}: base.mass", "kg")
    base_inertia = _array(_get(base, "inertia", f"{src}: base"), (6,), f"{src}: base.inertia")
    _check_inertia(base_inertia, f"{src}: base.inertia")
    base_link = str(base.get("link", "base"))
    for what, value in [("name", name), ("base.link", base_link)] + [
            (f"arms[{k}].name", a.name) for k, a in enumerate(arms)] + [
            (f"arms[{k}].prefix", a.prefix) for k, a in enumerate(arms)]:
        if not _NAME_RE.match(value):
            raise ModelError(f"{src}: {what} = {value!r}: expected a name of letters, digits, '_' or '-' "
                             "starting with a letter or '_' (it becomes a URDF/XML name)")
    desc = RobotDescription(
        name=name, base_type=base_type, base_link=base_link,
        base_mass=float(base_mass),
        base_com=_array(base.get("com", [0, 0, 0]), (3,), f"{src}: base.com"),
        base_inertia=base_inertia,
        base_boxes=tuple(boxes), arm_types=arm_types, arms=tuple(arms), source=p,
        notes=str(data.get("notes", "")), extra=dict(data.get("extra", {})),
    )
    _check_lengths(desc, src)
    return desc


def _check_lengths(desc: RobotDescription, src: str) -> None:
    """Every length of a description (base boxes and CoM, mounts, D-H a and d, link CoMs, tools,
    capsules, serpentine links) within ±``optplan.limits.MAX_COORDINATE_M`` [m]: a 1e308 m link
    would load and poison every later computation with infinities."""
    from ..limits import MAX_COORDINATE_M

    fields: list[tuple[str, Any]] = [("base.com", desc.base_com)]
    fields += [(f"base.boxes[{k}].{f}", b[f]) for k, b in enumerate(desc.base_boxes) for f in ("size", "xyz")]
    fields += [(f"arms[{k}].mount_xyz", a.xyz) for k, a in enumerate(desc.arms)]
    for name, at in desc.arm_types.items():
        w = f"arm_types.{name}"
        if isinstance(at, ArmType):
            fields += [(f"{w}.dh (a, d columns)", np.asarray(at.dh)[:, 2:4]), (f"{w}.coms", at.coms),
                       (f"{w}.tool.xyz", at.tool_xyz)]
            fields += [(f"{w}.capsules[{k}].{f}", c[f]) for k, c in enumerate(at.capsules)
                       for f in ("a", "b", "radius") if f in c]
        else:
            fields += [(f"{w}.link_length", at.link_length), (f"{w}.capsule_radius", at.capsule_radius),
                       (f"{w}.tool.xyz", at.tool_xyz)]
    for what, value in fields:
        v = np.abs(np.asarray(value, dtype=float))
        if v.size and float(v.max()) > MAX_COORDINATE_M:
            raise ModelError(f"{src}: {what}: lengths must be within ±{MAX_COORDINATE_M:g} m "
                             f"(optplan.limits.MAX_COORDINATE_M), got {np.asarray(value).tolist()}")


def arm_metadata(desc: RobotDescription) -> dict[str, Any]:
    """Arm groups as RobotModel expects them: ``{arm: {"joints": [...], "ee": frame}}``."""
    def joints(a):
        at = desc.arm_types[a.type]
        if isinstance(at, SerpentineArmType):
            return at.joint_names(a.prefix)
        return [f"{a.prefix}_joint{i}" for i in range(1, at.n + 1)]
    return {a.name: {"joints": joints(a), "ee": f"{a.prefix}_ee"} for a in desc.arms}


def dh_capsules(arm: ArmType, radius: float, min_length: float = 1e-9) -> list[dict]:
    """Capsules along the D-H link segments (each in its D-H frame), a helper for writing the
    ``capsules`` list of a new arm: the ``a`` leg of a link belongs to it, and so does the ``d``
    leg along its own joint axis. Zero-length legs are skipped."""
    caps = []
    for i in range(1, arm.n + 1):
        off, alpha, a, d = arm.dh[i - 1]
        if arm.convention == "modified":
            legs = []
            if abs(d) > min_length:
                legs.append((np.array([0.0, 0.0, -d]), np.zeros(3)))
            if i < arm.n:
                a_next = arm.dh[i][2]
                if abs(a_next) > min_length:
                    legs.append((np.zeros(3), np.array([a_next, 0.0, 0.0])))
        else:
            Tinv = np.linalg.inv(_tz(d) @ _tx(a) @ _hrot(rotx(alpha)))
            o_prev = (Tinv @ np.r_[0.0, 0.0, 0.0, 1.0])[:3]
            knee = (Tinv @ _tz(d) @ np.r_[0.0, 0.0, 0.0, 1.0])[:3]
            legs = [(s, e) for s, e in ((o_prev, knee), (knee, np.zeros(3)))
                    if np.linalg.norm(e - s) > min_length]
        for s, e in legs:
            caps.append({"link": i, "a": s, "b": e, "radius": radius})
    return caps


def __getattr__(name):
    # URDF generation lives in .urdf_writer (which imports this module); the old path warns
    if name in ("build_all", "urdf_string", "write_urdf"):
        from .._compat import moved

        return moved(__name__, name, "optplan.model.urdf_writer")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
