"""`Solution`: what `OptProblem.solve` returns — always, whether IPOPT succeeded or not."""
from __future__ import annotations

import dataclasses
import json
import threading
import types
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .nlp import IpoptStatus, SolveOutcome

__all__ = ["IpoptStatus", "LazyTerms", "Solution"]


class LazyTerms(Mapping[str, float]):
    """A read-only mapping of term names to values computed by ``compute`` (a callable returning
    the mapping) on its first read, once: what a :class:`Solution` on the B-spline core holds as
    :attr:`Solution.terms`, so that a re-solve whose terms are never read does not evaluate the
    cost terms (the same numbers as computing them at once). ``computed``: whether it was read."""

    __slots__ = ("_compute", "_values", "_lock")

    def __init__(self, compute: Callable[[], Mapping[str, float]]):
        self._compute: Callable[[], Mapping[str, float]] | None = compute
        self._values: dict[str, float] | None = None
        self._lock = threading.Lock()

    @property
    def computed(self) -> bool:
        return self._values is not None

    def _get(self) -> dict[str, float]:
        v = self._values
        if v is None:
            with self._lock:
                if self._values is None:
                    assert self._compute is not None
                    self._values = {str(k): float(x) for k, x in dict(self._compute()).items()}
                    self._compute = None   # the arrays it read are released
                v = self._values
        return v

    def __getitem__(self, key: str) -> float:
        return self._get()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._get())

    def __len__(self) -> int:
        return len(self._get())

    def __repr__(self) -> str:
        return repr(self._get())

    def __reduce__(self) -> Any:   # pickled (process pools) as the plain values
        return (dict, (self._get(),))


_ARRAYS = ("t", "q", "qd", "qdd", "jerk", "base_quat", "base_position", "x", "lam_g", "lam_x")


@dataclass(frozen=True)
class Solution:
    """Result of a trajectory NLP (immutable: fields cannot be reassigned, arrays are read-only).

    ``success`` is True only when IPOPT converged, the maximum constraint violation is below
    the problem's tolerance *and* (for :meth:`OptProblem.solve`) the dense check between knots
    found no violation (:mod:`optplan.problem.guarantees`; otherwise the status is
    ``VIOLATED_BETWEEN_KNOTS`` and :attr:`between_knots` lists the violations). ``status``, ``iterations``, ``wall_time`` [s] (the IPOPT run),
    ``cpu_time`` [s] and ``setup_time`` [s] (NLP construction and solver creation before it; 0
    when a built solver was reused) describe the run that produced this trajectory; ``attempts``
    lists every run that led to it, in order (:class:`~optplan.problem.nlp.SolveOutcome`:
    status, iterations, times, label — e.g. a pipeline's retries), this one last; the totals are
    :attr:`total_iterations`, :attr:`total_wall_time`, :attr:`total_setup_time`.
    ``t`` [s] (N+1,), ``q`` [rad] (N+1, nj), ``qd``, ``qdd``, ``jerk`` (N, nj);
    ``base_quat`` (N+1, 4) and ``base_position`` (N+1, 3) for a floating robot. ``terms`` maps each
    named term to its value (cost terms: weighted cost; constraints: max violation), plus
    ``"dynamics"``: the max violation of the transcription's own constraints (integration,
    momentum, base attitude); on the B-spline core it is computed when first read
    (:class:`LazyTerms`).

    A Solution returned by :meth:`OptProblem.solve` evaluates the problem's terms through their
    handles: :meth:`value`, :meth:`violation`, :meth:`dual`, :meth:`sample` (a loaded Solution
    has no problem attached and refuses these with a clear error).
    """

    success: bool
    status: IpoptStatus
    iterations: int
    wall_time: float
    cost: float
    max_constraint_violation: float
    terms: Mapping[str, float]  # read-only mapping
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    jerk: np.ndarray
    joint_names: tuple[str, ...]
    base_quat: np.ndarray | None = None
    base_position: np.ndarray | None = None
    setup_time: float = 0.0  # [s] building the NLP and creating the IPOPT instance (first solve only)
    x: np.ndarray | None = field(default=None, repr=False)  # raw decision vector (warm starts)
    lam_g: np.ndarray | None = field(default=None, repr=False)
    lam_x: np.ndarray | None = field(default=None, repr=False)
    #: the transcription's nominal interval h₀ [s] that scales ``x`` (q̇ h₀, q̈ h₀², j h₀³)
    x_scale_h: float | None = None
    cpu_time: float = 0.0  # [s] CPU time of the IPOPT run
    #: every solve that led to this solution, in order (this one last); summaries without arrays
    attempts: tuple[SolveOutcome, ...] = ()
    #: the built problem's term evaluator (not saved); see value/violation/dual/sample
    evaluator: Any = field(default=None, repr=False, compare=False)
    #: constraints violated between knots (:class:`~optplan.problem.guarantees.Violation`, worst
    #: first) when the dense check after the solve failed (status ``VIOLATED_BETWEEN_KNOTS``); not saved
    between_knots: tuple[Any, ...] = field(default=(), repr=False, compare=False)

    def __post_init__(self) -> None:
        set_: Callable[[str, Any], None] = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731  (frozen: only here)
        if not isinstance(self.status, IpoptStatus):
            set_("status", IpoptStatus.from_string(self.status))
        set_("joint_names", tuple(self.joint_names))
        if not isinstance(self.terms, LazyTerms):   # a lazy mapping is read-only and computed once
            set_("terms", types.MappingProxyType({str(k): float(v) for k, v in dict(self.terms).items()}))
        for k in _ARRAYS:
            a = getattr(self, k)
            if a is not None:
                a = np.array(a)
                a.flags.writeable = False
                set_(k, a)
        if not self.attempts:
            set_("attempts", (SolveOutcome(self.status, int(self.iterations), float(self.wall_time),
                                           float(self.cpu_time), float(self.setup_time), float(self.cost)),))
        else:
            set_("attempts", tuple(a.summary() for a in self.attempts))
        # a Solution never claims success about data that fails its own checks
        if self.success:
            try:
                self.check()
            except ValueError as exc:
                import logging

                logging.getLogger(__name__).error("Solution marked failed: %s", exc)
                set_("success", False)

    # ------------------------------------------------------------------ pickling (process pools)
    def __getstate__(self) -> dict[str, Any]:
        d = dict(self.__dict__)
        d["terms"] = dict(d["terms"])
        d["evaluator"] = None        # the problem's CasADi functions stay in the process that solved it
        return d

    def __setstate__(self, d: dict[str, Any]) -> None:
        for k, v in d.items():
            object.__setattr__(self, k, v)
        object.__setattr__(self, "terms", types.MappingProxyType(dict(d["terms"])))
        for k in _ARRAYS:
            a = getattr(self, k, None)
            if isinstance(a, np.ndarray):
                a.flags.writeable = False

    # ------------------------------------------------------------------ attempts
    def after(self, *earlier: Solution) -> Solution:
        """This solution with the attempts of ``earlier`` solutions (e.g. a pipeline's previous
        retries, in order) listed before its own — nothing is added up."""
        prev = tuple(a for s in earlier for a in s.attempts)
        return dataclasses.replace(self, attempts=prev + self.attempts)

    def labelled(self, label: str) -> Solution:
        """This solution with its own (last) attempt labelled (e.g. ``"collision retry"``)."""
        att = self.attempts[:-1] + (self.attempts[-1].with_label(label),)
        return dataclasses.replace(self, attempts=att)

    @property
    def total_iterations(self) -> int:
        """IPOPT iterations summed over :attr:`attempts` (runs that did not start count 0)."""
        return int(sum(max(a.iterations, 0) for a in self.attempts))

    @property
    def total_wall_time(self) -> float:
        """IPOPT wall time [s] summed over :attr:`attempts`."""
        return float(sum(a.wall_time for a in self.attempts))

    @property
    def total_setup_time(self) -> float:
        """Setup time [s] summed over :attr:`attempts`."""
        return float(sum(a.setup_time for a in self.attempts))

    # ------------------------------------------------------------------ term handles
    def _ev(self, what: str) -> Any:
        if self.evaluator is None:
            raise ValueError(f"Solution.{what}: this solution carries no problem to evaluate terms with (it was "
                             "loaded from a file or made by a solver without term handles); evaluate the term on the "
                             "OptProblem that produced it")
        return self.evaluator

    def value(self, handle: Any) -> Any:
        """The term's value at this solution: a constraint's residual rows (shaped per knot,
        ``(points, rows per point)``, where the term is evaluated point by point), a cost's
        weighted cost (float)."""
        return self._ev("value").value(handle, self)

    def violation(self, handle: Any) -> np.ndarray:
        """``max(lower − r, r − upper, 0)`` of a constraint's rows (≥ 0, shaped as :meth:`value`);
        in the rows' physical units ([m], [rad], …)."""
        out: np.ndarray = self._ev("violation").violation(handle, self)
        return out

    def dual(self, handle: Any) -> np.ndarray:
        """The multipliers of a constraint's rows, shaped as :meth:`value`, as the sensitivity of
        the optimal cost to the rows' active bound: ``∂f*/∂bound`` (≥ 0 for an active lower
        bound, ≤ 0 for an active upper bound, 0 for an inactive row; Drake's convention; CasADi's
        ``lam_g`` with the opposite sign)."""
        out: np.ndarray = self._ev("dual").dual(handle, self)
        return out

    def check(self, success: bool | None = None) -> None:
        """Raise :class:`~optplan.errors.ConfigurationError` when the arrays are inconsistent
        (shapes ``t`` (N+1,), ``q``/``qd``/``qdd`` (N+1, nj), ``jerk`` (N, nj), base arrays (N+1, 4/3)),
        non-finite, ``t`` not increasing, or ``success`` with a status that did not converge."""
        from ..errors import ConfigurationError

        t = np.asarray(self.t)
        if t.ndim != 1 or t.size < 2:
            raise ConfigurationError(f"Solution.t: expected N+1 ≥ 2 knot times, got shape {t.shape}")
        n1 = t.size
        nj = len(self.joint_names)
        shapes = {"q": (n1, nj), "qd": (n1, nj), "qdd": (n1, nj), "jerk": (n1 - 1, nj)}
        if self.base_quat is not None:
            shapes["base_quat"] = (n1, 4)
        if self.base_position is not None:
            shapes["base_position"] = (n1, 3)
        for k, shape in {"t": (n1,), **shapes}.items():
            a = np.asarray(getattr(self, k))
            if a.shape != shape:
                raise ConfigurationError(f"Solution.{k}: expected shape {shape}, got {a.shape}")
            if a.dtype.kind not in "fiu" or not np.all(np.isfinite(a)):
                raise ConfigurationError(f"Solution.{k}: expected finite numbers, got non-finite or non-numeric "
                                         f"values (dtype {a.dtype})")
        if np.any(np.diff(t) <= 0):
            raise ConfigurationError(f"Solution.t: knot times must increase, got {t.tolist()[:8]}...")
        claim = self.success if success is None else bool(success)
        if claim and not self.status.succeeded:
            raise ConfigurationError(f"Solution: success with status {self.status.value!r}")
        if claim and not (np.isfinite(self.max_constraint_violation) and np.isfinite(self.cost)):
            raise ConfigurationError(f"Solution: success with cost {self.cost} and max constraint violation "
                                     f"{self.max_constraint_violation}")

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def sample(self, t: Any, handle: Any = None) -> Any:
        """Joint position/velocity/acceleration at times ``t`` [s] — exact for the transcription
        (piecewise cubic with constant jerk on each interval): ``{"t", "q", "qd", "qdd"}``.

        With a term ``handle``: the term evaluated along the continuous trajectory at ``t``,
        ``(len(t), rows per point)`` — the same quantity as :meth:`value` at the knots,
        evaluated numerically (Pinocchio, coal) between them."""
        if handle is not None:
            return self._ev("sample").sample(handle, self, t)
        t = np.atleast_1d(np.asarray(t, float))
        if np.any(t < self.t[0] - 1e-12) or np.any(t > self.t[-1] + 1e-12):
            raise ValueError(f"sample: times must be in [{self.t[0]}, {self.t[-1]}] s, got "
                             f"[{t.min()}, {t.max()}]")
        N = len(self.t) - 1
        h = (self.t[-1] - self.t[0]) / N
        k = np.clip(((t - self.t[0]) / h).astype(int), 0, N - 1)
        tau = (t - self.t[k])[:, None]
        q0, v0, a0, j0 = self.q[k], self.qd[k], self.qdd[k], self.jerk[k]
        return {"t": t, "q": q0 + tau * v0 + tau**2 / 2 * a0 + tau**3 / 6 * j0,
                "qd": v0 + tau * a0 + tau**2 / 2 * j0, "qdd": a0 + tau * j0}

    # ------------------------------------------------------------------ persistence
    def _arrays(self) -> dict[str, Any]:
        out: dict[str, Any] = {"t": self.t, "q": self.q, "qd": self.qd, "qdd": self.qdd, "jerk": self.jerk}
        if self.base_quat is not None:
            out["base_quat"] = self.base_quat
            out["base_position"] = self.base_position
        if self.x is not None:
            out["x"] = self.x
        if self.lam_g is not None:
            out["lam_g"] = self.lam_g
        if self.lam_x is not None:
            out["lam_x"] = self.lam_x
        return out

    def _meta(self) -> dict[str, Any]:
        return {"success": self.success, "status": self.status.value, "iterations": self.iterations,
                "wall_time": self.wall_time, "setup_time": self.setup_time, "cost": self.cost,
                "max_constraint_violation": self.max_constraint_violation, "terms": dict(self.terms),
                "joint_names": list(self.joint_names), "x_scale_h": self.x_scale_h, "cpu_time": self.cpu_time,
                "attempts": [a.to_dict() for a in self.attempts]}

    def save(self, path: str | Path) -> Path:
        """Save as ``.npz`` (arrays + JSON metadata) or ``.json`` (everything as lists), atomically
        (complete or absent; a failed write raises :class:`optplan.errors.OutputError`)."""
        from .._io import atomic_path, write_text
        from ..errors import ResultFileError
        from ..limits import check_output_path

        path = check_output_path(path, "Solution.save: file", ResultFileError)
        if path.suffix == ".json":
            d = self._meta()
            d.update({k: v.tolist() for k, v in self._arrays().items()})
            write_text(path, json.dumps(d))
        else:
            if path.suffix != ".npz" and (path.is_file() or not path.exists()):   # np.savez's naming
                path = path.with_name(path.name + ".npz")
            with atomic_path(path) as tmp, open(tmp, "wb") as f:
                np.savez(f, meta=json.dumps(self._meta()), joint_names=np.array(self.joint_names),
                         **self._arrays())
        return path

    @classmethod
    def load(cls, path: str | Path) -> Solution:
        """Read a file written by :meth:`save`. A missing file is FileNotFoundError; a corrupted one
        (not npz/JSON, missing or malformed fields, an unknown status, NaN or wrongly shaped arrays,
        success claimed on data that fails :meth:`check`) is a
        :class:`~optplan.errors.ResultFileError` naming the file and what is wrong."""
        import zipfile

        from ..errors import OptplanError, ResultFileError

        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"no solution file at {str(path)!r}")
        try:
            if path.suffix == ".json":
                d = json.loads(path.read_bytes().decode("utf-8"))
                if not isinstance(d, dict):
                    raise ResultFileError(f"{path}: expected a JSON object, got {type(d).__name__}")
                arrays: dict[str, Any] = {k: np.asarray(d[k], float) for k in _ARRAYS if k in d}
                meta = d
            else:
                with np.load(path, allow_pickle=False) as z:
                    meta = json.loads(str(z["meta"]))
                    arrays = {k: z[k] for k in z.files if k not in ("meta", "joint_names")}
            if not isinstance(meta, dict):
                raise ResultFileError(f"{path}: metadata is not a JSON object")
            status = meta["status"]
            if str(status).lower() not in {m.value.lower() for m in IpoptStatus}:
                raise ResultFileError(f"{path}: unknown status {status!r}; expected one of "
                                      f"{', '.join(m.value for m in IpoptStatus)}")
            missing = [k for k in ("t", "q", "qd", "qdd", "jerk") if k not in arrays]
            if missing:
                raise ResultFileError(f"{path}: missing arrays {missing}")
            arrays.setdefault("base_quat", None)
            arrays.setdefault("base_position", None)
            success = meta["success"]
            if not isinstance(success, (bool, np.bool_)):
                raise ResultFileError(f"{path}: success: expected true or false, got {success!r}")
            attempts = meta.get("attempts") or ()   # files written before attempts were saved have none
            if not isinstance(attempts, (list, tuple)) or not all(isinstance(a, dict) for a in attempts):
                raise ResultFileError(f"{path}: attempts: expected a list of objects, got {attempts!r}")
            sol = cls(success=False, status=IpoptStatus.from_string(status),
                      iterations=int(meta["iterations"]), wall_time=float(meta["wall_time"]),
                      setup_time=float(meta.get("setup_time", 0.0)), cpu_time=float(meta.get("cpu_time", 0.0)),
                      cost=float(meta["cost"]), max_constraint_violation=float(meta["max_constraint_violation"]),
                      terms={str(k): float(v) for k, v in dict(meta["terms"]).items()},
                      joint_names=tuple(str(n) for n in meta["joint_names"]), x_scale_h=meta.get("x_scale_h"),
                      attempts=tuple(SolveOutcome.from_dict(a) for a in attempts), **arrays)
            sol.check(success=bool(success))   # success claimed: status and figures must support it
            if success:
                sol = dataclasses.replace(sol, success=True)
        except ResultFileError:
            raise
        except KeyError as exc:
            raise ResultFileError(f"{path}: missing field {exc}") from None
        except (zipfile.BadZipFile, json.JSONDecodeError, UnicodeDecodeError, EOFError, OSError) as exc:
            raise ResultFileError(f"{path}: not a readable solution file ({type(exc).__name__}: {exc})") from None
        except (OptplanError, TypeError, ValueError, AttributeError) as exc:
            raise ResultFileError(f"{path}: {exc}") from None
        return sol
