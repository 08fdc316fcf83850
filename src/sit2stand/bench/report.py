"""`make results`: the generated tables of ``docs/results.md``, rewritten from the benchmarks' JSON.

    python -m sit2stand.bench.report [--results bench/results] [--doc docs/results.md]

A generated table sits between ``<!-- generated: NAME -->`` and ``<!-- end: NAME -->`` in the document; this
rewrites what is between from NAME's JSON (its figures and the date, commit and command that made them, which every
benchmark stamps: :func:`sit2stand.bench.write_result`) and leaves the rest of the document as it is. A table whose
JSON is not there (its benchmark not run on this machine) is left as it was, and said.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable
from pathlib import Path


def _stamp(measured: dict | None) -> str:
    if not measured:
        return "Not stamped (made before benchmarks carried their provenance)."
    return (f"{measured['date']}, code at {measured['commit']}, `{measured['command']}` ({measured['host']}).")


def _table(header: list[str], rows: list[list]) -> list[str]:
    return ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |",
            *("| " + " | ".join(str(c) for c in row) + " |" for row in rows)]


def ik(doc: dict) -> list[str]:
    """`make bench-ik`: per-frame IK against mink and pink."""
    lines = [_stamp(doc.get("measured")), "",
             f"{doc['frames']} frames of `{Path(doc['bag']).name}` ({doc['robot']}): time per frame, its ratio to "
             f"ours (theirs / ours), marker cost against ours (median), largest COM residual. Interleaved: each "
             f"frame by every solver in turn; blocked: each solver over all frames.",
             ""]
    rows = []
    for mode, solvers in doc["modes"].items():
        for name, s in solvers.items():
            rows.append([mode.replace("_", " "), name, f"{s['ms_p50']:.3f}", f"{s['ms_p99']:.3f}",
                         f"{s['ratio_p50']:.2f}", f"{s['ratio_p99']:.2f}", f"{s['marker_cost_rel_p50']:+.4f}",
                         f"{s['com_error_max_mm']:.3f}"])
    return lines + _table(["mode", "solver", "p50 ms", "p99 ms", "x ours p50", "x ours p99", "marker cost vs ours",
                           "COM residual max mm"], rows)


def live(docs: list[dict]) -> list[str]:
    """`make bench-live` (and its other protocols and rates): capture -> markers, COM, joint command, pooled over
    each setting's runs; one row per setting, each with its stamp."""
    rows, stamps = [], []
    for doc in docs:
        s = doc["summary"]
        target = s.get("command_p99_target_ms", 10.0)
        stamps.append(f"- {doc['protocol']} at {doc['marker_rate_hz']:g} Hz: {_stamp(doc.get('measured'))}")
        rows.append([doc["protocol"], f"{doc['marker_rate_hz']:g} Hz", f"{s['stood_up']:.0f} of {s['runs']:.0f}",
                     f"{s['com_tracking_rms_cm_median']:.2f} cm ({s['com_tracking_rms_cm_max']:.2f})",
                     f"{s['capture_to_markers_p99_ms_median']:.2f} ms ({s['capture_to_markers_p99_ms_max']:.2f})",
                     f"{s['capture_to_human_com_p99_ms_median']:.2f} ms ({s['capture_to_human_com_p99_ms_max']:.2f})",
                     f"{s['capture_to_command_p50_ms_median']:.2f} ms",
                     f"{s['capture_to_command_p99_ms_median']:.2f} ms ({s['capture_to_command_p99_ms_max']:.2f})",
                     f"{s['runs_command_p99_within_target']:.0f} of {s['runs']:.0f} within {target:g} ms"])
    return stamps + [""] + _table(
        ["protocol", "capture", "stood", "COM tracking, median (max)", "-> markers p99, median (max)",
         "-> /human/com p99, median (max)", "-> joint command p50, median", "-> joint command p99, median (max)",
         "command target"], rows)


def _figures(section: dict, labels: dict[str, str]) -> list[str]:
    return [_stamp(section.get("measured")), ""] + _table(
        ["figure", "value"], [[label, f"{section[key]:.3g}"] for key, label in labels.items() if key in section])


def driver(doc: dict) -> list[str]:
    """`make bench-driver`: the plant's step and the driver node's real-time factor."""
    return _figures(doc["driver"], {
        "bare_mj_step_none_us": "bare `mj_step` of TALOS on its chair [us]",
        "plant_step_none_us": "plant step, joint PD [us]", "plant_step_none_vs_bare": "... over a bare mj_step",
        "plant_step_gravity_us": "plant step, joint PD + gravity feed-forward at 200 Hz [us]",
        "plant_step_gravity_vs_bare": "... over a bare mj_step",
        "plant_step_wbc_us": "plant step, whole-body torque control (QP at 500 Hz) [us]",
        "plant_step_wbc_vs_bare": "... over a bare mj_step",
        "driver_node_rtf_joint_pd": "driver node as fast as it can, 500 Hz states, joint PD [x real time]",
        "driver_node_rtf_wbc": "driver node as fast as it can, 500 Hz states, whole-body torque control [x real time]"})


def estimator(doc: dict) -> list[str]:
    """`make bench-estimator`: the streaming human COM estimator's cost per frame."""
    return _figures(doc["human_com"], {
        "stream_cost_p50_ms": "streaming estimator per frame, no ROS, p50 [ms]",
        "stream_cost_p99_ms": "streaming estimator per frame, no ROS, p99 [ms]",
        "node_cost_p50_ms": "`human_com` node in a real-time graph (replayer, node, recorder), p50 [ms]",
        "node_cost_p99_ms": "`human_com` node in a real-time graph (replayer, node, recorder), p99 [ms]",
        "offline_frames_per_s": "offline estimator [frames/s]"})


RENDER: dict[str, tuple[str, Callable]] = {
    "ik": ("ik.json", ik), "live": ("live*.json", live), "driver": ("bench.json", driver),
    "estimator": ("bench.json", estimator)}
"""Each generated table: its JSON under the results folder (a pattern: every match, in name order, to one table)
and how it is written."""


def rewrite(text: str, results: Path) -> tuple[str, list[str]]:
    """``text`` with every generated table rewritten from its JSON; and the tables left as they were, and why."""
    kept = []

    def block(match: re.Match) -> str:
        name = match.group(1)
        if name not in RENDER:
            kept.append(f"{name}: no such table")
            return match.group(0)
        pattern, render = RENDER[name]
        paths = sorted(results.glob(pattern))
        try:
            if not paths:
                raise FileNotFoundError(f"no {pattern}")
            docs = [json.loads(p.read_text()) for p in paths]
            lines = render(docs if "*" in pattern else docs[0])
        except (OSError, KeyError, ValueError) as err:
            kept.append(f"{name}: {results / pattern}: {type(err).__name__} {err}")
            return match.group(0)
        return f"<!-- generated: {name} -->\n" + "\n".join(lines) + f"\n<!-- end: {name} -->"

    out = re.sub(r"<!-- generated: (\w+) -->\n.*?<!-- end: \1 -->", block, text, flags=re.S)
    return out, kept


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=Path("bench/results"))
    parser.add_argument("--doc", type=Path, default=Path("docs/results.md"))
    args = parser.parse_args(argv)
    text, kept = rewrite(args.doc.read_text(), args.results)
    args.doc.write_text(text)
    for line in kept:
        print(f"left as it was: {line}")
    print(f"wrote {args.doc}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
