"""The named effects as a plant's ``unmodeled`` section: one mapping for the hidden-effect plants, the augmented
model file and the re-simulation.

An effect is a dict as the workflow reports it: ``kind``, ``location`` (a link, a joint, ``ft_<side>/<axis>`` or
"all joints"), and ``mass_kg`` + ``pos_m`` (extra mass) or ``value`` (the rest; a torque gain as measured / true).
"""

from __future__ import annotations

from dataclasses import asdict

from ..robot.model import ExtraBodyMass, Unmodeled

FT_AXES = ("fx", "fy", "fz", "tx", "ty", "tz")
JOINT_TABLES = {"viscous_friction": "viscous_friction", "coulomb_friction": "coulomb_friction",
                "torque_bias": "torque_bias_nm", "torque_gain": "torque_gain", "joint_offset": "joint_offset_rad"}


def ft_location(location: str) -> tuple[str, int]:
    """``ft_<side>/<axis>`` -> (side, axis index in FT_AXES)."""
    side, axis = location.split("_", 1)[1].split("/")
    return side, FT_AXES.index(axis)


def unmodeled_from(effects: list[dict], mass_prefix: str = "found") -> Unmodeled:
    """The effects as a plant's unmodeled section; effects of one kind at one place add up (gains multiply). A
    negative extra mass (a link lighter than modelled) has no plant body: it is left out here (the augmented
    model's ``links`` carry it)."""
    um = Unmodeled()
    for e in effects:
        k = e["kind"]
        if k == "extra_mass":
            if e["mass_kg"] > 0:
                um.masses.append(ExtraBodyMass(e["location"], float(e["mass_kg"]),
                                               tuple(float(v) for v in e["pos_m"]), f"{mass_prefix}_{len(um.masses)}"))
        elif k == "ft_bias":
            side, a = ft_location(e["location"])
            bias = list(um.ft_bias.get(side, (0.0,) * 6))
            bias[a] += float(e["value"])
            um.ft_bias[side] = tuple(bias)
        elif k == "actuator_delay":
            um.actuator_delay_s += float(e["value"])
        else:
            table = getattr(um, JOINT_TABLES[k])
            old = table.get(e["location"], 1.0 if k == "torque_gain" else 0.0)
            table[e["location"]] = old * float(e["value"]) if k == "torque_gain" else old + float(e["value"])
    return um


def unmodeled_dict(um: Unmodeled) -> dict:
    """The fields of ``um`` that hold something, as plain data for a plant YAML's ``unmodeled`` section."""
    out = {}
    for key, value in asdict(um).items():
        if isinstance(value, (list, dict)) and not value:
            continue
        if isinstance(value, tuple) and not any(value):
            continue
        if isinstance(value, float) and value == 0.0:
            continue
        out[key] = value
    return out
