"""`RobotModel`: a Pinocchio model (fixed or free-flyer base), its coal collision geometry and
its arm groups.

Configuration layout is Pinocchio's: for a floating robot ``q = [x, y, z, qx, qy, qz, qw, joints]``
(base position [m] in the world, base orientation as a unit quaternion) and
``v = [v_base (3, base frame) [m/s], ω_base (3, base frame) [rad/s], joint rates]``; for a fixed base
``q`` and ``v`` are the joint angles [rad] and rates [rad/s]. ``joint`` vectors (``nj`` entries) are
the actuated joints only, in Pinocchio order.
"""
from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from ..errors import ConfigurationError, ModelError, UnknownNameError, check_vector
from .description import arm_metadata, available_models, load_description, urdf_dir
from .urdf_checks import check_urdf_structure

__all__ = ["Arm", "RobotModel"]
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Arm:
    """An arm group: its actuated joints and its end-effector frame.

    ``q_idx``/``v_idx`` index the full Pinocchio ``q``/``v``; ``j_idx`` indexes the joint vector
    (``nj`` entries, base excluded).
    """

    name: str
    joint_names: tuple[str, ...]
    ee_frame: str
    ee_frame_id: int
    q_idx: np.ndarray
    v_idx: np.ndarray
    j_idx: np.ndarray

    @property
    def n(self) -> int:
        return len(self.joint_names)


class RobotModel:
    """A robot for planning: kinematic tree, limits, collision geometry and arm groups.

    Build it with :meth:`from_name` (a model shipped in ``models/robots``) or :meth:`from_urdf`
    (any URDF; name the arms' end-effector frames and, optionally, their joints).
    """

    #: The self-collision pair filtering report, set only by loaders that filter the pairs
    #: (:func:`optplan.model.dual_panda.load_dual_panda`); a declaration, not a default.
    pair_budget: dict
    #: The same robot with the exact (mesh) geometry, when this one plans on fitted primitives
    #: (robot files, ``collision = "auto"``): :func:`optplan.verify` judges on it (:attr:`judge`).
    exact: RobotModel
    #: Per replaced mesh: its certified capsules and volumes (robot files; :mod:`.primitive_fit`).
    primitive_report: dict
    #: The robot file's settings this robot was loaded from (robot files only).
    robot_file: dict

    def __init__(self, model: pin.Model, collision_model: pin.GeometryModel, arms: Mapping[str, Mapping],
                 *, name: str | None = None, floating: bool, urdf_path: Path | None = None):
        self.model = model
        self.collision_model = collision_model
        self.name = name or model.name
        self.is_floating = floating
        self.urdf_path = urdf_path
        self.data = model.createData()
        self.base_nq = 7 if floating else 0
        self.base_nv = 6 if floating else 0
        self.nq, self.nv = model.nq, model.nv
        self.nj = self.nv - self.base_nv
        first = 2 if floating else 1
        names = []
        for jid in range(first, model.njoints):
            if model.joints[jid].shortname() == "JointModelMimic":
                continue  # coupled joint: driven by the joint it mimics, no own coordinate
            if model.nqs[jid] != 1 or model.nvs[jid] != 1:
                raise ModelError(f"joint {model.names[jid]!r} has nq={model.nqs[jid]}, nv={model.nvs[jid]}; "
                                 "only 1-DoF joints (and mimic joints) are supported below the optional "
                                 "free-flyer root")
            names.append(model.names[jid])
        self.joint_names: tuple[str, ...] = tuple(names)
        self.lower = np.array(model.lowerPositionLimit[self.base_nq:], dtype=float)
        self.upper = np.array(model.upperPositionLimit[self.base_nq:], dtype=float)
        self.velocity_limit = np.array(model.velocityLimit[self.base_nv:], dtype=float)
        self.arms: dict[str, Arm] = {}
        for arm_name, spec in arms.items():
            self.arms[arm_name] = self._make_arm(arm_name, spec)
        self.collision_pairs = self._default_collision_pairs()
        self.collision_model.removeAllCollisionPairs()
        for a, b in self.collision_pairs:
            self.collision_model.addCollisionPair(pin.CollisionPair(a, b))
        self.collision_data = pin.GeometryData(self.collision_model)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_name(cls, name: str) -> RobotModel:
        """Load a shipped model (``models/robots/<name>.toml`` + ``urdf/<name>.urdf``), a robot
        file (a path, or a name in ``models/robots/files``) or a bare URDF path
        (:mod:`optplan.model.robot_file`)."""
        from .robot_file import is_robot_path, load_robot_file

        if isinstance(name, Path) or (isinstance(name, str) and is_robot_path(name)):
            return load_robot_file(name, cls)
        if name not in available_models():
            from .robot_file import available_robot_files, robot_files_dir

            if name in available_robot_files():
                return load_robot_file(robot_files_dir() / f"{name}.toml", cls)
            raise UnknownNameError("robot model", name, available_models() + available_robot_files()
                                   + ["a robot file (.toml) or URDF path"])
            raise UnknownNameError("robot model", name, available_models())
        desc = load_description(name)
        path = urdf_dir() / f"{name}.urdf"
        if not path.exists():
            raise ModelError(f"{path} is missing: run `optplan models build` to generate it")
        from .urdf_writer import urdf_string

        if _read_text(path) != urdf_string(desc):   # never use a URDF older than its description
            raise ModelError(f"{path} is out of date with {desc.source}: the description changed after the "
                             "URDF was generated; run `optplan models build` to regenerate it")
        arms = arm_metadata(desc)
        return cls.from_urdf(path, arms=arms, floating=desc.base_type == "floating", name=name)

    @classmethod
    def from_urdf(cls, path: str | Path, arms: Mapping[str, str | Mapping], *, floating: bool = False,
                  name: str | None = None, mimic: bool = True, package_dirs: Sequence[str | Path] | None = None,
                  fixed_joints: Sequence[str] | Mapping[str, float] | None = None) -> RobotModel:
        """Load any URDF.

        Parameters
        ----------
        path: the URDF file.
        arms: ``{arm_name: ee_frame}`` or ``{arm_name: {"ee": ee_frame, "joints": [names]}}``;
            without ``joints`` the arm is every 1-DoF joint from the root to the EE frame.
        floating: add a free-flyer root joint (free-floating base).
        mimic: read URDF ``<mimic>`` tags as coupled joints (``θ = multiplier · q + offset``).
        package_dirs: where ``package://`` mesh names are looked up first (then
            ``ROS_PACKAGE_PATH`` and installed packages, :func:`~.robot_file.package_search_dirs`);
            relative mesh names are relative to the URDF.
        fixed_joints: joints (names or fnmatch patterns, e.g. ``"*finger*"``) locked at 0, or
            ``{name: value}`` [rad or m]: grippers and fingers that are not planning joints.
        """
        from .. import limits

        if not isinstance(path, (str, Path)):
            raise ModelError(f"URDF file: expected a path, got {type(path).__name__} {path!r}")
        path = limits.check_path(path, "URDF file", ModelError)
        if not path.exists():
            raise ModelError(f"URDF file {str(path)!r} does not exist")
        if path.is_dir():
            raise ModelError(f"URDF file {str(path)!r} is a folder; expected a .urdf file")
        limits.check_file_size(path, limits.MAX_URDF_BYTES, "URDF", ModelError, "MAX_URDF_BYTES")
        norm = _arm_specs(arms)
        text = _read_text(path)
        if package_dirs is not None or fixed_joints is not None or "package://" in text:
            from .robot_file import _cached_urdf, _fix_joints, _resolve_meshes

            root0 = ET.fromstring(text) if text.lstrip().startswith("<") else None
            if root0 is not None and root0.tag == "robot":
                _resolve_meshes(root0, path.parent, list(package_dirs or ()))
                if fixed_joints is not None:
                    _fix_joints(root0, fixed_joints)
                text = ET.tostring(root0, encoding="unicode")
                path = _cached_urdf(text, path.stem)
        try:
            root = ET.fromstring(text)
        except ET.ParseError as exc:
            raise ModelError(f"{path}: malformed URDF XML: {exc}") from exc
        if root.tag != "robot":
            raise ModelError(f"{path}: expected a <robot> root element, got <{root.tag}>")
        check_urdf_structure(root, text, path)
        _check_urdf_joints(root, text, path)
        try:
            if floating:
                model = pin.buildModelFromXML(text, pin.JointModelFreeFlyer(), mimic=mimic)
            else:
                model = pin.buildModelFromXML(text, mimic=mimic)
            geom = pin.buildGeomFromUrdfString(model, text, pin.COLLISION)
        except (RuntimeError, ValueError, TypeError) as exc:   # TypeError: Boost.Python.ArgumentError
            raise ModelError(f"{path}: Pinocchio could not parse the URDF: {_pinocchio_message(exc)}") from exc
        _capsules_from_cylinders(root, geom)
        return cls(model, geom, norm, name=name or model.name, floating=floating, urdf_path=path)

    # ------------------------------------------------------------------ names
    @property
    def frame_names(self) -> list[str]:
        return [f.name for f in self.model.frames]

    def frame_id(self, name: str | int) -> int:
        """Index of a frame by name (an int is returned unchanged after a range check)."""
        if isinstance(name, bool):
            raise UnknownNameError("frame", name, self.frame_names)
        if isinstance(name, (int, np.integer)):
            if not 0 <= int(name) < self.model.nframes:
                raise UnknownNameError("frame id", name, [str(i) for i in range(self.model.nframes)])
            return int(name)
        if not isinstance(name, str) or not self.model.existFrame(name):
            raise UnknownNameError("frame", name, self.frame_names)
        return int(self.model.getFrameId(name))

    def arm(self, name: str) -> Arm:
        try:
            return self.arms[name]
        except KeyError:
            raise UnknownNameError("arm", name, self.arms) from None

    def _make_arm(self, arm_name: str, spec: Mapping) -> Arm:
        if "ee" not in spec:
            raise ModelError(f"arm {arm_name!r}: missing 'ee' (end-effector frame name)")
        fid = self.frame_id(spec["ee"])
        if "joints" in spec and spec["joints"] is not None:
            jids = []
            chain, j = set(), int(self.model.frames[fid].parentJoint)
            while j > 0:   # the joints between the root and the end-effector frame
                chain.add(j)
                j = int(self.model.parents[j])
            for jn in spec["joints"]:
                if jn not in self.joint_names:
                    raise UnknownNameError("joint", jn, self.joint_names)
                jid = int(self.model.getJointId(jn))
                if jid not in chain:
                    on_chain = [self.model.names[k] for k in sorted(chain) if self.model.names[k] in self.joint_names]
                    raise ModelError(f"arm {arm_name!r}: joint {jn!r} does not move its end-effector frame "
                                     f"{spec['ee']!r} (it is not between the root and that frame); the joints "
                                     f"that do: {on_chain}")
                if jid in jids:
                    raise ModelError(f"arm {arm_name!r}: joint {jn!r} is listed twice")
                jids.append(jid)
        else:
            jids, j = [], int(self.model.frames[fid].parentJoint)
            while j > (1 if self.is_floating else 0):
                if self.model.nqs[j] == 1:  # skip mimic (coupled) joints
                    jids.append(j)
                j = int(self.model.parents[j])
            jids.reverse()
        if not jids:
            raise ModelError(f"arm {arm_name!r}: no actuated joint between the root and frame {spec['ee']!r}")
        q_idx = np.array([self.model.idx_qs[j] for j in jids])
        v_idx = np.array([self.model.idx_vs[j] for j in jids])
        return Arm(arm_name, tuple(self.model.names[j] for j in jids), str(spec["ee"]), fid,
                   q_idx, v_idx, v_idx - self.base_nv)

    # ------------------------------------------------------------------ configurations
    def check_q(self, q, what: str = "q") -> np.ndarray:
        """Validate a full configuration (size nq, finite, unit quaternion for a floating base)."""
        if type(q) is np.ndarray and q.dtype == np.float64 and q.shape == (self.nq,) and np.isfinite(q).all():
            if not self.is_floating or abs(float(q[3:7] @ q[3:7]) - 1.0) < 2e-6:
                return q  # fast path for hot loops; the slow path below builds the error message
        q = check_vector(q, self.nq, f"{what} (Pinocchio configuration of {self.name!r}, nq={self.nq})")
        if self.is_floating:
            n = np.linalg.norm(q[3:7])
            if abs(n - 1.0) > 1e-6:
                raise ConfigurationError(f"{what}: base quaternion q[3:7]={q[3:7].tolist()} has norm {n:.6g}, "
                                         "expected a unit quaternion (x, y, z, w)")
        return q

    def check_in_limits(self, q, what: str = "q", tol: float = 1e-6) -> np.ndarray:
        """``q`` (checked by :meth:`check_q`) with every joint within its limits ± ``tol`` [rad or
        m], else :class:`ConfigurationError` naming the joints, values and limits."""
        q = self.check_q(q, what)
        qj = q[self.base_nq:]
        bad = np.flatnonzero((qj < self.lower - tol) | (qj > self.upper + tol))
        if bad.size:
            shown = ", ".join(f"{self.joint_names[i]} = {qj[i]:.6g} not in [{self.lower[i]:.6g}, {self.upper[i]:.6g}]"
                              for i in bad[:5])
            raise ConfigurationError(f"{what}: {bad.size} joint(s) outside their limits: {shown}"
                                     + (" ..." if bad.size > 5 else ""))
        return q

    def check_v(self, v, what: str = "v") -> np.ndarray:
        return check_vector(v, self.nv, f"{what} (velocity of {self.name!r}, nv={self.nv})")

    def check_joints(self, qj, what: str = "joint vector") -> np.ndarray:
        return check_vector(qj, self.nj, f"{what} ({self.nj} actuated joints of {self.name!r})")

    def neutral(self) -> np.ndarray:
        """Neutral configuration: base at the origin, joints at 0 (clipped into the limits)."""
        q = pin.neutral(self.model)
        q[self.base_nq:] = np.clip(q[self.base_nq:], self.lower, self.upper)
        return q

    def random_joints(self, rng: np.random.Generator) -> np.ndarray:
        """Joint vector uniform in the joint limits (infinite limits are replaced by ±π)."""
        lo = np.where(np.isfinite(self.lower), self.lower, -np.pi)
        hi = np.where(np.isfinite(self.upper), self.upper, np.pi)
        return rng.uniform(lo, hi)

    def random_configuration(self, rng: np.random.Generator) -> np.ndarray:
        """Full configuration: random joints; for a floating base a random unit quaternion and a
        position in [-1, 1]³ m."""
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng: expected numpy.random.Generator, got {type(rng).__name__}")
        q = np.empty(self.nq)
        if self.is_floating:
            q[:3] = rng.uniform(-1.0, 1.0, 3)
            quat = rng.normal(size=4)
            q[3:7] = quat / np.linalg.norm(quat)
        q[self.base_nq:] = self.random_joints(rng)
        return q

    def joints_of(self, q) -> np.ndarray:
        """Actuated-joint part of a full configuration."""
        return np.asarray(q, dtype=float)[self.base_nq:]

    def configuration(self, joints, base: pin.SE3 | None = None) -> np.ndarray:
        """Full configuration from a joint vector and (floating robots) a base placement."""
        qj = self.check_joints(joints)
        if not self.is_floating:
            if base is not None:
                raise ConfigurationError(f"{self.name!r} has a fixed base; got a base placement")
            return qj.copy()
        base = pin.SE3.Identity() if base is None else base
        return np.concatenate([pin.SE3ToXYZQUAT(base), qj])

    def base_placement(self, q) -> pin.SE3:
        """Base placement of a full configuration (identity for a fixed base)."""
        if not self.is_floating:
            return pin.SE3.Identity()
        return pin.XYZQUATToSE3(np.asarray(q, dtype=float)[:7])

    # ------------------------------------------------------------------ collision
    def _joint_distance(self, ja: int, jb: int) -> int:
        """Number of joints between two joints in the kinematic tree."""
        m = self.model

        def chain(j):
            out = [j]
            while j > 0:
                j = int(m.parents[j])
                out.append(j)
            return out
        ca_, cb = chain(ja), chain(jb)
        common = next(j for j in ca_ if j in cb)
        return ca_.index(common) + cb.index(common)

    def _default_collision_pairs(self, min_joint_distance: int = 3) -> list[tuple[int, int]]:
        """All geometry pairs except: pairs fewer than ``min_joint_distance`` joints apart in the
        tree (the same link, parent/child and grandparent links: they touch or nearly touch by
        construction, e.g. a forearm and the wrist link two joints further), and pairs already in
        contact at the neutral configuration."""
        gm = self.collision_model
        objs = gm.geometryObjects
        pairs = []
        for a in range(len(objs)):
            for b in range(a + 1, len(objs)):
                if self._joint_distance(objs[a].parentJoint, objs[b].parentJoint) < min_joint_distance:
                    continue
                pairs.append((a, b))
        if not pairs:
            return pairs
        gd = pin.GeometryData(gm)
        q0 = self.neutral()
        pin.updateGeometryPlacements(self.model, self.data, gm, gd, q0)
        keep = []
        for a, b in pairs:
            d = _geom_distance(gm, gd, a, b)
            if d <= 0.0:
                log.info("collision pair (%s, %s) disabled: in contact at the neutral configuration",
                         objs[a].name, objs[b].name)
            else:
                keep.append((a, b))
        return keep

    def set_collision_pairs(self, pairs) -> None:
        """Replace the self-collision pairs (geometry index pairs ``(a, b)``, ``a < b``)."""
        n = len(self.collision_model.geometryObjects)
        out = []
        for a, b in pairs:
            a, b = int(a), int(b)
            if not (0 <= a < n and 0 <= b < n and a != b):
                raise ModelError(f"collision pair ({a}, {b}): expected two different geometry indices in [0, {n})")
            out.append((min(a, b), max(a, b)))
        self.collision_pairs = sorted(set(out))
        self.collision_model.removeAllCollisionPairs()
        for a, b in self.collision_pairs:
            self.collision_model.addCollisionPair(pin.CollisionPair(a, b))
        self.collision_data = pin.GeometryData(self.collision_model)

    @property
    def judge(self) -> RobotModel:
        """The robot :func:`optplan.verify` checks collisions on: the exact geometry when the
        planning geometry is fitted primitives (``exact``, set by robot files with
        ``collision = "auto"``), else this robot."""
        return getattr(self, "exact", None) or self

    def self_distances(self, q) -> np.ndarray:
        """Exact (coal) distances [m] of every active self-collision pair at ``q`` (joints within
        their limits, else ConfigurationError: a configuration the robot cannot take has no
        self-collision answer)."""
        q = self.check_in_limits(q)
        pin.updateGeometryPlacements(self.model, self.data, self.collision_model, self.collision_data, q)
        return np.array([_geom_distance(self.collision_model, self.collision_data, a, b)
                         for a, b in self.collision_pairs])

    def __repr__(self) -> str:
        return (f"RobotModel({self.name!r}, {'floating' if self.is_floating else 'fixed'} base, nq={self.nq}, "
                f"nv={self.nv}, arms={list(self.arms)})")


def _geom_distance(gm: pin.GeometryModel, gd: pin.GeometryData, a: int, b: int) -> float:
    """Exact signed distance between geometry objects a and b at the placements in gd [m]."""
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    oa, ob = gm.geometryObjects[a], gm.geometryObjects[b]
    return float(coal.distance(oa.geometry, _tf(gd.oMg[a]), ob.geometry, _tf(gd.oMg[b]), req, res))


def _tf(M: pin.SE3) -> coal.Transform3s:
    return coal.Transform3s(M.rotation, M.translation)


def _capsules_from_cylinders(root: ET.Element, geom: pin.GeometryModel) -> None:
    """Replace the cylinders whose URDF collision name ends in ``_capsule`` by coal capsules.

    Pinocchio names collision objects ``<link>_<k>`` in document order; URDF has no capsule."""
    for link in root.iter("link"):
        lname = link.get("name")
        for k, col in enumerate(link.findall("collision")):
            if not (col.get("name") or "").endswith("_capsule"):
                continue
            cyl = col.find("geometry/cylinder")
            if cyl is None:
                raise ModelError(f"collision {col.get('name')!r} of link {lname!r} is named *_capsule "
                                 "but is not a <cylinder>")
            gname = f"{lname}_{k}"
            if not geom.existGeometryName(gname):
                raise ModelError(f"collision geometry {gname!r} not found after parsing")
            obj = geom.geometryObjects[geom.getGeometryId(gname)]
            obj.geometry = coal.Capsule(float(cyl.attrib["radius"]), float(cyl.attrib["length"]))


def _arm_specs(arms) -> dict[str, dict]:
    """``{arm: {"ee": frame, "joints": [...]}}`` from the ``arms`` argument of :meth:`RobotModel.from_urdf`."""
    if not isinstance(arms, Mapping):
        raise ModelError(f"arms: expected a mapping {{arm_name: ee_frame}} or {{arm_name: {{'ee': frame, 'joints': "
                         f"[...]}}}}, got {type(arms).__name__} {arms!r}")
    out = {}
    for k, v in arms.items():
        if not isinstance(k, str) or not k:
            raise ModelError(f"arms: arm names must be non-empty strings, got {k!r}")
        if isinstance(v, str):
            out[k] = {"ee": v}
        elif isinstance(v, Mapping):
            unknown = sorted(set(v) - {"ee", "joints"})
            if unknown:
                raise ModelError(f"arms[{k!r}]: unknown keys {unknown}; expected 'ee' and optionally 'joints'")
            joints = v.get("joints")
            if joints is not None and (isinstance(joints, str) or not all(isinstance(j, str) for j in joints)):
                raise ModelError(f"arms[{k!r}].joints: expected a list of joint names, got {joints!r}")
            if not isinstance(v.get("ee"), str):
                raise ModelError(f"arms[{k!r}].ee: expected an end-effector frame name, got {v.get('ee')!r}")
            out[k] = dict(v)
        else:
            raise ModelError(f"arms[{k!r}]: expected an end-effector frame name or {{'ee': frame, 'joints': [...]}}, "
                             f"got {type(v).__name__} {v!r}")
    return out


def _pinocchio_message(exc: Exception) -> str:
    """The useful part of a Pinocchio/coal exception: the ``message:`` lines (they name the mesh
    file and the loader's reason) when there are some, else the first line."""
    lines = [ln.strip() for ln in str(exc).strip().splitlines() if ln.strip()]
    if not lines:
        return type(exc).__name__
    for i, ln in enumerate(lines):
        if ln.startswith("message:"):
            rest = [ln[len("message:"):].strip()] + [x for x in lines[i + 1:] if not x.startswith("Hint:")]
            return " ".join(x for x in rest if x)
    return lines[0]


def _read_text(path: Path) -> str:
    try:
        return path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ModelError(f"{path}: not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    except OSError as exc:
        raise ModelError(f"{path}: cannot be read ({exc.strerror or exc})") from None


def _check_urdf_joints(root, text: str, path: Path) -> None:
    """Physics checks Pinocchio's parser skips: every revolute/continuous/prismatic joint has a
    nonzero finite axis, and finite limits with lower ≤ upper, velocity ≥ 0 and effort ≥ 0.
    Messages name the file, the joint and its line."""
    def line_of(name: str) -> int:
        i = text.find(f'name="{name}"')
        return text.count("\n", 0, i) + 1 if i >= 0 else 0

    def floats(s: str | None, n: int, what: str, jn: str) -> np.ndarray:
        try:
            v = np.array([float(t) for t in str(s).split()])
        except ValueError:
            v = np.zeros(0)
        if v.shape != (n,) or not np.all(np.isfinite(v)):
            raise ModelError(f"{path}:{line_of(jn)}: joint {jn!r}: {what}={s!r}: expected {n} finite numbers")
        return v

    for j in root.iter("joint"):
        jn, jt = j.get("name", "?"), j.get("type", "")
        if jt not in ("revolute", "continuous", "prismatic"):
            continue
        ax = j.find("axis")
        if ax is not None:
            a = floats(ax.get("xyz", "1 0 0"), 3, "<axis xyz>", jn)
            if np.linalg.norm(a) < 1e-12:
                raise ModelError(f"{path}:{line_of(jn)}: joint {jn!r}: zero axis {a.tolist()}; expected a "
                                 "nonzero direction")
        lim = j.find("limit")
        if lim is None:
            continue
        vals = {k: float(floats(lim.get(k), 1, f"<limit {k}>", jn)[0]) for k in ("lower", "upper", "velocity", "effort")
                if lim.get(k) is not None}
        if "lower" in vals and "upper" in vals and vals["lower"] > vals["upper"]:
            raise ModelError(f"{path}:{line_of(jn)}: joint {jn!r}: lower limit {vals['lower']} > upper limit "
                             f"{vals['upper']}")
        for k in ("velocity", "effort"):
            if k in vals and vals[k] < 0:
                raise ModelError(f"{path}:{line_of(jn)}: joint {jn!r}: {k} limit {vals[k]} < 0")
