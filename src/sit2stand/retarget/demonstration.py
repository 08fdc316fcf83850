"""What one seated calibration frame fixes for a whole demonstration (:meth:`Retargeter.calibrate
<sit2stand.retarget.stream.Retargeter.calibrate>`): the forward COM map (:class:`ComMap`), the marker tasks
(:class:`MarkerTasks`) and the human as it sat (:class:`HumanSeated`); and what the retargeter follows frame by frame
of the human (:class:`HumanWatch`) and of the robot's own seat-off (:class:`RobotSeatOff`).

Units SI; lab and world frames REP-103 (x forward, y left, z up).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .calibration import MarkerMap


@dataclass(frozen=True)
class ComMap:
    """The forward COM map (Mistry et al. 2010 map the COM relative to the left foot): the human COM's x relative to
    its left ankle, scaled by the leg-length ratio ``scale`` (robot / human), through a monotone (non-decreasing)
    piecewise-linear map with knots ``knots_h`` -> ``knots_r`` (seated COM, heel, ankle) to the robot's x relative to
    its left ankle [m]; one to one beyond the ankle."""

    scale: float
    human_ankle_x_m: float
    robot_ankle_x_m: float
    knots_h: np.ndarray
    knots_r: np.ndarray

    def target_x(self, human_com_x_m: float | np.ndarray, toe_limit_x_m: float) -> np.ndarray:
        """The robot's forward COM target [m] for a human COM x [m], at most ``toe_limit_x_m``."""
        h = self.scale * (np.asarray(human_com_x_m, float) - self.human_ankle_x_m)
        r = np.interp(h, self.knots_h, self.knots_r, left=self.knots_r[0], right=np.nan)
        beyond = h > self.knots_h[-1]
        r = np.where(beyond, self.knots_r[-1] + (h - self.knots_h[-1]), r)
        return np.minimum(self.robot_ankle_x_m + r, toe_limit_x_m)

    @property
    def seat_off_x_m(self) -> float:
        """The robot's seat-off knot [m, world]: its COM must be this far forward before its hips leave the seat."""
        return float(self.robot_ankle_x_m + self.knots_r[1])


@dataclass(frozen=True)
class MarkerTasks:
    """The IK's marker tasks for the stream's markers ``names``: each one's robot frame (``frame_ids``; -1: not on
    the robot, weight 0) and weight; the pelvis markers and the left knee's and ankle's (indices into ``names``);
    and the calibration's similarity, pelvis on pelvis, scaled ``scale`` (x, y, z) about the human's and the robot's
    seated pelvis [m]."""

    marker_map: MarkerMap
    frames: dict[str, int]
    names: list[str]
    weights: np.ndarray
    frame_ids: np.ndarray
    pelvis: list[int]
    knee_ankle: list[list[int]]
    scale: np.ndarray
    human_pelvis0_m: np.ndarray
    robot_pelvis0_m: np.ndarray

    def targets(self, positions_m: np.ndarray, scale: np.ndarray) -> np.ndarray:
        """(M, 3) the markers' targets on the robot [m, world] for the human's ``positions_m``, scaled ``scale``."""
        return self.robot_pelvis0_m + scale * (positions_m - self.human_pelvis0_m)

    def knee_flexion(self, positions_m: np.ndarray, ok: np.ndarray, pelvis_m: np.ndarray) -> float | None:
        """The human's left knee flexion [rad] (:func:`knee_flexion`)."""
        return knee_flexion(self.knee_ankle, positions_m, ok, pelvis_m)


def knee_flexion(knee_ankle: list[list[int]], positions_m: np.ndarray, ok: np.ndarray,
                 pelvis_m: np.ndarray) -> float | None:
    """The human's left knee flexion [rad] in the sagittal (x-z) plane: the angle between the thigh (pelvis centre ->
    knee) and the shank (knee -> ankle), from the knee's and the ankle's markers (``knee_ankle``: their indices);
    None when a knee or ankle marker is not seen."""
    points = []
    for markers in knee_ankle:
        seen = [i for i in markers if ok[i]]
        if not seen:
            return None
        points.append(positions_m[seen].mean(axis=0))
    thigh, shank = (points[0] - pelvis_m)[[0, 2]], (points[1] - points[0])[[0, 2]]
    turn = np.arctan2(thigh[0] * shank[1] - thigh[1] * shank[0], thigh @ shank)
    return float(-turn)                     # the shank turns back (clockwise seen from the left) as it flexes


@dataclass(frozen=True)
class HumanSeated:
    """The human as the calibration frame saw it: thigh length [m], left knee flexion [rad], seated COM x [m, lab]
    (from the body's proportions when the recording starts after the seat-off: ``started_seated`` False)."""

    thigh_m: float
    knee_flexion_rad: float
    com_x_m: float
    started_seated: bool


@dataclass
class HumanWatch:
    """What the human's markers and chair plate have shown so far: its seat-off, whether the chair was loaded, its
    pelvis's highest rise over its seated height [m] and its last seen pelvis centre [m]."""

    pelvis_last_m: np.ndarray
    seat_off: bool = False
    chair_loaded: bool = False
    rise_peak_m: float = 0.0


@dataclass(frozen=True)
class RobotSeatOff:
    """The robot's seat-off: when [s], its COM's lateral position then [m], and the human pelvis's displacement
    already made then (taken out of the marker targets and given back as the human's pelvis rises, so that the
    robot's pelvis does not lunge) with its height then [m]."""

    t_s: float
    com_y_m: float
    marker_offset_m: np.ndarray
    pelvis_z_m: float
