"""Lopsided effects where the evidence is symmetric: a one-sided effect refused when the mirrored side shows the same.

A cause that acts on both sides alike (both shanks longer than modelled) leaves the same residual on the left and the
right joints. A one-sided candidate (a mass on the left thigh, a bias of the left F/T sensor) can still win the
selection, by a little, and then explains one side and leaves the other: a confident, wrong, lopsided name. For each
one-sided effect whose mirror was not named too, the residual of the mirrored channels (the nominal one less the
other named effects': a left F/T bias loads the left hip too) is projected onto the effect's own contribution moved
to them (floor-weighted). A true one-sided effect leaves the mirrored rows alone (the
other leg's rows do not carry it): the projection is noise. When it carries at least ``SYMMETRY_SHARE`` of the
effect's size, significantly, the evidence is symmetric and the effect is refused.
"""

from __future__ import annotations

import numpy as np

from .dataset import Dataset
from .select import Selected

SYMMETRY_SHARE = 0.5         # the mirrored side shows at least half the effect's own signature: symmetric
SIGNIFICANT_PROJECTION_Z = 3.0


def mirror(name: str) -> str:
    """``name`` with left and right swapped."""
    return name.replace("left", "\0").replace("right", "left").replace("\0", "right")


def side_of(name: str) -> str | None:
    """"left", "right" or None (a name of both sides or of none)."""
    left, right = "left" in name, "right" in name
    return "left" if left and not right else "right" if right and not left else None


def lopsided(ds: Dataset, effects: list[Selected], contribution) -> list[tuple[str, str]]:
    """(candidate key, why) of each one-sided effect in ``effects`` refused for symmetric evidence;
    ``contribution(r, selected)``: its (N, C) contribution to recording r's residual (physical units)."""
    named = {(s.candidate.kind, s.candidate.location) for s in effects}
    parts = [[contribution(r, s) for s in effects] for r in range(len(ds.evaluations))]
    out = []
    for i, s in enumerate(effects):
        c = s.candidate
        side = side_of(c.location)
        if side is None or (c.kind, mirror(c.location)) in named:
            continue
        left = [ev.e - sum(p for j, p in enumerate(parts[r]) if j != i) for r, ev in enumerate(ds.evaluations)]
        num, den = _projection(ds, left, [parts[r][i] for r in range(len(left))], side)
        if den <= 0:
            continue
        beta, z = num / den, abs(num) / np.sqrt(den)
        if abs(beta) >= SYMMETRY_SHARE and z >= SIGNIFICANT_PROJECTION_Z:
            out.append((c.key, f"the mirrored side's residual shows {100 * abs(beta):.0f} % of its signature: "
                               "the evidence is symmetric"))
    return out


def _projection(ds: Dataset, residual: list[np.ndarray], own: list[np.ndarray], side: str) -> tuple[float, float]:
    """Floor-weighted <mirrored residual, moved contribution> and <contribution, contribution> over all recordings."""
    chans = ds.channels
    pairs = [(c, chans.index(mirror(ch))) for c, ch in enumerate(chans)
             if f"_{side}_" in ch and mirror(ch) in chans]
    num = den = 0.0
    for r, ev in enumerate(ds.evaluations):
        f = own[r]
        for c, cm in pairs:
            m = ev.valid[:, c] & ev.valid[:, cm]
            w = 1.0 / ds.floors[r][cm] ** 2
            num += w * float(residual[r][m, cm] @ f[m, c])
            den += w * float(f[m, c] @ f[m, c])
    return num, den
