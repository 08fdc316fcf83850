"""A body's own variation, on the human side of the model gap (:mod:`sit2stand.gap.human`).

The skeletal model's segment masses are de Leva's table: a population's mean proportions scaled to the subject's
stature and scale mass. A person's own segments differ from it (``SEGMENT_MASS_SD`` of each segment's mass), and that
difference loads the plates as a hidden mass would: fitted freely, it was named as a 2-6 kg load on the trunk or the
head of bodies that carried nothing (half the bodies of the human-side benchmark).

So before a load is looked for, the body's own variation explains what it can: each segment's mass (1 + delta_s)
times the table's, at the segment's centre of mass and within the scale mass, delta_s ~ N(0, sd^2), fitted as the
maximum a posteriori estimate (a ridge; the data counted at their effective share of rows, from the autocorrelation
of what no candidate fits: smoothed signals counted sample by sample would leave the prior no say). Where every
departure stays within ``VARIATION_Z`` standard deviations, the body's own proportions are a sufficient explanation
and no load is named (a wrong declared body mass still is: no departure within the scale mass changes the weight;
it is fitted beside them); otherwise the loads are looked for as before. An 8 kg load on a 75 kg body's trunk is then
not named (the plates see it as a trunk 19 % and a head 10 % heavier than the table's, within their spread), which is
the honest answer: the plates cannot tell it from a heavier upper body. A 15 kg one is named.
"""

from __future__ import annotations

import numpy as np

VARIATION_Z = 3.0
"""A body's own segment departures up to this many standard deviations explain the plates without a load: the
largest of 17 independent normal departures exceeds 3 in 4.5 % of bodies (2.5: in 19 %)."""


def map_departures(y: np.ndarray, Xv: np.ndarray, sd: np.ndarray, frac: float, X_free: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The maximum a posteriori departures delta (S,) of the columns ``Xv`` (rows weighted to unit noise, one per
    segment) under the prior N(0, ``sd``^2), the data counted at ``frac`` of their rows, fitted jointly with free
    columns ``X_free`` (no prior); and the residual."""
    k = 0 if X_free is None else X_free.shape[1]
    X = Xv if X_free is None else np.hstack([X_free, Xv])
    penalty = np.concatenate([np.zeros(k), 1.0 / np.asarray(sd, float) ** 2])
    theta = np.linalg.solve(frac * (X.T @ X) + np.diag(penalty), frac * (X.T @ y))
    return theta[k:], y - X @ theta


def within_spread(delta: np.ndarray, sd: np.ndarray, z: float = VARIATION_Z) -> bool:
    """Whether every departure is within ``z`` standard deviations."""
    return bool(np.all(np.abs(delta) <= z * np.asarray(sd, float)))


def largest_departures(delta: np.ndarray, names: list[str], top: int = 3) -> str:
    """The largest segment departures in words: ``torso +6 %, head -4 %``."""
    order = np.argsort(-np.abs(delta))[:top]
    return ", ".join(f"{names[i]} {100 * delta[i]:+.0f} %" for i in order)
