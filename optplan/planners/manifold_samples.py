"""Valid configurations on the closed-chain manifold of a scene, generated offline and cached on disk.

The Precomputed Graph baseline and the learned samplers (:mod:`optplan.planners.learned`) of the
TCBiRRT paper's comparison (Section 5.2) start from a set of configurations of the dual-arm robot
holding the object (closed-chain residual ``max |h| < tolerance``), inside the joint limits and
collision-free. :func:`generate_manifold_samples` draws them by **projection + collision check**:
joints uniform in the limits (or, with probability ``walk_probability``, a configuration already in
the set perturbed by ``N(0, walk_sigma²)``: a random walk on the manifold that spreads from every valid
configuration found), Newton-Raphson projection onto ``h(q) = 0`` (the projection of
:class:`~optplan.planners.cbirrt2.CBiRRT2`, damped pseudo-inverse; a projection that lands on the
spurious zero of the residual at a relative rotation of π, which a far start can reach, is rejected
by the independent :func:`~optplan.constraints.closed_chain.closure_error`), then the limits and the shared
:class:`~optplan.planners.validity.ValidityChecker` (object held). Everything is seeded by one
``numpy.random.Generator``: the same settings give the same set. Parts of the set can instead be drawn
by constrained random walks in the start and goal regions (``region_fraction``) or as the nodes of a
task-space exploration over the object's whole workspace (``task_fraction``,
:mod:`~optplan.planners.manifold_explore`).

:func:`manifold_samples` caches the set under ``$OPTPLAN_CACHE/manifold/`` (default
``~/.cache/optplan``), keyed by a hash of the scene (obstacles, object, grasps), the robot (name,
joint limits) and the settings (:class:`ManifoldSampleSettings`), so a changed scene or setting
never reuses a stale file.
"""
from __future__ import annotations

import hashlib
import json
import logging
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..constraints.closed_chain import ClosedChainKinematics, closure_error
from ..errors import ConfigurationError
from ..model.robot import RobotModel
from ..scene import Scene
from .chain_projection import project_onto_chain
from .validity import ValidityChecker

__all__ = ["ManifoldSampleSettings", "ManifoldSamples", "generate_manifold_samples", "manifold_samples",
           "project_onto_chain", "scene_digest"]
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ManifoldSampleSettings:
    """How the on-manifold sample set of a scene is drawn."""

    #: Valid configurations to collect [count] (the paper: 10,000 per scene).
    n: int = 10_000
    #: Seed of the generator [-].
    seed: int = 0
    #: Projection tolerance on the closed-chain residual, max |h| [m or rad per row].
    tolerance: float = 1e-7
    #: Newton iterations of one projection [count].
    max_projection_iterations: int = 50
    #: Clearance counted as contact [m].
    margin: float = 0.0
    #: Candidates drawn before giving up, as a multiple of ``n`` [-].
    max_draws_factor: int = 200
    #: Probability that a candidate starts from a configuration already in the set, perturbed by
    #: ``N(0, walk_sigma²)`` per joint, instead of uniform joints [-] (uniform joints project onto a
    #: collision-free configuration about once in 180 draws on the SSPS scenes, a perturbed valid one
    #: far more often).
    walk_probability: float = 0.8
    #: Standard deviation of the perturbation of a walk candidate [rad].
    walk_sigma: float = 0.5
    #: Start the walk from the scene's nominal start and goal configurations (``[extra] q_start``/``q_goal``
    #: polished by IK, as the benchmark's trials do) when the scene has them, so that the set covers the
    #: arm branches the tasks are posed on (they are not put in the set themselves) [-].
    seed_from_scene: bool = True
    #: Share of the set drawn by constrained random walks in the task's start and goal regions [-]: each walk
    #: starts from the scene's nominal start or goal object pose perturbed as the benchmark's trials are
    #: (position uniform in ±``[extra] trial_position_range``, default 0.2 m, RPY in ±``trial_angle_range``,
    #: default 0.5 rad, per axis), solved by IK continuation from the nominal configuration, and takes
    #: ``region_walk_length`` steps of ``N(0, region_walk_sigma²)`` per joint, each projected and
    #: collision-checked (a failed step is retried from the same configuration). 0: the uniform / walk
    #: draws above only. Needs the scene's ``[extra] q_start`` / ``q_goal``.
    region_fraction: float = 0.0
    #: Per-joint standard deviation of one step of a region walk [rad].
    region_walk_sigma: float = 0.1
    #: Valid steps of one region walk before the next starts from a new start or goal pose [count].
    region_walk_length: int = 50
    #: Share of the set drawn as the nodes of a **task-space exploration** [-]
    #: (:func:`~optplan.planners.manifold_explore.task_space_exploration`): an RRT over the object pose,
    #: ξ_rand uniform in TCBiRRT's ξ box (the object's whole reachable workspace, not a query's start or
    #: goal), both hands solved by IK continuation along the step from the nearest node, rooted at the
    #: scene's nominal configurations. 0: the draws above only. Needs the scene's ``[extra] q_start`` / ``q_goal``.
    task_fraction: float = 0.0
    #: Largest step of one exploration extension in ξ (TCBiRRT's s_ξ) [m and rad, Euclidean in ξ].
    task_step: float = 0.6
    #: Object poses interpolated along one extension, each solved by IK (TCBiRRT's N) [count].
    task_waypoints: int = 5
    #: Draws of ξ_rand while the object alone collides or a grasp point is out of reach [count].
    task_filter_tries: int = 20

    def __post_init__(self) -> None:
        for name in ("n", "max_projection_iterations", "max_draws_factor", "task_waypoints", "task_filter_tries"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"ManifoldSampleSettings.{name}: expected an integer >= 1, got {v!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"ManifoldSampleSettings.seed: expected an integer >= 0, got {self.seed!r}")
        if not (isinstance(self.tolerance, (int, float)) and math.isfinite(self.tolerance) and self.tolerance > 0):
            raise ValueError(f"ManifoldSampleSettings.tolerance: expected a positive number, got {self.tolerance!r}")
        if not (isinstance(self.walk_probability, (int, float)) and 0 <= self.walk_probability <= 1):
            raise ValueError(f"ManifoldSampleSettings.walk_probability: expected a number in [0, 1], "
                             f"got {self.walk_probability!r}")
        if not (isinstance(self.walk_sigma, (int, float)) and math.isfinite(self.walk_sigma) and self.walk_sigma > 0):
            raise ValueError(f"ManifoldSampleSettings.walk_sigma: expected a positive number [rad], got {self.walk_sigma!r}")
        if not (isinstance(self.region_walk_sigma, (int, float)) and math.isfinite(self.region_walk_sigma)
                and self.region_walk_sigma > 0):
            raise ValueError(f"ManifoldSampleSettings.region_walk_sigma: expected a positive number [rad], "
                             f"got {self.region_walk_sigma!r}")
        for name in ("region_fraction", "task_fraction"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v <= 1):
                raise ValueError(f"ManifoldSampleSettings.{name}: expected a number in [0, 1], got {v!r}")
        if self.region_fraction + self.task_fraction > 1:
            raise ValueError(f"ManifoldSampleSettings: region_fraction + task_fraction must be <= 1, got "
                             f"{self.region_fraction!r} + {self.task_fraction!r}")
        if not (isinstance(self.task_step, (int, float)) and math.isfinite(self.task_step) and self.task_step > 0):
            raise ValueError(f"ManifoldSampleSettings.task_step: expected a positive number [m, rad], "
                             f"got {self.task_step!r}")
        v = self.region_walk_length
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise ValueError(f"ManifoldSampleSettings.region_walk_length: expected an integer >= 1, got {v!r}")
        if not isinstance(self.seed_from_scene, bool):
            raise ValueError(f"ManifoldSampleSettings.seed_from_scene: expected True/False, got {self.seed_from_scene!r}")
        if not (isinstance(self.margin, (int, float)) and math.isfinite(self.margin) and self.margin >= 0):
            raise ValueError(f"ManifoldSampleSettings.margin: expected a number >= 0 m, got {self.margin!r}")


@dataclass
class ManifoldSamples:
    """A generated set: ``Q`` (``n × nq`` [rad]), the number of candidates drawn, how many failed to
    project or collided, the wall time [s] and the cache file (None when not cached)."""

    Q: np.ndarray
    draws: int
    projection_failures: int
    collisions: int
    time_s: float
    path: Path | None = None


def scene_digest(robot: RobotModel, scene: Scene, extra: dict[str, Any] | None = None) -> str:
    """A short hash of what an offline set depends on: the robot (name, joint limits), the scene's
    obstacles, object and grasps, and ``extra`` (settings)."""
    def se3(M: Any) -> list[float]:
        return [round(float(x), 12) for x in np.asarray(M.homogeneous).ravel()]

    obj = scene.object
    desc = {"robot": robot.name, "nq": robot.nq, "lower": [round(float(x), 12) for x in robot.lower],
            "upper": [round(float(x), 12) for x in robot.upper],
            "obstacles": [[o.name, o.shape, se3(o.placement), o.size, o.radius, o.length, list(o.exclude_links)]
                          for o in scene.obstacles],
            "object": None if obj is None else [list(obj.size), {a: se3(g) for a, g in obj.grasps.items()},
                                                list(obj.exclude_links)],
            "extra": extra or {}}
    return hashlib.sha256(json.dumps(desc, sort_keys=True, default=str).encode()).hexdigest()[:16]


def generate_manifold_samples(robot: RobotModel, scene: Scene, settings: ManifoldSampleSettings | None = None, *,
                              checker: ValidityChecker | None = None, kinematics: ClosedChainKinematics | None = None,
                              progress: bool = False) -> ManifoldSamples:
    """Draw ``settings.n`` valid on-manifold configurations (module docstring); a
    :class:`~optplan.errors.ConfigurationError` when fewer than that are found within
    ``n · max_draws_factor`` candidates."""
    import time

    s = settings or ManifoldSampleSettings()
    if scene.object is None or len(scene.object.grasps) != 2:
        raise ConfigurationError(f"scene {scene.name!r}: on-manifold samples need an [object] grasped by two arms")
    kin = kinematics or ClosedChainKinematics(robot, scene.object.grasps)
    ck = checker or ValidityChecker(robot, scene, margin=s.margin)
    rng = np.random.default_rng(s.seed)
    data = robot.model.createData()
    lo, hi = robot.lower, robot.upper
    out: list[np.ndarray] = []
    pool = _scene_seeds(robot, scene, kin, ck) if s.seed_from_scene else []
    draws = fails = coll = 0
    t0 = time.perf_counter()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=s.n, desc=f"on-manifold samples {scene.name}", unit="q")
    n_region = int(round(s.region_fraction * s.n))
    if n_region:
        region = _region_walks(robot, scene, kin, ck, s, n_region, np.random.default_rng([s.seed, 1]))
        out.extend(region.pop("Q"))
        draws, fails, coll = region["draws"], region["fails"], region["coll"]
        if bar is not None:
            bar.update(len(out))
    n_task = min(int(round(s.task_fraction * s.n)), s.n - len(out))
    if n_task:
        from .manifold_explore import task_space_exploration

        roots = pool or _scene_seeds(robot, scene, kin, ck)
        task = task_space_exploration(robot, scene, kin, ck, s, n_task, np.random.default_rng([s.seed, 2]), roots, bar)
        out.extend(task.pop("Q"))
        draws, fails, coll = draws + task["draws"], fails + task["fails"], coll + task["coll"]
    try:
        while len(out) < s.n:
            if draws >= s.n * s.max_draws_factor:
                raise ConfigurationError(f"scene {scene.name!r}: only {len(out)} of {s.n} valid on-manifold "
                                         f"configurations in {draws} draws (max_draws_factor={s.max_draws_factor})")
            draws += 1
            if (out or pool) and rng.random() < s.walk_probability:
                base = out + pool
                x = base[int(rng.integers(len(base)))] + rng.normal(0.0, s.walk_sigma, robot.nq)
            else:
                x = rng.uniform(lo, hi)
            q = project_onto_chain(kin, np.clip(x, lo, hi), lo, hi, s.tolerance, s.max_projection_iterations)
            # h = 0 also at the relative rotation θ = π (sin θ · axis vanishes): the independent check rejects it
            if q is not None and max(closure_error(robot, scene.object.grasps, q, data)) > 10 * s.tolerance:
                q = None
            if q is None:
                fails += 1
                continue
            if not ck.is_valid(q):
                coll += 1
                continue
            out.append(q)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return ManifoldSamples(np.array(out).reshape(-1, robot.nq), draws, fails, coll, time.perf_counter() - t0)


def _region_walks(robot: RobotModel, scene: Scene, kin: ClosedChainKinematics, ck: ValidityChecker,
                  s: ManifoldSampleSettings, n: int, rng: np.random.Generator) -> dict[str, Any]:
    """``n`` configurations of constrained random walks in the start and goal regions (``region_fraction``)."""
    import pinocchio as pin

    from ..constraints.closed_chain import IKSettings
    from ..geometry.spatial import rpy_to_matrix
    from .task_space import interpolate_task

    ex = scene.extra or {}
    nominal = []
    for key, M in (("q_start", scene.start), ("q_goal", scene.goal)):
        if key in ex and M is not None:
            q0 = np.asarray(ex[key], float) * (math.pi / 180.0 if ex.get("q_unit", "rad") == "deg" else 1.0)
            if q0.shape == (robot.nq,):
                nominal.append((M, q0))
    if not nominal:
        raise ConfigurationError(f"scene {scene.name!r}: region_fraction > 0 needs the scene's [extra] q_start / "
                                 f"q_goal and its start / goal object poses")
    assert scene.object is not None   # checked by the caller
    grasps = scene.object.grasps
    dp = float(ex.get("trial_position_range", 0.2))
    da = float(ex.get("trial_angle_range", 0.5))
    data = robot.model.createData()
    lo, hi = robot.lower, robot.upper
    ik = IKSettings()
    out: list[np.ndarray] = []
    draws = fails = coll = 0
    k = 0
    while len(out) < n:
        if draws >= n * s.max_draws_factor:
            raise ConfigurationError(f"scene {scene.name!r}: only {len(out)} of {n} region-walk configurations "
                                     f"in {draws} draws (max_draws_factor={s.max_draws_factor})")
        M0, q0 = nominal[k % len(nominal)]
        k += 1
        q: np.ndarray | None = q0
        M = M0 * pin.SE3(rpy_to_matrix(*rng.uniform(-da, da, 3)), rng.uniform(-dp, dp, 3))
        for R, p in interpolate_task(M0.rotation, M0.translation, M.rotation, M.translation, 10):
            if q is None:
                break
            q, _ = kin.ik(q, R, p, ik)
        if q is None or not ck.in_limits(q) or not ck.is_valid(q):
            draws += 1   # a start or goal pose without a valid configuration counts as a failed draw
            fails += 1
            continue
        steps = 0
        while steps < s.region_walk_length and len(out) < n and draws < n * s.max_draws_factor:
            draws += 1
            x = project_onto_chain(kin, np.clip(q + rng.normal(0.0, s.region_walk_sigma, robot.nq), lo, hi), lo, hi,
                                   s.tolerance, s.max_projection_iterations)
            if x is None or max(closure_error(robot, grasps, x, data)) > 10 * s.tolerance:
                fails += 1
                continue
            if not ck.is_valid(x):
                coll += 1
                continue
            out.append(x)
            q = x
            steps += 1
    return {"Q": out, "draws": draws, "fails": fails, "coll": coll}


def _scene_seeds(robot: RobotModel, scene: Scene, kin: ClosedChainKinematics, ck: ValidityChecker) -> list[np.ndarray]:
    """The scene's nominal start / goal configurations, IK-polished onto the nominal object poses, that are valid."""
    from ..constraints.closed_chain import IKSettings

    out = []
    ex = scene.extra or {}
    for key, M in (("q_start", scene.start), ("q_goal", scene.goal)):
        if key not in ex or M is None:
            continue
        q0 = np.asarray(ex[key], float) * (math.pi / 180.0 if ex.get("q_unit", "rad") == "deg" else 1.0)
        if q0.shape != (robot.nq,):
            continue
        q, _ = kin.ik(q0, M.rotation, M.translation, IKSettings())
        if q is not None and ck.in_limits(q) and ck.is_valid(q):
            out.append(q)
    return out


def manifold_samples(robot: RobotModel, scene: Scene, settings: ManifoldSampleSettings | None = None, *,
                     checker: ValidityChecker | None = None, kinematics: ClosedChainKinematics | None = None,
                     cache: bool = True, progress: bool = False) -> ManifoldSamples:
    """:func:`generate_manifold_samples`, read from / written to the on-disk cache (``cache=False``:
    always generate, write nothing). A cache file that cannot be read is regenerated."""
    from ..codegen import cache_dir

    s = settings or ManifoldSampleSettings()
    d = asdict(s)
    if not s.region_fraction:   # the sets drawn before region walks existed keep their cache files
        for k in ("region_fraction", "region_walk_sigma", "region_walk_length"):
            d.pop(k)
    if not s.task_fraction:     # ... and those drawn before the task-space exploration existed
        for k in ("task_fraction", "task_step", "task_waypoints", "task_filter_tries"):
            d.pop(k)
    digest = scene_digest(robot, scene, {"manifold_samples": d, "version": 3})
    path = cache_dir() / "manifold" / f"{scene.name}_{digest}.npz"
    if cache and path.exists():
        try:
            with np.load(path) as z:
                Q = np.asarray(z["Q"], float)
                meta = json.loads(str(z["meta"]))
            if Q.shape == (s.n, robot.nq) and np.all(np.isfinite(Q)):
                return ManifoldSamples(Q, int(meta["draws"]), int(meta["projection_failures"]),
                                       int(meta["collisions"]), float(meta["time_s"]), path)
            log.warning("%s: unexpected shape %s, regenerating", path, Q.shape)
        except (OSError, ValueError, KeyError) as exc:
            log.warning("%s: unreadable (%s), regenerating", path, exc)
    res = generate_manifold_samples(robot, scene, s, checker=checker, kinematics=kinematics, progress=progress)
    if cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {"draws": res.draws, "projection_failures": res.projection_failures, "collisions": res.collisions,
                "time_s": res.time_s, "settings": asdict(s), "scene": scene.name}
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, Q=res.Q, meta=json.dumps(meta))
        tmp.replace(path)
        res.path = path
    return res
