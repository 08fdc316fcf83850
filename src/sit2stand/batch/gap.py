"""The model-gap suites as batch cases (:mod:`sit2stand.batch.engine`): what ``sit2stand batch gap`` and
``sit2stand batch gap-human`` run, and ``make bench-gap`` and ``make bench-gap-human`` score.

**Robot side** (:func:`gap_cases`): plants with hidden effects drawn by :func:`sit2stand.gap.hidden.draw`, each
excited and analysed on its bags alone by :func:`sit2stand.gap.hidden.run_case`.

**Human side** (:func:`draw_cases`): digital humans of the stand-up population
(:func:`sit2stand.batch.standup.sample_population`), every one a different body, each hiding an extra point mass on
one segment group (:data:`GROUPS`: a plausible load there), a whole-body scale error, or nothing, then synthesised,
bagged and run through :func:`sit2stand.gap.human.human_gap` on the bag alone.

* A hidden mass: drawn per human uniformly in the group's range, at an offset from the segment's COM uniform in
  +-``offset`` per axis, on a side drawn at random for the sided groups. The bag's body mass is the true total
  (extra included, as a scale weighs the loaded person).
* A scale error: the true body is 5-12 % heavier or lighter (sign at random) than the body mass in the bag
  (:attr:`SynthConfig.declared_mass_factor`); the plates weigh the truth. The right answer is the ``mass_scale``
  effect with ``value`` = true / declared.
* Nothing hidden: right when nothing is named and the verdict is "no significant discrepancy" or "no load beyond the
  body's own proportions" (:mod:`sit2stand.gap.human`).

The synthesiser's bodies differ from de Leva's proportions by design (segment masses sd 8 %, ``vary_subject``): each
row lists the largest of those differences (:func:`body_deviation`) beside what was named. A body the synthesiser
refuses at every seed is replaced by a spare body of the same style (:func:`spare_body`).

Scoring (:func:`score_run`): a hit names the hidden effect's kind, its place (the segment on the right side; a mass on
a foot named on that foot's toes counts too: the synthesised toe joint never moves, so foot and toes are one rigid
body to the plates) and its size within 20 % (a mass: of the hidden kg; a scale error: of true / declared - 1).
Clean: nothing else named (nothing at all where nothing is hidden).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

from ..gap.effects import KINDS, MASS_SCALE, OUT_OF_LIBRARY, Effect
from ..gap.hidden import draw, run_case
from ..gap.human import WITHIN_VARIATION, human_gap
from ..gap.workflow import NO_DISCREPANCY
from ..human.demonstration_bag import write_demonstration_bag
from ..human.skeleton import SEGMENTS, ExtraMass, Subject, build_human
from ..robot.model import DEFAULT_ROBOT
from .engine import Job
from .standup import Case, sample_population, synthesise


def gap_cases(n_per_kind: int, n_two: int, kinds: tuple[str, ...] = KINDS + OUT_OF_LIBRARY,
              robot: str = DEFAULT_ROBOT) -> list[tuple]:
    """(kind, hidden effects, seed) of the model-gap benchmark on ``robot``: ``n_per_kind`` seeds per kind in
    ``kinds`` (in the library and outside it), as many plants with nothing hidden, and ``n_two`` with two in-library
    kinds."""
    cases = [(kind, [draw(kind, seed, robot)], seed) for kind in kinds for seed in range(n_per_kind)]
    cases += [("none", [], seed) for seed in range(n_per_kind)]
    rng = np.random.default_rng(7)
    for seed in range(n_two):
        a, b = rng.choice(len(KINDS), 2, replace=False)
        cases.append(("two", [draw(KINDS[a], 100 + seed, robot), draw(KINDS[b], 200 + seed, robot)], 100 + seed))
    return cases


def run_gap_case(arg: tuple[list, int, str], workdir: Path) -> dict:
    """One hidden-effect plant as a batch case (:class:`~sit2stand.batch.engine.Job`'s ``run``): its scores."""
    hidden, seed, robot = arg
    return run_case(hidden, seed, str(workdir), robot=robot)


def gap_jobs(cases: list[tuple], robot: str = DEFAULT_ROBOT) -> list[Job]:
    """One batch job per hidden-effect plant of :func:`gap_cases`."""
    return [Job("gap", f"{kind}_{seed}", {"hidden_kind": kind, "seed": seed, "robot": robot}, run_gap_case,
                (hidden, seed, robot)) for kind, hidden, seed in cases]


GROUPS = {
    # segment group -> hidden mass range [kg], offset half-range from the segment's COM per axis [m]
    "pelvis": ((3.0, 10.0), 0.08),      # a weight belt, a loaded tool belt
    "torso": ((3.0, 10.0), 0.08),       # a backpack, a weighted vest
    "head": ((1.0, 3.0), 0.03),         # a helmet, a head-mounted display
    "upper_arm": ((1.0, 3.0), 0.03),    # a cuff weight, a brace
    "forearm": ((1.0, 3.0), 0.03),      # a cast
    "hand": ((1.0, 3.0), 0.03),         # a held object
    "thigh": ((2.0, 5.0), 0.03),        # a thigh brace, a cuff weight
    "shank": ((1.0, 3.0), 0.03),        # an ankle weight, a cast
    "foot": ((1.0, 3.0), 0.03),         # a heavy boot, an orthosis
}
SCALE_DEVIATION = (0.05, 0.12)
"""|true / declared body mass - 1| of the scale-error case, drawn uniformly, the sign at random."""
CASES = tuple(GROUPS) + ("scale", "none")
SIZE_TOLERANCE = 0.2
SPARE_BODIES = 3
"""Spare bodies tried for a digital human the synthesiser refuses at every seed."""


@dataclasses.dataclass(frozen=True)
class GapCase(Case):
    """A digital human of the population with something hidden (nothing, an extra mass, a scale error)."""

    case: str = "none"
    extra: tuple[ExtraMass, ...] = ()
    declared_mass_factor: float = 1.0
    vary_subject: bool = True           # False: de Leva's proportions exactly (only the hidden effect differs)

    def config(self):
        """The synthesiser's configuration: the population's, with the extra mass and the declared-mass factor."""
        return dataclasses.replace(super().config(), extra=list(self.extra),
                                   declared_mass_factor=self.declared_mass_factor, vary_subject=self.vary_subject)

    def hidden(self) -> Effect | None:
        """What is hidden, in the workflow's terms (None: nothing); an extra mass without its place (the scores
        ask for its segment and size)."""
        if self.extra:
            return Effect("extra_mass", self.extra[0].segment, mass_kg=self.extra[0].mass_kg)
        if self.declared_mass_factor != 1.0:
            return Effect(MASS_SCALE, value=1.0 / self.declared_mass_factor)
        return None

    def hidden_row(self) -> dict | None:
        """:meth:`hidden` as plain data for the rows; an extra mass with its offset from its segment's COM
        (``offset_m``, segment axes)."""
        h = self.hidden()
        if h is None:
            return None
        row = h.as_dict()
        if self.extra:
            row.pop("pos_m")
            row["offset_m"] = list(self.extra[0].offset_m)
        return row


def draw_cases(n: int, cases: tuple[str, ...] = CASES, seed: int = 0, vary_subject: bool = True) -> list[GapCase]:
    """``n`` digital humans per case, all different: one population of ``n x len(cases)`` bodies drawn by
    :func:`~sit2stand.batch.standup.sample_population` and dealt out case by case; what each hides is drawn from
    one RNG seeded with ``seed`` (the same for every choice of ``cases``, case by case). ``vary_subject`` False:
    bodies of de Leva's proportions exactly (the synthesiser's random segment factors off)."""
    unknown = [c for c in cases if c not in CASES]
    if unknown or not cases:
        raise ValueError(f"cases must be among {', '.join(CASES)}, not {', '.join(unknown) or 'none'}")
    people = sample_population(n * len(CASES), seed)
    out = []
    for ci, name in enumerate(CASES):
        rng = np.random.default_rng([seed, ci])
        for i in range(n):
            person = dataclasses.asdict(people[ci * n + i])
            u_mass, u_side, u_sign = rng.random(3)
            offset = rng.uniform(-1.0, 1.0, 3)
            if name not in cases:
                continue
            person.update(index=i, vary_subject=vary_subject)
            if name in GROUPS:
                (lo, hi), reach = GROUPS[name]
                segment = name if name in SEGMENTS else f"{name}_{'l' if u_side < 0.5 else 'r'}"
                mass = round(float(lo + u_mass * (hi - lo)), 2)
                extra = ExtraMass(segment, mass, tuple(round(float(v), 3) for v in reach * offset))
                out.append(GapCase(**person, case=name, extra=(extra,)))
            elif name == "scale":
                lo, hi = SCALE_DEVIATION
                dev = (lo + u_mass * (hi - lo)) * (1.0 if u_sign < 0.5 else -1.0)
                out.append(GapCase(**person, case=name, declared_mass_factor=1.0 / (1.0 + round(float(dev), 4))))
            else:
                out.append(GapCase(**person, case=name))
    return out


def spare_body(case: GapCase, k: int) -> GapCase:
    """The ``k``-th spare of ``case`` (k >= 1): another body of the population's ranges in the same style, drawn from
    the case's own seed (what it hides kept)."""
    other = sample_population(k, case.seed, (case.style,))[k - 1]
    return dataclasses.replace(case, **{f: getattr(other, f) for f in ("height_m", "mass_kg", "sex", "seat_height_m",
                                                                       "rise_s", "seed")})


def body_deviation(demo, top: int = 3) -> list[str]:
    """What the model lacks beyond the hidden effect: the largest differences [kg] between the body's own segment
    masses (the hidden extra left out) and de Leva's at its true mass without the extra (the model the workflow
    builds, once the hidden effect's candidate is applied): ``segment +-kg``, largest first."""
    true = dict(demo.human.segment_mass)
    for e in demo.config.extra:
        true[e.segment] -= e.mass_kg
    nominal = build_human(Subject(demo.config.height_m, sum(true.values()), demo.config.sex)).segment_mass
    dev = sorted(((true[s] - nominal[s], s) for s in SEGMENTS), key=lambda d: -abs(d[0]))
    return [f"{s} {d:+.2f}" for d, s in dev[:top]]


def _place(location: str) -> set[str]:
    """The segments a mass on ``location`` may be named on: itself, and for a foot its toes (one rigid body)."""
    return {location, location.replace("foot", "toes")} if location.startswith("foot") else {location}


def _group(location: str) -> str:
    """A segment's group (no side; the toes in the foot's)."""
    base = location[:-2] if location.endswith(("_l", "_r")) else location
    return "foot" if base == "toes" else base


def _size_error(hidden: Effect, effect: Effect) -> float:
    """Relative size error of a named effect: of the mass [kg], or of the scale's deviation from 1."""
    if hidden.kind == "extra_mass":
        return abs(effect.mass_kg - hidden.mass_kg) / hidden.mass_kg
    return abs(effect.value - hidden.value) / abs(hidden.value - 1.0)


def score_run(hidden: Effect | None, effects: list[Effect], verdict: str) -> dict:
    """Score one run: ``found`` (kind and place right), ``size_error``, ``hit`` (found, size within 20 %; nothing
    hidden: nothing named and no discrepancy), ``clean`` (nothing named but the hidden effect), ``wrong_side`` (the
    mass named on the right group's other side), ``spurious`` (the other effects named)."""
    if hidden is None:
        quiet = verdict == NO_DISCREPANCY or verdict.startswith(WITHIN_VARIATION)
        return {"found": False, "size_error": float("nan"), "hit": not effects and quiet,
                "clean": not effects, "wrong_side": False, "spurious": [_named(e) for e in effects]}
    match = next((k for k, e in enumerate(effects) if e.kind == hidden.kind
                  and (e.kind != "extra_mass" or e.location in _place(hidden.location))), None)
    err = _size_error(hidden, effects[match]) if match is not None else float("nan")
    wrong_side = match is None and hidden.kind == "extra_mass" and any(
        e.kind == "extra_mass" and _group(e.location) == _group(hidden.location) for e in effects)
    spurious = [_named(e) for k, e in enumerate(effects) if k != match]
    return {"found": match is not None, "size_error": err, "hit": match is not None and err <= SIZE_TOLERANCE,
            "clean": not spurious, "wrong_side": wrong_side, "spurious": spurious}


def _effect_row(e: Effect) -> dict:
    """A named effect's figures for the JSON rows (a mass's position in its segment's joint frame too)."""
    keys = ("kind", "location", "mass_kg", "mass_ci95_kg", "pos_m", "value", "ci95", "share_of_gap")
    return {k: v for k, v in e.as_dict().items() if k in keys}


def _named(e: Effect) -> str:
    """An effect in a few words: kind @ place, size."""
    if e.kind == "extra_mass":
        return f"extra_mass @ {e.location} {e.mass_kg:.2f} kg"
    return f"{e.kind} {e.value:.3f}"


FAILED_ROW = {"named": [], "verdict": "error", "found": False, "size_error": float("nan"), "hit": False,
              "clean": False, "wrong_side": False, "spurious": []}
"""The scores of a run that broke: a miss."""


def run_one(case: GapCase) -> dict:
    """Synthesise, bag and analyse one digital human; its row (``error`` where a stage raised)."""
    t0 = time.monotonic()
    body = dataclasses.asdict(case)
    body.pop("extra")
    row: dict = {"case": case.case, "body": body, "hidden": case.hidden_row()}
    try:
        for k in range(SPARE_BODIES + 1):
            try:
                demo, row["synth_seed"] = synthesise(spare_body(case, k) if k else case)
                break
            except ValueError:
                if k == SPARE_BODIES:
                    raise
        row["spare_body"] = k
        row["body"].update({f: getattr(demo.config, f) for f in ("height_m", "mass_kg", "sex", "seat_height_m")})
        with tempfile.TemporaryDirectory(prefix="sit2stand-gap-human-") as tmp:
            write_demonstration_bag(demo, Path(tmp) / "bag")
            r = human_gap(Path(tmp) / "bag")
        row["body_deviation"] = body_deviation(demo)
        row["named"] = [_named(e) for e in r.effects]
        row["effects"] = [_effect_row(e) for e in r.effects]
        row["verdict"] = r.verdict
        row["z_before_max"] = float(np.max(r.rms_before / r.floors))
        row["z_after_max"] = float(np.max(r.rms_after / r.floors))
        row.update(score_run(case.hidden(), r.effects, r.verdict))
    except Exception as exc:  # noqa: BLE001 - a run that breaks is a result too (a miss), the benchmark goes on
        row.update({"error": f"{type(exc).__name__}: {exc}", **FAILED_ROW})
    row["wall_s"] = round(time.monotonic() - t0, 2)
    return row


def run_gap_human(case: GapCase, workdir: Path) -> dict:
    """:func:`run_one` as a batch case (:class:`~sit2stand.batch.engine.Job`'s ``run``)."""
    return run_one(case)


def gap_human_jobs(cases: list[GapCase]) -> list[Job]:
    """One batch job per digital human; its row shows the case, the body and what is hidden."""
    return [Job("gap-human", f"{c.case}_{c.index:02d}",
                {"case": c.case, "index": c.index, "style": c.style, "height_m": c.height_m, "mass_kg": c.mass_kg},
                run_gap_human, c) for c in cases]
