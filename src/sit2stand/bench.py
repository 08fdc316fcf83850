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
import time
from pathlib import Path

import numpy as np

from .io import messages as M
from .io.bag import BagReader, BagWriter


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
        bag.add_topic(M.plate_topic("feet"), M.PLATE_TYPE)
        bag.add_topic(M.MARKERS_TOPIC, M.MOCAP_TYPE)
        t1 = time.perf_counter()
        for i, msg in enumerate(plates):
            bag.write(M.plate_topic("feet"), i * 500_000, msg)
        t2 = time.perf_counter()
        for i, msg in enumerate(frames):
            bag.write(M.MARKERS_TOPIC, i * 10_000_000, msg)
        t3 = time.perf_counter()
    t4 = time.perf_counter()
    return {"write_plate_msg_per_s": _rate(len(plates), t2 - t1), "write_mocap40_msg_per_s": _rate(len(frames), t3 - t2),
            "write_total_msg_per_s": _rate(n, t4 - t0), "bag_size_mb": sum(p.stat().st_size for p in path.iterdir()) / 1e6}


def bench_read(path: Path) -> dict[str, float]:
    from rosbags.rosbag2 import Reader

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
                                f"output:={record_to}", "-p", "regex:=^/(mocap|force)", "-p", "discovery_period_s:=0.1"],
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="sit2stand-bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results/bench.json"))
    parser.add_argument("--messages", type=int, default=40_000)
    args = parser.parse_args(argv)

    results: dict[str, object] = {"machine": {"python": sys.version.split()[0], "cpu_count": os.cpu_count(),
                                              "platform": platform.platform()}}
    env = dict(os.environ, ROS_DOMAIN_ID=os.environ.get("ROS_DOMAIN_ID", "91"),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
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
                               "into_recorder_msg_per_s": into_recorder, "into_recorder_vs_bare_read": into_recorder / bare}

    width = max(len(k) for section in ("bag", "replayer") for k in results[section])
    for section in ("bag", "replayer"):
        print(f"\n[{section}]")
        for key, value in results[section].items():
            print(f"  {key:<{width}}  {value:>12,.2f}" if isinstance(value, float) else f"  {key:<{width}}  {value:>12}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2))
    print(f"\nwritten to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
