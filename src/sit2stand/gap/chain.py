"""Encoder offsets that cancel along a kinematic chain: a frame turned, refused as independent encoder errors.

A joint's frame turned by a small angle about its parent joint's axis, between that joint and the ones after it (its
axis tilted within the plane the two span, a link mounted turned), rotates everything beyond the parent by that angle
and turns it back at the children: to first order the same as an encoder offset on the parent joint and the
opposite offset on each child joint whose axis is parallel to the parent's. Only the positions of the links in
between tell the two apart, which the torques show weakly. The selection can therefore name such a set of offsets,
a confident name for an effect the library does not hold (seen: the torso's pitch axis tilted 5 degrees toward x
named as offsets of +0.08 rad at the torso's yaw and -0.08 rad at both first shoulder joints, the replay then within
noise).
Independent encoder errors do not cancel: a parent offset matched, within ``CANCEL_TOLERANCE``, by opposite offsets
of children about parallel axes (``PARALLEL_COS``, at the model's zero posture) is refused, with the children's, and
the residual they would have absorbed is left to be reported as unexplained.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .select import Selected

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
