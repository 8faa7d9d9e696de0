"""Shared pieces of the EBA paper's methods (:mod:`optplan.papers.eba`): the two scenarios of the
paper's Section 4, fast numeric kinematics for the ODE right-hand sides, the trajectory container
every method returns, and the evaluation of a trajectory with the independent free-floating
simulator (:func:`optplan.simulate_base`).

Conventions
-----------
* Joint vectors are the 14 actuated joints in Pinocchio order (arm A joints 1-7, then arm B).
  The paper's joint angles (Section 4) are read as the **URDF joint variables** (D-H angle =
  variable + θ offset of Table 1), the reading of ``optplan demo`` and ``shared/spec/conventions.md``.
* Base attitude as the paper's state: ``α = (roll, pitch, yaw)`` [rad] with
  ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (Pinocchio's RPY; the paper's ``[αz, αy, αx]`` reversed).
* ``K(θ)`` (3 × 14): base angular velocity **in the base frame** per joint rate at zero momentum,
  ``ω_b = K(θ) θ̇`` (rows 3-5 of ``-Ag_b⁻¹ Ag_m``; independent of the base pose). The paper's
  ``J_sa`` (Eq. 1) is ``E(α)⁻¹ K(θ)`` with ``E(α)⁻¹`` mapping body rates to RPY rates.
* Closed chain: ``H(θ) θ̇ = 0`` (6 × 14, world axes) with
  ``H = [J_vb − J_va − [r_ab]× J_ωa ; J_ωb − J_ωa]``, ``r_ab = p_a − p_b`` — the rigid-grasp form
  of the paper's Eq. 25-26 (whose printed Eq. 26 has a sign and a subscript typo). The base twist
  moves both hands rigidly together and cancels out of ``H``, so ``H`` built from fixed-base
  Jacobians equals the one built from generalized Jacobians (a test checks it).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from scipy.linalg.lapack import dgesv

from ...constraints.closed_chain import ChainSpec, closure_error, project_closed_chain
from ...errors import ConfigurationError
from ...geometry.spatial import rotation_angle as _rotation_angle
from ...geometry.spatial import skew
from ...model.floating import rk4_step, simulate_base
from ...model.robot import RobotModel

__all__ = [
    "THETA0_DEG", "FREE_END_THETAF_DEG", "END_CONSTRAINED_THETAF_DEG", "PAPER_FIGURES", "Scenario",
    "free_end_scenario", "end_constrained_scenario", "EBAKinematics", "Segment", "MethodResult",
    "MethodReport", "evaluate", "simulate_result", "integrate_rpy", "rpy_rate_matrix", "skew3",
]
log = logging.getLogger(__name__)

# --------------------------------------------------------------------------- the paper's data
THETA0_DEG = np.array([-23.44, -90.0, 12.51, 104.8, -27.33, 66.56, -38.0] * 2)
FREE_END_THETAF_DEG = np.array([-23.44, -80.0, -17.49, 134.8, -12.33, 111.56, -38.0,
                                -23.44, -180.0, 47.51, 144.8, 7.67, 86.56, -38.0])
END_CONSTRAINED_THETAF_DEG = np.array([-23.44, -141.29, 16.92, 168.53, -110.15, 75.40, 16.68,
                                       -23.44, -84.38, 66.04, 95.38, -71.42, 63.47, -41.08])

#: The paper's reported figures (Section 4.1 / 4.2). "planned" = the planning result ("desired"),
#: "real" = after the paper's closed-loop control simulation, which optplan does not reproduce.
PAPER_FIGURES: dict[str, dict[str, dict[str, Any]]] = {
    "free_end": {
        "quintic": {"planned_rpy_deg": (-0.81, 0.53, 0.78), "real_rpy_deg": (-0.82, 0.52, 0.79), "runtime_s": 0.42},
        "ba": {"planned_rpy_deg": (0.0, 0.0, 0.0), "real_rpy_deg": (-0.07, 0.02, 0.13), "runtime_s": 370.0},
        "eba": {"planned_rpy_deg": (0.0, 0.0, 0.0), "real_rpy_deg": (-0.01, 0.0, 0.01), "runtime_s": 370.0},
        "fourier": {"planned_rpy_deg": (0.0, 0.0, 0.0), "real_rpy_deg": (0.01, 0.0, -0.04), "runtime_s": 6300.0},
    },
    "end_constrained": {
        "leader_follower": {"planned_rpy_deg": (0.32, 0.67, 1.75), "real_rpy_deg": (0.33, 0.66, 1.76), "runtime_s": 22.0},
        "eba": {"planned_rpy_deg": (0.11, 0.01, -0.05), "real_rpy_deg": (0.08, 0.0, -0.04), "runtime_s": 270.0},
        "fourier": {"planned_rpy_deg": (0.0, 0.0, 0.0), "real_rpy_deg": (-0.02, -0.05, -0.18), "runtime_s": 6200.0},
    },
}


skew3 = skew   # the cross-product matrix ``[r]×`` (:func:`optplan.geometry.spatial.skew`)


def rpy_rate_matrix(rpy: np.ndarray) -> np.ndarray:
    """``E(α)⁻¹``: RPY rates ``α̇`` from base-frame angular velocity ``ω_b`` (α = roll, pitch,
    yaw; ``R = Rz Ry Rx``). Singular at pitch = ±90° (never approached here: attitudes are a few
    degrees)."""
    r, p = rpy[0], rpy[1]
    sr, cr, cp = np.sin(r), np.cos(r), np.cos(p)
    tp = np.tan(p)
    return np.array([[1.0, sr * tp, cr * tp], [0.0, cr, -sr], [0.0, sr / cp, cr / cp]])


def rpy_matrix(rpy) -> np.ndarray:
    return np.asarray(pin.rpy.rpyToMatrix(np.asarray(rpy, float)))


def matrix_rpy(R) -> np.ndarray:
    return np.asarray(pin.rpy.matrixToRpy(np.asarray(R, float)))


rotation_angle = _rotation_angle   # geodesic angle [rad] (:func:`optplan.geometry.spatial.rotation_angle`)


# --------------------------------------------------------------------------- kinematics
class EBAKinematics:
    """Numeric kinematics for the ODE right-hand sides (Pinocchio; one ``pin.Data``; not
    thread-safe). All quantities at the identity base pose — they do not depend on it."""

    def __init__(self, robot: RobotModel, arm_a: str = "A", arm_b: str = "B"):
        if not robot.is_floating:
            raise ConfigurationError(f"the EBA methods need a free-floating robot; {robot.name!r} has a fixed base")
        self.robot = robot
        self.model = robot.model
        self.data = robot.model.createData()
        self.nj = robot.nj
        self._q = robot.configuration(np.zeros(robot.nj))
        self.arm_a, self.arm_b = arm_a, arm_b
        self.fa = robot.arm(arm_a).ee_frame_id
        self.fb = robot.arm(arm_b).ee_frame_id

    def _set(self, theta) -> np.ndarray:
        self._q[7:] = theta
        return self._q

    def base_rate_map(self, theta) -> np.ndarray:
        """``K(θ)`` (3 × nj): base angular velocity (base frame) per joint rate, zero momentum."""
        Ag = pin.computeCentroidalMap(self.model, self.data, self._set(theta))
        _, _, X, info = dgesv(Ag[:, :6], Ag[:, 6:])
        if info != 0:
            raise np.linalg.LinAlgError("singular base block of the centroidal map")
        return -X[3:6]

    def rate_map_and_constraint(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """``(K(θ), H(θ))`` with one forward pass (see the module docstring for ``H``)."""
        K = self.base_rate_map(theta)  # runs forward kinematics
        m, d = self.model, self.data
        pin.computeJointJacobians(m, d)
        pin.updateFramePlacements(m, d)
        LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        Ja = pin.getFrameJacobian(m, d, self.fa, LWA)[:, 6:]
        Jb = pin.getFrameJacobian(m, d, self.fb, LWA)[:, 6:]
        r_ab = d.oMf[self.fa].translation - d.oMf[self.fb].translation
        H = np.vstack([Jb[:3] - Ja[:3] - skew3(r_ab) @ Ja[3:], Jb[3:] - Ja[3:]])
        return K, H

    def constraint_jacobian(self, theta) -> np.ndarray:
        return self.rate_map_and_constraint(theta)[1]

    def hand_placements(self, theta) -> tuple[pin.SE3, pin.SE3]:
        pin.framesForwardKinematics(self.model, self.data, self._set(theta))
        return self.data.oMf[self.fa].copy(), self.data.oMf[self.fb].copy()

    def relative_pose(self, theta) -> pin.SE3:
        """``T_a⁻¹ T_b``: hand B in the frame of hand A (as :class:`~optplan.problem.ClosedChain`)."""
        Ma, Mb = self.hand_placements(theta)
        return Ma.actInv(Mb)

    def closed_chain_error(self, theta, rel0: pin.SE3) -> tuple[np.ndarray, np.ndarray]:
        """Error ``e = [p − p0; log3(R R0ᵀ)]`` of the relative pose (``p``, ``R`` of
        :meth:`relative_pose`) and the rotation ``R_a`` of hand A; ``ė ≈ diag(R_aᵀ, R_aᵀ) H θ̇``."""
        Ma, Mb = self.hand_placements(theta)
        rel = Ma.actInv(Mb)
        e = np.concatenate([rel.translation - rel0.translation, pin.log3(rel.rotation @ rel0.rotation.T)])
        return e, Ma.rotation

    def closed_chain_residual(self, theta, rel0: pin.SE3) -> float:
        """max(position error [m], rotation error [rad]) of the relative hand pose
        (:func:`optplan.constraints.closed_chain.closure_error`, as :func:`optplan.verify`)."""
        return max(closure_error(self.robot, ChainSpec(self.arm_a, self.arm_b, rel0), self._set(theta), self.data))

    def project_closed_chain(self, theta, rel0: pin.SE3, joints=None, tol: float = 1e-13,
                             max_iter: int = 50) -> np.ndarray:
        """Newton projection of ``θ`` onto ``{relative_pose = rel0}`` with a minimum-norm change of
        ``joints`` (indices into the joint vector; default all), joint limits not enforced
        (:func:`optplan.constraints.closed_chain.project_closed_chain`)."""
        idx = np.arange(self.nj) if joints is None else np.asarray(joints)
        r = project_closed_chain(self.robot, self._set(np.array(theta, float)).copy(),
                                 ChainSpec(self.arm_a, self.arm_b, rel0), tol=tol, max_iterations=max_iter,
                                 data=self.data, joints=idx, clip=False)
        if r.residual > 1e-9:
            raise ConfigurationError(f"closed-chain projection did not converge (error {r.residual:.2e})")
        return r.q[7:].copy()


# --------------------------------------------------------------------------- scenarios
@dataclass(frozen=True)
class Scenario:
    """One of the paper's two simulations: start/goal joints [rad], base attitude identity at both
    ends. ``closed_chain``: the hands keep their relative pose at ``theta0`` (``relative``);
    ``thetaf_paper`` is the goal as printed, ``thetaf`` the one used (see
    :func:`end_constrained_scenario`)."""

    name: str
    theta0: np.ndarray
    thetaf: np.ndarray
    thetaf_paper: np.ndarray
    closed_chain: bool = False
    relative: pin.SE3 | None = field(default=None, repr=False)

    @property
    def goal_adjustment_deg(self) -> float:
        return float(np.rad2deg(np.max(np.abs(self.thetaf - self.thetaf_paper))))


def free_end_scenario() -> Scenario:
    """Section 4.1: both arms from θ0 to their own goals, free hands."""
    th0, thf = np.deg2rad(THETA0_DEG), np.deg2rad(FREE_END_THETAF_DEG)
    return Scenario("free_end", th0, thf, thf.copy(), False, None)


def end_constrained_scenario(robot: RobotModel) -> Scenario:
    """Section 4.2: the hands keep their relative pose at θ0 (a grasped object).

    The printed goal is rounded to 0.01°, so its relative hand pose differs from the start's by
    ≈ 0.5 mm / 0.01° on our model; arm B's goal joints are moved (minimum-norm Newton projection,
    ≈ 0.08° at most) so that start and goal lie on the same closed-chain manifold to 1e-13.
    """
    kin = EBAKinematics(robot)
    th0, thf_p = np.deg2rad(THETA0_DEG), np.deg2rad(END_CONSTRAINED_THETAF_DEG)
    rel0 = kin.relative_pose(th0)
    thf = kin.project_closed_chain(thf_p, rel0, joints=robot.arm("B").j_idx)
    log.debug("end-constrained goal: arm B moved by %.4f deg", np.rad2deg(np.abs(thf - thf_p).max()))
    return Scenario("end_constrained", th0, thf, thf_p, True, rel0)


# --------------------------------------------------------------------------- trajectories
@dataclass(frozen=True)
class Segment:
    """A piece of joint trajectory on which velocity is continuous: ``t`` (M,) [s], ``q``, ``qd``,
    ``qdd`` (M, nj) [rad, rad/s, rad/s²]."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray

    def __post_init__(self):
        t = np.asarray(self.t)
        if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0):
            raise ConfigurationError("Segment.t: expected ≥ 2 strictly increasing times")
        for n in ("q", "qd", "qdd"):
            a = np.asarray(getattr(self, n))
            if a.shape[0] != t.size or a.ndim != 2:
                raise ConfigurationError(f"Segment.{n}: expected ({t.size}, nj), got {a.shape}")


@dataclass
class MethodResult:
    """What every method returns: the joint trajectory as velocity-continuous ``segments`` (BA
    and EBA have two: the real robot on ``[0, t_m]`` and the time-reversed virtual robot on
    ``[t_m, 2 t_m]``), the planner's ``runtime_s``, and the method's own prediction of the final
    base rotation (``planned_final_rotation``, 3 × 3) when it has one. ``success`` says whether
    the method ran to completion (an ODE that diverged, a failed NLP: False, with ``message``)."""

    name: str
    segments: list[Segment]
    runtime_s: float
    planned_final_rotation: np.ndarray | None = None
    meeting_time: float | None = None
    success: bool = True
    message: str = ""
    info: dict = field(default_factory=dict)
    raw: object = field(default=None, repr=False)  # e.g. the NLP's Solution

    @property
    def t(self) -> np.ndarray:
        return self._cat("t")

    @property
    def q(self) -> np.ndarray:
        return self._cat("q")

    @property
    def qd(self) -> np.ndarray:
        return self._cat("qd")

    def _cat(self, name):
        parts = [getattr(self.segments[0], name)]
        for s in self.segments[1:]:
            parts.append(getattr(s, name)[1:])  # the boundary sample appears once (left piece's)
        return np.concatenate(parts, axis=0)

    @property
    def duration(self) -> float:
        return float(self.segments[-1].t[-1] - self.segments[0].t[0])

    def velocity_jumps(self) -> list[tuple[float, float]]:
        """``(t, ‖Δq̇‖∞)`` [s, rad/s] at the start (from rest), at every segment boundary and at
        the end (to rest)."""
        out = [(float(self.segments[0].t[0]), float(np.max(np.abs(self.segments[0].qd[0]))))]
        for a, b in zip(self.segments[:-1], self.segments[1:]):
            out.append((float(b.t[0]), float(np.max(np.abs(b.qd[0] - a.qd[-1])))))
        out.append((float(self.segments[-1].t[-1]), float(np.max(np.abs(self.segments[-1].qd[-1])))))
        return out

    def position_jumps(self) -> float:
        """Largest joint-angle discontinuity between segments [rad] (BA/EBA: |θ1(t_m) − θ2(t_m)|)."""
        if len(self.segments) < 2:
            return 0.0
        return float(max(np.max(np.abs(b.q[0] - a.q[-1])) for a, b in zip(self.segments[:-1], self.segments[1:])))

    def save_npz(self, path, joint_names) -> None:
        """``t`` [s], ``q`` [rad] (joints only, Pinocchio order), ``qd``, ``joint_names``; the
        meeting sample appears once."""
        from ..._io import atomic_path

        p = Path(path) if str(path).endswith(".npz") else Path(f"{path}.npz")
        with atomic_path(p) as tmp, open(tmp, "wb") as f:
            np.savez(f, t=self.t, q=self.q, qd=self.qd, joint_names=np.array(joint_names))


def hermite_segment(t, q, qd) -> Segment:
    """A :class:`Segment` whose ``qdd`` is the numerical derivative of ``qd`` (second order)."""
    t = np.asarray(t, float)
    return Segment(t, np.asarray(q, float), np.asarray(qd, float), np.gradient(np.asarray(qd, float), t, axis=0))


# --------------------------------------------------------------------------- attitude integration
def integrate_rpy(kin: EBAKinematics, segments: list[Segment], substeps: int = 1,
                  rpy0=None) -> np.ndarray:
    """The paper's attitude equation ``α̇ = E(α)⁻¹ K(θ) θ̇`` (Eq. 1) integrated by RK4 along the
    segments (cubic Hermite between samples, ``substeps`` per sample interval); returns the RPY
    [rad] at every sample of the concatenated trajectory. A second implementation of the base
    attitude next to :func:`optplan.simulate_base` (which integrates the quaternion)."""
    from scipy.interpolate import CubicHermiteSpline

    a = np.zeros(3) if rpy0 is None else np.asarray(rpy0, float).copy()
    out = [a.copy()]
    for s in segments:  # a segment's first sample is the previous one's last (same time)
        sp = CubicHermiteSpline(s.t, s.q, s.qd, axis=0)
        dsp = sp.derivative()

        def f(tt, al, sp=sp, dsp=dsp):
            return rpy_rate_matrix(al) @ (kin.base_rate_map(sp(tt)) @ dsp(tt))

        for k in range(len(s.t) - 1):
            h = (s.t[k + 1] - s.t[k]) / substeps
            tt = s.t[k]
            for _ in range(substeps):
                a = rk4_step(f, tt, a, h)
                tt += h
            out.append(a.copy())
    return np.array(out)


def _thin(t: np.ndarray, max_points: int) -> np.ndarray:
    if t.size <= max_points:
        return np.arange(t.size)
    idx = np.unique(np.round(np.linspace(0, t.size - 1, max_points)).astype(int))
    return idx


def simulate_result(robot: RobotModel, res: MethodResult, substeps: int = 2,
                    max_points_per_segment: int = 4001):
    """Base attitude along the method's joint trajectory from the independent simulator
    :func:`optplan.simulate_base`, segment by segment (the base pose carried across segment
    boundaries, so velocity jumps are integrated exactly). Returns ``(t, base_rpy (N, 3) [rad],
    final_rotation (3 × 3), max_momentum_residual)``."""
    base = pin.SE3.Identity()
    ts, rpys = [], []
    mom = 0.0
    for si, s in enumerate(res.segments):
        idx = _thin(s.t, max_points_per_segment)
        sim = simulate_base(robot, (s.t, s.q, s.qd), s.t[idx], base0=base, substeps=substeps)
        base = sim.final_base
        mom = max(mom, float(sim.momentum_residual.max()))
        k0 = 0 if si == 0 else 1
        ts.append(sim.t[k0:])
        rpys.append(sim.base_rpy[k0:])
    return np.concatenate(ts), np.concatenate(rpys), np.array(base.rotation), mom


# --------------------------------------------------------------------------- evaluation
@dataclass(frozen=True)
class MethodReport:
    """Figures of one method (angles in degrees; the issue's JSON keys come from
    :meth:`to_json`).

    ``final_base_rpy_deg``: final base RPY from the independent simulator; ``planned_...``: the
    method's own prediction; ``planned_vs_simulated_rad``: angle between the two;
    ``final_joint_error_deg``: max |q(T) − θf| plus the joint-angle discontinuity at the meeting
    (BA/EBA), i.e. what a continuous execution would miss the goal by; velocity jumps at the start,
    segment boundaries (t_m) and end; ``max_closed_chain_residual``: max(position [m], rotation
    [rad]) error of the relative hand pose over all samples (nan for the free-end case)."""

    name: str
    success: bool
    message: str
    final_base_rpy_deg: tuple
    final_base_attitude_error_deg: float
    planned_final_base_rpy_deg: tuple | None
    planned_vs_simulated_rad: float
    final_joint_error_deg: float
    max_velocity_deg_s: float
    max_acceleration_deg_s2: float
    max_velocity_jump_deg_s: float
    velocity_jumps_deg_s: tuple
    runtime_s: float
    max_closed_chain_residual: float
    max_momentum_residual: float
    duration_s: float
    info: dict = field(default_factory=dict)

    def to_json(self, closed_chain: bool) -> dict:
        d = {"final_base_rpy_deg": list(self.final_base_rpy_deg),
             "final_joint_error_deg": self.final_joint_error_deg,
             "max_velocity_jump_deg_s": self.max_velocity_jump_deg_s,
             "runtime_s": self.runtime_s}
        if closed_chain:
            d["max_closed_chain_residual"] = self.max_closed_chain_residual
        d.update({"success": self.success, "message": self.message,
                  "final_base_attitude_error_deg": self.final_base_attitude_error_deg,
                  "planned_final_base_rpy_deg": None if self.planned_final_base_rpy_deg is None
                  else list(self.planned_final_base_rpy_deg),
                  "planned_vs_simulated_rad": self.planned_vs_simulated_rad,
                  "max_velocity_deg_s": self.max_velocity_deg_s,
                  "max_acceleration_deg_s2": self.max_acceleration_deg_s2,
                  "velocity_jumps_deg_s": [list(v) for v in self.velocity_jumps_deg_s],
                  "max_momentum_residual": self.max_momentum_residual, "duration_s": self.duration_s})
        d.update(self.info)
        return d


def evaluate(robot: RobotModel, res: MethodResult, scenario: Scenario, *, sim_substeps: int = 2,
             keep_traces: bool = False):
    """Evaluate a :class:`MethodResult` on a :class:`Scenario` (simulator, joints, velocities,
    closed chain). Returns a :class:`MethodReport`, plus ``(t, base_rpy)`` traces when
    ``keep_traces``."""
    t0 = time.perf_counter()
    ts, rpy, Rf, mom = simulate_result(robot, res, substeps=sim_substeps)
    planned_rpy, mismatch = None, float("nan")
    if res.planned_final_rotation is not None:
        planned_rpy = tuple(np.rad2deg(matrix_rpy(res.planned_final_rotation)).tolist())
        mismatch = rotation_angle(res.planned_final_rotation.T @ Rf)
    q_end = res.segments[-1].q[-1]
    joint_err = float(np.max(np.abs(q_end - scenario.thetaf))) + res.position_jumps()
    jumps = tuple((t, float(np.rad2deg(v))) for t, v in res.velocity_jumps())
    vmax = max(float(np.max(np.abs(s.qd))) for s in res.segments)
    amax = max(float(np.max(np.abs(s.qdd))) for s in res.segments)
    cc = float("nan")
    if scenario.closed_chain:
        kin = EBAKinematics(robot)
        cc = max(kin.closed_chain_residual(q, scenario.relative) for s in res.segments for q in s.q)
    rep = MethodReport(
        name=res.name, success=res.success, message=res.message,
        final_base_rpy_deg=tuple(np.rad2deg(matrix_rpy(Rf)).tolist()),
        final_base_attitude_error_deg=float(np.rad2deg(rotation_angle(Rf))),
        planned_final_base_rpy_deg=planned_rpy, planned_vs_simulated_rad=mismatch,
        final_joint_error_deg=float(np.rad2deg(joint_err)), max_velocity_deg_s=float(np.rad2deg(vmax)),
        max_acceleration_deg_s2=float(np.rad2deg(amax)), max_velocity_jump_deg_s=max(v for _, v in jumps),
        velocity_jumps_deg_s=jumps, runtime_s=float(res.runtime_s), max_closed_chain_residual=cc,
        max_momentum_residual=mom, duration_s=res.duration, info=dict(res.info))
    log.debug("evaluate %s: %.2f s", res.name, time.perf_counter() - t0)
    if keep_traces:
        return rep, (ts, rpy)
    return rep
