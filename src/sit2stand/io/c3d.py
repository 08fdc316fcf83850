"""C3D import: markers and force plates of a lab recording, in SI units and a REP-103 lab frame, into a bag.

:func:`read_c3d` parses a file (via ezc3d) into :class:`C3DTrial` arrays; :func:`write_trial_bag` writes them as
``/mocap/markers`` (sit2stand_msgs/MocapFrame at the point rate), one ``/force_plate/<name>`` topic per loaded
plate (sit2stand_msgs/ForcePlateSample at the analog rate), the capture software's modelled points on
``/mocap/model_points``, and its whole-body COM (Vicon ``CentreOfMass``), if any, on ``/mocap/reference_com``.

Lab frame (REP-103): x forward (the direction the subject faces), y left, z up. The C3D's own axes are mapped by a
signed permutation chosen from, in order: the caller's ``forward``/``up`` arguments; the data (up = direction of the
plates' mean reaction force, forward = heel-to-toe direction of the foot markers); the file's POINT:X_SCREEN and
Y_SCREEN. The choice and its reasons are stored in the bag's metadata (custom_data).

Occluded markers (negative residual, NaN, or exactly zero coordinates) are marked invalid; their positions are NaN,
never zero. The plate wrench is expressed in lab axes about the lab origin; the COP is computed from it and the
plate's corner geometry, and is invalid below a normal-force threshold.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

import ezc3d
import numpy as np

from .topics import (COM_TYPE, MARKERS_TOPIC, MOCAP_TYPE, MODEL_POINTS_TOPIC, PLATE_TYPE, REFERENCE_COM_TOPIC,
                     SUBJECT_TOPIC, SUBJECT_TYPE, plate_topic)
from ..errors import Sit2StandError
from .bag import BagWriter, reliable_qos
from ..forceplate import DEFAULT_COP_THRESHOLD_N, PLATE_CORNERS_KEY, PlateSeries, plate_corners_json, wrench_in_lab
from .messages import center_of_mass, mocap_frame, plate_messages, subject

LENGTH_SCALE = {"mm": 1e-3, "cm": 1e-2, "m": 1.0, "dm": 0.1}
NON_POSITION_GROUPS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "REACTIONS", "SCALARS")
# Vicon Plug-in-Gait bone outputs: segment origin/anterior/lateral/proximal points, e.g. PELO, LFEA, RTIP.
PIG_BONE = re.compile(r"^(PEL|[LR](FE|TI|FO|TO|CL|HU|RA|HN)|HED|TRX)[OALP]$")
UNLABELLED = re.compile(r"^\*\d+$")
AXES = {"+X": (0, 1.0), "-X": (0, -1.0), "+Y": (1, 1.0), "-Y": (1, -1.0), "+Z": (2, 1.0), "-Z": (2, -1.0)}


class C3DError(Sit2StandError, ValueError):
    """A C3D file that cannot be imported as asked; the message names the file and the problem."""


@dataclass
class LabAxes:
    """Which signed C3D axes are the lab's forward (x) and up (z); left (y) = up x forward."""

    forward: str = "+X"
    up: str = "+Z"
    reason: str = ""

    def rotation(self) -> np.ndarray:
        """R (3x3) with v_lab = R @ v_file."""
        f, u = _axis_vector(self.forward), _axis_vector(self.up)
        if abs(f @ u) > 1e-9:
            raise C3DError(f"forward axis {self.forward} and up axis {self.up} are not perpendicular")
        return np.vstack([f, np.cross(u, f), u])


def _axis_vector(name: str) -> np.ndarray:
    """Unit vector of a signed file axis name (``+X``, ``-Y``, ``Z``...); C3DError on another name."""
    key = name.strip().upper()
    if key in ("X", "Y", "Z"):
        key = "+" + key
    if key not in AXES:
        raise C3DError(f"axis {name!r} is not one of +X -X +Y -Y +Z -Z")
    idx, sign = AXES[key]
    v = np.zeros(3)
    v[idx] = sign
    return v


def _snap(v: np.ndarray, exclude: np.ndarray | None = None) -> tuple[str, float]:
    """Nearest signed file axis to ``v`` (optionally perpendicular to ``exclude``) and the cosine to it."""
    best, best_cos = "+X", -2.0
    n = np.linalg.norm(v)
    for name in AXES:
        a = _axis_vector(name)
        if exclude is not None and abs(a @ exclude) > 0.5:
            continue
        c = float(a @ v / n) if n > 0 else -1.0
        if c > best_cos:
            best, best_cos = name, c
    return best, best_cos


@dataclass
class PointSeries:
    """Labelled 3-D points over time, in the lab frame. positions_m: (N, M, 3), NaN where invalid."""

    names: list[str]
    rate_hz: float
    t0_s: float
    positions_m: np.ndarray
    valid: np.ndarray
    residuals_m: np.ndarray

    @property
    def times_s(self) -> np.ndarray:
        """Sample times [s] on the file's clock."""
        return self.t0_s + np.arange(self.positions_m.shape[0]) / self.rate_hz


@dataclass
class C3DTrial:
    """Everything imported from one C3D file."""

    path: Path
    markers: PointSeries
    model_points: PointSeries | None
    plates: list[PlateSeries]
    all_plate_count: int
    axes: LabAxes
    body_mass_kg: float | None = None
    height_m: float | None = None
    events: list[tuple[str, str, float]] = field(default_factory=list)
    skipped_labels: list[str] = field(default_factory=list)
    zero_frames: tuple[int, int] | None = None


def _zero_range(path: Path, params: dict, zero_frames, n_frames: int) -> tuple[int, int] | None:
    """The 1-based, inclusive point-frame range whose mean plate wrench is the baseline, or None."""
    if zero_frames is None or zero_frames == "off":
        return None
    if zero_frames == "auto":
        raw = np.ravel(np.asarray(_param(params, "FORCE_PLATFORM", "ZERO", [0, 0]), int))
        if raw.size < 2 or not 1 <= raw[0] <= raw[1] <= n_frames:
            return None  # C3D writes [1 0] or [0 0] for "no baseline"
        return int(raw[0]), int(raw[1])
    first, last = (int(v) for v in zero_frames)
    if not 1 <= first <= last <= n_frames:
        raise C3DError(f"{path}: zero frames {first}..{last} are outside 1..{n_frames}")
    return first, last


def _param(params: dict, group: str, name: str, default=None):
    """The value of parameter GROUP:NAME, or ``default`` where the file lacks it."""
    try:
        return params[group][name]["value"]
    except (KeyError, TypeError):
        return default


def _labels(params: dict, group: str, n: int) -> list[str]:
    """The ``n`` labels of a group (LABELS, LABELS2, ...), stripped; ``*<i>`` for the missing ones."""
    labels: list[str] = list(_param(params, group, "LABELS", []) or [])
    k = 2
    while len(labels) < n and _param(params, group, f"LABELS{k}") is not None:
        labels += list(_param(params, group, f"LABELS{k}"))
        k += 1
    labels = [str(s).strip() for s in labels[:n]]
    return labels + [f"*{i}" for i in range(len(labels), n)]


def _group_labels(params: dict, names: tuple[str, ...]) -> set[str]:
    """The point labels that POINT:<name>[2|3] lists (e.g. ANGLES): model outputs that are not positions."""
    out: set[str] = set()
    for name in names:
        for key in (name, name + "2", name + "3"):
            out |= {str(s).strip() for s in (_param(params, "POINT", key, []) or [])}
    return out


def _first_number(value) -> float | None:
    """The first element of a parameter value as a positive finite number, else None."""
    try:
        v = float(np.asarray(value, float).ravel()[0])
    except (TypeError, ValueError, IndexError):
        return None
    return v if np.isfinite(v) and v > 0 else None


@dataclass
class _RawFile:
    """A C3D file as read, before the lab frame: its parameters, points (4, M, N) in file units and point clock."""

    path: Path
    c3d: object                            # the ezc3d.c3d handle
    params: dict
    points: np.ndarray
    rate_hz: float
    t0_s: float
    scale: float                           # file length unit -> m

    @property
    def n_points(self) -> int:
        """Number of point trajectories (markers and model outputs)."""
        return self.points.shape[1]

    @property
    def n_frames(self) -> int:
        """Number of point frames."""
        return self.points.shape[2]


def read_c3d(path: str | Path, *, chair_plate: int | None = None, feet_plate: int | None = None,
             forward: str | None = None, up: str | None = None,
             cop_threshold_n: float = DEFAULT_COP_THRESHOLD_N, markers_only: bool = False,
             zero_frames: tuple[int, int] | str | None = "auto") -> C3DTrial:
    """Read a C3D file into lab-frame arrays (see the module docstring for the conventions).

    Args:
        path: the .c3d file.
        chair_plate, feet_plate: 0-based plate indices to name "chair" and "feet" (others are "plate<i>").
        forward, up: signed file axes (e.g. "+Y", "+Z") to use as lab x and z; detected when None.
        cop_threshold_n: normal force below which the COP is invalid.
        markers_only: import a file without force plates (otherwise that is an error).
        zero_frames: plate baseline removal: "auto" uses FORCE_PLATFORM:ZERO (1-based first/last point frames
            whose mean wrench is subtracted) when it names a valid range; (first, last) gives the range; None: off.

    Raises:
        C3DError: unreadable file, no force plates (unless ``markers_only``), a plate index that does not exist,
            or unknown units; the message names the file.
    """
    raw = _open(Path(path))
    params = raw.params
    platforms = raw.c3d["data"].get("platform", []) or []
    _check_plate_choice(raw, len(platforms), chair_plate, feet_plate, markers_only)
    zero = _zero_range(raw.path, params, zero_frames, raw.n_frames)
    raw_plates = [_file_plate(raw, i, pl, zero) for i, pl in enumerate(platforms)]
    labels = _labels(params, "POINT", raw.n_points)
    axes = _choose_axes(raw.path, params, raw.points, labels, raw_plates, forward, up, cop_threshold_n, raw.scale)
    R = axes.rotation()
    markers, model_points, skipped = _point_series(raw, labels, R)
    analog_rate = _first_number(_param(params, "ANALOG", "RATE")) or float(raw.c3d["header"]["analogs"]["frame_rate"])
    plates = _lab_plates(raw_plates, R, raw.t0_s, analog_rate, {chair_plate: "chair", feet_plate: "feet"},
                         cop_threshold_n)
    mass = _first_number(_param(params, "PROCESSING", "Bodymass"))
    height = _first_number(_param(params, "PROCESSING", "Height"))
    return C3DTrial(path=raw.path, markers=markers, model_points=model_points, plates=plates,
                    all_plate_count=len(platforms), axes=axes, zero_frames=zero if raw_plates else None,
                    body_mass_kg=mass, height_m=height * 1e-3 if height and height > 10 else height,
                    events=_events(params), skipped_labels=skipped)


def _open(path: Path) -> _RawFile:
    """Read the file with ezc3d, with its point rate [Hz], start time [s] and length unit; C3DError if it cannot."""
    if not path.is_file():
        raise C3DError(f"{path}: no such file")
    try:
        c3d = ezc3d.c3d(str(path), extract_forceplat_data=True)
    except Exception as err:  # noqa: BLE001 - ezc3d raises RuntimeError/IOError variants
        raise C3DError(f"{path}: not a readable C3D file: {err}") from None
    params = c3d["parameters"]
    points = np.asarray(c3d["data"]["points"], float)  # (4, M, N), file units
    announced = _header_frame_count(path)
    if announced is not None and announced > points.shape[2]:
        raise C3DError(f"{path}: the header announces {announced} frames, the file holds {points.shape[2]}: it is "
                       f"truncated (export it again, or cut it with the capture software)")
    rate = _first_number(_param(params, "POINT", "RATE")) or float(c3d["header"]["points"]["frame_rate"])
    first_frame = int(c3d["header"]["points"]["first_frame"])
    units = str((_param(params, "POINT", "UNITS", ["mm"]) or ["mm"])[0]).strip().lower()
    if units not in LENGTH_SCALE:
        raise C3DError(f"{path}: POINT:UNITS {units!r} is not a length unit I know ({', '.join(LENGTH_SCALE)})")
    return _RawFile(path, c3d, params, points, rate, first_frame / rate, LENGTH_SCALE[units])


def _header_frame_count(path: Path) -> int | None:
    """Frames the file's own header announces (words 4 and 5: first and last frame, 1-based), read from the raw
    bytes: ezc3d rewrites its header and POINT:FRAMES from the data it could read, so a cut file looks whole there.
    Little-endian first (Intel/DEC files), else big-endian; None when neither reads as a range."""
    with open(path, "rb") as f:
        head = f.read(10)
    for order in ("<", ">"):
        first, last = struct.unpack(order + "HH", head[6:10])
        if 1 <= first <= last:
            return last - first + 1
    return None


def _check_plate_choice(raw: _RawFile, n_plates: int, chair_plate: int | None, feet_plate: int | None,
                        markers_only: bool) -> None:
    """C3DError on a chair/feet plate index the file lacks, the same plate twice, or no plates unless markers_only."""
    path = raw.path
    for label, idx in (("--chair-plate", chair_plate), ("--feet-plate", feet_plate)):
        if idx is not None and not 0 <= idx < n_plates:
            have = f"it has {n_plates} (indices 0..{n_plates - 1})" if n_plates else "it has no force plates"
            raise C3DError(f"{path}: {label} {idx} does not exist: {have}")
    if chair_plate is not None and chair_plate == feet_plate:
        raise C3DError(f"{path}: the chair and feet plates must differ (both are {chair_plate})")
    if n_plates == 0 and not markers_only:
        used = _param(raw.params, "FORCE_PLATFORM", "USED", [0])
        raise C3DError(f"{path}: has no force plates (FORCE_PLATFORM:USED = {np.ravel(used)[0] if len(used) else 0});"
                       f" pass markers_only (--markers-only) to import the markers alone")


def _file_plate(raw: _RawFile, i: int, pl: dict, zero: tuple[int, int] | None) -> tuple:
    """Plate ``i`` in file axes: (i, force [N], moment about its surface centre [N m], corners [m]), baseline off."""
    f_scale = 1.0 if str(pl.get("unit_force", "N")).strip() == "N" else None
    m_unit = str(pl.get("unit_moment", "Nmm")).strip()
    p_unit = str(pl.get("unit_position", "mm")).strip().lower()
    if f_scale is None or m_unit not in ("Nmm", "Nm") or p_unit not in LENGTH_SCALE:
        raise C3DError(f"{raw.path}: plate {i}: units force={pl.get('unit_force')} moment={m_unit} "
                       f"position={p_unit} not supported")
    m_scale = 1e-3 if m_unit == "Nmm" else 1.0
    force = np.asarray(pl["force"], float).T                     # (K, 3) N, file axes
    moment_c = np.asarray(pl["moment"], float).T * m_scale       # about the plate surface centre (ezc3d)
    corners = np.asarray(pl["corners"], float).T * LENGTH_SCALE[p_unit]  # (4, 3)
    if zero is not None:
        analog_per_frame = max(1, int(round(len(force) / raw.n_frames)))
        a, b = (zero[0] - 1) * analog_per_frame, zero[1] * analog_per_frame
        force = force - np.nanmean(force[a:b], axis=0)
        moment_c = moment_c - np.nanmean(moment_c[a:b], axis=0)
    return i, force, moment_c, corners


def _point_series(raw: _RawFile, labels: list[str],
                  R: np.ndarray) -> tuple[PointSeries, PointSeries | None, list[str]]:
    """Points in the lab frame [m], split into markers and model outputs; and the labels skipped."""
    params, n_points, scale = raw.params, raw.n_points, raw.scale
    non_position = _group_labels(params, NON_POSITION_GROUPS)
    modelled = _group_labels(params, ("MODELED_MARKERS",))
    residuals = np.asarray(raw.c3d["data"]["meta_points"]["residuals"], float).reshape(n_points, raw.n_frames)
    xyz = raw.points[:3].transpose(2, 1, 0) * scale                # (N, M, 3) metres, file axes
    res = residuals.T                                               # (N, M)
    valid = np.all(np.isfinite(xyz), axis=2) & ~np.all(xyz == 0.0, axis=2) & ~(res < 0)
    xyz = xyz @ R.T
    xyz[~valid] = np.nan
    res_m = np.where(valid & np.isfinite(res), res * scale, np.nan)

    marker_idx, model_idx, skipped = [], [], []
    for j, name in enumerate(labels):
        if not name or UNLABELLED.match(name) or name in non_position:
            skipped.append(name or f"<empty label {j}>")
        elif name in modelled or PIG_BONE.match(name):
            model_idx.append(j)
        else:
            marker_idx.append(j)
    if not marker_idx:
        raise C3DError(f"{raw.path}: no marker trajectories (all {n_points} points are model outputs or unlabelled)")

    def series(idx: list[int]) -> PointSeries:
        """The points ``idx`` as a series."""
        return PointSeries([labels[j] for j in idx], raw.rate_hz, raw.t0_s, xyz[:, idx], valid[:, idx], res_m[:, idx])

    return series(marker_idx), series(model_idx) if model_idx else None, skipped


def _lab_plates(raw_plates: list[tuple], R: np.ndarray, t0_s: float, analog_rate_hz: float, named: dict,
                cop_threshold_n: float) -> list[PlateSeries]:
    """The plates in lab axes, wrench about the lab origin, with their COP; unloaded unnamed plates left out."""
    plates: list[PlateSeries] = []
    for i, force_f, moment_f, corners_f in raw_plates:
        w = wrench_in_lab(force_f, moment_f, corners_f, R, cop_threshold_n)
        force = w.force_n
        name = named.get(i, f"plate{i}")
        loaded = np.count_nonzero(np.abs(force @ w.normal) > cop_threshold_n) >= max(1, 0.01 * len(force))
        if not loaded and i not in named:
            continue  # unused plates are not published
        t_s = t0_s + np.arange(len(force)) / analog_rate_hz
        plates.append(PlateSeries(name, t_s, force, w.moment_origin_nm, w.cop_m, w.cop_valid, w.free_moment_nm,
                                  w.corners_m, index=i))
    return plates


def _events(params: dict) -> list[tuple[str, str, float]]:
    """The file's events: (label, context, time [s])."""
    events = []
    ev_labels = list(_param(params, "EVENT", "LABELS", []) or [])
    ev_contexts = list(_param(params, "EVENT", "CONTEXTS", []) or [])
    ev_times = np.asarray(_param(params, "EVENT", "TIMES", np.zeros((2, 0))), float)
    if ev_labels and ev_times.ndim == 2 and ev_times.shape[0] == 2:  # C3D: row 0 minutes, row 1 seconds
        for k, lab in enumerate(ev_labels[:ev_times.shape[1]]):
            ctx = str(ev_contexts[k]).strip() if k < len(ev_contexts) else ""
            events.append((str(lab).strip(), ctx, float(ev_times[0, k] * 60.0 + ev_times[1, k])))
    return events


def _choose_axes(path: Path, params: dict, points: np.ndarray, labels: list[str], raw_plates: list,
                 forward: str | None, up: str | None, threshold_n: float, scale: float) -> LabAxes:
    """Pick lab forward/up among the file's signed axes (caller > data > POINT:X_SCREEN/Y_SCREEN > defaults)."""
    reasons = []
    if up is not None:
        up_name = up.upper() if up[0] in "+-" else "+" + up.upper()
        _axis_vector(up_name)
        reasons.append(f"up {up_name} (given)")
    else:
        total = np.zeros(3)
        for _i, force, _m, _c in raw_plates:
            loaded = np.linalg.norm(force, axis=1) > threshold_n
            if loaded.any():
                total += np.nanmean(force[loaded], axis=0)
        if np.linalg.norm(total) > 0:
            up_name, cos = _snap(total)
            reasons.append(f"up {up_name} (mean plate reaction force, cos {cos:.2f})")
        else:
            screen_y = str((_param(params, "POINT", "Y_SCREEN", ["+Z"]) or ["+Z"])[0]).strip().upper()
            up_name = screen_y if screen_y in AXES else "+Z"
            reasons.append(f"up {up_name} (POINT:Y_SCREEN)")
    up_vec = _axis_vector(up_name)

    if forward is not None:
        fwd_name = forward.upper() if forward[0] in "+-" else "+" + forward.upper()
        if abs(_axis_vector(fwd_name) @ up_vec) > 0.5:
            raise C3DError(f"{path}: forward axis {fwd_name} is not perpendicular to up axis {up_name}")
        reasons.append(f"forward {fwd_name} (given)")
        return LabAxes(fwd_name, up_name, "; ".join(reasons))

    # heel -> toe direction of the foot markers (Plug-in-Gait names)
    idx = {name: j for j, name in enumerate(labels)}
    vecs = []
    for side in "LR":
        heel, toe = idx.get(f"{side}HEE"), idx.get(f"{side}TOE")
        if heel is not None and toe is not None:
            d = points[:3, toe, :].T - points[:3, heel, :].T
            ok = np.all(np.isfinite(d), axis=1) & np.any(d != 0, axis=1)
            if ok.any():
                vecs.append(np.nanmean(d[ok], axis=0) * scale)
    if vecs:
        v = np.sum(vecs, axis=0)
        v -= (v @ up_vec) * up_vec
        name, cos = _snap(v, exclude=up_vec)
        if cos > 0.7:
            reasons.append(f"forward {name} (heel-to-toe markers, cos {cos:.2f})")
            return LabAxes(name, up_name, "; ".join(reasons))
    screen_x = str((_param(params, "POINT", "X_SCREEN", ["+X"]) or ["+X"])[0]).strip().upper()
    if screen_x in AXES and abs(_axis_vector(screen_x) @ up_vec) < 0.5:
        reasons.append(f"forward {screen_x} (POINT:X_SCREEN)")
        return LabAxes(screen_x, up_name, "; ".join(reasons))
    for name in ("+X", "+Y", "+Z"):
        if abs(_axis_vector(name) @ up_vec) < 0.5:
            reasons.append(f"forward {name} (default)")
            return LabAxes(name, up_name, "; ".join(reasons))
    raise AssertionError("unreachable")


def _to_ns(t_s: float) -> int:
    """Bag time [ns] of a time on the file's clock [s]."""
    return int(round(t_s * 1e9))


def write_trial_bag(trial: C3DTrial, out: str | Path) -> dict[str, int]:
    """Write a :class:`C3DTrial` as a bag; returns message counts per topic.

    Message times are the trial's own clock (first frame / rate).
    """
    custom = {
        "source": str(trial.path.name),
        "lab_axes": f"forward={trial.axes.forward} up={trial.axes.up}: {trial.axes.reason}",
        "plates": ", ".join(f"{p.name}=index {p.index}" for p in trial.plates) or "none",
        PLATE_CORNERS_KEY: plate_corners_json(trial.plates),
        "plate_baseline": (f"mean of frames {trial.zero_frames[0]}..{trial.zero_frames[1]} subtracted"
                           if trial.zero_frames else "none"),
    }
    if trial.body_mass_kg:
        custom["body_mass_kg"] = f"{trial.body_mass_kg:g}"
    if trial.height_m:
        custom["height_m"] = f"{trial.height_m:g}"
    if trial.events:
        custom["events"] = "; ".join(f"{lab}@{t:.3f}s" for lab, _ctx, t in trial.events)
    with BagWriter(out, custom_data=custom) as bag:
        m = trial.markers
        if trial.body_mass_kg and trial.height_m:
            # the subject in the stream too (latched, as in synthesised bags): a conversion that drops custom_data
            # (ROS 1) keeps it, and a live human_com node reads it when not given the subject's parameters
            t0 = _to_ns(float(m.times_s[0]) if len(m.times_s) else 0.0)
            bag.add_topic(SUBJECT_TOPIC, SUBJECT_TYPE, [reliable_qos(1, transient_local=True)])
            bag.write(SUBJECT_TOPIC, t0, subject(t0, trial.height_m, trial.body_mass_kg, ""))
        bag.add_topic(MARKERS_TOPIC, MOCAP_TYPE)
        for k, t in enumerate(m.times_s):
            bag.write(MARKERS_TOPIC, _to_ns(t), mocap_frame(_to_ns(t), m.names, m.positions_m[k], m.valid[k],
                                                           m.residuals_m[k]))
        if trial.model_points is not None:
            mp = trial.model_points
            bag.add_topic(MODEL_POINTS_TOPIC, MOCAP_TYPE)
            for k, t in enumerate(mp.times_s):
                bag.write(MODEL_POINTS_TOPIC, _to_ns(t), mocap_frame(_to_ns(t), mp.names, mp.positions_m[k],
                                                                    mp.valid[k], mp.residuals_m[k]))
            if "CentreOfMass" in mp.names:
                j = mp.names.index("CentreOfMass")
                pos, ok = mp.positions_m[:, j], mp.valid[:, j]
                vel = np.gradient(pos, 1.0 / mp.rate_hz, axis=0) if len(pos) > 1 else np.zeros_like(pos)
                acc = np.gradient(vel, 1.0 / mp.rate_hz, axis=0) if len(pos) > 1 else np.zeros_like(pos)
                bag.add_topic(REFERENCE_COM_TOPIC, COM_TYPE)
                for k, t in enumerate(mp.times_s):
                    bag.write(REFERENCE_COM_TOPIC, _to_ns(t), center_of_mass(
                        _to_ns(t), pos[k], vel[k], acc[k], source=f"c3d:{trial.path.name}:CentreOfMass",
                        valid=bool(ok[k])))
        for p in trial.plates:
            topic = plate_topic(p.name)
            bag.add_topic(topic, PLATE_TYPE)
            for t_ns, msg in plate_messages(p):
                bag.write(topic, t_ns, msg)
        return dict(bag.counts)
