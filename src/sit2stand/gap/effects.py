"""The effect kinds of the model gap, one typed entry each (:data:`EFFECT_KINDS`: where a kind acts, its unit and
parameters, whether it alters the compiled model, the kinematics or only a sensor, whether only a replay sees it, and
whether the hidden-effect suite draws it inside the workflow's library): adding a kind is one entry. And the named
effects as a plant's ``unmodeled`` section, or as changes to the compiled MuJoCo model: one mapping for the
hidden-effect plants, the augmented model file and the re-simulation.

An effect is an :class:`Effect` record, named by the workflow or hidden in a plant; ``Effect.as_dict`` and
``Effect.from_dict`` are its plain-data form in reports, model files and JSON rows.

The plant file's ``unmodeled`` section has no field for a joint spring or a rotor inertia, nor for the kinematic and
contact errors the hidden-effect suite hides outside the workflow's library (link length, joint axis, sole contact
stiffness): :func:`alter_model` applies those to a compiled model (``MODEL_KINDS``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from fnmatch import fnmatchcase

import mujoco
import numpy as np

from ..errors import InputError
from ..robot.model import ExtraBodyMass, Unmodeled

FT_AXES = ("fx", "fy", "fz", "tx", "ty", "tz")
JOINT_TABLES = {"viscous_friction": "viscous_friction", "coulomb_friction": "coulomb_friction",
                "torque_bias": "torque_bias_nm", "torque_gain": "torque_gain", "joint_offset": "joint_offset_rad",
                "backlash": "backlash_rad"}


@dataclass(frozen=True)
class EffectKind:
    """One kind of model-gap effect, and how each part of the workflow treats it: its one home."""

    name: str
    acts_on: str               # where: a link, a joint, an F/T axis, all joints, the soles, the model's kinematics
    unit: str | tuple[str, ...]  # of its value (an extra mass: its mass and its position)
    parameters: int = 1        # fitted per location (a joint spring: stiffness and rest angle)
    in_model: bool = False     # applied to the compiled model (alter_model): no field of a plant's unmodeled section
    kinematic: bool = False    # changes the kinematics: the soles' closure finds it (gap.kinematics)
    torque_sensor: bool = False  # a joint torque sensor's fault: the motion and every other signal unchanged
    replay_only: bool = False  # no inverse-dynamics signature (the measured forces carry it): only a replay sees it
    reevaluated: bool = False  # non-linear in the residuals: evaluated again with it applied
    library: bool = True       # in the workflow's library (False: the hidden-effect suite's cases outside it)


EFFECT_KINDS = {k.name: k for k in (
    EffectKind("extra_mass", "link", ("kg", "m"), reevaluated=True),
    EffectKind("viscous_friction", "joint", "N m s/rad"),
    EffectKind("coulomb_friction", "joint", "N m"),
    EffectKind("torque_bias", "joint", "N m", torque_sensor=True),
    EffectKind("torque_gain", "joint", "1", torque_sensor=True),                    # measured / true
    EffectKind("joint_offset", "joint", "rad", reevaluated=True),
    EffectKind("ft_bias", "F/T axis", "N or N m"),
    EffectKind("actuator_delay", "all joints", "s"),
    EffectKind("joint_spring", "joint", "N m/rad", parameters=2, in_model=True),     # about rest_rad
    EffectKind("rotor_inertia", "joint", "kg m^2", in_model=True),                   # added to the armature
    EffectKind("contact_softness", "soles", "s", in_model=True, replay_only=True),   # MuJoCo solref time constant
    EffectKind("link_length", "link", "scale", in_model=True, kinematic=True, reevaluated=True),
    EffectKind("joint_axis", "joint", "rad", in_model=True, kinematic=True, reevaluated=True),   # see tilted_axis
    EffectKind("backlash", "joint", "rad"),
    EffectKind("torso_axis", "joint", "rad", library=False),
    EffectKind("ft_rotation", "F/T sensor", "rad", library=False))}
"""Every kind, in the hidden-effect suite's order (its random draws are seeded by a kind's index)."""


MASS_SCALE = "mass_scale"
"""The human side's whole-body mass scale (true / model): a kind of the human gap, not of a robot's model."""
KIND_UNITS = {**{name: kind.unit for name, kind in EFFECT_KINDS.items()}, MASS_SCALE: "true / model"}


@dataclass
class Effect:
    """One model-gap effect, named by the workflow or hidden in a plant: ``kind`` (an :data:`EFFECT_KINDS` name, or
    :data:`MASS_SCALE`) at ``location`` (a link, a joint, ``ft_<side>/<axis>``, ``ft_<side>``, ``soles``, ``all
    joints``, a glob such as ``*_knee_link``, a body segment).

    Its size: an extra mass ``mass_kg`` at ``pos_m`` (link frame, m); any other kind ``value`` in the kind's unit
    (a torque gain: measured / true; a link length: its scale), with ``value_2`` a tilt's second direction [rad]
    (joint axis, F/T mounting) and ``rest_rad`` a joint spring's rest angle. A named effect also has its 95 %
    intervals (``ci95``, ``ci95_2``, ``mass_ci95_kg``, ``pos_ci95_m``), ``unit``, how the selection chose it
    (``share_of_gap``, ``delta_bic``, ``alternatives``; a mass's rigid group ``members``) and, a Coulomb friction, the
    transition speed its signature used (``v0_radps``). None: not known or not applicable."""

    kind: str
    location: str = ""
    value: float = 0.0
    value_2: float = 0.0
    rest_rad: float = 0.0
    mass_kg: float = 0.0
    pos_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    unit: str | None = None
    ci95: float | None = None
    ci95_2: float | None = None
    mass_ci95_kg: float | None = None
    pos_ci95_m: tuple[float, float, float] | None = None
    members: tuple[str, ...] | None = None
    share_of_gap: float | None = None
    delta_bic: float | None = None
    alternatives: tuple[str, ...] | None = None
    v0_radps: float | None = None
    refined: str | None = None        # a kinematic effect the dynamics corrected: by what

    @property
    def key(self) -> str:
        """``kind@location``: the selection's name for it."""
        return f"{self.kind}@{self.location}"

    @property
    def size(self) -> float:
        """Its magnitude: the mass [kg] of an extra mass, else ``value``."""
        return self.mass_kg if self.kind == "extra_mass" else self.value

    def as_dict(self) -> dict:
        """Plain data (reports, model files, JSON rows): the fields this kind has, those not known left out."""
        mass = self.kind == "extra_mass"
        skip = {"value", "value_2", "rest_rad"} if mass else {"mass_kg", "pos_m"}
        if not mass and self.kind != "joint_axis" and not self.value_2:
            skip.add("value_2")
        if self.kind != "joint_spring":
            skip.add("rest_rad")
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name not in skip and v is not None:
                out[f.name] = list(v) if isinstance(v, tuple) else v
        return out

    @classmethod
    def from_dict(cls, d: dict, where: str = "effect") -> Effect:
        """An effect from its plain data; an unknown kind or field, or a size that is not a number, is an
        :class:`InputError` naming ``where`` (the file) and the field."""
        if not isinstance(d, dict) or d.get("kind") not in KIND_UNITS:
            raise InputError(f"{where}: an effect needs a kind among {', '.join(KIND_UNITS)}, not {d!r}")
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise InputError(f"{where}: effect {d['kind']}: unknown field(s) {', '.join(unknown)}")
        try:
            return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})._checked(where)
        except (TypeError, ValueError) as err:
            raise InputError(f"{where}: effect {d['kind']}: {err}") from None

    def _checked(self, where: str) -> Effect:
        for name in ("value", "value_2", "rest_rad", "mass_kg"):
            if not isinstance(getattr(self, name), (int, float)):
                raise InputError(f"{where}: effect {self.kind}: {name} is not a number: {getattr(self, name)!r}")
        self.pos_m = tuple(float(x) for x in self.pos_m)
        if len(self.pos_m) != 3:
            raise InputError(f"{where}: effect {self.kind}: pos_m needs 3 coordinates, not {len(self.pos_m)}")
        return self


def kinds(**flags: bool) -> tuple[str, ...]:
    """The names of the kinds with these :class:`EffectKind` flags, in the registry's order."""
    return tuple(k.name for k in EFFECT_KINDS.values() if all(getattr(k, f) == v for f, v in flags.items()))


KINDS = kinds(library=True)                 # the workflow's library: what the hidden-effect suite draws
OUT_OF_LIBRARY = kinds(library=False)       # an honest answer flags these as unexplained
MODEL_KINDS = kinds(in_model=True)
KINEMATIC_KINDS = kinds(kinematic=True)
SENSOR_KINDS = kinds(torque_sensor=True)
REPLAY_ONLY_KINDS = kinds(replay_only=True)
REEVALUATED_KINDS = kinds(reevaluated=True)
DAMPING_RATIO = 1.0          # the soles' contact damping ratio (MuJoCo's default), kept when the stiffness changes


def ft_location(location: str) -> tuple[str, int]:
    """``ft_<side>/<axis>`` -> (side, axis index in FT_AXES)."""
    side, axis = location.split("_", 1)[1].split("/")
    return side, FT_AXES.index(axis)


def unmodeled_from(effects: list[Effect], mass_prefix: str = "found") -> Unmodeled:
    """The effects as a plant's unmodeled section; effects of one kind at one place add up (gains multiply). A
    negative extra mass (a link lighter than modelled) has no plant body: it is left out here (the augmented
    model's ``links`` carry it, and :func:`alter_model` takes it off the compiled plant's link)."""
    um = Unmodeled()
    for e in effects:
        k, v = e.kind, float(e.value)
        if k == "extra_mass":
            if e.mass_kg > 0:
                um.masses.append(ExtraBodyMass(e.location, float(e.mass_kg), tuple(float(x) for x in e.pos_m),
                                               f"{mass_prefix}_{len(um.masses)}"))
        elif k == "ft_bias":
            side, a = ft_location(e.location)
            bias = list(um.ft_bias.get(side, (0.0,) * 6))
            bias[a] += v
            um.ft_bias[side] = tuple(bias)
        elif k == "actuator_delay":
            um.actuator_delay_s += v
        elif k == "ft_rotation":      # a plant's effect only: no workflow candidate names it
            um.ft_rotation_rad[e.location.removeprefix("ft_")] = (v, float(e.value_2), 0.0)
        elif k in MODEL_KINDS:
            continue                     # applied to the compiled model (alter_model)
        else:
            table = getattr(um, JOINT_TABLES[k])
            old = table.get(e.location, 1.0 if k == "torque_gain" else 0.0)
            table[e.location] = old * v if k == "torque_gain" else old + v
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


def alter_model(model: mujoco.MjModel, effects: list[Effect]) -> None:
    """Apply the ``MODEL_KINDS`` effects of ``effects`` to a compiled plant model in place (a location may be a glob
    such as ``*_knee_link``); the other kinds are left to :func:`unmodeled_from`."""
    for e in effects:
        k, v = e.kind, float(e.value)
        if k == "extra_mass" and e.mass_kg < 0:
            _lighten(model, e)
        if k not in MODEL_KINDS:
            continue
        if k == "contact_softness":
            for g in _matching(model, mujoco.mjtObj.mjOBJ_GEOM, model.ngeom, "sole_box_*"):
                model.geom_solref[g] = [v, DAMPING_RATIO]
            continue
        obj = mujoco.mjtObj.mjOBJ_BODY if k == "link_length" else mujoco.mjtObj.mjOBJ_JOINT
        ids = _matching(model, obj, model.nbody if k == "link_length" else model.njnt, e.location)
        if not ids:
            raise InputError(f"{k}: no {'link' if k == 'link_length' else 'joint'} matches {e.location!r}")
        for i in ids:
            _alter_one(model, k, i, v, e)


def _lighten(model: mujoco.MjModel, effect: Effect) -> None:
    """A negative extra mass: the link's mass lowered and its centre of mass moved away from the removed point (the
    body frame of a URDF link is its joint's frame, as in the workflow's model)."""
    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, effect.location)
    if i < 0:
        raise InputError(f"extra_mass: no link {effect.location!r}")
    m, old = float(effect.mass_kg), float(model.body_mass[i])
    total = max(old + m, 1e-6)
    model.body_ipos[i] = (old * model.body_ipos[i] + m * np.asarray(effect.pos_m, float)) / total
    model.body_mass[i] = total


def _alter_one(model: mujoco.MjModel, kind: str, i: int, v: float, effect: Effect) -> None:
    """One body or joint ``i`` of ``model`` changed by effect ``kind`` of size ``v``."""
    if kind == "link_length":
        model.body_pos[i] *= v
    elif kind == "joint_spring":
        model.jnt_stiffness[i] = v
        model.qpos_spring[model.jnt_qposadr[i]] = float(effect.rest_rad)
    elif kind == "rotor_inertia":
        model.dof_armature[model.jnt_dofadr[i]] += v
    elif kind == "joint_axis":
        model.jnt_axis[i] = tilted_axis(np.array(model.jnt_axis[i]), v, float(effect.value_2))


def tilt_directions(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two directions a joint axis is tilted toward: ``axis x z`` (``axis x x`` for a vertical axis), and
    ``axis`` crossed with that."""
    p1 = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    p1 /= np.linalg.norm(p1)
    return p1, np.cross(axis, p1)


def tilted_axis(axis: np.ndarray, t1: float, t2: float) -> np.ndarray:
    """``axis`` tilted by ``t1`` toward the first direction and ``t2`` toward the second (unit)."""
    p1, p2 = tilt_directions(axis)
    t = np.hypot(t1, t2)
    if t < 1e-12:
        return axis.copy()
    return np.cos(t) * axis + np.sin(t) * (t1 * p1 + t2 * p2) / t


def _matching(model: mujoco.MjModel, obj: mujoco.mjtObj, count: int, pattern: str) -> list[int]:
    """Ids of the objects of type ``obj`` whose name matches ``pattern``."""
    return [i for i in range(count) if fnmatchcase(mujoco.mj_id2name(model, obj, i) or "", pattern)]
