"""An excitation run of the simulated robot, recorded as a robot bag: the data the model-gap workflow is tested on.

The robot stands (no chair) and moves smoothly from one statically stable stance to the next (the identification's
stances: hip, knee, ankle and torso pitch across the stand-up's ranges, both arms at random shoulder and elbow
angles), with a quintic profile of ``move_s`` and a hold of ``hold_s`` at each stance, under PD + inverse-dynamics
feed-forward with the controller's (CAD) model. Everything is written as the driver would publish it, at
``rate_hz``: ``/robot/joint_states`` (measured torque as effort), ``/robot/ft/*``, ``/robot/cop``,
``/robot/base_pose`` and the references sent, ``/robot/joint_command``. The bag's metadata names the plant file's
``name`` only: never its ``unmodeled`` section.

Joints that do not move in these runs (hip yaw and roll, ankle roll, torso yaw, head, wrists, grippers, the upper-arm
rotation) cannot show friction, and masses on links rigidly joined by them cannot be told apart: the workflow names
such a mass by the group of links.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..io.topics import ROBOT_JOINT_COMMAND_TOPIC
from ..io import messages as M
from ..io.bag import BagWriter
from ..robot.model import SIDES, PlantConfig
from ..robot.plant import Plant
from ..robot.postures import home_com_bias, plan_postures
from .effects import alter_model


def quintic(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-jerk profile on s in [0, 1]: position, first and second derivative (per unit s)."""
    s = np.clip(s, 0.0, 1.0)
    return 10 * s**3 - 15 * s**4 + 6 * s**5, 30 * s**2 - 60 * s**3 + 30 * s**4, 60 * s - 180 * s**2 + 120 * s**3


def excite(cfg: PlantConfig, out: str | Path, seed: int = 0, n_moves: int = 8, move_s: float = 2.5,
           hold_s: float = 0.5, rate_hz: float = 100.0, progress: bool = False,
           alterations: list[dict] | None = None) -> dict:
    """Run and record an excitation (see the module docstring); returns a summary (duration, fell).
    ``alterations``: effects applied to the compiled plant (``gap.effects.alter_model``: springs, rotor inertia,
    kinematic and contact errors)."""
    plant = Plant(replace(cfg, fall_tilt_rad=np.pi), with_chair=False)
    if alterations:
        alter_model(plant.model, alterations)
        plant.reset()
    bias = home_com_bias(plant)
    stances = plan_postures(plant, n_moves, seed=seed, com_bias_m=bias)
    if len(stances) < n_moves:
        raise RuntimeError(f"only {len(stances)} of {n_moves} stable stances found")
    plant.reset(stances[0])
    plant.command(plant.q_ref, feedforward="inverse_dynamics")
    plant.step(int(round(1.0 / cfg.timestep_s)))          # settle in the first stance
    plant.data.time = 0.0
    dt = cfg.timestep_s
    every = max(1, int(round(1.0 / (rate_hz * dt))))
    refs = [s[plant.qadr] + plant.q_offset for s in stances]
    segment_s = move_s + hold_s
    duration = segment_s * (len(refs) - 1) + hold_s
    steps = int(round(duration / dt))
    t0_ns = 1_000_000_000
    with BagWriter(out, custom_data={"source": "sit2stand excite", "plant": cfg.name, "seed": str(seed),
                                     "joint_names": ",".join(plant.joint_names)}) as bag:
        for topic, msgtype in M.ROBOT_STATE_TOPICS.items():
            bag.add_topic(topic, msgtype)
        bag.add_topic(ROBOT_JOINT_COMMAND_TOPIC, "trajectory_msgs/msg/JointTrajectory")
        for k in range(steps):
            # the joint controller interpolates the reference at every physics step, as a real one does; the
            # bag gets it at rate_hz (a reference held for a whole output period makes the forces jump at each
            # update, and sampling locked to the updates would read a bias)
            t = k * dt
            i = min(int(t // segment_s), len(refs) - 2)
            s, sd, sdd = quintic(np.array((t - i * segment_s) / move_s))
            dq = refs[i + 1] - refs[i]
            q, qd, qdd = refs[i] + s * dq, sd / move_s * dq, sdd / move_s**2 * dq
            plant.command(q, qd, qdd, refresh=False)
            if k % every == 0:
                t_ns = t0_ns + int(round(t * 1e9))
                command = M.joint_trajectory_point(t_ns, plant.joint_names, q, qd, qdd, plant.cfg.profile.root_link)
                bag.write(ROBOT_JOINT_COMMAND_TOPIC, t_ns, command)
                sens = plant.sensors()
                for topic, msg in M.robot_state(t_ns, plant.joint_names, sens.q, sens.qd, sens.tau,
                                                sens.wrench_world, sens.cop_m, sens.base_pose,
                                                plant.cfg.profile.root_link):
                    bag.write(topic, t_ns, msg)
                if progress and k % int(round(2.0 / dt)) == 0:
                    print(f"  excite: {t:.1f}/{duration:.1f} s", file=sys.stderr, flush=True)
            plant.step(1)
            if plant.fallen:
                break
    feet = {s: plant.data.site(f"sole_{s}").xpos.copy() for s in SIDES}
    return {"duration_s": duration, "fell": bool(plant.fallen), "status": plant.status_text,
            "feet_x_m": [float(feet[s][0]) for s in SIDES]}
