"""Memory of a run of floating carries: the NLP structures a floating robot's kernel cache keeps are
bounded (``FloatingKernels.max_structures``), and a structure pushed out is freed — checked by weak
references to its compiled functions, not by the cache's own count alone."""
from __future__ import annotations

import gc
import weakref

import numpy as np

from optplan.problem import OptProblem
from optplan.problem.floating_kernels import FloatingKernels
from optplan.problem.kernels import KernelCache
from optplan.problem.terms import JointBoundary, Smoothness

DEG = np.pi / 180.0
Q0 = np.r_[[45.47, 42.5, -79.86, 20.38, -81.13, -150.5, 167.97] * 2] * DEG
Z = np.zeros(14)


def test_floating_structures_are_bounded_and_freed(eba):
    """One more NLP shape than the bound, each solved once (as a run of trials does): the cache
    holds ``max_structures`` of them, the oldest one's compiled functions are gone, the newest
    ones' alive."""
    kc = FloatingKernels.of(eba)
    kc.clear_structures()
    bound = FloatingKernels.max_structures
    assert bound < KernelCache.max_structures
    refs = []
    for N in range(4, 4 + bound + 2):
        p = OptProblem(eba, n_intervals=N, duration=10.0, transcription="bspline")
        p.add_constraint(JointBoundary("start", q=Q0, qd=Z, qdd=Z))
        p.add_constraint(JointBoundary("end", q=Q0 + 0.05, qd=Z, qdd=Z))
        p.add_cost(Smoothness("jerk"))
        sol = p.solve(guarantees=False, max_iter=3)
        assert sol.status is not None
        st = next(reversed(kc._structures.values()))
        refs.append([weakref.ref(st[k]) for k in ("gfun", "cfun", "ffun")])
        del p, sol, st
    gc.collect()
    assert len(kc._structures) == bound
    alive = [all(r() is not None for r in rs) for rs in refs]
    assert alive == [False] * 2 + [True] * bound, alive
