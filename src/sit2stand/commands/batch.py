"""``sit2stand batch``: many cases at once on Ray (:mod:`sit2stand.batch.engine`), one results table."""

from __future__ import annotations

import argparse
from pathlib import Path

from .robot import CONTROLLER_CHOICES, DEFAULT_CONTROLLER, DEFAULT_PLAN, PLAN_CHOICES, ROBOT_HELP

KINDS = ("standup", "gap", "gap-human")


def _demo_params(robot: str) -> str | None:
    """``make demo``'s identified parameters of ``robot`` when run from the project that has them, else None."""
    from ..demo import demo_params

    path = demo_params(robot)
    return str(path) if path.exists() else None


def _jobs(args: argparse.Namespace) -> list:
    """The batch's jobs for its kind and options."""
    if args.kind == "standup":
        from ..batch.standup import Setting, grid_cases, sample_population, standup_jobs

        params = None if args.cad else args.params or _demo_params(args.robot)
        print(f"batch standup: robot {args.robot}, plant {args.plant}, controller {args.controller}, parameters "
              f"{params or 'CAD'}, plan {args.plan}")
        setting = Setting(args.robot, args.plant, args.controller, params, args.plan)
        cases = grid_cases(Path(args.grid), args.seed, setting) if args.grid else \
            [(c, setting) for c in sample_population(args.cases, args.seed)]
        return standup_jobs(cases)
    if args.kind == "gap":
        from ..batch.gap import gap_cases, gap_jobs

        return gap_jobs(gap_cases(args.cases, args.cases // 2, robot=args.robot), args.robot)
    from ..batch.gap import draw_cases, gap_human_jobs

    return gap_human_jobs(draw_cases(args.cases, seed=args.seed))


def _batch(args: argparse.Namespace) -> int:
    import pandas as pd

    from ..batch.engine import TABLE, run_jobs
    from ..batch.standup import plot_batch

    if args.grid and args.kind != "standup":
        raise SystemExit("sit2stand batch: --grid is for standup batches")
    out = Path(args.out)
    rows = run_jobs(_jobs(args), out, address=args.address, workers=args.workers, label=f"batch {args.kind}")
    table = pd.DataFrame(rows)
    failed = table[table["status"] == "failed"]
    nodes = table["node"].dropna().value_counts().to_dict() if "node" in table else {}
    print(f"{len(table)} cases in {out / TABLE} (and results.csv): {len(table) - len(failed)} ok, {len(failed)} "
          f"failed; cases per node: {nodes}")
    for _, r in failed.iterrows():
        print(f"  failed {r['key']}: {r['error']}")
    if args.kind == "standup":
        print(f"wrote {plot_batch(table, out / 'batch.png')}")
    return 1 if len(failed) else 0


def add_batch(sub) -> None:
    p = sub.add_parser("batch", help="many cases on Ray (this machine, or a cluster): digital humans stood up by a "
                                     "robot, or the model-gap suites; one results table, resumable")
    p.add_argument("kind", choices=KINDS, help="standup: digital humans retargeted and simulated; gap: hidden-effect "
                                               "plants (per kind); gap-human: the human-side suite (per case)")
    p.add_argument("--out", required=True, help="the batch's folder: results.parquet, results.csv, cases/, batch.png")
    p.add_argument("--cases", type=int, default=30, help="standup: digital humans; gap, gap-human: per kind")
    p.add_argument("--grid", help="standup: a YAML grid of statures, masses, seats, styles, robots, plants instead "
                                  "of a random population (docs/method.md)")
    p.add_argument("--seed", type=int, default=0, help="the population's RNG seed")
    p.add_argument("--robot", default="talos", help=ROBOT_HELP)
    p.add_argument("--plant", default="default", help="standup: the plant (a packaged name or a YAML file)")
    p.add_argument("--controller", choices=CONTROLLER_CHOICES, default=DEFAULT_CONTROLLER)
    p.add_argument("--params", help="standup: identified parameters (default: make demo's, else CAD)")
    p.add_argument("--cad", action="store_true", help="standup: plan and control with the CAD model")
    p.add_argument("--plan", choices=PLAN_CHOICES, default=DEFAULT_PLAN,
                   help="standup: how each case is planned (sit2stand retarget --plan; default whole)")
    p.add_argument("--workers", type=int, help="Ray workers on this machine (default: one per CPU; 1: no Ray, "
                                               "this process)")
    p.add_argument("--address", help="join a Ray cluster (ray start --head on one machine, ray start --address on "
                                     "the others)")
    p.set_defaults(func=_batch)
