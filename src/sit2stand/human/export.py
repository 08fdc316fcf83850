"""Plain-table exports of an offline human COM result: CSV for any tool, and an OpenSim Storage (.sto) file.

Written beside the result bag by ``sit2stand human-com`` (:func:`sit2stand.human.offline.run`):

- ``com.csv``: ``t, x, y, z, vx, vy, vz, ax, ay, az, valid`` per marker frame: the COM [m], its velocity [m/s] and
  acceleration [m/s^2] in the lab frame, ``valid`` 1 where the frame's markers were fitted (0: bridged);
- ``joint_angles.csv``: ``t``, the pelvis pose (``pelvis_tx/ty/tz`` [m]; ``pelvis_rz/ry/rx`` [rad], Z-Y-X Euler
  angles of the pelvis in the lab, R = Rz Ry Rx) and every joint angle [rad] of the skeleton
  (:mod:`sit2stand.human.skeleton` names and signs);
- ``human_states.sto``: the same coordinates and the COM position and velocity in OpenSim's Storage format (a
  ``key=value`` header: ``version=1``, ``nRows``, ``nColumns``, ``inDegrees=no``, then ``endheader``, a tab-separated
  row of column labels beginning with ``time``, and one row per frame), which OpenSim's tools and plotters read.

Everything is in sit2stand's lab frame (REP-103: x forward, y left, z up) and SI units, times in seconds on the
bag's clock. The coordinates are sit2stand's skeleton's, not an OpenSim model's: names and signs differ from Gait2392.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

from .com import ComResult

PELVIS_COLUMNS = ["pelvis_tx", "pelvis_ty", "pelvis_tz", "pelvis_rz", "pelvis_ry", "pelvis_rx"]


def pelvis_coordinates(q: np.ndarray) -> np.ndarray:
    """(N, 6) pelvis position [m] and Z-Y-X Euler angles [rad] (rz, ry, rx) from (N, nq) configurations."""
    out = np.zeros((len(q), 6))
    for k, qk in enumerate(q):
        R = pin.Quaternion(np.asarray(qk[3:7], float)).toRotationMatrix()   # (x, y, z, w) as Pinocchio stores it
        roll, pitch, yaw = pin.rpy.matrixToRpy(R)
        out[k] = [qk[0], qk[1], qk[2], yaw, pitch, roll]
    return out


def coordinate_table(result: ComResult, joint_names: list[str]) -> tuple[list[str], np.ndarray]:
    """Column labels and (N, 6 + joints) values of the pelvis pose and joint angles along the result."""
    if result.q is None:
        raise ValueError("the COM result carries no configurations (q) to export")
    values = np.hstack([pelvis_coordinates(result.q), np.asarray(result.q)[:, 7:]])
    return PELVIS_COLUMNS + list(joint_names), values


def _write_csv(path: Path, labels: list[str], rows: np.ndarray) -> None:
    """A comma-separated table with a header row; numbers with 9 significant digits."""
    with open(path, "w") as f:
        f.write(",".join(labels) + "\n")
        for row in rows:
            f.write(",".join(f"{v:.9g}" for v in row) + "\n")


def write_sto(path: Path, name: str, labels: list[str], rows: np.ndarray, description: str = "") -> None:
    """An OpenSim Storage file: ``labels`` begin with ``time``; angles are in radians (``inDegrees=no``)."""
    rows = np.asarray(rows, float)
    header = [name, "version=1", f"nRows={rows.shape[0]}", f"nColumns={rows.shape[1]}", "inDegrees=no"]
    if description:
        header.append(description)
    with open(path, "w") as f:
        f.write("\n".join(header + ["endheader", "\t".join(labels)]) + "\n")
        for row in rows:
            f.write("\t".join(f"{v:.10g}" for v in row) + "\n")


def write_exports(result: ComResult, out_dir: Path, joint_names: list[str]) -> list[Path]:
    """Write ``com.csv``, ``joint_angles.csv`` and ``human_states.sto`` into ``out_dir``; returns their paths."""
    out_dir = Path(out_dir)
    t = np.asarray(result.t_s, float)[:, None]
    com = np.hstack([t, result.com_m, result.com_vel, result.com_acc, np.asarray(result.fit_ok, float)[:, None]])
    paths = [out_dir / "com.csv", out_dir / "joint_angles.csv", out_dir / "human_states.sto"]
    _write_csv(paths[0], ["t", "x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az", "valid"], com)
    labels, coords = coordinate_table(result, joint_names)
    _write_csv(paths[1], ["t"] + labels, np.hstack([t, coords]))
    com_labels = ["com_x", "com_y", "com_z", "com_vx", "com_vy", "com_vz"]
    write_sto(paths[2], "human_states", ["time"] + labels + com_labels,
              np.hstack([t, coords, result.com_m, result.com_vel]),
              "sit2stand human COM: lab frame REP-103 (x forward, y left, z up), SI units, angles in radians")
    return paths
