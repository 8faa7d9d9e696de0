"""The Drake peer's model: optplan's robot and scene as a Drake MultibodyPlant with its collision
geometry (:class:`DrakeModel`), and the closed-chain residual written for Drake's autodiff
(:class:`ClosedChainResidual`). Optional: needs ``pydrake`` (``pip install "optplan[drake]"``)."""
from __future__ import annotations

import logging
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

from ..collision.checker import CollisionChecker
from ..geometry.spatial import skew, vee_skew
from ..model.robot import RobotModel
from ..scene import Scene

__all__ = ["DrakeUnavailable", "require_drake", "DrakeModel", "ClosedChainResidual"]
log = logging.getLogger(__name__)


class DrakeUnavailable(ImportError):
    """Drake (``pydrake``) is not installed: ``pip install "optplan[drake]"``."""


def require_drake():
    """``pydrake.all``, or :class:`DrakeUnavailable` naming the extra to install."""
    try:
        import pydrake  # noqa: F401
    except ImportError as exc:
        raise DrakeUnavailable('the Drake peer needs pydrake: pip install "optplan[drake]"') from exc
    import pydrake.all as pd

    return pd


def _rt(M: pin.SE3):
    from pydrake.math import RigidTransform, RotationMatrix

    return RigidTransform(RotationMatrix(np.asarray(M.rotation)), np.asarray(M.translation))


_skew, _vee_skew = skew, vee_skew


# --------------------------------------------------------------------------- model
class DrakeModel:
    """Our robot and scene in a Drake ``MultibodyPlant`` + ``SceneGraph`` diagram.

    The kinematic tree comes from the robot's URDF with its ``<collision>``/``<visual>`` elements
    removed; the collision geometry is registered by hand from optplan's own collision model
    (URDF cylinders named ``*_capsule`` are capsules there, Drake would read cylinders), the
    scene's obstacles on the world body and the held object on ``object_arm``'s hand. The collision
    filter leaves exactly the pairs of :class:`optplan.collision.checker.CollisionChecker` as candidates;
    ``missing_pairs`` lists optplan pairs Drake would not check (empty when the two agree).

    ``to_drake(q)`` / ``from_drake(q)`` map joint vectors between optplan's (Pinocchio's) order
    and the plant's position order.
    """

    def __init__(self, robot: RobotModel, scene: Scene | None, *, object_arm: str | None = None,
                 held_object: bool = True):
        pd = require_drake()
        if robot.is_floating:
            raise ValueError("the Drake peer handles fixed-base robots only (got a free-floating base)")
        if robot.urdf_path is None:
            raise ValueError("the Drake peer loads the robot's URDF: this RobotModel has no urdf_path")
        self.robot, self.scene = robot, scene
        builder = pd.DiagramBuilder()
        plant, sg = pd.AddMultibodyPlantSceneGraph(builder, 0.0)
        root = ET.parse(robot.urdf_path).getroot()
        for link in root.iter("link"):
            for tag in ("collision", "visual"):
                for el in list(link.findall(tag)):
                    link.remove(el)
        children = {c.get("link") for j in root.iter("joint") if (c := j.find("child")) is not None}
        roots = [lk.get("name") for lk in root.iter("link") if lk.get("name") not in children]
        pd.Parser(plant).AddModelsFromString(ET.tostring(root, encoding="unicode"), "urdf")
        if roots and roots[0] != "world":
            plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(roots[0]))
        friction = pd.CoulombFriction(0.5, 0.5)
        # robot capsules/boxes from optplan's collision model (placements relative to the link frame)
        gm, model = robot.collision_model, robot.model
        self.robot_gids: list = []
        for g in gm.geometryObjects:
            frame = model.frames[g.parentFrame]
            body = plant.GetBodyByName(frame.name)
            X = frame.placement.inverse() * g.placement
            self.robot_gids.append(plant.RegisterCollisionGeometry(body, _rt(X), _shape(g.geometry), g.name, friction))
        self.obstacle_gids = []
        obstacles = list(scene.obstacles) if scene is not None else []
        for o in obstacles:
            if o.shape == "box":
                assert o.size is not None  # a box obstacle has its edges (Scene.from_dict requires them)
                shp = pd.Box(*o.size)
            elif o.shape == "sphere":
                shp = pd.Sphere(o.radius)
            else:
                shp = pd.Capsule(o.radius, o.length)
            self.obstacle_gids.append(plant.RegisterCollisionGeometry(plant.world_body(), _rt(o.placement), shp,
                                                                      o.name, friction))
        self.object_gid = None
        obj = scene.object if scene is not None and held_object else None
        has_obj = obj is not None
        self.object_arm = (object_arm or next(iter(obj.grasps))) if obj is not None else None
        if obj is not None and self.object_arm is not None:
            hand = plant.GetFrameByName(robot.arm(self.object_arm).ee_frame).body()
            X_hand_ee = plant.GetFrameByName(robot.arm(self.object_arm).ee_frame).GetFixedPoseInBodyFrame()
            X = X_hand_ee.multiply(_rt(obj.grasps[self.object_arm].inverse()))
            self.object_gid = plant.RegisterCollisionGeometry(hand, X, pd.Box(*obj.size), "object", friction)
        plant.Finalize()
        # collision filter: exactly optplan's pairs
        checker = CollisionChecker(robot, scene, held_object=has_obj, object_arm=self.object_arm)
        self.n_optplan_pairs = len(checker.pairs)
        want = {frozenset((self._gid(p.kind, p.a, "a"), self._gid(p.kind, p.b, "b"))) for p in checker.pairs}
        allg = self.robot_gids + self.obstacle_gids + ([self.object_gid] if self.object_gid is not None else [])
        decl = pd.CollisionFilterDeclaration()
        for i, a in enumerate(allg):
            for b in allg[i + 1:]:
                if frozenset((a, b)) not in want:
                    decl.ExcludeBetween(pd.GeometrySet(a), pd.GeometrySet(b))
        sg.collision_filter_manager().Apply(decl)
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.plant, self.scene_graph = plant, sg
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        inspector = sg.model_inspector()
        have = {frozenset(c) for c in inspector.GetCollisionCandidates()}
        names = {g: inspector.GetName(g) for g in allg}
        self.missing_pairs = sorted(tuple(sorted(names[g] for g in p)) for p in want - have)
        self.extra_pairs = sorted(tuple(sorted(names[g] for g in p)) for p in have - want)
        if self.missing_pairs or self.extra_pairs:
            log.warning("Drake's collision candidates differ from optplan's pairs: %d missing, %d extra",
                        len(self.missing_pairs), len(self.extra_pairs))
        # joint order
        if plant.num_positions() != robot.nj:
            raise ValueError(f"Drake plant has {plant.num_positions()} positions, the robot {robot.nj} joints")
        self._idx = np.array([plant.GetJointByName(n).position_start() for n in robot.joint_names])
        self.lower = self.to_drake(robot.lower)
        self.upper = self.to_drake(robot.upper)
        self.velocity_limit = self.to_drake(robot.velocity_limit)

    def _gid(self, kind: str, idx: int, side: str):
        if idx == -1:
            return self.object_gid
        if kind == "self" or side == "a" or kind == "object-robot":
            return self.robot_gids[idx]
        return self.obstacle_gids[idx]

    @property
    def n_candidate_pairs(self) -> int:
        return len(self.scene_graph.model_inspector().GetCollisionCandidates())

    def to_drake(self, q) -> np.ndarray:
        q = np.asarray(q, float)
        out = np.empty_like(q)
        out[..., self._idx] = q
        return out

    def from_drake(self, q) -> np.ndarray:
        return np.asarray(q, float)[..., self._idx]

    def min_distance(self, q_optplan) -> float:
        """Smallest signed distance [m] over the candidate pairs (Drake's query), at optplan's q."""
        self.plant.SetPositions(self.plant_context, self.to_drake(q_optplan))
        qo = self.plant.get_geometry_query_input_port().Eval(self.plant_context)
        return float(min(p.distance for p in qo.ComputeSignedDistancePairwiseClosestPoints(1e3)))


def _shape(geom):
    from pydrake.geometry import Box, Capsule, Sphere

    name = type(geom).__name__
    if name == "Capsule":
        return Capsule(geom.radius, 2.0 * geom.halfLength)
    if name == "Box":
        return Box(*(2.0 * np.asarray(geom.halfSide)))
    if name == "Sphere":
        return Sphere(geom.radius)
    raise ValueError(f"collision geometry {name}: the Drake peer handles capsules, boxes and spheres")


# --------------------------------------------------------------------------- closed chain
class ClosedChainResidual:
    """optplan's closed-chain residual written with Drake's kinematics: with ``X = T_a⁻¹ T_b`` the
    relative pose of the two hands and ``(R_t, p_t)`` the required one,
    ``r = [p − p_t; vee(E − Eᵀ)/2; trace(E)]`` with ``E = R_tᵀ R`` (rows 0-5 must be 0, row 6
    ≥ 1). Exact Jacobian from ``CalcJacobianSpatialVelocity`` of hand b measured and expressed in
    hand a's frame. Call with a Drake-ordered float or AutoDiffXd vector (what a Drake
    ``Constraint`` receives)."""

    def __init__(self, dm: DrakeModel, closed_chain, trace_row: bool = True):
        self.dm = dm
        self.plant = dm.plant
        # its own context, so that the min-distance constraint's cached kinematics are not shared
        self.context = dm.plant.CreateDefaultContext()
        self.fa = dm.plant.GetFrameByName(dm.robot.arm(closed_chain.arm_a).ee_frame)
        self.fb = dm.plant.GetFrameByName(dm.robot.arm(closed_chain.arm_b).ee_frame)
        self.Rt = np.asarray(closed_chain.relative.rotation)
        self.pt = np.asarray(closed_chain.relative.translation)
        self.trace_row = bool(trace_row)
        self.n_rows = 7 if trace_row else 6
        # d vee_skew(Rtᵀ [w]× R)/dw and d trace(...)/dw are linear in w: precomputed per call from R
        self._E = [_skew(e) for e in np.eye(3)]

    @property
    def lower(self) -> np.ndarray:
        return np.r_[np.zeros(6), 1.0][: self.n_rows]

    @property
    def upper(self) -> np.ndarray:
        return np.r_[np.zeros(6), np.inf][: self.n_rows]

    def value_and_jacobian(self, q_drake) -> tuple[np.ndarray, np.ndarray]:
        from pydrake.multibody.tree import JacobianWrtVariable

        p = self.plant
        p.SetPositions(self.context, np.asarray(q_drake, float))
        X = p.CalcRelativeTransform(self.context, self.fa, self.fb)
        R, t = X.rotation().matrix(), X.translation()
        E = self.Rt.T @ R
        r = np.r_[t - self.pt, _vee_skew(E), np.trace(E)]
        J = p.CalcJacobianSpatialVelocity(self.context, JacobianWrtVariable.kQDot, self.fb, np.zeros(3),
                                          self.fa, self.fa)  # rows [ω; v] of b in a, expressed in a
        L = np.column_stack([_vee_skew(self.Rt.T @ S @ R) for S in self._E])     # d r_rot / d ω
        tr = np.array([np.trace(self.Rt.T @ S @ R) for S in self._E])            # d trace / d ω
        Jr = np.vstack([J[3:], L @ J[:3], tr @ J[:3]])
        return r[: self.n_rows], Jr[: self.n_rows]

    def __call__(self, x):
        x = np.asarray(x)
        if x.dtype == object:
            from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff

            v = ExtractValue(x).ravel()
            G = ExtractGradient(x)
            r, J = self.value_and_jacobian(v)
            return InitializeAutoDiff(r, J @ G).ravel()
        return self.value_and_jacobian(x)[0]

    def constraint(self):
        """A Drake ``Constraint`` (nq → n_rows) evaluating this residual."""
        from pydrake.solvers import MathematicalProgram

        prog = MathematicalProgram()
        q = prog.NewContinuousVariables(self.plant.num_positions(), "q")
        b = prog.AddConstraint(self, self.lower, self.upper, q, description="closed_chain")
        self._keep = prog  # the evaluator refers to this callable only; keep the program alive anyway
        return b.evaluator()


# --------------------------------------------------------------------------- B-spline helpers
