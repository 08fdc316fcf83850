"""Which frames have the subject's whole weight on the force plates, and the plates' summed wrench at marker times.

Only such frames can scale the skeleton's masses: the plates must carry every external force on the body. With a
chair on a plate that is the whole trial; without one, the chair carries part of the weight until the feet first
take (nearly) all of it, so frames count only from then on. The same :class:`SupportRule` decides offline and live.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..dynamics import G
from ..forceplate import PlateSeries
from .skeleton import HumanModel

MIN_SUPPORT_WEIGHT_FRACTION = 0.3
"""Below this share of the body weight the plates cannot be carrying the whole body (a plate unloaded, a step)."""
MAX_SUPPORT_WEIGHT_FRACTION = 3.0
"""Above it the reading is an impact or a fault, not support."""
FEET_TAKE_WEIGHT_FRACTION = 0.9
"""Without a chair plate, frames count from the first time the feet plate carries this share of the weight."""


@dataclass
class SupportRule:
    """The whole-weight-on-plates rule, frame by frame (call :meth:`step` with each frame's summed vertical force).

    Args:
        body_weight_n: the subject's weight [N].
        chair_on_plate: the chair stands on a plate (then every frame may count from the start).
    """

    body_weight_n: float
    chair_on_plate: bool
    feet_carried: bool = field(init=False)

    def __post_init__(self) -> None:
        self.feet_carried = self.chair_on_plate

    def step(self, force_z_n: float) -> bool:
        """True if a frame with this summed plate force [N] (vertical, on the body) has its whole weight on plates."""
        if force_z_n >= FEET_TAKE_WEIGHT_FRACTION * self.body_weight_n:
            self.feet_carried = True
        in_range = MIN_SUPPORT_WEIGHT_FRACTION * self.body_weight_n < force_z_n < \
            MAX_SUPPORT_WEIGHT_FRACTION * self.body_weight_n
        return self.feet_carried and in_range

    def series(self, force_z_n: np.ndarray) -> np.ndarray:
        """:meth:`step` over a whole trial's forces (N,); returns (N,) bool."""
        return np.array([self.step(float(f)) for f in force_z_n], bool)


def plate_wrench_at(times_s: np.ndarray, plates: list[PlateSeries],
                    half_width_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Summed plate force (N, 3) [N] and moment about the lab origin (N, 3) [N m], each averaged over
    +-``half_width_s`` around each of ``times_s``, and a coverage flag (N,), False where any plate has no finite
    sample there (a plate that dropped out)."""
    n = len(times_s)
    force, moment = np.zeros((n, 3)), np.zeros((n, 3))
    covered = np.ones(n, bool)
    for plate in plates:
        lo = np.searchsorted(plate.t_s, times_s - half_width_s)
        hi = np.searchsorted(plate.t_s, times_s + half_width_s, side="right")
        first = int(lo.min()) if n else 0     # sums over the span the windows cover only (a stream asks for one)
        span = slice(first, int(hi.max()) if n else 0)
        lo, hi = lo - first, hi - first
        force_span = plate.force_n[span]
        csum_f = np.vstack([np.zeros(3), np.cumsum(np.nan_to_num(force_span), axis=0)])
        csum_m = np.vstack([np.zeros(3), np.cumsum(np.nan_to_num(plate.moment_origin_nm[span]), axis=0)])
        bad = np.concatenate([[0], np.cumsum(~np.all(np.isfinite(force_span), axis=1))])
        count = hi - lo
        has = (count > 0) & (bad[hi] - bad[lo] == 0)
        covered &= has
        cnt = np.maximum(count, 1)[:, None]
        force += np.where(has[:, None], (csum_f[hi] - csum_f[lo]) / cnt, 0.0)
        moment += np.where(has[:, None], (csum_m[hi] - csum_m[lo]) / cnt, 0.0)
    return force, moment, covered


def plate_gaps(times_s: np.ndarray, plates: list[PlateSeries], dt: float) -> list[tuple[str, float, float]]:
    """(plate, start [s], end [s]) of each stretch of marker frames with no finite sample of that plate."""
    gaps = []
    for plate in plates:
        _, _, covered = plate_wrench_at(times_s, [plate], dt / 2)
        missing = np.concatenate([[False], ~covered, [False]]).astype(int)
        starts = np.flatnonzero(np.diff(missing) == 1)
        ends = np.flatnonzero(np.diff(missing) == -1) - 1
        gaps += [(plate.name, float(times_s[a]), float(times_s[b])) for a, b in zip(starts, ends)]
    return gaps


def body_mass_from_plates(force_n: np.ndarray, supported: np.ndarray, qs: np.ndarray, human: HumanModel,
                          dt: float, max_com_acc: float = 0.3) -> float | None:
    """Body mass [kg] = mean vertical force / g over supported frames where the COM barely accelerates
    (|a_com| < ``max_com_acc`` m/s^2); None if there are fewer than 10 such frames."""
    model, data = human.model, human.model.createData()
    com_z = np.array([pin.centerOfMass(model, data, q)[2] for q in qs])
    acc = np.abs(np.gradient(np.gradient(com_z, dt), dt))
    quiet = supported & (acc < max_com_acc)
    if quiet.sum() < 10:
        return None
    return float(np.mean(force_n[quiet, 2]) / G)
