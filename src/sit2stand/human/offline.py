"""`sit2stand human-com BAG --out DIR`: the human COM estimator on a whole bag, with evaluation and a figure.

Reads ``/mocap/markers`` and every ``/force_plate/*`` topic, runs :func:`sit2stand.human.com.estimate_com`, and
writes into DIR: a bag ``human_com`` (``/human/com``, ``/human/model_cop``, ``/human/joint_states``,
``/human/scaling``), ``summary.json`` and ``human_com.png``. When the bag carries a reference it is evaluated:
``/ground_truth/com`` (synthetic demonstrations) gives the COM error; ``/mocap/reference_com`` (the capture
software's own COM, e.g. Vicon's ``CentreOfMass``) gives the distance to it and, in the standing phase, both COMs'
horizontal distance to the measured COP. Every trial gets the residual of Newton's law on the COM
(:func:`newton_residual`) over the frames whose whole weight is on the plates. The COM and the joint angles also go
to ``com.csv``, ``joint_angles.csv`` and an OpenSim ``human_states.sto`` (:mod:`sit2stand.human.export`).

The marker set is the one given, else the packaged set that covers most of the bag's marker names
(:func:`sit2stand.human.marker_sets.choose_marker_set`): Plug-in-Gait, its lower body, or OpenSim's Gait2392.
"""

from __future__ import annotations

import json
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from ..errors import InputError
from ..io import messages as M
from ..io.bag import BagError, BagReader, BagWriter, bag_subject
from ..forceplate import PlateSeries
from ..io.topics import (COM_TYPE, FORCE_PLATE_PREFIX, GROUND_TRUTH_COM_TOPIC, HUMAN_COM_TOPIC, HUMAN_JOINTS_TOPIC,
                         HUMAN_MODEL_COP_TOPIC, HUMAN_SCALING_TOPIC, MARKERS_TOPIC, REFERENCE_COM_TOPIC,
                         SUBJECT_TOPIC)
from ..dynamics import G, savgol_series
from ..io.typestore import typestore
from ..io.c3d import read_c3d
from ..io.trc import read_trc
from .calibration import StreamCalibration, calibrate_stream
from .calibration_frames import FrameChoice, frames_at, quiet_frames
from .com import ComResult, estimate_com
from .export import write_exports
from .marker_ik import MarkerUnitsError
from .marker_sets import MarkerSet, choose_marker_set
from .skeleton import Subject, build_human
from .support import plate_wrench_at

NEWTON_WINDOW_S = 0.3
"""Savitzky-Golay window [s] (order 4) of the COM's second derivative and the plate force in :func:`newton_residual`."""


@dataclass
class Trial:
    """Arrays of one bag: markers at their rate, plates at theirs, what the lab knows of the subject."""

    marker_t_s: np.ndarray
    marker_names: list[str]
    positions: np.ndarray
    valid: np.ndarray
    plates: list[PlateSeries]
    height_m: float | None
    mass_kg: float | None
    sex: str
    truth: tuple[np.ndarray, np.ndarray] | None          # (t, com)
    reference: tuple[np.ndarray, np.ndarray, np.ndarray] | None   # (t, com, valid)


def read_trial(bag_path: str | Path) -> Trial:
    """Load markers, plates and metadata of a bag (names the bag and topic on any problem)."""
    with BagReader(bag_path) as bag:
        topics = bag.topics()
        if MARKERS_TOPIC not in topics:
            raise BagError(f"{bag_path}: no {MARKERS_TOPIC} topic (it has {', '.join(sorted(topics))})")
        frames = bag.read(MARKERS_TOPIC)
        if not frames:
            raise BagError(f"{bag_path}: {MARKERS_TOPIC} has no messages")
        names = list(frames[0][1].marker_names)
        t = np.array([ts for ts, _ in frames]) * 1e-9
        pos = np.full((len(frames), len(names), 3), np.nan)
        valid = np.zeros((len(frames), len(names)), bool)
        for k, (_, msg) in enumerate(frames):
            pos[k], valid[k] = M.reorder_markers(*M.mocap_arrays(msg), names)
        plates = [M.plate_series(topic[len(FORCE_PLATE_PREFIX):], bag.read(topic))
                  for topic in sorted(topics) if topic.startswith(FORCE_PLATE_PREFIX)]
        custom = bag.custom_data
        subject_msg = bag.read(SUBJECT_TOPIC)[-1][1] if bag.topics().get(SUBJECT_TOPIC) else None
        truth = reference = None
        if GROUND_TRUTH_COM_TOPIC in topics:
            msgs = bag.read(GROUND_TRUTH_COM_TOPIC)
            truth = (np.array([ts for ts, _ in msgs]) * 1e-9,
                     np.array([[m.position.x, m.position.y, m.position.z] for _, m in msgs]))
        if REFERENCE_COM_TOPIC in topics:
            msgs = bag.read(REFERENCE_COM_TOPIC)
            reference = (np.array([ts for ts, _ in msgs]) * 1e-9,
                         np.array([[m.position.x, m.position.y, m.position.z] for _, m in msgs]),
                         np.array([m.valid for _, m in msgs]))
    named = bag_subject(custom)
    height_m, mass_kg, sex = (named.height_m, named.mass_kg, named.sex) if named else (None, None, "male")
    if named is None and subject_msg is not None:     # custom_data lost (ROS 1, recorder)
        height_m, mass_kg, sex = subject_msg.height_m, subject_msg.mass_kg, subject_msg.sex or sex
    return Trial(t, names, pos, valid, plates, height_m, mass_kg, sex, truth, reference)


def standing_phase(result: ComResult, fraction: float = 0.95) -> np.ndarray:
    """Frames after the rise: COM height within (1 - fraction) of its final rise, from the last time it got there."""
    z = result.com_m[:, 2]
    lo, hi = np.min(z), np.median(z[-max(5, len(z) // 10):])
    thresh = lo + fraction * (hi - lo)
    below = np.flatnonzero(z < thresh)
    start = below[-1] + 1 if len(below) else 0
    out = np.zeros(len(z), bool)
    out[start:] = True
    return out


def newton_residual(t_s: np.ndarray, com_m: np.ndarray, plates: list[PlateSeries], mass_kg: float,
                    window_s: float = NEWTON_WINDOW_S, order: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Newton's law on the COM, F_plates = m (a_com + g z): its residual F_plates - m (a_com + g z) [N], (N, 3).

    a_com is the Savitzky-Golay second derivative of the COM (``window_s``, ``order``); the plates' summed force at
    the marker times is smoothed by the same filter (one bandwidth for both). Only frames whose whole weight is on
    the plates can satisfy it. Also returns (N,) True where every plate has samples around the frame."""
    dt = float(np.median(np.diff(t_s)))
    window = min(2 * int(round(window_s / dt / 2)) + 1, len(t_s) - (1 - len(t_s) % 2))
    acc = savgol_series(np.asarray(com_m, float), window, order, 2) / dt**2
    force, _, covered = plate_wrench_at(np.asarray(t_s, float), plates, dt / 2)
    force = savgol_series(force, window, order, 0)
    return force - mass_kg * (acc + np.array([0.0, 0.0, G])), covered


def evaluate(trial: Trial, result: ComResult) -> dict:
    """Figures of merit: COP fit, and against the truth / the capture software's COM where present."""
    out: dict = {
        "frames": int(len(result.t_s)), "frames_fitted": int(result.fit_ok.sum()),
        "frames_supported": int(result.supported.sum()),
        "marker_rms_mm": float(np.nanmean(result.marker_rms_m) * 1e3),
        "calibration_marker_rms_mm": [result.calibration_rms_before_m * 1e3, result.calibration_rms_after_m * 1e3],
        "cop_rms_unscaled_mm": result.scaling.cop_rms_before_m * 1e3,
        "cop_rms_scaled_mm": result.scaling.cop_rms_after_m * 1e3,
        "cop_within_2cm": bool(result.scaling.cop_rms_after_m <= 0.02),
        "mass_factors": {k: round(v, 4) for k, v in result.scaling.factors().items()},
        "torso_com_shift_mm": (result.scaling.torso_com_shift_m * 1e3).round(2).tolist(),
        "segment_length_factors": {k: round(v, 4) for k, v in result.subject.lengths.items()},
        "scaling_condition_number": result.scaling.condition_number,
        "plate_gaps": [{"plate": p, "from_s": a, "to_s": b} for p, a, b in result.plate_gaps],
        "body_mass_used_kg": result.subject.mass_kg,
        "segment_table": result.segment_table,
        "factors_at_bounds": [{"kind": f.kind, "group": f.group, "factor": round(f.factor, 4), "bound": f.bound,
                               "side": f.side} for f in result.at_bounds],
        "notes": result.notes,
    }
    if trial.plates and len(result.t_s) > 10:
        residual, covered = newton_residual(result.t_s, result.com_m, trial.plates, result.subject.mass_kg)
        sel = result.supported & covered
        if sel.any():
            out["newton_residual_frames"] = int(sel.sum())
            out["newton_residual_rms_xyz_n"] = np.sqrt(np.mean(residual[sel] ** 2, axis=0)).round(2).tolist()
    if trial.truth is not None:
        tt, com = trial.truth
        truth = np.array([np.interp(result.t_s, tt, com[:, i]) for i in range(3)]).T
        for name, est in (("scaled", result.com_m), ("unscaled", result.com_unscaled_m)):
            err = est - truth
            out[f"com_rms_vs_truth_{name}_mm"] = float(np.sqrt(np.mean(np.sum(err**2, axis=1))) * 1e3)
            out[f"com_rms_vs_truth_{name}_xyz_mm"] = (np.sqrt(np.mean(err**2, axis=0)) * 1e3).round(2).tolist()
    stand = standing_phase(result) & result.supported & np.all(np.isfinite(result.measured_cop_m), axis=1)
    if stand.any():
        d_ours = np.linalg.norm(result.com_m[stand, :2] - result.measured_cop_m[stand, :2], axis=1)
        out["standing_frames"] = int(stand.sum())
        out["standing_com_to_cop_mm"] = {"mean": float(d_ours.mean() * 1e3), "max": float(d_ours.max() * 1e3)}
    if trial.reference is not None:
        tr, ref, ok = trial.reference
        refi = np.array([np.interp(result.t_s, tr[ok], ref[ok, i]) for i in range(3)]).T
        out["com_rms_vs_reference_mm"] = float(np.sqrt(np.mean(np.sum((result.com_m - refi) ** 2, axis=1))) * 1e3)
        if stand.any():
            d_ref = np.linalg.norm(refi[stand, :2] - result.measured_cop_m[stand, :2], axis=1)
            out["standing_reference_com_to_cop_mm"] = {"mean": float(d_ref.mean() * 1e3),
                                                        "max": float(d_ref.max() * 1e3)}
    return out


def figure(trial: Trial, result: ComResult, png: Path, title: str) -> None:
    """COM (forward and vertical) and the COPs against time, plus the sagittal COM path."""

    matplotlib.use("Agg")

    t = result.t_s - result.t_s[0]
    fig, axes = plt.subplots(2, 2, figsize=(12, 7.5))
    ax = axes[0, 0]
    ax.plot(t, result.com_m[:, 0], label="COM x, scaled model", lw=2)
    ax.plot(t, result.com_unscaled_m[:, 0], "--", label="COM x, average model")
    ax.plot(t, result.measured_cop_m[:, 0], color="0.6", lw=0.8, label="measured COP x (all plates)")
    ax.plot(t, result.model_cop_m[:, 0], ":", label="model COP x (scaled)")
    ax = axes[1, 0]
    ax.plot(t, result.com_m[:, 2], label="COM z, scaled model", lw=2)
    ax.plot(t, result.com_unscaled_m[:, 2], "--", label="COM z, average model")
    for key, data, style in (("truth", trial.truth, "k-"), ("capture software", trial.reference, "k-.")):
        if data is not None:
            tt = data[0] - result.t_s[0]
            axes[0, 0].plot(tt, data[1][:, 0], style, lw=1, label=f"COM x, {key}")
            axes[1, 0].plot(tt, data[1][:, 2], style, lw=1, label=f"COM z, {key}")
            axes[0, 1].plot(data[1][:, 0], data[1][:, 2], style, lw=1, label=key)
    axes[0, 1].plot(result.com_m[:, 0], result.com_m[:, 2], lw=2, label="scaled model")
    axes[0, 1].plot(result.com_unscaled_m[:, 0], result.com_unscaled_m[:, 2], "--", label="average model")
    axes[0, 1].set_xlabel("COM x (forward) [m]")
    axes[0, 1].set_ylabel("COM z [m]")
    axes[0, 1].set_title("sagittal COM path")
    axes[0, 1].axis("equal")
    err = np.linalg.norm(result.model_cop_m[:, :2] - result.measured_cop_m[:, :2], axis=1)
    axes[1, 1].plot(t, err * 1e3, label="|model COP - measured COP| [mm]")
    axes[1, 1].plot(t, result.marker_rms_m * 1e3, label="marker fit RMS [mm]")
    axes[1, 1].fill_between(t, 0, np.where(result.supported, 5, np.nan), color="g", alpha=0.15,
                            label="whole weight on plates")
    axes[1, 1].set_ylim(0, max(40, np.nanpercentile(err * 1e3, 98) * 1.2 if np.isfinite(err).any() else 40))
    for a, label in ((axes[0, 0], "forward [m]"), (axes[1, 0], "height [m]"), (axes[1, 1], "[mm]")):
        a.set_xlabel("time [s]")
        a.set_ylabel(label)
    for a in axes.ravel():
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def write_result_bag(result: ComResult, out: Path, joint_names: list[str]) -> None:

    store = typestore().types
    with BagWriter(out) as bag:
        bag.add_topic(HUMAN_COM_TOPIC, COM_TYPE)
        bag.add_topic(HUMAN_MODEL_COP_TOPIC, "geometry_msgs/msg/PointStamped")
        bag.add_topic(HUMAN_JOINTS_TOPIC, "sensor_msgs/msg/JointState")
        bag.add_topic(HUMAN_SCALING_TOPIC, "sit2stand_msgs/msg/InertialParameters")
        t0 = int(round(result.t_s[0] * 1e9))
        bag.write(HUMAN_SCALING_TOPIC, t0, store["sit2stand_msgs/msg/InertialParameters"](
            header=M.header(t0), model="human_scaling",
            names=[f"{g}.mass" for g in result.scaling.masses] + [f"{g}.length_factor" for g in result.subject.lengths]
            + ["torso.com_shift_x"],
            values=np.array(list(result.scaling.masses.values()) + list(result.subject.lengths.values())
                            + [result.scaling.torso_com_shift_m[0]]),
            std_devs=np.full(len(result.scaling.masses) + len(result.subject.lengths) + 1, np.nan), yaml_path=""))
        for k, ts in enumerate(result.t_s):
            t_ns = int(round(ts * 1e9))
            bag.write(HUMAN_COM_TOPIC, t_ns, M.center_of_mass(
                t_ns, result.com_m[k], result.com_vel[k], result.com_acc[k], source="skeleton_fit",
                valid=bool(result.fit_ok[k]), marker_rms_m=float(result.marker_rms_m[k]),
                cop_error_m=float(np.linalg.norm(result.model_cop_m[k, :2] - result.measured_cop_m[k, :2])),
                n_markers=int(result.n_markers[k])))
            p = store["geometry_msgs/msg/PointStamped"](header=M.header(t_ns), point=store["geometry_msgs/msg/Point"](
                x=float(result.model_cop_m[k, 0]), y=float(result.model_cop_m[k, 1]), z=0.0))
            bag.write(HUMAN_MODEL_COP_TOPIC, t_ns, p)
            bag.write(HUMAN_JOINTS_TOPIC, t_ns, store["sensor_msgs/msg/JointState"](
                header=M.header(t_ns), name=["pelvis_x", "pelvis_y", "pelvis_z", "pelvis_qx", "pelvis_qy",
                                                       "pelvis_qz", "pelvis_qw"] + joint_names,
                position=result.q[k].astype(float), velocity=np.zeros(0), effort=np.zeros(0)))


def run(bag_path: Path, out_dir: Path, *, height_m: float | None = None, mass_kg: float | None = None,
        sex: str | None = None, calibrate: bool = True, scale: bool = True, quiet: bool = False,
        marker_set: MarkerSet | str | None = None, calibration_frame: int | str | None = None,
        static: str | Path | None = None) -> dict:
    """The whole offline job; returns the summary dict (also written to OUT/summary.json). ``marker_set``: a
    packaged set's name, a file or a MarkerSet; None chooses from the bag's marker names. The skeleton is calibrated
    on every frame of the trial, unless ``calibration_frame`` (a frame, or ``"auto"``: :func:`choose_frames`) or a
    ``static`` trial says where."""
    trial = read_trial(bag_path)
    height = height_m or trial.height_m
    mass = mass_kg or trial.mass_kg
    if height is None or mass is None:
        raise BagError(f"{bag_path}: the subject's {'height' if height is None else 'mass'} is not in the bag's "
                       f"metadata; give --height/--mass")
    markers = choose_marker_set(trial.marker_names, marker_set)
    subject = Subject(height, mass, sex or trial.sex, marker_set=markers)
    chair = any(p.name == "chair" for p in trial.plates)

    def progress(k: int, n: int) -> None:
        if not quiet and (k == n or k % max(1, n // 10) == 0):
            print(f"  marker fit: frame {k} of {n}", file=sys.stderr, flush=True)

    if not quiet:
        print(f"{bag_path}: {len(trial.marker_names)} markers x {len(trial.marker_t_s)} frames, plates "
              f"{', '.join(p.name for p in trial.plates)}; subject {height:g} m, {mass:g} kg"
              f"{'' if chair else ' (chair not on a plate: scaling uses frames after seat-off)'}", file=sys.stderr)
        print(f"  marker set {markers.name}: {len(markers.covered(trial.marker_names))} of the "
              f"{len(trial.marker_names)} markers", file=sys.stderr)
    made = None
    if calibrate and (calibration_frame is not None or static is not None):
        made, reason = calibrate_subject(trial, subject, calibration_frame, static)
        if not quiet:
            print(f"  skeleton calibrated on {reason}", file=sys.stderr)
    try:
        result = estimate_com(trial.marker_t_s, trial.marker_names, trial.positions, trial.valid, trial.plates,
                              subject, calibrate=calibrate, scale_masses=scale, chair_on_plate=chair,
                              progress=progress, trust_plate_mass=mass_kg is None, calibration=made)
    except MarkerUnitsError as err:          # the estimator checks the units; the bag is named here
        raise MarkerUnitsError(f"{bag_path}: {MARKERS_TOPIC}: {err}") from None
    summary = {"bag": str(bag_path), "subject": {"height_m": height, "mass_kg": mass, "sex": subject.sex},
               "marker_set": markers.name, **evaluate(trial, result)}
    warned = {f.note() for f in result.at_bounds}
    for note in result.notes:
        print(f"{'warning' if note in warned else 'note'}: {note}", file=sys.stderr)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    figure(trial, result, out_dir / "human_com.png", f"Human COM: {Path(bag_path).name}")

    res_bag = out_dir / "human_com"
    if res_bag.exists():
        shutil.rmtree(res_bag)
    joint_names = build_human(result.subject).joint_names()
    write_result_bag(result, res_bag, joint_names)
    write_exports(result, out_dir, joint_names)
    return summary


def read_static(path: str | Path) -> Trial:
    """A static trial's markers (``--static FILE``): a bag (folder or .mcap), a C3D or an OpenSim TRC file, in the
    lab axes the import commands choose. Raises InputError naming the file when it is none of these."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".c3d", ".trc"):
        if suffix == ".c3d":
            lab = read_c3d(path, markers_only=True)
            m, height, mass = lab.markers, lab.height_m, lab.body_mass_kg
        else:
            m, height, mass = read_trc(path), None, None
        return Trial(m.times_s, list(m.names), m.positions_m, m.valid, [], height, mass, "", None, None)
    if path.is_dir() or suffix == ".mcap":
        return read_trial(path)
    raise InputError(f"--static {path}: not a bag, a .c3d nor a .trc file")


def choose_frames(trial: Trial, calibration_frame: int | str | None, n: int) -> FrameChoice:
    """The frames to calibrate on: ``n`` from a given frame, or (``"auto"``, None) the quietest stretch of ``n``
    frames that sees the most markers (:func:`sit2stand.human.calibration_frames.quiet_frames`)."""
    if calibration_frame is None or calibration_frame == "auto":
        return quiet_frames(trial.marker_t_s, trial.positions, trial.valid, n)
    return frames_at(int(calibration_frame), trial.positions, trial.valid, n)


def calibrate_subject(trial: Trial, subject: Subject, calibration_frame: int | str | None = None,
                      static: str | Path | None = None, n: int = 50) -> tuple[StreamCalibration, str]:
    """The subject's skeleton calibrated on ``n`` frames of a ``static`` trial (its quietest, most complete
    stretch), or of ``trial`` (:func:`choose_frames`); with the frames chosen, in words."""
    source = read_static(static) if static is not None else trial
    choice = choose_frames(source, None if static is not None else calibration_frame, n)
    k = choice.frames
    cal = calibrate_stream(subject, source.marker_names, source.positions[k], source.valid[k])
    where = f"{static}: " if static is not None else ""
    return cal, (f"{where}{choice.reason}; marker RMS {cal.marker_rms_before_m * 1e3:.1f} -> "
                 f"{cal.marker_rms_after_m * 1e3:.1f} mm")


def calibrate_from_bag(bag_path: str | Path, out_yaml: str | Path, frames: int = 50, height_m: float | None = None,
                       mass_kg: float | None = None, sex: str | None = None, marker_set: MarkerSet | str | None = None,
                       calibration_frame: int | str | None = None,
                       static: str | Path | None = None) -> tuple[StreamCalibration, str]:
    """The streaming estimator's skeleton calibration, for the human_com node's ``calibration_file``: on
    ``frames`` frames of the bag (the quietest, most complete stretch, or from ``calibration_frame``) or of a
    ``static`` trial. Written to ``out_yaml``; returns it and the frames used, in words."""

    trial = read_trial(bag_path)
    height, mass = height_m or trial.height_m, mass_kg or trial.mass_kg
    if height is None or mass is None:
        raise InputError(f"{bag_path}: no subject height_m/body_mass_kg in its metadata; give them")
    subject = Subject(height, mass, sex or trial.sex, marker_set=choose_marker_set(trial.marker_names, marker_set))
    cal, reason = calibrate_subject(trial, subject, calibration_frame, static, frames)
    Path(out_yaml).parent.mkdir(parents=True, exist_ok=True)
    cal.save(out_yaml)
    return cal, reason
