"""CasADi mirror of the kinematics, built from the Pinocchio model (the PyPI ``pin`` wheel has no
``pinocchio.casadi``).

Supported joints: a free-flyer root, 1-DoF revolute or prismatic joints about any axis
(Pinocchio's RX/RY/RZ, unaligned, PX/PY/PZ, ...) and coupled (mimic) joints
``θ = scaling · q_mimicked + offset`` — each joint is described by its axis, read off Pinocchio's
motion subspace, so every 1-DoF joint type Pinocchio builds is covered. Fixed URDF joints are
Pinocchio frames and are handled as frames.

Conventions are those of :mod:`optplan.model.kinematics`: ``q`` in Pinocchio order (free-flyer base
``[x, y, z, qx, qy, qz, qw]``; the quaternion is used as given, so keep it unit), Jacobians with
rows ``[linear; angular]``, ``Ag`` about the CoM in world axes.

Every builder works on SX or MX expressions; the ``*_function`` helpers wrap them in
``casadi.Function`` objects (inputs ``q``; outputs named).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import pinocchio as pin

from ..errors import ConfigurationError, ModelError, check_vector, real_array
from ..geometry.spatial import skew as _skew
from .robot import RobotModel

__all__ = ["SymbolicKinematics", "skew", "quat_to_matrix", "rodrigues"]


skew = _skew   # 3 × 3 cross-product matrix (:func:`optplan.geometry.spatial.skew`)


def quat_to_matrix(quat):
    """Rotation matrix of a unit quaternion stored ``(x, y, z, w)`` (Pinocchio order)."""
    x, y, z, w = quat[0], quat[1], quat[2], quat[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
        ca.horzcat(2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
        ca.horzcat(2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)),
    )


def rodrigues(axis: np.ndarray, angle):
    """``exp(angle [axis]×)`` for a constant unit axis and a symbolic angle."""
    K = _skew(np.asarray(axis, float))
    return ca.DM.eye(3) + ca.sin(angle) * ca.DM(K) + (1 - ca.cos(angle)) * ca.DM(K @ K)


@dataclass(frozen=True)
class _Joint:
    kind: str  # "free_flyer" | "revolute" | "prismatic"
    parent: int
    placement_R: np.ndarray
    placement_p: np.ndarray
    axis: np.ndarray  # unit axis in the joint frame
    q_index: int  # index in q of the driving variable (mimicked joint for a mimic)
    v_index: int  # velocity column it contributes to
    scaling: float
    offset: float


def _describe_joints(model: pin.Model) -> list[_Joint | None]:
    """Per-joint symbolic description (index 0, the universe, is None)."""
    data = model.createData()
    out: list[_Joint | None] = [None]
    q0 = pin.neutral(model)
    pin.forwardKinematics(model, data, q0)
    for j in range(1, model.njoints):
        jm = model.joints[j]
        name = jm.shortname()
        Mj = model.jointPlacements[j]
        R, p = np.array(Mj.rotation), np.array(Mj.translation)
        if name == "JointModelFreeFlyer":
            out.append(_Joint("free_flyer", int(model.parents[j]), R, p, np.zeros(3), jm.idx_q, jm.idx_v, 1.0, 0.0))
            continue
        scaling, offset = 1.0, 0.0
        if name == "JointModelMimic":
            ext = jm.extract()
            scaling, offset = float(ext.scaling), float(ext.offset)
            if scaling == 0.0:
                raise ModelError(f"mimic joint {model.names[j]!r} has scaling 0")
        elif model.nqs[j] != 1 or model.nvs[j] != 1:
            raise ModelError(f"joint {model.names[j]!r} of type {name} is not supported by the symbolic "
                             "kinematics (supported: free-flyer root, 1-DoF revolute/prismatic, mimic)")
        S = np.array(data.joints[j].S).reshape(6) / scaling
        lin, ang = S[:3], S[3:]
        if np.linalg.norm(ang) > 1e-12 and np.linalg.norm(lin) < 1e-12:
            kind, axis = "revolute", ang / np.linalg.norm(ang)
        elif np.linalg.norm(lin) > 1e-12 and np.linalg.norm(ang) < 1e-12:
            kind, axis = "prismatic", lin / np.linalg.norm(lin)
        else:
            raise ModelError(f"joint {model.names[j]!r} ({name}) has motion subspace {S.tolist()}: "
                             "neither a pure rotation nor a pure translation")
        if "Unbounded" in name:
            raise ModelError(f"joint {model.names[j]!r}: continuous (unbounded) joints use nq=2 and are "
                             "not supported; give the URDF joint finite limits (type revolute)")
        out.append(_Joint(kind, int(model.parents[j]), R, p, axis, jm.idx_q, jm.idx_v, scaling, offset))
    return out


class CheckedFunction(ca.Function):
    """A ``casadi.Function`` whose numeric calls are checked first: every numeric argument (NumPy
    array, list, number, ``casadi.DM``) must have the input's number of entries and only finite
    values, else :class:`~optplan.errors.ConfigurationError` names the function, the input and the
    value (CasADi would raise a bare ``RuntimeError`` for a wrong size and return NaN for NaN).
    Symbolic arguments (``SX``/``MX``) pass unchanged."""

    def __init__(self, f: ca.Function, owner: str = "") -> None:
        super().__init__(f)
        self._owner = owner
        self._numel = tuple(f.numel_in(i) for i in range(f.n_in()))   # SWIG calls cost µs: once

    def _sizes(self) -> tuple[int, ...]:
        n = getattr(self, "_numel", None)   # (absent on an unpickled copy)
        if n is None:
            n = self._numel = tuple(self.numel_in(i) for i in range(self.n_in()))
        return n

    def _checked(self, i: int, value):
        if isinstance(value, (ca.SX, ca.MX)):
            return value
        if type(value) is np.ndarray and value.dtype == np.float64 and value.ndim == 1 \
                and value.size == self._sizes()[i] and np.isfinite(value).all():
            return value   # the common case, without building a message
        name = self.name_in(i)
        n = self.numel_in(i)
        what = f"{self.name()}({name}){getattr(self, '_owner', '')}"
        if isinstance(value, ca.DM):
            value = np.asarray(value.full(), float)
        arr = real_array(value, f"{what}: expected {n} numbers")
        if arr.size != n:
            raise ConfigurationError(f"{what}: expected {n} numbers (shape {self.size_in(i)}), got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            bad = np.flatnonzero(~np.isfinite(arr.ravel())).tolist()
            raise ConfigurationError(f"{what}: entries {bad[:20]} are not finite")
        return arr.reshape(self.size_in(i), order="F")

    def __call__(self, *args, **kwargs):
        if args and len(args) == len(self._sizes()):
            args = tuple(self._checked(i, a) for i, a in enumerate(args))
        elif kwargs:
            names = self.name_in()
            kwargs = {k: (self._checked(names.index(k), v) if k in names else v) for k, v in kwargs.items()}
        return super().__call__(*args, **kwargs)


class SymbolicKinematics:
    """Symbolic forward kinematics, Jacobians and momentum matrix of a :class:`RobotModel`.

    ``sym`` is ``casadi.SX`` (default; fastest to evaluate and differentiate) or ``casadi.MX``.
    """

    def __init__(self, robot: RobotModel, sym=ca.SX):
        self.robot = robot
        self.model = robot.model
        self.sym = sym
        self.joints = _describe_joints(robot.model)
        self._functions: dict[tuple, ca.Function] = {}

    # ------------------------------------------------------------------ core recursions
    def joint_placements(self, q):
        """World ``(R, p)`` of every joint frame (index 0 = world) for the expression ``q``."""
        if not isinstance(q, (ca.SX, ca.MX)):   # numbers: the size and finiteness are checked
            q = ca.DM(check_vector(np.asarray(q.full()) if isinstance(q, ca.DM) else q, self.model.nq,
                                   f"q (Pinocchio configuration of {self.robot.name!r}, nq={self.model.nq})"))
        out = [(ca.DM.eye(3), ca.DM.zeros(3))]
        for j in range(1, self.model.njoints):
            jt = self.joints[j]
            Rp, pp = out[jt.parent]
            R0 = Rp @ ca.DM(jt.placement_R)
            p0 = pp + Rp @ ca.DM(jt.placement_p)
            if jt.kind == "free_flyer":
                qi = jt.q_index
                Rj = quat_to_matrix(q[qi + 3:qi + 7])
                R, p = R0 @ Rj, p0 + R0 @ q[qi:qi + 3]
            elif jt.kind == "revolute":
                R, p = R0 @ rodrigues(jt.axis, jt.scaling * q[jt.q_index] + jt.offset), p0
            else:
                R, p = R0, p0 + R0 @ ca.DM(jt.axis) * (jt.scaling * q[jt.q_index] + jt.offset)
            out.append((R, p))
        return out

    def _columns(self, j: int, X):
        """Velocity fields of joint j's columns: list of (v_index, ω (3), v_O (3)) with v_O the
        velocity of the point at the world origin (spatial velocity, world axes)."""
        jt = self.joints[j]
        assert jt is not None   # joint 0 (the universe) has no columns
        R, p = X[j]
        if jt.kind == "free_flyer":
            cols = []
            for k in range(3):
                cols.append((jt.v_index + k, ca.DM.zeros(3), R[:, k]))
            for k in range(3):
                w = R[:, k]
                cols.append((jt.v_index + 3 + k, w, -ca.cross(w, p)))
            return cols
        a = R @ ca.DM(jt.axis) * jt.scaling
        if jt.kind == "revolute":
            return [(jt.v_index, a, -ca.cross(a, p))]
        return [(jt.v_index, ca.DM.zeros(3), a)]

    def _support(self, j: int) -> list[int]:
        out = []
        while j > 0:
            out.append(j)
            j = int(self.model.parents[j])
        return out[::-1]

    def frame_placement(self, q, frame, X=None):
        """World ``(R, p)`` of a frame (name or id)."""
        fid = self.robot.frame_id(frame)
        f = self.model.frames[fid]
        X = self.joint_placements(q) if X is None else X
        R, p = X[f.parentJoint]
        return R @ ca.DM(np.array(f.placement.rotation)), p + R @ ca.DM(np.array(f.placement.translation))

    def frame_jacobian(self, q, frame, reference: str = "world_aligned", X=None):
        """6 × nv Jacobian of a frame: ``"world_aligned"`` (origin velocity, world axes) or
        ``"local"`` (frame axes) or ``"world"`` (spatial velocity at the world origin)."""
        if reference not in ("world_aligned", "local", "world"):
            raise ValueError(f"reference: expected 'world_aligned', 'local' or 'world', got {reference!r}")
        fid = self.robot.frame_id(frame)
        X = self.joint_placements(q) if X is None else X
        Rf, pf = self.frame_placement(q, fid, X)
        J = self.sym.zeros(6, self.model.nv) if self.sym is ca.SX else ca.MX.zeros(6, self.model.nv)
        cols: dict[int, list] = {}
        for j in self._support(self.model.frames[fid].parentJoint):
            for idx, w, vO in self._columns(j, X):
                lin = vO if reference == "world" else vO + ca.cross(w, pf)
                cols.setdefault(idx, []).append(ca.vertcat(lin, w))
        for idx, parts in cols.items():
            J[:, idx] = sum(parts[1:], parts[0])
        if reference == "local":
            Rt = Rf.T
            J = ca.vertcat(Rt @ J[:3, :], Rt @ J[3:, :])
        return J

    def center_of_mass(self, q, X=None):
        X = self.joint_placements(q) if X is None else X
        mtot, acc = 0.0, 0
        for j in range(1, self.model.njoints):
            I = self.model.inertias[j]
            if I.mass == 0:
                continue
            R, p = X[j]
            acc = acc + I.mass * (p + R @ ca.DM(np.array(I.lever)))
            mtot += I.mass
        return acc / mtot

    def centroidal_map(self, q, X=None):
        """Centroidal momentum matrix Ag (6 × nv): ``h = Ag v``, momentum ``[p; L]`` about the CoM,
        world axes — mirrors ``pin.computeCentroidalMap``."""
        X = self.joint_placements(q) if X is None else X
        nv = self.model.nv
        bodies = []
        for b in range(1, self.model.njoints):
            I = self.model.inertias[b]
            if I.mass == 0:
                continue
            R, p = X[b]
            xb = p + R @ ca.DM(np.array(I.lever))
            Iw = R @ ca.DM(np.array(I.inertia)) @ R.T
            bodies.append((b, float(I.mass), xb, Iw))
        mtot = sum(m for _, m, _, _ in bodies)
        G = sum((m * xb for _, m, xb, _ in bodies[1:]), bodies[0][1] * bodies[0][2]) / mtot
        subtree = {j: set() for j in range(self.model.njoints)}
        for b in range(1, self.model.njoints):
            for j in self._support(b):
                subtree[j].add(b)
        cols: dict[int, list] = {}
        for j in range(1, self.model.njoints):
            sub = [bd for bd in bodies if bd[0] in subtree[j]]
            if not sub:
                continue
            for idx, w, vO in self._columns(j, X):
                hl, ha = 0, 0
                for _, m, xb, Iw in sub:
                    vb = vO + ca.cross(w, xb)
                    hl = hl + m * vb
                    ha = ha + m * ca.cross(xb - G, vb) + Iw @ w
                cols.setdefault(idx, []).append(ca.vertcat(hl, ha))
        Ag = self.sym.zeros(6, nv) if self.sym is ca.SX else ca.MX.zeros(6, nv)
        for idx, parts in cols.items():
            Ag[:, idx] = sum(parts[1:], parts[0])
        return Ag

    def momentum(self, q, v, X=None):
        """Spatial momentum ``[p; L]`` about the world origin (world axes) for the expressions
        ``(q, v)``, by an O(n) forward recursion of body velocities — linear in ``v`` and free of
        any matrix inverse. (Equals ``Ag v`` transported from the CoM to the origin.)"""
        X = self.joint_placements(q) if X is None else X
        V = [(ca.DM.zeros(3), ca.DM.zeros(3))]  # (ω, v_O) spatial velocity of each joint frame
        for j in range(1, self.model.njoints):
            w, vO = V[self.joints[j].parent]
            for idx, wc, vc in self._columns(j, X):
                w, vO = w + wc * v[idx], vO + vc * v[idx]
            V.append((w, vO))
        hl, ha = 0, 0
        for b in range(1, self.model.njoints):
            I = self.model.inertias[b]
            if I.mass == 0:
                continue
            R, p = X[b]
            c = p + R @ ca.DM(np.array(I.lever))
            w, vO = V[b]
            vc = vO + ca.cross(w, c)
            hl = hl + I.mass * vc
            ha = ha + ca.cross(c, I.mass * vc) + R @ ca.DM(np.array(I.inertia)) @ (R.T @ w)
        return ca.vertcat(hl, ha)

    def generalized_jacobian(self, q, arm: str, X=None):
        """J* = J_m − J_b Ag_b⁻¹ Ag_m (6 × nj, world axes, zero momentum) of an arm's EE;
        the ordinary 6 × nj Jacobian for a fixed base."""
        a = self.robot.arm(arm)
        X = self.joint_placements(q) if X is None else X
        J = self.frame_jacobian(q, a.ee_frame_id, "world_aligned", X)
        if not self.robot.is_floating:
            return J
        Ag = self.centroidal_map(q, X)
        return J[:, 6:] - J[:, :6] @ ca.solve(Ag[:, :6], Ag[:, 6:])

    # ------------------------------------------------------------------ end-effector motion
    def ee_velocity_function(self, arm: str) -> ca.Function:
        """``f(q_joints, q̇_joints) -> v`` (3,) [m/s]: linear velocity of an arm's end-effector
        (world axes). Fixed base: ``J q̇``; free-floating: ``J* q̇`` (zero momentum, base at identity).
        For the quartic-spline NLP (``smooth_quartic(..., ee_velocity=...)``)."""
        a = self.robot.arm(arm)
        qj, qdj = ca.SX.sym("qj", self.robot.nj), ca.SX.sym("qdj", self.robot.nj)
        v = self._ee_jacobian(qj, a.name)[:3, :] @ qdj
        return ca.Function(f"ee_velocity_{arm}", [qj, qdj], [v], ["qj", "qdj"], ["v"])

    def ee_acceleration_function(self, arm: str) -> ca.Function:
        """``f(q, q̇, q̈) -> a`` (3,) [m/s²]: classical linear acceleration of the end-effector
        origin, ``J q̈ + (∂(J q̇)/∂q) q̇`` (world axes; J* for a free-floating robot)."""
        a = self.robot.arm(arm)
        qj, qdj, qddj = (ca.SX.sym(n, self.robot.nj) for n in ("qj", "qdj", "qddj"))
        v = self._ee_jacobian(qj, a.name)[:3, :] @ qdj
        acc = ca.jacobian(v, qj) @ qdj + ca.jacobian(v, qdj) @ qddj
        return ca.Function(f"ee_acceleration_{arm}", [qj, qdj, qddj], [acc], ["qj", "qdj", "qddj"], ["a"])

    def _ee_jacobian(self, qj, arm: str):
        if self.robot.is_floating:
            qfull = ca.vertcat(ca.DM([0, 0, 0, 0, 0, 0, 1.0]), qj)
            return self.generalized_jacobian(qfull, arm)
        return self.frame_jacobian(qj, self.robot.arm(arm).ee_frame_id, "world_aligned")

    # ------------------------------------------------------------------ casadi.Function wrappers
    def _q(self):
        return self.sym.sym("q", self.model.nq)

    def _cached(self, key, build):
        if key not in self._functions:
            self._functions[key] = CheckedFunction(build(), f" of {self.robot.name!r}")
        return self._functions[key]

    def fk_function(self, frame) -> ca.Function:
        """``f(q) -> (R 3×3, p 3)`` world placement of a frame."""
        fid = self.robot.frame_id(frame)

        def build():
            q = self._q()
            R, p = self.frame_placement(q, fid)
            return ca.Function(f"fk_{self.model.frames[fid].name}", [q], [R, p], ["q"], ["R", "p"])
        return self._cached(("fk", fid), build)

    def fk_jacobian_function(self, frame, reference: str = "world_aligned") -> ca.Function:
        """``f(q) -> (R, p, J)``: placement and 6 × nv Jacobian of a frame, one shared recursion."""
        fid = self.robot.frame_id(frame)

        def build():
            q = self._q()
            X = self.joint_placements(q)
            R, p = self.frame_placement(q, fid, X)
            J = self.frame_jacobian(q, fid, reference, X)
            return ca.Function(f"fkj_{self.model.frames[fid].name}", [q], [R, p, J], ["q"], ["R", "p", "J"])
        return self._cached(("fkj", fid, reference), build)

    def jacobian_function(self, frame, reference: str = "world_aligned") -> ca.Function:
        """``f(q) -> J`` (6 × nv)."""
        fid = self.robot.frame_id(frame)

        def build():
            q = self._q()
            return ca.Function(f"jac_{self.model.frames[fid].name}", [q],
                               [self.frame_jacobian(q, fid, reference)], ["q"], ["J"])
        return self._cached(("jac", fid, reference), build)

    def centroidal_map_function(self) -> ca.Function:
        """``f(q) -> Ag`` (6 × nv)."""
        def build():
            q = self._q()
            return ca.Function("centroidal_map", [q], [self.centroidal_map(q)], ["q"], ["Ag"])
        return self._cached(("Ag",), build)

    def generalized_jacobian_function(self, arm: str) -> ca.Function:
        """``f(q) -> J*`` (6 × nj) of an arm's end-effector (see :meth:`generalized_jacobian`)."""
        self.robot.arm(arm)

        def build():
            q = self._q()
            return ca.Function(f"gjac_{arm}", [q], [self.generalized_jacobian(q, arm)], ["q"], ["Jstar"])
        return self._cached(("gjac", arm), build)
