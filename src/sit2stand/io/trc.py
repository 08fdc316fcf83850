"""OpenSim files: TRC markers and .mot ground reaction forces, in SI units and a REP-103 lab frame, into a bag.

**TRC** (``PathFileType 4 (X/Y/Z)``): a header of key names and values (``DataRate``, ``NumFrames``, ``NumMarkers``,
``Units`` in mm, cm or m, ...), a row of marker names (each over three columns), a row of ``X1 Y1 Z1 ...`` and then
one tab-separated row per frame: frame number, time, then x, y, z per marker. A blank or NaN field is an occluded
marker: invalid, NaN, never zero. Frame numbers that jump leave NaN frames in between; times are the first frame's
time plus the frame index over ``DataRate``.

**.mot ground reaction forces** (OpenSim's Storage format: ``key=value`` lines up to ``endheader``, then a row of
column names and rows of numbers): one plate per column prefix, each with ``<p>ground_force_v{x,y,z}`` (the force on
the body [N]), ``<p>ground_force_p{x,y,z}`` (its point of application [m]) and ``<p>ground_torque_{x,y,z}`` (the free
torque about that point [N m]); e.g. the prefixes ``""`` and ``"1_"`` of OpenSim's Gait2392 example. The wrench
about the lab origin is ``M_O = p x F + T`` and the COP follows from it on the horizontal plane through ``p``
(:func:`~sit2stand.forceplate.center_of_pressure`; it equals ``p`` when the torque is vertical). Plates are named
``plate0``, ``plate1``... in the file's order (a walking trial has no chair).

**Lab frame.** OpenSim's ground is x forward, y up, z right; REP-103 is x forward, y left, z up, so a vector
``(x, y, z)`` of the file is ``(x, -z, y)`` in the lab (:data:`OPENSIM_AXES`). Other axes can be given as signed
file axes (``forward``/``up``), as for the C3D import.

:func:`read_opensim_trial` returns the same :class:`~sit2stand.io.c3d.C3DTrial` the C3D import does, so
:func:`~sit2stand.io.c3d.write_trial_bag` writes the bag (``/mocap/markers``, ``/force_plate/<name>``, the subject's
stature and mass in the bag's metadata).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import Sit2StandError
from .c3d import LENGTH_SCALE, C3DTrial, LabAxes, PointSeries
from ..forceplate import DEFAULT_COP_THRESHOLD_N, PlateSeries, center_of_pressure

OPENSIM_AXES = LabAxes("+X", "+Y", "OpenSim's ground frame (x forward, y up, z right): lab (x, y, z) = file (x, -z, y)")
"""The lab axes of an OpenSim file: file x is lab x (forward), file y is lab z (up)."""
_FORCE = re.compile(r"^(.*)ground_force_v([xyz])$")


class TrcError(Sit2StandError, ValueError):
    """A TRC or .mot file that cannot be read as asked; the message names the file, the line or the column."""


def _axes(forward: str | None, up: str | None) -> LabAxes:
    """The lab axes: OpenSim's unless the caller names others."""
    if forward is None and up is None:
        return OPENSIM_AXES
    return LabAxes(forward or OPENSIM_AXES.forward, up or OPENSIM_AXES.up,
                   f"forward={forward or OPENSIM_AXES.forward} up={up or OPENSIM_AXES.up} (given)")


def _number(text: str) -> float:
    """A field of a data row: NaN when blank or not a number."""
    try:
        return float(text)
    except ValueError:
        return float("nan")


def read_trc(path: str | Path, axes: LabAxes = OPENSIM_AXES) -> PointSeries:
    """Markers of a TRC file in metres, in the lab frame of ``axes`` (see the module docstring).

    Raises:
        TrcError: a missing file, a header without DataRate/Units/NumMarkers, unknown units, or no data rows.
    """
    path = Path(path)
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError as err:
        raise TrcError(f"{path}: cannot read: {err}") from None
    if len(lines) < 6 or not lines[0].startswith("PathFileType"):
        raise TrcError(f"{path}: not a TRC file (the first line must start with PathFileType)")
    header = dict(zip(lines[1].split("\t"), lines[2].split("\t")))
    header = {k.strip(): v.strip() for k, v in header.items()}
    try:
        rate = float(header["DataRate"])
        units = header["Units"].lower()
        n_markers = int(header["NumMarkers"])
    except (KeyError, ValueError):
        raise TrcError(f"{path}: the header needs DataRate, NumMarkers and Units (it has "
                       f"{', '.join(f'{k}={v}' for k, v in header.items())})") from None
    if units not in LENGTH_SCALE:
        raise TrcError(f"{path}: unknown length unit {header['Units']!r} (known: {', '.join(LENGTH_SCALE)})")
    if not rate > 0:
        raise TrcError(f"{path}: DataRate must be positive, got {rate}")
    names = [n.strip() for n in lines[3].split("\t")[2:] if n.strip()]
    if len(names) != n_markers:
        raise TrcError(f"{path}: the header says {n_markers} markers, the name row has {len(names)}")
    rows = [line.split("\t") for line in lines[5:] if line.strip()]
    rows = [r for r in rows if r[0].strip()]
    if not rows:
        raise TrcError(f"{path}: no data rows")
    try:
        frame_no = np.array([int(float(r[0])) for r in rows])
        t_first = float(rows[0][1])
    except ValueError:
        raise TrcError(f"{path}: a data row does not start with a frame number and a time") from None
    n = int(frame_no.max() - frame_no[0] + 1)
    xyz = np.full((n, n_markers, 3), np.nan)
    width = 3 * n_markers
    for k, r in zip(frame_no - frame_no[0], rows):
        values = [_number(v) for v in r[2:2 + width]]
        xyz[k].flat[:len(values)] = values                 # short rows: trailing markers missing
    xyz *= LENGTH_SCALE[units]
    valid = np.all(np.isfinite(xyz), axis=2)
    lab = xyz @ axes.rotation().T
    lab[~valid] = np.nan
    return PointSeries(names, rate, t_first, lab, valid, np.where(valid, 0.0, np.nan))


def _read_storage(path: Path) -> tuple[dict[str, str], list[str], np.ndarray]:
    """An OpenSim Storage file (.mot/.sto): header key=value pairs, column names, (rows, columns) numbers."""
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError as err:
        raise TrcError(f"{path}: cannot read: {err}") from None
    try:
        end = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    except StopIteration:
        raise TrcError(f"{path}: not an OpenSim storage file (no 'endheader' line)") from None
    header = {}
    for line in lines[:end]:
        if "=" in line:
            key, value = line.split("=", 1)
            header[key.strip()] = value.strip()
    columns = lines[end + 1].split()
    try:
        data = np.array([[float(v) for v in line.split()] for line in lines[end + 2:] if line.strip()], float)
    except ValueError as err:
        raise TrcError(f"{path}: a data row is not numbers: {err}") from None
    if data.ndim != 2 or data.shape[0] == 0 or data.shape[1] != len(columns):
        raise TrcError(f"{path}: {len(columns)} column names but rows of {data.shape[-1] if data.size else 0} "
                       f"numbers")
    return header, columns, data


def _uniform_times(t: np.ndarray) -> np.ndarray:
    """Sample times printed with few decimals (0.0017, 0.0033, ...) back on the uniform grid they round, when they
    are one; otherwise as they are."""
    if len(t) < 3:
        return t
    grid = np.linspace(t[0], t[-1], len(t))
    step = (t[-1] - t[0]) / (len(t) - 1)
    return grid if np.max(np.abs(t - grid)) < 0.5 * step else t


def read_grf_mot(path: str | Path, axes: LabAxes = OPENSIM_AXES,
                 cop_threshold_n: float = DEFAULT_COP_THRESHOLD_N) -> list[PlateSeries]:
    """The force plates of an OpenSim ground-reaction .mot file as :class:`PlateSeries` (force on the body, moment
    about the lab origin, COP), in the lab frame of ``axes`` (see the module docstring).

    Raises:
        TrcError: no ``time`` column, no ``ground_force_v*`` columns, or a plate lacking its point or torque.
    """
    path = Path(path)
    _, columns, data = _read_storage(path)
    col = {c: i for i, c in enumerate(columns)}
    if "time" not in col:
        raise TrcError(f"{path}: no 'time' column (columns: {', '.join(columns[:8])}...)")
    prefixes = list(dict.fromkeys(m.group(1) for c in columns if (m := _FORCE.match(c))))
    if not prefixes:
        raise TrcError(f"{path}: no ground_force_v{{x,y,z}} columns: not a ground reaction file")
    R = axes.rotation()
    t = _uniform_times(data[:, col["time"]])
    up = np.array([0.0, 0.0, 1.0])
    plates = []
    for i, p in enumerate(prefixes):
        needed = [f"{p}ground_force_{q}{a}" for q in "vp" for a in "xyz"] + [f"{p}ground_torque_{a}" for a in "xyz"]
        missing = [c for c in needed if c not in col]
        if missing:
            raise TrcError(f"{path}: plate {p or '(no prefix)'} lacks the column(s) {', '.join(missing)}")
        force, point, torque = (data[:, [col[c] for c in needed[3 * k:3 * k + 3]]] @ R.T for k in range(3))
        moment = np.cross(point, force) + torque
        cop, cop_valid, tau = center_of_pressure(force, torque, point, up, cop_threshold_n)
        cop = np.where(cop_valid[:, None], cop, np.nan)
        plates.append(PlateSeries(f"plate{i}", t.copy(), force, moment, cop, cop_valid, tau, index=i))
    return plates


def read_opensim_trial(trc_path: str | Path, grf_path: str | Path | None = None, *, mass_kg: float | None = None,
                       height_m: float | None = None, forward: str | None = None, up: str | None = None,
                       cop_threshold_n: float = DEFAULT_COP_THRESHOLD_N) -> C3DTrial:
    """A TRC file and, optionally, its ground reaction .mot as one lab trial, for
    :func:`~sit2stand.io.c3d.write_trial_bag`. The subject's ``mass_kg`` and ``height_m`` (which TRC files do not
    carry) go into the bag's metadata."""
    axes = _axes(forward, up)
    markers = read_trc(trc_path, axes)
    plates = read_grf_mot(grf_path, axes, cop_threshold_n) if grf_path is not None else []
    if plates:
        gap = abs(plates[0].t_s[0] - markers.t0_s)
        span = markers.times_s[-1] - markers.t0_s
        if gap > 0.5 * span:
            raise TrcError(f"{grf_path}: its time starts {plates[0].t_s[0]:g} s, the markers' at "
                           f"{markers.t0_s:g} s: not the same trial's clock")
    return C3DTrial(path=Path(trc_path), markers=markers, model_points=None, plates=plates,
                    all_plate_count=len(plates), axes=axes, body_mass_kg=mass_kg, height_m=height_m)
