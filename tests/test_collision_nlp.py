"""CollisionAvoidance (optplan.problem.collision_term) as NLP constraints, against coal.

(a) Conservativeness, evaluated on the NLP's own residual expressions (``term_function``) at
    random configurations of tcbirrt_dual_arm holding the transport object:
    * separating planes (pairs with a box): for ANY plane (n, b) with ‖n‖ ≤ 1 whose rows hold
      with margin m > 0, coal's exact distance is ≥ m; with coal's witness plane (the term's
      own initial plane) the certified margin equals the exact distance (the plane rows use the
      right vertices/radii, not a looser or wrong set);
    * smooth capsule distances (self pairs): ≤ coal's exact distance for separated pairs, and
      within the documented accuracy.
(b) End-to-end transport solve (N = 25): success; ``verify`` with coal: clearance ≥ 0 and
    closed-chain residual ≤ 1e-5 — while the straight-line initial guess collides.
(c) No nearby pairs: zero constraints, the problem still builds and solves.
"""
from __future__ import annotations

import time

import casadi as ca
import coal
import numpy as np
import pytest

from optplan.collision.checker import CollisionChecker
from optplan.constraints.closed_chain import solve_grasp_ik
from optplan.geometry.spatial import interpolate_pose
from optplan.model.ik import IKOptions
from optplan.problem import (
    ClosedChain,
    CollisionAvoidance,
    JointBoundary,
    JointPositionLimits,
    JointVelocityLimits,
    OptProblem,
    Smoothness,
)
from optplan.scene import Scene
from optplan.verification import verify


@pytest.fixture(scope="module")
def transport():
    return Scene.load("transport")


def _is_box_side(chk: CollisionChecker, kind: str, idx: int) -> bool:
    """Independent of the term: does this side of a pair have a box (→ separating plane)?"""
    if kind == "object":
        return True
    if kind == "obstacle":
        return chk.obstacles[idx].shape == "box"
    return isinstance(chk.gmodel.geometryObjects[idx].geometry, coal.Box)


KINDS = {"self": ("robot", "robot"), "robot-obstacle": ("robot", "obstacle"),
         "object-obstacle": ("object", "obstacle"), "object-robot": ("object", "robot")}


class Rows:
    """A CollisionAvoidance term on a problem whose knots are the given configurations, with every
    pair active at every knot; residual rows split into planes and smooth distances."""

    def __init__(self, robot, scene, Q, margin):
        N = len(Q) - 1
        self.Q = Q
        self.margin = margin
        self.prob = OptProblem(robot, n_intervals=N, duration=float(N))
        self.term = CollisionAvoidance(scene, margin=margin, activation=1e6, window=N)
        self.h = self.prob.add_constraint(self.term)
        self.prob.set_initial(q=Q)
        self.F = self.prob.term_function(self.h)
        b = self.prob._built
        self.x0 = np.concatenate([self.prob.initial_guess, b["aux_init"]])
        nbase = b["nbase"]
        assert np.allclose(self.prob.tp.unpack(self.x0)["q"], Q, atol=1e-12)   # knots = the configurations
        self.info = info = self.prob.term_data(self.h).info
        chk = info["model"].checker
        self.chk = chk
        # structural dependence of every row on the plane variables
        xs = ca.MX.sym("x", self.x0.size)
        sp = ca.jacobian(self.F(xs), xs).sparsity()
        rows, cols = np.array(sp.get_triplet())
        nrow = self.F.size1_out(0)
        aux_of_row = np.full(nrow, -1)
        for r, c in zip(rows, cols):
            if c >= nbase:
                aux_of_row[r] = (c - nbase) // 4
        self.aux_of_row = aux_of_row
        # planes: (pair, k, aux index) — and the smooth rows in order, one per (pair, knot)
        self.planes = info["plane_slots"]
        assert len({i for _, _, i in self.planes}) == len(self.planes)
        aux = self.prob.term_data(self.h).aux
        assert len(aux) == len(self.planes) and all(a.size == 4 for a in aux)
        self.smooth = []
        for p in info["active_pairs"]:
            ka, kb = KINDS[p.kind]
            if p in info["skipped"]:
                continue
            if _is_box_side(chk, ka, p.a) or _is_box_side(chk, kb, p.b):
                continue
            self.smooth += [(p, k) for k in range(N + 1)]
        self.smooth_rows = np.flatnonzero(aux_of_row < 0)
        assert self.smooth_rows.size == len(self.smooth), (self.smooth_rows.size, len(self.smooth))
        # box pairs are exactly the pairs with planes, at every knot
        n_box = sum(1 for p in info["active_pairs"] if p not in info["skipped"] and
                    (_is_box_side(chk, KINDS[p.kind][0], p.a) or _is_box_side(chk, KINDS[p.kind][1], p.b)))
        assert len(self.planes) == n_box * (N + 1)
        self.dist = np.array([chk.distances(q) for q in Q])            # exact, coal

    def exact(self, pair, k):
        return self.dist[k, self.chk.pairs.index(pair)]

    def eval(self, x):
        return np.array(self.F(x)).ravel()

    def plane_margin(self, r, i):
        """(certified margin m, ‖n‖² ≤ 1 row value) of plane i from residual values r: the plane rows
        hold with margin m iff every row ≥ m/2; the norm row is 1 − ‖n‖²."""
        rows = np.flatnonzero(self.aux_of_row == i)
        vals = r[rows]
        lb = self.prob._built["lbg"][self.prob._con_slices[self.h.name]][rows]
        norm_rows = lb == 0.0
        assert norm_rows.sum() == 1 and np.all(lb[~norm_rows] == self.margin / 2)
        return 2 * vals[~norm_rows].min(), float(vals[norm_rows][0])


@pytest.fixture(scope="module")
def rows(tcb, transport):
    rng = np.random.default_rng(2024)
    Q = np.array([tcb.random_joints(rng) * 0.6 for _ in range(6)])
    return Rows(tcb, transport, Q, margin=0.04)


def test_plane_rows_certify_exact_distance(rows):
    """Witness planes (the term's initial planes from coal) certify exactly the coal distance for
    separated pairs; any certified margin is ≤ the exact distance."""
    r = rows.eval(rows.x0)
    n_sep = 0
    kinds = set()
    for pair, k, i in rows.planes:
        m, nrow = rows.plane_margin(r, i)
        d = rows.exact(pair, k)
        assert nrow >= -1e-12, "the initial plane normal is a unit vector"
        if m > 0:
            assert d >= m - 1e-9, f"{pair.name_a}/{pair.name_b} knot {k}: plane certifies {m} > exact {d}"
        if d > 1e-3:
            n_sep += 1
            kinds.add(pair.kind)
            assert m == pytest.approx(d, abs=1e-6), f"{pair.name_a}/{pair.name_b} knot {k}: witness plane {m} vs {d}"
    assert n_sep > 50
    assert kinds == {"object-obstacle", "object-robot", "robot-obstacle", "self"}, kinds


def test_random_feasible_planes_are_conservative(rows):
    """Perturbed planes with ‖n‖ ≤ 1: whenever all rows hold with margin m > 0, exact ≥ m."""
    rng = np.random.default_rng(5)
    nbase = rows.prob._built["nbase"]
    checked = 0
    for _trial in range(12):
        x = rows.x0.copy()
        P = x[nbase:].reshape(-1, 4)
        P[:, :3] += rng.normal(size=(P.shape[0], 3)) * 0.15
        P[:, :3] *= (rng.uniform(0.6, 1.0, size=(P.shape[0], 1)) / np.maximum(1.0, np.linalg.norm(P[:, :3], axis=1, keepdims=True)))
        P[:, 3] += rng.normal(size=P.shape[0]) * 0.05
        x[nbase:] = P.ravel()
        r = rows.eval(x)
        for pair, k, i in rows.planes:
            m, nrow = rows.plane_margin(r, i)
            assert nrow >= 0
            if m > 0:
                checked += 1
                d = rows.exact(pair, k)
                assert d >= m - 1e-9, f"{pair.name_a}/{pair.name_b} knot {k}: plane certifies {m} > exact {d}"
                if d > 0.05:
                    # a perturbed plane certifies strictly less than a witness plane
                    assert m <= d
    assert checked > 300


def test_smooth_self_distances_are_conservative(rows):
    r = rows.eval(rows.x0)
    sm = r[rows.smooth_rows]
    n_sep = 0
    for (pair, k), v in zip(rows.smooth, sm):
        d = rows.exact(pair, k)
        assert pair.kind == "self"
        if d >= 0:
            n_sep += 1
            assert v <= d + 1e-9, f"{pair.name_a}/{pair.name_b} knot {k}: smooth {v} > exact {d}"
            # documented accuracy: cover_tol (0.02 m default here) + 3 mm
            assert d - v <= rows.term.cover_tol + 3e-3 + 1e-9, (pair.name_a, pair.name_b, d, v)
        else:
            assert v < 0, f"penetrating pair with a non-negative smooth distance {v}"
    assert n_sep > 100


def test_collision_residual_jacobian_matches_finite_differences(rows):
    """AD Jacobian of the whole collision residual vs central differences of the residual function
    along random directions in the joint knots and the planes."""
    rng = np.random.default_rng(11)
    xs = ca.MX.sym("x", rows.x0.size)
    Jf = ca.Function("collision_jacobian", [xs], [ca.jacobian(rows.F(xs), xs)])
    Jad = Jf(rows.x0).sparse()                     # scipy sparse matrix
    nbase = rows.prob._built["nbase"]
    nq = rows.prob.tp.nj * (rows.prob.N + 1)
    for _ in range(4):
        d = np.zeros(rows.x0.size)
        d[:nq] = rng.normal(size=nq) * 0.1
        d[nbase:] = rng.normal(size=rows.x0.size - nbase) * 0.1
        eps = 1e-6
        fd = (rows.eval(rows.x0 + eps * d) - rows.eval(rows.x0 - eps * d)) / (2 * eps)
        ad = Jad @ d
        np.testing.assert_allclose(ad, fd, atol=2e-5 * max(1.0, np.abs(fd).max()))


# --------------------------------------------------------------------------- (c) no pairs
def test_no_pairs_gives_zero_constraints(tcb, transport, rng):
    q0 = tcb.random_joints(rng) * 0.3
    for kwargs in ({"scene": Scene("empty", None, ()), "self_collision": False, "held_object": False},
                   {"scene": transport, "activation": -1e3}):
        prob = OptProblem(tcb, n_intervals=4, duration=2.0)
        term = CollisionAvoidance(**kwargs)
        h = prob.add_constraint(term)
        prob.add_constraint(JointBoundary("start", q=q0))
        prob.add_cost(Smoothness("jerk"))
        prob.set_initial_straight_line(q0, q0 + 0.2)
        F = prob.term_function(h)
        assert F.size1_out(0) == 0
        assert prob.term_data(h).info["active_pairs"] == ()
        assert prob.term_data(h).aux == ()
        sol = prob.solve(guarantees=False)   # no pair constrained: what coal finds between knots is not checked here
        assert sol.success, sol.status
        assert sol.terms[h.name] == 0.0
        np.testing.assert_allclose(sol.q[0], q0, atol=1e-8)
        assert np.abs(sol.jerk).max() < 1e-5          # only the start is fixed: jerk-free optimum


def test_activation_prunes_far_pairs(tcb, transport, rng):
    """Pairs whose exact distance along the initial guess stays above ``activation`` are left out;
    every pair that comes closer is in."""
    Q = np.array([tcb.random_joints(rng) * 0.4 for _ in range(4)])
    prob = OptProblem(tcb, n_intervals=3, duration=3.0)
    term = CollisionAvoidance(transport, activation=0.3, window=0)
    prob.add_constraint(term)
    prob.set_initial(q=Q)
    prob.term_function(prob.terms["collision"])
    chk = CollisionChecker(tcb, transport)
    D = np.array([chk.distances(q) for q in Q])
    expect = [p for i, p in enumerate(chk.pairs) if (D[:, i] < 0.3).any()]
    info = prob.term_data(prob.terms["collision"]).info
    assert list(info["active_pairs"]) == expect
    assert 0 < len(expect) < len(chk.pairs)
    for i, p in enumerate(chk.pairs):
        if p in expect:
            assert info["active_knots"][p] == np.flatnonzero(D[:, i] < 0.3).tolist()
    # the distances kept for the margin relaxation: exact below the activation, +inf above
    D0 = info["model"]._init_dist
    np.testing.assert_allclose(D0[D < 0.3], D[D < 0.3], atol=1e-9)
    assert np.all(np.isinf(D0[D >= 0.3]))


# --------------------------------------------------------------------------- (b) end to end
def _straight_line_ik(robot, scene, N, rng):
    chk = CollisionChecker(robot, scene)
    opts = IKOptions(tol_position=1e-10, tol_orientation=1e-10, max_iterations=300)
    step = IKOptions(tol_position=1e-10, tol_orientation=1e-10, max_step=0.05)
    for _ in range(300):
        res = solve_grasp_ik(robot, scene.start, scene.object.grasps, robot.random_configuration(rng), opts)
        if not (res.success and chk.min_distance(res.q)[0] > 0.05):
            continue
        qs, ok = [res.q], True
        for k in range(1, N + 1):
            rr = solve_grasp_ik(robot, interpolate_pose(scene.start, scene.goal, k / N), scene.object.grasps,
                                qs[-1], step)
            qs.append(rr.q)
            ok &= rr.success
        if ok and chk.min_distance(qs[-1])[0] > 0.05:
            return np.array(qs), chk
    pytest.fail("no collision-free closed-chain start/goal found by IK")


def _transport_problem(tcb, transport, Q, **col_kw):
    """Rest-to-rest transport NLP through the knots Q: closed chain, limits, 20 mm collision
    margin, minimum jerk; returns (problem, closed chain, collision handle)."""
    z = np.zeros(tcb.nj)
    prob = OptProblem(tcb, n_intervals=len(Q) - 1, duration=60.0, transcription="knots")  # its collision term
    prob.add_constraint(JointBoundary("start", q=Q[0], qd=z, qdd=z))
    prob.add_constraint(JointBoundary("end", q=Q[-1], qd=z, qdd=z))
    cc = ClosedChain.from_grasps(transport.object.grasps["A"], transport.object.grasps["B"])
    prob.add_constraint(cc)
    prob.add_constraint(JointPositionLimits())
    prob.add_constraint(JointVelocityLimits())
    col = prob.add_constraint(CollisionAvoidance(transport, margin=0.02, **col_kw))
    prob.add_cost(Smoothness("jerk"))
    prob.set_initial(q=Q)
    return prob, cc, col


def test_transport_end_to_end(tcb, transport):
    N = 25
    Q, chk = _straight_line_ik(tcb, transport, N, np.random.default_rng(0))
    clear0 = min(chk.min_distance(q)[0] for q in Q)
    assert clear0 < 0, "the straight-line initial guess should collide (else the test proves nothing)"
    prob, cc, col = _transport_problem(tcb, transport, Q)
    t0 = time.perf_counter()
    sol = prob.solve()
    wall = time.perf_counter() - t0
    assert sol.success, (sol.status, sol.max_constraint_violation, sol.terms)
    assert sol.terms[col.name] <= 1e-6
    rep = verify(tcb, sol, transport, closed_chain=cc)
    assert rep.min_clearance_m >= 0.0, rep
    assert rep.max_closed_chain_residual <= 1e-5, rep
    # at the knots the margin holds up to the solver tolerance (planes are exact)
    assert min(chk.min_distance(q)[0] for q in sol.q) >= 0.02 - 1e-5
    # boundary configurations are kept; the optimizer really moved the path
    np.testing.assert_allclose(sol.q[[0, -1]], Q[[0, -1]], atol=1e-6)
    assert np.abs(sol.q - Q).max() > 0.05
    print(f"transport N={N}: clearance guess {clear0:.4f} → {rep.min_clearance_m:.4f} m, closed chain "
          f"{rep.max_closed_chain_residual:.2e}, {sol.iterations} it, {wall:.1f} s")


def test_fixed_normals_hold_coal_witness_normals(tcb, transport):
    """``fixed_normals``: every plane's normal is bounded to (lbx == ubx) coal's unit witness normal
    at the initial guess, its offset stays free; the solve keeps those normals and still gives a
    trajectory that coal finds clear by the margin at the knots; a new initial guess re-seeds the
    fixed normals from coal at that guess."""
    N = 25
    Q, chk = _straight_line_ik(tcb, transport, N, np.random.default_rng(0))
    prob, cc, col = _transport_problem(tcb, transport, Q, fixed_normals=True)
    prob._build()
    b = prob._built
    nb = b["nbase"]
    info = prob.term_data(col).info
    model, slots = info["model"], info["plane_slots"]

    def check_bounds(traj):
        assert slots, "the transport scene has box pairs"
        for pair, k, i in slots:
            lo, hi = b["lbx"][nb + 4 * i:nb + 4 * i + 4], b["ubx"][nb + 4 * i:nb + 4 * i + 4]
            n_exp = model._plane_init(pair, traj.q_full(k))[:3]
            np.testing.assert_allclose(lo[:3], n_exp, atol=1e-12)
            np.testing.assert_array_equal(lo[:3], hi[:3])
            assert np.linalg.norm(lo[:3]) == pytest.approx(1.0, abs=1e-9)
            assert lo[3] == -np.inf and hi[3] == np.inf

    check_bounds(prob.numeric_trajectory(prob._full_x0()))
    sol = prob.solve()
    assert sol.success, (sol.status, sol.max_constraint_violation)
    x = np.asarray(sol.x)
    for _pair, _k, i in slots:
        np.testing.assert_allclose(x[nb + 4 * i:nb + 4 * i + 3], b["lbx"][nb + 4 * i:nb + 4 * i + 3], atol=1e-9)
    assert min(chk.min_distance(q)[0] for q in sol.q) >= 0.02 - 1e-5
    assert verify(tcb, sol, transport, closed_chain=cc).max_closed_chain_residual <= 1e-5
    # a new initial guess (the solution, resampled on a shifted time grid) re-seeds the normals
    old = b["lbx"][nb:].copy()
    prob.set_initial(q=sol.q, t=np.sqrt(np.linspace(0.0, 1.0, N + 1)))
    check_bounds(prob.numeric_trajectory(prob._full_x0()))
    fin = np.isfinite(old)
    assert np.abs(b["lbx"][nb:][fin] - old[fin]).max() > 1e-3
