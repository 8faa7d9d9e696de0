"""Piecewise polynomials, quintic point-to-point profiles and C3 quartic splines (pure numpy/scipy).

Units: positions ``x``/``q`` in rad (joints) or m (Cartesian), times ``t`` in s; derivatives are in
unit/s, unit/s^2, ... accordingly.

The quartic spline is the smoothing technique of the spline-RRT* seed paper (Sec. 3.3, Eq. 8-11):
on every interval ``[t_i, t_{i+1}]``

    x_i(t) = a_i + b_i (t-t_i) + c_i (t-t_i)^2 + d_i (t-t_i)^3 + e_i (t-t_i)^4,

through the waypoints (C0), with continuous velocity, acceleration and jerk (C1-C3) at the inner
waypoints and given initial velocity, initial acceleration and final velocity: 5m equations for the
5m unknowns of every dimension, solved for all dimensions with one banded LU factorisation.
"""
from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Any

import numpy as np

from .banded import solve_banded

__all__ = [
    "quintic_time_law",
    "PiecewisePolynomial",
    "quintic",
    "quartic_spline",
    "clamped_cubic",
    "resample_path",
    "time_grid_from_path",
]


def quintic_time_law(s):
    """The rest-to-rest quintic time law ``p(s) = 10s³ − 15s⁴ + 6s⁵`` on s ∈ [0, 1] (zero velocity
    and acceleration at both ends) and its first two derivatives in s: ``(p, p', p'')``."""
    s = np.asarray(s, float)
    return (10 * s**3 - 15 * s**4 + 6 * s**5, 30 * s**2 - 60 * s**3 + 30 * s**4, 60 * s - 180 * s**2 + 120 * s**3)


ArrayLike = float | np.ndarray | list | tuple


# ----------------------------------------------------------------------------- validation helpers
def _float_array(value: Any, name: str) -> np.ndarray:
    if value is None:
        raise TypeError(f"{name}: expected a number or an array of numbers, got None")
    if isinstance(value, (str, bytes)):
        raise TypeError(f"{name}: expected a number or an array of numbers, got {value!r}")
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}: expected a number or an array of numbers, got {value!r}") from exc
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr)).tolist()
        raise ValueError(f"{name}: expected finite values, got non-finite entries at {bad}")
    return arr


def _check_int(value: Any, name: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise TypeError(f"{name}: expected an integer >= {minimum}, got {value!r}")
    if int(value) < minimum:
        raise ValueError(f"{name}: expected an integer >= {minimum}, got {value}")
    return int(value)


def _check_positive(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real):
        raise TypeError(f"{name}: expected a positive finite number, got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError(f"{name}: expected a positive finite number, got {value}")
    return v


def _strictly_increasing(t: Any, name: str, min_len: int = 2) -> np.ndarray:
    arr = _float_array(t, name)
    if arr.ndim != 1 or arr.size < min_len:
        raise ValueError(f"{name}: expected a 1-D array of at least {min_len} times [s], got shape {arr.shape}")
    steps = np.diff(arr)
    if np.any(steps <= 0.0):
        k = int(np.flatnonzero(steps <= 0.0)[0])
        raise ValueError(f"{name}: expected strictly increasing times [s], "
                         f"got {name}[{k}]={arr[k]!r} >= {name}[{k + 1}]={arr[k + 1]!r}")
    return arr


def _broadcast_vec(value: Any, n: int, name: str, default: float = 0.0) -> np.ndarray:
    """Scalar or (n,) -> (n,) float array (None -> default)."""
    if value is None:
        return np.full(n, float(default))
    arr = _float_array(value, name)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    arr = arr.reshape(-1) if arr.ndim == 2 and 1 in arr.shape else arr
    if arr.shape != (n,):
        raise ValueError(f"{name}: expected a scalar or an array of shape ({n},), got shape {np.shape(value)}")
    return arr


def _falling(p: int, k: int) -> float:
    """p (p-1) ... (p-k+1): coefficient of the k-th derivative of tau^p."""
    out = 1.0
    for j in range(k):
        out *= p - j
    return out


# ----------------------------------------------------------------------------- piecewise polynomial
class PiecewisePolynomial:
    """Vector-valued piecewise polynomial in the local power basis.

    On segment ``i`` (``breakpoints[i] <= t <= breakpoints[i+1]``)
    ``x(t) = sum_k coefficients[i, k, :] * (t - breakpoints[i])**k`` (ascending powers).

    Args:
        breakpoints: (m+1,) strictly increasing times [s].
        coefficients: (m, degree+1, n) coefficients; ``coefficients[i, k]`` has units unit/s^k.

    Evaluation convention: a time equal to an inner breakpoint ``t_i`` is evaluated on segment ``i``
    (right-continuous), ``t_m`` on the last segment. Times outside ``[t0, tf]`` by more than a
    round-off tolerance ``1e-10 * max(1, |t0|, |tf|)`` raise ValueError; times within the tolerance
    are clamped to the range (no extrapolation).
    """

    __slots__ = ("_t", "_c")

    def __init__(self, breakpoints: ArrayLike, coefficients: ArrayLike):
        t = _strictly_increasing(breakpoints, "breakpoints")
        c = _float_array(coefficients, "coefficients")
        m = t.size - 1
        if c.ndim != 3 or c.shape[0] != m or c.shape[1] < 1 or c.shape[2] < 1:
            raise ValueError(
                f"coefficients: expected shape ({m}, degree+1, n) for {m + 1} breakpoints, got shape {c.shape}"
            )
        t.setflags(write=False)
        c.setflags(write=False)
        self._t = t
        self._c = c

    # -- properties
    @property
    def breakpoints(self) -> np.ndarray:
        """(m+1,) breakpoint times [s] (read-only)."""
        return self._t

    @property
    def coefficients(self) -> np.ndarray:
        """(m, degree+1, n) local power-basis coefficients, ascending powers (read-only)."""
        return self._c

    @property
    def degree(self) -> int:
        return self._c.shape[1] - 1

    @property
    def n_segments(self) -> int:
        return self._c.shape[0]

    @property
    def dim(self) -> int:
        """Dimension n of the value x(t)."""
        return self._c.shape[2]

    @property
    def t0(self) -> float:
        """Start time [s]."""
        return float(self._t[0])

    @property
    def tf(self) -> float:
        """Final time [s]."""
        return float(self._t[-1])

    @property
    def duration(self) -> float:
        """tf - t0 [s]."""
        return float(self._t[-1] - self._t[0])

    @property
    def durations(self) -> np.ndarray:
        """(m,) segment durations h_i = t_{i+1} - t_i [s]."""
        return np.diff(self._t)

    def __repr__(self) -> str:
        return (f"PiecewisePolynomial(segments={self.n_segments}, degree={self.degree}, dim={self.dim}, "
                f"t=[{self.t0:g}, {self.tf:g}])")

    # -- derivatives and evaluation
    def _derivative_coefficients(self, k: int) -> np.ndarray:
        deg = self.degree
        if k > deg:
            return np.zeros((self.n_segments, 1, self.dim))
        scale = np.array([_falling(p + k, k) for p in range(deg - k + 1)])
        return self._c[:, k:, :] * scale[None, :, None]

    def derivative(self, k: int = 1) -> PiecewisePolynomial:
        """The k-th time derivative as a PiecewisePolynomial (degree ``max(degree-k, 0)``; zero if k > degree)."""
        k = _check_int(k, "k (derivative order)", 0)
        return PiecewisePolynomial(self._t, self._derivative_coefficients(k))

    def _check_times(self, t: Any) -> np.ndarray:
        arr = _float_array(t, "t")
        tol = 1e-10 * max(1.0, abs(self._t[0]), abs(self._t[-1]))
        if arr.size:
            lo, hi = float(arr.min()), float(arr.max())
            if lo < self._t[0] - tol or hi > self._t[-1] + tol:
                bad = lo if lo < self._t[0] - tol else hi
                raise ValueError(f"t={bad!r} s is outside the spline's time range [{self.t0!r}, {self.tf!r}] s")
        return np.clip(arr, self._t[0], self._t[-1])

    def segment_index(self, t: ArrayLike) -> np.ndarray:
        """Segment index of every time (see the class docstring for the convention at breakpoints)."""
        arr = self._check_times(t)
        return np.clip(np.searchsorted(self._t, arr, side="right") - 1, 0, self.n_segments - 1)

    def __call__(self, t: ArrayLike, derivative: int = 0) -> np.ndarray:
        """Evaluate the ``derivative``-th time derivative at ``t`` [s].

        Returns shape ``(n,)`` for a scalar ``t`` and ``t.shape + (n,)`` for an array.
        """
        k = _check_int(derivative, "derivative", 0)
        arr = self._check_times(t)
        flat = arr.reshape(-1)
        idx = np.clip(np.searchsorted(self._t, flat, side="right") - 1, 0, self.n_segments - 1)
        tau = (flat - self._t[idx])[:, None]
        c = self._derivative_coefficients(k)[idx]  # (N, deg+1, n)
        out = c[:, -1, :].copy()
        for p in range(c.shape[1] - 2, -1, -1):
            out *= tau
            out += c[:, p, :]
        return out.reshape(arr.shape + (self.dim,))

    def time_scaled(self, factor: float) -> PiecewisePolynomial:
        """The same path run ``factor`` times slower (factor > 1: slower, < 1: faster).

        The start time is kept: ``t' = t0 + factor (t - t0)``, so that ``y(t') = x(t)``; the k-th
        derivative is divided by ``factor**k``.
        """
        f = _check_positive(factor, "factor")
        t = self._t[0] + f * (self._t - self._t[0])
        powers = f ** -np.arange(self.degree + 1, dtype=float)
        return PiecewisePolynomial(t, self._c * powers[None, :, None])

    def sample(self, n: int, derivative: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """``n`` >= 2 uniform times over ``[t0, tf]`` [s] and the values there: ``(t (n,), x (n, dim))``."""
        n = _check_int(n, "n (number of samples)", 2)
        t = np.linspace(self._t[0], self._t[-1], n)
        return t, self(t, derivative)

    def max_abs(self, derivative: int = 0, samples_per_segment: int = 64) -> np.ndarray:
        """Max over time of ``|d^k x / dt^k|`` per dimension, shape (n,).

        Computed by dense sampling (``samples_per_segment`` uniform points per segment, both ends
        included) and Newton iterations towards a stationary point started from every sample; the
        result is the max over samples and Newton end points (all true values of the polynomial),
        so it never over-estimates and equals the exact maximum to round-off as soon as one sample
        lies in the basin of the maximising critical point (always for the low degrees used here
        and the default density).
        """
        seg_max, _ = segment_max_abs(self, derivative, samples_per_segment)
        return seg_max.max(axis=0)

    # -- serialisation
    def to_dict(self) -> dict:
        """JSON-serialisable dict (lists of floats); inverse of :meth:`from_dict`."""
        return {
            "type": "PiecewisePolynomial",
            "basis": "local_power_ascending",
            "breakpoints": self._t.tolist(),
            "coefficients": self._c.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict) -> PiecewisePolynomial:
        """Rebuild from :meth:`to_dict` output."""
        if not isinstance(data, dict):
            raise TypeError(f"data: expected a dict from PiecewisePolynomial.to_dict(), got {type(data).__name__}")
        missing = [k for k in ("breakpoints", "coefficients") if k not in data]
        if missing:
            raise ValueError(f"data: missing keys {missing}; expected 'breakpoints' and 'coefficients'")
        basis = data.get("basis", "local_power_ascending")
        if basis != "local_power_ascending":
            raise ValueError(f"data['basis']: expected 'local_power_ascending', got {basis!r}")
        return cls(data["breakpoints"], data["coefficients"])


def segment_max_abs(pp: PiecewisePolynomial, derivative: int = 0,
                    samples_per_segment: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Per-segment maximum of ``|x^(k)|``: ``(max (m, n), location as a fraction in [0, 1] of the segment (m, n))``.

    Dense sampling + Newton polishing, see :meth:`PiecewisePolynomial.max_abs`.
    """
    k = _check_int(derivative, "derivative", 0)
    s = _check_int(samples_per_segment, "samples_per_segment", 2)
    h = pp.durations
    c = pp._derivative_coefficients(k)  # (m, d+1, n)
    dc = np.zeros_like(c)
    ddc = np.zeros_like(c)
    dc[:, :-1] = c[:, 1:] * np.arange(1, c.shape[1])[None, :, None]
    ddc[:, :-1] = dc[:, 1:] * np.arange(1, c.shape[1])[None, :, None]

    def horner(coef: np.ndarray, tau: np.ndarray) -> np.ndarray:  # coef (m, d+1, n), tau (m, G, n)
        out = np.broadcast_to(coef[:, -1:, :], tau.shape).copy()
        for p in range(coef.shape[1] - 2, -1, -1):
            out = out * tau + coef[:, p:p + 1, :]
        return out

    frac = np.linspace(0.0, 1.0, s)
    tau = np.broadcast_to((frac[None, :] * h[:, None])[:, :, None], (pp.n_segments, s, pp.dim))
    vals = np.abs(horner(c, tau))
    t_new = tau.copy()
    for _ in range(8):  # Newton on the stationarity condition, started from every sample
        d1 = horner(dc, t_new)
        d2 = horner(ddc, t_new)
        step = np.divide(d1, d2, out=np.zeros_like(d1), where=np.abs(d2) > 1e-300)
        t_new = np.clip(t_new - step, 0.0, h[:, None, None])
    new_vals = np.abs(horner(c, t_new))
    use_new = new_vals > vals
    vals = np.where(use_new, new_vals, vals)
    tau = np.where(use_new, t_new, tau)
    best = np.argmax(vals, axis=1)[:, None, :]  # (m, 1, n)
    seg_max = np.take_along_axis(vals, best, axis=1)[:, 0, :]
    loc = np.take_along_axis(tau, best, axis=1)[:, 0, :] / h[:, None]
    return seg_max, loc


# ----------------------------------------------------------------------------- quintic
def quintic(q0: ArrayLike, qf: ArrayLike, T: float, v0: ArrayLike = 0.0, vf: ArrayLike = 0.0,
            a0: ArrayLike = 0.0, af: ArrayLike = 0.0, t0: float = 0.0) -> PiecewisePolynomial:
    """Quintic point-to-point profile on ``[t0, t0 + T]`` (one segment of degree 5).

    Args:
        q0, qf: start / goal position, scalar or (n,) [rad or m].
        T: duration [s] (> 0).
        v0, vf: start / goal velocity [unit/s]; a0, af: start / goal acceleration [unit/s^2]
            (scalar or (n,); default 0, i.e. the rest-to-rest minimum-jerk profile
            ``q0 + (qf - q0)(10 s^3 - 15 s^4 + 6 s^5)``, ``s = (t - t0)/T``).
        t0: start time [s].
    """
    q0a, qfa = _float_array(q0, "q0"), _float_array(qf, "qf")
    for arr, name in ((q0a, "q0"), (qfa, "qf")):
        if arr.ndim > 1:
            raise ValueError(f"{name}: expected a scalar or a 1-D array, got shape {arr.shape}")
    if q0a.ndim and qfa.ndim and q0a.size != qfa.size:
        raise ValueError(f"q0, qf: expected the same number of entries, got {q0a.size} (q0) and {qfa.size} (qf)")
    n = max(q0a.size if q0a.ndim else 1, qfa.size if qfa.ndim else 1)
    q0v, qfv = _broadcast_vec(q0a, n, "q0"), _broadcast_vec(qfa, n, "qf")
    Tv = _check_positive(T, "T (duration [s])")
    t0a = _float_array(t0, "t0")
    if t0a.ndim != 0:
        raise ValueError(f"t0: expected a scalar start time [s], got shape {t0a.shape}")
    t0v = float(t0a)
    v0v, vfv = _broadcast_vec(v0, n, "v0"), _broadcast_vec(vf, n, "vf")
    a0v, afv = _broadcast_vec(a0, n, "a0"), _broadcast_vec(af, n, "af")
    d = qfv - q0v
    c = np.empty((1, 6, n))
    c[0, 0], c[0, 1], c[0, 2] = q0v, v0v, 0.5 * a0v
    c[0, 3] = (20 * d - (8 * vfv + 12 * v0v) * Tv - (3 * a0v - afv) * Tv**2) / (2 * Tv**3)
    c[0, 4] = (-30 * d + (14 * vfv + 16 * v0v) * Tv + (3 * a0v - 2 * afv) * Tv**2) / (2 * Tv**4)
    c[0, 5] = (12 * d - 6 * (vfv + v0v) * Tv + (afv - a0v) * Tv**2) / (2 * Tv**5)
    return PiecewisePolynomial([t0v, t0v + Tv], c)


# ----------------------------------------------------------------------------- quartic spline (Eq. 11)
_KL, _KU = 3, 2  # lower / upper bandwidth of the normalised Eq. 11 system


def _quartic_triplets(h: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows, columns, values of the 5m x 5m Eq. 11 system in normalised unknowns.

    Unknowns ``p[5i+k] = coef_{i,k} h_i^k`` (position units, so the matrix is O(1) and independent of
    the time unit). Row order: v0, a0, then per segment i: start position, end position and, for inner
    waypoints, C1, C2, C3 (each multiplied by h_i^k), or vf for the last segment. Banded (3 lower, 2 upper).
    """
    m = h.size
    rows, cols, vals = [np.array([0, 1])], [np.array([1, 2])], [np.array([1.0, 2.0])]
    i = np.arange(m)
    base = 2 + 5 * i
    k = np.arange(5)
    rows += [base, np.repeat(base + 1, 5)]
    cols += [5 * i, (5 * i[:, None] + k[None, :]).ravel()]
    vals += [np.ones(m), np.ones(5 * m)]
    # derivative-matching rows: C1 (order 1), C2 (order 2), C3 (order 3) for i < m-1, vf for i = m-1
    inner = i[:-1]
    r = h[:-1] / h[1:]
    for order in (1, 2, 3):
        ks = np.arange(order, 5)
        w = np.array([_falling(int(p), order) for p in ks])
        row = base[:-1] + 1 + order
        rows += [np.repeat(row, ks.size), row]
        cols += [(5 * inner[:, None] + ks[None, :]).ravel(), 5 * (inner + 1) + order]
        vals += [np.tile(w, inner.size), -math.factorial(order) * r**order]
    ks = np.arange(1, 5)
    rows.append(np.full(4, 5 * m - 1))
    cols.append(5 * (m - 1) + ks)
    vals.append(ks.astype(float))
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)


def quartic_spline(times: ArrayLike, waypoints: ArrayLike, v0: ArrayLike | None = None,
                   a0: ArrayLike | None = None, vf: ArrayLike | None = None) -> PiecewisePolynomial:
    """C3 piecewise-quartic spline through waypoints (seed paper Eq. 8-11, any number m >= 1 of segments).

    Args:
        times: (m+1,) strictly increasing waypoint times t_k [s].
        waypoints: (m+1,) or (m+1, n) waypoint positions x_k [rad or m].
        v0: initial velocity [unit/s], a0: initial acceleration [unit/s^2], vf: final velocity [unit/s];
            scalar or (n,), default 0. The final acceleration is free (as in the paper).

    Returns:
        PiecewisePolynomial of degree 4 with m segments: C0 at all waypoints, C1-C3 at the inner ones.

    The 5m x 5m system (the same matrix for every dimension) is assembled in normalised unknowns
    ``coef_{i,k} h_i^k`` as a banded matrix (3 sub-, 2 super-diagonals) and solved for all n
    right-hand sides with one LAPACK banded LU (``gbsv``, partial pivoting): O(m n) time; m = 600,
    n = 14 takes ~1-2 ms in total (scipy.sparse spsolve: ~2 ms for the solve alone, dense: ~300 ms).

    Note: for uniform durations the jerk-continuity recursion has a transfer eigenvalue of -1, so a
    local disturbance (noisy waypoint, non-zero v0/a0) is propagated undamped, as a sign-alternating
    wiggle, to all later segments; pass smoothed / resampled waypoints for long paths.
    """
    t = _strictly_increasing(times, "times")
    x = _float_array(waypoints, "waypoints")
    m = t.size - 1
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] != m + 1 or x.shape[1] < 1:
        raise ValueError(f"waypoints: expected shape ({m + 1},) or ({m + 1}, n) to match {m + 1} times, "
                         f"got shape {x.shape}")
    n = x.shape[1]
    v0v, a0v, vfv = (_broadcast_vec(v, n, name) for v, name in ((v0, "v0"), (a0, "a0"), (vf, "vf")))
    h = np.diff(t)
    rows, cols, vals = _quartic_triplets(h)
    ab = np.zeros((_KL + _KU + 1, 5 * m))
    np.add.at(ab, (_KU + rows - cols, cols), vals)
    rhs = np.zeros((5 * m, n))
    rhs[0] = v0v * h[0]
    rhs[1] = a0v * h[0] ** 2
    base = 2 + 5 * np.arange(m)
    rhs[base] = x[:-1]
    rhs[base + 1] = x[1:]
    rhs[5 * m - 1] = vfv * h[-1]
    from scipy.linalg import solve_banded as scipy_solve_banded  # lazy: scipy.linalg is ~0.07 s of import

    try:
        p = scipy_solve_banded((_KL, _KU), ab, rhs, overwrite_ab=True, overwrite_b=True, check_finite=False)
    except np.linalg.LinAlgError as exc:  # pragma: no cover - never observed for durations h > 0
        raise ValueError(f"quartic spline system is singular for durations {h.tolist()}") from exc
    p = p.reshape(m, 5, n)
    coef = p / h[:, None, None] ** np.arange(5)[None, :, None]
    return PiecewisePolynomial(t, coef)


def clamped_cubic(t: ArrayLike, y: ArrayLike, at: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The C2 cubic spline through ``y`` ((m+1) × n) at strictly increasing times ``t`` (m+1,) [s]
    with zero velocity at both ends (scipy's ``CubicSpline(t, y, axis=0, bc_type="clamped")``,
    without importing scipy.interpolate or scipy.linalg, 0.1-0.2 s of start-up), evaluated at the times ``at``
    (k,) [s]: positions, velocities [unit/s] and accelerations [unit/s²], each k × n. Times outside
    ``[t_0, t_m]`` extrapolate the end pieces."""
    t = _strictly_increasing(t, "t")
    y = np.asarray(y, float)
    if y.ndim != 2 or y.shape[0] != t.size:
        raise ValueError(f"y: expected shape ({t.size}, n) to match {t.size} times, got shape {y.shape}")
    at = np.asarray(at, float)
    h = np.diff(t)
    d = np.diff(y, axis=0) / h[:, None]            # secant slopes
    m = t.size - 1
    slope = np.zeros_like(y)                        # knot velocities; the ends clamped to 0
    if m >= 2:
        # interior rows: h_i s_{i-1} + 2 (h_{i-1} + h_i) s_i + h_{i-1} s_{i+1} = 3 (h_i d_{i-1} + h_{i-1} d_i)
        ab = np.zeros((3, m - 1))
        ab[0, 1:] = h[:-2]                          # super-diagonal: h_{i-1} (row i, column i+1)
        ab[1] = 2.0 * (h[:-1] + h[1:])
        ab[2, :-1] = h[2:]                          # sub-diagonal: h_i (row i, column i-1)
        rhs = 3.0 * (h[1:, None] * d[:-1] + h[:-1, None] * d[1:])
        slope[1:-1] = solve_banded((1, 1), ab, rhs)   # numpy alone: scipy.linalg is not imported for a plan
    i = np.clip(np.searchsorted(t, at, side="right") - 1, 0, m - 1)
    s = (at - t[i])[:, None]
    hi = h[i][:, None]
    c2 = (3.0 * d[i] - 2.0 * slope[i] - slope[i + 1]) / hi
    c3 = (slope[i] + slope[i + 1] - 2.0 * d[i]) / hi ** 2
    return (y[i] + s * (slope[i] + s * (c2 + s * c3)), slope[i] + s * (2.0 * c2 + 3.0 * s * c3),
            2.0 * c2 + 6.0 * s * c3)


# ----------------------------------------------------------------------------- path helpers
def _path_and_lengths(path: Any, metric: ArrayLike | None) -> tuple[np.ndarray, np.ndarray]:
    p = _float_array(path, "path")
    if p.ndim == 1:
        p = p[:, None]
    if p.ndim != 2 or p.shape[0] < 2 or p.shape[1] < 1:
        raise ValueError(f"path: expected an (N, d) array with N >= 2 points, got shape {np.shape(path)}")
    w = np.ones(p.shape[1]) if metric is None else _broadcast_vec(metric, p.shape[1], "metric")
    if np.any(w < 0):
        raise ValueError(f"metric: expected non-negative per-dimension weights, got {w.tolist()}")
    seg = np.sqrt(((np.diff(p, axis=0) * w) ** 2).sum(axis=1))
    return p, seg


def resample_path(path: ArrayLike, n: int, metric: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Resample a polyline at ``n`` points uniformly spaced in (weighted) arc length.

    Args:
        path: (N, d) polyline vertices (N >= 2) [rad or m].
        n: number of output points (>= 2); the first and last vertex are kept exactly.
        metric: optional (d,) non-negative weights w; segment length = ``||w * dx||_2``.

    Returns:
        ``(s (n,), points (n, d))`` with ``s`` the normalised arc length in [0, 1]. A path of zero
        length returns ``s = linspace(0, 1, n)`` and copies of its single point.
    """
    p, seg = _path_and_lengths(path, metric)
    n = _check_int(n, "n (number of points)", 2)
    total = float(seg.sum())
    s = np.linspace(0.0, 1.0, n)
    if total <= 0.0:
        return s, np.repeat(p[:1], n, axis=0)
    keep = np.concatenate([[True], seg > 0.0])  # drop repeated vertices (zero-length segments)
    cum = np.concatenate([[0.0], np.cumsum(seg)])[keep] / total
    pk = p[keep]
    cum[-1] = 1.0
    pts = np.column_stack([np.interp(s, cum, pk[:, j]) for j in range(p.shape[1])])
    pts[0], pts[-1] = p[0], p[-1]
    return s, pts


def time_grid_from_path(path: ArrayLike, total_time: float, metric: ArrayLike | None = None,
                        min_fraction: float = 0.05) -> np.ndarray:
    """Waypoint times [s] on ``[0, total_time]`` with intervals proportional to segment lengths.

    Every interval gets at least ``min_fraction`` times the mean interval length (the floor keeps
    repeated points from producing zero-length intervals); a path of zero length gets uniform times.

    Args:
        path: (N, d) waypoints (N >= 2); total_time: duration [s] (> 0);
        metric: optional (d,) weights as in :func:`resample_path`; min_fraction: floor in (0, 1].
    Returns:
        (N,) strictly increasing times, ``t[0] = 0``, ``t[-1] = total_time``.
    """
    _, seg = _path_and_lengths(path, metric)
    T = _check_positive(total_time, "total_time")
    frac = _check_positive(min_fraction, "min_fraction")
    if frac > 1.0:
        raise ValueError(f"min_fraction: expected a value in (0, 1], got {min_fraction}")
    if seg.sum() <= 0.0:
        seg = np.ones_like(seg)
    seg = np.maximum(seg, frac * seg.mean())
    t = np.concatenate([[0.0], np.cumsum(seg)]) * (T / seg.sum())
    t[-1] = T
    return t
