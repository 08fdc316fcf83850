"""`sit2stand` sub-commands of bags, graphs and the nodes that play and record them.

Each ``add_*`` function adds one sub-command to the parser (see :mod:`sit2stand.cli`); each handler imports its
stage when it runs, so that ``sit2stand --help`` stays fast (measured in :mod:`sit2stand.cli`'s docstring).
"""

from __future__ import annotations

import argparse
from pathlib import Path


def _bag_info(args: argparse.Namespace) -> int:
    from ..io.bag import BagReader, bag_info

    print(bag_info(args.dir))
    with BagReader(args.dir) as bag:
        for key, value in sorted(bag.custom_data.items()):
            print(f"{key}: {value}")
    return 0


def _bag_merge(args: argparse.Namespace) -> int:
    from ..io.bag import merge_bags

    counts = merge_bags(Path(args.out), [Path(p) for p in args.inputs])
    print(f"wrote {args.out}: {sum(counts.values())} messages on {len(counts)} topics")
    return 0


def _bag_recover(args: argparse.Namespace) -> int:
    from ..io.recover import recover_bag

    print(recover_bag(args.dir, args.out))
    return 0


def _launch(args: argparse.Namespace) -> int:
    from ..launch import LaunchError, Launcher, load_graph, parse_overrides, select_nodes

    graph = load_graph(args.graph, parse_overrides(args.overrides), namespace=args.namespace)
    if args.only or args.host:           # one machine's share of a graph spread over several
        try:
            graph = select_nodes(graph, [n for n in (args.only or "").split(",") if n] or None, args.host)
        except LaunchError:
            graph.discard()
            raise
    return Launcher(graph, grace_s=args.grace).run(timeout_s=args.timeout)


def ros_params(pairs: list[tuple[str, object]]) -> list[str]:
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
    from ..nodes.replayer import main as replayer_main

    return replayer_main(["replayer"] + ros_params([
        ("bag", str(args.dir)), ("rate", float(args.rate)), ("loop", args.loop), ("topics", args.topics or None),
        ("at_end", "idle" if args.idle else "exit"), ("wait_for_subscribers", args.wait_for_subscribers)]))


def _record(args: argparse.Namespace) -> int:
    from ..nodes.recorder import main as recorder_main

    return recorder_main(["recorder"] + ros_params([
        ("output", str(args.out)), ("topics", args.topics or None), ("regex", args.regex or None),
        ("use_sim_time", args.use_sim_time)]))


def add_bag(sub) -> None:
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


def add_launch(sub) -> None:
    p = sub.add_parser("launch", help="start a graph of nodes from a YAML graph file")
    p.add_argument("graph", type=Path, help="graph YAML file, or a packaged graph's name (standup, human_com, "
                   "retarget, robot_seated, roundtrip, identification, live)")
    p.add_argument("overrides", nargs="*", help="NAME:=VALUE for the graph's arguments")
    p.add_argument("--timeout", type=float, help="stop the graph after this many seconds")
    p.add_argument("--grace", type=float, default=10.0, help="seconds between SIGINT and SIGTERM at shutdown")
    p.add_argument("--only", help="start only these nodes (comma-separated names): this machine's share")
    p.add_argument("--host", help="start only the nodes labelled host: HOST in the graph file")
    p.add_argument("--namespace", default="", help="run every node (and so every topic, /clock included) in this "
                   "ROS namespace, e.g. robot2: two graphs side by side on one domain")
    p.set_defaults(func=_launch)


def add_replay(sub) -> None:
    p = sub.add_parser("replay", help="play a bag onto topics (the replayer node)")
    p.add_argument("dir", type=Path)
    p.add_argument("--rate", type=float, default=1.0, help="0.1..50 x real time, 0 = as fast as subscribers take")
    p.add_argument("--loop", action="store_true")
    p.add_argument("--idle", action="store_true", help="stay alive at the end instead of exiting")
    p.add_argument("--topics", nargs="*")
    p.add_argument("--wait-for-subscribers", type=int, default=0)
    p.set_defaults(func=_replay)


def add_record(sub) -> None:
    p = sub.add_parser("record", help="record topics into a bag (the recorder node)")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--topics", nargs="*")
    p.add_argument("--regex")
    p.add_argument("--use-sim-time", action="store_true")
    p.set_defaults(func=_record)
