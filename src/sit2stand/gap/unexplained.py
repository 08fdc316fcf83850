""""Unexplained" as an answer: where a residual no candidate explains sits, and what kind of effect its shape suggests.

For each channel left above its noise floor (the inverse-dynamics channels after the named effects applied for real,
and the re-simulation's), the report says when (the worst instant, the span above ``SIGNIFICANT_Z`` floors, the
phases it is large in) and what it follows, without naming a parameter:

* **position-dependent**: it follows a joint's angle (a spring, a kinematic error, a mass the library cannot place);
* **velocity-dependent**: a joint's velocity or its sign (damping, friction of an unusual law);
* **acceleration-dependent**: a joint's acceleration (an inertia);
* **contact**: the re-simulation's COP or feet force disagree while the inverse dynamics agree (the soles' stiffness
  or damping, the foot's geometry);
* **one phase only**: most of its energy in phases that hold under half the samples (e.g. seat-off).

A feature class suggests the kind when its best single joint explains at least ``SHAPE_R2`` of the residual's
variance (least squares with an intercept).
"""

from __future__ import annotations

import numpy as np

from .dataset import MOVING_RADPS, Dataset
from .residuals import COULOMB_V0_RADPS

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
