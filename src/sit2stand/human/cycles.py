"""Trials of several sit-stand-sit cycles (the five-times sit-to-stand test) from one synthesised rise, and the
cycles of a recorded trial.

:func:`cycled` plays a :class:`~sit2stand.human.synth.Demonstration`'s rise, then its mirror image in time (the
sit-down), ``cycles`` times. Mirrored in time, a motion keeps its positions and accelerations and flips its
velocities, so the plates' wrenches (gravity, acceleration and the velocity-squared terms) stay those of inverse
dynamics; only the COM velocity changes sign. Between two cycles the human sits ``seated_s``: a brief touch
(~0.1 s, as many people do in the timed test) or a full sit (1-1.6 s).

:func:`find_cycles` reads the rises and sit-downs of any trial off the pelvis height, as
:mod:`sit2stand.retarget.phases` does for one.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..forceplate import PlateSeries
from .synth import Demonstration

MAX_CYCLES = 10


def cycled(demo: Demonstration, cycles: int, seated_s: float = 1.0) -> Demonstration:
    """``demo``'s rise and sit-down ``cycles`` times, ``seated_s`` [s] on the seat between them; it starts and ends
    seated as ``demo`` starts. Times restart at 0; the events (seat-off, rise start and end) are the first cycle's.

    Raises:
        InputError: ``cycles`` outside 1-10, or ``seated_s`` outside what the rise's seated lead-in can give.
    """
    cfg = demo.config
    r = int(round(cfg.plate_rate_hz / cfg.marker_rate_hz))
    lead = int(demo.rise_start_s * cfg.plate_rate_hz) // r * r           # seated samples before the rise
    half = int(round(seated_s * cfg.plate_rate_hz / 2 / r)) * r
    if not 1 <= cycles <= MAX_CYCLES:
        raise InputError(f"cycles must be 1-{MAX_CYCLES}, not {cycles}")
    if not r <= half <= lead:
        raise InputError(f"seated time between cycles {seated_s:g} s is outside {2 * r / cfg.plate_rate_hz:g}-"
                         f"{2 * lead / cfg.plate_rate_hz:g} s (twice the rise's {cfg.sit_before_s:g} s seated lead-in)")
    top = (len(demo.t_s) - 1) // r * r
    segments, start = [], 0
    for c in range(cycles):
        low = 0 if c == cycles - 1 else lead - half
        segments += [(start, top), (top, low)]
        start = low
    plate, sign = _indices(segments)
    marker, _ = _indices([(a // r, b // r) for a, b in segments])
    t = np.arange(len(plate)) / cfg.plate_rate_hz
    return dataclasses.replace(
        demo, t_s=t, q=demo.q[plate], com_m=demo.com_m[plate], com_vel=demo.com_vel[plate] * sign[:, None],
        com_acc=demo.com_acc[plate], marker_t_s=np.arange(len(marker)) / cfg.marker_rate_hz,
        markers_m=demo.markers_m[marker], marker_valid=demo.marker_valid[marker],
        plates=[_plate(p, plate, t) for p in demo.plates])


def _indices(segments: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """The sample indices of ``segments`` (start included, end excluded, each up or down) and the final sample,
    with +1 where a segment plays forward and -1 where it plays back."""
    parts, signs = [], []
    for a, b in segments:
        run = np.arange(a, b, 1 if b > a else -1)
        parts.append(run)
        signs.append(np.full(len(run), 1.0 if b > a else -1.0))
    parts.append(np.array([segments[-1][1]]))
    signs.append(np.array([-1.0]))
    return np.concatenate(parts), np.concatenate(signs)


def _plate(p: PlateSeries, idx: np.ndarray, t: np.ndarray) -> PlateSeries:
    """A plate's samples at ``idx``, on the times ``t``."""
    def pick(a):
        return None if a is None else a[idx]
    return dataclasses.replace(p, t_s=t, force_n=p.force_n[idx], moment_origin_nm=p.moment_origin_nm[idx],
                               cop_m=pick(p.cop_m), cop_valid=pick(p.cop_valid), free_moment_nm=pick(p.free_moment_nm))


SEATED_FRACTION = 0.1
"""The pelvis within this share of its range above its lowest: seated (or about to be)."""
STANDING_FRACTION = 0.9
"""... above this share: standing."""


def pelvis_bands(t_s: np.ndarray, pelvis_z_m: np.ndarray) -> tuple[np.ndarray, float, float, np.ndarray, np.ndarray]:
    """The pelvis height [m] with its gaps (NaN) interpolated, its 5th and 95th percentiles, and the frames where it
    is seated and standing (:data:`SEATED_FRACTION`, :data:`STANDING_FRACTION`)."""
    t = np.asarray(t_s, float)
    ok = np.isfinite(pelvis_z_m)
    z = np.interp(t, t[ok], np.asarray(pelvis_z_m, float)[ok])
    lo, hi = float(np.percentile(z, 5)), float(np.percentile(z, 95))
    return z, lo, hi, z <= lo + SEATED_FRACTION * (hi - lo), z >= lo + STANDING_FRACTION * (hi - lo)


def first(mask: np.ndarray, start: int = 0) -> int | None:
    """The first index at or after ``start`` where ``mask`` holds (None: nowhere)."""
    hits = np.flatnonzero(mask[start:])
    return int(hits[0]) + start if len(hits) else None


@dataclass(frozen=True)
class Cycle:
    """One sit-stand-sit cycle of a trial [s]: the last seated instant before the rise, the first standing one, the
    first instant that is no longer standing and the first seated one after it (None: the trial ends before)."""

    rise_start_s: float
    standing_s: float
    sit_down_s: float | None
    seated_s: float | None

    @property
    def rise_s(self) -> float:
        """Seated to standing [s]."""
        return self.standing_s - self.rise_start_s

    @property
    def sit_s(self) -> float | None:
        """Standing to seated [s]."""
        return None if self.seated_s is None or self.sit_down_s is None else self.seated_s - self.sit_down_s


def find_cycles(t_s: np.ndarray, pelvis_z_m: np.ndarray) -> list[Cycle]:
    """The rises of a trial (each from seated to standing) and the sit-downs after them, from the pelvis height
    (NaN where unseen); an empty list when the pelvis never goes from seated to standing."""
    t = np.asarray(t_s, float)
    if np.isfinite(pelvis_z_m).sum() < 2:
        return []
    _, _, _, seated, standing = pelvis_bands(t, pelvis_z_m)
    out, k = [], 0
    while True:
        s0 = first(seated, k)
        up = None if s0 is None else first(standing, s0)
        if up is None:
            return out
        last_seated = up - 1 - int(np.argmax(seated[:up][::-1]))
        down = first(~standing, up)
        back = None if down is None else first(seated, down)
        out.append(Cycle(float(t[last_seated]), float(t[up]), None if down is None else float(t[down]),
                         None if back is None else float(t[back])))
        if back is None:
            return out
        k = back
