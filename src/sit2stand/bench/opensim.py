"""OpenSim's scaled Gait2392 COM for `make bench-human`, from a venv of its own (never sit2stand's).

PyPI ``opensim`` 4.6 (~400 MB, Python 3.11) goes into ``.venv-opensim/`` beside ``.venv/`` the first time it is
needed; ``bench/opensim_gait2392.py`` runs there (scale on the static trial, IK, the model's COM per frame) and writes
a CSV, read back here and turned into the lab frame. The generic model and its scale set-up are not on PyPI: they come
from a checkout of github.com/opensim-org/opensim-models named by ``SIT2STAND_OPENSIM_MODELS``. When something is
missing the result says what, in one line, and the bench goes on without OpenSim's row.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from . import own_venv, project_folder, run_command
from ..io.trc import OPENSIM_AXES



def _venv() -> Path:
    """OpenSim's own environment (make bench-human makes it)."""
    return project_folder() / ".venv-opensim"


def _worker() -> Path:
    return project_folder() / "bench" / "opensim_gait2392.py"
MODELS_ENV = "SIT2STAND_OPENSIM_MODELS"
REQUIREMENT = "opensim==4.6"
GENERIC = Path("Models/Gait2392_Simbody/gait2392_thelen2003muscle.osim")


def models_dir() -> tuple[Path | None, str]:
    """The opensim-models checkout, or None and why not."""
    folder = os.environ.get(MODELS_ENV, "")
    if not folder:
        return None, (f"set {MODELS_ENV} to a checkout of github.com/opensim-org/opensim-models (the Gait2392 model "
                      f"and its scale set-up are not on PyPI)")
    if not (Path(folder) / GENERIC).is_file():
        return None, f"{MODELS_ENV}={folder}: no {GENERIC} there"
    return Path(folder), ""


def opensim_python() -> tuple[Path | None, str]:
    """The Python of ``.venv-opensim`` with ``opensim`` importable (~400 MB), made on demand; or None and why not."""
    return own_venv(_venv(), [REQUIREMENT], ready=["-c", "import opensim"])


def read_worker_csv(path: Path) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """(t [s], COM (N, 3) in the lab frame [m], the worker's figures) from the worker's CSV (OpenSim's axes)."""
    lines = path.read_text().splitlines()
    figures = dict(item.split("=") for item in lines[-1].lstrip("# ").split())
    rows = np.array([line.split(",") for line in lines[1:-1]], float)
    return rows[:, 0], rows[:, 1:4] @ OPENSIM_AXES.rotation().T, {k: float(v) for k, v in figures.items()}


def opensim_com(static: Path, trial: Path, mass_kg: float, height_m: float,
                t_s: np.ndarray) -> tuple[np.ndarray | None, dict]:
    """OpenSim's COM of ``trial`` at ``t_s`` [s] in the lab frame (N, 3) [m], with the model scaled on ``static``
    for a ``mass_kg``, ``height_m`` subject; and what to report (IK marker RMS, time per frame, or why skipped)."""
    models, why = models_dir()
    python, why = opensim_python() if models is not None else (None, why)
    if python is None:
        return None, {"skipped": why}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "com.csv"
        done = run_command([str(python), str(_worker()), str(models), str(static), str(trial), f"{mass_kg:.6g}",
                     f"{height_m:.6g}", str(out)], timeout_s=600, cwd=tmp)   # OpenSim logs into its cwd
        if done.returncode != 0 or not out.is_file():
            tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
            return None, {"skipped": f"{_worker().name} failed: {tail[0][:160]}"}
        t, com, figures = read_worker_csv(out)
    at = np.stack([np.interp(t_s, t, com[:, i]) for i in range(3)], axis=1)
    return at, {"ik_marker_rms_mm": round(figures["marker_rms_m"] * 1e3, 1),
                "ik_ms_per_frame": round(figures["ik_s_per_frame"] * 1e3, 1)}
