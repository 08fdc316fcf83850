"""Shared fixtures: real lab recordings from ../shared, a private ROS domain per test, node processes."""

from __future__ import annotations

import itertools
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from rerun.chunk import McapReader, RrdReader

from sit2stand.cli import main as sit2stand_main
from sit2stand.data import folder, plant_path
from sit2stand.io.c3d import read_c3d, write_trial_bag
from sit2stand.scheduling import Scheduling

ROOT = Path(__file__).resolve().parents[1]
REAL = (ROOT / ".." / "shared" / "data" / "real").resolve()
GRAPHS = folder("graphs")       # the packaged graphs (sit2stand/data/graphs)


def real_file(name: str) -> Path:
    """A file of ../shared/data/real (never copied into the project); skips the test where it is absent."""
    path = REAL / name
    if not path.is_file():
        pytest.skip(f"real recording {path} is not available on this machine")
    return path


# ROS domains 1-100 handed out in turn from a random start: no two of 100 consecutive tests share one, so the nodes
# of a test never meet the DDS state (shared-memory ports) that a node killed by a recent test left behind
_DOMAINS = itertools.islice(itertools.cycle(range(1, 101)),
                            random.Random(os.getpid() * 7919 + time.time_ns()).randrange(100), None)


def node_env(domain: int | str) -> dict[str, str]:
    """Environment for node processes on ROS domain ``domain``: discovery on localhost only, Fast DDS on UDP only; a
    node that hangs dumps its Python stacks on SIGABRT (faulthandler).

    UDP only because the suite kills nodes on purpose, and a killed node leaves its Fast DDS shared-memory ports in
    /dev/shm; in 3 of 5 full runs one node then hung inside participant creation (rclpy ``Node.__init__``), a known
    Fast DDS hazard (eProsima/Fast-DDS#1144, #2051) that never showed with a single test. The two graph tests that
    still ran on shared memory failed in full runs with a reader that never matched its writer in 20 s."""
    env = dict(os.environ)
    env.update({"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4",
                "PYTHONUNBUFFERED": "1", "PYTHONFAULTHANDLER": "1", "RCUTILS_COLORIZED_OUTPUT": "0"})
    return env


@pytest.fixture
def ros_env(monkeypatch) -> dict[str, str]:
    """:func:`node_env` on a ROS domain of this test's own, also set in the test's own process."""
    env = node_env(next(_DOMAINS))
    for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "FASTDDS_BUILTIN_TRANSPORTS"):
        monkeypatch.setenv(key, env[key])
    return env


def try_fifo(priority: int) -> None:
    """SCHED_FIFO for the calling process (and the threads it makes), where permitted (a ``preexec_fn``)."""
    Scheduling("fifo", priority).try_apply(0)


class NodeProcess:
    """A node (or the sit2stand CLI) in its own process; output goes to a log file in the test's tmp dir."""

    def __init__(self, args: list[str], env: dict[str, str], log: Path, fifo_priority: int | None = None) -> None:
        """``fifo_priority``: run it under SCHED_FIFO at that priority where permitted (else as usual)."""
        self.log_path = log
        self._log = open(log, "wb")
        self.proc = subprocess.Popen([sys.executable, "-m", *args], env=env, stdout=self._log,
                                     stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                     preexec_fn=None if fifo_priority is None else lambda: try_fifo(fifo_priority))

    def wait(self, timeout: float = 60.0) -> int:
        """The exit code; a process still running ``timeout`` later fails the test with its output and Python stacks
        (a node was seen to hang at start-up in full runs of the suite, 1 run in 2, never alone)."""
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            pytest.fail(f"still running after {timeout:g} s:\n{self.stacks()[-6000:]}")
        finally:
            self._log.flush()

    def stop(self, sig: int = signal.SIGINT, timeout: float = 20.0) -> int:
        """Send ``sig`` and wait for the exit code (see :meth:`wait`)."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        return self.wait(timeout)

    @property
    def output(self) -> str:
        self._log.flush()
        return self.log_path.read_text(errors="replace")

    def wait_for_output(self, text: str, timeout: float = 20.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.output:
                return True
            if self.proc.poll() is not None:
                return text in self.output
            time.sleep(0.05)
        return False

    def stacks(self, timeout: float = 5.0) -> str:
        """The output after SIGABRT, which makes a hung node print its Python stacks (PYTHONFAULTHANDLER)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGABRT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                pass
        return self.output

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)
        self._log.close()


@pytest.fixture
def run_node(tmp_path, ros_env):
    """Start ``python -m MODULE ARGS...`` processes. Those still running when the test ends get SIGINT, as from a
    user, so that they leave no DDS shared-memory ports behind, and SIGKILL 5 s later."""
    started: list[NodeProcess] = []

    def start(*args: str, log_name: str | None = None) -> NodeProcess:
        name = log_name or args[0].split(".")[-1]
        node = NodeProcess(list(args), ros_env, tmp_path / f"{name}-{len(started)}.log")
        started.append(node)
        return node

    yield start
    end_processes([node.proc for node in started])
    for node in started:
        node.kill()


def end_processes(procs: list[subprocess.Popen], grace_s: float = 5.0) -> None:
    """SIGINT to every process still running, then SIGKILL to those still running ``grace_s`` later."""
    running = [p for p in procs if p.poll() is None]
    for proc in running:
        proc.send_signal(signal.SIGINT)
    deadline = time.monotonic() + grace_s
    for proc in running:
        try:
            proc.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


@pytest.fixture(scope="session")
def elderly_standup(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """One live stand-up of the graph on bags/elderly with the CAD plant (CAD parameters: the consistent case), in a
    ROS domain of its own, its marker map written: (run folder holding ``run`` (the bag) and ``markers.yaml``, the
    launcher's result). Shared by the graph tests that read one stand-up (its frames, its commands): each stand-up
    costs ~35 s of the 2-core host. Joint PD with the retargeter's COM feedback (not the graph's default torque
    control, which test_graph_retarget runs on its own): the feedback's topic and shifts are checked on it."""
    run_dir = tmp_path_factory.mktemp("elderly_standup")
    env = node_env(random.Random(os.getpid() * 31 + time.time_ns()).randint(101, 200))
    cmd = [sys.executable, "-m", "sit2stand.cli", "launch", str(GRAPHS / "standup.yaml"),
           f"bag:={ROOT / 'bags' / 'elderly'}", f"out:={run_dir / 'run'}", f"plant:={plant_path('cad')}",
           f"marker_map:={run_dir / 'markers.yaml'}", "controller:=inverse_dynamics"]
    return run_dir, subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=240)


@pytest.fixture(scope="session")
def elderly_calibration(tmp_path_factory) -> Path:
    """The shipped elderly demonstration's skeleton calibration (``sit2stand human-calibrate bags/elderly``), made
    once per session and worker for the live graph tests that stream it."""
    out = tmp_path_factory.mktemp("elderly_calibration") / "calibration.yaml"
    assert sit2stand_main(["human-calibrate", str(ROOT / "bags" / "elderly"), "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="session")
def g1_simulated_run(tmp_path_factory) -> Path:
    """``sit2stand retarget bags/natural --robot g1 --simulate --plan frames`` (once per session and worker): its
    output folder (the per-frame plan: what its users check is the run's files, not the planner)."""
    out = tmp_path_factory.mktemp("g1") / "rt"
    assert sit2stand_main(["retarget", str(ROOT / "bags" / "natural"), "--robot", "g1", "--simulate",
                           "--plan", "frames", "--out", str(out)]) == 0
    return out


def rerun_entities(path: Path) -> dict[str, set[str]]:
    """Entity path -> its component columns, as Rerun's own readers see a recording (``.rrd``) or an MCAP file."""
    reader = McapReader(path) if Path(path).suffix == ".mcap" else RrdReader(path)
    out: dict[str, set[str]] = {}
    for chunk in reader.stream():
        out.setdefault(chunk.entity_path, set()).update(f.name for f in chunk.to_record_batch().schema)
    return out


@pytest.fixture(scope="session")
def sts_bag(tmp_path_factory) -> Path:
    """../shared/data/real/sts_child_vicon_01.c3d imported into a bag (once per session)."""

    src = real_file("sts_child_vicon_01.c3d")
    out = tmp_path_factory.mktemp("imported") / "sts_child"
    write_trial_bag(read_c3d(src, feet_plate=2), out)
    return out
