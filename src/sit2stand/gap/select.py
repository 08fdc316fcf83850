"""Sparse selection of the physical effects that explain a model's residuals: greedy forward selection of candidate
groups with the Bayesian information criterion, then a backward check, parameter estimates and confidence intervals.

The problem is linear: residual rows y (each channel divided by its noise floor) and, per candidate effect k, a
signature X_k (the same rows, p_k columns). At each step every remaining candidate is tried against the residual
left by those already chosen (its columns orthogonalised against theirs); the one that lowers the criterion most is
kept if

* BIC falls by more than ``bic_threshold`` (10: "very strong" evidence), with the number of rows replaced by the
  **effective** number of independent samples (the residual's lag-1 autocorrelation along time: smoothed sensor
  signals are not independent sample to sample, and counting them as such would accept anything), and
* it lowers the sum of squares by at least ``min_share`` of what pure noise would leave (a practical floor: an
  effect must matter, not only be detectable), and
* its estimate is physically plausible (e.g. an extra mass within reach of its link): an implausible winner is
  skipped and the next candidate tried.

Candidates whose fit is nearly as good as the winner's (``ambiguity`` of its gain) are reported as alternatives: the
data cannot tell them apart. After the forward pass, each chosen effect is dropped in turn and the criterion checked
again (backward elimination), so that an early choice made redundant by later ones goes; and an effect whose leading
parameter is within 1.96 standard errors of zero in the joint fit (two effects trading off along a direction the
data cannot see) is dropped.

Confidence intervals are 95 % (1.96 standard errors) from the least-squares covariance scaled by the residual variance
and by n / n_eff.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Candidate:
    """One candidate effect: ``kind`` at ``location``, with parameters ``params`` (names with units) and its
    weighted signature ``X`` (rows x p)."""

    kind: str
    location: str
    params: list[str]
    X: np.ndarray
    members: list[str] = field(default_factory=list)
    plausible: Callable[[np.ndarray], bool] | None = None    # physical check of a parameter estimate

    @property
    def key(self) -> str:
        return f"{self.kind}@{self.location}"


@dataclass
class Selected:
    candidate: Candidate
    theta: np.ndarray
    cov: np.ndarray                  # (p, p) covariance of theta
    gain: float                      # share of the initial residual sum of squares it explained when chosen
    delta_bic: float
    alternatives: list[str] = field(default_factory=list)


@dataclass
class Selection:
    effects: list[Selected]
    rss0: float
    rss: float
    n_rows: int
    n_eff: float
    steps: list[dict] = field(default_factory=list)


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


def _orth(X: np.ndarray) -> np.ndarray:
    if X.shape[1] == 0:
        return X
    U, s, _ = np.linalg.svd(X, full_matrices=False)
    return U[:, s > 1e-9 * max(s[0], 1e-300)]


def _gain(r: np.ndarray, Q: np.ndarray, X: np.ndarray) -> tuple[float, int]:
    """Drop of the residual sum of squares when X (orthogonalised against Q) is added; its rank."""
    Xp = X - Q @ (Q.T @ X) if Q.shape[1] else X
    U = _orth(Xp)
    if U.shape[1] == 0:
        return 0.0, 0
    c = U.T @ r
    return float(c @ c), U.shape[1]


def select(y: np.ndarray, candidates: list[Candidate], series_id: np.ndarray | None = None,
           bic_threshold: float = 10.0, min_share: float = 0.02, max_effects: int = 40,
           ambiguity: float = 0.05, noise_rss: float | None = None, progress=None) -> Selection:
    """Greedy forward selection (see the module docstring); ``noise_rss`` is what pure noise would leave (the number
    of rows when y is in units of the noise floor)."""
    n = len(y)
    noise_rss = float(n if noise_rss is None else noise_rss)
    rss0 = float(y @ y)
    chosen: list[int] = []
    gains: dict[int, tuple[float, float, list[str]]] = {}
    Q = np.zeros((n, 0))
    r = y.copy()
    steps = []
    while len(chosen) < max_effects:
        rss = float(r @ r)
        frac = effective_fraction(r, series_id)
        n_eff = max(frac * n, 10.0)
        scores = []
        for k, cand in enumerate(candidates):
            if k in chosen:
                continue
            g, p = _gain(r, Q, cand.X)
            if p == 0:
                continue
            dbic = n_eff * np.log(max(rss - g, 1e-300) / rss) + p * np.log(n_eff)
            scores.append((dbic, g, k))
        scores.sort()
        best, best_score, g_best = None, 0.0, 0.0
        X_sel = [candidates[k].X for k in chosen]
        for dbic, g, k in scores[:10]:
            if dbic > -bic_threshold:
                break
            cand = candidates[k]
            if cand.plausible is not None:
                theta, *_ = np.linalg.lstsq(np.hstack(X_sel + [cand.X]), y, rcond=None)
                if not cand.plausible(theta[-cand.X.shape[1]:]):
                    steps.append({"step": len(chosen) + 1, "implausible": cand.key, "delta_bic": float(dbic)})
                    continue
            best, best_score, g_best = k, dbic, g
            break
        if best is None:
            steps.append({"step": len(chosen) + 1, "stop": "no candidate lowers BIC by more than "
                          f"{bic_threshold:g}" + (f" (best {candidates[scores[0][2]].key}: {scores[0][0]:.1f})"
                                                  if scores else "")})
            break
        share = g_best / max(noise_rss, 1e-12)
        steps.append({"step": len(chosen) + 1, "best": candidates[best].key, "delta_bic": float(best_score),
                      "share_of_noise": float(share), "n_eff": float(n_eff)})
        if share < min_share:
            steps[-1]["stop"] = f"explains under {100 * min_share:g} % of the noise level"
            break
        alts = [candidates[k].key for d, g, k in sorted(scores) if k != best and g >= (1 - ambiguity) * g_best]
        chosen.append(best)
        gains[best] = (g_best / max(rss0, 1e-12), float(best_score), alts)
        Q = _orth(np.hstack([Q, candidates[best].X]))
        r = y - Q @ (Q.T @ y)
        if progress:
            progress(f"  chose {candidates[best].key} ({100 * gains[best][0]:.1f} % of the residual, "
                     f"dBIC {best_score:.0f})")
    # backward: drop what later choices made redundant
    changed = True
    while changed and len(chosen) > 1:
        changed = False
        X_all = [candidates[k].X for k in chosen]
        full_rss = _rss(y, np.hstack(X_all))
        n_eff = max(effective_fraction(y - _fit(y, np.hstack(X_all)), series_id) * n, 10.0)
        for i, k in enumerate(chosen):
            rest = np.hstack([X for j, X in enumerate(X_all) if j != i])
            dbic = n_eff * np.log(_rss(y, rest) / full_rss) - candidates[k].X.shape[1] * np.log(n_eff)
            if dbic < bic_threshold:
                steps.append({"dropped": candidates[k].key, "delta_bic": float(-dbic)})
                chosen.pop(i)
                changed = True
                break
    # an effect whose leading parameter is not distinguishable from zero in the joint fit (|theta| < 1.96 standard
    # errors: two effects trading off along a direction the data cannot see) is dropped, the weakest first
    while chosen:
        X = np.hstack([candidates[k].X for k in chosen])
        theta, *_ = np.linalg.lstsq(X, y, rcond=None)
        res = y - X @ theta
        frac = effective_fraction(res, series_id)
        cov = float(res @ res) / max(n - X.shape[1], 1) * np.linalg.pinv(X.T @ X) / max(frac, 1e-3)
        starts = np.cumsum([0] + [candidates[k].X.shape[1] for k in chosen])[:-1]
        t = np.array([abs(theta[i]) / max(np.sqrt(max(cov[i, i], 0.0)), 1e-300) for i in starts])
        if t.min() >= 1.96:
            break
        i = int(np.argmin(t))
        steps.append({"dropped": candidates[chosen[i]].key, "t": float(t[i]), "why": "not distinguishable from 0"})
        chosen.pop(i)
    effects = []
    if chosen:
        X = np.hstack([candidates[k].X for k in chosen])
        theta, *_ = np.linalg.lstsq(X, y, rcond=None)
        res = y - X @ theta
        frac = effective_fraction(res, series_id)
        dof = max(n - X.shape[1], 1)
        s2 = float(res @ res) / dof
        cov = s2 * np.linalg.pinv(X.T @ X) / max(frac, 1e-3)
        i = 0
        for k in chosen:
            p = candidates[k].X.shape[1]
            share, dbic, alts = gains.get(k, (0.0, 0.0, []))
            effects.append(Selected(candidates[k], theta[i:i + p], cov[i:i + p, i:i + p], share, dbic, alts))
            i += p
        rss = float(res @ res)
        n_eff = frac * n
    else:
        rss = rss0
        n_eff = effective_fraction(y, series_id) * n
    return Selection(effects, rss0, rss, n, float(n_eff), steps)


def _fit(y: np.ndarray, X: np.ndarray) -> np.ndarray:
    theta, *_ = np.linalg.lstsq(X, y, rcond=None)
    return X @ theta


def _rss(y: np.ndarray, X: np.ndarray) -> float:
    r = y - _fit(y, X)
    return float(r @ r)
