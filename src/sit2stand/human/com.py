"""Offline human centre-of-mass estimation of a whole trial, from markers and force plates.

Pipeline (the paper's section on the human COM, with the scaling done automatically):

1. :func:`~sit2stand.human.calibration.calibrate_lengths` scales segment lengths to the markers and
   :func:`~sit2stand.human.calibration.calibrate_markers` places the markers on their segments.
2. :class:`~sit2stand.human.marker_ik.MarkerIK` fits the skeleton to each frame; frames it cannot fit are bridged.
3. :func:`~sit2stand.dynamics.smooth_motion` smooths the fitted motion (Savitzky-Golay, ~8 Hz) and differentiates
   it; the plate wrench is smoothed the same way, so kinematics and forces share one bandwidth.
4. Frames whose whole weight is on the plates (:class:`~sit2stand.human.support.SupportRule`) and whose window
   holds no bridged frame scale the segment masses to the plates' wrench (:mod:`sit2stand.human.mass_scaling`).
5. COM position, velocity and acceleration follow from the scaled model.
6. A length or mass factor that ends at a bound of its fit is named in the notes (:class:`FactorAtBound`), and so is
   a children's segment table (:func:`~sit2stand.human.anthropometry.anthropometric_set`).

Units SI, lab frame REP-103.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..dynamics import G, model_cop, savgol_frames, savgol_series, smooth_motion
from ..forceplate import PlateSeries, center_of_pressure
from .anthropometry import anthropometric_set
from .calibration import StreamCalibration, calibrate_lengths, calibrate_markers
from .marker_ik import MarkerIK, TooFewMarkers, bridge_skipped, check_marker_units, fit_sequence
from .mass_scaling import (FactorAtBound, MassScaling, apply_scaling, assemble_rows, frame_rows, lengths_at_bounds,
                           fit_mass_scaling, prior_scaling, scaling_at_bounds)
from .skeleton import HumanModel, Subject, build_human
from .support import SupportRule, body_mass_from_plates, plate_gaps, plate_wrench_at

WINDOW_S = 0.3
"""The Savitzky-Golay window [s] (order 4, about 8 Hz) of the fitted motion and the plate wrench, offline and in the
stream (31 frames at 100 Hz). In seconds: over 31 frames of a 200 Hz capture (0.15 s) the streamed COM velocity's
error doubled (0.031 against 0.017 m/s RMS on a digital human) and the mass factors strayed (pelvis 1.43 against
1.23)."""
PLATE_MASS_TOLERANCE = 0.05
"""Relative difference beyond which the plates' weighing of the subject replaces the given body mass."""


def model_series(model: pin.Model, qs: np.ndarray, vs: np.ndarray, as_: np.ndarray):
    """COM, COM velocity, COM acceleration and model COP (each (N, 3) float) along a motion."""
    data = model.createData()
    out = [model_cop(model, data, q, v, a) for q, v, a in zip(qs, vs, as_)]
    return tuple(np.array([o[i] for o in out], dtype=float) for i in range(4))


@dataclass
class ComResult:
    """Output of :func:`estimate_com` (arrays at the marker rate)."""

    t_s: np.ndarray
    com_m: np.ndarray
    com_vel: np.ndarray
    com_acc: np.ndarray
    com_unscaled_m: np.ndarray
    model_cop_m: np.ndarray
    measured_cop_m: np.ndarray
    supported: np.ndarray          # frames whose whole weight is on the plates
    fit_ok: np.ndarray
    marker_rms_m: np.ndarray
    n_markers: np.ndarray
    scaling: MassScaling
    subject: Subject
    calibration_rms_before_m: float
    calibration_rms_after_m: float
    plate_gaps: list[tuple[str, float, float]] = field(default_factory=list)
    q: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    v: np.ndarray | None = None              # (N, nv) smoothed velocities of the fitted motion
    a: np.ndarray | None = None              # (N, nv) and accelerations
    force_n: np.ndarray | None = None        # (N, 3) plates' total force at the marker times (smoothed alike)
    moment_nm: np.ndarray | None = None      # (N, 3) and moment about the lab origin
    model: pin.Model | None = None           # the calibrated skeleton before any mass scaling
    at_bounds: list[FactorAtBound] = field(default_factory=list)   # fitted factors at a bound (also in notes)
    segment_table: str = ""                  # which anthropometric table the skeleton has (anthropometric_set)



@dataclass
class _Motion:
    """The fitted, bridged and smoothed motion of a trial: (N, nq) q and (N, nv) v, a; ``fitted`` (N,)."""

    human: HumanModel
    subject: Subject
    fits: list
    fitted: np.ndarray
    qs: np.ndarray
    vs: np.ndarray
    as_: np.ndarray
    rms_before_m: float = float("nan")     # marker RMS of the default model
    rms_after_m: float = float("nan")      # and after lengths and placements are calibrated


def _fit_motion(marker_t_s, marker_names, positions, valid, subject: Subject, calibrate: bool, window: int,
                progress, calibration: StreamCalibration | None = None) -> _Motion:
    """Calibrate (optionally; on the whole trial, or use ``calibration``), fit every frame, bridge the frames that
    could not be fitted, smooth."""
    dt = float(np.median(np.diff(marker_t_s)))
    first = int(np.argmax(np.sum(valid, axis=1)))          # the frame that sees the most markers
    check_marker_units(positions[first], valid[first], subject.height_m, "markers")
    rms_before = rms_after = float("nan")
    if calibration is not None:
        subject, human = calibration.build(subject)
        rms_before, rms_after = calibration.marker_rms_before_m, calibration.marker_rms_after_m
    elif calibrate:
        subject, rms_before, _ = calibrate_lengths(subject, marker_names, positions, valid)
        human = build_human(subject)
        _, rms_after = calibrate_markers(human, marker_names, positions, valid)
    else:
        human = build_human(subject)
    fits = fit_sequence(MarkerIK(human, marker_names), positions, valid, progress)
    ok = np.array([f.ok for f in fits])
    if ok.sum() < window:
        raise TooFewMarkers(f"only {ok.sum()} frames could be fitted (need {window}); check the marker set")
    q_raw = bridge_skipped(human.model, np.array([f.q for f in fits]), ok)
    qs, vs, as_ = smooth_motion(human.model, q_raw, dt, window)
    return _Motion(human, subject, fits, ok, qs, vs, as_, rms_before, rms_after)


def _plate_wrench(marker_t_s: np.ndarray, plates: list[PlateSeries], window: int):
    """Plates' summed force and moment at the marker times, smoothed like the kinematics, and coverage."""
    dt = float(np.median(np.diff(marker_t_s)))
    force, moment, covered = plate_wrench_at(marker_t_s, plates, dt / 2)
    w_eff = min(window, len(force) - (1 - len(force) % 2))
    force = savgol_series(force, w_eff, 4, 0)     # the same filter as the kinematics: one bandwidth for both
    moment = savgol_series(moment, w_eff, 4, 0)
    return force, moment, covered


def _supported(force: np.ndarray, covered: np.ndarray, fitted: np.ndarray, weight_n: float, chair_on_plate: bool,
               window: int) -> np.ndarray:
    """Frames whose whole weight is on the plates, with every plate sampled and no bridged frame in the smoothing
    window (a bridged pose has made-up derivatives), away from the trial's edges (the smoother extrapolates)."""
    supported = covered & SupportRule(weight_n, chair_on_plate).series(force[:, 2])
    half = window // 2
    near_bridged = np.convolve(~fitted, np.ones(window), mode="same") > 0
    supported &= ~near_bridged
    supported[:half] = supported[-half:] = False
    return supported


def _reweighed(motion: _Motion, plate_mass: float, notes: list[str]) -> _Motion:
    """The motion's subject with the plates' body mass (calibrated marker placements kept)."""
    rel = plate_mass / motion.subject.mass_kg - 1.0
    notes.append(f"the plates weigh the subject at {plate_mass:.2f} kg in quiet support, {100 * rel:+.1f} % "
                 f"from the given {motion.subject.mass_kg:g} kg; using the plates' value")
    subject = dataclasses.replace(motion.subject, mass_kg=plate_mass)     # marker set, lengths, extras kept
    human = build_human(subject)
    for name, fid in motion.human.marker_frames.items():
        human.model.frames[human.marker_frames[name]].placement = motion.human.model.frames[fid].placement
    motion.subject, motion.human = subject, human
    return motion


def _measured_cop(force: np.ndarray, moment: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """(N, 3) COP of the summed plate wrench on the floor, NaN where a plate is missing or unloaded."""
    cop = np.full((len(force), 3), np.nan)
    for k in np.flatnonzero(covered):
        cop[k], _, _ = center_of_pressure(force[k], moment[k], np.zeros(3), np.array([0, 0, 1.0]), threshold_n=1.0)
    return cop


def _cop_rms(cop: np.ndarray, measured: np.ndarray, sel: np.ndarray) -> float:
    """Horizontal RMS distance [m] between two COP series over the selected frames."""
    if not sel.any():
        return float("nan")
    return float(np.sqrt(np.mean(np.sum((cop[sel, :2] - measured[sel, :2]) ** 2, axis=1))))


def estimate_com(marker_t_s: np.ndarray, marker_names: list[str], positions: np.ndarray, valid: np.ndarray,
                 plates: list[PlateSeries], subject: Subject, *, calibrate: bool = True, scale_masses: bool = True,
                 chair_on_plate: bool = True, window_s: float = WINDOW_S, trust_plate_mass: bool = True,
                 quasi_static_acc: float = 0.15, progress=None,
                 calibration: StreamCalibration | None = None) -> ComResult:
    """Offline COM estimation of a whole trial (see the module docstring).

    Args:
        marker_t_s: (N,) marker frame times [s]; ``positions`` (N, M, 3) [m] and ``valid`` (N, M) in the order of
            ``marker_names``.
        plates: the trial's force plates.
        subject: stature, body mass and sex (the mass is replaced by the plates' weighing if they differ by more
            than :data:`PLATE_MASS_TOLERANCE` and ``trust_plate_mass``).
        chair_on_plate: the chair stands on a plate (see :class:`~sit2stand.human.support.SupportRule`).
        calibration: a skeleton calibration made beforehand (on chosen frames or a static trial,
            :func:`~sit2stand.human.offline.calibrate_subject`) instead of the one on the whole trial.
    """
    dt = float(np.median(np.diff(marker_t_s))) if len(marker_t_s) > 1 else 0.0
    if not dt > 0:
        raise TooFewMarkers(f"{len(marker_t_s)} marker frames, {dt:g} s apart: a trial needs frames at increasing "
                            "times")
    window = savgol_frames(window_s, dt)
    motion = _fit_motion(marker_t_s, marker_names, positions, valid, subject, calibrate, window, progress,
                         calibration)
    force, moment, covered = _plate_wrench(marker_t_s, plates, window)
    supported = _supported(force, covered, motion.fitted, subject.mass_kg * G, chair_on_plate, window)
    notes: list[str] = []
    plate_mass = body_mass_from_plates(force, supported, motion.qs, motion.human, dt)
    if plate_mass is not None and trust_plate_mass and abs(plate_mass / subject.mass_kg - 1) > PLATE_MASS_TOLERANCE:
        motion = _reweighed(motion, plate_mass, notes)
    human, qs, vs, as_ = motion.human, motion.qs, motion.vs, motion.as_
    measured_cop = _measured_cop(force, moment, covered)
    com_unscaled, _, _, cop_unscaled = model_series(human.model, qs, vs, as_)
    if scale_masses and supported.sum() >= 10:
        data = human.model.createData()
        rows = [frame_rows(human, qs[k], vs[k], as_[k], force[k], moment[k], measured_cop[k],
                           motion.subject.mass_kg, data) for k in np.flatnonzero(supported)]
        scaling = fit_mass_scaling(human, assemble_rows(rows, quasi_static_acc), motion.subject.mass_kg)
        model = apply_scaling(human, scaling)
    else:
        scaling, model = prior_scaling(human), human.model
    com, vcom, acom, cop_model = model_series(model, qs, vs, as_)
    sel = supported & np.all(np.isfinite(measured_cop), axis=1)
    scaling.cop_rms_before_m = _cop_rms(cop_unscaled, measured_cop, sel)
    scaling.cop_rms_after_m = _cop_rms(cop_model, measured_cop, sel)
    table = anthropometric_set(motion.subject.height_m, motion.subject.sex)
    if not table.is_adult:
        notes.append(table.describe())
    at_bounds = (lengths_at_bounds(motion.subject.lengths) if calibrate or calibration is not None else []) + \
        scaling_at_bounds(scaling)
    notes += [f.note() for f in at_bounds]
    fits = motion.fits
    return ComResult(marker_t_s, com, vcom, acom, com_unscaled,
                     cop_model, measured_cop, supported, motion.fitted, np.array([f.rms_m for f in fits]),
                     np.array([f.n_markers for f in fits]), scaling, motion.subject, motion.rms_before_m,
                     motion.rms_after_m, plate_gaps(marker_t_s, plates, dt), qs, notes,
                     vs, as_, force, moment, human.model, at_bounds=at_bounds, segment_table=table.describe())
