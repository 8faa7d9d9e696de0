"""Fast closed-chain kinematics for the planners: the two-hand IK step of the TCBiRRT paper's Alg. 4, the
closed-chain residual h(q) of Eq. 1-2 with its Jacobian, and the held object's pose.

The hot functions are CasADi expressions built from :class:`optplan.SymbolicKinematics` and
compiled to C (:func:`optplan.codegen.compile_function`), then called through ctypes with
preallocated buffers (~5 µs per call for both arms' FK, Jacobians and damped least-squares
step). Without a C compiler the interpreted CasADi functions are used (slower, same numbers).
"""
from __future__ import annotations

import ctypes
import logging
from dataclasses import dataclass

import casadi as ca
import numpy as np
import pinocchio as pin

from ..codegen import CompiledFunction, compile_function
from ..robot import RobotModel
from ..symbolic import SymbolicKinematics

__all__ = ["IKSettings", "ClosedChainKinematics", "closure_error"]
log = logging.getLogger(__name__)


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

    def __post_init__(self):
        for name in ("tol_position", "tol_orientation", "gain", "max_step"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise ValueError(f"IKSettings.{name}: expected a positive number, got {v!r}")
        if not (isinstance(self.damping, (int, float)) and np.isfinite(self.damping) and self.damping >= 0):
            raise ValueError(f"IKSettings.damping: expected a number >= 0, got {self.damping!r}")
        if not (isinstance(self.max_iterations, int) and self.max_iterations >= 1):
            raise ValueError(f"IKSettings.max_iterations: expected an int >= 1, got {self.max_iterations!r}")


class _Fast:
    """A CasADi function with dense inputs and ONE dense vector output, compiled and called
    through ctypes with preallocated buffers (falls back to the interpreted function)."""

    def __init__(self, f: ca.Function, opt: str = "-O2"):
        if not f.sparsity_out(0).is_dense():
            raise ValueError(f"{f.name()}: the output must be dense")
        self.f = f
        self.n_out = int(f.nnz_out(0))
        cf = compile_function(f, opt)
        self.compiled = isinstance(cf, CompiledFunction)
        if not self.compiled:
            return
        lib = cf.lib
        self._fn = getattr(lib, f.name())
        self._fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int]
        self._fn.restype = ctypes.c_int
        sz = [ctypes.c_longlong() for _ in range(4)]
        getattr(lib, f"{f.name()}_work")(*[ctypes.byref(x) for x in sz])
        self._in = [np.zeros(f.nnz_in(i)) for i in range(f.n_in())]
        self._out = np.zeros(max(self.n_out, 1))
        self._iw = np.zeros(max(sz[2].value, 1), dtype=np.int64)
        self._w = np.zeros(max(sz[3].value, 1))
        self._arg = (ctypes.c_void_p * max(sz[0].value, f.n_in()))()
        self._res = (ctypes.c_void_p * max(sz[1].value, 1))()
        for i, b in enumerate(self._in):
            self._arg[i] = b.ctypes.data
        self._res[0] = self._out.ctypes.data
        self._iwp = self._iw.ctypes.data
        self._wp = self._w.ctypes.data
        self._keep = cf  # keep the library loaded

    def __call__(self, *inputs) -> np.ndarray:
        if not self.compiled:
            return np.asarray(self.f(*inputs), dtype=float).ravel(order="F")
        for b, x in zip(self._in, inputs):
            b[:] = x
        if self._fn(self._arg, self._res, self._iwp, self._wp, 0) != 0:
            raise RuntimeError(f"{self.f.name()}: evaluation failed")
        return self._out[:self.n_out].copy()


def _vee_log(R):
    """Rotation vector of a CasADi 3 × 3 rotation (exact away from π; Appendix Eq. 12-14)."""
    v = 0.5 * ca.vertcat(R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1])
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

    def __init__(self, robot: RobotModel, grasps: dict[str, pin.SE3]):
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
        self._build()

    # ------------------------------------------------------------------ code generation
    def _arm_terms(self, sk: SymbolicKinematics, q, Ro, po, damp, with_step: bool = True):
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

    def _build(self):
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
        # closed-chain residual, Eq. 1-2: T_e = T_2^-1 T_1 T_21, h = [p_e; roll; pitch; yaw]
        (R1, p1), (R2, p2) = terms[0][3], terms[1][3]
        R21, p21 = ca.DM(np.array(self.T21.rotation)), ca.DM(np.array(self.T21.translation))
        Re = R2.T @ R1 @ R21
        pe = R2.T @ (R1 @ p21 + p1 - p2)
        h = ca.vertcat(pe, ca.atan2(Re[2, 1], Re[2, 2]), -ca.atan2(Re[2, 0], ca.sqrt(Re[2, 1] ** 2 + Re[2, 2] ** 2)),
                       ca.atan2(Re[1, 0], Re[0, 0]))
        Jh = ca.jacobian(h, q)
        hfun = ca.Function("occ_h", [q], [h])
        hjfun = ca.Function("occ_hj", [q], [ca.vertcat(h, ca.vec(ca.densify(Jh)))])
        self._fun = {"step": step, "h": hfun, "hj": hjfun}
        self._fast: dict[str, _Fast] = {}
        self._block = _Fast(block, "-O1")   # -O1: a third less compile time than -O2, same speed here
        self.compiled = self._block.compiled
        if not self.compiled:
            log.warning("closed-chain kinematics run interpreted (no C compiler): planners will be slow")
        self._par = np.zeros(6)

    def _get(self, name: str) -> _Fast:
        """Compiled on first use (only the IK block is needed by TCBiRRT)."""
        f = self._fast.get(name)
        if f is None:
            f = self._fast[name] = _Fast(self._fun[name])
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
        """Closed-chain residual (Eq. 2): position [m] and RPY [rad] of ``T_2⁻¹ T_1 T_21``."""
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


def closure_error(robot: RobotModel, grasps: dict[str, pin.SE3], q, data: pin.Data | None = None) -> tuple[float, float]:
    """Independent check with Pinocchio FK: ``(position error [m], rotation error [rad])`` of the
    hands' relative pose against the grasps' (same measure as :func:`optplan.verify.verify`)."""
    a, b = list(grasps)
    data = data or robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, np.asarray(q, float))
    rel = data.oMf[robot.arm(a).ee_frame_id].actInv(data.oMf[robot.arm(b).ee_frame_id])
    err = grasps[a].actInv(grasps[b]).actInv(rel)
    return float(np.linalg.norm(err.translation)), float(np.linalg.norm(pin.log3(err.rotation)))
