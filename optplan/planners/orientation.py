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
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from ..codegen import compile_function
from ..errors import ConfigurationError
from ..geometry.spatial import rpy_to_matrix
from ..model.ik_analytic import DecoupledArmIK
from ..model.robot import RobotModel
from ..scene import Scene

__all__ = ["DualArmOrientationConstraint", "OrientationManifold", "constraint_from_scene", "endpoints_from_scene"]


@dataclass
class DualArmOrientationConstraint:
    """See the module docstring. ``R_hands``: world orientation of each hand (open mode: both
    arms; closed mode: the active arm's is used); ``T_rel``: passive hand pose in the active hand
    frame (closed mode); ``orientation_bounds``: 3 × 2 array, world-axis bounds [rad] on each
    hand's orientation error (default all zero: orientation fixed)."""

    robot: RobotModel
    mode: str
    R_hands: dict[str, np.ndarray]
    active: str = "left"
    passive: str = "right"
    T_rel: pin.SE3 | None = None
    orientation_bounds: np.ndarray = field(default_factory=lambda: np.zeros((3, 2)))

    def __post_init__(self) -> None:
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
            assert self.T_rel is not None  # checked above
            self.R_hands[self.passive] = np.asarray(self.R_hands[self.active]) @ self.T_rel.rotation
        self.fids = {a: self.robot.arm(a).ee_frame_id for a in (self.active, self.passive)}
        self.data = self.robot.model.createData()
        self.dim = 6 if self.mode == "open" else 9
        self.ambient_dim = self.robot.nq

    # ------------------------------------------------------------------ residual (projection planners)
    def _orientation_rows(self, arm: str, with_jac: bool) -> tuple[np.ndarray, np.ndarray | None]:
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

    def _relative_rows(self, with_jac: bool) -> tuple[np.ndarray, np.ndarray | None]:
        m, d = self.robot.model, self.data
        assert self.T_rel is not None  # closed mode (__post_init__)
        T1, T2 = d.oMf[self.fids[self.active]], d.oMf[self.fids[self.passive]]
        Terr = self.T_rel.actInv(T1.actInv(T2))
        h = pin.log6(Terr).vector
        if not with_jac:
            return h, None
        J1 = pin.getFrameJacobian(m, d, self.fids[self.active], pin.ReferenceFrame.LOCAL)
        J2 = pin.getFrameJacobian(m, d, self.fids[self.passive], pin.ReferenceFrame.LOCAL)
        Ad21 = (T2.actInv(T1)).toActionMatrix()
        return h, pin.Jlog6(Terr) @ (J2 - Ad21 @ J1)

    def h_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual (``dim``) and its Jacobian (``dim × nq``) at q."""
        m, d = self.robot.model, self.data
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacements(m, d)
        if self.mode == "open":
            ha, Ja = self._orientation_rows(self.active, True)
            hb, Jb = self._orientation_rows(self.passive, True)
            assert Ja is not None and Jb is not None  # with_jac=True
            return np.r_[ha, hb], np.vstack([Ja, Jb])
        ha, Ja = self._orientation_rows(self.active, True)
        hr, Jr = self._relative_rows(True)
        assert Ja is not None and Jr is not None  # with_jac=True
        return np.r_[ha, hr], np.vstack([Ja, Jr])

    def h(self, q: np.ndarray) -> np.ndarray:
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        if self.mode == "open":
            return np.r_[self._orientation_rows(self.active, False)[0], self._orientation_rows(self.passive, False)[0]]
        return np.r_[self._orientation_rows(self.active, False)[0], self._relative_rows(False)[0]]

    # ------------------------------------------------------------------ metrics
    def errors(self, q: np.ndarray) -> tuple[float, float]:
        """(orientation error [rad]: the larger of the two hands' ``|log(R_dᵀ R)|``, relative
        position error [m] of the passive hand in the active hand frame; 0 in open mode)."""
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        d = self.data
        eo = max(float(np.linalg.norm(pin.log3(np.asarray(self.R_hands[a]).T @ d.oMf[self.fids[a]].rotation)))
                 for a in (self.active, self.passive))
        ep = 0.0
        if self.mode == "closed":
            assert self.T_rel is not None  # closed mode (__post_init__)
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

    def hand_pose(self, q: np.ndarray, arm: str) -> pin.SE3:
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        return self.data.oMf[self.fids[arm]].copy()

    def object_pose(self, q: np.ndarray) -> pin.SE3 | None:
        return None


class OrientationManifold:
    """The analytic parameterisation of a :class:`DualArmOrientationConstraint` (fixed
    orientations, no free axes) used by OC-RRT.

    Parameters ``p``: open mode ``[q1..q4 of the active arm, q1..q4 of the passive arm]`` (8);
    closed mode ``[q1..q4 of the active arm, q1 of the passive arm]`` (5). :meth:`complete` maps
    ``p`` to every configuration on the manifold (wrist in closed form, passive arm by the
    redundancy-angle IK) and picks the branch nearest to a reference configuration.

    ``compiled``: evaluate every closed-form branch in one C function generated with CasADi (the
    same formulas as :class:`~optplan.ik_analytic.DecoupledArmIK`, 30-100x faster than the Python
    path); joint limits and the branch choice are applied in numpy. ``False`` keeps the Python
    path (the reference the compiled one is tested against).
    """

    def __init__(self, constraint: DualArmOrientationConstraint, *, compiled: bool = True) -> None:
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
        # index slices of the joints complete() writes (plain slices when the indices are a range)
        self._ix = {k: _as_slice(v) for k, v in (("a4", ia.q_idx[:4]), ("aw", ia.q_idx[4:]), ("p4", ip.q_idx[:4]),
                                                ("pw", ip.q_idx[4:]), ("p1", ip.q_idx[1:]))}
        #: every branch of :meth:`complete` in one compiled call (None: the Python reference path,
        #: used when ``compiled=False`` or when the passive arm's full-pose IK needs Newton steps)
        self.kernel: tuple[_Kernel, ...] | None = None
        self._shared_passive = c.mode == "closed" and ia.spherical   # one passive block for both wrist branches
        if compiled and (c.mode == "open" or ip.spherical):
            self.kernel = _completion_kernel(self)

    def params(self, q: Any) -> np.ndarray:
        return np.asarray(q, float)[self.p_idx]

    def _pick(self, sols: np.ndarray, ref: np.ndarray | None,
              rng: np.random.Generator | None) -> np.ndarray | None:
        if len(sols) == 0:
            return None
        if ref is not None:
            return sols[int(np.argmin(np.abs(sols - ref).max(axis=1)))]
        if rng is not None:
            return sols[int(rng.integers(len(sols)))]
        return sols[0]

    def complete(self, p: np.ndarray, ref: np.ndarray | None = None, rng: np.random.Generator | None = None) -> np.ndarray | None:
        """The configuration on the manifold with parameters ``p``: the branch (wrist / passive
        arm solution) nearest to ``ref`` (max-norm), else a random one (``rng``), else the first.
        None when the parameters admit no solution inside the joint limits."""
        self.n_complete += 1
        if self.kernel is not None:
            return self._complete_compiled(np.asarray(p, float), ref, rng)
        return self.complete_reference(p, ref, rng)

    def complete_step(self, p: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray | None, float]:
        """:meth:`complete` ``(p, ref=ref)`` for float arrays (the planners' inner loop, without
        the conversions and dispatch), and the max-norm joint distance of the result from ``ref``
        [rad] (0.0 when there is no solution)."""
        self.n_complete += 1
        if self.kernel is not None:
            return self.kernel[1].flagged(p, ref)
        q = self.complete_reference(p, ref, None)
        return (None, 0.0) if q is None else (q, float(np.abs(q - ref).max()))

    def _complete_compiled(self, p: np.ndarray, ref: np.ndarray | None,
                           rng: np.random.Generator | None) -> np.ndarray | None:
        assert self.kernel is not None  # complete() calls this only with a kernel
        if ref is not None:
            return self.kernel[1].flagged(p, ref)[0]
        c, ia, ip = self.c, self.ik[self.c.active], self.ik[self.c.passive]
        QA, okA, QP, okP = self.kernel[0].peek(p)     # read here only; the choice copies what it returns
        closed = c.mode == "closed"
        if closed and (not okP.any() or not (ip.lower[0] - 1e-12 <= p[4] <= ip.upper[0] + 1e-12)):
            return None     # no passive-arm solution for any wrist branch
        ix = self._ix
        q = np.empty(self.robot.nq)
        q[ix["a4"]] = p[:4]
        b, w = _choose(QA, okA, ia.lower[4:], ia.upper[4:], rng)
        if w is None:
            return None
        q[ix["aw"]] = w
        if not closed:
            _, w = _choose(QP, okP, ip.lower[4:], ip.upper[4:], rng)
            if w is None:
                return None
            q[ix["p4"]] = p[4:8]
            q[ix["pw"]] = w
            return q
        blk = slice(0, len(QP)) if self._shared_passive else slice(b * (len(QP) // 2), (b + 1) * (len(QP) // 2))
        _, s = _choose(QP[blk, 1:], okP[blk], ip.lower[1:], ip.upper[1:], rng, dedup=True)
        if s is None:
            return None
        q[self.ip[0]] = p[4]
        q[ix["p1"]] = s
        return q

    def complete_reference(self, p: np.ndarray, ref: np.ndarray | None = None,
                           rng: np.random.Generator | None = None) -> np.ndarray | None:
        """:meth:`complete` on the Python path of :class:`~optplan.ik_analytic.DecoupledArmIK`
        (no compiled code; the reference for tests)."""
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


_TWO_PI = 2.0 * math.pi


def _as_slice(idx: Any) -> slice | np.ndarray:
    """``slice(a, b)`` when the integer indices are ``a, a+1, ..., b-1``, else the indices."""
    idx = np.asarray(idx, dtype=int)
    if idx.size and np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)):
        return slice(int(idx[0]), int(idx[0]) + idx.size)
    return idx


def _choose(X: np.ndarray, ok: np.ndarray, lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator | None, *,
            dedup: bool = False, tol: float = 1e-12) -> tuple[int, np.ndarray | None]:
    """One solution among the raw branches ``X`` (rows, with flags ``ok``) and their ``2πk`` shifts
    inside [lo, hi] (within ``tol``, then clipped): a uniformly random one (``rng``), else the first,
    counted in the order of :class:`~optplan.ik_analytic.DecoupledArmIK` (branch, then shifts, the
    last joint fastest). ``dedup``: branches equal modulo 2π count once. Returns (row, angles) or
    (-1, None).

    Scalar Python on the few (2-8) rows of three angles: the same IEEE operations in the same
    order as the array form it replaced (same choice for the same generator, one draw), without
    ~15 numpy calls of per-call overhead."""
    idx = [i for i, f in enumerate(ok.tolist()) if f > 0.5]
    if not idx:
        return -1, None
    if dedup and len(idx) > 1:
        Xs = X[idx]
        D = np.abs((Xs[:, None, :] - Xs[None, :, :] + math.pi) % _TWO_PI - math.pi).max(axis=2)
        keep = (~np.any(np.tril(D < 1e-9, -1), axis=1)).tolist()     # no earlier branch equal modulo 2π
        idx = [i for i, k in zip(idx, keep) if k]
    rows = X.tolist()
    lim = list(zip(lo.tolist(), hi.tolist()))
    floor, ceil = math.floor, math.ceil
    cum = []
    total = 0
    for i in idx:               # in-limit shifts of row i: the product over its angles
        n = 1
        for (a, b), v in zip(lim, rows[i]):
            c = floor((b + tol - v) / _TWO_PI) - ceil((a - tol - v) / _TWO_PI) + 1
            if c <= 0:
                n = 0
                break
            n *= c
        total += n
        cum.append(total)
    if total == 0:
        return -1, None
    j = int(rng.integers(total)) if rng is not None else 0
    r = 0
    while cum[r] <= j:      # first row whose cumulative count exceeds j
        r += 1
    j -= cum[r - 1] if r else 0
    y = rows[idx[r]]
    out = [0.0] * len(y)
    for k in range(len(y) - 1, -1, -1):
        a, b = lim[k]
        v = y[k]
        km = ceil((a - tol - v) / _TWO_PI)
        n = floor((b + tol - v) / _TWO_PI) - km + 1
        v += _TWO_PI * (km + j % n)
        j //= n
        out[k] = min(max(v, a), b)
    return idx[r], np.array(out)


def _sx_nearest(rows: list[Any], oks: list[Any], ref: list[Any], lo: np.ndarray, hi: np.ndarray, n_fixed: int = 0,
                tol: float = 1e-12) -> tuple[Any, Any, Any]:
    """:func:`_choose` with a reference, in CasADi SX: (angles, distance, found) of the in-limit
    ``2πk`` shift of the raw branches nearest ``ref`` (max-norm; first branch on ties). The first
    ``n_fixed`` angles are given (never shifted, not limit-checked)."""
    best: Any = None
    best_d: Any = None
    found: Any = None
    for x, ok in zip(rows, oks):
        y: list[Any] = []
        good, d = ok, 0.0
        for k, t in enumerate(x):
            if k >= n_fixed:
                t = t + _TWO_PI * ca.floor((ref[k] - t) / _TWO_PI + 0.5)
                t = ca.if_else(t < lo[k] - tol, t + _TWO_PI, t)
                t = ca.if_else(t > hi[k] + tol, t - _TWO_PI, t)
                good = ca.logic_and(good, ca.logic_and(t >= lo[k] - tol, t <= hi[k] + tol))
                t = ca.fmin(ca.fmax(t, lo[k]), hi[k])
            y.append(t)
            d = ca.fmax(d, ca.fabs(t - ref[k]))
        d = ca.if_else(good, d, 1e30)
        if best is None:
            best, best_d, found = y, d, good
            continue
        better = d < best_d
        best = [ca.if_else(better, a, b) for a, b in zip(y, best)]
        best_d = ca.fmin(d, best_d)
        found = ca.logic_or(found, good)
    return best, best_d, found


def _completion_kernel(mf: OrientationManifold) -> tuple[_Kernel, ...]:
    """Two compiled functions of the manifold parameters ``p``:

    * ``raw(p) -> (QA, okA, QP, okP)``: the active arm's two raw wrist branches (2 × 3) and the
      passive arm's raw wrist branches (open: 2 × 3) or full-pose branches for each active branch
      (closed: 16 × 7, eight per active branch), with existence / accuracy flags;
    * ``nearest(p, ref) -> (q, found, dist)``: the whole configuration on the branches nearest
      ``ref`` (what :meth:`OrientationManifold.complete` returns with a reference), joint limits
      applied, and its max-norm distance from ``ref`` [rad].
    """
    c, robot = mf.c, mf.robot
    ia, ip = mf.ik[c.active], mf.ik[c.passive]
    p = ca.SX.sym("p", mf.dim)
    ref = ca.SX.sym("ref", robot.nq)
    ra, rp = [ref[int(i)] for i in mf.ia], [ref[int(i)] for i in mf.ip]
    wa = ia.sx_wrist([p[k] for k in range(4)], ca.DM(np.asarray(c.R_hands[c.active], float)))
    QA = ca.vertcat(*[ca.horzcat(*b[:3]) for b in wa])
    okA = ca.vertcat(*[b[3] for b in wa])
    best_a, da, found_a = _sx_nearest([b[:3] for b in wa], [b[3] for b in wa], ra[4:], ia.lower[4:], ia.upper[4:])
    q: list[Any] = [None] * robot.nq
    for k in range(4):
        q[int(mf.ia[k])] = p[k]
    for k in range(3):
        q[int(mf.ia[4 + k])] = best_a[k]
    if c.mode == "open":
        wp = ip.sx_wrist([p[4 + k] for k in range(4)], ca.DM(np.asarray(c.R_hands[c.passive], float)))
        QP = ca.vertcat(*[ca.horzcat(*b[:3]) for b in wp])
        okP = ca.vertcat(*[b[3] for b in wp])
        best_p, _, found_p = _sx_nearest([b[:3] for b in wp], [b[3] for b in wp], rp[4:], ip.lower[4:], ip.upper[4:])
        for k in range(4):
            q[int(mf.ip[k])] = p[4 + k]
        for k in range(3):
            q[int(mf.ip[4 + k])] = best_p[k]
    else:
        assert c.T_rel is not None  # closed mode
        Rr, pr = ca.DM(c.T_rel.rotation), ca.DM(c.T_rel.translation)
        rows, oks, per_branch = [], [], []
        sols = None
        for t5, t6, t7, _ in wa:
            if ia.spherical:   # the active hand pose does not depend on the wrist branch
                R1 = ca.DM(np.asarray(c.R_hands[c.active], float))
                p1 = ia.sx_hand_position([p[k] for k in range(4)], R1)  # type: ignore[no-untyped-call]  # ik_analytic is not annotated yet
            else:
                R1, p1 = ia.sx_fk([p[0], p[1], p[2], p[3], t5, t6, t7])
            if sols is None or not ia.spherical:
                sols = ip.sx_solve(R1 @ Rr, R1 @ pr + p1, p[4])
            rows += [ca.horzcat(*x) for x, _ in sols]
            oks += [ok for _, ok in sols]
            per_branch.append(_sx_nearest([x for x, _ in sols], [ok for _, ok in sols], rp, ip.lower, ip.upper, n_fixed=1))
        QP, okP = ca.vertcat(*rows), ca.vertcat(*oks)
        # the active branch chosen above (first on ties) decides which passive block is used
        da0 = _sx_nearest([wa[0][:3]], [wa[0][3]], ra[4:], ia.lower[4:], ia.upper[4:])[1]
        second = ca.logic_and(ca.logic_and(len(wa) > 1, da < da0), found_a)
        (b0, _, f0), (b1, _, f1) = per_branch
        best_p = [ca.if_else(second, y1, y0) for y0, y1 in zip(b0, b1)]
        q1_ok = ca.logic_and(p[4] >= ip.lower[0] - 1e-12, p[4] <= ip.upper[0] + 1e-12)
        found_p = ca.logic_and(ca.if_else(second, f1, f0), q1_ok)
        for k in range(7):
            q[int(mf.ip[k])] = best_p[k]
    if c.mode == "closed" and ia.spherical:   # both blocks are the same: keep one
        QP, okP = ca.vertcat(*rows[:len(rows) // 2]), ca.vertcat(*oks[:len(oks) // 2])
    raw = ca.Function(f"oc_branches_{c.mode}", [p], _cse([QA, okA, QP, okP]))
    qv = ca.vertcat(*q)
    near = ca.Function(f"oc_nearest_{c.mode}", [p, ref],
                       _cse([qv, ca.logic_and(found_a, found_p), ca.mmax(ca.fabs(qv - ref))]))
    return tuple(_Kernel(compile_function(f)) for f in (raw, near))


def _cse(outs: list[Any]) -> list[Any]:
    return list(ca.cse(outs)) if hasattr(ca, "cse") else outs


class _Kernel:
    """Call a compiled function with dense inputs and outputs through its preallocated buffers
    (no per-call sparsity mapping), or the interpreted casadi.Function when there is no C compiler.
    Returns fresh numpy arrays (outputs in column-major order, reshaped)."""

    def __init__(self, cf: Any) -> None:
        self.cf = cf
        self.compiled = not isinstance(cf, ca.Function)
        f = cf if not self.compiled else None
        if self.compiled and any(len(r) != s[0] * s[1] for s, r, _ in cf._out_map):
            self.compiled = False    # a structurally sparse output: the interpreted function
            self.cf = f = cf.f
        if self.compiled:
            self._shapes = [shape for shape, _, _ in cf._out_map]
            self._call = (cf._fn, cf._arg, cf._res, cf._iw_p, cf._w_p)
            self._bufs = (cf._in_bufs, cf._out_bufs)
            self._n0 = self._shapes[0][0] * self._shapes[0][1]
            self._views = tuple(b[:s[0]] if s[1] == 1 else b[:s[0] * s[1]].reshape(s, order="F")
                                for b, s in zip(cf._out_bufs, self._shapes))
        else:
            assert f is not None
            self._shapes = [f.size_out(i) for i in range(f.n_out())]

    def peek(self, *inputs: Any) -> tuple[np.ndarray, ...]:
        """The outputs as views of the kernel's buffers (valid until its next call; read, do not
        keep): :meth:`__call__` without the copies."""
        if not self.compiled:
            return self(*inputs)
        for buf, x in zip(self._bufs[0], inputs):
            buf[:] = x
        fn, arg, res, iw, w = self._call
        if fn(arg, res, iw, w, 0) != 0:
            raise RuntimeError(f"{self.cf.name}: evaluation failed")
        return self._views

    def flagged(self, *inputs: Any) -> tuple[np.ndarray | None, float]:
        """(first output (a vector, fresh copy), first entry of the third output) when the first
        entry of the second output is > 0.5, else (None, 0.0): :meth:`__call__` without building
        the outputs that are not returned."""
        if not self.compiled:
            out, flag, aux = self(*inputs)[:3]
            return (out, float(np.asarray(aux).flat[0])) if flag.flat[0] > 0.5 else (None, 0.0)
        ins, outs = self._bufs
        for buf, x in zip(ins, inputs):
            buf[:] = x
        fn, arg, res, iw, w = self._call
        if fn(arg, res, iw, w, 0) != 0:
            raise RuntimeError(f"{self.cf.name}: evaluation failed")
        return (outs[0][:self._n0].copy(), float(outs[2][0])) if outs[1][0] > 0.5 else (None, 0.0)

    def __call__(self, *inputs: Any) -> tuple[np.ndarray, ...]:
        if not self.compiled:
            outs = self.cf(*inputs)
            outs = outs if isinstance(outs, (list, tuple)) else [outs]
            return tuple(np.asarray(o.full()).squeeze(axis=1) if o.size2() == 1 else np.asarray(o.full()) for o in outs)
        for buf, x in zip(self.cf._in_bufs, inputs):
            buf[:] = x
        fn, arg, res, iw, w = self._call
        if fn(arg, res, iw, w, 0) != 0:
            raise RuntimeError(f"{self.cf.name}: evaluation failed")
        return tuple(b[:s[0]].copy() if s[1] == 1 else b[:s[0] * s[1]].reshape(s, order="F")
                     for b, s in zip(self.cf._out_bufs, self._shapes))

def constraint_from_scene(robot: RobotModel, scene: Scene) -> DualArmOrientationConstraint:
    """The orientation task of a scene's ``[extra]`` table: ``mode`` ("open"/"closed"),
    ``active``/``passive`` arm names, ``hand_rpy`` = {arm: [r, p, y]} (scene angle unit: deg) and,
    in closed mode, the ``[object]`` grasps of the two arms (``T_rel = G_active⁻¹ G_passive``)."""
    ex = scene.extra
    mode: Any = ex.get("mode")  # validated by DualArmOrientationConstraint
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
    q: np.ndarray | None = qs
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
