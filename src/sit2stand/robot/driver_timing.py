"""The driver's time and command policy, without ROS: which simulated time stands for which ROS time, how far the
simulation steps per tick, when a command is due, and what the robot does once it has fallen.

Three time bases, one per way the driver runs (:class:`SimulationClock`):

* ``use_sim_time`` (a replayer's ``/clock`` drives the graph): the simulation starts at the first ``/clock`` time
  and follows that clock, each state stamped with the ``/clock`` time it simulates;
* ``publish_clock`` (the driver is the time source): ROS time is :data:`SIM_EPOCH_S` plus the simulated time;
* otherwise wall time, scaled by the real-time factor (0: as fast as it can, no ROS time of its own).

A command is applied when the simulation reaches its stamp (:class:`CommandQueue`): a simulation held up by a
loaded machine catches up with each command at its own time, not with the newest one over the whole gap (that
lurched the robot forward). A stamp more than :data:`MAX_COMMAND_LEAD_S` ahead of the graph's clock (two machines'
clocks apart, a wall-time stamp to a simulated-time driver) is applied at once.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator

SIM_EPOCH_S = 100.0
"""Simulated time starts here when the driver is the time source (0 reads as "unset")."""
MAX_COMMAND_LEAD_S = 0.5
"""A command stamped further ahead of the graph's clock [s] is applied at once."""
MAX_STEP_PER_TICK_S = 0.02
"""A tick steps at most this much simulated time [s]: behind, the simulation catches up a slice at a time, taking
the commands sent meanwhile at their stamps."""
AS_FAST_AS_POSSIBLE_STEP_S = 0.25
"""Simulated time per tick [s] with no real-time factor."""
FALL_POLICIES = ("limp", "hold")


class SimulationClock:
    """The ROS time of the simulated state and the simulated time a tick should reach (see the module docstring).
    Times: simulated [s] (the plant's), wall [s] (monotonic), ROS [ns]."""

    def __init__(self, sim_time: bool, publish_clock: bool, real_time_factor: float) -> None:
        self.sim_time, self.publish_clock, self.rtf = sim_time, publish_clock, real_time_factor
        self.sim0_s = self.wall0_s = 0.0
        self.ros0_ns = 0
        self.clock0_ns: int | None = None       # under use_sim_time: the /clock time the simulation started at sim0

    def start(self, sim_s: float, wall_s: float, ros_ns: int) -> None:
        """Count from here: the simulated time ``sim_s`` at wall time ``wall_s`` and ROS time ``ros_ns``; under
        ``use_sim_time`` the /clock origin is taken again at the next :meth:`follow` (a reset keeps the clock's
        time now: pass it as ``ros_ns``)."""
        self.sim0_s, self.wall0_s, self.ros0_ns = sim_s, wall_s, ros_ns
        if self.clock0_ns is not None:
            self.clock0_ns = ros_ns

    def follow(self, clock_ns: int, sim_s: float) -> bool:
        """Under ``use_sim_time``: take the first /clock time ``clock_ns`` as the simulation's start; True the first
        time (the driver then publishes what it latches and its seated state at once)."""
        if self.clock0_ns is not None:
            return False
        self.clock0_ns, self.sim0_s = clock_ns, sim_s
        return True

    def ros_ns(self, sim_s: float) -> int | None:
        """The ROS time [ns] of the simulated time ``sim_s``: the /clock time it simulates, the published simulated
        time, or the wall time it stands for; None while waiting for /clock, or when not paced."""
        elapsed_s = sim_s - self.sim0_s
        if self.clock0_ns is not None:
            return self.clock0_ns + int(round(elapsed_s * 1e9))
        if self.publish_clock:
            return int(round((SIM_EPOCH_S + sim_s) * 1e9))
        if self.sim_time or self.rtf <= 0:
            return None
        return self.ros0_ns + int(round(elapsed_s / self.rtf * 1e9))

    def target_s(self, sim_s: float, clock_ns: int | None, wall_s: float) -> float | None:
        """The simulated time this tick should reach, at most :data:`MAX_STEP_PER_TICK_S` past ``sim_s`` when paced;
        None under ``use_sim_time`` before the first /clock (``clock_ns`` 0 or None)."""
        if self.sim_time:
            if not clock_ns or self.clock0_ns is None:
                return None
            target = self.sim0_s + (clock_ns - self.clock0_ns) * 1e-9
        elif self.rtf > 0:
            target = self.sim0_s + (wall_s - self.wall0_s) * self.rtf
        else:
            return sim_s + AS_FAST_AS_POSSIBLE_STEP_S
        return min(target, sim_s + MAX_STEP_PER_TICK_S)

    def real_time_factor(self, sim_s: float, wall_s: float) -> float:
        """Simulated over wall time since :meth:`start`."""
        return (sim_s - self.sim0_s) / max(wall_s - self.wall0_s, 1e-9)


class CommandQueue:
    """Commands waiting for the simulation to reach their stamps, applied in the order they came."""

    def __init__(self) -> None:
        self._pending: deque[tuple[int, tuple]] = deque()

    def add(self, stamp_ns: int, command: tuple, graph_now_ns: int | None) -> bool:
        """Queue ``command`` for ``stamp_ns`` (0: at once); False when the stamp is more than
        :data:`MAX_COMMAND_LEAD_S` ahead of ``graph_now_ns`` (None: unknown), and the command is due at once."""
        ahead = graph_now_ns is not None and stamp_ns > graph_now_ns + MAX_COMMAND_LEAD_S * 1e9
        self._pending.append((0 if ahead else stamp_ns, command))
        return not ahead

    def due(self, sim_ns: int | None) -> Iterator[tuple]:
        """The commands whose stamps ``sim_ns`` has reached (all of them when it is None), taken off the queue."""
        while self._pending and (sim_ns is None or self._pending[0][0] <= sim_ns):
            yield self._pending.popleft()[1]

    def clear(self) -> None:
        self._pending.clear()

    def __len__(self) -> int:
        return len(self._pending)


def respond_to_fall(plant, policy: str) -> None:
    """What the robot does once it has fallen: ``limp`` (no torque) or ``hold`` (the posture it fell into)."""
    if policy == "limp":
        plant.set_limp(True)
    else:
        plant.command(plant.data.qpos[plant.qadr].copy())
