"""sit2stand.retarget.calibration: human markers land on the right robot links; the COM maps by proportions."""

import numpy as np
import pinocchio as pin
import pytest
import yaml

from sit2stand.human.marker_sets import load_marker_set
from sit2stand.human.offline import read_trial
from sit2stand.retarget.calibration import (MarkerMap, calibrate_markers, map_com, map_frame, marker_group,
                                            marker_roles, posed_like)
from sit2stand.retarget.robot import robot_setup
from sit2stand.retarget.stream import RetargetConfig, Retargeter
from sit2stand.robot.model import PlantConfig
from sit2stand.robot.plant import Plant
from sit2stand.robot.profile import profile_of

EXPECTED = {"LASI": ["root"], "RPSI": ["root"], "C7": ["torso_2_joint", "head_1_joint"],
            "LFHD": ["head_1_joint", "head_2_joint"], "LKNE": ["leg_left_3_joint", "leg_left_4_joint"],
            "RANK": ["leg_right_4_joint", "leg_right_5_joint", "leg_right_6_joint"],
            # the overlay puts the human's feet (shank tilt ~13 deg) beside the robot's shank (tilted 25 deg back):
            # foot markers land on the shank or the foot; matching the seated postures first would fix that
            "LTOE": ["leg_left_4_joint", "leg_left_5_joint", "leg_left_6_joint"],
            "LHEE": ["leg_left_4_joint", "leg_left_5_joint", "leg_left_6_joint"],
            "RTHI": ["leg_right_3_joint"]}


@pytest.fixture(scope="module")
def calibrated():
    trial = read_trial("bags/natural")
    plant = Plant(PlantConfig())
    q = plant.pin_configuration(plant.q_seated)
    k = 10   # a seated frame
    mm = calibrate_markers(plant.ctrl, q, trial.marker_names, trial.positions[k], trial.valid[k],
                           human_thigh_m=0.42, robot_thigh_m=0.38)
    return plant, mm


def test_markers_are_fixed_to_the_expected_links(calibrated):
    plant, mm = calibrated
    root = plant.ctrl.names[1]
    for marker, links in EXPECTED.items():
        want = [root if link == "root" else link for link in links]
        assert mm.links[marker] in want, (marker, mm.links[marker])
    assert all("right" not in mm.links[m] for m in mm.links if m.startswith("L"))
    assert all(np.linalg.norm(o) < 0.5 for o in mm.offsets.values())


def test_marker_map_round_trips_through_yaml(calibrated, tmp_path):
    plant, mm = calibrated
    mm.save(tmp_path / "m.yaml")
    back = MarkerMap.load(tmp_path / "m.yaml")
    assert back.links == mm.links and all(np.allclose(back.offsets[m], mm.offsets[m]) for m in mm.links)
    frames = back.add_frames(plant.ctrl.copy())
    assert len(frames) == len(mm.links)


def test_com_mapping_scales_relative_to_the_left_foot():
    human = np.array([[0.10, 0.05, 0.90], [0.20, 0.02, 1.00]])
    target = map_com(human, np.array([0.0, 0.1, 0.0]), 0.9, np.array([0.0, 0.085, 0.0]), 0.8)
    assert target[:, 0] == pytest.approx(human[:, 0] * 0.8 / 0.9)
    assert target[:, 2] == pytest.approx(human[:, 2] * 0.8 / 0.9)
    assert np.all(target[:, 1] == 0.0)


def test_calibration_needs_the_pelvis():
    plant = Plant(PlantConfig())
    with pytest.raises(ValueError, match="need 3"):
        calibrate_markers(plant.ctrl, plant.pin_configuration(plant.q_seated), ["LASI", "C7"],
                          np.zeros((2, 3)), np.array([True, True]), 0.42, 0.38)


def test_marker_roles_come_from_the_set_plug_in_gaits_as_its_names_said():
    pig = marker_roles("plug_in_gait")
    assert all(pig.group(n) == marker_group(n) for n in pig.groups)      # the name rules, now read off the set
    assert (pig.pelvis, pig.knee, pig.ankle, pig.heel) == (("LASI", "RASI", "LPSI", "RPSI"), ("LKNE",), ("LANK",),
                                                           ("LHEE",))
    g = marker_roles("gait2392")
    assert (g.pelvis, g.knee, g.ankle, g.heel) == (("R.ASIS", "L.ASIS", "V.Sacral"), ("L.Knee.Lat", "L.Knee.Med"),
                                                   ("L.Ankle.Lat", "L.Ankle.Med"), ("L.Heel",))
    assert (g.group("L.Acromium"), g.sides["L.Acromium"], g.group("Sternum"), g.sides["Sternum"]) == \
        ("arm", "left", "trunk", None)


def test_a_renamed_marker_set_retargets_as_plug_in_gait(tmp_path):
    """Plug-in-Gait's markers renamed in a user's YAML: the same marker map, the same COM map knots."""
    trial = read_trial("bags/natural")
    pig = load_marker_set("plug_in_gait")
    doc = yaml.safe_load(open(pig.source))
    rename = {n: f"m_{n.lower()}" for n in pig.names}
    doc["pelvis"] = {k: [rename[n] for n in v] for k, v in doc["pelvis"].items()}
    doc["markers"] = {rename[n]: v for n, v in doc["markers"].items()}
    (tmp_path / "renamed.yaml").write_text(yaml.safe_dump(doc))
    robot = robot_setup()
    k, com = 10, np.array([-0.25, 0.0, 0.75])
    maps, knots = [], []
    renamed = RetargetConfig(marker_set=str(tmp_path / "renamed.yaml"))
    for names, cfg in ((trial.marker_names, RetargetConfig()), ([rename[n] for n in trial.marker_names], renamed)):
        rt = Retargeter(robot, cfg)
        maps.append(rt.calibrate(names, trial.positions[k], trial.valid[k], com))
        knots.append((rt.com_map.knots_h, rt.com_map.scale))
    assert {rename[m]: link for m, link in maps[0].links.items()} == maps[1].links
    np.testing.assert_allclose(knots[0][0], knots[1][0])
    with pytest.raises(ValueError, match=r"marker\(s\) m_lhee missing"):
        valid = trial.valid[k] & (np.array(trial.marker_names) != "LHEE")
        Retargeter(robot, renamed).calibrate([rename[n] for n in trial.marker_names], trial.positions[k], valid, com)


def test_the_marker_map_frame_is_a_seated_one():
    trial = read_trial("bags/natural")
    t, pos, valid = trial.marker_t_s, trial.positions, trial.valid
    auto = map_frame(t, pos, valid, seated_frames=60)
    assert auto.first < 60 and "seated" in auto.reason
    assert map_frame(t, pos, valid, seated_frames=0).first == 0            # starts mid-rise: the nearest to seated
    assert map_frame(t, pos, valid, 60, given=12).first == 12
    with pytest.raises(ValueError, match=r"--calibration-frame 200: the human is no longer seated there \(the rise "
                                         r"starts at frame 60\)"):
        map_frame(t, pos, valid, 60, given=200)


def test_a_marker_on_a_joint_between_two_links_goes_to_the_distal_one_even_when_its_links_are_not_found():
    """The nearest bone within 5 mm, the more distal link among those: a knee marker exactly at the robot's knee is
    as near the thigh (which ends there) as the shank (which starts there) and goes to the shank. Links a marker
    may not have (an ``allowed_links`` naming none of the robot's) fall back to every bone of its side."""
    robot = robot_setup()
    model, q = robot.model, robot.q_seated
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    pelvis, knee = data.oMi[1].translation, data.oMi[model.getJointId("leg_left_4_joint")].translation
    names = ["LASI", "RASI", "LPSI", "RPSI", "LKNE"]
    # the pelvis markers' mean on the robot's pelvis, and both thighs of one length: a marker lands where it is put
    positions = np.array([pelvis + [0.1, 0.1, 0.0], pelvis + [0.1, -0.1, 0.0], pelvis + [-0.1, 0.1, 0.0],
                          pelvis + [-0.1, -0.1, 0.0], knee])
    valid = np.ones(5, bool)
    assert calibrate_markers(model, q, names, positions, valid, 0.4, 0.4).links["LKNE"] == "leg_left_4_joint"
    nowhere = calibrate_markers(model, q, names, positions, valid, 0.4, 0.4, allowed_links=lambda *_: ("none",))
    assert nowhere.links["LKNE"] == "leg_left_4_joint"
    assert nowhere.links["LASI"] != nowhere.links["LKNE"]


@pytest.mark.parametrize("robot", ["talos", "g1"])
def test_the_robot_posed_like_a_humans_flexions_keeps_its_soles_flat_and_its_left_ankle(robot):
    setup = robot_setup(robot=robot)
    model, q0 = setup.model, setup.q_seated
    flexion = {"trunk": 15.0, "hip": 60.0, "knee": 70.0, "ankle": 20.0}
    q = posed_like(model, q0, flexion)
    profile = profile_of(model)
    for label, (joints, sign) in profile.sagittal_flexion().items():
        for name in joints:
            i = model.joints[model.getJointId(name)].idx_q
            want = np.clip(sign * np.radians(flexion[label]), model.lowerPositionLimit[i], model.upperPositionLimit[i])
            assert q[i] == pytest.approx(want), name
    poses = []
    for config in (q0, q):
        data = model.createData()
        pin.framesForwardKinematics(model, data, config)
        poses.append([data.oMf[f].copy() for f in setup.sole_frames] +
                     [data.oMi[model.getJointId(profile.leg("left", "ankle_pitch"))].copy()])
    for after in poses[1][:-1]:
        assert np.degrees(np.arccos(np.clip(after.rotation[2, 2], -1, 1))) < 0.5, "the soles stay flat"
    assert np.linalg.norm(poses[1][-1].translation - poses[0][-1].translation) < 1e-9, "the left ankle stays"
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    assert data.oMi[1].translation[2] > q0[2] + 0.05, "the pelvis rises out of the seat"
