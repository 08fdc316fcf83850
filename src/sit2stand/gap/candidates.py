"""The model-gap workflow's candidate effects: every effect of the library that a dataset can show, with its
signature rows (the residual columns it would explain, weighted by each channel's noise floor) and its plausibility
check (:mod:`sit2stand.gap.plausibility`). Links joined by joints that did not move in the data are one rigid group.

Also the named effects in physical terms (:func:`describe`, :func:`effect_summary`).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..robot.profile import SIDES, profile_of
from .dataset import MOVING_RADPS, Dataset
from .effects import FT_AXES, KIND_UNITS, MASS_SCALE, Effect
from .plausibility import Limits, refusal
from .residuals import body_link_names, joint_columns
from .select import Candidate, Selection

MOVED_RAD = 0.1              # a joint whose range in the data is below this did not move: its links are one body

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
    """The candidate's plausibility check (gap.plausibility): estimate -> why it is refused, or None."""
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
            params = [f"{kind} [{KIND_UNITS[kind]}]"] + (["preload [N m]"] if kind == "joint_spring" else [])
            out.append(Candidate(kind, name, params, X, plausible=_bounded(model, links, kind, name)))
    return out


# --- The named effects in physical terms: the selection's estimates as effects with 95 % intervals, and one line
# per effect for a person (the workflow's report, the verdict, ``sit2stand gap``).


def effect_summary(sel: Selection) -> list[Effect]:
    """The chosen effects in physical terms with 95 % intervals (1.96 standard errors; position by the delta
    method from the mass and first moment)."""
    out = []
    for s in sel.effects:
        c = s.candidate
        d = Effect(c.kind, c.location, share_of_gap=s.gain, delta_bic=s.delta_bic, alternatives=tuple(s.alternatives))
        se = np.sqrt(np.clip(np.diag(s.cov), 0, None))
        if c.kind == "extra_mass":
            m, mc = float(s.theta[0]), s.theta[1:]
            pos = mc / m if abs(m) > 1e-6 else np.full(3, np.nan)
            J = np.zeros((3, 4))           # d(mc/m) / d(m, mc)
            J[:, 0] = -mc / m ** 2
            J[:, 1:] = np.eye(3) / m
            pos_se = np.sqrt(np.clip(np.diag(J @ s.cov @ J.T), 0, None))
            d.members, d.mass_kg, d.mass_ci95_kg = tuple(c.members), m, 1.96 * float(se[0])
            d.pos_m, d.pos_ci95_m = tuple(pos.tolist()), tuple((1.96 * pos_se).tolist())
        else:
            v, d.ci95, d.unit = float(s.theta[0]), 1.96 * float(se[0]), KIND_UNITS[c.kind]
            d.value = v
            if c.kind in ("torque_gain", MASS_SCALE):   # fitted as the departure from 1
                d.value = 1.0 + v
                d.unit = "measured / true" if c.kind == "torque_gain" else d.unit
            elif c.kind == "joint_spring":    # k and the preload -k q_rest
                d.rest_rad = -float(s.theta[1]) / v if abs(v) > 1e-9 else 0.0
            elif c.kind == "ft_bias":
                d.unit = "N" if c.location.endswith(("fx", "fy", "fz")) else "N m"
        out.append(d)
    return out


def describe(effect: Effect) -> str:
    """One line naming an effect for a person."""
    k, e = effect.kind, effect
    if k == "extra_mass":
        p = e.pos_m
        members = [m for m in e.members or () if m != e.location]
        group = f" (rigid in these data with {', '.join(members)})" if members else ""
        return (f"extra mass on {e.location}{group}: {e.mass_kg:.2f} +- {e.mass_ci95_kg or 0.0:.2f} "
                f"kg at ({p[0]:+.3f}, {p[1]:+.3f}, {p[2]:+.3f}) m in the link frame")
    label = {"viscous_friction": "viscous friction", "coulomb_friction": "Coulomb friction",
             "torque_bias": "torque-sensor bias", "torque_gain": "torque-sensor gain",
             "joint_offset": "encoder offset", "ft_bias": "force/torque sensor bias (sensor axes)",
             "actuator_delay": "actuator delay", "joint_spring": "joint spring", "rotor_inertia": "rotor inertia",
             "backlash": "backlash (half the gear's play; the joint torque's dead zone is +-kp times it)",
             "contact_softness": "soles' contact time constant (MuJoCo solref; the model's 0.02 s)",
             "link_length": "link length (its offset from the parent joint, scaled)",
             "joint_axis": "joint axis tilt (toward axis x z)"}[k]
    text = f"{label} at {e.location}: {e.value:.4g} +- {e.ci95 or 0.0:.2g} {e.unit or KIND_UNITS[k]}"
    if k == "joint_axis":
        text += f", and {e.value_2:.4g} +- {e.ci95_2 or 0.0:.2g} rad toward the axis x (axis x z)"
    return text
