"""The live stand-up over three machines: network namespaces joined by virtual Ethernet through a bridge.

capture host (10.77.0.1): serve-c3d + mocap_bridge; control host (.2): human_com + retargeter; robot host (.3):
driver + recorder. Each host launches its share of ``live.yaml`` with ``--host``; DDS finds the others as a lab
sets it up: ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` (multicast on the link) and ``ROS_STATIC_PEERS`` (the other
hosts' unicast addresses, what works where multicast is blocked). Skips where namespaces cannot be made.
"""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import GRAPHS, try_fifo
from sit2stand.capture.latency import capture_origin_ns, latencies_ms, p50_p99
from sit2stand.data import plant_path
from sit2stand.scheduling import CAPTURE_STAND_IN_PRIORITY, OBSERVER_PRIORITY
from sit2stand.io.bag import BagReader
from sit2stand.retarget.pacing import READY_LINE

pytestmark = pytest.mark.graph
ROOT = Path(__file__).resolve().parents[1]
HOSTS = {"capture": "10.77.0.1", "control": "10.77.0.2", "robot": "10.77.0.3"}
PORT = 22223


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, timeout=10)


@pytest.fixture
def lab():
    """Three namespaces and a switch namespace (a Linux bridge); always removed afterwards."""
    tag = f"{os.getpid() % 10000}"
    names = {h: f"s2s{tag}-{h}" for h in HOSTS}
    switch = f"s2s{tag}-sw"
    made = []
    try:
        for ns in [switch, *names.values()]:
            _ip("netns", "add", ns)
            made.append(ns)
    except (subprocess.CalledProcessError, FileNotFoundError, PermissionError) as err:
        for ns in made:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        pytest.skip(f"network namespaces cannot be made here (needs root and iproute2): {err}")
    try:
        _ip("-n", switch, "link", "add", "br0", "type", "bridge")
        _ip("-n", switch, "link", "set", "br0", "up")
        for i, (host, ns) in enumerate(names.items()):
            _ip("link", "add", f"s2s{tag}v{i}", "netns", ns, "type", "veth", "peer", "name", f"p{i}", "netns", switch)
            _ip("-n", ns, "link", "set", f"s2s{tag}v{i}", "name", "eth0")
            _ip("-n", ns, "addr", "add", f"{HOSTS[host]}/24", "dev", "eth0")
            for dev in ("lo", "eth0"):
                _ip("-n", ns, "link", "set", dev, "up")
            _ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", "eth0")        # DDS multicast discovery
            _ip("-n", switch, "link", "set", f"p{i}", "master", "br0")
            _ip("-n", switch, "link", "set", f"p{i}", "up")
        yield names
    finally:
        for ns in made:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)


def _start(ns: str, args: list[str], env: dict, log: Path, fifo_priority: int | None = None) -> subprocess.Popen:
    """``fifo_priority``: under SCHED_FIFO at that priority where permitted (see test_graph_live.py)."""
    return subprocess.Popen(["ip", "netns", "exec", ns, sys.executable, "-m", *args], env=env,
                            stdout=open(log, "wb"), stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            preexec_fn=None if fifo_priority is None else lambda: try_fifo(fifo_priority))


def _wait_for(log: Path, text: str, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if log.exists() and text in log.read_text(errors="replace"):
            return True
        time.sleep(0.2)
    return False


def test_the_live_stand_up_runs_with_capture_control_and_robot_on_three_hosts(tmp_path, ros_env, lab,
                                                                              elderly_calibration):
    calibration = elderly_calibration
    # UDP only: the namespaces share /dev/shm, and Fast DDS would otherwise pass samples through shared memory,
    # past the virtual network (separate machines have no shared memory to take)
    env = {**ros_env, "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": ";".join(HOSTS.values()),
           "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}
    out, probe_out = tmp_path / "run", tmp_path / "latency.json"
    graph = str(GRAPHS / "live.yaml")
    common = [f"plant:={plant_path('cad')}", f"calibration:={calibration}"]
    procs = {
        "robot": _start(lab["robot"], ["sit2stand.cli", "launch", graph, f"out:={out}", *common, "--host",
                                       "robot", "--timeout", "200"], env, tmp_path / "robot.log"),
        "control": _start(lab["control"], ["sit2stand.cli", "launch", graph, *common, "estimator_policy:=fifo",
                                           "--host", "control", "--timeout", "200"], env,
                          tmp_path / "control.log"),
        "capture": _start(lab["capture"], ["sit2stand.cli", "launch", graph,
                                           f"capture_host:={HOSTS['capture']}", f"capture_port:={PORT}", "--host",
                                           "capture", "--timeout", "200"], env, tmp_path / "capture.log"),
        "probe": _start(lab["robot"], ["sit2stand.nodes.latency_probe", str(probe_out), "/mocap/markers",
                                       "/robot/retarget/ik"],
                        env, tmp_path / "probe.log", fifo_priority=OBSERVER_PRIORITY),
    }
    try:
        assert _wait_for(tmp_path / "robot.log", "TALOS seated", 120), (tmp_path / "robot.log").read_text()
        assert _wait_for(tmp_path / "control.log", READY_LINE, 90), (tmp_path / "control.log").read_text()[-3000:]
        server = _start(lab["capture"], ["sit2stand.cli", "serve-c3d", str(ROOT / "bags" / "elderly"),
                                         "--host", HOSTS["capture"], "--port", str(PORT)], env, tmp_path / "serve.log",
                        fifo_priority=CAPTURE_STAND_IN_PRIORITY)
        assert server.wait(90) == 0, (tmp_path / "serve.log").read_text()
        assert procs["control"].wait(240) == 0, (tmp_path / "control.log").read_text()[-4000:]
    finally:
        for name in ("probe", "capture", "robot", "control"):
            if procs[name].poll() is None:
                procs[name].send_signal(2)
        for p in procs.values():
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()
    logs = {h: (tmp_path / f"{h}.log").read_text(errors="replace") for h in ("capture", "control", "robot")}
    origin = capture_origin_ns((tmp_path / "serve.log").read_text())
    markers = latencies_ms(probe_out, "/mocap/markers", origin, 100.0)
    commands = latencies_ms(probe_out, "/robot/retarget/ik", origin, 100.0)
    print(f"across hosts: capture -> /mocap/markers {p50_p99(markers)}; capture -> joint command {p50_p99(commands)}")
    assert "[mocap_bridge] 531 frames, 0 lost" in logs["capture"], logs["capture"][-3000:]
    assert "[retargeter] 531 frames" in logs["control"], logs["control"][-3000:]
    with BagReader(out) as bag:
        assert bag.topics()["/mocap/markers"].count == 531, "the robot host recorded every frame of the capture host"
        z = [m.pose.position.z for _, m in bag.read("/robot/base_pose")]
    assert "FALLEN" not in logs["robot"] and z[0] < 0.65 and z[-1] > 0.85, f"pelvis {z[0]:.2f} -> {z[-1]:.2f} m"
