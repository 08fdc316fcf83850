"""Constrained linear least squares, solved as a dense QP with proxsuite.

    minimise  || W (A x - b) ||^2 + || R (x - x_prior) ||^2
    subject to  E x = e,   lb <= x <= ub

Used for the human's segment-mass scaling and the robot's inertial identification. :func:`effective_fraction`
counts the independent rows of a smooth, sampled residual. Also reports the condition
number of the scaled, weighted problem, so that callers can refuse an ill-conditioned one with the number in hand.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import proxsuite   # at import (~0.1 s), not inside a live node's first solve
from scipy.linalg import lapack
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


class ActiveSetQp:
    """A small dense QP solved exactly by a primal-dual active set on its bounds and inequality rows:

        minimise  1/2 x' H x + g' x   subject to  A x = b,  C x >= d,  lo <= x <= hi      (H positive definite)

    Each pass fixes the working set's variables at their bounds, makes its rows equalities and solves the reduced
    KKT system; the next working set takes the free variables and rows that the answer violates and keeps the fixed
    ones whose multipliers have the right sign. It starts from the last call's working set: between the
    Gauss-Newton steps of one frame and the frames of a motion, the joints on their limits change little, and one
    or two KKT solves (tens of microseconds) replace an interior-point or proximal solve.

    :meth:`solve` returns x only where the KKT conditions hold to ``tol`` (then x is the optimum, to rounding);
    None where it cannot tell (a singular KKT system, e.g. equalities that the fixed variables make dependent or
    infeasible, or no settled working set within ``max_passes``): the caller's general solver decides. A working set
    that fails is dropped: the pass starts again from an empty one.
    """

    def __init__(self, max_passes: int = 8, tol: float = 1e-9) -> None:
        self.max_passes = max_passes
        self.tol = tol
        self._at_lo = self._at_hi = np.zeros(0, bool)
        self._rows = np.zeros(0, bool)

    def solve(self, H: np.ndarray, g: np.ndarray, A: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              C: np.ndarray | None = None, d: np.ndarray | None = None) -> np.ndarray | None:
        n = len(g)
        C = np.zeros((0, n)) if C is None else C
        d = np.zeros(0) if d is None else d
        if len(self._at_lo) != n or len(self._rows) != len(C):
            self._at_lo, self._at_hi, self._rows = np.zeros(n, bool), np.zeros(n, bool), np.zeros(len(C), bool)
        x = self._passes(H, g, A, b, lo, hi, C, d, self._at_lo & (lo > -1e19), self._at_hi & (hi < 1e19),
                         self._rows)
        if x is None and (self._at_lo.any() or self._at_hi.any() or self._rows.any()):
            # the last working set does not fit this problem: from an empty one (kept for the next call if it fails)
            self._at_lo, self._at_hi, self._rows = np.zeros(n, bool), np.zeros(n, bool), np.zeros(len(C), bool)
            x = self._passes(H, g, A, b, lo, hi, C, d, self._at_lo, self._at_hi, self._rows)
        return x

    def _passes(self, H, g, A, b, lo, hi, C, d, at_lo, at_hi, rows) -> np.ndarray | None:
        """Working-set passes from (at_lo, at_hi, rows); x, and the settled set kept for the next call."""
        t = self.tol
        for _ in range(self.max_passes):
            solved = self._kkt(H, g, A, b, lo, hi, C, d, at_lo, at_hi, rows)
            if solved is None:
                return None
            x, r, sigma = solved
            # a fixed variable sits on its bound exactly, and a free one has r = 0: one test covers both kinds
            add_lo, add_hi = x < lo - t, x > hi + t
            drop_lo, drop_hi = at_lo & (r < -t), at_hi & (r > t)
            add_rows, drop_rows = (C @ x < d - t) & ~rows, rows & (sigma < -t)
            if not (add_lo.any() or add_hi.any() or drop_lo.any() or drop_hi.any() or add_rows.any()
                    or drop_rows.any()):
                self._at_lo, self._at_hi, self._rows = at_lo, at_hi, rows
                return x
            at_lo, at_hi = (at_lo & ~drop_lo) | add_lo, (at_hi & ~drop_hi) | add_hi
            rows = (rows & ~drop_rows) | add_rows
        return None

    @staticmethod
    def _kkt(H, g, A, b, lo, hi, C, d, at_lo, at_hi, rows):
        """x with the working set held, the bound multipliers r (the Lagrangian's gradient on the fixed variables)
        and the rows' multipliers sigma (>= 0 at the optimum on the active rows, 0 on the others); None when the
        KKT system is singular."""
        fixed = at_lo | at_hi
        free = np.flatnonzero(~fixed)
        x = np.where(at_lo, lo, np.where(at_hi, hi, 0.0))
        E, e = (np.vstack([A, C[rows]]), np.concatenate([b, d[rows]])) if rows.any() else (A, b)
        Ef = E.take(free, 1)
        nf, m = len(free), len(E)
        K = np.zeros((nf + m, nf + m))
        K[:nf, :nf] = H.take(free, 0).take(free, 1)
        K[:nf, nf:] = Ef.T
        K[nf:, :nf] = Ef
        rhs = np.empty(nf + m)
        rhs[:nf] = -(g.take(free) + H.take(free, 0) @ x)      # x is 0 on the free variables
        rhs[nf:] = e - E @ x
        sol, info = lapack.dgesv(K, rhs)[2:]           # LAPACK directly: numpy's wrapper costs as much again
        if info != 0 or not np.isfinite(sol).all() or np.abs(K @ sol - rhs).max() > 1e-8 * (1.0 + np.abs(rhs).max()):
            return None
        x[free] = sol[:nf]
        nu = sol[nf:]
        r = H @ x + g + E.T @ nu
        sigma = np.zeros(len(C))
        sigma[rows] = -nu[len(A):]
        return x, r, sigma
