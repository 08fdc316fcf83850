"""A capture-system stand-in: serves a :class:`~.recording.CaptureRecording` over QTM's real-time protocol or NatNet.

``sit2stand serve-c3d FILE --protocol qtm --port P [--rate R] [--loop]``. Speaks protocol 1.8-1.25 on the
little-endian port as QTM does (see :mod:`.qtm_protocol`): the welcome string, ``Version``, ``QTMVersion``,
``ByteOrder``, ``GetState``, ``GetParameters`` (General, 3D, Force), ``GetCurrentFrame``, ``StreamFrames``
(``AllFrames``, ``FrequencyDivisor:n``, ``Frequency:n``; over TCP or ``UDP[:address]:port``; components 3D, 3DRes,
3DNoLabels, Force, ForceSingle) and ``ByeBye``/``Quit``; anything else is answered ``Parse Error``.

The measurement is one clock shared by every client, like QTM's: it starts at the first ``StreamFrames`` (so a
client that connects first gets frame 1) and plays at the file's rate times ``speed``. Frame ``k`` is sent when
its capture time ``origin + k / rate`` comes: the origin (CLOCK_REALTIME) is printed, so a program on the same
clock measures latency from capture. At the end (without ``loop``) every streaming client gets a No More Data
packet and the event RT From File Stopped.

Threads, not asyncio: the frame clock sleeps to 1 ms before a frame's time and spins the rest, so frames leave
within ~0.1 ms of their capture time (an asyncio timer was 1 ms late at p50); at real-time priority it only sleeps.

``sit2stand serve-c3d FILE --protocol natnet --port P [--rate R] [--loop]`` (:class:`NatNetServer`) stands in for
OptiTrack Motive streaming NatNet 4.1 in unicast (see :mod:`.natnet_protocol`): one UDP socket on the command port
answers NAT_CONNECT (server info), NAT_REQUEST_MODELDEF (one marker set named after the file, with its labels),
NAT_REQUEST_FRAMEOFDATA (the current frame), ``FrameRate`` requests, keep-alives and NAT_DISCONNECT; anything else
is answered NAT_UNRECOGNIZED_REQUEST. Frames go, from the same socket, to the address each NAT_CONNECT came from:
``natnet``'s unicast client binds its data socket to a port nobody is told and reads frames on its command socket,
which keeps the server's path open with keep-alives. A client silent for :data:`CLIENT_TIMEOUT_S` is dropped. The
clock starts once the reply to the first NAT_REQUEST_MODELDEF has left (a client that connects and asks for the
names gets frame 1, after the names), or :data:`NATNET_START_S` after the first NAT_CONNECT. Markers only: force
plates are not served over NatNet (Motive's plates stream raw channels without geometry, which the bridge does not
publish). Positions are metres in Motive's default y-up axes (``--up-axis Y``; ``Z``: the recording's own axes).
"""

from __future__ import annotations

import os
import socket
import struct
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from . import natnet_protocol as nn
from .qtm_protocol import (OLDEST_VERSION, PROTOCOL_VERSION, WELCOME, Component, Event, PacketType, ProtocolError,
                           StreamRequest, data_packet, event_packet, packet, parameters_xml, parse_stream_frames,
                           parse_version, split_packets, string_packet, text_of)
from .recording import CaptureRecording

QTM_VERSION = "QTM Version is 2024.2 (sit2stand serve-c3d)"
SPIN_S = 0.001


@dataclass
class _Stream:
    """A client's StreamFrames request: where to send, which components, every n-th frame."""

    client: _Client
    request: StreamRequest
    divisor: int
    udp_target: tuple[str, int] | None


class _Client(threading.Thread):
    """One TCP client: reads commands, answers them; the frame clock writes its data packets."""

    def __init__(self, server: QtmServer, sock: socket.socket, address: tuple[str, int]) -> None:
        super().__init__(name=f"qtm-client-{address[1]}", daemon=True)
        self.server, self.sock, self.address = server, sock, address
        self.lock = threading.Lock()
        self.alive = True
        self.version = "1.1"

    def send(self, data: bytes) -> None:
        with self.lock:
            try:
                self.sock.sendall(data)
            except OSError:
                self.alive = False

    def run(self) -> None:
        self.send(string_packet(PacketType.COMMAND, WELCOME))
        buffer = b""
        try:
            while self.alive and not self.server.stopped.is_set():
                chunk = self.sock.recv(65536)
                if not chunk:
                    break
                packets, buffer = split_packets(buffer + chunk)
                for kind, body in packets:
                    self._on_packet(kind, body)
        except (OSError, ProtocolError):
            pass
        finally:
            self.close()

    def close(self) -> None:
        self.alive = False
        self.server.drop(self)
        try:
            self.sock.close()
        except OSError:
            pass

    def _on_packet(self, kind: PacketType, body: bytes) -> None:
        if kind != PacketType.COMMAND:
            self.send(string_packet(PacketType.ERROR, "Parse Error"))
            return
        words = text_of(body).split()
        if not words:
            return
        try:
            reply = self.server.command(self, words[0].lower(), words[1:])
        except ProtocolError as err:
            reply = string_packet(PacketType.ERROR, str(err))
        if reply:
            self.send(reply)


class _FrameClock:
    """The measurement's clock, shared by both servers: waits for :attr:`started`, then sends frame ``k`` when its
    capture time ``origin + k / (rate x speed)`` comes (:meth:`_send_frame`), once or looping, then :meth:`_end`."""

    recording: CaptureRecording
    speed: float
    loop: bool
    stopped: threading.Event
    started: threading.Event
    origin_ns: int
    frames_sent: int
    log: Callable[..., None]

    # --- the frame clock -------------------------------------------------------------------------------------
    def _wait_until(self, t_ns: int) -> None:
        # time-shared, a sleep wakes up to ~1 ms late: sleep to SPIN_S before, spin the rest; in real time it wakes
        # within tens of microseconds, and a spin at real-time priority would hold the rest of a small machine off
        spin_s = 0.0 if os.sched_getscheduler(0) in (os.SCHED_FIFO, os.SCHED_RR) else SPIN_S
        while not self.stopped.is_set():
            left = (t_ns - time.time_ns()) * 1e-9
            if left <= 0:
                return
            if left > spin_s:
                time.sleep(left - spin_s)

    def _play(self) -> None:
        self.started.wait()
        rec = self.recording
        period_ns = 1e9 / (rec.rate_hz * self.speed)
        self.origin_ns = time.time_ns()
        self.log(f"streaming {rec.source}: {rec.n_frames} frames at {rec.rate_hz * self.speed:g} Hz; capture clock "
                 f"origin {self.origin_ns} ns (CLOCK_REALTIME) at timestamp 0", flush=True)
        pass_index = 0
        while not self.stopped.is_set():
            for k in range(rec.n_frames):
                number = pass_index * rec.n_frames + k
                self._wait_until(self.origin_ns + int(round(number * period_ns)))
                if self.stopped.is_set():
                    return
                self._send_frame(k, pass_index)
            pass_index += 1
            if not self.loop:
                break
        self._end()

    def _send_frame(self, k: int, pass_index: int) -> None:
        raise NotImplementedError

    def _end(self) -> None:
        raise NotImplementedError


class QtmServer(_FrameClock):
    """Serves one recording to any number of clients (see the module docstring)."""

    def __init__(self, recording: CaptureRecording, host: str = "127.0.0.1", port: int = 22223,
                 speed: float = 1.0, loop: bool = False, log=print) -> None:
        if speed <= 0:
            raise ProtocolError(f"--rate must be positive, not {speed}")
        self.recording, self.speed, self.loop, self.log = recording, float(speed), loop, log
        self.stopped = threading.Event()
        self.started = threading.Event()
        self.streams: dict[int, _Stream] = {}
        self.clients: list[_Client] = []
        self.frames_sent = 0
        self.origin_ns = 0
        self.listener = socket.create_server((host, port), reuse_port=False)
        self.port = self.listener.getsockname()[1]
        self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._lock = threading.Lock()

    # --- commands --------------------------------------------------------------------------------------------
    def command(self, client: _Client, word: str, args: list[str]) -> bytes | None:
        """The reply packet to one command (None: no reply, as for ``StreamFrames``)."""
        if word == "version":
            return self._version(client, args)
        if word == "qtmversion":
            return string_packet(PacketType.COMMAND, QTM_VERSION)
        if word == "byteorder":
            return string_packet(PacketType.COMMAND, "Byte order is little endian")
        if word == "getstate":
            return event_packet(Event.RT_FROM_FILE_STARTED if self.started.is_set() else Event.RT_FROM_FILE_STOPPED)
        if word == "getparameters":
            return self._parameters(client, {a.lower() for a in args})
        if word == "getcurrentframe":
            req = parse_stream_frames(["allframes", *args])
            return data_packet(self.recording.frame(min(self.frames_sent, self.recording.n_frames - 1)),
                               req.components)
        if word == "streamframes":
            return self._stream(client, args)
        if word in ("byebye", "bye", "quit"):
            client.alive = False
            return None
        return string_packet(PacketType.ERROR, "Parse Error")

    def _version(self, client: _Client, args: list[str]) -> bytes:
        if not args:
            return string_packet(PacketType.COMMAND, f"Version is {client.version}")
        major, minor = parse_version(args[0])
        if major != 1 or (major, minor) < OLDEST_VERSION or (major, minor) > parse_version(PROTOCOL_VERSION):
            return string_packet(PacketType.ERROR, "Version NOT supported")
        client.version = f"{major}.{minor}"
        return string_packet(PacketType.COMMAND, f"Version set to {client.version}")

    def _parameters(self, client: _Client, what: set[str]) -> bytes:
        rec = self.recording
        every = "all" in what
        labels = rec.labels if every or "3d" in what else None
        plates = [replace(p.info, rate_hz=p.info.rate_hz * self.speed) for p in rec.plates] \
            if every or "force" in what else None      # served at speed x the file's rate: so are the plates
        return string_packet(PacketType.XML, parameters_xml(labels, plates, rec.rate_hz * self.speed, client.version))

    def _stream(self, client: _Client, args: list[str]) -> None:
        if args and args[0].lower() == "stop":
            with self._lock:
                self.streams.pop(id(client), None)
            return None
        req = parse_stream_frames(args)
        divisor = req.divisor
        if req.frequency_hz:
            divisor = max(1, int(round(self.recording.rate_hz * self.speed / req.frequency_hz)))
        target = (req.udp_address or client.address[0], req.udp_port) if req.udp_port else None
        with self._lock:
            self.streams[id(client)] = _Stream(client, req, divisor, target)
        self.started.set()
        return None

    def drop(self, client: _Client) -> None:
        with self._lock:
            self.streams.pop(id(client), None)
            if client in self.clients:
                self.clients.remove(client)

    # --- the frame clock (_FrameClock) -------------------------------------------------------------------------
    def _send_frame(self, k: int, pass_index: int) -> None:
        frame = self.recording.frame(k, pass_index, self.speed)
        with self._lock:
            streams = list(self.streams.values())
        encoded: dict[tuple[Component, ...], bytes] = {}
        for s in streams:
            if (frame.frame_number - 1) % s.divisor:
                continue
            key = tuple(s.request.components)
            data = encoded.get(key) or encoded.setdefault(key, data_packet(frame, s.request.components))
            if s.udp_target is not None:
                try:
                    self.udp.sendto(data, s.udp_target)
                except OSError:
                    pass
            else:
                s.client.send(data)
        self.frames_sent += 1

    def _end(self) -> None:
        with self._lock:
            streams = list(self.streams.values())
        for s in streams:
            s.client.send(packet(PacketType.NO_MORE_DATA) + event_packet(Event.RT_FROM_FILE_STOPPED))
        self.log(f"end of {self.recording.source}: {self.frames_sent} frames sent", flush=True)

    # --- running ---------------------------------------------------------------------------------------------
    def serve(self, exit_at_end: bool = True) -> int:
        """Accept clients and play the recording; returns when it has been played (``exit_at_end``), on
        :meth:`stop`, or never with ``loop``."""
        player = threading.Thread(target=self._play, name="frame-clock", daemon=True)
        player.start()
        self.listener.settimeout(0.2)
        try:
            while not self.stopped.is_set():
                if exit_at_end and not player.is_alive():
                    time.sleep(0.5)          # the end packets reach the clients before the sockets close
                    break
                try:
                    sock, address = self.listener.accept()
                except TimeoutError:
                    continue
                except OSError:          # stop() closed the socket from another thread
                    break
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)   # as the protocol asks: no Nagle
                client = _Client(self, sock, address)
                with self._lock:
                    self.clients.append(client)
                client.start()
        finally:
            self.stop()
        return 0

    def stop(self) -> None:
        """Stop playing, close every client and the listening socket."""
        self.stopped.set()
        self.started.set()
        with self._lock:
            clients = list(self.clients)
        for c in clients:
            c.close()
        self.listener.close()
        self.udp.close()


CLIENT_TIMEOUT_S = 10.0
NATNET_START_S = 1.0


class NatNetServer(_FrameClock):
    """Serves one recording's markers over NatNet, unicast, to any number of clients (see the module docstring)."""

    def __init__(self, recording: CaptureRecording, host: str = "127.0.0.1", port: int = 1510,
                 speed: float = 1.0, loop: bool = False, up_axis: str = "Y", log=print) -> None:
        if speed <= 0:
            raise ProtocolError(f"--rate must be positive, not {speed}")
        if up_axis.upper() not in ("Y", "Z"):
            raise ProtocolError(f"--up-axis must be Y (Motive's default) or Z, not {up_axis!r}")
        self.recording, self.speed, self.loop, self.log = recording, float(speed), loop, log
        self.axes = nn.Y_UP if up_axis.upper() == "Y" else nn.Z_UP
        self.set_name = Path(recording.source).stem or "markers"
        self.stopped = threading.Event()
        self.started = threading.Event()
        self.clients: dict[tuple[str, int], float] = {}      # address -> when last heard (monotonic)
        self.frames_sent = 0
        self.origin_ns = 0
        self.current = 0
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self.port = self.sock.getsockname()[1]
        self._lock = threading.Lock()
        self._start_timer: threading.Timer | None = None
        self._start_after_reply = False     # the clock starts once the NAT_MODELDEF reply has left

    # --- requests --------------------------------------------------------------------------------------------
    def reply(self, data: bytes, address: tuple[str, int]) -> bytes | None:
        """The reply to one datagram from ``address`` (None: none, as for a keep-alive)."""
        try:
            kind, text = nn.parse_request(data)
        except Exception:  # noqa: BLE001 - a malformed datagram is dropped, as a server must
            return None
        now = time.monotonic()
        with self._lock:
            if address in self.clients:
                self.clients[address] = now
        if kind == nn.Message.CONNECT:
            with self._lock:
                new = address not in self.clients
                self.clients[address] = now
            if new:
                self.log(f"NatNet client {address[0]}:{address[1]} connected", flush=True)
            if self._start_timer is None and not self.started.is_set():
                self._start_timer = threading.Timer(NATNET_START_S, self.started.set)
                self._start_timer.daemon = True
                self._start_timer.start()
            return nn.server_info(data_port=self.port)
        if kind == nn.Message.REQUEST_MODELDEF:
            self._start_after_reply = True      # frame 1 must not overtake the names (a client drops it unnamed)
            return nn.model_definitions([(self.set_name, self.recording.labels)])
        if kind == nn.Message.REQUEST_FRAMEOFDATA:
            return nn.frame_of_data(self._frame(min(self.current, self.recording.n_frames - 1), 0))
        if kind == nn.Message.KEEPALIVE:
            return None
        if kind == nn.Message.DISCONNECT:
            with self._lock:
                self.clients.pop(address, None)
            return None
        if kind == nn.Message.REQUEST and text.lower() == "framerate":
            return nn.message(nn.Message.RESPONSE, struct.pack("<f", self.recording.rate_hz * self.speed))
        return nn.message(nn.Message.UNRECOGNIZED_REQUEST)

    # --- the frame clock (_FrameClock) -------------------------------------------------------------------------
    def _frame(self, k: int, pass_index: int) -> nn.NatNetFrame:
        frame = self.recording.frame(k, pass_index, self.speed)
        t_ns = self.origin_ns + frame.timestamp_us * 1000
        return nn.capture_frame(frame, self.recording.labels, self.set_name, self.axes,
                                stamps=(t_ns, t_ns, time.time_ns()))

    def _send_frame(self, k: int, pass_index: int) -> None:
        self.current = k
        now = time.monotonic()
        with self._lock:
            for address in [a for a, t in self.clients.items() if now - t > CLIENT_TIMEOUT_S]:
                del self.clients[address]
                self.log(f"NatNet client {address[0]}:{address[1]} dropped: silent for {CLIENT_TIMEOUT_S:g} s",
                         flush=True)
            targets = list(self.clients)
        if targets:
            data = nn.frame_of_data(self._frame(k, pass_index))
            for address in targets:
                try:
                    self.sock.sendto(data, address)
                except OSError:
                    pass
        self.frames_sent += 1

    def _end(self) -> None:
        self.log(f"end of {self.recording.source}: {self.frames_sent} frames sent", flush=True)

    # --- running ---------------------------------------------------------------------------------------------
    def serve(self, exit_at_end: bool = True) -> int:
        """Answer requests and play the recording; returns when it has been played (``exit_at_end``), on
        :meth:`stop`, or never with ``loop``."""
        player = threading.Thread(target=self._play, name="frame-clock", daemon=True)
        player.start()
        self.sock.settimeout(0.2)
        try:
            while not self.stopped.is_set():
                if exit_at_end and not player.is_alive():
                    break
                try:
                    data, address = self.sock.recvfrom(65536)
                except TimeoutError:
                    continue
                except OSError:           # stop() closed the socket, or an ICMP error of an earlier send
                    if self.stopped.is_set():
                        break
                    continue
                answer = self.reply(data, address)
                if answer:
                    try:
                        self.sock.sendto(answer, address)
                    except OSError:
                        pass
                if self._start_after_reply:
                    self.started.set()
        finally:
            self.stop()
        return 0

    def stop(self) -> None:
        """Stop playing and close the socket."""
        self.stopped.set()
        self.started.set()
        if self._start_timer is not None:
            self._start_timer.cancel()
        self.sock.close()
