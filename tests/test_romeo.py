"""Aldebaran Romeo (example-robot-data's romeo_small.urdf), the fourth packaged humanoid: its file spells its links'
sides unlike its joints' (``LAnkleRoll`` moves ``l_ankle``), its trunk only turns, its hips' axis is 20 cm below
its base's origin and only 29 degrees of hip flexion are left for the lean, and two of its link inertias break the
triangle inequality."""

from __future__ import annotations

import json
import re
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from sit2stand.cli import main as sit2stand
from sit2stand.retarget.ik import ComIk
from sit2stand.retarget.robot import robot_model, robot_setup
from sit2stand.robot.model import SIDES, held_on_seat_b, hips_axis_in_base, sole_corners_world
from sit2stand.robot.mujoco_urdf import inertias_mujoco_takes
from sit2stand.robot.profile import load_profile

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def romeo():
    """The retargeter's Romeo (CAD), seated: (model, q_seated, sole frame ids, their placements)."""
    model, q, _ = robot_model(robot="romeo")
    data = model.createData()
    soles = [model.getFrameId(f"sole_{s}") for s in SIDES]
    pin.framesForwardKinematics(model, data, q)
    return model, q, soles, [data.oMf[f].copy() for f in soles]


def test_romeos_feet_are_named_per_side_and_its_seat_holds_its_hips_axis(romeo):
    model = romeo[0]
    profile = load_profile("romeo")
    assert profile.foot_links == {"left": "l_ankle", "right": "r_ankle"} and profile.trunk_pitch is None
    assert hips_axis_in_base(model) == pytest.approx([0.0, 0.0, -0.2], abs=1e-3)
    seat = model.frames[model.getFrameId("seat")].placement.translation
    assert held_on_seat_b(model) == pytest.approx(seat) and seat == pytest.approx(hips_axis_in_base(model))
    talos = robot_model(robot="talos")[0]          # a trunk pitch joint: the base's origin, the seat's surface
    assert not held_on_seat_b(talos).any() and talos.frames[talos.getFrameId("seat")].placement.translation[2] < -0.3


def pitch_of(q: np.ndarray) -> float:
    R = pin.Quaternion(q[3:7]).toRotationMatrix()
    return float(np.arctan2(R[0, 2], R[2, 2]))


def lean(romeo, point: np.ndarray, forward_m: float):
    """The seated IK (no markers) with the COM ``forward_m`` ahead, ``point`` of the base held: (result, how far the
    held point moved [m] (x, z))."""
    model, q0, soles, sole_targets = romeo
    ik = ComIk(model, soles, hold_point_b=point)
    held_at = q0[:3] + pin.Quaternion(q0[3:7]).toRotationMatrix() @ point
    com = pin.centerOfMass(model, model.createData(), q0) + [forward_m, 0.0, 0.0]
    r = ik.solve(q0, [], com, sole_targets, com_axes=(0,), max_iterations=60, tol=1e-10, base_xz=held_at,
                 base_pitch_min=pitch_of(q0))
    return r, (r.q[:3] + pin.Quaternion(r.q[3:7]).toRotationMatrix() @ point - held_at)[[0, 2]]


def test_the_pelvis_leans_about_the_held_hips_where_about_its_origin_it_cannot(romeo):
    """Seated, the COM 2-6 cm forward (the lean before seat-off), no markers: held at its hips' axis the pelvis
    pitches forward about it (0.38 rad at 6 cm), the axis where it was; held at the base's origin, 20 cm higher, the
    lean swings the hips back and not even 2 cm of it has a solution."""
    model, q0 = romeo[:2]
    for forward_m in (0.02, 0.04, 0.06):
        r, moved = lean(romeo, held_on_seat_b(model), forward_m)
        assert r.feasible and r.com_error_m < 1e-6 and np.abs(moved).max() < 1e-6, forward_m
        assert pitch_of(r.q) > pitch_of(q0) + 5.0 * forward_m
    r, _ = lean(romeo, np.zeros(3), 0.02)
    assert not r.feasible and r.com_error_m > 0.01


def test_off_the_seat_the_floor_is_under_the_hips_axis_not_the_base_origin(romeo):
    """Leaned 6 cm on the seat, the pelvis pitched about its hips lowers the base's origin by over a centimetre. Off
    the seat, the floor (the held point's seated height plus the clearance, here 5 mm) lifts the hips' axis, the
    origin with it by as much: with the floor on the origin, the plan's first frame off the seat jumped 1.1-1.5 cm,
    and on Romeo's second rise of a cycles trial found no solution and fell back."""
    model, q0, soles, targets = romeo
    point = held_on_seat_b(model)
    held = lambda q: q[:3] + pin.Quaternion(q[3:7]).toRotationMatrix() @ point     # noqa: E731
    leaned, _ = lean(romeo, point, 0.06)
    assert leaned.feasible and leaned.q[2] < q0[2] - 0.01
    com = pin.centerOfMass(model, model.createData(), leaned.q)
    off = ComIk(model, soles, hold_point_b=point, dt=0.01).solve(
        leaned.q, [], com, targets, com_axes=(0, 1), q_prev=leaned.q, max_iterations=60, tol=1e-10,
        base_xz=held(leaned.q), base_weight=1e4, base_z_min=held(q0)[2] + 0.005)
    assert off.feasible and held(off.q)[2] >= held(q0)[2] + 0.005 - 1e-6
    assert off.q[2] - leaned.q[2] == pytest.approx(0.005, abs=0.001)


@pytest.mark.parametrize("robot,clipped", [("romeo", True), ("talos", False)])
def test_the_support_ends_where_the_ankles_can_hold_the_centre_of_pressure(robot, clipped):
    """Under half its weight, Romeo's 25.8 N m ankle pitch motors hold the centre of pressure at most 13 cm ahead of
    the ankles, its soles reach 14.8: the support (the COM map's toes, the ZMP's polygon) ends at the 13. TALOS's
    160 N m reach past its soles, which bound it."""
    setup = robot_setup(prebuilt=robot_model(robot=robot))
    model, data = setup.model, setup.model.createData()
    pin.framesForwardKinematics(model, data, setup.q_seated)
    toes = float(sole_corners_world(model, data)[:, 0].max())
    heels = float(sole_corners_world(model, data)[:, 0].min())
    ankles = [model.getJointId(load_profile(robot).leg(side, "ankle_pitch")) for side in SIDES]
    arm = model.effortLimit[model.joints[ankles[0]].idx_v] / (pin.computeTotalMass(model) * 9.81 / 2)
    x = [float(data.oMi[a].translation[0]) for a in ankles]
    reach = float(min(x) + arm)
    assert (reach < toes - 0.01) is clipped
    assert setup.toe_x_m == pytest.approx(min(toes, reach), abs=1e-6)
    assert setup.heel_x_m == pytest.approx(max(heels, max(x) - arm), abs=1e-6)
    assert float(np.max(setup.support_xy[:, 0])) == pytest.approx(setup.toe_x_m, abs=1e-6)


def test_inertias_that_break_the_triangle_inequality_are_balanced_for_mujoco_alone():
    profile = load_profile("romeo")
    text = profile.urdf_text()
    fixed = inertias_mujoco_takes(text)
    links = lambda urdf: dict(re.findall(r'<link\s+name="([^"]+)"\s*>(.*?)</link>', urdf, re.S))  # noqa: E731
    before, after = links(text), links(fixed)
    assert [name for name in before if before[name] != after[name]] == ["RShoulderYawLink", "RElbowYawLink"]
    v = dict((k, float(x)) for k, x in re.findall(r'(i[xyz]{2})="([^"]*)"', after["RElbowYawLink"]))
    tensor = np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]], [v["ixz"], v["iyz"], v["izz"]]])
    a, b, c = np.linalg.eigvalsh(tensor)
    assert a + b >= c and c == pytest.approx(0.00213058, rel=0.01)    # the largest moment kept
    link = '<robot name="r"><link name="l"><inertial><mass value="1"/><inertia ixx="1e-3" ixy="0" ixz="0" ' \
           'iyy="1e-3" iyz="0" izz="3e-3"/></inertial></link></robot>'
    with pytest.raises(ValueError, match="A \\+ B >= C"):
        mujoco.MjModel.from_xml_string(link)
    assert mujoco.MjModel.from_xml_string(inertias_mujoco_takes(link)).nbody >= 1     # compiles


def test_romeo_stands_up_from_the_natural_demonstration_at_the_humans_timing(tmp_path, capsys):
    """Its default plant hides 3 kg (``romeo_default``); CAD parameters. Measured: time scale 1.00 on the optimised
    plan, knees 12.4 degrees (the human's 12.0), pelvis 99 % of its stance, COM 0.8 cm."""
    out = tmp_path / "rt"
    code = sit2stand(["retarget", str(ROOT / "bags" / "natural"), "--robot", "romeo", "--simulate", "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert code == 0 and "stood up" in capsys.readouterr().out, summary
    assert summary["time_scale"] <= 1.05 and summary["standing_knees_match"], summary
    assert summary["final_pelvis_height_ratio"] > 0.95 and summary["com_tracking_rms_m"] < 0.015, summary
