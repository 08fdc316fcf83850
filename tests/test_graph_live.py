"""The live stand-up: serve-c3d (a QTM stand-in) -> mocap_bridge -> human_com -> retargeter -> driver -> recorder."""

import re
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import GRAPHS, NodeProcess
from live_support import capture_origin_ns, latencies_ms, p50_p99
from sit2stand.data import plant_path
from sit2stand.io.bag import BagReader
from sit2stand.retarget.pacing import READY_LINE
from sit2stand.scheduling import CAPTURE_STAND_IN_PRIORITY, OBSERVER_PRIORITY

pytestmark = pytest.mark.graph
LOSS_TOLERATED = 50
"""Messages (of ~48,000 in a run: 0.1 %) the recorder may report lost in this test: on 2 cores, at the stream's
start (five real-time processes: the stand-in, the probe, the bridge, the retargeter's calibration, the estimator),
it lost 2-5 of the driver's state messages in 3 of 10 runs and 30 feet-plate samples in another on 2026-12-02 (a
known gap; the recorder reports them and exits 1, as it must)."""
ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent


def test_the_robot_stands_up_from_a_live_qtm_stream_of_the_shipped_elderly_demonstration(tmp_path, ros_env):
    calibration = tmp_path / "calibration.yaml"
    subprocess.run([sys.executable, "-m", "sit2stand.cli", "human-calibrate", str(ROOT / "bags" / "elderly"),
                    "--out", str(calibration)], check=True, env=ros_env, capture_output=True, timeout=120)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out, probe_out = tmp_path / "run", tmp_path / "latency.json"
    # the estimator in real time (below the bridge and the retargeter): with a calibration made beforehand it has no
    # calibration pause to starve the rest with
    graph = NodeProcess(["sit2stand.cli", "launch", str(GRAPHS / "live.yaml"), f"out:={out}",
                         f"plant:={plant_path('cad')}", f"capture_port:={port}", f"calibration:={calibration}",
                         "estimator_policy:=fifo", "--timeout", "200"], ros_env, tmp_path / "launch.log")
    probe = NodeProcess(["latency_probe", str(probe_out), "/mocap/markers", "/human/com", "/robot/retarget/ik"],
                        {**ros_env, "PYTHONPATH": str(HERE)}, tmp_path / "probe.log", fifo_priority=OBSERVER_PRIORITY)
    server = None
    try:
        assert graph.wait_for_output("TALOS seated", 120), graph.output[-3000:]
        assert graph.wait_for_output("/human/com publisher found", 60), graph.output[-3000:]
        assert graph.wait_for_output(READY_LINE, 60), graph.output[-3000:]
        assert probe.wait_for_output("probe ready", 30), probe.output
        # the capture system runs on its own PC in a lab; here it shares 2 cores with the graph it feeds, and its
        # frames sent late would count as the graph's latency: it runs in real time, above the graph, where permitted
        server = NodeProcess(["sit2stand.cli", "serve-c3d", str(ROOT / "bags" / "elderly"), "--port", str(port),
                              "--host", "127.0.0.1"], ros_env, tmp_path / "serve.log",
                             fifo_priority=CAPTURE_STAND_IN_PRIORITY)
        assert server.wait(60) == 0, server.output
        code = graph.wait(240)
        assert code == 0 or "FALLEN" in graph.output or _only_a_few_lost(graph.output), graph.output[-4000:]
    finally:
        probe.stop()
        for p in (graph, server):
            if p is not None:
                p.kill()
    log = graph.log_path.read_text(errors="replace")
    origin = capture_origin_ns(server.log_path.read_text())
    markers, coms, commands = (latencies_ms(probe_out, topic, origin, 100.0)
                               for topic in ("/mocap/markers", "/human/com", "/robot/retarget/ik"))
    print(f"capture -> /mocap/markers {p50_p99(markers)}; capture -> /human/com {p50_p99(coms)}; capture -> joint "
          f"command {p50_p99(commands)}")
    assert "[mocap_bridge] 531 frames, 0 lost, 1 connection(s)" in log, log[-4000:]
    assert "[retargeter] 531 frames" in log, log[-4000:]
    assert len(markers) == 531
    with BagReader(out) as bag:
        z = [m.pose.position.z for _, m in bag.read("/robot/base_pose")]
    assert "FALLEN" not in log and z[0] < 0.65 and z[-1] > 0.85, f"pelvis {z[0]:.2f} -> {z[-1]:.2f} m\n{log[-3000:]}"


def _only_a_few_lost(output: str) -> bool:
    """Whether the graph failed only because its recorder reported at most LOSS_TOLERATED messages lost (printed
    for the record)."""
    found = re.search(r"\[recorder\] error: lost (\d+) messages \(([^)]*)\)", output)
    failed = {name for name, code in re.findall(r"(\w+) exited with code (-?\d+)", output) if code != "0"}
    if not found or failed != {"recorder"}:
        return False
    print(f"the recorder lost {found.group(1)} messages ({found.group(2)})")
    return int(found.group(1)) <= LOSS_TOLERATED
