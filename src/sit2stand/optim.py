"""Constrained linear least squares, solved as a dense QP with proxsuite.

    minimise  || W (A x - b) ||^2 + || R (x - x_prior) ||^2
    subject to  E x = e,   lb <= x <= ub

Used for the human's segment-mass scaling and the robot's inertial identification. :func:`effective_fraction`
counts the independent rows of a smooth, sampled residual. Also reports the condition
number of the scaled, weighted problem, so that callers can refuse an ill-conditioned one with the number in hand.

:class:`WarmQp`: a small dense QP warm-started from call to call (the retargeter's IK steps).
"""

from __future__ import annotations

from dataclasses import dataclass

import daqp
import numpy as np
import proxsuite   # at import (~0.1 s), not inside a live node's first solve
from . import native
from .errors import InputError


@dataclass
class LsqResult:
    x: np.ndarray
    cost: float
    condition_number: float
    active_bounds: int
    status: str


def constrained_lsq(A: np.ndarray, b: np.ndarray, *, weights: np.ndarray | None = None,
                    E: np.ndarray | None = None, e: np.ndarray | None = None,
                    lb: np.ndarray | None = None, ub: np.ndarray | None = None,
                    prior: np.ndarray | None = None, prior_weights: np.ndarray | None = None,
                    eps_abs: float = 1e-10) -> LsqResult:
    """Solve the problem in the module docstring. Shapes: A (m, n), b (m,), E (p, n), weights (m,), prior (n,).

    Raises:
        ValueError: inconsistent shapes, or the QP solver fails (the status is named).
    """
    A = np.atleast_2d(np.asarray(A, float))
    b = np.asarray(b, float).ravel()
    m, n = A.shape
    if b.shape != (m,):
        raise InputError(f"b has shape {b.shape}, expected ({m},)")
    w = np.ones(m) if weights is None else np.asarray(weights, float)
    Aw, bw = A * w[:, None], b * w
    H = Aw.T @ Aw
    g = -Aw.T @ bw
    if prior is not None:
        r = np.ones(n) if prior_weights is None else np.asarray(prior_weights, float)
        H += np.diag(r**2)
        g -= r**2 * np.asarray(prior, float)
    # scale columns so that the QP is well posed numerically
    scale = np.sqrt(np.maximum(np.diag(H), 1e-300))
    Hs = H / scale[:, None] / scale[None, :]
    gs = g / scale
    cond = float(np.linalg.cond(Hs)) ** 0.5   # condition number of the scaled regressor (sqrt of the normal matrix's)
    if E is None and lb is None and ub is None:
        # nothing to constrain: the normal equations directly (a QP solver can call a nearly singular, regularised
        # problem dual infeasible)
        x = np.linalg.lstsq(Hs, -gs, rcond=None)[0] / scale
        resid = Aw @ x - bw
        return LsqResult(x, float(resid @ resid), cond, 0, "SOLVED (normal equations)")
    n_eq = 0 if E is None else np.atleast_2d(E).shape[0]
    Es = None if E is None else np.atleast_2d(np.asarray(E, float)) / scale[None, :]
    n_in = n if (lb is not None or ub is not None) else 0
    qp = proxsuite.proxqp.dense.QP(n, n_eq, n_in)
    qp.settings.eps_abs = eps_abs
    qp.settings.max_iter = 10_000
    qp.settings.verbose = False
    C = np.eye(n) if n_in else None
    lo = None if not n_in else (np.full(n, -1e20) if lb is None else np.asarray(lb, float) * scale)
    hi = None if not n_in else (np.full(n, 1e20) if ub is None else np.asarray(ub, float) * scale)
    qp.init(Hs, gs, Es, None if e is None else np.asarray(e, float), C, lo, hi)
    qp.solve()
    status = str(qp.results.info.status).split(".")[-1]
    if "SOLVED" not in status or "INACCURATE" in status:
        raise InputError(f"constrained least squares: QP solver status {status}")
    x = qp.results.x / scale
    resid = Aw @ x - bw
    active = 0
    if n_in:
        tol = 1e-7 * (1 + np.abs(x))
        active = int(np.sum((lb is not None) & (np.abs(x - (lb if lb is not None else x)) < tol)) +
                     np.sum((ub is not None) & (np.abs(x - (ub if ub is not None else x)) < tol)))
    return LsqResult(x, float(resid @ resid), cond, active, status)


def effective_fraction(r: np.ndarray, series_id: np.ndarray | None) -> float:
    """(1 - rho) / (1 + rho) from the lag-1 autocorrelation rho of ``r`` within each series (``series_id`` groups
    the rows of one channel of one recording, in time order); 1 when rows are independent (None)."""
    if series_id is None:
        return 1.0
    same = series_id[1:] == series_id[:-1]
    a, b = r[:-1][same], r[1:][same]
    if len(a) < 10 or np.dot(a, a) <= 0:
        return 1.0
    rho = float(np.clip(np.dot(a, b) / np.sqrt(np.dot(a, a) * np.dot(b, b)), 0.0, 0.98))
    return (1 - rho) / (1 + rho)


class QpProblem:
    """One QP shape's arrays, allocated once (:meth:`WarmQp.problem`) and filled in place by the caller, step after
    step: H (n, n), g (n,), A (me, n), b (me,), C (mi, n), d (mi,), lo, hi (n,). ``kernel`` holds the compiled
    solver's state for the shape (:class:`sit2stand.native.ActiveSetQp`)."""

    def __init__(self, n: int, me: int, mi: int) -> None:
        self.shape = (n, me, mi)
        self.H, self.g, self.A, self.b = np.zeros((n, n)), np.zeros(n), np.zeros((me, n)), np.zeros(me)
        self.C, self.d, self.lo, self.hi = np.zeros((mi, n)), np.zeros(mi), np.zeros(n), np.zeros(n)
        self.kernel = None

    def rows(self) -> np.ndarray:
        """[A; C]."""
        return np.vstack((self.A, self.C)) if len(self.C) else self.A


class WarmQp:
    """A small dense QP, warm-started from one call to the next:

        minimise  1/2 x' H x + g' x   subject to  A x = b,  C x >= d,  lo <= x <= hi      (H positive definite)

    First by the compiled primal-dual active set (:class:`sit2stand.native.ActiveSetQp`) from the last problem's
    working set: between the Gauss-Newton steps of one frame and the frames of a motion the bounds that hold change
    little, and 999 of 1000 of a retargeting run's QPs are solved there in one iteration. Where it gives up, or
    without a C compiler, DAQP (a dual active-set solver: Arnstrom, Bemporad, Axehill, IEEE TAC 2022; the bounds
    first, then the rows, equalities as rows with equal bounds), one workspace per problem shape, set up once and
    updated with each problem, started from its last active set; a warm start that fails is solved again from the
    equalities alone. A problem with no solution (equalities the bounds cannot meet) gets None.

    A caller that solves one shape again and again fills its :meth:`problem` in place and calls
    :meth:`solve_problem` (nothing copied); :meth:`solve` takes arrays.
    """

    def __init__(self) -> None:
        self._problems: dict[tuple[int, int, int], QpProblem] = {}
        self._models: dict[tuple[int, int, int], daqp.Model] = {}     # one DAQP workspace per shape
        self._sense: dict[tuple[int, int, int], np.ndarray] = {}
        self._last: tuple | None = None     # the last solved problem, its x and multipliers
        self.daqp_solves = 0                # the problems the compiled active set gave up on (or all: no compiler)
        lib = native.kernels()
        self._native = None if lib is None else native.ActiveSetQp(lib)

    def problem(self, n: int, me: int, mi: int) -> QpProblem:
        """The arrays of the shape (n unknowns, me equalities, mi inequality rows), to fill in place."""
        p = self._problems.get((n, me, mi))
        if p is None:
            p = self._problems[n, me, mi] = QpProblem(n, me, mi)
        return p

    def solve(self, H: np.ndarray, g: np.ndarray, A: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              C: np.ndarray | None = None, d: np.ndarray | None = None) -> np.ndarray | None:
        """x, or None if the problem has no solution."""
        p = self.problem(len(g), len(b), 0 if C is None else len(d))
        p.H[:], p.g[:], p.A[:], p.b[:], p.lo[:], p.hi[:] = H, g, A, b, lo, hi
        if C is not None:
            p.C[:], p.d[:] = C, d
        return self.solve_problem(p)

    def solve_problem(self, p: QpProblem) -> np.ndarray | None:
        """x (its own array), or None if the problem has no solution. The multipliers are kept for
        :meth:`dual_residual`, which reads the problem's arrays: ask it before filling them again."""
        if self._native is not None:
            solved = self._native.solve_problem(p)
            if solved is not None:
                self._last = (p, *solved)
                return solved[0]
        self.daqp_solves += 1
        return self._daqp(p)

    def _daqp(self, p: QpProblem) -> np.ndarray | None:
        H, g, b, C, d, lo, hi = p.H, p.g, p.b, p.C, p.d, p.lo, p.hi
        key = p.shape
        n = key[0]
        rows = p.rows()
        if not len(C):
            upper, lower = np.concatenate((hi, b)), np.concatenate((lo, b))
        else:
            upper, lower = np.concatenate((hi, b, np.full(len(d), 1e30))), np.concatenate((lo, b, d))
        model = self._models.get(key)
        if model is None:
            sense = self._sense[key] = np.zeros(sum(key), np.int32)
            sense[n:n + key[1]] = 5        # DAQP: an equality (active, immutable)
            model = daqp.Model()
            if model.setup(H, g, rows, upper, lower, sense)[0] < 0:
                self._last = None
                return None
            self._models[key] = model
            x, _, flag, info = model.solve()
        else:       # DAQP's update reads past an empty row block: none given then
            model.update(H=H, f=g, A=rows if len(rows) else None, bupper=upper, blower=lower)
            x, _, flag, info = model.solve()
            # from the equalities alone; also where the last active set held a bound that is infinite now (a
            # joint on its stop), from which DAQP's warm start answers NaN
            if flag != 1 or not np.isfinite(x).all():
                model.update(sense=self._sense[key])
                x, _, flag, info = model.solve()
        if flag != 1 or not np.isfinite(x).all():
            model.update(sense=self._sense[key])           # the next problem starts clean
            self._last = None
            return None
        self._last = (p, x, info["lam"])
        if self._native is not None:
            self._native.remember(p, info["lam"])
        return x

    def dual_residual(self) -> float:
        """The last solve's stationarity residual max |H x + g + multipliers' forces| (inf if it found none)."""
        if self._last is None:
            return float("inf")
        p, x, lam = self._last
        n = len(x)
        return float(np.abs(p.H @ x + p.g + lam[:n] + p.rows().T @ lam[n:]).max())
