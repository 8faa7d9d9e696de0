"""Symbolic per-point quantities of a trajectory problem, for constraints and costs in one line.

    prob.q, prob.qd, prob.qdd          joint position [rad], velocity [rad/s], acceleration [rad/s²]
    prob.t, prob.T                     time of the point [s], duration [s]
    prob.frame("a_ee").translation     world position of a frame [m] (3 × 1), .rotation (3 × 3)
    prob.com                           centre of mass [m] (world)
    prob.base.rotation                 base attitude (floating robots, world, 3 × 3)
    prob.parameter(shape, value)       a value that can change between solves without a rebuild

Each handle is a CasADi ``SX`` expression of one point's quantities, indexable and combinable as
any CasADi expression (``prob.qd[1]``, ``ca.sumsqr(prob.qdd)``, ``prob.frame("a_ee").rotation[2, 2]``).
The problem turns an expression into a per-point kernel (:func:`point_kernel`), a CasADi Function of
the point's raw inputs — the B-spline's q, dq/du, d²q/du² at the point, the base quaternion, the
point's time fraction, T, the base's start attitude and centre of mass, the parameters — that the
transcription maps over its points, compiled and cached per robot and structure.

A new per-point quantity is registered with ONE function, :func:`register_quantity`:
``register_quantity("tau", lambda s: my_tau(s.q, s.qd, s.qdd))`` makes ``prob.tau`` available on
every problem (``s``: the :class:`PointSymbols` of the problem's robot).

Frames and the centre of mass are checked once per robot and frame against Pinocchio at a random
configuration (``numpy.random.default_rng(0)``): a mismatch is a :class:`~optplan.errors.ModelError`.
"""
from __future__ import annotations

import hashlib
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
import pinocchio as pin

from ..errors import ConfigurationError, ModelError, UnknownNameError
from ..model.robot import RobotModel
from ..model.symbolic import quat_to_matrix

__all__ = ["PointSymbols", "Frame", "Parameter", "register_quantity", "point_kernel", "symbols_of"]

#: tolerance of the Pinocchio twin check of frames and centre of mass [m, rad]
TWIN_TOL = 1e-9

_QUANTITIES: dict[str, Callable[[PointSymbols], Any]] = {}


def register_quantity(name: str, fn: Callable[[PointSymbols], Any]) -> None:
    """Make ``prob.<name>`` the per-point expression ``fn(symbols)`` on every problem
    (``symbols``: :class:`PointSymbols` of its robot: ``q``, ``qd``, ``qdd``, ``frame(name)``, …)."""
    if not name.isidentifier():
        raise ConfigurationError(f"register_quantity: expected an identifier, got {name!r}")
    _QUANTITIES[name] = fn


def quantity(symbols: PointSymbols, name: str) -> Any:
    """The registered quantity ``name`` for ``symbols`` (AttributeError when none)."""
    fn = _QUANTITIES.get(name)
    if fn is None:
        raise AttributeError(name)
    return fn(symbols)


@dataclass(frozen=True)
class Frame:
    """A frame's world placement at one point: ``translation`` [m] (3 × 1), ``rotation`` (3 × 3)."""

    name: str
    translation: Any
    rotation: Any


@dataclass(frozen=True)
class Base:
    """A floating base's world placement at one point: ``rotation`` (3 × 3), ``translation`` [m]."""

    rotation: Any
    translation: Any


class Parameter:
    """A problem parameter: an ``SX`` symbol of ``shape`` (use it in any expression) with a value
    that :meth:`OptProblem.set_value` changes between solves without rebuilding anything."""

    def __init__(self, index: int, shape: tuple[int, int], value: np.ndarray):
        self.index, self.shape = index, shape
        self.sym = ca.SX.sym(f"par{index}", *shape)
        self.value = value

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1]


class PointSymbols:
    """The symbols of one point of a trajectory of ``robot`` (one set per robot, shared by its
    problems so that equal expressions hash equally): ``q``, ``qd``, ``qdd`` (nj × 1), ``t``,
    ``T``, and for a floating robot ``xi`` (the base attitude relative to the start, quaternion
    ``x, y, z, w``), ``base0`` (the start attitude, quaternion) and ``com0`` (the fixed centre of
    mass [m], world)."""

    def __init__(self, robot: RobotModel):
        from .floating_kernels import FloatingKernels
        from .kernels import KernelCache

        self.robot = robot
        self.floating = robot.is_floating
        self.kc = FloatingKernels.of(robot) if self.floating else KernelCache.of(robot)
        nj = robot.nj
        self.q = self.kc._q
        self.qd, self.qdd = ca.SX.sym("qd", nj), ca.SX.sym("qdd", nj)
        self.t, self.T = ca.SX.sym("t"), ca.SX.sym("T")
        self.xi = ca.SX.sym("xi", 4) if self.floating else ca.SX(0, 1)
        self.base0 = ca.SX.sym("base0", 4) if self.floating else ca.SX(0, 1)
        self.com0 = ca.SX.sym("com0", 3) if self.floating else ca.SX(0, 1)
        self._frames: dict[str, Frame] = {}
        self._checked: set[str] = set()
        self._com: Any = None

    # ------------------------------------------------------------------ inputs
    def inputs(self) -> list[Any]:
        """The point's symbols in kernel order (parameters follow)."""
        return [self.q, self.qd, self.qdd, self.xi, self.t, self.T, self.base0, self.com0]

    def base_rotation(self) -> Any:
        """World base attitude ``R(base0) R(xi)`` (floating robots)."""
        if not self.floating:
            raise ConfigurationError(f"{self.robot.name!r} has a fixed base: it has no base attitude")
        return quat_to_matrix(self.base0) @ quat_to_matrix(self.xi)

    def _com_base(self) -> Any:
        """Centre of mass in the base frame (floating) or world (fixed)."""
        if self._com is None:
            qf = ca.vertcat(ca.DM([0, 0, 0, 0, 0, 0, 1.0]), self.q) if self.floating else self.q
            self._com = self.kc.sym.center_of_mass(qf, self.kc._X)
        return self._com

    def base(self) -> Base:
        Rw = self.base_rotation()
        return Base(Rw, self.com0 - Rw @ self._com_base())

    def com(self) -> Any:
        """Centre of mass [m], world (a floating robot's stays at ``com0``: zero momentum)."""
        self._check("__com__")
        return self.com0 if self.floating else self._com_base()

    def frame(self, name: str) -> Frame:
        """World placement of frame ``name`` (floating: composed with the base, whose position
        keeps the centre of mass at ``com0``)."""
        got = self._frames.get(name)
        if got is not None:
            return got
        if not isinstance(name, str) or not self.robot.model.existFrame(name):
            names = [f.name for f in self.robot.model.frames]
            raise UnknownNameError("frame", name, names)
        fid = self.robot.model.getFrameId(name)
        R, p = self.kc.frame(fid)
        if self.floating:
            Rw = self.base_rotation()
            R, p = Rw @ R, self.com0 + Rw @ (p - self._com_base())
        self._check(name, R, p)
        f = self._frames[name] = Frame(name, p, R)
        return f

    # ------------------------------------------------------------------ Pinocchio twin check
    def _check(self, name: str, R: Any = None, p: Any = None) -> None:
        """Compare the symbolic frame (or the centre of mass, ``name="__com__"``) with Pinocchio
        at a random point, once per robot and name."""
        if name in self._checked:
            return
        rng = np.random.default_rng(0)
        robot, model = self.robot, self.robot.model
        lo = np.where(np.isfinite(robot.lower), robot.lower, -np.pi)
        hi = np.where(np.isfinite(robot.upper), robot.upper, np.pi)
        qj = rng.uniform(lo, hi)
        vals: list[tuple[Any, Any]] = [(self.q, qj)]
        data = model.createData()
        if self.floating:
            xi = rng.normal(size=4)
            xi /= np.linalg.norm(xi)
            b0 = rng.normal(size=4)
            b0 /= np.linalg.norm(b0)
            c0 = rng.normal(size=3)
            Rw = pin.Quaternion(b0[3], *b0[:3]).toRotationMatrix() @ pin.Quaternion(xi[3], *xi[:3]).toRotationMatrix()
            cb = pin.centerOfMass(model, data, np.r_[np.zeros(6), 1.0, qj]).copy()
            qfull = np.r_[c0 - Rw @ cb, pin.Quaternion(Rw).coeffs(), qj]
            vals += [(self.xi, xi), (self.base0, b0), (self.com0, c0)]
        else:
            qfull = qj
        if name == "__com__":
            sym = [self.com0 if self.floating else self._com_base()]
            ref = [pin.centerOfMass(model, data, qfull).copy()]
        else:
            pin.framesForwardKinematics(model, data, qfull)
            M = data.oMf[model.getFrameId(name)]
            sym, ref = [p, R], [M.translation, M.rotation]
        fn = ca.Function("twin", [v[0] for v in vals], sym)
        got = fn(*[v[1] for v in vals])
        got = got if isinstance(got, (list, tuple)) else [got]
        for g, r in zip(got, ref):
            err = float(np.max(np.abs(np.array(g).reshape(np.shape(r)) - r)))
            if not err <= TWIN_TOL:
                raise ModelError(f"{self.robot.name!r}: the symbolic {name if name != '__com__' else 'centre of mass'}"
                                 f" differs from Pinocchio's by {err:.3g} at a random configuration "
                                 f"(expected ≤ {TWIN_TOL})")
        self._checked.add(name)


_SYMBOLS: weakref.WeakKeyDictionary[RobotModel, PointSymbols] = weakref.WeakKeyDictionary()


def symbols_of(robot: RobotModel) -> PointSymbols:
    """The :class:`PointSymbols` of ``robot`` (one per robot object)."""
    s = _SYMBOLS.get(robot)
    if s is None:
        s = _SYMBOLS[robot] = PointSymbols(robot)
    return s


# --------------------------------------------------------------------------- kernels
#: kinds of point kernels: "point" (a constraint's rows), "cost" (weight × rows' value summed,
#: times the quadrature weight input)
def point_kernel(symbols: PointSymbols, expr: Any, params: list[Parameter], N: int, kind: str,
                 weight: Any = 1.0) -> ca.Function:
    """The per-point kernel of ``expr``: ``f(z) -> rows`` with the raw inputs
    ``z = [q; dq/du; d²q/du²; xi; s; T; base0; com0; parameters; w]`` of one point (u = t·N/T:
    time in intervals; s = t/T; w: the quadrature weight, cost kernels only) — the B-spline gives
    these as fixed linear combinations of its decision variables. ``kind="cost"``: a scalar
    ``weight · w · Σ rows²`` (one row: ``weight · w · row`` when the expression is a scalar)."""
    expr = ca.SX(expr) if not isinstance(expr, ca.SX) else expr
    check_symbols(symbols, expr, params, "expression")
    nj = symbols.robot.nj
    fl = symbols.floating
    q, qu, quu = ca.SX.sym("q", nj), ca.SX.sym("q_u", nj), ca.SX.sym("q_uu", nj)
    xi = ca.SX.sym("xi", 4 if fl else 0)
    s, T = ca.SX.sym("s"), ca.SX.sym("T")
    b0, c0 = ca.SX.sym("base0", 4 if fl else 0), ca.SX.sym("com0", 3 if fl else 0)
    par = [ca.SX.sym(f"par{i}", *p.shape) for i, p in enumerate(params)]
    w = ca.SX.sym("w")
    user = ca.Function("user", symbols.inputs() + [p.sym for p in params], [ca.vec(expr)])
    r = user(q, qu * N / T, quu * (N / T) ** 2, xi, s * T, T, b0, c0, *par)
    z = [q, qu, quu, xi, s, T, b0, c0] + [ca.vec(p) for p in par]
    if kind == "cost":
        wexpr = ca.SX(weight) if not isinstance(weight, ca.SX) else weight
        check_symbols(symbols, wexpr, params, "weight")
        wf = ca.Function("wf", [p.sym for p in params], [wexpr])(*par) if params else ca.DM(ca.evalf(wexpr))
        r = wf * w * (r if r.shape[0] == 1 else ca.sumsqr(r))
        z.append(w)
    zz = ca.vertcat(*z)
    f = ca.Function("k", [zz], [r])
    h = hashlib.sha1(f.serialize().encode())
    return ca.Function(f"expr_{kind}_{h.hexdigest()[:16]}", [zz], [f(zz)])


def check_symbols(symbols: PointSymbols, expr: Any, params: list[Parameter], what: str) -> None:
    """Refuse an expression with a symbol that is neither a point quantity of this robot nor a
    parameter of this problem."""
    inputs = symbols.inputs() + [p.sym for p in params]
    try:
        ca.Function("check", inputs, [expr])
    except RuntimeError:
        own = {s.name() for v in inputs for s in ca.symvar(v)}
        names = sorted({s.name() for s in ca.symvar(expr)} - own) or sorted({s.name() for s in ca.symvar(expr)})
        raise ConfigurationError(f"{what}: symbols {names} are neither quantities of this problem "
                                 "(prob.q, prob.qd, prob.frame(...), ...) nor its parameters (prob.parameter)"
                                 ) from None


def parameter_value(value: Any, shape: tuple[int, int], what: str) -> np.ndarray:
    """``value`` as a finite float array of ``shape`` (column-major ravel order, as CasADi)."""
    a = np.asarray(value, float)
    if a.size == shape[0] * shape[1] and a.ndim <= 2:
        a = a.reshape(shape, order="F") if a.shape != shape else a
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise ConfigurationError(f"{what}: expected finite numbers of shape {shape}, got {value!r}")
    return a.copy()
