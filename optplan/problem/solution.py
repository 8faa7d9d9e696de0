"""`Solution`: what `OptProblem.solve` returns — always, whether IPOPT succeeded or not."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path

import numpy as np

__all__ = ["IpoptStatus", "Solution"]


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

    @classmethod
    def from_string(cls, s: str) -> "IpoptStatus":
        for m in cls:
            if m.value.lower() == str(s).lower():
                return m
        return cls.UNKNOWN

    @property
    def succeeded(self) -> bool:
        return self in (IpoptStatus.SOLVE_SUCCEEDED, IpoptStatus.SOLVED_TO_ACCEPTABLE_LEVEL)

    @property
    def infeasible(self) -> bool:
        return self in (IpoptStatus.INFEASIBLE_PROBLEM_DETECTED, IpoptStatus.RESTORATION_FAILED)


@dataclass
class Solution:
    """Result of a trajectory NLP.

    ``success`` is True only when IPOPT converged *and* the maximum constraint violation is below
    the problem's tolerance. ``wall_time`` [s] is the IPOPT run; ``setup_time`` [s] the NLP
    construction and solver creation that preceded it (0 when a built solver was reused). ``t`` [s] (N+1,), ``q`` [rad] (N+1, nj), ``qd``, ``qdd``, ``jerk`` (N, nj);
    ``base_quat`` (N+1, 4) and ``base_position`` (N+1, 3) for a floating robot. ``terms`` maps each
    named term to its value (cost terms: weighted cost; constraints: max violation), plus
    ``"dynamics"``: the max violation of the transcription's own constraints (integration,
    momentum, base attitude).
    """

    success: bool
    status: IpoptStatus
    iterations: int
    wall_time: float
    cost: float
    max_constraint_violation: float
    terms: dict[str, float]
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

    def __post_init__(self):
        # a Solution never claims success about data that fails its own checks
        if self.success:
            try:
                self.check()
            except ValueError as exc:
                import logging

                logging.getLogger(__name__).error("Solution marked failed: %s", exc)
                self.success = False

    def check(self) -> None:
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
        if self.success and not self.status.succeeded:
            raise ConfigurationError(f"Solution: success with status {self.status.value!r}")
        if self.success and not (np.isfinite(self.max_constraint_violation) and np.isfinite(self.cost)):
            raise ConfigurationError(f"Solution: success with cost {self.cost} and max constraint violation "
                                     f"{self.max_constraint_violation}")

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def sample(self, t) -> dict[str, np.ndarray]:
        """Joint position/velocity/acceleration at times ``t`` [s] — exact for the transcription
        (piecewise cubic with constant jerk on each interval)."""
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
    def _arrays(self) -> dict[str, np.ndarray]:
        out = {"t": self.t, "q": self.q, "qd": self.qd, "qdd": self.qdd, "jerk": self.jerk}
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

    def _meta(self) -> dict:
        return {"success": self.success, "status": self.status.value, "iterations": self.iterations,
                "wall_time": self.wall_time, "setup_time": self.setup_time, "cost": self.cost,
                "max_constraint_violation": self.max_constraint_violation, "terms": self.terms,
                "joint_names": list(self.joint_names), "x_scale_h": self.x_scale_h}

    def save(self, path: str | Path) -> Path:
        """Save as ``.npz`` (arrays + JSON metadata) or ``.json`` (everything as lists)."""
        path = Path(path)
        if path.suffix == ".json":
            d = self._meta()
            d.update({k: v.tolist() for k, v in self._arrays().items()})
            path.write_text(json.dumps(d))
        else:
            np.savez(path, meta=json.dumps(self._meta()), joint_names=np.array(self.joint_names),
                     **self._arrays())
            if path.suffix != ".npz":
                path = path.with_name(path.name + ".npz")
        return path

    @classmethod
    def load(cls, path: str | Path) -> "Solution":
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
                arrays = {k: np.asarray(d[k], float) for k in ("t", "q", "qd", "qdd", "jerk", "base_quat",
                                                               "base_position", "x", "lam_g", "lam_x") if k in d}
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
            sol = cls.__new__(cls)
            sol.__init__(success=False, status=IpoptStatus.from_string(status),
                         iterations=int(meta["iterations"]), wall_time=float(meta["wall_time"]),
                         setup_time=float(meta.get("setup_time", 0.0)),
                         cost=float(meta["cost"]), max_constraint_violation=float(meta["max_constraint_violation"]),
                         terms={str(k): float(v) for k, v in dict(meta["terms"]).items()},
                         joint_names=tuple(str(n) for n in meta["joint_names"]), x_scale_h=meta.get("x_scale_h"),
                         **arrays)
            sol.check()
            sol.success = bool(success)
            sol.check()   # success now claimed: status and figures must support it
        except ResultFileError:
            raise
        except KeyError as exc:
            raise ResultFileError(f"{path}: missing field {exc}") from None
        except (zipfile.BadZipFile, json.JSONDecodeError, UnicodeDecodeError, EOFError, OSError) as exc:
            raise ResultFileError(f"{path}: not a readable solution file ({type(exc).__name__}: {exc})") from None
        except (OptplanError, TypeError, ValueError, AttributeError) as exc:
            raise ResultFileError(f"{path}: {exc}") from None
        return sol
