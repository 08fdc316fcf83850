"""`make demo`: the main job on a demonstration, end to end through real nodes, into a run directory.

At this stage of the project (foundation) the job is: a lab recording -> bag -> replayer node -> DDS -> recorder node
-> bag, checked message by message, with a figure of what was recorded. The demonstration is the real sit-to-stand
recording ``../shared/data/real/sts_child_vicon_01.c3d`` (read in place, never copied into the project) until the
shipped digital-human demonstrations arrive in ``bags/``.

    python -m sit2stand.demo --out runs/demo [--c3d FILE] [--rate 1.0]

Writes ``OUT/imported`` (bag), ``OUT/recorded`` (bag), ``OUT/summary.json`` and ``OUT/demo.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from .io import messages as M
from .io.bag import BagReader, bag_info
from .io.c3d import read_c3d, write_trial_bag

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_C3D = ROOT.parent / "shared" / "data" / "real" / "sts_child_vicon_01.c3d"


def compare_bags(original: Path, recorded: Path) -> dict[str, dict[str, int]]:
    """Per topic: messages in each bag and how many recorded messages differ from the original (by value)."""
    out = {}
    with BagReader(original) as a, BagReader(recorded) as b:
        rec_topics = b.topics()
        for topic in sorted(a.topics()):
            xs = a.read(topic)
            ys = b.read(topic) if topic in rec_topics else []
            differ = sum(1 for (_, x), (_, y) in zip(xs, ys) if repr(x).replace("nan", "N") != repr(y).replace("nan", "N"))
            out[topic] = {"original": len(xs), "recorded": len(ys), "differ": differ + abs(len(xs) - len(ys))}
    return out


def figure(bag: Path, png: Path) -> None:
    """Vertical force and COP of each plate, and pelvis-marker height, against time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with BagReader(bag) as b:
        topics = b.topics()
        plates = {t: b.read(t) for t in topics if t.startswith(M.FORCE_PLATE_PREFIX)}
        frames = b.read(M.MARKERS_TOPIC)
    t0 = frames[0][0]
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for topic, msgs in plates.items():
        arr = M.plate_arrays([m for _, m in msgs])
        t = (np.array([ts for ts, _ in msgs]) - t0) * 1e-9
        axes[0].plot(t, arr["force_n"][:, 2], label=topic)
        axes[1].plot(t, arr["cop_m"][:, 0], label=f"{topic} COP x (forward)")
        axes[1].plot(t, arr["cop_m"][:, 1], "--", label=f"{topic} COP y (left)")
    names, _, _ = M.mocap_arrays(frames[0][1])
    pelvis = [i for i, n in enumerate(names) if n in ("LASI", "RASI", "LPSI", "RPSI")]
    if pelvis:
        z = np.array([np.nanmean(M.mocap_arrays(m)[1][pelvis, 2]) for _, m in frames])
        axes[2].plot((np.array([ts for ts, _ in frames]) - t0) * 1e-9, z, label="pelvis markers mean height")
    axes[0].set_ylabel("vertical force [N]")
    axes[1].set_ylabel("COP [m] (lab frame)")
    axes[2].set_ylabel("height [m]")
    axes[2].set_xlabel("time since first frame [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    fig.suptitle(f"Recorded through replayer -> DDS -> recorder: {bag.parent.name}")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="sit2stand-demo", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("runs/demo"))
    parser.add_argument("--c3d", type=Path, default=DEFAULT_C3D)
    parser.add_argument("--rate", type=float, default=1.0)
    args = parser.parse_args(argv)
    if not args.c3d.is_file():
        print(f"sit2stand demo: error: demonstration {args.c3d} not found (the real recordings live in "
              f"../shared/data/real beside the project)", file=sys.stderr)
        return 2
    if args.out.exists():
        shutil.rmtree(args.out)
    args.out.mkdir(parents=True)
    imported, recorded = args.out / "imported", args.out / "recorded"

    print(f"[1/3] import {args.c3d}", flush=True)
    trial = read_c3d(args.c3d, feet_plate=2 if args.c3d == DEFAULT_C3D else None)
    write_trial_bag(trial, imported)
    print(bag_info(imported), flush=True)

    print(f"\n[2/3] replay at {args.rate:g}x through DDS into the recorder (sit2stand launch)", flush=True)
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    t0 = time.monotonic()
    code = subprocess.call([sys.executable, "-m", "sit2stand.cli", "launch", str(ROOT / "ros_ws/graphs/roundtrip.yaml"),
                            f"bag:={imported.resolve()}", f"out:={recorded.resolve()}", f"rate:={args.rate}"], env=env)
    wall = time.monotonic() - t0
    if code != 0:
        print(f"sit2stand demo: error: the graph exited with code {code}", file=sys.stderr)
        return 1

    print("\n[3/3] compare and plot", flush=True)
    comparison = compare_bags(imported, recorded)
    figure(recorded, args.out / "demo.png")
    summary = {"demonstration": str(args.c3d), "lab_axes": trial.axes.reason, "graph_wall_s": round(wall, 3),
               "topics": comparison, "identical": all(v["differ"] == 0 for v in comparison.values())}
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2))
    for topic, v in comparison.items():
        print(f"  {topic:<28} original {v['original']:>6}  recorded {v['recorded']:>6}  differing {v['differ']}")
    print(f"\n{'identical' if summary['identical'] else 'DIFFERENT'}; wrote {args.out}/summary.json and demo.png")
    return 0 if summary["identical"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
