"""Options of :class:`~optplan.planners.tcbirrt.TCBiRRT`: the paper's configuration, the improved
variant's values (:data:`VARIANTS`), and the sampling box scaled to a robot's reach."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import cast

import numpy as np

from ..constraints.closed_chain import IKSettings
from ..model.robot import RobotModel
from .cbirrt2 import CBiRRT2Options
from .ik_seed import PREDICTORS
from .rrtconnect import RRTConnectOptions

__all__ = ["TCBiRRTOptions", "VARIANTS", "PAPER_XI_LOWER", "PAPER_XI_UPPER", "PAPER_REACH", "reach_scaled_workspace"]

PAPER_XI_LOWER = (-2.0, -3.0, 0.0, -math.pi, -math.pi, -math.pi)
PAPER_XI_UPPER = (2.0, 3.0, 4.0, math.pi, math.pi, math.pi)
#: option values of each variant (fields left at None take them)
VARIANTS = {
    "paper": {"goal_bias": 0.0, "sample_filter": False, "bridge_probability": 0.0, "keep_prefix": False,
              "guide_probability": 0.0, "geodesic_probability": 0.0, "ik_restarts": 0,
              "edge_tolerance": 0.0, "lazy_edges": False, "joint_connect": False, "max_joint_step": 0.5,
              "regrasp_share_orders": False, "verify_path": False, "branch_grafts": 0, "frontier_grafts": 0,
              "regrasp_both_arms": False, "regrasp_backoff": False, "lead_orientation_probability": 0.0,
              "branch_roots": False, "stall_iterations": 0, "trap_grafts": 0, "restart_iterations": 0,
              "restart_branch_roots": False, "filter_robot_body": False, "ik_predictor": "none",
              "trap_graft_target": "other", "trap_graft_stream": "search", "trap_graft_after": 0,
              "ik_restart_iterations": 0, "ik_restart_clip": False, "trap_adapt": "off", "domain_radius": 1.0,
              "regrasp_balance": 0.0},
    "improved": {"goal_bias": 0.1, "sample_filter": True, "bridge_probability": 0.0, "keep_prefix": True,
                 "guide_probability": 0.4, "geodesic_probability": 0.5, "ik_restarts": 2,
                 "edge_tolerance": 0.01, "lazy_edges": False, "joint_connect": False, "max_joint_step": 0.25,
                 "regrasp_share_orders": False, "verify_path": True, "branch_grafts": 4, "frontier_grafts": 4,
                 "regrasp_both_arms": False, "regrasp_backoff": False, "lead_orientation_probability": 0.5,
                 "branch_roots": False, "stall_iterations": 0, "trap_grafts": 4, "restart_iterations": 0,
                 "restart_branch_roots": False, "filter_robot_body": False, "ik_predictor": "none",
                 "trap_graft_target": "sample", "trap_graft_stream": "own", "trap_graft_after": 1500,
                 "ik_restart_iterations": 0, "ik_restart_clip": False, "trap_adapt": "off", "domain_radius": 1.0,
                 "regrasp_balance": 1.0},
}


def _pos(name: str, v: object, allow_zero: bool = False) -> None:
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        raise ValueError(f"TCBiRRTOptions.{name}: expected a {'non-negative' if allow_zero else 'positive'} number, got {v!r}")


@dataclass(frozen=True)
class TCBiRRTOptions:
    """Options of :class:`TCBiRRT` (the paper's defaults; the module docstring explains the deviations).

    ``variant`` selects ``"paper"`` (Alg. 1-4 as published, the default) or ``"improved"``; fields left
    at None take the variant's value (:data:`VARIANTS`), an explicit value overrides it.
    """

    #: s_ξ of Eq. 3: largest task-space step of an extension [mixed m / rad, as the paper's ξ].
    step_size: float = 0.6
    #: N of Eq. 4: object poses per extension [count].
    n_interp: int = 5
    #: ξ_l: lower corner of the sampling box (x, y, z [m], roll, pitch, yaw [rad]; world = base frame).
    xi_lower: tuple[float, ...] = PAPER_XI_LOWER
    #: ξ_h: upper corner of the sampling box (x, y, z [m], roll, pitch, yaw [rad]).
    xi_upper: tuple[float, ...] = PAPER_XI_UPPER
    #: Alg. 4's IK settings (ε_p, ε_o, n, K·λ).
    ik: IKSettings = field(default_factory=IKSettings)
    #: A waypoint whose IK solution jumps by more than this from the previous one fails [rad] (``inf``: off;
    #: None: the variant's value, :data:`VARIANTS`: paper 0.5, improved 0.25).
    max_joint_step: float | None = None
    #: ``"geodesic"`` (Eq. 4 on the relative rotation) or ``"absolute"`` (the literal Eq. 4 on unwrapped
    #: exponential coordinates).
    interpolation: str = "geodesic"
    #: Check the straight joint-space segments between consecutive configurations every this many radians [rad]
    #: (None: only the N+1 configurations, as the paper).
    edge_resolution: float | None = None
    #: Check edges so densely that no point of the arms or object moves farther than this between two checks [m]
    #: (0: off; None: the variant's value, :data:`VARIANTS`: paper 0, improved 0.01).
    edge_tolerance: float | None = None
    #: Check constrained edges only once they lie on a start-goal path (lazy collision checking) (None: the
    #: variant's value, :data:`VARIANTS`).
    lazy_edges: bool | None = None
    #: The bound that spaces the ``edge_tolerance`` checks: ``"jacobian"`` (each geometry's speed from the Jacobian
    #: plus a second-order remainder) or ``"static"`` (the configuration-free per-geometry bound); both conservative;
    #: or ``"certified"``: every edge certified collision-free at every point (conservative advancement on exact
    #: distances, :meth:`.ValidityChecker.edge_is_certified`; ``edge_tolerance`` > 0 only switches the checks on).
    edge_bound: str = "jacobian"
    #: ``edge_bound="certified"``: an edge is rejected where the exact clearance drops below this, and a certified
    #: edge keeps every pair at least half of it apart [m].
    edge_min_clearance: float = 1e-3
    #: Re-check a found path's edges at the configuration-free bound's uniform spacing (the benchmark's); a
    #: failing edge removes its subtree and the search goes on (None: the variant's value, :data:`VARIANTS`).
    verify_path: bool | None = None
    #: Join the trees in joint space (CBiRRT2's ConstrainedExtend) when the task-space connection cannot (None:
    #: the variant's value, :data:`VARIANTS`); see docs/decisions/0004-tcbirrt-improved-variant.md.
    joint_connect: bool | None = None
    #: The joint-space connection is tried when a connect step is trapped within this ξ distance of the other
    #: tree's node [mixed m / rad].
    joint_connect_radius: float = 1.0
    #: The joint-space connection is tried only when the two configurations are within this Euclidean joint distance [rad] (farther ones are
    #: other IK branches).
    joint_connect_max_distance: float = 2.0
    #: CBiRRT2 options of the joint-space connection.
    joint_connect_options: CBiRRT2Options = field(default_factory=lambda: CBiRRT2Options(max_edge=0.3, collision_step=0.1,
                                                                                         tolerance=1e-8))
    #: RRTConnect options of a regrasp motion (one arm, 7-D, object fixed).
    regrasp: RRTConnectOptions = field(default_factory=lambda: RRTConnectOptions(range=1.0, resolution=0.03,
                                                                                 shortcut_iterations=50, balance=0.0))
    #: Time limit per regrasp attempt [s]: a backstop of ``regrasp_iterations`` (docs/planners.md, "Reproducible searches").
    regrasp_time_limit: float = 20.0
    #: Work budget of one regrasp: RRT-Connect iterations of its motions, shared by the arm orders as the time is
    #: [count] (0: none, the time limit alone). It ends the regrasp at the same point on any machine and load.
    regrasp_iterations: int = 15000
    #: A regrasp motion's RRT-Connect gives up when one of its two trees has added no node for this many
    #: iterations [count] (0: ``regrasp.stall_iterations``, by default never): the moving arm's start or goal is
    #: walled in, and the search would otherwise spend the whole ``regrasp_time_limit`` (or ``graft_time_limit``)
    #: failing; the counter ``regrasp_stalled`` counts such motions.
    regrasp_stall_iterations: int = 0
    #: Tree balancing of the regrasp motions' RRT-Connect (:attr:`.RRTConnectOptions.balance`, VAMP's tree ratio: the
    #: tree that just grew grows again while the other has at least this many times its nodes more; 0: the trees
    #: alternate) when ``regrasp.balance`` is 0 [-] (None: the variant's value, :data:`VARIANTS`). A motion whose one
    #: end sits in a narrow place (a hand at the object) then spends its samples on that end's smaller tree.
    regrasp_balance: float | None = None
    #: When neither one-arm-at-a-time order of a regrasp passes, move both arms at once (RRTConnect in the two
    #: arms' joints, the object standing still at its pose: a released object in orbit stays where it is), in
    #: what is left of the regrasp's time (None: the variant's value, :data:`VARIANTS`: off in both; a path with such a
    #: motion has a ``"regrasp"`` segment whose ``arm`` is :data:`.BOTH_ARMS`).
    regrasp_both_arms: bool | None = None
    #: Halve a regrasp's time limit after each failed regrasp of the query, down to ``regrasp_min_time_limit``; a
    #: successful regrasp restores ``regrasp_time_limit`` (None: the variant's value: off in both; see docs/generalization.md).
    regrasp_backoff: bool | None = None
    #: Smallest regrasp time limit of ``regrasp_backoff`` [s] (a backstop of ``regrasp_min_iterations``).
    regrasp_min_time_limit: float = 0.5
    #: Smallest regrasp work budget of ``regrasp_backoff`` (halved with the time limit) [count].
    regrasp_min_iterations: int = 380
    #: An arm whose two solutions differ by less than this (max-norm) does not move [rad].
    regrasp_tolerance: float = 1e-4
    #: The two arm orders of a regrasp (A first, B first) each get an equal share of ``regrasp_time_limit``
    #: instead of the first order using all it needs (None: the variant's value: off in both, see
    #: docs/planners.md).
    regrasp_share_orders: bool | None = None
    #: Grow up to this many other IK branches into each tree [count] (None: the variant's value, :data:`VARIANTS`):
    #: a node's object pose is solved by IK seeded from the other tree's configuration nearest in ξ, and, when
    #: that solution lies on another branch, the arms regrasp to it (object fixed) and it becomes a node of the
    #: same tree; a connection then prefers the node whose configuration is nearest the other tree's.
    branch_grafts: int | None = None
    #: Iterations between two branch-graft attempts (each tree's first attempt is at its root) [count].
    graft_interval: int = 100
    #: Iterations of the search before the first branch graft [count] (0: from the start); a query solved sooner
    #: is untouched by grafts.
    graft_after: int = 1500
    #: Try a graft at both roots before the search (with ``graft_after`` 0) (instead of after the first ``graft_interval`` iterations,
    #: which leaves queries solved quickly without grafts untouched) [bool].
    root_grafts_first: bool = True
    #: Time limit of one graft's regrasp (branch, frontier, trap and root grafts) [s]: a backstop of ``graft_iterations``.
    graft_time_limit: float = 5.0
    #: Work budget of one graft's regrasp: RRT-Connect iterations [count] (0: none, the time limit alone).
    graft_iterations: int = 3800
    #: IK seeds per branch-graft attempt (the other tree's configuration, then perturbed by ``ik_restart_sigma``) [count].
    graft_seeds: int = 4
    #: A graft may also move one arm only to its new IK solution (the other keeps its own) [bool].
    graft_single_arm: bool = False
    #: A branch graft does not regrasp from a node to a joint solution within ``graft_min_distance`` of one whose
    #: regrasp from that node already failed (the same branch: the same search again, which fails again at
    #: ``graft_time_limit``); counted as ``graft_repeats_skipped`` [bool] (on by a rule stated before its measurement:
    #: decision 0019, addendum 2026-11-29).
    graft_skip_failed: bool = True
    #: Seed a graft's IK first with the other tree's branches — its root's configuration and its own grafts' — before
    #: the configuration nearest in ξ (the other tree's branch is usually free away from where the trees meet, where
    #: the nearest configuration's IK solution collides) [bool].
    graft_branch_seeds: bool = False
    #: Which node a branch graft is tried at: ``"meet"`` (the node nearest a random node of the other tree: where the
    #: trees meet), ``"any"`` (a random live node of the tree) or ``"mixed"`` (either, with equal probability).
    graft_node: str = "meet"
    #: Frontier grafts per tree [count] (None: the variant's value, :data:`VARIANTS`; 0: off): at the node nearest the
    #: other tree, the arms re-grasp into an IK solution from which one constrained step toward the other tree
    #: passes (:mod:`.frontier_graft`); tried every ``frontier_interval`` iterations after ``graft_after``.
    frontier_grafts: int | None = None
    #: Iterations between two frontier-graft attempts (the trees take turns) [count].
    frontier_interval: int = 50
    #: A frontier graft is also tried, at any iteration, when the trees have stopped approaching: the smallest
    #: ξ distance a connection has left between them (0 when it reached the other tree's pose but its regrasp
    #: failed) has not shrunk by 1 % for this many iterations [count] (None: the variant's value,
    #: :data:`VARIANTS`: 0 in both, see docs/planners.md; 0: off). The count restarts after each such attempt.
    stall_iterations: int | None = None
    #: Before the search, re-grasp the goal tree's root onto the start's IK branch at the goal pose (arm by arm; the
    #: branch found by path IK along the straight start-goal object motion), or, where that configuration
    #: collides, the start tree's root onto the goal's branch; the tree then grows from that branch, so that the
    #: trees can meet without a regrasp (None: the variant's value, :data:`VARIANTS`: False in both, see
    #: docs/planners.md).
    branch_roots: bool | None = None
    #: Trap grafts per tree [count] (None: the variant's value, :data:`VARIANTS`: paper 0, improved 4, see
    #: docs/generalization.md; 0: off): when the extension from one
    #: node of the tree growing toward a sample has been trapped ``trap_graft_count`` times, the arms re-grasp at that
    #: node into an IK solution from which one constrained step passes (the look-ahead
    #: graft of :mod:`.frontier_graft`; toward ``trap_graft_target``), at any iteration; each node is tried once.
    trap_grafts: int | None = None
    #: Trapped extensions from one node that trigger its trap graft [count].
    trap_graft_count: int = 20
    #: The look-ahead step of a trap graft goes toward ``"other"`` (the other tree's node nearest in ξ: where the trees
    #: must meet) or ``"sample"`` (the sample that trapped the extension) (None: the variant's value, :data:`VARIANTS`:
    #: paper ``"other"``, improved ``"sample"``).
    trap_graft_target: str | None = None
    #: Iterations before which no trap graft is attempted and no trapped extension is counted for one [count]
    #: (None: the variant's value, :data:`VARIANTS`: paper 0, improved 1500 = ``graft_after``; 0: from the first
    #: iteration). A search that ends by then is identical to ``trap_grafts=0``.
    trap_graft_after: int | None = None
    #: The random streams a trap-graft attempt draws from (its IK seeds, look-ahead restarts and regrasp): ``"search"``
    #: (the search's own) or ``"own"`` (each tree's own, seeded by the query's seed): then a failed attempt leaves the
    #: search as it was, and a search whose attempts all fail is ``trap_grafts=0``'s, plus the attempts' CPU (None: the
    #: variant's value, :data:`VARIANTS`: paper ``"search"``, improved ``"own"``).
    trap_graft_stream: str | None = None
    #: Random IK seeds per frontier-graft (and trap-graft) attempt [count].
    frontier_seeds: int = 6
    #: Random node pairs of which a frontier graft takes the closest in ξ [count].
    frontier_pairs: int = 8
    #: A frontier graft is tried only when that closest pair is at most this far apart in ξ [m and rad, as ξ]
    #: (0: at any distance).
    frontier_radius: float = 0.0
    #: A graft's joint solution must differ from its node's by at least this (Euclidean) [rad]; nearer ones are the
    #: same branch.
    graft_min_distance: float = 1.5
    #: Start and goal must satisfy the closed chain to this (position [m] and angle [rad]).
    closure_tolerance: float = 1e-6
    #: Clearance counted as contact [m].
    margin: float = 0.0
    #: Backend of the boolean collision checks and of the task-space filter's object test: ``"native"``
    #: (the compiled planning kernel, :mod:`optplan.planners.kernel`; coal when it cannot be built) or
    #: ``"coal"`` (Pinocchio + coal).
    validity_kernel: str = "native"
    #: Where an iteration runs: ``"loop"`` (compiled code for the sampler — task-space draws, filter, bridge
    #: tests, goal bias, lead-path poses — fused with the nearest-neighbour search, the object lead path, and each
    #: extension with its IK restarts; the random draws of these from a native generator seeded by the
    #: planner's, so a seed gives another search than ``"python"``'s), ``"native"`` (one call into compiled code
    #: per extension and per filter test, :mod:`.tcbirrt_native`; the sampler and restarts in Python on the
    #: planner's generator: the same search as ``"python"``) or ``"python"``. Without a compiler or with
    #: ``validity_kernel="coal"`` the Python code runs.
    extension: str = "loop"
    #: With ``extension="loop"``: run series of iterations in one native call (:mod:`.tcbirrt_streak`): trapped
    #: extensions, advanced ones with their node and tree b's connection, the twins' draws; and every connection
    #: in one native call too. The same search as without, faster on hard scenes. False: one call per step.
    streaks: bool = True
    #: Cap on Alg. 1 iterations [count] (0: only the time limit), over all restarts.
    max_iterations: int = 0
    #: Restart the search from the two roots (new trees; the lead path kept; the query's random stream going on)
    #: when it has run this many iterations without a path [count] (None: the variant's value, :data:`VARIANTS`:
    #: 0 (off) in both; 5000 measured on fresh generated scenes and left off, see docs/planners.md). A restart cuts
    #: the heavy tail of one query's search times across random streams, and loses searches that needed more.
    restart_iterations: int | None = None
    #: Each restart's iteration budget is the previous one's times this [-] (>= 1).
    restart_growth: float = 1.5
    #: Every second search after a restart (the 2nd, 4th, ...) runs with ``branch_roots`` the other way: a search
    #: whose roots sit on IK branches that cannot meet is followed by one whose roots share a branch, and the
    #: other way round (None: the variant's value, :data:`VARIANTS`: False in both).
    restart_branch_roots: bool | None = None
    #: The task-space filter — of the samples (``sample_filter``) and of the object's lead path — counts the robot's
    #: own body fixed to the world (a fixed base's geometry, :func:`.task_sampling.robot_body_obstacles`) as an
    #: obstacle of the object (None: the variant's value, :data:`VARIANTS`: False in both; measured on fresh generated
    #: scenes and the suite and left off, see docs/planners.md).
    filter_robot_body: bool | None = None
    #: ``"paper"`` (the published algorithm) or ``"improved"`` (task-space sampling aids).
    variant: str = "paper"
    #: Probability that ξ_rand is the pose of a random node of the other tree [-] (None: the variant's value,
    #: :data:`VARIANTS`): paper 0, improved 0.1.
    goal_bias: float | None = None
    #: Reject ξ_rand while the object alone collides or a grasp point is beyond its arm's reach (no IK;
    #: :mod:`.task_sampling`) (None: the variant's value, :data:`VARIANTS`).
    sample_filter: bool | None = None
    #: Probability of a bridge-test sample in ξ (object in collision at two nearby poses, free at their
    #: midpoint) [-] (None: the variant's value, :data:`VARIANTS`): 0 in both; see
    #: docs/decisions/0004-tcbirrt-improved-variant.md.
    bridge_probability: float | None = None
    #: Spread of the bridge test's second pose: (position [m], angle [rad]).
    bridge_sigma: tuple[float, float] = (0.3, 0.4)
    #: When PathInverseKinematics fails after ≥ 1 valid waypoint, keep the valid part as a shorter extension
    #: (None: the variant's value, :data:`VARIANTS`).
    keep_prefix: bool | None = None
    #: Probability that ξ_rand is a pose of the object's lead path plus Gaussian noise ``guide_sigma`` [-]
    #: (None: the variant's value, :data:`VARIANTS`): paper 0, improved 0.4.
    guide_probability: float | None = None
    #: Noise of a lead-path sample: (position [m], angle [rad]).
    guide_sigma: tuple[float, float] = (0.05, 0.05)
    #: Time spent on the object's lead path per query, at most [s]: a backstop of ``guide_iterations``.
    guide_time_limit: float = 30.0
    #: Time of one lead-path attempt (restarted while none is found) [s]: a backstop of ``guide_attempt_iterations``.
    guide_attempt_time: float = 3.0
    #: Work budget of the object's lead path per query: its RRT-Connect iterations [count] (0: none, the time alone).
    guide_iterations: int = 42000
    #: Work budget of one lead-path attempt: RRT-Connect iterations [count] (0: none, the time alone).
    guide_attempt_iterations: int = 4200
    #: Probability that a sample's orientation is drawn on the start-goal rotation geodesic, perturbed by
    #: ``geodesic_sigma`` [-] (None: the variant's value, :data:`VARIANTS`): paper 0, improved 0.5.
    geodesic_probability: float | None = None
    #: Perturbation of a geodesic orientation sample, per axis [rad].
    geodesic_sigma: float = 0.15
    #: Probability that a uniform sample's orientation is the lead path's orientation at the lead pose nearest in
    #: position, perturbed by ``geodesic_sigma`` (the orientation the passage there admits; once a lead path is
    #: known; before ``geodesic_probability``) [-] (None: the variant's value, :data:`VARIANTS`: paper 0, improved 0.5).
    lead_orientation_probability: float | None = None
    #: When a waypoint's IK solution collides or fails, retry IK this many times from the previous configuration
    #: perturbed by ``N(0, ik_restart_sigma²)`` [count] (None: the variant's value, :data:`VARIANTS`): paper 0,
    #: improved 2.
    ik_restarts: int | None = None
    #: Standard deviation of an IK restart's perturbation, per joint [rad].
    ik_restart_sigma: float = 0.3
    #: The iteration limit of a restart's IK [count]; 0: the IK's own ``ik.max_iterations`` (None: the variant's value,
    #: :data:`VARIANTS`: 0 in both). A restart is accepted only near the previous configuration: on three long searches
    #: of generated scenes (a bay, a wall, an overhang; 85,000-115,000 iterations) 5,043 of the 5,125 accepted restarts
    #: (98.4 %) had converged within 12 iterations, while 89,734 of 326,673 restarts ran to the IK's 30 without
    #: converging (2.7 of the queries' 8.3 million IK iterations). A limit of 12 was measured on 214 fresh generated
    #: scenes and left off: the same successes, CPU per iteration only 4.5 % lower (docs: planners page).
    ik_restart_iterations: int | None = None
    #: Clip each joint's offset of a restart's seed to ±``max_joint_step``, the bound an accepted solution must keep
    #: (the same draws). Unclipped, a seed's largest offset of N(0, 0.3²) over 14 joints mostly exceeds 0.25 rad, and
    #: about half the restarts converge beyond the bound and are refused. Measured on 211 fresh generated scenes and
    #: left off: the same successes (bays +3, walls -2), a fifth fewer iterations where both solve (docs: planners
    #: page). ``"first"``: a failing waypoint's first restart clipped, the later ones not; measured on 213 fresh
    #: generated scenes and left off: bays 34 → 32 of 35, the suite's bays and trusses about twice as fast (docs:
    #: planners page) (None: the variant's value, :data:`VARIANTS`: off in both).
    ik_restart_clip: bool | str | None = None
    #: The path IK's seed of a waypoint after the first (:mod:`.ik_seed`): ``"none"`` (the previous solution, Alg. 3)
    #: or ``"secant"`` (``q_{k−1} + (q_{k−1} − q_{k−2})`` clamped to the joint limits; the joint-jump bound stays
    #: relative to ``q_{k−1}``) (None: the variant's value, :data:`VARIANTS`).
    ik_predictor: str | None = None
    #: What a trapped extension changes at the node it started from: ``"off"``; ``"step"`` (adaptive step size:
    #: the node's s_ξ is halved, down to s_ξ/8, and doubled back after an extension that is not trapped); or
    #: ``"domain"`` (dynamic domain: from then on a sample farther than ``domain_radius`` · s_ξ from the node,
    #: when it is the nearest, is drawn again, up to ``domain_tries`` draws) (None: the variant's value,
    #: :data:`VARIANTS`).
    trap_adapt: str | None = None
    #: Dynamic-domain radius of a node after a trapped extension, in units of s_ξ [-] (None: the variant's value).
    domain_radius: float | None = None
    #: Draws per iteration with ``trap_adapt="domain"`` (the last one is extended toward regardless) [count].
    domain_tries: int = 10
    #: Scale the default box's position part and the step size by the robot's mean sampled arm reach
    #: (:func:`.task_sampling.arm_reach_estimate`) / :data:`PAPER_REACH_ESTIMATE` about its
    #: shoulders' midpoint (a box or step set explicitly is used as given).
    scale_to_reach: bool = True

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise ValueError(f"TCBiRRTOptions.variant: expected one of {tuple(VARIANTS)}, got {self.variant!r}")
        for name, v in VARIANTS[self.variant].items():   # None: the variant's value
            if getattr(self, name) is None:
                object.__setattr__(self, name, v)
        for name in ("goal_bias", "bridge_probability", "guide_probability", "geodesic_probability",
                     "lead_orientation_probability"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0.0 <= v <= 1.0):
                raise ValueError(f"TCBiRRTOptions.{name}: expected a probability in [0, 1], got {v!r}")
        if cast(float, self.goal_bias) + cast(float, self.bridge_probability) + cast(float, self.guide_probability) > 1.0:
            raise ValueError(f"TCBiRRTOptions: goal_bias + bridge_probability + guide_probability must be <= 1, "
                             f"got {self.goal_bias} + {self.bridge_probability} + {self.guide_probability}")
        for name in ("bridge_sigma", "guide_sigma"):
            bs = getattr(self, name)
            if not (isinstance(bs, (tuple, list)) and len(bs) == 2
                    and all(isinstance(x, (int, float)) and x > 0 for x in bs)):
                raise ValueError(f"TCBiRRTOptions.{name}: expected (position [m], angle [rad]) > 0, got {bs!r}")
            object.__setattr__(self, name, (float(bs[0]), float(bs[1])))
        _pos("guide_time_limit", self.guide_time_limit)
        _pos("guide_attempt_time", self.guide_attempt_time)
        _pos("geodesic_sigma", self.geodesic_sigma)
        _pos("ik_restart_sigma", self.ik_restart_sigma)
        if self.trap_adapt not in ("off", "step", "domain"):
            raise ValueError(f"TCBiRRTOptions.trap_adapt: expected 'off', 'step' or 'domain', got {self.trap_adapt!r}")
        _pos("domain_radius", self.domain_radius)
        if not isinstance(self.streaks, bool):
            raise ValueError(f"TCBiRRTOptions.streaks: expected True or False, got {self.streaks!r}")
        if not (isinstance(self.domain_tries, int) and not isinstance(self.domain_tries, bool) and self.domain_tries >= 1):
            raise ValueError(f"TCBiRRTOptions.domain_tries: expected an int >= 1, got {self.domain_tries!r}")
        if not (isinstance(self.ik_restarts, int) and not isinstance(self.ik_restarts, bool) and self.ik_restarts >= 0):
            raise ValueError(f"TCBiRRTOptions.ik_restarts: expected an int >= 0, got {self.ik_restarts!r}")
        if not (isinstance(self.ik_restart_clip, bool) or self.ik_restart_clip == "first"):
            raise ValueError(f"TCBiRRTOptions.ik_restart_clip: expected True, False or 'first', got "
                             f"{self.ik_restart_clip!r}")
        if not (isinstance(self.ik_restart_iterations, int) and not isinstance(self.ik_restart_iterations, bool)
                and self.ik_restart_iterations >= 0):
            raise ValueError(f"TCBiRRTOptions.ik_restart_iterations: expected an int >= 0 (0: the IK's own limit), got "
                             f"{self.ik_restart_iterations!r}")
        for name in ("regrasp_stall_iterations", "branch_grafts", "graft_after", "graft_interval", "graft_seeds",
                     "frontier_grafts", "frontier_interval", "frontier_seeds", "frontier_pairs", "stall_iterations", "trap_grafts", "trap_graft_count",
                     "restart_iterations"):
            v, low = getattr(self, name), (0 if name in ("regrasp_stall_iterations", "branch_grafts", "graft_after", "frontier_grafts", "stall_iterations",
                                                         "trap_grafts", "restart_iterations") else 1)
            if not (isinstance(v, int) and not isinstance(v, bool) and v >= low):
                raise ValueError(f"TCBiRRTOptions.{name}: expected an int >= {low}, got {v!r}")
        _pos("graft_time_limit", self.graft_time_limit)
        _pos("regrasp_balance", self.regrasp_balance, allow_zero=True)
        for name in ("regrasp_iterations", "regrasp_min_iterations", "graft_iterations", "guide_iterations",
                     "guide_attempt_iterations"):   # work budgets of sub-searches (0: none)
            if not (isinstance(getattr(self, name), int) and not isinstance(getattr(self, name), bool) and getattr(self, name) >= 0):
                raise ValueError(f"TCBiRRTOptions.{name}: expected an int >= 0 (iterations; 0: no budget), got {getattr(self, name)!r}")
        if not (isinstance(self.restart_growth, (int, float)) and not isinstance(self.restart_growth, bool)
                and math.isfinite(self.restart_growth) and self.restart_growth >= 1.0):
            raise ValueError(f"TCBiRRTOptions.restart_growth: expected a number >= 1, got {self.restart_growth!r}")
        if self.trap_graft_after is not None and not (isinstance(self.trap_graft_after, int)
                                                      and not isinstance(self.trap_graft_after, bool) and self.trap_graft_after >= 0):
            raise ValueError(f"TCBiRRTOptions.trap_graft_after: expected None or an int >= 0, got {self.trap_graft_after!r}")
        if self.trap_graft_stream not in ("search", "own"):
            raise ValueError(f"TCBiRRTOptions.trap_graft_stream: expected 'search' or 'own', got {self.trap_graft_stream!r}")
        if self.trap_graft_target not in ("other", "sample"):
            raise ValueError(f"TCBiRRTOptions.trap_graft_target: expected 'other' or 'sample', got {self.trap_graft_target!r}")
        if self.graft_node not in ("meet", "any", "mixed"):
            raise ValueError(f"TCBiRRTOptions.graft_node: expected 'meet', 'any' or 'mixed', got {self.graft_node!r}")
        _pos("graft_min_distance", self.graft_min_distance)
        _pos("frontier_radius", self.frontier_radius, allow_zero=True)
        _pos("joint_connect_radius", self.joint_connect_radius)
        _pos("joint_connect_max_distance", self.joint_connect_max_distance)
        if not isinstance(self.joint_connect_options, CBiRRT2Options):
            raise ValueError(f"TCBiRRTOptions.joint_connect_options: expected CBiRRT2Options, "
                             f"got {type(self.joint_connect_options).__name__}")
        for name in ("sample_filter", "keep_prefix", "scale_to_reach", "lazy_edges", "joint_connect",
                     "regrasp_share_orders", "verify_path", "graft_single_arm", "graft_skip_failed", "regrasp_both_arms", "regrasp_backoff", "root_grafts_first",
                     "graft_branch_seeds", "branch_roots", "restart_branch_roots", "filter_robot_body"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"TCBiRRTOptions.{name}: expected True/False, got {getattr(self, name)!r}")
        _pos("step_size", self.step_size)
        if not (isinstance(self.n_interp, int) and self.n_interp >= 1):
            raise ValueError(f"TCBiRRTOptions.n_interp: expected an int >= 1, got {self.n_interp!r}")
        lo, hi = np.asarray(self.xi_lower, float), np.asarray(self.xi_upper, float)
        if lo.shape != (6,) or hi.shape != (6,) or not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)) \
                or np.any(hi < lo):
            raise ValueError(f"TCBiRRTOptions.xi_lower/xi_upper: expected two 6-vectors with lower <= upper, "
                             f"got {self.xi_lower!r}, {self.xi_upper!r}")
        object.__setattr__(self, "xi_lower", tuple(float(x) for x in lo))
        object.__setattr__(self, "xi_upper", tuple(float(x) for x in hi))
        if not isinstance(self.ik, IKSettings):
            raise ValueError(f"TCBiRRTOptions.ik: expected IKSettings, got {type(self.ik).__name__}")
        if not (isinstance(self.max_joint_step, (int, float)) and self.max_joint_step > 0):
            raise ValueError(f"TCBiRRTOptions.max_joint_step: expected a positive number (inf: off), got {self.max_joint_step!r}")
        if self.edge_bound not in ("jacobian", "static", "certified"):
            raise ValueError(f"TCBiRRTOptions.edge_bound: expected 'jacobian', 'static' or 'certified', got {self.edge_bound!r}")
        _pos("edge_min_clearance", self.edge_min_clearance)
        if self.interpolation not in ("geodesic", "absolute"):
            raise ValueError(f"TCBiRRTOptions.interpolation: expected 'geodesic' or 'absolute', got {self.interpolation!r}")
        if self.edge_resolution is not None:
            _pos("edge_resolution", self.edge_resolution)
        _pos("edge_tolerance", self.edge_tolerance, allow_zero=True)
        if not isinstance(self.regrasp, RRTConnectOptions):
            raise ValueError(f"TCBiRRTOptions.regrasp: expected RRTConnectOptions, got {type(self.regrasp).__name__}")
        _pos("regrasp_time_limit", self.regrasp_time_limit)
        _pos("regrasp_min_time_limit", self.regrasp_min_time_limit)
        _pos("regrasp_tolerance", self.regrasp_tolerance, allow_zero=True)
        _pos("closure_tolerance", self.closure_tolerance)
        _pos("margin", self.margin, allow_zero=True)
        if self.validity_kernel not in ("native", "coal"):
            raise ValueError(f"TCBiRRTOptions.validity_kernel: expected 'native' or 'coal', got {self.validity_kernel!r}")
        if self.ik_predictor not in PREDICTORS:
            raise ValueError(f"TCBiRRTOptions.ik_predictor: expected one of {PREDICTORS}, got {self.ik_predictor!r}")
        if self.extension not in ("loop", "native", "python"):
            raise ValueError(f"TCBiRRTOptions.extension: expected 'loop', 'native' or 'python', got {self.extension!r}")
        if not (isinstance(self.max_iterations, int) and self.max_iterations >= 0):
            raise ValueError(f"TCBiRRTOptions.max_iterations: expected an int >= 0, got {self.max_iterations!r}")


#: [m] the paper robot's arm reach bound (:func:`.task_sampling.arm_reach` of ``tcbirrt_dual_arm``)
PAPER_REACH = 2.938195019102723
#: [m] the paper robot's sampled arm reach (:func:`.task_sampling.arm_reach_estimate` of
#: ``tcbirrt_dual_arm``): the sampling box, the step and the trial perturbations scale with a
#: robot's estimate over this
PAPER_REACH_ESTIMATE = 2.703369268366084


def reach_scale(robot: RobotModel) -> float:
    """The robot's mean sampled arm reach / the paper robot's (exactly 1 for that robot)."""
    from .task_sampling import arm_reach_estimate

    scale = float(np.mean([arm_reach_estimate(robot, a)[0] for a in robot.arms])) / PAPER_REACH_ESTIMATE
    return 1.0 if abs(scale - 1.0) < 1e-9 else scale


def reach_scaled_workspace(robot: RobotModel, options: TCBiRRTOptions) -> tuple[np.ndarray, np.ndarray, float]:
    """``(xi_lower, xi_upper, step_size)`` the planner uses for ``robot`` (see
    :attr:`TCBiRRTOptions.scale_to_reach`)."""
    from .task_sampling import arm_reach

    lo, hi, step = np.asarray(options.xi_lower, float), np.asarray(options.xi_upper, float), float(options.step_size)
    default = (options.xi_lower == PAPER_XI_LOWER and options.xi_upper == PAPER_XI_UPPER
               and step == TCBiRRTOptions.step_size)
    if not (options.scale_to_reach and default) or robot.is_floating or not robot.arms:
        return lo, hi, step
    reach = [arm_reach(robot, a) for a in robot.arms]
    scale = reach_scale(robot)
    centre = np.mean([sh for sh, _ in reach], axis=0)
    paper_centre = 0.5 * (lo[:3] + hi[:3])
    if scale == 1.0 and np.allclose(centre, paper_centre, atol=1e-9):
        return lo, hi, step
    lo, hi = lo.copy(), hi.copy()
    half = 0.5 * (hi[:3] - lo[:3]) * scale
    lo[:3], hi[:3] = centre - half, centre + half
    return lo, hi, step * scale
