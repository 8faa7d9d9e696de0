"""The closed chain of two hands holding one rigid object — the one place it is defined.

Two end-effectors ``a``, ``b`` keep their relative pose ``T_a⁻¹ T_b = relative`` (hand b in hand a's
frame; for an object held with grasp frames ``G_a``, ``G_b`` in the object frame, ``relative =
G_a⁻¹ G_b``; the TCBiRRT paper Eq. 1-2). Its residual is the singularity-free pose residual of
:func:`optplan.geometry.spatial.pose_residual` of the relative pose against ``relative``:
``h = [p_rel − p*; vee((E − Eᵀ)/2)]`` with ``E = R*ᵀ R_rel`` (position [m], sin θ · axis), with
``trace(E) ≥ 1`` excluding the spurious θ = π zero. Everything that needs the closed chain calls
this module:

* :func:`relative_pose_residual` — the residual from the two hands' placements (numpy or CasADi),
  used by the NLP term :class:`~optplan.problem.ClosedChain` and the paper methods;
* :func:`closed_chain_residual` — ``(h, ∂h/∂q)`` numerically with Pinocchio (exact Jacobian);
* :func:`project_closed_chain` — Newton–Raphson projection with minimum-norm steps;
* :func:`manifold_resample` — a planner's path resampled by joint-space arc length, each sample
  projected (the warm start of the trajectory NLPs);
* :func:`closure_error` — the independent check (position error [m], rotation angle [rad]);
* :func:`solve_grasp_ik` — damped least-squares IK of both hands onto an object pose;
* :class:`ClosedChainKinematics` — the same residual, its Jacobian and the two-hand IK step of the
  TCBiRRT paper's Alg. 4 as CasADi expressions compiled to C for the planners' hot loops
  (:class:`optplan.codegen.FastFunction`, ~5 µs per call for both arms' FK, Jacobians and damped
  least-squares step; without a C compiler the interpreted CasADi functions are used).
"""
from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import casadi as ca
import numpy as np
import pinocchio as pin

from ..codegen import FastFunction, MemoFunctions, memo_functions
from ..errors import ConfigurationError
from ..geometry.spatial import check_pose, pose_residual, rotation_angle, skew, vee_skew
from ..geometry.splines import resample_path
from ..model.ik import IKOptions, IKResult, solve_multi
from ..model.robot import RobotModel
from ..model.symbolic import SymbolicKinematics

__all__ = ["relative_pose_residual", "closed_chain_residual", "project_closed_chain", "ProjectionResult",
           "closure_error", "closure_errors", "manifold_resample", "solve_grasp_ik", "IKSettings", "ClosedChainKinematics", "ChainSpec"]
log = logging.getLogger(__name__)


class ChainLike(Protocol):
    """Anything that describes a closed chain: :class:`ChainSpec`, :class:`~optplan.problem.ClosedChain`."""

    @property
    def arm_a(self) -> str: ...
    @property
    def arm_b(self) -> str: ...
    @property
    def relative(self) -> pin.SE3: ...


@dataclass(frozen=True)
class ChainSpec:
    """The closed chain as data: arm names ``arm_a``, ``arm_b`` and ``relative`` = ``T_a⁻¹ T_b``
    (any object with these three attributes, e.g. :class:`~optplan.problem.ClosedChain`, is
    accepted where a chain is expected)."""

    arm_a: str
    arm_b: str
    relative: pin.SE3

    @classmethod
    def from_grasps(cls, grasps: dict[str, pin.SE3]) -> ChainSpec:
        """Both hands on one object: ``grasps`` = {arm: grasp frame in the object frame} (two arms)."""
        if not isinstance(grasps, dict) or len(grasps) != 2:
            raise ConfigurationError(f"grasps: expected a dict of two arms {{arm: pinocchio.SE3}}, got {grasps!r}")
        a, b = list(grasps)
        return cls(a, b, grasps[a].actInv(grasps[b]))


def relative_pose_residual(Ra: Any, pa: Any, Rb: Any, pb: Any, relative: pin.SE3) -> tuple[Any, Any]:
    """``(h (6), trace(E))`` of hand b's pose in hand a's frame, ``(Raᵀ Rb, Raᵀ (pb − pa))``,
    against ``relative`` (CasADi when the placements are CasADi, numpy otherwise)."""
    Rt, pt = np.array(relative.rotation), np.array(relative.translation)
    if isinstance(Ra, (ca.SX, ca.MX)) or isinstance(pa, (ca.SX, ca.MX)):
        return pose_residual(Ra.T @ Rb, Ra.T @ (pb - pa), Rt, ca.DM(pt))
    return pose_residual(Ra.T @ Rb, Ra.T @ (pb - pa), Rt, pt)


@dataclass(frozen=True)
class ProjectionResult:
    """Result of :func:`project_closed_chain`: configuration ``q``, ``success``, Newton
    ``iterations``, final ``residual`` ‖h‖∞ ([m] / [rad])."""

    q: np.ndarray
    success: bool
    iterations: int
    residual: float


def closed_chain_residual(robot: RobotModel, q: np.ndarray, closed_chain: ChainLike,
                          data: pin.Data | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(h (6,), J_h (6 × nv))``: the closed-chain residual (module docstring) at the full
    configuration ``q``, expressed in hand a's frame, and its exact Jacobian. ``closed_chain``: any
    object with ``arm_a``, ``arm_b``, ``relative`` (:class:`ChainSpec`, the NLP term)."""
    data = data or robot.model.createData()
    a, b = robot.arm(closed_chain.arm_a), robot.arm(closed_chain.arm_b)
    model = robot.model
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    Ma, Mb = data.oMf[a.ee_frame_id], data.oMf[b.ee_frame_id]
    h, _ = relative_pose_residual(Ma.rotation, Ma.translation, Mb.rotation, Mb.translation, closed_chain.relative)
    E = closed_chain.relative.rotation.T @ Ma.rotation.T @ Mb.rotation
    LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    Ja = pin.getFrameJacobian(model, data, a.ee_frame_id, LWA)
    Jb = pin.getFrameJacobian(model, data, b.ee_frame_id, LWA)
    Jlin = Ma.rotation.T @ (Jb[:3] - Ja[:3] + skew(Mb.translation - Ma.translation) @ Ja[3:])
    # Ė = E [ω]× with ω = R_bᵀ (ω_b − ω_a) (body rate), and d vee((E − Eᵀ)/2) = ½ (tr E · I − Eᵀ) ω
    Jang = 0.5 * (np.trace(E) * np.eye(3) - E.T) @ Mb.rotation.T @ (Jb[3:] - Ja[3:])
    return h, np.vstack([Jlin, Jang])


#: compiled ``(q, vec(R*), p*) -> [h; vec(∂h/∂q)]`` per (robot model, arm a, arm b); None: not available
_RESIDUAL_FNS: dict[tuple[int, str, str], tuple[Any, FastFunction | None]] = {}


def _compiled_residual(robot: RobotModel, arm_a: str, arm_b: str) -> FastFunction | None:
    """The closed-chain residual and its Jacobian with respect to the full ``q`` as one compiled
    function of ``(q, vec(relative rotation), relative translation)`` (fixed-base robots; None
    for a floating base or without a C compiler). Built once per robot and arm pair in a process;
    the compiled library is cached on disk."""
    key = (id(robot.model), arm_a, arm_b)
    got = _RESIDUAL_FNS.get(key)
    if got is not None:
        return got[1]
    fn = None
    if not robot.is_floating and robot.model.nq == robot.model.nv:
        from ..model.digest import kinematics_digest

        def build() -> dict[str, ca.Function]:
            sk = SymbolicKinematics(robot)
            q = ca.SX.sym("q", robot.nq)
            Rt, pt = ca.SX.sym("Rt", 3, 3), ca.SX.sym("pt", 3)
            X = sk.joint_placements(q)
            Ra, pa = sk.frame_placement(q, robot.arm(arm_a).ee_frame_id, X)
            Rb, pb = sk.frame_placement(q, robot.arm(arm_b).ee_frame_id, X)
            h, _ = pose_residual(Ra.T @ Rb, Ra.T @ (pb - pa), Rt, pt)
            return {"hj": ca.Function("closed_chain_hj", [q, ca.vec(Rt), pt],
                                      [ca.vertcat(h, ca.vec(ca.densify(ca.jacobian(h, q))))])}

        fast = FastFunction.of(memo_functions("closed_chain_hj", (kinematics_digest(robot), arm_a, arm_b), build),
                               "hj", "-O1")
        fn = fast if fast.compiled else None
    _RESIDUAL_FNS[key] = (robot.model, fn)      # the model is kept alive so that its id stays unique
    return fn


def project_closed_chain(robot: RobotModel, q: np.ndarray, closed_chain: ChainLike, *, tol: float = 1e-10,
                         max_iterations: int = 50, data: pin.Data | None = None, joints: Any = None,
                         clip: bool = True) -> ProjectionResult:
    """Newton–Raphson projection of the full configuration ``q`` onto ``T_a⁻¹ T_b = relative``
    with minimum-norm steps ``dq = −J⁺ h``. ``joints``: indices into the joint vector that may move
    (default: both arms' joints); ``clip``: keep them within the joint limits. ``tol`` on ‖h‖∞
    ([m], [rad]). On a fixed-base robot the residual and its Jacobian come from one compiled
    function (the same values as :func:`closed_chain_residual`, which is used otherwise)."""
    q = np.array(robot.check_q(q), float)
    if joints is None:
        arms = (robot.arm(closed_chain.arm_a), robot.arm(closed_chain.arm_b))
        j_idx = np.concatenate([a.j_idx for a in arms])
    else:
        j_idx = np.asarray(joints, dtype=int)
    off_q, off_v = robot.nq - robot.nj, robot.model.nv - robot.nj   # floating base: 7 / 6
    qidx, cols = j_idx + off_q, j_idx + off_v
    lo, hi = robot.lower[j_idx], robot.upper[j_idx]
    fast = _compiled_residual(robot, closed_chain.arm_a, closed_chain.arm_b)
    if fast is not None:
        rel = closed_chain.relative
        Rt = np.asarray(rel.rotation).reshape(-1, order="F")
        pt = np.asarray(rel.translation)
        nq = robot.nq
    else:
        data = data or robot.model.createData()
    reg = 1e-12 * np.eye(6)
    res = np.inf
    for it in range(max_iterations + 1):
        if fast is not None:
            out = fast(q, Rt, pt)
            h, Jc = out[:6], out[6:].reshape(6, nq, order="F")[:, cols]
        else:
            h, J = closed_chain_residual(robot, q, closed_chain, data)
            Jc = J[:, cols]
        res = float(np.abs(h).max())
        if res < tol:
            return ProjectionResult(q, True, it, res)
        if it == max_iterations:
            break
        dq = -Jc.T @ np.linalg.solve(Jc @ Jc.T + reg, h)
        q[qidx] = np.clip(q[qidx] + dq, lo, hi) if clip else q[qidx] + dq
    return ProjectionResult(q, False, max_iterations, res)


def closure_error(robot: RobotModel, grasps_or_chain: dict[str, pin.SE3] | ChainLike, q: np.ndarray, data: pin.Data | None = None) -> tuple[float, float]:
    """Independent check with Pinocchio FK: ``(position error [m], rotation angle [rad])`` of the
    hands' relative pose at ``q`` against the chain's (``grasps_or_chain``: {arm: grasp frame} of
    two arms, or an object with ``arm_a``, ``arm_b``, ``relative``); the measure of
    :func:`optplan.verify`."""
    cc: ChainLike = ChainSpec.from_grasps(grasps_or_chain) if isinstance(grasps_or_chain, dict) else grasps_or_chain
    data = data or robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, np.asarray(q, float))
    rel = data.oMf[robot.arm(cc.arm_a).ee_frame_id].actInv(data.oMf[robot.arm(cc.arm_b).ee_frame_id])
    err = cc.relative.actInv(rel)
    return float(np.linalg.norm(err.translation)), rotation_angle(err.rotation)


def closure_errors(robot: RobotModel, grasps_or_chain: dict[str, pin.SE3] | ChainLike, Q: np.ndarray,
                   data: pin.Data | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`closure_error` at every row of ``Q`` (M × nq): ``(position errors [m] (M,), rotation
    angles [rad] (M,))``, Pinocchio FK of the two hands per row and the error arithmetic in numpy."""
    cc: ChainLike = ChainSpec.from_grasps(grasps_or_chain) if isinstance(grasps_or_chain, dict) else grasps_or_chain
    Q = np.asarray(Q, float)
    if Q.ndim != 2 or Q.shape[1] != robot.nq:
        raise ValueError(f"Q: expected an (M, {robot.nq}) array of configurations, got shape {Q.shape}")
    model = robot.model
    data = data or model.createData()
    fa, fb = robot.arm(cc.arm_a).ee_frame_id, robot.arm(cc.arm_b).ee_frame_id
    M = len(Q)
    Ra, Rb, pa, pb = np.empty((M, 3, 3)), np.empty((M, 3, 3)), np.empty((M, 3)), np.empty((M, 3))
    for i, q in enumerate(Q):
        pin.forwardKinematics(model, data, q)
        A = pin.updateFramePlacement(model, data, fa)
        B = pin.updateFramePlacement(model, data, fb)
        Ra[i], pa[i], Rb[i], pb[i] = A.rotation, A.translation, B.rotation, B.translation
    Rt, pt = np.asarray(cc.relative.rotation), np.asarray(cc.relative.translation)
    RaT = np.transpose(Ra, (0, 2, 1))
    p_rel = np.einsum("mij,mj->mi", RaT, pb - pa)                 # hand b in hand a
    E = np.einsum("ji,mjk->mik", Rt, RaT @ Rb)                     # Rtᵀ R_rel
    pos = np.linalg.norm(p_rel - pt, axis=1)                       # |Rtᵀ (p_rel − pt)|
    v = 0.5 * np.stack([E[:, 2, 1] - E[:, 1, 2], E[:, 0, 2] - E[:, 2, 0], E[:, 1, 0] - E[:, 0, 1]], axis=1)
    c = np.clip((np.trace(E, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return pos, np.arctan2(np.linalg.norm(v, axis=1), c)


def solve_grasp_ik(robot: RobotModel, object_pose: pin.SE3, grasps: dict[str, pin.SE3], q0: np.ndarray,
                   options: IKOptions | None = None, data: pin.Data | None = None, *,
                   checker: Any = None, min_clearance: float = 0.0, restarts: int = 0,
                   rng: np.random.Generator | None = None) -> IKResult:
    """Closed-chain IK: every arm in ``grasps`` puts its end-effector on
    ``object_pose * grasps[arm]`` (grasp frames in the object frame); damped least squares
    (:class:`~optplan.model.ik.IKOptions`) from ``q0``.

    With a ``checker`` (:class:`~optplan.collision.checker.CollisionChecker`, e.g. of the scene
    with the object held) a converged configuration closer than ``min_clearance`` [m] (exact
    coal distance) is rejected: it is repaired by up to ``restarts`` solves from random
    configurations (``rng``), and if none is clear the result has ``success`` False and
    ``status`` ``"in_collision"`` (the closest-to-clear configuration found, its clearance)."""
    check_pose(object_pose, "solve_grasp_ik: object_pose")
    if not isinstance(grasps, dict) or not grasps:
        raise ConfigurationError(f"solve_grasp_ik: grasps: expected a dict {{arm: pinocchio.SE3}}, got {grasps!r}")
    for a, g in grasps.items():
        check_pose(g, f"solve_grasp_ik: grasps[{a!r}]")
    if isinstance(restarts, bool) or not isinstance(restarts, (int, np.integer)) or restarts < 0:
        raise ConfigurationError(f"solve_grasp_ik: restarts: expected an integer ≥ 0, got {restarts!r}")
    if restarts and not isinstance(rng, np.random.Generator):
        raise ConfigurationError(f"solve_grasp_ik: restarts={restarts} needs rng (a numpy.random.Generator), got {rng!r}")
    targets = [(a, object_pose * g) for a, g in grasps.items()]
    data = data or robot.model.createData()
    res = solve_multi(robot, data, q0, targets, options or IKOptions())
    if checker is None:
        return res
    best: IKResult | None = None
    for k in range(int(restarts) + 1):
        if k:
            assert rng is not None
            res = solve_multi(robot, data, robot.random_configuration(rng), targets, options or IKOptions())
        if not res.success:
            continue
        d = float(checker.min_distance(res.q)[0])
        if d >= min_clearance:
            return dataclasses.replace(res, clearance=d)
        if best is None or d > best.clearance:
            best = dataclasses.replace(res, success=False, status="in_collision", clearance=d)
    return best if best is not None else res


def manifold_resample(robot: RobotModel, path: Any, n: int, closed_chain: ChainLike | None = None) -> tuple[np.ndarray, bool]:
    """``n`` configurations uniform in joint-space arc length along ``path`` (M × nq), each
    projected onto the closed-chain manifold when ``closed_chain`` is given. Returns the array and
    whether every projection converged."""
    path = np.asarray(path, float)
    if path.ndim != 2 or path.shape[1] != robot.nq or path.shape[0] < 2:
        raise ValueError(f"path: expected (M ≥ 2, {robot.nq}) configurations, got shape {path.shape}")
    _, Q = resample_path(path, int(n))
    if closed_chain is None:
        return Q, True
    ok = True
    data = robot.model.createData()
    for i in range(1, len(Q) - 1):
        r = project_closed_chain(robot, Q[i], closed_chain, data=data)
        Q[i] = r.q
        ok &= r.success
    return Q, bool(ok)


@dataclass(frozen=True)
class IKSettings:
    """Alg. 4 of the TCBiRRT paper (per-arm iterations ``q ← q + λ J† K e``)."""

    #: ε_p: tolerance on each hand's position error (Eq. 5) [m].
    tol_position: float = 1e-7
    #: ε_o: tolerance on each hand's orientation error (Eq. 6) [rad].
    tol_orientation: float = 1e-7
    #: n: iterations per solve [count].
    max_iterations: int = 30
    #: K·λ: scalar step gain [-] (1 = Newton step).
    gain: float = 1.0
    #: δ of the damped pseudo-inverse ``Jᵀ (J Jᵀ + δ² I)⁻¹`` [-] (δ → 0 is the paper's pseudo-inverse; a small δ
    #: keeps the step bounded near singularities).
    damping: float = 1e-4
    #: Largest joint change per iteration [rad].
    max_step: float = 0.5

    def __post_init__(self) -> None:
        for name in ("tol_position", "tol_orientation", "gain", "max_step"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise ValueError(f"IKSettings.{name}: expected a positive number, got {v!r}")
        if not (isinstance(self.damping, (int, float)) and np.isfinite(self.damping) and self.damping >= 0):
            raise ValueError(f"IKSettings.damping: expected a number >= 0, got {self.damping!r}")
        if not (isinstance(self.max_iterations, int) and self.max_iterations >= 1):
            raise ValueError(f"IKSettings.max_iterations: expected an int >= 1, got {self.max_iterations!r}")



def _vee_log(R: ca.SX) -> ca.SX:
    """Rotation vector of a CasADi 3 × 3 rotation (exact away from π; Appendix Eq. 12-14)."""
    v = vee_skew(R)
    s = ca.norm_2(v)
    c = (R[0, 0] + R[1, 1] + R[2, 2] - 1.0) / 2.0
    th = ca.atan2(s, c)
    return v * ca.if_else(s > 1e-12, th / ca.fmax(s, 1e-300), 1.0)


class ClosedChainKinematics:
    """Kinematics of two arms holding one rigid object.

    ``grasps``: arm name → grasp frame in the object frame (``scene.object.grasps``); the first
    arm is the paper's arm 1 (the object pose is read from its hand). Configurations are the
    robot's full ``q`` (fixed base).
    """

    UNROLL = 4   # IK iterations per compiled call
    #: the compiled functions of every (robot model, arms, grasps) built in this process: a planner made
    #: for each query of the same robot and object reuses them instead of generating the C code again
    _BUILT: ClassVar[dict[tuple[Any, ...], tuple[Any, ...]]] = {}

    def __init__(self, robot: RobotModel, grasps: dict[str, pin.SE3]) -> None:
        if len(grasps) != 2:
            raise ValueError(f"grasps: expected two arms, got {list(grasps)}")
        self.robot = robot
        self.arm_names = tuple(grasps)
        self.grasps = {a: pin.SE3(g) for a, g in grasps.items()}
        self.arms = [robot.arm(a) for a in self.arm_names]
        self.idx = [a.q_idx for a in self.arms]
        self.lower, self.upper = robot.lower.copy(), robot.upper.copy()
        self.nq = robot.nq
        ga, gb = (self.grasps[a] for a in self.arm_names)
        self.T21 = ga.actInv(gb)   # hand 2 in hand 1 (Eq. 1)
        self._grasp1_inv = ga.inverse()
        self._data = robot.model.createData()
        self._fun: MemoFunctions
        self._fast: dict[str, FastFunction]
        self._block: FastFunction
        key = (id(robot.model), self.arm_names,
               tuple(np.asarray(self.grasps[a].homogeneous).round(15).tobytes() for a in self.arm_names))
        built = ClosedChainKinematics._BUILT.get(key)
        if built is None:
            self._build()
            # the model is kept alive so that its id stays unique
            ClosedChainKinematics._BUILT[key] = (robot.model, self._fun, self._fast, self._block)
        else:
            _, self._fun, self._fast, self._block = built
            self.compiled = self._block.compiled
        self._par = np.zeros(6)

    # ------------------------------------------------------------------ code generation
    def _arm_terms(self, sk: SymbolicKinematics, q: ca.SX, Ro: ca.SX, po: ca.SX, damp: ca.SX,
                   with_step: bool = True) -> list[tuple[Any, ca.SX, ca.SX, tuple[ca.SX, ca.SX]]]:
        """Per arm: (dq of its joints or None, |e_p|, |e_o|, (R, p) of the hand) at ``q``."""
        X = sk.joint_placements(q)
        out = []
        for a in self.arms:
            R, p = sk.frame_placement(q, a.ee_frame_id, X)
            G = self.grasps[a.name]
            Rg = Ro @ ca.DM(np.array(G.rotation))
            pg = po + Ro @ ca.DM(np.array(G.translation))
            ep = pg - p                                     # Eq. 5
            eo = Rg @ _vee_log(R.T @ Rg)                    # Eq. 6
            dq = None
            if with_step:
                J = sk.frame_jacobian(q, a.ee_frame_id, "world_aligned", X)[:, [int(i) for i in a.v_idx]]
                e = ca.vertcat(ep, eo)
                dq = J.T @ ca.solve(J @ J.T + damp ** 2 * ca.SX.eye(6), e)   # Eq. 7 (K = I), damped
            out.append((dq, ca.norm_2(ep), ca.norm_2(eo), (R, p)))
        return out

    def _build(self) -> None:
        """The compiled IK block and the interpreted step and residual functions: built once per robot,
        grasps and joint limits, then loaded from the set-up memo (:func:`optplan.codegen.memo_functions`)."""
        from ..model.digest import kinematics_digest

        key = (kinematics_digest(self.robot), self.arm_names, self.UNROLL,
               *(np.asarray(self.grasps[a].homogeneous, float).tobytes() for a in self.arm_names),
               np.asarray(self.lower, float).tobytes(), np.asarray(self.upper, float).tobytes())
        self._fun = memo_functions("closed_chain_ik", key, self._functions)   # each read when first used
        self._fast = {}
        self._block = FastFunction.of(self._fun, "block", "-O1")   # -O1: a third less compile time than -O2, same speed here
        self.compiled = self._block.compiled
        if not self.compiled:
            log.warning("closed-chain kinematics run interpreted (no C compiler): planners will be slow")
        self._par = np.zeros(6)

    def _functions(self) -> dict[str, ca.Function]:
        """The symbolic functions of :meth:`_build`: ``step``, ``block`` (``UNROLL`` iterations), ``h``, ``hj``."""
        robot = self.robot
        sk = SymbolicKinematics(robot)
        nq = robot.nq
        q = ca.SX.sym("q", nq)
        Ro = ca.SX.sym("Ro", 3, 3)
        po = ca.SX.sym("po", 3)
        damp = ca.SX.sym("damping")
        terms = self._arm_terms(sk, q, Ro, po, damp)
        dq_full = ca.SX.zeros(nq)
        for a, (dq, _, _, _) in zip(self.arms, terms):
            for k, i in enumerate(a.q_idx):
                dq_full[int(i)] = dq[k]
        errs = [x for t in terms for x in t[1:3]]
        step = ca.Function("occ_ik_step", [q, ca.vec(Ro), po, damp], [ca.vertcat(dq_full, *errs)])
        # K unrolled iterations of Alg. 4 (both arms; an arm stops once its errors are below ε)
        par = ca.SX.sym("par", 6)   # damping, tol_p, tol_o, gain, max_step, remaining iterations
        qk = q
        n_it: ca.SX | int = 0
        lo, hi = ca.DM(self.lower), ca.DM(self.upper)
        for k in range(self.UNROLL):
            tk = self._arm_terms(sk, qk, Ro, po, par[0])
            conv = [ca.logic_and(t[1] < par[1], t[2] < par[2]) for t in tk]
            active = k < par[5]
            both = ca.logic_and(conv[0], conv[1])
            n_it = n_it + ca.if_else(ca.logic_and(active, ca.logic_not(both)), 1, 0)
            qn = ca.SX(qk)
            for a, t, c in zip(self.arms, tk, conv):
                idx = [int(i) for i in a.q_idx]
                st = par[3] * t[0]
                m = ca.mmax(ca.fabs(st))
                st = st * ca.fmin(1.0, par[4] / ca.fmax(m, 1e-300))
                new = ca.fmin(ca.fmax(qk[idx] + st, lo[idx]), hi[idx])
                keep = ca.logic_or(c, ca.logic_not(active))
                for j, i in enumerate(idx):
                    qn[i] = ca.if_else(keep, qk[i], new[j])
            qk = qn
        tf = self._arm_terms(sk, qk, Ro, po, par[0], with_step=False)
        block = ca.Function("occ_ik_block", [q, ca.vec(Ro), po, par],
                            [ca.vertcat(qk, *[x for t in tf for x in t[1:3]], n_it)])
        # the closed-chain residual (module docstring): hand 2 in hand 1 against T_21
        (R1, p1), (R2, p2) = terms[0][3], terms[1][3]
        h, _ = relative_pose_residual(R1, p1, R2, p2, self.T21)
        Jh = ca.jacobian(h, q)
        hfun = ca.Function("occ_h", [q], [h])
        hjfun = ca.Function("occ_hj", [q], [ca.vertcat(h, ca.vec(ca.densify(Jh)))])
        return {"step": step, "block": block, "h": hfun, "hj": hjfun}

    def _get(self, name: str) -> FastFunction:
        """Compiled on first use (only the IK block is needed by TCBiRRT)."""
        f = self._fast.get(name)
        if f is None:
            f = self._fast[name] = FastFunction.of(self._fun, name)
        return f

    # ------------------------------------------------------------------ IK (Alg. 4)
    def ik(self, q_seed: np.ndarray, R_obj: np.ndarray, p_obj: np.ndarray, s: IKSettings) -> tuple[np.ndarray | None, int]:
        """Both hands onto their grasps of the object at ``(R_obj, p_obj)``, starting from
        ``q_seed`` (Alg. 4: errors Eq. 5-6, step ``q ← clamp(q + K·λ·J† e)`` with the step's largest
        joint change clipped to ``max_step``; an arm stops once ``|e_p| < ε_p`` and ``|e_o| < ε_o``).
        Returns ``(q, iterations)``; ``q = None`` when not converged within ``max_iterations``
        (Alg. 4 line 11). Runs ``UNROLL`` iterations per compiled call."""
        par = self._par
        par[0], par[1], par[2], par[3], par[4] = s.damping, s.tol_position, s.tol_orientation, s.gain, s.max_step
        Rf = R_obj.reshape(-1, order="F")
        q = q_seed
        nq, its, tp, to = self.nq, 0, s.tol_position, s.tol_orientation
        while True:
            par[5] = s.max_iterations - its
            out = self._block(q, Rf, p_obj, par)
            q = out[:nq]
            its += int(out[nq + 4])
            if out[nq] < tp and out[nq + 1] < to and out[nq + 2] < tp and out[nq + 3] < to:
                return q, its
            if its >= s.max_iterations:
                return None, its

    def ik_reference(self, q_seed: np.ndarray, R_obj: np.ndarray, p_obj: np.ndarray, s: IKSettings) -> tuple[np.ndarray | None, int]:
        """Same as :meth:`ik`, one Python iteration per step (reference for the tests)."""
        q = q_seed.copy()
        Rf = R_obj.reshape(-1, order="F")
        ia, ib = self.idx
        lo, hi = self.lower, self.upper
        tp, to, gain, mstep = s.tol_position, s.tol_orientation, s.gain, s.max_step
        for it in range(s.max_iterations + 1):
            out = self._get("step")(q, Rf, p_obj, s.damping)
            ok_a = out[self.nq] < tp and out[self.nq + 1] < to
            ok_b = out[self.nq + 2] < tp and out[self.nq + 3] < to
            if ok_a and ok_b:
                return q, it
            if it == s.max_iterations:
                break
            for ok, idx in ((ok_a, ia), (ok_b, ib)):
                if ok:
                    continue
                dq = gain * out[idx]
                m = np.abs(dq).max()
                if m > mstep:
                    dq *= mstep / m
                q[idx] = np.minimum(np.maximum(q[idx] + dq, lo[idx]), hi[idx])
        return None, s.max_iterations

    def hand_errors(self, q: np.ndarray, R_obj: np.ndarray, p_obj: np.ndarray) -> np.ndarray:
        """``[|e_p1|, |e_o1|, |e_p2|, |e_o2|]`` of the hands against the object pose."""
        return self._get("step")(q, R_obj.reshape(-1, order="F"), p_obj, 0.0)[self.nq:]

    # ------------------------------------------------------------------ constraint h(q)
    def h(self, q: np.ndarray) -> np.ndarray:
        """The closed-chain residual (module docstring) of hand 2 in hand 1 against ``T_21``:
        position [m] and sin θ · axis."""
        return self._get("h")(q)

    def h_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(h(q), ∂h/∂q)`` (6 and 6 × nq)."""
        out = self._get("hj")(q)
        return out[:6], out[6:].reshape(6, self.nq, order="F")

    # ------------------------------------------------------------------ object
    def object_pose(self, q: np.ndarray) -> pin.SE3:
        """World pose of the object from arm 1's hand (Pinocchio FK)."""
        pin.framesForwardKinematics(self.robot.model, self._data, q)
        return self._data.oMf[self.arms[0].ee_frame_id] * self._grasp1_inv
