"""sit2stand.robot: TALOS in MuJoCo and Pinocchio (same joints, same CAD body), the plant's sensors and seating."""

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from sit2stand.robot.actuation import reference_at
from sit2stand.robot.model import PlantConfig, PlantConfigError, build_spec, controller_model
from sit2stand.robot.plant import Plant
from sit2stand.robot.postures import standing_qpos

DEFAULT = "default"             # the packaged plant (sit2stand/data/plants/default.yaml)


@pytest.fixture(scope="module")
def cad():
    return controller_model(PlantConfig())


def test_mujoco_and_pinocchio_have_the_same_joints_and_cad_com(cad):
    model = build_spec(PlantConfig(), plant=False).compile()
    data = mujoco.MjData(model)
    names = [model.joint(i).name for i in range(1, model.njnt)]
    assert names == list(cad.names[2:]) and len(names) == 32
    assert model.nu == 64   # a PD servo and a feed-forward motor per joint
    assert model.body_subtreemass[1] == pytest.approx(pin.computeTotalMass(cad), abs=1e-3)
    pdata = cad.createData()
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = pin.randomConfiguration(cad)
        q[:3] = rng.normal(size=3)
        data.qpos[:3], data.qpos[3:7], data.qpos[7:] = q[:3], [q[6], q[3], q[4], q[5]], q[7:]
        mujoco.mj_forward(model, data)
        assert np.abs(data.subtree_com[1] - pin.centerOfMass(cad, pdata, q)).max() < 1e-4


def test_unmodeled_masses_only_in_the_plant(cad):
    cfg = PlantConfig.load(DEFAULT)
    truth = build_spec(cfg, plant=True).compile()
    hidden = cfg.total_extra_mass()
    assert hidden == pytest.approx(26.0)
    assert truth.body_subtreemass[1] == pytest.approx(pin.computeTotalMass(cad) + hidden, abs=1e-3)
    assert pin.computeTotalMass(controller_model(cfg)) == pytest.approx(pin.computeTotalMass(cad))


def test_bad_plant_files_are_named(tmp_path):
    bad = tmp_path / "p.yaml"
    bad.write_text("timestep: 0.001\n")
    with pytest.raises(PlantConfigError, match="unknown field 'timestep'"):
        PlantConfig.load(bad)
    bad.write_text("unmodeled:\n  masses:\n    - {link: wing, mass_kg: 3}\n")
    with pytest.raises(PlantConfigError, match="unknown link 'wing'"):
        build_spec(PlantConfig.load(bad), plant=True)


def test_standing_robot_measures_its_cop_where_its_true_com_is():
    plant = Plant(PlantConfig.load(DEFAULT), with_chair=False)
    # the hidden masses sit behind: standing straight would put the true COM over the heels, so lean 0.1 rad
    qpos = standing_qpos(plant, 0.0, 0.0, -0.1, 0.0)
    plant.reset(qpos)
    plant.command(qpos[plant.qadr], feedforward="gravity")
    plant.step(3000)
    s = plant.sensors()
    assert not plant.fallen and s.cop_valid
    weight = plant.model.body_subtreemass[1] * 9.81
    fz = s.wrench_world["left"][2] + s.wrench_world["right"][2]
    assert fz == pytest.approx(weight, rel=0.01)                  # the F/T sensors carry the whole (true) weight
    assert abs(s.cop_m[0] - plant.true_com()[0]) < 0.005            # static: COP under the COM (1.2 mm measured)
    assert np.abs(s.tau).max() < plant.joints.effort.max()


def test_the_joint_servo_follows_the_command_along_its_velocity_and_acceleration():
    plant = Plant(PlantConfig.load(DEFAULT))
    plant.step(200)
    rng = np.random.default_rng(3)
    q, qd, qdd = (plant.q_ref + 0.01 * rng.standard_normal(plant.n), rng.standard_normal(plant.n),
                  rng.standard_normal(plant.n))
    for steps in (7, 100):                  # within the reference's extrapolation, then past it (held at its end)
        plant.command(q, qd, qdd)
        plant.step(steps)
        # the servo's target of the last step (taken at its start): the reference there, less the encoders' offset,
        # plus kd/kp times the reference's velocity
        q_t, qd_t = reference_at(q, qd, qdd, plant.t_s - plant.cfg.timestep_s - plant.ref.t_s)
        jm = plant.joints
        assert np.allclose(plant.data.ctrl[jm.pd_ids], q_t - plant.faults.q_offset + jm.kd / jm.kp * qd_t,
                           rtol=0, atol=1e-12)


def test_robot_stays_seated_on_the_chair():
    plant = Plant(PlantConfig.load(DEFAULT))
    plant.step(3000)                                               # settle onto the seat
    x0 = plant.data.qpos[:3].copy()
    plant.step(5000)
    assert not plant.fallen
    assert plant.chair_force_n() > 0.2 * plant.model.body_subtreemass[1] * 9.81   # 27 % measured (feet drawn back)
    assert np.linalg.norm(plant.data.qpos[:3] - x0) < 0.01         # pelvis moved < 1 cm in 5 s


def test_feet_sensing_is_consistent_with_itself_and_with_a_turned_sensor():
    cfg = PlantConfig.load(DEFAULT)
    plant = Plant(cfg)
    plant.step(500)
    feet, data = plant.feet, plant.data
    ground = feet.ground_reactions(data, feet.readings(data, np.zeros(12)))
    # the controller's quick vertical force is the z of the full ground reactions, the sensor errors aside
    unbiased = feet.ground_reactions(data, feet.readings(data, np.zeros(12)) - feet.bias)
    assert feet.vertical_force(data) == pytest.approx(unbiased[:, 2].sum(), rel=1e-9)
    # the two feet's COP: the moments about the origin (numpy's cross product) through the floor
    soles = data.site_xpos[feet.sites[2:]]
    moment = (ground[:, 3:] + np.cross(soles, ground[:, :3])).sum(axis=0)
    cop = feet.combined_cop(data, ground, 1.0)
    assert cop == pytest.approx([-moment[1] / ground[:, 2].sum(), moment[0] / ground[:, 2].sum(), 0.0], abs=1e-12)
    assert feet.combined_cop(data, ground * 0.0, 1.0) is None
    # each foot in world axes (numpy's products): its weight W and the leg's wrench balance the ground's, the moment
    # about the sole being arm x ground force + lever x W - the leg's torque
    R = data.site_xmat[feet.ft_sites].reshape(-1, 3, 3)
    f_leg, t_leg, lever = (np.einsum("kij,kj->ki", R, v) for v in
                           (*feet.readings(data, np.zeros(12)).reshape(2, 2, 3).transpose(1, 0, 2), feet.lever_m))
    arm, weight = data.site_xpos[feet.ft_sites] - soles, np.outer(feet.weight_n, (0.0, 0.0, 1.0))
    assert np.allclose(ground[:, :3], weight - f_leg, rtol=0, atol=1e-9)
    assert np.allclose(ground[:, 3:], np.cross(arm, ground[:, :3]) + np.cross(lever, weight) - t_leg, rtol=0,
                       atol=1e-9)
    # a sensor mounted turned 0.1 rad about z reads the same wrench turned back
    cfg.unmodeled.ft_rotation_rad["left"] = (0.0, 0.0, 0.1)
    turned = Plant(cfg).feet                                  # the same sensors, one mounted turned
    raw = turned.readings(data, np.zeros(12)) - turned.bias
    R = pin.exp3(np.array([0.0, 0.0, 0.1]))
    straight = feet.readings(data, np.zeros(12)) - feet.bias
    assert raw[0, :3] == pytest.approx(straight[0, :3] @ R, abs=1e-6)
    assert raw[1] == pytest.approx(straight[1], abs=1e-9)
