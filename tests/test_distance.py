"""Tests of optplan.geometry.distance against coal's exact signed distance (independent implementation)."""
from __future__ import annotations

import math

import casadi as ca
import coal
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from optplan.geometry import distance as D
from optplan.geometry.distance import (
    Box,
    Capsule,
    Sphere,
    capsule_box,
    capsule_capsule,
    capsule_sphere,
    error_bound,
    make_distance_function,
    n_covering_spheres,
    point_segment_distance,
    point_segment_distance_sq,
    signed_distance,
    sphere_box,
    sphere_sphere,
)

N_SEPARATED = 500  # separated placements per pair type
TOL = 1e-9  # [m] conservativeness slack (floating point)
PAIRS = ["sphere-sphere", "capsule-sphere", "sphere-capsule", "capsule-capsule", "sphere-box",
         "box-sphere", "capsule-box", "box-capsule"]
KINDS = {"sphere": Sphere, "capsule": Capsule, "box": Box}


# ----------------------------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------------------------
def rot(rng: np.random.Generator) -> np.ndarray:
    return Rotation.random(random_state=rng).as_matrix()


def z_to(u: np.ndarray) -> np.ndarray:
    """A rotation whose third column is the unit vector u."""
    x = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(u, x), u])


def coal_object(shape, R: np.ndarray, p: np.ndarray):
    """(coal geometry, coal.Transform3s) of ``shape`` placed at (R, p)."""
    if isinstance(shape, Sphere):
        return coal.Sphere(shape.radius), coal.Transform3s(R, p + R @ np.array(shape.center))
    if isinstance(shape, Capsule):
        a, b = np.array(shape.a), np.array(shape.b)
        L = np.linalg.norm(b - a)
        Rl = z_to((b - a) / L) if L > 0 else np.eye(3)
        return coal.Capsule(shape.radius, L), coal.Transform3s(R @ Rl, p + R @ (0.5 * (a + b)))
    return coal.Box(2.0 * np.array(shape.half_extents)), coal.Transform3s(R, p)


def exact(shape1, pose1, shape2, pose2) -> tuple[float, np.ndarray]:
    """coal's signed distance [m] (negative = penetration depth) and normal (1 -> 2)."""
    g1, t1 = coal_object(shape1, *pose1)
    g2, t2 = coal_object(shape2, *pose2)
    req = coal.DistanceRequest()
    req.enable_signed_distance = True
    req.gjk_tolerance = 1e-12
    res = coal.DistanceResult()
    d = coal.distance(g1, t1, g2, t2, req, res)
    return float(d), np.array(res.normal, dtype=float)


def random_shape(kind: str, rng: np.random.Generator):
    if kind == "sphere":
        centre = rng.normal(0.0, 0.05, 3) if rng.random() < 0.3 else (0.0, 0.0, 0.0)
        return Sphere(rng.uniform(0.005, 0.3), centre)
    if kind == "capsule":
        r = rng.uniform(0.005, 0.3)
        u = rng.random()
        if u < 0.1:
            return Capsule.along_z(r, 0.0)
        if u < 0.7:
            return Capsule.along_z(r, rng.uniform(0.0, 1.0))
        return Capsule(r, rng.uniform(-0.4, 0.4, 3), rng.uniform(-0.4, 0.4, 3))
    return Box(rng.uniform(0.005, 0.5, 3))


def random_placements(pair: str, seed: int, n_separated: int = N_SEPARATED):
    """Yield (shape1, pose1, shape2, pose2, d_exact); half are moved to near contact (< 3 cm)."""
    k1, k2 = pair.split("-")
    rng = np.random.default_rng(seed)
    n_sep = 0
    for _ in range(50 * n_separated):
        s1, s2 = random_shape(k1, rng), random_shape(k2, rng)
        pose1 = (rot(rng), rng.uniform(-0.7, 0.7, 3))
        pose2 = (rot(rng), rng.uniform(-0.7, 0.7, 3))
        d, normal = exact(s1, pose1, s2, pose2)
        if rng.random() < 0.5 and np.all(np.isfinite(normal)) and np.linalg.norm(normal) > 0.5:
            target = rng.uniform(0.0, 0.03) if rng.random() < 0.8 else rng.uniform(-0.05, 0.0)
            pose2 = (pose2[0], pose2[1] + (target - d) * normal)
            d, _ = exact(s1, pose1, s2, pose2)
        n_sep += d >= 0.0
        yield s1, pose1, s2, pose2, d
        if n_sep >= n_separated:
            return
    raise AssertionError("could not generate enough separated placements")


def world(shape, pose):
    """World-frame data of a shape for the low-level functions."""
    R, p = pose
    if isinstance(shape, Sphere):
        return (p + R @ np.array(shape.center), shape.radius)
    if isinstance(shape, Capsule):
        return (p + R @ np.array(shape.a), p + R @ np.array(shape.b), shape.radius)
    return (R, p, np.array(shape.half_extents))


def low_level(shape1, pose1, shape2, pose2) -> float:
    """Same distance through the world-frame functions (order-normalised)."""
    order = {Sphere: 0, Capsule: 1, Box: 2}
    if order[type(shape1)] > order[type(shape2)]:
        shape1, pose1, shape2, pose2 = shape2, pose2, shape1, pose1
    w1, w2 = world(shape1, pose1), world(shape2, pose2)
    kinds = (type(shape1), type(shape2))
    if kinds == (Sphere, Sphere):
        return sphere_sphere(*w1, *w2)
    if kinds == (Sphere, Capsule):
        return capsule_sphere(*w2, *w1)
    if kinds == (Capsule, Capsule):
        return capsule_capsule(*w1, *w2)
    if kinds == (Sphere, Box):
        return sphere_box(*w1, *w2)
    return capsule_box(*w1, *w2)


def pose_vector(pose1, pose2) -> np.ndarray:
    return np.concatenate([pose1[0].ravel(order="F"), pose1[1], pose2[0].ravel(order="F"), pose2[1]])


def poses_of(x: np.ndarray):
    return ((x[:9].reshape(3, 3, order="F"), x[9:12]), (x[12:21].reshape(3, 3, order="F"), x[21:24]))


def fd_gradient(f, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    return np.array([(f(x + h * e) - f(x - h * e)) / (2.0 * h) for e in np.eye(len(x))])


def casadi_gradient(shape1, shape2):
    """numpy function x (24,) -> (value, gradient) through casadi.jacobian on SX."""
    x = ca.SX.sym("x", 24)
    d = signed_distance(shape1, (ca.reshape(x[:9], 3, 3), x[9:12]), shape2,
                        (ca.reshape(x[12:21], 3, 3), x[21:24]))
    f = ca.Function("f", [x], [d, ca.jacobian(d, x)])

    def evaluate(xv: np.ndarray):
        val, jac = f(xv)
        return float(val), np.array(ca.densify(jac)).ravel()
    return evaluate


# ----------------------------------------------------------------------------------------------
# conservativeness and accuracy against coal
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("pair", PAIRS)
def test_conservative_and_accurate_vs_coal(pair: str) -> None:
    n_sep = n_pen = 0
    worst_excess, worst_ratio = -np.inf, 0.0
    for s1, pose1, s2, pose2, d_ex in random_placements(pair, seed=PAIRS.index(pair)):
        d = signed_distance(s1, pose1, s2, pose2)
        assert isinstance(d, float) and math.isfinite(d)
        assert abs(low_level(s1, pose1, s2, pose2) - d) <= 1e-12
        if d_ex >= 0.0:
            n_sep += 1
            bound = error_bound(s1, s2)
            assert d <= d_ex + TOL, (pair, s1, s2, d, d_ex)
            assert d_ex - d <= bound + TOL, (pair, s1, s2, d, d_ex, bound)
            worst_excess = max(worst_excess, d - d_ex)
            worst_ratio = max(worst_ratio, (d_ex - d) / bound if bound > 0 else 0.0)
        elif d_ex < -1e-6:
            n_pen += 1
            assert d < 0.0, (pair, s1, s2, d, d_ex)  # sign-consistent in penetration
            if pair in ("sphere-sphere", "capsule-sphere", "sphere-capsule", "sphere-box", "box-sphere"):
                assert d <= d_ex + 1e-6, (pair, s1, s2, d, d_ex)  # true lower bound (EPA tolerance)
    assert n_sep >= N_SEPARATED and n_pen > 50
    assert worst_excess <= TOL and worst_ratio <= 1.0


@pytest.mark.parametrize("pair", ["capsule-capsule", "capsule-box"])
def test_unreduced_sphere_distances(pair: str) -> None:
    rng = np.random.default_rng(7)
    for s1, pose1, s2, pose2, d_ex in random_placements(pair, seed=100, n_separated=100):
        if d_ex < 0 or not isinstance(s1, Capsule):
            continue
        w1, w2 = world(s1, pose1), world(s2, pose2)
        fn = capsule_capsule if pair == "capsule-capsule" else capsule_box
        k = n_covering_spheres(s1.length, s1.radius, D.DEFAULT_COVER_TOL) + int(rng.integers(0, 3))
        vec = fn(*w1, *w2, n_spheres=k, reduce=False)
        assert vec.shape == (k,)
        red = fn(*w1, *w2, n_spheres=k)
        assert red <= vec.min() + 1e-12
        assert vec.min() <= d_ex + TOL


# ----------------------------------------------------------------------------------------------
# derivatives
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("pair", PAIRS)
def test_casadi_gradient_matches_finite_differences(pair: str) -> None:
    rng = np.random.default_rng(1000 + PAIRS.index(pair))
    k1, k2 = pair.split("-")
    checked = 0
    while checked < 12:
        s1, s2 = random_shape(k1, rng), random_shape(k2, rng)
        if isinstance(s1, Capsule) or isinstance(s2, Capsule):  # keep the SX graphs small
            if max(getattr(s, "length", 0) / max(getattr(s, "radius", 1), 1e-9) for s in (s1, s2)) > 20:
                continue
        pose1, pose2 = (rot(rng), rng.uniform(-0.6, 0.6, 3)), (rot(rng), rng.uniform(-0.6, 0.6, 3))
        x = pose_vector(pose1, pose2)
        val, grad = casadi_gradient(s1, s2)(x)
        assert abs(val - signed_distance(s1, pose1, s2, pose2)) <= 1e-12
        fd = fd_gradient(lambda y, s1=s1, s2=s2: signed_distance(s1, poses_of(y)[0], s2, poses_of(y)[1]), x)
        assert np.all(np.isfinite(grad))
        assert np.max(np.abs(grad - fd)) <= 1e-5 * max(1.0, np.max(np.abs(fd))), (pair, s1, s2, grad, fd)
        checked += 1


def test_make_distance_function_mx_and_hessian() -> None:
    rng = np.random.default_rng(3)
    shapes = [Sphere(0.1, (0.02, 0.0, 0.0)), Capsule.along_z(0.07, 0.4), Box((0.2, 0.1, 0.05))]
    for s1 in shapes:
        for s2 in shapes:
            if isinstance(s1, Box) and isinstance(s2, Box):
                with pytest.raises(TypeError):
                    make_distance_function(s1, s2)
                continue
            f = make_distance_function(s1, s2)
            assert f.name_in() == ["R1", "p1", "R2", "p2"] and f.n_out() == 1
            pose1, pose2 = (rot(rng), rng.uniform(-0.5, 0.5, 3)), (rot(rng), rng.uniform(-0.5, 0.5, 3))
            assert abs(float(f(*pose1, *pose2)) - signed_distance(s1, pose1, s2, pose2)) <= 1e-12
            R1, p1, R2, p2 = (ca.MX.sym(n, *sh) for n, sh in (("R1", (3, 3)), ("p1", (3, 1)),
                                                               ("R2", (3, 3)), ("p2", (3, 1))))
            d_mx = signed_distance(s1, (R1, p1), s2, (R2, p2))
            assert isinstance(d_mx, ca.MX)
            z = ca.vertcat(p1, p2)
            H = ca.Function("H", [R1, p1, R2, p2], [ca.hessian(d_mx, z)[0]])
            hv = np.array(H(*pose1, *pose2))
            assert np.all(np.isfinite(hv)) and np.allclose(hv, hv.T)
            dm = signed_distance(s1, (ca.DM(pose1[0]), ca.DM(pose1[1])), s2, pose2)
            assert abs(float(dm) - signed_distance(s1, pose1, s2, pose2)) <= 1e-12


# ----------------------------------------------------------------------------------------------
# smoothness across the kinks of the exact closest-point maps
# ----------------------------------------------------------------------------------------------
def max_gradient_jump(f, s_grid: np.ndarray, h: float = 1e-7) -> float:
    """Largest jump between FD derivatives at consecutive grid points, divided by the grid step."""
    g = np.array([(f(s + h) - f(s - h)) / (2 * h) for s in s_grid])
    return float(np.max(np.abs(np.diff(g))) / (s_grid[1] - s_grid[0]))


GRID = np.linspace(-0.001, 0.001, 201)  # step 1e-5


def _caps_z(L: float):
    return np.array([0.0, 0.0, -L / 2]), np.array([0.0, 0.0, L / 2])


KINK_PATHS = {
    # sphere moving along the capsule axis direction past the end points (t crosses 0 and 1)
    "capsule-sphere t=1": lambda s: capsule_sphere(*_caps_z(0.6), 0.05, np.array([0.1, 0.0, 0.3 + s]), 0.05),
    "capsule-sphere t=0": lambda s: capsule_sphere(*_caps_z(0.6), 0.05, np.array([0.0, 0.1, -0.3 + s]), 0.05),
    # sphere centre crossing the plane between face region and edge region / corner region
    "sphere-box face/edge": lambda s: sphere_box(np.array([0.2 + s, 0.15, 0.0]), 0.02, np.eye(3), np.zeros(3), (0.2, 0.1, 0.3)),
    "sphere-box edge/corner": lambda s: sphere_box(np.array([0.25, 0.15, 0.3 + s]), 0.02, np.eye(3), np.zeros(3), (0.2, 0.1, 0.3)),
    # point crossing the box surface (value crosses 0: feasible boundary) and the inside diagonal
    "point-box surface": lambda s: sphere_box(np.array([0.05, 0.0, 0.3 + s]), 0.0, np.eye(3), np.zeros(3), (0.2, 0.1, 0.3)),
    "sphere-box inside diagonal": lambda s: sphere_box(np.array([0.05 + s, 0.05, 0.0]), 0.2, np.eye(3), np.zeros(3), (0.1, 0.1, 0.3)),
    # capsules rotating through the parallel configuration (exact distance has a kink there)
    "capsule-capsule parallel": lambda s: capsule_capsule(*_caps_z(0.6), 0.05, np.array([0.3, 0.0, -0.3]),
                                                          np.array([0.3 + 0.6 * math.sin(s), 0.0, -0.3 + 0.6 * math.cos(s)]), 0.05),
    # capsule rotating through parallel to a box face (exact: kink; covering spheres exchange roles)
    "capsule-box parallel": lambda s: capsule_box(np.array([-0.3 * math.cos(s), 0.0, 0.4 - 0.3 * math.sin(s)]),
                                                  np.array([0.3 * math.cos(s), 0.0, 0.4 + 0.3 * math.sin(s)]), 0.03,
                                                  np.eye(3), np.zeros(3), (0.5, 0.5, 0.3)),
}


@pytest.mark.parametrize("name", sorted(KINK_PATHS))
def test_gradient_continuous_across_kinks(name: str) -> None:
    jump = max_gradient_jump(KINK_PATHS[name], GRID)
    assert jump < 1e4, (name, jump)  # curvature <= ~4/eps: jumps O(step); a kink gives slope-jump/step


def test_kink_detector_flags_exact_parallel_capsules() -> None:
    """The jump criterion above does detect the kink of the exact segment-segment distance."""
    def exact_cc(s: float) -> float:
        a2 = np.array([0.3, 0.0, -0.3])
        u = np.array([math.sin(s), 0.0, math.cos(s)])
        c1 = Capsule.along_z(0.05, 0.6)
        c2 = Capsule.along_z(0.05, 0.6)
        return exact(c1, (np.eye(3), np.zeros(3)), c2, (z_to(u), a2 + 0.3 * u))[0]
    assert max_gradient_jump(exact_cc, GRID) > 1e4


# ----------------------------------------------------------------------------------------------
# degenerate and bad inputs
# ----------------------------------------------------------------------------------------------
def _finite_value_and_gradient(fn, *args) -> None:
    """fn on numpy args is finite; on SX symbols (all 3-vectors symbolic) value and jacobian finite."""
    val = fn(*args)
    assert np.all(np.isfinite(val))
    syms, sym_args = [], []
    for i, a in enumerate(args):
        if isinstance(a, np.ndarray) and a.shape == (3,):
            s = ca.SX.sym(f"v{i}", 3)
            syms.append(s)
            sym_args.append(s)
        else:
            sym_args.append(a)
    x = ca.vertcat(*syms)
    expr = fn(*sym_args)
    f = ca.Function("f", [x], [expr, ca.jacobian(expr, x)])
    v, j = f(np.concatenate([a for a in args if isinstance(a, np.ndarray) and a.shape == (3,)]))
    assert abs(float(v) - float(val)) <= 1e-12
    assert np.all(np.isfinite(np.array(ca.densify(j))))


def test_degenerate_inputs_are_finite() -> None:
    c = np.array([0.1, -0.2, 0.3])
    _finite_value_and_gradient(sphere_sphere, c, 0.1, c.copy(), 0.2)  # coincident centres
    _finite_value_and_gradient(sphere_sphere, c, 0.0, c.copy(), 0.0)  # coincident points
    _finite_value_and_gradient(capsule_sphere, c, c.copy(), 0.1, c + 0.3, 0.1)  # zero-length capsule
    _finite_value_and_gradient(capsule_sphere, c, c.copy(), 0.1, c.copy(), 0.1)  # ... and coincident
    _finite_value_and_gradient(capsule_sphere, c, c + 0.5, 0.1, c + 0.25, 0.1)  # centre on the axis
    _finite_value_and_gradient(point_segment_distance, c, c.copy(), c.copy())
    _finite_value_and_gradient(point_segment_distance_sq, c, c.copy(), c.copy())
    _finite_value_and_gradient(lambda a, b, a2, b2: capsule_capsule(a, b, 0.1, a2, b2, 0.1, n_spheres=3),
                               c, c.copy(), c.copy(), c.copy())  # zero-length, coincident capsules
    _finite_value_and_gradient(lambda a, b: capsule_capsule(a, b, 0.0, a.copy() if isinstance(a, np.ndarray) else a,
                                                            b, 0.0, n_spheres=2), c, c + 0.3)  # identical segments
    h = np.array([0.2, 0.1, 0.3])
    R = Rotation.from_rotvec([0.3, -0.2, 0.1]).as_matrix()
    p = np.array([0.5, 0.1, -0.2])
    for local in ([0.2, 0.0, 0.0], [0.2, 0.1, 0.0], [0.2, 0.1, 0.3], [0.0, 0.0, 0.0], [0.1, 0.0, 0.3]):
        q = p + R @ np.array(local)  # point on a face / edge / corner / box centre
        _finite_value_and_gradient(lambda cc, pp: sphere_box(cc, 0.0, R, pp, h), q, p.copy())
        _finite_value_and_gradient(lambda cc, pp: capsule_box(cc, cc, 0.0, R, pp, h, n_spheres=2), q, p.copy())
        _finite_value_and_gradient(lambda cc, pp: capsule_box(cc, pp, 0.05, R, pp, h, n_spheres=4), q, p.copy())
    assert sphere_box(p + R @ np.array([0.2, 0.0, 0.0]), 0.0, R, p, h) <= 0.0
    assert sphere_box(p, 0.0, R, p, h) < -0.09  # point deep inside: about -min(h) = -0.1
    zero_box = Box((0.0, 0.0, 0.0))
    assert math.isfinite(signed_distance(Sphere(0.1), (np.eye(3), c), zero_box, (np.eye(3), c)))


@pytest.mark.parametrize("call, name", [
    (lambda: sphere_sphere(np.zeros(3), -0.1, np.ones(3), 0.1), "r1"),
    (lambda: sphere_sphere(np.zeros(3), 0.1, np.ones(3), float("nan")), "r2"),
    (lambda: sphere_sphere(np.zeros(4), 0.1, np.ones(3), 0.1), "c1"),
    (lambda: sphere_sphere(np.zeros(3), 0.1, np.ones((3, 3)), 0.1), "c2"),
    (lambda: sphere_sphere(np.zeros(3), 0.1, np.ones(3), 0.1, eps=0.0), "eps"),
    (lambda: capsule_sphere(np.zeros(3), np.ones(2), 0.1, np.ones(3), 0.1), "b"),
    (lambda: capsule_sphere(np.zeros(3), np.ones(3), -1.0, np.ones(3), 0.1), "r"),
    (lambda: capsule_capsule(np.zeros(3), np.ones(3), 0.1, np.ones(3), np.ones(3), -0.2), "r2"),
    (lambda: capsule_capsule(np.zeros(3), np.ones(3), 0.1, np.ones(3), np.ones(3), 0.2, n_spheres=0), "n_spheres"),
    (lambda: capsule_capsule(ca.SX.sym("a", 3), np.ones(3), 0.1, np.ones(3), np.ones(3), 0.2), "n_spheres"),
    (lambda: sphere_box(np.zeros(3), 0.1, np.eye(3), np.zeros(3), (0.1, -0.1, 0.1)), "h"),
    (lambda: sphere_box(np.zeros(3), 0.1, np.eye(3), np.zeros(3), (0.1, 0.1)), "h"),
    (lambda: sphere_box(np.zeros(3), 0.1, np.eye(4), np.zeros(3), (0.1, 0.1, 0.1)), "R"),
    (lambda: sphere_box(np.zeros(3), 0.1, 2 * np.eye(3), np.zeros(3), (0.1, 0.1, 0.1)), "R"),
    (lambda: capsule_box(np.zeros(3), np.ones(3), 0.1, np.eye(3), np.zeros(2), (0.1, 0.1, 0.1)), "p"),
    (lambda: capsule_box(np.zeros(3), np.ones(3), 0.1, np.eye(3), np.zeros(3), (1, 1, 1), softmin_tol=-1), "softmin_tol"),
    (lambda: Sphere(-0.1), "Sphere.radius"),
    (lambda: Capsule(0.1, (0, 0, 0), (0, 0)), "Capsule.b"),
    (lambda: Capsule.along_z(0.1, -1.0), "length"),
    (lambda: Box((0.1, 0.1, -0.1)), "Box.half_extents"),
    (lambda: Box((0.1, 0.1)), "Box.half_extents"),
    (lambda: signed_distance(Sphere(0.1), (np.eye(3),), Sphere(0.1), (np.eye(3), np.zeros(3))), "pose1"),
    (lambda: signed_distance(Sphere(0.1), (np.eye(3), np.zeros(3)), Sphere(0.1), (np.eye(3), np.zeros(5))), "pose2"),
    (lambda: signed_distance("ball", (np.eye(3), np.zeros(3)), Sphere(0.1), (np.eye(3), np.zeros(3))), "shape1"),
    (lambda: error_bound(Capsule.along_z(0.1, 1.0), Box((1, 1, 1)), n_spheres=-2), "n_spheres"),
])
def test_bad_input_raises_value_error_naming_it(call, name: str) -> None:
    with pytest.raises(ValueError, match=name.replace(".", r"\.")):
        call()


def test_box_box_not_supported() -> None:
    with pytest.raises(TypeError):
        signed_distance(Box((1, 1, 1)), (np.eye(3), np.zeros(3)), Box((1, 1, 1)), (np.eye(3), np.ones(3) * 3))


def test_covering_and_bounds_with_defaults_under_one_centimetre() -> None:
    for r, L in [(0.005, 1.0), (0.05, 0.5), (0.3, 0.0), (0.0, 0.2), (0.1, 2.0)]:
        k = n_covering_spheres(L, r, D.DEFAULT_COVER_TOL)
        rho = D._s.covering_radius(r, L, k)
        assert rho - r <= D.DEFAULT_COVER_TOL + 1e-15
        if k > 2:  # minimal: one sphere fewer would exceed the tolerance
            assert D._s.covering_radius(r, L, k - 1) - r > D.DEFAULT_COVER_TOL
        cap = Capsule.along_z(max(r, 1e-3), L)
        for other in (Sphere(0.1), Capsule.along_z(0.2, 0.3), Box((0.1, 0.2, 0.3))):
            assert error_bound(cap, other) <= 0.01


# ----------------------------------------------------------------------------------------------
# hypothesis property test
# ----------------------------------------------------------------------------------------------
unit = st.floats(-1.0, 1.0, allow_nan=False)
vec = st.tuples(unit, unit, unit).map(np.array)
rotvec = st.tuples(*(st.floats(-math.pi, math.pi, allow_nan=False),) * 3).map(lambda v: Rotation.from_rotvec(v).as_matrix())


@settings(max_examples=100, deadline=None)
@given(kind=st.sampled_from(["capsule-capsule", "capsule-box", "sphere-box", "capsule-sphere"]),
       r1=st.floats(0.001, 0.3), l1=st.floats(0.0, 1.0), size2=st.tuples(*(st.floats(0.001, 0.4),) * 3),
       R1=rotvec, R2=rotvec, p1=vec, p2=vec, eps=st.sampled_from([1e-4, 1e-3, 1e-2]))
def test_property_conservative_accurate_sign(kind, r1, l1, size2, R1, R2, p1, p2, eps) -> None:
    s1 = Capsule.along_z(r1, l1)
    s2 = {"capsule-capsule": Capsule.along_z(size2[0], size2[1]), "capsule-box": Box(size2),
          "sphere-box": Box(size2), "capsule-sphere": Sphere(size2[0])}[kind]
    if kind == "sphere-box":
        s1 = Sphere(r1)
    d = signed_distance(s1, (R1, p1), s2, (R2, p2), eps=eps)
    d_ex, _ = exact(s1, (R1, p1), s2, (R2, p2))
    assert math.isfinite(d)
    if d_ex >= 0.0:
        assert d <= d_ex + TOL
        assert d_ex - d <= error_bound(s1, s2, eps=eps) + TOL
    elif d_ex < -1e-9:
        assert d < 0.0


# ----------------------------------------------------------------------------------------------
# end-to-end: IPOPT with the distance as a constraint
# ----------------------------------------------------------------------------------------------
def test_ipopt_constraint_solution_is_collision_free() -> None:
    """Pull a capsule towards a target behind a box: the optimum touches the box, never penetrates."""
    box, caps = Box((0.2, 0.3, 0.1)), Capsule.along_z(0.05, 0.4)
    f = make_distance_function(caps, box)
    R_box = Rotation.from_rotvec([0.2, 0.1, -0.3]).as_matrix()
    R_caps = Rotation.from_rotvec([1.2, 0.0, 0.3]).as_matrix()
    x = ca.MX.sym("x", 3)
    target = np.array([0.0, 0.0, -0.5])
    nlp = {"x": x, "f": ca.sumsqr(x - target), "g": f(R_caps, x, R_box, np.zeros(3))}
    solver = ca.nlpsol("s", "ipopt", nlp, {"ipopt.print_level": 0, "print_time": False, "ipopt.tol": 1e-10})
    sol = solver(x0=[0.0, 0.0, 0.8], lbg=0.0, ubg=np.inf)
    assert solver.stats()["success"]
    p = np.array(sol["x"]).ravel()
    d_ex, _ = exact(caps, (R_caps, p), box, (R_box, np.zeros(3)))
    assert -1e-7 <= d_ex <= error_bound(caps, box) + 1e-7
