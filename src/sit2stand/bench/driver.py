"""The simulated robot's speed for `make bench`: the plant's step against a bare ``mj_step``, per on-board controller,
and the driver node's real-time factor running as fast as it can with its 500 Hz states.

* Plant step: :meth:`Plant.step` of the default plant (TALOS seated on its chair) over 1000 steps, the fastest of
  six alternated passes, against as many bare ``mujoco.mj_step`` calls on the same model and data: joint PD alone
  (``none``), joint PD + the contact-consistent gravity feed-forward at 200 Hz (``gravity``, the joint-PD default),
  and whole-body torque control (``wbc``, its QP at 500 Hz).
* Driver node: ``python -m sit2stand.nodes.driver`` with ``real_time_factor:=0`` for ``seconds`` of wall time,
  its own closing line read back: seated under joint PD, and holding its seat under whole-body torque control (an
  empty ``/robot/joint_state_command`` switches it).
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
_SWITCH_TO_WBC = """
import time, rclpy
from sensor_msgs.msg import JointState
rclpy.init()
node = rclpy.create_node("bench_switch_to_wbc")
pub = node.create_publisher(JointState, "/robot/joint_state_command", 10)
for _ in range(40):
    pub.publish(JointState())
    time.sleep(0.1)
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
    """The driver node's real-time factor as fast as it can (500 Hz states, /tf at 50 Hz), from its closing line."""
    args = [sys.executable, "-m", "sit2stand.nodes.driver", "--ros-args", "-p", "real_time_factor:=0.0",
            "-p", f"controller:={'wbc' if wbc else 'inverse_dynamics'}"]
    node = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    switch = subprocess.Popen([sys.executable, "-c", _SWITCH_TO_WBC], env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL) if wbc else None
    time.sleep(seconds)
    node.send_signal(2)
    out, _ = node.communicate(timeout=60)
    if switch is not None:
        switch.kill()
        switch.wait(10)
    match = re.search(r"real-time factor ([\d.]+)\)", out)
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
