"""Phases of a recorded sit-to-stand trial, from the kinematics (and the chair plate where there is one).

A lab trial may start seated, mid-rise or at seat-off, and may end standing or seated again. The phases follow the
sit-to-stand literature (Schenkman et al., Phys. Ther. 1990): seated, flexion (the trunk leans, the COM moves
forward, the hips still on the seat), seat-off, extension (the hips rise), standing, sitting down, seated. They are
read off the pelvis markers' height (its lowest and highest tenth of the trial are "seated" and "standing"), the COM's
forward speed (flexion starts when it first exceeds :data:`FLEXION_SPEED_MPS`) and, where there is one, the chair plate
(seat-off when it unloads). Units SI; times [s] of the recording.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..human.cycles import first, pelvis_bands

MIN_RISE_STATURES = 0.1
"""A pelvis rise below this share of the stature is no sit-to-stand."""
FLEXION_SPEED_MPS = 0.05
"""Forward COM speed [m/s] above which a seated human has begun to lean forward."""
SEAT_OFF_RISE_M = 0.02
"""Without a chair plate, seat-off is when the pelvis has risen this much above its seated height."""
CHAIR_UNLOADED_N = 30.0


@dataclass
class Phases:
    """A trial's phase per frame and the times of its events [s] (None: not in the recording)."""

    labels: np.ndarray                      # (N,) str: seated, flexion, extension, standing, sitting_down
    rise_start_s: float | None
    seat_off_s: float | None
    standing_s: float | None
    sit_down_s: float | None

    @property
    def starts_seated(self) -> bool:
        return self.labels[0] == "seated"

    @property
    def ends_seated(self) -> bool:
        return self.sit_down_s is not None

    def rise_and_stand(self, t_s: np.ndarray) -> np.ndarray:
        """(N,) frames to play by default: everything before the human starts to sit back down."""
        return np.asarray(t_s) < (self.sit_down_s if self.sit_down_s is not None else np.inf)


def find_phases(t_s: np.ndarray, pelvis_z_m: np.ndarray, com_x_m: np.ndarray, stature_m: float,
                chair_force_n: np.ndarray | None = None) -> Phases:
    """The phases of one trial (see the module docstring).

    Args:
        t_s: (N,) frame times [s]; ``pelvis_z_m`` (N,) the pelvis markers' mean height (NaN where unseen);
            ``com_x_m`` (N,) the human COM's forward position; ``chair_force_n`` (N,) the chair plate's vertical
            force at the frames, or None without a chair plate.

    Raises:
        InputError: the pelvis does not rise by :data:`MIN_RISE_STATURES` of the stature: no sit-to-stand.
    """
    t = np.asarray(t_s, float)
    z, lo, hi, low, standing = pelvis_bands(t, pelvis_z_m)
    if hi - lo < MIN_RISE_STATURES * stature_m:
        raise InputError(f"the pelvis rises {100 * (hi - lo):.1f} cm in this recording, less than "
                         f"{100 * MIN_RISE_STATURES:.0f} % of the stature: not a sit-to-stand")
    k_stand = first(standing)
    k_seated_last = first(low[:k_stand][::-1])        # the last low frame before standing, counted backwards
    k_seated_last = None if k_seated_last is None else k_stand - 1 - k_seated_last
    k_sit = first(~standing, k_stand)
    k_sit = k_sit if k_sit is not None and low[k_sit:].any() else None
    k_off = _seat_off(z, lo, k_stand, chair_force_n)
    vx = np.gradient(np.asarray(com_x_m, float), t)
    k_flex = None
    if k_seated_last is not None:          # the COM's first forward movement before seat-off (or standing)
        k_flex = first(vx[:(k_off if k_off is not None else k_stand)] > FLEXION_SPEED_MPS)
    labels = np.full(len(t), "extension", dtype=object)
    labels[:k_flex if k_flex is not None else 0] = "seated"
    if k_flex is not None:
        labels[k_flex:k_off if k_off is not None else k_stand] = "flexion"
    labels[k_stand:] = "standing"
    if k_sit is not None:
        labels[k_sit:] = "sitting_down"
        labels[k_sit + int(np.argmax(low[k_sit:])):] = "seated"
    def at(k: int | None) -> float | None:
        return None if k is None else float(t[k])

    return Phases(labels, at(k_flex), at(k_off), at(k_stand), at(k_sit))


def _seat_off(z: np.ndarray, z_seated: float, k_stand: int, chair_force_n: np.ndarray | None) -> int | None:
    """Seat-off frame before ``k_stand``: the chair plate unloading after it was loaded, else the pelvis rising
    :data:`SEAT_OFF_RISE_M`; None if the recording starts after it."""
    if chair_force_n is not None and np.any(chair_force_n[:k_stand] > 2 * CHAIR_UNLOADED_N):
        loaded = first(chair_force_n > 2 * CHAIR_UNLOADED_N)
        return first(chair_force_n < CHAIR_UNLOADED_N, loaded)
    risen = z[:k_stand + 1] > z_seated + SEAT_OFF_RISE_M
    k = first(risen)
    return None if k in (None, 0) else k
