"""What every sit2stand node shares: start-up/shut-down, message classes by name, parameters (QoS: :mod:`.qos`).

A node module defines a ``rclpy.node.Node`` subclass and ``main = node_main(ThatNode)``; it then runs as a
console script (``replayer --ros-args -p bag:=...``), as ``python -m sit2stand.nodes.replayer``, from
``sit2stand launch`` and, on a full ROS install, from ``ros2 run sit2stand replayer``.
"""

from __future__ import annotations

import faulthandler
import importlib
import os
import signal
import sys
import threading
import time
from collections.abc import Callable

import rclpy
from rclpy.clock import Clock as RosClock
from rclpy.clock import ClockType
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from ..errors import InputError, Sit2StandError
from ..io.frame_rate import FrameRateCheck
from ..io.topics import MARKERS_TOPIC, node_result_line
from .graph_guard import GraphGuard


class NodeError(Sit2StandError, RuntimeError):
    """A node cannot start or go on; the message names the parameter, file or topic at fault."""


def message_class(msgtype: str):
    """The Python class of ``pkg/msg/Type`` (or ``pkg/srv/Type``), e.g. sensor_msgs.msg.JointState.

    Raises:
        NodeError: no such module or type here.
    """
    parts = msgtype.split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3:
        raise NodeError(f"{msgtype!r} is not a message type name (pkg/msg/Type)")
    pkg, kind, name = parts
    try:
        module = importlib.import_module(f"{pkg}.{kind}")
        return getattr(module, name)
    except (ImportError, AttributeError) as err:
        raise NodeError(f"message type {msgtype} has no Python class here ({err}); build or install the "
                        f"package that defines it") from None


def declare(node: Node, name: str, default, description: str = ""):
    """Declare a parameter and return its value, typed like ``default`` (ints are accepted for floats).

    ``default`` None means a required string; an empty list means a string array.
    """

    if isinstance(default, list) and not default:
        value = node.declare_parameter(name, Parameter.Type.STRING_ARRAY,
                                       ParameterDescriptor(description=description)).value
        return list(value or [])
    descriptor = ParameterDescriptor(description=description, dynamic_typing=True)
    value = node.declare_parameter(name, "" if default is None else default, descriptor).value
    try:
        if isinstance(default, bool):
            if isinstance(value, str):
                return value.strip().lower() in ("1", "true", "yes", "on")
            return bool(value)
        if isinstance(default, float):
            return float(value)
        if isinstance(default, int):
            return int(value)
    except (TypeError, ValueError):
        raise NodeError(f"parameter {name!r}: {value!r} is not a {type(default).__name__}") from None
    if isinstance(default, list):
        return list(value or [])
    return value


def steady_timer(node: Node, period_s: float, callback: Callable[[], None]):
    """A timer on the monotonic clock: it runs under ``use_sim_time`` too, before the first /clock and after the
    last (a ROS-time timer would not: discovery waiting for the replayer, which waits for the discovery)."""
    return node.create_timer(period_s, callback, clock=RosClock(clock_type=ClockType.STEADY_TIME))


class IdleDrain:
    """A node's ``drain()`` after a signal: keep spinning until ``count()`` has not changed for ``idle_s``."""

    def __init__(self, count: Callable[[], int], idle_s: float = 0.3) -> None:
        self.count, self.idle_s = count, idle_s
        self._last: int | None = None
        self._since = 0.0

    def __call__(self) -> bool:
        now, n = time.monotonic(), self.count()
        if n != self._last:
            self._last, self._since = n, now
        return now - self._since < self.idle_s


def scheduling_text() -> str:
    """This process's Linux scheduling class, e.g. ``SCHED_FIFO priority 50`` or ``SCHED_OTHER nice 0``."""
    policy = os.sched_getscheduler(0)
    if policy in (os.SCHED_FIFO, os.SCHED_RR):
        return f"SCHED_{'FIFO' if policy == os.SCHED_FIFO else 'RR'} priority {os.sched_getparam(0).sched_priority}"
    return f"SCHED_OTHER nice {os.getpriority(os.PRIO_PROCESS, 0)}"


def _make_executor(kind: str):
    """SingleThreadedExecutor, or rclpy's EventsExecutor (about 3x the message rate in one process; never publish
    from another thread while it spins: that was seen to deadlock)."""
    if kind == "events":
        return EventsExecutor()
    return SingleThreadedExecutor()


# use_sim_time's /clock subscription is absolute in rclpy: remapped to the node's namespace (the replayer publishes
# there), so ``__ns`` moves a graph's time base with its topics. After the user's own arguments: a rule of theirs for
# /clock comes first and wins.
CLOCK_IN_NAMESPACE = ["--ros-args", "-r", "/clock:=clock"]


def marker_rate_check(rate_hz: float) -> FrameRateCheck:
    """The check of the markers' stamps against a node's ``rate_hz`` parameter; a rate no capture has stops the node
    at start."""
    try:
        return FrameRateCheck(MARKERS_TOPIC, rate_hz)
    except InputError as err:
        raise NodeError(str(err)) from None


def node_main(factory: Callable[[], Node]) -> Callable[[list[str] | None], int]:
    """Make a console-script ``main`` that runs one node until it finishes, SIGINT or SIGTERM.

    The node may define:
      ``finished`` (bool attribute): leave the spin loop; ``exit_code`` (int);
      ``drain()`` -> bool: called repeatedly after a signal while it returns True (keep spinning to take what
      DDS has already delivered), at most ``drain_timeout_s`` (attribute, default 5 s);
      ``close()``: called once on the way out, before the node is destroyed.
    A second signal during the drain stops at once.
    """

    def main(argv: list[str] | None = None) -> int:
        rclpy.init(args=list(sys.argv if argv is None else argv) + CLOCK_IN_NAMESPACE,
                   signal_handler_options=SignalHandlerOptions.NO)
        signals = {"count": 0}

        def on_signal(signum, _frame):
            signals["count"] += 1
            if signals["count"] > 1:
                raise KeyboardInterrupt

        previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        node = None
        code = 0
        try:
            node = factory()
            guard = GraphGuard(node)
            executor = _make_executor(getattr(node, "executor_kind", "single_threaded"))
            executor.add_node(node)
            while rclpy.ok() and not getattr(node, "finished", False) and not signals["count"] and not guard.conflict:
                executor.spin_once(timeout_sec=0.1)
            if guard.conflict:
                raise NodeError(guard.conflict)
            drain = getattr(node, "drain", None)
            if signals["count"] and drain is not None:
                deadline = time.monotonic() + float(getattr(node, "drain_timeout_s", 5.0))
                while rclpy.ok() and time.monotonic() < deadline and drain():
                    executor.spin_once(timeout_sec=0.05)
            code = int(getattr(node, "exit_code", 0))
        except (KeyboardInterrupt, ExternalShutdownException):
            code = int(getattr(node, "exit_code", 0)) if node is not None else 0
        except NodeError as err:
            print(f"[{getattr(node, 'get_name', lambda: 'node')()}] error: {err}", file=sys.stderr, flush=True)
            code = 2
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            if node is not None:
                closer = getattr(node, "close", None)
                if closer is not None:
                    try:
                        closer()
                        code = code or int(getattr(node, "exit_code", 0))   # what closing found (a recorder's losses)
                    except Exception as err:  # noqa: BLE001 - report, still shut down
                        print(f"[{node.get_name()}] error while closing: {err}", file=sys.stderr, flush=True)
                        code = code or 1
                _bounded_teardown(node, code)
            rclpy.try_shutdown()
        return code

    return main


# A node's results are written by close(); what follows is DDS teardown, which can block: two full runs saw a driver
# hang over 10 s in it after its summary, and the launcher's SIGTERM turned a good run into exit -15 (Fast DDS and
# Cyclone both have such reports: eProsima/Fast-DDS#235, ros2/rmw_cyclonedds#104)
TEARDOWN_LIMIT_S = 5.0
# a teardown blocked in the middleware holding Python's lock stops every Python thread, the bound's too: faulthandler's
# native thread then prints where it hangs and ends the process (exit 1); the launcher judges the node by its result
# line (io.topics.NODE_RESULT)
TEARDOWN_HARD_LIMIT_S = TEARDOWN_LIMIT_S + 2.0


def _bounded_teardown(node: Node, code: int) -> None:
    """Say the node's result, then destroy it; if DDS teardown (with rclpy's shutdown after it) takes over
    TEARDOWN_LIMIT_S, say so and leave the process with ``code``, the node's own result."""
    name = node.get_name()
    print(node_result_line(name, code), flush=True)

    def leave() -> None:
        print(f"[{name}] DDS teardown did not finish in {TEARDOWN_LIMIT_S:g} s; leaving without it (exit {code})",
              file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(code)

    watchdog = threading.Timer(TEARDOWN_LIMIT_S, leave)
    watchdog.daemon = True
    watchdog.start()
    faulthandler.dump_traceback_later(TEARDOWN_HARD_LIMIT_S, exit=True)
    node.destroy_node()
    rclpy.try_shutdown()
    faulthandler.cancel_dump_traceback_later()
    watchdog.cancel()
