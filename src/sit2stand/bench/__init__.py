"""Benchmarks (not tests): figures and ratios, printed and written to JSON (``make bench-*``).

``python -m sit2stand.bench`` runs :mod:`~sit2stand.bench.speed` (``make bench``); the others run as
``python -m sit2stand.bench.<name>``. They read the project's shipped data (``bags/``, ``runs/demo`` after ``make
demo``) from the project folder, :func:`project_folder`: the working directory, where the ``make`` targets run them.
"""

from __future__ import annotations

import os
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
