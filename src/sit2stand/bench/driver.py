"""The simulated robot's speed for `make bench`: the plant's step against a bare ``mj_step``, per on-board controller,
and the driver node's real-time factor running as fast as it can with its 500 Hz states.

* Plant step: :meth:`Plant.step` of the default plant (TALOS seated on its chair) over 1000 steps, the fastest of
  six alternated passes, against as many bare ``mujoco.mj_step`` calls on the same model and data: joint PD alone
  (``none``), joint PD + the contact-consistent gravity feed-forward at 200 Hz (``gravity``, the joint-PD default),
  and whole-body torque control (``wbc``, its QP at 500 Hz).
* Driver node: ``python -m sit2stand.nodes.driver`` with ``real_time_factor:=0``. Seated under joint PD: its own
  closing line after ``seconds`` of wall time. Holding its seat under whole-body torque control (an empty
  ``/robot/joint_state_command`` switches it once discovery lets it through): the simulated time its
  ``/robot/status`` reports over ``seconds`` of wall time from the first status under torque control, so that none
  of the joint-PD phase before the switch counts (its closing line mixes the two, by how long discovery took).
"""

from __future__ import annotations

import re
import subprocess
import sys
import time

import mujoco

from ..data import plant_path
from ..robot.model import PlantConfig
from ..robot.plant import Plant

PLANT_STEP_TARGET = 1.2           # the target: a plant step under joint PD at most 1.2 bare mj_steps
DRIVER_RTF_TARGET = 5.0           # the target: the driver node at least 5x real time with 500 Hz states
_WBC_RATE = """
import sys, time, rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import JointState
seconds, samples = float(sys.argv[1]), []
rclpy.init()
node = rclpy.create_node("bench_driver_wbc_rate")
pub = node.create_publisher(JointState, "/robot/joint_state_command", 10)
def on_status(msg):
    values = {kv.key: kv.value for kv in msg.values}
    if values.get("feedforward") == "wbc":
        samples.append((time.monotonic(), float(values["sim_time_s"])))
node.create_subscription(DiagnosticStatus, "/robot/status", on_status, 50)
deadline = time.monotonic() + 60.0
while time.monotonic() < deadline and (not samples or samples[-1][0] - samples[0][0] < seconds):
    if not samples:
        pub.publish(JointState())
    rclpy.spin_once(node, timeout_sec=0.1)
(w0, s0), (w1, s1) = samples[0], samples[-1]
print(f"wbc real-time factor {(s1 - s0) / (w1 - w0):.3f}" if w1 > w0 else "no status under torque control")
"""


def plant_steps(steps: int = 1000, passes: int = 6) -> dict[str, float]:
    """Per controller: the plant's step [us], the bare mj_step's [us] and their ratio."""
    out: dict[str, float] = {}
    for controller in ("none", "gravity", "wbc"):
        plant = Plant(PlantConfig.load(plant_path("default")))
        plant.step(200)
        plant.command(plant.q_ref, feedforward=controller)
        plant.step(200)
        best_plant = best_bare = float("inf")
        for _ in range(passes):
            t0 = time.perf_counter()
            plant.step(steps)
            best_plant = min(best_plant, time.perf_counter() - t0)
            t0 = time.perf_counter()
            for _ in range(steps):
                mujoco.mj_step(plant.model, plant.data)
            best_bare = min(best_bare, time.perf_counter() - t0)
        out[f"plant_step_{controller}_us"] = round(best_plant / steps * 1e6, 1)
        out[f"bare_mj_step_{controller}_us"] = round(best_bare / steps * 1e6, 1)
        out[f"plant_step_{controller}_vs_bare"] = round(best_plant / best_bare, 3)
    out["plant_step_pd_vs_1.2_target"] = round(out["plant_step_none_vs_bare"] / PLANT_STEP_TARGET, 3)
    return out


def driver_real_time_factor(env: dict[str, str], wbc: bool, seconds: float = 15.0) -> float:
    """The driver node's real-time factor as fast as it can (500 Hz states, /tf at 50 Hz): under joint PD from its
    closing line, under whole-body torque control from its status after the switch (see the module docstring)."""
    args = [sys.executable, "-m", "sit2stand.nodes.driver", "--ros-args", "-p", "real_time_factor:=0.0",
            "-p", f"controller:={'wbc' if wbc else 'inverse_dynamics'}"]
    node = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        if wbc:
            rate = subprocess.run([sys.executable, "-c", _WBC_RATE, str(seconds)], env=env, capture_output=True,
                                  text=True, timeout=120).stdout
        else:
            time.sleep(seconds)
    finally:
        node.send_signal(2)
        out, _ = node.communicate(timeout=60)
    match = re.search(r"wbc real-time factor ([\d.]+)", rate) if wbc else re.search(r"real-time factor ([\d.]+)\)", out)
    if not match or (wbc and "whole-body QP" not in out):
        raise RuntimeError(f"driver did not report its real-time factor{' under wbc' if wbc else ''}:\n{out[-2000:]}")
    return float(match.group(1))


def bench_driver(env: dict[str, str]) -> dict[str, float]:
    """The plant's step figures and the driver node's real-time factors (joint PD, whole-body torque control)."""
    out = plant_steps()
    out["driver_node_rtf_joint_pd"] = driver_real_time_factor(env, wbc=False)
    out["driver_node_rtf_wbc"] = driver_real_time_factor(env, wbc=True)
    out["driver_node_rtf_wbc_vs_5x_target"] = round(out["driver_node_rtf_wbc"] / DRIVER_RTF_TARGET, 3)
    return out
