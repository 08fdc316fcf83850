"""Live retargeting without ROS: matching each marker frame to its human COM, pacing the commands, latency figures.

The retargeter node is a thin shell around :class:`LiveRetargeting`: it feeds marker frames, human COM estimates,
chair-plate forces and the robot's measured state in as they arrive, and publishes the commands that come out.

* **COM by stamp** (:class:`HumanComTrack`): a frame uses the estimator's estimate for its own stamp; between two
  estimates (the frame's own was invalid) their interpolation; after the newest one, that one moved on by its
  velocity if it is at most ``com_wait_s`` old; otherwise the frame waits.
* **Plan rate**: every frame is planned, or every n-th of a faster capture (``plan_rate_hz``, by stamp); the plan's
  period is the time of n frames.
* **Pacing** (:class:`CommandPacer`): one command per plan period of the robot's clock (the ROS clock: wall time on
  a robot, ``/clock`` under ``use_sim_time``, which a simulated robot follows), sent as soon as a frame brings it,
  so a burst of queued frames (after the COM estimator's calibration pause, say) does not play the plan faster;
  when frames are late, the timer keeps the commands at the plan's rate. Paced on wall time, a replay whose ``/clock``
  fell behind (a loaded machine) played the plan 1.7x faster to the simulated robot than the player said.
* **Latency** (:class:`LatencyLog`): marker received -> its command sent; the same from when the frame's human COM
  was also there (the retargeter's own share); and over the frames whose COM kept in step with the markers.

Times: stamps [s] of the capture clock; the robot's clock [s] (``robot_clock``); wall times [s] from
``time.monotonic`` / ``time.perf_counter`` (latencies, time-outs).
"""

from __future__ import annotations

import dataclasses
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..io.messages import reorder_markers
from .player import (DEFAULT_MARGIN_M, DEFAULT_MAX_JOINT_SPEED, DEFAULT_MAX_TIME_SCALE, LOOKAHEAD_S, SEAT_OFF_DWELL_S,
                     SMOOTH_S, Command, PlanPlayer)
from .stabiliser import ComStabiliser, StabiliserConfig, com_feedback_applies, com_lag_m
from .robot import RobotSetup
from .stream import RetargetConfig, Retargeter

ROBOT_STATE_MAX_AGE_S = 0.1
ROBOT_STATE_MAX_DELAY_S = 0.2
"""A robot state received within ``ROBOT_STATE_MAX_AGE_S`` (the robot is alive) and stamped within this of now is
used by the COM feedback, compared with the plan of its own stamp; one from a simulation lagging more is not (the
last shift is kept instead). Replayed graphs in lockstep: states p99 80 ms old. A simulated robot starved on 2 cores
ran up to 5 s behind real time while the live stream ran; at 1 s allowed, the feedback closed its loop on states
0.7 s old as the robot caught up (a sway period is ~2 s), overcorrected the standing robot and felled it (3 live
runs in 2 full test runs, 2026-12-02)."""


def robot_state_current(received_ago_s: float, stamped_ago_s: float, sim_time: bool) -> bool:
    """Whether the robot's newest state is its state now: stamped at most ``ROBOT_STATE_MAX_DELAY_S`` before the
    graph's clock and, on a wall clock, received at most ``ROBOT_STATE_MAX_AGE_S`` ago. Under ``use_sim_time`` the
    time since it was received says nothing: a replayer's /clock held in lockstep holds the simulated robot and its
    states with it, and judging the state by it would make the retargeter wait for a newer state that waits for the
    clock, which waits for the retargeter's first command."""
    return stamped_ago_s <= ROBOT_STATE_MAX_DELAY_S and (sim_time or received_ago_s <= ROBOT_STATE_MAX_AGE_S)


READY_LINE = "ready for the capture"
"""What the retargeter node logs once it has what its first frame needs: the human COM's publisher and, unless
``wait_for_robot`` is off, the robot's state (the calibration overlays the first frame on the robot's measured
posture). A marker frame that comes before waits, and the wait counts in its latency."""


def plan_stride(rate_hz: float, plan_rate_hz: float) -> int:
    """Every how many capture frames the live retargeter plans one: the nearest whole number of frames to
    ``rate_hz / plan_rate_hz``, at least 1 (``plan_rate_hz`` 0: every frame; the plan then runs at
    ``rate_hz / stride``, e.g. 125 Hz for a 250 Hz capture and 100 Hz asked).

    Raises:
        InputError: a negative ``plan_rate_hz``.
    """
    if plan_rate_hz < 0:
        raise InputError(f"plan_rate_hz {plan_rate_hz:g}: give the plan's rate [Hz], or 0 to plan every frame")
    return max(1, round(rate_hz / plan_rate_hz)) if plan_rate_hz > 0 else 1


STAMP_TOLERANCE_S = 1e-6
"""Two stamps this close are the same frame's."""
MAX_CATCH_UP_PERIODS = 5.0
"""A command that comes late (the retargeter or the clock held up) moves the plan on by the robot's time since the
last one, up to this many periods: after a longer stall the plan waits instead of jumping ahead."""
PLANNED_COM_KEPT = 200
"""Planned COMs kept by the robot time of their command (2 s at 100 Hz), to compare a late robot state with."""


class HumanComTrack:
    """The human COM stream, kept by stamp (see the module docstring)."""

    def __init__(self, com_wait_s: float = 0.03, keep: int = 400) -> None:
        self.com_wait_s = com_wait_s
        self.samples: deque[tuple[float, np.ndarray, np.ndarray]] = deque(maxlen=keep)
        self.invalid = 0

    def add(self, t_s: float, position_m: np.ndarray, velocity_mps: np.ndarray, valid: bool) -> None:
        """One estimate; an invalid one (flagged, or not finite) is counted and left out."""
        if not valid or not np.all(np.isfinite(position_m)):
            self.invalid += 1
            return
        self.samples.append((t_s, np.asarray(position_m, float),
                             np.where(np.isfinite(velocity_mps), velocity_mps, 0.0)))

    def at(self, t_s: float) -> np.ndarray | None:
        """The human COM [m] for the frame stamped ``t_s``, or None: wait for it."""
        after = None
        for tc, p, v in reversed(self.samples):
            if abs(tc - t_s) < STAMP_TOLERANCE_S:
                return p
            if tc > t_s:
                after = (tc, p)
                continue
            if after is not None:
                w = (t_s - tc) / (after[0] - tc)
                return (1.0 - w) * p + w * after[1]
            return p + v * (t_s - tc) if t_s - tc <= self.com_wait_s else None
        return None

    def velocity_at(self, t_s: float) -> np.ndarray:
        """The COM velocity [m/s] of the estimate nearest to ``t_s`` (zero without any)."""
        if not self.samples:
            return np.zeros(3)
        return min(self.samples, key=lambda s: abs(s[0] - t_s))[2]

    def began_after(self, t_s: float) -> bool:
        """The COM stream's first estimate kept is later than ``t_s``: that frame will never get one."""
        return bool(self.samples) and self.samples[0][0] > t_s + STAMP_TOLERANCE_S


class ChairForceTrack:
    """The chair plate's vertical force [N] by stamp (the latest sample at or before a frame)."""

    def __init__(self, keep: int = 4000) -> None:
        self.samples: deque[tuple[float, float]] = deque(maxlen=keep)

    def add(self, t_s: float, force_z_n: float) -> None:
        self.samples.append((t_s, force_z_n))

    def at(self, t_s: float) -> float | None:
        """None without a chair plate; the first sample for frames before it."""
        if not self.samples:
            return None
        for tc, fz in reversed(self.samples):
            if tc <= t_s:
                return fz
        return self.samples[0][1]


class CommandPacer:
    """One command per period ``1 / rate_hz`` of the robot's clock (see the module docstring)."""

    def __init__(self, rate_hz: float) -> None:
        self.period_s = 1.0 / rate_hz
        self.next_due_s: float | None = None

    def due(self, now_s: float) -> bool:
        """A frame arrived at ``now_s``: may it send a command?"""
        return self.next_due_s is None or now_s >= self.next_due_s - 0.5 * self.period_s

    def sent(self, now_s: float) -> None:
        """A frame's command went out at ``now_s``: the next one is due a period later (not in the past)."""
        self.next_due_s = max(self.next_due_s or now_s, now_s - 0.5 * self.period_s) + self.period_s

    def late(self, now_s: float) -> bool:
        """The timer at ``now_s``: frames are late and a command is overdue."""
        return self.next_due_s is not None and now_s > self.next_due_s + 0.5 * self.period_s



def percentile_text(values_s: list[float], q: float) -> str:
    """The ``q``-th percentile of ``values_s`` [s] in ms with two decimals, or ``nan`` without values."""
    return f"{np.percentile(np.asarray(values_s) * 1e3, q):.2f}" if len(values_s) else "nan"


@dataclass
class LatencyLog:
    """Per-command latencies [s] and per-frame IK costs [s] (see the module docstring)."""

    in_step_s: float = 0.02
    marker_to_command: list[float] = field(default_factory=list)
    com_to_command: list[float] = field(default_factory=list)
    in_step: list[float] = field(default_factory=list)
    ik: list[float] = field(default_factory=list)

    def command(self, received_s: float, ready_s: float, sent_s: float) -> None:
        """A frame received at ``received_s``, with its human COM at ``ready_s``, whose command went at ``sent_s``."""
        self.marker_to_command.append(sent_s - received_s)
        self.com_to_command.append(sent_s - ready_s)
        if ready_s - received_s <= self.in_step_s:
            self.in_step.append(sent_s - received_s)

    def figures(self) -> dict[str, str]:
        """p50 / p99 of each series in ms, as text (``nan`` when empty)."""
        out = {"in_step_frames": str(len(self.in_step))}
        for key, values in (("ik", self.ik), ("latency", self.marker_to_command),
                            ("own_latency", self.com_to_command), ("in_step_latency", self.in_step)):
            out[f"{key}_p50_ms"], out[f"{key}_p99_ms"] = percentile_text(values, 50), percentile_text(values, 99)
        return out


@dataclass
class MarkerFrame:
    """One marker frame as received: stamp [s], positions (M, 3) [m], validity, and when it came (perf_counter)."""

    t_s: float
    names: list[str]
    positions_m: np.ndarray
    valid: np.ndarray
    received_s: float
    stamp_ns: int = 0              # the message's stamp [ns], handed back with the frame's IK pose


@dataclass
class LiveConfig:
    """The live retargeting's settings (the node's parameters)."""

    rate_hz: float = 100.0
    # the plan's rate [Hz]: every n-th frame, n the nearest whole number to rate_hz / plan_rate_hz (0: every frame):
    # a 200 Hz capture planned at 100 Hz halves the retargeter's work; on 2 cores beside the estimator and the
    # robot's loop, planning every frame ran out of time
    plan_rate_hz: float = 0.0
    margin_m: float = DEFAULT_MARGIN_M
    lookahead_s: float = LOOKAHEAD_S
    smooth_s: float = SMOOTH_S
    max_joint_speed: float = DEFAULT_MAX_JOINT_SPEED
    retiming: str = "local"
    seat_off_dwell_s: float = SEAT_OFF_DWELL_S
    fixed_time_scale: float | None = None
    max_time_scale: float = DEFAULT_MAX_TIME_SCALE
    com_wait_s: float = 0.03
    com_feedback: bool = True
    controller: str = "inverse_dynamics"    # the robot's on-board controller (robot.plant.CONTROLLERS)
    stabiliser: StabiliserConfig = field(default_factory=StabiliserConfig)
    marker_set: str = ""          # a packaged set's name or a YAML file; empty: chosen from the stream's names


@dataclass
class LiveProgress:
    """How far a live run has got: frames retargeted and of them infeasible, frames dropped without a human COM,
    frames off the plan's stride, lead-in frames, on-feet commands without a recent robot state, the COM feedback's
    largest shift [m]; and when the last frame was processed (``time.monotonic`` [s], and the robot's clock [s])."""

    processed: int = 0
    infeasible: int = 0
    skipped: int = 0
    between_plan_frames: int = 0
    lead_in_frames: int = 0
    state_stale: int = 0
    feedback_max_m: float = 0.0
    last_frame_s: float = 0.0
    last_frame_robot_s: float | None = None


@dataclass
class SentCommands:
    """What went to the robot: the robot's clock at the last command [s]; the planned COMs sent, with the robot time
    each went (a robot state can arrive late: it is compared with the plan of its own stamp); the plan's last command
    at rest, held once the plan is played; the robot's COM behind the plan's at the last command [m]."""

    last_s: float | None = None
    planned_com: deque[tuple[float, np.ndarray]] = field(default_factory=lambda: deque(maxlen=PLANNED_COM_KEPT))
    held: Command | None = None
    lag_m: float = 0.0

    def planned_com_at(self, t_s: float, default: np.ndarray) -> np.ndarray:
        """The planned COM of the last command sent at or before robot time ``t_s``: what a state measured then
        is compared with (against the newest plan a late state would read as a lag)."""
        for sent_s, com in reversed(self.planned_com):
            if sent_s <= t_s + 1e-9:
                return com
        return default


class LiveRetargeting:
    """Marker frames and human COMs in, paced joint commands out (see the module docstring).

    Args:
        cfg: the settings.
        send: publishes a command (the feedback's offset [m] or None) and returns when it went
            (``time.perf_counter``).
        measured_q: the robot's measured configuration in the model's order and the robot time [s] it was measured
            at (its stamp), or None when there is no recent one.
        robot_clock: the robot's time now [s], which paces the commands (the node's ROS clock).
    """

    def __init__(self, cfg: LiveConfig, send: Callable[[Command, np.ndarray | None], float],
                 measured_q: Callable[[], tuple[np.ndarray, float] | None],
                 robot_clock: Callable[[], float] = time.monotonic) -> None:
        self.cfg = cfg
        self.send, self.measured_q, self.robot_clock = send, measured_q, robot_clock
        self.stride = plan_stride(cfg.rate_hz, cfg.plan_rate_hz)
        self.plan_period_s = self.stride / cfg.rate_hz     # the time one planned frame stands for [s]
        self._first_stamp_s: float | None = None
        self.frames: deque[MarkerFrame] = deque()
        self.coms = HumanComTrack(cfg.com_wait_s)
        self.chair = ChairForceTrack()
        self.pacer = CommandPacer(1.0 / self.plan_period_s)
        self.latency = LatencyLog()
        self.retargeter: Retargeter | None = None
        self.player: PlanPlayer | None = None
        self.stabiliser: ComStabiliser | None = None
        self.model = self.model_data = None       # the robot model (the plan's COM parameters), once started
        self.names: list[str] = []
        self.progress = LiveProgress()
        self.sent = SentCommands()

    def start(self, robot: RobotSetup, frame: MarkerFrame, com_m: np.ndarray):
        """Calibrate on ``frame`` (the human seated) over the robot's start posture; returns the marker map.

        Raises:
            InputError: the frame cannot be overlaid on the robot (a missing marker, not seated).
        """
        self.retargeter = Retargeter(robot, RetargetConfig(marker_set=self.cfg.marker_set or None))
        marker_map = self.retargeter.calibrate(frame.names, frame.positions_m, frame.valid, com_m,
                                               frame_period_s=self.plan_period_s)
        c = self.cfg
        self.player = PlanPlayer(robot.model, self.plan_period_s, robot.support_xy, margin_m=c.margin_m,
                                 lookahead_s=c.lookahead_s, smooth_s=c.smooth_s,
                                 fixed_time_scale=c.fixed_time_scale, max_time_scale=c.max_time_scale,
                                 max_joint_speed=c.max_joint_speed, retiming=c.retiming,
                                 seat_off_dwell_s=c.seat_off_dwell_s)
        vx = float(self.coms.velocity_at(frame.t_s)[0])
        self.progress.lead_in_frames = len(self.retargeter.lead_in(frame.t_s, self.plan_period_s, frame.positions_m,
                                                          frame.valid, com_m, vx, on_frame=self._push))
        if com_feedback_applies(c.com_feedback, c.controller):
            self.stabiliser = ComStabiliser(robot.model, robot.sole_frames, robot.sole_targets, c.stabiliser)
        self.model, self.model_data = robot.model, robot.model.createData()
        self.names = frame.names
        return marker_map

    def add_frame(self, frame: MarkerFrame) -> None:
        """Queue a received frame if it is on the plan's stride (by its stamp: frames lost on the way do not shift
        it); the others are counted and left."""
        if self._first_stamp_s is None:
            self._first_stamp_s = frame.t_s
        if round((frame.t_s - self._first_stamp_s) * self.cfg.rate_hz) % self.stride:
            self.progress.between_plan_frames += 1
            return
        self.frames.append(frame)

    def _push(self, pose) -> None:
        """A lead-in pose into the plan, as a frame's would go."""
        self.player.push(pose.q, not pose.seated)

    def next_ready(self) -> tuple[MarkerFrame, np.ndarray] | None:
        """The oldest queued frame and its human COM once that COM is known (frames that can never get one are
        dropped and counted); None: wait."""
        while self.frames:
            frame = self.frames[0]
            com = self.coms.at(frame.t_s)
            if com is not None:
                return frame, com
            if not self.coms.began_after(frame.t_s):
                return None
            self.frames.popleft()
            self.progress.skipped += 1
        return None

    def step(self, frame: MarkerFrame, com_m: np.ndarray,
             after_command: Callable[[np.ndarray], None] | None = None) -> np.ndarray:
        """Retarget the ready ``frame`` (popped from the queue), send a command if one is due, then push the frame's
        pose to the player (:meth:`PlanPlayer.pull`'s ``coming``: the same commands, sent before the plan's
        smoothing and dynamics of the pose, ~0.3 ms); returns the frame's IK pose, handed to ``after_command``
        before the push too."""
        self.frames.popleft()
        ready = time.perf_counter()         # marker and COM both here: the retargeter's own latency starts
        pos, valid = reorder_markers(frame.names, frame.positions_m, frame.valid, self.names)
        result = self.retargeter.step(frame.t_s, pos, valid, com_m, self.chair.at(frame.t_s))
        self.latency.ik.append(result.ik.seconds)
        self.progress.infeasible += not result.ik.feasible
        now = self.robot_clock()
        if self.pacer.due(now):
            sent = self.pull_and_send(now, coming=1)
            if sent is not None:
                self.pacer.sent(now)
                self.latency.command(frame.received_s, ready, sent)
        if after_command is not None:
            after_command(result.q)
        self.player.push(result.q, not result.seated)
        self.progress.processed += 1
        self.progress.last_frame_s = time.monotonic()
        self.progress.last_frame_robot_s = self.robot_clock()
        return result.q

    def pull_and_send(self, robot_now_s: float, coming: int = 0) -> float | None:
        """Send the plan's next command (corrected by the COM feedback), if it has one, for the robot's time
        ``robot_now_s`` (``coming``: :meth:`PlanPlayer.pull`'s); returns when it went (wall time)."""
        sent = self.sent
        periods = 1.0 if sent.last_s is None else float(np.clip(
            (robot_now_s - sent.last_s) / self.pacer.period_s, 0.0, MAX_CATCH_UP_PERIODS))
        # a robot that trails its plan slows it (the player)
        cmd = self.player.pull(lag_m=sent.lag_m, periods=periods, coming=coming)
        if cmd is None:
            return None
        sent.last_s = robot_now_s
        # held after the plan: the same pose, at rest, still corrected by the COM feedback
        sent.held = dataclasses.replace(cmd, v=np.zeros_like(cmd.v), a=np.zeros_like(cmd.a))
        return self._correct_and_send(robot_now_s, cmd)

    def _correct_and_send(self, robot_now_s: float, cmd: Command) -> float:
        """Send ``cmd``, a command of the plan, corrected by the COM feedback for the robot's measured state; returns
        when it went (wall time)."""
        sent, progress = self.sent, self.progress
        sent.planned_com.append((robot_now_s, cmd.com))
        offset = None
        if self.stabiliser is not None:
            measured = self.measured_q()
            q_measured, plan_com = None, cmd.com
            if measured is not None:
                q_measured, plan_com = measured[0], sent.planned_com_at(measured[1], cmd.com)
            progress.state_stale += q_measured is None and cmd.on_feet
            fix = self.stabiliser.correct(cmd.q, plan_com, q_measured, cmd.on_feet, self.plan_period_s)
            cmd = dataclasses.replace(cmd, q=fix.q)
            offset = fix.offset_m
            sent.lag_m = fix.lag_m if q_measured is not None else 0.0
            progress.feedback_max_m = max(progress.feedback_max_m, float(np.abs(offset).max()))
        elif cmd.on_feet:       # no COM feedback: the plan still waits for a robot behind it, from its measured state
            sent.lag_m = self._measured_lag_m(cmd.com)
        return self.send(cmd, offset)

    def _measured_lag_m(self, plan_com: np.ndarray) -> float:
        """The robot's measured COM behind the plan's of its stamp [m] (0 without a recent state)."""
        measured = self.measured_q()
        if measured is None:
            self.progress.state_stale += 1
            return 0.0
        com = pin.centerOfMass(self.model, self.model_data, measured[0])
        return com_lag_m(self.sent.planned_com_at(measured[1], plan_com) - com)

    def tick(self) -> bool:
        """The timer: keep commands at the plan's rate when frames are late; after the markers stop (three periods
        of the robot's clock without one: on a graph held in lockstep, wall time says nothing), close the plan and
        play the rest; once played, hold its last pose (re-sent at the same rate, as a controller streams, still
        corrected by the COM feedback: a robot left standing keeps its balance).
        Returns True once the whole plan has been played."""
        if self.player is None:
            return False
        robot_now = self.robot_clock()
        if self.pacer.late(robot_now):
            if not self.player.done and self.pull_and_send(robot_now) is not None:
                self.pacer.sent(robot_now)      # after a jump of the clock: from now on, no burst to catch up
            elif self.player.done and self.sent.held is not None:
                self._correct_and_send(robot_now, self.sent.held)
                self.pacer.sent(robot_now)
        last = self.progress.last_frame_robot_s
        stopped_s = robot_now - (last if last is not None else robot_now)
        if self.frames or stopped_s < 3.0 * self.pacer.period_s:
            return False
        if not self.player.finished:
            self.player.close()
        return self.player.done

    def figures(self) -> dict[str, str]:
        """The run's figures as text, for the node's status and summary line."""
        torque_control = " (the robot's whole-body torque controller tracks the COM)" \
            if self.cfg.controller == "wbc" else ""
        n = self.progress
        feedback = f"off{torque_control}" if self.stabiliser is None else (
            f"largest shift {n.feedback_max_m * 100:.1f} cm; {n.state_stale} on-feet commands without a "
            "recent robot state")
        return {"frames": str(n.processed), "between_plan_frames": str(n.between_plan_frames),
                "infeasible_frames": str(n.infeasible),
                "skipped_frames": str(n.skipped),
                # the robot's duration over the human's, as sit2stand retarget's summary has it
                "time_scale": f"{self.player.duration_ratio:.2f}" if self.player else "nan",
                **self.latency.figures(), "com_feedback": feedback}


def summary_line(f: dict[str, str]) -> str:
    """One line of a run's :meth:`LiveRetargeting.figures` (the node prints it when it stops)."""
    between = f" planned ({f['between_plan_frames']} between them left out)" \
        if f.get("between_plan_frames", "0") != "0" else ""
    return (f"{f['frames']} frames{between}, {f['infeasible_frames']} infeasible, {f['skipped_frames']} without a "
            f"human COM; "
            f"time scale {f['time_scale']}; IK p50 {f['ik_p50_ms']} ms p99 {f['ik_p99_ms']} ms; marker->command "
            f"latency p50 {f['latency_p50_ms']} ms p99 {f['latency_p99_ms']} ms (waiting for the human COM "
            f"included); COM->command p50 {f['own_latency_p50_ms']} ms p99 {f['own_latency_p99_ms']} ms; "
            f"marker->command with the COM stream in step ({f['in_step_frames']} frames) p50 "
            f"{f['in_step_latency_p50_ms']} ms p99 {f['in_step_latency_p99_ms']} ms; scheduling "
            f"{f.get('scheduling', '?')}; COM feedback {f['com_feedback']}")
