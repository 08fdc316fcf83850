"""sit2stand.optim: the warm-started QP gives proxsuite's answers, cold or warm, and says when there is none; by
the compiled active-set kernel first (:mod:`sit2stand.native`) and by DAQP alone."""

import numpy as np
import proxsuite
import pytest

from sit2stand import native
from sit2stand.optim import WarmQp

PATHS = ["kernel", "daqp"] if native.kernels() is not None else ["daqp"]


@pytest.fixture(params=PATHS)
def make_solver(request):
    def make() -> WarmQp:
        solver = WarmQp()
        if request.param == "daqp":
            solver._native = None
        return solver
    return make


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
def test_the_answer_is_proxsuites_cold_and_warm(seed, make_solver):
    """A QP, then the next one of a sequence (the same shape, its data moved a little), from the first's
    multipliers: both answers are proxsuite's, inside every constraint, with bounds holding."""
    rng = np.random.default_rng(seed)
    solver = make_solver()
    problem = random_qp(rng)
    for _ in range(2):
        H, g, A, b, lo, hi, C, d = problem
        x = solver.solve(*problem)
        assert x is not None
        assert np.abs(x - proxsuite_answer(*problem)).max() < 1e-6
        assert np.abs(A @ x - b).max() < 1e-8 and (C @ x >= d - 1e-8).all()
        assert (x >= lo - 1e-9).all() and (x <= hi + 1e-9).all()
        assert ((x <= lo + 1e-9) | (x >= hi - 1e-9)).any(), "the box holds somewhere: the active set had work to do"
        assert solver.dual_residual() < 1e-6
        problem = (H, g + rng.normal(size=len(g)) * 0.2, A, b + rng.normal(size=len(b)) * 0.01, lo, hi, C, d)


def test_a_warm_start_that_no_longer_fits_is_solved_again_cold(make_solver):
    """Bounds held in one problem and a next problem whose equality those bounds would make unsatisfiable: the
    answer is still proxsuite's."""
    rng = np.random.default_rng(3)
    solver = make_solver()
    H, g, _, _, lo, hi, C, d = random_qp(rng, n=12, m=0, rows=0)
    A0 = np.zeros((1, 12))
    x0 = solver.solve(H, g, A0, np.zeros(1), lo, hi)
    held = np.flatnonzero((x0 <= lo + 1e-9) | (x0 >= hi - 1e-9))
    assert len(held)
    A = np.zeros((1, 12))
    A[0, held] = 1.0                      # an equality only the held variables can meet, off their bounds
    b = np.array([0.5 * (lo[held] + hi[held]).sum()])
    x = solver.solve(H, g, A, b, lo, hi)
    assert x is not None and abs(A @ x - b)[0] < 1e-8
    assert np.abs(x - proxsuite_answer(H, g, A, b, lo, hi, np.zeros((0, 12)), np.zeros(0))).max() < 1e-6


def test_an_infeasible_problem_gets_no_answer(make_solver):
    """Equalities that contradict each other: no answer, never a wrong one."""
    rng = np.random.default_rng(1)
    H, g, _, _, lo, hi, C, d = random_qp(rng, n=6, m=0, rows=0)
    A = np.array([[1.0, 0, 0, 0, 0, 0], [1.0, 0, 0, 0, 0, 0]])
    solver = make_solver()
    assert solver.solve(H, g, A, np.array([0.01, 0.02]), lo, hi, C, d) is None
    assert solver.dual_residual() == float("inf")
