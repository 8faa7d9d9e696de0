"""Orientation constraints of a dual-arm robot, shared by OC-RRT, CBiRRT and the OMPL peers.

:class:`DualArmOrientationConstraint` describes one of two task modes:

* ``"open"`` (open chain, e.g. two cups of water): each hand keeps its own world orientation
  ``R_hands[arm]``; positions are free.
* ``"closed"`` (closed chain, e.g. a tray held by both hands): the active hand keeps its world
  orientation and the passive hand keeps a fixed pose ``T_rel`` in the active hand's frame
  (relative position and orientation), so its world orientation is fixed too.

It gives the residual ``h(q)`` and Jacobian for projection planners (CBiRRT, OMPL) with TSR-style
bounds on the orientation error (``orientation_bounds`` [rad] per world axis: 0 = fixed,
``(-inf, inf)`` = free axis; the residual is the part of the error outside the bounds), and the
per-configuration errors used for ORMSD / PRMSD. The analytic parameterisation that OC-RRT uses
(sample q1..q4 of each arm, or q1..q4 of the active arm and the passive arm's redundancy angle)
lives in :class:`OrientationManifold`.

Errors: orientation error of a hand ``e_o = log(R_dᵀ R)`` [rad] (world-axis rotation vector for
the bounds: ``R e_o``); relative pose error ``log6(T_relᵀ T_1⁻¹ T_2)`` ([m], [rad]).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..errors import ConfigurationError
from ..ik_analytic import DecoupledArmIK
from ..robot import RobotModel
from ..scene import Scene
from ..spatial import rpy_to_matrix

__all__ = ["DualArmOrientationConstraint", "OrientationManifold", "constraint_from_scene", "endpoints_from_scene"]


@dataclass
class DualArmOrientationConstraint:
    """See the module docstring. ``R_hands``: world orientation of each hand (open mode: both
    arms; closed mode: the active arm's is used); ``T_rel``: passive hand pose in the active hand
    frame (closed mode); ``orientation_bounds``: 3 × 2 array, world-axis bounds [rad] on each
    hand's orientation error (default all zero: orientation fixed)."""

    robot: RobotModel
    mode: str
    R_hands: dict
    active: str = "left"
    passive: str = "right"
    T_rel: pin.SE3 | None = None
    orientation_bounds: np.ndarray = field(default_factory=lambda: np.zeros((3, 2)))

    def __post_init__(self):
        if self.mode not in ("open", "closed"):
            raise ConfigurationError(f"mode: expected 'open' or 'closed', got {self.mode!r}")
        self.robot.arm(self.active)
        self.robot.arm(self.passive)
        if self.active == self.passive:
            raise ConfigurationError("active and passive arm must differ")
        if self.mode == "closed" and self.T_rel is None:
            raise ConfigurationError("closed mode needs T_rel (passive hand pose in the active hand frame)")
        need = [self.active, self.passive] if self.mode == "open" else [self.active]
        for a in need:
            if a not in self.R_hands:
                raise ConfigurationError(f"R_hands: missing the orientation of arm {a!r}")
            R = np.asarray(self.R_hands[a], float)
            if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9):
                raise ConfigurationError(f"R_hands[{a!r}]: expected a rotation matrix, got {R!r}")
        b = np.asarray(self.orientation_bounds, float)
        if b.shape != (3, 2) or np.any(b[:, 0] > 0) or np.any(b[:, 1] < 0):
            raise ConfigurationError(f"orientation_bounds: expected 3 × 2 [lo <= 0 <= hi] per world axis, got {b!r}")
        self.orientation_bounds = b
        if self.mode == "closed":
            self.R_hands = dict(self.R_hands)
            self.R_hands[self.passive] = np.asarray(self.R_hands[self.active]) @ self.T_rel.rotation
        self.fids = {a: self.robot.arm(a).ee_frame_id for a in (self.active, self.passive)}
        self.data = self.robot.model.createData()
        self.dim = 6 if self.mode == "open" else 9
        self.ambient_dim = self.robot.nq

    # ------------------------------------------------------------------ residual (projection planners)
    def _orientation_rows(self, arm: str, with_jac: bool):
        m, d = self.robot.model, self.data
        R = d.oMf[self.fids[arm]].rotation
        Rd = np.asarray(self.R_hands[arm])
        Rerr = Rd.T @ R
        e_loc = pin.log3(Rerr)
        e = Rd @ e_loc                     # world-axis rotation vector
        lo, hi = self.orientation_bounds[:, 0], self.orientation_bounds[:, 1]
        h = e - np.clip(e, lo, hi)
        if not with_jac:
            return h, None
        Jl = pin.getFrameJacobian(m, d, self.fids[arm], pin.ReferenceFrame.LOCAL)[3:]
        J = Rd @ pin.Jlog3(Rerr) @ Jl
        J[(e > lo) & (e < hi)] = 0.0       # inside a free / bounded axis: no pull
        return h, J

    def _relative_rows(self, with_jac: bool):
        m, d = self.robot.model, self.data
        T1, T2 = d.oMf[self.fids[self.active]], d.oMf[self.fids[self.passive]]
        Terr = self.T_rel.actInv(T1.actInv(T2))
        h = pin.log6(Terr).vector
        if not with_jac:
            return h, None
        J1 = pin.getFrameJacobian(m, d, self.fids[self.active], pin.ReferenceFrame.LOCAL)
        J2 = pin.getFrameJacobian(m, d, self.fids[self.passive], pin.ReferenceFrame.LOCAL)
        Ad21 = (T2.actInv(T1)).toActionMatrix()
        return h, pin.Jlog6(Terr) @ (J2 - Ad21 @ J1)

    def h_jacobian(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Residual (``dim``) and its Jacobian (``dim × nq``) at q."""
        m, d = self.robot.model, self.data
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacements(m, d)
        if self.mode == "open":
            ha, Ja = self._orientation_rows(self.active, True)
            hb, Jb = self._orientation_rows(self.passive, True)
            return np.r_[ha, hb], np.vstack([Ja, Jb])
        ha, Ja = self._orientation_rows(self.active, True)
        hr, Jr = self._relative_rows(True)
        return np.r_[ha, hr], np.vstack([Ja, Jr])

    def h(self, q) -> np.ndarray:
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        if self.mode == "open":
            return np.r_[self._orientation_rows(self.active, False)[0], self._orientation_rows(self.passive, False)[0]]
        return np.r_[self._orientation_rows(self.active, False)[0], self._relative_rows(False)[0]]

    # ------------------------------------------------------------------ metrics
    def errors(self, q) -> tuple[float, float]:
        """(orientation error [rad]: the larger of the two hands' ``|log(R_dᵀ R)|``, relative
        position error [m] of the passive hand in the active hand frame; 0 in open mode)."""
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        d = self.data
        eo = max(float(np.linalg.norm(pin.log3(np.asarray(self.R_hands[a]).T @ d.oMf[self.fids[a]].rotation)))
                 for a in (self.active, self.passive))
        ep = 0.0
        if self.mode == "closed":
            T1, T2 = d.oMf[self.fids[self.active]], d.oMf[self.fids[self.passive]]
            ep = float(np.linalg.norm(T1.actInv(T2).translation - self.T_rel.translation))
        return eo, ep

    def rmsd(self, path: np.ndarray) -> tuple[float, float]:
        """(ORMSD [rad], PRMSD [m]) of a path: root mean square of :meth:`errors` over its rows
        (PRMSD is NaN in open mode)."""
        E = np.array([self.errors(q) for q in path])
        o = float(np.sqrt(np.mean(E[:, 0] ** 2)))
        p = float(np.sqrt(np.mean(E[:, 1] ** 2))) if self.mode == "closed" else float("nan")
        return o, p

    def hand_pose(self, q, arm: str) -> pin.SE3:
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        return self.data.oMf[self.fids[arm]].copy()

    def object_pose(self, q):
        return None


class OrientationManifold:
    """The analytic parameterisation of a :class:`DualArmOrientationConstraint` (fixed
    orientations, no free axes) used by OC-RRT.

    Parameters ``p``: open mode ``[q1..q4 of the active arm, q1..q4 of the passive arm]`` (8);
    closed mode ``[q1..q4 of the active arm, q1 of the passive arm]`` (5). :meth:`complete` maps
    ``p`` to every configuration on the manifold (wrist in closed form, passive arm by the
    redundancy-angle IK) and picks the branch nearest to a reference configuration.
    """

    def __init__(self, constraint: DualArmOrientationConstraint):
        c = constraint
        if np.any(c.orientation_bounds != 0.0):
            raise ConfigurationError("OC-RRT's analytic parameterisation needs fixed orientations "
                                     "(orientation_bounds all zero)")
        self.c = c
        self.robot = c.robot
        self.ik = {a: DecoupledArmIK(c.robot, a) for a in (c.active, c.passive)}
        ia, ip = self.ik[c.active], self.ik[c.passive]
        self.ia, self.ip = ia.q_idx, ip.q_idx
        if c.mode == "open":
            self.p_idx = np.r_[ia.q_idx[:4], ip.q_idx[:4]]
        else:
            self.p_idx = np.r_[ia.q_idx[:4], ip.q_idx[:1]]
        self.lower = c.robot.lower[self.p_idx]
        self.upper = c.robot.upper[self.p_idx]
        self.dim = len(self.p_idx)
        self.n_complete = 0

    def params(self, q) -> np.ndarray:
        return np.asarray(q, float)[self.p_idx]

    def _pick(self, sols: np.ndarray, ref, rng):
        if len(sols) == 0:
            return None
        if ref is not None:
            return sols[int(np.argmin(np.abs(sols - ref).max(axis=1)))]
        if rng is not None:
            return sols[int(rng.integers(len(sols)))]
        return sols[0]

    def complete(self, p, ref: np.ndarray | None = None, rng: np.random.Generator | None = None) -> np.ndarray | None:
        """The configuration on the manifold with parameters ``p``: the branch (wrist / passive
        arm solution) nearest to ``ref`` (max-norm), else a random one (``rng``), else the first.
        None when the parameters admit no solution inside the joint limits."""
        self.n_complete += 1
        c = self.c
        q = np.empty(self.robot.nq)
        ia, ip = self.ik[c.active], self.ik[c.passive]
        pa = p[:4]
        W = ia.wrist(pa, c.R_hands[c.active])
        w = self._pick(W, None if ref is None else ref[self.ia[4:]], rng)
        if w is None:
            return None
        q[self.ia[:4]] = pa
        q[self.ia[4:]] = w
        if c.mode == "open":
            W = ip.wrist(p[4:8], c.R_hands[c.passive])
            w = self._pick(W, None if ref is None else ref[self.ip[4:]], rng)
            if w is None:
                return None
            q[self.ip[:4]] = p[4:8]
            q[self.ip[4:]] = w
            return q
        R1, p1 = ia.fk(q[self.ia])
        T2 = pin.SE3(R1, p1) * c.T_rel
        S = ip.solve(T2.rotation, T2.translation, float(p[4]))
        s = self._pick(S, None if ref is None else ref[self.ip], rng)
        if s is None:
            return None
        q[self.ip] = s
        return q


def constraint_from_scene(robot: RobotModel, scene: Scene) -> DualArmOrientationConstraint:
    """The orientation task of a scene's ``[extra]`` table: ``mode`` ("open"/"closed"),
    ``active``/``passive`` arm names, ``hand_rpy`` = {arm: [r, p, y]} (scene angle unit: deg) and,
    in closed mode, the ``[object]`` grasps of the two arms (``T_rel = G_active⁻¹ G_passive``)."""
    ex = scene.extra
    mode = ex.get("mode")
    active, passive = ex.get("active", "left"), ex.get("passive", "right")
    rpy = ex.get("hand_rpy", {})
    unit = math.pi / 180.0 if ex.get("angle_unit", "deg") == "deg" else 1.0
    R = {a: rpy_to_matrix(*(np.asarray(v, float) * unit)) for a, v in rpy.items()}
    T_rel = None
    if mode == "closed":
        if scene.object is None or not {active, passive} <= set(scene.object.grasps):
            raise ConfigurationError(f"scene {scene.name!r}: closed mode needs [object] grasps for {active!r} and {passive!r}")
        T_rel = scene.object.grasps[active].inverse() * scene.object.grasps[passive]
    return DualArmOrientationConstraint(robot, mode, R, active, passive, T_rel)


def endpoints_from_scene(manifold: OrientationManifold, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Start and goal configurations of an orientation task scene: ``[extra]`` ``start_params`` /
    ``goal_params`` [rad] (the manifold parameters, see :class:`OrientationManifold`); the start on
    the branch nearest ``reference_q`` [rad] (default: all joints 0), the goal on the branch reached
    from the start along the straight parameter line (so that a continuous path exists within the
    ±2π roll limits), else the one nearest the start."""
    ex = scene.extra
    ref = np.asarray(ex.get("reference_q", np.zeros(manifold.robot.nq)), float)
    ps = []
    for key in ("start_params", "goal_params"):
        if key not in ex:
            raise ConfigurationError(f"scene {scene.name!r}: [extra] has no {key!r}")
        p = np.asarray(ex[key], float)
        if p.shape != (manifold.dim,):
            raise ConfigurationError(f"scene {scene.name!r}: {key} has {p.size} values, expected {manifold.dim}")
        ps.append(p)
    qs = manifold.complete(ps[0], ref=ref)
    if qs is None:
        raise ConfigurationError(f"scene {scene.name!r}: start_params {ps[0].tolist()} have no IK solution in the limits")
    # the goal on the same IK branch / 2π sheet as the start: follow the straight parameter line
    # (collisions ignored), else the solution nearest the start
    q = qs
    for s in np.linspace(0.0, 1.0, 201)[1:]:
        x = manifold.complete(ps[0] + s * (ps[1] - ps[0]), ref=q)
        if x is None or np.abs(x - q).max() > 0.3:
            q = None
            break
        q = x
    qg = q if q is not None else manifold.complete(ps[1], ref=qs)
    if qg is None:
        raise ConfigurationError(f"scene {scene.name!r}: goal_params {ps[1].tolist()} have no IK solution in the limits")
    return qs, qg
