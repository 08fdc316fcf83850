"""The controller channel: the measured joint torque against the robot's own control law, re-evaluated from the
recorded commands and the measured state.

The joint controller is known exactly (it is ours; only the robot's physics is uncertain):

    tau_act = clip(kp (q_ref - q) + kd (q'_ref - q') + clip(ff), +-effort),

with the reference followed along its velocity between command messages, and ff the contact-consistent inverse
dynamics of the *controller's* model (``robot.plant.contact_feedforward``). The residual of the measured torque
against it is zero whatever the physics (masses, friction) is, and shows what sits between the command and the
sensor:

* actuator delay d [s]: the law acts on the reference of d ago: r = -d (kp q'_ref + kd q''_ref + ff'),
* torque-sensor bias (1) and gain (tau_act),
* a gear's play of +-b [rad] (backlash, ``robot.plant``): the joint gets only the motor's drive beyond a dead zone of
  +-kp b, r = -clip(drive, -kp b, kp b), where drive = tau_act + kd q' is the law without the joint's damping.

The simulated driver publishes the torque applied during its last physics step: the law is evaluated
``sensor_lag_s`` (one step) before the sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..dynamics import savgol_series
from ..robot.model import DEFAULT_ROBOT, PlantConfig
from ..robot.actuation import reference_at
from ..robot.plant import Plant, contact_feedforward, feedforward_seated
from .recording import Recording, smoothing_window


@dataclass
class ControlLaw:
    """The control law re-evaluated along a recording (N samples, n joints; see the module docstring)."""

    torque: np.ndarray        # (N, n) tau_act [N m]
    delay: np.ndarray         # (N, n) the actuator delay's signature [N m/s]
    valid: np.ndarray         # (N,) samples with a command before them
    drive: np.ndarray         # (N, n) tau_act + kd q' [N m]: what a gear's play takes its dead zone from
    kp: np.ndarray            # (n,) the joint PD's stiffness [N m/rad]

    @staticmethod
    def absent(N: int, n: int) -> ControlLaw:
        """No commands recorded: nothing valid."""
        z = np.zeros((N, n))
        return ControlLaw(z, z, np.zeros(N, bool), z, np.ones(n))


def feedforward_rate(ff: np.ndarray, t_s: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """d ff / dt [N m/s] by the recording's own Savitzky-Golay filter (the measured torque it is compared with has
    that bandwidth), over the samples with a command: a sample without one (the first, before any command) holds its
    nearest valid neighbour's value. Differentiated as zeros there, the recording's first samples got a rate of
    -2,300 N m/s, 1.5 N m of still-phase signature (x the delay) the plant never made: left in the residual once the
    delay was subtracted, it was flagged on the hips as "one phase only, while still"."""
    if not valid.any():
        return np.zeros_like(ff)
    ok = np.flatnonzero(valid)
    held = ff[ok[np.clip(np.searchsorted(ok, np.arange(len(ff))), 0, len(ok) - 1)]]
    window = smoothing_window(t_s)
    if len(t_s) <= window:
        return np.gradient(held, t_s, axis=0) if len(t_s) > 2 else np.zeros_like(ff)
    return savgol_series(held, window, 3, 1) / float(np.median(np.diff(t_s)))


def control_law(rec: Recording, controller_params: dict | None = None, sensor_lag_s: float = 0.001,
                robot: str = DEFAULT_ROBOT) -> ControlLaw | None:
    """The control law along ``rec`` of ``robot`` (a profile's name); None without commands. ``controller_params``:
    the controller's identified link parameters (None: CAD)."""
    cmd = rec.commands
    if cmd is None or rec.static or len(cmd.t_s) < 2:
        return None
    plant = Plant(PlantConfig(robot=robot), controller_params=controller_params)
    names = plant.joint_names
    if names != rec.joint_names:
        order = [names.index(j) for j in rec.joint_names]
    else:
        order = list(range(len(names)))
    kp, kd, effort = plant.joints.kp[order], plant.joints.kd[order], plant.joints.effort[order]
    n, N = len(rec.joint_names), len(rec)
    law = np.zeros((N, n))
    ff_all = np.zeros((N, n))
    pd_rate = np.zeros((N, n))
    valid = np.zeros(N, bool)
    fz = rec.feet_force_z_n
    for k in range(N):
        t = rec.t_s[k] - sensor_lag_s
        c = int(np.searchsorted(cmd.t_s, t + 1e-6)) - 1
        if c < 0 or not np.all(np.isfinite(cmd.q[c])):
            continue
        q_t, qd_t = reference_at(cmd.q[c], cmd.qd[c], cmd.qdd[c], t - cmd.t_s[c])
        q_meas = rec.q[k] - sensor_lag_s * rec.qd[k]
        qd_meas = rec.qd[k] - sensor_lag_s * rec.qdd[k]
        base = rec.base_pose[k]
        qp = np.concatenate([base[:3], base[[4, 5, 6, 3]], np.zeros(n)])
        qp[7:][order] = q_t
        qd_full, qdd_full = np.zeros(n), np.zeros(n)
        qd_full[order], qdd_full[order] = qd_t, cmd.qdd[c]
        seated = feedforward_seated(base[2], plant.onboard.seated_base_z_m, fz[k], plant.onboard.mass_kg)
        ff = contact_feedforward(plant.ctrl, plant.onboard.data, qp, qd_full, qdd_full, True, seated)[order]
        ff = np.clip(ff, -effort, effort)
        law[k] = np.clip(kp * (q_t - q_meas) + kd * (qd_t - qd_meas) + ff, -effort, effort)
        ff_all[k] = ff
        pd_rate[k] = kp * qd_t + kd * cmd.qdd[c]
        valid[k] = True
    dff = feedforward_rate(ff_all, rec.t_s, valid)
    damping = kd * (rec.qd - sensor_lag_s * rec.qdd)          # the law's own kd q' (as evaluated above)
    return ControlLaw(law, -(pd_rate + dff), valid, law + damping, kp)
