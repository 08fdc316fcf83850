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
    sit2stand bag info|recover|merge ...
    sit2stand launch GRAPH [NAME:=VALUE ...] [--timeout S]   (a graph file, or a packaged graph's name: standup)
    sit2stand replay BAG [--rate R] [--loop] [--topics T ...]   (the replayer node)
    sit2stand record --out BAG [--topics T ...] [--regex RE]    (the recorder node)

PLANT is a plant YAML or a packaged plant's name (default, heavy_front, cad). Errors are printed as one line naming
the file, topic or field, with exit code 2.

Each sub-command imports its stage when it runs: importing every stage (Pinocchio, MuJoCo, SciPy, rclpy) costs
~3 s, while ``--help`` and ``bag info`` need 0.2-0.7 s (measured on the 2-core development machine).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _import_c3d(args: argparse.Namespace) -> int:
    from .io.bag import bag_info
    from .io.c3d import read_c3d, write_trial_bag

    zero = "auto" if args.zero_frames == "auto" else None if args.zero_frames == "off" else \
        tuple(int(v) for v in args.zero_frames.split(":"))
    trial = read_c3d(args.file, chair_plate=args.chair_plate, feet_plate=args.feet_plate, forward=args.forward,
                     up=args.up, cop_threshold_n=args.cop_threshold, markers_only=args.markers_only, zero_frames=zero)
    print(f"{trial.path}: {len(trial.markers.names)} markers at {trial.markers.rate_hz:g} Hz, "
          f"{len(trial.plates)} of {trial.all_plate_count} plates used; lab axes: {trial.axes.reason}")
    if trial.skipped_labels:
        print(f"  not published as markers (model outputs, unlabelled): {len(trial.skipped_labels)}")
    counts = write_trial_bag(trial, args.out)
    print(f"wrote {args.out}: " + ", ".join(f"{t} ({n})" for t, n in counts.items()))
    if args.verbose:
        print(bag_info(args.out))
    return 0


def _import_trc(args: argparse.Namespace) -> int:
    from .io.bag import bag_info
    from .io.c3d import write_trial_bag
    from .io.trc import read_opensim_trial

    trial = read_opensim_trial(args.file, args.grf, mass_kg=args.mass, height_m=args.height, forward=args.forward,
                               up=args.up, cop_threshold_n=args.cop_threshold)
    m = trial.markers
    print(f"{trial.path}: {len(m.names)} markers x {len(m.times_s)} frames at {m.rate_hz:g} Hz, "
          f"{len(trial.plates)} plates ({', '.join(p.name for p in trial.plates) or 'none'}); lab axes: "
          f"{trial.axes.reason}")
    if trial.height_m is None or trial.body_mass_kg is None:
        print("  no --height/--mass: give them to human-com later (TRC files do not carry them)")
    counts = write_trial_bag(trial, args.out)
    print(f"wrote {args.out}: " + ", ".join(f"{t} ({n})" for t, n in counts.items()))
    if args.verbose:
        print(bag_info(args.out))
    return 0


def _synth_human(args: argparse.Namespace) -> int:
    from .human.skeleton import ExtraMass
    from .human.demonstration_bag import write_demonstration_bag
    from .human.synth import SynthConfig, synthesize

    cfg = SynthConfig(style=args.style, height_m=args.height, mass_kg=args.mass, sex=args.sex,
                      seat_height_m=args.seat_height, duration_s=args.duration, seed=args.seed,
                      extra=[ExtraMass.parse(e) for e in args.extra_mass])
    demo = synthesize(cfg)
    for warning in demo.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    counts = write_demonstration_bag(demo, args.out)
    c, i0 = demo.com_m, int(demo.rise_start_s * cfg.plate_rate_hz)
    print(f"{cfg.style} rise of a {cfg.height_m:g} m, {demo.human.total_mass:.1f} kg {cfg.sex}: seat-off at "
          f"{demo.seat_off_s - demo.rise_start_s:.2f} s into a {demo.rise_end_s - demo.rise_start_s:.2f} s rise; "
          f"COM height {c[i0, 2]:.3f} -> min {c[i0:, 2].min():.3f} -> {c[-1, 2]:.3f} m")
    print(f"wrote {args.out}: " + ", ".join(f"{t} ({n})" for t, n in counts.items()))
    return 0


def _human_calibrate(args: argparse.Namespace) -> int:
    import time

    from .human.offline import calibrate_from_bag

    t0 = time.perf_counter()
    cal = calibrate_from_bag(args.bag, args.out, args.frames, args.height, args.mass, args.sex)
    print(f"calibrated a {cal.height_m:g} m {cal.sex} on the first {cal.frames} frames of {args.bag} in "
          f"{time.perf_counter() - t0:.1f} s: marker RMS {cal.marker_rms_before_m * 1e3:.1f} -> "
          f"{cal.marker_rms_after_m * 1e3:.1f} mm; wrote {args.out}")
    return 0


def _human_com(args: argparse.Namespace) -> int:
    from .human.offline import run

    summary = run(args.bag, args.out, height_m=args.height, mass_kg=args.mass, sex=args.sex,
                  calibrate=not args.no_calibration, scale=not args.no_scaling, marker_set=args.marker_set)
    keys = ["com_rms_vs_truth_scaled_mm", "com_rms_vs_truth_unscaled_mm", "cop_rms_unscaled_mm", "cop_rms_scaled_mm",
            "com_rms_vs_reference_mm", "standing_com_to_cop_mm", "standing_reference_com_to_cop_mm", "marker_rms_mm"]
    for key in keys:
        if key in summary:
            value = summary[key]
            text = (f"mean {value['mean']:.1f}, max {value['max']:.1f}" if isinstance(value, dict) else f"{value:.1f}")
            print(f"  {key:<36} {text}")
    print("  mass factors: " + ", ".join(f"{k} {v:.2f}" for k, v in summary["mass_factors"].items()))
    if summary.get("plate_gaps"):
        print("  force plates dropped out: " + "; ".join(
            f"{g['plate']} {g['from_s']:.3f}-{g['to_s']:.3f} s" for g in summary["plate_gaps"]))
    if "newton_residual_rms_xyz_n" in summary:
        rms = ", ".join(f"{v:.1f}" for v in summary["newton_residual_rms_xyz_n"])
        print(f"  {'newton_residual_rms_xyz_n':<36} {rms} ({summary['newton_residual_frames']} frames on the plates)")
    print(f"wrote {args.out}/summary.json, human_com.png, com.csv, joint_angles.csv, human_states.sto and the "
          f"human_com bag (marker set {summary['marker_set']})")
    return 0


def _retarget(args: argparse.Namespace) -> int:
    from .retarget.offline import run

    summary = run(Path(args.bag), Path(args.out), params=args.params, plant=args.plant,
                  human_com_bag=args.human_com, margin_m=args.margin, time_scale=args.time_scale,
                  **({"max_time_scale": args.max_time_scale} if args.max_time_scale else {}),
                  simulate=args.simulate, com_feedback=not args.no_com_feedback, whole=args.whole)
    print(json.dumps(summary, indent=2))
    if args.simulate:
        print("stood up" if summary["stood_up"] else f"did not stand up: {summary['fall'] or 'pelvis too low'}")
        return 0 if summary["stood_up"] else 1
    return 0


def _drive(args: argparse.Namespace) -> int:
    from .nodes.driver import main as driver_main

    return driver_main(["driver"] + _ros_params([
        ("plant", str(args.plant)), ("controller_params", str(args.params) if args.params else None),
        ("real_time_factor", float(args.rtf)), ("publish_clock", args.clock), ("feedforward", args.feedforward)]))


def _collect_postures(args: argparse.Namespace) -> int:
    from .robot.model import PlantConfig
    from .robot.postures import collect_postures

    cfg = PlantConfig.load(args.plant)
    counts = collect_postures(cfg, args.n, args.out, seed=args.seed)
    print(f"wrote {args.out}: {counts['kept']} postures held ({counts['dropped']} tipped over and were dropped; the "
          f"upright stance showed the real COM {counts['home_com_bias_m'] * 1e3:+.0f} mm from CAD's)")
    return 0 if counts["kept"] >= min(args.n, 6) else 1


def _identify(args: argparse.Namespace) -> int:
    from .robot.figures import com_path_figure, posture_figure
    from .robot.identify import identify, read_postures, write_yaml

    result = identify(args.dir, args.model, eval_fraction=args.eval_fraction, seed=args.seed)
    print(result.summary())
    write_yaml(result, args.out, source=str(args.dir))
    png = Path(args.out).with_suffix(".png")
    posture_figure(result, read_postures(args.dir), png, args.eval_fraction, args.seed)
    written = [str(args.out), str(png)]
    if result.model_name == "full":
        path_png = Path(args.out).with_name(Path(args.out).stem + "_com_path.png")
        com_path_figure(result, path_png)
        written.append(str(path_png))
    print("wrote " + ", ".join(written))
    return 0


def _bag_info(args: argparse.Namespace) -> int:
    from .io.bag import BagReader, bag_info

    print(bag_info(args.dir))
    with BagReader(args.dir) as bag:
        for key, value in sorted(bag.custom_data.items()):
            print(f"{key}: {value}")
    return 0


def _bag_merge(args: argparse.Namespace) -> int:
    from .io.bag import merge_bags

    counts = merge_bags(Path(args.out), [Path(p) for p in args.inputs])
    print(f"wrote {args.out}: {sum(counts.values())} messages on {len(counts)} topics")
    return 0


def _bag_recover(args: argparse.Namespace) -> int:
    from .io.recover import recover_bag

    print(recover_bag(args.dir, args.out))
    return 0


def _excite(args: argparse.Namespace) -> int:
    from .gap.excite import excite
    from .robot.model import PlantConfig

    info = excite(PlantConfig.load(args.plant), args.out, seed=args.seed, n_moves=args.moves, progress=True)
    print(f"wrote {args.out}: {info['duration_s']:.1f} s of excitation"
          + (f"; the robot fell ({info['status']})" if info["fell"] else ""))
    return 1 if info["fell"] else 0


def _gap(args: argparse.Namespace) -> int:
    from .gap.report import cop_rms, gap_command
    from .gap.workflow import describe, progress_printer

    result = gap_command(args.bags, args.out, model=args.model, rate_hz=args.rate, progress=progress_printer,
                         controller=args.controller)
    print(f"nominal model: {result.model_source}")
    if result.effects:
        print(f"named {len(result.effects)} effect(s):")
        for e in result.effects:
            print(f"  - {describe(e)}")
    else:
        print(result.verdict)
    if result.unexplained:
        print(f"left unexplained on {len(result.unexplained)} channel(s), worst {result.unexplained[0]['channel']} "
              f"at {result.unexplained[0]['z']:.1f} x its noise floor")
    print(f"gap above the noise on the disagreeing channels: {result.gap_before:.2f} -> {result.gap_after:.2f} "
          f"(shrink {100 * result.shrink:.0f} %)")
    for r, (b, a) in enumerate(cop_rms(result)):
        print(f"model COP error, {result.bags[r]}: {100 * b:.2f} -> {100 * a:.2f} cm RMS")
    print(f"report: {args.out}/report.md (+ gap.json, augmented_model.yaml, gap_*.png)")
    return 0


def _gap_human(args: argparse.Namespace) -> int:
    import json

    from .gap.human import human_gap
    from .gap.workflow import progress_printer

    r = human_gap(args.bag, progress=progress_printer)
    print(r.verdict)
    for e in r.effects:
        if e.get("alternatives"):
            print(f"  {e['location']}: nearly as good here: {', '.join(e['alternatives'][:4])}")
    names = ["force_x", "force_y", "force_z", "moment_x", "moment_y", "moment_z"]
    for n, f, b, a in zip(names, r.floors, r.rms_before, r.rms_after):
        print(f"  {n:9s} floor {f:6.2f}  RMS {b:6.2f} -> {a:6.2f}")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"bag": r.bag, "verdict": r.verdict, "effects": r.effects,
                                        "floors": r.floors.tolist(), "rms_before": r.rms_before.tolist(),
                                        "rms_after": r.rms_after.tolist(), "steps": r.selection.steps}, indent=1))
    return 0


def _launch(args: argparse.Namespace) -> int:
    from .launch import Launcher, load_graph, parse_overrides

    graph = load_graph(args.graph, parse_overrides(args.overrides))
    return Launcher(graph, grace_s=args.grace).run(timeout_s=args.timeout)


def _ros_params(pairs: list[tuple[str, object]]) -> list[str]:
    out = ["--ros-args"]
    for key, value in pairs:
        if value is None:
            continue
        if isinstance(value, bool):
            value = "true" if value else "false"
        elif isinstance(value, list):
            value = "[" + ",".join(f"'{v}'" for v in value) + "]"
        out += ["-p", f"{key}:={value}"]
    return out


def _replay(args: argparse.Namespace) -> int:
    from .nodes.replayer import main as replayer_main

    return replayer_main(["replayer"] + _ros_params([
        ("bag", str(args.dir)), ("rate", float(args.rate)), ("loop", args.loop), ("topics", args.topics or None),
        ("at_end", "idle" if args.idle else "exit"), ("wait_for_subscribers", args.wait_for_subscribers)]))


def _record(args: argparse.Namespace) -> int:
    from .nodes.recorder import main as recorder_main

    return recorder_main(["recorder"] + _ros_params([
        ("output", str(args.out)), ("topics", args.topics or None), ("regex", args.regex or None),
        ("use_sim_time", args.use_sim_time)]))


def _add_import_c3d(sub) -> None:
    p = sub.add_parser("import-c3d", help="C3D markers and force plates -> bag (SI units, REP-103 lab frame)")
    p.add_argument("file", type=Path)
    p.add_argument("--out", type=Path, required=True, help="bag directory to create")
    p.add_argument("--chair-plate", type=int, help="0-based index of the plate under the chair")
    p.add_argument("--feet-plate", type=int, help="0-based index of the plate under the feet")
    p.add_argument("--forward", help="file axis that is lab x (forward), e.g. +Y; detected if omitted")
    p.add_argument("--up", help="file axis that is lab z (up), e.g. +Z; detected if omitted")
    p.add_argument("--cop-threshold", type=float, default=20.0, help="normal force [N] below which COP is invalid")
    p.add_argument("--zero-frames", default="auto",
                   help="plate baseline: auto (FORCE_PLATFORM:ZERO), off, or FIRST:LAST 1-based point frames")
    p.add_argument("--markers-only", action="store_true", help="accept a file without force plates")
    p.add_argument("-v", "--verbose", action="store_true", help="print the bag summary afterwards")
    p.set_defaults(func=_import_c3d)


def _add_import_trc(sub) -> None:
    p = sub.add_parser("import-trc", help="OpenSim TRC markers (and .mot ground reaction forces) -> bag (SI, REP-103)")
    p.add_argument("file", type=Path, help="the .trc marker file")
    p.add_argument("--grf", type=Path, help="OpenSim .mot ground reaction forces (plates plate0, plate1, ...)")
    p.add_argument("--out", type=Path, required=True, help="bag directory to create")
    p.add_argument("--mass", type=float, help="body mass [kg] for the bag's metadata (TRC files lack it)")
    p.add_argument("--height", type=float, help="stature [m] for the bag's metadata (TRC files lack it)")
    p.add_argument("--forward", help="file axis that is lab x (forward); default +X (OpenSim's)")
    p.add_argument("--up", help="file axis that is lab z (up); default +Y (OpenSim's)")
    p.add_argument("--cop-threshold", type=float, default=20.0, help="normal force [N] below which COP is invalid")
    p.add_argument("-v", "--verbose", action="store_true", help="print the bag summary afterwards")
    p.set_defaults(func=_import_trc)


def _add_synth_human(sub) -> None:
    p = sub.add_parser("synth-human", help="digital-human sit-to-stand demonstration (markers, plates, true COM)")
    p.add_argument("--style", choices=["natural", "elderly"], default="natural")
    p.add_argument("--height", type=float, default=1.75, help="stature [m]")
    p.add_argument("--mass", type=float, default=75.0, help="body mass [kg] (extra masses come on top)")
    p.add_argument("--sex", choices=["male", "female"], default="male")
    p.add_argument("--seat-height", type=float, help="seat height [m] (default 0.26 x stature)")
    p.add_argument("--duration", type=float, help="rise duration [s] (default: natural 1.6, elderly 3.0)")
    p.add_argument("--seed", type=int, default=0, help="subject proportions, noise and occlusions")
    p.add_argument("--extra-mass", action="append", default=[], metavar="SEGMENT:KG[:x,y,z]",
                   help="hidden rigid mass on a segment, offset from its COM in segment axes (repeatable)")
    p.add_argument("--out", type=Path, required=True)
    p.set_defaults(func=_synth_human)


def _add_human_com(sub) -> None:
    p = sub.add_parser("human-com", help="human COM of a bag: skeleton fit, COP-matched scaling, JSON + PNG")
    p.add_argument("bag", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--height", type=float, help="stature [m] if the bag's metadata lacks it")
    p.add_argument("--mass", type=float, help="body mass [kg] if the bag's metadata lacks it")
    p.add_argument("--sex", choices=["male", "female"])
    p.add_argument("--no-calibration", action="store_true", help="keep de Leva's segment lengths")
    p.add_argument("--no-scaling", action="store_true", help="keep de Leva's segment masses")
    p.add_argument("--marker-set", help="marker set: plug_in_gait, plug_in_gait_lower, gait2392 or a YAML file "
                   "(default: the packaged set that covers most of the bag's marker names)")
    p.set_defaults(func=_human_com)


def _add_human_calibrate(sub) -> None:
    p = sub.add_parser("human-calibrate", help="calibrate the skeleton on a bag's first (seated, still) frames, "
                       "for the human_com node's calibration_file")
    p.add_argument("bag", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--frames", type=int, default=50, help="frames to use (the stream's own calibration takes 50)")
    p.add_argument("--height", type=float, help="stature [m] if the bag's metadata lacks it")
    p.add_argument("--mass", type=float, help="body mass [kg] if the bag's metadata lacks it")
    p.add_argument("--sex", choices=["male", "female"])
    p.set_defaults(func=_human_calibrate)


def _add_retarget(sub) -> None:
    p = sub.add_parser("retarget", help="retarget a demonstration to robot joint commands (optionally simulate them)")
    p.add_argument("bag", help="demonstration bag (/mocap/markers, force plates)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--params", default=None, help="identified COM parameters YAML (default: CAD)")
    p.add_argument("--plant", default=None, help="plant YAML (seated posture; default: the nominal plant)")
    p.add_argument("--human-com", default=None, help="bag with /human/com (default: the bag's, else estimated)")
    p.add_argument("--margin", type=float, default=0.06, help="ZMP margin inside the feet [m]")
    p.add_argument("--time-scale", type=float, default=None, help="fixed time scale (default: adaptive)")
    p.add_argument("--max-time-scale", type=float,
                   help="the adaptive time scale's cap: at most this many times slower than the human "
                        "(default: retarget.player.DEFAULT_MAX_TIME_SCALE, 4)")
    p.add_argument("--simulate", action="store_true", help="execute the commands on the MuJoCo plant")
    p.add_argument("--whole", action="store_true", help="play the whole recording; by default a trial that ends "
                   "seated is played up to the human's sit-down (the robot does not sit back down yet)")
    p.add_argument("--no-com-feedback", action="store_true",
                   help="simulate the commands as planned, without the COM feedback the node applies")
    p.set_defaults(func=_retarget)


def _add_drive(sub) -> None:
    p = sub.add_parser("drive", help="the simulated robot (the driver node), seated on its chair")
    p.add_argument("--plant", help="plant YAML or a packaged plant: default (the default), heavy_front, cad")
    p.add_argument("--params", type=Path, help="identified parameters YAML for the controller (default: CAD)")
    p.add_argument("--rtf", type=float, default=1.0, help="real-time factor; 0 = as fast as possible")
    p.add_argument("--clock", action="store_true", help="publish /clock (the driver is the time source)")
    p.add_argument("--feedforward", choices=["gravity", "inverse_dynamics", "none"], default="gravity")
    p.set_defaults(func=_drive)


def _add_collect_postures(sub) -> None:
    p = sub.add_parser("collect-postures", help="hold the simulated robot in static postures and record its sensors")
    p.add_argument("--plant", help="plant YAML or a packaged plant: default (the default), heavy_front, cad")
    p.add_argument("--n", type=int, default=88, help="postures to keep (the paper had 88)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, required=True)
    p.set_defaults(func=_collect_postures)


def _add_identify(sub) -> None:
    p = sub.add_parser("identify", help="identify the robot's mass/COM parameters from a static-posture bag")
    p.add_argument("dir", type=Path)
    p.add_argument("--model", choices=["planar5", "full"], default="full")
    p.add_argument("--eval-fraction", type=float, default=0.1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, required=True, help="parameters YAML (figures are written beside it)")
    p.set_defaults(func=_identify)


def _add_excite(sub) -> None:
    p = sub.add_parser("excite", help="record an excitation run of the simulated robot (standing, stance to stance)")
    p.add_argument("--plant", help="plant YAML or a packaged plant: default (the default), heavy_front, cad")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--moves", type=int, default=8)
    p.add_argument("--out", type=Path, required=True)
    p.set_defaults(func=_excite)


def _add_gap(sub) -> None:
    p = sub.add_parser("gap", help="find, name and add what a robot model misses, from measured robot bags")
    p.add_argument("bags", type=Path, nargs="+", help="robot bags: runs (driver, excite) and/or static postures")
    p.add_argument("--model", help="nominal model: cad (default), identified parameters or an augmented model YAML")
    p.add_argument("--controller", help="the parameters the robot's controller ran with (driver controller_params; "
                   "default: CAD): the control law is re-evaluated with them")
    p.add_argument("--rate", type=float, default=50.0, help="analysis rate [Hz] for runs")
    p.add_argument("--out", type=Path, required=True)
    p.set_defaults(func=_gap)


def _add_gap_human(sub) -> None:
    p = sub.add_parser("gap-human", help="the model-gap workflow on a human demonstration: a mass the skeleton lacks")
    p.add_argument("bag", type=Path)
    p.add_argument("--out", type=Path, help="JSON summary")
    p.set_defaults(func=_gap_human)


def _add_bag(sub) -> None:
    bag = sub.add_parser("bag", help="bag tools").add_subparsers(dest="bag_command", required=True)
    p = bag.add_parser("info", help="topics, types, counts, rates and duration")
    p.add_argument("dir", type=Path)
    p.set_defaults(func=_bag_info)
    p = bag.add_parser("recover", help="rebuild a bag whose recorder was killed (truncated .mcap, no metadata)")
    p.add_argument("dir", type=Path)
    p.add_argument("--out", type=Path, help="write the rebuilt bag here instead of in place")
    p.set_defaults(func=_bag_recover)
    p = bag.add_parser("merge", help="several bags into one, in time order (first bag wins a shared topic)")
    p.add_argument("out", type=Path)
    p.add_argument("inputs", type=Path, nargs="+")
    p.set_defaults(func=_bag_merge)


def _add_launch(sub) -> None:
    p = sub.add_parser("launch", help="start a graph of nodes from a YAML graph file")
    p.add_argument("graph", type=Path, help="graph YAML file, or a packaged graph's name (standup, human_com, "
                   "retarget, robot_seated, roundtrip, identification)")
    p.add_argument("overrides", nargs="*", help="NAME:=VALUE for the graph's arguments")
    p.add_argument("--timeout", type=float, help="stop the graph after this many seconds")
    p.add_argument("--grace", type=float, default=10.0, help="seconds between SIGINT and SIGTERM at shutdown")
    p.set_defaults(func=_launch)


def _add_replay(sub) -> None:
    p = sub.add_parser("replay", help="play a bag onto topics (the replayer node)")
    p.add_argument("dir", type=Path)
    p.add_argument("--rate", type=float, default=1.0, help="0.1..50 x real time, 0 = as fast as subscribers take")
    p.add_argument("--loop", action="store_true")
    p.add_argument("--idle", action="store_true", help="stay alive at the end instead of exiting")
    p.add_argument("--topics", nargs="*")
    p.add_argument("--wait-for-subscribers", type=int, default=0)
    p.set_defaults(func=_replay)


def _add_record(sub) -> None:
    p = sub.add_parser("record", help="record topics into a bag (the recorder node)")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--topics", nargs="*")
    p.add_argument("--regex")
    p.add_argument("--use-sim-time", action="store_true")
    p.set_defaults(func=_record)


COMMANDS = [
    _add_import_c3d,
    _add_import_trc,
    _add_synth_human,
    _add_human_com,
    _add_human_calibrate,
    _add_retarget,
    _add_drive,
    _add_collect_postures,
    _add_identify,
    _add_excite,
    _add_gap,
    _add_gap_human,
    _add_bag,
    _add_launch,
    _add_replay,
    _add_record,
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
        if hasattr(args, "plant"):
            args.plant = plant_path(args.plant or "default")
        return int(args.func(args) or 0)
    except (Sit2StandError, OSError) as err:
        print(f"sit2stand {args.command}: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
