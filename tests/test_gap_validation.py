"""The model gap's honesty checks without simulation: plausibility bounds per kind, the symmetric-evidence check,
the description of an unexplained residual, the new library signatures and the plant alterations."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from sit2stand.errors import InputError
from sit2stand.gap import validate as contact
from sit2stand.gap.control import feedforward_rate
from sit2stand.gap.effects import Effect, alter_model, unmodeled_from
from sit2stand.gap.human import map_departures, within_spread
from sit2stand.gap.plausibility import Limits, cancelling_offsets, lopsided, mirror, refusal, side_of
from sit2stand.gap.residuals import coulomb_signature, fit_backlash_widths, fit_coulomb_widths, joint_columns
from sit2stand.gap.select import Candidate, Selected, where_and_shape
from sit2stand.gap.validate import INCONSTANT_Z, effect_theta, half_sizes
from sit2stand.robot.model import PlantConfig, PlantConfigError, controller_model
from sit2stand.robot.plant import Plant
from sit2stand.robot.postures import standing_qpos

ARM = Limits(effort_nm=17.86, range_rad=2.36, link_mass_kg=1.1)


@pytest.mark.parametrize("kind, location, theta, ok", [
    ("joint_offset", "arm_left_6_joint", [102.0], False),          # the 102 rad offset
    ("joint_offset", "arm_left_6_joint", [0.03], True),
    ("extra_mass", "arm_left_4_link", [-2.0, 0.0, 0.0, -0.2], False),   # lighter than the link itself
    ("extra_mass", "arm_left_4_link", [-0.5, 0.0, 0.0, -0.05], True),
    ("extra_mass", "arm_left_4_link", [2.0, 0.0, 0.0, -1.4], False),    # 0.7 m from its link
    ("extra_mass", "arm_left_4_link", [45.0, 0.0, 0.0, 0.0], False),
    ("torque_bias", "arm_left_4_joint", [12.0], False),            # beyond half the sensor's 17.9 N m range
    ("torque_bias", "arm_left_4_joint", [4.0], True),
    ("torque_gain", "arm_left_4_joint", [-0.6], False),
    ("ft_bias", "ft_left/fz", [80.0], False),
    ("ft_bias", "ft_left/tx", [3.0], True),
    ("viscous_friction", "arm_left_4_joint", [-1.0], False),       # negative friction is not friction
    ("joint_spring", "arm_left_4_joint", [40.0, 1.0], True),
    ("rotor_inertia", "arm_left_4_joint", [-0.2], False),
    ("actuator_delay", "all joints", [0.0004], False),
])
def test_bounds_refuse_what_is_not_physical(kind, location, theta, ok):
    why = refusal(kind, location, np.array(theta), ARM)
    assert (why is None) == ok, why


def test_mirror_and_side():
    assert mirror("tau/leg_left_4_joint") == "tau/leg_right_4_joint"
    assert mirror("ft_right/fz") == "ft_left/fz"
    assert side_of("leg_left_3_link") == "left" and side_of("torso_2_link") is None


def _fake_dataset(left: np.ndarray, right: np.ndarray):
    """Two joint channels, one recording, unit floors."""
    e = np.column_stack([left, right])
    ev = SimpleNamespace(e=e, valid=np.ones_like(e, bool))
    return SimpleNamespace(channels=["tau/leg_left_4_joint", "tau/leg_right_4_joint"], evaluations=[ev],
                           floors=[np.ones(2)])


def test_one_sided_effect_is_refused_only_when_the_mirror_shows_the_same():
    rng = np.random.default_rng(0)
    shape = np.sin(np.linspace(0, 20, 800)) * 10
    cand = Candidate("extra_mass", "leg_left_4_link", ["m"], np.zeros((800, 1)))
    sel = Selected(cand, np.array([1.0]), np.eye(1), 0.9, -100.0)

    def contribution(r, s):
        return np.column_stack([shape, np.zeros(800)])

    symmetric = _fake_dataset(shape + rng.normal(size=800), shape + rng.normal(size=800))
    assert [k for k, _ in lopsided(symmetric, [sel], contribution)] == ["extra_mass@leg_left_4_link"]
    one_sided = _fake_dataset(shape + rng.normal(size=800), rng.normal(size=800))
    assert lopsided(one_sided, [sel], contribution) == []


def _fake_recording(n: int = 600):
    t = np.linspace(0, 12, n)
    q = np.column_stack([0.5 * np.sin(t), 0.3 * np.cos(0.7 * t)])
    qd = np.gradient(q, t, axis=0)
    qdd = np.gradient(qd, t, axis=0)
    return SimpleNamespace(t_s=t, q=q, qd=qd, qdd=qdd, joint_names=["leg_left_4_joint", "torso_2_joint"])


def test_unexplained_residual_is_described_by_where_and_shape():
    rec = _fake_recording()
    ds = SimpleNamespace(recordings=[rec], labels=[np.full(len(rec.t_s), "moving", dtype=object)])
    ok = np.ones(len(rec.t_s), bool)
    spring_like = 40.0 * rec.q[:, 0]
    d = where_and_shape(ds, 0, "tau/leg_left_4_joint", spring_like, ok, floor=0.2)
    assert d["shape"].startswith("position-dependent (follows leg_left_4_joint")
    assert d["above_s"] is not None and d["z_by_phase"]["moving"] > 3
    damper_like = 5.0 * rec.qd[:, 1]
    assert where_and_shape(ds, 0, "base/force_z", damper_like, ok, 0.2)["shape"].startswith("velocity-dependent")
    lab = np.where(rec.t_s < 1.0, "seat-off", "standing").astype(object)
    ds.labels = [lab]
    burst = np.where(rec.t_s < 1.0, 5.0, 0.0)
    assert where_and_shape(ds, 0, "tau/torso_2_joint", burst, ok, 0.2)["shape"].startswith("one phase only")


def test_spring_and_rotor_inertia_signatures():
    rec = _fake_recording()
    n = len(rec.t_s)
    ev = SimpleNamespace(e=np.zeros((n, 8)), n_joints=2, ctrl_law=None)
    spring = joint_columns(rec, ev, "joint_spring", 0)
    assert spring.shape == (n, 8, 2)
    assert np.allclose(spring[:, 6, 0], rec.q[:, 0]) and np.allclose(spring[:, 6, 1], 1.0)
    assert np.allclose(joint_columns(rec, ev, "rotor_inertia", 1)[:, 7, 0], rec.qdd[:, 1])
    # k (q - q_rest) = k q - k q_rest: the preload column carries -k q_rest
    assert np.allclose(effect_theta(Effect("joint_spring", value=40.0, rest_rad=0.1)), [40.0, -4.0])


def test_alterations_change_the_compiled_plant():
    plant = Plant(PlantConfig(), with_chair=False)
    m = plant.model
    knee = m.joint("leg_left_4_joint").id
    shank = m.body("leg_left_5_link").id
    arm0 = float(m.dof_armature[m.jnt_dofadr[knee]])
    pos0 = m.body_pos[m.body("leg_right_5_link").id].copy()
    forearm = m.body("arm_left_4_link").id
    mass0 = float(m.body_mass[forearm])
    effects = [Effect("extra_mass", "arm_left_4_link", mass_kg=-0.5, pos_m=(0.0, 0.0, -0.1)),
               Effect("joint_spring", "leg_left_4_joint", value=40.0, rest_rad=0.2),
               Effect("rotor_inertia", "leg_left_4_joint", value=0.5),
               Effect("link_length", "leg_*_5_link", value=1.05),
               Effect("contact_softness", "soles", value=0.05)]
    alter_model(m, effects)
    assert abs(m.body_mass[forearm] - (mass0 - 0.5)) < 1e-12     # a lighter link is lighter in the replay too
    assert m.jnt_stiffness[knee] == 40.0 and m.qpos_spring[m.jnt_qposadr[knee]] == 0.2
    assert abs(m.dof_armature[m.jnt_dofadr[knee]] - arm0 - 0.5) < 1e-12
    assert np.allclose(m.body_pos[m.body("leg_right_5_link").id], 1.05 * pos0)
    assert m.geom_solref[m.geom("sole_box_left").id][0] == 0.05 and shank > 0
    assert unmodeled_from(effects).masses == []          # none of these is a plant-file field
    with pytest.raises(InputError, match="no joint matches"):
        alter_model(m, [Effect("joint_spring", "knee", value=1.0)])


def test_contact_time_constant_is_searched_on_the_replay(monkeypatch):
    """The search alone, on a stand-in replay whose COP error grows with the distance to a 0.05 s sole."""
    def replay(ds, effects, nominal=None):
        tc = next((e.value for e in effects if e.kind == "contact_softness"), 0.02)
        return {0: {"tc": tc}}

    def z(res):
        return {(0, "replay/cop_x"): 40.0 * abs(np.log(res[0]["tc"] / 0.05)) + 0.5, (0, "replay/feet_fz"): 0.5}

    monkeypatch.setattr(contact, "replay_effects", replay)
    monkeypatch.setattr(contact, "replay_residuals", lambda ds, sims: sims)
    monkeypatch.setattr(contact, "replay_z", z)
    found, sims = contact.fit_contact(None, [], {0: {"tc": 0.02}}, lambda msg: None)
    assert found is not None and abs(found.value - 0.05) < 0.05 * 0.05, found
    assert sims[0]["tc"] == found.value
    # already agreeing: nothing searched, nothing named
    assert contact.fit_contact(None, [], {0: {"tc": 0.05}}, lambda msg: None)[0] is None


def _offset(joint: str, rad: float) -> Selected:
    return Selected(Candidate("joint_offset", joint, ["joint_offset [rad]"], np.zeros((1, 1))), np.array([rad]),
                    np.eye(1), 0.1, -50.0)


def test_offsets_that_cancel_along_a_chain_are_refused_as_a_turned_frame():
    """The torso's pitch axis tilted toward x was once named as +0.08 rad at torso_1 (yaw) and -0.08 rad at both
    shoulders' yaw joints: a frame turned between them, not three encoder errors."""
    model = controller_model()
    turned = [_offset("torso_1_joint", 0.08), _offset("arm_left_1_joint", -0.08), _offset("arm_right_1_joint", -0.07)]
    refused = dict(cancelling_offsets(model, turned))
    assert set(refused) == {"joint_offset@torso_1_joint", "joint_offset@arm_left_1_joint",
                            "joint_offset@arm_right_1_joint"}
    assert "cancel along the chain" in refused["joint_offset@torso_1_joint"]
    # one encoder off, or offsets that add up, or cancelling offsets on joints of different axes or other chains
    assert cancelling_offsets(model, [_offset("torso_1_joint", 0.08)]) == []
    assert cancelling_offsets(model, [_offset("torso_1_joint", 0.08), _offset("arm_left_1_joint", 0.08)]) == []
    assert cancelling_offsets(model, [_offset("torso_1_joint", 0.08), _offset("arm_left_2_joint", -0.08)]) == []
    assert cancelling_offsets(model, [_offset("leg_left_1_joint", 0.08), _offset("arm_left_1_joint", -0.08)]) == []
    assert cancelling_offsets(model, [_offset("torso_1_joint", 0.08), _offset("arm_left_1_joint", -0.04)]) == []


def test_an_effect_whose_size_changes_along_the_run_is_told_from_a_constant_one():
    rng = np.random.default_rng(1)
    n = 4000
    x = np.sin(np.linspace(0, 60, n))[:, None]
    first = np.arange(n) < n // 2
    series = np.zeros(n, int)
    constant = 0.5 * x[:, 0] + rng.normal(size=n)
    a, b, z = half_sizes(constant, [x], series, first)[0]
    assert z < INCONSTANT_Z and abs(a - 0.5) < 0.1 and abs(b - 0.5) < 0.1
    growing = np.where(first, 0.4, 0.6) * x[:, 0] + rng.normal(size=n)     # a proxy: its size follows the motion
    a, b, z = half_sizes(growing, [x], series, first)[0]
    assert z > INCONSTANT_Z and a < b


def test_an_ft_sensor_mounted_turned_reads_part_of_the_load_sideways(tmp_path):
    """The plant's F/T mounting error (outside the workflow's library): the left sensor turned 0.05 rad about x
    reads about 5 % of its vertical load as a sideways force; the right one reads as before."""
    readings = {}
    for turned in (False, True):
        cfg = PlantConfig(seed=3)
        cfg.unmodeled = unmodeled_from([Effect("ft_rotation", "ft_left", value=0.05)] if turned
                                       else [])
        plant = Plant(cfg, with_chair=False)
        qpos = standing_qpos(plant, 0.0, 0.0, 0.0, 0.0)
        plant.reset(qpos)
        plant.command(qpos[plant.qadr], feedforward="gravity")
        plant.step(500)
        readings[turned] = {s: plant.sensors().ft[s] for s in ("left", "right")}
    left0, left1 = readings[False]["left"], readings[True]["left"]
    assert abs(left1[1] - left0[1]) == pytest.approx(0.05 * abs(left0[2]), rel=0.1)
    assert np.allclose(readings[True]["right"][:3], readings[False]["right"][:3], atol=5.0)
    bad = tmp_path / "p.yaml"
    bad.write_text("unmodeled:\n  ft_rotation_rad: {left: [0.1, 0.2]}\n")
    with pytest.raises(PlantConfigError, match="ft_rotation_rad.left: needs 3 values"):
        PlantConfig.load(bad)


@pytest.mark.parametrize("true_v0", [0.002, 0.02])
def test_each_joints_coulomb_transition_speed_is_fitted_from_its_residual(true_v0):
    """A slow shoulder's dry friction changes sign within 0.002 rad/s, a loaded ankle's over 0.01-0.02; the one
    width for all (0.03 rad/s) once made the shoulder's friction look like a spring."""
    rng = np.random.default_rng(2)
    rec = _fake_recording()
    rec.qd = 0.1 * np.column_stack([np.sin(rec.t_s), np.cos(0.5 * rec.t_s)])     # slow: 0.1 rad/s at most
    rec.static = False
    e = np.zeros((len(rec.t_s), 8))
    e[:, 6] = 2.5 * coulomb_signature(rec.qd[:, 0], true_v0) + rng.normal(0, 0.2, len(rec.t_s))
    ev = SimpleNamespace(e=e, valid=np.ones_like(e, bool), n_joints=2, coulomb_v0=None, ctrl_law=None)
    fit_coulomb_widths([rec], [ev])
    assert ev.coulomb_v0[0] == pytest.approx(true_v0)
    col = joint_columns(rec, ev, "coulomb_friction", 0)[:, 6, 0]
    assert np.allclose(col, coulomb_signature(rec.qd[:, 0], true_v0))


def test_a_gears_play_is_a_dead_zone_in_the_joint_torque():
    """Backlash of +-b: the joint gets nothing while the motor's drive (PD + feed-forward) stays within +-kp b, and
    the drive less kp b beyond it; the other joints are untouched."""
    cfg = PlantConfig()
    cfg.unmodeled.backlash_rad = {"arm_left_4_joint": 0.01}
    plant = Plant(cfg, with_chair=False)
    j = plant.joint_names.index("arm_left_4_joint")
    q = plant.data.qpos[plant.qadr].copy()
    ff = np.zeros(plant.n)
    ff[j] = 2.0
    for u, expected in [(0.005, 0.0), (-0.009, 0.0), (0.03, 0.02), (-0.02, -0.01)]:
        target = q.copy()
        target[j] += u - ff[j] / plant.joints.kp[j]          # the servo's target that asks for kp u in all
        out = plant._dead_zone(target, ff)
        torque = plant.joints.kp * (out - q) + ff
        assert torque[j] == pytest.approx(plant.joints.kp[j] * expected, abs=1e-9)
        others = np.arange(plant.n) != j
        assert np.allclose(out[others], target[others])


@pytest.mark.parametrize("true_b", [0.002, 0.008])
def test_backlash_signature_and_its_width_are_fitted_from_the_controller_channel(true_b):
    """The controller channel of joint 0 carries -clip(drive, +-kp b) (gap.control); the width is found on the grid
    and the signature at that width fits the residual exactly, with b as its coefficient."""
    rng = np.random.default_rng(5)
    rec = _fake_recording()
    n = len(rec.t_s)
    kp = np.array([400.0, 1600.0])
    drive = np.column_stack([8.0 * np.sin(2.0 * rec.t_s), 30.0 + np.zeros(n)])
    e = np.zeros((n, 10))
    e[:, 8] = -np.clip(drive[:, 0], -kp[0] * true_b, kp[0] * true_b) + rng.normal(0, 0.05, n)
    ev = SimpleNamespace(e=e, valid=np.ones_like(e, bool), n_joints=2, ctrl_law=np.zeros((n, 2)),
                         ctrl_drive=drive, ctrl_kp=kp, backlash_b0=None)
    fit_backlash_widths([rec], [ev])
    assert ev.backlash_b0[0] == pytest.approx(true_b)
    col = joint_columns(rec, ev, "backlash", 0)
    assert np.allclose(col[:, :8], 0.0) and np.allclose(col[:, 9], 0.0)     # the controller channel alone
    b_hat = float(col[:, 8, 0] @ e[:, 8] / (col[:, 8, 0] @ col[:, 8, 0]))
    assert b_hat == pytest.approx(true_b, rel=0.05)
    assert refusal("backlash", "arm_left_4_joint", np.array([-0.004]), Limits()) is not None
    assert refusal("backlash", "arm_left_4_joint", np.array([0.004]), Limits()) is None


def test_a_bodys_own_variation_explains_departures_within_its_spread_and_not_beyond():
    """Three segments' mass signatures (noise units) whose masses may depart 8 % from the table: departures within that
    spread are recovered as such; a load of 60 % of the first segment's mass (7.5 sd) is past it."""
    rng = np.random.default_rng(0)
    n = 600
    Xv = 20.0 * rng.normal(size=(n, 3))
    sd = np.full(3, 0.08)
    own = Xv @ np.array([0.05, -0.08, 0.04]) + rng.normal(size=n)
    delta, left = map_departures(own, Xv, sd, frac=1.0)
    assert np.allclose(delta, [0.05, -0.08, 0.04], atol=0.01) and np.std(left) < 1.1
    assert within_spread(delta, sd)
    delta, _ = map_departures(own + 0.6 * Xv[:, 0], Xv, sd, frac=1.0)
    assert not within_spread(delta, sd) and delta[0] == pytest.approx(0.65, abs=0.02)
    # the data counted at 1 % of their rows: the prior holds the departures back
    assert abs(map_departures(own, Xv, sd, frac=1e-4)[0][0]) < 0.04


def test_the_feed_forwards_rate_holds_over_samples_without_a_command():
    """The first sample of a recording comes before any command: its feed-forward is unset (0). The rate is taken
    over the commanded samples only, the uncommanded one holding its neighbour's value: a ramp of 2 N m/s reads
    about 2 N m/s from the first commanded sample on, not the jump from 0 (which, times the delay, made a
    still-phase residual the plant never had)."""
    t = np.arange(200) * 0.02
    ff = np.stack([60.0 + 2.0 * t, -5.0 + 0.0 * t], axis=1)
    valid = np.ones(len(t), bool)
    valid[0] = False
    ff[0] = 0.0
    rate = feedforward_rate(ff, t, valid)
    np.testing.assert_allclose(rate[4:], [[2.0, 0.0]] * (len(t) - 4), atol=1e-9)
    assert np.all(np.abs(rate[:4, 0]) < 3.0) and np.all(np.abs(rate[:4, 1]) < 1e-9)  # -0.04 to 2.2 (a jump: 3,000)
    assert np.all(feedforward_rate(ff, t, np.zeros(len(t), bool)) == 0.0)



def test_an_effect_round_trips_as_plain_data_and_bad_data_names_the_file():
    """Effect.as_dict keeps the fields a kind has (no mass on a spring, no rest angle on a mass) and from_dict reads
    it back; an unknown kind or field, or a size that is not a number, is an error naming the file and the field."""
    spring = Effect("joint_spring", "leg_left_4_joint", value=40.0, rest_rad=0.2, ci95=1.5, unit="N m/rad")
    mass = Effect("extra_mass", "torso_2_link", mass_kg=2.0, pos_m=(0.0, 0.1, 0.2), members=("torso_2_link",))
    assert set(spring.as_dict()) == {"kind", "location", "value", "rest_rad", "ci95", "unit"}
    assert set(mass.as_dict()) == {"kind", "location", "mass_kg", "pos_m", "members"}
    for e in (spring, mass, Effect("joint_axis", "leg_left_4_joint", value=0.1)):
        assert Effect.from_dict(e.as_dict()) == e
    assert mass.key == "extra_mass@torso_2_link" and mass.size == 2.0 and spring.size == 40.0
    with pytest.raises(InputError, match=r"model\.yaml: an effect needs a kind"):
        Effect.from_dict({"kind": "gremlin", "location": "x"}, "model.yaml")
    with pytest.raises(InputError, match=r"model\.yaml: effect backlash: unknown field\(s\) width"):
        Effect.from_dict({"kind": "backlash", "location": "x", "width": 1.0}, "model.yaml")
    with pytest.raises(InputError, match="value is not a number"):
        Effect.from_dict({"kind": "backlash", "location": "x", "value": "wide"}, "model.yaml")
