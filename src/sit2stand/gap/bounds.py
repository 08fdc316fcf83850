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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
