"""The human and the robot compared as a person would compare them: each at the same share of its own rise.

* :func:`flexion_deg`: sagittal flexions (trunk on the pelvis, hip, knee, ankle dorsiflexion) from joint angles, by
  the shared definitions (``skeleton.SAGITTAL_FLEXION``, ``RobotProfile.sagittal_flexion``);
* :func:`rise_window`, :func:`posture_rms_deg`: the rise of each body (its COM's 5 % to 95 % of the way up) and the
  RMS of robot minus human flexion over it;
* :func:`matched_times`: the human's instant matched to a robot instant (the frames figure);
* :func:`cycle_rows`: one row per sit-stand-sit cycle, the human's and the robot's.

Units: s, m, deg.
"""

from __future__ import annotations

import numpy as np

from ..human.cycles import find_cycles

RISE_WINDOW = (0.05, 0.95)
"""A rise, for comparing postures, runs from the COM's first 5 % to its 95 % of the way up (from its lowest point
before its highest to its highest), each body's own: the two bodies compared at the same share of their rise."""
POSTURE_SAMPLES = 51


def flexion_deg(names: list[str], q: np.ndarray, groups: dict[str, tuple[tuple[str, ...], float]]
                ) -> dict[str, np.ndarray]:
    """(N,) flexion [deg] of each group present in ``names`` (the mean of its joints, times its sign) from joint
    angles ``q`` (N, len(names)) [rad]: ``SAGITTAL_FLEXION`` for the human, ``profile.sagittal_flexion()`` for a
    robot."""
    out = {}
    for label, (joints, sign) in groups.items():
        cols = [names.index(j) for j in joints if j in names]
        if cols:
            out[label] = sign * np.degrees(np.asarray(q, float)[:, cols].mean(axis=1))
    return out


def cycle_rows(human_t_s: np.ndarray, human_pelvis_z_m: np.ndarray, robot_t_s: np.ndarray,
               robot_pelvis_z_m: np.ndarray) -> list[dict]:
    """One row per sit-stand-sit cycle of the human (:func:`~sit2stand.human.cycles.find_cycles`): the human's and
    the simulated robot's rise and sit-down durations [s] (seated to standing, standing to seated), and whether the
    robot stood and sat in that cycle (its own k-th cycle reached standing, and seated again)."""
    robot = find_cycles(robot_t_s, robot_pelvis_z_m)
    rows = []
    for k, h in enumerate(find_cycles(human_t_s, human_pelvis_z_m)):
        r = robot[k] if k < len(robot) else None
        rows.append({"cycle": k + 1, "human_rise_s": h.rise_s, "human_sit_s": h.sit_s,
                     "robot_rise_s": None if r is None else r.rise_s, "robot_sit_s": None if r is None else r.sit_s,
                     "stood": r is not None, "sat": r is not None and r.seated_s is not None})
    return rows


def rise_window(t: np.ndarray, com_z: np.ndarray) -> tuple[float, float] | None:
    """Start and end [s] of a rise (:data:`RISE_WINDOW`) from COM heights; None when the COM does not rise."""
    top = int(np.nanargmax(com_z))
    low = int(np.nanargmin(com_z[:top + 1]))
    span = com_z[top] - com_z[low]
    if not span > 0.05:
        return None
    share = (com_z[low:top + 1] - com_z[low]) / span
    start = low + int(np.argmax(share >= RISE_WINDOW[0]))
    end = low + int(np.argmax(share >= RISE_WINDOW[1]))
    return float(t[start]), float(t[end])


def posture_rms_deg(human: tuple[np.ndarray, np.ndarray, dict], robot: tuple[np.ndarray, np.ndarray, dict]
                    ) -> dict[str, float] | None:
    """RMS [deg] of robot minus human sagittal flexion over the rise, per joint, each body's rise normalised to
    :data:`POSTURE_SAMPLES` instants (the robot's rise may last longer: its shape is what is compared). ``human``,
    ``robot``: (times [s], COM heights [m] at them, label -> flexion [deg] at them). None when either does not
    rise."""
    windows = [rise_window(t, z) for t, z, _ in (human, robot)]
    if None in windows:
        return None
    phase = np.linspace(0.0, 1.0, POSTURE_SAMPLES)
    on = [(lo + phase * (hi - lo)) for lo, hi in windows]
    out = {}
    for label in human[2].keys() & robot[2].keys():
        h = np.interp(on[0], human[0], human[2][label])
        r = np.interp(on[1], robot[0], robot[2][label])
        out[label] = float(np.sqrt(np.mean((r - h) ** 2)))
    return {k: out[k] for k in ("trunk", "hip", "knee", "ankle") if k in out}


def matched_times(robot: tuple[np.ndarray, np.ndarray], human: tuple[np.ndarray, np.ndarray],
                  robot_t_s: np.ndarray) -> np.ndarray:
    """The human's time [s] matched to each of ``robot_t_s``: at the same share of each body's own rise
    (:func:`rise_window`), one second for one second before and after it, within the human's recording. ``robot``,
    ``human``: (times [s], COM heights [m]), each on its own clock. Without a rise on either side, the same offset
    from each one's start."""
    (tr, zr), (th, zh) = robot, human
    wr, wh = rise_window(tr, zr), rise_window(th, zh)
    t = np.asarray(robot_t_s, float)
    if wr is None or wh is None:
        out = th[0] + (t - tr[0])
    else:
        rate = (wh[1] - wh[0]) / (wr[1] - wr[0])
        out = np.where(t < wr[0], wh[0] + (t - wr[0]),
                       np.where(t > wr[1], wh[1] + (t - wr[1]), wh[0] + (t - wr[0]) * rate))
    return np.clip(out, th[0], th[-1])
