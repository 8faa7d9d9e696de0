"""Per-call times of the numeric (Pinocchio) and symbolic (CasADi) kinematics.

Run: ``optplan bench kinematics [--robot eba_ffsr] [--calls 5000]``. Targets: generalized
Jacobian of both arms ≤ 20 µs numeric; CasADi FK + Jacobian within 5× of Pinocchio per call.
"""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import pinocchio as pin

from ..codegen import compile_function
from ..model.kinematics import Kinematics
from ..model.robot import RobotModel
from ..model.symbolic import SymbolicKinematics


def _per_call(fn: Callable[[], object], calls: int) -> float:
    """Best of 3 batches, seconds per call."""
    fn()
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - t0) / calls)
    return best


def run(robot_name: str = "eba_ffsr", calls: int = 5000, seed: int = 0) -> dict[str, float]:
    """Return ``{name: µs per call}``."""
    if isinstance(calls, bool) or not isinstance(calls, int) or calls < 1:
        from ..errors import OptionError

        raise OptionError(f"calls: expected an integer >= 1, got {calls!r}")
    robot = RobotModel.from_name(robot_name)
    kin, sym = Kinematics(robot), SymbolicKinematics(robot)
    model, data = robot.model, kin.data
    q = robot.random_configuration(np.random.default_rng(seed))
    arm = next(iter(robot.arms.values()))
    fid = arm.ee_frame_id
    LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    out: dict[str, float] = {}

    def pin_fk():
        pin.framesForwardKinematics(model, data, q)
        return data.oMf[fid]

    def pin_fk_jac():
        pin.framesForwardKinematics(model, data, q)
        return pin.computeFrameJacobian(model, data, q, fid, LWA)

    out["pinocchio FK (frames)"] = _per_call(pin_fk, calls)
    out["pinocchio FK + frame Jacobian"] = _per_call(pin_fk_jac, calls)
    out["pinocchio centroidal map Ag"] = _per_call(lambda: pin.computeCentroidalMap(model, data, q), calls)
    out["generalized Jacobian, both arms (numeric)"] = _per_call(lambda: kin.generalized_jacobians(q), calls)
    f = sym.fk_jacobian_function(fid)
    out["casadi FK + Jacobian (interpreted)"] = _per_call(lambda: f(q), calls)
    cf = compile_function(f)
    out["casadi FK + Jacobian (compiled C)"] = _per_call(lambda: cf(q), calls)
    fa = sym.centroidal_map_function()
    out["casadi centroidal map (interpreted)"] = _per_call(lambda: fa(q), calls)
    cfa = compile_function(fa)
    out["casadi centroidal map (compiled C)"] = _per_call(lambda: cfa(q), calls)
    if robot.is_floating:
        fg = sym.generalized_jacobian_function(arm.name)
        out["casadi generalized Jacobian, one arm (interpreted)"] = _per_call(lambda: fg(q), calls)
        cfg = compile_function(fg)
        out["casadi generalized Jacobian, one arm (compiled C)"] = _per_call(lambda: cfg(q), calls)
    return {k: v * 1e6 for k, v in out.items()}


def report(times: dict[str, float]) -> str:
    lines = [f"{'function':52s} {'µs/call':>9s}"]
    lines += [f"{k:52s} {v:9.2f}" for k, v in times.items()]
    gj = times["generalized Jacobian, both arms (numeric)"]
    ratio_i = times["casadi FK + Jacobian (interpreted)"] / times["pinocchio FK + frame Jacobian"]
    ratio_c = times["casadi FK + Jacobian (compiled C)"] / times["pinocchio FK + frame Jacobian"]
    lines.append("")
    lines.append(f"target: generalized Jacobian of both arms <= 20 us numeric   -> {gj:.1f} us "
                 f"{'OK' if gj <= 20 else 'MISSED'}")
    lines.append(f"target: CasADi FK + Jacobian within 5x of Pinocchio         -> interpreted {ratio_i:.1f}x, "
                 f"compiled {ratio_c:.1f}x {'OK' if min(ratio_i, ratio_c) <= 5 else 'MISSED'}")
    return "\n".join(lines)
