"""The simulated robot's joints as its actuators see them: where each joint's numbers live in MuJoCo
(:class:`JointMap`), the faults a plant may hide in them (:class:`JointFaults`: torque-sensor bias and gain, encoder
offset, gear play, actuator delay) and the joint controller's reference (:class:`JointReference`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from .model import Unmodeled, expand

EXTRAPOLATE_MAX_S = 0.05      # a reference is followed along its velocity for at most this long after its message


@dataclass(frozen=True)
class JointMap:
    """The plant's actuated joints (MuJoCo order) and their addresses, resolved once: MuJoCo's by-name accessors
    cost ~15 us each. Each joint has a position servo (``pd_ids``: the PD, gains ``kp`` [N m/rad], ``kd``
    [N m s/rad]) and a motor (``ff_ids``: the feed-forward); ``effort`` [N m] clamps their sum."""

    names: list[str]
    qadr: np.ndarray          # into qpos
    vadr: np.ndarray          # into qvel
    tau_adr: np.ndarray       # each joint's actuator-torque sensor, into sensordata
    pd_ids: np.ndarray
    ff_ids: np.ndarray
    effort: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    servo_prm: tuple[np.ndarray, np.ndarray]   # the servos' gainprm and biasprm rows (off: zeros)

    @classmethod
    def of(cls, m: mujoco.MjModel) -> JointMap:
        names = [m.joint(i).name for i in range(1, m.njnt)]
        pd = np.array([m.actuator(n).id for n in names])
        return cls(names, np.array([m.joint(n).qposadr[0] for n in names]),
                   np.array([m.joint(n).dofadr[0] for n in names]),
                   np.array([m.sensor_adr[m.sensor(f"tau_{n}").id] for n in names]), pd,
                   np.array([m.actuator(f"ff_{n}").id for n in names]),
                   np.array([m.jnt_actfrcrange[m.joint(n).id][1] for n in names]),
                   m.actuator_gainprm[pd, 0].copy(), -m.actuator_biasprm[pd, 2].copy(),
                   (m.actuator_gainprm[pd].copy(), m.actuator_biasprm[pd].copy()))

    @property
    def n(self) -> int:
        return len(self.names)

    def servos(self, m: mujoco.MjModel, on: bool) -> None:
        """The position servos on (PD) or off (torque control)."""
        gain, bias = self.servo_prm
        m.actuator_gainprm[self.pd_ids] = gain if on else 0.0
        m.actuator_biasprm[self.pd_ids] = bias if on else 0.0


@dataclass(frozen=True)
class JointFaults:
    """What a plant hides in its joints (a plant file's ``unmodeled`` section), per joint: the torque sensors' bias
    [N m] and gain (measured / true), the encoders' offset [rad] (reading - true angle; the servo tracks the
    reading), half the gear's play [rad], and the actuators' delay in physics steps."""

    tau_bias: np.ndarray
    tau_gain: np.ndarray
    q_offset: np.ndarray
    backlash: np.ndarray
    delay_steps: int
    has_backlash: bool = False     # any gear play: checked at every physics step

    @classmethod
    def of(cls, um: Unmodeled, names: list[str], timestep_s: float) -> JointFaults:
        def per_joint(values: dict[str, float], default: float) -> np.ndarray:
            out = np.full(len(names), default)
            for name, value in expand(values, names).items():
                out[names.index(name)] = value
            return out

        backlash = per_joint(um.backlash_rad, 0.0)
        return cls(per_joint(um.torque_bias_nm, 0.0), per_joint(um.torque_gain, 1.0),
                   per_joint(um.joint_offset_rad, 0.0), backlash, int(round(um.actuator_delay_s / timestep_s)),
                   bool(backlash.any()))


@dataclass
class JointReference:
    """The joint controller's reference: positions [rad], velocities [rad/s], accelerations [rad/s^2], and when it
    was commanded [s, plant time]."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    t_s: float = 0.0
    tau: np.ndarray | None = None    # the joint torques the plan asks [N m], when it has them (torque control)
    _servo: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(default=None, repr=False, compare=False)

    @classmethod
    def holding(cls, q: np.ndarray, t_s: float) -> JointReference:
        return cls(q, np.zeros(len(q)), np.zeros(len(q)), t_s)

    def at(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The reference [rad, rad/s] at ``t_s``: followed along its own velocity and acceleration, for at most
        EXTRAPOLATE_MAX_S after its command."""
        return reference_at(self.q, self.qd, self.qdd, t_s - self.t_s)

    def servo_target(self, t_s: float, q_offset: np.ndarray, kd_over_kp: np.ndarray) -> np.ndarray:
        """The position servo's target [rad] at ``t_s``: the reference there (:meth:`at`) less the encoders'
        ``q_offset``, plus ``kd_over_kp`` times its velocity (the servo's damping then acts on the velocity error).
        A polynomial in the age whose three terms are taken at the first call (the plant's offset and gains do not
        change; a command makes a new reference): this runs at every physics step."""
        if self._servo is None:
            self._servo = (self.q - q_offset + kd_over_kp * self.qd, self.qd + kd_over_kp * self.qdd, 0.5 * self.qdd)
        age = _extrapolation_age(t_s - self.t_s)
        base, linear, quadratic = self._servo
        return base + age * (linear + age * quadratic)


def _extrapolation_age(age_s: float) -> float:
    """How far [s] a reference ``age_s`` after its command is followed along its velocity: 0 to EXTRAPOLATE_MAX_S."""
    return min(max(age_s, 0.0), EXTRAPOLATE_MAX_S)


def reference_at(q_ref: np.ndarray, qd_ref: np.ndarray, qdd_ref: np.ndarray,
                 age_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The joint controller's reference [rad, rad/s] ``age_s`` after its command: followed along the command's own
    velocity and acceleration, for at most EXTRAPOLATE_MAX_S."""
    age = _extrapolation_age(age_s)
    return q_ref + age * qd_ref + 0.5 * age * age * qdd_ref, qd_ref + age * qdd_ref
