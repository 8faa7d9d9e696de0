"""Collision rows of a free-floating robot on the B-spline core (optplan.problem.floating_collision):
the world placement of each body is the base pose (attitude from the decision variables, position
from the fixed centre of mass) times the joint kinematics — checked against Pinocchio with the base
re-integrated independently by simulate_base — and an OptProblem whose collision-free-looking
joint motion collides only because of the base drift is made clear (verify is the judge)."""
from __future__ import annotations

import casadi as ca
import coal
import numpy as np
import pinocchio as pin
import pytest

from optplan.model.floating import simulate_base
from optplan.problem import OptProblem
from optplan.problem.collision_term import CollisionAvoidance
from optplan.problem.floating_collision import _world_kernel, full_configurations
from optplan.problem.spline_core import SplineCore
from optplan.problem.terms import JointBoundary, Smoothness
from optplan.scene import Obstacle, Scene
from optplan.verification import VerifyTolerances, verify

DEG = np.pi / 180.0
# the motion of tests/test_floating_verify.py: free of self-collision, turns the base by ≈ 0.14 rad
Q0 = np.r_[[45.47, 42.5, -79.86, 20.38, -81.13, -150.5, 167.97] * 2] * DEG
QF = np.r_[[27.33, 24.26, -82.17, -28.42, -75.52, -99.93, 175.52],
           [74.74, 96.16, -38.81, 49.66, -43.55, -112.08, 138.42]] * DEG
T = 40.0   # [s]
Z = np.zeros(14)


def _quintic(t):
    tau = np.asarray(t) / T
    s = 10 * tau ** 3 - 15 * tau ** 4 + 6 * tau ** 5
    sd = (30 * tau ** 2 - 60 * tau ** 3 + 30 * tau ** 4) / T
    return Q0 + np.outer(s, QF - Q0), np.outer(sd, QF - Q0)


def test_world_rows_match_pinocchio_with_the_independently_integrated_base(eba):
    """Kernel world points = Pinocchio's, with the base where simulate_base puts it after a random
    joint motion from a random start pose; the kernel's Jacobian matches central differences."""
    rng = np.random.default_rng(7)
    core = SplineCore(eba, 4, False, 2, 0)
    lo, hi = np.maximum(eba.lower, -np.pi), np.minimum(eba.upper, np.pi)
    model = eba.model
    data = model.createData()
    frames = [model.getFrameId(n) for n in ("a_link4", "b_link6")] + [eba.arm("A").ee_frame_id]
    for trial in range(3):
        qa = rng.uniform(lo, hi)
        qb = np.clip(qa + rng.uniform(-0.6, 0.6, 14), lo, hi)
        base0 = pin.SE3(pin.exp3(rng.normal(size=3)), rng.normal(size=3))
        ts = np.linspace(0.0, 10.0, 401)
        s = ts / 10.0
        Q, QD = qa + np.outer(s, qb - qa), np.tile((qb - qa) / 10.0, (ts.size, 1))
        Mf = simulate_base(eba, (ts, Q, QD), ts, base0=base0, substeps=4).final_base
        assert np.linalg.norm(pin.log3(base0.rotation.T @ Mf.rotation)) > 1e-3   # the base did turn
        com0 = base0.act(pin.centerOfMass(model, data, eba.configuration(qa)))
        xi = pin.Quaternion(base0.rotation.T @ Mf.rotation).coeffs()
        b0 = pin.Quaternion(base0.rotation).coeffs()
        pin.framesForwardKinematics(model, data, np.r_[pin.SE3ToXYZQUAT(Mf), qb])
        for fid in frames:
            V = rng.uniform(-0.1, 0.1, (3, 4))
            fn = _world_kernel(core, fid, V, 0.02)
            X = np.array([-(np.asarray(fn(np.r_[qb, xi, b0, com0, e, 0.0])).ravel() + 0.02) for e in np.eye(3)])
            X_pin = data.oMf[fid].rotation @ V + data.oMf[fid].translation[:, None]
            assert np.abs(X - X_pin).max() < 1e-7, (trial, model.frames[fid].name)
            # exact Jacobian of the row kernel against central differences
            n = rng.normal(size=3)
            z = np.r_[qb, xi, b0, com0, n / np.linalg.norm(n), 0.3]
            f, jf, _ = core.kernel_set(fn, False)
            J = np.asarray(ca.densify(jf(z)))
            Jfd = np.zeros_like(J)
            for i in range(z.size):
                dz = np.zeros(z.size)
                dz[i] = 1e-6
                Jfd[:, i] = (np.asarray(f(z + dz)).ravel() - np.asarray(f(z - dz)).ravel()) / 2e-6
            assert np.abs(J - Jfd).max() < 1e-6


def _probe_scene(eba):
    """A small sphere 5 mm inside a corner of the base box where momentum puts the base halfway
    through the quintic Q0 → QF, ≥ 4 cm from the base at both ends (a straight joint motion
    collides only because the base drifts)."""
    ts = np.linspace(0.0, T, 201)
    Q, QD = _quintic(ts)
    sim = simulate_base(eba, (ts, Q, QD), ts)
    half = np.array([0.6, 0.5, 0.8])   # the base box of eba_ffsr [m]
    box = coal.Box(*(2 * half))

    def dist(M, p):
        return coal.distance(box, coal.Transform3s(M.rotation, M.translation), coal.Sphere(1e-4),
                             coal.Transform3s(np.eye(3), p), coal.DistanceRequest(), coal.DistanceResult())

    Mm, M0, Mf = (pin.XYZQUATToSE3(sim.q[i, :7]) for i in (100, 0, -1))
    cands = [Mm.act(c * (half - 0.005)) for c in np.array(np.meshgrid(*[[-1, 1]] * 3)).T.reshape(-1, 3)]
    best = max(cands, key=lambda p: min(dist(M0, p), dist(Mf, p)))
    assert min(dist(M0, best), dist(Mf, best)) > 0.04
    obst = Obstacle(name="probe", shape="sphere", placement=pin.SE3(np.eye(3), best), radius=0.005)
    return Scene(name="probe", robot="eba_ffsr", obstacles=(obst,))


def _problem(eba, scene, collision):
    p = OptProblem(eba, n_intervals=16, duration=T, transcription="bspline")
    p.add_constraint(JointBoundary("start", q=Q0, qd=Z, qdd=Z))
    p.add_constraint(JointBoundary("end", q=QF, qd=Z, qdd=Z))
    if collision:
        p.add_constraint(CollisionAvoidance(scene, margin=0.005, held_object=False, fixed_normals=True))
    p.add_cost(Smoothness("jerk"))
    return p


@pytest.fixture(scope="module")
def probe(eba):
    return _probe_scene(eba)


def test_a_collision_due_to_the_base_drift_is_removed(eba, probe):
    plain = _problem(eba, probe, False).solve(guarantees=False)
    assert plain.success
    rep0 = verify(eba, plain, probe, held_object=False)
    assert rep0.min_clearance_m < 0 and "probe" in rep0.min_clearance_pair   # the straight motion collides

    p = _problem(eba, probe, True)
    sol = p.solve()
    assert sol.success, sol.status
    rep = verify(eba, sol, probe, held_object=False)
    free = VerifyTolerances(final_base_attitude_rad=None)   # no attitude asked of this motion
    assert rep.passed(free), rep.failures(free)
    assert rep.min_clearance_m >= 0.0 and rep.max_momentum_residual < 1e-8
    # the world rows (planes fixed in the world, base from the NLP's attitude) bound the exact
    # distance from below at the knots, with the base where the NLP puts it
    b = p._spline
    core = b.core
    x = np.asarray(sol.x, float)
    st = core.structure(b.row_families(), bool(b.pbounds), "auto")
    pv = b._pvec(T, b._com0(Q0), 1.0)
    g = np.asarray(st["gfun"](x, pv)).ravel()
    Qf = full_configurations(core, core.M["q"] @ core.control_points(x), core.knot_xi(x), p.base0,
                             pv[core.p_c0:core.p_c0 + 3])
    from optplan.collision.checker import CollisionChecker

    chk = CollisionChecker(eba, probe, held_object=False)
    world = [f for f in b.fams if f.kind == "pair" and f.data["world"]]
    assert world, "no world plane rows were active"
    for f in world:
        v = g[st["slices"][f.name]].reshape(len(f.points), -1)
        pair = f.name.removeprefix("collision:").split("|")
        i = next(j for j, pp in enumerate(chk.pairs) if {pp.name_a, pp.name_b} == set(pair))
        for k, row in zip(f.points, v):
            d = chk.distances(Qf[k])[i]
            assert row.min() <= d + 1e-9
            assert row.min() >= f.data["item"].margins[list(f.points).index(k)] - 1e-6


def test_two_collision_terms_keep_their_own_pairs_and_margins(eba, probe):
    """A link clearance (no scene: the robot's own bodies) and an obstacle clearance with another
    margin on one floating problem: each term plans its own pairs, its rows carry its margin, and
    the solution clears the probe (verify, with the base integrated independently)."""
    p = OptProblem(eba, n_intervals=16, duration=T, transcription="bspline")
    p.add_constraint(JointBoundary("start", q=Q0, qd=Z, qdd=Z))
    p.add_constraint(JointBoundary("end", q=QF, qd=Z, qdd=Z))
    links = p.add_constraint(CollisionAvoidance(None, margin=0.002, held_object=False, fixed_normals=True,
                                                activation=0.5), name="links")
    obst = p.add_constraint(CollisionAvoidance(probe, margin=0.005, self_collision=False, held_object=False,
                                               fixed_normals=True), name="probe_clearance")
    p.add_cost(Smoothness("jerk"))
    sol = p.solve()
    assert sol.success, sol.status
    rep = verify(eba, sol, probe, held_object=False)
    assert rep.passed(VerifyTolerances(final_base_attitude_rad=None)) and rep.min_clearance_m >= 0.0
    pairs = {h.name: p.term_data(h).info["active_pairs"] for h in (links, obst)}
    assert pairs["probe_clearance"] and all("probe" in (q.name_a, q.name_b) for q in pairs["probe_clearance"])
    assert pairs["links"] and not any("probe" in (q.name_a, q.name_b) for q in pairs["links"])
    fams = {f.name: f for f in p._spline.fams if f.kind == "pair"}
    for term, margin in (("links", 0.002), ("probe_clearance", 0.005)):
        mine = [f for n, f in fams.items() if n.startswith(f"collision:{term}:")]
        assert mine, term
        # a margin is the term's own, or halved next to a guess closer than it (relaxation)
        assert all(np.all(f.data["item"].margins <= margin + 1e-15) for f in mine)
        assert any(np.any(f.data["item"].margins == margin) for f in mine)
    assert len(fams) == sum(len(v) for v in (p._spline.owner["links"], p._spline.owner["probe_clearance"]))


def test_floating_plane_rows_solve_without_a_permanent_constraint_regularisation(eba, probe):
    """IPOPT's ``perturb_always_cd`` (the fixed-base segment NLP's setting for plane rows) is not
    used with a floating robot's momentum and attitude rows: it stalled the Spline-RRT* variant at
    a primal infeasibility ~1e-3 (docs/decisions/0022-papers-on-the-shared-core.md); the other
    plane-row settings stay."""
    p = _problem(eba, probe, True)
    p.solve(max_iter=2, guarantees=False)
    st = p._spline.core.structure(p._spline.row_families(), bool(p._spline.pbounds), "auto")
    keys = list(st["solvers"])
    assert keys and any("'ipopt.theta_max_fact', 10.0" in k for k in keys), keys
    assert not any("perturb_always_cd" in k for k in keys), keys
