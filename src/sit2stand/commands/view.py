"""``sit2stand view``: a run in Rerun's viewer (:mod:`sit2stand.view`)."""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from .robot import ROBOT_HELP


def _view(args: argparse.Namespace) -> int:
    from ..view import rerun_view
    from ..view.scene import load_scene, rise_time_s

    started = time.monotonic()
    scene = load_scene(Path(args.run), robot=args.robot)
    if args.save or args.screenshot:
        with tempfile.TemporaryDirectory() as tmp:
            rrd = Path(args.save) if args.save else Path(tmp) / "view.rrd"
            rerun_view.save(scene, rrd, overlay=args.overlay)
            print(f"{rrd}: {len(scene.robot.visuals) if scene.robot else 0} robot meshes, "
                  f"{time.monotonic() - started:.1f} s")
            if args.screenshot:
                at = args.at if args.at is not None else rise_time_s(scene)
                rerun_view.screenshot(rrd, Path(args.screenshot), at)
                print(f"{args.screenshot}: Rerun at t = {at:.2f} s")
        return 0
    url = rerun_view.show(scene, web=args.web, overlay=args.overlay)
    print(f"sent to the viewer in {time.monotonic() - started:.1f} s")
    if url is not None:
        print(f"Rerun's web viewer: {url} (Ctrl-C to stop)")
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
    return 0


def add_view(sub) -> None:
    p = sub.add_parser("view", help="a run in Rerun: robot meshes, human skeleton and markers, chairs, plates, COM, "
                                    "COP, ZMP and support polygon in 3D, beside human vs robot time series")
    p.add_argument("run", help="a bag, a stand-up run folder (its standup/ bag) or a `retarget --simulate` folder")
    p.add_argument("--save", metavar="FILE.rrd", help="write the recording (meshes included) instead of opening it")
    p.add_argument("--web", action="store_true", help="serve Rerun's browser viewer instead of the native one")
    p.add_argument("--screenshot", metavar="FILE.png", help="a picture of Rerun's viewer (headless, Vulkan) at --at")
    p.add_argument("--at", type=float, help="bag time [s] of the screenshot (default: half-way through the rise)")
    p.add_argument("--overlay", action="store_true", help="draw the human where the robot is, not beside it")
    p.add_argument("--robot", help=ROBOT_HELP)
    p.set_defaults(func=_view)
