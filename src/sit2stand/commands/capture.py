"""`sit2stand` sub-commands of live capture: a capture-system stand-in that serves a recording.

Each handler imports its stage when it runs (see :mod:`sit2stand.cli`).
"""

from __future__ import annotations

import argparse
import signal
from pathlib import Path

DEFAULT_PORTS = {"qtm": 22223, "natnet": 1510}


def _serve_c3d(args: argparse.Namespace) -> int:
    from ..capture.recording import load_recording
    from ..capture.server import NatNetServer, QtmServer

    recording = load_recording(args.file)
    port = DEFAULT_PORTS[args.protocol] if args.port is None else args.port
    if args.protocol == "natnet":
        server = NatNetServer(recording, args.host, port, speed=args.rate, loop=args.loop, up_axis=args.up_axis)
        what = (f"NatNet 4.1 (unicast, markers only, metres, {args.up_axis.upper()} up) on UDP "
                f"{args.host}:{server.port}")
    else:
        server = QtmServer(recording, args.host, port, speed=args.rate, loop=args.loop)
        what = f"QTM RT protocol on {args.host}:{server.port}"
    print(f"serve-c3d: {recording.source}: {len(recording.labels)} markers, {len(recording.plates)} plates, "
          f"{recording.n_frames} frames at {recording.rate_hz:g} Hz; {what}", flush=True)
    _stop_on_signals()
    try:
        return server.serve(exit_at_end=not args.stay)
    except KeyboardInterrupt:
        server.stop()
        print(f"serve-c3d: stopped: {server.frames_sent} frames sent", flush=True)
        return 0


def _stop_on_signals() -> None:
    """SIGINT and SIGTERM stop the server. Python leaves SIGINT ignored when the process starts with it ignored (a
    background job of a non-interactive shell, `nohup`, and everything they start): the server then ran on after
    SIGINT."""
    def stop(signum, frame):
        raise KeyboardInterrupt

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, stop)


def add_serve_c3d(sub) -> None:
    p = sub.add_parser("serve-c3d", help="serve a C3D's markers and plates over a capture system's real-time "
                       "protocol (a stand-in for QTM, or for OptiTrack Motive over NatNet: markers only)",
                       description="Serve a recording at its own rate as a capture system would stream it live. "
                       "qtm: QTM's RT protocol over TCP (or UDP streaming), labelled markers and force plates. "
                       "natnet: NatNet 4.1 unicast over UDP as Motive streams it, markers only (one marker set "
                       "named after the file; force plates are not served: the bridge publishes markers only on "
                       "NatNet), in metres in Motive's default y-up axes (bridge: up:=+Y; --up-axis Z keeps the "
                       "file's axes).")
    p.add_argument("file", type=Path, help="a .c3d file, or a sit2stand bag folder (a demonstration)")
    p.add_argument("--protocol", default="qtm", choices=["qtm", "natnet"])
    p.add_argument("--host", default="0.0.0.0", help="address to listen on (default: every interface)")
    p.add_argument("--port", type=int, default=None, help="qtm: TCP port (default 22223, QTM's little-endian port); "
                   "natnet: UDP command port (default 1510); 0: any")
    p.add_argument("--rate", type=float, default=1.0, help="speed: x the file's own rate (2: a 100 Hz file at 200 Hz)")
    p.add_argument("--loop", action="store_true", help="start again at the end (frame numbers and times go on)")
    p.add_argument("--stay", action="store_true",
                   help="keep serving after the end (qtm: new clients get No More Data; natnet: no more frames)")
    p.add_argument("--up-axis", default="Y", type=str.upper, choices=["Y", "Z"],
                   help="natnet: the served up axis: Y (Motive's default; z-up recordings are turned -90 deg "
                   "about x: served (x, y, z) = file (x, z, -y)) or Z (the file's own axes)")
    p.set_defaults(func=_serve_c3d)
