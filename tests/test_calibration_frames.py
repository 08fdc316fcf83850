"""sit2stand.human.calibration_frames: the calibration's frames are the quietest stretch that sees the most markers,
or the ones the user names, or a static trial's (subject01_static.trc, read in place)."""

import numpy as np
import pytest

from conftest import real_file
from sit2stand.errors import InputError
from sit2stand.human.calibration import StreamCalibration
from sit2stand.human.calibration_frames import frames_at, marker_speed, quiet_frames
from sit2stand.human.offline import calibrate_from_bag, read_static
from sit2stand.io.c3d import write_trial_bag
from sit2stand.io.trc import read_opensim_trial

RATE_HZ = 100.0


def trial(n=300, m=20, seed=0):
    """Markers with 2 mm of noise: moving (0-99), still with every marker (100-199), still with one occluded
    (200-299)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE_HZ
    base = rng.uniform(-0.5, 0.5, (m, 3))
    drift = np.where(t < 1.0, 0.5 * np.sin(2 * np.pi * t), 0.0)[:, None, None] * np.array([1.0, 0.0, 0.5])
    pos = base + drift + rng.normal(0, 0.002, (n, m, 3))
    valid = np.ones((n, m), bool)
    valid[200:, 3] = False
    pos[200:, 3] = np.nan
    return t, pos, valid


def test_the_quietest_stretch_that_sees_every_marker_is_chosen():
    t, pos, valid = trial()
    choice = quiet_frames(t, pos, valid, 50)
    assert 100 <= choice.first and choice.frames[-1] < 200 and len(choice.frames) == 50
    assert "20.0 markers seen" in choice.reason
    # marker noise alone is ~30 mm/s over one frame at 100 Hz; over the 0.1 s lag, a still subject reads lower
    assert np.median(marker_speed(t, pos, valid)[100:200]) < 0.05 < np.median(marker_speed(t, pos, valid)[:90])


def test_as_still_windows_go_to_the_earliest_and_stop_limits_the_search():
    t, pos, valid = trial()
    valid[200:, 3], pos[200:, 3] = True, pos[150, 3]          # the last stretch sees every marker too
    assert 100 <= quiet_frames(t, pos, valid, 50).first <= 110    # both still: the earlier (a seated start)
    assert quiet_frames(t, pos, valid, 50, stop=80).frames[-1] < 80


def test_given_frames_and_what_is_refused():
    t, pos, valid = trial()
    choice = frames_at(120, pos, valid, 10)
    assert list(choice.frames) == list(range(120, 130)) and "--calibration-frame 120" in choice.reason
    with pytest.raises(InputError, match=r"--calibration-frame 300: the trial has frames 0-299"):
        frames_at(300, pos, valid, 10)
    with pytest.raises(InputError, match=r"--calibration-frame 5: it sees 2 markers, a calibration needs 12"):
        frames_at(5, pos, valid[:, :2].repeat(10, axis=1) & (np.arange(20) < 2), 10)
    with pytest.raises(InputError, match=r"no frame sees 12 markers \(the most in one frame: 2\)"):
        quiet_frames(t, pos, valid & (np.arange(20) < 2), 10)


def test_a_static_trc_calibrates_the_skeleton_for_a_walking_trial(tmp_path):
    """OpenSim's subject01: the static trial has 49 markers (knees and ankles too), the walk 41."""
    static = read_static(real_file("subject01_static.trc"))
    assert len(static.marker_names) == 49 and static.height_m is None
    walk = read_opensim_trial(real_file("subject01_walk1.trc"), mass_kg=72.6, height_m=1.8)
    write_trial_bag(walk, tmp_path / "walk")
    cal, reason = calibrate_from_bag(tmp_path / "walk", tmp_path / "cal.yaml", frames=3,
                                     static=real_file("subject01_static.trc"))
    assert reason.startswith(f"{real_file('subject01_static.trc')}: frames 0-2 found: 49.0 markers seen")
    assert cal.marker_rms_after_m < 0.5 * cal.marker_rms_before_m
    assert "L.Knee.Lat" in StreamCalibration.load(tmp_path / "cal.yaml").marker_placements_m
    with pytest.raises(InputError, match=r"--static .*walk1_grf.mot: not a bag, a .c3d nor a .trc file"):
        read_static(real_file("subject01_walk1_grf.mot"))
