"""The soles' contact stiffness, from the re-simulation: the one effect the inverse dynamics cannot see.

The inverse-dynamics residuals use the measured contact forces, so a softer or stiffer sole leaves them at their
noise floor; it shows only when the recorded commands are replayed (the COP and the feet's force move differently).
When the replay with the named effects still disagrees on those channels while the inverse dynamics agree (the
workflow's check), the soles' contact time constant (MuJoCo's
``solref``; the plant's default 0.02 s) is searched by golden section on its logarithm over
``TIME_CONSTANT_RANGE_S``, each trial a replay. It is named when it brings the COP and feet force below
``SIGNIFICANT_Z`` floors and at least halves the replay's gap on them; otherwise the disagreement stays unexplained.
"""

from __future__ import annotations

import numpy as np

from .dataset import Dataset
from .unexplained import SIGNIFICANT_Z
from .validate import replay_effects, replay_gap, replay_residuals, replay_z

CONTACT_CHANNELS = ("replay/cop_x", "replay/feet_fz")
TIME_CONSTANT_RANGE_S = (0.01, 0.15)
SEARCH_TRIALS = 8            # replays of ~3 s each; the bracket ends 3 % wide in log time constant
GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


def contact_effect(time_constant_s: float, half_width_s: float = 0.0) -> dict:
    """The soles' contact time constant as a named effect."""
    return {"kind": "contact_softness", "location": "soles", "value": float(time_constant_s),
            "ci95": float(half_width_s), "unit": "s", "share_of_gap": 0.0, "delta_bic": 0.0, "alternatives": []}


def fit_contact(ds: Dataset, effects: list[dict], sims: dict[int, dict], say) -> tuple[dict | None, dict]:
    """(the contact effect, its replay) when the replay with ``effects`` disagrees on the contact channels and a
    time constant fixes it; (None, ``sims``) otherwise."""
    z = replay_z(replay_residuals(ds, sims))
    keys = [k for k in z if k[1] in CONTACT_CHANNELS]
    if not any(z[k] >= SIGNIFICANT_Z for k in keys):
        return None, sims
    say("  the replay's COP / feet force disagree: searching the soles' contact time constant")
    cache: dict[float, tuple[float, dict]] = {}

    def trial(log_tc: float) -> float:
        if log_tc not in cache:
            sim = replay_effects(ds, effects + [contact_effect(float(np.exp(log_tc)))])
            cache[log_tc] = (replay_gap(replay_z(replay_residuals(ds, sim)), keys), sim)
        return cache[log_tc][0]

    lo, hi = np.log(TIME_CONSTANT_RANGE_S[0]), np.log(TIME_CONSTANT_RANGE_S[1])
    a, b = hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo)
    for _ in range(SEARCH_TRIALS - 2):
        if trial(a) <= trial(b):
            hi, b, a = b, a, b - GOLDEN * (b - lo)
        else:
            lo, a, b = a, b, a + GOLDEN * (hi - a)
    best = min(cache, key=lambda k: cache[k][0])
    score, sim = cache[best]
    zb = replay_z(replay_residuals(ds, sim))
    if max(zb[k] for k in keys) >= SIGNIFICANT_Z or score > 0.5 * replay_gap(z, keys):
        return None, sims
    half = 0.5 * (np.exp(hi) - np.exp(lo))
    return contact_effect(float(np.exp(best)), float(half)), sim
