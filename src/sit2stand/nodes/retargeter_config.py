"""The retargeter node's stream parameters (:mod:`sit2stand.nodes.retargeter`), declared with their descriptions
into :class:`~sit2stand.retarget.pacing.LiveConfig`; ``docs/nodes.md`` (retargeter) lists them."""

from __future__ import annotations

from rclpy.node import Node

from ..retarget.pacing import LiveConfig
from ..retarget.player import (DEFAULT_MARGIN_M, DEFAULT_MAX_JOINT_SPEED, DEFAULT_MAX_TIME_SCALE, LOOKAHEAD_S,
                               SEAT_OFF_DWELL_S, SMOOTH_S)
from ..retarget.stabiliser import StabiliserConfig
from .runtime import declare


def live_config(node: Node) -> LiveConfig:
    """The node's parameters, declared."""
    gains = StabiliserConfig()
    scale = declare(node, "time_scale", 0.0, "0: adaptive retiming; else a fixed time scale")
    return LiveConfig(
        rate_hz=declare(node, "rate_hz", 100.0, "marker rate [Hz]"),
        plan_rate_hz=declare(node, "plan_rate_hz", 0.0, "the plan's rate [Hz]: every n-th frame, n the nearest "
                             "whole number to rate_hz / this (0: every frame)"),
        margin_m=declare(node, "margin_m", DEFAULT_MARGIN_M, "ZMP margin inside the feet [m]"),
        lookahead_s=declare(node, "lookahead_s", LOOKAHEAD_S, "look-ahead of the retiming [s]"),
        smooth_s=declare(node, "smooth_s", SMOOTH_S, "Savitzky-Golay window of the plan [s]"),
        max_joint_speed=declare(node, "max_joint_speed", DEFAULT_MAX_JOINT_SPEED,
                                "joint speed limit of the retimed plan [rad/s]"),
        retiming=declare(node, "retiming", "local", "local: slower only where a frame needs it; uniform: one factor"),
        seat_off_dwell_s=declare(node, "seat_off_dwell_s", SEAT_OFF_DWELL_S, "wait at the robot's seat-off [s]"),
        fixed_time_scale=scale if scale > 0 else None,
        max_time_scale=declare(node, "max_time_scale", DEFAULT_MAX_TIME_SCALE, "cap of the adaptive time scale"),
        com_wait_s=declare(node, "com_wait_s", 0.03, "use the latest human COM if at most this old [s]"),
        com_feedback=declare(node, "com_feedback", True, "correct the commands for the measured robot COM (under "
                             "joint PD)"),
        controller=declare(node, "controller", "inverse_dynamics", "the robot's on-board controller, as the driver's: "
                           "inverse_dynamics (joint PD) | wbc (whole-body torque control: no COM feedback)"),
        marker_set=declare(node, "marker_set", "", "marker set: a packaged set's name or a YAML file (empty: the "
                           "packaged set that covers most of the stream's marker names)"),
        stabiliser=StabiliserConfig(
            kp=declare(node, "com_feedback_kp", gains.kp, "COM feedback: proportional gain [m/m]"),
            ki=declare(node, "com_feedback_ki", gains.ki, "COM feedback: integral gain [1/s]"),
            kd=declare(node, "com_feedback_kd", gains.kd, "COM feedback: velocity gain [s]")))
