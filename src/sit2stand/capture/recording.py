"""What a capture system streams, frame by frame: labelled markers and force plates in its own axes and units.

A :class:`CaptureRecording` holds a trial the way QTM serves it live: marker positions [mm] and residuals [mm] in
the capture volume's axes (NaN where a marker is missing), and per plate the force [N], the moment about the
plate's surface centre [N m] and the application point [mm], at the plate's own rate, in the same axes, zeroed.
It is built from a C3D file (the file's own axes, so the bridge's ``forward``/``up`` choose the lab frame, as
``import-c3d``'s do) or from a sit2stand bag (already in the lab frame).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.bag import BagReader
from ..io.c3d import read_c3d
from ..forceplate import PlateSeries, shift_moment
from ..io.messages import mocap_arrays, plate_series
from ..io.topics import FORCE_PLATE_PREFIX, MARKERS_TOPIC
from .qtm_protocol import DataFrame, PlateChunk, PlateInfo

PLATE_HALF_SIZE_M = 0.25
"""Half the side of the square plate assumed under a bag's plate (a bag holds no plate geometry)."""


@dataclass
class RecordedPlate:
    """One plate: its description and its (K, 9) samples (force [N], moment about the surface centre [N m],
    application point [mm], NaN where there is none)."""

    info: PlateInfo
    samples: np.ndarray


@dataclass
class CaptureRecording:
    """A trial as a capture system streams it (see the module docstring)."""

    labels: list[str]
    rate_hz: float
    markers_mm: np.ndarray        # (N, M, 3)
    residuals_mm: np.ndarray      # (N, M)
    plates: list[RecordedPlate]
    source: str = ""

    @property
    def n_frames(self) -> int:
        """Number of marker frames."""
        return self.markers_mm.shape[0]

    def samples_per_frame(self, plate: RecordedPlate) -> int:
        """The plate's samples per marker frame (its rate over the marker rate)."""
        return max(1, int(round(len(plate.samples) / self.n_frames)))

    def frame(self, k: int, pass_index: int = 0, speed: float = 1.0) -> DataFrame:
        """Frame ``k`` of pass ``pass_index`` (a looping server's frame numbers and times go on across passes):
        timestamp [us from the first frame, at ``speed`` x the file's rate], frame number (from 1), markers and the
        plates' samples of the frame."""
        number = pass_index * self.n_frames + k
        chunks = []
        for p in self.plates:
            r = self.samples_per_frame(p)
            chunks.append(PlateChunk(p.info.plate_id, number * r, p.samples[k * r:(k + 1) * r]))
        return DataFrame(int(round(number * 1e6 / (self.rate_hz * speed))), number + 1, self.markers_mm[k],
                         self.residuals_mm[k], chunks)


def _plate_samples(plate: PlateSeries) -> np.ndarray:
    """(K, 9) samples of a plate in file axes: force, moment about its surface centre, COP in mm (NaN if none)."""
    centre = plate.corners_m.mean(axis=0)
    moment_c = shift_moment(plate.moment_origin_nm, plate.force_n, np.zeros(3), centre)
    cop = plate.cop_m if plate.cop_m is not None else np.full_like(plate.force_n, np.nan)
    return np.column_stack([plate.force_n, moment_c, cop * 1e3])


def recording_from_c3d(path: str | Path) -> CaptureRecording:
    """A C3D file's markers (the ones ``import-c3d`` publishes on ``/mocap/markers``) and loaded plates, in the
    file's own axes, plates zeroed over the file's ``FORCE_PLATFORM:ZERO`` frames as QTM zeroes them before a
    capture. Plate ids are the file's 0-based plate indices plus 1."""
    trial = read_c3d(path, forward="+X", up="+Z")        # the identity rotation: the file's own axes
    m = trial.markers
    plates = []
    for p in trial.plates:
        info = PlateInfo(p.index + 1, f"Force-plate {p.index + 1}", p.rate_hz, p.corners_m * 1e3)
        plates.append(RecordedPlate(info, _plate_samples(p)))
    return CaptureRecording(list(m.names), m.rate_hz, m.positions_m * 1e3, m.residuals_m * 1e3, plates,
                            str(Path(path).name))


def _bag_plate(plate: PlateSeries, index: int) -> RecordedPlate:
    """A bag's plate, with a square surface around its median COP (the COP lies on the surface)."""
    cop = plate.cop_m[plate.cop_valid] if plate.cop_valid is not None and plate.cop_valid.any() else None
    if cop is None:
        raise InputError(f"plate {plate.name!r} never has a valid COP: its surface cannot be placed")
    centre = np.median(cop, axis=0)
    h = PLATE_HALF_SIZE_M
    plate.corners_m = centre + np.array([[h, h, 0.0], [-h, h, 0.0], [-h, -h, 0.0], [h, -h, 0.0]])
    info = PlateInfo(index + 1, plate.name, plate.rate_hz, plate.corners_m * 1e3)
    return RecordedPlate(info, _plate_samples(plate))


def recording_from_bag(path: str | Path) -> CaptureRecording:
    """A sit2stand bag's ``/mocap/markers`` and plates (``/force_plate/*``; the chair first, then the feet, then
    the others by name) as a capture system in the lab's axes would stream them."""
    with BagReader(path) as bag:
        topics = bag.topics()
        if MARKERS_TOPIC not in topics:
            raise InputError(f"{path}: no {MARKERS_TOPIC} to serve")
        frames = [mocap_arrays(m) for _, m in bag.read(MARKERS_TOPIC)]
        names = sorted((t[len(FORCE_PLATE_PREFIX):] for t in topics if t.startswith(FORCE_PLATE_PREFIX)),
                       key=lambda n: ({"chair": 0, "feet": 1}.get(n, 2), n))
        plates = [plate_series(n, bag.read(FORCE_PLATE_PREFIX + n)) for n in names]
        t = np.array([ts for ts, _ in bag.read(MARKERS_TOPIC)], float) * 1e-9
    labels = frames[0][0]
    if any(f[0] != labels for f in frames):
        raise InputError(f"{path}: the marker names change within {MARKERS_TOPIC}; a capture stream's labels do not")
    pos = np.stack([f[1] for f in frames]) * 1e3
    rate = round(1.0 / float(np.median(np.diff(t))), 6)
    return CaptureRecording(labels, rate, pos, np.where(np.isfinite(pos[..., 0]), 0.0, np.nan),
                            [_bag_plate(p, i) for i, p in enumerate(plates)], Path(path).name)


def load_recording(path: str | Path) -> CaptureRecording:
    """A C3D file, or a sit2stand bag folder (a demonstration), as a :class:`CaptureRecording`."""
    path = Path(path)
    if path.is_dir():
        return recording_from_bag(path)
    if path.suffix.lower() != ".c3d":
        raise InputError(f"{path}: not a .c3d file nor a bag folder")
    return recording_from_c3d(path)
