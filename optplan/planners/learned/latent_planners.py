"""The learned baselines of the TCBiRRT paper's comparison (Section 5.2 items 4, 6, 7):

* :class:`LatentSampling` (Acar & Tee 2021) — CBiRRT2 whose random targets are latent samples ``z ~ N(0, I)`` of the
  scene's CVAE, decoded and projected onto the manifold (Newton-Raphson; the decoded configuration
  itself when the projection fails); extension, projection and edges are CBiRRT2's.
* :class:`LCBiRRT` — a bidirectional RRT **in the latent space** (Park et al. 2024). By default (``lazy``) its
  trees grow as Park et al.'s: by the classifier alone, with a branch decoded, projected and checked only when the
  trees meet in the latent space, a failed node removed and followed by a latent jump (:mod:`.latent_lazy`).
  With ``lazy=False`` (the eager variant, described here) they are trees of latent
  vectors, each node also holding its configuration as it is added. An extension steps ``latent_step`` toward the target
  in the latent space; a step whose latent vector the validity classifier rejects
  (``p(valid) < classifier_threshold``) ends it before any decoding — unless the classifier also scores the
  step's parent, a verified node, below the threshold (``classifier_trusts_verified``: there the classifier
  is known to be wrong, e.g. around a start whose latent code lies where its training samples were mostly
  invalid). A step's configuration is ``project(decode(z))`` (projected, collision-checked), the same in
  either tree, so two trees that reach the same latent vector hold the same configuration. From a decoded
  node the joint-space edge to it is checked by the constrained local planner
  (:func:`~optplan.planners.constrained_prm.constrained_edge`, every ``collision_step`` rad); from a node
  whose configuration is not its decoding — the start, the goal (the encoder's code of a configuration
  decodes only near it) or a jump node — it is reached by a **latent jump**: CBiRRT's constrained extension
  in joint space (:meth:`LCBiRRT.connect_q`, steps of ``joint_step`` rad), whose intermediate configurations
  join the tree with their encodings as latent vectors; where the step's own decoding is invalid there, the
  jump aims at the extension target's decoding. The trees alternate, as in CBiRRT; they are **linked in
  joint space**: when a connect extension reaches the other tree's new node in the latent space (or ends
  within ``latent_step`` of it) by a constrained joint-space connect between the two configurations (empty
  when both are decodings of the same vector), and otherwise when the new node's configuration is within
  ``link_distance`` rad of the other tree's nearest configuration. ``stats`` count the nodes of each tree,
  the classifier's score of each root, the steps it refused (``classifier_rejects``) or was overruled on,
  latent jumps and jump nodes, and the link attempts (``link_attempts`` latent, ``q_link_attempts`` joint
  space), their successes and the smallest joint-space gap tried (``link_gap_min``).
  ``anchored_decoding`` restores the earlier per-tree decoding ``decode(z) + q_i − decode(z_i)``.
* :class:`LCBiRRT` with ``lpo=True`` (name ``"lcbirrt-lpo"``) — plus local path optimisation in the
  latent space (Zhang et al. 2025). Lazy (default): every ``lpo_interval``-th meeting of the trees the branches
  are checked with the LPO authors' repair (:mod:`.latent_lazy`). Eager: every ``lpo_interval`` nodes a tree gains, the newest node and its
  ``lpo_interval − 1`` ancestors (not the root) whose learned distance is below ``lpo_clearance``
  are moved by gradient ascent on the learned distance, ``z ← z + γ ∇d(z)`` (γ = ``lpo_gamma``, at most
  ``lpo_iterations`` steps); a moved node is kept only when its projected configuration is valid and
  the edges to its parent and children hold.

Every returned configuration is projected onto the closed chain and collision-checked by the shared
:class:`~optplan.planners.validity.ValidityChecker`: the networks guide the search, they never decide
validity.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...constraints.closed_chain import ClosedChainKinematics
from ...errors import ConfigurationError
from ..base import Deadline, PathSegment, Planner, PlanResult, PlanStatus
from ..cbirrt2 import CBiRRT2, CBiRRT2Options
from ..constrained_prm import constrained_edge, invalid_endpoints
from ..manifold_samples import ManifoldSampleSettings, manifold_samples, project_onto_chain
from ..validity import ValidityChecker
from .cvae import CVAESettings, load_or_train_cvae
from .latent_lazy import plan_lazy
from .latent_models import LatentModelSettings, load_or_train_classifier, load_or_train_distance

__all__ = ["LatentSamplingOptions", "LatentSampling", "LCBiRRTOptions", "LCBiRRT", "TRAINING_FIELDS"]

#: option fields that select the trained models (forwarded to :class:`CVAESettings`)
TRAINING_FIELDS = ("cvae_epochs", "n_data", "train_seed", "cache", "data_region_fraction", "data_task_fraction")


def _check_training(cls: str, o: Any) -> None:
    for name in ("cvae_epochs", "n_data"):
        v = getattr(o, name)
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise ValueError(f"{cls}.{name}: expected an integer >= 1, got {v!r}")
    if isinstance(o.train_seed, bool) or not isinstance(o.train_seed, int) or o.train_seed < 0:
        raise ValueError(f"{cls}.train_seed: expected an integer >= 0, got {o.train_seed!r}")
    if not isinstance(o.cache, bool):
        raise ValueError(f"{cls}.cache: expected True/False, got {o.cache!r}")
    for name in ("data_region_fraction", "data_task_fraction"):
        v = getattr(o, name)
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v <= 1):
            raise ValueError(f"{cls}.{name}: expected a number in [0, 1], got {v!r}")
    if o.data_region_fraction + o.data_task_fraction > 1:
        raise ValueError(f"{cls}: data_region_fraction + data_task_fraction must be <= 1, got "
                         f"{o.data_region_fraction!r} + {o.data_task_fraction!r}")


@dataclass(frozen=True)
class LatentSamplingOptions(CBiRRT2Options):
    """Options of :class:`LatentSampling`: CBiRRT2's and the CVAE's training selection."""

    #: CVAE training epochs [count] (the paper: 1000; see :class:`~.cvae.CVAESettings`).
    cvae_epochs: int = CVAESettings.epochs
    #: On-manifold training configurations of the scene [count] (the paper: 10,000).
    n_data: int = CVAESettings.n_data
    #: Seed of the data and the training [-].
    train_seed: int = 0
    #: Read / write the data and the weights from / to the on-disk cache [-].
    cache: bool = True
    #: Share of the training data drawn by constrained random walks in the task's start and goal regions [-]
    #: (:attr:`~optplan.planners.manifold_samples.ManifoldSampleSettings.region_fraction`; 0: as the paper).
    data_region_fraction: float = 0.0
    #: Share of the training data drawn as the nodes of a task-space exploration over the object's whole
    #: workspace [-] (:attr:`~optplan.planners.manifold_samples.ManifoldSampleSettings.task_fraction`; 0: projected
    #: joint draws only).
    data_task_fraction: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_training("LatentSamplingOptions", self)


def _cvae(robot: Any, scene: Any, o: Any, checker: ValidityChecker, kin: ClosedChainKinematics, progress: bool) -> Any:
    s = CVAESettings(epochs=o.cvae_epochs, n_data=o.n_data, data_seed=o.train_seed, seed=o.train_seed,
                     data_region_fraction=o.data_region_fraction, data_task_fraction=o.data_task_fraction)
    return load_or_train_cvae(robot, scene, s, checker=checker, kinematics=kin, cache=o.cache, progress=progress)


class LatentSampling(CBiRRT2):
    """CBiRRT2 with CVAE latent sampling (module docstring)."""

    name = "latent-sampling"

    def __init__(self, robot: Any, scene: Any, options: LatentSamplingOptions | None = None, *,
                 checker: ValidityChecker | None = None, kinematics: ClosedChainKinematics | None = None,
                 progress: bool = False) -> None:
        options = options or LatentSamplingOptions()
        if not isinstance(options, LatentSamplingOptions):
            raise TypeError(f"options: expected LatentSamplingOptions, got {type(options).__name__}")
        super().__init__(robot, scene, options, checker=checker, kinematics=kinematics)
        self.cvae = _cvae(robot, scene, options, self.checker, self.kin, progress)

    def sample_target(self, rng: np.random.Generator, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """A decoded latent sample, projected when the projection converges."""
        q = np.clip(self.cvae.decode(rng.standard_normal(self.cvae.latent_dim)), lower, upper)
        x = project_onto_chain(self.kin, q, lower, upper, self.options.tolerance, self.options.max_projection_iterations)
        return q if x is None else x


@dataclass(frozen=True)
class LCBiRRTOptions:
    """Options of :class:`LCBiRRT` (LCBiRRT, and LCBiRRT-LPO with ``lpo=True``)."""

    #: Largest latent step of an extension [latent units; prior-CDF units with ``latent_interpolation="cdf"``]
    #: (Park et al.'s: 0.1 in the prior's CDF; the eager variant and the linear metric were measured with 0.3).
    latent_step: float = 0.1
    #: The lazy trees' latent metric: ``"cdf"`` — distances, nearest nodes and steps between the prior's CDF images
    #: ``Φ(z)`` (Park et al.'s), ``"linear"`` — in the latent space itself [-].
    latent_interpolation: str = "cdf"
    #: Probability per iteration of one joint-space step of a tree toward a uniform random configuration (lazy
    #: growth; Park et al.'s: 0.001) [-].
    random_growth: float = 0.001
    #: A latent vector with a classifier probability below this is not expanded [-].
    classifier_threshold: float = 0.5
    #: The classifier refuses a step only when it also scores the step's parent node as valid: a node in a tree
    #: has been decoded, projected and collision-checked, so where the classifier scores it below the threshold
    #: (e.g. a start whose latent code lies where the classifier's training samples were mostly invalid) it is
    #: known to be wrong there, and the step is decided by the decode + projection + collision check alone.
    #: Off: every step below the threshold is refused — a tree whose root the classifier scores invalid then
    #: never grows [-].
    classifier_trusts_verified: bool = True
    #: Joint spacing of the projected, collision-checked points of an edge [rad] (the paper: 0.2).
    collision_step: float = 0.2
    #: Steps of one extension before it stops [count].
    max_extend_steps: int = 20
    #: Park et al.'s lazy growth (:mod:`~.latent_lazy`): the trees grow in the latent space by the classifier alone
    #: and a branch is decoded, projected and checked when the trees meet, a failed node removed and followed by a
    #: latent jump; off: every step is decoded, projected and checked as it is added (the eager variant) [-].
    lazy: bool = True
    #: Joint-space steps of a latent jump after a failed validation (lazy growth) [count].
    jump_steps: int = 2
    #: Standard deviation of the latent sampling distribution [latent units].
    sample_sigma: float = 1.0
    #: Projection tolerance on the closed-chain residual, max |h| [m or rad per row].
    tolerance: float = 1e-7
    #: Decode a step as ``decode(z) + (q_parent − decode(z_parent))`` before the projection (each tree then
    #: carries its own decoding offset, so two trees that share a latent vector hold different configurations
    #: and rarely join); off (the default): every latent node's configuration is ``project(decode(z))``, the
    #: same in both trees, and nodes away from the decoder's image are reached by joint-space jumps [-].
    anchored_decoding: bool = False
    #: Step of the constrained joint-space extension that leaves a start, goal or jump node for the decoded
    #: configuration of a latent step, and that links the trees in joint space [rad].
    joint_step: float = 0.6
    #: The trees are linked in joint space when a new node comes this close to the other tree's nearest
    #: configuration (a constrained joint-space connect to it is then tried) [rad].
    link_distance: float = 1.0
    #: Local path optimisation in the latent space (LCBiRRT-LPO) [-].
    lpo: bool = False
    #: γ: gradient-ascent step on the learned distance [latent units per m] (the paper: 0.8).
    lpo_gamma: float = 0.8
    #: N_max: gradient-ascent iterations of one node [count] (the paper: 10).
    lpo_iterations: int = 10
    #: Lazy growth: every this many meetings of the trees (the first included) the branches are checked with LPO's
    #: repair (the LPO authors' whole-path check interval); eager: optimise every this many new nodes [count]
    #: (the paper's path optimisation interval: 3).
    lpo_interval: int = 3
    #: Nodes whose learned distance is below this are optimised (eager variant) [m].
    lpo_clearance: float = 0.05
    #: Clearance counted as contact [m].
    margin: float = 0.0
    #: Cap on the iterations [count] (0: only the time limit).
    max_iterations: int = 0
    #: CVAE training epochs [count] (the paper: 1000; see :class:`~.cvae.CVAESettings`).
    cvae_epochs: int = CVAESettings.epochs
    #: On-manifold training configurations of the scene [count] (the paper: 10,000).
    n_data: int = CVAESettings.n_data
    #: Seed of the data and the training [-].
    train_seed: int = 0
    #: Read / write the data and the weights from / to the on-disk cache [-].
    cache: bool = True
    #: Share of the training data drawn by constrained random walks in the task's start and goal regions [-]
    #: (:attr:`~optplan.planners.manifold_samples.ManifoldSampleSettings.region_fraction`; 0: as the paper).
    data_region_fraction: float = 0.0
    #: Share of the training data drawn as the nodes of a task-space exploration over the object's whole
    #: workspace [-] (:attr:`~optplan.planners.manifold_samples.ManifoldSampleSettings.task_fraction`; 0: projected
    #: joint draws only).
    data_task_fraction: float = 0.0
    #: Valid and invalid latent samples (classifier), free and colliding configurations (distance), each [count]
    #: (the paper: 1000).
    n_model_samples: int = 1000
    #: Classifier training epochs at most [count] (the paper: 150; early stopping, :class:`~.latent_models.LatentModelSettings`).
    classifier_epochs: int = 150
    #: Distance network training epochs at most [count] (the paper: 60; early stopping as the classifier).
    distance_epochs: int = 60

    def __post_init__(self) -> None:
        for name in ("n_model_samples", "classifier_epochs", "distance_epochs"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"LCBiRRTOptions.{name}: expected an integer >= 1, got {v!r}")
        for name in ("latent_step", "collision_step", "sample_sigma", "tolerance", "lpo_gamma", "joint_step",
                     "link_distance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"LCBiRRTOptions.{name}: expected a positive number, got {v!r}")
        if not (isinstance(self.classifier_threshold, (int, float)) and 0 <= self.classifier_threshold < 1):
            raise ValueError(f"LCBiRRTOptions.classifier_threshold: expected a number in [0, 1), "
                             f"got {self.classifier_threshold!r}")
        for name in ("max_extend_steps", "lpo_iterations", "lpo_interval", "jump_steps"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"LCBiRRTOptions.{name}: expected an integer >= 1, got {v!r}")
        if isinstance(self.max_iterations, bool) or not isinstance(self.max_iterations, int) or self.max_iterations < 0:
            raise ValueError(f"LCBiRRTOptions.max_iterations: expected an integer >= 0, got {self.max_iterations!r}")
        for name in ("lpo_clearance", "margin"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"LCBiRRTOptions.{name}: expected a number >= 0 m, got {v!r}")
        if not isinstance(self.classifier_trusts_verified, bool):
            raise ValueError(f"LCBiRRTOptions.classifier_trusts_verified: expected True/False, "
                             f"got {self.classifier_trusts_verified!r}")
        if not isinstance(self.anchored_decoding, bool):
            raise ValueError(f"LCBiRRTOptions.anchored_decoding: expected True/False, got {self.anchored_decoding!r}")
        if self.latent_interpolation not in ("cdf", "linear"):
            raise ValueError(f"LCBiRRTOptions.latent_interpolation: expected 'cdf' or 'linear', "
                             f"got {self.latent_interpolation!r}")
        if not (isinstance(self.random_growth, (int, float)) and not isinstance(self.random_growth, bool)
                and 0 <= self.random_growth <= 1):
            raise ValueError(f"LCBiRRTOptions.random_growth: expected a probability in [0, 1], got {self.random_growth!r}")
        for name in ("lpo", "lazy"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"LCBiRRTOptions.{name}: expected True/False, got {getattr(self, name)!r}")
        if self.lazy and self.anchored_decoding:
            raise ValueError("LCBiRRTOptions: anchored_decoding needs lazy=False (the lazy trees decode each latent "
                             "vector on its own)")
        _check_training("LCBiRRTOptions", self)


class _LatentTree:
    """Nodes with a latent vector ``Z``, a projected, valid configuration ``Q`` and ``decoded``: whether
    ``Q`` is ``project(decode(Z))`` (a latent node, the same configuration in either tree) or a configuration
    reached in joint space whose ``Z`` is its encoding (a root or a jump node)."""

    def __init__(self, z: np.ndarray, q: np.ndarray, p: float) -> None:
        self.Z = [z]
        self.Q = [q]
        self.P = [p]   # the classifier's probability of each node's latent vector
        self.decoded = [False]
        self.parent = [-1]
        self.children: list[list[int]] = [[]]
        self.edge: list[list[np.ndarray]] = [[]]   # projected points from the parent to the node
        self.added = 0

    def add(self, z: np.ndarray, q: np.ndarray, p: float, parent: int, edge: list[np.ndarray],
            decoded: bool = True) -> int:
        self.Z.append(z)
        self.Q.append(q)
        self.P.append(p)
        self.decoded.append(decoded)
        self.parent.append(parent)
        self.children.append([])
        self.children[parent].append(len(self.Z) - 1)
        self.edge.append(edge)
        self.added += 1
        return len(self.Z) - 1

    def nearest(self, z: np.ndarray) -> int:
        return int(np.argmin(np.linalg.norm(np.asarray(self.Z) - z, axis=1)))

    def nearest_q(self, q: np.ndarray) -> tuple[int, float]:
        d = np.linalg.norm(np.asarray(self.Q) - q, axis=1)
        j = int(np.argmin(d))
        return j, float(d[j])

    def branch(self, i: int) -> list[np.ndarray]:
        """Configurations from the root to node ``i``, edge points included."""
        out: list[np.ndarray] = []
        while i >= 0:
            out[:0] = [*self.edge[i], self.Q[i]]
            i = self.parent[i]
        return out


def _alive(t: Any, k: int) -> bool:
    return bool(t.alive[k]) if hasattr(t, "alive") else True


def _verified(t: Any) -> list[int]:
    return list(t.verified) if hasattr(t, "verified") else list(range(len(t.Q)))


def _gap(A: np.ndarray, B: np.ndarray) -> float:
    """Smallest distance between a row of ``A`` and a row of ``B`` (every row of the larger, at most 100 of the
    smaller)."""
    small, big = (A, B) if len(A) <= len(B) else (B, A)
    pick = small[::max(1, len(small) // 100)]
    return min(float(np.linalg.norm(big - x, axis=1).min()) for x in pick)


class LCBiRRT(Planner):
    """LCBiRRT / LCBiRRT-LPO (module docstring)."""

    name = "lcbirrt"

    def __init__(self, robot: Any, scene: Any, options: LCBiRRTOptions | None = None, *,
                 checker: ValidityChecker | None = None, kinematics: ClosedChainKinematics | None = None,
                 progress: bool = False) -> None:
        super().__init__(robot, scene)
        if scene is None or scene.object is None or len(scene.object.grasps) != 2:
            raise ConfigurationError("LCBiRRT needs a scene with an [object] grasped by two arms")
        self.options = o = options or LCBiRRTOptions()
        if not isinstance(o, LCBiRRTOptions):
            raise TypeError(f"options: expected LCBiRRTOptions, got {type(o).__name__}")
        self.name = "lcbirrt-lpo" if o.lpo else "lcbirrt"
        self.checker = checker or ValidityChecker(robot, scene, margin=o.margin)
        self.kin = kinematics or ClosedChainKinematics(robot, scene.object.grasps)
        self.grasps = scene.object.grasps
        self.cvae = _cvae(robot, scene, o, self.checker, self.kin, progress)
        ms = LatentModelSettings(n_classifier=o.n_model_samples, classifier_epochs=o.classifier_epochs,
                                 n_distance=o.n_model_samples, distance_epochs=o.distance_epochs, seed=o.train_seed)
        data = manifold_samples(robot, scene, ManifoldSampleSettings(n=o.n_data, seed=o.train_seed,
                                                                     region_fraction=o.data_region_fraction,
                                                                     task_fraction=o.data_task_fraction),
                                checker=self.checker, kinematics=self.kin, cache=o.cache)
        self.classifier = load_or_train_classifier(robot, scene, self.cvae, self.kin, self.checker, ms,
                                                   samples=data.Q, cache=o.cache, progress=progress)
        self.distance = None
        if o.lpo:
            self.distance = load_or_train_distance(robot, scene, self.cvae, self.kin, self.checker, data.Q, ms,
                                                   cache=o.cache, progress=progress)
            # JAX compiles the jitted gradient on its first call (~0.3 s of CPU): at construction, not in a query's budget
            self.distance.value_and_gradient(np.zeros(self.cvae.latent_dim))

    # ------------------------------------------------------------------ helpers
    def _config(self, z: np.ndarray, z_near: np.ndarray, near: np.ndarray, st: dict[str, Any]) -> np.ndarray | None:
        """Projected, valid configuration of ``z`` (None otherwise): ``project(decode(z))``, or with
        :attr:`LCBiRRTOptions.anchored_decoding` the decoding anchored at ``near``, the configuration of ``z_near``."""
        lo, hi = self.robot.lower, self.robot.upper
        st["decodes"] += 1
        q = self.cvae.decode(z)
        if self.options.anchored_decoding:
            q = q + (near - self.cvae.decode(z_near))
        x = project_onto_chain(self.kin, np.clip(q, lo, hi), lo, hi, self.options.tolerance)
        if x is None:
            st["projection_failures"] += 1
            return None
        if not self.checker.is_valid(x):
            st["collisions"] += 1
            return None
        return x

    def _edge(self, a: np.ndarray, b: np.ndarray, st: dict[str, Any], deadline: Deadline) -> list[np.ndarray] | None:
        st["edge_checks"] += 1
        o = self.options
        return constrained_edge(a, b, lambda x: project_onto_chain(self.kin, x, self.robot.lower, self.robot.upper,
                                                                   o.tolerance), self.checker.is_valid,
                                o.collision_step, deadline)

    def connect_q(self, tree: Any, i: int, target: np.ndarray, st: dict[str, Any], deadline: Deadline,
                  max_steps: int | None = None) -> tuple[list[np.ndarray] | None, int]:
        """Constrained joint-space extension from node ``i`` toward the configuration ``target`` (on the
        manifold and valid), CBiRRT's: steps of at most ``joint_step`` rad, each projected, collision-checked
        and joined by the constrained local planner; every intermediate configuration becomes a node of
        ``tree`` (latent vector: its encoding). ``(edge points to target, last node)`` when it arrives,
        ``(None, last node)`` when it is trapped (a failed projection or edge, no progress, the deadline) or has
        taken ``max_steps`` steps (default: ``max_extend_steps`` + the distance in steps)."""
        o = self.options
        lo, hi = self.robot.lower, self.robot.upper
        n = max_steps + 1 if max_steps is not None else o.max_extend_steps + int(np.linalg.norm(target - tree.Q[i]) / o.joint_step)
        for _ in range(n):
            if deadline.expired():
                break
            d = target - tree.Q[i]
            dist = float(np.linalg.norm(d))
            if dist <= o.joint_step:
                return self._edge(tree.Q[i], target, st, deadline), i
            x = project_onto_chain(self.kin, tree.Q[i] + (o.joint_step / dist) * d, lo, hi, o.tolerance)
            if x is None or float(np.linalg.norm(target - x)) >= dist - 1e-9 or not self.checker.is_valid(x):
                break
            edge = self._edge(tree.Q[i], x, st, deadline)
            if edge is None:
                break
            z = self.cvae.encode(x)
            st["jump_nodes"] += 1
            i = tree.add(z, x, float(self.classifier.probability(z)), i, edge, decoded=False)
        return None, i

    def extend(self, tree: _LatentTree, i: int, z_target: np.ndarray, st: dict[str, Any], deadline: Deadline,
               ) -> tuple[bool, int]:
        """Step from node ``i`` toward ``z_target`` in the latent space; ``(reached, last node)``. A step's
        configuration is ``project(decode(z))``; from a node whose configuration is not its decoding (a root,
        a jump node) it is reached by :meth:`connect_q` (a latent jump), from a decoded node by one edge."""
        o = self.options
        for _ in range(o.max_extend_steps):
            if deadline.expired():
                break
            d = z_target - tree.Z[i]
            dist = float(np.linalg.norm(d))
            if dist < 1e-9:
                return True, i
            z = z_target.copy() if dist <= o.latent_step else tree.Z[i] + (o.latent_step / dist) * d
            p = float(self.classifier.probability(z))
            if p < o.classifier_threshold:
                if o.classifier_trusts_verified and tree.P[i] < o.classifier_threshold:
                    st["classifier_overruled"] += 1   # the parent is valid where the classifier says not
                else:
                    st["classifier_rejects"] += 1
                    break
            q = self._config(z, tree.Z[i], tree.Q[i], st)
            if q is None and not (o.anchored_decoding or tree.decoded[i]):
                # around a root or jump node the decoder's image may be invalid (the CVAE reconstructs the node
                # poorly): jump in joint space toward the target's own decoded configuration instead
                if dist > o.latent_step:
                    z, p = z_target.copy(), float(self.classifier.probability(z_target))
                    q = self._config(z, tree.Z[i], tree.Q[i], st)
                    dist = 0.0
            if q is None:
                break
            if o.anchored_decoding or tree.decoded[i]:
                edge = self._edge(tree.Q[i], q, st, deadline)
            else:
                st["latent_jumps"] += 1
                edge, i = self.connect_q(tree, i, q, st, deadline)
            if edge is None:
                break
            i = tree.add(z, q, p, i, edge, decoded=not o.anchored_decoding)
            if o.lpo and tree.added % o.lpo_interval == 0:
                self._optimize(tree, i, st, deadline)
            if dist <= o.latent_step:
                return True, i
        return False, i

    def _link(self, ta: _LatentTree, i_a: int, tb: _LatentTree, i_b: int | None, st: dict[str, Any],
              deadline: Deadline) -> tuple[int, int, list[np.ndarray]] | None:
        """Join node ``i_a`` of ``ta`` to ``tb`` in joint space: to ``i_b`` (the connect extension's node, which
        reached ``ta.Z[i_a]`` in the latent space) when given, else to ``tb``'s nearest configuration when it is
        within ``link_distance`` rad; a constrained joint-space connect from ``tb`` to ``ta.Q[i_a]``.
        ``(i_a, last node of tb, edge points from ta.Q[i_a] to it)`` or None."""
        if i_b is None:
            i_b, gap = tb.nearest_q(ta.Q[i_a])
            if gap > self.options.link_distance:
                return None
            st["q_link_attempts"] += 1
        else:
            gap = float(np.linalg.norm(tb.Q[i_b] - ta.Q[i_a]))
            st["link_attempts"] += 1
        st["link_gap_min"] = min(st["link_gap_min"], gap)
        edge, j = self.connect_q(tb, i_b, ta.Q[i_a], st, deadline)
        if edge is None:
            return None
        st["link_successes"] += 1
        return i_a, j, edge[::-1]

    def _optimize(self, tree: _LatentTree, i: int, st: dict[str, Any], deadline: Deadline) -> None:
        """Local path optimisation of node ``i`` and its ancestors (module docstring)."""
        o = self.options
        assert self.distance is not None
        for _ in range(o.lpo_interval):
            if i <= 0 or deadline.expired():
                return
            z = tree.Z[i].copy()
            d, grad = self.distance.value_and_gradient(z)
            if d < o.lpo_clearance:
                st["lpo_nodes"] += 1
                for _ in range(o.lpo_iterations):
                    z = z + o.lpo_gamma * grad
                    d, grad = self.distance.value_and_gradient(z)
                    if d >= o.lpo_clearance:
                        break
                q = self._config(z, tree.Z[i], tree.Q[i], st)
                if q is not None:
                    par = self._edge(tree.Q[tree.parent[i]], q, st, deadline)
                    kids = [self._edge(q, tree.Q[c], st, deadline) for c in tree.children[i]] if par is not None else [None]
                    if par is not None and all(k is not None for k in kids):
                        tree.Z[i], tree.Q[i], tree.edge[i] = z, q, par
                        tree.P[i] = float(self.classifier.probability(z))
                        tree.decoded[i] = not o.anchored_decoding
                        for c, k in zip(tree.children[i], kids):
                            tree.edge[c] = k   # type: ignore[assignment]  # None excluded above
                        st["lpo_moves"] += 1
            i = tree.parent[i]

    # ------------------------------------------------------------------ main loop
    def _plan_eager(self, q_start: np.ndarray, q_goal: np.ndarray, deadline: Deadline, rng: np.random.Generator,
                    st: dict[str, Any]) -> tuple[Any, Any, bool, tuple[int, int, list[np.ndarray]] | None]:
        """The eager search: every latent step decoded, projected and checked as it is added."""
        o = self.options
        roots = []
        for q in (q_start, q_goal):
            z = self.cvae.encode(q)
            roots.append(_LatentTree(z, q, float(self.classifier.probability(z))))
        ta, tb = roots
        st["start_root_probability"], st["goal_root_probability"] = ta.P[0], tb.P[0]
        a_is_start = True
        found = None
        while not deadline.expired():
            if o.max_iterations and st["iterations"] >= o.max_iterations:
                break
            st["iterations"] += 1
            z_rand = rng.normal(0.0, o.sample_sigma, self.cvae.latent_dim)
            n_a = len(ta.Z)
            _, i_a = self.extend(ta, ta.nearest(z_rand), z_rand, st, deadline)
            reached, i_b = self.extend(tb, tb.nearest(ta.Z[i_a]), ta.Z[i_a].copy(), st, deadline)
            if not reached:   # the latent vectors agree only to the step: join the configurations in joint space
                j = tb.nearest(ta.Z[i_a])
                if float(np.linalg.norm(tb.Z[j] - ta.Z[i_a])) <= o.latent_step:
                    reached, i_b = True, j
            if reached:
                found = self._link(ta, i_a, tb, i_b, st, deadline)
            if found is None and len(ta.Z) > n_a:   # the new node may lie near the other tree in joint space
                found = self._link(ta, i_a, tb, None, st, deadline)
            if found is not None:
                break
            ta, tb, a_is_start = tb, ta, not a_is_start
        if not math.isfinite(st["link_gap_min"]):
            st["link_gap_min"] = None
        return ta, tb, a_is_start, found

    def _plan(self, q_start: np.ndarray, q_goal: np.ndarray, deadline: Deadline, rng: np.random.Generator,
              seed: int) -> PlanResult:
        o, ck = self.options, self.checker
        st: dict[str, Any] = {"iterations": 0, "decodes": 0, "projection_failures": 0, "collisions": 0, "classifier_rejects": 0,
              "classifier_overruled": 0, "edge_checks": 0, "link_attempts": 0, "q_link_attempts": 0, "link_successes": 0,
              "link_gap_min": math.inf, "latent_jumps": 0, "jump_nodes": 0, "lpo_nodes": 0, "lpo_moves": 0}
        c0 = ck.n_checks
        bad = invalid_endpoints(self, q_start, q_goal, st)
        if bad is not None:
            return bad
        if o.lazy:
            ta, tb, a_is_start, found = plan_lazy(self, q_start, q_goal, deadline, rng, st)
        else:
            ta, tb, a_is_start, found = self._plan_eager(q_start, q_goal, deadline, rng, st)
        # how far apart the trees stayed: the closest pair of nodes in joint space [rad] (verified nodes) and in the
        # latent space (at most 100 nodes of the smaller tree against the larger: milliseconds after the limit)
        st["tree_gap_q"] = _gap(*(np.asarray([t.Q[k] for k in _verified(t)]) for t in (ta, tb)))
        st["tree_gap_z"] = _gap(*(np.asarray(t.Z)[[k for k in range(len(t.Z)) if _alive(t, k)]] for t in (ta, tb)))
        t_start, t_goal = (ta, tb) if a_is_start else (tb, ta)
        st["start_tree_nodes"], st["goal_tree_nodes"] = (sum(_alive(t, k) for k in range(len(t.Z))) for t in (t_start, t_goal))
        st["nodes"] = st["start_tree_nodes"] + st["goal_tree_nodes"]
        st["start_tree_verified"], st["goal_tree_verified"] = len(_verified(t_start)), len(_verified(t_goal))
        st["collision_checks"] = ck.n_checks - c0
        if found is None:
            if deadline.expired():
                return self.empty_result(PlanStatus.TIMEOUT, "time limit reached", **st)
            return self.empty_result(PlanStatus.FAILED, "iteration cap reached", **st)
        i_a, i_b, link = found
        P = ta.branch(i_a) + link + tb.branch(i_b)[::-1]
        if not a_is_start:
            P = P[::-1]
        path = np.array(P)
        path[0], path[-1] = q_start, q_goal
        poses = [self.kin.object_pose(q) for q in path]
        return PlanResult(PlanStatus.EXACT, self.name, path, poses, np.ones(len(path), bool),
                          [PathSegment("constrained", 0, len(path) - 1)], st)
