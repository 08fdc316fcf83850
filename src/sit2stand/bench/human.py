"""`make bench-human`: the human COM on real lab trials, judged by Newton's law (no ground truth needed).

Per real recording in ``../shared/data/real/`` (read in place): the offline estimator's COM with COP-matched masses
and without (the anthropometric table alone), and the capture software's own COM where the file has one (Vicon's
``CentreOfMass``). Each is scored by the residual of Newton's law for the whole body, F_plates - m (a_com + g z), RMS
per axis [N] over the frames whose whole weight is on the plates (the same frames for every COM of a trial), a_com by
a Savitzky-Golay second derivative (0.3 s, order 4). On subject01, also OpenSim's own COM: the generic Gait2392
model scaled on ``subject01_static.trc`` and fitted by OpenSim's IK (:mod:`sit2stand.bench.opensim`; PyPI ``opensim``
4.6 in a venv of its own, made on demand, and a checkout of opensim-models named by ``SIT2STAND_OPENSIM_MODELS``);
without them the table says why. Printed as a table and written to JSON.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import project_folder
from .opensim import opensim_com
from ..human.com import estimate_com
from ..human.marker_sets import choose_marker_set
from ..human.offline import Trial, newton_residual, read_trial
from ..human.skeleton import Subject
from ..io.c3d import read_c3d, write_trial_bag
from ..io.trc import read_opensim_trial



def _real() -> Path:
    """The real recordings of other labs, beside the project (``../shared/data/real``)."""
    return project_folder().parent / "shared" / "data" / "real"


@dataclass
class RealTrial:
    """A real recording and how a lab would import it."""

    name: str
    files: tuple[str, ...]
    feet_plate: int | None = None
    height_m: float | None = None
    mass_kg: float | None = None
    opensim_static: str | None = None       # a Gait2392 static trial: OpenSim's scaled COM is scored too


TRIALS = [
    RealTrial("sts_child_vicon_01 (sit-to-stand, Vicon)", ("sts_child_vicon_01.c3d",), feet_plate=2),
    RealTrial("subject01_walk1 (walking, OpenSim Gait2392)", ("subject01_walk1.trc", "subject01_walk1_grf.mot"),
              height_m=1.8, mass_kg=72.6, opensim_static="subject01_static.trc"),
]


def _import(trial: RealTrial, out: Path) -> Path:
    """The trial as a bag, as `sit2stand import-c3d` / `import-trc` write it."""
    paths = [_real() / f for f in trial.files]
    if paths[0].suffix == ".c3d":
        lab = read_c3d(paths[0], feet_plate=trial.feet_plate)
    else:
        lab = read_opensim_trial(paths[0], paths[1], mass_kg=trial.mass_kg, height_m=trial.height_m)
    write_trial_bag(lab, out)
    return out


def _rms(residual: np.ndarray, frames: np.ndarray) -> list[float]:
    return np.sqrt(np.mean(residual[frames] ** 2, axis=0)).round(2).tolist()


def score(bag: Path, real: RealTrial | None = None) -> dict:
    """Newton residuals [N] (x, y, z RMS) of the COMs of one imported trial (``real``: how it was imported)."""
    trial: Trial = read_trial(bag)
    subject = Subject(trial.height_m, trial.mass_kg, trial.sex,
                      marker_set=choose_marker_set(trial.marker_names, None))
    chair = any(p.name == "chair" for p in trial.plates)
    coms = {}
    for label, scale in (("ours, COP-matched masses", True), ("ours, table masses", False)):
        res = estimate_com(trial.marker_t_s, trial.marker_names, trial.positions, trial.valid, trial.plates,
                           subject, scale_masses=scale, chair_on_plate=chair)
        coms[label] = res.com_m
    mass = res.subject.mass_kg                  # the plates' weighing when it differs from the file's
    if trial.reference is not None:
        t, com, ok = trial.reference
        coms["the capture software's own"] = np.stack([np.interp(res.t_s, t[ok], com[ok, i]) for i in range(3)], 1)
    extra = {}
    if real is not None and real.opensim_static:
        folder = _real()
        com, extra["opensim"] = opensim_com(folder / real.opensim_static, folder / real.files[0], mass,
                                            subject.height_m, res.t_s)
        if com is not None:
            coms["OpenSim, scaled Gait2392"] = com
    residuals = {k: newton_residual(res.t_s, c, trial.plates, mass) for k, c in coms.items()}
    frames = res.supported & next(iter(residuals.values()))[1]
    return {"frames": int(frames.sum()), "mass_kg": round(float(mass), 2), "marker_set": subject.marker_set.name,
            "newton_residual_rms_xyz_n": {k: _rms(r, frames) for k, (r, _) in residuals.items()}, **extra}


def bench_human_real(trials: list[RealTrial] = TRIALS) -> dict:
    """:func:`score` for each real trial that is on this machine."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for i, trial in enumerate(trials):
            if not all((_real() / f).is_file() for f in trial.files):
                out[trial.name] = {"skipped": f"not on this machine ({_real()})"}
                continue
            print(f"  {trial.name} ...", flush=True)
            out[trial.name] = score(_import(trial, Path(tmp) / f"trial{i}"), trial)
    return out


def print_table(results: dict) -> None:
    """The residuals as a table: one row per trial and COM."""
    print(f"  {'trial':<46} {'COM':<30} {'frames':>6}  Newton residual RMS x / y / z [N]")
    for name, r in results.items():
        if "skipped" in r:
            print(f"  {name:<46} skipped: {r['skipped']}")
            continue
        for label, (x, y, z) in r["newton_residual_rms_xyz_n"].items():
            print(f"  {name:<46} {label:<30} {r['frames']:>6}  {x:6.1f} / {y:6.1f} / {z:6.1f}")
        opensim = r.get("opensim", {})
        if "skipped" in opensim:
            print(f"  {name:<46} {'OpenSim, scaled Gait2392':<30} skipped: {opensim['skipped']}")
        elif opensim:
            print(f"  {'':<46} (OpenSim IK: marker RMS {opensim['ik_marker_rms_mm']} mm, "
                  f"{opensim['ik_ms_per_frame']} ms per frame)")
