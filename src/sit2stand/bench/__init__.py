"""Benchmarks (not tests): figures and ratios, printed and written to JSON (``make bench-*``).

``python -m sit2stand.bench`` runs :mod:`~sit2stand.bench.speed` (``make bench``); the others run as
``python -m sit2stand.bench.<name>``. They read the project's shipped data (``bags/``, ``runs/demo`` after ``make
demo``) from the project folder, :func:`project_folder`: the working directory, where the ``make`` targets run them.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

from ..errors import InputError

PROJECT_ENV = "SIT2STAND_PROJECT"
"""Names the project folder when a benchmark runs from elsewhere."""


def project_folder() -> Path:
    """The sit2stand project (the repository: ``bags/``, ``runs/``, ``bench/``): ``$SIT2STAND_PROJECT``, else the
    working directory.

    Raises:
        InputError: that folder has no ``bags/natural`` (not the project).
    """
    root = Path(os.environ.get(PROJECT_ENV) or Path.cwd()).resolve()
    if not (root / "bags" / "natural" / "metadata.yaml").exists():
        raise InputError(f"{root}: not the sit2stand project (no bags/natural): run the benchmark from the "
                         f"repository (make bench-...), or set {PROJECT_ENV}")
    return root


def provenance(command: str) -> dict:
    """When, at which commit and by which command a benchmark's figures were made (each JSON carries it)."""
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=Path.cwd(), timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True,
                               text=True, cwd=Path.cwd(), timeout=10).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        commit, dirty = "", ""
    return {"date": datetime.date.today().isoformat(), "commit": (commit or "unknown") + ("+" if dirty else ""),
            "command": command, "host": f"{platform.machine()}, {os.cpu_count()} CPUs, Python "
                                        f"{platform.python_version()}"}


def write_result(out: Path, result: dict, command: str) -> None:
    """Write a benchmark's ``result`` to ``out`` (JSON) under ``"measured"``: its :func:`provenance`."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"measured": provenance(command), **result}, indent=2) + "\n")
    print(f"wrote {out}")


def run_command(command: list[str], timeout_s: float = 120, cwd: str | None = None) -> subprocess.CompletedProcess:
    """``command`` run with its output captured; a command that cannot start or times out is a failed one."""
    try:
        return subprocess.run(command, capture_output=True, text=True, timeout=timeout_s, cwd=cwd)
    except (OSError, subprocess.TimeoutExpired) as err:
        return subprocess.CompletedProcess(command, 1, "", str(err))


def own_venv(folder: Path, requirements: list[str], ready: list[str] | None = None) -> tuple[Path | None, str]:
    """A venv of a benchmark's own (never sit2stand's) at ``folder`` with ``requirements`` installed, made once and
    kept while the requirements it was made with are these (or, made without that record, while its Python runs
    ``ready``). Its Python, or None and why not."""
    python, stamp = folder / "bin" / "python", folder / "sit2stand-requirements.txt"
    wanted = "\n".join(requirements)
    if python.is_file() and ((stamp.is_file() and stamp.read_text() == wanted) or
                             (not stamp.is_file() and ready and run_command([str(python), *ready]).returncode == 0)):
        return python, ""
    print(f"  installing {', '.join(requirements)} into {folder} (once) ...", flush=True)
    for step in ([sys.executable, "-m", "venv", "--clear", str(folder)],
                 [str(python), "-m", "pip", "install", "-q", *requirements]):
        done = run_command(step, timeout_s=1800)
        if done.returncode != 0:
            last = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
            return None, f"{' '.join(step[:4])} ... failed: {last[0][:160]}"
    stamp.write_text(wanted)
    return python, ""
