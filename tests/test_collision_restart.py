"""The B-spline segment's collision re-solve starts from the solution coal found in contact
(``PipelineOptions.collision_warm_start``), not from the first guess again: checked by stopping the
re-solve before its first iteration (IPOPT then returns its starting point), against the planner
path's segment of ``tests/data/segment_ssps_scene3_ends.npz``."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import optplan.pipeline as PL
from optplan.pipeline_options import PipelineOptions
from optplan.problem import ClosedChain
from optplan.scene import Scene
from optplan.segment_nlp import boost_and_activate, guess_knots
from optplan.tasks import segment_problem

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="module")
def segment(tcb):
    d = np.load(DATA / "segment_ssps_scene3_ends.npz")
    path, scene = np.asarray(d["path"], float), Scene.load(str(d["scene"]))
    grasps = PL._held_object(scene).grasps
    arms = list(grasps)
    cc = ClosedChain.from_grasps(grasps[arms[0]], grasps[arms[1]], arms[0], arms[1])
    opts = PipelineOptions()
    length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
    N = int(np.clip(np.ceil(length / opts.spline_interval_step), opts.spline_min_intervals, opts.spline_max_intervals))
    T = max(opts.min_duration, length / (opts.speed_fraction * float(np.min(tcb.velocity_limit))))

    def build():
        prob, _ = segment_problem(tcb, scene, path[0], path[-1], N, T, closed_chain=cc, margin=opts.margin,
                                  object_arm=arms[0], fixed_normals=True, transcription="bspline",
                                  velocity_activation=opts.spline_velocity_activation)
        prob.prepare_warm_start = False
        prob.set_initial_path(path, cc)
        return prob

    return build, T, dict(opts.ipopt_options)


def _pairs(prob) -> set[str]:
    return {f"{p.name_a}|{p.name_b}" for p in prob.term_data("collision").info["model"].active_pairs}


@pytest.mark.parametrize("restart", [True, False])
def test_collision_resolve_starts_where_asked(segment, restart):
    build, T, ipopt = segment
    prob = build()
    first = guess_knots(prob)
    sol = prob.solve(ipopt, guarantees=False)
    assert sol.success, sol.status
    pairs = _pairs(prob)
    moved = float(np.abs(sol.q - first).max())
    assert moved > 1e-3   # the optimum is not the first guess: the two starts can be told apart

    assert boost_and_activate(prob, sol, PL._dense_times(sol), T, restart=restart) is restart
    start = prob.solve(ipopt, max_iter=0, guarantees=False)   # no iteration: IPOPT's starting point
    expect = sol.q if restart else first
    other = first if restart else sol.q
    # (IPOPT pushes a start off its bounds by ~1e-6: the first guess comes back 2.6e-6 rad off)
    assert np.abs(start.q - expect).max() < 1e-3 * moved
    assert np.abs(start.q - other).max() > 0.5 * moved
    # the pairs the first build had rows for keep them (activated along the first guess and the solution)
    assert pairs <= _pairs(prob)
    # and a solve from there converges to a solution coal verifies as any other
    again = prob.solve(ipopt, guarantees=False)
    assert again.success, again.status
