"""The model-gap workflow on the human side: the skeletal model (de Leva segments, scaled to the subject's stature and
scale mass) against the force plates, to find a mass the model does not have (a backpack, a cast, a weight belt).

The person has no joint-torque sensors, but every contact is on a plate (chair and feet), so the whole body's
equation holds in every phase:

    e(t) = W_plates(t) - W_model(q, v, a)      (6 rows: force [N], moment about the lab origin [N m], world axes)

with q, v, a the marker-fitted motion (the COM estimator's calibrated skeleton, before any mass scaling) and
W_model the external wrench the model's dynamics need (the base rows of RNEA). The candidates are an extra point mass
on each segment (mass and first moment in the segment's joint frame: the mass columns of the joint-torque regressor)
and a uniform mass scale (the scale mass is the total: an extra mass on one segment makes every other one lighter
than the model says); they go through the same selection as the robot's effects (:mod:`sit2stand.gap.select`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..human.com import estimate_com
from ..human.offline import read_trial
from ..human.skeleton import SEGMENTS, Subject, build_human
from ..io.bag import BagError
from .residuals import base_to_world
from .select import Candidate, Selection, select
from .dataset import fast_part_floor
from .bounds import Limits, refusal
from .candidates import MASS_PARAMS
from .naming import effect_summary
from .workflow import NO_DISCREPANCY, SIGNIFICANT_Z, UNEXPLAINED


@dataclass
class HumanGap:
    bag: str
    segments: list[str]
    floors: np.ndarray                 # (6,)
    rms_before: np.ndarray             # (6,)
    rms_after: np.ndarray
    selection: Selection
    effects: list[dict]
    verdict: str


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
    model = res.model
    data = model.createData()
    human = build_human(res.subject)
    keep = np.flatnonzero(res.supported)
    nb = model.njoints - 1
    e = np.zeros((len(keep), 6))
    mass_cols = np.zeros((len(keep), 6, nb, 4))
    own = np.zeros((len(keep), 6, 1))
    for i, k in enumerate(keep):
        q, v, a = res.q[k], res.v[k], res.a[k]
        T = base_to_world(q, np.zeros(3))        # about the lab origin, as the plates give it
        need = T @ pin.rnea(model, data, q, v, a)[:6]
        e[i] = np.concatenate([res.force_n[k], res.moment_nm[k]]) - need
        own[i, :, 0] = need
        Y = pin.computeJointTorqueRegressor(model, data, q, v, a)[:6]
        mass_cols[i] = np.tensordot(T, Y.reshape(6, nb, 10)[:, :, :4], axes=(1, 0))
    valid = np.ones_like(e, bool)
    floors = np.maximum(fast_part_floor(e, valid, res.t_s[keep]), 1e-3)
    w = 1.0 / floors
    stack = lambda X: np.concatenate([X[:, c, :] * w[c] for c in range(6)], axis=0)  # noqa: E731
    y = stack(e[:, :, None])[:, 0]
    sid = np.repeat(np.arange(6), len(keep))
    total = float(sum(model.inertias[j].mass for j in range(1, model.njoints)))

    def within_scale_mass(seg: str) -> np.ndarray:
        """An extra mass on ``seg`` inside the scale mass: the other segments are lighter by the same share."""
        X = mass_cols[:, :, human.segment_joint[seg] - 1].copy()
        X[:, :, 0] -= own[:, :, 0] / total
        return X

    def bounded(seg: str):
        """The extra mass's bounds on ``seg``: the robot's (gap.bounds), and on a body, within the segment's reach
        and no lighter than ``LIGHTER_SHARE`` of the segment (see :func:`segment_refusal`)."""
        j = human.segment_joint[seg]
        limits = Limits(link_mass_kg=float(model.inertias[j].mass))
        reach = segment_reach_m(model, j)
        return lambda theta: refusal("extra_mass", seg, theta, limits) or segment_refusal(theta, limits, reach)

    cands = [Candidate("extra_mass", seg, MASS_PARAMS, stack(within_scale_mass(seg)), plausible=bounded(seg))
             for seg in SEGMENTS]
    cands.append(Candidate("mass_scale", "whole body", ["scale - 1"], stack(own)))
    rms_b = np.sqrt(np.mean(e ** 2, axis=0))
    if progress:
        progress(f"  {len(keep)} supported frames, {len(cands)} candidates: selecting")
    sel = select(y, cands, series_id=sid, noise_rss=float(len(y)))
    after = e.copy()
    for s in sel.effects:
        X = within_scale_mass(s.candidate.location) if s.candidate.kind == "extra_mass" else own
        after -= np.tensordot(X, s.theta, axes=(2, 0))
    effects = effect_summary(sel)
    rms_a = np.sqrt(np.mean(after ** 2, axis=0))
    if effects:
        verdict = "; ".join(_named(d) for d in effects)
    else:
        verdict = NO_DISCREPANCY if (rms_b / floors).max() < SIGNIFICANT_Z else UNEXPLAINED
    return HumanGap(str(bag), list(SEGMENTS), floors, rms_b, rms_a, sel, effects, verdict)


def _named(d: dict) -> str:
    """One named effect in words, with the segments the data cannot tell it from."""
    if d["kind"] != "extra_mass":
        return f"whole-body mass scale {d['value']:.3f}"
    alts = [a.split("@", 1)[-1] for a in d.get("alternatives", []) if a.startswith("extra_mass@")]
    where = d["location"] + (f" (or {', '.join(alts)}: the plates cannot tell them apart)" if alts else "")
    return f"extra mass on {where}: {d['mass_kg']:.2f} +- {d['mass_ci95_kg']:.2f} kg"


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
