"""Linux scheduling classes for the graph's processes (``scheduling`` in a graph file, ``sit2stand.launch``), the
priorities that tests and benchmarks give the processes that stand for other machines, and a process's cores and
OpenMP thread teams (their size, and how their idle threads wait)."""

from __future__ import annotations

import ctypes
import os
from dataclasses import dataclass

POLICIES = {"other": os.SCHED_OTHER, "fifo": os.SCHED_FIFO, "rr": os.SCHED_RR}
CAPTURE_STAND_IN_PRIORITY = 60
"""SCHED_FIFO priority of a capture-system stand-in (``serve-c3d``) on the machine of the live graph it feeds, in tests
and benchmarks: a capture system runs on a computer of its own, and frames it sent late would count as the graph's
latency."""
OBSERVER_PRIORITY = 59
"""SCHED_FIFO priority of a latency observer (a probe's subscriber) in tests and benchmarks, for the same reason."""


@dataclass(frozen=True)
class Scheduling:
    """A process's Linux scheduling class: ``policy`` other | fifo | rr, ``priority`` 1..99 (fifo/rr), ``nice``
    -20..19 (other)."""

    policy: str = "other"
    priority: int = 0
    nice: int = 0

    def __str__(self) -> str:
        if self.policy == "other":
            return f"SCHED_OTHER nice {self.nice}" if self.nice else "SCHED_OTHER"
        return f"SCHED_{self.policy.upper()} priority {self.priority}"

    def apply(self, pid: int = 0) -> None:
        """Set it on process ``pid`` (0: this one); raises OSError (e.g. PermissionError) when not allowed."""
        if self.policy == "other":
            os.sched_setscheduler(pid, os.SCHED_OTHER, os.sched_param(0))
            if self.nice:
                os.setpriority(os.PRIO_PROCESS, pid, self.nice)
        else:
            os.sched_setscheduler(pid, POLICIES[self.policy], os.sched_param(self.priority))

    def try_apply(self, pid: int = 0) -> bool:
        """:meth:`apply` where permitted; whether it was."""
        try:
            self.apply(pid)
        except OSError:
            return False
        return True

    def try_apply_to_process(self) -> bool:
        """:meth:`try_apply` on every thread of this process: Linux schedules threads, and a class set on one
        (``sched_setscheduler``'s pid is a thread id) leaves those already started, the middleware's receive threads
        among them, as they were; whether it was permitted on all."""
        permitted = True
        for tid in os.listdir("/proc/self/task"):
            try:
                self.apply(int(tid))
            except ProcessLookupError:      # the thread ended meanwhile
                continue
            except OSError:
                permitted = False
        return permitted

    def holds_for(self, pid: int) -> bool:
        """Whether process ``pid`` runs under this class."""
        if os.sched_getscheduler(pid) != POLICIES[self.policy]:
            return False
        if self.policy == "other":     # nice 0 asks for no change (a child inherits the launcher's niceness)
            return not self.nice or os.getpriority(os.PRIO_PROCESS, pid) == self.nice
        return os.sched_getparam(pid).sched_priority == self.priority


OPENMP_WAIT_POLICY = "PASSIVE"
"""How a process's idle OpenMP threads wait for work: asleep, not spinning. Two whole-rise solves side by side on two
cores, each on two threads, took 4.7-5.0 s each asleep against 6.9-7.2 s spinning (one alone on two idle cores: 3.7 s
either way, 4.9 s on one thread)."""


def openmp_threads_sleep_when_idle() -> None:
    """Ask :data:`OPENMP_WAIT_POLICY` of the OpenMP runtime, unless the environment names a policy. The runtime reads
    it once, when it is loaded (Pinocchio loads it), so the package does this on import."""
    os.environ.setdefault("OMP_WAIT_POLICY", OPENMP_WAIT_POLICY)


def usable_cores() -> int:
    """The CPU cores this process may run on (its affinity mask, which a container's CPU set narrows)."""
    return len(os.sched_getaffinity(0))


def hold_openmp_threads(n: int) -> None:
    """Hold the calling thread's OpenMP teams to ``n`` threads. Crocoddyl's library runs on OpenMP (libgomp), which
    by default makes a team as large as the machine for its parallel work; beside another busy process on 2 cores
    the teams' threads spin against each other: two solves at once took 310 s each, against 16 s alone and 15.5 s
    each held to one thread. Crocoddyl's own parallel knots
    (:attr:`sit2stand.retarget.whole_rise.WholeRiseConfig.threads`) name their team's size themselves."""
    try:
        ctypes.CDLL("libgomp.so.1").omp_set_num_threads(max(1, int(n)))
    except (OSError, AttributeError):      # no GNU OpenMP runtime: nothing spins
        pass
