"""The model-gap workflow's candidate effects: every effect of the library that a dataset can show, with its
signature rows (the residual columns it would explain, weighted by each channel's noise floor) and its plausibility
check (:mod:`sit2stand.gap.bounds`). Links joined by joints that did not move in the data are one rigid group.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..robot.profile import SIDES, profile_of
from .bounds import Limits, refusal
from .dataset import MOVING_RADPS, Dataset
from .effects import FT_AXES
from .residuals import body_link_names, joint_columns
from .select import Candidate

MOVED_RAD = 0.1              # a joint whose range in the data is below this did not move: its links are one body
UNITS = {"extra_mass": ("kg", "m"), "viscous_friction": "N m s/rad", "coulomb_friction": "N m",
         "torque_bias": "N m", "torque_gain": "1", "joint_offset": "rad", "actuator_delay": "s",
         "mass_scale": "true / model", "joint_spring": "N m/rad", "rotor_inertia": "kg m^2", "backlash": "rad"}

def moved_joints(ds: Dataset) -> np.ndarray:
    """(n,) joints whose range over the data exceeds MOVED_RAD."""
    return np.max([np.ptp(r.q, axis=0) for r in ds.recordings], axis=0) > MOVED_RAD


def rigid_groups(model: pin.Model, ds: Dataset) -> dict[int, list[int]]:
    """Pinocchio body index (0-based: joint i+1) of each group's root -> member bodies: links joined by joints that
    did not move are one rigid body in these data. The feet (below the F/T sensors) are left out."""
    moved = moved_joints(ds)
    by_name = {n: moved[i] for i, n in enumerate(ds.joint_names)}
    feet = {profile_of(model).foot_joint(s) for s in SIDES}
    groups: dict[int, list[int]] = {}
    for jid in range(1, model.njoints):
        name = model.names[jid]
        if name in feet:
            continue
        root = jid
        while root > 1 and not by_name.get(model.names[root], True):
            root = model.parents[root]
        groups.setdefault(root - 1, []).append(jid - 1)
    return groups


def _limits(model: pin.Model, links: list[str], kind: str, location: str) -> Limits:
    """The bounds' context of a candidate: its joint's effort and range, or its link's modelled mass."""
    if kind == "extra_mass":
        return Limits(link_mass_kg=float(model.inertias[links.index(location) + 1].mass))
    if model.existJointName(location):
        jid = model.getJointId(location)
        iq, iv = model.joints[jid].idx_q, model.joints[jid].idx_v
        return Limits(effort_nm=float(model.effortLimit[iv]),
                      range_rad=float(model.upperPositionLimit[iq] - model.lowerPositionLimit[iq]))
    return Limits()


def _bounded(model: pin.Model, links: list[str], kind: str, location: str):
    """The candidate's plausibility check (gap.bounds): estimate -> why it is refused, or None."""
    limits = _limits(model, links, kind, location)
    return lambda theta: refusal(kind, location, theta, limits)


def stack_rows(ds: Dataset, cols: list[np.ndarray]) -> np.ndarray:
    """Rows of every recording's valid samples (channel-major, time order within a channel), weighted by the floor;
    ``cols`` per recording: (N, C, p)."""
    out = []
    for ev, X, floor in zip(ds.evaluations, cols, ds.floors):
        Xw = X / floor[None, :, None]
        out.append(np.concatenate([Xw[ev.valid[:, c], c, :] for c in range(X.shape[1])], axis=0))
    return np.concatenate(out, axis=0)


def series_ids(ds: Dataset) -> np.ndarray:
    """Per stacked residual row, the id of its (recording, channel) series (time order within a series)."""
    ids = []
    for r, ev in enumerate(ds.evaluations):
        C = ev.e.shape[1]
        for c in range(C):
            ids.append(np.full(int(ev.valid[:, c].sum()), r * 1000 + c))
    return np.concatenate(ids)


MASS_PARAMS = ["mass [kg]", "mass*com_x [kg m]", "mass*com_y [kg m]", "mass*com_z [kg m]"]


def build_candidates(model: pin.Model, ds: Dataset, exclude: frozenset[str] = frozenset()) -> list[Candidate]:
    """Every effect of the library that these data can show (see the module docstring), with its signature rows;
    ``exclude``: candidate keys refused earlier."""
    links = body_link_names(model)
    cands: list[Candidate] = []
    for members in rigid_groups(model, ds).values():
        # a mass on each link of the group: rigid with the group's root in these data, but a hand's mass still
        # loads the wrist joints that did not move, which a mass on the forearm does not
        for m in members:
            cands.append(Candidate("extra_mass", links[m], MASS_PARAMS,
                                   stack_rows(ds, [ev.mass_cols[:, :, m, :] for ev in ds.evaluations]),
                                   members=[links[k] for k in members],
                                   plausible=_bounded(model, links, "extra_mass", links[m])))
    cands += _joint_candidates(model, links, ds)
    if any(ev.ctrl_delay is not None for ev in ds.evaluations):
        cands.append(Candidate("actuator_delay", "all joints", ["delay [s]"],
                               stack_rows(ds, [joint_columns(r, ev, "actuator_delay", 0)
                                           for r, ev in zip(ds.recordings, ds.evaluations)]),
                               plausible=_bounded(model, links, "actuator_delay", "all joints")))
    for side in ("left", "right"):          # one candidate per sensor axis: a bias is per channel
        for a, axis in enumerate(FT_AXES):
            loc = f"ft_{side}/{axis}"
            cands.append(Candidate("ft_bias", loc, [f"{axis} [{'N' if a < 3 else 'N m'}]"],
                                   stack_rows(ds, [ev.ft_cols[side][:, :, a:a + 1] for ev in ds.evaluations]),
                                   plausible=_bounded(model, links, "ft_bias", loc)))
    return [c for c in cands if c.key not in exclude]


def _joint_candidates(model: pin.Model, links: list[str], ds: Dataset) -> list[Candidate]:
    """The single-joint candidates: sensor faults on every joint; viscous friction and rotor inertia on the joints
    that moved fast enough to show them, Coulomb friction and a spring on every joint that moved (a spring on a still
    joint is a bias, its inertia shows no acceleration; dry friction shows in the sign of the velocity however slow:
    a slow shoulder's, 0.11 rad/s at most, was named as a spring while no friction was offered); a gear's play on
    the joints that moved or carry a varying load (its dead zone needs a drive to cut)."""
    static = all(r.static for r in ds.recordings)
    speed = np.sqrt(np.mean(np.concatenate([r.qd for r in ds.recordings]) ** 2, axis=0))
    tau_sd = np.std(np.concatenate([ev.tau_model for ev in ds.evaluations]), axis=0)
    moved = moved_joints(ds)
    out = []
    for j, name in enumerate(ds.joint_names):
        kinds = ["torque_bias", "joint_offset"]
        if tau_sd[j] > 1.0:
            kinds.append("torque_gain")
        if not static and (moved[j] or tau_sd[j] > 1.0):
            kinds.append("backlash")
        if not static and speed[j] > MOVING_RADPS:
            kinds += ["viscous_friction", "rotor_inertia"]
        if not static and moved[j]:
            kinds += ["coulomb_friction", "joint_spring"]
        for kind in kinds:
            X = stack_rows(ds, [joint_columns(r, ev, kind, j) for r, ev in zip(ds.recordings, ds.evaluations)])
            if np.linalg.norm(X) < 1e-6:
                continue
            params = [f"{kind} [{UNITS[kind]}]"] + (["preload [N m]"] if kind == "joint_spring" else [])
            out.append(Candidate(kind, name, params, X, plausible=_bounded(model, links, kind, name)))
    return out
