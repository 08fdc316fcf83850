"""Per-frame skeleton fit to labelled markers (inverse kinematics on marker positions).

Damped Gauss-Newton on the marker errors, with a weak pull toward a reference posture for what the markers do not
see, joint limits, and a warm start from the previous frames. Units SI, lab frame REP-103.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import Sit2StandError
from ..kinematics import PointJacobians, positions
from .skeleton import HumanModel

PELVIS_MARKERS = ("LASI", "RASI", "LPSI", "RPSI")
MIN_MARKERS = 8
"""Fewest skeleton markers a frame needs (3 of them on the pelvis) to be fitted."""


class TooFewMarkers(Sit2StandError, ValueError):
    """The marker set cannot constrain the skeleton; the message lists what is there and what is needed."""


class MarkerUnitsError(Sit2StandError, ValueError):
    """The markers' spread does not fit a body of the subject's stature in metres; the message names the likely
    unit."""


BODY_SPAN_RANGE = (0.2, 3.0)
"""Plausible span of one frame's markers (bounding-box diagonal) over the stature: seated, standing, arms out."""
UNIT_FACTORS = {"millimetres": 1000.0, "centimetres": 100.0, "inches": 39.37}


def check_marker_units(positions: np.ndarray, valid: np.ndarray, height_m: float, source: str) -> None:
    """Check that one frame's markers (M, 3) span a body of ``height_m`` in metres.

    Raises:
        MarkerUnitsError: they do not; the message names ``source`` (the file or topic), the span and the unit the
            numbers most likely are in.
    """
    pts = np.asarray(positions, float)[np.asarray(valid, bool)]
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < MIN_MARKERS:
        return
    span = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    ratio = span / height_m
    if BODY_SPAN_RANGE[0] <= ratio <= BODY_SPAN_RANGE[1]:
        return
    unit = min(UNIT_FACTORS, key=lambda u: abs(np.log(ratio / UNIT_FACTORS[u]))) if ratio > 1 else "not metres"
    raise MarkerUnitsError(f"{source}: the markers of one frame span {span:.4g} for a {height_m:g} m subject "
                           f"({ratio:.3g} x the stature); the positions look like {unit}, not metres "
                           f"(convert them, or check the subject's stature)")


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
        for it in range(1, max_iter + 1):  # noqa: B007 (the count is reported after the loop)
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



def bridge_skipped(model: pin.Model, q_raw: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Fill frames that could not be fitted (``ok`` False) by interpolating tangent coordinates between the
    fitted neighbours. ``q_raw`` (N, nq); returns a new (N, nq) array."""
    if ok.all():
        return q_raw
    ref = q_raw[np.argmax(ok)]
    x = np.array([pin.difference(model, ref, q) for q in q_raw])
    for j in range(x.shape[1]):
        x[~ok, j] = np.interp(np.flatnonzero(~ok), np.flatnonzero(ok), x[ok, j])
    return np.array([pin.integrate(model, ref, xi) for xi in x])
