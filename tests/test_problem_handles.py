"""Term handles on solutions (Drake-style bindings), the immutable Solution with its attempts, the
NLP core's options and the frozen terms.

Independent references: Pinocchio's numeric evaluation of each term (``term.numeric``) for
``Solution.value``; a central finite difference of the optimal cost with respect to a bound (a
re-solved NLP) for ``Solution.dual``; the values at the knots for ``Solution.sample`` along the
continuous trajectory.
"""
from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pytest

from optplan.errors import ConfigurationError, OptionError
from optplan.problem import (
    BaseAttitude,
    ClosedChain,
    CollisionAvoidance,
    FramePose,
    IpoptStatus,
    JointBoundary,
    JointPositionLimits,
    JointVelocityLimits,
    OptProblem,
    OrientationConstraint,
    Smoothness,
    Solution,
    SolveOutcome,
    SolverOptions,
)
from optplan.problem.nlp import NlpSolver
from optplan.scene import Scene

Z = np.zeros(14)


@pytest.fixture(scope="module")
def cc_problem(tcb):
    """A small closed-chain transport: both ends pinned on the manifold, velocity limits, jerk cost."""
    from optplan.constraints.closed_chain import project_closed_chain

    rng = np.random.default_rng(3)
    qa = tcb.random_joints(rng) * 0.4
    cc = ClosedChain.from_configuration(tcb, qa)
    qb = project_closed_chain(tcb, qa + rng.normal(size=14) * 0.15, cc).q
    prob = OptProblem(tcb, n_intervals=6, duration=4.0)
    prob.add_constraint(JointBoundary("start", q=qa, qd=Z, qdd=Z))
    prob.add_constraint(JointBoundary("end", q=qb, qd=Z, qdd=Z))
    h_cc = prob.add_constraint(cc)
    h_v = prob.add_constraint(JointVelocityLimits())
    h_o = prob.add_constraint(OrientationConstraint(tcb.arm("A").ee_frame, max_angle=np.pi))
    h_j = prob.add_cost(Smoothness("jerk"), weight=2.0)
    prob.set_initial_straight_line(qa, qb)
    # handles on this grid (N = 6: the closed chain drifts between knots; the dense check and its
    # refinement are tested in test_guarantees.py)
    sol = prob.solve(tol=1e-9, guarantees=False)
    assert sol.success, sol.status
    return prob, sol, {"cc": h_cc, "v": h_v, "o": h_o, "j": h_j}


# --------------------------------------------------------------------------- value
def test_value_matches_pinocchio_evaluation(cc_problem):
    prob, sol, h = cc_problem
    traj = prob.numeric_trajectory(sol.x)
    v = sol.value(h["cc"])
    assert v.shape == (prob.N + 1, 7)                            # per knot: 6 pose rows + trace
    np.testing.assert_allclose(v.ravel(), h["cc"].term.numeric(traj), atol=1e-10)
    np.testing.assert_allclose(sol.value(h["v"]), sol.qd, atol=1e-12)   # bound term: the bounded variables
    np.testing.assert_allclose(sol.value(h["o"]).ravel(), h["o"].term.numeric(traj), atol=1e-10)
    assert sol.value(h["j"]) == pytest.approx(2.0 * Smoothness("jerk").cost_numeric(traj), rel=1e-7)
    assert sol.value("closed_chain").shape == v.shape             # names work as handles


def test_violation_is_nonnegative_and_zero_at_a_feasible_solution(cc_problem):
    prob, sol, h = cc_problem
    for k in ("cc", "v", "o"):
        viol = sol.violation(h[k])
        assert viol.shape == np.shape(sol.value(h[k]))
        assert np.all(viol >= 0) and viol.max() <= 1e-8
    with pytest.raises(TypeError, match="cost"):
        sol.violation(h["j"])
    assert prob.infeasibilities(sol) == [] or max(r.violation for r in prob.infeasibilities(sol)) <= 1e-8


def test_sample_equals_value_at_the_knots_and_is_continuous(cc_problem):
    prob, sol, h = cc_problem
    # at the knots: the same (up to the integration rows' tolerance: the last knot is reached through
    # the last interval's cubic)
    np.testing.assert_allclose(sol.sample(sol.t, h["cc"]), sol.value(h["cc"]), atol=1e-7)
    np.testing.assert_allclose(sol.sample(sol.t, h["v"]), sol.value(h["v"]), atol=1e-7)
    t = np.linspace(sol.t[0], sol.t[-1], 61)
    s = sol.sample(t, h["cc"])
    assert s.shape == (61, 7)
    # between knots the closed chain drifts (the verify figure), but only slightly on this smooth motion
    assert np.abs(s[:, :6]).max() < 1e-2
    np.testing.assert_allclose(sol.sample(t, h["v"]), sol.sample(t)["qd"], atol=1e-12)
    with pytest.raises(TypeError, match="given knots"):
        sol.sample(t, "boundary")


def test_dual_of_an_equality_is_the_sensitivity_of_the_optimal_cost(tcb):
    """∂f*/∂b for the end-position rows of a rest-to-rest jerk problem: dual vs a central finite
    difference of the re-solved optimal cost (b moved by ±ε in both bounds of one row)."""
    rng = np.random.default_rng(11)
    qa, qb = tcb.random_joints(rng) * 0.3, tcb.random_joints(rng) * 0.3

    def solve(qend):
        p = OptProblem(tcb, n_intervals=4, duration=2.0)
        p.add_constraint(JointBoundary("start", q=qa, qd=Z, qdd=Z))
        h = p.add_constraint(JointBoundary("end", q=qend, qd=Z, qdd=Z))
        p.add_cost(Smoothness("jerk"))
        p.set_initial_straight_line(qa, qend)
        s = p.solve(tol=1e-11)
        assert s.success
        return s, h

    sol, h = solve(qb)
    dual = sol.dual(h)
    assert dual.shape == (1, 42)
    eps = 1e-4
    for j in (0, 5, 13):
        e = np.zeros(14)
        e[j] = eps
        fd = (solve(qb + e)[0].cost - solve(qb - e)[0].cost) / (2 * eps)
        assert dual[0, j] == pytest.approx(fd, rel=1e-4, abs=1e-8 * max(1.0, abs(fd)))
        assert abs(fd) > 1e-3          # a real sensitivity, not two zeros


def test_dual_of_active_velocity_bounds_is_the_sensitivity_to_the_limit(tcb):
    """``|q̇| ≤ v`` as variable bounds (scaled variables): the optimal cost's derivative with
    respect to v equals Σ dual·∂bound/∂v over the rows (+1 for upper, −1 for lower bounds), i.e.
    −Σ|dual| over active rows: duals ≥ 0 at active lower, ≤ 0 at active upper bounds."""
    rng = np.random.default_rng(2)
    qa = tcb.random_joints(rng) * 0.3
    qb = qa + 0.8

    def solve(v):
        p = OptProblem(tcb, n_intervals=8, duration=2.0)
        p.add_constraint(JointBoundary("start", q=qa, qd=Z, qdd=Z))
        p.add_constraint(JointBoundary("end", q=qb, qd=Z, qdd=Z))
        h = p.add_constraint(JointVelocityLimits(limit=v))
        p.add_cost(Smoothness("acceleration"))
        p.set_initial_straight_line(qa, qb)
        s = p.solve(tol=1e-11, objective_scaling=1.0)
        assert s.success, s.status
        return s, h

    v = 0.6           # the unconstrained optimum peaks at 0.656 rad/s
    sol, h = solve(v)
    dual = sol.dual(h)
    qd = sol.value(h)
    upper, lower = qd > v - 1e-6, qd < -v + 1e-6
    assert upper.any(), "the limit must be active for the test to mean something"
    assert np.all(dual[upper] <= 1e-8) and np.all(dual[lower] >= -1e-8)
    assert np.abs(dual[~(upper | lower)]).max() < 1e-5
    predicted = dual[upper].sum() - dual[lower].sum()
    eps = 1e-4
    fd = (solve(v + eps)[0].cost - solve(v - eps)[0].cost) / (2 * eps)
    assert predicted == pytest.approx(fd, rel=2e-3)
    assert fd < 0


# --------------------------------------------------------------------------- infeasibilities
def test_infeasibilities_rank_the_worst_rows_by_term(tcb):
    """A closed chain that the pinned end configuration violates: the worst rows are closed-chain
    rows at the end knot, in decreasing order, matching Solution.violation."""
    rng = np.random.default_rng(5)
    qa = tcb.random_joints(rng) * 0.4
    cc = ClosedChain.from_configuration(tcb, qa)
    qb = qa + 0.3                                    # off the manifold
    p = OptProblem(tcb, n_intervals=5, duration=3.0)
    p.add_constraint(JointBoundary("start", q=qa, qd=Z, qdd=Z))
    p.add_constraint(JointBoundary("end", q=qb, qd=Z, qdd=Z))
    h = p.add_constraint(cc)
    p.add_cost(Smoothness("jerk"))
    p.set_initial_straight_line(qa, qb)
    sol = p.solve(max_iter=30)
    assert not sol.success
    worst = p.infeasibilities(sol, n=5)
    assert len(worst) == 5
    v = [r.violation for r in worst]
    assert v == sorted(v, reverse=True) and v[0] > 1e-3
    all_rows = np.concatenate([np.ravel(sol.violation(n)) for n in ("boundary", "boundary_2", "closed_chain")])
    assert v[0] == pytest.approx(max(all_rows.max(), sol.terms["dynamics"]))
    top = worst[0]
    if top.term == "closed_chain":
        assert top.point is not None and sol.violation(h)[top.point if isinstance(top.point, int) else 0].max() \
            == pytest.approx(top.violation)
    assert "not in" in str(top)
    with pytest.raises(ValueError, match="integer"):
        p.infeasibilities(sol, n=-1)
    other = OptProblem(tcb, n_intervals=5, duration=3.0)
    with pytest.raises(ValueError, match="not produced by this problem"):
        other.infeasibilities(sol)


# --------------------------------------------------------------------------- immutability, attempts, files
def test_solution_is_immutable_and_lists_attempts(cc_problem, tmp_path):
    prob, sol, h = cc_problem
    with pytest.raises(dataclasses.FrozenInstanceError):
        sol.success = False
    with pytest.raises(ValueError):
        sol.q[0, 0] = 1.0                                      # read-only arrays
    with pytest.raises(TypeError):
        sol.terms["closed_chain"] = 0.0                        # read-only mapping
    assert len(sol.attempts) == 1 and isinstance(sol.attempts[0], SolveOutcome)
    a = sol.attempts[0]
    assert a.status == sol.status and a.iterations == sol.iterations and a.x is None
    both = sol.after(sol)
    assert len(both.attempts) == 2 and both.total_iterations == 2 * sol.iterations
    assert both.total_wall_time == pytest.approx(2 * sol.wall_time) and both.iterations == sol.iterations
    assert sol.labelled("refine").attempts[-1].label == "refine"
    for suffix in (".npz", ".json"):
        path = both.save(tmp_path / f"s{suffix}")
        back = Solution.load(path)
        assert back.success == both.success and back.status == both.status
        assert [x.to_dict() for x in back.attempts] == [x.to_dict() for x in both.attempts]
        np.testing.assert_array_equal(back.q, both.q)
        with pytest.raises(ValueError, match="no problem"):
            back.value("closed_chain")
    # a file written before attempts and CPU time were saved still loads (one attempt from its fields)
    d = json.loads((tmp_path / "s.json").read_text())
    d.pop("attempts"), d.pop("cpu_time")
    (tmp_path / "old.json").write_text(json.dumps(d))
    old = Solution.load(tmp_path / "old.json")
    assert len(old.attempts) == 1 and old.attempts[0].iterations == both.iterations


# --------------------------------------------------------------------------- options
@pytest.mark.parametrize("kwargs, match", [
    ({"tol": 0.0}, "tol"), ({"tol": float("nan")}, "tol"), ({"tol": "1e-6"}, "tol"),
    ({"max_iter": -1}, "max_iter"), ({"max_iter": 2.5}, "max_iter"), ({"max_iter": True}, "max_iter"),
    ({"max_wall_time": 0.0}, "max_wall_time"), ({"max_cpu_time": -3}, "max_cpu_time"),
    ({"print_level": 13}, "print_level"), ({"hessian": "bfgs"}, "hessian"),
    ({"linear_solver": "no_such_solver"}, "linear_solver"), ({"linear_solver": 3}, "linear_solver"),
    ({"raw": {"no_such_option": 1}}, "no_such_option"), ({"raw": {"tol": -1.0}}, "tol"), ({"raw": "tol=1"}, "raw"),
])
def test_solver_options_refuse_bad_values_naming_them(kwargs, match):
    with pytest.raises(OptionError, match=match):
        SolverOptions(**kwargs)


def test_solver_options_merge_order_and_immutability():
    o = SolverOptions(tol=1e-7, max_iter=3, max_wall_time=2.0, raw={"ipopt.tol": 1e-5, "mu_strategy": "adaptive"})
    c = o.casadi_options({"tol": 1e-3, "max_iter": 100, "mumps_pivot_order": 0})
    assert c["ipopt.tol"] == 1e-5 and c["ipopt.max_iter"] == 3 and c["ipopt.max_wall_time"] == 2.0
    assert c["ipopt.mu_strategy"] == "adaptive" and c["ipopt.mumps_pivot_order"] == 0
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.tol = 1.0
    with pytest.raises(TypeError):
        o.raw["tol"] = 1.0
    assert SolverOptions.coerce({"tol": 1e-4}).raw["tol"] == 1e-4
    assert SolverOptions.coerce(o, max_iter=9).max_iter == 9
    with pytest.raises(OptionError, match="SolverOptions"):
        SolverOptions.coerce(42)


def test_nlp_solver_outcomes_are_statuses():
    import casadi as ca

    x = ca.MX.sym("x", 2)
    s = NlpSolver("t", {"x": x, "f": ca.sumsqr(x - 1), "g": x[0] + x[1]}, SolverOptions(tol=1e-10))
    out = s.solve(np.zeros(2), lbg=0.0, ubg=0.0)
    assert out.status is IpoptStatus.SOLVE_SUCCEEDED and out.success and out.setup_time > 0
    np.testing.assert_allclose(out.x, [0, 0], atol=1e-8)
    # ∂f*/∂b for x0 + x1 = b at b = 0: f* = 2 (1 − b/2)² → −2; CasADi's lam_g = +2
    assert out.lam_g[0] == pytest.approx(2.0, rel=1e-6)
    assert s.solve(np.zeros(2), lbg=0.0, ubg=0.0).setup_time == 0.0          # created once
    capped = NlpSolver("t", {"x": x, "f": ca.sumsqr(x - 1), "g": x[0] + x[1]}, SolverOptions(max_iter=0))
    assert capped.solve(np.full(2, 5.0), lbg=0.0, ubg=0.0).status is IpoptStatus.MAXIMUM_ITERATIONS_EXCEEDED


def test_optproblem_solve_takes_solver_options(cc_problem):
    prob, sol, h = cc_problem
    prob.set_initial_straight_line(sol.q[0], sol.q[-1])
    capped = prob.solve(options=SolverOptions(max_iter=0))
    assert capped.status is IpoptStatus.MAXIMUM_ITERATIONS_EXCEEDED and not capped.success
    with pytest.raises(OptionError, match="SolverOptions"):
        prob.solve(options={"max_iter": 0})


# --------------------------------------------------------------------------- frozen, validated terms
@pytest.mark.parametrize("make, match", [
    (lambda r: JointBoundary("middle", q=Z), "at"),
    (lambda r: JointBoundary("start"), "at least one"),
    (lambda r: JointBoundary("start", q=[0.0, float("nan")]), "JointBoundary.q"),
    (lambda r: FramePose(r.arm("A").ee_frame, None), "target"),
    (lambda r: FramePose("", None), "frame"),
    (lambda r: OrientationConstraint(r.arm("A").ee_frame, axis_local=(0, 0, 0)), "axis_local"),
    (lambda r: OrientationConstraint(r.arm("A").ee_frame, max_angle=4.0), "max_angle"),
    (lambda r: ClosedChain(interior=-1), "interior"),
    (lambda r: JointVelocityLimits(limit=-1.0), "limit"),
    (lambda r: JointPositionLimits(lower=np.ones(14), upper=np.zeros(14)), "lower > upper"),
    (lambda r: Smoothness("snap"), "order"),
    (lambda r: CollisionAvoidance(None, margin=-0.1), "margin"),
    (lambda r: CollisionAvoidance(None, window=-1), "window"),
    (lambda r: CollisionAvoidance("transport"), "scene"),
])
def test_terms_are_validated_when_created(tcb, make, match):
    with pytest.raises(ConfigurationError, match=match):
        make(tcb)


def test_terms_are_frozen_configurations(tcb):
    cc = ClosedChain.from_configuration(tcb, Z)
    cc2 = dataclasses.replace(cc, interior=1)
    assert cc.interior == 0 and cc2.interior == 1
    with pytest.warns(DeprecationWarning, match="dataclasses.replace"):
        cc.skip_pinned = True                            # the old in-place style: warned (and validated)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        with pytest.raises(ConfigurationError, match="interior"):
            cc.interior = -2
    col = CollisionAvoidance(Scene.load("transport"), margin=0.01)
    assert dict(col.margin_boost) == {} and col.activate_with == ()
    with pytest.raises(TypeError):
        col.margin_boost[("a", 0)] = 1.0


def test_replace_term_rebuilds_with_the_new_term(cc_problem):
    prob, sol, h = cc_problem
    h_v = prob.terms["velocity_limits"]
    new = prob.replace_term(h_v, JointVelocityLimits(limit=0.05))
    assert new.name == h_v.name and prob.terms[new.name].term.limit == 0.05
    idx, lo, hi = prob.term_data(new).var_bounds
    assert np.allclose(hi / prob.term_data(new).var_scale, 0.05)
    with pytest.raises(KeyError, match="replaced"):
        prob.solve(max_iter=1).value(h_v)
    prob.replace_term(new, h_v.term)                     # restore for the other tests of this module


# --------------------------------------------------------------------------- the documented user term
def test_user_defined_term_of_the_docs(tcb):
    """The worked example of docs/optproblem.md ("Extending: add a term"): a user term's rows agree
    with its Pinocchio evaluation, its handle works on the solution, and it is enforced."""
    from dataclasses import dataclass

    import casadi as ca

    from optplan.problem import Term, TermData

    @dataclass(eq=False)
    class AboveTable(Term):
        frame: str = ""
        z_min: float = 0.0
        default_name = "above_table"

        def _validate(self):
            if not self.frame:
                raise ConfigurationError(f"AboveTable.frame: expected a frame name, got {self.frame!r}")
            if not np.isfinite(self.z_min):
                raise ConfigurationError(f"AboveTable.z_min: expected a finite height [m], got {self.z_min!r}")

        def rows(self, ctx):
            z = ca.vertcat(*[ctx.tp.frame(self.frame, k)[1][2] for k in range(ctx.N + 1)])
            return TermData(residual=z, lower=np.full(ctx.N + 1, self.z_min), upper=np.full(ctx.N + 1, np.inf),
                            points=tuple(range(ctx.N + 1)), point_rows=1)

        def numeric(self, traj):
            return np.array([traj.frame(self.frame, k).translation[2] for k in range(traj.N + 1)])

        def bounds_numeric(self, traj):
            return np.full(traj.N + 1, self.z_min), np.full(traj.N + 1, np.inf)

        def sampled(self):
            return self

    with pytest.raises(ConfigurationError, match="frame"):
        AboveTable("", 0.3)
    rng = np.random.default_rng(4)
    qa, qb = tcb.random_joints(rng) * 0.3, tcb.random_joints(rng) * 0.3
    frame = tcb.arm("A").ee_frame
    probe = OptProblem(tcb, n_intervals=5, duration=3.0)
    probe.set_initial_straight_line(qa, qb)
    z_guess = AboveTable(frame, 0.0).numeric(probe.numeric_trajectory(probe.initial_guess))
    z_min = float(z_guess.min() + 0.5 * np.ptp(z_guess[1:-1]) + 1e-3)   # binding in the middle of the motion
    z_min = min(z_min, float(min(z_guess[0], z_guess[-1])) - 1e-3)       # the pinned ends satisfy it
    prob = OptProblem(tcb, n_intervals=5, duration=3.0)
    prob.add_constraint(JointBoundary("start", q=qa, qd=Z, qdd=Z))
    prob.add_constraint(JointBoundary("end", q=qb, qd=Z, qdd=Z))
    h = prob.add_constraint(AboveTable(frame, z_min))
    prob.add_cost(Smoothness("jerk"))
    prob.set_initial_straight_line(qa, qb)
    sol = prob.solve(tol=1e-9)
    assert sol.success, sol.status
    np.testing.assert_allclose(sol.value(h).ravel(), h.term.numeric(prob.numeric_trajectory(sol.x)), atol=1e-10)
    assert sol.value(h).min() >= z_min - 1e-8 and sol.violation(h).max() <= 1e-8
    assert np.all(sol.dual(h) >= -1e-8) and sol.dual(h).max() > 1e-6   # lower bounds only; one is active
    np.testing.assert_allclose(sol.sample(sol.t, h), sol.value(h), atol=1e-7)


def test_sample_on_a_floating_base_matches_the_knots(eba):
    """Free-floating robot: the base attitude and a closed chain sampled at the knots equal their
    values there (the base quaternion is interpolated between knots, exact at them); at an iterate
    that is not a solution (max_iter=0) the handles still evaluate it."""
    rng = np.random.default_rng(8)
    q0 = eba.random_joints(rng) * 0.2
    prob = OptProblem(eba, n_intervals=3, duration=2.0)
    prob.add_constraint(JointBoundary("start", q=q0, qd=np.zeros(eba.nj), qdd=np.zeros(eba.nj)))
    h_b = prob.add_constraint(BaseAttitude(target=None, at="all"))
    h_c = prob.add_constraint(ClosedChain.from_configuration(eba, eba.configuration(q0)))
    prob.set_initial_straight_line(q0, q0 + 0.2)
    sol = prob.solve(max_iter=0)
    assert sol.status is IpoptStatus.MAXIMUM_ITERATIONS_EXCEEDED
    for h in (h_b, h_c):
        np.testing.assert_allclose(sol.sample(sol.t, h), sol.value(h), atol=1e-9)
    t = np.linspace(0.0, sol.duration, 13)
    s = sol.sample(t, h_b)
    assert s.shape == (13, 4) and np.all(np.isfinite(s))
    assert np.all(sol.violation(h_b) >= 0) and sol.violation(h_c).max() > 0   # the guess leaves the manifold


def test_collision_retry_by_replacing_the_term(tcb):
    """The pipeline's collision retry without mutation: ``with_activation`` adds a trajectory whose
    close pairs are activated too (coal distances on either trajectory below ``activation``), and
    ``replace_term`` rebuilds the NLP with it; the original term is unchanged."""
    from optplan.collision.checker import CollisionChecker

    scene = Scene.load("transport")
    rng = np.random.default_rng(21)
    Q1 = np.array([tcb.random_joints(rng) * 0.5 for _ in range(4)])
    Q2 = np.array([tcb.random_joints(rng) * 0.5 for _ in range(4)])
    prob = OptProblem(tcb, n_intervals=3, duration=3.0)
    col = CollisionAvoidance(scene, activation=0.1, window=0, held_object=False)
    h = prob.add_constraint(col)
    prob.set_initial(q=Q1)
    before = set(prob.term_data(h).info["active_pairs"])
    other = OptProblem(tcb, n_intervals=3, duration=3.0)
    other.set_initial(q=Q2)
    col2 = col.with_activation(other.numeric_trajectory(other.initial_guess))
    assert col.activate_with == () and len(col2.activate_with) == 1
    h2 = prob.replace_term(h, col2)
    after = set(prob.term_data(h2).info["active_pairs"])
    chk = CollisionChecker(tcb, scene, held_object=False)
    D = np.minimum(np.array([chk.distances(q) for q in Q1]), np.array([chk.distances(q) for q in Q2]))
    expect = {p for i, p in enumerate(chk.pairs) if (D[:, i] < 0.1).any()}
    assert after == expect and before <= after and len(after) > len(before)


def test_results_options_and_terms_pickle(cc_problem, tcb):
    """Process pools (the benchmark engine) pickle results: a Solution keeps everything but its
    evaluator (handles then ask for the problem), options and terms stay frozen."""
    import pickle

    prob, sol, h = cc_problem
    back = pickle.loads(pickle.dumps(sol))
    np.testing.assert_array_equal(back.q, sol.q)
    assert dict(back.terms) == dict(sol.terms) and back.attempts == sol.attempts
    with pytest.raises(ValueError):
        back.q[0, 0] = 0.0
    with pytest.raises(ValueError, match="no problem"):
        back.value(h["cc"])
    o = pickle.loads(pickle.dumps(SolverOptions(tol=1e-7, raw={"mu_strategy": "adaptive"})))
    assert o.raw["mu_strategy"] == "adaptive" and o.tol == 1e-7
    col = CollisionAvoidance(Scene.load("transport"), margin=0.01, margin_boost={})
    col2 = pickle.loads(pickle.dumps(col))
    assert col2.margin == 0.01 and dict(col2.margin_boost) == {}
    cc = pickle.loads(pickle.dumps(h["cc"].term))
    np.testing.assert_allclose(cc.relative.homogeneous, h["cc"].term.relative.homogeneous)
