"""sit2stand.gap.kinematics: the legs' kinematic errors in the controller's model match the plant's, and the soles'
closure names them (the workflow's runs on hidden plants are in test_gap.py)."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from sit2stand.gap.effects import Effect, alter_model, tilted_axis
from sit2stand.gap.kinematics import _pin_q, contact_points, kinematic_model
from sit2stand.robot.model import PlantConfig, controller_model
from sit2stand.robot.plant import Plant
from sit2stand.robot.profile import load_profile

TALOS = load_profile("talos")

EFFECTS = {
    "none": [],
    "shanks longer": [Effect("link_length", "leg_*_5_link", value=1.05)],
    "knee axis": [Effect("joint_axis", "leg_left_4_joint", value=0.09, value_2=-0.04)],
    "hip axis, thigh": [Effect("joint_axis", "leg_right_3_joint", value=-0.07),
                        Effect("link_length", "leg_right_4_link", value=0.96)],
}


@pytest.mark.parametrize("name", list(EFFECTS))
def test_the_models_kinematic_errors_are_the_plants(name):
    """The feet of the altered controller model (Pinocchio) are where the altered plant (MuJoCo) puts them, in
    bent postures: the closure fits the same error that the hidden-effect plants carry."""
    effects = EFFECTS[name]
    plant = Plant(PlantConfig(), with_chair=False)
    alter_model(plant.model, effects)
    model = kinematic_model(controller_model(PlantConfig()), effects)
    data = model.createData()
    rng = np.random.default_rng(3)
    names = plant.joint_names
    for _ in range(5):
        q = plant.q_ref + rng.uniform(-0.4, 0.4, len(names))
        base = np.array([0.1, -0.05, 1.0, *pin.Quaternion(pin.rpy.rpyToMatrix(0.05, 0.2, -0.1)).coeffs()[[3, 0, 1, 2]]])
        plant.data.qpos[:7] = base
        plant.data.qpos[plant.qadr] = q - plant.faults.q_offset
        mujoco.mj_kinematics(plant.model, plant.data)
        pin.framesForwardKinematics(model, data, _pin_q(model, names, base, q))
        for side in ("left", "right"):
            body = f"leg_{side}_6_link"
            where = plant.data.xpos[mujoco.mj_name2id(plant.model, mujoco.mjtObj.mjOBJ_BODY, body)]
            assert np.allclose(data.oMf[model.getFrameId(body)].translation, where, atol=1e-6), (side, name)


def test_a_tilt_turns_the_axis_by_its_angle_toward_the_stated_directions():
    y = np.array([0.0, 1.0, 0.0])
    a = tilted_axis(y, 0.1, 0.0)
    assert np.isclose(np.linalg.norm(a), 1.0) and np.isclose(np.arccos(a @ y), 0.1)
    assert np.isclose(a[0], np.sin(0.1))           # toward y x z = +x
    b = tilted_axis(y, 0.0, 0.1)
    assert np.isclose(b[2], -np.sin(0.1))          # toward y x x = -z


def test_the_point_that_stays_put_is_the_edge_a_foot_rolls_on():
    """Flat (COP well inside): the sole point; COP at the inner (right) edge of a left foot: that edge's middle;
    at the toe's left corner: that corner."""
    fz = 400.0
    wrench = np.array([[0, 0, fz, 0.01 * fz, -0.03 * fz, 0],          # COP (0.03, 0.01): flat
                       [0, 0, fz, -0.06 * fz, -0.02 * fz, 0],          # COP (0.02, -0.06): right edge
                       [0, 0, fz, 0.06 * fz, -0.12 * fz, 0]])          # COP (0.12, 0.06): toe, left corner
    points, kinds = contact_points(wrench, TALOS.sole)
    assert np.allclose(points[0], 0.0) and kinds[0] == 0
    assert np.allclose(points[1], [0.0, -TALOS.sole.half_size_m[1], 0.0])
    assert np.allclose(points[2], [TALOS.sole.centre_x_m + TALOS.sole.half_size_m[0], TALOS.sole.half_size_m[1], 0.0])
    assert len(set(kinds.tolist())) == 3
