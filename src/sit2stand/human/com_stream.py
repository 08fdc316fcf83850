"""Frame-by-frame human COM estimation: the human_com node's core, plain Python so it is tested without ROS.

Each marker frame is fitted (:class:`~sit2stand.human.marker_ik.MarkerIK`, warm-started), and its COM, velocity and
acceleration come from a causal Savitzky-Golay fit over the last window. Half a window later the same frame's
centred fit gives the model COP, the measured COP and, when the whole weight is on the plates, the rows of the
COP-matched mass scaling (:mod:`sit2stand.human.mass_scaling`), re-solved every so many rows.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from scipy.signal import savgol_coeffs   # at import time: the first frame must not pay for it

from ..dynamics import G, model_cop, savgol_frames
from ..forceplate import center_of_pressure
from ..vectors import cross
from .calibration import CALIBRATION_MIN_MARKERS, StreamCalibration, calibrate_stream
from .com import WINDOW_S
from .marker_ik import MIN_MARKERS, MarkerIK, check_marker_units
from .mass_scaling import (FactorAtBound, FrameRows, MassScaling, RowPool, apply_scaling, assemble_rows, frame_rows,
                           fit_mass_scaling_steps, lengths_at_bounds, scaling_at_bounds)
from .skeleton import Subject, build_human
from .support import SupportRule

STREAM_FIT_STEPS = 2
"""Gauss-Newton steps per streamed frame, warm-started from the last two fits (the first fit gets 40). A third step
moved the COM by at most 0.002 mm on the real Vicon child trial and by less than 0.01 mm on 10 digital humans at 100
and 200 Hz, and cost 12 % of a frame: at 200 Hz on 2 cores the live estimator then fell 30 ms behind in 2 of 3 runs,
in none of 3 without it (docs/results.md, human COM)."""
FIRST_RESCALE_S = 1.0
"""The first mass scaling is solved once this much time [s] of supported frames (one row each) has come in: a time,
not a frame count, so that a faster capture does not solve on less of the trial (at 200 Hz, 100 frames put the
natural rise's COM up to 40 mm off the truth; docs/results.md)."""
MIN_SCALE_S = 0.3
"""No mass scaling from less than this much time [s] of supported frames (the last solve at exit included)."""
RESCALE_EVERY_S = 2.5
"""After the first, the masses are re-solved every this much time [s] of supported frames."""
PLATE_HISTORY_S = 2.0
"""Plate samples kept behind the newest marker frame [s]."""


class PlateBuffer:
    """One plate's samples as they arrive: rows of (t [s], force (3) [N], moment about the lab origin (3) [N m]),
    grown by doubling and trimmed to the last :data:`PLATE_HISTORY_S` when full."""

    def __init__(self, name: str, capacity: int = 4096) -> None:
        self.name = name
        self.data = np.empty((capacity, 7))
        self.n = 0

    @property
    def newest_t_s(self) -> float:
        return float(self.data[self.n - 1, 0]) if self.n else -np.inf

    def append(self, rows: np.ndarray, now_s: float) -> None:
        if self.n + len(rows) > len(self.data):
            live = self.data[:self.n]
            keep = live[live[:, 0] > now_s - PLATE_HISTORY_S]
            size = max(len(self.data), 2 * (len(keep) + len(rows)))
            self.data = np.vstack([keep, np.empty((size - len(keep), 7))])
            self.n = len(keep)
        self.data[self.n:self.n + len(rows)] = rows
        self.n += len(rows)

    def mean_about(self, t_s: float, half_width_s: float) -> tuple[np.ndarray, bool]:
        """The mean wrench (force [N], moment about the lab origin [N m]) (6,) of the samples with |t - t_s| <=
        ``half_width_s``, and whether there are any and all are finite (as :func:`~sit2stand.human.support.
        plate_wrench_at` averages one plate)."""
        t = self.data[:self.n, 0]
        lo = int(np.searchsorted(t, t_s - half_width_s))
        hi = int(np.searchsorted(t, t_s + half_width_s, side="right"))
        d = self.data[lo:hi, 1:]
        finite = np.isfinite(d)
        if hi == lo or not finite[:, :3].all():        # a sample without its force: the plate dropped out
            return np.zeros(6), False
        if not finite.all():                            # a moment missing: counted as zero, as the offline path does
            d = np.where(finite, d, 0.0)
        return d.sum(axis=0) / (hi - lo), True


class PlateSet:
    """The stream's force plates: each one's samples (:class:`PlateBuffer`), their summed wrench per marker time
    (``bins``, kept once every plate's samples have passed it: consecutive windows share all but one frame) and, per
    plate, how many windows it left uncovered (``gaps``). ``dt``: the marker frame period [s]."""

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self.buffers: dict[str, PlateBuffer] = {}
        self.bins: dict[float, tuple[np.ndarray, bool]] = {}
        self.gaps: dict[str, int] = {}

    @property
    def newest_t_s(self) -> float:
        """The time [s] up to which every plate has samples (-inf: none, or no plate)."""
        return min((b.newest_t_s for b in self.buffers.values()), default=-np.inf)

    def add(self, name: str, rows: np.ndarray, now_s: float) -> None:
        buf = self.buffers.get(name)
        if buf is None:
            buf = self.buffers[name] = PlateBuffer(name, max(4096, 2 * len(rows)))
        buf.append(rows, now_s)

    def bin(self, t_s: float) -> tuple[np.ndarray, bool]:
        """All plates' summed wrench (force [N], moment about the lab origin [N m]) (6,), each plate averaged over
        ``t_s`` +- half a frame, and whether every plate has finite samples there."""
        got = self.bins.get(t_s)
        if got is not None:
            return got
        half = self.dt / 2
        total, covered, complete = np.zeros(6), True, True
        for buf in self.buffers.values():
            wrench, ok = buf.mean_about(t_s, half)
            covered &= ok
            complete &= buf.newest_t_s >= t_s + half
            if ok:
                total += wrench
        if complete:
            self.bins[t_s] = (total, covered)
        return total, covered

    def wrench(self, times: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """Summed plate wrench at the centre of the window's marker ``times``, smoothed by the centred
        Savitzky-Golay ``weights`` of the kinematics; covered is False if a plate has no sample there."""
        if not self.buffers:
            return np.zeros(3), np.zeros(3), False
        bins = [self.bin(float(t)) for t in times]
        for t in [t for t in self.bins if t < times[0]]:
            del self.bins[t]
        centre = len(times) // 2
        wrench, covered = bins[centre]
        if not covered:
            for name, buf in self.buffers.items():
                if not buf.mean_about(float(times[centre]), self.dt / 2)[1]:
                    self.gaps[name] = self.gaps.get(name, 0) + 1
            return wrench[:3], wrench[3:], False
        if all(ok for _, ok in bins):
            smoothed = weights @ np.array([w for w, _ in bins])
            return smoothed[:3], smoothed[3:], True
        return wrench[:3], wrench[3:], True


class MotionWindow:
    """The last ``2 window`` fitted frames: times [s], poses, their decoupled coordinates (base position, base
    rotation vector about the first frame's, joint angles) and whether each was fitted (False: its pose was held);
    with Savitzky-Golay fits over them (weights cached per position and length)."""

    def __init__(self, window: int, dt: float) -> None:
        self.window, self.dt = window, dt
        self.t: list[float] = []
        self.q: list[np.ndarray] = []
        self.x: list[np.ndarray] = []
        self.fitted: list[bool] = []
        self.R0: np.ndarray | None = None
        self._coeffs: dict[tuple[int, int], list[np.ndarray]] = {}

    def __len__(self) -> int:
        return len(self.x)

    def append(self, t_s: float, q: np.ndarray, fitted: bool) -> None:
        self.t.append(t_s)
        self.q.append(q.copy())
        self.x.append(self._coords(q))
        self.fitted.append(fitted)
        keep = 2 * self.window
        if len(self.q) > keep:
            del self.t[:-keep], self.q[:-keep], self.x[:-keep], self.fitted[:-keep]

    def clear(self) -> None:
        self.t.clear()
        self.q.clear()
        self.x.clear()
        self.fitted.clear()

    def _coords(self, q: np.ndarray) -> np.ndarray:
        """Decoupled coordinates of smooth_motion: base position, base rotation vector about R0, joint angles."""
        R = pin.Quaternion(q[3:7]).normalized().matrix()
        if self.R0 is None:
            self.R0 = R
        return np.concatenate([q[:3], pin.log3(self.R0.T @ R), q[7:]])

    def savgol(self, pos: int, length: int) -> list[np.ndarray]:
        """Savitzky-Golay weights (position, first and second derivative) at sample ``pos`` of ``length``, cached."""
        key = (pos, length)
        if key not in self._coeffs:
            order = min(4, length - 2)
            self._coeffs[key] = [savgol_coeffs(length, order, deriv=d, pos=pos, use="dot") / self.dt**d
                                 for d in (0, 1, 2)]
        return self._coeffs[key]

    def derivatives_at(self, pos: int, length: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, v, a of the window's sample ``pos`` from a Savitzky-Golay fit of the last ``length`` frames."""
        X = np.array(self.x[-length:])
        xs, xd, xdd = (c @ X for c in self.savgol(pos, length))
        r, rd, rdd = xs[3:6], xd[3:6], xdd[3:6]
        R = self.R0 @ pin.exp3(r)
        q = np.concatenate([xs[:3], pin.Quaternion(R).coeffs(), xs[6:]])
        Jr = pin.Jexp3(r)
        h = 1e-4
        dJr = (pin.Jexp3(r + h * rd) - pin.Jexp3(r - h * rd)) / (2 * h)
        w = Jr @ rd
        v_lin = R.T @ xd[:3]
        v = np.concatenate([v_lin, w, xd[6:]])
        a = np.concatenate([R.T @ xdd[:3] - cross(w, v_lin), Jr @ rdd + dJr @ rd, xdd[6:]])
        return q, v, a


@dataclass
class ScalingRows:
    """The COP-matched mass scaling's rows (one per supported frame), and when to solve them: first at ``first``
    rows, then every ``every``, never from fewer than ``min_rows``. ``defer``: a due solve is only flagged
    (``pending``), for a live caller to run after the frame is out (a re-solve costs ~10 ms)."""

    every: int
    min_rows: int
    first: int
    defer: bool = False
    frames: RowPool = field(default_factory=RowPool)
    skipped_unfitted: int = 0      # supported frames kept out: held poses in their window
    pending: bool = False

    def __len__(self) -> int:
        return len(self.frames)

    def add(self, rows: FrameRows) -> bool:
        """Add a frame's rows; whether to solve now (False also when the solve is deferred: ``pending``)."""
        self.frames.add(rows)
        n = len(self.frames)
        if n < self.min_rows or not (n == self.first or n % self.every == 0):
            return False
        self.pending = self.defer
        return not self.defer


@dataclass
class StreamOutput:
    """What one frame yields: the COM now, and, half a window later, the model COP of an earlier frame."""

    t_s: float
    valid: bool
    q: np.ndarray
    com_m: np.ndarray
    com_vel: np.ndarray
    com_acc: np.ndarray
    marker_rms_m: float
    n_markers: int
    delayed_t_s: float | None = None
    model_cop_m: np.ndarray | None = None
    measured_cop_m: np.ndarray | None = None
    rescaled: bool = False


class StreamingComEstimator:
    """Frame-by-frame COM estimation with calibration at the start and COP-matched scaling as data arrive.

    ``add_plate_samples`` takes force-plate samples as they come; ``update`` takes one marker frame and returns a
    :class:`StreamOutput`. The first ``calibration_frames`` valid frames calibrate segment lengths and marker
    placements (one pause of ~1-2 s, after which queued frames are processed at the normal rate), unless a
    ``calibration`` made beforehand (:func:`calibrate_stream` on a static trial) is given. The COM
    velocity/acceleration published are from a causal Savitzky-Golay fit over the last ``window_s`` [s]; the
    scaling uses the centred fit of the frame half a window back, as the offline estimator does.
    """

    def __init__(self, subject: Subject, marker_names: list[str], *, rate_hz: float = 100.0, window_s: float = WINDOW_S,
                 calibration_frames: int = 50, rescale_every_s: float = RESCALE_EVERY_S, chair_on_plate: bool = True,
                 calibration: StreamCalibration | None = None, defer_rescale: bool = False) -> None:
        self.subject = subject
        self.marker_names = list(marker_names)
        dt = 1.0 / rate_hz
        self.calibration_frames = calibration_frames
        if not rescale_every_s > 0:
            raise ValueError(f"rescale_every_s {rescale_every_s!r}: the time between two mass scalings must be > 0 s")
        # the scaling's schedule in rows (one per supported frame), from times: the same seconds at any rate; a
        # re-solve of the masses costs ~10 ms: a live caller may defer it past the frame's publication
        # (``rows.pending``, then :meth:`rescale`); the frame's own COM never depends on it
        min_rows = max(1, round(MIN_SCALE_S * rate_hz))
        self.rows = ScalingRows(max(1, round(rescale_every_s * rate_hz)), min_rows,
                                max(min_rows, round(FIRST_RESCALE_S * rate_hz)), defer_rescale)
        self.human = build_human(subject)
        self.ik = MarkerIK(self.human, self.marker_names)   # raises TooFewMarkers early
        self.model = self.human.model
        self.data = self.model.createData()
        self._calib: list[tuple[np.ndarray, np.ndarray]] = []
        self.motion = MotionWindow(savgol_frames(window_s, dt), dt)
        self.plates = PlateSet(dt)
        self._units_checked = False
        self._t_first: float | None = None    # the first marker frame's time [s]
        self.scaling: MassScaling | None = None
        self.scaled_model = self.model
        self.scaled_data = self.model.createData()
        self.frames = 0
        self.support = SupportRule(subject.mass_kg * G, chair_on_plate)
        self._pending: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]] = []
        self.calibration: StreamCalibration | None = None
        if calibration is not None:       # calibrated beforehand: no pause in the stream
            self._use(calibration)

    @property
    def dt(self) -> float:
        """The marker frame period [s]."""
        return self.motion.dt

    @property
    def window(self) -> int:
        """The Savitzky-Golay window [frames]."""
        return self.motion.window

    @property
    def calibrated(self) -> bool:
        return self.calibration is not None or self.calibration_frames <= 0

    @property
    def plate_gaps(self) -> dict[str, int]:
        """Per plate, the windows it left uncovered."""
        return self.plates.gaps

    # -- inputs ------------------------------------------------------------------------------------------------
    def expect_plate(self, name: str) -> None:
        """Declare a plate that must have data for a frame to count (before its first sample arrives)."""
        if name not in self.plates.buffers:
            self.plates.buffers[name] = PlateBuffer(name)

    def drop_silent_plates(self, after_s: float = 0.3) -> list[str]:
        """Expected plates that have sent nothing for ``after_s`` [s] of marker time while another plate has: the
        recording has no such plate. They stop holding frames back; without the chair plate, frames count for the
        scaling only once the feet carry the whole weight. Returns the plates dropped."""
        buffers, t = self.plates.buffers, self.motion.t
        if self._t_first is None or not t or t[-1] - self._t_first < after_s or not any(b.n for b in buffers.values()):
            return []
        silent = [name for name, b in buffers.items() if b.n == 0]
        for name in silent:
            del buffers[name]
        if "chair" in silent:
            self.support = SupportRule(self.subject.mass_kg * G, chair_on_plate=False)
        return silent

    def add_plate_samples(self, name: str, t_s: np.ndarray, force_n: np.ndarray, moment_nm: np.ndarray) -> None:
        """Append force-plate samples (times [s], force [N] and moment about the lab origin [N m], (K, 3))."""
        t = np.atleast_1d(np.asarray(t_s, float))
        rows = np.hstack([t[:, None], np.atleast_2d(force_n), np.atleast_2d(moment_nm)])
        self.plates.add(name, rows, self.motion.t[-1] if self.motion.t else t[0])

    def update(self, t_s: float, positions_m: np.ndarray, valid: np.ndarray,
               defer_delayed: bool = False) -> StreamOutput:
        """One marker frame (positions [m], validity, in the stream's marker order) at ``t_s`` [s]: the fit and the
        causal COM, then the delayed work (the centred window half a window back: model and measured COP, scaling
        rows). ``defer_delayed``: leave that to :meth:`process_delayed`, so that a live caller can publish the COM
        first (its model/measured COP then come with that call)."""
        self._t_first = t_s if self._t_first is None else self._t_first
        if not self._units_checked and np.sum(valid) >= MIN_MARKERS:
            check_marker_units(positions_m, valid, self.subject.height_m, "marker stream")
            self._units_checked = True
        if not self.calibrated:
            if np.sum(valid) >= CALIBRATION_MIN_MARKERS:
                self._calib.append((np.asarray(positions_m, float).copy(), np.asarray(valid, bool).copy()))
            if len(self._calib) >= self.calibration_frames:
                self._calibrate()
        fit = self.ik.fit(positions_m, valid, max_iter=STREAM_FIT_STEPS if self.ik.q is not None else 40)
        self.frames += 1
        if not fit.ok and not self.motion.q:
            nan3 = np.full(3, np.nan)
            return StreamOutput(t_s, False, fit.q, nan3, nan3, nan3, fit.rms_m, fit.n_markers)
        q = fit.q if fit.ok else self.motion.q[-1]
        self.motion.append(t_s, q, fit.ok)
        com, vcom, acom = self._causal_com()
        out = StreamOutput(t_s, fit.ok, q, com, vcom, acom, fit.rms_m, fit.n_markers)
        if not defer_delayed:
            self.process_delayed(out)
        return out

    def process_delayed(self, out: StreamOutput) -> StreamOutput:
        """The delayed part of :meth:`update` for its output ``out`` (fills its COP fields; see ``update``)."""
        self._delayed(out)
        return out

    # -- internals ----------------------------------------------------------------------------------------------
    def _calibrate(self) -> None:
        pos = np.array([p for p, _ in self._calib])
        val = np.array([v for _, v in self._calib])
        self._use(calibrate_stream(self.subject, self.marker_names, pos, val))

    def _use(self, calibration: StreamCalibration) -> None:
        self.calibration = calibration
        subject, human = calibration.build(self.subject)
        self.subject, self.human, self.model = subject, human, human.model
        self.data = self.model.createData()
        q_prev = self.ik.q
        self.ik = MarkerIK(human, self.marker_names)
        self.ik.q = q_prev
        self.scaled_model, self.scaled_data = self.model, self.model.createData()
        self.motion.clear()

    def _causal_com(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        motion = self.motion
        n = len(motion)
        if n < 7:
            pin.centerOfMass(self.scaled_model, self.scaled_data, motion.q[-1])
            return self.scaled_data.com[0].copy(), np.zeros(3), np.zeros(3)
        length = min(motion.window, n - (1 - n % 2))
        q, v, a = motion.derivatives_at(length - 1, length)
        pin.centerOfMass(self.scaled_model, self.scaled_data, motion.q[-1], v, a)
        return self.scaled_data.com[0].copy(), self.scaled_data.vcom[0].copy(), self.scaled_data.acom[0].copy()

    def _delayed(self, out: StreamOutput) -> None:
        """Queue the frame half a window back (its centred derivatives are known now) and process every queued
        frame whose plate samples have all arrived (plates may lag the markers on a busy executor)."""
        motion = self.motion
        n, w = len(motion), motion.window
        if n >= w and self.calibrated:
            q_k, v_k, a_k = motion.derivatives_at(w // 2, w)
            self._pending.append((np.array(motion.t[-w:]), q_k, v_k, a_k, all(motion.fitted[-w:])))
        while self._pending:
            times, q_k, v_k, a_k, fitted = self._pending[0]
            t_k = times[len(times) // 2]
            if self.plates.newest_t_s < times[-1] + self.dt / 2 and motion.t[-1] - t_k < 0.5 and self.plates.buffers:
                break                      # plate samples for this window not all here yet
            self._pending.pop(0)
            self._process(out, times, q_k, v_k, a_k, fitted)

    def _process(self, out: StreamOutput, times: np.ndarray, q_k: np.ndarray, v_k: np.ndarray,
                 a_k: np.ndarray, fitted: bool) -> None:
        t_k = times[len(times) // 2]
        force, moment, covered = self.plates.wrench(times, self.motion.savgol(len(times) // 2, len(times))[0])
        com, _, _, cop_model = model_cop(self.scaled_model, self.scaled_data, q_k, v_k, a_k)
        out.delayed_t_s = t_k
        out.model_cop_m = cop_model
        if not covered:
            return
        cop, ok, _ = center_of_pressure(force, moment, np.zeros(3), np.array([0.0, 0.0, 1.0]), threshold_n=1.0)
        out.measured_cop_m = cop if ok else None
        if not self.support.step(force[2]) or not ok:
            return
        if not fitted:
            # a held pose has no velocity or acceleration: its rows would pull every mass to a bound
            self.rows.skipped_unfitted += 1
            return
        if self.rows.add(frame_rows(self.human, q_k, v_k, a_k, force, moment, cop, self.subject.mass_kg, self.data)):
            self.rescale()
            out.rescaled = True

    def rescale(self) -> MassScaling | None:
        """Solve the scaling from all rows so far and switch the COM model to it (None: too few rows)."""
        steps = list(self.rescale_in_steps())
        return steps[-1] if steps else None

    def rescale_in_steps(self) -> Iterator[MassScaling | None]:
        """:meth:`rescale` a solve at a time (~0.3-0.8 ms each offline), for a live caller to run one piece after
        each frame's COM: whole, the re-solve held up the frame after it (at 100 Hz in the live graph up to 2.6 ms
        late, in pieces up to 0.8). Yields None after each piece but the last, which switches the COM model and
        yields its scaling; yields nothing when there are too few rows. The rows are those when it starts."""
        if len(self.rows) < self.rows.min_rows:
            return
        for fit in fit_mass_scaling_steps(self.human, assemble_rows(self.rows.frames), self.subject.mass_kg):
            scaling = fit
            yield None
        self.scaling = scaling
        self.scaled_model = apply_scaling(self.human, self.scaling)
        self.scaled_data = self.scaled_model.createData()
        yield self.scaling

    @property
    def at_bounds(self) -> list[FactorAtBound]:
        """The calibration's length factors and the latest scaling's mass factors that sit at a bound of their fit."""
        out = lengths_at_bounds(self.calibration.lengths) if self.calibration is not None else []
        return out + (scaling_at_bounds(self.scaling) if self.scaling is not None else [])

    @property
    def warnings(self) -> list[str]:
        """:attr:`at_bounds` as lines for a log, each naming the segment group and the factor (empty: none)."""
        return [f.note() for f in self.at_bounds]
