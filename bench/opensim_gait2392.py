"""OpenSim's own COM of a Gait2392 subject: scale the generic model on a static trial, run IK on a trial, write the
model's COM per frame. Runs in a venv with PyPI ``opensim`` 4.6 (``make bench-human`` makes one on demand), not in
sit2stand's: it imports nothing of sit2stand, and only opensim and the standard library.

    python opensim_gait2392.py MODELS_DIR STATIC.trc TRIAL.trc MASS_KG HEIGHT_M OUT.csv

MODELS_DIR is a checkout of github.com/opensim-org/opensim-models (the generic model
``Models/Gait2392_Simbody/gait2392_thelen2003muscle.osim``, the scale set-up and marker set of
``Pipelines/Gait2392_Simbody``). Scaling follows ``subject01_Setup_Scale.xml`` (marker-pair measurements, then the
marker placer on the static trial); IK weights follow ``subject01_Setup_IK.xml``. OUT.csv: ``t,x,y,z`` in OpenSim's
ground frame (x forward, y up, z right) [s, m], one row per trial frame; the last line is a comment with the IK
marker RMS [m] and the time per frame [s].
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import opensim as osim

GENERIC = "Models/Gait2392_Simbody/gait2392_thelen2003muscle.osim"
PIPELINE = "Pipelines/Gait2392_Simbody"


def scale(models: Path, static: Path, mass_kg: float, height_m: float, work: Path) -> Path:
    """The generic model scaled and its markers placed on ``static``; returns the scaled model's path."""
    tool = osim.ScaleTool(str(models / PIPELINE / "subject01_Setup_Scale.xml"))
    tool.setPathToSubject("")           # else every path below is taken relative to the set-up file's folder
    tool.setSubjectMass(mass_kg)
    tool.setSubjectHeight(height_m * 1e3)
    maker = tool.getGenericModelMaker()
    maker.setModelFileName(str(models / GENERIC))
    maker.setMarkerSetFileName(str(models / PIPELINE / "gait2392_Scale_MarkerSet.xml"))
    t0, t1 = _time_range(static)
    scaler, placer = tool.getModelScaler(), tool.getMarkerPlacer()
    scaler.setMarkerFileName(str(static))
    scaler.setTimeRange(_range(t0, t1))
    scaler.setOutputModelFileName(str(work / "scaled_only.osim"))
    placer.setMarkerFileName(str(static))
    placer.setTimeRange(_range(t0, t1))
    out = work / "subject_scaled.osim"
    placer.setOutputModelFileName(str(out))
    placer.setOutputMotionFileName(str(work / "static_output.mot"))
    if not tool.run():
        raise SystemExit(f"{static}: OpenSim's ScaleTool failed")
    return out


def _range(t0: float, t1: float) -> osim.ArrayDouble:
    r = osim.ArrayDouble()
    r.append(t0)
    r.append(t1)
    return r


def _time_range(trc: Path) -> tuple[float, float]:
    table = osim.TimeSeriesTableVec3(str(trc))
    t = table.getIndependentColumn()
    return float(t[0]), float(t[-1])


def inverse_kinematics(model_file: Path, models: Path, trial: Path, work: Path) -> tuple[Path, Path, float]:
    """IK of ``trial`` on the scaled model; returns (motion file, marker error file, seconds per frame)."""
    tool = osim.InverseKinematicsTool(str(models / PIPELINE / "subject01_Setup_IK.xml"))
    model = osim.Model(str(model_file))
    tool.setModel(model)
    tool.setMarkerDataFileName(str(trial))
    t0, t1 = _time_range(trial)
    tool.setStartTime(t0)
    tool.setEndTime(t1)
    out = work / "ik.mot"
    tool.setOutputMotionFileName(str(out))
    tool.set_report_errors(True)
    tool.setResultsDir(str(work))
    start = time.perf_counter()
    if not tool.run():
        raise SystemExit(f"{trial}: OpenSim's InverseKinematicsTool failed")
    n = osim.TimeSeriesTable(str(out)).getNumRows()
    errors = next(work.glob("*ik_marker_errors.sto"))       # named after the set-up's tool name
    return out, errors, (time.perf_counter() - start) / max(1, n)


def com_series(model_file: Path, motion: Path) -> list[tuple[float, float, float, float]]:
    """(t, x, y, z) of the model's COM at each row of the IK motion (degrees, as IK writes it)."""
    model = osim.Model(str(model_file))
    state = model.initSystem()
    table = osim.TimeSeriesTable(str(motion))
    labels = list(table.getColumnLabels())
    coords = model.getCoordinateSet()
    rows = []
    for i in range(table.getNumRows()):
        values = table.getRowAtIndex(i)
        for j, name in enumerate(labels):
            if coords.contains(name):
                c = coords.get(name)
                v = values[j]
                c.setValue(state, v * 3.141592653589793 / 180 if c.getMotionType() == 1 else v, False)
        model.assemble(state)
        model.realizePosition(state)
        p = model.calcMassCenterPosition(state)
        rows.append((float(table.getIndependentColumn()[i]), p.get(0), p.get(1), p.get(2)))
    return rows


def marker_rms(errors: Path) -> float:
    """RMS over frames of IK's per-frame marker RMS [m]."""
    table = osim.TimeSeriesTable(str(errors))
    col = list(table.getColumnLabels()).index("marker_error_RMS")
    values = [table.getRowAtIndex(i)[col] for i in range(table.getNumRows())]
    return (sum(v * v for v in values) / len(values)) ** 0.5


def main(argv: list[str]) -> int:
    models, static, trial = Path(argv[0]), Path(argv[1]), Path(argv[2])
    mass_kg, height_m, out = float(argv[3]), float(argv[4]), Path(argv[5])
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        scaled = scale(models, static, mass_kg, height_m, work)
        motion, errors, per_frame_s = inverse_kinematics(scaled, models, trial, work)
        rows = com_series(scaled, motion)
        rms = marker_rms(errors)
    lines = ["t,x,y,z"] + [f"{t:.6f},{x:.6f},{y:.6f},{z:.6f}" for t, x, y, z in rows]
    lines.append(f"# marker_rms_m={rms:.6f} ik_s_per_frame={per_frame_s:.6f}")
    out.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
