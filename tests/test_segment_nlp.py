"""The B-spline segment NLP (optplan.problem.bspline, optplan.problem.segment) against independent
references:

* the knot maps against scipy's ``BSpline`` evaluation and derivatives;
* the kernel-assembled constraint Jacobian and Lagrangian Hessian against CasADi's own automatic
  differentiation of the same NLP graph, and the Jacobian against central finite differences;
* the collision rows against coal's exact distances (a row's value is a certified lower bound);
* the transport solve end to end, checked by ``verify`` (Pinocchio + coal), and against the knot
  transcription's fixed-normal optimum of the same problem (the same function space);
* ``CollisionChecker.distances`` (pinocchio.computeDistances) against coal pair by pair.
"""
from __future__ import annotations

import casadi as ca
import coal
import numpy as np
import pytest
from scipy.interpolate import BSpline

from optplan.collision.checker import CollisionChecker
from optplan.model.robot import RobotModel
from optplan.problem import ClosedChain
from optplan.problem.bspline import boundary_points, fit_interior, knot_matrices, knot_values
from optplan.problem.segment import SegmentSpec, SplineSegmentProblem
from optplan.scene import Scene
from optplan.verification import verify


@pytest.fixture(scope="module")
def transport():
    return Scene.load("transport")


def _scipy_spline(P: np.ndarray, T: float) -> BSpline:
    N = P.shape[0] - 3
    h = T / N
    t = np.arange(-3, N + 4) * h  # uniform knots; the curve lives on [0, T]
    return BSpline(t, P, 3)


def test_knot_maps_match_scipy_bspline(rng):
    N, T, nj = 9, 4.5, 3
    P = rng.normal(size=(N + 3, nj))
    kv = knot_values(P, T / N)
    sp = _scipy_spline(P, T)
    tk = np.linspace(0, T, N + 1)
    np.testing.assert_allclose(kv["q"], sp(tk), atol=1e-12)
    np.testing.assert_allclose(kv["qd"], sp.derivative(1)(tk), atol=1e-11)
    np.testing.assert_allclose(kv["qdd"], sp.derivative(2)(tk), atol=1e-10)
    mid = (tk[:-1] + tk[1:]) / 2
    np.testing.assert_allclose(kv["jerk"], sp.derivative(3)(mid), atol=1e-9)


def test_boundary_points_give_the_state_and_fit_keeps_them(rng):
    N, T, nj = 8, 2.0, 4
    h = T / N
    q, v, a = (rng.normal(size=nj) for _ in range(3))
    q1 = rng.normal(size=nj)
    Ps, Pe = boundary_points(q, v, a, h, "start"), boundary_points(q1, -v, a, h, "end")
    Q = rng.normal(size=(N + 1, nj))
    P = np.vstack([Ps, fit_interior(Q, Ps, Pe), Pe])
    kv = knot_values(P, h)
    np.testing.assert_allclose([kv["q"][0], kv["qd"][0], kv["qdd"][0]], [q, v, a], atol=1e-12)
    np.testing.assert_allclose([kv["q"][-1], kv["qd"][-1], kv["qdd"][-1]], [q1, -v, a], atol=1e-12)
    with pytest.raises(ValueError, match="at least 4 intervals"):
        knot_matrices(3)


def _straight_segment(tcb, transport, N=24):
    """A closed-chain transport segment: the task-space straight line through IK (collides)."""
    from test_collision_nlp import _straight_line_ik

    Q, _ = _straight_line_ik(tcb, transport, N, np.random.default_rng(0))
    return Q, ClosedChain.from_grasps(transport.object.grasps["A"], transport.object.grasps["B"])


@pytest.fixture(scope="module")
def seg(tcb, transport):
    Q, cc = _straight_segment(tcb, transport)
    spec = SegmentSpec(len(Q) - 1, 60.0, Q[0], Q[-1], cc, margin=0.02, object_arm="A", activation=0.5)
    prob = SplineSegmentProblem(tcb, transport, spec)
    prob.set_initial(Q)
    return prob, Q, cc


def _core(prob):
    """The B-spline core of the segment's OptProblem: (backend, structure with symbolic kernels,
    parameter vector, first guess)."""
    op = prob.problem
    assert op.uses_bspline()
    be = op._spline
    st = be.core.structure(be.row_families(), bool(be.pbounds), False)
    return be, st, be._pvec(op.duration, np.zeros(3), 1.0), be.guess(op.duration)


def _pair_families(be):
    return [f for f in be.fams if f.kind == "pair"]


def test_assembled_derivatives_equal_casadi_ad_and_finite_differences(seg, rng):
    prob, Q, cc = seg
    be, st, pv, x0 = _core(prob)
    nlp, d = st["nlp"], st["derivs"]
    x, p = nlp["x"], nlp["p"]
    ng = st["lbg"].size
    assert _pair_families(be) and "closed_chain" in st["slices"], "the segment must have collision and chain rows"
    jac_ad = ca.Function("j", [x, p], [ca.jacobian(nlp["g"], x)])
    lf, lg = ca.MX.sym("lf"), ca.MX.sym("lg", ng)
    hess_ad = ca.Function("h", [x, p, lf, lg], [ca.triu(ca.hessian(lf * nlp["f"] + ca.dot(lg, nlp["g"]), x)[0])])
    for _trial in range(2):
        xv = x0 + 0.02 * rng.normal(size=x0.size)
        lam = rng.normal(size=ng)
        Jm = np.array(d["jac_g"](xv, pv)[1])
        np.testing.assert_allclose(Jm, np.array(jac_ad(xv, pv)), atol=1e-10)
        Hm = np.array(ca.triu(d["hess_lag"](xv, pv, 0.7, lam)))
        Ha = np.array(hess_ad(xv, pv, 0.7, lam))
        np.testing.assert_allclose(Hm, Ha, atol=1e-8 * max(1.0, np.abs(Ha).max()))
        # finite differences of g along a few coordinates
        for i in rng.choice(x0.size, 5, replace=False):
            e = np.zeros(x0.size)
            e[i] = 1e-6
            fd = (np.array(st["gfun"](xv + e, pv)) - np.array(st["gfun"](xv - e, pv))).ravel() / 2e-6
            np.testing.assert_allclose(Jm[:, i], fd, atol=1e-6)


def test_collision_rows_are_certified_lower_bounds_of_coal_distance(seg, tcb, transport, rng):
    """Each static pair's row value + margin is a lower bound of the exact distance (plane along a
    unit normal), at perturbed configurations too."""
    prob, Q, cc = seg
    be, st, pv, x0 = _core(prob)
    chk = CollisionChecker(tcb, transport, object_arm="A")
    names = {f"collision:{p.name_a}|{p.name_b}": i for i, p in enumerate(chk.pairs)}
    n_static = 0
    for _ in range(3):
        xv = x0 + 0.05 * rng.normal(size=x0.size)
        g = np.array(st["gfun"](xv, pv)).ravel()
        Qk = be.core.M["q"] @ be.core.control_points(xv)
        for f in _pair_families(be):
            it = f.data["item"]
            if not it.static:
                continue
            n_static += 1
            rows = g[st["slices"][f.name]].reshape(len(it.knots), it.nrow)
            i = names[it.name]
            for t, k in enumerate(it.knots):
                d = chk.distances(Qk[k])[i]
                assert rows[t].min() <= d + 1e-6, (it.name, k, rows[t].min(), d)
    assert n_static > 0


def test_transport_segment_solves_and_verifies(seg, tcb, transport):
    prob, Q, cc = seg
    chk = CollisionChecker(tcb, transport, object_arm="A")
    assert min(chk.min_distance(q)[0] for q in Q) < 0, "the initial guess should collide"
    sol = prob.solve()
    assert sol.success, (sol.status, sol.max_constraint_violation, sol.terms)
    rep = verify(tcb, sol, transport, closed_chain=cc)
    assert rep.min_clearance_m >= 0.0, rep
    assert rep.max_closed_chain_residual <= 1e-5, rep
    # position limits on the control points: IPOPT relaxes variable bounds by 1e-8 (relative)
    assert rep.max_velocity_limit_violation <= 1e-9 and rep.max_position_limit_violation <= 1e-7
    np.testing.assert_allclose(sol.q[[0, -1]], Q[[0, -1]], atol=1e-12)
    # rest at the ends: equality rows of the core, held to IPOPT's tolerance (1e-6)
    np.testing.assert_allclose(sol.qd[[0, -1]], 0.0, atol=1e-6)
    assert sol.iterations > 0 and sol.cost > 0
    # the cost is the exact jerk integral of the sampled trajectory
    t = np.linspace(0, sol.t[-1], 2001)
    assert sol.cost == pytest.approx(float(np.sum(sol.jerk**2) * (sol.t[1] - sol.t[0])), rel=1e-9)
    assert np.all(np.isfinite(sol.sample(t)["q"]))


def test_checker_distances_match_coal_pair_by_pair(tcb, rng):
    sc = Scene.load("ssps_scene1")
    chk = CollisionChecker(tcb, sc)
    req = coal.DistanceRequest()
    for _ in range(20):
        q = tcb.random_configuration(rng)
        d = chk.distances(q)
        Mo = chk._update(q)
        tf = coal.Transform3s(Mo.rotation, Mo.translation)
        ref = []
        for p in chk.pairs:
            g1, t1, g2, t2 = chk._geoms(p, tf)
            ref.append(coal.distance(g1, t1, g2, t2, req, coal.DistanceResult()))
        np.testing.assert_allclose(d, ref, atol=5e-6)  # GJK tolerance (1e-6) on two placements


def test_witness_planes_match_coal_pair_by_pair_and_separate(tcb, rng):
    """The batched planes (one placement update, one C++ distance per pair) against coal.distance on
    the pair's own geometries: the same unit normal from A to B and mid-plane offset, and for a
    separated pair the plane separates the witness points (A's below, B's above)."""
    from optplan.problem.collision_term import witness_plane

    sc = Scene.load("hard_clutter_dense")
    chk = CollisionChecker(tcb, sc)
    assert chk._flip.any() and not chk._flip.all(), "both pair orientations should occur in the combined model"
    req = coal.DistanceRequest()
    for _ in range(10):
        q = tcb.random_configuration(rng)
        W = chk.witness_planes(q, range(len(chk.pairs)))
        D = chk.distances(q)
        Mo = chk._update(q)
        tf = coal.Transform3s(Mo.rotation, Mo.translation)
        for i, p in enumerate(chk.pairs):
            ref = witness_plane(chk, p, tf)
            # GJK's witness points on two placements of the same geometry (hand x grasp vs the joint)
            np.testing.assert_allclose(W[i], ref, atol=1e-4 if D[i] > 1.0 else 1e-8)
            assert abs(np.linalg.norm(W[i, :3]) - 1) < 1e-12
            if D[i] > 1e-3:
                g1, t1, g2, t2 = chk._geoms(p, tf)
                res = coal.DistanceResult()
                coal.distance(g1, t1, g2, t2, req, res)
                n, b = W[i, :3], W[i, 3]
                assert n @ np.asarray(res.getNearestPoint1()) < b < n @ np.asarray(res.getNearestPoint2())
    with pytest.raises(ValueError):
        chk.witness_planes(np.zeros(3), [0])


def test_object_pairs_riding_on_a_holding_hand_are_constant_and_left_out(tcb, transport):
    """Without the scene's hand-link exclusions, the object's pairs with geometry on a holding
    hand's body (its parent joint is the hand frame's) are left out of the closed-chain NLP — and
    coal confirms each keeps its distance along the closed-chain path; in a regrasp (no closed
    chain) only the holder's stay out, the moving hand's are rows."""
    import dataclasses

    sc = dataclasses.replace(transport, object=dataclasses.replace(transport.object, exclude_links=()))
    Q, cc = _straight_segment(tcb, sc)
    hand_joint = {a: tcb.model.frames[tcb.arm(a).ee_frame_id].parentJoint for a in ("A", "B")}

    def rides(p, arms):
        geoms = tcb.collision_model.geometryObjects
        g = [i for i, n in ((p.a, p.name_a), (p.b, p.name_b)) if n != "object"]
        return len(g) == 1 and "object" in (p.name_a, p.name_b) and geoms[g[0]].parentJoint in {hand_joint[a] for a in arms}

    spec = SegmentSpec(len(Q) - 1, 60.0, Q[0], Q[-1], cc, margin=0.02, object_arm="A", activation=0.5)
    prob = SplineSegmentProblem(tcb, sc, spec)
    prob.set_initial(Q)
    const, active = prob.col.constant_pairs, prob.col.active_pairs
    assert const and all(rides(p, "AB") for p in const)
    assert {a for p in const for a in "AB" if rides(p, a)} == {"A", "B"}
    assert not any(rides(p, "AB") for p in active)
    chk = CollisionChecker(tcb, sc)
    idx = [chk.pairs.index(p) for p in const]
    D = np.array([chk.distances(q)[idx] for q in Q])
    assert np.ptp(D, axis=0).max() < 1e-6   # constant along the path, by coal
    # a regrasp of arm B: the object rides on A (fixed), B's hand moves past it
    lo, hi = tcb.lower.copy(), tcb.upper.copy()
    ia = tcb.arm("A").j_idx
    lo[ia] = hi[ia] = Q[0][ia]
    q1 = Q[0].copy()
    q1[tcb.arm("B").j_idx] += 0.3
    spec = SegmentSpec(20, 10.0, Q[0], q1, None, lo, hi, margin=0.02, object_arm="A", activation=0.5)
    prob = SplineSegmentProblem(tcb, sc, spec)
    prob.set_initial(np.linspace(Q[0], q1, 21))
    assert not any(rides(p, "B") for p in prob.col.constant_pairs)
    assert any(rides(p, "B") for p in prob.col.active_pairs)


def test_bad_arguments_are_clear_errors(tcb, transport):
    from optplan.errors import OptionError

    Q, cc = _straight_segment(tcb, transport, N=8)
    with pytest.raises(ValueError, match="duration"):
        SplineSegmentProblem(tcb, transport, SegmentSpec(8, -1.0, Q[0], Q[-1], cc))
    prob = SplineSegmentProblem(tcb, transport, SegmentSpec(8, 10.0, Q[0], Q[-1], cc))
    with pytest.raises(ValueError, match="no initial guess"):
        prob.solve()
    with pytest.raises(ValueError, match=r"expected \(9, 14\)"):
        prob.set_initial(Q[:-1])
    with pytest.raises(ValueError, match="non-finite"):
        prob.set_initial(np.full_like(Q, np.nan))
    prob.set_initial(Q)
    with pytest.raises(OptionError, match="no_such_option"):
        prob.solve({"no_such_option": 1})
    with pytest.raises(OptionError, match="tol"):
        prob.solve(tol=-1.0)
    with pytest.raises(ValueError, match="fixed-base"):
        SplineSegmentProblem(RobotModel.from_name("eba_ffsr"), None, SegmentSpec(8, 10.0, np.zeros(14), np.zeros(14)))


def test_cylinder_and_mesh_geometry_are_covered_not_dropped(rng):
    """A URDF cylinder becomes the capsule of its axis and radius (which contains it); a mesh its
    vertices; both in the parent frame. Checked by sampling the cylinder's surface."""
    import pinocchio as pin

    from optplan.problem.kernels import geometry_points as _geometry_points

    robot = RobotModel.from_name("tcbirrt_dual_arm")  # a private copy: its geometry is modified
    g = 3
    o = robot.collision_model.geometryObjects[g]
    o.geometry = coal.Cylinder(0.07, 0.6)
    o.placement = pin.SE3(pin.exp3(np.array([0.3, -0.2, 0.1])), np.array([0.05, 0.0, 0.1]))
    fid, V, r = _geometry_points(robot, g)
    assert fid == o.parentFrame and V.shape == (3, 2) and r == pytest.approx(0.07)
    a, b = V[:, 0], V[:, 1]
    for _ in range(200):
        th, z = rng.uniform(0, 2 * np.pi), rng.uniform(-0.3, 0.3)
        p = o.placement.act(np.array([0.07 * np.cos(th), 0.07 * np.sin(th), z]))
        t = np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
        assert np.linalg.norm(p - (a + t * (b - a))) <= r + 1e-12
    m = coal.BVHModelOBBRSS()
    verts = rng.normal(size=(10, 3))
    m.beginModel(0, 10)
    m.addVertices(verts)
    m.endModel()
    o.geometry = m
    fid, V, r = _geometry_points(robot, g)
    np.testing.assert_allclose(V.T, [o.placement.act(v) for v in verts], atol=1e-12)
    o.geometry = coal.Cone(0.1, 0.3)
    from optplan.errors import ConfigurationError

    with pytest.raises(ConfigurationError, match="Cone"):
        _geometry_points(robot, g)


def test_kernel_cache_on_disk_is_reused_and_keyed_by_the_robot(tmp_path, monkeypatch):
    """A second cache (a fresh process) loads the saved kernels: same names and values; another
    robot never gets them."""
    from optplan.problem.kernels import KernelCache

    monkeypatch.setenv("OPTPLAN_CACHE", str(tmp_path))
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    V = np.array([[0.0, 0.1], [0.0, 0.0], [0.0, 0.3]])
    fid = robot.arm("A").ee_frame_id
    f1 = KernelCache(robot).pair(fid, V, 0.05, None, np.zeros((3, 1)), 0.0)
    j1, h1 = KernelCache(robot).derivatives(f1)
    files = sorted(p.name for p in tmp_path.rglob("*.casadi"))
    assert len(files) == 3
    kc2 = KernelCache(robot)
    f2 = kc2.pair(fid, V, 0.05, None, np.zeros((3, 1)), 0.0)
    assert f2.name() == f1.name() and sorted(p.name for p in tmp_path.rglob("*.casadi")) == files
    q = robot.random_configuration(np.random.default_rng(0))
    args = (q, [0.0, 0.0, 1.0], 0.3)
    np.testing.assert_allclose(np.array(f2(*args)), np.array(f1(*args)), atol=1e-15)
    np.testing.assert_allclose(np.array(kc2.derivatives(f2)[1](*args, [1.0, -2.0])),
                               np.array(h1(*args, [1.0, -2.0])), atol=1e-13)
    other = RobotModel.from_name("dshdasr")
    assert KernelCache(other)._digest != kc2._digest


def _transport_problem(tcb, transport, Q, cc, duration=60.0, **spec_kw):
    spec = SegmentSpec(len(Q) - 1, duration, Q[0], Q[-1], cc, margin=0.02, object_arm="A", activation=0.5,
                       **spec_kw)
    prob = SplineSegmentProblem(tcb, transport, spec)
    prob.set_initial(Q)
    return prob


def _structure(prob):
    be = prob.problem._spline
    return be.core.structure(be.row_families(), bool(be.pbounds), prob.compile_kernels)


def test_same_shape_reuses_the_structure_and_only_numbers_change(tcb, transport):
    """A second NLP of the same shape builds nothing symbolic (the structure and its IPOPT
    instance come from the robot's kernel cache); with other numbers (duration, hence the velocity
    bounds and the objective weight) it still gives exactly what a fresh build gives."""
    Q, cc = _straight_segment(tcb, transport)
    p1 = _transport_problem(tcb, transport, Q, cc, velocity_activation=0.0)  # every velocity row
    s1 = p1.solve()
    kc = p1.problem._spline.core.kc
    n_struct, st1 = len(kc._structures), _structure(p1)
    p2 = _transport_problem(tcb, transport, Q, cc, velocity_activation=0.0)
    s2 = p2.solve()
    assert len(kc._structures) == n_struct and _structure(p2) is st1
    assert s2.iterations == s1.iterations and np.array_equal(s2.x, s1.x)
    # same shape, other numbers: a shorter duration (other velocity bounds and objective weight)
    p3 = _transport_problem(tcb, transport, Q, cc, duration=25.0, velocity_activation=0.0)
    s3 = p3.solve()
    assert _structure(p3) is st1
    kc._structures.clear()
    p4 = _transport_problem(tcb, transport, Q, cc, duration=25.0, velocity_activation=0.0)
    s4 = p4.solve()
    assert _structure(p4) is not st1
    assert s4.status == s3.status and s4.iterations == s3.iterations
    np.testing.assert_allclose(s4.x, s3.x, atol=1e-10)
    assert s4.cost == pytest.approx(s3.cost, rel=1e-10) and not s3.cost == pytest.approx(s1.cost, rel=1e-3)


def test_a_segment_of_the_same_kinds_builds_no_point_kernel_and_fits_its_guess_once(tcb, transport, monkeypatch):
    """A second segment with the same kinds of terms (the same closed chain, rest at two other
    ends) reuses the first one's boundary and closed-chain kernels — the same functions, other
    bounds — and fits its first guess once for the collision planning and the solve together
    (the same numbers as a fit from scratch)."""
    import optplan.problem.spline_problem as SPM
    from optplan.problem.spline_solve import SplineBackend

    Q, cc = _straight_segment(tcb, transport)
    p1 = _transport_problem(tcb, transport, Q, cc)
    p1.problem._spline.prepare()
    built: list[object] = []
    fits: list[int] = []
    real_kernel, real_fit = SPM.point_kernel, SplineBackend._fit_between_fixed
    monkeypatch.setattr(SPM, "point_kernel", lambda *a, **k: built.append(a) or real_kernel(*a, **k))
    monkeypatch.setattr(SplineBackend, "_fit_between_fixed",
                        lambda self, P, Qk: fits.append(1) or real_fit(self, P, Qk))
    p2 = _transport_problem(tcb, transport, Q[::-1].copy(), cc)   # other ends
    be = p2.problem._spline
    be.prepare()
    assert built == []
    k1 = {f.name: f for f in p1.problem._spline.fams if f.kind == "knot"}
    k2 = {f.name: f for f in be.fams if f.kind == "knot"}
    assert set(k1) == set(k2) == {"start", "end", "closed_chain"}
    assert all(k2[n].fn is k1[n].fn for n in k1)
    for n in ("start", "end"):               # q, q̇, q̈ at the ends: other numbers, as bounds
        assert not np.array_equal(k1[n].lower, k2[n].lower)
    assert len(fits) == 1                     # prepare planned the collision rows along the fitted guess
    x = be.guess(p2.problem.duration)
    assert len(fits) == 1                     # the solve's guess: the same fit
    be._fitted = None
    np.testing.assert_array_equal(be.guess(p2.problem.duration), x)
    assert len(fits) == 2


def _velocity_rows(prob):
    sl = _structure(prob)["slices"].get("velocity_limits", slice(0, 0))
    return sl.stop - sl.start


def test_lazy_velocity_rows_match_all_rows_and_catch_what_they_miss(tcb, transport):
    """Velocity rows only where the guess is fast give the same optimum as every row when no limit
    is active; with a duration so short that the limits bind, the rows the guess did not select
    are found after the solve and added (a re-solve in the same call), and the solution keeps
    every limit."""
    Q, cc = _straight_segment(tcb, transport)
    lazy = _transport_problem(tcb, transport, Q, cc)
    full = _transport_problem(tcb, transport, Q, cc, velocity_activation=0.0)
    sl, sf = lazy.solve(), full.solve()
    assert _velocity_rows(lazy) < _velocity_rows(full)
    assert sl.success and sf.success and lazy.velocity_violations(sl, 1e-6).size == 0
    assert sl.cost == pytest.approx(sf.cost, rel=1e-4)
    # a short duration with few velocity rows at first (activation 0.9 selects only entries near the
    # limit): the first optimum exceeds the limits elsewhere, and the added rows bring it back
    fast = _transport_problem(tcb, transport, Q, cc, duration=25.0, velocity_activation=0.9)
    first = _velocity_rows(fast) if fast.problem.uses_bspline() else 0
    s = fast.solve()
    assert s.success and fast.velocity_violations(s, 1e-6).size == 0
    assert _velocity_rows(fast) > first and any(a.label == "velocity rows" for a in s.attempts)
    rep = verify(tcb, s, transport, closed_chain=cc)
    assert rep.max_velocity_limit_violation <= 1e-6 / fast.h  # the rows hold to IPOPT's tolerance 1e-6
    with pytest.raises(ValueError, match="velocity_activation"):
        _transport_problem(tcb, transport, Q, cc, velocity_activation=1.5)


def test_compiled_kernels_equal_the_symbolic_ones_and_are_found_by_auto(tmp_path, monkeypatch):
    """A pair kernel and its derivatives compiled to C give the symbolic values; a fresh cache
    (another process) finds the libraries with ``"auto"`` without compiling, and ``"auto"`` with
    no library falls back to the symbolic kernels."""
    import shutil

    from optplan.problem.kernels import KernelCache

    if not (shutil.which("cc") or shutil.which("gcc")):
        pytest.skip("no C compiler")
    monkeypatch.setenv("OPTPLAN_CACHE", str(tmp_path))
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    fid = robot.arm("A").ee_frame_id
    V = np.array([[0.0, 0.1], [0.0, 0.0], [0.0, 0.3]])
    kc = KernelCache(robot)
    fn = kc.pair(fid, V, 0.05, None, np.zeros((3, 1)), 0.0)
    (f0, j0, h0), c0 = kc.evaluators(fn, "auto")
    assert c0 is False and f0 is fn  # nothing compiled yet
    (f1, j1, h1), c1 = kc.evaluators(fn, True)
    assert c1 is True and len(list(tmp_path.rglob("*.so"))) == 3
    fresh = KernelCache(robot)
    (f2, j2, h2), c2 = fresh.evaluators(fn, "auto")
    assert c2 is True
    # the libraries are found by name: the derivatives' symbolic forms are not loaded
    assert not any(isinstance(k, tuple) and k[0] in ("jac", "hess") for k in fresh._fns), list(fresh._fns)
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = robot.random_configuration(rng)
        n = rng.normal(size=3)
        args = (q, n / np.linalg.norm(n), 0.4)
        lam = rng.normal(size=2)
        for a, b in ((f2, f0), (j2, j0)):
            np.testing.assert_allclose(np.array(a(*args)), np.array(b(*args)), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(np.array(h2(*args, lam)), np.array(h0(*args, lam)), rtol=1e-12, atol=1e-13)
    with pytest.raises(ValueError, match="compile_kernels"):
        kc.evaluators(fn, "yes")


def test_infeasibilities_name_the_worst_rows_by_term_and_knot(tcb, transport):
    """A solve stopped after one iteration from a colliding guess violates rows: the list is sorted,
    each entry's violation is its value against its bounds, a closed-chain row names an interior
    knot and the collision term is among them; a converged solve lists nothing beyond IPOPT's
    tolerance."""
    Q, cc = _straight_segment(tcb, transport)
    prob = _transport_problem(tcb, transport, Q, cc)
    early = prob.solve(max_iter=1)
    worst = prob.infeasibilities(early, n=5)
    assert worst and all(a.violation >= b.violation for a, b in zip(worst, worst[1:]))
    for w in worst:
        assert w.violation == pytest.approx(max(w.lower - w.value, w.value - w.upper))
        if w.term == "closed_chain":
            assert 1 <= w.point <= prob.N - 1 and "closed_chain[k=" in w.label
    assert any(w.term == "collision" for w in prob.infeasibilities(early, n=10**6))
    done = prob.solve()
    assert done.success and all(w.violation <= 1e-5 for w in prob.infeasibilities(done))
