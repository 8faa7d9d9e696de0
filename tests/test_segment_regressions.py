"""Segment NLPs that once failed, kept as regressions: the constrained segments of two planner paths
(saved in ``tests/data``), optimized by the pipeline's B-spline segment policy and checked by
``verify`` (Pinocchio + coal), each beside the setting that made it fail.

* ``segment_stress_shelf_filter.npz`` (scene ``stress_shelf``, a 10.2 rad path on 160 intervals):
  with IPOPT's default filter bound (``theta_max_fact`` = 10⁴) a step to a closed-chain residual of
  3.3 was accepted at iteration 17 and the solve never came back (200 iterations, then the knot
  fallback failed too); the plane-row NLP's bound (10) keeps the iterates near the manifold.
* ``segment_ssps_scene3_ends.npz`` (scene ``ssps_scene3``): the planner's start configuration is
  2.1e-7 m off the closed-chain manifold, above the rows' tolerance (1.4e-7); IPOPT stalled at a
  violation of 1.5e-7 next to the pinned start until its iteration limit. The pipeline now holds the
  rows to twice the ends' own residual.
* ``segment_hard_window_regrasp.npz``: a regrasp path the pipeline shortens before optimizing it
  (``shortcut_free``), checked against exact distances on a finer grid than the shortcut's own.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import optplan.pipeline as PL
from optplan.constraints.closed_chain import closure_errors
from optplan.pipeline_options import PipelineOptions
from optplan.problem import ClosedChain, OptProblem
from optplan.scene import Scene
from optplan.tasks import segment_problem

DATA = Path(__file__).parent / "data"


def _load(name: str):
    d = np.load(DATA / name)
    return np.asarray(d["path"], float), str(d["scene"]), str(d["kind"])


def _chain(scene):
    grasps = PL._held_object(scene).grasps
    arms = list(grasps)
    return grasps, ClosedChain.from_grasps(grasps[arms[0]], grasps[arms[1]], arms[0], arms[1]), arms


def test_filter_bound_keeps_a_long_segment_near_the_manifold(tcb):
    path, scene_name, kind = _load("segment_stress_shelf_filter.npz")
    scene = Scene.load(scene_name)
    # this 10.2 rad segment on the grid it was recorded on (spline_max_intervals); the default first grid
    # (spline_first_max_intervals, 100 intervals) verifies too, at IPOPT's acceptable level
    for first_max, status in ((160, "Solve_Succeeded"), (None, None)):
        opts = PipelineOptions(failure_retries=0) if first_max is None else \
            PipelineOptions(failure_retries=0, spline_first_max_intervals=first_max)
        sol, rep, attempts = PL._spline_segment(tcb, scene, path, kind, None, opts,
                                                dict(opts.ipopt_options))  # as the pipeline calls it
        first = attempts[0]
        assert first["reason"] == "initial" and first["N"] == min(opts.spline_first_max_intervals, 160), attempts
        assert (first["status"] == status) if status else sol.success, attempts
        assert first["iterations"] <= 100, attempts
        assert rep.min_clearance_m >= 0.0 and rep.max_closed_chain_residual <= opts.closed_chain_tol, rep
    opts = PipelineOptions(failure_retries=0)

    # the same NLP with the pipeline's IPOPT options, 30 iterations: the filter bound holds the
    # iterates near the manifold. (On the closed segment NLP, IPOPT's own bound, 10⁴, accepted a step
    # to a residual of 3.3 here; the shared core's NLP — every control point free, the ends as rows —
    # stayed at 4e-4 under either bound, measured 2026-11-28; with its ends fixed by bounds as the
    # closed class's are, 5e-5 under either bound, measured the same day. From the closed class's
    # guess, knots at the quintic law's arc lengths, it reached 0.10: the guess matters.)
    grasps, cc, arms = _chain(scene)
    length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
    N = int(np.clip(np.ceil(length / opts.spline_interval_step), opts.spline_min_intervals, opts.spline_max_intervals))
    T = max(opts.min_duration, length / (opts.speed_fraction * float(np.min(tcb.velocity_limit))))
    prob, _ = segment_problem(tcb, scene, path[0], path[-1], N, T, closed_chain=cc, margin=opts.margin,
                              object_arm=arms[0], fixed_normals=True, transcription="bspline",
                              velocity_activation=opts.spline_velocity_activation)
    prob.set_initial_path(path, cc)
    cv = 0.5 * opts.closed_chain_tol / (2.0 * np.sqrt(3.0))
    ipopt = {**dict(opts.ipopt_options), "constr_viol_tol": cv, "acceptable_constr_viol_tol": cv}
    bounded = prob.solve(ipopt, max_iter=30, guarantees=False)
    assert bounded.terms["closed_chain"] < 1e-2, bounded.terms


def test_rows_next_to_pinned_ends_are_held_to_what_the_ends_allow(tcb, monkeypatch):
    path, scene_name, kind = _load("segment_ssps_scene3_ends.npz")
    scene = Scene.load(scene_name)
    grasps, _, _ = _chain(scene)
    opts = PipelineOptions(failure_retries=0)
    quarter = 0.5 * opts.closed_chain_tol / (2.0 * np.sqrt(3.0))
    pos, rot = closure_errors(tcb, grasps, path[[0, -1]])
    end = float(max(pos.max(), rot.max()))
    assert end > quarter, "the saved path should start off the manifold by more than the rows' usual tolerance"

    seen = []
    solve = OptProblem.solve

    def spy(self, ipopt=None, **kw):
        seen.append(dict(ipopt or {}))
        return solve(self, ipopt, **kw)

    monkeypatch.setattr(OptProblem, "solve", spy)
    sol, rep, attempts = PL._spline_segment(tcb, scene, path, kind, None, opts, dict(opts.ipopt_options))  # as the pipeline calls it
    assert seen and all(o["constr_viol_tol"] >= min(2 * end, opts.closed_chain_tol / (2 * np.sqrt(3)))
                        for o in seen), seen
    first = attempts[0]
    # converged (to IPOPT's acceptable level at the same constraint tolerance, with never-monotone μ)
    assert first["status"] in ("Solve_Succeeded", "Solved_To_Acceptable_Level") and first["iterations"] <= 60, attempts
    assert sol.success and rep.min_clearance_m >= 0.0 and rep.max_closed_chain_residual <= opts.closed_chain_tol, rep


def test_a_stalled_solve_is_repeated_with_the_retry_globalization(tcb, monkeypatch):
    """The same saved segment held to IPOPT's tight tolerance (no acceptable level): never-monotone μ
    stalls next to the pinned start until the iteration cap (measured 2026-11-28: 200 iterations at a
    violation of ~1e-7); the policy then solves the same NLP from the same first guess with IPOPT's own
    μ globalization, which converges, and keeps that setting for the segment's later NLPs. Without the
    retry the stall stands (and the policy goes on, here to the knot transcription)."""
    path, scene_name, kind = _load("segment_ssps_scene3_ends.npz")
    scene = Scene.load(scene_name)
    strict = tuple(kv for kv in PipelineOptions().ipopt_options if not kv[0].startswith("acceptable"))
    seen: list[tuple[str, bytes]] = []
    solve = OptProblem.solve

    def spy(self, ipopt=None, **kw):
        seen.append((dict(ipopt or {}).get("adaptive_mu_globalization"), np.asarray(self.initial_guess).tobytes()))
        return solve(self, ipopt, **kw)

    monkeypatch.setattr(OptProblem, "solve", spy)
    opts = PipelineOptions(failure_retries=0, spline_max_iterations=60, ipopt_options=strict)
    sol, rep, attempts = PL._spline_segment(tcb, scene, path, kind, None, opts, dict(opts.ipopt_options))
    assert attempts[0]["reason"] == "initial" and attempts[0]["status"] == "Maximum_Iterations_Exceeded", attempts
    assert attempts[1]["reason"] == "globalization" and attempts[1]["status"] == "Solve_Succeeded", attempts
    assert seen[0][0] == "never-monotone-mode" and all(g == "obj-constr-filter" for g, _ in seen[1:]), seen
    assert seen[1][1] == seen[0][1], "the retry starts from the first guess, not from the stalled point"
    assert sol.success and rep.min_clearance_m >= 0.0 and rep.max_closed_chain_residual <= opts.closed_chain_tol, rep
    assert sol.total_iterations == sum(a["iterations"] for a in attempts)   # the stalled solve's iterations count

    seen.clear()
    off = PipelineOptions(failure_retries=0, spline_max_iterations=60, ipopt_options=strict, globalization_retry_options=())
    sol, _, attempts = PL._spline_segment(tcb, scene, path, kind, None, off, dict(off.ipopt_options))
    assert [a["reason"] for a in attempts][:2] == ["initial", "fallback-knots"], attempts   # the stall stands
    assert attempts[0]["status"] == "Maximum_Iterations_Exceeded", attempts


def test_regrasp_shortcut_keeps_ends_and_the_holding_arm_and_stays_collision_free(tcb):
    """A planner's regrasp path (``segment_hard_window_regrasp.npz``: arm A moves, B holds the
    object; the straight line between its ends passes 0.39 m deep through the wall) shortened by
    joint-space shortcuts: same ends, the holding arm's joints untouched, shorter, and every
    straight piece collision free when re-checked every 5 mrad by exact coal distances."""
    from optplan.collision.checker import CollisionChecker

    d = np.load(DATA / "segment_hard_window_regrasp.npz")
    path, scene, arm = np.asarray(d["path"], float), Scene.load(str(d["scene"])), str(d["arm"])
    holder = next(a for a in PL._held_object(scene).grasps if a != arm)
    chk = CollisionChecker(tcb, scene, object_arm=holder)

    def dense(P, step=0.005):
        return np.vstack([P[k] + np.linspace(0, 1, max(2, int(np.ceil(np.abs(P[k + 1] - P[k]).max() / step))) + 1)[:, None]
                          * (P[k + 1] - P[k]) for k in range(len(P) - 1)])

    assert chk.min_distance_along(dense(path[[0, -1]]))[0] < -0.1, "the straight line should cross the wall"
    out = PL.shortcut_free(tcb, scene, path, np.random.default_rng(0), 40, chk)
    L = lambda P: float(np.linalg.norm(np.diff(P, axis=0), axis=1).sum())  # noqa: E731
    assert len(out) < len(path) and L(out) < L(path) - 1.0
    np.testing.assert_array_equal(out[[0, -1]], path[[0, -1]])
    idx = tcb.arm(holder).j_idx
    np.testing.assert_array_equal(out[:, idx], np.broadcast_to(path[0, idx], out[:, idx].shape))
    assert chk.min_distance_along(dense(out))[0] > 0.0
    # every kept configuration is one of the planner's
    assert all(np.any(np.all(path == q, axis=1)) for q in out)
    with pytest.raises(ValueError):
        PipelineOptions(free_shortcut_attempts=-1)
