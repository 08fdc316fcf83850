"""The named effects in physical terms: the selection's estimates as effect dicts with 95 % intervals, and one line
per effect for a person (the workflow's report, the verdict, ``sit2stand gap``)."""

from __future__ import annotations

import numpy as np

from .candidates import UNITS
from .select import Selection


def effect_summary(sel: Selection) -> list[dict]:
    """The chosen effects in physical terms with 95 % intervals (1.96 standard errors; position by the delta
    method from the mass and first moment)."""
    out = []
    for s in sel.effects:
        c = s.candidate
        d = {"kind": c.kind, "location": c.location, "share_of_gap": s.gain, "delta_bic": s.delta_bic,
             "alternatives": s.alternatives}
        se = np.sqrt(np.clip(np.diag(s.cov), 0, None))
        if c.kind == "extra_mass":
            m, mc = float(s.theta[0]), s.theta[1:]
            pos = mc / m if abs(m) > 1e-6 else np.full(3, np.nan)
            J = np.zeros((3, 4))           # d(mc/m) / d(m, mc)
            J[:, 0] = -mc / m ** 2
            J[:, 1:] = np.eye(3) / m
            pos_se = np.sqrt(np.clip(np.diag(J @ s.cov @ J.T), 0, None))
            d.update({"members": c.members, "mass_kg": m, "mass_ci95_kg": 1.96 * float(se[0]),
                      "pos_m": pos.tolist(), "pos_ci95_m": (1.96 * pos_se).tolist()})
        else:
            v = float(s.theta[0])
            if c.kind in ("torque_gain", "mass_scale"):   # fitted as the departure from 1
                d.update({"value": 1.0 + v, "ci95": 1.96 * float(se[0]),
                          "unit": "measured / true" if c.kind == "torque_gain" else UNITS[c.kind]})
            elif c.kind == "joint_spring":    # k and the preload -k q_rest
                k = v
                d.update({"value": k, "ci95": 1.96 * float(se[0]), "unit": UNITS[c.kind],
                          "rest_rad": -float(s.theta[1]) / k if abs(k) > 1e-9 else 0.0})
            elif c.kind == "ft_bias":
                d.update({"value": v, "ci95": 1.96 * float(se[0]),
                          "unit": "N" if c.location.endswith(("fx", "fy", "fz")) else "N m"})
            else:
                d.update({"value": v, "ci95": 1.96 * float(se[0]), "unit": UNITS[c.kind]})
        out.append(d)
    return out


def describe(effect: dict) -> str:
    """One line naming an effect for a person."""
    k = effect["kind"]
    if k == "extra_mass":
        p = effect["pos_m"]
        members = [m for m in effect["members"] if m != effect["location"]]
        group = f" (rigid in these data with {', '.join(members)})" if members else ""
        return (f"extra mass on {effect['location']}{group}: {effect['mass_kg']:.2f} +- {effect['mass_ci95_kg']:.2f} "
                f"kg at ({p[0]:+.3f}, {p[1]:+.3f}, {p[2]:+.3f}) m in the link frame")
    label = {"viscous_friction": "viscous friction", "coulomb_friction": "Coulomb friction",
             "torque_bias": "torque-sensor bias", "torque_gain": "torque-sensor gain",
             "joint_offset": "encoder offset", "ft_bias": "force/torque sensor bias (sensor axes)",
             "actuator_delay": "actuator delay", "joint_spring": "joint spring", "rotor_inertia": "rotor inertia",
             "backlash": "backlash (half the gear's play; the joint torque's dead zone is +-kp times it)",
             "contact_softness": "soles' contact time constant (MuJoCo solref; the model's 0.02 s)",
             "link_length": "link length (its offset from the parent joint, scaled)",
             "joint_axis": "joint axis tilt (toward axis x z)"}[k]
    text = f"{label} at {effect['location']}: {effect['value']:.4g} +- {effect['ci95']:.2g} {effect['unit']}"
    if k == "joint_axis":
        text += f", and {effect['value_2']:.4g} +- {effect['ci95_2']:.2g} rad toward the axis x (axis x z)"
    return text
