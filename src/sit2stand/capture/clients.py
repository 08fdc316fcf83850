"""Capture-system client loops: connect, describe, stream, and reconnect when the server goes away.

:class:`QtmStream` drives Qualisys' own client library (``qtm-rt``) in a thread with its own asyncio loop:
``connect`` (the ``Version`` handshake), ``GetParameters 3D Force`` (labels, plates), ``StreamFrames AllFrames
3DRes Force`` over TCP, or over UDP (``transport="udp"``: the library asks over TCP; the datagrams are read here into
the library's :class:`qtm_rt.QRTPacket`); each packet's components are read as arrays (:func:`frame_from_qtm_packet`)
and the frame goes to ``on_frame`` in that thread.
:class:`NatNetStream` does the same for OptiTrack Motive through ``natnet`` (markers only); from protocol 4.1 on its
frames' markers are read by :func:`~.natnet_protocol.read_marker_frame`, not by ``natnet``'s parse of the whole frame.

Failures are reported through ``on_status`` as one line naming the protocol, host, port and the reason (refused,
timed out, version refused, no labels); the loop then waits (:class:`~.convert.ReconnectPolicy`) and tries again.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import qtm_rt
from natnet import NatNetClient
from qtm_rt.packet import QRTPacket, QRTPacketType, RTheader

from ..errors import Sit2StandError
from .convert import ReconnectPolicy
from .natnet_protocol import MarkerFrame, Message, read_marker_frame
from .qtm_protocol import (PROTOCOL_VERSION, DataFrame, PlateInfo, decode_data, parse_frequency, parse_labels,
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
    """A :class:`~.qtm_protocol.DataFrame` of a ``qtm_rt.QRTPacket``'s body, its 3D (residual) and force components
    read as arrays (:func:`~.qtm_protocol.decode_data`): 9 us for 39 markers and two plates' 10 samples, against
    70 us through the library's tuple per marker and per sample, on the capture -> joint command path."""
    return decode_data(packet.data)


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


class MarkerFrameClient(NatNetClient):
    """``natnet``'s client whose frames of data go to ``on_markers`` as :class:`MarkerFrame` where
    :func:`read_marker_frame` reads them (protocol 4.1 on), through ``natnet``'s own parse and events otherwise."""

    def __init__(self, on_markers: Callable[[MarkerFrame], None], **kwargs) -> None:
        super().__init__(**kwargs)
        self.on_markers = on_markers

    def _NatNetClient__process_message(self, buffer) -> None:
        # natnet 0.3.0's (name-mangled) dispatch of a received packet, which parses a frame of data in full
        data, version = buffer.data, self.protocol_version
        if version is not None and len(data) > 4 and int.from_bytes(data[:2], "little") == Message.FRAMEOFDATA:
            frame = read_marker_frame(data[4:], tuple(version.components))
            if frame is not None:
                self.on_markers(frame)
                return
        NatNetClient._NatNetClient__process_message(self, buffer)


class NatNetStream:
    """OptiTrack NatNet through ``natnet`` (markers only: the marker sets' markers, named from Motive's marker-set
    descriptions; NatNet's force plates carry raw channels without plate geometry and are not published).

    A thread connects (NAT_CONNECT, then the marker-set descriptions), hands each frame to ``on_frame`` from
    ``natnet``'s receiving thread, and connects again (:class:`~.convert.ReconnectPolicy`) when no frame has come
    for ``silence_s``; every failure goes to ``on_status`` naming protocol, host and port. Frames that come before
    the descriptions are dropped (their markers have no names yet). Labels are the marker names, prefixed with
    ``set:`` when more than one marker set is described; Motive's ``all`` set, which repeats the other sets'
    markers, is skipped when there are others. A new description makes a new :class:`StreamInfo` (the bridge then
    builds a new converter). ``local_ip`` None: the local address that routes to ``host``."""

    def __init__(self, host: str, port: int, on_frame: Callable[[DataFrame, StreamInfo], None],
                 on_status: Callable[[str, bool], None], local_ip: str | None = None, multicast: bool = False,
                 timeout_s: float = 3.0, silence_s: float = 2.0, policy: ReconnectPolicy | None = None) -> None:
        self.host, self.port, self.multicast = host, port, multicast
        self.where = f"NatNet ({'multicast' if multicast else 'unicast'}) at {host}:{port}"
        self.on_frame, self.on_status = on_frame, on_status
        self.local_ip = local_ip
        self.timeout_s, self.silence_s = timeout_s, silence_s
        self.policy = policy or ReconnectPolicy()
        self.info = StreamInfo([], [], float("nan"))
        self.connections = 0
        self.client: NatNetClient | None = None
        self._sets: list[tuple[str, int]] = []           # (marker set name, marker count) in the labels' order
        self._described = threading.Event()
        self._last_frame_s = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="natnet-client", daemon=True)

    def _local_ip(self) -> str:
        if self.local_ip:
            return self.local_ip
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect((self.host, self.port))       # no datagram is sent: the kernel picks the route
            return probe.getsockname()[0]

    def _on_descriptions(self, desc) -> None:
        sets = [ms for ms in desc.marker_sets if ms.name.lower() != "all"] or list(desc.marker_sets)
        labels = [f"{ms.name}:{m}" if len(sets) > 1 else m for ms in sets for m in ms.marker_names]
        self._sets = [(ms.name, len(ms.marker_names)) for ms in sets]
        if labels != self.info.labels:
            self.info = StreamInfo(labels, [], float("nan"))
        self._described.set()

    def _on_frame(self, frame) -> None:
        """A frame as ``natnet`` parsed it (a protocol before 4.1)."""
        self._on_markers(MarkerFrame(frame.prefix.frame_number, {ms.model_name: np.array(ms.marker_pos_list, float)
                                                                 for ms in frame.marker_sets}, frame.suffix.timestamp))

    def _on_markers(self, frame: MarkerFrame) -> None:
        self._last_frame_s = time.monotonic()
        if not self._described.is_set():
            return
        parts = []
        for name, count in self._sets:
            pos = frame.marker_sets.get(name, np.zeros((0, 3))).reshape(-1, 3)
            parts.append(pos if len(pos) == count else np.full((count, 3), np.nan))
        mm = np.vstack(parts) * 1e3 if parts else np.zeros((0, 3))
        self.on_frame(DataFrame(int(round(frame.timestamp_s * 1e6)), frame.frame_number, mm), self.info)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._close()

    def _close(self) -> None:
        client, self.client = self.client, None
        if client is not None:
            try:
                client.shutdown()
            except OSError:
                pass

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._session()
            except CaptureError as err:
                self.on_status(str(err), False)
            except Exception as err:  # noqa: BLE001 - the loop must survive
                self.on_status(f"{self.where}: {type(err).__name__}: {err}", False)
            finally:
                self._close()
            self._stop.wait(self.policy.next_delay_s())

    def _connect(self) -> NatNetClient:
        try:
            client = MarkerFrameClient(self._on_markers, server_ip_address=self.host,
                                       local_ip_address=self._local_ip(), command_port=self.port,
                                       data_port=self.port + 1, use_multicast=self.multicast)
            client.on_data_description_received_event.handlers.append(self._on_descriptions)
            client.on_data_frame_received_event.handlers.append(self._on_frame)
            self.client = client
            client.connect(timeout=self.timeout_s)
        except TimeoutError:
            raise CaptureError(f"cannot connect to {self.where}: no server info in reply to NAT_CONNECT within "
                               f"{self.timeout_s:g} s (is Motive streaming, unicast, with command port "
                               f"{self.port}?)") from None
        except OSError as err:
            raise CaptureError(f"cannot connect to {self.where}: {err}") from None
        return client

    def _session(self) -> None:
        self._described.clear()
        client = self._connect()
        server = client.server_info
        client.run_async()
        deadline = time.monotonic() + self.timeout_s
        while not self._stop.is_set() and not self._described.is_set():
            if time.monotonic() > deadline:
                raise CaptureError(f"{self.where}: no NAT_MODELDEF in reply to NAT_REQUEST_MODELDEF within "
                                   f"{self.timeout_s:g} s: the markers cannot be named")
            client.request_modeldef()                     # UDP: asked again until answered
            self._described.wait(0.5)
        if self._stop.is_set():
            return
        if not self.info.labels:
            raise CaptureError(f"{self.where}: the server describes no marker set: define the subject's marker "
                               "set (asset) in Motive")
        self.connections += 1
        self._last_frame_s = time.monotonic()
        self.on_status(f"connected to {self.where}: {server.application_name} {server.server_version}, NatNet "
                       f"{client.protocol_version.truncate(2)}; {len(self.info.labels)} markers in "
                       f"{len(self._sets)} marker set(s)", True)
        self.policy.succeeded()
        while not self._stop.wait(0.05):
            if time.monotonic() - self._last_frame_s > self.silence_s:
                raise CaptureError(f"{self.where}: no frame for {self.silence_s:g} s; reconnecting")
