"""`sit2stand` sub-commands of the robot side: retargeting, the simulated robot, identification, the model gap.

Each ``add_*`` function adds one sub-command to the parser (see :mod:`sit2stand.cli`); each handler imports its
stage when it runs, so that ``sit2stand --help`` stays fast (measured in :mod:`sit2stand.cli`'s docstring).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from .graph import ros_params

CONTROLLER_CHOICES = ("inverse_dynamics", "wbc")
"""``robot.plant.CONTROLLERS``, spelled here because the CLI builds its parsers without importing the robot
stack (a test keeps the two equal)."""
DEFAULT_CONTROLLER = "wbc"
"""``robot.plant.DEFAULT_CONTROLLER``, spelled here for the same reason (the same test keeps them equal)."""
PLAN_CHOICES, DEFAULT_PLAN = ("whole", "frames"), "whole"
"""``retarget.offline.PLANS`` and ``DEFAULT_PLAN``, spelled here for the same reason (a test keeps them equal)."""


ROBOT_HELP = "robot profile: a packaged one (`sit2stand robot list`) or a YAML file (default: the plant's; TALOS)"
"""The ``--robot`` option's help; ``docs/robots.md`` says how to write a profile."""


def _retarget(args: argparse.Namespace) -> int:
    from ..gap.workflow import progress_printer
    from ..retarget.offline import run
    from ..retarget.stream import RetargetConfig
    from ..retarget.whole_rise import WholeRiseConfig
    from ..scheduling import usable_cores

    summary = run(Path(args.bag), Path(args.out), params=args.params, plant=args.plant, robot=args.robot,
                  config=RetargetConfig(marker_set=args.marker_set), calibration_frame=args.calibration_frame,
                  static=args.static,
                  human_com_bag=args.human_com, margin_m=args.margin, time_scale=args.time_scale,
                  **({"max_time_scale": args.max_time_scale} if args.max_time_scale else {}),
                  simulate=args.simulate, com_feedback=not args.no_com_feedback, whole=args.whole,
                  dynamic=args.dynamic, controller=args.controller, retiming=args.retiming, plan=args.plan,
                  whole_rise=WholeRiseConfig(threads=args.oc_threads or usable_cores()), progress=progress_printer,
                  **({"seat_off_dwell_s": args.seat_off_dwell} if args.seat_off_dwell is not None else {}))
    print(json.dumps(summary, indent=2))
    if args.simulate:
        ok = summary["stood_up"] and summary.get("sat_down") is not False
        if not summary["stood_up"]:
            squat = summary.get("standing_knees_match") is False
            why = summary["fall"] or (f"ended in a squat: knees flexed {summary['final_knee_flexion_deg_robot']:.0f} "
                                      f"degrees, the human's {summary['final_knee_flexion_deg_human']:.0f}"
                                      if squat else "pelvis too low")
            print(f"did not stand up: {why}")
        elif summary.get("sat_down") is None:
            print("stood up")
        else:
            print("stood up and sat back down" if ok else f"stood up, did not sit back down: "
                  f"{summary['fall'] or 'pelvis not on the seat'}")
        _say_com_offset(summary)
        cycles = summary.get("cycles") or []
        if len(cycles) > 1:         # a trial of several sit-stand-sit cycles: each one counts
            stood, sat = sum(c["stood"] for c in cycles), sum(c["sat"] for c in cycles)
            print(f"{len(cycles)} cycles: stood up in {stood}, sat back down in {sat}")
            ok = ok and stood == sat == len(cycles)
        return 0 if ok else 1
    return 0


COM_OFFSET_TOLD_M = 0.01
"""The whole-body controller's COM offset estimate (``controller_com_offset_m``) from which ``retarget`` tells the
user that the controller's model misses mass [m]."""


def _say_com_offset(summary: dict) -> None:
    """Tell where the controller's feet put the robot's COM against its model's, when that is far enough off that the
    model misses mass worth identifying."""
    offset = summary.get("controller_com_offset_m")
    if offset is None or max(abs(offset[0]), abs(offset[1])) < COM_OFFSET_TOLD_M:
        return
    x, y = (100 * c for c in offset[:2])
    where = [f"{abs(x):.1f} cm {'behind' if x < 0 else 'ahead of'}"] if abs(x) >= 0.5 else []
    where += [f"{abs(y):.1f} cm {'right of' if y < 0 else 'left of'}"] if abs(y) >= 0.5 else []
    print(f"the robot's feet put its COM {' and '.join(where)} its model's, which the controller made up for: the "
          f"model misses mass (identify it: `sit2stand collect-postures`, `sit2stand identify`, `retarget --params`)")


def _drive(args: argparse.Namespace) -> int:
    from ..nodes.driver import main as driver_main

    return driver_main(["driver"] + ros_params([
        ("plant", str(args.plant) if args.plant else None), ("robot", args.robot),
        ("controller_params", str(args.params) if args.params else None), ("real_time_factor", float(args.rtf)),
        ("publish_clock", args.clock), ("feedforward", args.feedforward)]))


def _collect_postures(args: argparse.Namespace) -> int:
    from ..robot.model import PlantConfig
    from ..robot.postures import collect_postures

    cfg = PlantConfig.load(args.plant, args.robot)
    counts = collect_postures(cfg, args.n, args.out, seed=args.seed)
    print(f"wrote {args.out}: {counts['kept']} postures held ({counts['dropped']} tipped over and were dropped; the "
          f"upright stance showed the real COM {counts['home_com_bias_m'] * 1e3:+.0f} mm from CAD's)")
    return 0 if counts["kept"] >= min(args.n, 6) else 1


def _identify(args: argparse.Namespace) -> int:
    from ..robot.figures import com_path_figure, posture_figure
    from ..robot.identify import identify, read_postures, write_yaml

    result = identify(args.dir, args.model, eval_fraction=args.eval_fraction, seed=args.seed, robot=args.robot)
    print(result.summary())
    write_yaml(result, args.out, source=str(args.dir), robot=result.robot)
    png = Path(args.out).with_suffix(".png")
    posture_figure(result, read_postures(args.dir), png, args.eval_fraction, args.seed)
    written = [str(args.out), str(png)]
    if result.model_name == "full":
        path_png = Path(args.out).with_name(Path(args.out).stem + "_com_path.png")
        com_path_figure(result, path_png)
        written.append(str(path_png))
    print("wrote " + ", ".join(written))
    return 0


def _excite(args: argparse.Namespace) -> int:
    from ..gap.recording import excite
    from ..robot.model import PlantConfig

    info = excite(PlantConfig.load(args.plant, args.robot), args.out, seed=args.seed, n_moves=args.moves, progress=True)
    print(f"wrote {args.out}: {info['duration_s']:.1f} s of excitation"
          + (f"; the robot fell ({info['status']})" if info["fell"] else ""))
    return 1 if info["fell"] else 0


def _gap(args: argparse.Namespace) -> int:
    from ..gap.candidates import describe
    from ..gap.report import cop_lines, gap_command
    from ..gap.workflow import progress_printer

    result = gap_command(args.bags, args.out, model=args.model, rate_hz=args.rate, progress=progress_printer,
                         controller=args.controller, robot=args.robot)
    print(f"nominal model: {result.model_source}")
    if result.effects:
        print(f"named {len(result.effects)} effect(s):")
        for e in result.effects:
            print(f"  - {describe(e)}")
    else:
        print(result.verdict)
    if result.unexplained:
        worst = result.unexplained[0]
        print(f"left unexplained on {len(result.unexplained)} channel(s), worst {worst['channel']} "
              f"at {worst['z']:.1f} x its noise floor: {worst['shape']}")
    print(f"gap above the noise on the disagreeing channels, the effects applied: {result.gap_before:.2f} -> "
          f"{result.gap_after:.2f} (shrink {100 * result.shrink:.0f} %; to first order "
          f"{100 * result.shrink_first_order:.0f} %)")
    for line in cop_lines(result):
        print(line)
    print(f"report: {args.out}/report.md (+ gap.json, augmented_model.yaml, gap_*.png)")
    return 0


def add_retarget(sub) -> None:
    p = sub.add_parser("retarget", help="retarget a demonstration to robot joint commands (optionally simulate them)")
    p.add_argument("bag", help="demonstration bag (/mocap/markers, force plates)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--params", default=None, help="identified COM parameters YAML (default: CAD)")
    p.add_argument("--plant", default=None, help="plant YAML or a packaged plant: default (the default: the robot "
                   "with the mass its CAD model lacks), heavy_front, cad (nothing unmodeled)")
    p.add_argument("--human-com", default=None, help="bag with /human/com (default: the bag's, else estimated)")
    p.add_argument("--margin", type=float, default=0.04, help="ZMP margin inside the feet [m] (default 0.04)")
    p.add_argument("--time-scale", type=float, default=None, help="fixed time scale (default: adaptive)")
    p.add_argument("--max-time-scale", type=float,
                   help="the adaptive time scale's cap: at most this many times slower than the human "
                        "(default: retarget.player.DEFAULT_MAX_TIME_SCALE, 4)")
    p.add_argument("--simulate", action="store_true", help="execute the commands on the MuJoCo plant")
    p.add_argument("--whole", action="store_true", help="play the whole recording; by default a trial that ends "
                   "seated is played up to the human's sit-down; with --whole the robot sits back down")
    p.add_argument("--no-com-feedback", action="store_true",
                   help="simulate the commands as planned, without the COM feedback the node applies")
    p.add_argument("--dynamic", action="store_true",
                   help="experimental: pass the commands through the dynamics filter (whole-body QP: feet COP inside "
                        "the soles, torque limits), stretching time only where it cannot follow")
    p.add_argument("--controller", choices=CONTROLLER_CHOICES, default=DEFAULT_CONTROLLER,
                   help="the simulated robot's controller: whole-body torque control (a QP at 500 Hz; default) or "
                        "joint PD + inverse-dynamics feed-forward (inverse_dynamics)")
    p.add_argument("--seat-off-dwell", type=float, default=None,
                   help="the player's wait at the robot's seat-off [s] (default: retarget.player.SEAT_OFF_DWELL_S, 0)")
    p.add_argument("--plan", choices=PLAN_CHOICES, default=DEFAULT_PLAN,
                   help="whole: also the rise optimised as one problem (contacts, friction and COP cones, torque "
                        "limits) at the human's timing, and the plan that plays shorter played (default; 2-7x the "
                        "rise's duration); frames: the per-frame IK retimed frame by frame, as the live retargeter "
                        "plans")
    p.add_argument("--retiming", choices=("local", "uniform"), default="local",
                   help="local: slower only where a frame needs it (default); uniform: one growing factor")
    p.add_argument("--marker-set", help="marker set: plug_in_gait, plug_in_gait_lower, gait2392 or a YAML file "
                   "(default: the packaged set that covers most of the bag's marker names)")
    p.add_argument("--calibration-frame", type=int, metavar="N", help="the seated frame the robot's marker map is "
                   "made on (default: the one that sees the most markers in the quietest seated stretch)")
    p.add_argument("--oc-threads", type=_positive_int, metavar="N",
                   help="threads for the whole rise's optimisation, its knots in parallel (default: the cores this "
                        "process may use; on 2 idle cores 1.3x faster than 1, the solution the same to a few "
                        "iterations; a batch gives each case 1)")
    p.add_argument("--static", type=Path, metavar="FILE", help="calibrate the human skeleton on a static trial "
                   "(bag, .c3d or .trc) when the human COM is estimated here")
    p.add_argument("--robot", help=ROBOT_HELP)
    p.set_defaults(func=_retarget)


def _positive_int(text: str) -> int:
    n = int(text)
    if n < 1:
        raise argparse.ArgumentTypeError(f"{text}: at least 1")
    return n


def add_drive(sub) -> None:
    p = sub.add_parser("drive", help="the simulated robot (the driver node), seated on its chair")
    p.add_argument("--plant", help="plant YAML or a packaged plant: default (the default), heavy_front, cad")
    p.add_argument("--params", type=Path, help="identified parameters YAML for the controller (default: CAD)")
    p.add_argument("--rtf", type=float, default=1.0, help="real-time factor; 0 = as fast as possible")
    p.add_argument("--clock", action="store_true", help="publish /clock (the driver is the time source)")
    p.add_argument("--feedforward", choices=["gravity", "inverse_dynamics", "none"], default="gravity")
    p.add_argument("--robot", help=ROBOT_HELP)
    p.set_defaults(func=_drive)


def add_collect_postures(sub) -> None:
    p = sub.add_parser("collect-postures", help="hold the simulated robot in static postures and record its sensors")
    p.add_argument("--plant", help="plant YAML or a packaged plant: default (the default), heavy_front, cad")
    p.add_argument("--n", type=int, default=88, help="postures to keep (the paper had 88)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--robot", help=ROBOT_HELP)
    p.set_defaults(func=_collect_postures)


def add_identify(sub) -> None:
    p = sub.add_parser("identify", help="identify the robot's mass/COM parameters from a static-posture bag")
    p.add_argument("dir", type=Path)
    p.add_argument("--model", choices=["planar5", "full"], default="full")
    p.add_argument("--eval-fraction", type=float, default=0.1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, required=True, help="parameters YAML (figures are written beside it)")
    p.add_argument("--robot", help=ROBOT_HELP)
    p.set_defaults(func=_identify)


def add_excite(sub) -> None:
    p = sub.add_parser("excite", help="record an excitation run of the simulated robot (standing, stance to stance)")
    p.add_argument("--plant", help="plant YAML or a packaged plant: default (the default), heavy_front, cad")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--moves", type=int, default=8)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--robot", help=ROBOT_HELP)
    p.set_defaults(func=_excite)


def add_gap(sub) -> None:
    p = sub.add_parser("gap", help="find, name and add what a robot model misses, from measured robot bags")
    p.add_argument("bags", type=Path, nargs="+", help="robot bags: runs (driver, excite) and/or static postures")
    p.add_argument("--model", help="nominal model: cad (default), identified parameters or an augmented model YAML")
    p.add_argument("--controller", help="the parameters the robot's controller ran with (driver controller_params; "
                   "default: CAD): the control law is re-evaluated with them")
    p.add_argument("--rate", type=float, default=50.0, help="analysis rate [Hz] for runs")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--robot", help=ROBOT_HELP)
    p.set_defaults(func=_gap)


def _export(args: argparse.Namespace) -> int:
    from ..retarget.export import export

    done = export(args.run, args.out, args.format, args.rate, args.robot)
    print(f"wrote {done['out']}: {done['frames']} frames of {done['robot']} at {done['rate_hz']:g} Hz "
          f"({done['duration_s']:.2f} s, {done['joints']} joints)")
    return 0


def add_export(sub) -> None:
    p = sub.add_parser("export", help="a simulated stand-up as a motion file for learning pipelines (CSV rows: root "
                       "xyz, root quaternion xyzw, joints; or NPZ arrays)")
    p.add_argument("run", type=Path, help="a retarget --simulate folder or a stand-up bag")
    p.add_argument("--format", choices=("csv", "npz"), default="csv")
    p.add_argument("--rate", type=float, default=50.0, help="frames per second (default 50)")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--robot", help="robot profile (default: the packaged one whose joints the states name)")
    p.set_defaults(func=_export)


def _robot_check(args: argparse.Namespace) -> int:
    from ..robot.check import check_robot

    result = check_robot(args.robot, args.plant)
    print(json.dumps(result.as_dict(), indent=2) if args.json else "\n".join(result.lines()))
    return 0 if result.ok else 1


def _robot_list(args: argparse.Namespace) -> int:
    from ..robot.profile import load_profile, packaged_names

    for name in packaged_names():
        profile = load_profile(name)
        print(f"{name:8s} {profile.title} ({profile.urdf.name})")
    return 0


def add_robot(sub) -> None:
    p = sub.add_parser("robot", help="robot profiles: list the packaged ones, check one (docs/robots.md)")
    verbs = p.add_subparsers(dest="verb", required=True)
    check = verbs.add_parser("check", help="load a profile, build its robot, sit it on its chair, print its mass, "
                             "heights and the torque headroom of a sit-to-stand")
    check.add_argument("robot", help="a packaged profile's name (`sit2stand robot list`) or a profile YAML file")
    check.add_argument("--plant", help="a plant of this robot (default: none of its unmodeled effects)")
    check.add_argument("--json", action="store_true", help="print the figures as JSON")
    check.set_defaults(func=_robot_check)
    listing = verbs.add_parser("list", help="the packaged robot profiles")
    listing.set_defaults(func=_robot_list)
