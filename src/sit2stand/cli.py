"""The `sit2stand` command: one entry point for the offline tools and for starting nodes and graphs.

    sit2stand import-c3d FILE.c3d --out BAG [--chair-plate I] [--feet-plate J] [--forward +X --up +Z]
    sit2stand import-trc FILE.trc [--grf FILE.mot] [--mass KG --height M] --out BAG   (OpenSim markers and forces)
    sit2stand synth-human --style natural|elderly [--height M --mass KG ...] [--extra-mass SEG:KG[:x,y,z]] --out BAG
    sit2stand human-com BAG --out DIR [--marker-set NAME|FILE]   (offline human COM: JSON, PNG, CSV, .sto, a bag)
    sit2stand human-calibrate BAG --out FILE.yaml [--frames 50]   (the human_com node's calibration_file)
    sit2stand retarget BAG --out DIR [--params P.yaml] [--simulate] [--time-scale S | --max-time-scale S]
    sit2stand drive [--plant PLANT] [--params P.yaml] [--rtf R] [--clock]   (the driver node)
    sit2stand collect-postures [--plant PLANT] --n 88 --out DIR
    sit2stand identify DIR --model planar5|full --out params.yaml
    sit2stand excite [--plant PLANT] [--seed N] --out DIR    (an excitation run of the simulated robot)
    sit2stand gap BAG [BAG ...] [--model cad|FILE] [--controller P.yaml] --out DIR   (what the robot model misses)
    sit2stand gap-human BAG [--out FILE.json]                (the same on a human demonstration)
    sit2stand robot check ROBOT | robot list                  (a robot profile: check it; the packaged ones)
    sit2stand export RUN --format csv|npz [--rate HZ] --out FILE   (a simulated stand-up as a motion file)
    sit2stand view RUN|BAG [--save FILE.rrd | --web | --screenshot FILE.png [--at S]]   (a run in Rerun)
    sit2stand batch standup|gap|gap-human [--cases N | --grid F.yaml] [--address A] --out DIR   (batches on Ray)
    sit2stand bag info|recover|merge ...
    sit2stand launch GRAPH [NAME:=VALUE ...] [--timeout S]   (a graph file, or a packaged graph's name: standup)
    sit2stand replay BAG [--rate R] [--loop] [--topics T ...]   (the replayer node)
    sit2stand record --out BAG [--topics T ...] [--regex RE]    (the recorder node)
    sit2stand serve-c3d FILE.c3d --protocol qtm [--port P] [--rate R] [--loop]   (a QTM stand-in for the bridge)

PLANT is a plant YAML or a packaged plant's name (default, heavy_front, cad; G1's g1_default, g1_cad; iCub's
icub_default; Romeo's romeo_default). ROBOT (``--robot``) is a robot profile, packaged (``sit2stand robot list``) or
a YAML file; with it a packaged plant's name means that robot's own (``default`` is ``g1_default`` for G1).
Errors are printed as one line naming the file, topic or field, with exit code 2.

Each sub-command imports its stage when it runs: importing every stage (Pinocchio, MuJoCo, SciPy, rclpy) costs
~3 s, while ``--help`` and ``bag info`` need 0.2-0.7 s (measured on the 2-core development machine).
"""

from __future__ import annotations

import argparse
import sys

from .commands import batch, capture, graph, human, robot, view

COMMANDS = [
    human.add_import_c3d,
    human.add_import_trc,
    human.add_synth_human,
    human.add_human_com,
    human.add_human_calibrate,
    robot.add_retarget,
    robot.add_drive,
    robot.add_collect_postures,
    robot.add_identify,
    robot.add_excite,
    robot.add_gap,
    robot.add_robot,
    robot.add_export,
    view.add_view,
    batch.add_batch,
    human.add_gap_human,
    graph.add_bag,
    graph.add_launch,
    graph.add_replay,
    graph.add_record,
    capture.add_serve_c3d,
]
"""The sub-commands, in the order ``--help`` lists them."""


def build_parser() -> argparse.ArgumentParser:
    """The ``sit2stand`` argument parser: one sub-command per entry of :data:`COMMANDS`."""
    parser = argparse.ArgumentParser(prog="sit2stand", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for add in COMMANDS:
        add(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one sub-command; a domain error (or a file that cannot be read) is one line on stderr and exit 2."""
    from .data import plant_path
    from .errors import Sit2StandError

    args = build_parser().parse_args(argv)
    try:
        if hasattr(args, "plant"):       # named here before any stage loads (a packaged name: the robot's own)
            args.plant = args.plant or "default"
            plant_path(args.plant)
        return int(args.func(args) or 0)
    except (Sit2StandError, OSError) as err:
        print(f"sit2stand {args.command}: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
