"""Per-frame skeleton fit to labelled markers (inverse kinematics on marker positions).

Damped Gauss-Newton on the marker errors, with a weak pull toward a reference posture for what the markers do not
see, joint limits, and a warm start from the previous frames. Units SI, lab frame REP-103. A step that raises the
cost is taken back and retried with 10x the damping (Levenberg-Marquardt): from a far start (a walking pose fitted
from the upright reference) plain Gauss-Newton steps overshot into poses 160-210 mm RMS off on OpenSim's subject01,
where the damped ones reach ~31 mm (before calibration); steps that lower the cost are the plain ones, unchanged.

Which markers the skeleton carries, and which of them define the pelvis, is the skeleton's marker set
(:mod:`sit2stand.human.marker_sets`): 3 of Plug-in-Gait's LASI/RASI/LPSI/RPSI, or e.g. both ASIS and a sacral marker.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.linalg import lapack

from .. import native
from ..errors import Sit2StandError
from ..kinematics import PointJacobians
from .marker_sets import MIN_MARKERS, MarkerSetError, load_marker_set
from .skeleton import HumanModel

PELVIS_MARKERS = ("LASI", "RASI", "LPSI", "RPSI")
"""Plug-in-Gait's pelvis markers (the default marker set's; a skeleton's own are ``human.marker_set.pelvis``)."""


MIN_DAMPING = 1e-6
"""Damping of a Gauss-Newton step [m^2 per unit of tangent step]; raised 10x per uphill step, back after a downhill
one."""


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
    """Per-frame skeleton fit to labelled markers (the names of the skeleton's marker set; others are ignored).

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
        self.marker_set = human.marker_set or load_marker_set()
        try:
            self.marker_set.check_stream(list(marker_names))
        except MarkerSetError as err:
            raise TooFewMarkers(str(err)) from None
        self.used_names = known
        rule = self.marker_set.pelvis
        where = {n: k for k, n in enumerate(known)}
        self._pelvis_any3 = np.array([where[n] for n in rule.any_three_of if n in where], int)
        self._pelvis_asis = np.array([where[n] for n in rule.asis if n in where], int)
        self._pelvis_sacral = np.array([where[n] for n in rule.sacral if n in where], int)
        self._pelvis_all = np.array([where[n] for n in rule.markers if n in where], int)
        self._asis_complete = len(rule.asis) > 0 and len(self._pelvis_asis) == len(rule.asis)
        self.posture_weight = posture_weight
        self.q_ref = pin.neutral(self.model) if q_ref is None else q_ref.copy()
        self.lo, self.hi = self.model.lowerPositionLimit.copy(), self.model.upperPositionLimit.copy()
        self.q: np.ndarray | None = None
        self._q_prev: np.ndarray | None = None
        self.points = PointJacobians(self.model)
        self._point_set = self.points.point_set(self.frames)
        nv = self.model.nv           # the markers' terms in C where the kernels are built (None: the NumPy path)
        self._terms = native.MarkerTerms.of(self.data, np.zeros(nv))
        self._H, self._g = np.empty((nv, nv)), np.empty(nv)

    def pelvis_defined(self, ok: np.ndarray) -> bool:
        """True if the valid markers ``ok`` (in :attr:`used_names` order) define the pelvis (the set's rule)."""
        if ok[self._pelvis_any3].sum() >= 3:
            return True
        return self._asis_complete and bool(ok[self._pelvis_asis].all()) and bool(ok[self._pelvis_sacral].any())

    def _posture_error(self, q: np.ndarray) -> np.ndarray:
        """Tangent difference from the reference posture, zero on the floating base (which is free)."""
        e = pin.difference(self.model, self.q_ref, q)
        e[:6] = 0.0
        return e

    def _marker_positions(self, q: np.ndarray) -> np.ndarray:
        pin.forwardKinematics(self.model, self.data, q)
        return self.points.positions(self.data, self._point_set)

    def initial_guess(self, positions: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Pelvis pose by a Kabsch fit of the pelvis markers; the rest at the reference posture."""
        q = self.q_ref.copy()
        idx = sorted(k for k in self._pelvis_all if valid[k])     # in the stream's order
        model_pts = self._marker_positions(pin.neutral(self.model))[idx]
        meas = positions[idx]
        mc, sc = model_pts.mean(axis=0), meas.mean(axis=0)
        U, _, Vt = np.linalg.svd((model_pts - mc).T @ (meas - sc))
        D = np.diag([1, 1, np.sign(np.linalg.det(Vt.T @ U.T))])
        R = Vt.T @ D @ U.T
        q[:3] = sc - R @ mc
        q[3:7] = pin.Quaternion(R).coeffs()
        return q

    def _gauss_newton(self, q: np.ndarray, pos: np.ndarray, ok: np.ndarray, max_iter: int, tol: float
                      ) -> tuple[np.ndarray, np.ndarray, float, int]:
        """Damped Gauss-Newton from q on the markers ``ok`` (the others' rows weigh 0) and the posture prior: the
        last iterate, the best one, its cost and the iterations run."""
        model, nv = self.model, self.model.nv
        w_post = self.posture_weight
        target = np.where(ok[:, None], pos, 0.0)
        markers = self._marker_terms(ok, target)
        damping = MIN_DAMPING
        best_q, best_cost, JtJ, grad = q, np.inf, np.eye(nv), np.zeros(nv)
        it = 0
        for it in range(1, max_iter + 1):  # noqa: B007 (the count is reported after the loop)
            pin.computeJointJacobians(model, self.data, q)
            marker_cost, JtJ_q, Jtr_q = markers()
            e_post = self._posture_error(q)
            cost = marker_cost + w_post * (e_post @ e_post)
            if cost <= best_cost:     # downhill (or the start): keep it, and the damping back to its floor
                best_q, best_cost, JtJ, grad = q, cost, JtJ_q.copy(), Jtr_q + w_post * e_post
                damping = max(damping / 10, MIN_DAMPING)
            else:                     # uphill: back to the best pose, a shorter step
                damping *= 10
            H = JtJ.copy()
            H.flat[::nv + 1] += w_post + damping
            dq = -_solve_spd(H, grad)
            q = pin.integrate(model, best_q, dq)
            q[7:] = np.minimum(np.maximum(q[7:], self.lo[7:]), self.hi[7:])
            if np.abs(dq).max() < tol:
                break
        return q, best_q, best_cost, it

    def _marker_terms(self, ok: np.ndarray, target: np.ndarray):
        """For the markers ``ok`` (the others weigh 0) and their ``target`` positions (M, 3) [m]: a function that,
        after ``computeJointJacobians``, gives their cost sum |p - t|^2 [m^2], J'J and J'(p - t)."""
        terms = self._terms
        if terms is not None:
            weights = ok.astype(float)
            terms.load(self._point_set, weights, target)

            def compiled() -> tuple[float, np.ndarray, np.ndarray]:
                terms(self._H, self._g)
                d = terms.positions - target
                return float(weights @ np.einsum("ij,ij->i", d, d)), self._H, self._g
            return compiled
        rows, flat = np.repeat(ok, 3).astype(float), target.ravel()

        def numpy_terms() -> tuple[float, np.ndarray, np.ndarray]:
            P, Jm = self.points(self.data, self._point_set, rows)
            r = (P.ravel() - flat) * rows
            J = Jm.reshape(-1, self.model.nv)
            return float(r @ r), J.T @ J, J.T @ r
        return numpy_terms

    def fit(self, positions_m: np.ndarray, valid: np.ndarray, q0: np.ndarray | None = None,
            max_iter: int = 12, tol: float = 1e-5) -> FrameFit:
        """Fit one frame. ``positions_m``/``valid`` are in the stream's marker order (all names, as received)."""
        pos = np.asarray(positions_m, float)[self.stream_index]
        ok = np.asarray(valid, bool)[self.stream_index] & np.all(np.isfinite(pos), axis=1)
        n_ok = int(ok.sum())
        if n_ok < MIN_MARKERS or not self.pelvis_defined(ok):
            return FrameFit(self.q if self.q is not None else self.q_ref, float("nan"), n_ok, 0, False)
        if q0 is None and self.q is not None and self._q_prev is not None:
            # constant-velocity prediction from the last two fits: fewer iterations when streaming
            q0 = pin.integrate(self.model, self.q, pin.difference(self.model, self._q_prev, self.q))
        q = q0 if q0 is not None else (self.q if self.q is not None else self.initial_guess(pos, ok))
        q = q.copy()
        q[7:] = np.clip(q[7:], self.lo[7:], self.hi[7:])
        q, best_q, best_cost, it = self._gauss_newton(q, pos, ok, max_iter, tol)
        w_post = self.posture_weight
        err = self._marker_positions(q)[ok] - pos[ok]
        e_post = self._posture_error(q)
        if np.sum(err**2) + w_post * (e_post @ e_post) > best_cost:   # the last step went uphill
            q = best_q
            err = self._marker_positions(q)[ok] - pos[ok]
        self._q_prev = self.q
        self.q = q
        return FrameFit(q, float(np.sqrt(np.mean(np.sum(err**2, axis=1)))), n_ok, it, True)


def _solve_spd(H: np.ndarray, g: np.ndarray) -> np.ndarray:
    """H^-1 g for a symmetric positive definite H, by Cholesky (LAPACK directly: numpy's general solve and its
    wrapper cost several times more at this size)."""
    x, info = lapack.dposv(H, g)[1:]
    return x if info == 0 else np.linalg.solve(H, g)


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
