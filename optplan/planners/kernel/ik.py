"""The closed-chain IK of TCBiRRT's native extension, hand-written in C (:mod:`.ik_csource`).

:class:`NativeIK` describes the two arms of a
:class:`~optplan.constraints.closed_chain.ClosedChainKinematics` on the planning kernel's joint model (each
arm's chain, its Jacobian columns, its hand frame and grasp, the joint limits) for the C code of the
extension library (:func:`~optplan.planners.kernel.extend.load_extend_library`). The extension's path IK
and its random restarts then run Alg. 4 there instead of calling the compiled CasADi block: the same
iterates up to round-off, with per iteration only the chains of the arms not yet converged.
:meth:`NativeIK.solve` and :meth:`NativeIK.jacobian` call it from Python (the tests compare them with the
CasADi block and with Pinocchio).
"""
from __future__ import annotations

import ctypes
from typing import Any

import numpy as np

from ...errors import ConfigurationError, UsageError
from .native import KernelUnavailable, se3_pose12

__all__ = ["NativeIK"]

_P = ctypes.c_void_p
_MAXC = 32            # TIK_MAXC of the C source: joints per arm chain


class _IKM(ctypes.Structure):
    _fields_ = [("km", _P), ("nchain", ctypes.c_int * 2), ("chain", _P), ("col", _P), ("na", ctypes.c_int * 2),
                ("qidx", _P), ("eej", ctypes.c_int * 2), ("eeplace", _P), ("grasp", _P), ("lower", _P), ("upper", _P)]


class NativeIK:
    """The arms of ``kin`` (:class:`~optplan.constraints.closed_chain.ClosedChainKinematics`, fixed base) on
    the joint model of ``kernel`` (:class:`~optplan.planners.kernel.native.NativeKernel` of the same robot),
    run by ``lib``, the extension library (:func:`optplan.planners.kernel.extend.load_extend_library`).

    Raises :class:`~optplan.planners.kernel.native.KernelUnavailable` when the arms are not serial chains of
    1-dof joints (at most 32 per arm) of the kernel's model or the library cannot be built."""

    def __init__(self, kernel: Any, kin: Any, lib: Any) -> None:
        self.lib = lib
        model = kin.robot.model
        jparent, jtype = kernel._arrays[0], kernel._arrays[1]
        if len(jparent) != model.njoints or model.nq != model.nv or int(kin.nq) != model.nq:
            raise KernelUnavailable("the native IK needs the kernel's joint model of a fixed-base robot")
        chain = np.full((2, _MAXC), -1, np.int32)
        col = np.full((2, _MAXC), -1, np.int32)
        qidx = np.zeros((2, _MAXC), np.int32)
        ee = np.zeros((2, 12))
        grasp = np.zeros((2, 12))
        s = _IKM()
        for a, arm in enumerate(kin.arms):
            f = model.frames[int(arm.ee_frame_id)]
            js = []
            j = int(f.parentJoint)
            while j > 0:
                js.append(j)
                j = int(jparent[j])
            js.reverse()
            v_idx = [int(i) for i in arm.v_idx]
            if len(js) > _MAXC or len(v_idx) > _MAXC:
                raise KernelUnavailable(f"the native IK covers chains of up to {_MAXC} joints")
            for i, j in enumerate(js):
                if int(jtype[j]) not in (1, 2, 3, 4, 5) or model.joints[j].nv != 1:
                    raise KernelUnavailable(f"the native IK covers 1-dof joints; joint {model.names[j]!r} is not one")
                chain[a, i] = j
                iv = int(model.joints[j].idx_v)
                col[a, i] = v_idx.index(iv) if iv in v_idx else -1
            if sorted(c for c in col[a] if c >= 0) != list(range(len(v_idx))):
                raise KernelUnavailable("the native IK needs every joint of an arm on its hand's chain")
            qidx[a, :len(v_idx)] = v_idx
            ee[a] = se3_pose12(f.placement)
            grasp[a] = se3_pose12(kin.grasps[arm.name])
            s.nchain[a], s.na[a], s.eej[a] = len(js), len(v_idx), int(f.parentJoint)
        self._arrays = (chain, col, qidx, ee, grasp, np.ascontiguousarray(kin.lower, float),
                        np.ascontiguousarray(kin.upper, float))
        self._kernel = kernel
        s.km = kernel._km_p
        s.chain, s.col, s.qidx, s.eeplace, s.grasp, s.lower, s.upper = (x.ctypes.data for x in self._arrays)
        self._s = s
        #: the address of the C description (``tcb_ikm *``), for the extension's context
        self.address = ctypes.addressof(s)
        self.nq = int(kin.nq)
        self.na = (int(s.na[0]), int(s.na[1]))
        lib = self.lib
        lib.tik_solve_api.restype = ctypes.c_int
        lib.tik_solve_api.argtypes = [_P, ctypes.c_int, _P, _P, _P, _P, _P]
        lib.tik_jacobian_api.restype = None
        lib.tik_jacobian_api.argtypes = [_P, ctypes.c_int, _P, _P, _P, _P]

    @staticmethod
    def _pose(R: np.ndarray, p: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate([np.asarray(R, float).reshape(9), np.asarray(p, float).reshape(3)]))

    def solve(self, q_seed: np.ndarray, R_obj: np.ndarray, p_obj: np.ndarray, s: Any) -> tuple[np.ndarray | None, int]:
        """:meth:`~optplan.constraints.closed_chain.ClosedChainKinematics.ik` (Alg. 4, settings ``s``:
        :class:`~optplan.constraints.closed_chain.IKSettings`) toward the object at ``(R_obj, p_obj)`` [m]:
        ``(q, iterations)``, ``q`` None when not converged."""
        q0 = np.ascontiguousarray(q_seed, dtype=float)
        if q0.shape != (self.nq,):
            raise ConfigurationError(f"q_seed: expected {self.nq} joint values, got shape {q0.shape}")
        P = self._pose(R_obj, p_obj)
        par = np.array([s.damping, s.tol_position, s.tol_orientation, s.gain, s.max_step, s.max_iterations], float)
        out = np.empty(self.nq)
        its = ctypes.c_longlong(0)
        ok = self.lib.tik_solve_api(self.address, self.nq, q0.ctypes.data, P.ctypes.data, par.ctypes.data,
                                    out.ctypes.data, ctypes.byref(its))
        return (out if ok else None), int(its.value)

    def jacobian(self, arm: int, q: np.ndarray, R_obj: np.ndarray, p_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Arm ``arm`` (0 or 1) at ``q``: its errors ``(e_p [m], e_o [rad])`` against the grasp of the object at
        ``(R_obj, p_obj)`` and the world-aligned Jacobian of its hand (6 × the arm's joints)."""
        if arm not in (0, 1):
            raise UsageError(f"arm: expected 0 or 1, got {arm!r}")
        q0 = np.ascontiguousarray(q, dtype=float)
        if q0.shape != (self.nq,):
            raise ConfigurationError(f"q: expected {self.nq} joint values, got shape {q0.shape}")
        P = self._pose(R_obj, p_obj)
        e = np.empty(6)
        J = np.empty((6, self.na[arm]))
        self.lib.tik_jacobian_api(self.address, arm, q0.ctypes.data, P.ctypes.data, e.ctypes.data, J.ctypes.data)
        return e, J
