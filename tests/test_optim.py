"""sit2stand.optim: the exact active-set QP gives proxsuite's answers, and says when it cannot."""

import numpy as np
import proxsuite
import pytest

from sit2stand.optim import ActiveSetQp


def random_qp(rng, n=30, m=8, rows=2):
    """A strictly convex QP with equalities, inequality rows and a box tight enough that some bounds hold."""
    J = rng.normal(size=(2 * n, n))
    H = J.T @ J + 0.1 * np.eye(n)
    g = rng.normal(size=n) * 5
    A = rng.normal(size=(m, n))
    b = rng.normal(size=m) * 0.1
    C = rng.normal(size=(rows, n))
    d = rng.normal(size=rows) * 0.5
    lo, hi = -rng.uniform(0.05, 0.3, n), rng.uniform(0.05, 0.3, n)
    return H, g, A, b, lo, hi, C, d


def proxsuite_answer(H, g, A, b, lo, hi, C, d):
    qp = proxsuite.proxqp.dense.QP(len(g), len(A), len(C), True)
    qp.settings.eps_abs = 1e-11
    qp.settings.verbose = False
    qp.init(H, g, A, b, C, d, np.full(len(C), 1e20), lo, hi)
    qp.solve()
    return qp.results.x


@pytest.mark.parametrize("seed", range(20))
def test_the_active_set_answer_is_proxsuites(seed):
    rng = np.random.default_rng(seed)
    problem = random_qp(rng)
    H, g, A, b, lo, hi, C, d = problem
    x = ActiveSetQp(max_passes=30).solve(*problem)
    assert x is not None
    reference = proxsuite_answer(*problem)
    assert np.abs(x - reference).max() < 1e-6
    assert np.abs(A @ x - b).max() < 1e-9 and (C @ x >= d - 1e-9).all()
    assert (x >= lo - 1e-12).all() and (x <= hi + 1e-12).all()
    assert ((x <= lo + 1e-9) | (x >= hi - 1e-9)).any(), "the box holds somewhere: the active set had work to do"


def test_a_warm_working_set_that_no_longer_fits_is_dropped():
    """Bounds held in one problem and a next problem whose equalities those bounds would make unsatisfiable:
    the solver starts over from an empty working set and still answers exactly."""
    rng = np.random.default_rng(3)
    solver = ActiveSetQp(max_passes=30)
    first = random_qp(rng, n=12, m=2, rows=0)
    assert solver.solve(*first) is not None and solver._at_lo.any() | solver._at_hi.any()
    H, g, _, _, lo, hi, C, d = random_qp(rng, n=12, m=0, rows=0)
    held = np.flatnonzero(solver._at_lo | solver._at_hi)
    A = np.zeros((1, 12))
    A[0, held] = 1.0                      # an equality only the held variables can meet, off their bounds
    b = np.array([0.5 * (lo[held] + hi[held]).sum()])
    x = solver.solve(H, g, A, b, lo, hi, C, d)
    assert x is not None and abs(A @ x - b)[0] < 1e-9
    assert np.abs(x - proxsuite_answer(H, g, A, b, lo, hi, C, d)).max() < 1e-6


def test_an_infeasible_problem_gets_no_answer():
    """Equalities that contradict each other: a singular KKT system, no answer (the caller's general solver
    decides), never a wrong one."""
    rng = np.random.default_rng(1)
    H, g, _, _, lo, hi, C, d = random_qp(rng, n=6, m=0, rows=0)
    A = np.array([[1.0, 0, 0, 0, 0, 0], [1.0, 0, 0, 0, 0, 0]])
    assert ActiveSetQp().solve(H, g, A, np.array([0.01, 0.02]), lo, hi, C, d) is None
