"""The numpy banded solver (``optplan.geometry.banded``) against LAPACK's (scipy), and the plan's
spline fits without ``scipy.linalg``."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import scipy.linalg as sl

from optplan.errors import ConfigurationError
from optplan.geometry.banded import solve_banded, solve_banded_dense


@pytest.mark.parametrize("n,kl,ku,k", [(1, 0, 0, 1), (2, 1, 1, 1), (7, 1, 1, 3), (60, 2, 2, 14), (40, 0, 3, 2),
                                       (40, 3, 0, 2), (120, 1, 2, 5), (5, 4, 4, 1)])
def test_banded_solve_matches_lapack(n, kl, ku, k):
    rng = np.random.default_rng(n * 100 + kl * 10 + ku)
    ab = rng.standard_normal((kl + ku + 1, n))
    if kl == 0 or ku == 0:   # a random triangular matrix is ill-conditioned (~1e15 at n = 40): a dominant diagonal
        ab[ku] += np.sign(ab[ku]) * (kl + ku + 1)
    b = rng.standard_normal((n, k))
    A = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - kl), min(n, i + ku + 1)):
            A[i, j] = ab[ku + i - j, j]
    want = np.linalg.solve(A, b)      # LAPACK's dense solve of the same matrix
    if n > 1:                         # scipy 1.13's solve_banded fails on a 1 x 1 system
        np.testing.assert_allclose(sl.solve_banded((kl, ku), ab, b), want, rtol=1e-9,
                                   atol=1e-10 * np.abs(want).max())
    got = solve_banded((kl, ku), ab, b)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-10 * np.abs(want).max())
    np.testing.assert_allclose(solve_banded((kl, ku), ab, b[:, 0]), want[:, 0], rtol=1e-9,
                               atol=1e-10 * np.abs(want).max())


def test_banded_solve_pivots_on_a_zero_diagonal_and_reports_a_singular_matrix():
    A = np.array([[0.0, 1.0, 0.0], [2.0, 0.0, 1.0], [0.0, 3.0, 1.0]])   # no LU without a row exchange
    b = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(solve_banded_dense(A, b), np.linalg.solve(A, b), rtol=1e-12, atol=1e-14)
    with pytest.raises(np.linalg.LinAlgError, match="singular"):
        solve_banded_dense(np.array([[1.0, 2.0], [2.0, 4.0]]), np.ones(2))


def test_banded_solve_names_a_shape_that_does_not_fit():
    with pytest.raises(ConfigurationError, match=r"ab: expected shape \(3, n\)"):
        solve_banded((1, 1), np.ones((2, 4)), np.ones(4))
    with pytest.raises(ConfigurationError, match="b: expected 4 rows"):
        solve_banded((1, 1), np.ones((3, 4)), np.ones(5))
    with pytest.raises(ConfigurationError, match="A: expected a square matrix"):
        solve_banded_dense(np.ones((2, 3)), np.ones(2))


def test_b_spline_fit_system_as_the_segment_nlp_builds_it():
    """The control points through knot values with given end velocities (``SplineCore.fit``'s
    system: the uniform cubic B-spline's rows), against a dense LAPACK solve."""
    from optplan.problem.bspline import knot_matrices

    rng = np.random.default_rng(7)
    N, h = 135, 0.03
    M = knot_matrices(N)
    A = np.vstack([M["qd"][[0]] / h, M["q"], M["qd"][[N]] / h])
    b = rng.standard_normal((N + 3, 14))
    np.testing.assert_allclose(solve_banded_dense(A, b), np.linalg.solve(A, b), rtol=1e-9, atol=1e-12)


_NO_LINALG = """
import sys
import numpy as np
import scipy.sparse          # what it imports itself (older releases: scipy.linalg) is not the plan's doing
before = set(sys.modules)
import optplan.cli, optplan.pipeline, optplan.model.kinematics
from optplan.geometry.splines import clamped_cubic
t = np.linspace(0.0, 1.0, 9)
clamped_cubic(t, np.sin(np.c_[t, 2 * t]), np.linspace(0.0, 1.0, 30))
print(" ".join(m for m in ("scipy.linalg", "scipy.sparse.linalg") if m in sys.modules and m not in before))
"""


def test_the_plan_commands_modules_and_spline_fits_do_not_import_scipy_linalg(tmp_path):
    """scipy.linalg with scipy.sparse.linalg is ~0.1 s CPU of a plan's start-up that its fixed-base
    segments do not need (a fresh process); what ``scipy.sparse`` itself imports (older releases:
    both) is not the plan's doing."""
    env = dict(os.environ, OPTPLAN_CACHE=str(tmp_path), OPTPLAN_BACKGROUND_COMPILE="0")
    out = subprocess.run([sys.executable, "-c", _NO_LINALG], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "", f"imported: {out.stdout.strip()}"


_NO_OPT_STACK = """
import sys
import optplan.cli, optplan.cli_plan, optplan.pipeline, optplan.shortcuts, optplan.trials, optplan.verification
import optplan.planners.tcbirrt
print(" ".join(m for m in ("scipy.sparse", "optplan.problem", "optplan.tasks", "optplan.segment_nlp")
               if m in sys.modules))
"""


def test_the_plan_commands_planning_modules_do_not_import_the_optimization_stack():
    """``optplan plan`` plans and shortcuts while its segment worker imports the optimization stack
    (optplan.problem, the NLP modules, IPOPT): the modules it needs up to then must not import it."""
    out = subprocess.run([sys.executable, "-c", _NO_OPT_STACK], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "", f"imported: {out.stdout.strip()}"
