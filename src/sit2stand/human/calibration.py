"""Skeleton calibration to a subject's markers: segment lengths, then marker placements on their segments.

:func:`calibrate_lengths` scales segment lengths by nested least squares over a few frames; :func:`calibrate_markers`
moves each model marker by its median residual in its segment frame, as a marker placer does;
:class:`StreamCalibration` keeps both for a stream (made once on seated, still frames: a static trial).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import yaml
from scipy.optimize import least_squares

from ..errors import Sit2StandError
from .marker_ik import MIN_MARKERS, MarkerIK
from .skeleton import LENGTH_GROUPS, HumanModel, Subject, build_human

CALIBRATION_MIN_MARKERS = MIN_MARKERS + 4
"""Markers a frame needs to be used for a calibration."""


class CalibrationError(Sit2StandError, ValueError):
    """A calibration that cannot be read or does not fit the subject; the message names the file or the subject."""


def calibrate_lengths(subject: Subject, marker_names: list[str], positions: np.ndarray, valid: np.ndarray,
                      n_frames: int = 10, max_nfev: int = 60) -> tuple[Subject, float, float]:
    """Segment length factors that best fit the markers, over ``n_frames`` frames spread over the trial.

    Returns (subject with fitted ``lengths``, marker RMS before [m], after [m]). Factors are bounded to 0.6..1.6
    (children and adults).
    """
    valid = np.asarray(valid, bool) & np.all(np.isfinite(positions), axis=-1)    # a NaN marker is not seen
    good = [k for k in range(len(positions)) if np.sum(valid[k]) >= CALIBRATION_MIN_MARKERS]
    picks = [good[i] for i in np.linspace(0, len(good) - 1, min(n_frames, len(good))).astype(int)]
    groups = list(LENGTH_GROUPS)
    warm: dict[int, np.ndarray] = {}

    def residuals(x: np.ndarray) -> np.ndarray:
        subj = Subject(subject.height_m, subject.mass_kg, subject.sex, dict(zip(groups, x)), dict(subject.masses),
                       list(subject.extra), marker_set=subject.marker_set)
        ik = MarkerIK(build_human(subj), marker_names)
        out = []
        for k in picks:
            fit = ik.fit(positions[k], valid[k], q0=warm.get(k), max_iter=40, tol=1e-9)
            warm[k] = fit.q
            ok = np.asarray(valid[k], bool)[ik.stream_index]
            out.append((ik._marker_positions(fit.q)[ok] - positions[k][ik.stream_index][ok]).ravel())
        prior = 0.02 * (x - 1.0)  # weak pull to 1: unobserved groups (e.g. arms without arm markers) stay put
        return np.concatenate(out + [prior])

    x0 = np.array([subject.lengths.get(g, 1.0) for g in groups])
    r0 = residuals(x0)
    sol = least_squares(residuals, x0, bounds=(0.6, 1.6), diff_step=1e-3, max_nfev=max_nfev, x_scale=0.05)
    r1 = residuals(sol.x)
    n_m = len(r0) - len(groups)

    def rms(r: np.ndarray) -> float:   # per-marker distance RMS over the marker rows
        return float(np.sqrt(np.mean(r[:n_m] ** 2) * 3))

    fitted = Subject(subject.height_m, subject.mass_kg, subject.sex, dict(zip(groups, map(float, sol.x))),
                     dict(subject.masses), list(subject.extra), marker_set=subject.marker_set)
    return fitted, rms(r0), rms(r1)



def calibrate_markers(human: HumanModel, marker_names: list[str], positions: np.ndarray, valid: np.ndarray,
                      iterations: int = 3, max_shift_m: float = 0.06, stride: int = 3) -> tuple[float, float]:
    """Move each model marker (in its segment frame) by its median fit residual, as a marker placer does.

    Markers are never placed exactly where the model expects (wands, soft tissue, a child's head): after IK over
    every ``stride``-th frame, each marker's residual is expressed in its segment frame and its median added to the
    marker's placement (at most ``max_shift_m`` in all). Modifies ``human.model`` in place; returns the marker RMS
    [m] before and after.
    """
    model = human.model
    original = {n: model.frames[f].placement.translation.copy() for n, f in human.marker_frames.items()}
    frames = list(range(0, len(positions), stride))
    rms = []
    for it in range(iterations + 1):
        ik = MarkerIK(human, marker_names)
        per_marker: dict[str, list[np.ndarray]] = {n: [] for n in ik.used_names}
        errs = []
        for k in frames:
            fit = ik.fit(positions[k], valid[k], max_iter=40 if ik.q is None else 15)
            if not fit.ok:
                continue
            pin.framesForwardKinematics(model, ik.data, fit.q)
            for j, name in enumerate(ik.used_names):
                meas = positions[k][ik.stream_index[j]]
                if not valid[k][ik.stream_index[j]] or not np.all(np.isfinite(meas)):
                    continue
                oMf = ik.data.oMf[human.marker_frames[name]]
                per_marker[name].append(oMf.rotation.T @ (meas - oMf.translation))
                errs.append(np.linalg.norm(meas - oMf.translation))
        rms.append(float(np.sqrt(np.mean(np.square(errs)))) if errs else float("nan"))
        if it == iterations:
            break
        for name, residuals in per_marker.items():
            if len(residuals) < 3:
                continue
            fid = human.marker_frames[name]
            placement = model.frames[fid].placement
            new = placement.translation + np.median(residuals, axis=0)
            shift = new - original[name]
            norm = np.linalg.norm(shift)
            if norm > max_shift_m:
                new = original[name] + shift * max_shift_m / norm
            model.frames[fid].placement = pin.SE3(placement.rotation, new)
    return rms[0], rms[-1]


@dataclass
class StreamCalibration:
    """A subject's skeleton calibrated for streaming: segment length factors and each marker's placement in its
    segment's frame [m], from a stretch of seated, still frames (a static trial, as labs record before the motion).

    Given to :class:`StreamingComEstimator` (or the node's ``calibration_file``), the stream needs no calibration
    pause of its own."""

    lengths: dict[str, float]
    marker_placements_m: dict[str, list[float]]
    frames: int
    marker_rms_before_m: float
    marker_rms_after_m: float
    height_m: float = float("nan")    # the subject it was made for (length factors are relative to the stature)
    sex: str = ""

    def build(self, subject: Subject) -> tuple[Subject, HumanModel]:
        """The calibrated subject and skeleton (markers moved to their calibrated placements). Raises CalibrationError
        if it was made for another stature or sex."""
        if np.isfinite(self.height_m) and abs(self.height_m - subject.height_m) > 1e-6 or \
                self.sex and self.sex != subject.sex:
            raise CalibrationError(f"the calibration is for a {self.height_m:g} m {self.sex}, the subject is a "
                             f"{subject.height_m:g} m {subject.sex}")
        subj = Subject(subject.height_m, subject.mass_kg, subject.sex, dict(self.lengths), dict(subject.masses),
                       list(subject.extra), marker_set=subject.marker_set)
        human = build_human(subj)
        for name, p in self.marker_placements_m.items():
            fid = human.marker_frames.get(name)
            if fid is not None:
                old = human.model.frames[fid].placement
                human.model.frames[fid].placement = pin.SE3(old.rotation, np.asarray(p, float))
        return subj, human

    def save(self, path) -> None:
        doc = {"lengths": {k: float(v) for k, v in self.lengths.items()},
               "marker_placements_m": {k: [float(x) for x in v] for k, v in self.marker_placements_m.items()},
               "frames": int(self.frames), "marker_rms_before_m": float(self.marker_rms_before_m),
               "marker_rms_after_m": float(self.marker_rms_after_m), "height_m": float(self.height_m),
               "sex": self.sex}
        with open(path, "w") as f:
            f.write("# sit2stand human skeleton calibration (segment length factors; marker placements in their "
                    "segment frames [m])\n")
            yaml.safe_dump(doc, f, sort_keys=False)

    @classmethod
    def load(cls, path) -> StreamCalibration:
        """Read a file written by :meth:`save`; errors name the file and the field."""
        try:
            with open(path) as f:
                doc = yaml.safe_load(f) or {}
            return cls({str(k): float(v) for k, v in doc["lengths"].items()},
                       {str(k): [float(x) for x in v] for k, v in doc["marker_placements_m"].items()},
                       int(doc.get("frames", 0)), float(doc.get("marker_rms_before_m", "nan")),
                       float(doc.get("marker_rms_after_m", "nan")), float(doc.get("height_m", "nan")),
                       str(doc.get("sex", "")))
        except OSError as err:
            raise CalibrationError(f"{path}: cannot read the calibration: {err}") from None
        except (KeyError, TypeError, ValueError, AttributeError, yaml.YAMLError) as err:
            raise CalibrationError(f"{path}: not a skeleton calibration (needs lengths and marker_placements_m): "
                             f"{err!r}") from None


def calibrate_stream(subject: Subject, marker_names: list[str], positions: np.ndarray,
                     valid: np.ndarray) -> StreamCalibration:
    """Calibrate segment lengths and then marker placements on (N, M, 3) seated, still frames (the streaming
    estimator's first ``calibration_frames``, or a static trial beforehand)."""
    pos, val = np.asarray(positions, float), np.asarray(valid, bool)
    fitted, before, _ = calibrate_lengths(subject, marker_names, pos, val, n_frames=8, max_nfev=40)
    human = build_human(fitted)
    _, after = calibrate_markers(human, marker_names, pos, val, iterations=2, stride=max(1, len(pos) // 15))
    placements = {n: human.model.frames[f].placement.translation.tolist() for n, f in human.marker_frames.items()}
    return StreamCalibration(dict(fitted.lengths), placements, len(pos), before, after, subject.height_m, subject.sex)


def static_frames(positions: np.ndarray, valid: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The first ``n`` frames with enough markers for a calibration (as the stream itself takes them)."""
    keep = [k for k in range(len(positions)) if np.sum(valid[k]) >= CALIBRATION_MIN_MARKERS][:n]
    return np.asarray(positions)[keep], np.asarray(valid)[keep]

