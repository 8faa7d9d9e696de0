"""Frame terms of :class:`OptProblem`: poses and paths of frames, the closed chain of two hands,
axis orientation and the floating base's attitude (residuals of the conventions in
:mod:`.terms`; each with its Pinocchio evaluation)."""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from ..constraints.closed_chain import relative_pose_residual
from ..errors import ConfigurationError
from ..geometry.spatial import check_pose, pose_residual, vee_skew
from ..model.robot import RobotModel
from .build import TermData
from .terms import Term, _check_at, _knots, _set, pose_residual_numeric, pose_residuals

if TYPE_CHECKING:
    from .build import BuildContext
    from .terms import NumericTrajectory
    from .transcription import Transcription

#: point of a term's rows: a knot ``k`` or an interior point ``(k, fraction)``
_Point = int | tuple[int, float]


def _check_frame(obj: object, name: str = "frame") -> None:
    v = getattr(obj, name)
    if not isinstance(v, (str, int, np.integer)) or isinstance(v, bool) or (isinstance(v, str) and not v):
        raise ConfigurationError(f"{type(obj).__name__}.{name}: expected a frame name (or id), got {v!r}")

__all__ = ["FramePose", "FramePath", "ClosedChain", "OrientationConstraint", "BaseAttitude"]


# --------------------------------------------------------------------------- frame terms
@dataclass(eq=False)
class FramePose(Term):
    """A frame's world pose at a knot (``at``: "start", "end", "all", an index or a list)."""

    frame: str = ""
    target: pin.SE3 | None = None
    at: str | int | Sequence[int] = "end"
    position_only: bool = False
    default_name = "frame_pose"

    def _validate(self) -> None:
        _check_frame(self)
        if not isinstance(self.target, pin.SE3):
            raise ConfigurationError(f"FramePose.target: expected a pinocchio.SE3, got {self.target!r}")
        check_pose(self.target, "FramePose.target")
        _set(self, "at", _check_at(self.at, "FramePose.at"))

    def rows(self, ctx: BuildContext) -> TermData:
        r, lo, hi = self.residual(ctx.tp)
        return TermData(residual=r, lower=lo, upper=hi, points=tuple(_knots(self.at, ctx.N)),
                        point_rows=3 if self.position_only else 7)

    def sampled(self) -> Term:
        if self.at == "all":
            return self
        return super().sampled()

    def residual(self, tp: Transcription) -> tuple[Any, np.ndarray, np.ndarray]:
        rs, lo, hi = [], [], []
        for k in _knots(self.at, tp.N):
            R, p = tp.frame(self.frame, k)
            r, tr = pose_residual(R, p, np.array(self.target.rotation),  # type: ignore[union-attr]  # an SE3 after _validate
                                  ca.DM(self.target.translation))  # type: ignore[union-attr]
            if self.position_only:
                rs.append(r[:3])
                lo += [0.0] * 3
                hi += [0.0] * 3
            else:
                rs += [r, tr]
                lo += [0.0] * 6 + [1.0]
                hi += [0.0] * 6 + [np.inf]
        return ca.vertcat(*rs), np.array(lo), np.array(hi)

    def numeric(self, traj: NumericTrajectory) -> np.ndarray:
        assert self.target is not None  # an SE3 after _validate
        ((R, p),) = traj.placements([self.frame], _knots(self.at, traj.N))
        r = pose_residuals(R, p, self.target.rotation, self.target.translation)
        return (r[:, :3] if self.position_only else r).ravel()

    def bounds_numeric(self, traj: NumericTrajectory) -> tuple[np.ndarray, np.ndarray]:
        n = len(_knots(self.at, traj.N))
        one = (np.zeros(3), np.zeros(3)) if self.position_only else (np.r_[np.zeros(6), 1.0], np.r_[np.zeros(6), np.inf])
        return np.tile(one[0], n), np.tile(one[1], n)

    def cost_expr(self, ctx: BuildContext) -> Any:
        r, _, _ = self.residual(ctx.tp)
        step = 3 if self.position_only else 7
        keep = [i for i in range(r.shape[0]) if self.position_only or i % step != 6]
        return ca.sumsqr(r[keep])

    def cost_numeric(self, traj: NumericTrajectory) -> float:
        r = self.numeric(traj)
        step = 3 if self.position_only else 7
        keep = [i for i in range(r.size) if self.position_only or i % step != 6]
        return float(np.sum(r[keep] ** 2))


@dataclass(eq=False)
class FramePath(Term):
    """A frame follows given poses at every knot (``poses``: N+1 SE3, or a callable of time [s])."""

    frame: str = ""
    poses: Sequence[pin.SE3] | Callable[[float], pin.SE3] | None = None
    position_only: bool = False
    default_name = "frame_path"

    def _validate(self) -> None:
        _check_frame(self)
        if callable(self.poses):
            return
        try:
            poses = tuple(self.poses)  # type: ignore[arg-type]  # None: the TypeError reported below
        except TypeError:
            raise ConfigurationError(f"FramePath.poses: expected a list of pinocchio.SE3 (one per knot) or a "
                                     f"callable of time [s], got {self.poses!r}") from None
        for i, M in enumerate(poses):
            if not isinstance(M, pin.SE3):
                raise ConfigurationError(f"FramePath.poses[{i}]: expected a pinocchio.SE3, got {M!r}")
            check_pose(M, f"FramePath.poses[{i}]")
        _set(self, "poses", poses)

    def rows(self, ctx: BuildContext) -> TermData:
        r, lo, hi = self.residual(ctx.tp)
        return TermData(residual=r, lower=lo, upper=hi, points=tuple(range(ctx.N + 1)),
                        point_rows=3 if self.position_only else 6)

    def _targets(self, N: int, T: float) -> list[pin.SE3]:
        if callable(self.poses):
            return [self.poses(T * k / N) for k in range(N + 1)]
        if self.poses is None or len(self.poses) != N + 1:
            raise ValueError(f"FramePath.poses: expected {N + 1} poses (one per knot) or a callable of time")
        return list(self.poses)

    def _T(self, tp: Transcription) -> float:
        if tp.free_time and callable(self.poses):
            raise ValueError("FramePath with a callable of time needs a fixed duration")
        return float(ca.evalf(tp.T)) if not tp.free_time else 1.0

    def residual(self, tp: Transcription) -> tuple[Any, np.ndarray, np.ndarray]:
        rs = []
        for k, M in enumerate(self._targets(tp.N, self._T(tp))):
            R, p = tp.frame(self.frame, k)
            r, _ = pose_residual(R, p, np.array(M.rotation), ca.DM(M.translation))
            r = r[:3] if self.position_only else r
            rs.append(r)
        n = sum(x.shape[0] for x in rs)
        return ca.vertcat(*rs), np.zeros(n), np.zeros(n)

    def numeric(self, traj: NumericTrajectory) -> np.ndarray:
        targets = self._targets(traj.N, traj.T)
        ((R, p),) = traj.placements([self.frame], range(traj.N + 1))
        r = pose_residuals(R, p, np.array([M.rotation for M in targets]), np.array([M.translation for M in targets]))
        return (r[:, :3] if self.position_only else r[:, :6]).ravel()

    def bounds_numeric(self, traj: NumericTrajectory) -> tuple[np.ndarray, np.ndarray]:
        n = (traj.N + 1) * (3 if self.position_only else 6)
        return np.zeros(n), np.zeros(n)


@dataclass(eq=False)
class ClosedChain(Term):
    """Two end-effectors keep their relative pose ``T_a⁻¹ T_b = relative`` at every knot (the TCBiRRT paper
    Eq. 1-2, with the singularity-free residual of the module docstring).

    ``skip_pinned=True`` leaves out the knots whose joints a :class:`JointBoundary` pins and which
    satisfy the closed chain there (≤ ``pinned_tol``): there the rows repeat the boundary
    constraint and make the constraint Jacobian rank-deficient. A pinned configuration that
    violates it keeps its rows, so an inconsistent problem still ends infeasible. Off by default
    because IPOPT's path depends on it in both directions: see docs/decisions/0010-knot-transcription-defaults.md.
    The relative pose does not depend on the base, so a floating robot's
    hands are taken in the base frame (cheaper derivatives)."""

    arm_a: str = "A"
    arm_b: str = "B"
    relative: pin.SE3 | None = None
    interior: int = 0  # extra collocation points per interval (fixed-base robots), e.g. 1 = midpoints
    skip_pinned: bool = False
    pinned_tol: float = 1e-9
    default_name = "closed_chain"

    def _validate(self) -> None:
        if self.relative is not None:
            if not isinstance(self.relative, pin.SE3):
                raise ConfigurationError(f"ClosedChain.relative: expected a pinocchio.SE3 (use from_configuration/"
                                         f"from_grasps), got {self.relative!r}")
            check_pose(self.relative, "ClosedChain.relative")
        if isinstance(self.interior, bool) or not isinstance(self.interior, (int, np.integer)) or self.interior < 0:
            raise ConfigurationError(f"ClosedChain.interior: expected an integer ≥ 0 (points per interval), "
                                     f"got {self.interior!r}")
        if not (isinstance(self.pinned_tol, (int, float)) and np.isfinite(self.pinned_tol) and self.pinned_tol >= 0):
            raise ConfigurationError(f"ClosedChain.pinned_tol: expected a finite number ≥ 0, got {self.pinned_tol!r}")
        if self.arm_a == self.arm_b:
            raise ConfigurationError(f"ClosedChain: arm_a and arm_b are the same arm {self.arm_a!r}")

    def _points(self, N: int, robot: RobotModel | None = None,
                pinned: Mapping[int, np.ndarray] | None = None) -> list[_Point]:
        skip = set()
        if self.skip_pinned and pinned and robot is not None and self.relative is not None:
            for k, qk in pinned.items():
                M = self._relative_numeric(robot, robot.configuration(qk) if robot.is_floating else qk)
                r, tr = pose_residual_numeric(M, self.relative)
                if np.abs(r).max() <= self.pinned_tol and tr >= 1.0:
                    skip.add(int(k))
        if self.interior == 0:
            return [k for k in range(N + 1) if k not in skip]
        pts: list[_Point] = []
        for k in range(N + 1):
            if k not in skip:
                pts.append(k)
            if k < N:
                pts += [(k, (i + 1) / (self.interior + 1)) for i in range(self.interior)]
        return pts

    def _relative_numeric(self, robot: RobotModel, q: npt.ArrayLike) -> pin.SE3:
        fa, fb = self._frames(robot)
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, np.asarray(q, float))
        return data.oMf[robot.frame_id(fa)].actInv(data.oMf[robot.frame_id(fb)])

    @classmethod
    def from_configuration(cls, robot: RobotModel, q: npt.ArrayLike, arm_a: str = "A", arm_b: str = "B") -> ClosedChain:
        """The relative pose the two hands have at the full configuration ``q``."""
        from ..model.kinematics import Kinematics

        kin = Kinematics(robot)
        Ma, Mb = kin.frame_placements(q, [robot.arm(arm_a).ee_frame, robot.arm(arm_b).ee_frame])
        return cls(arm_a, arm_b, Ma.actInv(Mb))

    @classmethod
    def from_grasps(cls, grasp_a: pin.SE3, grasp_b: pin.SE3, arm_a: str = "A", arm_b: str = "B") -> ClosedChain:
        """Both hands on one rigid object with grasp frames ``grasp_a``, ``grasp_b`` (object frame)."""
        return cls(arm_a, arm_b, grasp_a.actInv(grasp_b))

    def _frames(self, robot: RobotModel) -> tuple[str, str]:
        return robot.arm(self.arm_a).ee_frame, robot.arm(self.arm_b).ee_frame

    def residual_at(self, tp: Transcription, k: _Point) -> tuple[Any, Any]:
        fa, fb = self._frames(tp.robot)
        Ra, pa = tp.frame(fa, k, base_frame=True)
        Rb, pb = tp.frame(fb, k, base_frame=True)
        return relative_pose_residual(Ra, pa, Rb, pb, self.relative)

    def residual(self, tp: Transcription, pinned_q: Mapping[int, np.ndarray] | None = None) -> tuple[Any, np.ndarray, np.ndarray]:
        """Rows at every collocation point (``pinned_q``: the knots a boundary pins, ``{k: q}``,
        left out with ``skip_pinned``)."""
        if self.relative is None:
            raise ValueError("ClosedChain.relative: expected a pinocchio.SE3 (use from_configuration/from_grasps)")
        rs = []
        pts = self._points(tp.N, tp.robot, pinned_q)
        for k in pts:
            r, tr = self.residual_at(tp, k)
            rs += [r, tr]
        lo = np.tile(np.r_[np.zeros(6), 1.0], len(pts))
        hi = np.tile(np.r_[np.zeros(6), np.inf], len(pts))
        return ca.vertcat(*rs), lo, hi

    def rows(self, ctx: BuildContext) -> TermData:
        r, lo, hi = self.residual(ctx.tp, ctx.pinned_q)
        return TermData(residual=r, lower=lo, upper=hi, points=tuple(self._points(ctx.N, ctx.robot, ctx.pinned_q)),
                        point_rows=7)

    def sampled(self) -> Term:
        return dataclasses.replace(self, interior=0, skip_pinned=False)

    def numeric(self, traj: NumericTrajectory) -> np.ndarray:
        pts = self._points(traj.N, traj.robot, traj.pinned_q)
        if not pts:
            return np.zeros(0)
        assert self.relative is not None  # narrowing only: checked by the build
        (Ra, pa), (Rb, pb) = traj.placements(self._frames(traj.robot), pts)
        # Ma⁻¹ Mb point by point: (Raᵀ Rb, Raᵀ (pb − pa))
        R = np.einsum("nji,njk->nik", Ra, Rb)
        p = np.einsum("nji,nj->ni", Ra, pb - pa)
        return pose_residuals(R, p, self.relative.rotation, self.relative.translation).ravel()

    def bounds_numeric(self, traj: NumericTrajectory) -> tuple[np.ndarray, np.ndarray]:
        n = len(self._points(traj.N, traj.robot, traj.pinned_q))
        return (np.tile(np.r_[np.zeros(6), 1.0], n), np.tile(np.r_[np.zeros(6), np.inf], n))


@dataclass(eq=False)
class OrientationConstraint(Term):
    """A body axis stays within ``max_angle`` [rad] of a world direction at every knot (the OC-RRT paper's
    orientation constraint, e.g. a cup kept upright): ``(R a_local) · a_world ≥ cos(max_angle)``."""

    frame: str = ""
    axis_local: Sequence[float] = (0.0, 0.0, 1.0)
    axis_world: Sequence[float] = (0.0, 0.0, 1.0)
    max_angle: float = 0.1
    default_name = "orientation"

    def _validate(self) -> None:
        _check_frame(self)
        for n in ("axis_local", "axis_world"):
            a = np.asarray(getattr(self, n), float) if np.ndim(getattr(self, n)) == 1 else None
            if a is None or a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) < 1e-12:
                raise ConfigurationError(f"OrientationConstraint.{n}: expected a non-zero 3-vector, "
                                         f"got {getattr(self, n)!r}")
            _set(self, n, tuple(float(v) for v in a))
        m = self.max_angle
        if isinstance(m, bool) or not isinstance(m, (int, float, np.floating)) or not 0 <= m <= np.pi:
            raise ConfigurationError(f"OrientationConstraint.max_angle: expected an angle in [0, π] [rad], got {m!r}")

    def rows(self, ctx: BuildContext) -> TermData:
        r, lo, hi = self.residual(ctx.tp)
        return TermData(residual=r, lower=lo, upper=hi, points=tuple(range(ctx.N + 1)), point_rows=1)

    def sampled(self) -> Term:
        return self

    def _axes(self) -> tuple[np.ndarray, np.ndarray]:
        a = np.asarray(self.axis_local, float)
        b = np.asarray(self.axis_world, float)
        return a / np.linalg.norm(a), b / np.linalg.norm(b)

    def residual(self, tp: Transcription) -> tuple[Any, np.ndarray, np.ndarray]:
        a, b = self._axes()
        r = ca.vertcat(*[ca.dot(tp.frame(self.frame, k)[0] @ ca.DM(a), ca.DM(b)) for k in range(tp.N + 1)])
        return r, np.full(tp.N + 1, np.cos(self.max_angle)), np.full(tp.N + 1, np.inf)

    def numeric(self, traj: NumericTrajectory) -> np.ndarray:
        a, b = self._axes()
        ((R, _),) = traj.placements([self.frame], range(traj.N + 1))
        return R @ a @ b

    def bounds_numeric(self, traj: NumericTrajectory) -> tuple[np.ndarray, np.ndarray]:
        return np.full(traj.N + 1, np.cos(self.max_angle)), np.full(traj.N + 1, np.inf)


@dataclass(eq=False)
class BaseAttitude(Term):
    """Base orientation of a free-floating robot at a knot equals ``target`` (a rotation matrix;
    default identity): residual ``vee(E − Eᵀ)/2`` and ``trace(E) ≥ 1`` with ``E = R_tᵀ R_b`` —
    attitude restoration when ``target`` is the initial attitude and ``at="end"``."""

    target: np.ndarray | None = None
    at: str | int | Sequence[int] = "end"
    default_name = "base_attitude"

    def _validate(self) -> None:
        if self.target is not None:
            R = np.asarray(self.target, float) if np.ndim(self.target) == 2 else None
            if R is None or R.shape != (3, 3) or not np.all(np.isfinite(R)) \
                    or not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
                raise ConfigurationError(f"BaseAttitude.target: expected a 3 × 3 rotation matrix, got {self.target!r}")
            R = R.copy()
            R.flags.writeable = False
            _set(self, "target", R)
        _set(self, "at", _check_at(self.at, "BaseAttitude.at"))

    def rows(self, ctx: BuildContext) -> TermData:
        r, lo, hi = self.residual(ctx.tp)
        return TermData(residual=r, lower=lo, upper=hi, points=tuple(_knots(self.at, ctx.N)), point_rows=4)

    def sampled(self) -> Term:
        if self.at == "all":
            return self
        return super().sampled()

    def _target(self) -> np.ndarray:
        return np.eye(3) if self.target is None else np.asarray(self.target, float)

    def residual(self, tp: Transcription) -> tuple[Any, np.ndarray, np.ndarray]:
        if not tp.floating:
            raise ConfigurationError("BaseAttitude needs a free-floating robot")
        rs = []
        for k in _knots(self.at, tp.N):
            E = ca.DM(self._target()).T @ tp.base_rotation(k)
            rs += [vee_skew(E), ca.trace(E)]
        n = len(_knots(self.at, tp.N))
        return ca.vertcat(*rs), np.tile(np.r_[0, 0, 0, 1.0], n), np.tile(np.r_[0, 0, 0, np.inf], n)

    def numeric(self, traj: NumericTrajectory) -> np.ndarray:
        out = []
        for k in _knots(self.at, traj.N):
            # a floating robot's trajectory (None on a fixed base: residual rejects those)
            x, y, z, w = traj.base_quat[k] / np.linalg.norm(traj.base_quat[k])  # type: ignore[index]
            E = self._target().T @ pin.Quaternion(w, x, y, z).toRotationMatrix()
            out.append(np.r_[vee_skew(E), np.trace(E)])
        return np.concatenate(out)

    def bounds_numeric(self, traj: NumericTrajectory) -> tuple[np.ndarray, np.ndarray]:
        n = len(_knots(self.at, traj.N))
        return np.tile(np.r_[0, 0, 0, 1.0], n), np.tile(np.r_[0, 0, 0, np.inf], n)

    def cost_expr(self, ctx: BuildContext) -> Any:
        r, _, _ = self.residual(ctx.tp)
        return ca.sumsqr(r[[i for i in range(r.shape[0]) if i % 4 != 3]])

    def cost_numeric(self, traj: NumericTrajectory) -> float:
        r = self.numeric(traj)
        return float(np.sum(r[[i for i in range(r.size) if i % 4 != 3]] ** 2))
