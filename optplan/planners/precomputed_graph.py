"""Precomputed Graph — CBiRRT2 whose random targets come from a precomputed set of on-manifold
configurations (Şucan & Chitta 2012; the TCBiRRT paper's Section 5.2 item 3: "10,000 configurations satisfying the
constraints are generated offline to form the graph. During planning, new nodes are sampled
directly from this graph").

The set is :func:`~optplan.planners.manifold_samples.manifold_samples` of the scene (projection +
collision check, seeded, cached on disk with a hash of the scene and the settings); it is built
once when the planner is constructed. Each CBiRRT2 iteration extends toward a node of the set drawn
uniformly with the query's ``rng`` instead of a uniform joint-box sample; extension, projection,
edge checks and the tree connection are CBiRRT2's (:class:`~optplan.planners.cbirrt2.CBiRRT2`).
The graph's nodes are what the planner samples; connectivity between them is not precomputed
(the paper does not describe edges, and CBiRRT2 checks every edge it grows).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..constraints.closed_chain import ClosedChainKinematics
from .cbirrt2 import CBiRRT2, CBiRRT2Options
from .manifold_samples import ManifoldSamples, ManifoldSampleSettings, manifold_samples
from .validity import ValidityChecker

__all__ = ["PrecomputedGraphOptions", "PrecomputedGraph"]


@dataclass(frozen=True)
class PrecomputedGraphOptions(CBiRRT2Options):
    """Options of :class:`PrecomputedGraph`: CBiRRT2's and the offline set's."""

    #: On-manifold configurations in the precomputed graph [count] (the paper: 10,000 per scene).
    n_samples: int = 10_000
    #: Seed of the offline set [-] (the query's own seed drives the search).
    samples_seed: int = 0
    #: Read / write the offline set from / to the on-disk cache [-].
    cache: bool = True
    #: Share of the set drawn by constrained random walks in the task's start and goal regions [-]
    #: (:attr:`~optplan.planners.manifold_samples.ManifoldSampleSettings.region_fraction`; 0: as before).
    region_fraction: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if isinstance(self.n_samples, bool) or not isinstance(self.n_samples, int) or self.n_samples < 1:
            raise ValueError(f"PrecomputedGraphOptions.n_samples: expected an integer >= 1, got {self.n_samples!r}")
        if isinstance(self.samples_seed, bool) or not isinstance(self.samples_seed, int) or self.samples_seed < 0:
            raise ValueError(f"PrecomputedGraphOptions.samples_seed: expected an integer >= 0, got {self.samples_seed!r}")
        if not isinstance(self.cache, bool):
            raise ValueError(f"PrecomputedGraphOptions.cache: expected True/False, got {self.cache!r}")


class PrecomputedGraph(CBiRRT2):
    """CBiRRT2 sampling its targets from the scene's precomputed on-manifold set (module docstring)."""

    name = "precomputed-graph"

    def __init__(self, robot: Any, scene: Any, options: PrecomputedGraphOptions | None = None, *,
                 checker: ValidityChecker | None = None, kinematics: ClosedChainKinematics | None = None,
                 progress: bool = False) -> None:
        options = options or PrecomputedGraphOptions()
        if not isinstance(options, PrecomputedGraphOptions):
            raise TypeError(f"options: expected PrecomputedGraphOptions, got {type(options).__name__}")
        super().__init__(robot, scene, options, checker=checker, kinematics=kinematics)
        o = options
        settings = ManifoldSampleSettings(n=o.n_samples, seed=o.samples_seed, tolerance=o.tolerance,
                                          max_projection_iterations=o.max_projection_iterations, margin=o.margin,
                                          region_fraction=o.region_fraction)
        self.samples: ManifoldSamples = manifold_samples(robot, scene, settings, checker=self.checker,
                                                         kinematics=self.kin, cache=o.cache, progress=progress)

    def sample_target(self, rng: np.random.Generator, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """A node of the precomputed graph, uniformly."""
        Q = self.samples.Q
        return Q[int(rng.integers(len(Q)))].copy()
