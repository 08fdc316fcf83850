"""Plants with a hidden effect drawn by seed, and the scoring of what the workflow named: the hidden-data test suite
and the benchmark's hit rates use these.

An effect is drawn by kind, then location and magnitude from the seed, among what an excitation run can show
(:mod:`sit2stand.gap.recording`): masses on links whose joints move, friction on moving joints, gains and offsets on
joints that carry load. A case is a **hit** when the workflow names the hidden effect's kind at its location (a mass
on any link of the rigid group named), its magnitude within ``tolerance`` (20 %), and nothing else.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..robot.model import DEFAULT_ROBOT, PlantConfig
from ..robot.profile import SIDES, load_profile
from .effects import FT_AXES, KINDS, MODEL_KINDS, OUT_OF_LIBRARY, Effect, unmodeled_from
from .recording import excite
from .workflow import run

# Where the suite hides effects, from the robot's profile (``gap``): a link of every rigid group of an excitation run
# and links inside groups (a hand, the head, a wrist) for masses; the joints that move for friction and backlash;
# the loaded joints (trunk pitch, hip, knee, ankle pitch) for gains, offsets, springs and rotor inertia; the moving
# joints and some that stay still for torque biases.


@dataclass(frozen=True)
class Places:
    """Where the hidden-effect suite may hide an effect on one robot."""

    mass_links: tuple[str, ...]
    moving_joints: tuple[str, ...]
    loaded_joints: tuple[str, ...]
    leg_pitch_joints: tuple[str, ...]
    bias_joints: tuple[str, ...]
    leg_length_links: tuple[str, ...]       # thigh and shank links, one side ({side}: "left"/"right"/"*" below)
    trunk_pitch: str                        # the trunk's pitch joint, or the left hip's where the trunk has none


def places(robot: str = DEFAULT_ROBOT) -> Places:
    """The places of ``robot``'s profile (its ``gap`` section and leg roles)."""
    profile = load_profile(robot)
    leg_pitch = tuple(profile.leg(s, r) for s in SIDES for r in ("hip_pitch", "knee", "ankle_pitch"))
    moving = tuple(profile.gap.get("moving_joints", ()))
    trunk = (profile.trunk_pitch,) if profile.trunk_pitch else ()
    return Places(tuple(profile.gap.get("mass_links", ())), moving, trunk + leg_pitch, leg_pitch,
                  moving + tuple(profile.gap.get("still_joints", ())),
                  tuple(profile.child_link(profile.leg("left", r)) for r in ("knee", "ankle_pitch")),
                  profile.trunk_pitch or profile.leg("left", "hip_pitch"))


@dataclass
class Hidden:
    """One hidden effect: ``kind`` at ``location`` with ``magnitude`` (kg, N m s/rad, N m, measured/true gain, rad, s,
    N or N m; a backlash: half the gear's play [rad]); a mass also has ``pos_m`` in the link frame."""

    kind: str
    location: str
    magnitude: float
    pos_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    outside: bool = False          # drawn outside the workflow's library (OUT_OF_LIBRARY)
    magnitude_2: float = 0.0       # a tilt's second direction [rad] (joint axis, F/T mounting; gap.effects)

    def as_effect(self) -> Effect:
        """In the workflow's terms (see gap.effects)."""
        if self.kind == "extra_mass":
            return Effect(self.kind, self.location, mass_kg=self.magnitude, pos_m=self.pos_m)
        return Effect(self.kind, self.location, value=self.magnitude, value_2=self.magnitude_2)

    def describe(self) -> str:
        extra = f" at {tuple(round(p, 3) for p in self.pos_m)} m" if self.kind == "extra_mass" else ""
        second = f", {self.magnitude_2:.4g}" if self.magnitude_2 else ""
        return f"{self.kind} @ {self.location}: {self.magnitude:.4g}{second}{extra}"


def draw(kind: str, seed: int, robot: str = DEFAULT_ROBOT) -> Hidden:
    """A hidden effect of ``kind`` on ``robot`` (a profile) with location and magnitude drawn from ``seed``."""
    if kind in OUT_OF_LIBRARY:
        return draw_outside(kind, seed, robot)
    at = places(robot)
    profile = load_profile(robot)
    rng = np.random.default_rng([KINDS.index(kind), seed])
    sign = rng.choice([-1.0, 1.0])
    if kind == "extra_mass":
        link = str(rng.choice(at.mass_links))
        mass = rng.uniform(1.5, 4.0) if profile.is_arm_link(link) else rng.uniform(2.0, 8.0)
        pos = tuple(float(v) for v in rng.uniform(-0.12, 0.12, 3))
        return Hidden(kind, link, float(mass), pos)
    if kind == "viscous_friction":
        return Hidden(kind, str(rng.choice(at.moving_joints)), float(rng.uniform(1.5, 5.0)))
    if kind == "coulomb_friction":
        return Hidden(kind, str(rng.choice(at.moving_joints)), float(rng.uniform(1.0, 3.0)))
    if kind == "torque_bias":       # within 40 % of the joint's effort (the head's is 4 N m): a sensor's range
        joint = str(rng.choice(at.bias_joints))
        return Hidden(kind, joint, float(sign * min(rng.uniform(1.0, 5.0), 0.4 * profile.effort_nm(joint))))
    if kind == "torque_gain":
        return Hidden(kind, str(rng.choice(at.loaded_joints)), float(1.0 + sign * rng.uniform(0.05, 0.15)))
    if kind == "joint_offset":
        return Hidden(kind, str(rng.choice(at.loaded_joints)), float(sign * rng.uniform(0.01, 0.04)))
    if kind == "ft_bias":
        side, axis = str(rng.choice(["left", "right"])), str(rng.choice(FT_AXES))
        size = rng.uniform(5.0, 20.0) if axis.startswith("f") else rng.uniform(1.0, 4.0)
        return Hidden(kind, f"ft_{side}/{axis}", float(sign * size))
    if kind == "actuator_delay":
        return Hidden(kind, "all joints", float(rng.uniform(0.005, 0.025)))
    if kind == "joint_spring":
        return Hidden(kind, str(rng.choice(at.loaded_joints)), float(rng.uniform(20.0, 80.0)))
    if kind == "rotor_inertia":
        return Hidden(kind, str(rng.choice(at.loaded_joints)), float(rng.uniform(0.5, 1.5)))
    if kind == "contact_softness":    # the soles 2-4 times softer (contact time constant [s], MuJoCo's default 0.02)
        return Hidden(kind, "soles", float(rng.uniform(0.04, 0.08)))
    if kind == "link_length":         # thighs or shanks 3-6 % longer or shorter on both legs, or 1-2.5 % on one
        where = str(rng.choice(["*", "*", "left", "right"]))   # (one shank 5 % short: the robot cannot stand)
        size = rng.uniform(0.03, 0.06) if where == "*" else rng.uniform(0.01, 0.025)
        left = at.leg_length_links[int(rng.choice([0, 1]))]
        link = profile.both_sides(left) if where == "*" else profile.side_name(profile.both_sides(left).replace(
            "*", "{side}", 1), where)
        return Hidden(kind, link, float(1.0 + sign * size))
    if kind == "backlash":            # half a gear's play of 0.1-0.5 degrees on a joint that moves
        return Hidden(kind, str(rng.choice(at.moving_joints)), float(rng.uniform(0.002, 0.008)))
    if kind == "joint_axis":          # a hip, knee or ankle pitch axis tilted 3-7 degrees
        return Hidden(kind, str(rng.choice(at.leg_pitch_joints)), float(sign * rng.uniform(0.05, 0.12)))
    raise InputError(f"unknown effect kind {kind!r} (known: {', '.join(KINDS)})")


def draw_outside(kind: str, seed: int, robot: str = DEFAULT_ROBOT) -> Hidden:
    """An effect outside the workflow's library, 3-7 degrees in a direction drawn at random: the torso's pitch axis
    tilted (``torso_axis``), or one foot's F/T sensor mounted turned about a horizontal axis (``ft_rotation``: it reads
    part of the vertical load as a horizontal force, in proportion to the load)."""
    if kind not in OUT_OF_LIBRARY:
        raise InputError(f"unknown effect kind {kind!r} (outside the library: {', '.join(OUT_OF_LIBRARY)})")
    rng = np.random.default_rng([100 + OUT_OF_LIBRARY.index(kind), seed])
    size, direction = rng.uniform(0.05, 0.12), rng.uniform(0.0, 2.0 * np.pi)
    t1, t2 = float(size * np.cos(direction)), float(size * np.sin(direction))
    if kind == "torso_axis":
        return Hidden("joint_axis", places(robot).trunk_pitch, t1, magnitude_2=t2, outside=True)
    return Hidden("ft_rotation", f"ft_{rng.choice(['left', 'right'])}", t1, magnitude_2=t2, outside=True)


def plant_with(effects: list[Hidden], seed: int = 0, robot: str = DEFAULT_ROBOT) -> PlantConfig:
    """``robot``'s CAD plant with ``effects`` hidden in its ``unmodeled`` section (named "hidden": the bag tells
    nothing)."""
    cfg = PlantConfig(name="hidden", seed=seed, robot=robot)
    cfg.unmodeled = unmodeled_from([h.as_effect() for h in effects], mass_prefix="hidden")
    return cfg


def matches(h: Hidden, effect: Effect) -> bool:
    """Whether a named effect is ``h``'s kind at ``h``'s location (a mass: any link of the named rigid group)."""
    if effect.kind != h.kind:
        return False
    if h.kind == "extra_mass":
        return h.location in (effect.members or (effect.location,))
    return effect.location == h.location


def relative_error(h: Hidden, effect: Effect) -> float:
    if h.kind in ("torque_gain", "link_length"):      # a factor's error relative to its departure from 1
        return abs(effect.size - h.magnitude) / abs(h.magnitude - 1.0)
    return abs(effect.size - h.magnitude) / abs(h.magnitude)


@dataclass
class Score:
    hidden: list[Hidden]
    named: list[Effect]
    found: list[bool] = field(default_factory=list)        # per hidden effect: right kind and location
    errors: list[float] = field(default_factory=list)      # per hidden effect: relative magnitude error (nan: missed)
    extra: list[Effect] = field(default_factory=list)      # named but not hidden

    def hit(self, tolerance: float = 0.2) -> bool:
        return all(self.found) and all(e <= tolerance for e in self.errors) and not self.extra


def score(hidden: list[Hidden], named: list[Effect]) -> Score:
    s = Score(hidden, named)
    used = set()
    for h in hidden:
        k = next((i for i, e in enumerate(named) if i not in used and matches(h, e)), None)
        s.found.append(k is not None)
        s.errors.append(relative_error(h, named[k]) if k is not None else float("nan"))
        if k is not None:
            used.add(k)
    s.extra = [e for i, e in enumerate(named) if i not in used]
    return s


def run_case(hidden: list[Hidden], seed: int, workdir: str, n_moves: int = 8, replay: bool = True,
             robot: str = DEFAULT_ROBOT) -> dict:
    """Build ``robot``'s plant, record its excitation bag, run the workflow on the bag alone and score it
    (``replay``: with the re-simulation, ~6 s a case)."""
    # a folder of its own: two cases of one kind and seed may run at once
    bag = Path(tempfile.mkdtemp(prefix=f"case_{seed}_{'_'.join(h.kind for h in hidden) or 'none'}_", dir=workdir))
    shutil.rmtree(bag, ignore_errors=True)
    t0 = time.monotonic()
    alter = [h.as_effect() for h in hidden if h.kind in MODEL_KINDS]
    info = excite(plant_with(hidden, seed=seed, robot=robot), bag, seed=seed, n_moves=n_moves, alterations=alter)
    t1 = time.monotonic()
    result = run([bag], replay=replay, robot=robot)
    t2 = time.monotonic()
    s = score(hidden, result.effects)
    shutil.rmtree(bag, ignore_errors=True)
    outside = any(h.outside for h in hidden)
    return {"hidden": [h.describe() for h in hidden],
            "named": [f"{e.kind} @ {e.location}" for e in result.effects],
            "found": s.found, "errors": s.errors, "extra": [f"{e.kind} @ {e.location}" for e in s.extra],
            "hit": s.hit() if not outside else honest(result), "outside": outside,
            "unexplained": [u["channel"] + ": " + u["shape"] for u in result.unexplained[:3]],
            "refused": [d["effect"] for d in result.refused],
            "shrink": result.shrink, "shrink_first_order": result.shrink_first_order,
            "gap_before": result.gap_before, "gap_after": result.gap_after,
            "replay_gap_before": result.replay_gap_before, "replay_gap_after": result.replay_gap_after,
            "verdict": result.verdict, "fell": info["fell"], "excite_s": t1 - t0, "workflow_s": t2 - t1}


def honest(result) -> bool:
    """An effect outside the library is answered honestly when a residual is flagged as unexplained (whether or not
    a close proxy was named beside it): never a confident name with nothing left."""
    return bool(result.unexplained)
