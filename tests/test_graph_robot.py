"""Graph tests of the robot side: the driver with the recorder (seated, steady), the identification service called
from another process."""

import re
import time

import numpy as np
import pytest
import rclpy
from conftest import GRAPHS
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from sit2stand.io.bag import BagReader
from sit2stand.nodes.qos import ROBOT_STATE_READER_QOS
from sit2stand.robot.model import PlantConfig
from sit2stand.robot.postures import collect_postures
from sit2stand_msgs.srv import IdentifyCom

pytestmark = pytest.mark.graph


def recorded_counts(output: str, topic: str) -> list[int]:
    """A recorder's counts of ``topic`` so far, by its log lines (every 5 s)."""
    return [int(n) for n in re.findall(rf"recorded \d+ messages \([^)]*{re.escape(topic)}: (\d+)", output)]


def test_driver_in_a_graph_sits_still_on_the_chair(tmp_path, run_node):
    out = tmp_path / "seated"
    graph = run_node("sit2stand.cli", "launch", str(GRAPHS / "robot_seated.yaml"), f"out:={out}", "rtf:=2.0",
                     log_name="launch")
    # stopped once the recorder holds 4 s of the robot's state at 500 Hz (not after a time its start-up may take)
    deadline = time.monotonic() + 120
    while max(recorded_counts(graph.output, "/robot/joint_states"), default=0) < 2000:
        assert graph.proc.poll() is None and time.monotonic() < deadline, graph.output[-3000:]
        time.sleep(0.2)
    assert graph.stop(timeout=60) == 0, graph.output[-3000:]
    stdout = graph.output
    assert "upright" in stdout and "FALLEN" not in stdout, stdout[-3000:]
    with BagReader(out) as bag:
        topics = bag.topics()
        js = bag.read("/robot/joint_states")
        sim_s = (js[-1][1].header.stamp.sec + js[-1][1].header.stamp.nanosec * 1e-9) - \
            (js[0][1].header.stamp.sec + js[0][1].header.stamp.nanosec * 1e-9)
        assert sim_s > 2.0 and topics["/robot/joint_states"].count / sim_s > 490   # >= 500 Hz of simulated time
        poses = bag.read("/robot/base_pose")
        z = np.array([m.pose.position.z for _, m in poses])
        x = np.array([m.pose.position.x for _, m in poses])
        late = slice(len(z) // 2, None)                                     # after settling on the seat
        assert np.ptp(z[late]) < 0.005 and np.ptp(x[late]) < 0.01           # seated and steady
        assert 0.6 < z.mean() < 0.72
        fz = np.array([m.wrench.force.z for _, m in bag.read("/robot/ft/left")])
        weight = 116.27 * 9.81
        assert 0.1 * weight < 2 * fz[late].mean() < 0.85 * weight          # the chair takes the rest (~27 %)
        assert len(js[-1][1].effort) == 32 and np.all(np.isfinite(js[-1][1].effort))


def test_identification_service_called_from_another_process(tmp_path, ros_env, run_node):

    data = tmp_path / "postures"
    # the paper's protocol, arms still: planar5 lumps the arms into its rigid torso
    collect_postures(PlantConfig.load("default"), 12, data, progress=False, move_arms=False)
    server = run_node("sit2stand.nodes.identification")
    assert server.wait_for_output("ready", 60), server.output
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("client", context=context)
        client = node.create_client(IdentifyCom, "/robot/identify_com")
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        assert client.wait_for_service(timeout_sec=60), server.output
        for model in ("full", "planar5"):
            future = client.call_async(IdentifyCom.Request(data_path=str(data), model=model,
                                                           output_path=str(tmp_path / f"{model}.yaml")))
            executor.spin_until_future_complete(future, timeout_sec=60)
            res = future.result()
            assert res.success, res.message
            assert res.eval_rms_m < 0.005 < res.cad_eval_rms_m and res.condition_number > 1
            assert (tmp_path / f"{model}.yaml").exists() and len(res.parameter_names) == len(res.parameter_values)
        future = client.call_async(IdentifyCom.Request(data_path=str(tmp_path / "nowhere"), model="full"))
        executor.spin_until_future_complete(future, timeout_sec=30)
        assert not future.result().success and "no such bag" in future.result().message
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert server.stop() == 0


def test_under_a_held_clock_the_driver_still_gives_its_seated_state(ros_env, run_node):
    """A driver that joins a replayer's /clock while it is held (the stand-up graph's lockstep waits at 2 s for the
    retargeter's first command, and the retargeter for a robot state) publishes its state at that time at once:
    waiting for the clock to move first, nothing would ever move."""
    driver = run_node("sit2stand.nodes.driver", "--ros-args", "-p", "use_sim_time:=true")
    assert driver.wait_for_output("seated", 90), driver.output
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("held_clock", context=context)
        clock_pub = node.create_publisher(Clock, "/clock", 10)
        states = []
        node.create_subscription(JointState, "/robot/joint_states", states.append, ROBOT_STATE_READER_QOS)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        held = Clock()
        held.clock.sec = 2
        deadline = time.monotonic() + 30.0
        while not states and time.monotonic() < deadline:
            clock_pub.publish(held)                      # the same time, again and again: the clock is held
            executor.spin_once(timeout_sec=0.1)
        assert states, driver.output
        assert (states[0].header.stamp.sec, states[0].header.stamp.nanosec) == (2, 0)
        assert len(states[0].position) == 32
    finally:
        rclpy.shutdown(context=context)
