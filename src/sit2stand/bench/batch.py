"""Benchmark (not a test): what Ray costs and gives a stand-up batch (make bench-batch).

    python -m sit2stand.bench.batch [--cases 40] [--robot g1] [--out bench/results/batch.json]

The same population (:func:`sit2stand.batch.standup.sample_population`, seed 0; CAD parameters, so that nothing
depends on ``make demo``) is run three times through :func:`sit2stand.batch.engine.run_jobs`: in this process (no
Ray), on Ray with one worker, and on Ray with two. Per run: wall time from the first case submitted to the last row
written (the workers' start included, Ray's own not), cases per minute, and the ratios against their targets:
throughput per worker against the single process (target: within 10 %), and two workers against one (target: at
least 1.8x). The host's CPU count bounds the second: two workers on two cores share them with the driver and Ray's
own processes.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import ray

from . import write_result
from ..batch.engine import run_jobs, start_ray
from ..batch.standup import Setting, sample_population, standup_jobs



def timed_batch(cases: int, robot: str, workers: int, on_ray: bool) -> dict:
    """One run of the population on ``workers`` Ray workers, or in this process; its wall time and throughput."""
    jobs = standup_jobs([(c, Setting(robot=robot)) for c in sample_population(cases, seed=0)])
    with tempfile.TemporaryDirectory(prefix="sit2stand-bench-batch-") as tmp:
        t0 = time.monotonic()
        rows = run_jobs(jobs, Path(tmp), workers=workers, in_process=not on_ray,
                        label=f"Ray, {workers} worker(s)" if on_ray else "one process")
        wall = time.monotonic() - t0
    if ray.is_initialized():
        ray.shutdown()
    ok = sum(r["status"] == "ok" for r in rows)
    return {"workers": workers, "ray": on_ray, "cases": len(rows), "ok": ok, "wall_s": round(wall, 1),
            "cases_per_min": round(60 * len(rows) / wall, 2),
            "case_wall_s_median": float(sorted(r.get("wall_s") or 0 for r in rows)[len(rows) // 2])}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="sit2stand-bench-batch", description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=40)
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--out", type=Path, default=Path("bench") / "results" / "batch.json")
    args = parser.parse_args(argv)
    single = timed_batch(args.cases, args.robot, 1, on_ray=False)
    print(f"single process: {single}", flush=True)
    one = _on_ray(args.cases, args.robot, 1)
    print(f"Ray, 1 worker: {one}", flush=True)
    two = _on_ray(args.cases, args.robot, 2)
    print(f"Ray, 2 workers: {two}", flush=True)
    doc = {"robot": args.robot, "cases": args.cases, "cpus": os.cpu_count(), "single_process": single,
           "ray_1_worker": one, "ray_2_workers": two,
           "per_worker_vs_single": round(one["cases_per_min"] / single["cases_per_min"], 3),
           "two_vs_one_worker": round(two["cases_per_min"] / one["cases_per_min"], 3)}
    print(f"throughput per Ray worker / single process: {doc['per_worker_vs_single']:.3f} (target >= 0.9); "
          f"2 workers / 1: {doc['two_vs_one_worker']:.2f}x (target >= 1.8)")
    write_result(args.out, doc, f"make bench-batch BATCH_CASES={args.cases}")
    return 0


def _on_ray(cases: int, robot: str, workers: int) -> dict:
    """The population on a Ray of ``workers`` CPUs started here as ``sit2stand batch`` starts it; Ray's own start
    (~2 s) is not counted, its workers' (they start and import the stack with their first case) is."""
    start_ray(None, workers)
    return timed_batch(cases, robot, workers, on_ray=True)


if __name__ == "__main__":
    sys.exit(main())
