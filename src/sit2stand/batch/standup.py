"""Stand-up batches: digital humans (a population, or a grid of statures, masses, seats, styles, robots and plants)
each synthesised, retargeted and simulated as one case of :mod:`sit2stand.batch.engine`.

A population (:func:`sample_population`): stature uniform in 1.5-1.95 m, body mass uniform in 50-110 kg within a BMI
of 17-38 (no implausible body: 50 kg at 1.95 m is a BMI of 13, 110 kg at 1.5 m one of 49), sex at random, seat
height 0.26 x stature (the synthesiser's default) +- 5 cm, and one of three styles in turn: ``natural`` (rise
1.4-1.8 s), ``elderly`` (2.6-3.4 s) and ``fast``, the natural kinematics rushed into 0.9-1.2 s (the synthesiser's
``duration_s``; it has no third style of its own). One RNG seed fixes the whole population. A grid
(:func:`grid_cases`, a YAML file) is every combination of the values it lists.

The synthesiser refuses some of its own random segment proportions (the chair and feet plates would overlap); such a
body is redrawn with the next seeds, same stature, mass, seat and style (``synth_seed`` says which), and a body
refused at every seed is a case with ``stage: synthesis`` and no robot run.

Each case runs :func:`sit2stand.retarget.offline.run` with ``--simulate`` (what ``sit2stand retarget BAG --simulate``
does) on its robot and plant, its figures those of :data:`FIGURES` from the run's summary.
"""

from __future__ import annotations

import dataclasses
import itertools
import shutil
import tempfile
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import yaml

from ..errors import InputError
from ..human.demonstration_bag import write_demonstration_bag
from ..human.synth import SynthConfig, synthesize
from ..retarget import offline
from ..robot.model import DEFAULT_ROBOT
from ..robot.plant import DEFAULT_CONTROLLER
from ..robot.profile import PROFILE_SUFFIXES
from .engine import Job

STYLES = ("natural", "elderly", "fast")
RISE_S = {"natural": (1.4, 1.8), "elderly": (2.6, 3.4), "fast": (0.9, 1.2)}
"""Rise duration range [s] per style (the synthesiser's defaults: natural 1.6 s, elderly 3.0 s)."""
SYNTH_STYLE = {"natural": "natural", "elderly": "elderly", "fast": "natural"}
HEIGHT_M = (1.5, 1.95)
MASS_KG = (50.0, 110.0)
BMI = (17.0, 38.0)
SEAT_OFFSET_M = 0.05
SEAT_FRACTION = 0.26            # the synthesiser's default seat height / stature
SYNTH_ATTEMPTS = 20            # seeds tried per case (the synthesiser refused 9 of 30 first draws at seed 0)


@dataclasses.dataclass(frozen=True)
class Case:
    """One digital human of the population."""

    index: int
    style: str
    height_m: float
    mass_kg: float
    sex: str
    seat_height_m: float
    rise_s: float
    seed: int
    marker_rate_hz: float = 100.0       # the capture's

    def config(self):
        """The synthesiser's configuration of this case."""
        return SynthConfig(style=SYNTH_STYLE[self.style], height_m=self.height_m, mass_kg=self.mass_kg, sex=self.sex,
                           seat_height_m=self.seat_height_m, duration_s=self.rise_s, seed=self.seed,
                           marker_rate_hz=self.marker_rate_hz)

    @property
    def name(self) -> str:
        return f"{self.index:02d}_{self.style}"


def sample_population(n: int, seed: int = 0, styles: tuple[str, ...] = STYLES,
                      marker_rate_hz: float = 100.0) -> list[Case]:
    """``n`` cases drawn from one RNG seeded with ``seed``; styles in turn, captured at ``marker_rate_hz``. The bodies
    do not depend on ``styles`` nor on the rate (every draw is made for every case), so ``--only-style`` and
    ``--marker-rate`` run the same people in another style or captured otherwise."""
    if n < 1:
        raise ValueError(f"the population needs at least 1 case, not {n}")
    unknown = [s for s in styles if s not in STYLES]
    if unknown or not styles:
        raise ValueError(f"styles must be among {', '.join(STYLES)}, not {', '.join(unknown) or 'none'}")
    rng = np.random.default_rng(seed)
    cases = []
    for i in range(n):
        height = float(rng.uniform(*HEIGHT_M))
        lo, hi = max(MASS_KG[0], BMI[0] * height**2), min(MASS_KG[1], BMI[1] * height**2)
        mass = float(rng.uniform(lo, hi))
        sex = "male" if rng.random() < 0.5 else "female"
        seat = SEAT_FRACTION * height + float(rng.uniform(-SEAT_OFFSET_M, SEAT_OFFSET_M))
        u_rise, case_seed = float(rng.random()), int(rng.integers(0, 2**31 - 1))
        style = styles[i % len(styles)]
        rise = RISE_S[style][0] + u_rise * (RISE_S[style][1] - RISE_S[style][0])
        cases.append(Case(i, style, round(height, 3), round(mass, 1), sex, round(seat, 3), round(rise, 2), case_seed,
                          marker_rate_hz))
    return cases


def synthesise(case: Case, attempts: int = SYNTH_ATTEMPTS):
    """The case's demonstration and the seed that made it. The synthesiser refuses some random segment proportions
    (``ValueError``, e.g. a joint angle out of its range; with ``vary_subject`` off every stature, seat and style
    here synthesises); those are redrawn with the next seeds, the same stature, mass, seat and style."""
    for k in range(attempts):
        try:
            return synthesize(dataclasses.replace(case.config(), seed=case.seed + k)), case.seed + k
        except ValueError as exc:
            last = exc
    raise ValueError(f"no demonstration in {attempts} seeds from {case.seed}: {last}")


FIGURES = ("stood_up", "fall", "time_scale", "time_scale_peak", "duration_ratio", "plan_duration_s",
           "com_tracking_rms_m", "com_deviation_rms_m", "com_deviation_max_m", "torque_demand_peak_ratio",
           "torque_demand_peak_joint", "torque_saturated_share", "infeasible_frames", "frames",
           "min_zmp_margin_on_feet_m", "zmp_outside_feet_share", "parameters", "controller_qp_ms_p99",
           "controller_qp_cpu_ms_p99", "final_knee_flexion_deg_robot", "final_knee_flexion_deg_human",
           "final_pelvis_height_ratio", "final_pelvis_pitch_deg", "standing_knees_match", "posture_rms_deg",
           "marker_rms_mm", "plan", "plan_ratio_whole", "plan_ratio_frames", "whole_rise_time_scale",
           "whole_rise_solve_s", "whole_rise_com_relaxed")
"""What a stand-up case reports, from the retarget run's summary (see ``sit2stand retarget``)."""


@dataclasses.dataclass(frozen=True)
class Setting:
    """What a case runs on: the robot profile, the plant, the controller, identified parameters (None: CAD), and how
    ``sit2stand retarget`` plans (:data:`~sit2stand.retarget.offline.PLANS`)."""

    robot: str = DEFAULT_ROBOT
    plant: str = "default"
    controller: str = DEFAULT_CONTROLLER
    params: str | None = None
    plan: str = offline.DEFAULT_PLAN

    @property
    def label(self) -> str:
        """The robot and plant in a case's key and folder name: a profile file by its name, not its path (whose
        slashes made the folder a tree of the path's directories)."""
        robot = Path(self.robot)
        name = robot.stem if robot.suffix in PROFILE_SUFFIXES else self.robot
        return f"{name}_{self.plant}"


def run_standup(arg: tuple[Case, Setting], workdir: Path) -> dict:
    """One case (a :class:`Job`'s ``run``): synthesise, bag, retarget and simulate; its figures. Its retarget
    folder is ``workdir/<case name>``."""
    case, setting = arg
    try:
        demo, synth_seed = synthesise(case)
    except ValueError as err:
        return {"stood_up": False, "stage": "synthesis", "synthesis_error": str(err)}
    out = Path(workdir) / f"{case.name}_{setting.label}"
    shutil.rmtree(out, ignore_errors=True)        # a try before this one's (its bag is never overwritten)
    with tempfile.TemporaryDirectory(prefix="sit2stand-batch-") as tmp:
        write_demonstration_bag(demo, Path(tmp) / case.name)
        summary = offline.run(Path(tmp) / case.name, out, params=setting.params, plant=setting.plant,
                              simulate=True, controller=setting.controller, robot=setting.robot, plan=setting.plan)
    return {"synth_seed": synth_seed, "human_rise_s": round(demo.rise_end_s - demo.rise_start_s, 3),
            **{k: summary.get(k) for k in FIGURES}}


def standup_jobs(cases: list[tuple[Case, Setting]]) -> list[Job]:
    """The batch's jobs: one per (case, setting); the row shows the body, the style, the robot and the plant."""
    return [Job("standup", f"{c.name}_{s.label}", {**dataclasses.asdict(c), **dataclasses.asdict(s)},
                run_standup, (c, s)) for c, s in cases]


GRID_KEYS = {"height_m": float, "mass_kg": float, "seat_height_m": float, "style": str, "robot": str, "plant": str,
             "sex": str, "rise_s": float}
"""What a grid file may list (each a value or a list): the stature [m], body mass [kg], seat height [m], style,
robot profile, plant, sex, rise duration [s]; a key left out takes the synthesiser's default (1.75 m, 75 kg, seat
0.26 x stature, natural, male, the style's rise) or the batch's robot and plant."""


def grid_cases(path: Path, seed: int = 0, setting: Setting = Setting()) -> list[tuple[Case, Setting]]:
    """Every combination of a grid file's values (see :data:`GRID_KEYS`), each case with its own seed from ``seed``.

    Raises:
        InputError: the file is not a mapping of the known keys to values or lists (naming the file and the key).
    """
    try:
        doc = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as err:
        raise InputError(f"{path}: cannot read the grid: {err}") from None
    if not isinstance(doc, dict) or not doc:
        raise InputError(f"{path}: a grid maps {', '.join(GRID_KEYS)} to values or lists")
    axes = {}
    for key, values in doc.items():
        if key not in GRID_KEYS:
            raise InputError(f"{path}: field {key!r}: not a grid key (known: {', '.join(GRID_KEYS)})")
        values = values if isinstance(values, list) else [values]
        try:
            axes[key] = [GRID_KEYS[key](v) for v in values]
        except (TypeError, ValueError):
            raise InputError(f"{path}: field {key!r}: {values!r} is not a list of {GRID_KEYS[key].__name__}") \
                from None
        if key == "style" and set(axes[key]) - set(STYLES):
            raise InputError(f"{path}: field 'style': {axes[key]}: styles are {', '.join(STYLES)}")
    out = []
    for i, combo in enumerate(itertools.product(*axes.values())):
        v = dict(zip(axes, combo))
        height = v.get("height_m", 1.75)
        style = v.get("style", "natural")
        rise = v.get("rise_s", float(np.mean(RISE_S[style])))
        case = Case(i, style, height, v.get("mass_kg", 75.0), v.get("sex", "male"),
                    v.get("seat_height_m", round(SEAT_FRACTION * height, 3)), rise, seed + i)
        out.append((case, dataclasses.replace(setting, robot=v.get("robot", setting.robot),
                                              plant=v.get("plant", setting.plant))))
    return out


def plot_batch(table: pd.DataFrame, png: Path) -> Path:
    """Success and time scale against stature, body mass and seat height, one point per case (stood up, fell, or
    failed: the case raised twice; refused by the synthesiser: left out)."""
    matplotlib.use("Agg")
    fig, axes = plt.subplots(1, 3, figsize=(13, 4), sharey=True)
    ok = table[table["status"] == "ok"]
    if "stage" in ok:
        ok = ok[ok["stage"].isna()]
    stood = ok["stood_up"].astype(bool) if len(ok) else ok.get("stood_up", pd.Series(dtype=bool))
    scale = ok["time_scale"].astype(float) if "time_scale" in ok else pd.Series(np.nan, index=ok.index)
    failed = table[table["status"] == "failed"]
    top = float(np.nanmax(scale)) if scale.notna().any() else 1.5
    for ax, (col, label) in zip(axes, (("height_m", "stature [m]"), ("mass_kg", "body mass [kg]"),
                                      ("seat_height_m", "seat height [m]"))):
        ax.scatter(ok[col][stood], scale[stood], c="tab:green", label="stood up", s=28)
        ax.scatter(ok[col][~stood], scale[~stood].fillna(top), c="tab:red", marker="v", label="fell / did not stand",
                   s=36)
        ax.scatter(failed[col], np.full(len(failed), top * 1.05), c="grey", marker="x", label="failed (error)", s=36)
        ax.axhline(1.0, color="k", lw=0.8, ls=":")
        ax.set_xlabel(label)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("time scale (robot / human rise)")
    n = len(table)
    axes[0].set_title(f"stood up {int(stood.sum())} of {len(ok)} run ({n} cases, {len(failed)} failed)", loc="left",
                      fontsize=10)
    axes[-1].legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png
