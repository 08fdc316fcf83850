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

Also "unexplained" as an answer (:func:`where_and_shape`): where a residual no candidate explains sits.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..optim import effective_fraction
from .dataset import MOVING_RADPS, Dataset
from .residuals import COULOMB_V0_RADPS

MIN_SHARE = 0.02             # an effect must lower the sum of squares by this share of what noise leaves
GAIN_RANK_TOL = 1e-12        # a direction of a signature below this share of its energy (left by Q) is not counted


@dataclass
class Candidate:
    """One candidate effect: ``kind`` at ``location``, with parameters ``params`` (names with units) and its
    weighted signature ``X`` (rows x p)."""

    kind: str
    location: str
    params: list[str]
    X: np.ndarray
    members: list[str] = field(default_factory=list)
    plausible: Callable[[np.ndarray], str | None] | None = None   # why an estimate is not physical (None: it is)
    columns: list[np.ndarray] | None = None    # per recording (N, C, p) unweighted, where no library kind gives them

    @property
    def key(self) -> str:
        """``kind@location``, the candidate's name in reports."""
        return f"{self.kind}@{self.location}"


@dataclass
class Selected:
    """A chosen effect: its candidate, estimate and covariance, and how it was chosen."""

    candidate: Candidate
    theta: np.ndarray
    cov: np.ndarray                  # (p, p) covariance of theta
    gain: float                      # share of the initial residual sum of squares it explained when chosen
    delta_bic: float
    alternatives: list[str] = field(default_factory=list)


@dataclass
class Selection:
    """The outcome: chosen effects, sums of squares before and after, rows, effective rows and the step log."""

    effects: list[Selected]
    rss0: float
    rss: float
    n_rows: int
    n_eff: float
    steps: list[dict] = field(default_factory=list)


def _orth(X: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the column space of X (numerically null directions left out)."""
    if X.shape[1] == 0:
        return X
    U, s, _ = np.linalg.svd(X, full_matrices=False)
    return U[:, s > 1e-9 * max(s[0], 1e-300)]


def _gain(r: np.ndarray, Q: np.ndarray, X: np.ndarray, gram: np.ndarray | None = None) -> tuple[float, int]:
    """Drop of the residual sum of squares when X (orthogonalised against Q) is added; its rank. ``r`` is orthogonal
    to Q, so Xp^T r = X^T r and Xp^T Xp = X^T X - (Q^T X)^T (Q^T X): the p x p normal equations, without forming
    Xp (4x faster than its SVD, the same choices on the hidden-effect cases); ``gram``: X^T X, if known."""
    G = X.T @ X if gram is None else gram
    scale = float(np.trace(G))
    if Q.shape[1]:
        B = Q.T @ X
        G = G - B.T @ B
    w, V = np.linalg.eigh(G)
    keep = w > GAIN_RANK_TOL * max(scale, 1e-300)
    if not keep.any():
        return 0.0, 0
    c = V[:, keep].T @ (X.T @ r)
    return float(np.sum(c * c / w[keep])), int(keep.sum())


@dataclass
class _Search:
    """What the selection's passes share: the rows, the candidates, the indices chosen so far and the log."""

    y: np.ndarray
    candidates: list[Candidate]
    series_id: np.ndarray | None
    chosen: list[int] = field(default_factory=list)
    gains: dict[int, tuple[float, float, list[str]]] = field(default_factory=dict)   # share, dBIC, alternatives
    steps: list[dict] = field(default_factory=list)
    grams: dict[int, np.ndarray] = field(default_factory=dict)    # candidate -> X^T X, computed once


def select(y: np.ndarray, candidates: list[Candidate], series_id: np.ndarray | None = None,
           bic_threshold: float = 10.0, min_share: float = MIN_SHARE, max_effects: int = 40,
           ambiguity: float = 0.05, noise_rss: float | None = None, progress=None) -> Selection:
    """Greedy forward selection (see the module docstring); ``noise_rss`` is what pure noise would leave (the number
    of rows when y is in units of the noise floor)."""
    n = len(y)
    noise_rss = float(n if noise_rss is None else noise_rss)
    rss0 = float(y @ y)
    search = _Search(y, candidates, series_id)
    _forward(search, rss0, noise_rss, bic_threshold, min_share, max_effects, ambiguity, progress)
    _backward(search, bic_threshold)
    _drop_indistinct(search)
    effects, rss, n_eff = _estimates(search, rss0)
    return Selection(effects, rss0, rss, n, float(n_eff), search.steps)


def _forward(s: _Search, rss0: float, noise_rss: float, bic_threshold: float, min_share: float, max_effects: int,
             ambiguity: float, progress) -> None:
    """Forward pass: keep adding the plausible candidate that lowers BIC most, while it lowers it enough and matters."""
    y, candidates, n = s.y, s.candidates, len(s.y)
    Q = np.zeros((n, 0))
    r = y.copy()
    while len(s.chosen) < max_effects:
        rss = float(r @ r)
        frac = effective_fraction(r, s.series_id)
        n_eff = max(frac * n, 10.0)
        scores = _scores(s, r, Q, rss, n_eff)
        best, best_score, g_best = _first_plausible(s, scores, bic_threshold)
        if best is None:
            s.steps.append({"step": len(s.chosen) + 1, "stop": "no candidate lowers BIC by more than "
                            f"{bic_threshold:g}" + (f" (best {candidates[scores[0][2]].key}: {scores[0][0]:.1f})"
                                                    if scores else "")})
            break
        share = g_best / max(noise_rss, 1e-12)
        s.steps.append({"step": len(s.chosen) + 1, "best": candidates[best].key, "delta_bic": float(best_score),
                        "share_of_noise": float(share), "n_eff": float(n_eff)})
        if share < min_share:
            s.steps[-1]["stop"] = f"explains under {100 * min_share:g} % of the noise level"
            break
        alts = [candidates[k].key for d, g, k in sorted(scores) if k != best and g >= (1 - ambiguity) * g_best]
        s.chosen.append(best)
        s.gains[best] = (g_best / max(rss0, 1e-12), float(best_score), alts)
        Q = _orth(np.hstack([Q, candidates[best].X]))
        r = y - Q @ (Q.T @ y)
        if progress:
            progress(f"  chose {candidates[best].key} ({100 * s.gains[best][0]:.1f} % of the residual, "
                     f"dBIC {best_score:.0f})")


def _scores(s: _Search, r: np.ndarray, Q: np.ndarray, rss: float, n_eff: float) -> list[tuple[float, float, int]]:
    """(delta BIC, drop of the sum of squares, index) of every remaining candidate against ``r``, lowest BIC first."""
    scores = []
    for k, cand in enumerate(s.candidates):
        if k in s.chosen:
            continue
        if k not in s.grams:
            s.grams[k] = cand.X.T @ cand.X
        g, p = _gain(r, Q, cand.X, s.grams[k])
        if p == 0:
            continue
        dbic = n_eff * np.log(max(rss - g, 1e-300) / rss) + p * np.log(n_eff)
        scores.append((dbic, g, k))
    scores.sort()
    return scores


def _first_plausible(s: _Search, scores: list[tuple[float, float, int]],
                     bic_threshold: float) -> tuple[int | None, float, float]:
    """Of the ten best, the first that lowers BIC by more than the threshold with a plausible estimate: (index,
    delta BIC, drop of the sum of squares); (None, 0, 0) if none."""
    X_sel = [s.candidates[k].X for k in s.chosen]
    for dbic, g, k in scores[:10]:
        if dbic > -bic_threshold:
            break
        cand = s.candidates[k]
        if cand.plausible is not None:
            theta, *_ = np.linalg.lstsq(np.hstack(X_sel + [cand.X]), s.y, rcond=None)
            why = cand.plausible(theta[-cand.X.shape[1]:])
            if why is not None:
                s.steps.append({"step": len(s.chosen) + 1, "implausible": cand.key, "why": why,
                                "delta_bic": float(dbic)})
                continue
        return k, dbic, g
    return None, 0.0, 0.0


def _backward(s: _Search, bic_threshold: float) -> None:
    """Backward pass: drop, one at a time, a chosen effect that later choices made redundant (BIC)."""
    y, candidates, chosen, n = s.y, s.candidates, s.chosen, len(s.y)
    changed = True
    while changed and len(chosen) > 1:
        changed = False
        X_all = [candidates[k].X for k in chosen]
        full_rss = _rss(y, np.hstack(X_all))
        n_eff = max(effective_fraction(y - _fit(y, np.hstack(X_all)), s.series_id) * n, 10.0)
        for i, k in enumerate(chosen):
            rest = np.hstack([X for j, X in enumerate(X_all) if j != i])
            dbic = n_eff * np.log(_rss(y, rest) / full_rss) - candidates[k].X.shape[1] * np.log(n_eff)
            if dbic < bic_threshold:
                s.steps.append({"dropped": candidates[k].key, "delta_bic": float(-dbic)})
                chosen.pop(i)
                changed = True
                break


def least_squares(X: np.ndarray, y: np.ndarray, series_id: np.ndarray | None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Least squares of y on X: theta, its covariance (scaled by n / n_eff), residual, n_eff / n."""
    theta, *_ = np.linalg.lstsq(X, y, rcond=None)
    res = y - X @ theta
    frac = effective_fraction(res, series_id)
    s2 = float(res @ res) / max(len(y) - X.shape[1], 1)
    return theta, s2 * np.linalg.pinv(X.T @ X) / max(frac, 1e-3), res, frac


def _joint_fit(s: _Search) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """:func:`least_squares` of y on all chosen signatures."""
    return least_squares(np.hstack([s.candidates[k].X for k in s.chosen]), s.y, s.series_id)


def _drop_indistinct(s: _Search) -> None:
    """Drop, weakest first, each effect whose leading parameter is within 1.96 standard errors of 0 in the joint fit."""
    # (two effects trading off along a direction the data cannot see)
    chosen = s.chosen
    while chosen:
        theta, cov, _, _ = _joint_fit(s)
        starts = np.cumsum([0] + [s.candidates[k].X.shape[1] for k in chosen])[:-1]
        t = np.array([abs(theta[i]) / max(np.sqrt(max(cov[i, i], 0.0)), 1e-300) for i in starts])
        if t.min() >= 1.96:
            break
        i = int(np.argmin(t))
        s.steps.append({"dropped": s.candidates[chosen[i]].key, "t": float(t[i]), "why": "not distinguishable from 0"})
        chosen.pop(i)


def _estimates(s: _Search, rss0: float) -> tuple[list[Selected], float, float]:
    """The chosen effects with their joint estimates and covariances; the residual sum of squares and n_eff."""
    n = len(s.y)
    if not s.chosen:
        return [], rss0, effective_fraction(s.y, s.series_id) * n
    theta, cov, res, frac = _joint_fit(s)
    effects = []
    i = 0
    for k in s.chosen:
        p = s.candidates[k].X.shape[1]
        share, dbic, alts = s.gains.get(k, (0.0, 0.0, []))
        effects.append(Selected(s.candidates[k], theta[i:i + p], cov[i:i + p, i:i + p], share, dbic, alts))
        i += p
    return effects, float(res @ res), frac * n


def _fit(y: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Least-squares fit of y by the columns of X."""
    theta, *_ = np.linalg.lstsq(X, y, rcond=None)
    return X @ theta


def _rss(y: np.ndarray, X: np.ndarray) -> float:
    """Residual sum of squares of y after its least-squares fit by X."""
    r = y - _fit(y, X)
    return float(r @ r)


# --- "Unexplained" as an answer: where a residual no candidate explains sits, and what kind of effect its shape
# suggests.
#
# For each channel left above its noise floor (the inverse-dynamics channels after the named effects applied for real,
# and the re-simulation's), the report says when (the worst instant, the span above ``SIGNIFICANT_Z`` floors, the
# phases it is large in) and what it follows, without naming a parameter:
#
# * **position-dependent**: it follows a joint's angle (a spring, a kinematic error, a mass the library cannot place);
# * **velocity-dependent**: a joint's velocity or its sign (damping, friction of an unusual law);
# * **acceleration-dependent**: a joint's acceleration (an inertia);
# * **contact**: the re-simulation's COP or feet force disagree while the inverse dynamics agree (the soles' stiffness
#   or damping, the foot's geometry);
# * **one phase only**: most of its energy in phases that hold under half the samples (e.g. seat-off).
#
# A feature class suggests the kind when its best single joint explains at least ``SHAPE_R2`` of the residual's
# variance (least squares with an intercept).


SIGNIFICANT_Z = 3.0          # a channel's RMS residual this many times its floor is a disagreement
SHAPE_R2 = 0.5
PHASE_SHARE = 0.8            # this share of the energy in phases holding under half the samples: one phase only


def where_and_shape(ds: Dataset, r: int, channel: str, x: np.ndarray, ok: np.ndarray, floor: float) -> dict:
    """When the residual ``x`` (recording ``r``, valid where ``ok``) is large, and what its shape suggests."""
    rec, lab = ds.recordings[r], ds.labels[r]
    t = rec.t_s
    big = ok & (np.abs(x) > SIGNIFICANT_Z * floor)
    k = int(np.argmax(np.where(ok, np.abs(x), -np.inf)))
    out = {"worst_t_s": float(t[k]), "worst": float(x[k]),
           "above_s": [float(t[big][0]), float(t[big][-1])] if big.any() else None,
           "above_share": float(big.sum() / max(ok.sum(), 1))}
    phases = {}
    for p in dict.fromkeys(lab):
        m = ok & (lab == p)
        if m.sum() >= 3:
            phases[str(p)] = float(np.sqrt(np.mean(x[m] ** 2)) / floor)
    out["z_by_phase"] = phases
    out["shape"] = _phase_only(x, ok, lab) or _shape(ds, r, channel, x, ok)
    return out


def _phase_only(x: np.ndarray, ok: np.ndarray, lab: np.ndarray) -> str | None:
    """"only while <phases>" when most of the residual's energy sits in phases holding under half the samples."""
    energy = {p: float(np.sum(x[ok & (lab == p)] ** 2)) for p in dict.fromkeys(lab[ok])}
    total = sum(energy.values())
    if total <= 0 or len(energy) < 2:
        return None
    top = sorted(energy, key=energy.get, reverse=True)
    for n in range(1, len(top)):
        share = sum(energy[p] for p in top[:n]) / total
        held = np.isin(lab[ok], top[:n]).mean()
        if share >= PHASE_SHARE and held < 0.5:
            return f"one phase only: {100 * share:.0f} % of it while {', '.join(top[:n])}"
    return None


def _shape(ds: Dataset, r: int, channel: str, x: np.ndarray, ok: np.ndarray) -> str:
    """The feature class (position, velocity, acceleration of one joint) that best explains ``x``, if any does."""
    rec = ds.recordings[r]
    own = channel.split("/")[-1]
    joints = [rec.joint_names.index(own)] if own in rec.joint_names else \
        [j for j in range(len(rec.joint_names)) if np.sqrt(np.mean(rec.qd[:, j] ** 2)) > MOVING_RADPS]
    best = ("", "", 0.0)
    for j in joints:
        feats = {"position-dependent": [rec.q[:, j]],
                 "velocity-dependent": [rec.qd[:, j], np.clip(rec.qd[:, j] / COULOMB_V0_RADPS, -1, 1)],
                 "acceleration-dependent": [rec.qdd[:, j]]}
        for kind, cols in feats.items():
            r2 = _r2(x[ok], np.column_stack(cols)[ok])
            if r2 > best[2]:
                best = (kind, rec.joint_names[j], r2)
    if best[2] >= SHAPE_R2:
        return f"{best[0]} (follows {best[1]}, R^2 {best[2]:.2f})"
    return f"no simple shape (best: {best[0] or 'none'} of {best[1] or '-'}, R^2 {best[2]:.2f})"


def _r2(y: np.ndarray, X: np.ndarray) -> float:
    """Share of the variance of y explained by X with an intercept."""
    if len(y) < 5 or np.var(y) <= 0:
        return 0.0
    A = np.column_stack([X, np.ones(len(y))])
    theta, *_ = np.linalg.lstsq(A, y, rcond=None)
    res = y - A @ theta
    return float(1.0 - np.var(res) / np.var(y))


def contact_note(id_quiet: bool, channel: str) -> str | None:
    """The shape of a re-simulation COP / feet-force disagreement when the inverse dynamics agree: contact."""
    if id_quiet and channel in ("replay/cop_x", "replay/feet_fz"):
        return ("contact: the re-simulation disagrees while the inverse dynamics agree (the soles' stiffness or "
                "damping, the foot's geometry)")
    return None
