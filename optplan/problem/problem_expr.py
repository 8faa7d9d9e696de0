"""The expression side of :class:`~optplan.problem.OptProblem`: the per-point quantities users
write constraints and costs with (``prob.q``, ``prob.frame("a_ee").translation``, …), parameters
(``prob.parameter``, ``prob.set_value``) and registered quantities (``prob.<name>``,
:func:`~optplan.problem.expressions.register_quantity`)."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigurationError, OptionError
from ..model.robot import RobotModel
from .expr_term import ExprTerm, knots_of
from .expressions import Base, Frame, Parameter, parameter_value, quantity, symbols_of
from .spline_problem import Unsupported

__all__ = ["ExpressionAPI", "check_weight"]


def check_weight(weight: Any) -> None:
    """A cost weight: a finite number ≥ 0 (an OptionError naming it otherwise)."""
    if isinstance(weight, bool) or not isinstance(weight, (int, float, np.integer, np.floating)) \
            or not np.isfinite(weight) or weight < 0:
        raise OptionError(f"weight: expected a finite number ≥ 0, got {weight!r}")


class ExpressionAPI:
    """Mixin of :class:`OptProblem`: symbolic per-point quantities and parameters."""

    robot: RobotModel
    _params: list[Parameter]
    _built: Any
    _handles: list[Any]
    _spline: Any
    transcription: str
    N: int

    # the problem's own (OptProblem defines them): forget what was built; add a term under a name
    _changed: Callable[[], None]
    _add: Callable[[Any, str, str | None, float], Any]

    def _add_expression(self, role: str, e: Any, name: str | None, **kw: Any) -> Any:
        """An :class:`ExprTerm` of expression ``e`` (``kw``: its bounds and knots, or its kind
        and weight), checked and added under ``name``."""
        what = "add_cost" if role == "cost" else "add_constraint"
        if role == "cost":
            if kw["kind"] not in ("integral", "end"):
                raise OptionError(f"add_cost: kind: expected 'integral' or 'end', got {kw['kind']!r}")
            if not isinstance(kw["weight"], ca.SX):
                check_weight(kw["weight"])
        else:
            if kw["lower"] is None and kw["upper"] is None:
                raise OptionError("add_constraint: give lower and/or upper for an expression")
            knots_of(kw["at"], self.N, name or what)
        term = ExprTerm(expr=self._expression(e, what), params=tuple(self._params), **kw)
        return self._add(term, role, name, 1.0)

    def _expression(self, e: Any, what: str) -> ca.SX:
        if isinstance(e, Parameter):
            e = e.sym
        if isinstance(e, (ca.MX,)):
            raise OptionError(f"{what}: expected an expression of prob.q, prob.frame(...), ... (CasADi SX), got MX")
        try:
            return ca.SX(e)
        except (NotImplementedError, TypeError, RuntimeError):
            raise OptionError(f"{what}: expected a term or an expression of the problem's quantities, got "
                              f"{type(e).__name__} {e!r}") from None

    # ------------------------------------------------------------------ expressions
    @property
    def q(self) -> ca.SX:
        """Joint positions at a point [rad] (nj × 1)."""
        return symbols_of(self.robot).q

    @property
    def qd(self) -> ca.SX:
        """Joint velocities at a point [rad/s] (nj × 1)."""
        return symbols_of(self.robot).qd

    @property
    def qdd(self) -> ca.SX:
        """Joint accelerations at a point [rad/s²] (nj × 1)."""
        return symbols_of(self.robot).qdd

    @property
    def t(self) -> ca.SX:
        """Time of a point [s]."""
        return symbols_of(self.robot).t

    @property
    def T(self) -> ca.SX:
        """Duration [s] (a variable when ``free_time``)."""
        return symbols_of(self.robot).T

    @property
    def com(self) -> ca.SX:
        """Centre of mass [m], world (3 × 1)."""
        return symbols_of(self.robot).com()

    @property
    def base(self) -> Base:
        """A floating base's world ``rotation`` (3 × 3) and ``translation`` [m] at a point."""
        return symbols_of(self.robot).base()

    def frame(self, name: str) -> Frame:
        """World placement of a frame at a point: ``.translation`` [m] (3 × 1), ``.rotation``."""
        return symbols_of(self.robot).frame(name)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_") or "robot" not in self.__dict__:
            raise AttributeError(name)
        try:
            return quantity(symbols_of(self.robot), name)
        except AttributeError:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}") from None

    def parameter(self, shape: int | tuple[int, int] = 1, value: ArrayLike | None = None) -> ca.SX:
        """A parameter of ``shape`` (n or (n, m)) with ``value`` (default zeros), usable in any
        expression, bound and cost weight; :meth:`set_value` changes it without a rebuild."""
        shp = (int(shape), 1) if isinstance(shape, (int, np.integer)) else tuple(int(s) for s in shape)
        if len(shp) != 2 or min(shp) < 1:
            raise OptionError(f"parameter: shape: expected n or (n, m) with n, m ≥ 1, got {shape!r}")
        val = parameter_value(np.zeros(shp) if value is None else value, shp, "parameter: value")
        par = Parameter(len(self._params), (shp[0], shp[1]), val)
        self._params.append(par)
        self._changed()
        return par.sym

    def set_value(self, parameter: Any, value: ArrayLike) -> None:
        """Give a parameter a new value; the next solve reuses the built NLP."""
        for par in self._params:
            if parameter is par.sym or (isinstance(parameter, ca.SX) and parameter.shape == par.sym.shape
                                        and ca.is_equal(parameter, par.sym)):
                par.value = parameter_value(value, par.shape, "set_value: value")
                self._built = None   # the knot transcription takes parameters as numbers
                return
        raise OptionError(f"set_value: {parameter!r} is not a parameter of this problem (prob.parameter)")

    def uses_bspline(self) -> bool:
        """Whether the next solve runs on the B-spline kernel core (see ``transcription``)."""
        return self._mode() == "bspline"

    def _mode(self) -> str:
        """"bspline" or "knots" for the next solve (``transcription``; "auto": the B-spline
        unless N < 4 or a term has no kernels there)."""
        if self.transcription == "knots" or (self.transcription == "auto" and self.N < 4):
            return "knots"
        if self.N < 4:
            raise ConfigurationError(f"the B-spline transcription needs n_intervals ≥ 4, got {self.N}")
        if self._spline.core is None:
            try:
                self._spline.prepare()
            except Unsupported as exc:
                if self.transcription == "bspline":
                    raise ConfigurationError(f"the B-spline transcription has no kernels for {exc}; use "
                                             "transcription='knots'") from None
                return "knots"
        return "bspline"
