"""Human centre-of-mass estimation from markers and force plates, with COP-matched segment-mass scaling.

Pipeline (the paper's section on the human COM, with the scaling done automatically):

1. :class:`MarkerIK` fits the skeleton to each frame's valid markers (damped Gauss-Newton on marker errors, a weak
   pull toward a reference posture for what the markers do not see, joint limits, warm start).
2. :func:`calibrate_lengths` scales segment lengths to the markers (nested least squares over a few frames).
3. :func:`smooth_motion` smooths the fitted motion (Savitzky-Golay, ~8 Hz) and differentiates it; the plate wrench
   is smoothed the same way, so kinematics and forces share one bandwidth (as inverse dynamics needs).
4. :func:`mass_scaling_rows` turns each frame into 6 equations linear in the segment masses (and the torso's COM
   shift): the measured external wrench equals the floating-base rows of the joint-torque regressor
   Y(q, v, a) pi. :func:`solve_mass_scaling` solves them as constrained least squares: masses within plausible
   bounds, left = right, summing to the body mass, pulled weakly toward de Leva. Matching the wrench's moment is
   matching the COP: the model COP from COM and centroidal dynamics then agrees with the measured COP.
5. COM position, velocity and acceleration follow from the scaled model.

Units SI, lab frame REP-103. Only frames whose whole weight is on the plates enter the scaling (both plates, or
the feet plate after seat-off when the chair has none).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from scipy.signal import savgol_coeffs   # at import time: the first frame must not pay for it

from ..dynamics import model_cop, savgol_series, smooth_motion
from ..io.forceplate import center_of_pressure
from ..kinematics import PointJacobians, positions
from ..optim import constrained_lsq   # imports proxsuite now: the first re-solve must not pay for it mid-stream
from .skeleton import LENGTH_GROUPS, SEGMENTS, HumanModel, Subject, build_human

G = 9.81
PELVIS_MARKERS = ("LASI", "RASI", "LPSI", "RPSI")
MIN_MARKERS = 8
STREAM_FIT_STEPS = 3      # Gauss-Newton steps per streamed frame (warm-started)
MASS_GROUPS = ["pelvis", "torso", "head", "upper_arm", "forearm", "hand", "thigh", "shank", "foot", "toes"]


class TooFewMarkers(ValueError):
    """The marker set cannot constrain the skeleton; the message lists what is there and what is needed."""


@dataclass
class FrameFit:
    q: np.ndarray
    rms_m: float
    n_markers: int
    iterations: int
    ok: bool


class MarkerIK:
    """Per-frame skeleton fit to labelled markers (Plug-in-Gait names; unknown names are ignored).

    Args:
        human: the skeleton.
        marker_names: the stream's marker names, in its order.
        posture_weight: weight of the pull toward ``q_ref`` relative to 1 m^-2 of marker error per marker.
    """

    def __init__(self, human: HumanModel, marker_names: list[str], posture_weight: float = 1e-3,
                 q_ref: np.ndarray | None = None) -> None:
        self.human = human
        self.model = human.model
        self.data = self.model.createData()
        self.stream_index = [i for i, n in enumerate(marker_names) if n in human.marker_frames]
        self.frames = [human.marker_frames[marker_names[i]] for i in self.stream_index]
        known = [marker_names[i] for i in self.stream_index]
        if len(known) < MIN_MARKERS or sum(n in known for n in PELVIS_MARKERS) < 3:
            raise TooFewMarkers(
                f"{len(known)} of the stream's {len(marker_names)} markers are Plug-in-Gait markers the skeleton "
                f"carries ({', '.join(known) or 'none'}); at least {MIN_MARKERS} are needed, including 3 of "
                f"{', '.join(PELVIS_MARKERS)}")
        self.used_names = known
        self.posture_weight = posture_weight
        self.q_ref = pin.neutral(self.model) if q_ref is None else q_ref.copy()
        self.lo, self.hi = self.model.lowerPositionLimit.copy(), self.model.upperPositionLimit.copy()
        self.q: np.ndarray | None = None
        self._q_prev: np.ndarray | None = None
        self.points = PointJacobians(self.model)

    def _marker_positions(self, q: np.ndarray) -> np.ndarray:
        pin.framesForwardKinematics(self.model, self.data, q)
        return positions(self.data, self.frames)

    def initial_guess(self, positions: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Pelvis pose by a Kabsch fit of the pelvis markers; the rest at the reference posture."""
        q = self.q_ref.copy()
        names = self.used_names
        idx = [k for k, n in enumerate(names) if n in PELVIS_MARKERS and valid[k]]
        model_pts = self._marker_positions(pin.neutral(self.model))[idx]
        meas = positions[idx]
        mc, sc = model_pts.mean(axis=0), meas.mean(axis=0)
        U, _, Vt = np.linalg.svd((model_pts - mc).T @ (meas - sc))
        D = np.diag([1, 1, np.sign(np.linalg.det(Vt.T @ U.T))])
        R = Vt.T @ D @ U.T
        q[:3] = sc - R @ mc
        q[3:7] = pin.Quaternion(R).coeffs()
        return q

    def fit(self, positions_m: np.ndarray, valid: np.ndarray, q0: np.ndarray | None = None,
            max_iter: int = 12, tol: float = 1e-5) -> FrameFit:
        """Fit one frame. ``positions_m``/``valid`` are in the stream's marker order (all names, as received)."""
        pos = np.asarray(positions_m, float)[self.stream_index]
        ok = np.asarray(valid, bool)[self.stream_index] & np.all(np.isfinite(pos), axis=1)
        n_ok = int(ok.sum())
        if n_ok < MIN_MARKERS or sum(ok[k] for k, n in enumerate(self.used_names) if n in PELVIS_MARKERS) < 3:
            return FrameFit(self.q if self.q is not None else self.q_ref, float("nan"), n_ok, 0, False)
        if q0 is None and self.q is not None and self._q_prev is not None:
            # constant-velocity prediction from the last two fits: fewer iterations when streaming
            q0 = pin.integrate(self.model, self.q, pin.difference(self.model, self._q_prev, self.q))
        q = q0 if q0 is not None else (self.q if self.q is not None else self.initial_guess(pos, ok))
        q = q.copy()
        q[7:] = np.clip(q[7:], self.lo[7:], self.hi[7:])
        model, data, nv = self.model, self.data, self.model.nv
        w_post = self.posture_weight
        it = 0
        damping = 1e-6
        eye = np.eye(nv)
        for it in range(1, max_iter + 1):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            P, Jm = self.points(data, self.frames)
            J = Jm[ok].reshape(-1, nv)
            r = (P[ok] - pos[ok]).ravel()
            e_post = pin.difference(model, self.q_ref, q)
            e_post[:6] = 0.0  # the floating base is free
            H = J.T @ J + (w_post + damping) * eye
            grad = J.T @ r + w_post * e_post
            dq = -np.linalg.solve(H, grad)
            q = pin.integrate(model, q, dq)
            q[7:] = np.clip(q[7:], self.lo[7:], self.hi[7:])
            if np.max(np.abs(dq)) < tol:
                break
        err = self._marker_positions(q)[ok] - pos[ok]
        self._q_prev = self.q
        self.q = q
        return FrameFit(q, float(np.sqrt(np.mean(np.sum(err**2, axis=1)))), n_ok, it, True)


def fit_sequence(ik: MarkerIK, positions: np.ndarray, valid: np.ndarray, progress=None) -> list[FrameFit]:
    """Fit every frame, warm-started from the previous good one. positions (N, M, 3), valid (N, M)."""
    fits = []
    for k in range(len(positions)):
        first = ik.q is None
        fit = ik.fit(positions[k], valid[k], max_iter=60 if first else 12)
        fits.append(fit)
        if progress is not None:
            progress(k + 1, len(positions))
    return fits


def calibrate_lengths(subject: Subject, marker_names: list[str], positions: np.ndarray, valid: np.ndarray,
                      n_frames: int = 10, max_nfev: int = 60) -> tuple[Subject, float, float]:
    """Segment length factors that best fit the markers, over ``n_frames`` frames spread over the trial.

    Returns (subject with fitted ``lengths``, marker RMS before [m], after [m]). Factors are bounded to 0.6..1.6 (children and adults).
    """
    from scipy.optimize import least_squares

    good = [k for k in range(len(positions)) if np.sum(valid[k]) >= MIN_MARKERS + 4]
    picks = [good[i] for i in np.linspace(0, len(good) - 1, min(n_frames, len(good))).astype(int)]
    groups = list(LENGTH_GROUPS)
    warm: dict[int, np.ndarray] = {}

    def residuals(x: np.ndarray) -> np.ndarray:
        subj = Subject(subject.height_m, subject.mass_kg, subject.sex, dict(zip(groups, x)), dict(subject.masses),
                       list(subject.extra))
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
    rms = lambda r: float(np.sqrt(np.mean(r[:n_m] ** 2) * 3))  # noqa: E731 - per-marker distance RMS
    fitted = Subject(subject.height_m, subject.mass_kg, subject.sex, dict(zip(groups, map(float, sol.x))),
                     dict(subject.masses), list(subject.extra))
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
        """The calibrated subject and skeleton (markers moved to their calibrated placements). Raises ValueError
        if it was made for another stature or sex."""
        if np.isfinite(self.height_m) and abs(self.height_m - subject.height_m) > 1e-6 or \
                self.sex and self.sex != subject.sex:
            raise ValueError(f"the calibration is for a {self.height_m:g} m {self.sex}, the subject is a "
                             f"{subject.height_m:g} m {subject.sex}")
        subj = Subject(subject.height_m, subject.mass_kg, subject.sex, dict(self.lengths), dict(subject.masses),
                       list(subject.extra))
        human = build_human(subj)
        for name, p in self.marker_placements_m.items():
            fid = human.marker_frames.get(name)
            if fid is not None:
                old = human.model.frames[fid].placement
                human.model.frames[fid].placement = pin.SE3(old.rotation, np.asarray(p, float))
        return subj, human

    def save(self, path) -> None:
        import yaml

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
        import yaml

        try:
            with open(path) as f:
                doc = yaml.safe_load(f) or {}
            return cls({str(k): float(v) for k, v in doc["lengths"].items()},
                       {str(k): [float(x) for x in v] for k, v in doc["marker_placements_m"].items()},
                       int(doc.get("frames", 0)), float(doc.get("marker_rms_before_m", "nan")),
                       float(doc.get("marker_rms_after_m", "nan")), float(doc.get("height_m", "nan")),
                       str(doc.get("sex", "")))
        except OSError as err:
            raise ValueError(f"{path}: cannot read the calibration: {err}") from None
        except (KeyError, TypeError, ValueError, AttributeError, yaml.YAMLError) as err:
            raise ValueError(f"{path}: not a skeleton calibration (needs lengths and marker_placements_m): "
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
    keep = [k for k in range(len(positions)) if np.sum(valid[k]) >= MIN_MARKERS + 4][:n]
    return np.asarray(positions)[keep], np.asarray(valid)[keep]


# ---------------------------------------------------------------------------------------------------------------
# smoothing and differentiation (the same filter offline and live)
# ---------------------------------------------------------------------------------------------------------------

def plate_wrench_at(times_s: np.ndarray, plates: list[dict], half_width_s: float) -> tuple[np.ndarray, np.ndarray,
                                                                                          np.ndarray]:
    """Summed plate force (N, 3) and moment about the origin (N, 3) averaged over +-half_width around each time,
    and a coverage flag (N,) False where any plate has no sample there (a plate that dropped out)."""
    n = len(times_s)
    force, moment = np.zeros((n, 3)), np.zeros((n, 3))
    covered = np.ones(n, bool)
    for plate in plates:
        t = plate["t_s"]
        lo = np.searchsorted(t, times_s - half_width_s)
        hi = np.searchsorted(t, times_s + half_width_s, side="right")
        csum_f = np.vstack([np.zeros(3), np.cumsum(np.nan_to_num(plate["force_n"]), axis=0)])
        csum_m = np.vstack([np.zeros(3), np.cumsum(np.nan_to_num(plate["moment_nm"]), axis=0)])
        bad = np.concatenate([[0], np.cumsum(~np.all(np.isfinite(plate["force_n"]), axis=1))])
        count = hi - lo
        has = (count > 0) & (bad[hi] - bad[lo] == 0)
        covered &= has
        cnt = np.maximum(count, 1)[:, None]
        force += np.where(has[:, None], (csum_f[hi] - csum_f[lo]) / cnt, 0.0)
        moment += np.where(has[:, None], (csum_m[hi] - csum_m[lo]) / cnt, 0.0)
    return force, moment, covered


# ---------------------------------------------------------------------------------------------------------------
# COP-matched mass scaling
# ---------------------------------------------------------------------------------------------------------------

@dataclass
class MassScaling:
    """Segment masses [kg] (left = right), the torso's COM shift (x, y) [m, torso frame] and the fit's figures."""

    masses: dict[str, float]
    torso_com_shift_m: np.ndarray
    prior_masses: dict[str, float]
    cop_rms_before_m: float = float("nan")
    cop_rms_after_m: float = float("nan")
    condition_number: float = float("nan")
    frames_used: int = 0

    def factors(self) -> dict[str, float]:
        return {g: self.masses[g] / self.prior_masses[g] for g in self.masses}


def _group_of(segment: str) -> str:
    return segment[:-2] if segment[-2:] in ("_l", "_r") else segment


def apply_scaling(human: HumanModel, scaling: MassScaling) -> pin.Model:
    """A copy of the skeleton's model with the scaled masses (inertias scale with mass) and torso COM shift."""
    model = human.model.copy()
    for seg in SEGMENTS:
        j = human.segment_joint[seg]
        old = model.inertias[j]
        k = scaling.masses[_group_of(seg)] / scaling.prior_masses[_group_of(seg)]
        lever = old.lever.copy() + (scaling.torso_com_shift_m if seg == "torso" else 0.0)
        model.inertias[j] = pin.Inertia(old.mass * k, lever, old.inertia * k)
    return model


def mass_scaling_rows(human: HumanModel, q: np.ndarray, v: np.ndarray, a: np.ndarray, force_n: np.ndarray,
                      moment_origin_nm: np.ndarray, data: pin.Data | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Six equations A theta = b of one frame; theta = (group masses [kg] ..., torso m*dx, m*dy [kg m]).

    The measured external wrench (lab axes, about the lab origin) is expressed in the pelvis frame and equated to
    the floating-base rows of the joint-torque regressor, with each segment's parameters scaled by its mass.
    """
    model = human.model
    data = data or model.createData()
    Y = pin.computeJointTorqueRegressor(model, data, q, v, a)[:6]     # (6, 10 * (njoints - 1))
    n_theta = len(MASS_GROUPS) + 2
    A = np.zeros((6, n_theta))
    for seg in SEGMENTS:
        j = human.segment_joint[seg]
        block = Y[:, 10 * (j - 1): 10 * j]
        inertia = model.inertias[j]
        pi_unit = inertia.toDynamicParameters() / inertia.mass
        A[:, MASS_GROUPS.index(_group_of(seg))] += block @ pi_unit
        if seg == "torso":
            A[:, -2] += block[:, 1]   # first moment along torso x (forward)
            A[:, -1] += block[:, 2]   # first moment along torso y (left)
    oMb = pin.SE3(pin.Quaternion(q[3:7]).normalized().matrix(), q[:3])
    w = pin.Force(np.asarray(force_n, float), np.asarray(moment_origin_nm, float))
    b = oMb.actInv(w).vector
    return A, b


def static_rows(human: HumanModel, q: np.ndarray, cop_xy: np.ndarray, body_mass_kg: float,
                data: pin.Data | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Two equations (x, y) of a quasi-static frame: the COM lies above the measured COP, M g c = M g COP, in the
    unknowns of :func:`mass_scaling_rows` (scaled by g to N m, like its moment rows). A tilted or cross-talking
    plate force cannot bias these, unlike the full dynamic rows."""
    model = human.model
    data = data or model.createData()
    pin.forwardKinematics(model, data, q)
    A = np.zeros((2, len(MASS_GROUPS) + 2))
    for seg in SEGMENTS:
        j = human.segment_joint[seg]
        c = data.oMi[j].act(model.inertias[j].lever)
        A[:, MASS_GROUPS.index(_group_of(seg))] += G * c[:2]
        if seg == "torso":
            R = data.oMi[j].rotation
            A[:, -2] += G * R[:2, 0]
            A[:, -1] += G * R[:2, 1]
    return A, G * body_mass_kg * np.asarray(cop_xy, float)[:2]


@dataclass
class FrameRows:
    """One supported frame's equations: the six dynamic rows, the quasi-static alternative (world vertical force
    and COM over COP), and the COM acceleration [m/s^2] that decides between them."""

    acc: float
    dynamic: tuple[np.ndarray, np.ndarray]
    static: tuple[np.ndarray, np.ndarray] | None


def frame_rows(human: HumanModel, q: np.ndarray, v: np.ndarray, a: np.ndarray, force_n: np.ndarray,
               moment_nm: np.ndarray, cop_m: np.ndarray, body_mass_kg: float,
               data: pin.Data | None = None) -> FrameRows:
    """The equations of one supported frame (see :class:`FrameRows`)."""
    data = data or human.model.createData()
    A6, b6 = mass_scaling_rows(human, q, v, a, force_n, moment_nm, data)
    pin.centerOfMass(human.model, data, q, v, a)
    acc = float(np.linalg.norm(data.acom[0]))
    static = None
    if np.all(np.isfinite(cop_m)):
        R = pin.Quaternion(q[3:7]).normalized().matrix()
        As, bs = static_rows(human, q, cop_m, body_mass_kg, data)
        static = (np.vstack([(R[2] @ A6[:3])[None, :], As]), np.concatenate([[R[2] @ b6[:3]], bs]))
    return FrameRows(acc, (A6, b6), static)


def assemble_rows(rows: list[FrameRows], quasi_static_acc: float = 0.15, quiet_fraction: float = 0.4,
                  force_sd_n: float = 5.0, moment_sd_nm: float = 2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stack frames' equations with weights. Quasi-static frames use the static alternative: |a_com| below
    ``quasi_static_acc``, or among the quietest ``quiet_fraction`` of all the frames given (a short recording may
    never be quite still)."""
    accs = np.array([r.acc for r in rows])
    limit = max(quasi_static_acc, float(np.quantile(accs, quiet_fraction))) if len(accs) else quasi_static_acc
    A_rows, b_rows, w_rows = [], [], []
    for r in rows:
        if r.acc <= limit and r.static is not None:
            A_rows.append(r.static[0])
            b_rows.append(r.static[1])
            w_rows.append(np.array([1 / force_sd_n, 1 / moment_sd_nm, 1 / moment_sd_nm]))
        else:
            A_rows.append(r.dynamic[0])
            b_rows.append(r.dynamic[1])
            w_rows.append(np.array([1 / force_sd_n] * 3 + [1 / moment_sd_nm] * 3))
    return np.vstack(A_rows), np.concatenate(b_rows), np.concatenate(w_rows)


def solve_mass_scaling(human: HumanModel, A: np.ndarray, b: np.ndarray, body_mass_kg: float,
                       bounds: tuple[float, float] = (0.5, 2.0), prior_sd: float = 0.2,
                       max_torso_shift_m: float = 0.12, force_sd_n: float = 5.0,
                       moment_sd_nm: float = 2.0, weights: np.ndarray | None = None) -> MassScaling:
    """Constrained least squares for the group masses and torso COM shift (rows stacked from many frames).

    ``weights`` (one per row) default to blocks of six dynamic rows: 1/force_sd_n for forces, 1/moment_sd_nm for
    moments; :func:`assemble_rows` builds mixed dynamic / quasi-static rows with their weights.
    """

    prior = {g: 0.0 for g in MASS_GROUPS}
    count = {g: 0 for g in MASS_GROUPS}
    for seg in SEGMENTS:
        g = _group_of(seg)
        prior[g] += human.model.inertias[human.segment_joint[seg]].mass
        count[g] += 1
    per_seg = np.array([prior[g] / count[g] for g in MASS_GROUPS])
    mult = np.array([count[g] for g in MASS_GROUPS], float)
    torso_m = per_seg[MASS_GROUPS.index("torso")]
    # unknowns are per-segment masses of each group (left = right): A's group column is already the sum over
    # the group's segments of their unit-mass contributions, so it multiplies the per-segment mass as it is
    A_seg = A
    x_prior = np.concatenate([per_seg, [0.0, 0.0]])
    prior_w = np.concatenate([1.0 / (prior_sd * per_seg), [1.0 / (0.05 * torso_m)] * 2])
    E = np.concatenate([mult, [0.0, 0.0]])[None, :]
    # the torso COM may move forward/back (a backpack, a belly) and sideways (asymmetry, unmarked arms held to one
    # side); its vertical shift would trade off against the masses and is not estimated
    lb = np.concatenate([bounds[0] * per_seg, [-max_torso_shift_m * torso_m * 2] * 2])
    ub = np.concatenate([bounds[1] * per_seg, [max_torso_shift_m * torso_m * 2] * 2])
    if weights is None:
        weights = np.tile([1 / force_sd_n] * 3 + [1 / moment_sd_nm] * 3, len(b) // 6)
    res = constrained_lsq(A_seg, b, weights=weights, E=E, e=np.array([body_mass_kg]), lb=lb, ub=ub,
                          prior=x_prior, prior_weights=prior_w)
    masses = {g: float(res.x[i]) * mult[i] for i, g in enumerate(MASS_GROUPS)}
    m_torso = res.x[MASS_GROUPS.index("torso")]
    shift = np.array([res.x[-2] / m_torso, res.x[-1] / m_torso, 0.0])
    return MassScaling(masses, shift, {g: prior[g] for g in MASS_GROUPS}, condition_number=res.condition_number,
                       frames_used=int(np.sum(weights > 0) // 3))


def _model_series(model: pin.Model, qs: np.ndarray, vs: np.ndarray, as_: np.ndarray):
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


def estimate_com(marker_t_s: np.ndarray, marker_names: list[str], positions: np.ndarray, valid: np.ndarray,
                 plates: list[dict], subject: Subject, *, calibrate: bool = True, scale_masses: bool = True,
                 chair_on_plate: bool = True, window: int = 31, trust_plate_mass: bool = True,
                 quasi_static_acc: float = 0.15,
                 progress=None) -> ComResult:
    """Offline COM estimation of a whole trial (see the module docstring). ``plates``: dicts with ``name``,
    ``t_s`` (K,), ``force_n`` (K, 3), ``moment_nm`` (K, 3, about the lab origin)."""
    dt = float(np.median(np.diff(marker_t_s)))
    rms_before = rms_after = float("nan")   # marker RMS of the default model, and after lengths + placements
    if calibrate:
        subject, rms_before, _ = calibrate_lengths(subject, marker_names, positions, valid)
    human = build_human(subject)
    if calibrate:
        _, rms_after = calibrate_markers(human, marker_names, positions, valid)
    ik = MarkerIK(human, marker_names)
    fits = fit_sequence(ik, positions, valid, progress)
    ok = np.array([f.ok for f in fits])
    if ok.sum() < window:
        raise TooFewMarkers(f"only {ok.sum()} frames could be fitted (need {window}); check the marker set")
    q_raw = np.array([f.q for f in fits])
    # bridge skipped frames by interpolating tangent coordinates from the neighbours
    if not ok.all():
        ref = q_raw[np.argmax(ok)]
        x = np.array([pin.difference(human.model, ref, q) for q in q_raw])
        for j in range(x.shape[1]):
            x[~ok, j] = np.interp(np.flatnonzero(~ok), np.flatnonzero(ok), x[ok, j])
        q_raw = np.array([pin.integrate(human.model, ref, xi) for xi in x])
    qs, vs, as_ = smooth_motion(human.model, q_raw, dt, window)

    force, moment, covered = plate_wrench_at(marker_t_s, plates, dt / 2)
    w_eff = min(window, len(force) - (1 - len(force) % 2))
    force = savgol_series(force, w_eff, 4, 0)     # the same filter as the kinematics: one bandwidth for both
    moment = savgol_series(moment, w_eff, 4, 0)
    gaps = _plate_gaps(marker_t_s, plates, dt)
    weight = subject.mass_kg * G
    fz_ok = (force[:, 2] > 0.3 * weight) & (force[:, 2] < 3.0 * weight)
    if chair_on_plate:
        supported = covered & fz_ok
    else:  # the chair is not on a plate: only after the feet first carry (nearly) the whole weight
        first = np.argmax(force[:, 2] >= 0.9 * weight) if np.any(force[:, 2] >= 0.9 * weight) else len(force)
        supported = covered & fz_ok & (np.arange(len(force)) >= first)
    half = window // 2
    supported[:half] = supported[-half:] = False   # edge frames: the smoother extrapolates there
    notes: list[str] = []
    plate_mass = body_mass_from_plates(force, supported, qs, human, dt)
    if plate_mass is not None and trust_plate_mass:
        rel = plate_mass / subject.mass_kg - 1.0
        if abs(rel) > 0.05:
            notes.append(f"the plates weigh the subject at {plate_mass:.2f} kg in quiet support, {100 * rel:+.1f} % "
                         f"from the given {subject.mass_kg:g} kg; using the plates' value")
            subject = Subject(subject.height_m, plate_mass, subject.sex, dict(subject.lengths), dict(subject.masses),
                              list(subject.extra))
            human = build_human(subject)
            for name, fid in ik.human.marker_frames.items():   # keep the calibrated marker placements
                human.model.frames[human.marker_frames[name]].placement = ik.human.model.frames[fid].placement

    data = human.model.createData()
    measured_cop = np.full((len(qs), 3), np.nan)
    for k in range(len(qs)):
        if covered[k]:
            measured_cop[k], _, _ = center_of_pressure(force[k], moment[k], np.zeros(3), np.array([0, 0, 1.0]),
                                                       threshold_n=1.0)
    com_unscaled, _, _, cop_unscaled = _model_series(human.model, qs, vs, as_)

    if scale_masses and supported.sum() >= 10:
        rows = [frame_rows(human, qs[k], vs[k], as_[k], force[k], moment[k], measured_cop[k], subject.mass_kg, data)
                for k in np.flatnonzero(supported)]
        A_rows, b_rows, w_rows = assemble_rows(rows, quasi_static_acc)
        scaling = solve_mass_scaling(human, A_rows, b_rows, subject.mass_kg, weights=w_rows)
        model = apply_scaling(human, scaling)
    else:
        prior = {}
        for seg in SEGMENTS:
            prior[_group_of(seg)] = prior.get(_group_of(seg), 0.0) + human.model.inertias[human.segment_joint[seg]].mass
        scaling = MassScaling(dict(prior), np.zeros(3), dict(prior))
        model = human.model
    com, vcom, acom, cop_model = _model_series(model, qs, vs, as_)
    sel = supported & np.all(np.isfinite(measured_cop), axis=1)
    dist = lambda c: float(np.sqrt(np.mean(np.sum((c[sel, :2] - measured_cop[sel, :2]) ** 2, axis=1))))  # noqa
    scaling.cop_rms_before_m = dist(cop_unscaled) if sel.any() else float("nan")
    scaling.cop_rms_after_m = dist(cop_model) if sel.any() else float("nan")
    return ComResult(marker_t_s, com, vcom, acom, com_unscaled,
                     cop_model, measured_cop, supported, ok, np.array([f.rms_m for f in fits]),
                     np.array([f.n_markers for f in fits]), scaling, subject, rms_before, rms_after, gaps, qs, notes,
                     vs, as_, force, moment, human.model)


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


def _plate_gaps(times_s: np.ndarray, plates: list[dict], dt: float) -> list[tuple[str, float, float]]:
    """(plate, start, end) of each stretch of marker frames with no sample (or NaN samples) of that plate."""
    gaps = []
    for plate in plates:
        _, _, covered = plate_wrench_at(times_s, [plate], dt / 2)
        k = 0
        while k < len(covered):
            if not covered[k]:
                j = k
                while j + 1 < len(covered) and not covered[j + 1]:
                    j += 1
                gaps.append((plate["name"], float(times_s[k]), float(times_s[j])))
                k = j + 1
            else:
                k += 1
    return gaps


# ---------------------------------------------------------------------------------------------------------------
# streaming (the node's core; pure, so it is tested without ROS)
# ---------------------------------------------------------------------------------------------------------------

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
    velocity/acceleration published are from a causal Savitzky-Golay fit over the last ``window`` frames; the
    scaling uses the centred fit of the frame ``window // 2`` back, as the offline estimator does.
    """

    def __init__(self, subject: Subject, marker_names: list[str], *, rate_hz: float = 100.0, window: int = 31,
                 calibration_frames: int = 50, rescale_every: int = 100, chair_on_plate: bool = True,
                 min_frames_to_scale: int = 30, first_rescale: int = 100,
                 calibration: StreamCalibration | None = None, defer_rescale: bool = False) -> None:
        self.subject = subject
        self.marker_names = list(marker_names)
        self.dt = 1.0 / rate_hz
        self.window = window | 1
        self.calibration_frames = calibration_frames
        self.rescale_every = rescale_every
        self.chair_on_plate = chair_on_plate
        self.min_frames_to_scale = min_frames_to_scale
        self.first_rescale = first_rescale
        self.human = build_human(subject)
        self.ik = MarkerIK(self.human, self.marker_names)   # raises TooFewMarkers early
        self.model = self.human.model
        self.data = self.model.createData()
        self.calibrated = calibration_frames <= 0
        self._calib: list[tuple[np.ndarray, np.ndarray]] = []
        self._t: list[float] = []
        self._q: list[np.ndarray] = []
        self._plates: dict[str, dict[str, list]] = {}
        self.rows: list[FrameRows] = []
        self._x: list[np.ndarray] = []       # tangent coordinates of each frame (see smooth_motion)
        self._R0: np.ndarray | None = None
        self.scaling: MassScaling | None = None
        self.scaled_model = self.model
        self.scaled_data = self.model.createData()
        self.frames = 0
        self.plate_gaps: dict[str, int] = {}
        self._seat_off_seen = chair_on_plate
        self._coeffs: dict[tuple[int, int], list[np.ndarray]] = {}
        self._pending: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        # a re-solve of the masses costs ~10 ms: a live caller may defer it past the frame's publication
        # (``rescale_pending``, then :meth:`rescale`); the frame's own COM never depends on it
        self.defer_rescale = defer_rescale
        self.rescale_pending = False
        self.calibration: StreamCalibration | None = None
        if calibration is not None:       # calibrated beforehand: no pause in the stream
            self._use(calibration)

    # -- inputs ------------------------------------------------------------------------------------------------
    def expect_plate(self, name: str) -> None:
        """Declare a plate that must have data for a frame to count (before its first sample arrives)."""
        self._plates.setdefault(name, {"data": np.empty((4096, 7)), "n": 0})

    def add_plate_samples(self, name: str, t_s: np.ndarray, force_n: np.ndarray, moment_nm: np.ndarray) -> None:
        """Append force-plate samples (times [s], force [N] and moment about the lab origin [N m], (K, 3))."""
        t = np.atleast_1d(np.asarray(t_s, float))
        rows = np.hstack([t[:, None], np.atleast_2d(force_n), np.atleast_2d(moment_nm)])
        buf = self._plates.get(name)
        if buf is None:
            buf = self._plates[name] = {"data": np.empty((max(4096, 2 * len(rows)), 7)), "n": 0}
        n = buf["n"]
        if n + len(rows) > len(buf["data"]):
            t_min = (self._t[-1] if self._t else t[0]) - 2.0      # keep ~2 s behind the newest marker frame
            keep = buf["data"][:n][buf["data"][:n, 0] > t_min]
            size = max(len(buf["data"]), 2 * (len(keep) + len(rows)))
            buf["data"] = np.vstack([keep, np.empty((size - len(keep), 7))])
            n = buf["n"] = len(keep)
        buf["data"][n:n + len(rows)] = rows
        buf["n"] = n + len(rows)

    def update(self, t_s: float, positions_m: np.ndarray, valid: np.ndarray,
               defer_delayed: bool = False) -> StreamOutput:
        """One marker frame (positions [m], validity, in the stream's marker order) at ``t_s`` [s]: the fit and the
        causal COM, then the delayed work (the centred window half a window back: model and measured COP, scaling
        rows). ``defer_delayed``: leave that to :meth:`process_delayed`, so that a live caller can publish the COM
        first (its model/measured COP then come with that call)."""
        if not self.calibrated:
            if np.sum(valid) >= MIN_MARKERS + 4:
                self._calib.append((np.asarray(positions_m, float).copy(), np.asarray(valid, bool).copy()))
            if len(self._calib) >= self.calibration_frames:
                self._calibrate()
        # warm-started from the last two fits: 3 Gauss-Newton steps; more moved the COM by < 0.01 mm on both
        # shipped demonstrations while costing ~0.3 ms each (the first fit gets 40)
        fit = self.ik.fit(positions_m, valid, max_iter=STREAM_FIT_STEPS if self.ik.q is not None else 40)
        self.frames += 1
        if not fit.ok and not self._q:
            nan3 = np.full(3, np.nan)
            return StreamOutput(t_s, False, fit.q, nan3, nan3, nan3, fit.rms_m, fit.n_markers)
        q = fit.q if fit.ok else self._q[-1]
        self._t.append(t_s)
        self._q.append(q.copy())
        self._x.append(self._coords(q))
        keep = 2 * self.window
        if len(self._q) > keep:
            del self._t[:-keep], self._q[:-keep], self._x[:-keep]
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
        self._q.clear()
        self._t.clear()
        self._x.clear()
        self.calibrated = True

    def _coords(self, q: np.ndarray) -> np.ndarray:
        """Decoupled coordinates of smooth_motion: base position, base rotation vector about R0, joint angles."""
        R = pin.Quaternion(q[3:7]).normalized().matrix()
        if self._R0 is None:
            self._R0 = R
        return np.concatenate([q[:3], pin.log3(self._R0.T @ R), q[7:]])

    def _savgol(self, pos: int, length: int) -> list[np.ndarray]:
        """Savitzky-Golay weights (position, first and second derivative) at sample ``pos`` of ``length``, cached."""
        key = (pos, length)
        if key not in self._coeffs:
            order = min(4, length - 2)
            self._coeffs[key] = [savgol_coeffs(length, order, deriv=d, pos=pos, use="dot") / self.dt**d
                                 for d in (0, 1, 2)]
        return self._coeffs[key]

    def _derivatives_at(self, pos: int, length: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, v, a of the window's sample ``pos`` from a Savitzky-Golay fit of the last ``length`` frames."""
        X = np.array(self._x[-length:])
        xs, xd, xdd = (c @ X for c in self._savgol(pos, length))
        r, rd, rdd = xs[3:6], xd[3:6], xdd[3:6]
        R = self._R0 @ pin.exp3(r)
        q = np.concatenate([xs[:3], pin.Quaternion(R).coeffs(), xs[6:]])
        Jr = pin.Jexp3(r)
        h = 1e-4
        dJr = (pin.Jexp3(r + h * rd) - pin.Jexp3(r - h * rd)) / (2 * h)
        w = Jr @ rd
        v_lin = R.T @ xd[:3]
        v = np.concatenate([v_lin, w, xd[6:]])
        a = np.concatenate([R.T @ xdd[:3] - np.cross(w, v_lin), Jr @ rdd + dJr @ rd, xdd[6:]])
        return q, v, a

    def _causal_com(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = len(self._x)
        if n < 7:
            pin.centerOfMass(self.scaled_model, self.scaled_data, self._q[-1])
            return self.scaled_data.com[0].copy(), np.zeros(3), np.zeros(3)
        length = min(self.window, n - (1 - n % 2))
        q, v, a = self._derivatives_at(length - 1, length)
        pin.centerOfMass(self.scaled_model, self.scaled_data, self._q[-1], v, a)
        return self.scaled_data.com[0].copy(), self.scaled_data.vcom[0].copy(), self.scaled_data.acom[0].copy()

    def _delayed(self, out: StreamOutput) -> None:
        """Queue the frame half a window back (its centred derivatives are known now) and process every queued
        frame whose plate samples have all arrived (plates may lag the markers on a busy executor)."""
        n, half = len(self._x), self.window // 2
        if n >= self.window and self.calibrated:
            q_k, v_k, a_k = self._derivatives_at(half, self.window)
            times = np.array(self._t[-self.window:])
            self._pending.append((times, q_k, v_k, a_k))
        while self._pending:
            times, q_k, v_k, a_k = self._pending[0]
            t_k = times[len(times) // 2]
            newest = min((b["data"][b["n"] - 1, 0] if b["n"] else -np.inf for b in self._plates.values()),
                         default=-np.inf)
            if newest < times[-1] + self.dt / 2 and self._t[-1] - t_k < 0.5 and self._plates:
                break                      # plate samples for this window not all here yet
            self._pending.pop(0)
            self._process(out, times, q_k, v_k, a_k)

    def _process(self, out: StreamOutput, times: np.ndarray, q_k: np.ndarray, v_k: np.ndarray,
                 a_k: np.ndarray) -> None:
        t_k = times[len(times) // 2]
        force, moment, covered = self._plate_wrench(times)
        com, _, _, cop_model = model_cop(self.scaled_model, self.scaled_data, q_k, v_k, a_k)
        out.delayed_t_s = t_k
        out.model_cop_m = cop_model
        if not covered:
            return
        cop, ok, _ = center_of_pressure(force, moment, np.zeros(3), np.array([0.0, 0.0, 1.0]), threshold_n=1.0)
        out.measured_cop_m = cop if ok else None
        weight = self.subject.mass_kg * G
        if not self._seat_off_seen and force[2] >= 0.9 * weight:
            self._seat_off_seen = True
        if not (self._seat_off_seen and 0.3 * weight < force[2] < 3.0 * weight) or not ok:
            return
        self.rows.append(frame_rows(self.human, q_k, v_k, a_k, force, moment, cop, self.subject.mass_kg, self.data))
        n = len(self.rows)
        if n >= self.min_frames_to_scale and (n == self.first_rescale or n % self.rescale_every == 0):
            if self.defer_rescale:         # the caller solves it after publishing this frame (see __init__)
                self.rescale_pending = True
            else:
                self.rescale()
                out.rescaled = True

    def rescale(self) -> MassScaling | None:
        """Solve the scaling from all rows so far and switch the COM model to it."""
        if len(self.rows) < self.min_frames_to_scale:
            return None
        A, b, w = assemble_rows(self.rows)
        self.scaling = solve_mass_scaling(self.human, A, b, self.subject.mass_kg, weights=w)
        self.scaled_model = apply_scaling(self.human, self.scaling)
        self.scaled_data = self.scaled_model.createData()
        return self.scaling

    def _plate_wrench(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """Summed plate wrench at the centre of the window's marker ``times``, smoothed by the same centred
        Savitzky-Golay fit as the kinematics; covered is False if a plate has no sample there."""
        plates = []
        for name, b in self._plates.items():      # only the samples around the window (not the 2 s buffer)
            t = b["data"][:b["n"], 0]
            lo, hi = np.searchsorted(t, [times[0] - self.dt, times[-1] + self.dt])
            d = b["data"][lo:hi]
            plates.append({"name": name, "t_s": d[:, 0], "force_n": d[:, 1:4], "moment_nm": d[:, 4:7]})
        if not plates:
            return np.zeros(3), np.zeros(3), False
        force, moment, covered = plate_wrench_at(times, plates, self.dt / 2)
        centre = len(times) // 2
        if not covered[centre]:
            for p in plates:
                if not plate_wrench_at(times[centre:centre + 1], [p], self.dt / 2)[2][0]:
                    self.plate_gaps[p["name"]] = self.plate_gaps.get(p["name"], 0) + 1
            return force[centre], moment[centre], False
        if covered.all():
            c = self._savgol(centre, len(times))[0]
            return c @ force, c @ moment, True
        return force[centre], moment[centre], True
