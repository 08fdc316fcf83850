"""Streaming retargeting on the shipped elderly-like demonstration: COM map, per-frame IK, retiming, ZMP."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from sit2stand.errors import InputError
from sit2stand.human.demonstration_bag import write_demonstration_bag
from sit2stand.human.offline import read_trial
from sit2stand.human.synth import SynthConfig, synthesize
from sit2stand.retarget.feasibility import plan_dynamics, plan_zmp, support_margin, zmp_at_scale
from sit2stand.retarget.player import LIFT_OFF_SPEED_RAD_S, MAX_TIME_SCALE_RATE, PlanPlayer
from sit2stand.retarget.robot import robot_setup
from sit2stand.retarget.stream import Retargeter, retarget_sequence

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def elderly():
    trial = read_trial(ROOT / "bags" / "elderly")
    t, com = trial.truth
    com_h = np.stack([np.interp(trial.marker_t_s, t, com[:, i]) for i in range(3)], axis=1)
    chair = next(p for p in trial.plates if p.name == "chair")
    fz = np.interp(trial.marker_t_s, chair.t_s, chair.force_n[:, 2])
    return trial, com_h, fz


@pytest.fixture(scope="module")
def retargeted(elderly):
    trial, com_h, fz = elderly
    robot = robot_setup()
    rt = Retargeter(robot)
    rt.calibrate(trial.marker_names, trial.positions[0], trial.valid[0], com_h[0])
    player = PlanPlayer(robot.model, 0.01, robot.support_xy, margin_m=0.06)
    frames, cmds = retarget_sequence(rt, player, trial.marker_t_s, trial.positions, trial.valid, com_h, fz)
    return robot, rt, frames, cmds, player


def test_com_map_is_monotone_and_passes_through_its_knots(retargeted):
    robot, rt, *_ = retargeted
    ankle_h = rt.com_map.human_ankle_x_m
    xs = ankle_h + np.linspace(rt.com_map.knots_h[0], 0.1, 200) / rt.com_map.scale
    r = rt.com_target_x(xs)
    assert np.all(np.diff(r) >= -1e-12), "the COM map must be monotone"
    knots = rt.com_target_x(ankle_h + rt.com_map.knots_h / rt.com_map.scale) - robot.ankle_left[0]
    assert np.allclose(knots, rt.com_map.knots_r, atol=1e-9)
    # the seated start maps to the robot's own seated COM, the seat-off knot lies inside the feet
    data = rt.model.createData()
    assert abs(rt.com_target_x(ankle_h + rt.com_map.knots_h[0] / rt.com_map.scale) - pin.centerOfMass(rt.model, data,
                                                                                      robot.q_seated)[0]) < 1e-9
    assert robot.heel_x_m < robot.ankle_left[0] + rt.com_map.knots_r[1] < robot.toe_x_m


def test_calibration_fixes_markers_to_their_own_body_parts(retargeted):
    _, rt, *_ = retargeted
    links = rt.markers.marker_map.links
    assert all(links[m] == rt.model.names[1] for m in ("LASI", "RASI", "LPSI", "RPSI"))
    assert links["C7"].startswith("torso_") and links["LFHD"].startswith("head_")
    assert links["LKNE"].startswith("leg_left_") and links["RWRA"].startswith("arm_right_")


def test_every_frame_is_finite_within_limits_and_the_com_equality_holds_where_feasible(retargeted):
    robot, rt, frames, *_ = retargeted
    model = rt.model
    qs = np.array([f.q for f in frames])
    assert np.all(np.isfinite(qs))
    assert np.all(qs[:, 7:] >= model.lowerPositionLimit[7:] - 1e-9)
    assert np.all(qs[:, 7:] <= model.upperPositionLimit[7:] + 1e-9)
    feasible = np.array([f.ik.feasible for f in frames])
    assert feasible.mean() > 0.85, f"only {feasible.mean():.0%} of the frames feasible"
    for f in frames:
        err = np.abs(f.com - f.com_target)[list(f.com_axes)].max()
        if f.ik.feasible:
            assert err < 1e-3, f"COM equality off by {err * 1e3:.2f} mm at t={f.t_s:.2f}"
        assert f.ik.sole_error < 1e-3, "the feet must stay where they are"
    # hips on the seat until the robot's seat-off, which comes no earlier than the human's
    so = next(i for i, f in enumerate(frames) if not f.seated)
    assert frames[so].human_seat_off
    assert np.allclose(qs[:so, [0, 2]], qs[0, [0, 2]], atol=1e-3)
    # standing at the end: the pelvis well above the seat
    assert qs[-1, 2] > qs[0, 2] + 0.2


def test_after_the_robots_seat_off_its_hips_rise_clear_of_the_seat(retargeted):
    """From the robot's seat-off the pelvis stays at least the growing clearance above its seated height, and is
    the whole ``seat_clearance_m`` above it from ``seat_clearance_s`` on: hips the plan has taken off the seat are
    off it."""
    _, rt, frames, *_ = retargeted
    z0, lift, ramp_s = rt.base_seated[2], rt.cfg.seat_clearance_m, rt.cfg.seat_clearance_s
    so = next(i for i, f in enumerate(frames) if not f.seated)
    after = [f for f in frames[so:] if not f.seated]
    for f in after:
        r = min(1.0, (f.t_s - frames[so].t_s) / ramp_s)
        assert f.q[2] >= z0 + lift * r * r * (3 - 2 * r) - 1e-4, f"pelvis {(f.q[2] - z0) * 1e3:.1f} mm at {f.t_s:.2f} s"
    late = [f for f in after if f.t_s >= frames[so].t_s + ramp_s]
    assert late and min(f.q[2] for f in late) >= z0 + lift - 1e-4


def _played(robot, frames, **options):
    """The IK poses of ``frames`` through a fresh player: (commands, player)."""
    player = PlanPlayer(robot.model, 0.01, robot.support_xy, margin_m=0.06, **options)
    cmds = []
    for f in frames:
        player.push(f.q, not f.seated)
        c = player.pull()
        if c is not None:
            cmds.append(c)
    player.close()
    while not player.done:
        cmds.append(player.pull())
    return cmds, player


def test_a_command_pulled_before_its_frames_pose_is_pushed_is_the_one_pushing_first_gives(retargeted):
    """As the node streams (retarget_sequence), a frame's command is pulled before the frame's pose is pushed
    (pull(coming=1)): the plan frame that pose completes lies past the look-ahead window, so every command is the
    one of pushing first, from the same tick on."""
    robot, _, frames, pulled_first, _ = retargeted
    pushed_first, _ = _played(robot, frames)
    assert len(pulled_first) == len(pushed_first)
    for a, b in zip(pulled_first, pushed_first):
        assert a.t_plan_s == pytest.approx(b.t_plan_s, abs=1e-12) and a.time_scale == pytest.approx(b.time_scale)
        np.testing.assert_allclose(np.r_[a.q, a.v, a.a], np.r_[b.q, b.v, b.a], rtol=0, atol=1e-9)


def test_the_uniform_player_retimes_until_the_zmp_keeps_its_margin(retargeted):
    robot, rt, frames, _, _ = retargeted
    cmds, player = _played(robot, frames, retiming="uniform", max_time_scale_rate=1.5)
    on_feet = [c for c in cmds if c.on_feet]
    assert on_feet and min(c.margin_at_scale_m for c in on_feet) >= 0.06 - 1e-3
    assert player.time_scale > 1.0, "the human's timing is too fast for the robot: the plan must be slowed"
    scales = np.array([c.time_scale for c in cmds])
    assert np.all(np.diff(scales) >= -1e-12) and np.all(np.diff(scales) <= 1.5 * 0.01 + 1e-9)
    # the human's own timing would need the ZMP outside the margin somewhere on the feet
    qs = np.array([f.q for f in frames])
    feet = np.array([not f.seated for f in frames])
    zmp, _ = plan_zmp(rt.model, qs, 0.01)

    assert support_margin(zmp[feet, :2], robot.support_xy).min() < 0.06
    for c in cmds:
        assert np.all(np.isfinite(c.q)) and np.all(np.isfinite(c.v)) and np.all(np.isfinite(c.a))


def test_the_local_player_is_slower_only_where_a_frame_needs_it(retargeted):
    """The default player: each command at least as slow as its own frame needs (ZMP margin, torques), the time
    scale back at the human's 1.0 between and after, at a bounded rate, and the whole far shorter than the uniform
    player's."""
    robot, _, frames, cmds, player = retargeted
    scales = np.array([c.time_scale for c in cmds])
    assert np.abs(np.diff(scales)).max() <= MAX_TIME_SCALE_RATE * 0.01 + 1e-9
    need = np.array([player.frame_scale(int(round(c.t_plan_s / 0.01))) for c in cmds])
    assert np.all(scales >= need - MAX_TIME_SCALE_RATE * 0.01 - 1e-9), "a frame played faster than it can be"
    # the last commands may stay a little slow: the knees straighten toward the human's as it stands (the knee task)
    assert scales.max() > 1.5 and scales[-1] <= 1.05
    assert np.mean(scales < 1.0 + 1e-9) > 0.3, "the human's timing wherever the robot can follow it"
    on_feet = [c for c in cmds if c.on_feet]
    assert min(c.margin_at_scale_m for c in on_feet if player.frame_scale(int(round(c.t_plan_s / 0.01))) <
               player.max_time_scale) >= 0.06 - 1e-3
    # the commands' own ZMP (the warp's changes of speed included) leaves the feet only briefly
    assert np.mean([c.margin_m < 0 for c in on_feet]) < 0.05
    uniform, _ = _played(robot, frames, retiming="uniform")
    assert len(cmds) < 0.75 * len(uniform)


def test_zmp_at_scale_equals_the_zmp_of_the_slowed_plan():
    robot = robot_setup()
    model = robot.model
    rng = np.random.default_rng(0)
    q0 = robot.q_seated
    wiggle = [np.r_[np.zeros(6), 0.2 * np.sin(0.05 * k + rng.uniform(0, 1, model.nv - 6))] for k in range(60)]
    qs = np.array([pin.integrate(model, q0, dq) for dq in wiggle])

    com, acc, dl = plan_dynamics(model, qs, 0.01)
    mass = float(pin.computeTotalMass(model))
    for s in (1.0, 1.7, 3.0):
        direct, _ = plan_zmp(model, qs, 0.01 * s)      # the same plan sampled s times slower
        assert np.allclose(zmp_at_scale(com, acc, dl, mass, s)[5:-5], direct[5:-5], atol=1e-9)


def test_without_a_chair_plate_the_pelvis_markers_tell_the_seat_off(elderly):
    trial, com_h, fz = elderly
    robot = robot_setup()
    seat_off = {}
    for source in ("plate", "pelvis"):
        rt = Retargeter(robot)
        rt.calibrate(trial.marker_names, trial.positions[0], trial.valid[0], com_h[0])
        for k, t in enumerate(trial.marker_t_s):
            f = rt.step(float(t), trial.positions[k], trial.valid[k], com_h[k],
                        float(fz[k]) if source == "plate" else None)
            if f.human_seat_off:
                seat_off[source] = float(t)
                break
    assert abs(seat_off["pelvis"] - seat_off["plate"]) < 0.3, seat_off


def test_a_calibration_frame_without_the_needed_markers_is_refused_by_name(elderly):
    trial, com_h, _ = elderly
    valid = trial.valid[0].copy()
    valid[trial.marker_names.index("LHEE")] = False
    with pytest.raises(ValueError, match="LHEE"):
        Retargeter(robot_setup()).calibrate(trial.marker_names, trial.positions[0], valid, com_h[0])
    rt = Retargeter(robot_setup())
    with pytest.raises(RuntimeError, match="calibrate"):
        rt.step(0.0, trial.positions[0], trial.valid[0], com_h[0])


def test_a_capture_at_200_hz_gives_the_plan_of_100_hz_in_time(retargeted, tmp_path):
    """The same digital human's rise captured at 200 Hz (the shipped elderly bag is its 100 Hz capture): told the
    frame period, the IK keeps its 4 rad/s joint-speed limit and gives the same joint paths in time, and the plan
    (smoothed over SMOOTH_S, not a frame count) lasts as long. When written: 5.50 s at both rates; with 100 Hz's
    period the IK moved at up to 8 rad/s, with 21 frames of smoothing the plan took 6.14 s."""
    robot, _, frames, cmds, _ = retargeted
    write_demonstration_bag(synthesize(SynthConfig(style="elderly", marker_rate_hz=200.0)), tmp_path / "b")
    trial = read_trial(tmp_path / "b")
    t, com = trial.truth
    com_h = np.stack([np.interp(trial.marker_t_s, t, com[:, i]) for i in range(3)], axis=1)
    chair = next(p for p in trial.plates if p.name == "chair")
    rt = Retargeter(robot)
    rt.calibrate(trial.marker_names, trial.positions[0], trial.valid[0], com_h[0], frame_period_s=0.005)
    player = PlanPlayer(robot.model, 0.005, robot.support_xy, margin_m=0.06)
    fast, fast_cmds = retarget_sequence(rt, player, trial.marker_t_s, trial.positions, trial.valid, com_h,
                                        np.interp(trial.marker_t_s, chair.t_s, chair.force_n[:, 2]))
    q200 = np.array([f.q[7:] for f in fast])
    assert np.abs(np.diff(q200, axis=0)).max() / 0.005 <= rt.cfg.velocity_limit_rad_s + 1e-6
    t100 = np.array([f.t_s for f in frames])
    at_100 = np.stack([np.interp(t100, trial.marker_t_s, q200[:, j]) for j in range(q200.shape[1])], axis=1)
    assert np.abs(at_100 - np.array([f.q[7:] for f in frames])).max() < 0.15
    assert len(fast_cmds) * 0.005 == pytest.approx(len(cmds) * 0.01, rel=0.03)
    with pytest.raises(InputError, match="frame period"):
        Retargeter(robot).calibrate(trial.marker_names, trial.positions[0], trial.valid[0], com_h[0],
                                    frame_period_s=0.0)


def test_a_recording_that_starts_after_seat_off_is_led_in_from_the_robots_seat(elderly):
    """The elderly rise cut where the human COM has passed the heel: the seated knot comes from the body's
    proportions and a lead-in takes the robot from its own seated COM to the first frame's target, smoothly."""
    trial, com_h, _ = elderly
    heel = trial.positions[0, trial.marker_names.index("LHEE"), 0]
    k0 = int(np.argmax(com_h[:, 0] > heel + 0.02))
    robot = robot_setup()
    rt = Retargeter(robot)
    rt.calibrate(trial.marker_names, trial.positions[k0], trial.valid[k0], com_h[k0])
    assert not rt.human.started_seated and rt.human_seat_off
    lead = rt.lead_in(float(trial.marker_t_s[k0]), 0.01, trial.positions[k0], trial.valid[k0], com_h[k0])
    targets = np.array([f.com_target[0] for f in lead])
    assert len(lead) >= 50 and targets[0] == pytest.approx(rt.com_seated[0], abs=0.002)
    assert np.all(np.diff(targets) > -1e-6), "the lead-in moves the COM forward only"
    assert np.abs(np.diff(targets)).max() < 0.01, "no jump: at most 1 cm per frame"
    assert lead[0].seated and not lead[-1].seated, "the robot leaves its seat during the lead-in"
    first = rt.step(float(trial.marker_t_s[k0]), trial.positions[k0], trial.valid[k0], com_h[k0])
    assert abs(first.com_target[0] - targets[-1]) < 0.01


def test_a_lead_in_to_a_posed_calibration_leads_the_marker_targets_from_the_seated_robots_sites(elderly):
    """A frame after seat-off is overlaid on the robot posed like the human: the lead-in's marker targets start at
    the seated robot's marker sites and end at the frame's own targets, so nothing pulls at the seated robot."""
    trial, com_h, _ = elderly
    heel = trial.positions[0, trial.marker_names.index("LHEE"), 0]
    k0 = int(np.argmax(com_h[:, 0] > heel + 0.02))
    robot = robot_setup()
    rt = Retargeter(robot)
    rt.calibrate(trial.marker_names, trial.positions[k0], trial.valid[k0], com_h[k0],
                 human_flexion_deg={"trunk": 25.0, "hip": 80.0, "knee": 70.0, "ankle": 15.0})
    assert rt.markers.robot_pelvis0_m[2] > robot.q_seated[2] + 0.05, "overlaid on the robot posed, not seated"
    lead = rt.lead_in(float(trial.marker_t_s[k0]), 0.01, trial.positions[k0], trial.valid[k0], com_h[k0])
    data = rt.model.createData()
    pin.framesForwardKinematics(rt.model, data, robot.q_seated)
    early, last = lead[1].markers, lead[-1].markers
    seated_sites = np.array([data.oMf[int(f)].translation for f in early.frame_ids])
    assert np.abs(early.targets_m - seated_sites).max() < 0.005
    frame = rt.markers.targets(trial.positions[k0], rt.markers.scale)[np.isin(rt.markers.frame_ids, last.frame_ids)]
    gap = np.abs(frame - seated_sites).max()
    assert gap > 0.1 and np.abs(last.targets_m - frame).max() < 0.01 * gap


def test_a_recording_that_starts_seated_gets_no_lead_in(retargeted, elderly):
    trial, com_h, _ = elderly
    _, rt, frames, *_ = retargeted
    assert rt.human.started_seated and len(frames) == len(trial.marker_t_s)
    assert rt.lead_in(0.0, 0.01, trial.positions[0], trial.valid[0], com_h[0]) == []


def test_a_joint_resting_on_its_stop_is_left_out_of_the_torque_criterion_and_one_lifting_off_counts(retargeted):
    """The torso pitch near its upper stop (0.785 rad) with its static torque pressing into it: the stop carries the
    load, so the joint does not hold the plan; far from the stop, pulled off it by its static torque, or lifted off it
    by the plan (moving away faster than LIFT_OFF_SPEED_RAD_S) while the IK's pose has left the stop, it counts."""
    robot, _, frames, _, player = retargeted
    model = player.model
    jid = model.getJointId("torso_2_joint")
    iq, iv = model.joints[jid].idx_q, model.joints[jid].idx_v - 6
    q = frames[0].q.copy()
    static, v = np.zeros(model.nv - 6), np.zeros(model.nv - 6)
    slow, fast = 0.5 * LIFT_OFF_SPEED_RAD_S, 2 * LIFT_OFF_SPEED_RAD_S
    for q_torso, static_torso, v_torso, resting in (
            (0.75, -70.0, 0.0, True), (0.5, -70.0, 0.0, False), (0.75, 70.0, 0.0, False),
            (-0.2, 30.0, 0.0, True), (-0.2, -30.0, 0.0, False),
            (0.75, -70.0, -slow, True), (0.75, -70.0, -fast, False), (0.75, -70.0, fast, True),
            (-0.2, 30.0, slow, True), (-0.2, 30.0, fast, False)):
        q[iq], static[iv], v[iv] = q_torso, static_torso, v_torso
        assert player.torque.resting_on_stop(q, q, v, static)[iv] == resting, (q_torso, static_torso, v_torso)
    # the smoothing's overshoot past the stop coming back, the IK's own pose on the stop: still resting
    on_stop = q.copy()
    on_stop[iq] = model.upperPositionLimit[iq]
    q[iq], static[iv], v[iv] = model.upperPositionLimit[iq] + 0.01, -70.0, -3 * LIFT_OFF_SPEED_RAD_S
    assert player.torque.resting_on_stop(q, on_stop, v, static)[iv]
    assert not player.torque.resting_on_stop(q, q - 0.05, v, static)[iv]
