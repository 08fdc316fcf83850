"""sit2stand.retarget.warm_up: the live retargeter's dry run of its first frame, made before the capture starts."""

import time

import numpy as np
import pytest

from sit2stand.data import plant_path
from sit2stand.human.synth import SynthConfig, synthesize
from sit2stand.retarget.pacing import LiveConfig, LiveRetargeting, MarkerFrame
from sit2stand.retarget.robot import robot_model, robot_setup
from sit2stand.retarget.warm_up import warm_up


def _live_poses(prebuilt, frames: int = 40) -> np.ndarray:
    """The IK poses of a live retargeting of a synthetic elderly rise's first ``frames`` frames."""
    demo = synthesize(SynthConfig(style="elderly", seed=7, plate_rate_hz=100.0, stand_after_s=0.0))
    robot = robot_setup(prebuilt=prebuilt)
    clock = {"now_s": 0.0}
    live = LiveRetargeting(LiveConfig(controller="wbc"), send=lambda cmd, offset: time.perf_counter(),
                           measured_q=lambda: (robot.q_seated, clock["now_s"]), robot_clock=lambda: clock["now_s"])
    com_velocity = np.gradient(demo.com_m, demo.marker_t_s, axis=0)
    poses = []
    for k in range(frames):
        t_s = clock["now_s"] = float(demo.marker_t_s[k])
        live.coms.add(t_s, demo.com_m[k], com_velocity[k], True)
        live.add_frame(MarkerFrame(t_s, demo.marker_names, demo.markers_m[k], demo.marker_valid[k], 0.0))
        frame, com = live.next_ready()
        if live.retargeter is None:
            live.start(robot, frame, com)
        poses.append(live.step(frame, com))
    return np.array(poses)


def test_the_dry_run_reaches_the_commands_and_leaves_the_live_run_as_it_was():
    """The dry run fills the player's look-ahead and has it hand out commands (the paths of a stream's first
    frames), and changes nothing a live run after it computes: the same poses (to 1e-9 rad: what a solver's
    rounding might move)."""
    prebuilt = robot_model(plant_path("cad"))
    before = _live_poses(prebuilt)
    dry = warm_up(LiveConfig(controller="wbc"), prebuilt)
    assert dry.frames == 80 and dry.commands >= 5 and dry.seconds > 0
    np.testing.assert_allclose(_live_poses(prebuilt), before, rtol=0, atol=1e-9)


@pytest.mark.parametrize("robot", ["g1"])
def test_the_dry_run_works_for_another_robot_and_a_faster_capture(robot):
    """Another robot's profile, and a 200 Hz capture planned at 100 Hz: the dry run still gets to the commands."""
    dry = warm_up(LiveConfig(rate_hz=200.0, plan_rate_hz=100.0), robot_model(robot=robot))
    assert dry.frames == 80 and dry.commands >= 5
