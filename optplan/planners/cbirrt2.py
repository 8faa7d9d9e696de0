"""CBiRRT2 — constrained bidirectional RRT in joint space with Newton-Raphson projection onto the
closed-chain manifold h(q) = 0 (Berenson, Srinivasa, Ferguson, Kuffner 2009; the TCBiRRT paper's
classical baseline, Section 5.2 item 2: "maximum edge length between nodes 0.6 rad, step size
for collision checking 0.2 rad").

ConstrainedExtend(T, q_near, q_target): repeat { step ``min(max_edge, |q_target − q_s|)`` toward
q_target; project onto h = 0 by Newton-Raphson (``q ← q − J⁺ h``, damped pseudo-inverse,
``tolerance`` on max |h|); stop when the projection fails, leaves the joint limits, jumps farther
than ``2 · max_edge``, moves away from the target, or the new configuration or its edge is in
collision }. Edges are checked every ``collision_step`` rad: the straight segment is cut into
pieces of at most ``collision_step`` (Euclidean), each cut point is projected onto the manifold
and checked, and the projected points are kept as path waypoints (so every returned
configuration satisfies h = 0 to ``tolerance``). With ``certified_edges`` the straight joint
segments between those waypoints — the path as it is executed — are certified collision-free at
every point (conservative advancement on exact distances). The trees alternate (extend toward a uniform
sample in the joint box, then connect the other tree to the reached node), as in CBiRRT.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..constraints.closed_chain import ClosedChainKinematics, closure_error
from ..errors import ConfigurationError
from .base import Deadline, PathSegment, Planner, PlanResult, PlanStatus
from .tree import Tree, joined_path
from .validity import ValidityChecker

__all__ = ["CBiRRT2Options", "CBiRRT2"]
log = logging.getLogger(__name__)

TRAPPED, ADVANCED, REACHED = 0, 1, 2


@dataclass(frozen=True)
class CBiRRT2Options:
    """Options of :class:`CBiRRT2` (Berenson et al.'s constrained bidirectional RRT)."""

    #: Step of ConstrainedExtend [rad] (the paper: 0.6).
    max_edge: float = 0.6
    #: Joint spacing of the collision checks along an edge [rad] (the paper: 0.2).
    collision_step: float = 0.2
    #: Projection tolerance on the constraint residual, max |h| [m or rad per row].
    tolerance: float = 1e-7
    #: Newton iterations of one projection onto the constraint [count].
    max_projection_iterations: int = 50
    #: Damping of the pseudo-inverse in the projection [-].
    damping: float = 1e-6
    #: The trees are joined when a connect step ends this close to its target [rad].
    connect_distance: float = 1e-3
    #: Clearance counted as contact [m].
    margin: float = 0.0
    #: Backend of the boolean collision checks: ``"native"`` (the compiled planning kernel,
    #: :mod:`optplan.planners.kernel`; coal when it cannot be built) or ``"coal"`` (Pinocchio + coal).
    validity_kernel: str = "native"
    #: Cap on the planner's iterations [count] (0: only the time limit).
    max_iterations: int = 0
    #: Certify every edge collision-free at every point: the straight joint segments between the edge's projected
    #: configurations (the path's waypoints) by conservative advancement on exact distances
    #: (:meth:`.ValidityChecker.path_is_certified`), after the configurations themselves passed. Off: the
    #: configurations every ``collision_step`` only (the paper).
    certified_edges: bool = False
    #: Certified edges keep every collision pair at least half of this apart [m].
    edge_min_clearance: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("max_edge", "collision_step", "tolerance", "connect_distance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"CBiRRT2Options.{name}: expected a positive number, got {v!r}")
        if not (isinstance(self.damping, (int, float)) and self.damping >= 0):
            raise ValueError(f"CBiRRT2Options.damping: expected a number >= 0, got {self.damping!r}")
        if not (isinstance(self.margin, (int, float)) and self.margin >= 0):
            raise ValueError(f"CBiRRT2Options.margin: expected a number >= 0 m, got {self.margin!r}")
        if self.validity_kernel not in ("native", "coal"):
            raise ValueError(f"CBiRRT2Options.validity_kernel: expected 'native' or 'coal', got {self.validity_kernel!r}")
        if not isinstance(self.certified_edges, bool):
            raise ValueError(f"CBiRRT2Options.certified_edges: expected True/False, got {self.certified_edges!r}")
        if not (isinstance(self.edge_min_clearance, (int, float)) and math.isfinite(self.edge_min_clearance)
                and self.edge_min_clearance > 0):
            raise ValueError(f"CBiRRT2Options.edge_min_clearance: expected a positive number of metres, "
                             f"got {self.edge_min_clearance!r}")
        for name in ("max_projection_iterations", "max_iterations"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= (1 if name == "max_projection_iterations" else 0)):
                raise ValueError(f"CBiRRT2Options.{name}: expected a non-negative int, got {v!r}")


class CBiRRT2(Planner):
    """CBiRRT2 on the closed chain of ``scene.object``'s two grasps (see the module docstring), or
    on any other ``constraint``: an object with ``h_jacobian(q) -> (h, J)`` (``dim`` residuals and
    their ``dim × nq`` Jacobian; residual 0 on the manifold, e.g.
    :class:`~optplan.planners.orientation.DualArmOrientationConstraint` with TSR-style bounds on
    the orientation error), ``dim`` and optionally ``object_pose(q)``. Works for any fixed-base robot."""

    name = "cbirrt2"

    def __init__(self, robot: Any, scene: Any, options: CBiRRT2Options | None = None, *,
                 checker: ValidityChecker | None = None, kinematics: ClosedChainKinematics | None = None,
                 constraint: Any = None) -> None:
        super().__init__(robot, scene)
        if constraint is None and (scene is None or scene.object is None or len(scene.object.grasps) != 2):
            raise ConfigurationError("CBiRRT2 needs a scene with an [object] grasped by two arms, or a constraint")
        if constraint is not None and not (hasattr(constraint, "h_jacobian") and hasattr(constraint, "dim")):
            raise TypeError(f"constraint: expected an object with h_jacobian(q) and dim, got {type(constraint).__name__}")
        self.options = options or CBiRRT2Options()
        if not isinstance(self.options, CBiRRT2Options):
            raise TypeError(f"options: expected CBiRRT2Options, got {type(self.options).__name__}")
        self.checker = checker or ValidityChecker(robot, scene, margin=self.options.margin,
                                                   kernel=self.options.validity_kernel)
        self.constraint = constraint
        if constraint is None:
            self.kin = kinematics or ClosedChainKinematics(robot, scene.object.grasps)
            self.grasps = scene.object.grasps
            self._eye = np.eye(6)
        else:
            self.kin = constraint
            self.grasps = None
            self._eye = np.eye(int(constraint.dim))
        # the compiled pieces the search uses are built (or loaded from the cache) here, not against the
        # planning deadline: with an empty cache they took 0.7 s wall inside the first iterations
        from .kernel.extend import nearest_available

        self.kin.h_jacobian(np.clip(np.zeros(robot.nq), robot.lower, robot.upper))
        nearest_available()

    # ------------------------------------------------------------------ projection
    def project(self, q: np.ndarray, st: dict[str, Any]) -> np.ndarray | None:
        """Newton-Raphson onto h = 0 (damped pseudo-inverse); None when it does not converge or
        leaves the joint limits."""
        o, kin = self.options, self.kin
        st["projections"] += 1
        lam2 = o.damping ** 2 * self._eye
        for _ in range(o.max_projection_iterations):
            h, J = kin.h_jacobian(q)
            if float(np.abs(h).max()) < o.tolerance:
                if np.any(q < self.robot.lower) or np.any(q > self.robot.upper):
                    return None
                return q
            q = q - J.T @ np.linalg.solve(J @ J.T + lam2, h)
        st["projection_failures"] += 1
        return None

    def _edge(self, qa: np.ndarray, qb: np.ndarray, st: dict[str, Any]) -> list[np.ndarray] | None:
        """Projected, collision-checked points strictly between qa and qb (both on the manifold); with
        ``certified_edges`` the straight segments qa → points → qb certified as well."""
        d = qb - qa
        n = int(math.ceil(float(np.sqrt(d @ d)) / self.options.collision_step))
        out = []
        for k in range(1, n):
            x = self.project(qa + (k / n) * d, st)
            if x is None or not self.checker.is_valid(x):
                return None
            out.append(x)
        if self.options.certified_edges:
            st["certified_edges"] = st.get("certified_edges", 0) + 1
            if not self.checker.path_is_certified(np.array([qa, *out, qb]), "held",
                                                  min_clearance=self.options.edge_min_clearance):
                st["certify_rejects"] = st.get("certify_rejects", 0) + 1
                return None
        return out

    # ------------------------------------------------------------------ ConstrainedExtend
    def extend(self, tree: Tree, i_near: int, target: np.ndarray, st: dict[str, Any],
               deadline: Deadline) -> tuple[int, int]:
        o = self.options
        i_old = i_near
        q_old = tree.X[i_near].copy()
        q_s = q_old
        res = TRAPPED
        while not deadline.expired():
            d = target - q_s
            dist = float(np.sqrt(d @ d))
            if dist < o.connect_distance:
                return REACHED, i_old
            if i_old != i_near and dist > float(np.linalg.norm(target - tree.X[tree.parent[i_old]])):
                return ADVANCED, i_old
            step = min(o.max_edge, dist)
            q_new = self.project(q_s + (step / dist) * d, st)
            if q_new is None:
                break
            dn = q_new - q_old
            if float(np.sqrt(dn @ dn)) > 2.0 * o.max_edge or not self.checker.is_valid(q_new):
                break
            edge = self._edge(q_old, q_new, st)
            if edge is None:
                break
            i_old = tree.add(q_new, i_old, edge)
            q_old = q_s = q_new
            res = ADVANCED
        return res, i_old

    # ------------------------------------------------------------------ main loop
    def sample_target(self, rng: np.random.Generator, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """The target of an iteration's extension: uniform in the joint box (subclasses draw it
        from a precomputed set or a learned sampler)."""
        return rng.uniform(lower, upper)

    def _plan(self, q_start: np.ndarray, q_goal: np.ndarray, deadline: Deadline, rng: np.random.Generator,
              seed: int) -> PlanResult:
        o, ck = self.options, self.checker
        st = {"iterations": 0, "projections": 0, "projection_failures": 0}
        c0 = ck.n_checks
        for which, q, status in (("start", q_start, PlanStatus.INVALID_START), ("goal", q_goal, PlanStatus.INVALID_GOAL)):
            if self.constraint is None:
                ep, eo = closure_error(self.robot, self.grasps, q)
            else:
                ep, eo = float(np.abs(self.constraint.h_jacobian(q)[0]).max()), 0.0
            if not ck.in_limits(q):
                return self.empty_result(status, f"{which} outside the joint limits", **st)
            if max(ep, eo) > 1e-6:
                return self.empty_result(status, f"{which} off the closed-chain manifold ({max(ep, eo):.1e})", **st)
            if not ck.is_valid(q):
                return self.empty_result(status, f"{which} in collision", **st)
        ta, tb = Tree(q_start, 512, edges=True), Tree(q_goal, 512, edges=True)
        a_is_start = True
        found = None
        lo, hi = self.robot.lower, self.robot.upper
        while not deadline.expired():
            if o.max_iterations and st["iterations"] >= o.max_iterations:
                break
            st["iterations"] += 1
            q_rand = self.sample_target(rng, lo, hi)
            _, i_a = self.extend(ta, ta.nearest(q_rand), q_rand, st, deadline)
            target = ta.X[i_a].copy()          # CBiRRT: connect to q_reached even when trapped at q_near
            res_b, i_b = self.extend(tb, tb.nearest(target), target, st, deadline)
            if res_b == REACHED:
                found = (i_a, i_b)
                break
            ta, tb, a_is_start = tb, ta, not a_is_start
        st["nodes"] = ta.n + tb.n
        st["collision_checks"] = ck.n_checks - c0
        if found is None:
            if deadline.expired():
                return self.empty_result(PlanStatus.TIMEOUT, "time limit reached", **st)
            return self.empty_result(PlanStatus.FAILED, "iteration cap reached", **st)
        P = np.array(joined_path(ta, found[0], tb, found[1], a_is_start))
        P[0], P[-1] = q_start, q_goal
        poses = [self.kin.object_pose(q) for q in P] if hasattr(self.kin, "object_pose") else [None] * len(P)
        return PlanResult(PlanStatus.EXACT, self.name, P, poses, np.ones(len(P), bool),
                          [PathSegment("constrained", 0, len(P) - 1)], st)
