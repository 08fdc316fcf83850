"""Benchmark (not a test): a fault campaign and a soak. Every fault of the campaign is injected into real files and real
node processes, and its outcome recorded; the soak runs the simulated robot and a recorder for minutes.

    python -m sit2stand.bench.faults [--soak-min 2] [--only CASE,...] [--out bench/results/faults.json]
    make bench-faults                       (the campaign and a 2-minute soak)
    make bench-faults SOAK_MIN=30           (the 30-minute soak)

Outcomes: ``clear error`` (exit 2 or a refusal, one line naming the file, topic or field), ``flagged`` (a result
marked invalid or warned about), ``recovered`` (what was lost is said), ``robot ran on`` (a node failure that did
not stop the graph, the job reported failed). Anything else is a failure of the campaign: ``TRACEBACK`` or
``SILENT`` (exit 0 and no word of the fault).

The soak: ``sit2stand launch robot_seated`` (the driver's 1 kHz loop in real time, its /clock driving a recorder that
records every topic); each node's resident memory (VmRSS) over the first and the last minute, the driver's real-time
factor over each (its /robot/status), and the recorder's lag (log time minus header stamp of /robot/joint_states) in
each; lost messages: gaps in the 200 Hz joint-state stamps and the recorder's own count.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus

from . import project_folder, write_result
from ..io.bag import BagError, BagReader, BagWriter
from ..io.messages import cdr_header_stamp_ns
from ..robot.identify import (IdentificationError, check_postures, check_result, controller_model, identify_full,
                             read_postures, write_yaml)
from ..robot.model import PlantConfig
from ..robot.postures import collect_postures



def _natural() -> Path:
    return project_folder() / "bags" / "natural"


def _real_c3d() -> Path:
    return (project_folder() / ".." / "shared" / "data" / "real" / "sts_child_vicon_01.c3d").resolve()
MARKERS = "/mocap/markers"


def _env(domain: int) -> dict[str, str]:
    return dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                PYTHONUNBUFFERED="1", RCUTILS_COLORIZED_OUTPUT="0")


def _cli(*args: str, timeout: float = 300, domain: int = 61) -> tuple[int, str]:
    """Run ``sit2stand ARGS``; its exit code and output."""
    result = subprocess.run([sys.executable, "-m", "sit2stand.cli", *map(str, args)], capture_output=True, text=True,
                            timeout=timeout, env=_env(domain), cwd=project_folder())
    return result.returncode, result.stdout + result.stderr


def _last_error(out: str) -> str:
    lines = [ln.strip() for ln in out.splitlines() if ln.strip()]
    errors = [ln for ln in lines if re.search(r"error|refus|invalid|warn|lost|corrupt|truncat", ln, re.I)]
    return (errors or lines or [""])[-1][:160]


def _judge(rc: int, out: str) -> tuple[str, str]:
    """``clear error`` on exit 2 without a traceback, else TRACEBACK / SILENT."""
    if "Traceback" in out:
        return "TRACEBACK", out.strip().splitlines()[-1][:160]
    if rc == 2:
        return "clear error", _last_error(out)
    return "SILENT", f"exit {rc}: {_last_error(out)}"


# --- bags and files ------------------------------------------------------------------------------------------------
def _copy(src: Path, work: Path, name: str) -> Path:
    dst = work / name
    shutil.copytree(src, dst)
    return dst


def _mcap(bag: Path) -> Path:
    return next(bag.glob("*.mcap"))


def _recover(bag: Path) -> tuple[str, str]:
    rc, out = _cli("bag", "recover", bag)
    if "Traceback" in out or rc not in (0, 1):
        return _judge(rc, out)
    said = [ln.strip() for ln in out.splitlines() if re.match(r"\s*(recovered|skipped)", ln)]
    return "recovered", "; ".join(said)[:200] or _last_error(out)


def case_corrupt_chunk(work: Path) -> list[tuple[str, str, str]]:
    bag = _copy(_natural(), work, "corrupt")
    data = bytearray(_mcap(bag).read_bytes())
    at = len(data) // 3
    data[at:at + 256] = random.Random(0).randbytes(256)
    _mcap(bag).write_bytes(bytes(data))
    rc, out = _cli("bag", "info", bag)
    return [("corrupt chunk: bag info", *_judge(rc, out)), ("corrupt chunk: bag recover", *_recover(bag))]


def case_cut_bag(work: Path) -> list[tuple[str, str, str]]:
    bag = _copy(_natural(), work, "cut")
    data = _mcap(bag).read_bytes()
    _mcap(bag).write_bytes(data[:len(data) // 2])
    (bag / "metadata.yaml").unlink()                     # as a recorder killed mid-run leaves it
    rc, out = _cli("bag", "info", bag)
    return [("cut bag: bag info", *_judge(rc, out)), ("cut bag: bag recover", *_recover(bag))]


def case_cut_c3d(work: Path) -> list[tuple[str, str, str]]:
    if not _real_c3d().is_file():
        return [("cut C3D: import-c3d", "skipped", f"{_real_c3d()} is not on this machine")]
    cut = work / "cut.c3d"
    data = _real_c3d().read_bytes()
    cut.write_bytes(data[:len(data) // 2])
    rc, out = _cli("import-c3d", cut, "--out", work / "cut_c3d")
    return [("cut C3D: import-c3d", *_judge(rc, out))]


def _edit_markers(src: Path, dst: Path, edit: Callable[[int, object], object | None]) -> Path:
    """A copy of ``src`` with each MocapFrame passed through ``edit(index, msg)`` (None drops it)."""
    with BagReader(src) as bag, BagWriter(dst, custom_data=bag.custom_data) as out:
        for topic, info in bag.topics().items():
            out.add_topic(topic, info.msgtype, bag.qos(topic))
        frame = 0
        for msg in bag.messages():
            value = bag.deserialize(msg)
            if msg.topic == MARKERS:
                value, frame = edit(frame, value), frame + 1
            if value is not None:
                out.write(msg.topic, msg.timestamp_ns, value)
    return dst


def _nan_stretch(i: int, msg):
    if 150 <= i < 200:
        for p in msg.positions:
            p.x = p.y = p.z = float("nan")
        msg.valid = np.zeros(len(msg.valid), bool)
    return msg


def _without(name: str):
    def edit(_i: int, msg):
        keep = [k for k, n in enumerate(msg.marker_names) if n != name]
        msg.marker_names = [msg.marker_names[k] for k in keep]
        msg.positions = [msg.positions[k] for k in keep]
        msg.valid = np.asarray(msg.valid)[keep]
        msg.residuals_m = np.asarray(msg.residuals_m)[keep]
        return msg
    return edit


def _in_mm(_i: int, msg):
    for p in msg.positions:
        p.x, p.y, p.z = p.x * 1000, p.y * 1000, p.z * 1000
    return msg


def case_markers(work: Path) -> list[tuple[str, str, str]]:
    rows = []
    for label, edit in (("NaN markers (50 frames)", _nan_stretch), ("missing marker RASI", _without("RASI")),
                        ("markers in mm", _in_mm)):
        bag = _edit_markers(_natural(), work / re.sub(r"\W+", "_", label), edit)
        rc, out = _cli("human-com", bag, "--out", work / f"{bag.name}_com")
        rows.append((f"{label}: human-com", *_human_com_outcome(rc, out, work / f"{bag.name}_com")))
    return rows


def _human_com_outcome(rc: int, out: str, out_dir: Path) -> tuple[str, str]:
    """``flagged`` when human-com's summary.json says it left frames out or has notes; with its COM error."""
    summary = out_dir / "summary.json"
    if rc != 0 or not summary.is_file():
        return _judge(rc, out)
    s = json.loads(summary.read_text())
    said = [f"{s['frames'] - s['frames_fitted']} of {s['frames']} frames not fitted"] if \
        s["frames_fitted"] < s["frames"] else []
    said += [str(n) for n in s.get("notes") or []] + [f"at bound: {b}" for b in s.get("factors_at_bounds") or []]
    error = f"COM {s.get('com_rms_vs_truth_scaled_mm', float('nan')):.1f} mm RMS from the truth"
    return ("flagged", f"{'; '.join(said)} ({error})"[:160]) if said else ("SILENT", error)


def case_empty_and_wrong_type(work: Path) -> list[tuple[str, str, str]]:
    empty = _edit_markers(_natural(), work / "empty_markers", lambda _i, _m: None)
    rc, out = _cli("human-com", empty, "--out", work / "empty_com")
    rows = [("topic without messages: human-com", *_judge(rc, out))]
    wrong = _copy(_natural(), work, "wrong_type")
    meta = wrong / "metadata.yaml"
    meta.write_text(meta.read_text().replace("sit2stand_msgs/msg/MocapFrame", "sit2stand_msgs/msg/CenterOfMass"))
    rc, out = _cli("human-com", wrong, "--out", work / "wrong_com")
    return rows + [("metadata naming the wrong type: human-com", *_judge(rc, out))]


def case_identification(work: Path) -> list[tuple[str, str, str]]:
    collect_postures(PlantConfig.load("default"), 30, work / "postures", progress=False)
    data, model = read_postures(work / "postures"), controller_model()
    q = data.q.copy()
    q[4, 3] = np.nan
    bad = {"foreign joint name": dataclasses.replace(data, joint_names=["arm_7_joint"] + data.joint_names[1:]),
           "NaN posture": dataclasses.replace(data, q=q)}
    rows = []
    for label, postures in bad.items():
        rows.append((f"identification, {label}", *_refused(lambda p=postures: check_postures(p, model, "postures"),
                                                           IdentificationError)))
    result = identify_full(data)
    check_result(result, "postures")
    write_yaml(result, work / "identified_full.yaml")          # the stand-up's parameters (killed_recorder)
    doubled = dataclasses.replace(data, tau=2 * data.tau, wrench={s: 2 * w for s, w in data.wrench.items()})
    rows.append(("identification, forces doubled", *_refused(
        lambda: check_result(identify_full(doubled), "postures"), IdentificationError)))
    return rows


def _refused(call: Callable[[], object], error: type[Exception]) -> tuple[str, str]:
    try:
        call()
    except error as err:
        return "clear error", str(err).splitlines()[0][:160]
    return "SILENT", "accepted"


# --- node processes -----------------------------------------------------------------------------------------------
def case_second_graph(work: Path) -> list[tuple[str, str, str]]:
    env = _env(62)
    first = subprocess.Popen([sys.executable, "-m", "sit2stand.nodes.replayer", "--ros-args", "-p",
                              f"bag:={_natural()}", "-p", "loop:=true"], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
    try:
        time.sleep(4.0)
        rc, out = _cli("replay", _natural(), domain=62, timeout=60)
    finally:
        first.send_signal(signal.SIGINT)
        first_out = first.communicate(timeout=30)[0]
    if first.returncode == 2 and rc != 2:          # the first saw the second before the second saw it
        rc, out = 2, first_out
    return [("second graph on the domain: replay", *_judge(rc, out))]


def case_killed_recorder(work: Path) -> list[tuple[str, str, str]]:
    rc, out = _standup_killing_the_recorder(work / "standup", work / "identified_full.yaml", at_percent=40.0)
    driver = re.search(r"\[driver\] (simulated .*?); (upright|FALLEN)", out)
    if "Traceback" in out:
        outcome = "TRACEBACK"
    elif "retargeter exited with code 0" in out and rc == 1 and "the job failed: recorder" in out:
        outcome = "robot ran on"           # the plan played to its end without the recorder; the job failed
    else:
        outcome = "SILENT" if rc == 0 else "stopped"
    detail = f"launcher exit {rc}; driver {driver.group(1) + ', ' + driver.group(2) if driver else 'did not report'}"
    return [("recorder killed (SIGKILL) in the stand-up", outcome, detail),
            ("recorder killed: bag recover", *_recover(work / "standup"))]


def _standup_killing_the_recorder(out_dir: Path, params: Path, at_percent: float) -> tuple[int, str]:
    """The stand-up graph on the natural rise, its recorder killed once the replay is ``at_percent`` through."""
    if not params.is_file():
        params = project_folder() / "runs" / "demo" / "robot" / "identified_full.yaml"
    proc = subprocess.Popen([sys.executable, "-m", "sit2stand.cli", "launch", "standup", f"bag:={_natural()}",
                             f"out:={out_dir}", f"params:={params}", "height:=1.75", "mass:=75"], env=_env(63),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=project_folder())
    lines, recorder_pid = [], 0
    for line in proc.stdout:
        lines.append(line)
        pid = re.search(r"started recorder \(pid (\d+)\)", line)
        if pid:
            recorder_pid = int(pid.group(1))
        progress = re.search(r"\[replayer\]:\s+([\d.]+)%", line)
        if recorder_pid and progress and float(progress.group(1)) >= at_percent:
            os.kill(recorder_pid, signal.SIGKILL)
            recorder_pid = 0
    return proc.wait(), "".join(lines)


CASES: dict[str, Callable[[Path], list[tuple[str, str, str]]]] = {
    "corrupt_chunk": case_corrupt_chunk, "cut_bag": case_cut_bag, "cut_c3d": case_cut_c3d, "markers": case_markers,
    "empty_and_wrong_type": case_empty_and_wrong_type, "identification": case_identification,
    "second_graph": case_second_graph, "killed_recorder": case_killed_recorder,
}


# --- soak ---------------------------------------------------------------------------------------------------------
def _rss_mb(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def _window(samples: list[tuple[float, float]], first: bool, span_s: float = 60.0) -> list[tuple[float, float]]:
    """The samples of the first (or last) ``span_s`` of a list of (wall time, value)."""
    if not samples:
        return []
    edge = samples[0][0] + span_s if first else samples[-1][0] - span_s
    return [s for s in samples if (s[0] <= edge if first else s[0] >= edge)]


def _each_minute(samples: list[tuple[float, float]]) -> list[float]:
    """The last value of each minute of a list of (wall time, value): a leak climbs steadily, a high-water mark
    (allocator pools, DDS queues after a burst) steps up and stays."""
    if not samples:
        return []
    t0 = samples[0][0]
    last: dict[int, float] = {}
    for t, v in samples:
        last[int((t - t0) // 60.0)] = v
    return [round(last[k], 1) for k in sorted(last)]


def _rate(samples: list[tuple[float, float]]) -> float:
    return (samples[-1][1] - samples[0][1]) / max(samples[-1][0] - samples[0][0], 1e-9) if len(samples) > 1 else 0.0


class _StatusWatch:
    """The driver's simulated time against this process's monotonic clock (from /robot/status, 10 Hz)."""

    def __init__(self) -> None:
        rclpy.init()
        self.rclpy, self.node = rclpy, rclpy.create_node("bench_soak")
        self.samples: list[tuple[float, float]] = []
        self.node.create_subscription(DiagnosticStatus, "/robot/status", self._on_status, 100)

    def _on_status(self, msg) -> None:
        values = {kv.key: kv.value for kv in msg.values}
        self.samples.append((time.monotonic(), float(values["sim_time_s"])))

    def spin(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.rclpy.spin_once(self.node, timeout_sec=0.1)

    def close(self) -> None:
        self.node.destroy_node()
        self.rclpy.try_shutdown()


def _run_graph(minutes: float, out: Path, domain: int) -> tuple[int, str, dict[str, list], list]:
    """``sit2stand launch robot_seated`` for ``minutes``: its exit code and output, each node's VmRSS every 5 s and
    the driver's (wall, simulated) times."""
    os.environ.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.Popen([sys.executable, "-m", "sit2stand.cli", "launch", "robot_seated", f"out:={out}",
                             "--timeout", f"{minutes * 60.0 + 1.0:g}"], env=_env(domain), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, cwd=project_folder())
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
    reader.start()
    watch, pids, rss = _StatusWatch(), {}, {}
    next_sample = time.monotonic()
    while proc.poll() is None:
        watch.spin(0.5)
        pids.update({m.group(1): int(m.group(2)) for m in re.finditer(r"started (\w+) \(pid (\d+)\)", "".join(lines))})
        if time.monotonic() >= next_sample:
            for name, pid in pids.items():
                rss.setdefault(name, []).append((time.monotonic(), _rss_mb(pid)))
            next_sample += 5.0
    reader.join(10)
    watch.close()
    return proc.returncode, "".join(lines), rss, watch.samples


def _recorder_figures(bag_dir: Path) -> dict[str, object]:
    """Lag of the recorder (log time minus header stamp) in the first and last minute, gaps in the joint states."""
    with BagReader(bag_dir) as bag:
        lost = bag.custom_data.get("lost_messages", "none")
        msgs = [(m.timestamp_ns, cdr_header_stamp_ns(m.data)) for m in bag.messages(["/robot/joint_states"])]
        total = bag.message_count
    log = np.array([t for t, _ in msgs], np.int64)
    stamp = np.array([s for _, s in msgs], np.int64)
    lag_ms = (log - stamp) * 1e-6
    minute = np.searchsorted(stamp, [stamp[0] + 60e9, stamp[-1] - 60e9])
    period = np.median(np.diff(stamp))
    return {"bag_messages": int(total), "recorder_lost_messages": lost,
            "joint_state_stamp_gaps": int(np.sum(np.diff(stamp) > 1.5 * period)),
            "recorder_lag_ms_p50_p99_first_min": _pcts(lag_ms[:minute[0]]),
            "recorder_lag_ms_p50_p99_last_min": _pcts(lag_ms[minute[1]:])}


def _pcts(x: np.ndarray) -> list[float]:
    return [round(float(v), 2) for v in np.percentile(x, [50, 99])] if len(x) else []


def soak(minutes: float, work: Path) -> dict[str, object]:
    """The seated robot and a recorder for ``minutes``; memory, real-time factor, recorder lag, losses."""
    rc, text, rss, status = _run_graph(minutes, work / "soak_bag", 64)
    figures: dict[str, object] = {"minutes": minutes, "launcher_exit": rc}
    for name, samples in rss.items():
        first, last = _window(samples, True), _window(samples, False)
        start, end = np.mean([v for _, v in first]), np.mean([v for _, v in last])
        figures[f"{name}_rss_mb_first_min"], figures[f"{name}_rss_mb_last_min"] = round(start, 1), round(end, 1)
        figures[f"{name}_rss_growth_pct"] = round(100.0 * (end - start) / start, 2)
        figures[f"{name}_rss_mb_each_min"] = _each_minute(samples)
    figures["driver_real_time_factor_first_min"] = round(_rate(_window(status, True)), 3)
    figures["driver_real_time_factor_last_min"] = round(_rate(_window(status, False)), 3)
    figures["launcher_end"] = [ln for ln in text.splitlines() if re.match(r"\[(launch|recorder)", ln)][-8:]
    try:
        figures.update(_recorder_figures(work / "soak_bag"))
    except BagError as err:
        figures["recorder_bag"] = str(err)
    figures["recorder_close"] = next((ln.split("] ", 1)[-1] for ln in text.splitlines() if "closed" in ln), "")
    return figures


# --- main ---------------------------------------------------------------------------------------------------------
FAILED = ("TRACEBACK", "SILENT", "stopped")


def run(only: list[str] | None, soak_min: float, work: Path) -> dict[str, object]:
    rows = []
    for name, case in CASES.items():
        if only and name not in only:
            continue
        t0 = time.monotonic()
        for label, outcome, detail in case(work):
            rows.append({"case": label, "outcome": outcome, "detail": detail, "seconds": round(time.monotonic() - t0)})
            print(f"{label:48s} {outcome:14s} {detail}", flush=True)
    result: dict[str, object] = {"cases": rows, "failures": sum(r["outcome"] in FAILED for r in rows)}
    if soak_min > 0 and (not only or "soak" in only):
        result["soak"] = soak(soak_min, work)
        for key, value in result["soak"].items():
            print(f"soak {key:44s} {value}", flush=True)
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="sit2stand-bench-faults", description=__doc__.split("\n\n")[0])
    parser.add_argument("--soak-min", type=float, default=2.0, help="soak minutes (the target: 30; 0: none)")
    parser.add_argument("--only", default="", help=f"comma-separated cases: {', '.join(CASES)}, soak")
    parser.add_argument("--out", type=Path, default=Path("bench/results/faults.json"))
    args = parser.parse_args(argv)
    only = [c for c in args.only.split(",") if c]
    unknown = set(only) - set(CASES) - {"soak"}
    if unknown:
        parser.error(f"no case {', '.join(sorted(unknown))} (cases: {', '.join(CASES)}, soak)")
    with tempfile.TemporaryDirectory(prefix="sit2stand-faults-") as tmp:
        result = run(only, args.soak_min, Path(tmp))
    write_result(args.out, result, f"make bench-faults SOAK_MIN={args.soak_min:g}")
    print(f"\n{result['failures']} case(s) not clear, flagged or recovered; written to {args.out}")
    return 1 if result["failures"] else 0


if __name__ == "__main__":
    sys.exit(main())
