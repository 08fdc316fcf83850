"""Benchmark (not a test): the human-side hit rate of the model-gap workflow.

    python -m sit2stand.bench --only gap_human [--gap-human-n 20] [--gap-human-cases hand,none] (make bench-gap-human)

Cases: an extra point mass hidden on one segment group (one case per group of the skeleton), a whole-body scale
error, nothing hidden; ``n`` digital humans per case, every one a different body of the stand-up benchmark's
population (:func:`sit2stand.batch.standup.sample_population`: stature 1.5-1.95 m, mass 50-110 kg within a BMI of
17-38, sex, seat height, natural/elderly/fast in turn, a synthesiser seed; a body the synthesiser refuses is redrawn
with the next seeds, :func:`sit2stand.batch.standup.synthesise`; one it refuses at every seed is replaced by a spare
body of the same style, :func:`spare_body`). Each is synthesised, written as a bag and run through
:func:`sit2stand.gap.human.human_gap` on the bag alone. The synthesiser's bodies differ from the model's de Leva
proportions by design (segment masses sd 8 %, ``vary_subject``): each row lists the largest of those differences
(``body_deviation``, kg, beyond the hidden effect) beside what was named, to tell a false alarm from a real one.

* A hidden mass: drawn per human uniformly in the group's range (:data:`GROUPS`: a plausible load there), at an offset
  from the segment's COM uniform in +-``offset`` per axis, on a side drawn at random for the sided groups. The bag's
  body mass is the true total (extra included, as a scale weighs the loaded person): the extra mass is inside the
  scale mass, the case the workflow's candidates describe.
* A scale error: the true body (nothing extra) is 5-12 % heavier or lighter (sign at random) than the body mass in
  the bag (:attr:`SynthConfig.declared_mass_factor`); the plates weigh the truth. The right answer is the
  ``mass_scale`` effect with ``value`` = true / declared.
* Nothing hidden: right when nothing is named and the verdict is "no significant discrepancy" or "no load beyond the
  body's own proportions" (:mod:`sit2stand.gap.variation`).

Scoring (:func:`score_run`): a hit names the hidden effect's kind, its place (the segment on the right side; a mass on
a foot named on that foot's toes counts too: the synthesised toe joint never moves, so foot and toes are one rigid
body to the plates and their mass columns are the same) and its size within 20 % (a mass: of the hidden kg; a scale
error: of the deviation true / declared - 1). Clean: nothing else named (nothing at all where nothing is hidden).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

from ..batch.engine import Job, run_jobs
from ..batch.standup import Case, sample_population, synthesise
from ..gap.human import WITHIN_VARIATION, human_gap
from ..gap.workflow import NO_DISCREPANCY
from ..human.demonstration_bag import write_demonstration_bag
from ..human.skeleton import SEGMENTS, ExtraMass, Subject, build_human

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
TARGETS = {"hit_rate": 0.9, "clean_rate": 0.9, "none_no_alarm_rate": 0.95}
"""Targets: in-library effects named fully right in 90 %, nothing spurious in 90 %; nothing hidden: no alarm 95 %."""
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

    def hidden(self) -> dict | None:
        """What is hidden, in the workflow's terms (None: nothing)."""
        if self.extra:
            e = self.extra[0]
            return {"kind": "extra_mass", "location": e.segment, "mass_kg": e.mass_kg, "offset_m": list(e.offset_m)}
        if self.declared_mass_factor != 1.0:
            return {"kind": "mass_scale", "value": 1.0 / self.declared_mass_factor}
        return None


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


def _size_error(hidden: dict, effect: dict) -> float:
    """Relative size error of a named effect: of the mass [kg], or of the scale's deviation from 1."""
    if hidden["kind"] == "extra_mass":
        return abs(effect["mass_kg"] - hidden["mass_kg"]) / hidden["mass_kg"]
    return abs(effect["value"] - hidden["value"]) / abs(hidden["value"] - 1.0)


def score_run(hidden: dict | None, effects: list[dict], verdict: str) -> dict:
    """Score one run: ``found`` (kind and place right), ``size_error``, ``hit`` (found, size within 20 %; nothing
    hidden: nothing named and no discrepancy), ``clean`` (nothing named but the hidden effect), ``wrong_side`` (the
    mass named on the right group's other side), ``spurious`` (the other effects named)."""
    if hidden is None:
        quiet = verdict == NO_DISCREPANCY or verdict.startswith(WITHIN_VARIATION)
        return {"found": False, "size_error": float("nan"), "hit": not effects and quiet,
                "clean": not effects, "wrong_side": False, "spurious": [_named(e) for e in effects]}
    match = next((k for k, e in enumerate(effects) if e["kind"] == hidden["kind"]
                  and (e["kind"] != "extra_mass" or e["location"] in _place(hidden["location"]))), None)
    err = _size_error(hidden, effects[match]) if match is not None else float("nan")
    wrong_side = match is None and hidden["kind"] == "extra_mass" and any(
        e["kind"] == "extra_mass" and _group(e["location"]) == _group(hidden["location"]) for e in effects)
    spurious = [_named(e) for k, e in enumerate(effects) if k != match]
    return {"found": match is not None, "size_error": err, "hit": match is not None and err <= SIZE_TOLERANCE,
            "clean": not spurious, "wrong_side": wrong_side, "spurious": spurious}


def _effect_row(e: dict) -> dict:
    """A named effect's figures for the JSON rows (a mass's position in its segment's joint frame too)."""
    keys = ("kind", "location", "mass_kg", "mass_ci95_kg", "pos_m", "value", "ci95", "share_of_gap")
    return {k: e[k] for k in keys if k in e}


def _named(e: dict) -> str:
    """An effect in a few words: kind @ place, size."""
    if e["kind"] == "extra_mass":
        return f"extra_mass @ {e['location']} {e['mass_kg']:.2f} kg"
    return f"{e['kind']} {e['value']:.3f}"


def _hidden_text(h: dict | None) -> str:
    if h is None:
        return "nothing"
    if h["kind"] == "extra_mass":
        return f"extra_mass @ {h['location']} {h['mass_kg']:.2f} kg"
    return f"mass_scale {h['value']:.3f}"


FAILED_ROW = {"named": [], "verdict": "error", "found": False, "size_error": float("nan"), "hit": False,
              "clean": False, "wrong_side": False, "spurious": []}
"""The scores of a run that broke: a miss."""


def run_one(case: GapCase) -> dict:
    """Synthesise, bag and analyse one digital human; its row (``error`` where a stage raised)."""
    t0 = time.monotonic()
    body = dataclasses.asdict(case)
    body.pop("extra")
    row: dict = {"case": case.case, "body": body, "hidden": case.hidden()}
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
        row.update(score_run(row["hidden"], r.effects, r.verdict))
    except Exception as exc:  # noqa: BLE001 - a run that breaks is a result too (a miss), the benchmark goes on
        row.update({"error": f"{type(exc).__name__}: {exc}", **FAILED_ROW})
    row["wall_s"] = round(time.monotonic() - t0, 2)
    return row


def progress_line(i: int, n: int, row: dict) -> str:
    """``[i/n] hit/MISS case: hidden ... -> named ...`` (``+`` after hit/MISS: something else named too)."""
    mark = ("hit " if row["hit"] else "MISS") + (" " if row["clean"] or row["hidden"] is None else "+")
    size = "" if np.isnan(row["size_error"]) else f" (size off {100 * row['size_error']:.0f} %)"
    err = f"; ERROR {row['error'][:100]}" if row.get("error") else ""
    return (f"  [{i}/{n}] {mark} {row['case']}: hidden {_hidden_text(row['hidden'])} -> named {row['named']}{size}; "
            f"{row['body']['style']} {row['body']['height_m']:.2f} m {row['body']['mass_kg']:.0f} kg; "
            f"{row['wall_s']:.1f} s{err}")


def run_gap_human(case: GapCase, workdir: Path) -> dict:
    """:func:`run_one` as a batch case (:class:`~sit2stand.batch.engine.Job`'s ``run``)."""
    return run_one(case)


def gap_human_jobs(cases: list[GapCase]) -> list[Job]:
    """One batch job per digital human; its row shows the case, the body and what is hidden."""
    return [Job("gap-human", f"{c.case}_{c.index:02d}",
                {"case": c.case, "index": c.index, "style": c.style, "height_m": c.height_m, "mass_kg": c.mass_kg},
                run_gap_human, c) for c in cases]


def bench_gap_human(n: int = 20, cases: tuple[str, ...] = CASES, workers: int = 1, seed: int = 0,
                    progress: bool = True, vary_subject: bool = True, out: Path | None = None,
                    address: str | None = None) -> dict:
    """The human-side hit rates (see the module docstring): the rows as a batch (:mod:`sit2stand.batch.engine`:
    ``workers`` Ray workers, or the cluster at ``address``; 1: this process; its table in ``out``, default a
    temporary folder), figures per case and overall against the targets (``vary_subject`` False: bodies of
    de Leva's proportions, a diagnosis)."""
    todo = draw_cases(n, cases, seed, vary_subject)
    t0 = time.perf_counter()
    done = [0]

    def show(row: dict) -> None:
        done[0] += 1
        if progress:
            print(progress_line(done[0], len(todo), row) if row["status"] == "ok" else
                  f"  [{done[0]}/{len(todo)}] FAILED {row['key']}: {row['error']}", flush=True)
    with tempfile.TemporaryDirectory(prefix="sit2stand-gap-human-") as tmp:
        rows = run_jobs(gap_human_jobs(todo), out or Path(tmp), address=address, workers=workers, fresh=True,
                        on_row=show, label="bench-gap-human")
    rows = [r if r["status"] == "ok" else {**r, **FAILED_ROW, "hidden": c.hidden(), "wall_s": float("nan")}
            for r, c in zip(rows, todo)]
    out_rates = gap_human_rates(rows)
    out_rates.update({"humans_per_case": n, "workers": workers, "seed": seed, "vary_subject": vary_subject,
                      "wall_s": time.perf_counter() - t0})
    return out_rates


def _median_pct(values: list[float]) -> float:
    vals = [v for v in values if not np.isnan(v)]
    return float(100 * np.median(vals)) if vals else float("nan")


def gap_human_rates(rows: list[dict]) -> dict:
    """The benchmark's figures per case, overall against :data:`TARGETS`, the misses, and every row."""
    out: dict[str, object] = {}
    for name in dict.fromkeys(r["case"] for r in rows):
        rs = [r for r in rows if r["case"] == name]
        if name == "none":
            out["none_no_alarm_rate"] = float(np.mean([r["hit"] for r in rs]))
            out["none_no_effect_rate"] = float(np.mean([r["clean"] for r in rs]))
        else:
            out[f"{name}_hit_rate"] = float(np.mean([r["hit"] for r in rs]))
            out[f"{name}_clean_rate"] = float(np.mean([r["clean"] for r in rs]))
            out[f"{name}_clean_hit_rate"] = float(np.mean([r["hit"] and r["clean"] for r in rs]))
            out[f"{name}_found_rate"] = float(np.mean([r["found"] for r in rs]))
            out[f"{name}_median_size_error_pct"] = _median_pct([r["size_error"] for r in rs])
            if name in GROUPS and name not in SEGMENTS:
                out[f"{name}_wrong_side_rate"] = float(np.mean([r["wrong_side"] for r in rs]))
        out[f"{name}_wall_s"] = float(sum(r["wall_s"] for r in rs))
    effect = [r for r in rows if r["hidden"] is not None]
    if effect:
        out["hit_rate"] = float(np.mean([r["hit"] for r in effect]))
        out["clean_rate"] = float(np.mean([r["clean"] for r in effect]))
        out["clean_hit_rate"] = float(np.mean([r["hit"] and r["clean"] for r in effect]))
        out["median_size_error_pct"] = _median_pct([r["size_error"] for r in effect])
    for key, target in TARGETS.items():
        if key in out:
            out[f"{key}_vs_{100 * target:.0f}pct_target"] = out[key] / target
    out["runs"] = len(rows)
    out["errors"] = sum(bool(r.get("error")) for r in rows)
    out["run_s_median"] = float(np.median([r["wall_s"] for r in rows])) if rows else float("nan")
    out["misses"] = [{k: r.get(k) for k in ("case", "hidden", "named", "size_error", "verdict", "error")}
                     for r in rows if not (r["hit"] and r["clean"])]
    out["rows"] = rows
    return out


def summary_table(out: dict) -> str:
    """Per case: hits, clean, median size error, wall; then the overall rates against the targets."""
    n = out.get("humans_per_case", 0)
    rows = out.get("rows", [])
    lines = [f"  {'case':<10} {'hits':>6} {'clean':>6} {'both':>6} {'size err':>9} {'wall s':>7}"]
    for name in dict.fromkeys(r["case"] for r in rows):
        rs = [r for r in rows if r["case"] == name]
        hits, clean = sum(r["hit"] for r in rs), sum(r["clean"] for r in rs)
        both = sum(r["hit"] and r["clean"] for r in rs)
        err = out.get(f"{name}_median_size_error_pct", float("nan"))
        lines.append(f"  {name:<10} {hits:>3}/{n:<2} {clean:>3}/{n:<2} {both:>3}/{n:<2} "
                     f"{'' if np.isnan(err) else f'{err:.0f} %':>9} {out[f'{name}_wall_s']:>7.0f}")
    for key, target in TARGETS.items():
        if key in out:
            lines.append(f"  {key}: {100 * out[key]:.0f} % (target {100 * target:.0f} %)")
    return "\n".join(lines)
