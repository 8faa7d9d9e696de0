"""The DSHDASR paper (``dshdasr``): the task definition and the robot's arc models.

* :data:`PAPER` (the paper's figures), :data:`TABLE1_XF` (the five extra goals of Table 1),
  :func:`quintic` (Eq. 42).
* :class:`TransposeTask` — the target transposition of Section 5; :func:`paper_task` is our
  reading of the paper's numbers (documented there and in docs/dshdasr.md).
* :class:`DshdasrArcs` — the two arc models of the robot (:mod:`optplan.papers.dshdasr.arcs`), arc
  parameters from joint angles and joints recovered from arc parameters.
* :class:`TrackResult` — the joint trajectory a method returns (shared by the arc NLP of
  :mod:`.dshdasr_nlp` and the DLS baseline of :mod:`.dshdasr_baseline`).

Public entry point: :mod:`optplan.papers.dshdasr`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin

from ...geometry.spatial import zyx_to_matrix
from ...geometry.splines import quintic_time_law
from ...model.description import load_description
from ...model.robot import RobotModel
from .arc_models import DiscreteArcModel, SerpentineArcModel

ROBOT = "dshdasr"
D2R = math.pi / 180.0

# The paper's figures (the DSHDASR paper, Section 5 and Table 1) for the comparison tables.
PAPER = {
    "max_tip_position_error_a_m": 8.991e-6,      # largest axis component, Fig. 12
    "max_tip_attitude_error_a_rad": 3.436e-5,    # largest Z-Y-X component, Fig. 12
    "max_tip_position_error_b_m": 8.015e-5,      # largest axis component, Fig. 13
    "max_tip_direction_error_b_rad": 4.846e-5,   # Fig. 13
    "bound_position_m": 8.5e-5, "bound_attitude_rad": 8.0e-5,
    "threshold_a_obs1_m": 0.45, "threshold_time_a_obs1_s": 41.57,
    "threshold_b_obs2_m": 0.373, "threshold_time_b_obs2_s": 47.08,
    "min_distance_b_obs1_m": 2.063, "min_distance_a_obs2_m": 2.156,
    "cases": ["S", "S", "S", "S", "S"],
    "toolchain": "Adams 2024 + MATLAB/Simulink 2020 (gradient descent, tolerance 1e-5)",
}

# Table 1 (kept its signs): goal poses of the five extra cases [m, m, m, deg, deg, deg].
TABLE1_XF = [
    [-3.8117, 2.8220, -2.0436, -126.94, -3.66, -98.99],
    [-3.8356, 2.8412, -2.0232, -124.64, -1.61, -101.65],
    [-3.8757, 2.8816, -1.9837, -126.95, -3.64, -100.62],
    [-3.8957, 2.9012, -1.9640, -123.16, -6.66, -95.95],
    [-3.9160, 2.9212, -1.9437, -127.81, -7.90, -95.65],
]


def _polar(M) -> np.ndarray:
    """Nearest rotation matrix (the printed matrices have 5 digits)."""
    U, _, Vt = np.linalg.svd(np.asarray(M, float))
    R = U @ Vt
    if np.linalg.det(R) < 0:
        raise ValueError("reading gives an improper rotation")
    return R


def _T(R, p) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p
    return T


def quintic(X0, Xf, t, tf: float) -> np.ndarray:
    """Eq. 42: X0 + (Xf − X0)(10 s³ − 15 s⁴ + 6 s⁵), s = t/tf (rest-to-rest)."""
    s = np.clip(np.asarray(t, float) / tf, 0.0, 1.0)
    h = quintic_time_law(s)[0]
    return np.asarray(X0)[None, :] + np.outer(h, np.asarray(Xf) - np.asarray(X0))


# --------------------------------------------------------------------------- task
@dataclass(frozen=True)
class TransposeTask:
    """Target transposition (the DSHDASR paper Section 4-5). Positions [m], angles [rad].

    ``X0``/``Xf``: target CoM pose (x, y, z, α, β, γ) with R = Rz(α) Ry(β) Rx(γ);
    ``T_et_a``/``T_et_b``: 4×4 pose of the target CoM frame in the Arm-a / Arm-b end-effector frame;
    ``obstacles``: sphere centres (n × 3) of radius ``obstacle_radius``; ``eps`` the safety margin;
    ``radius_a``/``radius_b`` the arm envelope radii (d_sd^k = R_k + R_obs + ε)."""

    X0: np.ndarray
    Xf: np.ndarray
    T_et_a: np.ndarray
    T_et_b: np.ndarray
    obstacles: np.ndarray
    obstacle_radius: float = 0.26
    eps: float = 0.10
    radius_a: float = 0.09
    radius_b: float = 0.035
    duration: float = 60.0
    rate: float = 10.0

    @property
    def thresholds(self) -> dict[str, float]:
        return {"a": self.radius_a + self.obstacle_radius + self.eps,
                "b": self.radius_b + self.obstacle_radius + self.eps}

    def times(self) -> np.ndarray:
        n = int(round(self.duration * self.rate))
        return np.linspace(0.0, self.duration, n + 1)

    def target(self, t) -> list[np.ndarray]:
        """4×4 target CoM poses at times t."""
        X = quintic(self.X0, self.Xf, np.atleast_1d(t), self.duration)
        return [_T(zyx_to_matrix(*x[3:]), x[:3]) for x in X]

    def desired(self, t) -> dict[str, np.ndarray]:
        """Desired tips at times t: ``pa`` (n×3), ``Ra`` (n×3×3) of Arm-a; ``pb`` (n×3) and the
        pointing direction ``kb`` (n×3, from Arm-b's tip to the locked point) of Arm-b."""
        Ta_inv, Tb_inv = np.linalg.inv(self.T_et_a), np.linalg.inv(self.T_et_b)
        pa, Ra, pb, kb = [], [], [], []
        for T in self.target(t):
            A, B = T @ Ta_inv, T @ Tb_inv
            pa.append(A[:3, 3])
            Ra.append(A[:3, :3])
            pb.append(B[:3, 3])
            d = A[:3, 3] - B[:3, 3]
            kb.append(d / np.linalg.norm(d))
        return {"pa": np.array(pa), "Ra": np.array(Ra), "pb": np.array(pb), "kb": np.array(kb)}

    def with_goal(self, Xf_deg) -> TransposeTask:
        """The same task with another goal pose given as (m, m, m, deg, deg, deg)."""
        Xf = np.asarray(Xf_deg, float).copy()
        Xf[3:] *= D2R
        return replace(self, Xf=Xf)


def paper_task() -> TransposeTask:
    """Our reading of the DSHDASR paper Section 5 (the text lost minus signs in its display equations):

    * Xf = (−3.8552, 2.8612, −2.0035 m, −122.59°, −2.96°, −100.89°): the signs of Table 1, whose
      five goals scatter around it;
    * X0 = (5.3135, 0.9097, 1.2121 m, −68.70°, −20.31°, 90.76°): β0 < 0 because the text says the
      pitch stays in [−21°, −1°]; α0 < 0 and γ0 > 0 are chosen with T_et^a below as the reading that
      needs the shortest arm: of all 256 sign readings of (α0, γ0, T_et^a) this one keeps the
      locked point within 3.46 m of the shoulder (most readings need 7-8 m);
    * T_et^a: translation as printed, rotation = nearest rotation to the printed matrix with
      r11, r12, r21, r33 negative (a half turn: the gripper's z axis against the target's z);
    * T_et^b: translation as printed, the same four signs negative plus r13, r23 (the only proper
      rotation with that pattern); Arm-b's tip then sits 1.0 m from the locked point. Its pointing
      axis is the line to the locked point (the paper's definition): no axis of the printed
      T_et^b points there under any sign reading;
    * obstacle centres as printed (all positive).
    """
    X0 = np.array([5.3135, 0.9097, 1.2121, -68.70 * D2R, -20.31 * D2R, 90.76 * D2R])
    Xf = np.array([-3.8552, 2.8612, -2.0035, -122.59 * D2R, -2.96 * D2R, -100.89 * D2R])
    Ra = _polar([[-0.75019, -0.66121, 0.00056], [-0.66122, 0.75017, 0.00018], [0.00030, 0.00050, -0.99999]])
    Rb = _polar([[-0.26258, -0.92949, -0.25903], [-0.93281, 0.31319, -0.17826], [0.24682, 0.19482, -0.94928]])
    return TransposeTask(
        X0=X0, Xf=Xf,
        T_et_a=_T(Ra, [0.43833, 0.40736, 2.80831]),
        T_et_b=_T(Rb, [0.22797, 0.33989, 2.28089]),
        obstacles=np.array([[1.8078, 1.0169, 0.6020], [1.7244, 0.7186, 3.0561]]),
    )


# --------------------------------------------------------------------------- robot <-> arcs
class DshdasrArcs:
    """The arc models of the ``dshdasr`` robot and the maps between joints and arc parameters."""

    def __init__(self, robot: RobotModel | None = None, desc=None):
        """``robot``/``desc``: the shipped ``dshdasr`` by default; a variant (e.g. another mount)
        as a RobotModel built from its URDF and the RobotDescription it was generated from."""
        self.robot = robot or RobotModel.from_name(ROBOT)
        desc = desc or load_description(ROBOT)
        mounts = {a.name: a for a in desc.arms}
        ta, tb = desc.arm_types[mounts["A"].type], desc.arm_types[mounts["B"].type]
        d = ta.dh[:, 3]
        self.a = DiscreteArcModel(d[0], d[2], d[4], d[6], mounts["A"].xyz, mounts["A"].R)
        self.b = SerpentineArcModel(tb.link_length, mounts["B"].xyz, mounts["B"].R,
                                    m=tb.joints_per_segment, segments=tb.segments)
        self.b_phi_max = tb.joints_per_segment * min(-tb.lower, tb.upper)
        self.arm_a, self.arm_b = self.robot.arm("A"), self.robot.arm("B")
        self.model = self.robot.model
        self.data = self.model.createData()
        f = self.model.getFrameId
        self._fa = [f("a_link2"), f("a_link4"), f("a_link6"), f("a_ee")]
        self._fb_ends = [f(f"b_link{i}_1") for i in range(2, 6)] + [f("b_ee")]
        self._fb_dirs = [f(f"b_link{i}_6") for i in range(1, 6)]
        self.fid_a, self.fid_b = f("a_ee"), f("b_ee")

    def q(self, qa, qb) -> np.ndarray:
        q = np.zeros(self.robot.nq)
        q[self.arm_a.q_idx], q[self.arm_b.q_idx] = qa, qb
        return q

    def tips(self, q) -> tuple[pin.SE3, pin.SE3]:
        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.fid_a].copy(), self.data.oMf[self.fid_b].copy()

    def params_from_q(self, q, refs=None) -> tuple[np.ndarray, np.ndarray]:
        """Arc parameters (X_a, X_b) of a joint configuration (``refs``: the angle frames
        ``(R_a3, R_b1, R_b3)``, identity = Eq. 25)."""
        refs = refs or (np.eye(3),) * 3
        pin.framesForwardKinematics(self.model, self.data, q)
        o = self.data.oMf
        pts = [o[i].translation for i in self._fa]
        Xa = self.a.params_from_points(pts[0], pts[1], pts[2], pts[3], o[self._fa[3]].rotation[:, 2], R_ref=refs[0])
        Xb = self.b.params_from_segments([o[i].translation for i in self._fb_ends],
                                         [o[i].rotation[:, 0] for i in self._fb_dirs], R_ref=refs[1:])
        return Xa, Xb

    def q_from_params(self, Xa, Xb, pa, Ra, pb, kb, q_prev=None, refs=None) -> np.ndarray:
        refs = refs or (np.eye(3),) * 3
        qa = self.a.recover_joints(Xa, pa, Ra, None if q_prev is None else q_prev[self.arm_a.q_idx], R_ref=refs[0])
        qb = self.b.recover_joints(Xb, pb, kb, R_ref=refs[1:])
        return self.q(qa, qb)


# --------------------------------------------------------------------------- results
@dataclass
class TrackResult:
    """Joint trajectory ``q`` (n × nq, Pinocchio order) of a method along ``t`` with the desired
    tips ``des``; ``runtime`` [s] of the whole loop (NLP solves and joint recovery, or DLS);
    for the arc planner ``X`` (n × 23) holds the arc parameters with the direction angles in the
    paper's frame (Eq. 25)."""

    method: str
    t: np.ndarray
    q: np.ndarray
    des: dict
    runtime: float
    nlp_time: float = float("nan")
    iterations: np.ndarray | None = None
    success: np.ndarray | None = None
    objective: np.ndarray | None = None
    X: np.ndarray | None = None
    metrics: dict = field(default_factory=dict)
    series: dict = field(default_factory=dict)   # per-waypoint errors and distances (evaluate)
    resolves: int = 0                             # waypoints re-solved with every constraint
