"""Plausibility bounds of the candidate effects: what a missing physical part or a sensor fault can be, per kind.

The selection fits any linear combination the data allow; two candidates can trade off along a direction the data
hardly see (a mass on a hand and an encoder offset on the wrist), and a lone candidate can soak up the residual of an
effect outside the library (a link-length error as a mass on a thigh). An estimate past these bounds is refused, and
the residual it would have absorbed is reported as unexplained. The bounds are generous: they refuse what is not
physical, not what is unusual.

* extra mass [kg] on a link: at most ``MASS_MAX_KG``, within ``MASS_REACH_M`` of the link's origin; a negative one (a
  lighter link than modelled) no larger than the link's own modelled mass;
* encoder offset [rad]: at most ``JOINT_OFFSET_MAX_RAD`` and a quarter of the joint's range;
* torque-sensor bias [N m]: at most half the joint's effort limit (the sensor's range); gain within
  ``TORQUE_GAIN_RANGE``;
* F/T-sensor bias: at most ``FT_FORCE_BIAS_MAX_N`` / ``FT_TORQUE_BIAS_MAX_NM`` per axis;
* friction, spring stiffness, rotor inertia and a gear's play: positive (a negative one is not the physical effect)
  and bounded;
* actuator delay: from one control step to ``DELAY_MAX_S``; a gear's play from ``BACKLASH_MIN_RAD``.

The refusals that weigh an effect against the others follow: encoder offsets that cancel along a kinematic
chain, and one-sided effects where the evidence is symmetric.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .dataset import Dataset
from .select import Selected

MASS_REACH_M = 0.6           # an extra mass further than this from its link's origin is not a mass on that link
MASS_MAX_KG = 40.0           # an extra mass above this on one link of a 90 kg robot is not a missing part
MASS_MIN_KG = 1e-3           # below this a first moment is not a mass
JOINT_OFFSET_MAX_RAD = 0.2   # a calibration error of 11 degrees is already gross
JOINT_OFFSET_RANGE_SHARE = 0.25
TORQUE_BIAS_EFFORT_SHARE = 0.5
TORQUE_GAIN_RANGE = (0.5, 2.0)
FT_FORCE_BIAS_MAX_N = 60.0
FT_TORQUE_BIAS_MAX_NM = 12.0
VISCOUS_MAX_NMS_PER_RAD = 50.0
COULOMB_EFFORT_SHARE = 0.3
SPRING_MAX_NM_PER_RAD = 2000.0
ROTOR_INERTIA_MAX_KGM2 = 2.0
BACKLASH_MAX_RAD = 0.035     # half a gear's play: 2 degrees is a broken gearbox
BACKLASH_MIN_RAD = 2e-4      # below a harmonic drive's lost motion (about 1 arcmin): the residue of the law's fit
DELAY_MIN_S = 0.001          # one control step of the simulated robot: below it, the residue of 50 Hz samples
DELAY_MAX_S = 0.1
RESIDUE = "residue: "        # a refusal for being too small to be an effect at all (not reported as refused)


@dataclass(frozen=True)
class Limits:
    """What the bounds of one candidate need to know: its joint's effort [N m] and range [rad], its link's mass
    [kg] (0 where it does not apply)."""

    effort_nm: float = 0.0
    range_rad: float = 0.0
    link_mass_kg: float = 0.0


def refusal(kind: str, location: str, theta: np.ndarray, limits: Limits) -> str | None:
    """Why the estimate ``theta`` of effect ``kind`` at ``location`` is not physical; None when it is plausible.
    ``theta`` is in the selection's terms (a mass: m, m c; a torque gain: its departure from 1)."""
    v = float(theta[0])
    if kind == "extra_mass":
        return _mass_refusal(theta, limits)
    if kind == "joint_offset":
        cap = min(JOINT_OFFSET_MAX_RAD, JOINT_OFFSET_RANGE_SHARE * limits.range_rad or JOINT_OFFSET_MAX_RAD)
        return f"encoder offset {v:.3g} rad beyond {cap:.3g} rad" if abs(v) > cap else None
    if kind == "torque_bias":
        cap = TORQUE_BIAS_EFFORT_SHARE * limits.effort_nm if limits.effort_nm else np.inf
        return f"torque bias {v:.3g} N m beyond half the sensor's range ({cap:.3g} N m)" if abs(v) > cap else None
    if kind == "torque_gain":
        lo, hi = TORQUE_GAIN_RANGE
        return None if lo <= 1.0 + v <= hi else f"torque gain {1.0 + v:.3g} outside {lo:g}..{hi:g}"
    if kind == "ft_bias":
        cap = FT_FORCE_BIAS_MAX_N if location.endswith(("fx", "fy", "fz")) else FT_TORQUE_BIAS_MAX_NM
        return f"F/T bias {v:.3g} beyond {cap:g}" if abs(v) > cap else None
    caps = {"viscous_friction": VISCOUS_MAX_NMS_PER_RAD, "joint_spring": SPRING_MAX_NM_PER_RAD,
            "rotor_inertia": ROTOR_INERTIA_MAX_KGM2, "backlash": BACKLASH_MAX_RAD,
            "coulomb_friction": COULOMB_EFFORT_SHARE * limits.effort_nm if limits.effort_nm else np.inf}
    if kind == "backlash" and abs(v) < BACKLASH_MIN_RAD:
        return f"{RESIDUE}play {v:.3g} rad below {BACKLASH_MIN_RAD:g} rad"
    if kind in caps:
        return None if 0.0 < v <= caps[kind] else f"{kind.replace('_', ' ')} {v:.3g} outside 0..{caps[kind]:.3g}"
    if kind == "actuator_delay":
        if v < DELAY_MIN_S:
            return f"{RESIDUE}delay {v:.3g} s below one control step"
        return None if v <= DELAY_MAX_S else f"delay {v:.3g} s above {DELAY_MAX_S} s"
    return None


def _mass_refusal(theta: np.ndarray, limits: Limits) -> str | None:
    """An extra point mass: see the module docstring."""
    m = float(theta[0])
    if abs(m) <= MASS_MIN_KG:
        return f"{RESIDUE}mass {m:.2g} kg too small to place"
    if m > MASS_MAX_KG:
        return f"mass {m:.3g} kg above {MASS_MAX_KG:g} kg"
    if m < 0 and -m > limits.link_mass_kg:
        return f"negative mass {m:.3g} kg larger than the link's own {limits.link_mass_kg:.3g} kg"
    reach = float(np.linalg.norm(np.asarray(theta[1:4]) / m))
    return f"mass {reach:.2f} m from its link (beyond {MASS_REACH_M:g} m)" if reach > MASS_REACH_M else None


# --- Encoder offsets that cancel along a kinematic chain: a frame turned, refused as independent encoder errors.
#
# A joint's frame turned by a small angle about its parent joint's axis, between that joint and the ones after it (its
# axis tilted within the plane the two span, a link mounted turned), rotates everything beyond the parent by that angle
# and turns it back at the children: to first order the same as an encoder offset on the parent joint and the
# opposite offset on each child joint whose axis is parallel to the parent's. Only the positions of the links in
# between tell the two apart, which the torques show weakly. The selection can therefore name such a set of offsets,
# a confident name for an effect the library does not hold (seen: the torso's pitch axis tilted 5 degrees toward x
# named as offsets of +0.08 rad at the torso's yaw and -0.08 rad at both first shoulder joints, the replay then within
# noise).
# Independent encoder errors do not cancel: a parent offset matched, within ``CANCEL_TOLERANCE``, by opposite offsets
# of children about parallel axes (``PARALLEL_COS``, at the model's zero posture) is refused, with the children's, and
# the residual they would have absorbed is left to be reported as unexplained.


PARALLEL_COS = np.cos(np.radians(10.0))   # axes within 10 degrees of each other at the zero posture are parallel
CANCEL_TOLERANCE = 0.3                    # a child's offset within 30 % of minus the parent's cancels it


def world_axes(model: pin.Model) -> dict[str, np.ndarray]:
    """Each revolute joint's axis in the world frame at the model's zero posture (free flyer at the origin)."""
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    out = {}
    for jid in range(1, model.njoints):
        axis = {"RX": 0, "RY": 1, "RZ": 2}.get(model.joints[jid].shortname()[-2:])
        if axis is not None:
            out[model.names[jid]] = data.oMi[jid].rotation[:, axis]
    return out


def _descends(model: pin.Model, child: str, parent: str) -> bool:
    """Joint ``child`` lies beyond joint ``parent`` on the kinematic tree."""
    jid, pid = model.getJointId(child), model.getJointId(parent)
    while jid > pid:
        jid = model.parents[jid]
    return jid == pid


def cancelling_offsets(model: pin.Model, effects: list[Selected]) -> list[tuple[str, str]]:
    """(candidate key, why) of each encoder offset of ``effects`` in a cancelling set (see the module docstring)."""
    axes = world_axes(model)
    offsets = {s.candidate.location: (s.candidate.key, float(s.theta[0])) for s in effects
               if s.candidate.kind == "joint_offset" and s.candidate.location in axes}
    out: dict[str, str] = {}
    for parent, (key, theta) in offsets.items():
        children = []
        for child, (ckey, ctheta) in offsets.items():
            cos = float(axes[parent] @ axes[child])
            if child == parent or abs(cos) < PARALLEL_COS or not _descends(model, child, parent):
                continue
            if abs(ctheta * np.sign(cos) + theta) <= CANCEL_TOLERANCE * abs(theta):
                children.append((child, ckey, ctheta))
        if not children:
            continue
        listed = ", ".join(f"{c} {t:+.3f} rad" for c, _, t in children)
        why = (f"encoder offsets that cancel along the chain ({parent} {theta:+.3f} rad; {listed}, parallel axes): "
               f"the links between turned about {parent}'s axis (a joint axis or a mounting off), not independent "
               "encoder errors")
        for k in [key] + [ck for _, ck, _ in children]:
            out.setdefault(k, why)
    return list(out.items())


# --- Lopsided effects where the evidence is symmetric: a one-sided effect refused when the mirrored side shows the
# same.
#
# A cause that acts on both sides alike (both shanks longer than modelled) leaves the same residual on the left and the
# right joints. A one-sided candidate (a mass on the left thigh, a bias of the left F/T sensor) can still win the
# selection, by a little, and then explains one side and leaves the other: a confident, wrong, lopsided name. For each
# one-sided effect whose mirror was not named too, the residual of the mirrored channels (the nominal one less the
# other named effects': a left F/T bias loads the left hip too) is projected onto the effect's own contribution moved
# to them (floor-weighted). A true one-sided effect leaves the mirrored rows alone (the
# other leg's rows do not carry it): the projection is noise. When it carries at least ``SYMMETRY_SHARE`` of the
# effect's size, significantly, the evidence is symmetric and the effect is refused.


SYMMETRY_SHARE = 0.5         # the mirrored side shows at least half the effect's own signature: symmetric
SIGNIFICANT_PROJECTION_Z = 3.0


def mirror(name: str) -> str:
    """``name`` with left and right swapped."""
    return name.replace("left", "\0").replace("right", "left").replace("\0", "right")


def side_of(name: str) -> str | None:
    """"left", "right" or None (a name of both sides or of none)."""
    left, right = "left" in name, "right" in name
    return "left" if left and not right else "right" if right and not left else None


def lopsided(ds: Dataset, effects: list[Selected], contribution) -> list[tuple[str, str]]:
    """(candidate key, why) of each one-sided effect in ``effects`` refused for symmetric evidence;
    ``contribution(r, selected)``: its (N, C) contribution to recording r's residual (physical units)."""
    named = {(s.candidate.kind, s.candidate.location) for s in effects}
    parts = [[contribution(r, s) for s in effects] for r in range(len(ds.evaluations))]
    out = []
    for i, s in enumerate(effects):
        c = s.candidate
        side = side_of(c.location)
        if side is None or (c.kind, mirror(c.location)) in named:
            continue
        left = [ev.e - sum(p for j, p in enumerate(parts[r]) if j != i) for r, ev in enumerate(ds.evaluations)]
        num, den = _projection(ds, left, [parts[r][i] for r in range(len(left))], side)
        if den <= 0:
            continue
        beta, z = num / den, abs(num) / np.sqrt(den)
        if abs(beta) >= SYMMETRY_SHARE and z >= SIGNIFICANT_PROJECTION_Z:
            out.append((c.key, f"the mirrored side's residual shows {100 * abs(beta):.0f} % of its signature: "
                               "the evidence is symmetric"))
    return out


def _projection(ds: Dataset, residual: list[np.ndarray], own: list[np.ndarray], side: str) -> tuple[float, float]:
    """Floor-weighted <mirrored residual, moved contribution> and <contribution, contribution> over all recordings."""
    chans = ds.channels
    pairs = [(c, chans.index(mirror(ch))) for c, ch in enumerate(chans)
             if f"_{side}_" in ch and mirror(ch) in chans]
    num = den = 0.0
    for r, ev in enumerate(ds.evaluations):
        f = own[r]
        for c, cm in pairs:
            m = ev.valid[:, c] & ev.valid[:, cm]
            w = 1.0 / ds.floors[r][cm] ** 2
            num += w * float(residual[r][m, cm] @ f[m, c])
            den += w * float(f[m, c] @ f[m, c])
    return num, den
