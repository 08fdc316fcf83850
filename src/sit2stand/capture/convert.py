"""A streamed capture frame to sit2stand's lab frame and SI units; the capture clock; lost frames; reconnecting.

The arithmetic is ``import-c3d``'s, shared with it: markers [mm] -> [m] rotated by the lab axes (``forward``,
``up``: signed capture axes, :class:`sit2stand.io.c3d.LabAxes`), a marker invalid where it is NaN, exactly zero or
has a negative residual; plates through :func:`sit2stand.forceplate.wrench_in_lab` (moment moved to the lab
origin, COP on the plate surface, invalid below the threshold). A stream and an import of the same trial
therefore agree to the float32 resolution of the wire (QTM sends single precision: 1e-7 m at 1.5 m).

Capture time -> ROS time is mapped once, at the first frame of a connection: ``stamp = capture time + offset``,
with ``offset = ROS now - capture time`` of that frame. Stamps then keep the capture system's spacing (no receive
jitter), and the first frame's transport delay is a constant bias (~0.2 ms on one host). A new connection, or a
capture clock that goes back (a new measurement), maps again.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..io.c3d import LabAxes
from ..io.stream_messages import MocapFrameEncoder, PlateSampleEncoder
from ..io.topics import LAB_FRAME
from ..forceplate import DEFAULT_COP_THRESHOLD_N, wrench_in_lab
from .qtm_protocol import DataFrame, PlateInfo


@dataclass
class MarkerSample:
    """One marker frame in the lab: stamp [ns], names, positions (M, 3) [m] (NaN where invalid), validity,
    residuals (M,) [m]."""

    t_ns: int
    names: list[str]
    positions_m: np.ndarray
    valid: np.ndarray
    residuals_m: np.ndarray


@dataclass
class PlateSamples:
    """One plate's samples of a frame in the lab: stamps [ns] and the fields of ForcePlateSample."""

    name: str
    t_ns: np.ndarray
    force_n: np.ndarray
    moment_origin_nm: np.ndarray
    cop_m: np.ndarray
    cop_valid: np.ndarray
    free_moment_nm: np.ndarray


def plate_names(plates: list[PlateInfo], chair_index: int, feet_index: int) -> dict[int, str]:
    """Topic names by plate id: ``chair`` and ``feet`` for the plates at those 0-based indices (the capture
    system's plate id minus 1, as ``import-c3d --chair-plate/--feet-plate``), ``plate<index>`` for the others."""
    named = {chair_index: "chair", feet_index: "feet"}
    return {p.plate_id: named.get(p.plate_id - 1, f"plate{p.plate_id - 1}") for p in plates}


class FrameConverter:
    """Converts :class:`~.qtm_protocol.DataFrame` s of one stream (fixed labels and plates) to lab samples."""

    def __init__(self, labels: list[str], plates: list[PlateInfo], axes: LabAxes, names: dict[int, str],
                 marker_set: list[str] | None = None, cop_threshold_n: float = DEFAULT_COP_THRESHOLD_N) -> None:
        self.rotation = axes.rotation()
        self.labels = list(labels)
        self.plates = {p.plate_id: p for p in plates}
        self.names = names
        self.threshold_n = cop_threshold_n
        self.marker_set = list(marker_set) if marker_set else None
        self.index = None
        if self.marker_set:
            where = {n: i for i, n in enumerate(self.labels)}
            self.index = np.array([where.get(n, -1) for n in self.marker_set])

    @property
    def marker_names(self) -> list[str]:
        """The markers each frame is published with: the marker set's, in its order, or the server's labels."""
        return self.marker_set if self.index is not None else self.labels

    def markers(self, frame: DataFrame, t_ns: int) -> MarkerSample:
        """The frame's markers (the marker set's, in its order, if one was given; missing ones invalid)."""
        mm = np.asarray(frame.markers_mm, float).reshape(-1, 3)
        res = frame.residuals_mm if frame.residuals_mm is not None else np.full(len(mm), np.nan)
        if self.index is not None:
            pad_mm = np.vstack([mm, np.full((1, 3), np.nan)])
            mm, res = pad_mm[self.index], np.append(res, np.nan)[self.index]
        valid = np.all(np.isfinite(mm), axis=1) & ~np.all(mm == 0.0, axis=1) & ~(res < 0)
        pos = (mm * 1e-3) @ self.rotation.T
        pos[~valid] = np.nan
        res_m = np.where(valid & np.isfinite(res), res * 1e-3, np.nan)
        return MarkerSample(t_ns, list(self.marker_names), pos, valid, res_m)

    def plate(self, plate_id: int, samples: np.ndarray, t_ns: np.ndarray) -> PlateSamples:
        """One plate's (K, 9) samples (force [N], moment about the surface centre [N m], application point) at
        stamps ``t_ns``; the COP is found from the wrench, as the importer does (the streamed point is not used)."""
        info = self.plates[plate_id]
        s = np.asarray(samples, float).reshape(-1, 9)
        w = wrench_in_lab(s[:, :3], s[:, 3:6], info.corners_mm * 1e-3, self.rotation, self.threshold_n)
        return PlateSamples(self.names.get(plate_id, f"plate{plate_id - 1}"), t_ns, w.force_n, w.moment_origin_nm,
                            w.cop_m, w.cop_valid, w.free_moment_nm)


class ClockMap:
    """Capture time -> ROS time [ns], mapped once per stream (see the module docstring)."""

    def __init__(self) -> None:
        self.offset_ns: int | None = None
        self._last_capture_ns = -1

    def reset(self) -> None:
        """Map again at the next frame (a new connection)."""
        self.offset_ns = None

    def stamp(self, capture_ns: int, now_ns: int) -> int:
        """The ROS stamp [ns] of capture time ``capture_ns``; ``now_ns`` (the ROS clock) is used at a (re)map."""
        if self.offset_ns is None or capture_ns < self._last_capture_ns:
            self.offset_ns = int(now_ns) - int(capture_ns)
        self._last_capture_ns = int(capture_ns)
        return int(capture_ns) + self.offset_ns


@dataclass
class DropCounter:
    """Frames lost, counted from the frame numbers (consecutive in an all-frames stream): a jump of n counts n - 1;
    a number that goes back starts a new count base (a new measurement), counted in ``restarts``."""

    step: int = 1
    received: int = 0
    dropped: int = 0
    restarts: int = 0
    last: int | None = None
    gaps: list[tuple[int, int]] = field(default_factory=list)

    def add(self, number: int) -> int:
        """Count one frame; returns how many were lost just before it."""
        lost = 0
        if self.last is not None:
            if number <= self.last:
                self.restarts += 1
            else:
                lost = (number - self.last) // self.step - 1
        if lost > 0:
            self.dropped += lost
            if len(self.gaps) < 100:
                self.gaps.append((self.last, number))
        self.last = number
        self.received += 1
        return lost


@dataclass
class ReconnectPolicy:
    """Wait before the next connection attempt: ``first_s``, doubled per failure up to ``max_s``; reset once a
    connection streams. A capture PC that reboots is back within the cap without being hammered."""

    first_s: float = 0.2
    max_s: float = 2.0
    failures: int = 0

    def next_delay_s(self) -> float:
        """The delay before the next attempt (and count this failure)."""
        delay = min(self.max_s, self.first_s * 2 ** self.failures)
        self.failures += 1
        return delay

    def succeeded(self) -> None:
        """A connection streamed: start again from ``first_s``."""
        self.failures = 0


def plate_stamps(first_sample: int, count: int, rate_hz: float, clock: ClockMap, now_ns: int) -> np.ndarray:
    """Stamps [ns] of ``count`` plate samples from sample number ``first_sample`` at ``rate_hz`` (the plate's own
    numbering from the measurement's start, on the capture clock)."""
    capture_ns = np.round((first_sample + np.arange(count)) * (1e9 / rate_hz)).astype(np.int64)
    if clock.offset_ns is None:
        clock.stamp(int(capture_ns[0]), now_ns)
    return capture_ns + clock.offset_ns


DEFAULT_PORTS = {"qtm": 22223, "natnet": 1510}
"""QTM's little-endian RT port, NatNet's command port."""


@dataclass(frozen=True)
class CaptureServer:
    """Where a bridge's capture system streams from, and how."""

    protocol: str               # qtm | natnet
    host: str
    port: int                   # 0: the protocol's default (DEFAULT_PORTS)
    transport: str = "tcp"      # tcp | udp (QTM streams its frames over UDP to udp_port; 0: any free port)
    udp_port: int = 0
    version: str = "1.25"       # the QTM RT protocol version asked for

    def __post_init__(self) -> None:
        if self.protocol not in DEFAULT_PORTS:
            raise ValueError(f"protocol must be 'qtm' or 'natnet', not {self.protocol!r}")
        if self.transport not in ("tcp", "udp"):
            raise ValueError(f"transport must be 'tcp' or 'udp', not {self.transport!r}")
        if not self.port:
            object.__setattr__(self, "port", DEFAULT_PORTS[self.protocol])

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"


@dataclass
class StreamLayout:
    """One connection's conversion (its labels and plates, :class:`FrameConverter`) and its messages' CDR layouts:
    the marker frame's, and each plate's from its first sample."""

    info: object
    converter: FrameConverter
    markers: MocapFrameEncoder
    plates: dict[str, PlateSampleEncoder] = field(default_factory=dict)

    def plate(self, name: str) -> PlateSampleEncoder:
        encoder = self.plates.get(name)
        if encoder is None:
            encoder = self.plates[name] = PlateSampleEncoder(name, LAB_FRAME)
        return encoder
