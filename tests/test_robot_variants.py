"""Humanoids with fewer joints than TALOS and G1: a trunk that only turns (G1's 23-DoF version locks the waist's roll
and pitch) and ankles that only pitch (Unitree H1's). Both are made from G1's file with those joints fixed and load
with nothing but their profiles, and stand up."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from sit2stand.cli import main as sit2stand
from sit2stand.retarget.robot import robot_model, robot_setup
from sit2stand.robot.check import check_robot
from sit2stand.robot.identify import identify
from sit2stand.robot.model import SIDES, PlantConfig
from sit2stand.robot.postures import collect_postures
from sit2stand.robot.profile import load_profile, profile_of
from sit2stand.robot.wbc import Reference, WholeBodyQP, feet_anchored_reference

from test_profile import copied_profile

ROOT = Path(__file__).resolve().parents[1]


def g1_with_fixed(tmp_path: Path, name: str, joints: list[str], **changes) -> Path:
    """A profile of G1 with ``joints`` welded (their URDF type fixed), its own URDF beside it."""
    g1 = load_profile("g1").urdf
    text = g1.read_text().replace('filename="../', f'filename="{g1.parent.parent}/')
    for joint in joints:
        text, n = re.subn(rf'(<joint\s+name="{joint}"\s+type=")revolute(")', r"\1fixed\2", text)
        assert n == 1, joint
    urdf = tmp_path / f"{name}.urdf"
    urdf.write_text(text)
    return copied_profile(tmp_path, name=name, urdf=str(urdf), **changes)


@pytest.fixture(scope="module")
def no_trunk_pitch(tmp_path_factory) -> Path:
    return g1_with_fixed(tmp_path_factory.mktemp("g1_23"), "g1_waist_yaw", ["waist_roll_joint", "waist_pitch_joint"],
                         **{"trunk": {"yaw": "waist_yaw_joint"}, "marker_links.trunk": ["waist_yaw_joint"],
                            "marker_links.head": ["waist_yaw_joint"],
                            "gap.moving_joints": ["left_hip_pitch_joint", "left_knee_joint"]})


@pytest.fixture(scope="module")
def no_ankle_roll(tmp_path_factory) -> Path:
    return g1_with_fixed(tmp_path_factory.mktemp("g1_pitch_ankles"), "g1_pitch_ankles",
                         ["left_ankle_roll_joint", "right_ankle_roll_joint"],
                         **{"legs.ankle_roll": None, "marker_links.foot": ["{side}_ankle_pitch_joint"]})


def test_a_trunk_that_only_turns_leans_with_the_hips_and_stands_up(no_trunk_pitch, tmp_path, capsys):
    profile = load_profile(str(no_trunk_pitch))
    assert profile.trunk_pitch is None and "trunk" not in profile.sagittal_flexion()
    result = check_robot(str(no_trunk_pitch))
    assert result.ok and result.as_dict()["trunk_limit_nm"] is None
    postures = tmp_path / "postures"          # on G1's default plant: 6.6 kg its CAD model lacks
    plant = PlantConfig.load("default", str(no_trunk_pitch))
    assert collect_postures(plant, 24, postures, progress=False)["kept"] == 24
    planar = identify(postures, "planar5", robot=str(no_trunk_pitch))
    assert len(planar.values) == 12                                      # four segments: the torso is the pelvis's
    assert planar.eval_rms_m < min(0.015, planar.cad_eval_rms_m)
    out = tmp_path / "rt"
    code = sit2stand(["retarget", str(ROOT / "bags" / "natural"), "--robot", str(no_trunk_pitch), "--simulate",
                      "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert code == 0 and summary["stood_up"] and summary["standing_knees_match"], summary
    assert summary["time_scale"] <= 1.15 and summary["final_pelvis_height_ratio"] > 0.95, summary


def test_ankles_that_only_pitch_carry_the_foot_and_stand_up(no_ankle_roll, tmp_path):
    """A leg without an ankle roll loads, sits, is optimised at the human's timing (its seated contacts redundant,
    their dynamics damped) and stands up under whole-body torque control on its default plant (6.6 kg its model
    lacks), its soles' dependent contact rows freed where the hips' roll axes align."""
    profile = load_profile(str(no_ankle_roll))
    assert "ankle_roll" not in profile.legs["left"] and profile.foot_joint("left") == "left_ankle_pitch_joint"
    assert "left_ankle_roll_joint" not in profile.lateral_joints()
    assert check_robot(str(no_ankle_roll)).ok
    out = tmp_path / "rt"
    bag = str(ROOT / "bags" / "natural")
    assert sit2stand(["retarget", bag, "--robot", str(no_ankle_roll), "--simulate", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["whole_rise_tries"] == [[1.0, True]], summary
    assert summary["stood_up"] and summary["standing_knees_match"], summary
    assert summary["time_scale"] <= 1.1 and summary["final_pelvis_height_ratio"] > 0.95, summary


@pytest.mark.parametrize("robot", ["talos", None])
def test_feet_without_an_ankle_roll_are_targeted_as_far_apart_as_straight_legs_put_them(no_ankle_roll, robot):
    """A measured seated start with the hips yawed 0.6 mrad apart (as H1 settles on its chair) puts the feet 0.2 mm
    wider than the hips; straight, legs without an ankle roll cannot: their soles are targeted with the lateral
    joints as the profile seats them (the IK found no standing frame otherwise). Legs with one keep the feet as
    measured."""
    prebuilt = robot_model(None, None, robot=robot or str(no_ankle_roll))
    model, q0 = prebuilt[:2]
    q = q0.copy()
    for side, sign in zip(SIDES, (1.0, -1.0)):
        q[model.joints[model.getJointId(profile_of(model).leg(side, "hip_yaw"))].idx_q] += sign * 6e-4
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    measured = [data.oMf[model.getFrameId(f"sole_{s}")].translation[1] for s in SIDES]
    nominal = [T.translation[1] for T in robot_setup(prebuilt=prebuilt).sole_targets]
    targets = [T.translation[1] for T in robot_setup(q_start=q, prebuilt=prebuilt).sole_targets]
    assert abs((measured[0] - measured[1]) - (nominal[0] - nominal[1])) > 1e-4
    assert targets == pytest.approx(nominal if robot is None else measured, abs=1e-9)


@pytest.mark.parametrize("robot,redundant", [("talos", False), ("g1", False), ("icub", False), (None, True)])
def test_the_soles_contacts_are_redundant_only_on_legs_without_an_ankle_roll(no_ankle_roll, robot, redundant):
    """Seated, the soles' and the seat's stacked contact Jacobian has a singular value near zero exactly then."""
    model, q, _ = robot_model(None, None, robot=robot or str(no_ankle_roll))
    assert profile_of(model).redundant_sole_contacts is redundant
    assert WholeBodyQP(model, model.getFrameId("seat")).redundant_contacts is redundant
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    J = np.vstack([pin.getFrameJacobian(model, data, model.getFrameId(f"sole_{s}"), pin.LOCAL) for s in SIDES]
                  + [pin.getFrameJacobian(model, data, model.getFrameId("seat"), pin.LOCAL_WORLD_ALIGNED)[:3]])
    s = np.linalg.svd(J, compute_uv=False)
    assert bool(s[-1] < 1e-3 * s[0]) is redundant, s[-1] / s[0]


def test_the_whole_body_qp_solves_redundant_soles_with_the_seat_on_off_and_on_again(no_ankle_roll):
    """The dynamics filter's QP (the seat a contact) on legs without an ankle roll, seated: solved with the seat
    carrying, without it (the robot then tips, its COM behind its feet) and with it again, the same answer as the
    first."""
    model, q, _ = robot_model(None, None, robot=str(no_ankle_roll))
    data, z = model.createData(), np.zeros(model.nv)
    qp = WholeBodyQP(model, model.getFrameId("seat"))
    ref = Reference(q, z, z, pin.centerOfMass(model, data, q).copy(), np.zeros(3), np.zeros(3))
    on, off, again = (qp.solve(q, z, ref, seat_force_max_n=f) for f in (400.0, 0.0, 400.0))
    assert on.solved and off.solved and again.solved
    assert np.abs(on.a).max() < 1e-4 and np.linalg.norm(on.seat_force) > 1.0       # at rest on the seat
    assert np.linalg.norm(off.seat_force) < 1e-9 and np.abs(off.a).max() > 0.1
    assert np.allclose(again.a, on.a, atol=1e-9) and np.allclose(again.tau, on.tau, atol=1e-6)


def test_legs_without_an_ankle_roll_straighten_as_fast_with_their_feet_toed_out(no_ankle_roll):
    """Standing on feet toed out 1.1 degrees each (near the aligned hips, the soles' contact rows nearly dependent),
    the whole-body QP straightens the hips toward the plan's posture as it does on parallel feet; holding that
    nearly dependent combination as an equality slowed it to 40 % (H1 stood 4.8 cm off its plan for good)."""
    model, _, _ = robot_model(None, None, robot=str(no_ankle_roll))
    profile, data, zero = profile_of(model), model.createData(), np.zeros(model.nv - 6)
    floor = pin.SE3(np.eye(3), np.array([0.0, 0.12, 0.0]))

    def standing(hip_pitch: float, knee: float, ankle: float, toe_out: float) -> np.ndarray:
        q = pin.neutral(model)
        for side, sign in zip(SIDES, (1.0, -1.0)):
            for joint, angle in ((profile.leg(side, "hip_yaw"), sign * toe_out), (profile.leg(side, "hip_pitch"),
                                 hip_pitch), (profile.leg(side, "knee"), knee), (profile.foot_joint(side), ankle)):
                q[model.joints[model.getJointId(joint)].idx_q] = angle
        return feet_anchored_reference(model, data, q, zero, zero, floor).q

    hip = model.joints[model.getJointId(profile.leg("left", "hip_pitch"))].idx_v
    accelerations = {}
    for toe_out in (0.0, 0.02):
        plan = feet_anchored_reference(model, data, standing(-0.37, 0.2, -0.1, toe_out), zero, zero, floor)
        result = WholeBodyQP(model, None).solve(standing(-0.5, 0.24, -0.05, toe_out), np.zeros(model.nv), plan)
        assert result.solved
        accelerations[toe_out] = result.a[hip]
    assert accelerations[0.0] > 10.0 and accelerations[0.02] > 0.9 * accelerations[0.0], accelerations
