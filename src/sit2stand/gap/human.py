"""The model-gap workflow on the human side: the skeletal model (de Leva segments, scaled to the subject's stature and
scale mass) against the force plates, to find a mass the model does not have (a backpack, a cast, a weight belt).

The person has no joint-torque sensors, but every contact is on a plate (chair and feet), so the whole body's
equation holds in every phase:

    e(t) = W_plates(t) - W_model(q, v, a)      (6 rows: force [N], moment about the lab origin [N m], world axes)

with q, v, a the marker-fitted motion (the COM estimator's calibrated skeleton, before any mass scaling) and
W_model the external wrench the model's dynamics need (the base rows of RNEA). The candidates are an extra point mass
on each segment (mass and first moment in the segment's joint frame: the mass columns of the joint-torque regressor)
and a uniform mass scale (the scale mass is the total: an extra mass on one segment makes every other one lighter
than the model says); they go through the same selection as the robot's effects (:mod:`sit2stand.gap.select`),
once the body's own departures from the table's segment masses, held to their spread, cannot explain the plates
(:mod:`sit2stand.gap.human`).

Also a body's own variation (:func:`within_spread`, :func:`map_departures`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..human.com import estimate_com
from ..human.offline import read_trial
from ..human.skeleton import SEGMENT_MASS_SD, SEGMENTS, Subject, build_human
from ..io.bag import BagError
from ..optim import effective_fraction
from .candidates import MASS_PARAMS, effect_summary
from .effects import Effect
from .dataset import fast_part_floor
from .plausibility import Limits, refusal
from .residuals import base_to_world
from .select import Candidate, Selection, select
from .workflow import NO_DISCREPANCY, SIGNIFICANT_Z, UNEXPLAINED

WITHIN_VARIATION = "no load beyond the body's own proportions"
"""The verdict's start where the body's own segment masses, within their spread, explain the plates (gap.human)."""


@dataclass
class HumanGap:
    bag: str
    segments: list[str]
    floors: np.ndarray                 # (6,)
    rms_before: np.ndarray             # (6,)
    rms_after: np.ndarray
    selection: Selection
    effects: list[Effect]
    verdict: str
    own_variation: np.ndarray          # (S,) the body's own segment-mass departures fitted [fraction of the table's]


def human_gap(bag: str | Path, progress=None) -> HumanGap:
    """Run the workflow on a human demonstration bag (markers + force plates + the subject's stature and mass)."""
    trial = read_trial(bag)
    if trial.height_m is None or trial.mass_kg is None:
        raise BagError(f"{bag}: the subject's stature and mass are not in the bag's metadata")
    chair = any(p.name == "chair" for p in trial.plates)
    if progress:
        progress(f"  {bag}: fitting the skeleton to {len(trial.marker_t_s)} marker frames")
    res = estimate_com(trial.marker_t_s, trial.marker_names, trial.positions, trial.valid, trial.plates,
                       Subject(trial.height_m, trial.mass_kg, trial.sex), scale_masses=False, chair_on_plate=chair,
                       trust_plate_mass=False)
    w = _Wrenches(res)
    columns = {seg: w.stack(w.signature("extra_mass", seg)) for seg in SEGMENTS} | {"whole body": w.stack(w.own)}
    Xv = np.column_stack([w.stack(x[:, :, None])[:, 0] for x in w.own_variation])
    sd = np.full(len(SEGMENTS), SEGMENT_MASS_SD)
    delta, _ = map_departures(w.y, Xv, sd, _noise_fraction(w.y, columns, w.series), columns["whole body"])
    cands = [Candidate("mass_scale", "whole body", ["scale - 1"], columns["whole body"])]
    if not within_spread(delta, sd):        # else no load: the body's own proportions explain the plates
        cands += [Candidate("extra_mass", seg, MASS_PARAMS, columns[seg], plausible=w.bounded(seg)) for seg in SEGMENTS]
    if progress:
        progress(f"  {len(w.keep)} supported frames, {len(cands)} candidates: selecting")
    sel = select(w.y, cands, series_id=w.series, noise_rss=float(len(w.y)))
    after = w.e.copy()
    if all(s.candidate.kind == "mass_scale" for s in sel.effects):   # the body's own proportions are what is left
        after -= sum(d * x for d, x in zip(delta, w.own_variation))
    for s in sel.effects:
        after -= np.tensordot(w.signature(s.candidate.kind, s.candidate.location), s.theta, axes=(2, 0))
    effects = effect_summary(sel)
    rms_b, rms_a = np.sqrt(np.mean(w.e ** 2, axis=0)), np.sqrt(np.mean(after ** 2, axis=0))
    return HumanGap(str(bag), list(SEGMENTS), w.floors, rms_b, rms_a, sel, effects,
                    _verdict(effects, rms_b / w.floors, rms_a / w.floors, delta), delta)


class _Wrenches:
    """The whole body's wrench residual along the supported frames of a COM estimate (see the module docstring),
    its noise floors and the candidates' signatures: ``e`` (K, 6), ``y`` its rows weighted by the floors."""

    def __init__(self, res) -> None:
        self.model = model = res.model
        data = model.createData()
        self.human = build_human(res.subject)
        self.keep = keep = np.flatnonzero(res.supported)
        nb = model.njoints - 1
        self.e = np.zeros((len(keep), 6))
        self.mass_cols = np.zeros((len(keep), 6, nb, 4))
        self.own = np.zeros((len(keep), 6, 1))           # the model's own wrench: a uniform mass scale's signature
        for i, k in enumerate(keep):
            q, v, a = res.q[k], res.v[k], res.a[k]
            T = base_to_world(q, np.zeros(3))        # about the lab origin, as the plates give it
            need = T @ pin.rnea(model, data, q, v, a)[:6]
            self.e[i] = np.concatenate([res.force_n[k], res.moment_nm[k]]) - need
            self.own[i, :, 0] = need
            Y = pin.computeJointTorqueRegressor(model, data, q, v, a)[:6]
            self.mass_cols[i] = np.tensordot(T, Y.reshape(6, nb, 10)[:, :, :4], axes=(1, 0))
        self.floors = np.maximum(fast_part_floor(self.e, np.ones_like(self.e, bool), res.t_s[keep]), 1e-3)
        self.y = self.stack(self.e[:, :, None])[:, 0]
        self.series = np.repeat(np.arange(6), len(keep))
        self.total_kg = float(sum(model.inertias[j].mass for j in range(1, model.njoints)))
        # a body's own segment masses (gap.human): per segment, its own mass at its COM, per unit of departure
        self.own_variation = [self.signature("extra_mass", seg) @ _mass_at_com(self._inertia(seg))
                              for seg in SEGMENTS]

    def stack(self, X: np.ndarray) -> np.ndarray:
        """(6 K, p) rows of the six channels of ``X`` (K, 6, p), each weighted by its floor."""
        return np.concatenate([X[:, c, :] / self.floors[c] for c in range(6)], axis=0)

    def _inertia(self, seg: str) -> pin.Inertia:
        return self.model.inertias[self.human.segment_joint[seg]]

    def signature(self, kind: str, seg: str) -> np.ndarray:
        """(K, 6, p) a candidate's columns: an extra mass on ``seg`` inside the scale mass (the other segments lighter
        by the same share), or the uniform mass scale."""
        if kind != "extra_mass":
            return self.own
        X = self.mass_cols[:, :, self.human.segment_joint[seg] - 1].copy()
        X[:, :, 0] -= self.own[:, :, 0] / self.total_kg
        return X

    def bounded(self, seg: str):
        """The extra mass's bounds on ``seg``: the robot's (gap.plausibility), and on a body, within the segment's reach
        and no lighter than ``LIGHTER_SHARE`` of the segment (see :func:`segment_refusal`)."""
        limits = Limits(link_mass_kg=float(self._inertia(seg).mass))
        reach = segment_reach_m(self.model, self.human.segment_joint[seg])
        return lambda theta: refusal("extra_mass", seg, theta, limits) or segment_refusal(theta, limits, reach)


def _noise_fraction(y: np.ndarray, columns: dict[str, np.ndarray], series: np.ndarray) -> float:
    """The effective share of the rows (:func:`~sit2stand.optim.effective_fraction`) of what no candidate can
    fit: the noise's, not the smooth signal's, whose autocorrelation would leave the data almost no weight."""
    X = np.hstack(list(columns.values()))
    theta, *_ = np.linalg.lstsq(X, y, rcond=None)
    return effective_fraction(y - X @ theta, series)


def _mass_at_com(inertia: pin.Inertia) -> np.ndarray:
    """(4,) a segment's own mass at its own COM, in the mass columns' terms (m, m c)."""
    return float(inertia.mass) * np.concatenate([[1.0], inertia.lever])


def _verdict(effects: list[Effect], z_before: np.ndarray, z_after: np.ndarray, delta: np.ndarray) -> str:
    """The named loads; or no discrepancy; or none beyond the body's own variation; or unexplained."""
    if effects:
        return "; ".join(_named(d) for d in effects)
    if z_before.max() < SIGNIFICANT_Z:
        return NO_DISCREPANCY
    if z_after.max() < SIGNIFICANT_Z:
        return f"{WITHIN_VARIATION} ({largest_departures(delta, list(SEGMENTS))} of the table's segment masses)"
    return UNEXPLAINED


def _named(d: Effect) -> str:
    """One named effect in words, with the segments the data cannot tell it from."""
    if d.kind != "extra_mass":
        return f"whole-body mass scale {d.value:.3f}"
    alts = [a.split("@", 1)[-1] for a in d.alternatives or () if a.startswith("extra_mass@")]
    where = d.location + (f" (or {', '.join(alts)}: the plates cannot tell them apart)" if alts else "")
    return f"extra mass on {where}: {d.mass_kg:.2f} +- {d.mass_ci95_kg:.2f} kg"


LIGHTER_SHARE = 0.3
"""A segment lighter than the table by more than this share of its mass is not a body's own variation, nor a load:
such a negative mass (seen: -2 to -7 kg on a 5 kg head, placed in the chest) stands in for something else, and is
refused (the residual it would take is reported as unexplained)."""
REACH_FACTOR = 1.5
"""An extra mass sits within this many segment lengths of its segment's joint (the robot's bound, 0.6 m, let a head
mass sit in the chest)."""


def segment_reach_m(model: pin.Model, joint: int) -> float:
    """How far from joint ``joint`` a mass on its segment can sit [m]: ``REACH_FACTOR`` x the segment's length (to
    its farthest child joint; a segment without one: twice its COM's distance)."""
    children = [c for c in range(joint + 1, model.njoints) if model.parents[c] == joint]
    length = max((float(np.linalg.norm(model.jointPlacements[c].translation)) for c in children),
                 default=2.0 * float(np.linalg.norm(model.inertias[joint].lever)))
    return REACH_FACTOR * length


def segment_refusal(theta: np.ndarray, limits: Limits, reach_m: float) -> str | None:
    """Why an extra mass ``theta`` (m, m c) is not a load on a body's segment; None when it can be."""
    m = float(theta[0])
    if m < -LIGHTER_SHARE * limits.link_mass_kg:
        return f"negative mass {m:.3g} kg beyond {LIGHTER_SHARE:.0%} of the segment's {limits.link_mass_kg:.3g} kg"
    if abs(m) > 1e-9 and (d := float(np.linalg.norm(np.asarray(theta[1:4]) / m))) > reach_m:
        return f"mass {d:.2f} m from its segment's joint (beyond {reach_m:.2f} m)"
    return None


# --- A body's own variation, on the human side of the model gap.
#
# The skeletal model's segment masses are de Leva's table: a population's mean proportions scaled to the subject's
# stature and scale mass. A person's own segments differ from it (``SEGMENT_MASS_SD`` of each segment's mass), and that
# difference loads the plates as a hidden mass would: fitted freely, it was named as a 2-6 kg load on the trunk or the
# head of bodies that carried nothing (half the bodies of the human-side benchmark).
#
# So before a load is looked for, the body's own variation explains what it can: each segment's mass (1 + delta_s)
# times the table's, at the segment's centre of mass and within the scale mass, delta_s ~ N(0, sd^2), fitted as the
# maximum a posteriori estimate (a ridge; the data counted at their effective share of rows, from the autocorrelation
# of what no candidate fits: smoothed signals counted sample by sample would leave the prior no say). Where every
# departure stays within ``VARIATION_Z`` standard deviations, the body's own proportions are a sufficient explanation
# and no load is named (a wrong declared body mass still is: no departure within the scale mass changes the weight;
# it is fitted beside them); otherwise the loads are looked for as before. An 8 kg load on a 75 kg body's trunk is then
# not named (the plates see it as a trunk 19 % and a head 10 % heavier than the table's, within their spread), which is
# the honest answer: the plates cannot tell it from a heavier upper body. A 15 kg one is named.


VARIATION_Z = 3.0
"""A body's own segment departures up to this many standard deviations explain the plates without a load: the
largest of 17 independent normal departures exceeds 3 in 4.5 % of bodies (2.5: in 19 %)."""


def map_departures(y: np.ndarray, Xv: np.ndarray, sd: np.ndarray, frac: float, X_free: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The maximum a posteriori departures delta (S,) of the columns ``Xv`` (rows weighted to unit noise, one per
    segment) under the prior N(0, ``sd``^2), the data counted at ``frac`` of their rows, fitted jointly with free
    columns ``X_free`` (no prior); and the residual."""
    k = 0 if X_free is None else X_free.shape[1]
    X = Xv if X_free is None else np.hstack([X_free, Xv])
    penalty = np.concatenate([np.zeros(k), 1.0 / np.asarray(sd, float) ** 2])
    theta = np.linalg.solve(frac * (X.T @ X) + np.diag(penalty), frac * (X.T @ y))
    return theta[k:], y - X @ theta


def within_spread(delta: np.ndarray, sd: np.ndarray, z: float = VARIATION_Z) -> bool:
    """Whether every departure is within ``z`` standard deviations."""
    return bool(np.all(np.abs(delta) <= z * np.asarray(sd, float)))


def largest_departures(delta: np.ndarray, names: list[str], top: int = 3) -> str:
    """The largest segment departures in words: ``torso +6 %, head -4 %``."""
    order = np.argsort(-np.abs(delta))[:top]
    return ", ".join(f"{names[i]} {100 * delta[i]:+.0f} %" for i in order)
