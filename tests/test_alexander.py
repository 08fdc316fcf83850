"""IHMC Alexander's lower body (example-robot-data's alexander_v1.lowerBodyOnly.urdf), the fifth packaged humanoid:
no arms, no head, a spine that only turns, and legs that carry 80 % of its mass, so that it sits with its COM already
ahead of its ankles, past the point where other robots leave the seat."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from sit2stand.cli import main as sit2stand
from sit2stand.human.offline import read_trial
from sit2stand.retarget.robot import robot_model, robot_setup
from sit2stand.retarget.stream import Retargeter, RetargetConfig
from sit2stand.robot.profile import load_profile

ROOT = Path(__file__).resolve().parents[1]


def test_alexander_has_no_upper_limbs_and_thirteen_joints():
    profile = load_profile("alexander")
    assert profile.trunk_pitch is None and not profile.upper_limbs
    model = robot_model(robot="alexander")[0]
    assert model.nv - 6 == 13


def test_a_robot_seated_with_its_com_past_its_seat_off_point_leaves_the_seat_a_little_further_forward():
    """The COM map's seat-off knot lies ``RetargetConfig.seat_off_ahead_m`` ahead of the robot's seated COM when the
    usual one (30 % along its feet) is behind it, and the ankle knot no further back: the map stays monotone, where
    it refused the robot before. The human's arm markers stay off the armless robot."""
    robot = robot_setup(robot="alexander")
    trial = read_trial(ROOT / "bags" / "natural")
    t, com = trial.truth
    com_h = np.array([np.interp(trial.marker_t_s[0], t, com[:, i]) for i in range(3)])
    rt = Retargeter(robot, RetargetConfig())
    rt.calibrate(trial.marker_names, trial.positions[0], trial.valid[0], com_h)
    seated = pin.centerOfMass(rt.model, rt.model.createData(), robot.q_seated)[0] - robot.ankle_left[0]
    usual = robot.heel_x_m + rt.cfg.seat_off_fraction * (robot.toe_x_m - robot.heel_x_m) - robot.ankle_left[0]
    assert seated > 0.03 > usual
    r = rt.com_map.knots_r
    assert r[0] == pytest.approx(seated, abs=1e-9)
    assert r[1] == pytest.approx(seated + rt.cfg.seat_off_ahead_m) and r[2] == r[1]
    xs = rt.com_map.human_ankle_x_m + np.linspace(rt.com_map.knots_h[0], 0.1, 200) / rt.com_map.scale
    assert np.all(np.diff(rt.com_target_x(xs)) >= -1e-12)
    arm = {"LSHO", "RSHO", "LELB", "RELB", "LWRA", "LWRB", "RWRA", "RWRB", "LFIN", "RFIN"}   # no link to go on
    assert not arm & set(rt.markers.frames) and {"LKNE", "LANK", "LASI", "C7"} <= set(rt.markers.frames)


def test_alexander_stands_up_from_the_natural_demonstration_at_the_humans_timing(tmp_path, capsys):
    """Its default plant hides 2.5 kg (``alexander_default``); CAD parameters. Measured: time scale 1.00, knees
    11.3 degrees (the human's 12.0), pelvis 98.8 % of its stance, COM 0.4 cm."""
    out = tmp_path / "rt"
    code = sit2stand(["retarget", str(ROOT / "bags" / "natural"), "--robot", "alexander", "--simulate",
                      "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert code == 0 and "stood up" in capsys.readouterr().out, summary
    assert summary["time_scale"] <= 1.05 and summary["standing_knees_match"], summary
    assert summary["final_pelvis_height_ratio"] > 0.95 and summary["com_tracking_rms_m"] < 0.015, summary
