"""Collision avoidance as NLP constraints: smooth, conservative distances (:mod:`optplan.geometry.distance`)
between the robot's link capsules, the scene's obstacles and the held object.

* Robot links: their exact capsules (the URDF ``*_capsule`` collision elements).
* Held object: its exact box. Obstacles: exact boxes, spheres and capsules.
* Pairs with a box on either side (object–obstacle, object–link, link–box obstacle, base box–
  obstacle) use a **separating plane** per pair and knot: auxiliary variables ``(n, b)`` with
  ``n·x + r_A ≤ b − m/2`` for every vertex/centre ``x`` of A (radius ``r_A``: 0 for box vertices,
  the capsule/sphere radius otherwise), ``n·y − r_B ≥ b + m/2`` for B, and ``‖n‖² ≤ 1``. Such a
  plane exists iff the shapes are at least ``m`` apart, so the constraints are exact, not an
  approximation, and conservative (distance ≥ m/‖n‖ ≥ m). Planes start from coal's witness normal
  at the initial guess.
* Sphere/capsule-only pairs (link–link self-collision, links vs sphere/capsule obstacles) use the
  smooth conservative distances of :mod:`optplan.geometry.distance` (≤ ``cover_tol`` + 3 mm below exact).

Pair activation: a pair is constrained at every knot when its exact coal distance along the
*initial guess* comes below ``activation`` [m] anywhere; far pairs are left out (the same pruning
TrajOpt uses). ``verify`` checks every pair exactly afterwards; :meth:`OptProblem.solve` callers
re-solve with a larger activation if it finds a violation (see ``solve_with_collision_retry``).
"""
from __future__ import annotations

import dataclasses
import types
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, NoReturn

import numpy as np
from numpy.typing import ArrayLike

from ..collision.checker import Pair
from ..errors import ConfigurationError
from ..model.robot import RobotModel
from ..scene import Scene
from .build import AuxVariable, BuildContext, TermData
from .collision_model import CollisionModel, _box_vertices, object_capsules, witness_plane
from .terms import NumericTrajectory, Term
from .transcription import Expr, Transcription

__all__ = ["CollisionAvoidance", "CollisionModel", "object_capsules", "witness_plane", "_box_vertices"]


@dataclass(eq=False)
class CollisionAvoidance(Term):
    """``d_smooth ≥ margin`` [m] for every active pair at every knot.

    scene: obstacles and (if ``held_object``) the grasped object; ``object_arm`` carries it.
    activation [m], window [knots]: a pair is constrained at the knots within ``window`` of those
    where the initial guess brings it closer than ``activation`` (see module docstring).
    skip_pinned: no rows at knots whose joints a JointBoundary pins — the configuration is given,
    its clearance is not the NLP's to change (``verify`` checks it by coal), and its rows would have
    no free joint (a planner's boundary configuration closer than the margin made a regrasp NLP
    infeasible). skip_constant: no rows for a pair whose two
    entities depend on no free joint (joints a JointPositionLimits holds at lower == upper, e.g. the
    holding arm of a regrasp, vs the base, an obstacle or the held object): its distance is the same
    at every knot, the NLP cannot change it, and a value below ``margin`` would make the NLP
    infeasible (a holding arm closer to the base than the margin); listed in
    ``constant_pairs``, checked by ``verify``. cover_tol [m]: sphere-covering tolerance of the smooth
    capsule distances (coarser = fewer spheres = faster NLP, more conservative).
    fixed_normals: the separating planes' normals are held at their initial values (coal's witness
    normal at the initial guess, per pair and knot; only the offsets b are free). The rows stay
    exact and conservative (distance ≥ margin along a unit normal), the NLP loses its bilinear
    plane terms and the trajectory stays in the corridor of half-spaces around the initial guess,
    at the price of a higher optimum. A new initial guess (``set_initial``) re-seeds the normals.
    See docs/decisions/0003-fixed-plane-normals.md and docs/decisions/0010-knot-transcription-defaults.md.
    """

    scene: Scene | None = None
    margin: float = 0.0
    activation: float = 0.3
    window: int = 3
    self_collision: bool = True
    held_object: bool = True
    object_arm: str | None = None
    object_grid: int = 2
    cover_tol: float = 0.02
    eps: float = 1e-3
    activate_with: tuple[NumericTrajectory, ...] = ()  # extra NumericTrajectory(s) for pair activation (see with_activation)
    skip_pinned: bool = True
    skip_constant: bool = True
    fixed_normals: bool = False
    #: (pair, knot) -> extra margin [m] (see with_boost)
    margin_boost: Mapping[tuple[Pair, int], float] = field(default_factory=dict)
    default_name = "collision"

    # A frozen configuration (see Term). Building it (build / model) creates a CollisionModel that holds the collision checker, the
    # active pairs and every other per-build decision. The only exception is the in-place style
    # of SplineSegmentProblem (it calls ``_setup`` and then sets ``activate_with`` /
    # ``active_pairs`` / ``constant_pairs``): after ``_setup`` those names, and the model's
    # methods, are forwarded to a model kept for that purpose (deprecated; use ``model(robot)``).
    _LEGACY_NAMES = frozenset({"activate_with", "active_pairs", "constant_pairs", "relaxed", "skipped"})

    def _validate(self) -> None:
        def bad(name: str, want: str) -> NoReturn:
            raise ConfigurationError(f"CollisionAvoidance.{name}: expected {want}, got {getattr(self, name)!r}")

        if self.scene is not None and not isinstance(self.scene, Scene):
            bad("scene", "an optplan Scene or None")
        for name in ("margin", "activation", "cover_tol", "eps"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not np.isfinite(v):
                bad(name, "a finite number [m]")
        if self.margin < 0:
            bad("margin", "a distance ≥ 0 [m]")
        if self.cover_tol <= 0 or self.eps <= 0:
            bad("cover_tol" if self.cover_tol <= 0 else "eps", "a distance > 0 [m]")
        for name, lo in (("window", 0), ("object_grid", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
                bad(name, f"an integer ≥ {lo}")
        object.__setattr__(self, "activate_with", tuple(self.activate_with))
        object.__setattr__(self, "margin_boost", types.MappingProxyType(dict(self.margin_boost)))

    def __setattr__(self, name: str, value: Any) -> None:
        legacy = self.__dict__.get("_legacy")
        if legacy is not None and name in self._LEGACY_NAMES:
            if name == "activate_with":
                value = tuple(value)
                object.__setattr__(self, name, value)
            setattr(legacy, name, value)
            return
        super().__setattr__(name, value)

    def __getattr__(self, name: str) -> Any:
        legacy = self.__dict__.get("_legacy")
        if legacy is not None and not name.startswith("__"):
            return getattr(legacy, name)
        raise AttributeError(f"{type(self).__name__!s} has no attribute {name!r}" + (
            " (build information such as active_pairs is in the built data: OptProblem.term_data(handle).info)"
            if name in self._LEGACY_NAMES or name in ("checker", "active_knots") else ""))

    # ------------------------------------------------------------------ model → data
    def model(self, robot: RobotModel) -> CollisionModel:
        """A new :class:`CollisionModel` (collision checker, NLP shapes, activation) for ``robot``."""
        return CollisionModel(self, robot)

    def _setup(self, robot: RobotModel) -> None:
        """Deprecated in-place setup (SplineSegmentProblem): keeps a model on this term and
        forwards the model's attributes and methods. Use :meth:`model`."""
        object.__setattr__(self, "_legacy", CollisionModel(self, robot))

    def rows(self, ctx: BuildContext) -> TermData:
        return self.model(ctx.robot).build_rows(ctx)

    def residual(self, tp: Transcription) -> tuple[Expr, np.ndarray, np.ndarray]:
        raise TypeError("CollisionAvoidance has no residual(tp): its rows depend on the initial guess and use "
                        "auxiliary variables (separating planes); build it with term.build(BuildContext(tp, ...)) "
                        "or evaluate it through OptProblem.term_function(handle)")

    def reseed(self, data: TermData, traj: NumericTrajectory) -> tuple[AuxVariable, ...]:
        """The auxiliary variables of built ``data`` re-seeded from a new initial guess ``traj``
        (same active pairs): the separating planes (and, with ``fixed_normals``, their fixed
        normals) from coal's witness normals."""
        return data.info["model"].reseed(data, traj)

    def with_activation(self, *trajectories: NumericTrajectory) -> CollisionAvoidance:
        """This term with more trajectories whose close pairs are activated (e.g. a solution that
        ``verify`` found colliding)."""
        return dataclasses.replace(self, activate_with=tuple(self.activate_with) + tuple(trajectories))

    def with_boost(self, data: TermData, traj_t: np.ndarray, traj_q: ArrayLike, knot_t: ArrayLike,
                   min_clearance: float = 0.0) -> tuple[CollisionAvoidance, int]:
        """``(term, n)``: this term with the margin raised where a solution collides between knots
        (:meth:`CollisionModel.boost_between_knots` on the pairs ``data`` activated), and the
        number of (pair, knot) rows boosted."""
        m = data.info["model"]
        n = m.boost_between_knots(traj_t, traj_q, knot_t, min_clearance)
        return dataclasses.replace(self, margin_boost=dict(m.margin_boost)), n

    def numeric(self, traj: NumericTrajectory, data: TermData | None = None) -> np.ndarray:
        """Exact coal distances of the active pairs at every knot, ``(N+1) × n_active`` — the pairs
        the built ``data`` activated, or (without it) the pairs ``traj`` itself activates."""
        if data is not None:
            return data.info["model"].numeric(traj)
        m = self.model(traj.robot)
        m.activate(traj.robot, traj)
        return m.numeric(traj)

    def numeric_built(self, traj: NumericTrajectory, data: TermData) -> np.ndarray:
        return self.numeric(traj, data)

    def bounds_numeric(self, traj: NumericTrajectory, data: TermData | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        if data is not None:
            return data.info["model"].bounds_numeric(traj)
        m = self.model(traj.robot)
        m.activate(traj.robot, traj)
        return m.bounds_numeric(traj)

    def sampled(self) -> Term:
        return self


