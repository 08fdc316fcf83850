"""`sit2stand` sub-commands of the human side: importing lab files, digital humans, the human COM.

Each ``add_*`` function adds one sub-command to the parser (see :mod:`sit2stand.cli`); each handler imports its
stage when it runs, so that ``sit2stand --help`` stays fast (measured in :mod:`sit2stand.cli`'s docstring).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _write_lab_trial(trial, args: argparse.Namespace) -> int:
    """An imported lab trial written as a bag (``args.out``), its topics said, the summary with ``-v``."""
    from ..io.bag import bag_info
    from ..io.c3d import write_trial_bag

    counts = write_trial_bag(trial, args.out)
    print(f"wrote {args.out}: " + ", ".join(f"{t} ({n})" for t, n in counts.items()))
    if args.verbose:
        print(bag_info(args.out))
    return 0


def _import_c3d(args: argparse.Namespace) -> int:
    from ..io.c3d import read_c3d

    zero = "auto" if args.zero_frames == "auto" else None if args.zero_frames == "off" else \
        tuple(int(v) for v in args.zero_frames.split(":"))
    trial = read_c3d(args.file, chair_plate=args.chair_plate, feet_plate=args.feet_plate, forward=args.forward,
                     up=args.up, cop_threshold_n=args.cop_threshold, markers_only=args.markers_only, zero_frames=zero)
    print(f"{trial.path}: {len(trial.markers.names)} markers at {trial.markers.rate_hz:g} Hz, "
          f"{len(trial.plates)} of {trial.all_plate_count} plates used; lab axes: {trial.axes.reason}")
    if trial.skipped_labels:
        print(f"  not published as markers (model outputs, unlabelled): {len(trial.skipped_labels)}")
    return _write_lab_trial(trial, args)


def _import_trc(args: argparse.Namespace) -> int:
    from ..io.trc import read_opensim_trial

    trial = read_opensim_trial(args.file, args.grf, mass_kg=args.mass, height_m=args.height, forward=args.forward,
                               up=args.up, cop_threshold_n=args.cop_threshold)
    m = trial.markers
    print(f"{trial.path}: {len(m.names)} markers x {len(m.times_s)} frames at {m.rate_hz:g} Hz, "
          f"{len(trial.plates)} plates ({', '.join(p.name for p in trial.plates) or 'none'}); lab axes: "
          f"{trial.axes.reason}")
    if trial.height_m is None or trial.body_mass_kg is None:
        print("  no --height/--mass: give them to human-com later (TRC files do not carry them)")
    return _write_lab_trial(trial, args)


def _synth_human(args: argparse.Namespace) -> int:
    from ..human.skeleton import ExtraMass
    from ..human.demonstration_bag import write_demonstration_bag
    from ..human.synth import SynthConfig, synthesize

    cfg = SynthConfig(style=args.style, height_m=args.height, mass_kg=args.mass, sex=args.sex,
                      seat_height_m=args.seat_height, duration_s=args.duration, seed=args.seed,
                      extra=[ExtraMass.parse(e) for e in args.extra_mass], marker_rate_hz=args.marker_rate)
    demo = synthesize(cfg)
    if args.cycles > 1:
        from ..human.cycles import cycled

        demo = cycled(demo, args.cycles, args.seated)
    for warning in demo.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    counts = write_demonstration_bag(demo, args.out)
    c, i0 = demo.com_m, int(demo.rise_start_s * cfg.plate_rate_hz)
    print(f"{cfg.style} rise of a {cfg.height_m:g} m, {demo.human.total_mass:.1f} kg {cfg.sex}: seat-off at "
          f"{demo.seat_off_s - demo.rise_start_s:.2f} s into a {demo.rise_end_s - demo.rise_start_s:.2f} s rise; "
          f"COM height {c[i0, 2]:.3f} -> min {c[i0:, 2].min():.3f} -> {c[-1, 2]:.3f} m")
    if args.cycles > 1:
        print(f"{args.cycles} sit-stand-sit cycles, {args.seated:g} s on the seat between them: {demo.t_s[-1]:.1f} s")
    print(f"wrote {args.out}: " + ", ".join(f"{t} ({n})" for t, n in counts.items()))
    return 0


def _human_calibrate(args: argparse.Namespace) -> int:
    import time

    from ..human.offline import calibrate_from_bag

    t0 = time.perf_counter()
    cal, reason = calibrate_from_bag(args.bag, args.out, args.frames, args.height, args.mass, args.sex,
                                     calibration_frame=args.calibration_frame, static=args.static)
    print(f"calibrated a {cal.height_m:g} m {cal.sex} on {reason} in "
          f"{time.perf_counter() - t0:.1f} s; wrote {args.out}")
    return 0


def _human_com(args: argparse.Namespace) -> int:
    from ..human.offline import run

    summary = run(args.bag, args.out, height_m=args.height, mass_kg=args.mass, sex=args.sex,
                  calibrate=not args.no_calibration, scale=not args.no_scaling, marker_set=args.marker_set,
                  calibration_frame=args.calibration_frame, static=args.static)
    skipped = summary["frames"] - summary["frames_fitted"]
    print(f"  fitted {summary['frames_fitted']} of {summary['frames']} frames"
          + (f" ({skipped} left out, too few markers or no pelvis: bridged between their neighbours)" if skipped
             else ""))
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


def _gap_human(args: argparse.Namespace) -> int:

    from ..gap.human import human_gap
    from ..gap.workflow import progress_printer

    r = human_gap(args.bag, progress=progress_printer)
    print(r.verdict)
    for e in r.effects:
        if e.alternatives:
            print(f"  {e.location}: nearly as good here: {', '.join(e.alternatives[:4])}")
    names = ["force_x", "force_y", "force_z", "moment_x", "moment_y", "moment_z"]
    for n, f, b, a in zip(names, r.floors, r.rms_before, r.rms_after):
        print(f"  {n:9s} floor {f:6.2f}  RMS {b:6.2f} -> {a:6.2f}")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"bag": r.bag, "verdict": r.verdict, "effects": [e.as_dict() for e in r.effects],
                                        "floors": r.floors.tolist(), "rms_before": r.rms_before.tolist(),
                                        "rms_after": r.rms_after.tolist(), "steps": r.selection.steps}, indent=1))
    return 0


def _add_lab_file_args(p, default_axes: str) -> None:
    """What every lab-file import takes: the bag to write, the file's axes, the COP threshold, the summary."""
    p.add_argument("--out", type=Path, required=True, help="bag directory to create")
    p.add_argument("--forward", help=f"file axis that is lab x (forward), e.g. +Y; {default_axes}")
    p.add_argument("--up", help=f"file axis that is lab z (up), e.g. +Z; {default_axes}")
    p.add_argument("--cop-threshold", type=float, default=20.0, help="normal force [N] below which COP is invalid")
    p.add_argument("-v", "--verbose", action="store_true", help="print the bag summary afterwards")


def calibration_frame(text: str) -> int | str:
    """``--calibration-frame``: a frame number (0-based) or ``auto``."""
    if text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a frame number (0-based) or auto, not {text!r}") from None


def add_calibration_args(p, default: str) -> None:
    """Where the skeleton (or the robot's marker map) is calibrated: ``default`` says where without the options."""
    group = p.add_mutually_exclusive_group()
    group.add_argument("--calibration-frame", type=calibration_frame, metavar="N|auto",
                       help=f"calibrate from frame N on (0-based), or on the quietest stretch that sees the most "
                            f"markers (auto); default: {default}")
    group.add_argument("--static", type=Path, metavar="FILE",
                       help="calibrate the skeleton on a static trial recorded beforehand (bag, .c3d or .trc)")


def add_import_c3d(sub) -> None:
    p = sub.add_parser("import-c3d", help="C3D markers and force plates -> bag (SI units, REP-103 lab frame)")
    p.add_argument("file", type=Path)
    _add_lab_file_args(p, "detected if omitted")
    p.add_argument("--chair-plate", type=int, help="0-based index of the plate under the chair")
    p.add_argument("--feet-plate", type=int, help="0-based index of the plate under the feet")
    p.add_argument("--zero-frames", default="auto",
                   help="plate baseline: auto (FORCE_PLATFORM:ZERO), off, or FIRST:LAST 1-based point frames")
    p.add_argument("--markers-only", action="store_true", help="accept a file without force plates")
    p.set_defaults(func=_import_c3d)


def add_import_trc(sub) -> None:
    p = sub.add_parser("import-trc", help="OpenSim TRC markers (and .mot ground reaction forces) -> bag (SI, REP-103)")
    p.add_argument("file", type=Path, help="the .trc marker file")
    _add_lab_file_args(p, "default OpenSim's (+X forward, +Y up)")
    p.add_argument("--grf", type=Path, help="OpenSim .mot ground reaction forces (plates plate0, plate1, ...)")
    p.add_argument("--mass", type=float, help="body mass [kg] for the bag's metadata (TRC files lack it)")
    p.add_argument("--height", type=float, help="stature [m] for the bag's metadata (TRC files lack it)")
    p.set_defaults(func=_import_trc)


def add_synth_human(sub) -> None:
    p = sub.add_parser("synth-human", help="digital-human sit-to-stand demonstration (markers, plates, true COM)")
    p.add_argument("--style", choices=["natural", "elderly"], default="natural")
    p.add_argument("--height", type=float, default=1.75, help="stature [m]")
    p.add_argument("--mass", type=float, default=75.0, help="body mass [kg] (extra masses come on top)")
    p.add_argument("--sex", choices=["male", "female"], default="male")
    p.add_argument("--seat-height", type=float, help="seat height [m] (default 0.26 x stature)")
    p.add_argument("--duration", type=float, help="rise duration [s] (default: natural 1.6, elderly 3.0)")
    p.add_argument("--seed", type=int, default=0, help="subject proportions, noise and occlusions")
    p.add_argument("--marker-rate", type=float, default=100.0,
                   help="capture rate [Hz] (default 100; divides the plates' 1000 Hz)")
    p.add_argument("--extra-mass", action="append", default=[], metavar="SEGMENT:KG[:x,y,z]",
                   help="hidden rigid mass on a segment, offset from its COM in segment axes (repeatable)")
    p.add_argument("--cycles", type=int, default=1,
                   help="sit-stand-sit cycles (default 1: one rise; 5: a five-times sit-to-stand test), each sit-down "
                   "the rise mirrored in time")
    p.add_argument("--seated", type=float, default=1.0,
                   help="seconds on the seat between cycles (default 1.0; ~0.1: a brief touch)")
    p.add_argument("--out", type=Path, required=True)
    p.set_defaults(func=_synth_human)


def add_human_com(sub) -> None:
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
    add_calibration_args(p, "every frame of the trial")
    p.set_defaults(func=_human_com)


def add_human_calibrate(sub) -> None:
    p = sub.add_parser("human-calibrate", help="calibrate the skeleton on a bag's quietest frames (or chosen ones, "
                       "or a static trial), for the human_com node's calibration_file")
    p.add_argument("bag", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--frames", type=int, default=50, help="frames to use (the stream's own calibration takes 50)")
    add_calibration_args(p, "auto")
    p.add_argument("--height", type=float, help="stature [m] if the bag's metadata lacks it")
    p.add_argument("--mass", type=float, help="body mass [kg] if the bag's metadata lacks it")
    p.add_argument("--sex", choices=["male", "female"])
    p.set_defaults(func=_human_calibrate)


def add_gap_human(sub) -> None:
    p = sub.add_parser("gap-human", help="the model-gap workflow on a human demonstration: a mass the skeleton lacks")
    p.add_argument("bag", type=Path)
    p.add_argument("--out", type=Path, help="JSON summary")
    p.set_defaults(func=_gap_human)
