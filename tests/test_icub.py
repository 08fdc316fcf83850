"""iCub, a robot whose file breaks TALOS's and G1's habits: its base frame faces backward, its hips and knees flex the
other way, its meshes are COLLADA, its sole hangs on a frame welded below the ankle and its URDF has point masses.
Loaded, converted, seated and stood up with nothing but its profile."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from sit2stand.cli import main as sit2stand
from sit2stand.robot.conventions import floating_base_removed
from sit2stand.robot.feet_sensing import below_sensor
from sit2stand.robot.meshes import MeshError, collada_triangles, readable_mesh
from sit2stand.robot.model import PlantConfig, controller_model
from sit2stand.robot.mujoco_urdf import inertias_mujoco_takes
from sit2stand.robot.identify import identify
from sit2stand.robot.plant import Plant
from sit2stand.robot.postures import collect_postures
from sit2stand.robot.profile import ProfileError, load_profile

from test_profile import copied_profile

ROOT = Path(__file__).resolve().parents[1]
TURNED_AND_FLIPPED = {"l_hip_pitch", "r_hip_pitch", "l_knee", "r_knee"}


def _placements(text: str, q_of: dict[str, float]) -> dict[str, pin.SE3]:
    """Every body frame's placement in the root's frame, the joints at ``q_of`` (the rest at zero)."""
    model = pin.buildModelFromXML(text)
    data = model.createData()
    q = pin.neutral(model)
    for name, value in q_of.items():
        q[model.joints[model.getJointId(name)].idx_q] = value
    pin.framesForwardKinematics(model, data, q)
    return {f.name: data.oMf[i].copy() for i, f in enumerate(model.frames) if f.type == pin.FrameType.BODY}


def test_icubs_file_is_brought_to_the_conventions_as_the_same_robot():
    profile = load_profile("icub")
    assert profile.conventions.base_yaw_rad == pytest.approx(math.pi)
    assert set(profile.conventions.flipped) == TURNED_AND_FLIPPED
    assert profile.seated_posture["l_knee"] > 0 > profile.seated_posture["l_hip_pitch"]      # the URDF's -1.9, 1.5708
    original = floating_base_removed(profile.urdf.read_text())
    turn = pin.SE3(pin.utils.rpyToMatrix(0.0, 0.0, math.pi), np.zeros(3))
    rng = np.random.default_rng(3)
    joints = sorted(profile.moving_joints())
    for _ in range(3):
        q = {n: float(rng.uniform(-0.4, 0.4)) for n in joints}
        before = _placements(original, q)
        after = _placements(profile.urdf_text(), {n: profile.conventions.angle(n, v) for n, v in q.items()})
        for name, placement in before.items():     # every link where it was, seen from the turned base (whose
            if name != profile.root_link:          # own frame is the one turned)
                assert (turn * placement).isApprox(after[name], 1e-9), name
    for robot in ("talos", "g1"):               # files already in the conventions are read as they are
        other = load_profile(robot)
        assert not other.conventions.changed
        assert other.urdf_text() == floating_base_removed(other.urdf.read_text())


def test_a_sagittal_joint_not_turning_about_y_is_refused_by_field(tmp_path):
    path = copied_profile(tmp_path, robot="icub", name="icub_rolled_knee", **{"legs.knee": "{side}_hip_roll"})
    with pytest.raises(ProfileError, match=r"field 'legs.knee': 'l_hip_roll' turns about \(.*\) in the base frame, "
                                           r"not about its y axis"):
        load_profile(str(path))


@pytest.mark.parametrize("robot", ["talos", "g1", "icub", "romeo", "alexander"])
def test_the_controllers_soles_are_where_the_plants_are(robot):
    """The sole and F/T frames hang on the foot link's frame in both models (iCub's is welded under its ankle; its
    MJCF site frames came in 5.5 cm off), and the weight the F/T sensing takes off is what hangs below the sensor."""
    plant = Plant(PlantConfig(robot=robot))
    plant.settle(0.5)
    mujoco.mj_kinematics(plant.model, plant.data)     # the sites where qpos puts them (a step leaves them 1 ms back)
    model, data = plant.ctrl, plant.ctrl.createData()
    pin.framesForwardKinematics(model, data, plant.pin_configuration(plant.data.qpos))
    for side in ("left", "right"):
        for frame in (f"sole_{side}", f"ft_{side}"):
            assert np.allclose(data.oMf[model.getFrameId(frame)].translation, plant.data.site(frame).xpos,
                               atol=1e-6), frame
    mass_kg, _ = below_sensor(model, plant.cfg, "left")
    body = plant.model.body(plant.cfg.profile.foot_links["left"]).id
    # the controller's model comes through MuJoCo's saved MJCF, which writes six significant digits
    assert mass_kg == pytest.approx(plant.model.body_subtreemass[body], rel=1e-5)


def test_icub_holds_its_seat_under_torque_control():
    """With its soles and the seat's force where they are, the whole-body controller holds the seated posture: the
    ankles drift 0.05 rad, hips 0.04 (with the sole frames 5.5 cm off and the seat's force 5 cm behind the hips, the
    trunk fell 0.27 rad forward and the hips 0.19 back)."""
    plant = Plant(PlantConfig(robot="icub"))
    plant.settle(2.0)
    q0 = plant.q_ref.copy()
    plant.command(q0, feedforward="wbc")
    plant.step(int(1.0 / plant.cfg.timestep_s))
    drift = np.abs(plant.data.qpos[plant.qadr] - q0)
    assert drift.max() < 0.08, dict(zip(plant.joint_names, drift.round(3)))
    assert plant.chair_force_n() > 0.8 * 28.3 * 9.81                              # sitting on it, not on its feet


def test_icub_identification_finds_its_hidden_mass(tmp_path):
    """On its default plant (2.5 kg the CAD model lacks), the static postures give the true mass back, and the
    held-out COM better than CAD's (measured: 30.8 kg; 0.1 mm against CAD's 6.4 mm on 40 postures)."""
    postures = tmp_path / "postures"
    assert collect_postures(PlantConfig.load("default", "icub"), 24, postures, progress=False)["kept"] == 24
    result = identify(postures, "full", robot="icub")
    assert result.total_mass_kg == pytest.approx(28.35 + 2.5, rel=0.02)
    assert result.eval_rms_m < min(0.002, result.cad_eval_rms_m)


def test_icub_stands_up_on_the_optimised_plan_its_lateral_joints_held(tmp_path, capsys):
    """By default the rise is optimised as a whole (``--plan whole``), which plays shorter than the per-frame plan on
    iCub; the optimisation holds the lateral joints near the IK's (``WholeRiseConfig.lateral_weight``): free, it swung
    the torso's roll from -13 to +10 degrees and the hips' roll 13 degrees apart, and the robot fell back."""
    out = tmp_path / "rt"
    code = sit2stand(["retarget", str(ROOT / "bags" / "natural"), "--robot", "icub", "--simulate", "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert code == 0 and "stood up" in capsys.readouterr().out, summary
    # default plant, CAD parameters; measured: the optimised plan played at 1.003 (the per-frame plan's checks 1.07),
    # knees 12.4 degrees (the human's 12.0), COM 0.6 cm
    assert summary["plan"] == "whole" and summary["plan_ratio_frames"] > summary["plan_ratio_whole"], summary
    assert summary["controller_plan_torques"], "the controller is given the optimised torques"
    assert summary["time_scale"] <= 1.05 and summary["standing_knees_match"], summary


def test_icub_stands_up_from_the_natural_demonstration_on_the_per_frame_plan(tmp_path, capsys):
    """``--plan frames``: the per-frame plan the live retargeter runs, without the optimisation."""
    out = tmp_path / "rt"
    code = sit2stand(["retarget", str(ROOT / "bags" / "natural"), "--robot", "icub", "--simulate", "--plan", "frames",
                      "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text())
    assert code == 0 and "stood up" in capsys.readouterr().out, summary
    assert summary["robot_seat_off_frame"] is not None
    # default plant, CAD parameters; measured: time scale 1.07, knees 12.4 degrees (the human's 12.0), pelvis 99.4 %
    # of its stance, COM 0.5 cm
    assert summary["time_scale"] <= 1.1 and summary["standing_knees_match"], summary
    assert summary["final_pelvis_height_ratio"] > 0.95 and summary["com_tracking_rms_m"] < 0.01, summary
    # exported in the file's own frames and senses: iCub's own URDF puts the soles on the floor, its knees negative
    assert sit2stand(["export", str(out), "--out", str(tmp_path / "m.csv")]) == 0
    rows = np.loadtxt(tmp_path / "m.csv", delimiter=",")
    profile = load_profile("icub")
    model = pin.buildModelFromXML(floating_base_removed(profile.urdf.read_text()), pin.JointModelFreeFlyer())
    data, names = model.createData(), [model.names[j] for j in range(2, model.njoints)]
    for row in (rows[0], rows[-1]):
        pin.framesForwardKinematics(model, data, np.concatenate([row[:7], row[7:]]))
        for sole in ("l_sole", "r_sole"):
            assert abs(data.oMf[model.getFrameId(sole)].translation[2]) < 0.005
        assert row[7 + names.index("l_knee")] < 0


COLLADA = """<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit meter="0.01"/><up_axis>Y_UP</up_axis></asset>
  <library_geometries><geometry id="g"><mesh>
    <source id="p"><float_array id="pa" count="12">0 0 0 10 0 0 0 10 0 0 0 10</float_array>
      <technique_common><accessor source="#pa" count="4" stride="3">
        <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
      </accessor></technique_common></source>
    <vertices id="v"><input semantic="POSITION" source="#p"/></vertices>
    <polylist count="1"><input semantic="VERTEX" source="#v" offset="0"/><vcount>4</vcount><p>0 1 2 3</p></polylist>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="s"><node id="n"><instance_geometry url="#g"/></node></visual_scene>
  </library_visual_scenes><scene><instance_visual_scene url="#s"/></scene>
</COLLADA>
"""


def test_collada_meshes_are_read_in_metres_with_z_up(tmp_path, monkeypatch):
    monkeypatch.setenv("SIT2STAND_CACHE", str(tmp_path / "cache"))
    dae = tmp_path / "quad.dae"
    dae.write_text(COLLADA)
    vertices, faces = collada_triangles(dae)
    assert faces.shape == (2, 3)                                    # a quadrilateral fanned into two triangles
    # centimetres to metres, and the file's y (up) is z: (x, y, z) -> (x, -z, y)
    assert np.allclose(vertices, [[0, 0, 0], [0.1, 0, 0], [0, 0, 0.1], [0, -0.1, 0]])
    obj = readable_mesh(dae)
    assert obj.suffix == ".obj" and readable_mesh(dae) == obj
    spec = mujoco.MjSpec()
    spec.add_mesh(name="m", file=str(obj))
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname="m")
    assert spec.compile().nmeshvert == 4                          # MuJoCo reads what was written
    broken = tmp_path / "broken.dae"
    broken.write_text("<COLLADA>")
    with pytest.raises(MeshError, match=re.escape(str(broken))):
        collada_triangles(broken)


def test_inertias_mujoco_refuses_become_small_balls_and_no_other_changes():
    link = '<link name="{}"><inertial><mass value="0.5"/><inertia ixx="{}" ixy="{}" ixz="0" iyy="0" iyz="0" ' \
           'izz="0"/></inertial></link>'
    moving = '<joint name="j" type="revolute"><parent link="a"/><child link="b"/></joint>'
    urdf = "<robot>" + link.format("a", 0, 0) + link.format("b", 0, 0) + link.format("c", -1e-20, 0) + \
        link.format("d", 0, 1e-20) + moving + "</robot>"
    fixed = inertias_mujoco_takes(urdf)
    assert link.format("a", 0, 0) in fixed                           # welded, all zero: MuJoCo takes it
    assert fixed.count('ixx="2e-05"') == 3                            # moved point mass, negative, products
    for robot in ("talos", "g1"):
        text = load_profile(robot).urdf_text()
        assert inertias_mujoco_takes(text) == text
    assert controller_model(PlantConfig(robot="icub")).nq == 7 + 29
