"""Tests of optplan.geometry.splines: quintic profiles, the Eq. 8-11 quartic spline, path helpers."""
from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from optplan.geometry.splines import PiecewisePolynomial, quartic_spline, quintic, resample_path, time_grid_from_path


def _segment_end_derivative(pp: PiecewisePolynomial, i: int, k: int) -> np.ndarray:
    """k-th derivative of segment i evaluated at its right end, from segment i's coefficients only."""
    c = pp.derivative(k).coefficients[i]
    h = pp.durations[i]
    return sum(c[p] * h**p for p in range(c.shape[0]))


def _segment_start_derivative(pp: PiecewisePolynomial, i: int, k: int) -> np.ndarray:
    return pp.derivative(k).coefficients[i, 0]


def _random_problem(rng, m, n):
    times = np.concatenate([[rng.uniform(-1, 1)], rng.uniform(0.2, 2.0, m)]).cumsum()
    x = rng.normal(size=(m + 1, n))
    v0, a0, vf = rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)
    return times, x, v0, a0, vf


def _check_quartic(pp, times, x, v0, a0, vf, tol=1e-9):
    m = times.size - 1
    scale = 1.0 + np.abs(pp.coefficients).max() * max(1.0, pp.durations.max() ** 4)
    assert pp.degree == 4 and pp.n_segments == m
    np.testing.assert_allclose(pp(times), x, atol=tol * scale)                       # C0
    for i in range(m):                                                              # both ends of each piece
        np.testing.assert_allclose(_segment_start_derivative(pp, i, 0), x[i], atol=tol * scale)
        np.testing.assert_allclose(_segment_end_derivative(pp, i, 0), x[i + 1], atol=tol * scale)
    for k in (1, 2, 3):                                                             # C1..C3 at inner waypoints
        for i in range(m - 1):
            left = _segment_end_derivative(pp, i, k)
            right = _segment_start_derivative(pp, i + 1, k)
            np.testing.assert_allclose(left, right, atol=tol * scale, err_msg=f"C{k} at waypoint {i + 1}")
    np.testing.assert_allclose(pp(times[0], 1), v0, atol=tol * scale)
    np.testing.assert_allclose(pp(times[0], 2), a0, atol=tol * scale)
    np.testing.assert_allclose(_segment_end_derivative(pp, m - 1, 1), vf, atol=tol * scale)


# ----------------------------------------------------------------------------- quintic
def test_quintic_boundary_values():
    rng = np.random.default_rng(0)
    q0, qf, v0, vf, a0, af = (rng.normal(size=3) for _ in range(6))
    pp = quintic(q0, qf, 2.5, v0=v0, vf=vf, a0=a0, af=af, t0=1.0)
    assert pp.degree == 5 and pp.dim == 3 and pp.t0 == 1.0 and pp.tf == pytest.approx(3.5)
    for t, vals in ((1.0, (q0, v0, a0)), (3.5, (qf, vf, af))):
        for k, expected in enumerate(vals):
            np.testing.assert_allclose(pp(t, k), expected, atol=1e-11)


def test_quintic_is_the_rest_to_rest_minimum_jerk_profile():
    q0, qf, T = np.array([0.3, -1.0]), np.array([1.3, 2.0]), 4.0
    pp = quintic(q0, qf, T)
    t = np.linspace(0.0, T, 201)
    s = t / T
    closed = q0 + (qf - q0) * (10 * s**3 - 15 * s**4 + 6 * s**5)[:, None]
    np.testing.assert_allclose(pp(t), closed, atol=1e-12)
    # peak velocity 15/8 (qf - q0)/T at mid-time
    np.testing.assert_allclose(pp.max_abs(1), 15 / 8 * np.abs(qf - q0) / T, rtol=1e-12)

    # any admissible perturbation (zero position/velocity/acceleration at both ends) has more jerk
    def jerk_integral(coef):
        tt = np.linspace(0, T, 4001)
        jerk = sum(coef[p] * p * (p - 1) * (p - 2) * tt ** (p - 3) for p in range(3, coef.size))
        return np.trapezoid(jerk**2, tt) if hasattr(np, "trapezoid") else np.trapz(jerk**2, tt)

    base = pp.coefficients[0, :, 0]
    j0 = jerk_integral(base)
    bump = np.polynomial.polynomial.polypow([0.0, 1.0 / T, -1.0 / T**2], 3)  # s^3 (1-s)^3 in t
    for eps in (-0.5, 0.1, 2.0):
        pert = np.zeros(7)
        pert[:6] = base
        pert += eps * bump
        assert jerk_integral(pert) > j0


def test_quintic_scalar_and_broadcast():
    pp = quintic(0.0, [1.0, 2.0], 1.0)
    assert pp.dim == 2
    np.testing.assert_allclose(pp(1.0), [1.0, 2.0])


# ----------------------------------------------------------------------------- quartic spline
def test_quartic_spline_three_segments_matches_hand_written_eq11():
    """The 15 x 15 system of Eq. 11 written out as in the paper, one dimension."""
    t = np.array([0.0, 0.4, 1.1, 1.5])
    x = np.array([0.0, 1.0, -0.5, 2.0])
    v0, a0, vf = 0.3, -0.7, 0.2
    h0, h1, h2 = np.diff(t)
    A = np.zeros((15, 15))
    b = np.zeros(15)
    # unknowns [a0 b0 c0 d0 e0 | a1 .. e1 | a2 .. e2]
    A[0, 0] = 1; b[0] = x[0]
    A[1, 5] = 1; b[1] = x[1]
    A[2, 10] = 1; b[2] = x[2]
    A[3, 0:5] = [1, h0, h0**2, h0**3, h0**4]; b[3] = x[1]
    A[4, 5:10] = [1, h1, h1**2, h1**3, h1**4]; b[4] = x[2]
    A[5, 10:15] = [1, h2, h2**2, h2**3, h2**4]; b[5] = x[3]
    A[6, 1:5] = [1, 2 * h0, 3 * h0**2, 4 * h0**3]; A[6, 6] = -1
    A[7, 6:10] = [1, 2 * h1, 3 * h1**2, 4 * h1**3]; A[7, 11] = -1
    A[8, 2:5] = [1, 3 * h0, 6 * h0**2]; A[8, 7] = -1
    A[9, 7:10] = [1, 3 * h1, 6 * h1**2]; A[9, 12] = -1
    A[10, 3:5] = [1, 4 * h0]; A[10, 8] = -1
    A[11, 8:10] = [1, 4 * h1]; A[11, 13] = -1
    A[12, 1] = 1; b[12] = v0
    A[13, 2] = 2; b[13] = a0
    A[14, 11:15] = [1, 2 * h2, 3 * h2**2, 4 * h2**3]; b[14] = vf
    expected = np.linalg.solve(A, b).reshape(3, 5)
    pp = quartic_spline(t, x, v0=v0, a0=a0, vf=vf)
    np.testing.assert_allclose(pp.coefficients[:, :, 0], expected, rtol=1e-10, atol=1e-10)


def test_quartic_spline_interpolation_continuity_and_boundary_conditions():
    rng = np.random.default_rng(1)
    times, x, v0, a0, vf = _random_problem(rng, 7, 3)
    pp = quartic_spline(times, x, v0=v0, a0=a0, vf=vf)
    _check_quartic(pp, times, x, v0, a0, vf)
    # evaluating just left / right of the inner waypoints agrees as well
    eps = 1e-7
    for k in (0, 1, 2, 3):
        np.testing.assert_allclose(pp(times[1:-1] - eps, k), pp(times[1:-1] + eps, k), atol=1e-4 * (1 + np.abs(pp(times[1:-1], k)).max()))


def test_quartic_spline_defaults_are_zero_and_single_segment_works():
    pp = quartic_spline([0.0, 2.0], [[1.0, -1.0], [3.0, 0.5]])
    _check_quartic(pp, np.array([0.0, 2.0]), np.array([[1.0, -1.0], [3.0, 0.5]]), 0.0, 0.0, 0.0)
    # m = 1: x = x0 + d s^3 T^3 + e s^4 T^4 with x(T) = xf, x'(T) = 0  ->  4 s^3 - 3 s^4 profile
    s = np.linspace(0, 1, 11)
    np.testing.assert_allclose(pp(2.0 * s)[:, 0], 1.0 + 2.0 * (4 * s**3 - 3 * s**4), atol=1e-12)


def test_quartic_spline_one_dimensional_waypoints():
    pp = quartic_spline([0.0, 1.0, 2.0], [0.0, 1.0, 0.0])
    assert pp.dim == 1
    assert pp(1.0).shape == (1,)
    assert pp(np.array([0.5, 1.5])).shape == (2, 1)


@settings(max_examples=50, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(1, 12), n=st.integers(1, 4))
def test_quartic_spline_property(seed, m, n):
    rng = np.random.default_rng(seed)
    times, x, v0, a0, vf = _random_problem(rng, m, n)
    pp = quartic_spline(times, x, v0=v0, a0=a0, vf=vf)
    _check_quartic(pp, times, x, v0, a0, vf, tol=1e-8)


def test_quartic_spline_600_segments_14_dims_is_fast():
    rng = np.random.default_rng(2)
    m, n = 600, 14
    times = np.concatenate([[0.0], rng.uniform(0.05, 0.2, m)]).cumsum()
    x = np.cumsum(rng.normal(scale=0.05, size=(m + 1, n)), axis=0)
    quartic_spline(times, x)  # warm-up (imports, allocation)
    best = math.inf
    for _ in range(3):
        t_start = time.perf_counter()
        pp = quartic_spline(times, x)
        best = min(best, time.perf_counter() - t_start)
    print(f"\nquartic_spline m={m} n={n}: {best * 1e3:.2f} ms")
    assert best < 2.0
    np.testing.assert_allclose(pp(times), x, atol=1e-9)
    for k in (1, 2, 3):
        left = np.array([_segment_end_derivative(pp, i, k) for i in range(0, m - 1, 37)])
        right = np.array([_segment_start_derivative(pp, i + 1, k) for i in range(0, m - 1, 37)])
        np.testing.assert_allclose(left, right, rtol=1e-7, atol=1e-7 * np.abs(right).max())


# ----------------------------------------------------------------------------- PiecewisePolynomial
def test_time_scaled():
    rng = np.random.default_rng(3)
    times, x, v0, a0, vf = _random_problem(rng, 4, 2)
    pp = quartic_spline(times, x, v0=v0, a0=a0, vf=vf)
    f = 2.5
    slow = pp.time_scaled(f)
    assert slow.t0 == pytest.approx(pp.t0) and slow.duration == pytest.approx(f * pp.duration)
    t = np.linspace(pp.t0, pp.tf, 57)
    t_slow = pp.t0 + f * (t - pp.t0)
    for k in range(5):
        np.testing.assert_allclose(slow(t_slow, k), pp(t, k) / f**k, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(slow.max_abs(1), pp.max_abs(1) / f, rtol=1e-9)


def test_evaluation_shapes_derivatives_and_convention():
    pp = PiecewisePolynomial([0.0, 1.0, 3.0], [[[0.0], [1.0]], [[1.0], [-1.0]]])  # degree 1, dim 1
    assert pp(1.0, 1)[0] == -1.0          # breakpoint belongs to the right segment
    assert pp(3.0, 1)[0] == -1.0          # last breakpoint to the last segment
    assert pp(np.zeros((2, 3))).shape == (2, 3, 1)
    np.testing.assert_array_equal(pp(0.5, 5), [0.0])  # beyond the degree: zero
    d = pp.derivative(1)
    assert d.degree == 0 and d(2.0)[0] == -1.0
    t, xs = pp.sample(5)
    np.testing.assert_allclose(t, np.linspace(0, 3, 5))
    assert xs.shape == (5, 1)
    assert pp(3.0 + 1e-13)[0] == pytest.approx(-1.0)  # round-off outside the range is clamped


def test_max_abs_is_exact_for_a_cubic_velocity():
    rng = np.random.default_rng(4)
    times, x, v0, a0, vf = _random_problem(rng, 5, 3)
    pp = quartic_spline(times, x, v0=v0, a0=a0, vf=vf)
    t = np.linspace(pp.t0, pp.tf, 400001)
    dense = np.abs(pp(t, 1)).max(axis=0)
    mx = pp.max_abs(1)
    assert np.all(mx >= dense - 1e-12)
    np.testing.assert_allclose(mx, dense, rtol=1e-8)


def test_to_dict_round_trip_through_json():
    pp = quintic([0.0, 1.0], [2.0, -1.0], 3.0, v0=[0.1, 0.2])
    data = json.loads(json.dumps(pp.to_dict()))
    back = PiecewisePolynomial.from_dict(data)
    np.testing.assert_array_equal(back.breakpoints, pp.breakpoints)
    np.testing.assert_array_equal(back.coefficients, pp.coefficients)


# ----------------------------------------------------------------------------- path helpers
def test_resample_path_uniform_arc_length():
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 3.0]])  # repeated vertex, length 4
    s, pts = resample_path(path, 5)
    np.testing.assert_allclose(s, np.linspace(0, 1, 5))
    np.testing.assert_allclose(pts, [[0, 0], [1, 0], [1, 1], [1, 2], [1, 3]], atol=1e-12)
    # weights: the y axis counts 3x, total weighted length 1 + 9 = 10
    _, pts_w = resample_path(path, 11, metric=[1.0, 3.0])
    np.testing.assert_allclose(pts_w[1], [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(pts_w[-2], [1.0, 8.0 / 3.0], atol=1e-12)
    _, same = resample_path(np.ones((3, 2)), 4)
    np.testing.assert_array_equal(same, np.ones((4, 2)))


def test_time_grid_from_path():
    path = np.array([[0.0], [1.0], [1.0], [4.0]])
    t = time_grid_from_path(path, 10.0, min_fraction=0.05)
    assert t[0] == 0.0 and t[-1] == 10.0
    assert np.all(np.diff(t) > 0)
    h = np.diff(t)
    assert h[2] / h[0] == pytest.approx(3.0)
    assert h[1] == pytest.approx(0.05 * 4.0 / 3.0 * h[0])
    np.testing.assert_allclose(time_grid_from_path(np.zeros((4, 2)), 3.0), [0, 1, 2, 3])
    pp = quartic_spline(t, path)  # usable as spline times
    np.testing.assert_allclose(pp(t), path, atol=1e-9)


# ----------------------------------------------------------------------------- input validation
def test_error_non_increasing_times():
    with pytest.raises(ValueError, match=r"strictly increasing.*times\[1\]"):
        quartic_spline([0.0, 1.0, 1.0], [0.0, 1.0, 2.0])


def test_error_nan_waypoint():
    with pytest.raises(ValueError, match="waypoints.*finite"):
        quartic_spline([0.0, 1.0, 2.0], [0.0, np.nan, 2.0])


def test_error_waypoint_shape():
    with pytest.raises(ValueError, match=r"waypoints.*\(3,\) or \(3, n\).*\(4, 2\)"):
        quartic_spline([0.0, 1.0, 2.0], np.zeros((4, 2)))


def test_error_fewer_than_one_segment():
    with pytest.raises(ValueError, match="at least 2"):
        quartic_spline([0.0], [[1.0]])


def test_error_boundary_condition_shape():
    with pytest.raises(ValueError, match=r"v0.*\(2,\)"):
        quartic_spline([0.0, 1.0], np.zeros((2, 2)), v0=[1.0, 2.0, 3.0])


def test_error_non_numeric_input():
    with pytest.raises(TypeError, match="times"):
        quartic_spline("abc", [0.0, 1.0])


def test_error_quintic_duration():
    with pytest.raises(ValueError, match="T .*positive"):
        quintic(0.0, 1.0, 0.0)
    with pytest.raises(TypeError, match="T "):
        quintic(0.0, 1.0, None)


def test_error_quintic_shape_mismatch():
    with pytest.raises(ValueError, match="qf"):
        quintic([0.0, 1.0], [1.0, 2.0, 3.0], 1.0)


def test_error_evaluation_outside_range():
    pp = quintic(0.0, 1.0, 2.0, t0=1.0)
    with pytest.raises(ValueError, match=r"t=3\.5 s is outside .*\[1\.0, 3\.0\]"):
        pp(np.array([1.5, 3.5]))
    with pytest.raises(ValueError, match="derivative"):
        pp(1.5, derivative=-1)
    with pytest.raises(TypeError, match="derivative"):
        pp(1.5, derivative=1.5)


def test_error_bad_coefficients_shape():
    with pytest.raises(ValueError, match=r"coefficients.*\(2, degree\+1, n\)"):
        PiecewisePolynomial([0.0, 1.0, 2.0], np.zeros((3, 4, 1)))


def test_error_time_scaled_factor():
    with pytest.raises(ValueError, match="factor"):
        quintic(0.0, 1.0, 1.0).time_scaled(-2.0)


def test_error_from_dict():
    with pytest.raises(ValueError, match="missing keys"):
        PiecewisePolynomial.from_dict({"breakpoints": [0, 1]})
    with pytest.raises(TypeError, match="dict"):
        PiecewisePolynomial.from_dict([1, 2])


def test_error_path_helpers():
    with pytest.raises(ValueError, match="N >= 2"):
        resample_path(np.zeros((1, 3)), 5)
    with pytest.raises(ValueError, match="n "):
        resample_path(np.zeros((3, 3)), 1)
    with pytest.raises(ValueError, match="metric"):
        resample_path(np.zeros((3, 2)), 4, metric=[1.0, -1.0])
    with pytest.raises(ValueError, match="total_time"):
        time_grid_from_path(np.zeros((3, 2)), 0.0)
    with pytest.raises(ValueError, match="min_fraction"):
        time_grid_from_path(np.zeros((3, 2)), 1.0, min_fraction=2.0)


@pytest.mark.parametrize("m", [1, 2, 3, 40])
def test_clamped_cubic_matches_scipys_clamped_cubic_spline(m):
    """The warm start's cubic spline (no scipy.interpolate at start-up) against scipy's CubicSpline with
    zero end velocities: positions, velocities and accelerations, at and between the knots and past the
    ends."""
    from scipy.interpolate import CubicSpline

    from optplan.geometry.splines import clamped_cubic

    rng = np.random.default_rng(m)
    t = 3.0 + np.cumsum(rng.uniform(0.05, 2.0, m + 1))
    y = rng.normal(size=(m + 1, 4))
    at = np.r_[np.linspace(t[0] - 0.5, t[-1] + 0.5, 201), t]
    ref = CubicSpline(t, y, axis=0, bc_type=((1, np.zeros(4)), (1, np.zeros(4))))
    for got, k in zip(clamped_cubic(t, y, at), range(3)):
        np.testing.assert_allclose(got, ref(at, k), rtol=0, atol=1e-10 * max(1.0, np.abs(ref(at, k)).max()))
    with pytest.raises(ValueError, match="y: expected shape"):
        clamped_cubic(t, y[:-1], at)
    with pytest.raises(ValueError):
        clamped_cubic(t[::-1], y, at)
