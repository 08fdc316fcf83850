"""sit2stand.human.skeleton: the Pinocchio skeleton, its markers, extra masses and the MJCF of the same body."""

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from sit2stand.human.skeleton import PLUG_IN_GAIT, ExtraMass, Subject, build_human, standing_configuration, to_mjcf


def test_degrees_of_freedom_markers_and_mass():
    human = build_human(Subject(1.8, 82.0, "male"))
    assert human.model.nv >= 30 and human.model.nq == human.model.nv + 1   # free-flyer quaternion
    assert set(PLUG_IN_GAIT) <= set(human.marker_frames)
    assert human.total_mass == pytest.approx(82.0)
    assert human.model.lowerPositionLimit[7:].max() < human.model.upperPositionLimit[7:].min() + 10


def test_standing_posture_has_the_soles_on_the_floor_and_com_at_55_to_58_percent():
    human = build_human(Subject(1.75, 75.0))
    q = standing_configuration(human)
    data = human.model.createData()
    com = pin.centerOfMass(human.model, data, q)
    assert 0.55 < com[2] / 1.75 < 0.58
    pin.framesForwardKinematics(human.model, data, q)
    for marker in ("LHEE", "RHEE", "LTOE", "RTOE"):
        assert abs(data.oMf[human.marker_frames[marker]].translation[2] - 0.025) < 0.01
    head = data.oMf[human.marker_frames["LFHD"]].translation[2]
    assert 1.55 < head < 1.75


def test_extra_mass_moves_the_com():
    base = build_human()
    heavy = build_human(Subject(extra=[ExtraMass.parse("trunk:8:-0.2,0,0")]))
    q = standing_configuration(base)
    c0 = pin.centerOfMass(base.model, base.model.createData(), q)
    c1 = pin.centerOfMass(heavy.model, heavy.model.createData(), q)
    assert heavy.total_mass == pytest.approx(83.0)
    # 8 kg, 20 cm behind the torso COM: the whole-body COM moves back by about 8 * 0.2 / 83 m (plus the shift
    # of the torso COM itself, which the extra mass also drags)
    assert c1[0] - c0[0] < -0.015


@pytest.mark.parametrize("text, match", [("wing:3", "unknown segment"), ("trunk", "SEGMENT:KG"),
                                         ("trunk:-1", "positive"), ("trunk:2:1,2", "three offset")])
def test_extra_mass_parsing_errors(text, match):
    with pytest.raises(ValueError, match=match):
        ExtraMass.parse(text)


def test_mjcf_is_the_same_body_as_pinocchio():
    human = build_human(Subject(1.68, 61.0, "female", lengths={"thigh": 1.05}, extra=[ExtraMass.parse("head:1")]))
    mj = mujoco.MjModel.from_xml_string(to_mjcf(human))
    md = mujoco.MjData(mj)
    data = human.model.createData()
    assert mj.nq == human.model.nq and mj.body_subtreemass[1] == pytest.approx(human.total_mass, abs=1e-3)
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = pin.randomConfiguration(human.model)
        q[:3] = rng.normal(size=3)
        md.qpos[:3], md.qpos[3:7] = q[:3], [q[6], q[3], q[4], q[5]]   # MuJoCo quaternion is w, x, y, z
        for j in range(2, human.model.njoints):
            md.qpos[mj.joint(human.model.names[j]).qposadr[0]] = q[human.model.joints[j].idx_q]
        mujoco.mj_forward(mj, md)
        com = pin.centerOfMass(human.model, data, q)
        assert np.abs(md.subtree_com[1] - com).max() < 1e-5
        pin.framesForwardKinematics(human.model, data, q)
        assert np.allclose(md.site("LTOE").xpos, data.oMf[human.marker_frames["LTOE"]].translation, atol=1e-5)
