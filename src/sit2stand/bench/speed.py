"""`make bench`: speed figures of the foundation, printed and written to JSON. Not a test: numbers, not verdicts.

Measured:
* bag write rate [msg/s]: BagWriter.write (serialize + write) of force-plate samples and 40-marker mocap frames;
* bag read rate [msg/s]: BagReader.messages (raw) and read + deserialize;
* bare rosbags read [msg/s] of the same bag (rosbags' Reader, no wrapper);
* replayer top rate [msg/s]: the replayer node at rate 0 with no subscriber, and into the recorder node (lossless,
  flow-controlled), each as a ratio of the bare rosbags read.

    python -m sit2stand.bench --out bench/results/bench.json [--messages 50000]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import tempfile as _tmp
import time
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import Reader

from ..batch.engine import run_jobs
from ..batch.gap import CASES as GAP_HUMAN_CASES
from ..batch.gap import gap_cases, gap_jobs
from ..data import graph_path, plant_path
from ..gap.effects import KINDS, OUT_OF_LIBRARY
from ..human.com import estimate_com
from ..human.com_stream import StreamingComEstimator
from ..human.offline import calibrate_from_bag, read_trial
from ..human.offline import run as human_com_offline
from ..human.skeleton import Subject
from ..io import messages as M
from ..io.bag import BagReader, BagWriter, merge_bags
from ..io.topics import MARKERS_TOPIC, MOCAP_TYPE, PLATE_TYPE, plate_topic
from ..retarget.player import PlanPlayer
from ..retarget.report import analyse
from ..retarget.robot import robot_setup
from ..retarget.stream import Retargeter
from ..robot.identify import identify
from ..robot.model import PlantConfig
from ..robot.plant import Plant
from ..robot.postures import collect_postures
from . import project_folder, provenance
from .driver import bench_driver
from .gap_human import bench_gap_human, summary_table
from .human import bench_human_real, print_table
from .live import COMMAND_P99_TARGET_MS


def _rate(n: int, seconds: float) -> float:
    return n / seconds if seconds > 0 else float("inf")


def bench_write(path: Path, n: int) -> dict[str, float]:
    """Write n/2 plate samples and n/2 mocap frames; messages are built beforehand (only writing is timed)."""
    rng = np.random.default_rng(0)
    names = [f"M{i:02d}" for i in range(40)]
    plates = [M.force_plate_sample(i * 500_000, "feet", rng.normal(size=3), rng.normal(size=3), rng.normal(size=3),
                                   True, 0.1) for i in range(n // 2)]
    frames = [M.mocap_frame(i * 10_000_000, names, rng.normal(size=(40, 3)), np.ones(40, bool))
              for i in range(n // 2)]
    t0 = time.perf_counter()
    with BagWriter(path) as bag:
        bag.add_topic(plate_topic("feet"), PLATE_TYPE)
        bag.add_topic(MARKERS_TOPIC, MOCAP_TYPE)
        t1 = time.perf_counter()
        for i, msg in enumerate(plates):
            bag.write(plate_topic("feet"), i * 500_000, msg)
        t2 = time.perf_counter()
        for i, msg in enumerate(frames):
            bag.write(MARKERS_TOPIC, i * 10_000_000, msg)
        t3 = time.perf_counter()
    t4 = time.perf_counter()
    size_mb = sum(p.stat().st_size for p in path.iterdir()) / 1e6
    return {"write_plate_msg_per_s": _rate(len(plates), t2 - t1),
            "write_mocap40_msg_per_s": _rate(len(frames), t3 - t2),
            "write_total_msg_per_s": _rate(n, t4 - t0), "bag_size_mb": size_mb}


def bench_read(path: Path) -> dict[str, float]:

    t0 = time.perf_counter()
    with Reader(path) as reader:
        n_bare = sum(1 for _ in reader.messages())
    t1 = time.perf_counter()
    with BagReader(path) as bag:
        n_raw = sum(1 for _ in bag.messages())
        t2 = time.perf_counter()
        n_des = sum(1 for m in bag.messages() if bag.deserialize(m) is not None)
        t3 = time.perf_counter()
    assert n_bare == n_raw == n_des
    return {"bare_rosbags_read_msg_per_s": _rate(n_bare, t1 - t0), "read_raw_msg_per_s": _rate(n_raw, t2 - t1),
            "read_deserialize_msg_per_s": _rate(n_des, t3 - t2), "messages": n_bare}


def _replayer_rate(bag: Path, env: dict[str, str], record_to: Path | None) -> float:
    """msg/s the replayer reports for an unpaced replay (optionally into a recorder process)."""
    rec = None
    if record_to is not None:
        rec = subprocess.Popen([sys.executable, "-m", "sit2stand.nodes.recorder", "--ros-args", "-p",
                                f"output:={record_to}", "-p", "regex:=^/(mocap|force)",
                                "-p", "discovery_period_s:=0.1"],
                               env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    args = [sys.executable, "-m", "sit2stand.nodes.replayer", "--ros-args", "-p", f"bag:={bag}", "-p", "rate:=0.0",
            "-p", "publish_clock:=false"]
    if rec is not None:
        args += ["-p", "wait_for_subscribers:=1"]
    out = subprocess.run(args, env=env, capture_output=True, text=True, timeout=600)
    if rec is not None:
        rec.send_signal(2)
        rec.wait(60)
    match = re.search(r"done: (\d+) messages published in ([\d.]+) s", out.stdout + out.stderr)
    if not match:
        raise RuntimeError(f"replayer did not report its rate:\n{out.stdout}{out.stderr}")
    if record_to is not None:
        with BagReader(record_to) as recorded:
            if recorded.message_count != int(match.group(1)):
                raise RuntimeError(f"recorder kept {recorded.message_count} of {match.group(1)} messages")
    return _rate(int(match.group(1)), float(match.group(2)))


def bench_human_com(bag: Path) -> dict[str, float]:
    """Per-frame cost of the streaming human COM estimator (the node's core) over a shipped demonstration, and
    the offline estimator's throughput. Calibration (one frame, once) and re-solves are included in the tails."""

    trial = read_trial(bag)
    subject = Subject(trial.height_m, trial.mass_kg, trial.sex)
    est = StreamingComEstimator(subject, trial.marker_names)
    plates = trial.plates
    idx = [0] * len(plates)
    costs = []
    for k, t in enumerate(trial.marker_t_s):
        for i, p in enumerate(plates):
            j = np.searchsorted(p.t_s, t, side="right")
            est.add_plate_samples(p.name, p.t_s[idx[i]:j], p.force_n[idx[i]:j], p.moment_origin_nm[idx[i]:j])
            idx[i] = j
        t0 = time.perf_counter()
        est.update(t, trial.positions[k], trial.valid[k])
        costs.append(time.perf_counter() - t0)
    c = np.array(costs) * 1e3
    steady = np.delete(c, int(np.argmax(c)))       # without the one calibration frame
    t0 = time.perf_counter()
    estimate_com(trial.marker_t_s, trial.marker_names, trial.positions, trial.valid, plates, subject)
    offline_s = time.perf_counter() - t0
    return {"stream_frames": int(len(c)), "stream_cost_p50_ms": float(np.percentile(steady, 50)),
            "stream_cost_p99_ms": float(np.percentile(steady, 99)), "stream_cost_max_ms": float(steady.max()),
            "calibration_frame_ms": float(c.max()), "offline_s": offline_s,
            "offline_frames_per_s": len(c) / offline_s}


def bench_human_com_graph(bag: Path, env: dict[str, str]) -> dict[str, float]:
    """The human_com node's own per-frame cost (p50/p99) in a real-time graph: replayer -> node -> recorder."""

    with BagReader(bag) as b:
        meta = b.custom_data
    with _tmp.TemporaryDirectory() as tmp:
        out = subprocess.run([sys.executable, "-m", "sit2stand.cli", "launch", str(graph_path("human_com")),
                              f"bag:={bag}", f"out:={Path(tmp) / 'rec'}", f"height:={meta['height_m']}",
                              f"mass:={meta['body_mass_kg']}"], env=env, capture_output=True, text=True, timeout=300)
    m = re.search(r"(\d+) frames, \d+ skipped .*cost p50 ([\d.]+) ms p99 ([\d.]+) ms", out.stdout)
    if out.returncode != 0 or not m:
        raise RuntimeError(f"human_com graph failed:\n{out.stdout[-3000:]}{out.stderr[-2000:]}")
    return {"node_frames": int(m.group(1)), "node_cost_p50_ms": float(m.group(2)),
            "node_cost_p99_ms": float(m.group(3))}


def bench_retarget(root: Path) -> dict[str, float]:
    """Per-frame cost of the retargeting IK and of the plan player on the shipped demonstrations (no ROS), and the
    same IK without the COM and seat constraints (markers and feet only) for comparison."""

    robot = robot_setup()
    ik_ms, player_ms, free_ms, rms_c, rms_free = [], [], [], [], []
    for name in ("natural", "elderly"):
        trial = read_trial(root / "bags" / name)
        t, com = trial.truth
        com_h = np.stack([np.interp(trial.marker_t_s, t, com[:, i]) for i in range(3)], axis=1)
        chair = next(p for p in trial.plates if p.name == "chair")
        fz = np.interp(trial.marker_t_s, chair.t_s, chair.force_n[:, 2])
        rt = Retargeter(robot)
        rt.calibrate(trial.marker_names, trial.positions[0], trial.valid[0], com_h[0])
        player = PlanPlayer(robot.model, 0.01, robot.support_xy)
        for k, tk in enumerate(trial.marker_t_s):
            f = rt.step(float(tk), trial.positions[k], trial.valid[k], com_h[k], float(fz[k]))
            ik_ms.append(f.ik.seconds * 1e3)
            rms_c.append(f.ik.marker_rms_m)
            t0 = time.perf_counter()
            player.push(f.q, not f.seated)
            player.pull()
            player_ms.append((time.perf_counter() - t0) * 1e3)
            # marker-only IK of the same marker tasks from the same pose: feet fixed, no COM rows, no seat
            t0 = time.perf_counter()
            free = rt.ik.solve(f.q, f.markers, f.com_target, robot.sole_targets, q_ref=f.q, com_axes=(),
                               max_iterations=rt.cfg.iterations)
            free_ms.append((time.perf_counter() - t0) * 1e3)
            rms_free.append(free.marker_rms_m)
    ik, pl = np.array(ik_ms), np.array(player_ms)
    return {"frames": len(ik), "ik_p50_ms": float(np.percentile(ik, 50)), "ik_p99_ms": float(np.percentile(ik, 99)),
            "ik_p50_vs_1ms_target": float(np.percentile(ik, 50)) / 1.0,
            "ik_p99_vs_3ms_target": float(np.percentile(ik, 99)) / 3,
            "player_p50_ms": float(np.percentile(pl, 50)), "player_p99_ms": float(np.percentile(pl, 99)),
            "marker_only_ik_p50_ms": float(np.percentile(free_ms, 50)),
            "marker_rms_com_hard_mm": float(np.mean(rms_c) * 1e3),
            "marker_rms_marker_only_mm": float(np.mean(rms_free) * 1e3)}


def bench_retarget_graphs(root: Path, env: dict[str, str]) -> dict[str, float]:
    """The retargeter's latency (a marker frame's arrival in the retargeter -> its joint command published; waiting
    for the human COM included) in real graphs on bags/elderly (CAD plant and parameters, so both stand up):

    * ``retarget.yaml``: the demonstration merged with its offline human COM, replayer -> retargeter -> driver ->
      recorder, the retargeter at SCHED_FIFO 50 (the graph's default) and under the time-sharing scheduler;
    * ``standup.yaml`` as ``make demo`` runs it: the human COM estimator live (skeleton calibrated beforehand on
      the first 50 frames), estimator, retargeter and the robot's loop at real-time priority.

    Each run's COM tracking too: the measured robot COM against the planned one (RMS, with the COM feedback)."""


    cad = plant_path("cad")
    pat = (r"latency p50 ([\d.]+) ms p99 ([\d.]+) ms .*COM->command p50 ([\d.]+) ms p99 ([\d.]+) ms; marker->command "
           r"with the COM stream in step \((\d+) frames\) p50 ([\w.]+) ms p99 ([\w.]+) ms; scheduling ([\w ]+)")
    out: dict[str, float | str] = {}
    with _tmp.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        bag = root / "bags" / "elderly"
        human_com_offline(bag, tmp / "hc", quiet=True)
        merge_bags(tmp / "with_com", [bag, tmp / "hc" / "human_com"])
        calibrate_from_bag(bag, tmp / "calibration.yaml")
        runs = (("retarget_graph", "retarget", tmp / "with_com", []),
                ("retarget_graph_timesharing", "retarget", tmp / "with_com", ["rt_policy:=other"]),
                ("standup_graph", "standup", bag, [f"calibration:={tmp / 'calibration.yaml'}",
                                                  "estimator_policy:=fifo", "driver_policy:=fifo"]))
        for key, graph, bag_in, extra in runs:
            proc = subprocess.run([sys.executable, "-m", "sit2stand.cli", "launch", "--timeout", "300",
                                   str(graph_path(graph)), f"bag:={bag_in}", f"out:={tmp / key}",
                                   f"plant:={cad}", *extra], env=env,
                                  capture_output=True, text=True, timeout=400)
            m = re.search(pat, proc.stdout)
            if proc.returncode != 0 or not m:
                raise RuntimeError(f"{graph} failed:\n{proc.stdout[-3000:]}{proc.stderr[-2000:]}")
            out[f"{key}_marker_to_command_p50_ms"] = float(m.group(1))
            out[f"{key}_marker_to_command_p99_ms"] = float(m.group(2))
            out[f"{key}_com_to_command_p50_ms"] = float(m.group(3))
            out[f"{key}_com_to_command_p99_ms"] = float(m.group(4))
            out[f"{key}_scheduling"] = m.group(8).strip()
            out[f"{key}_stood_up"] = float("upright" in proc.stdout and "FALLEN" not in proc.stdout)
            track = analyse(tmp / key, "elderly", None, cad).summary["com_tracking_rms_m"]
            out[f"{key}_com_tracking_rms_cm"] = round(track * 100, 2)      # measured robot COM vs its plan
    out["standup_graph_com_tracking_vs_2cm_target"] = out["standup_graph_com_tracking_rms_cm"] / 2.0
    out["retarget_graph_p99_vs_10ms_target"] = out["retarget_graph_marker_to_command_p99_ms"] / COMMAND_P99_TARGET_MS
    out["standup_graph_p99_vs_10ms_target"] = out["standup_graph_marker_to_command_p99_ms"] / COMMAND_P99_TARGET_MS
    return out


def bench_robot(n_postures: int = 88) -> dict[str, float]:
    """Plant real-time factor at 1 kHz (seated, PD + gravity feed-forward), and identification time."""


    cfg = PlantConfig.load(plant_path("default"))
    plant = Plant(cfg)
    plant.step(200)
    t0 = time.perf_counter()
    plant.step(5000)
    rtf = 5.0 / (time.perf_counter() - t0)
    out = {"plant_real_time_factor_1khz": rtf}
    with _tmp.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        counts = collect_postures(cfg, n_postures, Path(tmp) / "p", progress=False)
        out["collect_postures_s"] = time.perf_counter() - t0
        out["postures"] = counts["kept"]
        for model in ("full", "planar5"):
            r = identify(Path(tmp) / "p", model)
            out[f"identify_{model}_s"] = r.seconds
            out[f"identify_{model}_eval_rms_mm"] = r.eval_rms_m * 1e3
            out[f"identify_{model}_cad_eval_rms_mm"] = r.cad_eval_rms_m * 1e3
    return out


def _print_sections(results: dict, sections: list[str]) -> None:
    width = max((len(k) for section in sections for k in results[section]), default=0)
    for section in sections:
        print(f"\n[{section}]")
        for key, value in results[section].items():
            if key == "measured":
                continue
            if isinstance(value, list | dict):
                print(f"  {key:<{width}}  {len(value)} (see the JSON file)")
            else:
                text = f"{value:>12,.2f}" if isinstance(value, float) else f"{value:>12}"
                print(f"  {key:<{width}}  {text}")


def bench_gap(n_per_kind: int = 10, n_two: int = 5, workers: int = 2, progress: bool = True,
              kinds: tuple[str, ...] = KINDS + OUT_OF_LIBRARY, address: str | None = None) -> dict:
    """Hit rates of the model-gap workflow on hidden-effect plants (see :func:`gap_cases`), the plants as a batch
    (:mod:`sit2stand.batch.engine`: ``workers`` Ray workers, or the cluster at ``address``). In-library: a hit names
    the hidden effect's kind and location with its magnitude within 20 %, "clean" names nothing else. Outside the
    library: honest when a residual is flagged as unexplained (a close proxy may be named beside it). A plant that
    cannot stand to be excited (the case fails twice) is said, not scored."""
    jobs = gap_jobs(gap_cases(n_per_kind, n_two, kinds))
    t0 = time.perf_counter()

    def show(r: dict) -> None:
        if not progress:
            return
        if r["status"] == "failed":
            print(f"  SKIPPED {r['hidden_kind']}: {r['error']}", flush=True)
        else:
            print(f"  {'hit ' if _gap_ok(r) else 'MISS'} {r['hidden_kind']}: hidden {r['hidden']} -> named "
                  f"{r['named']}" + (f"; unexplained {r['unexplained'][:1]}" if r["unexplained"] else ""), flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        rows = run_jobs(jobs, Path(tmp), workers=workers, address=address, on_row=show, label="bench-gap")
    scored = [{**r, "kind": r["hidden_kind"]} for r in rows if r["status"] == "ok"]
    out = _gap_rates(scored)
    out["skipped"] = [{"kind": r["hidden_kind"], "why": r["error"]} for r in rows if r["status"] == "failed"]
    out["wall_s"] = time.perf_counter() - t0
    return out


def _gap_ok(r: dict) -> bool:
    """A case scored right: a hit (in the library), honest (outside), nothing named (nothing hidden)."""
    return r["hit"] or (r["kind"] == "none" and not r["named"] and not r["unexplained"])


def _gap_rates(rows: list[dict]) -> dict:
    """The benchmark's figures per kind from the case rows."""
    out: dict[str, object] = {}
    for kind in dict.fromkeys(r["kind"] for r in rows):
        rs = [r for r in rows if r["kind"] == kind]
        if kind == "none":
            out["none_no_effect_rate"] = float(np.mean([not r["named"] for r in rs]))
            out["none_no_alarm_rate"] = float(np.mean([_gap_ok(r) for r in rs]))
            continue
        if kind in OUT_OF_LIBRARY:
            out[f"{kind}_honest_rate"] = float(np.mean([r["hit"] for r in rs]))
            out[f"{kind}_confident_wrong_rate"] = float(np.mean([bool(r["named"]) and not r["unexplained"]
                                                                 for r in rs]))
        else:
            out[f"{kind}_hit_rate"] = float(np.mean([all(r["found"]) and max(r["errors"]) <= 0.2 for r in rs]))
            out[f"{kind}_clean_hit_rate"] = float(np.mean([r["hit"] for r in rs]))
            out[f"{kind}_located_rate"] = float(np.mean([all(r["found"]) for r in rs]))
            out[f"{kind}_median_error_pct"] = float(100 * np.nanmedian([max(r["errors"]) for r in rs]))
        moved = [r for r in rs if r["gap_before"] > 0 and r["named"]]
        for name in ("shrink", "shrink_first_order"):
            out[f"{kind}_median_{name}_pct"] = float(100 * np.median([r[name] for r in moved])) if moved \
                else float("nan")
        out[f"{kind}_median_replay_gap"] = [float(np.median([r[k] for r in rs]))
                                            for k in ("replay_gap_before", "replay_gap_after")]
    named = [r for r in rows if r["named"] and r["gap_before"] > 0]
    out["shrink_gap_max_points"] = float(max((100 * abs(r["shrink"] - r["shrink_first_order"]) for r in named),
                                             default=0.0))
    out["cases"] = len(rows)
    out["excite_s_median"] = float(np.median([r["excite_s"] for r in rows]))
    out["workflow_s_median"] = float(np.median([r["workflow_s"] for r in rows]))
    out["misses"] = [{k: r[k] for k in ("kind", "hidden", "named", "errors", "unexplained", "refused", "shrink",
                                        "shrink_first_order")} for r in rows if not _gap_ok(r)]
    return out


def _estimator_section(root: Path, env: dict[str, str]) -> dict:
    demo = root / "bags" / "natural"
    print("human COM: streaming estimator and offline run on bags/natural ...", flush=True)
    out = bench_human_com(demo)
    print("human COM: the node in a real-time graph ...", flush=True)
    out.update(bench_human_com_graph(demo, env))
    return out


def _retarget_section(root: Path, env: dict[str, str]) -> dict:
    print("retargeting: IK and plan player per frame on both demonstrations ...", flush=True)
    out = bench_retarget(root)
    print("retargeting: latency in the retarget and stand-up graphs on bags/elderly ...", flush=True)
    out.update(bench_retarget_graphs(root, env))
    return out


def _human_real_section() -> dict:
    print("human COM on real lab trials: Newton's law for the whole body ...", flush=True)
    out = bench_human_real()
    print_table(out)
    return out


def _gap_section(seeds: int, two: int | None = None, kinds: str | None = None) -> dict:
    chosen = tuple(k for k in kinds.split(",") if k) if kinds else KINDS + OUT_OF_LIBRARY
    bad = set(chosen) - set(KINDS + OUT_OF_LIBRARY)
    if bad:
        raise SystemExit(f"--gap-kinds: unknown {sorted(bad)} (known: {', '.join(KINDS + OUT_OF_LIBRARY)})")
    print(f"model gap: hidden-effect plants, {seeds} seeds per effect kind ({len(chosen)} kinds) ...", flush=True)
    return bench_gap(seeds, n_two=seeds // 2 if two is None else two, kinds=chosen)


def _gap_human_section(n: int, cases: str | None = None, workers: int = 1, de_leva: bool = False) -> dict:
    chosen = tuple(c for c in cases.split(",") if c) if cases else GAP_HUMAN_CASES
    bad = set(chosen) - set(GAP_HUMAN_CASES)
    if bad:
        raise SystemExit(f"--gap-human-cases: unknown {sorted(bad)} (known: {', '.join(GAP_HUMAN_CASES)})")
    print(f"model gap, human side: {n} digital humans per case ({len(chosen)} cases: {', '.join(chosen)})"
          + (", bodies of de Leva's proportions" if de_leva else "") + " ...", flush=True)
    out = bench_gap_human(n, chosen, workers, vary_subject=not de_leva)
    print(summary_table(out))
    return out


def _write(results: dict, out: Path, sections: list[str], made: list[str], command: str) -> None:
    """Print ``sections`` of ``results``, stamp the sections ``made`` by this run with their :func:`provenance`
    (``command``), and write all of it to ``out``."""
    for key in made:
        results[key] = {"measured": provenance(command), **results[key]}
    _print_sections(results, sections)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2))
    print(f"\nwritten to {out}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="sit2stand-bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results/bench.json"))
    parser.add_argument("--messages", type=int, default=40_000)
    parser.add_argument("--only", choices=["gap", "gap_human", "retarget", "human", "driver", "estimator"],
                        help="run one section and merge it into the JSON file")
    # 10 seeds x (14 kinds + 2 outside), 10 clean, 5 with two: ~25 s a case with its replays, ~40 min on 2 cores
    parser.add_argument("--gap-seeds", type=int, default=10, help="hidden-effect cases per effect kind")
    parser.add_argument("--gap-two", type=int, default=None, help="cases with two hidden effects (default: seeds / 2)")
    parser.add_argument("--gap-kinds", default=None, help="comma-separated kinds (default: all, in and outside "
                        "the library)")
    # 20 humans x 11 cases (a mass on each of 9 segment groups, a scale error, nothing): ~5 s a human, ~20 min
    parser.add_argument("--gap-human-n", type=int, default=20, help="digital humans per human-side case")
    parser.add_argument("--gap-human-cases", default=None, help="comma-separated human-side cases (default: all: "
                        + ", ".join(GAP_HUMAN_CASES) + ")")
    parser.add_argument("--gap-human-workers", type=int, default=1, help="human-side runs in parallel (processes)")
    parser.add_argument("--gap-human-de-leva", action="store_true", help="human side: bodies of de Leva's "
                        "proportions exactly (no random segment factors), to tell the workflow's misses from the "
                        "population's own mass differences")
    args = parser.parse_args(argv)
    root = project_folder()
    env = dict(os.environ, ROS_DOMAIN_ID=os.environ.get("ROS_DOMAIN_ID", "91"),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    if args.only:
        results = json.loads(args.out.read_text()) if args.out.exists() else {}
        sections = {"gap": lambda: _gap_section(args.gap_seeds, args.gap_two, args.gap_kinds),
                    "gap_human": lambda: _gap_human_section(args.gap_human_n, args.gap_human_cases,
                                                            args.gap_human_workers, args.gap_human_de_leva),
                    "retarget": lambda: _retarget_section(root, env),
                    "human": _human_real_section, "driver": lambda: bench_driver(env),
                    "estimator": lambda: _estimator_section(root, env)}
        key = {"human": "human_real", "estimator": "human_com"}.get(args.only, args.only)
        key += "_de_leva" if args.only == "gap_human" and args.gap_human_de_leva else ""    # beside, not over it
        results[key] = sections[args.only]()
        _write(results, args.out, [] if key == "human_real" else [key], [key],  # human_real: printed as its table
               f"make bench-{args.only.replace('_', '-')}")
        return 0

    results: dict[str, object] = {"machine": {"python": sys.version.split()[0], "cpu_count": os.cpu_count(),
                                              "platform": platform.platform()}}
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "bench"
        print(f"bag write/read with {args.messages} messages ...", flush=True)
        results["bag"] = bench_write(bag, args.messages)
        results["bag"].update(bench_read(bag))
        bare = results["bag"]["bare_rosbags_read_msg_per_s"]
        print("replayer, unpaced, no subscriber ...", flush=True)
        alone = _replayer_rate(bag, env, None)
        print("replayer -> recorder, unpaced, lossless ...", flush=True)
        into_recorder = _replayer_rate(bag, env, Path(tmp) / "copy")
        results["replayer"] = {"top_rate_msg_per_s": alone, "top_rate_vs_bare_read": alone / bare,
                               "into_recorder_msg_per_s": into_recorder,
                               "into_recorder_vs_bare_read": into_recorder / bare}

    results["human_com"] = _estimator_section(root, env)
    print("robot: plant real-time factor, 88 postures, identification ...", flush=True)
    results["robot"] = bench_robot()
    print("driver: plant step per controller against mj_step, the node's real-time factor ...", flush=True)
    results["driver"] = bench_driver(env)
    results["human_real"] = _human_real_section()
    results["retarget"] = _retarget_section(root, env)
    results["gap"] = _gap_section(args.gap_seeds, args.gap_two, args.gap_kinds)
    shown = [s for s in ("bag", "replayer", "human_com", "robot", "driver", "retarget", "gap") if s in results]
    _write(results, args.out, shown, [k for k in results if k != "machine"], "make bench")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
