"""COP-matched segment-mass scaling: the skeleton's masses fitted to the force plates' wrench.

Each supported frame gives six equations linear in the segment masses (and the torso's COM shift): the measured
external wrench equals the floating-base rows of the joint-torque regressor Y(q, v, a) pi
(:func:`mass_scaling_rows`). Quasi-static frames use two rows instead: the COM lies over the measured COP
(:func:`static_rows`). :func:`solve_mass_scaling` solves the stack as constrained least squares: masses within
plausible bounds, left = right, summing to the body mass, pulled weakly toward de Leva. Matching the wrench's
moment is matching the COP. Units SI, lab frame REP-103.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..dynamics import G
# optim imports proxsuite now: the first re-solve must not pay for it mid-stream
from ..optim import constrained_lsq, effective_fraction
from .skeleton import SEGMENTS, HumanModel

MASS_GROUPS = ["pelvis", "torso", "head", "upper_arm", "forearm", "hand", "thigh", "shank", "foot", "toes"]
"""Segment groups with one mass factor each (left and right segments share theirs)."""
MASS_FACTOR_BOUNDS = (0.5, 2.0)
"""Bounds of each group's mass factor (its mass over the segment table's) in :func:`solve_mass_scaling`."""
LENGTH_FACTOR_BOUNDS = (0.6, 1.6)
"""Bounds of the calibrated length factors (:func:`sit2stand.human.calibration.calibrate_lengths`)."""
AT_BOUND_TOLERANCE = 0.03
"""A factor within this fraction of a bound's value sits at that bound."""
NOISE_PASSES = 3
"""Refits of :func:`fit_mass_scaling` on row weights from the previous fit's residual (the weights settle in 2-3)."""


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
    bounds: tuple[float, float] = MASS_FACTOR_BOUNDS
    theta: np.ndarray | None = None     # the solution in the rows' unknowns (per-segment masses, torso m dx, m dy)
    noise_passes: int = 0               # the fits whose row weights came from the previous fit's residual

    def factors(self) -> dict[str, float]:
        return {g: self.masses[g] / self.prior_masses[g] for g in self.masses}


@dataclass(frozen=True)
class FactorAtBound:
    """A fitted factor that sits at a bound of its fit: ``kind`` "mass" (scaling) or "length" (calibration); ``side``
    "lower" or "upper"."""

    kind: str
    group: str
    factor: float
    bound: float
    side: str

    def note(self) -> str:
        """One line for notes, summaries and logs, naming the segment group and the factor."""
        why = {"mass": "the plates cannot place this mass",
               "length": "its markers sit unlike the model's (placement, marker size, shoes)"}[self.kind]
        return (f"{self.group} {self.kind} factor {self.factor:.3f} sits at its {self.side} bound {self.bound:g}: "
                f"the segment table does not fit this body there, or {why}")


def factors_at_bounds(factors: dict[str, float], bounds: tuple[float, float], kind: str,
                      tolerance: float = AT_BOUND_TOLERANCE) -> list[FactorAtBound]:
    """The factors (group -> factor) within ``tolerance`` (relative) of a bound of ``bounds``, as :class:`FactorAtBound`
    of ``kind``."""
    lo, hi = bounds
    out = []
    for group, f in factors.items():
        if f <= lo * (1 + tolerance):
            out.append(FactorAtBound(kind, group, float(f), float(lo), "lower"))
        elif f >= hi * (1 - tolerance):
            out.append(FactorAtBound(kind, group, float(f), float(hi), "upper"))
    return out


def scaling_at_bounds(scaling: MassScaling) -> list[FactorAtBound]:
    """The mass factors of a scaling that sit at their bounds."""
    return factors_at_bounds(scaling.factors(), scaling.bounds, "mass")


def lengths_at_bounds(lengths: dict[str, float]) -> list[FactorAtBound]:
    """The calibrated length factors (a subject's ``lengths``) that sit at :data:`LENGTH_FACTOR_BOUNDS`."""
    return factors_at_bounds(lengths, LENGTH_FACTOR_BOUNDS, "length")


def group_of(segment: str) -> str:
    return segment[:-2] if segment[-2:] in ("_l", "_r") else segment


def apply_scaling(human: HumanModel, scaling: MassScaling) -> pin.Model:
    """A copy of the skeleton's model with the scaled masses (inertias scale with mass) and torso COM shift."""
    model = human.model.copy()
    for seg in SEGMENTS:
        j = human.segment_joint[seg]
        old = model.inertias[j]
        k = scaling.masses[group_of(seg)] / scaling.prior_masses[group_of(seg)]
        lever = old.lever.copy() + (scaling.torso_com_shift_m if seg == "torso" else 0.0)
        model.inertias[j] = pin.Inertia(old.mass * k, lever, old.inertia * k)
    return model


@dataclass
class _SegmentMap:
    """The unknowns theta laid onto a skeleton's segments, once per model: the streaming estimator makes both
    kinds of rows every frame, and a loop over the segments cost most of its frame."""

    model: pin.Model                 # the model it was made for
    regressor_to_theta: np.ndarray   # (10 (njoints - 1), n_theta): Y @ it are the dynamic rows' A
    joints: list[int]                # each segment's joint
    levers: np.ndarray               # (segments, 4, 1): each segment's COM in its joint frame, homogeneous [m]
    groups: np.ndarray               # (segments, n_theta): 1 at the segment's mass group
    torso: int                       # the torso's index among the segments


_MAPS: dict[int, _SegmentMap] = {}


def _segment_map(human: HumanModel) -> _SegmentMap:
    model = human.model
    cached = _MAPS.get(id(model))
    if cached is not None and cached.model is model:
        return cached
    n_theta = len(MASS_GROUPS) + 2
    P = np.zeros((10 * (model.njoints - 1), n_theta))
    groups = np.zeros((len(SEGMENTS), n_theta))
    for i, seg in enumerate(SEGMENTS):
        j = human.segment_joint[seg]
        inertia = model.inertias[j]
        P[10 * (j - 1): 10 * j, MASS_GROUPS.index(group_of(seg))] += inertia.toDynamicParameters() / inertia.mass
        groups[i, MASS_GROUPS.index(group_of(seg))] = 1.0
    torso = human.segment_joint["torso"]
    P[10 * (torso - 1) + 1, -2] += 1.0    # first moment along torso x (forward)
    P[10 * (torso - 1) + 2, -1] += 1.0    # first moment along torso y (left)
    joints = [human.segment_joint[seg] for seg in SEGMENTS]
    levers = np.array([[*model.inertias[j].lever, 1.0] for j in joints]).reshape(-1, 4, 1)
    if len(_MAPS) >= 16:
        _MAPS.pop(next(iter(_MAPS)))
    _MAPS[id(model)] = out = _SegmentMap(model, P, joints, levers, groups, SEGMENTS.index("torso"))
    return out


def mass_scaling_rows(human: HumanModel, q: np.ndarray, v: np.ndarray, a: np.ndarray, force_n: np.ndarray,
                      moment_origin_nm: np.ndarray, data: pin.Data | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Six equations A theta = b of one frame; theta = (group masses [kg] ..., torso m*dx, m*dy [kg m]).

    The measured external wrench (lab axes, about the lab origin) is expressed in the pelvis frame and equated to
    the floating-base rows of the joint-torque regressor, with each segment's parameters scaled by its mass.
    """
    model = human.model
    data = data or model.createData()
    Y = pin.computeJointTorqueRegressor(model, data, q, v, a)[:6]     # (6, 10 * (njoints - 1))
    A = Y @ _segment_map(human).regressor_to_theta
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
    m = _segment_map(human)
    oMi = data.oMi.tolist()
    X = np.array([oMi[j].homogeneous for j in m.joints])
    com = (X @ m.levers)[:, :2, 0]                      # each segment's COM, world x y [m]
    A = G * com.T @ m.groups
    A[:, -2] += G * X[m.torso, :2, 0]                   # the torso's x and y axes, world x y
    A[:, -1] += G * X[m.torso, :2, 1]
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


@dataclass
class ScalingRows:
    """The stacked equations A theta = b of many frames, each row's weight [1/N or 1/(N m)], and its channel: 0-5
    the dynamic wrench rows (force x, y, z, moment x, y, z in the pelvis frame), 6-8 the quasi-static ones (vertical
    force, COM over COP x, y). Rows of one channel are in time order."""

    A: np.ndarray
    b: np.ndarray
    weights: np.ndarray
    channel: np.ndarray


class RowPool:
    """Frames' rows (:class:`FrameRows`) in arrays that grow by doubling: :func:`assemble_rows` then stacks them
    without a Python step per frame (a live re-solve over 500 frames comes after a frame's COM, before the next)."""

    def __init__(self) -> None:
        self.n = 0
        n_theta = len(MASS_GROUPS) + 2
        self.acc = np.zeros(0)                           # |a_com| [m/s^2]
        self.has_static = np.zeros(0, bool)
        self.dynamic_A, self.dynamic_b = np.zeros((0, 6, n_theta)), np.zeros((0, 6))
        self.static_A, self.static_b = np.zeros((0, 3, n_theta)), np.zeros((0, 3))     # 0 where none

    def __len__(self) -> int:
        return self.n

    @classmethod
    def of(cls, rows: list[FrameRows]) -> RowPool:
        pool = cls()
        for r in rows:
            pool.add(r)
        return pool

    def add(self, rows: FrameRows) -> None:
        if self.n == len(self.acc):
            for name in ("acc", "has_static", "dynamic_A", "dynamic_b", "static_A", "static_b"):
                old = getattr(self, name)
                grown = np.zeros((max(64, 2 * len(old)), *old.shape[1:]), old.dtype)
                grown[:self.n] = old[:self.n]
                setattr(self, name, grown)
        k, self.n = self.n, self.n + 1
        self.acc[k] = rows.acc
        self.dynamic_A[k], self.dynamic_b[k] = rows.dynamic
        self.has_static[k] = rows.static is not None
        if rows.static is not None:
            self.static_A[k], self.static_b[k] = rows.static


def assemble_rows(rows: list[FrameRows] | RowPool, quasi_static_acc: float = 0.15, quiet_fraction: float = 0.4,
                  force_sd_n: float = 5.0, moment_sd_nm: float = 2.0) -> ScalingRows:
    """Stack frames' equations with weights, each frame's rows in the frames' order. Quasi-static frames use the
    static alternative: |a_com| below ``quasi_static_acc``, or among the quietest ``quiet_fraction`` of all the
    frames given (a short recording may never be quite still)."""
    pool = rows if isinstance(rows, RowPool) else RowPool.of(rows)
    n, n_theta = pool.n, len(MASS_GROUPS) + 2
    if not n:
        return ScalingRows(np.zeros((0, n_theta)), np.zeros(0), np.zeros(0), np.zeros(0, int))
    accs = pool.acc[:n]
    limit = max(quasi_static_acc, float(np.quantile(accs, quiet_fraction)))
    static = (accs <= limit) & pool.has_static[:n]
    # all frames' six dynamic rows, then all frames' three static ones: each frame takes its own from there
    A_all = np.concatenate([pool.dynamic_A[:n].reshape(-1, n_theta), pool.static_A[:n].reshape(-1, n_theta)])
    b_all = np.concatenate([pool.dynamic_b[:n].ravel(), pool.static_b[:n].ravel()])
    count = np.where(static, 3, 6)
    first = np.where(static, 6 * n + 3 * np.arange(n), 6 * np.arange(n))
    end = np.cumsum(count)
    within = np.arange(end[-1]) - np.repeat(end - count, count)      # each row's place among its frame's rows
    take = np.repeat(first, count) + within
    dynamic_weights = np.array([1 / force_sd_n] * 3 + [1 / moment_sd_nm] * 3)
    static_weights = np.array([1 / force_sd_n, 1 / moment_sd_nm, 1 / moment_sd_nm])
    frame_static = np.repeat(static, count)
    weights = np.where(frame_static, static_weights[np.minimum(within, 2)], dynamic_weights[within])
    return ScalingRows(A_all[take], b_all[take], weights, np.where(frame_static, 6 + within, within))


def reweigh_by_residual(rows: ScalingRows, theta: np.ndarray) -> np.ndarray:
    """Row weights from a fit's own residual: the nominal weights (their ratios between forces and moments kept) over
    the weighted residual's RMS, times the square root of the rows' effective share
    (:func:`~sit2stand.optim.effective_fraction`, along time within each channel).

    The nominal noise (5 N, 2 N m per frame) is the plates'; what the rows really miss is mostly the skeleton's and
    the fitted motion's error, larger and smooth over many frames. Counted as independent 5 N samples, 120 frames of a
    walk outweighed the prior and put 7 of 10 factors at their bounds (subject01), with a worse Newton residual than
    the table's masses. One scale for all channels: rescaled channel by channel, the rows the skeleton fits worst
    (the moments) lost their say and the real child's COP fit got worse (12 -> 19 mm)."""
    r = rows.weights * (rows.A @ theta - rows.b)
    order = np.argsort(rows.channel, kind="stable")
    frac = effective_fraction(r[order], rows.channel[order])
    rms = float(np.sqrt(np.mean(r**2))) if len(r) else 1.0
    return rows.weights * np.sqrt(frac) / max(rms, 1e-9)


def solve_mass_scaling(human: HumanModel, A: np.ndarray, b: np.ndarray, body_mass_kg: float,
                       bounds: tuple[float, float] = MASS_FACTOR_BOUNDS, prior_sd: float = 0.2,
                       max_torso_shift_m: float = 0.12, force_sd_n: float = 5.0,
                       moment_sd_nm: float = 2.0, weights: np.ndarray | None = None) -> MassScaling:
    """Constrained least squares for the group masses and torso COM shift (rows stacked from many frames).

    ``weights`` (one per row) default to blocks of six dynamic rows: 1/force_sd_n for forces, 1/moment_sd_nm for
    moments; :func:`assemble_rows` builds mixed dynamic / quasi-static rows with their weights.
    """

    prior = {g: 0.0 for g in MASS_GROUPS}
    count = {g: 0 for g in MASS_GROUPS}
    for seg in SEGMENTS:
        g = group_of(seg)
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
                       frames_used=int(np.sum(weights > 0) // 3), bounds=(float(bounds[0]), float(bounds[1])),
                       theta=res.x)


def fit_mass_scaling(human: HumanModel, rows: ScalingRows, body_mass_kg: float, noise_passes: int = NOISE_PASSES
                     ) -> MassScaling:
    """:func:`solve_mass_scaling` on the nominal weights, then ``noise_passes`` times on the weights of the previous
    fit's residual (:func:`reweigh_by_residual`): the data count as much as they are worth against the prior."""
    *_, scaling = fit_mass_scaling_steps(human, rows, body_mass_kg, noise_passes)
    return scaling


def fit_mass_scaling_steps(human: HumanModel, rows: ScalingRows, body_mass_kg: float,
                           noise_passes: int = NOISE_PASSES) -> Iterator[MassScaling]:
    """:func:`fit_mass_scaling` one solve at a time: yields each pass's fit; the last is the answer."""
    scaling = solve_mass_scaling(human, rows.A, rows.b, body_mass_kg, weights=rows.weights)
    yield scaling
    for k in range(noise_passes):
        weights = reweigh_by_residual(rows, scaling.theta)
        scaling = solve_mass_scaling(human, rows.A, rows.b, body_mass_kg, weights=weights)
        scaling.noise_passes = k + 1
        yield scaling


def prior_scaling(human: HumanModel) -> MassScaling:
    """The unscaled skeleton's group masses (de Leva's), as a :class:`MassScaling` that changes nothing."""
    prior: dict[str, float] = {}
    for seg in SEGMENTS:
        prior[group_of(seg)] = prior.get(group_of(seg), 0.0) + human.model.inertias[human.segment_joint[seg]].mass
    return MassScaling(dict(prior), np.zeros(3), dict(prior))
