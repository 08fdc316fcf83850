"""`sit2stand` sub-commands of live capture: a capture-system stand-in that serves a recording.

Each handler imports its stage when it runs (see :mod:`sit2stand.cli`).
"""

from __future__ import annotations

import argparse
from pathlib import Path


def _serve_c3d(args: argparse.Namespace) -> int:
    from ..capture.recording import load_recording
    from ..capture.server import QtmServer
    from ..errors import InputError

    if args.protocol != "qtm":
        raise InputError(f"--protocol {args.protocol}: only qtm is served (the natnet package has no server or "
                         "replay of its own to serve NatNet with)")
    recording = load_recording(args.file)
    server = QtmServer(recording, args.host, args.port, speed=args.rate, loop=args.loop)
    print(f"serve-c3d: {recording.source}: {len(recording.labels)} markers, {len(recording.plates)} plates, "
          f"{recording.n_frames} frames at {recording.rate_hz:g} Hz; QTM RT protocol on {args.host}:{server.port}",
          flush=True)
    try:
        return server.serve(exit_at_end=not args.stay)
    except KeyboardInterrupt:
        server.stop()
        return 0


def add_serve_c3d(sub) -> None:
    p = sub.add_parser("serve-c3d", help="serve a C3D's markers and plates over a capture system's real-time "
                       "protocol (a stand-in for QTM)")
    p.add_argument("file", type=Path, help="a .c3d file, or a sit2stand bag folder (a demonstration)")
    p.add_argument("--protocol", default="qtm", choices=["qtm", "natnet"])
    p.add_argument("--host", default="0.0.0.0", help="address to listen on (default: every interface)")
    p.add_argument("--port", type=int, default=22223, help="TCP port (QTM's little-endian port: 22223; 0: any)")
    p.add_argument("--rate", type=float, default=1.0, help="speed: x the file's own rate (2: a 100 Hz file at 200 Hz)")
    p.add_argument("--loop", action="store_true", help="start again at the end (frame numbers and times go on)")
    p.add_argument("--stay", action="store_true", help="keep serving after the end (new clients get No More Data)")
    p.set_defaults(func=_serve_c3d)
