"""OC-RRT — orientation-constrained RRT for decoupled (spherical-wrist) dual arms (Alg. 1-2 of
"OC-RRT" by the PR2 dual-arm paper's authors), in RRT and RRT-Connect form.

Every node is ON the constraint manifold by construction, never projected:

* **Sampling** (Alg. 1): draw the manifold parameters ``p`` uniformly in the joint limits
  (open chain: q1..q4 of both arms; closed chain: q1..q4 of the active arm and the passive arm's
  redundancy angle q1), solve the wrist(s) in closed form for the required hand orientation(s)
  and, in closed chain, the passive arm by the analytic full-pose IK; a random branch is taken.
  Parameters without a solution in the joint limits are redrawn.
* **OCSteer** (Alg. 2): from the nearest node, step at most ``step`` [rad] (max-norm) in parameter
  space toward the sample, complete the configuration on the branch nearest the parent, and
  reject it if any joint moved more than ``max_joint_step`` [rad] (a branch jump or a
  near-singular wrist) or if it, or an intermediate configuration of the edge every
  ``collision_step`` [rad] of parameter motion (also completed on the manifold and checked for
  the same joint-step bound), is in collision.
* **Edges** are parameter-space straight lines completed on the manifold: :meth:`OCRRT.densify`
  resamples a returned path at any resolution, every configuration on the manifold to the IK's
  accuracy (~1e-14), which is how ORMSD / PRMSD are evaluated "along the path".

**Certified edges** (``certified_edges``, on by default; off in :meth:`OCRRTOptions.paper`): an
edge's manifold curve is not a straight joint line, so what is certified is the path the user
executes: the chord path (piecewise linear in joint space) through the edge's configurations
completed every ``certify_resolution`` [rad] of parameter motion — exactly the configurations
:meth:`OCRRT.densify` returns at that resolution — by conservative advancement on exact distances
(:meth:`.ValidityChecker.path_is_certified`): every collision pair stays at least
``edge_min_clearance / 2`` apart at every point of every chord. The chords leave the manifold by
O(resolution²) between their ends (the constraint holds exactly at the configurations); a path
densified at another resolution has its configurations on the manifold curve, within that chord
deviation of the certified chords, not on them. The cheap configuration checks every
``collision_step`` run first, so only edges that pass them pay for the certificate.

RRT variant: goal-biased (``goal_bias``) single tree; the goal is reached when a steer toward it
lands on it (same branch). ``OCRRTOptions.paper()`` is the paper's Algorithm 2 exactly; the
default single tree adds goal attempts from new nodes, samples around the goal's parameters on
the goal's branch (the few nodes past an obstacle next to the goal grow), goal attempts from the
nodes grown toward them, and bisection of fast but continuous steps next to singular wrists
(see :class:`OCRRTOptions`). RRT-Connect: two trees, extend one toward the sample, connect the
other greedily to the new node.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from ..errors import ConfigurationError
from .base import Deadline, PathSegment, Planner, PlanResult, PlanStatus
from .orientation import DualArmOrientationConstraint, OrientationManifold
from .tree import Tree, joined_path
from .validity import ValidityChecker

if TYPE_CHECKING:
    from ..model.robot import RobotModel
    from ..scene import Scene

__all__ = ["OCRRTOptions", "OCRRT"]
log = logging.getLogger(__name__)

TRAPPED, ADVANCED, REACHED = 0, 1, 2
_max = np.maximum.reduce


def _maxabs(a: np.ndarray) -> float:
    """max |a_i| (``float(np.abs(a).max())`` without the method's Python wrapper)."""
    return float(_max(np.abs(a)))


@dataclass(frozen=True)
class OCRRTOptions:
    """Options of :class:`OCRRT` (orientation-constrained RRT / RRT-Connect)."""

    #: RRT-Connect (two trees) instead of goal-biased RRT.
    connect: bool = True
    #: Largest parameter change per OCSteer, max-norm [rad].
    step: float = 0.3
    #: Parameter spacing of the configurations checked along an edge [rad].
    collision_step: float = 0.1
    #: Largest joint change between consecutive checked configurations [rad] (continuity on one IK branch).
    max_joint_step: float = 0.5
    #: Probability of steering to the goal (RRT) [-].
    goal_bias: float = 0.1
    #: RRT: with probability ``goal_bias`` also steer to the goal from each node just added, not only from the
    #: node nearest the goal.
    goal_from_new: bool = True
    #: Redraws of an unsolvable sample before the iteration is skipped [count].
    max_sample_tries: int = 50
    #: The trees meet / the goal is reached when the configurations agree to this, max-norm [rad].
    reach_tolerance: float = 1e-9
    #: Cap on iterations [count] (0: only the time limit).
    max_iterations: int = 0
    #: Clearance counted as contact [m].
    margin: float = 0.0
    #: ``"improved"`` or ``"paper"``: the paper's Algorithm 2 exactly (goal-biased steering from the node nearest
    #: the goal only; ``goal_from_new``, ``refine_depth``, ``extend_to_sample``, ``goal_turn_joints`` and the
    #: goal region are then ignored); :meth:`paper` builds it.
    variant: str = "improved"
    #: Bisections of a checked step that moves a joint more than ``max_joint_step`` before it is rejected [count]:
    #: a continuous but fast motion (wrist rolls next to a singular wrist) passes, a jump to another IK branch does
    #: not shrink and is still rejected; 0: reject at once (the paper); None: 3 for the single tree, 0 for
    #: RRT-Connect.
    refine_depth: int | None = None
    #: Single tree: steer toward the sample until it is reached or blocked (RRT-Ext-Connect) instead of one step.
    extend_to_sample: bool = False
    #: Names of continuous joints whose ``q + 2πk`` is the same physical configuration; the single tree then also
    #: accepts the goal's equivalents on them and the path ends at the one reached (``stats["goal_turns"]``).
    #: Empty: the exact goal.
    goal_turn_joints: tuple[str, ...] = ()
    #: Single tree: probability that a sample is drawn within ``goal_region_radius`` of the goal's parameters and
    #: completed on the goal's IK branch [-].
    goal_region_bias: float = 0.3
    #: Half-width of the goal region, max-norm over the parameters [rad].
    goal_region_radius: float = 1.0
    #: Steer to the goal from every node grown toward a goal-region sample.
    goal_from_region: bool = True
    #: Probability of a bridge-test sample (both ends in collision, midpoint free: narrow passages) [-].
    bridge_bias: float = 0.0
    #: Spread of the bridge test's second parameter vector (Gaussian) [rad].
    bridge_sigma: float = 0.2
    #: Certify every edge collision-free at every point (see the module docstring, "Certified edges"): the chord
    #: path through the edge's configurations every ``certify_resolution`` — what :meth:`OCRRT.densify` returns at
    #: that resolution — by conservative advancement on exact distances. Off: configurations checked every
    #: ``collision_step`` only (the paper).
    certified_edges: bool = True
    #: Certify an edge only once it lies on a start-goal path (a failing edge removes its node's subtree and the
    #: search goes on; lazy collision checking); False: every new edge at once.
    certify_lazily: bool = True
    #: Parameter spacing of the certified chord path [rad] (the benchmark densifies at 0.01 too).
    certify_resolution: float = 0.01
    #: Certified edges keep every collision pair at least half of this apart; an edge whose exact clearance drops
    #: below it at an evaluated configuration is rejected [m].
    edge_min_clearance: float = 1e-3

    @classmethod
    def paper(cls, **kw: Any) -> OCRRTOptions:
        """The paper's single-tree OC-RRT (Algorithm 2): goal-biased steering from the node
        nearest the goal, one OCSteer step toward each sample, the exact goal configuration."""
        kw.setdefault("certified_edges", False)
        return cls(connect=False, variant="paper", goal_from_new=False, **kw)

    def __post_init__(self) -> None:
        if self.variant not in ("improved", "paper"):
            raise ValueError(f"OCRRTOptions.variant: expected 'improved' or 'paper', got {self.variant!r}")
        if self.refine_depth is not None and not (isinstance(self.refine_depth, int) and 0 <= self.refine_depth <= 20):
            raise ValueError(f"OCRRTOptions.refine_depth: expected an int in [0, 20], got {self.refine_depth!r}")
        for name in ("goal_region_bias", "bridge_bias"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 <= v <= 1.0):
                raise ValueError(f"OCRRTOptions.{name}: expected a probability in [0, 1], got {v!r}")
        for name in ("goal_region_radius", "bridge_sigma"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"OCRRTOptions.{name}: expected a positive number of radians, got {v!r}")
        if not isinstance(self.certify_lazily, bool):
            raise ValueError(f"OCRRTOptions.certify_lazily: expected True/False, got {self.certify_lazily!r}")
        if not isinstance(self.certified_edges, bool):
            raise ValueError(f"OCRRTOptions.certified_edges: expected True/False, got {self.certified_edges!r}")
        for name in ("certify_resolution", "edge_min_clearance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"OCRRTOptions.{name}: expected a positive number, got {v!r}")
        if not isinstance(self.goal_from_region, bool):
            raise ValueError(f"OCRRTOptions.goal_from_region: expected True/False, got {self.goal_from_region!r}")
        if not isinstance(self.extend_to_sample, bool):
            raise ValueError(f"OCRRTOptions.extend_to_sample: expected True/False, got {self.extend_to_sample!r}")
        if isinstance(self.goal_turn_joints, str) or not all(isinstance(n, str) for n in self.goal_turn_joints):
            raise ValueError(f"OCRRTOptions.goal_turn_joints: expected a tuple of joint names, got {self.goal_turn_joints!r}")
        object.__setattr__(self, "goal_turn_joints", tuple(self.goal_turn_joints))
        for name in ("step", "collision_step", "max_joint_step", "reach_tolerance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"OCRRTOptions.{name}: expected a positive number, got {v!r}")
        if not (0.0 <= self.goal_bias <= 1.0):
            raise ValueError(f"OCRRTOptions.goal_bias: expected a probability in [0, 1], got {self.goal_bias!r}")
        for name in ("max_sample_tries", "max_iterations"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= (1 if name == "max_sample_tries" else 0)):
                raise ValueError(f"OCRRTOptions.{name}: expected a non-negative int, got {v!r}")
        if not isinstance(self.goal_from_new, bool):
            raise ValueError(f"OCRRTOptions.goal_from_new: expected True/False, got {self.goal_from_new!r}")
        if not (isinstance(self.margin, (int, float)) and self.margin >= 0):
            raise ValueError(f"OCRRTOptions.margin: expected a number >= 0 m, got {self.margin!r}")


class _ParamTree(Tree):
    """A tree whose nodes also carry the manifold parameters ``P`` (a column of :class:`Tree`)."""

    P: np.ndarray


class OCRRT(Planner):
    """OC-RRT / OC-RRT-Connect on a :class:`DualArmOrientationConstraint` (module docstring)."""

    name = "oc_rrt"

    def __init__(self, robot: RobotModel, scene: Scene | None, constraint: DualArmOrientationConstraint, options: OCRRTOptions | None = None,
                 *, checker: ValidityChecker | None = None, manifold: OrientationManifold | None = None) -> None:
        super().__init__(robot, scene)
        if not isinstance(constraint, DualArmOrientationConstraint):
            raise TypeError(f"constraint: expected DualArmOrientationConstraint, got {type(constraint).__name__}")
        self.options = options or OCRRTOptions()
        if not isinstance(self.options, OCRRTOptions):
            raise TypeError(f"options: expected OCRRTOptions, got {type(self.options).__name__}")
        self.constraint = constraint
        self.manifold = manifold or OrientationManifold(constraint)
        self.checker = checker or ValidityChecker(robot, scene, margin=self.options.margin)
        self.name = "oc_rrt_connect" if self.options.connect else "oc_rrt"
        self._valid = self.checker.is_valid
        o = self.options
        paper = o.variant == "paper"
        self._refine = 0 if paper else (o.refine_depth if o.refine_depth is not None else (0 if o.connect else 3))
        self._extend = o.extend_to_sample and not paper
        self._goal_from_new = o.goal_from_new and not paper
        self._goal_region = o.goal_region_bias > 0 and not paper
        self._bridge = o.bridge_bias > 0 and not paper
        self._goal_from_region = self._goal_region and o.goal_from_region
        self._from_goal_region = False
        self._eager_cert = o.certified_edges and not o.certify_lazily
        self._lazy_cert = o.certified_edges and o.certify_lazily
        self._cert_done: dict[int, set[int]] = {}
        names = list(robot.joint_names)
        unknown = [n for n in o.goal_turn_joints if n not in names]
        if unknown:
            raise ConfigurationError(f"OCRRTOptions.goal_turn_joints: {unknown} are not joints of {robot.name!r} "
                                     f"(joints: {names})")
        self._span = self.manifold.upper - self.manifold.lower   # what rng.uniform(lower, upper) scales by
        self._turn_idx = np.array([] if paper else [names.index(n) for n in o.goal_turn_joints], dtype=int)

    # ------------------------------------------------------------------ manifold moves
    def sample(self, rng: np.random.Generator, st: dict[str, Any]) -> tuple[np.ndarray, np.ndarray] | None:
        """Alg. 1: a configuration on the manifold from uniformly drawn parameters."""
        mf = self.manifold
        lo, span, n = mf.lower, self._span, mf.dim
        for _ in range(self.options.max_sample_tries):
            st["samples"] += 1
            p = lo + span * rng.random(n)      # = rng.uniform(lo, hi), same draws, ~20x less overhead
            q = mf.complete(p, rng=rng)
            if q is not None:
                return q, p
            st["sample_failures"] += 1
        return None

    def _advance(self, q: np.ndarray, pa: np.ndarray, pb: np.ndarray, depth: int, check: bool, st: dict[str, Any],
                 trace: list[Any] | None = None) -> np.ndarray | None:
        """The configuration at parameters ``pb`` followed from ``q`` (at ``pa``) on q's branch:
        rejected when the parameters have no solution, when a joint moves more than
        ``max_joint_step`` (after up to ``depth`` bisections of the parameter step) or, with
        ``check``, when it (or a bisection point) is in collision. None when rejected.
        ``trace`` receives the bisection points, in order."""
        o = self.options
        x, dq = self.manifold.complete_step(pb, q)
        if x is None:
            st["ik_rejects"] += 1
            return None
        if dq > o.max_joint_step:
            if depth <= 0:
                st["jump_rejects"] += 1
                return None
            st["refinements"] += 1
            pm = 0.5 * (pa + pb)
            y = self._advance(q, pa, pm, depth - 1, check, st, trace)
            if y is None:
                return None
            if trace is not None:
                trace.append(y)
            return self._advance(y, pm, pb, depth - 1, check, st, trace)
        if check and not self._valid(x):
            st["collisions"] += 1
            return None
        return x

    def _goal_region_sample(self, rng: np.random.Generator, st: dict[str, Any], p_goal: np.ndarray,
                            q_goal: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """A sample within ``goal_region_radius`` of the goal's parameters, on the goal's branch."""
        mf, r = self.manifold, self.options.goal_region_radius
        lo, hi, n = mf.lower, mf.upper, p_goal.size
        for _ in range(self.options.max_sample_tries):
            st["samples"] += 1
            # = np.clip(p_goal + rng.uniform(-r, r, n), lo, hi): same draws and values
            p = np.minimum(np.maximum(p_goal + (-r + (r + r) * rng.random(n)), lo), hi)
            q = mf.complete(p, ref=q_goal)
            if q is not None:
                return q, p
            st["sample_failures"] += 1
        return None

    def _bridge_sample(self, rng: np.random.Generator, st: dict[str, Any]) -> tuple[np.ndarray, np.ndarray] | None:
        """Bridge test: the midpoint of two colliding configurations ``bridge_sigma`` apart, if free."""
        mf, o = self.manifold, self.options
        for _ in range(o.max_sample_tries):
            s1 = self.sample(rng, st)
            if s1 is None or self._valid(s1[0]):
                continue
            p2 = np.clip(s1[1] + rng.normal(0.0, o.bridge_sigma, s1[1].size), mf.lower, mf.upper)
            q2 = mf.complete(p2, ref=s1[0])
            if q2 is None or self._valid(q2):
                continue
            pm = 0.5 * (s1[1] + p2)
            qm = mf.complete(pm, ref=s1[0])
            if qm is not None and self._valid(qm):
                st["bridge_samples"] += 1
                return qm, pm
        return None

    def _walk(self, q0: np.ndarray, p0: np.ndarray, p1: np.ndarray, st: dict[str, Any], d: np.ndarray | None = None,
              dist: float | None = None) -> np.ndarray | None:
        """Configurations from q0 (parameters p0) to parameters p1 along the parameter line, every
        ``collision_step``, each completed on the branch of its predecessor, continuity- and
        collision-checked. Returns the last configuration, or None. ``d``, ``dist``: ``p1 - p0``
        and its max-norm when the caller has them."""
        if d is None or dist is None:
            d = p1 - p0
            dist = _maxabs(d)
        n = max(1, int(math.ceil(dist / self.options.collision_step)))
        q, pa = q0, p0
        for k in range(1, n + 1):
            pb = p0 + (k / n) * d if k < n else p1
            qn = self._advance(q, pa, pb, self._refine, True, st)
            if qn is None:
                return None
            q, pa = qn, pb
        return q

    def oc_steer(self, tree: _ParamTree, i_near: int, p_target: np.ndarray, st: dict[str, Any]) -> tuple[int, int]:
        """One OCSteer step from node i_near toward the parameters p_target."""
        p0 = tree.P[i_near]
        d = p_target - p0
        dist = _maxabs(d)
        if dist < 1e-15:
            return REACHED, i_near
        if dist <= self.options.step:
            p1 = p_target
            q1 = self._walk(tree.X[i_near], p0, p1, st, d, dist)   # p1 - p0 is d
        else:
            p1 = p0 + (self.options.step / dist) * d
            q1 = self._walk(tree.X[i_near], p0, p1, st)
        if q1 is None or (self._eager_cert and not self._certified(tree.X[i_near], p0, q1, p1, st)):
            return TRAPPED, i_near
        j = tree.add(q1, i_near, P=p1)
        return (REACHED if p1 is p_target else ADVANCED), j

    def _branch_certified(self, tree: _ParamTree, i: int, st: dict[str, Any]) -> bool:
        """Lazy certification: every not yet certified edge from the root to node i (root side
        first); the first failing edge's node is removed with its subtree."""
        done = self._cert_done.setdefault(id(tree), set())
        chain = []
        while i > 0 and i not in done:
            chain.append(i)
            i = int(tree.parent[i])
        for k in reversed(chain):
            j = int(tree.parent[k])
            if not self._certified(tree.X[j], tree.P[j], tree.X[k], tree.P[k], st):
                st["certify_removed_nodes"] += tree.kill(k)
                return False
            done.add(k)
        return True

    def _turns(self, q: np.ndarray, q_goal: np.ndarray) -> np.ndarray | None:
        """Whole turns k on ``goal_turn_joints`` with ``q = q_goal + 2πk`` there (and q = q_goal
        elsewhere, to ``reach_tolerance``), or None."""
        d = q - q_goal
        k = np.round(d[self._turn_idx] / (2.0 * math.pi))
        d[self._turn_idx] -= 2.0 * math.pi * k
        return k if _maxabs(d) <= self.options.reach_tolerance else None

    def connect(self, tree: _ParamTree, q_target: np.ndarray, p_target: np.ndarray, st: dict[str, Any], deadline: Deadline,
                start: int | None = None,
                goal: bool = False) -> tuple[int, int]:
        """Steer repeatedly toward ``p_target`` from node ``start`` (default: the node nearest
        ``q_target``) until it is reached on ``q_target``'s branch (``goal``: or on a
        whole-turn equivalent, see ``goal_turn_joints``) or the steer is trapped."""
        i = tree.nearest(q_target) if start is None else int(start)
        while not deadline.expired():
            res, i = self.oc_steer(tree, i, p_target, st)
            if res == REACHED:
                if _maxabs(tree.X[i] - q_target) <= self.options.reach_tolerance:
                    return REACHED, i
                if goal and self._turn_idx.size and self._turns(tree.X[i], q_target) is not None:
                    return REACHED, i
                return TRAPPED, i     # same parameters, other IK branch
            if res == TRAPPED:
                return TRAPPED, i
        return TRAPPED, i

    def _draw(self, rng: np.random.Generator, st: dict[str, Any], p_goal: np.ndarray,
              q_goal: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The single tree's sample: goal-region, bridge or uniform (Alg. 1)."""
        o = self.options
        if self._goal_region and rng.random() < o.goal_region_bias:
            self._from_goal_region = True
            return self._goal_region_sample(rng, st, p_goal, q_goal)
        self._from_goal_region = False
        if self._bridge and rng.random() < o.bridge_bias:
            return self._bridge_sample(rng, st)
        return self.sample(rng, st)

    # ------------------------------------------------------------------ main loop
    def _check_endpoint(self, q: np.ndarray, which: str) -> str | None:
        if not self.checker.in_limits(q):
            return f"{which} outside the joint limits"
        eo, ep = self.constraint.errors(q)
        if max(eo, ep) > 1e-9:
            return f"{which} off the orientation-constraint manifold (errors {eo:.1e} rad, {ep:.1e} m)"
        if not self.checker.is_valid(q):
            return f"{which} in collision"
        return None

    def _plan(self, q_start: np.ndarray, q_goal: np.ndarray, deadline: Deadline, rng: np.random.Generator, seed: int) -> PlanResult:
        o, mf = self.options, self.manifold
        st: dict[str, Any] = {"iterations": 0, "samples": 0, "sample_failures": 0, "steer_rejects": 0, "collisions": 0,
              "ik_rejects": 0, "jump_rejects": 0, "refinements": 0, "goal_attempts": 0, "bridge_samples": 0,
              "certified_edges": 0, "certify_rejects": 0, "certify_removed_nodes": 0}
        self._cert_done = {}
        c0, n0 = self.checker.n_checks, mf.n_complete
        for which, q, status in (("start", q_start, PlanStatus.INVALID_START), ("goal", q_goal, PlanStatus.INVALID_GOAL)):
            msg = self._check_endpoint(q, which)
            if msg:
                return self.empty_result(status, msg, **st)
        ps, pg = mf.params(q_start), mf.params(q_goal)
        ta = _ParamTree(q_start, 512, P=ps)
        tb = _ParamTree(q_goal, 512, P=pg) if o.connect else None
        a_is_start, found = True, cast(tuple[int, int | None] | None, None)
        while not deadline.expired():
            if o.max_iterations and st["iterations"] >= o.max_iterations:
                break
            st["iterations"] += 1
            if not o.connect:
                start: int | None = -1  # -1: no goal attempt; None: from the node nearest the goal
                if rng.random() < o.goal_bias:
                    start = None
                elif (s := self._draw(rng, st, pg, q_goal)) is not None:
                    i_near = ta.nearest(s[0])
                    if self._extend:
                        res, j = self.connect(ta, s[0], s[1], st, deadline, start=i_near)
                        grew = j != i_near
                    else:
                        res, j = self.oc_steer(ta, i_near, s[1], st)
                        grew = res != TRAPPED
                    if self._goal_from_region and grew and self._from_goal_region:
                        start = j     # a node grown toward the goal region: try the goal from it
                    elif self._goal_from_new and grew and rng.random() < o.goal_bias:
                        # also from the node just added: the node nearest the goal can sit behind
                        # an obstacle for good, a new node elsewhere may see past it
                        start = j
                if start != -1:
                    st["goal_attempts"] += 1
                    res, i = self.connect(ta, q_goal, pg, st, deadline, start=start, goal=True)
                    if res == REACHED and (not self._lazy_cert or self._branch_certified(ta, i, st)):
                        found = (i, None)
                        break
                continue
            s = self.sample(rng, st)
            if s is None:
                continue
            res, i_a = self.oc_steer(ta, ta.nearest(s[0]), s[1], st)
            assert tb is not None  # RRT-Connect grows two trees
            if res != TRAPPED:
                res_b, i_b = self.connect(tb, ta.X[i_a], ta.P[i_a], st, deadline)
                if res_b == REACHED and (not self._lazy_cert or (self._branch_certified(ta, i_a, st)
                                                                 & self._branch_certified(tb, i_b, st))):
                    found = (i_a, i_b)
                    break
            ta, tb, a_is_start = tb, ta, not a_is_start
        st["steer_rejects"] = st["ik_rejects"] + st["jump_rejects"]
        st["nodes"] = ta.n + (tb.n if tb is not None else 0)
        st["collision_checks"] = self.checker.n_checks - c0
        st["ik_completions"] = mf.n_complete - n0
        if found is None:
            if deadline.expired():
                return self.empty_result(PlanStatus.TIMEOUT, "time limit reached", **st)
            return self.empty_result(PlanStatus.FAILED, "iteration cap reached", **st)
        if not o.connect:
            path = ta.branch(found[0])
        else:
            assert tb is not None and found[1] is not None
            path = joined_path(ta, found[0], tb, found[1], a_is_start)
        P = np.array(path)
        P[0], P[-1] = q_start, q_goal
        if not o.connect and self._turn_idx.size:
            k = self._turns(ta.X[found[0]].copy(), q_goal)
            if k is not None and np.any(k != 0):
                P[-1, self._turn_idx] += 2.0 * math.pi * k
                st["goal_turns"] = {self.robot.joint_names[j]: int(v) for j, v in zip(self._turn_idx, k) if v}
        return PlanResult(PlanStatus.EXACT, self.name, P, [None] * len(P), np.ones(len(P), bool),
                          [PathSegment("constrained", 0, len(P) - 1)], st)

    # ------------------------------------------------------------------ dense path
    def densify(self, path: np.ndarray, resolution: float = 0.01) -> np.ndarray:
        """The path resampled every ``resolution`` [rad] of parameter motion (and where the planner
        bisected a fast step, ``refine_depth``, at the bisection points as well), every
        configuration completed on the manifold on the branch of its predecessor (the planner's
        own edges): no joint moves more than ``max_joint_step`` between neighbours. At
        ``resolution = certify_resolution`` (0.01) and with ``certified_edges`` these are the
        configurations whose chord path (straight joint segments between them) was certified
        collision-free. Raises ValueError if an edge cannot be followed (a path not made by this
        planner)."""
        if not (resolution > 0):
            raise ValueError(f"resolution: expected a positive number of radians, got {resolution!r}")
        path = np.asarray(path, float)
        mf = self.manifold
        out = [path[0]]
        for a, b in zip(path[:-1], path[1:]):
            pts = self._follow(a, mf.params(a), mf.params(b), resolution)
            if isinstance(pts, str):
                raise ValueError(f"densify: {pts}")
            if float(np.abs(pts[-1] - b).max()) > 1e-8:
                raise ValueError(f"densify: the edge ends on another IK branch ({np.abs(pts[-1] - b).max():.2e} rad)")
            pts[-1] = b
            out += pts
        return np.array(out)

    def _follow(self, a: np.ndarray, pa: np.ndarray, pb: np.ndarray, resolution: float) -> list[np.ndarray] | str:
        """The manifold edge from ``a`` (parameters ``pa``) to parameters ``pb`` every ``resolution``
        [rad] of parameter motion (and at the bisection points of fast steps), each configuration
        completed on the branch of its predecessor; ``a`` excluded. A message when it cannot be
        followed."""
        n = max(1, int(math.ceil(float(np.abs(pb - pa).max()) / resolution)))
        q, p_prev, out = a, pa, []  # type: np.ndarray, np.ndarray, list[Any]
        st = {"ik_rejects": 0, "jump_rejects": 0, "refinements": 0}
        for k in range(1, n + 1):
            pk = pa + (k / n) * (pb - pa)
            x = self._advance(q, p_prev, pk, self._refine, False, st, out)
            if x is None:
                return f"the manifold edge cannot be followed at step {k}/{n}"
            out.append(x)
            q, p_prev = x, pk
        return out

    def _certified(self, q0: np.ndarray, p0: np.ndarray, q1: np.ndarray, p1: np.ndarray, st: dict[str, Any]) -> bool:
        """``certified_edges``: the chord path through the edge's configurations every
        ``certify_resolution`` (what :meth:`densify` returns at that resolution) certified
        collision-free (:meth:`.ValidityChecker.path_is_certified`)."""
        o = self.options
        pts = self._follow(q0, p0, p1, o.certify_resolution)
        st["certified_edges"] += 1
        if isinstance(pts, str) or _maxabs(pts[-1] - q1) > 1e-8:
            st["certify_rejects"] += 1
            return False
        pts[-1] = q1
        if not self.checker.path_is_certified(np.array([q0, *pts]), "held", min_clearance=o.edge_min_clearance):
            st["certify_rejects"] += 1
            return False
        return True
