"""COM feedback on the played plan (sit2stand.retarget.stabiliser): the shift it makes, its bounds, and the loop
closed on the MuJoCo plant."""

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from sit2stand.data import plant_path
from sit2stand.retarget.offline import physics_steps_due, run
from sit2stand.retarget.stabiliser import ComStabiliser, StabiliserConfig
from sit2stand.retarget.robot import robot_setup

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def standing():
    """TALOS (CAD) standing: the seated model with the legs straightened, feet where they are seated."""
    robot = robot_setup()
    model = robot.model
    q = robot.q_seated.copy()
    for side in ("left", "right"):
        for joint, angle in ((3, -0.3), (4, 0.6), (5, -0.3)):
            jid = model.getJointId(f"leg_{side}_{joint}_joint")
            q[model.joints[jid].idx_q] = angle
    # put the feet back where the robot's are: the same solve the stabiliser makes, with no shift
    stab = ComStabiliser(model, robot.sole_frames, robot.sole_targets, StabiliserConfig(iterations=20))
    data = model.createData()
    q = stab.ik.solve(q, [], pin.centerOfMass(model, data, q), robot.sole_targets, com_axes=(), max_iterations=30,
                      tol=1e-10).q
    return robot, q


def _com(model, q):
    return pin.centerOfMass(model, model.createData(), q).copy()


def test_no_error_no_shift_and_nothing_while_the_plan_is_seated(standing):
    robot, q = standing
    stab = ComStabiliser(robot.model, robot.sole_frames, robot.sole_targets)
    com = _com(robot.model, q)
    off = stab.correct(q, com + [0.05, 0.0, 0.0], q, on_feet=False, dt_s=0.01)
    assert not off.active and off.q is q and np.all(off.offset_m == 0)
    same = stab.correct(q, com, q, on_feet=True, dt_s=0.01)
    assert np.all(same.offset_m == 0) and np.abs(pin.difference(robot.model, q, same.q)).max() < 1e-6


def test_without_a_recent_robot_state_the_last_shift_is_kept(standing):
    robot, q = standing
    stab = ComStabiliser(robot.model, robot.sole_frames, robot.sole_targets, StabiliserConfig(ramp_s=0.0))
    planned = _com(robot.model, q)
    planned[0] += 0.01
    assert not stab.correct(q, planned, None, on_feet=True, dt_s=0.01).active, "no state yet: nothing to correct"
    first = stab.correct(q, planned, q, on_feet=True, dt_s=0.01)
    held = stab.correct(q, planned, None, on_feet=True, dt_s=0.01)
    assert first.active and held.active and np.all(held.offset_m == first.offset_m)
    assert np.allclose(held.q, first.q)


def test_an_error_shifts_the_commanded_com_by_the_gains_with_the_feet_fixed(standing):
    robot, q = standing
    model = robot.model
    cfg = StabiliserConfig(kp=0.8, ki=2.0, kd=0.0, ramp_s=0.0, iterations=3)
    stab = ComStabiliser(model, robot.sole_frames, robot.sole_targets, cfg)
    error = np.array([0.012, -0.008])
    planned = _com(model, q)
    planned[:2] += error                      # the plan's COM is ahead of (and right of) the measured one
    fix = stab.correct(q, planned, q, on_feet=True, dt_s=0.01)
    expected = (cfg.kp + cfg.ki * 0.01) * error
    assert np.allclose(fix.error_m, error, atol=1e-12)
    assert np.allclose(fix.offset_m, expected, atol=1e-12)
    moved = _com(model, fix.q)[:2] - _com(model, q)[:2]
    assert np.allclose(moved, expected, atol=2e-4), f"COM moved {moved}, asked {expected}"
    data = model.createData()
    pin.framesForwardKinematics(model, data, fix.q)
    for fid, target in zip(robot.sole_frames, robot.sole_targets):
        assert np.linalg.norm(pin.log6(target.actInv(data.oMf[fid])).vector) < 1e-5, "a foot moved"
    assert np.all(fix.q[7:] >= model.lowerPositionLimit[7:] - 1e-9)
    assert np.all(fix.q[7:] <= model.upperPositionLimit[7:] + 1e-9)
    arms = [model.joints[j].idx_q for j in range(2, model.njoints) if model.names[j].startswith(("arm_", "head_"))]
    legs = [model.joints[j].idx_q for j in range(2, model.njoints) if model.names[j].startswith("leg_")]
    dq = np.abs(fix.q - q)
    assert dq[arms].max() < 0.1 * dq[legs].max(), "the shift is made with the legs, not by swinging the arms"


def test_a_backward_shift_keeps_the_pelvis_no_lower_than_the_commands(standing):
    """A 3 cm backward COM shift from the standing pose, made freely by the same QP, bends the knees and lowers the
    pelvis ~2 mm; the stabiliser's shift keeps it at the command's height (the hips the plan lifted off a seat stay
    off it) and still moves the COM the whole 3 cm."""
    robot, q = standing
    model = robot.model
    cfg = StabiliserConfig(kp=1.0, ki=0.0, kd=0.0, ramp_s=0.0, iterations=3)
    stab = ComStabiliser(model, robot.sole_frames, robot.sole_targets, cfg)
    planned = _com(model, q) - [0.03, 0.0, 0.0]
    free = stab.ik.solve(q, [], planned, robot.sole_targets, q_ref=q, com_axes=(0, 1), max_iterations=3, tol=1e-9)
    assert free.q[2] < q[2] - 1e-3, "the unbounded shift lowers the pelvis"
    fix = stab.correct(q, planned, q, on_feet=True, dt_s=0.01)
    assert fix.q[2] >= q[2] - 1e-5
    assert np.allclose(_com(model, fix.q)[:2], planned[:2], atol=1e-4)


def test_the_shift_and_its_integral_are_bounded(standing):
    robot, q = standing
    cfg = StabiliserConfig(ramp_s=0.0)
    stab = ComStabiliser(robot.model, robot.sole_frames, robot.sole_targets, cfg)
    planned = _com(robot.model, q)
    planned[:2] += [0.5, -0.5]               # far beyond what feedback should chase
    for _ in range(200):
        fix = stab.correct(q, planned, q, on_feet=True, dt_s=0.01)
    assert np.allclose(np.abs(fix.offset_m), cfg.max_offset_m)
    assert np.all(np.abs(stab.integral) <= cfg.max_offset_m + 1e-12)
    assert np.all(np.isfinite(fix.q))
    stab.correct(q, planned, q, on_feet=False, dt_s=0.01)
    assert np.all(stab.integral == 0), "back on the chair: the integral starts again"


def test_closed_on_the_plant_the_feedback_brings_the_robot_com_onto_the_plan(tmp_path):
    """The elderly demonstration's per-frame plan on the CAD plant, as planned and with the feedback: both stand, and
    the measured COM follows the plan several times closer with it (1.6 cm -> 0.3 cm when written)."""
    runs = {}
    for feedback in (False, True):
        s = run(ROOT / "bags" / "elderly", tmp_path / str(feedback), plant=plant_path("cad"),
                simulate=True, com_feedback=feedback, controller="inverse_dynamics", plan="frames")
        assert s["stood_up"], f"feedback {feedback}: {s['fall']}"
        assert json.loads((tmp_path / str(feedback) / "summary.json").read_text())["com_feedback"] is feedback
        runs[feedback] = s
    open_loop, closed = runs[False]["com_tracking_rms_m"], runs[True]["com_tracking_rms_m"]
    assert closed < 0.01 and closed < 0.5 * open_loop, f"COM tracking {open_loop:.4f} m as planned, {closed:.4f} m"
    assert 0.0 < runs[True]["com_feedback_max_offset_m"] <= StabiliserConfig().max_offset_m + 1e-9


def test_after_a_long_gap_without_robot_states_the_loop_fades_in_again_from_the_shift_it_held(standing):
    """A robot that ran behind real time gave no recent state for seconds: the loop does not meet its full gains on
    the error gathered meanwhile; it restarts from the shift it held and fades in over ``ramp_s``."""
    robot, q = standing
    cfg = StabiliserConfig(kp=1.0, ki=1.0, kd=0.0, ramp_s=0.5)
    stab = ComStabiliser(robot.model, robot.sole_frames, robot.sole_targets, cfg)
    planned = _com(robot.model, q)
    planned[0] += 0.005
    for _ in range(100):                                   # 1 s on the feet with states: faded in
        held = stab.correct(q, planned, q, on_feet=True, dt_s=0.01).offset_m
    for _ in range(300):                                   # 3 s without a state: the shift held
        assert np.array_equal(stab.correct(q, planned, None, on_feet=True, dt_s=0.01).offset_m, held)
    planned[0] += 0.02                                     # meanwhile the robot drifted 2 cm from its plan
    back = stab.correct(q, planned, q, on_feet=True, dt_s=0.01).offset_m
    assert abs(back[0] - held[0]) < 0.002, (back, held)    # full gains would have stepped it by ~2 cm
    for _ in range(60):
        late = stab.correct(q, planned, q, on_feet=True, dt_s=0.01).offset_m
    assert late[0] == pytest.approx(min(cfg.max_offset_m, 0.025 + stab.integral[0]), abs=1e-6)


def test_the_offline_simulation_keeps_the_commands_clock_at_any_capture_rate():
    """One second of 120 Hz commands takes 1000 physics steps of 1 ms (8 a frame would make 960: the plan 4 % fast);
    at 100 Hz, 10 a frame."""
    for rate, per_frame in ((120.0, None), (100.0, 10)):
        taken, steps = 0, []
        for k in range(1, int(rate) + 1):
            steps.append(physics_steps_due(k, 1.0 / rate, 0.001, taken))
            taken += steps[-1]
        assert taken == 1000 and (per_frame is None or set(steps) == {per_frame}), (rate, set(steps))
