"""sit2stand.robot.profile: robot profiles load, name their robot's joints by role, and bad ones are named."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from sit2stand.cli import main as sit2stand
from sit2stand.robot.check import check_robot
from sit2stand.robot.description import FrameTree, robot_description
from sit2stand.robot.model import PlantConfig, PlantConfigError, apply_link_parameters, controller_model
from sit2stand.robot.plant import Plant
from sit2stand.robot.profile import ProfileError, load_profile, packaged_folder, profile_of

SRC = Path(__file__).resolve().parents[1] / "src" / "sit2stand"


def copied_profile(tmp_path: Path, robot: str = "g1", name: str = "mine", **changes) -> Path:
    """The packaged profile of ``robot`` copied to a file (its URDF by absolute path), with ``changes`` applied
    (dotted keys: ``legs.knee``; None deletes)."""
    doc = yaml.safe_load((packaged_folder() / f"{robot}.yaml").read_text())
    doc["name"] = name
    doc["urdf"] = str(load_profile(robot).urdf)
    for key, value in changes.items():
        node, parts = doc, key.split(".")
        for part in parts[:-1]:
            node = node[part]
        if value is None:
            del node[parts[-1]]
        else:
            node[parts[-1]] = value
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_both_packaged_robots_name_their_legs_by_role_in_chain_order():
    talos, g1 = load_profile("talos"), load_profile("g1")
    assert talos.leg("left", "knee") == "leg_left_4_joint" and g1.leg("right", "knee") == "right_knee_joint"
    assert talos.leg_chain("left")[0] == "leg_left_1_joint"           # TALOS: hip yaw first
    assert g1.leg_chain("left")[:3] == ["left_hip_pitch_joint", "left_hip_roll_joint", "left_hip_yaw_joint"]
    assert g1.child_link("left_knee_joint") == "left_knee_link" and g1.root_link == "pelvis"
    assert g1.is_upper_limb("left_elbow_joint") and not g1.is_upper_limb("waist_pitch_joint")
    assert set(g1.lateral_joints()) == {"waist_yaw_joint", "waist_roll_joint", "left_hip_yaw_joint",
                                        "right_hip_yaw_joint", "left_hip_roll_joint", "right_hip_roll_joint",
                                        "left_ankle_roll_joint", "right_ankle_roll_joint"}
    names = ["root"] + list(controller_model(PlantConfig(robot="g1")).names[2:])
    assert g1.marker_joints("thigh", "left", names) == ("left_hip_yaw_joint", "left_knee_joint")
    assert g1.marker_joints("pelvis", None, names) == ("root",)


@pytest.mark.parametrize("robot, mass_kg, joints", [("talos", 90.27, 32), ("g1", 33.34, 29)])
def test_each_robot_builds_sits_and_its_model_knows_its_profile(robot, mass_kg, joints):
    plant = Plant(PlantConfig(robot=robot))
    assert plant.n == joints
    assert pin.computeTotalMass(plant.ctrl) == pytest.approx(mass_kg, abs=0.01)
    assert profile_of(plant.ctrl).name == robot
    plant.settle(1.0)
    assert not plant.fallen
    assert abs(plant.data.qpos[2] - plant.q_seated[2]) < 0.02      # resting on its chair, where it was put


def test_g1_has_a_frame_tree_from_its_own_urdf_without_the_floating_joint():
    urdf = robot_description("g1")
    assert "floating_base_joint" not in urdf and '<link name="world"' not in urdf
    plant = Plant(PlantConfig(robot="g1"), with_chair=False)
    tree = FrameTree(plant.joint_names, urdf, "g1")
    assert tree.pairs[0] == ("world", "pelvis")
    t, _ = tree.transforms(plant.q_seated[:7], plant.q_seated[plant.qadr])
    soles = t[-2:]
    assert np.all(np.abs(soles[:, 2]) < 0.005), soles       # the sole frames on the floor, as the plant's
    assert "file:///" in robot_description("g1", meshes="file")


def test_plants_name_their_robot_and_a_packaged_name_means_the_robots_own():
    assert PlantConfig.load("default", "g1").name == "g1_default"
    assert PlantConfig.load("default", "talos").name == "default"
    assert PlantConfig.load("default").robot == "talos"
    with pytest.raises(PlantConfigError, match=r"heavy_front.yaml: field 'robot': this plant is for talos, not g1"):
        PlantConfig.load("heavy_front", "g1")


def test_identified_parameters_of_another_robot_are_refused_by_joint():
    talos_links = {"leg_left_4_joint": {"mass": 5.0, "com": [0.0, 0.0, -0.1]}}
    with pytest.raises(PlantConfigError, match="leg_left_4_joint, which g1 does not have: .*another robot"):
        apply_link_parameters(controller_model(PlantConfig(robot="g1")), talos_links)


def test_a_copied_profile_of_the_same_robot_loads_by_path(tmp_path):
    path = copied_profile(tmp_path, name="g1_copy")
    profile = load_profile(str(path))
    assert profile.name == "g1_copy" and profile.leg("left", "knee") == "left_knee_joint"
    model = controller_model(PlantConfig(robot=str(path)))
    assert profile_of(model) is profile


@pytest.mark.parametrize("changes, field, what", [
    ({"legs.knee": "left_knees_joint"}, "legs.knee", "'left_knees_joint' is not a moving joint of the URDF"),
    ({"legs.knee": None}, "legs", "no knee"),
    ({"seated_posture": {"*_knee_joint": 3.2}}, "seated_posture", "left_knee_joint at 3.2 rad is outside its limits"),
    ({"foot_link": "{side}_foot"}, "foot_link", "'left_foot' is not a link of the URDF"),
    ({"foot_link": {"left": "left_ankle_roll_link"}}, "foot_link", "or one for each of left, right"),
    ({"trunk": {"bend": "waist_pitch_joint"}}, "trunk", "names the trunk's joints by role (pitch, yaw, roll)"),
    ({"colliding_links": ["*_shin_link"]}, "colliding_links", "'*_shin_link' matches nothing"),
    ({"sole.half_size_m": [0.09, 0.035]}, "sole.half_size_m", "expected 3 numbers"),
    ({"urdf": "nowhere.urdf"}, "urdf", "no such file"),
])
def test_a_bad_profile_is_named_by_file_and_field(tmp_path, changes, field, what):
    path = copied_profile(tmp_path, name=f"bad_{abs(hash(field)) % 1000}", **changes)
    with pytest.raises(ProfileError, match=re.escape(f"{path}: field {field!r}: ") + ".*" + re.escape(what)):
        load_profile(str(path))


def test_a_seat_the_seated_posture_cannot_reach_is_refused(tmp_path):
    plant = tmp_path / "high_chair.yaml"
    plant.write_text("robot: g1\nname: high_chair\nchair_height_m: 0.40\n")
    with pytest.raises(PlantConfigError, match=r"field 'chair_height_m': 0.400 m, but the seated posture of g1 "
                                               r"rests its seat links on a seat at 0.231 m"):
        Plant(PlantConfig.load(plant))
    path = copied_profile(tmp_path, name="squat", **{"seated_posture": {"*_hip_pitch_joint": -0.2,
                                                                        "*_knee_joint": 2.8,
                                                                        "*_ankle_pitch_joint": -0.8}})
    with pytest.raises(PlantConfigError, match="field 'seated_posture': it puts the seat links"):
        Plant(PlantConfig(robot=str(path)))


def test_robot_check_prints_the_sit_to_stand_figures(capsys):
    result = check_robot("g1")
    assert result.ok and result.sits
    assert result.seat_height_m == pytest.approx(0.231, abs=0.003)
    assert 0.1 < result.knee_share < 0.4 and result.trunk_limit_nm == 35.0
    assert sit2stand(["robot", "check", "talos"]) == 0
    out = capsys.readouterr().out
    assert "90.3 kg, 32 actuated joints" in out and "ok: it can sit on its chair" in out
    assert sit2stand(["robot", "check", "nobody"]) == 2


def test_no_robots_joint_or_link_is_named_in_the_code():
    """Robot names live in profile files: no module under src/ spells a TALOS, G1, iCub or Romeo joint or link
    (iCub's ``root_link`` is also the name of a profile field)."""
    names = set()
    for robot in ("talos", "g1", "icub", "romeo", "alexander"):
        for parent, child in load_profile(robot).urdf_joints().values():
            names |= {parent, child}
        names |= set(load_profile(robot).urdf_joints())
    names = {n for n in names if "_" in n} - {"root_link"}   # one-word names ("pelvis", "world") are the human's too
    pattern = re.compile(r"\b(" + "|".join(map(re.escape, sorted(names, key=len, reverse=True))) + r")\b")
    found = [f"{p.relative_to(SRC)}:{i}: {m.group(1)}" for p in SRC.rglob("*.py")
             for i, line in enumerate(p.read_text().splitlines(), 1) for m in [pattern.search(line)] if m]
    assert not found, found


def test_a_copied_profile_naming_another_urdf_of_the_robot_stands_up(tmp_path, capsys):
    """G1's profile copied, pointing at G1's 43-DoF URDF with hands: no code change, its own plants vouched for by
    the profile it copied."""
    hands = str(load_profile("g1").urdf.with_name("g1_29dof_with_hand_rev_1_0.urdf"))
    path = copied_profile(tmp_path, name="g1_hands", urdf=hands)
    assert PlantConfig.load("default", str(path)).name == "g1_default"
    out = tmp_path / "rt"
    bag = Path(__file__).resolve().parents[1] / "bags" / "natural"
    assert sit2stand(["retarget", str(bag), "--robot", str(path), "--simulate", "--plan", "frames",
                      "--out", str(out)]) == 0, capsys.readouterr().out[-2000:]
    summary = yaml.safe_load((out / "summary.json").read_text())
    assert summary["robot"] == "g1_hands" and summary["stood_up"] and summary["time_scale"] <= 1.1
