"""Capture-system client loops: connect, describe, stream, and reconnect when the server goes away.

:class:`QtmStream` drives Qualisys' own client library (``qtm-rt``) in a thread with its own asyncio loop:
``connect`` (the ``Version`` handshake), ``GetParameters 3D Force`` (labels, plates), ``StreamFrames AllFrames
3DRes Force`` over TCP, or over UDP (``transport="udp"``: the library asks over TCP; the datagrams are read here and
decoded by the library's own :class:`qtm_rt.QRTPacket`). Each frame goes to ``on_frame`` in that thread.
:class:`NatNetStream` does the same for OptiTrack Motive through ``natnet`` (markers only).

Failures are reported through ``on_status`` as one line naming the protocol, host, port and the reason (refused,
timed out, version refused, no labels); the loop then waits (:class:`~.convert.ReconnectPolicy`) and tries again.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import qtm_rt
from natnet import NatNetClient
from qtm_rt.packet import QRTPacket, QRTPacketType, RTheader

from ..errors import Sit2StandError
from .convert import ReconnectPolicy
from .qtm_protocol import (PROTOCOL_VERSION, DataFrame, PlateChunk, PlateInfo, parse_frequency, parse_labels,
                           parse_plates)

QTM_PORT = 22223          # QTM's little-endian port (base port + 1)
NATNET_COMMAND_PORT = 1510


class CaptureError(Sit2StandError, RuntimeError):
    """A capture server that cannot be used; the message names protocol, host, port and what failed."""


@dataclass
class StreamInfo:
    """What a connection announced: marker labels, plates, the capture rate [Hz]."""

    labels: list[str]
    plates: list[PlateInfo]
    rate_hz: float


def frame_from_qtm_packet(packet) -> DataFrame:
    """A :class:`~.qtm_protocol.DataFrame` from the ``qtm_rt.QRTPacket`` the vendor's library decoded."""
    markers = packet.get_3d_markers_residual()
    if markers is not None:
        rows = np.array([tuple(m) for m in markers[1]], float).reshape(-1, 4)
        mm, res = rows[:, :3], rows[:, 3]
    else:
        plain = packet.get_3d_markers()
        mm, res = (np.array([tuple(m) for m in plain[1]], float).reshape(-1, 3) if plain else np.zeros((0, 3))), None
    chunks = []
    force = packet.get_force()
    for plate, samples in (force[1] if force else []):
        chunks.append(PlateChunk(plate.id, plate.force_number, np.array([tuple(s) for s in samples], float)))
    return DataFrame(packet.timestamp, packet.framenumber, mm, res, chunks)


class _LastError(logging.Handler):
    """Keeps qtm-rt's last logged error: its ``connect`` logs the reason and returns None."""

    def __init__(self) -> None:
        super().__init__(logging.ERROR)
        self.message = ""

    def emit(self, record: logging.LogRecord) -> None:
        self.message = record.getMessage()


class QtmStream:
    """The QTM client loop (see the module docstring)."""

    def __init__(self, host: str, port: int, on_frame: Callable[[DataFrame, StreamInfo], None],
                 on_status: Callable[[str, bool], None], transport: str = "tcp", udp_port: int = 0,
                 version: str = PROTOCOL_VERSION, timeout_s: float = 3.0,
                 policy: ReconnectPolicy | None = None) -> None:
        self.host, self.port, self.version, self.timeout_s = host, port, version, timeout_s
        self.on_frame, self.on_status = on_frame, on_status
        self.transport, self.udp_port = transport, udp_port
        self.policy = policy or ReconnectPolicy()
        self.connections = 0
        self._last_error_s = -1e9
        self._stop = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._errors = _LastError()
        logging.getLogger("qtm_rt").addHandler(self._errors)
        self._thread = threading.Thread(target=self._run, name="qtm-client", daemon=True)

    @property
    def where(self) -> str:
        return f"QTM RT protocol {self.version} at {self.host}:{self.port}"

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._loop is not None:
            self._loop.call_soon_threadsafe(lambda: None)
        self._thread.join(timeout=3.0)

    def _run(self) -> None:
        self._loop = asyncio.new_event_loop()
        try:
            self._loop.run_until_complete(self._forever())
        finally:
            self._loop.close()

    async def _forever(self) -> None:
        while not self._stop.is_set():
            try:
                await self._session()
            except CaptureError as err:
                self.on_status(str(err), False)
            except (OSError, asyncio.TimeoutError, Exception) as err:  # noqa: BLE001 - the loop must survive
                self.on_status(f"{self.where}: {type(err).__name__}: {err}", False)
            delay = self.policy.next_delay_s()
            end = self._loop.time() + delay
            while not self._stop.is_set() and self._loop.time() < end:
                await asyncio.sleep(0.05)

    async def _connect(self):
        lost = self._loop.create_future()
        self._errors.message = ""
        conn = await qtm_rt.connect(self.host, self.port, version=self.version, timeout=self.timeout_s,
                                    on_disconnect=lambda exc: lost.done() or lost.set_result(exc))
        if conn is None:
            reason = self._errors.message or "no answer"
            if reason.startswith(("b'", 'b"')):          # qtm-rt logs the server's error string as bytes' repr
                reason = reason[2:-1]
            if "Version" in reason or "version" in reason:
                reason = f"the server refused protocol version {self.version} ({reason})"
            raise CaptureError(f"cannot connect to {self.where}: {reason}")
        return conn, lost

    async def _describe(self, conn) -> StreamInfo:
        xml = await conn.get_parameters(["general", "3d", "force"])
        labels = parse_labels(xml)
        if not labels:
            raise CaptureError(f"{self.where}: the server streams no labelled markers (The_3D has no Label): label "
                               "the trajectories (AIM model) in QTM")
        rate = parse_frequency(xml)
        return StreamInfo(labels, parse_plates(xml), rate)

    async def _session(self) -> None:
        conn, lost = await self._connect()
        try:
            info = await self._describe(conn)
            self.connections += 1
            self.on_status(f"connected to {self.where}: {len(info.labels)} markers, {len(info.plates)} plates, "
                           f"{info.rate_hz:g} Hz, over {self.transport.upper()}", True)
            self.policy.succeeded()
            if self.transport == "udp":
                await self._stream_udp(conn, info, lost)
            else:
                await conn.stream_frames(components=["3dres", "force"], on_packet=lambda p: self._deliver(p, info))
                await self._until(lost)
        finally:
            if conn.has_transport():
                conn.disconnect()
        if not self._stop.is_set():
            raise CaptureError(f"{self.where}: the server closed the connection; reconnecting")

    def _deliver(self, packet, info: StreamInfo) -> None:
        """One decoded packet to ``on_frame``; an error there is reported (once a second), not raised: raised
        inside qtm-rt's data callback it would close the connection."""
        try:
            self.on_frame(frame_from_qtm_packet(packet), info)
        except Exception as err:  # noqa: BLE001 - see the docstring
            now = self._loop.time()
            if now - self._last_error_s > 1.0:
                self._last_error_s = now
                self.on_status(f"{self.where}: frame {packet.framenumber} not delivered: {type(err).__name__}: {err}",
                               True)

    async def _until(self, lost: asyncio.Future) -> None:
        while not self._stop.is_set() and not lost.done():
            await asyncio.sleep(0.05)

    async def _stream_udp(self, conn, info: StreamInfo, lost: asyncio.Future) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("", self.udp_port))
        sock.setblocking(False)
        port = sock.getsockname()[1]

        def on_datagram() -> None:
            data = sock.recv(65536)
            size, kind = RTheader.unpack_from(data, 0)
            if kind == QRTPacketType.PacketData.value:
                self._deliver(QRTPacket(data[RTheader.size:size]), info)

        self._loop.add_reader(sock.fileno(), on_datagram)
        try:
            await conn._protocol.send_command(f"streamframes allframes udp:{port} 3dres force", callback=False)
            await self._until(lost)
        finally:
            self._loop.remove_reader(sock.fileno())
            sock.close()


class NatNetStream:
    """OptiTrack NatNet through ``natnet`` (markers only: its labelled markers, named from Motive's marker-set
    descriptions; NatNet's force plates carry raw channels without plate geometry and are not published)."""

    def __init__(self, host: str, port: int, on_frame: Callable[[DataFrame, StreamInfo], None],
                 on_status: Callable[[str, bool], None], local_ip: str = "127.0.0.1", multicast: bool = False) -> None:
        self.where = f"NatNet at {host}:{port}"
        self.on_frame, self.on_status = on_frame, on_status
        self.info = StreamInfo([], [], float("nan"))
        self.client = NatNetClient(server_ip_address=host, local_ip_address=local_ip, command_port=port,
                                   data_port=port + 1, use_multicast=multicast)
        self.client.on_data_description_received_event.handlers.append(self._on_descriptions)
        self.client.on_data_frame_received_event.handlers.append(self._on_frame)

    def _on_descriptions(self, desc) -> None:
        self.info.labels = [f"{ms.name}:{m}" if len(desc.marker_sets) > 1 else m
                            for ms in desc.marker_sets for m in ms.marker_names]

    def _on_frame(self, frame) -> None:
        pos = np.array([p for ms in frame.marker_sets for p in ms.marker_pos_list], float).reshape(-1, 3) * 1e3
        self.on_frame(DataFrame(int(frame.suffix.timestamp * 1e6), frame.prefix.frame_number, pos), self.info)

    def start(self) -> None:
        try:
            self.client.connect(timeout=3.0)
        except Exception as err:  # noqa: BLE001 - natnet raises its own and socket errors
            raise CaptureError(f"cannot connect to {self.where}: {err}") from None
        self.client.request_modeldef()
        self.client.run_async()
        self.on_status(f"connected to {self.where}", True)

    def stop(self) -> None:
        self.client.shutdown()
