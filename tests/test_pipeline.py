"""The plan → shortcut → resample → optimize → verify pipeline (issue 4, item 4)."""
import numpy as np
import pinocchio as pin
import pytest

from optplan.collision.checker import CollisionChecker
from optplan.pipeline import PipelineOptions, PipelineResult, shortcut_constrained
from optplan.scene import Scene
from optplan.tasks import grasp_configuration, straight_line_poses, task_space_path


@pytest.fixture(scope="module")
def transport(tcb):
    sc = Scene.load("transport")
    rng = np.random.default_rng(3)
    chk = CollisionChecker(tcb, sc)
    for _ in range(20):
        g = grasp_configuration(tcb, sc, sc.start, rng, checker=chk)
        mid = pin.SE3(sc.start.rotation, sc.start.translation + np.array([-0.3, 0.0, 0.3]))
        poses = straight_line_poses(sc.start, mid, 6)[:-1] + straight_line_poses(mid, sc.start * pin.SE3(
            np.eye(3), np.array([0.0, 0.0, 0.0])), 6)
        Q, ok = task_space_path(tcb, sc, g.q, poses)
        if ok and all(chk.is_valid(q) for q in Q):
            return sc, Q
    pytest.skip("no valid detour path found")


def _closure(robot, scene, q):
    d = robot.model.createData()
    pin.framesForwardKinematics(robot.model, d, q)
    Ma, Mb = d.oMf[robot.arm("A").ee_frame_id], d.oMf[robot.arm("B").ee_frame_id]
    rel = Ma.actInv(Mb)
    ref = scene.object.grasps["A"].actInv(scene.object.grasps["B"])
    e = ref.actInv(rel)
    return max(np.linalg.norm(e.translation), np.linalg.norm(pin.log3(e.rotation)))


def test_shortcut_keeps_ends_closure_and_validity_and_shortens(tcb, transport):
    sc, Q = transport
    chk = CollisionChecker(tcb, sc)
    out = shortcut_constrained(tcb, sc, Q, np.random.default_rng(0), attempts=30, checker=chk)
    np.testing.assert_allclose(out[0], Q[0])
    np.testing.assert_allclose(out[-1], Q[-1])
    assert all(_closure(tcb, sc, q) < 1e-8 for q in out)
    assert all(chk.is_valid(q) for q in out)
    L = lambda P: np.linalg.norm(np.diff(P, axis=0), axis=1).sum()  # noqa: E731
    assert L(out) <= L(Q) + 1e-12
    assert L(out) < 0.9 * L(Q)  # the detour out and back is shortened


def test_pipeline_result_reports_failed_plan_as_status():
    class _Plan:
        success = False
        n_regrasp = 0

        class status:  # noqa: N801
            value = "timeout"

    res = PipelineResult(plan=_Plan())
    d = res.to_dict()
    assert d["success"] is False and d["plan_status"] == "timeout" and d["opt_status"] == "not_run"


def test_options_validated():
    with pytest.raises(ValueError):
        PipelineOptions(n_intervals=1)
    with pytest.raises(ValueError, match="plan_clock.*'sun'"):
        PipelineOptions(plan_clock="sun")


def test_removed_closed_segment_nlp_is_a_clear_option_error():
    """The closed segment class is retired: asking for it (options or the benchmark's flag) is an
    OptionError that says it was removed and what to use; any other value is named too."""
    import importlib

    from optplan.bench.warmstart import WarmstartConfig, validate
    from optplan.errors import OptionError

    with pytest.raises(OptionError, match=r"segment_nlp: 'closed' was removed.*use 'optproblem'"):
        PipelineOptions(segment_nlp="closed")
    with pytest.raises(OptionError, match=r"--segment-nlp: 'closed' was removed"):
        validate(WarmstartConfig(segment_nlp="closed"))
    with pytest.raises(OptionError, match=r"expected 'optproblem', got 'knots'"):
        PipelineOptions(segment_nlp="knots")
    assert PipelineOptions().segment_nlp == "optproblem"
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("optplan.problem.segment_closed")


def test_pipeline_scene1_trial(tcb, tmp_path):
    """The README's main job end to end (one trial of scene 1, ~15-30 s): planned (on the CPU
    clock: the planner gets the clock), every segment solved, the closed chain held to 1e-6 and
    positive clearance by the independent verify, and the saved trajectory has the documented
    keys, with ``constrained`` false inside regrasps."""
    from optplan.pipeline import run_pipeline
    from optplan.trials import TrialGenerator

    sc = Scene.load("ssps_scene1")
    tr = TrialGenerator(tcb, sc).generate(4, 0)
    res = run_pipeline(tcb, sc, tr.q_start, tr.q_goal, PipelineOptions(plan_clock="cpu"), seed=int(tr.seed))
    assert res.plan.success and res.plan.stats["clock"] == "cpu"
    assert res.success, res.to_dict()
    assert res.max_closed_chain_residual <= 1e-6 and res.min_clearance_m >= 0.0
    assert res.q.shape[1] == tcb.nq and res.constrained.shape == res.t.shape
    d = res.to_dict()
    for k in ("plan_status", "plan_time_s", "opt_status", "opt_time_s", "max_closed_chain_residual",
              "min_clearance_m", "n_regrasp"):
        assert k in d
    assert (res.n_regrasp > 0) == (not res.constrained.all())
    res.save(tmp_path / "traj.npz")
    with np.load(tmp_path / "traj.npz") as z:
        assert set(z.files) >= {"t", "q", "joint_names", "constrained"}
        assert np.all(np.diff(z["t"]) > 0)


def _scene1_plan(tcb):
    """Scene 1, trial 4: (scene, a successful TCBiRRT plan) for the segment-retry logic tests."""
    from optplan.planners import make_planner
    from optplan.trials import TrialGenerator

    sc = Scene.load("ssps_scene1")
    tr = TrialGenerator(tcb, sc).generate(4, 0)
    # the search of the NumPy-stream sampler ("native" = "python"): the tests below read this plan's segments
    plan = make_planner("tcbirrt", tcb, sc, extension="native").plan(tr.q_start, tr.q_goal, time_limit=10.0,
                                                                     seed=int(tr.seed))
    assert plan.success
    return sc, plan


def test_failed_segment_is_retried_on_a_finer_grid(tcb, monkeypatch):
    """A segment whose NLP fails is re-solved once on a 1.6× finer grid; one whose closed chain
    drifts between knots beyond closed_chain_tol is refined by (residual / (tol/2))^¼ (fake solves:
    the logic only)."""
    from types import SimpleNamespace

    import optplan.pipeline as PL
    sc, plan = _scene1_plan(tcb)
    calls = []

    def fake_solve(robot, scene, prob, cc, holder, opts, ipopt, kind):
        calls.append((kind, prob.N))
        first = len(calls) == 1
        sol = _fake_solution(prob, not first, "Maximum_Iterations_Exceeded")
        rep = SimpleNamespace(max_closed_chain_residual=(0.0 if first else 8e-6), min_clearance_m=0.01)
        if kind == "constrained" and len(calls) > 2:
            rep.max_closed_chain_residual = 1e-7
        return sol, rep

    monkeypatch.setattr(PL, "_solve_verified", fake_solve)
    opts = PipelineOptions(shortcut_attempts=0, fixed_plane_normals=False, transcription="knots")
    results, _ = PL.optimize_segments(tcb, sc, plan, opts, np.random.default_rng(0))
    (k0, n0), (k1, n1), (k2, n2) = calls[:3]
    assert k0 == k1 == k2 and n1 == min(opts.max_intervals, int(np.ceil(n0 * 1.6)))   # failure → 1.6×
    if k0 == "constrained":   # then the residual 8e-6 > 1e-6 → refined by (8e-6 / 5e-7)^¼ · 1.05
        assert n2 == min(opts.max_intervals, int(np.ceil(n1 * 1.05 * (8e-6 / 5e-7) ** 0.25)))
    # every attempt is listed (nothing is added up in place); the totals sum them
    assert len(results[0].solution.attempts) >= 2 and results[0].solution.total_iterations >= 20
    assert results[0].solution.total_iterations == sum(a.iterations for a in results[0].solution.attempts)

    # a solve that converges but still collides (after its collision retries) is retried too
    calls.clear()

    def colliding_solve(robot, scene, prob, cc, holder, opts, ipopt, kind):
        calls.append((kind, prob.N))
        sol = _fake_solution(prob, True, "Solve_Succeeded")
        return sol, SimpleNamespace(max_closed_chain_residual=1e-7, min_clearance_m=-0.005 if len(calls) == 1 else 0.01)

    monkeypatch.setattr(PL, "_solve_verified", colliding_solve)
    results, _ = PL.optimize_segments(tcb, sc, plan, opts, np.random.default_rng(0))
    (k0, n0), (k1, n1) = calls[:2]
    assert k0 == k1 and n1 == min(opts.max_intervals, int(np.ceil(n0 * 1.6)))
    assert results[0].report.min_clearance_m == 0.01


def _fake_solution(prob, success: bool, failed_status: str):
    """A Solution of ``prob``'s initial guess: 10 iterations, 1 s IPOPT, 0.5 s setup; converged
    when ``success``, else with ``failed_status``."""
    from optplan.problem.solution import IpoptStatus, Solution

    u = prob.tp.unpack(prob.initial_guess)
    status = IpoptStatus.SOLVE_SUCCEEDED if success else IpoptStatus.from_string(failed_status)
    return Solution(success, status, 10, 1.0, 1.0, 0.0, {}, np.linspace(0.0, 10.0, prob.N + 1), u["q"], u["qd"],
                    u["qdd"], u["jerk"], prob.robot.joint_names, setup_time=0.5)


def test_fixed_normal_failure_falls_back_to_free_normals(tcb, monkeypatch):
    """With fixed plane normals (the default), a failed segment NLP is first re-solved on the same
    grid with free normals, and later attempts keep free normals (fake solves: the logic only)."""
    from types import SimpleNamespace

    import optplan.pipeline as PL
    sc, plan = _scene1_plan(tcb)
    calls = []

    def fake_solve(robot, scene, prob, cc, holder, opts, ipopt, kind):
        calls.append((kind, prob.N, prob.terms["collision"].term.fixed_normals))
        sol = _fake_solution(prob, len(calls) != 1, "Infeasible_Problem_Detected")
        return sol, SimpleNamespace(max_closed_chain_residual=1e-7, min_clearance_m=0.01)

    monkeypatch.setattr(PL, "_solve_verified", fake_solve)
    opts = PipelineOptions(shortcut_attempts=0, transcription="knots")
    assert opts.fixed_plane_normals
    results, _ = PL.optimize_segments(tcb, sc, plan, opts, np.random.default_rng(0))
    (k0, n0, f0), (k1, n1, f1) = calls[:2]
    assert k0 == k1 and n0 == n1 and f0 and not f1
    assert all(f for _, _, f in calls[2:]), "the next segments start with fixed normals again"
    assert results[0].solution.success and results[0].solution.total_iterations == 20
    assert [a.status.value for a in results[0].solution.attempts] == ["Infeasible_Problem_Detected", "Solve_Succeeded"]


def _fake_policy(tcb, monkeypatch, reports):
    """Scene 1's first constrained segment, with OptProblem.solve and verify faked: each
    solve converges in 7 iterations at its initial guess, each verify returns the next (clearance,
    closed-chain residual) of ``reports``. Returns (scene, segment path, intervals of every solve)."""
    from types import SimpleNamespace

    import optplan.pipeline as PL
    from optplan.problem import OptProblem
    from optplan.problem.solution import IpoptStatus, Solution
    from optplan.segment_nlp import guess_knots

    sc, plan = _scene1_plan(tcb)
    seg = next(s for s in plan.segments if s.kind == "constrained")
    seg_path = np.asarray(plan.path[seg.start:seg.stop + 1])
    reports = iter(reports)
    Ns: list[int] = []

    def fake_solve(self, ipopt=None, **kw):
        Ns.append(self.N)
        Q = guess_knots(self)
        z = np.zeros_like(Q)
        return Solution(True, IpoptStatus.SOLVE_SUCCEEDED, 7, 0.1, 1.0, 0.0, {}, np.linspace(0, self.duration, self.N + 1),
                        Q, z, z, z[:-1], tcb.joint_names, setup_time=0.05)

    def fake_verify(robot, sol, scene, closed_chain=None, object_arm=None):
        c, r = next(reports)
        return SimpleNamespace(min_clearance_m=c, max_closed_chain_residual=r, min_clearance_pair="x")

    monkeypatch.setattr(OptProblem, "solve", fake_solve)
    monkeypatch.setattr(PL, "verify", fake_verify)
    return sc, seg_path, Ns


def test_spline_segment_retry_policy(tcb, monkeypatch):
    """The B-spline path's ordered retries (fake solves and reports: the logic only): a contact coal
    finds after a converged solve → re-solve with more pairs; a closed-chain residual above the
    tolerance → a finer grid warm-started from the solution; each attempt is recorded in order."""
    import optplan.pipeline as PL

    sc, seg_path, Ns = _fake_policy(tcb, monkeypatch, [(-0.01, 1e-7), (0.01, 5e-6), (0.01, 2e-7)])
    opts = PipelineOptions(shortcut_attempts=0)
    sol, rep, attempts = PL._spline_segment(tcb, sc, seg_path, "constrained", None, opts, {})
    assert [a["reason"] for a in attempts] == ["initial", "collision", "refine"]
    assert Ns[0] == Ns[1] < Ns[2]
    assert Ns[2] == int(np.ceil(Ns[1] * 1.05 * (5e-6 / 0.5e-6) ** 0.25))
    assert sol.total_iterations == 21 and sol.total_wall_time == pytest.approx(0.3)
    assert len(sol.attempts) == 3 and sol.iterations == 7
    assert rep.max_closed_chain_residual == 2e-7


def test_refinement_may_pass_the_interval_cap_and_its_contacts_are_fixed(tcb, monkeypatch):
    """A segment at ``spline_max_intervals`` whose closed chain drifts between knots is refined
    beyond the cap (up to ``spline_refine_max_intervals``), and a contact coal finds in the refined
    solution gets its collision re-solve (fake solves and reports: the policy only)."""
    import optplan.pipeline as PL

    sc, seg_path, Ns = _fake_policy(tcb, monkeypatch, [(0.01, 5e-6), (-0.01, 2e-7), (0.01, 2e-7)])
    opts = PipelineOptions(shortcut_attempts=0, spline_min_intervals=30, spline_max_intervals=30,
                           spline_refine_max_intervals=60)
    sol, rep, attempts = PL._spline_segment(tcb, sc, seg_path, "constrained", None, opts, {})
    assert [a["reason"] for a in attempts] == ["initial", "refine", "collision"]
    assert Ns == [30, int(np.ceil(30 * 1.05 * (5e-6 / 0.5e-6) ** 0.25)), Ns[1]] and 30 < Ns[1] <= 60
    assert rep.min_clearance_m == 0.01
    with pytest.raises(ValueError, match="spline_refine_max_intervals"):
        PipelineOptions(spline_max_intervals=160, spline_refine_max_intervals=100)


def test_first_grid_cap_leaves_the_finer_grid_its_room(tcb, monkeypatch):
    """A long segment starts on ``spline_first_max_intervals`` intervals, not ⌈length / step⌉; when coal
    still finds a contact after the collision re-solves, the finer grid goes past that cap (1.6 ×, up to
    ``spline_max_intervals``) — fake solves and reports: the policy only."""
    import optplan.pipeline as PL

    opts = PipelineOptions(shortcut_attempts=0, spline_first_max_intervals=40, spline_max_intervals=160)
    reports = [(-0.01, 1e-7)] * (1 + opts.collision_retries) + [(0.01, 1e-7)] * 4
    sc, seg_path, Ns = _fake_policy(tcb, monkeypatch, reports)
    length = float(np.linalg.norm(np.diff(seg_path, axis=0), axis=1).sum())
    assert np.ceil(length / opts.spline_interval_step) > 40            # a segment the cap shortens
    sol, rep, attempts = PL._spline_segment(tcb, sc, seg_path, "constrained", None, opts, {})
    reasons = [a["reason"] for a in attempts]
    assert reasons == ["initial"] + ["collision"] * opts.collision_retries + ["finer-grid"]
    assert Ns == [40] * (1 + opts.collision_retries) + [64]
    assert rep.min_clearance_m == 0.01


def test_mumps_workspace_of_the_segments_changes_no_result(tcb):
    """``mumps_mem_percent`` 100 in the pipeline's IPOPT options (MUMPS's workspace, not the method):
    a segment's solve against IPOPT's own 1000 takes the same iterations to the same trajectory."""
    import optplan.pipeline as PL

    assert dict(PipelineOptions().ipopt_options)["mumps_mem_percent"] == 100
    sc, plan = _scene1_plan(tcb)
    seg = max((s for s in plan.segments if s.kind == "constrained"), key=lambda s: s.stop - s.start)
    path = np.asarray(plan.path[seg.start:seg.stop + 1])
    opts = PipelineOptions(shortcut_attempts=0)
    runs = [PL._spline_segment(tcb, sc, path, "constrained", None, opts, {**dict(opts.ipopt_options),
                                                                          "mumps_mem_percent": m})
            for m in (100, 1000)]
    (s0, r0, a0), (s1, r1, a1) = runs
    assert s0.success and r0.min_clearance_m >= 0.0 and r0.max_closed_chain_residual <= opts.closed_chain_tol
    assert [a["iterations"] for a in a0] == [a["iterations"] for a in a1] and a0[0]["iterations"] > 3
    np.testing.assert_allclose(s0.q, s1.q, rtol=0, atol=1e-9)


def test_compare_pipeline_options_example_pairs_variants_and_rejects_bad_json(capsys):
    """examples/compare_pipeline_options.py: bad --variants is exit 2 with one line; two variants
    that differ only in a setting the trial does not exercise give the same plan and optimum."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / "compare_pipeline_options.py"
    spec = importlib.util.spec_from_file_location("compare_pipeline_options", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main(["--variants", "[1]"]) == 2
    assert "--variants" in capsys.readouterr().err
    assert mod.main(["--variants", '{"a": {"no_such_field": 1}}']) == 2
    assert mod.main(["--scene", "1", "--trials", "1", "--variants",
                     '{"a": {}, "b": {"velocity_retries": 3}}']) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("ssps_scene1 t0")]
    assert len(lines) == 2
    strip = [ln.split(None, 3)[3] for ln in lines]  # everything after the variant name …
    assert [s.split("cpu=")[0] for s in strip][0] == [s.split("cpu=")[0] for s in strip][1]  # … up to the CPU time


def test_coarse_to_fine_records_the_coarse_attempt_and_verifies():
    """coarse_factor: the constrained segments start from a coarse grid's optimum (a ``coarse``
    attempt before ``initial``), and the trial still verifies."""
    import dataclasses

    from optplan.model.robot import RobotModel
    from optplan.pipeline import PipelineOptions, run_pipeline
    from optplan.scene import Scene
    from optplan.trials import TrialGenerator

    robot, scene = RobotModel.from_name("tcbirrt_dual_arm"), Scene.load("ssps_scene1")
    trial = TrialGenerator(robot, scene).generate(0, 0)
    res = run_pipeline(robot, scene, trial.q_start, trial.q_goal,
                       dataclasses.replace(PipelineOptions(), coarse_factor=3), seed=int(trial.seed))
    assert res.success
    cons = [s for s in res.segments if s.kind == "constrained"]
    assert cons and all(s.attempts[0]["reason"] == "coarse" and s.attempts[1]["reason"] == "initial"
                        and s.attempts[0]["N"] == -(-s.attempts[1]["N"] // 3) for s in cons)
    assert all(s.attempts[0]["reason"] != "coarse" for s in res.segments if s.kind == "regrasp")


def test_pipeline_segment_nlp_is_an_optproblem_that_honours_a_user_term(tcb):
    """The pipeline's segment NLP is an OptProblem on the B-spline core (every grid of the retry
    policy); a constraint the user adds through ``PipelineOptions.segment_terms`` holds in the
    verified result, where the same segment without it runs past the bound (so the test can fail)."""
    import optplan.pipeline as PL
    from optplan.problem import OptProblem

    sc, plan = _scene1_plan(tcb)
    seg = next(s for s in plan.segments if s.kind == "constrained")
    path = np.asarray(plan.path[seg.start:seg.stop + 1])
    seen: list[tuple[OptProblem, str]] = []
    opts = PipelineOptions(shortcut_attempts=0, segment_nlp="optproblem",
                           segment_terms=lambda p, kind: seen.append((p, kind)))
    sol0, rep0, _ = PL._spline_segment(tcb, sc, path, "constrained", None, opts, dict(opts.ipopt_options))
    assert sol0.success and rep0.min_clearance_m >= 0.0
    assert seen and all(isinstance(p, OptProblem) and p.uses_bspline() and k == "constrained" for p, k in seen)
    # the joint that overshoots its end values most: cap it at half of that overshoot
    Q = sol0.sample(np.linspace(0.0, sol0.duration, 20 * (len(sol0.t) - 1) + 1))["q"]
    top = np.maximum(path[0], path[-1])
    j = int(np.argmax(Q.max(axis=0) - top))
    over = float(Q[:, j].max() - top[j])
    assert over > 1e-3, "the segment should overshoot an end value somewhere"
    cap = float(top[j] + 0.5 * over)

    def cap_joint(p: OptProblem, kind: str) -> None:
        p.add_constraint(p.q[j], upper=cap, name="user_cap")

    opts1 = PipelineOptions(shortcut_attempts=0, segment_nlp="optproblem", segment_terms=cap_joint)
    assert PipelineOptions(segment_terms=cap_joint).segment_nlp == "optproblem"   # the default
    sol1, rep1, _ = PL._spline_segment(tcb, sc, path, "constrained", None, opts1, dict(opts1.ipopt_options))
    assert sol1.success and rep1.min_clearance_m >= 0.0
    assert float(sol1.q[:, j].max()) <= cap + 1e-6            # at the knots, where the row holds
    assert float(Q[:, j].max()) > cap + 0.25 * over           # without it the bound is passed
    assert "user_cap" in sol1.terms


def test_the_early_segment_worker_changes_no_result(tcb, monkeypatch):
    """``optplan plan --scene 1``'s job with its segment worker forked before planning (it imports the
    optimization stack while the plan is made), forked after it, and in one process: the same
    trajectory and iterations, verified."""
    import optplan.pipeline_workers as PW
    from optplan import workers
    from optplan.pipeline import PLANNER_DEFAULTS, run_pipeline
    from optplan.trials import TrialGenerator

    sc = Scene.load("ssps_scene1")
    tr = TrialGenerator(tcb, sc).generate(0, 0)
    po = PLANNER_DEFAULTS["tcbirrt"] + (("variant", "improved"),)
    runs, started = [], []
    start = PW.start_workers

    def start_workers(*a, **k):
        started.append(start(*a, **k))
        return started[-1]

    monkeypatch.setattr(PW, "start_workers", start_workers)
    # threads other tests of this process left (a progress bar's monitor) would stop the early fork;
    # its guard is tested in test_workers.py
    monkeypatch.setattr(workers.threading, "active_count", lambda: 1)
    for workers_, early in ((2, True), (2, False), (1, None)):
        workers.shutdown(wait=True)   # (an early fork needs this process to have one thread)
        opts = PipelineOptions(planner_options=po, workers=workers_, early_worker=early, plan_clock="cpu")
        res = run_pipeline(tcb, sc, tr.q_start, tr.q_goal, opts, seed=0)
        assert res.success, res.to_dict()
        if workers_ == 2:
            assert workers.workers_started((tcb, sc), 2)   # the pool the segments used (this context)
        runs.append(res)
    workers.shutdown(wait=True)
    assert started == [True]                                 # forked before planning in the first run only
    for res in runs[1:]:
        assert [s.solution.total_iterations for s in res.segments] == \
            [s.solution.total_iterations for s in runs[0].segments]
        np.testing.assert_array_equal(res.q, runs[0].q)


@pytest.mark.parametrize("core_free", [True, False])
def test_no_early_fork_when_the_segments_run_in_this_process(monkeypatch, core_free):
    """With one segment process nothing is forked before planning, whatever the load; with two the
    default (``early_worker=None``) forks exactly when a core is free, and an explicit choice wins."""
    from optplan import pipeline_workers as PW

    calls = []
    monkeypatch.setattr(PW, "_a_core_is_free", lambda: core_free)
    monkeypatch.setattr(PW, "start_workers", lambda ctx, n, warm: calls.append(n) or True)
    robot, scene = object(), object()
    for early in (None, True, False):
        assert PW.start_early_worker(robot, scene, PipelineOptions(workers=1, early_worker=early)) is False
    assert calls == []
    assert PW.start_early_worker(robot, scene, PipelineOptions(workers=2)) is core_free
    assert PW.start_early_worker(robot, scene, PipelineOptions(workers=2, early_worker=True)) is True
    assert PW.start_early_worker(robot, scene, PipelineOptions(workers=2, early_worker=False)) is False
    assert calls == [2] * (1 + core_free)
