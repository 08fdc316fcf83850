"""Batches on Ray: each case a task, one table of results, resumable, a failed case recorded and the batch going on.

A *batch* is a list of :class:`Job` (a kind and its inputs, keyed by a name unique in the batch). :func:`run_jobs`
starts Ray on this machine (``ray.init`` with ``workers`` CPUs) or joins a cluster (``address``), runs each job as a
task of one CPU on whichever node has one free, and writes every finished job as one row of ``results.parquet``
(and ``results.csv``) in the batch's folder: the job's inputs, ``status`` (``ok`` or ``failed``), ``attempts``,
``error``, the node and host that ran it, its wall time and the kind's figures. The table is rewritten after each
row, so a batch stopped at any point keeps every finished case; run again, it skips the keys already in the table.

A case that raises, or whose worker dies (killed, out of memory, its node lost), is submitted once more; failing
twice, it is recorded as failed with the error, and the batch goes on. Figures that are lists or mappings are stored
as JSON text (Parquet and CSV columns hold scalars).
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
import ray

from ..errors import InputError

TABLE = "results.parquet"
TABLE_CSV = "results.csv"
ATTEMPTS = 2
"""Tries per case: a case that raises or loses its worker is run once more, then recorded as failed."""
KEY = "key"


@dataclass(frozen=True)
class Job:
    """One case of a batch: its kind, a key unique in the batch, the inputs its row shows, and what runs it:
    ``run(arg, workdir) -> figures`` (a module-level function: Ray sends it to the workers by name, so every node
    needs sit2stand installed)."""

    kind: str
    key: str
    inputs: dict
    run: Callable[[Any, Path], dict]
    arg: Any = None


@ray.remote(num_cpus=1, max_retries=0)
def _run_task(run: Callable[[Any, Path], dict], arg: Any, workdir: str) -> dict:
    """One case in a Ray worker: its figures, the node and host that ran it, its wall time [s]."""
    t0 = time.monotonic()
    figures = run(arg, Path(workdir))
    return {"figures": figures, "node": ray.get_runtime_context().get_node_id()[:12], "host": socket.gethostname(),
            "pid": os.getpid(), "wall_s": round(time.monotonic() - t0, 2)}


def _cell(value):
    """A table cell: scalars as they are, lists and mappings as JSON text."""
    if isinstance(value, dict | list | tuple):
        return json.dumps(value)
    return value


def read_table(out: Path) -> pd.DataFrame:
    """The batch's table so far (empty when it has none)."""
    path = Path(out) / TABLE
    if not path.exists():
        return pd.DataFrame({KEY: pd.Series(dtype=str)})
    try:
        return pd.read_parquet(path)
    except Exception as err:  # noqa: BLE001 - pyarrow raises assorted errors on a damaged file
        raise InputError(f"{path}: not a readable results table ({err}); move it away to start the batch over") \
            from None


def write_table(out: Path, rows: list[dict]) -> pd.DataFrame:
    """Write ``rows`` as ``results.parquet`` and ``results.csv`` (each through a temporary file: a batch killed while
    writing leaves the previous table whole)."""
    out = Path(out)
    table = pd.DataFrame([{k: _cell(v) for k, v in r.items()} for r in rows])
    for name, write in ((TABLE, lambda p: table.to_parquet(p, index=False)),
                        (TABLE_CSV, lambda p: table.to_csv(p, index=False))):
        tmp = out / f".{name}.tmp"
        write(tmp)
        os.replace(tmp, out / name)
    return table


class Progress:
    """One status line on stderr: done of total, failed, elapsed and an estimate of what is left."""

    def __init__(self, total: int, label: str, stream=None) -> None:
        self.total, self.label, self.done, self.failed = total, label, 0, 0
        self.t0 = time.monotonic()
        self.stream = stream or sys.stderr

    def step(self, failed: bool) -> None:
        self.done += 1
        self.failed += failed
        elapsed = time.monotonic() - self.t0
        left = elapsed / self.done * (self.total - self.done)
        width = 30
        bar = "#" * round(width * self.done / max(self.total, 1))
        tty = self.stream.isatty()          # a terminal: one line redrawn; a log: a line per case
        self.stream.write(f"{chr(13) if tty else ''}{self.label} [{bar:<{width}}] {self.done}/{self.total}"
                          f"{f' ({self.failed} failed)' if self.failed else ''} {elapsed:5.0f} s, ~{left:.0f} s left"
                          f"{'' if tty and self.done < self.total else chr(10)}")
        self.stream.flush()


def start_ray(address: str | None, workers: int | None) -> None:
    """Join the cluster at ``address``, or start Ray here with ``workers`` CPUs (default: all)."""
    if ray.is_initialized():
        return
    kwargs = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
    if address:
        ray.init(address=address, **kwargs)
        return
    # a Ray of our own: no metrics export from every worker (nothing reads them without a dashboard) and no usage
    # reports; a cluster started by `ray start` keeps its own settings
    os.environ.setdefault("RAY_enable_metrics_collection", "0")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    ray.init(num_cpus=workers, **kwargs)


def run_jobs(jobs: Iterable[Job], out: Path, address: str | None = None, workers: int | None = None,
             on_row: Callable[[dict], None] | None = None, label: str = "batch", fresh: bool = False,
             in_process: bool | None = None) -> list[dict]:
    """Run the jobs not yet in ``out``'s table (see the module docstring); every row of the table, old and new, in
    the jobs' order. ``on_row`` sees each new row as it is written; ``fresh``: the old table is discarded first.

    ``in_process`` (default: ``workers`` 1 and no ``address``): the cases run one after another in this process,
    without Ray (the same table, retries and rows: a single process to measure Ray's overhead against, and a batch
    to debug)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if fresh:
        for name in (TABLE, TABLE_CSV):
            (out / name).unlink(missing_ok=True)
    jobs = list(jobs)
    keys = [j.key for j in jobs]
    if len(set(keys)) != len(keys):
        raise InputError(f"batch {out}: two cases share a key ({sorted(k for k in keys if keys.count(k) > 1)[0]})")
    old = read_table(out)
    rows = {r[KEY]: r for r in old.to_dict("records")}
    todo = [j for j in jobs if j.key not in rows]
    if len(todo) < len(jobs):
        print(f"{label}: {len(jobs) - len(todo)} of {len(jobs)} cases already in {out / TABLE}", file=sys.stderr)
    if not todo:
        return [rows[k] for k in keys]
    progress = Progress(len(todo), label)
    workdir = out / "cases"
    workdir.mkdir(exist_ok=True)

    def record(job: Job, row: dict) -> None:
        rows[job.key] = row
        write_table(out, [rows[k] for k in keys if k in rows] + [r for k, r in rows.items() if k not in keys])
        progress.step(row["status"] == "failed")
        if on_row is not None:
            on_row(row)

    if in_process if in_process is not None else (workers == 1 and not address):
        for job in todo:
            record(job, _in_process(job, workdir))
        return [rows[k] for k in keys]
    start_ray(address, workers)
    pending = {_run_task.remote(j.run, j.arg, str(workdir)): (j, 1) for j in todo}
    while pending:
        [ref], _ = ray.wait(list(pending), num_returns=1)
        job, attempt = pending.pop(ref)
        try:
            record(job, _row(job, attempt, ray.get(ref)))
        except RAY_FAILURES as err:
            if attempt < ATTEMPTS:           # one more try
                pending[_run_task.remote(job.run, job.arg, str(workdir))] = (job, attempt + 1)
            else:
                record(job, _failed(job, attempt, getattr(err, "cause", None) or err))
    return [rows[k] for k in keys]


RAY_FAILURES = (ray.exceptions.RayTaskError, ray.exceptions.WorkerCrashedError, ray.exceptions.NodeDiedError,
                ray.exceptions.ObjectLostError, ray.exceptions.OutOfMemoryError)
"""What a task's result raises when the case raised or its worker or node died."""


def _in_process(job: Job, workdir: Path) -> dict:
    """A case run here, with the batch's tries."""
    for attempt in range(1, ATTEMPTS + 1):
        t0 = time.monotonic()
        try:
            figures = job.run(job.arg, workdir)
        except Exception as err:  # noqa: BLE001 - a case that raises is retried, then recorded as failed
            error = err
            continue
        return _row(job, attempt, {"figures": figures, "node": "local", "host": socket.gethostname(),
                                   "pid": os.getpid(), "wall_s": round(time.monotonic() - t0, 2)})
    return _failed(job, ATTEMPTS, error)


def _row(job: Job, attempt: int, result: dict) -> dict:
    return {KEY: job.key, "kind": job.kind, **job.inputs, "attempts": attempt, "status": "ok", "error": None,
            "node": result["node"], "host": result["host"], "wall_s": result["wall_s"], **result["figures"]}


def _failed(job: Job, attempt: int, err: BaseException) -> dict:
    return {KEY: job.key, "kind": job.kind, **job.inputs, "attempts": attempt, "status": "failed",
            "error": f"{type(err).__name__}: {str(err).strip()[:500]}"}
