"""A dry run of the live retargeting, made while the node waits for the capture.

The live stream's first frame calibrates the markers on the robot, builds the IK and the plan player and takes the
first steps. Made cold, that is also the first call of every function on the way: memory the process has not touched
yet, NumPy's and Pinocchio's first paths. On the shipped elderly rise (offline, 2 cores) the first frame took
23.6 ms cold and 10.6 ms after a dry run; in the live graph the frames that queue behind it set the stream's p99
latency. :func:`warm_up` runs the calibration and the steps up to the first commands on a synthetic rise
(:data:`WARM_UP_HUMAN`) over the same robot, with the same settings, and throws them away: nothing is sent.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from ..human.synth import SynthConfig, synthesize
from .pacing import LiveConfig, LiveRetargeting, MarkerFrame
from .robot import robot_setup

WARM_UP_HUMAN = SynthConfig(vary_subject=False, marker_noise_m=0.0, occlusion_gaps=0, marker_rate_hz=100.0,
                            plate_rate_hz=100.0, sit_before_s=0.1, duration_s=0.8, stand_after_s=0.0)
"""The digital human the dry run retargets (:mod:`sit2stand.human.synth`): a natural rise of 0.9 s at 100 Hz
without noise or gaps, ~40 ms to make."""


@dataclass
class DryRun:
    """What :func:`warm_up` did: frames retargeted, commands the player handed out, and how long it took [s]."""

    frames: int
    commands: int
    seconds: float


def warm_up(cfg: LiveConfig, prebuilt) -> DryRun:
    """Retarget the synthetic rise's frames with ``cfg``'s settings (any marker set: the synthetic human wears
    Plug-in-Gait) over the robot ``prebuilt`` (:func:`~sit2stand.retarget.robot.robot_model`'s result) seated in its
    nominal posture, until the player has handed out a few commands (which go nowhere).

    Raises:
        InputError: the synthetic human cannot be retargeted to this robot (its calibration's own errors).
    """
    began = time.perf_counter()
    demo = synthesize(WARM_UP_HUMAN)
    robot = robot_setup(prebuilt=prebuilt)
    period_s = 1.0 / cfg.rate_hz
    clock, commands = {"now_s": 0.0}, []
    live = LiveRetargeting(dataclasses.replace(cfg, marker_set=""),
                           send=lambda cmd, offset: commands.append(cmd) or time.perf_counter(),
                           measured_q=lambda: (robot.q_seated, clock["now_s"]), robot_clock=lambda: clock["now_s"])
    com_velocity = np.gradient(demo.com_m, demo.marker_t_s, axis=0)
    # the look-ahead and the smoothing window filled, and commands out, within the synthetic rise (0.9 s)
    for k in range(round(min(cfg.lookahead_s + cfg.smooth_s, demo.marker_t_s[-1]) / period_s)):
        t_s = k * period_s
        i = int(np.searchsorted(demo.marker_t_s, t_s - 1e-9))     # the synthetic frame of this time
        live.coms.add(t_s, demo.com_m[i], com_velocity[i], True)
        live.add_frame(MarkerFrame(t_s, demo.marker_names, demo.markers_m[i], demo.marker_valid[i],
                                   time.perf_counter(), round(t_s * 1e9)))
        clock["now_s"] = t_s
        while (ready := live.next_ready()) is not None:
            if live.retargeter is None:
                live.start(robot, *ready)
            live.step(*ready)
    return DryRun(live.progress.processed, len(commands), time.perf_counter() - began)
