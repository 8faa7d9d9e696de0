"""One interface for every planner: :class:`PlanStatus`, :class:`PlanResult`, :class:`Planner`.

A planner is built once for a robot and a scene (``Planner(robot, scene, options)``) and then asked
``plan(q_start, q_goal, time_limit=..., seed=...)`` any number of times. It always returns a
:class:`PlanResult` (never None, never raises on an unsolvable task): the status says what happened.

Path layout (``PlanResult``), for ``M`` configurations:

* ``path``: ``M × nq`` joint configurations [rad] (Pinocchio order), ``path[0] = q_start`` and
  ``path[-1] = q_goal`` on success (``0 × nq`` otherwise).
* ``object_poses``: one entry per configuration, the world pose of the grasped object
  (:class:`pinocchio.SE3`), or ``None`` when the planner has no object (plain RRTConnect).
  During a regrasp the object stays where it is, so its pose is still given.
* ``constrained``: one bool per configuration, True where both hands are on their grasps (the
  closed-chain constraint holds); False inside regrasp segments, where one hand is off the object.
* ``segments``: consecutive index ranges ``[start, stop]`` (inclusive, neighbours share their end
  configuration) of kind ``"constrained"`` (closed-chain motion; consecutive configurations are
  IK solutions of neighbouring object poses), ``"regrasp"`` (one arm, ``arm``, moves on straight
  joint-space edges while the other arm holds the object at ``object_pose``; the end
  configurations have both hands on the object) or ``"free"`` (unconstrained joint-space edges).
* ``stats``: ``time_s`` (wall time of ``plan``), ``nodes``, ``iterations``, ``seed`` and
  planner-specific counters.
"""
from __future__ import annotations

import abc
import enum
import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from ..errors import ConfigurationError, OptionError, check_int, check_real, real_array
from ..geometry.spatial import pose_to_vector, vector_to_pose
from ..model.robot import RobotModel
from ..scene import Scene

__all__ = ["PlanStatus", "PathSegment", "PlanResult", "Planner", "Deadline", "CLOCKS", "pose_to_vector", "vector_to_pose"]
log = logging.getLogger(__name__)


class PlanStatus(str, enum.Enum):
    """Outcome of a planning query."""

    EXACT = "exact"                  #: a path from start to goal was found
    APPROXIMATE = "approximate"      #: (OMPL) the planner returned a path that stops short of the goal
    TIMEOUT = "timeout"              #: the time limit elapsed without a path
    INVALID_START = "invalid_start"  #: start in collision, out of limits or off the constraint manifold
    INVALID_GOAL = "invalid_goal"    #: same for the goal
    FAILED = "failed"                #: the planner gave up before the time limit (iteration cap, ...)
    ERROR = "error"                  #: an exception inside the planner (message in PlanResult.message)

    @property
    def success(self) -> bool:
        return self is PlanStatus.EXACT


@dataclass(frozen=True)
class PathSegment:
    """A consecutive range ``[start, stop]`` (inclusive) of path indices of one kind:
    ``"constrained"``, ``"regrasp"`` (``arm`` moves, object fixed at ``object_pose``; ``arm`` is
    :data:`BOTH_ARMS` when both arms move, the object standing at ``object_pose``) or ``"free"``."""

    kind: str
    start: int
    stop: int
    arm: str | None = None
    object_pose: pin.SE3 | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "start": self.start, "stop": self.stop, "arm": self.arm,
                "object_pose": None if self.object_pose is None else pose_to_vector(self.object_pose).tolist()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PathSegment:
        op = d.get("object_pose")
        return cls(d["kind"], int(d["start"]), int(d["stop"]), d.get("arm"),
                   None if op is None else vector_to_pose(op))


#: ``PathSegment.arm`` of a regrasp in which both arms move (the object stands still where it is)
BOTH_ARMS = "both"


@dataclass
class PlanResult:
    """Result of :meth:`Planner.plan` (see the module docstring for the path layout)."""

    status: PlanStatus
    planner: str
    path: np.ndarray
    object_poses: list[pin.SE3 | None] = field(default_factory=list)
    constrained: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    segments: list[PathSegment] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)
    message: str = ""

    @property
    def success(self) -> bool:
        return self.status.success

    @property
    def time_s(self) -> float:
        return float(self.stats.get("time_s", float("nan")))

    @property
    def n_regrasp(self) -> int:
        """Number of regrasp segments (one per arm that lets go and grasps again)."""
        return sum(1 for s in self.segments if s.kind == "regrasp")

    def __len__(self) -> int:
        return len(self.path)

    def __bool__(self) -> bool:
        # with __len__ alone an empty (failed) result would be falsy: `if result:` must not stand in
        # for "exists" or "succeeded"
        raise TypeError("the truth value of a PlanResult is ambiguous: use `result.success` or `result is not None`")

    # ------------------------------------------------------------------ serialization
    def to_dict(self, include_path: bool = True) -> dict[str, Any]:
        d = {"status": self.status.value, "planner": self.planner, "message": self.message,
             "stats": _jsonable(self.stats), "n_configurations": int(len(self.path)),
             "n_regrasp": self.n_regrasp, "segments": [s.to_dict() for s in self.segments]}
        if include_path:
            d["path"] = np.asarray(self.path).tolist()
            d["object_poses"] = [None if M is None else pose_to_vector(M).tolist() for M in self.object_poses]
            d["constrained"] = [bool(c) for c in self.constrained]
        return d

    def to_json(self, include_path: bool = True) -> str:
        return json.dumps(self.to_dict(include_path))

    def check(self) -> None:
        """Raise ConfigurationError when the result is inconsistent: a path that is not an M × nq
        array of finite numbers, per-configuration lists of another length, segments outside the
        path, or a success status without a path."""
        p = self.path
        if not isinstance(p, np.ndarray) or p.ndim != 2 or p.dtype.kind != "f":
            raise ConfigurationError(f"PlanResult.path: expected an M x nq float array, got "
                                     f"{type(p).__name__} of shape {np.shape(p)}")
        if not np.isfinite(p).all():
            bad = np.argwhere(~np.isfinite(p))[0].tolist()
            raise ConfigurationError(f"PlanResult.path: non-finite entry at {bad} ({p[tuple(bad)]})")
        M = len(p)
        if self.object_poses and len(self.object_poses) != M:
            raise ConfigurationError(f"PlanResult.object_poses: {len(self.object_poses)} entries for {M} configurations")
        if len(self.constrained) not in (0, M):
            raise ConfigurationError(f"PlanResult.constrained: {len(self.constrained)} entries for {M} configurations")
        for sg in self.segments:
            if not (0 <= sg.start <= sg.stop < max(M, 1)):
                raise ConfigurationError(f"PlanResult.segments: {sg.kind} [{sg.start}, {sg.stop}] is outside the "
                                         f"path of {M} configurations")
        if self.status.success and M < 2:
            raise ConfigurationError(f"PlanResult: status {self.status.value!r} with a path of {M} configurations "
                                     "(a found path has at least start and goal)")

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "PlanResult") -> PlanResult:
        """Rebuild from :meth:`to_dict`; anything missing, malformed or inconsistent is a
        :class:`~optplan.errors.ResultFileError` naming ``source`` and the field."""
        from ..errors import OptplanError, ResultFileError

        if not isinstance(d, dict):
            raise ResultFileError(f"{source}: expected a JSON object with 'status', 'path', ..., got {type(d).__name__}")
        try:
            status = d["status"]
            if status not in {s.value for s in PlanStatus}:
                raise ResultFileError(f"{source}: unknown status {status!r}; expected one of "
                                      f"{', '.join(s.value for s in PlanStatus)}")
            raw = d.get("path", [])
            if isinstance(raw, np.ndarray):
                pass
            elif not isinstance(raw, list) or not all(isinstance(row, list) for row in raw) \
                    or len({len(row) for row in raw}) > 1:
                lens = sorted({len(row) for row in raw if isinstance(row, list)}) if isinstance(raw, list) else []
                raise ResultFileError(f"{source}: path: expected a list of M configurations of equal length "
                                      f"(M x nq numbers), got {type(raw).__name__}"
                                      + (f" with rows of lengths {lens[:10]}" if lens else "")
                                      + (" and non-list rows" if isinstance(raw, list)
                                         and not all(isinstance(row, list) for row in raw) else ""))
            path = real_array(raw, f"{source}: path", ResultFileError)
            if path.size == 0:
                path = path.reshape(0, path.shape[1] if path.ndim == 2 else 0)
            res = cls(PlanStatus(status), str(d.get("planner", "")), path,
                      [None if v is None else vector_to_pose(v) for v in d.get("object_poses", [])],
                      np.asarray(d.get("constrained", []), dtype=bool),
                      [PathSegment.from_dict(s) for s in d.get("segments", [])], dict(d.get("stats", {})),
                      str(d.get("message", "")))
            res.check()
        except ResultFileError:
            raise
        except KeyError as exc:
            raise ResultFileError(f"{source}: missing field {exc}") from None
        except (OptplanError, TypeError, ValueError, AttributeError) as exc:
            raise ResultFileError(f"{source}: {exc}") from None
        return res

    @classmethod
    def from_json(cls, text: str, source: str = "PlanResult JSON") -> PlanResult:
        from ..errors import ResultFileError
        from ..limits import check_nesting

        if isinstance(text, (bytes, bytearray)):
            try:
                text = text.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise ResultFileError(f"{source}: not UTF-8 text ({exc})") from None
        if not isinstance(text, str):
            raise ResultFileError(f"{source}: expected JSON text, got {type(text).__name__}")
        check_nesting(text, source, ResultFileError)
        try:
            d = json.loads(text)
        except (json.JSONDecodeError, UnicodeDecodeError, TypeError) as exc:
            raise ResultFileError(f"{source}: not valid JSON ({exc})") from None
        except RecursionError:   # belt and braces: check_nesting refuses the deep texts first
            raise ResultFileError(f"{source}: arrays nested too deeply to parse") from None
        return cls.from_dict(d, source)

    def save(self, path: str | Path) -> Path:
        """Write :meth:`to_json` to ``path``."""
        from ..errors import ResultFileError
        from ..limits import check_output_path

        self.check()
        p = check_output_path(path, "PlanResult.save: file", ResultFileError)
        from .._io import write_text

        write_text(p, self.to_json())   # atomic: complete or absent
        return p

    @classmethod
    def load(cls, path: str | Path) -> PlanResult:
        """Read a file written by :meth:`save`; a missing, unreadable or corrupted file is a
        :class:`~optplan.errors.ResultFileError` naming it."""
        from .. import limits
        from ..errors import ResultFileError

        p = limits.check_path(path, "plan result file", ResultFileError)
        if p.is_file():
            limits.check_file_size(p, limits.MAX_RESULT_BYTES, "plan result", ResultFileError, "MAX_RESULT_BYTES")
        try:
            text = p.read_bytes().decode("utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ResultFileError(f"{p}: cannot read a plan result ({exc})") from None
        return cls.from_json(text, str(p))


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating,)):
        return float(x)
    if isinstance(x, enum.Enum):
        return x.value
    return x


CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}


class Deadline:
    """A time budget: ``Deadline(seconds, clock="wall")``; ``expired()``, ``remaining()``,
    ``elapsed()``. ``clock="cpu"`` counts this process's CPU time (``time.process_time``), which
    does not grow while other processes hold the cores.

    A sub-deadline (:meth:`sub`) may also carry a work budget, ``work`` [count, in the unit of the sub-search
    that spends it: :meth:`spend`]: it is expired when either runs out, so a sub-search bounded by its work ends
    at the same point of its search on any machine and load (the seconds are then a backstop)."""

    __slots__ = ("t0", "limit", "end", "clock", "work", "up")

    def __init__(self, seconds: float, clock: str = "wall") -> None:
        if clock not in CLOCKS:
            raise ValueError(f"clock: expected 'wall' or 'cpu', got {clock!r}")
        self.clock = CLOCKS[clock]
        self.t0 = self.clock()
        self.limit = float(seconds)
        self.end = self.t0 + self.limit
        self.work: float = math.inf
        self.up: Deadline | None = None

    def expired(self) -> bool:
        return self.work <= 0 or self.clock() >= self.end

    def remaining(self) -> float:
        return self.end - self.clock()

    def elapsed(self) -> float:
        return self.clock() - self.t0

    def sub(self, seconds: float, work: float = math.inf) -> Deadline:
        """A deadline on the same clock ending at the earlier of ``seconds`` from now and this one, with the
        smaller of ``work`` and this one's work left (``math.inf``: no work budget)."""
        d = Deadline.__new__(Deadline)
        d.clock, d.t0 = self.clock, self.clock()
        d.limit = max(0.0, min(float(seconds), self.end - d.t0))
        d.end = d.t0 + d.limit
        d.work, d.up = min(float(work), self.work), self
        return d

    def spend(self, n: float) -> None:
        """``n`` units of work done: taken from this deadline's work budget and from those it is a sub-deadline of."""
        d: Deadline | None = self
        while d is not None:
            d.work -= n
            d = d.up

    def work_cap(self) -> int:
        """The work left as an iteration cap of a search: 0 when there is no work budget (call only while not
        :meth:`expired`)."""
        return 0 if math.isinf(self.work) else max(1, int(math.ceil(self.work)))


class Planner(abc.ABC):
    """Base class: ``plan(q_start, q_goal, time_limit=10.0, seed=0) -> PlanResult``.

    Subclasses implement :meth:`_plan` and may rely on :meth:`plan` for input checks (shape,
    finiteness), timing, seeding and turning exceptions into ``PlanStatus.ERROR``.
    """

    name = "planner"
    #: True: :meth:`_plan` receives ``rng`` None and makes ``np.random.default_rng(seed)`` itself when it needs one
    _lazy_rng = False

    def __init__(self, robot: RobotModel, scene: Scene | None = None) -> None:
        if not isinstance(robot, RobotModel):
            raise TypeError(f"robot: expected optplan.RobotModel, got {type(robot).__name__}")
        if robot.is_floating:
            raise ConfigurationError(f"{type(self).__name__} plans for fixed-base robots; {robot.name!r} is free-floating")
        self.robot = robot
        self.scene = scene

    def plan(self, q_start: npt.ArrayLike, q_goal: npt.ArrayLike, *, time_limit: float = 10.0, seed: int = 0,
             clock: str = "wall") -> PlanResult:
        """Plan from ``q_start`` to ``q_goal`` within ``time_limit`` seconds of ``clock`` ("wall"
        or "cpu"); ``seed`` makes the result reproducible (same seed, same path, unless the time
        limit cuts the search at a load-dependent point). ``stats`` gets ``time_s`` (wall) and
        ``cpu_time_s``."""
        qs = self.robot.check_q(np.array(q_start, dtype=float), "q_start").copy()
        qg = self.robot.check_q(np.array(q_goal, dtype=float), "q_goal").copy()
        time_limit = check_real(time_limit, f"{type(self).__name__}.plan: time_limit", minimum=0.0,
                                strict_minimum=True, unit="s")
        seed = check_int(seed, f"{type(self).__name__}.plan: seed", minimum=0, maximum=2**63 - 1)
        if clock not in CLOCKS:
            raise OptionError(f"{type(self).__name__}.plan: clock: expected 'wall' or 'cpu', got {clock!r}")
        c0, w0 = time.process_time(), time.perf_counter()
        deadline = Deadline(time_limit, clock)
        try:
            rng = cast(np.random.Generator, None) if self._lazy_rng else np.random.default_rng(seed)
            res = self._plan(qs, qg, deadline, rng, seed)
        except Exception as exc:  # a planner bug must not kill a benchmark run
            log.exception("%s failed", self.name)
            res = self.empty_result(PlanStatus.ERROR, f"{type(exc).__name__}: {exc}")
        try:
            res.check()
        except ConfigurationError as exc:  # never report success about a path that fails its own checks
            log.error("%s returned an inconsistent result: %s", self.name, exc)
            res = self.empty_result(PlanStatus.ERROR, f"inconsistent result: {exc}", **res.stats)
        res.stats.setdefault("seed", seed)
        res.stats["time_s"] = time.perf_counter() - w0
        res.stats["cpu_time_s"] = time.process_time() - c0
        res.stats["time_limit_s"] = float(time_limit)
        res.stats["clock"] = clock
        return res

    @abc.abstractmethod
    def _plan(self, q_start: np.ndarray, q_goal: np.ndarray, deadline: Deadline, rng: np.random.Generator,
              seed: int) -> PlanResult:
        ...

    def empty_result(self, status: PlanStatus, message: str = "", **stats: Any) -> PlanResult:
        return PlanResult(status, self.name, np.zeros((0, self.robot.nq)), [], np.zeros(0, bool), [], dict(stats),
                          message)
