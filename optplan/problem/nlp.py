"""The NLP core every optplan optimizer solves through: options, one solver call, one outcome.

* :class:`SolverOptions` — a frozen, validated description of how IPOPT runs (``tol``,
  ``max_iter``, ``max_wall_time`` [s], ``print_level``, ``linear_solver``, ``hessian``) with a
  ``raw`` pass-through of any other IPOPT/CasADi option. A field left at ``None`` keeps the
  default of the NLP that uses it (each NLP documents its own measured defaults).
* :class:`NlpSolver` — a ``casadi.nlpsol`` IPOPT instance created once from ``{x, f, g[, p]}``
  and the options, called any number of times with new bounds, parameters and warm starts.
* :class:`SolveOutcome` — what one IPOPT run did: :class:`IpoptStatus`, iterations, wall and CPU
  time [s], setup time [s], cost, the primal ``x`` and the multipliers ``lam_g``/``lam_x``. A run
  that raises inside CasADi is an outcome with ``IpoptStatus.INTERNAL_ERROR`` and the message,
  never an exception.

Problem ≠ transcription ≠ solver (the rockit/CasADi Opti split): the problems
(:class:`~optplan.problem.OptProblem`, the quartic smoothing, the Fourier restoration, the arc
planner) build expressions; this module only runs IPOPT on them::

    opts = SolverOptions(tol=1e-8, max_iter=200, raw={"mu_strategy": "adaptive"})
    solver = NlpSolver("demo", {"x": x, "f": f, "g": g}, opts)
    out = solver.solve(x0=np.zeros(2), lbg=0.0, ubg=0.0)
    out.status.succeeded, out.iterations, out.wall_time, out.x, out.lam_g
"""
from __future__ import annotations

import dataclasses
import logging
import math
import time
import types
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np

from ..errors import OptionError
from .blas_threads import limited_blas_threads

__all__ = ["IpoptStatus", "SolverOptions", "SolveOutcome", "NlpSolver", "outcome_from_stats"]
log = logging.getLogger(__name__)


class IpoptStatus(str, Enum):
    """IPOPT's return status (``solver.stats()["return_status"]``), plus optplan's own failures."""

    SOLVE_SUCCEEDED = "Solve_Succeeded"
    SOLVED_TO_ACCEPTABLE_LEVEL = "Solved_To_Acceptable_Level"
    INFEASIBLE_PROBLEM_DETECTED = "Infeasible_Problem_Detected"
    SEARCH_DIRECTION_BECOMES_TOO_SMALL = "Search_Direction_Becomes_Too_Small"
    DIVERGING_ITERATES = "Diverging_Iterates"
    USER_REQUESTED_STOP = "User_Requested_Stop"
    FEASIBLE_POINT_FOUND = "Feasible_Point_Found"
    MAXIMUM_ITERATIONS_EXCEEDED = "Maximum_Iterations_Exceeded"
    RESTORATION_FAILED = "Restoration_Failed"
    ERROR_IN_STEP_COMPUTATION = "Error_In_Step_Computation"
    MAXIMUM_CPUTIME_EXCEEDED = "Maximum_CpuTime_Exceeded"
    MAXIMUM_WALLTIME_EXCEEDED = "Maximum_WallTime_Exceeded"
    NOT_ENOUGH_DEGREES_OF_FREEDOM = "Not_Enough_Degrees_Of_Freedom"
    INVALID_PROBLEM_DEFINITION = "Invalid_Problem_Definition"
    INVALID_OPTION = "Invalid_Option"
    INVALID_NUMBER_DETECTED = "Invalid_Number_Detected"
    UNRECOVERABLE_EXCEPTION = "Unrecoverable_Exception"
    NONIPOPT_EXCEPTION_THROWN = "NonIpopt_Exception_Thrown"
    INSUFFICIENT_MEMORY = "Insufficient_Memory"
    INTERNAL_ERROR = "Internal_Error"
    UNKNOWN = "Unknown"
    #: converged, but a constraint is violated between knots (optplan's dense check)
    VIOLATED_BETWEEN_KNOTS = "Violated_Between_Knots"
    #: optplan's own: a configuration a JointBoundary pins is in collision (checked before IPOPT runs;
    #: the NLP cannot move it, and with its rows left out IPOPT would report success)
    BOUNDARY_IN_COLLISION = "Boundary_In_Collision"

    @classmethod
    def from_string(cls, s: str) -> IpoptStatus:
        return _STATUS_BY_NAME.get(str(s).lower(), cls.UNKNOWN)

    @property
    def succeeded(self) -> bool:
        return self in (IpoptStatus.SOLVE_SUCCEEDED, IpoptStatus.SOLVED_TO_ACCEPTABLE_LEVEL)

    @property
    def infeasible(self) -> bool:
        return self in (IpoptStatus.INFEASIBLE_PROBLEM_DETECTED, IpoptStatus.RESTORATION_FAILED)


_STATUS_BY_NAME = {m.value.lower(): m for m in IpoptStatus}
#: statuses of a run IPOPT ends before its first iteration
_NOT_STARTED = frozenset({IpoptStatus.INVALID_OPTION, IpoptStatus.INVALID_PROBLEM_DEFINITION,
                          IpoptStatus.NOT_ENOUGH_DEGREES_OF_FREEDOM})
_HESSIANS = ("exact", "limited-memory")
#: (name, type, value) of raw options IPOPT already accepted in this process (checking one creates
#: a solver instance: about a millisecond)
_CHECKED: set[tuple[str, str, str]] = set()


def _option_key(k: Any, v: Any) -> tuple[str, str, str]:
    return (str(k), type(v).__name__, repr(v))


def _number(value: Any, name: str, *, integer: bool = False, positive: bool = True, allow_zero: bool = False) -> None:
    bad = isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating))
    if not bad and integer and not float(value).is_integer():
        bad = True
    if not bad and not math.isfinite(float(value)):
        bad = True
    if not bad and positive and (value < 0 or (value == 0 and not allow_zero)):
        bad = True
    if bad:
        what = "an integer" if integer else "a finite number"
        rng = " ≥ 0" if allow_zero else (" > 0" if positive else "")
        raise OptionError(f"SolverOptions.{name}: expected {what}{rng}, got {value!r}")


@dataclass(frozen=True)
class SolverOptions:
    """How IPOPT runs. ``None`` keeps the default of the NLP that uses the options."""

    #: IPOPT's ``tol`` [-]; the problems of :mod:`optplan.problem` also use it as the constraint-violation
    #: tolerance (``constr_viol_tol``) and the bound ``Solution.success`` requires.
    tol: float | None = None
    #: Iteration cap [count] (integer ≥ 0).
    max_iter: int | None = None
    #: Wall-clock cap per solve [s] (> 0); a solve that hits it ends with
    #: ``IpoptStatus.MAXIMUM_WALLTIME_EXCEEDED``.
    max_wall_time: float | None = None
    #: CPU-time cap per solve [s] (> 0).
    max_cpu_time: float | None = None
    #: IPOPT's console output [level], 0 (silent) … 12.
    print_level: int = 0
    #: IPOPT's ``linear_solver`` (``"mumps"`` is the one every install has).
    linear_solver: str | None = None
    #: ``"exact"`` or ``"limited-memory"`` (L-BFGS).
    hessian: str | None = None
    #: Threads of the BLAS under IPOPT's linear solver (the OpenBLAS CasADi ships, which MUMPS
    #: calls) during a solve [count] (integer ≥ 1); ``None`` leaves the library's own count (one per
    #: core, whose idle threads spin after each factorization). Restored after the solve
    #: (:mod:`optplan.problem.blas_threads`).
    blas_threads: int | None = 1
    #: Any other IPOPT option (``"mu_strategy"`` or ``"ipopt.mu_strategy"``) or CasADi nlpsol option
    #: (``"expand"``, ``"print_time"``), applied last: it overrides everything, the fields above included.
    #: Checked against IPOPT when the options are created.
    raw: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from ..solver_options import check_ipopt_options

        if self.tol is not None:
            _number(self.tol, "tol")
        if self.max_iter is not None:
            _number(self.max_iter, "max_iter", integer=True, allow_zero=True)
        for name in ("max_wall_time", "max_cpu_time"):
            if getattr(self, name) is not None:
                _number(getattr(self, name), f"{name} [s]")
        _number(self.print_level, "print_level", integer=True, allow_zero=True)
        if self.blas_threads is not None:
            _number(self.blas_threads, "blas_threads [count]", integer=True)
        if not 0 <= int(self.print_level) <= 12:
            raise OptionError(f"SolverOptions.print_level: expected an integer in 0..12, got {self.print_level!r}")
        if self.hessian is not None and self.hessian not in _HESSIANS:
            raise OptionError(f"SolverOptions.hessian: expected one of {_HESSIANS}, got {self.hessian!r}")
        if self.linear_solver is not None:
            if not isinstance(self.linear_solver, str):
                raise OptionError(f"SolverOptions.linear_solver: expected a name such as 'mumps', "
                                  f"got {self.linear_solver!r}")
            if _option_key("linear_solver", self.linear_solver) not in _CHECKED:
                check_ipopt_options({"linear_solver": self.linear_solver})
                _CHECKED.add(_option_key("linear_solver", self.linear_solver))
        if self.raw is None:
            object.__setattr__(self, "raw", types.MappingProxyType({}))
        if not isinstance(self.raw, Mapping):
            raise OptionError(f"SolverOptions.raw: expected a dict {{option: value}}, got "
                              f"{type(self.raw).__name__} {self.raw!r}")
        raw = dict(self.raw)
        new = {k: v for k, v in raw.items() if _option_key(k, v) not in _CHECKED}
        if new:
            try:
                check_ipopt_options(new)
            except OptionError as exc:
                raise OptionError(f"SolverOptions.raw: {exc}") from None
            _CHECKED.update(_option_key(k, v) for k, v in new.items())
        object.__setattr__(self, "raw", types.MappingProxyType(raw))

    def __getstate__(self) -> dict[str, Any]:
        d = dict(self.__dict__)
        d["raw"] = dict(d["raw"])
        return d

    def __setstate__(self, d: dict[str, Any]) -> None:
        for k, v in d.items():
            object.__setattr__(self, k, v)
        object.__setattr__(self, "raw", types.MappingProxyType(dict(d["raw"])))

    # ------------------------------------------------------------------ conversions
    @classmethod
    def coerce(cls, options: SolverOptions | Mapping[str, Any] | None, **fields: Any) -> SolverOptions:
        """``options`` as :class:`SolverOptions`: an instance (``fields`` given explicitly
        override its fields), a plain dict of IPOPT options (→ ``raw``, the pass-through the
        problems' ``solve(ipopt_options)`` always accepted) or ``None``."""
        fields = {k: v for k, v in fields.items() if v is not None}
        if options is None:
            return cls(**fields)
        if isinstance(options, SolverOptions):
            return dataclasses.replace(options, **fields) if fields else options
        if isinstance(options, Mapping):
            from ..solver_options import check_ipopt_options

            new = {k: v for k, v in options.items() if _option_key(k, v) not in _CHECKED}
            check_ipopt_options(new)   # the error names ipopt_options[...], as it always did
            _CHECKED.update(_option_key(k, v) for k, v in new.items())
            return cls(raw=options, **fields)
        raise OptionError(f"solver options: expected SolverOptions, a dict of IPOPT options or None, got "
                          f"{type(options).__name__} {options!r}")

    def replace(self, **changes: Any) -> SolverOptions:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    def casadi_options(self, defaults: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """The ``casadi.nlpsol`` options dict: the NLP's ``defaults`` (flat ``"ipopt.x"`` names),
        then the fields that are set, then ``raw``."""
        from ..solver_options import casadi_option_name

        opts: dict[str, Any] = {"print_time": False, "ipopt.sb": "yes"}
        for k, v in (defaults or {}).items():
            opts[casadi_option_name(k)] = v
        opts["ipopt.print_level"] = int(self.print_level)
        if self.print_level > 0:
            opts["print_time"] = True
        if self.tol is not None:
            opts["ipopt.tol"] = float(self.tol)
        if self.max_iter is not None:
            opts["ipopt.max_iter"] = int(self.max_iter)
        if self.max_wall_time is not None:
            opts["ipopt.max_wall_time"] = float(self.max_wall_time)
        if self.max_cpu_time is not None:
            opts["ipopt.max_cpu_time"] = float(self.max_cpu_time)
        if self.linear_solver is not None:
            opts["ipopt.linear_solver"] = self.linear_solver
        if self.hessian is not None:
            opts["ipopt.hessian_approximation"] = self.hessian
        for k, v in self.raw.items():
            opts[casadi_option_name(k)] = v
        return opts

    def raw_value(self, name: str, default: Any = None) -> Any:
        """The value of an IPOPT option given in ``raw`` (with or without the ``ipopt.`` prefix)."""
        for k in (name, f"ipopt.{name}"):
            if k in self.raw:
                return self.raw[k]
        return default


@dataclass(frozen=True)
class SolveOutcome:
    """One IPOPT run.

    status: :class:`IpoptStatus`; iterations: IPOPT iterations (−1 when IPOPT did not run, 0 when it
    refused to start: an invalid option or problem);
    wall_time / cpu_time [s]: the run; setup_time [s]: building the NLP and creating the solver
    before it (0 when a built solver was reused); cost: the objective at ``x`` (the problem's
    own, unscaled objective); x, lam_g, lam_x: primal and multipliers (CasADi's convention:
    ``lam < 0`` on an active lower bound, ``> 0`` on an active upper bound; ``None`` when not
    available); label: why this run happened (e.g. a retry's reason); message: the exception
    text of a run that raised; g: the constraint values at ``x``. Arrays are read-only.
    """

    status: IpoptStatus
    iterations: int
    wall_time: float
    cpu_time: float = 0.0
    setup_time: float = 0.0
    cost: float = float("nan")
    x: np.ndarray | None = field(default=None, repr=False, compare=False)
    lam_g: np.ndarray | None = field(default=None, repr=False, compare=False)
    lam_x: np.ndarray | None = field(default=None, repr=False, compare=False)
    label: str = ""
    message: str = ""
    #: the constraint values g(x) IPOPT returned (None when not computed)
    g: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.status, IpoptStatus):
            object.__setattr__(self, "status", IpoptStatus.from_string(self.status))
        for name in ("x", "lam_g", "lam_x", "g"):
            a = getattr(self, name)
            if a is not None:
                a = np.array(a, dtype=float).reshape(-1)   # a copy the outcome owns
                a.flags.writeable = False
                object.__setattr__(self, name, a)

    @property
    def success(self) -> bool:
        """IPOPT converged (``status.succeeded``); a problem may still require more (feasibility)."""
        return self.status.succeeded

    def summary(self) -> SolveOutcome:
        """The same outcome without its arrays (what a result's list of attempts keeps)."""
        return dataclasses.replace(self, x=None, lam_g=None, lam_x=None, g=None)

    def with_label(self, label: str) -> SolveOutcome:
        return dataclasses.replace(self, label=str(label))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no arrays)."""
        return {"status": self.status.value, "iterations": int(self.iterations), "wall_time": float(self.wall_time),
                "cpu_time": float(self.cpu_time), "setup_time": float(self.setup_time), "cost": float(self.cost),
                "label": self.label, "message": self.message}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SolveOutcome:
        return cls(status=IpoptStatus.from_string(d.get("status", "Unknown")), iterations=int(d.get("iterations", -1)),
                   wall_time=float(d.get("wall_time", 0.0)), cpu_time=float(d.get("cpu_time", 0.0)),
                   setup_time=float(d.get("setup_time", 0.0)), cost=float(d.get("cost", float("nan"))),
                   label=str(d.get("label", "")), message=str(d.get("message", "")))


def outcome_from_stats(stats: Mapping[str, Any], out: Mapping[str, Any] | None, *, wall_time: float, cpu_time: float = 0.0,
                       setup_time: float = 0.0, cost_scale: float = 1.0, label: str = "",
                       copy: bool = True) -> SolveOutcome:
    """A :class:`SolveOutcome` from ``solver.stats()`` and the solver's output dict (for NLPs
    that call a ``casadi.nlpsol`` of their own). ``cost_scale`` divides the returned ``f``;
    ``copy=False``: float vectors of ``out`` are kept, not copied (outputs made for this call alone)."""
    status = IpoptStatus.from_string(stats.get("return_status", "Unknown"))
    # a run IPOPT refused before its first iteration leaves its counter unset (measured: 10878976,
    # -919633488 for a linear solver whose library is missing): no iterations
    iters = 0 if status in _NOT_STARTED else int(stats.get("iter_count", -1))
    if out is None:
        return SolveOutcome(status, iters, wall_time, cpu_time, setup_time, label=label)
    def arr(k: str) -> np.ndarray | None:
        v = out.get(k)
        if v is None:
            return None
        if not copy and isinstance(v, np.ndarray) and v.dtype == np.float64 and v.ndim == 1:
            return v
        # a DM's elements (column-major) as a list: ~2× faster than DM.full() for a vector
        return np.array(v.elements(), dtype=float) if hasattr(v, "elements") else np.array(v, dtype=float).ravel()

    fa = arr("f")
    cost = float(fa[0]) / cost_scale if fa is not None and fa.size == 1 else float("nan")
    return SolveOutcome(status, iters, wall_time, cpu_time, setup_time, cost, arr("x"), arr("lam_g"),
                        arr("lam_x"), label=label, g=arr("g"))


class NlpSolver:
    """An IPOPT instance for ``nlp = {"x", "f", "g"[, "p"]}`` (CasADi expressions), created once.

    ``defaults``: the NLP's own IPOPT defaults (flat names, e.g. ``{"mu_strategy": "adaptive"}``);
    ``options`` (:class:`SolverOptions`) override them; ``casadi_options``: nlpsol options that
    are not IPOPT's (``expand``, ``hess_lag``, derivative Functions …), applied first.
    ``setup_time`` [s]: the creation of the instance (charged to the first solve's outcome).
    """

    def __init__(self, name: str, nlp: Mapping[str, Any], options: SolverOptions | Mapping[str, Any] | None = None, *,
                 defaults: Mapping[str, Any] | None = None,
                 casadi_options: Mapping[str, Any] | None = None) -> None:
        import casadi as ca

        self.options = SolverOptions.coerce(options)
        opts = dict(casadi_options or {})
        opts.update(self.options.casadi_options(defaults))
        self.casadi_opts = opts
        t0 = time.perf_counter()
        self.solver = ca.nlpsol(name, "ipopt", dict(nlp), opts)
        self.setup_time = time.perf_counter() - t0
        self._setup_pending = self.setup_time
        self._names = (list(self.solver.name_in()), list(self.solver.name_out()))
        self._buffer: Any = None            # (CasADi function buffer, its call), made with the first solve
        self._stats: dict[str, Any] | None = None

    def take_setup_time(self) -> float:
        """The creation time [s] not yet charged to a solve, which the caller now charges to its
        own (an instance made with another solve's build); the next :meth:`solve` charges none."""
        t, self._setup_pending = self._setup_pending, 0.0
        return t

    def solve(self, x0: Any, *, lbx: Any = None, ubx: Any = None, lbg: Any = None, ubg: Any = None, p: Any = None,
              lam_g0: Any = None, lam_x0: Any = None,
              cost_scale: float = 1.0, label: str = "", extra_setup: float = 0.0) -> SolveOutcome:
        """Run IPOPT from ``x0``. Never raises for a failed run: a CasADi/IPOPT exception becomes
        ``IpoptStatus.INTERNAL_ERROR`` with ``x = x0``. ``cost_scale`` divides the returned
        objective (for NLPs that scale their objective themselves); ``extra_setup`` [s] is added
        to the outcome's ``setup_time`` (e.g. the NLP's own construction)."""
        args: dict[str, Any] = {"x0": x0}
        for k, v in (("lbx", lbx), ("ubx", ubx), ("lbg", lbg), ("ubg", ubg), ("p", p), ("lam_g0", lam_g0),
                     ("lam_x0", lam_x0)):
            if v is not None:
                args[k] = v
        setup = self._setup_pending + float(extra_setup)
        self._setup_pending = 0.0
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            with limited_blas_threads(self.options.blas_threads):
                got = self._call_buffered(args)
                fresh = got is not None   # the buffered call's outputs: arrays made for this call
                if got is None:
                    out = self.solver(**args)
                    stats = self._stats = dict(self.solver.stats())
                else:
                    out, stats = got
        except RuntimeError as exc:  # IPOPT/CasADi evaluation errors become a status
            log.warning("IPOPT raised: %s", exc)
            return SolveOutcome(IpoptStatus.INTERNAL_ERROR, -1, time.perf_counter() - t0,
                                time.process_time() - c0, setup, float("nan"), np.array(x0, float).ravel(),
                                label=label, message=str(exc).strip().splitlines()[-1] if str(exc).strip() else "")
        return outcome_from_stats(stats, out, wall_time=time.perf_counter() - t0, cpu_time=time.process_time() - c0,
                                  setup_time=setup, cost_scale=cost_scale, label=label, copy=not fresh)

    def _call_buffered(self, args: Mapping[str, Any]) -> tuple[dict[str, np.ndarray], dict[str, Any]] | None:
        """The solver called through one CasADi function buffer kept with the instance (one
        IPOPT memory, as the ordinary call's): the numbers pass as arrays, no ``DM`` made (~0.1 µs
        per number each way). ``(outputs, stats)``, or None (the ordinary call) when CasADi has
        no buffers or an argument is not a vector of its input's size."""
        f = self.solver
        names = self._names
        if self._buffer is None:
            try:
                self._buffer = f.buffer()
                if not hasattr(self._buffer[0], "stats"):   # older CasADi (3.6): no statistics from a buffer
                    self._buffer = False
            except (AttributeError, NotImplementedError, RuntimeError):
                self._buffer = False
        if self._buffer is False:
            return None
        ins = []
        for i, name in enumerate(names[0]):
            n = int(f.nnz_in(i))
            v = args.get(name)
            a = np.full(n, float(f.default_in(i))) if v is None else np.array(v, dtype=float).reshape(-1)
            if a.size != n:
                if a.size != 1:
                    return None
                a = np.full(n, float(a[0]))
            ins.append(a)
        outs = [np.empty(int(f.nnz_out(i))) for i in range(len(names[1]))]
        buf, run = self._buffer
        try:
            for i, a in enumerate(ins):
                buf.set_arg(i, a.data)
            for i, o in enumerate(outs):
                buf.set_res(i, o.data)
        except (NotImplementedError, TypeError):   # another buffer signature: the ordinary call from now on
            self._buffer = False
            return None
        run()   # ``ins`` and ``outs`` hold the memory the buffer points to until here
        if buf.ret() != 0:
            raise RuntimeError(f"{f.name()}: evaluation failed (return code {buf.ret()})")
        self._stats = dict(buf.stats())
        return dict(zip(names[1], outs)), self._stats

    def stats(self) -> dict[str, Any]:
        """IPOPT's statistics of the last solve."""
        return dict(self._stats) if self._stats is not None else dict(self.solver.stats())
