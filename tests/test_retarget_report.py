"""sit2stand.retarget.report's posture comparison: sagittal flexions named alike for the human and each robot, rises
found from the COM, and the robot's posture compared with the human's at the same share of each one's rise."""

from fnmatch import fnmatch

import numpy as np
import pytest

from sit2stand.human.skeleton import SAGITTAL_FLEXION
from sit2stand.retarget.compare import flexion_deg, matched_times, posture_rms_deg, rise_window
from sit2stand.retarget.report import strip_indices
from sit2stand.robot.profile import load_profile


def _rise(t0: float, duration: float, t: np.ndarray) -> np.ndarray:
    """A smooth 0 -> 1 over [t0, t0 + duration] (a COM rise's shape)."""
    s = np.clip((t - t0) / duration, 0.0, 1.0)
    return s * s * (3 - 2 * s)


def test_the_human_and_both_robots_name_the_same_flexions_with_flexion_positive():
    assert set(SAGITTAL_FLEXION) == {"trunk", "hip", "knee", "ankle"}
    for robot in ("talos", "g1"):
        groups = load_profile(robot).sagittal_flexion()
        assert set(groups) == set(SAGITTAL_FLEXION)
        names = [j for joints, _ in groups.values() for j in joints]
        seated = load_profile(robot).seated_posture                  # hips and knees flexed, as a seated person's
        q = np.array([[next((v for g, v in seated.items() if fnmatch(n, g)), 0.0) for n in names]])
        angles = flexion_deg(names, q, groups)
        assert angles["hip"][0] > 60 and angles["knee"][0] > 60, (robot, angles)


def test_a_rise_runs_from_5_to_95_percent_of_the_com_going_up():
    t = np.linspace(0.0, 4.0, 401)
    z = 0.6 + 0.35 * _rise(1.0, 2.0, t)
    start, end = rise_window(t, z)
    assert 1.0 < start < 1.5 and 2.5 < end < 3.0
    assert rise_window(t, np.full_like(t, 0.6)) is None, "no rise, no window"


def test_the_same_motion_played_slower_matches_and_a_constant_offset_is_its_rms():
    t_h, t_r = np.linspace(0, 4, 401), np.linspace(0, 8, 801)
    s_h, s_r = _rise(1.0, 1.6, t_h), _rise(2.0, 3.2, t_r)           # the robot: the same rise, twice as long
    human = {"knee": 95 * (1 - s_h), "hip": 80 * (1 - s_h)}
    robot = {"knee": 95 * (1 - s_r), "hip": 80 * (1 - s_r) + 10.0}
    rms = posture_rms_deg((t_h, 0.6 + 0.4 * s_h, human), (t_r, 0.5 + 0.4 * s_r, robot))
    assert rms["knee"] == pytest.approx(0.0, abs=0.5)
    assert rms["hip"] == pytest.approx(10.0, abs=0.5)
    assert posture_rms_deg((t_h, np.full_like(t_h, 0.6), human), (t_r, 0.5 + 0.4 * s_r, robot)) is None


def test_frames_of_a_slower_robot_meet_the_human_at_the_same_share_of_its_rise():
    t_h, t_r = np.linspace(0, 4, 401), np.linspace(10, 18, 801)      # the robot on another clock, twice as slow
    z_h, z_r = 0.6 + 0.4 * _rise(1.0, 1.6, t_h), 0.5 + 0.4 * _rise(12.0, 3.2, t_r)
    (h0, h1), (r0, r1) = rise_window(t_h, z_h), rise_window(t_r, z_r)
    at = np.array([10.0, r0, (r0 + r1) / 2, r1, r1 + 0.5, 30.0])
    got = matched_times((t_r, z_r), (t_h, z_h), at)
    assert got[1:4] == pytest.approx([h0, (h0 + h1) / 2, h1], abs=1e-9)
    assert got[4] == pytest.approx(h1 + 0.5)                       # after the rise: second for second
    assert got[0] == pytest.approx(max(0.0, h0 - (r0 - 10.0)))     # before it, within the recording
    assert got[5] == pytest.approx(4.0)                            # clipped to the human's end
    assert list(strip_indices(801, 6)) == [0, 160, 320, 480, 640, 800]
