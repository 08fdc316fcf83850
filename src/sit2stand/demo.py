"""`make demo`: the main job on the shipped demonstrations, end to end through real nodes, into a run directory.

For each shipped bag (``bags/natural``, ``bags/elderly``):

1. the human COM offline (``sit2stand human-com``): skeleton fit, length and marker calibration, COP-matched mass
   scaling; COM error against the demonstration's ground truth; JSON + figure;
2. the same live: replayer -> human_com node -> recorder over DDS (``sit2stand launch human_com``); the
   recorded ``/human/com`` against the ground truth, and the node's per-frame cost.

3. the stand-up, live: replayer -> human_com -> retargeter -> driver (default plant, identified COM parameters) ->
   recorder (``sit2stand launch standup``), the estimator's skeleton calibrated beforehand on the first 0.5 s
   (``sit2stand human-calibrate``), and it, the retargeter and the robot's loop at real-time priority; the run
   analysed (:mod:`sit2stand.retarget.report`): stood up or not, COM tracking, the paper's Fig. 6, and a strip of
   rendered frames.

Before that, for the robot (``--robot``: TALOS by default, G1): static postures of the simulated robot (its default
plant, with mass its CAD model lacks), identification of its mass/COM parameters (full model), the held-out COM error
next to CAD's, and the figures.
After: the sagittal COM paths of the humans, and Fig. 7 (the robot's COM paths, natural against elderly, identified
against CAD parameters). Everything in ``summary.json``; the last line says "stood up" for each demonstration.

    python -m sit2stand.demo --out runs/demo [--bags bags/natural bags/elderly] [--rate 1.0] [--robot g1]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from .data import graph_path
from .gap.candidates import describe
from .gap.recording import excite
from .gap.report import cop_rms, gap_command
from .human.offline import calibrate_from_bag
from .human.offline import run as human_com_offline
from .io import messages as M
from .io.bag import BagReader
from .io.topics import FELL_EXIT_CODE, GROUND_TRUTH_COM_TOPIC, HUMAN_COM_TOPIC
from .retarget.report import RunAnalysis, analyse, figure_6, figure_7, render_strip, strip_indices
from .robot.figures import com_path_figure, posture_figure
from .robot.identify import identify, read_postures, write_yaml
from .robot.model import DEFAULT_ROBOT, PlantConfig
from .robot.postures import collect_postures
from .view.scene import human_frames, load_scene

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_BAGS = [ROOT / "bags" / "natural", ROOT / "bags" / "elderly"]


def _series(bag: BagReader, topic: str) -> tuple[np.ndarray, np.ndarray]:
    """Header times [s] and positions [m] of a topic of center-of-mass messages."""
    msgs = bag.read(topic)
    return (np.array([M.stamp_ns(m.header) for _, m in msgs]) * 1e-9,
            np.array([[m.position.x, m.position.y, m.position.z] for _, m in msgs]))


def live(bag: Path, out: Path, rate: float) -> dict:
    """Run the human COM graph on ``bag``; returns the live figures."""
    with BagReader(bag) as b:
        meta = b.custom_data
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    cmd = [sys.executable, "-m", "sit2stand.cli", "launch", str(graph_path("human_com")),
           f"bag:={bag.resolve()}", f"out:={out.resolve()}", f"rate:={rate}",
           f"height:={meta.get('height_m', '1.75')}", f"mass:={meta.get('body_mass_kg', '75')}"]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    if proc.returncode != 0:
        raise RuntimeError(f"the human_com graph failed on {bag} (exit {proc.returncode}):\n{proc.stdout[-4000:]}")
    cost = re.search(r"cost p50 ([\d.]+) ms p99 ([\d.]+) ms", proc.stdout)
    with BagReader(out) as rec:
        t, com = _series(rec, HUMAN_COM_TOPIC)
        tg, truth = _series(rec, GROUND_TRUTH_COM_TOPIC)
    truth_i = np.array([np.interp(t, tg, truth[:, i]) for i in range(3)]).T
    err = np.linalg.norm(com - truth_i, axis=1)
    return {"wall_s": round(time.monotonic() - t0, 2), "frames": int(len(t)),
            "com_error_mean_mm": float(err.mean() * 1e3), "com_error_p95_mm": float(np.percentile(err, 95) * 1e3),
            "cost_p50_ms": float(cost.group(1)) if cost else None,
            "cost_p99_ms": float(cost.group(2)) if cost else None}


def standup(bag: Path, out: Path, params: Path, robot: str = DEFAULT_ROBOT) -> dict:
    """Run the stand-up graph on ``bag`` with ``robot``'s identified ``params``; analyse and plot the run."""
    with BagReader(bag) as b:
        meta = b.custom_data
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    plant = PlantConfig.load("default", robot).source
    height, mass = meta.get("height_m", "1.75"), meta.get("body_mass_kg", "75")
    # the skeleton calibrated beforehand on the first 0.5 s (seated, still), as on a static trial: the live
    # estimator then has no calibration pause, and runs in real time below the retargeter
    calibration = (out / "skeleton_calibration.yaml").resolve()
    calibrate_from_bag(bag, calibration, 50, float(height), float(mass))
    cmd = [sys.executable, "-m", "sit2stand.cli", "launch", str(graph_path("standup")),
           f"bag:={bag.resolve()}", f"out:={(out / 'standup').resolve()}", f"params:={params.resolve()}",
           f"plant:={plant}", f"robot:={robot}", f"height:={height}", f"mass:={mass}", f"calibration:={calibration}",
           "estimator_policy:=fifo", "driver_policy:=fifo", f"marker_map:={(out / 'marker_map.yaml').resolve()}"]
    t0 = time.monotonic()
    cmd[4:4] = ["--timeout", "300"]           # a graph that hangs is stopped, its bag and log kept
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=360)
    (out / "standup.log").write_text(proc.stdout + proc.stderr)
    fell = f"driver exited with code {FELL_EXIT_CODE}" in proc.stdout     # analysed below: "did not stand up"
    if proc.returncode != 0 and not fell:
        raise RuntimeError(f"the stand-up graph failed on {bag} (exit {proc.returncode}):\n{proc.stdout[-4000:]}")
    stats = re.search(r"\[retargeter\] (\d+) frames, (\d+) infeasible, \d+ without a human COM; time scale ([\d.]+); "
                      r"IK p50 ([\d.]+) ms p99 ([\d.]+) ms; marker->command latency p50 ([\d.]+) ms p99 ([\d.]+) ms .*"
                      r"COM->command p50 ([\d.]+) ms p99 ([\d.]+) ms", proc.stdout)
    a = analyse(out / "standup", bag.name, params, plant, robot=robot)
    figure_6(a, out / "fig6_com.png")
    why = render_strip(a, plant, out / "standup_frames.png", **_human_beside(out / "standup", bag, a))
    if why:
        print(f"      no rendered frames ({why})", flush=True)
    res = dict(a.summary, wall_s=round(time.monotonic() - t0, 1))
    if stats:
        keys = ("frames", "infeasible_frames", "time_scale", "ik_p50_ms", "ik_p99_ms", "latency_p50_ms",
                "latency_p99_ms", "com_to_command_p50_ms", "com_to_command_p99_ms")
        res.update({k: float(v) for k, v in zip(keys, stats.groups())})
    return res, a


def _human_beside(run: Path, demonstration: Path, a: RunAnalysis, frames: int = 6) -> dict:
    """:func:`render_strip`'s human row: the skeleton at the frames' matched instants, and the human's chair (from
    the demonstration's metadata and plates)."""
    scene = load_scene(run, a.robot)
    at = a.t[strip_indices(len(a.t), frames)]
    bones = human_frames(scene, a.t, a.com[:, 2], at)
    if bones is None:
        return {}
    chair = load_scene(demonstration).human_chair
    return {"human_bones": bones, "human_chair": None if chair is None else (chair.centre, chair.half_size)}


def demo_params(robot: str, project: Path | None = None) -> Path:
    """Where ``make demo`` leaves ``robot``'s identified parameters (``runs/demo`` for the default robot,
    ``runs/demo_<robot>`` for another) under ``project`` (default: the working directory, where ``make`` runs)."""
    run = "demo" if robot == DEFAULT_ROBOT else f"demo_{robot}"
    return (project or Path.cwd()) / "runs" / run / "robot" / "identified_full.yaml"


def robot_identification(out: Path, n_postures: int, robot: str = DEFAULT_ROBOT) -> dict:
    """Static postures of ``robot``'s default plant, full-model identification, figures."""
    cfg = PlantConfig.load("default", robot)
    print(f"[robot] {n_postures} static postures of the simulated {cfg.profile.title} (plant {cfg.name})", flush=True)
    out.mkdir(parents=True, exist_ok=True)
    counts = collect_postures(cfg, n_postures, out / "postures", progress=False)
    result = identify(out / "postures", "full", robot=robot)
    print(f"      {result.summary()}", flush=True)
    write_yaml(result, out / "identified_full.yaml", source=str(out / "postures"), robot=cfg.profile.name)
    posture_figure(result, read_postures(out / "postures"), out / "identified_full.png")
    com_path_figure(result, out / "identified_full_com_path.png")
    return {"postures_kept": counts["kept"], "eval_rms_mm": result.eval_rms_m * 1e3,
            "cad_eval_rms_mm": result.cad_eval_rms_m * 1e3, "total_mass_kg": result.total_mass_kg,
            "cad_mass_kg": result.cad_mass_kg, "identify_s": result.seconds}


def model_gap(out: Path, robot: str = DEFAULT_ROBOT) -> dict:
    """The model-gap workflow on ``robot``'s default plant against the CAD model: an excitation run (standing,
    stance to stance) recorded like the driver's stream, plus the identification's static postures."""
    cfg = PlantConfig.load("default", robot)
    print(f"[gap] excitation run of the simulated {cfg.profile.title} (plant {cfg.name}), then sit2stand gap "
          "against CAD", flush=True)
    excite(cfg, out / "excite", seed=0)
    bags = [out / "excite"] + ([out.parent / "robot" / "postures"] if (out.parent / "robot" / "postures").exists()
                               else [])
    result = gap_command(bags, out, robot=robot)
    for e in result.effects:
        print(f"      {describe(e)}", flush=True)
    cop = cop_rms(result)
    print(f"      gap above the noise {result.gap_before:.1f} -> {result.gap_after:.2f} (shrink "
          f"{100 * result.shrink:.0f} %); model COP error {100 * cop[0][0]:.2f} -> {100 * cop[0][1]:.2f} cm RMS; "
          f"report {out}/report.md", flush=True)
    masses = [e for e in result.effects if e.kind == "extra_mass"]
    return {"effects": [e.as_dict() for e in result.effects], "gap_before": result.gap_before,
            "gap_after": result.gap_after,
            "shrink": result.shrink, "cop_rms_before_m": cop[0][0], "cop_rms_after_m": cop[0][1],
            "extra_mass_kg": sum(e.mass_kg for e in masses), "mass_links": [e.location for e in masses]}


def com_paths_figure(runs: dict[str, tuple[Path, Path]], png: Path) -> None:
    """Sagittal COM paths of the demonstrations: estimated (offline, scaled) and true."""
    matplotlib.use("Agg")
    fig, ax = plt.subplots(figsize=(7, 5.5))
    for (name, (run_dir, bag)), color in zip(runs.items(), ("tab:blue", "tab:red", "tab:green")):
        with BagReader(run_dir / "human_com") as b:
            _, com = _series(b, HUMAN_COM_TOPIC)
        with BagReader(bag) as b:
            _, truth = _series(b, GROUND_TRUTH_COM_TOPIC)
        ax.plot(truth[:, 0], truth[:, 2], color=color, lw=1, ls="--", label=f"{name}: true COM")
        ax.plot(com[:, 0], com[:, 2], color=color, lw=2, label=f"{name}: estimated (skeleton + COP scaling)")
        ax.plot(com[0, 0], com[0, 2], "o", color=color)
    ax.set_xlabel("COM forward x [m] (feet at x = 0)")
    ax.set_ylabel("COM height z [m]")
    ax.set_title("Sagittal COM paths from sitting (dot) to standing")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """Run the demo (see the module docstring); 0 when every COM error is within bounds and every robot stood up."""
    args = _parse_args(argv)
    missing = [b for b in args.bags if not (b / "metadata.yaml").exists()]
    if missing:
        print(f"sit2stand demo: error: no demonstration bag at {', '.join(map(str, missing))}", file=sys.stderr)
        return 2
    if args.out.exists():
        shutil.rmtree(args.out)
    args.out.mkdir(parents=True)
    summary: dict = {}
    runs: dict[str, tuple[Path, Path]] = {}
    params = None
    if not args.skip_robot:
        summary["robot"] = robot_identification(args.out / "robot", args.postures, args.robot)
        params = args.out / "robot" / "identified_full.yaml"
    analyses = []
    for i, bag in enumerate(args.bags, 1):
        runs[bag.name] = (args.out / bag.name, bag)
        summary[bag.name], a = demonstration(bag, args.out / bag.name, args.rate, params, f"[{i}/{len(args.bags)}]",
                                             args.robot)
        if a is not None:
            analyses.append(a)
    if not args.skip_robot:
        summary["robot_gap"] = model_gap(args.out / "gap", args.robot)
    com_paths_figure(runs, args.out / "com_paths.png")
    if analyses:
        figure_7(analyses, args.out / "fig7_com_paths.png")
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2))
    return _report(summary, runs, args)


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The command line: output folder, bags, replay rate, robot postures, --skip-robot."""
    parser = argparse.ArgumentParser(prog="sit2stand-demo", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("runs/demo"))
    parser.add_argument("--bags", type=Path, nargs="*", default=DEFAULT_BAGS)
    parser.add_argument("--rate", type=float, default=1.0)
    parser.add_argument("--postures", type=int, default=88, help="static postures for the robot identification")
    parser.add_argument("--skip-robot", action="store_true")
    parser.add_argument("--robot", default=DEFAULT_ROBOT, help="robot profile: talos (default), g1 or a file")
    return parser.parse_args(argv)


def demonstration(bag: Path, run_dir: Path, rate: float, params: Path | None,
                  tag: str, robot: str = DEFAULT_ROBOT) -> tuple[dict, RunAnalysis | None]:
    """One demonstration: the human COM offline and live, then (with identified ``params``) the robot's stand-up;
    its summary and the stand-up's analysis (None without a robot)."""
    name = bag.name
    print(f"{tag} {name}: human COM offline", flush=True)
    offline = human_com_offline(bag, run_dir, quiet=True)
    print(f"      COM RMS vs truth {offline['com_rms_vs_truth_scaled_mm']:.1f} mm scaled, "
          f"{offline['com_rms_vs_truth_unscaled_mm']:.1f} mm average model; COP RMS "
          f"{offline['cop_rms_scaled_mm']:.1f} mm", flush=True)
    print(f"      live graph: replayer -> human_com -> recorder at {rate:g}x", flush=True)
    live_figs = live(bag, run_dir / "live", rate)
    print(f"      live COM error mean {live_figs['com_error_mean_mm']:.1f} mm; per-frame cost p50 "
          f"{live_figs['cost_p50_ms']} ms, p99 {live_figs['cost_p99_ms']} ms", flush=True)
    out = {"offline": offline, "live": live_figs}
    if params is None:
        return out, None
    print("      stand-up graph: replayer -> human_com -> retargeter -> driver -> recorder", flush=True)
    out["standup"], a = standup(bag, run_dir, params, robot)
    st = out["standup"]
    print(f"      {'stood up' if st['stood_up'] else 'DID NOT STAND UP'}: pelvis {st['pelvis_start_m']:.2f} -> "
          f"{st['pelvis_final_m']:.2f} m, COM tracking RMS {st['com_tracking_rms_m'] * 100:.1f} cm, time scale "
          f"{st.get('time_scale', float('nan')):.2f}, IK p50 {st.get('ik_p50_ms', float('nan')):.2f} ms, "
          f"marker->command p50 {st.get('latency_p50_ms', float('nan')):.1f} ms p99 "
          f"{st.get('latency_p99_ms', float('nan')):.1f} ms", flush=True)
    return out, a


def _report(summary: dict, runs: dict[str, tuple[Path, Path]], args: argparse.Namespace) -> int:
    """Print what was written and, per demonstration, whether the robot stood up; the exit status."""
    ok = all(s["offline"]["com_rms_vs_truth_scaled_mm"] <= 10.0 for n, s in summary.items()
             if n not in ("robot", "robot_gap"))
    ok = ok and ("robot" not in summary or summary["robot"]["eval_rms_mm"] <= 5.0)
    stood = {n: s["standup"]["stood_up"] for n, s in summary.items() if "standup" in s}
    print(f"\n{'done' if ok else 'COM ERROR ABOVE 1 cm'}: {args.out}/summary.json, com_paths.png, "
          + ", ".join(f"{n}/human_com.png" for n in runs) + ("" if args.skip_robot else
                                                            ", robot/*.png, */fig6_com.png, fig7_com_paths.png, "
                                                            "gap/report.md"))
    for n, ok_n in stood.items():
        print(f"{n}: {'stood up' if ok_n else 'did not stand up'}")
    return 0 if ok and all(stood.values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
