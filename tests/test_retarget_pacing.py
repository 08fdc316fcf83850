"""sit2stand.retarget.pacing: COM by stamp, command pacing and latency accounting of the live retargeter."""

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from sit2stand.data import plant_path
from sit2stand.retarget.player import Command
from sit2stand.retarget.stabiliser import ComStabiliser, StabiliserConfig
from sit2stand.retarget.robot import robot_model, robot_setup
from sit2stand.retarget.pacing import (ROBOT_STATE_MAX_AGE_S, ROBOT_STATE_MAX_DELAY_S, ChairForceTrack, CommandPacer,
                                       HumanComTrack, LatencyLog, LiveConfig, LiveRetargeting, MarkerFrame,
                                       percentile_text, plan_stride, robot_state_current, summary_line)


def test_a_frame_uses_its_own_com_estimate():
    track = HumanComTrack(com_wait_s=0.03)
    track.add(1.00, np.array([0.1, 0.0, 0.8]), np.zeros(3), True)
    track.add(1.01, np.array([0.2, 0.0, 0.8]), np.zeros(3), True)
    assert track.at(1.00) == pytest.approx([0.1, 0.0, 0.8])
    assert track.at(1.01) == pytest.approx([0.2, 0.0, 0.8])


def test_between_two_estimates_the_com_is_interpolated():
    track = HumanComTrack()
    track.add(1.00, np.array([0.0, 0.0, 0.8]), np.zeros(3), True)
    track.add(1.02, np.array([0.2, 0.0, 0.8]), np.zeros(3), True)
    assert track.at(1.01) == pytest.approx([0.1, 0.0, 0.8])


def test_after_the_newest_estimate_it_moves_on_by_its_velocity_until_too_old():
    track = HumanComTrack(com_wait_s=0.03)
    track.add(1.00, np.array([0.0, 0.0, 0.8]), np.array([1.0, 0.0, 0.0]), True)
    assert track.at(1.02) == pytest.approx([0.02, 0.0, 0.8])
    assert track.at(1.05) is None, "an estimate older than com_wait_s must make the frame wait"


def test_invalid_estimates_are_counted_and_left_out():
    track = HumanComTrack()
    track.add(1.00, np.array([np.nan, 0.0, 0.8]), np.zeros(3), True)
    track.add(1.01, np.array([0.0, 0.0, 0.8]), np.zeros(3), False)
    assert track.invalid == 2 and not track.samples
    assert not track.began_after(0.5)
    track.add(1.02, np.array([0.0, 0.0, 0.8]), np.zeros(3), True)
    assert track.began_after(1.0) and not track.began_after(1.02)


def test_chair_force_is_the_latest_sample_at_or_before_the_frame():
    chair = ChairForceTrack()
    assert chair.at(1.0) is None, "no chair plate: no force"
    chair.add(1.000, 400.0)
    chair.add(1.001, 300.0)
    assert chair.at(0.5) == 400.0 and chair.at(1.0005) == 400.0 and chair.at(2.0) == 300.0


def test_a_burst_of_frames_sends_one_command_per_period():
    pacer = CommandPacer(rate_hz=100.0)
    sent = 0
    for _ in range(10):                    # ten frames arrive at once
        if pacer.due(5.0):
            pacer.sent(5.0)
            sent += 1
    assert sent == 1
    assert not pacer.due(5.004) and pacer.due(5.006)


def test_the_timer_catches_up_when_frames_are_late():
    pacer = CommandPacer(rate_hz=100.0)
    assert not pacer.late(1.0), "nothing sent yet: nothing overdue"
    pacer.sent(1.0)
    assert not pacer.late(1.012) and pacer.late(1.016)
    pacer.sent(1.016)
    assert pacer.next_due_s == pytest.approx(1.021)


def test_a_jump_of_the_robots_clock_sends_one_command_not_a_burst():
    pacer = CommandPacer(rate_hz=100.0)
    pacer.sent(1.0)
    assert pacer.late(4.0), "the clock jumped 3 s ahead (a replay catching up)"
    pacer.sent(4.0)
    assert not pacer.late(4.009) and pacer.late(4.011), "one command, then one per period from now on"


def test_latency_log_separates_waiting_for_the_com_from_the_retargeters_own_share():
    log = LatencyLog(in_step_s=0.02)
    log.command(received_s=0.0, ready_s=0.001, sent_s=0.003)    # COM in step
    log.command(received_s=1.0, ready_s=1.05, sent_s=1.052)     # waited 50 ms for its COM
    f = log.figures()
    assert f["in_step_frames"] == "1"
    assert float(f["latency_p99_ms"]) == pytest.approx(3 + 0.99 * 49, abs=0.01)
    assert float(f["own_latency_p50_ms"]) == pytest.approx(2.0, abs=0.01)
    assert f["ik_p50_ms"] == "nan"
    assert percentile_text([0.001, 0.003], 50) == "2.00"


def test_frames_before_the_com_stream_began_are_dropped_and_counted():
    live = LiveRetargeting(LiveConfig(), send=lambda cmd, offset: 0.0, measured_q=lambda: None)
    for t in (0.98, 0.99, 1.00):
        live.frames.append(MarkerFrame(t, ["LASI"], np.zeros((1, 3)), np.ones(1, bool), 0.0))
    assert live.next_ready() is None, "no COM yet: wait"
    live.coms.add(1.00, np.array([0.0, 0.0, 0.8]), np.zeros(3), True)
    frame, com = live.next_ready()
    assert frame.t_s == 1.00 and live.progress.skipped == 2
    assert com == pytest.approx([0.0, 0.0, 0.8])
    assert "2 without a human COM" in summary_line(live.figures())


class _PlayedPlan:
    """A plan player whose plan has been played to its end."""
    done = finished = True


@dataclasses.dataclass
class _HeldPose:
    """The plan's last pose, at rest, on the chair (no COM feedback to apply)."""
    com: tuple = (0.0, 0.0, 0.8)
    on_feet: bool = False


def test_after_the_plan_the_last_pose_is_re_sent_once_per_period_of_the_robots_clock():
    robot_now, sent = [10.0], []
    live = LiveRetargeting(LiveConfig(), send=lambda cmd, offset: sent.append(cmd) or 0.0, measured_q=lambda: None,
                           robot_clock=lambda: robot_now[0])
    live.player = _PlayedPlan()
    live.sent.held = _HeldPose()
    live.progress.last_frame_robot_s = 10.0          # the last marker frame
    live.pacer.sent(10.0)
    for _ in range(3):                       # a graph held in lockstep: wall time passes, the robot's clock does not
        assert not live.tick() and not sent, "markers and commands both wait with the robot's clock"
    robot_now[0] = 10.016
    assert not live.tick() and sent == [live.sent.held], "the pose is held; markers not yet taken as stopped"
    robot_now[0] = 10.032
    assert live.tick() is True and len(sent) == 2, "three periods of the robot's clock without markers: done"


class _OnePlanCommand:
    """A plan player that hands out one on-feet command and remembers the lag it was given."""
    done = finished = False
    duration_ratio = 1.0

    def __init__(self, command):
        self.command, self.lags = command, []

    def pull(self, lag_m=0.0, periods=1.0, coming=0):
        self.lags.append(lag_m)
        return self.command


def test_under_torque_control_a_robot_behind_the_plan_slows_it_from_its_measured_com():
    """No COM feedback under whole-body torque control: the plan still waits for a robot whose measured COM (with the
    plan's model) trails the planned one, as the offline re-simulation does."""
    model, q_seated, _ = robot_model(plant_path("cad"))
    com_seated = pin.centerOfMass(model, model.createData(), q_seated)
    measured = [None]
    live = LiveRetargeting(LiveConfig(controller="wbc"), send=lambda cmd, offset: 0.0,
                           measured_q=lambda: measured[0], robot_clock=lambda: 5.0)
    live.model, live.model_data = model, model.createData()
    plan = Command(0.0, q_seated, np.zeros(model.nv), np.zeros(model.nv), 1.0, com_seated + [0.05, 0.0, 0.0],
                   com_seated, np.inf, True)
    live.player = _OnePlanCommand(plan)
    live.pull_and_send(5.0)
    assert live.sent.lag_m == 0.0 and live.progress.state_stale == 1, "no robot state: no lag, counted"
    measured[0] = (q_seated, 5.0)
    live.pull_and_send(5.01)
    assert live.sent.lag_m == pytest.approx(0.05, abs=1e-9)
    live.pull_and_send(5.02)
    assert live.player.lags[-1] == pytest.approx(0.05, abs=1e-9), "the next command is pulled with that lag"
    assert live.stabiliser is None and "whole-body torque controller" in live.figures()["com_feedback"]


def test_a_robot_state_held_with_the_replayers_clock_stays_current():
    """On a wall clock a state received long ago is a robot gone; under use_sim_time the clock held in lockstep
    holds the robot with it, and only the stamp counts (a held clock once waited for a command that waited for a
    newer state). A state stamped too long before the clock is stale on either clock."""
    old, fresh = 5.0, 0.5 * ROBOT_STATE_MAX_AGE_S
    assert robot_state_current(fresh, 0.05, sim_time=False)
    assert not robot_state_current(old, 0.05, sim_time=False)
    assert robot_state_current(old, 0.05, sim_time=True)
    for sim_time in (False, True):
        assert not robot_state_current(fresh, 2 * ROBOT_STATE_MAX_DELAY_S, sim_time)


def test_after_the_plan_the_held_pose_stays_under_the_com_feedback():
    """A robot left standing keeps its balance: once the plan is played, each re-sent pose is corrected for the
    robot's measured COM again (a shift frozen at the plan's end once left a real child's rise rocking heel to toe)."""
    robot = robot_setup()
    model, q = robot.model, robot.q_seated
    com = pin.centerOfMass(model, model.createData(), q).copy()
    robot_now, sent, measured = [10.0], [], [(q, 10.0)]
    live = LiveRetargeting(LiveConfig(), send=lambda cmd, offset: sent.append((cmd.q, offset)) or 0.0,
                           measured_q=lambda: measured[0], robot_clock=lambda: robot_now[0])
    live.model, live.model_data = model, model.createData()
    live.stabiliser = ComStabiliser(model, robot.sole_frames, robot.sole_targets, StabiliserConfig(ramp_s=0.0))
    live.player = _PlayedPlan()
    live.sent.held = Command(1.0, q, np.zeros(model.nv), np.zeros(model.nv), 1.0, com + [0.01, 0.0, 0.0], com, np.inf,
                         True)
    live.progress.last_frame_robot_s = robot_now[0]
    live.pacer.sent(robot_now[0])
    robot_now[0] += 0.016
    live.tick()
    measured[0] = (q, robot_now[0])
    robot_now[0] += 0.016
    live.tick()
    (q1, off1), (q2, off2) = sent
    assert off1[0] > 0.005 and off2[0] > off1[0], "the robot 1 cm behind: a forward shift, growing (integral)"
    assert np.abs(pin.difference(model, q, q2)).max() > 1e-4, "the held pose itself is moved"


def test_a_faster_capture_is_planned_on_every_nth_frame_by_its_stamps():
    """200 Hz planned at 100 Hz: every other frame, chosen by stamp (a frame lost on the way does not shift the
    stride); the plan's period is the stride's time; 250 Hz at 100 Hz: every 2nd (125 Hz); 0: every frame."""
    assert (plan_stride(200.0, 100.0), plan_stride(250.0, 100.0), plan_stride(120.0, 100.0)) == (2, 2, 1)
    assert plan_stride(200.0, 0.0) == 1 and plan_stride(50.0, 100.0) == 1
    live = LiveRetargeting(LiveConfig(rate_hz=200.0, plan_rate_hz=100.0), send=lambda cmd, offset: 0.0,
                           measured_q=lambda: None)
    assert live.plan_period_s == pytest.approx(0.01) and live.pacer.period_s == pytest.approx(0.01)
    for k in (0, 1, 2, 3, 5, 6, 8):          # frames 4 and 7 lost
        live.add_frame(MarkerFrame(10.0 + k * 0.005, ["LASI"], np.zeros((1, 3)), np.ones(1, bool), 0.0))
    assert [round((f.t_s - 10.0) / 0.005) for f in live.frames] == [0, 2, 6, 8]
    assert live.progress.between_plan_frames == 3
    assert "frames planned (3 between them left out)" in summary_line(live.figures())
    with pytest.raises(ValueError, match="plan_rate_hz"):
        plan_stride(200.0, -1.0)
